//! Commands: the panels never change the model; they push [`Command`]s that [`InspectorApp::apply`]
//! carries out, in one place, after the frame's UI is built.

use super::state::{InitSource, PALETTE, SequenceSource, State, TrackerEntry};
use super::worker::Job;
use super::{InspectorApp, Tool};
use crate::geometry::Quad;
use crate::ssm;
use std::path::PathBuf;

/// Everything the user can do.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    OpenSequence(SequenceSource),
    AddTracker,
    RemoveTracker(usize),
    /// Replace a tracker's settings (methods, parameters, colour, enabled).
    SetTracker(usize, Box<TrackerEntry>),
    Play,
    Pause,
    /// Track one more frame.
    Step,
    /// Show a frame.
    Seek(usize),
    SetPlaybackFps(f32),
    /// Re-initialise every enabled tracker on a frame and track from there.
    RerunFrom(usize),
    /// Initialise one tracker from the given source on the current frame (and re-run).
    InitTracker(usize, InitSource),
    SelectTracker(usize),
    SelectIteration(Option<usize>),
    SetTool(Tool),
    SetView(super::state::View),
    /// Opens or closes the cost-landscape view.
    ShowLandscape(bool),
    /// Show the cost landscape in a window of its own (`true`) or back in the panel.
    EnlargeLandscape(bool),
    /// What the cost-landscape view sweeps.
    SetLandscape(super::LandscapeSettings),
    /// Show (and correct) the ground truth projected on this SSM.
    SetGtSsm(String),
    /// An action of the ground-truth mode.
    Gt(GtCommand),
    /// A file dialog for a sequence: a folder of frames, or a ground-truth file.
    OpenDialog {
        folder: bool,
    },
    /// The session file *Save session* writes and *Load session* reads.
    SetSessionPath(String),
    /// Save the session; over an existing file other than the session's own, only after
    /// [`Command::ConfirmOverwrite`].
    SaveSession(PathBuf),
    /// The answer to "overwrite?": save (`true`) or keep the file (`false`).
    ConfirmOverwrite(bool),
    LoadSession(PathBuf),
    DismissError(usize),
    /// Show an error message.
    ReportError(String),
    /// Open a live source: `/dev/videoN` (V4L2) or `lavfi:<graph>` (an FFmpeg test source),
    /// at `width x height`.
    OpenCamera {
        source: String,
        width: usize,
        height: usize,
    },
    /// Close the live source.
    StopCamera,
    /// Start (`true`) or stop recording the live frames with the selected tracker's corners.
    Record(bool),
    /// The folder recordings go to.
    SetRecordFolder(String),
    /// The convergence experiment: start every enabled tracker on the shown frame from the
    /// ground truth (else the inspected tracker's corners) moved by Gaussian noise of the
    /// experiment's sigma (seeded: each press the next start).
    Perturb,
    SetPerturbSigma(f64),
    /// The frequency of convergence on the shown frame: every enabled tracker started this
    /// many times at each noise level 1..10 px around the ground truth (see
    /// [`crate::converge`]); the plot shows the fraction that converges.
    ConvergenceFrequency(usize),
    /// Track the session's patches ([`crate::session::PatchSettings`]: that many Shi-Tomasi
    /// corners, inside the ground truth when the frame has one, with those parameters) from the
    /// shown frame to the end of the sequence, on a task thread; the frame view draws them.
    TrackPatches,
    /// The session's many-patch settings.
    SetPatchSettings(crate::session::PatchSettings),
    ClearPatches,
    ClearExperiment,
    /// Write the plots shown (success rates, errors per frame, a landscape curve) as SVG and
    /// PNG into the folder, with `report`'s figure code.
    ExportPlots(PathBuf),
    /// Show a folder in the desktop's file manager (where the plots went).
    OpenFolder(PathBuf),
    /// A side panel was resized to this share of the window: kept between runs.
    KeepPanelShare(String, f32),
}

