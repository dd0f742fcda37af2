//! Robustness on real-footage conditions the reference implementation handles: light that
//! changes over a static target, and fast motion.

use crate::common::{paper_settings, texture};
use rayon::prelude::*;
use regtrack::geometry::{Quad, alignment_error};
use regtrack::imaging::GrayU8;
use regtrack::observe::NoObserver;
use regtrack::rng::Rng;
use regtrack::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};

/// A static, dark, sparsely textured target (a darkened, low-contrast crop of a texture) on a
/// dark background, under a global gain swing of +-35% and a broad light blob (+60 gray levels at
/// its centre, about 120 px wide) that crosses the target, with noise and 8-bit quantisation.
pub fn lit_static_sequence(frames: usize, seed: u64) -> (Vec<GrayU8>, Quad) {
    lit_sequence_with_contrast(frames, seed, 0.25)
}

/// [`lit_static_sequence`] with the target's texture at `contrast` of the brick's (0.25 there).
pub fn lit_sequence_with_contrast(frames: usize, seed: u64, contrast: f64) -> (Vec<GrayU8>, Quad) {
    let tex = texture("skimage_brick.png");
    let (w, h) = (480usize, 360usize);
    let target = Quad::from_rect(170.0, 110.0, 140.0, 140.0);
    let mut rng = Rng::new(seed);
    let mut plate = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let inside = (170..310).contains(&x) && (110..250).contains(&y);
            plate[y * w + x] = if inside {
                let (u, v) = ((x - 170) * 2, (y - 110) * 2);
                25.0 + contrast * tex.data[(v % tex.height) * tex.width + (u % tex.width)] as f64
            } else {
                30.0
            };
        }
    }
    let light = Light {
        gain: true,
        blob: true,
        jpeg: false,
    };
    (light.frames(&plate, w, frames, &mut rng), target)
}

/// Tracks the frames; returns the error per frame (infinite once lost).
fn run(spec: &TrackerSpec, frames: &[GrayU8], truth: &Quad) -> Vec<f64> {
    errors(spec, frames, truth, false)
}

/// The error per frame of the search started from the truth on that frame: where the cost's
/// optimum lies, whatever happened before.
fn from_truth(spec: &TrackerSpec, frames: &[GrayU8], truth: &Quad) -> Vec<f64> {
    errors(spec, frames, truth, true)
}

