//! The command line's flags: the subcommands and their arguments. Tracker parameters get a flag
//! each from their definitions ([`TRACKER_PARAMS`]), so that help, ranges and defaults are
//! written once.

use clap::{Arg, ArgAction, ArgMatches, Args, FromArgMatches, Subcommand};
use regtrack::Result;
use regtrack::eval;
use regtrack::spec::DEFAULT_TRACKER;
use regtrack::spec::{TRACKER_FLAGS, TRACKER_PARAMS};
use regtrack::tracker::{self, TrackerSpec};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Command {
    /// The interactive inspector (the default).
    #[command(after_help = regtrack::keys::help_text())]
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
        /// Open a live camera instead: `/dev/video0` (V4L2), or an FFmpeg test source
        /// `lavfi:testsrc=size=640x480:rate=30`; drag a box on the image to start a tracker.
        #[arg(long, conflicts_with = "seq")]
        camera: Option<String>,
        /// The camera's frame size, WxH.
        #[arg(long, default_value = "640x480", requires = "camera")]
        size: String,
    },
    /// Render the bundled demo sequence (once) and compare ICLK, FCLK and ESM with SSD and ZNCC.
    Demo {
        /// Where the demo sequence is rendered (default: the user cache folder).
        #[arg(long)]
        cache: Option<PathBuf>,
    },
    /// Track one sequence and write the corners in the MTF format.
    Track {
        /// A ground-truth file (MTF `<seq>.txt`, POT `_gt_points.txt`), a folder of images or a
        /// video file.
        #[arg(long, required_unless_present = "camera")]
        seq: Option<PathBuf>,
        /// A live camera instead: `/dev/video0` (V4L2), or an FFmpeg test source
        /// `lavfi:testsrc=size=320x240:rate=30`. Needs --init; frames arriving while the
        /// tracker works are dropped (and counted).
        #[arg(long, conflicts_with = "seq", requires = "init")]
        camera: Option<String>,
        /// The camera's frame size, WxH.
        #[arg(long, default_value = "640x480")]
        size: String,
        /// With --camera: stop after this many frames (default: until the camera stops).
        #[arg(long)]
        frames: Option<usize>,
        /// With --camera: record the frames and the tracked corners as a sequence in the MTF
        /// layout (`DIR/live.txt`, `DIR/live/`), to evaluate, correct and replay later.
        #[arg(long, requires = "camera")]
        record: Option<PathBuf>,
        #[command(flatten)]
        tracker: TrackerArgs,
        /// Initial corners `ulx,uly,urx,ury,lrx,lry,llx,lly` (default: the first ground truth).
        #[arg(
            long,
            value_name = "ULX,ULY,URX,URY,LRX,LRY,LLX,LLY",
            value_parser = parse_corners,
            allow_hyphen_values = true
        )]
        init: Option<Corners>,
        /// Track this many patches instead of one target (the many-patch mode): the strongest
        /// Shi-Tomasi corners of the first frame, inside its ground-truth quad when the sequence
        /// has one. --out is then a CSV of per-patch tracks.
        #[arg(long, conflicts_with_all = ["camera", "init", "render"])]
        patches: Option<usize>,
        /// The many-patch mode from these points of the first frame (a file of `x,y` lines).
        #[arg(long, conflicts_with_all = ["camera", "init", "render", "patches"])]
        points: Option<PathBuf>,
        /// A many-patch parameter, repeatable (e.g. --patch warp=affine --patch size=21);
        /// `regtrack list` lists them.
        #[arg(long = "patch", value_name = "NAME=VALUE")]
        patch_params: Vec<String>,
        /// Output corners file.
        #[arg(long)]
        out: PathBuf,
        /// Also write an annotated video (`out.mp4`, `.webm`, `.avi`...): the frames with the
        /// tracked quad (red) and the ground truth (green), encoded by FFmpeg.
        #[arg(long)]
        render: Option<PathBuf>,
    },
    /// Score a many-patch tracks file (`track --patches`, or another tracker's in its layout)
    /// against a sequence's ground truth.
    ScorePatches {
        /// The sequence (its ground truth carries each patch's first position).
        #[arg(long)]
        seq: PathBuf,
        /// The tracks: CSV `frame,patch,status,x,y,a00,a01,a10,a11,ncc`.
        #[arg(long)]
        tracks: PathBuf,
    },
    /// Evaluate every (sequence, SM, AM, SSM) of a dataset (MTF, POT, PlanarTrack, UCSB, VOT,
    /// GOT-10k, LaSOT layouts, detected from the folder: docs/benchmarks.md).
    Eval {
        /// Dataset root (MTF `<root>/<seq>.txt` with frames in `<root>/<seq>/`, or any layout
        /// of docs/benchmarks.md), or one sequence.
        #[arg(long)]
        dataset: PathBuf,
        /// Sequences (default: all).
        #[arg(long, value_delimiter = ',')]
        seqs: Option<Vec<String>>,
        // The trackers (default: regtrack::spec::DEFAULT_TRACKER).
        #[command(flatten)]
        select: SelectArgs,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Parallel runs (0 = all cores; 1 for clean timings).
        #[arg(long, default_value_t = 0)]
        jobs: usize,
        /// Only the runs `k, k + n, k + 2n, ...` of the product, as `k/n` (for Slurm arrays or
        /// GNU parallel: one shard per task, each with its own --out).
        #[arg(long)]
        shard: Option<eval::Shard>,
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
        /// Also write an annotated video of each run, `tracking_data/<seq>/<tracker>.mp4`: the
        /// frames with the tracked quad (red) and the ground truth (green), encoded by FFmpeg.
        #[arg(long)]
        render: bool,
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
        /// Merge an incomplete set (a shard or runs missing): the pooled rows are then
        /// `ALL-partial` and PARTIAL.txt says what is missing. Without it, refused.
        #[arg(long)]
        partial: bool,
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
        /// Report an incomplete set of shards, every figure and the table labelled partial.
        /// Without it, refused.
        #[arg(long)]
        partial: bool,
    },
    /// Write the runs of `eval` output folders as a benchmark's toolkit reads them
    /// (PlanarTrack/POT `<seq>_<tracker>.txt` and `_homography.txt`, VOT region files, GOT-10k
    /// and LaSOT boxes), so that its own evaluation runs on them.
    Export {
        /// The format: planartrack, pot, vot, got10k, lasot.
        #[arg(long)]
        format: String,
        /// Output folder (the tracker folders are made in it).
        #[arg(long)]
        out: PathBuf,
        /// `eval` output folders.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
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
        // The trackers (default: iclk,fclk,esm x ssd,zncc x homography).
        #[command(flatten)]
        select: SelectArgs,
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
    /// Frequency of convergence (Baker and Matthews' experiment): on one frame, each tracker
    /// started again and again from the ground truth moved by Gaussian noise of sigma px; the
    /// fraction that ends within --threshold px, per sigma. Writes convergence.csv, .svg, .png.
    Converge {
        /// Sequence (default: the demo).
        #[arg(long)]
        seq: Option<PathBuf>,
        /// The frame (1-based) whose ground truth is the target.
        #[arg(long, default_value_t = 1)]
        frame: usize,
        // The trackers (default: iclk,fclk,falk,esm x ssd x homography).
        #[command(flatten)]
        select: SelectArgs,
        /// The noise levels (px).
        #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6,7,8,9,10")]
        sigmas: Vec<f64>,
        /// Starts per noise level.
        #[arg(long, default_value_t = 100)]
        starts: usize,
        /// A start converged when its search ends this close (px, alignment error).
        #[arg(long, default_value_t = 1.0)]
        threshold: f64,
        /// Seed of the perturbations (the same starts for every tracker; `--seed` is the
        /// trackers' own, for NN and PF).
        #[arg(long, default_value_t = 0)]
        start_seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Args)]
