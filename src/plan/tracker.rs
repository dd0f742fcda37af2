//! The registration tracker: its own searcher (the finest level's problem and method), the
//! plan of stages it runs on each frame ([`Plan`]), where it reads frames ([`FrameSource`]),
//! and what it keeps between frames to judge them. Its policies are in the files beside it:
//! [`super::regrow`] (a frame's run of the plan, redone on a larger region), [`super::judge`]
//! (the loss checks), [`super::redetect`] (after a loss).

use super::judge::{iterations_of, more_confident};
use super::{Init, Judges, Plan, Searcher, predict::Predictor, redetect::Detector};
use crate::error::{Error, Result};
use crate::geometry::Quad;
use crate::imaging::gaussian_kernel;
use crate::landscape::{Landscape, LandscapeSpec};
use crate::observe::Observer;
use crate::registration::BlockCorrelation;
use crate::registration::{Context, FrameSource, LossCheck, SearchMethod, region_around};
use crate::spec::{LossPolicy, RegistrationSpec, TrackerParams, TrackerSpec};
use crate::ssm::Params;
use crate::status::{FrameOutcome, FrameTiming, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, Inspection, VisualTracker};
use std::time::Instant;

/// The confidence's blocks per side (see [`BlockCorrelation`]): 4 x 4 blocks of about
/// 12 x 12 samples on the default 50 x 50 grid.
pub(super) const CONFIDENCE_BLOCKS: usize = 4;

/// A registration tracker: SSM + AM + SM, built from a [`RegistrationSpec`] by the factory,
/// and the plan it runs on each frame.
#[derive(Debug)]
pub struct RegistrationTracker {
    pub(super) spec: TrackerSpec,
    pub(super) params: TrackerParams,
    /// The tracker's own search method and problem (the finest level's).
    pub(super) finest: Searcher,
    pub(super) plan: Plan,
    pub(super) src: FrameSource,
    pub(super) status: TrackStatus,
    pub(super) frame: usize,
    pub(super) corners: Quad,
    pub(super) initial_area: f64,
    /// The quad the tracker was initialised on (the view the template was taken from).
    pub(super) initial: Quad,
    /// The recent confidences the loss checks compare a frame's with.
    pub(super) loss: LossCheck,
    /// Where the last search ended when only its confidence failed (see `update`).
    pub(super) lost_at: Option<Params>,
    /// The confidences a frame's end is judged by.
    pub(super) judges: Judges,
    /// What `on_loss=redetect` ranks its candidates with.
    pub(super) detector: Detector,
    /// Whether a frame's region may be smoothed only where the search reads it (see
    /// [`crate::registration::Reader::Part`]); off only to compare with the whole region's
    /// results.
    pub(super) partial: bool,
    /// The largest move of a corner in the last tracked frame (pixels): how far beyond its
    /// start the first part of the next frame's region is smoothed.
    pub(super) motion: f64,
    /// Where the next frame's search starts (`predict=on`).
    pub(super) predictor: Predictor,
    /// The last frame tracked (the velocity of a target found again is over the frames since).
    pub(super) last_tracked: usize,
    /// The second hypothesis on frames that fail the checks (`second`, `plan/second.rs`).
    pub(super) second: Option<Box<RegistrationTracker>>,
    /// The template's periods, if it looks like itself shifted (`plan/periodic.rs`).
    pub(super) periods: Vec<(f64, f64)>,
}

impl RegistrationTracker {
    /// A tracker for `spec` (with canonical names and checked parameters) searching with `main`
    /// and running `plan` on each frame.
    pub fn from_plan(spec: RegistrationSpec, main: Searcher, plan: Plan) -> Self {
        let p = spec.params.clone();
        let gradient = main.sm.requires().derivatives;
        let kernel = gaussian_kernel(
            p.smoothing_size(gradient),
            p.smoothing_sigma(gradient) as f32,
        );
        let src = FrameSource::new(kernel, plan.levels());
        let src = match spec.params.channels {
            crate::spec::Channels::Df => src.with_descriptor_fields(),
            c => src.with_channels(c.count()),
        };
        RegistrationTracker {
            spec: TrackerSpec::Registration(spec),
            params: p,
            finest: main,
            plan,
            src,
            status: TrackStatus::Uninitialized,
            frame: 0,
            corners: Quad::default(),
            initial_area: 0.0,
            initial: Quad::default(),
            loss: LossCheck::default(),
            lost_at: None,
            judges: Judges::default(),
            detector: Detector::default(),
            partial: true,
            motion: 0.0,
            predictor: Predictor::default(),
            last_tracked: 0,
            second: None,
            periods: Vec::new(),
        }
    }

