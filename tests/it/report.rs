//! `regtrack report`: figures and table of an evaluation, pooled shards, clear errors; and the
//! grouping of trackers into figures.

use crate::cli::{regtrack, succeed, synth};
use crate::common::TempDir;
use regtrack::eval::Summary;
use regtrack::report::{self, FigureKind, TrackerResult};
use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The rows of report.md's table, split into cells.
fn table(md: &str) -> Vec<Vec<String>> {
    // The first table (the benchmarks' figures follow in tables of their own).
    md.lines()
        .skip_while(|l| !l.starts_with("| tracker |"))
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .filter(|l| l.starts_with("| "))
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_string())
                .collect()
        })
        .collect()
}

/// Checks a PNG figure: its size, curves or bars in the palette's first colour, text in the title
/// band, and not mostly blank.
fn check_png(path: &Path, width: u32, height: u32) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    assert_eq!(img.dimensions(), (width, height), "{}", path.display());
    let drawn = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    assert!(
        drawn > (width * height / 50) as usize,
        "{} is almost blank ({drawn} pixels drawn)",
        path.display()
    );
    let first = report::curve_style(0).0;
    assert!(
        img.pixels().any(|p| p.0 == [first.0, first.1, first.2]),
        "{}: no curve or bar",
        path.display()
    );
    let title_ink = (0..40)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c < 100))
        .count();
    assert!(title_ink > 100, "{}: no title text", path.display());
}

#[test]
fn report_of_an_evaluation_and_of_its_shards() {
    let d = TempDir::new("report");
    let data = d.path().join("data");
    succeed(synth(
        "ucsb_bricks_m3.txt",
        &data,
        "m3",
        &["--frames", "20", "--noise", "2"],
    ));
    let eval = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--dataset",
            s(&data),
            "--sm",
            "esm,iclk",
            "--am",
            "ssd,zncc",
            "--jobs",
            "2",
            "--out",
            s(out),
        ];
        args.extend_from_slice(extra);
        succeed(regtrack(&args));
    };
    let res = d.path().join("res");
    eval(&res, &[]);
    let out = regtrack(&["report", s(&res)]);
    succeed(out.clone());
    assert!(String::from_utf8_lossy(&out.stdout).contains("report.md"));

    let rep = res.join("report");
    let labels = [
        "esm_ssd_homography",
        "esm_zncc_homography",
        "iclk_ssd_homography",
        "iclk_zncc_homography",
    ];
    // (a) the SMs for each AM, (b) the AMs for each SM; every tracker is in one, so no others.
    let stems = [
        "sr_am_ssd",
        "sr_am_zncc",
        "sr_sm_esm",
        "sr_sm_iclk",
        "speed",
    ];
    for stem in stems {
        let (w, h) = report::FIGURE_SIZE;
        check_png(&rep.join(format!("{stem}.png")), w, h);
        let svg = std::fs::read_to_string(rep.join(format!("{stem}.svg"))).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("</svg>"), "{stem}");
        if stem == "speed" {
            for l in labels {
                assert!(svg.contains(l), "{l} missing from speed.svg");
            }
            assert!(svg.contains("log scale"));
        } else {
            assert!(svg.contains("error threshold t (px)") && svg.contains("success rate"));
        }
    }
    let svg = std::fs::read_to_string(rep.join("sr_am_ssd.svg")).unwrap();
    assert!(svg.contains("esm (") && svg.contains("iclk ("), "legend");
    assert!(!rep.join("sr_others.png").exists());

    // The table: one row per tracker, best mean SR first, with the numbers of summary.json.
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    let rows = table(&md);
    assert_eq!(rows.len(), 4, "{md}");
    let summary: Vec<Summary> =
        serde_json::from_str(&std::fs::read_to_string(res.join("summary.json")).unwrap()).unwrap();
    for l in labels {
        let row = rows
            .iter()
            .find(|r| r[0] == l)
            .unwrap_or_else(|| panic!("{l}: {md}"));
        // One sequence: its row is the tracker's pooled one.
        let want = summary.iter().find(|r| r.tracker == l).unwrap();
        assert_eq!(row[1], want.frames.to_string());
        let close = |cell: &str, v: f64, tol: f64| {
            let got: f64 = cell.parse().unwrap();
            assert!((got - v).abs() <= tol, "{l}: {cell} vs {v}");
        };
        close(&row[2], want.sr5, 5e-5);
        close(&row[3], want.sr10, 5e-5);
        close(&row[4], want.sr20, 5e-5);
        close(&row[5], want.mean_sr, 5e-5);
        close(&row[6], want.mean_error, 5e-5);
        assert_eq!(row[7], want.failures.to_string());
        close(&row[8], want.iterations_per_frame, 5e-3);
        close(&row[9], want.tracker_fps, 0.05);
        close(&row[10], want.live_fps, 0.05);
    }
    let mean: Vec<f64> = rows.iter().map(|r| r[5].parse().unwrap()).collect();
    assert!(mean.windows(2).all(|w| w[0] >= w[1]), "sorted: {mean:?}");
    // Every embedded figure exists, with relative links.
    let links: Vec<&str> = md
        .match_indices("](")
        .map(|(i, _)| &md[i + 2..i + 2 + md[i + 2..].find(')').unwrap()])
        .collect();
    assert_eq!(links.len(), 2 * stems.len(), "{links:?}");
    for l in links {
        assert!(!l.contains('/') && rep.join(l).is_file(), "{l}");
    }
    // Deterministic: the same report again.
    let again = d.path().join("again");
    succeed(regtrack(&["report", s(&res), "--out", s(&again)]));
    assert_eq!(
        md,
        std::fs::read_to_string(again.join("report.md")).unwrap()
    );
    assert_eq!(
        std::fs::read(rep.join("sr_am_ssd.png")).unwrap(),
        std::fs::read(again.join("sr_am_ssd.png")).unwrap()
    );

    // Two shards, given as two folders, pool to the same accuracy rows (timings differ).
    let (p0, p1) = (d.path().join("part0"), d.path().join("part1"));
    eval(&p0, &["--shard", "0/2"]);
    eval(&p1, &["--shard", "1/2"]);
    let merged = d.path().join("merged");
    succeed(regtrack(&["report", s(&p0), s(&p1), "--out", s(&merged)]));
    let accuracy = |rows: Vec<Vec<String>>| -> Vec<Vec<String>> {
        rows.into_iter().map(|r| r[..9].to_vec()).collect()
    };
    let shard_md = std::fs::read_to_string(merged.join("report.md")).unwrap();
    assert_eq!(accuracy(table(&shard_md)), accuracy(rows));

    // A run given twice would count twice.
    let out = regtrack(&["report", s(&res), s(&p0), "--out", s(&merged)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("also in") && err.contains(s(&res)), "{err}");
}

