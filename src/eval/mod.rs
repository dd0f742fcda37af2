//! Evaluation: per-frame errors (alignment error E_AL, centre location error, 1 - IoU), success
//! rates SR(t) for t = 0..20 px in steps of 0.1 px (the initialisation frame excluded), per
//! sequence and pooled over a dataset, and speed two ways: tracker-only (the search) and live
//! path (from an 8-bit frame in memory, pre-processing included). Batches of runs go in parallel.

mod batch;
pub mod benchmark;
mod files;
mod plan_file;
mod results_formats;

pub use batch::{
    Batch, BatchOutcome, Finished, POOLED, Plan, Shard, by_tracker, factor_label, factor_rows,
    summary_rows,
};
pub use files::{
    PARTIAL_FILE, POOLED_PARTIAL, finished_run, input_stamp, merge_shards, read_all_runs,
    read_runs, run_file, summary_table, write_run_files, write_summaries,
};
pub use plan_file::{Incomplete, PLAN_FILE, PlanFile, check_plans, completeness, require_complete};
pub use results_formats::{ResultsFormat, write_results};

/// JSON has no infinity: errors of frames without corners are written as `null`.
mod infinite_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

/// A fraction that may be undefined (`NaN`, written as `null` as [`infinite_as_null`] writes
/// every non-finite value).
mod nan_as_null {
    use serde::{Deserialize, Deserializer};

    pub use super::infinite_as_null::serialize;

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::{Quad, alignment_error, center_error, iou};
use crate::observe::Observer;
use crate::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;

/// Largest threshold of the success curve (px).
pub const SR_MAX: f64 = 20.0;
/// Step of the success curve's thresholds (px).
pub const SR_STEP: f64 = 0.1;

/// The thresholds `0, 0.1, ..., 20` px.
pub fn thresholds() -> Vec<f64> {
    let n = (SR_MAX / SR_STEP).round() as usize;
    (0..=n).map(|i| i as f64 * SR_STEP).collect()
}

/// SR(t): the fraction of `errors` that are at most `t` (non-finite errors never count).
pub fn success_rate(errors: &[f64], t: f64) -> f64 {
    if errors.is_empty() {
        return 0.0;
    }
    errors.iter().filter(|&&e| e <= t).count() as f64 / errors.len() as f64
}

/// The success curve `(t, SR(t))` over [`thresholds`].
pub fn success_curve(errors: &[f64]) -> Vec<(f64, f64)> {
    let mut sorted: Vec<f64> = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len().max(1) as f64;
    thresholds()
        .into_iter()
        .map(|t| (t, sorted.partition_point(|&e| e <= t) as f64 / n))
        .collect()
}

/// Mean of SR(t) over the thresholds (the area under the curve over 20 px).
pub fn mean_success_rate(errors: &[f64]) -> f64 {
    let c = success_curve(errors);
    c.iter().map(|p| p.1).sum::<f64>() / c.len() as f64
}

/// `EvalOptions::gt_ssm` for "each tracker against the low-DOF ground truth of its own SSM" (the
/// paper's protocol for comparing SSMs).
pub const OWN_SSM: &str = "own";

/// The error a success curve is drawn from (MTF's error types).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorKind {
    /// E_AL, the mean distance of the four corners (px; the paper's measure).
    #[default]
    Alignment,
    /// Centre location error: the distance of the centroids (px).
    Center,
    /// Jaccard error, 1 - IoU (0 to 1); its success curve runs over 0..1 instead of 0..20 px.
    Jaccard,
}

