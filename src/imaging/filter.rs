//! Separable Gaussian smoothing (of a whole image or only a region), half-size downsampling and
//! Gaussian pyramids.

use super::{GrayF32, Image, ImageRef, ImageView, Pixel, STAMP_LEVELS, new_stamp};
use crate::geometry::Rect;

/// A normalised 1-D Gaussian kernel (odd size). A size of 1 or a zero sigma means no smoothing.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianKernel {
    weights: Vec<f32>,
}

impl GaussianKernel {
    /// The taps of the kernel.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }
    /// Half the size: how many pixels the kernel reads on each side.
    pub fn radius(&self) -> usize {
        self.weights.len() / 2
    }
}

/// A normalised Gaussian kernel of `size` taps (made odd) and standard deviation `sigma` (px).
/// `size <= 1` or `sigma <= 0` gives the identity.
pub fn gaussian_kernel(size: usize, sigma: f32) -> GaussianKernel {
    if size <= 1 || sigma <= 0.0 || !sigma.is_finite() {
        return GaussianKernel { weights: vec![1.0] };
    }
    let size = size | 1;
    let r = (size / 2) as i32;
    let mut w: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= s);
    GaussianKernel { weights: w }
}

/// Smooths the region `[x0, x1) x [y0, y1)` of `src` (already clipped to it) into `out`
/// (row-major, `x1 - x0` wide), replicating the image border. `tmp` and `line` are scratch
/// buffers that keep their allocation between calls.
#[allow(clippy::too_many_arguments)]
fn blur_region<T: Pixel>(
    src: ImageRef<'_, T>,
    kernel: &GaussianKernel,
    region: (usize, usize, usize, usize),
    out: &mut Vec<f32>,
    tmp: &mut Vec<f32>,
    line: &mut Vec<f32>,
) {
    let w = region.2 - region.0;
    out.resize(w * (region.3 - region.1), 0.0);
    blur_region_into::<_, true>(src, kernel, region, (out, w), tmp, line);
}

/// [`gaussian_blur_into`] for the rows `rows` of the result only, into `out` (`rows.len()` rows
/// of `src.width` pixels, the same values as those rows of the whole image's): bands of rows
/// can be smoothed by different threads.
pub fn gaussian_blur_rows_into<'a, T: Pixel>(
    src: impl Into<ImageRef<'a, T>>,
    kernel: &GaussianKernel,
    rows: std::ops::Range<usize>,
    out: &mut [f32],
    tmp: &mut Vec<f32>,
    line: &mut Vec<f32>,
) {
    let src = src.into();
    let region = (0, rows.start, src.width, rows.end.min(src.height));
    blur_region_into::<_, true>(src, kernel, region, (out, src.width), tmp, line);
}

/// [`blur_region`] into `out`, rows `stride` apart (at least the region's width), which holds
/// the region's pixels: with a 5-tap kernel and `STRIPS`, both passes strip by strip
/// ([`blur_strips`]), else row by row then down the columns (the same bits). A pixel's value
/// depends only on the image around it, not on the region it is smoothed with.
#[allow(clippy::too_many_arguments)]
fn blur_region_into<T: Pixel, const STRIPS: bool>(
    src: ImageRef<'_, T>,
    kernel: &GaussianKernel,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    (out, stride): (&mut [f32], usize),
    tmp: &mut Vec<f32>,
    line: &mut Vec<f32>,
) {
    let w = x1.saturating_sub(x0);
    let h = y1.saturating_sub(y0);
    if w == 0 || h == 0 {
        return;
    }
    assert!(
        stride >= w && out.len() >= (h - 1) * stride + w,
        "the output holds the region"
    );
    let k = kernel.weights();
    let r = kernel.radius();
    if r == 0 {
        for y in 0..h {
            let row = &src.row(y0 + y)[x0..x1];
            for (o, &v) in out[y * stride..y * stride + w].iter_mut().zip(row) {
                *o = v.to_f32();
            }
        }
        return;
    }
    let rows = h + 2 * r;
    // The first rows' lines asked for at once; each row then asks for the one PREFETCH_ROWS
    // below it (`padded_row`).
    for j in 0..rows.min(PREFETCH_ROWS) {
        let sy = (y0 + j).saturating_sub(r).min(src.height - 1);
        prefetch(&src.row(sy)[x0.saturating_sub(r)..(x1 + r).min(src.width)]);
    }
    if let (Ok(k5), true) = (<&[f32; TAPS]>::try_from(k), STRIPS && w >= STRIP) {
        // The padded rows in `tmp`, then both passes strip by strip.
        let pw = w + 2 * r;
        tmp.resize(rows * pw, 0.0);
        for j in 0..rows {
            padded_row(src, (x0, y0, x1), r, j, &mut tmp[j * pw..(j + 1) * pw]);
        }
        blur_strips(k5, tmp, (w, h), (out, stride));
        return;
    }
    tmp.resize(rows * w, 0.0);
    line.clear();
    line.resize(w + 2 * r, 0.0);
    for j in 0..rows {
        padded_row(src, (x0, y0, x1), r, j, line);
        convolve_row(k, line, &mut tmp[j * w..(j + 1) * w]);
    }
    for y in 0..h {
        convolve_column(
            k,
            &tmp[y * w..(y + k.len()) * w],
            w,
            &mut out[y * stride..y * stride + w],
        );
    }
}

