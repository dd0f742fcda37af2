//! Live plots (success rate, error per frame, speed) and the convergence of the current frame:
//! similarity and corner change per iteration, an iteration slider whose quad the frame view
//! draws, and the template, warped patch and error images.

use super::color;
use crate::app::InspectorApp;
use crate::app::command::Command;
use eframe::egui;
use egui_plot::{
    AxisHints, Corner, HPlacement, Legend, Line, LineStyle, MarkerShape, Plot, PlotImage,
    PlotPoint, PlotPoints, Points, VLine,
};

/// The error plot draws each tracker's confidence (0..1) on its right-hand axis, scaled to
/// 0..[`CONFIDENCE_SCALE`] px of the left one (the success curve's range).
const CONFIDENCE_SCALE: f64 = 20.0;

/// Axes whose tick labels show even on short plots (egui_plot's defaults hide every label of a
/// 150 px plot but the extremes), in few digits whatever the range (a live similarity of
/// -4e-13 read "-0.0000000000004" and squeezed the plot).
fn axes(plot: Plot<'static>, x: &str, y: &str) -> Plot<'static> {
    plot.custom_x_axes(vec![
        AxisHints::new_x()
            .label(x.to_string())
            .label_spacing(30.0..=44.0)
            .formatter(tick),
    ])
    .custom_y_axes(vec![y_axis(y)])
    .grid_spacing(6.0..=200.0)
}

/// A y axis of [`axes`]: compact ticks, room for its label.
fn y_axis(label: &str) -> AxisHints<'static> {
    AxisHints::new_y()
        .label(label.to_string())
        .label_spacing(14.0..=22.0)
        .formatter(tick)
}

/// A frame-number axis: whole frames only (an empty plot read 0.5 0.6 ... 1.4), spaced so
/// that four-digit frames do not run together.
fn frame_axis(label: &str) -> AxisHints<'static> {
    AxisHints::new_x()
        .label(label.to_string())
        .label_spacing(40.0..=56.0)
        .formatter(|m, _| {
            if m.value.fract() == 0.0 && m.step_size >= 1.0 {
                format!("{:.0}", m.value)
            } else {
                String::new()
            }
        })
}

/// A tick label in at most four significant digits: plain in 0.001..100 000, else in
/// scientific notation.
pub(crate) fn tick(m: egui_plot::GridMark, _range: &std::ops::RangeInclusive<f64>) -> String {
    compact(m.value, m.step_size)
}

/// `v` on an axis whose ticks are `step` apart, in few characters.
pub(crate) fn compact(v: f64, step: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v == 0.0 { "0".into() } else { String::new() };
    }
    let a = v.abs().max(step.abs());
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        return s.replace(".0e", "e");
    }
    let decimals = (-step.abs().log10().floor()).clamp(0.0, 4.0) as usize;
    format!("{v:.decimals$}")
}

pub fn plots_panel(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    if !app.state.view.show_plots_panel {
        return;
    }
    let w = ui.ctx().content_rect().width();
    let most = if w < 1200.0 { 0.4 } else { 0.6 };
    let size = (430.0f32.min(w * 0.3), most, 220.0);
    let panel = ("plots", egui::Panel::right("plots"), size);
    super::side_panel(app, ui, out, panel, |ui, out| {
        // Vertical only: every plot, image and table fits the panel's width (a horizontal
        // scroll let them grow past it, and its bar covered the buttons under it); a margin
        // for the axes' rotated labels and the floating scroll bar.
        egui::ScrollArea::vertical()
            .auto_shrink([false, true])
            .show(ui, |ui| {
                egui::Frame::new()
                    .inner_margin(egui::Margin {
                        left: 4,
                        right: 12,
                        top: 0,
                        bottom: 0,
                    })
                    .show(ui, |ui| {
                        // The presentation scale: the plots' text (and their lines, below),
                        // half as much as the frame's labels (at x2 the panel's tables took
                        // the frame's room).
                        let k = 1.0 + (app.state.view.label_scale - 1.0) / 2.0;
                        if k != 1.0 {
                            for f in ui.style_mut().text_styles.values_mut() {
                                f.size *= k;
                            }
                        }
                        export_row(app, ui, out);
                        success_plot(app, ui);
                        ui.heading("Alignment error and confidence per frame");
                        error_legend(app, ui);
                        error_plot(app, ui, out);
                        if let Some((a, b)) = app.state.view.ab {
                            disagreement(app, ui, out, a, b);
                        }
                        speed_table(app, ui);
                        speed_plots(app, ui, out);
                        ui.separator();
                        convergence(app, ui, out);
                        ui.separator();
                        frequency(app, ui, out);
                        ui.separator();
                        landscape(app, ui, out);
                    });
            });
    });
}

/// The success-rate heading with the export button and its folder.
fn export_row(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    ui.horizontal_wrapped(|ui| {
        ui.heading("Success rate");
        let id = egui::Id::unique("export_folder");
        let mut folder = super::remembered_text(ui, id);
        if folder.is_empty() {
            folder = "plots".into();
        }
        if ui
            .small_button("Export plots")
            .on_hover_text(
                "Write the success rates, the errors per frame, a landscape \
                 curve and the frequency of convergence as SVG and PNG into the \
                 folder at the right (the figures of regtrack report)",
            )
            .clicked()
        {
            out.push(Command::ExportPlots(std::path::PathBuf::from(
                folder.trim(),
            )));
        }
        ui.add(egui::TextEdit::singleline(&mut folder).desired_width(90.0))
            .on_hover_text("The folder the plots are written to");
        super::remember_text(ui, id, folder);
    });
    // Where that is, in full (a relative folder is the one the app was started from), and
    // the folder of the last export to open.
    let target = std::path::absolute(folder_of(ui)).unwrap_or_default();
    ui.horizontal_wrapped(|ui| {
        ui.label(
            egui::RichText::new(format!("into {}", target.display()))
                .small()
                .weak(),
        );
        if let Some(dir) = &app.rt.ui.exported
            && ui
                .small_button("Open folder")
                .on_hover_text(format!("Show {} in the file manager", dir.display()))
                .clicked()
        {
            out.push(Command::OpenFolder(dir.clone()));
        }
    });
}

