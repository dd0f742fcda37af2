//! The factory: a tracker of any kind built at run time from a [`TrackerSpec`], its names
//! resolved against the registries (AM, SSM and SM for a registration tracker, the whole
//! trackers' registry), its parameters checked, impossible combinations refused with the reason.
//!
//! This is also the crate's one door to trackers: it re-exports the specs ([`crate::spec`]), the
//! tracker interface ([`crate::visual_tracker`]) and the status types, so that users write
//! `regtrack::tracker::{Tracker, TrackerSpec, FrameInput}`.

use crate::am::ilm::Illumination;
use crate::error::{Error, Result};
use crate::params::{MethodParams, ParamDef};
use crate::plan::{Plan, Searcher};
use crate::registration::spi::Selection;
use crate::registration::{Context, SmConfig};
use crate::registry;
use crate::{am, sm, ssm, whole};

pub use crate::plan::RegistrationTracker;
pub use crate::spec::{
    GridLayout, LossPolicy, RegistrationSpec, TRACKER_PARAMS, TrackerParams, TrackerSpec, WholeSpec,
};
pub use crate::status::{FrameOutcome, FrameTiming, LossReason, TrackStatus};
pub use crate::visual_tracker::{FrameInput, Inspection, VisualTracker};
pub use crate::whole::{REGISTRY as WHOLE_REGISTRY, WholeDef};

/// A tracker of any kind built from a [`TrackerSpec`]; derefs to [`VisualTracker`].
#[derive(Debug)]
pub struct Tracker(Box<dyn VisualTracker>);

impl Tracker {
    /// Builds a tracker; fails on unknown names, impossible combinations or bad parameters.
    pub fn new(spec: &TrackerSpec) -> Result<Self> {
        Ok(Tracker(match spec {
            TrackerSpec::Registration(r) => Box::new(RegistrationTracker::new(r)?),
            TrackerSpec::Whole(w) => {
                let e = registry::lookup(whole::REGISTRY, "tracker", &w.tracker)?;
                let defs: Vec<&ParamDef> = e.build.params.iter().collect();
                w.method.validate(&format!("tracker '{}'", e.name), &defs)?;
                let mut w = w.clone();
                w.tracker = e.name.to_string();
                (e.build.build)(&w)?
            }
        }))
    }
}

