//! The metrics the planar-tracking benchmarks publish, beside the paper's SR(t):
//!
//! - **precision P@t** (POT, PlanarTrack): the fraction of scored frames whose alignment error,
//!   in these benchmarks the root mean square of the four corner distances
//!   `sqrt(1/4 sum |x_i - x*_i|^2)`, is at most t px; the curve over t = 0..20 px, P@5 and
//!   P@15 the figures papers quote;
//! - **success by homography discrepancy** (POT's second metric, PlanarTrack's success plot):
//!   `1/4 sum |c_i - pi(H* H^-1 c_i)|` over the corners `c_i = (+-1, +-1)`, where `H` takes the
//!   first frame's target to the tracker's corners and `H*` to the ground truth (the
//!   benchmark's own homography where it gives one); the curve over 0..200 in steps of 10, and
//!   its mean (the area under it);
//! - **success by IoU** (OTB, LaSOT, GOT-10k): the fraction of frames whose IoU with the
//!   ground truth is above t, t = 0..1 in steps of 0.05, and its mean.
//!
//! A lost frame never counts as a success; the initialisation frames and the frames without
//! ground truth (not annotated, flagged) are not scored.

use super::{FrameRecord, RunResult};
use crate::geometry::{Point, Quad, apply_homography, homography_between};
use nalgebra::Matrix3;

/// Thresholds of the precision curve: 0, 1, ..., 20 px.
pub const PRECISION_MAX: usize = 20;
/// Thresholds of the homography-discrepancy success curve: 0, 10, ..., 200.
pub const DISCREPANCY_STEP: f64 = 10.0;
pub const DISCREPANCY_MAX: f64 = 200.0;
/// Thresholds of the IoU success curve: 0, 0.05, ..., 1.
pub const IOU_STEP: f64 = 0.05;

/// The benchmarks' alignment error: the root mean square of the four corner distances.
pub fn rms_corner_error(a: &Quad, b: &Quad) -> f64 {
    let s: f64 =
        a.0.iter()
            .zip(b.0.iter())
            .map(|(p, q)| (p.x - q.x).powi(2) + (p.y - q.y).powi(2))
            .sum();
    (s / 4.0).sqrt()
}

/// The homography discrepancy of a tracker's homography `h` (the first frame to this one)
/// against the ground truth's `h_gt`: the mean distance of the corners `(+-1, +-1)` from their
/// image by `h_gt h^-1`. Infinite when `h` cannot be inverted.
pub fn homography_discrepancy(h: &Matrix3<f64>, h_gt: &Matrix3<f64>) -> f64 {
    let Some(inv) = h.try_inverse() else {
        return f64::INFINITY;
    };
    let m = h_gt * inv;
    let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    let e = corners
        .iter()
        .map(|&(x, y)| {
            let c = Point::new(x, y);
            c.dist(apply_homography(&m, c))
        })
        .sum::<f64>()
        / 4.0;
    if e.is_finite() { e } else { f64::INFINITY }
}

/// The homography discrepancy of a frame: the tracker's `corners` and the ground truth `gt`
/// mapped from the `reference` (the first frame's target); `gt_h`, the benchmark's own
/// homography, is used for the ground truth when given. Infinite without corners.
pub fn frame_discrepancy(
    reference: &Quad,
    corners: Option<&Quad>,
    gt: &Quad,
    gt_h: Option<&Matrix3<f64>>,
) -> f64 {
    let Some(q) = corners else {
        return f64::INFINITY;
    };
    let Some(h) = homography_between(reference, q) else {
        return f64::INFINITY;
    };
    let h_gt = match gt_h {
        Some(h) => *h,
        None => match homography_between(reference, gt) {
            Some(h) => h,
            None => return f64::INFINITY,
        },
    };
    homography_discrepancy(&h, &h_gt)
}

/// The scored frames of runs: not initialisations, with ground truth.
fn scored<'a>(runs: &'a [&'a RunResult]) -> impl Iterator<Item = &'a FrameRecord> + 'a {
    runs.iter()
        .flat_map(|r| r.frames.iter())
        .filter(|f| !f.init && f.ground_truth.is_some())
}

/// The RMS corner errors of the scored frames (infinite when lost).
pub fn precision_errors(runs: &[&RunResult]) -> Vec<f64> {
    scored(runs)
        .map(|f| match (&f.corners, &f.ground_truth) {
            (Some(q), Some(g)) => rms_corner_error(q, g),
            _ => f64::INFINITY,
        })
        .collect()
}

/// The fraction of `errors` at most `t` (`NaN` without errors).
pub fn fraction_within(errors: &[f64], t: f64) -> f64 {
    if errors.is_empty() {
        return f64::NAN;
    }
    errors.iter().filter(|&&e| e <= t).count() as f64 / errors.len() as f64
}

