//! A batch evaluation: every (sequence, tracker) of a product, in parallel, optionally one shard
//! of it, writing each run's files as soon as it ends and resuming the runs an earlier batch in
//! the same folder finished. The command line, the tests and the bindings drive it the same way.

use super::{EvalOptions, RunResult, Summary, files, run_sequence_reading, summarize};
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::observe::NoObserver;
use crate::spec::TrackerSpec;
use rayon::prelude::*;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

/// One shard of a batch: the runs `index, index + count, index + 2 count, ...` of the product
/// (sequences outer, trackers inner), for a cluster scheduler's array of tasks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = Error;
    /// `k/n`, with `0 <= k < n`.
    fn from_str(s: &str) -> Result<Self> {
        let bad =
            || Error::InvalidParameter(format!("--shard must be k/n with 0 <= k < n, got '{s}'"));
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

/// What to evaluate and how.
#[derive(Clone, Debug)]
pub struct Batch<'a> {
    pub sequences: &'a [Sequence],
    pub specs: &'a [TrackerSpec],
    pub options: EvalOptions,
    /// Parallel runs (0: all cores).
    pub jobs: usize,
    pub shard: Option<Shard>,
    /// Where each run's files are written (and, with `resume`, read back from).
    pub out: Option<&'a Path>,
    /// Read back the runs that a batch in `out` finished with the same settings.
    pub resume: bool,
}

/// The runs of a batch that are done and those to make.
#[derive(Debug)]
pub struct Plan {
    /// Runs read back from the output folder.
    pub finished: Vec<RunResult>,
    /// `(sequence, spec)` indices still to run.
    pub todo: Vec<(usize, usize)>,
    /// The runs of this shard of the product (finished + todo).
    pub selected: usize,
}

/// The lock of an evaluation's output folder (`.regtrack-eval.lock`: host, pid and start),
/// held while a batch runs and removed when it ends. A second batch into the folder is refused
/// while its holder may run ([`crate::dataset::owner_may_run`]: on this host while its
/// process lives; on another host for a day, since its processes cannot be seen from here),
/// saying who holds it; a stale lock is taken over.
#[derive(Debug)]
pub struct OutLock {
    path: std::path::PathBuf,
}

/// The lock file's name in an output folder.
pub const LOCK_FILE: &str = ".regtrack-eval.lock";

impl OutLock {
    /// Takes the lock of `out` (made if missing).
    pub fn take(out: &Path) -> Result<OutLock> {
        std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
        let path = out.join(LOCK_FILE);
        let me = format!(
            "host {}\npid {}\nstarted {}\n",
            crate::dataset::host_name(),
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs())
        );
        for _ in 0..2 {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut f) => {
                    use std::io::Write as _;
                    f.write_all(me.as_bytes())
                        .map_err(|e| Error::io(&path, e))?;
                    return Ok(OutLock { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let text = std::fs::read_to_string(&path).unwrap_or_default();
                    let field = |k: &str| {
                        text.lines()
                            .find_map(|l| l.strip_prefix(k).map(|v| v.trim().to_string()))
                    };
                    let (host, pid) = (field("host "), field("pid ").and_then(|p| p.parse().ok()));
                    let age = std::fs::metadata(&path)
                        .and_then(|m| m.modified())
                        .ok()
                        .and_then(|t| t.elapsed().ok());
                    let live = pid.is_some_and(|pid| {
                        crate::dataset::owner_may_run(pid, host.as_deref(), age)
                    });
                    if live {
                        return Err(Error::report(
                            out,
                            format!(
                                "another evaluation writes into this folder: pid {} on host {} (its lock {}); give \
                                 this one another --out, or remove the lock if that job is gone",
                                pid.map_or("?".into(), |p: u32| p.to_string()),
                                host.as_deref().unwrap_or("?"),
                                path.display()
                            ),
                        ));
                    }
                    // Its holder is gone: the lock is stale.
                    let _ = std::fs::remove_file(&path);
                }
                Err(e) => return Err(Error::io(&path, e)),
            }
        }
        Err(Error::report(out, "cannot take the folder's lock"))
    }
}

impl Drop for OutLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// A run of a batch that has just finished, for the progress (a bar on a terminal, a line a
/// run in a cluster job's log).
#[derive(Clone, Debug)]
pub struct Finished<'a> {
    /// Runs finished so far in this execution, of `total`.
    pub done: usize,
    pub total: usize,
    pub sequence: &'a str,
    pub tracker: String,
    /// How it went: its frames and SR@5, or why it failed.
    pub what: String,
}

impl std::fmt::Display for Finished<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "run {} of {}: {} on {}: {}",
            self.done, self.total, self.tracker, self.sequence, self.what
        )
    }
}

