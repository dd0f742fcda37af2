//! The inspector: an interactive desktop application (eframe/egui) to load a sequence, pick
//! trackers (AM, SSM, SM) from the registries, watch them track against the ground truth, read
//! live success-rate and error plots, step through the iterations of a frame, and correct the
//! ground truth by hand.
//!
//! Layout of the code (as in rerun): [`state::State`] is what a session saves; the panels read it
//! and push [`command::Command`]s that [`InspectorApp::apply`] carries out; tracking runs on the
//! [`worker`] thread, polled every frame.

use eframe::egui;
pub mod command;
mod decoder;
mod gt_edit;
mod panels;
pub mod prefs;
mod queries;
mod runtime;
pub use crate::session as state;
mod window;
pub mod worker;

pub use queries::{Disagreement, rank_disagreements};
use runtime::{DisplayRt, LiveRt, MessagesRt, RunRt, SequenceRt, UiRt};
pub use runtime::{Experiment, Frequency, LandscapeView, Patches, Runtime, Tool, Versioned};
pub use state::LandscapeSettings;
pub use window::{AppError, RunOptions, ScreenshotPlan, ShotResult, run};

use command::Command;
use state::{InitSource, SequenceSource, State};
use std::path::PathBuf;
use worker::{Job, Reply, Worker};

/// The application.
pub struct InspectorApp {
    pub state: State,
    rt: Runtime,
}

impl InspectorApp {
    /// A new inspector on `state`; `wake` requests a repaint (from the worker thread).
    pub fn new(state: State, wake: impl Fn() + Send + Sync + 'static) -> Self {
        let rt = Runtime {
            worker: Worker::spawn(wake),
            commands: Vec::new(),
            seq: SequenceRt::default(),
            live: LiveRt::default(),
            run: RunRt::default(),
            display: DisplayRt::default(),
            msg: MessagesRt::default(),
            ui: UiRt::default(),
            gt: gt_edit::GtRuntime::default(),
            screenshot: None,
            frame_times: Vec::new(),
        };
        let mut app = InspectorApp {
            state: State::default(),
            rt,
        };
        if let Some(e) = app.rt.worker.spawn_error.clone() {
            app.error(e);
        }
        app.load_state(state);
        app
    }

    /// The session file the session field shows (and *Save session* writes), as the file the
    /// session came from (saving there again asks nothing).
    pub fn set_session_path(&mut self, p: &std::path::Path) {
        self.rt.ui.session_path = p.display().to_string();
        self.rt.ui.session_file = Some(p.to_path_buf());
    }

    /// Keeps the preferences (the recent sequences) in `path` between runs: reads them now
    /// (a file that cannot be read is one error, and the defaults), writes them on every change.
    pub fn use_prefs(&mut self, path: PathBuf) {
        match prefs::Prefs::load(&path) {
            Ok(p) => self.rt.ui.prefs = p,
            Err(e) => self.error(format!("cannot read the preferences (recent list): {e}")),
        }
        self.rt.ui.prefs_path = Some(path);
    }

    /// The recently opened sequences, newest first.
    pub fn recent(&self) -> &[PathBuf] {
        &self.rt.ui.prefs.recent
    }

    fn add_recent(&mut self, p: &std::path::Path) {
        self.rt.ui.prefs.add_recent(p);
        if let Some(path) = &self.rt.ui.prefs_path
            && let Err(e) = self.rt.ui.prefs.save(path)
        {
            self.error(format!("cannot keep the recent list: {e}"));
        }
    }

    /// Saves the session to `p`; over an existing file other than the session's own, only
    /// after the user confirms (`confirmed`).
    fn save_session(&mut self, p: PathBuf, confirmed: bool) {
        let own = self.rt.ui.session_file.as_ref() == Some(&p);
        if p.exists() && !own && !confirmed {
            self.rt.msg.status = format!("{} exists: overwrite it?", p.display());
            self.rt.ui.confirm_overwrite = Some(p);
            return;
        }
        self.rt.ui.confirm_overwrite = None;
        let replaced = p.exists();
        match self.state.save(&p) {
            Ok(()) => {
                self.rt.msg.status = if replaced {
                    format!("saved session {} (replaced the file)", p.display())
                } else {
                    format!("saved session {}", p.display())
                };
                self.set_session_path(&p);
            }
            Err(e) => self.error(format!("cannot save the session: {e}")),
        }
    }

    /// The save that waits for the user's yes (see [`Command::ConfirmOverwrite`]).
    pub fn overwrite_pending(&self) -> Option<&std::path::Path> {
        self.rt.ui.confirm_overwrite.as_deref()
    }

    /// Replaces the session (the trackers then run up to its saved frame).
    fn load_state(&mut self, state: State) {
        let src = state.sequence.clone();
        self.rt.seq.restore_frame = Some(state.frame);
        self.state = state;
        *self.rt.run.results.edit() = vec![Vec::new(); self.state.trackers.len()];
        self.open(src);
    }

    /// Queues a command (what panels do).
    pub fn send(&mut self, c: Command) {
        self.rt.commands.push(c);
    }

    /// Shows an error once: the same message again moves to the end instead of stacking.
    fn error(&mut self, e: String) {
        self.rt.msg.errors.retain(|x| *x != e);
        self.rt.msg.errors.push(e);
        // At most three, the newest: more pushes the frame down and hides what matters now.
        if self.rt.msg.errors.len() > 3 {
            self.rt.msg.errors.remove(0);
        }
    }

    fn open(&mut self, src: SequenceSource) {
        self.rt.run.playing = false;
        // A sequence replaces a live source (the worker closes it).
        self.rt.live.info = None;
        self.rt.msg.progress = Some(("opening the sequence".into(), 0, 0));
        // The session and the recent list change once it opened (a failed open changes nothing).
        self.rt.seq.opening = Some(src.clone());
        self.rt.worker.send(Job::Open(src));
    }

