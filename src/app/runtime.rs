//! The inspector's runtime state: what a session does not save, grouped by concern (the open
//! sequence, the run of the trackers, what the frame view shows, the messages, the window's
//! modes), and [`Versioned`] values whose caches follow every change.

use super::command::Command;
use super::decoder::FrameImage;
use super::gt_edit::GtRuntime;
use super::panels;
use super::state::SequenceSource;
use super::worker::{TrackerFrame, Worker};
use crate::dataset::Sequence;
use crate::geometry::Point;
use eframe::egui;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

/// What a pointer drag in the frame view does.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Tool {
    /// Drag pans, scroll zooms.
    #[default]
    Navigate,
    /// Four clicks give a tracker's initial quad (the corners clicked so far).
    DrawQuad { tracker: usize, corners: Vec<Point> },
    /// A drag gives a tracker's initial box.
    DrawBox {
        tracker: usize,
        start: Option<Point>,
    },
    /// Drag the ground-truth corners of the shown frame.
    EditGroundTruth,
}

/// What a tracker's errors depend on: generation, results' version, corrections' version,
/// ground-truth SSM, start frame.
pub(super) type ErrorsKey = (u64, u64, u64, String, usize);

/// Per tracker, its errors and what they were computed from.
pub(super) type ErrorsCache = std::cell::RefCell<BTreeMap<usize, (ErrorsKey, Vec<(usize, f64)>)>>;

/// The cost-landscape view's runtime part (what it shows and whether it is open are the
/// session's [`super::state::View`]): the request in flight, the last result.
#[derive(Default)]
pub struct LandscapeView {
    /// Shown in a window of its own.
    pub enlarged: bool,
    pub requested: Option<String>,
    pub result: Option<(String, Result<crate::landscape::Landscape, String>)>,
}

/// A value with a version that every change bumps: caches keyed by the version stay right
/// without anyone remembering to invalidate them. Reads go through `Deref`; changes through
/// [`Versioned::edit`].
#[derive(Debug, Default)]
pub struct Versioned<T> {
    pub(super) value: T,
    pub(super) version: u64,
}

impl<T> Versioned<T> {
    pub fn new(value: T) -> Self {
        Versioned { value, version: 0 }
    }
    /// The value, to change (the version moves on).
    pub fn edit(&mut self) -> &mut T {
        self.version += 1;
        &mut self.value
    }
    /// How many times the value was handed out for a change.
    pub fn version(&self) -> u64 {
        self.version
    }
}

impl<T> std::ops::Deref for Versioned<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.value
    }
}

/// The open sequence, and one being opened.
#[derive(Default)]
pub(super) struct SequenceRt {
    pub(super) sequence: Option<Arc<Sequence>>,
    /// A sequence being opened (the session points to it once it opened).
    pub(super) opening: Option<SequenceSource>,
    /// A loaded session's frame: the trackers run up to it once the sequence opened.
    pub(super) restore_frame: Option<usize>,
    /// A frame that could not be read, and why (the view shows a placeholder for it).
    pub(super) bad_frame: Option<(usize, String)>,
    /// The sequence being opened is a new one (not a session's): once it opened, the shown
    /// frame and the trackers' starts go back to its first frame.
    pub(super) fresh: bool,
}

/// The trackers' results and the run that makes them.
#[derive(Default)]
pub(super) struct RunRt {
    /// Bumped at every re-initialisation: replies of an older generation are dropped.
    pub(super) generation: u64,
    /// Per tracker, per frame.
    pub(super) results: Versioned<Vec<Vec<Option<TrackerFrame>>>>,
    /// Per tracker, the frame it was initialised on.
    pub(super) starts: Vec<usize>,
    /// Per tracker, later frames it was initialised on again (*Re-run from here*, which keeps
    /// the results before): their error is zero by construction and is not counted.
    pub(super) reinits: Vec<Vec<usize>>,
    /// The last frame the trackers reached.
    pub(super) tracked_until: Option<usize>,
    pub(super) playing: bool,
    /// Playing back stored results (not tracking): when the shown frame last advanced.
    pub(super) replaying: Option<std::time::Instant>,
    /// Play once the trackers are initialised (after *Re-run from here*).
    pub(super) play_after_start: bool,
    /// Trackers whose settings changed: each re-runs alone once the pointer is released.
    pub(super) rerun_due: std::collections::BTreeSet<usize>,
    /// Per tracker, the errors of [`InspectorApp::errors`] and what they were computed from.
    pub(super) errors_cache: ErrorsCache,
}

/// What the frame view shows: the frame's texture and where it was drawn.
#[derive(Default)]
pub(super) struct DisplayRt {
    pub(super) texture: Option<egui::TextureHandle>,
    pub(super) texture_frame: Option<usize>,
    pub(super) image_size: [usize; 2],
    pub(super) pending_image: Option<FrameImage>,
    /// The frame view's image-to-screen mapping, as last drawn.
    pub(super) transform: Option<panels::Transform>,
}

/// What the window tells the user.
#[derive(Default)]
pub(super) struct MessagesRt {
    pub(super) status: String,
    pub(super) errors: Vec<String>,
    /// The errors shown when the sequence being opened was asked for: stale once it opens
    /// (an error raised meanwhile, such as a broken session loaded after it, stays).
    pub(super) before_open: Vec<String>,
    pub(super) progress: Option<(String, usize, usize)>,
}