    /// Adds the second hypothesis (`second`): a tracker of the same SSM.
    pub fn with_second(mut self, second: RegistrationTracker) -> Self {
        self.second = Some(Box::new(second));
        self
    }

    /// Current SSM parameters (normalised frame).
    pub fn params(&self) -> Params {
        self.finest.ctx.params()
    }
    /// The plan's stages, in order (see [`Plan::describe`]).
    pub fn stages(&self) -> Vec<String> {
        self.plan.describe()
    }
    /// The models and buffers, taken out of the tracker (for benchmarks of single stages).
    pub fn into_context(self) -> Context {
        self.finest.ctx
    }
    /// The finest level's context and search method, for driving single iterations (the
    /// per-iteration benchmarks): after [`VisualTracker::initialize`] the method is initialised
    /// on the template and the context's parameters are where the tracker is.
    pub fn into_parts(self) -> (Context, Box<dyn SearchMethod>) {
        self.finest.into_parts()
    }
    /// The pre-smoothing kernel (of the finest level).
    pub fn smoothing(&self) -> &crate::imaging::GaussianKernel {
        self.src.kernel()
    }
    /// The models and buffers (template, last sampled patch...), read-only.
    pub fn context(&self) -> &Context {
        &self.finest.ctx
    }
    /// Whether frames may be smoothed only where the search reads (on by default; off to
    /// compare).
    pub fn set_partial(&mut self, on: bool) {
        self.partial = on;
    }

    /// The region to pre-process around `q`.
    pub(super) fn region_around(&self, q: &Quad) -> crate::geometry::Rect {
        region_around(q, self.params.roi_margin)
    }

    /// After an initialisation, a move by hand or a loss: the next frame has no previous
    /// frame to be compared with (its previous patch is not the target's, or not near).
    pub(super) fn forget_previous(&mut self) {
        self.judges.has_previous = false;
    }
}

impl RegistrationTracker {
    /// A frame tracked: where it ended is kept, and its patch for the next frame's check.
    fn tracked(
        &mut self,
        input: FrameInput<'_>,
        out: super::Estimate,
        start_corners: &Quad,
        timing: FrameTiming,
    ) -> FrameOutcome {
        self.motion = (0..4)
            .map(|i| out.corners.0[i].dist(start_corners.0[i]))
            .fold(0.0, f64::max);
        self.finest.ctx.set_params(out.params);
        if self.status == TrackStatus::Tracking {
            self.predictor.tracked(&self.corners, &out.corners);
        } else {
            let gap = self.frame.saturating_sub(self.last_tracked);
            self.predictor.found_again(&self.corners, &out.corners, gap);
        }
        self.last_tracked = self.frame;
        self.corners = out.corners;
        self.status = TrackStatus::Tracking;
        self.lost_at = None;
        self.detector.scan = Default::default();
        // The next frame's patch is compared with this one's (made in place: a frame's update
        // does not allocate once the buffers have grown).
        self.remember_patch(input, &out);
        if self.finest.ctx.am().learns() {
            self.learn(input, &out);
        }
        FrameOutcome {
            frame: self.frame,
            status: TrackStatus::Tracking,
            corners: out.corners,
            iterations: out.iterations,
            converged: out.converged,
            similarity: out.similarity,
            searched: true,
            estimate: Some(out.corners),
            confidence: out.confidence,
            timing,
        }
    }