/// The actions of the ground-truth mode ([`Command::Gt`]).
#[derive(Clone, Debug, PartialEq)]
pub enum GtCommand {
    /// A ground-truth drag in progress (drawn, not yet an edit).
    Drag {
        frame: usize,
        quad: Quad,
    },
    /// One ground-truth edit: the quad, refitted on the shown SSM.
    Commit {
        frame: usize,
        quad: Quad,
        label: String,
    },
    /// The corner the keyboard moves (`None`: the whole quad).
    PickCorner(Option<usize>),
    /// Moves the picked corner (or the quad) of the shown frame by this many pixels.
    Nudge {
        dx: f64,
        dy: f64,
    },
    /// The nudge step (px).
    Step(f64),
    /// Marks the shown frame occluded / not annotatable, or unmarks it.
    ToggleOccluded,
    /// The shown frame back to its original ground truth.
    Revert,
    Undo,
    Redo,
    /// Writes the corrected ground truth (own format and OptGT).
    Export,
    /// Seek to the uncorrected frame that most needs a look.
    JumpWorst,
    /// Interpolates between the corrected key frames around the shown frame.
    Interpolate,
    /// Tracks forward from the shown frame to propose corrections.
    Propagate,
    AcceptProposal,
    RejectProposal,
    /// The timeline's selected frame range (inclusive), or none.
    Select(Option<(usize, usize)>),
    /// Accepts the proposal's frames inside the selection only (the rest stays proposed).
    AcceptProposalInSelection,
    /// Deletes the corrections of the selected frames (back to the original ground truth).
    RevertSelection,
    /// Interpolates the frames inside the selection between its first and last frame's ground
    /// truth (corrected or not), in the shown SSM's parameters.
    InterpolateSelection,
    /// Propagates from the selection's first frame to its last (and no further), the old
    /// ground truth agreeing on the way not stopping it.
    PropagateSelection,
}

impl InspectorApp {
    /// Applies the queued commands.
    pub fn apply_pending(&mut self) {
        let cmds = std::mem::take(&mut self.rt.commands);
        for c in cmds {
            self.apply(c);
        }
    }

    /// The one handler of every command: each arm a call to what carries it out, by concern
    /// (sessions and sources in `sources.rs`, runs in `runs.rs`, experiments in
    /// `experiments.rs`, the ground truth in `gt_edit.rs`, the trackers and the view here).
    pub fn apply(&mut self, cmd: Command) {
        if self.refused_live(&cmd) {
            return;
        }
        match cmd {
            Command::OpenSequence(src) => {
                // The frames reset once it opened (a failed open changes nothing).
                self.rt.seq.fresh = true;
                self.open(src)
            }
            Command::AddTracker => self.add_tracker(),
            Command::RemoveTracker(i) => self.remove_tracker(i),
            Command::SetTracker(i, entry) => self.set_tracker(i, *entry),
            Command::Play => self.play(),
            Command::Pause => self.pause(),
            Command::Step => self.rt.worker.send(Job::Advance {
                generation: self.rt.run.generation,
                frames: Some(1),
                fps: 0.0,
            }),
            Command::Seek(i) => self.seek(i),
            Command::SetPlaybackFps(f) => self.set_playback_fps(f),
            Command::RerunFrom(f) => {
                // Re-tracking from here, and playing on; the results before stay.
                self.restart_from(f, true);
                self.rt.run.play_after_start = true;
            }
            Command::InitTracker(i, init) => self.init_tracker(i, init),
            Command::SelectTracker(i) => self.state.selected_tracker = i,
            Command::SelectIteration(it) => self.rt.ui.selected_iteration = it,
            Command::SetTool(t) => self.set_tool(t),
            Command::SetView(v) => self.state.view = v,
            Command::ShowLandscape(open) => self.state.view.show_landscape = open,
            Command::EnlargeLandscape(big) => self.rt.ui.landscape.enlarged = big,
            Command::SetLandscape(s) => self.state.view.landscape = s,
            Command::SetGtSsm(name) => match ssm::build(&name) {
                Ok(m) => self.state.gt_ssm = m.name().to_string(),
                Err(e) => self.error(e.to_string()),
            },
            Command::Gt(c) => self.apply_gt(c),
            Command::OpenDialog { folder } => self.open_dialog(folder),
            Command::SetSessionPath(p) => self.rt.ui.session_path = p,
            Command::SaveSession(p) => self.save_session(p, false),
            Command::ConfirmOverwrite(yes) => self.confirm_overwrite(yes),
            Command::LoadSession(p) => self.load_session(p),
            Command::ReportError(e) => self.error(e),
            Command::OpenCamera {
                source,
                width,
                height,
            } => self.open_live(source, width, height),
            Command::StopCamera => self.rt.worker.send(Job::StopLive),
            Command::Record(on) => self.record(on),
            Command::SetRecordFolder(f) => self.rt.live.record_folder = f,
            Command::Perturb => self.perturb(),
            Command::SetPerturbSigma(s) => self.rt.ui.perturb_sigma = s.clamp(0.0, 100.0),
            Command::ExportPlots(dir) => self.export_plots(dir),
            Command::OpenFolder(dir) => self.open_folder(&dir),
            Command::KeepPanelShare(name, share) => {
                self.rt.ui.prefs.panels.insert(name, share);
                self.save_prefs();
            }
            Command::ConvergenceFrequency(starts) => self.convergence_frequency(starts),
            Command::TrackPatches => self.track_patches(),
            Command::SetPatchSettings(p) => self.state.patches = p,
            Command::ClearPatches => self.rt.ui.patches = None,
            Command::ClearExperiment => {
                self.rt.ui.experiment = None;
                self.rt.ui.selected_iteration = None;
            }
            Command::DismissError(i) => {
                if i < self.rt.msg.errors.len() {
                    self.rt.msg.errors.remove(i);
                }
            }
        }
    }

