//! Background work, one way: the UI sends [`Job`]s to the tracking thread, or starts a task on a
//! thread of its own ([`Worker::spawn_task`], for what blocks, as a file dialog), and every
//! result comes back as a [`Reply`] on one channel, which the UI polls each frame; each reply
//! wakes the UI (a repaint). Slow work (opening or rendering a sequence, decoding frames,
//! tracking, propagating corrections, sweeping a landscape) never runs on the UI thread.
//! Results of an older generation (before a re-initialisation) are dropped by the UI.

use super::decoder::{AHEAD, Ahead, FrameImage, decode_frame, frame_image};
use super::state::SequenceSource;
use crate::dataset::{Sequence, demo};
use crate::error::{Error, Result};
use crate::geometry::Quad;
use crate::gt;
use crate::imaging::Frame8;
use crate::observe::{IterationRecord, Recorder, VisualRecord};
use crate::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};
use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant};

/// One tracker's result on one frame.
#[derive(Clone, Debug)]
pub struct TrackerFrame {
    /// Index of the tracker in the session.
    pub tracker: usize,
    pub status: TrackStatus,
    pub corners: Quad,
    /// The tracker's confidence in the frame (see [`crate::status::FrameOutcome::confidence`]).
    pub confidence: Option<f64>,
    pub iterations: Vec<IterationRecord>,
    /// Corners before the first iteration.
    pub start: Option<Quad>,
    pub search_us: f64,
    pub update_us: f64,
    /// Template, last sampled patch (res x res, once per channel: `channels` 1, 3 (red, green
    /// and blue one after the other) or 4 (the descriptor fields)).
    pub res: usize,
    pub channels: usize,
    pub template: Arc<Vec<f32>>,
    pub patch: Vec<f32>,
    /// What a sampling search method showed at its last iteration (NN's samples, PF's
    /// particles); the app keeps it for the newest frame only.
    pub visual: Option<Arc<VisualRecord>>,
    /// A non-rigid tracker's warped lattice over its target.
    pub grid: Option<crate::visual_tracker::WarpedGrid>,
}

/// Work for the thread.
#[derive(Debug)]
pub enum Job {
    /// Open (or render) a sequence.
    Open(SequenceSource),
    /// Decode a frame for display.
    Show(usize),
    /// (Re-)initialise trackers `(index, spec, corners)` on `frame`.
    Start {
        generation: u64,
        frame: usize,
        trackers: Vec<(usize, TrackerSpec, Quad)>,
    },
    /// (Re-)initialise one tracker `(index, spec, corners)` on `from` and track it up to
    /// `until` (the frame the others reached), leaving the others as they are; `None` removes it.
    Rerun {
        generation: u64,
        index: usize,
        tracker: Option<Box<(TrackerSpec, Quad)>>,
        from: usize,
        until: usize,
    },
    /// Sweeps a tracker's similarity around `at` on `frame` (the tracker built from `spec` and
    /// initialised on `start` at `init`, as the run did); answered by [`Reply::Landscape`].
    Landscape(Box<LandscapeJob>),
    /// Removes tracker `index`; the trackers after it move down by one.
    Remove { index: usize },
    /// Tracks forward from a corrected ground-truth frame to propose corrections of the next
    /// frames; answered by [`Reply::Proposal`].
    Propagate(Box<PropagateJob>),
    /// Track the next frames (`None`: to the end) at `fps` frames per second (0 = at once).
    Advance {
        generation: u64,
        frames: Option<usize>,
        fps: f32,
    },
    /// Open a live source (`/dev/videoN` or `lavfi:<graph>`) at `width x height`: its frames
    /// are shown and tracked as they come, the newest each time (see [`crate::dataset::live`]),
    /// until another source is opened, [`Job::StopLive`] or the source stops.
    Live {
        generation: u64,
        source: String,
        width: usize,
        height: usize,
    },
    /// Start recording the live frames with tracker `index`'s corners as a sequence under
    /// the folder (`None`: stop recording).
    Record(Option<(PathBuf, usize)>),
    /// Close the live source.
    StopLive,
    /// The convergence experiment: each tracker, initialised as its run was, started on
    /// `frame` from the `start` corners (a perturbation); answered by [`Reply::Experiment`].
    Experiment(Box<ExperimentJob>),
}

