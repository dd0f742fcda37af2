//! Kullback-Leibler divergence between joint intensity histograms, negated:
//! `f = -KL(p0 || m) = sum_ab p0(a, b) log(m(a, b) / p0(a, b))` with
//!
//! - `p(a, b)` the joint histogram of the template and current intensities and `p0(a, b)` that of
//!   the template with itself (what `p` is at `I = I*`), both estimated with the cubic B-spline
//!   Parzen window of [`super::parzen`] (8 bins over `0..255`, padding bins, smooth);
//! - `m = (1 - alpha) p + alpha p0`, `alpha = 0.1`: Lee's alpha-skew divergence. The plain
//!   `KL(p0 || p)` is infinite as soon as the current patch leaves a cell of the template's
//!   support empty (any large misalignment), and `KL(p || p0)` as soon as it fills a cell outside
//!   it; the skew keeps `m >= alpha p0 > 0` on the support of `p0`, the only cells summed.
//!
//! `f <= 0` (Gibbs' inequality: `m` is a distribution), with equality only when `m = p0`, i.e.
//! `p = p0`: the maximum is at `I = I*` (unlike MI's Parzen estimate, whose optimum is biased,
//! this one is exactly where the histograms coincide). Why not the marginal histograms alone:
//! they ignore where the pixels are (any permutation of a patch has the same histogram), so
//! a shift of a textured patch barely changes them and nothing pins the warp; the joint histogram
//! against the template's own joint does.
//!
//! ## Derivatives
//!
//! As in [`super::parzen`], with `k = 7/255` the bin scale, `beta` the B-spline and `t_j`, `c_j`
//! the scaled intensities: `p(a, b) = 1/N sum_j beta(a - t_j) beta(b - c_j)`,
//! `p0(a, b) = 1/N sum_j beta(a - t_j) beta(b - t_j)`. With respect to the current pixels only
//! `p` moves; with respect to the template's both do (`p0` through both coordinates).
//! First differential (with `dm = (1 - alpha) dp + alpha dp0`):
//! `dF = sum_ab dp0 (log(m / p0) - 1 + alpha p0 / m) + dp (1 - alpha) p0 / m`, i.e.
//! `G_p = (1 - alpha) p0 / m` and `G_0 = log(m / p0) + alpha p0 / m` (the `-1` drops since
//! `sum_ab dp0 = 0`, the B-spline being a partition of unity). Per pixel:
//! - `dF/dc_j = k/N sum_ab beta(a - t_j) beta'(b - c_j) G_p(a, b)`;
//! - `dF/dt_j = k/N sum_ab [beta'(a - t_j) beta(b - c_j) G_p(a, b) +
//!   (beta'(a - t_j) beta(b - t_j) + beta(a - t_j) beta'(b - t_j)) G_0(a, b)]`.
//!
//! Second differential: with `u = dp0`, `dm` as above, the first-order terms of `dG` give
//! `u dG_0 + dp dG_p = 2 u dm / m - u^2 / p0 - p0 dm^2 / m^2 = -p0 (dm / m - u / p0)^2`, so
//! `d2F = sum_ab [G_p d2p + G_0 d2p0] - sum_ab p0 (dm / m - dp0 / p0)^2`. Projected on `J`:
//! `J^T H J = sum_j D_j J_j J_j^T + Q` with `D_j = sum_ab G_p d2p/dx_j^2 + G_0 d2p0/dx_j^2` (16 or
//! 32 cells per pixel; `d2p0/dt_j^2` has the cross term `2 beta' beta'`) and
//! `Q = -sum_ab p0 W W^T`, `W = ((1 - alpha) V_p + alpha V_0) / m - V_0 / p0`,
//! `V_p(a, b) = sum_j dp(a, b)/dx_j J_j`, `V_0` likewise for `p0` (zero for the current pixels).
//!
//! ## Hessian kinds
//!
//! - Newton (default): `D + Q` at the current patch. Measured on the recovery protocol (coffee
//!   texture, sigma 2 px, FCLK, translation): 10 of 10 trials converge with Newton, 9 with
//!   Gauss-Newton, 5 with the Hessian after convergence, whose curvature only holds within about
//!   1 px of the optimum.
//! - Gauss-Newton: `Q`, negative semi-definite always (a sum of `-p0 W W^T`); the dropped `D`
//!   vanishes at `I = I*` (there `G_p = 1 - alpha` and `G_0 = alpha` are constants and
//!   `sum_ab d2p = sum_ab d2p0 = 0`).
//! - After convergence: Newton at `I = I*`, i.e. `Q` with `m = p = p0` (computed once per
//!   template), the same for either patch.
//!
//! ## Status: similarity only (the particle filter)
//!
//! The derivatives are exact (the generic finite-difference tests check them), but they are not
//! offered to the gradient search methods (`Capabilities::derivatives` is false, as for SAD): the
//! optimum of this divergence is too flat for a Newton step. At `p = p0` the Hessian is
//! `Q = -sum p0 W W^T` with `W ~ V_p = sum_j beta(a - t_j) beta'(b - t_j) J_j`: the first-order
//! move of histogram mass. Over a textured patch, the pixels of one intensity have image
//! gradients in every direction (light-to-dark as often as dark-to-light), so these sums nearly
//! cancel and `f` falls only with the fourth power of the misalignment near the truth, except
//! along the few directions that the patch's border pins. (MI and CCRE do not have this
//! problem: their joint entropy also reacts to the spread of the histogram, a second-order
//! term that does not cancel.) Measured on the recovery protocol (coffee texture, 100 x 100 px
//! target, start sigma 2 px, 30 trials):
//!
//! - similitude: FCLK converges to 0.08 px from the truth in 29 of 30 trials;
//! - homography, Newton Hessian: every SM stops at a point 0.35 px from the truth where `f` is
//!   -5.6e-7 (against 0 at the truth and about -4e-5 at 0.1 px across the valley), and zig-zags
//!   there until the iterations run out. Errors of the sampled image gradients (bilinear
//!   interpolation of central differences) do not cancel over the pixels as the true
//!   derivatives do, and there they outweigh the cancelled signal. 5-11 of the 30 trials
//!   diverge (the Newton Hessian is indefinite 2 px away);
//! - homography, Gauss-Newton: 29-30 of 30 trials diverge.
//!
//! The sampling methods (NN, which ranks by the similarity itself when a model has no embedding,
//! and the particle filter) only compare similarities, and for them the maximum at `I = I*` is
//! sharp enough: `f` is exactly 0 at the truth and negative elsewhere (every NN and PF
//! combination passes the generic recovery test). (MTF's KLD compares the marginal
//! histograms of the two patches, which a shift of a textured patch barely changes: a weaker
//! signal still.)
//!
//! The histograms of the last patch are kept from the similarity or gradient call for the
//! Hessian on the same patch. No embedding (a divergence between joint histograms of the pair).

