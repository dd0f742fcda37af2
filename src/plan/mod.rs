//! The plan of a registration tracker: what it does with each frame, as a list of stages run in
//! turn over the frame's estimate, built by the factory ([`crate::tracker`]) from the tracker's
//! parameters ([`Plan::standard`]). The executor ([`crate::registration::Executor`]) owns the
//! iteration loop; a stage decides where a search starts, on which problem and level, and what
//! is kept of it; a policy decides what happens after a stage's (or the plan's) outcome.
//!
//! The standard plan, each in its own file:
//! - [`Hierarchy`] (`ssm_hierarchy=on`): a cascade over SSMs of fewer DOF, each from its fit to
//!   the corners the last one found;
//! - [`Retry`] around the pyramid: [`Pyramid`] (`pyramid_levels` > 1, the gradient methods), a
//!   cascade over coarser levels checked against the finest level's confidence, then the rest
//!   of the plan; when the search from the coarse estimate ends less confident than the track's
//!   recent frames, the rest runs again from where the pyramid started and the more confident
//!   end is kept;
//! - [`Search`]: the tracker's own search method at the finest level;
//! - [`Polish`] (`polish=on`, methods that linearise at the template): forward-compositional
//!   steps while the confidence rises;
//! - [`Measure`]: the confidences of where the frame ended (against the template, against the
//!   last tracked frame's patch).
//!
//! Around the plan, the tracker's policies: a search that leaves the pre-processed region is
//! redone on a larger one ([`regrow`]); a frame is judged by the loss checks ([`judge`]), its
//! confidence allowing for motion blur when it moved fast (`blur.rs`), a periodic template's
//! frame checked against its look-alikes one period over (`periodic.rs`); a lost tracker
//! searches also from where the rejected search ended, then the whole frame ([`redetect`]).
//!
//! To add a stage: a file here with a type implementing [`Stage`] (its own test beside it),
//! and a line in [`Plan::standard`]. `plan::tests::every_stage_of_the_standard_plans_runs`
//! builds the standard plans of every combination of the tracker parameters that add stages
//! and tracks a rendered sequence with each.

mod blur;
mod escalate;
mod hierarchy;
pub mod judge;
mod measure;
mod periodic;
mod polish;
pub mod predict;
mod pyramid;
pub mod redetect;
pub mod regrow;
mod retry;
mod search;
mod second;
mod sweep;
mod tracker;

pub use escalate::{EASY, Escalate};
pub use hierarchy::{HIERARCHY, Hierarchy};
pub use measure::Measure;
pub use polish::Polish;
pub use pyramid::{MIN_LEVEL_RES, Pyramid, level_res};
pub use retry::Retry;
pub use search::Search;
pub use tracker::RegistrationTracker;

use crate::error::Result;
use crate::geometry::Quad;
use crate::registration::{BlockCorrelation, PatchSums};
use crate::registration::{Context, Executor, FrameSource, Reader, SearchMethod};
use crate::spec::TrackerParams;
use crate::ssm::Params;
use crate::status::LossReason;
use crate::visual_tracker::FrameInput;

/// A search method with its own problem: the tracker's own (the finest level's), or a stage's
/// (a coarse level's, an SSM of the hierarchy's).
#[derive(Debug)]
pub struct Searcher {
    pub(crate) ctx: Context,
    pub(crate) sm: Box<dyn SearchMethod>,
}

impl Searcher {
    pub fn new(ctx: Context, sm: Box<dyn SearchMethod>) -> Self {
        Searcher { ctx, sm }
    }
    /// The problem, state and buffers.
    pub fn context(&self) -> &Context {
        &self.ctx
    }
    /// The search method.
    pub fn method(&self) -> &dyn SearchMethod {
        &*self.sm
    }
    /// The context and the method, taken apart.
    pub fn into_parts(self) -> (Context, Box<dyn SearchMethod>) {
        (self.ctx, self.sm)
    }
    /// The AM learns the patch of `img` at `p` ([`crate::am::Am::learn`]) and the method is
    /// told (it may keep something made from the model: ICLK's Hessian, PF's scorers).
    pub fn learn(&mut self, img: &crate::imaging::ImageView, p: &Params) {
        self.ctx.learn_appearance(img, p);
        self.sm.model_updated(&mut self.ctx);
    }
}

