//! Illumination models for SSD, estimated jointly with the warp (the tracker option `ilm`).
//!
//! The frame is modelled as the template under a gain and a bias that vary across the patch:
//! `I(x) ~ (1 + g(x)) I*(x) + b(x)`, with `g = sum_k a_k phi_k` and `b = sum_k c_k phi_k` over
//! `K = cells x cells` basis functions of the patch's grid coordinates:
//! - [`Illumination::Pieces`]: `phi_k` is 1 on cell `k` of a `cells x cells` grid, 0 elsewhere (a
//!   gain and a bias per cell: the piecewise gain and bias of Silveira and Malis' illumination
//!   model);
//! - [`Illumination::Radial`]: Gaussian bumps centred on the cells, of the cells' size, normalised
//!   to sum to 1 at every point (a smooth light field: radial basis functions).
//!
//! Writing `theta = (a, c)` and `A = [phi_1 I*, ..., phi_K I*, phi_1, ..., phi_K]` (`N x 2K`, fixed
//! by the template), the similarity is SSD minimised over the light,
//! `f(I*, I) = -1/2 min_theta (|I - I* - A theta|^2 + theta^T Lambda theta)`,
//! a small ridge `Lambda` (1e-4 of each column's squared norm) keeping cells without texture at gain 1 and bias 0. The minimiser is
//! `theta = (A^T A + lambda)^-1 A^T (I - I*)`, precomputed as a `2K x N` matrix when the template is
//! set, so an evaluation costs two passes over `N x 2K`.
//!
//! Derivatives (variable projection: `theta` is optimal, so `df/dtheta = 0` and it needs no
//! derivative of its own), with the residual `r = I - I* - A theta`:
//! - `df/dI = -r`, and `d2f/dI2 = -(Id - A (A^T A + lambda)^-1 A^T)` exactly (the light absorbs
//!   what lies in the span of `A`), so the Hessian wrt the frame is
//!   `-(J^T J - (A^T J)^T (A^T A + lambda)^-1 (A^T J))`;
//! - `df/dI* = (1 + g) r`, with Gauss-Newton's Hessian on `J_w = diag(1 + g) J`, projected the
//!   same way.

use super::{Am, Capabilities, HessianKind, MAX_DOF, Wrt};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Which illumination model a least-squares tracker estimates with the warp.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Illumination {
    /// None: the AM alone.
    #[default]
    None,
    /// A gain and a bias per cell of a grid over the patch.
    #[serde(rename = "pgb")]
    Pieces,
    /// A gain and a bias that vary smoothly: Gaussian radial basis functions on the cells.
    #[serde(rename = "rbf")]
    Radial,
}

/// The AMs an illumination model can be added to (those whose similarity is a sum of squared
/// differences with the template).
pub const LEAST_SQUARES: &[&str] = &["ssd"];

/// The relative weight of the ridge that keeps the light of textureless cells at gain 1, bias 0.
const RIDGE: f64 = 1e-4;

/// SSD under an illumination model.
#[derive(Debug, Clone)]
pub struct IlmSsd {
    kind: Illumination,
    cells: usize,
    template: Vec<f32>,
    /// The basis: `phi[k * n + i]`, basis function `k` at sample `i`.
    phi: Vec<f32>,
    /// `A` by column: `a[j * n + i]`, `j < 2K`.
    a: Vec<f64>,
    /// `(A^T A + lambda)^-1 A^T`, row `j` at `pinv[j * n..]`.
    pinv: Vec<f64>,
    /// `(A^T A + lambda)^-1`.
    inv: DMatrix<f64>,
    /// `lambda` per column of `A`.
    ridge: Vec<f64>,
    /// Scratch of the Hessian: `A^T J` and `(A^T A + lambda)^-1 A^T J`, `2K x MAX_DOF` by row.
    atj: Vec<f64>,
    inv_atj: Vec<f64>,
    /// The last evaluation: light parameters, residual, gain `1 + g` per sample.
    theta: Vec<f64>,
    residual: Vec<f64>,
    gain: Vec<f32>,
}

