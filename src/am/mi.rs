//! Mutual information (Dowson and Bowden; Dame and Marchand) with a cubic B-spline Parzen
//! window: `f = sum_{a,b} p(a, b) log(p(a, b) / (p_t(a) p_c(b)))` in nats, `p` the joint
//! probability of the template and current intensities over `bins` bins (default 16, the paper's
//! 8 with `bins=8`; see [`super::parzen::BINS_PARAM`]) plus padding bins. The
//! estimator and the derivation of the exact gradient and Hessian (with respect to either patch)
//! are in [`super::parzen`]. With respect to the current pixels the gradient reduces to Dame and
//! Marchand's `sum_ab dp(a, b)/dc_j log(p(a, b) / p_c(b))`, since `p_t` does not move.
//!
//! The default Hessian is the one after convergence (the Newton Hessian at `I = I*`, constant per
//! template), as in the paper; Gauss-Newton is the negative semi-definite part of the Newton
//! Hessian (the first-order term of MI is positive semi-definite, so there is no least-squares
//! Gauss-Newton). No embedding: MI is not a distance between independently embedded patches.

use super::parzen::{Measure, PARAMS, Parzen};
use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "mi",
    aliases: &[],
    description: "mutual information (cubic B-spline Parzen joint histogram, 16 bins by default)",
    build: AmBuilder {
        params: &PARAMS,
        build: |p| Box::new(Mi(Parzen::from_params(Measure::Mi, p))),
    },
};

#[derive(Debug, Clone)]
pub struct Mi(Parzen);

impl Am for Mi {
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
    fn invariant_to_gain_and_bias_and_to_an_inversion() {
        let mut rng = Rng::new(31);
        let t = smooth_patch(&mut rng, 30);
        let mut mi = Mi(Parzen::new(Measure::Mi, crate::am::parzen::DEFAULT_BINS));
        mi.set_template(&t);
        let at = mi.similarity(&t);
        assert!(at > 0.5, "{at}");
        // A gain and bias that keep the bins' occupancy similar, and an inversion: close to the
        // value at the template (MI depends on the joint distribution, not on the grey levels).
        let inverted: Vec<f32> = t.iter().map(|&v| 255.0 - v).collect();
        assert!((mi.similarity(&inverted) - at).abs() < 0.02 * at);
        let lit: Vec<f32> = t.iter().map(|&v| 1.2 * v - 10.0).collect();
        let v = mi.similarity(&lit);
        assert!(v > 0.85 * at, "{v} vs {at}");
        // A shuffled patch shares no information.
        let mut shuffled = t.clone();
        for i in (1..shuffled.len()).rev() {
            shuffled.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        assert!(mi.similarity(&shuffled) < 0.1 * at);
    }

    #[test]
    fn maximum_at_identity_over_shifts() {
        let mut rng = Rng::new(37);
        let res = 40;
        let big = smooth_patch(&mut rng, res + 8);
        let crop = |dx: usize, dy: usize| -> Vec<f32> {
            (0..res * res)
                .map(|i| big[(i / res + dy) * (res + 8) + i % res + dx])
                .collect()
        };
        let t = crop(4, 4);
        let mut mi = Mi(Parzen::new(Measure::Mi, crate::am::parzen::DEFAULT_BINS));
        mi.set_template(&t);
        let at = mi.similarity(&t);
        for dy in 0..9 {
            for dx in 0..9 {
                if (dx, dy) != (4, 4) {
                    assert!(mi.similarity(&crop(dx, dy)) < at, "shift {dx} {dy}");
                }
            }
        }
    }

    #[test]
    fn symmetric_in_its_arguments_and_gradients() {
        let mut rng = Rng::new(41);
        let a: Vec<f32> = (0..300).map(|_| rng.range(20.0, 230.0) as f32).collect();
        let b: Vec<f32> = a
            .iter()
            .map(|&v| 0.5 * v + 60.0 + rng.range(-30.0, 30.0) as f32)
            .collect();
        let mut m = Mi(Parzen::new(Measure::Mi, crate::am::parzen::DEFAULT_BINS));
        m.set_template(&a);
        let (mut ga, mut gb) = (vec![0f32; 300], vec![0f32; 300]);
        let f1 = m.gradient(Wrt::Current, &b, &mut gb);
        m.set_template(&b);
        let f2 = m.gradient(Wrt::Template, &a, &mut ga);
        assert!((f1 - f2).abs() < 1e-12);
        // d MI / d b_j is the same whichever side b is on.
        m.set_template(&a);
        let mut gt = vec![0f32; 300];
        m.gradient(Wrt::Current, &b, &mut gt);
        m.set_template(&b);
        let mut gc = vec![0f32; 300];
        m.gradient(Wrt::Template, &a, &mut gc);
        for i in 0..300 {
            assert!((gt[i] - gc[i]).abs() <= 1e-6 * gt[i].abs().max(1e-3));
        }
    }
}
