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
mod gt_edit;
mod panels;
pub mod state;
pub mod worker;

use crate::dataset::Sequence;
use crate::eval;
use crate::geometry::{Point, alignment_error};
use crate::tracker::TrackStatus;
use command::Command;
use state::{InitSource, SequenceSource, State};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use worker::{FrameImage, Job, Reply, TrackerFrame, Worker};

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

/// What can stop the inspector from running (the errors of a running window are shown in it).
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error("cannot load the session: {0}")]
    Session(#[source] crate::Error),
    /// The windowing system's error, as it describes it.
    #[error("the window cannot run: {0}")]
    Window(String),
    #[error("cannot write the screenshot {}: {message}", path.display())]
    Screenshot { path: PathBuf, message: String },
    #[error("the window closed before the screenshot was taken")]
    NoScreenshot,
}

/// Where a screenshot's outcome is reported (`None` until it is taken).
/// On success, a summary of the window's frame rate while the trackers ran.
pub type ShotResult = Arc<Mutex<Option<Result<String, AppError>>>>;

/// Take a screenshot once enough frames are tracked, then close.
#[derive(Debug)]
pub struct ScreenshotPlan {
    pub frames: usize,
    pub path: PathBuf,
    started: bool,
    requested: bool,
    pub result: ShotResult,
}

/// What a tracker's errors depend on: generation, results' version, corrections' version,
/// ground-truth SSM, start frame.
type ErrorsKey = (u64, u64, u64, String, usize);

/// Per tracker, its errors and what they were computed from.
type ErrorsCache = std::cell::RefCell<BTreeMap<usize, (ErrorsKey, Vec<(usize, f64)>)>>;

/// What the cost-landscape view sweeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandscapeSettings {
    /// The swept parameters (0-based); the second is optional (a curve or a map).
    pub x: usize,
    pub y: Option<usize>,
    /// Half-width of the sweep, px of corner motion.
    pub radius: f64,
    /// Around the ground truth instead of the tracker's estimate.
    pub around_truth: bool,
}

impl Default for LandscapeSettings {
    fn default() -> Self {
        LandscapeSettings {
            x: 0,
            y: None,
            radius: 5.0,
            around_truth: false,
        }
    }
}

/// The cost-landscape view: open or not, its settings, the request in flight, the last result.
#[derive(Default)]
pub struct LandscapeView {
    pub open: bool,
    pub settings: LandscapeSettings,
    pub requested: Option<String>,
    pub result: Option<(String, Result<crate::landscape::Landscape, String>)>,
}

/// A value with a version that every change bumps: caches keyed by the version stay right
/// without anyone remembering to invalidate them. Reads go through `Deref`; changes through
/// [`Versioned::edit`].
#[derive(Debug, Default)]
pub struct Versioned<T> {
    value: T,
    version: u64,
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
struct SequenceRt {
    sequence: Option<Arc<Sequence>>,
    /// A sequence being opened (the session points to it once it opened).
    opening: Option<SequenceSource>,
    /// A loaded session's frame: the trackers run up to it once the sequence opened.
    restore_frame: Option<usize>,
    /// A frame that could not be read, and why (the view shows a placeholder for it).
    bad_frame: Option<(usize, String)>,
}

/// The trackers' results and the run that makes them.
#[derive(Default)]
struct RunRt {
    /// Bumped at every re-initialisation: replies of an older generation are dropped.
    generation: u64,
    /// Per tracker, per frame.
    results: Versioned<Vec<Vec<Option<TrackerFrame>>>>,
    /// Per tracker, the frame it was initialised on.
    starts: Vec<usize>,
    /// The last frame the trackers reached.
    tracked_until: Option<usize>,
    playing: bool,
    /// Playing back stored results (not tracking): when the shown frame last advanced.
    replaying: Option<std::time::Instant>,
    /// Play once the trackers are initialised (after *Re-run from here*).
    play_after_start: bool,
    /// Trackers whose settings changed: each re-runs alone once the pointer is released.
    rerun_due: std::collections::BTreeSet<usize>,
    /// Per tracker, the errors of [`InspectorApp::errors`] and what they were computed from.
    errors_cache: ErrorsCache,
}

/// What the frame view shows: the frame's texture and where it was drawn.
#[derive(Default)]
struct DisplayRt {
    texture: Option<egui::TextureHandle>,
    texture_frame: Option<usize>,
    image_size: [usize; 2],
    pending_image: Option<FrameImage>,
    /// The frame view's image-to-screen mapping, as last drawn.
    transform: Option<panels::Transform>,
}

/// What the window tells the user.
#[derive(Default)]
struct MessagesRt {
    status: String,
    errors: Vec<String>,
    progress: Option<(String, usize, usize)>,
}

/// The window's modes and fields that are not part of a session.
struct UiRt {
    tool: Tool,
    selected_iteration: Option<usize>,
    /// The keyboard help overlay is open.
    show_help: bool,
    /// The cost-landscape view: its settings, the request in flight and the last result.
    landscape: LandscapeView,
    /// The session file *Save session* writes.
    session_path: String,
    recent: Vec<PathBuf>,
    /// A file dialog is open (its answer arrives as a reply).
    dialog: bool,
}

impl Default for UiRt {
    fn default() -> Self {
        UiRt {
            tool: Tool::Navigate,
            selected_iteration: None,
            show_help: false,
            landscape: LandscapeView::default(),
            session_path: String::from("sessions/my_session.toml"),
            recent: Vec::new(),
            dialog: false,
        }
    }
}

/// Runtime state, never saved, grouped by concern.
pub struct Runtime {
    /// All background work: jobs out, replies in.
    worker: Worker,
    /// Commands pushed this frame, applied after the panels are drawn.
    commands: Vec<Command>,
    seq: SequenceRt,
    run: RunRt,
    display: DisplayRt,
    msg: MessagesRt,
    ui: UiRt,
    /// The ground-truth mode: corrections (journaled), drag, proposal, images.
    gt: gt_edit::GtRuntime,
    screenshot: Option<ScreenshotPlan>,
    /// Durations (s) of the window's frames, and of building the UI of each, while the
    /// trackers ran (the last 10 000).
    frame_times: Vec<(f32, f32)>,
}

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

