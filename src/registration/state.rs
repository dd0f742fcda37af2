//! Where a search is: the SSM's parameters, the last step taken and how (the line search
//! shortens it), and the damping of the Newton steps (Levenberg-Marquardt, set by `lm:`).

use crate::linalg::MAX_DOF;
use crate::ssm::{Params, Ssm};
use crate::status::LossReason;

/// How a step `dp` changes the parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Update {
    /// `p + dp`.
    Additive,
    /// `w(w(x, dp), p)`: `p` after `dp`.
    Compose,
    /// `w(w(x, dp)^-1, p)`: `p` after the inverse of `dp`.
    ComposeInverse,
}

/// See the module's documentation.
#[derive(Clone, Copy, Debug)]
pub struct State {
    params: Params,
    /// The last step [`State::apply`] made, and how.
    last_step: Option<(Params, Update)>,
    /// Levenberg-Marquardt damping `lambda` of the Newton steps (0: none).
    damping: f64,
}

impl Default for State {
    fn default() -> Self {
        State {
            params: [0.0; MAX_DOF],
            last_step: None,
            damping: 0.0,
        }
    }
}

impl State {
    /// The current parameters.
    pub fn params(&self) -> Params {
        self.params
    }
    /// Moves to `p` (not a step: the line search has nothing to shorten).
    pub fn set_params(&mut self, p: Params) {
        self.params = p;
    }
    /// The last step taken by [`State::apply`] since [`State::forget_step`], and how.
    pub fn last_step(&self) -> Option<(Params, Update)> {
        self.last_step
    }
    /// Forgets the last step (an iteration begins).
    pub fn forget_step(&mut self) {
        self.last_step = None;
    }
    /// The damping of the Newton steps (0: none).
    pub fn damping(&self) -> f64 {
        self.damping
    }
    pub fn set_damping(&mut self, lambda: f64) {
        self.damping = lambda;
    }

    /// Applies the step `dp` to the parameters (`ssm`'s algebra).
    pub fn apply(&mut self, ssm: &dyn Ssm, dp: &Params, update: Update) -> Result<(), LossReason> {
        let dp = *dp;
        let p = self.params;
        let next = match update {
            Update::Additive => Some(ssm.additive_update(&p, &dp)),
            Update::Compose => ssm.compose(&p, &dp),
            Update::ComposeInverse => ssm.invert(&dp).and_then(|inv| ssm.compose(&p, &inv)),
        }
        .ok_or(LossReason::Singular)?;
        if !next.iter().all(|v| v.is_finite()) {
            return Err(LossReason::NonFinite);
        }
        self.params = next;
        self.last_step = Some((dp, update));
        Ok(())
    }
}
