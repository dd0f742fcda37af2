//! Ground truth: low-DOF fitting (the paper's protocol, MTF's OptGT layout) and corrections that
//! are never lost.
//!
//! A correction is kept per SSM (the 8-DOF ground truth and each low-DOF one are corrected
//! separately; the 8-DOF SSMs share one) and per frame: corrected corners, or "occluded". Every
//! edit goes to the [`journal`] beside the sequence's ground truth, synced to disk, *before* it
//! takes effect; the original file is never written. [`Corrections::open`] replays the journal,
//! so reopening a sequence after a crash restores every edit, undo and redo included.
//! [`export`] writes the corrected ground truth atomically, in the sequence's own format and in
//! OptGT layout.

pub mod edit;
pub mod fit;
pub mod journal;

pub use edit::{Grab, drag, grab, move_corner, rectify};
pub use fit::{
    FitOutcome, LowDofGroundTruth, LowDofTruth, best_fit, fit_ground_truth, fit_sequences,
    ground_truth_dir, low_dof_ground_truth, opt_gt_path, write_opt_gt,
};
pub use journal::{Change, Mark};

use crate::dataset::{Sequence, read_ground_truth, write_ground_truth};
use crate::error::{Error, Result};
use crate::geometry::{Quad, alignment_error};
use crate::ssm;
use journal::{Record, Writer};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The model a ground truth of SSM `name` is fitted with: the SSM itself, or for a non-rigid
/// one (laid on a tracker's own quad, its ground truth four free corners) the homography.
pub(crate) fn quad_model(name: &str) -> Result<Box<dyn ssm::Ssm>> {
    let m = ssm::build(name)?;
    if m.projective() {
        Ok(m)
    } else {
        ssm::build("homography")
    }
}

/// The key corrections are kept under for an SSM: its registry name, `homography` for every
/// 8-DOF SSM and the non-rigid ones (their ground truth is four free corners: they describe the
/// same quads).
pub fn ssm_key(name: &str) -> Result<String> {
    let m = ssm::build(name)?;
    Ok(if m.dof() == 8 || !m.projective() {
        "homography".into()
    } else {
        m.name().to_string()
    })
}

/// The journal of a sequence: `<ground-truth folder>/<seq>_corrections.jsonl`.
pub fn journal_path(seq: &Sequence) -> PathBuf {
    ground_truth_dir(seq).join(format!("{}_corrections.jsonl", seq.name))
}

#[derive(Clone, Debug, PartialEq)]
struct Edit {
    id: u64,
    label: String,
    changes: Vec<Change>,
}

/// The corrections of one sequence, with undo/redo and the journal.
#[derive(Debug)]
pub struct Corrections {
    frames: usize,
    marks: BTreeMap<(String, usize), Mark>,
    done: Vec<Edit>,
    undone: Vec<Edit>,
    next_id: u64,
    journal: Option<Writer>,
    /// Why edits are refused (a journal that cannot be used): an edit that is not journaled
    /// would be lost at the next close or open.
    refused: Option<String>,
    /// The files this journal's exports wrote (an export replaces those freely, and keeps a
    /// copy of any other file it would replace).
    exported: std::collections::BTreeSet<PathBuf>,
    /// Edits (and undos/redos) since the last export.
    since_export: usize,
}

/// What [`Corrections::open`] found in the journal.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Recovery {
    /// Edits in effect after the replay.
    pub edits: usize,
    /// Frames (over every SSM) with a correction.
    pub corrected: usize,
    /// The last line was cut short by a crash and ignored.
    pub truncated_tail: bool,
    /// What was skipped, each as `file:line: why`: lines that are not records, and records that
    /// cannot be applied (a frame beyond the sequence, an unusable quad, an undo of an edit that
    /// was skipped). Every other record was applied.
    pub skipped: Vec<String>,
}

impl Recovery {
    /// Whether anything was skipped or dropped (the user should be told).
    pub fn damaged(&self) -> bool {
        self.truncated_tail || !self.skipped.is_empty()
    }
}