/// The error per frame (infinite once lost), each frame's search started from the previous
/// estimate or, with `restart`, from the truth.
fn errors(spec: &TrackerSpec, frames: &[GrayU8], truth: &Quad, restart: bool) -> Vec<f64> {
    let mut t = Tracker::new(spec).unwrap();
    t.initialize(FrameInput::Gray8(&frames[0]), truth).unwrap();
    frames[1..]
        .iter()
        .map(|f| {
            if restart {
                t.set_corners(truth).unwrap();
            }
            let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
            if out.status == TrackStatus::Tracking {
                alignment_error(&out.corners, truth)
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// The largest error over the first `n` frames.
fn worst(e: &[f64], n: usize) -> f64 {
    e.iter().take(n).copied().fold(0.0, f64::max)
}

#[test]
fn under_moving_light_the_drift_of_ssd_and_zncc_is_in_their_cost_not_the_search() {
    // On this sequence ESM with SSD or ZNCC drifts away from the static target. Started from the
    // truth on a later frame, the search still ends where the similarity is higher than at the
    // truth: the optimum of the cost itself moved with the light (see docs/robustness.md).
    // The paper's tracker (the robust defaults end 0.6 px off on this frame with ZNCC).
    let (frames, truth) = lit_static_sequence(22, 1);
    for am in ["ssd", "zncc"] {
        let mut spec = TrackerSpec::from_names("esm", am, "homography").unwrap();
        paper_settings(&mut spec);
        // Where the search ends, even where the confidence checks would call the frame lost.
        spec.set_param("min_confidence", "-1").unwrap();
        spec.set_param("confidence_drop", "0").unwrap();
        let mut one = spec.clone();
        one.set_param("max_iters", "1").unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        let mut probe = Tracker::new(&one).unwrap();
        t.initialize(FrameInput::Gray8(&frames[0]), &truth).unwrap();
        probe
            .initialize(FrameInput::Gray8(&frames[0]), &truth)
            .unwrap();
        t.set_corners(&truth).unwrap();
        let out = t.update(FrameInput::Gray8(&frames[21]), &mut NoObserver);
        probe.set_corners(&truth).unwrap();
        let at_truth = probe.update(FrameInput::Gray8(&frames[21]), &mut NoObserver);
        probe.set_corners(&out.corners).unwrap();
        let at_found = probe.update(FrameInput::Gray8(&frames[21]), &mut NoObserver);
        let err = alignment_error(&out.corners, &truth);
        eprintln!(
            "esm {am}, frame 21 from the truth: {err:.2} px off, f(truth) {:.1} < f(found) {:.1}",
            at_truth.similarity, at_found.similarity
        );
        assert!(err > 1.0, "{am}: {err}");
        assert!(at_found.similarity > at_truth.similarity, "{am}");
    }
}

#[test]
fn local_intensity_models_hold_a_static_target_under_moving_light() {
    // LSCV (per-region intensity maps, updated every frame) follows the light; SSD and ZNCC lose
    // the target within 40 frames of this sequence.
    let (frames, truth) = lit_static_sequence(61, 1);
    let err = |sm: &str, am: &str| {
        let spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
        worst(&run(&spec, &frames, &truth), 60)
    };
    let (lscv, zncc, ssd) = (err("esm", "lscv"), err("esm", "zncc"), err("esm", "ssd"));
    eprintln!("worst error over 60 frames: esm lscv {lscv:.2}, zncc {zncc:.2}, ssd {ssd:.2}");
    assert!(lscv < 5.0, "lscv {lscv}");
    assert!(lscv < zncc && lscv < ssd, "zncc {zncc} ssd {ssd}");
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

#[test]
fn iclk_follows_an_updated_intensity_map() {
    // A static target whose brightness drifts (gain 1 -> 0.6, bias 0 -> 40 over 10 frames). SCV's
    // map is learnt from each new frame at the previous estimate, then again where the search
    // settles (ICLK's constant Hessian refreshed each time): no lag behind the light, and a jump
    // under the new light is recovered. Learnt only after convergence, from the previous frame,
    // the map lagged one frame behind and SCV drifted 2 px here.
    let img = texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let lit = |a: f64| GrayU8 {
        width: img.width,
        height: img.height,
        data: img
            .data
            .iter()
            .map(|&v| ((1.0 - 0.4 * a) * v as f64 + 40.0 * a).round().min(255.0) as u8)
            .collect(),
    };
    let run = |am: &str| {
        let (sm, am) = am.split_once(' ').unwrap();
        // The single-level tracker: the iterations counted are those of the relearning.
        let mut spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
        paper_settings(&mut spec);
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
        let mut worst: f64 = 0.0;
        for k in 1..=10 {
            let out = t.update(FrameInput::Gray8(&lit(k as f64 / 10.0)), &mut NoObserver);
            assert_eq!(out.status, TrackStatus::Tracking, "{am} frame {k}");
            worst = worst.max(alignment_error(&out.corners, &truth));
        }
        // Then a jump of 1.5 px under the final light.
        let start = truth.map(|p| regtrack::geometry::Point::new(p.x + 1.5, p.y - 1.0));
        t.set_corners(&start).unwrap();
        let out = t.update(FrameInput::Gray8(&lit(1.0)), &mut NoObserver);
        (worst, alignment_error(&out.corners, &truth), out.iterations)
    };
    let (scv_drift, scv_jump, scv_iters) = run("iclk scv");
    let (ssd_drift, ssd_jump, _) = run("iclk ssd");
    eprintln!(
        "worst error while the light drifts: scv {scv_drift:.3}, ssd {ssd_drift:.3}; \
         after a 1.5 px jump: scv {scv_jump:.3} in {scv_iters} iterations, ssd {ssd_jump:.3}"
    );
    assert!(
        scv_drift < 0.05 && scv_jump < 0.05,
        "{scv_drift} {scv_jump}"
    );
    assert!(scv_iters <= 25, "{scv_iters}");
    for c in ["esm scv", "fclk rscv"] {
        let (drift, jump, _) = run(c);
        assert!(drift < 0.05 && jump < 0.05, "{c}: {drift} {jump}");
    }
}

/// The same light over a target of sparse, strong marks (14 bright discs of 3-8 px radius and
/// +40..+90 gray levels on a dark plate), optionally JPEG-compressed (quality 75), with the global
/// gain swing and the light blob switched on or off separately.
pub fn sparse_lit_sequence(
    frames: usize,
    seed: u64,
    jpeg: bool,
    gain_on: bool,
    blob_on: bool,
) -> (Vec<GrayU8>, Quad) {
    let (w, h) = (480usize, 360usize);
    let target = Quad::from_rect(170.0, 110.0, 140.0, 140.0);
    let mut rng = Rng::new(seed);
    let marks: Vec<(f64, f64, f64, f64)> = (0..14)
        .map(|_| {
            (
                175.0 + 130.0 * rng.uniform(),
                115.0 + 130.0 * rng.uniform(),
                3.0 + 5.0 * rng.uniform(),
                40.0 + 50.0 * rng.uniform(),
            )
        })
        .collect();
    let mut plate = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f64, y as f64);
            let inside = (170.0..310.0).contains(&fx) && (110.0..250.0).contains(&fy);
            let mut base = if inside { 22.0 } else { 30.0 };
            for &(mx, my, r, c) in &marks {
                let d = ((fx - mx).powi(2) + (fy - my).powi(2)).sqrt();
                base += c * (r + 0.5 - d).clamp(0.0, 1.0);
            }
            plate[y * w + x] = base;
        }
    }
    let light = Light {
        gain: gain_on,
        blob: blob_on,
        jpeg,
    };
    (light.frames(&plate, w, frames, &mut rng), target)
}

/// The light over a static plate: which of the nuisances are on.
struct Light {
    /// The global gain swing, +-35 % over 80 frames.
    gain: bool,
    /// An additive blob of +60 gray levels (sigma 60 px) sweeping across the frame.
    blob: bool,
    /// JPEG at quality 75.
    jpeg: bool,
}

impl Light {
    /// `frames` frames of the static `plate` (`w` wide) under this light, with noise of sigma 2.
    fn frames(&self, plate: &[f64], w: usize, frames: usize, rng: &mut Rng) -> Vec<GrayU8> {
        let h = plate.len() / w;
        let mut out = Vec::with_capacity(frames);
        for i in 0..frames {
            let t = i as f64;
            let gain = if self.gain {
                1.0 + 0.35 * (2.0 * std::f64::consts::PI * t / 80.0).sin()
            } else {
                1.0
            };
            let (bx, by) = (
                240.0 + 170.0 * (t / 25.0).cos(),
                180.0 + 110.0 * (t / 37.0).sin(),
            );
            let amp = if self.blob { 60.0 } else { 0.0 };
            let mut data = vec![0u8; w * h];
            for y in 0..h {
                for x in 0..w {
                    let d2 = (x as f64 - bx).powi(2) + (y as f64 - by).powi(2);
                    let blob = amp * (-d2 / (2.0 * 60.0f64.powi(2))).exp();
                    let v = plate[y * w + x] * gain + blob + 2.0 * rng.normal();
                    data[y * w + x] = v.round().clamp(0.0, 255.0) as u8;
                }
            }
            if self.jpeg {
                let mut buf = Vec::new();
                let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, 75);
                let img = image::GrayImage::from_raw(w as u32, h as u32, data).expect("frame size");
                img.write_with_encoder(enc).expect("jpeg encoding");
                data = image::load_from_memory(&buf)
                    .expect("jpeg decoding")
                    .to_luma8()
                    .into_raw();
            }
            out.push(GrayU8 {
                width: w,
                height: h,
                data,
            });
        }
        out
    }
}

/// A static star field: 40 point-like marks (Gaussian dots of 0.6-1.5 px sigma, +80..+200 gray
/// levels, so smaller than the 50x50 grid's 2.8 px step on the 140 px target) on a dark plate,
/// under the light of [`lit_static_sequence`] (gain swing of +-35 %, an additive blob of +60
/// sweeping across), noise of sigma 2 and JPEG at quality 75. The kind of sequence on which the
/// default trackers lost targets that the peers held (issue 17; docs/robustness.md).
pub fn star_field_sequence(frames: usize, seed: u64) -> (Vec<GrayU8>, Quad) {
    let (w, h) = (480usize, 360usize);
    let target = Quad::from_rect(170.0, 110.0, 140.0, 140.0);
    let mut rng = Rng::new(seed);
    let stars: Vec<(f64, f64, f64, f64)> = (0..40)
        .map(|_| {
            (
                175.0 + 130.0 * rng.uniform(),
                115.0 + 130.0 * rng.uniform(),
                0.6 + 0.9 * rng.uniform(),
                80.0 + 120.0 * rng.uniform(),
            )
        })
        .collect();
    let mut plate = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let inside = (170..310).contains(&x) && (110..250).contains(&y);
            plate[y * w + x] = if inside { 12.0 } else { 30.0 };
        }
    }
    for &(cx, cy, r, b) in &stars {
        for y in (cy - 5.0) as usize..=(cy + 5.0) as usize {
            for x in (cx - 5.0) as usize..=(cx + 5.0) as usize {
                let d2 = (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2);
                plate[y * w + x] += b * (-d2 / (2.0 * r * r)).exp();
            }
        }
    }
    let light = Light {
        gain: true,
        blob: true,
        jpeg: true,
    };
    (light.frames(&plate, w, frames, &mut rng), target)
}