/// The export folder as typed (`plots` when empty).
fn folder_of(ui: &egui::Ui) -> std::path::PathBuf {
    let typed = super::remembered_text(ui, egui::Id::unique("export_folder"));
    std::path::PathBuf::from(if typed.trim().is_empty() {
        "plots"
    } else {
        typed.trim()
    })
}

/// The success rate of every tracker shown (A and B only in A/B mode).
fn success_plot(app: &InspectorApp, ui: &mut egui::Ui) {
    axes(Plot::new("sr_plot"), "threshold t (px)", "SR")
        .height(190.0)
        // Below the curves (they rise at the left and run along the top).
        .legend(Legend::default().position(Corner::RightBottom))
        .include_x(0.0)
        .include_x(20.0)
        .include_y(0.0)
        .include_y(1.0)
        .allow_scroll(false)
        .show(ui, |p| {
            let ab = app.state.view.ab;
            for (i, t) in app.state.trackers.iter().enumerate() {
                // In A/B mode, only A and B.
                if ab.is_some_and(|(a, b)| i != a && i != b) {
                    continue;
                }
                let curve = app.success_curve(i);
                if !curve.is_empty() {
                    let pts: Vec<[f64; 2]> = curve.iter().map(|(x, y)| [*x, *y]).collect();
                    p.line(
                        Line::new(
                            format!("{} {}", i + 1, t.spec.label()),
                            PlotPoints::from(pts),
                        )
                        .color(color(t.color))
                        .width(line_width(app)),
                    );
                }
            }
        });
}

/// The alignment error and the confidence per frame, the lost frames marked; a click seeks.
fn error_plot(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let shown = app.state.frame;
    let r = axes(Plot::new("error_plot"), "frame", "E_AL (px)")
        .custom_x_axes(vec![frame_axis("frame")])
        .custom_y_axes(vec![
            y_axis("E_AL (px)"),
            AxisHints::new_y()
                .label("confidence (dashed)")
                .placement(HPlacement::Right)
                .label_spacing(14.0..=22.0)
                .formatter(|m, _| {
                    let c = m.value / CONFIDENCE_SCALE;
                    if (0.0..=1.0).contains(&c) {
                        format!("{c:.1}")
                    } else {
                        String::new()
                    }
                }),
        ])
        .height(170.0)
        .include_y(0.0)
        // Frames 1..10 before any is tracked: whole frame numbers.
        .include_x(1.0)
        .include_x(10.0f64.min(app.frame_count().max(2) as f64))
        .allow_scroll(false)
        .allow_drag(false)
        .show(ui, |p| {
            let ab = app.state.view.ab;
            for (i, t) in app.state.trackers.iter().enumerate() {
                if !ab.is_some_and(|(a, b)| i != a && i != b) {
                    tracker_errors(app, p, i, color(t.color));
                }
            }
            // The shown frame; a click seeks.
            p.vline(
                VLine::new("shown frame", (shown + 1) as f64).color(egui::Color32::from_gray(160)),
            );
            p.set_auto_bounds(true);
            p.pointer_coordinate()
        });
    seek_on_click(app, &r, out);
}

/// A click on a per-frame plot shows the frame under the pointer.
fn seek_on_click(
    app: &InspectorApp,
    r: &egui_plot::PlotResponse<Option<PlotPoint>>,
    out: &mut Vec<Command>,
) {
    if r.response.clicked()
        && let Some(pt) = r.inner
        && app.frame_count() > 0
    {
        let f = (pt.x.round().max(1.0) as usize - 1).min(app.frame_count() - 1);
        out.push(Command::Seek(f));
    }
}

/// Tracker `i`'s alignment errors, its confidence (dashed) and the frames reported lost, all
/// under its legend entry (which shows and hides the three).
fn tracker_errors(app: &InspectorApp, p: &mut egui_plot::PlotUi<'_>, i: usize, c: egui::Color32) {
    let pts: Vec<[f64; 2]> = app
        .errors(i)
        .into_iter()
        .filter(|(_, e)| e.is_finite())
        .map(|(f, e)| [(f + 1) as f64, e.min(50.0)])
        .collect();
    if !pts.is_empty() {
        p.line(
            Line::new(format!("{}", i + 1), PlotPoints::from(pts))
                .color(c)
                .width(line_width(app)),
        );
    }
    // The confidence, dashed, and the frames reported lost (under the
    // tracker's legend entry, which shows and hides all three).
    let conf = app.confidences(i);
    let scaled = |c: f64| c.clamp(0.0, 1.0) * CONFIDENCE_SCALE;
    let line: Vec<[f64; 2]> = conf
        .iter()
        .map(|(f, c, _)| [(f + 1) as f64, scaled(*c)])
        .collect();
    if !line.is_empty() {
        p.line(
            Line::new(format!("{}", i + 1), PlotPoints::from(line))
                .color(c.gamma_multiply(0.7))
                .width(line_width(app))
                .style(LineStyle::dashed_loose()),
        );
    }
    let lost: Vec<[f64; 2]> = conf
        .iter()
        .filter(|(_, _, lost)| *lost)
        .map(|(f, c, _)| [(f + 1) as f64, scaled(*c)])
        .collect();
    if !lost.is_empty() {
        p.points(
            Points::new(format!("{}", i + 1), PlotPoints::from(lost))
                .shape(MarkerShape::Cross)
                .radius(3.0 * app.state.view.label_scale)
                .color(egui::Color32::from_rgb(230, 60, 60)),
        );
    }
}

