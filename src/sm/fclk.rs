//! Forward compositional Lucas-Kanade (FCLK): linearise `I_t(w(w(x, dp), p))` at `dp = 0` with
//! the gradient of the warped current frame and `dw/dp` at the identity; `p <- p o dp`.
//!
//! Its iteration is in two halves, also used apart by the plan's polish
//! ([`crate::plan::Polish`], which judges the patch between them): the patch and its gradients
//! sampled at `p` ([`Context::sample_gradients_at`]), then [`step`].

use super::{Context, LossReason, SearchMethod, SmDef, Step, newton};
use crate::imaging::ImageView;
use crate::registry::Entry;
use crate::ssm::Params;

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
    fn non_rigid(&self) -> bool {
        true
    }
    fn line_search(&self) -> bool {
        true
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let p = ctx.params();
        ctx.sample_gradients_at(img, &p);
        step(ctx, &p).map(Step::auto)
    }
}

/// FCLK's step from `p`, once the frame's values and gradients have been sampled there;
/// returns the similarity at `p`.
pub fn step(ctx: &mut Context, p: &Params) -> Result<f64, LossReason> {
    newton::forward_compositional_step(ctx, p)
}