#[test]
fn ssd_and_zncc_hold_a_sparse_target_under_moving_light() {
    // Under the light of `lit_static_sequence` over a target of a few strong marks, SSD and ZNCC
    // hold 120 frames. The light still moves the optimum of the cost (started from the truth on
    // each frame, the homography ends 2-3.6 px off at worst, the translation 0.2-0.5 px: the
    // extra DOF are weakly pinned by sparse marks), but nothing in the search adds a drift of
    // its own: tracked frame to frame, each frame ends where the search started from the truth
    // ends (within 0.01 px for FCLK and ICLK; ESM, which ends a frame at its best point when its
    // steps keep lowering the similarity, differs by up to 0.52 px on single frames, 0.05 px on
    // average over the last 20). A bias of 0.02 px per frame in the search would add 2.4 px by
    // the end.
    let (frames, truth) = sparse_lit_sequence(121, 1, true, true, true);
    let mut report = Vec::new();
    for (sm, am, ssm) in [
        ("esm", "ssd", "homography"),
        ("esm", "zncc", "homography"),
        ("fclk", "zncc", "homography"),
        ("iclk", "ssd", "homography"),
        ("esm", "zncc", "translation"),
        ("iclk", "ssd", "translation"),
    ] {
        // The paper's tracker, whose drift this looks for; the robust defaults hold the sequence
        // at least as well.
        let mut spec = TrackerSpec::from_names(sm, am, ssm).unwrap();
        let default = worst(&run(&spec, &frames, &truth), 120);
        paper_settings(&mut spec);
        let tracked = run(&spec, &frames, &truth);
        let cost = from_truth(&spec, &frames, &truth);
        // Per frame, the tracked error beyond the from-truth one; and over the last 20 frames on
        // average, where a drift of the search's own would have accumulated.
        let extra: Vec<f64> = tracked.iter().zip(&cost).map(|(t, c)| t - c).collect();
        let most = extra.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let late = extra[100..].iter().sum::<f64>() / 20.0;
        let held = worst(&tracked, 120);
        report.push(format!(
            "{sm}-{am}-{ssm}: worst {held:.2}, from the truth {:.2}, extra {most:.2} (last 20 frames {late:.3}); defaults: worst {default:.2}",
            worst(&cost, 120)
        ));
        let bound = if ssm == "translation" { 1.0 } else { 5.0 };
        assert!(
            most < 1.0 && late.abs() < 0.1 && held < bound && default < bound.min(held + 0.5),
            "{report:#?}"
        );
    }
    eprintln!("{report:#?}");
}

#[test]
fn without_light_changes_nothing_drifts() {
    // The same marks, JPEG and noise, but constant light: every method stays within 0.15 px.
    let (frames, truth) = sparse_lit_sequence(61, 1, true, false, false);
    for (sm, am) in [
        ("esm", "ssd"),
        ("esm", "zncc"),
        ("iclk", "ssd"),
        ("fclk", "zncc"),
    ] {
        let spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
        let e = worst(&run(&spec, &frames, &truth), 60);
        assert!(e < 0.15, "{sm}-{am}: {e}");
    }
}

#[test]
fn lscv_holds_a_static_target_under_moving_light_for_200_frames() {
    // The blob crosses the target's centre around frame 120: with the paper's 3x3 regions the
    // blended maps cannot follow its peak and ESM-LSCV is lost there; the default 6x6 holds the
    // whole sequence (see the header of src/am/lscv.rs).
    let (frames, truth) = lit_static_sequence(201, 1);
    let run_with = |regions: &str| {
        let mut spec = TrackerSpec::from_names("esm", "lscv", "homography").unwrap();
        spec.set_param("regions", regions).unwrap();
        worst(&run(&spec, &frames, &truth), 200)
    };
    let (default, paper) = (run_with("6"), run_with("3"));
    eprintln!("esm-lscv worst error over 200 frames: 6x6 regions {default:.2}, 3x3 {paper:.2}");
    assert!(default < 2.0, "6x6: {default}");
    assert!(paper > 5.0, "3x3: {paper}");
    // The default is 6x6.
    let spec = TrackerSpec::from_names("esm", "lscv", "homography").unwrap();
    assert_eq!(worst(&run(&spec, &frames, &truth), 200), default);
}

