//! Result files: per run the corners (MTF format), per-frame errors and the success curve under
//! `tracking_data/<sequence>/<sm>_<am>_<ssm>*.txt`; per batch `summary.csv` and `summary.json`.

use super::{RunResult, Summary, success_curve};
use crate::dataset::{write_atomic, write_corners};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Writes a run's files; returns the corners file.
pub fn write_run_files(out: &Path, run: &RunResult) -> Result<PathBuf> {
    let dir = out.join("tracking_data").join(&run.sequence);
    let label = run.spec.label();
    let corners: Vec<_> = run.frames.iter().map(|f| f.corners).collect();
    let corners_path = dir.join(format!("{label}.txt"));
    write_corners(&corners_path, &corners, "jpg")?;
    let mut errors = String::from(
        "frame\talignment_error\tcenter_error\tiou_error\tstatus\titerations\tsearch_us\tupdate_us\n",
    );
    for f in &run.frames {
        let status = match f.status {
            crate::tracker::TrackStatus::Lost(r) => format!("lost:{}", serde_plain(&r)),
            s => serde_plain(&s),
        };
        errors.push_str(&format!(
            "{}\t{:.4}\t{:.4}\t{:.5}\t{}{}\t{}\t{:.1}\t{:.1}\n",
            f.frame + 1,
            f.alignment_error,
            f.center_error,
            f.iou_error,
            status,
            if f.init { ",init" } else { "" },
            f.iterations,
            f.search_us,
            f.update_us
        ));
    }
    write_atomic(&dir.join(format!("{label}_errors.txt")), errors.as_bytes())?;
    let mut sr = String::from("threshold\tsuccess_rate\n");
    for (t, v) in success_curve(&run.errors()) {
        sr.push_str(&format!("{t:.1}\t{v:.6}\n"));
    }
    write_atomic(&dir.join(format!("{label}_sr.txt")), sr.as_bytes())?;
    Ok(corners_path)
}

fn serde_plain<T: serde::Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(serde_json::Value::Object(m)) => m
            .values()
            .filter_map(|v| v.as_str())
            .collect::<Vec<_>>()
            .join(":"),
        Ok(other) => other.to_string(),
        Err(_) => String::new(),
    }
}

/// Writes `summary.csv` and `summary.json` in `out`.
pub fn write_summaries(out: &Path, rows: &[Summary]) -> Result<()> {
    let mut csv = String::from(
        "sequence,sm,am,ssm,frames,sr5,sr10,sr20,mean_sr,mean_error,failures,iterations_per_frame,tracker_fps,live_fps\n",
    );
    for r in rows {
        csv.push_str(&format!(
            "{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{:.2},{:.1},{:.1}\n",
            r.sequence,
            r.sm,
            r.am,
            r.ssm,
            r.frames,
            r.sr5,
            r.sr10,
            r.sr20,
            r.mean_sr,
            r.mean_error,
            r.failures,
            r.iterations_per_frame,
            r.tracker_fps,
            r.live_fps
        ));
    }
    write_atomic(&out.join("summary.csv"), csv.as_bytes())?;
    let json =
        serde_json::to_string_pretty(rows).map_err(|e| Error::InvalidParameter(e.to_string()))?;
    write_atomic(&out.join("summary.json"), json.as_bytes())
}
