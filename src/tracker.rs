//! A tracker built at run time from method names ([`TrackerSpec`]), and the driver that owns the
//! iteration loop: pre-processing of the region the tracker reads, the stop test, the observer
//! and the loss-of-track checks.

use crate::am;
use crate::error::{Error, Result};
use crate::geometry::Quad;
use crate::imaging::{GrayF32, GrayU8, ImageView, Preprocessor, gaussian_kernel};
use crate::observe::{Iteration, Observer};
use crate::params::{MethodParams, ParamDef};
pub use crate::params::{TRACKER_PARAMS, TrackerParams};
use crate::registry::{self, Entry};
use crate::sm::{self, Context, Control, SearchMethod, SmConfig};
use crate::ssm;
pub use crate::status::{FrameOutcome, FrameTiming, LossReason, TrackStatus};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// A registration tracker by name: search method, appearance model, state space model, the
/// tracker's parameters and the search method's own.
#[derive(Clone, Debug, PartialEq)]
pub struct RegistrationSpec {
    pub sm: String,
    pub am: String,
    pub ssm: String,
    pub params: TrackerParams,
    /// The search method's parameters ([`sm::param_defs`]); unset ones take their defaults.
    pub method: MethodParams,
}

impl RegistrationSpec {
    /// The definitions of the search method's and the appearance model's own parameters.
    pub fn method_defs(&self) -> Result<Vec<&'static ParamDef>> {
        let mut defs = sm::param_defs(&self.sm)?;
        defs.extend(am::param_defs(&self.am)?);
        Ok(defs)
    }

    /// Drops the method parameters that neither the search method nor the appearance model
    /// has (after either was changed); all of them when a name is unknown.
    pub fn keep_known_params(&mut self) {
        self.method = match self.method_defs() {
            Ok(defs) => self.method.split(&defs).0,
            Err(_) => MethodParams::default(),
        };
    }
}

/// A whole tracker by name (one entry of [`WHOLE_REGISTRY`]) with its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct WholeSpec {
    pub tracker: String,
    pub method: MethodParams,
}

/// Any tracker, by name: a registration tracker (AM x SSM x SM) or a whole tracker. Sessions and
/// run files store it as a table: `sm`, `am`, `ssm`, `params`, `method` for the first, `tracker`
/// and `method` for the second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawSpec", into = "RawSpec")]
pub enum TrackerSpec {
    Registration(RegistrationSpec),
    Whole(WholeSpec),
}

/// The stored form of a [`TrackerSpec`].
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tracker: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sm: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    am: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    ssm: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    params: Option<TrackerParams>,
    #[serde(default, skip_serializing_if = "MethodParams::is_empty")]
    method: MethodParams,
}

impl TryFrom<RawSpec> for TrackerSpec {
    type Error = String;
    fn try_from(r: RawSpec) -> std::result::Result<Self, String> {
        match (r.tracker, r.sm, r.am, r.ssm) {
            (Some(tracker), None, None, None) => {
                if r.params.is_some() {
                    return Err(format!(
                        "tracker '{tracker}' takes its parameters in `method`, not `params`"
                    ));
                }
                Ok(TrackerSpec::Whole(WholeSpec {
                    tracker,
                    method: r.method,
                }))
            }
            (None, Some(sm), Some(am), Some(ssm)) => {
                Ok(TrackerSpec::Registration(RegistrationSpec {
                    sm,
                    am,
                    ssm,
                    params: r.params.unwrap_or_default(),
                    method: r.method,
                }))
            }
            (Some(_), _, _, _) => {
                Err("a tracker is either `tracker = NAME` or `sm`, `am` and `ssm`, not both".into())
            }
            _ => Err("a registration tracker needs `sm`, `am` and `ssm`".into()),
        }
    }
}

impl From<TrackerSpec> for RawSpec {
    fn from(s: TrackerSpec) -> Self {
        match s {
            TrackerSpec::Registration(r) => RawSpec {
                sm: Some(r.sm),
                am: Some(r.am),
                ssm: Some(r.ssm),
                params: Some(r.params),
                method: r.method,
                ..Default::default()
            },
            TrackerSpec::Whole(w) => RawSpec {
                tracker: Some(w.tracker),
                method: w.method,
                ..Default::default()
            },
        }
    }
}

