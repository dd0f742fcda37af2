//! The whole (learning-based) trackers on rendered sequences: each follows its target with a
//! centre error below 5 px on at least 90% of the frames whose motion is within its model
//! (each registry entry's `motion`): every tracker of the registry is checked on the motions it
//! models.

use crate::common::{TempDir, root};
use regtrack::dataset::synth::{SynthConfig, render_frames};
use regtrack::geometry::Quad;
use regtrack::imaging::GrayU8;
use regtrack::observe::NoObserver;
use regtrack::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec, WHOLE_REGISTRY};
use regtrack::whole::Motion;
use std::path::Path;

/// The whole trackers of the registry that model at least `motion`.
fn modelling(motion: Motion) -> Vec<&'static str> {
    WHOLE_REGISTRY
        .iter()
        .filter(|e| e.build.motion >= motion)
        .map(|e| e.name)
        .collect()
}

/// Writes a motion profile (the TMT format the renderer reads).
fn write_profile(path: &Path, quads: &[Quad]) {
    let mut s = String::from("frame ulx uly urx ury lrx lry llx lly\n");
    for (i, q) in quads.iter().enumerate() {
        s.push_str(&format!("frame{:05}.jpg", i + 1));
        for v in q.to_array() {
            s.push_str(&format!(" {v:.4}"));
        }
        s.push('\n');
    }
    std::fs::write(path, s).expect("profile");
}

/// A 100 x 80 target under a smooth drift of up to 70 px (at most about 4 px a frame) with a
/// scale that follows `scale(t)`.
fn synthetic(frames: usize, scale: impl Fn(f64) -> f64) -> Vec<Quad> {
    (0..frames)
        .map(|i| {
            let t = i as f64;
            let (cx, cy) = (
                240.0 + 70.0 * (t / 17.0).sin(),
                180.0 + 45.0 * (t / 23.0).sin(),
            );
            let s = scale(t);
            Quad::from_rect(cx - 50.0 * s, cy - 40.0 * s, 100.0 * s, 80.0 * s)
        })
        .collect()
}

/// Renders `quads` (or a bundled profile) with the brick texture over grass, mild noise.
fn render(motion: &Path, size: Option<(usize, usize)>) -> (Vec<GrayU8>, Vec<Quad>) {
    render_on(motion, size, "skimage_grass.png")
}

fn render_on(motion: &Path, size: Option<(usize, usize)>, bg: &str) -> (Vec<GrayU8>, Vec<Quad>) {
    let a = root().join("assets");
    render_frames(&SynthConfig {
        texture: a.join("textures/skimage_brick.png"),
        background: Some(a.join("textures").join(bg)),
        motion: motion.to_path_buf(),
        size,
        noise: 2.0,
        seed: 5,
        ..SynthConfig::default()
    })
    .expect("render")
}

/// The fraction of frames (after the first) whose centre error is below 5 px.
/// Checks that each tracker keeps its centre within 5 px of the truth on at least 90% of the
/// frames after the first (the failure names the mean and worst errors).
fn check(trackers: &[&str], frames: &[GrayU8], truth: &[Quad], what: &str) {
    for name in trackers {
        let spec = TrackerSpec::whole(name).expect("registered");
        let mut t = Tracker::new(&spec).expect("builds");
        t.initialize(FrameInput::Gray8(&frames[0]), &truth[0])
            .expect("initialises");
        let mut good = 0;
        let mut errors = Vec::new();
        for (f, q) in frames[1..].iter().zip(&truth[1..]) {
            let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
            assert!(out.corners.is_finite());
            let e = out.corners.centroid().dist(q.centroid());
            errors.push(e);
            if out.status == TrackStatus::Tracking && e < 5.0 {
                good += 1;
            }
        }
        let frac = good as f64 / (frames.len() - 1) as f64;
        let worst = errors.iter().copied().fold(0.0, f64::max);
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!(
            frac >= 0.9,
            "{name} on {what}: {frac:.3} of frames within 5 px (mean {mean:.2} px, worst \
             {worst:.2} px)"
        );
    }
}

#[test]
fn whole_trackers_follow_a_translating_target() {
    let d = TempDir::new("whole-tr");
    let p = d.path().join("translation.txt");
    write_profile(&p, &synthetic(120, |_| 1.0));
    let (frames, truth) = render(&p, Some((480, 360)));
    check(
        &modelling(Motion::Translation),
        &frames,
        &truth,
        "translation",
    );
}

