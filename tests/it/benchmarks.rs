//! The benchmarks' own layouts (POT, PlanarTrack, UCSB, VOT, GOT-10k, LaSOT), their metrics and
//! their results formats, on small fixtures written here in each layout (never the data
//! itself), with the formats' corner cases: unlabelled rows, flags, every other frame
//! annotated, 0- and 1-based frame names, CRLF, stray files.

use crate::cli::{regtrack, succeed};
use crate::common::{TempDir, texture};
use regtrack::dataset::regions::{Region, parse_vot_regions};
use regtrack::dataset::{Layout, Sequence, discover};
use regtrack::eval::{self, Batch, EvalOptions, ResultsFormat, RunResult};
use regtrack::geometry::homography_between;
use regtrack::geometry::{Point, Quad};
use regtrack::tracker::TrackerSpec;
use std::path::Path;

/// Frames of the brick texture moving 1 px right and 0.5 px down a frame, and the target's
/// corners in each: frame `k` is written as `dir/<name(k)>`.
fn write_frames(dir: &Path, n: usize, name: impl Fn(usize) -> String) -> Vec<Quad> {
    std::fs::create_dir_all(dir).unwrap();
    let tex = texture("skimage_brick.png");
    let (w, h) = (120usize, 90usize);
    let base = Quad::from_rect(40.0, 30.0, 40.0, 30.0);
    (0..n)
        .map(|k| {
            let (dx, dy) = (k as f64, 0.5 * k as f64);
            let img = image::GrayImage::from_fn(w as u32, h as u32, |x, y| {
                // Bilinear sample of the texture at (x - dx + 60, y - dy + 60).
                let (sx, sy) = (x as f64 - dx + 60.0, y as f64 - dy + 60.0);
                let (x0, y0) = (sx.floor() as usize, sy.floor() as usize);
                let (fx, fy) = (sx - x0 as f64, sy - y0 as f64);
                let at = |x: usize, y: usize| tex.data[y * tex.width + x] as f64;
                let v = at(x0, y0) * (1.0 - fx) * (1.0 - fy)
                    + at(x0 + 1, y0) * fx * (1.0 - fy)
                    + at(x0, y0 + 1) * (1.0 - fx) * fy
                    + at(x0 + 1, y0 + 1) * fx * fy;
                image::Luma([v.round() as u8])
            });
            img.save(dir.join(name(k))).unwrap();
            base.map(|p| Point::new(p.x + dx, p.y + dy))
        })
        .collect()
}

