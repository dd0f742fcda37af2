//! The `regtrack` command: parses the command line and starts the library's work. Everything a
//! command does is in the library (the batch in [`regtrack::eval::Batch`], the specs in
//! [`regtrack::tracker`], the live run in [`regtrack::dataset::live::LiveRun`], the listing in
//! [`regtrack::catalogue`]); here are the flags (`args.rs`), the progress bars and what is
//! printed, by command: `track.rs` (track, score-patches), `evaluate.rs` (eval, gt-fit,
//! converge, bench, demo), `data.rs` (synth).

mod args;
mod data;
mod evaluate;
mod track;

use anyhow::{Context as _, Result, bail};
use args::{Command, TrackerArgs};
use clap::Parser;
use data::run_synth;
use evaluate::{run_bench, run_converge, run_demo, run_eval, run_gt_fit};
use indicatif::{ProgressBar, ProgressStyle};
use regtrack::dataset::{self, Sequence, demo};
use regtrack::eval::{self, Batch, EvalOptions};
use regtrack::gt;
use regtrack::tracker::{self, TrackerSpec};
use std::path::{Path, PathBuf};
use track::{print_patch_accuracy, run_live, run_patches, run_track};

#[derive(Parser)]
#[command(
    name = "regtrack",
    version,
    about = "Modular registration-based visual trackers (AM x SSM x SM)"
)]
struct Cli {
    /// Without a subcommand: the inspector on the bundled demo.
    #[command(subcommand)]
    command: Option<Command>,
}

