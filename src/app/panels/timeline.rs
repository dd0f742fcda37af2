//! The annotator's timeline: one strip over every frame of the sequence, in the ground-truth
//! mode. Per frame: the fit residual (or, where the ground truth is the 8-DOF one, the inspected
//! tracker's error) as a heat colour, occluded frames grey, frames without ground truth black,
//! corrected key frames as green ticks, a pending proposal's frames as an orange band, the
//! selection in blue and the shown frame as a white line. Click to seek; Shift-drag selects a
//! range, on which the buttons act.

use super::Commands;
use crate::app::InspectorApp;
use crate::app::command::{Command, GtCommand};
use crate::gt::GtFrame;
use eframe::egui;
use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};

/// Heat of an error (px): dark green at 0, yellow at 2.5, red from 5.
fn heat(e: f64) -> Color32 {
    let t = (e / 5.0).clamp(0.0, 1.0) as f32;
    if t < 0.5 {
        let u = t * 2.0;
        Color32::from_rgb((40.0 + 200.0 * u) as u8, (110.0 + 110.0 * u) as u8, 40)
    } else {
        let u = (t - 0.5) * 2.0;
        Color32::from_rgb(240, (220.0 * (1.0 - u)) as u8, 40)
    }
}

/// The strip's geometry: `n` frames across `rect`.
#[derive(Clone, Copy)]
struct Strip {
    rect: Rect,
    n: usize,
}

impl Strip {
    /// The centre of frame `f`'s column.
    fn x_of(&self, f: usize) -> f32 {
        self.rect.left() + self.rect.width() * (f as f32 + 0.5) / self.n as f32
    }
    /// The frame under `p`.
    fn frame_at(&self, p: Pos2) -> usize {
        (((p.x - self.rect.left()) / self.rect.width() * self.n as f32)
            .floor()
            .max(0.0) as usize)
            .min(self.n - 1)
    }
    /// A frame's width (at least a pixel).
    fn cell(&self) -> f32 {
        (self.rect.width() / self.n as f32).max(1.0)
    }
}

/// What the strip shows of each frame: its ground truth, fit residual and the inspected
/// tracker's error.
struct Frames {
    table: std::sync::Arc<crate::app::gt_edit::GtTable>,
    errors: std::collections::BTreeMap<usize, f64>,
}

impl Frames {
    fn gt(&self, f: usize) -> Option<GtFrame> {
        self.table.frames.get(f).copied()
    }
    fn residual(&self, f: usize) -> Option<f64> {
        self.table.residuals.get(f).copied().flatten()
    }
    /// A frame's colour and how bad it is (the heat of its residual or error; occluded grey;
    /// without ground truth black).
    fn colour(&self, f: usize) -> (Color32, f64) {
        match self.gt(f) {
            Some(GtFrame::Occluded) => (Color32::from_gray(90), 0.0),
            Some(GtFrame::Quad { .. }) => {
                let e = self
                    .residual(f)
                    .filter(|r| *r > 1e-9)
                    .or_else(|| self.errors.get(&f).copied())
                    .unwrap_or(0.0);
                (heat(e), e)
            }
            _ => (Color32::BLACK, -0.5),
        }
    }
    /// What the hover text says of frame `f`.
    fn describe(&self, f: usize) -> String {
        match (self.gt(f), self.residual(f), self.errors.get(&f)) {
            (Some(GtFrame::Occluded), _, _) => "occluded".to_string(),
            (
                Some(GtFrame::Quad {
                    corrected: true, ..
                }),
                _,
                _,
            ) => "corrected".to_string(),
            (Some(GtFrame::Quad { .. }), Some(r), _) if r > 1e-9 => {
                format!("fit residual {r:.2} px")
            }
            (Some(GtFrame::Quad { .. }), _, Some(e)) => format!("tracker error {e:.2} px"),
            (Some(GtFrame::Quad { .. }), _, None) => "ground truth".to_string(),
            _ => "no ground truth".to_string(),
        }
    }
}

pub fn timeline(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Commands) {
    let n = app.frame_count();
    if n == 0 {
        return;
    }
    let (rect, response) = ui.allocate_exact_size(
        Vec2::new(ui.available_width(), 30.0),
        Sense::click_and_drag(),
    );
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_gray(20));
    let strip = Strip { rect, n };
    // The table once (each lookup by frame would check its cache key).
    let Some(table) = app.gt_table() else {
        return;
    };
    let frames = Frames {
        table,
        errors: app.errors(app.state.selected_tracker).into_iter().collect(),
    };
    draw_heat(&painter, strip, &frames);
    draw_marks(app, &painter, strip);
    pointer(app, ui, &response, strip, out);
    let hover = response.hover_pos().map(|p| strip.frame_at(p));
    response.on_hover_text(match hover {
        Some(f) => format!(
            "frame {}: {} (click: show it; Shift-drag: select frames)",
            f + 1,
            frames.describe(f)
        ),
        None => String::new(),
    });
    ui.horizontal_wrapped(|ui| match app.gt_selection() {
        Some((a, b)) => selection_buttons(app, ui, (a, b), out),
        None => {
            ui.label(
                egui::RichText::new(
                    "timeline: heat = fit residual or tracker error, green ticks = corrected, \
                         orange = proposal; click to show a frame, Shift-drag to select",
                )
                .small()
                .weak(),
            );
        }
    });
}