impl Corrections {
    /// Corrections without a journal (tests, or a sequence whose folder is read-only).
    pub fn in_memory(frames: usize) -> Self {
        Corrections {
            frames,
            marks: BTreeMap::new(),
            done: Vec::new(),
            undone: Vec::new(),
            next_id: 1,
            journal: None,
            refused: None,
            exported: Default::default(),
            since_export: 0,
        }
    }

    /// No corrections, and every edit refused with `why` (the sequence's journal cannot be
    /// used: its edits could not be kept).
    pub fn refusing(frames: usize, why: String) -> Self {
        Corrections {
            refused: Some(why),
            ..Self::in_memory(frames)
        }
    }

    /// Why edits are refused, if they are ([`Corrections::refusing`]).
    pub fn refused(&self) -> Option<&str> {
        self.refused.as_deref()
    }

    /// Opens the journal at `path` of the sequence `sequence` of `frames` frames, replaying every
    /// intact record it holds (see [`Recovery`] for what is skipped); nothing is written until
    /// the first edit. Opening never changes the file. Errors (naming the file and line) for a
    /// journal that cannot be used at all: another sequence's, a newer format's, or not a
    /// journal.
    pub fn open(path: &Path, sequence: &str, frames: usize) -> Result<(Self, Recovery)> {
        let mut c = Corrections::in_memory(frames);
        let mut rec = Recovery::default();
        if let Some(parsed) = journal::read(path)? {
            if let Some(other) = journal::sequence_of(&parsed)
                && other != sequence
            {
                return Err(Error::Parse {
                    path: path.to_path_buf(),
                    line: 1,
                    message: format!(
                        "this is the journal of sequence '{other}', not of '{sequence}' \
                         (move it away to start a new one)"
                    ),
                });
            }
            rec.truncated_tail = parsed.truncated_tail;
            rec.skipped = parsed.skipped;
            for (line, r) in parsed.records {
                if let Err(message) = c.replay(r) {
                    rec.skipped
                        .push(format!("{}:{line}: skipped, {message}", path.display()));
                }
            }
        }
        c.journal = Some(Writer::open(path, sequence)?);
        rec.edits = c.done.len();
        rec.corrected = c.marks.len();
        Ok((c, rec))
    }

    /// Applies one record; an error leaves the corrections as they were.
    fn replay(&mut self, r: Record) -> std::result::Result<(), String> {
        match r {
            Record::Header { .. } => {}
            Record::Edit {
                id,
                label,
                mut changes,
            } => {
                for ch in &mut changes {
                    if ch.frame >= self.frames {
                        return Err(format!(
                            "frame {} is beyond the sequence's {} frames",
                            ch.frame as u128 + 1,
                            self.frames
                        ));
                    }
                    // Under the SSM's own key (an alias, `8` or `homography`, is one SSM),
                    // where the views look for it.
                    ch.ssm = ssm_key(&ch.ssm).map_err(|e| e.to_string())?;
                    for m in [&ch.before, &ch.after].into_iter().flatten() {
                        journal::check_mark(m)
                            .map_err(|e| format!("frame {}: {e}", ch.frame + 1))?;
                    }
                }
                if id == u64::MAX {
                    return Err(format!("edit id {id} is out of range"));
                }
                let e = Edit { id, label, changes };
                self.set(&e, false);
                self.done.push(e);
                self.undone.clear();
                self.next_id = self.next_id.max(id + 1);
                self.since_export += 1;
            }
            Record::Undo { id } => match self.done.last() {
                Some(e) if e.id == id => {
                    let e = self.done.pop().expect("checked");
                    self.set(&e, true);
                    self.undone.push(e);
                    self.since_export += 1;
                }
                _ => return Err(format!("undo of edit {id}, which is not the last edit")),
            },
            Record::Redo { id } => match self.undone.last() {
                Some(e) if e.id == id => {
                    let e = self.undone.pop().expect("checked");
                    self.set(&e, false);
                    self.done.push(e);
                    self.since_export += 1;
                }
                _ => return Err(format!("redo of edit {id}, which is not the last undone")),
            },
            Record::Export { paths } => {
                self.exported.extend(paths.into_iter().map(PathBuf::from));
                self.since_export = 0;
            }
        }
        Ok(())
    }

