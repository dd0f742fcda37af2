//! A learned appearance subspace (as IVT, Ross et al. 2008, and MTF's PCA model): the target's
//! appearance is a mean patch `m` plus the span of an orthonormal basis `U` (`k` patches), learnt
//! online from the patches tracked so far, and a patch's similarity is minus half its squared
//! distance from that affine subspace:
//!
//! `f = -1/2 |P (I - m)|^2`, `P = Id - U U^T` (a projection: symmetric, `P P = P`).
//!
//! Before anything is learnt (`k = 0`, `m = I*`) it is SSD. Its derivatives are exact for both
//! arguments (the template's being the mean's): `df/dI = -P (I - m)`, `df/dm = P (I - m)`, and
//! `d2f/dI2 = d2f/dm2 = -P` for every kind of Hessian, so `J^T (d2f/dI2) J = -J^T J +
//! sum_j (J^T u_j)(J^T u_j)^T`, which the forward methods also make from the moments' `J^T J`
//! ([`Am::hessian_from_projections`]).
//!
//! Learning ([`Am::learn`], once for each frame the tracker accepts, at the patch where it
//! ended) merges the patch into the weighted scatter of the patches seen, every older weight
//! multiplied by the forgetting factor `phi` first. With `w` the weight of the patches before
//! (the template counts 1) and `x` the new one, the merged mean and scatter are
//! `m' = (w m + x) / (w + 1)` and `S' = phi S + w/(w + 1) (x - m)(x - m)^T` (the scatter of two
//! weighted sets about their joint mean). With `S = U diag(s^2) U^T`, `b = sqrt(phi w/(phi w + 1))
//! (x - m)` (`w` already decayed), `c = U^T b` and `q = b - U c`:
//! `S' = [U q/|q|] R R^T [U q/|q|]^T` with the small upper-triangular
//! `R = [[sqrt(phi) diag(s), c], [0, |q|]]`; the eigenvectors `V` and eigenvalues of `R R^T` give
//! the new basis `[U q/|q|] V` and its `s^2`, of which the `components` largest are kept. So the
//! patches are never stored: a frame costs `O(N k^2)`.
//!
//! What is learnt is kept orthogonal to the template's motion directions (its pixel Jacobian
//! at the identity, [`Am::set_motion`]): `x - m` loses its part along them before it moves the
//! mean and enters the scatter. Without that, a patch tracked a fraction of a pixel off (on
//! frames that differ by nothing else) teaches the subspace the motion itself, and the
//! similarity stops telling the target from its neighbourhood: the generic recovery test, 20
//! perturbations of one frame each learnt, measured FCLK on the affine warp converging in 9 of
//! 20 and FALK in 13. Orthogonal to the motion, the Hessian near the optimum is SSD's.

use super::{Am, AmBuilder, Capabilities, HessianKind, Wrt};
use crate::linalg::{MAX_DOF, dot, jt_times, minus_jtj};
use crate::params::{MethodParams, ParamDef};
use crate::registry::Entry;
use nalgebra::SMatrix;

/// The most basis patches a model keeps.
pub const MAX_COMPONENTS: usize = 16;

/// The small matrix of an update: the basis and one new direction.
type Small = SMatrix<f64, { MAX_COMPONENTS + 1 }, { MAX_COMPONENTS + 1 }>;

const PARAMS: [ParamDef; 2] = [
    ParamDef::int(
        "components",
        "patches in the learnt basis of appearance (the subspace's dimension)",
        1.0,
        MAX_COMPONENTS as f64,
        8.0,
    ),
    ParamDef::float(
        "forgetting",
        "weight of the older patches each time one is learnt (1 = remember all alike)",
        0.5,
        1.0,
        0.95,
    ),
];

pub const ENTRY: Entry<AmBuilder> = Entry {
    name: "pca",
    aliases: &["ivt"],
    description: "distance from a learnt appearance subspace (mean + incremental PCA basis, with forgetting)",
    build: AmBuilder {
        params: &PARAMS,
        build: |p| Box::new(Pca::from_params(p)),
    },
};