/// The error plot's legend, above it (inside, it covered the curves): each tracker's colour and
/// what the line styles mean.
fn error_legend(app: &InspectorApp, ui: &mut egui::Ui) {
    let ab = app.state.view.ab;
    ui.horizontal_wrapped(|ui| {
        ui.spacing_mut().item_spacing.x = 10.0;
        for (i, t) in app.state.trackers.iter().enumerate() {
            if ab.is_some_and(|(a, b)| i != a && i != b) {
                continue;
            }
            ui.colored_label(color(t.color), format!("— {}", i + 1))
                .on_hover_text(t.spec.label());
        }
        ui.label(egui::RichText::new("solid: error · dashed: confidence · ×: lost").small());
    });
}

fn speed_table(app: &InspectorApp, ui: &mut egui::Ui) {
    ui.heading("Speed");
    // The figures first: in a narrow panel the names are what is cut off.
    egui::Grid::new("speed")
        .striped(true)
        .max_col_width((ui.available_width() - 230.0).max(60.0))
        .show(ui, |ui| {
            ui.label("");
            ui.label("tracker FPS")
                .on_hover_text("Frames per second of the tracker alone");
            ui.label("live FPS")
                .on_hover_text("Frames per second with the pre-processing of the frame");
            ui.label("it/frame");
            ui.label("tracker");
            ui.end_row();
            for (i, t) in app.state.trackers.iter().enumerate() {
                let (n, s, u, it) = app.speed(i);
                ui.colored_label(color(t.color), format!("{}", i + 1));
                let fps = |us: f64| {
                    if us > 0.0 {
                        format!("{:.0}", n as f64 / (us * 1e-6))
                    } else {
                        "-".into()
                    }
                };
                ui.label(fps(s));
                ui.label(fps(u));
                ui.label(if n > 0 {
                    format!("{:.2}", it as f64 / n as f64)
                } else {
                    "-".into()
                });
                // The name wraps at its parts in what the panel leaves (it was cut off).
                let name = t.spec.label().replace('_', " ");
                ui.add(
                    egui::Label::new(egui::RichText::new(name).color(color(t.color)))
                        .wrap_mode(egui::TextWrapMode::Wrap),
                );
                ui.end_row();
            }
        });
}

/// The width of the plots' curves at the presentation scale.
fn line_width(app: &InspectorApp) -> f32 {
    1.5 * app.state.view.label_scale
}

/// A frame's speed: (frame, update us, iterations).
type FrameSpeed = (usize, f64, usize);

/// Per frame, each tracker's update time and its iterations (a click seeks), in a collapsing
/// section under the speed table.
fn speed_plots(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    egui::CollapsingHeader::new("Speed and iterations per frame")
        .id_salt("speed_plots")
        .show(ui, |ui| {
            let ab = app.state.view.ab;
            let shown: Vec<(usize, egui::Color32, Vec<FrameSpeed>)> = app
                .state
                .trackers
                .iter()
                .enumerate()
                .filter(|(i, _)| !ab.is_some_and(|(a, b)| *i != a && *i != b))
                .map(|(i, t)| (i, color(t.color), app.per_frame_speed(i)))
                .collect();
            if shown.iter().all(|s| s.2.is_empty()) {
                ui.label(egui::RichText::new("no frame tracked yet").small().weak());
                return;
            }
            let frame = app.state.frame;
            let ms: fn(&FrameSpeed) -> f64 = |s| s.1 / 1000.0;
            let its: fn(&FrameSpeed) -> f64 = |s| s.2 as f64;
            let plots = [
                ("update_plot", "update (ms)", ms),
                ("iterations_plot", "iterations", its),
            ];
            for (id, y, value) in plots {
                let r = axes(Plot::new(id), "frame", y)
                    .custom_x_axes(vec![frame_axis("frame")])
                    .height(110.0)
                    .include_y(0.0)
                    .allow_scroll(false)
                    .allow_drag(false)
                    .show(ui, |p| {
                        for (i, c, pts) in &shown {
                            let line: Vec<[f64; 2]> =
                                pts.iter().map(|s| [(s.0 + 1) as f64, value(s)]).collect();
                            p.line(
                                Line::new(format!("{}", i + 1), PlotPoints::from(line)).color(*c),
                            );
                        }
                        p.vline(
                            VLine::new("shown frame", (frame + 1) as f64)
                                .color(egui::Color32::from_gray(160)),
                        );
                        p.pointer_coordinate()
                    });
                seek_on_click(app, &r, out);
            }
        });
}

/// A whole tracker makes one update per frame: what it did.
fn whole_tracker_note(ui: &mut egui::Ui, name: &str, r: &crate::app::worker::TrackerFrame) {
    ui.label(format!(
        "{name}: one update per frame · {:?} · {:.0} µs · score {:.3}",
        r.status,
        r.search_us,
        r.iterations.last().map_or(f64::NAN, |it| it.similarity)
    ));
    ui.label(
        egui::RichText::new(
            "Its internals (response map, detections, keypoints) are drawn on the frame with \
             \"show method internals\" (trackers panel).",
        )
        .small(),
    );
}

