//! Many patches per frame: the paper's case for registration trackers in robotics ("tracking
//! based SLAM systems like SVO ... track hundreds to thousands of patches per frame").
//!
//! A [`PatchTracker`] follows N small patches (a square grid of `size` x `size` samples each),
//! every one with its own warp, translation or affine ([`PatchWarp`]), by inverse-compositional
//! Lucas-Kanade (Baker and Matthews) over one pre-processed frame shared by all: one smoothing,
//! one Gaussian pyramid, built once per frame (in bands of rows, by the threads). Patches are
//! independent, so they are tracked in parallel over the cores (a [`Crew`]: each thread takes
//! blocks of neighbouring patches and works in its own scratch, so a patch's template, made
//! again each frame, never leaves that core's cache) and give the same result, bit for bit, on
//! any number of threads.
//!
//! The template of a patch is the previous frame's patch (`template=previous`, as KLT does:
//! no appearance drift, a slow positional one) or the first frame's (`template=first`: no
//! positional drift; with an affine warp it follows rotation, scale and shear). Each frame a
//! patch reports a [`TrackStatus`]: it is lost when it leaves the frame, when its window is flat
//! (`min_eigen`), when its values stop being finite, when its affine shape degenerates, when
//! the tracked patch no longer looks like its template (`min_ncc`), or, with `fb_max`, when
//! tracking it back to the previous frame misses its start by more than `fb_max` pixels (the
//! forward-backward error of Kalal et al.). A lost patch keeps its last good position and is
//! not searched again.
//!
//! One frame, per patch and pyramid level (coarse to fine): the template's values `T(u)` and
//! their gradients in patch coordinates give the steepest-descent images `SD = grad T * dW/dp`
//! and the Hessian `H = SD^T SD` (once per template); each iteration samples the frame at the
//! warped grid `I(W(u))`, solves `dp = H^-1 SD^T (I(W(u)) - T(u))` and composes the inverse of
//! the increment, `W <- W o W(dp)^-1`, until the patch's corners move less than `eps` pixels
//! (of that level). A translation warp samples a grid that only shifts, whose bilinear weights
//! are the same for every sample ([`imaging::sample_grid_shifted`]).

use crate::crew::{self, Crew, Shares};
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::{Point, Quad, apply_homography, homography_between};
use crate::imaging::{self, COARSE_EPS, GaussianKernel, GrayF32, ImageRef, ImageView, keypoints};
use crate::params::{MethodParams, ParamDef};
use crate::status::{LossReason, TrackStatus};
use nalgebra::{Matrix2, SMatrix};
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

mod kernels;
use kernels::{dot, dot2};

/// The warps a patch can have.
pub const WARPS: &[&str] = &["translation", "affine"];
/// Where a patch's template comes from.
pub const TEMPLATES: &[&str] = &["previous", "first"];

/// The many-patch tracker's parameters: their one definition (the command line's `--patch
/// name=value`, the Python binding's keywords and `regtrack list` read it).
pub const PATCH_PARAMS: &[ParamDef] = &[
    ParamDef::choice(
        "warp",
        "The warp of each patch: translation (2 parameters) or affine (6)",
        WARPS,
    ),
    ParamDef::int(
        "size",
        "Side of a patch's sampling grid, in pixels of each pyramid level",
        5.0,
        51.0,
        15.0,
    ),
    ParamDef::int(
        "levels",
        "Pyramid levels (1 = full resolution only)",
        1.0,
        6.0,
        3.0,
    ),
    ParamDef::int(
        "iterations",
        "Iterations per pyramid level at most",
        1.0,
        100.0,
        30.0,
    ),
    ParamDef::float(
        "eps",
        "Stop a level's iterations when the patch's corners move less than this (pixels of the level)",
        1e-4,
        1.0,
        0.01,
    ),
    ParamDef::choice(
        "template",
        "The template: the previous frame's patch (KLT) or the first frame's",
        TEMPLATES,
    ),
    ParamDef::float(
        "min_ncc",
        "A patch whose normalised cross-correlation with its template falls below this is lost",
        -1.0,
        1.0,
        0.7,
    ),
    ParamDef::float(
        "min_eigen",
        "A window whose structure tensor's smaller eigenvalue (per pixel, gray levels squared) is below this is flat: lost",
        0.0,
        1e5,
        1.0,
    ),
    ParamDef::float(
        "fb_max",
        "Also track each patch back to the previous frame; lost when it misses its start by more than this (pixels; 0 = no check)",
        0.0,
        1000.0,
        0.0,
    ),
    ParamDef::float(
        "smoothing",
        "Gaussian pre-smoothing of the frame, standard deviation in pixels (0 = none)",
        0.0,
        10.0,
        1.0,
    ),
    ParamDef::float(
        "min_distance",
        "Detected corners are at least this far apart (pixels)",
        0.0,
        1000.0,
        8.0,
    ),
    ParamDef::int(
        "threads",
        "Threads tracking the patches (0 = all cores)",
        0.0,
        1024.0,
        0.0,
    ),
];

/// The warp of a patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatchWarp {
    /// A shift: 2 parameters.
    Translation,
    /// A linear map and a shift: 6 parameters.
    Affine,
}

impl PatchWarp {
    fn dof(self) -> usize {
        match self {
            PatchWarp::Translation => 2,
            PatchWarp::Affine => 6,
        }
    }
}

/// Where a patch's template comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TemplateSource {
    /// The patch in the previous frame, where it was tracked (KLT).
    Previous,
    /// The patch in the frame it was initialised on.
    First,
}

/// The many-patch tracker's settings (see [`PATCH_PARAMS`] for each).
#[derive(Clone, Debug, PartialEq)]
pub struct PatchParams {
    pub warp: PatchWarp,
    pub size: usize,
    pub levels: usize,
    pub iterations: usize,
    pub eps: f64,
    pub template: TemplateSource,
    pub min_ncc: f64,
    pub min_eigen: f64,
    pub fb_max: f64,
    pub smoothing: f64,
    pub min_distance: f64,
    pub threads: usize,
}

impl Default for PatchParams {
    fn default() -> Self {
        Self::from_values(&MethodParams::default()).unwrap_or_else(|_| unreachable!())
    }
}