    /// Plans a screenshot after `frames` tracked frames (the inspector then plays, captures the
    /// window to `path`, reports in `result` and closes).
    pub fn screenshot_after(&mut self, frames: usize, path: PathBuf, result: ShotResult) {
        self.rt.screenshot = Some(ScreenshotPlan {
            frames,
            path,
            started: false,
            requested: false,
            result,
        });
    }

    /// The session file the session field shows (and *Save session* writes).
    pub fn set_session_path(&mut self, p: &std::path::Path) {
        self.rt.ui.session_path = p.display().to_string();
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
        if self.rt.msg.errors.len() > 5 {
            self.rt.msg.errors.remove(0);
        }
    }

    fn open(&mut self, src: SequenceSource) {
        self.rt.run.playing = false;
        self.rt.msg.progress = Some(("opening the sequence".into(), 0, 0));
        // The session and the recent list change once it opened (a failed open changes nothing).
        self.rt.seq.opening = Some(src.clone());
        self.rt.worker.send(Job::Open(src));
    }

    /// Frames in the open sequence.
    pub fn frame_count(&self) -> usize {
        self.rt.seq.sequence.as_ref().map_or(0, |s| s.len())
    }

    /// Whether the trackers are playing.
    pub fn is_playing(&self) -> bool {
        self.rt.run.playing
    }

    /// The last frame the trackers reached.
    pub fn tracked_until(&self) -> Option<usize> {
        self.rt.run.tracked_until
    }

    /// Where an image point was drawn on screen in the last frame view.
    pub fn screen_pos(&self, p: Point) -> Option<egui::Pos2> {
        self.rt.display.transform.map(|t| t.to_screen(p))
    }

    /// The frame the view shows a "could not be read" placeholder for.
    pub fn bad_frame(&self) -> Option<usize> {
        self.rt.seq.bad_frame.as_ref().map(|b| b.0)
    }

    /// The status line.
    pub fn status(&self) -> &str {
        &self.rt.msg.status
    }

    /// Error messages shown.
    pub fn errors_shown(&self) -> &[String] {
        &self.rt.msg.errors
    }

    /// Whether corrections were made since the last export (they are in the journal either
    /// way).
    pub fn ground_truth_edited(&self) -> bool {
        self.rt.gt.corrections.unexported()
    }

    /// The open sequence.
    pub fn sequence(&self) -> Option<&Arc<Sequence>> {
        self.rt.seq.sequence.as_ref()
    }