/// Builds a [`Searcher`] for an SSM (by name) on an `res x res` grid, with the tracker's AM and
/// search method and their parameters (the factory's).
pub type BuildSearcher<'a> = &'a dyn Fn(&str, usize) -> Result<Searcher>;

/// Where a frame's search is, as the stages pass it on.
#[derive(Clone, Copy, Debug)]
pub struct Estimate {
    /// The finest level's parameters.
    pub params: Params,
    /// The corners there (frame pixels); set by the searches.
    pub corners: Quad,
    /// The iterations of the frame so far, over every stage.
    pub iterations: usize,
    /// Whether the last search settled (its stop test, not its iteration limit).
    pub converged: bool,
    /// The similarity at the start of the last iteration.
    pub similarity: f64,
    /// The confidence there (the patch against the template), once measured.
    pub confidence: Option<f64>,
    /// The patch's correlation with the last tracked frame's, once measured.
    pub frame_confidence: Option<f64>,
}

impl Estimate {
    /// A frame starting at `params`, whose corners are `corners`.
    pub fn start(params: Params, corners: Quad) -> Self {
        Estimate {
            params,
            corners,
            iterations: 0,
            converged: false,
            similarity: f64::NAN,
            confidence: None,
            frame_confidence: None,
        }
    }

    /// This estimate, counting `iterations` for the frame (a run that goes on from it, or
    /// from where the frame started, after other stages' iterations).
    pub fn with_iterations(self, iterations: usize) -> Self {
        Estimate { iterations, ..self }
    }
}

/// What a frame's end is judged by: the confidence against the template, and against the last
/// tracked frame's patch when there is one, whose sums (made in the same pass) are kept with
/// the workspace's sampling they are of.
#[derive(Debug, Default)]
pub struct Judges {
    pub(crate) template: BlockCorrelation,
    pub(crate) previous: BlockCorrelation,
    pub(crate) has_previous: bool,
    /// The block sums of the last patch both confidences were made of in one pass, and which
    /// sampling of the finest workspace ([`crate::registration::Workspace::samples`]) that
    /// patch was: if the frame keeps it, it becomes `previous` without being summed again.
    pub(crate) sums: (Option<u64>, PatchSums),
    /// The template blurred along a frame's motion, and its confidence (`blur`).
    pub(crate) blurred: Vec<f32>,
    pub(crate) blur: BlockCorrelation,
}

impl Judges {
    /// The correlation with the last tracked frame's patch, if there is one.
    pub fn previous(&self) -> Option<&BlockCorrelation> {
        self.has_previous.then_some(&self.previous)
    }
}

/// One frame's run of the plan: what the stages read and move.
pub struct FrameRun<'a> {
    /// The tracker's own search method and problem (the finest level's).
    pub(crate) finest: &'a mut Searcher,
    pub(crate) src: &'a mut FrameSource,
    pub(crate) input: FrameInput<'a>,
    /// Whether the finest level's region is smoothed only where the searches read
    /// ([`Reader::Part`]).
    pub(crate) partial: bool,
    pub(crate) judges: &'a mut Judges,
    pub(crate) params: &'a TrackerParams,
    /// The median confidence of the track's recent frames.
    pub(crate) reference: Option<f64>,
    pub(crate) exec: Executor<'a>,
    pub(crate) estimate: Estimate,
}

impl<'a> FrameRun<'a> {
    /// The finest level, as a search reads it, with the tracker's problem and method.
    pub fn finest(&mut self) -> (&mut Searcher, Reader<'_>, &mut Executor<'a>) {
        let reader = self.src.reader(self.input, self.partial);
        (self.finest, reader, &mut self.exec)
    }
}

