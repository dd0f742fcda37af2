//! Cross cumulative residual entropy (CCRE; Wang and Vemuri, in the tracking form of Richa et al.
//! 2012): MI's construction with the joint probability replaced by the cumulative joint
//! distribution of the template intensity, `f = sum_{a,b} P(a, b) log(P(a, b) / (P_t(a) p_c(b)))`,
//! `P(a, b) = P(I* <= a, I = b)`, `P_t(a) = P(I* <= a)`, over the same cubic B-spline Parzen
//! histogram as MI (`bins` bins, default 16, plus padding). The exact gradient and Hessian with
//! respect to either patch are derived in [`super::parzen`] (by the chain rule through `G = df/dp`,
//! which for CCRE gathers the logarithms of every cumulative cell above a cell, and the quadratic
//! form of `d2f/dp2` on the cumulative sums of the projected cell derivatives).
//!
//! Not symmetric in its arguments (only the template side is cumulated). The default Hessian is
//! the one after convergence; Gauss-Newton is the negative semi-definite part of the Newton
//! Hessian, as for MI. No embedding.

use super::parzen::{Measure, PARAMS, Parzen};
use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "ccre",
    aliases: &[],
    description: "cross cumulative residual entropy (cumulative B-spline Parzen joint histogram)",
    build: AmBuilder {
        params: &PARAMS,
        build: |p| Box::new(Ccre(Parzen::from_params(Measure::Ccre, p))),
    },
};

#[derive(Debug, Clone)]
pub struct Ccre(Parzen);

impl Am for Ccre {
    fn max_dof(&self) -> usize {
        super::parzen::PDOF
    }
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities::DERIVATIVES_ONLY
    }
    fn default_hessian(&self) -> HessianKind {
        HessianKind::AfterConvergence
    }
    fn bins_grey_levels(&self) -> bool {
        true
    }
    super::forward_to_engine!();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    use crate::am::tests::smooth_patch;

    #[test]
    fn maximum_at_identity_over_shifts_and_robust_to_gain_and_bias() {
        let mut rng = Rng::new(43);
        let res = 40;
        let big = smooth_patch(&mut rng, res + 8);
        let crop = |dx: usize, dy: usize| -> Vec<f32> {
            (0..res * res)
                .map(|i| big[(i / res + dy) * (res + 8) + i % res + dx])
                .collect()
        };
        let t = crop(4, 4);
        let mut am = Ccre(Parzen::new(Measure::Ccre, crate::am::parzen::DEFAULT_BINS));
        am.set_template(&t);
        let at = am.similarity(&t);
        assert!(at > 0.0);
        let mut best_shift = f64::NEG_INFINITY;
        for dy in 0..9 {
            for dx in 0..9 {
                if (dx, dy) != (4, 4) {
                    let v = am.similarity(&crop(dx, dy));
                    assert!(v < at, "shift {dx} {dy}: {v} vs {at}");
                    best_shift = best_shift.max(v);
                }
            }
        }
        // Under a global gain and bias the true patch still beats every shifted one.
        let lit: Vec<f32> = t.iter().map(|&v| 1.2 * v - 10.0).collect();
        let v = am.similarity(&lit);
        assert!(v > best_shift, "{v} vs shifted {best_shift}");
        // A shuffled patch is much worse.
        let mut shuffled = t.clone();
        for i in (1..shuffled.len()).rev() {
            shuffled.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        assert!(am.similarity(&shuffled) < 0.2 * at);
    }
}
