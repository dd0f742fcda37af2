//! The panels. Each is given the app to read and a list to push [`Command`]s to, nothing else:
//! none of them changes the app. What a widget keeps between frames (a typed path, a texture
//! made from the app's data) lives in egui's memory, keyed by the widget.

use eframe::egui;
mod bars;
mod frame_view;
mod plots;
mod sidebar;
mod timeline;

pub use bars::{playback_bar, top_bar};
pub use frame_view::{Transform, frame_view, gt_strip};
pub use plots::plots_panel;
pub use sidebar::sidebar;
pub use timeline::timeline;

use crate::app::command::Command;
use std::hash::{Hash, Hasher};

/// Where panels push their commands.
pub type Commands = Vec<Command>;

/// A texture kept in egui's memory under `name`, made again only when `key` changes (`make`
/// is not called while it stays the same).
pub fn cached_texture(
    ctx: &egui::Context,
    name: &str,
    key: impl Hash,
    options: egui::TextureOptions,
    make: impl FnOnce() -> egui::ColorImage,
) -> egui::TextureHandle {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    key.hash(&mut h);
    let key = h.finish();
    let id = egui::Id::unique(("cached_texture", name));
    let cached: Option<(u64, egui::TextureHandle)> = ctx.data(|d| d.get_temp(id));
    match cached {
        Some((k, t)) if k == key => t,
        Some((_, mut t)) => {
            t.set(make(), options);
            ctx.data_mut(|d| d.insert_temp(id, (key, t.clone())));
            t
        }
        None => {
            let t = ctx.load_texture(name, make(), options);
            ctx.data_mut(|d| d.insert_temp(id, (key, t.clone())));
            t
        }
    }
}

/// A resizable side panel that keeps its share of the window: egui keeps a panel's width in
/// pixels, so one squeezed by a small window stayed narrow after the window grew again. `size`
/// is (default width in px, largest share of the window, smallest width in px); `saved` the
/// share kept from the last run. Pair with [`remember_share`] after the panel is shown.
fn follow_window(
    ctx: &egui::Context,
    name: &str,
    panel: egui::Panel,
    (default, most, least): (f32, f32, f32),
    saved: Option<f32>,
) -> egui::Panel {
    let w = ctx.content_rect().width();
    let max = (w * most).max(least);
    let panel = panel
        .resizable(true)
        .default_size(default.min(max))
        .max_size(max);
    let stored: Option<(f32, f32)> = ctx.data(|d| d.get_temp(share_id(name)));
    // The share kept from the last run, once (when the preferences are read).
    let applied_id = egui::Id::unique(("panel_share_applied", name));
    let applied: Option<f32> = ctx.data(|d| d.get_temp(applied_id));
    if let Some(share) = saved
        && applied != Some(share)
    {
        ctx.data_mut(|d| d.insert_temp(applied_id, share));
        return panel.exact_size((share * w).clamp(least.min(max), max));
    }
    match stored {
        // The window changed size: the panel takes the share it had.
        Some((last, share)) if (last - w).abs() > 0.5 => {
            panel.exact_size((share * w).clamp(least.min(max), max))
        }
        _ => panel,
    }
}

/// Records the width a [`follow_window`] panel was given, as a share of the window; once the
/// pointer is released after a change from the `saved` share, asks to keep it between runs.
fn remember_share(
    ctx: &egui::Context,
    name: &str,
    rect: egui::Rect,
    saved: Option<f32>,
    out: &mut Commands,
) {
    let (w, width) = (ctx.content_rect().width(), rect.width());
    // Where it is, for the layout tests ([`panel_rect`]).
    ctx.data_mut(|d| d.insert_temp(egui::Id::unique(("panel_rect", name)), rect));
    if w > 0.0 {
        let share = width / w;
        ctx.data_mut(|d| d.insert_temp(share_id(name), (w, share)));
        let moved = saved.is_none_or(|s| (s - share).abs() > 0.005);
        // Only a drag of the panel's edge changes it (not a window resized, which keeps it).
        let dragged = ctx.input(|i| i.pointer.any_released());
        if moved && dragged {
            out.push(Command::KeepPanelShare(name.to_string(), share));
        }
    }
}

/// A side panel `name` that keeps its share of the window and the share kept from the last
/// run ([`follow_window`], [`remember_share`]), showing `contents`.
pub fn side_panel(
    app: &crate::app::InspectorApp,
    ui: &mut egui::Ui,
    out: &mut Commands,
    (name, panel, size): (&str, egui::Panel, (f32, f32, f32)),
    contents: impl FnOnce(&mut egui::Ui, &mut Commands),
) {
    let ctx = ui.ctx().clone();
    let saved = app.panel_share(name);
    let shown = follow_window(&ctx, name, panel, size, saved).show(ui, |ui| contents(ui, out));
    remember_share(&ctx, name, shown.response.rect, saved, out);
}

/// Where side panel `name` (`trackers`, `plots`) was last drawn.
pub fn panel_rect(ctx: &egui::Context, name: &str) -> Option<egui::Rect> {
    ctx.data(|d| d.get_temp(egui::Id::unique(("panel_rect", name))))
}

fn share_id(name: &str) -> egui::Id {
    egui::Id::unique(("panel_share", name))
}

/// A text field's contents kept in egui's memory under `id` (for fields that are not part of
/// the app's state, as a path being typed).
pub fn remembered_text(ui: &egui::Ui, id: egui::Id) -> String {
    ui.data(|d| d.get_temp(id)).unwrap_or_default()
}

/// Keeps a text field's contents for the next frame.
pub fn remember_text(ui: &egui::Ui, id: egui::Id, text: String) {
    ui.data_mut(|d| d.insert_temp(id, text));
}

/// An egui colour from an RGB triple.
pub fn color(c: [u8; 3]) -> egui::Color32 {
    egui::Color32::from_rgb(c[0], c[1], c[2])
}

/// The colour of the ground truth.
pub const GT_COLOR: egui::Color32 = egui::Color32::from_rgb(60, 230, 90);