#[test]
fn esm_does_not_run_away_when_its_steps_lower_the_similarity() {
    // The same light over the brick at half and full contrast. Classic ESM (`max_falls=0`) has
    // no fixed point near the optimum on some frames and slides away while the similarity falls
    // (ZNCC at half contrast, SSD at full contrast: lost by frame 80); ending the frame at the
    // best point after three falls in a row holds both over 120 frames, as FCLK-ZNCC does.
    for (contrast, am) in [(0.5, "zncc"), (1.0, "ssd")] {
        let (frames, truth) = lit_sequence_with_contrast(121, 1, contrast);
        let held = |falls: &str| {
            let mut spec = TrackerSpec::from_names("esm", am, "homography").unwrap();
            paper_settings(&mut spec);
            spec.set_param("max_falls", falls).unwrap();
            worst(&run(&spec, &frames, &truth), 120)
        };
        let (classic, default) = (held("0"), held("3"));
        eprintln!("contrast {contrast}, esm-{am}: classic {classic:.2}, max_falls=3 {default:.2}");
        assert!(classic > 20.0, "{am}: classic {classic}");
        assert!(default < 5.0, "{am}: max_falls=3 {default}");
    }
}

/// The light sequences above written in the MTF layout (PNG frames) read back as they were
/// rendered: every frame, the target's corners. With `REGTRACK_LIT_OUT=/tmp/lit cargo test
/// --test it write_the_lit_sequences` they are kept there, for `regtrack eval` and for older
/// builds (docs/robustness.md compares the code the issue measured with today's on them).
#[test]
fn write_the_lit_sequences() {
    let temp = crate::common::TempDir::new("lit");
    let out = std::env::var_os("REGTRACK_LIT_OUT").map(std::path::PathBuf::from);
    let root = out.as_deref().unwrap_or(temp.path());
    let mut seqs: Vec<(String, Vec<GrayU8>, Quad)> = Vec::new();
    let (f, q) = sparse_lit_sequence(121, 1, true, true, true);
    seqs.push(("sparse".into(), f, q));
    let (f, q) = star_field_sequence(79, 1);
    seqs.push(("stars".into(), f, q));
    for c in [0.25, 0.5, 1.0] {
        let (f, q) = lit_sequence_with_contrast(121, 1, c);
        seqs.push((format!("brick{}", (c * 100.0) as i32), f, q));
    }
    for (name, frames, q) in seqs {
        let seq = write_static_sequence(root, &name, &frames, &q);
        assert_eq!(seq.len(), frames.len(), "{name}");
        for i in [0, frames.len() / 2, frames.len() - 1] {
            assert_eq!(seq.ground_truth(i), Some(q), "{name} {i}");
            assert_eq!(seq.load_gray(i).unwrap().data, frames[i].data, "{name} {i}");
        }
    }
}

/// Writes `frames` of a static target at `q` in the MTF layout under `root`; opens it back.
pub fn write_static_sequence(
    root: &std::path::Path,
    name: &str,
    frames: &[GrayU8],
    q: &Quad,
) -> regtrack::dataset::Sequence {
    let dir = root.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    for (i, fr) in frames.iter().enumerate() {
        image::GrayImage::from_raw(fr.width as u32, fr.height as u32, fr.data.clone())
            .unwrap()
            .save(dir.join(format!("frame{:05}.png", i + 1)))
            .unwrap();
    }
    let corners = vec![Some(*q); frames.len()];
    let gt = root.join(format!("{name}.txt"));
    regtrack::dataset::write_corners(&gt, &corners, "png").unwrap();
    regtrack::dataset::Sequence::open(&gt).unwrap()
}

#[test]
fn a_pyramid_keeps_a_star_field_that_its_coarse_levels_cannot_see() {
    // The star field's marks are finer than the coarse levels' pixels: there the search follows
    // the light. The finest level checks the coarse estimate against where the frame started,
    // and keeps the start when the coarse estimate is less similar (without that check ESM-ZNCC
    // with 3 levels held 31 of the 78 frames within 5 px, ICLK-ZNCC 25).
    let (frames, truth) = star_field_sequence(79, 1);
    for sm in ["esm", "iclk"] {
        let mut spec = TrackerSpec::from_names(sm, "zncc", "homography").unwrap();
        spec.set_param("pyramid_levels", "3").unwrap();
        spec.set_param("blur_sigma", "1").unwrap();
        let e = run(&spec, &frames, &truth);
        let worst = e.iter().copied().fold(0.0, f64::max);
        assert!(worst < 5.0, "{sm}-zncc, 3 levels: worst {worst:.2} px");
    }
}

