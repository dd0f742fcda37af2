//! Efficient second-order minimisation (ESM, Benhimane and Malis), in the extended form the paper
//! uses: the Jacobian is the mean of the forward (current frame, warped) and inverse (template)
//! Jacobians, both with `dw/dp` at the identity; `p <- p o dp`.

use super::{Context, LossReason, SearchMethod, SmBuilder, Update};
use crate::am::Wrt;
use crate::imaging::ImageView;
use crate::registry::Entry;

pub const ENTRY: Entry<SmBuilder> = Entry {
    name: "esm",
    aliases: &[],
    description: "efficient second-order minimisation (mean of initial and current Jacobians)",
    build: |_| Box::new(Esm),
};

#[derive(Debug, Clone, Copy)]
pub struct Esm;

impl SearchMethod for Esm {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn initialize(&mut self, _ctx: &mut Context) -> Result<(), LossReason> {
        Ok(())
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<f64, LossReason> {
        let p = ctx.params;
        ctx.warp_grid(&p);
        ctx.sample(img, true);
        ctx.warped_gradient(&p);
        for i in 0..ctx.len() {
            ctx.gx[i] = 0.5 * (ctx.gx[i] + ctx.template_gx[i]);
            ctx.gy[i] = 0.5 * (ctx.gy[i] + ctx.template_gy[i]);
        }
        let mut jac = std::mem::take(&mut ctx.jac);
        Context::project(&ctx.gx, &ctx.gy, &ctx.dwdp0, ctx.dof, &mut jac);
        let f = ctx.am.gradient(Wrt::Current, &ctx.values, &mut ctx.grad);
        let mut h = [0.0; 64];
        ctx.am.hessian(
            Wrt::Current,
            ctx.hessian,
            &ctx.values,
            &jac,
            ctx.dof,
            &mut h,
        );
        let r = ctx.step(&jac, &h, Update::Compose);
        ctx.jac = jac;
        r.map(|_| f)
    }
}
