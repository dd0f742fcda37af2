//! The top bar (sequence, session, messages) and the playback bar.

use crate::app::InspectorApp;
use crate::app::command::Command;
use crate::app::state::SequenceSource;
use eframe::egui;
use std::path::PathBuf;

/// Opening sequences and sessions, status and errors.
pub fn top_bar(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    egui::Panel::top("top_bar").show(ui, |ui| {
        ui.horizontal_wrapped(|ui| {
            ui.strong("regtrack");
            // Panels can be hidden so that the frame gets the window (F2, F3).
            let mut view = app.state.view.clone();
            ui.toggle_value(&mut view.show_trackers_panel, "Trackers")
                .on_hover_text("Show or hide the trackers panel (F2)");
            ui.toggle_value(&mut view.show_plots_panel, "Plots")
                .on_hover_text("Show or hide the plots panel (F3)");
            if view != app.state.view {
                out.push(Command::SetView(view));
            }
            ui.separator();
            open_controls(app, ui, out);
            session_controls(app, ui, out);
        });
        messages(app, ui, out);
    });
}

/// Opening a sequence: a folder, a file, a typed path, the demo, a camera, a recent one.
fn open_controls(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    if ui
        .button("Open folder…")
        .on_hover_text("A folder of frames or an MTF dataset sequence folder")
        .clicked()
    {
        out.push(Command::OpenDialog { folder: true });
    }
    if ui
        .button("Open file…")
        .on_hover_text(
            "An MTF <seq>.txt, a POT _gt_points.txt, or a video (mp4, mkv, avi, webm...) \
             with its ground truth beside it",
        )
        .clicked()
    {
        out.push(Command::OpenDialog { folder: false });
    }
    // Typed path: works without a desktop portal.
    let id = ui.make_persistent_id("path_input");
    let mut path = super::remembered_text(ui, id);
    let edit = ui.add(
        egui::TextEdit::singleline(&mut path)
            .hint_text("or type a path and press Enter")
            .desired_width(130.0),
    );
    let enter = edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
    if (ui.button("Open path").clicked() || enter) && !path.trim().is_empty() {
        let p = PathBuf::from(path.trim());
        out.push(Command::OpenSequence(SequenceSource::Path(p)));
    }
    super::remember_text(ui, id, path);
    if ui
        .button("Demo")
        .on_hover_text("The bundled demo sequence")
        .clicked()
    {
        out.push(Command::OpenSequence(SequenceSource::Demo));
    }
    // In a menu: the top bar stays one line at 1280 px.
    ui.menu_button("Camera…", |ui| {
        ui.horizontal(|ui| camera_controls(ui, out));
    })
    .response
    .on_hover_text("Open a live camera or an FFmpeg test source");
    if !app.recent().is_empty() {
        ui.menu_button("Recent", |ui| {
            for p in app.recent().iter().cloned() {
                if ui.button(p.display().to_string()).clicked() {
                    out.push(Command::OpenSequence(SequenceSource::Path(p)));
                    ui.close();
                }
            }
        })
        .response
        .on_hover_text("Sequences opened lately (kept between runs)");
    }
}

/// The session's file: save and load.
fn session_controls(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    ui.separator();
    let label = ui.label("Session:");
    let mut session = app.rt.ui.session_path.clone();
    if ui
        .add(egui::TextEdit::singleline(&mut session).desired_width(130.0))
        .labelled_by(label.id)
        .changed()
    {
        out.push(Command::SetSessionPath(session));
    }
    if ui.button("Save session").clicked() {
        out.push(Command::SaveSession(PathBuf::from(
            app.rt.ui.session_path.trim(),
        )));
    }
    if ui.button("Load session").clicked() {
        out.push(Command::LoadSession(PathBuf::from(
            app.rt.ui.session_path.trim(),
        )));
    }
    // Browsing without a desktop portal: the recent sessions and those of the sessions folders.
    let choices = app.session_choices();
    if !choices.is_empty() {
        ui.menu_button("Sessions", |ui| {
            for p in choices {
                if ui.button(p.display().to_string()).clicked() {
                    out.push(Command::LoadSession(p));
                    ui.close();
                }
            }
        })
        .response
        .on_hover_text("Load a recent session, or one of the sessions folders'");
    }
}

/// How long a status message is shown (s), and over how much of its end it fades.
pub const STATUS_SECONDS: f64 = 12.0;
const STATUS_FADE: f64 = 3.0;

