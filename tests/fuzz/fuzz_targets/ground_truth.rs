//! The ground-truth readers: MTF (named frames), 8 numbers per line, POT (`_gt_points.txt`,
//! every other frame), as bytes and through the sequence reader of each layout; then the low-DOF
//! fit of what was read.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::dataset::{Sequence, parse_ground_truth_bytes, unusable_quad};
use std::path::Path;

/// Six frames named as the MTF layout names them (never decoded by these readers).
fn frames(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    for k in 1..=6 {
        let p = dir.join(format!("frame{k:05}.jpg"));
        if !p.exists() {
            std::fs::write(p, b"x").unwrap();
        }
    }
}

fuzz_target!(|data: &[u8]| {
    for name in ["gt.txt", "s_gt_points.txt"] {
        if let Err(e) = parse_ground_truth_bytes(Path::new(name), data) {
            assert!(e.to_string().starts_with(name), "{e}");
        }
    }
    let root = scratch::scratch("ground_truth");
    frames(&root.join("mtf/s"));
    frames(&root.join("folder"));
    frames(&root.join("pot/p"));
    let files = [
        root.join("mtf/s.txt"),
        root.join("folder/groundtruth.txt"),
        root.join("pot/p/p_gt_points.txt"),
    ];
    for f in &files {
        std::fs::write(f, data).unwrap();
    }
    for open in [files[0].clone(), root.join("folder"), root.join("pot/p")] {
        let Ok(seq) = Sequence::open(&open) else {
            continue;
        };
        assert!(!seq.frames.is_empty());
        assert!(seq.ground_truth.is_empty() || seq.ground_truth.len() == seq.frames.len());
        for q in seq.ground_truth.iter().flatten() {
            assert!(unusable_quad(q).is_none(), "{q} was read as usable");
        }
        for ssm in ["translation", "similitude", "homography"] {
            if let Ok(regtrack::gt::LowDofTruth { quads, .. }) =
                regtrack::gt::low_dof_ground_truth(&seq, ssm)
            {
                // Per frame, or nothing without ground truth.
                assert!(quads.len() == seq.frames.len() || seq.ground_truth.is_empty());
            }
        }
    }
});