impl Tracker {
    /// Frame `index` of a stream the tracker follows from its start (a live run's): on the
    /// first it is initialised on `init`, on the others updated; the corners while it tracks.
    pub fn follow(
        &mut self,
        input: FrameInput<'_>,
        init: &crate::geometry::Quad,
        index: usize,
    ) -> Result<Option<crate::geometry::Quad>> {
        if index == 0 {
            self.initialize(input, init)?;
            return Ok(Some(*init));
        }
        let out = self.update(input, &mut crate::observe::NoObserver);
        Ok((out.status == TrackStatus::Tracking).then_some(out.corners))
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

impl TrackerSpec {
    /// The pre-smoothing a registration tracker of this spec applies to the region it reads
    /// (`blur_sigma` resolved for its search method); `None` for a whole tracker, and for one
    /// on the descriptor fields (it smooths the fields it makes of the frame, not the frame).
    pub fn smoothing(&self) -> Result<Option<crate::imaging::GaussianKernel>> {
        let Some(spec) = self.registration() else {
            return Ok(None);
        };
        if spec.params.channels == crate::spec::Channels::Df {
            return Ok(None);
        }
        Ok(Some(RegistrationTracker::new(spec)?.smoothing().clone()))
    }

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
        let e = registry::lookup(whole::REGISTRY, "tracker", name)?;
        Ok(TrackerSpec::Whole(WholeSpec {
            tracker: e.name.to_string(),
            method: MethodParams::default(),
        }))
    }

    /// Builds the tracker once to check names, combination and parameters.
    pub fn check(&self) -> Result<()> {
        Tracker::new(self).map(|_| ())
    }

    /// The definitions of the method's own parameters (the SM's and the AM's, or the whole
    /// tracker's).
    pub fn method_defs(&self) -> Result<Vec<&'static ParamDef>> {
        match self {
            TrackerSpec::Registration(r) => r.method_defs(),
            TrackerSpec::Whole(w) => Ok(registry::lookup(whole::REGISTRY, "tracker", &w.tracker)?
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

impl RegistrationTracker {
    /// Builds a registration tracker and its plan ([`Plan::standard`]); fails on unknown
    /// names, impossible combinations or bad parameters. Every searcher (the tracker's own,
    /// each pyramid level's, each SSM of the hierarchy) is built the same way, with the spec's
    /// AM and SM parameters.
    pub fn new(spec: &RegistrationSpec) -> Result<Self> {
        spec.params.validate()?;
        // The AM takes its own parameters; the search method gets (and checks) the others.
        let am_defs: Vec<&ParamDef> = am::param_defs(&spec.am)?.iter().collect();
        let sm_method = spec.method.split(&am_defs).1;
        let build = |ssm_name: &str, res: usize| -> Result<Searcher> {
            let cfg = SmConfig {
                method: &sm_method,
                tracker: &spec.params,
            };
            let model = appearance_model(spec)?;
            let sm = sm::build(&spec.sm, &cfg)?;
            check_capabilities(&*sm, &*model)?;
            check_selection(&spec.params, &*model)?;
            let warp = ssm::build(ssm_name)?;
            check_dof(&*warp, &*model)?;
            check_non_rigid(&*warp, &*sm, &cfg)?;
            let mut ctx = Context::new(warp, model, spec.params.hessian, res);
            ctx.set_selection(Selection::of(&spec.params));
            ctx.set_smoothness(spec.params.smoothness);
            ctx.set_channels(spec.params.channels.count());
            Ok(Searcher::new(ctx, sm))
        };
        let main = build(&spec.ssm, spec.params.res)?;
        let mut canonical = spec.clone();
        canonical.sm = main.method().name().to_string();
        canonical.am = main.context().am().name().to_string();
        canonical.ssm = main.context().ssm().name().to_string();
        let plan = Plan::standard(&spec.params, &canonical.ssm, &main, &build)?;
        let tracker = RegistrationTracker::from_plan(canonical.clone(), main, plan);
        // The second hypothesis: the same SSM and tracker parameters (without one of its own),
        // the method's and AM's defaults.
        match spec.params.second.names() {
            Some((sm, am)) => {
                let mut params = spec.params.clone();
                params.second = Default::default();
                let other = RegistrationSpec {
                    sm: sm.into(),
                    am: am.into(),
                    ssm: canonical.ssm,
                    params,
                    method: Default::default(),
                };
                Ok(tracker.with_second(RegistrationTracker::new(&other)?))
            }
            None => Ok(tracker),
        }
    }
}

/// The spec's AM, under its illumination model if it has one; for colour, on the three
/// channels' patches stacked into one (`channel_model = stacked`, but for a model that reads
/// the patch as its grid) or channel by channel ([`am::channels::PerChannel`]; not a model
/// that is a plain sum of squares over the pixels, SSD, which is its own sum over the channels
/// either way).
fn appearance_model(spec: &RegistrationSpec) -> Result<Box<dyn am::Am>> {
    let model = lit_model(spec)?;
    if spec.params.channels == crate::spec::Channels::Df && model.bins_grey_levels() {
        return Err(Error::Incompatible(format!(
            "'{}' bins grey levels 0..255 into its histogram; the descriptor fields \
             (channels=df) are derivatives piled up near zero: use ssd, zncc, ncc, scv or \
             another model that compares values",
            spec.am
        )));
    }
    let channels = spec.params.channels.count();
    // Stacked unless the model reads the patch as its grid (neighbours, regions), which it
    // can only do channel by channel.
    let stacked = spec.params.channel_model == crate::spec::ChannelModel::Stacked;
    let sum_of_squares = model.pixelwise() && model.hessian_is_minus_jtj();
    if channels == 1 || (stacked && !model.needs_grid()) || sum_of_squares {
        return Ok(model);
    }
    Ok(Box::new(am::channels::PerChannel::new(model, channels)))
}

/// The spec's AM, under its illumination model if it has one.
fn lit_model(spec: &RegistrationSpec) -> Result<Box<dyn am::Am>> {
    let model = am::build_with(&spec.am, &spec.method)?;
    let p = &spec.params;
    if p.ilm == Illumination::None {
        return Ok(model);
    }
    if !am::ilm::LEAST_SQUARES.contains(&model.name()) {
        return Err(Error::Incompatible(format!(
            "an illumination model (ilm={}) needs a least-squares appearance model ({}), not '{}'",
            Illumination::NAMES[crate::spec::ParamValue::to_param(&p.ilm) as usize],
            am::ilm::LEAST_SQUARES.join(", "),
            model.name()
        )));
    }
    Ok(Box::new(am::ilm::IlmSsd::new(p.ilm, p.ilm_cells)))
}

/// Refuses selective pixel integration (`spi`, a mask) with a model that reads the patch as the
/// whole grid.
fn check_selection(params: &TrackerParams, model: &dyn am::Am) -> Result<()> {
    if params.selective() && model.needs_grid() {
        let what = if params.ilm == Illumination::None {
            format!("appearance model '{}'", model.name())
        } else {
            "an illumination model (ilm)".to_string()
        };
        return Err(Error::Incompatible(format!(
            "selective pixel integration (spi, spi_mask_*) reads part of the grid, but {what} reads the patch as the whole grid (its neighbours or its blocks)"
        )));
    }
    Ok(())
}

/// Whether the models' capabilities allow the combination: the AM has what the search method
/// needs, its Hessian takes the SSM's parameters, and a non-rigid SSM has a search method that
/// can search it. What building a tracker checks, for the generic tests to predict.
pub fn allowed(sm: &dyn sm::SearchMethod, model: &dyn am::Am, warp: &dyn ssm::Ssm) -> bool {
    model.capabilities().missing(&sm.requires()).is_none()
        && warp.dof() <= model.max_dof()
        && (warp.projective() || sm.non_rigid())
}

/// Refuses an SSM of more parameters than the appearance model's Hessian takes, naming the
/// models that take it.
fn check_dof(warp: &dyn ssm::Ssm, model: &dyn am::Am) -> Result<()> {
    if warp.dof() <= model.max_dof() {
        return Ok(());
    }
    Err(Error::Incompatible(format!(
        "state space model '{}' has {} parameters, but appearance model '{}' takes at most {}; \
         appearance models that take {}: {}",
        warp.name(),
        warp.dof(),
        model.name(),
        model.max_dof(),
        warp.dof(),
        am::REGISTRY
            .iter()
            .filter(|e| e.build.default_model().max_dof() >= warp.dof())
            .map(|e| e.name)
            .collect::<Vec<_>>()
            .join(", ")
    )))
}

/// Refuses a non-rigid SSM with a search method that reads the warp as a matrix or draws
/// random warps, naming the methods that take it.
fn check_non_rigid(warp: &dyn ssm::Ssm, sm: &dyn sm::SearchMethod, cfg: &SmConfig) -> Result<()> {
    if warp.projective() || sm.non_rigid() {
        return Ok(());
    }
    let takers: Vec<&str> = sm::REGISTRY
        .iter()
        .filter(|e| sm::build(e.name, cfg).is_ok_and(|m| m.non_rigid()))
        .map(|e| e.name)
        .collect();
    Err(Error::Incompatible(format!(
        "state space model '{}' is non-rigid (a grid of control points), which search method \
         '{}' cannot search (it samples warps or reads them as a homography); search methods \
         that can: {} (and lm:, cascade: and parallel: of them)",
        warp.name(),
        sm.name(),
        takers.join(", ")
    )))
}

/// Refuses a search method whose needs the appearance model does not meet, naming the models
/// that do.
fn check_capabilities(sm: &dyn sm::SearchMethod, model: &dyn am::Am) -> Result<()> {
    let (need, have) = (sm.requires(), model.capabilities());
    match have.missing(&need) {
        None => Ok(()),
        Some(missing) => Err(Error::Incompatible(format!(
            "search method '{}' needs {missing}, which appearance model '{}' does not have; \
             appearance models that do: {}",
            sm.name(),
            model.name(),
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
        ))),
    }
}

/// Every registration tracker of the product `sms x ams x ssms` (each name resolved and the
/// combination checked), then the whole trackers, all with default parameters.
pub fn product(
    sms: &[String],
    ams: &[String],
    ssms: &[String],
    whole: &[String],
) -> Result<Vec<TrackerSpec>> {
    let mut out = Vec::new();
    for s in sms {
        for a in ams {
            for m in ssms {
                out.push(TrackerSpec::from_names(s, a, m)?);
            }
        }
    }
    for t in whole {
        out.push(TrackerSpec::whole(t)?);
    }
    Ok(out)
}

/// The default tracker ([`crate::spec::default_spec`]) on the state space model `ssm` (a name
/// or an alias), checked.
pub fn default_spec(ssm: &str) -> Result<TrackerSpec> {
    let ssm = registry::lookup(ssm::REGISTRY, "state space model", ssm)?.name;
    let spec = crate::spec::default_spec(ssm);
    spec.check()?;
    Ok(spec)
}

/// One registration tracker by its names, as `regtrack track` and Python's `Tracker()` take
/// them: the default tracker (with its parameters) when neither `sm` nor `am` is named, else
/// the plain combination, the default's method for the one not named.
pub fn one(sm: Option<&str>, am: Option<&str>, ssm: &str) -> Result<TrackerSpec> {
    let [default_sm, default_am, _] = crate::spec::DEFAULT_TRACKER;
    match (sm, am) {
        (None, None) => default_spec(ssm),
        _ => TrackerSpec::from_names(sm.unwrap_or(default_sm), am.unwrap_or(default_am), ssm),
    }
}

/// Gives every registration tracker of `specs` the default tracker's parameters
/// ([`crate::spec::default_params`]): for a selection that names neither an SM nor an AM,
/// before the parameters the user gives.
pub fn set_default_params(specs: &mut [TrackerSpec]) {
    for p in specs.iter_mut().filter_map(TrackerSpec::params_mut) {
        *p = crate::spec::default_params();
    }
}

/// The trackers of a selection: the product of the lists (`None`: the default's, none at all
/// when only whole trackers are named), with the default tracker's own parameters when neither
/// an SM nor an AM is named, then `assignments` (as [`set_params`]). `regtrack eval` and
/// Python's `eval` select with it.
pub fn select(
    sms: Option<&[String]>,
    ams: Option<&[String]>,
    ssms: Option<&[String]>,
    whole: &[String],
    assignments: &[(String, String)],
) -> Result<Vec<TrackerSpec>> {
    let only_whole = !whole.is_empty() && sms.is_none() && ams.is_none() && ssms.is_none();
    let d = crate::spec::DEFAULT_TRACKER;
    let list = |v: Option<&[String]>, default: &str| match v {
        _ if only_whole => Vec::new(),
        Some(v) => v.to_vec(),
        None => vec![default.to_string()],
    };
    let mut specs = product(&list(sms, d[0]), &list(ams, d[1]), &list(ssms, d[2]), whole)?;
    if sms.is_none() && ams.is_none() {
        set_default_params(&mut specs);
    }
    set_params(&mut specs, assignments)?;
    Ok(specs)
}

/// Sets each `(name, value)` on every tracker of `specs` that has such a parameter (`seed`
/// reaches the sampling search methods and the whole trackers that draw random numbers, `res`
/// only the registration trackers), then checks each tracker. A parameter that none of them has
/// is an error listing the first one's parameters.
pub fn set_params(specs: &mut [TrackerSpec], assignments: &[(String, String)]) -> Result<()> {
    for (name, value) in assignments {
        let mut taken = false;
        for spec in specs.iter_mut() {
            let has = (spec.params().is_some() && TrackerParams::def(name).is_some())
                || spec.method_defs()?.iter().any(|d| d.name == name);
            if has {
                spec.set_param(name, value)?;
                taken = true;
            }
        }
        if !taken && let Some(first) = specs.first_mut() {
            first.set_param(name, value)?;
        }
    }
    for spec in specs.iter() {
        spec.check()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A selection that names no SM and no AM is the default tracker with its own parameters;
    /// naming either gives the plain combination; the user's parameters come last.
    #[test]
    fn the_default_tracker_has_its_parameters_only_when_no_method_is_named() {
        use crate::spec::{DEFAULT_TRACKER, SecondHypothesis, default_params};
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        let second = |specs: &[TrackerSpec]| -> Vec<SecondHypothesis> {
            specs.iter().map(|t| t.params().unwrap().second).collect()
        };
        let d = select(None, None, Some(&s(&["homography", "affine"])), &[], &[]).unwrap();
        assert_eq!(d.len(), 2);
        assert_eq!(second(&d), vec![default_params().second; 2]);
        assert_ne!(default_params().second, SecondHypothesis::None);
        assert_eq!(d[0].columns().0, DEFAULT_TRACKER[0]);
        assert_eq!(d[0], default_spec("homography").unwrap());
        let plain = select(Some(&s(&[DEFAULT_TRACKER[0]])), None, None, &[], &[]).unwrap();
        assert_eq!(second(&plain), vec![SecondHypothesis::None]);
        let plain = select(None, Some(&s(&["zncc"])), None, &[], &[]).unwrap();
        assert_eq!(second(&plain), vec![SecondHypothesis::None]);
        let mine = [("second".to_string(), "none".to_string())];
        let own = select(None, None, None, &[], &mine).unwrap();
        assert_eq!(second(&own), vec![SecondHypothesis::None]);
        // Whole trackers alone: no registration tracker, nothing to set.
        let whole = select(None, None, None, &s(&["kcf"]), &[]).unwrap();
        assert_eq!(whole.len(), 1);
        assert!(whole[0].params().is_none());
        assert_eq!(
            crate::spec::default_tracker_text(),
            "fclk ssd homography, escalate=on, second=fclk_zncc"
        );
    }

    #[test]
    fn am_parameter_names_are_not_taken_by_search_methods_or_the_tracker() {
        // A registration tracker's method parameters are one bag: the AM takes its own names and
        // the search method the rest, so a name must belong to one of them only.
        for e in am::REGISTRY {
            for d in e.build.params {
                assert!(
                    !TRACKER_PARAMS.iter().any(|t| t.name == d.name),
                    "{}: '{}' is a tracker parameter",
                    e.name,
                    d.name
                );
                for s in sm::REGISTRY {
                    assert!(
                        !s.build.params.iter().any(|p| p.name == d.name),
                        "{}: '{}' is a parameter of {}",
                        e.name,
                        d.name,
                        s.name
                    );
                }
            }
        }
    }
}
