//! What the inspector shows, read from its state: results, errors, success curves, speed,
//! disagreements. Read-only: the panels call these.

use super::InspectorApp;
use super::runtime::ErrorsKey;
use super::worker::TrackerFrame;
use crate::dataset::Sequence;
use crate::eval;
use crate::geometry::{Point, Quad, alignment_error};
use crate::tracker::TrackStatus;
use eframe::egui;
use std::sync::Arc;

impl InspectorApp {
    /// Frames in the open sequence.
    pub fn frame_count(&self) -> usize {
        match &self.rt.live.info {
            Some(live) => live.frames,
            None => self.rt.seq.sequence.as_ref().map_or(0, |s| s.len()),
        }
    }

    /// The names of the inspected tracker's warp parameters (none for a whole tracker).
    pub fn inspected_param_names(&self) -> &'static [&'static str] {
        self.state
            .trackers
            .get(self.state.selected_tracker)
            .and_then(|t| t.spec.registration())
            .and_then(|r| crate::ssm::build(&r.ssm).ok())
            .map_or(&[][..], |m| m.param_names())
    }

    /// Whether a box or a quad is being drawn (pointer pressed, or corners clicked).
    pub fn drawing(&self) -> bool {
        match &self.rt.ui.tool {
            crate::app::Tool::DrawBox { start, .. } => start.is_some(),
            crate::app::Tool::DrawQuad { corners, .. } => !corners.is_empty(),
            _ => false,
        }
    }

    /// Whether the trackers are playing.
    pub fn is_playing(&self) -> bool {
        self.rt.run.playing
    }

    /// The last frame the trackers reached.
    pub fn tracked_until(&self) -> Option<usize> {
        self.rt.run.tracked_until
    }

    /// Where an image point was drawn on screen in the last frame view.
    pub fn screen_pos(&self, p: Point) -> Option<egui::Pos2> {
        self.rt.display.transform.map(|t| t.to_screen(p))
    }

    /// The iteration the convergence view and the frame view show (0-based).
    pub fn rt_selected_iteration(&self) -> Option<usize> {
        self.rt.ui.selected_iteration
    }

    /// Whether the keyboard help is open.
    pub fn help_shown(&self) -> bool {
        self.rt.ui.show_help
    }

    /// The running live source's progress (`None`: no live source runs).
    pub fn live(&self) -> Option<&crate::app::worker::LiveInfo> {
        self.rt.live.info.as_ref()
    }

    /// The last recording of a live source that ended: its ground-truth file and frames.
    pub fn last_recording(&self) -> Option<&(std::path::PathBuf, usize)> {
        self.rt.live.last_recording.as_ref()
    }

    /// The frame the view shows a "could not be read" placeholder for.
    pub fn bad_frame(&self) -> Option<usize> {
        self.rt.seq.bad_frame.as_ref().map(|b| b.0)
    }

    /// The status line.
    pub fn status(&self) -> &str {
        &self.rt.msg.status
    }

    /// Error messages shown.
    pub fn errors_shown(&self) -> &[String] {
        &self.rt.msg.errors
    }

    /// Whether corrections were made since the last export (they are in the journal either
    /// way).
    pub fn ground_truth_edited(&self) -> bool {
        self.rt.gt.corrections.unexported()
    }

    /// The open sequence.
    pub fn sequence(&self) -> Option<&Arc<Sequence>> {
        self.rt.seq.sequence.as_ref()
    }

    /// The frame tracker `t` was initialised on.
    /// Whether tracker `t` was initialised again on `frame` (see [`InspectorApp::restart_from`]).
    pub(super) fn reinit_on(&self, t: usize, frame: usize) -> bool {
        self.rt
            .run
            .reinits
            .get(t)
            .is_some_and(|r| r.contains(&frame))
    }

    pub(super) fn tracker_start(&self, t: usize) -> usize {
        self.rt
            .run
            .starts
            .get(t)
            .copied()
            .unwrap_or(self.state.start_frame)
    }

    /// Whether the cost landscape is shown in a window of its own.
    pub fn landscape_enlarged(&self) -> bool {
        self.rt.ui.landscape.enlarged
    }

    /// The cost landscape shown (the last one computed) and whether it is current.
    pub fn landscape_shown(&self) -> Option<(&Result<crate::landscape::Landscape, String>, bool)> {
        let (key, r) = self.rt.ui.landscape.result.as_ref()?;
        Some((
            r,
            self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()),
        ))
    }
    /// The frames both trackers of an A/B pair have a result on, ranked by how far apart their
    /// corners are, largest first (see [`rank_disagreements`]).
    pub fn disagreements(&self, a: usize, b: usize) -> Vec<Disagreement> {
        let (Some(ra), Some(rb)) = (self.rt.run.results.get(a), self.rt.run.results.get(b)) else {
            return Vec::new();
        };
        let lost = |r: &TrackerFrame| r.status != TrackStatus::Tracking;
        rank_disagreements(ra.iter().zip(rb).enumerate().filter_map(|(f, (x, y))| {
            let (x, y) = (x.as_ref()?, y.as_ref()?);
            Some((f, (lost(x), x.corners), (lost(y), y.corners)))
        }))
    }

    /// Whether stored results are being played back.
    pub fn is_replaying(&self) -> bool {
        self.rt.run.replaying.is_some()
    }

    /// The result of tracker `t` on `frame`.
    pub fn result(&self, t: usize, frame: usize) -> Option<&TrackerFrame> {
        // On the experiment's frame, the experiment's run (from its perturbed start).
        if let Some(r) = self
            .experiment_on(frame)
            .and_then(|e| e.results.as_ref())
            .and_then(|rs| rs.iter().find(|r| r.tracker == t))
        {
            return Some(r);
        }
        self.rt.run.results.get(t)?.get(frame)?.as_ref()
    }

    /// The convergence experiment, if it is on `frame`.
    pub fn experiment_on(&self, frame: usize) -> Option<&crate::app::Experiment> {
        self.rt.ui.experiment.as_ref().filter(|e| e.frame == frame)
    }

    /// Alignment errors of tracker `t` on the frames tracked after the start frame (lost frames
    /// are infinite), against the ground truth shown.
    pub fn errors(&self, t: usize) -> Vec<(usize, f64)> {
        let key: ErrorsKey = (
            self.rt.run.generation,
            self.rt.run.results.version(),
            self.rt.gt.corrections.version(),
            self.state.gt_ssm.clone(),
            self.state.start_frame,
        );
        if let Some((_, v)) = self
            .rt
            .run
            .errors_cache
            .borrow()
            .get(&t)
            .filter(|(k, _)| *k == key)
        {
            return v.clone();
        }
        let v = self.compute_errors(t);
        self.rt
            .run
            .errors_cache
            .borrow_mut()
            .insert(t, (key, v.clone()));
        v
    }

    fn compute_errors(&self, t: usize) -> Vec<(usize, f64)> {
        let Some(v) = self.rt.run.results.get(t) else {
            return Vec::new();
        };
        v.iter()
            .enumerate()
            .filter(|(f, r)| *f > self.tracker_start(t) && r.is_some() && !self.reinit_on(t, *f))
            .filter_map(|(f, r)| {
                let r = r.as_ref()?;
                let gt = self.ground_truth(f)?;
                let e = if r.status == TrackStatus::Tracking {
                    alignment_error(&r.corners, &gt)
                } else {
                    f64::INFINITY
                };
                Some((f, e))
            })
            .collect()
    }

    /// The confidence of tracker `t` per frame after its start frame, and whether it reported
    /// the frame lost: `(frame, confidence, lost)` (frames without a confidence are left out).
    pub fn confidences(&self, t: usize) -> Vec<(usize, f64, bool)> {
        let Some(v) = self.rt.run.results.get(t) else {
            return Vec::new();
        };
        v.iter()
            .enumerate()
            .filter(|(f, _)| *f > self.tracker_start(t))
            .filter_map(|(f, r)| {
                let r = r.as_ref()?;
                Some((f, r.confidence?, r.status != TrackStatus::Tracking))
            })
            .collect()
    }

    /// Speed of tracker `t` over the frames it tracked after the start frame (with or without
    /// ground truth): `(frames, search us, update us, iterations)`.
    pub fn speed(&self, t: usize) -> (usize, f64, f64, usize) {
        let Some(v) = self.rt.run.results.get(t) else {
            return (0, 0.0, 0.0, 0);
        };
        v.iter()
            .enumerate()
            .filter(|(f, _)| *f > self.tracker_start(t))
            .filter_map(|(_, r)| r.as_ref())
            .filter(|r| r.status == TrackStatus::Tracking)
            .fold((0, 0.0, 0.0, 0), |a, r| {
                (
                    a.0 + 1,
                    a.1 + r.search_us,
                    a.2 + r.update_us,
                    a.3 + r.iterations.len(),
                )
            })
    }

    /// Per frame tracked by tracker `t` after its start frame: `(frame, update us,
    /// iterations)` (the per-frame plots of speed and iterations).
    pub fn per_frame_speed(&self, t: usize) -> Vec<(usize, f64, usize)> {
        let Some(v) = self.rt.run.results.get(t) else {
            return Vec::new();
        };
        v.iter()
            .enumerate()
            .filter(|(f, _)| *f > self.tracker_start(t))
            .filter_map(|(f, r)| r.as_ref().map(|r| (f, r.update_us, r.iterations.len())))
            .collect()
    }

    /// The success curve of tracker `t` (from [`eval::success_curve`]).
    pub fn success_curve(&self, t: usize) -> Vec<(f64, f64)> {
        let e: Vec<f64> = self.errors(t).into_iter().map(|(_, e)| e).collect();
        if e.is_empty() {
            return Vec::new();
        }
        eval::success_curve(&e)
    }
}

