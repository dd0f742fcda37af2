//! Helpers shared by the integration tests.

use regtrack::imaging::{GrayU8, load_gray};
use std::path::PathBuf;

/// The crate's root folder.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Whether the exhaustive variants of the grids run (`REGTRACK_FULL_TESTS=1`): every trial of
/// the recovery grid, every SSM of the allocation test. The default is a seeded subset of the
/// same grids, each combination still run (README, "Tests").
pub fn full_tests() -> bool {
    std::env::var_os("REGTRACK_FULL_TESTS").is_some_and(|v| v != "0")
}

/// A bundled texture, in grayscale.
pub fn texture(name: &str) -> GrayU8 {
    load_gray(&root().join("assets/textures").join(name)).expect("bundled texture")
}

/// A bundled texture in colour (its grey is [`texture`]'s).
pub fn colour_texture(name: &str) -> regtrack::imaging::ColourU8 {
    regtrack::imaging::load_colour(&root().join("assets/textures").join(name))
        .expect("bundled texture")
}

/// A fresh empty folder under the system's temporary folder, removed when dropped.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static N: AtomicUsize = AtomicUsize::new(0);
        let p = std::env::temp_dir().join(format!(
            "regtrack-test-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).expect("temp dir");
        TempDir(p)
    }
    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Writes a small gray PNG.
pub fn write_png(path: &std::path::Path, w: u32, h: u32, seed: u8) {
    let img = image::GrayImage::from_fn(w, h, |x, y| {
        image::Luma([(x * 7 + y * 13 + seed as u32) as u8])
    });
    img.save(path).expect("png");
}

/// A sequence of `frames` small PNG frames in `dir/s/` with its ground truth `dir/s.txt` (the
/// same 30 x 20 box on every frame, MTF format); returns the ground truth's path.
pub fn tiny_sequence(dir: &std::path::Path, frames: usize) -> std::path::PathBuf {
    let folder = dir.join("s");
    std::fs::create_dir_all(&folder).unwrap();
    let mut text = String::from("frame ulx uly urx ury lrx lry llx lly\n");
    for i in 1..=frames {
        write_png(&folder.join(format!("frame{i:05}.png")), 60, 40, i as u8);
        text.push_str(&format!("frame{i:05}.png 10 10 40 10 40 30 10 30\n"));
    }
    let path = dir.join("s.txt");
    std::fs::write(&path, text).unwrap();
    path
}

/// The paper's single-level tracker: smoothing 5x5 with sigma 3, no pyramid, the classic
/// methods (no line search, no polish), and lost until initialised again. The tests that study how the classic methods behave
/// (where their drift comes from, what a rule of theirs changes) pin it; the defaults are the
/// robust tracker of issue 17 (docs/robustness.md).
pub fn paper_settings(spec: &mut regtrack::tracker::TrackerSpec) {
    for (k, v) in [
        ("blur_sigma", "3"),
        ("pyramid_levels", "1"),
        ("line_search", "off"),
        ("polish", "off"),
        ("on_loss", "stop"),
        ("predict", "off"),
    ] {
        spec.set_param(k, v).unwrap();
    }
}
