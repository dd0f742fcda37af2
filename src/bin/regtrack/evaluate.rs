//! `regtrack eval`, `gt-fit`, `converge`, `bench` and `demo`: the progress bars and what they
//! print; the batches and measurements are the library's.

use crate::track::by_frame;
use crate::{bar, load_demo, warn_about};
use anyhow::{Context as _, Result, bail};
use regtrack::dataset::{self, Sequence};
use regtrack::eval::{self, Batch};
use regtrack::tracker::{self, TrackerSpec};
use regtrack::{bench, gt};
use std::path::Path;

pub fn run_eval(batch: &Batch, out: &Path, render: bool) -> Result<()> {
    warn_about_low_dof(batch);
    let plan = batch.plan();
    if !plan.finished.is_empty() {
        println!(
            "resuming: {} of {} runs already finished in {} (--no-resume to redo them)",
            plan.finished.len(),
            plan.selected,
            out.display()
        );
    }
    let pb = bar(plan.todo.len(), "evaluating");
    // Not on a terminal (a Slurm job's log, a pipe), where the bar does not show: a line a run.
    let lines = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let outcome = batch.execute(plan, &|f| {
        if lines {
            eprintln!("{f}");
        }
        pb.set_position(f.done as u64)
    })?;
    pb.finish_and_clear();
    let rows = outcome.rows();
    eval::write_summaries(out, &rows)?;
    print!("{}", eval::summary_table(&rows));
    println!("wrote {}", out.join("summary.csv").display());
    if render {
        for run in &outcome.runs {
            let Some(seq) = batch.sequences.iter().find(|s| s.name == run.sequence) else {
                continue;
            };
            let video = eval::run_file(out, &run.sequence, &run.spec)
                .with_file_name(format!("{}.mp4", run.spec.label()));
            dataset::video::render(seq, &by_frame(run, seq.len()), &video)?;
            println!("wrote {}", video.display());
        }
    }
    if !outcome.failures.is_empty() {
        bail!(
            "{} run(s) failed:\n  {}",
            outcome.failures.len(),
            outcome.failures.join("\n  ")
        );
    }
    Ok(())
}

/// The warnings of the low-DOF ground truth a batch scores against (`--gt-ssm`): OptGT corners
/// that cannot be a target's, read as not annotated (at most five a file).
fn warn_about_low_dof(batch: &Batch) {
    let Some(g) = batch.options.gt_ssm.as_deref() else {
        return;
    };
    let mut ssms: Vec<&str> = if g == eval::OWN_SSM {
        batch
            .specs
            .iter()
            .filter_map(|s| s.registration().map(|r| r.ssm.as_str()))
            .collect()
    } else {
        vec![g]
    };
    ssms.sort_unstable();
    ssms.dedup();
    const SHOWN: usize = 5;
    for seq in batch.sequences {
        for ssm in &ssms {
            // An unreadable file is the runs' error, reported with them.
            let Ok(gt::LowDofTruth { warnings, .. }) = gt::low_dof_ground_truth(seq, ssm) else {
                continue;
            };
            for w in warnings.iter().take(SHOWN) {
                eprintln!("warning: {w}");
            }
            if warnings.len() > SHOWN {
                eprintln!(
                    "warning: ... and {} more in the {ssm} ground truth of {}",
                    warnings.len() - SHOWN,
                    seq.name
                );
            }
        }
    }
}

pub fn run_gt_fit(
    root: &Path,
    seqs: Option<Vec<String>>,
    ssms: &[String],
    force: bool,
) -> Result<()> {
    let sequences = dataset::open_or_discover(root, seqs.as_deref())?;
    warn_about(&sequences);
    let outcomes = gt::fit_sequences(&sequences, ssms, force)?;
    println!(
        "{:<24} {:<12} {:>8} {:>10} {:>10}  worst frame",
        "sequence", "ssm", "frames", "mean px", "max px"
    );
    let mut kept = 0;
    for o in &outcomes {
        match o {
            gt::FitOutcome::Kept {
                sequence,
                ssm,
                path,
            } => {
                kept += 1;
                println!(
                    "{sequence:<24} {ssm:<12} kept {} (--force to overwrite)",
                    path.display()
                );
            }
            gt::FitOutcome::Written {
                sequence,
                ssm,
                frames,
                mean_residual,
                worst,
                path,
            } => println!(
                "{sequence:<24} {ssm:<12} {frames:>8} {mean_residual:>10.3} {:>10.3}  {} ({})",
                worst.1,
                worst.0 + 1,
                path.display()
            ),
        }
    }
    if kept > 0 {
        println!("{kept} file(s) kept");
    }
    Ok(())
}

