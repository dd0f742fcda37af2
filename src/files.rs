//! Reading the files a user names, safely: only regular files (a FIFO would block the reader
//! forever, `/dev/zero` would be read until memory runs out, a directory or a device is not a
//! file of any format here), and at most a bound that fits the file's format. Every error names
//! the file: what it is instead of a file, or how large it is against the bound.
//!
//! Each format's bound is one constant below, used by its reader.

use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

/// Ground truth, tracking results, points and tracks files: 64 MiB (a million frames of
/// corners at about 60 bytes a line).
pub const TEXT_LIMIT: u64 = 64 << 20;
/// A run's results (`*_run.json`: every frame's corners, errors and iterations): 256 MiB.
pub const RUN_LIMIT: u64 = 256 << 20;
/// The corrections journal (one line per edit): 256 MiB, millions of edits.
pub const JOURNAL_LIMIT: u64 = 256 << 20;
/// A session or the preferences (TOML settings): 16 MiB.
pub const SETTINGS_LIMIT: u64 = 16 << 20;

/// What a path names when it is not a regular file, as a message says it (`None` for a regular
/// file).
fn not_a_file(meta: &std::fs::Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a folder");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() || t.is_block_device() {
            return Some("a device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// The error for a path whose metadata cannot be read: missing, a loop of symbolic links, or
/// another I/O failure, each naming the path.
fn metadata_error(path: &Path, e: std::io::Error) -> Error {
    // ELOOP (Linux 40, macOS 62): the loop is named as such, not as a missing file.
    #[cfg(unix)]
    if matches!(e.raw_os_error(), Some(40) | Some(62)) {
        return Error::NotAFile {
            path: path.to_path_buf(),
            what: "a loop of symbolic links",
        };
    }
    Error::io(path, e)
}

/// Checks that `path` is a regular file (following symbolic links): else an error saying
/// what it is (missing, a folder, a FIFO, a device, a loop of symbolic links). Returns its
/// length.
pub fn check_regular(path: &Path) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|e| metadata_error(path, e))?;
    match not_a_file(&meta) {
        None => Ok(meta.len()),
        Some(what) => Err(Error::NotAFile {
            path: path.to_path_buf(),
            what,
        }),
    }
}

/// The bytes of the regular file `path`, at most `limit` of them (a larger file is an error
/// naming it and the bound).
pub fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let len = check_regular(path)?;
    let too_large = || Error::TooLarge {
        path: path.to_path_buf(),
        limit,
    };
    if len > limit {
        return Err(too_large());
    }
    let f = std::fs::File::open(path).map_err(|e| metadata_error(path, e))?;
    // The length may change between the check and the read: read one byte past the bound.
    let mut bytes = Vec::with_capacity(len as usize);
    f.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(bytes)
}

/// [`read_bounded`], `None` when the file does not exist.
pub fn read_optional(path: &Path, limit: u64) -> Result<Option<Vec<u8>>> {
    match read_bounded(path, limit) {
        Ok(b) => Ok(Some(b)),
        Err(Error::Missing { .. }) => Ok(None),
        Err(e) => Err(e),
    }
}

/// [`read_bounded`] as UTF-8 text (a leading byte-order mark dropped); text that is not UTF-8
/// is an error naming the file and the line.
pub fn read_text(path: &Path, limit: u64) -> Result<String> {
    text_of(path, read_bounded(path, limit)?)
}

/// [`read_text`], `None` when the file does not exist.
pub fn read_text_optional(path: &Path, limit: u64) -> Result<Option<String>> {
    read_optional(path, limit)?
        .map(|b| text_of(path, b))
        .transpose()
}

/// The bytes as text, naming `path` and the first line that is not UTF-8.
pub fn text_of(path: &Path, bytes: Vec<u8>) -> Result<String> {
    let bytes = match bytes.strip_prefix(b"\xEF\xBB\xBF") {
        Some(rest) => rest.to_vec(),
        None => bytes,
    };
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        Error::Parse {
            path: path.to_path_buf(),
            line: e.as_bytes()[..valid]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1,
            message: "not UTF-8 text".into(),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("regtrack-files-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_regular_file_is_read_within_its_bound_and_refused_beyond() {
        let d = temp("bound");
        let p = d.join("a.txt");
        std::fs::write(&p, "\u{feff}12345").unwrap();
        assert_eq!(read_text(&p, 100).unwrap(), "12345");
        assert_eq!(read_bounded(&p, 8).unwrap().len(), 8);
        let e = read_bounded(&p, 7).unwrap_err().to_string();
        assert!(e.contains("a.txt") && e.contains("7 bytes"), "{e}");
        assert!(read_optional(&d.join("none.txt"), 10).unwrap().is_none());
        let e = read_bounded(&d.join("none.txt"), 10).unwrap_err();
        assert!(matches!(e, Error::Missing { .. }), "{e}");
        std::fs::write(&p, b"ok\nok\n\xff\n").unwrap();
        let e = read_text(&p, 100).unwrap_err().to_string();
        assert!(e.contains("a.txt:3") && e.contains("UTF-8"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A folder, a device, a FIFO (which would block the reader) and a loop of symbolic links
    /// are each named for what they are, and never read.
    #[cfg(unix)]
    #[test]
    fn what_is_not_a_regular_file_is_named_and_never_read() {
        let d = temp("special");
        let e = read_bounded(&d, 10).unwrap_err().to_string();
        assert!(e.contains("a folder"), "{e}");
        let e = read_bounded(Path::new("/dev/zero"), 10)
            .unwrap_err()
            .to_string();
        assert!(e.contains("/dev/zero") && e.contains("a device"), "{e}");
        let fifo = d.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let e = read_bounded(&fifo, 10).unwrap_err().to_string();
            assert!(e.contains("FIFO"), "{e}");
        }
        let (a, b) = (d.join("a"), d.join("b"));
        std::os::unix::fs::symlink(&b, &a).unwrap();
        std::os::unix::fs::symlink(&a, &b).unwrap();
        let e = read_bounded(&a, 10).unwrap_err().to_string();
        assert!(e.contains("loop of symbolic links"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
