//! A folder per fuzzing process for the files a target writes (in memory when /dev/shm exists:
//! the journal syncs every record).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

pub fn scratch(target: &str) -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = Path::new("/dev/shm");
        let base = if base.is_dir() {
            base.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let d = base.join(format!("regtrack-fuzz-{target}-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("scratch folder");
        d
    })
}
