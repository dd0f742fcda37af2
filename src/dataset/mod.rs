//! Sequences and ground truth: discovery of the supported layouts, frame loading, ground-truth
//! files, datasets of several sequences, and synthetic sequences with exact ground truth.
//!
//! Layouts:
//! - **MTF/TMT**: `<root>/<seq>.txt` (header line, then `frame00001.jpg ulx uly urx ury lrx lry
//!   llx lly`), frames in `<root>/<seq>/frame%05d.jpg`;
//! - **folder of images** (png, jpg, pgm/ppm, sorted by name) with an optional ground-truth file of
//!   8 numbers per line (`groundtruth.txt`, `gt.txt` or `<folder>.txt` inside it, or given);
//! - **POT**: `<seq>_gt_points.txt` with 8 numbers per annotated frame, frames in `<seq>/`,
//!   `<seq>/img/` or beside the file. When the file has half as many lines as there are frames,
//!   every other frame (the first, third, ...) is annotated.

pub mod demo;
mod groundtruth;
pub mod layouts;
pub mod live;
pub mod regions;
pub mod synth;
pub mod video;

pub use groundtruth::{
    GtEntry, host_name, owner_may_run, parse_ground_truth, parse_ground_truth_bytes,
    read_ground_truth, remove_stale_temporaries, write_atomic, write_corners, write_corners_named,
    write_ground_truth,
};
pub use layouts::{Entry, Layout};

use crate::error::{Error, Result};
use crate::geometry::Quad;
use crate::imaging::{self, GrayU8};
use std::path::{Path, PathBuf};

/// Image file extensions a sequence may hold.
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "pgm", "ppm", "pnm"];

/// A sequence of frames with optional ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Sequence {
    /// Name (the MTF sequence name or the folder's name).
    pub name: String,
    /// Frame files in order.
    pub frames: Vec<PathBuf>,
    /// Ground truth per frame (`None` where a frame is not annotated); empty without a file.
    pub ground_truth: Vec<Option<Quad>>,
    /// The ground-truth file, if any.
    pub gt_path: Option<PathBuf>,
    /// What was wrong but could be read around, each naming the file and line: ground-truth
    /// corners that are not a usable quad (the frame is then not annotated). Shown by the
    /// command line and the inspector.
    pub warnings: Vec<String>,
    /// The video the frames are decoded from (`frames` then names them `<video>#<n>`).
    pub video: Option<std::sync::Arc<video::Video>>,
    /// The layout it was read in.
    pub layout: Layout,
    /// Its challenge factors (attributes) as its benchmark names them (POT's from the name,
    /// PlanarTrack's from its attribute file); results are also pooled by each.
    pub factors: Vec<String>,
    /// The benchmark's ground-truth homographies from the first frame to each frame (POT,
    /// PlanarTrack), where given (`None` where a frame is not annotated); empty otherwise.
    pub homographies: Vec<Option<nalgebra::Matrix3<f64>>>,
    /// The first frame's size, read once (every frame must have it).
    first_size: std::sync::OnceLock<(usize, usize)>,
}

fn is_image(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// The image files of a folder, in natural order ([`natural_cmp`]: `frame2` before `frame10`).
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_image(p))
        .collect();
    sort_natural(&mut v);
    Ok(v)
}

/// Sorts paths in the natural order of their file names ([`natural_cmp`]).
pub fn sort_natural(paths: &mut [PathBuf]) {
    paths.sort_by(|a, b| {
        let name = |p: &PathBuf| p.file_name().map(|n| n.to_string_lossy().into_owned());
        natural_cmp(&name(a).unwrap_or_default(), &name(b).unwrap_or_default()).then(a.cmp(b))
    });
}

