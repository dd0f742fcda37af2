//! Trackers (methods from the registries, parameters, colour, initialisation) and the ground
//! truth's settings.

use super::color;
use crate::app::command::{Command, GtCommand};
use crate::app::state::InitSource;
use crate::app::{InspectorApp, Tool};
use crate::params::{ParamDef, ParamKind};
use crate::registry::Entry;
use crate::tracker::{TRACKER_PARAMS, TrackerSpec};
use crate::{am, sm, ssm};
use eframe::egui;

/// A dropdown of a registry; returns the chosen name when it changed.
fn method_combo<B>(
    ui: &mut egui::Ui,
    label: String,
    current: &str,
    entries: &[Entry<B>],
) -> Option<String> {
    let mut chosen = current.to_string();
    egui::ComboBox::from_label(label)
        .selected_text(current)
        .show_ui(ui, |ui| {
            for e in entries {
                ui.selectable_value(&mut chosen, e.name.to_string(), e.name)
                    .on_hover_text(e.description);
            }
        });
    (chosen != current).then_some(chosen)
}

pub fn sidebar(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    if !app.state.view.show_trackers_panel {
        return;
    }
    // A small part of a small window, so that the frame keeps most of it (F2 hides the panel).
    let w = ui.ctx().content_rect().width();
    let most = if w < 1200.0 { 0.22 } else { 0.3 };
    let size = (300.0f32.min(w * 0.22), most, 170.0);
    let panel = ("trackers", egui::Panel::left("trackers"), size);
    super::side_panel(app, ui, out, panel, |ui, out| {
        egui::ScrollArea::vertical().show(ui, |ui| {
            ui.heading("Trackers");
            let n = app.state.trackers.len();
            for i in 0..n {
                tracker_group(app, ui, out, i);
            }
            if ui.button("Add tracker").clicked() {
                out.push(Command::AddTracker);
            }
            ab_controls(app, ui, out);
            patch_controls(app, ui, out);
            ui.separator();
            ground_truth_section(app, ui, out);
        });
    });
}

/// Tracker `i`'s group: its colour, enabling, kind and methods, parameters, how it starts, and
/// what it did.
fn tracker_group(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>, i: usize) {
    let entry = app.state.trackers[i].clone();
    let mut next = entry.clone();
    let stats = tracker_stats(app, i);
    egui::Frame::group(ui.style()).show(ui, |ui| {
        ui.horizontal_wrapped(|ui| {
            ui.color_edit_button_srgb(&mut next.color);
            ui.checkbox(&mut next.enabled, format!("Tracker {}", i + 1));
            if ui
                .radio(app.state.selected_tracker == i, "inspect")
                .on_hover_text("Show its iterations")
                .clicked()
            {
                out.push(Command::SelectTracker(i));
            }
            if let Some(kind) = tracker_kind_combo(ui, i, &next.spec) {
                next.spec = kind;
            }
        });
        if let Some(r) = next.spec.registration_mut() {
            if let Some(v) = method_combo(ui, format!("SM {}", i + 1), &r.sm, sm::REGISTRY) {
                r.sm = v;
                // Another method has other parameters.
                r.keep_known_params();
            }
            if let Some(v) = method_combo(ui, format!("AM {}", i + 1), &r.am, am::REGISTRY) {
                r.am = v;
                r.keep_known_params();
            }
            if let Some(v) = method_combo(ui, format!("SSM {}", i + 1), &r.ssm, ssm::REGISTRY) {
                r.ssm = v;
            }
        }
        ui.collapsing(format!("Parameters {}", i + 1), |ui| {
            param_grid(ui, i, &mut next.spec);
        });
        ui.horizontal_wrapped(|ui| {
            if ui
                .button("Init from GT")
                .on_hover_text("Start from the ground truth of this frame")
                .clicked()
            {
                out.push(Command::InitTracker(i, InitSource::GroundTruth));
            }
            if ui
                .button("Draw quad")
                .on_hover_text("Click the four corners on the frame")
                .clicked()
            {
                out.push(Command::SetTool(Tool::DrawQuad {
                    tracker: i,
                    corners: Vec::new(),
                }));
            }
            if ui
                .button("Draw box")
                .on_hover_text("Drag a box on the frame")
                .clicked()
            {
                out.push(Command::SetTool(Tool::DrawBox {
                    tracker: i,
                    start: None,
                }));
            }
            if ui.button("Remove").clicked() {
                out.push(Command::RemoveTracker(i));
            }
        });
        ui.label(egui::RichText::new(stats).small().color(color(entry.color)));
    });
    if next != entry {
        out.push(Command::SetTracker(i, Box::new(next)));
    }
}

