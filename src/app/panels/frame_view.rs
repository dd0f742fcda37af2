//! The frame with the tracked and ground-truth quads; zoom and pan; drawing a tracker's initial
//! quad or box; dragging ground-truth corners. One place maps image to screen coordinates.

use super::{Commands, GT_COLOR, color};
use crate::app::command::{Command, GtCommand};
use crate::app::state::{InitSource, View};
use crate::app::{InspectorApp, Tool};
use crate::geometry::{Point, Quad};
use crate::observe::VisualRecord;
use crate::tracker::TrackStatus;
use eframe::egui;
use egui::{Color32, Pos2, Rect, Sense, Shape, Stroke, Vec2};

/// Image <-> screen mapping of the view.
#[derive(Clone, Copy, Debug)]
pub struct Transform {
    rect: Rect,
    scale: f32,
    center: [f32; 2],
    /// The presentation scale of labels and lines ([`View::label_scale`]).
    pub label_scale: f32,
}

impl Transform {
    fn new(rect: Rect, image: [usize; 2], view: &View) -> Self {
        let (w, h) = (image[0].max(1) as f32, image[1].max(1) as f32);
        if view.zoom <= 0.0 {
            Transform {
                rect,
                scale: (rect.width() / w).min(rect.height() / h),
                center: [w / 2.0 - 0.5, h / 2.0 - 0.5],
                label_scale: view.label_scale,
            }
        } else {
            Transform {
                rect,
                scale: view.zoom,
                center: view.center,
                label_scale: view.label_scale,
            }
        }
    }
    /// Image point to screen.
    pub fn to_screen(self, p: Point) -> Pos2 {
        self.rect.center()
            + Vec2::new(
                (p.x as f32 - self.center[0]) * self.scale,
                (p.y as f32 - self.center[1]) * self.scale,
            )
    }
    /// Screen to image point.
    pub fn to_image(self, s: Pos2) -> Point {
        let d = s - self.rect.center();
        Point::new(
            (d.x / self.scale + self.center[0]) as f64,
            (d.y / self.scale + self.center[1]) as f64,
        )
    }
}

/// The colour of a propagation's proposal.
const PROPOSAL_COLOR: Color32 = Color32::from_rgb(255, 150, 30);

fn quad_points(t: &Transform, q: &Quad) -> Vec<Pos2> {
    q.0.iter().map(|p| t.to_screen(*p)).collect()
}

fn draw_quad(
    painter: &egui::Painter,
    t: &Transform,
    q: &Quad,
    c: Color32,
    dashed: bool,
    numbers: bool,
) {
    let pts = quad_points(t, q);
    let k = t.label_scale;
    if dashed {
        let mut closed = pts.clone();
        closed.push(pts[0]);
        painter.extend(Shape::dashed_line(
            &closed,
            Stroke::new(2.0 * k, c),
            7.0 * k,
            4.0 * k,
        ));
    } else {
        painter.add(Shape::closed_line(pts.clone(), Stroke::new(2.0 * k, c)));
    }
    for (n, p) in pts.iter().enumerate() {
        painter.circle_filled(*p, 3.5 * k, c);
        if numbers {
            painter.text(
                *p + Vec2::new(5.0, -5.0) * k,
                egui::Align2::LEFT_BOTTOM,
                (n + 1).to_string(),
                egui::FontId::monospace(12.0 * k),
                c,
            );
        }
    }
}

/// A label of a quad on the frame, placed beside it by [`place_labels`].
pub struct QuadLabel {
    pub quad: Quad,
    pub text: String,
    pub color: Color32,
}

/// Draws the labels beside their quads (right of each quad's box, else left of it), at the
/// presentation scale, each on a dark backing and moved down past those already placed: on
/// the target they hid it and each other ("start 2", "iteration 7", "3 lost").
fn place_labels(painter: &egui::Painter, t: &Transform, labels: &[QuadLabel]) {
    let font = egui::FontId::proportional(14.0 * t.label_scale);
    let pad = Vec2::new(4.0, 2.0) * t.label_scale;
    let mut placed: Vec<Rect> = Vec::new();
    for l in labels {
        let pts = quad_points(t, &l.quad);
        let bbox = Rect::from_points(&pts);
        let galley = painter.layout_no_wrap(l.text.clone(), font.clone(), l.color);
        let size = galley.size() + 2.0 * pad;
        let gap = 6.0 * t.label_scale;
        let right = bbox.right() + gap + size.x <= t.rect.right();
        let x = if right {
            bbox.right() + gap
        } else {
            (bbox.left() - gap - size.x).max(t.rect.left())
        };
        let mut r = Rect::from_min_size(egui::pos2(x, bbox.top().max(t.rect.top())), size);
        for _ in 0..32 {
            match placed.iter().find(|p| p.intersects(r)) {
                Some(p) => r = r.translate(Vec2::new(0.0, p.bottom() - r.top() + 2.0)),
                None => break,
            }
        }
        painter.rect_filled(r, 3.0, Color32::from_black_alpha(170));
        painter.galley(r.min + pad, galley, l.color);
        placed.push(r);
    }
}

