//! Frame decoding through the project's loader, with its limits: never more than
//! `MAX_PIXELS`, and what decodes is a whole image.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::imaging::{MAX_PIXELS, load_gray};

fuzz_target!(|data: &[u8]| {
    // The loader catches a decoder's panic (zune-jpeg overflows on some files) and reports a
    // bad frame; libFuzzer's hook would abort before the unwinding reaches it. A panic the
    // loader does not catch still reaches libFuzzer, which reports it as a crash.
    static QUIET: std::sync::Once = std::sync::Once::new();
    QUIET.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let Some((&kind, bytes)) = data.split_first() else {
        return;
    };
    let ext = ["png", "jpg", "pgm"][kind as usize % 3];
    let p = scratch::scratch("image").join(format!("frame.{ext}"));
    std::fs::write(&p, bytes).unwrap();
    if let Ok(img) = load_gray(&p) {
        assert!((img.width * img.height) as u64 <= MAX_PIXELS);
        assert_eq!(img.data.len(), img.width * img.height);
    }
});
