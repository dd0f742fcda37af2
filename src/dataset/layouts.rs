//! The benchmarks' own layouts, as their users download them: which sequences a dataset root
//! holds, in which layout, and how each is opened.
//!
//! - **MTF/TMT**: `<root>/<seq>.txt` beside `<root>/<seq>/` (or a video `<root>/<seq>.mp4`).
//! - **POT-210/280**: `V<obj>_<k>_gt_points.txt` (8 numbers a frame, all-zero rows not
//!   annotated), `_gt_homography.txt` and `_flag.txt` (a frame counts when its flag is 0) in the
//!   root, `annotation/` or `annotation/annotation/`; the frames in `<root>/V01_1/` (`img/`),
//!   `<root>/V01/V01_1/`, `<root>/images/V01_1/`, or the videos `<root>/V01/V01_1.avi`. The
//!   challenge factor is `k`.
//! - **PlanarTrack**: `Seq_xxxxx.txt` (all-zero rows not labelled), `_flag.txt`,
//!   `_homography.txt` in `annotation/`, `annos/` or the root, attributes in
//!   `challenging_factor/<seq>_challenging_factor.txt`; the frames in `sequences/<seq>/`,
//!   `data/<seq>/` or `<root>/<seq>/`.
//! - **UCSB**: `<seq>.warps` or `<seq>.avi.warps` (a homography a frame, the frame's pixels to
//!   the reference plane in mm) in the root or `ground_truth/`, the frames in `<root>/<seq>/` or
//!   the video `<root>/<seq>.avi`.
//! - **VOT, GOT-10k, LaSOT** and plain folders: a folder per sequence holding `groundtruth.txt`,
//!   one or two levels down (`<root>/<seq>/`, LaSOT's `<root>/<class>/<class>-N/`); `list.txt`,
//!   where there is one, gives their order.
//!
//! A root mixing layouts is read when every annotation file in it finds its sequence; a file
//! that does not is an error naming it and why.

use super::{Sequence, list_images, regions, video};
use crate::error::{Error, Result};
use crate::geometry::Quad;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The layout a sequence was read in (a closed set).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// MTF/TMT `<seq>.txt` (or a ground-truth file given alone).
    #[default]
    Mtf,
    /// A folder of images, with or without a ground-truth file.
    Folder,
    /// A video file.
    Video,
    Pot,
    PlanarTrack,
    Ucsb,
    Vot,
    Got10k,
    Lasot,
}

impl Layout {
    /// The name the command line and the docs use.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Mtf => "mtf",
            Layout::Folder => "folder",
            Layout::Video => "video",
            Layout::Pot => "pot",
            Layout::PlanarTrack => "planartrack",
            Layout::Ucsb => "ucsb",
            Layout::Vot => "vot",
            Layout::Got10k => "got10k",
            Layout::Lasot => "lasot",
        }
    }
}

/// POT's challenge factors, by the `k` of `V<obj>_<k>`.
pub const POT_FACTORS: [&str; 7] = [
    "scale",
    "rotation",
    "perspective",
    "blur",
    "occlusion",
    "out_of_view",
    "unconstrained",
];

/// PlanarTrack's attributes, in the order of its `_challenging_factor.txt` flags.
pub const PLANARTRACK_FACTORS: [&str; 8] = [
    "occlusion",
    "blur",
    "rotation",
    "scale",
    "perspective",
    "out_of_view",
    "low_resolution",
    "background_clutter",
];

/// The UCSB reference region, in the reference plane's millimetres: the textured area inside
/// the markers (the markers' corners at 12.7 and 342.9 x 279.4 mm, the texture 1.5 in inside).
pub const UCSB_REFERENCE: [f64; 8] = [50.8, 50.8, 304.8, 50.8, 304.8, 241.3, 50.8, 241.3];

/// Where a sequence's frames are.
#[derive(Clone, Debug, PartialEq)]
pub enum Frames {
    Dir(PathBuf),
    Video(PathBuf),
}

/// A sequence found in a dataset root, opened by [`Entry::open`].
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub name: String,
    pub layout: Layout,
    source: Source,
}

