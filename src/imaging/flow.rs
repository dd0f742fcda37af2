//! Sparse optical flow: pyramidal Lucas-Kanade tracking of points between two frames (Bouguet's
//! coarse-to-fine scheme), and the forward-backward error of Kalal et al. used by the
//! median-flow tracker and by CMT.

use super::{GrayF32, ImageView, pyramid, sample_value};
use crate::geometry::Point;

/// Lucas-Kanade settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LkParams {
    /// Half-size of the square window (a window of `2 r + 1` pixels a side).
    pub radius: usize,
    /// Pyramid levels (1 = full resolution only).
    pub levels: usize,
    /// Iterations per level at most.
    pub iterations: usize,
    /// Stop when a step is below this many pixels.
    pub epsilon: f64,
    /// A point whose window's smaller structure-tensor eigenvalue (per pixel, in squared gray
    /// levels per pixel) is below this is not trackable.
    pub min_eigen: f64,
}

impl Default for LkParams {
    fn default() -> Self {
        LkParams {
            radius: 4,
            levels: 3,
            iterations: 20,
            epsilon: 0.03,
            min_eigen: 1e-2,
        }
    }
}

/// A frame's pyramid, built once and shared by every point (and by the backward pass).
#[derive(Clone, Debug, Default)]
pub struct Pyramid {
    pub levels: Vec<GrayF32>,
}

impl Pyramid {
    /// `levels` levels of `img` (each half the previous).
    pub fn new(img: &GrayF32, levels: usize) -> Self {
        Pyramid {
            levels: pyramid(img, levels.max(1)),
        }
    }
}

/// Tracks each point of `pts` from `prev` to `next`; `None` where the point cannot be tracked
/// (flat window, left the frame, diverged).
pub fn track_points(
    prev: &Pyramid,
    next: &Pyramid,
    pts: &[Point],
    guesses: Option<&[Point]>,
    p: &LkParams,
) -> Vec<Option<Point>> {
    // Whole images (what a pyramid holds) are sampled without the general view's checks: the
    // same bits.
    let whole = prev
        .levels
        .iter()
        .chain(&next.levels)
        .all(|l| l.view().is_whole());
    if whole {
        track_points_with(prev, next, pts, guesses, p, true, |v, x, y| {
            v.sample_whole(x, y)
        })
    } else {
        track_points_with(prev, next, pts, guesses, p, true, |v, x, y| {
            sample_value(v, x, y)
        })
    }
}

