//! Normalised cross-correlation without mean removal: `f = I* . I / (|I*| |I|)`.
//! Invariant to gain, not to bias; uses the Hessian after convergence by default, as in the
//! robust-AM trackers of the paper.

use super::correlation::Correlation;
use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "ncc",
    aliases: &[],
    description: "normalised cross-correlation",
    build: || Box::new(Ncc(Correlation::new(false))),
};

#[derive(Debug, Clone)]
pub struct Ncc(Correlation);

impl Am for Ncc {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn default_hessian(&self) -> HessianKind {
        HessianKind::AfterConvergence
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