#[derive(Clone, Debug, PartialEq)]
enum Source {
    /// A ground-truth file [`Sequence::open`] finds the frames of (MTF).
    File(PathBuf),
    /// A folder holding its ground truth ([`open_folder`]).
    Folder(PathBuf),
    /// POT and PlanarTrack: corners, homographies, flags, attributes.
    Planar {
        points: PathBuf,
        homography: Option<PathBuf>,
        flags: Option<PathBuf>,
        factors: Vec<String>,
        frames: Frames,
    },
    Ucsb {
        warps: PathBuf,
        frames: Frames,
    },
}

impl Entry {
    /// Opens the sequence.
    pub fn open(&self) -> Result<Sequence> {
        match &self.source {
            Source::File(p) => Sequence::open(p),
            Source::Folder(d) => open_folder(d),
            Source::Planar {
                points,
                homography,
                flags,
                factors,
                frames,
            } => open_planar(
                &self.name,
                self.layout,
                points,
                homography.as_deref(),
                flags.as_deref(),
                factors,
                frames,
            ),
            Source::Ucsb { warps, frames } => open_ucsb(&self.name, warps, frames),
        }
    }
}

/// Files of a root that are not annotations of any layout.
fn ignorable(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    lower.starts_with('.')
        || lower.starts_with("readme")
        || lower.starts_with("license")
        || matches!(
            lower.as_str(),
            "list.txt" | "test_seq.txt" | "training_set.txt" | "sequences.txt"
        )
}