/// A convergence experiment to run (see [`Job::Experiment`]).
#[derive(Debug)]
pub struct ExperimentJob {
    /// Identifies the request (the reply carries it back).
    pub key: u64,
    pub frame: usize,
    pub start: Quad,
    /// Per tracker: its index, spec, and the frame and corners it was initialised on.
    pub trackers: Vec<(usize, TrackerSpec, usize, Quad)>,
}

pub use crate::dataset::live::LiveInfo;

/// Live frames kept for initialising a tracker on the frame a box was drawn on (about 3 s at
/// 30 fps).
pub const LIVE_KEPT: usize = 90;

/// A live source being shown and tracked: the library's run ([`crate::dataset::live::LiveRun`]),
/// the newest frames, and which tracker's corners the recording keeps.
struct LiveShown {
    run: crate::dataset::live::LiveRun,
    /// The newest frames, by index.
    kept: std::collections::VecDeque<(usize, Frame8)>,
    /// The tracker whose corners are recorded, while recording.
    recorded: Option<usize>,
}

impl LiveShown {
    fn info(&self) -> &LiveInfo {
        self.run.info()
    }
}

/// A tracker's result on a tracked frame, with what the recorder saw of its iterations.
fn tracked_frame(
    index: usize,
    t: &Tracker,
    rec: &mut Recorder,
    out: &crate::tracker::FrameOutcome,
    template: Arc<Vec<f32>>,
) -> TrackerFrame {
    TrackerFrame {
        tracker: index,
        status: out.status,
        corners: out.corners,
        confidence: out.confidence,
        iterations: rec.iterations.clone(),
        visual: rec.method_visuals.pop().map(Arc::new),
        start: rec.start,
        search_us: out.timing.search.as_secs_f64() * 1e6,
        update_us: (out.timing.search + out.timing.preprocess).as_secs_f64() * 1e6,
        res: t.inspection().map(|i| i.res).unwrap_or(0),
        channels: t.inspection().map_or(1, |i| i.channels),
        template,
        patch: t.inspection().map(|i| i.patch.to_vec()).unwrap_or_default(),
        grid: t.warped_grid(),
    }
}

/// A tracker's result on the frame it was initialised on (its patch is the template).
fn initial_frame(index: usize, t: &Tracker, template: Arc<Vec<f32>>) -> TrackerFrame {
    TrackerFrame {
        tracker: index,
        status: t.status(),
        corners: t.corners(),
        confidence: None,
        iterations: Vec::new(),
        visual: None,
        start: None,
        search_us: 0.0,
        update_us: 0.0,
        res: t.inspection().map(|i| i.res).unwrap_or(0),
        channels: t.inspection().map_or(1, |i| i.channels),
        patch: template.to_vec(),
        template,
        grid: t.warped_grid(),
    }
}

/// A cost landscape to compute.
#[derive(Debug)]
pub struct LandscapeJob {
    /// Identifies the request (the reply carries it back).
    pub key: String,
    pub spec: TrackerSpec,
    pub start: usize,
    pub init: Quad,
    pub frame: usize,
    pub at: Quad,
    pub sweep: crate::landscape::LandscapeSpec,
}

/// A propagation to run (see [`gt::propagate`]).
#[derive(Debug)]
pub struct PropagateJob {
    /// What the proposal is called in the undo history.
    pub label: String,
    /// The sequence it was asked on (the one the app shows): a sequence opened since (the open
    /// was under way when the propagation was asked for) is not propagated over.
    pub sequence: Arc<Sequence>,
    pub spec: TrackerSpec,
    /// The corrected frame it starts from, and its corners.
    pub from: (usize, Quad),
    /// The ground truth before the propagation, per frame.
    pub old: Vec<Option<Quad>>,
    /// Frames corrected by hand (the propagation stops before them).
    pub corrected: BTreeSet<usize>,
    /// Where else it stops.
    pub limits: gt::PropagateLimits,
}