/// The similarity and the corner change per iteration, and the slider of the iteration the
/// frame view draws.
fn iteration_plots(
    app: &InspectorApp,
    ui: &mut egui::Ui,
    out: &mut Vec<Command>,
    r: &crate::app::worker::TrackerFrame,
    c: egui::Color32,
) {
    let n = r.iterations.len();
    let cost: Vec<[f64; 2]> = r
        .iterations
        .iter()
        .map(|it| [it.iteration as f64 + 1.0, it.similarity])
        .collect();
    let step: Vec<[f64; 2]> = r
        .iterations
        .iter()
        .map(|it| [it.iteration as f64 + 1.0, it.step.max(1e-6).log10()])
        .collect();
    let marker = app.rt.ui.selected_iteration.map(|k| {
        VLine::new("selected iteration", (k + 1) as f64).color(egui::Color32::from_gray(170))
    });
    ui.columns(2, |cols| {
        axes(Plot::new("cost_plot"), "iteration", "similarity f")
            .height(130.0)
            .allow_scroll(false)
            .show(&mut cols[0], |p| {
                p.line(Line::new("f", PlotPoints::from(cost)).color(c));
                if let Some(m) = marker.clone() {
                    p.vline(m);
                }
            });
        axes(Plot::new("step_plot"), "iteration", "log10 step (px)")
            .height(130.0)
            .allow_scroll(false)
            .show(&mut cols[1], |p| {
                p.line(Line::new("step", PlotPoints::from(step)).color(c));
                if let Some(m) = marker.clone() {
                    p.vline(m);
                }
            });
    });
    let mut sel = app.rt.ui.selected_iteration.map_or(0, |s| s + 1);
    let changed = ui
        .add(egui::Slider::new(&mut sel, 0..=n).text("iteration (0 = none)"))
        .on_hover_text("The frame view draws the quad after this iteration, dashed")
        .changed();
    if changed {
        out.push(Command::SelectIteration(sel.checked_sub(1)));
    }
}

fn convergence(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let i = app.state.selected_tracker;
    let frame = app.state.frame;
    ui.heading(format!(
        "Convergence: tracker {}, frame {}",
        i + 1,
        frame + 1
    ));
    experiment_controls(app, ui, out, frame);
    let Some(r) = app.result(i, frame).cloned() else {
        ui.label("not tracked on this frame");
        return;
    };
    let c = app
        .state
        .trackers
        .get(i)
        .map_or(egui::Color32::WHITE, |t| color(t.color));
    let n = r.iterations.len();
    let whole = app.state.trackers.get(i).and_then(|t| match &t.spec {
        crate::tracker::TrackerSpec::Whole(w) => Some(w.tracker.clone()),
        crate::tracker::TrackerSpec::Registration(_) => None,
    });
    if let Some(name) = whole {
        // A whole tracker makes one update per frame: no iterations to plot.
        return whole_tracker_note(ui, &name, &r);
    }
    ui.label(format!(
        "{n} iterations · {:?} · {:.0} µs",
        r.status, r.search_us
    ));
    if n > 0 {
        iteration_plots(app, ui, out, &r, c);
    }
    patches(app, ui, i, frame, &r);
}

/// The frequency of convergence on the shown frame: run it, and the fraction of starts that
/// converge per noise level, per tracker.
fn frequency(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    egui::CollapsingHeader::new("Frequency of convergence")
        .id_salt("frequency")
        .show(ui, |ui| {
            let running = app.frequency().is_some_and(|f| f.result.is_none());
            frequency_run_row(app, ui, out, running);
            let Some(f) = app.frequency() else {
                ui.label(egui::RichText::new("not run yet").small().weak());
                return;
            };
            let curves = match &f.result {
                None => {
                    ui.label(format!("running on frame {}…", f.frame + 1));
                    return;
                }
                Some(Err(e)) => {
                    ui.colored_label(egui::Color32::from_rgb(255, 110, 110), e);
                    return;
                }
                Some(Ok(c)) => c,
            };
            ui.label(
                egui::RichText::new(format!(
                    "frame {}, {} starts per σ; converged: within 1 px",
                    f.frame + 1,
                    f.starts
                ))
                .small(),
            );
            axes(Plot::new("frequency_plot"), "σ (px)", "fraction converged")
                .height(170.0)
                .legend(Legend::default().position(Corner::LeftBottom))
                .include_x(0.0)
                .include_x(10.0)
                .include_y(0.0)
                .include_y(1.0)
                .allow_scroll(false)
                .show(ui, |p| {
                    for (i, c) in curves {
                        let colour = app
                            .state
                            .trackers
                            .get(*i)
                            .map_or(egui::Color32::WHITE, |t| color(t.color));
                        let pts: Vec<[f64; 2]> = c.points.iter().map(|q| [q.0, q.1]).collect();
                        let name = format!("{} {}", i + 1, c.tracker);
                        p.line(
                            Line::new(name.clone(), PlotPoints::from(pts.clone())).color(colour),
                        );
                        p.points(Points::new(name, pts).radius(2.5).color(colour));
                    }
                });
        });
}

/// The starts per noise level and the button that runs the frequency of convergence.
fn frequency_run_row(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>, running: bool) {
    ui.horizontal_wrapped(|ui| {
        let id = ui.make_persistent_id("frequency_starts");
        let mut starts: usize = ui
            .data(|d| d.get_temp(id))
            .unwrap_or(app.rt.ui.frequency_starts);
        ui.add(
            egui::DragValue::new(&mut starts)
                .range(1..=1000)
                .suffix(" starts"),
        )
        .on_hover_text("Starts per noise level (each a fresh tracker)");
        ui.data_mut(|d| d.insert_temp(id, starts));
        if ui
            .add_enabled(
                !running,
                egui::Button::new(if running {
                    "Running…"
                } else {
                    "Run on this frame"
                }),
            )
            .on_hover_text(
                "Every enabled tracker initialised at the ground truth of this frame, \
                 then started on the same frame from the corners moved by Gaussian \
                 noise of σ = 1..10 px; a start converges when it ends within 1 px \
                 (Baker and Matthews' experiment; regtrack converge on the command line)",
            )
            .clicked()
        {
            out.push(Command::ConvergenceFrequency(starts));
        }
    });
}