/// See the module's documentation.
#[derive(Debug, Clone)]
pub struct Pca {
    components: usize,
    forgetting: f64,
    /// The mean patch `m`.
    mean: Vec<f32>,
    /// The basis, `k` patches one after the other (orthonormal).
    basis: Vec<f32>,
    /// How many basis patches there are (`k`).
    k: usize,
    /// Their singular values (the scatter's square roots along them).
    sigma: [f64; MAX_COMPONENTS],
    /// The weight of the patches learnt so far (after forgetting).
    weight: f64,
    /// The residual `P (I - m)` of the last patch scored.
    residual: Vec<f32>,
    /// Scratch of a learning step: the new direction, and the next basis.
    direction: Vec<f32>,
    next: Vec<f32>,
    /// The template's motion directions ([`Am::set_motion`]), orthonormal, one after the other.
    motion: Vec<f32>,
}

impl Pca {
    fn from_params(p: &MethodParams) -> Self {
        Pca::new(p.get(&PARAMS[0]) as usize, p.get(&PARAMS[1]))
    }

    /// A model keeping `components` basis patches with forgetting factor `forgetting`.
    pub fn new(components: usize, forgetting: f64) -> Self {
        Pca {
            components: components.clamp(1, MAX_COMPONENTS),
            forgetting: forgetting.clamp(0.0, 1.0),
            mean: Vec::new(),
            basis: Vec::new(),
            k: 0,
            sigma: [0.0; MAX_COMPONENTS],
            weight: 1.0,
            residual: Vec::new(),
            direction: Vec::new(),
            next: Vec::new(),
            motion: Vec::new(),
        }
    }

    /// Removes from `v` its components along the motion directions.
    fn without_motion(motion: &[f32], v: &mut [f32]) {
        let n = v.len();
        if n == 0 {
            return;
        }
        for m in motion.chunks_exact(n) {
            let d = dot(m, v) as f32;
            for (x, &m) in v.iter_mut().zip(m) {
                *x = (-d).mul_add(m, *x);
            }
        }
    }

    /// The `j`-th basis patch.
    fn u(&self, j: usize) -> &[f32] {
        let n = self.mean.len();
        &self.basis[j * n..(j + 1) * n]
    }

    /// The basis learnt so far (`k` patches of the template's length, one after the other) and
    /// its singular values.
    pub fn basis(&self) -> (&[f32], &[f64]) {
        let n = self.mean.len();
        (&self.basis[..self.k * n], &self.sigma[..self.k])
    }

    /// `P (I - m)` into `residual`; returns `f`.
    fn project(&mut self, current: &[f32]) -> f64 {
        let n = self.mean.len().min(current.len());
        let r = &mut self.residual[..n];
        for ((r, &c), &m) in r.iter_mut().zip(current).zip(&self.mean) {
            *r = c - m;
        }
        for j in 0..self.k {
            let u = &self.basis[j * self.mean.len()..][..n];
            let c = dot(u, r) as f32;
            for (r, &u) in r.iter_mut().zip(u) {
                *r = (-c).mul_add(u, *r);
            }
        }
        -0.5 * dot(r, r)
    }

