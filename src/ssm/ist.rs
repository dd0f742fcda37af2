//! Isotropic scaling and translation (MTF's IST): 3 DOF, `w(x) = (1 + s) x + t`, parameters
//! `(tx, ty, s)`. A target that comes nearer or moves away without turning (a camera zooming on
//! a sign, a conveyor seen from above).

use super::{Params, Ssm, SsmBuilder, fit_similarity, normalise_h33, put};
use crate::geometry::{Point, Quad};
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "ist",
    aliases: &["isotropic_scaling"],
    description: "3 DOF isotropic scaling and translation (tx, ty, s)",
    build: || Box::new(Ist),
};

#[derive(Debug, Clone, Copy)]
pub struct Ist;

impl Ssm for Ist {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        3
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["tx", "ty", "s"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        let a = 1.0 + p[2];
        Matrix3::new(a, 0.0, p[0], 0.0, a, p[1], 0.0, 0.0, 1.0)
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let m = normalise_h33(m)?;
        let mut p = self.identity();
        p[0] = m[(0, 2)];
        p[1] = m[(1, 2)];
        p[2] = 0.5 * (m[(0, 0)] + m[(1, 1)]) - 1.0;
        Some(p)
    }
    fn jacobian(&self, _p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            put(out, n, i, 0, 1.0, 0.0);
            put(out, n, i, 1, 0.0, 1.0);
            put(out, n, i, 2, x, y);
        }
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        // The similitude's least-squares scale (its rotation part, fitted apart from the scale,
        // is dropped); about the centroids the translation follows.
        let (a, _, _, _) = fit_similarity(src, dst, false)?;
        let (cs, cd) = (Quad(*src).centroid(), Quad(*dst).centroid());
        let mut p = self.identity();
        p[0] = cd.x - a * cs.x;
        p[1] = cd.y - a * cs.y;
        p[2] = a - 1.0;
        p.iter().all(|v| v.is_finite()).then_some(p)
    }
}