#[test]
fn report_errors_name_the_folder() {
    let d = TempDir::new("report-empty");
    let out = regtrack(&["report", s(d.path())]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(s(d.path())) && err.contains("no evaluation runs"),
        "{err}"
    );
    assert!(!d.path().join("report").exists());
    // A tracking_data folder without run files is no better.
    std::fs::create_dir_all(d.path().join("tracking_data/seq")).unwrap();
    let err = regtrack::eval::read_all_runs(&[d.path().to_path_buf()]).unwrap_err();
    assert!(
        matches!(&err, regtrack::Error::Report { path, .. } if path == d.path()),
        "{err}"
    );
    let missing = d.path().join("nonexistent");
    let out = regtrack(&["report", s(&missing)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains(s(&missing)));
}

/// A pooled tracker with a straight SR curve reaching `mean_sr`.
fn tracker(sm: &str, am: &str, ssm: &str, mean_sr: f64) -> TrackerResult {
    let label = if ssm.is_empty() {
        sm.to_string()
    } else {
        format!("{sm}_{am}_{ssm}")
    };
    TrackerResult {
        summary: Summary {
            sequence: "ALL".into(),
            tracker: label,
            sm: sm.into(),
            am: am.into(),
            ssm: ssm.into(),
            frames: 100,
            sr5: mean_sr,
            sr10: mean_sr,
            sr20: mean_sr,
            mean_sr,
            mean_error: 1.0,
            failures: 0,
            iterations_per_frame: 5.0,
            tracker_fps: 100.0 + 1000.0 * mean_sr,
            live_fps: 90.0,
            error_type: "alignment".into(),
            gt: "full".into(),
            lost_when_off: 1.0,
            lost_when_on: 0.0,
            stopped: 0,
            p5: mean_sr,
            p15: mean_sr,
            success_h: mean_sr,
            success_iou: mean_sr,
        },
        sequences: vec!["a".into()],
        precision: Vec::new(),
        discrepancy: Vec::new(),
        iou: Vec::new(),
        factors: Vec::new(),
        curve: regtrack::eval::thresholds()
            .into_iter()
            .map(|t| (t, (t / 10.0).min(1.0) * mean_sr))
            .collect(),
    }
}

#[test]
fn trackers_are_grouped_by_module() {
    let mut ts = vec![
        tracker("esm", "ssd", "homography", 0.9),
        tracker("iclk", "ssd", "homography", 0.8),
        tracker("esm", "zncc", "homography", 0.7),
        tracker("iclk", "zncc", "homography", 0.6),
        tracker("esm", "ssd", "affine", 0.5),
        tracker("fclk", "ncc", "affine", 0.4),
        tracker("dsst", "", "", 0.3),
    ];
    ts.sort_by(|a, b| a.summary.tracker.cmp(&b.summary.tracker));
    assert_eq!(report::comparison_ssm(&ts).as_deref(), Some("homography"));
    let figs = report::sr_figures(&ts);
    let got: Vec<(FigureKind, &str, Vec<&str>)> = figs
        .iter()
        .map(|f| {
            (
                f.kind,
                f.stem.as_str(),
                f.curves.iter().map(|c| c.name.as_str()).collect(),
            )
        })
        .collect();
    use FigureKind::*;
    assert_eq!(
        got,
        vec![
            (SmsPerAm, "sr_am_ssd", vec!["esm", "iclk"]),
            (SmsPerAm, "sr_am_zncc", vec!["esm", "iclk"]),
            (AmsPerSm, "sr_sm_esm", vec!["ssd", "zncc"]),
            (AmsPerSm, "sr_sm_iclk", vec!["ssd", "zncc"]),
            (Ssms, "sr_ssm_esm_ssd", vec!["homography", "affine"]),
            (Others, "sr_others", vec!["fclk_ncc_affine", "dsst"]),
        ]
    );
    // Without homography, the SSM most trackers used.
    let affine: Vec<TrackerResult> = ["esm", "iclk", "fclk"]
        .iter()
        .map(|sm| tracker(sm, "ssd", "affine", 0.5))
        .chain([tracker("esm", "ssd", "translation", 0.5)])
        .collect();
    assert_eq!(report::comparison_ssm(&affine).as_deref(), Some("affine"));

    // Too many curves for one figure: parts, the later curves dashed; drawn at the given size.
    let many: Vec<TrackerResult> = (0..14)
        .map(|i| tracker(&format!("whole{i:02}"), "", "", 0.2 + 0.05 * i as f64))
        .collect();
    let figs = report::sr_figures(&many);
    assert_eq!(figs.len(), 2);
    assert_eq!(figs[0].title, "All trackers (1/2)");
    assert_eq!(figs[0].curves.len(), report::MAX_CURVES);
    assert_eq!(figs[1].stem, "sr_others_2");
    assert!(report::curve_style(11).1 && !report::curve_style(9).1);
    let d = TempDir::new("report-figures");
    let png = d.path().join("many.png");
    report::draw_sr_figure(&png, &figs[0], (900, 600)).unwrap();
    check_png(&png, 900, 600);
    let png = d.path().join("speed.png");
    report::draw_speed_chart(&png, &many, (900, 600)).unwrap();
    let (w, h) = image::image_dimensions(&png).unwrap();
    assert!(w == 900 && h >= 600, "{w}x{h}");
    let err = report::draw_sr_figure(&d.path().join("x.pdf"), &figs[0], (900, 600)).unwrap_err();
    assert!(err.to_string().contains("x.pdf"), "{err}");
}

/// The learning-based trackers get their own figure beside the best registration trackers
/// scored against translation ground truth (as in the paper); registration trackers scored
/// against the full ground truth are not compared with them.
#[test]
fn learning_trackers_are_drawn_beside_the_best_translation_trackers() {
    let translation = |sm: &str, am: &str, sr: f64| {
        let mut t = tracker(sm, am, "translation", sr);
        t.summary.gt = "translation".into();
        t
    };
    let ts: Vec<TrackerResult> = (0..8)
        .map(|i| translation(&format!("sm{i}"), "ssd", 0.3 + 0.05 * i as f64))
        .chain(["kcf", "dsst", "tld"].map(|w| {
            let mut t = tracker(w, "", "", 0.5);
            t.summary.gt = "translation".into();
            t
        }))
        .chain([tracker("esm", "ssd", "homography", 0.99)])
        // A whole tracker scored against the full ground truth (`--gt-ssm own`): not in the
        // figure of translation ground truth.
        .chain([{
            let mut t = tracker("mil", "", "", 0.6);
            t.summary.gt = "full".into();
            t
        }])
        .collect();
    let figs = report::sr_figures(&ts);
    let learning: Vec<&report::Figure> = figs
        .iter()
        .filter(|f| f.kind == FigureKind::Learning)
        .collect();
    assert_eq!(learning.len(), 1);
    let names: Vec<&str> = learning[0].curves.iter().map(|c| c.name.as_str()).collect();
    // The three whole trackers and the six best translation trackers, best first.
    assert_eq!(names.len(), 9, "{names:?}");
    for w in ["kcf", "dsst", "tld"] {
        assert!(names.contains(&w));
    }
    assert!(names.contains(&"sm7_ssd_translation") && !names.contains(&"sm1_ssd_translation"));
    assert!(!names.contains(&"esm_ssd_homography") && !names.contains(&"mil"));
    // The whole trackers are in no other figure.
    assert!(
        figs.iter()
            .filter(|f| f.kind != FigureKind::Learning)
            .all(|f| f
                .curves
                .iter()
                .all(|c| !["kcf", "dsst", "tld"].contains(&c.name.as_str())))
    );
}

/// A curve figure draws a non-finite point as a gap (two lines, not one bridging it), each
/// curve in its own colour and dash when given, its marks as crosses; a map figure draws its
/// cells in the colour map.
#[test]
fn curves_break_at_gaps_keep_their_colours_and_maps_draw() {
    let d = TempDir::new("report-gaps");
    let fig = report::Figure {
        kind: FigureKind::Others,
        stem: "errors".into(),
        title: "errors".into(),
        curves: vec![report::Curve {
            name: "1 a".into(),
            tracker: "a".into(),
            mean_sr: 1.0,
            points: vec![
                (1.0, 1.0),
                (2.0, 2.0),
                (3.0, f64::NAN),
                (4.0, 1.0),
                (5.0, 2.0),
            ],
            style: Some(([12, 34, 56], false)),
            marks: vec![(3.0, 4.0)],
        }],
    };
    let axes = report::Axes {
        x_desc: "frame".into(),
        y_desc: "px".into(),
        x_range: (1.0, 5.0),
        y_range: (0.0, 5.0),
        legend_header: "mean".into(),
    };
    let p = d.path().join("errors.svg");
    report::draw_curve_figure(&p, &fig, &axes, (600, 400)).unwrap();
    let svg = std::fs::read_to_string(&p).unwrap();
    let count = |tag: &str| {
        svg.lines()
            .filter(|l| l.contains(tag) && l.contains("#0C2238"))
            .count()
    };
    // Two runs of the curve and the legend's sample; the cross's two strokes.
    assert_eq!((count("<polyline"), count("<line")), (3, 2), "{svg}");
    let map = report::MapFigure {
        title: "map".into(),
        x_desc: "x".into(),
        y_desc: "y".into(),
        values: (0..9).map(|k| k as f64).collect(),
        offsets: vec![-1.0, 0.0, 1.0],
        path: vec![(0.5, 0.5), (0.0, 0.0)],
        best: Some((1.0, 1.0)),
    };
    for ext in ["svg", "png"] {
        let p = d.path().join(format!("map.{ext}"));
        report::draw_map_figure(&p, &map, (500, 400)).unwrap();
        assert!(std::fs::metadata(&p).unwrap().len() > 1000);
    }
    let svg = std::fs::read_to_string(d.path().join("map.svg")).unwrap();
    let [r, g, b] = report::colormap(1.0);
    assert!(
        svg.to_uppercase()
            .contains(&format!("#{r:02X}{g:02X}{b:02X}"))
    );
}
