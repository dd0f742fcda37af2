//! What each output folder of an evaluation knows of the whole (`eval-plan.json`): the product
//! of sequences and trackers, this folder's shard of it and a stamp of the inputs and settings.
//! `merge` and `report` check a set of folders against it ([`completeness`]): folders of other
//! evaluations (mixed) or the same shard twice are refused; missing shards or runs (a task that
//! never ran, or was cancelled part way) are named, and pooled only when asked (`--partial`),
//! the result then labelled partial.

use super::files::Fnv;
use super::{EvalOptions, RunResult};
use crate::dataset::{Sequence, write_atomic};
use crate::error::{Error, Result};
use crate::spec::TrackerSpec;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The plan file's name in an output folder.
pub const PLAN_FILE: &str = "eval-plan.json";

/// See the module's documentation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanFile {
    /// The file's format.
    pub format: u32,
    /// A stamp of the product's names, each sequence's input files and ground truth, the
    /// options and every tracker's spec: two folders of one evaluation have the same.
    pub stamp: String,
    /// This folder's shard `[k, n]`; none for the whole product.
    pub shard: Option<(usize, usize)>,
    /// The whole product, sequences outer, trackers inner: `[sequence, tracker]`.
    pub runs: Vec<(String, String)>,
}

impl PlanFile {
    /// The plan of the product of `sequences` and `specs` with `options`, as shard `shard`.
    pub fn of(
        sequences: &[Sequence],
        specs: &[TrackerSpec],
        options: &EvalOptions,
        shard: Option<(usize, usize)>,
    ) -> Self {
        let mut h = Fnv::new();
        for s in sequences {
            h.write(super::files::input_stamp(s).as_bytes());
        }
        for s in specs {
            h.write(super::files::json(s).to_string().as_bytes());
        }
        h.write(super::files::json(options).to_string().as_bytes());
        PlanFile {
            format: 1,
            stamp: format!("{:016x}", h.finish()),
            shard,
            runs: sequences
                .iter()
                .flat_map(|s| specs.iter().map(|p| (s.name.clone(), p.label())))
                .collect(),
        }
    }

    /// Written into `out` (atomically).
    pub fn write(&self, out: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::InvalidParameter(e.to_string()))?;
        write_atomic(&out.join(PLAN_FILE), text.as_bytes())
    }

    /// The plan file of `dir`, if it has one.
    pub fn read(dir: &Path) -> Result<Option<Self>> {
        let path = dir.join(PLAN_FILE);
        let Some(text) = crate::files::read_text_optional(&path, crate::files::TEXT_LIMIT)? else {
            return Ok(None);
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| Error::report(&path, format!("not an evaluation's plan: {e}")))
    }
}

/// What a set of output folders lacks of the evaluation they are of.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Incomplete {
    /// Folders without a plan file (made by a regtrack before plan files, or not `eval`'s).
    pub unplanned: Vec<PathBuf>,
    /// The shards none of the folders is (`k`), of `shards`.
    pub missing_shards: Vec<usize>,
    pub shards: usize,
    /// The runs of the product none of the folders holds, of `total`.
    pub missing_runs: Vec<(String, String)>,
    pub total: usize,
}

