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

/// The records of a journal, what was skipped, and whether its last line was cut short (a crash
/// mid-write).
#[derive(Debug, Default)]
pub struct Parsed {
    /// Records with their 1-based line numbers.
    pub records: Vec<(usize, Record)>,
    /// The last line is incomplete and does not parse (a crash mid-write): ignored.
    pub truncated_tail: bool,
    /// Lines (or parts of lines) that were not records and were skipped, each as
    /// `file:line: why`. Every intact record around them is read.
    pub skipped: Vec<String>,
}

/// Where a record begins: serde writes the tag first.
const RECORD_START: &[u8] = b"{\"kind\":";

fn parse_record(raw: &[u8]) -> std::result::Result<Option<Record>, String> {
    let text = std::str::from_utf8(raw)
        .map_err(|e| format!("not UTF-8 text (byte {})", e.valid_up_to() + 1))?;
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    serde_json::from_str::<Record>(text)
        .map(Some)
        .map_err(|e| format!("not a journal record: {e}"))
}

/// Parses journal bytes. A line that is not a record is skipped and reported (naming `path` and
/// the 1-based line); when a record follows a fragment on the same line (a write cut short, then
/// a later append), the record is read. The last line counts even without its newline. Errors
/// (naming `path` and the line) only for a journal that cannot be read at all: a newer format, a
/// first record that is not the header, or no record in a non-empty file.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Parsed> {
    let mut out = Parsed::default();
    let complete = bytes.last().is_none_or(|&b| b == b'\n');
    let lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
    let last = lines.len().saturating_sub(1);
    let mut first_bad: Option<(usize, String)> = None;
    for (i, raw) in lines.iter().enumerate() {
        let line_no = i + 1;
        match parse_record(raw) {
            Ok(Some(r)) => out.records.push((line_no, r)),
            Ok(None) => {}
            // A crash while appending leaves at most the last line incomplete.
            Err(_) if i == last && !complete => out.truncated_tail = true,
            Err(m) => {
                // A fragment, then a whole record appended after it on the same line.
                let recovered = (1..raw.len())
                    .filter(|&k| raw[k..].starts_with(RECORD_START))
                    .find_map(|k| parse_record(&raw[k..]).ok().flatten().map(|r| (k, r)));
                let what = match &recovered {
                    Some((k, _)) => format!("{} byte(s) before a record skipped ({m})", k),
                    None => format!("skipped, {m}"),
                };
                first_bad.get_or_insert((line_no, m));
                out.skipped
                    .push(format!("{}:{line_no}: {what}", path.display()));
                if let Some((_, r)) = recovered {
                    out.records.push((line_no, r));
                }
            }
        }
    }
    let err = |line: usize, message: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    match out.records.first() {
        None => {
            if let Some((line, m)) = first_bad {
                return Err(err(line, format!("not a corrections journal ({m})")));
            }
        }
        Some((_, Record::Header { format, .. })) if *format <= FORMAT => {}
        Some((line, Record::Header { format, .. })) => {
            return Err(err(
                *line,
                format!("journal format {format} is newer than this regtrack reads ({FORMAT})"),
            ));
        }
        // A damaged header (one flipped byte) before intact records: the records are kept,
        // and the damage said (the journal's name still says whose it is).
        Some((line, _)) if *line > 1 && first_bad.as_ref().is_some_and(|(l, _)| *l == 1) => {
            out.skipped.push(format!(
                "{}:1: the header is damaged; the records after it are kept",
                path.display()
            ));
        }
        Some((line, _)) => {
            return Err(err(
                *line,
                "the journal does not start with its header".into(),
            ));
        }
    }
    Ok(out)
}

/// The sequence a parsed journal's header names.
pub fn sequence_of(parsed: &Parsed) -> Option<&str> {
    match parsed.records.first() {
        Some((_, Record::Header { sequence, .. })) => Some(sequence),
        _ => None,
    }
}

/// Checks a correction: an occlusion, or a usable quad ([`crate::geometry::Quad::unusable`]:
/// what the editor can make and the evaluation can use).
pub fn check_mark(m: &Mark) -> std::result::Result<(), String> {
    match m {
        Mark::Quad(v) => match crate::geometry::Quad::from_array(*v).unusable() {
            Some(why) => Err(why),
            None => Ok(()),
        },
        Mark::Occluded => Ok(()),
    }
}

