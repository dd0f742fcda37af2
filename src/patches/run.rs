//! A run of the many-patch tracker over a sequence, and its accuracy against the sequence's
//! ground truth.

use super::*;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::{Point, apply_homography, homography_between};
use std::path::Path;
use std::time::{Duration, Instant};

/// A run of the many-patch tracker over a sequence.
#[derive(Clone, Debug, Default)]
pub struct PatchRun {
    /// The sequence's frame the run started on (`frames[0]`).
    pub first: usize,
    /// Per frame, every patch's state.
    pub frames: Vec<Vec<PatchState>>,
    /// Time spent tracking (pre-processing and searching; not reading frames), per frame
    /// after the first.
    pub times: Vec<Duration>,
}

impl PatchRun {
    /// Patches (those of the first frame).
    pub fn patches(&self) -> usize {
        self.frames.first().map_or(0, |f| f.len())
    }

    /// Patch updates per second of tracking: patches searched, over the tracking time.
    pub fn updates_per_second(&self) -> f64 {
        // Every frame but the last is searched from in the next one.
        let before_last = &self.frames[..self.frames.len().saturating_sub(1)];
        let searched: usize = before_last
            .iter()
            .map(|f| f.iter().filter(|s| s.tracking()).count())
            .sum();
        let t: f64 = self.times.iter().map(|d| d.as_secs_f64()).sum();
        if t > 0.0 { searched as f64 / t } else { 0.0 }
    }

    /// The mean and median forward-backward error (pixels) over every patch update that
    /// measured one (`fb_max` > 0); `None` when none did.
    pub fn forward_backward_errors(&self) -> Option<(f64, f64)> {
        let e: Vec<f64> = self
            .frames
            .iter()
            .flatten()
            .filter_map(|s| s.fb_error)
            .collect();
        if e.is_empty() {
            return None;
        }
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        Some((mean, crate::linalg::median(e)))
    }

    /// Mean iterations per patch update (all levels together).
    pub fn iterations_per_update(&self) -> f64 {
        let (mut it, mut n) = (0usize, 0usize);
        for f in self.frames.iter().skip(1) {
            for s in f.iter().filter(|s| s.iterations > 0) {
                it += s.iterations;
                n += 1;
            }
        }
        if n == 0 { 0.0 } else { it as f64 / n as f64 }
    }

    /// Frames per second of tracking (median frame time).
    pub fn frames_per_second(&self) -> f64 {
        let mut t: Vec<f64> = self.times.iter().map(|d| d.as_secs_f64()).collect();
        if t.is_empty() {
            return 0.0;
        }
        t.sort_by(f64::total_cmp);
        let m = t[t.len() / 2];
        if m > 0.0 { 1.0 / m } else { 0.0 }
    }
}

/// Where the patches start.
#[derive(Clone, Debug)]
pub enum PatchSeeds {
    /// These points of the first frame.
    Points(Vec<Point>),
    /// The strongest Shi-Tomasi corners of the first frame, at most this many: inside the
    /// first ground-truth quad when the sequence has one, else anywhere.
    Corners(usize),
}

/// Reads points, one `x,y` (or `x y`) per line; `#` starts a comment. A malformed line is an
/// error naming the file and the line.
pub fn read_points(path: &Path) -> Result<Vec<Point>> {
    let text = crate::files::read_text(path, crate::files::TEXT_LIMIT)?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let v: Vec<f64> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| t.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .filter(|v: &Vec<f64>| v.len() == 2)
            .ok_or_else(|| Error::Parse {
                path: path.to_path_buf(),
                line: n + 1,
                message: format!("expected two finite numbers x,y, got '{line}'"),
            })?;
        points.push(Point { x: v[0], y: v[1] });
    }
    Ok(points)
}

/// Tracks patches over `seq` from its first frame; `progress` sees each frame's index.
pub fn track_sequence(
    seq: &Sequence,
    params: &PatchParams,
    seeds: &PatchSeeds,
    progress: &mut dyn FnMut(usize),
) -> Result<PatchRun> {
    track_sequence_from(seq, 0, params, seeds, progress)
}