impl ErrorKind {
    /// The names accepted on the command line.
    pub const NAMES: &'static [&'static str] = &["alignment", "center", "jaccard"];

    /// Parses `alignment` (`al`, `mcd`), `center` (`cl`, `cle`) or `jaccard` (`iou`).
    pub fn parse(s: &str) -> Result<ErrorKind> {
        match s.to_ascii_lowercase().as_str() {
            "alignment" | "al" | "mcd" | "e_al" => Ok(ErrorKind::Alignment),
            "center" | "centre" | "cl" | "cle" => Ok(ErrorKind::Center),
            "jaccard" | "iou" => Ok(ErrorKind::Jaccard),
            _ => Err(Error::InvalidParameter(format!(
                "unknown error type '{s}'; available: {}",
                Self::NAMES.join(", ")
            ))),
        }
    }

    /// The name.
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// A frame's error of this kind: infinite for a frame without corners (lost or skipped),
    /// which never counts as a success (its `iou_error` is 1, the most a frame with corners can
    /// have, so the Jaccard error of a lost frame is not read from it).
    pub fn of(self, f: &FrameRecord) -> f64 {
        if f.corners.is_none() {
            return f64::INFINITY;
        }
        match self {
            ErrorKind::Alignment => f.alignment_error,
            ErrorKind::Center => f.center_error,
            ErrorKind::Jaccard => f.iou_error,
        }
    }

    /// Errors of this kind per unit of the success curve's 0..20 grid (Jaccard's 0..1 is drawn on
    /// the same grid: SR at "5" is the fraction with 1 - IoU <= 0.25).
    pub fn grid_scale(self) -> f64 {
        match self {
            ErrorKind::Jaccard => 1.0 / SR_MAX,
            _ => 1.0,
        }
    }
}

/// How a batch run treats failures, and what it is scored against.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EvalOptions {
    /// Re-initialise from the ground truth after a failure (MTF's `reinit`).
    pub reinit: bool,
    /// A frame fails when the tracker is lost or its E_AL exceeds this (px).
    pub failure_threshold: f64,
    /// With `reinit`: frames skipped after a failure before re-initialising.
    pub reinit_skip: usize,
    /// Score against the low-DOF ground truth of this SSM (OptGT when present, fitted
    /// otherwise), as the paper does; [`OWN_SSM`]: each tracker against its own SSM's; `None`:
    /// the sequence's own ground truth.
    pub gt_ssm: Option<String>,
    /// The error the success rates are computed from.
    pub error: ErrorKind,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            reinit: false,
            failure_threshold: SR_MAX,
            reinit_skip: 5,
            gt_ssm: None,
            error: ErrorKind::Alignment,
        }
    }
}

/// One frame of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    pub frame: usize,
    /// The tracker's corners (`None` when lost, skipped or not tracked).
    pub corners: Option<Quad>,
    pub ground_truth: Option<Quad>,
    /// E_AL, centre error and 1 - IoU (infinite / 1 when there are no corners; infinity is
    /// `null` in JSON).
    #[serde(with = "infinite_as_null")]
    pub alignment_error: f64,
    #[serde(with = "infinite_as_null")]
    pub center_error: f64,
    pub iou_error: f64,
    pub status: TrackStatus,
    pub iterations: usize,
    /// Microseconds in the search and in the whole update (pre-processing included).
    pub search_us: f64,
    pub update_us: f64,
    /// Whether this frame (re-)initialised the tracker (excluded from the success rates).
    pub init: bool,
    /// Whether the tracker searched this frame (not when idle after a loss, skipped or
    /// initialised).
    #[serde(default)]
    pub searched: bool,
    /// E_AL of where the search ended, also when the tracker then reported the frame lost
    /// (infinite when it has no estimate): what the loss detection is scored on.
    #[serde(with = "infinite_as_null", default = "infinite")]
    pub estimate_error: f64,
    /// The tracker's confidence in the frame (see [`crate::status::FrameOutcome::confidence`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<f64>,
    /// The homography discrepancy ([`benchmark::frame_discrepancy`]; infinite without corners
    /// or ground truth).
    #[serde(with = "infinite_as_null", default = "infinite")]
    pub homography_error: f64,
}

fn infinite() -> f64 {
    f64::INFINITY
}

