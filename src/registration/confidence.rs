//! Knowing when the tracker is lost: the checks a frame's confidence must pass.
//!
//! The confidence of a frame is the block-wise correlation of the patch where the search ended
//! with the template ([`super::BlockCorrelation`]): near 1 on the target whatever the light,
//! near 0 on anything else. A frame is lost when its confidence is
//! - below `min_confidence` (the target is not there), or below `min_confidence + 0.1` when the
//!   search ran out of iterations without settling (a search that wanders ends on look-alikes:
//!   the next brick of a wall), or
//! - below `confidence_drop` times the median confidence of the last [`HISTORY`] frames tracked
//!   (a sudden fall: the search jumped to something that only resembles the target, while the
//!   light, blur or scale that lower the confidence slowly move the median with them), or
//! - its patch correlates (the same block-wise way) less than `min_frame_confidence` with the
//!   patch of the previous frame, when that frame was tracked. Light, blur and scale change
//!   little from one frame to the next, so on the target this stays near 1 (median 0.996 on the
//!   fast-motion renders, 0.98 on dim star fields) where the confidence against the template has
//!   fallen to 0.7-0.8; a slip to a look-alike (the next rows of a brick wall, whose confidence
//!   against the template is 0.6-0.8 too) makes it fall at once, or
//! - the tracker was lost before and the frame's confidence is below [`RESUME`] times the
//!   median: a target found again must look almost as it did before the loss.
//!
//! Only frames tracked on from a tracked frame join the median, so a look-alike found after a
//! loss does not lower it.
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
/// The fraction of the reference confidence a frame found again after a loss needs.
pub const RESUME: f64 = 0.85;

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

    /// Whether a frame is tracked (see the module's header for the rules); a frame tracked on
    /// from a tracked previous frame joins the history.
    pub fn judge(&mut self, frame: &Judged, params: &TrackerParams) -> Result<(), LossReason> {
        self.check(frame, params)?;
        // Only frames tracked on from a tracked one: frames found again after a loss would let
        // a look-alike's level into the reference.
        if frame.frame_confidence.is_none() {
            return Ok(());
        }
        if self.recent.len() == HISTORY {
            self.recent.pop_front();
        }
        self.recent.push_back(frame.confidence);
        Ok(())
    }

    /// Whether a frame would be tracked, leaving the history as it is.
    pub fn check(&self, frame: &Judged, params: &TrackerParams) -> Result<(), LossReason> {
        let Judged {
            confidence,
            frame_confidence,
            converged,
            resuming,
        } = *frame;
        // At -1 the floor is off, for every frame.
        let floor = if converged || params.min_confidence <= -1.0 {
            params.min_confidence
        } else {
            params.min_confidence + UNCONVERGED_MARGIN
        };
        let reference = self.reference();
        let drop = match reference {
            Some(r) if params.confidence_drop > 0.0 => params.confidence_drop * r,
            _ => f64::NEG_INFINITY,
        };
        // Coming back after a loss: the match must look almost as much like the template as the
        // track did before it (a look-alike, the next rows of a brick wall, passes the floor).
        let resume = match reference {
            Some(r) if resuming && params.confidence_drop > 0.0 => RESUME * r,
            _ => f64::NEG_INFINITY,
        };
        let ok = confidence >= floor
            && confidence >= drop
            && confidence >= resume
            && frame_confidence.is_none_or(|c| c >= params.min_frame_confidence);
        if ok {
            Ok(())
        } else {
            Err(LossReason::LowConfidence)
        }
    }
}

/// What the checks judge a frame by.
#[derive(Clone, Copy, Debug)]
pub struct Judged {
    /// The patch's confidence against the template.
    pub confidence: f64,
    /// Its correlation with the last tracked frame's patch (`None` after an initialisation, a
    /// move by hand or a loss).
    pub frame_confidence: Option<f64>,
    /// Whether the search settled.
    pub converged: bool,
    /// Whether the tracker was lost before this frame.
    pub resuming: bool,
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

    /// A frame tracked on from a tracked one, whose patch matches the previous frame's.
    fn f(confidence: f64, converged: bool) -> Judged {
        Judged {
            confidence,
            frame_confidence: Some(0.99),
            converged,
            resuming: false,
        }
    }

    #[test]
    fn a_frame_is_lost_below_the_floor_or_after_a_sudden_fall() {
        let p = params(0.6, 0.8);
        let mut c = LossCheck::default();
        assert_eq!(c.judge(&f(0.59, true), &p), Err(LossReason::LowConfidence));
        // Not converged: 0.1 more is needed.
        assert_eq!(c.judge(&f(0.65, false), &p), Err(LossReason::LowConfidence));
        for _ in 0..HISTORY {
            assert_eq!(c.judge(&f(0.95, true), &p), Ok(()));
        }
        assert_eq!(c.reference(), Some(0.95));
        // 0.8 x 0.95 = 0.76: a fall to 0.7 is a loss, a slow decline is not.
        assert_eq!(c.judge(&f(0.70, true), &p), Err(LossReason::LowConfidence));
        let mut v = 0.95;
        while v > 0.62 {
            v -= 0.01;
            assert_eq!(c.judge(&f(v, true), &p), Ok(()), "{v}");
        }
        // NaN never passes.
        assert_eq!(
            c.judge(&f(f64::NAN, true), &p),
            Err(LossReason::LowConfidence)
        );
        c.reset();
        assert_eq!(c.reference(), None);
    }

    #[test]
    fn a_patch_unlike_the_previous_frames_is_lost_and_a_target_found_again_must_look_as_before() {
        let p = params(0.5, 0.75);
        let mut c = LossCheck::default();
        for _ in 0..HISTORY {
            assert_eq!(c.judge(&f(0.95, true), &p), Ok(()));
        }
        // A look-alike: as like the template as the light could make the target (0.8), but not
        // like the previous frame's patch.
        let slip = Judged {
            frame_confidence: Some(0.6),
            ..f(0.8, true)
        };
        assert_eq!(c.judge(&slip, &p), Err(LossReason::LowConfidence));
        // Found again after the loss (no previous frame): 0.8 < 0.85 x 0.95 is not enough...
        let found = |confidence| Judged {
            confidence,
            frame_confidence: None,
            converged: true,
            resuming: true,
        };
        assert_eq!(c.judge(&found(0.8), &p), Err(LossReason::LowConfidence));
        // ...0.9 is, and it does not join the reference: the next look-alike is judged against
        // the track's own level.
        assert_eq!(c.judge(&found(0.9), &p), Ok(()));
        assert_eq!(c.reference(), Some(0.95));
        // The frame check is off at -1.
        let off = TrackerParams {
            min_frame_confidence: -1.0,
            ..p.clone()
        };
        assert_eq!(c.judge(&slip, &off), Ok(()));
    }

    #[test]
    fn the_checks_are_off_at_their_limits() {
        let p = TrackerParams {
            min_frame_confidence: -1.0,
            ..params(-1.0, 0.0)
        };
        let mut c = LossCheck::default();
        for v in [1.0, -1.0, 0.0, -1.0] {
            let j = Judged {
                confidence: v,
                frame_confidence: Some(-1.0),
                converged: false,
                resuming: true,
            };
            assert_eq!(c.judge(&j, &p), Ok(()));
        }
    }
}