pub struct TrackerArgs {
    /// A whole tracker (instead of --sm/--am/--ssm).
    #[arg(long, conflicts_with_all = ["sm", "am", "ssm"])]
    pub tracker: Option<String>,
    /// Search method: a name, an alias, or a composite `cascade:nn+iclk`, `parallel:esm+fclk`
    /// [default: the default tracker, FCLK-SSD with the second hypothesis `second=fclk_zncc`
    /// and `escalate=on`, when neither --sm nor --am is given; `--sm fclk --am ssd` is the plain combination].
    #[arg(long)]
    pub sm: Option<String>,
    /// Appearance model [default: the default tracker's].
    #[arg(long)]
    pub am: Option<String>,
    /// State space model.
    #[arg(long, default_value = DEFAULT_TRACKER[2])]
    pub ssm: String,
    #[command(flatten)]
    pub params: ParamArgs,
}

/// The trackers of `eval` and `bench`: the product of the method lists, and whole trackers.
#[derive(Args)]
pub struct SelectArgs {
    /// Search methods [none when only --tracker is given].
    #[arg(long, value_delimiter = ',')]
    pub sm: Option<Vec<String>>,
    /// Appearance models.
    #[arg(long, value_delimiter = ',')]
    pub am: Option<Vec<String>>,
    /// State space models.
    #[arg(long, value_delimiter = ',')]
    pub ssm: Option<Vec<String>>,
    /// Whole trackers (`regtrack list` names them), beside the registration trackers (alone when
    /// no --sm, --am or --ssm is given).
    #[arg(long, value_delimiter = ',')]
    pub tracker: Vec<String>,
    #[command(flatten)]
    pub params: ParamArgs,
}