/// A job with the cancellation epoch it was sent in: an advance runs only while no stop,
/// start or open came after it.
type Stamped = (u64, Job);

/// What the thread reports.
#[derive(Debug)]
pub enum Reply {
    Progress(String, usize, usize),
    Opened(Arc<Sequence>),
    Image(FrameImage),
    /// Results for a frame (initialisation or tracking) of a generation. `catch_up`: one
    /// tracker re-run over frames the others already reached (the view does not follow it).
    Frame {
        generation: u64,
        frame: usize,
        results: Vec<TrackerFrame>,
        image: Option<FrameImage>,
        catch_up: bool,
    },
    /// An advance ended (end of sequence, asked frames done, or stopped).
    Stopped {
        generation: u64,
        frame: usize,
    },
    /// A job that failed, with what it was doing.
    Error {
        context: String,
        error: Error,
    },
    /// A frame that cannot be read (the error names its file).
    FrameError {
        index: usize,
        error: Error,
    },
    /// A cost landscape (for the request `key`; boxed: its centre holds a whole parameter
    /// vector).
    Landscape {
        key: String,
        result: Result<Box<crate::landscape::Landscape>>,
    },
    /// A propagation's proposal (see [`Job::Propagate`]).
    Proposal {
        label: String,
        result: Result<gt::Proposal>,
    },
    /// The path a file dialog returned (`None`: it was closed without a choice).
    Picked(Option<PathBuf>),
    /// A live source opened, or its progress (with each live frame).
    Live(LiveInfo),
    /// The live source was closed (`error: None`), could not open or stopped by itself (the
    /// error names it and the frame).
    LiveEnded {
        error: Option<String>,
    },
    /// A recording ended (asked, or its source stopped): its ground-truth file and frames,
    /// kept on disk.
    RecordingEnded {
        path: PathBuf,
        frames: usize,
    },
    /// Plots written (the files), or why not.
    Exported(std::result::Result<Vec<PathBuf>, String>),
    /// Patches tracked from `from` (see [`super::Patches`]).
    Patches {
        from: usize,
        result: std::result::Result<crate::patches::PatchRun, String>,
    },
    /// The frequency of convergence on `frame` (see [`super::Frequency`]).
    Frequency {
        frame: usize,
        result: std::result::Result<Vec<(usize, crate::converge::ConvergeCurve)>, String>,
    },
    /// A convergence experiment's runs, per tracker (for the request `key`).
    Experiment {
        key: u64,
        results: Vec<TrackerFrame>,
    },
}

/// The handle the UI keeps.
pub struct Worker {
    jobs: Sender<Stamped>,
    replies: Receiver<Reply>,
    /// For the tasks on threads of their own.
    reply_tx: Sender<Reply>,
    wake: Arc<dyn Fn() + Send + Sync>,
    epoch: Arc<AtomicU64>,
    /// Why the thread could not start, if it could not.
    pub spawn_error: Option<String>,
}

impl Worker {
    /// Starts the thread; `wake` is called after every reply (to request a repaint).
    pub fn spawn(wake: impl Fn() + Send + Sync + 'static) -> Worker {
        let (jobs, job_rx) = channel::<Stamped>();
        let (reply_tx, replies) = channel::<Reply>();
        let epoch = Arc::new(AtomicU64::new(0));
        let epoch2 = epoch.clone();
        let wake: Arc<dyn Fn() + Send + Sync> = Arc::new(wake);
        let (tx2, wake2) = (reply_tx.clone(), wake.clone());
        let spawned = std::thread::Builder::new()
            .name("regtrack-worker".into())
            .spawn(move || {
                super::background::yield_to_window();
                Thread::new(tx2, epoch2, move || wake2()).run(job_rx)
            });
        Worker {
            jobs,
            replies,
            reply_tx,
            wake,
            epoch,
            // The handle still works without its thread (jobs go nowhere); the UI shows why.
            spawn_error: spawned
                .err()
                .map(|e| format!("cannot start the tracking thread: {e}")),
        }
    }

