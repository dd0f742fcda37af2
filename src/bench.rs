//! The speed benchmark behind `regtrack bench`: per tracker, iterations per frame, microseconds
//! per iteration (the iterations' own time, [`crate::observe::Iteration::duration`]), the rest of
//! a frame's time (pyramid, loss checks), tracker-only FPS (the search on pre-smoothed frames) and
//! live-path FPS (from 8-bit frames in memory, pre-processing of the region included), and the
//! microseconds per iteration again on the live path. Frames are decoded before timing starts;
//! every figure is the median over repeats.
//!
//! The two per-iteration figures differ by where the frame is when the search reads it. The
//! tracker-only run smooths every frame beforehand (about 60 MB for 140 frames of 384 x 288), so
//! a frame's first samples come from main memory; on the live path the tracker has just smoothed
//! the region it reads into a buffer of its own, which is in the core's cache, as it is whenever
//! frames arrive one at a time.

use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::imaging::{Frame8, GrayF32, GrayU8, gaussian_blur};
use crate::linalg::median;
use crate::observe::IterationCounter;
use crate::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// One benchmark row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchRow {
    pub tracker: String,
    /// Frames tracked per repeat (the target may be lost before the end).
    pub frames: usize,
    pub iterations_per_frame: f64,
    /// The time of one iteration: the search method's step and the executor's bookkeeping of it.
    pub us_per_iteration: f64,
    /// A frame's time outside its iterations: the pyramid levels, the loss-of-track checks.
    pub us_per_frame_other: f64,
    /// [`BenchRow::us_per_iteration`] on the live path (the region just smoothed by the tracker,
    /// in the cache), and the iterations per frame there.
    #[serde(default)]
    pub live_us_per_iteration: f64,
    pub tracker_fps: f64,
    pub live_fps: f64,
    /// Initialisation time (template, NN index, ...), ms.
    pub init_ms: f64,
    /// The longest update while lost (ms): the tracker, lost on a frame of noise the size of the
    /// sequence's, updated on [`LOST_FRAMES`] more (each a search for the target, as
    /// `on_loss=redetect` makes it).
    #[serde(default)]
    pub lost_ms: f64,
    /// Frames lost (in the live-path run).
    pub lost_at: Option<usize>,
}

impl BenchRow {
    /// The column names of [`BenchRow::line`].
    pub const HEADER: &'static str = "tracker                     frames it/frame  us/iter  other us/frame  tracker FPS   live FPS  live us/iter   init ms   lost ms";

    /// The row as `regtrack bench` prints it, under [`BenchRow::HEADER`].
    pub fn line(&self) -> String {
        format!(
            "{:<26} {:>7} {:>8.2} {:>8.2} {:>15.1} {:>12.0} {:>10.0} {:>13.2} {:>9.1} {:>9.2}{}",
            self.tracker,
            self.frames,
            self.iterations_per_frame,
            self.us_per_iteration,
            self.us_per_frame_other,
            self.tracker_fps,
            self.live_fps,
            self.live_us_per_iteration,
            self.init_ms,
            self.lost_ms,
            self.lost_at
                .map(|f| format!("  (lost at frame {f})"))
                .unwrap_or_default()
        )
    }
}

/// How many updates while lost `bench_tracker` times.
pub const LOST_FRAMES: usize = 12;

/// Frames of a sequence loaded in memory: grey, or in colour when a tracker reads colour.
pub struct LoadedFrames {
    pub frames: Vec<Frame8>,
    pub init: crate::geometry::Quad,
}

impl LoadedFrames {
    /// Frame `i` as a tracker of `channels` reads it (in colour when loaded so).
    fn input(&self, i: usize, channels: usize) -> FrameInput<'_> {
        match &self.frames[i] {
            Frame8::Colour(c) if channels == 3 => FrameInput::Colour(c),
            f => FrameInput::Gray8(f.gray()),
        }
    }
}

/// Loads up to `max_frames` frames, in colour too with `colour`.
pub fn load_frames(
    seq: &Sequence,
    max_frames: Option<usize>,
    colour: bool,
) -> Result<LoadedFrames> {
    let n = max_frames.unwrap_or(usize::MAX).min(seq.len());
    if n < 2 {
        return Err(Error::InvalidParameter(format!(
            "the benchmark needs at least 2 frames, {} has {n}",
            seq.name
        )));
    }
    let init = seq.ground_truth(0).ok_or_else(|| Error::Sequence {
        path: seq.frames.first().cloned().unwrap_or_default(),
        message: "the benchmark needs ground truth for the first frame".into(),
    })?;
    let frames = (0..n)
        .map(|i| seq.load_frame(i, colour))
        .collect::<Result<Vec<_>>>()?;
    Ok(LoadedFrames { frames, init })
}

