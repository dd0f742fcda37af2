//! The interface between the executor and a search method: one iteration
//! ([`SearchMethod::iterate`]) on the shared [`Context`], and what the executor does after it
//! ([`Step`], [`Control`]). The methods themselves are in [`crate::sm`].

use super::Context;
use crate::am::Capabilities;
use crate::imaging::ImageView;
use crate::observe::MethodVisual;
use crate::params::{MethodParams, ParamDef};
use crate::spec::TrackerParams;
use crate::status::LossReason;

/// What the executor does after an iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// The executor's stop test decides (the corners moved less than `eps`).
    Auto,
    /// The method has finished this frame (one-shot methods such as NN, the last stage of a
    /// cascade).
    Done,
    /// Go on even if the corners did not move (a cascade moving to its next stage).
    Continue,
}

/// The result of one iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// The similarity before the step (at the parameters the iteration started from).
    pub similarity: f64,
    pub control: Control,
}

impl Step {
    /// A step left to the executor's stop test.
    pub fn auto(similarity: f64) -> Self {
        Step {
            similarity,
            control: Control::Auto,
        }
    }
    /// The last step of the frame.
    pub fn done(similarity: f64) -> Self {
        Step {
            similarity,
            control: Control::Done,
        }
    }
}

/// One search method. Object-safe; its per-pixel loops are concrete.
pub trait SearchMethod: Send + std::fmt::Debug {
    /// The canonical name (the registry name, or a composite's `cascade:a+b`).
    fn name(&self) -> &str;
    /// AM capabilities the method needs.
    fn requires(&self) -> Capabilities {
        Capabilities {
            derivatives: true,
            distance: false,
        }
    }
    /// Whether coarser pyramid levels widen the method's basin (tracker parameter
    /// `pyramid_levels`): so for the methods that descend a gradient; not for the sampling
    /// methods (they search the spread of their own samples) nor for the grid methods (their
    /// patches do).
    fn pyramid(&self) -> bool {
        self.requires().derivatives
    }
    /// Called once the template is set in `ctx` (values and gradients sampled) with the
    /// (pre-processed) initialisation frame, which sampling methods draw warped patches from.
    fn initialize(&mut self, _ctx: &mut Context, _img: &ImageView) -> Result<(), LossReason> {
        Ok(())
    }
    /// Whether the executor's line search (tracker parameter `line_search`) applies: the
    /// method's iteration is a Newton step from where it started, which a shorter step along
    /// the same direction may improve on (the Lucas-Kanade methods).
    fn line_search(&self) -> bool {
        false
    }
    /// Whether the method linearises with the template's gradients (ICLK, IALK, ESM in part),
    /// so that its fixed point is the AM's optimum only where the frame looks like the
    /// template: the plan then polishes its result (tracker parameter `polish`).
    fn template_linearised(&self) -> bool {
        false
    }
    /// Whether every patch the method samples in a frame is at `ctx.params` as the executor sees
    /// it, before or after an iteration (or at parameters it had before in the frame): the
    /// frame source then smooths the frame only around them (see `crate::registration::Reader::Part`). Not for
    /// methods that sample candidates elsewhere (NN's samples, PF's particles).
    fn local(&self) -> bool {
        false
    }
    /// Whether the method works with a non-rigid SSM ([`crate::ssm::Ssm::projective`] false):
    /// it reads the warp only through the problem's grid warp, point Jacobians, `dw/dp` and the
    /// SSM's updates (the gradient methods), not through a matrix, nor by drawing random warps
    /// (the sampling and grid methods, which fit four corners and so could not move a control
    /// point inside the target).
    fn non_rigid(&self) -> bool {
        false
    }
    /// A new frame starts from `ctx.params`.
    fn start_frame(&mut self, _ctx: &mut Context) {}
    /// The AM's model was just updated ([`crate::am::Am::update_model`]): refresh what was computed from it
    /// (ICLK's constant Hessian).
    fn model_updated(&mut self, _ctx: &mut Context) {}
    /// One iteration on `img`: updates `ctx.params`.
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason>;
    /// How many iterations a frame may take, given the tracker's `max_iters` (a cascade gives
    /// each of its stages that many).
    fn max_iterations(&self, max_iters: usize) -> usize {
        max_iters
    }
    /// What the method shows of its state after the last iteration (asked only when an
    /// observer wants it).
    fn visual(&mut self, _ctx: &Context) -> Option<MethodVisual<'_>> {
        None
    }
}

/// What a search method is built from: its own parameters (validated against its
/// [`crate::sm::SmDef::params`]) and the tracker's.
#[derive(Clone, Copy, Debug)]
pub struct SmConfig<'a> {
    pub method: &'a MethodParams,
    pub tracker: &'a TrackerParams,
}

impl SmConfig<'_> {
    /// The value of one of the method's parameters.
    pub fn get(&self, def: &ParamDef) -> f64 {
        self.method.get(def)
    }
}
