//! Ratio image uniformity (Woods, Cherry and Mazziotta 1992): the ratio image `r = I / I*` of two
//! aligned images is uniform, so its coefficient of variation `std(r) / mean(r)` is minimised.
//! Here `f = -(std(r) / mean(r))^2 = -v / m^2` with `m`, `v` the (population) mean and variance of
//! `r_i = (I_i + eps) / (I*_i + eps)`, `eps = 64` grey levels:
//!
//! - squared, because the coefficient of variation itself has a cone (`sqrt(v)`) at its minimum
//!   `v = 0`, where Newton-type methods need a second derivative; squaring is monotone on
//!   `v >= 0`, so the ranking (and the optimum) are those of RIU;
//! - the offset `eps` keeps the ratio finite on black template pixels and makes `r = 1`
//!   exactly at `I = I*`, so the maximum `f = 0` is at the template. Its size, a quarter of the
//!   grey range, is a trade-off: a ratio against a near-black pixel is mostly noise (the known
//!   weakness of RIU), and `r` is a hyperbola in the template pixel whose curvature relative to
//!   its slope is `2 / (I*_i + eps)`: with `eps = 8` the derivatives with respect to dark template
//!   pixels change by several percent within one grey level (the finite-difference check at one
//!   grey level measured 0.9% errors, 0.17% at `eps = 64`). The price is that the invariance to a
//!   gain `I = g I*` is approximate, `r_i = g - (g - 1) eps / (I*_i + eps)` (exact for `eps = 0`;
//!   exact for a gain on the offset intensities, `I + eps = g (I* + eps)`; tested: gains of 0.6 and 1.7
//!   cost less than 5% of what a reversed patch costs). Template pixels below `-eps / 2` (not
//!   grey levels) are clamped there.
//!
//! ## Derivatives
//!
//! `f = F(m, q) = 1 - q / m^2` with `m = 1/N sum r_i`, `q = 1/N sum r_i^2`; `F_m = 2q / m^3`,
//! `F_q = -1 / m^2` and the second derivatives come from the jet of [`super::ssim::Jet`]. Each
//! `r_i` depends on its own pixel `x_i` only: with `w_i = 1 / (I*_i + eps)`,
//! - with respect to the current pixels `r' = w`, `r'' = 0`;
//! - with respect to the template's `r' = -r w`, `r'' = 2 r w^2`.
//!
//! Then `dm/dx_i = r'_i / N`, `dq/dx_i = 2 r_i r'_i / N`, `d2m/dx_i^2 = r''_i / N`,
//! `d2q/dx_i^2 = (2 r'_i^2 + 2 r_i r''_i) / N`, so
//! - gradient `df/dx_i = r'_i (F_m + 2 F_q r_i) / N`;
//! - Newton `J^T (d2f/dx2) J = 1/N^2 sum_st F_st u_s u_t^T + 1/N J^T diag(d) J` with
//!   `u_m = J^T r'`, `u_q = 2 J^T (r r')` and `d_i = r''_i (F_m + 2 F_q r_i) + 2 F_q r'_i^2`.
//!
//! In centred form (`r_i = (r_i - m) + m`): `F_m + 2 F_q r_i = 2v / m^3 + 2 F_q (r_i - m)`, and
//! `u = B u'` with `u' = (J^T r', J^T ((r - m) r'))`, `B = [[1, 0], [2m, 2]]`.
//!
//! Hessian kinds: Newton at the current patch; after convergence the same at `I = I*` (`r = 1`:
//! `2/N^2 (J^T w)(J^T w)^T - 2/N J^T diag(w^2) J`, negative semi-definite by Cauchy-Schwarz, for
//! either patch); Gauss-Newton (default) the negative semi-definite part of Newton, as for SSIM.
//! No embedding (the ratio couples the two patches).

use super::ssim::{Jet, add_moment_form};
use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::{MAX_DOF, dot, negative_part};
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "riu",
    aliases: &[],
    description: "ratio image uniformity (negated squared coefficient of variation of I / I*)",
    build: AmBuilder::plain(|_| Box::new(Riu::default())),
};

const EPS: f32 = 64.0;

#[derive(Debug, Default, Clone)]
pub struct Riu {
    template: Vec<f32>,
    /// `1 / (I* + eps)` per pixel, and whether it was clamped.
    w: Vec<f32>,
    clamped: Vec<bool>,
    /// Scratch: `r`, `r'`, `(r - m) r'`, the Hessian diagonal, a product buffer.
    r: Vec<f32>,
    rp: Vec<f32>,
    rcp: Vec<f32>,
    diag: Vec<f32>,
}

/// Mean and variance of the ratio image.
struct Stats {
    m: f64,
    v: f64,
}

impl Riu {
    /// Fills `r` for `current`; returns its mean and variance.
    fn ratios(&mut self, current: &[f32]) -> Stats {
        let n = current.len().max(1) as f64;
        self.r.clear();
        self.r
            .extend(current.iter().zip(&self.w).map(|(&c, &w)| (c + EPS) * w));
        let m = crate::linalg::sum(&self.r) / n;
        let mut lanes = [0.0f64; 8];
        let e = self.r.chunks_exact(8);
        for &x in e.remainder() {
            lanes[0] += (x as f64 - m).powi(2);
        }
        for c in e {
            for l in 0..8 {
                let d = c[l] as f64 - m;
                lanes[l] += d * d;
            }
        }
        Stats {
            m,
            v: lanes.iter().sum::<f64>() / n,
        }
    }