    /// Opens a live source (`/dev/videoN`, or `lavfi:<graph>` for an FFmpeg test source): its
    /// frames are shown as they come; a box drawn on the image starts a tracker on the frame
    /// it was drawn on.
    fn open_live(&mut self, source: String, width: usize, height: usize) {
        self.rt.run.playing = false;
        self.rt.run.replaying = None;
        self.rt.run.generation += 1;
        self.rt.run.tracked_until = None;
        self.rt.ui.selected_iteration = None;
        self.rt.seq.sequence = None;
        self.rt.seq.opening = None;
        self.rt.seq.bad_frame = None;
        self.rt.display.texture = None;
        self.rt.display.texture_frame = None;
        self.rt.display.pending_image = None;
        self.state.start_frame = 0;
        self.state.frame = 0;
        // No ground truth live: every tracker waits for a box.
        for t in &mut self.state.trackers {
            t.init = InitSource::GroundTruth;
        }
        self.rt.run.starts = vec![0; self.state.trackers.len()];
        self.rt.run.reinits = Vec::new();
        *self.rt.run.results.edit() = vec![Vec::new(); self.state.trackers.len()];
        self.rt.live.info = Some(worker::LiveInfo {
            source: source.clone(),
            ..Default::default()
        });
        self.rt.msg.errors.clear();
        self.rt.msg.progress = None;
        self.rt.msg.status = format!(
            "live: {source}; drag a box on the image (Trackers panel: Draw box) to start a tracker"
        );
        if !self.state.trackers.is_empty() {
            let tracker = self
                .state
                .selected_tracker
                .min(self.state.trackers.len() - 1);
            self.rt.ui.tool = Tool::DrawBox {
                tracker,
                start: None,
            };
        }
        self.rt.worker.send(Job::Live {
            generation: self.rt.run.generation,
            source,
            width,
            height,
        });
    }

    /// Whether a result of the worker is awaited: a propagation, a landscape, a file dialog, a
    /// live source's frames.
    fn awaiting_worker(&self) -> bool {
        let landscape = &self.rt.ui.landscape;
        self.rt.gt.running
            || self
                .rt
                .ui
                .frequency
                .as_ref()
                .is_some_and(|f| f.result.is_none())
            || self
                .rt
                .ui
                .experiment
                .as_ref()
                .is_some_and(|e| e.results.is_none())
            || self.rt.ui.dialog
            || self.is_live()
            || self.rt.seq.opening.is_some()
            || (self.state.view.show_landscape
                && landscape.requested.is_some()
                && landscape.result.as_ref().map(|r| &r.0) != landscape.requested.as_ref())
    }

    /// Starts the convergence experiment on the shown frame (see [`Command::Perturb`]).
    fn perturb(&mut self) {
        let frame = self.state.frame;
        let i = self.state.selected_tracker;
        let truth = self.ground_truth(frame);
        let base = truth.or_else(|| {
            self.rt
                .run
                .results
                .get(i)
                .and_then(|v| v.get(frame))
                .and_then(|r| r.as_ref())
                .map(|r| r.corners)
        });
        let Some(base) = base else {
            self.error(format!(
                "nothing to perturb on frame {}: give it ground truth or track it first",
                frame + 1
            ));
            return;
        };
        let mut trackers = Vec::new();
        for (k, t) in self
            .state
            .trackers
            .iter()
            .enumerate()
            .filter(|(_, t)| t.enabled)
        {
            let from = self.tracker_start(k);
            if let Some(q) = self.init_quad(&t.init, from) {
                trackers.push((k, t.spec.clone(), from, q));
            }
        }
        if trackers.is_empty() {
            self.error("no tracker to run the experiment: initialise one first".into());
            return;
        }
        let sigma = self.rt.ui.perturb_sigma;
        let n = self.rt.ui.perturbations;
        self.rt.ui.perturbations += 1;
        let start = crate::converge::perturbed(&base, sigma, 0, n as usize);
        let key = self.rt.ui.experiment.as_ref().map_or(0, |e| e.key) + 1;
        self.rt.ui.experiment = Some(runtime::Experiment {
            key,
            frame,
            start,
            sigma,
            from_truth: truth.is_some(),
            number: n + 1,
            results: None,
        });
        self.rt.ui.selected_iteration = None;
        self.rt.msg.status = format!("experiment: start {} at σ {sigma} px…", n + 1);
        self.rt
            .worker
            .send(Job::Experiment(Box::new(worker::ExperimentJob {
                key,
                frame,
                start,
                trackers,
            })));
    }

    /// Runs the frequency of convergence of every enabled registration tracker on the shown
    /// frame, around its ground truth, on a thread of its own (see [`Command::ConvergenceFrequency`]).
    fn convergence_frequency(&mut self, starts: usize) {
        let frame = self.state.frame;
        let starts = starts.clamp(1, 1000);
        self.rt.ui.frequency_starts = starts;
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        let Some(truth) = self.ground_truth(frame) else {
            self.error(format!(
                "the frequency of convergence needs ground truth on frame {}",
                frame + 1
            ));
            return;
        };
        let trackers: Vec<(usize, crate::tracker::TrackerSpec)> = self
            .state
            .trackers
            .iter()
            .enumerate()
            .filter(|(_, t)| t.enabled && t.spec.registration().is_some())
            .map(|(i, t)| (i, t.spec.clone()))
            .collect();
        if trackers.is_empty() {
            self.error("no enabled registration tracker to run".into());
            return;
        }
        if self
            .rt
            .ui
            .frequency
            .as_ref()
            .is_some_and(|f| f.result.is_none())
        {
            self.rt.msg.status = "the frequency of convergence is running".into();
            return;
        }
        self.rt.ui.frequency = Some(runtime::Frequency {
            frame,
            starts,
            result: None,
        });
        self.rt.msg.status = format!(
            "frequency of convergence on frame {}: {} tracker(s) x 10 noise levels x {starts} starts…",
            frame + 1,
            trackers.len()
        );
        let spawned = self.rt.worker.spawn_task("convergence", move || {
            let run = || -> crate::Result<Vec<(usize, crate::converge::ConvergeCurve)>> {
                let img = seq.load_gray(frame)?;
                let spec = crate::converge::ConvergeSpec {
                    starts,
                    ..Default::default()
                };
                trackers
                    .iter()
                    .map(|(i, t)| {
                        crate::converge::frequency_of_convergence(t, &img, &truth, &spec)
                            .map(|c| (*i, c))
                    })
                    .collect()
            };
            Reply::Frequency {
                frame,
                result: run().map_err(|e| e.to_string()),
            }
        });
        if let Err(e) = spawned {
            self.rt.ui.frequency = None;
            self.error(format!("cannot run the frequency of convergence: {e}"));
        }
    }

