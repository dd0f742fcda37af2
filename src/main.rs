//! The `regtrack` command: parses the command line and starts the library's work.

use anyhow::{Context as _, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use regtrack::dataset::{self, Sequence, demo, synth};
use regtrack::eval::{self, EvalOptions, Summary};
use regtrack::geometry::Quad;
use regtrack::observe::NoObserver;
use regtrack::tracker::TrackerSpec;
use regtrack::{am, bench, sm, ssm};
use std::path::{Path, PathBuf};

/// `regtrack inspect --help`: the keyboard shortcuts (the same table as the help overlay, F1).
const INSPECT_KEYS: &str = "Keyboard (F1 or ? in the window shows this too):
  Space                           play / pause
  Right / Left                    next frame (tracks it if needed) / previous frame
  Home / End                      start frame / last tracked frame
  Ctrl+O / Ctrl+S                 open a sequence / save the session
  F2 / F3                         hide or show the trackers / plots panel
  Ctrl+Z / Ctrl+Shift+Z           undo / redo a ground-truth correction
  ground-truth mode: 1-4, 0       pick a corner, the whole quad
  ground-truth mode: arrows, +/-  nudge by the step, double / halve the step
  ground-truth mode: N / P, J, O  next / previous frame, worst frame, mark occluded
  ground-truth mode: Enter / Esc  accept / reject a propagation's proposal";

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

#[derive(Subcommand)]
enum Command {
    /// The interactive inspector (the default).
    #[command(after_help = INSPECT_KEYS)]
    Inspect {
        /// A saved session (sessions/*.toml).
        #[arg(long)]
        session: Option<PathBuf>,
        /// A sequence to open instead of the session's.
        #[arg(long)]
        seq: Option<PathBuf>,
        /// With --screenshot: frames to track first.
        #[arg(long, default_value_t = 30)]
        frames: usize,
        /// Track, save a screenshot of the whole window to this PNG, and exit.
        #[arg(long)]
        screenshot: Option<PathBuf>,
    },
    /// Render the bundled demo sequence (once) and compare ICLK, FCLK and ESM with SSD and ZNCC.
    Demo {
        /// Where the demo sequence is rendered (default: the user cache folder).
        #[arg(long)]
        cache: Option<PathBuf>,
    },
    /// Track one sequence and write the corners in the MTF format.
    Track {
        /// A ground-truth file (MTF `<seq>.txt`, POT `_gt_points.txt`) or a folder of images.
        #[arg(long)]
        seq: PathBuf,
        #[command(flatten)]
        tracker: TrackerArgs,
        /// Initial corners `ulx,uly,urx,ury,lrx,lry,llx,lly` (default: the first ground truth).
        #[arg(
            long,
            value_delimiter = ',',
            num_args = 8,
            allow_negative_numbers = true
        )]
        init: Option<Vec<f64>>,
        /// Output corners file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Evaluate every (sequence, SM, AM, SSM) of a dataset in the MTF layout.
    Eval {
        /// Dataset root: `<root>/<seq>.txt` with frames in `<root>/<seq>/`.
        #[arg(long)]
        dataset: PathBuf,
        /// Sequences (default: all).
        #[arg(long, value_delimiter = ',')]
        seqs: Option<Vec<String>>,
        /// Search methods [default: esm; none when only --tracker is given].
        #[arg(long, value_delimiter = ',')]
        sm: Option<Vec<String>>,
        /// Appearance models [default: ssd].
        #[arg(long, value_delimiter = ',')]
        am: Option<Vec<String>>,
        /// State space models [default: homography].
        #[arg(long, value_delimiter = ',')]
        ssm: Option<Vec<String>>,
        /// Whole trackers (kcf, dsst, rct, tld, cmt), evaluated beside the registration trackers
        /// (alone when no --sm, --am or --ssm is given).
        #[arg(long, value_delimiter = ',')]
        tracker: Vec<String>,
        #[command(flatten)]
        params: ParamArgs,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Parallel runs (0 = all cores; 1 for clean timings).
        #[arg(long, default_value_t = 0)]
        jobs: usize,
        /// Only the runs `k, k + n, k + 2n, ...` of the product, as `k/n` (for Slurm arrays or
        /// GNU parallel: one shard per task, each with its own --out).
        #[arg(long)]
        shard: Option<String>,
        /// Re-initialise from the ground truth 5 frames after a failure.
        #[arg(long)]
        reinit: bool,
        /// Score against the low-DOF ground truth of this SSM, as the paper does (read from
        /// `<root>/OptGT/<seq>_<ssm>.txt` when it exists, fitted otherwise: see `gt-fit`);
        /// `own`: each tracker against its own SSM's.
        #[arg(long)]
        gt_ssm: Option<String>,
        /// Error type of the success rates: alignment (mean corner distance, E_AL), center
        /// (centre location error) or jaccard (1 - IoU, SR over 0..1).
        #[arg(long, default_value = "alignment")]
        error: String,
        /// Run everything again, even the runs a previous (killed) batch in --out finished.
        #[arg(long)]
        no_resume: bool,
    },
    /// Low-DOF ground truth (the paper's protocol): per sequence and SSM, the warp of the first
    /// frame's quad with the least alignment error to each frame's 8-DOF ground truth, written
    /// in MTF's OptGT layout (`<root>/OptGT/<seq>_<ssm>.txt`) with the residual per frame beside
    /// it (`<seq>_<ssm>_residuals.txt`).
    GtFit {
        /// Dataset root in the MTF layout, or one sequence (ground-truth file or folder).
        #[arg(long)]
        dataset: PathBuf,
        /// Sequences (default: all).
        #[arg(long, value_delimiter = ',')]
        seqs: Option<Vec<String>>,
        /// State space models.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "translation,isometry,similitude,affine"
        )]
        ssm: Vec<String>,
        /// Overwrite OptGT files that exist (they may hold corrections exported by the inspector).
        #[arg(long)]
        force: bool,
    },
    /// Merge the outputs of `eval --shard` runs into one summary (with `ALL` rows pooled over
    /// every sequence).
    Merge {
        /// Output folder for summary.csv and summary.json.
        #[arg(long)]
        out: PathBuf,
        /// The shards' output folders.
        #[arg(required = true)]
        shards: Vec<PathBuf>,
    },
    /// Success-rate and speed figures (PNG, SVG) and a markdown table (`report.md`) of `eval`
    /// output folders, each tracker pooled over every sequence (shards: give all their folders).
    Report {
        /// `eval` output folders.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Output folder (default: `report` in the first folder).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// List every appearance model, state space model and search method with its aliases.
    List,
    /// Render a synthetic sequence with exact ground truth (MTF layout).
    Synth(SynthArgs),
    /// Speed per tracker on the demo sequence (or --seq): iterations per frame, us per iteration,
    /// tracker-only and live-path FPS (medians over repeats).
    Bench {
        /// Sequence (default: the demo).
        #[arg(long)]
        seq: Option<PathBuf>,
        /// Search methods [default: iclk,fclk,esm; none when only --tracker is given].
        #[arg(long, value_delimiter = ',')]
        sm: Option<Vec<String>>,
        /// Appearance models [default: ssd,zncc].
        #[arg(long, value_delimiter = ',')]
        am: Option<Vec<String>>,
        /// State space models [default: homography].
        #[arg(long, value_delimiter = ',')]
        ssm: Option<Vec<String>>,
        /// Whole trackers (kcf, dsst, rct, tld, cmt), benchmarked beside the registration
        /// trackers (alone when no --sm, --am or --ssm is given).
        #[arg(long, value_delimiter = ',')]
        tracker: Vec<String>,
        #[command(flatten)]
        params: ParamArgs,
        /// Repeats (the median is reported).
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Use only the first frames.
        #[arg(long)]
        frames: Option<usize>,
        /// Also write the rows as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

#[derive(Args)]
struct TrackerArgs {
    /// A whole tracker (instead of --sm/--am/--ssm).
    #[arg(long)]
    tracker: Option<String>,
    /// Search method: a name, an alias, or a composite `cascade:nn+iclk`, `parallel:esm+fclk`.
    #[arg(long, default_value = "esm")]
    sm: String,
    #[arg(long, default_value = "ssd")]
    am: String,
    #[arg(long, default_value = "homography")]
    ssm: String,
    #[command(flatten)]
    params: ParamArgs,
}

/// Tracker parameters. Each flag is a shortcut for `--param NAME=VALUE`; ranges and defaults are
/// those of `regtrack list` (one definition for the command line, the inspector and sessions).
#[derive(Args, Clone, Default)]
struct ParamArgs {
    /// Sampling resolution (res x res points; default 50).
    #[arg(long)]
    res: Option<String>,
    /// Maximum iterations per frame (default 30).
    #[arg(long)]
    max_iters: Option<String>,
    /// Stop when the corners move less than this (L2 norm, px; default 0.001).
    #[arg(long)]
    eps: Option<String>,
    /// Gaussian pre-smoothing standard deviation (px; default 3).
    #[arg(long)]
    sigma: Option<String>,
    /// Gaussian pre-smoothing kernel size (default 5; 1 = none).
    #[arg(long)]
    blur: Option<String>,
    /// Coarse-to-fine pyramid levels (default 1 = none).
    #[arg(long)]
    levels: Option<String>,
    /// Hessian: default, gauss_newton, newton, after_convergence.
    #[arg(long)]
    hessian: Option<String>,
    /// Margin of the pre-processed region around the target, in target sizes (default 0.25).
    #[arg(long)]
    roi_margin: Option<String>,
    /// Seed of the sampling search methods (NN, PF; default 0).
    #[arg(long)]
    seed: Option<String>,
    /// Any tracker or search-method parameter as NAME=VALUE, repeatable (e.g. `--param
    /// samples=5000 --param sigma=0.03`); `regtrack list` lists them.
    #[arg(long = "param", value_name = "NAME=VALUE")]
    param: Vec<String>,
}

impl ParamArgs {
    /// Sets every given parameter on `spec` (checked against its definition).
    /// Every assignment given (the flags, then `--param`), in order.
    fn assignments(&self) -> Result<Vec<(String, String)>> {
        let flags = [
            ("res", &self.res),
            ("max_iters", &self.max_iters),
            ("eps", &self.eps),
            ("blur_sigma", &self.sigma),
            ("blur_size", &self.blur),
            ("pyramid_levels", &self.levels),
            ("hessian", &self.hessian),
            ("roi_margin", &self.roi_margin),
            ("seed", &self.seed),
        ];
        let mut out: Vec<(String, String)> = flags
            .iter()
            .filter_map(|(n, v)| v.as_ref().map(|v| (n.to_string(), v.clone())))
            .collect();
        for a in &self.param {
            let (name, v) = regtrack::params::split_assignment(a)?;
            out.push((name.to_string(), v.to_string()));
        }
        Ok(out)
    }

    /// Sets every parameter on `spec` (an unknown one is an error naming the known ones).
    fn apply(&self, spec: &mut TrackerSpec) -> Result<()> {
        for (name, v) in self.assignments()? {
            spec.set_param(&name, &v)?;
        }
        spec.check()?;
        Ok(())
    }

    /// Sets each parameter on the trackers that have it (`--seed` reaches the sampling search
    /// methods and the whole trackers that draw random numbers, `--res` only the registration
    /// trackers); a parameter none of them has is an error.
    fn apply_all(&self, specs: &mut [TrackerSpec]) -> Result<()> {
        for (name, v) in self.assignments()? {
            let mut taken = false;
            for spec in specs.iter_mut() {
                let has = spec.params().is_some()
                    && regtrack::tracker::TrackerParams::def(&name).is_some()
                    || spec.method_defs()?.iter().any(|d| d.name == name);
                if has {
                    spec.set_param(&name, &v)?;
                    taken = true;
                }
            }
            if !taken && let Some(first) = specs.first_mut() {
                // The error lists what the first tracker has.
                first.set_param(&name, &v)?;
            }
        }
        for spec in specs.iter() {
            spec.check()?;
        }
        Ok(())
    }
}

/// The registration trackers' method lists: each as given, or its default; none at all when
/// only whole trackers are asked for (`--tracker` without `--sm`, `--am` or `--ssm`).
fn registration_lists(
    sm: Option<Vec<String>>,
    am: Option<Vec<String>>,
    ssm: Option<Vec<String>>,
    whole: &[String],
    defaults: [&str; 3],
) -> [Vec<String>; 3] {
    if sm.is_none() && am.is_none() && ssm.is_none() && !whole.is_empty() {
        return [Vec::new(), Vec::new(), Vec::new()];
    }
    let list = |v: Option<Vec<String>>, d: &str| {
        v.unwrap_or_else(|| d.split(',').map(str::to_string).collect())
    };
    [
        list(sm, defaults[0]),
        list(am, defaults[1]),
        list(ssm, defaults[2]),
    ]
}

#[derive(Args)]
struct SynthArgs {
    /// Texture rendered into the target quad.
    #[arg(long)]
    texture: PathBuf,
    /// Background image (default: mid-gray).
    #[arg(long)]
    background: Option<PathBuf>,
    /// Motion profile (four corners per frame, TMT/MTF format).
    #[arg(long)]
    motion: PathBuf,
    /// Output root: writes `<out>/<name>.txt` and `<out>/<name>/`.
    #[arg(long)]
    out: PathBuf,
    /// Sequence name.
    #[arg(long)]
    name: String,
    /// Frame size `WxH` (default: the smallest common size holding the motion).
    #[arg(long)]
    size: Option<String>,
    /// Use only the first frames.
    #[arg(long)]
    frames: Option<usize>,
    /// Take every k-th frame of the profile (k times faster motion).
    #[arg(long, default_value_t = 1)]
    step: usize,
    /// Supersampling per axis.
    #[arg(long, default_value_t = 3)]
    supersample: usize,
    /// Gaussian noise (gray levels).
    #[arg(long, default_value_t = 0.0)]
    noise: f32,
    /// Global gain drift amplitude (0.2 = +-20%).
    #[arg(long, default_value_t = 0.0)]
    gain_drift: f32,
    /// Global bias drift amplitude (gray levels).
    #[arg(long, default_value_t = 0.0)]
    bias_drift: f32,
    /// Moving local light amplitude (0.5 = +50% at its centre).
    #[arg(long, default_value_t = 0.0)]
    local_light: f32,
    /// Motion blur sub-frames (0 = none).
    #[arg(long, default_value_t = 0)]
    motion_blur: usize,
    /// Occluder size as a fraction of the target (0 = none).
    #[arg(long, default_value_t = 0.0)]
    occlusion: f32,
    /// JPEG quality (0 = PNG frames).
    #[arg(long, default_value_t = 95)]
    jpeg_quality: u8,
    /// Seed of the random nuisances.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    let command = cli.command.unwrap_or(Command::Inspect {
        session: None,
        seq: None,
        frames: 30,
        screenshot: None,
    });
    match command {
        Command::Inspect {
            session,
            seq,
            frames,
            screenshot,
        } => run_inspector(session, seq, frames, screenshot),
        Command::Demo { cache } => run_demo(cache.as_deref()),
        Command::Track {
            seq,
            tracker,
            init,
            out,
        } => run_track(&seq, &tracker, init, &out),
        Command::Eval {
            dataset,
            seqs,
            sm,
            am,
            ssm,
            tracker,
            params,
            out,
            jobs,
            shard,
            reinit,
            gt_ssm,
            error,
            no_resume,
        } => {
            let [sm, am, ssm] =
                registration_lists(sm, am, ssm, &tracker, ["esm", "ssd", "homography"]);
            run_eval(
                &dataset,
                seqs,
                &sm,
                &am,
                &ssm,
                &tracker,
                &params,
                &out,
                jobs,
                shard.as_deref(),
                EvalOptions {
                    reinit,
                    gt_ssm,
                    error: eval::ErrorKind::parse(&error)?,
                    ..EvalOptions::default()
                },
                !no_resume,
            )
        }
        Command::GtFit {
            dataset,
            seqs,
            ssm,
            force,
        } => run_gt_fit(&dataset, seqs, &ssm, force),
        Command::Merge { out, shards } => {
            let rows = eval::merge_shards(&shards, &out)?;
            print_table(&rows);
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
            print_list();
            Ok(())
        }
        Command::Synth(args) => run_synth(args),
        Command::Bench {
            seq,
            sm,
            am,
            ssm,
            tracker,
            params,
            repeats,
            frames,
            json,
        } => {
            let [sm, am, ssm] = registration_lists(
                sm,
                am,
                ssm,
                &tracker,
                ["iclk,fclk,esm", "ssd,zncc", "homography"],
            );
            run_bench(
                seq.as_deref(),
                &sm,
                &am,
                &ssm,
                &tracker,
                &params,
                repeats,
                frames,
                json.as_deref(),
            )
        }
    }
}

