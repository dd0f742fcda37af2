//! OptGT files (`<gt folder>/OptGT/<seq>_<ssm>.txt`, a corrected low-DOF export) as `eval
//! --gt-ssm` reads them beside a sequence with valid ground truth: the file is used, every quad
//! it gives is usable (what is not is a warning naming the file and line), or the error names
//! the file.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::dataset::{Sequence, unusable_quad};
use regtrack::gt::fit::{ground_truth_dir, opt_gt_path};
use std::fmt::Write;

fuzz_target!(|data: &[u8]| {
    let root = scratch::scratch("optgt");
    let dir = root.join("s");
    std::fs::create_dir_all(&dir).unwrap();
    let mut gt = String::from("frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n");
    for k in 1..=5 {
        let p = dir.join(format!("frame{k:05}.jpg"));
        if !p.exists() {
            std::fs::write(p, b"x").unwrap();
        }
        let x = 10.0 + k as f64;
        writeln!(
            gt,
            "frame{k:05}.jpg\t{x}\t10\t{}\t10\t{}\t50\t{x}\t50",
            x + 40.0,
            x + 40.0
        )
        .unwrap();
    }
    let file = root.join("s.txt");
    std::fs::write(&file, gt).unwrap();
    let seq = Sequence::open(&file).expect("the sequence is valid");
    for ssm in ["translation", "similitude", "homography"] {
        let name = regtrack::ssm::build(ssm).unwrap().name().to_string();
        let opt = opt_gt_path(&ground_truth_dir(&seq), &seq.name, &name);
        std::fs::create_dir_all(opt.parent().unwrap()).unwrap();
        std::fs::write(&opt, data).unwrap();
        match regtrack::gt::low_dof_ground_truth(&seq, ssm) {
            Ok(t) => {
                assert_eq!(t.path.as_deref(), Some(opt.as_path()));
                assert_eq!(t.quads.len(), seq.frames.len());
                for q in t.quads.iter().flatten() {
                    assert!(unusable_quad(q).is_none(), "{q} was read as usable");
                }
                for w in &t.warnings {
                    assert!(w.contains(&*opt.to_string_lossy()), "{w}");
                }
            }
            Err(e) => {
                let e = e.to_string();
                assert!(e.contains(&*opt.to_string_lossy()), "{e}");
            }
        }
        std::fs::remove_file(&opt).unwrap();
    }
});
