//! Translation: 2 DOF, `w(x) = x + t`.

use super::{Params, Ssm, SsmBuilder, normalise_h33, projection_rows};
use crate::geometry::{Point, Quad};
use crate::registry::Entry;
use nalgebra::Matrix3;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "translation",
    aliases: &["2", "trans"],
    description: "2 DOF translation (tx, ty)",
    build: || Box::new(Translation),
};

#[derive(Debug, Clone, Copy)]
pub struct Translation;

impl Ssm for Translation {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn dof(&self) -> usize {
        2
    }
    fn param_names(&self) -> &'static [&'static str] {
        &["tx", "ty"]
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        Matrix3::new(1.0, 0.0, p[0], 0.0, 1.0, p[1], 0.0, 0.0, 1.0)
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        let m = normalise_h33(m)?;
        let mut p = self.identity();
        p[0] = m[(0, 2)];
        p[1] = m[(1, 2)];
        Some(p)
    }
    fn jacobian(&self, _p: &Params, xs: &[f32], _ys: &[f32], out: &mut [f32]) {
        let n = xs.len();
        out[..n].fill(1.0);
        out[n..3 * n].fill(0.0);
        out[3 * n..4 * n].fill(1.0);
    }
    fn project_at_identity(
        &self,
        gx: &[f32],
        gy: &[f32],
        xs: &[f32],
        ys: &[f32],
        jac: &mut [f32],
    ) -> bool {
        // dw/dp is (1, 0) for w_x and (0, 1) for w_y.
        let [j0, j1] = projection_rows(jac, (gx, gy, xs, ys));
        j0.copy_from_slice(gx);
        j1.copy_from_slice(gy);
        true
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        let (cs, cd) = (Quad(*src).centroid(), Quad(*dst).centroid());
        let mut p = self.identity();
        p[0] = cd.x - cs.x;
        p[1] = cd.y - cs.y;
        p.iter().all(|v| v.is_finite()).then_some(p)
    }
}
