//! The policy after a loss (tracker parameter `on_loss=redetect`, the default): when a frame's
//! searches fail the checks (a tracking frame's, and a lost tracker's from its last good estimate
//! and from where the rejected search ended), the frame is searched for the template, within a
//! budget; on the frame the loss happens on, a candidate must also reach [`AT_LOSS`]. The last good
//! quad is moved over the frame at [`REDETECT_SCALES`], in rings around where it was lost; each
//! candidate is ranked by its confidence on the tracker's coarsest pyramid level ([`Detector`]), in
//! steps of a sixth of the target's size in that level's pixels (at least two of them). Every lost
//! frame ranks the [`NEAR_RINGS`] first (a target that comes back mostly comes back near), then the
//! far rings from where the last lost frame stopped ([`Scan`]), reading at most
//! [`REDETECT_SAMPLES`] samples, so that no update while lost takes long (the whole frame is
//! covered in a few frames, then the far search starts again). Of the [`REDETECT_REFINED`] best
//! candidates of the frame, the best is refined by the plan and the others only when ranked at
//! `min_confidence` or more, in turn; the first that passes the checks (the confidence's whatever
//! the SSM) is the frame's end.

use super::judge::SearchResult;
use super::tracker::CONFIDENCE_BLOCKS;
use super::{Estimate, RegistrationTracker};
use crate::geometry::{Point, Quad, Rect};
use crate::imaging::{ImageView, sample_values};
use crate::observe::Observer;
use crate::registration::BlockCorrelation;
use crate::registration::{Problem, warp_points};
use crate::ssm::Params;
use crate::status::FrameTiming;
use crate::visual_tracker::FrameInput;
use std::time::Instant;

/// The scales of the last good quad at which the frame is searched.
pub const REDETECT_SCALES: [f64; 3] = [0.8, 1.0, 1.25];
/// The candidates of a frame's search that are refined.
pub const REDETECT_REFINED: usize = 3;
/// The most samples a lost frame's ranking reads, over its candidates (300 candidates of the
/// finest level's 625 samples; `regtrack bench`'s `lost ms` is the longest update while lost).
pub const REDETECT_SAMPLES: usize = 187_500;
/// The rings around the last good position that every lost frame ranks first.
pub const NEAR_RINGS: usize = 4;
/// On the frame a loss happens on, a candidate's end must be at least this many times as
/// confident as the track's recent frames (their median; the template's 1 before any). The
/// frame is searched for the template there too (a sudden acceleration leaves the searches from
/// the prediction and the last pose on a look-alike, and by the next frame the target is
/// further away): on the held-out renders' fast motion SR@5 0.727 -> 0.770. Without a bar, on
/// the slip test's brick wall 7 of the 75 frames more than 20 px off went unreported (a row of
/// bricks over passes the checks), with 0.8 4 of 70, as before; 0.8 and no bar gave the same
/// SR@5 on the tune half (0.873), 0.9 and 0.95 less (0.814, 0.820: a fast move's blur lowers
/// the target's confidence too).
pub const AT_LOSS: f64 = 0.8;

/// Where the frame search goes on: the ring around the last good position (in steps; 0 is the
/// position itself) and the next of its candidates (positions times scales).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Scan {
    ring: usize,
    next: usize,
}

impl Scan {
    /// The candidates of ring `r`: its positions (1, then `8 r`) times the scales.
    fn size(r: usize) -> usize {
        REDETECT_SCALES.len() * if r == 0 { 1 } else { 8 * r }
    }

    /// The offset (in steps) and the scale of candidate `next` of ring `r`: the ring's square
    /// walked clockwise from its upper-left corner.
    fn at(r: usize, next: usize) -> ((i64, i64), f64) {
        let scale = REDETECT_SCALES[next % REDETECT_SCALES.len()];
        let k = next / REDETECT_SCALES.len();
        if r == 0 {
            return ((0, 0), scale);
        }
        let (r, side, t) = (r as i64, (k / (2 * r)) as i64, (k % (2 * r)) as i64);
        let offset = match side {
            0 => (-r + t, -r),
            1 => (r, -r + t),
            2 => (r - t, r),
            _ => (-r, r - t),
        };
        (offset, scale)
    }
}