#[test]
fn a_lost_tracker_says_so_and_a_tracking_one_does_not() {
    // Two kinds of sequence on which trackers are lost: the star field under moving light (the
    // SSD trackers slide off it at the default smoothing) and fast motion (the coffee over the
    // brick on the UCSB `m3` profile played three times as fast: everything is lost within a
    // few frames). With `on_loss=continue` each tracker searches every frame, so every frame is
    // judged. Before the confidence checks, 22 % of the 226 frames more than 20 px off were
    // reported lost here; with them all 108 are (the trackers now wait at the last good
    // estimate instead of following the background), and 1 of 414 frames within 5 px. With the
    // motion prediction (`predict=on`) and the line search's end at the similarity's noise,
    // the trackers held most of the profile played twice as fast (27 frames off were left):
    // three times as fast leaves 54.
    use regtrack::dataset::synth::{SynthConfig, render_sequence};
    use regtrack::eval::{self, EvalOptions};
    let d = crate::common::TempDir::new("loss");
    let (frames, q) = star_field_sequence(79, 1);
    let stars = write_static_sequence(d.path(), "stars", &frames, &q);
    let root = crate::common::root();
    let cfg = SynthConfig {
        texture: root.join("assets/textures/skimage_coffee.png"),
        background: Some(root.join("assets/textures/skimage_brick.png")),
        motion: root.join("assets/motion/ucsb_bricks_m3.txt"),
        step: 3,
        noise: 3.0,
        jpeg_quality: 90,
        max_frames: Some(40),
        seed: 1,
        ..SynthConfig::default()
    };
    let fast = render_sequence(&cfg, &d.path().join("fast"), "m3x2", &|_, _| {}).unwrap();
    let mut runs = Vec::new();
    for seq in [&stars, &fast] {
        for sm in ["esm", "fclk", "iclk"] {
            for am in ["ssd", "zncc"] {
                let mut spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
                spec.set_param("on_loss", "continue").unwrap();
                let opts = EvalOptions::default();
                runs.push(eval::run_sequence(seq, &spec, &opts, None, &mut NoObserver).unwrap());
            }
        }
    }
    let frames = |f: &dyn Fn(&eval::FrameRecord) -> bool| {
        runs.iter()
            .flat_map(|r| r.frames.iter())
            .filter(|r| r.searched && f(r))
            .count()
    };
    let off = frames(&|r| r.estimate_error > eval::LOSS_OFF);
    let on = frames(&|r| r.estimate_error <= eval::LOSS_ON);
    assert!(off >= 30 && on >= 300, "{off} frames off, {on} on");
    let refs: Vec<&eval::RunResult> = runs.iter().collect();
    let s = eval::summarize("ALL", &refs);
    assert!(
        s.lost_when_off >= 0.95,
        "{} of {off} frames off reported lost",
        s.lost_when_off
    );
    assert!(
        s.lost_when_on <= 0.02,
        "{} of {on} frames on reported lost",
        s.lost_when_on
    );
    // Every frame judged has a confidence in -1..1.
    assert!(
        runs.iter()
            .flat_map(|r| r.frames.iter())
            .filter(|f| f.searched)
            .all(|f| { f.confidence.is_none_or(|c| (-1.0..=1.0).contains(&c)) })
    );
}

#[test]
fn ssd_with_an_illumination_model_holds_the_star_field_at_the_papers_smoothing() {
    // Without a model of the light, SSD's optimum follows the blob and the gain off the star
    // field at the paper's smoothing (ESM, FCLK, ICLK: about half the frames within 5 px). With
    // a gain and a bias estimated with the warp, per cell (pgb) or smoothly (rbf), each holds it.
    let (frames, truth) = star_field_sequence(79, 1);
    for sm in ["esm", "fclk", "iclk"] {
        let mut plain = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        paper_settings(&mut plain);
        let lost = run(&plain, &frames, &truth)
            .iter()
            .filter(|e| **e > 5.0)
            .count();
        assert!(lost > 20, "{sm}-ssd alone: {lost} frames off");
        for ilm in ["pgb", "rbf"] {
            let mut spec = plain.clone();
            spec.set_param("ilm", ilm).unwrap();
            let worst = worst(&run(&spec, &frames, &truth), 78);
            assert!(worst < 3.0, "{sm}-ssd ilm={ilm}: worst {worst:.2} px");
        }
    }
}

/// A frame of the grass texture with a 100 x 100 crop of the coffee pasted at `(x, y)`, scaled
/// by `scale` (nearest neighbour); returns the frame and the crop's quad.
fn pasted(x: f64, y: f64, scale: f64) -> (GrayU8, Quad) {
    let bg = texture("skimage_grass.png");
    let fg = texture("skimage_coffee.png");
    let mut img = bg.clone();
    let side = 100.0 * scale;
    for j in 0..side as usize {
        for i in 0..side as usize {
            let (u, v) = ((i as f64 / scale) as usize, (j as f64 / scale) as usize);
            let (px, py) = (x as usize + i, y as usize + j);
            if px < img.width && py < img.height {
                img.data[py * img.width + px] = fg.data[(150 + v) * fg.width + 250 + u];
            }
        }
    }
    (img, Quad::from_rect(x - 0.5, y - 0.5, side, side))
}

#[test]
fn redetection_finds_a_target_that_comes_back_elsewhere() {
    // The target is hidden for a frame (the tracker is lost), then shows again 200 px away and
    // 10 % larger. `continue` searches where it was and stays lost; `redetect` searches the
    // frame, a budget of candidates a frame, nearest first, finds it (ring 12 of steps of 17
    // px: about 1,600 candidates, within the frames its budget takes) and tracks on.
    let (first, truth) = pasted(100.0, 80.0, 1.0);
    let hidden = texture("skimage_grass.png");
    let (moved, there) = pasted(300.0, 200.0, 1.1);
    for policy in ["continue", "redetect"] {
        let mut spec = TrackerSpec::from_names("esm", "ssd", "homography").unwrap();
        spec.set_param("on_loss", policy).unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&first), &truth).unwrap();
        let lost = t.update(FrameInput::Gray8(&hidden), &mut NoObserver);
        assert!(
            matches!(lost.status, TrackStatus::Lost(_)),
            "{policy}: {lost:?}"
        );
        let mut errors = Vec::new();
        for _ in 0..10 {
            let out = t.update(FrameInput::Gray8(&moved), &mut NoObserver);
            errors.push(if out.status == TrackStatus::Tracking {
                alignment_error(&out.corners, &there)
            } else {
                f64::INFINITY
            });
        }
        if policy == "continue" {
            assert!(
                errors.iter().all(|e| e.is_infinite()),
                "continue: {errors:?}"
            );
        } else {
            let found = errors
                .iter()
                .position(|e| e.is_finite())
                .expect("found again");
            assert!(found <= 7, "redetect: found on frame {found}: {errors:?}");
            assert!(
                errors[found..].iter().all(|e| *e < 1.5),
                "redetect: {errors:?}"
            );
        }
    }
}

