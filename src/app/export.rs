//! The plots shown, written as figures (SVG and PNG) on a thread of their own.

use super::worker::Reply;
use super::{InspectorApp, runtime};
use crate::report::{Axes, Curve, Figure, FigureKind};
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
        if figures.is_empty() {
            self.error("nothing to export: track some frames first".into());
            return;
        }
        let spawned = self.rt.worker.spawn_task("export-plots", move || {
            let mut files = Vec::new();
            for (stem, fig, axes) in &figures {
                for ext in ["svg", "png"] {
                    let p = dir.join(format!("{stem}.{ext}"));
                    if let Err(e) = crate::report::draw_curve_figure(&p, fig, axes, (900, 560)) {
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

    /// The success rates and the errors per frame of every tracker.
    fn tracking_figures(&self, name: &str) -> Vec<ExportedFigure> {
        let mut sr = Vec::new();
        let mut errors = Vec::new();
        let mut worst: f64 = 5.0;
        let mut last = 1.0f64;
        for (i, t) in self.state.trackers.iter().enumerate() {
            let label = t.spec.label();
            let curve = self.success_curve(i);
            if !curve.is_empty() {
                let mean = curve.iter().map(|p| p.1).sum::<f64>() / curve.len() as f64;
                sr.push(Curve {
                    name: format!("{} {label}", i + 1),
                    tracker: label.clone(),
                    mean_sr: mean,
                    points: curve,
                });
            }
            let e: Vec<(f64, f64)> = self
                .errors(i)
                .into_iter()
                .filter(|(_, e)| e.is_finite())
                .map(|(f, e)| ((f + 1) as f64, e.min(50.0)))
                .collect();
            if !e.is_empty() {
                worst = e.iter().map(|p| p.1).fold(worst, f64::max);
                last = e.iter().map(|p| p.0).fold(last, f64::max);
                let mean = e.iter().map(|p| p.1).sum::<f64>() / e.len() as f64;
                errors.push(Curve {
                    name: format!("{} {label}", i + 1),
                    tracker: label,
                    mean_sr: mean,
                    points: e,
                });
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
                    y_desc: "alignment error (px, at most 50)".into(),
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

/// A figure to write: its file stem, its curves and its axes.
type ExportedFigure = (&'static str, Figure, Axes);
