//! The driver of a registration tracker: it owns the iteration loop of every frame (the stop
//! test, the model relearning, the observer), the pre-processing of the region the tracker
//! reads, the coarse-to-fine pyramid and the SSM hierarchy, and the loss-of-track checks. The
//! search method makes one iteration at a time ([`SearchMethod::iterate`]).

use super::{Context, Control, SearchMethod, sweep};
use crate::am::{BlockCorrelation, PatchSums};
use crate::error::{Error, Result};
use crate::geometry::{Quad, apply_homography};
use crate::imaging::{ImageView, Preprocessor, gaussian_kernel};
use crate::landscape::{Landscape, LandscapeSpec};
use crate::observe::{Iteration, Observer};
use crate::spec::{LossPolicy, RegistrationSpec, TrackerParams, TrackerSpec};
use crate::ssm::Params;
use crate::status::{FrameOutcome, FrameTiming, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, Inspection, VisualTracker};
use std::cmp::Ordering;
use std::time::Instant;

/// The SSMs of the hierarchy (`ssm_hierarchy=on`), fewer DOF first; those below the tracker's
/// own are searched before it.
pub const HIERARCHY: [&str; 3] = ["translation", "similitude", "affine"];

/// The confidence's blocks per side (see [`BlockCorrelation`]): 4 x 4 blocks of
/// about 12 x 12 samples on the default 50 x 50 grid.
const CONFIDENCE_BLOCKS: usize = 4;

/// A frame's search: where it ended, or why it failed (with where it ended when a check failed).
type SearchResult = std::result::Result<Searched, (LossReason, Option<Searched>)>;

/// `a >= b`, false when either is NaN.
fn at_least(a: f64, b: f64) -> bool {
    matches!(a.partial_cmp(&b), Some(Ordering::Greater | Ordering::Equal))
}

/// The fewest grid points per side of a pyramid level (each coarser level halves `res`).
pub const MIN_LEVEL_RES: usize = 10;

/// The grid points per side of pyramid level `level` (0 = the finest) of a tracker of `res`:
/// half the finer level's, so that every level samples its own pixels alike.
pub fn level_res(res: usize, level: usize) -> usize {
    (res >> level.min(31)).max(MIN_LEVEL_RES.min(res))
}

/// A frame whose search, started from the coarse levels' estimate, ends less like the template
/// than this fraction of the recent frames' median confidence is searched again at the finest
/// level from where the frame started, and the more confident end is kept.
const RETRY_BELOW: f64 = 0.95;

/// The stop threshold of a coarse pyramid level, in that level's pixels (px of corner motion
/// at the finest level: 0.1 at level 1, 0.2 at level 2...).
const COARSE_EPS: f64 = 0.05;

/// How many times the line search halves a step before the frame ends at its best point.
const LINE_SEARCH_HALVINGS: i32 = 4;

/// The scales of the last good quad at which `on_loss=redetect` searches the frame.
const REDETECT_SCALES: [f64; 3] = [0.8, 1.0, 1.25];
/// The candidates of the frame search that are refined.
const REDETECT_REFINED: usize = 3;

/// Where one frame's search ended.
#[derive(Clone, Copy, Debug)]
struct Searched {
    params: Params,
    corners: Quad,
    iterations: usize,
    converged: bool,
    similarity: f64,
    /// The correlation of the patch there with the template.
    confidence: f64,
    /// Its correlation with the last tracked frame's patch (`None` without one).
    frame_confidence: Option<f64>,
}

/// What the end of a search is judged by: the confidence against the template, and against
/// the last tracked frame's patch when there is one, whose sums (made in the same pass) are kept
/// in `sums` with the context's sampling they are of.
struct Judges<'a> {
    template: &'a BlockCorrelation,
    previous: Option<&'a BlockCorrelation>,
    sums: &'a mut (Option<u64>, PatchSums),
}

/// Where [`RegistrationTracker::polish`] ended: the confidence there, the similarity of its
/// last accepted step's start, and its iterations.
#[derive(Clone, Copy, Debug)]
struct Polished {
    confidence: f64,
    similarity: f64,
    iterations: usize,
}

/// One search: a search method and its context (models, grid, template, buffers).
#[derive(Debug)]
pub struct Stage {
    pub ctx: Context,
    pub sm: Box<dyn SearchMethod>,
}

/// A registration tracker: SSM + AM + SM, built from a [`RegistrationSpec`], and the driver that
/// owns the iteration loop.
#[derive(Debug)]
pub struct RegistrationTracker {
    spec: TrackerSpec,
    params: TrackerParams,
    ctx: Context,
    sm: Box<dyn SearchMethod>,
    /// Pyramid levels 1, 2, ... (coarser and coarser), each with its own template.
    coarse: Vec<Stage>,
    /// The SSM hierarchy's stages (fewer DOF first), at full resolution.
    lower: Vec<Stage>,
    pre: Preprocessor,
    /// Builds the pyramid of already smoothed input.
    pre_copy: Preprocessor,
    status: TrackStatus,
    frame: usize,
    corners: Quad,
    initial_area: f64,
    /// The recent confidences the loss checks compare a frame's with.
    loss: super::LossCheck,
    /// Where the last search ended when only its confidence failed (see `update`).
    lost_at: Option<Params>,
    /// The confidence against the template, and what `on_loss=redetect` ranks its candidates
    /// with (both made with the template).
    confidence: BlockCorrelation,
    detector: Detector,
    /// The confidence against the last tracked frame's patch, and whether there is one (not
    /// after an initialisation, a move by hand or a loss).
    previous: BlockCorrelation,
    has_previous: bool,
    /// The block sums of the last patch both confidences were made of in one pass, and which
    /// sampling of the context's (`Workspace::samples`) that patch was: if the frame keeps it,
    /// it becomes `previous` without being summed again.
    patch_sums: (Option<u64>, PatchSums),
    /// Whether a frame's region may be smoothed only where the search reads it (see
    /// [`Source`]); off only to compare with the whole region's results.
    partial: bool,
    /// The largest move of a corner in the last tracked frame (pixels): how far beyond its
    /// start the first part of the next frame's region is smoothed.
    motion: f64,
}