fn files_of(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn dirs_of(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn name_of(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn has_images(d: &Path) -> bool {
    d.is_dir() && list_images(d).is_ok_and(|v| !v.is_empty())
}

/// The frames of sequence `name` among `dirs` (folders of images, `img/` inside each tried
/// first) and `videos` (stems without extension).
fn find_frames(dirs: &[PathBuf], videos: &[PathBuf]) -> Option<Frames> {
    for d in dirs {
        for c in [d.join("img"), d.clone()] {
            if has_images(&c) {
                return Some(Frames::Dir(c));
            }
        }
    }
    videos.iter().find_map(|stem| {
        video::VIDEO_EXTENSIONS
            .iter()
            .flat_map(|e| [e.to_string(), e.to_ascii_uppercase()])
            .map(|e| PathBuf::from(format!("{}.{e}", stem.display())))
            .find(|p| p.is_file())
            .map(Frames::Video)
    })
}

fn looked_in(dirs: &[PathBuf], videos: &[PathBuf]) -> String {
    dirs.iter()
        .map(|d| format!("{}/", d.display()))
        .chain(
            videos
                .iter()
                .map(|v| format!("{}.avi|mp4|...", v.display())),
        )
        .collect::<Vec<_>>()
        .join(", ")
}

/// An annotation file no layout could place, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Unplaced {
    pub path: PathBuf,
    pub why: String,
}

/// What a root holds ([`scan`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan {
    /// Its sequences: the files' sorted by name, then the folders' (in `list.txt`'s order).
    pub entries: Vec<Entry>,
    /// The annotation files no layout could place.
    pub unplaced: Vec<Unplaced>,
}

/// What a root holds: its sequences and the annotation files no layout could place.
pub fn scan(root: &Path) -> Result<Scan> {
    if !root.is_dir() {
        return Err(Error::Missing {
            path: root.to_path_buf(),
        });
    }
    let mut entries: Vec<Entry> = Vec::new();
    let mut unplaced: Vec<Unplaced> = Vec::new();
    let mut not_placed = |path: &Path, why: String| {
        unplaced.push(Unplaced {
            path: path.to_path_buf(),
            why,
        })
    };
    let mut placed: Vec<PathBuf> = Vec::new();
    let ann_dirs: Vec<PathBuf> = [
        root.to_path_buf(),
        root.join("annotation"),
        root.join("annotation").join("annotation"),
        root.join("annotations"),
        root.join("annos"),
        root.join("ground_truth"),
        root.join("groundtruth"),
    ]
    .into_iter()
    .filter(|d| d.is_dir())
    .collect();

    // POT and PlanarTrack: corner files with their flags or homographies beside them.
    for dir in &ann_dirs {
        for f in files_of(dir) {
            let Some((name, layout)) = planar_corner_file(dir, &name_of(&f)) else {
                continue;
            };
            let (homography, flags) = if layout == Layout::Pot {
                (
                    dir.join(format!("{name}_gt_homography.txt")),
                    dir.join(format!("{name}_flag.txt")),
                )
            } else {
                (
                    dir.join(format!("{name}_homography.txt")),
                    dir.join(format!("{name}_flag.txt")),
                )
            };
            let object = name.split('_').next().unwrap_or(&name).to_string();
            let frame_dirs: Vec<PathBuf> = [
                root.join(&name),
                root.join(&object).join(&name),
                root.join("images").join(&name),
                root.join("extracted").join("images").join(&name),
                root.join("sequences").join(&name),
                root.join("data").join(&name),
            ]
            .into_iter()
            .collect();
            let videos = [root.join(&object).join(&name), root.join(&name)];
            placed.push(f.clone());
            placed.extend([homography.clone(), flags.clone()]);
            let Some(frames) = find_frames(&frame_dirs, &videos) else {
                not_placed(
                    &f,
                    format!(
                        "{} ground truth of '{name}' without its frames (looked in {})",
                        layout.name(),
                        looked_in(&frame_dirs, &videos)
                    ),
                );
                continue;
            };
            let factors = match layout {
                Layout::Pot => name
                    .rsplit_once('_')
                    .and_then(|(_, k)| k.parse::<usize>().ok())
                    .and_then(|k| POT_FACTORS.get(k.wrapping_sub(1)))
                    .map(|f| vec![f.to_string()])
                    .unwrap_or_default(),
                _ => {
                    let file = dir
                        .join("challenging_factor")
                        .join(format!("{name}_challenging_factor.txt"));
                    placed.push(file.clone());
                    read_attribute_flags(&file, &PLANARTRACK_FACTORS)?
                }
            };
            entries.push(Entry {
                name: name.clone(),
                layout,
                source: Source::Planar {
                    points: f,
                    homography: homography.is_file().then_some(homography),
                    flags: flags.is_file().then_some(flags),
                    factors,
                    frames,
                },
            });
        }
    }

    // UCSB: `.warps` files.
    for dir in &ann_dirs {
        for f in files_of(dir) {
            let file = name_of(&f);
            let Some(stem) = file.strip_suffix(".warps") else {
                continue;
            };
            let name = match Path::new(stem).extension() {
                Some(e) if video::is_video(Path::new(stem)) => {
                    stem[..stem.len() - e.len() - 1].to_string()
                }
                _ => stem.to_string(),
            };
            placed.push(f.clone());
            let dirs = [root.join(&name), root.join("frames").join(&name)];
            let videos = [
                root.join(&name),
                root.join("videos").join(&name),
                dir.join(&name),
            ];
            match find_frames(&dirs, &videos) {
                Some(frames) => entries.push(Entry {
                    name,
                    layout: Layout::Ucsb,
                    source: Source::Ucsb { warps: f, frames },
                }),
                None => not_placed(
                    &f,
                    format!(
                        "UCSB warps of '{name}' without its frames (looked in {})",
                        looked_in(&dirs, &videos)
                    ),
                ),
            }
        }
    }

    // MTF: `<seq>.txt` beside `<seq>/` or a video.
    let taken = |entries: &[Entry], n: &str| entries.iter().any(|e| e.name == n);
    for f in files_of(root) {
        if placed.contains(&f) || f.extension().is_none_or(|e| e != "txt") {
            continue;
        }
        let stem = f
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let beside_video = super::video_beside(root, &stem).is_some();
        if (root.join(&stem).is_dir() || beside_video) && !taken(&entries, &stem) {
            placed.push(f.clone());
            entries.push(Entry {
                name: stem,
                layout: Layout::Mtf,
                source: Source::File(f),
            });
        }
    }

    // Folders holding `groundtruth.txt`, one or two levels down.
    let mut folders: Vec<(String, PathBuf)> = Vec::new();
    for d in dirs_of(root) {
        if d.join("groundtruth.txt").is_file() {
            folders.push((name_of(&d), d));
        } else if !taken(&entries, &name_of(&d)) {
            for sub in dirs_of(&d) {
                if sub.join("groundtruth.txt").is_file() {
                    folders.push((name_of(&sub), sub));
                }
            }
        }
    }
    if let Ok(list) = std::fs::read_to_string(root.join("list.txt")) {
        let order: Vec<&str> = list
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect();
        for n in &order {
            if !folders.iter().any(|(f, _)| f == n) {
                not_placed(
                    &root.join("list.txt"),
                    format!("names '{n}', but there is no {n}/groundtruth.txt"),
                );
            }
        }
        let rank = |n: &str| order.iter().position(|o| *o == n).unwrap_or(usize::MAX);
        folders.sort_by(|a, b| rank(&a.0).cmp(&rank(&b.0)).then(a.0.cmp(&b.0)));
    }
    for (name, d) in folders {
        if taken(&entries, &name) {
            continue;
        }
        let layout = folder_layout(&d);
        entries.push(Entry {
            name,
            layout,
            source: Source::Folder(d),
        });
    }

    // What is left: annotation-like files no sequence took.
    let names: Vec<String> = entries.iter().map(|e| e.name.clone()).collect();
    for dir in &ann_dirs {
        for f in files_of(dir) {
            let file = name_of(&f);
            let annotation = file.ends_with(".txt") || file.ends_with(".warps");
            if !annotation || ignorable(&file) || placed.contains(&f) {
                continue;
            }
            // Files a sequence's own tools write beside it (exported corrections, timings).
            if names.iter().any(|n| file.starts_with(&format!("{n}_"))) {
                continue;
            }
            not_placed(&f, unplaced_reason(&file));
        }
    }
    // The files' sequences by name; the folders' stay in `list.txt`'s order after them.
    let (folders, mut files): (Vec<Entry>, Vec<Entry>) = entries
        .into_iter()
        .partition(|e| matches!(e.source, Source::Folder(_)));
    files.sort_by(|a, b| super::natural_cmp(&a.name, &b.name));
    files.extend(folders);
    Ok(Scan {
        entries: files,
        unplaced,
    })
}

fn unplaced_reason(file: &str) -> String {
    if let Some(s) = file
        .strip_suffix("_flag.txt")
        .or_else(|| file.strip_suffix("_gt_homography.txt"))
        .or_else(|| file.strip_suffix("_homography.txt"))
    {
        format!("flags or homographies of '{s}', whose corner file is missing")
    } else if let Some(s) = file.strip_suffix(".txt") {
        format!(
            "not a sequence of any layout (MTF needs the folder {s}/ or a video {s}.mp4 beside \
             it; POT names its corners <seq>_gt_points.txt, PlanarTrack Seq_<n>.txt)"
        )
    } else {
        "not a sequence of any layout".into()
    }
}

/// The sequence and layout of a corner file `file` of `dir`: POT's `<seq>_gt_points.txt`, or
/// PlanarTrack's `Seq_<n>.txt` (or any `<seq>.txt` with `<seq>_flag.txt` or
/// `<seq>_homography.txt` beside it).
fn planar_corner_file(dir: &Path, file: &str) -> Option<(String, Layout)> {
    if let Some(s) = file.strip_suffix("_gt_points.txt") {
        return Some((s.to_string(), Layout::Pot));
    }
    let s = file.strip_suffix(".txt")?;
    let beside = |suffix: &str| dir.join(format!("{s}_{suffix}.txt")).is_file();
    let planar = is_planartrack_name(s)
        || (!s.is_empty()
            && !s.ends_with("_flag")
            && !s.ends_with("_homography")
            && (beside("flag") || beside("homography")));
    planar.then(|| (s.to_string(), Layout::PlanarTrack))
}

fn is_planartrack_name(s: &str) -> bool {
    s.strip_prefix("Seq_")
        .is_some_and(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()))
}