/// What a stage is given when the tracker is initialised: the quad, the frame (prepared around
/// it, with the plan's levels) and the tracker's parameters.
pub struct Init<'a> {
    pub(crate) quad: &'a Quad,
    pub(crate) input: FrameInput<'a>,
    pub(crate) src: &'a FrameSource,
    pub(crate) params: &'a TrackerParams,
}

/// Where a frame the tracker accepted ended, for the stages' searchers to learn the target's
/// appearance there ([`Stage::learn`], AMs that learn: [`crate::am::Am::learn`]).
pub struct Learn<'a> {
    pub(crate) src: &'a mut FrameSource,
    pub(crate) input: FrameInput<'a>,
    /// The finest level's parameters (the same at every pyramid level).
    pub(crate) params: Params,
    /// The corners in the normalised frame (which an SSM of the hierarchy fits).
    pub(crate) normalised: Quad,
}

/// One stage of a plan.
pub trait Stage: std::fmt::Debug + Send {
    /// What the stage is.
    fn name(&self) -> &'static str;
    /// The stage as [`Plan::describe`] lists it (with the stages it holds, if any).
    fn describe(&self) -> String {
        self.name().to_string()
    }
    /// Sets up what the stage owns once the tracker's own template is sampled.
    fn initialize(&mut self, _init: &Init<'_>) -> Result<()> {
        Ok(())
    }
    /// Runs the stage on the frame: moves `run.estimate`, or fails the frame.
    fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason>;
    /// Whether the stage reads only the finest level, at parameters its searches report (the
    /// frame's region may then be smoothed in parts, see [`Reader::Part`]).
    fn local(&self, finest: &dyn SearchMethod) -> bool;
    /// How many coarser pyramid levels the stage reads.
    fn levels(&self) -> usize {
        0
    }
    /// The stage's own searchers (a pyramid level's, an SSM of the hierarchy's) learn the
    /// appearance where a frame the tracker accepted ended (called only for AMs that learn).
    fn learn(&mut self, _at: &mut Learn<'_>) {}
}

/// The two lists of stages a policy stage holds and runs (the pyramid's [`Retry`], the
/// [`Escalate`] stage): `first`, then `then`, with what the plan asks of stages summed over
/// both.
#[derive(Debug)]
pub struct TwoStages {
    pub(crate) first: Vec<Box<dyn Stage>>,
    pub(crate) then: Vec<Box<dyn Stage>>,
}

impl TwoStages {
    pub fn new(first: Vec<Box<dyn Stage>>, then: Vec<Box<dyn Stage>>) -> Self {
        TwoStages { first, then }
    }

    fn all(&self) -> impl Iterator<Item = &Box<dyn Stage>> {
        self.first.iter().chain(&self.then)
    }

    /// `name(first; then)`, each stage as it describes itself.
    pub fn describe(&self, name: &str) -> String {
        let list = |v: &[Box<dyn Stage>]| {
            v.iter()
                .map(|s| s.describe())
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!("{name}({}; {})", list(&self.first), list(&self.then))
    }

    /// Whether every stage of both is local ([`Stage::local`]).
    pub fn local(&self, finest: &dyn SearchMethod) -> bool {
        self.all().all(|s| s.local(finest))
    }

    /// The most coarse levels a stage of either reads.
    pub fn levels(&self) -> usize {
        self.all().map(|s| s.levels()).max().unwrap_or(0)
    }

    /// Every stage of both learns ([`Stage::learn`]).
    pub fn learn(&mut self, at: &mut Learn<'_>) {
        self.first
            .iter_mut()
            .chain(&mut self.then)
            .for_each(|s| s.learn(at));
    }

    /// Sets up every stage of both.
    pub fn initialize(&mut self, init: &Init<'_>) -> Result<()> {
        self.first
            .iter_mut()
            .chain(&mut self.then)
            .try_for_each(|s| s.initialize(init))
    }
}

/// The confidence an estimate was measured at (NaN before it was).
pub(crate) fn measured(e: &Estimate) -> f64 {
    e.confidence.unwrap_or(f64::NAN)
}

/// Runs `stages` in turn on the frame; the first failure ends the frame.
pub fn run_stages(
    stages: &mut [Box<dyn Stage>],
    run: &mut FrameRun<'_>,
) -> std::result::Result<(), LossReason> {
    for stage in stages {
        stage.run(run)?;
    }
    Ok(())
}

/// See the module's documentation.
#[derive(Debug)]
pub struct Plan {
    stages: Vec<Box<dyn Stage>>,
}

impl Plan {
    /// A plan of these stages, run in turn.
    pub fn new(stages: Vec<Box<dyn Stage>>) -> Self {
        Plan { stages }
    }