    /// Live, the frames come from the source: playing and stepping are refused, with why.
    fn refused_live(&mut self, cmd: &Command) -> bool {
        let refused = self.is_live()
            && matches!(
                cmd,
                Command::Play | Command::Step | Command::RerunFrom(_) | Command::Pause
            );
        if refused {
            self.rt.msg.status =
                "live: the frames come from the source (Stop camera, then open the recording \
                 to step through it)"
                    .into();
        }
        refused
    }

    /// A new tracker, a copy of the last one, started from the ground truth; it alone runs up
    /// to where the others are.
    fn add_tracker(&mut self) {
        let n = self.state.trackers.len();
        let mut entry = self
            .state
            .trackers
            .last()
            .cloned()
            .unwrap_or_else(|| State::default().trackers[0].clone());
        entry.color = PALETTE[n % PALETTE.len()];
        entry.init = InitSource::GroundTruth;
        self.rt.msg.status = format!(
            "tracker {} added: a copy of tracker {n} (pick its methods in its panel)",
            n + 1
        );
        self.state.trackers.push(entry);
        self.rt.run.results.edit().push(Vec::new());
        self.rt.run.starts.push(self.state.start_frame);
        self.rerun_tracker(n);
    }

    fn remove_tracker(&mut self, i: usize) {
        if i >= self.state.trackers.len() {
            return;
        }
        self.state.trackers.remove(i);
        if i < self.rt.run.results.len() {
            self.rt.run.results.edit().remove(i);
        }
        if i < self.rt.run.starts.len() {
            self.rt.run.starts.remove(i);
        }
        if i < self.rt.run.reinits.len() {
            self.rt.run.reinits.remove(i);
        }
        self.rt.worker.send(Job::Remove { index: i });
        self.state.selected_tracker = self
            .state
            .selected_tracker
            .min(self.state.trackers.len().saturating_sub(1));
    }

    /// A tracker's settings changed: a new method or its enabling re-runs it (once the pointer
    /// is released, not on every drag step; the other trackers keep their results).
    fn set_tracker(&mut self, i: usize, entry: crate::session::TrackerEntry) {
        let Some(t) = self.state.trackers.get_mut(i) else {
            return;
        };
        let rerun = t.spec != entry.spec || t.enabled != entry.enabled;
        *t = entry;
        if rerun {
            match crate::tracker::Tracker::new(&t.spec) {
                Ok(_) => {
                    self.rt.run.rerun_due.insert(i);
                }
                Err(e) => self.error(format!("tracker {}: {e}", i + 1)),
            }
        }
    }

    /// Tracker `i` starts on the shown frame from `init`; the others keep their results.
    fn init_tracker(&mut self, i: usize, init: InitSource) {
        if let Some(t) = self.state.trackers.get_mut(i) {
            // Said where it happened (a "drag a box ... to start a tracker" stayed after it).
            let how = match &init {
                InitSource::GroundTruth => "the ground truth",
                _ => "the drawn corners",
            };
            self.rt.msg.status = format!(
                "tracker {} started on frame {} from {how}",
                i + 1,
                self.state.frame + 1
            );
            t.init = init;
            if let Some(s) = self.rt.run.starts.get_mut(i) {
                *s = self.state.frame;
            }
            self.rerun_tracker(i);
        }
    }

    fn set_tool(&mut self, t: Tool) {
        if t == Tool::EditGroundTruth && self.rt.ui.tool != t {
            // The ground-truth mode needs the gray frame: show the frame again.
            self.rt.display.texture_frame = None;
        }
        self.rt.ui.tool = t;
    }

    /// Ground truth of a frame as shown: corrected, else fitted on the chosen SSM; a drag in
    /// progress shows as dragged. `None` for a frame without corners (or marked occluded).
    pub fn ground_truth(&self, frame: usize) -> Option<Quad> {
        if let Some((f, q)) = self.rt.gt.drag
            && f == frame
        {
            return Some(q);
        }
        self.gt_frame(frame)?.quad()
    }
}