    /// Applies an edit's changes (their `after`), or reverts them (their `before`).
    fn set(&mut self, e: &Edit, revert: bool) {
        let changes: Box<dyn Iterator<Item = &Change>> = if revert {
            Box::new(e.changes.iter().rev())
        } else {
            Box::new(e.changes.iter())
        };
        for ch in changes {
            let key = (ch.ssm.clone(), ch.frame);
            match if revert { ch.before } else { ch.after } {
                Some(m) => {
                    self.marks.insert(key, m);
                }
                None => {
                    self.marks.remove(&key);
                }
            }
        }
    }

    fn log(&mut self, r: &Record) -> Result<()> {
        if let Some(why) = &self.refused {
            return Err(Error::Refused(why.clone()));
        }
        match self.journal.as_mut() {
            Some(w) => w.append(r),
            None => Ok(()),
        }
    }

    /// Injects faults into the journal's writes (tests only).
    #[doc(hidden)]
    pub fn inject_faults(&mut self, faults: journal::Faults) {
        if let Some(w) = self.journal.as_mut() {
            w.inject(faults);
        }
    }

    /// The journal's path (`None` in memory).
    pub fn journal_path(&self) -> Option<&Path> {
        self.journal.as_ref().map(Writer::path)
    }

    /// The correction of `frame` in `ssm` (a key from [`ssm_key`]).
    pub fn mark(&self, ssm: &str, frame: usize) -> Option<Mark> {
        self.marks.get(&(ssm.to_string(), frame)).copied()
    }

    /// Frames corrected in `ssm`, in order.
    pub fn corrected_frames(&self, ssm: &str) -> Vec<usize> {
        self.marks
            .keys()
            .filter(|(s, _)| s == ssm)
            .map(|(_, f)| *f)
            .collect()
    }

    /// Corrections in effect (over every SSM).
    pub fn len(&self) -> usize {
        self.marks.len()
    }

    /// Whether there is no correction.
    pub fn is_empty(&self) -> bool {
        self.marks.is_empty()
    }

    /// Whether edits were made since the last export (they are safe in the journal either way).
    pub fn unexported(&self) -> bool {
        self.since_export > 0
    }

    /// One undoable edit: sets each `(ssm, frame)` to its mark (`None`: back to the original).
    /// The journal is written and synced first; if that fails nothing changes. Changes that
    /// change nothing are dropped; an edit of no change is not recorded (`Ok(false)`).
    pub fn edit(&mut self, label: &str, changes: &[(String, usize, Option<Mark>)]) -> Result<bool> {
        let mut out: Vec<Change> = Vec::new();
        for (s, f, after) in changes {
            if *f >= self.frames {
                return Err(Error::InvalidParameter(format!(
                    "frame {} is beyond the sequence's {} frames",
                    f + 1,
                    self.frames
                )));
            }
            let ssm = ssm_key(s)?;
            if let Some(m) = after {
                journal::check_mark(m)
                    .map_err(|e| Error::InvalidRegion(format!("frame {}: {e}", f + 1)))?;
            }
            // The state before this edit (an earlier change of the same frame counts).
            let before = out
                .iter()
                .rev()
                .find(|c| c.ssm == ssm && c.frame == *f)
                .map(|c| c.after)
                .unwrap_or_else(|| self.mark(&ssm, *f));
            if before != *after {
                out.push(Change {
                    ssm,
                    frame: *f,
                    before,
                    after: *after,
                });
            }
        }
        if out.is_empty() {
            return Ok(false);
        }
        let e = Edit {
            id: self.next_id,
            label: label.to_string(),
            changes: out,
        };
        self.log(&Record::Edit {
            id: e.id,
            label: e.label.clone(),
            changes: e.changes.clone(),
        })?;
        self.next_id += 1;
        self.set(&e, false);
        self.done.push(e);
        self.undone.clear();
        self.since_export += 1;
        Ok(true)
    }

    /// Undoes the last edit; returns its label and the frames it touched (`None`: nothing to
    /// undo).
    pub fn undo(&mut self) -> Result<Option<(String, Vec<usize>)>> {
        self.step_history(true)
    }