use super::parzen::{PDOF, SCALE, SIDE, Weights};
use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::MAX_DOF;
use crate::registry::Entry;

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "kld",
    aliases: &[],
    description: "Kullback-Leibler (alpha-skew) divergence of the joint histogram from the template's (similarity only: NN, particle filter)",
    build: AmBuilder::plain(|_| Box::new(Kld::default())),
};

const ALPHA: f64 = 0.1;

/// The statistics of one (template, current) pair on the support of `p0`.
#[derive(Clone, Debug)]
struct Stats {
    p: Vec<f64>,
    m: Vec<f64>,
    gp: Vec<f64>,
    g0: Vec<f64>,
    value: f64,
}

impl Default for Stats {
    fn default() -> Self {
        Stats {
            p: vec![0.0; SIDE * SIDE],
            m: vec![0.0; SIDE * SIDE],
            gp: vec![0.0; SIDE * SIDE],
            g0: vec![0.0; SIDE * SIDE],
            value: 0.0,
        }
    }
}

/// A pixel's four weights (f32) in f64.
fn wide(w: &[f32; 4]) -> [f64; 4] {
    w.map(f64::from)
}

/// `h[a][b] = 1/N sum_j x_j(a) y_j(b)` over the four cells of each pixel.
fn histogram(xb: &[u32], x: &[[f32; 4]], yb: &[u32], y: &[[f32; 4]], h: &mut [f64]) {
    h.iter_mut().for_each(|v| *v = 0.0);
    let n = xb.len();
    for j in 0..n {
        let (a, b) = (xb[j] as usize, yb[j] as usize);
        for u in 0..4 {
            let row = &mut h[(a + u) * SIDE + b..(a + u) * SIDE + b + 4];
            let xu = x[j][u] as f64;
            for v in 0..4 {
                row[v] += xu * y[j][v] as f64;
            }
        }
    }
    let inv = 1.0 / n.max(1) as f64;
    h.iter_mut().for_each(|v| *v *= inv);
}

impl Stats {
    fn compute(&mut self, tw: &Weights, cw: &Weights, p0: &[f64]) {
        histogram(&tw.base, &tw.w, &cw.base, &cw.w, &mut self.p);
        let mut value = 0.0;
        for i in 0..SIDE * SIDE {
            let q = p0[i];
            if q > 0.0 {
                let m = (1.0 - ALPHA) * self.p[i] + ALPHA * q;
                self.m[i] = m;
                let l = (m / q).ln();
                value += q * l;
                self.gp[i] = (1.0 - ALPHA) * q / m;
                self.g0[i] = l + ALPHA * q / m;
            } else {
                self.m[i] = 0.0;
                self.gp[i] = 0.0;
                self.g0[i] = 0.0;
            }
        }
        self.value = value;
    }
}