#[test]
fn scale_trackers_follow_a_target_that_changes_scale() {
    let d = TempDir::new("whole-sc");
    let p = d.path().join("scale.txt");
    // 1 -> 1.5 -> 0.7 times the size, about 1% a frame at most.
    write_profile(&p, &synthetic(150, |t| 1.1 + 0.4 * (t / 24.0).sin()));
    let (frames, truth) = render(&p, Some((560, 420)));
    check(
        &modelling(Motion::TranslationScale),
        &frames,
        &truth,
        "scale change",
    );
}

/// The width of the fragments FragTrack shows (its box at the size it searched), frame by frame.
#[derive(Default)]
struct FragmentWidths(Vec<f64>);

impl regtrack::observe::Observer for FragmentWidths {
    fn iteration(&mut self, _: &regtrack::observe::Iteration<'_>) {}
    fn wants_method_visuals(&self) -> bool {
        true
    }
    fn method_visual(&mut self, _: usize, _: usize, v: &regtrack::observe::MethodVisual<'_>) {
        let xs = || v.quads.iter().flat_map(|q| q.0.iter().map(|p| p.x));
        let (lo, hi) = (xs().fold(f64::MAX, f64::min), xs().fold(f64::MIN, f64::max));
        self.0.push(hi - lo);
    }
}

/// FragTrack reports a translation, but its fragments vote on size as the paper's do: on a
/// photograph that grows to 1.5 times its size and shrinks to 0.7, the box it searches follows
/// the target's width and the centre stays on the target far more often than with one size
/// (`scale_step = 0`), whose fragments slide to an edge of the grown target. (Over the brick
/// texture, whose rows repeat, the height is ambiguous and drifts: docs/learning.md.)
#[test]
fn fragtrack_searches_the_targets_size_and_keeps_its_centre() {
    let d = TempDir::new("whole-frag-sc");
    let p = d.path().join("scale.txt");
    write_profile(&p, &synthetic(150, |t| 1.1 + 0.4 * (t / 24.0).sin()));
    let a = root().join("assets/textures");
    let (frames, truth) = render_frames(&SynthConfig {
        texture: a.join("skimage_coffee.png"),
        background: Some(a.join("skimage_grass.png")),
        motion: p,
        size: Some((560, 420)),
        noise: 2.0,
        seed: 5,
        ..SynthConfig::default()
    })
    .expect("render");
    let run = |step: &str| {
        let mut spec = TrackerSpec::whole("fragtrack").expect("registered");
        spec.set_param("scale_step", step).expect("a parameter");
        let mut t = Tracker::new(&spec).expect("builds");
        t.initialize(FrameInput::Gray8(&frames[0]), &truth[0])
            .expect("initialises");
        let mut widths = FragmentWidths::default();
        let mut errors = Vec::new();
        for (f, q) in frames[1..].iter().zip(&truth[1..]) {
            let out = t.update(FrameInput::Gray8(f), &mut widths);
            assert_eq!(out.status, TrackStatus::Tracking);
            errors.push(out.corners.centroid().dist(q.centroid()));
        }
        let sized = widths
            .0
            .iter()
            .zip(&truth[1..])
            .filter(|(w, q)| (*w / (q.0[1].x - q.0[0].x) - 1.0).abs() < 0.1)
            .count() as f64
            / widths.0.len() as f64;
        let within = errors.iter().filter(|e| **e < 5.0).count() as f64 / errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        (widths.0, sized, within, mean)
    };
    let (_, sized, within, mean) = run("0.05");
    let (fixed, sized1, within1, mean1) = run("0");
    let w0 = truth[0].0[1].x - truth[0].0[0].x;
    assert!(fixed.iter().all(|w| (w - w0).abs() <= 1.0), "one size");
    assert!(
        sized >= 0.8 && within >= 0.9 && mean < 0.5 * mean1,
        "box within 10% of the target's width on {sized:.3} of the frames ({sized1:.3} with one \
         size); centre within 5 px on {within:.3} (mean {mean:.2} px) against {within1:.3} \
         ({mean1:.2} px) with one size"
    );
}

/// The UCSB profiles over a photograph (as the real sequences were filmed in a room). Over the
/// grass texture, whose clutter is stronger than the small brick target's texture, KCF with the
/// paper's padding (a window 2.5 times the target) locks onto the static background on
/// `ucsb_bricks_m1` from the second frame; DSST (padding 1) and RCT hold (docs/learning.md).
#[test]
fn whole_trackers_follow_the_ucsb_profiles_within_their_model() {
    let m = root().join("assets/motion");
    for (profile, motion) in [
        ("ucsb_bricks_m1.txt", Motion::Translation),
        ("ucsb_bricks_m3.txt", Motion::Translation),
        ("ucsb_bricks_zm.txt", Motion::TranslationScale),
        ("ucsb_bricks_rt.txt", Motion::Similarity),
    ] {
        let (frames, truth) = render_on(&m.join(profile), None, "skimage_coffee.png");
        check(&modelling(motion), &frames, &truth, profile);
    }
}

/// TLD reports the target lost while it is gone (a covered camera) and re-detects it where it
/// comes back, 30 frames of motion later.
#[test]
fn tld_loses_the_target_while_it_is_gone_and_redetects_it() {
    let d = TempDir::new("whole-tld");
    let p = d.path().join("translation.txt");
    write_profile(&p, &synthetic(120, |_| 1.0));
    let (frames, truth) = render(&p, Some((480, 360)));
    let blank = GrayU8 {
        width: 480,
        height: 360,
        data: vec![90; 480 * 360],
    };
    let spec = TrackerSpec::whole("tld").unwrap();
    let mut t = Tracker::new(&spec).unwrap();
    t.initialize(FrameInput::Gray8(&frames[0]), &truth[0])
        .unwrap();
    for f in &frames[1..40] {
        assert_eq!(
            t.update(FrameInput::Gray8(f), &mut NoObserver).status,
            TrackStatus::Tracking
        );
    }
    for _ in 0..10 {
        let out = t.update(FrameInput::Gray8(&blank), &mut NoObserver);
        assert!(
            matches!(out.status, TrackStatus::Lost(_)),
            "{:?}",
            out.status
        );
        assert!(out.corners.is_finite());
    }
    let jump = truth[70].centroid().dist(truth[39].centroid());
    assert!(jump > 30.0, "the target comes back {jump:.0} px away");
    let mut good = 0;
    for (f, q) in frames[70..].iter().zip(&truth[70..]) {
        let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
        if out.status == TrackStatus::Tracking && out.corners.centroid().dist(q.centroid()) < 5.0 {
            good += 1;
        }
    }
    assert!(good >= 45, "{good} of 50 frames found after the return");
}

/// The random trackers are reproducible from their seed, and the seed matters.
#[test]
fn seeded_trackers_repeat_themselves() {
    let d = TempDir::new("whole-seed");
    let p = d.path().join("translation.txt");
    write_profile(&p, &synthetic(40, |_| 1.0));
    let (frames, truth) = render(&p, Some((480, 360)));
    let run = |name: &str, seed: &str| -> Vec<Quad> {
        let mut spec = TrackerSpec::whole(name).unwrap();
        spec.set_param("seed", seed).unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&frames[0]), &truth[0])
            .unwrap();
        frames[1..]
            .iter()
            .map(|f| t.update(FrameInput::Gray8(f), &mut NoObserver).corners)
            .collect()
    };
    // Every tracker that draws random numbers (it has a `seed`) repeats itself under a seed.
    for e in WHOLE_REGISTRY
        .iter()
        .filter(|e| e.build.params.iter().any(|d| d.name == "seed"))
    {
        assert_eq!(run(e.name, "3"), run(e.name, "3"), "{}", e.name);
    }
    assert_ne!(run("rct", "3"), run("rct", "4"));
}

