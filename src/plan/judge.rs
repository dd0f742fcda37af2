//! The loss-of-track checks on where a frame's plan ended, and what a tracked frame leaves for
//! the next: the quad must be finite, convex, of a plausible area and in or near the frame;
//! then (for SSMs that model scale, [`MIN_DOF`]) the confidences must pass the track's
//! [`crate::registration::LossCheck`]. A frame that passes becomes the next frame's previous
//! patch.

use super::tracker::CONFIDENCE_BLOCKS;
use super::{Estimate, RegistrationTracker};
use crate::geometry::Quad;
use crate::registration::{Judged, MIN_DOF};
use crate::status::{LossReason, TrackStatus};
use crate::visual_tracker::FrameInput;

/// A frame's run of the plan: where it ended, or why it failed (with where it ended when a
/// check failed).
pub type SearchResult = std::result::Result<Estimate, (LossReason, Option<Estimate>)>;

/// The confidence a frame's run ended with (the lowest for a run that failed before any end).
pub fn confidence_of(r: &SearchResult) -> f64 {
    match r {
        Ok(o) | Err((_, Some(o))) => o.confidence.unwrap_or(f64::NAN),
        Err((_, None)) => f64::NEG_INFINITY,
    }
}

/// The more confident of two runs of a frame (the first on a tie).
// By value: a frame's update does not allocate.
#[allow(clippy::result_large_err)]
pub fn more_confident(a: SearchResult, b: SearchResult) -> SearchResult {
    if confidence_of(&b) > confidence_of(&a) {
        b
    } else {
        a
    }
}

/// The iterations a frame's run took (none for a run that failed before any end).
pub fn iterations_of(r: &SearchResult) -> usize {
    match r {
        Ok(o) | Err((_, Some(o))) => o.iterations,
        Err((_, None)) => 0,
    }
}

/// The checks on a frame's final quad in a `fw x fh` frame, against the track's initial area.
pub fn check_quad(q: &Quad, initial_area: f64, (fw, fh): (usize, usize)) -> Result<(), LossReason> {
    if !q.is_finite() {
        return Err(LossReason::NonFinite);
    }
    let area = q.signed_area().abs();
    if !q.is_convex() || area < initial_area / 100.0 || area > initial_area * 100.0 {
        return Err(LossReason::Degenerate);
    }
    if q.centroid().far_outside(fw, fh) {
        return Err(LossReason::OutOfFrame);
    }
    Ok(())
}

impl RegistrationTracker {
    /// A frame's run judged: an end that fails the checks becomes a failure with that end.
    // Returned by value: a frame's update does not allocate.
    #[allow(clippy::result_large_err)]
    pub(super) fn judge(&mut self, result: SearchResult, size: (usize, usize)) -> SearchResult {
        result.and_then(|out| {
            let confidence = self.finest.ctx.dof() >= MIN_DOF;
            self.accept(&out, size, confidence)
                .map(|()| out)
                .map_err(|r| (r, Some(out)))
        })
    }

    /// Whether a frame's run would be tracked (the checks of [`RegistrationTracker::judge`],
    /// nothing kept).
    pub(super) fn passes(&self, result: &SearchResult, size: (usize, usize)) -> bool {
        let Ok(out) = result else {
            return false;
        };
        check_quad(&out.corners, self.initial_area, size).is_ok()
            && (self.finest.ctx.dof() < MIN_DOF
                || self.loss.check(&self.judged(out), &self.params).is_ok())
    }

    /// What the confidence checks judge `out` by.
    fn judged(&self, out: &Estimate) -> Judged {
        Judged {
            confidence: out.confidence.unwrap_or(f64::NAN),
            frame_confidence: out.frame_confidence,
            converged: out.converged,
            resuming: self.status != TrackStatus::Tracking,
        }
    }

    /// The checks a frame's end must pass to be tracked: its quad's, then (if `confidence`)
    /// its confidence's, which a passing frame joins the history of.
    pub(super) fn accept(
        &mut self,
        out: &Estimate,
        size: (usize, usize),
        confidence: bool,
    ) -> Result<(), LossReason> {
        check_quad(&out.corners, self.initial_area, size)?;
        if confidence {
            let judged = self.judged(out);
            self.loss.judge(&judged, &self.params)?;
        }
        Ok(())
    }

    /// Keeps the patch where a tracked frame ended as the next frame's previous patch.
    pub(super) fn remember_patch(&mut self, input: FrameInput<'_>, out: &Estimate) {
        // The frame's last search may have pre-processed another region (a second start, a
        // candidate of the frame search): the patch is sampled where the accepted one ended.
        self.src.hold(input, &out.corners, self.params.roi_margin);
        let view = self.src.view(input, 0);
        let ctx = &mut self.finest.ctx;
        ctx.whole_patch_at(&view, &out.params);
        let res = self.params.res;
        let judges = &mut self.judges;
        let values = ctx.whole_values();
        match &judges.sums {
            // The patch both confidences were just made of: its sums are there.
            (Some(made), sums) if *made == ctx.work().samples() => judges
                .previous
                .set_template_from(values, res, CONFIDENCE_BLOCKS, sums),
            _ => judges.previous.set_template(values, res, CONFIDENCE_BLOCKS),
        }
        judges.has_previous = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quad_is_lost_when_not_finite_folded_of_another_size_or_far_outside() {
        let q = Quad::from_rect(10.0, 10.0, 20.0, 20.0);
        let area = 400.0;
        let size = (100, 80);
        assert_eq!(check_quad(&q, area, size), Ok(()));
        let mut nan = q;
        nan.0[1].x = f64::NAN;
        assert_eq!(check_quad(&nan, area, size), Err(LossReason::NonFinite));
        let mut folded = q;
        folded.0.swap(1, 2);
        assert_eq!(check_quad(&folded, area, size), Err(LossReason::Degenerate));
        let tiny = Quad::from_rect(10.0, 10.0, 1.0, 1.0);
        assert_eq!(check_quad(&tiny, area, size), Err(LossReason::Degenerate));
        let huge = Quad::from_rect(0.0, 0.0, 300.0, 300.0);
        assert_eq!(check_quad(&huge, area, size), Err(LossReason::Degenerate));
        let away = Quad::from_rect(200.0, 10.0, 20.0, 20.0);
        assert_eq!(check_quad(&away, area, size), Err(LossReason::OutOfFrame));
        // Half a frame beyond its edge is still near enough.
        let near = Quad::from_rect(130.0, -40.0, 20.0, 20.0);
        assert_eq!(check_quad(&near, area, size), Ok(()));
    }
}
