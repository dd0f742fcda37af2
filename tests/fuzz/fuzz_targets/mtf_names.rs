//! MTF sequences whose frames are the folder's images and whose ground-truth lines are matched
//! to them by name: the first byte chooses which of eight frames exist (one of them named
//! without zero padding), the rest is the ground-truth file. Whatever is read, the frames are
//! exactly the images there, in natural order, each with its own line or none, and a line naming
//! a frame that is not there is an error naming it.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::dataset::{Sequence, unusable_quad};

const NAMES: [&str; 8] = [
    "frame00001.jpg",
    "frame00002.jpg",
    "frame00003.jpg",
    "frame00004.jpg",
    "frame00005.jpg",
    "frame00010.jpg",
    "frame9.jpg",
    "frame00006.png",
];

fuzz_target!(|data: &[u8]| {
    let Some((&mask, gt)) = data.split_first() else {
        return;
    };
    let root = scratch::scratch("mtf_names");
    let dir = root.join("s");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let present: Vec<&str> = NAMES
        .iter()
        .enumerate()
        .filter(|(k, _)| mask & (1 << k) != 0)
        .map(|(_, n)| *n)
        .collect();
    for n in &present {
        std::fs::write(dir.join(n), b"x").unwrap();
    }
    let file = root.join("s.txt");
    std::fs::write(&file, gt).unwrap();
    match Sequence::open(&file) {
        Ok(seq) => {
            // The frames are the images in the folder, in natural order.
            let names = seq.frame_names();
            let mut expected: Vec<String> = present.iter().map(|s| s.to_string()).collect();
            expected.sort_by(|a, b| regtrack::dataset::natural_cmp(a, b));
            assert_eq!(names, expected);
            assert!(seq.ground_truth.is_empty() || seq.ground_truth.len() == seq.frames.len());
            for q in seq.ground_truth.iter().flatten() {
                assert!(unusable_quad(q).is_none(), "{q} was read as usable");
            }
        }
        Err(e) => {
            let e = e.to_string();
            assert!(e.contains("s.txt") || e.contains("/s"), "{e}");
        }
    }
});
