//! A policy on the outcome of the finest level's search when stages before it moved its start
//! (the pyramid): when that search ends less like the template than [`RETRY_BELOW`] times the
//! track's recent frames' median confidence, the finest level is searched again from where
//! those stages started, and the more confident end is kept. (A coarse level that followed the
//! light may still have looked better than the start, and the finest level then settles on a
//! look-alike nearby.)

use super::{FrameRun, Init, Learn, Stage, TwoStages, measured, run_stages};
use crate::error::Result;
use crate::registration::{SearchMethod, at_least};
use crate::status::LossReason;

/// The fraction of the recent frames' median confidence below which the finest level is
/// searched again from the start.
pub const RETRY_BELOW: f64 = 0.95;

/// See the module's documentation: `first` (the pyramid) moves the start, `then` (the finest
/// level's stages, ending with the confidence measured) search from there and may run again.
#[derive(Debug)]
pub struct Retry {
    stages: TwoStages,
}

impl Retry {
    pub fn new(first: Vec<Box<dyn Stage>>, then: Vec<Box<dyn Stage>>) -> Self {
        Retry {
            stages: TwoStages::new(first, then),
        }
    }
}

impl Stage for Retry {
    fn name(&self) -> &'static str {
        "retry"
    }

    fn local(&self, finest: &dyn SearchMethod) -> bool {
        self.stages.local(finest)
    }

    fn describe(&self) -> String {
        self.stages.describe(self.name())
    }

    fn levels(&self) -> usize {
        self.stages.levels()
    }

    fn initialize(&mut self, init: &Init<'_>) -> Result<()> {
        self.stages.initialize(init)
    }

    fn learn(&mut self, at: &mut Learn<'_>) {
        self.stages.learn(at)
    }

    fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
        let start = run.estimate;
        run_stages(&mut self.stages.first, run)?;
        let moved = run.estimate.params != start.params;
        run_stages(&mut self.stages.then, run)?;
        let first = run.estimate;
        let low = run
            .reference
            .is_some_and(|r| !at_least(measured(&first), RETRY_BELOW * r));
        if !(moved && low) {
            return Ok(());
        }
        run.estimate = start.with_iterations(first.iterations);
        let again = run_stages(&mut self.stages.then, run);
        let second = run.estimate;
        run.estimate = match again {
            Ok(()) if measured(&second) > measured(&first) => second,
            Ok(()) => first.with_iterations(second.iterations),
            Err(_) => first,
        };
        run.finest.ctx.set_params(run.estimate.params);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::NoObserver;
    use crate::plan::RegistrationTracker;
    use crate::plan::harness::{tracker, with_run};
    use crate::ssm::Params;

    /// Moves the estimate's first parameter by `by` (a pyramid that moves the start).
    #[derive(Debug)]
    struct Move {
        by: f64,
    }
    impl Stage for Move {
        fn name(&self) -> &'static str {
            "move"
        }
        fn local(&self, _: &dyn SearchMethod) -> bool {
            false
        }
        fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
            run.estimate.params[0] += self.by;
            Ok(())
        }
    }

    /// A finest level's search: one iteration, ending where it started, as confident as
    /// `confidence` says of where it started (or failing there).
    #[derive(Debug)]
    struct Score {
        confidence: fn(&Params) -> Option<f64>,
    }
    impl Stage for Score {
        fn name(&self) -> &'static str {
            "score"
        }
        fn local(&self, _: &dyn SearchMethod) -> bool {
            true
        }
        fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
            run.estimate.iterations += 1;
            run.estimate.confidence =
                Some((self.confidence)(&run.estimate.params).ok_or(LossReason::Singular)?);
            Ok(())
        }
    }

    fn retry(by: f64, confidence: fn(&Params) -> Option<f64>) -> Retry {
        Retry::new(
            vec![Box::new(Move { by })],
            vec![Box::new(Score { confidence })],
        )
    }

    /// The confidence of a start moved by 0.5 is 0.3, of the start itself 0.9.
    fn moved_is_worse(p: &Params) -> Option<f64> {
        Some(if p[0] > 0.25 { 0.3 } else { 0.9 })
    }

    #[test]
    fn a_moved_start_that_ends_less_confident_than_the_track_is_searched_again_from_the_start() {
        let (mut t, gray, quads) = tracker(("iclk", "ssd", "translation"), |_| {}, (2, 1));
        let run_with = |t: &mut RegistrationTracker, mut r: Retry, reference: Option<f64>| {
            with_run(t, &gray[1], &quads[1], &mut NoObserver, |run| {
                run.reference = reference;
                let start = run.estimate.params;
                let out = r.run(run).map(|()| run.estimate);
                (start, out, run.finest.ctx.params())
            })
        };
        // Less confident than 0.95 of the track's 0.8: again from the start, that end kept,
        // the iterations of both runs counted.
        let (start, out, at) = run_with(&mut t, retry(0.5, moved_is_worse), Some(0.8));
        let out = out.unwrap();
        assert_eq!(
            (out.params, out.confidence, out.iterations),
            (start, Some(0.9), 2)
        );
        assert_eq!(at, start);
        // No track yet, or confident enough: the first end stands.
        for reference in [None, Some(0.3)] {
            let (start, out, _) = run_with(&mut t, retry(0.5, moved_is_worse), reference);
            let out = out.unwrap();
            assert_eq!((out.params[0], out.confidence), (start[0] + 0.5, Some(0.3)));
            assert_eq!(out.iterations, 1);
        }
        // The start not moved: nothing to search again from.
        let (_, out, _) = run_with(&mut t, retry(0.0, |_| Some(0.1)), Some(0.8));
        assert_eq!(out.unwrap().iterations, 1);
        // The second end less confident, or failing: the first kept (with every iteration
        // counted when the second ended).
        let (start, out, _) = run_with(
            &mut t,
            retry(0.5, |p| Some(if p[0] > 0.25 { 0.3 } else { 0.2 })),
            Some(0.8),
        );
        let out = out.unwrap();
        assert_eq!(
            (out.params[0], out.confidence, out.iterations),
            (start[0] + 0.5, Some(0.3), 2)
        );
        let (start, out, _) = run_with(
            &mut t,
            retry(0.5, |p| (p[0] > 0.25).then_some(0.3)),
            Some(0.8),
        );
        let out = out.unwrap();
        assert_eq!(
            (out.params[0], out.confidence, out.iterations),
            (start[0] + 0.5, Some(0.3), 1)
        );
        // The first end failing fails the frame.
        let (_, out, _) = run_with(&mut t, retry(0.5, |_| None), Some(0.8));
        assert_eq!(out.unwrap_err(), LossReason::Singular);
    }
}