#[test]
fn a_sudden_jump_is_found_on_the_frame_it_happens() {
    // The target moves 4 px a frame, then jumps 43 or 58 px (and half that down): the searches
    // from the prediction and from the last pose (and the pyramid's basin) miss it. With
    // `on_loss=redetect` the frame itself is searched for the template, so the jump costs no
    // frame (before, the search began on the next frame, as with `continue`, which loses it).
    for jump in [55.0, 70.0] {
        let frames: Vec<(GrayU8, Quad)> = [0.0, 4.0, 8.0, 12.0, jump, jump + 4.0]
            .iter()
            .map(|&dx| pasted(100.0 + dx, 80.0 + dx / 2.0, 1.0))
            .collect();
        for policy in ["continue", "redetect"] {
            let mut spec = regtrack::tracker::default_spec("homography").unwrap();
            spec.set_param("on_loss", policy).unwrap();
            let mut t = Tracker::new(&spec).unwrap();
            t.initialize(FrameInput::Gray8(&frames[0].0), &frames[0].1)
                .unwrap();
            let mut tracked = Vec::new();
            for (img, truth) in &frames[1..] {
                let out = t.update(FrameInput::Gray8(img), &mut NoObserver);
                tracked.push(
                    out.status == TrackStatus::Tracking
                        && alignment_error(&out.corners, truth) < 1.0,
                );
            }
            if policy == "redetect" {
                assert!(tracked.iter().all(|&t| t), "{jump} redetect: {tracked:?}");
            } else {
                assert!(
                    tracked[..3].iter().all(|&t| t) && !tracked[3],
                    "{jump} continue: {tracked:?}"
                );
            }
        }
    }
}

/// The eight combinations issue 17 holds to the peers: ESM, FCLK, FALK, ICLK x SSD, ZNCC.
const PEER_COMBINATIONS: [(&str, &str); 8] = [
    ("esm", "ssd"),
    ("esm", "zncc"),
    ("fclk", "ssd"),
    ("fclk", "zncc"),
    ("falk", "ssd"),
    ("falk", "zncc"),
    ("iclk", "ssd"),
    ("iclk", "zncc"),
];

#[test]
fn every_default_tracker_holds_the_star_field_that_the_papers_settings_lose() {
    // The star field under a gain swing and a moving light blob, JPEG and noise (issue 17's
    // first situation). With the paper's settings (5x5 sigma 3, one level) the SSD trackers
    // and ICLK-ZNCC slide off it (half the frames within 5 px: what the issue measured); the
    // defaults, a sharp finest level under a pyramid, hold it with every combination.
    let (frames, truth) = star_field_sequence(79, 1);
    let mut report = Vec::new();
    let mut paper_lost = 0;
    for (sm, am) in PEER_COMBINATIONS {
        let spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
        let e = run(&spec, &frames, &truth);
        let held = e.iter().filter(|&&v| v <= 5.0).count();
        let mut paper = spec.clone();
        paper_settings(&mut paper);
        let p = run(&paper, &frames, &truth);
        let paper_held = p.iter().filter(|&&v| v <= 5.0).count();
        paper_lost += usize::from(paper_held < 70);
        report.push(format!(
            "{sm}-{am}: {held}/78 within 5 px (worst {:.2}), paper's settings {paper_held}/78",
            worst(&e, 78)
        ));
    }
    eprintln!("{report:#?}");
    assert!(report.iter().all(|r| r.contains(": 78/78")), "{report:#?}");
    // The sequence is one the paper's settings lose: the test would have caught the loss.
    assert!(paper_lost >= 4, "{report:#?}");
}

#[test]
fn a_slip_to_a_look_alike_is_reported_lost() {
    // The brick wall of the evidence set on the UCSB `uc` profile (jumps of up to 30 px a
    // frame, an occluder, JPEG): the search lands on the next rows of bricks, whose patch looks
    // like the template (confidence 0.6-0.8 against the track's 0.7-0.99). The patch's
    // correlation with the previous frame's tells the slip: with it at least 95 % of the frames
    // more than 20 px off are reported lost and at most 2 % of those within 5 px; without it
    // (`min_frame_confidence=-1`, the checks before) about 70 % were.
    use regtrack::dataset::synth::{SynthConfig, render_sequence};
    use regtrack::eval::{self, EvalOptions};
    let d = crate::common::TempDir::new("slip");
    let root = crate::common::root();
    let cfg = SynthConfig {
        texture: root.join("assets/textures/skimage_brick.png"),
        background: Some(root.join("assets/textures/skimage_grass.png")),
        motion: root.join("assets/motion/ucsb_bricks_uc.txt"),
        noise: 2.0,
        occlusion: 0.15,
        jpeg_quality: 80,
        seed: 7,
        ..SynthConfig::default()
    };
    let seq = render_sequence(&cfg, &d.path().join("uc"), "bricks_uc", &|_, _| {}).unwrap();
    let opts = EvalOptions {
        reinit: true,
        ..EvalOptions::default()
    };
    // The eight combinations and the default tracker (with its second hypothesis).
    let mut specs: Vec<TrackerSpec> = PEER_COMBINATIONS
        .iter()
        .map(|(sm, am)| TrackerSpec::from_names(sm, am, "homography").unwrap())
        .collect();
    specs.push(regtrack::tracker::default_spec("homography").unwrap());
    let judge = |frame_check: bool| {
        let runs: Vec<eval::RunResult> = specs
            .par_iter()
            .map(|spec| {
                let mut spec = spec.clone();
                if !frame_check {
                    spec.set_param("min_frame_confidence", "-1").unwrap();
                }
                eval::run_sequence(&seq, &spec, &opts, None, &mut NoObserver).unwrap()
            })
            .collect();
        let refs: Vec<&eval::RunResult> = runs.iter().collect();
        let s = eval::summarize("ALL", &refs);
        let off = runs
            .iter()
            .flat_map(|r| r.frames.iter())
            .filter(|f| f.searched && !f.init && f.estimate_error > eval::LOSS_OFF)
            .count();
        (s.lost_when_off, s.lost_when_on, off)
    };
    let (off_lost, on_lost, off) = judge(true);
    let (before, _, before_off) = judge(false);
    eprintln!(
        "frames > 20 px off reported lost: {off_lost:.3} of {off} (without the frame check \
         {before:.3} of {before_off}); within 5 px reported lost: {on_lost:.4}"
    );
    assert!(off >= 30, "{off} frames off");
    // At least 95 %, to the frame: at most 5 % of them (rounded up) unreported. (With 74 frames
    // off, 4 unreported is 0.946: a tracker that slips less has fewer frames off, and the same
    // unreported frame weighs more.)
    let unreported = ((1.0 - off_lost) * off as f64).round() as usize;
    assert!(
        unreported <= (0.05 * off as f64).ceil() as usize,
        "{off_lost} of {off}: {unreported} unreported"
    );
    assert!(on_lost <= 0.02, "{on_lost}");
    assert!(before < 0.9, "without the frame check: {before}");
}