impl SelectArgs {
    /// The trackers, the default tracker for the lists not given (with its own parameters when
    /// neither --sm nor --am is given), with their parameters set.
    pub fn default_specs(&self) -> Result<Vec<TrackerSpec>> {
        tracker::select(
            self.sm.as_deref(),
            self.am.as_deref(),
            self.ssm.as_deref(),
            &self.tracker,
            &self.params.assignments,
        )
    }

    /// The trackers, with `defaults` for the lists not given (none at all when only whole
    /// trackers are asked for), with their parameters set.
    pub fn specs(&self, defaults: [&str; 3]) -> Result<Vec<TrackerSpec>> {
        let only_whole = !self.tracker.is_empty()
            && self.sm.is_none()
            && self.am.is_none()
            && self.ssm.is_none();
        let list = |v: &Option<Vec<String>>, d: &str| match v {
            _ if only_whole => Vec::new(),
            Some(v) => v.clone(),
            None => d.split(',').map(String::from).collect(),
        };
        let mut specs = tracker::product(
            &list(&self.sm, defaults[0]),
            &list(&self.am, defaults[1]),
            &list(&self.ssm, defaults[2]),
            &self.tracker,
        )?;
        tracker::set_params(&mut specs, &self.params.assignments)?;
        Ok(specs)
    }
}

/// Tracker parameters: a flag per parameter of [`TRACKER_PARAMS`] (with the short flags of
/// [`TRACKER_FLAGS`]), each a shortcut for `--param NAME=VALUE`, and `--param` for any tracker,
/// search-method or appearance-model parameter. Help, ranges and defaults come from the
/// definitions, as `regtrack list` shows them.
#[derive(Clone, Default)]
pub struct ParamArgs {
    /// Every assignment given: the flags, then `--param`, in order.
    pub assignments: Vec<(String, String)>,
}

impl Args for ParamArgs {
    fn augment_args(mut cmd: clap::Command) -> clap::Command {
        for d in TRACKER_PARAMS {
            let mut arg = Arg::new(d.name)
                .long(d.name)
                .value_name("VALUE")
                .allow_negative_numbers(true)
                .help(d.describe());
            for (flag, _) in TRACKER_FLAGS.iter().filter(|(_, n)| *n == d.name) {
                arg = arg.visible_alias(*flag);
            }
            cmd = cmd.arg(arg);
        }
        cmd.arg(
            Arg::new("param")
                .long("param")
                .value_name("NAME=VALUE")
                .action(ArgAction::Append)
                .help(
                    "Any tracker, search-method or appearance-model parameter, repeatable \
                     (e.g. --param samples=5000 --param bins=8); `regtrack list` lists them",
                ),
        )
    }
    fn augment_args_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_args(cmd)
    }
}

