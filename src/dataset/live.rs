//! Live cameras through the `ffmpeg` program: V4L2 devices (`/dev/video0`) and FFmpeg's
//! `lavfi` test sources (`lavfi:testsrc=size=320x240:rate=30`), which arrive as a live stream
//! through the same code and test it where there is no camera.
//!
//! A reader thread takes every frame as it comes and keeps only the newest: a tracker slower
//! than the camera gets the latest frame each time, and the frames it never saw are counted as
//! dropped. A camera that stops (unplugged, the stream ends) is reported with the frame it
//! stopped at.

use crate::error::{Error, Result};
use crate::imaging::{ColourU8, Frame8, GrayU8};
use std::io::Read;
use std::process::{Child, Stdio};
use std::sync::{Arc, Condvar, Mutex};

/// A frame size `WxH` (what is read; [`check_size`] is the range a live source takes).
pub fn parse_size(s: &str) -> Option<(usize, usize)> {
    let (w, h) = s.trim().split_once(['x', 'X'])?;
    Some((w.trim().parse().ok()?, h.trim().parse().ok()?))
}

/// How long a live source may send nothing before [`Live::newest`] gives up on it.
pub const STALL: std::time::Duration = std::time::Duration::from_secs(20);

/// The widest and tallest frame a live source may have, in pixels.
pub const MAX_SIDE: usize = 16384;

/// Checks a live source's frame size: both sides 1..=[`MAX_SIDE`] and at most
/// [`crate::imaging::MAX_PIXELS`] pixels (as a frame file may have), so that a frame's buffer
/// can be allocated (a size of 10^9 x 10^9 aborted the process; 2^32 wrapped to 0).
pub fn check_size(width: usize, height: usize) -> Result<()> {
    let pixels = width as u128 * height as u128;
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(Error::InvalidParameter(format!(
            "live source size {width}x{height}: each side must be 1..={MAX_SIDE} px"
        )));
    }
    if pixels > crate::imaging::MAX_PIXELS as u128 {
        return Err(Error::InvalidParameter(format!(
            "live source size {width}x{height}: {pixels} pixels, more than the {} a frame may have",
            crate::imaging::MAX_PIXELS
        )));
    }
    Ok(())
}

/// A live source: `/dev/videoN` (V4L2) or `lavfi:<graph>` (an FFmpeg test source).
pub struct Live {
    pub source: String,
    pub width: usize,
    pub height: usize,
    child: Child,
    shared: Arc<(Mutex<Slot>, Condvar)>,
    /// The sequence number of the last frame handed out.
    taken: u64,
    /// How long [`Live::newest`] waits for a frame ([`STALL`] unless set).
    stall: std::time::Duration,
}

#[derive(Default)]
struct Slot {
    frame: Option<Frame8>,
    /// Frames received so far.
    received: u64,
    /// Why the stream ended, once it has.
    ended: Option<String>,
}

/// A frame from a live source (in colour when opened so), with how many were dropped before it.
pub struct LiveFrame {
    pub image: Frame8,
    /// Frames the camera sent since the previous one handed out that were never handed out.
    pub dropped: u64,
}