/// A tracker run over one sequence.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    pub sequence: String,
    pub spec: TrackerSpec,
    pub frames: Vec<FrameRecord>,
    /// A frame fails when the tracker is lost or its E_AL exceeds this (px).
    #[serde(default = "default_threshold")]
    pub failure_threshold: f64,
    /// The options the run was made with (ground truth, error type, reinit).
    #[serde(default)]
    pub options: EvalOptions,
    /// Why the run stopped before the end of the sequence (a frame that could not be read); the
    /// frames before it are kept.
    #[serde(default)]
    pub error: Option<String>,
    /// The fingerprint of the inputs the run read ([`files::input_stamp`]): a batch resumes the
    /// run only while they are unchanged.
    #[serde(default)]
    pub inputs: Option<String>,
    /// The sequence's challenge factors ([`crate::dataset::Sequence::factors`]): the summary
    /// pools the runs of each too.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub factors: Vec<String>,
    /// Whether the frames' homography discrepancies were recorded (not in runs written before
    /// they were).
    #[serde(default)]
    pub discrepancy: bool,
}

fn default_threshold() -> f64 {
    SR_MAX
}

/// One row of `summary.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub sequence: String,
    /// The tracker's label (`sm_am_ssm`, or a whole tracker's name).
    #[serde(default)]
    pub tracker: String,
    pub sm: String,
    pub am: String,
    pub ssm: String,
    /// Frames evaluated (initialisation frames excluded).
    pub frames: usize,
    pub sr5: f64,
    pub sr10: f64,
    pub sr20: f64,
    pub mean_sr: f64,
    /// Mean E_AL over the frames with corners.
    pub mean_error: f64,
    /// Failure events (the tracker lost, or E_AL above the failure threshold).
    pub failures: usize,
    pub iterations_per_frame: f64,
    /// Frames per second of the search alone, and of the whole update.
    pub tracker_fps: f64,
    pub live_fps: f64,
    /// The error type of the success rates and `mean_error`.
    #[serde(default)]
    pub error_type: String,
    /// The ground truth scored against: `full`, or the SSM of a low-DOF ground truth.
    #[serde(default)]
    pub gt: String,
    /// Loss detection: of the frames searched whose estimate was more than 20 px off, the
    /// fraction reported lost (`NaN` without such frames).
    #[serde(with = "nan_as_null", default = "not_a_number")]
    pub lost_when_off: f64,
    /// Of the frames searched whose estimate was within 5 px, the fraction reported lost.
    #[serde(with = "nan_as_null", default = "not_a_number")]
    pub lost_when_on: f64,
    /// Runs (of the row's) that stopped before the end of their sequence, a frame that could not
    /// be read: their rates are over the frames before it only.
    #[serde(default)]
    pub stopped: usize,
    /// The benchmarks' figures ([`benchmark`]): precision P@5 and P@15 (RMS corner error), the
    /// success by homography discrepancy and by IoU (the means of their curves).
    #[serde(with = "nan_as_null", default = "not_a_number")]
    pub p5: f64,
    #[serde(with = "nan_as_null", default = "not_a_number")]
    pub p15: f64,
    #[serde(with = "nan_as_null", default = "not_a_number")]
    pub success_h: f64,
    #[serde(with = "nan_as_null", default = "not_a_number")]
    pub success_iou: f64,
}

fn not_a_number() -> f64 {
    f64::NAN
}

/// The estimate error above which a frame should be reported lost, and below which it should
/// not ([`Summary::lost_when_off`], [`Summary::lost_when_on`]), px.
pub const LOSS_OFF: f64 = 20.0;
pub const LOSS_ON: f64 = 5.0;

/// The fractions of [`Summary::lost_when_off`] and [`Summary::lost_when_on`] over `frames`.
pub fn loss_detection<'a>(frames: impl Iterator<Item = &'a FrameRecord>) -> (f64, f64) {
    let (mut off, mut off_lost, mut on, mut on_lost) = (0usize, 0usize, 0usize, 0usize);
    for f in frames.filter(|f| f.searched && !f.init && f.ground_truth.is_some()) {
        let lost = f.status != TrackStatus::Tracking;
        if f.estimate_error > LOSS_OFF {
            off += 1;
            off_lost += usize::from(lost);
        } else if f.estimate_error <= LOSS_ON {
            on += 1;
            on_lost += usize::from(lost);
        }
    }
    let frac = |k: usize, n: usize| {
        if n == 0 {
            f64::NAN
        } else {
            k as f64 / n as f64
        }
    };
    (frac(off_lost, off), frac(on_lost, on))
}

