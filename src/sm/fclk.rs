//! Forward compositional Lucas-Kanade (FCLK): linearise `I_t(w(w(x, dp), p))` at `dp = 0` with
//! the gradient of the warped current frame and `dw/dp` at the identity; `p <- p o dp`.

use super::{Context, SearchMethod, SmBuilder, Update};
use crate::am::Wrt;
use crate::imaging::ImageView;
use crate::registry::Entry;

pub const ENTRY: Entry<SmBuilder> = Entry {
    name: "fclk",
    aliases: &["fc"],
    description: "forward compositional Lucas-Kanade",
    build: |_| Box::new(Fclk),
};

#[derive(Debug, Clone, Copy)]
pub struct Fclk;

impl SearchMethod for Fclk {
    fn name(&self) -> &'static str {
        ENTRY.name
    }
    fn initialize(&mut self, _ctx: &mut Context) -> Result<(), super::LossReason> {
        Ok(())
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<f64, super::LossReason> {
        let p = ctx.params;
        ctx.warp_grid(&p);
        ctx.sample(img, true);
        ctx.warped_gradient(&p);
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
