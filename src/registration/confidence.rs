//! Knowing when the tracker is lost: the checks a frame's confidence must pass.
//!
//! The confidence of a frame is the block-wise correlation of the patch where the search ended
//! with the template ([`crate::am::BlockCorrelation`]): near 1 on the target whatever the light,
//! near 0 on anything else. A frame is lost when its confidence is
//! - below `min_confidence` (the target is not there), or below `min_confidence + 0.1` when the
//!   search ran out of iterations without settling (a search that wanders ends on look-alikes:
//!   the next brick of a wall), or
//! - below `confidence_drop` times the median confidence of the last [`HISTORY`] frames tracked
//!   (a sudden fall: the search jumped to something that only resembles the target, while the
//!   light, blur or scale that lower the confidence slowly move the median with them).
//!
//! The checks apply to SSMs that model scale ([`MIN_DOF`] and more: similitude, affine,
//! homography). A translation or isometry tracker follows a target that zooms or turns while its
//! patch stops matching the template: on the evidence set, against its own low-DOF ground truth,
//! the checks reported 3 % of such frames within 5 px lost and cost 0.05-0.07 of SR@5.
//!
//! Chosen on the evidence set, the lit sequences and the fast-motion renders (docs/robustness.md,
//! "Knowing when it is lost").

use crate::spec::TrackerParams;
use crate::status::LossReason;
use std::collections::VecDeque;

/// The fewest DOF of an SSM whose tracker's confidence is checked.
pub const MIN_DOF: usize = 4;

/// Frames whose confidence the reference is the median of.
pub const HISTORY: usize = 10;
/// How much more confidence a frame needs when its search did not converge.
pub const UNCONVERGED_MARGIN: f64 = 0.1;

/// The recent confidences of a track.
#[derive(Clone, Debug)]
pub struct LossCheck {
    recent: VecDeque<f64>,
}

impl Default for LossCheck {
    fn default() -> Self {
        LossCheck {
            recent: VecDeque::with_capacity(HISTORY),
        }
    }
}

impl LossCheck {
    /// Forgets the track (a new initialisation, or corners set by hand).
    pub fn reset(&mut self) {
        self.recent.clear();
    }

    /// The median confidence of the last frames tracked (`None` before the first).
    pub fn reference(&self) -> Option<f64> {
        let n = self.recent.len();
        if n == 0 {
            return None;
        }
        // On the stack: a frame's update does not allocate.
        let mut v = [0.0; HISTORY];
        for (d, s) in v.iter_mut().zip(&self.recent) {
            *d = *s;
        }
        v[..n].sort_by(f64::total_cmp);
        Some(v[n / 2])
    }

    /// Whether a frame of `confidence` (whose search converged or not) is tracked; a tracked
    /// frame's confidence joins the history.
    pub fn judge(
        &mut self,
        confidence: f64,
        converged: bool,
        params: &TrackerParams,
    ) -> Result<(), LossReason> {
        // At -1 the floor is off, for every frame.
        let floor = if converged || params.min_confidence <= -1.0 {
            params.min_confidence
        } else {
            params.min_confidence + UNCONVERGED_MARGIN
        };
        let drop = match self.reference() {
            Some(r) if params.confidence_drop > 0.0 => params.confidence_drop * r,
            _ => f64::NEG_INFINITY,
        };
        if !(confidence >= floor && confidence >= drop) {
            return Err(LossReason::LowConfidence);
        }
        if self.recent.len() == HISTORY {
            self.recent.pop_front();
        }
        self.recent.push_back(confidence);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(min: f64, drop: f64) -> TrackerParams {
        TrackerParams {
            min_confidence: min,
            confidence_drop: drop,
            ..TrackerParams::default()
        }
    }

    #[test]
    fn a_frame_is_lost_below_the_floor_or_after_a_sudden_fall() {
        let p = params(0.6, 0.8);
        let mut c = LossCheck::default();
        assert_eq!(c.judge(0.59, true, &p), Err(LossReason::LowConfidence));
        // Not converged: 0.1 more is needed.
        assert_eq!(c.judge(0.65, false, &p), Err(LossReason::LowConfidence));
        for _ in 0..HISTORY {
            assert_eq!(c.judge(0.95, true, &p), Ok(()));
        }
        assert_eq!(c.reference(), Some(0.95));
        // 0.8 x 0.95 = 0.76: a fall to 0.7 is a loss, a slow decline is not.
        assert_eq!(c.judge(0.70, true, &p), Err(LossReason::LowConfidence));
        let mut v = 0.95;
        while v > 0.62 {
            v -= 0.01;
            assert_eq!(c.judge(v, true, &p), Ok(()), "{v}");
        }
        // NaN never passes.
        assert_eq!(c.judge(f64::NAN, true, &p), Err(LossReason::LowConfidence));
        c.reset();
        assert_eq!(c.reference(), None);
    }

    #[test]
    fn the_checks_are_off_at_their_limits() {
        let p = params(-1.0, 0.0);
        let mut c = LossCheck::default();
        for v in [1.0, -1.0, 0.0, -1.0] {
            assert_eq!(c.judge(v, false, &p), Ok(()));
        }
    }
}
