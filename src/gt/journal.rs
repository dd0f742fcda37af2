//! The corrections journal: one JSON record per line, appended and synced to disk before an edit
//! takes effect, so that a crash (even `kill -9`) loses nothing. Reopening the sequence replays
//! it. A last line cut short by a crash mid-write is ignored (and reported); any other malformed
//! line is an error naming the file and the line.
//!
//! ```text
//! {"kind":"header","format":1,"sequence":"bookI"}
//! {"kind":"edit","id":1,"label":"move corner 2","changes":[{"ssm":"similitude","frame":12,"before":null,"after":{"quad":[..8 numbers..]}}]}
//! {"kind":"undo","id":1}
//! {"kind":"redo","id":1}
//! {"kind":"export","paths":["bookI_gt_similitude.txt","OptGT/bookI_similitude.txt"]}
//! ```

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The journal format version this build writes and reads.
pub const FORMAT: u32 = 1;

/// A frame's correction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mark {
    /// Corrected corners `ulx uly urx ury lrx lry llx lly`.
    Quad([f64; 8]),
    /// Occluded or not annotatable: no corners, skipped by the evaluation.
    Occluded,
}

/// One frame's change in an edit: what it was and what it became (`None`: no correction, the
/// original ground truth).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Change {
    pub ssm: String,
    pub frame: usize,
    pub before: Option<Mark>,
    pub after: Option<Mark>,
}

/// One line of the journal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Record {
    Header {
        format: u32,
        sequence: String,
    },
    /// An edit: one undoable step, over one or many frames.
    Edit {
        id: u64,
        label: String,
        changes: Vec<Change>,
    },
    Undo {
        id: u64,
    },
    Redo {
        id: u64,
    },
    /// The corrected ground truth was exported to these files.
    Export {
        paths: Vec<String>,
    },
}

/// The records of a journal, and whether its last line was cut short (a crash mid-write).
#[derive(Debug, Default)]
pub struct Parsed {
    /// Records with their 1-based line numbers.
    pub records: Vec<(usize, Record)>,
    pub truncated_tail: bool,
}

/// Parses journal bytes; errors name `path` and the 1-based line.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Parsed> {
    let mut out = Parsed::default();
    let complete = bytes.last().is_none_or(|&b| b == b'\n');
    let lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
    let last = lines.len().saturating_sub(1);
    for (i, raw) in lines.iter().enumerate() {
        let line_no = i + 1;
        let err = |message: String| Error::Parse {
            path: path.to_path_buf(),
            line: line_no,
            message,
        };
        let parsed = std::str::from_utf8(raw)
            .map_err(|e| format!("not UTF-8 text (byte {})", e.valid_up_to() + 1))
            .and_then(|text| {
                let text = text.trim();
                if text.is_empty() {
                    return Ok(None);
                }
                serde_json::from_str::<Record>(text)
                    .map(Some)
                    .map_err(|e| format!("not a journal record: {e}"))
            });
        match parsed {
            Ok(Some(r)) => out.records.push((line_no, r)),
            Ok(None) => {}
            // A crash while appending leaves at most the last line incomplete.
            Err(_) if i == last && !complete => out.truncated_tail = true,
            Err(m) => return Err(err(m)),
        }
    }
    match out.records.first() {
        None => {}
        Some((_, Record::Header { format, .. })) if *format <= FORMAT => {}
        Some((_, Record::Header { format, .. })) => {
            return Err(Error::Parse {
                path: path.to_path_buf(),
                line: 1,
                message: format!(
                    "journal format {format} is newer than this regtrack reads ({FORMAT})"
                ),
            });
        }
        Some((line, _)) => {
            return Err(Error::Parse {
                path: path.to_path_buf(),
                line: *line,
                message: "the journal does not start with its header".into(),
            });
        }
    }
    Ok(out)
}

/// Reads a journal file (`Ok(None)` when there is none).
pub fn read(path: &Path) -> Result<Option<Parsed>> {
    match std::fs::read(path) {
        Ok(bytes) => parse(path, &bytes).map(Some),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(path, e)),
    }
}

/// Appends records to a journal file, each synced to disk before [`Writer::append`] returns.
#[derive(Debug)]
pub struct Writer {
    path: PathBuf,
    file: std::fs::File,
}

impl Writer {
    /// Opens (or creates, with its header) the journal at `path`. A last line cut short by a
    /// crash is ended first, so that new records start on a line of their own.
    pub fn open(path: &Path, sequence: &str) -> Result<Writer> {
        if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
        }
        let existing = match std::fs::read(path) {
            Ok(b) => Some(b),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(Error::io(path, e)),
        };
        // A record cut short by a crash was never acknowledged (its edit never took effect):
        // it is cut off, so that new records start on a line of their own.
        if let Some(b) = &existing
            && b.last().is_some_and(|&c| c != b'\n')
        {
            let keep = b.iter().rposition(|&c| c == b'\n').map_or(0, |i| i + 1);
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .map_err(|e| Error::io(path, e))?;
            f.set_len(keep as u64)
                .and_then(|()| f.sync_all())
                .map_err(|e| Error::io(path, e))?;
        }
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| Error::io(path, e))?;
        let mut w = Writer {
            path: path.to_path_buf(),
            file,
        };
        let has_header = existing.as_ref().is_some_and(|b| b.contains(&b'\n'));
        if !has_header {
            w.append(&Record::Header {
                format: FORMAT,
                sequence: sequence.to_string(),
            })?;
        }
        // The journal's folder entry must reach the disk too.
        if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty())
            && let Ok(dir) = std::fs::File::open(d)
        {
            let _ = dir.sync_all();
        }
        Ok(w)
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write_raw(&mut self, bytes: &[u8]) -> Result<()> {
        self.file
            .write_all(bytes)
            .and_then(|()| self.file.sync_data())
            .map_err(|e| Error::io(&self.path, e))
    }

    /// Appends one record and syncs it to disk.
    pub fn append(&mut self, r: &Record) -> Result<()> {
        let mut line =
            serde_json::to_string(r).map_err(|e| Error::InvalidParameter(e.to_string()))?;
        line.push('\n');
        self.write_raw(line.as_bytes())
    }
}
