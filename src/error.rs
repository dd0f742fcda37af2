//! The library's error type. Every message names what it is about: the file and line of a
//! malformed ground-truth entry, the path of a missing frame, the list of methods that exist.

use std::path::PathBuf;

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in the library (tracking loss is not an error: it is a
/// [`crate::tracker::TrackStatus`]).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A method name that no registry entry has.
    #[error("unknown {kind} '{name}'; available: {available}")]
    UnknownMethod {
        kind: &'static str,
        name: String,
        available: String,
    },
    /// Methods that exist but cannot work together.
    #[error("incompatible combination: {0}")]
    Incompatible(String),
    /// A parameter value out of its range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// A malformed line in a text file.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A file that should exist but does not.
    #[error("missing file: {}", path.display())]
    Missing { path: PathBuf },
    /// An image that could not be read (decoded), or a frame that is not what the sequence
    /// needs.
    #[error("cannot read the image {}: {message}", path.display())]
    Image { path: PathBuf, message: String },
    /// An image or video that could not be written.
    #[error("cannot write {}: {message}", path.display())]
    ImageWrite { path: PathBuf, message: String },
    /// A path that names something other than a regular file where a file is read (a folder,
    /// a FIFO, a device, a loop of symbolic links).
    #[error("not a regular file: {} is {what}", path.display())]
    NotAFile { path: PathBuf, what: &'static str },
    /// A file larger than its format's bound (`crate::files`).
    #[error("{} is larger than {limit} bytes, more than a file of its kind holds", path.display())]
    TooLarge { path: PathBuf, limit: u64 },
    /// Any other I/O failure, with the path it concerns. The cause is part of the message and
    /// not a `source` (a caller that prints the chain would print it twice).
    #[error("I/O error on {}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// An initial region a tracker cannot start from (degenerate quad, outside the frame...).
    #[error("invalid region: {0}")]
    InvalidRegion(String),
    /// A sequence or dataset that does not hold what it should.
    #[error("invalid sequence {}: {message}", path.display())]
    Sequence { path: PathBuf, message: String },
    /// A live source (camera, test source) that stopped or cannot be read.
    #[error("live source {name}: {message}")]
    Live { name: String, message: String },
    /// A report that cannot be made: a folder without runs, a figure that cannot be drawn.
    #[error("{}: {message}", path.display())]
    Report { path: PathBuf, message: String },
    /// The worker threads of a batch or of a tracker could not be started.
    #[error("cannot start {threads} worker threads: {message}")]
    Threads { threads: usize, message: String },
    /// An action refused, the message saying why (a correction while the sequence's journal
    /// cannot be used).
    #[error("{0}")]
    Refused(String),
}

impl Error {
    /// A report or result folder that cannot be used, with the path it concerns.
    pub fn report(path: &std::path::Path, message: impl Into<String>) -> Self {
        Error::Report {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        let path = path.into();
        if source.kind() == std::io::ErrorKind::NotFound {
            Error::Missing { path }
        } else {
            Error::Io {
                path,
                cause: source,
            }
        }
    }
}

/// Text from a file or an argument as a message quotes it: at most 40 characters, then how
/// long it was (a 1 MB token is not echoed whole).
pub fn short_text(s: &str) -> String {
    const SHOWN: usize = 40;
    match s.char_indices().nth(SHOWN) {
        None => s.to_string(),
        Some((end, _)) => format!("{}... ({} bytes)", &s[..end], s.len()),
    }
}

/// A number for a message: `decimals` places, or scientific notation when it is too large or
/// too small to read that way (1e308 is not printed with 309 digits).
pub fn short_number(x: f64, decimals: usize) -> String {
    if x.is_finite() && x != 0.0 && !(1e-3..1e7).contains(&x.abs()) {
        format!("{x:.3e}")
    } else {
        format!("{x:.decimals$}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn short_numbers_stay_short() {
        assert_eq!(super::short_number(1e308, 2), "1.000e308");
        assert_eq!(super::short_number(-2.5, 2), "-2.50");
        assert_eq!(super::short_number(0.0, 1), "0.0");
        assert_eq!(super::short_number(f64::NAN, 2), "NaN");
        assert_eq!(super::short_number(1.5e-9, 2), "1.500e-9");
    }
}
