//! The worker's replies, each handled once: a sequence opened, a frame decoded or tracked, a
//! live source's news, an experiment's or a task's result.

use super::command::Command;
use super::state::{InitSource, SequenceSource};
use super::worker::{Job, Reply};
use super::{InspectorApp, PATCH_FRAMES, Tool};

impl InspectorApp {
    /// Handles the worker's replies, each once.
    pub(super) fn poll_worker(&mut self) {
        for r in self.rt.worker.poll() {
            match r {
                Reply::Progress(what, d, t) => {
                    self.rt.msg.progress = (!what.is_empty()).then_some((what, d, t))
                }
                // A sequence opened before a live source replaced it (the worker closed it).
                Reply::Opened(_) if self.is_live() => self.rt.msg.progress = None,
                Reply::Opened(seq) => self.opened(seq),
                Reply::Image(img) => self.image_decoded(img),
                Reply::Frame {
                    generation,
                    frame,
                    results,
                    image,
                    catch_up,
                } => {
                    if generation == self.rt.run.generation {
                        self.tracked(frame, results, image, catch_up);
                    }
                }
                Reply::Stopped { generation, .. } => {
                    if generation == self.rt.run.generation {
                        self.rt.run.playing = false;
                    }
                }
                Reply::Error { context, error } => {
                    self.rt.msg.progress = None;
                    self.rt.seq.opening = None;
                    self.rt.seq.fresh = false;
                    self.error(format!("{context}: {error}"));
                }
                Reply::Landscape { key, result } => {
                    if self.rt.ui.landscape.requested.as_deref() == Some(key.as_str()) {
                        self.rt.ui.landscape.result =
                            Some((key, result.map(|l| *l).map_err(|e| e.to_string())));
                    }
                }
                Reply::FrameError { index, error } => {
                    self.rt.msg.progress = None;
                    let message = error.to_string();
                    self.error(format!("frame {}: {message}", index + 1));
                    self.rt.seq.bad_frame = Some((index, message));
                }
                Reply::Proposal { label, result } => self.proposal_arrived(label, result),
                Reply::Live(info) => {
                    if self.rt.live.info.is_some() {
                        self.rt.live.info = Some(info);
                    }
                }
                Reply::LiveEnded { error } => self.live_ended(error),
                Reply::Experiment { key, results } => self.experiment_done(key, results),
                Reply::Patches { from, result } => self.patches_done(from, result),
                Reply::Frequency { frame, result } => self.frequency_done(frame, result),
                Reply::Exported(result) => match result {
                    Ok(files) => {
                        let dir = files
                            .first()
                            .and_then(|f| f.parent())
                            .map(|d| d.to_path_buf())
                            .unwrap_or_default();
                        let stems: std::collections::BTreeSet<String> = files
                            .iter()
                            .filter_map(|f| f.file_stem())
                            .map(|s| s.to_string_lossy().into_owned())
                            .collect();
                        self.rt.msg.status = format!(
                            "wrote {} figures (SVG and PNG) to {}: {}",
                            stems.len(),
                            dir.display(),
                            stems.into_iter().collect::<Vec<_>>().join(", ")
                        );
                        self.rt.ui.exported = Some(dir);
                    }
                    Err(e) => self.error(format!("cannot export the plots: {e}")),
                },
                Reply::RecordingEnded { path, frames } => {
                    self.rt.msg.status =
                        format!("recorded {frames} frames as a sequence: {}", path.display());
                    // In the Recent list too: it stays at hand once another sequence opens.
                    if frames > 0 {
                        self.add_recent(&path);
                    }
                    self.rt.live.last_recording = Some((path, frames));
                }
                Reply::Picked(path) => self.picked(path),
            }
        }
    }

