//! Periodic templates (issue 43): a template that looks like itself shifted (a brick wall, tiles,
//! a grating) has look-alikes one period away in every frame, and a search that lands on one
//! (a fast move, a coarse level that aliases) passes the checks: on a brick wall the patch a
//! course of bricks over correlates 0.8-0.9 with the template. At initialisation the template's
//! periods are found ([`periods`]: the secondary maxima of its autocorrelation); on a tracked
//! frame of such a template whose confidence fell below [`SUSPECT`] times the track's recent
//! median, the quads one period either way are measured too, and when one is more confident by
//! [`MARGIN`], the frame is searched again from there and the more confident end kept
//! ([`RegistrationTracker::periodic_check`]).

use super::judge::{SearchResult, check_quad};
use super::{Estimate, RegistrationTracker};
use crate::geometry::{Point, Quad, apply_homography, homography_from_points};
use crate::observe::Observer;
use crate::status::FrameTiming;
use crate::visual_tracker::FrameInput;
use std::time::Instant;

/// The most periods kept (each tried both ways).
pub const MAX_PERIODS: usize = 4;
/// A secondary maximum of the template's autocorrelation at least this high is a period.
pub const PERIODIC: f64 = 0.5;
/// A tracked frame is checked against its look-alikes when its confidence is below this times
/// the track's recent median (or there is no median yet).
pub const SUSPECT: f64 = 0.97;
/// A look-alike one period away is searched from when it is this much more confident.
pub const MARGIN: f64 = 0.03;

/// The periods of a `res x res` template (row-major values), as shifts in fractions of the
/// target's sides (the unit square's): the secondary local maxima of its normalised
/// autocorrelation over shifts of up to half the target, at least [`PERIODIC`] high, strongest
/// first, at most [`MAX_PERIODS`] (of a shift and its opposite, one). Computed on the template
/// averaged over 2 x 2 blocks.
pub fn periods(template: &[f32], res: usize) -> Vec<(f64, f64)> {
    let n = res / 2;
    if n < 6 || template.len() < res * res {
        return Vec::new();
    }
    let mut small = vec![0.0f64; n * n];
    for j in 0..n {
        for i in 0..n {
            let at = |x: usize, y: usize| template[y * res + x] as f64;
            small[j * n + i] = 0.25
                * (at(2 * i, 2 * j)
                    + at(2 * i + 1, 2 * j)
                    + at(2 * i, 2 * j + 1)
                    + at(2 * i + 1, 2 * j + 1));
        }
    }
    let half = (n / 2) as i64;
    let side = (2 * half + 1) as usize;
    let mut corr = vec![f64::NEG_INFINITY; side * side];
    for dy in -half..=half {
        for dx in -half..=half {
            // The overlap of the template and its shifted copy.
            let (x0, x1) = (dx.max(0) as usize, (n as i64 + dx.min(0)) as usize);
            let (y0, y1) = (dy.max(0) as usize, (n as i64 + dy.min(0)) as usize);
            let count = ((x1 - x0) * (y1 - y0)) as f64;
            let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for y in y0..y1 {
                for x in x0..x1 {
                    let a = small[y * n + x];
                    let b = small[(y as i64 - dy) as usize * n + (x as i64 - dx) as usize];
                    sa += a;
                    sb += b;
                    saa += a * a;
                    sbb += b * b;
                    sab += a * b;
                }
            }
            let va = saa - sa * sa / count;
            let vb = sbb - sb * sb / count;
            let c = (sab - sa * sb / count) / (va * vb).sqrt();
            corr[((dy + half) as usize) * side + (dx + half) as usize] =
                if c.is_finite() { c } else { f64::NEG_INFINITY };
        }
    }
    let at = |dx: i64, dy: i64| {
        if dx.abs() > half || dy.abs() > half {
            f64::NEG_INFINITY
        } else {
            corr[((dy + half) as usize) * side + (dx + half) as usize]
        }
    };
    let mut peaks: Vec<(f64, (i64, i64))> = Vec::new();
    for dy in -half..=half {
        for dx in -half..=half {
            // One of each opposite pair; not the centre.
            if (dy, dx) <= (0, 0) {
                continue;
            }
            let c = at(dx, dy);
            if c < PERIODIC {
                continue;
            }
            let local = (-1..=1)
                .flat_map(|j| (-1..=1).map(move |i| (i, j)))
                .filter(|&(i, j)| (i, j) != (0, 0))
                .all(|(i, j)| at(dx + i, dy + j) < c);
            if local {
                peaks.push((c, (dx, dy)));
            }
        }
    }
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    peaks
        .into_iter()
        .take(MAX_PERIODS)
        .map(|(_, (dx, dy))| (dx as f64 / n as f64, dy as f64 / n as f64))
        .collect()
}

/// `q` moved by `(sx, sy)` of its own sides (through the homography of the unit square onto
/// it), or `None` when `q` has three collinear corners.
pub fn shifted_by(q: &Quad, (sx, sy): (f64, f64)) -> Option<Quad> {
    let unit = [
        Point::new(0.0, 0.0),
        Point::new(1.0, 0.0),
        Point::new(1.0, 1.0),
        Point::new(0.0, 1.0),
    ];
    let h = homography_from_points(&unit, &q.0)?;
    Some(Quad(unit.map(|p| {
        apply_homography(&h, Point::new(p.x + sx, p.y + sy))
    })))
}

