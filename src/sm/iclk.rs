//! Inverse compositional Lucas-Kanade (ICLK, Baker and Matthews): the step warps the template,
//! `I*(w(x, dp))`, so the Jacobian `grad I*(x) dw/dp(x, 0)` and (for every Hessian kind but
//! Newton) the Hessian are computed once per template; `p <- p o dp^-1`.
//!
//! The constant Hessian is the template-side second derivative after convergence. How far a
//! step should go depends instead on how the template-side gradient moves with the current
//! patch (the mixed derivative `d2f / dT dC`), which is minus that Hessian for SSD and nearly
//! so for MI, but 1.25x it for CCRE with 8 bins (2.3-2.8x with 4): ICLK-CCRE overshoots, and
//! without the line search settles into a 2-cycle a few tenths of a pixel wide. The mixed term
//! in its place cut the iterations (30 -> 9.6 a frame) but also the frequency of convergence
//! from far starts (docs/speed.md, "ICLK's Hessian with CCRE"), so it is not used.

use super::{Context, LossReason, SearchMethod, SmDef, Step, Update, newton};
use crate::am::{HessianKind, Wrt};
use crate::imaging::ImageView;
use crate::linalg::jt_times;
use crate::linalg::{MAX_DOF, SquareBuf};
use crate::registry::Entry;

pub const ENTRY: Entry<SmDef> = Entry {
    name: "iclk",
    aliases: &["ic"],
    description: "inverse compositional Lucas-Kanade (Baker-Matthews)",
    build: SmDef {
        params: &[],
        build: |_| Ok(Box::new(Iclk::default())),
    },
};

#[derive(Debug, Clone, Default)]
pub struct Iclk {
    /// Template Jacobian `N x S`.
    jac: Vec<f32>,
    /// Constant Hessian (unless the Newton kind is asked for).
    hessian: SquareBuf,
}

impl Iclk {
    /// The constant Hessian: at the template the current patch equals it. Allocation-free (it
    /// runs after every frame for the AMs that keep a model).
    fn template_hessian(&mut self, ctx: &mut Context) {
        let (problem, _, work) = ctx.parts_mut();
        let kind = match problem.hessian() {
            HessianKind::Newton => HessianKind::AfterConvergence,
            k => k,
        };
        let dof = problem.dof();
        // The AM's contract: the Hessian follows a gradient on the same patch.
        let (am, template) = problem.am_and_template_mut();
        am.gradient(Wrt::Template, template, work.grad_mut());
        am.hessian(
            Wrt::Template,
            kind,
            template,
            &self.jac,
            dof,
            &mut self.hessian,
        );
    }
}

impl SearchMethod for Iclk {
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
    fn initialize(&mut self, ctx: &mut Context, _img: &ImageView) -> Result<(), LossReason> {
        let problem = ctx.problem();
        self.jac.resize(problem.len() * problem.dof(), 0.0);
        let (tx, ty) = problem.template_gradient();
        newton::project(tx, ty, problem.dwdp0().0, problem.dof(), &mut self.jac);
        self.template_hessian(ctx);
        Ok(())
    }
    fn model_updated(&mut self, ctx: &mut Context) {
        // An intensity map (SCV...) changed the AM's second derivative: refresh the constant
        // Hessian (the Jacobian of the template does not change).
        self.template_hessian(ctx);
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let p = ctx.params();
        // Often sampled there already (the plan's checks between the pyramid levels).
        ctx.patch_at(img, &p);
        let f = ctx.am_gradient(Wrt::Template);
        let (problem, _, work) = ctx.parts_mut();
        let dof = problem.dof();
        if problem.hessian() == HessianKind::Newton {
            problem.am_mut().hessian(
                Wrt::Template,
                HessianKind::Newton,
                work.values(),
                &self.jac,
                dof,
                &mut self.hessian,
            );
        }
        // J^T g: from the moments of the gradient times the template's gradient on the grid
        // where the region has them (six or more parameters, SSD), else through the Jacobian.
        let mut g = [0.0; MAX_DOF];
        match problem.moments_and_unit_gradient() {
            (Some(m), (tu, tv)) => m.jtr(tu, tv, work.grad(), &mut g),
            (None, _) => jt_times(&self.jac, work.grad(), dof, &mut g),
        }
        newton::solve_step(ctx, &g, &self.hessian, Update::ComposeInverse)?;
        Ok(Step::auto(f))
    }
}
