//! Appearance models: the similarity `f(I*, I)` between the template intensities `I*` and the
//! intensities `I` sampled from the current frame at the warped grid (higher is better).
//!
//! An AM knows nothing about geometry. Given whole patches it returns the similarity, its
//! gradient with respect to the current or the template pixels, and the Hessian terms the search
//! methods need, already projected on a pixel Jacobian `J` (`N x S`, row-major:
//! `J[i * S + k] = dI_i / dp_k`) so that its per-pixel loops stay inside the AM:
//! `J^T (d2f/dI2) J`. Models with internal state (joint histograms, intensity maps: SCV, MI, ...)
//! update it only in [`Am::update_model`], never as a side effect of computing a similarity.
//!
//! Each model is one file and one line in [`REGISTRY`].

mod correlation;
mod ncc;
mod ssd;
mod zncc;

use crate::linalg::MAX_DOF;
use crate::registry::{self, Entry};
use serde::{Deserialize, Serialize};

/// Which pixels a derivative is taken with respect to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrt {
    /// The current frame's pixels `I` (forward methods, ESM).
    Current,
    /// The template's pixels `I*` (inverse methods).
    Template,
}

/// Which second derivative a search method uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HessianKind {
    /// The AM's own default (Gauss-Newton for the L2-type models, after convergence for the
    /// robust ones).
    #[default]
    Default,
    /// Gauss-Newton: the first-order approximation of the AM's least-squares form.
    GaussNewton,
    /// The exact second derivative of `f` with respect to the pixels.
    Newton,
    /// The "Hessian after convergence": the exact second derivative evaluated where the current
    /// patch equals the template; constant over a sequence.
    AfterConvergence,
}

/// Optional capabilities that only some AMs have; a search method that needs one rejects AMs
/// without it when the tracker is built.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Capabilities {
    /// Has analytic derivatives (the gradient-based search methods need them).
    pub derivatives: bool,
    /// Can serve as a distance between patches (nearest-neighbour search).
    pub distance: bool,
}

/// An appearance model.
pub trait Am: Send + Sync + std::fmt::Debug {
    /// The registry name.
    fn name(&self) -> &'static str;
    /// What the model can do.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            derivatives: true,
            distance: true,
        }
    }
    /// The Hessian a search method gets when it asks for [`HessianKind::Default`].
    fn default_hessian(&self) -> HessianKind {
        HessianKind::GaussNewton
    }
    /// Sets the template `I*` (and resets any internal model).
    fn set_template(&mut self, template: &[f32]);
    /// The template.
    fn template(&self) -> &[f32];
    /// The similarity `f(I*, I)`.
    fn similarity(&mut self, current: &[f32]) -> f64;
    /// The similarity and its gradient with respect to the `wrt` pixels, written to `grad`.
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64;
    /// `J^T (d2f / dI2) J` with respect to the `wrt` pixels (`J` is `N x dof`), written row-major
    /// into the first `dof * dof` entries of `out`.
    fn hessian(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    );
    /// Updates an internal model (e.g. the intensity map of SCV) once a frame has converged.
    fn update_model(&mut self, _current: &[f32]) {}
}

/// Builds an AM.
pub type AmBuilder = fn() -> Box<dyn Am>;

/// Every appearance model.
pub const REGISTRY: &[Entry<AmBuilder>] = &[ssd::ENTRY, zncc::ENTRY, ncc::ENTRY];

/// The AM called `name` (or one of its aliases).
pub fn build(name: &str) -> crate::Result<Box<dyn Am>> {
    Ok((registry::lookup(REGISTRY, "appearance model", name)?.build)())
}

/// `out = -J^T J` (row-major `dof x dof`), the Gauss-Newton Hessian of SSD.
pub(crate) fn minus_jtj(jac: &[f32], dof: usize, out: &mut [f64; MAX_DOF * MAX_DOF]) {
    let mut acc = [0.0f64; MAX_DOF * MAX_DOF];
    accumulate_jtj(jac, dof, &mut acc);
    for i in 0..dof {
        for j in 0..dof {
            out[i * dof + j] = -acc[i * MAX_DOF + j];
        }
    }
}

/// Adds `J^T J` (upper triangle, then mirrored) into `acc` (stride [`MAX_DOF`]); accumulates in
/// f32 per block of pixels and in f64 across blocks.
pub fn accumulate_jtj(jac: &[f32], dof: usize, acc: &mut [f64; MAX_DOF * MAX_DOF]) {
    macro_rules! body {
        ($s:expr) => {{
            const S: usize = $s;
            for block in jac.chunks(S * 256) {
                let mut part = [[0.0f32; S]; S];
                for row in block.chunks_exact(S) {
                    for i in 0..S {
                        let ri = row[i];
                        for j in i..S {
                            part[i][j] += ri * row[j];
                        }
                    }
                }
                for i in 0..S {
                    for j in i..S {
                        acc[i * MAX_DOF + j] += part[i][j] as f64;
                    }
                }
            }
        }};
    }
    match dof {
        2 => body!(2),
        3 => body!(3),
        4 => body!(4),
        6 => body!(6),
        8 => body!(8),
        _ => {
            for row in jac.chunks_exact(dof) {
                for i in 0..dof {
                    for j in i..dof {
                        acc[i * MAX_DOF + j] += (row[i] * row[j]) as f64;
                    }
                }
            }
        }
    }
    for i in 0..dof {
        for j in 0..i {
            acc[i * MAX_DOF + j] = acc[j * MAX_DOF + i];
        }
    }
}

/// `out[k] = sum_i J[i * dof + k] * v[i]`.
pub fn jt_times(jac: &[f32], v: &[f32], dof: usize, out: &mut [f64; MAX_DOF]) {
    macro_rules! body {
        ($s:expr) => {{
            const S: usize = $s;
            for (jb, vb) in jac.chunks(S * 256).zip(v.chunks(256)) {
                let mut part = [0.0f32; S];
                for (row, &e) in jb.chunks_exact(S).zip(vb) {
                    for k in 0..S {
                        part[k] += row[k] * e;
                    }
                }
                for k in 0..S {
                    out[k] += part[k] as f64;
                }
            }
        }};
    }
    out.fill(0.0);
    match dof {
        2 => body!(2),
        3 => body!(3),
        4 => body!(4),
        6 => body!(6),
        8 => body!(8),
        _ => {
            for (row, &e) in jac.chunks_exact(dof).zip(v) {
                for k in 0..dof {
                    out[k] += (row[k] * e) as f64;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