/// The ground truth: what is shown of it, its SSM, and its correction mode.
fn ground_truth_section(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    ui.heading("Ground truth");
    let mut view = app.state.view.clone();
    // Side by side where the panel is wide enough (the ground-truth mode's tools below stay
    // on the first screen).
    ui.horizontal_wrapped(|ui| {
    ui.checkbox(&mut view.show_ground_truth, "show ground truth");
    ui.checkbox(&mut view.show_corner_numbers, "number the corners");
    ui.checkbox(&mut view.show_samples, "show method internals")
        .on_hover_text("On the newest frame: where NN and PF looked (brighter = more similar), KCF's and DSST's response map, TLD's detections and flow points, CMT's keypoints (inliers bright), RCT's candidates");
    // One toggle, for the mode shown: the ground truth in the ground-truth mode, the
    // inspected tracker otherwise.
    let (follow, what) = if app.rt.ui.tool == Tool::EditGroundTruth {
        (&mut view.follow_in_gt_mode, "the ground truth")
    } else {
        (&mut view.follow_tracker, "the inspected tracker")
    };
    ui.checkbox(follow, "follow the target")
        .on_hover_text(format!("Zoomed in, each frame is centred on {what}"));
    ui.add(
        egui::DragValue::new(&mut view.label_scale)
            .range(crate::session::LABEL_SCALE)
            .speed(0.05)
            .prefix("labels x "),
    )
    .on_hover_text(
        "Presentation scale (F4 toggles 1 and 2): the frame's labels and quads, the plots' \
         text and lines",
    );
    });
    if view != app.state.view {
        out.push(Command::SetView(view));
    }
    if let Some(v) = method_combo(ui, "GT SSM".into(), &app.state.gt_ssm, ssm::REGISTRY) {
        out.push(Command::SetGtSsm(v));
    }
    ui.label(egui::RichText::new("Trackers are scored against the ground truth projected on this SSM (low-DOF ground truth).").small());
    let editing = app.rt.ui.tool == Tool::EditGroundTruth;
    if ui
        .selectable_label(editing, "Edit ground-truth corners")
        .on_hover_text(
            "Ground-truth mode: drag a corner or the quad; keys 1-4/0, Shift+arrows, +/-, Right/Left, J, O",
        )
        .clicked()
    {
        out.push(Command::SetTool(if editing {
            Tool::Navigate
        } else {
            Tool::EditGroundTruth
        }));
    }
    if editing {
        gt_controls(app, ui, out);
    }
}

/// Many patches: how many, their warp, and a run from the shown frame (drawn on the frames).
fn patch_controls(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    egui::CollapsingHeader::new("Patches")
        .id_salt("patches")
        .show(ui, |ui| {
            let running = app.patches().is_some_and(|p| p.result.is_none());
            let mut next = app.state.patches.clone();
            ui.add(
                egui::DragValue::new(&mut next.count)
                    .range(crate::session::PATCH_COUNT)
                    .suffix(" patches"),
            )
            .on_hover_text("How many corners to track (the strongest first)");
            ui.collapsing("Patch parameters", |ui| {
                egui::Grid::new("patch_params")
                    .num_columns(2)
                    .show(ui, |ui| {
                        for d in crate::patches::PATCH_PARAMS {
                            let old = next.params.get(d);
                            let v = param_widget(ui, (usize::MAX, d.name), d, old);
                            if v != old {
                                next.params.set(d.name, v);
                            }
                        }
                    });
            });
            if next != app.state.patches {
                out.push(Command::SetPatchSettings(next));
            }
            let side = app.state.patches.patch_params().map_or(15, |p| p.size);
            ui.horizontal_wrapped(|ui| {
                if ui
                    .add_enabled(
                        !running,
                        egui::Button::new(if running {
                            "Tracking…"
                        } else {
                            "Track from this frame"
                        }),
                    )
                    .on_hover_text(format!(
                        "The strongest Shi-Tomasi corners of this frame (inside its ground \
                             truth when it has one), each a {side}x{side} patch tracked to the end \
                             of the sequence by inverse-compositional LK over one shared pyramid \
                             (regtrack track --patches on the command line). Green: tracking; \
                             red: lost."
                    ))
                    .clicked()
                {
                    out.push(Command::TrackPatches);
                }
                if app.patches().is_some() && ui.button("Clear").clicked() {
                    out.push(Command::ClearPatches);
                }
            });
            match app.patches_on(app.state.frame) {
                Some((states, _)) => {
                    let on = states.iter().filter(|s| s.tracking()).count();
                    ui.label(format!("{on} of {} tracking on this frame", states.len()));
                }
                None => {
                    if let Some(p) = app.patches() {
                        let text = match &p.result {
                            None => format!("tracking from frame {}…", p.from + 1),
                            Some(Err(e)) => e.clone(),
                            Some(Ok(_)) => format!("tracked from frame {}", p.from + 1),
                        };
                        ui.label(egui::RichText::new(text).small().weak());
                    }
                }
            }
        });
}