#[cfg(feature = "gui")]
fn run_inspector(
    session: Option<PathBuf>,
    seq: Option<PathBuf>,
    frames: usize,
    screenshot: Option<PathBuf>,
) -> Result<()> {
    let shot = screenshot.clone();
    let summary = regtrack::app::run(regtrack::app::RunOptions {
        session,
        sequence: seq,
        screenshot: screenshot.map(|p| (frames, p)),
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

/// Every registration tracker of the product `sms x ams x ssms`, then the whole trackers, with the
/// given parameters.
fn specs(
    sms: &[String],
    ams: &[String],
    ssms: &[String],
    whole: &[String],
    params: &ParamArgs,
) -> Result<Vec<TrackerSpec>> {
    let mut out = Vec::new();
    for s in sms {
        for a in ams {
            for m in ssms {
                out.push(TrackerSpec::from_names(s, a, m)?);
            }
        }
    }
    for t in whole {
        out.push(TrackerSpec::whole(t)?);
    }
    params.apply_all(&mut out)?;
    Ok(out)
}

fn print_table(rows: &[Summary]) {
    println!(
        "{:<12} {:<22} {:>6} {:>6} {:>6} {:>8} {:>5} {:>6} {:>11} {:>9}",
        "sequence",
        "tracker",
        "frames",
        "SR@5",
        "SR@20",
        "mean err",
        "fail",
        "it/fr",
        "tracker FPS",
        "live FPS"
    );
    for r in rows {
        println!(
            "{:<12} {:<22} {:>6} {:>6.3} {:>6.3} {:>8.3} {:>5} {:>6.2} {:>11.0} {:>9.0}",
            r.sequence,
            r.tracker,
            r.frames,
            r.sr5,
            r.sr20,
            r.mean_error,
            r.failures,
            r.iterations_per_frame,
            r.tracker_fps,
            r.live_fps
        );
    }
}

fn run_demo(cache: Option<&Path>) -> Result<()> {
    let seq = load_demo(cache)?;
    println!(
        "demo sequence: {} frames ({})",
        seq.len(),
        seq.gt_path.as_deref().unwrap_or(Path::new("")).display()
    );
    let specs = specs(
        &["iclk".into(), "fclk".into(), "esm".into()],
        &["ssd".into(), "zncc".into()],
        &["homography".into()],
        &[],
        &ParamArgs::default(),
    )?;
    let pb = bar(specs.len(), "tracking");
    let results = eval::run_batch(
        std::slice::from_ref(&seq),
        &specs,
        &EvalOptions::default(),
        1,
        &|d, _| pb.set_position(d as u64),
    )?;
    pb.finish_and_clear();
    let rows = results
        .into_iter()
        .map(|r| r.map(|r| r.summary()))
        .collect::<Result<Vec<_>, _>>()?;
    print_table(&rows);
    Ok(())
}

fn run_track(seq: &Path, t: &TrackerArgs, init: Option<Vec<f64>>, out: &Path) -> Result<()> {
    let seq = Sequence::open(seq)?;
    let mut spec = match &t.tracker {
        Some(name) => TrackerSpec::whole(name)?,
        None => TrackerSpec::from_names(&t.sm, &t.am, &t.ssm)?,
    };
    t.params.apply(&mut spec)?;
    let init = match init {
        Some(v) => {
            let arr: [f64; 8] = v
                .try_into()
                .map_err(|_| anyhow::anyhow!("--init needs 8 numbers"))?;
            Some(Quad::from_array(arr))
        }
        None => None,
    };
    let run = eval::run_sequence(&seq, &spec, &EvalOptions::default(), init, &mut NoObserver)?;
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
        print_table(&[run.summary()]);
    }
    if let Some(e) = &run.error {
        bail!(
            "the run {e}; the frames tracked before it are in {}",
            out.display()
        );
    }
    Ok(())
}

fn run_gt_fit(root: &Path, seqs: Option<Vec<String>>, ssms: &[String], force: bool) -> Result<()> {
    // One sequence (a ground-truth file, or a folder that is not a dataset root), or a dataset.
    let single = root.is_file()
        || (root.is_dir() && seqs.is_none() && dataset::discover(root, None).is_err());
    let sequences = if single {
        vec![Sequence::open(root)?]
    } else {
        dataset::discover(root, seqs.as_deref())?
    };
    let mut skipped = 0;
    println!(
        "{:<24} {:<12} {:>8} {:>10} {:>10}  worst frame",
        "sequence", "ssm", "frames", "mean px", "max px"
    );
    for seq in &sequences {
        if seq.ground_truth.iter().all(Option::is_none) {
            bail!("sequence '{}' has no ground truth to fit", seq.name);
        }
        let dir = regtrack::gt::ground_truth_dir(seq);
        for name in ssms {
            let low = regtrack::gt::fit_ground_truth(name, &seq.ground_truth)?;
            let path = regtrack::gt::opt_gt_path(&dir, &seq.name, &low.ssm);
            if path.exists() && !force {
                println!(
                    "{:<24} {:<12} kept {} (--force to overwrite)",
                    seq.name,
                    low.ssm,
                    path.display()
                );
                skipped += 1;
                continue;
            }
            let (quads, _) = regtrack::gt::write_opt_gt(&dir, seq, &low, &[])?;
            let r: Vec<f64> = low.residuals.iter().flatten().copied().collect();
            let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
            let worst = low.worst_frames();
            let (wf, wr) = worst.first().copied().unwrap_or((0, 0.0));
            println!(
                "{:<24} {:<12} {:>8} {:>10.3} {:>10.3}  {} ({})",
                seq.name,
                low.ssm,
                r.len(),
                mean,
                wr,
                wf + 1,
                quads.display()
            );
        }
    }
    if skipped > 0 {
        println!("{skipped} file(s) kept");
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn run_eval(
    root: &Path,
    seqs: Option<Vec<String>>,
    sms: &[String],
    ams: &[String],
    ssms: &[String],
    whole: &[String],
    params: &ParamArgs,
    out: &Path,
    jobs: usize,
    shard: Option<&str>,
    mut opts: EvalOptions,
    resume: bool,
) -> Result<()> {
    let specs = specs(sms, ams, ssms, whole, params)?;
    let sequences = dataset::discover(root, seqs.as_deref())?;
    if let Some(g) = opts.gt_ssm.as_deref().filter(|g| *g != eval::OWN_SSM) {
        opts.gt_ssm = Some(regtrack::gt::ssm_key(g)?);
    }
    let pairs: Vec<(usize, usize)> = (0..sequences.len())
        .flat_map(|s| (0..specs.len()).map(move |p| (s, p)))
        .collect();
    let selected: Vec<(usize, usize)> = match shard {
        None => pairs,
        Some(s) => {
            let (k, n) = s.split_once('/').context("--shard must be k/n, e.g. 0/4")?;
            let (k, n): (usize, usize) = (k.trim().parse()?, n.trim().parse()?);
            if n == 0 || k >= n {
                bail!("--shard {s}: need 0 <= k < n");
            }
            pairs
                .into_iter()
                .enumerate()
                .filter(|(i, _)| i % n == k)
                .map(|(_, p)| p)
                .collect()
        }
    };
    // Resume: a run a previous batch finished with the same settings is read back, not redone
    // (its run file is written last and atomically, so it exists only for a complete run).
    let mut finished = Vec::new();
    let mut todo = Vec::new();
    for &(s, p) in &selected {
        match resume
            .then(|| eval::finished_run(out, &sequences[s].name, &specs[p], &opts))
            .flatten()
        {
            Some(r) => finished.push(r),
            None => todo.push((s, p)),
        }
    }
    if !finished.is_empty() {
        println!(
            "resuming: {} of {} runs already finished in {} (--no-resume to redo them)",
            finished.len(),
            selected.len(),
            out.display()
        );
    }
    let pb = bar(todo.len(), "evaluating");
    let done = std::sync::atomic::AtomicUsize::new(0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build()?;
    let mut failed = Vec::new();
    let runs: Vec<_> = pool.install(|| {
        use rayon::prelude::*;
        todo.par_iter()
            .map(|&(s, p)| {
                let r = eval::run_sequence(&sequences[s], &specs[p], &opts, None, &mut NoObserver)
                    .with_context(|| format!("{} on {}", specs[p].label(), sequences[s].name));
                // Each run's files are written as soon as it ends, so a killed batch keeps them.
                let r = r.and_then(|r| {
                    eval::write_run_files(out, &r)?;
                    Ok(r)
                });
                pb.set_position(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) as u64 + 1);
                r
            })
            .collect()
    });
    pb.finish_and_clear();
    // A run that fails (no ground truth to start from) or stops early (a frame that cannot be
    // read: what it tracked is kept) is reported; the others are still written.
    let mut all: Vec<_> = finished;
    for r in runs {
        match r {
            Ok(r) => {
                if let Some(e) = &r.error {
                    failed.push(format!("{} on {}: {e}", r.spec.label(), r.sequence));
                }
                all.push(r);
            }
            Err(e) => failed.push(format!("{e:#}")),
        }
    }
    let runs = all;
    let mut rows = Vec::new();
    for r in &runs {
        rows.push(r.summary());
    }
    // Pooled over all sequences of this output, per tracker.
    for spec in &specs {
        let mine: Vec<_> = runs
            .iter()
            .filter(|r| r.spec.label() == spec.label())
            .collect();
        if mine.len() > 1 {
            rows.push(eval::summarize("ALL", &mine));
        }
    }
    eval::write_summaries(out, &rows)?;
    print_table(&rows);
    println!("wrote {}", out.join("summary.csv").display());
    if !failed.is_empty() {
        bail!("{} run(s) failed:\n  {}", failed.len(), failed.join("\n  "));
    }
    Ok(())
}

fn print_list() {
    let row = |name: &str, al: &[&str], desc: &str| {
        println!("  {:<12} {:<22} {}", name, aliases(al), desc)
    };
    println!("appearance models (--am):");
    for e in am::REGISTRY {
        let c = e.build.default_model().capabilities();
        let mut tags = Vec::new();
        if !c.derivatives {
            tags.push("no gradient search");
        }
        if c.distance {
            tags.push("NN");
        }
        let tags = if tags.is_empty() {
            String::new()
        } else {
            format!(" [{}]", tags.join(", "))
        };
        row(e.name, e.aliases, &format!("{}{tags}", e.description));
        for d in e.build.params {
            println!("  {:<12}   --param {}", "", d.describe());
        }
    }
    println!("state space models (--ssm):");
    for e in ssm::REGISTRY {
        row(e.name, e.aliases, e.description);
    }
    println!(
        "search methods (--sm; composites: cascade:A+B+... stages in turn, parallel:A+B+... the most similar, lm:A Levenberg-Marquardt damping):"
    );
    for e in sm::REGISTRY {
        row(e.name, e.aliases, e.description);
        for d in e.build.params {
            println!("  {:<12}   --param {}", "", d.describe());
        }
    }
    println!("whole trackers (--tracker):");
    for e in regtrack::tracker::WHOLE_REGISTRY {
        row(e.name, e.aliases, e.description);
        for d in e.build.params {
            println!("  {:<12}   --param {}", "", d.describe());
        }
    }
    println!("tracker parameters (--param NAME=VALUE, or their flags):");
    for d in regtrack::tracker::TRACKER_PARAMS {
        println!("  {}", d.describe());
    }
}

fn aliases(a: &[&str]) -> String {
    if a.is_empty() {
        String::new()
    } else {
        format!("[{}]", a.join(", "))
    }
}

fn run_synth(a: SynthArgs) -> Result<()> {
    let size = match a.size {
        Some(s) => {
            let (w, h) = s
                .split_once(['x', 'X'])
                .context("--size must be WxH, e.g. 640x480")?;
            Some((w.trim().parse()?, h.trim().parse()?))
        }
        None => None,
    };
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

#[allow(clippy::too_many_arguments)]
fn run_bench(
    seq: Option<&Path>,
    sms: &[String],
    ams: &[String],
    ssms: &[String],
    whole: &[String],
    params: &ParamArgs,
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
        "{} frames of {}, {} repeats (medians); tracker-only = search on pre-smoothed frames, live = from 8-bit frames",
        loaded.gray.len(),
        seq.name,
        repeats
    );
    println!(
        "{:<26} {:>7} {:>8} {:>8} {:>12} {:>10} {:>9}",
        "tracker", "frames", "it/frame", "us/iter", "tracker FPS", "live FPS", "init ms"
    );
    let mut rows = Vec::new();
    for spec in specs(sms, ams, ssms, whole, params)? {
        let r = bench::bench_tracker(&spec, &loaded, repeats)?;
        println!(
            "{:<26} {:>7} {:>8.2} {:>8.1} {:>12.0} {:>10.0} {:>9.1}{}",
            r.tracker,
            r.frames,
            r.iterations_per_frame,
            r.us_per_iteration,
            r.tracker_fps,
            r.live_fps,
            r.init_ms,
            r.lost_at
                .map(|f| format!("  (lost at frame {f})"))
                .unwrap_or_default()
        );
        rows.push(r);
    }
    if let Some(p) = json {
        dataset::write_atomic(p, serde_json::to_string_pretty(&rows)?.as_bytes())?;
    }
    Ok(())
}