/// [`track_sequence`] from frame `start` (corners are then detected in that frame's ground
/// truth, when it has one).
pub fn track_sequence_from(
    seq: &Sequence,
    start: usize,
    params: &PatchParams,
    seeds: &PatchSeeds,
    progress: &mut dyn FnMut(usize),
) -> Result<PatchRun> {
    let mut t = PatchTracker::new(params.clone())?;
    let first = seq.load_gray(start)?;
    let points = match seeds {
        PatchSeeds::Points(p) => p.clone(),
        PatchSeeds::Corners(0) => {
            return Err(Error::InvalidParameter(
                "patches: track at least one patch (--patches 0 asks for none)".into(),
            ));
        }
        PatchSeeds::Corners(n) => {
            let region = seq.ground_truth(start);
            t.detect(&first, *n, region.as_ref())
        }
    };
    t.initialize(&first, &points)?;
    let mut run = PatchRun {
        first: start,
        ..PatchRun::default()
    };
    run.frames.push(t.states().copied().collect());
    progress(start);
    for i in start + 1..seq.len() {
        let frame = seq.load_gray(i)?;
        let start = Instant::now();
        t.update(&frame)?;
        run.times.push(start.elapsed());
        run.frames.push(t.states().copied().collect());
        progress(i);
    }
    Ok(run)
}

/// How well patch tracks follow a sequence's ground truth: each patch's true position in a
/// frame is its first-frame centre carried by the homography between the two frames'
/// ground-truth quads (right for points on the planar target).
#[derive(Clone, Debug, PartialEq)]
pub struct PatchAccuracy {
    /// Patches scored (those whose start is inside the first ground-truth quad).
    pub patches: usize,
    /// Mean and median distance to the truth over every tracked patch and frame (pixels).
    pub mean_error: f64,
    pub median_error: f64,
    /// Patches still tracked at the last frame, and how many of those are within 2 px of
    /// the truth there.
    pub tracked_at_end: usize,
    pub within_2px_at_end: usize,
    /// The fraction of patch-frames tracked.
    pub tracked_fraction: f64,
}

/// Scores `run` against `seq`'s ground truth (`None` without one on the first frame).
pub fn accuracy(run: &PatchRun, seq: &Sequence) -> Option<PatchAccuracy> {
    let q0 = seq.ground_truth(run.first)?;
    let starts: Vec<(usize, Point)> = run
        .frames
        .first()?
        .iter()
        .enumerate()
        .filter(|(_, s)| s.tracking() && inside(&q0, s.centre))
        .map(|(k, s)| (k, s.centre))
        .collect();
    let mut errors = Vec::new();
    let (mut tracked, mut total) = (0usize, 0usize);
    let (mut at_end, mut near_end) = (0, 0);
    let last = run.frames.len().saturating_sub(1);
    for (i, states) in run.frames.iter().enumerate().skip(1) {
        let Some(h) = seq
            .ground_truth(run.first + i)
            .and_then(|q| homography_between(&q0, &q))
        else {
            continue;
        };
        for &(k, p0) in &starts {
            total += 1;
            let Some(s) = states.get(k) else { continue };
            if !s.tracking() {
                continue;
            }
            tracked += 1;
            let e = s.centre.dist(apply_homography(&h, p0));
            if e.is_finite() {
                errors.push(e);
            }
            if i == last {
                at_end += 1;
                if e <= 2.0 {
                    near_end += 1;
                }
            }
        }
    }
    let mean = if errors.is_empty() {
        0.0
    } else {
        errors.iter().sum::<f64>() / errors.len() as f64
    };
    Some(PatchAccuracy {
        patches: starts.len(),
        mean_error: mean,
        median_error: if errors.is_empty() {
            0.0
        } else {
            crate::linalg::median(errors)
        },
        tracked_at_end: at_end,
        within_2px_at_end: near_end,
        tracked_fraction: if total == 0 {
            0.0
        } else {
            tracked as f64 / total as f64
        },
    })
}
