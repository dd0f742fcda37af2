//! Issue 44's adversarial inputs: special files where a file is read, sizes that would
//! abort, ground truth that would silently misalign. Each test fails without its fix.

use crate::common::TempDir;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Runs `read` on another thread and returns its error message; a read that blocks (a FIFO)
/// or runs out of memory (`/dev/zero`) fails the test after 20 s instead of hanging it.
fn refused<T: Send + 'static>(
    what: &str,
    path: &Path,
    read: impl FnOnce(PathBuf) -> regtrack::Result<T> + Send + 'static,
) -> String {
    let (tx, rx) = std::sync::mpsc::channel();
    let p = path.to_path_buf();
    std::thread::spawn(move || {
        let _ = tx.send(read(p).err().map(|e| e.to_string()));
    });
    match rx.recv_timeout(Duration::from_secs(20)) {
        Ok(Some(e)) => e,
        Ok(None) => panic!("{what}: {} was read", path.display()),
        Err(_) => panic!("{what}: reading {} blocked", path.display()),
    }
}

fn mkfifo(path: &Path) -> bool {
    std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .is_ok_and(|s| s.success())
}

/// Every reader of a file the user names refuses a FIFO (it blocked them forever) and
/// `/dev/zero` (read until memory ran out), naming the file and what it is.
#[cfg(unix)]
#[test]
fn readers_refuse_fifos_and_devices_naming_them() {
    let d = TempDir::new("special");
    let fifo = d.path().join("pipe");
    if !mkfifo(&fifo) {
        eprintln!("mkfifo is not here: skipped");
        return;
    }
    type Reader = fn(PathBuf) -> regtrack::Result<()>;
    #[allow(unused_mut)]
    let mut readers: Vec<(&str, Reader)> = vec![
        ("journal", |p| regtrack::gt::journal::read(&p).map(|_| ())),
        ("journal writer", |p| {
            regtrack::gt::journal::Writer::open(&p, "s").map(|_| ())
        }),
        ("session", |p| {
            regtrack::session::State::load(&p).map(|_| ())
        }),
        ("tracks", |p| regtrack::patches::read_tracks(&p).map(|_| ())),
        ("points", |p| regtrack::patches::read_points(&p).map(|_| ())),
        ("ground truth", |p| {
            regtrack::dataset::read_ground_truth(&p).map(|_| ())
        }),
        ("frame", |p| regtrack::imaging::load_gray(&p).map(|_| ())),
    ];
    #[cfg(feature = "gui")]
    readers.push(("preferences", |p| {
        regtrack::app::prefs::Prefs::load(&p).map(|_| ())
    }));
    for (what, read) in readers {
        let e = refused(what, &fifo, read);
        assert!(e.contains("pipe") && e.contains("FIFO"), "{what}: {e}");
        let e = refused(what, Path::new("/dev/zero"), read);
        assert!(
            e.contains("/dev/zero") && e.contains("a device"),
            "{what}: {e}"
        );
    }
    // A run file that is a FIFO, for `merge` and `report`.
    let runs = d.path().join("out/tracking_data/s");
    std::fs::create_dir_all(&runs).unwrap();
    let run = runs.join("t_run.json");
    assert!(mkfifo(&run));
    let out = d.path().join("out");
    let e = refused("run files", &out, |p| regtrack::eval::read_runs(&p));
    assert!(e.contains("t_run.json") && e.contains("FIFO"), "{e}");
}

/// A frame path that is a folder or a loop of symbolic links is named for what it is, not
/// as a missing file.
#[cfg(unix)]
#[test]
fn a_frame_that_is_a_folder_or_a_link_loop_says_so() {
    let d = TempDir::new("frames");
    let dir = d.path().join("frame00001.jpg");
    std::fs::create_dir_all(&dir).unwrap();
    let e = regtrack::imaging::load_gray(&dir).unwrap_err().to_string();
    assert!(e.contains("is a folder"), "{e}");
    let (a, b) = (d.path().join("a.png"), d.path().join("b.png"));
    std::os::unix::fs::symlink(&b, &a).unwrap();
    std::os::unix::fs::symlink(&a, &b).unwrap();
    let e = regtrack::imaging::load_gray(&a).unwrap_err().to_string();
    assert!(e.contains("loop of symbolic links"), "{e}");
    let e = regtrack::imaging::load_gray(&d.path().join("none.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing file"), "{e}");
}

