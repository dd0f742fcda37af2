//! What every tracker is: initialised on a frame and a quad, then updated frame by frame
//! ([`VisualTracker`]), with what it is given ([`FrameInput`]) and what it shows of itself
//! ([`Inspection`], [`Landscape`]).

use crate::error::Result;
use crate::geometry::Quad;
use crate::imaging::{ColourU8, Frame8, GrayF32, GrayU8, ImageRef};
use crate::landscape::{Landscape, LandscapeSpec};
use crate::observe::Observer;
use crate::spec::TrackerSpec;
use crate::status::{FrameOutcome, TrackStatus};

/// What a tracker is given for a frame.
#[derive(Clone, Copy, Debug)]
pub enum FrameInput<'a> {
    /// An 8-bit frame: the tracker converts and smooths only the region it reads (live path).
    Gray8(&'a GrayU8),
    /// A float frame, not smoothed yet: likewise.
    Gray32(&'a GrayF32),
    /// A float frame already smoothed by the caller: used as it is (tracker-only timing).
    Smoothed(&'a GrayF32),
    /// An 8-bit frame in someone else's buffer (numpy's, a decoder's), read where it is: as
    /// `Gray8` otherwise.
    View8(ImageRef<'a, u8>),
    /// An 8-bit colour frame: a tracker with `channels = rgb` reads its three channels, every
    /// other one its grey image ([`FrameInput::gray`]).
    Colour(&'a ColourU8),
}

impl<'a> FrameInput<'a> {
    /// `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        match self {
            FrameInput::Gray8(i) => (i.width, i.height),
            FrameInput::Gray32(i) | FrameInput::Smoothed(i) => (i.width, i.height),
            FrameInput::View8(i) => (i.width, i.height),
            FrameInput::Colour(c) => c.size(),
        }
    }

    /// The frame as a grey reader takes it: a colour frame's grey image, any other as it is.
    pub fn gray(self) -> FrameInput<'a> {
        match self {
            FrameInput::Colour(c) => FrameInput::Gray8(&c.gray),
            other => other,
        }
    }

    /// The colour frame, if it is one.
    pub fn colour(self) -> Option<&'a ColourU8> {
        match self {
            FrameInput::Colour(c) => Some(c),
            _ => None,
        }
    }

    /// The input of a frame a sequence handed out.
    pub fn of(frame: &'a Frame8) -> Self {
        match frame {
            Frame8::Gray(g) => FrameInput::Gray8(g),
            Frame8::Colour(c) => FrameInput::Colour(c),
        }
    }
}

/// Checks that `quad` can start a tracker on a `width x height` frame: a usable quad
/// ([`Quad::validate`]) at least part of which is in the frame.
pub fn check_initial_region(quad: &Quad, width: usize, height: usize) -> Result<()> {
    quad.validate()?;
    let crate::geometry::Rect { x0, y0, x1, y1 } = quad.bbox();
    if x1 <= 0.0 || y1 <= 0.0 || x0 >= width as f64 || y0 >= height as f64 {
        return Err(crate::Error::InvalidRegion(format!(
            "{quad} lies outside the {width}x{height} frame"
        )));
    }
    Ok(())
}

/// Re-exported here beside [`why_flat`], which says it in its errors.
pub use crate::geometry::fraction_inside;

