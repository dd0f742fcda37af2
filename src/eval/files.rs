//! Result files: per run the corners (MTF format), per-frame errors and the success curve under
//! `tracking_data/<sequence>/<sm>_<am>_<ssm>*.txt` and the whole run as `..._run.json`; per batch
//! `summary.csv` and `summary.json`. Shards of a batch (one `--out` each) merge into one summary.

use super::{RunResult, Summary, success_curve, summary_rows};
use crate::dataset::{write_atomic, write_corners_named};
use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Writes a run's files, the corners named as the sequence names its frames (`names`,
/// [`crate::dataset::Sequence::frame_names`]); returns the corners file.
pub fn write_run_files(out: &Path, run: &RunResult, names: &[String]) -> Result<PathBuf> {
    let dir = out.join("tracking_data").join(&run.sequence);
    let label = run.spec.label();
    let corners: Vec<_> = run.frames.iter().map(|f| f.corners).collect();
    let corners_path = dir.join(format!("{label}.txt"));
    write_corners_named(&corners_path, &corners, names)?;
    let mut errors = String::from(
        "frame\talignment_error\tcenter_error\tiou_error\tstatus\titerations\tsearch_us\tupdate_us\n",
    );
    for f in &run.frames {
        let status = match f.status {
            crate::status::TrackStatus::Lost(r) => format!("lost:{}", serde_plain(&r)),
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
    // On the success curve's 0..20 grid, as `summary.csv`'s rates (Jaccard's 0..1 scaled).
    for (t, v) in success_curve(&run.sr_errors()) {
        sr.push_str(&format!("{t:.1}\t{v:.6}\n"));
    }
    write_atomic(&dir.join(format!("{label}_sr.txt")), sr.as_bytes())?;
    let json = serde_json::to_string(run).map_err(|e| Error::InvalidParameter(e.to_string()))?;
    write_atomic(&dir.join(format!("{label}_run.json")), json.as_bytes())?;
    Ok(corners_path)
}

/// The run file of a tracker on a sequence under an output folder.
pub fn run_file(out: &Path, sequence: &str, spec: &crate::spec::TrackerSpec) -> PathBuf {
    out.join("tracking_data")
        .join(sequence)
        .join(format!("{}_run.json", spec.label()))
}

/// A finished run of `spec` on `seq` with the same options and the same inputs, saved under
/// `out` (for resuming a batch): its run file (written last, atomically) exists, reads back, the
/// run reached the end of the sequence and its [`input_stamp`] is `stamp`. Anything else (a
/// ground truth or frame list changed since, a run file of an older version without a stamp)
/// means the run must be made again.
pub fn finished_run(
    out: &Path,
    seq: &crate::dataset::Sequence,
    stamp: &str,
    spec: &crate::spec::TrackerSpec,
    opts: &super::EvalOptions,
) -> Option<RunResult> {
    let bytes =
        crate::files::read_bounded(&run_file(out, &seq.name, spec), crate::files::RUN_LIMIT);
    let text = String::from_utf8(bytes.ok()?).ok()?;
    let run: RunResult = serde_json::from_str(&text).ok()?;
    (run.error.is_none()
        && &run.spec == spec
        && &run.options == opts
        && run.sequence == seq.name
        && run.inputs.as_deref() == Some(stamp))
    .then_some(run)
}

/// 64-bit FNV-1a, for [`input_stamp`] and the plan file's stamp (stable across builds and
/// platforms).
pub(super) struct Fnv(u64);

impl Fnv {
    pub(super) fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    pub(super) fn finish(&self) -> u64 {
        self.0
    }

    pub(super) fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
        // A separator, so that ("ab", "c") and ("a", "bc") differ.
        self.0 = (self.0 ^ 0xff).wrapping_mul(0x0000_0100_0000_01b3);
    }

    /// A file's path, size and modification time (or that it is missing).
    fn file(&mut self, path: &Path) {
        self.write(path.as_os_str().as_encoded_bytes());
        match std::fs::metadata(path) {
            Ok(m) => {
                self.write(&m.len().to_le_bytes());
                let t = m
                    .modified()
                    .ok()
                    .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                    .map_or(0, |d| d.as_nanos());
                self.write(&t.to_le_bytes());
            }
            Err(_) => self.write(b"missing"),
        }
    }
}

/// A fingerprint of what a run on `seq` reads: its frame list (each frame's name, size and
/// modification time), its ground truth as loaded, and the low-DOF ground-truth files
/// (`OptGT/<seq>_*.txt`) beside it. A resumed run is used only if this has not changed.
pub fn input_stamp(seq: &crate::dataset::Sequence) -> String {
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    h.write(seq.name.as_bytes());
    h.write(&(seq.frames.len() as u64).to_le_bytes());
    // A video's frames are in the video file.
    if let Some(v) = &seq.video {
        h.file(&v.path);
    }
    for f in &seq.frames {
        h.file(f);
    }
    for q in &seq.ground_truth {
        match q {
            Some(q) => {
                for v in q.to_array() {
                    h.write(&v.to_bits().to_le_bytes());
                }
            }
            None => h.write(b"none"),
        }
    }
    // The benchmark's own homographies score the discrepancy (none: nothing written, the
    // stamps of the layouts without them unchanged).
    for m in &seq.homographies {
        match m {
            Some(m) => {
                for v in m.iter() {
                    h.write(&v.to_bits().to_le_bytes());
                }
            }
            None => h.write(b"no homography"),
        }
    }
    let opt = crate::gt::ground_truth_dir(seq).join("OptGT");
    let prefix = format!("{}_", seq.name);
    let mut low: Vec<PathBuf> = std::fs::read_dir(&opt)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with(&prefix) && n.ends_with(".txt"))
                })
                .collect()
        })
        .unwrap_or_default();
    low.sort();
    for p in low {
        h.write(p.as_os_str().as_encoded_bytes());
        h.write(&crate::files::read_bounded(&p, crate::files::TEXT_LIMIT).unwrap_or_default());
    }
    format!("{:016x}", h.0)
}