/// `converge`: the trackers in parallel, a line each, then the files.
pub fn run_converge(
    seq: Option<&Path>,
    frame: usize,
    specs: &[TrackerSpec],
    c: &regtrack::converge::ConvergeSpec,
    out: &Path,
) -> Result<()> {
    use rayon::prelude::*;
    let seq = match seq {
        Some(p) => Sequence::open(p)?,
        None => load_demo(None)?,
    };
    let k = frame
        .checked_sub(1)
        .filter(|&k| k < seq.len())
        .with_context(|| format!("--frame must be 1..={}", seq.len()))?;
    let truth = seq
        .ground_truth(k)
        .with_context(|| format!("frame {frame} of {} has no ground truth", seq.name))?;
    // In colour when a tracker reads colour.
    let img = seq.load_frame(k, specs.iter().any(|s| s.reads_colour()))?;
    let curves: Vec<regtrack::converge::ConvergeCurve> = specs
        .par_iter()
        .map(|s| regtrack::converge::frequency_of_convergence(s, &img, &truth, c))
        .collect::<regtrack::Result<_>>()?;
    println!(
        "frequency of convergence on frame {frame} of {} ({} starts per sigma, within {} px)",
        seq.name, c.starts, c.threshold
    );
    let sigmas: Vec<String> = c.sigmas.iter().map(|s| format!("{s:>5}")).collect();
    println!("{:<28} {}   mean", "tracker \\ sigma", sigmas.join(" "));
    for curve in &curves {
        let f: Vec<String> = curve
            .points
            .iter()
            .map(|p| format!("{:>5.2}", p.1))
            .collect();
        println!("{:<28} {}  {:.3}", curve.tracker, f.join(" "), curve.mean());
    }
    let title = format!("Frequency of convergence: {}, frame {frame}", seq.name);
    for f in regtrack::converge::write_results(out, &curves, c, &title)? {
        println!("wrote {}", f.display());
    }
    Ok(())
}

pub fn run_bench(
    seq: Option<&Path>,
    specs: &[TrackerSpec],
    repeats: usize,
    frames: Option<usize>,
    json: Option<&Path>,
) -> Result<()> {
    let seq = match seq {
        Some(p) => Sequence::open(p)?,
        None => load_demo(None)?,
    };
    // In colour too when a tracker reads colour.
    let colour = specs.iter().any(|s| s.reads_colour());
    let loaded = bench::load_frames(&seq, frames, colour)?;
    println!(
        "{} frames of {}, {} repeats (medians); us/iter = an iteration's own time, other = the rest of a frame (pyramid, loss checks); tracker-only = search on pre-smoothed frames (read from memory; grey, which a colour tracker reads as three equal channels), live = from 8-bit frames, in colour for a colour tracker (the region the tracker smooths is in the cache when it searches)",
        loaded.frames.len(),
        seq.name,
        repeats
    );
    println!("kernels: {}", regtrack::cpu::kernels());
    println!("{}", bench::BenchRow::HEADER);
    let mut rows = Vec::new();
    for spec in specs {
        let r = bench::bench_tracker(spec, &loaded, repeats)?;
        println!("{}", r.line());
        rows.push(r);
    }
    if let Some(p) = json {
        dataset::write_atomic(p, serde_json::to_string_pretty(&rows)?.as_bytes())?;
    }
    Ok(())
}

pub fn run_demo(cache: Option<&Path>) -> Result<()> {
    let seq = load_demo(cache)?;
    println!(
        "demo sequence: {} frames ({})",
        seq.len(),
        seq.gt_path.as_deref().unwrap_or(Path::new("")).display()
    );
    let specs = tracker::product(
        &["iclk".into(), "fclk".into(), "esm".into()],
        &["ssd".into(), "zncc".into()],
        &["homography".into()],
        &[],
    )?;
    let pb = bar(specs.len(), "tracking");
    let sequences = [seq];
    let outcome = Batch {
        jobs: 1,
        ..Batch::new(&sequences, &specs)
    }
    .run(&|f| pb.set_position(f.done as u64))?;
    pb.finish_and_clear();
    if let Some(e) = outcome.failures.first() {
        bail!("{e}");
    }
    print!("{}", eval::summary_table(&outcome.rows()));
    Ok(())
}