    /// A sequence opened: it is shown from its start (or a session's frame, tracked up to).
    fn opened(&mut self, seq: std::sync::Arc<crate::dataset::Sequence>) {
        self.rt.msg.progress = None;
        // A new sequence (not a session's): nothing of the old one's frames carries
        // over. (Reset only now: a failed open leaves the shown sequence as it was.)
        if std::mem::take(&mut self.rt.seq.fresh) {
            self.state.start_frame = 0;
            self.state.frame = 0;
            for t in &mut self.state.trackers {
                t.init = InitSource::GroundTruth;
            }
        }
        self.rt.msg.status = format!("{}: {} frames", seq.name, seq.len());
        let start = self.state.start_frame.min(seq.len() - 1);
        if let Some(src) = self.rt.seq.opening.take() {
            if let SequenceSource::Path(p) = &src {
                self.add_recent(&p.clone());
            }
            // Another sequence: the recording's button goes (it is in the Recent list).
            if !matches!(&src, SequenceSource::Path(p)
                if self.rt.live.last_recording.as_ref().is_some_and(|(r, _)| r == p))
            {
                self.rt.live.last_recording = None;
            }
            self.state.sequence = src;
        }
        // Errors of an earlier attempt are stale now; those raised since it was asked for stay.
        let stale = std::mem::take(&mut self.rt.msg.before_open);
        self.rt.msg.errors.retain(|e| !stale.contains(e));
        self.rt.seq.bad_frame = None;
        if let Some(w) = seq.warnings.first() {
            self.error(format!(
                "{w}{}",
                match seq.warnings.len() {
                    1 => String::new(),
                    n => format!(" (and {} more such lines)", n - 1),
                }
            ));
        }
        // What was measured on the old sequence's frames is not this one's (a late answer
        // of a request in flight finds nothing to fill and is dropped).
        self.rt.ui.frequency = None;
        self.rt.ui.patches = None;
        self.rt.ui.landscape.requested = None;
        self.rt.ui.landscape.result = None;
        self.open_corrections(&seq);
        let restore = self.rt.seq.restore_frame.take();
        let n = seq.len();
        self.rt.seq.sequence = Some(seq);
        self.rt.display.texture_frame = None;
        self.restart(start);
        // A session's saved frame: track up to it.
        if let Some(f) = restore.map(|f| f.min(n - 1)).filter(|&f| f > start)
            && self.rt.screenshot.is_none()
        {
            self.rt.run.playing = true;
            self.rt.worker.send(Job::Advance {
                generation: self.rt.run.generation,
                frames: Some(f - start),
                fps: 0.0,
            });
        }
    }

    /// A frame decoded for display.
    fn image_decoded(&mut self, img: super::decoder::FrameImage) {
        if self
            .rt
            .seq
            .bad_frame
            .as_ref()
            .is_some_and(|b| b.0 == img.index)
        {
            self.rt.seq.bad_frame = None;
        }
        if img.index == self.state.frame {
            self.rt.display.pending_image = Some(img);
        }
    }

    /// The trackers' results on `frame` (of this run), kept; the view follows them.
    fn tracked(
        &mut self,
        frame: usize,
        results: Vec<super::worker::TrackerFrame>,
        image: Option<super::decoder::FrameImage>,
        catch_up: bool,
    ) {
        let stored = self.rt.run.results.edit();
        for r in results {
            if let Some(v) = stored.get_mut(r.tracker) {
                if v.len() <= frame {
                    v.resize(frame + 1, None);
                }
                // Samples and particles are kept for the newest frame only, the
                // iterations' patches for the newest PATCH_FRAMES (memory stays
                // bounded on long sequences).
                if let Some(Some(prev)) = frame.checked_sub(1).and_then(|p| v.get_mut(p)) {
                    prev.visual = None;
                }
                if let Some(Some(old)) = frame.checked_sub(PATCH_FRAMES).and_then(|p| v.get_mut(p))
                {
                    for it in &mut old.iterations {
                        it.patch = Vec::new();
                    }
                }
                v[frame] = Some(r);
            }
        }
        if catch_up {
            // One tracker re-run over frames the others reached: the view stays.
            return;
        }
        self.rt.run.tracked_until = Some(frame);
        // Live, the image holds while a box or a quad is being drawn on it (the
        // tracker then starts on the frame it was drawn on).
        if self.is_live() && self.drawing() {
            return;
        }
        // Follow the trackers while they run.
        self.state.frame = frame;
        if std::mem::take(&mut self.rt.run.play_after_start) {
            self.send(Command::Play);
        }
        if let Some(img) = image {
            self.rt.display.pending_image = Some(img);
        }
    }

