//! Normalised SSD: the SSD between the two patches after each is normalised to zero mean and unit
//! variance (its z-score `z(x) = (x - mean(x)) / std(x)`, population standard deviation):
//! `f = -1/2 |z(I*) - z(I)|^2`. Invariant to a gain and a bias of either patch.
//!
//! ## Which normalisation, and how it relates to ZNCC
//!
//! MTF's NSSD normalises each patch to a fixed range with its minimum and maximum. That is not
//! differentiable wherever the extreme pixel changes (and the FD checks would catch it: two
//! pixels within a grey level of the maximum are common), and its derivative with respect to a
//! pixel that is not an extreme ignores the normalisation altogether. Zero mean and unit variance
//! is the smooth choice. With it, `|z|^2 = N` for both patches, so
//! `|z(I*) - z(I)|^2 = 2N - 2 z(I*) . z(I) = 2N (1 - rho)` with `rho` the correlation
//! coefficient, and `f = N (rho - 1)`: **NSSD with this normalisation is exactly ZNCC in its
//! SSD form** ([`super::zncc`]), value, derivatives and embedding. It is kept as its own entry
//! (MTF's name, so that MTF configurations resolve) and shares ZNCC's implementation, whose header
//! in [`super::correlation`] has the derivation (gradient `N/n (o - rho v)`, exact, Gauss-Newton
//! and after-convergence Hessians). Embedding: `z(x)` itself, whose squared L2 distance is `-2f`.

use super::correlation::Correlation;
use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "nssd",
    aliases: &[],
    description: "SSD of zero-mean unit-variance patches (equal to zncc)",
    build: || Box::new(Nssd(Correlation::new(true))),
};

#[derive(Debug, Clone)]
pub struct Nssd(Correlation);

impl Am for Nssd {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn set_template(&mut self, template: &[f32]) {
        self.0.set_template(template)
    }
    fn template(&self) -> &[f32] {
        self.0.template()
    }
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        self.0.embed(patch, out)
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.0.similarity(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        self.0.gradient(wrt, current, grad)
    }
    fn hessian(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        self.0.hessian(wrt, kind, current, jac, dof, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn is_the_ssd_of_z_scores() {
        let mut rng = Rng::new(8);
        let n = 200;
        let t: Vec<f32> = (0..n).map(|_| rng.range(20.0, 230.0) as f32).collect();
        let c: Vec<f32> = t
            .iter()
            .map(|&v| 0.8 * v + 15.0 + rng.range(-25.0, 25.0) as f32)
            .collect();
        let z = |x: &[f32]| -> Vec<f64> {
            let m = x.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
            let s = (x.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / n as f64).sqrt();
            x.iter().map(|&v| (v as f64 - m) / s).collect()
        };
        let (zt, zc) = (z(&t), z(&c));
        let want = -0.5
            * zt.iter()
                .zip(&zc)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>();
        let mut am = Nssd(Correlation::new(true));
        am.set_template(&t);
        let f = am.similarity(&c);
        assert!((f - want).abs() < 1e-4 * want.abs(), "{f} vs {want}");
        // Gain and bias of the current patch change nothing; identity is the maximum 0.
        let lit: Vec<f32> = c.iter().map(|&v| 1.6 * v - 30.0).collect();
        assert!((am.similarity(&lit) - f).abs() < 1e-3 * f.abs());
        assert!(am.similarity(&t).abs() < 1e-6 * n as f64);
    }
}