/// The convergence experiment: perturb the start on this frame, run every enabled tracker
/// from it, step through the iterations.
fn experiment_controls(
    app: &InspectorApp,
    ui: &mut egui::Ui,
    out: &mut Vec<Command>,
    frame: usize,
) {
    ui.horizontal(|ui| {
        let mut sigma = app.rt.ui.perturb_sigma;
        ui.label("perturb σ");
        if ui
            .add(
                egui::DragValue::new(&mut sigma)
                    .range(0.0..=100.0)
                    .speed(0.1)
                    .suffix(" px"),
            )
            .on_hover_text("Gaussian noise added to each corner coordinate")
            .changed()
        {
            out.push(Command::SetPerturbSigma(sigma));
        }
        if ui
            .button("Perturb (P)")
            .on_hover_text(
                "Start every enabled tracker on this frame from the ground truth (else the \
                 inspected tracker's corners) moved by this noise, seeded: each press the next \
                 start. Step the iterations with . and , (the slider below).",
            )
            .clicked()
        {
            out.push(Command::Perturb);
        }
        if app.rt.ui.experiment.is_some() && ui.button("Clear (Esc)").clicked() {
            out.push(Command::ClearExperiment);
        }
    });
    if let Some(e) = app.experiment_on(frame) {
        let what = if e.from_truth {
            "the ground truth"
        } else {
            "the tracker's corners"
        };
        let text = match &e.results {
            None => format!("experiment: start {} running…", e.number),
            Some(_) => format!(
                "experiment: start {}, {what} moved by σ {} px (dashed white); the views show \
                 each tracker's run from it",
                e.number, e.sigma
            ),
        };
        ui.label(
            egui::RichText::new(text)
                .small()
                .color(egui::Color32::from_rgb(255, 220, 120)),
        );
    }
}

/// The template (`kind` 0), the warped patch (1) or their difference (2) of `r` as an image,
/// in the template's grey range (the difference four times brighter; black for a coarser
/// level's patch, whose grid is not the template's).
fn patch_image(
    r: &crate::app::worker::TrackerFrame,
    current: &[f32],
    size: [usize; 2],
    coarse: bool,
    kind: usize,
) -> egui::ColorImage {
    let n = r.res * r.res * r.channels;
    let (lo, hi) = r
        .template
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = (hi - lo).max(1e-3);
    let to8 = |v: f32| ((v - lo) / span * 255.0).clamp(0.0, 255.0) as u8;
    let (g, size): (Vec<u8>, _) = match kind {
        0 => (r.template.iter().map(|&v| to8(v)).collect(), [r.res, r.res]),
        1 => (current.iter().map(|&v| to8(v)).collect(), size),
        _ if coarse => (vec![0; n], [r.res, r.res]),
        _ => (
            r.template
                .iter()
                .zip(current)
                .map(|(a, b)| ((a - b).abs() / span * 4.0 * 255.0).clamp(0.0, 255.0) as u8)
                .collect(),
            size,
        ),
    };
    planes_image(&g, size, r.channels)
}

/// An image of `size` from `values` (one plane, or a colour patch's three, red, green and blue
/// one after the other; the descriptor fields' four are shown as their mean, the gradient's
/// magnitude along x and y).
fn planes_image(values: &[u8], size: [usize; 2], channels: usize) -> egui::ColorImage {
    let n = size[0] * size[1];
    if channels > 1 && channels != 3 && values.len() == channels * n {
        let mean: Vec<u8> = (0..n)
            .map(|i| {
                let sum: usize = (0..channels).map(|c| values[c * n + i] as usize).sum();
                (sum / channels) as u8
            })
            .collect();
        return egui::ColorImage::from_gray(size, &mean);
    }
    if channels != 3 || values.len() != 3 * n {
        return egui::ColorImage::from_gray(size, &values[..n.min(values.len())]);
    }
    let rgb: Vec<u8> = (0..n)
        .flat_map(|i| [values[i], values[n + i], values[2 * n + i]])
        .collect();
    egui::ColorImage::from_rgb(size, &rgb)
}