/// The natural order of names: runs of digits compare by their value (`frame2` before
/// `frame10`, `frame007` beside `frame7`), the rest character by character; names equal so
/// compare by their text.
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    use std::cmp::Ordering;
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    let digits = |s: &[u8]| s.iter().take_while(|c| c.is_ascii_digit()).count();
    while let (Some(&c), Some(&d)) = (x.first(), y.first()) {
        if c.is_ascii_digit() && d.is_ascii_digit() {
            let (n, m) = (digits(x), digits(y));
            let strip = |s: &[u8]| {
                let z = s.iter().take_while(|&&c| c == b'0').count();
                s[z.min(s.len().saturating_sub(1))..].to_vec()
            };
            let (u, v) = (strip(&x[..n]), strip(&y[..m]));
            let by_value = u.len().cmp(&v.len()).then_with(|| u.cmp(&v));
            if by_value != Ordering::Equal {
                return by_value;
            }
            (x, y) = (&x[n..], &y[m..]);
        } else {
            if c != d {
                return c.cmp(&d);
            }
            (x, y) = (&x[1..], &y[1..]);
        }
    }
    x.len().cmp(&y.len()).then_with(|| a.cmp(b))
}

/// Frames [`Sequence::each_frame`] decodes ahead of the one being used, at most.
const READ_AHEAD: usize = 4;

impl Sequence {
    /// Calls `f` with each frame of `range` in order ([`Sequence::load_frame`]'s result, in
    /// colour when `colour`: an error names the file) until `f` breaks (its value is returned) or the frames end
    /// (`None`). With `ahead`, another thread decodes the next frames meanwhile (at most
    /// `READ_AHEAD` ahead): a tracker then waits for no decoding (on a sequence of JPEG
    /// files, most of a run's time), at the cost of a core; without it, or when no thread can
    /// be started, the frames are read in turn. `f` runs on the calling thread.
    pub fn each_frame<B>(
        &self,
        range: std::ops::Range<usize>,
        ahead: bool,
        colour: bool,
        mut f: impl FnMut(usize, Result<imaging::Frame8>) -> std::ops::ControlFlow<B>,
    ) -> Option<B> {
        use std::ops::ControlFlow::{Break, Continue};
        let in_turn = |range: std::ops::Range<usize>,
                       f: &mut dyn FnMut(
            usize,
            Result<imaging::Frame8>,
        ) -> std::ops::ControlFlow<B>| {
            for i in range {
                if let Break(b) = f(i, self.load_frame(i, colour)) {
                    return Some(b);
                }
            }
            None
        };
        if !ahead || range.len() < 2 {
            return in_turn(range, &mut f);
        }
        std::thread::scope(|scope| {
            let (tx, rx) = std::sync::mpsc::sync_channel(READ_AHEAD);
            let frames = range.clone();
            let reader = std::thread::Builder::new()
                .name("regtrack-frames".into())
                .spawn_scoped(scope, move || {
                    for i in frames {
                        // The receiver is gone once `f` broke: stop reading.
                        if tx.send((i, self.load_frame(i, colour))).is_err() {
                            break;
                        }
                    }
                });
            if reader.is_err() {
                return in_turn(range, &mut f);
            }
            // Dropping the receiver (on a break) ends the reader's loop.
            for (i, frame) in rx {
                match f(i, frame) {
                    Break(b) => return Some(b),
                    Continue(()) => {}
                }
            }
            None
        })
    }

    /// Opens a sequence from a ground-truth file (MTF `<seq>.txt` or POT `_gt_points.txt`) or a
    /// folder of images, finding the other half as described in the module documentation.
    pub fn open(path: &Path) -> Result<Self> {
        if path.is_dir() {
            let dir = path;
            let name = file_name(dir);
            // MTF layout with the folder given: <root>/<seq>.txt beside it.
            let sibling = dir.with_extension("txt");
            if sibling.is_file() {
                return Self::open_gt_file(&sibling);
            }
            // VOT, GOT-10k, LaSOT or a folder with its `groundtruth.txt`.
            if dir.join("groundtruth.txt").is_file() {
                return layouts::open_folder(dir);
            }
            let gt = [
                "groundtruth.txt",
                "gt.txt",
                &format!("{name}.txt"),
                &format!("{name}_gt_points.txt"),
            ]
            .iter()
            .map(|f| dir.join(f))
            .find(|p| p.is_file());
            let frames_dir = if dir.join("img").is_dir() {
                dir.join("img")
            } else {
                dir.to_path_buf()
            };
            Self::from_parts(&name, &frames_dir, gt.as_deref())
        } else if path.is_file() && video::is_video(path) {
            Self::from_video(path)
        } else if path.is_file() {
            // A benchmark's annotation file (POT, PlanarTrack, UCSB): opened as its dataset
            // root lays it out, flags and homographies with it.
            if let Some(e) = layouts::entry_of_file(path) {
                return e.open();
            }
            Self::open_gt_file(path)
        } else if path.exists() {
            Err(Error::Sequence {
                path: path.to_path_buf(),
                message: "is neither a ground-truth file nor a folder of frames".into(),
            })
        } else {
            Err(Error::Missing {
                path: path.to_path_buf(),
            })
        }
    }