/// An I/O failure's cause is printed once, not once in the message and again as its source.
#[test]
fn an_io_cause_is_printed_once() {
    let e = regtrack::Error::io(
        "x.txt",
        std::io::Error::new(std::io::ErrorKind::PermissionDenied, "denied here"),
    );
    let chain = format!("{:#}", anyhow::Error::from(e));
    assert_eq!(chain.matches("denied here").count(), 1, "{chain}");
}

/// A live source's size that cannot be a frame's is refused before anything is allocated or
/// started (10^9 x 10^9 aborted the process, 2^32 wrapped to 0, usize::MAX panicked the reader
/// thread while the caller waited forever).
#[test]
fn a_live_size_that_cannot_be_a_frame_is_refused() {
    use regtrack::dataset::live::{Live, check_size};
    for (w, h) in [
        (1_000_000_000, 1_000_000_000),
        (1 << 32, 1 << 32),
        (usize::MAX, 1),
        (0, 240),
        (16385, 2),
        (16384, 16384),
    ] {
        let e = check_size(w, h).unwrap_err().to_string();
        assert!(e.contains(&format!("{w}x{h}")), "{e}");
        let e = Live::open("lavfi:testsrc=size=320x240:rate=30", w, h, false)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("live source size"), "{e}");
    }
    assert!(check_size(8192, 8192).is_ok());
    assert!(check_size(1, 1).is_ok());
}

/// A source that stops sending (an FFmpeg that stalls) is reported after the stall time, not
/// waited on forever.
#[test]
fn a_live_source_that_stalls_is_reported() {
    if !crate::dataset::have_ffmpeg() {
        eprintln!("ffmpeg is not here: skipped");
        return;
    }
    // One frame every 4 s (FFmpeg holds each until the next: the first after about 4 s),
    // then nothing for longer than the stall time.
    let mut live =
        regtrack::dataset::live::Live::open("lavfi:testsrc=size=32x32:rate=0.25", 32, 32, false)
            .unwrap();
    live.set_stall(Duration::from_secs(20));
    live.newest().unwrap();
    live.set_stall(Duration::from_secs(1));
    let t = std::time::Instant::now();
    let e = live.newest().err().expect("stalled").to_string();
    assert!(e.contains("stalled") && e.contains("after frame 1"), "{e}");
    assert!(t.elapsed() < Duration::from_secs(10));
}

/// An MTF sequence's frames are the images of its folder; its ground truth is matched to them
/// by name. A missing line left a gap (index 4 became `frame00006`), a missing first line
/// started at `frame00002`, a shorter file dropped the last images, swapped lines played the
/// frames out of order.
#[test]
fn mtf_frames_are_the_folders_images_and_lines_match_them_by_name() {
    use regtrack::dataset::Sequence;
    let d = TempDir::new("mtf-names");
    let frames = d.path().join("s");
    std::fs::create_dir_all(&frames).unwrap();
    for i in 1..=6 {
        crate::common::write_png(&frames.join(format!("frame{i:05}.png")), 40, 30, i as u8);
    }
    let line = |i: usize| {
        let x = i as f64;
        format!(
            "frame{i:05}.png {x} 1 {} 1 {} 9 {x} 9\n",
            x + 10.0,
            x + 10.0
        )
    };
    let header = "frame ulx uly urx ury lrx lry llx lly\n";
    let open = |lines: &[usize]| {
        let mut text = header.to_string();
        for &i in lines {
            text.push_str(&line(i));
        }
        std::fs::write(d.path().join("s.txt"), text).unwrap();
        Sequence::open(&d.path().join("s.txt")).unwrap()
    };
    let ulx = |s: &Sequence, i: usize| s.ground_truth(i).map(|q| q.to_array()[0]);
    // A line missing in the middle: the frame stays, not annotated, one warning.
    let s = open(&[1, 2, 3, 5, 6]);
    assert_eq!(s.len(), 6);
    assert!(s.frames[4].ends_with("frame00005.png"));
    assert_eq!((ulx(&s, 3), ulx(&s, 4)), (None, Some(5.0)));
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("frame00004.png"), "{:?}", s.warnings);
    // The first line missing: the sequence still starts at frame00001.
    let s = open(&[2, 3, 4, 5, 6]);
    assert!(s.frames[0].ends_with("frame00001.png"));
    assert_eq!((ulx(&s, 0), ulx(&s, 1)), (None, Some(2.0)));
    // A shorter file: every image is a frame.
    let s = open(&[1, 2, 3]);
    assert_eq!(s.len(), 6);
    assert_eq!(ulx(&s, 5), None);
    // Swapped lines: each frame has its own line, in the folder's order.
    let s = open(&[1, 3, 2, 4, 6, 5]);
    for i in 0..6 {
        assert_eq!(ulx(&s, i), Some((i + 1) as f64));
    }
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    // A line whose image is not there: an error naming the file and the line.
    let mut text = header.to_string() + &line(1);
    text.push_str("frame00099.png 1 1 9 1 9 9 1 9\n");
    std::fs::write(d.path().join("s.txt"), text).unwrap();
    let e = Sequence::open(&d.path().join("s.txt"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("s.txt:3: missing frame") && e.contains("frame00099.png"),
        "{e}"
    );
    // Results name the frames as the sequence does (PNG here, not `frame%05d.jpg`).
    let s = open(&[1, 2, 3, 4, 5, 6]);
    let out = d.path().join("out.txt");
    let corners: Vec<_> = (0..6).map(|i| s.ground_truth(i)).collect();
    regtrack::dataset::write_corners_named(&out, &corners, &s.frame_names()).unwrap();
    let back = regtrack::dataset::read_ground_truth(&out).unwrap();
    assert_eq!(back[2].frame.as_deref(), Some("frame00003.png"));
}