impl TrackerSpec {
    /// A registration tracker from names or aliases, with the default parameters; names are
    /// made canonical. Fails with the list of what exists on an unknown name or an impossible
    /// combination.
    pub fn from_names(sm: &str, am: &str, ssm: &str) -> Result<Self> {
        let spec = TrackerSpec::Registration(RegistrationSpec {
            sm: sm::canonical_name(sm)?,
            am: registry::lookup(am::REGISTRY, "appearance model", am)?
                .name
                .to_string(),
            ssm: registry::lookup(ssm::REGISTRY, "state space model", ssm)?
                .name
                .to_string(),
            params: TrackerParams::default(),
            method: MethodParams::default(),
        });
        spec.check()?;
        Ok(spec)
    }

    /// A whole tracker by name or alias, with its default parameters.
    pub fn whole(name: &str) -> Result<Self> {
        let e = registry::lookup(WHOLE_REGISTRY, "tracker", name)?;
        Ok(TrackerSpec::Whole(WholeSpec {
            tracker: e.name.to_string(),
            method: MethodParams::default(),
        }))
    }

    /// Builds the tracker once to check names, combination and parameters.
    pub fn check(&self) -> Result<()> {
        Tracker::new(self).map(|_| ())
    }

    /// The registration tracker's names and parameters, if it is one.
    pub fn registration(&self) -> Option<&RegistrationSpec> {
        match self {
            TrackerSpec::Registration(r) => Some(r),
            TrackerSpec::Whole(_) => None,
        }
    }

    /// Mutable [`TrackerSpec::registration`].
    pub fn registration_mut(&mut self) -> Option<&mut RegistrationSpec> {
        match self {
            TrackerSpec::Registration(r) => Some(r),
            TrackerSpec::Whole(_) => None,
        }
    }

    /// The tracker's parameters (a registration tracker's; `None` for a whole tracker).
    pub fn params(&self) -> Option<&TrackerParams> {
        self.registration().map(|r| &r.params)
    }

    /// Mutable [`TrackerSpec::params`].
    pub fn params_mut(&mut self) -> Option<&mut TrackerParams> {
        self.registration_mut().map(|r| &mut r.params)
    }

    /// The method's own parameters.
    pub fn method_params(&self) -> &MethodParams {
        match self {
            TrackerSpec::Registration(r) => &r.method,
            TrackerSpec::Whole(w) => &w.method,
        }
    }

    /// The definitions of the method's own parameters (the SM's and the AM's, or the whole
    /// tracker's).
    pub fn method_defs(&self) -> Result<Vec<&'static ParamDef>> {
        match self {
            TrackerSpec::Registration(r) => r.method_defs(),
            TrackerSpec::Whole(w) => Ok(registry::lookup(WHOLE_REGISTRY, "tracker", &w.tracker)?
                .build
                .params
                .iter()
                .collect()),
        }
    }

    /// Sets a parameter by name from its typed form: a tracker parameter ([`TRACKER_PARAMS`]) or
    /// one of the method's own. An unknown name is an error that lists the known ones.
    pub fn set_param(&mut self, name: &str, value: &str) -> Result<()> {
        if let TrackerSpec::Registration(r) = self
            && r.params.assign(name, value)?
        {
            return Ok(());
        }
        let defs = self.method_defs()?;
        let owner = self.label();
        let def = defs.iter().find(|d| d.name == name).ok_or_else(|| {
            let mut known: Vec<&str> = defs.iter().map(|d| d.name).collect();
            if self.registration().is_some() {
                known.extend(TRACKER_PARAMS.iter().map(|d| d.name));
            }
            Error::InvalidParameter(format!(
                "{owner} has no parameter '{name}'; its parameters: {}",
                known.join(", ")
            ))
        })?;
        let v = def.parse(&owner, value)?;
        match self {
            TrackerSpec::Registration(r) => r.method.set(name, v),
            TrackerSpec::Whole(w) => w.method.set(name, v),
        }
        Ok(())
    }

    /// `(sm, am, ssm)` as summary columns (a whole tracker: its name, then empty).
    pub fn columns(&self) -> (String, String, String) {
        match self {
            TrackerSpec::Registration(r) => (r.sm.clone(), r.am.clone(), r.ssm.clone()),
            TrackerSpec::Whole(w) => (w.tracker.clone(), String::new(), String::new()),
        }
    }

    /// `sm_am_ssm` (or the whole tracker's name), as used in result file names; a composite's
    /// `cascade:a+b` becomes `cascade-a+b`.
    pub fn label(&self) -> String {
        match self {
            TrackerSpec::Registration(r) => {
                format!("{}_{}_{}", r.sm.replace(':', "-"), r.am, r.ssm)
            }
            TrackerSpec::Whole(w) => w.tracker.clone(),
        }
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

/// What a tracker shows of its inner state for inspection: the template and the current patch
/// (on a `res x res` grid, row-major), from which the error image follows.
#[derive(Clone, Copy, Debug)]
pub struct Inspection<'a> {
    pub res: usize,
    pub template: &'a [f32],
    pub patch: &'a [f32],
}