/// Pixels around a patch's corners its sampling reads: the 4 x 4 neighbourhood of a point
/// (one before, two after) and a pixel for rounding.
const READ_PX: f64 = 4.0;

/// Pixels beyond the start's reads, on top of twice the last frame's motion, that a frame's
/// region is smoothed first when it is smoothed in parts.
const FIRST_PART_PX: f64 = 2.0;

/// The pixels the patch whose corners are `q` reads, grown by `more`: the bounding box of a
/// convex quad (which holds its grid's points); everything for any other.
fn reads(q: &Quad, more: f64) -> (f64, f64, f64, f64) {
    if !(q.is_finite() && q.is_convex()) {
        return (
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::INFINITY,
        );
    }
    let (x0, y0, x1, y1) = q.bbox();
    let m = READ_PX + more;
    (x0 - m, y0 - m, x1 + m, y1 + m)
}

/// The finest level a frame's search reads. Either a view that holds every pixel it may read
/// (the pre-processed region, a pre-smoothed frame, a pyramid level) or, for a method whose
/// patches are all at the parameters the driver sees ([`SearchMethod::local`]), the region
/// smoothed only where the patches so far read: [`Source::cover`] smooths the rest of it
/// before a patch reads beyond (the region's whole smoothing was a seventh of a frame's work
/// for a target that stays within a few pixels of where it started). The values read are the
/// same bits either way.
enum Source<'a> {
    Whole(ImageView<'a>),
    Part {
        pre: &'a mut Preprocessor,
        input: FrameInput<'a>,
    },
}

impl Source<'_> {
    fn view(&self) -> ImageView<'_> {
        match self {
            Source::Whole(v) => *v,
            Source::Part { pre, .. } => pre.view(),
        }
    }

    /// Makes sure that the patch with corners `q` reads smoothed pixels only.
    fn cover(&mut self, q: &Quad) {
        if let Source::Part { pre, input } = self
            && !pre.holds(reads(q, 0.0))
        {
            complete(pre, *input);
        }
    }
}

/// Smooths the rest of a region that [`Preprocessor::process_part`] smoothed in part.
fn complete(pre: &mut Preprocessor, input: FrameInput<'_>) {
    match input {
        FrameInput::Gray8(img) => pre.complete(img),
        FrameInput::Gray32(img) => pre.complete(img),
        FrameInput::View8(img) => pre.complete(img),
        FrameInput::Smoothed(_) => {}
    }
}

/// The grid samples `on_loss=redetect` ranks its candidates on (every other one per axis, a
/// quarter of the work), the template there, and a buffer for a candidate's patch: made when
/// the template is sampled, so that a lost frame does not allocate either.
#[derive(Debug, Default)]
struct Detector {
    picks: Vec<usize>,
    confidence: BlockCorrelation,
    patch: Vec<f32>,
}

impl Detector {
    /// The confidence of the target at `q` (frame pixels) in `view`, on the detector's grid,
    /// and the SSM's parameters there (`None` if the SSM cannot fit `q`).
    fn candidate(&mut self, ctx: &Context, view: &ImageView, q: &Quad) -> Option<(f64, Params)> {
        let target = q.map(|p| ctx.norm.to_norm(p));
        let p = ctx.ssm.fit(&ctx.template_corners.0, &target.0)?;
        let m = ctx.pixel_matrix(&p);
        for (v, &k) in self.patch.iter_mut().zip(&self.picks) {
            let pt = apply_homography(
                &m,
                crate::geometry::Point::new(ctx.grid_x[k] as f64, ctx.grid_y[k] as f64),
            );
            *v = crate::imaging::sample_value(view, pt.x as f32, pt.y as f32);
        }
        Some((self.confidence.of(&self.patch), p))
    }

    fn new(res: usize, template: &[f32]) -> Self {
        let side = res.div_ceil(2);
        let picks: Vec<usize> = (0..side)
            .flat_map(|j| (0..side).map(move |i| 2 * j * res + 2 * i))
            .collect();
        let picked: Vec<f32> = picks.iter().map(|&k| template[k]).collect();
        Detector {
            confidence: BlockCorrelation::new(&picked, side, CONFIDENCE_BLOCKS),
            patch: vec![0.0; picks.len()],
            picks,
        }
    }
}

impl RegistrationTracker {
    /// A tracker for `spec` (with canonical names and checked parameters) searching with `main`,
    /// whose other stages are made by `build`: given an SSM's name, the AM, the SM and their
    /// context as `spec` has them. Every stage, at every pyramid level and of the SSM hierarchy,
    /// is built by it, so each has the spec's AM and SM parameters.
    pub fn from_stages(
        spec: RegistrationSpec,
        main: Stage,
        build: &dyn Fn(&str, usize) -> Result<Stage>,
    ) -> Result<Self> {
        let p = spec.params.clone();
        // The coarse levels widen the basin of the methods that descend a gradient; the sampling
        // methods (NN, PF) search the spread of their own samples, at the finest level only.
        let gradient = main.sm.requires().derivatives;
        let levels = if gradient { p.pyramid_levels } else { 1 };
        let coarse = (1..levels)
            .map(|l| build(&spec.ssm, level_res(p.res, l)))
            .collect::<Result<Vec<_>>>()?;
        let mut lower = Vec::new();
        if p.ssm_hierarchy {
            let dof = main.ctx.dof;
            for name in HIERARCHY {
                let stage = build(name, p.res)?;
                if stage.ctx.dof < dof {
                    lower.push(stage);
                }
            }
        }
        let pre = Preprocessor::new(gaussian_kernel(
            p.blur_size,
            p.smoothing_sigma(gradient) as f32,
        ));
        Ok(RegistrationTracker {
            spec: TrackerSpec::Registration(spec),
            params: p,
            ctx: main.ctx,
            sm: main.sm,
            coarse,
            lower,
            pre,
            pre_copy: Preprocessor::new(gaussian_kernel(1, 0.0)),
            status: TrackStatus::Uninitialized,
            frame: 0,
            corners: Quad::default(),
            initial_area: 0.0,
            loss: super::LossCheck::default(),
            lost_at: None,
            confidence: BlockCorrelation::default(),
            detector: Detector::default(),
            previous: BlockCorrelation::default(),
            has_previous: false,
            patch_sums: (None, PatchSums::default()),
            partial: true,
            motion: 0.0,
        })
    }

