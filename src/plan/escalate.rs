//! Pay only when a frame needs it (`escalate=on`): the frame is first searched at the finest level
//! alone (the search, at most [`FIRST_ITERS`] iterations, stopping at [`FIRST_EPS_TIMES`] times
//! `eps` or when the next step extrapolated from the last two would; then the confidences; no
//! pyramid, no polish). When that search settled ([`Estimate::converged`]) on a patch at least
//! [`EASY`] times as like the template as the track's recent frames (their median confidence), and
//! at least [`EASY_FRAME`] like the last tracked frame's patch, the frame is done. Otherwise the
//! full stages (the pyramid, the search, the polish) run from where the frame started and their end
//! is the frame's, as without the first attempt (the first attempt's end only when they fail).
//! Until the track has recent frames to compare with, every frame runs the full stages alone.
//!
//! Keeping the more confident of the two ends instead was measured worse: on a periodic
//! texture the first attempt's end one period over is often the more confident, and a slip
//! that the full stages would have avoided or shown went unreported (on a rendered brick wall,
//! FALK-ZNCC reported 0.875 of its frames more than 20 px off lost, against 1.000 without the
//! first attempt).
//!
//! Most frames of most footage are easy: the motion is small or predicted, and one level
//! settles in a few iterations. A hard frame (a large or sudden motion, blur, a change of
//! light) pays both.

use super::{Estimate, FrameRun, Init, Learn, Stage, TwoStages, measured, run_stages};
use crate::error::Result;
use crate::registration::{SearchMethod, at_least};
use crate::status::LossReason;

/// The fraction of the recent frames' median confidence a first attempt must reach to end the
/// frame (the same bar as the retry's, `retry::RETRY_BELOW`: a frame that reaches it is one the
/// pyramid's retry would have kept too).
pub const EASY: f64 = super::retry::RETRY_BELOW;

/// The correlation with the last tracked frame's patch a first attempt needs at least (or
/// `min_frame_confidence` if higher). On the tune half of the held-out renders, with the
/// frame check's 0.8 instead, ICLK-ZNCC reported 0.830 of its frames more than 20 px off lost
/// (0.859 without `escalate`); with 0.95, 0.842, the speed kept (book, 384 x 288: 16,018 live
/// FPS against 8,832 without `escalate`).
pub const EASY_FRAME: f64 = 0.95;

/// The first attempt's iterations at most: a frame that needs more is not easy.
pub const FIRST_ITERS: usize = 10;

/// The first attempt stops once its corners move less than this many times the tracker's
/// `eps` in an iteration (0.03 px, the L2 norm of the 8 coordinates, at the default 0.001), or
/// once the next step extrapolated from the last two would
/// ([`crate::registration::Limits::extrapolate`]): a search from a good start converges
/// geometrically (steps of about 1, 0.1, 0.02 px on the book sequence), and its third step only
/// confirms the second. Each frame is registered to the template, not to the last frame, so a
/// frame ended a hundredth of a pixel short of the optimum does not pass its error on. Chosen
/// on the tune half of the held-out renders (10, 30, 50, 100: SR@5 0.848-0.852, 30 the best);
/// docs/speed.md says what it saves.
pub const FIRST_EPS_TIMES: f64 = 30.0;

/// See the module's documentation: `first` (the finest level's search and confidences) and,
/// when its end is not easy, `then` (the full stages) from the same start.
#[derive(Debug)]
pub struct Escalate {
    stages: TwoStages,
}

impl Escalate {
    pub fn new(first: Vec<Box<dyn Stage>>, then: Vec<Box<dyn Stage>>) -> Self {
        Escalate {
            stages: TwoStages::new(first, then),
        }
    }
}

/// Whether a first attempt's end `e` is good enough to end the frame, against the track's
/// recent median confidence `reference` and the frame-to-frame bar `min_frame`.
pub fn easy(e: &Estimate, reference: Option<f64>, min_frame: f64) -> bool {
    let Some(reference) = reference else {
        return false;
    };
    e.converged
        && at_least(measured(e), EASY * reference)
        && e.frame_confidence
            .is_none_or(|f| at_least(f, min_frame.max(EASY_FRAME)))
}