/// The precision curve `(t, P@t)`, t = 0..20 px.
pub fn precision_curve(errors: &[f64]) -> Vec<(f64, f64)> {
    (0..=PRECISION_MAX)
        .map(|t| (t as f64, fraction_within(errors, t as f64)))
        .collect()
}

/// The homography discrepancies of the scored frames, `None` when a run was made before they
/// were recorded.
pub fn discrepancies(runs: &[&RunResult]) -> Option<Vec<f64>> {
    if runs.iter().any(|r| !r.discrepancy) {
        return None;
    }
    Some(scored(runs).map(|f| f.homography_error).collect())
}

/// The success curve by homography discrepancy, t = 0, 10, ..., 200.
pub fn discrepancy_curve(errors: &[f64]) -> Vec<(f64, f64)> {
    let n = (DISCREPANCY_MAX / DISCREPANCY_STEP).round() as usize;
    (0..=n)
        .map(|k| {
            let t = k as f64 * DISCREPANCY_STEP;
            (t, fraction_within(errors, t))
        })
        .collect()
}

/// The IoU of the scored frames (0 when lost).
pub fn ious(runs: &[&RunResult]) -> Vec<f64> {
    scored(runs)
        .map(|f| {
            if f.corners.is_some() {
                1.0 - f.iou_error
            } else {
                0.0
            }
        })
        .collect()
}

/// The success curve by IoU `(t, fraction of IoU > t)`, t = 0..1 in steps of 0.05.
pub fn iou_curve(ious: &[f64]) -> Vec<(f64, f64)> {
    let n = (1.0 / IOU_STEP).round() as usize;
    (0..=n)
        .map(|k| {
            let t = k as f64 * IOU_STEP;
            let frac = if ious.is_empty() {
                f64::NAN
            } else {
                ious.iter().filter(|&&o| o > t).count() as f64 / ious.len() as f64
            };
            (t, frac)
        })
        .collect()
}

/// The mean of a curve's values (the area under it, normalised).
pub fn area(curve: &[(f64, f64)]) -> f64 {
    if curve.is_empty() {
        return f64::NAN;
    }
    curve.iter().map(|p| p.1).sum::<f64>() / curve.len() as f64
}

/// The benchmark figures of runs pooled: P@5, P@15, the success by homography discrepancy and
/// by IoU (means of their curves).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Figures {
    pub p5: f64,
    pub p15: f64,
    pub success_h: f64,
    pub success_iou: f64,
}

/// [`Figures`] of runs (pooled over their frames).
pub fn figures(runs: &[&RunResult]) -> Figures {
    let e = precision_errors(runs);
    Figures {
        p5: fraction_within(&e, 5.0),
        p15: fraction_within(&e, 15.0),
        success_h: discrepancies(runs).map_or(f64::NAN, |d| area(&discrepancy_curve(&d))),
        success_iou: area(&iou_curve(&ious(runs))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn discrepancy_is_zero_on_the_truth_and_grows_with_the_error() {
        let reference = Quad::from_rect(100.0, 100.0, 50.0, 40.0);
        let gt = Quad::from_array([110.0, 95.0, 162.0, 101.0, 158.0, 146.0, 104.0, 139.0]);
        assert!(frame_discrepancy(&reference, Some(&gt), &gt, None) < 1e-9);
        let off = gt.map(|p| Point::new(p.x + 3.0, p.y));
        let d = frame_discrepancy(&reference, Some(&off), &gt, None);
        // A shift of the image by 3 px moves the corners (+-1, +-1) by 3 px.
        assert!((d - 3.0).abs() < 1e-6, "{d}");
        assert_eq!(
            frame_discrepancy(&reference, None, &gt, None),
            f64::INFINITY
        );
        // The benchmark's own homography is used for the ground truth when given.
        let h = homography_between(&reference, &gt).unwrap();
        assert!(frame_discrepancy(&reference, Some(&gt), &gt, Some(&h)) < 1e-9);
    }

    #[test]
    fn rms_weighs_the_worst_corner_more_than_the_mean() {
        let a = Quad::from_rect(0.0, 0.0, 10.0, 10.0);
        let mut b = a;
        b.0[0].x += 4.0;
        assert!((rms_corner_error(&a, &b) - 2.0).abs() < 1e-12);
        assert!((crate::geometry::alignment_error(&a, &b) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn curves_count_lost_frames_as_failures() {
        let e = [0.0, 4.0, 6.0, f64::INFINITY];
        assert_eq!(fraction_within(&e, 5.0), 0.5);
        let c = precision_curve(&e);
        assert_eq!(c.len(), 21);
        assert_eq!(c[20].1, 0.75);
        let o = iou_curve(&[1.0, 0.5, 0.0]);
        assert_eq!(o[0].1, 2.0 / 3.0);
        assert_eq!(o[20].1, 0.0);
        assert!(fraction_within(&[], 5.0).is_nan());
    }
}
