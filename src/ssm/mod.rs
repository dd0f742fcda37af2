//! State space models: the warp `w(x, p)` and its parameters.
//!
//! An SSM knows nothing about pixels. Its warp acts in the tracker's *normalised frame* (see
//! [`crate::geometry::Normaliser`]): a similarity of the image that puts the initial quad's
//! centroid at the origin with unit size. Every SSM here is a subgroup of the projective group,
//! so each warp also has a 3x3 [`Ssm::matrix`], but the non-rigid ones ([`displacement`]:
//! `spline` and `tps`, a grid of control points), which are not projective
//! ([`Ssm::projective`]); the identity warp has all parameters zero.
//!
//! Each model is one file and one line in [`REGISTRY`].

mod affine;
mod ast;
mod corner;
pub mod displacement;
mod homography;
mod isometry;
mod ist;
mod similitude;
mod sl3;
mod spline;
mod tps;
mod translation;

pub use corner::CornerHomography;
pub use homography::Homography;
pub use sl3::Sl3;

use crate::geometry::{Point, Quad, apply_homography};
use crate::linalg::MAX_DOF;
use crate::registry::{self, Entry};
use crate::rng::Rng;
use nalgebra::Matrix3;

/// Warp parameters: the first [`Ssm::dof`] entries are used, the rest are zero.
pub type Params = [f64; MAX_DOF];

/// Parameters from their first values (the rest zero).
pub fn params(values: &[f64]) -> Params {
    let mut p = [0.0; MAX_DOF];
    p[..values.len()].copy_from_slice(values);
    p
}

/// A state space model. Object-safe and called once per patch: the per-point loops inside each
/// implementation are concrete.
pub trait Ssm: Send + Sync + std::fmt::Debug {
    /// The registry name.
    fn name(&self) -> &'static str;
    /// Degrees of freedom.
    fn dof(&self) -> usize;
    /// The parameters' names, as the module's documentation writes them (`dof` of them).
    fn param_names(&self) -> &'static [&'static str];
    /// The identity warp.
    fn identity(&self) -> Params {
        [0.0; MAX_DOF]
    }
    /// Whether the warp is its [`Ssm::matrix`] (every SSM but the non-rigid ones,
    /// [`displacement`]: theirs is `x + sum_k phi_k(x) (p_2k, p_2k+1)`, linear in `p`, and
    /// their matrix only the homography through the moved corners).
    fn projective(&self) -> bool {
        true
    }
    /// The template's quad in the normalised frame, for a model laid on it (the non-rigid
    /// ones' control points); the others ignore it.
    fn set_base(&mut self, _corners: &[Point; 4]) {}
    /// For a non-rigid model ([`Ssm::projective`] false): the gradients of its basis functions
    /// `phi_k` at the points, `out[2k N + i] = d phi_k / dx`, `out[(2k + 1) N + i] = d phi_k /
    /// dy` (`dof / 2` functions); `false` for the others, `out` untouched.
    fn basis_gradients(&self, _xs: &[f32], _ys: &[f32], _out: &mut [f32]) -> bool {
        false
    }
    /// For a non-rigid model: the matrix `R` (`dof / 2` square, row-major) of its smoothness
    /// prior, `d^T R d` the bending of the field's component `d` (the control points'
    /// displacements along one axis), zero for an affine field; `None` for the others.
    fn smoothness(&self) -> Option<&[f64]> {
        None
    }
    /// The weight of [`Ssm::smoothness`]'s prior when the tracker leaves it to the model
    /// (`smoothness = -1`).
    fn default_smoothness(&self) -> f64 {
        0.0
    }
    /// The warp as a 3x3 homogeneous matrix (for a non-rigid model, the homography through
    /// the moved corners).
    fn matrix(&self, p: &Params) -> Matrix3<f64>;
    /// The parameters of a matrix of this model's group (defined up to scale). `None` when the
    /// matrix is degenerate. For a matrix outside the group the result is unspecified: use
    /// [`Ssm::fit`] to project a general warp onto the model.
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params>;
    /// Jacobian of the warped points with respect to the parameters at `p`, stored by parameter
    /// (structure of arrays, so that the per-pixel loops vectorise): with `N` points,
    /// `out[2k N + i] = d w_x(x_i, p) / d p_k` and `out[(2k + 1) N + i] = d w_y(x_i, p) / d p_k`
    /// (see [`put`]).
    fn jacobian(&self, p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]);
    /// The pixel Jacobian at the identity, `jac[k N + i] = gx[i] dw_x/dp_k + gy[i] dw_y/dp_k`
    /// for the points `xs`, `ys`, made from the points without reading a stored `dw/dp` (the
    /// compositional methods project on it every iteration); bit for bit the projection on
    /// [`Ssm::jacobian`]'s rows at the identity (rows that are zero left out). `false` if the
    /// model has no such form, and `jac` is untouched.
    fn project_at_identity(
        &self,
        _gx: &[f32],
        _gy: &[f32],
        _xs: &[f32],
        _ys: &[f32],
        _jac: &mut [f32],
    ) -> bool {
        false
    }
    /// Least-squares parameters `p` minimising `sum_k |w(src_k, p) - dst_k|^2` (exact for 8 DOF).
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params>;

    /// The composition `w(w(x, q), p)`: `p` after `q`.
    fn compose(&self, p: &Params, q: &Params) -> Option<Params> {
        self.params_from_matrix(&(self.matrix(p) * self.matrix(q)))
    }
    /// The warp `p` followed by the homography `m` (of the normalised frame): for the
    /// projective SSMs the composition of their matrices; for a non-rigid one the projection
    /// of that field onto the model, its shape between the corners kept.
    fn then_matrix(&self, p: &Params, m: &Matrix3<f64>) -> Option<Params> {
        self.params_from_matrix(&(m * self.matrix(p)))
    }
    /// The inverse warp.
    fn invert(&self, p: &Params) -> Option<Params> {
        self.params_from_matrix(&self.matrix(p).try_inverse()?)
    }
    /// The additive update `p + dp`.
    fn additive_update(&self, p: &Params, dp: &Params) -> Params {
        let mut out = *p;
        for k in 0..self.dof() {
            out[k] += dp[k];
        }
        out
    }
    /// Warps points.
    fn warp_points(&self, p: &Params, pts: &[Point], out: &mut [Point]) {
        let m = self.matrix(p);
        for (o, &q) in out.iter_mut().zip(pts) {
            *o = apply_homography(&m, q);
        }
    }
}

