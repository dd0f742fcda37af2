use super::*;
use crate::dataset::parse_ground_truth_bytes;
use crate::geometry::Point;
use proptest::prelude::*;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "regtrack-gt-{name}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0)
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn quad(dx: f64) -> Quad {
    Quad::from_rect(10.0 + dx, 20.0, 30.0, 40.0)
}

fn set(ssm: &str, f: usize, dx: f64) -> (String, usize, Option<Mark>) {
    (ssm.into(), f, Some(Mark::Quad(quad(dx).to_array())))
}

#[test]
fn edits_undo_and_redo_survive_a_reopen() {
    let d = tmp("reopen");
    let j = d.join("s_corrections.jsonl");
    {
        let (mut c, rec) = Corrections::open(&j, "s", 10).unwrap();
        assert_eq!(rec, Recovery::default());
        assert!(c.edit("a", &[set("similitude", 1, 1.0)]).unwrap());
        assert!(
            c.edit("b", &[set("homography", 2, 2.0), set("sl3", 3, 3.0)])
                .unwrap()
        );
        assert!(
            c.edit("c", &[("similitude".into(), 4, Some(Mark::Occluded))])
                .unwrap()
        );
        assert_eq!(c.undo().unwrap().unwrap().0, "c");
        assert_eq!(c.undo().unwrap().unwrap().0, "b");
        assert_eq!(c.redo().unwrap().unwrap().0, "b");
        // A no-op edit is not recorded.
        assert!(!c.edit("same", &[set("similitude", 1, 1.0)]).unwrap());
    }
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!(rec.edits, 2);
    assert!(!rec.truncated_tail);
    assert_eq!(
        c.mark("similitude", 1),
        Some(Mark::Quad(quad(1.0).to_array()))
    );
    // sl3 is 8-DOF: kept with the homography corrections.
    assert_eq!(
        c.mark("homography", 3),
        Some(Mark::Quad(quad(3.0).to_array()))
    );
    assert_eq!(c.mark("similitude", 4), None, "edit c was undone");
    let (done, redo) = c.history();
    assert_eq!((done, redo), (vec!["a", "b"], vec!["c"]));
}

#[test]
fn undo_restores_what_was_there_across_frames() {
    let mut c = Corrections::in_memory(5);
    c.edit("first", &[set("affine", 0, 1.0), set("affine", 1, 1.0)])
        .unwrap();
    c.edit("second", &[set("affine", 1, 5.0), set("affine", 2, 5.0)])
        .unwrap();
    c.undo().unwrap();
    assert_eq!(c.mark("affine", 1), Some(Mark::Quad(quad(1.0).to_array())));
    assert_eq!(c.mark("affine", 2), None);
    c.undo().unwrap();
    assert!(c.is_empty());
    assert!(c.undo().unwrap().is_none());
    c.redo().unwrap();
    c.redo().unwrap();
    assert_eq!(c.mark("affine", 2), Some(Mark::Quad(quad(5.0).to_array())));
    // A new edit clears the redo history.
    c.undo().unwrap();
    c.edit("third", &[set("affine", 3, 0.0)]).unwrap();
    assert!(c.redo().unwrap().is_none());
}