/// In a file of 8 numbers per line (a folder's `groundtruth.txt`, POT), lines are frames by
/// position: a blank line is a frame not annotated (it shifted every later frame's ground truth
/// back one frame), fewer lines than frames is said, and frames named without zero padding are
/// in natural order (`frame2` before `frame10`).
#[test]
fn positional_ground_truth_keeps_its_frames_and_folders_sort_naturally() {
    use regtrack::dataset::Sequence;
    let d = TempDir::new("positional");
    let dir = d.path().join("clip");
    std::fs::create_dir_all(&dir).unwrap();
    for i in 1..=12 {
        crate::common::write_png(&dir.join(format!("frame{i}.png")), 40, 30, i as u8);
    }
    let quad = |i: usize| {
        let x = i as f64;
        format!("{x} 1 {} 1 {} 9 {x} 9\n", x + 10.0, x + 10.0)
    };
    let mut text = String::new();
    for i in 1..=12 {
        text.push_str(&if i == 4 { "\n".to_string() } else { quad(i) });
    }
    text.push_str("\n\n");
    std::fs::write(dir.join("groundtruth.txt"), &text).unwrap();
    let s = Sequence::open(&dir).unwrap();
    let names: Vec<String> = s.frame_names();
    assert_eq!(names[1], "frame2.png");
    assert_eq!(names[9], "frame10.png");
    assert_eq!(s.len(), 12);
    for i in 0..12 {
        let want = if i == 3 { None } else { Some((i + 1) as f64) };
        assert_eq!(
            s.ground_truth(i).map(|q| q.to_array()[0]),
            want,
            "frame {}",
            i + 1
        );
    }
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    // Fewer lines than frames: said, naming the frames left without.
    let short: String = (1..=9).map(quad).collect();
    std::fs::write(dir.join("groundtruth.txt"), short).unwrap();
    let s = Sequence::open(&dir).unwrap();
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("frames 10 to 12"),
        "{:?}",
        s.warnings
    );
    // A byte-order mark is not part of the first line (it was refused here, accepted in MTF).
    let bom = format!("\u{feff}{}", (1..=12).map(quad).collect::<String>());
    std::fs::write(dir.join("groundtruth.txt"), bom).unwrap();
    let s = Sequence::open(&dir).unwrap();
    assert_eq!(s.ground_truth(0).map(|q| q.to_array()[0]), Some(1.0));
}

#[test]
fn natural_order_compares_numbers_by_value() {
    use regtrack::dataset::natural_cmp;
    use std::cmp::Ordering::*;
    assert_eq!(natural_cmp("frame2.png", "frame10.png"), Less);
    assert_eq!(natural_cmp("frame10.png", "frame9.png"), Greater);
    assert_eq!(natural_cmp("frame00010.png", "frame00009.png"), Greater);
    assert_eq!(natural_cmp("a1b2", "a1b10"), Less);
    assert_eq!(natural_cmp("img", "img1"), Less);
    assert_ne!(natural_cmp("frame007.png", "frame7.png"), Equal);
    assert!(natural_cmp("x0", "x00").is_ne());
}