impl Stage for Escalate {
    fn name(&self) -> &'static str {
        "escalate"
    }

    fn describe(&self) -> String {
        self.stages.describe(self.name())
    }

    fn local(&self, finest: &dyn SearchMethod) -> bool {
        self.stages.local(finest)
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
        // Nothing to judge a first attempt by yet: the full stages alone.
        if run.reference.is_none() {
            run_stages(&mut self.stages.then, run)?;
            run.finest.ctx.set_params(run.estimate.params);
            return Ok(());
        }
        let start = run.estimate;
        let tried = run_stages(&mut self.stages.first, run);
        let first = run.estimate;
        if tried.is_ok() && easy(&first, run.reference, run.params.min_frame_confidence) {
            return Ok(());
        }
        run.estimate = start.with_iterations(first.iterations);
        let full = run_stages(&mut self.stages.then, run);
        let second = run.estimate;
        run.estimate = match full {
            Ok(()) => second,
            Err(_) if tried.is_ok() => first.with_iterations(second.iterations),
            Err(e) => return Err(e),
        };
        run.finest.ctx.set_params(run.estimate.params);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::NoObserver;
    use crate::plan::harness::{tracker, with_run};
    use crate::ssm::Params;

    /// A search that moves the first parameter by `by`, one iteration, settled or not, as
    /// confident as `confidence` says of where it ends (or failing there).
    #[derive(Debug)]
    struct Attempt {
        by: f64,
        converged: bool,
        confidence: fn(&Params) -> Option<f64>,
    }
    impl Stage for Attempt {
        fn name(&self) -> &'static str {
            "attempt"
        }
        fn local(&self, _: &dyn SearchMethod) -> bool {
            true
        }
        fn run(&mut self, run: &mut FrameRun<'_>) -> std::result::Result<(), LossReason> {
            run.estimate.params[0] += self.by;
            run.estimate.iterations += 1;
            run.estimate.converged = self.converged;
            run.estimate.confidence =
                Some((self.confidence)(&run.estimate.params).ok_or(LossReason::Singular)?);
            Ok(())
        }
    }

    fn escalate(
        first: (bool, fn(&Params) -> Option<f64>),
        then: fn(&Params) -> Option<f64>,
    ) -> Escalate {
        let attempt = |by, converged, confidence| -> Vec<Box<dyn Stage>> {
            vec![Box::new(Attempt {
                by,
                converged,
                confidence,
            })]
        };
        Escalate::new(attempt(0.5, first.0, first.1), attempt(1.0, true, then))
    }

    #[test]
    fn a_frame_pays_the_full_stages_only_when_the_first_attempt_is_not_easy() {
        let (mut t, gray, quads) = tracker(("iclk", "ssd", "translation"), |_| {}, (2, 1));
        let mut run_with = |mut e: Escalate, reference: Option<f64>| {
            with_run(&mut t, &gray[1], &quads[1], &mut NoObserver, |run| {
                run.reference = reference;
                let start = run.estimate.params[0];
                let out = e.run(run).map(|()| run.estimate);
                let at = run.finest.ctx.params()[0];
                out.map(|o| (o.params[0] - start, o.confidence, o.iterations, at - start))
            })
        };
        let first_good: fn(&Params) -> Option<f64> = |_| Some(0.9);
        let full_better: fn(&Params) -> Option<f64> = |_| Some(0.95);
        // Settled and as confident as the track: the frame ends after the first attempt.
        let out = run_with(escalate((true, first_good), full_better), Some(0.9));
        assert_eq!(out.unwrap().0..out.unwrap().2 as f64, 0.5..1.0);
        // Not settled, or less confident than the track: the full stages from the frame's
        // start, their end kept, every iteration counted; no track yet: the full stages alone
        // (nothing to judge a first attempt by).
        for (converged, reference, n) in [
            (false, Some(0.9), 2),
            (true, Some(0.99), 2),
            (true, None, 1),
        ] {
            let out = run_with(escalate((converged, first_good), full_better), reference);
            let (moved, c, iterations, at) = out.unwrap();
            assert_eq!((moved, c, iterations), (1.0, Some(0.95), n));
            assert_eq!(at, 1.0, "the problem left where the kept end is");
        }
        // The full stages' end even when less confident; the first end only when they fail.
        let worse: fn(&Params) -> Option<f64> = |_| Some(0.5);
        let out = run_with(escalate((false, first_good), worse), Some(0.9)).unwrap();
        assert_eq!((out.0, out.1, out.2, out.3), (1.0, Some(0.5), 2, 1.0));
        let fails: fn(&Params) -> Option<f64> = |_| None;
        let out = run_with(escalate((false, first_good), fails), Some(0.9)).unwrap();
        assert_eq!((out.0, out.1, out.3), (0.5, Some(0.9), 0.5));
        // The first attempt failing: the full stages' end, or their failure.
        let out = run_with(escalate((true, fails), full_better), Some(0.9)).unwrap();
        assert_eq!((out.0, out.1), (1.0, Some(0.95)));
        let out = run_with(escalate((true, fails), fails), Some(0.9));
        assert_eq!(out.unwrap_err(), LossReason::Singular);
    }

    /// The bar: settled, at least `EASY` of the track's median, and as like the last frame's
    /// patch as asked.
    #[test]
    fn an_easy_end_is_settled_and_as_confident_as_the_track() {
        let mut e = Estimate::start([0.0; crate::linalg::MAX_DOF], Default::default());
        e.converged = true;
        e.confidence = Some(0.9);
        assert!(easy(&e, Some(0.9 / EASY), 0.8));
        assert!(!easy(&e, Some(0.9 / EASY + 1e-9), 0.8));
        assert!(!easy(&e, None, 0.8));
        // As like the last frame's patch as EASY_FRAME asks, or min_frame_confidence if higher.
        e.frame_confidence = Some(EASY_FRAME - 0.01);
        assert!(!easy(&e, Some(0.9), 0.8));
        e.frame_confidence = Some(EASY_FRAME);
        assert!(easy(&e, Some(0.9), 0.8));
        assert!(!easy(&e, Some(0.9), EASY_FRAME + 0.01));
        e.converged = false;
        assert!(!easy(&e, Some(0.9), 0.8));
        e.converged = true;
        e.confidence = Some(f64::NAN);
        assert!(!easy(&e, Some(0.9), 0.8));
    }
}
