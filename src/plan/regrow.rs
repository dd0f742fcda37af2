//! A frame's run of the plan, and the policy on its outcome: the frame's region is
//! pre-processed around where it starts (only the part around the start at first, when every
//! stage allows it), the plan runs; when the search left the region, the frame is run again on
//! a larger one, and after a failure on the whole frame (once).

use super::judge::SearchResult;
use super::{Estimate, FrameRun, RegistrationTracker};
use crate::geometry::{Quad, Rect};
use crate::observe::Observer;
use crate::registration::{Executor, FrameSource, reads};
use crate::ssm::Params;
use crate::status::{FrameTiming, LossReason};
use crate::visual_tracker::FrameInput;
use std::time::Instant;

/// Pixels beyond the start's reads, on top of twice the last frame's motion, that a frame's
/// region is smoothed first when it is smoothed in parts.
const FIRST_PART_PX: f64 = 2.0;

/// Pixels from the region's edge within which a search's end is taken to have left it.
const EDGE_PX: f64 = 3.0;

/// Whether the box `b` of a search's end reached the edge of the pre-processed `region` where
/// the region is not the frame's edge (`fw x fh`).
fn escaped(b: &Rect, region: &Rect, (fw, fh): (usize, usize)) -> bool {
    (b.x0 - EDGE_PX < region.x0 && region.x0 > 0.0)
        || (b.y0 - EDGE_PX < region.y0 && region.y0 > 0.0)
        || (b.x1 + EDGE_PX > region.x1 && region.x1 < fw as f64)
        || (b.y1 + EDGE_PX > region.y1 && region.y1 < fh as f64)
}

impl RegistrationTracker {
    /// One frame's run of the plan from `start_params` (at `start_corners`), redone once on a
    /// larger region when it leaves the pre-processed one.
    // Returned by value: a frame's update does not allocate.
    #[allow(clippy::result_large_err)]
    pub(super) fn search_from(
        &mut self,
        input: FrameInput<'_>,
        start_params: Params,
        start_corners: &Quad,
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
    ) -> SearchResult {
        let (fw, fh) = input.size();
        let mut region = self.region_around(start_corners);
        let mut result: SearchResult = Err((LossReason::NonFinite, None));
        for attempt in 0..2 {
            self.finest.ctx.set_params(start_params);
            observer.frame_started(self.frame, start_corners);
            result = self
                .run_plan(input, region, observer, started, timing)
                .map_err(|r| (r, None));
            // The search left the pre-processed region (or failed in it): redo the frame once
            // on a larger region, or on the whole frame after a failure.
            if attempt == 0 && FrameSource::can_part(input) {
                let r = self.src.region();
                let whole = r.contains(&Rect::of_size(fw, fh));
                match &result {
                    Ok(out)
                        if out.corners.is_finite()
                            && escaped(&out.corners.bbox(), &r, (fw, fh)) =>
                    {
                        region = region.union(&self.region_around(&out.corners));
                        continue;
                    }
                    Err(_) if !whole => {
                        region = Rect::of_size(fw, fh);
                        continue;
                    }
                    _ => {}
                }
            }
            break;
        }
        result
    }

    /// The plan's run on one pre-processed region, from the finest problem's parameters.
    fn run_plan(
        &mut self,
        input: FrameInput<'_>,
        region: Rect,
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
    ) -> Result<Estimate, LossReason> {
        let t0 = Instant::now();
        // One level, one SSM and a method whose patches the plan sees: the region is smoothed
        // around where the frame starts first, and further only if the search goes there.
        let partial =
            self.partial && self.plan.local(&*self.finest.sm) && FrameSource::can_part(input);
        let start = self.finest.ctx.params();
        let corners = self.finest.ctx.corners(&start);
        if partial {
            let part = reads(&corners, FIRST_PART_PX + 2.0 * self.motion);
            self.src.prepare_part(input, region, part);
        } else {
            self.src.prepare(input, region);
        }
        let t1 = Instant::now();
        timing.preprocess += t1 - t0;
        let mut run = FrameRun {
            finest: &mut self.finest,
            src: &mut self.src,
            input,
            partial,
            judges: &mut self.judges,
            params: &self.params,
            reference: self.loss.reference(),
            exec: Executor::new(observer, self.frame, started),
            estimate: Estimate::start(start, corners),
        };
        let result = self.plan.run(&mut run).map(|()| run.estimate);
        timing.search += t1.elapsed();
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_end_at_the_regions_edge_left_it_unless_the_edge_is_the_frames() {
        let region = Rect::new(10.0, 10.0, 90.0, 70.0);
        let inside = Rect::new(20.0, 20.0, 60.0, 50.0);
        assert!(!escaped(&inside, &region, (100, 80)));
        let near_left = Rect::new(12.0, 20.0, 60.0, 50.0);
        assert!(escaped(&near_left, &region, (100, 80)));
        // The region reaches the frame's left edge: nothing more to pre-process there.
        let at_frame = Rect::new(0.0, 10.0, 90.0, 70.0);
        let b = Rect::new(1.0, 20.0, 60.0, 50.0);
        assert!(!escaped(&b, &at_frame, (100, 80)));
        let near_bottom = Rect::new(20.0, 20.0, 60.0, 68.0);
        assert!(escaped(&near_bottom, &region, (100, 80)));
        assert!(!escaped(&near_bottom, &region, (100, 70)));
    }
}
