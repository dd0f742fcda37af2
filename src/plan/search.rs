//! The tracker's own search method at the finest level, from the frame's estimate: the
//! executor's loop with the tracker's limits (or fewer iterations, for a first attempt that
//! is worth keeping only if it settles quickly, [`super::Escalate`]).

use super::{FrameRun, Stage};
use crate::registration::{Limits, SearchMethod};
use crate::status::LossReason;

/// See the module's documentation: at most `max_iters` iterations when set (else the
/// tracker's), stopping once the corners move less than `eps_times` times the tracker's `eps`
/// (1 when not set; the line search's end stays where the tracker's `eps` puts it), or, with
/// `extrapolate`, once the next step extrapolated from the last two would
/// ([`crate::registration::Limits::extrapolate`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Search {
    pub max_iters: Option<usize>,
    pub eps_times: Option<f64>,
    pub extrapolate: bool,
}

impl Stage for Search {
    fn name(&self) -> &'static str {
        "search"
    }

    fn local(&self, finest: &dyn SearchMethod) -> bool {
        finest.local()
    }

    fn run(&mut self, run: &mut FrameRun<'_>) -> Result<(), LossReason> {
        let mut limits = Limits::of(run.params);
        if let Some(n) = self.max_iters {
            limits.max_iters = limits.max_iters.min(n);
        }
        if let Some(k) = self.eps_times {
            limits.eps *= k;
        }
        limits.extrapolate = self.extrapolate;
        let first = run.estimate.iterations;
        let from = run.estimate.params;
        let (finest, mut reader, exec) = run.finest();
        finest.ctx.set_params(from);
        let ran = exec.run(
            &mut finest.ctx,
            &mut *finest.sm,
            &limits,
            (0, first),
            &mut reader,
        )?;
        let params = finest.ctx.params();
        let e = &mut run.estimate;
        e.params = params;
        e.corners = ran.corners;
        e.iterations = first + ran.iterations;
        e.converged = ran.converged;
        e.similarity = ran.similarity;
        e.confidence = None;
        e.frame_confidence = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::IterationCounter;
    use crate::plan::harness::{error, shifted, tracker, with_run};

    /// From 3 px off on a later frame, the search ends on the target, settled, its estimate
    /// the finest problem's parameters, with nothing measured yet.
    #[test]
    fn the_search_moves_the_estimate_onto_the_target() {
        let (mut t, gray, quads) = tracker(
            ("fclk", "ssd", "homography"),
            |p| p.pyramid_levels = 1,
            (6, 2),
        );
        let start = shifted(&quads[5], 3.0, -2.0);
        let mut counter = IterationCounter::default();
        let e = with_run(&mut t, &gray[5], &start, &mut counter, |run| {
            run.estimate.iterations = 7;
            Search::default().run(run).unwrap();
            assert_eq!(run.estimate.params, run.finest.ctx.params());
            run.estimate
        });
        assert!(
            error(&e.corners, &quads[5]) < 0.3,
            "{}",
            error(&e.corners, &quads[5])
        );
        assert!(e.converged);
        assert_eq!(e.iterations, 7 + counter.iterations as usize);
        assert!(counter.iterations > 1);
        assert_eq!((e.confidence, e.frame_confidence), (None, None));
    }
}