    /// Current SSM parameters (normalised frame).
    pub fn params(&self) -> &[f64] {
        &self.ctx.params[..self.ctx.dof]
    }
    /// The models and buffers, taken out of the tracker (for benchmarks of single stages).
    pub fn into_context(self) -> Context {
        self.ctx
    }

    /// The finest level's context and search method, for driving single iterations (the
    /// per-iteration benchmarks): after [`VisualTracker::initialize`] the method is initialised
    /// on the template and the context's parameters are where the tracker is.
    pub fn into_parts(self) -> (Context, Box<dyn SearchMethod>) {
        (self.ctx, self.sm)
    }

    /// The pre-smoothing kernel (of the finest level).
    pub fn smoothing(&self) -> &crate::imaging::GaussianKernel {
        self.pre.kernel()
    }

    /// The models and buffers (template, last sampled patch...), read-only.
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Pre-processes the region the trackers read (and its pyramid levels).
    fn prepare(&mut self, input: FrameInput<'_>, region: (f64, f64, f64, f64)) {
        self.prepare_part(input, region, region);
    }

    /// [`RegistrationTracker::prepare`], smoothing the finest level only within `part` of the
    /// region (see [`Source`]; the pyramid's levels need the whole region).
    fn prepare_part(
        &mut self,
        input: FrameInput<'_>,
        region: (f64, f64, f64, f64),
        part: (f64, f64, f64, f64),
    ) {
        // Another frame or region: no context's last sampled patch is this view's.
        self.ctx.work.sampled_at = None;
        for stage in self.coarse.iter_mut().chain(&mut self.lower) {
            stage.ctx.work.sampled_at = None;
        }
        let levels = self.coarse.len();
        let pre = match input {
            FrameInput::Gray8(img) => {
                self.pre.process_part(img, region, part);
                &mut self.pre
            }
            FrameInput::Gray32(img) => {
                self.pre.process_part(img, region, part);
                &mut self.pre
            }
            FrameInput::View8(img) => {
                self.pre.process_part(img, region, part);
                &mut self.pre
            }
            FrameInput::Smoothed(img) => {
                if levels == 0 {
                    return;
                }
                let (x0, y0, x1, y1) = region;
                self.pre_copy.process(img, x0, y0, x1, y1);
                &mut self.pre_copy
            }
        };
        pre.build_levels(levels);
    }

    /// The view of pyramid level `level` prepared by [`RegistrationTracker::prepare`].
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

    /// See [`VisualTracker::landscape`]: the region the sweep reads is pre-processed, then
    /// [`sweep::sweep`].
    fn sweep(
        &mut self,
        input: FrameInput<'_>,
        at: &Quad,
        spec: &LandscapeSpec,
    ) -> Result<Landscape> {
        if self.status == TrackStatus::Uninitialized {
            return Err(Error::InvalidRegion(
                "the tracker is not initialised".into(),
            ));
        }
        at.validate()?;
        let (x0, y0, x1, y1) = self.region_around(at);
        let grow = sweep::reach(spec);
        self.prepare(input, (x0 - grow, y0 - grow, x1 + grow, y1 + grow));
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        sweep::sweep(&mut self.ctx, &view, at, spec)
    }

    /// The region to pre-process around `q`: its bounding box grown by the margin.
    fn region_around(&self, q: &Quad) -> (f64, f64, f64, f64) {
        let (x0, y0, x1, y1) = q.bbox();
        let m = self.params.roi_margin * (x1 - x0).max(y1 - y0) + 8.0;
        (x0 - m, y0 - m, x1 + m, y1 + m)
    }

