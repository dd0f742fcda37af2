//! Robust fits of a homography to point matches, for the grid search methods: least squares
//! (the direct linear transform with `h33 = 1` on Hartley-normalised points, through its 8 x 8
//! normal equations), RANSAC (Fischler and Bolles: minimal samples of four matches, the model
//! with the most matches within a reprojection threshold, its sample count adapted to the inlier
//! ratio found) and least median of squares (Rousseeuw: the model of the smallest median squared
//! error, its inliers within 2.5 robust standard deviations). Each ends with a least-squares fit
//! to its inliers. Nothing here allocates: the buffers are the caller's.

use crate::geometry::Point;
use crate::rng::Rng;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// How a grid's matches are fitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Estimator {
    Ransac,
    LeastMedian,
    LeastSquares,
}

impl Estimator {
    /// The names of the `estimator` parameter's choices, in its order.
    pub const NAMES: [&'static str; 3] = ["ransac", "lmeds", "least_squares"];

    pub fn from_index(i: f64) -> Self {
        match i as usize {
            1 => Estimator::LeastMedian,
            2 => Estimator::LeastSquares,
            _ => Estimator::Ransac,
        }
    }
}

/// The RANSAC and LMedS settings.
#[derive(Clone, Copy, Debug)]
pub struct Robust {
    pub estimator: Estimator,
    /// RANSAC's inlier threshold (px of reprojection error).
    pub threshold: f64,
    /// The most minimal samples drawn.
    pub max_samples: usize,
    /// The probability that some sample is all inliers (RANSAC's and LMedS' sample counts).
    pub confidence: f64,
}

/// `h(p)`.
pub fn apply(h: &Matrix3<f64>, p: Point) -> Point {
    let v = h * Vector3::new(p.x, p.y, 1.0);
    Point::new(v.x / v.z, v.y / v.z)
}

/// The similarity taking `pts` (those in `mask`) to zero mean and mean distance `sqrt(2)`.
fn normaliser(pts: &[Point], mask: Option<&[bool]>) -> Option<Matrix3<f64>> {
    let kept = |i: usize| mask.is_none_or(|m| m[i]);
    let (mut n, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for (_, p) in pts.iter().enumerate().filter(|(i, _)| kept(*i)) {
        n += 1.0;
        cx += p.x;
        cy += p.y;
    }
    if n < 4.0 {
        return None;
    }
    let (cx, cy) = (cx / n, cy / n);
    let spread = pts
        .iter()
        .enumerate()
        .filter(|(i, _)| kept(*i))
        .map(|(_, p)| ((p.x - cx).powi(2) + (p.y - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    if spread.is_nan() || spread <= 1e-9 {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / spread;
    Some(Matrix3::new(
        s,
        0.0,
        -s * cx,
        0.0,
        s,
        -s * cy,
        0.0,
        0.0,
        1.0,
    ))
}

/// The least-squares homography taking `src[i]` to `dst[i]` for the `i` in `mask` (all without
/// one): `None` with fewer than four, or for a degenerate set.
pub fn fit_least_squares(
    src: &[Point],
    dst: &[Point],
    mask: Option<&[bool]>,
) -> Option<Matrix3<f64>> {
    let ts = normaliser(src, mask)?;
    let td = normaliser(dst, mask)?;
    let mut ata = SMatrix::<f64, 8, 8>::zeros();
    let mut atb = SVector::<f64, 8>::zeros();
    for i in (0..src.len()).filter(|&i| mask.is_none_or(|m| m[i])) {
        let (a, b) = (apply(&ts, src[i]), apply(&td, dst[i]));
        let (x, y, u, v) = (a.x, a.y, b.x, b.y);
        for (row, rhs) in [
            ([x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y], u),
            ([0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y], v),
        ] {
            let r = SVector::<f64, 8>::from(row);
            ata += r * r.transpose();
            atb += r * rhs;
        }
    }
    let h = ata.cholesky()?.solve(&atb);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0);
    let out = td.try_inverse()? * hn * ts;
    (out.iter().all(|v| v.is_finite()) && out[(2, 2)].abs() > 1e-12).then(|| out / out[(2, 2)])
}

/// The squared reprojection error of match `i` under `h`.
fn error2(h: &Matrix3<f64>, src: Point, dst: Point) -> f64 {
    let p = apply(h, src);
    let e = (p.x - dst.x).powi(2) + (p.y - dst.y).powi(2);
    if e.is_finite() { e } else { f64::INFINITY }
}

/// Four distinct indices below `n`, none three of them collinear in `src` (`None` after a few
/// draws that all were).
fn sample(rng: &mut Rng, src: &[Point], n: usize) -> Option<[usize; 4]> {
    'draw: for _ in 0..16 {
        let mut k = [0usize; 4];
        for j in 0..4 {
            loop {
                let c = ((rng.uniform() * n as f64) as usize).min(n - 1);
                if !k[..j].contains(&c) {
                    k[j] = c;
                    break;
                }
            }
        }
        for (a, b, c) in [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)] {
            let (p, q, r) = (src[k[a]], src[k[b]], src[k[c]]);
            let cross = (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x);
            if cross.abs() < 1e-6 {
                continue 'draw;
            }
        }
        return Some(k);
    }
    None
}

/// The homography of four matches.
fn minimal(src: &[Point], dst: &[Point], k: [usize; 4]) -> Option<Matrix3<f64>> {
    let s = k.map(|i| src[i]);
    let d = k.map(|i| dst[i]);
    fit_least_squares(&s, &d, None)
}

/// How many minimal samples make one all-inlier sample likely at `confidence`, with an inlier
/// ratio `w`.
fn samples_needed(confidence: f64, w: f64, most: usize) -> usize {
    let all = w.powi(4);
    if all >= 1.0 - 1e-12 {
        return 1;
    }
    if all <= 1e-12 {
        return most;
    }
    let n = (1.0 - confidence).ln() / (1.0 - all).ln();
    if n.is_finite() {
        (n.ceil() as usize).clamp(1, most)
    } else {
        most
    }
}

/// The robust fit of a homography to the matches `src[i] -> dst[i]`; `inliers` (as long as
/// `src`) receives which matches it kept, `errors` is scratch of the same length. `None` when
/// fewer than four matches support a model.
pub fn fit(
    src: &[Point],
    dst: &[Point],
    robust: &Robust,
    rng: &mut Rng,
    (inliers, errors): (&mut [bool], &mut [f64]),
) -> Option<Matrix3<f64>> {
    let n = src.len().min(dst.len());
    let (inliers, errors) = (&mut inliers[..n], &mut errors[..n]);
    if n < 4 {
        return None;
    }
    let h = match robust.estimator {
        Estimator::LeastSquares => {
            inliers.fill(true);
            fit_least_squares(src, dst, None)?
        }
        Estimator::Ransac => ransac(src, dst, robust, rng, inliers)?,
        Estimator::LeastMedian => least_median(src, dst, robust, rng, inliers, errors)?,
    };
    // The model refitted to its inliers, which are then those of the refit.
    let refit = fit_least_squares(src, dst, Some(inliers)).unwrap_or(h);
    if robust.estimator == Estimator::Ransac {
        let t2 = robust.threshold * robust.threshold;
        for i in 0..n {
            inliers[i] = error2(&refit, src[i], dst[i]) < t2;
        }
        if inliers.iter().filter(|&&k| k).count() < 4 {
            return None;
        }
    }
    Some(refit)
}

fn ransac(
    src: &[Point],
    dst: &[Point],
    robust: &Robust,
    rng: &mut Rng,
    best_inliers: &mut [bool],
) -> Option<Matrix3<f64>> {
    let n = best_inliers.len();
    let t2 = robust.threshold * robust.threshold;
    let (mut best, mut best_count) = (None, 0usize);
    let mut needed = robust.max_samples;
    let mut drawn = 0;
    while drawn < needed {
        drawn += 1;
        let Some(k) = sample(rng, src, n) else {
            break;
        };
        let Some(h) = minimal(src, dst, k) else {
            continue;
        };
        let count = (0..n).filter(|&i| error2(&h, src[i], dst[i]) < t2).count();
        if count > best_count {
            best_count = count;
            for (i, m) in best_inliers.iter_mut().enumerate() {
                *m = error2(&h, src[i], dst[i]) < t2;
            }
            best = Some(h);
            needed = samples_needed(
                robust.confidence,
                count as f64 / n as f64,
                robust.max_samples,
            );
        }
    }
    (best_count >= 4).then_some(best).flatten()
}

/// The share of outliers least median of squares is built to withstand (its sample count).
const LMEDS_OUTLIERS: f64 = 0.45;

fn least_median(
    src: &[Point],
    dst: &[Point],
    robust: &Robust,
    rng: &mut Rng,
    inliers: &mut [bool],
    errors: &mut [f64],
) -> Option<Matrix3<f64>> {
    let n = inliers.len();
    let draws = samples_needed(robust.confidence, 1.0 - LMEDS_OUTLIERS, robust.max_samples);
    let (mut best, mut best_median) = (None, f64::INFINITY);
    for _ in 0..draws {
        let Some(k) = sample(rng, src, n) else {
            break;
        };
        let Some(h) = minimal(src, dst, k) else {
            continue;
        };
        for i in 0..n {
            errors[i] = error2(&h, src[i], dst[i]);
        }
        let mid = n / 2;
        let (_, median, _) = errors.select_nth_unstable_by(mid, f64::total_cmp);
        if *median < best_median {
            best_median = *median;
            best = Some(h);
        }
    }
    let h = best?;
    // Rousseeuw's scale: 1.4826 (1 + 5 / (n - p)) sqrt(median), p = 4 matches a model.
    let sigma = 1.4826 * (1.0 + 5.0 / (n as f64 - 4.0).max(1.0)) * best_median.sqrt();
    let t2 = (2.5 * sigma).powi(2).max(1e-12);
    for i in 0..n {
        inliers[i] = error2(&h, src[i], dst[i]) <= t2;
    }
    (inliers.iter().filter(|&&k| k).count() >= 4).then_some(h)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A homography close to the ones between frames: a small rotation, scale, shear and a
    /// little perspective.
    fn truth() -> Matrix3<f64> {
        Matrix3::new(1.02, -0.05, 6.0, 0.04, 0.97, -3.0, 1e-4, -2e-4, 1.0)
    }

    fn grid() -> Vec<Point> {
        (0..100)
            .map(|k| {
                Point::new(
                    100.0 + 12.0 * (k % 10) as f64,
                    80.0 + 11.0 * (k / 10) as f64,
                )
            })
            .collect()
    }

    /// Least squares recovers an exact homography; with a third of the matches moved far away,
    /// RANSAC and LMedS recover it still (and say which matches were the outliers) where least
    /// squares does not; with fewer than four matches nothing is fitted.
    #[test]
    fn the_robust_fits_see_through_outliers() {
        let h = truth();
        let src = grid();
        let mut rng = Rng::new(5);
        let exact: Vec<Point> = src.iter().map(|&p| apply(&h, p)).collect();
        let ls = fit_least_squares(&src, &exact, None).unwrap();
        assert!((ls - h).abs().max() < 1e-8, "{ls}");
        let mut dst = exact.clone();
        let mut outlier = vec![false; src.len()];
        for (i, d) in dst.iter_mut().enumerate() {
            // Noise of a tenth of a pixel on every match.
            d.x += 0.1 * rng.normal();
            d.y += 0.1 * rng.normal();
            if i % 3 == 0 {
                d.x += 20.0 + 30.0 * rng.uniform();
                d.y -= 25.0 * rng.uniform() + 15.0;
                outlier[i] = true;
            }
        }
        let (mut inliers, mut errors) = (vec![false; src.len()], vec![0.0; src.len()]);
        for estimator in [
            Estimator::Ransac,
            Estimator::LeastMedian,
            Estimator::LeastSquares,
        ] {
            let robust = Robust {
                estimator,
                threshold: 2.0,
                max_samples: 500,
                confidence: 0.995,
            };
            let got = fit(&src, &dst, &robust, &mut rng, (&mut inliers, &mut errors)).unwrap();
            let worst = src
                .iter()
                .map(|&p| apply(&got, p).dist(apply(&h, p)))
                .fold(0.0, f64::max);
            if estimator == Estimator::LeastSquares {
                assert!(worst > 3.0, "least squares: {worst}");
            } else {
                assert!(worst < 0.2, "{estimator:?}: {worst} px");
                let flagged: Vec<bool> = inliers.iter().map(|k| !k).collect();
                assert_eq!(flagged, outlier, "{estimator:?}");
            }
        }
        let robust = Robust {
            estimator: Estimator::Ransac,
            threshold: 2.0,
            max_samples: 100,
            confidence: 0.99,
        };
        assert!(
            fit(
                &src[..3],
                &dst[..3],
                &robust,
                &mut rng,
                (&mut inliers, &mut errors)
            )
            .is_none()
        );
    }
}