    /// An AM that learns the target's appearance (PCA) learns the patch where the accepted
    /// frame ended, at every level and SSM the plan searches (`remember_patch` sampled the
    /// finest level's there).
    fn learn(&mut self, input: FrameInput<'_>, out: &super::Estimate) {
        self.finest.learn(&self.src.view(input, 0), &out.params);
        let normalised = self.finest.ctx.problem().normalised_corners(&out.params);
        self.plan.learn(&mut super::Learn {
            src: &mut self.src,
            input,
            params: out.params,
            normalised,
        });
    }

    /// A frame lost for `reason`: the tracker stays where the frame started (`start`), and
    /// searches from `lost_at` too next time.
    fn lost(
        &mut self,
        reason: LossReason,
        out: Option<super::Estimate>,
        (start_params, start_corners): (Params, Quad),
        lost_at: Option<Params>,
        timing: FrameTiming,
    ) -> FrameOutcome {
        self.forget_previous();
        self.predictor.lost();
        self.finest.ctx.set_params(start_params);
        self.status = TrackStatus::Lost(reason);
        self.lost_at = lost_at;
        let finite = out.filter(|o| o.corners.is_finite());
        FrameOutcome {
            frame: self.frame,
            status: self.status,
            corners: start_corners,
            iterations: out.map_or(0, |o| o.iterations),
            converged: false,
            similarity: f64::NAN,
            searched: true,
            estimate: finite.map(|o| o.corners),
            confidence: finite.and_then(|o| o.confidence),
            timing,
        }
    }
}

impl RegistrationTracker {
    /// Where the next frame's search starts when it is predicted (`predict=on`, tracking, and
    /// a prediction away from the last pose): its parameters and corners.
    fn predicted(&self, resume: bool) -> Option<(Params, Quad)> {
        if !self.params.predict || resume {
            return None;
        }
        let q = self.predictor.predict(&self.corners);
        if q == self.corners {
            return None;
        }
        let ctx = &self.finest.ctx;
        let p = ctx.problem().moved(&ctx.params(), &self.corners, &q)?;
        Some((p, ctx.corners(&p)))
    }
}

