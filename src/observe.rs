//! The per-iteration observer: the tracker's executor reports every iteration to it. The
//! inspector's convergence plot and step-through view are built on [`Recorder`]; benchmarks use
//! [`NoObserver`].

use crate::geometry::{Point, Quad};
use crate::status::FrameOutcome;
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// What a method shows of its state: a sampling method's candidates (NN's samples, PF's
/// particles) as the target's quad under each candidate warp, in frame pixels, with their
/// weights; a whole tracker's detections (quads), keypoints (points) and response map.
#[derive(Clone, Copy, Debug)]
pub struct MethodVisual<'a> {
    /// What the quads are ("samples", "particles", "detections").
    pub label: &'static str,
    pub quads: &'a [Quad],
    /// One weight per quad in `0..=1` (the best is 1).
    pub weights: &'a [f32],
    /// The candidate the method chose, if any.
    pub chosen: Option<usize>,
    /// Points (keypoints, flow points) with a weight each in `0..=1` (`points.len()` weights).
    pub points: &'a [Point],
    pub point_weights: &'a [f32],
    /// A map over a region of the frame (a correlation filter's response).
    pub map: Option<ResponseMap<'a>>,
}

impl<'a> MethodVisual<'a> {
    /// Quads and their weights only.
    pub fn quads(
        label: &'static str,
        quads: &'a [Quad],
        weights: &'a [f32],
        chosen: Option<usize>,
    ) -> Self {
        MethodVisual {
            label,
            quads,
            weights,
            chosen,
            points: &[],
            point_weights: &[],
            map: None,
        }
    }
}

/// The label of the visual a registration tracker that reads part of its grid shows: the points
/// it reads ([`crate::registration::spi`]).
pub const SELECTED_PIXELS: &str = "selected pixels";

/// A `width x height` map (row-major) laid over the quad `at` of the frame: value `(0, 0)` at its
/// first corner, rows along its first side.
#[derive(Clone, Copy, Debug)]
pub struct ResponseMap<'a> {
    pub width: usize,
    pub height: usize,
    pub values: &'a [f32],
    pub at: Quad,
}

/// One iteration of a search method on one frame.
#[derive(Clone, Copy, Debug)]
pub struct Iteration<'a> {
    /// Frame index (0 is the initialisation frame).
    pub frame: usize,
    /// Pyramid level (0 = full resolution).
    pub level: usize,
    /// Iteration index within the frame (over all levels), from 0.
    pub iteration: usize,
    /// The SSM parameters after the iteration (normalised frame; `dof` entries).
    pub params: &'a [f64],
    /// The corners after the iteration (image coordinates).
    pub corners: Quad,
    /// The similarity `f` before the iteration's step.
    pub similarity: f64,
    /// The L2 norm of the change of the corners made by this iteration (pixels).
    pub step: f64,
    /// Time since the frame's update started.
    pub elapsed: Duration,
    /// The time this iteration took: the search method's step and the executor's bookkeeping of
    /// it (the line search, the stop test), not the observer's own work.
    pub duration: Duration,
    /// The patch sampled at the parameters after the iteration (pre-processed frame, `res x res`),
    /// when the observer asked for it ([`Observer::wants_patches`]).
    pub patch: Option<&'a [f32]>,
}

