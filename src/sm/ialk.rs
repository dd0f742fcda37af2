//! Inverse additive Lucas-Kanade (IALK, Hager and Belhumeur): the frame gradient at the warped
//! point is replaced by the template gradient mapped through the inverse point Jacobian,
//! `grad I_t(w(x, p)) ~ grad I*(x) (dw/dx)^-1`, so only the template is differentiated;
//! `p <- p + dp`.

use super::{Context, SearchMethod, SmDef, Step, Update, newton};
use crate::imaging::ImageView;
use crate::registry::Entry;

pub const ENTRY: Entry<SmDef> = Entry {
    name: "ialk",
    aliases: &["ia"],
    description: "inverse additive Lucas-Kanade (Hager-Belhumeur)",
    build: SmDef {
        params: &[],
        build: |_| Ok(Box::new(Ialk)),
    },
};

#[derive(Debug, Clone, Copy)]
pub struct Ialk;

impl SearchMethod for Ialk {
    fn name(&self) -> &str {
        ENTRY.name
    }
    fn local(&self) -> bool {
        true
    }
    fn non_rigid(&self) -> bool {
        true
    }
    fn line_search(&self) -> bool {
        true
    }
    fn template_linearised(&self) -> bool {
        true
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, super::LossReason> {
        let p = ctx.params();
        ctx.sample_at(img, &p);
        // Template gradient times the inverse of the warp's point Jacobian (normalised frame).
        if !ctx.ssm().projective() {
            let (problem, _, work) = ctx.parts_mut();
            let (template_gx, template_gy) = problem.template_gradient();
            let (gx, gy) = work.gradients_mut();
            for i in 0..problem.len() {
                let [a00, a01, a10, a11] = problem.point_jacobian(&p, i);
                let det = a00 * a11 - a01 * a10;
                let (tx, ty) = (template_gx[i], template_gy[i]);
                gx[i] = (tx * a11 - ty * a10) / det;
                gy[i] = (-tx * a01 + ty * a00) / det;
            }
            newton::project_gradients(ctx, Some(&p));
            return newton::forward_step(ctx, Update::Additive).map(Step::auto);
        }
        let m = ctx.ssm().matrix(&p).cast::<f32>();
        let (problem, _, work) = ctx.parts_mut();
        let ((grid_x, grid_y), (template_gx, template_gy)) =
            (problem.grid(), problem.template_gradient());
        let (gx, gy) = work.gradients_mut();
        for i in 0..problem.len() {
            let (x, y) = (grid_x[i], grid_y[i]);
            let iw = 1.0 / (m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)]);
            let u = (m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)]) * iw;
            let v = (m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)]) * iw;
            let a00 = (m[(0, 0)] - u * m[(2, 0)]) * iw;
            let a01 = (m[(0, 1)] - u * m[(2, 1)]) * iw;
            let a10 = (m[(1, 0)] - v * m[(2, 0)]) * iw;
            let a11 = (m[(1, 1)] - v * m[(2, 1)]) * iw;
            let det = a00 * a11 - a01 * a10;
            let (tx, ty) = (template_gx[i], template_gy[i]);
            // (tx, ty) A^-1 with A^-1 = [[a11, -a01], [-a10, a00]] / det.
            gx[i] = (tx * a11 - ty * a10) / det;
            gy[i] = (-tx * a01 + ty * a00) / det;
        }
        newton::project_gradients(ctx, Some(&p));
        newton::forward_step(ctx, Update::Additive).map(Step::auto)
    }
}