/// OptGT corners (`eval --gt-ssm`) are checked as the sequence's own are: folded, collinear,
/// tiny and far-off quads are read as not annotated with a warning naming the file and line (a
/// mean error of 588,649 px came from them); a first line without corners is blamed on the
/// OptGT file, not on the sequence's.
#[test]
fn optgt_corners_are_checked_and_its_errors_name_it() {
    use regtrack::dataset::Sequence;
    let d = TempDir::new("optgt");
    let seq = Sequence::open(&crate::common::tiny_sequence(d.path(), 6)).unwrap();
    std::fs::create_dir_all(d.path().join("OptGT")).unwrap();
    let opt = d.path().join("OptGT/s_translation.txt");
    let lines = [
        "10 10 40 10 40 30 10 30",
        "10 10 40 30 40 10 10 30",             // folded
        "10 10 20 10 30 10 40 10",             // collinear
        "10 10 10.01 10 10.01 10.01 10 10.01", // tiny
        "1e308 10 40 10 40 30 10 30",          // far beyond any frame
        "-2e7 -2e7 2e7 -2e7 2e7 2e7 -2e7 2e7", // 2e7 px
    ];
    std::fs::write(&opt, lines.join("\n") + "\n").unwrap();
    let regtrack::gt::LowDofTruth {
        quads,
        path,
        warnings,
    } = regtrack::gt::low_dof_ground_truth(&seq, "translation").unwrap();
    assert_eq!(path.as_deref(), Some(opt.as_path()));
    assert!(quads[0].is_some());
    assert!(quads[1..].iter().all(Option::is_none), "{quads:?}");
    assert_eq!(warnings.len(), 5, "{warnings:?}");
    for (w, line) in warnings.iter().zip(2..) {
        assert!(w.contains(&format!("s_translation.txt:{line}")), "{w}");
    }
    // The first line without corners: the OptGT file is named.
    std::fs::write(&opt, format!("lost\n{}\n", lines[1..].join("\n"))).unwrap();
    let spec = regtrack::tracker::TrackerSpec::from_names("iclk", "ssd", "translation").unwrap();
    let opts = regtrack::eval::EvalOptions {
        gt_ssm: Some("translation".into()),
        ..Default::default()
    };
    let e =
        regtrack::eval::run_sequence(&seq, &spec, &opts, None, &mut regtrack::observe::NoObserver)
            .unwrap_err()
            .to_string();
    assert!(
        e.contains("s_translation.txt") && !e.contains("s.txt:"),
        "{e}"
    );
}

/// Paths reach FFmpeg as files, never as URLs or options: `concat:a.mp4` tracked `a.mp4`,
/// `pipe:0.mp4` read standard input, `-h.mp4` was an option to ffprobe, `--render
/// file:out2.mp4` wrote `out2.mp4`. A render to an image name is refused before anything is
/// written, and a failed render says FFmpeg's reason, not "Broken pipe".
#[test]
fn ffmpeg_is_given_paths_as_files() {
    if !crate::dataset::have_ffmpeg() {
        return;
    }
    let d = TempDir::new("ffpaths");
    let make = |name: &str, frames: usize| {
        let ok = std::process::Command::new("ffmpeg")
            .current_dir(d.path())
            .args(["-v", "error", "-y", "-f", "lavfi", "-i"])
            .arg(format!(
                "testsrc=size=96x64:rate=10,trim=end_frame={frames}"
            ))
            .args(["-pix_fmt", "yuv420p", "--", "tmp.mp4"])
            .status()
            .unwrap();
        assert!(ok.success());
        std::fs::rename(d.path().join("tmp.mp4"), d.path().join(name)).unwrap();
    };
    make("a.mp4", 9);
    make("concat:a.mp4", 5);
    make("pipe:0.mp4", 6);
    make("-h.mp4", 7);
    let track = |seq: &str, render: Option<&str>| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_regtrack"));
        c.current_dir(d.path()).args([
            "track",
            &format!("--seq={seq}"),
            "--init",
            "20,16,60,16,60,48,20,48",
            "--out",
            "out.txt",
        ]);
        if let Some(r) = render {
            c.args(["--render", r]);
        }
        c.stdin(std::process::Stdio::null()).output().unwrap()
    };
    for (seq, frames) in [("concat:a.mp4", 5), ("pipe:0.mp4", 6), ("-h.mp4", 7)] {
        let out = track(seq, None);
        let said = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && said.contains(&format!("of {frames} frames")),
            "{seq}: {said} {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let out = track("a.mp4", Some("file:out2.mp4"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(d.path().join("file:out2.mp4").is_file());
    assert!(!d.path().join("out2.mp4").exists());
    // An image name: refused, nothing written.
    let out = track("a.mp4", Some("out.jpg"));
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("not a video file name"),
        "{e}"
    );
    assert!(!d.path().join("out.jpg").exists());
    // A render FFmpeg cannot write (its folder is a file): FFmpeg's reason, no broken pipe.
    std::fs::write(d.path().join("blocker"), b"").unwrap();
    let out = track("a.mp4", Some("blocker/x.mp4"));
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && !e.contains("Broken pipe"), "{e}");
}

