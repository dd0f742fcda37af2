//! Live cameras through the `ffmpeg` program: V4L2 devices (`/dev/video0`) and FFmpeg's
//! `lavfi` test sources (`lavfi:testsrc=size=320x240:rate=30`), which arrive as a live stream
//! through the same code and test it where there is no camera.
//!
//! A reader thread takes every frame as it comes and keeps only the newest: a tracker slower
//! than the camera gets the latest frame each time, and the frames it never saw are counted as
//! dropped. A camera that stops (unplugged, the stream ends) is reported with the frame it
//! stopped at.

use crate::error::{Error, Result};
use crate::imaging::GrayU8;
use std::io::Read;
use std::process::{Child, Stdio};
use std::sync::{Arc, Condvar, Mutex};

/// A live source: `/dev/videoN` (V4L2) or `lavfi:<graph>` (an FFmpeg test source).
pub struct Live {
    pub source: String,
    pub width: usize,
    pub height: usize,
    child: Child,
    shared: Arc<(Mutex<Slot>, Condvar)>,
    /// The sequence number of the last frame handed out.
    taken: u64,
}

#[derive(Default)]
struct Slot {
    frame: Option<GrayU8>,
    /// Frames received so far.
    received: u64,
    /// Why the stream ended, once it has.
    ended: Option<String>,
}

/// A frame from a live source, with how many were dropped before it.
pub struct LiveFrame {
    pub image: GrayU8,
    /// Frames the camera sent since the previous one handed out that were never handed out.
    pub dropped: u64,
}

impl Live {
    /// Opens `source` at `width x height` (the camera's mode, or the test source's size).
    pub fn open(source: &str, width: usize, height: usize) -> Result<Live> {
        if width == 0 || height == 0 {
            return Err(Error::InvalidParameter("a live source needs a size".into()));
        }
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
            "gray",
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
            loop {
                let mut img = GrayU8 {
                    width,
                    height,
                    data: vec![0; width * height],
                };
                let read = out.read_exact(&mut img.data);
                let (lock, cv) = &*writer;
                let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
                match read {
                    Ok(()) => {
                        slot.frame = Some(img);
                        slot.received += 1;
                    }
                    Err(_) => {
                        let mut why = String::new();
                        let _ = err.read_to_string(&mut why);
                        let why = why.trim().replace('\n', "; ");
                        slot.ended = Some(format!(
                            "the live source stopped after {} frame(s){}",
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
        })
    }

    /// The newest frame not handed out yet, waiting for one if needed; an error once the
    /// source has stopped (naming it and how many frames it gave).
    pub fn newest(&mut self) -> Result<LiveFrame> {
        let (lock, cv) = &*self.shared;
        let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if slot.received > self.taken
                && let Some(image) = slot.frame.take()
            {
                let dropped = slot.received - self.taken - 1;
                self.taken = slot.received;
                return Ok(LiveFrame { image, dropped });
            }
            if let Some(why) = &slot.ended {
                return Err(Error::Sequence {
                    path: self.source.clone().into(),
                    message: why.clone(),
                });
            }
            slot = cv.wait(slot).unwrap_or_else(|e| e.into_inner());
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