    /// Redoes the last undone edit.
    pub fn redo(&mut self) -> Result<Option<(String, Vec<usize>)>> {
        self.step_history(false)
    }

    /// Moves the last edit of one history (done for an undo, undone for a redo) to the other,
    /// journaled first.
    fn step_history(&mut self, undo: bool) -> Result<Option<(String, Vec<usize>)>> {
        let from = if undo { &self.done } else { &self.undone };
        let Some(id) = from.last().map(|e| e.id) else {
            return Ok(None);
        };
        self.log(&if undo {
            Record::Undo { id }
        } else {
            Record::Redo { id }
        })?;
        let popped = if undo {
            self.done.pop()
        } else {
            self.undone.pop()
        };
        let Some(e) = popped else {
            return Ok(None);
        };
        self.set(&e, undo);
        let out = (e.label.clone(), e.changes.iter().map(|c| c.frame).collect());
        if undo {
            self.undone.push(e);
        } else {
            self.done.push(e);
        }
        self.since_export += 1;
        Ok(Some(out))
    }

    /// Labels of the edits that can be undone (oldest first) and redone (next first).
    pub fn history(&self) -> (Vec<&str>, Vec<&str>) {
        (
            self.done.iter().map(|e| e.label.as_str()).collect(),
            self.undone.iter().rev().map(|e| e.label.as_str()).collect(),
        )
    }

    fn note_export(&mut self, paths: &[PathBuf]) -> Result<()> {
        self.log(&Record::Export {
            paths: paths.iter().map(|p| p.display().to_string()).collect(),
        })?;
        self.exported.extend(paths.iter().cloned());
        self.since_export = 0;
        Ok(())
    }

    /// Keeps a copy of each of `paths` that exists and that no export of this journal wrote
    /// (a dataset's own OptGT file, another annotator's export), beside it as
    /// `<name>.orig` (`.orig2`, ... when taken: not a `.txt` a dataset's listing would take for
    /// a sequence), before an export replaces it. Returns the copies made.
    fn keep_what_export_replaces(&self, paths: &[&Path]) -> Result<Vec<PathBuf>> {
        let mut kept = Vec::new();
        for &p in paths {
            if !p.is_file() || self.exported.contains(p) {
                continue;
            }
            let name = p.file_name().map(|s| s.to_string_lossy().into_owned());
            let name = name.unwrap_or_default();
            let copy = (1..)
                .map(|k| {
                    let n = if k == 1 { String::new() } else { k.to_string() };
                    p.with_file_name(format!("{name}.orig{n}"))
                })
                .find(|c| !c.exists())
                .expect("a free name");
            std::fs::copy(p, &copy).map_err(|e| Error::io(&copy, e))?;
            kept.push(copy);
        }
        Ok(kept)
    }
}

/// A sequence's ground truth with its corrections, as shown and exported.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GtFrame {
    /// Corners; `corrected` when they come from a correction.
    Quad { quad: Quad, corrected: bool },
    /// Marked occluded / not annotatable.
    Occluded,
    /// Not annotated (and not corrected).
    Missing,
}

impl GtFrame {
    /// The corners, if any.
    pub fn quad(&self) -> Option<Quad> {
        match self {
            GtFrame::Quad { quad, .. } => Some(*quad),
            _ => None,
        }
    }
}

/// The 8-DOF ground truth of every frame with its corrections.
pub fn full_ground_truth(seq: &Sequence, c: &Corrections) -> Vec<GtFrame> {
    (0..seq.len())
        .map(|f| match c.mark("homography", f) {
            Some(Mark::Quad(v)) => GtFrame::Quad {
                quad: Quad::from_array(v),
                corrected: true,
            },
            Some(Mark::Occluded) => GtFrame::Occluded,
            None => match seq.ground_truth(f) {
                Some(q) => GtFrame::Quad {
                    quad: q,
                    corrected: false,
                },
                None => GtFrame::Missing,
            },
        })
        .collect()
}