impl FromArgMatches for ParamArgs {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        let mut p = ParamArgs::default();
        p.update_from_arg_matches(m)?;
        Ok(p)
    }
    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        for d in TRACKER_PARAMS {
            if let Some(v) = m.get_one::<String>(d.name) {
                self.assignments.push((d.name.to_string(), v.clone()));
            }
        }
        for a in m.get_many::<String>("param").into_iter().flatten() {
            let (name, v) = regtrack::params::split_assignment(a)
                .map_err(|e| clap::Error::raw(clap::error::ErrorKind::ValueValidation, e))?;
            // One value a parameter: `--res 20 --param res=10` would let one win unsaid.
            if let Some((_, was)) = self
                .assignments
                .iter()
                .find(|(n, w)| n == name && w.trim() != v.trim())
            {
                return Err(clap::Error::raw(
                    clap::error::ErrorKind::ArgumentConflict,
                    format!("{name} is given twice, as {was} and as {v}: give it once\n"),
                ));
            }
            self.assignments.push((name.to_string(), v.to_string()));
        }
        Ok(())
    }
}

#[derive(Args)]
pub struct SynthArgs {
    /// Texture rendered into the target quad.
    #[arg(long)]
    pub texture: PathBuf,
    /// Background image (default: mid-gray).
    #[arg(long)]
    pub background: Option<PathBuf>,
    /// Motion profile (four corners per frame, TMT/MTF format).
    #[arg(long)]
    pub motion: PathBuf,
    /// Output root: writes `<out>/<name>.txt` and `<out>/<name>/`.
    #[arg(long)]
    pub out: PathBuf,
    /// Sequence name.
    #[arg(long)]
    pub name: String,
    /// Frame size `WxH` (default: the smallest common size holding the motion).
    #[arg(long)]
    pub size: Option<String>,
    /// Use only the first frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Take every k-th frame of the profile (k times faster motion).
    #[arg(long, default_value_t = 1)]
    pub step: usize,
    /// Supersampling per axis.
    #[arg(long, default_value_t = 3)]
    pub supersample: usize,
    /// Gaussian noise (gray levels).
    #[arg(long, default_value_t = 0.0)]
    pub noise: f32,
    /// Global gain drift amplitude (0.2 = +-20%).
    #[arg(long, default_value_t = 0.0)]
    pub gain_drift: f32,
    /// Global bias drift amplitude (gray levels).
    #[arg(long, default_value_t = 0.0)]
    pub bias_drift: f32,
    /// Moving local light amplitude (0.5 = +50% at its centre).
    #[arg(long, default_value_t = 0.0)]
    pub local_light: f32,
    /// Motion blur sub-frames (0 = none).
    #[arg(long, default_value_t = 0)]
    pub motion_blur: usize,
    /// Occluder size as a fraction of the target (0 = none).
    #[arg(long, default_value_t = 0.0)]
    pub occlusion: f32,
    /// Non-rigid bend amplitude as a fraction of the target's size (0 = rigid; up to 0.2):
    /// the texture waves, its corners with it.
    #[arg(long, default_value_t = 0.0)]
    pub bend: f32,
    /// JPEG quality (0 = PNG frames).
    #[arg(long, default_value_t = 95)]
    pub jpeg_quality: u8,
    /// Seed of the random nuisances.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Eight corner coordinates, separated by commas or spaces (`--init 10,20,...` or
/// `--init "10 20 ..."`).
fn parse_corners(s: &str) -> Result<Corners, String> {
    let v: Vec<f64> = s
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("'{t}' is not a finite number"))
        })
        .collect::<Result<_, _>>()?;
    if v.len() != 8 {
        return Err(format!(
            "expected 8 numbers ulx,uly,urx,ury,lrx,lry,llx,lly, got {}",
            v.len()
        ));
    }
    let arr: [f64; 8] = v.try_into().expect("8 numbers, checked above");
    Ok(Corners(regtrack::geometry::Quad::from_array(arr)))
}

/// The corners `--init` gives.
#[derive(Clone, Debug)]
pub struct Corners(pub regtrack::geometry::Quad);