/// Any tracker: initialised on a frame and a quad, then updated frame by frame. Registration
/// trackers ([`RegistrationTracker`]) and whole trackers ([`WHOLE_REGISTRY`]) implement it; the
/// evaluation, the benchmarks, the command line and the inspector use only this.
pub trait VisualTracker: Send + std::fmt::Debug {
    /// The spec it was built from (with canonical names).
    fn spec(&self) -> &TrackerSpec;
    /// Starts tracking `quad` in `input`.
    fn initialize(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()>;
    /// Tracks one frame. Never panics and never returns non-finite corners: a loss of track is
    /// reported in the status, with the last good corners.
    fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome;
    /// Moves the tracker to `quad` keeping what it learnt, and resumes tracking if it was lost.
    fn set_corners(&mut self, quad: &Quad) -> Result<()>;
    /// Current status.
    fn status(&self) -> TrackStatus;
    /// Current corners (image coordinates).
    fn corners(&self) -> Quad;
    /// The template and current patch, for trackers that have them.
    fn inspection(&self) -> Option<Inspection<'_>> {
        None
    }
    /// The label used in file names and tables.
    fn label(&self) -> String {
        self.spec().label()
    }
    /// The similarity swept around the warp whose corners are `at`, on `input` (see
    /// [`crate::landscape`]); `None` for trackers without a similarity over warps.
    fn landscape(
        &mut self,
        _input: FrameInput<'_>,
        _at: &Quad,
        _spec: &crate::landscape::LandscapeSpec,
    ) -> Option<Result<crate::landscape::Landscape>> {
        None
    }
}

/// A registry entry of a whole tracker: its parameters and its constructor.
#[derive(Clone, Copy)]
pub struct WholeDef {
    pub params: &'static [ParamDef],
    pub build: fn(&WholeSpec) -> Result<Box<dyn VisualTracker>>,
}

/// Whole trackers (not decomposed into AM x SSM x SM): the learning-based trackers the paper
/// compares with.
pub const WHOLE_REGISTRY: &[Entry<WholeDef>] = crate::whole::REGISTRY;

/// A tracker of any kind built from a [`TrackerSpec`]; derefs to [`VisualTracker`].
#[derive(Debug)]
pub struct Tracker(Box<dyn VisualTracker>);

impl Tracker {
    /// Builds a tracker; fails on unknown names, impossible combinations or bad parameters.
    pub fn new(spec: &TrackerSpec) -> Result<Self> {
        Ok(Tracker(match spec {
            TrackerSpec::Registration(r) => Box::new(RegistrationTracker::new(r)?),
            TrackerSpec::Whole(w) => {
                let e = registry::lookup(WHOLE_REGISTRY, "tracker", &w.tracker)?;
                let defs: Vec<&ParamDef> = e.build.params.iter().collect();
                w.method.validate(&format!("tracker '{}'", e.name), &defs)?;
                let mut w = w.clone();
                w.tracker = e.name.to_string();
                (e.build.build)(&w)?
            }
        }))
    }

