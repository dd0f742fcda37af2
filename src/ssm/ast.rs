//! Anisotropic scaling and translation (MTF's AST): 4 DOF, `w(x) = diag(1 + sx, 1 + sy) x + t`,
//! parameters `(tx, ty, sx, sy)`. An axis-aligned box whose width and height change apart (a
//! door opening towards the camera, a page seen more and more obliquely).

use super::{Params, Ssm, SsmBuilder, normalise_h33, put};
use crate::geometry::{Point, Quad};
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "ast",
    aliases: &["anisotropic_scaling"],
    description: "4 DOF anisotropic scaling and translation (tx, ty, sx, sy)",
    build: || Box::new(Ast),
};

#[derive(Debug, Clone, Copy)]
pub struct Ast;

impl Ssm for Ast {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        4
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["tx", "ty", "sx", "sy"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        Matrix3::new(1.0 + p[2], 0.0, p[0], 0.0, 1.0 + p[3], p[1], 0.0, 0.0, 1.0)
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let m = normalise_h33(m)?;
        let mut p = self.identity();
        p[0] = m[(0, 2)];
        p[1] = m[(1, 2)];
        p[2] = m[(0, 0)] - 1.0;
        p[3] = m[(1, 1)] - 1.0;
        Some(p)
    }
    fn jacobian(&self, _p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let n = xs.len();
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            put(out, n, i, 0, 1.0, 0.0);
            put(out, n, i, 1, 0.0, 1.0);
            put(out, n, i, 2, x, 0.0);
            put(out, n, i, 3, 0.0, y);
        }
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        // The two axes are apart: a line fit along each, about the centroids.
        let (cs, cd) = (Quad(*src).centroid(), Quad(*dst).centroid());
        let (mut xu, mut xx, mut yv, mut yy) = (0.0, 0.0, 0.0, 0.0);
        for (s, d) in src.iter().zip(dst) {
            let (x, y) = (s.x - cs.x, s.y - cs.y);
            xu += x * (d.x - cd.x);
            xx += x * x;
            yv += y * (d.y - cd.y);
            yy += y * y;
        }
        if xx <= 0.0 || yy <= 0.0 {
            return None;
        }
        let (ax, ay) = (xu / xx, yv / yy);
        let mut p = self.identity();
        p[0] = cd.x - ax * cs.x;
        p[1] = cd.y - ay * cs.y;
        p[2] = ax - 1.0;
        p[3] = ay - 1.0;
        p.iter().all(|v| v.is_finite()).then_some(p)
    }
}
