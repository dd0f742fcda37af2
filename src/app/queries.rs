//! What the inspector shows, read from its state: results, errors, success curves, speed,
//! disagreements. Read-only: the panels call these.

use super::InspectorApp;
use super::runtime::ErrorsKey;
use super::worker::TrackerFrame;
use crate::dataset::Sequence;
use crate::eval;
use crate::geometry::{Point, alignment_error};
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
    pub(super) fn tracker_start(&self, t: usize) -> usize {
        self.rt
            .run
            .starts
            .get(t)
            .copied()
            .unwrap_or(self.state.start_frame)
    }

    /// The cost landscape shown (the last one computed) and whether it is current.
    pub fn landscape_shown(&self) -> Option<(&Result<crate::landscape::Landscape, String>, bool)> {
        let (key, r) = self.rt.ui.landscape.result.as_ref()?;
        Some((
            r,
            self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()),
        ))
    }

    /// The frames where trackers `a` and `b` disagree most: the alignment error between their
    /// corners (infinite where exactly one of them is lost), largest first.
    pub fn disagreements(&self, a: usize, b: usize) -> Vec<(usize, f64)> {
        let (Some(ra), Some(rb)) = (self.rt.run.results.get(a), self.rt.run.results.get(b)) else {
            return Vec::new();
        };
        let mut v: Vec<(usize, f64)> = ra
            .iter()
            .zip(rb)
            .enumerate()
            .filter_map(|(f, (x, y))| {
                let (x, y) = (x.as_ref()?, y.as_ref()?);
                let (lx, ly) = (
                    x.status != TrackStatus::Tracking,
                    y.status != TrackStatus::Tracking,
                );
                match (lx, ly) {
                    (false, false) => Some((f, alignment_error(&x.corners, &y.corners))),
                    (true, true) => None,
                    _ => Some((f, f64::INFINITY)),
                }
            })
            .collect();
        v.sort_by(|p, q| q.1.total_cmp(&p.1).then(p.0.cmp(&q.0)));
        v
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
            .filter(|(f, r)| *f > self.tracker_start(t) && r.is_some())
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

    /// The success curve of tracker `t` (from [`eval::success_curve`]).
    pub fn success_curve(&self, t: usize) -> Vec<(f64, f64)> {
        let e: Vec<f64> = self.errors(t).into_iter().map(|(_, e)| e).collect();
        if e.is_empty() {
            return Vec::new();
        }
        eval::success_curve(&e)
    }
}
