//! Similitude (similarity): 4 DOF, `w(x) = [[1+a, -b], [b, 1+a]] x + t`, parameters
//! `(tx, ty, a, b)`.

use super::{Params, Ssm, SsmBuilder, fit_similarity, normalise_h33, put};
use crate::geometry::Point;
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "similitude",
    aliases: &["4", "sim", "similarity"],
    description: "4 DOF rotation, uniform scale and translation (tx, ty, a, b)",
    build: || Box::new(Similitude),
};

#[derive(Debug, Clone, Copy)]
pub struct Similitude;

impl Ssm for Similitude {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        4
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["tx", "ty", "a", "b"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        Matrix3::new(
            1.0 + p[2],
            -p[3],
            p[0],
            p[3],
            1.0 + p[2],
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
        p[2] = 0.5 * (m[(0, 0)] + m[(1, 1)]) - 1.0;
        p[3] = 0.5 * (m[(1, 0)] - m[(0, 1)]);
        Some(p)
    }
    fn jacobian(&self, _p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            put(out, n, i, 0, 1.0, 0.0);
            put(out, n, i, 1, 0.0, 1.0);
            put(out, n, i, 2, x, y);
            put(out, n, i, 3, -y, x);
        }
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        let (a, b, tx, ty) = fit_similarity(src, dst, false)?;
        let mut p = self.identity();
        p[0] = tx;
        p[1] = ty;
        p[2] = a - 1.0;
        p[3] = b;
        Some(p)
    }
}