    /// The iteration loop on one pre-processed region.
    fn iterate_frame(
        &mut self,
        input: FrameInput<'_>,
        region: (f64, f64, f64, f64),
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
    ) -> std::result::Result<Searched, LossReason> {
        let t0 = Instant::now();
        // One level, one SSM and a method whose patches the driver sees: the region is smoothed
        // around where the frame starts first, and further only if the search goes there.
        let partial = self.partial
            && self.coarse.is_empty()
            && self.lower.is_empty()
            && self.sm.local()
            && !matches!(input, FrameInput::Smoothed(_));
        if partial {
            let start = self.ctx.corners(&self.ctx.params);
            let part = reads(&start, FIRST_PART_PX + 2.0 * self.motion);
            self.prepare_part(input, region, part);
        } else {
            self.prepare(input, region);
        }
        let t1 = Instant::now();
        timing.preprocess += t1 - t0;
        let params = &self.params;
        let mut done = 0;
        // The SSM hierarchy: each stage starts from its SSM's least-squares fit to the corners the
        // previous stage found (every context shares the normaliser and the template corners).
        if !self.lower.is_empty() {
            let view = Self::view(&self.pre, &self.pre_copy, input, 0);
            // The corners in the normalised frame.
            let m = self.ctx.ssm.matrix(&self.ctx.params);
            let mut corners = self.ctx.template_corners.map(|c| apply_homography(&m, c));
            for Stage { ctx, sm } in self.lower.iter_mut() {
                ctx.params = ctx
                    .ssm
                    .fit(&ctx.template_corners.0, &corners.0)
                    .ok_or(LossReason::Singular)?;
                let (_, iters, _, _) = Self::search(
                    ctx,
                    &mut **sm,
                    params,
                    self.frame,
                    0,
                    done,
                    &mut Source::Whole(view),
                    observer,
                    started,
                )?;
                done += iters;
                let m = ctx.ssm.matrix(&ctx.params);
                corners = ctx.template_corners.map(|c| apply_homography(&m, c));
            }
            self.ctx.params = self
                .ctx
                .ssm
                .fit(&self.ctx.template_corners.0, &corners.0)
                .ok_or(LossReason::Singular)?;
        }
        let mut p = self.ctx.params;
        let start = p;
        // Coarse to fine: each level starts from the parameters the coarser one found (the
        // parameters live in the normalised frame, the same at every level).
        // A coarse level stops once its corners move less than COARSE_EPS of its own pixels, or
        // after a third of `max_iters`: it only has to bring the search into the finer level's
        // basin (and where it cannot see the target, a star field, it would wander for all of
        // them).
        let mut coarse_params = params.clone();
        for (l, Stage { ctx, sm }) in self.coarse.iter_mut().enumerate().rev() {
            ctx.params = p;
            let view = Self::view(&self.pre, &self.pre_copy, input, l + 1);
            coarse_params.eps = params.eps.max(COARSE_EPS * (1 << (l + 1)) as f64);
            coarse_params.max_iters = params.max_iters.div_ceil(3);
            let (_, iters, _, _) = Self::search(
                ctx,
                &mut **sm,
                &coarse_params,
                self.frame,
                l + 1,
                done,
                &mut Source::Whole(view),
                observer,
                started,
            )?;
            done += iters;
            p = ctx.params;
        }
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        // A check between the levels: the coarse levels' estimate is kept only if, at the finest
        // level, the patch there looks at least as much like the template (the confidence,
        // which light does not sway as it sways SSD) as where the frame started. Marks finer
        // than the coarse levels' pixels (a star field) vanish there, and the coarse search
        // then follows the light instead of the target.
        let coarse_moved = !self.coarse.is_empty() && p != start;
        if coarse_moved {
            let (ctx, conf) = (&mut self.ctx, &self.confidence);
            // The start first: the patch at the coarse estimate, where the search goes on, is
            // then the one in the context's buffer (a method that samples with `patch_at` does
            // not sample it again).
            let at_start = Self::confidence_at(ctx, conf, &view, &start);
            let at_coarse = Self::confidence_at(ctx, conf, &view, &p);
            // Also when either is NaN: the start is the safe side.
            if !at_least(at_coarse, at_start) {
                p = start;
            }
        }
        let mut src = if partial {
            Source::Part {
                pre: &mut self.pre,
                input,
            }
        } else {
            Source::Whole(view)
        };
        let mut result = Self::finish(
            &mut self.ctx,
            &mut *self.sm,
            &mut Judges {
                template: &self.confidence,
                previous: self.has_previous.then_some(&self.previous),
                sums: &mut self.patch_sums,
            },
            params,
            (self.frame, done),
            &mut src,
            observer,
            started,
            p,
        );
        // Ended less like the template than the track's recent frames, from the coarse estimate:
        // the finest level is searched again from where the frame started, and the more
        // confident end is kept. (A coarse level that followed the light may still have looked
        // better than the start, and the finest level then settles on a look-alike nearby.)
        if p != start
            && let Ok(first) = result
            && self
                .loss
                .reference()
                .is_some_and(|r| !at_least(first.confidence, RETRY_BELOW * r))
        {
            let again = Self::finish(
                &mut self.ctx,
                &mut *self.sm,
                &mut Judges {
                    template: &self.confidence,
                    previous: self.has_previous.then_some(&self.previous),
                    sums: &mut self.patch_sums,
                },
                params,
                (self.frame, first.iterations),
                &mut src,
                observer,
                started,
                start,
            );
            result = Ok(match again {
                Ok(second) if second.confidence > first.confidence => second,
                Ok(second) => Searched {
                    iterations: second.iterations,
                    ..first
                },
                Err(_) => first,
            });
            if let Ok(out) = &result {
                self.ctx.params = out.params;
            }
        }
        // The correlation with the last tracked frame's patch (unless the search made it with
        // the confidence).
        if let Ok(out) = &mut result
            && self.has_previous
            && out.frame_confidence.is_none()
        {
            let q = out.params;
            // Usually just sampled there, for the confidence.
            self.ctx.patch_at(&src.view(), &q);
            out.frame_confidence = Some(self.previous.of(&self.ctx.work.values));
        }
        timing.search += t1.elapsed();
        result
    }

    /// Tells the observer where an iteration (`frame`, `level`, `iteration`) ended: corners,
    /// similarity, corner change, and, for observers that show it, the patch there (the next
    /// iteration samples again, so the shared buffers may be used).
    fn report_iteration(
        ctx: &mut Context,
        view: &ImageView,
        observer: &mut dyn Observer,
        (frame, level, iteration): (usize, usize, usize),
        (corners, similarity, step): (Quad, f64, f64),
        (started, iteration_started): (Instant, Instant),
    ) {
        let duration = iteration_started.elapsed();
        let patch = if observer.wants_patches() {
            let p = ctx.params;
            ctx.sample_at(view, &p);
            Some(&ctx.work.values[..])
        } else {
            None
        };
        observer.iteration(&Iteration {
            frame,
            level,
            iteration,
            params: &ctx.params[..ctx.dof],
            corners,
            similarity,
            step,
            elapsed: started.elapsed(),
            duration,
            patch,
        });
    }

    /// The confidence of the patch of `view` under `p` (one sampling of the grid).
    fn confidence_at(
        ctx: &mut Context,
        confidence: &BlockCorrelation,
        view: &ImageView,
        p: &Params,
    ) -> f64 {
        ctx.sample_at(view, p);
        confidence.of(&ctx.work.values)
    }