/// Every run saved under `dir/tracking_data` (sorted by sequence, then tracker).
pub fn read_runs(dir: &Path) -> Result<Vec<RunResult>> {
    run_paths(dir)?
        .iter()
        .map(|f| {
            let text = crate::files::read_text(f, crate::files::RUN_LIMIT)?;
            serde_json::from_str(&text).map_err(|e| Error::Parse {
                path: f.clone(),
                line: e.line(),
                message: e.to_string(),
            })
        })
        .collect()
}

/// The runs under `dir/tracking_data` that can be read (the others are skipped: a batch makes
/// them again); none without the folder.
pub fn readable_runs(dir: &Path) -> Vec<RunResult> {
    run_paths(dir)
        .unwrap_or_default()
        .iter()
        .filter_map(|f| {
            let bytes = crate::files::read_bounded(f, crate::files::RUN_LIMIT).ok()?;
            serde_json::from_slice(&bytes).ok()
        })
        .collect()
}

/// The run files under `dir/tracking_data`, sorted.
fn run_paths(dir: &Path) -> Result<Vec<PathBuf>> {
    let data = dir.join("tracking_data");
    let mut files = Vec::new();
    for seq in std::fs::read_dir(&data).map_err(|e| Error::io(&data, e))? {
        let seq = seq.map_err(|e| Error::io(&data, e))?.path();
        if seq.is_dir() {
            for f in std::fs::read_dir(&seq).map_err(|e| Error::io(&seq, e))? {
                let f = f.map_err(|e| Error::io(&seq, e))?.path();
                if f.to_string_lossy().ends_with("_run.json") {
                    files.push(f);
                }
            }
        }
    }
    files.sort();
    Ok(files)
}

