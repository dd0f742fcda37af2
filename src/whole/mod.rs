//! Whole trackers: the learning-based trackers the paper compares the registration trackers with
//! (KCF, DSST, RCT, TLD, CMT), and more of those MTF bundles (DFT, FragTrack, MIL, Struck), each one file and
//! one entry of [`REGISTRY`]. They track a box (and
//! CMT a rotated one): the output quad is the initial quad moved by a similarity (translation,
//! scale, rotation about its centre), so they are compared with the registration trackers
//! against translation ground truth, as in the paper.

/// The [`WholeTracker::base`] accessors of a tracker whose [`Base`] is its field `base`.
macro_rules! base_field {
    () => {
        fn base(&self) -> &Base {
            &self.base
        }
        fn base_mut(&mut self) -> &mut Base {
            &mut self.base
        }
    };
}

pub(crate) mod cf;
pub mod cmt;
pub mod dft;
pub mod dsst;
pub mod fragtrack;
pub mod kcf;
pub mod mil;
pub mod rct;
pub mod struck;
pub mod tld;

use crate::error::{Error, Result};
use crate::geometry::{Point, Quad};
use crate::imaging::GrayF32;
use crate::observe::MethodVisual;
use crate::observe::{Iteration, Observer};
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::spec::{TrackerSpec, WholeSpec};
use crate::status::{FrameOutcome, FrameTiming, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};
use std::borrow::Cow;
use std::time::{Duration, Instant};

/// A registry entry of a whole tracker: its parameters, the motion it models and its
/// constructor.
#[derive(Clone, Copy)]
pub struct WholeDef {
    pub params: &'static [ParamDef],
    pub motion: Motion,
    pub build: fn(&WholeSpec) -> Result<Box<dyn VisualTracker>>,
}

/// What motion of its target a whole tracker estimates (the initial quad moved by it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Motion {
    Translation,
    /// Translation and scale.
    TranslationScale,
    /// Translation, scale and rotation.
    Similarity,
}

/// The whole trackers: one entry per file.
pub const REGISTRY: &[Entry<WholeDef>] = &[
    kcf::ENTRY,
    dsst::ENTRY,
    rct::ENTRY,
    tld::ENTRY,
    cmt::ENTRY,
    dft::ENTRY,
    fragtrack::ENTRY,
    mil::ENTRY,
    struck::ENTRY,
];

/// Where a whole tracker puts its target: the initial quad moved by a similarity about its
/// centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// The target's centre in the frame.
    pub cx: f64,
    pub cy: f64,
    /// Size relative to the initial quad.
    pub scale: f64,
    /// Rotation from the initial quad (radians, image axes).
    pub angle: f64,
}

/// What a whole tracker implements; [`VisualTracker`] follows from it (the spec, the status and
/// the corners are the [`Base`]'s; initialising and moving the tracker check the quad there
/// first).
pub trait WholeTracker: Send + std::fmt::Debug {
    /// The smallest side (px) of a target the tracker can start on.
    const MIN_SIDE: f64;
    fn base(&self) -> &Base;
    fn base_mut(&mut self) -> &mut Base;
    /// Learns the target: called once the base has started on `quad` (checked, at least
    /// [`WholeTracker::MIN_SIDE`] a side).
    fn start(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()>;
    /// Tracks one frame ([`VisualTracker::update`]).
    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome;
    /// The base was moved to new corners ([`VisualTracker::set_corners`]): adjust the pose to
    /// what the tracker can represent, and its model. By default the pose keeps only what the
    /// tracker's registry entry models ([`Base::keep_only`]).
    fn corners_set(&mut self) -> Result<()> {
        let motion = self.base().motion;
        self.base_mut().keep_only(motion);
        Ok(())
    }
}

impl<T: WholeTracker> VisualTracker for T {
    fn spec(&self) -> &TrackerSpec {
        &self.base().spec
    }
    fn initialize(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()> {
        let (w, h) = input.size();
        crate::visual_tracker::check_initial_region(quad, w, h)?;
        self.base_mut().start(quad, T::MIN_SIDE)?;
        // The learning trackers read grey (a colour frame's grey image).
        self.start(input.gray(), quad)
    }
    fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        self.track(input.gray(), observer)
    }
    fn set_corners(&mut self, quad: &Quad) -> Result<()> {
        self.base_mut().set_corners(quad)?;
        self.corners_set()
    }
    fn status(&self) -> TrackStatus {
        self.base().status
    }
    fn corners(&self) -> Quad {
        self.base().quad()
    }
}

/// What every whole tracker keeps: its spec, the initial quad, the pose, the status.
#[derive(Clone, Debug)]
pub struct Base {
    pub spec: TrackerSpec,
    pub init: Quad,
    pub c0: Point,
    /// The target's width and height (mean of opposite sides of the initial quad).
    pub size0: (f64, f64),
    pub pose: Pose,
    pub status: TrackStatus,
    pub frame: usize,
    /// What the tracker's registry entry models (every motion for a name no entry has).
    pub motion: Motion,
}

impl Base {
    pub fn new(spec: &WholeSpec) -> Self {
        let motion = crate::registry::lookup(REGISTRY, "whole tracker", &spec.tracker)
            .map_or(Motion::Similarity, |e| e.build.motion);
        Base {
            motion,
            spec: TrackerSpec::Whole(spec.clone()),
            init: Quad::default(),
            c0: Point::default(),
            size0: (0.0, 0.0),
            pose: Pose {
                cx: 0.0,
                cy: 0.0,
                scale: 1.0,
                angle: 0.0,
            },
            status: TrackStatus::Uninitialized,
            frame: 0,
        }
    }

