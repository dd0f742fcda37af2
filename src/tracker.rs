//! A tracker built at run time from method names ([`TrackerSpec`]), and the driver that owns the
//! iteration loop: pre-processing of the region the tracker reads, the stop test, the observer
//! and the loss-of-track checks.

use crate::am::{self, HessianKind};
use crate::error::{Error, Result};
use crate::geometry::Quad;
use crate::imaging::{GrayF32, GrayU8, ImageView, Preprocessor, gaussian_kernel};
use crate::observe::{Iteration, Observer};
use crate::registry;
use crate::sm::{self, Context, LossReason, SearchMethod};
use crate::ssm;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// The parameters every tracker has (the paper's defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerParams {
    /// Sampling resolution: `res x res` points on the target.
    pub res: usize,
    /// Maximum iterations per frame.
    pub max_iters: usize,
    /// Stop when the L2 norm of the change of the corners in an iteration is below this (px).
    pub eps: f64,
    /// Gaussian pre-smoothing kernel size (1 = none).
    pub blur_size: usize,
    /// Gaussian pre-smoothing standard deviation (px).
    pub blur_sigma: f32,
    /// Which Hessian the search method uses.
    pub hessian: HessianKind,
    /// Margin of the pre-processed region around the target, as a fraction of its size.
    pub roi_margin: f64,
    /// Coarse-to-fine search over this many pyramid levels (1 = the frame only), each half the
    /// size of the previous; each level has its own template.
    pub pyramid_levels: usize,
}

impl Default for TrackerParams {
    fn default() -> Self {
        TrackerParams {
            res: 50,
            max_iters: 30,
            eps: 0.001,
            blur_size: 5,
            blur_sigma: 3.0,
            hessian: HessianKind::Default,
            roi_margin: 0.25,
            pyramid_levels: 1,
        }
    }
}

impl TrackerParams {
    /// Checks the ranges; the error says which parameter is wrong.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidParameter(m));
        if !(2..=1000).contains(&self.res) {
            return bad(format!("res must be in 2..=1000, got {}", self.res));
        }
        if !(1..=10_000).contains(&self.max_iters) {
            return bad(format!(
                "max_iters must be in 1..=10000, got {}",
                self.max_iters
            ));
        }
        if !(self.eps >= 0.0 && self.eps.is_finite()) {
            return bad(format!(
                "eps must be a finite number >= 0, got {}",
                self.eps
            ));
        }
        if self.blur_size > 31 {
            return bad(format!(
                "blur_size must be at most 31, got {}",
                self.blur_size
            ));
        }
        if !(self.blur_sigma >= 0.0 && self.blur_sigma.is_finite()) {
            return bad(format!("blur_sigma must be >= 0, got {}", self.blur_sigma));
        }
        if !(1..=6).contains(&self.pyramid_levels) {
            return bad(format!(
                "pyramid_levels must be in 1..=6, got {}",
                self.pyramid_levels
            ));
        }
        if !(0.0..=10.0).contains(&self.roi_margin) {
            return bad(format!(
                "roi_margin must be in 0..=10, got {}",
                self.roi_margin
            ));
        }
        Ok(())
    }
}

/// A tracker by name: search method, appearance model, state space model, and parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrackerSpec {
    pub sm: String,
    pub am: String,
    pub ssm: String,
    #[serde(default)]
    pub params: TrackerParams,
}

impl TrackerSpec {
    /// A spec from names or aliases, with the default parameters; names are made canonical.
    /// Fails with the list of what exists on an unknown name or an impossible combination.
    pub fn from_names(sm: &str, am: &str, ssm: &str) -> Result<Self> {
        let spec = TrackerSpec {
            sm: registry::lookup(sm::REGISTRY, "search method", sm)?
                .name
                .to_string(),
            am: registry::lookup(am::REGISTRY, "appearance model", am)?
                .name
                .to_string(),
            ssm: registry::lookup(ssm::REGISTRY, "state space model", ssm)?
                .name
                .to_string(),
            params: TrackerParams::default(),
        };
        Tracker::new(&spec)?;
        Ok(spec)
    }

