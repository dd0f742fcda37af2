//! A policy on frames judged while the target moves fast: motion blur lowers the confidence
//! against the sharp template although the search ended on the target (a target moving 15 px a
//! frame, blurred over two thirds of that: confidence 0.61 on the target, where the track's
//! median was 0.98, so the frame and every later one were reported lost).
//!
//! When a tracked frame's end fails the confidence checks, the target moved at least
//! [`MIN_MOTION_PX`] since the last frame, and the patch there is blurred along that motion
//! (its derivative along the motion weaker than the template's, [`BLURRED`]), the template is
//! blurred along that motion, as the
//! camera would have blurred it (a box along the motion, centred: an exposure around the
//! frame's time), over each of the [`EXPOSURES`] fractions of the motion, and the frame's
//! confidence becomes the highest of its correlations with those templates and the sharp one.
//! The blur's direction and length come from where the track was and where the search ended,
//! mapped onto the template's grid by the target's sides; nothing is searched again. A slip to a
//! look-alike is still caught by the frame check (the previous frame's patch is as blurred as
//! this one, or nearly), which the blurred template does not change.

use super::{Estimate, RegistrationTracker};
use crate::geometry::{Point, Quad};
use crate::registration::at_least;
use crate::visual_tracker::FrameInput;

/// The least motion (px, of the target's centre since the last frame) for which the template
/// is blurred.
pub const MIN_MOTION_PX: f64 = 2.0;

/// The fractions of a frame's motion the exposure may have lasted.
pub const EXPOSURES: [f64; 2] = [0.5, 1.0];

/// A patch is blurred along the motion when its energy of the derivative along the motion
/// (relative to its variance) is below this fraction of the template's: only then is the
/// template blurred. A slip to a sharp look-alike (the next bricks of a wall) is as sharp as
/// the template, and a blurred template would have let it pass.
pub const BLURRED: f64 = 0.6;

/// The most taps of the blur (its length in grid steps, at most).
const MAX_TAPS: usize = 25;

/// The motion `d` (frame px) in the template grid's steps: through the target's sides as the
/// quad `q` has them (an affine approximation of the warp at the centre), over a grid whose
/// steps are `du` of the unit square.
fn grid_motion(q: &Quad, d: Point, du: f64) -> Option<(f64, f64)> {
    let [ul, ur, lr, ll] = q.0;
    let ex = (
        (ur.x - ul.x + lr.x - ll.x) / 2.0,
        (ur.y - ul.y + lr.y - ll.y) / 2.0,
    );
    let ey = (
        (ll.x - ul.x + lr.x - ur.x) / 2.0,
        (ll.y - ul.y + lr.y - ur.y) / 2.0,
    );
    let det = ex.0 * ey.1 - ex.1 * ey.0;
    if det.abs() <= 1e-9 || du <= 0.0 || det.is_nan() || du.is_nan() {
        return None;
    }
    let u = (d.x * ey.1 - d.y * ey.0) / det;
    let v = (ex.0 * d.y - ex.1 * d.x) / det;
    Some((u / du, v / du))
}

