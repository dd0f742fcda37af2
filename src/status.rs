//! What a tracker reports about a frame: whether it follows its target, why it lost it, where
//! the time went. Shared by the trackers, the observer and the evaluation.

use crate::geometry::Quad;
use serde::{Deserialize, Serialize};

/// Why a tracker lost the target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LossReason {
    /// A parameter, a corner or the similarity became NaN or infinite.
    NonFinite,
    /// The Newton system could not be solved (flat patch, degenerate Jacobian).
    Singular,
    /// The quad folded over, or its area changed by more than a factor of 100.
    Degenerate,
    /// The quad's centre left the frame by more than half a frame.
    OutOfFrame,
    /// A tracker with its own detector found the target neither by tracking nor by detection
    /// (it keeps searching and reports `Tracking` again when it finds it).
    NotFound,
    /// The patch where the search ended no longer looks like the template: its confidence (the
    /// zero-mean normalised cross-correlation with the template) fell below `min_confidence`.
    LowConfidence,
}

impl LossReason {
    /// Every reason, in the order of declaration.
    pub const ALL: [LossReason; 6] = [
        LossReason::NonFinite,
        LossReason::Singular,
        LossReason::Degenerate,
        LossReason::OutOfFrame,
        LossReason::NotFound,
        LossReason::LowConfidence,
    ];

    /// The reason's key in files (its serde name: `non_finite`, `out_of_frame`...).
    pub fn key(self) -> &'static str {
        match self {
            LossReason::NonFinite => "non_finite",
            LossReason::Singular => "singular",
            LossReason::Degenerate => "degenerate",
            LossReason::OutOfFrame => "out_of_frame",
            LossReason::NotFound => "not_found",
            LossReason::LowConfidence => "low_confidence",
        }
    }

    /// The reason whose [`LossReason::key`] is `key`.
    pub fn from_key(key: &str) -> Option<LossReason> {
        LossReason::ALL.into_iter().find(|r| r.key() == key)
    }
}

impl std::fmt::Display for LossReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LossReason::NonFinite => "non-finite values",
            LossReason::Singular => "singular system",
            LossReason::Degenerate => "degenerate quad",
            LossReason::OutOfFrame => "out of frame",
            LossReason::NotFound => "not found",
            LossReason::LowConfidence => "low confidence",
        })
    }
}

/// Whether a tracker follows its target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "status", content = "reason")]
pub enum TrackStatus {
    /// Not initialised yet.
    Uninitialized,
    /// Tracking.
    Tracking,
    /// The target was lost; the tracker stays lost until it is initialised again.
    Lost(LossReason),
}

/// The result of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameOutcome {
    /// Frame index since initialisation (the initialisation frame is 0).
    pub frame: usize,
    pub status: TrackStatus,
    /// The corners: the new estimate, or the last good one when lost (always finite).
    pub corners: Quad,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the stop test was met before the iteration limit.
    pub converged: bool,
    /// The similarity before the last iteration's step.
    pub similarity: f64,
    /// Whether the tracker searched this frame (`false` when it was idle: not initialised, or
    /// lost with `on_loss=stop`).
    pub searched: bool,
    /// Where the search ended, also when a check then rejected it and the status is `Lost`
    /// (`None` when it did not search or its values were not finite).
    pub estimate: Option<Quad>,
    /// How much the patch at `estimate` looks like the template, in -1..1: their zero-mean
    /// normalised cross-correlation, insensitive to gain and bias (`None` for trackers that do
    /// not compute it).
    pub confidence: Option<f64>,
    /// Time spent pre-processing (smoothing the region read) and searching.
    pub timing: FrameTiming,
}

impl FrameOutcome {
    /// The outcome of a frame a tracker did not search (not initialised, or lost and stopped):
    /// its status and corners as they are.
    pub fn idle(frame: usize, status: TrackStatus, corners: Quad) -> Self {
        FrameOutcome {
            frame,
            status,
            corners,
            iterations: 0,
            converged: false,
            similarity: f64::NAN,
            searched: false,
            estimate: None,
            confidence: None,
            timing: FrameTiming::default(),
        }
    }
}

/// Where the time of one update went.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameTiming {
    /// Conversion and smoothing of the region the tracker reads (zero for smoothed input).
    pub preprocess: std::time::Duration,
    /// The search method's iterations (what MTF reports as the tracker's speed).
    pub search: std::time::Duration,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_loss_reason_is_listed_once_and_its_key_is_its_serde_name() {
        for (i, r) in LossReason::ALL.into_iter().enumerate() {
            // A new variant fails to compile here until it is given its place in `ALL`.
            let place = match r {
                LossReason::NonFinite => 0,
                LossReason::Singular => 1,
                LossReason::Degenerate => 2,
                LossReason::OutOfFrame => 3,
                LossReason::NotFound => 4,
                LossReason::LowConfidence => 5,
            };
            assert_eq!(place, i);
            let serde = serde_json::to_string(&r).unwrap();
            assert_eq!(serde, format!("\"{}\"", r.key()));
            assert_eq!(LossReason::from_key(r.key()), Some(r));
        }
        assert_eq!(LossReason::from_key("tracking"), None);
    }
}