/// Columns of a strip of [`blur_strips`].
const STRIP: usize = 8;
/// The kernel size [`blur_strips`] is for (the smoothing's default, 5 x 5).
const TAPS: usize = 5;

/// Row `j` of the region `[x0, x1)` from row `y0 - r`, widened by `r` on both sides, with the
/// image's border replicated, as floats into `line` (`x1 - x0 + 2 r` long). Asks memory for the
/// source row a few below: a frame fresh from a decoder or a camera is rarely in the core's
/// caches, and one row's few cache lines at a time would leave the memory idle between them.
fn padded_row<T: Pixel>(
    src: ImageRef<'_, T>,
    (x0, y0, x1): (usize, usize, usize),
    r: usize,
    j: usize,
    line: &mut [f32],
) {
    let last_x = src.width as isize - 1;
    let last_y = src.height as isize - 1;
    let sy = (y0 as isize + j as isize - r as isize).clamp(0, last_y) as usize;
    let ahead = (sy + PREFETCH_ROWS).min(last_y as usize);
    prefetch(&src.row(ahead)[x0.saturating_sub(r)..(x1 + r).min(src.width)]);
    let srow = src.row(sy);
    let start = x0 as isize - r as isize;
    let lo = (-start).clamp(0, line.len() as isize) as usize;
    let hi = ((last_x + 1 - start).clamp(lo as isize, line.len() as isize)) as usize;
    for (l, &v) in line[lo..hi]
        .iter_mut()
        .zip(&srow[(start + lo as isize) as usize..])
    {
        *l = v.to_f32();
    }
    for (i, l) in line.iter_mut().enumerate().take(lo) {
        *l = srow[(start + i as isize).clamp(0, last_x) as usize].to_f32();
    }
    for (i, l) in line.iter_mut().enumerate().skip(hi) {
        *l = srow[(start + i as isize).clamp(0, last_x) as usize].to_f32();
    }
}

/// Both passes of the separable kernel `k` over `padded` (`h + 4` rows of `w + 4`), eight
/// columns at a time from top to bottom, the last five rows' horizontal sums kept in registers
/// (instead of a pass over all rows into a buffer that outgrows the L1 cache, then one down
/// the columns): each output is the same sum in the same order as [`convolve_row`] then
/// [`convolve_column`] make it. The last strip overlaps the one before when `w` is not a
/// multiple of eight (its columns are written twice, with the same values).
fn blur_strips(
    k: &[f32; TAPS],
    padded: &[f32],
    (w, h): (usize, usize),
    (out, stride): (&mut [f32], usize),
) {
    let pw = w + TAPS - 1;
    let padded = &padded[..(h + TAPS - 1) * pw];
    let out = &mut out[..(h - 1) * stride + w];
    let mut x = 0;
    while x < w {
        let xs = x.min(w - STRIP);
        // The window of the last rows' horizontal sums, the newest last: the first TAPS - 1
        // rows fill it; each row after them makes an output row.
        let mut win = [[0f32; STRIP]; TAPS];
        for (j, row) in padded.chunks_exact(pw).enumerate() {
            let px = row[xs..].first_chunk().unwrap_or(&[0.0; STRIP + TAPS - 1]);
            for t in 0..TAPS - 1 {
                win[t] = win[t + 1];
            }
            win[TAPS - 1] = taps(k, |t, l| px[l + t]);
            if let Some(y) = (j + 1).checked_sub(TAPS)
                && let Some(dst) = out[y * stride + xs..].first_chunk_mut::<STRIP>()
            {
                *dst = taps(k, |t, l| win[t][l]);
            }
        }
        x += STRIP;
    }
}

/// `sum_t k[t] at(t, l)` for the eight lanes `l`, in the order of [`convolve_row`] and
/// [`convolve_column`] (a product, then multiply-adds).
#[inline(always)]
fn taps(k: &[f32; TAPS], at: impl Fn(usize, usize) -> f32) -> [f32; STRIP] {
    let mut acc = [0f32; STRIP];
    for (l, a) in acc.iter_mut().enumerate() {
        *a = k[0] * at(0, l);
    }
    for t in 1..TAPS {
        for (l, a) in acc.iter_mut().enumerate() {
            *a = k[t].mul_add(at(t, l), *a);
        }
    }
    acc
}

/// How many rows ahead of the one being smoothed [`blur_region_into`] prefetches.
const PREFETCH_ROWS: usize = 8;