    /// Queues a job.
    pub fn send(&self, job: Job) {
        if matches!(job, Job::Start { .. } | Job::Open(_) | Job::Live { .. }) {
            self.stop();
        }
        let _ = self.jobs.send((self.epoch.load(Ordering::SeqCst), job));
    }

    /// Runs `task` on a thread of its own (for work that blocks, as a file dialog); its reply
    /// comes back with the others. The error says why the thread could not start.
    pub fn spawn_task(
        &self,
        name: &str,
        task: impl FnOnce() -> Reply + Send + 'static,
    ) -> std::io::Result<()> {
        let (tx, wake) = (self.reply_tx.clone(), self.wake.clone());
        std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || {
                super::background::yield_to_window();
                let _ = tx.send(task());
                wake();
            })
            .map(|_| ())
    }

    /// Stops a running advance after its current frame, and any advance queued before.
    pub fn stop(&self) {
        self.epoch.fetch_add(1, Ordering::SeqCst);
    }

    /// Replies received so far.
    pub fn poll(&self) -> Vec<Reply> {
        self.replies.try_iter().collect()
    }
}

struct Thread<W: Fn() + Sync> {
    out: Sender<Reply>,
    epoch: Arc<AtomicU64>,
    wake: W,
    sequence: Option<Arc<Sequence>>,
    /// Frames decoded ahead on their own thread.
    ahead: Ahead,
    trackers: Vec<(usize, Tracker)>,
    templates: Vec<Arc<Vec<f32>>>,
    generation: u64,
    frame: usize,
    live: Option<LiveShown>,
}

impl<W: Fn() + Sync> Thread<W> {
    fn new(out: Sender<Reply>, epoch: Arc<AtomicU64>, wake: W) -> Self {
        Thread {
            out,
            epoch,
            wake,
            sequence: None,
            ahead: Ahead::spawn(),
            trackers: Vec::new(),
            templates: Vec::new(),
            generation: 0,
            frame: 0,
            live: None,
        }
    }

    fn reply(&self, r: Reply) {
        let _ = self.out.send(r);
        (self.wake)();
    }

    fn run(mut self, jobs: Receiver<Stamped>) {
        loop {
            // While a live source runs, its frames are taken between jobs.
            let next = if self.live.is_some() {
                match jobs.try_recv() {
                    Ok(j) => j,
                    Err(std::sync::mpsc::TryRecvError::Empty) => {
                        self.live_step();
                        continue;
                    }
                    Err(std::sync::mpsc::TryRecvError::Disconnected) => break,
                }
            } else {
                match jobs.recv() {
                    Ok(j) => j,
                    Err(_) => break,
                }
            };
            let (epoch, job) = next;
            self.job(job, epoch);
        }
    }

    /// Carries out one job (`epoch`: when it was sent, for a stop sent after it).
    fn job(&mut self, job: Job, epoch: u64) {
        match job {
            Job::Open(src) => {
                self.end_live(None);
                self.open(src)
            }
            Job::Live {
                generation,
                source,
                width,
                height,
            } => self.open_live(generation, source, width, height),
            Job::Record(what) => self.record(what),
            Job::StopLive => self.end_live(None),
            Job::Show(i) => match self.decode(i) {
                Ok((_, img)) => self.reply(Reply::Image(img)),
                Err(e) => self.reply(Reply::FrameError { index: i, error: e }),
            },
            Job::Start {
                generation,
                frame,
                trackers,
            } => self.start(generation, frame, trackers),
            Job::Rerun {
                generation,
                index,
                tracker,
                from,
                until,
            } => {
                if generation == self.generation {
                    self.rerun(index, tracker.map(|b| *b), from, until);
                }
            }
            Job::Experiment(job) => {
                let results = self.experiment(&job);
                self.reply(Reply::Experiment {
                    key: job.key,
                    results,
                });
            }
            Job::Landscape(job) => {
                let result = self.landscape(&job).map(Box::new);
                self.reply(Reply::Landscape {
                    key: job.key.clone(),
                    result,
                });
            }
            Job::Propagate(job) => {
                let result = self.propagate(&job);
                self.reply(Reply::Proposal {
                    label: job.label,
                    result,
                });
            }
            Job::Remove { index } => self.remove(index),
            Job::Advance {
                generation,
                frames,
                fps,
            } => {
                if generation == self.generation {
                    self.advance(frames, fps, epoch)
                } else {
                    self.reply(Reply::Stopped {
                        generation,
                        frame: self.frame,
                    });
                }
            }
        }
    }