/// Every tracker with a `threads` parameter (the work of a frame shared among threads) tracks
/// to the same bits on one thread as on three.
#[test]
fn threaded_trackers_give_the_same_bits_on_any_number_of_threads() {
    let d = TempDir::new("whole-threads");
    let p = d.path().join("translation.txt");
    write_profile(&p, &synthetic(30, |_| 1.0));
    let (frames, truth) = render(&p, Some((480, 360)));
    let run = |name: &str, threads: &str| -> Vec<(u64, u64)> {
        let mut spec = TrackerSpec::whole(name).unwrap();
        spec.set_param("threads", threads).unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&frames[0]), &truth[0])
            .unwrap();
        frames[1..]
            .iter()
            .flat_map(|f| {
                let c = t.update(FrameInput::Gray8(f), &mut NoObserver).corners;
                c.0.map(|p| (p.x.to_bits(), p.y.to_bits()))
            })
            .collect()
    };
    let threaded: Vec<_> = WHOLE_REGISTRY
        .iter()
        .filter(|e| e.build.params.iter().any(|d| d.name == "threads"))
        .map(|e| e.name)
        .collect();
    assert!(threaded.contains(&"kcf") && threaded.contains(&"cmt"));
    for name in threaded {
        assert_eq!(run(name, "1"), run(name, "3"), "{name}");
    }
}

