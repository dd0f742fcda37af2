//! Isometry (Euclidean): 3 DOF, `w(x) = R(theta) x + t`, parameters `(tx, ty, theta)`.

use super::{Params, Ssm, SsmBuilder, fit_similarity, normalise_h33, put};
use crate::geometry::Point;
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "isometry",
    aliases: &["3", "iso", "euclidean"],
    description: "3 DOF rotation and translation (tx, ty, theta)",
    build: || Box::new(Isometry),
};

#[derive(Debug, Clone, Copy)]
pub struct Isometry;

impl Ssm for Isometry {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        3
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["tx", "ty", "theta"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        let (s, c) = p[2].sin_cos();
        Matrix3::new(c, -s, p[0], s, c, p[1], 0.0, 0.0, 1.0)
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let m = normalise_h33(m)?;
        let mut p = self.identity();
        p[0] = m[(0, 2)];
        p[1] = m[(1, 2)];
        p[2] = m[(1, 0)].atan2(m[(0, 0)]);
        Some(p)
    }
    fn jacobian(&self, p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let (s, c) = p[2].sin_cos();
        let (s, c) = (s as f32, c as f32);
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            put(out, n, i, 0, 1.0, 0.0);
            put(out, n, i, 1, 0.0, 1.0);
            put(out, n, i, 2, -s * x - c * y, c * x - s * y);
        }
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        let (a, b, tx, ty) = fit_similarity(src, dst, true)?;
        let mut p = self.identity();
        p[0] = tx;
        p[1] = ty;
        p[2] = b.atan2(a);
        Some(p)
    }
}