/// The kind of tracker, in the tracker's header: a registration tracker (AM x SSM x SM, chosen
/// below) or one of the whole trackers; returns the new spec when it changed (a whole tracker
/// with its defaults, or ESM + SSD + homography).
fn tracker_kind_combo(ui: &mut egui::Ui, i: usize, spec: &TrackerSpec) -> Option<TrackerSpec> {
    const REGISTRATION: &str = "AM x SSM x SM";
    let current = match spec {
        TrackerSpec::Registration(_) => REGISTRATION.to_string(),
        TrackerSpec::Whole(w) => w.tracker.clone(),
    };
    let mut chosen = current.clone();
    egui::ComboBox::from_id_salt(("type", i))
        .selected_text(&current)
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut chosen, REGISTRATION.to_string(), REGISTRATION)
                .on_hover_text(
                    "A registration tracker: an appearance model, a state space model and a search method",
                );
            for e in crate::tracker::WHOLE_REGISTRY {
                ui.selectable_value(&mut chosen, e.name.to_string(), e.name)
                    .on_hover_text(e.description);
            }
        })
        .response
        .on_hover_text(format!(
            "Type of tracker {}: a registration tracker or a learning-based one",
            i + 1
        ));
    if chosen == current {
        return None;
    }
    if chosen == REGISTRATION {
        crate::tracker::default_spec(crate::spec::DEFAULT_TRACKER[2]).ok()
    } else {
        TrackerSpec::whole(&chosen).ok()
    }
}

/// A/B mode: two trackers side by side.
fn ab_controls(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let n = app.state.trackers.len();
    let mut view = app.state.view.clone();
    let mut on = view.ab.is_some();
    ui.horizontal(|ui| {
        ui.add_enabled(n >= 2, egui::Checkbox::new(&mut on, "A/B"))
            .on_hover_text("Two trackers side by side, with the frames where they disagree most");
        if on {
            let (mut a, mut b) = view.ab.unwrap_or((0, 1.min(n.saturating_sub(1))));
            for (label, v) in [("A", &mut a), ("B", &mut b)] {
                egui::ComboBox::from_id_salt(format!("ab_{label}"))
                    .selected_text(format!("{label}: {}", *v + 1))
                    .width(60.0)
                    .show_ui(ui, |ui| {
                        for k in 0..n {
                            ui.selectable_value(v, k, format!("{}", k + 1));
                        }
                    });
            }
            view.ab = Some((a.min(n - 1), b.min(n - 1)));
        } else {
            view.ab = None;
        }
    });
    if view != app.state.view {
        out.push(Command::SetView(view));
    }
}

/// The ground-truth mode's controls: corner, step, undo/redo, occluded, propagate,
/// interpolate, export.
fn gt_controls(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    gt_cursor(app, ui, out);
    gt_history(app, ui, out);
    let occluded = app.gt_frame(app.state.frame) == Some(crate::gt::GtFrame::Occluded);
    ui.horizontal(|ui| {
        if ui
            .selectable_label(occluded, "Occluded")
            .on_hover_text("O: not annotatable; skipped by the evaluation")
            .clicked()
        {
            out.push(Command::Gt(GtCommand::ToggleOccluded));
        }
        if ui
            .button("Jump to worst")
            .on_hover_text(
                "J: the uncorrected frame with the largest fit residual or tracker error",
            )
            .clicked()
        {
            out.push(Command::Gt(GtCommand::JumpWorst));
        }
    });
    if let Some(r) = app.gt_residual(app.state.frame) {
        ui.label(format!("fit residual on this frame: {r:.2} px"));
    }
    gt_proposals(app, ui, out);
    gt_journal(app, ui, out);
}

