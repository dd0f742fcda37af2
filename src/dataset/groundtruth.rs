//! Ground-truth and result files: four corners per frame.
//!
//! Accepted lines (lines starting with `#` are skipped, separators are white space or commas;
//! blank lines are skipped too, except between the lines of a file of 8 numbers per line, where
//! lines are frames by position: there a blank line is a frame not annotated):
//! - `frame00001.jpg ulx uly urx ury lrx lry llx lly` (TMT/MTF, after a header line `frame ...`);
//! - `ulx uly urx ury lrx lry llx lly` (8 numbers: folders of images, POT `_gt_points.txt`);
//! - `frame00012.jpg lost` (a frame without corners: tracking results of a lost tracker; also
//!   `occluded`, `none`, `invalid`), or the word alone in the 8-number layout.

use crate::error::{Error, Result};
use crate::geometry::Quad;
use std::io::Write;
use std::path::Path;

/// One line of a ground-truth file.
#[derive(Clone, Debug, PartialEq)]
pub struct GtEntry {
    /// The frame file name, when the line names one.
    pub frame: Option<String>,
    /// The corners (`None` for a frame marked lost or unannotated).
    pub quad: Option<Quad>,
    /// The 1-based line it was read from.
    pub line: usize,
}

/// Words that mark a frame without corners.
const NO_CORNERS: &[&str] = &[
    "lost",
    "invalid",
    "invalid_tracker_state",
    "none",
    "nan",
    "occluded",
];

/// Parses ground-truth text; errors name `path` and the 1-based line.
pub fn parse_ground_truth(path: &Path, text: &str) -> Result<Vec<GtEntry>> {
    let mut out = Vec::new();
    let mut first_content = true;
    // Whether the lines name their frames (decided by the first entry), and the blank lines
    // since the last entry (frames not annotated, in a file without names, when an entry
    // follows them).
    let mut named: Option<bool> = None;
    let mut blanks: Vec<usize> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        if line.starts_with('#') {
            continue;
        }
        let tokens: Vec<&str> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
            .collect();
        if tokens.is_empty() {
            // Blank, or only separators.
            if named == Some(false) {
                blanks.push(line_no);
            }
            continue;
        }
        let err = |message: String| Error::Parse {
            path: path.to_path_buf(),
            line: line_no,
            message,
        };
        // A header names columns: `frame ulx uly ...` (not `frame00001.jpg lost`).
        let is_header = first_content
            && tokens.len() > 2
            && tokens[0].parse::<f64>().is_err()
            && tokens.iter().skip(1).all(|t| t.parse::<f64>().is_err());
        first_content = false;
        if is_header {
            continue;
        }
        let (frame, nums) =
            if tokens.len() == 1 && NO_CORNERS.contains(&tokens[0].to_ascii_lowercase().as_str()) {
                (None, &tokens[..])
            } else if tokens[0].parse::<f64>().is_err() {
                (Some(tokens[0].to_string()), &tokens[1..])
            } else {
                (None, &tokens[..])
            };
        if named.is_none() {
            named = Some(frame.is_some());
        }
        for line in blanks.drain(..) {
            out.push(GtEntry {
                frame: None,
                quad: None,
                line,
            });
        }
        if nums.len() == 1 && NO_CORNERS.contains(&nums[0].to_ascii_lowercase().as_str()) {
            out.push(GtEntry {
                frame,
                quad: None,
                line: line_no,
            });
            continue;
        }
        if nums.len() != 8 {
            return Err(err(format!(
                "expected 8 numbers (ulx uly urx ury lrx lry llx lly){}, found {}",
                if frame.is_some() {
                    " after the frame name"
                } else {
                    ""
                },
                nums.len()
            )));
        }
        let mut v = [0.0f64; 8];
        for (k, t) in nums.iter().enumerate() {
            v[k] = t.parse::<f64>().map_err(|_| {
                err(format!(
                    "'{}' is not a number (value {} of 8)",
                    crate::error::short_text(t),
                    k + 1
                ))
            })?;
            if !v[k].is_finite() {
                return Err(err(format!(
                    "'{}' is not a finite number (value {} of 8)",
                    crate::error::short_text(t),
                    k + 1
                )));
            }
        }
        out.push(GtEntry {
            frame,
            quad: Some(Quad::from_array(v)),
            line: line_no,
        });
    }
    Ok(out)
}

/// Parses ground-truth bytes: text that is not UTF-8 is an error naming the line; a byte-order
/// mark is not part of the first line.
pub fn parse_ground_truth_bytes(path: &Path, bytes: &[u8]) -> Result<Vec<GtEntry>> {
    let text = crate::files::text_of(path, bytes.to_vec())?;
    parse_ground_truth(path, &text)
}

/// Reads and parses a ground-truth file.
pub fn read_ground_truth(path: &Path) -> Result<Vec<GtEntry>> {
    let text = crate::files::read_text(path, crate::files::TEXT_LIMIT)?;
    parse_ground_truth(path, &text)
}

