//! The registration tracker, `p_t = argmax_p f(I*, I_t(w(x, p)))`: the problem one tracker
//! solves ([`Context`]: models, grid, template, buffers, and the objective at a warp), the
//! interface of a search method ([`SearchMethod`]: one iteration at a time), the driver that owns
//! the loop ([`RegistrationTracker`]) and the cost-landscape sweep.
//!
//! Imports go downwards: this module uses the AM, SSM, imaging, observer and spec layers; the
//! search methods ([`crate::sm`]) implement its interface; the factory ([`crate::tracker`])
//! builds the stages from the registries and hands them to the driver.

mod confidence;
mod context;
mod driver;
mod method;
pub mod moments;
mod sweep;

pub use confidence::{Judged, LossCheck};
pub use context::{Context, Update, Workspace, warp_points};
pub use driver::{HIERARCHY, MIN_LEVEL_RES, RegistrationTracker, Stage, level_res};
pub use method::{Control, SearchMethod, SmConfig, Step};