/// A line of 0/1 flags, comma or space separated (one line, or one flag a line), as the names
/// whose flag is 1; no file: no names.
fn read_attribute_flags(path: &Path, names: &[&str]) -> Result<Vec<String>> {
    let Some(text) = crate::files::read_text_optional(path, crate::files::TEXT_LIMIT)? else {
        return Ok(Vec::new());
    };
    let flags: Vec<&str> = text
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .collect();
    if flags.len() != names.len() || flags.iter().any(|f| *f != "0" && *f != "1") {
        return Err(Error::Parse {
            path: path.to_path_buf(),
            line: 1,
            message: format!(
                "expected {} flags of 0 or 1 ({}), found '{}'",
                names.len(),
                names.join(", "),
                crate::error::short_text(text.trim())
            ),
        });
    }
    Ok(names
        .iter()
        .zip(flags)
        .filter(|(_, f)| *f == "1")
        .map(|(n, _)| n.to_string())
        .collect())
}

/// The layout of a folder holding `groundtruth.txt`: LaSOT (`img/` with `full_occlusion.txt` or
/// `out_of_view.txt`), GOT-10k (`absence.label`, `cover.label` or `meta_info.ini`), VOT (a
/// `sequence` file, `color/`, tags, or regions that are not 8 numbers a line), else a folder.
pub fn folder_layout(dir: &Path) -> Layout {
    let has = |f: &str| dir.join(f).exists();
    if has("full_occlusion.txt") || has("out_of_view.txt") || (has("img") && has("nlp.txt")) {
        return Layout::Lasot;
    }
    if has("absence.label") || has("cover.label") || has("meta_info.ini") {
        return Layout::Got10k;
    }
    let tags = files_of(dir).iter().any(|f| {
        f.extension()
            .is_some_and(|e| e == "tag" || e == "label" || e == "value")
    });
    if has("sequence") || dir.join("color").is_dir() || tags {
        return Layout::Vot;
    }
    Layout::Folder
}

