//! Sessions, preferences and sources: saving and loading a session, the recent list, opening a
//! sequence (by path, dialog or drop) or a live source, and recording it.

use super::command::Command;
use super::state::{InitSource, SequenceSource, State};
use super::worker::{Job, Reply};
use super::{InspectorApp, Tool, prefs, worker};
use eframe::egui;
use std::path::PathBuf;

impl InspectorApp {
    /// The session file the session field shows (and *Save session* writes), as the file the
    /// session came from (saving there again asks nothing).
    pub fn set_session_path(&mut self, p: &std::path::Path) {
        self.rt.ui.session_path = p.display().to_string();
        self.rt.ui.session_file = Some(p.to_path_buf());
        let p = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        self.rt.ui.prefs.add_recent_session(&p);
        self.save_prefs();
    }

    /// Writes the preferences when they are kept (an error once, naming the file).
    pub(super) fn save_prefs(&mut self) {
        if let Some(path) = &self.rt.ui.prefs_path
            && let Err(e) = self.rt.ui.prefs.save(path)
        {
            self.error(format!("cannot keep the preferences: {e}"));
        }
    }

    /// The file this session was loaded from or last saved to.
    pub fn session_file(&self) -> Option<&std::path::Path> {
        self.rt.ui.session_file.as_deref()
    }

    /// The sessions to offer in the Sessions menu (recent first).
    pub fn session_choices(&self) -> Vec<std::path::PathBuf> {
        self.rt.ui.prefs.session_choices()
    }

    /// The saved share of the window of side panel `name`, if any.
    pub fn panel_share(&self, name: &str) -> Option<f32> {
        self.rt.ui.prefs.panels.get(name).copied()
    }

    /// Keeps the preferences (the recent sequences) in `path` between runs: reads them now
    /// (a file that cannot be read is one error, and the defaults), writes them on every change.
    pub fn use_prefs(&mut self, path: PathBuf) {
        match prefs::Prefs::load(&path) {
            Ok(p) => self.rt.ui.prefs = p,
            Err(e) => self.error(format!("cannot read the preferences (recent list): {e}")),
        }
        self.rt.ui.prefs_path = Some(path);
    }

    /// The recently opened sequences, newest first.
    pub fn recent(&self) -> &[PathBuf] {
        &self.rt.ui.prefs.recent
    }

    pub(super) fn add_recent(&mut self, p: &std::path::Path) {
        self.rt.ui.prefs.add_recent(p);
        self.save_prefs();
    }

    /// Saves the session to `p`; over an existing file other than the session's own, only
    /// after the user confirms (`confirmed`).
    pub(super) fn save_session(&mut self, p: PathBuf, confirmed: bool) {
        let own = self.rt.ui.session_file.as_ref() == Some(&p);
        if p.exists() && !own && !confirmed {
            self.rt.msg.status = format!("{} exists: overwrite it?", p.display());
            self.rt.ui.confirm_overwrite = Some(p);
            return;
        }
        self.rt.ui.confirm_overwrite = None;
        let replaced = p.exists();
        match self.state.save(&p) {
            Ok(()) => {
                self.rt.msg.status = if replaced {
                    format!("saved session {} (replaced the file)", p.display())
                } else {
                    format!("saved session {}", p.display())
                };
                self.set_session_path(&p);
            }
            Err(e) => self.error(format!("cannot save the session: {e}")),
        }
    }

    /// The save that waits for the user's yes (see [`Command::ConfirmOverwrite`]).
    pub fn overwrite_pending(&self) -> Option<&std::path::Path> {
        self.rt.ui.confirm_overwrite.as_deref()
    }

    /// Replaces the session (the trackers then run up to its saved frame).
    pub(super) fn load_state(&mut self, state: State) {
        let src = state.sequence.clone();
        self.rt.seq.restore_frame = Some(state.frame);
        self.state = state;
        *self.rt.run.results.edit() = vec![Vec::new(); self.state.trackers.len()];
        self.open(src);
    }

    pub(super) fn open(&mut self, src: SequenceSource) {
        self.rt.run.playing = false;
        // A sequence replaces a live source (the worker closes it).
        self.rt.live.info = None;
        self.rt.msg.progress = Some(("opening the sequence".into(), 0, 0));
        // The session and the recent list change once it opened (a failed open changes nothing).
        self.rt.seq.opening = Some(src.clone());
        self.rt.msg.before_open = self.rt.msg.errors.clone();
        self.rt.worker.send(Job::Open(src));
    }

