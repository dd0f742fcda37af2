//! Where a registration tracker reads a frame: [`FrameSource`] pre-processes the region around
//! the target (conversion to float, Gaussian smoothing, the pyramid's levels) into buffers it
//! keeps between frames, and hands out views of it. It is the one place that knows the cases of
//! [`FrameInput`] (an 8-bit frame, a float one, someone else's buffer, a frame already
//! smoothed).
//!
//! A search whose patches are all at the parameters it reports ([`crate::registration::SearchMethod::local`])
//! may read the region smoothed only where its patches so far read ([`Reader::Part`]):
//! [`Reader::cover`] smooths the rest before a patch reads beyond (the region's whole smoothing
//! was a seventh of a frame's work for a target that stays within a few pixels of where it
//! started). The values read are the same bits either way: a pixel's smoothed value depends
//! only on the image around it.
//!
//! The pyramid's coarser levels are made only when a stage asks for them
//! ([`FrameSource::build_levels`]): a frame that the finest level's search settles does not
//! pay for them.

use crate::geometry::{Quad, Rect};
use crate::imaging::{FIELDS, GaussianKernel, ImageRef, ImageView, Preprocessor};
use crate::imaging::{GrayF32, descriptor_fields_into, gaussian_kernel, new_stamp};
use crate::visual_tracker::FrameInput;

/// Pixels around a patch's corners its sampling reads: the 4 x 4 neighbourhood of a point
/// (one before, two after) and a pixel for rounding.
const READ_PX: f64 = 4.0;

/// The pixels the patch whose corners are `q` reads, grown by `more`: the bounding box of a
/// convex quad (which holds its grid's points); everything for any other.
pub fn reads(q: &Quad, more: f64) -> Rect {
    if !(q.is_finite() && q.is_convex()) {
        return Rect::EVERYTHING;
    }
    q.bbox().grown(READ_PX + more)
}

/// The region to pre-process around `q`: its bounding box grown by `margin` times its larger
/// side and 8 px.
pub fn region_around(q: &Quad, margin: f64) -> Rect {
    let b = q.bbox();
    b.grown(margin * b.width().max(b.height()) + 8.0)
}

