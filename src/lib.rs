//! # regtrack: modular registration-based visual trackers
//!
//! A registration-based tracker estimates, frame by frame, the warp of a template patch:
//!
//! ```text
//! p_t = argmax_p f(I*, I_t(w(x, p)))
//! ```
//!
//! Each symbol belongs to one module (Singh, Roy, Zhang and Jagersand, "Modular Decomposition and
//! Analysis of Registration based Trackers"):
//!
//! - [`ssm`], the **state space model**, owns the warp `w` and its parameters `p`;
//! - [`am`], the **appearance model**, owns the similarity `f` between the template `I*` and the
//!   warped patch of the current frame;
//! - [`sm`], the **search method**, owns the `argmax`: it combines the two by the chain rule and
//!   iterates.
//!
//! Any AM works with any SSM and any SM; a [`tracker::Tracker`] is built at run time from their
//! names through the registries ([`tracker::TrackerSpec`]). Every iteration is reported to an
//! [`observe::Observer`]. The [`imaging`] layer pre-processes only the region a tracker reads; the
//! [`dataset`] module reads sequences and ground truth and renders synthetic sequences; [`eval`]
//! measures alignment error, success rates and speed. (This example runs, on a rendered sequence,
//! in `tests/it/patches.rs`.)
//!
//! ```no_run
//! use regtrack::{dataset, tracker::{FrameInput, Tracker, TrackerSpec}, observe::NoObserver};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let seq = dataset::Sequence::open(std::path::Path::new("data/seq.txt"))?;
//! let spec = TrackerSpec::from_names("esm", "ssd", "homography")?;
//! let mut tracker = Tracker::new(&spec)?;
//! let first = seq.load_gray(0)?;
//! tracker.initialize(FrameInput::Gray8(&first), &seq.ground_truth(0).ok_or("no ground truth")?)?;
//! for i in 1..seq.len() {
//!     let frame = seq.load_gray(i)?;
//!     let outcome = tracker.update(FrameInput::Gray8(&frame), &mut NoObserver);
//!     println!("{i}: {:?} {:?}", outcome.status, outcome.corners);
//! }
//! # Ok(()) }
//! ```

pub mod am;
#[cfg(feature = "gui")]
pub mod app;
pub mod bench;
pub mod catalogue;
pub mod converge;
pub mod cpu;
pub mod crew;
pub mod dataset;
pub mod error;
pub mod eval;
pub mod files;
pub mod geometry;
pub mod gt;
pub mod imaging;
pub mod keys;
pub mod landscape;
pub mod linalg;
pub mod observe;
pub mod params;
pub mod patches;
pub mod plan;
#[cfg(feature = "python")]
pub mod python;
pub mod registration;
pub mod registry;
pub mod report;
pub mod rng;
pub mod session;
pub mod sm;
pub mod spec;
pub mod ssm;
pub mod status;
pub mod tracker;
pub mod visual_tracker;
pub mod whole;

pub use error::{Error, Result};
pub use geometry::{Point, Quad};
pub use tracker::{Tracker, TrackerSpec};
