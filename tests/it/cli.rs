//! The command line: list, synth, track and eval end to end, and clear errors.

use crate::common::{TempDir, root};
use std::process::Command;

pub(crate) fn regtrack(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_regtrack"))
        .args(args)
        .output()
        .expect("run regtrack")
}

/// Checks that a command succeeded, showing its error output otherwise.
pub(crate) fn succeed(out: std::process::Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `regtrack synth` of the bundled coffee texture on a bundled motion profile.
pub(crate) fn synth(
    motion: &str,
    out: &std::path::Path,
    name: &str,
    extra: &[&str],
) -> std::process::Output {
    let tex = root().join("assets/textures/skimage_coffee.png");
    let motion = root().join("assets/motion").join(motion);
    let mut args = vec![
        "synth",
        "--texture",
        tex.to_str().unwrap(),
        "--motion",
        motion.to_str().unwrap(),
    ];
    args.extend(["--out", out.to_str().unwrap(), "--name", name]);
    args.extend(extra);
    regtrack(&args)
}

#[test]
fn list_shows_every_method_with_aliases() {
    let out = regtrack(&["list"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for e in regtrack::am::REGISTRY
        .iter()
        .map(|e| e.name)
        .chain(regtrack::ssm::REGISTRY.iter().map(|e| e.name))
        .chain(regtrack::sm::REGISTRY.iter().map(|e| e.name))
    {
        assert!(
            text.lines().any(|l| l.trim_start().starts_with(e)),
            "{e} missing from:\n{text}"
        );
    }
    assert!(text.contains("[ic]") && text.contains("[c8"), "{text}");
}

#[test]
fn synth_track_and_eval_end_to_end() {
    let d = TempDir::new("cli");
    let data = d.path().join("data");
    succeed(synth(
        "ucsb_bricks_rt.txt",
        &data,
        "rt",
        &["--frames", "12", "--noise", "1"],
    ));
    assert!(data.join("rt/frame00012.jpg").is_file());

    let corners = d.path().join("rt_corners.txt");
    succeed(regtrack(&[
        "track",
        "--seq",
        data.join("rt.txt").to_str().unwrap(),
        "--sm",
        "ic",
        "--am",
        "zncc",
        "--ssm",
        "8",
        "--out",
        corners.to_str().unwrap(),
    ]));
    let text = std::fs::read_to_string(&corners).unwrap();
    assert_eq!(text.lines().count(), 13, "header + 12 frames");

    let res = d.path().join("res");
    let out = regtrack(&[
        "eval",
        "--dataset",
        data.to_str().unwrap(),
        "--sm",
        "esm,fclk",
        "--am",
        "ssd",
        "--ssm",
        "homography,affine",
        "--out",
        res.to_str().unwrap(),
        "--jobs",
        "2",
    ]);
    // Not on a terminal (a cluster job's log): a line a finished run, where the bar is hidden.
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("run ")).collect();
    assert_eq!(lines.len(), 4, "{err}");
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("run 4 of 4: ") && l.contains(" on rt: 12 frames, SR@5 ")),
        "{err}"
    );
    succeed(out);
    let csv = std::fs::read_to_string(res.join("summary.csv")).unwrap();
    assert_eq!(csv.lines().count(), 5, "{csv}");
    assert!(
        res.join("tracking_data/rt/fclk_ssd_affine_errors.txt")
            .is_file()
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 4);

    // Shards of a two-sequence evaluation merge into the summary of the whole.
    succeed(synth(
        "ucsb_bricks_zm.txt",
        &data,
        "zm",
        &["--frames", "10"],
    ));
    let whole = d.path().join("whole");
    let args = |out: &std::path::Path| -> Vec<String> {
        [
            "eval",
            "--dataset",
            data.to_str().unwrap(),
            "--sm",
            "esm,iclk",
            "--am",
            "zncc",
            "--jobs",
            "1",
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let run = |a: Vec<String>| {
        let o = Command::new(env!("CARGO_BIN_EXE_regtrack"))
            .args(&a)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(args(&whole));
    let mut shards = Vec::new();
    for k in 0..3 {
        let dir = d.path().join(format!("part{k}"));
        let mut a = args(&dir);
        a.extend(["--shard".to_string(), format!("{k}/3")]);
        run(a);
        shards.push(dir);
    }
    let merged = d.path().join("merged");
    let mut a = vec![
        "merge".to_string(),
        "--out".to_string(),
        merged.to_str().unwrap().to_string(),
    ];
    a.extend(shards.iter().map(|p| p.to_str().unwrap().to_string()));
    run(a);
    let rows = |p: &std::path::Path| -> Vec<(String, String, u64, f64)> {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(p.join("summary.json")).unwrap())
                .unwrap();
        let mut r: Vec<_> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                (
                    r["sequence"].as_str().unwrap().to_string(),
                    r["sm"].as_str().unwrap().to_string(),
                    r["frames"].as_u64().unwrap(),
                    r["mean_sr"].as_f64().unwrap(),
                )
            })
            .collect();
        r.sort_by(|a, b| (&a.0, &a.1).cmp(&(&b.0, &b.1)));
        r
    };
    let (w, m) = (rows(&whole), rows(&merged));
    assert_eq!(w.len(), 6, "4 runs and 2 pooled rows: {w:?}");
    assert_eq!(w, m);
    assert!(w.iter().any(|r| r.0 == "ALL" && r.2 == 20));

    // Each shard knows the whole evaluation (its eval-plan.json): a set with a shard missing,
    // a shard given twice, a shard of another evaluation or a shard cut short is refused,
    // naming what is missing; `--partial` merges it labelled.
    let merge_of = |dirs: &[&std::path::Path], extra: &[&str]| {
        let out = d.path().join("merged2");
        let mut a: Vec<String> = vec!["merge".into(), "--out".into(), out.display().to_string()];
        a.extend(dirs.iter().map(|p| p.display().to_string()));
        a.extend(extra.iter().map(|s| s.to_string()));
        let o = Command::new(env!("CARGO_BIN_EXE_regtrack"))
            .args(&a)
            .output()
            .unwrap();
        (o, out)
    };
    let text = |o: &std::process::Output| {
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    };
    let (o, _) = merge_of(&[&shards[0], &shards[1]], &[]);
    assert!(!o.status.success());
    let msg = text(&o);
    assert!(
        msg.contains("incomplete evaluation")
            && msg.contains("shard 2/3 missing")
            && msg.contains("1 of 4 runs missing")
            && msg.contains("--partial")
            && !msg.contains("panicked"),
        "{msg}"
    );
    let (o, out) = merge_of(&[&shards[0], &shards[1]], &["--partial"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("PARTIAL"), "{}", text(&o));
    let partial = rows(&out);
    assert!(partial.iter().any(|r| r.0 == "ALL-partial"), "{partial:?}");
    assert!(!partial.iter().any(|r| r.0 == "ALL"), "{partial:?}");
    assert!(out.join("PARTIAL.txt").is_file());
    // ... and the report of that set, refused, then labelled.
    let report_of = |extra: &[&str]| {
        let mut a: Vec<String> = vec!["report".into()];
        a.extend(
            [&shards[0], &shards[1]]
                .iter()
                .map(|p| p.display().to_string()),
        );
        a.extend(["--out".into(), d.path().join("rep").display().to_string()]);
        a.extend(extra.iter().map(|s| s.to_string()));
        Command::new(env!("CARGO_BIN_EXE_regtrack"))
            .args(&a)
            .output()
            .unwrap()
    };
    let o = report_of(&[]);
    assert!(
        !o.status.success() && text(&o).contains("shard 2/3 missing"),
        "{}",
        text(&o)
    );
    succeed(report_of(&["--partial"]));
    let md = std::fs::read_to_string(d.path().join("rep/report.md")).unwrap();
    assert!(
        md.contains("**Partial result**") && md.contains("(partial)"),
        "{md}"
    );
    // The same shard twice.
    let (o, _) = merge_of(&[&shards[0], &shards[1], &shards[1]], &[]);
    assert!(
        !o.status.success() && text(&o).contains("given twice"),
        "{}",
        text(&o)
    );
    // A shard of another evaluation (other trackers).
    let other = d.path().join("other");
    let mut a = args(&other);
    a[4] = "fclk".into();
    a.extend(["--shard".to_string(), "2/3".to_string()]);
    run(a);
    let (o, _) = merge_of(&[&shards[0], &shards[1], &other], &[]);
    assert!(
        !o.status.success() && text(&o).contains("different evaluations"),
        "{}",
        text(&o)
    );
    // A shard cut short (a task cancelled after some runs: one run's file missing) is named;
    // the task submitted again resumes and the set is whole again.
    let cut = std::fs::read_dir(shards[1].join("tracking_data"))
        .unwrap()
        .flat_map(|e| std::fs::read_dir(e.unwrap().path()).unwrap())
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().ends_with("_run.json"))
        .unwrap();
    std::fs::remove_file(&cut).unwrap();
    let (o, _) = merge_of(&[&shards[0], &shards[1], &shards[2]], &[]);
    assert!(
        !o.status.success() && text(&o).contains("1 of 4 runs missing"),
        "{}",
        text(&o)
    );
    let mut a = args(&shards[1]);
    a.extend(["--shard".to_string(), "1/3".to_string()]);
    run(a);
    let (o, out) = merge_of(&[&shards[0], &shards[1], &shards[2]], &[]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(rows(&out), w);
    assert!(!out.join("PARTIAL.txt").exists());

    // A shard runs only its share.
    let shard = d.path().join("shard");
    succeed(regtrack(&[
        "eval",
        "--dataset",
        data.to_str().unwrap(),
        "--sm",
        "esm,fclk",
        "--am",
        "ssd",
        "--out",
        shard.to_str().unwrap(),
        "--shard",
        "1/2",
    ]));
    let csv = std::fs::read_to_string(shard.join("summary.csv")).unwrap();
    assert_eq!(
        csv.lines().count(),
        4,
        "runs 1 and 3 of 4, and their pooled row: {csv}"
    );
    assert!(!csv.contains(",esm,"));
    assert!(csv.contains(",fclk,"));
}

#[test]
fn errors_are_clear() {
    let out = regtrack(&[
        "track",
        "--seq",
        "/nonexistent/seq.txt",
        "--out",
        "/tmp/x.txt",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/seq.txt"), "{err}");
    let out = regtrack(&["eval", "--dataset", "/tmp", "--sm", "gd", "--out", "/tmp/x"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("unknown search method 'gd'") && err.contains("esm"),
        "{err}"
    );
    // Parameters: unknown names list the known ones, values out of range name the range.
    let bad = |args: &[&str]| {
        let mut all = vec!["eval", "--dataset", "/tmp", "--out", "/tmp/x"];
        all.extend_from_slice(args);
        let out = regtrack(&all);
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let err = bad(&["--sm", "nn", "--param", "particles=5"]);
    assert!(
        err.contains("'particles'") && err.contains("samples"),
        "{err}"
    );
    let err = bad(&["--sm", "nn", "--param", "samples=3"]);
    assert!(
        err.contains("samples") && err.contains("10..=100000"),
        "{err}"
    );
    let err = bad(&["--hessian", "exact"]);
    assert!(err.contains("gauss_newton"), "{err}");
    let err = bad(&["--roi-margin=-1"]);
    assert!(err.contains("roi_margin"), "{err}");
    let err = bad(&["--sm", "cascade:nn"]);
    assert!(err.contains("at least two stages"), "{err}");
    // Impossible sizes are refused, not rendered (or looped on).
    let tex = root().join("assets/textures/skimage_coffee.png");
    let never = std::path::Path::new("/tmp/regtrack-never");
    let out = synth(
        "ucsb_bricks_rt.txt",
        never,
        "x",
        &["--background", tex.to_str().unwrap(), "--size", "0x0"],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("16..=8192"));
}

/// Bad input gets one clear message naming what is wrong (issue 18): the documented `--init`
/// form, a quad outside the frame, unusable and duplicated ground-truth lines, a malformed
/// ground-truth file in a dataset, and no backtrace for a user error even under RUST_BACKTRACE.
#[test]
fn bad_input_gets_one_clear_message() {
    let d = TempDir::new("badin");
    let data = d.path().join("data");
    succeed(synth("ucsb_bricks_rt.txt", &data, "rt", &["--frames", "6"]));
    let gt = data.join("rt.txt");
    let text = std::fs::read_to_string(&gt).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let first: Vec<f64> = lines[1]
        .split_whitespace()
        .skip(1)
        .map(|t| t.parse().unwrap())
        .collect();
    let corners: Vec<String> = first.iter().map(|v| v.to_string()).collect();
    let out = d.path().join("c.txt");
    let track = |init: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_regtrack"))
            .args(["track", "--seq", gt.to_str().unwrap(), "--out"])
            .arg(&out)
            .args(["--init", init])
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    // The documented comma-separated form.
    let (ok, err) = track(&corners.join(","));
    assert!(ok, "{err}");
    // Wholly outside the frame: said so, in one line, without a backtrace.
    let (ok, err) = track("-500,-500,-400,-500,-400,-400,-500,-400");
    assert!(!ok && err.contains("lies outside the"), "{err}");
    assert!(
        !err.contains("backtrace") && err.trim().lines().count() == 1,
        "{err}"
    );
    // A folded quad on a later frame is read as not annotated, with a warning naming the line;
    // a frame listed twice is an error naming both lines.
    let mut bad: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    let name3 = bad[3].split_whitespace().next().unwrap().to_string();
    bad[3] = format!("{name3} 10 10 50 50 50 10 10 50");
    std::fs::write(&gt, bad.join("\n") + "\n").unwrap();
    let (ok, err) = track(&corners.join(","));
    assert!(
        ok && err.contains("rt.txt:4: ") && err.contains("not annotated"),
        "{err}"
    );
    let mut dup = bad.clone();
    dup[4] = dup[2].clone();
    std::fs::write(&gt, dup.join("\n") + "\n").unwrap();
    let (ok, err) = track(&corners.join(","));
    assert!(
        !ok && err.contains("rt.txt:5: ") && err.contains("listed twice (also on line 3)"),
        "{err}"
    );
    // gt-fit: an unusable first quad is refused; a malformed file in a dataset is named.
    let mut first_bad = lines.iter().map(|l| l.to_string()).collect::<Vec<_>>();
    let name1 = first_bad[1].split_whitespace().next().unwrap().to_string();
    first_bad[1] = format!("{name1} 5 5 5 5 5 5 5 5");
    std::fs::write(&gt, first_bad.join("\n") + "\n").unwrap();
    let fit = regtrack(&[
        "gt-fit",
        "--dataset",
        data.to_str().unwrap(),
        "--ssm",
        "translation",
    ]);
    let err = String::from_utf8_lossy(&fit.stderr);
    assert!(
        !fit.status.success() && err.contains("first frame") && err.contains("rt.txt:2"),
        "{err}"
    );
    let mut malformed = lines.iter().map(|l| l.to_string()).collect::<Vec<_>>();
    malformed[4] = format!(
        "{} 1.2.3 0 0 0 0 0 0 0",
        malformed[4].split_whitespace().next().unwrap()
    );
    std::fs::write(&gt, malformed.join("\n") + "\n").unwrap();
    let fit = regtrack(&[
        "gt-fit",
        "--dataset",
        data.to_str().unwrap(),
        "--ssm",
        "translation",
    ]);
    let err = String::from_utf8_lossy(&fit.stderr);
    assert!(
        !fit.status.success() && err.contains("rt.txt:5: '1.2.3' is not a number"),
        "{err}"
    );
}

/// Frames that cannot be tracked as they are, and parameters that cannot work together, are
/// named in one message (issue 18): a frame of another size, a JPEG cut short, an image too
/// large to decode (grey or colour alike), NN samples that would not fit in memory, `--sm` with
/// a whole tracker, and a path that is neither a file nor a folder.
#[test]
fn bad_frames_and_parameters_get_one_clear_message() {
    let d = TempDir::new("badframes");
    let data = d.path().join("data");
    succeed(synth("ucsb_bricks_rt.txt", &data, "rt", &["--frames", "6"]));
    let gt = data.join("rt.txt");
    let out = d.path().join("c.txt");
    let track = |extra: &[&str]| {
        let o = regtrack(
            &[
                &[
                    "track",
                    "--seq",
                    gt.to_str().unwrap(),
                    "--out",
                    out.to_str().unwrap(),
                ],
                extra,
            ]
            .concat(),
        );
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let frame = |k: usize| data.join(format!("rt/frame{k:05}.jpg"));
    let original = std::fs::read(frame(1)).unwrap();
    // A JPEG cut short as the first frame.
    std::fs::write(frame(1), &original[..original.len() / 2]).unwrap();
    let (ok, err) = track(&[]);
    assert!(
        !ok && err.contains("frame00001.jpg") && err.contains("cut short"),
        "{err}"
    );
    std::fs::write(frame(1), &original).unwrap();
    // A frame of another size.
    let small = image::GrayImage::from_fn(64, 48, |x, y| image::Luma([(x * 5 + y * 3) as u8]));
    small
        .save_with_format(frame(4), image::ImageFormat::Jpeg)
        .unwrap();
    let (ok, err) = track(&[]);
    assert!(
        !ok && err.contains("frame00004.jpg")
            && err.contains("frame 4 is 64x48, but the sequence's first frame is"),
        "{err}"
    );
    // Too large to decode, grey and colour alike: refused from the header, before decoding.
    for (magic, what) in [("P5", "grey"), ("P6", "colour")] {
        let big = d.path().join(format!("big_{what}.pgm"));
        std::fs::write(&big, format!("{magic}\n20000 20000\n255\n")).unwrap();
        let e = regtrack::imaging::load_gray(&big).unwrap_err().to_string();
        assert!(
            e.contains("20000x20000 is more than the 64 megapixels"),
            "{what}: {e}"
        );
    }
    // NN's samples times the grid: refused with what it would need, not an abort.
    let (ok, err) = track(&["--sm", "nn", "--param", "samples=100000", "--res", "1000"]);
    assert!(
        !ok && err.contains("400.0 GB") && err.contains("lower samples or res"),
        "{err}"
    );
    // Numbers in messages stay short; a negative value is a value, not a flag.
    let (ok, err) = track(&["--eps", "1e308"]);
    assert!(
        !ok && err.contains("got 1.000e308") && err.len() < 300,
        "{err}"
    );
    let (ok, err) = track(&["--eps", "-1"]);
    assert!(
        !ok && err.contains("eps must be a number in 0..=1000, got -1"),
        "{err}"
    );
    // --sm means nothing to a whole tracker.
    let (ok, err) = track(&["--tracker", "kcf", "--sm", "iclk"]);
    assert!(!ok && err.contains("cannot be used with"), "{err}");
    // Not a file, not a folder.
    let o = regtrack(&[
        "track",
        "--seq",
        "/dev/null",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("neither a ground-truth file nor a folder"),
        "{err}"
    );
}

/// A killed batch's half-written files are removed by the next batch into the folder; a live
/// process's are kept.
#[test]
fn stale_temporaries_of_a_killed_batch_are_removed() {
    let d = TempDir::new("stale");
    let sub = d.path().join("tracking_data/s");
    std::fs::create_dir_all(&sub).unwrap();
    // A process id that is not running (beyond Linux's pid_max), and this process's own.
    let host = regtrack::dataset::host_name();
    let dead = sub.join(".esm_ssd_homography_run.json.tmp4194999");
    let dead_here = sub.join(format!(".y.txt.tmp4194998@{host}"));
    let live = sub.join(format!(".x.txt.tmp{}@{host}", std::process::id()));
    // Another node's job on a shared file system: its pid means nothing here, its file stays.
    let elsewhere = sub.join(".z.txt.tmp4194997@another-node");
    let other = sub.join("notes.tmp123");
    for p in [&dead, &dead_here, &live, &elsewhere, &other] {
        std::fs::write(p, b"partial").unwrap();
    }
    assert_eq!(regtrack::dataset::remove_stale_temporaries(d.path()), 2);
    assert!(!dead.exists() && !dead_here.exists());
    assert!(live.exists() && elsewhere.exists() && other.exists());
}

/// Two batches into one --out: the second is refused while the first holds the folder's lock,
/// naming its host and pid; a lock whose process is gone is taken over, and a finished batch
/// leaves no lock.
#[test]
fn a_second_batch_into_a_held_folder_is_refused_and_a_stale_lock_taken_over() {
    let d = TempDir::new("lock");
    let data = d.path().join("data");
    succeed(synth("ucsb_bricks_rt.txt", &data, "rt", &["--frames", "6"]));
    let out = d.path().join("res");
    let eval = |out: &std::path::Path| {
        regtrack(&[
            "eval",
            "--dataset",
            data.to_str().unwrap(),
            "--sm",
            "fclk",
            "--am",
            "ssd",
            "--out",
            out.to_str().unwrap(),
        ])
    };
    // Held by a live process of this host (this test's own).
    std::fs::create_dir_all(&out).unwrap();
    let lock = out.join(".regtrack-eval.lock");
    let host = regtrack::dataset::host_name();
    std::fs::write(
        &lock,
        format!("host {host}\npid {}\nstarted 0\n", std::process::id()),
    )
    .unwrap();
    let o = eval(&out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("another evaluation writes into this folder")
            && err.contains(&format!("pid {} on host {host}", std::process::id())),
        "{err}"
    );
    assert!(!out.join("summary.csv").exists());
    // Its process gone: taken over, and removed at the end.
    std::fs::write(&lock, format!("host {host}\npid 4194999\nstarted 0\n")).unwrap();
    succeed(eval(&out));
    assert!(out.join("summary.csv").is_file() && !lock.exists());
}