/// The grid samples the frame search ranks its candidates on, on the tracker's coarsest pyramid
/// level (every `2^level`-th one per axis, at least every other one), the template there, and
/// a buffer for a candidate's patch: made when the template is sampled, so that a lost frame
/// does not allocate either. Ranked on the coarsest level, where the smoothing has widened the
/// correlation's peak to several pixels, a candidate a few pixels off the target still ranks
/// it: on the finest level fine texture (text, sparse marks) correlates with the template only
/// within a pixel or two of it, which a search in steps of several pixels misses.
#[derive(Debug, Default)]
pub struct Detector {
    /// The pyramid level the candidates are ranked on.
    level: usize,
    /// The grid's points the detector samples (every `2^level`-th one per axis, at least every
    /// other one), normalised frame.
    xs: Vec<f32>,
    ys: Vec<f32>,
    /// Where they are under a candidate (frame pixels), and the values there.
    px: Vec<f32>,
    py: Vec<f32>,
    patch: Vec<f32>,
    confidence: BlockCorrelation,
    /// Where the frame search goes on.
    pub(super) scan: Scan,
}

impl Detector {
    /// The detector of a `res x res` grid of `problem` ranking on pyramid level `level`, its
    /// template sampled from `view` (that level of the first frame) where the problem's
    /// parameters `p` put the grid.
    pub fn new(problem: &Problem, res: usize, level: usize, view: &ImageView, p: &Params) -> Self {
        let (grid_x, grid_y) = problem.grid();
        let stride = (1usize << level.min(8)).max(2);
        let side = res.div_ceil(stride);
        let picks: Vec<usize> = (0..side)
            .flat_map(|j| (0..side).map(move |i| stride * j * res + stride * i))
            .collect();
        let n = picks.len();
        let mut d = Detector {
            level,
            xs: picks.iter().map(|&k| grid_x[k]).collect(),
            ys: picks.iter().map(|&k| grid_y[k]).collect(),
            px: vec![0.0; n],
            py: vec![0.0; n],
            patch: vec![0.0; n],
            confidence: BlockCorrelation::default(),
            scan: Scan::default(),
        };
        d.sample(problem, view, p);
        d.confidence = BlockCorrelation::new(&d.patch, side, CONFIDENCE_BLOCKS);
        d
    }

    /// The pyramid level the candidates are ranked on.
    pub fn level(&self) -> usize {
        self.level
    }

    /// Samples the detector's grid points of `view` under the parameters `p` into `patch`.
    fn sample(&mut self, problem: &Problem, view: &ImageView, p: &Params) {
        let m = problem.pixel_matrix(p);
        warp_points(&m, &self.xs, &self.ys, &mut self.px, &mut self.py);
        sample_values(view, &self.px, &self.py, &mut self.patch);
    }

    /// The confidence of the target at `q` (frame pixels) in `view`, on the detector's grid,
    /// and the SSM's parameters there (`None` if the SSM cannot fit `q`).
    pub fn candidate(
        &mut self,
        problem: &Problem,
        view: &ImageView,
        q: &Quad,
    ) -> Option<(f64, Params)> {
        let p = problem.fit(q)?;
        self.sample(problem, view, &p);
        Some((self.confidence.of(&self.patch), p))
    }
}