impl IlmSsd {
    /// SSD under the model `kind` with `cells x cells` cells (1..=8).
    pub fn new(kind: Illumination, cells: usize) -> Self {
        IlmSsd {
            kind,
            cells: cells.clamp(1, 8),
            template: Vec::new(),
            phi: Vec::new(),
            a: Vec::new(),
            pinv: Vec::new(),
            inv: DMatrix::zeros(0, 0),
            ridge: Vec::new(),
            atj: Vec::new(),
            inv_atj: Vec::new(),
            theta: Vec::new(),
            residual: Vec::new(),
            gain: Vec::new(),
        }
    }

    /// The gain `1 + g` of the last evaluation, per sample.
    pub fn gain(&self) -> &[f32] {
        &self.gain
    }

    fn basis(&mut self, n: usize) {
        let res = ((n as f64).sqrt().round() as usize).max(1);
        let k = self.cells * self.cells;
        self.phi = vec![0.0; k * n];
        let cells = self.cells as f64;
        for i in 0..n {
            // Grid coordinates in 0..1 (a square patch, row by row).
            let u = ((i % res) as f64 + 0.5) / res as f64;
            let v = ((i / res) as f64 + 0.5) / res as f64;
            match self.kind {
                Illumination::Pieces | Illumination::None => {
                    let cx = ((u * cells) as usize).min(self.cells - 1);
                    let cy = ((v * cells) as usize).min(self.cells - 1);
                    self.phi[(cy * self.cells + cx) * n + i] = 1.0;
                }
                Illumination::Radial => {
                    let mut total = 0.0;
                    let mut w = [0.0f64; 64];
                    for cy in 0..self.cells {
                        for cx in 0..self.cells {
                            let (du, dv) =
                                (u - (cx as f64 + 0.5) / cells, v - (cy as f64 + 0.5) / cells);
                            // Sigma: one cell.
                            let e = (-(du * du + dv * dv) * cells * cells / 2.0).exp();
                            w[cy * self.cells + cx] = e;
                            total += e;
                        }
                    }
                    for (kk, e) in w[..k].iter().enumerate() {
                        self.phi[kk * n + i] = (e / total) as f32;
                    }
                }
            }
        }
    }

    /// Fits the light to `current`; fills `theta`, `residual`, `gain`; returns the similarity.
    fn fit(&mut self, current: &[f32]) -> f64 {
        let n = self.template.len().min(current.len());
        let m = self.theta.len();
        for j in 0..m {
            let row = &self.pinv[j * n..(j + 1) * n];
            let mut s = 0.0;
            for i in 0..n {
                s += row[i] * (current[i] as f64 - self.template[i] as f64);
            }
            self.theta[j] = s;
        }
        let k = m / 2;
        let mut ssq = 0.0;
        for i in 0..n {
            let mut model = 0.0;
            let mut g = 0.0;
            for j in 0..m {
                model += self.a[j * n + i] * self.theta[j];
            }
            for kk in 0..k {
                g += self.phi[kk * n + i] as f64 * self.theta[kk];
            }
            let r = current[i] as f64 - self.template[i] as f64 - model;
            self.residual[i] = r;
            self.gain[i] = (1.0 + g) as f32;
            ssq += r * r;
        }
        let ridge: f64 = self
            .ridge
            .iter()
            .zip(&self.theta)
            .map(|(l, t)| l * t * t)
            .sum();
        -0.5 * (ssq + ridge)
    }
}

impl IlmSsd {
    /// Adds `(A^T J)^T (A^T A + lambda)^-1 (A^T J)` to `out` (the light absorbs the span of `A`),
    /// with `J` weighted by the gain `1 + g` if `weighted`. In the scratch buffers: an iteration
    /// does not allocate.
    fn add_projection(
        &mut self,
        jac: &[f32],
        dof: usize,
        weighted: bool,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        let n = self.template.len();
        let m = self.theta.len();
        for j in 0..m {
            let col = &self.a[j * n..(j + 1) * n];
            for p in 0..dof {
                let jp = &jac[p * n..(p + 1) * n];
                self.atj[j * MAX_DOF + p] = if weighted {
                    col.iter()
                        .zip(jp)
                        .zip(&self.gain)
                        .map(|((a, b), w)| a * (*b * *w) as f64)
                        .sum()
                } else {
                    col.iter().zip(jp).map(|(a, b)| a * *b as f64).sum()
                };
            }
        }
        for j in 0..m {
            for p in 0..dof {
                let mut s = 0.0;
                for l in 0..m {
                    s += self.inv[(j, l)] * self.atj[l * MAX_DOF + p];
                }
                self.inv_atj[j * MAX_DOF + p] = s;
            }
        }
        for r in 0..dof {
            for c in 0..dof {
                let s: f64 = (0..m)
                    .map(|j| self.atj[j * MAX_DOF + r] * self.inv_atj[j * MAX_DOF + c])
                    .sum();
                out[r * dof + c] += s;
            }
        }
    }
}

