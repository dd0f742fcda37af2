//! The frequency of convergence (Baker and Matthews' experiment, the paper's Fig. "success
//! rate" of the search methods): a tracker initialised on a frame at its ground truth is started
//! again and again on that same frame from the ground truth's corners moved by Gaussian noise
//! of standard deviation `sigma` px (each coordinate independently, seeded), and converges when
//! its search ends within `threshold` px (alignment error) of the ground truth. The fraction of
//! starts that converge, per `sigma`, is the curve: how wide a tracker's basin is.

use crate::error::{Error, Result};
use crate::geometry::{Point, Quad, alignment_error};
use crate::observe::NoObserver;
use crate::rng::Rng;
use crate::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};

/// What to run.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvergeSpec {
    /// The noise levels (px).
    pub sigmas: Vec<f64>,
    /// Starts per noise level.
    pub starts: usize,
    /// A start converged when the search ends this close (px) to the ground truth.
    pub threshold: f64,
    pub seed: u64,
}

impl Default for ConvergeSpec {
    fn default() -> Self {
        ConvergeSpec {
            sigmas: (1..=10).map(f64::from).collect(),
            starts: 100,
            threshold: 1.0,
            seed: 0,
        }
    }
}

/// One tracker's curve.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvergeCurve {
    pub tracker: String,
    /// Per noise level: `(sigma, fraction converged, mean final error of the converged px)`.
    pub points: Vec<(f64, f64, f64)>,
}

impl ConvergeCurve {
    /// The mean fraction over the noise levels (the curve's area, normalised).
    pub fn mean(&self) -> f64 {
        self.points.iter().map(|p| p.1).sum::<f64>() / self.points.len().max(1) as f64
    }
}

/// The starting corners of start `k` at noise level `sigma` (the same for every tracker: the
/// generator is seeded per level and start).
pub fn perturbed(truth: &Quad, sigma: f64, seed: u64, k: usize) -> Quad {
    let mut rng = Rng::new(
        seed ^ (sigma.to_bits().rotate_left(17)) ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
    );
    let mut q = *truth;
    for p in &mut q.0 {
        *p = Point::new(p.x + sigma * rng.normal(), p.y + sigma * rng.normal());
    }
    q
}

/// Runs the experiment for `spec` on `frame` with ground truth `truth`.
pub fn frequency_of_convergence(
    spec: &TrackerSpec,
    frame: &crate::imaging::Frame8,
    truth: &Quad,
    c: &ConvergeSpec,
) -> Result<ConvergeCurve> {
    if c.starts == 0 || c.sigmas.is_empty() || c.sigmas.iter().any(|s| !s.is_finite() || *s < 0.0) {
        return Err(Error::InvalidParameter(
            "the convergence experiment needs starts >= 1 and noise levels >= 0".into(),
        ));
    }
    let mut points = Vec::with_capacity(c.sigmas.len());
    for &sigma in &c.sigmas {
        let (mut converged, mut err_sum) = (0usize, 0.0);
        for k in 0..c.starts {
            // A fresh tracker per start: nothing of one start's history reaches the next.
            let mut t = Tracker::new(spec)?;
            t.initialize(FrameInput::of(frame), truth)?;
            let start = perturbed(truth, sigma, c.seed, k);
            if t.set_corners(&start).is_err() {
                // A start the tracker cannot take (folded corners) counts as not converged.
                continue;
            }
            let out = t.update(FrameInput::of(frame), &mut NoObserver);
            let e = alignment_error(&out.corners, truth);
            if out.status == TrackStatus::Tracking && e <= c.threshold {
                converged += 1;
                err_sum += e;
            }
        }
        points.push((
            sigma,
            converged as f64 / c.starts as f64,
            if converged > 0 {
                err_sum / converged as f64
            } else {
                f64::NAN
            },
        ));
    }
    Ok(ConvergeCurve {
        tracker: spec.label(),
        points,
    })
}

/// Writes `convergence.csv` (tracker, sigma, fraction converged, mean error of the converged)
/// and the figure `convergence.svg` and `.png` into `out`; returns the files written.
pub fn write_results(
    out: &std::path::Path,
    curves: &[ConvergeCurve],
    c: &ConvergeSpec,
    title: &str,
) -> Result<Vec<std::path::PathBuf>> {
    use crate::report::{Axes, Curve, Figure, FigureKind, draw_curve_figure};
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let mut csv = String::from("tracker,sigma,converged,mean_error\n");
    for curve in curves {
        for (s, f, e) in &curve.points {
            csv.push_str(&format!("{},{s},{f:.4},{e:.4}\n", curve.tracker));
        }
    }
    let csv_path = out.join("convergence.csv");
    crate::dataset::write_atomic(&csv_path, csv.as_bytes())?;
    let mut sorted: Vec<&ConvergeCurve> = curves.iter().collect();
    sorted.sort_by(|a, b| b.mean().total_cmp(&a.mean()));
    let figure = Figure {
        kind: FigureKind::Others,
        stem: "convergence".into(),
        title: title.to_string(),
        curves: sorted
            .iter()
            .map(|k| Curve {
                name: k.tracker.clone(),
                tracker: k.tracker.clone(),
                mean_sr: k.mean(),
                points: k.points.iter().map(|p| (p.0, p.1)).collect(),
                ..Default::default()
            })
            .collect(),
    };
    let axes = Axes {
        x_desc: "initial perturbation sigma (px)".into(),
        y_desc: format!("fraction converged (within {} px)", c.threshold),
        x_range: (0.0, c.sigmas.iter().copied().fold(1.0, f64::max)),
        y_range: (0.0, 1.02),
        legend_header: "mean".into(),
    };
    let mut files = vec![csv_path];
    for ext in ["svg", "png"] {
        let p = out.join(format!("convergence.{ext}"));
        draw_curve_figure(&p, &figure, &axes, (900, 560))?;
        files.push(p);
    }
    Ok(files)
}
