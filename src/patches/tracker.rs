//! The many-patch tracker: N patches per frame over one pre-processed frame, in parallel over
//! a crew of threads (blocks of neighbouring patches, each thread in its own scratch).

use super::*;
use crate::crew::{self, Crew, Shares};
use crate::error::{Error, Result};
use crate::geometry::{Point, Quad};
use crate::imaging::{self, GaussianKernel, ImageRef, keypoints};
use crate::status::{LossReason, TrackStatus};

/// Tracks N patches per frame (see the module's documentation).
pub struct PatchTracker {
    pub(super) params: PatchParams,
    pub(super) grid: Grid,
    /// The frames' pre-smoothing.
    pub(super) kernel: GaussianKernel,
    pub(super) cur: Frame,
    pub(super) prev: Frame,
    /// The patches in raster order of their first positions (neighbours read the same rows
    /// of the frame one after the other, from the cache).
    pub(super) patches: Vec<Patch>,
    /// Where each patch, in the order it was given, is in `patches`.
    pub(super) order: Vec<usize>,
    /// The threads, each with its own [`Scratch`] (member 0 is the caller's).
    pub(super) crew: Crew<Scratch>,
    pub(super) size: (usize, usize),
    pub(super) frames: usize,
}

impl PatchTracker {
    /// A tracker with these settings and no patches.
    pub fn new(params: PatchParams) -> Result<Self> {
        let sigma = params.smoothing as f32;
        let kernel = if sigma > 0.0 {
            imaging::gaussian_kernel(2 * (2.0 * sigma).ceil() as usize + 1, sigma)
        } else {
            imaging::gaussian_kernel(1, 0.0)
        };
        let grid = Grid::new(params.size);
        let scratch = Scratch::new(&grid, params.levels, params.warp.dof());
        let mut crew = Crew::try_new(vec![scratch; crew::threads_for(params.threads)])
            .map_err(|e| Error::InvalidParameter(format!("patches: threads: {e}")))?;
        // Each member's buffers made again by its own thread (from its own allocator arena):
        // the copies above lie side by side, and two cores writing the ends of neighbouring
        // buffers would share cache lines.
        crew.run(&|s: &mut Scratch, _| *s = s.clone());
        Ok(PatchTracker {
            grid,
            kernel,
            cur: Frame::default(),
            prev: Frame::default(),
            patches: Vec::new(),
            order: Vec::new(),
            crew,
            size: (0, 0),
            frames: 0,
            params,
        })
    }

    /// The settings.
    pub fn params(&self) -> &PatchParams {
        &self.params
    }