fn patches(
    app: &InspectorApp,
    ui: &mut egui::Ui,
    i: usize,
    frame: usize,
    r: &crate::app::worker::TrackerFrame,
) {
    // A colour tracker's patches are its channels' one after the other.
    let channels = r.channels.max(1);
    let n = r.res * r.res * channels;
    if r.template.len() != n || r.patch.len() != n || n == 0 {
        return;
    }
    // The patch after the selected iteration (recorded per iteration), else the final one. An
    // iteration of a coarser pyramid level sampled its own, smaller grid: its patch is shown at
    // its size, and the template and the error only at the finest level's.
    let selected = app.rt.ui.selected_iteration;
    let chosen = selected.and_then(|k| r.iterations.get(k));
    let recorded: Option<Vec<f32>> = chosen
        .filter(|it| !it.patch.is_empty())
        .map(|it| it.patch.iter().map(|&v| v as f32).collect());
    let missing = selected.is_some() && recorded.is_none();
    let current: &[f32] = recorded.as_deref().unwrap_or(&r.patch);
    let side = ((current.len() / channels) as f64).sqrt().round() as usize;
    let coarse = chosen.filter(|_| current.len() != n).map(|it| it.level);
    if side * side * channels != current.len() {
        return;
    }
    let size = [side, side];
    // Made again only when the shown result changes (the run, its results, the iteration,
    // an experiment's run on this frame, the template itself: another sequence's template is
    // another allocation).
    let key = (
        (frame, app.rt.run.generation, selected),
        app.rt.run.results.version(),
        app.experiment_on(frame)
            .map(|e| (e.key, e.results.is_some())),
        (
            std::sync::Arc::as_ptr(&r.template) as usize,
            r.template.len(),
        ),
    );
    let handles = [(0, "template"), (1, "patch"), (2, "error")].map(|(kind, name)| {
        super::cached_texture(
            ui.ctx(),
            &format!("{name}{i}"),
            key,
            egui::TextureOptions::NEAREST,
            || patch_image(r, current, size, coarse.is_some(), kind),
        )
    });
    let at = match (selected, coarse) {
        (Some(k), Some(level)) => {
            format!("iteration {}: pyramid level {level}, {side}x{side}", k + 1)
        }
        (Some(k), None) if !missing => format!("warped patch, iteration {}", k + 1),
        _ => "warped patch (final)".into(),
    };
    if missing {
        ui.label(
            egui::RichText::new(format!(
                "the iterations' patches are kept for the newest {} tracked frames",
                crate::app::PATCH_FRAMES
            ))
            .small(),
        );
    }
    let error = if coarse.is_some() {
        "|error|: finest level only".to_string()
    } else {
        "|error| x4".to_string()
    };
    // Three columns that fit the panel (at 1280x800 the third was squeezed to 10 px and its
    // label wrapped a letter a line): the labels wrap within their image's width, in a row
    // of their own so that the images line up.
    let gap = ui.spacing().item_spacing.x;
    let side = ((ui.available_width() - 2.0 * gap) / 3.0).clamp(48.0, 160.0);
    ui.horizontal_top(|ui| {
        for label in ["template".to_string(), at, error] {
            ui.allocate_ui_with_layout(
                egui::vec2(side, 0.0),
                egui::Layout::top_down(egui::Align::Min),
                |ui| {
                    ui.set_width(side);
                    ui.add(egui::Label::new(egui::RichText::new(label).small()).wrap());
                },
            );
        }
    });
    ui.horizontal(|ui| {
        for h in &handles {
            ui.image((h.id(), egui::Vec2::splat(side)));
        }
    });
}

/// The landscape's colour map (the exported figure's, [`crate::report::colormap`]).
fn colormap(t: f64) -> egui::Color32 {
    let [r, g, b] = crate::report::colormap(t);
    egui::Color32::from_rgb(r, g, b)
}

/// The cost landscape of the inspected tracker on the shown frame: the similarity swept along
/// one parameter (a curve, with the analytic and numeric gradients drawn as tangents) or two (a
/// map, with the path of the iterations), around the estimate or the ground truth.
fn landscape(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let open = egui::CollapsingHeader::new("Cost landscape")
        .id_salt("landscape")
        .open(Some(app.state.view.show_landscape))
        .show(ui, |ui| {
            let names = app.inspected_param_names();
            let dof = names.len();
            if dof == 0 {
                ui.label("the inspected tracker has no warp parameters");
                return;
            }
            let mut settings = app.state.view.landscape;
            landscape_settings(ui, &mut settings, names);
            if settings != app.state.view.landscape {
                out.push(Command::SetLandscape(settings));
            }
            if app.landscape_enlarged() {
                ui.label("shown in its own window");
                if ui.button("Back into the panel").clicked() {
                    out.push(Command::EnlargeLandscape(false));
                }
                return;
            }
            if ui
                .small_button("Enlarge")
                .on_hover_text("Show the landscape in a window of its own, resizable")
                .clicked()
            {
                out.push(Command::EnlargeLandscape(true));
            }
            landscape_plot(app, ui, names, None);
        });
    if open.header_response.clicked() {
        out.push(Command::ShowLandscape(!app.state.view.show_landscape));
    }
    if app.state.view.show_landscape && app.landscape_enlarged() {
        landscape_window(app, ui, out);
    }
}

/// The landscape's axes (`x`, `y` among the parameters `names`), its half-width and its centre.
fn landscape_settings(ui: &mut egui::Ui, v: &mut crate::app::LandscapeSettings, names: &[&str]) {
    let dof = names.len();
    let name = |k: usize| names.get(k).copied().unwrap_or("?");
    ui.horizontal(|ui| {
        ui.label("x");
        egui::ComboBox::from_id_salt("landscape_x")
            .selected_text(name(v.x))
            .show_ui(ui, |ui| {
                for k in 0..dof {
                    ui.selectable_value(&mut v.x, k, name(k));
                }
            });
        ui.label("y");
        egui::ComboBox::from_id_salt("landscape_y")
            .selected_text(v.y.map_or("none", name))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut v.y, None, "none");
                for k in 0..dof {
                    ui.selectable_value(&mut v.y, Some(k), name(k));
                }
            });
        v.x = v.x.min(dof - 1);
        if v.y.is_some_and(|y| y >= dof) {
            v.y = None;
        }
        ui.add(
            egui::DragValue::new(&mut v.radius)
                .range(crate::app::state::LANDSCAPE_RADIUS)
                .speed(0.1)
                .prefix("± ")
                .suffix(" px"),
        )
        .on_hover_text("Half-width of the sweep, in px of mean corner motion");
    });
    ui.horizontal(|ui| {
        ui.radio_value(&mut v.around_truth, false, "around the estimate");
        ui.radio_value(&mut v.around_truth, true, "around the ground truth");
    });
}