impl PatchParams {
    /// The settings from values by name ([`PATCH_PARAMS`]'s defaults for the others); an unknown
    /// name or a value out of range is an error naming it.
    pub fn from_values(v: &MethodParams) -> Result<Self> {
        let defs: Vec<&ParamDef> = PATCH_PARAMS.iter().collect();
        v.validate("patches", &defs)?;
        let get = |name: &str| {
            PATCH_PARAMS
                .iter()
                .find(|d| d.name == name)
                .map_or(0.0, |d| v.get(d))
        };
        Ok(PatchParams {
            warp: if get("warp") == 1.0 {
                PatchWarp::Affine
            } else {
                PatchWarp::Translation
            },
            size: get("size") as usize,
            levels: get("levels") as usize,
            iterations: get("iterations") as usize,
            eps: get("eps"),
            template: if get("template") == 1.0 {
                TemplateSource::First
            } else {
                TemplateSource::Previous
            },
            min_ncc: get("min_ncc"),
            min_eigen: get("min_eigen"),
            fb_max: get("fb_max"),
            smoothing: get("smoothing"),
            min_distance: get("min_distance"),
            threads: get("threads") as usize,
        })
    }

    /// The settings from `name=value` assignments (choices by name).
    pub fn parse(assignments: &[(String, String)]) -> Result<Self> {
        let mut v = MethodParams::default();
        for (name, value) in assignments {
            let def = PATCH_PARAMS
                .iter()
                .find(|d| d.name == name.as_str())
                .ok_or_else(|| {
                    Error::InvalidParameter(format!(
                        "patches have no parameter '{name}'; their parameters: {}",
                        PATCH_PARAMS
                            .iter()
                            .map(|d| d.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            v.set(name, def.parse("patches", value)?);
        }
        Self::from_values(&v)
    }
}

/// What a patch is doing, after a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchState {
    /// The patch's centre in the frame (the last good one when lost).
    pub centre: Point,
    /// The linear part of its warp, `[a00, a01, a10, a11]` (the identity for translation): a
    /// patch offset `(u, v)` sits at `centre + (a00 u + a01 v, a10 u + a11 v)`.
    pub linear: [f64; 4],
    pub status: TrackStatus,
    /// The normalised cross-correlation of the tracked patch with its template (-1..1).
    pub ncc: f64,
    /// The forward-backward error (pixels), when `fb_max` asks for it and the frame was tracked.
    pub fb_error: Option<f64>,
    /// Iterations run on this frame, all levels together.
    pub iterations: usize,
}

impl PatchState {
    /// Whether the patch is followed.
    pub fn tracking(&self) -> bool {
        self.status == TrackStatus::Tracking
    }

    /// The corners of the patch's window (`half` pixels from the centre along each side, before
    /// the linear map): upper left, upper right, lower right, lower left.
    pub fn corners(&self, half: f64) -> Quad {
        let [a, b, c, d] = self.linear;
        let at = |u: f64, v: f64| Point {
            x: self.centre.x + a * u + b * v,
            y: self.centre.y + c * u + d * v,
        };
        Quad([
            at(-half, -half),
            at(half, -half),
            at(half, half),
            at(-half, half),
        ])
    }
}

/// A patch's warp: frame point of patch offset `u` at level `l` is `A u + c / 2^l`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Warp {
    a: [f64; 4],
    c: Point,
}

impl Warp {
    fn at(c: Point) -> Self {
        Warp {
            a: [1.0, 0.0, 0.0, 1.0],
            c,
        }
    }

    fn is_shift(&self) -> bool {
        self.a == [1.0, 0.0, 0.0, 1.0]
    }
}

/// The sampling grid's offsets from a patch's centre, shared by all patches.
///
/// Every per-sample array of a patch (template, steepest-descent images, samples) is stored
/// row by row with `stride` entries a row: `side` rounded up to lanes of eight, so the loops
/// over them run whole lanes. The entries past `side` are padding: the template and its
/// steepest-descent images are zero there (they weigh nothing in the sums) and `mask` is 0.
#[derive(Clone, Debug)]
struct Grid {
    side: usize,
    half: f64,
    stride: usize,
    ux: Vec<f32>,
    uy: Vec<f32>,
    /// 1 on the grid's samples, 0 on the padding.
    mask: Vec<f32>,
    /// The grid grown by one sample on every side (for the template's central differences):
    /// `side + 2` rows of `ext_stride` (at least `stride + 2`, in lanes of eight) samples from
    /// `-half - 1`.
    ext_stride: usize,
    ex: Vec<f32>,
    ey: Vec<f32>,
}

impl Grid {
    fn new(side: usize) -> Self {
        let half = (side as f64 - 1.0) / 2.0;
        let stride = side.div_ceil(8) * 8;
        let ext_stride = (stride + 2).div_ceil(8) * 8;
        let offsets = |from: f64, rows: usize, cols: usize| {
            let (mut xs, mut ys) = (Vec::new(), Vec::new());
            for j in 0..rows {
                for i in 0..cols {
                    xs.push((i as f64 - from) as f32);
                    ys.push((j as f64 - from) as f32);
                }
            }
            (xs, ys)
        };
        let (ux, uy) = offsets(half, side, stride);
        let (ex, ey) = offsets(half + 1.0, side + 2, ext_stride);
        let mask = (0..side * stride)
            .map(|k| if k % stride < side { 1.0 } else { 0.0 })
            .collect();
        Grid {
            side,
            half,
            stride,
            ux,
            uy,
            mask,
            ext_stride,
            ex,
            ey,
        }
    }

    /// The grid's samples.
    fn len(&self) -> usize {
        self.side * self.side
    }

    /// The entries of a per-sample array, padding included.
    fn padded_len(&self) -> usize {
        self.side * self.stride
    }
}

/// One frame, pre-processed once for every patch: the smoothed frame's pyramid.
#[derive(Clone, Debug, Default)]
struct Frame {
    levels: Vec<GrayF32>,
    /// The levels with a replicated border of [`Frame::border`] pixels: a patch whose centre is
    /// in the frame reads only inside these.
    padded: Vec<GrayF32>,
    border: usize,
}

impl Frame {
    /// Level `l`, padded, and its border.
    fn level(&self, l: usize) -> (&GrayF32, usize) {
        (&self.padded[l], self.border)
    }
}

/// Bands of rows a level is split into, at most (for the threads building a frame).
const MAX_BANDS: usize = 16;

/// One band of a level's rows being built: its rows, their pixels and the padded level's rows
/// that copy them (with the top or bottom border when the band has the first or last row).
struct Band<'a> {
    rows: std::ops::Range<usize>,
    out: &'a mut [f32],
    pad: &'a mut [f32],
    /// The padded level's first row in `pad`.
    pad_from: usize,
}

impl Frame {
    /// The smoothed frame's pyramid of at most `levels` levels and their padded copies. Each
    /// level is split into bands of rows that the crew's threads take as they are free; the
    /// result is the same for any number of threads.
    fn build(
        &mut self,
        src: ImageRef<'_, u8>,
        levels: usize,
        border: usize,
        kernel: &GaussianKernel,
        crew: &mut Crew<Scratch>,
    ) {
        // The levels' sizes: each half the one below, while that is at least 32 x 32.
        let mut kept = 1;
        let (mut w, mut h) = (src.width, src.height);
        self.levels.resize_with(levels.max(1), GrayF32::default);
        self.levels[0].resize(w, h);
        while kept < levels && w >= 32 && h >= 32 {
            (w, h) = (w.div_ceil(2), h.div_ceil(2));
            self.levels[kept].resize(w, h);
            kept += 1;
        }
        self.levels.truncate(kept);
        self.border = border;
        self.padded.resize_with(kept, GrayF32::default);
        let b = border;
        for l in 0..kept {
            let (done, todo) = self.levels.split_at_mut(l);
            let below = done.last();
            let level = &mut todo[0];
            let (w, h) = (level.width, level.height);
            let (pw, ph) = (w + 2 * b, h + 2 * b);
            let pad = &mut self.padded[l];
            pad.resize(pw, ph);
            if w == 0 || h == 0 {
                pad.data.fill(0.0);
                continue;
            }
            // Bands: twice the threads (so one that is late does not hold the others up).
            let n = (2 * crew.len()).min(MAX_BANDS).min(h).max(1);
            let mut bands: [Option<Band<'_>>; MAX_BANDS] = std::array::from_fn(|_| None);
            let (mut out, mut padded) = (&mut level.data[..w * h], &mut pad.data[..pw * ph]);
            let mut pad_at = 0;
            for (k, band) in bands.iter_mut().take(n).enumerate() {
                let rows = k * h / n..(k + 1) * h / n;
                let pad_to = if rows.end == h { ph } else { rows.end + b };
                let (o, rest) = std::mem::take(&mut out).split_at_mut(rows.len() * w);
                let (q, prest) = std::mem::take(&mut padded).split_at_mut((pad_to - pad_at) * pw);
                (out, padded) = (rest, prest);
                *band = Some(Band {
                    rows,
                    out: o,
                    pad: q,
                    pad_from: pad_at,
                });
                pad_at = pad_to;
            }
            // Each member its own rows first (the patches are handed out the same way).
            let shares = Shares::new(&mut bands[..n], 1, crew.len());
            crew.run(&|s: &mut Scratch, m| {
                while let Some((_, taken)) = shares.take(m) {
                    let Some(band) = taken[0].take() else {
                        continue;
                    };
                    match below {
                        None => imaging::gaussian_blur_rows_into(
                            src,
                            kernel,
                            band.rows.clone(),
                            band.out,
                            &mut s.prep.tmp,
                            &mut s.prep.line,
                        ),
                        Some(below) => imaging::downsample_half_rows_into(
                            below,
                            band.rows.clone(),
                            band.out,
                            &mut s.prep.half,
                        ),
                    }
                    // The padded rows: pixel (x, y) at (x + b, y + b), edges replicated.
                    for (r, dst) in band.pad.chunks_exact_mut(pw).enumerate() {
                        let sy = (band.pad_from + r).saturating_sub(b).min(h - 1);
                        let row = &band.out[(sy - band.rows.start) * w..][..w];
                        dst[..b].fill(row[0]);
                        dst[b..b + w].copy_from_slice(row);
                        dst[b + w..].fill(row[w - 1]);
                    }
                }
            });
        }
    }
}

/// The pre-processing's buffers of one thread.
#[derive(Clone, Debug, Default)]
struct PrepBuffers {
    tmp: Vec<f32>,
    line: Vec<f32>,
    half: Vec<f32>,
}

/// A template at every level: values, steepest-descent images and the inverse Hessian.
#[derive(Clone, Debug, Default)]
struct Template {
    t: Vec<f32>,
    sd: Vec<f32>,
    /// `SD^T T` per level: the residual's projection is `SD^T I(W(u))` minus this.
    sdt: Vec<[f64; 6]>,
    hinv: Vec<[f64; 36]>,
    usable: Vec<bool>,
}

/// One patch: its state, warp and, when it keeps the first frame's, its template.
#[derive(Clone, Debug)]
struct Patch {
    state: PatchState,
    warp: Warp,
    /// The first frame's template (`template=first`); made again each frame otherwise.
    first: Option<Box<Template>>,
}

/// What a thread tracking patches works in, one patch after the other: the template made
/// each frame, the backward one and the samples. Kept by the thread (not by each patch), so
/// it stays in the core's cache.
#[derive(Clone, Debug)]
struct Scratch {
    fwd: Template,
    back: Template,
    buf: Buffers,
    prep: PrepBuffers,
}

/// The samples of one search or template.
#[derive(Clone, Debug)]
struct Buffers {
    vals: Vec<f32>,
    xs: Vec<f32>,
    ys: Vec<f32>,
    /// The template's values on the grown grid.
    ext: Vec<f32>,
}

/// Patches a thread takes at a time.
const PATCH_BLOCK: usize = 16;

/// Why a search failed.
type Search = std::result::Result<(Warp, usize, f64), LossReason>;

impl Template {
    fn new(grid: &Grid, levels: usize, dof: usize) -> Self {
        let n = grid.padded_len();
        Template {
            t: vec![0.0; levels * n],
            sd: vec![0.0; levels * dof * n],
            hinv: vec![[0.0; 36]; levels],
            sdt: vec![[0.0; 6]; levels],
            usable: vec![false; levels],
        }
    }
}

impl Scratch {
    fn new(grid: &Grid, levels: usize, dof: usize) -> Self {
        let n = grid.padded_len().max(grid.ex.len());
        Scratch {
            fwd: Template::new(grid, levels, dof),
            back: Template::new(grid, levels, dof),
            buf: Buffers {
                vals: vec![0.0; grid.padded_len()],
                xs: vec![0.0; n],
                ys: vec![0.0; n],
                ext: vec![0.0; grid.ex.len()],
            },
            prep: PrepBuffers::default(),
        }
    }
}

impl Patch {
    fn new(centre: Point) -> Self {
        Patch {
            state: PatchState {
                centre,
                linear: [1.0, 0.0, 0.0, 1.0],
                status: TrackStatus::Tracking,
                ncc: 1.0,
                fb_error: None,
                iterations: 0,
            },
            warp: Warp::at(centre),
            first: None,
        }
    }
}

/// A grid's layout for [`sample`]: columns (the row stride), rows, the offset of its first
/// sample from the centre (negated) and every sample's offsets.
type Layout<'a> = (usize, usize, f64, &'a [f32], &'a [f32]);

/// Samples `img` at the grid warped by `w` at level `l` into `out` (`xs`, `ys` are scratch).
#[allow(clippy::too_many_arguments)]
fn sample(
    (img, border): (&GrayF32, usize),
    w: &Warp,
    l: usize,
    (cols, rows, half, ux, uy): Layout<'_>,
    out: &mut [f32],
    xs: &mut [f32],
    ys: &mut [f32],
) {
    let s = (1u32 << l) as f64;
    let b = border as f64;
    let (cx, cy) = (w.c.x / s + b, w.c.y / s + b);
    if w.is_shift()
        && imaging::sample_grid_shifted(
            img,
            (cx - half) as f32,
            (cy - half) as f32,
            cols,
            rows,
            out,
        )
    {
        return;
    }
    let [a, b, c, d] = w.a.map(|v| v as f32);
    let (cx, cy) = (cx as f32, cy as f32);
    let n = cols * rows;
    let (xs, ys, out) = (&mut xs[..n], &mut ys[..n], &mut out[..n]);
    for i in 0..n {
        let (u, v) = (ux[i], uy[i]);
        xs[i] = a * u + b * v + cx;
        ys[i] = c * u + d * v + cy;
    }
    let view = ImageView::new(&img.data, img.width, img.height, 0, 0);
    imaging::sample_values(&view, xs, ys, out);
}

impl Grid {
    /// The grid, for [`sample`].
    fn plain(&self) -> Layout<'_> {
        (self.stride, self.side, self.half, &self.ux, &self.uy)
    }

    /// The grid grown by one sample on every side, for [`sample`].
    fn grown(&self) -> Layout<'_> {
        (
            self.ext_stride,
            self.side + 2,
            self.half + 1.0,
            &self.ex,
            &self.ey,
        )
    }
}

/// The warp searched at level `l`: affine patches that follow the previous frame's patch search
/// only a shift, on an image-aligned window, at the coarse levels (between two frames the
/// shape barely changes; the shift is what the coarse levels are for), then the whole affine
/// warp at the finest level. Their coarse levels then cost what a translation patch's do.
fn level_warp(prm: &PatchParams, l: usize) -> PatchWarp {
    if l > 0 && prm.warp == PatchWarp::Affine && prm.template == TemplateSource::Previous {
        PatchWarp::Translation
    } else {
        prm.warp
    }
}

/// The window sampled at level `l` for the warp `w`: image-aligned where [`level_warp`] is a
/// shift of an affine patch.
fn level_window(prm: &PatchParams, l: usize, w: &Warp) -> Warp {
    if level_warp(prm, l) != prm.warp {
        Warp::at(w.c)
    } else {
        *w
    }
}

/// The template of the patch warped by `w` in `frame`, at every level, into `tp`. Flat levels
/// are marked unusable; `false` when the finest is flat.
fn make_template(
    tp: &mut Template,
    b: &mut Buffers,
    frame: &Frame,
    start: &Warp,
    grid: &Grid,
    prm: &PatchParams,
) -> bool {
    let (n, np) = (grid.len(), grid.padded_len());
    let full = prm.warp.dof();
    let min_eigen = prm.min_eigen;
    for l in 0..frame.levels.len() {
        let dof = level_warp(prm, l).dof();
        let w = &level_window(prm, l, start);
        // The values on the grown grid; the template is its inside and the gradients in patch
        // coordinates its central differences (for a shift, exactly the bilinear samples of the
        // frame's central-difference gradients).
        sample(
            frame.level(l),
            w,
            l,
            grid.grown(),
            &mut b.ext,
            &mut b.xs,
            &mut b.ys,
        );
        let t = &mut tp.t[l * np..(l + 1) * np];
        let sd = &mut tp.sd[l * full * np..(l * full + dof) * np];
        let (tx, rest) = sd.split_at_mut(np);
        let (ty, rest) = rest.split_at_mut(np);
        // One pass in lanes of eight: the template, its gradients (zero on the padding) and
        // the sums of their products: SD^T T and the shift's 2x2 Hessian.
        let rows = kernels::Rows {
            ext: &b.ext,
            ext_stride: grid.ext_stride,
            stride: grid.stride,
            side: grid.side,
            mask: &grid.mask,
        };
        let [stx, sty, hxx, hxy, hyy] = kernels::template_rows(&rows, t, tx, ty).map(f64::from);
        if dof == 6 {
            // Columns: tx ux, tx uy, ty ux, ty uy, tx, ty (the shift last).
            let (c0, rest) = rest.split_at_mut(np);
            let (c1, rest) = rest.split_at_mut(np);
            let (c2, c3) = rest.split_at_mut(np);
            for i in 0..np {
                let (u, v) = (grid.ux[i], grid.uy[i]);
                c0[i] = tx[i] * u;
                c1[i] = tx[i] * v;
                c2[i] = ty[i] * u;
                c3[i] = ty[i] * v;
            }
            // Reorder so the shift's columns come last: [c0 c1 c2 c3 tx ty].
            sd.rotate_left(2 * np);
        }
        let sd = &tp.sd[l * full * np..(l * full + dof) * np];
        let col = |k: usize| &sd[k * np..(k + 1) * np];
        let t = &tp.t[l * np..(l + 1) * np];
        for k in 0..dof - 2 {
            tp.sdt[l][k] = dot(col(k), t) as f64;
        }
        tp.sdt[l][dof - 2] = stx;
        tp.sdt[l][dof - 1] = sty;
        let tr = hxx + hyy;
        let det = hxx * hyy - hxy * hxy;
        let min_eig = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt()) / n as f64;
        let mut usable = min_eig >= min_eigen && min_eig > 0.0;
        if usable {
            match dof {
                2 => {
                    let h = Matrix2::new(hxx, hxy, hxy, hyy);
                    match h.try_inverse() {
                        Some(inv) => {
                            tp.hinv[l][..4].copy_from_slice(inv.as_slice());
                        }
                        None => usable = false,
                    }
                }
                _ => {
                    let mut h = SMatrix::<f64, 6, 6>::zeros();
                    for r in 0..6 {
                        for c in r..6 {
                            let v = dot(col(r), col(c)) as f64;
                            h[(r, c)] = v;
                            h[(c, r)] = v;
                        }
                    }
                    match h.try_inverse() {
                        Some(inv) if inv.iter().all(|v| v.is_finite()) => {
                            tp.hinv[l].copy_from_slice(inv.as_slice());
                        }
                        _ => usable = false,
                    }
                }
            }
        }
        tp.usable[l] = usable;
    }
    tp.usable.first().copied().unwrap_or(false)
}

