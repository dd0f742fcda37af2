//! The normalised-correlation core shared by ZNCC and NCC.
//!
//! With `P` the centring projector (ZNCC) or the identity (NCC), unit vectors `a = P I* / |P I*|`
//! and `c = P I / |P I|`, and `rho = a . c`, the similarity is `f = beta rho + const` with
//! `beta = N` for ZNCC (`f = -1/2 |z* - z|^2` of the z-scores) and `beta = 1` for NCC. With `x`
//! the variable patch (norm `n`, unit `v`) and `o` the other unit vector:
//! - gradient `df/dx = beta / n (o - rho v)`;
//! - exact Hessian `beta / n^2 (-o v^T - v o^T - rho P + 3 rho v v^T)`;
//! - Gauss-Newton Hessian of `beta (1 - |o - v|^2 / 2)`: `-beta / n^2 (P - v v^T)`;
//! - after convergence (`x = I*`): `beta / n^2 (a a^T - P)`, equal to both above there.

use super::{HessianKind, Wrt};
use crate::linalg::{MAX_DOF, SquareBuf, clear_square};
use crate::linalg::{accumulate_jtj, jt_times_many, sum};

#[derive(Debug, Clone, Default)]
pub(crate) struct Correlation {
    centered: bool,
    template: Vec<f32>,
    t_unit: Vec<f32>,
    t_norm: f64,
    /// `P I*` in double precision, for an accurate `rho`.
    t_centered: Vec<f64>,
    c_unit: Vec<f32>,
    /// The patch [`Correlation::gradient`] last saw (its address and length) with its
    /// `(|P I|, rho)` (`c_unit` is its unit vector), for the [`Correlation::hessian`] that
    /// follows on the same patch; cleared by anything else that reads a patch.
    seen: Option<(usize, usize, f64, f64)>,
    /// A patch of ones: `J^T 1` (the sums of `J`'s columns) with the other products in one pass ([`jt_times_many`]).
    ones: Vec<f32>,
    /// `J^T J` (stride [`MAX_DOF`]), the Hessian's scratch.
    jtj: SquareBuf,
}

/// Writes the unit vector of `P x` into `out`; returns `|P x|` (0 for a flat patch, with `out`
/// zero).
fn unit(x: &[f32], centered: bool, out: &mut Vec<f32>) -> f64 {
    out.clear();
    let mean = mean(x, centered);
    let m = mean as f32;
    out.extend(x.iter().map(|&v| v - m));
    // The norm in double precision: NCC's gradient is tiny near a match.
    let mut lanes = [0.0f64; 8];
    let chunks = x.chunks_exact(8);
    let tail: f64 = chunks
        .remainder()
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum();
    for c in chunks {
        for l in 0..8 {
            let d = c[l] as f64 - mean;
            lanes[l] += d * d;
        }
    }
    let norm = (lanes.iter().sum::<f64>() + tail).sqrt();
    if norm > 1e-9 {
        let inv = (1.0 / norm) as f32;
        out.iter_mut().for_each(|v| *v *= inv);
        norm
    } else {
        out.iter_mut().for_each(|v| *v = 0.0);
        0.0
    }
}

/// The mean of a patch (0 when not centring).
fn mean(x: &[f32], centered: bool) -> f64 {
    if centered {
        sum(x) / x.len().max(1) as f64
    } else {
        0.0
    }
}

