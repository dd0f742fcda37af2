//! Normalised gradient fields (Haber and Modersitzki 2006), in their SSD form:
//! `f = -1/2 sum_i |n_i(I*) - n_i(I)|^2` with `n_i(x) = g_i / sqrt(|g_i|^2 + eta^2)` the
//! normalised image gradient of patch `x` at pixel `i` and `eta = 32` grey levels per grid step
//! (the edge-noise level: weaker gradients are damped towards zero instead of normalised to unit
//! length; see below for its size). Invariant to a bias exactly (differences) and nearly to a gain where edges are
//! strong. Haber and Modersitzki's other form, `sum_i 1 - (n_i(I*) . n_i(I))^2`, also ignores
//! contrast inversions, but its value at `I = I*` is not its maximum unless every `|g_i| >> eta`
//! (so the Hessian kinds would not agree at convergence); the SSD form is maximal (0) at `I = I*`.
//!
//! ## The gradients of a patch from the patch
//!
//! The [`Am`] trait only receives intensities, but a patch is sampled on a `res x res` grid
//! (row-major, `N = res^2`), so its gradient field follows from the patch itself: central
//! differences `g_x(u, v) = (x(u + 1, v) - x(u - 1, v)) / 2` with the border replicated
//! (`g_x(0, v) = (x(1, v) - x(0, v)) / 2`, likewise at the far border and for `g_y` along
//! columns), in grey levels per grid step. The replicated border halves the border gradients, but
//! the same operator is applied to both patches. This is a
//! linear operator `g = D x` (`D_x`, `D_y`, each `N x N`, three non-zeros per row), applied and
//! transposed with two passes over the grid. When `N` is not a perfect square (only in tests),
//! the patch is read as `w` columns by `N / w` rows with `w` the largest divisor of `N` not above
//! `sqrt(N)` (a single column or row has zero gradient across it).
//!
//! ## Derivatives
//!
//! With `x` the variable patch (current or template: `f` is symmetric), `y` the other one,
//! `s_i = sqrt(|g_i|^2 + eta^2)`, `n_i = g_i / s_i` (of `x`), `e_i = n_i(x) - n_i(y)`:
//! - `dn_i/dg_i = (Id - n_i n_i^T) / s_i =: M_i` (symmetric), so `df/dg_i = -M_i e_i =: h_i` and
//!   `df/dx = D_x^T h_x + D_y^T h_y`;
//! - second derivatives of `n`: `d2 n_c / dg_k dg_l = -(delta_ck g_l + delta_cl g_k +
//!   delta_kl g_c) / s^3 + 3 g_c g_k g_l / s^5`, contracted with `e`:
//!   `T = -(e g^T + g e^T + (e . g) Id) / s^3 + 3 (e . g) g g^T / s^5`;
//! - Newton: `d2f/dg_i^2 = -(M_i^2 + T_i)` with `M^2 = (Id - (2 - |n|^2) n n^T) / s^2`; the
//!   Hessian in the pixels is `D^T blockdiag(.) D` and, projected on `J`,
//!   `sum_i (D J)_i^T P_i (D J)_i` with `(D J)_i` the `2 x dof` gradients of the Jacobian's
//!   columns at pixel `i` and `P_i` the per-pixel `2 x 2` matrix;
//! - Gauss-Newton (default): `P_i = -M_i^2` (the residual `e` is dropped), negative
//!   semi-definite;
//! - after convergence (`x = y = I*`, `e = 0`): `P_i = -M_i(I*)^2`, equal to both above there.
//!
//! ## The size of `eta`
//!
//! `n(g)` bends on the scale of `s = sqrt(|g|^2 + eta^2)`, so with a small `eta` the similarity is
//! sharply curved in the pixels whose gradient nearly vanishes: with `eta = 10` and one-sided
//! border differences the generic finite-difference check at one grey level measured up to 6%
//! gradient errors on random patches (exact at small steps: the derivatives are right). Halving
//! the border stencil and `eta = 32` bring that below 0.1% (measured on the same kind of
//! patches). Gradients below about `eta` are then compared nearly linearly (SSD of gradients
//! scaled by `1 / eta`), stronger ones by direction: on the 50 x 50 grid over a 100 x 100 px
//! target, a grid step is 2 px, and texture gradients of 10-60 grey levels per step straddle
//! `eta`.
//!
//! The template's field is computed once per template. No embedding: the natural one, the
//! stacked field `n(x)` (whose squared distance is `-2f`), has `2N` values and [`Am::embed`]
//! writes `N`.