    /// Tracker `index` is gone: the later ones move down.
    fn remove(&mut self, index: usize) {
        if let Some(k) = self.trackers.iter().position(|t| t.0 == index) {
            self.trackers.remove(k);
            self.templates.remove(k);
        }
        for t in &mut self.trackers {
            if t.0 > index {
                t.0 -= 1;
            }
        }
    }

    fn open(&mut self, src: SequenceSource) {
        self.frame = 0;
        let result = match &src {
            SequenceSource::Demo => {
                let out = self.out.clone();
                let wake = &self.wake;
                demo::ensure_demo(None, &|d, t| {
                    let _ = out.send(Reply::Progress("rendering the demo sequence".into(), d, t));
                    wake();
                })
            }
            SequenceSource::Path(p) => Sequence::open(p),
        };
        match result {
            Ok(seq) => {
                let seq = Arc::new(seq);
                self.sequence = Some(seq.clone());
                self.trackers.clear();
                self.reply(Reply::Opened(seq));
            }
            Err(e) => self.reply(Reply::Error {
                context: "cannot open the sequence".into(),
                error: e,
            }),
        }
    }

    /// Frame `i`: from the frames decoded ahead, else decoded now; asks the decoder for the
    /// next few frames (tracking and replay go forward).
    fn decode(&self, i: usize) -> Result<(Frame8, FrameImage)> {
        if let Some(run) = &self.live {
            let gray = run
                .kept
                .iter()
                .find(|(k, _)| *k == i)
                .map(|(_, g)| g.clone())
                .ok_or_else(|| {
                    Error::InvalidParameter(format!(
                        "live frame {} is no longer kept (the last {LIVE_KEPT} are)",
                        i + 1
                    ))
                })?;
            let image = frame_image(i, &gray);
            return Ok((gray, image));
        }
        let seq = self
            .sequence
            .as_ref()
            .ok_or_else(|| Error::InvalidParameter("no sequence is open".into()))?;
        let ahead = self.ahead.take(seq, i);
        self.ahead
            .request(seq, i + 1..(i + 1 + AHEAD).min(seq.len()));
        match ahead {
            Some(r) => r,
            None => decode_frame(seq, i),
        }
    }

    fn snapshot(
        &self,
        k: usize,
        t: &Tracker,
        rec: &mut Recorder,
        out: &crate::tracker::FrameOutcome,
    ) -> TrackerFrame {
        tracked_frame(self.trackers[k].0, t, rec, out, self.templates[k].clone())
    }

    fn start(&mut self, generation: u64, frame: usize, specs: Vec<(usize, TrackerSpec, Quad)>) {
        self.generation = generation;
        self.frame = frame;
        self.trackers.clear();
        self.templates.clear();
        let (gray, image) = match self.decode(frame) {
            Ok(v) => v,
            Err(e) => {
                return self.reply(Reply::FrameError {
                    index: frame,
                    error: e,
                });
            }
        };
        let mut results = Vec::new();
        for (idx, spec, quad) in specs {
            let made = Tracker::new(&spec).and_then(|mut t| {
                t.initialize(FrameInput::of(&gray), &quad)?;
                Ok(t)
            });
            match made {
                Ok(t) => {
                    self.templates.push(Arc::new(
                        t.inspection()
                            .map(|i| i.template.to_vec())
                            .unwrap_or_default(),
                    ));
                    self.trackers.push((idx, t));
                    let k = self.trackers.len() - 1;
                    results.push(initial_frame(
                        idx,
                        &self.trackers[k].1,
                        self.templates[k].clone(),
                    ));
                }
                Err(e) => self.reply(Reply::Error {
                    context: spec.label(),
                    error: e,
                }),
            }
        }
        self.reply(Reply::Frame {
            generation,
            frame,
            results,
            image: Some(image),
            catch_up: false,
        });
    }

