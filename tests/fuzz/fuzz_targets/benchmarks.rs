//! The benchmarks' annotation readers (VOT regions, boxes, homographies, flags, `.warps`) as
//! text, then through the layouts of a dataset root: POT as downloaded, PlanarTrack, UCSB, VOT,
//! GOT-10k and LaSOT folders, each annotation file replaced by the input.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::dataset::regions;
use regtrack::dataset::{discover, unusable_quad};
use std::path::Path;

fn frames(dir: &Path, name: impl Fn(usize) -> String) {
    std::fs::create_dir_all(dir).unwrap();
    for k in 0..6 {
        let p = dir.join(name(k));
        if !p.exists() {
            std::fs::write(p, b"x").unwrap();
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let p = Path::new("f.txt");
    let named = |e: regtrack::Error| assert!(e.to_string().starts_with("f.txt:"), "{e}");
    if let Ok(r) = regions::parse_vot_regions(p, text) {
        for reg in &r {
            // What is written reads back the same.
            let line = regions::vot_region_line(reg);
            if !line.is_empty() {
                let back = regions::parse_vot_regions(p, &line).unwrap();
                assert_eq!(back.len(), 1);
            }
        }
    } else if let Err(e) = regions::parse_vot_regions(p, text) {
        named(e);
    }
    for r in [
        regions::parse_boxes(p, text).map(|_| ()),
        regions::parse_homographies(p, text).map(|_| ()),
        regions::parse_flags(p, text).map(|_| ()),
    ] {
        if let Err(e) = r {
            named(e);
        }
    }
    let root = scratch::scratch("benchmarks");
    frames(&root.join("V01/V01_1"), |k| format!("{:04}.jpg", k + 1));
    frames(&root.join("sequences/Seq_00001"), |k| format!("{:05}.jpg", k + 1));
    frames(&root.join("fi-br-m1"), |k| format!("{k:04}.jpg"));
    frames(&root.join("vot/color"), |k| format!("{:08}.jpg", k + 1));
    frames(&root.join("got"), |k| format!("{:08}.jpg", k + 1));
    frames(&root.join("c/c-1/img"), |k| format!("{:08}.jpg", k + 1));
    let ann = root.join("annotation");
    std::fs::create_dir_all(&ann).unwrap();
    for f in [
        ann.join("V01_1_gt_points.txt"),
        ann.join("V01_1_gt_homography.txt"),
        ann.join("V01_1_flag.txt"),
        ann.join("Seq_00001.txt"),
        ann.join("Seq_00001_flag.txt"),
        root.join("fi-br-m1.warps"),
        root.join("vot/groundtruth.txt"),
        root.join("got/groundtruth.txt"),
        root.join("got/absence.label"),
        root.join("c/c-1/groundtruth.txt"),
        root.join("c/c-1/full_occlusion.txt"),
    ] {
        std::fs::write(&f, data).unwrap();
    }
    std::fs::write(root.join("vot/occlusion.tag"), b"0\n").unwrap();
    for name in ["V01_1", "Seq_00001", "fi-br-m1", "vot", "got", "c-1"] {
        let Ok(seqs) = discover(&root, Some(&[name.to_string()])) else {
            continue;
        };
        for seq in seqs {
            assert!(!seq.frames.is_empty());
            assert!(seq.ground_truth.is_empty() || seq.ground_truth.len() == seq.frames.len());
            for q in seq.ground_truth.iter().flatten() {
                assert!(unusable_quad(q).is_none(), "{q} was read as usable");
            }
        }
    }
});
