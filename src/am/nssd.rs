//! Normalised SSD, as MTF defines it: SSD over intensities first mapped linearly from the pixel
//! range `0..255` onto `0..1`, `f = -1/2 sum_i (s (I*_i - I_i))^2` with `s = 1/255`.
//!
//! The mapping is fixed (not per patch), so the optimum, the search and the robustness are those
//! of SSD; what changes is the scale of `f`, which is what a particle filter's likelihood or a
//! similarity threshold reads (an SSD of 1 on this scale is a difference of 255 gray levels).
//! Not to be confused with the SSD of z-scores, which is ZNCC.

use super::ssd::Ssd;
use super::{Am, AmBuilder, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "nssd",
    aliases: &[],
    description: "normalised SSD (intensities mapped from 0..255 onto 0..1, as MTF)",
    build: AmBuilder::plain(|_| Box::new(Nssd::default())),
};

/// The scale of the intensity mapping.
const SCALE: f32 = 1.0 / 255.0;
/// What the scale does to `f` and its derivatives with respect to the intensities.
const SCALE_SQ: f64 = (SCALE as f64) * (SCALE as f64);

/// SSD's value and derivatives, times `s^2`.
#[derive(Debug, Default, Clone)]
pub struct Nssd(Ssd);

impl Am for Nssd {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn pixelwise(&self) -> bool {
        true
    }
    fn set_template(&mut self, template: &[f32]) {
        self.0.set_template(template)
    }
    fn template(&self) -> &[f32] {
        self.0.template()
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        SCALE_SQ * self.0.similarity(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let f = self.0.gradient(wrt, current, grad);
        grad.iter_mut().for_each(|g| *g *= SCALE_SQ as f32);
        SCALE_SQ * f
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
        self.0.hessian(wrt, kind, current, jac, dof, out);
        out[..dof * dof].iter_mut().for_each(|v| *v *= SCALE_SQ);
    }
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        for (o, &p) in out.iter_mut().zip(patch) {
            *o = SCALE * p;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nssd_is_ssd_on_the_unit_range() {
        let t: Vec<f32> = (0..100).map(|i| (i * 37 % 251) as f32).collect();
        let c: Vec<f32> = t.iter().map(|v| 255.0 - v).collect();
        let mut nssd = Nssd::default();
        let mut ssd = super::super::build("ssd").unwrap();
        nssd.set_template(&t);
        ssd.set_template(&t);
        let (a, b) = (nssd.similarity(&c), ssd.similarity(&c));
        assert!((a - b / 255f64.powi(2)).abs() < 1e-9 * b.abs(), "{a} {b}");
        // Opposite patches over the full range: every difference is 1 on the unit scale or less.
        assert!(a >= -0.5 * t.len() as f64);
        // The embedding's squared distance is -2 f.
        let (mut et, mut ec) = (vec![0.0; 100], vec![0.0; 100]);
        nssd.embed(&t, &mut et);
        nssd.embed(&c, &mut ec);
        let d: f64 = et
            .iter()
            .zip(&ec)
            .map(|(x, y)| ((x - y) as f64).powi(2))
            .sum();
        assert!((d + 2.0 * a).abs() < 1e-4, "{d} {a}");
    }
}