/// The frequency of convergence (Baker and Matthews' experiment, see [`crate::converge`]) of
/// the enabled trackers on one frame: per tracker (its index) the fraction of starts that
/// converge per noise level.
#[derive(Clone, Debug)]
pub struct Frequency {
    pub frame: usize,
    pub starts: usize,
    pub result: Option<Result<Vec<(usize, crate::converge::ConvergeCurve)>, String>>,
}

/// Many patches tracked over the open sequence from one frame (`regtrack track --patches`'s
/// run), drawn on the frames it reached.
#[derive(Clone, Debug)]
pub struct Patches {
    /// The frame they start on, how many were asked for, and their warp.
    pub from: usize,
    pub count: usize,
    pub affine: bool,
    /// Half the side of a patch (pixels).
    pub half: f64,
    pub result: Option<Result<std::sync::Arc<crate::patches::PatchRun>, String>>,
}

/// The convergence experiment shown on a frame: every enabled tracker started from the same
/// perturbed corners, its iterations to step through.
pub struct Experiment {
    /// Identifies the request in flight.
    pub key: u64,
    pub frame: usize,
    /// The perturbed start, and what was perturbed (the ground truth, or the inspected
    /// tracker's corners).
    pub start: crate::geometry::Quad,
    pub sigma: f64,
    pub from_truth: bool,
    /// Which start of the seeded sequence this is (1-based).
    pub number: u64,
    /// Per tracker, its run from the start (`None` until the worker answers).
    pub results: Option<Vec<TrackerFrame>>,
}

/// The window's modes and fields that are not part of a session.
pub(super) struct UiRt {
    pub(super) tool: Tool,
    pub(super) selected_iteration: Option<usize>,
    /// The keyboard help overlay is open.
    pub(super) show_help: bool,
    /// The cost-landscape view: its settings, the request in flight and the last result.
    pub(super) landscape: LandscapeView,
    /// The session file *Save session* writes.
    pub(super) session_path: String,
    /// The file this session was loaded from or last saved to: saving there again needs no
    /// confirmation, saving over another existing file does.
    pub(super) session_file: Option<PathBuf>,
    /// A save over an existing file that waits for the user's yes.
    pub(super) confirm_overwrite: Option<PathBuf>,
    /// The preferences kept between runs (the recent sequences), and their file (`None`: not
    /// kept, as in tests and screenshots).
    pub(super) prefs: super::prefs::Prefs,
    pub(super) prefs_path: Option<PathBuf>,
    /// A file dialog is open (its answer arrives as a reply).
    pub(super) dialog: bool,
    /// The convergence experiment, its noise (px) and how many starts were drawn.
    pub(super) experiment: Option<Experiment>,
    /// The frequency of convergence on a frame (running while its result is `None`), and the
    /// starts per noise level it runs.
    pub(super) frequency: Option<Frequency>,
    pub(super) frequency_starts: usize,
    /// Patches tracked over the sequence (running while its result is `None`).
    pub(super) patches: Option<Patches>,
    pub(super) perturb_sigma: f64,
    pub(super) perturbations: u64,
    /// The folder the plots were last exported to (absolute).
    pub(super) exported: Option<PathBuf>,
}

impl Default for UiRt {
    fn default() -> Self {
        UiRt {
            tool: Tool::Navigate,
            selected_iteration: None,
            show_help: false,
            landscape: LandscapeView::default(),
            session_path: super::prefs::default_session_path().display().to_string(),
            session_file: None,
            confirm_overwrite: None,
            prefs: Default::default(),
            prefs_path: None,
            dialog: false,
            experiment: None,
            frequency: None,
            frequency_starts: 50,
            patches: None,
            perturb_sigma: 5.0,
            perturbations: 0,
            exported: None,
        }
    }
}

/// A live source (a camera or an FFmpeg test source): shown and tracked while it runs, and
/// what it recorded.
pub(super) struct LiveRt {
    /// The running source's progress (`None`: no live source runs).
    pub(super) info: Option<super::worker::LiveInfo>,
    /// The folder recordings go to (each recording a sequence `live.txt` + `live/`, then
    /// `live_2`...).
    pub(super) record_folder: String,
    /// The last recording that ended (its ground-truth file and frames), to open.
    pub(super) last_recording: Option<(PathBuf, usize)>,
}

impl Default for LiveRt {
    fn default() -> Self {
        LiveRt {
            info: None,
            record_folder: "recordings".into(),
            last_recording: None,
        }
    }
}

/// Runtime state, never saved, grouped by concern.
pub struct Runtime {
    /// All background work: jobs out, replies in.
    pub(super) worker: Worker,
    /// Commands pushed this frame, applied after the panels are drawn.
    pub(super) commands: Vec<Command>,
    pub(super) seq: SequenceRt,
    pub(super) live: LiveRt,
    pub(super) run: RunRt,
    pub(super) display: DisplayRt,
    pub(super) msg: MessagesRt,
    pub(super) ui: UiRt,
    /// The ground-truth mode: corrections (journaled), drag, proposal, images.
    pub(super) gt: GtRuntime,
    pub(super) screenshot: Option<super::window::ScreenshotPlan>,
    /// Durations (s) of the window's frames, and of building the UI of each, while the
    /// trackers ran (the last 10 000).
    pub(super) frame_times: Vec<(f32, f32)>,
}
