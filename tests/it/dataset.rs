//! Sequence layouts and ground-truth parsing: good input opens, bad input gives an error that
//! names the file and line (or the missing path), never a panic.

use crate::common::{TempDir, write_png};
use regtrack::Error;
use regtrack::dataset::{Sequence, parse_ground_truth, read_ground_truth, write_corners};
use regtrack::geometry::Quad;
use std::path::Path;

const HEADER: &str = "frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n";

fn mtf_layout(dir: &Path, n: usize) -> std::path::PathBuf {
    let seq = dir.join("seq");
    std::fs::create_dir_all(&seq).unwrap();
    let mut gt = HEADER.to_string();
    for i in 1..=n {
        write_png(&seq.join(format!("frame{i:05}.png")), 32, 24, i as u8);
        gt.push_str(&format!("frame{i:05}.png 1 2 21 2 21 16 1 16\n"));
    }
    let p = dir.join("seq.txt");
    std::fs::write(&p, gt).unwrap();
    p
}

#[test]
fn mtf_layout_opens_from_the_file_or_the_folder() {
    let d = TempDir::new("mtf");
    let gt = mtf_layout(d.path(), 3);
    for p in [gt.clone(), d.path().join("seq")] {
        let s = Sequence::open(&p).unwrap();
        assert_eq!((s.name.as_str(), s.len()), ("seq", 3));
        assert_eq!(
            s.ground_truth(2),
            Some(Quad::from_array([1., 2., 21., 2., 21., 16., 1., 16.]))
        );
        assert_eq!(s.load_gray(1).unwrap().width, 32);
    }
    let all = regtrack::dataset::discover(d.path(), None).unwrap();
    assert_eq!(all.len(), 1);
    let err = regtrack::dataset::discover(d.path(), Some(&["nope".to_string()]))
        .unwrap_err()
        .to_string();
    assert!(err.contains("nope") && err.contains("seq"), "{err}");
}

#[test]
fn a_missing_frame_names_its_path() {
    let d = TempDir::new("missing");
    mtf_layout(d.path(), 3);
    std::fs::remove_file(d.path().join("seq/frame00002.png")).unwrap();
    // The line that names it is an error naming the ground truth's line and the frame's path.
    match Sequence::open(&d.path().join("seq.txt")) {
        Err(e @ Error::Parse { line: 3, .. }) => {
            let e = e.to_string();
            let frame = d.path().join("seq/frame00002.png");
            assert!(e.contains(&frame.display().to_string()), "{e}")
        }
        other => panic!("expected a missing-frame error, got {other:?}"),
    }
}

#[test]
fn an_undecodable_frame_names_its_path() {
    let d = TempDir::new("undecodable");
    let gt = mtf_layout(d.path(), 2);
    std::fs::write(d.path().join("seq/frame00002.png"), b"not a png").unwrap();
    let s = Sequence::open(&gt).unwrap();
    let err = s.load_gray(1).unwrap_err().to_string();
    assert!(err.contains("frame00002.png"), "{err}");
}

/// Frames read ahead come in order, each once; an undecodable one arrives as its error in its
/// place; a break stops the reading (and returns its value).
#[test]
fn frames_read_ahead_come_in_order_with_their_errors() {
    use std::ops::ControlFlow::{Break, Continue};
    let d = TempDir::new("ahead");
    let gt = mtf_layout(d.path(), 12);
    std::fs::write(d.path().join("seq/frame00007.png"), b"not a png").unwrap();
    let s = Sequence::open(&gt).unwrap();
    let mut seen = Vec::new();
    // In colour: a grey file's channels are its grey.
    let none: Option<()> = s.each_frame(1..12, true, true, |i, frame| {
        match frame {
            // Frame i holds the gray level i + 1 (`mtf_layout`).
            Ok(regtrack::imaging::Frame8::Colour(c)) => {
                assert!(c.channels.iter().all(|p| p == &c.gray));
                seen.push((i, c.gray.data[0]))
            }
            Ok(other) => panic!("a grey frame where colour was asked for: {other:?}"),
            Err(e) => {
                assert!(e.to_string().contains("frame00007.png"), "{e}");
                seen.push((i, 0));
            }
        }
        Continue(())
    });
    assert!(none.is_none());
    let want: Vec<(usize, u8)> = (1..12)
        .map(|i| (i, if i == 6 { 0 } else { i as u8 + 1 }))
        .collect();
    assert_eq!(seen, want);
    // A break at the fourth frame: its value back, no frame after it seen.
    let mut count = 0;
    let stopped = s.each_frame(0..12, true, false, |i, _| {
        count += 1;
        if i == 3 { Break(i * 10) } else { Continue(()) }
    });
    assert_eq!((stopped, count), (Some(30), 4));
    // One frame or none, or not ahead: read in turn.
    assert_eq!(
        s.each_frame(5..6, true, false, |i, f| Break((i, f.is_ok()))),
        Some((5, true))
    );
    assert_eq!(
        s.each_frame(5..9, false, false, |i, f| Break((i, f.is_ok()))),
        Some((5, true))
    );
    assert_eq!(s.each_frame(5..5, true, false, |_, _| Break(())), None);
}