/// The frames folder of a VOT sequence: its `sequence` file's colour channel
/// (`channels.color=color/%08d.jpg`), else `color/`, else the folder.
fn vot_frames(dir: &Path) -> PathBuf {
    if let Ok(text) = std::fs::read_to_string(dir.join("sequence")) {
        for line in text.lines() {
            if let Some(v) = line.trim().strip_prefix("channels.color=")
                && let Some(sub) = Path::new(v.trim()).parent()
            {
                return dir.join(sub);
            }
        }
    }
    if dir.join("color").is_dir() {
        dir.join("color")
    } else {
        dir.to_path_buf()
    }
}

/// Flags of a frame each, one a line or all on one line separated by commas (LaSOT): `true`
/// where the value is not 0.
fn per_frame_flags(path: &Path) -> Result<Option<Vec<bool>>> {
    let Some(text) = crate::files::read_text_optional(path, crate::files::TEXT_LIMIT)? else {
        return Ok(None);
    };
    let one_line = text.lines().filter(|l| !l.trim().is_empty()).count() <= 1;
    if one_line {
        let v: Vec<bool> = text
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| {
                t.parse::<f64>()
                    .map(|x| x != 0.0)
                    .map_err(|_| Error::Parse {
                        path: path.to_path_buf(),
                        line: 1,
                        message: format!(
                            "'{}' is not a flag (0 or 1)",
                            crate::error::short_text(t)
                        ),
                    })
            })
            .collect::<Result<_>>()?;
        return Ok(Some(v));
    }
    Ok(Some(
        regions::parse_flags(path, &text)?
            .into_iter()
            .map(|f| f != 0)
            .collect(),
    ))
}