/// What a batch did.
#[derive(Debug)]
pub struct BatchOutcome {
    /// Every run made or read back (in the order of the product, resumed ones first).
    pub runs: Vec<RunResult>,
    /// How many were read back instead of made.
    pub resumed: usize,
    /// Runs that failed (no ground truth to start from, files that cannot be written) or
    /// stopped early (a frame that cannot be read: what they tracked is in `runs`), one message
    /// each.
    pub failures: Vec<String>,
}

impl BatchOutcome {
    /// The summary rows: one per run, then the pooled rows ([`summary_rows`]).
    pub fn rows(&self) -> Vec<Summary> {
        summary_rows(&self.runs)
    }
}

impl<'a> Batch<'a> {
    /// Every pair of the product, with the default options, all cores, no files.
    pub fn new(sequences: &'a [Sequence], specs: &'a [TrackerSpec]) -> Self {
        Batch {
            sequences,
            specs,
            options: EvalOptions::default(),
            jobs: 0,
            shard: None,
            out: None,
            resume: false,
        }
    }

    /// The runs of this shard, split into those an earlier batch finished and those to make.
    pub fn plan(&self) -> Plan {
        let pairs = (0..self.sequences.len())
            .flat_map(|s| (0..self.specs.len()).map(move |p| (s, p)))
            .enumerate()
            .filter(|(i, _)| self.shard.is_none_or(|sh| i % sh.count == sh.index))
            .map(|(_, p)| p);
        let mut plan = Plan {
            finished: Vec::new(),
            todo: Vec::new(),
            selected: 0,
        };
        let mut stamps: Vec<Option<String>> = vec![None; self.sequences.len()];
        for (s, p) in pairs {
            plan.selected += 1;
            // A run file is written last and atomically: it exists only for a complete run.
            let done = self.out.filter(|_| self.resume).and_then(|out| {
                let seq = &self.sequences[s];
                let stamp = stamps[s].get_or_insert_with(|| files::input_stamp(seq));
                // A run from before the homography discrepancy was recorded is made again (its
                // benchmark figures would be missing); the factors are the sequence's today.
                files::finished_run(out, seq, stamp, &self.specs[p], &self.options)
                    .filter(|r| r.discrepancy)
                    .map(|mut r| {
                        r.factors = seq.factors.clone();
                        r
                    })
            });
            match done {
                Some(r) => plan.finished.push(r),
                None => plan.todo.push((s, p)),
            }
        }
        plan
    }