#[test]
fn folder_of_images_with_and_without_ground_truth() {
    let d = TempDir::new("folder");
    for i in 0..4 {
        write_png(&d.path().join(format!("img_{i}.png")), 16, 16, i);
    }
    let s = Sequence::open(d.path()).unwrap();
    assert_eq!(s.len(), 4);
    assert!(s.ground_truth.is_empty() && s.ground_truth(0).is_none());
    std::fs::write(
        d.path().join("groundtruth.txt"),
        "1,1,9,1,9,9,1,9\n2 2 10 2 10 10 2 10\n",
    )
    .unwrap();
    let s = Sequence::open(d.path()).unwrap();
    assert_eq!(s.ground_truth(1).unwrap().0[0].x, 2.0);
    assert!(s.ground_truth(2).is_none());
}

#[test]
fn pot_ground_truth_every_other_frame() {
    let d = TempDir::new("pot");
    let frames = d.path().join("V01/img");
    std::fs::create_dir_all(&frames).unwrap();
    for i in 0..6 {
        write_png(&frames.join(format!("{i:04}.png")), 16, 16, i);
    }
    let gt = d.path().join("V01_gt_points.txt");
    std::fs::write(
        &gt,
        "1 1 9 1 9 9 1 9\n2 1 10 1 10 9 2 9\n3 1 11 1 11 9 3 9\n",
    )
    .unwrap();
    let s = Sequence::open(&gt).unwrap();
    assert_eq!((s.name.as_str(), s.len()), ("V01", 6));
    assert_eq!(s.ground_truth(2).unwrap().0[0].x, 2.0);
    assert!(s.ground_truth(1).is_none() && s.ground_truth(4).is_some());
}

