//! The trackers' runs: (re)starting them on a frame, re-running one, playing, pausing,
//! seeking, and replaying stored results.

use super::InspectorApp;
use super::command::Command;
use super::state::InitSource;
use super::worker::Job;
use eframe::egui;

impl InspectorApp {
    /// The corners a tracker starts from on `frame`: its own quad, or the ground truth there.
    pub(super) fn init_quad(
        &self,
        init: &InitSource,
        frame: usize,
    ) -> Option<crate::geometry::Quad> {
        match init {
            InitSource::Quad(q) => Some(*q),
            InitSource::GroundTruth => self.ground_truth(frame),
        }
    }

    /// Re-initialises every enabled tracker on `frame` and shows it.
    pub(super) fn restart(&mut self, frame: usize) {
        self.restart_from(frame, false);
    }

    /// Re-initialises every enabled tracker on `frame` and shows it; with `keep_before`, the
    /// results on the frames before it stay (the plots keep them; `frame` is then a
    /// re-initialisation, left out of the errors as the start frame is).
    pub(super) fn restart_from(&mut self, frame: usize, keep_before: bool) {
        let n = self.frame_count();
        if n == 0 {
            return;
        }
        let frame = frame.min(n - 1);
        let keep = keep_before && frame > self.state.start_frame;
        self.rt.run.generation += 1;
        self.rt.run.playing = false;
        self.rt.run.tracked_until = None;
        self.rt.ui.selected_iteration = None;
        self.rt.ui.experiment = None;
        self.state.frame = frame;
        self.rt.run.replaying = None;
        let count = self.state.trackers.len();
        if keep {
            self.rt.run.starts.resize(count, self.state.start_frame);
            self.rt.run.reinits.resize(count, Vec::new());
            for (i, r) in self.rt.run.reinits.iter_mut().enumerate() {
                if self.rt.run.starts[i] < frame {
                    r.retain(|&f| f < frame);
                    r.push(frame);
                } else {
                    self.rt.run.starts[i] = frame;
                    r.clear();
                }
            }
        } else {
            self.state.start_frame = frame;
            self.rt.run.starts = vec![frame; count];
            self.rt.run.reinits = vec![Vec::new(); count];
        }
        let results = self.rt.run.results.edit();
        results.resize(count, Vec::new());
        for r in results {
            r.truncate(if keep { frame } else { 0 });
        }
        let mut specs = Vec::new();
        let mut missing = Vec::new();
        for (i, t) in self
            .state
            .trackers
            .iter()
            .enumerate()
            .filter(|(_, t)| t.enabled)
        {
            match self.init_quad(&t.init, frame) {
                Some(q) => specs.push((i, t.spec.clone(), q)),
                None => missing.push(i + 1),
            }
        }
        if !missing.is_empty() {
            self.error(format!(
                "no ground truth on frame {}: draw a quad or a box for tracker(s) {:?}",
                frame + 1,
                missing
            ));
        }
        self.rt.worker.send(Job::Start {
            generation: self.rt.run.generation,
            frame,
            trackers: specs,
        });
    }

    /// Re-runs tracker `i` alone, from its start frame up to the frame the others reached; the
    /// view stays on its frame.
    pub(super) fn rerun_tracker(&mut self, i: usize) {
        let n = self.frame_count();
        if n == 0 {
            return;
        }
        let Some(t) = self.state.trackers.get(i).cloned() else {
            return;
        };
        if self.rt.run.playing {
            self.rt.run.playing = false;
            self.rt.worker.stop();
        }
        self.rt
            .run
            .starts
            .resize(self.state.trackers.len(), self.state.start_frame);
        let results = self.rt.run.results.edit();
        results.resize(self.state.trackers.len(), Vec::new());
        results[i].clear();
        // It runs straight through from its start: no re-initialisation on the way.
        if let Some(r) = self.rt.run.reinits.get_mut(i) {
            r.clear();
        }
        let from = self.rt.run.starts[i].min(n - 1);
        let until = self.rt.run.tracked_until.unwrap_or(from).max(from);
        let tracker = if t.enabled {
            match self.init_quad(&t.init, from) {
                Some(q) => Some(Box::new((t.spec.clone(), q))),
                None => {
                    self.error(format!(
                        "no ground truth on frame {}: draw a quad or a box for tracker {}",
                        from + 1,
                        i + 1
                    ));
                    None
                }
            }
        } else {
            None
        };
        self.rt.worker.send(Job::Rerun {
            generation: self.rt.run.generation,
            index: i,
            tracker,
            from,
            until,
        });
    }

