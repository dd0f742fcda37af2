//! `regtrack synth`: renders a sequence with the library's renderer, with a progress bar.

use crate::args::SynthArgs;
use crate::{bar, parse_size};
use anyhow::Result;
use regtrack::dataset::synth;
use std::path::Path;

pub fn run_synth(a: SynthArgs) -> Result<()> {
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
        bend: a.bend,
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
