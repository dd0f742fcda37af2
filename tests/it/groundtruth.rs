//! Ground truth: `gt-fit` (OptGT and residuals against a known warp), `eval --gt-ssm`, error
//! types, resuming a batch, partial runs on a corrupt frame, and a corrections journal that
//! survives `kill -9`.

use crate::cli::{regtrack, succeed, synth};
use crate::common::{TempDir, write_png};
use regtrack::dataset::{Sequence, read_ground_truth};
use regtrack::geometry::{Point, Quad, alignment_error};
use regtrack::gt::{self, Corrections, Mark};
use regtrack::ssm;

/// An MTF dataset whose 8-DOF ground truth is a known similitude motion of the first quad,
/// except frame 5 (index 4), which has one corner pushed 6 px off (no similitude reaches it).
fn known_similitude_dataset(root: &std::path::Path) -> Vec<Quad> {
    let dir = root.join("known");
    std::fs::create_dir_all(&dir).unwrap();
    let base = Quad::from_rect(40.0, 30.0, 60.0, 40.0);
    let m = ssm::build("similitude").unwrap();
    let mut text = String::from("frame ulx uly urx ury lrx lry llx lly\n");
    let mut quads = Vec::new();
    for k in 0..8 {
        let (s, th) = (1.0 + 0.02 * k as f64, 0.03 * k as f64);
        let target = base.map(|c| {
            let (x, y) = (c.x - 70.0, c.y - 50.0);
            Point::new(
                s * (th.cos() * x - th.sin() * y) + 70.0 + 1.5 * k as f64,
                s * (th.sin() * x + th.cos() * y) + 50.0 - k as f64,
            )
        });
        let p = m.fit(&base.0, &target.0).unwrap();
        let mut q = ssm::warp_quad(&*m, &p, &base);
        if k == 4 {
            q.0[2].x += 6.0;
        }
        quads.push(q);
        let name = format!("frame{:05}.png", k + 1);
        write_png(&dir.join(&name), 160, 120, k as u8);
        let v: Vec<String> = q.to_array().iter().map(|v| format!("{v:.6}")).collect();
        text.push_str(&format!("{name} {}\n", v.join(" ")));
    }
    std::fs::write(root.join("known.txt"), text).unwrap();
    quads
}

#[test]
fn gt_fit_writes_opt_gt_with_residuals_against_a_known_warp() {
    let d = TempDir::new("gtfit");
    let quads = known_similitude_dataset(d.path());
    succeed(regtrack(&[
        "gt-fit",
        "--dataset",
        d.path().to_str().unwrap(),
        "--ssm",
        "similitude,translation",
    ]));
    let opt = d.path().join("OptGT/known_similitude.txt");
    let fitted = read_ground_truth(&opt).unwrap();
    assert_eq!(fitted.len(), 8);
    assert_eq!(fitted[0].frame.as_deref(), Some("frame00001.png"));
    let res =
        std::fs::read_to_string(d.path().join("OptGT/known_similitude_residuals.txt")).unwrap();
    let residuals: Vec<f64> = res
        .lines()
        .skip(1)
        .map(|l| l.split('\t').nth(1).unwrap().parse().unwrap())
        .collect();
    for (k, r) in residuals.iter().enumerate() {
        let q = fitted[k].quad.unwrap();
        // The exact similitude frames are reproduced; frame 5's residual is its E_AL to the fit,
        // and the fit is no worse than moving the pushed corner back (6 px / 4 corners).
        if k == 4 {
            assert!(*r > 0.5 && *r <= 1.5 + 1e-6, "frame 5 residual {r}");
            assert!((alignment_error(&q, &quads[k]) - r).abs() < 1e-3);
        } else {
            assert!(*r < 1e-3, "frame {} residual {r}", k + 1);
            assert!(alignment_error(&q, &quads[k]) < 1e-3);
        }
    }
    // The OptGT file opens as a sequence (its frames are the sequence's).
    let seq = Sequence::open(&opt).unwrap();
    assert_eq!(seq.name, "known");
    assert_eq!(seq.len(), 8);
    // Existing OptGT files are kept unless forced.
    let out = regtrack(&[
        "gt-fit",
        "--dataset",
        d.path().to_str().unwrap(),
        "--ssm",
        "similitude",
    ]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("kept"));
}