    /// Adds `b` (already scaled) to the scatter `U diag(s^2) U^T` decayed by `phi`: the new
    /// basis and singular values (see the module's documentation).
    fn merge(&mut self, phi: f64) {
        let (n, k) = (self.mean.len(), self.k);
        // c = U^T b, q = b - U c (twice: once more against what rounding left).
        let mut c = [0.0f64; MAX_COMPONENTS];
        for _ in 0..2 {
            for (j, cj) in c.iter_mut().enumerate().take(k) {
                let u = &self.basis[j * n..(j + 1) * n];
                let d = dot(u, &self.direction);
                *cj += d;
                for (q, &u) in self.direction.iter_mut().zip(u) {
                    *q = (-d as f32).mul_add(u, *q);
                }
            }
        }
        let qn = dot(&self.direction, &self.direction).sqrt();
        let scale = self.sigma[..k].iter().fold(qn, |m, &s| m.max(s));
        // A direction the basis already spans (to rounding) adds nothing new.
        let fresh = qn > 1e-6 * scale && qn > 0.0;
        let size = if fresh { k + 1 } else { k };
        if size == 0 {
            return;
        }
        let mut r = Small::zeros();
        for j in 0..k {
            r[(j, j)] = phi.sqrt() * self.sigma[j];
            r[(j, k)] = c[j];
        }
        if fresh {
            r[(k, k)] = qn;
            let inv = (1.0 / qn) as f32;
            self.direction.iter_mut().for_each(|q| *q *= inv);
        }
        let eig = (r * r.transpose()).symmetric_eigen();
        let mut order = [0usize; MAX_COMPONENTS + 1];
        for (i, o) in order.iter_mut().enumerate() {
            *o = i;
        }
        order[..size].sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let top = eig.eigenvalues[order[0]].max(0.0);
        let mut kept = 0;
        for &i in order[..size].iter().take(self.components) {
            let l = eig.eigenvalues[i];
            // (NaN too.)
            if l.is_nan() || l <= 1e-12 * top {
                break;
            }
            // The new basis patch: [U q] v.
            let out = &mut self.next[kept * n..(kept + 1) * n];
            out.fill(0.0);
            for j in 0..size {
                let v = eig.eigenvectors[(j, i)] as f32;
                let src = if j < k {
                    &self.basis[j * n..(j + 1) * n]
                } else {
                    &self.direction[..]
                };
                for (o, &s) in out.iter_mut().zip(src) {
                    *o = v.mul_add(s, *o);
                }
            }
            self.sigma[kept] = l.sqrt();
            kept += 1;
        }
        std::mem::swap(&mut self.basis, &mut self.next);
        self.k = kept;
        self.orthonormalise();
    }

    /// Gram-Schmidt on the basis (rounding in f32 would let it drift from orthonormal over a
    /// long sequence); a patch that loses its length is dropped with those after it.
    fn orthonormalise(&mut self) {
        let n = self.mean.len();
        for j in 0..self.k {
            let (done, rest) = self.basis.split_at_mut(j * n);
            let u = &mut rest[..n];
            Self::without_motion(&self.motion, u);
            for i in 0..j {
                let prev = &done[i * n..(i + 1) * n];
                let d = dot(prev, u) as f32;
                for (x, &p) in u.iter_mut().zip(prev) {
                    *x = (-d).mul_add(p, *x);
                }
            }
            let len = dot(u, u).sqrt();
            if len.is_nan() || len <= 0.5 {
                self.k = j;
                return;
            }
            let inv = (1.0 / len) as f32;
            u.iter_mut().for_each(|x| *x *= inv);
        }
    }

    #[cfg(test)]
    pub(crate) fn set_mean(&mut self, mean: &[f32]) {
        self.mean.copy_from_slice(mean);
    }
}