    /// Shi-Tomasi corners of `frame` (smoothed as the tracker smooths), at most `max`, at
    /// least `min_distance` apart, strongest first, where a whole patch fits in the frame and,
    /// with `region`, in that quad.
    pub fn detect<'a>(
        &mut self,
        frame: impl Into<ImageRef<'a, u8>>,
        max: usize,
        region: Option<&Quad>,
    ) -> Vec<Point> {
        let frame = frame.into();
        let mut f = Frame::default();
        f.build(frame, 1, 0, &self.kernel, &mut self.crew);
        let img = &f.levels[0];
        let half = self.grid.half;
        let border = half.ceil() as usize + 2;
        let bounds = match region {
            Some(q) => {
                let crate::geometry::Rect { x0, y0, x1, y1 } = q.bbox();
                (
                    x0.max(0.0) as usize,
                    y0.max(0.0) as usize,
                    (x1.max(0.0) as usize + 1).min(img.width),
                    (y1.max(0.0) as usize + 1).min(img.height),
                )
            }
            None => (0, 0, img.width, img.height),
        };
        // Every candidate (the spacing is applied after the region's test).
        let found = keypoints::shi_tomasi(img, 3, usize::MAX, 0.0, 0.01, border, bounds);
        let md2 = self.params.min_distance * self.params.min_distance;
        let mut kept: Vec<Point> = Vec::new();
        for k in found {
            if kept.len() >= max {
                break;
            }
            let p = k.point();
            if let Some(q) = region {
                let window = Quad::from_rect(p.x - half, p.y - half, 2.0 * half, 2.0 * half);
                if !window.0.iter().all(|&c| inside(q, c)) {
                    continue;
                }
            }
            if kept
                .iter()
                .any(|o| (o.x - p.x).powi(2) + (o.y - p.y).powi(2) < md2)
            {
                continue;
            }
            kept.push(p);
        }
        kept
    }

    /// Starts tracking a patch centred on each of `points` in `frame`. A point whose window is
    /// flat or outside the frame starts lost (its status says why).
    pub fn initialize<'a>(
        &mut self,
        frame: impl Into<ImageRef<'a, u8>>,
        points: &[Point],
    ) -> Result<()> {
        let frame = frame.into();
        if frame.width < 8 || frame.height < 8 {
            return Err(Error::InvalidParameter(format!(
                "patches: a {}x{} frame is too small",
                frame.width, frame.height
            )));
        }
        if let Some(k) = points.iter().position(|p| !p.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "patches: point {} is ({}, {}), not a position in the frame",
                k + 1,
                points[k].x,
                points[k].y
            )));
        }
        self.size = (frame.width, frame.height);
        self.build_current(frame);
        let levels = self.params.levels;
        let dof = self.params.warp.dof();
        let grid = &self.grid;
        let (w, h) = self.size;
        let mut scratch = self.crew.states().next().expect("a crew has a member");
        let scratch = &mut *scratch;
        // Raster order of the points, by rows of 16 pixels (ties keep the given order).
        let mut by_place: Vec<usize> = (0..points.len()).collect();
        let key = |p: Point| {
            if p.is_finite() {
                ((p.y / 16.0).floor() as i64, p.x)
            } else {
                (i64::MAX, 0.0)
            }
        };
        by_place.sort_by(|&a, &b| {
            let (ka, kb) = (key(points[a]), key(points[b]));
            ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
        });
        self.order = vec![0; points.len()];
        for (place, &k) in by_place.iter().enumerate() {
            self.order[k] = place;
        }
        self.patches = by_place
            .iter()
            .map(|&k| points[k])
            .map(|c| {
                let mut p = Patch::new(c);
                let keep = self.params.template == TemplateSource::First;
                if keep {
                    p.first = Some(Box::new(Template::new(grid, levels, dof)));
                }
                if !(c.is_finite()
                    && c.x >= 0.0
                    && c.y >= 0.0
                    && c.x <= (w - 1) as f64
                    && c.y <= (h - 1) as f64)
                {
                    p.state.status = TrackStatus::Lost(LossReason::OutOfFrame);
                    if !c.is_finite() {
                        p.state.centre = Point::default();
                        p.warp = Warp::at(Point::default());
                    }
                } else {
                    let tp = match p.first.as_deref_mut() {
                        Some(tp) => tp,
                        None => &mut scratch.fwd,
                    };
                    if !make_template(
                        tp,
                        &mut scratch.buf,
                        &self.cur,
                        &Warp::at(c),
                        grid,
                        &self.params,
                    ) {
                        p.state.status = TrackStatus::Lost(LossReason::Singular);
                    }
                }
                p
            })
            .collect();
        self.frames = 1;
        Ok(())
    }

    /// Tracks every patch that is not lost into `frame`.
    pub fn update<'a>(&mut self, frame: impl Into<ImageRef<'a, u8>>) -> Result<()> {
        let frame = frame.into();
        if self.frames == 0 {
            return Err(Error::InvalidParameter(
                "patches: update before initialize".into(),
            ));
        }
        if (frame.width, frame.height) != self.size {
            return Err(Error::InvalidParameter(format!(
                "patches: a {}x{} frame after {}x{} ones",
                frame.width, frame.height, self.size.0, self.size.1
            )));
        }
        std::mem::swap(&mut self.cur, &mut self.prev);
        self.build_current(frame);
        let (cur, prev, grid, prm) = (&self.cur, &self.prev, &self.grid, &self.params);
        let size = self.size;
        // Blocks of neighbouring patches (they read the same rows of the frame): each thread
        // takes those of its own part first (the rows it built), then whichever are left.
        let shares = Shares::new(&mut self.patches, PATCH_BLOCK, self.crew.len());
        self.crew.run(&|scratch: &mut Scratch, m| {
            while let Some((_, block)) = shares.take(m) {
                for p in block {
                    track_patch(p, scratch, prev, cur, grid, prm, size);
                }
            }
        });
        self.frames += 1;
        Ok(())
    }

    /// Every patch's state, in the order of the initial points.
    pub fn states(&self) -> impl ExactSizeIterator<Item = &PatchState> {
        self.order.iter().map(|&k| &self.patches[k].state)
    }

    /// Patches followed now.
    pub fn tracking(&self) -> usize {
        self.states().filter(|s| s.tracking()).count()
    }

    /// Pre-processes `frame` into the current frame (its pyramid, by the crew).
    pub(super) fn build_current(&mut self, frame: ImageRef<'_, u8>) {
        let (levels, border) = (self.params.levels, self.border());
        self.cur
            .build(frame, levels, border, &self.kernel, &mut self.crew);
    }

    /// The border the frame's levels get: a patch whose centre is inside reads inside it.
    pub(super) fn border(&self) -> usize {
        // The grown grid's rows (`ext_stride` samples from `-half - 1`) read one pixel more.
        (self.grid.ext_stride as f64 - self.grid.half).ceil() as usize + 3
    }

    /// Half the side of a patch's window (pixels at the finest level).
    pub fn half_size(&self) -> f64 {
        self.grid.half
    }
}