    fn open_gt_file(gt: &Path) -> Result<Self> {
        let stem = gt
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut name = stem.strip_suffix("_gt_points").unwrap_or(&stem).to_string();
        let mut parent = gt.parent().unwrap_or(Path::new(".")).to_path_buf();
        // An exported correction (`<seq>_gt_<ssm>.txt` beside the original) or a low-DOF ground
        // truth in MTF's OptGT layout (`<root>/OptGT/<seq>_<ssm>.txt`): the frames are the
        // sequence's.
        let ssm_suffix = |s: &str, sep: &str| {
            crate::ssm::REGISTRY.iter().find_map(|e| {
                s.strip_suffix(&format!("{sep}{}", e.name))
                    .filter(|base| !base.is_empty())
                    .map(str::to_string)
            })
        };
        if parent.file_name().is_some_and(|n| n == "OptGT")
            && let Some(base) = ssm_suffix(&name, "_")
        {
            name = base;
            parent = parent.parent().unwrap_or(Path::new(".")).to_path_buf();
        } else if let Some(base) = ssm_suffix(&name, "_gt_")
            && !parent.join(&name).is_dir()
        {
            name = base;
        }
        let parent = parent.as_path();
        // A video with the ground truth's name beside it (`clip.txt` and `clip.mp4`), when there
        // is no folder of frames.
        if !parent.join(&name).is_dir()
            && let Some(v) = video_beside(parent, &name)
        {
            // With this ground truth (an export or an OptGT file is the video's frames' too).
            return Self::from_video_and_gt(&v, Some(gt));
        }
        let candidates = [
            parent.join(&name).join("img"),
            parent.join(&name),
            parent.to_path_buf(),
        ];
        let frames_dir = candidates
            .iter()
            .find(|d| d.is_dir() && list_images(d).map(|v| !v.is_empty()).unwrap_or(false))
            .cloned()
            .ok_or_else(|| Error::Sequence {
                path: gt.to_path_buf(),
                message: format!(
                    "no frames found for sequence '{name}' (looked in {})",
                    candidates
                        .iter()
                        .map(|c| c.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
        Self::from_parts(&name, &frames_dir, Some(gt))
    }

    /// A sequence from a video file, with the ground truth beside it (`clip.txt` for
    /// `clip.mp4`: MTF format, its lines taken in order whatever frames they name, or 8 numbers
    /// per line), if any.
    pub fn from_video(path: &Path) -> Result<Self> {
        let gt = path.with_extension("txt");
        Self::from_video_and_gt(path, gt.is_file().then_some(gt.as_path()))
    }

    /// A sequence from a video file and the ground-truth file `gt` (read as
    /// [`Sequence::from_video`] reads `clip.txt`; `None`: not annotated).
    pub fn from_video_and_gt(path: &Path, gt: Option<&Path>) -> Result<Self> {
        let v = video::Video::open(path)?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "video".into());
        let frames: Vec<PathBuf> = (1..=v.frames)
            .map(|k| PathBuf::from(format!("{}#{k:05}", path.display())))
            .collect();
        let (ground_truth, gt_path, warnings) = if let Some(gt) = gt {
            let gt = gt.to_path_buf();
            let mut entries = read_ground_truth(&gt)?;
            let mut warnings = Vec::new();
            // A video cut short (a copy, a recording that stopped) keeps the frames it has.
            if entries.len() > frames.len() {
                warnings.push(format!(
                    "{}: {} ground-truth lines but {} has {} frames (cut short?): the \
                     sequence ends there",
                    gt.display(),
                    entries.len(),
                    path.display(),
                    frames.len()
                ));
                entries.truncate(frames.len());
            }
            if entries.len() < frames.len() {
                warnings.push(format!(
                    "{}: {} ground-truth lines for the {} frames of {}: frames {} to {} are not \
                     annotated",
                    gt.display(),
                    entries.len(),
                    frames.len(),
                    path.display(),
                    entries.len() + 1,
                    frames.len()
                ));
            }
            warnings.extend(drop_unusable(&gt, &mut entries));
            let mut quads: Vec<Option<Quad>> = entries.iter().map(|e| e.quad).collect();
            quads.resize(frames.len(), None);
            (quads, Some(gt), warnings)
        } else {
            (Vec::new(), None, Vec::new())
        };
        Ok(Sequence {
            name,
            frames,
            ground_truth,
            gt_path,
            warnings,
            video: Some(std::sync::Arc::new(v)),
            layout: Layout::Video,
            factors: Vec::new(),
            homographies: Vec::new(),
            first_size: Default::default(),
        })
    }

    /// A sequence from a folder of frames and an optional ground-truth file.
    pub fn from_parts(name: &str, frames_dir: &Path, gt: Option<&Path>) -> Result<Self> {
        let listed = list_images(frames_dir)?;
        let Some(gt) = gt else {
            if listed.is_empty() {
                return Err(Error::Sequence {
                    path: frames_dir.to_path_buf(),
                    message: "the folder holds no png, jpg or pgm image".into(),
                });
            }
            return Ok(Sequence {
                name: name.to_string(),
                frames: listed,
                ground_truth: Vec::new(),
                gt_path: None,
                warnings: Vec::new(),
                video: None,
                layout: Layout::Folder,
                factors: Vec::new(),
                homographies: Vec::new(),
                first_size: Default::default(),
            });
        };
        let mut entries = read_ground_truth(gt)?;
        if is_pot(gt) {
            // POT's rows of zeros are frames not annotated.
            for e in entries.iter_mut() {
                if e.quad
                    .is_some_and(|q| regions::is_unlabelled(&q.to_array()))
                {
                    e.quad = None;
                }
            }
        }
        let mut warnings = drop_unusable(gt, &mut entries);
        let named = entries.iter().all(|e| e.frame.is_some()) && !entries.is_empty();
        if named {
            let mut seen: std::collections::HashMap<&str, usize> = Default::default();
            for e in &entries {
                let f = e.frame.as_deref().unwrap_or_default();
                if let Some(first) = seen.insert(f, e.line) {
                    return Err(Error::Parse {
                        path: gt.to_path_buf(),
                        line: e.line,
                        message: format!(
                            "{} is listed twice (also on line {first})",
                            crate::error::short_text(f)
                        ),
                    });
                }
            }
        }
        let (frames, ground_truth) = if named {
            // MTF: the frames are the folder's images; each line is matched to its image by
            // name (a line without its image is an error, an image without a line a frame
            // not annotated).
            let gtv = match_by_name(gt, frames_dir, &listed, &entries, &mut warnings)?;
            (listed, gtv)
        } else {
            let n = listed.len();
            let m = entries.len();
            let quads: Vec<Option<Quad>> = entries.iter().map(|e| e.quad).collect();
            if m == 0 {
                (listed, Vec::new())
            } else if is_pot(gt) && m <= n && (2 * m == n || 2 * m == n + 1) && m > 1 {
                // Every other frame annotated (POT).
                let mut gtv = vec![None; n];
                for (k, q) in quads.into_iter().enumerate() {
                    gtv[2 * k] = q;
                }
                (listed, gtv)
            } else if m <= n {
                if m < n {
                    warnings.push(format!(
                        "{}: {m} lines for {n} frames in {} (a line per frame, blank for a frame \
                         not annotated): frames {} to {n} are not annotated",
                        gt.display(),
                        frames_dir.display(),
                        m + 1
                    ));
                }
                let mut gtv = quads;
                gtv.resize(n, None);
                (listed, gtv)
            } else {
                return Err(Error::Sequence {
                    path: gt.to_path_buf(),
                    message: format!(
                        "{m} ground-truth lines but only {n} frames in {}",
                        frames_dir.display()
                    ),
                });
            }
        };
        if frames.is_empty() {
            return Err(Error::Sequence {
                path: gt.to_path_buf(),
                message: "the sequence has no frames".into(),
            });
        }
        Ok(Sequence {
            name: name.to_string(),
            frames,
            ground_truth,
            gt_path: Some(gt.to_path_buf()),
            warnings,
            video: None,
            layout: Layout::Mtf,
            factors: Vec::new(),
            homographies: Vec::new(),
            first_size: Default::default(),
        })
    }

    /// A sequence of a benchmark's layout from its frames and the corners read from `gt` (a
    /// line each, `None` where a frame is not annotated): fewer lines than frames leave the
    /// last frames not annotated (POT's files of the annotated frames only, half as many, are
    /// the first, third, ... frames); more are an error, or cut at a video's end with a warning.
    pub fn from_quads(
        name: &str,
        frames: layouts::Frames,
        mut quads: Vec<Option<Quad>>,
        gt: &Path,
        layout: Layout,
    ) -> Result<Self> {
        let (frame_paths, video) = match frames {
            layouts::Frames::Dir(d) => (list_images(&d)?, None),
            layouts::Frames::Video(p) => {
                let v = video::Video::open(&p)?;
                let f: Vec<PathBuf> = (1..=v.frames)
                    .map(|k| PathBuf::from(format!("{}#{k:05}", p.display())))
                    .collect();
                (f, Some(std::sync::Arc::new(v)))
            }
        };
        let (n, m) = (frame_paths.len(), quads.len());
        if n == 0 {
            return Err(Error::Sequence {
                path: gt.to_path_buf(),
                message: format!("the sequence '{name}' has no frames"),
            });
        }
        let mut warnings = Vec::new();
        for (k, q) in quads.iter_mut().enumerate() {
            if let Some(why) = q.as_ref().and_then(unusable_quad) {
                warnings.push(format!(
                    "{}:{}: {why}: the frame is read as not annotated",
                    gt.display(),
                    k + 1
                ));
                *q = None;
            }
        }
        let quads = if layout == Layout::Pot && m > 1 && m < n && (2 * m == n || 2 * m == n + 1) {
            let mut v = vec![None; n];
            for (k, q) in quads.into_iter().enumerate() {
                v[2 * k] = q;
            }
            v
        } else if m > n && video.is_some() {
            warnings.push(format!(
                "{}: {m} ground-truth lines but the video has {n} frames (cut short?): the \
                 sequence ends there",
                gt.display()
            ));
            quads.truncate(n);
            quads
        } else if m > n {
            return Err(Error::Sequence {
                path: gt.to_path_buf(),
                message: format!("{m} ground-truth lines but only {n} frames for '{name}'"),
            });
        } else {
            if m < n {
                warnings.push(format!(
                    "{}: {m} lines for {n} frames: frames {} to {n} are not annotated",
                    gt.display(),
                    m + 1
                ));
            }
            quads.resize(n, None);
            quads
        };
        Ok(Sequence {
            name: name.to_string(),
            frames: frame_paths,
            ground_truth: quads,
            gt_path: Some(gt.to_path_buf()),
            warnings,
            video,
            layout,
            factors: Vec::new(),
            homographies: Vec::new(),
            first_size: Default::default(),
        })
    }

    /// The frames' names as result files list them: each image's file name (`frame%05d` by
    /// index for a video's frames).
    pub fn frame_names(&self) -> Vec<String> {
        (0..self.frames.len())
            .map(|i| match (&self.video, self.frames[i].file_name()) {
                (None, Some(n)) => n.to_string_lossy().into_owned(),
                _ => format!("frame{:05}", i + 1),
            })
            .collect()
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }
    /// Whether the sequence has no frames.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
    /// The ground truth of frame `i`, if annotated.
    pub fn ground_truth(&self, i: usize) -> Option<Quad> {
        self.ground_truth.get(i).copied().flatten()
    }
    /// Frame `i` as 8-bit grayscale; the error names the file.
    pub fn load_gray(&self, i: usize) -> Result<GrayU8> {
        match self.load_frame(i, false)? {
            imaging::Frame8::Gray(g) => Ok(g),
            imaging::Frame8::Colour(c) => Ok(c.gray),
        }
    }

    /// Frame `i`, in colour when `colour` (its three channels and its grey, for a tracker
    /// that reads colour, [`crate::imaging::ColourU8`]), else grey; the error names the file.
    pub fn load_frame(&self, i: usize, colour: bool) -> Result<imaging::Frame8> {
        let p = self.frames.get(i).ok_or_else(|| Error::Sequence {
            path: self.gt_path.clone().unwrap_or_default(),
            message: format!("frame index {i} out of range (0..{})", self.len()),
        })?;
        if let Some(v) = &self.video {
            if !colour {
                return Ok(imaging::Frame8::Gray(v.frame(i)?));
            }
            let (w, h) = (v.width, v.height);
            let rgb = v.frame_rgb(i)?;
            let frame = imaging::ColourU8::from_rgb(w, h, &rgb).ok_or_else(|| Error::Sequence {
                path: p.clone(),
                message: format!("frame {} decoded to the wrong size", i + 1),
            })?;
            return Ok(imaging::Frame8::Colour(frame));
        }
        let img = if colour {
            imaging::Frame8::Colour(imaging::load_colour(p)?)
        } else {
            imaging::Frame8::Gray(imaging::load_gray(p)?)
        };
        let (width, height) = (img.gray().width, img.gray().height);
        // Every frame has the first one's size (a tracker's coordinates are the first's).
        if i > 0 {
            let first = match self.first_size.get() {
                Some(&s) => s,
                None => {
                    let s = imaging::image_size(&self.frames[0])?;
                    *self.first_size.get_or_init(|| s)
                }
            };
            if (width, height) != first {
                return Err(Error::Image {
                    path: p.clone(),
                    message: format!(
                        "frame {} is {}x{}, but the sequence's first frame is {}x{}",
                        i + 1,
                        width,
                        height,
                        first.0,
                        first.1
                    ),
                });
            }
        }
        Ok(img)
    }
}

/// The ground truth of each of the `frames` (images of `frames_dir`) from the lines of `gt`
/// that name their frames: each line matched to its image by file name (or by stem, when the
/// line names the frame without its extension or with another); a line without its image is
/// an error naming the line; the frames without a line are not annotated, one warning for
/// them all.
fn match_by_name(
    gt: &Path,
    frames_dir: &Path,
    frames: &[PathBuf],
    entries: &[GtEntry],
    warnings: &mut Vec<String>,
) -> Result<Vec<Option<Quad>>> {
    use std::collections::HashMap;
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    let stem = |p: &Path| p.file_stem().map(|n| n.to_string_lossy().into_owned());
    let by_name: HashMap<String, usize> = frames
        .iter()
        .enumerate()
        .filter_map(|(i, p)| name(p).map(|n| (n, i)))
        .collect();
    // A stem two images share (`a.jpg`, `a.png`) matches neither.
    let mut by_stem: HashMap<String, Option<usize>> = HashMap::new();
    for (i, p) in frames.iter().enumerate() {
        if let Some(s) = stem(p) {
            by_stem
                .entry(s)
                .and_modify(|v| *v = None)
                .or_insert(Some(i));
        }
    }
    let mut gtv = vec![None; frames.len()];
    let mut lined = vec![false; frames.len()];
    for e in entries {
        let f = e.frame.as_deref().unwrap_or_default();
        let i = by_name
            .get(f)
            .copied()
            .or_else(|| by_stem.get(&stem(Path::new(f))?).copied().flatten());
        let Some(i) = i else {
            return Err(Error::Parse {
                path: gt.to_path_buf(),
                line: e.line,
                message: format!("missing frame {}", frames_dir.join(f).display()),
            });
        };
        gtv[i] = e.quad;
        lined[i] = true;
    }
    let without: Vec<usize> = (0..frames.len()).filter(|&i| !lined[i]).collect();
    if !without.is_empty() {
        let shown: Vec<String> = without
            .iter()
            .take(3)
            .filter_map(|&i| name(&frames[i]))
            .collect();
        warnings.push(format!(
            "{}: {} of the {} frames in {} have no line ({}{}): not annotated",
            gt.display(),
            without.len(),
            frames.len(),
            frames_dir.display(),
            shown.join(", "),
            if without.len() > 3 { ", ..." } else { "" }
        ));
    }
    Ok(gtv)
}

/// Why ground-truth corners cannot be a target's, if they cannot ([`Quad::unusable`]).
pub fn unusable_quad(q: &Quad) -> Option<String> {
    q.unusable()
}

/// Reads corners that cannot be a target's (folded, collinear, tiny, far beyond any frame) as
/// not annotated; returns a warning for each, naming `gt` and the line.
pub fn drop_unusable(gt: &Path, entries: &mut [GtEntry]) -> Vec<String> {
    let mut warnings = Vec::new();
    for e in entries.iter_mut() {
        if let Some(why) = e.quad.and_then(|q| unusable_quad(&q)) {
            warnings.push(format!(
                "{}:{}: {why}: the frame is read as not annotated",
                gt.display(),
                e.line
            ));
            e.quad = None;
        }
    }
    warnings
}

/// The video `dir/<name>.<ext>` for a video extension, if there is one.
fn video_beside(dir: &Path, name: &str) -> Option<PathBuf> {
    video::VIDEO_EXTENSIONS
        .iter()
        .map(|e| dir.join(format!("{name}.{e}")))
        .find(|p| p.is_file())
}

/// Whether a ground-truth file is in the POT naming (`<seq>_gt_points.txt`).
fn is_pot(gt: &Path) -> bool {
    gt.file_name()
        .is_some_and(|n| n.to_string_lossy().ends_with("_gt_points.txt"))
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "sequence".into())
}

/// One sequence (a ground-truth file, or a folder that is not a dataset root) or the sequences
/// of a dataset root ([`discover`]).
pub fn open_or_discover(path: &Path, names: Option<&[String]>) -> Result<Vec<Sequence>> {
    // A folder is a dataset root when it holds sequences of a layout ([`layouts::scan`]):
    // then its sequences' own errors are reported, not "no image here".
    let single = path.is_file()
        || (path.is_dir() && names.is_none() && layouts::scan(path)?.entries.is_empty());
    if single {
        Ok(vec![Sequence::open(path)?])
    } else {
        discover(path, names)
    }
}

/// The sequences of a dataset root in any of the layouts of [`layouts`] (MTF, POT,
/// PlanarTrack, UCSB, VOT, GOT-10k, LaSOT, folders with `groundtruth.txt`), sorted by name
/// (folders in `list.txt`'s order); with `names`, only those (in that order; an unknown name is
/// an error listing what exists). Without `names`, an annotation file no layout could place is
/// an error naming it.
pub fn discover(root: &Path, names: Option<&[String]>) -> Result<Vec<Sequence>> {
    let found = layouts::entries(root, names)?;
    let chosen: Vec<&Entry> = match names {
        None => found.iter().collect(),
        Some(names) => names
            .iter()
            .map(|n| {
                found
                    .iter()
                    .find(|e| &e.name == n)
                    .ok_or_else(|| Error::Sequence {
                        path: root.to_path_buf(),
                        message: format!(
                            "no sequence '{n}'; available: {}",
                            found
                                .iter()
                                .map(|e| e.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    })
            })
            .collect::<Result<_>>()?,
    };
    if chosen.is_empty() {
        return Err(Error::Sequence {
            path: root.to_path_buf(),
            message:
                "no sequence found (expected MTF <root>/<seq>.txt with frames in <root>/<seq>/, \
                      POT <seq>_gt_points.txt, PlanarTrack Seq_<n>.txt, UCSB <seq>.warps, or \
                      folders holding groundtruth.txt: see docs/benchmarks.md)"
                    .into(),
        });
    }
    chosen.iter().map(|e| e.open()).collect()
}
