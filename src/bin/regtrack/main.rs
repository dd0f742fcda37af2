//! The `regtrack` command: parses the command line and starts the library's work. Everything a
//! command does is in the library (the batch in [`regtrack::eval::Batch`], the specs in
//! [`regtrack::tracker`], the listing in [`regtrack::catalogue`]); here are the flags, the
//! progress bars and what is printed.

mod args;

use anyhow::{Context as _, Result, bail};
use args::{Command, SynthArgs, TrackerArgs};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use regtrack::dataset::{self, Sequence, demo, synth};
use regtrack::eval::{self, Batch, EvalOptions};
use regtrack::geometry::Quad;
use regtrack::observe::NoObserver;
use regtrack::tracker::{self, TrackerSpec};
use regtrack::{bench, gt};
use std::path::{Path, PathBuf};

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
            let run = regtrack::patches::read_tracks(&tracks)?;
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
            let specs = select.specs(regtrack::spec::DEFAULT_TRACKER)?;
            let sequences = dataset::discover(&dataset, seqs.as_deref())?;
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
        Command::Merge { out, shards } => {
            let rows = eval::merge_shards(&shards, &out)?;
            print!("{}", eval::summary_table(&rows));
            println!("wrote {}", out.join("summary.csv").display());
            Ok(())
        }
        Command::Report { dirs, out } => {
            let out =
                out.unwrap_or_else(|| dirs.first().cloned().unwrap_or_default().join("report"));
            let report = regtrack::report::write_report(&dirs, &out)?;
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

/// `converge`: the trackers in parallel, a line each, then the files.
fn run_converge(
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
    let img = seq.load_gray(k)?;
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

fn run_demo(cache: Option<&Path>) -> Result<()> {
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
    .run(&|d, _| pb.set_position(d as u64))?;
    pb.finish_and_clear();
    if let Some(e) = outcome.failures.first() {
        bail!("{e}");
    }
    print!("{}", eval::summary_table(&outcome.rows()));
    Ok(())
}

/// The tracker `--tracker` or `--sm/--am/--ssm` name, with its parameters set.
fn spec_of(t: &TrackerArgs) -> Result<TrackerSpec> {
    let mut spec = match &t.tracker {
        Some(name) => TrackerSpec::whole(name)?,
        None => TrackerSpec::from_names(&t.sm, &t.am, &t.ssm)?,
    };
    tracker::set_params(std::slice::from_mut(&mut spec), &t.params.assignments)?;
    Ok(spec)
}

/// `WxH`, e.g. `640x480`.
fn parse_size(s: &str) -> Result<(usize, usize)> {
    dataset::live::parse_size(s)
        .with_context(|| format!("--size must be WxH, e.g. 640x480, got '{s}'"))
}

/// A run's corners by frame index (`None` where lost or not tracked), for the first `n` frames.
fn by_frame(run: &eval::RunResult, n: usize) -> Vec<Option<Quad>> {
    let mut out = vec![None; n];
    for f in &run.frames {
        if let Some(slot) = out.get_mut(f.frame) {
            *slot = f.corners;
        }
    }
    out
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

fn run_track(
    seq: &Path,
    t: &TrackerArgs,
    init: Option<Quad>,
    out: &Path,
    render: Option<&Path>,
) -> Result<()> {
    let seq = Sequence::open(seq)?;
    warn_about(std::slice::from_ref(&seq));
    let spec = spec_of(t)?;
    // One run: a second core (if any) decodes the frames ahead.
    let spare = std::thread::available_parallelism().is_ok_and(|n| n.get() > 1);
    let options = EvalOptions::default();
    let run = eval::run_sequence_reading(&seq, &spec, &options, init, &mut NoObserver, spare)?;
    let corners: Vec<_> = run.frames.iter().map(|f| f.corners).collect();
    dataset::write_corners(out, &corners, "jpg")?;
    let lost = run.frames.iter().filter(|f| f.corners.is_none()).count();
    println!(
        "wrote {} ({} of {} frames, {} lost)",
        out.display(),
        run.frames.len(),
        seq.len(),
        lost
    );
    if !seq.ground_truth.is_empty() {
        print!("{}", eval::summary_table(&[run.summary()]));
    }
    if let Some(video) = render {
        dataset::video::render(&seq, &by_frame(&run, run.frames.len()), video)?;
        println!("wrote {}", video.display());
    }
    if let Some(e) = &run.error {
        bail!(
            "the run {e}; the frames tracked before it are in {}",
            out.display()
        );
    }
    Ok(())
}

/// `track --patches N` / `--points FILE`: the many-patch mode over a sequence.
fn run_patches(
    seq: &Path,
    n: Option<usize>,
    points: Option<&Path>,
    assignments: &[String],
    out: &Path,
) -> Result<()> {
    use regtrack::patches::{self, PatchParams, PatchSeeds};
    let seq = Sequence::open(seq)?;
    warn_about(std::slice::from_ref(&seq));
    let pairs = assignments
        .iter()
        .map(|a| regtrack::params::split_assignment(a).map(|(k, v)| (k.to_string(), v.to_string())))
        .collect::<regtrack::error::Result<Vec<_>>>()?;
    let params = PatchParams::parse(&pairs)?;
    let seeds = match points {
        Some(p) => PatchSeeds::Points(patches::read_points(p)?),
        None => PatchSeeds::Corners(n.unwrap_or(1000)),
    };
    let pb = bar(seq.len(), "frames");
    let run = patches::track_sequence(&seq, &params, &seeds, &mut |_| pb.inc(1))?;
    pb.finish_and_clear();
    patches::write_tracks(out, &run)?;
    let last = run
        .frames
        .last()
        .map_or(0, |f| f.iter().filter(|s| s.tracking()).count());
    println!(
        "wrote {} ({} patches x {} frames; {} tracked at the last frame)",
        out.display(),
        run.patches(),
        run.frames.len(),
        last
    );
    println!(
        "speed: {:.0} patch updates/s, {:.1} frames/s (median; tracking only, {} thread{}); \
         {:.1} iterations per update",
        run.updates_per_second(),
        run.frames_per_second(),
        if params.threads == 0 {
            "all".to_string()
        } else {
            params.threads.to_string()
        },
        if params.threads == 1 { "" } else { "s" },
        run.iterations_per_update()
    );
    if let Some((mean, median)) = run.forward_backward_errors() {
        println!("forward-backward error: mean {mean:.3} px, median {median:.3} px");
    }
    if let Some(a) = patches::accuracy(&run, &seq) {
        print_patch_accuracy(&a);
    }
    Ok(())
}

fn print_patch_accuracy(a: &regtrack::patches::PatchAccuracy) {
    println!(
        "accuracy: {} patches on the target; error to the ground truth mean {:.3} px, median \
         {:.3} px; {:.1} % of patch-frames tracked; at the last frame {} tracked, {} within 2 px",
        a.patches,
        a.mean_error,
        a.median_error,
        100.0 * a.tracked_fraction,
        a.tracked_at_end,
        a.within_2px_at_end
    );
}

/// `track --camera`: frames as they come, the newest each time (those that came meanwhile are
/// dropped and counted), until `frames` or the camera stops; optionally recorded as a sequence.
fn run_live(
    camera: &str,
    size: &str,
    frames: Option<usize>,
    record: Option<&Path>,
    t: &TrackerArgs,
    init: Quad,
    out: &Path,
) -> Result<()> {
    let (w, h) = parse_size(size)?;
    let spec = spec_of(t)?;
    let mut tracker = tracker::Tracker::new(&spec)?;
    let mut live = dataset::live::Live::open(camera, w, h)?;
    // Written as it happens: a run that ends in any way leaves a sequence up to its last frame.
    let mut recording = record
        .map(|d| dataset::live::Recording::create(d, "live"))
        .transpose()?;
    let mut corners = Vec::new();
    let (mut dropped, mut lost) = (0u64, 0usize);
    let started = std::time::Instant::now();
    let mut stopped = None;
    while frames.is_none_or(|n| corners.len() < n) {
        let f = match live.newest() {
            Ok(f) => f,
            Err(e) => {
                stopped = Some(e);
                break;
            }
        };
        let input = regtrack::tracker::FrameInput::Gray8(&f.image);
        let q = if corners.is_empty() {
            tracker.initialize(input, &init)?;
            Some(init)
        } else {
            dropped += f.dropped;
            let o = tracker.update(input, &mut NoObserver);
            (o.status == regtrack::tracker::TrackStatus::Tracking).then_some(o.corners)
        };
        lost += q.is_none() as usize;
        if let Some(r) = &mut recording {
            r.push(&f.image, q.as_ref())?;
        }
        corners.push(q);
    }
    let secs = started.elapsed().as_secs_f64();
    dataset::write_corners(out, &corners, "jpg")?;
    println!(
        "{camera}: {} frames tracked in {secs:.1} s ({:.1} fps), {dropped} dropped, {lost} lost; \
         wrote {}",
        corners.len(),
        corners.len() as f64 / secs.max(1e-9),
        out.display()
    );
    if let Some(r) = &recording {
        println!(
            "recorded {} frames as a sequence: {}",
            r.frames(),
            r.path().display()
        );
    }
    match stopped {
        // Asked for more frames than came: the camera went away (what was tracked is kept).
        Some(e) if corners.is_empty() || frames.is_some() => Err(anyhow::anyhow!(
            "{e} (frame {}); the frames tracked before it are in {}",
            corners.len() + 1,
            out.display()
        )),
        Some(e) => {
            println!("{e}");
            Ok(())
        }
        None => Ok(()),
    }
}

fn run_gt_fit(root: &Path, seqs: Option<Vec<String>>, ssms: &[String], force: bool) -> Result<()> {
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

fn run_eval(batch: &Batch, out: &Path, render: bool) -> Result<()> {
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
    let outcome = batch.execute(plan, &|d, _| pb.set_position(d as u64))?;
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

fn run_synth(a: SynthArgs) -> Result<()> {
    let size = a.size.as_deref().map(parse_size).transpose()?;
    let cfg = synth::SynthConfig {
        texture: a.texture,
        background: a.background,
        motion: a.motion,
        size,
        max_frames: a.frames,
        step: a.step,
        supersample: a.supersample,
        noise: a.noise,
        gain_drift: a.gain_drift,
        bias_drift: a.bias_drift,
        local_light: a.local_light,
        motion_blur: a.motion_blur,
        occlusion: a.occlusion,
        jpeg_quality: a.jpeg_quality,
        seed: a.seed,
    };
    let pb = bar(0, "rendering");
    let seq = synth::render_sequence(&cfg, &a.out, &a.name, &|d, t| {
        pb.set_length(t as u64);
        pb.set_position(d as u64);
    })?;
    pb.finish_and_clear();
    println!(
        "wrote {} frames: {}",
        seq.len(),
        seq.gt_path.as_deref().unwrap_or(Path::new("")).display()
    );
    Ok(())
}

fn run_bench(
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
    let loaded = bench::load_frames(&seq, frames)?;
    println!(
        "{} frames of {}, {} repeats (medians); us/iter = an iteration's own time, other = the rest of a frame (pyramid, loss checks); tracker-only = search on pre-smoothed frames (read from memory), live = from 8-bit frames (the region the tracker smooths is in the cache when it searches)",
        loaded.gray.len(),
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