/// The status line: a message shows for [`STATUS_SECONDS`] after it last changed, then fades
/// out ("tracker 3 added" stayed until the next message, long after it was news). Hovering
/// the line's place brings the last one back.
fn status_line(ui: &mut egui::Ui, status: &str) {
    let id = egui::Id::unique("status_since");
    let now = ui.input(|i| i.time);
    let since: Option<(String, f64)> = ui.data(|d| d.get_temp(id));
    let since = match since {
        Some((s, t)) if s == status => t,
        _ => {
            ui.data_mut(|d| d.insert_temp(id, (status.to_string(), now)));
            now
        }
    };
    let age = now - since;
    let alpha = ((STATUS_SECONDS - age) / STATUS_FADE).clamp(0.0, 1.0) as f32;
    if alpha < 1.0 && alpha > 0.0 {
        ui.ctx().request_repaint();
    } else if alpha >= 1.0 {
        ui.ctx()
            .request_repaint_after(std::time::Duration::from_secs_f64(
                (STATUS_SECONDS - STATUS_FADE - age).max(0.05),
            ));
    }
    let colour = ui.visuals().text_color().gamma_multiply(alpha.max(0.0));
    let r = ui.label(egui::RichText::new(status).color(colour));
    if alpha <= 0.0 && !status.is_empty() {
        r.on_hover_text(status);
    }
}

/// The progress, the status line and the errors (each dismissable).
fn messages(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        if let Some((what, d, t)) = &app.rt.msg.progress {
            ui.spinner();
            if *t > 0 {
                ui.add(
                    egui::ProgressBar::new(*d as f32 / *t as f32)
                        .text(format!("{what}: {d}/{t}"))
                        .desired_width(300.0),
                );
            } else {
                ui.label(what.as_str());
            }
        }
        status_line(ui, &app.rt.msg.status);
    });
    let mut dismiss = None;
    for (i, e) in app.rt.msg.errors.iter().enumerate() {
        // The dismiss button first, so that a long message wraps after it, never over it.
        ui.horizontal_top(|ui| {
            if ui.small_button("dismiss").clicked() {
                dismiss = Some(i);
            }
            ui.add(
                egui::Label::new(
                    egui::RichText::new(format!("Error: {e}"))
                        .color(egui::Color32::from_rgb(255, 110, 110)),
                )
                .wrap(),
            );
        });
    }
    if let Some(i) = dismiss {
        out.push(Command::DismissError(i));
    }
}

/// A live source to open: a V4L2 device or an FFmpeg test source, and its frame size.
fn camera_controls(ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let id = ui.make_persistent_id("camera_input");
    let mut source = super::remembered_text(ui, id);
    let edit = ui.add(
        egui::TextEdit::singleline(&mut source)
            .hint_text("/dev/video0 or lavfi:testsrc")
            .desired_width(150.0),
    );
    let size_id = ui.make_persistent_id("camera_size");
    let mut size = super::remembered_text(ui, size_id);
    ui.add(
        egui::TextEdit::singleline(&mut size)
            .hint_text("640x480")
            .desired_width(70.0),
    )
    .on_hover_text("The camera's frame size, WxH");
    let enter = edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
    if (ui
        .button("Open camera")
        .on_hover_text(
            "A live source: frames shown as they come; drag a box on the image to start a \
             tracker, Record to keep the frames and corners as a sequence",
        )
        .clicked()
        || enter)
        && !source.trim().is_empty()
    {
        let size = if size.trim().is_empty() {
            "640x480"
        } else {
            size.trim()
        };
        match crate::dataset::live::parse_size(size) {
            Some((width, height)) => out.push(Command::OpenCamera {
                source: source.trim().to_string(),
                width,
                height,
            }),
            None => out.push(Command::ReportError(format!(
                "camera size {size:?}: expected WxH, e.g. 640x480"
            ))),
        }
    }
    super::remember_text(ui, id, source);
    super::remember_text(ui, size_id, size);
}