#[derive(Debug, Clone, Default)]
pub struct Kld {
    template: Vec<f32>,
    tw: Weights,
    cw: Weights,
    p0: Vec<f64>,
    stats: Stats,
    last: Vec<f32>,
    valid: bool,
    self_stats: Stats,
    self_valid: bool,
    /// Scratch: `V_p`, `V_0` (`SIDE x SIDE x PDOF`), the per-pixel diagonal, a product buffer.
    vp: Vec<f64>,
    v0: Vec<f64>,
    diag: Vec<f32>,
}

impl Kld {
    fn observe(&mut self, current: &[f32]) {
        if self.valid && self.last.as_slice() == current {
            return;
        }
        self.cw.fill(current);
        self.stats.compute(&self.tw, &self.cw, &self.p0);
        self.last.clear();
        self.last.extend_from_slice(current);
        self.valid = true;
    }
}

impl Am for Kld {
    fn max_dof(&self) -> usize {
        super::parzen::PDOF
    }
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            derivatives: false,
            distance: false,
        }
    }
    fn exact_derivatives(&self) -> bool {
        true
    }
    fn default_hessian(&self) -> HessianKind {
        HessianKind::Newton
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
        self.tw.fill(template);
        self.p0.resize(SIDE * SIDE, 0.0);
        histogram(
            &self.tw.base,
            &self.tw.w,
            &self.tw.base,
            &self.tw.w,
            &mut self.p0,
        );
        self.valid = false;
        self.self_valid = false;
        self.vp.resize(SIDE * SIDE * PDOF, 0.0);
        self.v0.resize(SIDE * SIDE * PDOF, 0.0);
        self.diag.resize(template.len(), 0.0);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.observe(current);
        self.stats.value
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        self.observe(current);
        let (gp, g0) = (&self.stats.gp, &self.stats.g0);
        let k = SCALE / current.len().max(1) as f64;
        let (tw, cw) = (&self.tw, &self.cw);
        for (j, out) in grad.iter_mut().enumerate() {
            let (ta, cb) = (tw.base[j] as usize, cw.base[j] as usize);
            let mut acc = 0.0;
            match wrt {
                Wrt::Current => {
                    let (x, y) = (wide(&tw.w[j]), wide(&cw.d[j]));
                    for u in 0..4 {
                        let row = &gp[(ta + u) * SIDE + cb..(ta + u) * SIDE + cb + 4];
                        acc +=
                            x[u] * (row[0] * y[0] + row[1] * y[1] + row[2] * y[2] + row[3] * y[3]);
                    }
                }
                Wrt::Template => {
                    let (tw0, td, cw0) = (wide(&tw.w[j]), wide(&tw.d[j]), wide(&cw.w[j]));
                    for u in 0..4 {
                        let row = &gp[(ta + u) * SIDE + cb..(ta + u) * SIDE + cb + 4];
                        acc += td[u]
                            * (row[0] * cw0[0]
                                + row[1] * cw0[1]
                                + row[2] * cw0[2]
                                + row[3] * cw0[3]);
                        let row0 = &g0[(ta + u) * SIDE + ta..(ta + u) * SIDE + ta + 4];
                        for v in 0..4 {
                            acc += (td[u] * tw0[v] + tw0[u] * td[v]) * row0[v];
                        }
                    }
                }
            }
            *out = (k * acc) as f32;
        }
        self.stats.value
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
        if after {
            if !self.self_valid {
                self.self_stats.compute(&self.tw, &self.tw, &self.p0);
                self.self_valid = true;
            }
        } else {
            self.observe(current);
        }
        let (st, cw) = if after {
            (&self.self_stats, &self.tw)
        } else {
            (&self.stats, &self.cw)
        };
        let tw = &self.tw;
        let n = tw.base.len();
        let inv_n = 1.0 / n.max(1) as f64;
        let current_side = wrt == Wrt::Current;
        let with_diag = kind == HessianKind::Newton;
        self.vp.iter_mut().for_each(|v| *v = 0.0);
        if !current_side {
            self.v0.iter_mut().for_each(|v| *v = 0.0);
        }
        let (gp, g0) = (&st.gp, &st.g0);
        for j in 0..n {
            let (ta, cb) = (tw.base[j] as usize, cw.base[j] as usize);
            let mut jj = [0.0f64; PDOF];
            for (k, e) in jj.iter_mut().enumerate().take(dof) {
                *e = jac[k * n + j] as f64;
            }
            let (x, y, x2, y2) = if current_side {
                (&tw.w[j], &cw.d[j], &tw.w[j], &cw.d2[j])
            } else {
                (&tw.d[j], &cw.w[j], &tw.d2[j], &cw.w[j])
            };
            let (x, y, x2, y2) = (wide(x), wide(y), wide(x2), wide(y2));
            let mut dj = 0.0;
            for u in 0..4 {
                let row = (ta + u) * SIDE + cb;
                for v in 0..4 {
                    let cell = row + v;
                    if with_diag {
                        dj += x2[u] * y2[v] * gp[cell];
                    }
                    let coef = x[u] * y[v];
                    let vc = &mut self.vp[cell * PDOF..cell * PDOF + dof];
                    for (e, &q) in vc.iter_mut().zip(&jj[..dof]) {
                        *e += coef * q;
                    }
                }
            }
            if !current_side {
                let (w0, d1, d2) = (wide(&tw.w[j]), wide(&tw.d[j]), wide(&tw.d2[j]));
                for u in 0..4 {
                    let row = (ta + u) * SIDE + ta;
                    for v in 0..4 {
                        let cell = row + v;
                        if with_diag {
                            let c2 = d2[u] * w0[v] + 2.0 * d1[u] * d1[v] + w0[u] * d2[v];
                            dj += c2 * g0[cell];
                        }
                        let coef = d1[u] * w0[v] + w0[u] * d1[v];
                        let vc = &mut self.v0[cell * PDOF..cell * PDOF + dof];
                        for (e, &q) in vc.iter_mut().zip(&jj[..dof]) {
                            *e += coef * q;
                        }
                    }
                }
            }
            self.diag[j] = dj as f32;
        }
        if with_diag {
            super::intensity_map::jt_diag_j(jac, &self.diag, dof, out);
            let s = SCALE * SCALE * inv_n;
            out[..dof * dof].iter_mut().for_each(|v| *v *= s);
        } else {
            out[..dof * dof].iter_mut().for_each(|v| *v = 0.0);
        }
        // Q = -sum p0 W W^T, W = ((1 - alpha) V_p + alpha V_0) / m - V_0 / p0, times (k/N)^2.
        let kn = SCALE * inv_n;
        let mut q = [0.0f64; PDOF * PDOF];
        for cell in 0..SIDE * SIDE {
            let p0 = self.p0[cell];
            if p0 <= 0.0 {
                continue;
            }
            let m = st.m[cell];
            let mut w = [0.0f64; PDOF];
            let vp = &self.vp[cell * PDOF..cell * PDOF + dof];
            if current_side {
                for (e, &a) in w.iter_mut().zip(vp) {
                    *e = (1.0 - ALPHA) * a / m;
                }
            } else {
                let v0 = &self.v0[cell * PDOF..cell * PDOF + dof];
                for ((e, &a), &b) in w.iter_mut().zip(vp).zip(v0) {
                    *e = ((1.0 - ALPHA) * a + ALPHA * b) / m - b / p0;
                }
            }
            for a in 0..dof {
                let wa = p0 * w[a];
                for b in 0..dof {
                    q[a * PDOF + b] += wa * w[b];
                }
            }
        }
        for a in 0..dof {
            for b in 0..dof {
                out[a * dof + b] -= kn * kn * q[a * PDOF + b];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::tests::smooth_patch;
    use crate::rng::Rng;

    #[test]
    fn non_positive_zero_at_identity_and_maximal_there_over_shifts() {
        let mut rng = Rng::new(43);
        let (res, pad) = (40, 4);
        let side = res + 2 * pad;
        let big = smooth_patch(&mut rng, side);
        let crop = |dx: usize, dy: usize| -> Vec<f32> {
            (0..res * res)
                .map(|i| big[(i / res + dy) * side + i % res + dx])
                .collect()
        };
        let t = crop(pad, pad);
        let mut am = Kld::default();
        am.set_template(&t);
        assert!(am.similarity(&t).abs() < 1e-12);
        let mut g = vec![0f32; res * res];
        am.gradient(Wrt::Current, &t, &mut g);
        assert!(g.iter().all(|v| v.abs() < 1e-9));
        for dy in 0..=2 * pad {
            for dx in 0..=2 * pad {
                if (dx, dy) != (pad, pad) {
                    let v = am.similarity(&crop(dx, dy));
                    assert!(v < 0.0, "shift {dx} {dy}: {v}");
                }
            }
        }
        // Far from the template (reversed) it stays finite: the skew bounds it by log(alpha).
        let rev: Vec<f32> = t.iter().rev().copied().collect();
        let v = am.similarity(&rev);
        assert!(v.is_finite() && v < 0.0 && v >= ALPHA.ln());
    }
}