/// Sees every iteration.
pub trait Observer {
    /// A frame starts from `corners`.
    fn frame_started(&mut self, _frame: usize, _corners: &Quad) {}
    /// An iteration finished.
    fn iteration(&mut self, it: &Iteration<'_>);
    /// The frame finished.
    fn frame_finished(&mut self, _frame: usize, _outcome: &FrameOutcome) {}
    /// Whether [`Observer::method_visual`] should be called (drawing a sampling method's state
    /// costs time, so only observers that show it ask).
    fn wants_method_visuals(&self) -> bool {
        false
    }
    /// Whether [`Iteration::patch`] should be sampled (one more warp and sampling per iteration,
    /// so only observers that show it ask).
    fn wants_patches(&self) -> bool {
        false
    }
    /// What a sampling method shows after iteration `iteration` (NN's samples, PF's particles).
    fn method_visual(&mut self, _frame: usize, _iteration: usize, _visual: &MethodVisual<'_>) {}
}

/// Ignores everything (for benchmarks and batch runs).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoObserver;

impl Observer for NoObserver {
    #[inline]
    fn iteration(&mut self, _it: &Iteration<'_>) {}
}

/// An owned copy of an [`Iteration`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationRecord {
    pub frame: usize,
    pub level: usize,
    pub iteration: usize,
    pub params: Vec<f64>,
    pub corners: Quad,
    pub similarity: f64,
    pub step: f64,
    pub elapsed_us: f64,
    /// The patch after the iteration, as 8-bit (empty when not recorded).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub patch: Vec<u8>,
}

/// An owned copy of a [`MethodVisual`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VisualRecord {
    pub iteration: usize,
    pub label: String,
    pub quads: Vec<Quad>,
    pub weights: Vec<f32>,
    pub chosen: Option<usize>,
    pub points: Vec<crate::geometry::Point>,
    pub point_weights: Vec<f32>,
    pub map: Option<MapRecord>,
}

/// An owned copy of a [`ResponseMap`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapRecord {
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
    pub at: Quad,
}

/// Keeps the iterations of the last frame (and the frame's starting corners), for the
/// convergence plot and the step-through view; with `visuals` set, also what sampling methods
/// show at each iteration.
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    pub frame: usize,
    pub start: Option<Quad>,
    pub iterations: Vec<IterationRecord>,
    /// Whether to keep method visuals.
    pub visuals: bool,
    /// Whether to keep each iteration's patch.
    pub patches: bool,
    pub method_visuals: Vec<VisualRecord>,
}

impl Observer for Recorder {
    fn frame_started(&mut self, frame: usize, corners: &Quad) {
        self.frame = frame;
        self.start = Some(*corners);
        self.iterations.clear();
        self.method_visuals.clear();
    }
    fn iteration(&mut self, it: &Iteration<'_>) {
        self.iterations.push(IterationRecord {
            frame: it.frame,
            level: it.level,
            iteration: it.iteration,
            params: it.params.to_vec(),
            corners: it.corners,
            similarity: it.similarity,
            step: it.step,
            elapsed_us: it.elapsed.as_secs_f64() * 1e6,
            patch: it
                .patch
                .map(|p| {
                    p.iter()
                        .map(|&v| v.round().clamp(0.0, 255.0) as u8)
                        .collect()
                })
                .unwrap_or_default(),
        });
    }
    fn wants_patches(&self) -> bool {
        self.patches
    }
    fn wants_method_visuals(&self) -> bool {
        self.visuals
    }
    fn method_visual(&mut self, _frame: usize, iteration: usize, v: &MethodVisual<'_>) {
        self.method_visuals.push(VisualRecord {
            iteration,
            label: v.label.to_string(),
            quads: v.quads.to_vec(),
            weights: v.weights.to_vec(),
            chosen: v.chosen,
            points: v.points.to_vec(),
            point_weights: v.point_weights.to_vec(),
            map: v.map.map(|m| MapRecord {
                width: m.width,
                height: m.height,
                values: m.values.to_vec(),
                at: m.at,
            }),
        });
    }
}

/// Counts iterations (for benchmarks: iterations per frame without recording them).
#[derive(Clone, Copy, Debug, Default)]
pub struct IterationCounter {
    pub iterations: u64,
    pub frames: u64,
    /// The iterations' summed [`Iteration::duration`].
    pub busy: Duration,
}

impl Observer for IterationCounter {
    fn frame_started(&mut self, _frame: usize, _corners: &Quad) {
        self.frames += 1;
    }
    #[inline]
    fn iteration(&mut self, it: &Iteration<'_>) {
        self.iterations += 1;
        self.busy += it.duration;
    }
}