/// [`track_points`] with the sampler `at`; `share`: the template's gradients from its own
/// samples where that gives the same bits (off: every sample made anew, for the test).
fn track_points_with(
    prev: &Pyramid,
    next: &Pyramid,
    pts: &[Point],
    guesses: Option<&[Point]>,
    p: &LkParams,
    share: bool,
    at: impl Fn(&ImageView, f32, f32) -> f32,
) -> Vec<Option<Point>> {
    let levels = prev
        .levels
        .len()
        .min(next.levels.len())
        .min(p.levels.max(1));
    let r = p.radius as i64;
    let n = ((2 * r + 1) * (2 * r + 1)) as usize;
    let mut tmpl = vec![0f32; n];
    let mut gx = vec![0f32; n];
    let mut gy = vec![0f32; n];
    let mut ext = Vec::with_capacity(((2 * r + 3) * (2 * r + 3)) as usize);
    pts.iter()
        .enumerate()
        .map(|(k, &pt)| {
            if !pt.is_finite() {
                return None;
            }
            // The displacement guess, carried from level to level.
            let guess = guesses.and_then(|g| g.get(k)).copied().unwrap_or(pt);
            let mut d = (
                (guess.x - pt.x) / (1u64 << (levels - 1)) as f64,
                (guess.y - pt.y) / (1u64 << (levels - 1)) as f64,
            );
            for l in (0..levels).rev() {
                let s = (1u64 << l) as f64;
                let (a, b) = (&prev.levels[l], &next.levels[l]);
                let (va, vb): (ImageView, ImageView) = (a.view(), b.view());
                let (x, y) = (pt.x / s, pt.y / s);
                // The template window and its gradients (central differences).
                let (mut gxx, mut gxy, mut gyy) = (0f64, 0f64, 0f64);
                // The sample positions along each axis, one beyond the window on each side.
                // Where `u + 1` and `u - 1` are the neighbouring positions (nearly always; not
                // where f32 rounding differs across a power of two), the gradients' samples are
                // the window's own, each sampled once.
                let ax = |c: f64, k: i64| (c + k as f64) as f32;
                let shared = |c: f64| {
                    (-r..=r)
                        .all(|k| ax(c, k) + 1.0 == ax(c, k + 1) && ax(c, k) - 1.0 == ax(c, k - 1))
                };
                if share && shared(x) && shared(y) {
                    let side = (2 * r + 3) as usize;
                    ext.clear();
                    for dy in -r - 1..=r + 1 {
                        for dx in -r - 1..=r + 1 {
                            let corner = dx.abs() > r && dy.abs() > r;
                            ext.push(if corner {
                                0.0
                            } else {
                                at(&va, ax(x, dx), ax(y, dy))
                            });
                        }
                    }
                    let e = |dx: i64, dy: i64| {
                        ext[(dy + r + 1) as usize * side + (dx + r + 1) as usize]
                    };
                    let mut i = 0;
                    for dy in -r..=r {
                        for dx in -r..=r {
                            tmpl[i] = e(dx, dy);
                            gx[i] = 0.5 * (e(dx + 1, dy) - e(dx - 1, dy));
                            gy[i] = 0.5 * (e(dx, dy + 1) - e(dx, dy - 1));
                            gxx += (gx[i] * gx[i]) as f64;
                            gxy += (gx[i] * gy[i]) as f64;
                            gyy += (gy[i] * gy[i]) as f64;
                            i += 1;
                        }
                    }
                } else {
                    let mut i = 0;
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let (u, v) = (ax(x, dx), ax(y, dy));
                            tmpl[i] = at(&va, u, v);
                            gx[i] = 0.5 * (at(&va, u + 1.0, v) - at(&va, u - 1.0, v));
                            gy[i] = 0.5 * (at(&va, u, v + 1.0) - at(&va, u, v - 1.0));
                            gxx += (gx[i] * gx[i]) as f64;
                            gxy += (gx[i] * gy[i]) as f64;
                            gyy += (gy[i] * gy[i]) as f64;
                            i += 1;
                        }
                    }
                }
                let det = gxx * gyy - gxy * gxy;
                let tr = gxx + gyy;
                let min_eig = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt()) / n as f64;
                if min_eig < p.min_eigen || det <= 0.0 {
                    return None;
                }
                for _ in 0..p.iterations {
                    let (cx, cy) = (x + d.0, y + d.1);
                    let (mut bx, mut by) = (0f64, 0f64);
                    let mut i = 0;
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let j = at(&vb, (cx + dx as f64) as f32, (cy + dy as f64) as f32);
                            let e = (tmpl[i] - j) as f64;
                            bx += e * gx[i] as f64;
                            by += e * gy[i] as f64;
                            i += 1;
                        }
                    }
                    let sx = (gyy * bx - gxy * by) / det;
                    let sy = (gxx * by - gxy * bx) / det;
                    d = (d.0 + sx, d.1 + sy);
                    if !(d.0.is_finite() && d.1.is_finite()) {
                        return None;
                    }
                    if sx * sx + sy * sy < p.epsilon * p.epsilon {
                        break;
                    }
                }
                if l > 0 {
                    d = (2.0 * d.0, 2.0 * d.1);
                }
            }
            let q = Point {
                x: pt.x + d.0,
                y: pt.y + d.1,
            };
            let (w, h) = (prev.levels[0].width as f64, prev.levels[0].height as f64);
            (q.is_finite() && q.x >= 0.0 && q.y >= 0.0 && q.x <= w - 1.0 && q.y <= h - 1.0)
                .then_some(q)
        })
        .collect()
}

/// Forward-backward tracking: each point tracked to `next` and back to `prev`; returns the
/// tracked point and the distance between the start and the back-tracked point (the
/// forward-backward error), or `None` where either pass failed.
pub fn track_forward_backward(
    prev: &Pyramid,
    next: &Pyramid,
    pts: &[Point],
    p: &LkParams,
) -> Vec<Option<(Point, f64)>> {
    let fwd = track_points(prev, next, pts, None, p);
    let ok: Vec<Point> = fwd.iter().map(|f| f.unwrap_or(Point::default())).collect();
    let back = track_points(next, prev, &ok, Some(pts), p);
    fwd.iter()
        .zip(&back)
        .zip(pts)
        .map(|((f, b), s)| match (f, b) {
            (Some(f), Some(b)) => Some((*f, b.dist(*s))),
            _ => None,
        })
        .collect()
}

/// The normalised cross-correlation of the `(2 r + 1)`-pixel windows around `a` in `ia` and `b`
/// in `ib` (1 for identical windows up to gain and bias; 0 when either is flat).
pub fn window_ncc(ia: &GrayF32, a: Point, ib: &GrayF32, b: Point, r: usize) -> f64 {
    let (va, vb) = (ia.view(), ib.view());
    let r = r as i64;
    let mut xs = Vec::with_capacity(((2 * r + 1) * (2 * r + 1)) as usize);
    let mut ys = Vec::with_capacity(xs.capacity());
    for dy in -r..=r {
        for dx in -r..=r {
            xs.push(sample_value(&va, (a.x + dx as f64) as f32, (a.y + dy as f64) as f32) as f64);
            ys.push(sample_value(&vb, (b.x + dx as f64) as f32, (b.y + dy as f64) as f32) as f64);
        }
    }
    ncc(&xs, &ys)
}