/// Which corner (or the whole quad) the keys move, and by how much.
fn gt_cursor(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let (picked, step) = app.gt_cursor();
    ui.horizontal(|ui| {
        ui.label("move");
        for k in 0..4 {
            if ui
                .selectable_label(picked == Some(k), format!("{}", k + 1))
                .clicked()
            {
                out.push(Command::Gt(GtCommand::PickCorner(Some(k))));
            }
        }
        if ui.selectable_label(picked.is_none(), "quad").clicked() {
            out.push(Command::Gt(GtCommand::PickCorner(None)));
        }
    });
    ui.horizontal(|ui| {
        ui.label(format!("step {step} px"));
        if ui.small_button("-").clicked() {
            out.push(Command::Gt(GtCommand::Step(step / 2.0)));
        }
        if ui.small_button("+").clicked() {
            out.push(Command::Gt(GtCommand::Step(step * 2.0)));
        }
    });
}

/// Undo, redo, revert the frame.
fn gt_history(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let (done, redo) = {
        let (d, r) = app.corrections().history();
        (
            d.last().map(|s| s.to_string()),
            r.first().map(|s| s.to_string()),
        )
    };
    ui.horizontal(|ui| {
        if ui
            .add_enabled(done.is_some(), egui::Button::new("Undo"))
            .on_hover_text(format!("Ctrl+Z: {}", done.as_deref().unwrap_or("nothing")))
            .clicked()
        {
            out.push(Command::Gt(GtCommand::Undo));
        }
        if ui
            .add_enabled(redo.is_some(), egui::Button::new("Redo"))
            .on_hover_text(format!(
                "Ctrl+Shift+Z: {}",
                redo.as_deref().unwrap_or("nothing")
            ))
            .clicked()
        {
            out.push(Command::Gt(GtCommand::Redo));
        }
        if ui
            .button("Revert frame")
            .on_hover_text("Back to the original ground truth")
            .clicked()
        {
            out.push(Command::Gt(GtCommand::Revert));
        }
    });
}

/// Propagation and interpolation, and a pending proposal to accept or reject.
fn gt_proposals(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        let running = app.gt_propagating();
        if ui.add_enabled(!running, egui::Button::new(if running { "Propagating…" } else { "Propagate" }))
            .on_hover_text("Track forward from this frame with the inspected tracker on this SSM, until a corrected frame or an error jump; then accept or reject")
            .clicked()
        {
            out.push(Command::Gt(GtCommand::Propagate));
        }
        if ui.button("Interpolate").on_hover_text("Between the corrected key frames around this frame, in the SSM's parameters").clicked() {
            out.push(Command::Gt(GtCommand::Interpolate));
        }
    });
    if let Some(p) = app.gt_proposal() {
        let (a, b) = (
            p.frames.first().map_or(0, |f| f.0),
            p.frames.last().map_or(0, |f| f.0),
        );
        ui.label(format!("proposal: frames {}-{} ({})", a + 1, b + 1, p.stop));
        ui.horizontal(|ui| {
            if ui
                .button("Accept")
                .on_hover_text("Enter: one undoable edit")
                .clicked()
            {
                out.push(Command::Gt(GtCommand::AcceptProposal));
            }
            if ui.button("Reject").on_hover_text("Esc").clicked() {
                out.push(Command::Gt(GtCommand::RejectProposal));
            }
        });
    }
}

/// Where the corrections are kept, and their export.
fn gt_journal(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let c = app.corrections();
    let journal = c
        .journal_path()
        .map(|p| p.display().to_string())
        .unwrap_or_else(|| match c.refused() {
            Some(_) => "none (it cannot be used): corrections are refused".into(),
            None => "none: NOT saved".into(),
        });
    ui.label(
        egui::RichText::new(format!(
            "{} correction(s), kept in the journal {journal}",
            c.len()
        ))
        .small(),
    );
    let label = if app.ground_truth_edited() {
        "Export ground truth*"
    } else {
        "Export ground truth"
    };
    if ui.button(label).on_hover_text("Writes <seq>_gt_<ssm>.txt (the sequence's format) and OptGT/<seq>_<ssm>.txt atomically; the original is never written").clicked() {
        out.push(Command::Gt(GtCommand::Export));
    }
}