    /// Tracks the session's patches from the shown frame to the end on a thread of its own (see
    /// [`Command::TrackPatches`]).
    fn track_patches(&mut self) {
        let from = self.state.frame;
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        if self
            .rt
            .ui
            .patches
            .as_ref()
            .is_some_and(|p| p.result.is_none())
        {
            self.rt.msg.status = "patches are being tracked".into();
            return;
        }
        let count = self.state.patches.count.clamp(
            *crate::session::PATCH_COUNT.start(),
            *crate::session::PATCH_COUNT.end(),
        );
        let params = match self.state.patches.patch_params() {
            Ok(p) => p,
            Err(e) => return self.error(e.to_string()),
        };
        self.rt.ui.patches = Some(runtime::Patches {
            from,
            count,
            affine: params.warp == crate::patches::PatchWarp::Affine,
            half: (params.size as f64 - 1.0) / 2.0,
            result: None,
        });
        self.rt.msg.status = format!("tracking {count} patches from frame {}…", from + 1);
        let spawned = self.rt.worker.spawn_task("patches", move || {
            let seeds = crate::patches::PatchSeeds::Corners(count);
            Reply::Patches {
                from,
                result: crate::patches::track_sequence_from(
                    &seq,
                    from,
                    &params,
                    &seeds,
                    &mut |_| {},
                )
                .map_err(|e| e.to_string()),
            }
        });
        if let Err(e) = spawned {
            self.rt.ui.patches = None;
            self.error(format!("cannot track patches: {e}"));
        }
    }

    /// The patches tracked last (or being tracked).
    pub fn patches(&self) -> Option<&runtime::Patches> {
        self.rt.ui.patches.as_ref()
    }

    /// The patches' states on `frame`, with half a patch's side, when a run reached it.
    pub fn patches_on(&self, frame: usize) -> Option<(&[crate::patches::PatchState], f64)> {
        let p = self.rt.ui.patches.as_ref()?;
        let run = p.result.as_ref()?.as_ref().ok()?;
        let k = frame.checked_sub(run.first)?;
        run.frames.get(k).map(|f| (f.as_slice(), p.half))
    }

    /// The frequency of convergence run last (or running).
    pub fn frequency(&self) -> Option<&runtime::Frequency> {
        self.rt.ui.frequency.as_ref()
    }