/// The live source's bar: what it has shown and dropped, recording, closing it.
fn live_bar(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let Some(info) = &app.rt.live.info else {
        return;
    };
    ui.horizontal(|ui| {
        ui.label(
            egui::RichText::new("LIVE")
                .strong()
                .color(egui::Color32::from_rgb(230, 60, 60)),
        )
        .on_hover_text(info.source.as_str());
        ui.label(format!(
            "{} frames, {} dropped, {:.0} fps",
            info.frames, info.dropped, info.fps
        ))
        .on_hover_text(
            "Dropped: frames the source sent while the trackers were busy (each frame shown is \
             the newest)",
        );
        ui.separator();
        match &info.recording {
            Some((path, n)) => {
                if ui
                    .button("Stop recording")
                    .on_hover_text("The recording stays on disk as a sequence")
                    .clicked()
                {
                    out.push(Command::Record(false));
                }
                ui.label(format!("recording: {n} frames to {}", path.display()));
            }
            None => {
                if ui
                    .button("Record")
                    .on_hover_text(
                        "Write every frame shown and the selected tracker's corners as a \
                         sequence (MTF layout: live.txt + live/, then live_2...), to evaluate, \
                         correct and replay later",
                    )
                    .clicked()
                {
                    out.push(Command::Record(true));
                }
                let label = ui.label("to folder");
                let mut folder = app.rt.live.record_folder.clone();
                if ui
                    .add(egui::TextEdit::singleline(&mut folder).desired_width(140.0))
                    .labelled_by(label.id)
                    .changed()
                {
                    out.push(Command::SetRecordFolder(folder));
                }
            }
        }
        ui.separator();
        if ui.button("Stop camera").clicked() {
            out.push(Command::StopCamera);
        }
        open_recording_button(app, ui, out);
        // The source last: a lavfi graph can be long.
        ui.add(egui::Label::new(egui::RichText::new(info.source.as_str()).weak()).truncate());
    });
}

/// Opens the last recording as a sequence (for stepping, evaluating and correcting it).
fn open_recording_button(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let open = app.sequence().and_then(|s| s.gt_path.as_deref());
    let recording = app.rt.live.last_recording.as_ref();
    if let Some((path, n)) = recording.filter(|(p, n)| *n > 0 && open != Some(p.as_path()))
        && ui
            .button(format!("Open the recording ({n} frames)"))
            .on_hover_text(path.display().to_string())
            .clicked()
    {
        out.push(Command::OpenSequence(SequenceSource::Path(path.clone())));
    }
}

/// Play, pause, step, seek, speed, re-run.
pub fn playback_bar(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    egui::Panel::bottom("playback").show(ui, |ui| {
        if app.is_live() {
            live_bar(app, ui, out);
            return;
        }
        ui.horizontal(|ui| {
            open_recording_button(app, ui, out);
            let n = app.frame_count();
            if ui
                .button("|< Start")
                .on_hover_text("Show the start frame")
                .clicked()
            {
                out.push(Command::Seek(app.state.start_frame));
            }
            if app.is_playing() || app.is_replaying() {
                if ui.button("Pause").clicked() {
                    out.push(Command::Pause);
                }
            } else if ui
                .add_enabled(n > 0, egui::Button::new("Play"))
                .on_hover_text("Replays the tracked frames, then tracks on (Space)")
                .clicked()
            {
                out.push(Command::Play);
            }
            if ui
                .add_enabled(n > 0 && !app.is_playing(), egui::Button::new("Step"))
                .on_hover_text("Track one more frame")
                .clicked()
            {
                out.push(Command::Step);
            }
            if n == 0 {
                ui.label(egui::RichText::new("no sequence open").weak());
            } else {
                let mut frame = app.state.frame + 1;
                let slider = ui.add(egui::Slider::new(&mut frame, 1..=n).text(format!("of {n}")));
                if slider.changed() {
                    out.push(Command::Seek(frame.saturating_sub(1)));
                }
            }
            if ui
                .add_enabled(n > 0, egui::Button::new("Re-run from here"))
                .on_hover_text(
                    "Re-initialise every tracker on this frame and play; the results before \
                     it stay in the plots",
                )
                .clicked()
            {
                out.push(Command::RerunFrom(app.state.frame));
            }
            let mut fps = app.state.playback_fps;
            ui.label("speed");
            if ui
                .add(
                    egui::DragValue::new(&mut fps)
                        .range(0.0..=*crate::app::state::PLAYBACK_FPS.end())
                        .suffix(" fps"),
                )
                .on_hover_text("0 = as fast as the trackers go")
                .changed()
            {
                out.push(Command::SetPlaybackFps(fps));
            }
            if let Some(f) = app.rt.run.tracked_until.filter(|_| n > 0) {
                ui.label(format!("tracked to frame {}", f + 1));
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let dt = ui.input(|i| i.stable_dt).max(1e-4);
                ui.label(
                    egui::RichText::new(format!("UI {:.0} fps", 1.0 / dt))
                        .small()
                        .weak(),
                );
            });
        });
    });
}
