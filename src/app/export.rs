//! The plots shown, written as figures (SVG and PNG) on a thread of their own.

use super::worker::Reply;
use super::{InspectorApp, runtime};
use crate::report::{Axes, Curve, Figure, FigureKind, MapFigure};
use std::path::PathBuf;

impl InspectorApp {
    /// Writes the plots shown as figures (on a thread of its own; the files come back as a
    /// reply): `sr`, `errors` and, when a landscape curve is shown, `landscape`, each `.svg` and
    /// `.png`.
    pub(super) fn export_plots(&mut self, dir: PathBuf) {
        let name = self
            .sequence()
            .map_or("sequence".into(), |s| s.name.clone());
        let mut figures = self.tracking_figures(&name);
        figures.extend(self.landscape_figure(&name));
        figures.extend(self.convergence_figure(&name));
        let map = self.landscape_map_figure(&name);
        if figures.is_empty() && map.is_none() {
            self.error("nothing to export: track some frames first".into());
            return;
        }
        // Relative folders are the session's working folder's: say where, in full.
        let dir = std::path::absolute(&dir).unwrap_or(dir);
        let spawned = self.rt.worker.spawn_task("export-plots", move || {
            let mut files = Vec::new();
            for ext in ["svg", "png"] {
                for (stem, fig, axes) in &figures {
                    let p = dir.join(format!("{stem}.{ext}"));
                    if let Err(e) = crate::report::draw_curve_figure(&p, fig, axes, (900, 560)) {
                        return Reply::Exported(Err(e.to_string()));
                    }
                    files.push(p);
                }
                if let Some(m) = &map {
                    let p = dir.join(format!("landscape_map.{ext}"));
                    if let Err(e) = crate::report::draw_map_figure(&p, m, (760, 640)) {
                        return Reply::Exported(Err(e.to_string()));
                    }
                    files.push(p);
                }
            }
            Reply::Exported(Ok(files))
        });
        if let Err(e) = spawned {
            self.error(format!("cannot export the plots: {e}"));
        }
    }

    /// Shows `dir` in the desktop's file manager (`xdg-open`, `open` on macOS, `explorer` on
    /// Windows); an error says so when none is there.
    pub(super) fn open_folder(&mut self, dir: &std::path::Path) {
        let opener = if cfg!(target_os = "macos") {
            "open"
        } else if cfg!(windows) {
            "explorer"
        } else {
            "xdg-open"
        };
        let spawned = std::process::Command::new(opener)
            .arg(dir)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn();
        match spawned {
            Ok(_) => self.rt.msg.status = format!("opened {}", dir.display()),
            Err(e) => self.error(format!(
                "cannot show {} in a file manager ({opener}: {e}); the figures are there",
                dir.display()
            )),
        }
    }

    /// The success rates and the errors per frame of every tracker, drawn as the window draws
    /// them: each tracker in its colour, the confidence dashed (scaled to 0..20 px), the
    /// frames reported lost as crosses on it and a gap in the error.
    fn tracking_figures(&self, name: &str) -> Vec<ExportedFigure> {
        let mut sr = Vec::new();
        let mut errors = Vec::new();
        let mut worst: f64 = CONFIDENCE_SCALE;
        let mut last = 1.0f64;
        for (i, t) in self.state.trackers.iter().enumerate() {
            if self.state.view.ab.is_some_and(|(a, b)| i != a && i != b) {
                continue;
            }
            let label = t.spec.label();
            let colour = Some((t.color, false));
            let curve = self.success_curve(i);
            if !curve.is_empty() {
                let mean = curve.iter().map(|p| p.1).sum::<f64>() / curve.len() as f64;
                sr.push(Curve {
                    name: format!("{} {label}", i + 1),
                    tracker: label.clone(),
                    mean_sr: mean,
                    points: curve,
                    style: colour,
                    ..Default::default()
                });
            }
            let all = self.errors(i);
            let e: Vec<(f64, f64)> = all
                .iter()
                .map(|&(f, e)| {
                    (
                        (f + 1) as f64,
                        if e.is_finite() { e.min(50.0) } else { f64::NAN },
                    )
                })
                .collect();
            let finite: Vec<f64> = e.iter().map(|p| p.1).filter(|v| v.is_finite()).collect();
            if !finite.is_empty() {
                worst = finite.iter().copied().fold(worst, f64::max);
                last = e.iter().map(|p| p.0).fold(last, f64::max);
                let mean = finite.iter().sum::<f64>() / finite.len() as f64;
                errors.push(Curve {
                    name: format!("{} {label}", i + 1),
                    tracker: label.clone(),
                    mean_sr: mean,
                    points: e,
                    style: colour,
                    ..Default::default()
                });
                let conf = self.confidences(i);
                let scaled = |c: f64| c.clamp(0.0, 1.0) * CONFIDENCE_SCALE;
                if !conf.is_empty() {
                    let points: Vec<(f64, f64)> = conf
                        .iter()
                        .map(|(f, c, _)| ((f + 1) as f64, scaled(*c)))
                        .collect();
                    let mean_c = conf.iter().map(|c| c.1).sum::<f64>() / conf.len() as f64;
                    errors.push(Curve {
                        name: format!("{} confidence x {CONFIDENCE_SCALE:.0}", i + 1),
                        tracker: label,
                        mean_sr: mean_c,
                        points,
                        style: Some((t.color, true)),
                        marks: conf
                            .iter()
                            .filter(|c| c.2)
                            .map(|(f, c, _)| ((f + 1) as f64, scaled(*c)))
                            .collect(),
                    });
                }
            }
        }
        sr.sort_by(|a, b| b.mean_sr.total_cmp(&a.mean_sr));
        let mut figures = Vec::new();
        if !sr.is_empty() {
            figures.push((
                "sr",
                Figure {
                    kind: FigureKind::Others,
                    stem: "sr".into(),
                    title: format!("Success rate: {name}"),
                    curves: sr,
                },
                Axes {
                    x_desc: "error threshold t (px)".into(),
                    y_desc: "success rate".into(),
                    x_range: (0.0, 20.0),
                    y_range: (0.0, 1.02),
                    legend_header: "mean SR".into(),
                },
            ));
        }
        if !errors.is_empty() {
            figures.push((
                "errors",
                Figure {
                    kind: FigureKind::Others,
                    stem: "errors".into(),
                    title: format!("Alignment error per frame: {name}"),
                    curves: errors,
                },
                Axes {
                    x_desc: "frame".into(),
                    y_desc: "alignment error (px, at most 50); dashed: confidence x 20, x: lost"
                        .into(),
                    x_range: (1.0, last.max(2.0)),
                    y_range: (0.0, worst * 1.05),
                    legend_header: "mean px".into(),
                },
            ));
        }
        figures
    }