/// Writes the derivatives of point `i` (of `n`) with respect to parameter `k` in the layout of
/// [`Ssm::jacobian`].
#[inline(always)]
pub fn put(out: &mut [f32], n: usize, i: usize, k: usize, dx: f32, dy: f32) {
    out[2 * k * n + i] = dx;
    out[(2 * k + 1) * n + i] = dy;
}

/// The `K` rows (`n` values each, `n` the gradients' and points' common length, checked) of
/// a pixel Jacobian stored by parameter: what [`Ssm::project_at_identity`] writes.
#[inline(always)]
pub(crate) fn projection_rows<'a, const K: usize>(
    jac: &'a mut [f32],
    (gx, gy, xs, ys): (&[f32], &[f32], &[f32], &[f32]),
) -> [&'a mut [f32]; K] {
    let n = gx.len();
    assert!(gy.len() == n && xs.len() == n && ys.len() == n && jac.len() >= K * n);
    if n == 0 {
        return std::array::from_fn(|_| Default::default());
    }
    let mut rows = jac[..K * n].chunks_exact_mut(n);
    std::array::from_fn(|_| rows.next().expect("K rows of n values"))
}

/// Builds an SSM.
pub type SsmBuilder = fn() -> Box<dyn Ssm>;

/// Every state space model, in order of increasing DOF.
pub const REGISTRY: &[Entry<SsmBuilder>] = &[
    translation::ENTRY,
    isometry::ENTRY,
    ist::ENTRY,
    similitude::ENTRY,
    ast::ENTRY,
    affine::ENTRY,
    homography::ENTRY,
    sl3::ENTRY,
    corner::ENTRY,
    spline::ENTRY,
    tps::ENTRY,
    spline::ENTRY_5,
    tps::ENTRY_5,
];

