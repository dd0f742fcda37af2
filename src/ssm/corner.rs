//! Corner-based homography: 8 DOF, the parameters are the displacements
//! `(dx0, dy0, ..., dx3, dy3)` of the corners of the canonical square `[-0.5, 0.5]^2` (the
//! normalised initial region's size) under the warp.

use super::{Params, Ssm, SsmBuilder, entries, homography_point_jacobian, put};
use crate::geometry::{Point, Quad, apply_homography, homography_from_points};
use crate::registry::Entry;
use nalgebra::{Matrix3, SMatrix};

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "corner",
    aliases: &["c8", "corner_homography", "chom"],
    description: "8 DOF homography parameterised by the displacements of four corners",
    build: || Box::new(CornerHomography),
};

#[derive(Debug, Clone, Copy)]
pub struct CornerHomography;

fn base() -> [Point; 4] {
    Quad::unit_square().0
}

fn targets(p: &Params) -> [Point; 4] {
    let b = base();
    std::array::from_fn(|k| Point::new(b[k].x + p[2 * k], b[k].y + p[2 * k + 1]))
}

impl CornerHomography {
    /// The DLT system `A h = b` of the homography from the base square to the displaced corners.
    fn system(&self, p: &Params) -> SMatrix<f64, 8, 8> {
        let (src, dst) = (base(), targets(p));
        let mut a = SMatrix::<f64, 8, 8>::zeros();
        for k in 0..4 {
            let (x, y, u, v) = (src[k].x, src[k].y, dst[k].x, dst[k].y);
            let r = 2 * k;
            a[(r, 0)] = x;
            a[(r, 1)] = y;
            a[(r, 2)] = 1.0;
            a[(r, 6)] = -u * x;
            a[(r, 7)] = -u * y;
            a[(r + 1, 3)] = x;
            a[(r + 1, 4)] = y;
            a[(r + 1, 5)] = 1.0;
            a[(r + 1, 6)] = -v * x;
            a[(r + 1, 7)] = -v * y;
        }
        a
    }
}

impl Ssm for CornerHomography {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        8
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["dx0", "dy0", "dx1", "dy1", "dx2", "dy2", "dx3", "dy3"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        // A degenerate corner configuration has no homography: report it as non-finite so that
        // the search method sees the loss.
        homography_from_points(&base(), &targets(p))
            .unwrap_or_else(|| Matrix3::from_element(f64::NAN))
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let b = base();
        let mut p = self.identity();
        for k in 0..4 {
            let q = apply_homography(m, b[k]);
            p[2 * k] = q.x - b[k].x;
            p[2 * k + 1] = q.y - b[k].y;
        }
        p.iter().all(|v| v.is_finite()).then_some(p)
    }
    fn jacobian(&self, p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        // Implicit differentiation of A(p) h = b(p): moving corner k's target u_k changes row 2k,
        // d h / d u_k = A^-1 e_2k * w_k where w_k = h6 x_k + h7 y_k + 1 (likewise for v_k).
        let h = entries(&self.matrix(p));
        let mut dh_dp = SMatrix::<f64, 8, 8>::zeros();
        if let Some(ainv) = self.system(p).try_inverse() {
            let src = base();
            for k in 0..4 {
                let wk = h[6] * src[k].x + h[7] * src[k].y + 1.0;
                for r in 0..2 {
                    let col = 2 * k + r;
                    for i in 0..8 {
                        dh_dp[(i, col)] = ainv[(i, col)] * wk;
                    }
                }
            }
        } else {
            dh_dp.fill(f64::NAN);
        }
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            let (jx, jy) = homography_point_jacobian(&h, x as f64, y as f64);
            for c in 0..8 {
                let (mut sx, mut sy) = (0.0, 0.0);
                for i in 0..8 {
                    sx += jx[i] * dh_dp[(i, c)];
                    sy += jy[i] * dh_dp[(i, c)];
                }
                put(out, n, i, c, sx as f32, sy as f32);
            }
        }
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        self.params_from_matrix(&homography_from_points(src, dst)?)
    }
}