/// One column per pixel at most: the worst frame of each column is drawn.
fn draw_heat(painter: &egui::Painter, strip: Strip, frames: &Frames) {
    let (rect, n) = (strip.rect, strip.n);
    let columns = (rect.width().floor() as usize).clamp(1, n);
    for c in 0..columns {
        let (a, b) = (
            c * n / columns,
            ((c + 1) * n / columns).max(c * n / columns + 1),
        );
        let mut colour = Color32::BLACK;
        let mut worst = -1.0f64;
        for f in a..b.min(n) {
            let (col, e) = frames.colour(f);
            if e > worst {
                worst = e;
                colour = col;
            }
        }
        let x0 = rect.left() + rect.width() * a as f32 / n as f32;
        let x1 = rect.left() + rect.width() * b.min(n) as f32 / n as f32;
        painter.rect_filled(
            Rect::from_min_max(
                Pos2::new(x0, rect.top() + 6.0),
                Pos2::new(x1.max(x0 + 1.0), rect.bottom() - 6.0),
            ),
            0.0,
            colour,
        );
    }
}

/// The corrected key frames, a pending proposal's frames, the selection and the shown frame.
fn draw_marks(app: &InspectorApp, painter: &egui::Painter, strip: Strip) {
    let (rect, cell) = (strip.rect, strip.cell());
    let key = crate::gt::ssm_key(&app.state.gt_ssm).unwrap_or_default();
    for f in app.corrections().corrected_frames(&key) {
        let x = strip.x_of(f);
        painter.line_segment(
            [Pos2::new(x, rect.top()), Pos2::new(x, rect.top() + 6.0)],
            Stroke::new(cell.clamp(1.5, 3.0), Color32::from_rgb(60, 230, 90)),
        );
    }
    if let Some(p) = app.gt_proposal() {
        for (f, _) in &p.frames {
            let x = strip.x_of(*f);
            painter.line_segment(
                [
                    Pos2::new(x, rect.bottom() - 6.0),
                    Pos2::new(x, rect.bottom()),
                ],
                Stroke::new(cell.max(1.5), Color32::from_rgb(255, 150, 30)),
            );
        }
    }
    if let Some((a, b)) = app.gt_selection() {
        let r = Rect::from_min_max(
            Pos2::new(strip.x_of(a) - cell / 2.0, rect.top()),
            Pos2::new(strip.x_of(b) + cell / 2.0, rect.bottom()),
        );
        painter.rect_filled(r, 0.0, Color32::from_rgba_unmultiplied(80, 140, 255, 70));
    }
    let x = strip.x_of(app.state.frame);
    painter.line_segment(
        [Pos2::new(x, rect.top()), Pos2::new(x, rect.bottom())],
        Stroke::new(2.0, Color32::WHITE),
    );
}

/// Shift-drag selects; a click seeks (Shift-click selects from the shown frame).
fn pointer(
    app: &InspectorApp,
    ui: &egui::Ui,
    response: &egui::Response,
    strip: Strip,
    out: &mut Commands,
) {
    let shift = ui.input(|i| i.modifiers.shift);
    if shift
        && response.dragged()
        && let (Some(origin), Some(now)) = (
            ui.input(|i| i.pointer.press_origin()),
            response.interact_pointer_pos(),
        )
    {
        out.push(Command::Gt(GtCommand::Select(Some((
            strip.frame_at(origin),
            strip.frame_at(now),
        )))));
    } else if response.clicked()
        && let Some(p) = response.interact_pointer_pos()
    {
        if shift {
            out.push(Command::Gt(GtCommand::Select(Some((
                app.state.frame,
                strip.frame_at(p),
            )))));
        } else {
            out.push(Command::Seek(strip.frame_at(p)));
        }
    }
}

/// What can be done with the selected frames `a..=b`.
fn selection_buttons(
    app: &InspectorApp,
    ui: &mut egui::Ui,
    (a, b): (usize, usize),
    out: &mut Commands,
) {
    ui.label(format!("selected: frames {}-{}", a + 1, b + 1));
    if app.gt_proposal().is_some()
        && ui
            .button("Accept the proposal here")
            .on_hover_text("Accept the proposed frames inside the selection only")
            .clicked()
    {
        out.push(Command::Gt(GtCommand::AcceptProposalInSelection));
    }
    if ui
        .button("Interpolate here")
        .on_hover_text(
            "The frames inside the selection from its first and last frames' ground \
             truth, in the SSM's parameters (one undoable edit)",
        )
        .clicked()
    {
        out.push(Command::Gt(GtCommand::InterpolateSelection));
    }
    if ui
        .add_enabled(!app.gt_propagating(), egui::Button::new("Propagate here"))
        .on_hover_text(
            "Track from the selection's first frame to its last with the inspected \
             tracker; then accept or reject the proposal",
        )
        .clicked()
    {
        out.push(Command::Gt(GtCommand::PropagateSelection));
    }
    if ui
        .button("Delete corrections here")
        .on_hover_text("The selected frames back to the original ground truth (one undoable edit)")
        .clicked()
    {
        out.push(Command::Gt(GtCommand::RevertSelection));
    }
    if ui.button("Clear selection").clicked() {
        out.push(Command::Gt(GtCommand::Select(None)));
    }
}
