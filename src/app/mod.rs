//! The inspector: an interactive desktop application (eframe/egui) to load a sequence, pick
//! trackers (AM, SSM, SM) from the registries, watch them track against the ground truth, read
//! live success-rate and error plots, step through the iterations of a frame, and correct the
//! ground truth by hand.
//!
//! Layout of the code (as in rerun): [`state::State`] is what a session saves; the panels read it
//! and push [`command::Command`]s that [`InspectorApp::apply`] carries out; tracking runs on the
//! [`worker`] thread, polled every frame.

use eframe::egui;
mod background;
pub mod command;
mod decoder;
mod experiments;
mod export;
mod gt_edit;
mod panels;
pub mod prefs;
mod queries;
mod replies;
mod runs;
mod runtime;
mod shortcuts;
mod sources;
pub use crate::session as state;
mod window;
pub mod worker;

pub use panels::panel_rect;
pub use queries::{Disagreement, rank_disagreements};
use runtime::{DisplayRt, LiveRt, MessagesRt, RunRt, SequenceRt, UiRt};
pub use runtime::{Experiment, Frequency, LandscapeView, Patches, Runtime, Tool, Versioned};
pub use state::LandscapeSettings;
pub use window::{AppError, RunOptions, ScreenshotPlan, ShotResult, run};

use command::Command;
use state::State;
use std::path::PathBuf;
use worker::{Job, Worker};

/// The application.
pub struct InspectorApp {
    pub state: State,
    rt: Runtime,
}

impl InspectorApp {
    /// A new inspector on `state`; `wake` requests a repaint (from the worker thread).
    pub fn new(state: State, wake: impl Fn() + Send + Sync + 'static) -> Self {
        let rt = Runtime {
            worker: Worker::spawn(wake),
            commands: Vec::new(),
            seq: SequenceRt::default(),
            live: LiveRt::default(),
            run: RunRt::default(),
            display: DisplayRt::default(),
            msg: MessagesRt::default(),
            ui: UiRt::default(),
            gt: gt_edit::GtRuntime::default(),
            screenshot: None,
            frame_times: Vec::new(),
        };
        let mut app = InspectorApp {
            state: State::default(),
            rt,
        };
        if let Some(e) = app.rt.worker.spawn_error.clone() {
            app.error(e);
        }
        app.load_state(state);
        app
    }

    /// Queues a command (what panels do).
    pub fn send(&mut self, c: Command) {
        self.rt.commands.push(c);
    }

    /// Shows an error once: the same message again moves to the end instead of stacking.
    fn error(&mut self, e: String) {
        self.rt.msg.errors.retain(|x| *x != e);
        self.rt.msg.errors.push(e);
        // At most three, the newest: more pushes the frame down and hides what matters now.
        if self.rt.msg.errors.len() > 3 {
            self.rt.msg.errors.remove(0);
        }
    }

    /// Whether a result of the worker is awaited: a propagation, a landscape, a file dialog, a
    /// live source's frames.
    fn awaiting_worker(&self) -> bool {
        let landscape = &self.rt.ui.landscape;
        self.rt.gt.running
            || self
                .rt
                .ui
                .frequency
                .as_ref()
                .is_some_and(|f| f.result.is_none())
            || self
                .rt
                .ui
                .experiment
                .as_ref()
                .is_some_and(|e| e.results.is_none())
            || self.rt.ui.dialog
            || self.is_live()
            || self.rt.seq.opening.is_some()
            || (self.state.view.show_landscape
                && landscape.requested.is_some()
                && landscape.result.as_ref().map(|r| &r.0) != landscape.requested.as_ref())
    }

    /// Whether a live source runs.
    pub fn is_live(&self) -> bool {
        self.rt.live.info.is_some()
    }

    /// Uploads the newest decoded frame as the view's texture.
    fn upload(&mut self, ctx: &egui::Context) {
        if let Some(img) = self.rt.display.pending_image.take() {
            let color =
                // Frames are opaque: premultiplied is the same bytes, without a pass over them.
                egui::ColorImage::from_rgba_premultiplied([img.width, img.height], &img.rgba);
            match &mut self.rt.display.texture {
                Some(t) => t.set(color, egui::TextureOptions::LINEAR),
                None => {
                    self.rt.display.texture =
                        Some(ctx.load_texture("frame", color, egui::TextureOptions::LINEAR))
                }
            }
            self.rt.display.image_size = [img.width, img.height];
            self.rt.display.texture_frame = Some(img.index);
            // The gray frame, for the ground-truth mode's patch view (only in that mode: it costs
            // a pass over the frame).
            if self.rt.ui.tool == Tool::EditGroundTruth {
                let gray: Vec<f32> = img
                    .rgba
                    .chunks_exact(4)
                    .map(|p| crate::imaging::luma(p[0], p[1], p[2]) as f32)
                    .collect();
                self.rt.gt.frame_image =
                    crate::imaging::GrayF32::from_vec(img.width, img.height, gray)
                        .map(|g| (img.index, g));
            }
        }
        if self.rt.display.texture_frame != Some(self.state.frame)
            && self.rt.seq.sequence.is_some()
            && !self.rt.run.playing
        {
            self.rt.display.texture_frame = Some(self.state.frame);
            self.rt.worker.send(Job::Show(self.state.frame));
        }
    }