#[test]
fn eval_scores_against_low_dof_ground_truth_and_resumes() {
    let d = TempDir::new("gteval");
    let data = d.path().join("data");
    succeed(synth(
        "ucsb_bricks_zm.txt",
        &data,
        "zm",
        &["--frames", "12"],
    ));
    let out = d.path().join("res");
    let eval = |extra: &[&str]| {
        let mut a = vec![
            "eval",
            "--dataset",
            data.to_str().unwrap(),
            "--sm",
            "esm",
            "--am",
            "ssd",
            "--ssm",
            "translation",
            "--out",
            out.to_str().unwrap(),
        ];
        a.extend(extra);
        regtrack(&a)
    };
    // Against the full ground truth a translation tracker cannot follow a zoom; against the
    // translation ground truth (fitted: no OptGT yet) it can.
    succeed(eval(&["--no-resume"]));
    let full: Vec<regtrack::eval::RunResult> = regtrack::eval::read_runs(&out).unwrap();
    succeed(eval(&["--gt-ssm", "translation", "--no-resume"]));
    let low = regtrack::eval::read_runs(&out).unwrap();
    let mean = |r: &regtrack::eval::RunResult| {
        let e = r.errors();
        e.iter().sum::<f64>() / e.len() as f64
    };
    assert!(
        mean(&low[0]) < 0.5 * mean(&full[0]),
        "low-DOF {} vs full {}",
        mean(&low[0]),
        mean(&full[0])
    );
    assert_eq!(low[0].options.gt_ssm.as_deref(), Some("translation"));
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert!(
        csv.lines()
            .nth(1)
            .unwrap()
            .contains(",alignment,translation,"),
        "{csv}"
    );

    // Resuming: the finished run is read back, not redone (its file is untouched).
    let run_file = out.join("tracking_data/zm/esm_ssd_translation_run.json");
    let before = std::fs::metadata(&run_file).unwrap().modified().unwrap();
    let again = eval(&["--gt-ssm", "translation"]);
    succeed(again.clone());
    assert!(String::from_utf8_lossy(&again.stdout).contains("1 of 1 runs already finished"));
    assert_eq!(
        std::fs::metadata(&run_file).unwrap().modified().unwrap(),
        before
    );
    // Other options make it run again.
    let other = eval(&["--gt-ssm", "translation", "--error", "center"]);
    succeed(other.clone());
    assert!(!String::from_utf8_lossy(&other.stdout).contains("already finished"));
    // A resumed run is tied to its inputs: change the ground truth (shift it, cut it short)
    // and the run is made again, against the new one.
    succeed(eval(&[]));
    let gt_file = data.join("zm.txt");
    let text = std::fs::read_to_string(&gt_file).unwrap();
    let shifted: String = text
        .lines()
        .enumerate()
        .filter(|(i, _)| *i < 9)
        .map(|(i, l)| {
            if i == 0 {
                return format!("{l}\n");
            }
            let mut t: Vec<String> = l.split_whitespace().map(str::to_string).collect();
            for v in t.iter_mut().skip(1).step_by(2) {
                *v = format!("{:.4}", v.parse::<f64>().unwrap() + 30.0);
            }
            format!("{}\n", t.join(" "))
        })
        .collect();
    let before_shift = read_ground_truth(&gt_file).unwrap();
    std::fs::write(&gt_file, &shifted).unwrap();
    let redone = eval(&[]);
    assert!(
        !String::from_utf8_lossy(&redone.stdout).contains("already finished"),
        "{}",
        String::from_utf8_lossy(&redone.stdout)
    );
    let runs = regtrack::eval::read_runs(&out).unwrap();
    // The frames are the folder's 12 images; the last 4 have no line left (not annotated).
    assert_eq!(runs[0].frames.len(), 12, "every image of the folder");
    assert!(runs[0].frames[8..].iter().all(|f| f.ground_truth.is_none()));
    let last = runs[0].frames[..8].last().unwrap();
    let gt_x = last.ground_truth.unwrap().0[0].x;
    let was = before_shift[last.frame].quad.unwrap().0[0].x;
    assert!(
        (gt_x - was - 30.0).abs() < 1e-3,
        "scored against {gt_x}, the new ground truth is {was} + 30"
    );
    std::fs::write(&gt_file, text).unwrap();
    succeed(eval(&["--no-resume"]));
    // An OptGT file is read when present: shift it and the errors follow.
    succeed(regtrack(&[
        "gt-fit",
        "--dataset",
        data.to_str().unwrap(),
        "--ssm",
        "translation",
    ]));
    let opt = data.join("OptGT/zm_translation.txt");
    let shifted: String = std::fs::read_to_string(&opt)
        .unwrap()
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i < 2 {
                return format!("{l}\n");
            }
            let mut t: Vec<String> = l.split_whitespace().map(str::to_string).collect();
            for v in t.iter_mut().skip(1).step_by(2) {
                *v = format!("{:.4}", v.parse::<f64>().unwrap() + 30.0);
            }
            format!("{}\n", t.join(" "))
        })
        .collect();
    std::fs::write(&opt, shifted).unwrap();
    succeed(eval(&["--gt-ssm", "translation", "--no-resume"]));
    let shifted_run = regtrack::eval::read_runs(&out).unwrap();
    assert!(mean(&shifted_run[0]) > 25.0, "{}", mean(&shifted_run[0]));
    // Unknown error types are refused with the list.
    let bad = eval(&["--error", "psnr"]);
    assert!(String::from_utf8_lossy(&bad.stderr).contains("alignment, center, jaccard"));
}