/// Searches `frame` for the template `tp` (forward or backward) from `start`, coarse to
/// fine. Returns the warp, the iterations and the template's NCC with the last samples.
fn search(
    tp: &Template,
    b: &mut Buffers,
    frame: &Frame,
    start: Warp,
    grid: &Grid,
    prm: &PatchParams,
) -> Search {
    let np = grid.padded_len();
    let full = prm.warp.dof();
    let mut w = start;
    let mut iterations = 0;
    let levels = frame.levels.len();
    let mut last_level_sampled = false;
    for l in (0..levels).rev() {
        if !tp.usable[l] {
            continue;
        }
        let s = (1u32 << l) as f64;
        let img = frame.level(l);
        // A coarse level only has to bring the patch within the finer level's basin.
        let eps = if l == 0 {
            prm.eps
        } else {
            prm.eps.max(COARSE_EPS)
        };
        let model = level_warp(prm, l);
        let dof = model.dof();
        for _ in 0..prm.iterations {
            // The window searched (image-aligned for the shift of an affine patch).
            let win = level_window(prm, l, &w);
            sample(
                img,
                &win,
                l,
                grid.plain(),
                &mut b.vals,
                &mut b.xs,
                &mut b.ys,
            );
            iterations += 1;
            // SD^T (I(W(u)) - T), with SD^T T made once per template.
            let sd = &tp.sd[l * full * np..(l * full + dof) * np];
            let mut g = [0f64; 6];
            for k in (0..dof).step_by(2) {
                let (a, b) = dot2(
                    &sd[k * np..(k + 1) * np],
                    &sd[(k + 1) * np..(k + 2) * np],
                    &b.vals,
                );
                g[k] = a as f64 - tp.sdt[l][k];
                g[k + 1] = b as f64 - tp.sdt[l][k + 1];
            }
            let hinv = &tp.hinv[l];
            let mut dp = [0f64; 6];
            for r in 0..dof {
                // Column-major inverse (nalgebra's layout); it is symmetric anyway.
                dp[r] = (0..dof).map(|c| hinv[c * dof + r] * g[c]).sum();
            }
            // W <- W o W(dp)^-1: with W(dp) = M u + t, A' = A M^-1 and c' = c - A' t.
            let (m, t) = match model {
                PatchWarp::Translation => ([1.0, 0.0, 0.0, 1.0], (dp[0], dp[1])),
                PatchWarp::Affine => ([1.0 + dp[0], dp[1], dp[2], 1.0 + dp[3]], (dp[4], dp[5])),
            };
            let det = m[0] * m[3] - m[1] * m[2];
            if !(det.is_finite() && det.abs() > 1e-6) {
                return Err(LossReason::Singular);
            }
            let mi = [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det];
            let a = win.a;
            let na = [
                a[0] * mi[0] + a[1] * mi[2],
                a[0] * mi[1] + a[1] * mi[3],
                a[2] * mi[0] + a[3] * mi[2],
                a[2] * mi[1] + a[3] * mi[3],
            ];
            // The centre at this level, moved; back in frame pixels.
            let (cx, cy) = (
                w.c.x / s - (na[0] * t.0 + na[1] * t.1),
                w.c.y / s - (na[2] * t.0 + na[3] * t.1),
            );
            let next = Warp {
                a: if model == PatchWarp::Translation {
                    w.a
                } else {
                    na
                },
                c: Point {
                    x: cx * s,
                    y: cy * s,
                },
            };
            if !(next.c.is_finite() && next.a.iter().all(|v| v.is_finite())) {
                return Err(LossReason::NonFinite);
            }
            // How far the window's corners moved (pixels of this level).
            let h = grid.half;
            let mut step = 0f64;
            for (u, v) in [(-h, -h), (h, -h), (h, h), (-h, h)] {
                let dx =
                    (next.a[0] - w.a[0]) * u + (next.a[1] - w.a[1]) * v + (next.c.x - w.c.x) / s;
                let dy =
                    (next.a[2] - w.a[2]) * u + (next.a[3] - w.a[3]) * v + (next.c.y - w.c.y) / s;
                step = step.max(dx * dx + dy * dy);
            }
            w = next;
            last_level_sampled = l == 0;
            if step < eps * eps {
                break;
            }
        }
    }
    let ad = w.a[0] * w.a[3] - w.a[1] * w.a[2];
    if !(0.2..=5.0).contains(&ad) {
        return Err(LossReason::Degenerate);
    }
    // The NCC of the finest level's last samples with the template.
    if !last_level_sampled {
        return Err(LossReason::Singular);
    }
    Ok((
        w,
        iterations,
        ncc(&b.vals, &tp.t[..np], &grid.mask, grid.len()),
    ))
}

