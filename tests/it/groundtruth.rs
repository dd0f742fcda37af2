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
    let out = regtrack(&args);
    assert!(!String::from_utf8_lossy(&out.stdout).contains("already finished"));
}

/// Run by [`the_journal_survives_kill_9`] in a child process: makes edits forever, printing
/// each one's number once it is applied (so once its journal record is synced).
#[test]
#[ignore = "child process of the_journal_survives_kill_9"]
fn journal_child() {
    let Ok(path) = std::env::var("REGTRACK_JOURNAL_CHILD") else {
        return;
    };
    let (mut c, _) = Corrections::open(std::path::Path::new(&path), "kill", 1000).unwrap();
    for k in 0.. {
        let q = Quad::from_rect(k as f64, 2.0 * k as f64, 50.0, 40.0);
        let ssm = ["similitude", "homography", "translation"][k % 3];
        c.edit(
            &format!("edit {k}"),
            &[(ssm.into(), k % 1000, Some(Mark::Quad(q.to_array())))],
        )
        .unwrap();
        if k % 7 == 6 {
            c.undo().unwrap();
            println!("undo {k}");
        }
        println!("edit {k}");
    }
}

#[test]
fn the_journal_survives_kill_9() {
    use std::io::BufRead;
    let d = TempDir::new("kill9");
    let path = d.path().join("kill_corrections.jsonl");
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
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut acknowledged = Vec::new();
    for line in std::io::BufReader::new(stdout).lines() {
        let line = line.unwrap();
        if let Some(k) = line.strip_prefix("edit ") {
            acknowledged.push(k.parse::<usize>().unwrap());
            if acknowledged.len() == 40 {
                // SIGKILL: no destructor, no flush.
                child.kill().unwrap();
                break;
            }
        }
    }
    let _ = child.wait();
    assert_eq!(acknowledged.len(), 40, "the child did not make its edits");
    let (c, rec) = Corrections::open(&path, "kill", 1000).unwrap();
    // Every acknowledged edit is there (undone ones as undone); at most the edit in flight
    // when the process died is beyond them.
    for &k in &acknowledged {
        let ssm = gt::ssm_key(["similitude", "homography", "translation"][k % 3]).unwrap();
        let q = Quad::from_rect(k as f64, 2.0 * k as f64, 50.0, 40.0);
        let expect = (k % 7 != 6).then_some(Mark::Quad(q.to_array()));
        assert_eq!(c.mark(&ssm, k), expect, "edit {k}");
    }
    assert!(rec.edits >= 40 - 40 / 7 - 1, "{rec:?}");
}
