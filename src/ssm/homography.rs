//! Homography with the matrix entries as parameters: 8 DOF,
//! `H = [[1+p0, p1, p2], [p3, 1+p4, p5], [p6, p7, 1]]`.

use super::{
    Params, Ssm, SsmBuilder, entries, homography_point_jacobian, normalise_h33, projection_rows,
    put,
};
use crate::geometry::{Point, homography_from_points};
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "homography",
    aliases: &["8", "hom", "lie_hom"],
    description: "8 DOF homography parameterised by its matrix entries",
    build: || Box::new(Homography),
};

#[derive(Debug, Clone, Copy)]
pub struct Homography;

impl Ssm for Homography {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        8
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["h11-1", "h12", "h13", "h21", "h22-1", "h23", "h31", "h32"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        Matrix3::new(
            1.0 + p[0],
            p[1],
            p[2],
            p[3],
            1.0 + p[4],
            p[5],
            p[6],
            p[7],
            1.0,
        )
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let e = entries(&normalise_h33(m)?);
        Some(super::params(&[
            e[0] - 1.0,
            e[1],
            e[2],
            e[3],
            e[4] - 1.0,
            e[5],
            e[6],
            e[7],
        ]))
    }
    fn jacobian(&self, p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let h = entries(&self.matrix(p));
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            let (jx, jy) = homography_point_jacobian(&h, x as f64, y as f64);
            for k in 0..8 {
                put(out, n, i, k, jx[k] as f32, jy[k] as f32);
            }
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
        // At the identity dw/dp is (x, y, 1, 0, 0, 0, -x^2, -xy) for w_x and (0, 0, 0, x, y, 1,
        // -xy, -y^2) for w_y; each f32 product here is the f64 product of the stored Jacobian
        // rounded once, so the same bits.
        let rows: [_; 8] = projection_rows(jac, (gx, gy, xs, ys));
        // Every row as long as the inputs, where the loop's bounds checks can see it.
        assert!(rows.iter().all(|r| r.len() == gx.len()));
        let [j0, j1, j2, j3, j4, j5, j6, j7] = rows;
        for i in 0..gx.len() {
            let (a, b, x, y) = (gx[i], gy[i], xs[i], ys[i]);
            let (xx, xy, yy) = (-(x * x), -(x * y), -(y * y));
            j0[i] = a * x;
            j1[i] = a * y;
            j2[i] = a;
            j3[i] = b * x;
            j4[i] = b * y;
            j5[i] = b;
            j6[i] = a * xx + b * xy;
            j7[i] = a * xy + b * yy;
        }
        true
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        self.params_from_matrix(&homography_from_points(src, dst)?)
    }
}