    /// Opens a live source (`/dev/videoN`, or `lavfi:<graph>` for an FFmpeg test source): its
    /// frames are shown as they come; a box drawn on the image starts a tracker on the frame
    /// it was drawn on.
    pub(super) fn open_live(&mut self, source: String, width: usize, height: usize) {
        self.rt.run.playing = false;
        self.rt.run.replaying = None;
        self.rt.run.generation += 1;
        self.rt.run.tracked_until = None;
        self.rt.ui.selected_iteration = None;
        self.rt.seq.sequence = None;
        self.rt.seq.opening = None;
        self.rt.seq.bad_frame = None;
        self.rt.display.texture = None;
        self.rt.display.texture_frame = None;
        self.rt.display.pending_image = None;
        self.state.start_frame = 0;
        self.state.frame = 0;
        // No ground truth live: every tracker waits for a box.
        for t in &mut self.state.trackers {
            t.init = InitSource::GroundTruth;
        }
        self.rt.run.starts = vec![0; self.state.trackers.len()];
        self.rt.run.reinits = Vec::new();
        *self.rt.run.results.edit() = vec![Vec::new(); self.state.trackers.len()];
        self.rt.live.info = Some(worker::LiveInfo {
            source: source.clone(),
            ..Default::default()
        });
        self.rt.msg.errors.clear();
        self.rt.msg.progress = None;
        self.rt.msg.status = format!(
            "live: {source}; drag a box on the image (Trackers panel: Draw box) to start a tracker"
        );
        if !self.state.trackers.is_empty() {
            let tracker = self
                .state
                .selected_tracker
                .min(self.state.trackers.len() - 1);
            self.rt.ui.tool = Tool::DrawBox {
                tracker,
                start: None,
            };
        }
        self.rt.worker.send(Job::Live {
            generation: self.rt.run.generation,
            source,
            width,
            height,
        });
    }

    /// Opens a file dialog on a thread of its own (the window keeps drawing meanwhile); the
    /// path comes back as a worker reply.
    pub(super) fn open_dialog(&mut self, folder: bool) {
        if self.rt.ui.dialog {
            return;
        }
        let spawned = self.rt.worker.spawn_task("file-dialog", move || {
            let d = rfd::FileDialog::new();
            Reply::Picked(if folder {
                d.pick_folder()
            } else {
                let mut exts = vec!["txt"];
                exts.extend_from_slice(crate::dataset::video::VIDEO_EXTENSIONS);
                d.add_filter("ground truth or video", &exts)
                    .add_filter("ground truth", &["txt"])
                    .add_filter("video", crate::dataset::video::VIDEO_EXTENSIONS)
                    .pick_file()
            })
        });
        match spawned {
            Ok(()) => self.rt.ui.dialog = true,
            Err(e) => self.error(format!(
                "cannot open a file dialog ({e}): type the path instead"
            )),
        }
    }

    pub(super) fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if let Some(p) = dropped.into_iter().next() {
            self.send(Command::OpenSequence(SequenceSource::Path(p)));
        }
    }

    /// The user's answer to the overwrite question.
    pub(super) fn confirm_overwrite(&mut self, yes: bool) {
        if let Some(p) = self.rt.ui.confirm_overwrite.take() {
            if yes {
                self.save_session(p, true);
            } else {
                self.rt.msg.status = format!("not saved: {} kept", p.display());
            }
        }
    }

    pub(super) fn load_session(&mut self, p: PathBuf) {
        match State::load(&p) {
            Ok(s) => {
                self.set_session_path(&p);
                self.load_state(s);
            }
            Err(e) => self.error(format!("cannot load the session: {e}")),
        }
    }

    /// Starts (into the record folder, with the selected tracker's corners) or stops recording
    /// the live frames.
    pub(super) fn record(&mut self, on: bool) {
        let what = on.then(|| {
            (
                PathBuf::from(self.rt.live.record_folder.trim()),
                self.state.selected_tracker,
            )
        });
        self.rt.worker.send(Job::Record(what));
    }
}
