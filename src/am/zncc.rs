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
    build: AmBuilder::plain(|_| Box::new(Zncc(Correlation::new(true)))),
};

#[derive(Debug, Clone)]
pub struct Zncc(Correlation);

impl Am for Zncc {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn pixelwise(&self) -> bool {
        true
    }
    super::forward_to_engine!();
    super::forward_projections!();
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        self.0.embed(patch, out)
    }
}
