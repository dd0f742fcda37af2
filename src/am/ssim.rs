//! Structural similarity (Wang, Bovik, Sheikh and Simoncelli 2004) computed over the whole patch
//! (one window): with population means `mu`, variances `v` and covariance `c` of the template
//! `a = I*` and the current patch `b = I`,
//!
//! `f = (2 mu_a mu_b + C1)(2 c_ab + C2) / ((mu_a^2 + mu_b^2 + C1)(v_a + v_b + C2))`,
//!
//! `C1 = (0.01 * 255)^2`, `C2 = (0.03 * 255)^2` (the paper's constants for 8-bit images). `f <= 1`
//! with equality only at `b = a`; it is symmetric in `a` and `b`, so the derivatives with respect
//! to the template are those with respect to the current patch with the roles swapped.
//!
//! ## Derivatives
//!
//! Write `x` for the patch the derivative is taken with respect to and `y` for the other one. `f`
//! is a function `F(m, q, r)` of three moments of `x` (the other patch's mean `mu_y` and variance
//! `v_y` are constants): `m = 1/N sum x_i`, `q = 1/N sum x_i^2`, `r = 1/N sum x_i y_i`, since
//! `mu_x = m`, `v_x = q - m^2`, `c_xy = r - mu_y m`:
//! `F = A1 A2 / (B1 B2)` with `A1 = 2 mu_y m + C1`, `B1 = mu_y^2 + m^2 + C1`,
//! `A2 = 2 (r - mu_y m) + C2`, `B2 = v_y + q - m^2 + C2` (`B1, B2 >= C1, C2 > 0`: smooth everywhere).
//! Its gradient `F_s` and Hessian `F_st` in `(m, q, r)` are propagated with a second-order jet
//! ([`Jet`]: sums, products and reciprocals). Per pixel, `dm/dx_i = 1/N`, `dq/dx_i = 2 x_i / N`,
//! `dr/dx_i = y_i / N`, and the only non-zero second derivative is `d2q/dx_i^2 = 2 / N`, so
//!
//! - gradient: `df/dx_i = (F_m + 2 F_q x_i + F_r y_i) / N`;
//! - Newton: `J^T (d2f/dx2) J = 1/N^2 sum_st F_st u_s u_t^T + 2 F_q / N J^T J` with
//!   `u_m = J^T 1`, `u_q = 2 J^T x`, `u_r = J^T y`.
//!
//! Both are evaluated in centred form to avoid cancellation (`x_i = (x_i - m) + m`): the gradient
//! as `(F_m + 2 m F_q + mu_y F_r) / N + (2 F_q (x_i - m) + F_r (y_i - mu_y)) / N`, the Hessian with
//! `u' = (J^T 1, J^T (x - m), J^T (y - mu_y))` and `u = B u'`, `B = [[1, 0, 0], [2m, 2, 0],
//! [mu_y, 0, 1]]`, i.e. the moment Hessian `B^T F B`.
//!
//! ## Hessian kinds
//!
//! - Newton: the above at the current patch.
//! - After convergence: the above at `b = a` (both patches the template).
//! - Gauss-Newton: SSIM is not a sum of squares, so as for MI the "Gauss-Newton" Hessian is the
//!   negative semi-definite part of the projected Newton Hessian (an ascent direction always,
//!   equal to Newton at the maximum `b = a`, where Newton is negative semi-definite). Default.
//!
//! The moments of a patch are three vectorised passes; the Hessian recomputes them rather than
//! comparing the patch with the last one (which costs as much). No scratch is allocated after
//! the first call. No embedding: there is no L2 geometry ranking patches as SSIM does.

use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::linalg::products::jtj_into;
use crate::linalg::{dot, negative_part, sum};
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "ssim",
    aliases: &[],
    description: "structural similarity over the whole patch",
    build: AmBuilder::plain(|_| Box::new(Ssim::default())),
};

const C1: f64 = (0.01 * 255.0) * (0.01 * 255.0);
const C2: f64 = (0.03 * 255.0) * (0.03 * 255.0);