/// The zero-mean normalised cross-correlation of two equally long vectors over the entries
/// where `mask` is 1 (`mask` is 0 or 1; 0 when either is flat). One pass over eight lanes, on
/// values shifted by the first of `b` (gray levels are small enough that the single-precision
/// sums keep the correlation to about 1e-4).
fn ncc(a: &[f32], b: &[f32], mask: &[f32], count: usize) -> f64 {
    let n = a.len().min(b.len()).min(mask.len());
    let Some(&k) = b.first() else {
        return 0.0;
    };
    let mut acc = [[0f32; 8]; 5];
    let (ca, cb, cm) = (
        a[..n].chunks_exact(8),
        b[..n].chunks_exact(8),
        mask[..n].chunks_exact(8),
    );
    let (ra, rb, rm) = (ca.remainder(), cb.remainder(), cm.remainder());
    for ((x, y), m) in ca.zip(cb).zip(cm) {
        for l in 0..8 {
            let (x, y) = ((x[l] - k) * m[l], (y[l] - k) * m[l]);
            acc[0][l] += x;
            acc[1][l] += y;
            acc[2][l] += x * x;
            acc[3][l] += y * y;
            acc[4][l] += x * y;
        }
    }
    let mut s = acc.map(|a| a.iter().map(|&v| v as f64).sum::<f64>());
    for ((&x, &y), &m) in ra.iter().zip(rb).zip(rm) {
        let (x, y) = (((x - k) * m) as f64, ((y - k) * m) as f64);
        s[0] += x;
        s[1] += y;
        s[2] += x * x;
        s[3] += y * y;
        s[4] += x * y;
    }
    let nf = count.max(1) as f64;
    let aa = s[2] - s[0] * s[0] / nf;
    let bb = s[3] - s[1] * s[1] / nf;
    let ab = s[4] - s[0] * s[1] / nf;
    if aa <= 1e-6 * nf || bb <= 1e-6 * nf {
        0.0
    } else {
        (ab / (aa * bb).sqrt()).clamp(-1.0, 1.0)
    }
}

