//! Frame decoding through the project's loader, with its limits: never more than
//! `MAX_PIXELS`, and what decodes is a whole image.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::imaging::{MAX_PIXELS, load_gray};

fuzz_target!(|data: &[u8]| {
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