    /// Starts on `quad` (checked), at frame 0. The target must be at least `min_side` pixels
    /// a side.
    pub fn start(&mut self, quad: &Quad, min_side: f64) -> Result<()> {
        quad.validate()?;
        let p = quad.0;
        let w = 0.5 * (p[0].dist(p[1]) + p[3].dist(p[2]));
        let h = 0.5 * (p[0].dist(p[3]) + p[1].dist(p[2]));
        if w < min_side || h < min_side {
            return Err(Error::InvalidRegion(format!(
                "{}: the target must be at least {min_side} px a side, got {w:.1} x {h:.1}",
                self.spec.label()
            )));
        }
        self.init = *quad;
        self.c0 = quad.centroid();
        self.size0 = (w, h);
        self.pose = Pose {
            cx: self.c0.x,
            cy: self.c0.y,
            scale: 1.0,
            angle: 0.0,
        };
        self.status = TrackStatus::Tracking;
        self.frame = 0;
        Ok(())
    }

    /// The quad at `pose`.
    pub fn quad_at(&self, pose: &Pose) -> Quad {
        let (s, c) = pose.angle.sin_cos();
        self.init.map(|p| {
            let (dx, dy) = (p.x - self.c0.x, p.y - self.c0.y);
            Point {
                x: pose.cx + pose.scale * (c * dx - s * dy),
                y: pose.cy + pose.scale * (s * dx + c * dy),
            }
        })
    }

    /// The current quad.
    pub fn quad(&self) -> Quad {
        self.quad_at(&self.pose)
    }

    /// The pose closest to `quad`: its centre, the square root of the area ratio, the mean
    /// rotation of its sides.
    pub fn pose_of(&self, quad: &Quad) -> Pose {
        let c = quad.centroid();
        let a0 = self.init.signed_area().abs().max(1e-9);
        let scale = (quad.signed_area().abs() / a0).sqrt();
        let (mut sx, mut sy) = (0.0, 0.0);
        for k in 0..4 {
            let (a, b) = (self.init.0[k], self.init.0[(k + 1) % 4]);
            let (p, q) = (quad.0[k], quad.0[(k + 1) % 4]);
            let angle = (q.y - p.y).atan2(q.x - p.x) - (b.y - a.y).atan2(b.x - a.x);
            sx += angle.cos();
            sy += angle.sin();
        }
        Pose {
            cx: c.x,
            cy: c.y,
            scale,
            angle: sy.atan2(sx),
        }
    }

    /// Drops from the pose what a tracker of `motion` does not estimate (a translation tracker
    /// keeps neither scale nor rotation, a translation-and-scale one no rotation): what its
    /// [`WholeTracker::corners_set`] does with corners set by hand.
    pub fn keep_only(&mut self, motion: Motion) {
        if motion < Motion::Similarity {
            self.pose.angle = 0.0;
        }
        if motion < Motion::TranslationScale {
            self.pose.scale = 1.0;
        }
    }

    /// Moves to `quad` (checked) and resumes tracking.
    pub fn set_corners(&mut self, quad: &Quad) -> Result<()> {
        if self.status == TrackStatus::Uninitialized {
            return Err(Error::InvalidParameter(format!(
                "{}: initialise before setting the corners",
                self.spec.label()
            )));
        }
        quad.validate()?;
        self.pose = self.pose_of(quad);
        self.status = TrackStatus::Tracking;
        Ok(())
    }