impl RunResult {
    /// Errors of the evaluated frames, of the run's error type (lost frames count as infinite;
    /// frames without ground truth, such as occluded ones, are skipped).
    pub fn errors(&self) -> Vec<f64> {
        let kind = self.options.error;
        self.frames
            .iter()
            .filter(|f| !f.init && f.ground_truth.is_some())
            .map(|f| kind.of(f))
            .collect()
    }

    /// [`RunResult::errors`] on the success curve's 0..20 grid (see [`ErrorKind::grid_scale`]).
    pub fn sr_errors(&self) -> Vec<f64> {
        let s = self.options.error.grid_scale();
        self.errors().into_iter().map(|e| e / s).collect()
    }

    /// The summary row.
    pub fn summary(&self) -> Summary {
        summarize(&self.sequence, &[self])
    }
}

/// The summary of one or several runs of the same tracker (pooled over all their frames).
pub fn summarize(name: &str, runs: &[&RunResult]) -> Summary {
    let raw: Vec<f64> = runs.iter().flat_map(|r| r.errors()).collect();
    let errors: Vec<f64> = runs.iter().flat_map(|r| r.sr_errors()).collect();
    // Speed is over every frame the tracker searched, tracked or lost (a lost frame's search for
    // the target takes its time too); not over the frames skipped before a re-initialisation,
    // nor those a stopped tracker (`on_loss stop`) did not search. (A run file of a version
    // before `searched` was recorded: the frames with a search time.)
    let searched: Vec<&FrameRecord> = runs
        .iter()
        .flat_map(|r| r.frames.iter())
        .filter(|f| !f.init && (f.searched || f.search_us > 0.0))
        .collect();
    let finite: Vec<f64> = raw.iter().copied().filter(|e| e.is_finite()).collect();
    let search: f64 = searched.iter().map(|f| f.search_us).sum();
    let update: f64 = searched.iter().map(|f| f.update_us).sum();
    let n = searched.len() as f64;
    let fps = |us: f64| if us > 0.0 { n / (us * 1e-6) } else { 0.0 };
    let failures = runs.iter().map(|r| count_failures(r)).sum();
    let spec = runs.first().map(|r| r.spec.clone());
    let cols = spec.as_ref().map(|s| s.columns()).unwrap_or_default();
    let (lost_when_off, lost_when_on) = loss_detection(runs.iter().flat_map(|r| r.frames.iter()));
    let bench = benchmark::figures(runs);
    Summary {
        sequence: name.to_string(),
        tracker: spec.as_ref().map(|s| s.label()).unwrap_or_default(),
        sm: cols.0,
        am: cols.1,
        ssm: cols.2,
        frames: errors.len(),
        sr5: success_rate(&errors, 5.0),
        sr10: success_rate(&errors, 10.0),
        sr20: success_rate(&errors, 20.0),
        mean_sr: mean_success_rate(&errors),
        mean_error: if finite.is_empty() {
            f64::NAN
        } else {
            finite.iter().sum::<f64>() / finite.len() as f64
        },
        failures,
        iterations_per_frame: if n > 0.0 {
            searched.iter().map(|f| f.iterations as f64).sum::<f64>() / n
        } else {
            0.0
        },
        tracker_fps: fps(search),
        live_fps: fps(update),
        error_type: runs
            .first()
            .map(|r| r.options.error.name())
            .unwrap_or_default()
            .to_string(),
        gt: runs
            .first()
            .and_then(|r| match r.options.gt_ssm.as_deref() {
                Some(OWN_SSM) => r
                    .spec
                    .registration()
                    .map(|x| crate::gt::ssm_key(&x.ssm).unwrap_or_else(|_| x.ssm.clone())),
                other => other.map(str::to_string),
            })
            .unwrap_or_else(|| "full".into()),
        lost_when_off,
        lost_when_on,
        stopped: runs.iter().filter(|r| r.error.is_some()).count(),
        p5: bench.p5,
        p15: bench.p15,
        success_h: bench.success_h,
        success_iou: bench.success_iou,
    }
}