    /// Re-initialises every enabled tracker on `frame` and shows it.
    fn restart(&mut self, frame: usize) {
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        let frame = frame.min(seq.len().saturating_sub(1));
        self.rt.run.generation += 1;
        self.rt.run.playing = false;
        self.rt.run.tracked_until = None;
        self.rt.ui.selected_iteration = None;
        self.state.start_frame = frame;
        self.state.frame = frame;
        self.rt.run.replaying = None;
        self.rt.run.starts = vec![frame; self.state.trackers.len()];
        let results = self.rt.run.results.edit();
        results.resize(self.state.trackers.len(), Vec::new());
        for r in results {
            r.clear();
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
            let quad = match &t.init {
                InitSource::Quad(q) => Some(*q),
                InitSource::GroundTruth => self.ground_truth(frame),
            };
            match quad {
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

    /// The frame tracker `t` was initialised on.
    fn tracker_start(&self, t: usize) -> usize {
        self.rt
            .run
            .starts
            .get(t)
            .copied()
            .unwrap_or(self.state.start_frame)
    }

    /// Re-runs tracker `i` alone, from its start frame up to the frame the others reached; the
    /// view stays on its frame.
    fn rerun_tracker(&mut self, i: usize) {
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
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
        let from = self.rt.run.starts[i].min(seq.len().saturating_sub(1));
        let until = self.rt.run.tracked_until.unwrap_or(from).max(from);
        let tracker = if t.enabled {
            let quad = match &t.init {
                InitSource::Quad(q) => Some(*q),
                InitSource::GroundTruth => self.ground_truth(from),
            };
            match quad {
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
        if !self.rt.ui.landscape.open {
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
        let init = match &t.init {
            state::InitSource::Quad(q) => Some(*q),
            state::InitSource::GroundTruth => self.ground_truth(start),
        };
        let at = if self.rt.ui.landscape.settings.around_truth {
            self.ground_truth(frame)
        } else {
            Some(estimate)
        };
        let (Some(init), Some(at)) = (init, at) else {
            return;
        };
        let v = &self.rt.ui.landscape.settings;
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

    /// The cost landscape shown (the last one computed) and whether it is current.
    pub fn landscape_shown(&self) -> Option<(&Result<crate::landscape::Landscape, String>, bool)> {
        let (key, r) = self.rt.ui.landscape.result.as_ref()?;
        Some((
            r,
            self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()),
        ))
    }

    /// The frames where trackers `a` and `b` disagree most: the alignment error between their
    /// corners (infinite where exactly one of them is lost), largest first.
    pub fn disagreements(&self, a: usize, b: usize) -> Vec<(usize, f64)> {
        let (Some(ra), Some(rb)) = (self.rt.run.results.get(a), self.rt.run.results.get(b)) else {
            return Vec::new();
        };
        let mut v: Vec<(usize, f64)> = ra
            .iter()
            .zip(rb)
            .enumerate()
            .filter_map(|(f, (x, y))| {
                let (x, y) = (x.as_ref()?, y.as_ref()?);
                let (lx, ly) = (
                    x.status != TrackStatus::Tracking,
                    y.status != TrackStatus::Tracking,
                );
                match (lx, ly) {
                    (false, false) => Some((f, alignment_error(&x.corners, &y.corners))),
                    (true, true) => None,
                    _ => Some((f, f64::INFINITY)),
                }
            })
            .collect();
        v.sort_by(|p, q| q.1.total_cmp(&p.1).then(p.0.cmp(&q.0)));
        v
    }

    /// Whether stored results are being played back.
    pub fn is_replaying(&self) -> bool {
        self.rt.run.replaying.is_some()
    }

    /// Handles the worker's replies.
    fn poll_worker(&mut self) {
        for r in self.rt.worker.poll() {
            match r {
                Reply::Progress(what, d, t) => {
                    self.rt.msg.progress = (!what.is_empty()).then_some((what, d, t))
                }
                Reply::Opened(seq) => {
                    self.rt.msg.progress = None;
                    self.rt.msg.status = format!("{}: {} frames", seq.name, seq.len());
                    let start = self.state.start_frame.min(seq.len() - 1);
                    if let Some(src) = self.rt.seq.opening.take() {
                        if let SequenceSource::Path(p) = &src {
                            self.rt.ui.recent.retain(|r| r != p);
                            self.rt.ui.recent.insert(0, p.clone());
                            self.rt.ui.recent.truncate(8);
                        }
                        self.state.sequence = src;
                    }
                    // Errors of an earlier attempt are stale now.
                    self.rt.msg.errors.clear();
                    self.rt.seq.bad_frame = None;
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

    /// The result of tracker `t` on `frame`.
    pub fn result(&self, t: usize, frame: usize) -> Option<&TrackerFrame> {
        self.rt.run.results.get(t)?.get(frame)?.as_ref()
    }

    /// Alignment errors of tracker `t` on the frames tracked after the start frame (lost frames
    /// are infinite), against the ground truth shown.
    pub fn errors(&self, t: usize) -> Vec<(usize, f64)> {
        let key: ErrorsKey = (
            self.rt.run.generation,
            self.rt.run.results.version(),
            self.rt.gt.corrections.version(),
            self.state.gt_ssm.clone(),
            self.state.start_frame,
        );
        if let Some((_, v)) = self
            .rt
            .run
            .errors_cache
            .borrow()
            .get(&t)
            .filter(|(k, _)| *k == key)
        {
            return v.clone();
        }
        let v = self.compute_errors(t);
        self.rt
            .run
            .errors_cache
            .borrow_mut()
            .insert(t, (key, v.clone()));
        v
    }

    fn compute_errors(&self, t: usize) -> Vec<(usize, f64)> {
        let Some(v) = self.rt.run.results.get(t) else {
            return Vec::new();
        };
        v.iter()
            .enumerate()
            .filter(|(f, r)| *f > self.tracker_start(t) && r.is_some())
            .filter_map(|(f, r)| {
                let r = r.as_ref()?;
                let gt = self.ground_truth(f)?;
                let e = if r.status == TrackStatus::Tracking {
                    alignment_error(&r.corners, &gt)
                } else {
                    f64::INFINITY
                };
                Some((f, e))
            })
            .collect()
    }

    /// Speed of tracker `t` over the frames it tracked after the start frame (with or without
    /// ground truth): `(frames, search us, update us, iterations)`.
    pub fn speed(&self, t: usize) -> (usize, f64, f64, usize) {
        let Some(v) = self.rt.run.results.get(t) else {
            return (0, 0.0, 0.0, 0);
        };
        v.iter()
            .enumerate()
            .filter(|(f, _)| *f > self.tracker_start(t))
            .filter_map(|(_, r)| r.as_ref())
            .filter(|r| r.status == TrackStatus::Tracking)
            .fold((0, 0.0, 0.0, 0), |a, r| {
                (
                    a.0 + 1,
                    a.1 + r.search_us,
                    a.2 + r.update_us,
                    a.3 + r.iterations.len(),
                )
            })
    }

    /// The success curve of tracker `t` (from [`eval::success_curve`]).
    pub fn success_curve(&self, t: usize) -> Vec<(f64, f64)> {
        let e: Vec<f64> = self.errors(t).into_iter().map(|(_, e)| e).collect();
        if e.is_empty() {
            return Vec::new();
        }
        eval::success_curve(&e)
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
                    egui::Panel::bottom("gt_strip").show(ui, |ui| panels::gt_strip(self, ui));
                }
                panels::frame_view(self, ui, &mut out)
            })
            .inner;
        if transform.is_some() {
            self.rt.display.transform = transform;
        }
        self.rt.commands.extend(out);
        self.apply_pending();
        if !self.rt.run.rerun_due.is_empty() && !ctx.input(|i| i.pointer.any_down()) {
            for i in std::mem::take(&mut self.rt.run.rerun_due) {
                self.rerun_tracker(i);
            }
        }
        self.replay(&ctx);
        if !self.rt.run.playing {
            self.request_landscape();
        }
        if self.rt.ui.show_help {
            help_window(&ctx, &mut self.rt.ui.show_help);
        }
        self.screenshot(&ctx);
        if self.rt.run.playing || self.rt.msg.progress.is_some() {
            ctx.request_repaint();
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
            if i.modifiers.command || n == 0 {
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
                d.add_filter("ground truth", &["txt"]).pick_file()
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

    /// Drives a planned screenshot: track the planned frames, wait for the frame to be shown,
    /// then capture the window and close it.
    fn screenshot(&mut self, ctx: &egui::Context) {
        let (n, start, generation) = (
            self.frame_count(),
            self.state.start_frame,
            self.rt.run.generation,
        );
        let Some(plan) = self.rt.screenshot.as_mut() else {
            return;
        };
        if plan.requested || n == 0 {
            return;
        }
        ctx.request_repaint();
        let target = (start + plan.frames).min(n - 1);
        let Some(reached) = self.rt.run.tracked_until else {
            return;
        };
        if reached < target {
            if !plan.started {
                plan.started = true;
                self.rt.run.playing = true;
                self.rt.worker.send(Job::Advance {
                    generation,
                    frames: Some(target - reached),
                    fps: self.state.playback_fps,
                });
            }
            return;
        }
        if self.rt.run.playing
            || self.rt.display.texture_frame != Some(reached)
            || self.rt.display.pending_image.is_some()
        {
            return;
        }
        plan.requested = true;
        let path = plan.path.clone();
        let result = plan.result.clone();
        let ctx2 = ctx.clone();
        let summary = frame_rate_summary(&self.rt.frame_times);
        ctx.request_screenshot(move |img| {
            let saved = save_png(&path, &img).map(|()| summary);
            if let Ok(mut r) = result.lock() {
                *r = Some(saved);
            }
            ctx2.send_viewport_cmd(egui::ViewportCommand::Close);
            ctx2.request_repaint();
        });
    }
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

fn help_window(ctx: &egui::Context, open: &mut bool) {
    egui::Window::new("Keyboard shortcuts")
        .open(open)
        .collapsible(false)
        .resizable(false)
        .anchor(egui::Align2::CENTER_CENTER, egui::Vec2::ZERO)
        .show(ctx, |ui| {
            egui::Grid::new("shortcuts").striped(true).show(ui, |ui| {
                for (k, what) in SHORTCUTS {
                    ui.strong(*k);
                    ui.label(*what);
                    ui.end_row();
                }
            });
        });
}

/// The window's frame rate while the trackers ran, and the time the UI took to build a frame
/// (what the app itself costs; the rest is rendering).
fn frame_rate_summary(times: &[(f32, f32)]) -> String {
    let median = |mut v: Vec<f32>| -> f32 {
        v.sort_by(f32::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f32::NAN)
    };
    let dts: Vec<f32> = times.iter().map(|t| t.0).filter(|v| *v > 0.0).collect();
    if dts.is_empty() {
        return "window: no frame while tracking".into();
    }
    let n = dts.len();
    let (frame, build) = (median(dts), median(times.iter().map(|t| t.1).collect()));
    format!(
        "window: median {:.0} fps over {n} frames while tracking; building the UI took a median {:.2} ms per frame",
        1.0 / frame,
        build * 1e3
    )
}

fn save_png(path: &std::path::Path, img: &egui::ColorImage) -> Result<(), AppError> {
    let fail = |message: String| AppError::Screenshot {
        path: path.to_path_buf(),
        message,
    };
    let [w, h] = img.size;
    let raw: Vec<u8> = img.pixels.iter().flat_map(|c| c.to_array()).collect();
    let buf = image::RgbaImage::from_raw(w as u32, h as u32, raw)
        .ok_or_else(|| fail("an image of the wrong size".into()))?;
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|e| fail(format!("{}: {e}", d.display())))?;
    }
    buf.save(path).map_err(|e| fail(e.to_string()))
}

impl eframe::App for InspectorApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        InspectorApp::ui(self, ui);
    }
}

/// How to start the inspector.
#[derive(Debug, Default)]
pub struct RunOptions {
    pub session: Option<PathBuf>,
    pub sequence: Option<PathBuf>,
    pub screenshot: Option<(usize, PathBuf)>,
}

/// Opens the inspector window (blocks until it closes).
pub fn run(opts: RunOptions) -> Result<Option<String>, AppError> {
    let mut state = match &opts.session {
        Some(p) => State::load(p).map_err(AppError::Session)?,
        None => State::default(),
    };
    if let Some(p) = &opts.sequence {
        state.sequence = SequenceSource::Path(p.clone());
    }
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("regtrack inspector")
            .with_inner_size([1280.0, 800.0]),
        ..Default::default()
    };
    let shot = opts.screenshot.clone();
    let session = opts.session.clone();
    let result: ShotResult = Arc::new(Mutex::new(None));
    let result2 = result.clone();
    eframe::run_native(
        "regtrack inspector",
        native,
        Box::new(move |cc| {
            let ctx = cc.egui_ctx.clone();
            let mut app = InspectorApp::new(state, move || ctx.request_repaint());
            if let Some(p) = &session {
                app.set_session_path(p);
            }
            if let Some((frames, path)) = shot {
                app.screenshot_after(frames, path, result2);
            }
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| AppError::Window(e.to_string()))?;
    if opts.screenshot.is_none() {
        return Ok(None);
    }
    let outcome = result.lock().ok().and_then(|mut r| r.take());
    outcome.unwrap_or(Err(AppError::NoScreenshot)).map(Some)
}