    /// Starts a frame: the clock, the frame count and the observer's `frame_started`.
    pub fn begin(&mut self, observer: &mut dyn Observer) -> Instant {
        let started = Instant::now();
        self.frame += 1;
        observer.frame_started(self.frame, &self.quad());
        started
    }

    /// The outcome of a frame on which the tracker does not run (not initialised, or lost).
    pub fn idle(&self) -> FrameOutcome {
        FrameOutcome::idle(self.frame, self.status, self.quad())
    }

    /// Ends a frame: checks the new pose (finite, a scale within 1/20..20 of the initial size,
    /// the centre within half a frame of the frame), updates the status, reports one iteration
    /// (parameters `cx, cy, scale, angle`), the method's visual and the outcome to the observer.
    #[allow(clippy::too_many_arguments)]
    pub fn finish(
        &mut self,
        found: std::result::Result<(Pose, f64), LossReason>,
        frame_size: (usize, usize),
        started: Instant,
        preprocess: Duration,
        observer: &mut dyn Observer,
        visual: Option<MethodVisual<'_>>,
    ) -> FrameOutcome {
        let start = self.quad();
        let estimate = found
            .as_ref()
            .ok()
            .map(|(pose, _)| self.quad_at(pose))
            .filter(Quad::is_finite);
        let checked = found.and_then(|(pose, sim)| {
            let ok = [pose.cx, pose.cy, pose.scale, pose.angle, sim]
                .iter()
                .all(|v| v.is_finite());
            if !ok {
                return Err(LossReason::NonFinite);
            }
            if !(0.05..=20.0).contains(&pose.scale) {
                return Err(LossReason::Degenerate);
            }
            let centre = crate::geometry::Point::new(pose.cx, pose.cy);
            if centre.far_outside(frame_size.0, frame_size.1) {
                return Err(LossReason::OutOfFrame);
            }
            Ok((pose, sim))
        });
        let (status, similarity) = match checked {
            Ok((pose, sim)) => {
                self.pose = pose;
                (TrackStatus::Tracking, sim)
            }
            Err(r) => (TrackStatus::Lost(r), f64::NAN),
        };
        self.status = status;
        let corners = self.quad();
        let elapsed = started.elapsed();
        if status == TrackStatus::Tracking {
            let p = self.pose;
            observer.iteration(&Iteration {
                frame: self.frame,
                level: 0,
                iteration: 0,
                params: &[p.cx, p.cy, p.scale, p.angle],
                corners,
                similarity,
                step: corners.change_norm(&start),
                elapsed,
                duration: elapsed,
                patch: None,
            });
        }
        if let Some(v) = visual
            && observer.wants_method_visuals()
        {
            observer.method_visual(self.frame, 0, &v);
        }
        let outcome = FrameOutcome {
            frame: self.frame,
            status,
            corners,
            iterations: usize::from(status == TrackStatus::Tracking),
            converged: status == TrackStatus::Tracking,
            similarity,
            searched: true,
            estimate,
            confidence: None,
            timing: FrameTiming {
                preprocess,
                search: elapsed.saturating_sub(preprocess),
            },
        };
        observer.frame_finished(self.frame, &outcome);
        outcome
    }
}

/// The best of `score` (higher is better) over the whole-pixel positions within `radius` of
/// `(x0, y0)`: with `coarse_step` > 1, every `coarse_step`-th position first, then every
/// position within 1.5 steps of the best of those (the coarse-to-fine search of RCT, MIL,
/// Struck and FragTrack). A tie keeps the position visited first. Returns the position and its
/// score (`(x0, y0, -inf)` when no score is above minus infinity).
pub(crate) fn search_disc(
    (x0, y0): (i64, i64),
    radius: f64,
    coarse_step: i64,
    mut score: impl FnMut(i64, i64) -> f64,
) -> (i64, i64, f64) {
    let mut best = (x0, y0, f64::NEG_INFINITY);
    let mut visit = |cx: i64, cy: i64, radius: f64, step: i64, best: &mut (i64, i64, f64)| {
        let r = radius.floor() as i64;
        let mut dy = -r - (-r).rem_euclid(step);
        while dy <= r {
            let mut dx = -r - (-r).rem_euclid(step);
            while dx <= r {
                if ((dx * dx + dy * dy) as f64) <= radius * radius {
                    let s = score(cx + dx, cy + dy);
                    if s > best.2 {
                        *best = (cx + dx, cy + dy, s);
                    }
                }
                dx += step;
            }
            dy += step;
        }
    };
    if coarse_step > 1 {
        visit(x0, y0, radius, coarse_step, &mut best);
        let (bx, by) = (best.0, best.1);
        visit(bx, by, coarse_step as f64 * 1.5, 1, &mut best);
    } else {
        visit(x0, y0, radius, 1, &mut best);
    }
    best
}

/// The value of parameter `name` (one of `defs`) in `spec`: its set value or its default.
pub(crate) fn param(spec: &WholeSpec, defs: &[ParamDef], name: &str) -> f64 {
    defs.iter()
        .find(|d| d.name == name)
        .map(|d| spec.method.get(d))
        .unwrap_or(0.0)
}

/// Single linkage: the connected components of `0..n` under `linked(i, j)` (tested for
/// `i < j`), as one label per item (items of a component share it).
pub(crate) fn components(n: usize, linked: impl Fn(usize, usize) -> bool) -> Vec<usize> {
    fn root(l: &mut [usize], i: usize) -> usize {
        let mut r = i;
        while l[r] != r {
            r = l[r];
        }
        l[i] = r;
        r
    }
    let mut label: Vec<usize> = (0..n).collect();
    for i in 0..n {
        for j in i + 1..n {
            if linked(i, j) {
                let (a, b) = (root(&mut label, i), root(&mut label, j));
                label[a] = b;
            }
        }
    }
    (0..n).map(|i| root(&mut label, i)).collect()
}

/// The frame as floats (8-bit frames are converted; float frames are used as they are).
pub(crate) fn frame_f32(input: FrameInput<'_>) -> Cow<'_, GrayF32> {
    match input {
        FrameInput::Gray8(i) => Cow::Owned(i.to_f32()),
        FrameInput::View8(i) => Cow::Owned(crate::imaging::Image {
            width: i.width,
            height: i.height,
            data: i.data.iter().map(|&v| v as f32).collect(),
        }),
        FrameInput::Gray32(i) | FrameInput::Smoothed(i) => Cow::Borrowed(i),
        FrameInput::Colour(c) => Cow::Owned(c.gray.to_f32()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::MethodParams;

    /// A base knows its tracker's motion from the registry (by name or alias), and corners set
    /// by hand keep only that motion.
    #[test]
    fn a_base_keeps_only_its_entrys_motion() {
        let spec = |name: &str| WholeSpec {
            tracker: name.into(),
            method: MethodParams::default(),
        };
        for e in REGISTRY {
            assert_eq!(
                Base::new(&spec(e.name)).motion,
                e.build.motion,
                "{}",
                e.name
            );
            for a in e.aliases {
                assert_eq!(Base::new(&spec(a)).motion, e.build.motion, "{a}");
            }
        }
        let mut b = Base::new(&spec("kcf"));
        b.pose.scale = 1.3;
        b.pose.angle = 0.2;
        b.keep_only(b.motion);
        assert_eq!((b.pose.scale, b.pose.angle), (1.0, 0.0));
        let mut b = Base::new(&spec("tld"));
        b.pose.scale = 1.3;
        b.pose.angle = 0.2;
        b.keep_only(b.motion);
        assert_eq!((b.pose.scale, b.pose.angle), (1.3, 0.0));
    }

    #[test]
    fn a_pose_maps_the_initial_quad_and_is_recovered_from_its_quad() {
        let mut b = Base::new(&WholeSpec {
            tracker: "kcf".into(),
            method: MethodParams::default(),
        });
        let q = Quad::from_rect(10.0, 20.0, 40.0, 30.0);
        b.start(&q, 4.0).unwrap();
        assert_eq!(b.quad(), q);
        let pose = Pose {
            cx: 100.0,
            cy: 80.0,
            scale: 1.5,
            angle: 0.3,
        };
        let moved = b.quad_at(&pose);
        let back = b.pose_of(&moved);
        for (a, e) in [
            (back.cx, pose.cx),
            (back.cy, pose.cy),
            (back.scale, pose.scale),
            (back.angle, pose.angle),
        ] {
            assert!((a - e).abs() < 1e-9, "{a} vs {e}");
        }
        assert!(b.start(&Quad::from_rect(0.0, 0.0, 2.0, 30.0), 4.0).is_err());
    }
}