    /// Writes the plots shown as figures (on a thread of its own; the files come back as a
    /// reply): `sr`, `errors` and, when a landscape curve is shown, `landscape`, each `.svg` and
    /// `.png`.
    fn export_plots(&mut self, dir: PathBuf) {
        use crate::report::{Axes, Curve, Figure, FigureKind};
        let name = self
            .sequence()
            .map_or("sequence".into(), |s| s.name.clone());
        let mut sr = Vec::new();
        let mut errors = Vec::new();
        let mut worst: f64 = 5.0;
        let mut last = 1.0f64;
        for (i, t) in self.state.trackers.iter().enumerate() {
            let label = t.spec.label();
            let curve = self.success_curve(i);
            if !curve.is_empty() {
                let mean = curve.iter().map(|p| p.1).sum::<f64>() / curve.len() as f64;
                sr.push(Curve {
                    name: format!("{} {label}", i + 1),
                    tracker: label.clone(),
                    mean_sr: mean,
                    points: curve,
                });
            }
            let e: Vec<(f64, f64)> = self
                .errors(i)
                .into_iter()
                .filter(|(_, e)| e.is_finite())
                .map(|(f, e)| ((f + 1) as f64, e.min(50.0)))
                .collect();
            if !e.is_empty() {
                worst = e.iter().map(|p| p.1).fold(worst, f64::max);
                last = e.iter().map(|p| p.0).fold(last, f64::max);
                let mean = e.iter().map(|p| p.1).sum::<f64>() / e.len() as f64;
                errors.push(Curve {
                    name: format!("{} {label}", i + 1),
                    tracker: label,
                    mean_sr: mean,
                    points: e,
                });
            }
        }
        sr.sort_by(|a, b| b.mean_sr.total_cmp(&a.mean_sr));
        let mut figures = Vec::new();
        if !sr.is_empty() {
            figures.push((
                "sr",
                Figure {
                    kind: FigureKind::Others,
                    stem: "sr".into(),
                    title: format!("Success rate: {name}"),
                    curves: sr,
                },
                Axes {
                    x_desc: "error threshold t (px)".into(),
                    y_desc: "success rate".into(),
                    x_range: (0.0, 20.0),
                    y_range: (0.0, 1.02),
                    legend_header: "mean SR".into(),
                },
            ));
        }
        if !errors.is_empty() {
            figures.push((
                "errors",
                Figure {
                    kind: FigureKind::Others,
                    stem: "errors".into(),
                    title: format!("Alignment error per frame: {name}"),
                    curves: errors,
                },
                Axes {
                    x_desc: "frame".into(),
                    y_desc: "alignment error (px, at most 50)".into(),
                    x_range: (1.0, last.max(2.0)),
                    y_range: (0.0, worst * 1.05),
                    legend_header: "mean px".into(),
                },
            ));
        }
        if let Some((_, Ok(l))) = &self.rt.ui.landscape.result
            && l.axes.len() == 1
        {
            let names = self.inspected_param_names();
            let axis = names.get(l.axes[0]).copied().unwrap_or("?");
            let points: Vec<(f64, f64)> = l
                .offsets
                .iter()
                .copied()
                .zip(l.values.iter().copied())
                .collect();
            let (lo, hi) = points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.1), b.max(p.1))
                });
            let r = l.offsets.last().copied().unwrap_or(1.0);
            if lo.is_finite() && hi.is_finite() {
                let pad = ((hi - lo) * 0.05).max(1e-9);
                figures.push((
                    "landscape",
                    Figure {
                        kind: FigureKind::Others,
                        stem: "landscape".into(),
                        title: format!(
                            "Cost landscape along {axis}: {name}, frame {}",
                            self.state.frame + 1
                        ),
                        curves: vec![Curve {
                            name: format!("tracker {}", self.state.selected_tracker + 1),
                            tracker: String::new(),
                            mean_sr: l.center_value,
                            points,
                        }],
                    },
                    Axes {
                        x_desc: format!("{axis} offset (px of corner motion)"),
                        y_desc: "similarity f".into(),
                        x_range: (-r, r),
                        y_range: (lo - pad, hi + pad),
                        legend_header: "f at the centre".into(),
                    },
                ));
            }
        }
        if let Some(runtime::Frequency {
            frame,
            starts,
            result: Some(Ok(curves)),
        }) = &self.rt.ui.frequency
        {
            figures.push((
                "convergence",
                Figure {
                    kind: FigureKind::Others,
                    stem: "convergence".into(),
                    title: format!(
                        "Frequency of convergence: {name}, frame {}, {starts} starts per σ",
                        frame + 1
                    ),
                    curves: curves
                        .iter()
                        .map(|(i, c)| Curve {
                            name: format!("{} {}", i + 1, c.tracker),
                            tracker: c.tracker.clone(),
                            mean_sr: c.mean(),
                            points: c.points.iter().map(|p| (p.0, p.1)).collect(),
                        })
                        .collect(),
                },
                Axes {
                    x_desc: "σ of the corner noise (px)".into(),
                    y_desc: "fraction converged (within 1 px)".into(),
                    x_range: (0.0, 10.5),
                    y_range: (0.0, 1.02),
                    legend_header: "mean".into(),
                },
            ));
        }
        if figures.is_empty() {
            self.error("nothing to export: track some frames first".into());
            return;
        }
        let spawned = self.rt.worker.spawn_task("export-plots", move || {
            let mut files = Vec::new();
            for (stem, fig, axes) in &figures {
                for ext in ["svg", "png"] {
                    let p = dir.join(format!("{stem}.{ext}"));
                    if let Err(e) = crate::report::draw_curve_figure(&p, fig, axes, (900, 560)) {
                        return Reply::Exported(Err(e.to_string()));
                    }
                    files.push(p);
                }
            }
            Reply::Exported(Ok(files))
        });
        if let Err(e) = spawned {
            self.error(format!("cannot export the plots: {e}"));
        }
    }

    /// Whether a live source runs.
    pub fn is_live(&self) -> bool {
        self.rt.live.info.is_some()
    }

    /// The corners a tracker starts from on `frame`: its own quad, or the ground truth there.
    fn init_quad(&self, init: &InitSource, frame: usize) -> Option<crate::geometry::Quad> {
        match init {
            InitSource::Quad(q) => Some(*q),
            InitSource::GroundTruth => self.ground_truth(frame),
        }
    }

    /// Re-initialises every enabled tracker on `frame` and shows it.
    fn restart(&mut self, frame: usize) {
        self.restart_from(frame, false);
    }

    /// Re-initialises every enabled tracker on `frame` and shows it; with `keep_before`, the
    /// results on the frames before it stay (the plots keep them; `frame` is then a
    /// re-initialisation, left out of the errors as the start frame is).
    fn restart_from(&mut self, frame: usize, keep_before: bool) {
        let n = self.frame_count();
        if n == 0 {
            return;
        }
        let frame = frame.min(n - 1);
        let keep = keep_before && frame > self.state.start_frame;
        self.rt.run.generation += 1;
        self.rt.run.playing = false;
        self.rt.run.tracked_until = None;
        self.rt.ui.selected_iteration = None;
        self.rt.ui.experiment = None;
        self.state.frame = frame;
        self.rt.run.replaying = None;
        let count = self.state.trackers.len();
        if keep {
            self.rt.run.starts.resize(count, self.state.start_frame);
            self.rt.run.reinits.resize(count, Vec::new());
            for (i, r) in self.rt.run.reinits.iter_mut().enumerate() {
                if self.rt.run.starts[i] < frame {
                    r.retain(|&f| f < frame);
                    r.push(frame);
                } else {
                    self.rt.run.starts[i] = frame;
                    r.clear();
                }
            }
        } else {
            self.state.start_frame = frame;
            self.rt.run.starts = vec![frame; count];
            self.rt.run.reinits = vec![Vec::new(); count];
        }
        let results = self.rt.run.results.edit();
        results.resize(count, Vec::new());
        for r in results {
            r.truncate(if keep { frame } else { 0 });
        }
        let mut specs = Vec::new();
        let mut missing = Vec::new();
        for (i, t) in self
            .state
            .trackers
            .iter()
            .enumerate()
            .filter(|(_, t)| t.enabled)
        {
            match self.init_quad(&t.init, frame) {
                Some(q) => specs.push((i, t.spec.clone(), q)),
                None => missing.push(i + 1),
            }
        }
        if !missing.is_empty() {
            self.error(format!(
                "no ground truth on frame {}: draw a quad or a box for tracker(s) {:?}",
                frame + 1,
                missing
            ));
        }
        self.rt.worker.send(Job::Start {
            generation: self.rt.run.generation,
            frame,
            trackers: specs,
        });
    }

    /// Re-runs tracker `i` alone, from its start frame up to the frame the others reached; the
    /// view stays on its frame.
    fn rerun_tracker(&mut self, i: usize) {
        let n = self.frame_count();
        if n == 0 {
            return;
        }
        let Some(t) = self.state.trackers.get(i).cloned() else {
            return;
        };
        if self.rt.run.playing {
            self.rt.run.playing = false;
            self.rt.worker.stop();
        }
        self.rt
            .run
            .starts
            .resize(self.state.trackers.len(), self.state.start_frame);
        let results = self.rt.run.results.edit();
        results.resize(self.state.trackers.len(), Vec::new());
        results[i].clear();
        // It runs straight through from its start: no re-initialisation on the way.
        if let Some(r) = self.rt.run.reinits.get_mut(i) {
            r.clear();
        }
        let from = self.rt.run.starts[i].min(n - 1);
        let until = self.rt.run.tracked_until.unwrap_or(from).max(from);
        let tracker = if t.enabled {
            match self.init_quad(&t.init, from) {
                Some(q) => Some(Box::new((t.spec.clone(), q))),
                None => {
                    self.error(format!(
                        "no ground truth on frame {}: draw a quad or a box for tracker {}",
                        from + 1,
                        i + 1
                    ));
                    None
                }
            }
        } else {
            None
        };
        self.rt.worker.send(Job::Rerun {
            generation: self.rt.run.generation,
            index: i,
            tracker,
            from,
            until,
        });
    }

    /// Plays back stored results (Play on a frame the trackers already passed): the shown frame
    /// advances at the playback speed (30 fps when "as fast as the trackers go"), and tracking
    /// goes on from the last tracked frame.
    fn replay(&mut self, ctx: &egui::Context) {
        let Some(last) = self.rt.run.replaying else {
            return;
        };
        ctx.request_repaint();
        let fps = if self.state.playback_fps > 0.0 {
            self.state.playback_fps
        } else {
            30.0
        };
        if last.elapsed().as_secs_f32() < 1.0 / fps
            || self.rt.display.texture_frame != Some(self.state.frame)
        {
            return;
        }
        let until = self.rt.run.tracked_until.unwrap_or(0);
        if self.state.frame < until {
            self.state.frame += 1;
            self.rt.ui.selected_iteration = None;
            self.rt.run.replaying = Some(std::time::Instant::now());
        } else {
            self.rt.run.replaying = None;
            if until + 1 < self.frame_count() {
                self.send(Command::Play);
            } else {
                self.rt.msg.status = "end of the sequence".into();
            }
        }
    }

    /// Asks the worker for the cost landscape of the inspected tracker on the shown frame when
    /// the view is open and what it shows changed.
    fn request_landscape(&mut self) {
        if !self.state.view.show_landscape {
            return;
        }
        let (i, frame) = (self.state.selected_tracker, self.state.frame);
        let Some(t) = self.state.trackers.get(i).cloned() else {
            return;
        };
        let start = self.tracker_start(i);
        let Some(r) = self.result(i, frame) else {
            return;
        };
        let estimate = r.corners;
        let init = self.init_quad(&t.init, start);
        let at = if self.state.view.landscape.around_truth {
            self.ground_truth(frame)
        } else {
            Some(estimate)
        };
        let (Some(init), Some(at)) = (init, at) else {
            return;
        };
        let v = &self.state.view.landscape;
        let mut axes = vec![v.x];
        axes.extend(v.y.filter(|&y| y != v.x));
        let sweep = crate::landscape::LandscapeSpec {
            steps: if axes.len() == 1 { 81 } else { 41 },
            axes,
            radius: v.radius,
        };
        let key = format!("{:?}|{start}|{init}|{frame}|{at}|{sweep:?}", t.spec);
        if self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()) {
            return;
        }
        self.rt.ui.landscape.requested = Some(key.clone());
        self.rt
            .worker
            .send(Job::Landscape(Box::new(worker::LandscapeJob {
                key,
                spec: t.spec,
                start,
                init,
                frame,
                at,
                sweep,
            })));
    }

    /// Handles the worker's replies.
    fn poll_worker(&mut self) {
        for r in self.rt.worker.poll() {
            match r {
                Reply::Progress(what, d, t) => {
                    self.rt.msg.progress = (!what.is_empty()).then_some((what, d, t))
                }
                // A sequence opened before a live source replaced it (the worker closed it).
                Reply::Opened(_) if self.is_live() => self.rt.msg.progress = None,
                Reply::Opened(seq) => {
                    self.rt.msg.progress = None;
                    // A new sequence (not a session's): nothing of the old one's frames carries
                    // over. (Reset only now: a failed open leaves the shown sequence as it was.)
                    if std::mem::take(&mut self.rt.seq.fresh) {
                        self.state.start_frame = 0;
                        self.state.frame = 0;
                        for t in &mut self.state.trackers {
                            t.init = InitSource::GroundTruth;
                        }
                    }
                    self.rt.msg.status = format!("{}: {} frames", seq.name, seq.len());
                    let start = self.state.start_frame.min(seq.len() - 1);
                    if let Some(src) = self.rt.seq.opening.take() {
                        if let SequenceSource::Path(p) = &src {
                            self.add_recent(&p.clone());
                        }
                        self.state.sequence = src;
                    }
                    // Errors of an earlier attempt are stale now.
                    self.rt.msg.errors.clear();
                    self.rt.seq.bad_frame = None;
                    if let Some(w) = seq.warnings.first() {
                        self.error(format!(
                            "{w}{}",
                            match seq.warnings.len() {
                                1 => String::new(),
                                n => format!(" (and {} more such lines)", n - 1),
                            }
                        ));
                    }
                    self.open_corrections(&seq);
                    let restore = self.rt.seq.restore_frame.take();
                    let n = seq.len();
                    self.rt.seq.sequence = Some(seq);
                    self.rt.display.texture_frame = None;
                    self.restart(start);
                    // A session's saved frame: track up to it.
                    if let Some(f) = restore.map(|f| f.min(n - 1)).filter(|&f| f > start)
                        && self.rt.screenshot.is_none()
                    {
                        self.rt.run.playing = true;
                        self.rt.worker.send(Job::Advance {
                            generation: self.rt.run.generation,
                            frames: Some(f - start),
                            fps: 0.0,
                        });
                    }
                }
                Reply::Image(img) => {
                    if self
                        .rt
                        .seq
                        .bad_frame
                        .as_ref()
                        .is_some_and(|b| b.0 == img.index)
                    {
                        self.rt.seq.bad_frame = None;
                    }
                    if img.index == self.state.frame {
                        self.rt.display.pending_image = Some(img);
                    }
                }
                Reply::Frame {
                    generation,
                    frame,
                    results,
                    image,
                    catch_up,
                } => {
                    if generation != self.rt.run.generation {
                        continue;
                    }
                    let stored = self.rt.run.results.edit();
                    for r in results {
                        if let Some(v) = stored.get_mut(r.tracker) {
                            if v.len() <= frame {
                                v.resize(frame + 1, None);
                            }
                            // Samples and particles are kept for the newest frame only, the
                            // iterations' patches for the newest PATCH_FRAMES (memory stays
                            // bounded on long sequences).
                            if let Some(Some(prev)) =
                                frame.checked_sub(1).and_then(|p| v.get_mut(p))
                            {
                                prev.visual = None;
                            }
                            if let Some(Some(old)) =
                                frame.checked_sub(PATCH_FRAMES).and_then(|p| v.get_mut(p))
                            {
                                for it in &mut old.iterations {
                                    it.patch = Vec::new();
                                }
                            }
                            v[frame] = Some(r);
                        }
                    }
                    if catch_up {
                        // One tracker re-run over frames the others reached: the view stays.
                        continue;
                    }
                    self.rt.run.tracked_until = Some(frame);
                    // Live, the image holds while a box or a quad is being drawn on it (the
                    // tracker then starts on the frame it was drawn on).
                    if self.is_live() && self.drawing() {
                        continue;
                    }
                    // Follow the trackers while they run.
                    self.state.frame = frame;
                    if std::mem::take(&mut self.rt.run.play_after_start) {
                        self.send(Command::Play);
                    }
                    if let Some(img) = image {
                        self.rt.display.pending_image = Some(img);
                    }
                }
                Reply::Stopped { generation, .. } => {
                    if generation == self.rt.run.generation {
                        self.rt.run.playing = false;
                    }
                }
                Reply::Error { context, error } => {
                    self.rt.msg.progress = None;
                    self.rt.seq.opening = None;
                    self.rt.seq.fresh = false;
                    self.error(format!("{context}: {error}"));
                }
                Reply::Landscape { key, result } => {
                    if self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()) {
                        self.rt.ui.landscape.result =
                            Some((key, result.map_err(|e| e.to_string())));
                    }
                }
                Reply::FrameError { index, error } => {
                    self.rt.msg.progress = None;
                    let message = error.to_string();
                    self.error(format!("frame {}: {message}", index + 1));
                    self.rt.seq.bad_frame = Some((index, message));
                }
                Reply::Proposal { label, result } => self.proposal_arrived(label, result),
                Reply::Live(info) => {
                    if self.rt.live.info.is_some() {
                        self.rt.live.info = Some(info);
                    }
                }
                Reply::LiveEnded { error } => {
                    let source = self.rt.live.info.take().map(|i| i.source);
                    if error.is_some() {
                        self.rt.msg.status = "the live source stopped".into();
                    }
                    match error {
                        Some(e) => self.error(match &self.rt.live.last_recording {
                            Some((p, n)) if source.is_some() => {
                                format!("{e}; the recording of {n} frames is kept: {}", p.display())
                            }
                            _ => e,
                        }),
                        None => {
                            if let Some(s) = source {
                                self.rt.msg.status = format!("live source {s} closed");
                            }
                        }
                    }
                }
                Reply::Experiment { key, results } => {
                    if let Some(e) = self.rt.ui.experiment.as_mut()
                        && e.key == key
                    {
                        let converged: Vec<String> = results
                            .iter()
                            .map(|r| {
                                format!(
                                    "tracker {}: {} iterations",
                                    r.tracker + 1,
                                    r.iterations.len()
                                )
                            })
                            .collect();
                        e.results = Some(results);
                        self.rt.ui.selected_iteration = Some(0);
                        self.rt.msg.status = format!(
                            "experiment, start {} (σ {} px): {}; step with . and , (Esc clears)",
                            e.number,
                            e.sigma,
                            converged.join(", ")
                        );
                    }
                }
                Reply::Patches { from, result } => {
                    if let Some(p) = self.rt.ui.patches.as_mut().filter(|p| p.from == from) {
                        match result {
                            Ok(run) => {
                                let last = run
                                    .frames
                                    .last()
                                    .map_or(0, |f| f.iter().filter(|s| s.tracking()).count());
                                self.rt.msg.status = format!(
                                    "{} patches tracked from frame {} over {} frames ({:.0} frames/s); {} still tracking at the end",
                                    run.patches(),
                                    from + 1,
                                    run.frames.len(),
                                    run.frames_per_second(),
                                    last
                                );
                                p.result = Some(Ok(std::sync::Arc::new(run)));
                            }
                            Err(e) => {
                                p.result = Some(Err(e.clone()));
                                self.error(format!("tracking patches: {e}"));
                            }
                        }
                    }
                }
                Reply::Frequency { frame, result } => {
                    if let Some(f) = self.rt.ui.frequency.as_mut().filter(|f| f.frame == frame) {
                        match &result {
                            Ok(curves) => {
                                let means: Vec<String> = curves
                                    .iter()
                                    .map(|(i, c)| format!("{} {:.2}", i + 1, c.mean()))
                                    .collect();
                                self.rt.msg.status = format!(
                                    "frequency of convergence on frame {}: mean fraction {}",
                                    frame + 1,
                                    means.join(", ")
                                );
                            }
                            Err(e) => {
                                self.rt.msg.status =
                                    format!("the frequency of convergence failed: {e}")
                            }
                        }
                        f.result = Some(result);
                    }
                }
                Reply::Exported(result) => match result {
                    Ok(files) => self.rt.msg.status = format!("wrote {}", list_paths(&files)),
                    Err(e) => self.error(format!("cannot export the plots: {e}")),
                },
                Reply::RecordingEnded { path, frames } => {
                    self.rt.msg.status =
                        format!("recorded {frames} frames as a sequence: {}", path.display());
                    self.rt.live.last_recording = Some((path, frames));
                }
                Reply::Picked(path) => {
                    self.rt.ui.dialog = false;
                    match path {
                        Some(p) => self.apply(Command::OpenSequence(SequenceSource::Path(p))),
                        None => {
                            self.rt.msg.status = "no file chosen (without a desktop portal the \
                                                  dialog cannot open: type the path)"
                                .into()
                        }
                    }
                }
            }
        }
    }

    /// Uploads the newest decoded frame as the view's texture.
    fn upload(&mut self, ctx: &egui::Context) {
        if let Some(img) = self.rt.display.pending_image.take() {
            let color =
                // Frames are opaque: premultiplied is the same bytes, without a pass over them.
                egui::ColorImage::from_rgba_premultiplied([img.width, img.height], &img.rgba);
            match &mut self.rt.display.texture {
                Some(t) => t.set(color, egui::TextureOptions::LINEAR),
                None => {
                    self.rt.display.texture =
                        Some(ctx.load_texture("frame", color, egui::TextureOptions::LINEAR))
                }
            }
            self.rt.display.image_size = [img.width, img.height];
            self.rt.display.texture_frame = Some(img.index);
            // The gray frame, for the ground-truth mode's patch view (only in that mode: it costs
            // a pass over the frame).
            if self.rt.ui.tool == Tool::EditGroundTruth {
                let gray: Vec<f32> = img
                    .rgba
                    .chunks_exact(4)
                    .map(|p| crate::imaging::luma(p[0], p[1], p[2]) as f32)
                    .collect();
                self.rt.gt.frame_image =
                    crate::imaging::GrayF32::from_vec(img.width, img.height, gray)
                        .map(|g| (img.index, g));
            }
        }
        if self.rt.display.texture_frame != Some(self.state.frame)
            && self.rt.seq.sequence.is_some()
            && !self.rt.run.playing
        {
            self.rt.display.texture_frame = Some(self.state.frame);
            self.rt.worker.send(Job::Show(self.state.frame));
        }
    }

    /// Draws the whole window into `ui` (used by eframe and by the UI tests).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let built = std::time::Instant::now();
        let ctx = ui.ctx().clone();
        self.poll_worker();
        self.upload(&ctx);
        self.gt_keys(&ctx);
        self.global_keys(&ctx);
        self.handle_dropped_files(&ctx);
        // The panels read the app and push commands; they are applied once all are drawn.
        let mut out = panels::Commands::new();
        panels::top_bar(self, ui, &mut out);
        panels::playback_bar(self, ui, &mut out);
        panels::sidebar(self, ui, &mut out);
        panels::plots_panel(self, ui, &mut out);
        let transform = egui::CentralPanel::default()
            .show(ui, |ui| {
                if self.rt.ui.tool == Tool::EditGroundTruth && self.rt.seq.sequence.is_some() {
                    egui::Panel::bottom("gt_strip").show(ui, |ui| {
                        panels::timeline(self, ui, &mut out);
                        panels::gt_strip(self, ui)
                    });
                }
                panels::frame_view(self, ui, &mut out)
            })
            .inner;
        if transform.is_some() {
            self.rt.display.transform = transform;
        }
        self.rt.commands.extend(out);
        self.apply_pending();
        // Once the pointer is released and no value is being typed (typing "50" re-runs at 50,
        // not at 5 first).
        if !self.rt.run.rerun_due.is_empty()
            && !ctx.input(|i| i.pointer.any_down())
            && !ctx.egui_wants_keyboard_input()
        {
            for i in std::mem::take(&mut self.rt.run.rerun_due) {
                self.rerun_tracker(i);
            }
        }
        self.replay(&ctx);
        if !self.rt.run.playing {
            self.request_landscape();
        }
        if self.rt.ui.show_help {
            window::help_window(&ctx, &mut self.rt.ui.show_help);
        }
        if let Some(p) = self.rt.ui.confirm_overwrite.clone()
            && let Some(yes) = window::overwrite_window(&ctx, &p)
        {
            self.apply(Command::ConfirmOverwrite(yes));
        }
        self.screenshot(&ctx);
        if self.rt.run.playing || self.rt.msg.progress.is_some() {
            ctx.request_repaint();
        } else if self.awaiting_worker() {
            // Every reply requests a repaint; this is the safety net should a request made
            // while a frame is being built be folded into it (a result then waited for the
            // next mouse move).
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
        if self.rt.run.playing {
            let dt = ctx.input(|i| i.unstable_dt);
            if self.rt.frame_times.len() >= 10_000 {
                self.rt.frame_times.remove(0);
            }
            self.rt
                .frame_times
                .push((dt, built.elapsed().as_secs_f32()));
        }
    }

    /// The shortcuts of the whole window (when no text field has the keyboard).
    fn global_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let gt_mode = self.rt.ui.tool == Tool::EditGroundTruth;
        let (frame, n) = (self.state.frame, self.frame_count());
        let mut cmds = Vec::new();
        let mut dialog = false;
        ctx.input(|i| {
            if i.key_pressed(egui::Key::F1) || i.key_pressed(egui::Key::Questionmark) {
                self.rt.ui.show_help = !self.rt.ui.show_help;
            }
            if i.key_pressed(egui::Key::Escape) {
                self.rt.ui.show_help = false;
                if self.rt.ui.confirm_overwrite.is_some() {
                    cmds.push(Command::ConfirmOverwrite(false));
                }
            }
            if i.key_pressed(egui::Key::F2) || i.key_pressed(egui::Key::F3) {
                let mut view = self.state.view.clone();
                if i.key_pressed(egui::Key::F2) {
                    view.show_trackers_panel = !view.show_trackers_panel;
                } else {
                    view.show_plots_panel = !view.show_plots_panel;
                }
                cmds.push(Command::SetView(view));
            }
            if shortcut(i, egui::Key::S).is_some() {
                cmds.push(Command::SaveSession(PathBuf::from(
                    self.rt.ui.session_path.trim(),
                )));
            }
            if shortcut(i, egui::Key::O).is_some() {
                dialog = true;
            }
            if i.modifiers.command || n == 0 || self.is_live() {
                return;
            }
            if i.key_pressed(egui::Key::Space) {
                cmds.push(if self.rt.run.playing || self.rt.run.replaying.is_some() {
                    Command::Pause
                } else {
                    Command::Play
                });
            }
            if !gt_mode {
                if i.key_pressed(egui::Key::P) {
                    cmds.push(Command::Perturb);
                }
                let shown = self.result(self.state.selected_tracker, frame);
                let n_it = shown.map_or(0, |r| r.iterations.len());
                let sel = self.rt.ui.selected_iteration;
                if i.key_pressed(egui::Key::Period) && n_it > 0 {
                    cmds.push(Command::SelectIteration(Some(
                        sel.map_or(0, |k| (k + 1).min(n_it - 1)),
                    )));
                }
                if i.key_pressed(egui::Key::Comma) && n_it > 0 {
                    cmds.push(Command::SelectIteration(Some(
                        sel.map_or(0, |k| k.saturating_sub(1)),
                    )));
                }
                if i.key_pressed(egui::Key::Escape) && self.rt.ui.experiment.is_some() {
                    cmds.push(Command::ClearExperiment);
                }
                if i.key_pressed(egui::Key::ArrowRight) {
                    match self.rt.run.tracked_until {
                        Some(t) if frame < t => cmds.push(Command::Seek(frame + 1)),
                        _ if frame + 1 < n => cmds.push(Command::Step),
                        _ => {}
                    }
                }
                let back = i.num_presses(egui::Key::ArrowLeft);
                if back > 0 && frame > 0 {
                    cmds.push(Command::Seek(frame.saturating_sub(back)));
                }
            }
            if i.key_pressed(egui::Key::Home) {
                cmds.push(Command::Seek(self.state.start_frame));
            }
            if i.key_pressed(egui::Key::End) {
                cmds.push(Command::Seek(self.rt.run.tracked_until.unwrap_or(frame)));
            }
        });
        if dialog {
            cmds.push(Command::OpenDialog { folder: false });
        }
        for c in cmds {
            self.send(c);
        }
    }

    /// Opens a file dialog on a thread of its own (the window keeps drawing meanwhile); the
    /// path comes back as a worker reply.
    fn open_dialog(&mut self, folder: bool) {
        if self.rt.ui.dialog {
            return;
        }
        let spawned = self.rt.worker.spawn_task("file-dialog", move || {
            let d = rfd::FileDialog::new();
            Reply::Picked(if folder {
                d.pick_folder()
            } else {
                let mut exts = vec!["txt"];
                exts.extend_from_slice(crate::dataset::video::VIDEO_EXTENSIONS);
                d.add_filter("ground truth or video", &exts)
                    .add_filter("ground truth", &["txt"])
                    .add_filter("video", crate::dataset::video::VIDEO_EXTENSIONS)
                    .pick_file()
            })
        });
        match spawned {
            Ok(()) => self.rt.ui.dialog = true,
            Err(e) => self.error(format!(
                "cannot open a file dialog ({e}): type the path instead"
            )),
        }
    }

    fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if let Some(p) = dropped.into_iter().next() {
            self.send(Command::OpenSequence(SequenceSource::Path(p)));
        }
    }
}

/// Paths for a status line, comma-separated.
fn list_paths(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// `Ctrl` (`Cmd` on macOS) + `key` pressed this frame, with the modifiers held *at that press*
/// (a quick Ctrl+Z can press and release Ctrl within one frame, so the frame's modifiers miss it).
fn shortcut(i: &egui::InputState, key: egui::Key) -> Option<egui::Modifiers> {
    i.events.iter().find_map(|e| match e {
        egui::Event::Key {
            key: k,
            pressed: true,
            modifiers,
            ..
        } if *k == key && modifiers.command => Some(*modifiers),
        _ => None,
    })
}

/// Per tracker, the iterations' patches are kept for this many of the newest tracked frames.
pub const PATCH_FRAMES: usize = 300;

pub use crate::keys::SHORTCUTS;
