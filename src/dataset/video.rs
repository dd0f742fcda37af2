//! Video files as sequences, decoded by the `ffmpeg` program as a subprocess (grey raw frames on
//! a pipe), with `ffprobe` for the size, the frame rate and the frame count.
//!
//! Why a subprocess (docs/video.md, "Video files"): it needs nothing at build time, so `cargo run` and
//! `cargo test` keep working on a machine without FFmpeg's development packages, and it has
//! FFmpeg's whole coverage of containers and codecs. Decoding is sequential. The frames decoded
//! last are kept (a bounded cache: stepping back a little decodes nothing); a frame further
//! away restarts the decoder with an input seek (`-ss` before `-i`: to the keyframe before it,
//! then decoded up to it), so a jump does not decode from the start. A missing program is an
//! error that names the package to install.

use crate::error::{Error, Result};
use crate::imaging::GrayU8;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::Mutex;

/// File extensions read as videos.
pub const VIDEO_EXTENSIONS: &[&str] = &[
    "mp4", "m4v", "mov", "avi", "mkv", "webm", "mpg", "mpeg", "ts", "wmv", "flv", "ogv",
];

/// Whether `p` names a video file (by its extension).
pub fn is_video(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| VIDEO_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// A path as FFmpeg's programs must be given it to read or write that file and nothing else:
/// `file:` and the absolute path. A bare path is a URL to them (`concat:a.mp4|b.mp4` reads
/// other files, `pipe:0.mp4` standard input) or an option (`-h.mp4`).
pub fn ffmpeg_path(path: &Path) -> std::ffi::OsString {
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut s = std::ffi::OsString::from("file:");
    s.push(abs.as_os_str());
    s
}

/// A video file: its first video stream's size, frame rate and frame count, and the decoder.
#[derive(Debug)]
pub struct Video {
    pub path: PathBuf,
    pub width: usize,
    pub height: usize,
    /// Frames per second (the stream's nominal rate).
    pub fps: f64,
    /// Frames in the stream (its packets, counted by `ffprobe`).
    pub frames: usize,
    /// The stream's first timestamp, seconds.
    start: f64,
    decoder: Mutex<Option<Decoder>>,
    /// A second decoder, in colour, for display ([`Video::frame_rgb`]): the trackers read
    /// FFmpeg's grey as before.
    colour: Mutex<Option<Decoder>>,
    /// The frames decoded last (newest at the back), at most [`CACHE_BYTES`] of them: stepping
    /// back a little, as the inspector does, decodes nothing.
    cache: Mutex<std::collections::VecDeque<(usize, GrayU8)>>,
}

/// The memory the recently decoded frames of a video may take (at least 4 frames are kept).
pub const CACHE_BYTES: usize = 64 << 20;

impl PartialEq for Video {
    fn eq(&self, other: &Self) -> bool {
        self.path == other.path
    }
}

#[derive(Debug)]
struct Decoder {
    child: Child,
    out: ChildStdout,
    /// The frame the next read gives.
    next: usize,
    /// The last lines FFmpeg wrote to its standard error (read on a thread of their own).
    said: std::sync::Arc<Mutex<Vec<String>>>,
}

/// How many of FFmpeg's last error lines a decoder keeps.
const SAID_LINES: usize = 4;

impl Decoder {
    /// FFmpeg's last error lines, joined; empty when it said nothing. `wait` gives it that long
    /// to say something (its messages and the frame's bytes travel on different pipes).
    fn said(&self, wait: std::time::Duration) -> String {
        let until = std::time::Instant::now() + wait;
        loop {
            let lines = self.said.lock().unwrap_or_else(|e| e.into_inner());
            if !lines.is_empty() || std::time::Instant::now() >= until {
                return lines.join("; ");
            }
            drop(lines);
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }
}

impl Drop for Decoder {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs an FFmpeg program; its absence is an error naming the package.
pub(super) fn command(program: &str) -> Command {
    let mut c = Command::new(program);
    c.stdin(Stdio::null());
    c
}

pub(super) fn missing(program: &str, e: std::io::Error) -> Error {
    Error::InvalidParameter(format!(
        "cannot run `{program}` ({e}): videos and cameras are read by FFmpeg's programs; \
         install them (Debian/Ubuntu: apt-get install ffmpeg)"
    ))
}

impl Video {
    /// Probes a video file.
    pub fn open(path: &Path) -> Result<Video> {
        crate::files::check_regular(path)?;
        let out = command("ffprobe")
            .args([
                "-v",
                "error",
                "-select_streams",
                "v:0",
                "-count_packets",
                "-show_entries",
                "stream=width,height,r_frame_rate,nb_read_packets,start_time",
                "-of",
                "default=noprint_wrappers=1",
            ])
            .arg(ffmpeg_path(path))
            .output()
            .map_err(|e| missing("ffprobe", e))?;
        let bad = |message: String| Error::Sequence {
            path: path.to_path_buf(),
            message,
        };
        let text = String::from_utf8_lossy(&out.stdout);
        if !out.status.success() {
            let why: Vec<String> = String::from_utf8_lossy(&out.stderr)
                .lines()
                .map(|l| l.trim().to_string())
                .filter(|l| !l.is_empty())
                .collect();
            return Err(bad(format!(
                "not a video FFmpeg can read: {}",
                why.join("; ")
            )));
        }
        let field = |k: &str| {
            text.lines()
                .find_map(|l| l.strip_prefix(&format!("{k}=")))
                .map(str::trim)
        };
        let number = |k: &str| -> Result<usize> {
            field(k)
                .and_then(|v| v.parse::<usize>().ok())
                .ok_or_else(|| bad(format!("no video stream (ffprobe gave no {k})")))
        };
        let (width, height, frames) = (
            number("width")?,
            number("height")?,
            number("nb_read_packets")?,
        );
        let fps = field("r_frame_rate")
            .and_then(|r| {
                let (a, b) = r.split_once('/')?;
                let (a, b) = (a.parse::<f64>().ok()?, b.parse::<f64>().ok()?);
                (a > 0.0 && b > 0.0).then_some(a / b)
            })
            .ok_or_else(|| bad("the video stream has no frame rate".into()))?;
        let start = field("start_time")
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .unwrap_or(0.0);
        if width == 0 || height == 0 || frames == 0 {
            return Err(bad("the video stream has no frames".into()));
        }
        if (width as u64) * (height as u64) > crate::imaging::MAX_PIXELS {
            return Err(bad(format!(
                "{width}x{height} is more than the {} megapixels a frame may have",
                crate::imaging::MAX_PIXELS >> 20
            )));
        }
        Ok(Video {
            path: path.to_path_buf(),
            width,
            height,
            fps,
            frames,
            start,
            decoder: Mutex::new(None),
            colour: Mutex::new(None),
            cache: Mutex::new(Default::default()),
        })
    }

    /// Starts decoding at frame `i`, in grey.
    fn spawn(&self, i: usize) -> Result<Decoder> {
        self.spawn_as(i, "gray")
    }

    /// Frame `i` (0-based) in colour, 8-bit RGB rows, for display (the inspector showed a
    /// video grey where the same frames as JPEGs showed in colour). Decoded by a process of
    /// its own, forward from the last frame asked for; not cached.
    pub fn frame_rgb(&self, i: usize) -> Result<Vec<u8>> {
        self.check_frame(i)?;
        let mut guard = self.colour.lock().unwrap_or_else(|e| e.into_inner());
        if !self.reusable(guard.as_ref(), i) {
            *guard = Some(self.spawn_as(i, "rgb24")?);
        }
        let d = guard.as_mut().expect("set above");
        let mut rgb = vec![0u8; self.width * self.height * 3];
        while d.next <= i {
            if let Err(e) = d.out.read_exact(&mut rgb) {
                let at = d.next;
                *guard = None;
                return Err(Error::Sequence {
                    path: self.path.clone(),
                    message: format!("frame {} could not be decoded in colour: {e}", at + 1),
                });
            }
            d.next += 1;
        }
        Ok(rgb)
    }

    /// Starts decoding at frame `i` in FFmpeg's pixel format `pix_fmt`.
    fn spawn_as(&self, i: usize, pix_fmt: &str) -> Result<Decoder> {
        let mut c = command("ffmpeg");
        c.args(["-v", "error", "-nostdin"]);
        if i > 0 {
            // Half a frame before the frame's timestamp: the decoder lands on it exactly.
            let t = self.start + (i as f64 - 0.5) / self.fps;
            c.args(["-ss", &format!("{t:.6}")]);
        }
        c.arg("-i")
            .arg(ffmpeg_path(&self.path))
            .args(["-map", "0:v:0", "-f", "rawvideo", "-pix_fmt", pix_fmt, "-"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = c.spawn().map_err(|e| missing("ffmpeg", e))?;
        let out = child.stdout.take().expect("piped");
        let err = child.stderr.take().expect("piped");
        let said = std::sync::Arc::new(Mutex::new(Vec::new()));
        let keep = said.clone();
        // Drained always (a full pipe would stop FFmpeg); the thread ends with the process.
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(err).split(b'\n') {
                let Ok(line) = line else { break };
                let line = String::from_utf8_lossy(&line);
                let line = line.trim();
                if line.is_empty() {
                    continue;
                }
                let mut lines = keep.lock().unwrap_or_else(|e| e.into_inner());
                if lines.len() == SAID_LINES {
                    lines.remove(0);
                }
                // At most 200 characters a line.
                let end = line.char_indices().nth(200).map_or(line.len(), |(k, _)| k);
                lines.push(line[..end].to_string());
            }
        });
        Ok(Decoder {
            child,
            out,
            next: i,
            said,
        })
    }

    /// An error naming frame `i` when the video has no such frame.
    fn check_frame(&self, i: usize) -> Result<()> {
        if i >= self.frames {
            return Err(Error::Sequence {
                path: self.path.clone(),
                message: format!(
                    "frame {} is beyond the video's {} frames",
                    i + 1,
                    self.frames
                ),
            });
        }
        Ok(())
    }

    /// Whether decoder `d` reaches frame `i` by decoding on (close frames ahead; anything else
    /// restarts at the frame).
    fn reusable(&self, d: Option<&Decoder>, i: usize) -> bool {
        d.is_some_and(|d| d.next <= i && i < d.next + 2 * self.fps.max(1.0) as usize)
    }

    /// Frame `i` (0-based) as 8-bit grey. The error names the file and the frame.
    pub fn frame(&self, i: usize) -> Result<GrayU8> {
        self.check_frame(i)?;
        {
            let cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
            if let Some((_, img)) = cache.iter().find(|(k, _)| *k == i) {
                return Ok(img.clone());
            }
        }
        let mut guard = self.decoder.lock().unwrap_or_else(|e| e.into_inner());
        if !self.reusable(guard.as_ref(), i) {
            *guard = Some(self.spawn(i)?);
        }
        let d = guard.as_mut().expect("set above");
        let mut img = GrayU8 {
            width: self.width,
            height: self.height,
            data: vec![0; self.width * self.height],
        };
        while d.next <= i {
            if let Err(e) = d.out.read_exact(&mut img.data) {
                let at = d.next;
                let said = d.said(std::time::Duration::from_millis(200));
                *guard = None;
                let why = if said.is_empty() {
                    e.to_string()
                } else {
                    format!("FFmpeg: {said}")
                };
                return Err(Error::Sequence {
                    path: self.path.clone(),
                    message: format!(
                        "frame {} could not be decoded (the video is cut short or corrupt: {why})",
                        at + 1
                    ),
                });
            }
            // A frame of one value that FFmpeg complained about is what its decoder shows
            // where the data is missing (a video cut short), not a picture.
            if img.data.iter().all(|&v| v == img.data[0]) {
                let said = d.said(std::time::Duration::from_millis(100));
                if !said.is_empty() {
                    let at = d.next;
                    *guard = None;
                    return Err(Error::Sequence {
                        path: self.path.clone(),
                        message: format!(
                            "frame {} could not be decoded, FFmpeg shows it as one grey (the \
                             video is cut short or corrupt: FFmpeg: {said})",
                            at + 1
                        ),
                    });
                }
            }
            d.next += 1;
            self.remember(d.next - 1, &img);
        }
        Ok(img)
    }

    /// Keeps a decoded frame in the cache, dropping the oldest beyond [`CACHE_BYTES`].
    fn remember(&self, i: usize, img: &GrayU8) {
        let keep = (CACHE_BYTES / (self.width * self.height).max(1)).max(4);
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if cache.iter().any(|(k, _)| *k == i) {
            return;
        }
        while cache.len() >= keep {
            cache.pop_front();
        }
        cache.push_back((i, img.clone()));
    }
}

/// Colours of [`render`]: the tracker's quad, the ground truth's.
pub const TRACKED_RGB: [u8; 3] = [255, 60, 60];
pub const TRUTH_RGB: [u8; 3] = [60, 220, 90];

/// Draws the segment `a`-`b` on an RGB image, 2 px wide (samples every half pixel).
fn draw_segment(
    rgb: &mut [u8],
    w: usize,
    h: usize,
    a: crate::geometry::Point,
    b: crate::geometry::Point,
    c: [u8; 3],
) {
    let steps = ((b.x - a.x).hypot(b.y - a.y) * 2.0).ceil().clamp(1.0, 1e5) as usize;
    for s in 0..=steps {
        let t = s as f64 / steps as f64;
        let (x, y) = (a.x + t * (b.x - a.x), a.y + t * (b.y - a.y));
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let (px, py) = ((x - 0.5 + dx).floor(), (y - 0.5 + dy).floor());
            if px >= 0.0 && py >= 0.0 && (px as usize) < w && (py as usize) < h {
                let k = 3 * (py as usize * w + px as usize);
                rgb[k..k + 3].copy_from_slice(&c);
            }
        }
    }
}

/// Draws a quad's outline, with a dot on its first corner (the orientation).
pub fn draw_quad(rgb: &mut [u8], w: usize, h: usize, q: &crate::geometry::Quad, c: [u8; 3]) {
    if !q.is_finite() {
        return;
    }
    for k in 0..4 {
        draw_segment(rgb, w, h, q.0[k], q.0[(k + 1) % 4], c);
    }
    let p = q.0[0];
    for (dx, dy) in [(-2.0, 0.0), (2.0, 0.0), (0.0, -2.0), (0.0, 2.0)] {
        draw_segment(
            rgb,
            w,
            h,
            p,
            crate::geometry::Point::new(p.x + dx, p.y + dy),
            c,
        );
    }
}

/// Writes an annotated video of `seq`: each frame with the tracked quad (`tracked[i]`, none
/// where lost) and the ground truth drawn, encoded by the `ffmpeg` program to `out` (its
/// extension picks the container and codec FFmpeg defaults to), at the video's frame rate or
/// 30 fps. Frames past `tracked` are not written.
pub fn render(
    seq: &super::Sequence,
    tracked: &[Option<crate::geometry::Quad>],
    out: &Path,
) -> Result<()> {
    let n = tracked.len().min(seq.len());
    if n == 0 {
        return Err(Error::InvalidParameter("no frame to render".into()));
    }
    // A video container: FFmpeg writes an image format (`out.jpg`) as one image, cut short.
    if !is_video(out) {
        return Err(Error::InvalidParameter(format!(
            "cannot render to {}: not a video file name (its extension must be one of {})",
            out.display(),
            VIDEO_EXTENSIONS.join(", ")
        )));
    }
    let first = seq.load_gray(0)?;
    let (w, h) = (first.width, first.height);
    let fps = seq.video.as_ref().map_or(30.0, |v| v.fps);
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
    }
    let mut child = command("ffmpeg")
        .args([
            "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s",
        ])
        .arg(format!("{w}x{h}"))
        .args(["-r", &format!("{fps}"), "-i", "-"])
        // Codecs for yuv420p need even sizes.
        .args([
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
            "-pix_fmt",
            "yuv420p",
        ])
        .arg(ffmpeg_path(out))
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| missing("ffmpeg", e))?;
    let mut stdin = child.stdin.take().expect("piped");
    let mut rgb = vec![0u8; 3 * w * h];
    let mut failed = None;
    for i in 0..n {
        let g = if i == 0 {
            first.clone()
        } else {
            seq.load_gray(i)?
        };
        if (g.width, g.height) != (w, h) {
            failed = Some(format!("frame {} has another size", i + 1));
            break;
        }
        for (px, &v) in rgb.chunks_exact_mut(3).zip(&g.data) {
            px.fill(v);
        }
        if let Some(q) = seq.ground_truth(i) {
            draw_quad(&mut rgb, w, h, &q, TRUTH_RGB);
        }
        if let Some(q) = tracked[i] {
            draw_quad(&mut rgb, w, h, &q, TRACKED_RGB);
        }
        if let Err(e) = std::io::Write::write_all(&mut stdin, &rgb) {
            failed = Some(e.to_string());
            break;
        }
    }
    drop(stdin);
    let done = child.wait_with_output().map_err(|e| Error::io(out, e))?;
    // FFmpeg's own reason first (a write to it fails only as a broken pipe once it has quit).
    let said = String::from_utf8_lossy(&done.stderr)
        .trim()
        .replace('\n', "; ");
    let why = match failed {
        _ if !done.status.success() && !said.is_empty() => Some(said),
        Some(f) => Some(f),
        None => (!done.status.success()).then(|| format!("ffmpeg exited with {}", done.status)),
    };
    if let Some(why) = why {
        // Nothing half-written is left behind.
        let _ = std::fs::remove_file(out);
        return Err(Error::ImageWrite {
            path: out.to_path_buf(),
            message: format!("the annotated video: {why}"),
        });
    }
    Ok(())
}