/// Opens a folder holding `groundtruth.txt` (or a folder of images) in its layout.
pub fn open_folder(dir: &Path) -> Result<Sequence> {
    let layout = folder_layout(dir);
    let gt = dir.join("groundtruth.txt");
    let name = name_of(dir);
    let frames_dir = match layout {
        Layout::Vot => vot_frames(dir),
        _ if dir.join("img").is_dir() => dir.join("img"),
        _ => dir.to_path_buf(),
    };
    let text = match crate::files::read_text_optional(&gt, crate::files::TEXT_LIMIT)? {
        Some(t) => t,
        None => return Sequence::from_parts(&name, &frames_dir, None),
    };
    let first: Vec<&str> = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            l.split(|c: char| c == ',' || c.is_whitespace())
                .filter(|t| !t.is_empty())
                .collect()
        })
        .unwrap_or_default();
    let numeric = !first.is_empty() && first.iter().all(|t| t.parse::<f64>().is_ok());
    let mut quads: Vec<Option<Quad>> = match layout {
        Layout::Got10k | Layout::Lasot => regions::parse_boxes(&gt, &text)?,
        Layout::Vot => regions::parse_vot_regions(&gt, &text)?
            .iter()
            .map(regions::Region::quad)
            .collect(),
        // A plain folder: 4 numbers a line are boxes, other VOT regions polygons; 8 numbers or
        // named frames the corner files of `groundtruth`.
        _ if numeric && first.len() == 4 => regions::parse_boxes(&gt, &text)?,
        _ if numeric && first.len() != 8 => regions::parse_vot_regions(&gt, &text)?
            .iter()
            .map(regions::Region::quad)
            .collect(),
        _ => return Sequence::from_parts(&name, &frames_dir, Some(&gt)),
    };
    let mut warnings = Vec::new();
    if layout == Layout::Lasot {
        // LaSOT's boxes count pixels from 1.
        for q in quads.iter_mut().flatten() {
            *q = q.map(|p| crate::geometry::Point::new(p.x - 1.0, p.y - 1.0));
        }
    }
    let absent: &[&str] = match layout {
        Layout::Got10k => &["absence.label"],
        Layout::Lasot => &["full_occlusion.txt", "out_of_view.txt"],
        _ => &[],
    };
    for f in absent {
        let path = dir.join(f);
        if let Some(flags) = per_frame_flags(&path)? {
            if flags.len() != quads.len() {
                warnings.push(format!(
                    "{}: {} flags for {} ground-truth lines",
                    path.display(),
                    flags.len(),
                    quads.len()
                ));
            }
            for (q, f) in quads.iter_mut().zip(flags) {
                if f {
                    *q = None;
                }
            }
        }
    }
    let mut seq = Sequence::from_quads(&name, Frames::Dir(frames_dir), quads, &gt, layout)?;
    seq.warnings.splice(0..0, warnings);
    Ok(seq)
}

/// Opens a POT or PlanarTrack sequence.
fn open_planar(
    name: &str,
    layout: Layout,
    points: &Path,
    homography: Option<&Path>,
    flags: Option<&Path>,
    factors: &[String],
    frames: &Frames,
) -> Result<Sequence> {
    let text = crate::files::read_text(points, crate::files::TEXT_LIMIT)?;
    let rows = regions::parse_rows(points, &text, 8, "x1 y1 x2 y2 x3 y3 x4 y4")?;
    let mut quads: Vec<Option<Quad>> = rows
        .iter()
        .map(|r| {
            let v = r.as_ref()?;
            if regions::is_unlabelled(v) {
                return None;
            }
            let mut a = [0.0; 8];
            a.copy_from_slice(v);
            Some(Quad::from_array(a))
        })
        .collect();
    let mut warnings = Vec::new();
    if let Some(path) = flags {
        let text = crate::files::read_text(path, crate::files::TEXT_LIMIT)?;
        let f = regions::parse_flags(path, &text)?;
        if f.len() != quads.len() {
            warnings.push(format!(
                "{}: {} flags for the {} lines of {}",
                path.display(),
                f.len(),
                quads.len(),
                points.display()
            ));
        }
        for (q, flag) in quads.iter_mut().zip(f) {
            if flag != 0 {
                *q = None;
            }
        }
    }
    let homographies = match homography {
        Some(path) => {
            let text = crate::files::read_text(path, crate::files::TEXT_LIMIT)?;
            let h = regions::parse_homographies(path, &text)?;
            if h.len() != rows.len() {
                warnings.push(format!(
                    "{}: {} homographies for the {} lines of {}",
                    path.display(),
                    h.len(),
                    rows.len(),
                    points.display()
                ));
            }
            h
        }
        None => Vec::new(),
    };
    // POT's files that hold only the annotated frames (half as many lines as frames).
    let mut seq = Sequence::from_quads(name, frames.clone(), quads, points, layout)?;
    if !homographies.is_empty() {
        let mut h: Vec<Option<Matrix3<f64>>> = homographies;
        h.resize(seq.len(), None);
        // A homography counts where the corners do (flags, unlabelled rows).
        for (k, hk) in h.iter_mut().enumerate() {
            if seq.ground_truth(k).is_none() {
                *hk = None;
            }
        }
        seq.homographies = h;
    }
    seq.factors = factors.to_vec();
    seq.warnings.splice(0..0, warnings);
    Ok(seq)
}