/// A value with its gradient and Hessian in (up to) three variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Jet {
    pub v: f64,
    pub d: [f64; 3],
    pub h: [[f64; 3]; 3],
}

impl Jet {
    /// A constant.
    pub fn cst(v: f64) -> Self {
        Jet {
            v,
            ..Default::default()
        }
    }
    /// Variable `k` at value `v`.
    pub fn var(v: f64, k: usize) -> Self {
        let mut j = Jet::cst(v);
        j.d[k] = 1.0;
        j
    }
    /// `s * self + t`.
    pub fn affine(self, s: f64, t: f64) -> Self {
        let mut r = self;
        r.v = s * self.v + t;
        for k in 0..3 {
            r.d[k] *= s;
            for l in 0..3 {
                r.h[k][l] *= s;
            }
        }
        r
    }
    /// `1 / self`: `r' = -f'/f^2`, `r'' = -f''/f^2 + 2 f' f'^T / f^3`.
    pub fn recip(self) -> Self {
        let (f, f2) = (self.v, self.v * self.v);
        let mut r = Jet::cst(1.0 / f);
        for k in 0..3 {
            r.d[k] = -self.d[k] / f2;
            for l in 0..3 {
                r.h[k][l] = -self.h[k][l] / f2 + 2.0 * self.d[k] * self.d[l] / (f2 * f);
            }
        }
        r
    }
}

impl std::ops::Add for Jet {
    type Output = Jet;
    fn add(self, o: Jet) -> Jet {
        let mut r = self;
        r.v += o.v;
        for k in 0..3 {
            r.d[k] += o.d[k];
            for l in 0..3 {
                r.h[k][l] += o.h[k][l];
            }
        }
        r
    }
}

impl std::ops::Sub for Jet {
    type Output = Jet;
    fn sub(self, o: Jet) -> Jet {
        self + o.affine(-1.0, 0.0)
    }
}

impl std::ops::Mul for Jet {
    type Output = Jet;
    /// `(fg)' = f'g + fg'`, `(fg)'' = f''g + f'g'^T + g'f'^T + fg''`.
    fn mul(self, o: Jet) -> Jet {
        let mut r = Jet::cst(self.v * o.v);
        for k in 0..3 {
            r.d[k] = self.d[k] * o.v + self.v * o.d[k];
            for l in 0..3 {
                r.h[k][l] = self.h[k][l] * o.v
                    + self.d[k] * o.d[l]
                    + o.d[k] * self.d[l]
                    + self.v * o.h[k][l];
            }
        }
        r
    }
}

/// `sum_{s,t} u_s[i] M[s][t] u_t[j]` into `out` (row-major `dof x dof`), scaled by `scale`, plus
/// what `out` holds times `base`.
pub(crate) fn add_moment_form<const K: usize>(
    u: &[[f64; MAX_DOF]; K],
    m: &[[f64; K]; K],
    scale: f64,
    dof: usize,
    out: &mut [f64; MAX_DOF * MAX_DOF],
) {
    for i in 0..dof {
        for j in 0..dof {
            let mut acc = 0.0;
            for s in 0..K {
                for t in 0..K {
                    acc += u[s][i] * m[s][t] * u[t][j];
                }
            }
            out[i * dof + j] += scale * acc;
        }
    }
}

/// Centred statistics of the variable patch `x` and the other one `y`.
#[derive(Clone, Copy, Debug, Default)]
struct Moments {
    mx: f64,
    vx: f64,
    my: f64,
    vy: f64,
    cxy: f64,
}