impl Am for IlmSsd {
    fn name(&self) -> &'static str {
        "ssd"
    }
    /// The light's cells are blocks of the square grid.
    fn needs_grid(&self) -> bool {
        true
    }
    fn capabilities(&self) -> Capabilities {
        // The light is fitted to each patch: no fixed embedding for nearest neighbours.
        Capabilities::DERIVATIVES_ONLY
    }
    fn set_template(&mut self, template: &[f32]) {
        let n = template.len();
        self.template = template.to_vec();
        self.basis(n);
        let k = self.cells * self.cells;
        let m = 2 * k;
        self.a = vec![0.0; m * n];
        for kk in 0..k {
            for i in 0..n {
                let p = self.phi[kk * n + i] as f64;
                self.a[kk * n + i] = p * template[i] as f64;
                self.a[(k + kk) * n + i] = p;
            }
        }
        let mut ata = DMatrix::<f64>::zeros(m, m);
        for r in 0..m {
            for c in r..m {
                let (x, y) = (&self.a[r * n..(r + 1) * n], &self.a[c * n..(c + 1) * n]);
                let s: f64 = x.iter().zip(y).map(|(p, q)| p * q).sum();
                ata[(r, c)] = s;
                ata[(c, r)] = s;
            }
        }
        // Each column's ridge relative to its own size (a gain's and a bias's differ by the
        // template's scale); a tiny absolute one for empty cells.
        self.ridge = (0..m).map(|d| RIDGE * ata[(d, d)] + 1e-9).collect();
        for d in 0..m {
            ata[(d, d)] += self.ridge[d];
        }
        // Symmetric positive definite with the ridge.
        self.inv = ata
            .cholesky()
            .map(|c| c.inverse())
            .unwrap_or_else(|| DMatrix::zeros(m, m));
        self.pinv = vec![0.0; m * n];
        for j in 0..m {
            for i in 0..n {
                let mut s = 0.0;
                for l in 0..m {
                    s += self.inv[(j, l)] * self.a[l * n + i];
                }
                self.pinv[j * n + i] = s;
            }
        }
        self.atj = vec![0.0; m * MAX_DOF];
        self.inv_atj = vec![0.0; m * MAX_DOF];
        self.theta = vec![0.0; m];
        self.residual = vec![0.0; n];
        self.gain = vec![1.0; n];
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.fit(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let f = self.fit(current);
        match wrt {
            Wrt::Current => {
                for (g, r) in grad.iter_mut().zip(&self.residual) {
                    *g = -*r as f32;
                }
            }
            Wrt::Template => {
                for ((g, r), w) in grad.iter_mut().zip(&self.residual).zip(&self.gain) {
                    *g = *w * *r as f32;
                }
            }
        }
        f
    }
    fn hessian(
        &mut self,
        wrt: Wrt,
        _kind: HessianKind,
        _current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        let n = self.template.len();
        match wrt {
            Wrt::Current => {
                crate::linalg::minus_jtj(jac, dof, out);
                self.add_projection(jac, dof, false, out);
            }
            Wrt::Template => {
                // Gauss-Newton on the weighted Jacobian J_w = diag(1 + g) J, with the same
                // projection: -(J_w^T J_w - (A^T J_w)^T (A^T A + lambda)^-1 (A^T J_w)).
                for r in 0..dof {
                    let jr = &jac[r * n..(r + 1) * n];
                    for c in r..dof {
                        let jc = &jac[c * n..(c + 1) * n];
                        let s: f64 = jr
                            .iter()
                            .zip(jc)
                            .zip(&self.gain)
                            .map(|((a, b), w)| (*a as f64) * (*b as f64) * (*w as f64).powi(2))
                            .sum();
                        out[r * dof + c] = -s;
                        out[c * dof + r] = -s;
                    }
                }
                self.add_projection(jac, dof, true, out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::tests::smooth_patch;
    use crate::rng::Rng;

    fn model(kind: Illumination, template: &[f32]) -> IlmSsd {
        let mut m = IlmSsd::new(kind, 3);
        m.set_template(template);
        m
    }

    #[test]
    fn a_light_in_the_model_costs_nothing() {
        let mut rng = Rng::new(3);
        let res = 30;
        let t = smooth_patch(&mut rng, res);
        // A gain and a bias per cell (pieces), and a smooth light (radial).
        let cell = |i: usize| ((i % res) * 3 / res, (i / res) * 3 / res);
        let pieces: Vec<f32> = (0..res * res)
            .map(|i| {
                let (cx, cy) = cell(i);
                (1.0 + 0.1 * cx as f32 - 0.15 * cy as f32) * t[i] + 10.0 * cx as f32 - 5.0
            })
            .collect();
        let mut m = model(Illumination::Pieces, &t);
        let f = m.similarity(&pieces);
        let plain = -0.5
            * t.iter()
                .zip(&pieces)
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum::<f64>();
        assert!(f > 1e-3 * plain, "pieces: {f} against SSD's {plain}");
        let smooth: Vec<f32> = (0..res * res)
            .map(|i| {
                let (u, v) = ((i % res) as f32 / res as f32, (i / res) as f32 / res as f32);
                (0.8 + 0.4 * u) * t[i] + 30.0 * v - 10.0
            })
            .collect();
        let mut m = model(Illumination::Radial, &t);
        let f = m.similarity(&smooth);
        let plain = -0.5
            * t.iter()
                .zip(&smooth)
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum::<f64>();
        assert!(f > 0.01 * plain, "radial: {f} against SSD's {plain}");
        // The template itself: 0.
        assert!(m.similarity(&t).abs() < 1e-6);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let mut rng = Rng::new(5);
        let res = 12;
        let n = res * res;
        let t = smooth_patch(&mut rng, res);
        let c: Vec<f32> = t
            .iter()
            .map(|v| 0.9 * v + 7.0 + rng.range(-4.0, 4.0) as f32)
            .collect();
        for kind in [Illumination::Pieces, Illumination::Radial] {
            let mut m = model(kind, &t);
            let mut g = vec![0.0f32; n];
            // d f / d I.
            m.gradient(Wrt::Current, &c, &mut g);
            let h = 1e-2f32;
            for i in [0, 7, 40, 77, n - 1] {
                let (mut up, mut down) = (c.clone(), c.clone());
                up[i] += h;
                down[i] -= h;
                let fd = (m.similarity(&up) - m.similarity(&down)) / (2.0 * h as f64);
                assert!(
                    (fd - g[i] as f64).abs() < 1e-2 * (1.0 + fd.abs()),
                    "{kind:?} dI {i}: {fd} {}",
                    g[i]
                );
            }
            // d f / d I*.
            m.gradient(Wrt::Template, &c, &mut g);
            for i in [3, 50, 99] {
                let (mut up, mut down) = (t.clone(), t.clone());
                up[i] += h;
                down[i] -= h;
                let (mut mu, mut md) = (model(kind, &up), model(kind, &down));
                let fd = (mu.similarity(&c) - md.similarity(&c)) / (2.0 * h as f64);
                assert!(
                    (fd - g[i] as f64).abs() < 2e-2 * (1.0 + fd.abs()),
                    "{kind:?} dI* {i}: {fd} {}",
                    g[i]
                );
            }
            // The Hessian wrt the frame along a direction J (one DOF): d2f/ds2 of f(c + s J).
            let jv: Vec<f32> = (0..n).map(|i| ((i * 7) % 11) as f32 - 5.0).collect();
            let mut out = [0.0f64; MAX_DOF * MAX_DOF];
            m.gradient(Wrt::Current, &c, &mut g);
            m.hessian(Wrt::Current, HessianKind::Newton, &c, &jv, 1, &mut out);
            let s = 0.05f32;
            let at = |k: f32| {
                let p: Vec<f32> = c.iter().zip(&jv).map(|(a, b)| a + k * b).collect();
                model(kind, &t).similarity(&p)
            };
            let fd = (at(s) - 2.0 * at(0.0) + at(-s)) / (s as f64 * s as f64);
            assert!(
                (fd - out[0]).abs() < 1e-3 * fd.abs(),
                "{kind:?} H: {fd} {}",
                out[0]
            );
        }
    }
}