/// The frame's image under `t` (pixel centres on integer coordinates); returns where it lies.
fn draw_frame(
    painter: &egui::Painter,
    t: &Transform,
    texture: &egui::TextureHandle,
    size: [usize; 2],
) -> Rect {
    let [w, h] = size;
    let img_rect = Rect::from_min_max(
        t.to_screen(Point::new(-0.5, -0.5)),
        t.to_screen(Point::new(w as f64 - 0.5, h as f64 - 0.5)),
    );
    painter.image(
        texture.id(),
        img_rect,
        Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
        Color32::WHITE,
    );
    img_rect
}

/// A non-rigid tracker's lattice: its rows and columns as thin lines.
fn draw_warped_grid(
    painter: &egui::Painter,
    t: &Transform,
    grid: &crate::visual_tracker::WarpedGrid,
    c: Color32,
) {
    let n = grid.side;
    if n < 2 || grid.points.len() != n * n {
        return;
    }
    let stroke = egui::Stroke::new(1.0, c);
    let at = |k: usize| t.to_screen(grid.points[k]);
    for i in 0..n {
        let row: Vec<egui::Pos2> = (0..n).map(|j| at(i * n + j)).collect();
        let col: Vec<egui::Pos2> = (0..n).map(|j| at(j * n + i)).collect();
        painter.add(Shape::line(row, stroke));
        painter.add(Shape::line(col, stroke));
    }
}

/// A tracker's corners in its colour; a lost tracker's last corners dashed and faded.
fn draw_tracker_quad(
    painter: &egui::Painter,
    t: &Transform,
    r: &crate::app::worker::TrackerFrame,
    c: Color32,
    numbers: bool,
) {
    let lost = r.status != TrackStatus::Tracking;
    if let (Some(grid), false) = (&r.grid, lost) {
        draw_warped_grid(painter, t, grid, c.gamma_multiply(0.6));
    }
    draw_quad(
        painter,
        t,
        &r.corners,
        if lost { c.gamma_multiply(0.5) } else { c },
        lost,
        numbers && !lost,
    );
}

/// Scroll zooms around the pointer (the image point under it stays); double-click fits.
fn zoom(
    app: &InspectorApp,
    ui: &egui::Ui,
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
) {
    if let Some(pos) = response.hover_pos() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            let anchor = t.to_image(pos);
            let scale = (t.scale * (scroll * 0.003).exp()).clamp(
                *crate::app::state::ZOOM.start(),
                *crate::app::state::ZOOM.end(),
            );
            let d = pos - t.rect.center();
            let mut view = app.state.view.clone();
            view.zoom = scale;
            view.center = [anchor.x as f32 - d.x / scale, anchor.y as f32 - d.y / scale];
            out.push(Command::SetView(view));
        }
    }
    if response.double_clicked() && app.rt.ui.tool == Tool::Navigate {
        let mut view = app.state.view.clone();
        view.zoom = 0.0;
        out.push(Command::SetView(view));
    }
}

/// A/B mode: the frame twice, tracker A's quad on the left and B's on the right (the ground truth
/// on both), under the same zoom.
fn ab_view(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Commands, a: usize, b: usize) {
    let rect = ui.available_rect_before_wrap();
    let response = ui.allocate_rect(rect, Sense::click_and_drag());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_gray(24));
    let Some(texture) = app.rt.display.texture.clone() else {
        return;
    };
    let frame = app.state.frame;
    let half = rect.width() / 2.0;
    for (side, k) in [(0usize, a), (1, b)] {
        let r = Rect::from_min_size(
            rect.left_top() + Vec2::new(side as f32 * half, 0.0),
            Vec2::new(half - 2.0, rect.height()),
        );
        let t = Transform::new(r, app.rt.display.image_size, &app.state.view);
        let p = painter.with_clip_rect(r);
        draw_frame(&p, &t, &texture, app.rt.display.image_size);
        if app.state.view.show_ground_truth
            && let Some(gt) = app.ground_truth(frame)
        {
            draw_quad(&p, &t, &gt, GT_COLOR, true, false);
        }
        let Some(entry) = app.state.trackers.get(k) else {
            continue;
        };
        let c = color(entry.color);
        if let Some(res) = app.result(k, frame) {
            draw_tracker_quad(&p, &t, res, c, false);
        }
        p.text(
            r.left_top() + Vec2::new(8.0, 8.0),
            egui::Align2::LEFT_TOP,
            format!("{} {}: {}", ["A", "B"][side], k + 1, entry.spec.label()),
            egui::FontId::proportional(15.0),
            c,
        );
    }
    painter.line_segment(
        [rect.center_top(), rect.center_bottom()],
        Stroke::new(1.0, Color32::from_gray(90)),
    );
    // Scroll zooms both halves alike (around the pointer, in the half it is over).
    if let Some(pos) = response.hover_pos() {
        let side = if pos.x < rect.center().x { 0.0 } else { half };
        let r = Rect::from_min_size(
            rect.left_top() + Vec2::new(side, 0.0),
            Vec2::new(half - 2.0, rect.height()),
        );
        zoom(
            app,
            ui,
            out,
            &response,
            &Transform::new(r, app.rt.display.image_size, &app.state.view),
        );
    }
}