    /// The standard plan of a tracker of `params` whose own searcher is `main` (see the
    /// module's documentation); `build` makes the searchers of the other levels and SSMs.
    pub fn standard(
        params: &TrackerParams,
        ssm: &str,
        main: &Searcher,
        build: BuildSearcher<'_>,
    ) -> Result<Self> {
        // The coarse levels widen the basin of the methods that descend a gradient; the
        // sampling methods (NN, PF) search the spread of their own samples and the grid
        // methods have their patches, at the finest level only.
        let levels = if main.sm.pyramid() {
            params.pyramid_levels
        } else {
            1
        };
        let pyramid = Pyramid::new(ssm, params, levels, build)?;
        let hierarchy = if params.ssm_hierarchy {
            Hierarchy::new(main.ctx.dof(), params.res, build)?
        } else {
            None
        };
        let mut finest: Vec<Box<dyn Stage>> = vec![Box::new(Search::default())];
        if params.polish && main.sm.template_linearised() {
            finest.push(Box::new(Polish));
        }
        finest.push(Box::new(Measure));
        let mut stages: Vec<Box<dyn Stage>> = Vec::new();
        if let Some(h) = hierarchy {
            stages.push(Box::new(h));
        }
        let full: Vec<Box<dyn Stage>> = match pyramid {
            Some(p) => vec![Box::new(Retry::new(vec![Box::new(p)], finest))],
            None => finest,
        };
        // Something beyond the search and the measure to escalate to: a first attempt at the
        // finest level alone.
        let more = full.len() > 2 || full.iter().any(|s| s.levels() > 0);
        if params.escalate && more {
            let first: Vec<Box<dyn Stage>> = vec![
                Box::new(Search {
                    max_iters: Some(escalate::FIRST_ITERS),
                    eps_times: Some(escalate::FIRST_EPS_TIMES),
                    extrapolate: true,
                }),
                Box::new(Measure),
            ];
            stages.push(Box::new(Escalate::new(first, full)));
        } else {
            stages.extend(full);
        }
        Ok(Plan::new(stages))
    }

    /// The stages, in order, each as it describes itself.
    pub fn describe(&self) -> Vec<String> {
        self.stages.iter().map(|s| s.describe()).collect()
    }

    /// Whether every stage reads only the finest level, at parameters its searches report.
    pub fn local(&self, finest: &dyn SearchMethod) -> bool {
        self.stages.iter().all(|s| s.local(finest))
    }

    /// The coarser pyramid levels the stages read.
    pub fn levels(&self) -> usize {
        self.stages.iter().map(|s| s.levels()).max().unwrap_or(0)
    }

    /// Sets up every stage.
    pub fn initialize(&mut self, init: &Init<'_>) -> Result<()> {
        self.stages.iter_mut().try_for_each(|s| s.initialize(init))
    }

    /// Runs the stages on the frame.
    pub fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
        run_stages(&mut self.stages, run)
    }