/// Asks for the cache lines of `s` (a hint: no effect on the results).
#[inline(always)]
fn prefetch<T>(s: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        let bytes = std::mem::size_of_val(s);
        let p = s.as_ptr() as *const i8;
        // Every line the slice touches: from its first byte's, 64 bytes at a time, and its last.
        let mut off = 0;
        while off < bytes + (p as usize % 64) {
            // SAFETY: a prefetch does not read or fault; the address is inside `s` (clamped to
            // its last byte).
            unsafe {
                std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                    p.add(off.min(bytes.saturating_sub(1))),
                )
            };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = s;
}

/// `out[x] = sum_t k[t] line[x + t]`: with the kernel size known at compile time (3, 5, 7) the
/// taps are unrolled and the loop over `x` vectorises.
fn convolve_row(k: &[f32], line: &[f32], out: &mut [f32]) {
    fn fixed<const K: usize>(k: &[f32; K], line: &[f32], out: &mut [f32]) {
        let w = out.len();
        let line = &line[..w + K - 1];
        for x in 0..w {
            let mut acc = k[0] * line[x];
            for t in 1..K {
                acc = k[t].mul_add(line[x + t], acc);
            }
            out[x] = acc;
        }
    }
    match k.len() {
        3 => fixed::<3>(k.try_into().unwrap_or(&[0.0; 3]), line, out),
        5 => fixed::<5>(k.try_into().unwrap_or(&[0.0; 5]), line, out),
        7 => fixed::<7>(k.try_into().unwrap_or(&[0.0; 7]), line, out),
        _ => {
            out.fill(0.0);
            for (t, &kt) in k.iter().enumerate() {
                for (o, &v) in out.iter_mut().zip(&line[t..]) {
                    *o = kt.mul_add(v, *o);
                }
            }
        }
    }
}

/// `out[x] = sum_t k[t] rows[t w + x]` over `k.len()` consecutive rows of width `w`.
fn convolve_column(k: &[f32], rows: &[f32], w: usize, out: &mut [f32]) {
    fn fixed<const K: usize>(k: &[f32; K], rows: &[f32], w: usize, out: &mut [f32]) {
        let r: [&[f32]; K] = std::array::from_fn(|t| &rows[t * w..(t + 1) * w]);
        for x in 0..w.min(out.len()) {
            let mut acc = k[0] * r[0][x];
            for t in 1..K {
                acc = k[t].mul_add(r[t][x], acc);
            }
            out[x] = acc;
        }
    }
    match k.len() {
        3 => fixed::<3>(k.try_into().unwrap_or(&[0.0; 3]), rows, w, out),
        5 => fixed::<5>(k.try_into().unwrap_or(&[0.0; 5]), rows, w, out),
        7 => fixed::<7>(k.try_into().unwrap_or(&[0.0; 7]), rows, w, out),
        _ => {
            out.fill(0.0);
            for (t, &kt) in k.iter().enumerate() {
                for (o, &v) in out.iter_mut().zip(&rows[t * w..(t + 1) * w]) {
                    *o = kt.mul_add(v, *o);
                }
            }
        }
    }
}

/// Smooths a whole image with a separable Gaussian kernel (border replicated).
pub fn gaussian_blur<T: Pixel>(src: &Image<T>, kernel: &GaussianKernel) -> GrayF32 {
    let mut out = Vec::new();
    let (mut tmp, mut line) = (Vec::new(), Vec::new());
    blur_region(
        src.into(),
        kernel,
        (0, 0, src.width, src.height),
        &mut out,
        &mut tmp,
        &mut line,
    );
    Image {
        width: src.width,
        height: src.height,
        data: out,
    }
}

/// Smooths a whole image into `out` with a separable Gaussian kernel (border replicated);
/// `tmp` and `line` are scratch. Every buffer keeps its allocation from frame to frame.
pub fn gaussian_blur_into<'a, T: Pixel>(
    src: impl Into<ImageRef<'a, T>>,
    kernel: &GaussianKernel,
    out: &mut GrayF32,
    tmp: &mut Vec<f32>,
    line: &mut Vec<f32>,
) {
    let src = src.into();
    let (w, h) = (src.width, src.height);
    out.width = w;
    out.height = h;
    blur_region(src, kernel, (0, 0, w, h), &mut out.data, tmp, line);
}

/// `src` with a border of `b` pixels on every side, replicating its edges, into `out` (which
/// keeps its allocation): pixel `(x, y)` of `src` is pixel `(x + b, y + b)` of `out`.
pub fn pad_replicate_into(src: &GrayF32, b: usize, out: &mut GrayF32) {
    let (w, h) = (src.width, src.height);
    let pw = w + 2 * b;
    out.resize(pw, h + 2 * b);
    if w == 0 || h == 0 {
        out.data.fill(0.0);
        return;
    }
    for y in 0..h + 2 * b {
        let sy = y.saturating_sub(b).min(h - 1);
        let row = &src.data[sy * w..(sy + 1) * w];
        let dst = &mut out.data[y * pw..(y + 1) * pw];
        dst[..b].fill(row[0]);
        dst[b..b + w].copy_from_slice(row);
        dst[b + w..].fill(row[w - 1]);
    }
}