/// A frame as the pre-processor reads it.
#[derive(Clone, Copy)]
enum Raw<'a> {
    U8(ImageRef<'a, u8>),
    F32(ImageRef<'a, f32>),
    /// Already smoothed by the caller: read as it is.
    Smoothed(&'a GrayF32),
}

impl<'a> Raw<'a> {
    /// Plane `plane` of `input` as a tracker of `channels` reads it: a grey tracker reads a
    /// colour frame's grey image, a colour tracker its channel `plane`.
    fn of(input: FrameInput<'a>, channels: usize, plane: usize) -> Self {
        match input {
            FrameInput::Colour(c) if channels == 3 => Raw::U8((&c.channels[plane]).into()),
            FrameInput::Colour(c) => Raw::U8((&c.gray).into()),
            FrameInput::Gray8(img) => Raw::U8(img.into()),
            FrameInput::View8(img) => Raw::U8(img),
            FrameInput::Gray32(img) => Raw::F32(img.into()),
            FrameInput::Smoothed(img) => Raw::Smoothed(img),
        }
    }
}

/// See the module's documentation.
#[derive(Clone, Debug)]
pub struct FrameSource {
    /// The finest level's region, smoothed by the tracker's kernel, and its coarser levels:
    /// the grey frame's, or a colour tracker's first channel's.
    pre: Preprocessor,
    /// A colour tracker's second and third channels, or the other three descriptor fields,
    /// made as `pre` (empty for grey).
    others: Vec<Preprocessor>,
    /// A descriptor-field source's raw fields of the grey frame (frame-sized, filled around
    /// each region before the planes smooth them; see [`FrameSource::with_descriptor_fields`]).
    fields: Option<Box<[GrayF32; FIELDS]>>,
    /// Whether the frame last prepared had its own channels (a grey frame given to a colour
    /// tracker is read as three equal ones, from `pre`).
    colour: bool,
    /// The coarser levels of a frame the caller smoothed.
    copy: Preprocessor,
    /// The coarse pyramid levels made of each region.
    levels: usize,
    /// Whether the last region's coarse levels are made, and the region (for a frame the caller
    /// smoothed, whose levels are made of a copy of it).
    built: bool,
    region: Rect,
    /// The stamp of the views of a frame the caller smoothed ([`ImageView::stamp`]).
    stamp: u64,
}

impl FrameSource {
    /// A source that smooths with `kernel` and makes `levels` coarser levels of each region.
    pub fn new(kernel: GaussianKernel, levels: usize) -> Self {
        FrameSource {
            pre: Preprocessor::new(kernel),
            others: Vec::new(),
            fields: None,
            colour: false,
            copy: Preprocessor::new(gaussian_kernel(1, 0.0)),
            levels,
            built: false,
            region: Rect::default(),
            stamp: 0,
        }
    }

    /// The same source reading `channels` (1, or 3: a colour tracker's, whose views have the
    /// frame's three channels as planes, [`ImageView::with_planes`]).
    pub fn with_channels(mut self, channels: usize) -> Self {
        let more = if channels == 3 { 2 } else { 0 };
        self.others = vec![self.pre.clone(); more];
        self
    }

    /// The same source reading the grey frame's four descriptor fields
    /// ([`crate::imaging::descriptor_fields_into`]) as its planes, each smoothed (and its
    /// pyramid made) by the source's kernel as a grey source smooths the frame. The whole
    /// region is made at once (no reading in part), and a frame the caller smoothed is read as
    /// the grey frame (its fields smoothed again).
    pub fn with_descriptor_fields(mut self) -> Self {
        self.others = vec![self.pre.clone(); FIELDS - 1];
        self.fields = Some(Box::default());
        self
    }

    /// The channels its views have (1, 3 or 4).
    pub fn channels(&self) -> usize {
        1 + self.others.len()
    }

    /// The coarser pyramid levels made of each region.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// The smoothing kernel of the finest level.
    pub fn kernel(&self) -> &GaussianKernel {
        self.pre.kernel()
    }

    /// Pre-processes `region` of `input` (its pyramid levels when asked,
    /// [`FrameSource::build_levels`]).
    pub fn prepare(&mut self, input: FrameInput<'_>, region: Rect) {
        self.prepare_part(input, region, region);
    }

    /// [`FrameSource::prepare`], smoothing the finest level only within `part` of the region
    /// (see [`Reader::Part`]; the pyramid's levels complete it when they are made).
    pub fn prepare_part(&mut self, input: FrameInput<'_>, region: Rect, part: Rect) {
        // Another frame or region: views of it are new content.
        self.stamp = new_stamp();
        self.built = false;
        self.region = region;
        if let Some(fields) = self.fields.as_deref_mut() {
            // The fields wherever the smoothing of the region reads (and a pixel more).
            let rect = region.grown((self.pre.kernel().radius() + 1) as f64);
            match Raw::of(input, 1, 0) {
                Raw::U8(img) => descriptor_fields_into(img, rect, fields),
                Raw::F32(img) => descriptor_fields_into(img, rect, fields),
                Raw::Smoothed(img) => descriptor_fields_into(img, rect, fields),
            }
            let planes = std::iter::once(&mut self.pre).chain(&mut self.others);
            for (pre, field) in planes.zip(fields.iter()) {
                pre.process(field, region);
            }
            self.colour = true;
            return;
        }
        self.colour = self.channels() == 3 && input.colour().is_some();
        for (pre, raw) in self.planes_mut(input) {
            match raw {
                Raw::U8(img) => pre.process_part(img, region, part),
                Raw::F32(img) => pre.process_part(img, region, part),
                Raw::Smoothed(_) => {}
            }
        }
    }

    /// Makes the coarser pyramid levels of the region last prepared (completing its smoothing
    /// first), once per region.
    pub fn build_levels(&mut self, input: FrameInput<'_>) {
        if self.built || self.levels == 0 {
            return;
        }
        self.built = true;
        // A field source made its planes of a frame the caller smoothed as of any other.
        if let Raw::Smoothed(img) = Raw::of(input, 1, 0)
            && self.fields.is_none()
        {
            self.copy.process(img, self.region);
            self.copy.build_levels(self.levels);
            return;
        }
        let levels = self.levels;
        for (pre, raw) in self.planes_mut(input) {
            complete(pre, raw);
            pre.build_levels(levels);
        }
    }

    /// The pre-processors of the planes the last frame has (its channels, or the grey), each
    /// with what it reads of `input` ([`Raw::of`]).
    fn planes_mut<'s, 'a>(
        &'s mut self,
        input: FrameInput<'a>,
    ) -> impl Iterator<Item = (&'s mut Preprocessor, Raw<'a>)> {
        let channels = self.channels();
        let n = if self.colour { self.others.len() } else { 0 };
        let planes = std::iter::once(&mut self.pre).chain(&mut self.others[..n]);
        planes
            .enumerate()
            .map(move |(c, pre)| (pre, Raw::of(input, channels, c)))
    }

    /// Smooths the rest of a region each plane's pre-processor smoothed in part.
    fn complete_planes(&mut self, input: FrameInput<'_>) {
        for (pre, raw) in self.planes_mut(input) {
            complete(pre, raw);
        }
    }

    /// The region last pre-processed, in whole pixels.
    pub fn region(&self) -> Rect {
        self.pre.region()
    }

    /// Whether the region last pre-processed is smoothed whole (not only in part).
    pub fn is_whole(&self) -> bool {
        self.pre.is_whole()
    }

    /// Pyramid level `level` (0: the finest) of the frame last prepared from `input`; for a
    /// colour tracker a view of three planes (a grey frame's three times), for a field
    /// tracker of its four fields.
    pub fn view<'a>(&'a self, input: FrameInput<'a>, level: usize) -> ImageView<'a> {
        let v = match input {
            _ if self.fields.is_some() => self.pre.level_view(level),
            FrameInput::Smoothed(img) if level == 0 => img.view().with_stamp(self.stamp),
            FrameInput::Smoothed(_) => self.copy.level_view(level),
            _ => self.pre.level_view(level),
        };
        self.with_planes(v, level)
    }

    /// `v` (plane 0 of `level`) with the other planes of a colour tracker, or the other
    /// descriptor fields.
    fn with_planes<'a>(&'a self, v: ImageView<'a>, level: usize) -> ImageView<'a> {
        match self.others.as_slice() {
            [a, b, c] => v.with_more_planes(&[
                a.level_view(level).pixels(),
                b.level_view(level).pixels(),
                c.level_view(level).pixels(),
            ]),
            [g, b] if self.colour => {
                v.with_planes(g.level_view(level).pixels(), b.level_view(level).pixels())
            }
            [_, _] => v.with_planes(v.pixels(), v.pixels()),
            _ => v,
        }
    }

    /// The finest level of the frame last prepared from `input`, to be read by a search:
    /// smoothed only in part when `part` (as [`FrameSource::prepare_part`] left it).
    pub fn reader<'a>(&'a mut self, input: FrameInput<'a>, part: bool) -> Reader<'a> {
        if part && self.fields.is_none() && !matches!(input, FrameInput::Smoothed(_)) {
            Reader::Part { src: self, input }
        } else {
            Reader::Whole(self.view(input, 0))
        }
    }

    /// Makes sure that the patch with corners `q` reads pre-processed pixels of `input`: the
    /// region is made again around `q` (grown by `margin`, see [`region_around`]) when `q` is
    /// not inside it, completed when it was smoothed only in part.
    pub fn hold(&mut self, input: FrameInput<'_>, q: &Quad, margin: f64) {
        let smoothed = matches!(input, FrameInput::Smoothed(_)) && self.fields.is_none();
        if !self.region().contains(&q.bbox()) && !smoothed {
            self.prepare(input, region_around(q, margin));
        } else if !self.pre.holds(&reads(q, 0.0)) {
            // A region smoothed in part, by another search than the one whose end is kept.
            self.complete_planes(input);
        }
    }

    /// Whether a frame may be read in parts: raw input (a frame the caller smoothed is read
    /// whole).
    pub fn can_part(input: FrameInput<'_>) -> bool {
        !matches!(input, FrameInput::Smoothed(_))
    }
}

/// Smooths the rest of a region that [`Preprocessor::process_part`] smoothed in part, from
/// `raw`, the image it was given.
fn complete(pre: &mut Preprocessor, raw: Raw<'_>) {
    match raw {
        Raw::U8(img) => pre.complete(img),
        Raw::F32(img) => pre.complete(img),
        Raw::Smoothed(_) => {}
    }
}

/// The finest level a search reads. Either a view that holds every pixel it may read (the
/// pre-processed region, a pre-smoothed frame, a pyramid level) or the region smoothed only
/// where the patches so far read (see the module's documentation).
pub enum Reader<'a> {
    Whole(ImageView<'a>),
    Part {
        src: &'a mut FrameSource,
        input: FrameInput<'a>,
    },
}

impl Reader<'_> {
    /// The view to sample.
    pub fn view(&self) -> ImageView<'_> {
        match self {
            Reader::Whole(v) => *v,
            Reader::Part { src, .. } => src.with_planes(src.pre.view(), 0),
        }
    }

    /// Makes sure that the patch with corners `q` reads smoothed pixels only.
    pub fn cover(&mut self, q: &Quad) {
        if let Reader::Part { src, input } = self
            && !src.pre.holds(&reads(q, 0.0))
        {
            src.complete_planes(*input);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imaging::GrayU8;

    fn frame() -> GrayU8 {
        let data = (0..64 * 48).map(|i| ((i * 37) % 251) as u8).collect();
        GrayU8::from_vec(64, 48, data).unwrap()
    }

    /// Each frame prepared is new content (a new stamp, for every level and for a frame the
    /// caller smoothed), completing a region smoothed in part is not; `hold` makes the region
    /// again around a quad outside it and completes one smoothed in part.
    #[test]
    fn a_prepared_frame_is_new_content_and_hold_covers_a_quad() {
        let g = frame();
        let input = FrameInput::Gray8(&g);
        let mut src = FrameSource::new(gaussian_kernel(5, 1.0), 1);
        src.prepare(input, Rect::new(4.0, 4.0, 40.0, 30.0));
        src.build_levels(input);
        let (a0, a1) = (src.view(input, 0).stamp(), src.view(input, 1).stamp());
        assert!(a0 != 0 && a1 != 0 && a0 != a1);
        src.prepare(input, Rect::new(4.0, 4.0, 40.0, 30.0));
        src.build_levels(input);
        let (b0, b1) = (src.view(input, 0).stamp(), src.view(input, 1).stamp());
        assert!(b0 != a0 && b1 != a1 && b0 != b1);
        let smoothed = crate::imaging::gaussian_blur(&g, src.kernel());
        let s = FrameInput::Smoothed(&smoothed);
        src.prepare(s, Rect::new(4.0, 4.0, 40.0, 30.0));
        let c0 = src.view(s, 0).stamp();
        src.prepare(s, Rect::new(4.0, 4.0, 40.0, 30.0));
        assert!(c0 != 0 && src.view(s, 0).stamp() != c0);

        // In part, then held around a quad inside the region: completed, same stamp.
        let mut src = FrameSource::new(gaussian_kernel(5, 1.0), 0);
        let region = Rect::new(0.0, 0.0, 50.0, 40.0);
        src.prepare_part(input, region, Rect::new(10.0, 10.0, 20.0, 20.0));
        assert!(!src.is_whole());
        let stamp = src.view(input, 0).stamp();
        let q = Quad::from_rect(25.0, 20.0, 10.0, 10.0);
        src.hold(input, &q, 0.25);
        assert!(src.is_whole() && src.region() == region);
        assert_eq!(src.view(input, 0).stamp(), stamp);
        // A quad beyond the region: made again around it.
        let far = Quad::from_rect(50.0, 30.0, 8.0, 8.0);
        src.hold(input, &far, 0.25);
        assert!(src.region().contains(&far.bbox()));
        assert_ne!(src.view(input, 0).stamp(), stamp);
        // Read in part, a reader covers what a patch reads.
        src.prepare_part(input, region, Rect::new(10.0, 10.0, 30.0, 30.0));
        let mut reader = src.reader(input, true);
        reader.cover(&Quad::from_rect(15.0, 15.0, 5.0, 5.0));
        assert!(matches!(reader, Reader::Part { ref src, .. } if !src.is_whole()));
        reader.cover(&q);
        assert!(matches!(reader, Reader::Part { ref src, .. } if src.is_whole()));
        assert!(matches!(src.reader(s, true), Reader::Whole(_)));
    }

    /// Plane `c` of `v` is level `level` of what a grey source makes of `plane` over `region`
    /// (the same kernel, the same pyramid).
    fn assert_plane_is_grey(
        v: &ImageView<'_>,
        c: usize,
        plane: FrameInput<'_>,
        region: Rect,
        level: usize,
    ) {
        let mut grey = FrameSource::new(gaussian_kernel(5, 1.0), 1);
        grey.prepare(plane, region);
        grey.build_levels(plane);
        let want = grey.view(plane, level);
        assert_eq!(
            v.plane(c).pixels(),
            want.pixels(),
            "level {level} plane {c}"
        );
        assert_eq!(v.plane(c).origin(), want.origin());
    }

    /// A colour source's views have the frame's three channels as planes, each smoothed (and
    /// its pyramid made) as a grey source smooths that channel; read in part and covered, the
    /// same bits. A grey frame given to it is three equal planes; a grey source reads a colour
    /// frame's grey.
    #[test]
    fn a_colour_source_makes_each_channel_as_a_grey_one() {
        let (w, h) = (64, 48);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| ((i * 53) % 241) as u8).collect();
        let colour = crate::imaging::ColourU8::from_rgb(w, h, &rgb).unwrap();
        let input = FrameInput::Colour(&colour);
        let region = Rect::new(3.0, 2.0, 50.0, 40.0);
        let mut src = FrameSource::new(gaussian_kernel(5, 1.0), 1).with_channels(3);
        assert_eq!(src.channels(), 3);
        src.prepare(input, region);
        src.build_levels(input);
        for level in 0..2 {
            let v = src.view(input, level);
            assert_eq!(v.planes(), 3);
            for c in 0..3 {
                let plane = FrameInput::Gray8(&colour.channels[c]);
                assert_plane_is_grey(&v, c, plane, region, level);
            }
        }
        // In part, then covered: the whole region's bits in every plane.
        let whole: Vec<Vec<f32>> = (0..3)
            .map(|c| src.view(input, 0).plane(c).pixels().to_vec())
            .collect();
        src.prepare_part(input, region, Rect::new(10.0, 10.0, 20.0, 20.0));
        let mut reader = src.reader(input, true);
        reader.cover(&Quad::from_rect(30.0, 25.0, 10.0, 10.0));
        for (c, want) in whole.iter().enumerate() {
            assert_eq!(reader.view().plane(c).pixels(), &want[..], "channel {c}");
        }
        // A grey frame: three equal planes.
        let g = frame();
        src.prepare(FrameInput::Gray8(&g), region);
        let v = src.view(FrameInput::Gray8(&g), 0);
        assert_eq!(v.planes(), 3);
        assert_eq!(v.plane(1).pixels(), v.plane(0).pixels());
        assert_eq!(v.plane(2).pixels(), v.plane(0).pixels());
        // A grey source on a colour frame: its grey.
        let mut grey = FrameSource::new(gaussian_kernel(5, 1.0), 0);
        grey.prepare(input, region);
        let mut luma = FrameSource::new(gaussian_kernel(5, 1.0), 0);
        luma.prepare(FrameInput::Gray8(&colour.gray), region);
        let (a, b) = (
            grey.view(input, 0),
            luma.view(FrameInput::Gray8(&colour.gray), 0),
        );
        assert_eq!(a.planes(), 1);
        assert_eq!(a.pixels(), b.pixels());
    }

    /// A descriptor-field source's views have the grey frame's four fields as planes, each
    /// smoothed (and its pyramid made) as a grey source smooths that field made of the whole
    /// frame; a colour frame is read as its grey, a frame the caller smoothed as a grey frame.
    #[test]
    fn a_descriptor_field_source_smooths_each_field_as_a_grey_one() {
        let g = frame();
        let input = FrameInput::Gray8(&g);
        let mut whole: [GrayF32; FIELDS] = Default::default();
        descriptor_fields_into(
            &g,
            Rect::new(0.0, 0.0, g.width as f64, g.height as f64),
            &mut whole,
        );
        // Regions inside the frame and across its edges.
        for region in [
            Rect::new(9.0, 7.0, 41.0, 33.0),
            Rect::new(-5.0, 3.0, 30.0, 60.0),
        ] {
            let mut src = FrameSource::new(gaussian_kernel(5, 1.0), 1).with_descriptor_fields();
            assert_eq!(src.channels(), FIELDS);
            src.prepare_part(input, region, Rect::new(20.0, 20.0, 25.0, 25.0));
            assert!(src.is_whole(), "made whole at once");
            src.build_levels(input);
            for level in 0..2 {
                let v = src.view(input, level);
                assert_eq!(v.planes(), FIELDS);
                for (c, field) in whole.iter().enumerate() {
                    assert_plane_is_grey(&v, c, FrameInput::Gray32(field), region, level);
                }
            }
            let fields: Vec<Vec<f32>> = (0..FIELDS)
                .map(|c| src.view(input, 0).plane(c).pixels().to_vec())
                .collect();
            // Read through a reader (never in part) and as a colour frame's grey.
            assert_eq!(
                src.reader(input, true).view().plane(3).pixels(),
                &fields[3][..]
            );
            // Channels unlike the grey: the fields are the grey's.
            let rgb: Vec<u8> = (0..g.data.len() * 3)
                .map(|i| (i * 29 % 256) as u8)
                .collect();
            let colour = crate::imaging::ColourU8::from_rgb_and_gray(&rgb, g.clone()).unwrap();
            src.prepare(FrameInput::Colour(&colour), region);
            for (c, want) in fields.iter().enumerate() {
                let v = src.view(FrameInput::Colour(&colour), 0);
                assert_eq!(v.plane(c).pixels(), &want[..], "colour, field {c}");
            }
            // A frame the caller smoothed: its fields, smoothed again.
            let f32 = g.to_f32();
            src.prepare(FrameInput::Smoothed(&f32), region);
            let v = src.view(FrameInput::Smoothed(&f32), 0);
            assert_eq!(v.planes(), FIELDS);
            assert_eq!(v.plane(1).pixels(), &fields[1][..]);
        }
    }

    #[test]
    fn what_a_patch_reads_is_its_box_grown_or_everything() {
        let q = Quad::from_rect(10.0, 20.0, 30.0, 40.0);
        assert_eq!(reads(&q, 1.0), Rect::new(5.0, 15.0, 45.0, 65.0));
        let mut folded = q;
        folded.0.swap(0, 1);
        assert_eq!(reads(&folded, 1.0), Rect::EVERYTHING);
        assert_eq!(region_around(&q, 0.5), Rect::new(-18.0, -8.0, 68.0, 88.0));
    }
}