/// The landscape enlarged in a window of its own.
fn landscape_window(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>) {
    let i = app.state.selected_tracker;
    let names = app.inspected_param_names();
    let mut keep = true;
    egui::Window::new(format!(
        "Cost landscape: tracker {}, frame {}",
        i + 1,
        app.state.frame + 1
    ))
    .id(egui::Id::unique("landscape_window"))
    .open(&mut keep)
    .resizable(true)
    .default_size([620.0, 600.0])
    // Over the frame, not over the panel that shows its settings.
    .default_pos(ui.ctx().content_rect().left_top() + egui::vec2(240.0, 60.0))
    .show(ui.ctx(), |ui| {
        // The plot takes what the window leaves after the caption and the colour bar.
        let h = (ui.available_height() - 70.0).max(160.0);
        landscape_plot(app, ui, names, Some(h));
    });
    if !keep {
        out.push(Command::EnlargeLandscape(false));
    }
}

/// The landscape's plot (a curve or a map) and its caption; `height` `None` is the panel's size.
fn landscape_plot(app: &InspectorApp, ui: &mut egui::Ui, names: &[&str], height: Option<f32>) {
    let i = app.state.selected_tracker;
    let name = |k: usize| names.get(k).copied().unwrap_or("?");
    let iterations: Vec<Vec<f64>> = app
        .result(i, app.state.frame)
        .map(|r| r.iterations.iter().map(|it| it.params.clone()).collect())
        .unwrap_or_default();
    let c = app
        .state
        .trackers
        .get(i)
        .map_or(egui::Color32::WHITE, |t| color(t.color));
    let Some((result, current)) = app.landscape_shown() else {
        ui.label("computing…");
        return;
    };
    let l = match result {
        Ok(l) => l.clone(),
        Err(e) => {
            ui.colored_label(egui::Color32::from_rgb(255, 110, 110), e);
            return;
        }
    };
    if !current {
        ui.label(egui::RichText::new("updating…").small().weak());
    }
    let scale = l.slope_scale();
    let grads: Vec<String> = l
        .axes
        .iter()
        .zip(l.analytic.iter().zip(&l.numeric))
        .zip(&scale)
        .map(|((k, (a, n)), s)| {
            // At an optimum both are noise next to the slope a pixel away: say so
            // rather than let a gap of "-0.04 against -185" look like a wrong derivative.
            let flat = if a.abs().max(n.abs()) < 0.02 * s {
                format!(" (both ≈ 0 next to {s:.4} a px away: an optimum)")
            } else {
                String::new()
            };
            format!("{}: analytic {a:.4}, numeric {n:.4}{flat}", name(*k))
        })
        .collect();
    ui.label(
        egui::RichText::new(format!(
            "df/du at the centre (per px): {}",
            grads.join("; ")
        ))
        .small(),
    )
    .on_hover_text(
        "The analytic slope is made of image gradients by central differences (what \
         every gradient search method uses: a smoothed derivative); the numeric one is \
         the slope of the interpolated frame over ±0.01 px. On a lightly smoothed frame \
         they differ by up to about a tenth of the gradient without either being wrong \
         (e.g. ZNCC-similitude on the coffee: 38.1 against 42.0 at σ 0.7, 27.5 against \
         28.9 at σ 3); the AM's derivatives themselves pass finite-difference tests.",
    );
    let path: Vec<Vec<f64>> = iterations.iter().map(|p| l.offsets_of(p)).collect();
    if l.axes.len() == 1 {
        landscape_curve(ui, &l, &path, c, names, height.unwrap_or(170.0));
    } else {
        landscape_map(ui, &l, &path, names, height.unwrap_or(230.0));
    }
}

fn landscape_curve(
    ui: &mut egui::Ui,
    l: &crate::landscape::Landscape,
    path: &[Vec<f64>],
    c: egui::Color32,
    names: &[&str],
    height: f32,
) {
    let pts: Vec<[f64; 2]> = l
        .offsets
        .iter()
        .zip(&l.values)
        .filter(|(_, v)| v.is_finite())
        .map(|(u, v)| [*u, *v])
        .collect();
    let r = l.offsets.last().copied().unwrap_or(1.0);
    let tangent = |slope: f64| -> Vec<[f64; 2]> {
        [-r / 3.0, r / 3.0]
            .iter()
            .map(|&u| [u, l.center_value + slope * u])
            .collect()
    };
    // f at an offset, interpolated along the sampled curve (for the iterations' marks).
    let f_at = |u: f64| {
        let step = l.offsets[1] - l.offsets[0];
        let x = ((u - l.offsets[0]) / step).clamp(0.0, (l.offsets.len() - 1) as f64);
        let (i, t) = (x.floor() as usize, x - x.floor());
        let j = (i + 1).min(l.values.len() - 1);
        l.values[i] * (1.0 - t) + l.values[j] * t
    };
    let marks: Vec<[f64; 2]> = path
        .iter()
        .filter_map(|o| o.first().copied())
        .filter(|u| u.abs() <= r)
        .map(|u| [u, f_at(u)])
        .collect();
    axes(
        Plot::new("landscape_curve"),
        &format!(
            "{} offset (px of corner motion)",
            names.get(l.axes[0]).copied().unwrap_or("?")
        ),
        "similarity f",
    )
    .height(height)
    .allow_scroll(false)
    .show(ui, |p| {
        p.line(Line::new("f", PlotPoints::from(pts)).color(c));
        p.line(
            Line::new(
                "analytic gradient",
                PlotPoints::from(tangent(l.analytic[0])),
            )
            .color(egui::Color32::from_rgb(255, 160, 40))
            .width(2.0),
        );
        p.line(
            Line::new("numeric gradient", PlotPoints::from(tangent(l.numeric[0])))
                .color(egui::Color32::from_rgb(120, 220, 120))
                .style(LineStyle::dashed_loose()),
        );
        p.vline(VLine::new("centre", 0.0).color(egui::Color32::from_gray(150)));
        if !marks.is_empty() {
            p.points(
                Points::new("iterations", marks)
                    .radius(3.0)
                    .color(egui::Color32::WHITE),
            );
        }
    });
}