/// [`downsample_half`] into `out`, keeping the allocations of `out` and `scratch`.
pub fn downsample_half_into(src: &GrayF32, out: &mut GrayF32, scratch: &mut Vec<f32>) {
    half_into(&src.data, src.width, src.height, out, scratch);
}

/// Halves `src` (`w x h`) into `out`: binomial (1 4 6 4 1)/16 smoothing, then every other
/// pixel (pixel `i` of the result is pixel `2 i` of the source), the border replicated.
/// `scratch` keeps its allocation.
fn half_into(src: &[f32], w: usize, h: usize, out: &mut GrayF32, scratch: &mut Vec<f32>) {
    let (ow, oh) = (w.div_ceil(2).max(1), h.div_ceil(2).max(1));
    out.resize(ow, oh);
    half_rows_into(src, w, h, 0..oh, &mut out.data, scratch);
}

/// [`downsample_half_into`] for the rows `rows` of the result only, into `out` (`rows.len()`
/// rows of `src.width.div_ceil(2)` pixels, the same values as those rows of the whole
/// result's): bands of rows can be halved by different threads.
pub fn downsample_half_rows_into(
    src: &GrayF32,
    rows: std::ops::Range<usize>,
    out: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    half_rows_into(&src.data, src.width, src.height, rows, out, scratch);
}

/// Rows `rows` of the halving of `src` (`w x h`) into `out`.
fn half_rows_into(
    src: &[f32],
    w: usize,
    h: usize,
    rows: std::ops::Range<usize>,
    out: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    let ow = w.div_ceil(2).max(1);
    let out = &mut out[..rows.len() * ow];
    if w == 0 || h == 0 {
        out.fill(0.0);
        return;
    }
    const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    // The source rows the band reads: 2 y - 2 to 2 y + 2, clamped.
    let first = (2 * rows.start).saturating_sub(2).min(h - 1);
    let last = (2 * rows.end + 1).min(h - 1);
    // Horizontal pass at the kept columns, for those rows: the columns whose five taps are all
    // inside the row without clamping, the others (at most two on each side) with it.
    scratch.resize(ow * (last + 1 - first), 0.0);
    // Inner columns x: pixels 2 x - 2 to 2 x + 3 (the last pair's odd pixel included) in the row.
    let inner = 1..ow.min((w.saturating_sub(4)) / 2 + 1).max(1);
    let band = &src[first * w..(last + 1) * w];
    for (row, line) in band.chunks_exact(w).zip(scratch.chunks_exact_mut(ow)) {
        let tap = |c: isize| row[c.clamp(0, w as isize - 1) as usize];
        for x in (0..inner.start).chain(inner.end..ow) {
            let c = 2 * x as isize;
            line[x] = K[0] * tap(c - 2)
                + K[1] * tap(c - 1)
                + K[2] * tap(c)
                + K[3] * tap(c + 1)
                + K[4] * tap(c + 2);
        }
        // The row as (even, odd) pixel pairs: output x reads pairs x - 1, x and x + 1.
        let (pairs, _) = row.as_chunks::<2>();
        for x in inner.clone() {
            let (a, b, c) = (pairs[x - 1], pairs[x], pairs[x + 1]);
            line[x] = K[0] * (a[0] + c[0]) + K[1] * (a[1] + b[1]) + K[2] * b[0];
        }
    }
    // Vertical pass at the kept rows: five whole rows of the scratch, weighted.
    for (y, dst) in rows.zip(out.chunks_exact_mut(ow)) {
        let row = |t: isize| {
            let sy = (2 * y as isize + t).clamp(0, h as isize - 1) as usize - first;
            &scratch[sy * ow..(sy + 1) * ow]
        };
        let (a, b, c, d, e) = (row(-2), row(-1), row(0), row(1), row(2));
        for x in 0..ow {
            dst[x] = K[0] * (a[x] + e[x]) + K[1] * (b[x] + d[x]) + K[2] * c[x];
        }
    }
}

/// Halves an image: binomial (1 4 6 4 1)/16 smoothing, then every other pixel.
pub fn downsample_half(src: &GrayF32) -> GrayF32 {
    let mut out = Image::default();
    half_into(&src.data, src.width, src.height, &mut out, &mut Vec::new());
    out
}

/// A Gaussian pyramid of `levels` levels (level 0 is `src`), each half the size of the previous.
/// Stops early when a level would be smaller than 8 pixels on a side.
pub fn pyramid(src: &GrayF32, levels: usize) -> Vec<GrayF32> {
    let mut out = vec![src.clone()];
    while out.len() < levels.max(1) {
        let prev = &out[out.len() - 1];
        if prev.width < 16 || prev.height < 16 {
            break;
        }
        out.push(downsample_half(prev));
    }
    out
}