/// Benchmarks one tracker on loaded frames, `repeats` times.
pub fn bench_tracker(
    spec: &TrackerSpec,
    frames: &LoadedFrames,
    repeats: usize,
) -> Result<BenchRow> {
    // A registration tracker's tracker-only input is the frame smoothed as it would smooth it;
    // a whole tracker's pre-processing is its own business (timed): it gets the frame as floats.
    let smoothed: Vec<GrayF32> = match spec.smoothing()? {
        Some(kernel) => frames
            .frames
            .iter()
            .map(|f| gaussian_blur(f.gray(), &kernel))
            .collect(),
        None => frames
            .frames
            .iter()
            .map(|f| f.gray())
            .map(|g| GrayF32 {
                width: g.width,
                height: g.height,
                data: g.data.iter().map(|&v| v as f32).collect(),
            })
            .collect(),
    };
    let (mut fps_t, mut fps_l, mut ipf, mut upi) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut other = Vec::new();
    let mut live_upi = Vec::new();
    let mut init_ms = Vec::new();
    let mut tracked = 0;
    let mut lost_at = None;
    for _ in 0..repeats.max(1) {
        // Tracker only: pre-smoothed whole frames, the search alone is timed.
        let mut t = Tracker::new(spec)?;
        let start = Instant::now();
        t.initialize(FrameInput::Smoothed(&smoothed[0]), &frames.init)?;
        init_ms.push(start.elapsed().as_secs_f64() * 1e3);
        let mut counter = IterationCounter::default();
        let mut n = 0usize;
        let start = Instant::now();
        for img in &smoothed[1..] {
            let out = t.update(FrameInput::Smoothed(img), &mut counter);
            if out.status != TrackStatus::Tracking {
                break;
            }
            n += 1;
        }
        let secs = start.elapsed().as_secs_f64();
        if n > 0 && secs > 0.0 {
            fps_t.push(n as f64 / secs);
            ipf.push(counter.iterations as f64 / counter.frames.max(1) as f64);
            let busy = counter.busy.as_secs_f64();
            upi.push(busy * 1e6 / counter.iterations.max(1) as f64);
            other.push((secs - busy).max(0.0) * 1e6 / n as f64);
        }
        tracked = n;
        // Live path: 8-bit frames (in colour for a tracker that reads colour), the tracker
        // smooths the region it reads.
        let mut t = Tracker::new(spec)?;
        let channels = t.channels();
        t.initialize(frames.input(0, channels), &frames.init)?;
        let mut counter = IterationCounter::default();
        let mut n = 0usize;
        let start = Instant::now();
        lost_at = None;
        for i in 0..frames.frames.len() - 1 {
            let out = t.update(frames.input(i + 1, channels), &mut counter);
            if out.status != TrackStatus::Tracking {
                lost_at = Some(i + 1);
                break;
            }
            n += 1;
        }
        let secs = start.elapsed().as_secs_f64();
        if n > 0 && secs > 0.0 {
            fps_l.push(n as f64 / secs);
            let busy = counter.busy.as_secs_f64();
            live_upi.push(busy * 1e6 / counter.iterations.max(1) as f64);
        }
    }
    let lost_ms = lost_update_ms(spec, frames)?;
    Ok(BenchRow {
        tracker: spec.label(),
        frames: tracked,
        iterations_per_frame: median(ipf),
        us_per_iteration: median(upi),
        us_per_frame_other: median(other),
        live_us_per_iteration: median(live_upi),
        tracker_fps: median(fps_t),
        live_fps: median(fps_l),
        init_ms: median(init_ms),
        lost_ms,
        lost_at,
    })
}

/// The longest of [`LOST_FRAMES`] updates while lost, ms: the tracker initialised on the first
/// frame, then given frames of seeded noise of the same size (the target gone: it is lost on
/// the first, and searches for the target on every one after).
fn lost_update_ms(spec: &TrackerSpec, frames: &LoadedFrames) -> Result<f64> {
    let first = frames.frames[0].gray();
    let noise = GrayU8::noise(first.width, first.height, &mut crate::rng::Rng::new(7));
    let mut t = Tracker::new(spec)?;
    t.initialize(FrameInput::Gray8(first), &frames.init)?;
    let mut counter = IterationCounter::default();
    t.update(FrameInput::Gray8(&noise), &mut counter);
    let mut longest = 0.0f64;
    for _ in 0..LOST_FRAMES {
        let start = Instant::now();
        t.update(FrameInput::Gray8(&noise), &mut counter);
        longest = longest.max(start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(longest)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::demo::demo_config;
    use crate::dataset::synth::{SynthConfig, render_frames};

    #[test]
    fn a_row_reports_every_per_iteration_and_per_frame_figure() {
        let (gray, quads) = render_frames(&SynthConfig {
            max_frames: Some(12),
            ..demo_config()
        })
        .unwrap();
        let frames = LoadedFrames {
            frames: gray.into_iter().map(Frame8::Gray).collect(),
            init: quads[0],
        };
        let spec = TrackerSpec::from_names("iclk", "ssd", "homography").unwrap();
        let row = bench_tracker(&spec, &frames, 2).unwrap();
        assert_eq!((row.frames, row.lost_at), (11, None), "{row:?}");
        assert!(row.iterations_per_frame >= 1.0, "{row:?}");
        for v in [
            row.us_per_iteration,
            row.live_us_per_iteration,
            row.tracker_fps,
            row.live_fps,
        ] {
            assert!(v.is_finite() && v > 0.0, "{row:?}");
        }
        // A frame is at least its iterations, on either path.
        let live_us_per_frame = 1e6 / row.live_fps;
        assert!(
            live_us_per_frame >= row.live_us_per_iteration * row.iterations_per_frame * 0.5,
            "{row:?}"
        );
        // Lost, an update searches for the target: it takes time, and it is said.
        assert!(row.lost_ms > 0.0 && row.lost_ms.is_finite(), "{row:?}");
        // The line has the header's columns: the name and nine figures.
        let line = row.line();
        let fields: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(fields.len(), 10, "{line}");
        assert_eq!(fields[0], "iclk_ssd_homography");
        let live_upi: f64 = fields[7].parse().unwrap();
        assert!(
            (live_upi - row.live_us_per_iteration).abs() < 0.006,
            "{line}"
        );
        // The JSON of a row written before the live column existed still reads.
        let mut old = serde_json::to_value(&row).unwrap();
        old.as_object_mut().unwrap().remove("live_us_per_iteration");
        let back: BenchRow = serde_json::from_value(old).unwrap();
        assert_eq!(back.live_us_per_iteration, 0.0);
    }
}