impl FrameRecord {
    /// Whether the frame failed: no corners (lost, skipped), or E_AL above `threshold`; `None`
    /// for a tracked frame without ground truth (occluded), which cannot be judged.
    fn failed(&self, threshold: f64) -> Option<bool> {
        match (&self.corners, &self.ground_truth) {
            (None, _) => Some(true),
            (Some(_), None) => None,
            (Some(_), Some(_)) => Some(self.alignment_error > threshold),
        }
    }
}

/// Failure events: transitions into a failed frame ([`FrameRecord::failed`]); a frame that
/// cannot be judged leaves the state as it was.
fn count_failures(r: &RunResult) -> usize {
    let mut count = 0;
    let mut failed = false;
    for f in &r.frames {
        if f.init {
            failed = false;
            continue;
        }
        let Some(now) = f.failed(r.failure_threshold) else {
            continue;
        };
        if now && !failed {
            count += 1;
        }
        failed = now;
    }
    count
}

/// Tracks a whole sequence: initialises on frame 0 from `init` or the ground truth, then
/// updates on every frame, feeding 8-bit frames (the live path). The observer sees every
/// iteration. Scored against the ground truth `opts` names (the low-DOF one with `gt_ssm`).
///
/// A frame after the first that cannot be read ends the run early: the frames tracked so far
/// are kept and [`RunResult::error`] names the frame.
pub fn run_sequence(
    seq: &Sequence,
    spec: &TrackerSpec,
    opts: &EvalOptions,
    init: Option<Quad>,
    observer: &mut dyn Observer,
) -> Result<RunResult> {
    run_sequence_reading(seq, spec, opts, init, observer, false)
}