    /// Each tracker of the experiment from its start; a tracker that cannot run it is
    /// reported and left out.
    fn experiment(&self, job: &ExperimentJob) -> Vec<TrackerFrame> {
        let mut out = Vec::new();
        for (index, spec, from, init) in &job.trackers {
            let run = || -> Result<TrackerFrame> {
                let (first, _) = self.decode(*from)?;
                let mut t = Tracker::new(spec)?;
                t.initialize(FrameInput::of(&first), init)?;
                let template = Arc::new(
                    t.inspection()
                        .map(|i| i.template.to_vec())
                        .unwrap_or_default(),
                );
                let (img, _) = self.decode(job.frame)?;
                t.set_corners(&job.start)?;
                let mut rec = Recorder {
                    visuals: true,
                    patches: true,
                    ..Recorder::default()
                };
                let o = t.update(FrameInput::of(&img), &mut rec);
                Ok(tracked_frame(*index, &t, &mut rec, &o, template))
            };
            match run() {
                Ok(r) => out.push(r),
                Err(e) => self.reply(Reply::Error {
                    context: format!("experiment, tracker {}", index + 1),
                    error: e,
                }),
            }
        }
        out
    }

    fn landscape(&self, job: &LandscapeJob) -> Result<crate::landscape::Landscape> {
        let (start, _) = self.decode(job.start)?;
        let mut t = Tracker::new(&job.spec)?;
        t.initialize(FrameInput::of(&start), &job.init)?;
        let (img, _) = self.decode(job.frame)?;
        t.landscape(FrameInput::of(&img), &job.at, &job.sweep)
            .unwrap_or_else(|| {
                Err(Error::Incompatible(format!(
                    "{} has no similarity over warps",
                    job.spec.label()
                )))
            })
    }

    fn propagate(&self, job: &PropagateJob) -> Result<gt::Proposal> {
        let seq = self
            .sequence
            .as_ref()
            .ok_or_else(|| Error::InvalidParameter("no sequence is open".into()))?;
        if !Arc::ptr_eq(seq, &job.sequence) {
            return Err(Error::InvalidParameter(
                "another sequence was opened before the propagation ran: propagate again".into(),
            ));
        }
        gt::propagate(
            seq,
            &job.spec,
            job.from,
            &job.old,
            &|f| job.corrected.contains(&f),
            job.limits,
        )
    }

    /// Re-runs one tracker from `from` to `until` (see [`Job::Rerun`]); the others keep their
    /// state, and the re-run one joins them for the next frames.
    fn rerun(
        &mut self,
        index: usize,
        tracker: Option<(TrackerSpec, Quad)>,
        from: usize,
        until: usize,
    ) {
        if let Some(k) = self.trackers.iter().position(|t| t.0 == index) {
            self.trackers.remove(k);
            self.templates.remove(k);
        }
        let Some((spec, quad)) = tracker else { return };
        let len = match (&self.live, &self.sequence) {
            (Some(run), _) => run.info().frames,
            (None, Some(seq)) => seq.len(),
            (None, None) => return,
        };
        let until = until.min(len.saturating_sub(1)).max(from);
        let Some(mut t) = self.start_one(&spec, &quad, from) else {
            return;
        };
        let template = Arc::new(
            t.inspection()
                .map(|i| i.template.to_vec())
                .unwrap_or_default(),
        );
        self.reply(Reply::Frame {
            generation: self.generation,
            frame: from,
            results: vec![initial_frame(index, &t, template.clone())],
            image: None,
            catch_up: true,
        });
        for i in from + 1..=until {
            if i % 10 == 0 {
                self.reply(Reply::Progress(
                    format!("re-running tracker {}", index + 1),
                    i - from,
                    until - from,
                ));
            }
            let gray = match self.decode(i) {
                Ok(v) => v.0,
                Err(e) => {
                    self.reply(Reply::FrameError { index: i, error: e });
                    break;
                }
            };
            let mut rec = Recorder {
                visuals: i == until,
                patches: true,
                ..Recorder::default()
            };
            let out = t.update(FrameInput::of(&gray), &mut rec);
            self.reply(Reply::Frame {
                generation: self.generation,
                frame: i,
                results: vec![tracked_frame(index, &t, &mut rec, &out, template.clone())],
                image: None,
                catch_up: true,
            });
        }
        self.reply(Reply::Progress(String::new(), 0, 0));
        self.trackers.push((index, t));
        self.templates.push(template);
    }