use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::linalg::dot;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "ngf",
    aliases: &[],
    description: "normalised gradient fields (SSD form; gradients by differences on the grid)",
    build: AmBuilder::plain(|_| Box::new(Ngf::default())),
};

const ETA: f64 = 32.0;

/// The gradient field of a patch and its normalisation.
#[derive(Debug, Default, Clone)]
struct Field {
    gx: Vec<f64>,
    gy: Vec<f64>,
    nx: Vec<f64>,
    ny: Vec<f64>,
    s: Vec<f64>,
}

/// Conversion of the difference operator's output.
trait Scalar: Copy {
    fn from_f64(v: f64) -> Self;
}
impl Scalar for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}
impl Scalar for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// Differences along one line of the grid (`len` points from `base`, `stride` apart).
fn line_diff<T: Scalar>(v: &[f32], base: usize, stride: usize, len: usize, out: &mut [T]) {
    if len < 2 {
        for k in 0..len {
            out[base + k * stride] = T::from_f64(0.0);
        }
        return;
    }
    let at = |k: usize| v[base + k * stride] as f64;
    out[base] = T::from_f64(0.5 * (at(1) - at(0)));
    out[base + (len - 1) * stride] = T::from_f64(0.5 * (at(len - 1) - at(len - 2)));
    for k in 1..len - 1 {
        out[base + k * stride] = T::from_f64(0.5 * (at(k + 1) - at(k - 1)));
    }
}

/// Adds the transpose of [`line_diff`] applied to `h` into `out`.
fn line_adjoint(h: &[f64], base: usize, stride: usize, len: usize, out: &mut [f64]) {
    if len < 2 {
        return;
    }
    let (first, last) = (base, base + (len - 1) * stride);
    let (hf, hl) = (0.5 * h[first], 0.5 * h[last]);
    out[first] -= hf;
    out[first + stride] += hf;
    out[last] += hl;
    out[last - stride] -= hl;
    for k in 1..len - 1 {
        let i = base + k * stride;
        let v = 0.5 * h[i];
        out[i + stride] += v;
        out[i - stride] -= v;
    }
}

/// `D_x v`, `D_y v` on a `w x rows` grid.
fn grad2d<T: Scalar>(v: &[f32], w: usize, rows: usize, gx: &mut [T], gy: &mut [T]) {
    for r in 0..rows {
        line_diff(v, r * w, 1, w, gx);
    }
    for c in 0..w {
        line_diff(v, c, w, rows, gy);
    }
}

/// The grid a patch of `n` pixels is read as: `(columns, rows)`.
fn dims(n: usize) -> (usize, usize) {
    if n == 0 {
        return (0, 0);
    }
    let mut w = (n as f64).sqrt().floor() as usize;
    while w > 1 && !n.is_multiple_of(w) {
        w -= 1;
    }
    let w = w.max(1);
    (w, n / w)
}

impl Field {
    fn fill(&mut self, x: &[f32], w: usize, rows: usize) {
        let n = x.len();
        for v in [
            &mut self.gx,
            &mut self.gy,
            &mut self.nx,
            &mut self.ny,
            &mut self.s,
        ] {
            v.resize(n, 0.0);
        }
        grad2d(x, w, rows, &mut self.gx, &mut self.gy);
        for i in 0..n {
            let (gx, gy) = (self.gx[i], self.gy[i]);
            let s = (gx * gx + gy * gy + ETA * ETA).sqrt();
            self.s[i] = s;
            self.nx[i] = gx / s;
            self.ny[i] = gy / s;
        }
    }
}

#[derive(Debug, Default, Clone)]
pub struct Ngf {
    template: Vec<f32>,
    w: usize,
    rows: usize,
    tf: Field,
    cf: Field,
    /// Scratch: `h_x`, `h_y`, the adjoint's accumulator, per-pixel `P` entries, the gradients
    /// of the Jacobian's columns, two product buffers.
    hx: Vec<f64>,
    hy: Vec<f64>,
    acc: Vec<f64>,
    pxx: Vec<f32>,
    pxy: Vec<f32>,
    pyy: Vec<f32>,
    djx: Vec<f32>,
    djy: Vec<f32>,
    tx: Vec<f32>,
    ty: Vec<f32>,
}