impl Am for Pca {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    /// No embedding: the distance is from a subspace that changes as it learns, which an index
    /// built once (NN's) would not follow.
    fn capabilities(&self) -> Capabilities {
        Capabilities::DERIVATIVES_ONLY
    }
    fn set_template(&mut self, template: &[f32]) {
        let n = template.len();
        self.mean.clear();
        self.mean.extend_from_slice(template);
        self.basis.clear();
        self.basis.resize(n * MAX_COMPONENTS, 0.0);
        self.next.clear();
        self.next.resize(n * MAX_COMPONENTS, 0.0);
        self.residual.clear();
        self.residual.resize(n, 0.0);
        self.direction.clear();
        self.direction.resize(n, 0.0);
        self.k = 0;
        self.sigma = [0.0; MAX_COMPONENTS];
        self.weight = 1.0;
        self.motion.clear();
    }
    fn set_motion(&mut self, jac: &[f32], dof: usize) {
        let n = self.mean.len();
        self.motion.clear();
        if n == 0 || jac.len() < n * dof {
            return;
        }
        // Orthonormal (Gram-Schmidt), a direction the others span left out.
        for k in 0..dof {
            let mut v = jac[k * n..(k + 1) * n].to_vec();
            let before = dot(&v, &v).sqrt();
            Self::without_motion(&self.motion, &mut v);
            Self::without_motion(&self.motion, &mut v);
            let len = dot(&v, &v).sqrt();
            if len > 1e-3 * before && len > 0.0 {
                let inv = (1.0 / len) as f32;
                self.motion.extend(v.iter().map(|x| x * inv));
            }
        }
    }
    fn template(&self) -> &[f32] {
        &self.mean
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        self.project(current)
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let f = self.project(current);
        let sign = match wrt {
            Wrt::Current => -1.0,
            Wrt::Template => 1.0,
        };
        for (g, &r) in grad.iter_mut().zip(&self.residual) {
            *g = sign * r;
        }
        f
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
        // -P for both arguments and every kind.
        minus_jtj(jac, dof, out);
        let mut rows = [[0.0; MAX_DOF]; MAX_COMPONENTS];
        for (j, row) in rows.iter_mut().enumerate().take(self.k) {
            jt_times(jac, self.u(j), dof, row);
        }
        add_outer_products(&rows[..self.k], dof, out);
    }
    fn hessian_from_jtj(&self) -> bool {
        true
    }
    fn hessian_from_projections(
        &mut self,
        _kind: HessianKind,
        _current: &[f32],
        jtj: &[f64; MAX_DOF * MAX_DOF],
        project: super::Projections<'_>,
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) -> bool {
        for i in 0..dof {
            for l in 0..dof {
                out[i * dof + l] = -jtj[i * MAX_DOF + l];
            }
        }
        let n = self.mean.len();
        let mut us: [&[f32]; MAX_COMPONENTS] = [&[]; MAX_COMPONENTS];
        for (j, u) in us.iter_mut().enumerate().take(self.k) {
            *u = &self.basis[j * n..(j + 1) * n];
        }
        let mut rows = [[0.0; MAX_DOF]; MAX_COMPONENTS];
        project(&us[..self.k], &mut rows[..self.k]);
        add_outer_products(&rows[..self.k], dof, out);
        true
    }
    fn learns(&self) -> bool {
        true
    }
    fn learn(&mut self, patch: &[f32]) {
        let n = self.mean.len();
        if patch.len() != n || n == 0 || patch.iter().any(|v| !v.is_finite()) {
            return;
        }
        let phi = self.forgetting;
        let w = phi * self.weight;
        // The patch's difference from the mean, less its part along the motion: what the
        // model learns (the mean moves by it too).
        for ((d, &x), &m) in self.direction.iter_mut().zip(patch).zip(&self.mean) {
            *d = x - m;
        }
        Self::without_motion(&self.motion, &mut self.direction);
        let b = (1.0 / (w + 1.0)) as f32;
        for (m, &d) in self.mean.iter_mut().zip(&self.direction) {
            *m = b.mul_add(d, *m);
        }
        let s = (w / (w + 1.0)).sqrt() as f32;
        self.direction.iter_mut().for_each(|d| *d *= s);
        self.merge(phi);
        self.weight = w + 1.0;
    }
}

/// `sum_j a_j a_j^T` (each `a_j = J^T u_j` of a basis patch) added to `out` (`dof x dof`).
fn add_outer_products(rows: &[[f64; MAX_DOF]], dof: usize, out: &mut [f64; MAX_DOF * MAX_DOF]) {
    for a in rows {
        for i in 0..dof {
            for l in 0..dof {
                out[i * dof + l] += a[i] * a[l];
            }
        }
    }
}

#[cfg(test)]
mod tests;