/// Runs of different settings are never pooled silently: `merge` and `report` refuse shards of
/// another `--res`, `--error` or `--gt-ssm`, and `eval` refuses an `--out` that holds runs of
/// other settings it would leave beside its own (two evaluations into one folder both exited
/// 0, leaving runs at res 50 and res 30 and a summary that disagreed with its run files).
#[test]
fn runs_of_different_settings_are_never_pooled() {
    use crate::cli::{regtrack, succeed, synth};
    let d = TempDir::new("settings");
    let data = d.path().join("data");
    for name in ["a", "b"] {
        succeed(synth("ucsb_bricks_rt.txt", &data, name, &["--frames", "6"]));
    }
    let eval = |out: &str, seqs: &str, extra: &[&str]| {
        let out = d.path().join(out);
        let mut a = vec![
            "eval",
            "--dataset",
            data.to_str().unwrap(),
            "--seqs",
            seqs,
            "--sm",
            "iclk",
            "--am",
            "ssd",
            "--ssm",
            "homography",
            "--out",
            out.to_str().unwrap(),
        ];
        a.extend(extra);
        regtrack(&a)
    };
    let path = |out: &str| d.path().join(out).to_str().unwrap().to_string();
    succeed(eval("s1", "a", &[]));
    succeed(eval("s2", "b", &["--res", "30"]));
    succeed(eval("s3", "b", &["--error", "center"]));
    for other in ["s2", "s3"] {
        for cmd in ["merge", "report"] {
            let merged = path(&format!("{cmd}-{other}"));
            let out = regtrack(&[cmd, &path("s1"), &path(other), "--out", &merged]);
            let e = String::from_utf8_lossy(&out.stderr);
            assert!(
                !out.status.success() && e.contains("different settings"),
                "{cmd} s1 {other}: {e}"
            );
        }
    }
    // One folder, two settings: the second evaluation is refused, naming the run.
    let out = eval("s1", "b", &["--res", "30"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("other settings") && e.contains("res"),
        "{e}"
    );
    // The same settings go on into the folder.
    succeed(eval("s1", "b", &[]));
    let runs = regtrack::eval::read_all_runs(&[d.path().join("s1")]).unwrap();
    assert_eq!(runs.len(), 2);
}

/// `synth --name` is a name, not a path: `../../x` wrote outside `--out`.
#[test]
fn a_synth_name_cannot_leave_the_output_folder() {
    use crate::cli::synth;
    let d = TempDir::new("synth-name");
    let out = d.path().join("out");
    for name in ["../escaped", "/tmp/escaped", "a/b", "..", ""] {
        let r = synth("ucsb_bricks_rt.txt", &out, name, &["--frames", "2"]);
        let e = String::from_utf8_lossy(&r.stderr);
        assert!(
            !r.status.success() && e.contains("sequence name"),
            "{name}: {e}"
        );
    }
    assert!(!d.path().join("escaped").exists() && !d.path().join("escaped.txt").exists());
}

/// A session's tracker colour is three 0-255 values: four, or a million, were accepted.
#[test]
fn a_session_colour_has_three_values() {
    let d = TempDir::new("session-colour");
    let text = std::fs::read_to_string(crate::common::root().join("sessions/demo.toml")).unwrap();
    assert!(text.contains("color = [255, 80, 80]"));
    let long = format!("[{}]", vec!["7"; 1_000_000].join(","));
    for bad in ["[255, 80, 80, 9]", "[255, 80]", long.as_str()] {
        let p = d.path().join("s.toml");
        std::fs::write(&p, text.replacen("[255, 80, 80]", bad, 1)).unwrap();
        let e = regtrack::session::State::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("s.toml") && e.contains("3"),
            "{}",
            &e[..e.len().min(300)]
        );
    }
}