/// One line of figures for a tracker: frames, SR@5, mean error, speed.
fn tracker_stats(app: &InspectorApp, i: usize) -> String {
    let errors = app.errors(i);
    if errors.is_empty() {
        // Without ground truth (a live source, an unannotated sequence): what it did.
        let confidences = app.confidences(i);
        let (n, us, _, _) = app.speed(i);
        if confidences.is_empty() {
            return "not tracked yet".into();
        }
        let lost = confidences.iter().filter(|c| c.2).count();
        return format!(
            "{} frames · {lost} lost · {:.0} FPS · no ground truth",
            confidences.len(),
            if us > 0.0 {
                n as f64 / (us * 1e-6)
            } else {
                0.0
            }
        );
    }
    let e: Vec<f64> = errors.iter().map(|(_, e)| *e).collect();
    let finite: Vec<f64> = e.iter().copied().filter(|v| v.is_finite()).collect();
    let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
    let (n, us, _, _) = app.speed(i);
    let fps = if us > 0.0 {
        n as f64 / (us * 1e-6)
    } else {
        0.0
    };
    format!(
        "{} frames · SR@5 {:.3} · mean error {:.2} px · {:.0} FPS",
        e.len(),
        crate::eval::success_rate(&e, 5.0),
        mean,
        fps
    )
}

/// One drag value for a parameter, with its definition's range and help; returns the new value.
fn param_widget(ui: &mut egui::Ui, id: (usize, &str), def: &ParamDef, value: f64) -> f64 {
    let mut v = value;
    ui.label(def.name).on_hover_text(def.help);
    match def.kind {
        ParamKind::Choice(names) => {
            egui::ComboBox::from_id_salt(id)
                .selected_text(def.format(v))
                .show_ui(ui, |ui| {
                    for (k, n) in names.iter().enumerate() {
                        ui.selectable_value(&mut v, k as f64, *n);
                    }
                });
        }
        ParamKind::Int => {
            let speed = ((def.max - def.min) / 500.0).clamp(0.05, 50.0);
            ui.add(
                egui::DragValue::new(&mut v)
                    .range(def.min..=def.max)
                    .speed(speed)
                    .max_decimals(0),
            )
            .on_hover_text(def.help);
        }
        ParamKind::Float => {
            let speed = ((def.max - def.min) / 2000.0).clamp(1e-4, 1.0);
            ui.add(
                egui::DragValue::new(&mut v)
                    .range(def.min..=def.max)
                    .speed(speed),
            )
            .on_hover_text(def.help);
        }
    }
    ui.end_row();
    v
}

/// The tracker's and the method's parameters, from their definitions.
fn param_grid(ui: &mut egui::Ui, i: usize, spec: &mut TrackerSpec) {
    egui::Grid::new(("params", i))
        .num_columns(2)
        .show(ui, |ui| {
            if let Some(r) = spec.registration_mut() {
                for d in TRACKER_PARAMS {
                    let v = param_widget(ui, (i, d.name), d, r.params.value(d.name));
                    if v != r.params.value(d.name) {
                        r.params.set_value(d.name, v);
                    }
                }
            }
            // The search method's and the appearance model's own (one bag, under two headings),
            // or the whole tracker's.
            let groups: Vec<(&str, Vec<&'static ParamDef>)> = match &*spec {
                TrackerSpec::Registration(r) => vec![
                    ("search method", sm::param_defs(&r.sm).unwrap_or_default()),
                    (
                        "appearance model",
                        am::param_defs(&r.am)
                            .map(|d| d.iter().collect())
                            .unwrap_or_default(),
                    ),
                ],
                TrackerSpec::Whole(_) => vec![("method", spec.method_defs().unwrap_or_default())],
            };
            for (heading, defs) in groups {
                if !defs.is_empty() {
                    ui.label(egui::RichText::new(heading).strong());
                    ui.end_row();
                }
                for d in defs {
                    let old = spec.method_params().get(d);
                    let v = param_widget(ui, (i, d.name), d, old);
                    if v != old {
                        match spec {
                            TrackerSpec::Registration(r) => r.method.set(d.name, v),
                            TrackerSpec::Whole(w) => w.method.set(d.name, v),
                        }
                    }
                }
            }
        });
}