impl VisualTracker for RegistrationTracker {
    fn landscape(
        &mut self,
        input: FrameInput<'_>,
        at: &Quad,
        spec: &LandscapeSpec,
    ) -> Option<Result<Landscape>> {
        Some(self.sweep(input, at, spec))
    }
    /// The spec (with canonical names).
    fn spec(&self) -> &TrackerSpec {
        &self.spec
    }
    /// Current status.
    fn status(&self) -> TrackStatus {
        self.status
    }
    /// Current corners (image coordinates).
    fn corners(&self) -> Quad {
        self.corners
    }
    /// Starts tracking `quad` in `input`: samples the template there.
    fn initialize(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()> {
        // Until it succeeds the tracker is not usable (its context is being replaced).
        self.status = TrackStatus::Uninitialized;
        let (w, h) = input.size();
        crate::visual_tracker::check_initial_region(quad, w, h)?;
        let res = self.params.res;
        let ctx = &mut self.finest.ctx;
        ctx.set_region(quad, res, self.params.grid)?;
        self.src
            .prepare(input, region_around(quad, self.params.roi_margin));
        self.src.build_levels(input);
        let view = self.src.view(input, 0);
        ctx.sample_template(&view);
        let (tx, ty) = ctx.problem().template_gradient();
        let energy: f64 = tx
            .iter()
            .zip(ty)
            .map(|(&a, &b)| (a * a + b * b) as f64)
            .sum();
        if energy.partial_cmp(&(1e-6 * ctx.len() as f64)) != Some(std::cmp::Ordering::Greater) {
            return Err(Error::InvalidRegion(format!(
                "cannot track {quad}: the template is flat, it has no image gradient ({})",
                crate::visual_tracker::why_flat(quad, input),
            )));
        }
        self.finest
            .sm
            .initialize(ctx, &view)
            .map_err(|r| Error::InvalidRegion(format!("cannot track {quad}: {r}")))?;
        self.plan.initialize(&Init {
            quad,
            input,
            src: &self.src,
            params: &self.params,
        })?;
        if let Some(second) = &mut self.second {
            second.initialize(input, quad)?;
        }
        self.status = TrackStatus::Tracking;
        self.frame = 0;
        self.last_tracked = 0;
        self.motion = 0.0;
        let ctx = &self.finest.ctx;
        self.corners = ctx.corners(&ctx.params());
        self.initial_area = quad.signed_area().abs();
        self.initial = self.corners;
        // What judges a frame reads the whole grid (also when the searches read part of it).
        let template = ctx.problem().whole_template();
        let mask = self.params.spi_mask();
        self.judges.template = BlockCorrelation::new(template, res, CONFIDENCE_BLOCKS);
        self.judges.template.set_mask(mask);
        self.judges.previous.set_mask(mask);
        // A colour template's periods: those of its channel of most contrast.
        let strongest = ctx.problem().strongest_channel() * res * res;
        self.periods = super::periodic::periods(&template[strongest..], res);
        // Made here so that a frame's update does not allocate.
        self.judges.blurred = vec![0.0; template.len()];
        self.judges.blur = BlockCorrelation::new(template, res, CONFIDENCE_BLOCKS);
        self.judges.blur.set_mask(mask);
        // The coarsest level made of this region (built above when the plan has levels).
        let level = self.src.levels();
        let view = self.src.view(input, level);
        self.detector = Detector::new(ctx.problem(), res, level, &view, &ctx.params());
        self.loss.reset();
        self.lost_at = None;
        self.predictor.reset();
        self.forget_previous();
        Ok(())
    }

    /// Moves the tracker to `quad` keeping its template (the SSM's least-squares fit to the
    /// quad), and resumes tracking if it was lost.
    fn set_corners(&mut self, quad: &Quad) -> Result<()> {
        if self.status == TrackStatus::Uninitialized {
            return Err(Error::InvalidRegion(
                "the tracker is not initialised".into(),
            ));
        }
        quad.validate()?;
        let ctx = &mut self.finest.ctx;
        let p = ctx.problem().fit(quad).ok_or_else(|| {
            Error::InvalidRegion(format!("cannot fit {} to {quad}", ctx.ssm().name()))
        })?;
        ctx.set_params(p);
        self.corners = ctx.corners(&p);
        self.status = TrackStatus::Tracking;
        self.loss.reset();
        self.forget_previous();
        self.lost_at = None;
        self.predictor.reset();
        self.detector.scan = Default::default();
        Ok(())
    }

    /// Tracks one frame. Never panics and never returns non-finite corners: a loss of track is
    /// reported in the status, with the last good corners.
    fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        let resume =
            matches!(self.status, TrackStatus::Lost(_)) && self.params.on_loss != LossPolicy::Stop;
        if self.status != TrackStatus::Tracking && !resume {
            return FrameOutcome::idle(self.frame, self.status, self.corners);
        }
        self.frame += 1;
        // Sums are used only in the frame they were made in (a context made again by an
        // initialisation counts its samplings from zero).
        self.judges.sums.0 = None;
        let mut timing = FrameTiming::default();
        let start_params = self.finest.ctx.params();
        let start_corners = self.corners;
        let started = Instant::now();
        // From where the target is going (`predict`), else from the last pose.
        let predicted = self.predicted(resume);
        let (from_params, from_corners) = predicted.unwrap_or((start_params, start_corners));
        let mut result = self.search_from(
            input,
            from_params,
            &from_corners,
            observer,
            started,
            &mut timing,
        );
        if resume {
            // Lost and searching on: also from where the last search ended when only its
            // confidence failed. A frame judged lost on the target (a sudden blur) is then found
            // again, where a search from the last good estimate alone falls behind a moving
            // target for good.
            if let Some(p) = self.lost_at {
                let from = self.finest.ctx.corners(&p);
                let other = self.search_from(input, p, &from, observer, started, &mut timing);
                result = more_confident(result, other);
            }
        } else {
            // Tracking: each of these runs only while the frame's end fails the checks.
            let size = input.size();
            let mut passes = self.passes(&result, size);
            // The prediction checked: a search from it that fails is done again from the last
            // pose, and the more confident end is kept.
            if predicted.is_some() && !passes {
                let other = self.search_from(
                    input,
                    start_params,
                    &start_corners,
                    observer,
                    started,
                    &mut timing,
                );
                result = more_confident(result, other);
                passes = self.passes(&result, size);
            }
            // The second hypothesis from the same start, the more confident end kept.
            if !passes
                && self.second.is_some()
                && let Some(other) =
                    self.second_hypothesis(input, &from_corners, iterations_of(&result))
            {
                result = more_confident(result, other);
                passes = self.passes(&result, size);
            }
            // Only the confidence failing: allowing for the blur of a fast move.
            if !passes && let Ok(out) = &mut result {
                self.allow_for_blur(input, out);
            }
            // A periodic template: not a look-alike one period over.
            if passes && let Ok(out) = result {
                result = Ok(self.periodic_check(input, out, observer, started, &mut timing));
            }
        }
        let checked = self.judge(result, input.size());
        // Where a search that only failed the confidence checks ended: with `on_loss=continue`
        // (or `redetect`) the next frame is searched from there too.
        let lost_at = match &checked {
            Err((LossReason::LowConfidence, Some(o))) => Some(o.params),
            _ => None,
        };
        // Failing the checks with `on_loss=redetect`: search the whole frame, also on the frame
        // the loss happens on (a sudden acceleration, 8 then 15 px a frame, left the searches
        // from the prediction and the last pose on a look-alike; by the next frame the target
        // is further away). There a candidate must also be nearly as confident as the frames
        // before ([`super::redetect::AT_LOSS`]).
        let checked = match checked {
            Err(failed) if self.params.on_loss == LossPolicy::Redetect => {
                let bar = if resume {
                    None
                } else {
                    // Before any frame was tracked, a bar of its own: nothing says yet how
                    // confident this target's frames are.
                    Some(
                        self.loss
                            .reference()
                            .map_or(super::redetect::AT_FIRST, |m| super::redetect::AT_LOSS * m),
                    )
                };
                self.redetect(input, observer, started, &mut timing, bar)
                    .ok_or(failed)
                    .map_err(|(_, out)| (LossReason::NotFound, out))
            }
            other => other,
        };
        let outcome = match checked {
            Ok(out) => self.tracked(input, out, &start_corners, timing),
            Err((reason, out)) => {
                self.lost(reason, out, (start_params, start_corners), lost_at, timing)
            }
        };
        observer.frame_finished(self.frame, &outcome);
        outcome
    }