    /// `r'` (and `(r - m) r'`) into the scratch buffers; `r` must be filled.
    fn slopes(&mut self, wrt: Wrt, m: f64) {
        let n = self.r.len();
        self.rp.resize(n, 0.0);
        self.rcp.resize(n, 0.0);
        let m = m as f32;
        for i in 0..n {
            let d = match wrt {
                Wrt::Current => self.w[i],
                Wrt::Template if self.clamped[i] => 0.0,
                Wrt::Template => -self.r[i] * self.w[i],
            };
            self.rp[i] = d;
            self.rcp[i] = (self.r[i] - m) * d;
        }
    }
}

fn jet(s: &Stats) -> Jet {
    let m = Jet::var(s.m, 0);
    let q = Jet::var(s.v + s.m * s.m, 1);
    Jet::cst(1.0) - q * (m * m).recip()
}

fn value(s: &Stats) -> f64 {
    if s.m != 0.0 { -s.v / (s.m * s.m) } else { 0.0 }
}

impl Am for Riu {
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
        self.w.clear();
        self.clamped.clear();
        for &t in template {
            let den = t + EPS;
            let c = den.is_nan() || den < 0.5 * EPS;
            self.clamped.push(c);
            self.w.push(1.0 / if c { 0.5 * EPS } else { den });
        }
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        let s = self.ratios(current);
        value(&s)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let s = self.ratios(current);
        if s.m == 0.0 {
            grad.iter_mut().for_each(|g| *g = 0.0);
            return 0.0;
        }
        let j = jet(&s);
        let n = current.len().max(1) as f64;
        self.slopes(wrt, s.m);
        // df/dx_i = [r' (F_m + 2 m F_q) + 2 F_q (r - m) r'] / N.
        let k0 = ((j.d[0] + 2.0 * s.m * j.d[1]) / n) as f32;
        let k1 = (2.0 * j.d[1] / n) as f32;
        for ((g, &d), &dc) in grad.iter_mut().zip(&self.rp).zip(&self.rcp) {
            *g = k0 * d + k1 * dc;
        }
        value(&s)
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
            let s = self.ratios(&t);
            self.template = t;
            s
        } else {
            self.ratios(current)
        };
        out[..dof * dof].iter_mut().for_each(|v| *v = 0.0);
        if s.m == 0.0 {
            return;
        }
        let j = jet(&s);
        let n = self.r.len();
        let nf = n.max(1) as f64;
        self.slopes(wrt, s.m);
        // Diagonal: d_i = r''_i (F_m + 2 F_q r_i) + 2 F_q r'_i^2 (scaled by 1/N).
        let k0 = (j.d[0] + 2.0 * s.m * j.d[1]) as f32;
        let fq2 = (2.0 * j.d[1]) as f32;
        let m = s.m as f32;
        self.diag.resize(n, 0.0);
        for i in 0..n {
            let rp = self.rp[i];
            let rpp = match wrt {
                Wrt::Current => 0.0,
                Wrt::Template if self.clamped[i] => 0.0,
                Wrt::Template => 2.0 * self.r[i] * self.w[i] * self.w[i],
            };
            self.diag[i] = rpp * (k0 + fq2 * (self.r[i] - m)) + fq2 * rp * rp;
        }
        super::intensity_map::jt_diag_j(jac, &self.diag, dof, out);
        for v in out[..dof * dof].iter_mut() {
            *v /= nf;
        }
        let mut u = [[0.0f64; MAX_DOF]; 2];
        for k in 0..dof {
            let col = &jac[k * n..(k + 1) * n];
            u[0][k] = dot(col, &self.rp);
            u[1][k] = dot(col, &self.rcp);
        }
        let b = [[1.0, 0.0], [2.0 * s.m, 2.0]];
        let mut f2 = [[0.0f64; 2]; 2];
        for (p, row) in f2.iter_mut().enumerate() {
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
        add_moment_form(&u, &f2, 1.0 / (nf * nf), dof, out);
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
    fn zero_at_identity_nearly_invariant_to_gain() {
        let mut rng = Rng::new(21);
        let t = patch(&mut rng, 900);
        let mut am = Riu::default();
        am.set_template(&t);
        assert!(am.similarity(&t).abs() < 1e-12);
        let lit: Vec<f32> = t.iter().map(|&v| 1.7 * v).collect();
        let dim: Vec<f32> = t.iter().map(|&v| 0.6 * v).collect();
        let mut shuffled = t.clone();
        shuffled.reverse();
        let bad = am.similarity(&shuffled);
        assert!(bad < -0.1, "{bad}");
        for x in [&lit, &dim] {
            let v = am.similarity(x);
            assert!(v <= 0.0 && v > 0.05 * bad, "{v} vs {bad}");
        }
        // The ratio is taken against the template: the gradient vanishes at I = I*.
        let mut g = vec![0f32; 900];
        am.gradient(Wrt::Current, &t, &mut g);
        assert!(g.iter().all(|v| v.abs() < 1e-9));
    }

    #[test]
    fn exactly_gain_invariant_in_the_ratio_of_offset_intensities() {
        // A gain on the offset intensities (I + eps) = g (I* + eps) leaves r constant: f = 0.
        let mut rng = Rng::new(22);
        let t = patch(&mut rng, 400);
        let c: Vec<f32> = t.iter().map(|&v| 1.3 * (v + EPS) - EPS).collect();
        let mut am = Riu::default();
        am.set_template(&t);
        assert!(am.similarity(&c).abs() < 1e-10);
    }
}
