//! The experiments on the shown frame: a perturbed start stepped through (the convergence
//! experiment), the frequency of convergence, the many patches from here, the cost landscape.

use super::worker::{Job, Reply};
use super::{InspectorApp, runtime, worker};

impl InspectorApp {
    /// Starts the convergence experiment on the shown frame (see [`Command::Perturb`]).
    pub(super) fn perturb(&mut self) {
        let frame = self.state.frame;
        let i = self.state.selected_tracker;
        let truth = self.ground_truth(frame);
        let base = truth.or_else(|| {
            self.rt
                .run
                .results
                .get(i)
                .and_then(|v| v.get(frame))
                .and_then(|r| r.as_ref())
                .map(|r| r.corners)
        });
        let Some(base) = base else {
            self.error(format!(
                "nothing to perturb on frame {}: give it ground truth or track it first",
                frame + 1
            ));
            return;
        };
        let mut trackers = Vec::new();
        for (k, t) in self
            .state
            .trackers
            .iter()
            .enumerate()
            .filter(|(_, t)| t.enabled)
        {
            let from = self.tracker_start(k);
            if let Some(q) = self.init_quad(&t.init, from) {
                trackers.push((k, t.spec.clone(), from, q));
            }
        }
        if trackers.is_empty() {
            self.error("no tracker to run the experiment: initialise one first".into());
            return;
        }
        let sigma = self.rt.ui.perturb_sigma;
        let n = self.rt.ui.perturbations;
        self.rt.ui.perturbations += 1;
        let start = crate::converge::perturbed(&base, sigma, 0, n as usize);
        let key = self.rt.ui.experiment.as_ref().map_or(0, |e| e.key) + 1;
        self.rt.ui.experiment = Some(runtime::Experiment {
            key,
            frame,
            start,
            sigma,
            from_truth: truth.is_some(),
            number: n + 1,
            results: None,
        });
        self.rt.ui.selected_iteration = None;
        self.rt.msg.status = format!("experiment: start {} at σ {sigma} px…", n + 1);
        self.rt
            .worker
            .send(Job::Experiment(Box::new(worker::ExperimentJob {
                key,
                frame,
                start,
                trackers,
            })));
    }

    /// Runs the frequency of convergence of every enabled registration tracker on the shown
    /// frame, around its ground truth, on a thread of its own (see [`Command::ConvergenceFrequency`]).
    pub(super) fn convergence_frequency(&mut self, starts: usize) {
        let frame = self.state.frame;
        let starts = starts.clamp(1, 1000);
        self.rt.ui.frequency_starts = starts;
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        let Some(truth) = self.ground_truth(frame) else {
            self.error(format!(
                "the frequency of convergence needs ground truth on frame {}",
                frame + 1
            ));
            return;
        };
        let trackers: Vec<(usize, crate::tracker::TrackerSpec)> = self
            .state
            .trackers
            .iter()
            .enumerate()
            .filter(|(_, t)| t.enabled && t.spec.registration().is_some())
            .map(|(i, t)| (i, t.spec.clone()))
            .collect();
        if trackers.is_empty() {
            self.error("no enabled registration tracker to run".into());
            return;
        }
        if self
            .rt
            .ui
            .frequency
            .as_ref()
            .is_some_and(|f| f.result.is_none())
        {
            self.rt.msg.status = "the frequency of convergence is running".into();
            return;
        }
        self.rt.ui.frequency = Some(runtime::Frequency {
            frame,
            starts,
            result: None,
        });
        self.rt.msg.status = format!(
            "frequency of convergence on frame {}: {} tracker(s) x 10 noise levels x {starts} starts…",
            frame + 1,
            trackers.len()
        );
        let spawned = self.rt.worker.spawn_task("convergence", move || {
            let run = || -> crate::Result<Vec<(usize, crate::converge::ConvergeCurve)>> {
                // In colour when a tracker reads colour.
                let colour = trackers.iter().any(|(_, t)| t.reads_colour());
                let img = seq.load_frame(frame, colour)?;
                let spec = crate::converge::ConvergeSpec {
                    starts,
                    ..Default::default()
                };
                trackers
                    .iter()
                    .map(|(i, t)| {
                        crate::converge::frequency_of_convergence(t, &img, &truth, &spec)
                            .map(|c| (*i, c))
                    })
                    .collect()
            };
            Reply::Frequency {
                frame,
                result: run().map_err(|e| e.to_string()),
            }
        });
        if let Err(e) = spawned {
            self.rt.ui.frequency = None;
            self.error(format!("cannot run the frequency of convergence: {e}"));
        }
    }

