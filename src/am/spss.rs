//! Sum of pixel-wise structural similarity: `f = sum_i s(I*_i, I_i)` with
//! `s(a, b) = (2 a b + c) / (a^2 + b^2 + c)`, `c = (0.2 * 255)^2`, the luminance term of SSIM
//! applied to single pixels. `s <= 1` with equality only at `a = b`, since
//! `1 - s = (a - b)^2 / (a^2 + b^2 + c)`: a squared error relative to the pixels' energy, so the
//! same difference costs less on bright pixels. Symmetric in `a` and `b`.
//!
//! The constant is a stabiliser, as in SSIM, but much larger than SSIM's `C1 = (0.01 * 255)^2`:
//! `s` is a bump of width about `sqrt(a^2 + b^2 + c)` grey levels, so with a small `c` the
//! near-black pixels both dominate the similarity (their relative errors are noise) and make it
//! sharply curved at the grey-level scale (with SSIM's `C2 = (0.03 * 255)^2` the generic
//! finite-difference check at one grey level measured 0.8% gradient errors on dark pixels, 0.15%
//! with this `c`). With `c = 2601` a pixel pair at 20 weighs like one at 50, and bright pixels
//! still see the relative error.
//!
//! ## Derivatives
//!
//! Per pixel, with `x` the variable intensity, `y` the other one and `D = x^2 + y^2 + c`
//! (`>= c > 0`: smooth everywhere):
//! - `ds/dx = (2y D - (2xy + c) 2x) / D^2 = 2 (y - x s) / D`;
//! - `d2s/dx2 = d/dx [2 (y - x s) / D] = (-2 s - 2 x s') / D - 2 (y - x s) 2x / D^2
//!   = -2 (s + 2 x s') / D` (with `s' = ds/dx`).
//!
//! `f` is separable, so `d2f/dx2` is diagonal and every Hessian is `J^T diag(h) J`:
//! - Newton: `h_i = d2s/dx2` at the current patch;
//! - Gauss-Newton: `f = N - sum_i rho_i^2` with the residual `rho = (x - y) / sqrt(D)`,
//!   `drho/dx = (D - (x - y) x) / D^{3/2}`, so `h_i = -2 (D - (x - y) x)^2 / D^3 <= 0` (default);
//! - after convergence (`x = y = I*`): `s = 1`, `s' = 0`, `h_i = -2 / (2 I*_i^2 + c)`, equal to
//!   both above there.
//!
//! The value is accumulated as `N - sum_i (1 - s_i)` and `y - x s` as `(y - x) + x (1 - s)`, which
//! keep single precision accurate near a match. No embedding: `1 - s` is not a squared difference of per-pixel embeddings.

use super::intensity_map::jt_diag_j;
use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "spss",
    aliases: &[],
    description: "sum of pixel-wise structural similarity",
    build: AmBuilder::plain(|_| Box::new(Spss::default())),
};

const C: f32 = (0.2 * 255.0) * (0.2 * 255.0);

#[derive(Debug, Default, Clone)]
pub struct Spss {
    template: Vec<f32>,
    /// Scratch: the per-pixel Hessian diagonal.
    diag: Vec<f32>,
}

/// `1 - s(x, y) = (x - y)^2 / (x^2 + y^2 + c)`: summing these deficits (small numbers) instead of
/// the `s` (all close to 1) keeps the value accurate in single precision.
#[inline]
fn deficit(x: f32, y: f32) -> f32 {
    let d = x - y;
    d * d / (x * x + y * y + C)
}

fn value(a: &[f32], b: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for (ca, cb) in a.chunks(256).zip(b.chunks(256)) {
        let v: f32 = ca.iter().zip(cb).map(|(&x, &y)| deficit(x, y)).sum();
        total += v as f64;
    }
    a.len() as f64 - total
}

impl Am for Spss {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn pixelwise(&self) -> bool {
        true
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities::DERIVATIVES_ONLY
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
        self.diag.resize(template.len(), 0.0);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        value(&self.template, current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        // Symmetric: the same formula with the variable and the other patch swapped.
        let mut total = 0.0f64;
        let (t, c) = (&self.template, current);
        for ((gc, tc), cc) in grad.chunks_mut(256).zip(t.chunks(256)).zip(c.chunks(256)) {
            let mut acc = 0.0f32;
            for ((g, &a), &b) in gc.iter_mut().zip(tc).zip(cc) {
                let (x, y) = match wrt {
                    Wrt::Current => (b, a),
                    Wrt::Template => (a, b),
                };
                // y - x s = (y - x) + x (1 - s).
                let d = x * x + y * y + C;
                let e = x - y;
                let def = e * e / d;
                acc += def;
                *g = 2.0 * (x * def - e) / d;
            }
            total += acc as f64;
        }
        self.template.len() as f64 - total
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
        let kind = kind.or(self.default_hessian());
        self.diag.resize(self.template.len(), 0.0);
        for ((h, &a), &b) in self.diag.iter_mut().zip(&self.template).zip(current) {
            let (x, y) = match wrt {
                Wrt::Current => (b, a),
                Wrt::Template => (a, b),
            };
            *h = match kind {
                HessianKind::AfterConvergence => -2.0 / (2.0 * a * a + C),
                HessianKind::GaussNewton | HessianKind::Default => {
                    let d = x * x + y * y + C;
                    let r = d - (x - y) * x;
                    -2.0 * r * r / (d * d * d)
                }
                HessianKind::Newton => {
                    let d = x * x + y * y + C;
                    let e = x - y;
                    let def = e * e / d;
                    let dv = 2.0 * (x * def - e) / d;
                    -2.0 * (1.0 - def + 2.0 * x * dv) / d
                }
            };
        }
        jt_diag_j(jac, &self.diag, dof, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn n_at_identity_below_elsewhere_and_symmetric() {
        let mut rng = Rng::new(12);
        let t: Vec<f32> = (0..300).map(|_| rng.range(0.0, 255.0) as f32).collect();
        let c: Vec<f32> = t
            .iter()
            .map(|&v| v + rng.range(-20.0, 20.0) as f32)
            .collect();
        let mut am = Spss::default();
        am.set_template(&t);
        assert!((am.similarity(&t) - 300.0).abs() < 1e-3);
        let f = am.similarity(&c);
        assert!(f < 300.0 - 1.0);
        am.set_template(&c);
        assert!((am.similarity(&t) - f).abs() < 1e-3);
        // A dark pixel off by 10 costs more than a bright one off by 10.
        am.set_template(&[20.0, 200.0]);
        assert!(am.similarity(&[30.0, 200.0]) < am.similarity(&[20.0, 210.0]));
    }

    #[test]
    fn per_pixel_derivatives_match_finite_differences() {
        for &(x, y) in &[(10.0f64, 40.0f64), (200.0, 150.0), (0.0, 0.0), (-5.0, 80.0)] {
            let c = C as f64;
            let sv = |x: f64| (2.0 * x * y + c) / (x * x + y * y + c);
            let d = x * x + y * y + c;
            let ds = 2.0 * (y - x * sv(x)) / d;
            let dsv = |x: f64| 2.0 * (y - x * sv(x)) / (x * x + y * y + c);
            let d2 = -2.0 * (sv(x) + 2.0 * x * ds) / d;
            let h = 1e-3;
            assert!(((sv(x + h) - sv(x - h)) / (2.0 * h) - ds).abs() < 1e-8);
            assert!(((dsv(x + h) - dsv(x - h)) / (2.0 * h) - d2).abs() < 1e-8);
        }
    }
}
