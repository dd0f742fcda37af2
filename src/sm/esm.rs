//! Efficient second-order minimisation (ESM, Benhimane and Malis), in the extended form the paper
//! uses: the Jacobian is the mean of the forward (current frame, warped) and inverse (template)
//! Jacobians, both with `dw/dp` at the identity; `p <- p o dp`.

use super::{Context, LossReason, SearchMethod, SmDef, Step, Update};
use crate::imaging::ImageView;
use crate::registry::Entry;

pub const ENTRY: Entry<SmDef> = Entry {
    name: "esm",
    aliases: &[],
    description: "efficient second-order minimisation (mean of initial and current Jacobians)",
    build: SmDef {
        params: &[],
        build: |_| Ok(Box::new(Esm)),
    },
};

#[derive(Debug, Clone, Copy)]
pub struct Esm;

impl SearchMethod for Esm {
    fn name(&self) -> &str {
        ENTRY.name
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let p = ctx.params;
        ctx.warp_grid(&p);
        ctx.sample(img, true);
        ctx.warped_gradient(&p);
        for i in 0..ctx.len() {
            ctx.work.gx[i] = 0.5 * (ctx.work.gx[i] + ctx.template_gx[i]);
            ctx.work.gy[i] = 0.5 * (ctx.work.gy[i] + ctx.template_gy[i]);
        }
        ctx.project_gradients(None);
        ctx.forward_step(Update::Compose).map(Step::auto)
    }
}