/// `sum_i a_i (b_i - mb)` in double precision, four lanes at a time.
fn dot_f64(a: &[f64], b: &[f32], mb: f64) -> f64 {
    let mut lanes = [0.0f64; 8];
    let (ea, eb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ea
        .remainder()
        .iter()
        .zip(eb.remainder())
        .map(|(&x, &y)| x * (y as f64 - mb))
        .sum();
    for (x, y) in ea.zip(eb) {
        for l in 0..8 {
            lanes[l] += x[l] * (y[l] as f64 - mb);
        }
    }
    lanes.iter().sum::<f64>() + tail
}

impl Correlation {
    pub fn new(centered: bool) -> Self {
        Correlation {
            centered,
            ..Default::default()
        }
    }

    fn beta(&self) -> f64 {
        if self.centered {
            self.template.len() as f64
        } else {
            1.0
        }
    }

    fn value(&self, rho: f64) -> f64 {
        let b = self.beta();
        if self.centered { b * rho - b } else { b * rho }
    }

    pub fn set_template(&mut self, template: &[f32]) {
        self.seen = None;
        self.ones.clear();
        self.ones.resize(template.len(), 1.0);
        self.template.clear();
        self.template.extend_from_slice(template);
        self.t_norm = unit(template, self.centered, &mut self.t_unit);
        let mean = mean(template, self.centered);
        self.t_centered.clear();
        self.t_centered
            .extend(template.iter().map(|&v| v as f64 - mean));
    }

    pub fn template(&self) -> &[f32] {
        &self.template
    }

    /// `sqrt(beta)` times the unit vector of `P x`: `|e(a) - e(b)|^2 = 2 beta (1 - rho)`.
    pub fn embed(&self, patch: &[f32], out: &mut [f32]) {
        let m = mean(patch, self.centered);
        let norm = patch
            .iter()
            .map(|&v| (v as f64 - m).powi(2))
            .sum::<f64>()
            .sqrt();
        let beta = if self.centered {
            patch.len() as f64
        } else {
            1.0
        };
        let s = if norm > 1e-9 {
            (beta.sqrt() / norm) as f32
        } else {
            0.0
        };
        let m = m as f32;
        for (o, &v) in out.iter_mut().zip(patch) {
            *o = s * (v - m);
        }
    }

    /// Normalises the current patch into the scratch buffer; returns `(|P I|, rho)`.
    fn current(&mut self, current: &[f32]) -> (f64, f64) {
        let n = unit(current, self.centered, &mut self.c_unit);
        let mc = mean(current, self.centered);
        let num = dot_f64(&self.t_centered, current, mc);
        let rho = if n > 0.0 && self.t_norm > 0.0 {
            num / (n * self.t_norm)
        } else {
            0.0
        };
        (n, rho)
    }

    pub fn similarity(&mut self, current: &[f32]) -> f64 {
        self.seen = None;
        let (_, rho) = self.current(current);
        self.value(rho)
    }

    pub fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let (nc, rho) = self.current(current);
        self.seen = Some((current.as_ptr() as usize, current.len(), nc, rho));
        let beta = self.beta();
        let (n, var, other) = match wrt {
            Wrt::Current => (nc, &self.c_unit, &self.t_unit),
            Wrt::Template => (self.t_norm, &self.t_unit, &self.c_unit),
        };
        if n > 0.0 {
            let s = (beta / n) as f32;
            let r = rho as f32;
            for ((g, &o), &v) in grad.iter_mut().zip(other).zip(var) {
                *g = s * (o - r * v);
            }
        } else {
            grad.iter_mut().for_each(|g| *g = 0.0);
        }
        self.value(rho)
    }

    pub fn hessian(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        let centered = self.centered;
        self.hessian_with(
            wrt,
            kind,
            current,
            dof,
            out,
            |ones, other, var, jtj, uvw| {
                accumulate_jtj(jac, dof, jtj);
                // u = J^T other, v = J^T var and, centred, w = J^T 1 (the sums of J's columns), in
                // one pass over J.
                if centered {
                    jt_times_many(jac, [other, var, ones], dof, uvw);
                } else {
                    let mut uv = [[0.0; MAX_DOF]; 2];
                    jt_times_many(jac, [other, var], dof, &mut uv);
                    uvw[..2].copy_from_slice(&uv);
                }
            },
        );
    }

    /// [`Correlation::hessian`] with respect to the current pixels from `J^T J` and the products
    /// `J^T x` that `project` makes (see [`crate::am::Am::hessian_from_projections`]): only
    /// those the Hessian of `kind` uses are asked for (`J^T` of the other patch's unit vector
    /// only for Newton's).
    pub fn hessian_from_projections(
        &mut self,
        kind: HessianKind,
        current: &[f32],
        jtj: &[f64; MAX_DOF * MAX_DOF],
        project: super::Projections<'_>,
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        let newton = matches!(kind, HessianKind::Newton | HessianKind::AfterConvergence);
        let centered = self.centered;
        self.hessian_with(
            Wrt::Current,
            kind,
            current,
            dof,
            out,
            |ones, other, var, into, uvw| {
                let used = (dof - 1) * MAX_DOF + dof;
                into[..used].copy_from_slice(&jtj[..used]);
                let mut got = [[0.0; MAX_DOF]; 3];
                match (newton, centered) {
                    (true, true) => project(&[other, var, ones], &mut got),
                    (true, false) => project(&[other, var], &mut got[..2]),
                    (false, true) => project(&[var, ones], &mut got[1..]),
                    (false, false) => project(&[var], &mut got[1..2]),
                }
                *uvw = got;
            },
        );
    }

    /// The Hessian of `kind` from the patch's statistics and what `products` writes: `J^T J`
    /// (stride [`MAX_DOF`]) and `J^T other`, `J^T var`, `J^T 1`, given the ones, the other
    /// patch's unit vector and the variable patch's.
    fn hessian_with(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
        products: impl FnOnce(
            &[f32],
            &[f32],
            &[f32],
            &mut [f64; MAX_DOF * MAX_DOF],
            &mut [[f64; MAX_DOF]; 3],
        ),
    ) {
        let beta = self.beta();
        let npx = self.template.len() as f64;
        let after = kind == HessianKind::AfterConvergence;
        // The gradient just computed the patch's statistics (the trait's contract: the Hessian
        // follows the gradient on the same patch); anything else computes them.
        let seen = self.seen.take();
        let (nc, rho) = match seen {
            _ if after => (self.t_norm, 1.0),
            Some((at, len, nc, rho)) if at == current.as_ptr() as usize && len == current.len() => {
                (nc, rho)
            }
            _ => self.current(current),
        };
        let (n, var, other): (f64, &[f32], &[f32]) = match (after, wrt) {
            (true, _) => (self.t_norm, &self.t_unit, &self.t_unit),
            (false, Wrt::Current) => (nc, &self.c_unit, &self.t_unit),
            (false, Wrt::Template) => (self.t_norm, &self.t_unit, &self.c_unit),
        };
        out[..dof * dof].fill(0.0);
        if n <= 0.0 || dof == 0 {
            return;
        }
        let jtj = &mut self.jtj;
        clear_square(jtj, dof);
        let mut uvw = [[0.0; MAX_DOF]; 3];
        products(&self.ones, other, var, jtj, &mut uvw);
        let [u, v, w] = uvw;
        let s = beta / (n * n);
        let newton = matches!(kind, HessianKind::Newton | HessianKind::AfterConvergence);
        for i in 0..dof {
            for j in 0..dof {
                let mut pj = jtj[i * MAX_DOF + j];
                if self.centered {
                    pj -= w[i] * w[j] / npx;
                }
                out[i * dof + j] = if newton {
                    s * (-u[i] * v[j] - v[i] * u[j] - rho * pj + 3.0 * rho * v[i] * v[j])
                } else {
                    -s * (pj - v[i] * v[j])
                };
            }
        }
    }
}
