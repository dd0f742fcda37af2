//! `regtrack track` (one target, many patches, a live camera) and `score-patches`: what they
//! print and write; the tracking is the library's.

use crate::args::TrackerArgs;
use crate::{bar, parse_size, spec_of, warn_about};
use anyhow::{Result, bail};
use regtrack::dataset::{self, Sequence};
use regtrack::eval::{self, EvalOptions};
use regtrack::geometry::Quad;
use regtrack::observe::NoObserver;
use regtrack::tracker::{self};
use std::path::Path;

pub fn run_track(
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
    dataset::write_corners_named(out, &corners, &seq.frame_names())?;
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
pub fn run_patches(
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

pub fn print_patch_accuracy(a: &regtrack::patches::PatchAccuracy) {
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
pub fn run_live(
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
    // In colour for a tracker that reads colour (and so recorded).
    let colour = tracker.channels() == 3;
    let mut live = dataset::live::LiveRun::open(camera, w, h, colour)?;
    // Written as it happens: a run that ends in any way leaves a sequence up to its last frame.
    if let Some(d) = record {
        live.start_recording(d, Some("live"))?;
    }
    let mut corners = Vec::new();
    let started = std::time::Instant::now();
    let mut stopped = None;
    while frames.is_none_or(|n| corners.len() < n) {
        let f = match live.take(None) {
            Ok(Some(f)) => f,
            Ok(None) => continue,
            Err(e) => {
                stopped = Some(e);
                break;
            }
        };
        let q = tracker.follow(regtrack::tracker::FrameInput::of(&f.image), &init, f.index)?;
        if let Err((e, _)) = live.record(&f.image, q.as_ref()) {
            return Err(e.into());
        }
        corners.push(q);
    }
    let secs = started.elapsed().as_secs_f64();
    dataset::write_corners(out, &corners, "jpg")?;
    let info = live.info();
    let lost = corners.iter().filter(|q| q.is_none()).count();
    println!(
        "{camera}: {} frames tracked in {secs:.1} s ({:.1} fps), {} dropped, {lost} lost; wrote {}",
        corners.len(),
        corners.len() as f64 / secs.max(1e-9),
        info.dropped,
        out.display()
    );
    if let Some((path, frames)) = live.stop_recording() {
        println!("recorded {frames} frames as a sequence: {}", path.display());
    }
    match stopped {
        // Asked for more frames than came: the camera went away (what was tracked is kept).
        Some(e) if corners.is_empty() || frames.is_some() => Err(anyhow::anyhow!(
            "{e}; the frames tracked before it are in {}",
            out.display()
        )),
        Some(e) => {
            println!("{e}");
            Ok(())
        }
        None => Ok(()),
    }
}

/// A run's corners by frame index (`None` where lost or not tracked), for the first `n` frames.
pub fn by_frame(run: &eval::RunResult, n: usize) -> Vec<Option<Quad>> {
    let mut out = vec![None; n];
    for f in &run.frames {
        if let Some(slot) = out.get_mut(f.frame) {
            *slot = f.corners;
        }
    }
    out
}
