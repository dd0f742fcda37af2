//! Decoding frames: a frame file to the trackers' image (in colour, [`Frame8::Colour`]: its grey
//! for a grey tracker, its channels for `channels = rgb`) and RGBA for display, and a
//! thread that decodes the next frames while the worker tracks the current one (at most
//! [`AHEAD`] of them, so memory stays bounded); a frame being decoded is waited for on a
//! condition variable.

use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::imaging::{ColourU8, Frame8, GrayU8, gray_from_dynamic, load_dynamic};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::mpsc::{Sender, channel};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// A decoded frame for display (RGBA, 8 bits per channel).
#[derive(Clone, Debug)]
pub struct FrameImage {
    pub index: usize,
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<u8>,
}

/// Frames decoded ahead of the one asked for, at most this many (memory stays bounded whatever
/// the sequence's length: about 4 x 1280 x 720 x 5 bytes).
pub(super) const AHEAD: usize = 4;

/// Decodes frame `i`: in colour for the trackers (their grey is the command line's), RGBA for
/// display.
pub(super) fn decode_frame(seq: &Sequence, i: usize) -> Result<(Frame8, FrameImage)> {
    let path = seq.frames.get(i).ok_or_else(|| {
        Error::InvalidParameter(format!(
            "frame {} is out of range (1..{})",
            i + 1,
            seq.len()
        ))
    })?;
    if let Some(video) = &seq.video {
        // The trackers' grey and the colour (grey when it cannot be had), for display too.
        let gray = seq.load_gray(i)?;
        let (w, h) = (gray.width, gray.height);
        return Ok(match video.frame_rgb(i) {
            Ok(rgb) if rgb.len() == w * h * 3 => {
                let image = FrameImage {
                    index: i,
                    width: w,
                    height: h,
                    rgba: rgb
                        .chunks_exact(3)
                        .flat_map(|c| [c[0], c[1], c[2], 255])
                        .collect(),
                };
                let colour = ColourU8::from_rgb_and_gray(&rgb, gray).expect("length checked");
                (Frame8::Colour(colour), image)
            }
            _ => {
                let image = gray_image(i, &gray);
                (Frame8::Gray(gray), image)
            }
        });
    }
    let img = load_dynamic(path)?;
    let gray = gray_from_dynamic(&img);
    let rgba = img.to_rgba8();
    let colour =
        ColourU8::from_rgb_and_gray(img.to_rgb8().as_raw(), gray).expect("the image's own size");
    Ok((
        Frame8::Colour(colour),
        FrameImage {
            index: i,
            width: rgba.width() as usize,
            height: rgba.height() as usize,
            rgba: rgba.into_raw(),
        },
    ))
}

/// A frame for display: a colour frame's channels, a grey one's grey (a live source's).
pub(super) fn frame_image(index: usize, frame: &Frame8) -> FrameImage {
    match frame {
        Frame8::Gray(g) => gray_image(index, g),
        Frame8::Colour(c) => FrameImage {
            index,
            width: c.gray.width,
            height: c.gray.height,
            rgba: c
                .rgb_pixels()
                .flat_map(|[r, g, b]| [r, g, b, 255])
                .collect(),
        },
    }
}

/// A gray frame for display (a video's or a live source's).
pub(super) fn gray_image(index: usize, gray: &GrayU8) -> FrameImage {
    FrameImage {
        index,
        width: gray.width,
        height: gray.height,
        rgba: gray.data.iter().flat_map(|&v| [v, v, v, 255]).collect(),
    }
}

pub(super) type Decoded = Result<(Frame8, FrameImage)>;

/// A thread that decodes the next frames while the worker tracks the current one.
pub(super) struct Ahead {
    requests: Option<Sender<(Arc<Sequence>, usize)>>,
    /// Decoded frames by (sequence identity, index); `pending` were asked for. The condition
    /// variable is notified whenever a frame is decoded.
    done: Arc<(Mutex<AheadState>, Condvar)>,
}

#[derive(Default)]
struct AheadState {
    frames: BTreeMap<usize, Decoded>,
    pending: BTreeSet<usize>,
    /// The sequence the frames belong to (its address).
    sequence: usize,
}

impl AheadState {
    /// Starts over for the sequence `id` if the state is another's.
    fn for_sequence(&mut self, id: usize) -> bool {
        if self.sequence == id {
            return true;
        }
        *self = AheadState {
            sequence: id,
            ..AheadState::default()
        };
        false
    }
}

/// How long [`Ahead::take`] waits for a frame being decoded before decoding it itself.
const AHEAD_WAIT: Duration = Duration::from_secs(1);