    /// Every stage learns where a frame the tracker accepted ended ([`Stage::learn`]).
    pub fn learn(&mut self, at: &mut Learn<'_>) {
        self.stages.iter_mut().for_each(|s| s.learn(at));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::demo::demo_config;
    use crate::dataset::synth::{SynthConfig, render_frames};
    use crate::geometry::Quad;
    use crate::imaging::GrayU8;
    use crate::observe::{Iteration, NoObserver, Observer};
    use crate::status::TrackStatus;
    use crate::visual_tracker::VisualTracker;

    fn frames(n: usize, step: usize) -> (Vec<GrayU8>, Vec<Quad>) {
        render_frames(&SynthConfig {
            max_frames: Some(n),
            step,
            ..demo_config()
        })
        .unwrap()
    }

    use super::harness::spec;

    /// A tracker whose AM learns (PCA, with the pyramid and the SSM hierarchy) learns on every
    /// frame it tracks and on none it loses, and follows the demo's target.
    #[test]
    fn an_am_that_learns_learns_on_the_frames_tracked_only() {
        let (gray, quads) = frames(10, 2);
        let mut spec = spec("esm", "pca", "homography");
        spec.params.ssm_hierarchy = true;
        spec.params.on_loss = crate::spec::LossPolicy::Continue;
        let mut t = RegistrationTracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&gray[0]), &quads[0])
            .unwrap();
        let mean = |t: &RegistrationTracker| t.context().am().template().to_vec();
        let mut last = mean(&t);
        assert_eq!(last, t.context().problem().template());
        for k in 1..gray.len() {
            let out = t.update(FrameInput::Gray8(&gray[k]), &mut NoObserver);
            assert_eq!(out.status, TrackStatus::Tracking, "frame {k}");
            let e = super::harness::error(&out.corners, &quads[k]);
            assert!(e < 1.0, "frame {k}: {e} px");
            let now = mean(&t);
            assert_ne!(now, last, "frame {k}: nothing learnt");
            last = now;
        }
        // The target gone (a flat frame): lost, and nothing learnt.
        let (w, h) = (gray[0].width, gray[0].height);
        let flat = GrayU8::from_vec(w, h, vec![128; w * h]).unwrap();
        let out = t.update(FrameInput::Gray8(&flat), &mut NoObserver);
        assert!(
            matches!(out.status, TrackStatus::Lost(_)),
            "{:?}",
            out.status
        );
        assert_eq!(mean(&t), last);
    }

    /// The levels at which an observer saw iterations.
    #[derive(Default)]
    struct Levels(std::collections::BTreeSet<usize>, usize);
    impl Observer for Levels {
        fn iteration(&mut self, it: &Iteration<'_>) {
            self.0.insert(it.level);
            self.1 += 1;
        }
    }

    /// Every standard plan the tracker parameters can make (the SSM hierarchy on and off, one
    /// level and three, the polish on and off, a method that linearises at the template, one
    /// that does not and a sampling one) has the stages the parameters ask for, in order, and
    /// tracks a rendered sequence with them: a new stage in [`Plan::standard`] is run here.
    #[test]
    fn every_stage_of_the_standard_plans_runs() {
        let (gray, quads) = frames(12, 2);
        let mut seen = std::collections::BTreeSet::new();
        let combinations = ["iclk", "fclk", "nn1k"].into_iter().flat_map(|sm| {
            [false, true].into_iter().flat_map(move |h| {
                [1, 3].into_iter().flat_map(move |l| {
                    [false, true]
                        .into_iter()
                        .flat_map(move |p| [false, true].map(|e| (sm, h, l, p, e)))
                })
            })
        });
        for (sm, hierarchy, levels, polish, escalate) in combinations {
            let mut s = spec(sm, "ssd", "homography");
            s.params.ssm_hierarchy = hierarchy;
            s.params.pyramid_levels = levels;
            s.params.polish = polish;
            s.params.escalate = escalate;
            let mut t = RegistrationTracker::new(&s).unwrap();
            let gradient = sm != "nn1k";
            let finest = if polish && sm == "iclk" {
                "search, polish, measure"
            } else {
                "search, measure"
            };
            let mut expected = Vec::new();
            if hierarchy {
                expected.push("hierarchy".to_string());
            }
            let full: Vec<String> = if gradient && levels > 1 {
                vec![format!("retry(pyramid; {finest})")]
            } else {
                finest.split(", ").map(String::from).collect()
            };
            if escalate && full != ["search", "measure"] {
                expected.push(format!("escalate(search, measure; {})", full.join(", ")));
            } else {
                expected.extend(full);
            }
            let stages = t.stages();
            assert_eq!(stages, expected, "{s:?}");
            seen.extend(stages);
            t.initialize(FrameInput::Gray8(&gray[0]), &quads[0])
                .unwrap();
            let mut levels_seen = Levels::default();
            let mut tracked = 0;
            for g in &gray[1..] {
                let out = t.update(FrameInput::Gray8(g), &mut levels_seen);
                tracked += (out.status == TrackStatus::Tracking) as usize;
            }
            assert!(2 * tracked >= gray.len() - 1, "{s:?}: {tracked} tracked");
            assert!(levels_seen.1 > 0, "{s:?}");
            // The pyramid's levels were searched.
            assert_eq!(
                levels_seen.0.iter().any(|&l| l > 0),
                gradient && levels > 1,
                "{s:?}: levels {:?}",
                levels_seen.0
            );
        }
        for stage in [
            "hierarchy",
            "retry(pyramid; search, polish, measure)",
            "escalate(search, measure; retry(pyramid; search, polish, measure))",
            "search",
        ] {
            assert!(seen.contains(stage), "{stage}: {seen:?}");
        }
    }