/// [`run_sequence`], the frames decoded ahead by another thread when `ahead` (see
/// [`Sequence::each_frame`]): for a run that leaves a core free (one run at a time on a
/// machine of two cores or more), whose speed figures another thread then does not disturb.
pub fn run_sequence_reading(
    seq: &Sequence,
    spec: &TrackerSpec,
    opts: &EvalOptions,
    init: Option<Quad>,
    observer: &mut dyn Observer,
    ahead: bool,
) -> Result<RunResult> {
    // Before anything is read: what the run is made from.
    let inputs = files::input_stamp(seq);
    let gt_ssm = match opts.gt_ssm.as_deref() {
        // Each tracker against its own SSM's low-DOF ground truth (a whole tracker: the full one).
        Some(OWN_SSM) => spec.registration().map(|r| r.ssm.as_str()),
        other => other,
    };
    let (gt, gt_file): (Vec<Option<Quad>>, _) = match gt_ssm {
        Some(ssm) => {
            let t = crate::gt::low_dof_ground_truth(seq, ssm)?;
            (t.quads, t.path)
        }
        None => (seq.ground_truth.clone(), None),
    };
    // The benchmark's own homographies score the sequence's own ground truth only.
    let gt_h = |i: usize| {
        if gt_ssm.is_none() {
            seq.homographies.get(i).copied().flatten()
        } else {
            None
        }
    };
    let ground_truth = |i: usize| gt.get(i).copied().flatten();
    let first = init
        .or_else(|| ground_truth(0))
        .ok_or_else(|| Error::Sequence {
            // The file the first frame's corners were to come from (an OptGT file, when the
            // run scores against one).
            path: gt_file
                .clone()
                .or_else(|| seq.gt_path.clone())
                .or_else(|| seq.frames.first().cloned())
                .unwrap_or_default(),
            message: "no ground truth for the first frame: give the initial corners".into(),
        })?;
    let mut tracker = Tracker::new(spec)?;
    let mut frames = Vec::with_capacity(seq.len());
    let mut skip_until: Option<usize> = None;
    let mut stopped = None;
    let record =
        |i: usize, corners: Option<Quad>, status, iterations, search_us, update_us, init| {
            let gt = ground_truth(i);
            let (e, c, o) = match (corners, gt) {
                (Some(q), Some(g)) => (
                    alignment_error(&q, &g),
                    center_error(&q, &g),
                    1.0 - iou(&q, &g),
                ),
                _ => (f64::INFINITY, f64::INFINITY, 1.0),
            };
            let h = match gt {
                Some(g) => {
                    benchmark::frame_discrepancy(&first, corners.as_ref(), &g, gt_h(i).as_ref())
                }
                None => f64::INFINITY,
            };
            FrameRecord {
                frame: i,
                corners,
                ground_truth: gt,
                alignment_error: e,
                center_error: c,
                iou_error: o,
                status,
                iterations,
                search_us,
                update_us,
                init,
                searched: false,
                estimate_error: f64::INFINITY,
                confidence: None,
                homography_error: h,
            }
        };
    // With `ahead`, each frame decoded while the tracker works on the one before.
    // A tracker that reads colour is handed colour frames.
    let colour = tracker.channels() == 3;
    let ended = seq.each_frame(
        0..seq.len(),
        ahead,
        colour,
        |i, img| -> ControlFlow<Result<()>> {
            let img = match img {
                Ok(img) => img,
                Err(e) if i > 0 => {
                    stopped = Some(format!("stopped at frame {}: {e}", i + 1));
                    return ControlFlow::Break(Ok(()));
                }
                Err(e) => return ControlFlow::Break(Err(e)),
            };
            let reinit_here = match skip_until {
                Some(k) if i >= k => ground_truth(i).is_some(),
                _ => false,
            };
            if i == 0 {
                if let Err(e) = tracker.initialize(FrameInput::of(&img), &first) {
                    return ControlFlow::Break(Err(e));
                }
                frames.push(record(
                    i,
                    Some(first),
                    TrackStatus::Tracking,
                    0,
                    0.0,
                    0.0,
                    true,
                ));
                return ControlFlow::Continue(());
            }
            if reinit_here {
                let q = ground_truth(i).unwrap_or(first);
                // A frame the tracker cannot start on (occluded, degenerate ground truth) counts as
                // failed; the next annotated frame is tried.
                if tracker.initialize(FrameInput::of(&img), &q).is_ok() {
                    skip_until = None;
                    frames.push(record(i, Some(q), TrackStatus::Tracking, 0, 0.0, 0.0, true));
                } else {
                    skip_until = Some(i + 1);
                    frames.push(record(i, None, tracker.status(), 0, 0.0, 0.0, false));
                }
                return ControlFlow::Continue(());
            }
            if skip_until.is_some() {
                // Skipped after a failure, before re-initialisation: counts as failed.
                frames.push(record(i, None, tracker.status(), 0, 0.0, 0.0, false));
                return ControlFlow::Continue(());
            }
            let out = tracker.update(FrameInput::of(&img), observer);
            let corners = (out.status == TrackStatus::Tracking).then_some(out.corners);
            let search = out.timing.search.as_secs_f64() * 1e6;
            let update = search + out.timing.preprocess.as_secs_f64() * 1e6;
            let mut rec = record(
                i,
                corners,
                out.status,
                out.iterations,
                search,
                update,
                false,
            );
            rec.searched = out.searched;
            rec.confidence = out.confidence;
            if let (Some(q), Some(g)) = (out.estimate, rec.ground_truth) {
                rec.estimate_error = alignment_error(&q, &g);
            }
            // A frame without ground truth (occluded) is a failure only if the tracker is lost.
            let failed = rec.failed(opts.failure_threshold) == Some(true);
            frames.push(rec);
            if opts.reinit && failed {
                skip_until = Some(i + 1 + opts.reinit_skip);
            }
            ControlFlow::Continue(())
        },
    );
    if let Some(Err(e)) = ended {
        return Err(e);
    }
    Ok(RunResult {
        sequence: seq.name.clone(),
        spec: tracker.spec().clone(),
        frames,
        failure_threshold: opts.failure_threshold,
        options: opts.clone(),
        error: stopped,
        inputs: Some(inputs),
        factors: seq.factors.clone(),
        discrepancy: true,
    })
}