impl RegistrationTracker {
    /// See the module's documentation: `out` (a tracking frame's end that passes the checks)
    /// or, when a look-alike one period away is more confident and the search from there ends
    /// more confident still, that end.
    pub(super) fn periodic_check(
        &mut self,
        input: FrameInput<'_>,
        out: Estimate,
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
    ) -> Estimate {
        let Some(found) = out.confidence else {
            return out;
        };
        if self.periods.is_empty() || self.loss.reference().is_some_and(|m| found >= SUSPECT * m) {
            return out;
        }
        let size = input.size();
        let mut best: Option<(f64, Estimate)> = None;
        for k in 0..self.periods.len() * 2 {
            let (sx, sy) = self.periods[k / 2];
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            let Some(q) = shifted_by(&out.corners, (sign * sx, sign * sy)) else {
                continue;
            };
            if check_quad(&q, self.initial_area, size).is_err() {
                continue;
            }
            let Some(p) = self.finest.ctx.problem().fit(&q) else {
                continue;
            };
            self.src.hold(input, &q, self.params.roi_margin);
            let view = self.src.view(input, 0);
            let c = self
                .judges
                .template
                .of(self.finest.ctx.whole_sample_at(&view, &p));
            if c > found + MARGIN && best.as_ref().is_none_or(|(b, _)| c > *b) {
                best = Some((c, Estimate::start(p, q)));
            }
        }
        let Some((_, from)) = best else {
            return out;
        };
        let again: SearchResult =
            self.search_from(input, from.params, &from.corners, observer, started, timing);
        match again {
            Ok(other)
                if other.confidence.is_some_and(|c| c > found)
                    && check_quad(&other.corners, self.initial_area, size).is_ok() =>
            {
                other
            }
            _ => out,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A template of tiles 10 grid points apart (both ways) has periods of a fifth of the
    /// target; a random one has none; a quad moved by a fifth of its width.
    #[test]
    fn tiles_have_a_period_and_noise_none() {
        let res = 50;
        let tau = std::f32::consts::TAU;
        let tiles: Vec<f32> = (0..res * res)
            .map(|k| {
                let (x, y) = ((k % res) as f32, (k / res) as f32);
                100.0 + 50.0 * (x * tau / 10.0).sin() * (y * tau / 10.0).sin()
            })
            .collect();
        let p = periods(&tiles, res);
        assert!(!p.is_empty(), "{p:?}");
        for &(sx, sy) in &p {
            let fifths = |v: f64| (v * 5.0 - (v * 5.0).round()).abs() < 1e-9;
            assert!(fifths(sx) && fifths(sy) && (sx, sy) != (0.0, 0.0), "{p:?}");
        }
        let mut rng = crate::rng::Rng::new(3);
        let noise: Vec<f32> = (0..res * res)
            .map(|_| rng.range(0.0, 255.0) as f32)
            .collect();
        assert!(periods(&noise, res).is_empty());
        // A quad moved by a fifth of its width.
        let q = Quad::from_rect(10.0, 20.0, 100.0, 50.0);
        let s = shifted_by(&q, (0.2, 0.0)).unwrap();
        assert!((s.0[0].x - 30.0).abs() < 1e-9 && (s.0[2].y - 70.0).abs() < 1e-9);
    }
}

#[cfg(test)]
mod check {
    use super::*;
    use crate::imaging::GrayU8;
    use crate::observe::NoObserver;
    use crate::rng::Rng;
    use crate::status::FrameTiming;
    use crate::visual_tracker::VisualTracker;

    /// Tiles 25 px a period both ways whose tiles differ a little (each its own contrast and
    /// ripple), with grain: one tile over looks nearly, not quite, like the target.
    fn tiles(w: usize, h: usize) -> GrayU8 {
        let mut rng = Rng::new(11);
        let (nx, ny) = (w / 25 + 1, h / 25 + 1);
        let own: Vec<(f64, f64, f64)> = (0..nx * ny)
            .map(|_| {
                (
                    rng.range(0.75, 1.25),
                    rng.range(6.0, 12.0),
                    rng.range(0.0, 6.3),
                )
            })
            .collect();
        let tau = std::f64::consts::TAU;
        let mut img = GrayU8::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (gain, ripple, phase) = own[(y / 25) * nx + x / 25];
                let (fx, fy) = (x as f64 * tau / 25.0, y as f64 * tau / 25.0);
                let v = 128.0
                    + 80.0 * gain * fx.sin() * fy.sin()
                    + 20.0 * (x as f64 * tau / ripple + phase).sin()
                    + rng.range(-6.0, 6.0);
                img.data[y * w + x] = v.clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    /// A frame's end one tile off the target (a look-alike that passes the checks) is
    /// recognised and moved back onto the target.
    #[test]
    fn a_look_alike_one_period_over_is_moved_back() {
        let frame = tiles(480, 360);
        let truth = Quad::from_rect(150.0, 100.0, 150.0, 120.0);
        let spec = crate::plan::harness::spec("fclk", "ssd", "homography");
        let mut t = RegistrationTracker::new(&spec).unwrap();
        let input = FrameInput::Gray8(&frame);
        t.initialize(input, &truth).unwrap();
        assert!(!t.periods.is_empty(), "the grating periods");
        // Where a search one period over ends, with its confidence.
        let over = truth.map(|p| Point::new(p.x + 25.0, p.y));
        let p = t.finest.ctx.problem().fit(&over).unwrap();
        t.src.hold(input, &over, t.params.roi_margin);
        let view = t.src.view(input, 0);
        t.finest.ctx.sample_at(&view, &p);
        let c = t.judges.template.of(t.finest.ctx.values());
        assert!((0.6..0.97).contains(&c), "the look-alike's confidence {c}");
        let mut out = Estimate::start(p, over);
        out.confidence = Some(c);
        let mut timing = FrameTiming::default();
        let end = t.periodic_check(input, out, &mut NoObserver, Instant::now(), &mut timing);
        let e = crate::geometry::alignment_error(&end.corners, &truth);
        assert!(e < 0.5, "{e} px off, confidence {:?}", end.confidence);
    }
}
