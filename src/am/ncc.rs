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
    build: AmBuilder::plain(|_| Box::new(Ncc(Correlation::new(false)))),
};

#[derive(Debug, Clone)]
pub struct Ncc(Correlation);

impl Am for Ncc {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn pixelwise(&self) -> bool {
        true
    }
    fn default_hessian(&self) -> HessianKind {
        HessianKind::AfterConvergence
    }
    super::forward_to_engine!();
    super::forward_projections!();
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        self.0.embed(patch, out)
    }
}