impl std::fmt::Display for Incomplete {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut parts = Vec::new();
        if !self.unplanned.is_empty() {
            let names: Vec<String> = self
                .unplanned
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            parts.push(format!(
                "{} has no {PLAN_FILE}, so what the whole evaluation is cannot be told",
                names.join(", ")
            ));
        }
        if !self.missing_shards.is_empty() {
            let names: Vec<String> = self
                .missing_shards
                .iter()
                .map(|k| format!("{k}/{}", self.shards))
                .collect();
            parts.push(format!("shard {} missing", names.join(", ")));
        }
        if !self.missing_runs.is_empty() {
            let shown: Vec<String> = self
                .missing_runs
                .iter()
                .take(8)
                .map(|(s, t)| format!("{t} on {s}"))
                .collect();
            let more = self.missing_runs.len().saturating_sub(shown.len());
            parts.push(format!(
                "{} of {} runs missing: {}{}",
                self.missing_runs.len(),
                self.total,
                shown.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        write!(f, "{}", parts.join("; "))
    }
}

/// The plan files of `dirs` (`None` for a folder without one), checked not to hold one shard
/// of an evaluation twice: an error naming the two folders otherwise.
pub fn check_plans(dirs: &[PathBuf]) -> Result<Vec<Option<PlanFile>>> {
    let plans: Vec<Option<PlanFile>> = dirs
        .iter()
        .map(|d| PlanFile::read(d))
        .collect::<Result<_>>()?;
    let mut seen: BTreeMap<(&str, usize, usize), &PathBuf> = BTreeMap::new();
    for (d, p) in dirs.iter().zip(&plans) {
        let Some(p) = p else { continue };
        let (k, n) = p.shard.unwrap_or((0, 1));
        if let Some(other) = seen.insert((p.stamp.as_str(), k, n), d) {
            return Err(Error::InvalidParameter(format!(
                "shard {k}/{n} is given twice: {} and {}",
                other.display(),
                d.display()
            )));
        }
    }
    Ok(plans)
}

/// Refuses folders of different evaluations (another product, inputs, settings or shard
/// count), naming two of them.
fn check_one_evaluation(dirs: &[PathBuf], plans: &[Option<PlanFile>]) -> Result<()> {
    let count = |p: &PlanFile| p.shard.map_or(1, |(_, n)| n);
    let mut first: Option<(&PathBuf, &PlanFile)> = None;
    for (d, p) in dirs.iter().zip(plans) {
        let Some(p) = p else { continue };
        let (fd, f) = *first.get_or_insert((d, p));
        if p.stamp != f.stamp || p.runs != f.runs || count(p) != count(f) {
            return Err(Error::InvalidParameter(format!(
                "{} and {} are of different evaluations (other sequences, trackers, settings or \
                 shard counts): give the folders of one evaluation",
                fd.display(),
                d.display()
            )));
        }
    }
    Ok(())
}

/// Checks the folders `dirs` (their runs `runs`) against their plan files `plans` (as
/// [`check_plans`] read them): that they are of one evaluation; what they lack of the whole
/// evaluation (`None` when nothing).
pub fn completeness(
    dirs: &[PathBuf],
    plans: &[Option<PlanFile>],
    runs: &[RunResult],
) -> Result<Option<Incomplete>> {
    check_one_evaluation(dirs, plans)?;
    let mut inc = Incomplete::default();
    for (d, p) in dirs.iter().zip(plans) {
        if p.is_none() {
            inc.unplanned.push(d.clone());
        }
    }
    let Some(first) = plans.iter().flatten().next() else {
        return Ok((!inc.unplanned.is_empty()).then_some(inc));
    };
    let shards: BTreeSet<usize> = plans
        .iter()
        .flatten()
        .map(|p| p.shard.map_or(0, |(k, _)| k))
        .collect();
    inc.shards = first.shard.map_or(1, |(_, n)| n);
    inc.missing_shards = (0..inc.shards).filter(|k| !shards.contains(k)).collect();
    let held: BTreeSet<(&str, String)> = runs
        .iter()
        .map(|r| (r.sequence.as_str(), r.spec.label()))
        .collect();
    inc.total = first.runs.len();
    inc.missing_runs = first
        .runs
        .iter()
        .filter(|(s, t)| !held.contains(&(s.as_str(), t.clone())))
        .cloned()
        .collect();
    let complete =
        inc.unplanned.is_empty() && inc.missing_shards.is_empty() && inc.missing_runs.is_empty();
    Ok((!complete).then_some(inc))
}

/// [`completeness`] as `merge` and `report` apply it: an incomplete set is an error naming
/// what is missing, unless `partial`, when it is returned to be labelled.
pub fn require_complete(
    dirs: &[PathBuf],
    plans: &[Option<PlanFile>],
    runs: &[RunResult],
    partial: bool,
) -> Result<Option<Incomplete>> {
    match completeness(dirs, plans, runs)? {
        Some(inc) if !partial => Err(Error::InvalidParameter(format!(
            "incomplete evaluation: {inc}. Give every shard's folder (a cancelled task \
             submitted again resumes where it stopped), or --partial for a result labelled \
             partial"
        ))),
        other => Ok(other),
    }
}