/// The ground truth of every frame in `ssm_name` with its corrections: a corrected frame as
/// corrected; otherwise the SSM's best fit (from the first annotated frame's quad) to the 8-DOF
/// ground truth (itself corrected where it was), with the fit's residual E_AL.
pub fn ground_truth_in(
    seq: &Sequence,
    c: &Corrections,
    ssm_name: &str,
) -> Result<(Vec<GtFrame>, Vec<Option<f64>>)> {
    let key = ssm_key(ssm_name)?;
    let full = full_ground_truth(seq, c);
    if key == "homography" {
        let n = full.len();
        return Ok((full, vec![Some(0.0); n]));
    }
    let quads: Vec<Option<Quad>> = full.iter().map(GtFrame::quad).collect();
    let low = fit_ground_truth(&key, &quads)?;
    let frames = (0..seq.len())
        .map(|f| match c.mark(&key, f) {
            Some(Mark::Quad(v)) => GtFrame::Quad {
                quad: Quad::from_array(v),
                corrected: true,
            },
            Some(Mark::Occluded) => GtFrame::Occluded,
            None => match (low.quads[f], full[f]) {
                (Some(q), _) => GtFrame::Quad {
                    quad: q,
                    corrected: false,
                },
                (None, GtFrame::Occluded) => GtFrame::Occluded,
                _ => GtFrame::Missing,
            },
        })
        .collect::<Vec<_>>();
    // Residuals of the fit against the (corrected) 8-DOF ground truth. A frame corrected by
    // hand in this SSM has none: the correction is the annotator's word, and where it fixed a
    // wrong original it would point "jump to worst" and the residual file at the fixed frame.
    let residuals = frames
        .iter()
        .zip(&quads)
        .map(|(g, full)| match (g, full) {
            (
                GtFrame::Quad {
                    corrected: true, ..
                },
                _,
            ) => None,
            (GtFrame::Quad { quad, .. }, Some(b)) => Some(alignment_error(quad, b)),
            _ => None,
        })
        .collect();
    Ok((frames, residuals))
}

/// Whether the sequence's ground-truth file names its frames (the MTF format) rather than
/// listing 8 numbers per line.
fn names_frames(seq: &Sequence) -> bool {
    match &seq.gt_path {
        Some(p) => read_ground_truth(p)
            .map(|e| !e.is_empty() && e.iter().all(|e| e.frame.is_some()))
            .unwrap_or(true),
        None => true,
    }
}

/// Writes the corrected ground truth of `ssm_name` atomically, in the sequence's own format
/// (`<gt folder>/<seq>_gt_<ssm>.txt`) and in OptGT layout (`<gt folder>/OptGT/<seq>_<ssm>.txt`
/// with its residuals); the original file is never written. A file it replaces that no export of
/// this journal wrote (a dataset's own OptGT file) is copied aside first (`<name>.orig`).
/// Records the export in the journal. Returns the files written, then the copies kept.
pub fn export(seq: &Sequence, c: &mut Corrections, ssm_name: &str) -> Result<Vec<PathBuf>> {
    let key = ssm_key(ssm_name)?;
    let (frames, residuals) = ground_truth_in(seq, c, &key)?;
    let quads: Vec<Option<Quad>> = frames.iter().map(GtFrame::quad).collect();
    let occluded: Vec<bool> = frames.iter().map(|f| *f == GtFrame::Occluded).collect();
    let dir = ground_truth_dir(seq);
    let names = fit::frame_names(seq);
    let own = dir.join(format!("{}_gt_{key}.txt", seq.name));
    if seq.gt_path.as_deref() == Some(own.as_path()) {
        return Err(Error::InvalidParameter(format!(
            "the export would overwrite the open ground truth {}: open the original sequence",
            own.display()
        )));
    }
    // Nothing another wrote is lost: a file the export replaces that no export of this
    // journal wrote is copied aside first.
    let opt = opt_gt_path(&dir, &seq.name, &key);
    let res = fit::opt_gt_residuals_path(&dir, &seq.name, &key);
    let kept = c.keep_what_export_replaces(&[&own, &opt, &res])?;
    write_ground_truth(
        &own,
        &quads,
        &occluded,
        names_frames(seq).then_some(names.as_slice()),
    )?;
    let low = LowDofGroundTruth {
        ssm: key.clone(),
        quads,
        residuals,
    };
    let (opt, res) = write_opt_gt(&dir, seq, &low, &occluded)?;
    let paths = vec![own, opt, res];
    c.note_export(&paths)?;
    Ok(paths.into_iter().chain(kept).collect())
}