/// The frame with the quads; returns where it drew the image (`None` in A/B mode or without an
/// image).
pub fn frame_view(app: &InspectorApp, ui: &mut egui::Ui, out: &mut Commands) -> Option<Transform> {
    if let Some((a, b)) = app.state.view.ab
        && a < app.state.trackers.len()
        && b < app.state.trackers.len()
        && app.rt.ui.tool == Tool::Navigate
    {
        ab_view(app, ui, out, a, b);
        return None;
    }
    let rect = ui.available_rect_before_wrap();
    let response = ui.allocate_rect(rect, Sense::click_and_drag());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_gray(24));
    let Some(texture) = app.rt.display.texture.clone() else {
        // What is under way (the first start renders the demo for a while), else what to do.
        let text = match &app.rt.msg.progress {
            Some((what, d, t)) if *t > 0 => format!("{what}: {d} of {t}…"),
            Some((what, _, _)) => format!("{what}…"),
            None => "open a sequence (or drop a folder here)".into(),
        };
        painter.text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            text,
            egui::FontId::proportional(18.0),
            Color32::GRAY,
        );
        if let Some((_, d, t)) = &app.rt.msg.progress
            && *t > 0
        {
            let w = (rect.width() * 0.5).min(360.0);
            let bar =
                Rect::from_center_size(rect.center() + Vec2::new(0.0, 30.0), Vec2::new(w, 8.0));
            painter.rect_filled(bar, 3.0, Color32::from_gray(60));
            let done = Rect::from_min_size(
                bar.min,
                Vec2::new(w * (*d as f32 / *t as f32).clamp(0.0, 1.0), 8.0),
            );
            painter.rect_filled(done, 3.0, Color32::from_rgb(90, 150, 230));
        }
        return None;
    };
    follow_target(app, ui, out, rect);
    let t = Transform::new(rect, app.rt.display.image_size, &app.state.view);
    draw_image(app, &painter, &t, &texture);
    let frame = app.state.frame;
    let mut labels = Vec::new();
    draw_truth_and_proposal(app, &painter, &t, frame, &mut labels);
    if let Some((states, half)) = app.patches_on(frame) {
        draw_patches(&painter, &t, states, half);
    }
    draw_trackers(app, &painter, &t, frame, &mut labels);
    draw_iteration_and_experiment(app, &painter, &t, frame, &mut labels);
    place_labels(&painter, &t, &labels);
    interact(app, ui, out, &response, &t, &painter);
    Some(t)
}

/// Zoomed in with "follow the target" on, a newly shown frame is centred on the target (its
/// ground truth in the ground-truth mode, the inspected tracker's corners otherwise), once per
/// frame so that the view can still be panned.
fn follow_target(app: &InspectorApp, ui: &egui::Ui, out: &mut Commands, rect: Rect) {
    let view = &app.state.view;
    let gt_mode = app.rt.ui.tool == Tool::EditGroundTruth;
    let on = if gt_mode {
        view.follow_in_gt_mode
    } else {
        view.follow_tracker
    };
    let frame = app.state.frame;
    let id = egui::Id::unique("followed_frame");
    let last: Option<(usize, bool)> = ui.data(|d| d.get_temp(id));
    if !on || view.zoom <= 0.0 || last == Some((frame, gt_mode)) {
        return;
    }
    let target = if gt_mode {
        app.ground_truth(frame)
    } else {
        app.result(app.state.selected_tracker, frame)
            .map(|r| r.corners)
            .or_else(|| app.ground_truth(frame))
    };
    let Some(q) = target else {
        return;
    };
    ui.data_mut(|d| d.insert_temp(id, (frame, gt_mode)));
    let c = q.centroid();
    // Only when it left the middle of the view (a small move keeps the view still).
    let t = Transform::new(rect, app.rt.display.image_size, view);
    let at = t.to_screen(c);
    if rect.shrink2(rect.size() * 0.2).contains(at) {
        return;
    }
    let mut v = view.clone();
    v.center = [c.x as f32, c.y as f32];
    out.push(Command::SetView(v));
}

/// The frame's image, or why it could not be read (instead of the previous image under this
/// frame's ground truth).
fn draw_image(
    app: &InspectorApp,
    painter: &egui::Painter,
    t: &Transform,
    texture: &egui::TextureHandle,
) {
    let [w, h] = app.rt.display.image_size;
    match app
        .rt
        .seq
        .bad_frame
        .as_ref()
        .filter(|b| b.0 == app.state.frame)
    {
        // The frame could not be read: say so instead of showing the previous image under this
        // frame's ground truth.
        Some((_, message)) => {
            let img_rect = Rect::from_min_max(
                t.to_screen(Point::new(-0.5, -0.5)),
                t.to_screen(Point::new(w as f64 - 0.5, h as f64 - 0.5)),
            );
            painter.rect_filled(img_rect, 0.0, Color32::from_gray(40));
            painter.text(
                img_rect.center(),
                egui::Align2::CENTER_CENTER,
                format!("frame {} could not be read\n{message}", app.state.frame + 1),
                egui::FontId::proportional(15.0),
                Color32::from_rgb(255, 110, 110),
            );
        }
        None => {
            draw_frame(painter, t, texture, app.rt.display.image_size);
        }
    }
}