    /// The finest level's search from `from` (then the polish, for the methods that need it),
    /// and the confidence where it ended. `(frame, done)`: the frame and the iterations the
    /// frame has made so far.
    #[allow(clippy::too_many_arguments)]
    fn finish(
        ctx: &mut Context,
        sm: &mut dyn SearchMethod,
        judges: &mut Judges<'_>,
        params: &TrackerParams,
        (frame, done): (usize, usize),
        src: &mut Source<'_>,
        observer: &mut dyn Observer,
        started: Instant,
        from: Params,
    ) -> std::result::Result<Searched, LossReason> {
        let confidence = judges.template;
        ctx.params = from;
        let (mut corners, mut iters, converged, mut similarity) =
            Self::search(ctx, sm, params, frame, 0, done, src, observer, started)?;
        let conf = if params.polish && sm.template_linearised() {
            let polished = Self::polish(
                ctx,
                confidence,
                params,
                (frame, done + iters),
                src,
                observer,
                started,
            );
            iters += polished.iterations;
            if polished.iterations > 0 {
                corners = ctx.corners(&ctx.params);
                similarity = polished.similarity;
            }
            (polished.confidence, None)
        } else if let Some(previous) = judges.previous {
            // Both confidences from one pass over the patch, its sums kept.
            let p = ctx.params;
            ctx.sample_at(&src.view(), &p);
            let (c, f) = confidence.of_pair(previous, &ctx.work.values, &mut judges.sums.1);
            judges.sums.0 = Some(ctx.work.samples);
            (c, Some(f))
        } else {
            let p = ctx.params;
            (Self::confidence_at(ctx, confidence, &src.view(), &p), None)
        };
        Ok(Searched {
            params: ctx.params,
            corners,
            iterations: iters + done,
            converged,
            similarity,
            confidence: conf.0,
            frame_confidence: conf.1,
        })
    }

    /// Forward-compositional steps from where a method that linearises with the template's
    /// gradients converged, toward the AM's own optimum (FCLK's fixed point), as long as each
    /// step leaves a patch more like the template than the last (the confidence): under light
    /// that changes across the target the AM's optimum itself may leave a sparse target, and
    /// the template's half of ESM's Jacobian, which no light reaches, held it better there.
    /// Ends at the most confident point it visited.
    fn polish(
        ctx: &mut Context,
        confidence: &BlockCorrelation,
        params: &TrackerParams,
        (frame, first): (usize, usize),
        src: &mut Source<'_>,
        observer: &mut dyn Observer,
        started: Instant,
    ) -> Polished {
        let mut prev = ctx.corners(&ctx.params);
        // The most confident point so far, its confidence and similarity.
        let mut best: Option<(Params, f64, f64)> = None;
        let mut iterations = 0;
        for it in 0..params.max_iters {
            let iteration_started = Instant::now();
            let p = ctx.params;
            ctx.sample_gradients_at(&src.view(), &p);
            let c = confidence.of(&ctx.work.values);
            if let Some((bp, bc, bf)) = best
                && c.partial_cmp(&bc) != Some(Ordering::Greater)
            {
                ctx.params = bp;
                return Polished {
                    confidence: bc,
                    similarity: bf,
                    iterations,
                };
            }
            let Ok(f) = ctx.forward_compositional_step(&p) else {
                ctx.params = p;
                return Polished {
                    confidence: c,
                    similarity: best.map_or(f64::NAN, |b| b.2),
                    iterations,
                };
            };
            best = Some((p, c, f));
            let corners = ctx.corners(&ctx.params);
            if !corners.is_finite() || f.is_nan() {
                ctx.params = p;
                return Polished {
                    confidence: c,
                    similarity: f,
                    iterations,
                };
            }
            src.cover(&corners);
            iterations = it + 1;
            let step = corners.change_norm(&prev);
            prev = corners;
            Self::report_iteration(
                ctx,
                &src.view(),
                observer,
                (frame, 0, first + it),
                (corners, f, step),
                (started, iteration_started),
            );
            if step < params.eps {
                break;
            }
        }
        // Settled or out of iterations: the last step's end is kept if it is the most confident.
        let q = ctx.params;
        let c = Self::confidence_at(ctx, confidence, &src.view(), &q);
        match best {
            Some((bp, bc, bf)) if !at_least(c, bc) => {
                ctx.params = bp;
                Polished {
                    confidence: bc,
                    similarity: bf,
                    iterations,
                }
            }
            Some((_, _, bf)) => Polished {
                confidence: c,
                similarity: bf,
                iterations,
            },
            None => Polished {
                confidence: c,
                similarity: f64::NAN,
                iterations,
            },
        }
    }

    /// Searches the whole frame for the template: the last good quad moved over the frame in
    /// steps of a sixth of its size, at [`REDETECT_SCALES`], each candidate ranked by its
    /// confidence; the [`REDETECT_REFINED`] best are refined by the search method in turn, and
    /// the first that passes the checks is returned.
    fn redetect(
        &mut self,
        input: FrameInput<'_>,
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
        fw: usize,
        fh: usize,
    ) -> Option<Searched> {
        let t0 = Instant::now();
        self.prepare(input, (0.0, 0.0, fw as f64, fh as f64));
        timing.preprocess += t0.elapsed();
        let base = self.corners;
        let c = base.centroid();
        let (x0, y0, x1, y1) = base.bbox();
        let step = ((x1 - x0).max(y1 - y0) / 6.0).max(4.0);
        let mut best = [(f64::NEG_INFINITY, self.ctx.params); REDETECT_REFINED];
        let t1 = Instant::now();
        {
            let view = Self::view(&self.pre, &self.pre_copy, input, 0);
            let (ctx, det) = (&self.ctx, &mut self.detector);
            for scale in REDETECT_SCALES {
                let mut cy = step / 2.0;
                while cy < fh as f64 {
                    let mut cx = step / 2.0;
                    while cx < fw as f64 {
                        let q = base.map(|p| {
                            crate::geometry::Point::new(
                                cx + scale * (p.x - c.x),
                                cy + scale * (p.y - c.y),
                            )
                        });
                        if let Some((conf, p)) = det.candidate(ctx, &view, &q) {
                            // Keep the best few, best first.
                            if conf > best[REDETECT_REFINED - 1].0 {
                                best[REDETECT_REFINED - 1] = (conf, p);
                                best.sort_by(|a, b| b.0.total_cmp(&a.0));
                            }
                        }
                        cx += step;
                    }
                    cy += step;
                }
            }
        }
        timing.search += t1.elapsed();
        for (conf, p) in best {
            if !conf.is_finite() {
                break;
            }
            let from = self.ctx.corners(&p);
            // A candidate is the target only if it looks like it, whatever the SSM: the confidence
            // is checked for every SSM here.
            if let Ok(out) = self.search_from(input, p, &from, observer, started, timing)
                && self.accept(&out, fw, fh, true).is_ok()
            {
                return Some(out);
            }
        }
        None
    }