/// `t` (`res x res`, row-major) blurred by a centred box of `g` grid steps into `out`:
/// bilinear samples along the box, the grid's edge repeated beyond it.
fn box_blur(t: &[f32], res: usize, g: (f64, f64), out: &mut [f32]) {
    let len = g.0.hypot(g.1);
    let taps = (len.ceil() as usize + 1).clamp(2, MAX_TAPS);
    let at = |x: f64, y: f64| -> f64 {
        let max = (res - 1) as f64;
        let (x, y) = (x.clamp(0.0, max), y.clamp(0.0, max));
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(res - 1), (y0 + 1).min(res - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let v = |i: usize, j: usize| t[j * res + i] as f64;
        (1.0 - fy) * ((1.0 - fx) * v(x0, y0) + fx * v(x1, y0))
            + fy * ((1.0 - fx) * v(x0, y1) + fx * v(x1, y1))
    };
    for j in 0..res {
        for i in 0..res {
            let mut sum = 0.0;
            for k in 0..taps {
                let s = k as f64 / (taps - 1) as f64 - 0.5;
                sum += at(i as f64 + s * g.0, j as f64 + s * g.1);
            }
            out[j * res + i] = (sum / taps as f64) as f32;
        }
    }
}

/// The energy of `v`'s (`res x res`) central differences along the unit direction `u` over
/// its variance (0 for a flat `v`).
fn sharpness(v: &[f32], res: usize, u: (f64, f64)) -> f64 {
    let n = (res * res) as f64;
    let mean = v.iter().map(|&x| x as f64).sum::<f64>() / n;
    let var = v.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n;
    if var.is_nan() || var <= 0.0 || res < 3 {
        return 0.0;
    }
    let mut energy = 0.0;
    for j in 1..res - 1 {
        for i in 1..res - 1 {
            let at = |i: usize, j: usize| v[j * res + i] as f64;
            let d = u.0 * (at(i + 1, j) - at(i - 1, j)) + u.1 * (at(i, j + 1) - at(i, j - 1));
            energy += d * d;
        }
    }
    energy / ((res - 2) * (res - 2)) as f64 / var
}

impl RegistrationTracker {
    /// See the module's documentation: raises `out`'s confidence to its best against the
    /// template blurred along the frame's motion, when the target moved enough.
    pub(super) fn allow_for_blur(&mut self, input: FrameInput<'_>, out: &mut Estimate) {
        let Some(confidence) = out.confidence else {
            return;
        };
        let (a, b) = (out.corners.centroid(), self.corners.centroid());
        let d = Point::new(a.x - b.x, a.y - b.y);
        if d.x.hypot(d.y).is_nan() || d.x.hypot(d.y) < MIN_MOTION_PX || !out.corners.is_finite() {
            return;
        }
        let res = self.params.res;
        let ctx = &mut self.finest.ctx;
        let (gu, _) = ctx.problem().unit_grid();
        let du = if gu.len() > 1 {
            (gu[1] - gu[0]) as f64
        } else {
            return;
        };
        let Some(g) = grid_motion(&out.corners, d, du) else {
            return;
        };
        self.src.hold(input, &out.corners, self.params.roi_margin);
        let view = self.src.view(input, 0);
        ctx.whole_patch_at(&view, &out.params);
        let (values, whole) = (ctx.whole_values(), ctx.problem().whole_template());
        let len = g.0.hypot(g.1);
        let along = (g.0 / len, g.1 / len);
        // A colour patch's channels one after the other, each `res x res`.
        let m = res * res;
        let channels = (whole.len() / m).max(1);
        let sharp = |v: &[f32]| {
            let each = (0..channels).map(|c| sharpness(&v[c * m..(c + 1) * m], res, along));
            each.sum::<f64>() / channels as f64
        };
        let template = sharp(whole);
        // Not blurred (or nothing to tell by): the confidence stands.
        if at_least(sharp(values), BLURRED * template) || template == 0.0 {
            return;
        }
        let judges = &mut self.judges;
        let mut best = confidence;
        for f in EXPOSURES {
            for c in 0..channels {
                let r = c * m..(c + 1) * m;
                box_blur(
                    &whole[r.clone()],
                    res,
                    (f * g.0, f * g.1),
                    &mut judges.blurred[r],
                );
            }
            judges
                .blur
                .set_template(&judges.blurred, res, super::tracker::CONFIDENCE_BLOCKS);
            best = best.max(judges.blur.of(values));
        }
        out.confidence = Some(best);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Across the target's sides: a motion along its top edge is along the grid's rows, by the
    /// edge's length in grid steps; down its left side, along its columns.
    #[test]
    fn the_motion_maps_onto_the_grid_by_the_targets_sides() {
        let q = Quad::from_rect(10.0, 20.0, 100.0, 50.0);
        let (gx, gy) = grid_motion(&q, Point::new(10.0, 0.0), 0.02).unwrap();
        assert!((gx - 10.0 / 100.0 / 0.02).abs() < 1e-9 && gy.abs() < 1e-9);
        let (gx, gy) = grid_motion(&q, Point::new(0.0, 5.0), 0.02).unwrap();
        assert!(gx.abs() < 1e-9 && (gy - 5.0 / 50.0 / 0.02).abs() < 1e-9);
        let flat = Quad::from_array([0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 1.0, 0.0]);
        assert!(grid_motion(&flat, Point::new(1.0, 0.0), 0.02).is_none());
    }

    /// The box keeps what is constant along it and averages across: vertical stripes blurred
    /// along the rows by their period become flat, along the columns they stay.
    #[test]
    fn a_box_along_the_motion_averages_along_it_only() {
        let res = 20;
        let t: Vec<f32> = (0..res * res)
            .map(|k| if (k % res) % 4 < 2 { 100.0 } else { 0.0 })
            .collect();
        let mut out = vec![0.0; res * res];
        box_blur(&t, res, (0.0, 6.0), &mut out);
        // Along the stripes: the edge repeated, the values unchanged.
        assert!(t.iter().zip(&out).all(|(a, b)| (a - b).abs() < 1e-3));
        box_blur(&t, res, (4.0, 0.0), &mut out);
        // Across, over a period: near the mean inside the grid.
        for i in 4..res - 4 {
            assert!(
                (out[5 * res + i] - 50.0).abs() < 13.0,
                "{i}: {}",
                out[5 * res + i]
            );
        }
    }

    /// Along the stripes a patch of vertical stripes is flat, across it is sharp; a fine
    /// texture blurred by a box along one direction is less sharp along it, not across.
    #[test]
    fn sharpness_is_along_the_direction() {
        let res = 20;
        let t: Vec<f32> = (0..res * res)
            .map(|k| if (k % res) % 6 < 3 { 100.0 } else { 0.0 })
            .collect();
        assert_eq!(sharpness(&t, res, (0.0, 1.0)), 0.0);
        assert!(sharpness(&t, res, (1.0, 0.0)) > 0.5);
        // A seeded fine texture.
        let mut x = 12345u32;
        let noise: Vec<f32> = (0..res * res)
            .map(|_| {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                (x >> 16) as f32 / 65536.0 * 100.0
            })
            .collect();
        let mut out = vec![0.0; res * res];
        box_blur(&noise, res, (4.0, 0.0), &mut out);
        let along = sharpness(&out, res, (1.0, 0.0)) / sharpness(&noise, res, (1.0, 0.0));
        let across = sharpness(&out, res, (0.0, 1.0)) / sharpness(&noise, res, (0.0, 1.0));
        assert!(along < BLURRED && across > BLURRED, "{along} {across}");
        assert_eq!(sharpness(&[5.0; 400], res, (1.0, 0.0)), 0.0);
    }
}