    /// `sm_am_ssm`, as used in result file names.
    pub fn label(&self) -> String {
        format!("{}_{}_{}", self.sm, self.am, self.ssm)
    }
}

/// What a tracker is given for a frame.
#[derive(Clone, Copy, Debug)]
pub enum FrameInput<'a> {
    /// An 8-bit frame: the tracker converts and smooths only the region it reads (live path).
    Gray8(&'a GrayU8),
    /// A float frame, not smoothed yet: likewise.
    Gray32(&'a GrayF32),
    /// A float frame already smoothed by the caller: used as it is (tracker-only timing).
    Smoothed(&'a GrayF32),
}

impl FrameInput<'_> {
    /// `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        match self {
            FrameInput::Gray8(i) => (i.width, i.height),
            FrameInput::Gray32(i) | FrameInput::Smoothed(i) => (i.width, i.height),
        }
    }
}

impl<'a> From<&'a GrayU8> for FrameInput<'a> {
    fn from(i: &'a GrayU8) -> Self {
        FrameInput::Gray8(i)
    }
}

/// Whether a tracker follows its target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "status", content = "reason")]
pub enum TrackStatus {
    /// Not initialised yet.
    Uninitialized,
    /// Tracking.
    Tracking,
    /// The target was lost; the tracker stays lost until it is initialised again.
    Lost(LossReason),
}

/// The result of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameOutcome {
    /// Frame index since initialisation (the initialisation frame is 0).
    pub frame: usize,
    pub status: TrackStatus,
    /// The corners: the new estimate, or the last good one when lost (always finite).
    pub corners: Quad,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the stop test was met before the iteration limit.
    pub converged: bool,
    /// The similarity before the last iteration's step.
    pub similarity: f64,
    /// Time spent pre-processing (smoothing the region read) and searching.
    pub timing: FrameTiming,
}

/// Where the time of one update went.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameTiming {
    /// Conversion and smoothing of the region the tracker reads (zero for smoothed input).
    pub preprocess: std::time::Duration,
    /// The search method's iterations (what MTF reports as the tracker's speed).
    pub search: std::time::Duration,
}

/// A registration tracker: SSM + AM + SM, built from a [`TrackerSpec`].
#[derive(Debug)]
pub struct Tracker {
    spec: TrackerSpec,
    ctx: Context,
    sm: Box<dyn SearchMethod>,
    /// Pyramid levels 1, 2, ... (coarser and coarser), each with its own template.
    coarse: Vec<(Context, Box<dyn SearchMethod>)>,
    pre: Preprocessor,
    /// Builds the pyramid of already smoothed input.
    pre_copy: Preprocessor,
    status: TrackStatus,
    frame: usize,
    corners: Quad,
    initial_area: f64,
}