/// Interpolates between two key frames in `ssm_name`'s parameter space: the frames strictly
/// between `a` and `b` get the SSM warp (of `qa`) whose parameters move linearly from identity
/// to the warp taking `qa` to `qb`. `None` when the SSM cannot relate the two quads.
pub fn interpolate(
    ssm_name: &str,
    a: (usize, Quad),
    b: (usize, Quad),
) -> Result<Option<Vec<(usize, Quad)>>> {
    let m = quad_model(ssm_name)?;
    let ((fa, qa), (fb, qb)) = if a.0 <= b.0 { (a, b) } else { (b, a) };
    let Some(p) = m.fit(&qa.0, &qb.0) else {
        return Ok(None);
    };
    let id = m.identity();
    let mut out = Vec::new();
    for f in fa + 1..fb {
        let t = (f - fa) as f64 / (fb - fa) as f64;
        let mut q = id;
        for k in 0..m.dof() {
            q[k] = id[k] + t * (p[k] - id[k]);
        }
        out.push((f, ssm::warp_quad(&*m, &q, &qa)));
    }
    Ok(Some(out))
}

#[cfg(test)]
mod tests;

/// Why a propagation stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum PropagateStop {
    /// At a frame the user corrected before (not overwritten).
    Corrected(usize),
    /// The tracker's error against the old ground truth jumped at this frame (not proposed).
    Jump { frame: usize, from: f64, to: f64 },
    /// The tracker lost the target at this frame.
    Lost(usize),
    /// From this frame on the old ground truth agrees with the tracker again (within
    /// [`PropagateLimits::agree_px`] for [`PropagateLimits::agree_frames`] frames): the frames
    /// from here are kept as they are.
    Agrees(usize),
    /// The proposal reached its length limit or the end of the sequence.
    End,
    /// A frame could not be read (the message names it).
    Frame(String),
}

impl std::fmt::Display for PropagateStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PropagateStop::Corrected(k) => {
                write!(f, "stopped before frame {}, corrected earlier", k + 1)
            }
            PropagateStop::Jump { frame, from, to } => write!(
                f,
                "stopped at frame {}: the error against the old ground truth jumped from {from:.2} to {to:.2} px",
                frame + 1
            ),
            PropagateStop::Lost(k) => write!(f, "the tracker lost the target at frame {}", k + 1),
            PropagateStop::Agrees(k) => write!(
                f,
                "stopped before frame {}: the old ground truth agrees with the tracker from there",
                k + 1
            ),
            PropagateStop::End => write!(f, "reached the end"),
            PropagateStop::Frame(m) => write!(f, "stopped: {m}"),
        }
    }
}

/// A propagation's proposed corners for the frames after the start, and why it stopped.
#[derive(Clone, Debug, PartialEq)]
pub struct Proposal {
    pub frames: Vec<(usize, Quad)>,
    pub stop: PropagateStop,
}

/// When a propagation stops on its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PropagateLimits {
    /// A rise of the error against the old ground truth from one frame to the next above this
    /// (px) stops it.
    pub jump_px: f64,
    /// At most this many frames are proposed.
    pub max_frames: usize,
    /// The old ground truth is right again once it is within this (px) of the tracker ...
    pub agree_px: f64,
    /// ... on this many frames in a row (which are not proposed).
    pub agree_frames: usize,
}

impl Default for PropagateLimits {
    fn default() -> Self {
        PropagateLimits {
            jump_px: 5.0,
            max_frames: 500,
            agree_px: 1.0,
            agree_frames: 3,
        }
    }
}