    /// Tracks the session's patches from the shown frame to the end on a thread of its own (see
    /// [`Command::TrackPatches`]).
    pub(super) fn track_patches(&mut self) {
        let from = self.state.frame;
        let Some(seq) = self.rt.seq.sequence.clone() else {
            return;
        };
        if self
            .rt
            .ui
            .patches
            .as_ref()
            .is_some_and(|p| p.result.is_none())
        {
            self.rt.msg.status = "patches are being tracked".into();
            return;
        }
        let count = self.state.patches.count.clamp(
            *crate::session::PATCH_COUNT.start(),
            *crate::session::PATCH_COUNT.end(),
        );
        let params = match self.state.patches.patch_params() {
            Ok(p) => p,
            Err(e) => return self.error(e.to_string()),
        };
        self.rt.ui.patches = Some(runtime::Patches {
            from,
            count,
            affine: params.warp == crate::patches::PatchWarp::Affine,
            half: (params.size as f64 - 1.0) / 2.0,
            result: None,
        });
        self.rt.msg.status = format!("tracking {count} patches from frame {}…", from + 1);
        let spawned = self.rt.worker.spawn_task("patches", move || {
            let seeds = crate::patches::PatchSeeds::Corners(count);
            Reply::Patches {
                from,
                result: crate::patches::track_sequence_from(
                    &seq,
                    from,
                    &params,
                    &seeds,
                    &mut |_| {},
                )
                .map_err(|e| e.to_string()),
            }
        });
        if let Err(e) = spawned {
            self.rt.ui.patches = None;
            self.error(format!("cannot track patches: {e}"));
        }
    }

    /// The patches tracked last (or being tracked).
    pub fn patches(&self) -> Option<&runtime::Patches> {
        self.rt.ui.patches.as_ref()
    }

    /// The patches' states on `frame`, with half a patch's side, when a run reached it.
    pub fn patches_on(&self, frame: usize) -> Option<(&[crate::patches::PatchState], f64)> {
        let p = self.rt.ui.patches.as_ref()?;
        let run = p.result.as_ref()?.as_ref().ok()?;
        let k = frame.checked_sub(run.first)?;
        run.frames.get(k).map(|f| (f.as_slice(), p.half))
    }

    /// The frequency of convergence run last (or running).
    pub fn frequency(&self) -> Option<&runtime::Frequency> {
        self.rt.ui.frequency.as_ref()
    }

    /// Asks the worker for the cost landscape of the inspected tracker on the shown frame when
    /// the view is open and what it shows changed.
    pub(super) fn request_landscape(&mut self) {
        if !self.state.view.show_landscape {
            return;
        }
        let (i, frame) = (self.state.selected_tracker, self.state.frame);
        let Some(t) = self.state.trackers.get(i).cloned() else {
            return;
        };
        let start = self.tracker_start(i);
        let Some(r) = self.result(i, frame) else {
            return;
        };
        let estimate = r.corners;
        let init = self.init_quad(&t.init, start);
        let at = if self.state.view.landscape.around_truth {
            self.ground_truth(frame)
        } else {
            Some(estimate)
        };
        let (Some(init), Some(at)) = (init, at) else {
            return;
        };
        let v = &self.state.view.landscape;
        let mut axes = vec![v.x];
        axes.extend(v.y.filter(|&y| y != v.x));
        let sweep = crate::landscape::LandscapeSpec {
            steps: if axes.len() == 1 { 81 } else { 41 },
            axes,
            radius: v.radius,
        };
        let key = format!("{:?}|{start}|{init}|{frame}|{at}|{sweep:?}", t.spec);
        if self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()) {
            return;
        }
        self.rt.ui.landscape.requested = Some(key.clone());
        self.rt
            .worker
            .send(Job::Landscape(Box::new(worker::LandscapeJob {
                key,
                spec: t.spec,
                start,
                init,
                frame,
                at,
                sweep,
            })));
    }
}
