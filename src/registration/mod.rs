//! The registration problem, `p_t = argmax_p f(I*, I_t(w(x, p)))`, and its executor: what one
//! tracker solves at one level ([`Problem`]: models, grid, template), where its search is
//! ([`State`]: parameters, last step), the buffers of an iteration with their own cache
//! ([`Workspace`]), the three together as a search method sees them ([`Context`]), the
//! interface of a search method ([`SearchMethod`]: one iteration at a time), the loop that runs
//! one ([`Executor`]: the stop test, the line search, the observer), where a frame is read
//! from ([`FrameSource`]: pre-processing, partial smoothing, pyramid levels), and the
//! confidence a frame's end is judged by ([`LossCheck`]).
//!
//! Imports go downwards: this module uses the AM, SSM, imaging, observer and spec layers; the
//! search methods ([`crate::sm`]) implement its interface and hold their Newton steps; the plan
//! of stages a tracker runs per frame ([`crate::plan`]) drives the executor.

mod block_correlation;
mod confidence;
mod context;
mod executor;
mod line_search;
mod method;
pub mod moments;
mod problem;
mod source;
pub mod spi;
mod state;
mod workspace;

pub use block_correlation::{BlockCorrelation, MAX_BLOCKS, PatchSums, block_correlation};
pub use confidence::{Judged, LossCheck, MIN_DOF};
pub use context::Context;
pub use executor::{Executor, Limits, Ran};
pub use line_search::LineSearch;
pub use method::{Control, SearchMethod, SmConfig, Step};
pub use problem::Problem;
pub use source::{FrameSource, Reader, reads, region_around};
pub use state::{State, Update};
pub use workspace::{NewtonParts, Workspace, warp_points};

use std::cmp::Ordering;

/// `a >= b`, false when either is NaN.
pub fn at_least(a: f64, b: f64) -> bool {
    matches!(a.partial_cmp(&b), Some(Ordering::Greater | Ordering::Equal))
}