#[test]
fn a_corrupt_frame_keeps_what_was_tracked() {
    let d = TempDir::new("corrupt");
    let data = d.path().join("data");
    succeed(synth(
        "ucsb_bricks_rt.txt",
        &data,
        "rt",
        &["--frames", "10"],
    ));
    let bad = data.join("rt/frame00006.jpg");
    std::fs::write(&bad, b"not a jpeg").unwrap();
    let corners = d.path().join("c.txt");
    let out = regtrack(&[
        "track",
        "--seq",
        data.join("rt.txt").to_str().unwrap(),
        "--out",
        corners.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("frame00006.jpg") && err.contains("frame 6"),
        "{err}"
    );
    let written = read_ground_truth(&corners).unwrap();
    assert_eq!(written.len(), 5, "the 5 frames before the corrupt one");
    assert!(written.iter().all(|e| e.quad.is_some()));
    // eval keeps the partial run, reports it, and a resumed batch runs it again.
    let res = d.path().join("res");
    let args = [
        "eval",
        "--dataset",
        data.to_str().unwrap(),
        "--out",
        res.to_str().unwrap(),
    ];
    let out = regtrack(&args);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("frame00006.jpg"));
    let runs = regtrack::eval::read_runs(&res).unwrap();
    assert_eq!(runs[0].frames.len(), 5);
    // The summary says the run is partial.
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("stopped"), "{stdout}");
    let csv = std::fs::read_to_string(res.join("summary.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "stopped").unwrap();
    let row: Vec<&str> = csv.lines().nth(1).unwrap().split(',').collect();
    assert_eq!(row[col], "1", "{csv}");
    let out = regtrack(&args);
    assert!(!String::from_utf8_lossy(&out.stdout).contains("already finished"));
}

/// The frames of the journal the kill test writes (one edit per frame, never reused).
const KILL_FRAMES: usize = 100_000;

/// The correction that edit `k` of the kill test makes: its SSM key and its mark.
fn kill_edit(k: usize) -> (&'static str, Mark) {
    let ssm = ["similitude", "homography", "translation"][k % 3];
    let q = Quad::from_rect((k % 500) as f64, 2.0 + (k % 300) as f64, 50.0, 40.0);
    (ssm, Mark::Quad(q.to_array()))
}

/// Run by [`the_journal_survives_200_kills_and_a_full_disk`] in a child process: makes edits
/// `from`, `from + 1`, ... forever (every 7th undone right after), printing each one's number
/// once it is applied (so once its journal record is synced). With `full:N` in
/// `REGTRACK_JOURNAL_FAULT` the disk holds only N more bytes: edits fail (`fail k`) until, after
/// three failures, space is freed and the failed edit is made again; with `pause` every record
/// waits 2 ms between its write and its sync, where the kills land.
#[test]
#[ignore = "child process of the_journal_survives_200_kills_and_a_full_disk"]
fn journal_child() {
    let Ok(path) = std::env::var("REGTRACK_JOURNAL_CHILD") else {
        return;
    };
    let path = std::path::Path::new(&path);
    let from: usize = std::env::var("REGTRACK_JOURNAL_FROM")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let fault = std::env::var("REGTRACK_JOURNAL_FAULT").unwrap_or_default();
    let (mut c, _) = Corrections::open(path, "kill", KILL_FRAMES).unwrap();
    let len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let mut faults = gt::journal::Faults::default();
    if let Some(n) = fault.strip_prefix("full:") {
        faults.capacity = Some(len + n.parse::<u64>().unwrap());
    } else if fault == "pause" {
        faults.pause_before_sync = std::time::Duration::from_millis(2);
    }
    c.inject_faults(faults);
    let mut failures = 0;
    let mut k = from;
    while k < KILL_FRAMES {
        let (ssm, mark) = kill_edit(k);
        match c.edit(&format!("edit {k}"), &[(ssm.into(), k, Some(mark))]) {
            Ok(_) => {}
            Err(e) => {
                assert!(e.to_string().contains("No space left"), "{e}");
                assert_eq!(
                    c.mark(&gt::ssm_key(ssm).unwrap(), k),
                    None,
                    "a failed edit took effect"
                );
                println!("fail {k}");
                failures += 1;
                if failures == 3 {
                    faults.capacity = None;
                    c.inject_faults(faults);
                }
                continue;
            }
        }
        while k % 7 == 6 && c.mark(&gt::ssm_key(ssm).unwrap(), k).is_some() {
            if let Err(e) = c.undo() {
                assert!(e.to_string().contains("No space left"), "{e}");
                println!("fail undo {k}");
                failures += 1;
                if failures == 3 {
                    faults.capacity = None;
                    c.inject_faults(faults);
                }
            }
        }
        println!("edit {k}");
        k += 1;
    }
}

#[test]
fn the_journal_survives_200_kills_and_a_full_disk() {
    use std::io::BufRead;
    let d = TempDir::new("kill9");
    let path = d.path().join("kill_corrections.jsonl");
    // Seeded: the same kills on every run.
    let mut rng = regtrack::rng::Rng::new(17);
    let mut acknowledged: Vec<usize> = Vec::new();
    let (mut failed, mut paused, mut starved) = (0, 0, 0);
    for kill in 0..200 {
        let from = acknowledged.last().map_or(0, |k| k + 1);
        let fault = match kill % 4 {
            1 => {
                starved += 1;
                format!("full:{}", rng.range(0.0, 400.0) as u64)
            }
            2 => {
                paused += 1;
                "pause".to_string()
            }
            _ => String::new(),
        };
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--ignored",
                "--exact",
                "groundtruth::journal_child",
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("REGTRACK_JOURNAL_CHILD", &path)
            .env("REGTRACK_JOURNAL_FROM", from.to_string())
            .env("REGTRACK_JOURNAL_FAULT", &fault)
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let wanted = rng.range(0.0, 12.0) as usize;
        let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
        let mut seen = 0;
        let note = |line: &str, acknowledged: &mut Vec<usize>, failed: &mut usize| {
            if let Some(k) = line.strip_prefix("edit ") {
                acknowledged.push(k.parse().unwrap());
            } else if line.starts_with("fail ") {
                *failed += 1;
            }
        };
        if wanted > 0 {
            for line in lines.by_ref() {
                let line = line.unwrap();
                note(&line, &mut acknowledged, &mut failed);
                seen += line.starts_with("edit ") as usize;
                if seen >= wanted {
                    break;
                }
            }
        }
        // Anywhere: in a write, between a write and its sync, between two records.
        std::thread::sleep(std::time::Duration::from_micros(
            rng.range(0.0, 3000.0) as u64
        ));
        // SIGKILL: no destructor, no flush.
        let _ = child.kill();
        for line in lines {
            note(&line.unwrap(), &mut acknowledged, &mut failed);
        }
        let _ = child.wait();
        let (c, rec) = Corrections::open(&path, "kill", KILL_FRAMES)
            .unwrap_or_else(|e| panic!("after kill {kill}: {e}"));
        assert!(
            rec.skipped.is_empty(),
            "after kill {kill}: {:?}",
            rec.skipped
        );
        // Every acknowledged edit is there (every 7th as undone).
        for &k in &acknowledged {
            let (ssm, mark) = kill_edit(k);
            let expect = (k % 7 != 6).then_some(mark);
            assert_eq!(
                c.mark(&gt::ssm_key(ssm).unwrap(), k),
                expect,
                "after kill {kill}: edit {k}"
            );
        }
    }
    println!(
        "200 kills: {} edits acknowledged and read back, {failed} refused by a full disk",
        acknowledged.len()
    );
    assert!(
        acknowledged.len() > 400,
        "{} edits acknowledged",
        acknowledged.len()
    );
    assert!(
        failed > 20 && starved == 50 && paused == 50,
        "{failed} failed edits"
    );
}

/// A frame corrected by hand has no fit residual: the correction is the annotator's word, and
/// against a wrong original it would point "jump to worst" at the fixed frame.
#[test]
fn a_corrected_frame_has_no_residual_against_the_original_it_fixed() {
    let d = TempDir::new("gt-residual");
    let quads = known_similitude_dataset(d.path());
    let seq = Sequence::open(&d.path().join("known.txt")).unwrap();
    let (mut c, _) = Corrections::open(&d.path().join("known.journal"), "known", 8).unwrap();
    let (_, before) = gt::ground_truth_in(&seq, &c, "similitude").unwrap();
    assert!(before[4].unwrap() > 1.0, "frame 5 is off: {:?}", before[4]);
    // Frame 5 corrected to where the similitude puts it (the original's pushed corner undone).
    let mut fixed = quads[4];
    fixed.0[2].x -= 6.0;
    c.edit(
        "fix frame 5",
        &[("similitude".into(), 4, Some(Mark::Quad(fixed.to_array())))],
    )
    .unwrap();
    let (frames, after) = gt::ground_truth_in(&seq, &c, "similitude").unwrap();
    assert_eq!(after[4], None);
    assert_eq!(frames[4].quad(), Some(fixed));
    for (k, r) in after.iter().enumerate().filter(|(k, _)| *k != 4) {
        assert!(r.unwrap() < 1e-3, "frame {}: {r:?}", k + 1);
    }
}

/// Propagating a correction stops where the old ground truth is right again: frames 9-12 of
/// a rendered sequence are 6 px off, frame 9 is corrected, and the proposal covers frames
/// 10-12 only, not the good frames after them.
#[test]
fn propagation_stops_where_the_old_ground_truth_is_right_again() {
    use regtrack::dataset::synth::{SynthConfig, render_sequence};
    let d = TempDir::new("gt-propagate");
    let a = crate::common::root().join("assets");
    let cfg = SynthConfig {
        texture: a.join("textures/skimage_coffee.png"),
        background: Some(a.join("textures/skimage_grass.png")),
        motion: a.join("motion/ucsb_bricks_rt.txt"),
        max_frames: Some(24),
        jpeg_quality: 0,
        ..SynthConfig::default()
    };
    let seq = render_sequence(&cfg, d.path(), "rt", &|_, _| {}).unwrap();
    let truth: Vec<Quad> = (0..seq.len())
        .map(|f| seq.ground_truth(f).unwrap())
        .collect();
    let old: Vec<Option<Quad>> = truth
        .iter()
        .enumerate()
        .map(|(f, q)| {
            Some(if (8..12).contains(&f) {
                q.map(|p| Point::new(p.x + 6.0, p.y))
            } else {
                *q
            })
        })
        .collect();
    let spec = regtrack::tracker::TrackerSpec::from_names("iclk", "zncc", "homography").unwrap();
    let p = gt::propagate(
        &seq,
        &spec,
        (8, truth[8]),
        &old,
        &|_| false,
        gt::PropagateLimits::default(),
    )
    .unwrap();
    let proposed: Vec<usize> = p.frames.iter().map(|(f, _)| *f).collect();
    assert_eq!(proposed, vec![9, 10, 11], "{}", p.stop);
    assert_eq!(p.stop, gt::PropagateStop::Agrees(12));
    for (f, q) in &p.frames {
        assert!(alignment_error(q, &truth[*f]) < 1.0, "frame {}", f + 1);
    }
}

/// Propagating over a selection on a brick wall moving 5 px a frame, in similitude, goes
/// through the selection: started cold, the tracker has no motion to predict, and its search
/// from the last pose settled a brick off on the second frame ("proposal for 1 frame(s); the
/// tracker lost the target at frame 63"); the old ground truth's motion gives the start of the
/// first frame and of a frame the tracker lost.
#[test]
fn propagation_over_a_moving_brick_wall_goes_through_the_selection() {
    use regtrack::dataset::synth::{SynthConfig, render_sequence};
    let d = TempDir::new("gt-propagate-bricks");
    let a = crate::common::root().join("assets");
    let cfg = SynthConfig {
        texture: a.join("textures/skimage_brick.png"),
        background: Some(a.join("textures/skimage_grass.png")),
        motion: a.join("motion/ucsb_bricks_m1.txt"),
        max_frames: Some(76),
        // JPEG frames, as the bundled renders (the PNG ones did not show it).
        jpeg_quality: 95,
        ..SynthConfig::default()
    };
    let seq = render_sequence(&cfg, d.path(), "bricks", &|_, _| {}).unwrap();
    let c = Corrections::in_memory(seq.len());
    let (frames, _) = gt::ground_truth_in(&seq, &c, "similitude").unwrap();
    let old: Vec<Option<Quad>> = frames.iter().map(|g| g.quad()).collect();
    let spec = regtrack::tracker::TrackerSpec::from_names("fclk", "ssd", "similitude").unwrap();
    let limits = gt::PropagateLimits {
        max_frames: 15,
        agree_frames: 0,
        ..Default::default()
    };
    // Selections starting every fourth frame.
    for from in (0..=60).step_by(4) {
        let p = gt::propagate(
            &seq,
            &spec,
            (from, old[from].unwrap()),
            &old,
            &|_| false,
            limits,
        )
        .unwrap();
        assert_eq!(
            p.stop,
            gt::PropagateStop::End,
            "from frame {}: {}",
            from + 1,
            p.stop
        );
        assert_eq!(p.frames.len(), 15);
        for (f, q) in &p.frames {
            let e = alignment_error(q, &old[*f].unwrap());
            assert!(
                e < 1.0,
                "from frame {}, frame {}: {e:.2} px",
                from + 1,
                f + 1
            );
        }
    }
}

/// `eval --gt-ssm own` scores the three parameterisations of the homography (and the non-rigid
/// SSMs) against the same ground truth: a corrected export, `OptGT/<seq>_homography.txt`, is
/// read for every one of them (it was read for `homography` alone, `sl3` and `corner` scoring
/// against the sequence's own under the same label).
#[test]
fn every_8_dof_ssm_reads_the_corrected_homography_export() {
    let d = TempDir::new("optgt8");
    let gt_file = crate::common::tiny_sequence(d.path(), 4);
    let export = "12 10 42 10 42 30 12 30\n".repeat(4);
    std::fs::create_dir_all(d.path().join("OptGT")).unwrap();
    let opt = d.path().join("OptGT/s_homography.txt");
    std::fs::write(&opt, export).unwrap();
    let seq = Sequence::open(&gt_file).unwrap();
    for name in ["homography", "sl3", "corner", "spline", "tps5"] {
        let low = gt::low_dof_ground_truth(&seq, name).unwrap();
        assert_eq!(low.path.as_deref(), Some(opt.as_path()), "{name}");
        assert_eq!(low.quads[1].unwrap().0[0].x, 12.0, "{name}");
    }
    // A low-DOF SSM reads its own file (none here: fitted from the sequence's).
    let low = gt::low_dof_ground_truth(&seq, "similitude").unwrap();
    assert_eq!(low.path, None);
}

/// Two inspectors with the same sequence open (its exported ground truth opens under the same
/// name, so with the same journal): the second's edits are refused, with the reason, while the
/// first writes, and after it (its replay missed the first's edits, and its ids would repeat
/// them); reopened, it continues from both. Nothing of the first's is lost or cut.
#[test]
fn a_second_writer_of_a_journal_is_refused_until_it_reopens() {
    let d = TempDir::new("two-writers");
    let path = d.path().join("s_corrections.jsonl");
    let q = |x: f64| Some(Mark::Quad(Quad::from_rect(x, 10.0, 50.0, 40.0).to_array()));
    let (mut a, _) = Corrections::open(&path, "s", 20).unwrap();
    let (mut b, _) = Corrections::open(&path, "s", 20).unwrap();
    a.edit("a 3", &[("homography".into(), 3, q(3.0))]).unwrap();
    let err = b
        .edit("b 7", &[("homography".into(), 7, q(7.0))])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("another regtrack is writing") && err.contains("s_corrections.jsonl"),
        "{err}"
    );
    assert_eq!(
        b.mark("homography", 7),
        None,
        "a refused edit took no effect"
    );
    a.edit("a 4", &[("homography".into(), 4, q(4.0))]).unwrap();
    let written = std::fs::read(&path).unwrap();
    drop(a);
    let err = b
        .edit("b 7", &[("homography".into(), 7, q(7.0))])
        .unwrap_err()
        .to_string();
    assert!(err.contains("written by another regtrack since"), "{err}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        written,
        "nothing cut or added"
    );
    drop(b);
    let (mut b, rec) = Corrections::open(&path, "s", 20).unwrap();
    assert_eq!(rec.edits, 2);
    b.edit("b 7", &[("homography".into(), 7, q(7.0))]).unwrap();
    b.undo().unwrap();
    b.undo().unwrap();
    drop(b);
    let (c, rec) = Corrections::open(&path, "s", 20).unwrap();
    assert!(rec.skipped.is_empty(), "{:?}", rec.skipped);
    assert_eq!(rec.edits, 1);
    assert!(c.mark("homography", 3).is_some());
    assert_eq!(
        (c.mark("homography", 4), c.mark("homography", 7)),
        (None, None)
    );
}