impl Live {
    /// Opens `source` at `width x height` (the camera's mode, or the test source's size), its
    /// frames grey, or in colour with `colour` (their channels and grey, [`ColourU8`]).
    pub fn open(source: &str, width: usize, height: usize, colour: bool) -> Result<Live> {
        check_size(width, height)?;
        let mut c = super::video::command("ffmpeg");
        c.args(["-v", "error", "-nostdin"]);
        match source.strip_prefix("lavfi:") {
            Some(graph) => {
                c.args(["-re", "-f", "lavfi", "-i", graph]);
            }
            None => {
                c.args([
                    "-f",
                    "v4l2",
                    "-video_size",
                    &format!("{width}x{height}"),
                    "-i",
                    source,
                ]);
            }
        }
        c.args([
            "-vf",
            &format!("scale={width}:{height}"),
            "-f",
            "rawvideo",
            "-pix_fmt",
            if colour { "rgb24" } else { "gray" },
            "-",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
        let mut child = c.spawn().map_err(|e| super::video::missing("ffmpeg", e))?;
        let mut out = child.stdout.take().expect("piped");
        let mut err = child.stderr.take().expect("piped");
        let shared: Arc<(Mutex<Slot>, Condvar)> = Arc::default();
        let writer = shared.clone();
        std::thread::spawn(move || {
            let bytes = width * height * if colour { 3 } else { 1 };
            loop {
                let mut data = vec![0; bytes];
                let read = out.read_exact(&mut data);
                let frame = match colour {
                    true => ColourU8::from_rgb(width, height, &data).map(Frame8::Colour),
                    false => GrayU8::from_vec(width, height, data).map(Frame8::Gray),
                };
                let (lock, cv) = &*writer;
                let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
                match (read, frame) {
                    (Ok(()), Some(frame)) => {
                        slot.frame = Some(frame);
                        slot.received += 1;
                    }
                    (Ok(()), None) => {
                        slot.ended = Some("a frame of the wrong size".into());
                        cv.notify_all();
                        return;
                    }
                    (Err(_), _) => {
                        let mut why = String::new();
                        let _ = err.read_to_string(&mut why);
                        let why = why.trim().replace('\n', "; ");
                        slot.ended = Some(format!(
                            "stopped after {} frame(s){}",
                            slot.received,
                            if why.is_empty() {
                                String::new()
                            } else {
                                format!(": {why}")
                            }
                        ));
                        cv.notify_all();
                        return;
                    }
                }
                cv.notify_all();
            }
        });
        Ok(Live {
            source: source.to_string(),
            width,
            height,
            child,
            shared,
            taken: 0,
            stall: STALL,
        })
    }

    /// How long [`Live::newest`] waits for a frame before it reports the source stalled.
    pub fn set_stall(&mut self, stall: std::time::Duration) {
        self.stall = stall;
    }

    /// The newest frame not handed out yet, waiting for one if needed; an error once the
    /// source has stopped (naming it and how many frames it gave) or has sent nothing for
    /// [`STALL`] (an FFmpeg that stalls would otherwise hang its caller).
    pub fn newest(&mut self) -> Result<LiveFrame> {
        match self.newest_within(self.stall)? {
            Some(f) => Ok(f),
            None => Err(Error::Live {
                name: self.source.clone(),
                message: format!(
                    "no frame for {:.0} s after frame {} (the source stalled)",
                    self.stall.as_secs_f64(),
                    self.taken
                ),
            }),
        }
    }

    /// As [`Live::newest`], waiting at most `wait` (`None` when no frame came meanwhile), so
    /// that a caller can do other work while a camera is slow.
    pub fn newest_within(&mut self, wait: std::time::Duration) -> Result<Option<LiveFrame>> {
        let deadline = std::time::Instant::now() + wait;
        let (lock, cv) = &*self.shared;
        let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if slot.received > self.taken
                && let Some(image) = slot.frame.take()
            {
                let dropped = slot.received - self.taken - 1;
                self.taken = slot.received;
                return Ok(Some(LiveFrame { image, dropped }));
            }
            if let Some(why) = &slot.ended {
                return Err(Error::Live {
                    name: self.source.clone(),
                    message: why.clone(),
                });
            }
            let Some(left) = deadline.checked_duration_since(std::time::Instant::now()) else {
                return Ok(None);
            };
            slot = cv
                .wait_timeout(slot, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A live run written as a sequence in the MTF layout as it happens: `ROOT/NAME/frame00001.jpg`...
/// and `ROOT/NAME.txt`, one line per frame (the tracked corners, or `lost`), appended and flushed
/// after its frame is on disk. A run that ends in any way (the camera unplugged, the program
/// killed) leaves a sequence that opens, evaluates and replays up to its last complete frame.
pub struct Recording {
    gt_path: std::path::PathBuf,
    frames_dir: std::path::PathBuf,
    gt: std::fs::File,
    frames: usize,
}

/// JPEG quality of recorded frames (high: a recording is evaluated and corrected later).
const RECORD_QUALITY: u8 = 95;

impl Recording {
    /// Starts a recording `ROOT/NAME.txt` + `ROOT/NAME/`; refuses to overwrite one.
    pub fn create(root: &std::path::Path, name: &str) -> Result<Recording> {
        let gt_path = root.join(format!("{name}.txt"));
        let frames_dir = root.join(name);
        if gt_path.exists() || frames_dir.exists() {
            return Err(Error::io(
                &gt_path,
                std::io::Error::new(
                    std::io::ErrorKind::AlreadyExists,
                    "a recording of that name exists (choose another name or folder)",
                ),
            ));
        }
        std::fs::create_dir_all(&frames_dir).map_err(|e| Error::io(&frames_dir, e))?;
        let mut gt = std::fs::File::create(&gt_path).map_err(|e| Error::io(&gt_path, e))?;
        use std::io::Write;
        gt.write_all(b"frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n")
            .and_then(|()| gt.flush())
            .map_err(|e| Error::io(&gt_path, e))?;
        Ok(Recording {
            gt_path,
            frames_dir,
            gt,
            frames: 0,
        })
    }

    /// Starts a recording in `root` under the first free name of `live`, `live_2`, `live_3`...
    pub fn create_fresh(root: &std::path::Path) -> Result<Recording> {
        let free = (1..10_000)
            .map(|k| match k {
                1 => "live".to_string(),
                k => format!("live_{k}"),
            })
            .find(|n| !root.join(format!("{n}.txt")).exists() && !root.join(n).exists())
            .unwrap_or_else(|| "live".into());
        Recording::create(root, &free)
    }

    /// Appends a frame (grey, or in colour) and its corners (`None`: not tracked, written
    /// `lost`).
    pub fn push(&mut self, frame: &Frame8, corners: Option<&crate::geometry::Quad>) -> Result<()> {
        use std::io::Write;
        let name = format!("frame{:05}.jpg", self.frames + 1);
        let path = self.frames_dir.join(&name);
        let image = frame.gray();
        if image.data.len() != image.width * image.height {
            return Err(Error::InvalidParameter(
                "a frame's data does not match its size".into(),
            ));
        }
        let (data, kind) = match frame {
            Frame8::Gray(g) => (
                std::borrow::Cow::Borrowed(&g.data[..]),
                image::ExtendedColorType::L8,
            ),
            Frame8::Colour(c) => {
                let rgb = c.rgb_pixels().flatten();
                (
                    std::borrow::Cow::Owned(rgb.collect()),
                    image::ExtendedColorType::Rgb8,
                )
            }
        };
        let file = std::fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
        let mut writer = std::io::BufWriter::new(file);
        image::ImageEncoder::write_image(
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut writer, RECORD_QUALITY),
            &data,
            image.width as u32,
            image.height as u32,
            kind,
        )
        .map_err(|e| Error::ImageWrite {
            path: path.clone(),
            message: e.to_string(),
        })?;
        writer.flush().map_err(|e| Error::io(&path, e))?;
        drop(writer);
        let mut line = name;
        match corners {
            Some(q) => {
                for v in q.to_array() {
                    line.push_str(&format!(" {v:.4}"));
                }
            }
            None => line.push_str(" lost"),
        }
        line.push('\n');
        self.gt
            .write_all(line.as_bytes())
            .and_then(|()| self.gt.flush())
            .map_err(|e| Error::io(&self.gt_path, e))?;
        self.frames += 1;
        Ok(())
    }

    /// Frames recorded so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The recording's ground-truth file (what opens it as a sequence).
    pub fn path(&self) -> &std::path::Path {
        &self.gt_path
    }
}

/// What a live run shows of itself.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LiveInfo {
    pub source: String,
    /// Frames taken (and tracked, shown).
    pub frames: usize,
    /// Frames the source sent after the first one taken that were never taken (they came
    /// while the trackers were busy).
    pub dropped: u64,
    /// Frames taken per second, over the last second or so.
    pub fps: f32,
    /// The recording's ground-truth file and its frames, while recording.
    pub recording: Option<(std::path::PathBuf, usize)>,
}

/// A frame a live run took: its index in the run and its image (in colour when opened so).
pub struct Taken {
    pub index: usize,
    pub image: Frame8,
}

/// A live run, the one loop of every live user (`regtrack track --camera`, the inspector's live
/// mode, Python's `Camera`): the newest frame of a source each time ([`LiveRun::take`]),
/// counted (frames, frames dropped, the rate over the last second), and, when asked, recorded
/// as a sequence with the corners its caller tracked on it ([`LiveRun::record`]). What tracks
/// the frames is the caller's: one tracker initialised on the first frame, or the inspector's
/// trackers started on frames a box was drawn on.
pub struct LiveRun {
    live: Live,
    info: LiveInfo,
    /// When the frames of the last second were taken (for the rate).
    taken: std::collections::VecDeque<std::time::Instant>,
    recording: Option<Recording>,
}

impl LiveRun {
    /// Opens `source` at `width x height`, in colour with `colour` (see [`Live::open`]).
    pub fn open(source: &str, width: usize, height: usize, colour: bool) -> Result<LiveRun> {
        Ok(LiveRun {
            live: Live::open(source, width, height, colour)?,
            info: LiveInfo {
                source: source.to_string(),
                ..LiveInfo::default()
            },
            taken: Default::default(),
            recording: None,
        })
    }

    /// How long a frame is waited for before the source is reported stalled ([`STALL`]).
    pub fn set_stall(&mut self, stall: std::time::Duration) {
        self.live.set_stall(stall);
    }

    /// The run so far.
    pub fn info(&self) -> &LiveInfo {
        &self.info
    }

    /// The newest frame, waiting at most `wait` for one (`None`: as long as it takes): `None`
    /// when none came within `wait`; an error once the source stopped (naming it and the frame
    /// it stopped at).
    pub fn take(&mut self, wait: Option<std::time::Duration>) -> Result<Option<Taken>> {
        let got = match wait {
            Some(w) => self.live.newest_within(w),
            None => self.live.newest().map(Some),
        };
        let frame = match got {
            Ok(Some(f)) => f,
            Ok(None) => return Ok(None),
            Err(Error::Live { name, message }) => {
                return Err(Error::Live {
                    name,
                    message: format!("{message} (at live frame {})", self.info.frames + 1),
                });
            }
            Err(e) => return Err(e),
        };
        let index = self.info.frames;
        if index > 0 {
            self.info.dropped += frame.dropped;
        }
        self.info.frames += 1;
        let now = std::time::Instant::now();
        self.taken.push_back(now);
        while self
            .taken
            .front()
            .is_some_and(|t| now.duration_since(*t) > std::time::Duration::from_secs(1))
        {
            self.taken.pop_front();
        }
        self.info.fps = self.taken.len() as f32;
        Ok(Some(Taken {
            index,
            image: frame.image,
        }))
    }

    /// Starts recording the frames taken from now on as the sequence `ROOT/NAME`, or under the
    /// first free name `live`, `live_2`... without a name; the recording that ran is ended (its
    /// ground-truth file and frames, kept on disk).
    pub fn start_recording(
        &mut self,
        root: &std::path::Path,
        name: Option<&str>,
    ) -> Result<Option<(std::path::PathBuf, usize)>> {
        let ended = self.stop_recording();
        let r = match name {
            Some(n) => Recording::create(root, n)?,
            None => Recording::create_fresh(root)?,
        };
        self.info.recording = Some((r.path().to_path_buf(), 0));
        self.recording = Some(r);
        Ok(ended)
    }

    /// Ends the recording, if one runs: its ground-truth file and frames (kept on disk).
    pub fn stop_recording(&mut self) -> Option<(std::path::PathBuf, usize)> {
        self.info.recording = None;
        self.recording
            .take()
            .map(|r| (r.path().to_path_buf(), r.frames()))
    }

    /// Records a frame taken and the corners tracked on it (`None`: lost, or not tracked), when
    /// recording. A failed write ends the recording (what it wrote is kept: `Err` with it).
    #[allow(clippy::type_complexity)]
    pub fn record(
        &mut self,
        image: &Frame8,
        corners: Option<&crate::geometry::Quad>,
    ) -> std::result::Result<(), (Error, Option<(std::path::PathBuf, usize)>)> {
        let Some(r) = self.recording.as_mut() else {
            return Ok(());
        };
        match r.push(image, corners) {
            Ok(()) => {
                self.info.recording = Some((r.path().to_path_buf(), r.frames()));
                Ok(())
            }
            Err(e) => Err((e, self.stop_recording())),
        }
    }
}