    /// Plays back stored results (Play on a frame the trackers already passed): the shown frame
    /// advances at the playback speed (30 fps when "as fast as the trackers go"), and tracking
    /// goes on from the last tracked frame.
    pub(super) fn replay(&mut self, ctx: &egui::Context) {
        let Some(last) = self.rt.run.replaying else {
            return;
        };
        ctx.request_repaint();
        let fps = if self.state.playback_fps > 0.0 {
            self.state.playback_fps
        } else {
            30.0
        };
        if last.elapsed().as_secs_f32() < 1.0 / fps
            || self.rt.display.texture_frame != Some(self.state.frame)
        {
            return;
        }
        let until = self.rt.run.tracked_until.unwrap_or(0);
        if self.state.frame < until {
            self.state.frame += 1;
            self.rt.ui.selected_iteration = None;
            self.rt.run.replaying = Some(std::time::Instant::now());
        } else {
            self.rt.run.replaying = None;
            if until + 1 < self.frame_count() {
                self.send(Command::Play);
            } else {
                self.rt.msg.status = "end of the sequence".into();
            }
        }
    }

    /// Plays: replays the stored results up to the last tracked frame, then tracks on.
    pub(super) fn play(&mut self) {
        let n = self.frame_count();
        let until = self.rt.run.tracked_until;
        let start = self.state.start_frame;
        // Nothing tracked past the start frame and a later frame shown (a video sought to
        // frame 199): the trackers start on the shown frame (they started from frame 1).
        let fresh = until.is_none_or(|u| u <= start)
            && self.state.frame > start
            && self
                .state
                .trackers
                .iter()
                .all(|t| t.init == InitSource::GroundTruth);
        if n == 0 {
        } else if fresh {
            let frame = self.state.frame;
            self.restart_from(frame, false);
            self.rt.run.play_after_start = true;
            self.rt.msg.status = format!("tracking from frame {}, the one shown", frame + 1);
        } else if until.is_some_and(|u| self.state.frame < u) {
            self.rt.run.replaying = Some(std::time::Instant::now());
        } else if until.is_some_and(|u| u + 1 >= n) {
            self.rt.msg.status = "at the end of the sequence: |< Start and Play replays, \
                              Re-run from here tracks again"
                .into();
        } else {
            self.rt.run.playing = true;
            self.rt.worker.send(Job::Advance {
                generation: self.rt.run.generation,
                frames: None,
                fps: self.state.playback_fps,
            });
        }
    }

    pub(super) fn pause(&mut self) {
        self.rt.run.playing = false;
        self.rt.run.replaying = None;
        self.rt.worker.stop();
    }

    /// Shows frame `i` (playing stops).
    pub(super) fn seek(&mut self, i: usize) {
        self.rt.run.replaying = None;
        if self.rt.run.playing {
            self.rt.run.playing = false;
            self.rt.worker.stop();
        }
        let n = self.frame_count();
        if n > 0 {
            self.state.frame = i.min(n - 1);
            self.rt.ui.selected_iteration = None;
            self.rt.worker.send(Job::Show(self.state.frame));
        }
    }

    /// 0 (as fast as possible), or a speed in the widget's range.
    pub(super) fn set_playback_fps(&mut self, f: f32) {
        self.state.playback_fps = if f > 0.0 {
            f.clamp(
                *super::state::PLAYBACK_FPS.start(),
                *super::state::PLAYBACK_FPS.end(),
            )
        } else {
            0.0
        };
    }
}