impl Ahead {
    pub(super) fn spawn() -> Ahead {
        let (tx, rx) = channel::<(Arc<Sequence>, usize)>();
        let done = Arc::new((Mutex::new(AheadState::default()), Condvar::new()));
        let state = done.clone();
        let spawned = std::thread::Builder::new()
            .name("regtrack-decoder".into())
            .spawn(move || {
                super::background::yield_to_window();
                let (lock, decoded) = &*state;
                while let Ok((seq, i)) = rx.recv() {
                    let id = Arc::as_ptr(&seq) as usize;
                    let wanted = lock
                        .lock()
                        .map(|s| s.sequence == id && s.pending.contains(&i))
                        .unwrap_or(false);
                    if !wanted {
                        continue;
                    }
                    let r = decode_frame(&seq, i);
                    if let Ok(mut s) = lock.lock()
                        && s.sequence == id
                        && s.pending.remove(&i)
                    {
                        s.frames.insert(i, r);
                    }
                    decoded.notify_all();
                }
            });
        Ahead {
            // Without its thread every frame is decoded when asked.
            requests: spawned.ok().map(|_| tx),
            done,
        }
    }

    /// Takes frame `i` if it was decoded ahead (waiting for it if it is being decoded); drops
    /// every frame outside the `AHEAD` after it.
    pub(super) fn take(&self, seq: &Arc<Sequence>, i: usize) -> Option<Decoded> {
        let id = Arc::as_ptr(seq) as usize;
        let (lock, decoded) = &*self.done;
        let mut s = lock.lock().ok()?;
        if !s.for_sequence(id) {
            return None;
        }
        // Wait while the frame is being decoded (the decoder notifies after each frame).
        let deadline = Instant::now() + AHEAD_WAIT;
        while s.pending.contains(&i) && !s.frames.contains_key(&i) {
            let left = deadline.checked_duration_since(Instant::now())?;
            s = decoded.wait_timeout(s, left).ok()?.0;
            if s.sequence != id {
                return None;
            }
        }
        // Only the frames just ahead of `i` are kept (a seek drops the others).
        let got = s.frames.remove(&i);
        let window = |k: usize| k > i && k <= i + AHEAD;
        s.frames.retain(|&k, _| window(k));
        s.pending.retain(|&k| window(k));
        got
    }

    /// Asks for the frames in `range` not yet decoded or asked for.
    pub(super) fn request(&self, seq: &Arc<Sequence>, range: std::ops::Range<usize>) {
        let Some(tx) = &self.requests else { return };
        let id = Arc::as_ptr(seq) as usize;
        let Ok(mut s) = self.done.0.lock() else {
            return;
        };
        s.for_sequence(id);
        for k in range {
            if !s.frames.contains_key(&k) && s.pending.insert(k) {
                let _ = tx.send((seq.clone(), k));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_decoded_ahead_are_the_frames_and_stay_few() {
        let dir = std::env::temp_dir().join(format!("regtrack-ahead-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for k in 0..8u32 {
            let img = image::GrayImage::from_fn(32, 24, |x, y| {
                image::Luma([(x * 5 + y * 3 + k * 20) as u8])
            });
            img.save(dir.join(format!("f{k:02}.png"))).unwrap();
        }
        let seq = Arc::new(Sequence::from_parts("s", &dir, None).unwrap());
        let ahead = Ahead::spawn();
        for i in 0..8 {
            let got = ahead.take(&seq, i).unwrap_or_else(|| decode_frame(&seq, i));
            ahead.request(&seq, i + 1..(i + 1 + AHEAD).min(seq.len()));
            let (frame, image) = got.unwrap();
            let direct = decode_frame(&seq, i).unwrap();
            assert_eq!(frame, direct.0, "frame {i}");
            // The trackers' grey is the command line's; a grey file's channels are its grey.
            assert_eq!(frame.gray(), &seq.load_gray(i).unwrap());
            let Frame8::Colour(c) = &frame else {
                panic!("frame {i} decoded without its channels")
            };
            assert!(c.channels.iter().all(|p| p == frame.gray()));
            assert_eq!(image.index, i);
            let s = ahead.done.0.lock().unwrap();
            assert!(
                s.frames.len() + s.pending.len() <= AHEAD,
                "{} kept",
                s.frames.len()
            );
            assert!(s.frames.keys().all(|&k| k > i));
        }
        // A seek back keeps only the frames just after it.
        ahead.request(&seq, 4..8);
        std::thread::sleep(Duration::from_millis(50));
        let _ = ahead.take(&seq, 0);
        let s = ahead.done.0.lock().unwrap();
        assert!(
            s.frames
                .keys()
                .chain(s.pending.iter())
                .all(|&k| (1..=AHEAD).contains(&k))
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
