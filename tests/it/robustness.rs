//! Robustness on real-footage conditions the reference implementation handles: light that
//! changes over a static target, and fast motion.

use crate::common::texture;
use regtrack::geometry::{Quad, alignment_error};
use regtrack::imaging::GrayU8;
use regtrack::observe::NoObserver;
use regtrack::rng::Rng;
use regtrack::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};

/// A static, dark, sparsely textured target (a darkened, low-contrast crop of a texture) on a
/// dark background, under a global gain swing of +-35% and a broad light blob (+60 gray levels at
/// its centre, about 120 px wide) that crosses the target, with noise and 8-bit quantisation.
pub fn lit_static_sequence(frames: usize, seed: u64) -> (Vec<GrayU8>, Quad) {
    let tex = texture("skimage_brick.png");
    let (w, h) = (480usize, 360usize);
    let target = Quad::from_rect(170.0, 110.0, 140.0, 140.0);
    let mut rng = Rng::new(seed);
    let mut out = Vec::with_capacity(frames);
    for i in 0..frames {
        let t = i as f64;
        let gain = 1.0 + 0.35 * (2.0 * std::f64::consts::PI * t / 80.0).sin();
        let (bx, by) = (
            240.0 + 170.0 * (t / 25.0).cos(),
            180.0 + 110.0 * (t / 37.0).sin(),
        );
        let mut data = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f64, y as f64);
                let inside = fx >= 170.0 && fx < 310.0 && fy >= 110.0 && fy < 250.0;
                let base = if inside {
                    let (u, v) = ((x - 170) * 2, (y - 110) * 2);
                    let s = tex.data[(v % tex.height) * tex.width + (u % tex.width)] as f64;
                    25.0 + 0.25 * s
                } else {
                    30.0
                };
                let d2 = (fx - bx).powi(2) + (fy - by).powi(2);
                let blob = 60.0 * (-d2 / (2.0 * 60.0f64.powi(2))).exp();
                let v = base * gain + blob + 2.0 * rng.normal();
                data[y * w + x] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
        out.push(GrayU8 {
            width: w,
            height: h,
            data,
        });
    }
    (out, target)
}

/// Tracks the frames; returns the error per frame (infinite once lost).
fn run(spec: &TrackerSpec, frames: &[GrayU8], truth: &Quad) -> Vec<f64> {
    let mut t = Tracker::new(spec).unwrap();
    t.initialize(FrameInput::Gray8(&frames[0]), truth).unwrap();
    frames[1..]
        .iter()
        .map(|f| {
            let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
            if out.status == TrackStatus::Tracking {
                alignment_error(&out.corners, truth)
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

#[test]
fn probe_light() {
    let (frames, truth) = lit_static_sequence(120, 1);
    for sm in ["esm", "iclk", "fclk"] {
        for am in ["ssd", "zncc", "lscv", "rscv", "scv"] {
            let spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
            let e = run(&spec, &frames, &truth);
            let at = |k: usize| e.get(k).copied().unwrap_or(f64::NAN);
            eprintln!(
                "{sm} {am}: err@10 {:.3} @40 {:.3} @80 {:.3} @119 {:.3} max {:.3}",
                at(9),
                at(39),
                at(79),
                at(118),
                e.iter().cloned().fold(0.0, f64::max)
            );
        }
    }
}

#[test]
fn probe_light2() {
    let (frames, truth) = lit_static_sequence(60, 1);
    for am in ["ssd", "zncc"] {
        let spec = TrackerSpec::from_names("esm", am, "homography").unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&frames[0]), &truth).unwrap();
        let mut line = String::new();
        for (k, f) in frames.iter().enumerate().skip(1).step_by(5) {
            t.set_corners(&truth).unwrap();
            let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
            line += &format!(
                " {k}:{:.2}/{}",
                alignment_error(&out.corners, &truth),
                out.iterations
            );
        }
        eprintln!("from truth esm {am}:{line}");
        let e = run(&spec, &frames, &truth);
        let line: String = e
            .iter()
            .enumerate()
            .step_by(5)
            .map(|(k, v)| format!(" {}:{v:.2}", k + 1))
            .collect();
        eprintln!("tracked esm {am}:{line}");
    }
}

#[test]
fn probe_light3() {
    let (frames, truth) = lit_static_sequence(40, 1);
    for am in ["ssd", "zncc"] {
        let spec = TrackerSpec::from_names("esm", am, "homography").unwrap();
        let mut one = spec.clone();
        one.set_param("max_iters", "1").unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        let mut t1 = Tracker::new(&one).unwrap();
        t.initialize(FrameInput::Gray8(&frames[0]), &truth).unwrap();
        t1.initialize(FrameInput::Gray8(&frames[0]), &truth)
            .unwrap();
        for k in [5usize, 11, 16, 21] {
            t.set_corners(&truth).unwrap();
            let out = t.update(FrameInput::Gray8(&frames[k]), &mut NoObserver);
            t1.set_corners(&truth).unwrap();
            let at_truth = t1
                .update(FrameInput::Gray8(&frames[k]), &mut NoObserver)
                .similarity;
            t1.set_corners(&out.corners).unwrap();
            let at_conv = t1
                .update(FrameInput::Gray8(&frames[k]), &mut NoObserver)
                .similarity;
            eprintln!(
                "{am} frame {k}: err {:.2} f(truth) {at_truth:.3} f(converged) {at_conv:.3}",
                alignment_error(&out.corners, &truth)
            );
        }
    }
}

#[test]
fn a_lost_tracker_stops_or_continues_as_asked() {
    // The target jumps far away for two frames (the tracker is lost), then comes back.
    let img = texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let blank = GrayU8 {
        width: img.width,
        height: img.height,
        data: vec![128; img.data.len()],
    };
    for policy in ["stop", "continue"] {
        let mut spec = TrackerSpec::from_names("esm", "ssd", "homography").unwrap();
        spec.set_param("on_loss", policy).unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
        let lost = t.update(FrameInput::Gray8(&blank), &mut NoObserver);
        assert!(
            matches!(lost.status, TrackStatus::Lost(_)),
            "{policy}: {lost:?}"
        );
        assert!(lost.corners.is_finite());
        let back = t.update(FrameInput::Gray8(&img), &mut NoObserver);
        if policy == "stop" {
            assert!(matches!(back.status, TrackStatus::Lost(_)));
            assert_eq!(back.iterations, 0);
        } else {
            assert_eq!(back.status, TrackStatus::Tracking, "{back:?}");
            assert!(alignment_error(&back.corners, &truth) < 0.5);
        }
    }
}