/// Tracks N patches per frame (see the module's documentation).
pub struct PatchTracker {
    params: PatchParams,
    grid: Grid,
    /// The frames' pre-smoothing.
    kernel: GaussianKernel,
    cur: Frame,
    prev: Frame,
    /// The patches in raster order of their first positions (neighbours read the same rows
    /// of the frame one after the other, from the cache).
    patches: Vec<Patch>,
    /// Where each patch, in the order it was given, is in `patches`.
    order: Vec<usize>,
    /// The threads, each with its own [`Scratch`] (member 0 is the caller's).
    crew: Crew<Scratch>,
    size: (usize, usize),
    frames: usize,
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
            if kept.len() == max {
                break;
            }
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
    fn build_current(&mut self, frame: ImageRef<'_, u8>) {
        let (levels, border) = (self.params.levels, self.border());
        self.cur
            .build(frame, levels, border, &self.kernel, &mut self.crew);
    }

    /// The border the frame's levels get: a patch whose centre is inside reads inside it.
    fn border(&self) -> usize {
        // The grown grid's rows (`ext_stride` samples from `-half - 1`) read one pixel more.
        (self.grid.ext_stride as f64 - self.grid.half).ceil() as usize + 3
    }

    /// Half the side of a patch's window (pixels at the finest level).
    pub fn half_size(&self) -> f64 {
        self.grid.half
    }
}

