//! Affine: 6 DOF, `w(x) = [[1+a11, a12], [a21, 1+a22]] x + t`, parameters
//! `(tx, ty, a11, a12, a21, a22)`.

use super::{Params, Ssm, SsmBuilder, normalise_h33, projection_rows, put};
use crate::geometry::Point;
use crate::registry::Entry;
use nalgebra::{Matrix3, Vector3};

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "affine",
    aliases: &["6", "aff"],
    description: "6 DOF affine (tx, ty, a11, a12, a21, a22)",
    build: || Box::new(Affine),
};

#[derive(Debug, Clone, Copy)]
pub struct Affine;

impl Ssm for Affine {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        6
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["tx", "ty", "a11", "a12", "a21", "a22"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        Matrix3::new(
            1.0 + p[2],
            p[3],
            p[0],
            p[4],
            1.0 + p[5],
            p[1],
            0.0,
            0.0,
            1.0,
        )
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let m = normalise_h33(m)?;
        let mut p = self.identity();
        p[0] = m[(0, 2)];
        p[1] = m[(1, 2)];
        p[2] = m[(0, 0)] - 1.0;
        p[3] = m[(0, 1)];
        p[4] = m[(1, 0)];
        p[5] = m[(1, 1)] - 1.0;
        Some(p)
    }
    fn jacobian(&self, _p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            put(out, n, i, 0, 1.0, 0.0);
            put(out, n, i, 1, 0.0, 1.0);
            put(out, n, i, 2, x, 0.0);
            put(out, n, i, 3, y, 0.0);
            put(out, n, i, 4, 0.0, x);
            put(out, n, i, 5, 0.0, y);
        }
    }
    fn project_at_identity(
        &self,
        gx: &[f32],
        gy: &[f32],
        xs: &[f32],
        ys: &[f32],
        jac: &mut [f32],
    ) -> bool {
        // dw/dp is (1, 0, x, y, 0, 0) for w_x and (0, 1, 0, 0, x, y) for w_y.
        let rows: [_; 6] = projection_rows(jac, (gx, gy, xs, ys));
        // Every row as long as the inputs, where the loop's bounds checks can see it.
        assert!(rows.iter().all(|r| r.len() == gx.len()));
        let [j0, j1, j2, j3, j4, j5] = rows;
        for i in 0..gx.len() {
            let (a, b, x, y) = (gx[i], gy[i], xs[i], ys[i]);
            j0[i] = a;
            j1[i] = b;
            j2[i] = a * x;
            j3[i] = a * y;
            j4[i] = b * x;
            j5[i] = b * y;
        }
        true
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        // Normal equations of [x y 1] [a b t]^T = u, one per output coordinate.
        let mut ata = Matrix3::zeros();
        let (mut atu, mut atv) = (Vector3::zeros(), Vector3::zeros());
        for k in 0..4 {
            let r = Vector3::new(src[k].x, src[k].y, 1.0);
            ata += r * r.transpose();
            atu += r * dst[k].x;
            atv += r * dst[k].y;
        }
        let lu = ata.lu();
        let a = lu.solve(&atu)?;
        let b = lu.solve(&atv)?;
        let p = super::params(&[a[2], b[2], a[0] - 1.0, a[1], b[0], b[1] - 1.0]);
        p.iter().all(|v| v.is_finite()).then_some(p)
    }
}