#[test]
fn a_small_brick_wall_moving_5_px_a_frame_is_held() {
    // Issue 43's case: a brick texture of about 84 x 120 px on grass, on the UCSB `m1` profile
    // (5 px a frame, 88 frames), rendered as `regtrack synth` renders it. The default of
    // da632e0 (ICLK-ZNCC, a pyramid whose coarse levels alias the bricks' 7 px period, no
    // motion prediction) was lost at frame 11 with the target 0.07 px from the truth on frame
    // 10, and never found it again: SR@5 0.103. With the motion prediction the search starts
    // where the wall is going: the default and every ESM/FCLK/ICLK x SSD/ZNCC hold it (with
    // `--predict off` today: ICLK-ZNCC 0.138, ESM-ZNCC 0.046, ESM-SSD 0.678, FCLK-SSD 1.000).
    use regtrack::dataset::synth::{SynthConfig, render_sequence};
    use regtrack::eval::{self, EvalOptions};
    let d = crate::common::TempDir::new("bricks5");
    let root = crate::common::root();
    let cfg = SynthConfig {
        texture: root.join("assets/textures/skimage_brick.png"),
        background: Some(root.join("assets/textures/skimage_grass.png")),
        motion: root.join("assets/motion/ucsb_bricks_m1.txt"),
        noise: 2.0,
        ..SynthConfig::default()
    };
    let seq = render_sequence(&cfg, &d.path().join("b5"), "b5", &|_, _| {}).unwrap();
    // The default tracker (with its second hypothesis), then the plain combinations.
    let mut trackers = vec![regtrack::tracker::default_spec("homography").unwrap()];
    for sm in ["esm", "fclk", "iclk"] {
        for am in ["ssd", "zncc"] {
            trackers.push(TrackerSpec::from_names(sm, am, "homography").unwrap());
        }
    }
    let sr: Vec<f64> = trackers
        .par_iter()
        .map(|spec| {
            let run =
                eval::run_sequence(&seq, spec, &EvalOptions::default(), None, &mut NoObserver)
                    .unwrap();
            eval::summarize("b5", &[&run]).sr5
        })
        .collect();
    let names: Vec<String> = trackers.iter().map(TrackerSpec::label).collect();
    eprintln!("SR@5 on the small brick wall at 5 px a frame: {names:?} {sr:?}");
    for (t, s) in names.iter().zip(&sr) {
        assert!(*s >= 0.95, "{t}: SR@5 {s}");
    }
}

#[test]
fn the_polish_holds_a_blurred_wall_that_iclk_drifts_off() {
    // The evidence set's `bricks_m1`: the brick wall on the UCSB `m1` profile (5 px a frame)
    // with motion blur. ICLK linearises with the sharp template's gradients, the frames are
    // blurred along the motion, and its fixed point is not the AM's optimum: it converges
    // slowly to a point a fraction of a pixel off, frame after frame, and drifts off the wall's
    // period (docs/robustness.md, "Fast motion"). The polish's forward steps, taken while the
    // patch grows more like the template, hold it.
    use regtrack::dataset::synth::{SynthConfig, render_sequence};
    use regtrack::eval::{self, EvalOptions};
    let d = crate::common::TempDir::new("polish");
    let root = crate::common::root();
    let cfg = SynthConfig {
        texture: root.join("assets/textures/skimage_brick.png"),
        background: Some(root.join("assets/textures/skimage_coffee.png")),
        motion: root.join("assets/motion/ucsb_bricks_m1.txt"),
        noise: 2.0,
        motion_blur: 3,
        seed: 7,
        ..SynthConfig::default()
    };
    let seq = render_sequence(&cfg, &d.path().join("m1"), "bricks_m1", &|_, _| {}).unwrap();
    for am in ["ssd", "zncc"] {
        let sr = |polish: &str| {
            let mut spec = TrackerSpec::from_names("iclk", am, "homography").unwrap();
            spec.set_param("polish", polish).unwrap();
            // The polish alone: with the motion prediction ICLK-ZNCC holds more of the wall
            // without the polish too (SR@5 0.63), and with the re-detection on the coarsest
            // level it finds the wall again after drifting off (0.69).
            spec.set_param("predict", "off").unwrap();
            spec.set_param("on_loss", "continue").unwrap();
            let run =
                eval::run_sequence(&seq, &spec, &EvalOptions::default(), None, &mut NoObserver)
                    .unwrap();
            eval::summarize("m1", &[&run]).sr5
        };
        let (off, on) = (sr("off"), sr("on"));
        eprintln!(
            "iclk-{am} on the blurred wall: SR@5 {off:.3} without the polish, {on:.3} with it"
        );
        assert!(on >= 0.95 && off < 0.6, "{am}: {off} {on}");
    }
}

#[test]
fn the_line_search_settles_the_forward_methods_on_a_star_field() {
    // Without it FCLK and FALK run out of iterations on a third to a half of the star field's
    // frames (the Gauss-Newton step overshoots and cycles between two points); with it every
    // frame settles, in fewer iterations, and the track holds.
    let (frames, truth) = star_field_sequence(79, 1);
    for (sm, am) in [("fclk", "ssd"), ("fclk", "zncc"), ("falk", "zncc")] {
        let settle = |line_search: &str| {
            let mut spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
            spec.set_param("line_search", line_search).unwrap();
            let mut t = Tracker::new(&spec).unwrap();
            t.initialize(FrameInput::Gray8(&frames[0]), &truth).unwrap();
            let (mut unsettled, mut iterations, mut worst) = (0, 0, 0.0f64);
            for f in &frames[1..] {
                let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
                unsettled += usize::from(!out.converged);
                iterations += out.iterations;
                worst = worst.max(alignment_error(&out.corners, &truth));
            }
            (unsettled, iterations, worst)
        };
        let (off, on) = (settle("off"), settle("on"));
        eprintln!(
            "{sm}-{am}: without the line search {off:?}, with it {on:?} (unsettled frames, iterations, worst px)"
        );
        assert!(off.0 >= 20 && on.0 == 0, "{off:?} {on:?}");
        assert!(on.1 < off.1 && on.2 < 2.0, "{off:?} {on:?}");
    }
}