/// Moments of `x` and `y`; writes the centred patches to `xc`, `yc`.
fn moments(x: &[f32], y: &[f32], xc: &mut Vec<f32>, yc: &mut Vec<f32>) -> Moments {
    let n = x.len().max(1) as f64;
    let (mx, my) = (sum(x) / n, sum(y) / n);
    xc.clear();
    xc.extend(x.iter().map(|&v| (v as f64 - mx) as f32));
    yc.clear();
    yc.extend(y.iter().map(|&v| (v as f64 - my) as f32));
    // Second moments in double precision, eight lanes at a time.
    let (mut sxx, mut syy, mut sxy) = ([0.0f64; 8], [0.0f64; 8], [0.0f64; 8]);
    let (ex, ey) = (x.chunks_exact(8), y.chunks_exact(8));
    let (rx, ry) = (ex.remainder(), ey.remainder());
    for (a, b) in ex.zip(ey) {
        for l in 0..8 {
            let (p, q) = (a[l] as f64 - mx, b[l] as f64 - my);
            sxx[l] += p * p;
            syy[l] += q * q;
            sxy[l] += p * q;
        }
    }
    for (&a, &b) in rx.iter().zip(ry) {
        let (p, q) = (a as f64 - mx, b as f64 - my);
        sxx[0] += p * p;
        syy[0] += q * q;
        sxy[0] += p * q;
    }
    let tot = |s: [f64; 8]| s.iter().sum::<f64>() / n;
    Moments {
        mx,
        vx: tot(sxx),
        my,
        vy: tot(syy),
        cxy: tot(sxy),
    }
}

/// SSIM as a jet in the raw moments `(m, q, r)` of the variable patch.
fn ssim_jet(s: &Moments) -> Jet {
    let m = Jet::var(s.mx, 0);
    let q = Jet::var(s.vx + s.mx * s.mx, 1);
    let r = Jet::var(s.cxy + s.mx * s.my, 2);
    let a1 = m.affine(2.0 * s.my, C1);
    let b1 = m * m + Jet::cst(s.my * s.my + C1);
    let a2 = (r - m.affine(s.my, 0.0)).affine(2.0, C2);
    let b2 = q - m * m + Jet::cst(s.vy + C2);
    a1 * a2 * b1.recip() * b2.recip()
}

/// The SSIM value from the moments (no jet).
fn ssim_value(s: &Moments) -> f64 {
    (2.0 * s.mx * s.my + C1) * (2.0 * s.cxy + C2)
        / ((s.mx * s.mx + s.my * s.my + C1) * (s.vx + s.vy + C2))
}

#[derive(Debug, Clone, Default)]
pub struct Ssim {
    template: Vec<f32>,
    /// Scratch: the centred variable and other patches.
    xc: Vec<f32>,
    yc: Vec<f32>,
}

impl Ssim {
    /// `(x, y)` for a derivative with respect to `wrt`.
    fn stats(&mut self, wrt: Wrt, current: &[f32]) -> Moments {
        match wrt {
            Wrt::Current => moments(current, &self.template, &mut self.xc, &mut self.yc),
            Wrt::Template => moments(&self.template, current, &mut self.xc, &mut self.yc),
        }
    }
}