#[test]
fn a_line_cut_by_a_crash_is_ignored_and_the_journal_goes_on() {
    let d = tmp("cut");
    let j = d.join("s_corrections.jsonl");
    {
        let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
        c.edit("a", &[set("translation", 1, 1.0)]).unwrap();
    }
    // A crash in the middle of appending the next record.
    let mut f = std::fs::OpenOptions::new().append(true).open(&j).unwrap();
    std::io::Write::write_all(&mut f, b"{\"kind\":\"edit\",\"id\":2,\"lab").unwrap();
    drop(f);
    let (mut c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert!(rec.truncated_tail && rec.edits == 1);
    c.edit("b", &[set("translation", 2, 2.0)]).unwrap();
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!(rec.edits, 2, "the edit after the cut line is read back");
    assert!(c.mark("translation", 2).is_some());
}

#[test]
fn a_malformed_record_is_skipped_and_named_by_file_and_line() {
    let d = tmp("bad");
    let j = d.join("s_corrections.jsonl");
    let header = "{\"kind\":\"header\",\"format\":1,\"sequence\":\"s\"}\n";
    let good = "{\"kind\":\"edit\",\"id\":7,\"label\":\"ok\",\"changes\":[{\"ssm\":\"affine\",\"frame\":1,\"before\":null,\"after\":\"occluded\"}]}\n";
    let q = |v: &str| {
        format!(
            "{{\"kind\":\"edit\",\"id\":1,\"label\":\"x\",\"changes\":[{{\"ssm\":\"affine\",\"frame\":1,\"before\":null,\"after\":{{\"quad\":[{v}]}}}}]}}\n"
        )
    };
    for (body, what) in [
        ("{\"kind\":\"edit\",\"id\":1}\n".to_string(), "not a journal record"),
        ("garbage\n".to_string(), "not a journal"),
        ("{\"kind\":\"undo\",\"id\":4}\n".to_string(), "not the last edit"),
        (
            "{\"kind\":\"edit\",\"id\":1,\"label\":\"x\",\"changes\":[{\"ssm\":\"affine\",\"frame\":99,\"before\":null,\"after\":\"occluded\"}]}\n".to_string(),
            "beyond",
        ),
        (
            "{\"kind\":\"edit\",\"id\":1,\"label\":\"x\",\"changes\":[{\"ssm\":\"warp9\",\"frame\":1,\"before\":null,\"after\":\"occluded\"}]}\n".to_string(),
            "warp9",
        ),
        (
            "{\"kind\":\"edit\",\"id\":1,\"label\":\"x\",\"changes\":[{\"ssm\":\"affine\",\"frame\":18446744073709551615,\"before\":null,\"after\":\"occluded\"}]}\n".to_string(),
            "frame 18446744073709551616 is beyond",
        ),
        (q("1e308,0,10,0,10,10,0,10"), "1.000e308"),
        (q("5,5,5,5,5,5,5,5"), "convex"),
        (q("0,0,10,0,20,0,30,0"), "convex"),
        (q("0,0,10,10,10,0,0,10"), "convex"),
    ] {
        // The bad record between a header and a good edit.
        std::fs::write(&j, format!("{header}{body}{good}")).unwrap();
        let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
        assert_eq!(rec.skipped.len(), 1, "{body}: {:?}", rec.skipped);
        let m = &rec.skipped[0];
        assert!(
            m.contains("s_corrections.jsonl:2") && m.contains(what) && m.len() < 500,
            "{body}: {m}"
        );
        assert_eq!(c.mark("affine", 1), Some(Mark::Occluded), "{body}: the good edit");
    }
    // Not a journal at all, or no header: refused (nothing would be appended to it).
    for (bytes, what) in [
        ("{\"kind\":\"undo\",\"id\":1}\n", "header"),
        ("some notes\nof mine\n", "not a corrections journal"),
    ] {
        std::fs::write(&j, bytes).unwrap();
        let e = Corrections::open(&j, "s", 10).unwrap_err().to_string();
        assert!(e.contains(":1") && e.contains(what), "{e}");
    }
    // Another sequence's journal.
    std::fs::write(&j, header.replace("\"s\"", "\"other\"")).unwrap();
    let e = Corrections::open(&j, "s", 10).unwrap_err().to_string();
    assert!(e.contains("'other'") && e.contains("not of 's'"), "{e}");
}

/// The journal's bytes and what two successive opens restore.
fn open_twice(j: &Path) -> (Vec<u8>, Recovery, Recovery, Vec<usize>) {
    let before = std::fs::read(j).unwrap();
    let (c1, r1) = Corrections::open(j, "s", 10).unwrap();
    assert_eq!(
        std::fs::read(j).unwrap(),
        before,
        "the first open changed the journal"
    );
    let (c2, r2) = Corrections::open(j, "s", 10).unwrap();
    assert_eq!(
        std::fs::read(j).unwrap(),
        before,
        "the second open changed the journal"
    );
    assert_eq!(c1.corrected_frames("affine"), c2.corrected_frames("affine"));
    (before, r1, r2, c2.corrected_frames("affine"))
}

#[test]
fn a_whole_last_record_without_its_newline_is_kept() {
    let d = tmp("nonl");
    let j = d.join("s_corrections.jsonl");
    {
        let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
        c.edit("a", &[set("affine", 1, 1.0)]).unwrap();
        c.edit("b", &[set("affine", 2, 1.0)]).unwrap();
    }
    // An editor or a copy drops the final newline.
    let mut bytes = std::fs::read(&j).unwrap();
    assert_eq!(bytes.pop(), Some(b'\n'));
    std::fs::write(&j, &bytes).unwrap();
    let (_, r1, r2, frames) = open_twice(&j);
    assert_eq!((r1.edits, r2.edits), (2, 2));
    assert!(!r1.damaged(), "{r1:?}");
    assert_eq!(frames, vec![1, 2]);
    // The next edit ends the line first.
    let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
    c.edit("c", &[set("affine", 3, 1.0)]).unwrap();
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!((rec.edits, rec.damaged()), (3, false), "{rec:?}");
    assert_eq!(c.corrected_frames("affine"), vec![1, 2, 3]);
}

#[test]
fn reopening_changes_nothing_whatever_the_journal_holds() {
    let d = tmp("twice");
    let j = d.join("s_corrections.jsonl");
    let header = "{\"kind\":\"header\",\"format\":1,\"sequence\":\"s\"}\n";
    let edit = |id: u64, f: usize| {
        format!(
            "{{\"kind\":\"edit\",\"id\":{id},\"label\":\"x\",\"changes\":[{{\"ssm\":\"affine\",\"frame\":{f},\"before\":null,\"after\":\"occluded\"}}]}}\n"
        )
    };
    let cases = [
        (format!("{header}{}{}", edit(1, 1), edit(2, 2)), vec![1, 2]),
        (format!("{header}{}{{\"kind\":\"ed", edit(1, 1)), vec![1]),
        (
            format!("{header}{}{}", edit(1, 1), edit(2, 2).trim_end()),
            vec![1, 2],
        ),
        (
            format!("{header}{}\u{0}\u{0}\n{}", edit(1, 1), edit(2, 2)),
            vec![1, 2],
        ),
        (header.to_string(), vec![]),
    ];
    for (bytes, frames) in cases {
        std::fs::write(&j, &bytes).unwrap();
        let (_, r1, r2, got) = open_twice(&j);
        assert_eq!(r1, r2, "{bytes}");
        assert_eq!(got, frames, "{bytes}");
    }
}

#[test]
fn a_record_after_a_torn_one_on_the_same_line_is_recovered() {
    // What a failed append (a full disk) left before this version repaired it: part of a
    // record, then the next records, the first of them on the same line.
    let d = tmp("torn");
    let j = d.join("s_corrections.jsonl");
    let header = "{\"kind\":\"header\",\"format\":1,\"sequence\":\"s\"}\n";
    let edit = |id: u64, f: usize| {
        format!(
            "{{\"kind\":\"edit\",\"id\":{id},\"label\":\"x\",\"changes\":[{{\"ssm\":\"affine\",\"frame\":{f},\"before\":null,\"after\":\"occluded\"}}]}}\n"
        )
    };
    let torn = &edit(2, 9)[..40];
    std::fs::write(
        &j,
        format!("{header}{}{torn}{}{}", edit(1, 1), edit(3, 3), edit(4, 4)),
    )
    .unwrap();
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!(c.corrected_frames("affine"), vec![1, 3, 4]);
    assert_eq!(rec.skipped.len(), 1, "{:?}", rec.skipped);
    assert!(
        rec.skipped[0].contains(":3: 40 byte(s) before a record skipped"),
        "{:?}",
        rec.skipped
    );
}

#[test]
fn a_failed_append_leaves_nothing_and_later_edits_are_kept() {
    let d = tmp("full");
    let j = d.join("s_corrections.jsonl");
    let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
    c.edit("a", &[set("affine", 1, 1.0)]).unwrap();
    let len = std::fs::metadata(&j).unwrap().len();
    // The disk fills up in the middle of the next record.
    c.inject_faults(journal::Faults {
        capacity: Some(len + 30),
        ..Default::default()
    });
    for f in [2, 3] {
        let e = c
            .edit("b", &[set("affine", f, 1.0)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("No space left"), "{e}");
        assert_eq!(
            c.corrected_frames("affine"),
            vec![1],
            "a failed edit takes no effect"
        );
        assert_eq!(
            std::fs::metadata(&j).unwrap().len(),
            len,
            "the torn record is cut off"
        );
    }
    // Space is freed; three more edits.
    c.inject_faults(journal::Faults::default());
    for f in [4, 5, 6] {
        c.edit("c", &[set("affine", f, 1.0)]).unwrap();
    }
    c.undo().unwrap();
    drop(c);
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert!(!rec.damaged(), "{rec:?}");
    assert_eq!(c.corrected_frames("affine"), vec![1, 4, 5]);
}

#[test]
fn opening_a_sequence_writes_no_journal_until_the_first_edit() {
    let d = tmp("lazy");
    let j = d.join("sub").join("s_corrections.jsonl");
    let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
    assert!(!j.exists());
    c.edit("a", &[set("affine", 1, 1.0)]).unwrap();
    let text = std::fs::read_to_string(&j).unwrap();
    assert!(
        text.starts_with("{\"kind\":\"header\"") && text.lines().count() == 2,
        "{text}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn the_journal_reader_never_panics_on_arbitrary_bytes(
        bytes in proptest::collection::vec(any::<u8>(), 0..400),
        prefix in any::<bool>(),
    ) {
        let path = Path::new("fuzz_corrections.jsonl");
        let mut data = Vec::new();
        if prefix {
            data.extend_from_slice(b"{\"kind\":\"header\",\"format\":1,\"sequence\":\"s\"}\n");
        }
        data.extend_from_slice(&bytes);
        if let Err(e) = journal::parse(path, &data) {
            let m = e.to_string();
            prop_assert!(m.starts_with("fuzz_corrections.jsonl:"), "{}", m);
        }
    }

    #[test]
    fn the_ground_truth_reader_never_panics_on_arbitrary_bytes(
        bytes in proptest::collection::vec(any::<u8>(), 0..400),
    ) {
        let path = Path::new("fuzz_gt.txt");
        if let Err(e) = parse_ground_truth_bytes(path, &bytes) {
            let m = e.to_string();
            prop_assert!(m.starts_with("fuzz_gt.txt:"), "{}", m);
        }
    }

    #[test]
    fn ground_truth_like_lines_never_panic(
        lines in proptest::collection::vec(
            proptest::collection::vec(
                prop_oneof![
                    Just("frame00001.jpg".to_string()),
                    Just("lost".to_string()),
                    Just("occluded".to_string()),
                    Just("nan".to_string()),
                    Just("inf".to_string()),
                    Just(",".to_string()),
                    any::<f32>().prop_map(|v| v.to_string()),
                    "[a-z#]{0,3}",
                ],
                0..11,
            ),
            0..6,
        ),
    ) {
        let text = lines.iter().map(|l| l.join(" ")).collect::<Vec<_>>().join("\n");
        if let Err(e) = parse_ground_truth_bytes(Path::new("g.txt"), text.as_bytes()) {
            prop_assert!(e.to_string().starts_with("g.txt:"));
        }
    }
}

#[test]
fn interpolation_follows_the_ssm() {
    let a = quad(0.0);
    let m = ssm::build("similitude").unwrap();
    let p = m
        .fit(
            &a.0,
            &a.map(|c| Point::new(2.0 * c.x + 10.0, 2.0 * c.y - 4.0)).0,
        )
        .unwrap();
    let b = ssm::warp_quad(&*m, &p, &a);
    let out = interpolate("similitude", (10, a), (14, b))
        .unwrap()
        .unwrap();
    assert_eq!(
        out.iter().map(|x| x.0).collect::<Vec<_>>(),
        vec![11, 12, 13]
    );
    // Halfway: scale 1.5 (linear in the similitude's parameters) and still a similitude of a.
    let mid = out[1].1;
    let side = |q: &Quad| q.0[0].dist(q.0[1]);
    assert!((side(&mid) / side(&a) - 1.5).abs() < 1e-9);
    let (_, _, r) = best_fit(&*m, &a, &mid).unwrap();
    assert!(r < 1e-9);
    // Given in reverse order, the same frames.
    let rev = interpolate("similitude", (14, b), (10, a))
        .unwrap()
        .unwrap();
    assert_eq!(rev, out);
}

/// An edit recorded under an SSM's alias (`"ssm":"8"`, written by hand or by another tool) is
/// restored under the SSM's own key, where the views show it (it was counted as restored and
/// shown nowhere).
#[test]
fn an_edit_under_an_ssm_alias_is_restored_where_it_is_shown() {
    let d = tmp("alias");
    let j = d.join("s_corrections.jsonl");
    {
        let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
        assert!(c.edit("a", &[set("homography", 2, 2.0)]).unwrap());
    }
    let text = std::fs::read_to_string(&j).unwrap();
    assert!(text.contains("\"ssm\":\"homography\""), "{text}");
    std::fs::write(&j, text.replace("\"ssm\":\"homography\"", "\"ssm\":\"8\"")).unwrap();
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!(rec.edits, 1);
    assert_eq!(
        c.mark("homography", 2),
        Some(Mark::Quad(quad(2.0).to_array()))
    );
    assert_eq!(c.corrected_frames("homography"), vec![2]);
    let _ = std::fs::remove_dir_all(&d);
}

/// One flipped byte in the header refused the whole journal: the intact edits after it are
/// kept, the damage said, and the journal goes on (a new header is written with the next edit).
#[test]
fn a_damaged_header_keeps_the_edits_after_it() {
    let d = tmp("header");
    let j = d.join("s_corrections.jsonl");
    {
        let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
        assert!(c.edit("a", &[set("homography", 2, 2.0)]).unwrap());
        assert!(c.edit("b", &[set("similitude", 3, 3.0)]).unwrap());
    }
    let mut bytes = std::fs::read(&j).unwrap();
    let at = bytes.iter().position(|&b| b == b':').unwrap();
    bytes[at] = b';';
    std::fs::write(&j, &bytes).unwrap();
    let (mut c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!(rec.edits, 2);
    assert!(
        rec.skipped
            .iter()
            .any(|s| s.contains(":1: the header is damaged")),
        "{:?}",
        rec.skipped
    );
    assert!(c.edit("c", &[set("homography", 4, 4.0)]).unwrap());
    drop(c);
    let (c, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!(rec.edits, 3);
    assert!(c.mark("similitude", 3).is_some() && c.mark("homography", 4).is_some());
    let _ = std::fs::remove_dir_all(&d);
}

/// A journal never grows past what its reader takes: the edit that would is refused (and takes
/// no effect), so every record in it can still be read back.
#[test]
fn a_full_journal_refuses_the_edit_that_would_make_it_unreadable() {
    let d = tmp("full");
    let j = d.join("s_corrections.jsonl");
    let (mut c, _) = Corrections::open(&j, "s", 10).unwrap();
    assert!(c.edit("a", &[set("similitude", 1, 1.0)]).unwrap());
    let len = std::fs::metadata(&j).unwrap().len();
    c.inject_faults(journal::Faults {
        limit: Some(len + 200),
        ..Default::default()
    });
    let mut made = 1;
    let err = loop {
        match c.edit("b", &[set("similitude", 2 + made % 5, made as f64)]) {
            Ok(_) => made += 1,
            Err(e) => break e.to_string(),
        }
    };
    assert!(
        err.contains("is full") && err.contains("s_corrections.jsonl"),
        "{err}"
    );
    assert!(std::fs::metadata(&j).unwrap().len() <= len + 200);
    drop(c);
    let (_, rec) = Corrections::open(&j, "s", 10).unwrap();
    assert_eq!((rec.edits, rec.damaged()), (made, false));
}