/// One patch, one frame.
fn track_patch(
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
fn inside(q: &Quad, p: Point) -> bool {
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

/// A run of the many-patch tracker over a sequence.
#[derive(Clone, Debug, Default)]
pub struct PatchRun {
    /// The sequence's frame the run started on (`frames[0]`).
    pub first: usize,
    /// Per frame, every patch's state.
    pub frames: Vec<Vec<PatchState>>,
    /// Time spent tracking (pre-processing and searching; not reading frames), per frame
    /// after the first.
    pub times: Vec<Duration>,
}

impl PatchRun {
    /// Patches (those of the first frame).
    pub fn patches(&self) -> usize {
        self.frames.first().map_or(0, |f| f.len())
    }

    /// Patch updates per second of tracking: patches searched, over the tracking time.
    pub fn updates_per_second(&self) -> f64 {
        // Every frame but the last is searched from in the next one.
        let before_last = &self.frames[..self.frames.len().saturating_sub(1)];
        let searched: usize = before_last
            .iter()
            .map(|f| f.iter().filter(|s| s.tracking()).count())
            .sum();
        let t: f64 = self.times.iter().map(|d| d.as_secs_f64()).sum();
        if t > 0.0 { searched as f64 / t } else { 0.0 }
    }

    /// The mean and median forward-backward error (pixels) over every patch update that
    /// measured one (`fb_max` > 0); `None` when none did.
    pub fn forward_backward_errors(&self) -> Option<(f64, f64)> {
        let e: Vec<f64> = self
            .frames
            .iter()
            .flatten()
            .filter_map(|s| s.fb_error)
            .collect();
        if e.is_empty() {
            return None;
        }
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        Some((mean, crate::linalg::median(e)))
    }

    /// Mean iterations per patch update (all levels together).
    pub fn iterations_per_update(&self) -> f64 {
        let (mut it, mut n) = (0usize, 0usize);
        for f in self.frames.iter().skip(1) {
            for s in f.iter().filter(|s| s.iterations > 0) {
                it += s.iterations;
                n += 1;
            }
        }
        if n == 0 { 0.0 } else { it as f64 / n as f64 }
    }

    /// Frames per second of tracking (median frame time).
    pub fn frames_per_second(&self) -> f64 {
        let mut t: Vec<f64> = self.times.iter().map(|d| d.as_secs_f64()).collect();
        if t.is_empty() {
            return 0.0;
        }
        t.sort_by(f64::total_cmp);
        let m = t[t.len() / 2];
        if m > 0.0 { 1.0 / m } else { 0.0 }
    }
}

/// Where the patches start.
#[derive(Clone, Debug)]
pub enum PatchSeeds {
    /// These points of the first frame.
    Points(Vec<Point>),
    /// The strongest Shi-Tomasi corners of the first frame, at most this many: inside the
    /// first ground-truth quad when the sequence has one, else anywhere.
    Corners(usize),
}

/// Reads points, one `x,y` (or `x y`) per line; `#` starts a comment. A malformed line is an
/// error naming the file and the line.
pub fn read_points(path: &Path) -> Result<Vec<Point>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let v: Vec<f64> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| t.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .filter(|v: &Vec<f64>| v.len() == 2)
            .ok_or_else(|| Error::Parse {
                path: path.to_path_buf(),
                line: n + 1,
                message: format!("expected two finite numbers x,y, got '{line}'"),
            })?;
        points.push(Point { x: v[0], y: v[1] });
    }
    Ok(points)
}

/// Tracks patches over `seq` from its first frame; `progress` sees each frame's index.
pub fn track_sequence(
    seq: &Sequence,
    params: &PatchParams,
    seeds: &PatchSeeds,
    progress: &mut dyn FnMut(usize),
) -> Result<PatchRun> {
    track_sequence_from(seq, 0, params, seeds, progress)
}

