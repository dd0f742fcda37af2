//! Evaluation files: a run file (`*_run.json`) and summaries, as text and through the folder
//! reader; what reads is summarised, written and read back.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::eval::{RunResult, Summary, read_all_runs, summary_rows, summary_table};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(run) = serde_json::from_str::<RunResult>(text) {
        let _ = summary_table(&[run.summary()]);
    }
    if let Ok(rows) = serde_json::from_str::<Vec<Summary>>(text) {
        let _ = summary_table(&rows);
    }
    let dir = scratch::scratch("run_files");
    let seq = dir.join("tracking_data/s");
    std::fs::create_dir_all(&seq).unwrap();
    std::fs::write(seq.join("esm_ssd_homography_run.json"), data).unwrap();
    if let Ok(runs) = read_all_runs(&[dir.to_path_buf()]) {
        let rows = summary_rows(&runs);
        let _ = summary_table(&rows);
        let out = dir.join("out");
        regtrack::eval::write_summaries(&out, &rows).expect("summaries of runs that read");
    }
});
