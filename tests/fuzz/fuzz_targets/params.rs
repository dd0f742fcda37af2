//! The parameter paths: a tracker spec as TOML (sessions) and JSON (run files), and
//! `name=value` assignments (the command line's `--param`); whatever is accepted builds a
//! tracker or is refused with an error, never a panic or an abort.
#![no_main]

use libfuzzer_sys::fuzz_target;
use regtrack::tracker::{Tracker, TrackerSpec};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for spec in [
        toml::from_str::<TrackerSpec>(text).ok(),
        serde_json::from_str::<TrackerSpec>(text).ok(),
    ]
    .into_iter()
    .flatten()
    {
        let _ = Tracker::new(&spec);
    }
    let mut spec = TrackerSpec::from_names("fclk", "zncc", "homography").expect("the default");
    for line in text.lines().take(8) {
        if let Some((name, value)) = line.split_once('=')
            && spec.set_param(name.trim(), value.trim()).is_err()
        {
            return;
        }
    }
    let _ = Tracker::new(&spec);
});