/// Opens a UCSB sequence: the corners of [`UCSB_REFERENCE`] in each frame, from the inverse of
/// its `.warps` homography.
fn open_ucsb(name: &str, warps: &Path, frames: &Frames) -> Result<Sequence> {
    let text = crate::files::read_text(warps, crate::files::TEXT_LIMIT)?;
    let h = regions::parse_homographies(warps, &text)?;
    let quads = regions::corners_from_warps(&h, &Quad::from_array(UCSB_REFERENCE));
    let mut seq = Sequence::from_quads(name, frames.clone(), quads, warps, Layout::Ucsb)?;
    // The motion of the sequence (`fi-<texture>-<motion>`) as its challenge factor.
    if let Some(m) = name.rsplit('-').next().filter(|m| *m != name) {
        seq.factors = vec![m.to_string()];
    }
    Ok(seq)
}

/// The entries of `root` for [`super::discover`]: an error naming the files no layout could
/// place, when there are sequences beside them (a root of one layout with a stray or incomplete
/// file); with `names`, only those sequences are wanted and the rest is not checked.
pub fn entries(root: &Path, names: Option<&[String]>) -> Result<Vec<Entry>> {
    let Scan { entries, unplaced } = scan(root)?;
    if names.is_none() && !entries.is_empty() && !unplaced.is_empty() {
        let shown: Vec<String> = unplaced
            .iter()
            .take(5)
            .map(|u| format!("{}: {}", u.path.display(), u.why))
            .collect();
        return Err(Error::Sequence {
            path: root.to_path_buf(),
            message: format!(
                "{} file{} could not be placed in any layout ({} sequence{} found): {}{}",
                unplaced.len(),
                if unplaced.len() == 1 { "" } else { "s" },
                entries.len(),
                if entries.len() == 1 { "" } else { "s" },
                shown.join("; "),
                if unplaced.len() > 5 { "; ..." } else { "" }
            ),
        });
    }
    Ok(entries)
}

/// The entry a benchmark's annotation file given alone belongs to (POT `_gt_points.txt`,
/// PlanarTrack `Seq_<n>.txt`, UCSB `.warps`): found by scanning the roots it may sit in (its
/// folder, and the folders above an `annotation/` or `ground_truth/` one). `None` for other
/// files.
pub fn entry_of_file(path: &Path) -> Option<Entry> {
    let file = name_of(path);
    let dir = path.parent().unwrap_or(Path::new("."));
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    if !file.ends_with(".warps") && planar_corner_file(dir, &file).is_none() {
        return None;
    }
    let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let target = canonical(path);
    let mut roots = vec![dir.to_path_buf()];
    let mut up = dir.to_path_buf();
    for _ in 0..2 {
        match up.parent() {
            Some(p) if !p.as_os_str().is_empty() => {
                roots.push(p.to_path_buf());
                up = p.to_path_buf();
            }
            _ => break,
        }
    }
    for root in roots {
        let Ok(found) = scan(&root) else {
            continue;
        };
        if let Some(e) = found.entries.into_iter().find(|e| match &e.source {
            Source::Planar { points, .. } => canonical(points) == target,
            Source::Ucsb { warps, .. } => canonical(warps) == target,
            _ => false,
        }) {
            return Some(e);
        }
    }
    // Its frames are not where the layout keeps them: opened as a corner file, its frames
    // beside it.
    None
}