/// Every run saved under each of `dirs` (`DIR/tracking_data/<seq>/*_run.json`). A folder without
/// runs is an error naming it, and so is a run (sequence and tracker) found in two folders: its
/// frames would count twice.
pub fn read_all_runs(dirs: &[PathBuf]) -> Result<Vec<RunResult>> {
    if dirs.is_empty() {
        return Err(Error::InvalidParameter(
            "no evaluation folder given".to_string(),
        ));
    }
    let mut seen: BTreeMap<(String, String), &Path> = BTreeMap::new();
    let mut all = Vec::new();
    for dir in dirs {
        if !dir.is_dir() {
            return Err(Error::Missing { path: dir.clone() });
        }
        let no_runs = || {
            Error::report(
                dir,
                "no evaluation runs here (tracking_data/<sequence>/*_run.json); \
                 give an output folder of `regtrack eval`",
            )
        };
        // A folder an evaluation planned but finished no run in (a task cancelled before its
        // first run ended) is an empty shard: what it lacks is said by the plan's check.
        let planned = dir.join(super::PLAN_FILE).is_file();
        if !dir.join("tracking_data").is_dir() {
            if planned {
                continue;
            }
            return Err(no_runs());
        }
        let runs = read_runs(dir)?;
        if runs.is_empty() && !planned {
            return Err(no_runs());
        }
        for r in &runs {
            let key = (r.sequence.clone(), r.spec.label());
            if let Some(first) = seen.insert(key, dir) {
                return Err(Error::report(
                    dir,
                    format!(
                        "the run of {} on {} is also in {}: give each run once",
                        r.spec.label(),
                        r.sequence,
                        first.display()
                    ),
                ));
            }
        }
        all.extend(runs);
    }
    check_one_setting(&all)?;
    Ok(all)
}

/// Where two values differ, as `path: a vs b` (at most three), from their JSON forms.
pub(crate) fn differences(a: &serde_json::Value, b: &serde_json::Value) -> Vec<String> {
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        use serde_json::Value::Object;
        match (a, b) {
            (Object(x), Object(y)) => {
                let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
                for k in keys {
                    let null = serde_json::Value::Null;
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    walk(
                        &p,
                        x.get(k).unwrap_or(&null),
                        y.get(k).unwrap_or(&null),
                        out,
                    );
                }
            }
            _ if a != b => out.push(format!("{path}: {a} vs {b}")),
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk("", a, b, &mut out);
    out.truncate(3);
    out
}

/// How run `b`'s settings differ from run `a`'s where they must be the same to be pooled or
/// kept side by side (`None`: they do not): the evaluation's options (the error, the ground
/// truth, the re-initialisation) for any two runs, and the whole spec (every parameter) for two
/// runs of one tracker.
pub fn settings_differ(a: &RunResult, b: &RunResult) -> Option<String> {
    let mut d = differences(&json(&a.options), &json(&b.options));
    if a.spec.label() == b.spec.label() {
        d.extend(differences(&json(&a.spec), &json(&b.spec)));
    }
    (!d.is_empty()).then(|| d.join(", "))
}

/// What [`settings_differ`] compares, as JSON.
pub(crate) fn json<T: serde::Serialize>(v: &T) -> serde_json::Value {
    serde_json::to_value(v).unwrap_or(serde_json::Value::Null)
}

/// Refuses runs of different settings pooled together ([`settings_differ`]): a different
/// `--res`, `--error` or `--gt-ssm` averaged in with the rest would make every pooled row a mix.
pub fn check_one_setting(runs: &[RunResult]) -> Result<()> {
    let Some(first) = runs.first() else {
        return Ok(());
    };
    let mut by_label: BTreeMap<String, &RunResult> = BTreeMap::new();
    for r in runs {
        let a = by_label.entry(r.spec.label()).or_insert(r);
        for a in [first, *a] {
            if let Some(d) = settings_differ(a, r) {
                return Err(Error::InvalidParameter(format!(
                    "runs of different settings cannot be pooled: {} on {} and {} on {} differ \
                     ({d}); give the runs of one setting",
                    a.spec.label(),
                    a.sequence,
                    r.spec.label(),
                    r.sequence
                )));
            }
        }
    }
    Ok(())
}

/// Merges the outputs of several shards of one evaluation: the summary rows of all their runs
/// ([`summary_rows`]), written to `out`. A run found in two shards, folders of different
/// evaluations or a shard given twice are errors; so is an incomplete set (a shard or a run
/// missing), unless `partial`, when the pooled rows are named [`POOLED_PARTIAL`] and
/// `PARTIAL.txt` in `out` says what is missing. Returns the rows and what is missing.
pub fn merge_shards(
    shards: &[PathBuf],
    out: &Path,
    partial: bool,
) -> Result<(Vec<Summary>, Option<super::Incomplete>)> {
    // Folders of other evaluations or a shard twice, said as such (before the runs they share).
    let plans = super::plan_file::check_plans(shards)?;
    let runs = read_all_runs(shards)?;
    let missing = super::plan_file::require_complete(shards, &plans, &runs, partial)?;
    let mut rows = summary_rows(&runs);
    let note = out.join(PARTIAL_FILE);
    match &missing {
        Some(inc) => {
            for r in rows.iter_mut() {
                if r.sequence == super::POOLED {
                    r.sequence = POOLED_PARTIAL.to_string();
                } else if let Some(f) = r.sequence.strip_prefix(&format!("{}:", super::POOLED)) {
                    r.sequence = super::factor_label(POOLED_PARTIAL, f);
                }
            }
            std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
            write_atomic(&note, format!("partial result: {inc}\n").as_bytes())?;
        }
        None => {
            // A complete merge into a folder a partial one wrote: no longer partial.
            let _ = std::fs::remove_file(&note);
        }
    }
    write_summaries(out, &rows)?;
    Ok((rows, missing))
}

/// The sequence name of the pooled rows of a partial result (`merge --partial`).
pub const POOLED_PARTIAL: &str = "ALL-partial";
/// The file a partial merge writes beside its summary, saying what is missing.
pub const PARTIAL_FILE: &str = "PARTIAL.txt";

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
        "sequence,tracker,sm,am,ssm,frames,sr5,sr10,sr20,mean_sr,mean_error,failures,iterations_per_frame,tracker_fps,live_fps,error_type,gt,lost_when_off,lost_when_on,stopped,p5,p15,success_h,success_iou\n",
    );
    for r in rows {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{:.2},{:.1},{:.1},{},{},{},{},{},{},{},{},{}\n",
            r.sequence,
            r.tracker,
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
            r.live_fps,
            r.error_type,
            r.gt,
            fraction(r.lost_when_off, 4, ""),
            fraction(r.lost_when_on, 4, ""),
            r.stopped,
            fraction(r.p5, 4, ""),
            fraction(r.p15, 4, ""),
            fraction(r.success_h, 4, ""),
            fraction(r.success_iou, 4, ""),
        ));
    }
    write_atomic(&out.join("summary.csv"), csv.as_bytes())?;
    let json =
        serde_json::to_string_pretty(rows).map_err(|e| Error::InvalidParameter(e.to_string()))?;
    write_atomic(&out.join("summary.json"), json.as_bytes())
}