    fn channels(&self) -> usize {
        // Descriptor fields are made of the grey frame.
        match self.params.channels {
            crate::spec::Channels::Rgb => 3,
            _ => 1,
        }
    }

    fn warped_grid(&self) -> Option<crate::visual_tracker::WarpedGrid> {
        const SIDE: usize = 11;
        let ctx = &self.finest.ctx;
        let problem = ctx.problem();
        if problem.ssm().projective() {
            return None;
        }
        // The lattice on the unit square [-0.5, 0.5]^2, which the grid's homography takes to
        // the template's quad (normalised frame), then warped to the frame.
        let unit = problem.unit();
        let (mut xs, mut ys) = (vec![0f32; SIDE * SIDE], vec![0f32; SIDE * SIDE]);
        for k in 0..SIDE * SIDE {
            let at = |i: usize| -0.5 + i as f64 / (SIDE - 1) as f64;
            let q = crate::geometry::apply_homography(
                unit,
                crate::geometry::Point::new(at(k % SIDE), at(k / SIDE)),
            );
            xs[k] = q.x as f32;
            ys[k] = q.y as f32;
        }
        let (mut px, mut py) = (vec![0f32; SIDE * SIDE], vec![0f32; SIDE * SIDE]);
        problem.warp_points(&ctx.params(), &xs, &ys, &mut px, &mut py);
        let points = px
            .iter()
            .zip(&py)
            .map(|(&x, &y)| crate::geometry::Point::new(x as f64, y as f64))
            .collect();
        Some(crate::visual_tracker::WarpedGrid { side: SIDE, points })
    }
    fn inspection(&self) -> Option<Inspection<'_>> {
        let ctx = &self.finest.ctx;
        Some(Inspection {
            res: self.params.res,
            channels: ctx.problem().channels(),
            template: ctx.problem().whole_template(),
            patch: ctx.whole_values(),
        })
    }
}