/// An export that replaces a file no export of the journal wrote (a dataset's own OptGT file)
/// keeps a copy of it first; its own earlier exports it replaces freely, after a reopen too.
#[test]
fn an_export_keeps_what_it_replaces_that_it_did_not_write() {
    let d = TempDir::new("export-keeps");
    let gt_file = crate::common::tiny_sequence(d.path(), 4);
    std::fs::create_dir_all(d.path().join("OptGT")).unwrap();
    let shipped = d.path().join("OptGT/s_similitude.txt");
    let original = "11 10 41 10 41 30 11 30\n".repeat(4);
    std::fs::write(&shipped, &original).unwrap();
    let seq = Sequence::open(&gt_file).unwrap();
    let journal = gt::journal_path(&seq);
    let (mut c, _) = Corrections::open(&journal, "s", 4).unwrap();
    let q = Quad::from_rect(12.0, 10.0, 30.0, 20.0);
    c.edit(
        "move",
        &[("similitude".into(), 2, Some(Mark::Quad(q.to_array())))],
    )
    .unwrap();
    let paths = gt::export(&seq, &mut c, "similitude").unwrap();
    let kept = d.path().join("OptGT/s_similitude.txt.orig");
    assert!(paths.contains(&kept), "{paths:?}");
    assert_eq!(std::fs::read_to_string(&kept).unwrap(), original);
    assert_ne!(std::fs::read_to_string(&shipped).unwrap(), original);
    // Its own export, replaced again: nothing more kept, now or after a reopen.
    assert_eq!(gt::export(&seq, &mut c, "similitude").unwrap().len(), 3);
    drop(c);
    let (mut c, _) = Corrections::open(&journal, "s", 4).unwrap();
    assert_eq!(gt::export(&seq, &mut c, "similitude").unwrap().len(), 3);
    assert!(!d.path().join("OptGT/s_similitude.txt.orig2").exists());
}

