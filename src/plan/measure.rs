//! The confidences of where a frame's search ended, for the loss checks: the patch there
//! against the template, and against the last tracked frame's patch when there is one (both in
//! one pass over the patch, its sums kept for the next frame). What a stage before measured
//! (the polish, which walks by the confidence) is not measured again.

use super::{FrameRun, Judges, Stage};
use crate::registration::SearchMethod;
use crate::status::LossReason;

/// See the module's documentation.
#[derive(Clone, Copy, Debug)]
pub struct Measure;

impl Stage for Measure {
    fn name(&self) -> &'static str {
        "measure"
    }

    fn local(&self, _finest: &dyn SearchMethod) -> bool {
        true
    }

    fn run(&mut self, run: &mut FrameRun<'_>) -> Result<(), LossReason> {
        let p = run.estimate.params;
        let reader = run.src.reader(run.input, run.partial);
        let view = reader.view();
        let ctx = &mut run.finest.ctx;
        let Judges {
            template,
            previous,
            has_previous,
            sums,
            ..
        } = &mut *run.judges;
        let previous = has_previous.then_some(&*previous);
        let e = &mut run.estimate;
        if e.confidence.is_none() {
            ctx.whole_sample_at(&view, &p);
            match previous {
                Some(previous) => {
                    // Both confidences from one pass over the patch, its sums kept.
                    let (c, f) = template.of_pair(previous, ctx.whole_values(), &mut sums.1);
                    sums.0 = Some(ctx.work().samples());
                    e.confidence = Some(c);
                    e.frame_confidence = Some(f);
                }
                None => e.confidence = Some(template.of(ctx.whole_values())),
            }
        }
        if e.frame_confidence.is_none()
            && let Some(previous) = previous
        {
            // Usually just sampled there, for the confidence.
            e.frame_confidence = Some(previous.of(ctx.whole_patch_at(&view, &p)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::NoObserver;
    use crate::plan::harness::{confidence_at, shifted, tracker, with_run};

    /// The confidence against the template alone without a previous patch; both, as their
    /// own correlations give them, with one; what a stage before measured kept.
    #[test]
    fn the_confidences_are_those_of_the_patch_where_the_frame_ended() {
        let (mut t, gray, quads) = tracker(("iclk", "zncc", "homography"), |_| {}, (4, 2));
        let at = shifted(&quads[3], 1.0, 0.5);
        with_run(&mut t, &gray[3], &at, &mut NoObserver, |run| {
            let p = run.estimate.params;
            Measure.run(run).unwrap();
            let c = confidence_at(run, &p);
            assert_eq!(run.estimate.confidence, Some(c));
            assert_eq!(run.estimate.frame_confidence, None);
            // The patch of frame 2 as the previous one.
            let view = run.src.view(run.input, 0);
            run.finest.ctx.sample_at(&view, &p);
            let patch = run.finest.ctx.values().to_vec();
            run.judges.previous.set_template(&patch, 50, 4);
            run.judges.has_previous = true;
            run.estimate.confidence = None;
            Measure.run(run).unwrap();
            assert_eq!(run.estimate.confidence, Some(c));
            let f = run.judges.previous.of(&patch);
            assert_eq!(run.estimate.frame_confidence, Some(f));
            assert!(f > 0.999, "{f}");
            // Measured before (the polish): only the frame confidence is made.
            run.estimate.confidence = Some(0.25);
            run.estimate.frame_confidence = None;
            Measure.run(run).unwrap();
            assert_eq!(run.estimate.confidence, Some(0.25));
            assert_eq!(run.estimate.frame_confidence, Some(f));
        });
    }
}
