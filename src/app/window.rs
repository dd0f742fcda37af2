//! The inspector as a window: [`run`] opens it (blocking until it closes), with a planned
//! screenshot for `regtrack inspect --screenshot`; the keyboard help overlay.

use super::state::{SequenceSource, State};
use super::worker::Job;
use super::{InspectorApp, SHORTCUTS};
use eframe::egui;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// What can stop the inspector from running (the errors of a running window are shown in it).
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error("cannot load the session: {0}")]
    Session(#[source] crate::Error),
    /// The windowing system's error, as it describes it.
    #[error("the window cannot run: {0}")]
    Window(String),
    #[error("cannot write the screenshot {}: {message}", path.display())]
    Screenshot { path: PathBuf, message: String },
    #[error("the window closed before the screenshot was taken")]
    NoScreenshot,
    /// The planned frames could not be shown (the sequence did not open, a frame could not be
    /// read); the screenshot shows the window with the error.
    #[error("{message} (the screenshot {} shows the window)", path.display())]
    Failed { path: PathBuf, message: String },
}

/// Where a screenshot's outcome is reported (`None` until it is taken).
/// On success, a summary of the window's frame rate while the trackers ran.
pub type ShotResult = Arc<Mutex<Option<Result<String, AppError>>>>;

/// Take a screenshot once enough frames are tracked, then close.
#[derive(Debug)]
pub struct ScreenshotPlan {
    pub frames: usize,
    pub path: PathBuf,
    started: bool,
    requested: bool,
    pub result: ShotResult,
}

impl InspectorApp {
    /// Plans a screenshot after `frames` tracked frames (the inspector then plays, captures the
    /// window to `path`, reports in `result` and closes).
    pub fn screenshot_after(&mut self, frames: usize, path: PathBuf, result: ShotResult) {
        self.rt.screenshot = Some(ScreenshotPlan {
            frames,
            path,
            started: false,
            requested: false,
            result,
        });
    }

    /// Drives a planned screenshot: track the planned frames, wait for the frame to be shown,
    /// then capture the window and close it.
    pub(super) fn screenshot(&mut self, ctx: &egui::Context) {
        let (n, start, generation) = (
            self.frame_count(),
            self.state.start_frame,
            self.rt.run.generation,
        );
        // What stops the planned frames from being shown: the window is captured as it is, with
        // the error, and the screenshot reports the failure (rather than wait forever).
        let failed = if self.rt.seq.sequence.is_none() && self.rt.seq.opening.is_none() {
            self.rt.msg.errors.first().cloned()
        } else if !self.rt.run.playing {
            self.rt
                .seq
                .bad_frame
                .as_ref()
                .map(|(i, m)| format!("frame {}: {m}", i + 1))
        } else {
            None
        };
        let Some(plan) = self.rt.screenshot.as_mut() else {
            return;
        };
        if plan.requested {
            return;
        }
        if let Some(message) = failed {
            plan.requested = true;
            let path = plan.path.clone();
            return capture(ctx, plan, move |img| {
                save_png(&path, img).and(Err(AppError::Failed {
                    path: path.clone(),
                    message,
                }))
            });
        }
        if n == 0 {
            ctx.request_repaint();
            return;
        }
        ctx.request_repaint();
        let target = (start + plan.frames).min(n - 1);
        let Some(reached) = self.rt.run.tracked_until else {
            return;
        };
        if reached < target {
            if !plan.started {
                plan.started = true;
                self.rt.run.playing = true;
                self.rt.worker.send(Job::Advance {
                    generation,
                    frames: Some(target - reached),
                    fps: self.state.playback_fps,
                });
            }
            return;
        }
        if self.rt.run.playing
            || self.rt.display.texture_frame != Some(reached)
            || self.rt.display.pending_image.is_some()
        {
            return;
        }
        plan.requested = true;
        let path = plan.path.clone();
        let summary = frame_rate_summary(&self.rt.frame_times);
        capture(ctx, plan, move |img| save_png(&path, img).map(|()| summary));
    }
}

/// Captures the window, keeps what `save` makes of the image as the plan's result, and closes
/// the window.
fn capture(
    ctx: &egui::Context,
    plan: &ScreenshotPlan,
    save: impl FnOnce(&egui::ColorImage) -> Result<String, AppError> + Send + 'static,
) {
    let result = plan.result.clone();
    let ctx2 = ctx.clone();
    ctx.request_screenshot(move |img| {
        let saved = save(&img);
        if let Ok(mut r) = result.lock() {
            *r = Some(saved);
        }
        ctx2.send_viewport_cmd(egui::ViewportCommand::Close);
        ctx2.request_repaint();
    });
}