/// A folder whose frames' names hold spaces, annotated from scratch: its export opens again,
/// with its corrections on the right frames (the names, which a line cannot hold, were replaced
/// by made-up ones that named no frame).
#[test]
fn an_export_of_frames_named_with_spaces_opens_again() {
    let d = TempDir::new("spaces");
    let folder = d.path().join("my seq");
    std::fs::create_dir_all(&folder).unwrap();
    for i in 1..=4 {
        write_png(&folder.join(format!("shot {i}.png")), 60, 40, 10 * i as u8);
    }
    let seq = Sequence::open(&folder).unwrap();
    let (mut c, _) = Corrections::open(&gt::journal_path(&seq), &seq.name, 4).unwrap();
    let q = Quad::from_rect(12.0, 10.0, 30.0, 20.0);
    c.edit(
        "mark",
        &[("homography".into(), 2, Some(Mark::Quad(q.to_array())))],
    )
    .unwrap();
    let paths = gt::export(&seq, &mut c, "homography").unwrap();
    let again = Sequence::open(&paths[0]).unwrap();
    assert_eq!(again.len(), 4);
    assert_eq!(again.frames[2].file_name().unwrap(), "shot 3.png");
    assert!(alignment_error(&again.ground_truth(2).unwrap(), &q) < 1e-3);
    assert!(again.ground_truth(1).is_none());
}