/// A target of vertical stripes (nothing along them to register: a camera on a bar code, or
/// FFmpeg's colour bars) on a static frame stays where it is, tracking: without the Newton
/// system's ridge the pivot of the unconstrained direction is rounding, and the step along
/// it sent every gradient method's quad out of the frame on the first update.
#[test]
fn stripes_on_a_static_frame_stay_put_and_tracking() {
    let (w, h) = (320usize, 240usize);
    let data = (0..w * h)
        .map(|i| [20u8, 200, 90, 240, 140, 60, 180, 110][(i % w) / 40])
        .collect();
    let img = GrayU8 {
        width: w,
        height: h,
        data,
    };
    let truth = Quad::from_rect(60.0, 40.0, 140.0, 110.0);
    for (sm, am) in [
        ("iclk", "zncc"),
        ("fclk", "ssd"),
        ("esm", "ssd"),
        ("ialk", "zncc"),
    ] {
        let spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
        for k in 0..5 {
            let out = t.update(FrameInput::Gray8(&img), &mut NoObserver);
            assert_eq!(out.status, TrackStatus::Tracking, "{sm}-{am} frame {k}");
            let e = alignment_error(&out.corners, &truth);
            assert!(e < 0.05, "{sm}-{am} frame {k}: {e} px");
        }
    }
}

/// A known occluder left out (`spi_mask_*`): the demo with the left third of its target
/// showing a picture that changes every frame (a screen, a flickering sticker). Searching the
/// whole grid the tracker is pulled off by it (1 to 5 px, and lost on some frames); leaving
/// that third out of the searches and of the confidences' blocks, it follows the target to
/// within a pixel on every frame (0.02 to 0.07 px, measured), never judged lost.
#[test]
fn a_mask_leaves_out_a_known_occluder() {
    use regtrack::dataset::{
        demo::demo_config,
        synth::{SynthConfig, render_frames},
    };
    use regtrack::geometry::{Point, apply_homography, homography_between};
    let (mut frames, quads) = render_frames(&SynthConfig {
        max_frames: Some(60),
        step: 2,
        ..demo_config()
    })
    .unwrap();
    // The left third of the target, in each frame, a new pattern of bright and dark stripes.
    for (k, (frame, quad)) in frames.iter_mut().zip(&quads).enumerate() {
        let to_unit = homography_between(quad, &Quad::unit_square()).unwrap();
        let (w, h) = (frame.width, frame.height);
        for y in 0..h {
            for x in 0..w {
                let u = apply_homography(&to_unit, Point::new(x as f64, y as f64));
                let (u, v) = (u.x + 0.5, u.y + 0.5);
                if (0.0..0.35).contains(&u) && (0.0..1.0).contains(&v) {
                    let stripe = ((u * 40.0 + v * 17.0 + k as f64 * 2.3).floor() as i64) % 2;
                    frame.data[y * w + x] = if stripe == 0 { 30 } else { 225 };
                }
            }
        }
    }
    let run = |mask: bool| -> Vec<f64> {
        let mut spec = TrackerSpec::from_names("esm", "ssd", "homography").unwrap();
        if mask {
            spec.set_param("spi_mask_right", "0.35").unwrap();
            spec.set_param("spi_mask_bottom", "1").unwrap();
        }
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&frames[0]), &quads[0])
            .unwrap();
        (1..frames.len())
            .map(|k| {
                let out = t.update(FrameInput::Gray8(&frames[k]), &mut NoObserver);
                match out.status {
                    TrackStatus::Tracking => alignment_error(&out.corners, &quads[k]),
                    _ => f64::INFINITY,
                }
            })
            .collect()
    };
    let (whole, masked) = (run(false), run(true));
    // An observer that shows methods (the inspector) sees the points the masked tracker reads:
    // every one outside the mask, where the tracked quad puts them.
    let mut spec = TrackerSpec::from_names("esm", "ssd", "homography").unwrap();
    spec.set_param("spi_mask_right", "0.35").unwrap();
    spec.set_param("spi_mask_bottom", "1").unwrap();
    let mut t = Tracker::new(&spec).unwrap();
    t.initialize(FrameInput::Gray8(&frames[0]), &quads[0])
        .unwrap();
    let mut rec = regtrack::observe::Recorder {
        visuals: true,
        ..Default::default()
    };
    let out = t.update(FrameInput::Gray8(&frames[1]), &mut rec);
    let v = rec
        .method_visuals
        .last()
        .expect("a visual of the points read");
    assert_eq!(v.label, regtrack::observe::SELECTED_PIXELS);
    let TrackerSpec::Registration(reg) = &spec else {
        panic!("a registration tracker")
    };
    let res = reg.params.res;
    assert!(
        v.points.len() > res * res / 2 && v.points.len() < res * res * 7 / 10,
        "{} points of {}",
        v.points.len(),
        res * res
    );
    let to_unit = homography_between(&out.corners, &Quad::unit_square()).unwrap();
    for p in &v.points {
        let u = apply_homography(&to_unit, *p);
        assert!(u.x + 0.5 > 0.33 && u.x < 0.51 && u.y.abs() < 0.51, "{u:?}");
    }
    let worst = |e: &[f64]| e.iter().copied().fold(0.0, f64::max);
    assert!(
        worst(&masked) < 1.0,
        "masked: worst {:.3} px",
        worst(&masked)
    );
    let off = whole.iter().filter(|&&e| e > 1.0).count();
    assert!(
        off >= 10,
        "the whole grid: only {off} frames more than 1 px off"
    );
}
