//! Zero-mean normalised cross-correlation in its SSD-like form: `f = -1/2 |z(I*) - z(I)|^2`
//! with `z` the z-score of a patch (zero mean, unit variance), i.e. `N (rho - 1)` where `rho` is
//! the correlation coefficient. Invariant to gain and bias.

use super::correlation::Correlation;
use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "zncc",
    aliases: &[],
    description: "zero-mean normalised cross-correlation (SSD of z-scores)",
    build: || Box::new(Zncc(Correlation::new(true))),
};

#[derive(Debug, Clone)]
pub struct Zncc(Correlation);

impl Am for Zncc {
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