    /// The live source ended (with why, if it failed).
    fn live_ended(&mut self, error: Option<String>) {
        let source = self.rt.live.info.take().map(|i| i.source);
        // Nothing of the live run is shown any more: no "1 of 0 ... tracked to frame 1403".
        self.rt.run.tracked_until = None;
        self.rt.run.playing = false;
        self.state.frame = 0;
        self.rt.ui.tool = Tool::Navigate;
        if error.is_some() {
            self.rt.msg.status = "the live source stopped".into();
        }
        match error {
            Some(e) => self.error(match &self.rt.live.last_recording {
                Some((p, n)) if source.is_some() => {
                    format!("{e}; the recording of {n} frames is kept: {}", p.display())
                }
                _ => e,
            }),
            None => {
                if let Some(s) = source {
                    self.rt.msg.status = format!("live source {s} closed");
                }
            }
        }
    }

    /// The convergence experiment's runs.
    fn experiment_done(&mut self, key: u64, results: Vec<super::worker::TrackerFrame>) {
        if let Some(e) = self.rt.ui.experiment.as_mut()
            && e.key == key
        {
            let converged: Vec<String> = results
                .iter()
                .map(|r| {
                    format!(
                        "tracker {}: {} iterations",
                        r.tracker + 1,
                        r.iterations.len()
                    )
                })
                .collect();
            e.results = Some(results);
            self.rt.ui.selected_iteration = Some(0);
            self.rt.msg.status = format!(
                "experiment, start {} (σ {} px): {}; step with . and , (Esc clears)",
                e.number,
                e.sigma,
                converged.join(", ")
            );
        }
    }

    /// The many patches tracked from `from`.
    fn patches_done(&mut self, from: usize, result: Result<crate::patches::PatchRun, String>) {
        if let Some(p) = self.rt.ui.patches.as_mut().filter(|p| p.from == from) {
            match result {
                Ok(run) => {
                    let last = run
                        .frames
                        .last()
                        .map_or(0, |f| f.iter().filter(|s| s.tracking()).count());
                    self.rt.msg.status = format!(
                        "{} patches tracked from frame {} over {} frames ({:.0} frames/s); {} still tracking at the end",
                        run.patches(),
                        from + 1,
                        run.frames.len(),
                        run.frames_per_second(),
                        last
                    );
                    p.result = Some(Ok(std::sync::Arc::new(run)));
                }
                Err(e) => {
                    p.result = Some(Err(e.clone()));
                    self.error(format!("tracking patches: {e}"));
                }
            }
        }
    }

    /// The frequency of convergence on `frame`.
    #[allow(clippy::type_complexity)]
    fn frequency_done(
        &mut self,
        frame: usize,
        result: Result<Vec<(usize, crate::converge::ConvergeCurve)>, String>,
    ) {
        if let Some(f) = self.rt.ui.frequency.as_mut().filter(|f| f.frame == frame) {
            match &result {
                Ok(curves) => {
                    let means: Vec<String> = curves
                        .iter()
                        .map(|(i, c)| format!("{} {:.2}", i + 1, c.mean()))
                        .collect();
                    self.rt.msg.status = format!(
                        "frequency of convergence on frame {}: mean fraction {}",
                        frame + 1,
                        means.join(", ")
                    );
                }
                Err(e) => self.rt.msg.status = format!("the frequency of convergence failed: {e}"),
            }
            f.result = Some(result);
        }
    }

    /// The file dialog's choice.
    fn picked(&mut self, path: Option<std::path::PathBuf>) {
        self.rt.ui.dialog = false;
        match path {
            Some(p) => self.apply(Command::OpenSequence(SequenceSource::Path(p))),
            None => {
                self.rt.msg.status = "no file chosen (without a desktop portal the \
                                          dialog cannot open: type the path)"
                    .into()
            }
        }
    }
}