#[test]
fn malformed_ground_truth_names_file_and_line() {
    let p = Path::new("data/seq.txt");
    let cases = [
        (
            format!("{HEADER}frame00001.jpg 1 2 3 4 5 6 7 8\nframe00002.jpg 1 2 3 4 5\n"),
            3,
            "found 5",
        ),
        (
            format!("{HEADER}frame00001.jpg 1 2 3 4 5 6 7 x8\n"),
            2,
            "'x8' is not a number",
        ),
        (
            "1 2 3 4 5 6 7 8\n\n1 2 3 4 5 6 7 8 9\n".to_string(),
            3,
            "found 9",
        ),
        ("1 2 3 4 5 6 7 inf\n".to_string(), 1, "not a finite number"),
    ];
    for (text, line, msg) in cases {
        match parse_ground_truth(p, &text) {
            Err(e @ Error::Parse { .. }) => {
                let s = e.to_string();
                assert!(
                    s.starts_with(&format!("data/seq.txt:{line}:")) && s.contains(msg),
                    "{s}"
                );
            }
            other => panic!("{text:?}: expected a parse error, got {other:?}"),
        }
    }
    // A first line for a lost frame is a frame, not a header.
    let g = parse_ground_truth(p, "frame00001.jpg lost\nframe00002.jpg 1 2 3 4 5 6 7 8\n").unwrap();
    assert_eq!(g.len(), 2);
    assert!(g[0].quad.is_none() && g[1].quad.is_some());
    // Empty input, comments and a lone header are fine.
    assert!(parse_ground_truth(p, "").unwrap().is_empty());
    assert!(
        parse_ground_truth(p, "# comment\nframe ulx uly urx ury lrx lry llx lly\n")
            .unwrap()
            .is_empty()
    );
    // A missing file is named.
    let err = read_ground_truth(Path::new("/nonexistent/gt.txt"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/gt.txt"), "{err}");
}

#[test]
fn corners_round_trip_with_lost_frames() {
    let d = TempDir::new("corners");
    let p = d.path().join("out/run.txt");
    let q = Quad::from_array([1.5, 2.25, 30.0, 2.0, 31.0, 40.0, 0.5, 41.0]);
    write_corners(&p, &[Some(q), None, Some(q)], "jpg").unwrap();
    let back = read_ground_truth(&p).unwrap();
    assert_eq!(back.len(), 3);
    assert_eq!(back[0].quad, Some(q));
    assert_eq!(back[1].quad, None);
    assert_eq!(back[2].frame.as_deref(), Some("frame00003.jpg"));
}

/// The crashes the fuzz targets found, as regression tests: each input of
/// `tests/fuzz/corpus/image/crash_*` (first byte: the extension, as the `image` target reads it)
/// is refused with an error naming the file, never a panic. zune-jpeg 0.5 overflows on
/// `crash_zune_jpeg_overflow` (a multiplication in its bit reader).
#[test]
fn images_that_crashed_a_decoder_are_bad_frames() {
    let d = crate::common::TempDir::new("crashes");
    let corpus = crate::common::root().join("tests/fuzz/corpus/image");
    let mut seen = 0;
    for e in std::fs::read_dir(&corpus).unwrap() {
        let p = e.unwrap().path();
        if !p
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("crash_")
        {
            continue;
        }
        let bytes = std::fs::read(&p).unwrap();
        let ext = ["png", "jpg", "pgm"][bytes[0] as usize % 3];
        let frame = d.path().join(format!("frame.{ext}"));
        std::fs::write(&frame, &bytes[1..]).unwrap();
        match regtrack::imaging::load_gray(&frame) {
            Err(e) => assert!(e.to_string().contains("frame."), "{}: {e}", p.display()),
            // Without overflow checks (a release build) the decoder's arithmetic wraps instead
            // of panicking, and it returns an image: no panic either way.
            Ok(img) if cfg!(debug_assertions) => panic!(
                "{}: decoded as a {}x{} image",
                p.display(),
                img.width,
                img.height
            ),
            Ok(_) => {}
        }
        seen += 1;
    }
    assert!(seen >= 1);
}

/// Whether FFmpeg's programs are here (CI installs them; elsewhere the video tests say they are
/// skipped).
pub fn have_ffmpeg() -> bool {
    let ok = ["ffmpeg", "ffprobe"].iter().all(|p| {
        std::process::Command::new(p)
            .arg("-version")
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if !ok {
        assert!(std::env::var_os("CI").is_none(), "ffmpeg is missing on CI");
        eprintln!("skipped: ffmpeg is not installed");
    }
    ok
}

/// A video made from a rendered sequence (x264, near-lossless) is a sequence: its ground truth
/// beside it, any frame reached by seeking equal to the same frame decoded in order, tracked as
/// its frames are (within the codec's loss) by `track` and `eval`; a video cut short is the
/// frames it has, with a warning naming it, and a frame that cannot be decoded ends the run
/// naming the file and the frame, keeping the frames before it; a file that is not a video is
/// one line naming it.
#[test]
fn a_video_is_a_sequence() {
    if !have_ffmpeg() {
        return;
    }
    use crate::cli::{regtrack, succeed, synth};
    let d = TempDir::new("video");
    let data = d.path().join("data");
    succeed(synth(
        "ucsb_bricks_rt.txt",
        &data,
        "rt",
        &["--frames", "30", "--jpeg-quality", "0"],
    ));
    let videos = d.path().join("videos");
    std::fs::create_dir_all(&videos).unwrap();
    let clip = videos.join("rt.mp4");
    let made = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-framerate", "25", "-i"])
        .arg(data.join("rt/frame%05d.png"))
        .args([
            "-c:v", "libx264", "-crf", "4", "-g", "10", "-pix_fmt", "yuv420p",
        ])
        // The index first: a copy cut short still opens (and fails at the frame it lacks).
        .args(["-movflags", "+faststart"])
        .arg(&clip)
        .status()
        .unwrap();
    assert!(made.success());
    std::fs::copy(data.join("rt.txt"), videos.join("rt.txt")).unwrap();
    let seq = Sequence::open(&clip).unwrap();
    assert_eq!((seq.len(), seq.name.as_str()), (30, "rt"));
    assert!(seq.ground_truth(29).is_some());
    // An exported correction beside the video (`rt_gt_homography.txt`) and an OptGT file are
    // read with the video's frames: their corners, not `rt.txt`'s.
    let shift = |src: &std::path::Path, dst: &std::path::Path| {
        let entries = regtrack::dataset::read_ground_truth(src).unwrap();
        let quads: Vec<_> = entries
            .iter()
            .map(|e| {
                e.quad
                    .map(|q| q.map(|p| regtrack::geometry::Point::new(p.x + 30.0, p.y)))
            })
            .collect();
        regtrack::dataset::write_ground_truth(dst, &quads, &[], None).unwrap();
    };
    std::fs::create_dir_all(videos.join("OptGT")).unwrap();
    for export in [
        videos.join("rt_gt_homography.txt"),
        videos.join("OptGT/rt_translation.txt"),
    ] {
        shift(&videos.join("rt.txt"), &export);
        let corrected = Sequence::open(&export).unwrap();
        assert_eq!((corrected.len(), corrected.name.as_str()), (30, "rt"));
        assert!(corrected.video.is_some(), "{}", export.display());
        let (a, b) = (
            seq.ground_truth(5).unwrap(),
            corrected.ground_truth(5).unwrap(),
        );
        assert!(
            (b.0[0].x - a.0[0].x - 30.0).abs() < 1e-3,
            "{}",
            export.display()
        );
        assert_eq!(corrected.gt_path.as_deref(), Some(export.as_path()));
    }
    // Seeking lands on the frame decoding in order gives.
    let in_order: Vec<_> = (0..30).map(|i| seq.load_gray(i).unwrap()).collect();
    let frames = Sequence::open(&data.join("rt.txt")).unwrap();
    // A fresh sequence (its cache empty): 25, 3 and 0 are reached by an input seek, 4 and 17
    // by decoding on, 28 and 12 from the cache.
    let seeking = Sequence::open(&clip).unwrap();
    for i in [25, 3, 4, 17, 0, 29, 28, 12] {
        let g = seeking.load_gray(i).unwrap();
        assert_eq!(
            g.data,
            in_order[i].data,
            "frame {} reached by seeking",
            i + 1
        );
        // And it is the rendered frame, within the codec's loss.
        let png = frames.load_gray(i).unwrap();
        let mean = g
            .data
            .iter()
            .zip(&png.data)
            .map(|(&a, &b)| (a as f64 - b as f64).abs())
            .sum::<f64>()
            / g.data.len() as f64;
        assert!(mean < 3.0, "frame {}: mean difference {mean}", i + 1);
    }
    // In colour for display (the coffee is red-brown), as the PNG frames are, within the
    // codec's loss; the trackers' grey is unchanged.
    let video = seq.video.as_ref().unwrap();
    for i in [7, 3, 20] {
        let rgb = video.frame_rgb(i).unwrap();
        let png = image::open(data.join(format!("rt/frame{:05}.png", i + 1)))
            .unwrap()
            .to_rgb8();
        assert_eq!(rgb.len(), png.as_raw().len());
        let mean = rgb
            .iter()
            .zip(png.as_raw())
            .map(|(&a, &b)| (a as f64 - b as f64).abs())
            .sum::<f64>()
            / rgb.len() as f64;
        assert!(
            mean < 4.0,
            "frame {} in colour: mean difference {mean}",
            i + 1
        );
        let coloured = rgb
            .chunks_exact(3)
            .filter(|c| (c[0] as i32 - c[2] as i32).abs() > 30)
            .count();
        assert!(
            coloured > 100,
            "frame {}: {coloured} coloured pixels",
            i + 1
        );
    }
    assert_eq!(seq.load_gray(7).unwrap().data, in_order[7].data);
    // `eval` over a dataset of videos gives the frames' success rates.
    let res = |root: &Path, out: &str| {
        let out = d.path().join(out);
        succeed(regtrack(&[
            "eval",
            "--dataset",
            root.to_str().unwrap(),
            "--sm",
            "esm,fclk",
            "--am",
            "ssd",
            "--out",
            out.to_str().unwrap(),
        ]));
        regtrack::eval::read_runs(&out).unwrap()
    };
    let (v, f) = (res(&videos, "rv"), res(&data, "rf"));
    for (a, b) in v.iter().zip(&f) {
        let (sa, sb) = (a.summary(), b.summary());
        assert_eq!(sa.sr5, sb.sr5, "{}", sa.tracker);
        assert!(
            (sa.mean_error - sb.mean_error).abs() < 0.5,
            "{} vs {}",
            sa.mean_error,
            sb.mean_error
        );
    }
    // Cut short: the run ends at the frame that cannot be decoded, keeping what was tracked.
    let bytes = std::fs::read(&clip).unwrap();
    let cut = d.path().join("cut");
    std::fs::create_dir_all(&cut).unwrap();
    std::fs::write(cut.join("rt.mp4"), &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = d.path().join("c.txt");
    std::fs::copy(data.join("rt.txt"), cut.join("rt.txt")).unwrap();
    let o = regtrack(&[
        "track",
        "--seq",
        cut.join("rt.mp4").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("rt.mp4 has") && err.contains("cut short"),
        "{err}"
    );
    // Its last packet is partial: the run ends there, naming the file and the frame.
    if !o.status.success() {
        assert!(
            err.contains("rt.mp4: frame") && err.contains("could not be decoded"),
            "{err}"
        );
    }
    let kept = read_ground_truth(&out).unwrap();
    assert!(
        kept.len() >= 5 && kept.len() < 30,
        "{} frames kept",
        kept.len()
    );
    // Not a video at all: one line naming the file.
    std::fs::write(cut.join("bad.mp4"), b"not a video").unwrap();
    let e = Sequence::open(&cut.join("bad.mp4"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bad.mp4") && e.contains("not a video") && !e.contains('\n'),
        "{e}"
    );
}

/// `track --render` and `eval --render` write annotated videos: every tracked frame, with the
/// tracked quad drawn in red where the tracker put it.
#[test]
fn an_annotated_video_shows_the_tracked_quad() {
    if !have_ffmpeg() {
        return;
    }
    use crate::cli::{regtrack, succeed, synth};
    let d = TempDir::new("render");
    let data = d.path().join("data");
    succeed(synth(
        "ucsb_bricks_rt.txt",
        &data,
        "rt",
        &["--frames", "12"],
    ));
    let video = d.path().join("out/rt.mp4");
    let corners = d.path().join("c.txt");
    succeed(regtrack(&[
        "track",
        "--seq",
        data.join("rt.txt").to_str().unwrap(),
        "--out",
        corners.to_str().unwrap(),
        "--render",
        video.to_str().unwrap(),
    ]));
    let clip = Sequence::open(&video).unwrap();
    assert_eq!(clip.len(), 12);
    // Frame 6 as RGB: red along the tracked quad's top edge, not elsewhere.
    let raw = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(&video)
        .args([
            "-vf",
            "select=eq(n\\,5)",
            "-frames:v",
            "1",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-",
        ])
        .output()
        .unwrap()
        .stdout;
    let (w, h) = (
        clip.load_gray(0).unwrap().width,
        clip.load_gray(0).unwrap().height,
    );
    assert_eq!(raw.len(), 3 * w * h);
    let tracked = read_ground_truth(&corners).unwrap()[5].quad.unwrap();
    let red = |x: f64, y: f64| {
        let k = 3 * (y.round() as usize * w + x.round() as usize);
        raw[k] > 150 && raw[k + 1] < 120 && raw[k + 2] < 120
    };
    let (a, b) = (tracked.0[0], tracked.0[1]);
    let on_edge = (1..10)
        .filter(|&s| {
            let t = s as f64 / 10.0;
            red(a.x + t * (b.x - a.x), a.y + t * (b.y - a.y))
        })
        .count();
    assert!(
        on_edge >= 7,
        "{on_edge} of 9 points of the top edge are red"
    );
    let c = tracked.centroid();
    assert!(!red(c.x, c.y), "the quad's centre is not drawn on");
    // eval: one video per run beside its files.
    let res = d.path().join("res");
    succeed(regtrack(&[
        "eval",
        "--dataset",
        data.to_str().unwrap(),
        "--sm",
        "esm",
        "--am",
        "ssd",
        "--out",
        res.to_str().unwrap(),
        "--render",
    ]));
    let per_run = res.join("tracking_data/rt/esm_ssd_homography.mp4");
    assert_eq!(Sequence::open(&per_run).unwrap().len(), 12);
}

/// The live path, on FFmpeg's `testsrc` (which arrives as a live stream through the same code
/// as a camera): frames as they come, those that arrive while a slow tracker works dropped and
/// counted, the run recorded as an MTF sequence that opens and replays, and a source that stops
/// early is an error naming it and the frame, keeping what was tracked.
#[test]
fn a_live_source_is_tracked_dropped_recorded_and_its_end_reported() {
    if !have_ffmpeg() {
        return;
    }
    use crate::cli::{regtrack, succeed};
    let d = TempDir::new("live");
    let out = d.path().join("c.txt");
    let (rec, rec2) = (d.path().join("rec"), d.path().join("rec_colour"));
    let live = |source: &str, frames: &str, extra: &[&str]| {
        regtrack(
            &[
                &[
                    "track",
                    "--camera",
                    source,
                    "--size",
                    "320x240",
                    "--init",
                    "100,60,220,60,220,180,100,180",
                    "--frames",
                    frames,
                    "--out",
                    out.to_str().unwrap(),
                ][..],
                extra,
            ]
            .concat(),
        )
    };
    let o = live(
        "lavfi:testsrc=size=320x240:rate=30",
        "20",
        &["--record", rec.to_str().unwrap()],
    );
    succeed(o.clone());
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("20 frames tracked"), "{said}");
    let recorded = Sequence::open(&rec.join("live.txt")).unwrap();
    assert_eq!(recorded.len(), 20);
    assert!(recorded.ground_truth(0).is_some());
    assert_eq!(read_ground_truth(&out).unwrap().len(), 20);
    // A colour tracker reads the camera in colour, and the recording keeps it (the test
    // source's bars differ in hue).
    let o = live(
        "lavfi:testsrc=size=320x240:rate=30",
        "8",
        &["--channels", "rgb", "--record", rec2.to_str().unwrap()],
    );
    succeed(o.clone());
    let recorded = Sequence::open(&rec2.join("live.txt")).unwrap();
    assert_eq!(recorded.len(), 8);
    let regtrack::imaging::Frame8::Colour(c) = recorded.load_frame(0, true).unwrap() else {
        panic!("read grey")
    };
    assert!(c.channels[0] != c.channels[1] && c.channels[1] != c.channels[2]);
    // A tracker slower than the camera (a 200x200 grid, 100 iterations a frame, no early stop)
    // drops frames, and says how many.
    let o = live(
        "lavfi:testsrc=size=320x240:rate=120",
        "15",
        &[
            "--sm",
            "esm",
            "--am",
            "ssd",
            "--res",
            "200",
            "--max_iters",
            "100",
            "--eps",
            "0",
        ],
    );
    succeed(o.clone());
    let said = String::from_utf8_lossy(&o.stdout);
    let dropped: u64 = said
        .split(", ")
        .find_map(|p| p.strip_suffix(" dropped"))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("{said}"));
    assert!(dropped > 0, "{said}");
    // The source stops after 10 frames of the 30 asked for.
    let o = live(
        "lavfi:testsrc=size=320x240:rate=30:duration=0.34",
        "30",
        &[],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("stopped after") && err.contains("(at live frame "),
        "{err}"
    );
    assert!(
        err.contains("testsrc") && err.trim().lines().count() == 1,
        "{err}"
    );
    let kept = read_ground_truth(&out).unwrap().len();
    assert!((5..30).contains(&kept), "{kept} frames kept");
}

/// A frame that is not an image says so in the user's terms, naming the file (not "cannot
/// decode or encode image").
#[test]
fn a_frame_that_is_no_image_is_named_as_such() {
    let d = TempDir::new("not-an-image");
    let f = d.path().join("frame00001.jpg");
    std::fs::write(&f, b"notanimage at all").unwrap();
    let e = regtrack::imaging::load_gray(&f).unwrap_err().to_string();
    assert!(e.starts_with("cannot read the image "), "{e}");
    assert!(
        e.contains("frame00001.jpg") && e.contains("damaged or not the image"),
        "{e}"
    );
    let g = d.path().join("frame00002.png");
    std::fs::write(&g, [0u8; 64]).unwrap();
    let e = regtrack::imaging::load_gray(&g).unwrap_err().to_string();
    assert!(
        e.contains("cannot read the image") && e.contains("frame00002.png"),
        "{e}"
    );
}