    /// The cost landscape's curve, when one along a single parameter is shown.
    fn landscape_figure(&self, name: &str) -> Option<ExportedFigure> {
        let Some((_, Ok(l))) = &self.rt.ui.landscape.result else {
            return None;
        };
        if l.axes.len() != 1 {
            return None;
        }
        {
            let names = self.inspected_param_names();
            let axis = names.get(l.axes[0]).copied().unwrap_or("?");
            let points: Vec<(f64, f64)> = l
                .offsets
                .iter()
                .copied()
                .zip(l.values.iter().copied())
                .collect();
            let (lo, hi) = points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.1), b.max(p.1))
                });
            let r = l.offsets.last().copied().unwrap_or(1.0);
            if lo.is_finite() && hi.is_finite() {
                let pad = ((hi - lo) * 0.05).max(1e-9);
                return Some((
                    "landscape",
                    Figure {
                        kind: FigureKind::Others,
                        stem: "landscape".into(),
                        title: format!(
                            "Cost landscape along {axis}: {name}, frame {}",
                            self.state.frame + 1
                        ),
                        curves: vec![Curve {
                            name: format!("tracker {}", self.state.selected_tracker + 1),
                            tracker: String::new(),
                            mean_sr: l.center_value,
                            points,
                            style: self
                                .state
                                .trackers
                                .get(self.state.selected_tracker)
                                .map(|t| (t.color, false)),
                            ..Default::default()
                        }],
                    },
                    Axes {
                        x_desc: format!("{axis} offset (px of corner motion)"),
                        y_desc: "similarity f".into(),
                        x_range: (-r, r),
                        y_range: (lo - pad, hi + pad),
                        legend_header: "f at the centre".into(),
                    },
                ));
            }
        }
        None
    }

    /// The cost landscape's map, when one over two parameters is shown.
    fn landscape_map_figure(&self, name: &str) -> Option<MapFigure> {
        let Some((_, Ok(l))) = &self.rt.ui.landscape.result else {
            return None;
        };
        if l.axes.len() != 2 {
            return None;
        }
        let names = self.inspected_param_names();
        let axis = |k: usize| names.get(l.axes[k]).copied().unwrap_or("?");
        let path = self
            .result(self.state.selected_tracker, self.state.frame)
            .map(|r| {
                r.iterations
                    .iter()
                    .map(|it| l.offsets_of(&it.params))
                    .filter(|o| o.len() == 2)
                    .map(|o| (o[0], o[1]))
                    .collect()
            })
            .unwrap_or_default();
        let best = l.best();
        Some(MapFigure {
            title: format!(
                "Cost landscape over {} and {}: {name}, frame {}",
                axis(0),
                axis(1),
                self.state.frame + 1
            ),
            x_desc: format!("{} offset (px)", axis(0)),
            y_desc: format!("{} offset (px)", axis(1)),
            values: l.values.clone(),
            offsets: l.offsets.clone(),
            path,
            best: Some((best[0], best[1])),
        })
    }

    /// The frequency of convergence, when it ran.
    fn convergence_figure(&self, name: &str) -> Option<ExportedFigure> {
        let Some(runtime::Frequency {
            frame,
            starts,
            result: Some(Ok(curves)),
        }) = &self.rt.ui.frequency
        else {
            return None;
        };
        {
            Some((
                "convergence",
                Figure {
                    kind: FigureKind::Others,
                    stem: "convergence".into(),
                    title: format!(
                        "Frequency of convergence: {name}, frame {}, {starts} starts per σ",
                        frame + 1
                    ),
                    curves: curves
                        .iter()
                        .map(|(i, c)| Curve {
                            name: format!("{} {}", i + 1, c.tracker),
                            tracker: c.tracker.clone(),
                            mean_sr: c.mean(),
                            points: c.points.iter().map(|p| (p.0, p.1)).collect(),
                            style: self.state.trackers.get(*i).map(|t| (t.color, false)),
                            ..Default::default()
                        })
                        .collect(),
                },
                Axes {
                    x_desc: "σ of the corner noise (px)".into(),
                    y_desc: "fraction converged (within 1 px)".into(),
                    x_range: (0.0, 10.5),
                    y_range: (0.0, 1.02),
                    legend_header: "mean".into(),
                },
            ))
        }
    }
}

/// The error figure draws the confidence (0..1) scaled to 0..this px, as the window does.
const CONFIDENCE_SCALE: f64 = 20.0;

/// A figure to write: its file stem, its curves and its axes.
type ExportedFigure = (&'static str, Figure, Axes);