    /// Draws the whole window into `ui` (used by eframe and by the UI tests).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let built = std::time::Instant::now();
        let ctx = ui.ctx().clone();
        self.poll_worker();
        self.upload(&ctx);
        self.gt_keys(&ctx);
        self.global_keys(&ctx);
        self.handle_dropped_files(&ctx);
        // The panels read the app and push commands; they are applied once all are drawn.
        let mut out = panels::Commands::new();
        panels::top_bar(self, ui, &mut out);
        panels::playback_bar(self, ui, &mut out);
        panels::sidebar(self, ui, &mut out);
        panels::plots_panel(self, ui, &mut out);
        let transform = egui::CentralPanel::default()
            .show(ui, |ui| {
                if self.rt.ui.tool == Tool::EditGroundTruth && self.rt.seq.sequence.is_some() {
                    egui::Panel::bottom("gt_strip").show(ui, |ui| {
                        panels::timeline(self, ui, &mut out);
                        panels::gt_strip(self, ui)
                    });
                }
                panels::frame_view(self, ui, &mut out)
            })
            .inner;
        if transform.is_some() {
            self.rt.display.transform = transform;
        }
        self.rt.commands.extend(out);
        self.apply_pending();
        // Once the pointer is released and no value is being typed (typing "50" re-runs at 50,
        // not at 5 first).
        if !self.rt.run.rerun_due.is_empty()
            && !ctx.input(|i| i.pointer.any_down())
            && !ctx.egui_wants_keyboard_input()
        {
            for i in std::mem::take(&mut self.rt.run.rerun_due) {
                self.rerun_tracker(i);
            }
        }
        self.replay(&ctx);
        if !self.rt.run.playing {
            self.request_landscape();
        }
        if self.rt.ui.show_help {
            window::help_window(&ctx, &mut self.rt.ui.show_help);
        }
        if let Some(p) = self.rt.ui.confirm_overwrite.clone()
            && let Some(yes) = window::overwrite_window(&ctx, &p)
        {
            self.apply(Command::ConfirmOverwrite(yes));
        }
        self.screenshot(&ctx);
        if self.rt.run.playing || self.rt.msg.progress.is_some() {
            ctx.request_repaint();
        } else if self.awaiting_worker() {
            // Every reply requests a repaint; this is the safety net should a request made
            // while a frame is being built be folded into it (a result then waited for the
            // next mouse move).
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
        if self.rt.run.playing {
            let dt = ctx.input(|i| i.unstable_dt);
            if self.rt.frame_times.len() >= 10_000 {
                self.rt.frame_times.remove(0);
            }
            self.rt
                .frame_times
                .push((dt, built.elapsed().as_secs_f32()));
        }
    }
}

/// Paths for a status line, comma-separated.
fn list_paths(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// `Ctrl` (`Cmd` on macOS) + `key` pressed this frame, with the modifiers held *at that press*
/// (a quick Ctrl+Z can press and release Ctrl within one frame, so the frame's modifiers miss it).
fn shortcut(i: &egui::InputState, key: egui::Key) -> Option<egui::Modifiers> {
    i.events.iter().find_map(|e| match e {
        egui::Event::Key {
            key: k,
            pressed: true,
            modifiers,
            ..
        } if *k == key && modifiers.command => Some(*modifiers),
        _ => None,
    })
}

/// How many times `key` was pressed this frame with Shift held (`shift`) or not, other
/// modifiers aside: every press counts, also several within one frame of the window.
fn presses(i: &egui::InputState, key: egui::Key, shift: bool) -> usize {
    i.events
        .iter()
        .filter(|e| {
            matches!(e, egui::Event::Key { key: k, pressed: true, modifiers, .. }
                if *k == key && modifiers.shift == shift)
        })
        .count()
}

/// Per tracker, the iterations' patches are kept for this many of the newest tracked frames.
pub const PATCH_FRAMES: usize = 300;

pub use crate::keys::SHORTCUTS;
