//! The shortcuts of the whole window (those of the ground-truth mode are in `gt_edit.rs`).

use super::command::Command;
use super::{InspectorApp, Tool, shortcut};
use eframe::egui;
use std::path::PathBuf;

impl InspectorApp {
    /// The shortcuts of the whole window (when no text field has the keyboard).
    pub(super) fn global_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let gt_mode = self.rt.ui.tool == Tool::EditGroundTruth;
        let n = self.frame_count();
        let mut cmds = Vec::new();
        let mut dialog = false;
        ctx.input(|i| {
            if i.key_pressed(egui::Key::F1) || i.key_pressed(egui::Key::Questionmark) {
                self.rt.ui.show_help = !self.rt.ui.show_help;
            }
            if i.key_pressed(egui::Key::Escape) {
                self.rt.ui.show_help = false;
                if self.rt.ui.confirm_overwrite.is_some() {
                    cmds.push(Command::ConfirmOverwrite(false));
                }
            }
            if i.key_pressed(egui::Key::F4) {
                // The presentation scale, for a class: 2 and back.
                let mut view = self.state.view.clone();
                view.label_scale = if view.label_scale == 1.0 { 2.0 } else { 1.0 };
                cmds.push(Command::SetView(view));
            }
            if i.key_pressed(egui::Key::F2) || i.key_pressed(egui::Key::F3) {
                let mut view = self.state.view.clone();
                if i.key_pressed(egui::Key::F2) {
                    view.show_trackers_panel = !view.show_trackers_panel;
                } else {
                    view.show_plots_panel = !view.show_plots_panel;
                }
                cmds.push(Command::SetView(view));
            }
            if shortcut(i, egui::Key::S).is_some() {
                cmds.push(Command::SaveSession(PathBuf::from(
                    self.rt.ui.session_path.trim(),
                )));
            }
            if shortcut(i, egui::Key::O).is_some() {
                dialog = true;
            }
            if !(i.modifiers.command || n == 0 || self.is_live()) {
                self.frame_keys(i, gt_mode, &mut cmds);
            }
        });
        if dialog {
            cmds.push(Command::OpenDialog { folder: false });
        }
        for c in cmds {
            self.send(c);
        }
    }

    /// The keys that move through the frames and the iterations (not live).
    fn frame_keys(&self, i: &egui::InputState, gt_mode: bool, cmds: &mut Vec<Command>) {
        let (frame, n) = (self.state.frame, self.frame_count());
        if i.key_pressed(egui::Key::Space) {
            cmds.push(if self.rt.run.playing || self.rt.run.replaying.is_some() {
                Command::Pause
            } else {
                Command::Play
            });
        }
        if !gt_mode {
            if i.key_pressed(egui::Key::P) {
                cmds.push(Command::Perturb);
            }
            let shown = self.result(self.state.selected_tracker, frame);
            let n_it = shown.map_or(0, |r| r.iterations.len());
            let sel = self.rt.ui.selected_iteration;
            if i.key_pressed(egui::Key::Period) && n_it > 0 {
                cmds.push(Command::SelectIteration(Some(
                    sel.map_or(0, |k| (k + 1).min(n_it - 1)),
                )));
            }
            if i.key_pressed(egui::Key::Comma) && n_it > 0 {
                cmds.push(Command::SelectIteration(Some(
                    sel.map_or(0, |k| k.saturating_sub(1)),
                )));
            }
            if i.key_pressed(egui::Key::Escape) && self.rt.ui.experiment.is_some() {
                cmds.push(Command::ClearExperiment);
            }
        }
        // The frame keys, the same in every mode (Shift+arrows nudge in the ground-truth
        // mode). Right tracks the next frame when it is not tracked yet.
        let on = super::presses(i, egui::Key::ArrowRight, false);
        if on > 0 {
            // Through the tracked frames, then a step per press left.
            let target = (frame + on).min(n - 1);
            // Beyond the tracked frames (a frame sought past them), the next is shown only.
            match self.rt.run.tracked_until {
                Some(t) if frame <= t && target > t => {
                    if frame < t {
                        cmds.push(Command::Seek(t));
                    }
                    cmds.extend((t..target).map(|_| Command::Step));
                }
                _ => cmds.push(Command::Seek(target)),
            }
        }
        let back = super::presses(i, egui::Key::ArrowLeft, false)
            + super::presses(i, egui::Key::PageUp, false);
        if back > 0 && frame > 0 {
            cmds.push(Command::Seek(frame.saturating_sub(back)));
        }
        let on = super::presses(i, egui::Key::PageDown, false);
        if on > 0 && frame + 1 < n {
            cmds.push(Command::Seek((frame + on).min(n - 1)));
        }
        if i.key_pressed(egui::Key::Home) {
            cmds.push(Command::Seek(self.state.start_frame));
        }
        if i.key_pressed(egui::Key::End) {
            cmds.push(Command::Seek(self.rt.run.tracked_until.unwrap_or(frame)));
        }
    }
}