/// The ground truth (with the 8-DOF one under a low-DOF one when correcting it) and a pending
/// proposal's quad.
fn draw_truth_and_proposal(
    app: &InspectorApp,
    painter: &egui::Painter,
    t: &Transform,
    frame: usize,
    labels: &mut Vec<QuadLabel>,
) {
    let numbers = app.state.view.show_corner_numbers;
    if app.state.view.show_ground_truth {
        // The 8-DOF ground truth under a low-DOF one, thin.
        if app.rt.ui.tool == Tool::EditGroundTruth
            && crate::gt::ssm_key(&app.state.gt_ssm).is_ok_and(|k| k != "homography")
            && let Some(full) = app.sequence().and_then(|s| s.ground_truth(frame))
        {
            let pts = quad_points(t, &full);
            painter.add(Shape::closed_line(
                pts,
                Stroke::new(1.0, GT_COLOR.gamma_multiply(0.6)),
            ));
        }
        if let Some(gt) = app.ground_truth(frame) {
            draw_quad(painter, t, &gt, GT_COLOR, true, numbers);
        }
    }
    if let Some(q) = app
        .gt_proposal()
        .and_then(|p| p.frames.iter().find(|(f, _)| *f == frame))
        .map(|(_, q)| *q)
    {
        draw_quad(painter, t, &q, PROPOSAL_COLOR, true, false);
        labels.push(QuadLabel {
            quad: q,
            text: "proposal".into(),
            color: PROPOSAL_COLOR,
        });
    }
}

/// Each tracker's quad and label, and what the methods show of themselves.
fn draw_trackers(
    app: &InspectorApp,
    painter: &egui::Painter,
    t: &Transform,
    frame: usize,
    labels: &mut Vec<QuadLabel>,
) {
    let numbers = app.state.view.show_corner_numbers;
    if app.state.view.show_samples {
        for (i, entry) in app.state.trackers.iter().enumerate() {
            if let Some(v) = app.result(i, frame).and_then(|r| r.visual.as_ref()) {
                draw_visual(painter, t, v, color(entry.color));
            }
        }
    }
    for (i, entry) in app.state.trackers.iter().enumerate() {
        if let Some(r) = app.result(i, frame) {
            let c = color(entry.color);
            draw_tracker_quad(painter, t, r, c, numbers);
            let label = match r.status {
                TrackStatus::Lost(reason) => format!("{} lost: {reason}", i + 1),
                _ => format!("{}", i + 1),
            };
            labels.push(QuadLabel {
                quad: r.corners,
                text: label,
                color: c,
            });
        }
    }
}

/// The selected iteration of the inspected tracker, and the convergence experiment's start.
fn draw_iteration_and_experiment(
    app: &InspectorApp,
    painter: &egui::Painter,
    t: &Transform,
    frame: usize,
    labels: &mut Vec<QuadLabel>,
) {
    // The selected iteration of the inspected tracker.
    if let (Some(it), Some(r)) = (
        app.rt.ui.selected_iteration,
        app.result(app.state.selected_tracker, frame),
    ) && let Some(rec) = r.iterations.get(it)
    {
        // In the inspected tracker's colour, lightened so that it stands out from its final quad.
        let c = app
            .state
            .trackers
            .get(app.state.selected_tracker)
            .map_or(Color32::YELLOW, |t| color(t.color));
        let light = Color32::from_rgb(
            c.r().saturating_add(90),
            c.g().saturating_add(90),
            c.b().saturating_add(90),
        );
        draw_quad(painter, t, &rec.corners, light, true, false);
        labels.push(QuadLabel {
            quad: rec.corners,
            text: format!("iteration {}", it + 1),
            color: light,
        });
    }
    // The convergence experiment's start, dashed white.
    if let Some(e) = app.experiment_on(frame) {
        let pts = quad_points(t, &e.start);
        let mut closed = pts.clone();
        closed.push(pts[0]);
        let k = t.label_scale;
        painter.add(Shape::dashed_line(
            &closed,
            Stroke::new(1.5 * k, Color32::WHITE),
            6.0 * k,
            4.0 * k,
        ));
        labels.push(QuadLabel {
            quad: e.start,
            text: format!("start {} (σ {} px)", e.number, e.sigma),
            color: Color32::WHITE,
        });
    }
}