/// How far apart an A/B pair is on a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disagreement {
    pub frame: usize,
    /// Alignment error of one's corners against the other's (px).
    pub px: f64,
    /// Which of the two (A, B) reported the frame lost.
    pub lost: [bool; 2],
}

/// Ranks frames by the distance between the two trackers' corners, largest first (ties: the
/// earlier frame). A tracker that reports a loss still has corners (where it last was or
/// searched), so a frame where one is lost ranks by how far it is from the other: the onset of
/// a loss, where the two part, comes before frames where the lost one happens to lie close.
/// Frames where both are lost say nothing about which is right and are left out, as are
/// corners that are not finite.
pub fn rank_disagreements(
    frames: impl Iterator<Item = (usize, (bool, Quad), (bool, Quad))>,
) -> Vec<Disagreement> {
    let mut v: Vec<Disagreement> = frames
        .filter(|(_, a, b)| !(a.0 && b.0))
        .map(|(frame, a, b)| Disagreement {
            frame,
            px: alignment_error(&a.1, &b.1),
            lost: [a.0, b.0],
        })
        .filter(|d| d.px.is_finite())
        .collect();
    v.sort_by(|p, q| q.px.total_cmp(&p.px).then(p.frame.cmp(&q.frame)));
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x: f64) -> Quad {
        Quad::from_rect(x, 0.0, 10.0, 10.0)
    }

    #[test]
    fn a_loss_ranks_by_the_distance_not_first_or_in_frame_order() {
        let frames = vec![
            (0, (false, square(0.0)), (false, square(1.0))),
            // B lost and far: the top.
            (1, (false, square(0.0)), (true, square(30.0))),
            // B lost but close: below a frame where both track 4 px apart.
            (2, (false, square(0.0)), (true, square(2.0))),
            (3, (false, square(0.0)), (false, square(4.0))),
            // Both lost: left out.
            (4, (true, square(0.0)), (true, square(50.0))),
            (
                5,
                (false, square(0.0)),
                (false, Quad([Point::new(f64::NAN, 0.0); 4])),
            ),
        ];
        let r = rank_disagreements(frames.into_iter());
        let order: Vec<usize> = r.iter().map(|d| d.frame).collect();
        assert_eq!(order, vec![1, 3, 2, 0]);
        assert_eq!(r[0].lost, [false, true]);
        assert!((r[0].px - 30.0).abs() < 1e-9);
    }
}