    /// The finest level's stages of every plan: the search, the polish where it applies, the
    /// measure last.
    #[test]
    fn the_polish_follows_the_methods_that_linearise_at_the_template() {
        for (sm, polished) in [
            ("iclk", true),
            ("esm", true),
            ("fclk", false),
            ("nn1k", false),
        ] {
            let mut s = spec(sm, "zncc", "affine");
            s.params.pyramid_levels = 1;
            s.params.escalate = false;
            let t = RegistrationTracker::new(&s).unwrap();
            let expected: &[&str] = if polished {
                &["search", "polish", "measure"]
            } else {
                &["search", "measure"]
            };
            assert_eq!(t.stages(), expected, "{sm}");
            s.params.polish = false;
            let t = RegistrationTracker::new(&s).unwrap();
            assert_eq!(t.stages(), ["search", "measure"], "{sm}");
        }
    }

    /// A frame's region smoothed in parts ([`Reader::Part`]) gives the same tracks, bit for
    /// bit, as the whole region smoothed at once, for every method that allows it (with the
    /// line search and the polish and without), on a sequence fast enough that some frames'
    /// searches leave the first part. With debug assertions, the part not smoothed is NaN: a
    /// read of it would show as a lost frame or other corners.
    #[test]
    fn a_region_smoothed_in_parts_tracks_as_the_whole_region() {
        let (gray, quads) = frames(30, 6);
        let (mut partial_frames, mut completed_frames) = (0, 0);
        let (mut tracked, mut n) = (0, 0);
        let local: Vec<&str> = crate::sm::REGISTRY
            .iter()
            .map(|e| e.name)
            .filter(|name| {
                let s = spec(name, "ssd", "homography");
                RegistrationTracker::new(&s)
                    .map(|t| t.finest.sm.local())
                    .unwrap_or(false)
            })
            .collect();
        assert!(local.len() >= 5, "{local:?}");
        for sm in local {
            for (am, ssm, classic) in [
                ("ssd", "homography", true),
                ("zncc", "affine", false),
                ("ssd", "similitude", false),
            ] {
                let mut s = spec(sm, am, ssm);
                s.params.pyramid_levels = 1;
                s.params.line_search = !classic;
                s.params.polish = !classic;
                let mut run = |partial: bool| {
                    let mut t = RegistrationTracker::new(&s).unwrap();
                    t.set_partial(partial);
                    t.initialize(FrameInput::Gray8(&gray[0]), &quads[0])
                        .unwrap();
                    let mut track = Vec::new();
                    for g in &gray[1..] {
                        let out = t.update(FrameInput::Gray8(g), &mut NoObserver);
                        track.push((out.status, out.corners.to_array().map(f64::to_bits)));
                        match (partial, t.src.is_whole()) {
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
                n += parts.len();
            }
        }
        // Both ways of a frame: searches that stayed in the first part, searches that left it.
        assert!(
            partial_frames > 0 && completed_frames > 0,
            "{partial_frames} {completed_frames}"
        );
        // Tracks, not losses, compared.
        assert!(5 * tracked >= 4 * n, "{tracked} of {n} frames tracked");
    }
}

/// What the stages' tests share: a tracker on a rendered sequence, and a frame's run of it.
#[cfg(test)]
pub(crate) mod harness {
    use super::*;
    use crate::dataset::demo::demo_config;
    use crate::dataset::synth::{SynthConfig, render_frames};
    use crate::imaging::GrayU8;
    use crate::observe::Observer;
    use crate::spec::RegistrationSpec;
    use crate::visual_tracker::VisualTracker;
    use std::time::Instant;

    /// The spec `sm`-`am`-`ssm` with the default parameters.
    pub fn spec(sm: &str, am: &str, ssm: &str) -> RegistrationSpec {
        RegistrationSpec {
            sm: sm.into(),
            am: am.into(),
            ssm: ssm.into(),
            params: TrackerParams::default(),
            method: Default::default(),
        }
    }

    /// A tracker `sm`-`am`-`ssm` (its parameters as `tweak` leaves them) initialised on the
    /// first of `n` frames of the demo's motion taken every `step`-th, with the frames and the
    /// true quads.
    pub fn tracker(
        (sm, am, ssm): (&str, &str, &str),
        tweak: impl FnOnce(&mut TrackerParams),
        (n, step): (usize, usize),
    ) -> (RegistrationTracker, Vec<GrayU8>, Vec<Quad>) {
        let (gray, quads) = render_frames(&SynthConfig {
            max_frames: Some(n),
            step,
            ..demo_config()
        })
        .unwrap();
        let mut spec = spec(sm, am, ssm);
        tweak(&mut spec.params);
        let mut t = RegistrationTracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&gray[0]), &quads[0])
            .unwrap();
        (t, gray, quads)
    }

    /// `f` on a frame's run of `t` on `frame` from `start` (frame pixels), its region prepared
    /// whole as a frame's run prepares it.
    pub fn with_run<R>(
        t: &mut RegistrationTracker,
        frame: &GrayU8,
        start: &Quad,
        observer: &mut dyn Observer,
        f: impl FnOnce(&mut FrameRun<'_>) -> R,
    ) -> R {
        let p = t.finest.ctx.problem().fit(start).unwrap();
        t.finest.ctx.set_params(p);
        let corners = t.finest.ctx.corners(&p);
        let input = FrameInput::Gray8(frame);
        t.src.prepare(input, t.region_around(&corners));
        let mut run = FrameRun {
            finest: &mut t.finest,
            src: &mut t.src,
            input,
            partial: false,
            judges: &mut t.judges,
            params: &t.params,
            reference: t.loss.reference(),
            exec: Executor::new(observer, 1, Instant::now()),
            estimate: Estimate::start(p, corners),
        };
        f(&mut run)
    }

    /// What the factory makes of a spec `sm`-`am` (default parameters): a searcher of an SSM
    /// on a grid.
    pub fn searchers(
        sm: &'static str,
        am: &'static str,
    ) -> impl Fn(&str, usize) -> Result<Searcher> {
        move |ssm: &str, res: usize| {
            let params = TrackerParams::default();
            let method = crate::params::MethodParams::default();
            let cfg = crate::registration::SmConfig {
                method: &method,
                tracker: &params,
            };
            let ctx = Context::new(
                crate::ssm::build(ssm)?,
                crate::am::build(am)?,
                params.hessian,
                res,
            );
            Ok(Searcher::new(ctx, crate::sm::build(sm, &cfg)?))
        }
    }

    /// Initialises `stage` for `t`'s target `quad` on `frame` (the region prepared as the
    /// tracker prepares it, with the stage's levels).
    pub fn initialize(stage: &mut dyn Stage, t: &RegistrationTracker, frame: &GrayU8, quad: &Quad) {
        let input = FrameInput::Gray8(frame);
        let mut src = FrameSource::new(t.src.kernel().clone(), stage.levels());
        src.prepare(input, t.region_around(quad));
        src.build_levels(input);
        stage
            .initialize(&Init {
                quad,
                input,
                src: &src,
                params: &t.params,
            })
            .unwrap();
    }

    /// Teaches `stage` (built for `t`) where `frame` shows the target at `quad`, as the tracker
    /// does on a frame it accepts; returns the frame's source (with the stage's levels) and the
    /// finest level's parameters there.
    pub fn learn_at(
        stage: &mut dyn Stage,
        t: &RegistrationTracker,
        frame: &GrayU8,
        quad: &Quad,
    ) -> (FrameSource, Params) {
        let input = FrameInput::Gray8(frame);
        let mut src = FrameSource::new(t.src.kernel().clone(), stage.levels());
        src.prepare(input, t.region_around(quad));
        let problem = t.finest.ctx.problem();
        let params = problem.fit(quad).unwrap();
        let normalised = problem.normalised_corners(&params);
        stage.learn(&mut Learn {
            src: &mut src,
            input,
            params,
            normalised,
        });
        (src, params)
    }

    /// Checks that `s` (a `pca` model's, default parameters, one patch learnt) has learnt the
    /// patch of `view` at `p`: its mean moved from the template by that patch's difference,
    /// weighed as the model weighs it, less its part along the template's motion (its pixel
    /// Jacobian, to which the move is orthogonal, and the part left out to the move).
    pub fn assert_learnt(s: &mut Searcher, view: &crate::imaging::ImageView, p: &Params) {
        s.ctx.sample_at(view, p);
        let patch = s.ctx.values().to_vec();
        let problem = s.ctx.problem();
        let (template, mean) = (problem.template(), s.ctx.am().template());
        let w = 0.95f64;
        let n = template.len();
        let e: Vec<f64> = mean
            .iter()
            .zip(template)
            .map(|(&m, &t)| (w + 1.0) * (m - t) as f64)
            .collect();
        let d: Vec<f64> = patch
            .iter()
            .zip(template)
            .map(|(&x, &t)| (x - t) as f64)
            .collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let norm = |a: &[f64]| dot(a, a).sqrt();
        assert!(norm(&e) > 0.1 * (n as f64).sqrt(), "nothing learnt");
        let (gx, gy) = problem.template_gradient();
        let (dwdp, _) = problem.dwdp0();
        for k in 0..problem.dof() {
            let j: Vec<f64> = (0..n)
                .map(|i| (gx[i] * dwdp[2 * k * n + i] + gy[i] * dwdp[(2 * k + 1) * n + i]) as f64)
                .collect();
            let cos = dot(&e, &j) / (norm(&e) * norm(&j));
            assert!(cos.abs() < 1e-3, "the mean moved along motion {k}: {cos}");
        }
        let rest: Vec<f64> = d.iter().zip(&e).map(|(d, e)| d - e).collect();
        let cos = dot(&e, &rest) / (norm(&e) * norm(&rest).max(1e-9));
        assert!(
            cos.abs() < 1e-3,
            "the move is not the difference's projection: {cos}"
        );
    }

    /// The confidence against the template of the patch at `p` on the run's finest level.
    pub fn confidence_at(run: &mut FrameRun<'_>, p: &Params) -> f64 {
        let view = run.src.view(run.input, 0);
        run.judges
            .template
            .of(run.finest.ctx.whole_sample_at(&view, p))
    }

    /// `q` moved by `(dx, dy)` px.
    pub fn shifted(q: &Quad, dx: f64, dy: f64) -> Quad {
        q.map(|p| crate::geometry::Point::new(p.x + dx, p.y + dy))
    }

    /// The mean distance of the corners.
    pub fn error(a: &Quad, b: &Quad) -> f64 {
        crate::geometry::alignment_error(a, b)
    }
}