impl RegistrationTracker {
    /// See the module's documentation.
    pub(super) fn redetect(
        &mut self,
        input: FrameInput<'_>,
        observer: &mut dyn Observer,
        started: Instant,
        timing: &mut FrameTiming,
        bar: Option<f64>,
    ) -> Option<Estimate> {
        let (fw, fh) = input.size();
        // What a candidate's end must pass: the checks, and the confidence `bar` when given.
        let passes = |t: &mut Self, out: &Estimate| {
            t.accept(out, (fw, fh), true).is_ok()
                && bar.is_none_or(|b| out.confidence.is_some_and(|c| c >= b))
        };
        let t0 = Instant::now();
        self.src.prepare(input, Rect::of_size(fw, fh));
        // The detector's level is the coarsest the source makes (none without a pyramid).
        let level = self.detector.level();
        self.src.build_levels(input);
        timing.preprocess += t0.elapsed();
        let base = self.corners;
        let c = base.centroid();
        let b = base.bbox();
        // A sixth of the target's size in the level's pixels (on a coarse level the smoothing
        // widens the correlation's peak), at least two of them and 4 px.
        let unit = (1u32 << level.min(8)) as f64;
        let step = (b.width().max(b.height()) / (6.0 * unit)).max((2.0 * unit).max(4.0));
        // The rings that reach every corner of the frame.
        let reach = [
            (0.0, 0.0),
            (fw as f64, 0.0),
            (0.0, fh as f64),
            (fw as f64, fh as f64),
        ]
        .iter()
        .map(|&(x, y)| ((x - c.x).abs().max((y - c.y).abs()) / step).ceil() as usize)
        .max()
        .unwrap_or(0);
        // The best candidates: confidence and the SSM's parameters there.
        let mut best = [(f64::NEG_INFINITY, self.finest.ctx.params()); REDETECT_REFINED];
        let place = |(cx, cy): (f64, f64), scale: f64| {
            base.map(|p| Point::new(cx + scale * (p.x - c.x), cy + scale * (p.y - c.y)))
        };
        let t1 = Instant::now();
        {
            let view = self.src.view(input, level);
            let (problem, det) = (self.finest.ctx.problem(), &mut self.detector);
            let budget = REDETECT_SAMPLES / det.xs.len().max(1);
            let mut scan = det.scan;
            let mut rank = |(i, j): (i64, i64), scale: f64| {
                let (cx, cy) = (c.x + i as f64 * step, c.y + j as f64 * step);
                if cx < 0.0 || cy < 0.0 || cx >= fw as f64 || cy >= fh as f64 {
                    return false;
                }
                if let Some((conf, p)) = det.candidate(problem, &view, &place((cx, cy), scale)) {
                    // Keep the best few, best first.
                    if conf > best[REDETECT_REFINED - 1].0 {
                        best[REDETECT_REFINED - 1] = (conf, p);
                        best.sort_by(|a, b| b.0.total_cmp(&a.0));
                    }
                }
                true
            };
            // Near first, on every lost frame (a target that comes back mostly comes back
            // near), then the far rings from where the last lost frame stopped.
            let near = NEAR_RINGS.min(reach);
            let mut ranked = 0;
            for ring in 0..=near {
                for next in 0..Scan::size(ring) {
                    let (offset, scale) = Scan::at(ring, next);
                    ranked += usize::from(rank(offset, scale));
                }
            }
            let mut wrapped = false;
            while reach > near && ranked < budget {
                let Scan { ring, next } = scan;
                if ring <= near || next >= Scan::size(ring) {
                    let around = ring >= reach;
                    scan = Scan {
                        ring: if around {
                            near + 1
                        } else {
                            (ring + 1).max(near + 1)
                        },
                        next: 0,
                    };
                    // Once round the frame in one frame (a small frame): enough.
                    if around {
                        if wrapped {
                            break;
                        }
                        wrapped = true;
                    }
                    continue;
                }
                scan.next += 1;
                let (offset, scale) = Scan::at(ring, next);
                ranked += usize::from(rank(offset, scale));
            }
            self.detector.scan = scan;
        }
        timing.search += t1.elapsed();
        // The best candidate is refined; the next ones only if they correlate with the template
        // as much as a tracked frame must: a frame without the target (noise, another scene)
        // costs its ranking and one refinement.
        let floor = self.params.min_confidence;
        for (k, (conf, p)) in best.into_iter().enumerate() {
            if !conf.is_finite() || (k > 0 && conf < floor) {
                break;
            }
            let from = self.finest.ctx.corners(&p);
            // A candidate is the target only if it looks like it, whatever the SSM: the
            // confidence is checked for every SSM here.
            let found: SearchResult = self.search_from(input, p, &from, observer, started, timing);
            if let Ok(out) = found
                && passes(self, &out)
            {
                if out.converged {
                    return Some(out);
                }
                // Far from a candidate, the search may end at its iteration limit on the way
                // to the target: once more from there (only when the target is found).
                let again =
                    self.search_from(input, out.params, &out.corners, observer, started, timing);
                return Some(match again {
                    Ok(better) if passes(self, &better) => better,
                    _ => out,
                });
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::NoObserver;

    /// Every ring's candidates are the cells of its square, each once, at every scale.
    #[test]
    fn a_ring_walks_its_square_once() {
        for r in 0..6 {
            let mut seen = std::collections::BTreeSet::new();
            for next in 0..Scan::size(r) {
                let ((i, j), scale) = Scan::at(r, next);
                assert_eq!(i.abs().max(j.abs()) as usize, r);
                assert!(seen.insert((i, j, (scale * 100.0) as i64)), "{r} {next}");
            }
            assert_eq!(seen.len(), Scan::size(r));
        }
    }
    use crate::plan::harness::{error, shifted, tracker};
    use crate::status::TrackStatus;
    use crate::visual_tracker::VisualTracker;

    /// The detector ranks the target above the quads around it; a tracker moved far from the
    /// target (lost) finds it again within the frames its search takes to reach it, each lost
    /// frame ranking at most the budget's candidates, nearest rings first.
    #[test]
    fn the_frame_search_finds_the_target_again() {
        let (mut t, gray, quads) = tracker(("iclk", "zncc", "homography"), |_| {}, (4, 1));
        let view_of = |t: &mut RegistrationTracker, i: usize| {
            let input = FrameInput::Gray8(&gray[i]);
            t.src
                .prepare(input, Rect::of_size(gray[i].width, gray[i].height));
            t.src.build_levels(input);
        };
        view_of(&mut t, 0);
        // Ranked on the coarsest level of the tracker's pyramid.
        assert_eq!(t.detector.level(), 2);
        let view = t.src.view(FrameInput::Gray8(&gray[0]), 2);
        let problem = t.finest.ctx.problem();
        let (on, _) = t.detector.candidate(problem, &view, &quads[0]).unwrap();
        assert!(on > 0.95, "{on}");
        for (dx, dy) in [(20.0, 0.0), (0.0, -25.0), (-30.0, 30.0)] {
            let (off, _) = t
                .detector
                .candidate(problem, &view, &shifted(&quads[0], dx, dy))
                .unwrap();
            assert!(off < on - 0.2, "{dx} {dy}: {off} vs {on}");
        }
        // Lost far away: the searches from there fail, the frame search does not, once its
        // far rings reach the target (160 px right, 110 down: beyond the near rings, ring 20
        // of steps of 8 px, about 4,000 candidates on, within the budget of the third to sixth
        // lost frame: about 860 far candidates each).
        t.set_corners(&shifted(&quads[1], 160.0, 110.0)).unwrap();
        t.status = TrackStatus::Lost(crate::status::LossReason::LowConfidence);
        let mut found = None;
        for k in 0..8 {
            let before = t.detector.scan;
            let out = t.update(FrameInput::Gray8(&gray[2]), &mut NoObserver);
            if out.status == TrackStatus::Tracking {
                found = Some((k, out.corners));
                break;
            }
            // Each lost frame goes on where the last one stopped.
            assert_ne!(t.detector.scan, before);
        }
        let (k, corners) = found.expect("found again");
        assert!((2..=5).contains(&k), "found on lost frame {k}");
        assert!(
            error(&corners, &quads[2]) < 0.5,
            "{}",
            error(&corners, &quads[2])
        );
        // Tracked again: the next loss searches near first.
        assert_eq!(t.detector.scan, Scan::default());
    }
}
