//! Helpers shared by the integration tests.

use regtrack::imaging::{load_gray, GrayU8};
use std::path::PathBuf;

/// The crate's root folder.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A bundled texture, in grayscale.
pub fn texture(name: &str) -> GrayU8 {
    load_gray(&root().join("assets/textures").join(name)).expect("bundled texture")
}