/// Tracks forward from a corrected frame to propose corrections of the next ones: initialises
/// `spec` on frame `from` at `start`, then proposes the tracked corners of each next frame until
/// a frame for which `corrected` holds, a jump of the error against the `old` ground truth from
/// one tracked frame to the next, the old ground truth agreeing with the tracker again, the loss
/// of the target, or the length limit.
pub fn propagate(
    seq: &Sequence,
    spec: &crate::tracker::TrackerSpec,
    (from, start): (usize, Quad),
    old: &[Option<Quad>],
    corrected: &dyn Fn(usize) -> bool,
    limits: PropagateLimits,
) -> Result<Proposal> {
    let PropagateLimits {
        jump_px,
        max_frames,
        agree_px,
        agree_frames,
    } = limits;
    // Frames in a row (the newest last) on which the old ground truth agrees with the tracker.
    let mut agreeing = 0usize;
    use crate::tracker::{FrameInput, TrackStatus, Tracker};
    let mut tracker = Tracker::new(spec)?;
    // A tracker that reads colour is handed colour frames.
    let colour = tracker.channels() == 3;
    let img = seq.load_frame(from, colour)?;
    tracker.initialize(FrameInput::of(&img), &start)?;
    let mut frames = Vec::new();
    // The baseline is the first tracked frame's error: a correction moves the start away from
    // the old ground truth, and that offset is what the next frames inherit, not a jump.
    let mut prev_err: Option<f64> = None;
    let end = seq.len().min(from + 1 + max_frames);
    for f in from + 1..end {
        if corrected(f) {
            return Ok(Proposal {
                frames,
                stop: PropagateStop::Corrected(f),
            });
        }
        let img = match seq.load_frame(f, colour) {
            Ok(i) => i,
            Err(e) => {
                return Ok(Proposal {
                    frames,
                    stop: PropagateStop::Frame(e.to_string()),
                });
            }
        };
        // The first frame from where the old ground truth went (the tracker has no motion of
        // its own to predict yet).
        if frames.is_empty()
            && let Some(moved) = moved_as_before(old, f, &start)
        {
            tracker.set_corners(&moved)?;
        }
        let mut out = tracker.update(FrameInput::of(&img), &mut crate::observe::NoObserver);
        // Lost: once more from where the old ground truth says the target went (its motion
        // from the frame before, applied to the last proposed corners). A tracker started on
        // the selection has no motion to predict yet: on a brick wall moving 5 px a frame the
        // search from the last pose settled a brick off on the second frame, which a whole
        // track (predicting by then) did not.
        let last = frames.last().map_or(start, |&(_, q)| q);
        if out.status != TrackStatus::Tracking
            && let Some(moved) = moved_as_before(old, f, &last)
            && tracker.set_corners(&moved).is_ok()
        {
            out = tracker.update(FrameInput::of(&img), &mut crate::observe::NoObserver);
        }
        if out.status != TrackStatus::Tracking {
            return Ok(Proposal {
                frames,
                stop: PropagateStop::Lost(f),
            });
        }
        let err = old
            .get(f)
            .copied()
            .flatten()
            .map(|g| alignment_error(&out.corners, &g));
        if let (Some(a), Some(b)) = (prev_err, err)
            && b - a > jump_px
        {
            return Ok(Proposal {
                frames,
                stop: PropagateStop::Jump {
                    frame: f,
                    from: a,
                    to: b,
                },
            });
        }
        if err.is_some() {
            prev_err = err;
        }
        agreeing = match err {
            Some(e) if e <= agree_px => agreeing + 1,
            _ => 0,
        };
        frames.push((f, out.corners));
        if agree_frames > 0 && agreeing >= agree_frames {
            // The old ground truth is right again: its frames stay as they are.
            frames.truncate(frames.len() - agreeing);
            return Ok(Proposal {
                frames,
                stop: PropagateStop::Agrees(f + 1 - agreeing),
            });
        }
    }
    Ok(Proposal {
        frames,
        stop: PropagateStop::End,
    })
}

/// `last` (the corners proposed for frame `f - 1`) moved as the old ground truth moved from
/// frame `f - 1` to `f` (`None` where either is missing or the motion is degenerate).
fn moved_as_before(old: &[Option<Quad>], f: usize, last: &Quad) -> Option<Quad> {
    let (a, b) = (old.get(f.checked_sub(1)?)?.as_ref()?, old.get(f)?.as_ref()?);
    let h = crate::geometry::homography_between(a, b)?;
    let q = last.map(|p| crate::geometry::apply_homography(&h, p));
    (q.is_finite() && q.validate().is_ok()).then_some(q)
}