/// What a method shows: a response map under everything (blue to yellow, translucent), a
/// sampling method's candidates as the corners of the target under each (faint when unlike the
/// template, bright when like it) or a detector's boxes, the chosen one outlined, and points
/// (keypoints; bright when they count).
/// Many patches: each tracked one's window (its affine shape) in green, each lost one as a red
/// cross where it was last.
fn draw_patches(
    painter: &egui::Painter,
    t: &Transform,
    states: &[crate::patches::PatchState],
    half: f64,
) {
    let green = Stroke::new(1.0, Color32::from_rgb(80, 230, 120));
    let red = Stroke::new(1.0, Color32::from_rgb(255, 90, 90));
    for s in states {
        if s.tracking() {
            painter.add(Shape::closed_line(quad_points(t, &s.corners(half)), green));
        } else {
            let c = t.to_screen(s.centre);
            let d = 3.0;
            painter.line_segment([c + Vec2::new(-d, -d), c + Vec2::new(d, d)], red);
            painter.line_segment([c + Vec2::new(-d, d), c + Vec2::new(d, -d)], red);
        }
    }
}

fn draw_visual(painter: &egui::Painter, t: &Transform, v: &VisualRecord, c: Color32) {
    if let Some(m) = &v.map {
        draw_response_map(painter, t, m);
    }
    let boxes = v.label == "detections";
    // Weights relative to the largest: a particle filter's sum to 1 over hundreds of particles,
    // each too small to see on an absolute scale.
    let top = v.weights.iter().copied().fold(0.0f32, f32::max);
    let rel = |w: f32| {
        if top > 0.0 {
            (w / top).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    // The best candidates' outlines (the rest would bury the frame).
    let mut order: Vec<usize> = (0..v.quads.len().min(v.weights.len())).collect();
    order.sort_by(|&a, &b| v.weights[b].total_cmp(&v.weights[a]));
    for (rank, &k) in order.iter().enumerate() {
        let (q, w) = (&v.quads[k], rel(v.weights[k]));
        let col = c.gamma_multiply(0.15 + 0.85 * w);
        if boxes || rank < 8 {
            painter.add(Shape::closed_line(
                quad_points(t, q),
                Stroke::new(if boxes { 1.0 } else { 0.8 }, col),
            ));
        }
        if !boxes {
            // Each candidate as a dot at its centre, larger and brighter the likelier it is.
            let centre = crate::geometry::Point::new(
                q.0.iter().map(|p| p.x).sum::<f64>() / 4.0,
                q.0.iter().map(|p| p.y).sum::<f64>() / 4.0,
            );
            painter.circle_filled(t.to_screen(centre), 1.5 + 3.0 * w, col);
        }
    }
    if let Some(q) = v.chosen.and_then(|k| v.quads.get(k)) {
        let pts = quad_points(t, q);
        painter.add(Shape::closed_line(pts, Stroke::new(1.5, Color32::WHITE)));
    }
    if v.label == crate::observe::SELECTED_PIXELS {
        // Hundreds of grid points: small dots.
        let col = c.gamma_multiply(0.8);
        for p in &v.points {
            painter.circle_filled(t.to_screen(*p), 1.2, col);
        }
        return;
    }
    for (k, p) in v.points.iter().enumerate() {
        let w = v
            .point_weights
            .get(k)
            .copied()
            .unwrap_or(1.0)
            .clamp(0.0, 1.0);
        painter.circle_stroke(
            t.to_screen(*p),
            2.5,
            Stroke::new(1.2, c.gamma_multiply(0.2 + 0.8 * w)),
        );
    }
}

/// A response map under everything (blue to yellow, translucent), its cells along its quad's
/// sides (an axis-aligned box for the filters).
fn draw_response_map(painter: &egui::Painter, t: &Transform, m: &crate::observe::MapRecord) {
    if m.width == 0 || m.height == 0 || m.values.len() != m.width * m.height {
        return;
    }
    let (lo, hi) = m
        .values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let span = (hi - lo).max(1e-12);
    // The map's cells, along its quad's sides (an axis-aligned box for the filters).
    let q = m.at.0;
    let at = |u: f64, w: f64| crate::geometry::Point {
        x: q[0].x + u * (q[1].x - q[0].x) + w * (q[3].x - q[0].x),
        y: q[0].y + u * (q[1].y - q[0].y) + w * (q[3].y - q[0].y),
    };
    let mut mesh = egui::Mesh::default();
    for j in 0..m.height {
        for i in 0..m.width {
            let v = ((m.values[j * m.width + i] - lo) / span).clamp(0.0, 1.0);
            let col = Color32::from_rgba_unmultiplied(
                (255.0 * v) as u8,
                (200.0 * v + 40.0 * (1.0 - v)) as u8,
                (160.0 * (1.0 - v)) as u8,
                (40.0 + 120.0 * v) as u8,
            );
            let (u0, u1) = (i as f64 / m.width as f64, (i + 1) as f64 / m.width as f64);
            let (w0, w1) = (j as f64 / m.height as f64, (j + 1) as f64 / m.height as f64);
            let base = mesh.vertices.len() as u32;
            for (u, w) in [(u0, w0), (u1, w0), (u1, w1), (u0, w1)] {
                mesh.colored_vertex(t.to_screen(at(u, w)), col);
            }
            mesh.add_triangle(base, base + 1, base + 2);
            mesh.add_triangle(base, base + 2, base + 3);
        }
    }
    painter.add(Shape::mesh(mesh));
}

fn interact(
    app: &InspectorApp,
    ui: &egui::Ui,
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
    painter: &egui::Painter,
) {
    zoom(app, ui, out, response, t);
    match app.rt.ui.tool.clone() {
        Tool::Navigate => {
            if response.dragged() {
                let d = response.drag_delta();
                let mut view = app.state.view.clone();
                view.zoom = t.scale;
                view.center = [t.center[0] - d.x / t.scale, t.center[1] - d.y / t.scale];
                out.push(Command::SetView(view));
            }
        }
        Tool::DrawQuad { tracker, corners } => {
            draw_quad_tool(out, response, t, painter, tracker, corners)
        }
        Tool::DrawBox { tracker, start } => {
            draw_box_tool(ui, out, response, t, painter, (tracker, start))
        }
        Tool::EditGroundTruth => edit_ground_truth(app, ui, out, response, t, painter),
    }
}

/// Drawing a quad for `tracker`: its corners so far, a click adds one; the fourth starts the
/// tracker there.
fn draw_quad_tool(
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
    painter: &egui::Painter,
    tracker: usize,
    mut corners: Vec<Point>,
) {
    for (k, p) in corners.iter().enumerate() {
        painter.circle_filled(t.to_screen(*p), 4.0, Color32::YELLOW);
        painter.text(
            t.to_screen(*p) + Vec2::new(5.0, -5.0),
            egui::Align2::LEFT_BOTTOM,
            (k + 1).to_string(),
            egui::FontId::monospace(12.0),
            Color32::YELLOW,
        );
    }
    painter.text(
        t.rect.left_top() + Vec2::new(8.0, 8.0),
        egui::Align2::LEFT_TOP,
        format!(
            "tracker {}: click corner {} of 4 (upper-left first, clockwise)",
            tracker + 1,
            corners.len() + 1
        ),
        egui::FontId::proportional(15.0),
        Color32::YELLOW,
    );
    if let (true, Some(pos)) = (response.clicked(), response.interact_pointer_pos()) {
        corners.push(t.to_image(pos));
        if corners.len() == 4 {
            let q = Quad([corners[0], corners[1], corners[2], corners[3]]);
            finish_drawing(out, tracker, q);
        } else {
            out.push(Command::SetTool(Tool::DrawQuad { tracker, corners }));
        }
    }
}

/// Dragging a box for `tracker` (from where the drag `start`ed); its release starts the
/// tracker there.
fn draw_box_tool(
    ui: &egui::Ui,
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
    painter: &egui::Painter,
    (tracker, start): (usize, Option<Point>),
) {
    let hover = response.hover_pos();
    painter.text(
        t.rect.left_top() + Vec2::new(8.0, 8.0),
        egui::Align2::LEFT_TOP,
        format!("tracker {}: drag a box", tracker + 1),
        egui::FontId::proportional(15.0),
        Color32::YELLOW,
    );
    // From where the button went down, not where the drag was recognised (a few px on).
    if response.drag_started()
        && let Some(pos) = ui
            .input(|i| i.pointer.press_origin())
            .or(response.interact_pointer_pos())
    {
        out.push(Command::SetTool(Tool::DrawBox {
            tracker,
            start: Some(t.to_image(pos)),
        }));
    }
    if let (Some(a), Some(pos)) = (start, response.interact_pointer_pos().or(hover)) {
        let b = t.to_image(pos);
        let q = Quad::from_rect(
            a.x.min(b.x),
            a.y.min(b.y),
            (a.x - b.x).abs(),
            (a.y - b.y).abs(),
        );
        draw_quad(painter, t, &q, Color32::YELLOW, true, false);
        if response.drag_stopped() {
            finish_drawing(out, tracker, q);
        }
    }
}

/// The ground-truth mode: drag a corner (constrained to the shown SSM) or the whole quad (from
/// inside it); one edit on release. Draws the picked corner, a magnifier around it and the
/// template beside the shown frame's rectified region.
fn edit_ground_truth(
    app: &InspectorApp,
    ui: &egui::Ui,
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
    painter: &egui::Painter,
) {
    let frame = app.state.frame;
    let (picked, step) = app.gt_cursor();
    let Some(gt) = app.ground_truth(frame) else {
        let occluded = app.gt_frame(frame) == Some(crate::gt::GtFrame::Occluded);
        painter.text(
            t.rect.left_top() + Vec2::new(8.0, 8.0),
            egui::Align2::LEFT_TOP,
            if occluded {
                "frame marked occluded (O unmarks it)"
            } else {
                "no ground truth on this frame: drag a box to annotate it"
            },
            egui::FontId::proportional(15.0),
            Color32::YELLOW,
        );
        if !occluded {
            annotate_box(ui, out, response, t, painter, frame);
        }
        return;
    };
    drag_ground_truth(app, ui, out, response, t, &gt);
    for (k, p) in gt.0.iter().enumerate() {
        let picked = picked == Some(k);
        painter.circle_stroke(
            t.to_screen(*p),
            if picked { 11.0 } else { 8.0 },
            Stroke::new(
                if picked { 2.5 } else { 1.5 },
                if picked { Color32::WHITE } else { GT_COLOR },
            ),
        );
    }
    painter.text(
        t.rect.left_top() + Vec2::new(8.0, 8.0),
        egui::Align2::LEFT_TOP,
        format!(
            "GT {}: {} · step {step} px · Shift+arrows nudge · F1: keys",
            app.state.gt_ssm,
            match picked {
                Some(k) => format!("corner {}", k + 1),
                None => "whole quad".into(),
            }
        ),
        egui::FontId::proportional(13.0),
        Color32::YELLOW,
    );
}

/// What a drag of the ground truth holds: what was grabbed, the press point, the quad then.
type Grab = (crate::gt::Grab, Point, Quad);

/// A drag of a corner (within 15 screen px) or of the whole quad (from inside it): shown as it
/// goes, committed on release.
fn drag_ground_truth(
    app: &InspectorApp,
    ui: &egui::Ui,
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
    gt: &Quad,
) {
    let frame = app.state.frame;
    let id = response.id.with("gt_grab");
    if response.drag_started()
        && let Some(pos) = ui
            .input(|i| i.pointer.press_origin())
            .or(response.interact_pointer_pos())
    {
        // A corner within 15 screen px, else the whole quad from inside it.
        let p = t.to_image(pos);
        let grab: Option<Grab> = crate::gt::grab(gt, p, 15.0 / t.scale as f64).map(|g| (g, p, *gt));
        if let Some((g, _, _)) = grab {
            out.push(Command::Gt(GtCommand::PickCorner(g.corner())));
        }
        ui.data_mut(|d| d.insert_temp(id, grab));
    }
    let grab: Option<Grab> = ui.data(|d| d.get_temp(id)).flatten();
    if let Some((g, from, q0)) = grab
        && let Some(pos) = response.interact_pointer_pos().or(response.hover_pos())
    {
        let moved = crate::gt::drag(&app.state.gt_ssm, &q0, g, from, t.to_image(pos));
        if response.drag_stopped() {
            ui.data_mut(|d| d.remove::<Option<Grab>>(id));
            let label = match g.corner() {
                Some(k) => format!("move corner {}", k + 1),
                None => "move the quad".into(),
            };
            out.push(Command::Gt(GtCommand::Commit {
                frame,
                quad: moved,
                label,
            }));
        } else if response.dragged() {
            out.push(Command::Gt(GtCommand::Drag { frame, quad: moved }));
        }
    }
}

fn finish_drawing(out: &mut Commands, tracker: usize, q: Quad) {
    out.push(Command::SetTool(Tool::Navigate));
    match q.validate() {
        Ok(()) => out.push(Command::InitTracker(tracker, InitSource::Quad(q))),
        Err(e) => out.push(Command::ReportError(format!("not a usable quad: {e}"))),
    }
}

/// The ground-truth mode on a frame without ground truth: a dragged box becomes its ground truth
/// (one journaled edit), so that a sequence can be annotated from scratch.
fn annotate_box(
    ui: &egui::Ui,
    out: &mut Commands,
    response: &egui::Response,
    t: &Transform,
    painter: &egui::Painter,
    frame: usize,
) {
    let id = response.id.with("gt_box");
    if response.drag_started()
        && let Some(pos) = ui
            .input(|i| i.pointer.press_origin())
            .or(response.interact_pointer_pos())
    {
        ui.data_mut(|d| d.insert_temp(id, Some(t.to_image(pos))));
    }
    let start: Option<Point> = ui.data(|d| d.get_temp(id)).flatten();
    if let (Some(a), Some(pos)) = (
        start,
        response.interact_pointer_pos().or(response.hover_pos()),
    ) {
        let b = t.to_image(pos);
        let q = Quad::from_rect(
            a.x.min(b.x),
            a.y.min(b.y),
            (a.x - b.x).abs(),
            (a.y - b.y).abs(),
        );
        draw_quad(painter, t, &q, GT_COLOR, true, false);
        if response.drag_stopped() {
            ui.data_mut(|d| d.remove::<Option<Point>>(id));
            match q.validate() {
                Ok(()) => out.push(Command::Gt(GtCommand::Commit {
                    frame,
                    quad: q,
                    label: "annotate".into(),
                })),
                Err(e) => out.push(Command::ReportError(format!("not a usable box: {e}"))),
            }
        }
    }
}

/// The ground-truth mode's strip under the frame: a magnifier around the picked corner and the
/// template beside the shown frame's ground-truth region, rectified (a misalignment shows as a
/// shift between the two).
pub fn gt_strip(app: &InspectorApp, ui: &mut egui::Ui) {
    let side = 150.0f32;
    let (rect, _) =
        ui.allocate_exact_size(Vec2::new(ui.available_width(), side + 18.0), Sense::hover());
    let painter = ui.painter_at(rect);
    let frame = app.state.frame;
    let (picked, _) = app.gt_cursor();
    let Some(gt) = app.ground_truth(frame) else {
        return;
    };
    let label = |r: Rect, text: String| {
        painter.text(
            r.left_bottom() + Vec2::new(0.0, 2.0),
            egui::Align2::LEFT_TOP,
            text,
            egui::FontId::proportional(12.0),
            Color32::LIGHT_GRAY,
        );
    };
    // Magnifier around the picked corner (or the centre), 6x.
    if let Some(texture) = app.rt.display.texture.clone() {
        let area = Rect::from_min_size(rect.left_top(), Vec2::splat(side));
        let c = magnifier(app, &painter, &texture, area, (&gt, picked));
        label(
            area,
            match picked {
                Some(k) => format!("corner {} ({:.1}, {:.1})", k + 1, c.x, c.y),
                None => format!("centre ({:.1}, {:.1})", c.x, c.y),
            },
        );
    }
    let this = match app.gt_residual(frame) {
        Some(r) => format!("frame {} · fit residual {r:.2} px", frame + 1),
        None => format!("frame {}", frame + 1),
    };
    if let Some([a, b]) = gt_patches(app, ui.ctx()) {
        for (k, (tex, text)) in [(a, "template (first frame)".to_string()), (b, this)]
            .into_iter()
            .enumerate()
        {
            let r = Rect::from_min_size(
                rect.left_top() + Vec2::new((k + 1) as f32 * (side + 12.0), 0.0),
                Vec2::splat(side),
            );
            painter.image(
                tex.id(),
                r,
                Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                Color32::WHITE,
            );
            label(r, text);
        }
    }
}

/// The frame around the picked corner of `gt` (or its centre) magnified 6x into `area`, the
/// quad over it; returns the point magnified.
fn magnifier(
    app: &InspectorApp,
    painter: &egui::Painter,
    texture: &egui::TextureHandle,
    area: Rect,
    (gt, picked): (&Quad, Option<usize>),
) -> Point {
    let side = area.width();
    let c = picked.map_or(gt.centroid(), |k| gt.0[k]);
    let r = side / 12.0;
    let [w, h] = app.rt.display.image_size;
    let (w, h) = (w.max(1) as f32, h.max(1) as f32);
    let uv = Rect::from_min_max(
        Pos2::new((c.x as f32 + 0.5 - r) / w, (c.y as f32 + 0.5 - r) / h),
        Pos2::new((c.x as f32 + 0.5 + r) / w, (c.y as f32 + 0.5 + r) / h),
    );
    painter.rect_filled(area, 0.0, Color32::BLACK);
    painter.image(texture.id(), area, uv, Color32::WHITE);
    let mag = |p: Point| {
        area.center()
            + Vec2::new(
                (p.x - c.x) as f32 * side / (2.0 * r),
                (p.y - c.y) as f32 * side / (2.0 * r),
            )
    };
    let pts: Vec<Pos2> = gt.0.iter().map(|p| mag(*p)).collect();
    let clip = painter.with_clip_rect(area);
    clip.add(Shape::closed_line(pts.clone(), Stroke::new(1.5, GT_COLOR)));
    if let Some(k) = picked {
        clip.circle_stroke(pts[k], 6.0, Stroke::new(1.5, Color32::WHITE));
    }
    painter.rect_stroke(
        area,
        0.0,
        Stroke::new(1.0, Color32::GRAY),
        egui::StrokeKind::Inside,
    );
    c
}

/// The template and the shown frame's ground-truth region, rectified, as textures (made again
/// when the frame or its ground truth changes).
fn gt_patches(app: &InspectorApp, ctx: &egui::Context) -> Option<[egui::TextureHandle; 2]> {
    use crate::app::gt_edit::{PATCH, rectified};
    let frame = app.state.frame;
    let (tf, timg) = app.rt.gt.template_image.as_ref()?;
    let (ff, fimg) = app.rt.gt.frame_image.as_ref()?;
    if *ff != frame {
        return None;
    }
    let tq = app.ground_truth(*tf)?;
    let fq = app.ground_truth(frame);
    let opts = egui::TextureOptions::NEAREST;
    // The images belong to the open sequence: its identity (not its address, which a later
    // sequence may reuse) is part of the keys.
    let seq = app
        .sequence()
        .map(|s| (s.name.clone(), s.gt_path.clone(), s.frames.first().cloned()));
    let bits = |q: Quad| q.to_array().map(f64::to_bits);
    let template = super::cached_texture(ctx, "gt-template", (&seq, *tf, bits(tq)), opts, || {
        rectified(timg, &tq).unwrap_or_else(|| blank_patch(PATCH))
    });
    let key = (&seq, frame, fq.map(bits));
    let current = super::cached_texture(ctx, "gt-current", key, opts, || {
        fq.and_then(|q| rectified(fimg, &q))
            .unwrap_or_else(|| blank_patch(PATCH))
    });
    Some([template, current])
}

fn blank_patch(side: usize) -> egui::ColorImage {
    egui::ColorImage::new([side, side], vec![Color32::from_gray(40); side * side])
}