fn row(q: &Quad) -> String {
    q.to_array()
        .iter()
        .map(|v| format!("{v:.6}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn write(path: &Path, text: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// The homography row (9 numbers) taking `from` to `to`.
fn h_row(from: &Quad, to: &Quad) -> String {
    let h = homography_between(from, to).unwrap();
    h.transpose()
        .iter()
        .map(|v| format!("{v:.9}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn runs(seqs: &[Sequence], reinit: bool) -> Vec<RunResult> {
    let spec = TrackerSpec::from_names("fclk", "ssd", "homography").unwrap();
    let batch = Batch {
        options: EvalOptions {
            reinit,
            ..EvalOptions::default()
        },
        ..Batch::new(seqs, std::slice::from_ref(&spec))
    };
    let outcome = batch.run(&|_| {}).unwrap();
    assert!(outcome.failures.is_empty(), "{:?}", outcome.failures);
    outcome.runs
}

/// POT as downloaded: the annotations in `annotation/annotation/` (CRLF), frames extracted per
/// object (`V01/V01_1/0001.png`, 1-based) or beside (`V01_5/0000.png`, 0-based); 9 lines for 9
/// frames whose even ones (1-based) are zeros, a flagged frame, homographies; a file of the
/// annotated frames only (half as many lines). The challenge factor from the name pools the
/// results.
#[test]
fn pot_as_downloaded_is_read_scored_and_pooled_by_challenge_factor() {
    let d = TempDir::new("pot");
    let root = d.path();
    let ann = root.join("annotation").join("annotation");
    let q1 = write_frames(&root.join("V01").join("V01_1"), 9, |k| {
        format!("{:04}.png", k + 1)
    });
    let (mut points, mut homs, mut flags) = (String::new(), String::new(), String::new());
    for (k, q) in q1.iter().enumerate() {
        if k % 2 == 1 {
            points.push_str(&format!("{}\r\n", row(&Quad([Point::new(0.0, 0.0); 4]))));
            homs.push_str("0 0 0 0 0 0 0 0 0\r\n");
        } else {
            points.push_str(&format!("{}\r\n", row(q)));
            homs.push_str(&format!("{}\r\n", h_row(&q1[0], q)));
        }
        // Frame 5 (k = 4) is annotated but more than half out of view.
        flags.push_str(if k == 4 { "2\r\n" } else { "0\r\n" });
    }
    write(&ann.join("V01_1_gt_points.txt"), &points);
    write(&ann.join("V01_1_gt_homography.txt"), &homs);
    write(&ann.join("V01_1_flag.txt"), &flags);
    let q5 = write_frames(&root.join("V01_5"), 9, |k| format!("{k:04}.png"));
    let half: String = q5
        .iter()
        .step_by(2)
        .map(|q| format!("{}\n", row(q)))
        .collect();
    write(&ann.join("V01_5_gt_points.txt"), &half);

    let seqs = discover(root, None).unwrap();
    let names: Vec<&str> = seqs.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["V01_1", "V01_5"]);
    let (a, b) = (&seqs[0], &seqs[1]);
    assert!(a.layout == Layout::Pot && b.layout == Layout::Pot);
    assert_eq!(a.factors, ["scale"]);
    assert_eq!(b.factors, ["occlusion"]);
    let annotated: Vec<usize> = (0..9).filter(|&k| a.ground_truth(k).is_some()).collect();
    assert_eq!(
        annotated,
        [0, 2, 6, 8],
        "zeros and the flag are not annotated"
    );
    assert!((a.ground_truth(2).unwrap().0[0].x - q1[2].0[0].x).abs() < 1e-5);
    assert_eq!(a.homographies.len(), 9);
    assert!(a.homographies[2].is_some() && a.homographies[4].is_none());
    let annotated: Vec<usize> = (0..9).filter(|&k| b.ground_truth(k).is_some()).collect();
    assert_eq!(annotated, [0, 2, 4, 6, 8], "every other frame");
    assert!(
        a.warnings.is_empty() && b.warnings.is_empty(),
        "{:?}",
        a.warnings
    );
    // The annotation file given alone is opened with its flags and frames.
    let alone = Sequence::open(&ann.join("V01_1_gt_points.txt")).unwrap();
    assert_eq!(alone.ground_truth, a.ground_truth);

    // Scored: P@t, success by homography discrepancy and IoU, pooled per factor.
    let runs = runs(&seqs, false);
    for r in &runs {
        let scored: Vec<_> = r
            .frames
            .iter()
            .filter(|f| !f.init && f.ground_truth.is_some())
            .collect();
        assert!(!scored.is_empty());
        for f in scored {
            assert!(
                f.homography_error < 0.5,
                "frame {}: {}",
                f.frame,
                f.homography_error
            );
        }
    }
    let rows = eval::summary_rows(&runs);
    let label = |s: &str| {
        rows.iter()
            .find(|r| r.sequence == s)
            .unwrap_or_else(|| panic!("{s}"))
    };
    let all = label("ALL");
    assert_eq!(all.frames, 3 + 4);
    assert_eq!((all.p5, all.p15), (1.0, 1.0));
    assert!(all.success_h > 0.95 && all.success_iou > 0.9, "{all:?}");
    assert_eq!(label("ALL:scale").frames, 3);
    assert_eq!(label("ALL:occlusion").frames, 4);

    // A stray file or a sequence without its frames is named.
    write(&ann.join("V02_3_flag.txt"), "0\n");
    let e = discover(root, None).unwrap_err().to_string();
    assert!(
        e.contains("V02_3_flag.txt") && e.contains("corner file is missing"),
        "{e}"
    );
    std::fs::remove_file(ann.join("V02_3_flag.txt")).unwrap();
    write(&ann.join("V03_2_gt_points.txt"), &half);
    let e = discover(root, None).unwrap_err().to_string();
    assert!(
        e.contains("V03_2_gt_points.txt") && e.contains("without its frames"),
        "{e}"
    );
    // Asked for by name, the others are not checked.
    let one = discover(root, Some(&["V01_5".to_string()])).unwrap();
    assert_eq!(one.len(), 1);
}

/// PlanarTrack: `Seq_xxxxx.txt` with all-zero rows for frames not labelled (trailing spaces,
/// CRLF), its flags, homographies and attributes; results written as its toolkit reads them.
#[test]
fn planartrack_is_read_and_its_results_written_as_its_toolkit_reads_them() {
    let d = TempDir::new("planartrack");
    let root = d.path();
    let ann = root.join("annotation");
    let q = write_frames(&root.join("sequences").join("Seq_00007"), 8, |k| {
        format!("{:05}.png", k + 1)
    });
    let (mut points, mut flags, mut homs) = (String::new(), String::new(), String::new());
    for (k, quad) in q.iter().enumerate() {
        let unlabelled = k == 3 || k == 4;
        if unlabelled {
            points.push_str(&format!("{} \r\n", row(&Quad([Point::new(0.0, 0.0); 4]))));
            homs.push_str("1.0000 0.0000 0.0000 0.0000 1.0000 0.0000 0.0000 0.0000 1.0000\n");
        } else {
            points.push_str(&format!("{} \r\n", row(quad)));
            homs.push_str(&format!("{}\n", h_row(&q[0], quad)));
        }
        flags.push_str(if unlabelled { "1 \r\n" } else { "0 \r\n" });
    }
    write(&ann.join("Seq_00007.txt"), &points);
    write(&ann.join("Seq_00007_flag.txt"), &flags);
    write(&ann.join("Seq_00007_homography.txt"), &homs);
    write(
        &ann.join("challenging_factor")
            .join("Seq_00007_challenging_factor.txt"),
        "0,1,1,0,0,0,0,1\n",
    );
    let seqs = discover(root, None).unwrap();
    assert_eq!(seqs.len(), 1);
    let s = &seqs[0];
    assert_eq!(
        (s.name.as_str(), s.layout),
        ("Seq_00007", Layout::PlanarTrack)
    );
    assert_eq!(s.factors, ["blur", "rotation", "background_clutter"]);
    assert!(s.ground_truth(3).is_none() && s.ground_truth(4).is_none());
    assert_eq!((0..8).filter(|&k| s.ground_truth(k).is_some()).count(), 6);

    let runs = runs(&seqs, false);
    let out = root.join("results");
    let files = eval::write_results(&runs, ResultsFormat::PlanarTrack, &out).unwrap();
    let tracker = runs[0].spec.label();
    let corners = out.join(&tracker).join(format!("Seq_00007_{tracker}.txt"));
    let homs = out
        .join(&tracker)
        .join(format!("Seq_00007_{tracker}_homography.txt"));
    assert_eq!(files, [corners.clone(), homs.clone()]);
    let c = std::fs::read_to_string(&corners).unwrap();
    let h = std::fs::read_to_string(&homs).unwrap();
    assert_eq!((c.lines().count(), h.lines().count()), (8, 8));
    let first_h: Vec<f64> = h
        .lines()
        .next()
        .unwrap()
        .split(' ')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(first_h, [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    // The rows are the tracker's corners, as PlanarTrack's toolkit reads them back.
    for (line, f) in c.lines().zip(&runs[0].frames) {
        let v: Vec<f64> = line.split(' ').map(|v| v.parse().unwrap()).collect();
        let q = f.corners.unwrap();
        for (a, b) in v.iter().zip(q.to_array()) {
            assert!((a - b).abs() < 1e-3);
        }
    }
}

/// UCSB: a `.warps` homography a frame (the frame's pixels to the reference plane, mm); the
/// corners are the reference region mapped back.
#[test]
fn ucsb_warps_give_the_reference_region_in_each_frame() {
    let d = TempDir::new("ucsb");
    let root = d.path();
    let q = write_frames(&root.join("fi-br-m1"), 4, |k| format!("frame{:04}.png", k));
    let reference = Quad::from_array(regtrack::dataset::layouts::UCSB_REFERENCE);
    // The plane to each frame: the reference region onto the target; the file holds its inverse.
    let mut warps = String::new();
    for quad in &q {
        let to_frame = homography_between(&reference, quad).unwrap();
        let to_plane = to_frame.try_inverse().unwrap();
        let v: Vec<String> = to_plane
            .transpose()
            .iter()
            .map(|x| format!("{x:e}"))
            .collect();
        warps.push_str(&format!("{}\n", v.join(" ")));
    }
    write(
        &root.join("ground_truth").join("fi-br-m1.avi.warps"),
        &warps,
    );
    let seqs = discover(root, None).unwrap();
    let s = &seqs[0];
    assert_eq!((s.name.as_str(), s.layout), ("fi-br-m1", Layout::Ucsb));
    assert_eq!(s.factors, ["m1"]);
    for (k, quad) in q.iter().enumerate() {
        let g = s.ground_truth(k).unwrap();
        assert!(
            regtrack::geometry::alignment_error(&g, quad) < 1e-6,
            "frame {k}"
        );
    }
}

/// VOT, GOT-10k and LaSOT folders in one root, `list.txt` giving their order; VOT results
/// written with the codes of a re-initialised run and read back.
#[test]
fn vot_got10k_and_lasot_folders_and_vot_results() {
    let d = TempDir::new("vot");
    let root = d.path();
    // VOT: a `sequence` file naming `color/%08d.jpg` frames (PNG here), polygons and a box.
    let v = write_frames(&root.join("ball").join("color"), 5, |k| {
        format!("{:08}.png", k + 1)
    });
    write(
        &root.join("ball").join("sequence"),
        "channels.color=color/%08d.png\nfps=30\n",
    );
    let mut gt = String::new();
    for (k, q) in v.iter().enumerate() {
        if k == 2 {
            let r = q.bbox();
            gt.push_str(&format!("{},{},{},{}\n", r.x0, r.y0, r.width(), r.height()));
        } else {
            let a = q.to_array();
            gt.push_str(
                &a.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join(","),
            );
            gt.push('\n');
        }
    }
    write(&root.join("ball").join("groundtruth.txt"), &gt);
    write(&root.join("ball").join("occlusion.tag"), "0\n0\n1\n0\n0\n");
    // GOT-10k: boxes, an absent frame.
    let g = write_frames(&root.join("GOT-10k_Val_000001"), 4, |k| {
        format!("{:08}.png", k + 1)
    });
    let boxes: String = g
        .iter()
        .map(|q| {
            let r = q.bbox();
            format!(
                "{:.4},{:.4},{:.4},{:.4}\r\n",
                r.x0,
                r.y0,
                r.width(),
                r.height()
            )
        })
        .collect();
    write(
        &root.join("GOT-10k_Val_000001").join("groundtruth.txt"),
        &boxes,
    );
    write(
        &root.join("GOT-10k_Val_000001").join("absence.label"),
        "0\n0\n1\n0\n",
    );
    // LaSOT: `<class>/<class>-N/img/`, 1-based boxes, occlusion and out-of-view on one line.
    let l = write_frames(&root.join("cup").join("cup-3").join("img"), 4, |k| {
        format!("{:08}.png", k + 1)
    });
    let boxes: String = l
        .iter()
        .map(|q| {
            let r = q.bbox();
            format!(
                "{},{},{},{}\n",
                r.x0 + 1.0,
                r.y0 + 1.0,
                r.width(),
                r.height()
            )
        })
        .collect();
    let cup = root.join("cup").join("cup-3");
    write(&cup.join("groundtruth.txt"), &boxes);
    write(&cup.join("full_occlusion.txt"), "0,0,0,1\n");
    write(&cup.join("out_of_view.txt"), "0,1,0,0\n");
    write(&root.join("list.txt"), "GOT-10k_Val_000001\nball\ncup-3\n");

    let seqs = discover(root, None).unwrap();
    let got: Vec<(&str, Layout)> = seqs.iter().map(|s| (s.name.as_str(), s.layout)).collect();
    assert_eq!(
        got,
        [
            ("GOT-10k_Val_000001", Layout::Got10k),
            ("ball", Layout::Vot),
            ("cup-3", Layout::Lasot)
        ]
    );
    let (gs, vs, ls) = (&seqs[0], &seqs[1], &seqs[2]);
    assert!(gs.ground_truth(2).is_none() && gs.ground_truth(3).is_some());
    assert!(regtrack::geometry::alignment_error(&gs.ground_truth(0).unwrap(), &g[0]) < 1e-3);
    assert_eq!(vs.len(), 5);
    assert!(regtrack::geometry::alignment_error(&vs.ground_truth(4).unwrap(), &v[4]) < 1e-9);
    assert_eq!(
        vs.ground_truth(2).unwrap(),
        v[2],
        "a box is its four corners"
    );
    assert!(ls.ground_truth(1).is_none() && ls.ground_truth(3).is_none());
    assert!(regtrack::geometry::alignment_error(&ls.ground_truth(2).unwrap(), &l[2]) < 1e-9);
    // A VOT folder given alone.
    assert_eq!(
        Sequence::open(&root.join("ball")).unwrap().ground_truth,
        vs.ground_truth
    );

    // VOT results: 1 on the initialisation, the polygon, 2 on a failure, 0 after it.
    let mut runs = runs(std::slice::from_ref(vs), true);
    let frames = &mut runs[0].frames;
    frames[2].corners = None;
    frames[3].corners = None;
    let out = root.join("vot-results");
    let files = eval::write_results(&runs, ResultsFormat::Vot, &out).unwrap();
    let tracker = runs[0].spec.label();
    assert_eq!(
        files,
        [out.join(&tracker)
            .join("baseline")
            .join("ball")
            .join("ball_001.txt")]
    );
    let text = std::fs::read_to_string(&files[0]).unwrap();
    let back = parse_vot_regions(&files[0], &text).unwrap();
    assert_eq!(back.len(), 5);
    assert_eq!(back[0], Region::Code(1));
    assert_eq!(
        (back[2].clone(), back[3].clone()),
        (Region::Code(2), Region::Code(0))
    );
    let q = back[1].quad().unwrap();
    assert!(regtrack::geometry::alignment_error(&q, &runs[0].frames[1].corners.unwrap()) < 1e-3);
    // GOT-10k and LaSOT boxes.
    let files = eval::write_results(&runs, ResultsFormat::Lasot, &out).unwrap();
    let first = std::fs::read_to_string(&files[0]).unwrap();
    let b: Vec<f64> = first
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let r = runs[0].frames[1].corners.unwrap().bbox();
    assert!((b[0] - (r.x0 + 1.0)).abs() < 1e-3 && (b[2] - r.width()).abs() < 1e-3);
    // GOT-10k: boxes from 0 and a time a frame.
    let files = eval::write_results(&runs, ResultsFormat::Got10k, &out).unwrap();
    let dir = out.join(&tracker).join("ball");
    assert_eq!(files, [dir.join("ball_001.txt"), dir.join("ball_time.txt")]);
    let boxes = std::fs::read_to_string(&files[0]).unwrap();
    let x: f64 = boxes
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((x - r.x0).abs() < 1e-3);
    assert_eq!(
        std::fs::read_to_string(&files[1]).unwrap().lines().count(),
        5
    );
}

/// A root mixing layouts is read when every file finds its sequence, and a file that does not
/// is named with the reason.
#[test]
fn a_root_mixing_layouts_names_the_file_it_could_not_place() {
    let d = TempDir::new("mixed");
    let root = d.path();
    let q = write_frames(&root.join("book"), 3, |k| format!("frame{:05}.png", k + 1));
    regtrack::dataset::write_corners(
        &root.join("book.txt"),
        &q.iter().copied().map(Some).collect::<Vec<_>>(),
        "png",
    )
    .unwrap();
    let p = write_frames(&root.join("V07_2"), 3, |k| format!("{:04}.png", k + 1));
    let text: String = p.iter().map(|q| format!("{}\n", row(q))).collect();
    write(&root.join("V07_2_gt_points.txt"), &text);
    let seqs = discover(root, None).unwrap();
    let got: Vec<(&str, Layout)> = seqs.iter().map(|s| (s.name.as_str(), s.layout)).collect();
    assert_eq!(got, [("V07_2", Layout::Pot), ("book", Layout::Mtf)]);
    assert_eq!(seqs[0].factors, ["rotation"]);
    // Files the tools write beside a sequence and read-me files are not sequences.
    write(&root.join("book_gt_affine.txt"), "");
    write(&root.join("README.txt"), "about\n");
    assert_eq!(discover(root, None).unwrap().len(), 2);
    write(&root.join("notes.txt"), "1 2 3 4 5 6 7 8\n");
    let e = discover(root, None).unwrap_err().to_string();
    assert!(
        e.contains("notes.txt") && e.contains("not a sequence of any layout"),
        "{e}"
    );
}

/// `regtrack eval` on POT as downloaded prints the benchmarks' figures and the factors' rows;
/// `regtrack export` writes the files PlanarTrack's and POT's evaluations read.
#[test]
fn eval_and_export_on_the_command_line() {
    let d = TempDir::new("bench-cli");
    let root = d.path().join("POT");
    for (name, k) in [("V02_4", 4usize), ("V03_4", 5)] {
        let q = write_frames(&root.join(name), k, |i| format!("{:04}.png", i + 1));
        let text: String = q.iter().map(|q| format!("{}\n", row(q))).collect();
        write(
            &root
                .join("annotation")
                .join(format!("{name}_gt_points.txt")),
            &text,
        );
    }
    let out = d.path().join("out");
    let o = regtrack(&[
        "eval",
        "--dataset",
        root.to_str().unwrap(),
        "--sm",
        "fclk",
        "--am",
        "ssd",
        "--ssm",
        "homography",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    succeed(o);
    assert!(
        stdout.contains("P@5") && stdout.contains("ALL:blur"),
        "{stdout}"
    );
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    for col in ["p5", "p15", "success_h", "success_iou"] {
        assert!(header.contains(&col), "{header:?}");
    }
    // One sequence of the dataset, its annotation file given alone.
    let one = d.path().join("one");
    let o = regtrack(&[
        "eval",
        "--dataset",
        root.join("annotation")
            .join("V03_4_gt_points.txt")
            .to_str()
            .unwrap(),
        "--sm",
        "fclk",
        "--am",
        "ssd",
        "--ssm",
        "homography",
        "--out",
        one.to_str().unwrap(),
    ]);
    succeed(o);
    let csv = std::fs::read_to_string(one.join("summary.csv")).unwrap();
    assert!(csv.lines().nth(1).unwrap().starts_with("V03_4,"), "{csv}");
    let dest = d.path().join("pt");
    succeed(regtrack(&[
        "export",
        "--format",
        "pot",
        "--out",
        dest.to_str().unwrap(),
        out.to_str().unwrap(),
    ]));
    let tracker = "fclk_ssd_homography";
    let f = dest.join(tracker).join(format!("V03_4_{tracker}.txt"));
    assert_eq!(std::fs::read_to_string(&f).unwrap().lines().count(), 5);
    let bad = regtrack(&[
        "export",
        "--format",
        "otb",
        "--out",
        "x",
        out.to_str().unwrap(),
    ]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown results format 'otb'"));
    // The report has the benchmarks' table and curves.
    let rep = d.path().join("report");
    succeed(regtrack(&[
        "report",
        "--out",
        rep.to_str().unwrap(),
        out.to_str().unwrap(),
    ]));
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(md.contains("| P@5 | P@15 | S(H) | S(IoU) |") && md.contains("Per challenge factor"));
    let curves = std::fs::read_to_string(rep.join("benchmark_curves.csv")).unwrap();
    assert!(curves.contains(",precision,5,") && curves.contains(",success_h,200,"));
}

/// POT as its videos are downloaded (`V04/V04_6.avi`, MJPEG here), the annotations apart: the
/// sequence is the video's frames, scored as the extracted frames are.
#[test]
fn pot_videos_as_downloaded_are_sequences() {
    if !crate::dataset::have_ffmpeg() {
        return;
    }
    let d = TempDir::new("pot-video");
    let root = d.path().join("POT");
    let frames = d.path().join("frames");
    let q = write_frames(&frames, 9, |k| format!("{:04}.png", k + 1));
    std::fs::create_dir_all(root.join("V04")).unwrap();
    let made = std::process::Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-framerate",
            "25",
            "-start_number",
            "1",
            "-i",
        ])
        .arg(frames.join("%04d.png"))
        .args(["-c:v", "mjpeg", "-q:v", "1", "-pix_fmt", "yuvj420p"])
        .arg(root.join("V04").join("V04_6.avi"))
        .status()
        .unwrap();
    assert!(made.success());
    let points: String = q.iter().map(|q| format!("{}\n", row(q))).collect();
    write(
        &root
            .join("annotation")
            .join("annotation")
            .join("V04_6_gt_points.txt"),
        &points,
    );
    let seqs = discover(&root, None).unwrap();
    assert_eq!(seqs.len(), 1);
    let s = &seqs[0];
    assert!(s.video.is_some() && s.len() == 9, "{:?}", s.frames.first());
    assert_eq!(
        (s.layout, s.factors.as_slice()),
        (Layout::Pot, &["out_of_view".to_string()][..])
    );
    let rows = eval::summary_rows(&runs(&seqs, false));
    assert!(
        rows[0].p5 == 1.0 && rows[0].success_h > 0.9,
        "{:?}",
        rows[0]
    );
}
