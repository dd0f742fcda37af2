//! The corrections journal: parse, replay and reopen. Opening never changes the file; a journal
//! that opens once opens again to the same corrections; an edit made after opening is read back
//! with every correction restored before it.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::geometry::Quad;
use regtrack::gt::{Corrections, Mark, ssm_key};

const FRAMES: usize = 50;

/// Every correction in effect: (SSM key, frame, mark).
fn marks(c: &Corrections) -> Vec<(String, usize, Mark)> {
    let mut keys: Vec<String> = regtrack::ssm::REGISTRY
        .iter()
        .filter_map(|e| ssm_key(e.name).ok())
        .collect();
    keys.sort();
    keys.dedup();
    keys.iter()
        .flat_map(|k| {
            c.corrected_frames(k)
                .into_iter()
                .map(|f| (k.clone(), f, c.mark(k, f).expect("listed")))
                .collect::<Vec<_>>()
        })
        .collect()
}

fuzz_target!(|data: &[u8]| {
    let j = scratch::scratch("journal").join("s_corrections.jsonl");
    std::fs::write(&j, data).unwrap();
    let first = Corrections::open(&j, "s", FRAMES);
    assert_eq!(
        std::fs::read(&j).unwrap(),
        data,
        "opening changed the journal"
    );
    let Ok((mut c, rec)) = first else {
        return;
    };
    let (c2, rec2) = Corrections::open(&j, "s", FRAMES).expect("it opened once");
    assert_eq!(rec, rec2);
    let before = marks(&c);
    assert_eq!(before, marks(&c2));
    let q = Mark::Quad(Quad::from_rect(1.0, 2.0, 30.0, 40.0).to_array());
    c.edit("fuzz", &[("translation".into(), 3, Some(q))])
        .expect("an edit of a journal that opened");
    drop(c);
    let (c3, rec3) = Corrections::open(&j, "s", FRAMES).expect("the journal after an edit");
    assert_eq!(c3.mark("translation", 3), Some(q), "the edit is read back");
    assert_eq!(
        rec3.skipped.len(),
        rec.skipped.len(),
        "{:?} then {:?}",
        rec.skipped,
        rec3.skipped
    );
    let mut expect: Vec<_> = before
        .into_iter()
        .filter(|(k, f, _)| !(k == "translation" && *f == 3))
        .collect();
    expect.push(("translation".into(), 3, q));
    expect.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    let mut got = marks(&c3);
    got.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    assert_eq!(
        got, expect,
        "a correction restored before the edit was lost"
    );
});