/// [`track_sequence`] from frame `start` (corners are then detected in that frame's ground
/// truth, when it has one).
pub fn track_sequence_from(
    seq: &Sequence,
    start: usize,
    params: &PatchParams,
    seeds: &PatchSeeds,
    progress: &mut dyn FnMut(usize),
) -> Result<PatchRun> {
    let mut t = PatchTracker::new(params.clone())?;
    let first = seq.load_gray(start)?;
    let points = match seeds {
        PatchSeeds::Points(p) => p.clone(),
        PatchSeeds::Corners(n) => {
            let region = seq.ground_truth(start);
            t.detect(&first, *n, region.as_ref())
        }
    };
    t.initialize(&first, &points)?;
    let mut run = PatchRun {
        first: start,
        ..PatchRun::default()
    };
    run.frames.push(t.states().copied().collect());
    progress(start);
    for i in start + 1..seq.len() {
        let frame = seq.load_gray(i)?;
        let start = Instant::now();
        t.update(&frame)?;
        run.times.push(start.elapsed());
        run.frames.push(t.states().copied().collect());
        progress(i);
    }
    Ok(run)
}

/// How well patch tracks follow a sequence's ground truth: each patch's true position in a
/// frame is its first-frame centre carried by the homography between the two frames'
/// ground-truth quads (right for points on the planar target).
#[derive(Clone, Debug, PartialEq)]
pub struct PatchAccuracy {
    /// Patches scored (those whose start is inside the first ground-truth quad).
    pub patches: usize,
    /// Mean and median distance to the truth over every tracked patch and frame (pixels).
    pub mean_error: f64,
    pub median_error: f64,
    /// Patches still tracked at the last frame, and how many of those are within 2 px of
    /// the truth there.
    pub tracked_at_end: usize,
    pub within_2px_at_end: usize,
    /// The fraction of patch-frames tracked.
    pub tracked_fraction: f64,
}

/// Scores `run` against `seq`'s ground truth (`None` without one on the first frame).
pub fn accuracy(run: &PatchRun, seq: &Sequence) -> Option<PatchAccuracy> {
    let q0 = seq.ground_truth(run.first)?;
    let starts: Vec<(usize, Point)> = run
        .frames
        .first()?
        .iter()
        .enumerate()
        .filter(|(_, s)| s.tracking() && inside(&q0, s.centre))
        .map(|(k, s)| (k, s.centre))
        .collect();
    let mut errors = Vec::new();
    let (mut tracked, mut total) = (0usize, 0usize);
    let (mut at_end, mut near_end) = (0, 0);
    let last = run.frames.len().saturating_sub(1);
    for (i, states) in run.frames.iter().enumerate().skip(1) {
        let Some(h) = seq
            .ground_truth(run.first + i)
            .and_then(|q| homography_between(&q0, &q))
        else {
            continue;
        };
        for &(k, p0) in &starts {
            total += 1;
            let Some(s) = states.get(k) else { continue };
            if !s.tracking() {
                continue;
            }
            tracked += 1;
            let e = s.centre.dist(apply_homography(&h, p0));
            if e.is_finite() {
                errors.push(e);
            }
            if i == last {
                at_end += 1;
                if e <= 2.0 {
                    near_end += 1;
                }
            }
        }
    }
    let mean = if errors.is_empty() {
        0.0
    } else {
        errors.iter().sum::<f64>() / errors.len() as f64
    };
    Some(PatchAccuracy {
        patches: starts.len(),
        mean_error: mean,
        median_error: if errors.is_empty() {
            0.0
        } else {
            crate::linalg::median(errors)
        },
        tracked_at_end: at_end,
        within_2px_at_end: near_end,
        tracked_fraction: if total == 0 {
            0.0
        } else {
            tracked as f64 / total as f64
        },
    })
}

/// The header of a patch tracks file.
pub const TRACKS_HEADER: &str = "frame,patch,status,x,y,a00,a01,a10,a11,ncc";

/// Writes `run` as CSV: one line per frame and patch, [`TRACKS_HEADER`]'s columns; the status
/// is `tracking` or `lost:<reason>`.
pub fn write_tracks(path: &Path, run: &PatchRun) -> Result<()> {
    let io = |e: std::io::Error| Error::Io {
        path: path.to_path_buf(),
        source: e,
    };
    let file = std::fs::File::create(path).map_err(io)?;
    let mut out = std::io::BufWriter::new(file);
    writeln!(out, "{TRACKS_HEADER}").map_err(io)?;
    // A line at a time into one buffer; the numbers as `{:.N}` writes them, faster (a thousand
    // patches make 200,000 lines of seven numbers each per 200 frames).
    use std::fmt::Write as _;
    let mut line = String::with_capacity(128);
    for (i, states) in run.frames.iter().enumerate() {
        for (k, s) in states.iter().enumerate() {
            line.clear();
            match s.status {
                TrackStatus::Lost(r) => write!(line, "{i},{k},lost:{},", r.key()),
                _ => write!(line, "{i},{k},tracking,"),
            }
            .expect("writing to a String");
            let [a, b, c, d] = s.linear;
            let numbers = [
                (s.centre.x, 4),
                (s.centre.y, 4),
                (a, 6),
                (b, 6),
                (c, 6),
                (d, 6),
                (s.ncc, 4),
            ];
            for (n, (v, digits)) in numbers.into_iter().enumerate() {
                if n > 0 {
                    line.push(',');
                }
                write_fixed(&mut line, v, digits);
            }
            line.push('\n');
            out.write_all(line.as_bytes()).map_err(io)?;
        }
    }
    out.flush().map_err(io)
}

/// Appends `v` with `digits` decimals exactly as `format!("{v:.digits$}")` does (the binary
/// value rounded half to even), without its slow path: the value's mantissa times `10^digits`
/// is shifted by its exponent in 128-bit integers.
fn write_fixed(out: &mut String, v: f64, digits: u32) {
    use std::fmt::Write as _;
    let d = digits as usize;
    if !v.is_finite() || v.abs() >= 1e15 || digits > 9 {
        write!(out, "{v:.d$}").expect("writing to a String");
        return;
    }
    let bits = v.to_bits();
    let (exp, frac) = (((bits >> 52) & 0x7ff) as i32, bits & ((1u64 << 52) - 1));
    // v = m 2^e.
    let (m, e) = if exp == 0 {
        (frac, -1074)
    } else {
        (frac | (1u64 << 52), exp - 1075)
    };
    let scale = 10u128.pow(digits);
    let x = m as u128 * scale;
    let r = if e >= 0 {
        // |v| < 1e15 < 2^50, so x 2^e < 2^80.
        x << e
    } else if -e >= 128 {
        0
    } else {
        let s = (-e) as u32;
        let q = x >> s;
        let rem = x - (q << s);
        let half = 1u128 << (s - 1);
        if rem > half || (rem == half && q & 1 == 1) {
            q + 1
        } else {
            q
        }
    };
    if bits >> 63 == 1 {
        out.push('-');
    }
    let (int, fraction) = (r / scale, r % scale);
    if d == 0 {
        write!(out, "{int}")
    } else {
        write!(out, "{int}.{fraction:0d$}")
    }
    .expect("writing to a String");
}