fn landscape_map(
    ui: &mut egui::Ui,
    l: &crate::landscape::Landscape,
    path: &[Vec<f64>],
    names: &[&str],
    height: f32,
) {
    let name = |k: usize| names.get(k).copied().unwrap_or("?");
    let n = l.offsets.len();
    let finite = l.values.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let span = (hi - lo).max(1e-12);
    // Rows from the top: the largest second-axis offset first (the plot's y grows upwards).
    let mut pixels = Vec::with_capacity(n * n);
    for row in (0..n).rev() {
        for col in 0..n {
            pixels.push(colormap((l.values[row * n + col] - lo) / span));
        }
    }
    let key = format!("{:?}{:?}{}", l.axes, l.center, l.center_value);
    let tex = super::cached_texture(
        ui.ctx(),
        "landscape",
        key,
        egui::TextureOptions::NEAREST,
        || egui::ColorImage::new([n, n], pixels),
    );
    let r = l.offsets[n - 1];
    let cell = 2.0 * r / (n - 1) as f64;
    let line: Vec<[f64; 2]> = path
        .iter()
        .filter(|o| o.len() == 2)
        .map(|o| [o[0], o[1]])
        .collect();
    let best = l.best();
    let shown = axes(
        Plot::new("landscape_map"),
        &format!("{} offset (px)", name(l.axes[0])),
        &format!("{} offset (px)", name(l.axes[1])),
    )
    .height(height)
    .data_aspect(1.0)
    .allow_scroll(false)
    .show(ui, |p| {
        p.image(PlotImage::new(
            "similarity",
            tex.id(),
            PlotPoint::new(0.0, 0.0),
            egui::Vec2::splat((2.0 * r + cell) as f32),
        ));
        if !line.is_empty() {
            p.line(
                Line::new("iterations", PlotPoints::from(line.clone())).color(egui::Color32::WHITE),
            );
            p.points(
                Points::new("iterations", line)
                    .radius(2.5)
                    .color(egui::Color32::WHITE),
            );
        }
        p.points(
            Points::new("best sample", vec![[best[0], best[1]]])
                .radius(4.0)
                .color(egui::Color32::from_rgb(255, 80, 80)),
        );
    });
    colour_bar(ui, lo, hi, shown.response.rect.width());
    ui.label(egui::RichText::new("red: the best sample; white: the iterations").small());
}

/// The map's colour scale: the colour of each value of f from `lo` to `hi`, with both ends
/// and the middle labelled.
fn colour_bar(ui: &mut egui::Ui, lo: f64, hi: f64, width: f32) {
    let w = width.min(ui.available_width()).max(60.0);
    let (rect, _) = ui.allocate_exact_size(egui::vec2(w, 12.0), egui::Sense::hover());
    let steps = 64;
    for k in 0..steps {
        let (a, b) = (k as f32 / steps as f32, (k + 1) as f32 / steps as f32);
        let r = egui::Rect::from_min_max(
            egui::pos2(rect.left() + a * w, rect.top()),
            egui::pos2(rect.left() + b * w + 0.5, rect.bottom()),
        );
        ui.painter()
            .rect_filled(r, 0.0, colormap((k as f64 + 0.5) / steps as f64));
    }
    ui.horizontal(|ui| {
        ui.set_width(w);
        let small = |v: f64| {
            let text = if v.abs() >= 100.0 {
                format!("{v:.0}")
            } else {
                format!("{v:.4}")
            };
            egui::RichText::new(text).small()
        };
        ui.label(small(lo)).on_hover_text("f at the darkest colour");
        let mid = ui.available_width() / 2.0 - 40.0;
        ui.add_space(mid.max(0.0));
        ui.label(small(0.5 * (lo + hi)));
        ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
            ui.label(small(hi))
                .on_hover_text("f at the brightest colour");
        });
    });
}

/// A/B mode: the frames where the two trackers disagree most, for a jump.
fn disagreement(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Vec<Command>, a: usize, b: usize) {
    ui.heading(format!("Where {} and {} disagree most", a + 1, b + 1));
    let worst = app.disagreements(a, b);
    if worst.is_empty() {
        ui.label("no frame tracked by both yet");
        return;
    }
    ui.horizontal_wrapped(|ui| {
        for d in worst.iter().take(12) {
            let who = match d.lost {
                [true, _] => format!(" ({} lost)", a + 1),
                [_, true] => format!(" ({} lost)", b + 1),
                _ => String::new(),
            };
            let text = format!("frame {}: {:.1} px{who}", d.frame + 1, d.px);
            if ui
                .selectable_label(app.state.frame == d.frame, text)
                .on_hover_text("Show this frame (ranked by the distance between the two)")
                .clicked()
            {
                out.push(Command::Seek(d.frame));
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::compact;

    /// Tick labels in few characters whatever the range: a live similarity of -4e-13 read
    /// "-0.0000000000004" and squeezed its plot.
    #[test]
    fn tick_labels_are_compact() {
        assert_eq!(compact(-4e-13, 1e-13), "-4e-13");
        assert_eq!(compact(0.0, 1e-13), "0");
        assert_eq!(compact(-30000.0, 10000.0), "-30000");
        assert_eq!(compact(2.5e6, 5e5), "2.5e6");
        assert_eq!(compact(0.25, 0.05), "0.25");
        assert_eq!(compact(12.0, 2.0), "12");
        assert!(compact(f64::NAN, 1.0).is_empty());
    }
}