/// The normalised cross-correlation of two equally long vectors (0 when either is flat).
pub fn ncc(xs: &[f64], ys: &[f64]) -> f64 {
    let n = xs.len().max(1) as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in xs.iter().zip(ys) {
        let (a, b) = (x - mx, y - my);
        sxy += a * b;
        sxx += a * a;
        syy += b * b;
    }
    let d = (sxx * syy).sqrt();
    if d > 1e-12 { sxy / d } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blobs(w: usize, h: usize, shift: (f64, f64)) -> GrayF32 {
        let mut img = GrayF32::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f64 - shift.0, y as f64 - shift.1);
                let val = 128.0
                    + 50.0 * (u / 7.0).sin() * (v / 9.0).cos()
                    + 30.0 * ((u + 2.0 * v) / 13.0).sin();
                img.set(x, y, val as f32);
            }
        }
        img
    }

    /// The template's gradients from its own samples, and the whole-image sampler, give the
    /// bits of sampling every point anew through the general view (points near powers of two,
    /// where the positions' rounding differs, included).
    #[test]
    fn shared_samples_and_the_whole_image_sampler_change_no_bit() {
        let a = blobs(300, 200, (0.0, 0.0));
        let b = blobs(300, 200, (2.3, -1.7));
        let p = LkParams::default();
        let (pa, pb) = (Pyramid::new(&a, p.levels), Pyramid::new(&b, p.levels));
        let mut rng = crate::rng::Rng::new(11);
        let mut pts: Vec<Point> = (0..300)
            .map(|_| Point {
                x: rng.range(5.0, 295.0),
                y: rng.range(5.0, 195.0),
            })
            .collect();
        for c in [64.0, 128.0, 256.0] {
            pts.push(Point {
                x: c - 1e-6,
                y: 127.999_999_9,
            });
            pts.push(Point {
                x: c + 4.0 - 3e-7,
                y: 63.999_999,
            });
        }
        let plain = track_points_with(&pa, &pb, &pts, None, &p, false, |v, x, y| {
            sample_value(v, x, y)
        });
        let fast = track_points(&pa, &pb, &pts, None, &p);
        let bits = |q: &Option<Point>| q.map(|q| (q.x.to_bits(), q.y.to_bits()));
        assert!(plain.iter().filter(|q| q.is_some()).count() > 250);
        for (k, (u, v)) in plain.iter().zip(&fast).enumerate() {
            assert_eq!(bits(u), bits(v), "point {k} {:?}", pts[k]);
        }
    }

    #[test]
    fn lucas_kanade_recovers_a_shift_and_the_forward_backward_error_is_small() {
        let a = blobs(160, 120, (0.0, 0.0));
        let b = blobs(160, 120, (6.3, -4.7));
        let p = LkParams::default();
        let (pa, pb) = (Pyramid::new(&a, p.levels), Pyramid::new(&b, p.levels));
        let pts: Vec<Point> = (0..5)
            .map(|k| Point {
                x: 50.0 + 12.0 * k as f64,
                y: 60.0 - 5.0 * k as f64,
            })
            .collect();
        for (s, r) in pts.iter().zip(track_forward_backward(&pa, &pb, &pts, &p)) {
            let (q, fb) = r.expect("tracked");
            assert!(
                (q.x - s.x - 6.3).abs() < 0.05 && (q.y - s.y + 4.7).abs() < 0.05,
                "{q:?}"
            );
            assert!(fb < 0.05, "fb {fb}");
            assert!(window_ncc(&a, *s, &b, q, 5) > 0.99);
        }
        // A flat image cannot be tracked.
        let flat = GrayF32 {
            width: 40,
            height: 40,
            data: vec![9.0; 1600],
        };
        let pf = Pyramid::new(&flat, 1);
        assert!(track_points(&pf, &pf, &[Point { x: 20.0, y: 20.0 }], None, &p)[0].is_none());
    }

    /// A point whose window changes between the frames (here: replaced by other content)
    /// tracks with a large forward-backward error or not at all.
    #[test]
    fn an_occluded_point_has_a_large_forward_backward_error() {
        let a = blobs(160, 120, (0.0, 0.0));
        let mut b = blobs(160, 120, (3.0, 0.0));
        for y in 40..80 {
            for x in 60..100 {
                b.set(x, y, ((x * 37 + y * 91) % 97) as f32 * 2.5);
            }
        }
        let p = LkParams::default();
        let (pa, pb) = (Pyramid::new(&a, p.levels), Pyramid::new(&b, p.levels));
        let r = track_forward_backward(&pa, &pb, &[Point { x: 80.0, y: 60.0 }], &p);
        assert!(r[0].is_none_or(|(_, fb)| fb > 1.0), "{r:?}");
    }
}