    /// Wraps a tracker built elsewhere.
    pub fn from_boxed(inner: Box<dyn VisualTracker>) -> Self {
        Tracker(inner)
    }
}

impl std::ops::Deref for Tracker {
    type Target = dyn VisualTracker;
    fn deref(&self) -> &Self::Target {
        &*self.0
    }
}

impl std::ops::DerefMut for Tracker {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut *self.0
    }
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
    coarse: Vec<(Context, Box<dyn SearchMethod>)>,
    /// The SSM hierarchy's stages (fewer DOF first), at full resolution.
    lower: Vec<(Context, Box<dyn SearchMethod>)>,
    pre: Preprocessor,
    /// Builds the pyramid of already smoothed input.
    pre_copy: Preprocessor,
    status: TrackStatus,
    frame: usize,
    corners: Quad,
    initial_area: f64,
}

impl RegistrationTracker {
    /// Builds a tracker; fails on unknown names, impossible combinations or bad parameters.
    pub fn new(spec: &RegistrationSpec) -> Result<Self> {
        spec.params.validate()?;
        let ssm = ssm::build(&spec.ssm)?;
        let am = am::build_with(&spec.am, &spec.method)?;
        // The AM takes its own parameters; the search method gets (and checks) the others.
        let am_defs: Vec<&ParamDef> = am::param_defs(&spec.am)?.iter().collect();
        let sm_method = spec.method.split(&am_defs).1;
        let cfg = SmConfig {
            method: &sm_method,
            tracker: &spec.params,
        };
        let sm = sm::build(&spec.sm, &cfg)?;
        let (need, have) = (sm.requires(), am.capabilities());
        if let Some(missing) = have.missing(&need) {
            return Err(Error::Incompatible(format!(
                "search method '{}' needs {missing}, which appearance model '{}' does not have; \
                 appearance models that do: {}",
                sm.name(),
                am.name(),
                am::REGISTRY
                    .iter()
                    .filter(|e| e
                        .build
                        .default_model()
                        .capabilities()
                        .missing(&need)
                        .is_none())
                    .map(|e| e.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        let mut spec = spec.clone();
        spec.sm = sm.name().to_string();
        spec.am = am.name().to_string();
        spec.ssm = ssm.name().to_string();
        let p = spec.params.clone();
        let ctx = Context::new(ssm, am, p.hessian, p.res);
        let mut coarse = Vec::new();
        for _ in 1..p.pyramid_levels {
            let c = Context::new(
                ssm::build(&spec.ssm)?,
                am::build(&spec.am)?,
                p.hessian,
                p.res,
            );
            coarse.push((c, sm::build(&spec.sm, &cfg)?));
        }
        let mut lower = Vec::new();
        if p.ssm_hierarchy {
            let dof = ssm::build(&spec.ssm)?.dof();
            for name in ["translation", "similitude", "affine"] {
                let m = ssm::build(name)?;
                if m.dof() < dof {
                    let c = Context::new(m, am::build(&spec.am)?, p.hessian, p.res);
                    lower.push((c, sm::build(&spec.sm, &cfg)?));
                }
            }
        }
        let pre = Preprocessor::new(gaussian_kernel(p.blur_size, p.blur_sigma));
        Ok(RegistrationTracker {
            spec: TrackerSpec::Registration(spec),
            params: p,
            ctx,
            sm,
            coarse,
            lower,
            pre,
            pre_copy: Preprocessor::new(gaussian_kernel(1, 0.0)),
            status: TrackStatus::Uninitialized,
            frame: 0,
            corners: Quad::default(),
            initial_area: 0.0,
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

    /// See [`VisualTracker::landscape`].
    fn sweep(
        &mut self,
        input: FrameInput<'_>,
        at: &Quad,
        spec: &crate::landscape::LandscapeSpec,
    ) -> Result<crate::landscape::Landscape> {
        use crate::am::{Wrt, jt_times};
        if self.status == TrackStatus::Uninitialized {
            return Err(Error::InvalidRegion(
                "the tracker is not initialised".into(),
            ));
        }
        let dof = self.ctx.dof;
        if spec.axes.is_empty() || spec.axes.len() > 2 || spec.axes.iter().any(|&k| k >= dof) {
            return Err(Error::InvalidParameter(format!(
                "the landscape sweeps 1 or 2 of the {dof} parameters of {}",
                self.ctx.ssm.name()
            )));
        }
        at.validate()?;
        let steps = (spec.steps.max(3) / 2) * 2 + 1;
        let radius = spec.radius.abs().max(1e-3);
        let target = at.map(|p| self.ctx.norm.to_norm(p));
        let p0 = self
            .ctx
            .ssm
            .fit(&self.ctx.template_corners.0, &target.0)
            .ok_or_else(|| {
                Error::InvalidRegion(format!("cannot fit {} to {at}", self.ctx.ssm.name()))
            })?;
        // Parameter change per px of mean corner motion, per axis.
        let c0 = self.ctx.corners(&p0);
        let mut deltas = Vec::new();
        for &k in &spec.axes {
            let h = 1e-6 * (1.0 + p0[k].abs());
            let mut p = p0;
            p[k] += h;
            let moved = crate::geometry::alignment_error(&self.ctx.corners(&p), &c0) / h;
            if !(moved > 0.0 && moved.is_finite()) {
                return Err(Error::InvalidParameter(format!(
                    "parameter {} does not move the corners",
                    k + 1
                )));
            }
            deltas.push(1.0 / moved);
        }
        // Pre-process a region that holds every swept warp.
        let (x0, y0, x1, y1) = self.region_around(at);
        let grow = 3.0 * radius + 8.0;
        self.prepare(input, (x0 - grow, y0 - grow, x1 + grow, y1 + grow));
        let view = Self::view(&self.pre, &self.pre_copy, input, 0);
        let saved = self.ctx.params;
        let ctx = &mut self.ctx;
        let f_at = |ctx: &mut Context, p: &crate::ssm::Params| {
            ctx.warp_grid(p);
            ctx.sample(&view, false);
            ctx.am.similarity(&ctx.work.values)
        };
        let offsets: Vec<f64> = (0..steps)
            .map(|i| -radius + 2.0 * radius * i as f64 / (steps - 1) as f64)
            .collect();
        let at_offsets = |u: &[f64]| {
            let mut p = p0;
            for (j, &k) in spec.axes.iter().enumerate() {
                p[k] += u[j] * deltas[j];
            }
            p
        };
        let mut values = Vec::with_capacity(steps.pow(spec.axes.len() as u32));
        if spec.axes.len() == 1 {
            for &u in &offsets {
                values.push(f_at(ctx, &at_offsets(&[u])));
            }
        } else {
            for &v in &offsets {
                for &u in &offsets {
                    values.push(f_at(ctx, &at_offsets(&[u, v])));
                }
            }
        }
        // The analytic gradient at the centre, as FALK forms it: the AM's gradient with respect
        // to the current pixels through dI/dp = grad I . dw/dp at p0.
        ctx.warp_grid(&p0);
        ctx.sample(&view, true);
        let s = ctx.norm.scale as f32;
        ctx.work.gx.iter_mut().for_each(|g| *g *= s);
        ctx.work.gy.iter_mut().for_each(|g| *g *= s);
        ctx.project_gradients(Some(&p0));
        let center_value = ctx
            .am
            .gradient(Wrt::Current, &ctx.work.values, &mut ctx.work.grad);
        let mut g = [0.0f64; crate::linalg::MAX_DOF];
        jt_times(&ctx.work.jac, &ctx.work.grad, dof, &mut g);
        let analytic: Vec<f64> = spec
            .axes
            .iter()
            .zip(&deltas)
            .map(|(&k, &d)| g[k] * d)
            .collect();
        let h = 0.01;
        let mut numeric = Vec::new();
        for j in 0..spec.axes.len() {
            let mut up = vec![0.0; spec.axes.len()];
            let mut down = up.clone();
            up[j] = h;
            down[j] = -h;
            let (a, b) = (f_at(ctx, &at_offsets(&up)), f_at(ctx, &at_offsets(&down)));
            numeric.push((a - b) / (2.0 * h));
        }
        ctx.params = saved;
        Ok(crate::landscape::Landscape {
            axes: spec.axes.clone(),
            deltas,
            offsets,
            values,
            center: p0,
            center_value,
            analytic,
            numeric,
        })
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
    ) -> std::result::Result<(Quad, usize, bool, f64), LossReason> {
        let t0 = Instant::now();
        self.prepare(input, region);
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
            let mut corners = self
                .ctx
                .template_corners
                .map(|c| crate::geometry::apply_homography(&m, c));
            for (ctx, sm) in self.lower.iter_mut() {
                ctx.params = ctx
                    .ssm
                    .fit(&ctx.template_corners.0, &corners.0)
                    .ok_or(LossReason::Singular)?;
                let (_, iters, _, _) = Self::search(
                    ctx, &mut **sm, params, self.frame, 0, done, &view, observer, started,
                )?;
                done += iters;
                let m = ctx.ssm.matrix(&ctx.params);
                corners = ctx
                    .template_corners
                    .map(|c| crate::geometry::apply_homography(&m, c));
            }
            self.ctx.params = self
                .ctx
                .ssm
                .fit(&self.ctx.template_corners.0, &corners.0)
                .ok_or(LossReason::Singular)?;
        }
        let mut p = self.ctx.params;
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
        sm.start_frame(ctx);
        let budget = sm.max_iterations(params.max_iters);
        let mut relearnt = 0;
        for it in 0..budget {
            let s = sm.iterate(ctx, view)?;
            let f = s.similarity;
            let corners = ctx.corners(&ctx.params);
            if !corners.is_finite() || f.is_nan() {
                return Err(LossReason::NonFinite);
            }
            let step = corners.change_norm(&prev);
            prev = corners;
            iterations = it + 1;
            similarity = f;
            // The patch where this iteration ended, for observers that show it (the next
            // iteration samples again, so the shared buffers may be used).
            let patch = if observer.wants_patches() {
                let p = ctx.params;
                ctx.warp_grid(&p);
                ctx.sample(view, false);
                Some(&ctx.work.values[..])
            } else {
                None
            };
            observer.iteration(&Iteration {
                frame,
                level,
                iteration: first + it,
                params: &ctx.params[..ctx.dof],
                corners,
                similarity: f,
                step,
                elapsed: started.elapsed(),
                patch,
            });
            if observer.wants_method_visuals()
                && let Some(v) = sm.visual(ctx)
            {
                observer.method_visual(frame, first + it, &v);
            }
            let stop = match s.control {
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
                    Self::learn_model(ctx, sm, view);
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
        ctx.warp_grid(&p);
        ctx.sample(view, false);
        let values = std::mem::take(&mut ctx.work.values);
        ctx.am.update_model(&values);
        ctx.work.values = values;
        sm.model_updated(ctx);
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
        spec: &crate::landscape::LandscapeSpec,
    ) -> Option<Result<crate::landscape::Landscape>> {
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
        for (l, (ctx, sm)) in self.coarse.iter_mut().enumerate() {
            ctx.set_region(quad, self.params.res, self.params.grid)?;
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
        for (ctx, sm) in self.lower.iter_mut() {
            ctx.set_region(quad, self.params.res, self.params.grid)?;
            ctx.sample_template(&view);
            sm.initialize(ctx, &view).map_err(|r| {
                Error::InvalidRegion(format!("cannot track {quad} with {}: {r}", ctx.ssm.name()))
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
        Ok(())
    }

    /// Tracks one frame. Never panics and never returns non-finite corners: a loss of track is
    /// reported in the status, with the last good corners.
    fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        let resume = matches!(self.status, TrackStatus::Lost(_))
            && self.params.on_loss == crate::params::LossPolicy::Continue;
        if self.status != TrackStatus::Tracking && !resume {
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
                self.status = TrackStatus::Tracking;
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

    fn inspection(&self) -> Option<Inspection<'_>> {
        Some(Inspection {
            res: self.params.res,
            template: &self.ctx.template,
            patch: &self.ctx.work.values,
        })
    }
}
