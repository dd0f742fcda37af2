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
fn a_malformed_journal_names_the_file_and_line() {
    let d = tmp("bad");
    let j = d.join("s_corrections.jsonl");
    let header = "{\"kind\":\"header\",\"format\":1,\"sequence\":\"s\"}\n";
    for (body, line, what) in [
        ("{\"kind\":\"edit\",\"id\":1}\n", 2, "not a journal record"),
        (
            "garbage\n{\"kind\":\"undo\",\"id\":1}\n",
            2,
            "not a journal",
        ),
        ("{\"kind\":\"undo\",\"id\":4}\n", 2, "not the last edit"),
        (
            "{\"kind\":\"edit\",\"id\":1,\"label\":\"x\",\"changes\":[{\"ssm\":\"affine\",\"frame\":99,\"before\":null,\"after\":\"occluded\"}]}\n",
            2,
            "beyond",
        ),
        (
            "{\"kind\":\"edit\",\"id\":1,\"label\":\"x\",\"changes\":[{\"ssm\":\"warp9\",\"frame\":1,\"before\":null,\"after\":\"occluded\"}]}\n",
            2,
            "warp9",
        ),
    ] {
        std::fs::write(&j, format!("{header}{body}")).unwrap();
        let e = Corrections::open(&j, "s", 10).unwrap_err().to_string();
        assert!(
            e.contains(&format!("s_corrections.jsonl:{line}")) && e.contains(what),
            "{body}: {e}"
        );
    }
    std::fs::write(&j, "{\"kind\":\"undo\",\"id\":1}\n").unwrap();
    let e = Corrections::open(&j, "s", 10).unwrap_err().to_string();
    assert!(e.contains(":1") && e.contains("header"), "{e}");
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