/// KCF on raw gray levels follows a target whose texture dominates its window. (Raw levels are
/// not normalised per cell as HOG is: a small, faint target over a contrasted background, as the
/// brick texture over grass, leaves the window's static background to win.)
#[test]
fn kcf_follows_a_contrasted_target_with_raw_pixels() {
    let d = TempDir::new("whole-raw");
    let p = d.path().join("translation.txt");
    write_profile(&p, &synthetic(60, |_| 1.0));
    let a = root().join("assets");
    let (frames, truth) = render_frames(&SynthConfig {
        texture: a.join("textures/skimage_grass.png"),
        motion: p.clone(),
        size: Some((480, 360)),
        noise: 2.0,
        seed: 5,
        ..SynthConfig::default()
    })
    .expect("render");
    let mut spec = TrackerSpec::whole("kcf").unwrap();
    for (k, v) in [
        ("features", "raw"),
        ("kernel_sigma", "0.2"),
        ("interp", "0.075"),
    ] {
        spec.set_param(k, v).unwrap();
    }
    let mut t = Tracker::new(&spec).unwrap();
    t.initialize(FrameInput::Gray8(&frames[0]), &truth[0])
        .unwrap();
    let good = frames[1..]
        .iter()
        .zip(&truth[1..])
        .filter(|(f, q)| {
            let out = t.update(FrameInput::Gray8(f), &mut NoObserver);
            out.corners.centroid().dist(q.centroid()) < 5.0
        })
        .count();
    assert!(good >= 54, "KCF raw: {good} of 59 frames within 5 px");
}

/// A frame in someone else's buffer (`FrameInput::View8`, what the Python binding passes for
/// numpy frames) is tracked exactly as the same frame owned (`Gray8`), by a registration tracker
/// and a whole tracker.
#[test]
fn a_borrowed_frame_tracks_as_an_owned_one() {
    use regtrack::dataset::synth::{SynthConfig, render_frames};
    use regtrack::imaging::ImageRef;
    use regtrack::observe::NoObserver;
    use regtrack::tracker::{FrameInput, Tracker, TrackerSpec};
    let cfg = SynthConfig {
        texture: crate::common::root().join("assets/textures/skimage_coffee.png"),
        motion: crate::common::root().join("assets/motion/ucsb_bricks_rt.txt"),
        max_frames: Some(6),
        ..SynthConfig::default()
    };
    let (frames, quads) = render_frames(&cfg).unwrap();
    for spec in [
        TrackerSpec::from_names("fclk", "zncc", "homography").unwrap(),
        TrackerSpec::whole("kcf").unwrap(),
    ] {
        let (mut owned, mut borrowed) =
            (Tracker::new(&spec).unwrap(), Tracker::new(&spec).unwrap());
        let view = |k: usize| {
            FrameInput::View8(
                ImageRef::new(frames[k].width, frames[k].height, &frames[k].data).unwrap(),
            )
        };
        owned
            .initialize(FrameInput::Gray8(&frames[0]), &quads[0])
            .unwrap();
        borrowed.initialize(view(0), &quads[0]).unwrap();
        for k in 1..frames.len() {
            let a = owned.update(FrameInput::Gray8(&frames[k]), &mut NoObserver);
            let b = borrowed.update(view(k), &mut NoObserver);
            assert_eq!(
                (a.status, a.corners),
                (b.status, b.corners),
                "{}: frame {k}",
                spec.label()
            );
        }
    }
}
