//! Forward additive Lucas-Kanade (FALK, the original of Lucas and Kanade): linearise
//! `I_t(w(x, p + dp))` with the frame gradient and `dw/dp` at the current `p`; `p <- p + dp`.

use super::{Context, SearchMethod, SmDef, Step, Update, newton};
use crate::imaging::ImageView;
use crate::registry::Entry;

pub const ENTRY: Entry<SmDef> = Entry {
    name: "falk",
    aliases: &["fa"],
    description: "forward additive Lucas-Kanade",
    build: SmDef {
        params: &[],
        build: |_| Ok(Box::new(Falk)),
    },
};

#[derive(Debug, Clone, Copy)]
pub struct Falk;

impl SearchMethod for Falk {
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
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, super::LossReason> {
        let p = ctx.params();
        ctx.sample_gradients_at(img, &p);
        // d pixel / d (normalised point) is the scale of the normaliser.
        let s = ctx.problem().norm().scale as f32;
        let (gx, gy) = ctx.work_mut().gradients_mut();
        gx.iter_mut().chain(gy.iter_mut()).for_each(|g| *g *= s);
        newton::project_gradients(ctx, Some(&p));
        newton::forward_step(ctx, Update::Additive).map(Step::auto)
    }
}