/// Reads a journal file (`Ok(None)` when there is none).
pub fn read(path: &Path) -> Result<Option<Parsed>> {
    match crate::files::read_optional(path, crate::files::JOURNAL_LIMIT)? {
        Some(bytes) => parse(path, &bytes).map(Some),
        None => Ok(None),
    }
}

/// Appends records to a journal file, each synced to disk before [`Writer::append`] returns.
///
/// Opening writes nothing: the file (with its header) is created by the first append. The
/// journal is never rewritten; it is only ever cut back to the end of its last intact record,
/// and only before an append: a last line cut short by a crash (it does not parse: its edit was
/// never acknowledged) before the first, and what a failed append left (a full disk) before the
/// next. A last record that is whole but lacks its newline is kept and ended first.
#[derive(Debug)]
pub struct Writer {
    path: PathBuf,
    sequence: String,
    file: Option<std::fs::File>,
    /// The journal's length up to the end of its last intact record.
    good_len: u64,
    /// What must be repaired before the next record is written.
    pending: Pending,
    /// The intact part ends with a newline (else one is written before the next record).
    ends_with_newline: bool,
    /// The journal has no header yet (a new file).
    needs_header: bool,
    /// The journal's length when it was read (0: there was none): on the first append, a
    /// journal of another length was written by someone else since (another inspector with
    /// the same sequence open), whose records this writer's replay has not seen.
    read_len: u64,
    faults: Faults,
}

/// Faults injected into a [`Writer`], for the tests that kill and starve it: a disk of
/// `capacity` bytes (a write past it writes what fits, then fails as a full disk does), and a
/// pause between a record's write and its sync (where a kill lands between the two).
#[doc(hidden)]
#[derive(Clone, Copy, Debug, Default)]
pub struct Faults {
    pub capacity: Option<u64>,
    pub pause_before_sync: std::time::Duration,
    /// The most a journal may hold, instead of [`crate::files::JOURNAL_LIMIT`].
    pub limit: Option<u64>,
}

/// The state of a journal's end, before the next append.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pending {
    /// It ends with a whole line.
    Nothing,
    /// Its last record is whole but has no newline: one is written first.
    Newline,
    /// It ends with part of a record (a crash, a failed append): cut back to `good_len` first.
    Cut,
}

