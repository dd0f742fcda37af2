//! Forward compositional Lucas-Kanade (FCLK): linearise `I_t(w(w(x, dp), p))` at `dp = 0` with
//! the gradient of the warped current frame and `dw/dp` at the identity; `p <- p o dp`.

use super::{Context, SearchMethod, SmDef, Step};
use crate::imaging::ImageView;
use crate::registry::Entry;

pub const ENTRY: Entry<SmDef> = Entry {
    name: "fclk",
    aliases: &["fc"],
    description: "forward compositional Lucas-Kanade",
    build: SmDef {
        params: &[],
        build: |_| Ok(Box::new(Fclk)),
    },
};

#[derive(Debug, Clone, Copy)]
pub struct Fclk;

impl SearchMethod for Fclk {
    fn name(&self) -> &str {
        ENTRY.name
    }
    fn local(&self) -> bool {
        true
    }
    fn line_search(&self) -> bool {
        true
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, super::LossReason> {
        let p = ctx.params;
        ctx.sample_gradients_at(img, &p);
        ctx.forward_compositional_step(&p).map(Step::auto)
    }
}