    /// A tracker of `spec` initialised on `quad` in frame `from` (`None`, the reason replied,
    /// when the frame cannot be read or the tracker cannot start there).
    fn start_one(&mut self, spec: &TrackerSpec, quad: &Quad, from: usize) -> Option<Tracker> {
        let gray = match self.decode(from) {
            Ok(v) => v.0,
            Err(e) => {
                self.reply(Reply::FrameError {
                    index: from,
                    error: e,
                });
                return None;
            }
        };
        match Tracker::new(spec).and_then(|mut t| {
            t.initialize(FrameInput::of(&gray), quad)?;
            Ok(t)
        }) {
            Ok(t) => Some(t),
            Err(e) => {
                self.reply(Reply::Error {
                    context: spec.label(),
                    error: e,
                });
                None
            }
        }
    }

    /// Opens a live source; its frames then come between jobs ([`Thread::live_step`]).
    fn open_live(&mut self, generation: u64, source: String, width: usize, height: usize) {
        self.end_live(None);
        // In colour: shown so, and read so by a tracker with `channels = rgb`.
        match crate::dataset::live::LiveRun::open(&source, width, height, true) {
            Ok(run) => {
                self.sequence = None;
                self.trackers.clear();
                self.templates.clear();
                self.generation = generation;
                self.frame = 0;
                self.reply(Reply::Live(run.info().clone()));
                self.live = Some(LiveShown {
                    run,
                    kept: Default::default(),
                    recorded: None,
                });
            }
            Err(e) => self.reply(Reply::LiveEnded {
                error: Some(format!("cannot open the live source {source}: {e}")),
            }),
        }
    }

    /// Takes the newest live frame (waiting a little for one), tracks it with the trackers
    /// initialised so far, records it when recording, and sends it.
    fn live_step(&mut self) {
        let Some(live) = self.live.as_mut() else {
            return;
        };
        let taken = match live.run.take(Some(Duration::from_millis(50))) {
            Ok(Some(t)) => t,
            Ok(None) => return,
            Err(e) => return self.end_live(Some(e.to_string())),
        };
        let i = taken.index;
        live.kept.push_back((i, taken.image));
        if live.kept.len() > LIVE_KEPT {
            live.kept.pop_front();
        }
        let gray = &live.kept.back().expect("just pushed").1;
        let image = frame_image(i, gray);
        // Trackers initialised on this frame or before (a box drawn on a kept frame starts
        // its tracker there) follow it.
        let mut results = Vec::with_capacity(self.trackers.len());
        for k in 0..self.trackers.len() {
            let mut rec = Recorder {
                visuals: true,
                patches: true,
                ..Recorder::default()
            };
            let out = self.trackers[k].1.update(FrameInput::of(gray), &mut rec);
            results.push(tracked_frame(
                self.trackers[k].0,
                &self.trackers[k].1,
                &mut rec,
                &out,
                self.templates[k].clone(),
            ));
        }
        self.frame = i;
        let corners = live.recorded.and_then(|index| {
            results
                .iter()
                .find(|r| r.tracker == index && r.status == TrackStatus::Tracking)
                .map(|r| r.corners)
        });
        if let Err((e, kept)) = live.run.record(gray, corners.as_ref()) {
            // The recording stops (what it wrote is kept); the live view goes on.
            live.recorded = None;
            self.reply(Reply::Error {
                context: "the recording stopped".into(),
                error: e,
            });
            if let Some((path, frames)) = kept {
                self.reply(Reply::RecordingEnded { path, frames });
            }
        }
        let info = self
            .live
            .as_ref()
            .map(|r| r.info().clone())
            .unwrap_or_default();
        self.reply(Reply::Frame {
            generation: self.generation,
            frame: i,
            results,
            image: Some(image),
            catch_up: false,
        });
        self.reply(Reply::Live(info));
    }

