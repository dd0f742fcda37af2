//! The cost landscape: a registration tracker's similarity `f` swept along one or two of its
//! SSM's parameters around a warp, with the analytic gradient (the AM's gradient through the
//! pixel Jacobian, as FALK computes it) beside the numeric one. It shows why a search method
//! converges or not, and a wrong derivative at a glance.
//!
//! Units: an offset `u` along parameter `k` is in pixels of mean corner motion: the parameters
//! are `p0 + u delta_k e_k`, with `delta_k` the change of `p_k` that moves the corners by 1 px on
//! average at `p0` (so that the axes of every parameter compare).

use crate::ssm::Params;
use serde::{Deserialize, Serialize};

/// What to sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LandscapeSpec {
    /// One parameter index (a curve) or two (a map).
    pub axes: Vec<usize>,
    /// The sweep spans `-radius..radius` px of mean corner motion along each axis.
    pub radius: f64,
    /// Samples per axis (odd, so that the centre is sampled).
    pub steps: usize,
}

impl Default for LandscapeSpec {
    fn default() -> Self {
        LandscapeSpec {
            axes: vec![0],
            radius: 5.0,
            steps: 41,
        }
    }
}

/// A swept similarity.
#[derive(Clone, Debug, PartialEq)]
pub struct Landscape {
    pub axes: Vec<usize>,
    /// Per axis, the parameter change per px of mean corner motion.
    pub deltas: Vec<f64>,
    /// The sample offsets along each axis (px), `-radius..=radius`.
    pub offsets: Vec<f64>,
    /// `f` at each sample: along the axis, or row by row (second axis outer, first inner).
    pub values: Vec<f64>,
    /// The parameters at the centre (normalised frame) and `f` there.
    pub center: Params,
    pub center_value: f64,
    /// Per axis, `df/du` at the centre: from the AM's analytic gradient, and by central
    /// differences of `f` over +-0.01 px (`u` in px). They differ by up to about a tenth of
    /// the gradient's size on a lightly smoothed frame, without either being wrong: the
    /// analytic slope is made of image gradients by central differences (what every gradient
    /// search method uses, a smoothed derivative), the numeric one is the slope of the
    /// bilinearly interpolated frame; the gap narrows as the frame is smoothed (the AM's own
    /// derivatives pass finite-difference tests in `am/tests.rs`).
    pub analytic: Vec<f64>,
    pub numeric: Vec<f64>,
}

impl Landscape {
    /// The offsets (px, per axis) of parameters `p` from the centre along the swept axes.
    pub fn offsets_of(&self, p: &[f64]) -> Vec<f64> {
        self.axes
            .iter()
            .zip(&self.deltas)
            .map(|(&k, &d)| {
                let v = p.get(k).copied().unwrap_or(0.0);
                if d != 0.0 {
                    (v - self.center[k]) / d
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Per axis, the mean slope of `f` between the centre and the samples nearest ±1 px
    /// (`|f(±1) - f(0)|`, per px): the scale the slopes at the centre compare with. At an
    /// optimum the slopes at the centre are near zero next to it, and what is left of them
    /// (the analytic and the numeric may then differ even in sign) is noise.
    pub fn slope_scale(&self) -> Vec<f64> {
        let n = self.offsets.len();
        if n < 3 {
            return vec![f64::NAN; self.axes.len()];
        }
        let mid = n / 2;
        let step = self.offsets[1] - self.offsets[0];
        let k = ((1.0 / step).round() as usize).clamp(1, mid);
        let at = |col: usize, row: usize| match self.axes.len() {
            1 => self.values[col],
            _ => self.values[row * n + col],
        };
        let slope = |a: f64, b: f64| {
            ((a - self.center_value).abs() + (b - self.center_value).abs())
                / (2.0 * k as f64 * step)
        };
        (0..self.axes.len())
            .map(|axis| match axis {
                0 => slope(at(mid - k, mid), at(mid + k, mid)),
                _ => slope(at(mid, mid - k), at(mid, mid + k)),
            })
            .collect()
    }

    /// The sample with the highest similarity: its offsets (px).
    pub fn best(&self) -> Vec<f64> {
        let Some((i, _)) = self
            .values
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .max_by(|a, b| a.1.total_cmp(b.1))
        else {
            return vec![0.0; self.axes.len()];
        };
        let n = self.offsets.len();
        match self.axes.len() {
            1 => vec![self.offsets[i]],
            _ => vec![self.offsets[i % n], self.offsets[i / n]],
        }
    }
}