pub(super) fn help_window(ctx: &egui::Context, open: &mut bool) {
    egui::Window::new("Keyboard shortcuts")
        .open(open)
        .collapsible(false)
        .resizable(false)
        .anchor(egui::Align2::CENTER_CENTER, egui::Vec2::ZERO)
        .show(ctx, |ui| {
            egui::Grid::new("shortcuts").striped(true).show(ui, |ui| {
                for (k, what) in SHORTCUTS {
                    ui.strong(*k);
                    ui.label(*what);
                    ui.end_row();
                }
            });
        });
}

/// Asks whether to overwrite `path`: `Some(answer)` once given (Enter is yes; Esc, handled
/// with the other keys, is no).
pub(super) fn overwrite_window(ctx: &egui::Context, path: &std::path::Path) -> Option<bool> {
    let mut answer = None;
    egui::Window::new("Overwrite the session file?")
        .collapsible(false)
        .resizable(false)
        .anchor(egui::Align2::CENTER_CENTER, egui::Vec2::ZERO)
        .show(ctx, |ui| {
            ui.label(format!(
                "{} exists and is not this session's file.",
                path.display()
            ));
            ui.horizontal(|ui| {
                if ui.button("Overwrite").clicked() || ui.input(|i| i.key_pressed(egui::Key::Enter))
                {
                    answer = Some(true);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(false);
                }
            });
        });
    answer
}

/// The window's frame rate while the trackers ran, and the time the UI took to build a frame
/// (what the app itself costs; the rest is rendering).
fn frame_rate_summary(times: &[(f32, f32)]) -> String {
    let median = |mut v: Vec<f32>| -> f32 {
        v.sort_by(f32::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f32::NAN)
    };
    let dts: Vec<f32> = times.iter().map(|t| t.0).filter(|v| *v > 0.0).collect();
    if dts.is_empty() {
        return "window: no frame while tracking".into();
    }
    let n = dts.len();
    let (frame, build) = (median(dts), median(times.iter().map(|t| t.1).collect()));
    format!(
        "window: median {:.0} fps over {n} frames while tracking; building the UI took a median {:.2} ms per frame",
        1.0 / frame,
        build * 1e3
    )
}

fn save_png(path: &std::path::Path, img: &egui::ColorImage) -> Result<(), AppError> {
    let fail = |message: String| AppError::Screenshot {
        path: path.to_path_buf(),
        message,
    };
    let [w, h] = img.size;
    let raw: Vec<u8> = img.pixels.iter().flat_map(|c| c.to_array()).collect();
    let buf = image::RgbaImage::from_raw(w as u32, h as u32, raw)
        .ok_or_else(|| fail("an image of the wrong size".into()))?;
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|e| fail(format!("{}: {e}", d.display())))?;
    }
    buf.save(path).map_err(|e| fail(e.to_string()))
}

impl eframe::App for InspectorApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        InspectorApp::ui(self, ui);
    }
}

/// How to start the inspector.
#[derive(Debug, Default)]
pub struct RunOptions {
    pub session: Option<PathBuf>,
    pub sequence: Option<PathBuf>,
    pub screenshot: Option<(usize, PathBuf)>,
    /// A live source to open at start, and its frame size.
    pub camera: Option<(String, usize, usize)>,
}

/// Opens the inspector window (blocks until it closes).
pub fn run(opts: RunOptions) -> Result<Option<String>, AppError> {
    let mut state = match &opts.session {
        Some(p) => State::load(p).map_err(AppError::Session)?,
        None => State::default(),
    };
    if let Some(p) = &opts.sequence {
        state.sequence = SequenceSource::Path(p.clone());
    }
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("regtrack inspector")
            .with_inner_size([1280.0, 800.0]),
        ..Default::default()
    };
    let shot = opts.screenshot.clone();
    let session = opts.session.clone();
    let camera = opts.camera.clone();
    let result: ShotResult = Arc::new(Mutex::new(None));
    let result2 = result.clone();
    eframe::run_native(
        "regtrack inspector",
        native,
        Box::new(move |cc| {
            let ctx = cc.egui_ctx.clone();
            let mut app = InspectorApp::new(state, move || ctx.request_repaint());
            if let Some(p) = &session {
                app.set_session_path(p);
            }
            // A screenshot is a batch run: it leaves the user's recent list alone.
            if shot.is_none()
                && let Some(p) = super::prefs::prefs_path()
            {
                app.use_prefs(p);
            }
            if let Some((frames, path)) = shot {
                app.screenshot_after(frames, path, result2);
            }
            if let Some((source, width, height)) = camera {
                app.apply(super::command::Command::OpenCamera {
                    source,
                    width,
                    height,
                });
            }
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| AppError::Window(e.to_string()))?;
    if opts.screenshot.is_none() {
        return Ok(None);
    }
    let outcome = result.lock().ok().and_then(|mut r| r.take());
    outcome.unwrap_or(Err(AppError::NoScreenshot)).map(Some)
}