/// Reads a tracks file written by [`write_tracks`] (or by another tracker in its layout: the
/// benchmark scores OpenCV's tracks this way). A malformed line is an error naming the file
/// and the line.
pub fn read_tracks(path: &Path) -> Result<PatchRun> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let bad = |line: usize, what: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message: what,
    };
    let mut run = PatchRun::default();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = line.trim();
        if line.is_empty() || (n == 0 && line.starts_with("frame")) {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 10 {
            return Err(bad(
                line_no,
                format!("expected 10 fields ({TRACKS_HEADER}), got {}", f.len()),
            ));
        }
        let int = |k: usize| {
            f[k].parse::<usize>().map_err(|_| {
                bad(
                    line_no,
                    format!("field {} is not a whole number: '{}'", k + 1, f[k]),
                )
            })
        };
        let num = |k: usize| {
            f[k].parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(
                        line_no,
                        format!("field {} is not a finite number: '{}'", k + 1, f[k]),
                    )
                })
        };
        let (frame, patch) = (int(0)?, int(1)?);
        let status = match f[2] {
            "tracking" => TrackStatus::Tracking,
            s => match s.strip_prefix("lost:").map(LossReason::from_key) {
                Some(Some(r)) => TrackStatus::Lost(r),
                _ => {
                    return Err(bad(
                        line_no,
                        format!("status '{s}' is neither 'tracking' nor 'lost:<reason>'"),
                    ));
                }
            },
        };
        if frame > run.frames.len() || (frame + 1 < run.frames.len()) {
            return Err(bad(line_no, format!("frame {frame} out of order")));
        }
        if frame == run.frames.len() {
            run.frames.push(Vec::new());
        }
        let states = &mut run.frames[frame];
        if patch != states.len() {
            return Err(bad(
                line_no,
                format!("patch {patch} out of order (expected {})", states.len()),
            ));
        }
        states.push(PatchState {
            centre: Point {
                x: num(3)?,
                y: num(4)?,
            },
            linear: [num(5)?, num(6)?, num(7)?, num(8)?],
            status,
            ncc: num(9)?,
            fb_error: None,
            iterations: 0,
        });
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_decimals_are_those_of_the_standard_formatting() {
        let mut rng = crate::rng::Rng::new(7);
        let mut special = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            0.00005,
            -0.00005,
            0.00015,
            2.5e-7,
            -1e-300,
            f64::MIN_POSITIVE,
            5e-324,
            123456.78125,
            9.99999999e14,
            2e15,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // Halves of the last digit exactly (ties go to even), and random values of every size.
        special.extend((0..2000).map(|k| k as f64 / 2e4 + 1.0 / 32.0));
        special.extend((0..20_000).map(|k| {
            let v = rng.range(-1.0, 1.0) * 10f64.powi((k % 30) - 12);
            if k % 3 == 0 {
                (v * 1e6).round() / 1e6
            } else {
                v
            }
        }));
        let mut mine = String::new();
        for &v in &special {
            for digits in [0u32, 1, 4, 6, 9] {
                mine.clear();
                write_fixed(&mut mine, v, digits);
                assert_eq!(
                    mine,
                    format!("{v:.*}", digits as usize),
                    "{v:e} to {digits}"
                );
            }
        }
    }

    #[test]
    fn ncc_is_one_up_to_gain_and_bias_and_zero_for_a_flat_patch() {
        let a: Vec<f32> = (0..441)
            .map(|i| 100.0 + 60.0 * (i as f32 * 0.3).sin())
            .collect();
        let b: Vec<f32> = a.iter().map(|v| 0.5 * v + 40.0).collect();
        let m = vec![1.0; 441];
        let r = ncc(&a, &b, &m, 441);
        assert!((r - 1.0).abs() < 1e-4, "{r}");
        let c: Vec<f32> = a.iter().map(|v| 255.0 - v).collect();
        assert!((ncc(&a, &c, &m, 441) + 1.0).abs() < 1e-4);
        assert_eq!(ncc(&a, &vec![7.0; 441], &m, 441), 0.0);
        // The masked entries do not count, whatever they hold.
        let mut d = b.clone();
        let mut half = m.clone();
        for k in (1..441).step_by(3) {
            d[k] = -1e4;
            half[k] = 0.0;
        }
        assert!((ncc(&a, &d, &half, 294) - 1.0).abs() < 1e-4);
    }

    #[test]
    fn points_and_tracks_files_are_read_and_a_bad_line_is_named() {
        let d = std::env::temp_dir().join(format!("regtrack-points-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("points.txt");
        std::fs::write(&p, "# corners\n10,20\n 30.5 40 \n").unwrap();
        assert_eq!(
            read_points(&p).unwrap(),
            vec![Point { x: 10.0, y: 20.0 }, Point { x: 30.5, y: 40.0 }]
        );
        std::fs::write(&p, "10,20\n1,2,3\n").unwrap();
        let e = read_points(&p).unwrap_err().to_string();
        assert!(e.contains("points.txt:2"), "{e}");
        // A run written and read back.
        let state = PatchState {
            centre: Point { x: 1.5, y: 2.25 },
            linear: [1.0, 0.0, 0.0, 1.0],
            status: TrackStatus::Lost(LossReason::OutOfFrame),
            ncc: 0.5,
            fb_error: None,
            iterations: 0,
        };
        let run = PatchRun {
            first: 0,
            frames: vec![vec![state; 2]; 3],
            times: Vec::new(),
        };
        let t = d.join("tracks.csv");
        write_tracks(&t, &run).unwrap();
        assert_eq!(read_tracks(&t).unwrap().frames, run.frames);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn unknown_and_out_of_range_parameters_are_named() {
        let e = PatchParams::parse(&[("sise".into(), "9".into())]).unwrap_err();
        assert!(e.to_string().contains("sise"), "{e}");
        let e = PatchParams::parse(&[("size".into(), "3".into())]).unwrap_err();
        assert!(e.to_string().contains("size"), "{e}");
        let p = PatchParams::parse(&[
            ("warp".into(), "affine".into()),
            ("template".into(), "first".into()),
        ])
        .unwrap();
        assert_eq!(
            (p.warp, p.template),
            (PatchWarp::Affine, TemplateSource::First)
        );
    }
}
