//! Normalised SSD, as MTF defines it: SSD over intensities first mapped linearly from the pixel
//! range `0..255` onto `0..1`, `f = -1/2 sum_i (s (I*_i - I_i))^2` with `s = 1/255`.
//!
//! The mapping is fixed (not per patch), so the optimum, the search and the robustness are those
//! of SSD; what changes is the scale of `f`, which is what a particle filter's likelihood or a
//! similarity threshold reads (an SSD of 1 on this scale is a difference of 255 gray levels).
//! Not to be confused with the SSD of z-scores, which is ZNCC.

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

#[derive(Debug, Default, Clone)]
pub struct Nssd {
    template: Vec<f32>,
}

impl Nssd {
    fn value(&self, current: &[f32]) -> f64 {
        let mut total = 0.0f64;
        for (ct, cc) in self.template.chunks(256).zip(current.chunks(256)) {
            let s: f32 = ct
                .iter()
                .zip(cc)
                .map(|(t, c)| {
                    let d = SCALE * (t - c);
                    d * d
                })
                .sum();
            total += s as f64;
        }
        -0.5 * total
    }
}

impl Am for Nssd {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.value(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        // df/dI_i = s^2 (I*_i - I_i); the template's is its negative.
        let k = match wrt {
            Wrt::Current => SCALE * SCALE,
            Wrt::Template => -SCALE * SCALE,
        };
        for ((g, &t), &c) in grad.iter_mut().zip(&self.template).zip(current) {
            *g = k * (t - c);
        }
        self.value(current)
    }
    fn hessian(
        &mut self,
        _wrt: Wrt,
        _kind: HessianKind,
        _current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        // d2f/dI2 = -s^2 Id for both arguments and every kind.
        super::minus_jtj(jac, dof, out);
        let k = (SCALE * SCALE) as f64;
        out[..dof * dof].iter_mut().for_each(|v| *v *= k);
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