    /// Refuses an output folder that holds runs of other settings this batch would leave beside
    /// its own (another `--error`, `--gt-ssm` or re-initialisation, or a tracker of this batch
    /// with other parameters): its summary and any report of the folder would mix them. The
    /// runs this batch makes or resumes are its own.
    fn check_out(&self, out: &Path, plan: &Plan) -> Result<()> {
        let mine: std::collections::HashSet<(String, String)> = plan
            .todo
            .iter()
            .map(|&(s, p)| (self.sequences[s].name.clone(), self.specs[p].label()))
            .chain(
                plan.finished
                    .iter()
                    .map(|r| (r.sequence.clone(), r.spec.label())),
            )
            .collect();
        for r in files::readable_runs(out) {
            if mine.contains(&(r.sequence.clone(), r.spec.label())) {
                continue;
            }
            let mut d = files::differences(&files::json(&r.options), &files::json(&self.options));
            if let Some(s) = self.specs.iter().find(|s| s.label() == r.spec.label()) {
                d.extend(files::differences(&files::json(&r.spec), &files::json(s)));
            }
            if !d.is_empty() {
                return Err(Error::report(
                    out,
                    format!(
                        "holds the run of {} on {} made with other settings ({}); this batch \
                         would leave it beside runs it cannot be pooled with: give another \
                         --out, or remove that run",
                        r.spec.label(),
                        r.sequence,
                        d.join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Makes the runs `plan` has still to make, calling `progress(done, total)` after each.
    pub fn execute(
        &self,
        plan: Plan,
        progress: &(dyn Fn(Finished<'_>) + Sync),
    ) -> Result<BatchOutcome> {
        // One batch at a time in a folder (two jobs given one --out both did all the work);
        // then what a killed batch left half-written goes.
        let _lock = match self.out {
            Some(out) => {
                let lock = OutLock::take(out)?;
                crate::dataset::remove_stale_temporaries(out);
                self.check_out(out, &plan)?;
                // What the whole evaluation is, for `merge` and `report` to check the shards
                // against.
                let shard = self.shard.map(|s| (s.index, s.count));
                super::PlanFile::of(self.sequences, self.specs, &self.options, shard).write(out)?;
                Some(lock)
            }
            None => None,
        };
        let total = plan.todo.len();
        let done = AtomicUsize::new(0);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(self.jobs)
            .build()
            .map_err(|e| Error::Threads {
                threads: self.jobs,
                message: e.to_string(),
            })?;
        // Runs that leave a core free have their frames decoded ahead by it.
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let ahead = pool.current_num_threads().min(total) < cores;
        let made: Vec<Result<RunResult>> = pool.install(|| {
            plan.todo
                .par_iter()
                .map(|&(s, p)| {
                    let (seq, spec) = (&self.sequences[s], &self.specs[p]);
                    let r = self.run_one(seq, spec, ahead);
                    let what = match &r {
                        Ok(run) => {
                            let e = run.sr_errors();
                            let sr = super::success_rate(&e, 5.0);
                            match &run.error {
                                Some(why) => format!(
                                    "{} frames, SR@5 {sr:.3}; stopped: {why}",
                                    run.frames.len()
                                ),
                                None => format!("{} frames, SR@5 {sr:.3}", run.frames.len()),
                            }
                        }
                        Err(e) => format!("failed: {e}"),
                    };
                    progress(Finished {
                        done: done.fetch_add(1, Ordering::Relaxed) + 1,
                        total,
                        sequence: &seq.name,
                        tracker: spec.label(),
                        what,
                    });
                    r
                })
                .collect()
        });
        let resumed = plan.finished.len();
        let mut outcome = BatchOutcome {
            runs: plan.finished,
            resumed,
            failures: Vec::new(),
        };
        for (r, &(s, p)) in made.into_iter().zip(&plan.todo) {
            match r {
                Ok(r) => {
                    if let Some(e) = &r.error {
                        outcome
                            .failures
                            .push(format!("{} on {}: {e}", r.spec.label(), r.sequence));
                    }
                    outcome.runs.push(r);
                }
                Err(e) => outcome.failures.push(format!(
                    "{} on {}: {e}",
                    self.specs[p].label(),
                    self.sequences[s].name
                )),
            }
        }
        Ok(outcome)
    }

    /// [`Batch::plan`], then [`Batch::execute`].
    pub fn run(&self, progress: &(dyn Fn(Finished<'_>) + Sync)) -> Result<BatchOutcome> {
        self.execute(self.plan(), progress)
    }

    /// One run; its files are written as soon as it ends, so that a killed batch keeps them.
    fn run_one(&self, seq: &Sequence, spec: &TrackerSpec, ahead: bool) -> Result<RunResult> {
        let run = run_sequence_reading(seq, spec, &self.options, None, &mut NoObserver, ahead)?;
        if let Some(out) = self.out {
            files::write_run_files(out, &run, &seq.frame_names())?;
        }
        Ok(run)
    }
}

/// The runs grouped by tracker (its label), in the order each tracker first appears.
pub fn by_tracker(runs: &[RunResult]) -> Vec<Vec<&RunResult>> {
    let mut groups: Vec<(String, Vec<&RunResult>)> = Vec::new();
    for r in runs {
        let label = r.spec.label();
        match groups.iter_mut().find(|(l, _)| *l == label) {
            Some((_, g)) => g.push(r),
            None => groups.push((label, vec![r])),
        }
    }
    groups.into_iter().map(|(_, g)| g).collect()
}

/// The rows of a summary: one per run, then, for each tracker with runs on more than one
/// sequence, one pooled over them (sequence `ALL`: its frames counted together), then one per
/// challenge factor of its sequences ([`factor_label`]: `ALL:<factor>`, its runs on the
/// sequences of that factor pooled), factors in the order they first appear.
pub fn summary_rows(runs: &[RunResult]) -> Vec<Summary> {
    let mut rows: Vec<Summary> = runs.iter().map(RunResult::summary).collect();
    let groups: Vec<Vec<&RunResult>> = by_tracker(runs)
        .into_iter()
        .filter(|g| g.len() > 1)
        .collect();
    rows.extend(groups.iter().map(|g| summarize(POOLED, g)));
    rows.extend(groups.iter().flat_map(|g| factor_rows(g)));
    rows
}

/// One tracker's runs pooled per challenge factor of their sequences (`ALL:<factor>`, the runs
/// on the sequences of that factor counted together), factors in the order they first appear.
pub fn factor_rows(runs: &[&RunResult]) -> Vec<Summary> {
    let mut factors: Vec<&str> = Vec::new();
    for f in runs.iter().flat_map(|r| r.factors.iter()) {
        if !factors.contains(&f.as_str()) {
            factors.push(f);
        }
    }
    factors
        .into_iter()
        .map(|f| {
            let mine: Vec<&RunResult> = runs
                .iter()
                .copied()
                .filter(|r| r.factors.iter().any(|x| x == f))
                .collect();
            summarize(&factor_label(POOLED, f), &mine)
        })
        .collect()
}

/// The sequence name of the rows pooled over the sequences of a challenge factor:
/// `<pooled>:<factor>` (`ALL:blur`).
pub fn factor_label(pooled: &str, factor: &str) -> String {
    format!("{pooled}:{factor}")
}

/// The sequence name of the pooled rows.
pub const POOLED: &str = "ALL";
