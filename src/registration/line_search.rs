//! The executor's line search (tracker parameter `line_search`, for the methods whose
//! iteration is a Newton step from where it started, [`super::SearchMethod::line_search`]): an
//! iteration that starts lower than the best start so far (its similarity fell) drops its own
//! step and halves the best point's, up to [`HALVINGS`] times, after which the frame ends at
//! the best point. A step that lowered the similarity while moving the corners less than
//! [`SETTLED`] times the stop test's `eps` ends the frame at the best point at once: the search
//! has reached the noise of the similarity, where halving the step (four more iterations)
//! only finds points no better than the best one.

use super::{Context, Update, at_least};
use crate::ssm::Params;
use crate::status::LossReason;

/// How many times the line search halves a step before the frame ends at its best point.
pub const HALVINGS: i32 = 4;

/// A step whose corners moved less than this many times `eps` and lowered the similarity ends
/// the frame at the best point (see the module's documentation).
pub const SETTLED: f64 = 20.0;

/// See the module's documentation.
#[derive(Clone, Copy, Debug)]
pub struct LineSearch {
    on: bool,
    /// Below this (px, the corners' L2 change) a step that lowered the similarity ends the frame.
    settled: f64,
    /// The best start of an iteration this frame, its similarity and the step taken from it.
    best: Option<(Params, f64, Params, Update)>,
    /// How many times that step has been halved.
    halvings: i32,
}

impl LineSearch {
    /// A line search that does something only when `on`, settled below `settled` px
    /// (`SETTLED` times the stop test's `eps`, [`super::Limits::settled`]).
    pub fn new(on: bool, settled: f64) -> Self {
        LineSearch {
            on,
            settled,
            best: None,
            halvings: 0,
        }
    }

    pub fn is_on(&self) -> bool {
        self.on
    }

    /// Whether the last iteration's step stands (no step of this frame is being halved).
    pub fn kept(&self) -> bool {
        self.halvings == 0
    }

    /// After an iteration from `from`, where the similarity was `f`, that took the context's
    /// last step: the similarity of the point the context is now at's start (`f`, or the best
    /// point's), and whether the halvings are exhausted (the frame ends at the best point).
    pub fn after(
        &mut self,
        ctx: &mut Context,
        from: Params,
        f: f64,
    ) -> Result<(f64, bool), LossReason> {
        if !self.on {
            return Ok((f, false));
        }
        match (self.best, ctx.state().last_step()) {
            // This iteration started lower than the best point (or at NaN): its own step is
            // dropped and the best point's is halved.
            (Some((bp, bf, dp, update)), _) if !at_least(f, bf) => {
                self.halvings += 1;
                let moved = ctx.corners(&from).change_norm(&ctx.corners(&bp));
                ctx.set_params(bp);
                if self.halvings > HALVINGS || moved < self.settled {
                    return Ok((bf, true));
                }
                let scale = 0.5f64.powi(self.halvings);
                ctx.apply(&dp.map(|v| v * scale), update)?;
                Ok((bf, false))
            }
            (_, Some((dp, update))) => {
                self.best = Some((from, f, dp, update));
                self.halvings = 0;
                Ok((f, false))
            }
            _ => Ok((f, false)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::HessianKind;
    use crate::geometry::Quad;
    use crate::spec::GridLayout;

    fn context() -> Context {
        let mut ctx = Context::new(
            crate::ssm::build("translation").unwrap(),
            crate::am::build("ssd").unwrap(),
            HessianKind::Default,
            4,
        );
        ctx.set_region(
            &Quad::from_rect(0.0, 0.0, 10.0, 10.0),
            4,
            GridLayout::Centres,
        )
        .unwrap();
        ctx
    }

    /// A step after which the similarity rose is kept; one after which it fell is replaced by
    /// the best point's step halved, then quartered..., and after four halvings the search ends
    /// at the best point; off, nothing is touched.
    #[test]
    fn a_step_that_lowered_the_similarity_is_halved_from_the_best_point() {
        let mut ctx = context();
        let mut line = LineSearch::new(true, 0.0);
        let start = ctx.params();
        let mut dp = [0.0; crate::linalg::MAX_DOF];
        dp[0] = 0.4;
        // First iteration from the start, similarity -10, a step of 0.4.
        ctx.state_mut().forget_step();
        ctx.apply(&dp, Update::Additive).unwrap();
        assert_eq!(line.after(&mut ctx, start, -10.0).unwrap(), (-10.0, false));
        let after_first = ctx.params();
        // The next iteration starts lower (-12): back to the start plus half the step.
        for k in 1..=HALVINGS {
            ctx.state_mut().forget_step();
            ctx.apply(&dp, Update::Additive).unwrap();
            let (f, exhausted) = line.after(&mut ctx, after_first, -12.0).unwrap();
            assert_eq!((f, exhausted), (-10.0, false));
            let expected = start[0] + 0.4 * 0.5f64.powi(k);
            assert!((ctx.params()[0] - expected).abs() < 1e-12, "{k}");
        }
        let (f, exhausted) = line.after(&mut ctx, after_first, -12.0).unwrap();
        assert_eq!((f, exhausted), (-10.0, true));
        assert_eq!(ctx.params(), start);
        // Off: the step stays whatever the similarity did.
        let mut off = LineSearch::new(false, 0.0);
        ctx.apply(&dp, Update::Additive).unwrap();
        let p = ctx.params();
        let (f, exhausted) = off.after(&mut ctx, start, -20.0).unwrap();
        assert_eq!((f, exhausted), (-20.0, false));
        assert_eq!(ctx.params(), p);
    }

    /// A step that lowered the similarity while moving the corners less than `SETTLED` times
    /// `eps` ends the frame at the best point at once; a larger one is halved.
    #[test]
    fn a_step_at_the_similaritys_noise_ends_the_frame_at_once() {
        for (size, ends) in [
            (0.9 * SETTLED * 0.001, true),
            (1.1 * SETTLED * 0.001, false),
        ] {
            let mut ctx = context();
            // The corners move by `size` px (L2 over the 8 coordinates) for a step of `dp`.
            let unit = {
                let start = ctx.corners(&ctx.params());
                let mut dp = [0.0; crate::linalg::MAX_DOF];
                dp[0] = 1.0;
                ctx.apply(&dp, Update::Additive).unwrap();
                let moved = ctx.corners(&ctx.params()).change_norm(&start);
                ctx.set_params([0.0; crate::linalg::MAX_DOF]);
                moved
            };
            let mut line = LineSearch::new(true, SETTLED * 0.001);
            let start = ctx.params();
            let mut dp = [0.0; crate::linalg::MAX_DOF];
            dp[0] = size / unit;
            ctx.state_mut().forget_step();
            ctx.apply(&dp, Update::Additive).unwrap();
            assert_eq!(line.after(&mut ctx, start, -10.0).unwrap(), (-10.0, false));
            let after_first = ctx.params();
            ctx.state_mut().forget_step();
            ctx.apply(&dp, Update::Additive).unwrap();
            let (f, exhausted) = line.after(&mut ctx, after_first, -12.0).unwrap();
            assert_eq!((f, exhausted), (-10.0, ends), "{size}");
            if ends {
                assert_eq!(ctx.params(), start);
            }
        }
    }
}
