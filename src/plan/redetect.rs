//! The policy after a loss (tracker parameter `on_loss=redetect`, the default): when a lost
//! tracker's searches from its last good estimate (and from where the rejected search ended)
//! fail the checks again, the whole frame is searched for the template. The last good quad is
//! moved over the frame in steps of a sixth of its size, at [`REDETECT_SCALES`]; each candidate
//! is ranked by its confidence on a quarter of the grid ([`Detector`]); the
//! [`REDETECT_REFINED`] best are refined by the plan in turn, and the first that passes the
//! checks (the confidence's whatever the SSM) is the frame's end.

use super::judge::SearchResult;
use super::tracker::CONFIDENCE_BLOCKS;
use super::{Estimate, RegistrationTracker};
use crate::geometry::{Point, Quad, Rect, apply_homography};
use crate::imaging::{ImageView, sample_value};
use crate::observe::Observer;
use crate::registration::BlockCorrelation;
use crate::registration::Problem;
use crate::ssm::Params;
use crate::status::FrameTiming;
use crate::visual_tracker::FrameInput;
use std::time::Instant;

/// The scales of the last good quad at which the frame is searched.
pub const REDETECT_SCALES: [f64; 3] = [0.8, 1.0, 1.25];
/// The candidates of the frame search that are refined.
pub const REDETECT_REFINED: usize = 3;

/// The grid samples the frame search ranks its candidates on (every other one per axis, a
/// quarter of the work), the template there, and a buffer for a candidate's patch: made when
/// the template is sampled, so that a lost frame does not allocate either.
#[derive(Debug, Default)]
pub struct Detector {
    picks: Vec<usize>,
    confidence: BlockCorrelation,
    patch: Vec<f32>,
}

impl Detector {
    /// The detector of a `res x res` template.
    pub fn new(res: usize, template: &[f32]) -> Self {
        let side = res.div_ceil(2);
        let picks: Vec<usize> = (0..side)
            .flat_map(|j| (0..side).map(move |i| 2 * j * res + 2 * i))
            .collect();
        let picked: Vec<f32> = picks.iter().map(|&k| template[k]).collect();
        Detector {
            confidence: BlockCorrelation::new(&picked, side, CONFIDENCE_BLOCKS),
            patch: vec![0.0; picks.len()],
            picks,
        }
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
        let m = problem.pixel_matrix(&p);
        let (gx, gy) = problem.grid();
        for (v, &k) in self.patch.iter_mut().zip(&self.picks) {
            let pt = apply_homography(&m, Point::new(gx[k] as f64, gy[k] as f64));
            *v = sample_value(view, pt.x as f32, pt.y as f32);
        }
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
    ) -> Option<Estimate> {
        let (fw, fh) = input.size();
        let t0 = Instant::now();
        self.src.prepare(input, Rect::of_size(fw, fh));
        timing.preprocess += t0.elapsed();
        let base = self.corners;
        let c = base.centroid();
        let b = base.bbox();
        let step = (b.width().max(b.height()) / 6.0).max(4.0);
        let mut best = [(f64::NEG_INFINITY, self.finest.ctx.params()); REDETECT_REFINED];
        let t1 = Instant::now();
        {
            let view = self.src.view(input, 0);
            let (problem, det) = (self.finest.ctx.problem(), &mut self.detector);
            for scale in REDETECT_SCALES {
                let mut cy = step / 2.0;
                while cy < fh as f64 {
                    let mut cx = step / 2.0;
                    while cx < fw as f64 {
                        let q = base.map(|p| {
                            Point::new(cx + scale * (p.x - c.x), cy + scale * (p.y - c.y))
                        });
                        if let Some((conf, p)) = det.candidate(problem, &view, &q) {
                            // Keep the best few, best first.
                            if conf > best[REDETECT_REFINED - 1].0 {
                                best[REDETECT_REFINED - 1] = (conf, p);
                                best.sort_by(|a, b| b.0.total_cmp(&a.0));
                            }
                        }
                        cx += step;
                    }
                    cy += step;
                }
            }
        }
        timing.search += t1.elapsed();
        for (conf, p) in best {
            if !conf.is_finite() {
                break;
            }
            let from = self.finest.ctx.corners(&p);
            // A candidate is the target only if it looks like it, whatever the SSM: the
            // confidence is checked for every SSM here.
            let found: SearchResult = self.search_from(input, p, &from, observer, started, timing);
            if let Ok(out) = found
                && self.accept(&out, (fw, fh), true).is_ok()
            {
                return Some(out);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::NoObserver;
    use crate::plan::harness::{error, shifted, tracker};
    use crate::status::TrackStatus;
    use crate::visual_tracker::VisualTracker;

    /// The detector ranks the target above the quads around it; a tracker moved far from the
    /// target (lost) finds it again on the next frame by searching the whole frame.
    #[test]
    fn the_frame_search_finds_the_target_again() {
        let (mut t, gray, quads) = tracker(("iclk", "zncc", "homography"), |_| {}, (4, 1));
        let view_of = |t: &mut RegistrationTracker, i: usize| {
            let input = FrameInput::Gray8(&gray[i]);
            t.src
                .prepare(input, Rect::of_size(gray[i].width, gray[i].height));
        };
        view_of(&mut t, 0);
        let view = t.src.view(FrameInput::Gray8(&gray[0]), 0);
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
        // Lost far away: the next frame's searches from there fail, the frame search does not.
        t.set_corners(&shifted(&quads[1], 160.0, 110.0)).unwrap();
        t.status = TrackStatus::Lost(crate::status::LossReason::LowConfidence);
        let out = t.update(FrameInput::Gray8(&gray[2]), &mut NoObserver);
        assert_eq!(out.status, TrackStatus::Tracking);
        assert!(
            error(&out.corners, &quads[2]) < 0.5,
            "{}",
            error(&out.corners, &quads[2])
        );
    }
}