/// Why a region's template has no gradient, for the error that refuses it: the part of it
/// outside the frame, and the frame's pixels there when they are all one value (a blank or
/// damaged frame, such as the grey a decoder shows for a video cut short).
pub fn why_flat(quad: &Quad, input: FrameInput<'_>) -> String {
    let input = input.gray();
    let (w, h) = input.size();
    let mut why = Vec::new();
    let inside = fraction_inside(quad, w, h);
    if inside < 1.0 - 1e-9 {
        why.push(format!(
            "{:.0} % of the region lies outside the {w}x{h} frame",
            (1.0 - inside) * 100.0
        ));
    }
    let b = quad.bbox();
    let (x0, y0) = (
        b.x0.max(0.0).floor() as usize,
        b.y0.max(0.0).floor() as usize,
    );
    let (x1, y1) = (
        (b.x1.ceil().max(0.0) as usize).min(w),
        (b.y1.ceil().max(0.0) as usize).min(h),
    );
    let mut range: Option<(f32, f32)> = None;
    for y in y0..y1 {
        for x in x0..x1 {
            let v = match input {
                FrameInput::Gray8(i) => i.data[y * w + x] as f32,
                FrameInput::View8(i) => i.data[y * w + x] as f32,
                FrameInput::Gray32(i) | FrameInput::Smoothed(i) => i.data[y * w + x],
                FrameInput::Colour(c) => c.gray.data[y * w + x] as f32,
            };
            range = Some(range.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
        }
    }
    match range {
        Some((lo, hi)) if lo == hi => why.push(format!(
            "every pixel of the frame there is {lo}: a blank frame, or a damaged one (a video \
             cut short decodes as one grey)"
        )),
        Some((lo, hi)) if hi - lo < 2.0 => why.push(format!(
            "the frame's pixels there differ by {} at most",
            hi - lo
        )),
        _ => {}
    }
    if why.is_empty() {
        "its pixels barely vary".into()
    } else {
        why.join("; ")
    }
}

impl<'a> From<&'a GrayU8> for FrameInput<'a> {
    fn from(i: &'a GrayU8) -> Self {
        FrameInput::Gray8(i)
    }
}

/// A lattice of `side x side` points on the template's quad, row by row (the first along its
/// first side), under a tracker's warp, in image coordinates: what a non-rigid warp does to the
/// target between its corners.
#[derive(Clone, Debug, PartialEq)]
pub struct WarpedGrid {
    pub side: usize,
    pub points: Vec<crate::geometry::Point>,
}

/// What a tracker shows of its inner state for inspection: the template and the current patch
/// (on a `res x res` grid, row-major; a colour tracker's `channels` such patches, red, green
/// and blue, one after the other), from which the error image follows.
#[derive(Clone, Copy, Debug)]
pub struct Inspection<'a> {
    pub res: usize,
    pub channels: usize,
    pub template: &'a [f32],
    pub patch: &'a [f32],
}

/// Any tracker: initialised on a frame and a quad, then updated frame by frame. Registration
/// trackers ([`crate::plan::RegistrationTracker`]) and whole trackers
/// ([`crate::whole::REGISTRY`]) implement it; the evaluation, the benchmarks, the command line
/// and the inspector use only this (through [`crate::tracker::Tracker`]).
pub trait VisualTracker: Send + std::fmt::Debug {
    /// The spec it was built from (with canonical names).
    fn spec(&self) -> &TrackerSpec;
    /// Starts tracking `quad` in `input`.
    fn initialize(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()>;
    /// Tracks one frame. Never panics and never returns non-finite corners: a loss of track is
    /// reported in the status, with the last good corners.
    fn update(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome;
    /// Moves the tracker to `quad` keeping what it learnt, and resumes tracking if it was lost.
    fn set_corners(&mut self, quad: &Quad) -> Result<()>;
    /// Current status.
    fn status(&self) -> TrackStatus;
    /// Current corners (image coordinates).
    fn corners(&self) -> Quad;
    /// The template and current patch, for trackers that have them.
    fn inspection(&self) -> Option<Inspection<'_>> {
        None
    }
    /// The frame's channels it reads: 1 (grey, every tracker but a registration tracker with
    /// `channels = rgb`; descriptor fields, `channels = df`, are made of the grey) or 3. A caller that has colour frames hands them to a tracker of 3
    /// ([`FrameInput::Colour`]); a grey frame given to it is read as three equal channels.
    fn channels(&self) -> usize {
        1
    }
    /// A non-rigid tracker's warp drawn as a lattice over its target (the inspector draws it);
    /// `None` for the others.
    fn warped_grid(&self) -> Option<WarpedGrid> {
        None
    }
    /// The label used in file names and tables.
    fn label(&self) -> String {
        self.spec().label()
    }
    /// The similarity swept around the warp whose corners are `at`, on `input` (see
    /// [`crate::landscape`]); `None` for trackers without a similarity over warps.
    fn landscape(
        &mut self,
        _input: FrameInput<'_>,
        _at: &Quad,
        _spec: &LandscapeSpec,
    ) -> Option<Result<Landscape>> {
        None
    }
}