/// `[x0, x1) x [y0, y1)` rounded outwards to whole pixels and clipped to `within` (NaN to its
/// start), never reversed.
pub(super) fn clip_rect(
    Rect { x0, y0, x1, y1 }: Rect,
    (wx0, wy0, wx1, wy1): (usize, usize, usize, usize),
) -> (usize, usize, usize, usize) {
    let clip = |v: f64, lo: usize, hi: usize| -> usize {
        if v.is_nan() {
            lo
        } else {
            v.clamp(lo as f64, hi as f64) as usize
        }
    };
    let cx0 = clip(x0.floor(), wx0, wx1);
    let cy0 = clip(y0.floor(), wy0, wy1);
    let cx1 = clip(x1.ceil(), wx0, wx1).max(cx0);
    let cy1 = clip(y1.ceil(), wy0, wy1).max(cy0);
    (cx0, cy0, cx1, cy1)
}

/// The stop threshold of a search at a coarse pyramid level, in that level's pixels: a coarse
/// level only has to bring the search into the finer level's basin (and where it cannot see the
/// target, a star field, it would wander for all its iterations).
pub const COARSE_EPS: f64 = 0.05;

/// Pre-processes only the region a tracker reads: converts it to float and smooths it (border
/// replicated at the image edges), into buffers it keeps between frames, so the hot path does
/// not allocate once they have grown to the region's size.
#[derive(Clone, Debug)]
pub struct Preprocessor {
    kernel: GaussianKernel,
    out: Vec<f32>,
    tmp: Vec<f32>,
    line: Vec<f32>,
    region: (usize, usize, usize, usize),
    /// The part of the region smoothed so far (all of it but after [`Preprocessor::process_part`]).
    smoothed: (usize, usize, usize, usize),
    /// Coarser levels of the region (level 1, 2, ...), each half the previous.
    levels: Vec<GrayF32>,
    scratch: Vec<f32>,
    /// The stamp of the views of the region last processed ([`ImageView::stamp`]).
    stamp: u64,
}

impl Preprocessor {
    /// A pre-processor with the given smoothing kernel.
    pub fn new(kernel: GaussianKernel) -> Self {
        Preprocessor {
            kernel,
            out: Vec::new(),
            tmp: Vec::new(),
            line: Vec::new(),
            region: (0, 0, 0, 0),
            smoothed: (0, 0, 0, 0),
            levels: Vec::new(),
            scratch: Vec::new(),
            stamp: 0,
        }
    }

    /// The smoothing kernel.
    pub fn kernel(&self) -> &GaussianKernel {
        &self.kernel
    }

