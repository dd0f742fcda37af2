//! Tracking results written as the benchmarks' own toolkits read them, from the runs of
//! `regtrack eval`, so that their evaluation runs on regtrack's output:
//!
//! - **PlanarTrack** (and POT, whose evaluations read the same rows):
//!   `<out>/<tracker>/<seq>_<tracker>.txt`, the four corners a frame (8 numbers), and
//!   `<seq>_<tracker>_homography.txt`, the homography from the first frame a frame (9 numbers,
//!   row by row); a frame without corners is a row of zeros.
//! - **VOT**: `<out>/<tracker>/baseline/<seq>/<seq>_001.txt`, a region a frame: `1` on an
//!   initialisation, the polygon of the corners, `2` on the frame a failure starts, `0` on the
//!   frames after it without corners.
//! - **GOT-10k**: `<out>/<tracker>/<seq>/<seq>_001.txt` (boxes `x,y,w,h` around the corners)
//!   and `<seq>_time.txt` (seconds a frame).
//! - **LaSOT**: `<out>/<tracker>_tracking_result/<seq>.txt` (boxes, 1-based as LaSOT's are).

use super::RunResult;
use crate::dataset::regions::{Region, VOT_FAILURE, VOT_INIT, VOT_SKIPPED, vot_region_line};
use crate::dataset::write_atomic;
use crate::error::{Error, Result};
use crate::geometry::{Quad, homography_between};
use std::path::{Path, PathBuf};

/// A benchmark's results format (a closed set).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResultsFormat {
    PlanarTrack,
    Pot,
    Vot,
    Got10k,
    Lasot,
}

impl ResultsFormat {
    /// The names accepted on the command line.
    pub const NAMES: &'static [&'static str] = &["planartrack", "pot", "vot", "got10k", "lasot"];

    /// Parses a format's name.
    pub fn parse(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().replace(['-', '_'], "").as_str() {
            "planartrack" => Ok(Self::PlanarTrack),
            "pot" | "pot210" | "pot280" => Ok(Self::Pot),
            "vot" => Ok(Self::Vot),
            "got10k" | "got" => Ok(Self::Got10k),
            "lasot" => Ok(Self::Lasot),
            _ => Err(Error::InvalidParameter(format!(
                "unknown results format '{s}'; available: {}",
                Self::NAMES.join(", ")
            ))),
        }
    }
}

fn numbers(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.4}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The box `x, y, w, h` around corners.
fn bbox(q: &Quad) -> [f64; 4] {
    let r = q.bbox();
    [r.x0, r.y0, r.width(), r.height()]
}

/// A file name made of a label: characters other than letters, digits, `-`, `_` and `.`
/// become `_`.
fn safe(label: &str) -> String {
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes the results of `runs` in `format` under `out`; returns the files written.
pub fn write_results(
    runs: &[RunResult],
    format: ResultsFormat,
    out: &Path,
) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for r in runs {
        let tracker = safe(&r.spec.label());
        let seq = safe(&r.sequence);
        match format {
            ResultsFormat::PlanarTrack | ResultsFormat::Pot => {
                let dir = out.join(&tracker);
                let reference = r.frames.first().and_then(|f| f.corners);
                let (mut corners, mut homographies) = (String::new(), String::new());
                for f in &r.frames {
                    match f.corners {
                        Some(q) => corners.push_str(&numbers(&q.to_array())),
                        None => corners.push_str(&numbers(&[0.0; 8])),
                    }
                    corners.push('\n');
                    let h = reference
                        .zip(f.corners)
                        .and_then(|(a, b)| homography_between(&a, &b));
                    match h {
                        Some(h) => {
                            let v: Vec<f64> = h.transpose().iter().copied().collect();
                            homographies.push_str(&numbers(&v));
                        }
                        None => homographies.push_str(&numbers(&[0.0; 9])),
                    }
                    homographies.push('\n');
                }
                let c = dir.join(format!("{seq}_{tracker}.txt"));
                let h = dir.join(format!("{seq}_{tracker}_homography.txt"));
                write_atomic(&c, corners.as_bytes())?;
                write_atomic(&h, homographies.as_bytes())?;
                files.extend([c, h]);
            }
            ResultsFormat::Vot => {
                let mut text = String::new();
                let mut failed = false;
                for f in &r.frames {
                    let region = if f.init {
                        failed = false;
                        Region::Code(VOT_INIT)
                    } else if let Some(q) = f.corners {
                        failed = false;
                        Region::Polygon(q.0.to_vec())
                    } else if failed {
                        Region::Code(VOT_SKIPPED)
                    } else {
                        failed = true;
                        Region::Code(VOT_FAILURE)
                    };
                    text.push_str(&vot_region_line(&region));
                    text.push('\n');
                }
                let p = out
                    .join(&tracker)
                    .join("baseline")
                    .join(&seq)
                    .join(format!("{seq}_001.txt"));
                write_atomic(&p, text.as_bytes())?;
                files.push(p);
            }
            ResultsFormat::Got10k | ResultsFormat::Lasot => {
                let one = if format == ResultsFormat::Lasot {
                    1.0
                } else {
                    0.0
                };
                let mut boxes = String::new();
                for f in &r.frames {
                    let b = f.corners.map_or([0.0; 4], |q| {
                        let b = bbox(&q);
                        [b[0] + one, b[1] + one, b[2], b[3]]
                    });
                    boxes.push_str(
                        &b.iter()
                            .map(|x| format!("{x:.4}"))
                            .collect::<Vec<_>>()
                            .join(","),
                    );
                    boxes.push('\n');
                }
                if format == ResultsFormat::Lasot {
                    let p = out
                        .join(format!("{tracker}_tracking_result"))
                        .join(format!("{seq}.txt"));
                    write_atomic(&p, boxes.as_bytes())?;
                    files.push(p);
                } else {
                    let dir = out.join(&tracker).join(&seq);
                    let p = dir.join(format!("{seq}_001.txt"));
                    let t = dir.join(format!("{seq}_time.txt"));
                    let times: String = r
                        .frames
                        .iter()
                        .map(|f| format!("{:.6}\n", f.update_us * 1e-6))
                        .collect();
                    write_atomic(&p, boxes.as_bytes())?;
                    write_atomic(&t, times.as_bytes())?;
                    files.extend([p, t]);
                }
            }
        }
    }
    Ok(files)
}