    /// One frame's search from `start_params` (at `start_corners`), redone once on a larger
    /// region when it leaves the pre-processed one.
    // Returned by value: a frame's update does not allocate.
    #[allow(clippy::result_large_err)]
    fn search_from(
        &mut self,
        input: FrameInput<'_>,
        start_params: Params,
        start_corners: &Quad,
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
    ) -> SearchResult {
        let (fw, fh) = input.size();
        let mut region = self.region_around(start_corners);
        let mut result: SearchResult = Err((LossReason::NonFinite, None));
        for attempt in 0..2 {
            self.ctx.params = start_params;
            observer.frame_started(self.frame, start_corners);
            result = self
                .iterate_frame(input, region, observer, started, timing)
                .map_err(|r| (r, None));
            // The search left the pre-processed region (or failed in it): redo the frame once on
            // a larger region, or on the whole frame after a failure.
            let raw = matches!(
                input,
                FrameInput::Gray8(_) | FrameInput::Gray32(_) | FrameInput::View8(_)
            );
            if attempt == 0 && raw {
                let (rx0, ry0, rx1, ry1) = {
                    let (a, b, c, d) = self.pre.region();
                    (a as f64, b as f64, c as f64, d as f64)
                };
                let whole = rx0 <= 0.0 && ry0 <= 0.0 && rx1 >= fw as f64 && ry1 >= fh as f64;
                match &result {
                    Ok(out) => {
                        let (x0, y0, x1, y1) = out.corners.bbox();
                        let escaped = (x0 - 3.0 < rx0 && rx0 > 0.0)
                            || (y0 - 3.0 < ry0 && ry0 > 0.0)
                            || (x1 + 3.0 > rx1 && rx1 < fw as f64)
                            || (y1 + 3.0 > ry1 && ry1 < fh as f64);
                        if escaped && out.corners.is_finite() {
                            let grown = self.region_around(&out.corners);
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
        src: &mut Source<'_>,
        observer: &mut dyn Observer,
        started: Instant,
    ) -> std::result::Result<(Quad, usize, bool, f64), LossReason> {
        let mut prev = ctx.corners(&ctx.params);
        src.cover(&prev);
        let (mut converged, mut iterations, mut similarity) = (false, 0, f64::NAN);
        sm.start_frame(ctx);
        let budget = sm.max_iterations(params.max_iters);
        let mut relearnt = 0;
        // The line search: the best start of an iteration this frame, its similarity and the
        // step taken from it; how many times that step has been halved.
        let line_search = params.line_search && sm.line_search();
        let mut best: Option<(Params, f64, Params, super::Update)> = None;
        let mut halvings = 0;
        for it in 0..budget {
            let iteration_started = Instant::now();
            let from = ctx.params;
            ctx.last_step = None;
            let s = sm.iterate(ctx, &src.view())?;
            let mut f = s.similarity;
            let mut exhausted = false;
            if line_search && s.control == Control::Auto {
                match (best, ctx.last_step) {
                    // This iteration started lower than the best point (or at NaN): its own step
                    // is dropped and the best point's is halved.
                    (Some((bp, bf, dp, update)), _) if !at_least(f, bf) => {
                        halvings += 1;
                        ctx.params = bp;
                        f = bf;
                        if halvings > LINE_SEARCH_HALVINGS {
                            exhausted = true;
                        } else {
                            let scale = 0.5f64.powi(halvings);
                            ctx.apply(&dp.map(|v| v * scale), update)?;
                        }
                    }
                    (_, Some((dp, update))) => {
                        best = Some((from, f, dp, update));
                        halvings = 0;
                    }
                    _ => {}
                }
            }
            let corners = ctx.corners(&ctx.params);
            if !corners.is_finite() || f.is_nan() {
                return Err(LossReason::NonFinite);
            }
            // Where the next patches are sampled (the observer's, the next iteration's).
            src.cover(&corners);
            let step = corners.change_norm(&prev);
            prev = corners;
            iterations = it + 1;
            similarity = f;
            Self::report_iteration(
                ctx,
                &src.view(),
                observer,
                (frame, level, first + it),
                (corners, f, step),
                (started, iteration_started),
            );
            if observer.wants_method_visuals()
                && let Some(v) = sm.visual(ctx)
            {
                observer.method_visual(frame, first + it, &v);
            }
            let stop = exhausted
                || match s.control {
                    Control::Done => true,
                    Control::Continue => false,
                    Control::Auto => step < params.eps,
                };
            if stop {
                // A model that follows the light (SCV's intensity map) was learnt on the previous
                // frame: once the search has settled, it learns this frame's light there and the
                // search goes on (alternating the warp and the intensity map), up to three times a
                // frame. Learnt only once per frame, after convergence, it lagged one frame behind
                // a steady change of light; learnt where the frame starts, it absorbs the motion.
                if ctx.am.updates_model() && relearnt < 3 && it + 1 < budget {
                    relearnt += 1;
                    // The similarity changes with the model: values before and after do not
                    // compare.
                    best = None;
                    halvings = 0;
                    Self::learn_model(ctx, sm, &src.view());
                    continue;
                }
                converged = true;
                break;
            }
        }
        Ok((prev, iterations, converged, similarity))
    }

    /// The AM's model learns the patch of `view` at the current parameters; the search method
    /// refreshes what depends on it.
    fn learn_model(ctx: &mut Context, sm: &mut dyn SearchMethod, view: &ImageView) {
        let p = ctx.params;
        ctx.sample_at(view, &p);
        let values = std::mem::take(&mut ctx.work.values);
        ctx.am.update_model(&values);
        ctx.work.values = values;
        sm.model_updated(ctx);
    }

    /// The checks a frame's search must pass to be tracked: its quad's, then (if `confidence`)
    /// its confidence's, which a passing frame joins the history of.
    fn accept(
        &mut self,
        out: &Searched,
        fw: usize,
        fh: usize,
        confidence: bool,
    ) -> std::result::Result<(), LossReason> {
        self.check_quad(&out.corners, fw, fh)?;
        if confidence {
            self.loss.judge(
                &super::Judged {
                    confidence: out.confidence,
                    frame_confidence: out.frame_confidence,
                    converged: out.converged,
                    resuming: self.status != TrackStatus::Tracking,
                },
                &self.params,
            )?;
        }
        Ok(())
    }

    /// After an initialisation, a move by hand or a loss: the next frame has no previous
    /// frame to be compared with (its previous patch is not the target's, or not near).
    fn remember_patch(&mut self, input: FrameInput<'_>, out: &Searched) {
        // The frame's last search may have pre-processed another region (a second start, a
        // candidate of the frame search): the patch is sampled where the accepted one ended.
        let (x0, y0, x1, y1) = out.corners.bbox();
        let (rx0, ry0, rx1, ry1) = self.pre.region();
        let inside = x0 >= rx0 as f64 && y0 >= ry0 as f64 && x1 <= rx1 as f64 && y1 <= ry1 as f64;
        if !inside && !matches!(input, FrameInput::Smoothed(_)) {
            let region = self.region_around(&out.corners);
            self.prepare(input, region);
        } else if !self.pre.holds(reads(&out.corners, 0.0)) {
            // A region smoothed in part, by another search than the accepted one's.
            complete(&mut self.pre, input);
        }
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        self.ctx.patch_at(&view, &out.params);
        let (res, values) = (self.params.res, &self.ctx.work.values);
        match &self.patch_sums {
            // The patch both confidences were just made of: its sums are there.
            (Some(made), sums) if *made == self.ctx.work.samples => self
                .previous
                .set_template_from(values, res, CONFIDENCE_BLOCKS, sums),
            _ => self.previous.set_template(values, res, CONFIDENCE_BLOCKS),
        }
        self.has_previous = true;
    }

    fn forget_previous(&mut self) {
        self.has_previous = false;
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
        self.ctx
            .set_region(quad, self.params.res, self.params.grid)?;
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
            .initialize(&mut self.ctx, &view)
            .map_err(|r| Error::InvalidRegion(format!("cannot track {quad}: {r}")))?;
        for (l, Stage { ctx, sm }) in self.coarse.iter_mut().enumerate() {
            ctx.set_region(quad, level_res(self.params.res, l + 1), self.params.grid)?;
            let view = Self::view(&self.pre, &self.pre_copy, input, l + 1);
            ctx.sample_template(&view);
            sm.initialize(ctx, &view).map_err(|r| {
                Error::InvalidRegion(format!(
                    "cannot track {quad} at pyramid level {}: {r}",
                    l + 1
                ))
            })?;
        }
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        for Stage { ctx, sm } in self.lower.iter_mut() {
            ctx.set_region(quad, self.params.res, self.params.grid)?;
            ctx.sample_template(&view);
            sm.initialize(ctx, &view).map_err(|r| {
                Error::InvalidRegion(format!("cannot track {quad} with {}: {r}", ctx.ssm.name()))
            })?;
        }
        self.status = TrackStatus::Tracking;
        self.frame = 0;
        self.motion = 0.0;
        self.corners = self.ctx.corners(&self.ctx.params);
        self.initial_area = quad.signed_area().abs();
        self.confidence =
            BlockCorrelation::new(&self.ctx.template, self.params.res, CONFIDENCE_BLOCKS);
        self.detector = Detector::new(self.params.res, &self.ctx.template);
        self.loss.reset();
        self.lost_at = None;
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
        let target = quad.map(|p| self.ctx.norm.to_norm(p));
        let p = self
            .ctx
            .ssm
            .fit(&self.ctx.template_corners.0, &target.0)
            .ok_or_else(|| {
                Error::InvalidRegion(format!("cannot fit {} to {quad}", self.ctx.ssm.name()))
            })?;
        self.ctx.params = p;
        self.corners = self.ctx.corners(&p);
        self.status = TrackStatus::Tracking;
        self.loss.reset();
        self.forget_previous();
        self.lost_at = None;
        Ok(())
    }

    /// Tracks one frame. Never panics and never returns non-finite corners: a loss of track is
    /// reported in the status, with the last good corners.
    #[allow(clippy::result_large_err)]
    fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        let resume =
            matches!(self.status, TrackStatus::Lost(_)) && self.params.on_loss != LossPolicy::Stop;
        if self.status != TrackStatus::Tracking && !resume {
            return FrameOutcome::idle(self.frame, self.status, self.corners);
        }
        self.frame += 1;
        // Sums are used only in the frame they were made in (a context made again by an
        // initialisation counts its samplings from zero).
        self.patch_sums.0 = None;
        let mut timing = FrameTiming::default();
        let start_params = self.ctx.params;
        let start_corners = self.corners;
        let (fw, fh) = input.size();
        let started = Instant::now();
        let mut result = self.search_from(
            input,
            start_params,
            &start_corners,
            observer,
            started,
            &mut timing,
        );
        // Lost and searching on: also from where the last search ended when only its confidence
        // failed. A frame judged lost on the target (a sudden blur) is then found again, where
        // a search from the last good estimate alone falls behind a moving target for good.
        if resume && let Some(p) = self.lost_at {
            let from = self.ctx.corners(&p);
            let other = self.search_from(input, p, &from, observer, started, &mut timing);
            let conf = |r: &SearchResult| match r {
                Ok(o) | Err((_, Some(o))) => o.confidence,
                Err((_, None)) => f64::NEG_INFINITY,
            };
            if conf(&other) > conf(&result) {
                result = other;
            }
        }
        let checked = result.and_then(|out| {
            let confidence = self.ctx.dof >= super::confidence::MIN_DOF;
            self.accept(&out, fw, fh, confidence)
                .map(|()| out)
                .map_err(|r| (r, Some(out)))
        });
        // Where a search that only failed the confidence checks ended: with `on_loss=continue`
        // (or `redetect`) the next frame is searched from there too.
        let lost_at = match &checked {
            Err((LossReason::LowConfidence, Some(o))) => Some(o.params),
            _ => None,
        };
        // Still lost with `on_loss=redetect`: search the whole frame.
        let checked = match checked {
            Err(failed) if resume && self.params.on_loss == LossPolicy::Redetect => {
                let found = self.redetect(input, observer, started, &mut timing, fw, fh);
                found
                    .ok_or(failed)
                    .map_err(|(_, out)| (LossReason::NotFound, out))
            }
            other => other,
        };
        let outcome = match checked {
            Ok(out) => {
                self.motion = (0..4)
                    .map(|i| out.corners.0[i].dist(start_corners.0[i]))
                    .fold(0.0, f64::max);
                self.ctx.params = out.params;
                self.corners = out.corners;
                self.status = TrackStatus::Tracking;
                self.lost_at = None;
                // The next frame's patch is compared with this one's (made in place: a frame's
                // update does not allocate once the buffers have grown).
                self.remember_patch(input, &out);
                FrameOutcome {
                    frame: self.frame,
                    status: TrackStatus::Tracking,
                    corners: out.corners,
                    iterations: out.iterations,
                    converged: out.converged,
                    similarity: out.similarity,
                    searched: true,
                    estimate: Some(out.corners),
                    confidence: Some(out.confidence),
                    timing,
                }
            }
            Err((reason, out)) => {
                self.forget_previous();
                self.ctx.params = start_params;
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
                    confidence: finite.map(|o| o.confidence),
                    timing,
                }
            }
        };
        observer.frame_finished(self.frame, &outcome);
        outcome
    }

    fn inspection(&self) -> Option<Inspection<'_>> {
        Some(Inspection {
            res: self.params.res,
            template: &self.ctx.template,
            patch: &self.ctx.work.values,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imaging::GrayF32;
    use crate::spec::RegistrationSpec;

    /// A search method may reuse the patch in its context's buffer when it was sampled at the
    /// same parameters (`Context::patch_at`); so every context, each pyramid level's and each
    /// stage of the SSM hierarchy too, forgets its patch when another frame is prepared (the
    /// same parameters on another frame are another patch).
    #[test]
    fn a_new_frame_leaves_no_context_with_a_sampled_patch() {
        let mut spec = RegistrationSpec {
            sm: "iclk".into(),
            am: "ssd".into(),
            ssm: "homography".into(),
            params: TrackerParams::default(),
            method: Default::default(),
        };
        spec.params.ssm_hierarchy = true;
        let mut t = RegistrationTracker::new(&spec).unwrap();
        assert!(!t.coarse.is_empty() && !t.lower.is_empty());
        let frame = GrayF32 {
            width: 64,
            height: 48,
            data: (0..64 * 48).map(|i| ((i * 37) % 251) as f32).collect(),
        };
        let p = t.ctx.params;
        for stage in t.coarse.iter_mut().chain(&mut t.lower) {
            stage.ctx.work.sampled_at = Some(p);
        }
        t.ctx.work.sampled_at = Some(p);
        t.prepare(FrameInput::Gray32(&frame), (4.0, 4.0, 40.0, 30.0));
        assert_eq!(t.ctx.work.sampled_at, None);
        for stage in t.coarse.iter().chain(&t.lower) {
            assert_eq!(stage.ctx.work.sampled_at, None);
        }
    }

    /// A frame's region smoothed in parts ([`Source`]) gives the same tracks, bit for bit, as
    /// the whole region smoothed at once, for every method that allows it (with the line
    /// search and the polish and without), on a sequence fast enough that some frames' searches
    /// leave the first part. With debug assertions, the part not smoothed is NaN: a read of it
    /// would show as a lost frame or other corners.
    #[test]
    fn a_region_smoothed_in_parts_tracks_as_the_whole_region() {
        use crate::dataset::demo::demo_config;
        use crate::dataset::synth::{SynthConfig, render_frames};
        use crate::observe::NoObserver;
        let (gray, quads) = render_frames(&SynthConfig {
            max_frames: Some(30),
            step: 6,
            ..demo_config()
        })
        .unwrap();
        let (mut partial_frames, mut completed_frames) = (0, 0);
        let (mut tracked, mut frames) = (0, 0);
        for sm in ["iclk", "fclk", "esm", "falk", "ialk"] {
            for (am, ssm, classic) in [
                ("ssd", "homography", true),
                ("zncc", "affine", false),
                ("ssd", "similitude", false),
            ] {
                let mut spec = RegistrationSpec {
                    sm: sm.into(),
                    am: am.into(),
                    ssm: ssm.into(),
                    params: TrackerParams::default(),
                    method: Default::default(),
                };
                spec.params.pyramid_levels = 1;
                spec.params.line_search = !classic;
                spec.params.polish = !classic;
                let mut run = |partial: bool| {
                    let mut t = RegistrationTracker::new(&spec).unwrap();
                    t.partial = partial;
                    t.initialize(FrameInput::Gray8(&gray[0]), &quads[0])
                        .unwrap();
                    let mut track = Vec::new();
                    for g in &gray[1..] {
                        let out = t.update(FrameInput::Gray8(g), &mut NoObserver);
                        track.push((out.status, out.corners.to_array().map(f64::to_bits)));
                        match (partial, t.pre.is_whole()) {
                            (true, true) => completed_frames += 1,
                            (true, false) => partial_frames += 1,
                            _ => {}
                        }
                    }
                    track
                };
                let (parts, whole) = (run(true), run(false));
                assert_eq!(parts, whole, "{sm} {am} {ssm}");
                tracked += parts
                    .iter()
                    .filter(|(s, _)| *s == TrackStatus::Tracking)
                    .count();
                frames += parts.len();
            }
        }
        // Both ways of a frame: searches that stayed in the first part, searches that left it.
        assert!(
            partial_frames > 0 && completed_frames > 0,
            "{partial_frames} {completed_frames}"
        );
        // Tracks, not losses, compared.
        assert!(
            5 * tracked >= 4 * frames,
            "{tracked} of {frames} frames tracked"
        );
    }
}
