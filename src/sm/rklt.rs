//! RKLT (Zhang, Singh and Jagersand, as MTF has it): the grid tracker's estimate
//! ([`super::grid`]) refined by a registration tracker that keeps the first frame's template
//! (`refine`: ESM by default, as MTF recommends). When the refined corners end farther than
//! `rklt_fail_px` from the grid's (the L2 norm of the eight coordinates), the refinement is
//! taken to have failed and the grid's estimate stands; either way the grid's patches are laid
//! on the frame's final estimate for the next frame (MTF's feedback).
//!
//! The grid brings a large motion or a partly hidden target within the registration
//! tracker's basin; the registration tracker, against the first frame's template, undoes the
//! grid's drift from frame to frame.

use super::cascade::{finished, union};
use super::esm::Esm;
use super::fclk::Fclk;
use super::grid::{GRID_PARAMS, Grid};
use super::iclk::Iclk;
use super::{Context, Control, LossReason, MethodVisual, SearchMethod, SmConfig, SmDef, Step};
use crate::am::Capabilities;
use crate::geometry::Quad;
use crate::imaging::ImageView;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::ssm::Params;

/// The search methods that may refine the grid's estimate.
pub const REFINERS: [&str; 3] = ["esm", "iclk", "fclk"];

/// RKLT's parameters: the grid's, then its own.
pub const RKLT_PARAMS: [ParamDef; 7] = [
    GRID_PARAMS[0],
    GRID_PARAMS[1],
    GRID_PARAMS[2],
    GRID_PARAMS[3],
    GRID_PARAMS[4],
    ParamDef::choice(
        "refine",
        "the registration method that refines the grid's estimate",
        &REFINERS,
    ),
    ParamDef::float(
        "rklt_fail_px",
        "the refinement is dropped when its corners end farther than this from the grid's (L2 norm of the eight coordinates, px)",
        0.1,
        1000.0,
        15.0,
    ),
];

pub const ENTRY: Entry<SmDef> = Entry {
    name: "rklt",
    aliases: &["rkl"],
    description: "the grid tracker refined by a registration tracker (ESM by default), with failure detection",
    build: SmDef {
        params: &RKLT_PARAMS,
        build: |cfg| Ok(Box::new(Rklt::new(cfg))),
    },
};

/// See the module's documentation.
#[derive(Debug)]
pub struct Rklt {
    grid: Grid,
    refine: Box<dyn SearchMethod>,
    fail_px: f64,
    eps: f64,
    max_iters: usize,
    /// The frame's stage (0: the grid, 1: the refinement) and the refinement's iterations.
    stage: usize,
    count: usize,
    /// Where the grid put the target this frame.
    grid_at: (Params, Quad),
}

impl Rklt {
    pub fn new(cfg: &SmConfig) -> Self {
        let refine: Box<dyn SearchMethod> = match cfg.get(&RKLT_PARAMS[5]) as usize {
            1 => Box::new(Iclk::default()),
            2 => Box::new(Fclk),
            _ => Box::new(Esm::new(3)),
        };
        Rklt {
            grid: Grid::new(cfg),
            refine,
            fail_px: cfg.get(&RKLT_PARAMS[6]),
            eps: cfg.tracker.eps,
            max_iters: cfg.tracker.max_iters,
            stage: 0,
            count: 0,
            grid_at: ([0.0; crate::linalg::MAX_DOF], Quad::default()),
        }
    }

    /// The end of a frame: the refinement dropped if it strayed from the grid's estimate, the
    /// grid's patches laid on the estimate that stands.
    fn end_frame(&mut self, ctx: &mut Context, img: &ImageView) {
        let refined = ctx.corners(&ctx.params());
        if !refined.is_finite() || refined.change_norm(&self.grid_at.1) > self.fail_px {
            ctx.set_params(self.grid_at.0);
        }
        self.grid.retemplate(ctx, img);
    }
}

impl SearchMethod for Rklt {
    fn name(&self) -> &str {
        ENTRY.name
    }
    fn requires(&self) -> Capabilities {
        union([&self.grid as &dyn SearchMethod, &*self.refine])
    }
    fn pyramid(&self) -> bool {
        // The grid's patches bring the target within the refinement's basin.
        false
    }
    fn template_linearised(&self) -> bool {
        // The frame ends with the refinement.
        self.refine.template_linearised()
    }
    fn initialize(&mut self, ctx: &mut Context, img: &ImageView) -> Result<(), LossReason> {
        self.grid.initialize(ctx, img)?;
        self.refine.initialize(ctx, img)
    }
    fn model_updated(&mut self, ctx: &mut Context) {
        self.refine.model_updated(ctx);
    }
    fn start_frame(&mut self, ctx: &mut Context) {
        self.stage = 0;
        self.count = 0;
        self.grid.start_frame(ctx);
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        if self.stage == 0 {
            let step = self.grid.iterate(ctx, img)?;
            let p = ctx.params();
            self.grid_at = (p, ctx.corners(&p));
            self.stage = 1;
            self.refine.start_frame(ctx);
            return Ok(Step {
                similarity: step.similarity,
                control: Control::Continue,
            });
        }
        let before = ctx.corners(&ctx.params());
        // A refinement that fails leaves the grid's estimate.
        let step = match self.refine.iterate(ctx, img) {
            Ok(s) => s,
            Err(_) => {
                ctx.set_params(self.grid_at.0);
                self.grid.retemplate(ctx, img);
                let f = ctx.similarity_at(img, &self.grid_at.0);
                return Ok(Step::done(f));
            }
        };
        self.count += 1;
        let moved = ctx.corners(&ctx.params()).change_norm(&before);
        if !finished(step.control, moved, self.eps, self.count, self.max_iters) {
            return Ok(Step {
                similarity: step.similarity,
                control: Control::Continue,
            });
        }
        self.end_frame(ctx, img);
        Ok(Step::done(step.similarity))
    }
    fn max_iterations(&self, max_iters: usize) -> usize {
        1 + self.refine.max_iterations(max_iters)
    }
    fn visual(&mut self, ctx: &Context) -> Option<MethodVisual<'_>> {
        self.grid.visual(ctx)
    }
}