/// The SSM called `name` (or one of its aliases).
pub fn build(name: &str) -> crate::Result<Box<dyn Ssm>> {
    Ok((registry::lookup(REGISTRY, "state space model", name)?.build)())
}

/// Warps a quad.
pub fn warp_quad(ssm: &dyn Ssm, p: &Params, q: &Quad) -> Quad {
    let mut out = [Point::default(); 4];
    ssm.warp_points(p, &q.0, &mut out);
    Quad(out)
}

/// A random warp of the SSM: the corners of `base` displaced by independent Gaussian noise of
/// standard deviation `sigma`, projected onto the SSM by a least-squares fit. Returns the
/// parameters of the warp (relative to the identity). Used by the recovery tests and by the
/// sampling search methods.
pub fn random_warp(ssm: &dyn Ssm, base: &Quad, sigma: f64, rng: &mut Rng) -> Option<Params> {
    let mut dst = base.0;
    for p in dst.iter_mut() {
        p.x += sigma * rng.normal();
        p.y += sigma * rng.normal();
    }
    ssm.fit(&base.0, &dst)
}

/// Linear least squares for the similitude family `x' = a x - b y + tx, y' = b x + a y + ty`
/// (with `rotation_only`, `a^2 + b^2 = 1`: the Procrustes solution). Returns `(a, b, tx, ty)`.
pub(crate) fn fit_similarity(
    src: &[Point; 4],
    dst: &[Point; 4],
    rotation_only: bool,
) -> Option<(f64, f64, f64, f64)> {
    let cs = Quad(*src).centroid();
    let cd = Quad(*dst).centroid();
    let (mut dot, mut cross, mut ss) = (0.0, 0.0, 0.0);
    for k in 0..4 {
        let (x, y) = (src[k].x - cs.x, src[k].y - cs.y);
        let (u, v) = (dst[k].x - cd.x, dst[k].y - cd.y);
        dot += x * u + y * v;
        cross += x * v - y * u;
        ss += x * x + y * y;
    }
    let (a, b) = if rotation_only {
        let th = cross.atan2(dot);
        (th.cos(), th.sin())
    } else {
        if ss <= 0.0 {
            return None;
        }
        (dot / ss, cross / ss)
    };
    let tx = cd.x - (a * cs.x - b * cs.y);
    let ty = cd.y - (b * cs.x + a * cs.y);
    [a, b, tx, ty]
        .iter()
        .all(|v| v.is_finite())
        .then_some((a, b, tx, ty))
}

/// Homography Jacobian at one point with respect to the 8 entries `h` of
/// `[[h0 h1 h2] [h3 h4 h5] [h6 h7 1]]` (used by the homography and the corner parameterisation).
#[inline(always)]
pub(crate) fn homography_point_jacobian(h: &[f64; 9], x: f64, y: f64) -> ([f64; 8], [f64; 8]) {
    let w = h[6] * x + h[7] * y + h[8];
    let iw = 1.0 / w;
    let wx = (h[0] * x + h[1] * y + h[2]) * iw;
    let wy = (h[3] * x + h[4] * y + h[5]) * iw;
    (
        [
            x * iw,
            y * iw,
            iw,
            0.0,
            0.0,
            0.0,
            -wx * x * iw,
            -wx * y * iw,
        ],
        [
            0.0,
            0.0,
            0.0,
            x * iw,
            y * iw,
            iw,
            -wy * x * iw,
            -wy * y * iw,
        ],
    )
}

/// Matrix entries row by row.
pub(crate) fn entries(m: &Matrix3<f64>) -> [f64; 9] {
    [
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 0)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 0)],
        m[(2, 1)],
        m[(2, 2)],
    ]
}

/// Scales a homogeneous matrix so that its (2, 2) entry is 1; `None` if that entry is ~0.
pub(crate) fn normalise_h33(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let s = m[(2, 2)];
    if s.abs() < 1e-12 || !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(m / s)
}

#[cfg(test)]
mod tests;