    /// Starts or stops recording the live frames.
    fn record(&mut self, what: Option<(PathBuf, usize)>) {
        let Some(live) = self.live.as_mut() else {
            return self.reply(Reply::Error {
                context: "cannot record".into(),
                error: Error::InvalidParameter("no live source is open".into()),
            });
        };
        let ended = live.run.stop_recording();
        live.recorded = None;
        let mut error = None;
        if let Some((root, index)) = what {
            match live.run.start_recording(&root, None) {
                Ok(_) => live.recorded = Some(index),
                Err(e) => error = Some(e),
            }
        }
        let info = live.info().clone();
        if let Some(e) = error {
            self.reply(Reply::Error {
                context: "cannot record".into(),
                error: e,
            });
        }
        if let Some((path, frames)) = ended {
            self.reply(Reply::RecordingEnded { path, frames });
        }
        self.reply(Reply::Live(info));
    }

    /// Closes the live source, if one runs (the recording it made stays on disk).
    fn end_live(&mut self, error: Option<String>) {
        let Some(mut live) = self.live.take() else {
            return;
        };
        if let Some((path, frames)) = live.run.stop_recording() {
            self.reply(Reply::RecordingEnded { path, frames });
        }
        self.reply(Reply::LiveEnded { error });
    }

    fn advance(&mut self, frames: Option<usize>, fps: f32, epoch: u64) {
        let Some(seq) = self.sequence.clone() else {
            return self.reply(Reply::Error {
                context: "cannot track".into(),
                error: Error::InvalidParameter("no sequence is open".into()),
            });
        };
        let last = match frames {
            Some(n) => (self.frame + n).min(seq.len() - 1),
            None => seq.len() - 1,
        };
        let mut last_image = Instant::now() - Duration::from_secs(1);
        let started = Instant::now();
        let first = self.frame + 1;
        while self.frame < last && self.epoch.load(Ordering::SeqCst) == epoch {
            let i = self.frame + 1;
            let (gray, image) = match self.decode(i) {
                Ok(v) => v,
                Err(e) => {
                    self.reply(Reply::FrameError { index: i, error: e });
                    break;
                }
            };
            let mut results = Vec::with_capacity(self.trackers.len());
            for k in 0..self.trackers.len() {
                let mut rec = Recorder {
                    visuals: true,
                    patches: true,
                    ..Recorder::default()
                };
                let out = self.trackers[k].1.update(FrameInput::of(&gray), &mut rec);
                results.push(self.snapshot(k, &self.trackers[k].1, &mut rec, &out));
            }
            self.frame = i;
            // Images at display rate (and always the last one): the UI shows only the newest.
            let send_image =
                i == last || last_image.elapsed() >= Duration::from_millis(15) || fps > 0.0;
            if send_image {
                last_image = Instant::now();
            }
            self.reply(Reply::Frame {
                generation: self.generation,
                frame: i,
                results,
                image: send_image.then_some(image),
                catch_up: false,
            });
            // The slowest speed the widget and a session allow, whatever was sent.
            let fps = if fps > 0.0 {
                fps.max(*super::state::PLAYBACK_FPS.start())
            } else {
                0.0
            };
            if fps > 0.0
                && let Ok(after) = Duration::try_from_secs_f32((i + 1 - first) as f32 / fps)
            {
                let due = started + after;
                if let Some(wait) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(wait);
                }
            }
        }
        self.reply(Reply::Stopped {
            generation: self.generation,
            frame: self.frame,
        });
    }
}