impl Tracker {
    /// Builds a tracker; fails on unknown names, impossible combinations or bad parameters.
    pub fn new(spec: &TrackerSpec) -> Result<Self> {
        spec.params.validate()?;
        let ssm = ssm::build(&spec.ssm)?;
        let am = am::build(&spec.am)?;
        let sm = sm::build(&spec.sm, &spec.params)?;
        let (need, have) = (sm.requires(), am.capabilities());
        if (need.derivatives && !have.derivatives) || (need.distance && !have.distance) {
            return Err(Error::Incompatible(format!(
                "search method '{}' needs {} which appearance model '{}' does not provide; \
                 appearance models that do: {}",
                sm.name(),
                if need.derivatives && !have.derivatives {
                    "analytic derivatives"
                } else {
                    "a patch distance"
                },
                am.name(),
                am::REGISTRY
                    .iter()
                    .filter(|e| {
                        let c = (e.build)().capabilities();
                        (!need.derivatives || c.derivatives) && (!need.distance || c.distance)
                    })
                    .map(|e| e.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        let mut spec = spec.clone();
        spec.sm = sm.name().to_string();
        spec.am = am.name().to_string();
        spec.ssm = ssm.name().to_string();
        let p = &spec.params;
        let ctx = Context::new(ssm, am, p.hessian, p.res);
        let mut coarse = Vec::new();
        for _ in 1..p.pyramid_levels {
            let c = Context::new(
                ssm::build(&spec.ssm)?,
                am::build(&spec.am)?,
                p.hessian,
                p.res,
            );
            coarse.push((c, sm::build(&spec.sm, p)?));
        }
        let pre = Preprocessor::new(gaussian_kernel(p.blur_size, p.blur_sigma));
        Ok(Tracker {
            spec,
            ctx,
            sm,
            coarse,
            pre,
            pre_copy: Preprocessor::new(gaussian_kernel(1, 0.0)),
            status: TrackStatus::Uninitialized,
            frame: 0,
            corners: Quad::default(),
            initial_area: 0.0,
        })
    }

    /// The spec (with canonical names).
    pub fn spec(&self) -> &TrackerSpec {
        &self.spec
    }
    /// Current status.
    pub fn status(&self) -> TrackStatus {
        self.status
    }
    /// Current corners (image coordinates).
    pub fn corners(&self) -> Quad {
        self.corners
    }
    /// Current SSM parameters (normalised frame).
    pub fn params(&self) -> &[f64] {
        &self.ctx.params[..self.ctx.dof]
    }
    /// The models and buffers, taken out of the tracker (for benchmarks of single stages).
    pub fn into_context(self) -> Context {
        self.ctx
    }

    /// The models and buffers (template, last sampled patch...), read-only.
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Pre-processes the region the trackers read (and its pyramid levels).
    fn prepare(&mut self, input: FrameInput<'_>, region: (f64, f64, f64, f64)) {
        let (x0, y0, x1, y1) = region;
        let levels = self.coarse.len();
        let pre = match input {
            FrameInput::Gray8(img) => {
                self.pre.process(img, x0, y0, x1, y1);
                &mut self.pre
            }
            FrameInput::Gray32(img) => {
                self.pre.process(img, x0, y0, x1, y1);
                &mut self.pre
            }
            FrameInput::Smoothed(img) => {
                if levels == 0 {
                    return;
                }
                self.pre_copy.process(img, x0, y0, x1, y1);
                &mut self.pre_copy
            }
        };
        pre.build_levels(levels);
    }

    /// The view of pyramid level `level` prepared by [`Tracker::prepare`].
    fn view<'a>(
        pre: &'a Preprocessor,
        pre_copy: &'a Preprocessor,
        input: FrameInput<'a>,
        level: usize,
    ) -> ImageView<'a> {
        match input {
            FrameInput::Smoothed(img) if level == 0 => img.view(),
            FrameInput::Smoothed(_) => pre_copy.level_view(level),
            _ => pre.level_view(level),
        }
    }

    /// The region to pre-process around `q`: its bounding box grown by the margin.
    fn region_around(&self, q: &Quad) -> (f64, f64, f64, f64) {
        let (x0, y0, x1, y1) = q.bbox();
        let m = self.spec.params.roi_margin * (x1 - x0).max(y1 - y0) + 8.0;
        (x0 - m, y0 - m, x1 + m, y1 + m)
    }

    /// Starts tracking `quad` in `input`: samples the template there.
    pub fn initialize(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()> {
        // Until it succeeds the tracker is not usable (its context is being replaced).
        self.status = TrackStatus::Uninitialized;
        self.ctx.set_region(quad, self.spec.params.res)?;
        let region = self.region_around(quad);
        self.prepare(input, region);
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        self.ctx.sample_template(&view);
        let energy: f64 = self
            .ctx
            .template_gx
            .iter()
            .zip(&self.ctx.template_gy)
            .map(|(&a, &b)| (a * a + b * b) as f64)
            .sum();
        if energy.partial_cmp(&(1e-6 * self.ctx.len() as f64)) != Some(std::cmp::Ordering::Greater)
        {
            self.status = TrackStatus::Uninitialized;
            return Err(Error::InvalidRegion(format!(
                "cannot track {quad}: the template is flat (no image gradient): {}",
                LossReason::Singular
            )));
        }
        self.sm
            .initialize(&mut self.ctx)
            .map_err(|r| Error::InvalidRegion(format!("cannot track {quad}: {r}")))?;
        for (l, (ctx, sm)) in self.coarse.iter_mut().enumerate() {
            ctx.set_region(quad, self.spec.params.res)?;
            ctx.sample_template(&Self::view(&self.pre, &self.pre_copy, input, l + 1));
            sm.initialize(ctx).map_err(|r| {
                Error::InvalidRegion(format!(
                    "cannot track {quad} at pyramid level {}: {r}",
                    l + 1
                ))
            })?;
        }
        self.status = TrackStatus::Tracking;
        self.frame = 0;
        self.corners = self.ctx.corners(&self.ctx.params);
        self.initial_area = quad.signed_area().abs();
        Ok(())
    }

    /// Moves the tracker to `quad` keeping its template (the SSM's least-squares fit to the
    /// quad), and resumes tracking if it was lost.
    pub fn set_corners(&mut self, quad: &Quad) -> Result<()> {
        if self.status == TrackStatus::Uninitialized {
            return Err(Error::InvalidRegion(
                "the tracker is not initialised".into(),
            ));
        }
        quad.validate()?;
        let target = quad.map(|p| self.ctx.norm.to_norm(p));
        let p = self
            .ctx
            .ssm
            .fit(&self.ctx.template_corners.0, &target.0)
            .ok_or_else(|| {
                Error::InvalidRegion(format!("cannot fit {} to {quad}", self.spec.ssm))
            })?;
        self.ctx.params = p;
        self.corners = self.ctx.corners(&p);
        self.status = TrackStatus::Tracking;
        Ok(())
    }

    /// Tracks one frame. Never panics and never returns non-finite corners: a loss of track is
    /// reported in the status, with the last good corners.
    pub fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.status != TrackStatus::Tracking {
            return FrameOutcome {
                frame: self.frame,
                status: self.status,
                corners: self.corners,
                iterations: 0,
                converged: false,
                similarity: f64::NAN,
                timing: FrameTiming::default(),
            };
        }
        self.frame += 1;
        let mut timing = FrameTiming::default();
        let start_params = self.ctx.params;
        let start_corners = self.corners;
        let (fw, fh) = input.size();
        let mut region = self.region_around(&start_corners);
        let started = Instant::now();
        let mut result = Err(LossReason::NonFinite);
        for attempt in 0..2 {
            self.ctx.params = start_params;
            observer.frame_started(self.frame, &start_corners);
            result = self.iterate_frame(input, region, observer, started, &mut timing);
            // The search left the pre-processed region (or failed in it): redo the frame once on
            // a larger region, or on the whole frame after a failure.
            let raw = matches!(input, FrameInput::Gray8(_) | FrameInput::Gray32(_));
            if attempt == 0 && raw {
                let (rx0, ry0, rx1, ry1) = {
                    let (a, b, c, d) = self.pre.region();
                    (a as f64, b as f64, c as f64, d as f64)
                };
                let whole = rx0 <= 0.0 && ry0 <= 0.0 && rx1 >= fw as f64 && ry1 >= fh as f64;
                match &result {
                    Ok(out) => {
                        let (x0, y0, x1, y1) = out.0.bbox();
                        let escaped = (x0 - 3.0 < rx0 && rx0 > 0.0)
                            || (y0 - 3.0 < ry0 && ry0 > 0.0)
                            || (x1 + 3.0 > rx1 && rx1 < fw as f64)
                            || (y1 + 3.0 > ry1 && ry1 < fh as f64);
                        if escaped && out.0.is_finite() {
                            let grown = self.region_around(&out.0);
                            region = (
                                region.0.min(grown.0),
                                region.1.min(grown.1),
                                region.2.max(grown.2),
                                region.3.max(grown.3),
                            );
                            continue;
                        }
                    }
                    Err(_) if !whole => {
                        region = (0.0, 0.0, fw as f64, fh as f64);
                        continue;
                    }
                    Err(_) => {}
                }
            }
            break;
        }
        let outcome = match result.and_then(|(q, iters, conv, f)| {
            self.check_quad(&q, fw, fh).map(|_| (q, iters, conv, f))
        }) {
            Ok((q, iterations, converged, similarity)) => {
                self.corners = q;
                FrameOutcome {
                    frame: self.frame,
                    status: TrackStatus::Tracking,
                    corners: q,
                    iterations,
                    converged,
                    similarity,
                    timing,
                }
            }
            Err(reason) => {
                self.ctx.params = start_params;
                self.status = TrackStatus::Lost(reason);
                FrameOutcome {
                    frame: self.frame,
                    status: self.status,
                    corners: start_corners,
                    iterations: 0,
                    converged: false,
                    similarity: f64::NAN,
                    timing,
                }
            }
        };
        observer.frame_finished(self.frame, &outcome);
        outcome
    }

    /// The iteration loop on one pre-processed region.
    fn iterate_frame(
        &mut self,
        input: FrameInput<'_>,
        region: (f64, f64, f64, f64),
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
    ) -> std::result::Result<(Quad, usize, bool, f64), LossReason> {
        let t0 = Instant::now();
        self.prepare(input, region);
        let t1 = Instant::now();
        timing.preprocess += t1 - t0;
        let params = &self.spec.params;
        let mut p = self.ctx.params;
        let mut done = 0;
        // Coarse to fine: each level starts from the parameters the coarser one found (the
        // parameters live in the normalised frame, the same at every level).
        for (l, (ctx, sm)) in self.coarse.iter_mut().enumerate().rev() {
            ctx.params = p;
            let view = Self::view(&self.pre, &self.pre_copy, input, l + 1);
            let (_, iters, _, _) = Self::search(
                ctx,
                &mut **sm,
                params,
                self.frame,
                l + 1,
                done,
                &view,
                observer,
                started,
            )?;
            done += iters;
            p = ctx.params;
        }
        self.ctx.params = p;
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        let result = Self::search(
            &mut self.ctx,
            &mut *self.sm,
            params,
            self.frame,
            0,
            done,
            &view,
            observer,
            started,
        )
        .map(|(q, iters, conv, f)| (q, iters + done, conv, f));
        timing.search += t1.elapsed();
        result
    }

    /// The iteration loop proper.
    #[allow(clippy::too_many_arguments)]
    fn search(
        ctx: &mut Context,
        sm: &mut dyn SearchMethod,
        params: &TrackerParams,
        frame: usize,
        level: usize,
        first: usize,
        view: &ImageView,
        observer: &mut dyn Observer,
        started: Instant,
    ) -> std::result::Result<(Quad, usize, bool, f64), LossReason> {
        let mut prev = ctx.corners(&ctx.params);
        let (mut converged, mut iterations, mut similarity) = (false, 0, f64::NAN);
        for it in 0..params.max_iters {
            let f = sm.iterate(ctx, view)?;
            let corners = ctx.corners(&ctx.params);
            if !corners.is_finite() || f.is_nan() {
                return Err(LossReason::NonFinite);
            }
            let step = corners.change_norm(&prev);
            prev = corners;
            iterations = it + 1;
            similarity = f;
            observer.iteration(&Iteration {
                frame,
                level,
                iteration: first + it,
                params: &ctx.params[..ctx.dof],
                corners,
                similarity: f,
                step,
                elapsed: started.elapsed(),
            });
            if step < params.eps {
                converged = true;
                break;
            }
        }
        Ok((prev, iterations, converged, similarity))
    }

    /// The loss-of-track checks on a frame's final quad.
    fn check_quad(&self, q: &Quad, fw: usize, fh: usize) -> std::result::Result<(), LossReason> {
        if !q.is_finite() {
            return Err(LossReason::NonFinite);
        }
        let area = q.signed_area().abs();
        if !q.is_convex() || area < self.initial_area / 100.0 || area > self.initial_area * 100.0 {
            return Err(LossReason::Degenerate);
        }
        let c = q.centroid();
        let (w, h) = (fw as f64, fh as f64);
        if c.x < -0.5 * w || c.x > 1.5 * w || c.y < -0.5 * h || c.y > 1.5 * h {
            return Err(LossReason::OutOfFrame);
        }
        Ok(())
    }
}