impl Am for Ssim {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities::DERIVATIVES_ONLY
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        let s = self.stats(Wrt::Current, current);
        ssim_value(&s)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let s = self.stats(wrt, current);
        let j = ssim_jet(&s);
        let n = current.len().max(1) as f64;
        let k0 = ((j.d[0] + 2.0 * s.mx * j.d[1] + s.my * j.d[2]) / n) as f32;
        let (kx, ky) = ((2.0 * j.d[1] / n) as f32, (j.d[2] / n) as f32);
        for ((g, &x), &y) in grad.iter_mut().zip(&self.xc).zip(&self.yc) {
            *g = k0 + kx * x + ky * y;
        }
        ssim_value(&s)
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
        let s = if kind == HessianKind::AfterConvergence {
            let t = std::mem::take(&mut self.template);
            let s = moments(&t, &t, &mut self.xc, &mut self.yc);
            self.template = t;
            s
        } else {
            self.stats(wrt, current)
        };
        let j = ssim_jet(&s);
        let n = self.xc.len().max(1);
        let nf = n as f64;
        // u' = (J^T 1, J^T (x - m), J^T (y - mu_y)).
        let mut u = [[0.0f64; MAX_DOF]; 3];
        for k in 0..dof {
            let col = &jac[k * n..(k + 1) * n];
            u[0][k] = sum(col);
            u[1][k] = dot(col, &self.xc);
            u[2][k] = dot(col, &self.yc);
        }
        // B^T F B with B = [[1, 0, 0], [2m, 2, 0], [mu_y, 0, 1]].
        let b = [[1.0, 0.0, 0.0], [2.0 * s.mx, 2.0, 0.0], [s.my, 0.0, 1.0]];
        let mut m = [[0.0f64; 3]; 3];
        for (p, row) in m.iter_mut().enumerate() {
            for (q, e) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (s1, bs) in b.iter().enumerate() {
                    for (t1, bt) in b.iter().enumerate() {
                        acc += bs[p] * j.h[s1][t1] * bt[q];
                    }
                }
                *e = acc;
            }
        }
        out[..dof * dof].fill(0.0);
        jtj_into(jac, None, dof, dof, out);
        let diag = 2.0 * j.d[1] / nf;
        out[..dof * dof].iter_mut().for_each(|v| *v *= diag);
        add_moment_form(&u, &m, 1.0 / (nf * nf), dof, out);
        if kind == HessianKind::GaussNewton {
            negative_part(out, dof);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    use crate::am::tests::patch;

    #[test]
    fn one_at_identity_and_below_elsewhere() {
        let mut rng = Rng::new(2);
        let t = patch(&mut rng, 400);
        let mut am = Ssim::default();
        am.set_template(&t);
        assert!((am.similarity(&t) - 1.0).abs() < 1e-9);
        let noisy: Vec<f32> = t
            .iter()
            .map(|&v| v + rng.range(-20.0, 20.0) as f32)
            .collect();
        let v = am.similarity(&noisy);
        assert!(v < 0.99 && v > 0.5, "{v}");
        // Gradient vanishes at the maximum.
        let mut g = vec![0f32; 400];
        am.gradient(Wrt::Current, &t, &mut g);
        assert!(g.iter().all(|v| v.abs() < 1e-7));
    }

    #[test]
    fn symmetric_and_nearly_invariant_to_small_bias_not_to_gain() {
        let mut rng = Rng::new(3);
        let t = patch(&mut rng, 400);
        let c: Vec<f32> = t
            .iter()
            .map(|&v| v + rng.range(-30.0, 30.0) as f32)
            .collect();
        let mut am = Ssim::default();
        am.set_template(&t);
        let f1 = am.similarity(&c);
        am.set_template(&c);
        assert!((am.similarity(&t) - f1).abs() < 1e-12);
        // The structure term is invariant to a bias; the luminance term nearly so when the bias
        // is small against the mean.
        am.set_template(&t);
        let biased: Vec<f32> = t.iter().map(|&v| v + 5.0).collect();
        assert!(am.similarity(&biased) > 0.999);
        // A contrast change costs more.
        let gain: Vec<f32> = t.iter().map(|&v| 0.5 * v + 62.5).collect();
        assert!(am.similarity(&gain) < 0.85);
    }

    #[test]
    fn jet_matches_finite_differences() {
        let s = Moments {
            mx: 100.0,
            vx: 900.0,
            my: 110.0,
            vy: 700.0,
            cxy: 500.0,
        };
        let j = ssim_jet(&s);
        assert!((j.v - ssim_value(&s)).abs() < 1e-12);
        // Perturb the raw moments.
        let at = |d: [f64; 3]| {
            let m = s.mx + d[0];
            let q = s.vx + s.mx * s.mx + d[1];
            let r = s.cxy + s.mx * s.my + d[2];
            ssim_jet(&Moments {
                mx: m,
                vx: q - m * m,
                my: s.my,
                vy: s.vy,
                cxy: r - m * s.my,
            })
        };
        for k in 0..3 {
            let h = 1e-3;
            let mut d = [0.0; 3];
            d[k] = h;
            let p = at(d);
            d[k] = -h;
            let m = at(d);
            let fd = (p.v - m.v) / (2.0 * h);
            assert!((fd - j.d[k]).abs() < 1e-6 * j.d[k].abs().max(1e-9), "{k}");
            let scale = j.h[k].iter().fold(0f64, |a, v| a.max(v.abs()));
            for l in 0..3 {
                let fd = (p.d[l] - m.d[l]) / (2.0 * h);
                assert!((fd - j.h[k][l]).abs() < 1e-5 * scale + 1e-15, "{k} {l}");
            }
        }
    }
}
