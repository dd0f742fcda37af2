//! The bundled demo sequence: the TMT "book" motion profile with a bundled texture over a bundled
//! background, rendered deterministically on first use into a cache folder (frames are never
//! committed) and reused while its configuration is unchanged.

use super::synth::{SynthConfig, render_sequence};
use super::{Sequence, write_atomic};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Name of the demo sequence.
pub const DEMO_NAME: &str = "demo_book";

/// The folder of the bundled assets: `$REGTRACK_ASSETS`, else the crate's `assets/`.
pub fn assets_dir() -> PathBuf {
    std::env::var_os("REGTRACK_ASSETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("assets"))
}

/// Where rendered sequences are cached: `$REGTRACK_CACHE`, else `$XDG_CACHE_HOME/regtrack`, else
/// `~/.cache/regtrack`, else the temporary folder.
pub fn cache_dir() -> PathBuf {
    if let Some(p) = std::env::var_os("REGTRACK_CACHE") {
        return PathBuf::from(p);
    }
    if let Some(p) = std::env::var_os("XDG_CACHE_HOME") {
        return PathBuf::from(p).join("regtrack");
    }
    if let Some(h) = std::env::var_os("HOME") {
        return PathBuf::from(h).join(".cache").join("regtrack");
    }
    std::env::temp_dir().join("regtrack")
}

/// The demo's rendering configuration.
pub fn demo_config() -> SynthConfig {
    let a = assets_dir();
    SynthConfig {
        texture: a.join("textures/skimage_coffee.png"),
        background: Some(a.join("textures/skimage_grass.png")),
        motion: a.join("motion/tmt_dl_bookIII_s5.txt"),
        noise: 1.5,
        jpeg_quality: 92,
        seed: 2026,
        ..SynthConfig::default()
    }
}

/// The demo sequence under `root` (default [`cache_dir`]), rendered if missing or stale.
pub fn ensure_demo(
    root: Option<&Path>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Sequence> {
    let root = root.map(Path::to_path_buf).unwrap_or_else(cache_dir);
    let cfg = demo_config();
    let stamp_path = root.join(format!("{DEMO_NAME}.render.json"));
    let stamp =
        serde_json::to_string_pretty(&cfg).map_err(|e| Error::InvalidParameter(e.to_string()))?;
    let gt = root.join(format!("{DEMO_NAME}.txt"));
    let fresh = gt.is_file() && std::fs::read_to_string(&stamp_path).is_ok_and(|s| s == stamp);
    if let (true, Ok(seq)) = (fresh, Sequence::open(&gt)) {
        return Ok(seq);
    }
    let seq = render_sequence(&cfg, &root, DEMO_NAME, progress)?;
    write_atomic(&stamp_path, stamp.as_bytes())?;
    Ok(seq)
}
