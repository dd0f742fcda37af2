//! Many patches per frame: the paper's case for registration trackers in robotics ("tracking
//! based SLAM systems like SVO ... track hundreds to thousands of patches per frame").
//!
//! A [`PatchTracker`] follows N small patches (a square grid of `size` x `size` samples each),
//! every one with its own warp, translation or affine ([`PatchWarp`]), by inverse-compositional
//! Lucas-Kanade (Baker and Matthews) over one pre-processed frame shared by all: one smoothing,
//! one Gaussian pyramid, built once per frame (in bands of rows, by the threads). Patches are
//! independent, so they are tracked in parallel over the cores (a [`crate::crew::Crew`]: each thread takes
//! blocks of neighbouring patches and works in its own scratch, so a patch's template, made
//! again each frame, never leaves that core's cache) and give the same result, bit for bit, on
//! any number of threads.
//!
//! The template of a patch is the previous frame's patch (`template=previous`, as KLT does:
//! no appearance drift, a slow positional one) or the first frame's (`template=first`: no
//! positional drift; with an affine warp it follows rotation, scale and shear). Each frame a
//! patch reports a [`crate::status::TrackStatus`]: it is lost when it leaves the frame, when its window is flat
//! (`min_eigen`), when its values stop being finite, when its affine shape degenerates, when
//! the tracked patch no longer looks like its template (`min_ncc`), or, with `fb_max`, when
//! tracking it back to the previous frame misses its start by more than `fb_max` pixels (the
//! forward-backward error of Kalal et al.). A lost patch keeps its last good position and is
//! not searched again.
//!
//! One frame, per patch and pyramid level (coarse to fine): the template's values `T(u)` and
//! their gradients in patch coordinates give the steepest-descent images `SD = grad T * dW/dp`
//! and the Hessian `H = SD^T SD` (once per template); each iteration samples the frame at the
//! warped grid `I(W(u))`, solves `dp = H^-1 SD^T (I(W(u)) - T(u))` and composes the inverse of
//! the increment, `W <- W o W(dp)^-1`, until the patch's corners move less than `eps` pixels
//! (of that level). A translation warp samples a grid that only shifts, whose bilinear weights
//! are the same for every sample ([`crate::imaging::sample_grid_shifted`]).

mod frame;
mod kernels;
mod params;
mod run;
mod search;
mod tracker;
mod tracks;

use frame::*;
pub use params::{
    PATCH_PARAMS, PatchParams, PatchState, PatchWarp, TEMPLATES, TemplateSource, WARPS,
};
pub use run::{
    PatchAccuracy, PatchRun, PatchSeeds, accuracy, read_points, track_sequence, track_sequence_from,
};
use search::*;
pub use tracker::PatchTracker;
use tracker::*;
pub use tracks::{TRACKS_HEADER, read_tracks, write_tracks};