/// Writes ground truth atomically: with `names`, in the MTF format (header, frame names); else
/// 8 numbers per line. Frames without corners are written `occluded` where `occluded` says so,
/// `none` otherwise. Names that a line cannot hold (one with a space, an empty one) make the
/// whole file 8 numbers per line, its lines the frames in order (the file's own frames, listed,
/// are then taken by position): a made-up name would name a frame that does not exist.
pub fn write_ground_truth(
    path: &Path,
    quads: &[Option<Quad>],
    occluded: &[bool],
    names: Option<&[String]>,
) -> Result<()> {
    let names = names.filter(|names| {
        (0..quads.len()).all(|i| {
            names
                .get(i)
                .is_some_and(|n| !n.is_empty() && !n.contains(char::is_whitespace))
        })
    });
    let mut text = String::new();
    if names.is_some() {
        text.push_str("frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n");
    }
    for (i, q) in quads.iter().enumerate() {
        if let Some(names) = names {
            text.push_str(&names[i]);
            text.push(' ');
        }
        match q {
            Some(q) => {
                let v: Vec<String> = q.to_array().iter().map(|v| format!("{v:.4}")).collect();
                text.push_str(&v.join(" "));
            }
            None if occluded.get(i).copied().unwrap_or(false) => text.push_str("occluded"),
            None => text.push_str("none"),
        }
        text.push('\n');
    }
    write_atomic(path, text.as_bytes())
}

/// Writes corners in the TMT/MTF format (`frame ulx uly ...` header, `frame%05d.<ext>` names,
/// `lost` for frames without corners), atomically: to a temporary file renamed over `path`.
pub fn write_corners(path: &Path, corners: &[Option<Quad>], ext: &str) -> Result<()> {
    let names: Vec<String> = (0..corners.len())
        .map(|i| format!("frame{:05}.{ext}", i + 1))
        .collect();
    write_corners_named(path, corners, &names)
}

/// Like [`write_corners`] with the frames' own file names.
pub fn write_corners_named(path: &Path, corners: &[Option<Quad>], names: &[String]) -> Result<()> {
    let mut text = String::from("frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n");
    for (i, q) in corners.iter().enumerate() {
        match names
            .get(i)
            .filter(|n| !n.is_empty() && !n.contains(char::is_whitespace))
        {
            Some(n) => text.push_str(n),
            None => text.push_str(&format!("frame{:05}", i + 1)),
        }
        match q {
            Some(q) => {
                for v in q.to_array() {
                    text.push_str(&format!(" {v:.4}"));
                }
            }
            None => text.push_str(" lost"),
        }
        text.push('\n');
    }
    write_atomic(path, text.as_bytes())
}

/// Writes a file atomically: a temporary file in the same folder, synced, then renamed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // By pid and host: on a shared file system another node's job has pids of its own.
    let tmp = dir.join(format!(".{name}.tmp{}@{}", std::process::id(), host_name()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
}

/// This machine's name, as temporaries and locks on a shared file system name their owner
/// (`/proc/sys/kernel/hostname`, else `$HOSTNAME` or `$COMPUTERNAME`, else `localhost`), with
/// only letters, digits, `-` and `.` kept.
pub fn host_name() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .or_else(|| std::env::var("COMPUTERNAME").ok())
        .unwrap_or_default();
    let name: String = raw
        .trim()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '.')
        .collect();
    if name.is_empty() {
        "localhost".into()
    } else {
        name
    }
}

/// Whether process `pid` of host `host` (`None`: this one, a name from before temporaries
/// named their host) may still run: on this host, `/proc/<pid>` (elsewhere than Linux, a file
/// younger than an hour); on another host nothing can be checked from here, and a file younger
/// than a day is taken as live.
pub fn owner_may_run(pid: u32, host: Option<&str>, age: Option<std::time::Duration>) -> bool {
    let local = host.is_none_or(|h| h == host_name());
    if local && pid == std::process::id() {
        return true;
    }
    if local && Path::new("/proc/self").exists() {
        return Path::new("/proc").join(pid.to_string()).exists();
    }
    let limit = if local { 3600 } else { 24 * 3600 };
    age.is_none_or(|a| a.as_secs() <= limit)
}

/// Removes the temporary files [`write_atomic`] leaves when its process is killed
/// (`.<name>.tmp<pid>@<host>`) under `dir`, recursively, when that process is gone
/// ([`owner_may_run`]: a live job on another node sharing the folder keeps its files). Returns
/// how many were removed.
pub fn remove_stale_temporaries(dir: &Path) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for e in rd.flatten() {
        let p = e.path();
        let Ok(kind) = e.file_type() else { continue };
        if kind.is_dir() {
            removed += remove_stale_temporaries(&p);
            continue;
        }
        let name = e.file_name().to_string_lossy().into_owned();
        let Some((pid, host)) = name
            .strip_prefix('.')
            .and_then(|n| n.rsplit_once(".tmp"))
            .and_then(|(_, owner)| {
                let (pid, host) = match owner.split_once('@') {
                    Some((p, h)) => (p, Some(h)),
                    None => (owner, None),
                };
                Some((pid.parse::<u32>().ok()?, host))
            })
        else {
            continue;
        };
        let age = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok());
        let gone = !owner_may_run(pid, host, age);
        if gone && std::fs::remove_file(&p).is_ok() {
            removed += 1;
        }
    }
    removed
}