/// A user error is printed as one message (its causes joined), never with a backtrace, even
/// under `RUST_BACKTRACE`: backtraces are for panics, which are bugs.
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("Error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let cli = Cli::parse();
    let command = cli.command.unwrap_or(Command::Inspect {
        session: None,
        seq: None,
        frames: 30,
        screenshot: None,
        camera: None,
        size: "640x480".into(),
    });
    match command {
        Command::Inspect {
            session,
            seq,
            frames,
            screenshot,
            camera,
            size,
        } => {
            let camera = match camera {
                Some(c) => {
                    let (w, h) = parse_size(&size)?;
                    Some((c, w, h))
                }
                None => None,
            };
            run_inspector(session, seq, frames, screenshot, camera)
        }
        Command::Demo { cache } => run_demo(cache.as_deref()),
        Command::Track {
            seq,
            camera,
            size,
            frames,
            record,
            tracker,
            init,
            patches,
            points,
            patch_params,
            out,
            render,
        } => match (seq, camera) {
            (Some(seq), _) if patches.is_some() || points.is_some() || !patch_params.is_empty() => {
                run_patches(&seq, patches, points.as_deref(), &patch_params, &out)
            }
            (Some(seq), _) => run_track(&seq, &tracker, init.map(|c| c.0), &out, render.as_deref()),
            (None, Some(camera)) => run_live(
                &camera,
                &size,
                frames,
                record.as_deref(),
                &tracker,
                init.context("--camera needs --init")?.0,
                &out,
            ),
            (None, None) => bail!("give --seq or --camera"),
        },
        Command::ScorePatches { seq, tracks } => {
            let seq = Sequence::open(&seq)?;
            warn_about(std::slice::from_ref(&seq));
            let run = regtrack::patches::read_tracks(&tracks)?;
            // Every frame of the sequence from the first tracked one, no more, no fewer.
            let frames = run.frames.len();
            if frames == 0 {
                bail!("{}: no tracks in the file", tracks.display());
            }
            if run.first + frames != seq.len() {
                bail!(
                    "{}: tracks of {frames} frames from frame {}, but {} has {} frames: give \
                     the tracks of this sequence",
                    tracks.display(),
                    run.first + 1,
                    seq.name,
                    seq.len()
                );
            }
            match regtrack::patches::accuracy(&run, &seq) {
                Some(a) => {
                    print_patch_accuracy(&a);
                    Ok(())
                }
                None => bail!("{} has no ground truth on its first frame", seq.name),
            }
        }
        Command::Eval {
            dataset,
            seqs,
            select,
            out,
            jobs,
            shard,
            reinit,
            gt_ssm,
            error,
            no_resume,
            render,
        } => {
            let gt_ssm = match gt_ssm {
                Some(g) if g != eval::OWN_SSM => Some(gt::ssm_key(&g)?),
                g => g,
            };
            let options = EvalOptions {
                reinit,
                gt_ssm,
                error: eval::ErrorKind::parse(&error)?,
                ..EvalOptions::default()
            };
            let specs = select.default_specs()?;
            let sequences = dataset::open_or_discover(&dataset, seqs.as_deref())?;
            warn_about(&sequences);
            let batch = Batch {
                options,
                jobs,
                shard,
                out: Some(&out),
                resume: !no_resume,
                ..Batch::new(&sequences, &specs)
            };
            run_eval(&batch, &out, render)
        }
        Command::GtFit {
            dataset,
            seqs,
            ssm,
            force,
        } => run_gt_fit(&dataset, seqs, &ssm, force),
        Command::Merge {
            out,
            shards,
            partial,
        } => {
            let (rows, missing) = eval::merge_shards(&shards, &out, partial)?;
            print!("{}", eval::summary_table(&rows));
            if let Some(inc) = missing {
                println!(
                    "PARTIAL: {inc} (the pooled rows are `{}`; {} says so)",
                    eval::POOLED_PARTIAL,
                    out.join(eval::PARTIAL_FILE).display()
                );
            }
            println!("wrote {}", out.join("summary.csv").display());
            Ok(())
        }
        Command::Export { format, out, dirs } => {
            let format = eval::ResultsFormat::parse(&format)?;
            let runs = eval::read_all_runs(&dirs)?;
            if runs.is_empty() {
                bail!(
                    "no runs in {} (give the folders `eval --out` wrote)",
                    dirs.iter()
                        .map(|d| d.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
            let files = eval::write_results(&runs, format, &out)?;
            println!(
                "wrote {} files of {} runs under {}",
                files.len(),
                runs.len(),
                out.display()
            );
            Ok(())
        }
        Command::Report { dirs, out, partial } => {
            let out =
                out.unwrap_or_else(|| dirs.first().cloned().unwrap_or_default().join("report"));
            let report = regtrack::report::write_report(&dirs, &out, partial)?;
            println!(
                "wrote {} ({} trackers, {} figures)",
                out.join("report.md").display(),
                report.trackers.len(),
                report.figures.len() + 1
            );
            Ok(())
        }
        Command::List => {
            print!("{}", regtrack::catalogue::listing());
            Ok(())
        }
        Command::Synth(args) => run_synth(args),
        Command::Bench {
            seq,
            select,
            repeats,
            frames,
            json,
        } => {
            let specs = select.specs(["iclk,fclk,esm", "ssd,zncc", "homography"])?;
            run_bench(seq.as_deref(), &specs, repeats, frames, json.as_deref())
        }
        Command::Converge {
            seq,
            frame,
            select,
            sigmas,
            starts,
            threshold,
            start_seed,
            out,
        } => {
            let specs = select.specs(["iclk,fclk,falk,esm", "ssd", "homography"])?;
            let c = regtrack::converge::ConvergeSpec {
                sigmas,
                starts,
                threshold,
                seed: start_seed,
            };
            run_converge(seq.as_deref(), frame, &specs, &c, &out)
        }
    }
}

#[cfg(feature = "gui")]
fn run_inspector(
    session: Option<PathBuf>,
    seq: Option<PathBuf>,
    frames: usize,
    screenshot: Option<PathBuf>,
    camera: Option<(String, usize, usize)>,
) -> Result<()> {
    let shot = screenshot.clone();
    let summary = regtrack::app::run(regtrack::app::RunOptions {
        session,
        sequence: seq,
        screenshot: screenshot.map(|p| (frames, p)),
        camera,
    })
    .map_err(|e| anyhow::anyhow!("inspector: {e}"))?;
    if let (Some(p), Some(summary)) = (shot, summary) {
        println!("wrote {} ({summary})", p.display());
    }
    Ok(())
}

#[cfg(not(feature = "gui"))]
fn run_inspector(
    _: Option<PathBuf>,
    _: Option<PathBuf>,
    _: usize,
    _: Option<PathBuf>,
    _: Option<(String, usize, usize)>,
) -> Result<()> {
    bail!("this regtrack was built without the inspector (feature `gui`); see `regtrack --help`")
}

fn bar(len: usize, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len as u64);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed_precise}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

fn load_demo(cache: Option<&Path>) -> Result<Sequence> {
    let pb = bar(0, "rendering the demo sequence");
    let seq = demo::ensure_demo(cache, &|d, t| {
        pb.set_length(t as u64);
        pb.set_position(d as u64);
    })
    .context("cannot prepare the demo sequence")?;
    pb.finish_and_clear();
    Ok(seq)
}

/// The tracker `--tracker` or `--sm/--am/--ssm` name, with its parameters set.
fn spec_of(t: &TrackerArgs) -> Result<TrackerSpec> {
    let mut spec = match &t.tracker {
        Some(name) => TrackerSpec::whole(name)?,
        None => tracker::one(t.sm.as_deref(), t.am.as_deref(), &t.ssm)?,
    };
    tracker::set_params(std::slice::from_mut(&mut spec), &t.params.assignments)?;
    Ok(spec)
}

/// `WxH`, e.g. `640x480`.
fn parse_size(s: &str) -> Result<(usize, usize)> {
    dataset::live::parse_size(s)
        .with_context(|| format!("--size must be WxH, e.g. 640x480, got '{s}'"))
}

/// Prints what could be read around in the sequences' ground truth (a few lines each).
fn warn_about(sequences: &[Sequence]) {
    const SHOWN: usize = 5;
    for seq in sequences {
        for w in seq.warnings.iter().take(SHOWN) {
            eprintln!("warning: {w}");
        }
        if seq.warnings.len() > SHOWN {
            eprintln!(
                "warning: ... and {} more in the ground truth of {}",
                seq.warnings.len() - SHOWN,
                seq.name
            );
        }
    }
}