/// One patch, one frame.
pub(super) fn track_patch(
    p: &mut Patch,
    scratch: &mut Scratch,
    prev: &Frame,
    cur: &Frame,
    grid: &Grid,
    prm: &PatchParams,
    (w, h): (usize, usize),
) {
    if !p.state.tracking() {
        p.state.iterations = 0;
        p.state.fb_error = None;
        return;
    }
    // Following the previous frame's patch, an affine patch is searched as the change between
    // the two frames, on a window aligned with the image (the local motion of the frame is the
    // same affine map whatever the window's shape): its template is a shifted grid, sampled
    // without gathers, and its shape is that change composed with its shape so far.
    let relative = prm.warp == PatchWarp::Affine && prm.template == TemplateSource::Previous;
    let start = if relative { Warp::at(p.warp.c) } else { p.warp };
    p.state.fb_error = None;
    let Scratch { fwd, back, buf, .. } = scratch;
    let fwd: &Template = match p.first.as_deref() {
        Some(first) => first,
        None => {
            if !make_template(fwd, buf, prev, &start, grid, prm) {
                p.state.status = TrackStatus::Lost(LossReason::Singular);
                return;
            }
            fwd
        }
    };
    let lose = |p: &mut Patch, r: LossReason| {
        p.state.status = TrackStatus::Lost(r);
    };
    match search(fwd, buf, cur, start, grid, prm) {
        Err(r) => lose(p, r),
        Ok((found, iterations, similarity)) => {
            p.state.iterations = iterations;
            p.state.ncc = similarity;
            let c = found.c;
            if !(c.x >= 0.0 && c.y >= 0.0 && c.x <= (w - 1) as f64 && c.y <= (h - 1) as f64) {
                return lose(p, LossReason::OutOfFrame);
            }
            if similarity < prm.min_ncc {
                return lose(p, LossReason::LowConfidence);
            }
            let shape = if relative {
                let (d, a) = (found.a, p.warp.a);
                [
                    d[0] * a[0] + d[1] * a[2],
                    d[0] * a[1] + d[1] * a[3],
                    d[2] * a[0] + d[3] * a[2],
                    d[2] * a[1] + d[3] * a[3],
                ]
            } else {
                found.a
            };
            if !(0.2..=5.0).contains(&(shape[0] * shape[3] - shape[1] * shape[2])) {
                return lose(p, LossReason::Degenerate);
            }
            if prm.fb_max > 0.0 {
                let back_start = if relative { Warp::at(c) } else { found };
                if !make_template(back, buf, cur, &back_start, grid, prm) {
                    return lose(p, LossReason::Singular);
                }
                match search(back, buf, prev, back_start, grid, prm) {
                    Err(r) => return lose(p, r),
                    Ok((back, _, _)) => {
                        let e = back.c.dist(start.c);
                        p.state.fb_error = Some(e);
                        if e > prm.fb_max {
                            return lose(p, LossReason::LowConfidence);
                        }
                    }
                }
            }
            p.warp = Warp { a: shape, c };
            p.state.centre = c;
            p.state.linear = shape;
        }
    }
}

/// Whether `p` is inside the convex quad `q` (either orientation).
pub(super) fn inside(q: &Quad, p: Point) -> bool {
    let mut sign = 0.0;
    for k in 0..4 {
        let (a, b) = (q.0[k], q.0[(k + 1) % 4]);
        let cross = (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
        if cross != 0.0 {
            if sign == 0.0 {
                sign = cross.signum();
            } else if cross.signum() != sign {
                return false;
            }
        }
    }
    true
}
