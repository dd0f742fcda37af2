//! The panels. They read the app and push commands; none of them changes the model.

use eframe::egui;
mod bars;
mod frame_view;
mod plots;
mod sidebar;

pub use bars::{playback_bar, top_bar};
pub use frame_view::{Transform, frame_view, gt_strip};
pub use plots::plots_panel;
pub use sidebar::sidebar;

/// An egui colour from an RGB triple.
pub fn color(c: [u8; 3]) -> egui::Color32 {
    egui::Color32::from_rgb(c[0], c[1], c[2])
}

/// The colour of the ground truth.
pub const GT_COLOR: egui::Color32 = egui::Color32::from_rgb(60, 230, 90);