    /// Smooths the region `[x0, x1) x [y0, y1)` (real coordinates, clipped to the image and
    /// rounded outwards) of `src`.
    pub fn process<'a, T: Pixel>(&mut self, src: impl Into<ImageRef<'a, T>>, region: Rect) {
        self.process_part(src, region, region);
    }

    /// Like [`Preprocessor::process`] for the region `[x0, x1) x [y0, y1)`, whose view it
    /// gives, but smooths only the part of it within `part` (real coordinates, rounded
    /// outwards); [`Preprocessor::holds`] says whether a rectangle is in that part,
    /// [`Preprocessor::complete`] smooths the rest. Each pixel is smoothed as `process` smooths
    /// it (the same bits). Until completed, the view's other pixels are left from earlier
    /// frames (NaN in builds with debug assertions, so that a read of one shows). With `part`
    /// the region itself, [`Preprocessor::process`].
    pub fn process_part<'a, T: Pixel>(
        &mut self,
        src: impl Into<ImageRef<'a, T>>,
        region: Rect,
        part: Rect,
    ) {
        let src = src.into();
        self.stamp = new_stamp();
        self.region = clip_rect(region, (0, 0, src.width, src.height));
        let (rx0, ry0, rx1, ry1) = self.region;
        let rw = rx1 - rx0;
        self.out.resize(rw * (ry1 - ry0), 0.0);
        self.smoothed = clip_rect(part, self.region);
        if cfg!(debug_assertions) && !self.is_whole() {
            self.out.fill(f32::NAN);
        }
        self.smooth(src, self.smoothed);
    }

    /// Whether the pixels of the rectangle `[x0, x1) x [y0, y1)` (frame coordinates) are
    /// smoothed: inside the region and its smoothed part.
    pub fn holds(&self, r: &Rect) -> bool {
        let (sx0, sy0, sx1, sy1) = self.smoothed;
        Rect::new(sx0 as f64, sy0 as f64, sx1 as f64, sy1 as f64).contains(r)
    }

    /// Whether the whole region is smoothed (not after a [`Preprocessor::process_part`] until
    /// [`Preprocessor::complete`]).
    pub fn is_whole(&self) -> bool {
        self.smoothed == self.region
    }

    /// Smooths what [`Preprocessor::process_part`] left of the region (`src` is the image it
    /// was given): the bands above, below, left and right of the smoothed part.
    pub fn complete<'a, T: Pixel>(&mut self, src: impl Into<ImageRef<'a, T>>) {
        let src = src.into();
        let (rx0, ry0, rx1, ry1) = self.region;
        let (sx0, sy0, sx1, sy1) = self.smoothed;
        if self.smoothed == self.region {
            return;
        }
        // An empty part (a target outside the region) leaves the whole region.
        let (sx0, sy0, sx1, sy1) = if sx0 >= sx1 || sy0 >= sy1 {
            (rx0, ry0, rx0, ry0)
        } else {
            (sx0, sy0, sx1, sy1)
        };
        for band in [
            (rx0, ry0, rx1, sy0),
            (rx0, sy1, rx1, ry1),
            (rx0, sy0, sx0, sy1),
            (sx1, sy0, rx1, sy1),
        ] {
            self.smooth(src, band);
        }
        self.smoothed = self.region;
    }

    /// Smooths `rect` (within the region) into its place in the region's buffer.
    fn smooth<T: Pixel>(&mut self, src: ImageRef<'_, T>, rect: (usize, usize, usize, usize)) {
        let (rx0, ry0, rx1, _) = self.region;
        let (x0, y0, x1, y1) = rect;
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        let rw = rx1 - rx0;
        let at = (y0 - ry0) * rw + (x0 - rx0);
        blur_region_into::<_, true>(
            src,
            &self.kernel,
            rect,
            (&mut self.out[at..], rw),
            &mut self.tmp,
            &mut self.line,
        );
    }

    /// The region last processed, in whole pixels (end exclusive).
    pub fn region(&self) -> Rect {
        let (x0, y0, x1, y1) = self.region;
        Rect::new(x0 as f64, y0 as f64, x1 as f64, y1 as f64)
    }

    /// A view of the region last processed, in frame coordinates (stamped: see
    /// [`ImageView::stamp`]; completing a region smoothed in part keeps the stamp, since the
    /// pixels already smoothed do not change).
    pub fn view(&self) -> ImageView<'_> {
        let (x0, y0, x1, y1) = self.region;
        ImageView::new(&self.out, x1 - x0, y1 - y0, x0 as i64, y0 as i64).with_stamp(self.stamp)
    }

    /// Builds `count` coarser levels of the region last processed (binomial smoothing and
    /// decimation by two each), in buffers kept between frames.
    pub fn build_levels(&mut self, count: usize) {
        debug_assert!(
            count == 0 || self.is_whole(),
            "levels of a region smoothed in part"
        );
        self.levels.truncate(count);
        while self.levels.len() < count {
            self.levels.push(Image::default());
        }
        let (x0, y0, x1, y1) = self.region;
        let (mut w, mut h) = (x1 - x0, y1 - y0);
        for l in 0..count {
            let (done, rest) = self.levels.split_at_mut(l);
            let src: &[f32] = if l == 0 { &self.out } else { &done[l - 1].data };
            half_into(src, w, h, &mut rest[0], &mut self.scratch);
            w = rest[0].width;
            h = rest[0].height;
        }
    }

    /// Level `l` (0 = the region itself) as a view in frame coordinates.
    pub fn level_view(&self, l: usize) -> ImageView<'_> {
        if l == 0 || l > self.levels.len() {
            return self.view();
        }
        let (x0, y0, _, _) = self.region;
        let img = &self.levels[l - 1];
        debug_assert!((l as u64) < STAMP_LEVELS);
        ImageView::new(&img.data, img.width, img.height, x0 as i64, y0 as i64)
            .with_scale((1u32 << l) as f32)
            .with_stamp(self.stamp + l as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A band of rows smoothed or halved alone equals those rows of the whole image's, for
    /// bands that touch the image's top, bottom or neither.
    #[test]
    fn bands_of_rows_equal_the_whole_images_rows() {
        let mut rng = crate::rng::Rng::new(11);
        for (w, h) in [(37usize, 23usize), (8, 9), (64, 40)] {
            let src = GrayF32::from_vec(
                w,
                h,
                (0..w * h).map(|_| 255.0 * rng.uniform() as f32).collect(),
            )
            .unwrap();
            let kernel = gaussian_kernel(5, 1.0);
            let (mut whole, mut tmp, mut line) = (GrayF32::default(), Vec::new(), Vec::new());
            gaussian_blur_into(&src, &kernel, &mut whole, &mut tmp, &mut line);
            let half = downsample_half(&src);
            for n in [1, 2, 3, 7] {
                for k in 0..n {
                    let rows = k * h / n..(k + 1) * h / n;
                    let mut band = vec![0.0; rows.len() * w];
                    gaussian_blur_rows_into(
                        &src,
                        &kernel,
                        rows.clone(),
                        &mut band,
                        &mut tmp,
                        &mut line,
                    );
                    assert_eq!(
                        band,
                        whole.data[rows.start * w..rows.end * w],
                        "{w}x{h} {n} {k}"
                    );
                    let oh = half.height;
                    let rows = k * oh / n..(k + 1) * oh / n;
                    let mut band = vec![0.0; rows.len() * half.width];
                    downsample_half_rows_into(&src, rows.clone(), &mut band, &mut tmp);
                    let want = &half.data[rows.start * half.width..rows.end * half.width];
                    assert_eq!(band, want, "half {w}x{h} {n} {k}");
                }
            }
        }
    }

    /// A region smoothed in part, then completed, is the region smoothed at once, bit for bit;
    /// the part holds what it covers only. Regions at the image's borders and inside, parts
    /// inside them, across their edges and outside.
    #[test]
    fn a_region_smoothed_in_parts_is_the_region_smoothed_at_once() {
        let mut rng = crate::rng::Rng::new(5);
        let (w, h) = (61usize, 47usize);
        let src = crate::imaging::GrayU8::noise(w, h, &mut rng);
        let mut whole = Preprocessor::new(gaussian_kernel(5, 0.9));
        let mut parts = whole.clone();
        let bits = |p: &Preprocessor| -> Vec<u32> { p.out.iter().map(|v| v.to_bits()).collect() };
        for region in [
            Rect::new(-3.0, -2.0, 70.0, 50.0),
            Rect::new(5.2, 7.9, 40.1, 33.0),
            Rect::new(20.0, 0.0, 61.0, 12.0),
        ] {
            whole.process(&src, region);
            for part in [
                Rect::new(12.5, 10.0, 30.0, 25.0),
                Rect::new(-10.0, 9.0, 18.0, 60.0),
                Rect::new(3.0, 3.0, 3.5, 4.0),
                Rect::new(100.0, 100.0, 120.0, 130.0),
            ] {
                parts.process_part(&src, region, part);
                assert_eq!(parts.region(), whole.region());
                let (rx0, ry0, rx1, ry1) = parts.region;
                let (sx0, sy0, sx1, sy1) = parts.smoothed;
                // The part's pixels are already the whole's.
                let rw = rx1 - rx0;
                for y in sy0..sy1 {
                    for x in sx0..sx1 {
                        let i = (y - ry0) * rw + (x - rx0);
                        assert_eq!(parts.out[i].to_bits(), whole.out[i].to_bits());
                    }
                }
                let inside = Rect::new(sx0 as f64, sy0 as f64, sx1 as f64, sy1 as f64);
                assert!(parts.holds(&inside));
                let beyond = Rect::new(sx0 as f64 - 1.0, sy0 as f64, sx1 as f64, sy1 as f64);
                assert!(!parts.holds(&beyond));
                parts.complete(&src);
                assert!(
                    parts.is_whole()
                        && parts.holds(&Rect::new(rx0 as f64, ry0 as f64, rx1 as f64, ry1 as f64))
                );
                assert_eq!(bits(&parts), bits(&whole), "{region:?} {part:?}");
            }
        }
    }

    #[test]
    fn padding_replicates_the_edges() {
        let src = GrayF32::from_vec(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let mut out = GrayF32::default();
        pad_replicate_into(&src, 2, &mut out);
        assert_eq!((out.width, out.height), (7, 6));
        assert_eq!(out.row(0), &[1.0, 1.0, 1.0, 2.0, 3.0, 3.0, 3.0]);
        assert_eq!(out.row(3), &[4.0, 4.0, 4.0, 5.0, 6.0, 6.0, 6.0]);
        assert_eq!(out.row(5), out.row(3));
    }
    use crate::rng::Rng;

    fn naive(src: &GrayF32, k: &[f32]) -> GrayF32 {
        let r = (k.len() / 2) as i64;
        let (w, h) = (src.width as i64, src.height as i64);
        let mut out = Image::new(src.width, src.height);
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0f64;
                for (j, &kj) in k.iter().enumerate() {
                    for (i, &ki) in k.iter().enumerate() {
                        let sx = (x + i as i64 - r).clamp(0, w - 1) as usize;
                        let sy = (y + j as i64 - r).clamp(0, h - 1) as usize;
                        acc += (ki * kj) as f64 * src.get(sx, sy) as f64;
                    }
                }
                out.set(x as usize, y as usize, acc as f32);
            }
        }
        out
    }

    #[test]
    fn the_strips_make_the_bits_of_the_rows_then_the_columns() {
        let mut rng = Rng::new(11);
        let (w, h) = (53, 37);
        let src8 = Image {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|_| rng.range(0.0, 255.0) as u8)
                .collect::<Vec<u8>>(),
        };
        let src32 = Image {
            width: w,
            height: h,
            data: src8
                .data
                .iter()
                .map(|&v| v as f32 + 0.37)
                .collect::<Vec<f32>>(),
        };
        let k = gaussian_kernel(5, 0.7);
        // The region smoothed both ways, with scratch buffers that other regions used before.
        fn both<T: Pixel>(
            src: &Image<T>,
            k: &GaussianKernel,
            region: (usize, usize, usize, usize),
        ) -> (Vec<f32>, Vec<f32>) {
            let (x0, y0, x1, y1) = region;
            let n = (x1 - x0) * (y1 - y0);
            let (mut a, mut b) = (vec![f32::NAN; n], vec![f32::NAN; n]);
            let (mut tmp, mut line) = (vec![1.0; 9999], vec![2.0; 99]);
            let rw = x1 - x0;
            let (sa, sb) = ((&mut a[..], rw), (&mut b[..], rw));
            blur_region_into::<_, true>(src.into(), k, region, sa, &mut tmp, &mut line);
            blur_region_into::<_, false>(src.into(), k, region, sb, &mut tmp, &mut line);
            (a, b)
        }
        let same = |(a, b): (Vec<f32>, Vec<f32>)| {
            a.len() == b.len() && a.iter().zip(&b).all(|(a, b)| a.to_bits() == b.to_bits())
        };
        // Widths from one strip to several with a partial last one, regions at every border
        // and inside.
        for x0 in [0, 3, 17] {
            for x1 in [x0 + 8, x0 + 9, x0 + 15, x0 + 16, x0 + 23, w] {
                for (y0, y1) in [(0, h), (2, 11), (20, h), (5, 6)] {
                    let region = (x0, y0, x1.min(w), y1);
                    assert!(same(both(&src8, &k, region)), "{region:?} (8-bit)");
                    assert!(same(both(&src32, &k, region)), "{region:?} (floats)");
                }
            }
        }
    }

    #[test]
    fn separable_blur_matches_the_2d_convolution_and_regions_match_the_whole() {
        let mut rng = Rng::new(5);
        let src = Image {
            width: 41,
            height: 29,
            data: (0..41 * 29)
                .map(|_| rng.range(0.0, 255.0) as f32)
                .collect::<Vec<f32>>(),
        };
        let src8 = Image {
            width: 41,
            height: 29,
            data: src.data.iter().map(|&v| v as u8).collect::<Vec<u8>>(),
        };
        for (size, sigma) in [(3, 0.8), (5, 3.0), (7, 1.5), (9, 2.0), (1, 1.0)] {
            let k = gaussian_kernel(size, sigma);
            assert!((k.weights().iter().sum::<f32>() - 1.0).abs() < 1e-6);
            let fast = gaussian_blur(&src, &k);
            let slow = naive(&src, k.weights());
            for (a, b) in fast.data.iter().zip(&slow.data) {
                assert!((a - b).abs() < 1e-3, "size {size}: {a} vs {b}");
            }
            // A region (partly outside the image) equals the same pixels of the whole.
            let whole8 = gaussian_blur(&src8, &k);
            let mut pre = Preprocessor::new(k.clone());
            pre.process(&src8, Rect::new(-3.0, 4.2, 20.5, 40.0));
            assert_eq!(pre.region(), Rect::new(0.0, 4.0, 21.0, 29.0));
            let v = pre.view();
            for y in 4..29 {
                for x in 0..21 {
                    let got = crate::imaging::sample_value(&v, x as f32, y as f32);
                    assert!((got - whole8.get(x, y)).abs() < 1e-3);
                }
            }
        }
    }

    #[test]
    fn halving_matches_the_clamped_binomial_filter_at_every_size() {
        // The reference: every tap clamped to the image, pixel 2 i of the smoothed source.
        let k = [1.0f64, 4.0, 6.0, 4.0, 1.0].map(|v| v / 16.0);
        let mut rng = Rng::new(3);
        for (w, h) in [
            (1, 1),
            (2, 3),
            (3, 2),
            (4, 4),
            (5, 7),
            (6, 5),
            (16, 9),
            (33, 20),
        ] {
            let data: Vec<f32> = (0..w * h).map(|_| 255.0 * rng.uniform() as f32).collect();
            let mut out = Image::default();
            half_into(&data, w, h, &mut out, &mut Vec::new());
            let at = |x: i64, y: i64| {
                data[(y.clamp(0, h as i64 - 1) * w as i64 + x.clamp(0, w as i64 - 1)) as usize]
                    as f64
            };
            assert_eq!((out.width, out.height), (w.div_ceil(2), h.div_ceil(2)));
            for y in 0..out.height {
                for x in 0..out.width {
                    let mut v = 0.0;
                    for (j, kj) in k.iter().enumerate() {
                        for (i, ki) in k.iter().enumerate() {
                            v += kj
                                * ki
                                * at(2 * x as i64 + i as i64 - 2, 2 * y as i64 + j as i64 - 2);
                        }
                    }
                    let got = out.data[y * out.width + x] as f64;
                    assert!(
                        (got - v).abs() < 1e-3,
                        "{w}x{h} at ({x}, {y}): {got} != {v}"
                    );
                }
            }
        }
    }

    #[test]
    fn pyramid_halves_and_keeps_flat_images_flat() {
        let img = Image {
            width: 64,
            height: 40,
            data: vec![7.0f32; 64 * 40],
        };
        let p = pyramid(&img, 4);
        assert_eq!(
            p.iter().map(|l| (l.width, l.height)).collect::<Vec<_>>(),
            vec![(64, 40), (32, 20), (16, 10)]
        );
        assert!(
            p.iter()
                .all(|l| l.data.iter().all(|&v| (v - 7.0).abs() < 1e-5))
        );
    }
}