impl Writer {
    /// Prepares appending to the journal at `path` (which may not exist yet); writes nothing.
    pub fn open(path: &Path, sequence: &str) -> Result<Writer> {
        let bytes = crate::files::read_optional(path, crate::files::JOURNAL_LIMIT)?;
        let read_len = bytes.as_ref().map_or(0, |b| b.len() as u64);
        let (good_len, pending, needs_header) = match bytes {
            Some(b) if b.is_empty() => (0, Pending::Nothing, true),
            Some(b) => {
                let tail_start = b.iter().rposition(|&c| c == b'\n').map_or(0, |i| i + 1);
                let (good_len, pending) = if tail_start == b.len() {
                    (b.len(), Pending::Nothing)
                } else if parse_record(&b[tail_start..]).is_ok_and(|r| r.is_some()) {
                    (b.len(), Pending::Newline)
                } else {
                    (tail_start, Pending::Cut)
                };
                let header = b[..good_len]
                    .split(|&c| c == b'\n')
                    .any(|l| matches!(parse_record(l), Ok(Some(Record::Header { .. }))));
                (good_len as u64, pending, !header)
            }
            None => (0, Pending::Nothing, true),
        };
        Ok(Writer {
            path: path.to_path_buf(),
            sequence: sequence.to_string(),
            file: None,
            good_len,
            pending,
            ends_with_newline: pending != Pending::Newline,
            needs_header,
            read_len,
            faults: Faults::default(),
        })
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Injects faults (tests only).
    #[doc(hidden)]
    pub fn inject(&mut self, faults: Faults) {
        self.faults = faults;
    }

    /// The file, opened for appending (created, with its folder, on the first append).
    fn file(&mut self) -> Result<&mut std::fs::File> {
        if self.file.is_none() {
            let created = !self.path.exists();
            if let Some(d) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
            }
            let f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)
                .map_err(|e| Error::io(&self.path, e))?;
            // One writer at a time: the lock is held while this writer lives (a file system
            // without locks is written without). Then the journal must be as it was read: a
            // writer that appended after another would number its edits from a replay that
            // missed the other's, and its repairs would cut the other's records.
            match f.try_lock() {
                Ok(()) | Err(std::fs::TryLockError::Error(_)) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(Error::Refused(format!(
                        "{}: another regtrack is writing to this corrections journal (the \
                         sequence is open in another inspector); nothing was saved here: close \
                         the other, then reopen the sequence",
                        self.path.display()
                    )));
                }
            }
            let len = f.metadata().map_err(|e| Error::io(&self.path, e))?.len();
            if len != self.read_len {
                return Err(Error::Refused(format!(
                    "{}: the corrections journal was written by another regtrack since the \
                     sequence was opened ({} bytes then, {len} now); nothing was saved here: \
                     reopen the sequence to continue from its corrections",
                    self.path.display(),
                    self.read_len
                )));
            }
            // A new journal's folder entry must reach the disk too.
            if created
                && let Some(d) = self.path.parent().filter(|d| !d.as_os_str().is_empty())
                && let Ok(dir) = std::fs::File::open(d)
            {
                let _ = dir.sync_all();
            }
            self.file = Some(f);
        }
        Ok(self.file.as_mut().expect("opened above"))
    }

    /// Cuts the journal back to the end of its last intact record.
    fn cut(&mut self) -> Result<()> {
        let len = self.good_len;
        let path = self.path.clone();
        let f = self.file()?;
        f.set_len(len)
            .and_then(|()| f.sync_all())
            .map_err(|e| Error::io(&path, e))?;
        self.pending = if self.ends_with_newline {
            Pending::Nothing
        } else {
            Pending::Newline
        };
        Ok(())
    }

    /// Appends one record and syncs it to disk. When that fails, nothing of it is left (or what
    /// is left is cut off before the next append), so the journal stays readable.
    pub fn append(&mut self, r: &Record) -> Result<()> {
        let line = |r: &Record| {
            serde_json::to_string(r)
                .map(|mut l| {
                    l.push('\n');
                    l
                })
                .map_err(|e| Error::InvalidParameter(e.to_string()))
        };
        let mut bytes = String::new();
        if self.pending == Pending::Cut {
            self.cut()?;
        }
        if self.pending == Pending::Newline {
            bytes.push('\n');
        }
        if self.needs_header {
            bytes += &line(&Record::Header {
                format: FORMAT,
                sequence: self.sequence.clone(),
            })?;
        }
        bytes += &line(r)?;
        // A journal is read whole, up to JOURNAL_LIMIT: a record that would take it past that
        // is refused, so that every record it holds can still be read back.
        let limit = self.faults.limit.unwrap_or(crate::files::JOURNAL_LIMIT);
        if self.good_len + bytes.len() as u64 > limit {
            return Err(Error::Refused(format!(
                "{} is full (its reader takes {} bytes): export the ground truth, then move the \
                 journal away to start a new one",
                self.path.display(),
                limit
            )));
        }
        let path = self.path.clone();
        let (good_len, faults) = (self.good_len, self.faults);
        let f = self.file()?;
        let written =
            write_synced(f, bytes.as_bytes(), good_len, faults).map_err(|e| Error::io(&path, e));
        match written {
            Ok(()) => {
                self.good_len += bytes.len() as u64;
                self.pending = Pending::Nothing;
                self.ends_with_newline = true;
                self.needs_header = false;
                Ok(())
            }
            Err(e) => {
                // Part of the record may be on disk: cut it off now, or before the next append.
                self.pending = Pending::Cut;
                let _ = self.cut();
                Err(e)
            }
        }
    }
}

/// Writes `bytes` at the end of `f` (which is `len` bytes long) and syncs them, under `faults`.
fn write_synced(
    f: &mut std::fs::File,
    bytes: &[u8],
    len: u64,
    faults: Faults,
) -> std::io::Result<()> {
    let room = faults
        .capacity
        .map_or(bytes.len() as u64, |c| c.saturating_sub(len));
    if room < bytes.len() as u64 {
        f.write_all(&bytes[..room as usize])?;
        return Err(std::io::Error::new(
            std::io::ErrorKind::StorageFull,
            "No space left on device (injected)",
        ));
    }
    f.write_all(bytes)?;
    if !faults.pause_before_sync.is_zero() {
        std::thread::sleep(faults.pause_before_sync);
    }
    f.sync_data()
}