/// A fraction with `decimals`, or `missing` when it is undefined (`NaN`).
fn fraction(v: f64, decimals: usize, missing: &str) -> String {
    if v.is_nan() {
        missing.to_string()
    } else {
        format!("{v:.decimals$}")
    }
}

/// The summary rows as the command line prints them: a header, then a line per row.
pub fn summary_table(rows: &[Summary]) -> String {
    let mut out = format!(
        "{:<12} {:<22} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>8} {:>5} {:>6} {:>11} {:>9} {:>7} {:>7} {:>7}\n",
        "sequence",
        "tracker",
        "frames",
        "SR@5",
        "SR@20",
        "P@5",
        "P@15",
        "S(H)",
        "S(IoU)",
        "mean err",
        "fail",
        "it/fr",
        "tracker FPS",
        "live FPS",
        "lost>20",
        "lost<5",
        "stopped"
    );
    for r in rows {
        out.push_str(&format!(
            "{:<12} {:<22} {:>6} {:>6.3} {:>6.3} {:>6} {:>6} {:>6} {:>6} {:>8.3} {:>5} {:>6.2} {:>11.0} {:>9.0} {:>7} {:>7} {:>7}\n",
            r.sequence,
            r.tracker,
            r.frames,
            r.sr5,
            r.sr20,
            fraction(r.p5, 3, "-"),
            fraction(r.p15, 3, "-"),
            fraction(r.success_h, 3, "-"),
            fraction(r.success_iou, 3, "-"),
            r.mean_error,
            r.failures,
            r.iterations_per_frame,
            r.tracker_fps,
            r.live_fps,
            fraction(r.lost_when_off, 3, "-"),
            fraction(r.lost_when_on, 3, "-"),
            if r.stopped == 0 {
                "-".to_string()
            } else {
                r.stopped.to_string()
            }
        ));
    }
    out
}