/// `--patches 0` asked for none and tracked 40; a NaN point started a patch at (0, 0); a
/// parameter given twice (`--res 20 --param res=10`) let one win unsaid.
#[test]
fn patches_and_parameters_take_what_they_are_given() {
    use crate::cli::{regtrack, synth};
    use regtrack::geometry::Point;
    let d = TempDir::new("patches0");
    let data = d.path().join("data");
    crate::cli::succeed(synth("ucsb_bricks_rt.txt", &data, "p", &["--frames", "3"]));
    let seq = data.join("p.txt");
    let out = d.path().join("t.csv");
    let r = regtrack(&[
        "track",
        "--seq",
        seq.to_str().unwrap(),
        "--patches",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&r.stderr);
    assert!(
        !r.status.success() && e.contains("at least one patch"),
        "{e}"
    );
    let frame = regtrack::imaging::load_gray(&data.join("p/frame00001.jpg")).unwrap();
    let mut t = regtrack::patches::PatchTracker::new(Default::default()).unwrap();
    let e = t
        .initialize(&frame, &[Point::new(50.0, 50.0), Point::new(f64::NAN, 3.0)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("point 2"), "{e}");
    let r = regtrack(&[
        "track",
        "--seq",
        seq.to_str().unwrap(),
        "--res",
        "20",
        "--param",
        "res=10",
        "--out",
        out.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&r.stderr);
    assert!(
        !r.status.success() && e.contains("res is given twice"),
        "{e}"
    );
}

/// `lm:` damps a Newton step: on a sampling method (`lm:nn1k`, `lm:pf`) it was accepted and
/// did nothing.
#[test]
fn lm_takes_a_gradient_method_only() {
    use regtrack::tracker::{Tracker, TrackerSpec};
    for sm in ["lm:nn1k", "lm:pf"] {
        let e = TrackerSpec::from_names(sm, "ssd", "homography")
            .and_then(|s| Tracker::new(&s).map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("gradient"), "{sm}: {e}");
    }
    let ok = TrackerSpec::from_names("lm:iclk", "ssd", "homography").unwrap();
    assert!(Tracker::new(&ok).is_ok());
}

/// `score-patches` says the sequence's warnings, refuses coordinates beyond any frame (1e155
/// was counted as tracked and dropped from the mean as infinite), a tracks file of another
/// length than the sequence, and an empty one (which was blamed on the ground truth).
#[test]
fn score_patches_refuses_tracks_that_are_not_the_sequences() {
    use crate::cli::{regtrack, succeed, synth};
    let d = TempDir::new("score");
    let data = d.path().join("data");
    succeed(synth("ucsb_bricks_rt.txt", &data, "p", &["--frames", "4"]));
    let seq = data.join("p.txt");
    let tracks = d.path().join("t.csv");
    succeed(regtrack(&[
        "track",
        "--seq",
        seq.to_str().unwrap(),
        "--patches",
        "5",
        "--out",
        tracks.to_str().unwrap(),
    ]));
    let score = |t: &std::path::Path| {
        regtrack(&[
            "score-patches",
            "--seq",
            seq.to_str().unwrap(),
            "--tracks",
            t.to_str().unwrap(),
        ])
    };
    succeed(score(&tracks));
    let text = std::fs::read_to_string(&tracks).unwrap();
    let bad = d.path().join("bad.csv");
    let check = |content: String, says: &str| {
        std::fs::write(&bad, content).unwrap();
        let out = score(&bad);
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && e.contains(says), "{says}: {e}");
    };
    // The last frame's lines cut off.
    let short: Vec<&str> = text.lines().filter(|l| !l.starts_with("3,")).collect();
    check(short.join("\n") + "\n", "tracks of 3 frames");
    check(String::new(), "no tracks");
    // A coordinate no frame has.
    let mut far: Vec<String> = text.lines().map(str::to_string).collect();
    let mut f: Vec<String> = far[2].split(',').map(str::to_string).collect();
    f[3] = "1e155".into();
    far[2] = f.join(",");
    check(far.join("\n") + "\n", "bad.csv:3");
    // The sequence's warnings are said.
    let gt = std::fs::read_to_string(&seq).unwrap();
    let lines: Vec<&str> = gt.lines().collect();
    let folded =
        lines[3].split_whitespace().next().unwrap().to_string() + " 10 10 40 30 40 10 10 30";
    let mut g: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
    g[3] = folded;
    std::fs::write(&seq, g.join("\n") + "\n").unwrap();
    let out = score(&tracks);
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning:"));
}

/// A 1 MB token is quoted short in the error that names it, not echoed whole.
#[test]
fn a_huge_token_is_quoted_short() {
    let token = "x".repeat(1 << 20);
    let p = std::path::Path::new("g.txt");
    let e = regtrack::dataset::parse_ground_truth(p, &format!("1 2 3 4 5 6 7 {token}\n"))
        .unwrap_err()
        .to_string();
    assert!(
        e.len() < 300 && e.contains("1048576 bytes"),
        "{}",
        &e[..e.len().min(300)]
    );
    let e = regtrack::tracker::TrackerSpec::from_names(&token, "ssd", "homography")
        .and_then(|s| regtrack::tracker::Tracker::new(&s).map(|_| ()))
        .unwrap_err()
        .to_string();
    assert!(
        e.len() < 2000 && e.contains("1048576 bytes"),
        "{}",
        &e[..e.len().min(300)]
    );
    let e = regtrack::params::split_assignment(&token)
        .unwrap_err()
        .to_string();
    assert!(e.len() < 300, "{}", &e[..e.len().min(300)]);
}

/// A region partly outside the frame, on a blank frame, and a video cut short (its first frame
/// decoded as one grey) were each refused as "the template is flat ... singular system": the
/// errors now say what is outside and that the frame is blank or damaged.
#[test]
fn a_flat_start_says_why() {
    use regtrack::visual_tracker::{FrameInput, fraction_inside};
    let quad = |v: [f64; 8]| regtrack::geometry::Quad::from_array(v);
    // Half of a 40x40 square over the left edge, all of one inside, none of one beyond.
    let half = quad([-20.0, 10.0, 20.0, 10.0, 20.0, 50.0, -20.0, 50.0]);
    assert!((fraction_inside(&half, 100, 80) - 0.5).abs() < 1e-9);
    let whole = quad([10.0, 10.0, 50.0, 10.0, 50.0, 50.0, 10.0, 50.0]);
    assert!((fraction_inside(&whole, 100, 80) - 1.0).abs() < 1e-9);
    let beyond = quad([110.0, 10.0, 150.0, 10.0, 150.0, 50.0, 110.0, 50.0]);
    assert_eq!(fraction_inside(&beyond, 100, 80), 0.0);
    // A rotated square over a corner: the clipped area by hand (a triangle of legs 20).
    let diamond = quad([0.0, -20.0, 20.0, 0.0, 0.0, 20.0, -20.0, 0.0]);
    assert!((fraction_inside(&diamond, 100, 80) - 200.0 / 800.0).abs() < 1e-9);

    let blank = regtrack::imaging::GrayU8 {
        width: 100,
        height: 80,
        data: vec![130; 8000],
    };
    let spec = regtrack::tracker::default_spec("homography").unwrap();
    let mut t = regtrack::tracker::Tracker::new(&spec).unwrap();
    let e = t
        .initialize(FrameInput::Gray8(&blank), &half)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("50 % of the region lies outside the 100x80 frame")
            && e.contains("every pixel of the frame there is 130")
            && !e.contains("singular"),
        "{e}"
    );

    if !crate::dataset::have_ffmpeg() {
        return;
    }
    let d = TempDir::new("cut-video");
    let ok = std::process::Command::new("ffmpeg")
        .current_dir(d.path())
        .args(["-v", "error", "-y", "-f", "lavfi", "-i"])
        .arg("testsrc=size=192x144:rate=10,trim=end_frame=20")
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "--", "v.ts"])
        .status()
        .unwrap();
    assert!(ok.success());
    let bytes = std::fs::read(d.path().join("v.ts")).unwrap();
    // The first packets only: the first frame's data is cut.
    let cut = d.path().join("cut.ts");
    std::fs::write(&cut, &bytes[..2000.min(bytes.len() / 4)]).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_regtrack"))
        .args(["track", "--init", "40,30,120,30,120,100,40,100", "--out"])
        .arg(d.path().join("out.txt"))
        .arg("--seq")
        .arg(&cut)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{e}");
    assert!(
        !e.contains("template is flat")
            && e.contains("frame 1")
            && e.contains("cut short or corrupt"),
        "{e}"
    );
}