fn value(a: &Field, b: &Field) -> f64 {
    let mut total = 0.0;
    for i in 0..a.nx.len() {
        let (ex, ey) = (a.nx[i] - b.nx[i], a.ny[i] - b.ny[i]);
        total += ex * ex + ey * ey;
    }
    -0.5 * total
}

impl Ngf {
    fn observe(&mut self, current: &[f32]) {
        self.cf.fill(current, self.w, self.rows);
    }
}

impl Am for Ngf {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    /// The fields are the patch's differences between neighbours on the grid.
    fn needs_grid(&self) -> bool {
        true
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities::DERIVATIVES_ONLY
    }
    fn set_template(&mut self, template: &[f32]) {
        let n = template.len();
        self.template.clear();
        self.template.extend_from_slice(template);
        (self.w, self.rows) = dims(n);
        self.tf.fill(template, self.w, self.rows);
        for v in [&mut self.hx, &mut self.hy, &mut self.acc] {
            v.resize(n, 0.0);
        }
        for v in [
            &mut self.pxx,
            &mut self.pxy,
            &mut self.pyy,
            &mut self.tx,
            &mut self.ty,
        ] {
            v.resize(n, 0.0);
        }
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.observe(current);
        value(&self.tf, &self.cf)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        self.observe(current);
        let (x, y) = match wrt {
            Wrt::Current => (&self.cf, &self.tf),
            Wrt::Template => (&self.tf, &self.cf),
        };
        let n = x.nx.len();
        for i in 0..n {
            let (nx, ny, s) = (x.nx[i], x.ny[i], x.s[i]);
            let (ex, ey) = (nx - y.nx[i], ny - y.ny[i]);
            let ne = nx * ex + ny * ey;
            // h = -M e = -(e - n (n . e)) / s.
            self.hx[i] = -(ex - nx * ne) / s;
            self.hy[i] = -(ey - ny * ne) / s;
        }
        self.acc.iter_mut().for_each(|v| *v = 0.0);
        for r in 0..self.rows {
            line_adjoint(&self.hx, r * self.w, 1, self.w, &mut self.acc);
        }
        for c in 0..self.w {
            line_adjoint(&self.hy, c, self.w, self.rows, &mut self.acc);
        }
        for (g, &a) in grad.iter_mut().zip(&self.acc) {
            *g = a as f32;
        }
        value(&self.tf, &self.cf)
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
        let after = kind == HessianKind::AfterConvergence;
        if !after {
            self.observe(current);
        }
        let (x, y) = match (after, wrt) {
            (true, _) => (&self.tf, &self.tf),
            (false, Wrt::Current) => (&self.cf, &self.tf),
            (false, Wrt::Template) => (&self.tf, &self.cf),
        };
        let newton = kind == HessianKind::Newton;
        let n = x.nx.len();
        for i in 0..n {
            let (nx, ny, s) = (x.nx[i], x.ny[i], x.s[i]);
            let s2 = s * s;
            let k = 2.0 - (nx * nx + ny * ny);
            let (mut axx, mut axy, mut ayy) = (
                (1.0 - k * nx * nx) / s2,
                -k * nx * ny / s2,
                (1.0 - k * ny * ny) / s2,
            );
            if newton {
                let (gx, gy) = (x.gx[i], x.gy[i]);
                let (ex, ey) = (nx - y.nx[i], ny - y.ny[i]);
                let eg = ex * gx + ey * gy;
                let (s3, s5) = (s2 * s, s2 * s2 * s);
                axx += (-2.0 * ex * gx - eg) / s3 + 3.0 * eg * gx * gx / s5;
                axy += -(ex * gy + ey * gx) / s3 + 3.0 * eg * gx * gy / s5;
                ayy += (-2.0 * ey * gy - eg) / s3 + 3.0 * eg * gy * gy / s5;
            }
            self.pxx[i] = -axx as f32;
            self.pxy[i] = -axy as f32;
            self.pyy[i] = -ayy as f32;
        }
        // The gradients of the Jacobian's columns.
        self.djx.resize(dof * n, 0.0);
        self.djy.resize(dof * n, 0.0);
        for c in 0..dof {
            let col = &jac[c * n..(c + 1) * n];
            let (dx, dy) = (
                &mut self.djx[c * n..(c + 1) * n],
                &mut self.djy[c * n..(c + 1) * n],
            );
            grad2d(col, self.w, self.rows, dx, dy);
        }
        for a in 0..dof {
            let (dxa, dya) = (&self.djx[a * n..(a + 1) * n], &self.djy[a * n..(a + 1) * n]);
            for i in 0..n {
                self.tx[i] = self.pxx[i] * dxa[i] + self.pxy[i] * dya[i];
                self.ty[i] = self.pxy[i] * dxa[i] + self.pyy[i] * dya[i];
            }
            for b in a..dof {
                let v = dot(&self.tx, &self.djx[b * n..(b + 1) * n])
                    + dot(&self.ty, &self.djy[b * n..(b + 1) * n]);
                out[a * dof + b] = v;
                out[b * dof + a] = v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn grid_and_difference_operator_with_its_adjoint() {
        assert_eq!(dims(2500), (50, 50));
        assert_eq!(dims(40), (5, 8));
        assert_eq!(dims(7), (1, 7));
        // A ramp along x has g_x = slope (half on the border columns), g_y = 0.
        let (w, rows) = (6, 4);
        let v: Vec<f32> = (0..w * rows).map(|i| 3.0 * (i % w) as f32 + 10.0).collect();
        let (mut gx, mut gy) = (vec![0f64; 24], vec![0f64; 24]);
        grad2d(&v, w, rows, &mut gx, &mut gy);
        for (i, &g) in gx.iter().enumerate() {
            let want = if i % w == 0 || i % w == w - 1 {
                1.5
            } else {
                3.0
            };
            assert!((g - want).abs() < 1e-12);
        }
        assert!(gy.iter().all(|&g| g == 0.0));
        // <D v, h> = <v, D^T h> for both directions.
        let mut rng = Rng::new(4);
        let v: Vec<f32> = (0..24).map(|_| rng.range(0.0, 100.0) as f32).collect();
        let h: Vec<f64> = (0..24).map(|_| rng.normal()).collect();
        grad2d(&v, w, rows, &mut gx, &mut gy);
        let mut acc = vec![0f64; 24];
        for r in 0..rows {
            line_adjoint(&h, r * w, 1, w, &mut acc);
        }
        let lhs: f64 = gx.iter().zip(&h).map(|(a, b)| a * b).sum();
        let rhs: f64 = v.iter().zip(&acc).map(|(&a, b)| a as f64 * b).sum();
        assert!((lhs - rhs).abs() < 1e-9 * lhs.abs().max(1.0));
        let mut acc = vec![0f64; 24];
        for c in 0..w {
            line_adjoint(&h, c, w, rows, &mut acc);
        }
        let lhs: f64 = gy.iter().zip(&h).map(|(a, b)| a * b).sum();
        let rhs: f64 = v.iter().zip(&acc).map(|(&a, b)| a as f64 * b).sum();
        assert!((lhs - rhs).abs() < 1e-9 * lhs.abs().max(1.0));
    }

    #[test]
    fn zero_at_identity_invariant_to_bias_sensitive_to_shift() {
        let res = 30;
        let img = |dx: f32| -> Vec<f32> {
            (0..res * res)
                .map(|i| {
                    let (x, y) = ((i % res) as f32 + dx, (i / res) as f32);
                    120.0 + 100.0 * (0.9 * x).sin() * (0.7 * y).cos()
                })
                .collect()
        };
        let t = img(0.0);
        let mut am = Ngf::default();
        am.set_template(&t);
        assert_eq!(am.similarity(&t), 0.0);
        let biased: Vec<f32> = t.iter().map(|&v| v + 40.0).collect();
        assert!(am.similarity(&biased).abs() < 1e-9);
        // On strong edges (gradients up to 90 per step, above eta) a gain changes the
        // normalised gradients little: it costs less than a 1-px shift.
        let gain: Vec<f32> = t.iter().map(|&v| 0.7 * (v - 120.0) + 120.0).collect();
        let shifted = img(1.0);
        let (fg, fs) = (am.similarity(&gain), am.similarity(&shifted));
        assert!(fs < fg && fs < -1.0, "gain {fg} shift {fs}");
    }
}
