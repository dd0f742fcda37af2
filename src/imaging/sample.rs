//! Bilinear sampling of values and gradients at sub-pixel points.
//!
//! Gradients are central differences of the bilinearly interpolated image with a one-pixel step,
//! `gx = (I(x+1, y) - I(x-1, y)) / 2`: the same as interpolating the central-difference gradient
//! images, without computing them over the whole region.

/// What a sample outside the image reads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Border {
    /// The nearest pixel of the image (edge replicated).
    #[default]
    Replicate,
    /// Zero.
    Zero,
}

/// A new stamp for views of content just made ([`ImageView::stamp`]): unique in the process,
/// and followed by [`STAMP_LEVELS`] - 1 more for the same content's pyramid levels.
pub fn new_stamp() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(STAMP_LEVELS);
    NEXT.fetch_add(STAMP_LEVELS, std::sync::atomic::Ordering::Relaxed)
}

/// The stamps reserved by one [`new_stamp`]: level `l` of the content is stamped `stamp + l`.
pub const STAMP_LEVELS: u64 = 8;

/// The most planes a view has: the four descriptor fields ([`crate::spec::Channels::Df`]).
pub const MAX_PLANES: usize = 4;

/// A read-only window of a float image placed at `(x0, y0)` in frame coordinates: points are
/// given in frame coordinates and sampled from the window.
#[derive(Clone, Copy, Debug)]
pub struct ImageView<'a> {
    data: &'a [f32],
    width: usize,
    height: usize,
    x0: i64,
    y0: i64,
    /// Frame pixels per window pixel (2^l for level l of a pyramid).
    scale: f32,
    border: Border,
    /// What content this is (see [`ImageView::stamp`]); 0: unknown.
    stamp: u64,
    /// The other planes of a view of several (the same window of a colour frame's other
    /// channels, or of the other descriptor fields; see [`ImageView::with_planes`]), and how
    /// many planes the view has (1 to [`MAX_PLANES`]).
    others: [&'a [f32]; MAX_PLANES - 1],
    planes: u8,
}

impl<'a> ImageView<'a> {
    /// A window of `width x height` pixels whose first pixel is at `(x0, y0)` in the frame.
    ///
    /// # Panics
    /// If `data` is shorter than `width * height` (a programming error).
    pub fn new(data: &'a [f32], width: usize, height: usize, x0: i64, y0: i64) -> Self {
        assert!(
            data.len() >= width * height,
            "image view larger than its data"
        );
        ImageView {
            data,
            width,
            height,
            x0,
            y0,
            scale: 1.0,
            border: Border::Replicate,
            stamp: 0,
            others: [&[]; MAX_PLANES - 1],
            planes: 1,
        }
    }

    /// The same window of three planes (a colour frame's channels): `self`'s pixels are the
    /// first, `second` and `third` the others, laid out alike. The sampling functions
    /// ([`sample_values`], [`sample_values_gradients`]) then read a grid of three equal parts,
    /// part `c` from plane `c`; everything else reads the first plane.
    ///
    /// # Panics
    /// If a plane is shorter than the window (a programming error).
    pub fn with_planes(self, second: &'a [f32], third: &'a [f32]) -> Self {
        self.with_more_planes(&[second, third])
    }

    /// The same window of `1 + more.len()` planes (at most [`MAX_PLANES`]): `self`'s pixels
    /// are the first, `more` the others, laid out alike; as [`ImageView::with_planes`].
    ///
    /// # Panics
    /// If a plane is shorter than the window, or there are more than [`MAX_PLANES`] (a
    /// programming error).
    pub fn with_more_planes(mut self, more: &[&'a [f32]]) -> Self {
        let n = self.width * self.height;
        assert!(more.len() < MAX_PLANES, "more planes than a view holds");
        assert!(
            more.iter().all(|p| p.len() >= n),
            "image plane smaller than its view"
        );
        self.others = [&[]; MAX_PLANES - 1];
        self.others[..more.len()].copy_from_slice(more);
        self.planes = 1 + more.len() as u8;
        self
    }

    /// How many planes the view has: 1, or more for a colour view or descriptor fields
    /// ([`ImageView::with_planes`]).
    pub fn planes(&self) -> usize {
        self.planes as usize
    }

    /// Plane `c` alone (`c < planes()`; the first for any other).
    pub fn plane(&self, c: usize) -> ImageView<'a> {
        let mut v = *self;
        if c > 0 && c < self.planes() {
            v.data = self.others[c - 1];
        }
        v.others = [&[]; MAX_PLANES - 1];
        v.planes = 1;
        v
    }

    /// The same view marked as showing the content `stamp` (see [`ImageView::stamp`]).
    pub fn with_stamp(mut self, stamp: u64) -> Self {
        self.stamp = stamp;
        self
    }

    /// Which content the view shows: two views with the same non-zero stamp show the same
    /// pixels (a pre-processed region is stamped anew each time it is made, [`new_stamp`]), so
    /// what was sampled from one holds for the other; 0 for a view nothing is known of.
    pub fn stamp(&self) -> u64 {
        self.stamp
    }

    /// The same view as a pyramid level: each window pixel covers `scale` frame pixels, window
    /// pixel `i` sits at frame coordinate `x0 + scale * i`. Gradients stay per frame pixel.
    pub fn with_scale(mut self, scale: f32) -> Self {
        if scale.is_finite() && scale > 0.0 {
            self.scale = scale;
        }
        self
    }

    /// Frame pixels per window pixel.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The same view with another border policy.
    pub fn with_border(mut self, border: Border) -> Self {
        self.border = border;
        self
    }

    /// The window's pixels, row by row (`width x height`).
    pub fn pixels(&self) -> &'a [f32] {
        self.data
    }
    /// Width of the window in pixels.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height of the window in pixels.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Frame coordinates of the window's first pixel.
    pub fn origin(&self) -> (i64, i64) {
        (self.x0, self.y0)
    }
    /// Whether the window holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    /// Whether [`ImageView::sample_whole`] may sample this view: a whole image (placed at the
    /// origin, scale 1) with its edge replicated, at least 2 x 2.
    pub fn is_whole(&self) -> bool {
        self.x0 == 0
            && self.y0 == 0
            && self.scale == 1.0
            && self.border == Border::Replicate
            && self.width >= 2
            && self.height >= 2
    }

    /// [`sample_value`] on a view that [`ImageView::is_whole`]: the same bits (frame and window
    /// coordinates are the same), without the checks of each call.
    #[inline(always)]
    pub fn sample_whole(&self, x: f32, y: f32) -> f32 {
        debug_assert!(self.is_whole());
        self.bilinear_replicate(x, y)
    }

    #[inline(always)]
    fn pixel(&self, ix: i64, iy: i64) -> f32 {
        let (w, h) = (self.width as i64, self.height as i64);
        match self.border {
            Border::Replicate => {
                let x = ix.clamp(0, w - 1) as usize;
                let y = iy.clamp(0, h - 1) as usize;
                self.data[y * self.width + x]
            }
            Border::Zero => {
                if ix < 0 || iy < 0 || ix >= w || iy >= h {
                    0.0
                } else {
                    self.data[iy as usize * self.width + ix as usize]
                }
            }
        }
    }

    /// Bilinear value at window coordinates with the border replicated (at least 2x2 pixels):
    /// the coordinates are clamped into the window (NaN goes to 0), so every read is in bounds.
    #[inline(always)]
    fn bilinear_replicate(&self, x: f32, y: f32) -> f32 {
        let (wm, hm) = ((self.width - 1) as f32, (self.height - 1) as f32);
        let xc = x.max(0.0).min(wm);
        let yc = y.max(0.0).min(hm);
        let ix = (xc as i32 as usize).min(self.width - 2);
        let iy = (yc as i32 as usize).min(self.height - 2);
        let (ax, ay) = (xc - ix as f32, yc - iy as f32);
        let i = iy * self.width + ix;
        let d = &self.data[i..i + self.width + 2];
        let (p00, p10, p01, p11) = (d[0], d[1], d[self.width], d[self.width + 1]);
        let top = p00 + ax * (p10 - p00);
        let bot = p01 + ax * (p11 - p01);
        top + ay * (bot - top)
    }

    /// Bilinear value at window coordinates (general path, any border).
    #[inline(always)]
    fn bilinear_local(&self, x: f32, y: f32) -> f32 {
        let fx0 = x.floor();
        let fy0 = y.floor();
        let (ix, iy) = (fx0 as i64, fy0 as i64);
        let (ax, ay) = (x - fx0, y - fy0);
        let p00 = self.pixel(ix, iy);
        let p10 = self.pixel(ix + 1, iy);
        let p01 = self.pixel(ix, iy + 1);
        let p11 = self.pixel(ix + 1, iy + 1);
        let top = p00 + ax * (p10 - p00);
        let bot = p01 + ax * (p11 - p01);
        top + ay * (bot - top)
    }

    /// Value and gradient at frame point `(x, y)` by the general path (any border, any point).
    #[inline]
    fn value_gradient_general(&self, x: f32, y: f32) -> (f32, f32, f32) {
        let (lx, ly) = self.local(x, y);
        let (lx, ly) = clamp_far(lx, ly, self);
        let (v, gx, gy) = self.value_gradient_local(lx, ly);
        let inv = 1.0 / self.scale;
        (v, gx * inv, gy * inv)
    }

    /// Value and gradient at window coordinates (general path, any border).
    #[inline(always)]
    fn value_gradient_local(&self, x: f32, y: f32) -> (f32, f32, f32) {
        let v = self.bilinear_local(x, y);
        let gx = 0.5 * (self.bilinear_local(x + 1.0, y) - self.bilinear_local(x - 1.0, y));
        let gy = 0.5 * (self.bilinear_local(x, y + 1.0) - self.bilinear_local(x, y - 1.0));
        (v, gx, gy)
    }

    #[inline(always)]
    fn local(&self, x: f32, y: f32) -> (f32, f32) {
        let inv = 1.0 / self.scale;
        ((x - self.x0 as f32) * inv, (y - self.y0 as f32) * inv)
    }
}

/// The bilinearly interpolated value at frame point `(x, y)`. A NaN coordinate reads like 0.
#[inline]
pub fn sample_value(img: &ImageView, x: f32, y: f32) -> f32 {
    if img.is_empty() {
        return 0.0;
    }
    let (lx, ly) = img.local(x, y);
    if img.border == Border::Replicate && img.width >= 2 && img.height >= 2 {
        return img.bilinear_replicate(lx, ly);
    }
    let (lx, ly) = clamp_far(lx, ly, img);
    img.bilinear_local(lx, ly)
}

/// Keeps far-away coordinates in a range where integer conversion is exact (NaN becomes the
/// lower bound); the border policy gives the same value anywhere that far outside.
#[inline(always)]
fn clamp_far(x: f32, y: f32, img: &ImageView) -> (f32, f32) {
    let (w, h) = (img.width as f32, img.height as f32);
    (x.max(-4.0).min(w + 4.0), y.max(-4.0).min(h + 4.0))
}

/// Points are processed in blocks of this many: a first pass computes the indices and weights
/// of a block (vectorised), a second reads the pixels.
const BLOCK: usize = 256;

/// Samples the values at frame points `(xs[i], ys[i])` into `out`.
///
/// On a view of several planes ([`ImageView::with_planes`]) the points are that many equal
/// parts, part `c` read from plane `c` (a colour grid: the same points once per channel).
pub fn sample_values(img: &ImageView, xs: &[f32], ys: &[f32], out: &mut [f32]) {
    debug_assert!(xs.len() == ys.len() && out.len() == xs.len());
    if img.planes > 1 {
        let n = xs.len() / img.planes();
        debug_assert_eq!(n * img.planes(), xs.len(), "a colour grid of equal parts");
        for c in 0..img.planes() {
            let r = c * n..(c + 1) * n;
            sample_values(&img.plane(c), &xs[r.clone()], &ys[r.clone()], &mut out[r]);
        }
        return;
    }
    if !(img.border == Border::Replicate && img.width >= 2 && img.height >= 2) {
        for ((o, &x), &y) in out.iter_mut().zip(xs).zip(ys) {
            *o = sample_value(img, x, y);
        }
        return;
    }
    // Whole groups of eight points with AVX2, the rest below.
    #[cfg(simd = "avx2")]
    let done = avx2::values(img, xs, ys, out);
    #[cfg(not(simd = "avx2"))]
    let done = 0;
    let (xs, ys, out) = (&xs[done..], &ys[done..], &mut out[done..]);
    // The vector path leaves fewer than eight: scratch arrays that short need no zeroing of a
    // whole block's (which took 4 % of a tracked frame).
    if xs.len() <= 8 {
        values_rest::<8>(img, xs, ys, out);
    } else {
        values_rest::<BLOCK>(img, xs, ys, out);
    }
}

/// [`sample_values`]'s scalar loop over `xs`, blocks of `B` points at a time.
fn values_rest<const B: usize>(img: &ImageView, xs: &[f32], ys: &[f32], out: &mut [f32]) {
    let w = img.width;
    let (ox, oy, inv) = (img.x0 as f32, img.y0 as f32, 1.0 / img.scale);
    let (wm, hm) = ((img.width - 1) as f32, (img.height - 1) as f32);
    let (wm2, hm2) = ((img.width - 2) as f32, (img.height - 2) as f32);
    let mut idx = [0u32; B];
    let mut ax = [0f32; B];
    let mut ay = [0f32; B];
    for ((xb, yb), ob) in xs.chunks(B).zip(ys.chunks(B)).zip(out.chunks_mut(B)) {
        let n = xb.len();
        for i in 0..n {
            // Clamped into the window (NaN goes to 0): replicate border, every read in bounds.
            let x = ((xb[i] - ox) * inv).max(0.0).min(wm);
            let y = ((yb[i] - oy) * inv).max(0.0).min(hm);
            let fx = x.floor().min(wm2);
            let fy = y.floor().min(hm2);
            ax[i] = x - fx;
            ay[i] = y - fy;
            idx[i] = fy as u32 * w as u32 + fx as u32;
        }
        for i in 0..n {
            let k = idx[i] as usize;
            let d = &img.data[k..k + w + 2];
            let (p00, p10, p01, p11) = (d[0], d[1], d[w], d[w + 1]);
            let top = p00 + ax[i] * (p10 - p00);
            let bot = p01 + ax[i] * (p11 - p01);
            ob[i] = top + ay[i] * (bot - top);
        }
    }
}

/// Rows this long or longer that cross the border are sampled pixel by pixel.
const PADDED: usize = 64;

/// Samples the `cols x rows` grid of points `(x0 + i, y0 + j)` of `img` into `out` (row by
/// row), the border replicated as [`sample_values`] does. Every point shares the fractional
/// part of `(x0, y0)`, so the bilinear weights are the same for all and each row is a weighted
/// sum of two image rows (vectorised where the row is inside the image). Returns `false`,
/// writing nothing, when a coordinate is not finite or the image is smaller than 2 x 2.
pub fn sample_grid_shifted(
    img: &super::GrayF32,
    x0: f32,
    y0: f32,
    cols: usize,
    rows: usize,
    out: &mut [f32],
) -> bool {
    let (w, h) = (img.width, img.height);
    if !(x0.is_finite() && y0.is_finite()) || out.len() < cols * rows || w < 2 || h < 2 {
        return false;
    }
    // Far outside, every read is the border's: keep the integers exact.
    let x0 = x0.clamp(-(cols as f32) - 2.0, w as f32 + 2.0);
    let y0 = y0.clamp(-(rows as f32) - 2.0, h as f32 + 2.0);
    let (fx, fy) = (x0.floor(), y0.floor());
    let (ix, iy) = (fx as i64, fy as i64);
    let (ax, ay) = (x0 - fx, y0 - fy);
    let (w00, w10, w01, w11) = (
        (1.0 - ax) * (1.0 - ay),
        ax * (1.0 - ay),
        (1.0 - ax) * ay,
        ax * ay,
    );
    let row_of = |y: i64| y.clamp(0, h as i64 - 1) as usize * w;
    let inside_x = ix >= 0 && ix + (cols as i64) < w as i64;
    if inside_x
        && cols.is_multiple_of(8)
        && cols <= PADDED
        && iy >= 0
        && iy + (rows as i64) < h as i64
    {
        // Whole rows of eight inside: each image row weighed across once (`h`), each output
        // row the vertical blend of two of them, in lanes of eight.
        let (ix, iy) = (ix as usize, iy as usize);
        #[inline(always)]
        fn across(src: &[f32], ax: f32, h: &mut [f32]) {
            let (a, b) = (&src[..h.len()], &src[1..=h.len()]);
            for ((h, a), b) in h
                .chunks_exact_mut(8)
                .zip(a.chunks_exact(8))
                .zip(b.chunks_exact(8))
            {
                for l in 0..8 {
                    h[l] = a[l] + ax * (b[l] - a[l]);
                }
            }
        }
        let row = |r: usize| &img.data[(iy + r) * w + ix..][..cols + 1];
        // Two buffers, used in turn as the upper and the lower row.
        let mut bufs = [[0f32; PADDED]; 2];
        across(row(0), ax, &mut bufs[0][..cols]);
        for (j, o) in out[..cols * rows].chunks_exact_mut(cols).enumerate() {
            let (a, b) = bufs.split_at_mut(1);
            let (up, down) = if j % 2 == 0 {
                (&a[0], &mut b[0])
            } else {
                (&b[0], &mut a[0])
            };
            across(row(j + 1), ax, &mut down[..cols]);
            for ((o, u), d) in o
                .chunks_exact_mut(8)
                .zip(up[..cols].chunks_exact(8))
                .zip(down[..cols].chunks_exact(8))
            {
                for l in 0..8 {
                    o[l] = u[l] + ay * (d[l] - u[l]);
                }
            }
        }
        return true;
    }
    let col = |x: i64| x.clamp(0, w as i64 - 1) as usize;
    for (j, o) in out[..cols * rows].chunks_exact_mut(cols).enumerate() {
        let (r0, r1) = (row_of(iy + j as i64), row_of(iy + j as i64 + 1));
        if inside_x {
            let ix = ix as usize;
            let top = &img.data[r0 + ix..][..cols + 1];
            let bot = &img.data[r1 + ix..][..cols + 1];
            let (t0, t1, b0, b1) = (&top[..cols], &top[1..], &bot[..cols], &bot[1..]);
            for i in 0..cols {
                o[i] = w00 * t0[i] + w10 * t1[i] + w01 * b0[i] + w11 * b1[i];
            }
        } else if cols < PADDED {
            // The two rows' pixels, border replicated, copied out; then the same weighted sum.
            let (mut top, mut bot) = ([0f32; PADDED], [0f32; PADDED]);
            for i in 0..=cols {
                let c = col(ix + i as i64);
                top[i] = img.data[r0 + c];
                bot[i] = img.data[r1 + c];
            }
            let (t0, t1, b0, b1) = (&top[..cols], &top[1..=cols], &bot[..cols], &bot[1..=cols]);
            for i in 0..cols {
                o[i] = w00 * t0[i] + w10 * t1[i] + w01 * b0[i] + w11 * b1[i];
            }
        } else {
            for (i, v) in o.iter_mut().enumerate() {
                let (c0, c1) = (col(ix + i as i64), col(ix + i as i64 + 1));
                let d = &img.data;
                *v = w00 * d[r0 + c0] + w10 * d[r0 + c1] + w01 * d[r1 + c0] + w11 * d[r1 + c1];
            }
        }
    }
    true
}

/// Samples values and gradients (in frame pixels) at frame points `(xs[i], ys[i])`; on a view
/// of several planes, part by part as [`sample_values`].
pub fn sample_values_gradients(
    img: &ImageView,
    xs: &[f32],
    ys: &[f32],
    values: &mut [f32],
    gx: &mut [f32],
    gy: &mut [f32],
) {
    debug_assert!(xs.len() == ys.len() && values.len() == xs.len());
    debug_assert!(gx.len() == xs.len() && gy.len() == xs.len());
    if img.planes > 1 {
        let n = xs.len() / img.planes();
        debug_assert_eq!(n * img.planes(), xs.len(), "a colour grid of equal parts");
        for c in 0..img.planes() {
            let r = c * n..(c + 1) * n;
            sample_values_gradients(
                &img.plane(c),
                &xs[r.clone()],
                &ys[r.clone()],
                &mut values[r.clone()],
                &mut gx[r.clone()],
                &mut gy[r],
            );
        }
        return;
    }
    if img.is_empty() {
        values.fill(0.0);
        gx.fill(0.0);
        gy.fill(0.0);
        return;
    }
    if img.width < 4 || img.height < 4 {
        for o in 0..xs.len() {
            (values[o], gx[o], gy[o]) = img.value_gradient_general(xs[o], ys[o]);
        }
        return;
    }
    // Whole groups of eight points with AVX2, the rest below.
    #[cfg(simd = "avx2")]
    let done = avx2::values_gradients(img, xs, ys, values, gx, gy);
    #[cfg(not(simd = "avx2"))]
    let done = 0;
    let (xs, ys) = (&xs[done..], &ys[done..]);
    let out = (&mut values[done..], &mut gx[done..], &mut gy[done..]);
    // As in `sample_values`: short scratch arrays for the vector path's few left.
    if xs.len() <= 8 {
        values_gradients_rest::<8>(img, xs, ys, out);
    } else {
        values_gradients_rest::<BLOCK>(img, xs, ys, out);
    }
}

/// [`sample_values_gradients`]'s scalar loop over `xs`, blocks of `B` points at a time.
fn values_gradients_rest<const B: usize>(
    img: &ImageView,
    xs: &[f32],
    ys: &[f32],
    (values, gx, gy): (&mut [f32], &mut [f32], &mut [f32]),
) {
    let w = img.width;
    let (ox, oy, inv) = (img.x0 as f32, img.y0 as f32, 1.0 / img.scale);
    // The fast path needs the 4x4 neighbourhood inside: 1 <= x < w - 2, 1 <= y < h - 2.
    let (xmax, ymax) = (img.width as f32 - 2.0, img.height as f32 - 2.0);
    let mut idx = [0u32; B];
    let mut ax = [0f32; B];
    let mut ay = [0f32; B];
    let mut inside = [false; B];
    let mut start = 0;
    while start < xs.len() {
        let n = (xs.len() - start).min(B);
        for i in 0..n {
            let (x, y) = ((xs[start + i] - ox) * inv, (ys[start + i] - oy) * inv);
            inside[i] = x >= 1.0 && y >= 1.0 && x < xmax && y < ymax;
            let xc = x.max(1.0).min(xmax);
            let yc = y.max(1.0).min(ymax);
            let (fx, fy) = (xc.floor(), yc.floor());
            ax[i] = xc - fx;
            ay[i] = yc - fy;
            idx[i] = (fy as u32 - 1) * w as u32 + (fx as u32 - 1);
        }
        for i in 0..n {
            let o = start + i;
            let (v, dx, dy) = if inside[i] {
                let base = idx[i] as usize;
                let d = &img.data[base..base + 3 * w + 4];
                let (ax, ay) = (ax[i], ay[i]);
                let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
                let h = |r: usize, c: usize| lerp(d[r * w + c], d[r * w + c + 1], ax);
                let v = lerp(h(1, 1), h(2, 1), ay);
                let right = lerp(h(1, 2), h(2, 2), ay);
                let left = lerp(h(1, 0), h(2, 0), ay);
                let down = lerp(h(2, 1), h(3, 1), ay);
                let up = lerp(h(0, 1), h(1, 1), ay);
                (v, 0.5 * inv * (right - left), 0.5 * inv * (down - up))
            } else {
                img.value_gradient_general(xs[o], ys[o])
            };
            values[o] = v;
            gx[o] = dx;
            gy[o] = dy;
        }
        start += n;
    }
}

/// AVX2 versions of the sampling loops: eight points at a time, the pixels of each point read
/// with short loads of neighbouring pixels and transposed (gathers are several times slower on
/// CPUs with the gather-data-sampling mitigation).
#[cfg(simd = "avx2")]
mod avx2 {
    use super::ImageView;
    use std::arch::x86_64::*;

    /// Two neighbouring pixels of four points, one point per 64-bit lane: `[a, b, c, d]`,
    /// written as four 8-byte broadcasts and three blends (the compiler lowers them to 8-byte
    /// loads and inserts, fewer shuffles than a transposition of pairs).
    ///
    /// # Safety
    /// `a`, `b`, `c` and `d` must each point to two readable `f32`.
    #[inline(always)]
    unsafe fn pairs4(a: *const f32, b: *const f32, c: *const f32, d: *const f32) -> __m256d {
        // SAFETY: the caller's contract; unaligned 8-byte reads.
        unsafe {
            let bc = |p: *const f32| _mm256_set1_pd(std::ptr::read_unaligned(p as *const f64));
            _mm256_blend_pd::<0b1100>(
                _mm256_blend_pd::<0b0010>(bc(a), bc(b)),
                _mm256_blend_pd::<0b1000>(bc(c), bc(d)),
            )
        }
    }

    /// The pairs `(p[0], p[1])` of eight points `p` as two vectors of eight points: the first
    /// pixels and the second ones.
    ///
    /// # Safety
    /// Each `p[k]` must point to two readable `f32`.
    #[inline(always)]
    unsafe fn pairs8(p: [*const f32; 8]) -> (__m256, __m256) {
        // SAFETY: the caller's contract.
        unsafe {
            // [a0 b0 a1 b1 | a4 b4 a5 b5] and [a2 b2 a3 b3 | a6 b6 a7 b7].
            let x = _mm256_castpd_ps(pairs4(p[0], p[1], p[4], p[5]));
            let y = _mm256_castpd_ps(pairs4(p[2], p[3], p[6], p[7]));
            (
                _mm256_shuffle_ps::<0b10_00_10_00>(x, y),
                _mm256_shuffle_ps::<0b11_01_11_01>(x, y),
            )
        }
    }

    /// Four neighbouring pixels of eight points `p` as four vectors of eight points (one per
    /// pixel): points `k` and `k + 4` share a 256-bit load, then an in-lane transpose.
    ///
    /// # Safety
    /// Each `p[k]` must point to four readable `f32`.
    #[inline(always)]
    unsafe fn quads8(p: [*const f32; 8]) -> [__m256; 4] {
        // SAFETY: the caller's contract; unaligned 16-byte loads.
        unsafe {
            let q = |k: usize| _mm256_loadu2_m128(p[k + 4], p[k]);
            let (q0, q1, q2, q3) = (q(0), q(1), q(2), q(3));
            let (t0, t1) = (_mm256_unpacklo_ps(q0, q1), _mm256_unpackhi_ps(q0, q1));
            let (t2, t3) = (_mm256_unpacklo_ps(q2, q3), _mm256_unpackhi_ps(q2, q3));
            let pd = _mm256_castps_pd;
            [
                _mm256_castpd_ps(_mm256_unpacklo_pd(pd(t0), pd(t2))),
                _mm256_castpd_ps(_mm256_unpackhi_pd(pd(t0), pd(t2))),
                _mm256_castpd_ps(_mm256_unpacklo_pd(pd(t1), pd(t3))),
                _mm256_castpd_ps(_mm256_unpackhi_pd(pd(t1), pd(t3))),
            ]
        }
    }

    /// The row-major indices `fy w + fx` of whole coordinates: one f32 multiply-add where
    /// `exact` (an image of at most 2^24 pixels, where every product and sum is exact), else in
    /// integers.
    #[inline(always)]
    fn index(fx: __m256, fy: __m256, w: usize, exact: bool) -> __m256i {
        // SAFETY: AVX2 is enabled at compile time (the module's cfg), FMA with it as for the
        // module's interpolation; no memory is touched.
        unsafe {
            if exact {
                _mm256_cvttps_epi32(_mm256_fmadd_ps(fy, _mm256_set1_ps(w as f32), fx))
            } else {
                _mm256_add_epi32(
                    _mm256_mullo_epi32(_mm256_cvttps_epi32(fy), _mm256_set1_epi32(w as i32)),
                    _mm256_cvttps_epi32(fx),
                )
            }
        }
    }

    /// Bilinear values (border replicated) of the first `8 * (len / 8)` points; returns how many
    /// were done. The view is at least 2x2 and uses [`super::Border::Replicate`].
    // Inlined into its one caller (across codegen units too: the layout of the crate's modules
    // otherwise decides whether it is, and a call costs the sampler a tenth of its time).
    #[inline]
    pub(super) fn values(img: &ImageView, xs: &[f32], ys: &[f32], out: &mut [f32]) -> usize {
        let n = xs.len().min(ys.len()).min(out.len()) / 8 * 8;
        let (w, h) = (img.width, img.height);
        // Every index below is at most (h - 2) w + (w - 2) and reads up to index + w + 1, so
        // inside `data` as long as it holds the window and the window fits i32 indices.
        if w < 2 || h < 2 || img.data.len() < w * h || w * h >= i32::MAX as usize {
            return 0;
        }
        // SAFETY: AVX2 is enabled at compile time (cfg above); the loads and stores stay within
        // `xs`, `ys` and `out` (i + 8 <= n) and the run's arrays (k + 8 <= len <= RUN, n and so
        // len a multiple of 8); the loads read `data` at the clamped indices bounded as
        // explained above.
        unsafe {
            let (ox, oy) = (_mm256_set1_ps(img.x0 as f32), _mm256_set1_ps(img.y0 as f32));
            let inv = _mm256_set1_ps(1.0 / img.scale);
            let zero = _mm256_setzero_ps();
            let (wm, hm) = (
                _mm256_set1_ps((w - 1) as f32),
                _mm256_set1_ps((h - 1) as f32),
            );
            let (wm2, hm2) = (
                _mm256_set1_ps((w - 2) as f32),
                _mm256_set1_ps((h - 2) as f32),
            );
            let exact = w * h <= 1 << 24;
            let base = img.data.as_ptr();
            // The row below (`w` is at least 2 and `data` holds `w h` pixels).
            let below = base.add(w);
            // A run of points at a time: their indices and fractions in one pass (vector
            // arithmetic), then their pixels in a second, each index a plain scalar load (an
            // index taken from a vector register costs more than its load).
            const RUN: usize = 64;
            let mut at = [0i32; RUN];
            let mut fx_run = [0f32; RUN];
            let mut fy_run = [0f32; RUN];
            let mut start = 0;
            while start < n {
                let len = (n - start).min(RUN);
                let mut k = 0;
                while k < len {
                    let i = start + k;
                    // max(NaN, 0) is 0: a NaN coordinate reads the first pixel.
                    let x = _mm256_min_ps(
                        _mm256_max_ps(
                            _mm256_mul_ps(
                                _mm256_sub_ps(_mm256_loadu_ps(xs.as_ptr().add(i)), ox),
                                inv,
                            ),
                            zero,
                        ),
                        wm,
                    );
                    let y = _mm256_min_ps(
                        _mm256_max_ps(
                            _mm256_mul_ps(
                                _mm256_sub_ps(_mm256_loadu_ps(ys.as_ptr().add(i)), oy),
                                inv,
                            ),
                            zero,
                        ),
                        hm,
                    );
                    let fx = _mm256_min_ps(_mm256_floor_ps(x), wm2);
                    let fy = _mm256_min_ps(_mm256_floor_ps(y), hm2);
                    _mm256_storeu_ps(fx_run.as_mut_ptr().add(k), _mm256_sub_ps(x, fx));
                    _mm256_storeu_ps(fy_run.as_mut_ptr().add(k), _mm256_sub_ps(y, fy));
                    let idx = index(fx, fy, w, exact);
                    _mm256_storeu_si256(at.as_mut_ptr().add(k) as *mut __m256i, idx);
                    k += 8;
                }
                let mut k = 0;
                while k < len {
                    // Each point's two pixel pairs, (p00, p10) and (p01, p11), are two 8-byte
                    // loads (cheaper than four gathers, which microcode mitigations make
                    // slow), blended and shuffled into one vector per corner.
                    let (p00, p10) = pairs8(std::array::from_fn(|l| base.add(at[k + l] as usize)));
                    let (p01, p11) = pairs8(std::array::from_fn(|l| below.add(at[k + l] as usize)));
                    let ax = _mm256_loadu_ps(fx_run.as_ptr().add(k));
                    let ay = _mm256_loadu_ps(fy_run.as_ptr().add(k));
                    let top = _mm256_fmadd_ps(ax, _mm256_sub_ps(p10, p00), p00);
                    let bot = _mm256_fmadd_ps(ax, _mm256_sub_ps(p11, p01), p01);
                    let v = _mm256_fmadd_ps(ay, _mm256_sub_ps(bot, top), top);
                    _mm256_storeu_ps(out.as_mut_ptr().add(start + k), v);
                    k += 8;
                }
                start += len;
            }
        }
        n
    }

    /// Values and gradients of the first `8 * (len / 8)` points; returns how many were done.
    /// A group of eight with a point near the window's edge is done by the general path.
    #[inline]
    pub(super) fn values_gradients(
        img: &ImageView,
        xs: &[f32],
        ys: &[f32],
        values: &mut [f32],
        gx: &mut [f32],
        gy: &mut [f32],
    ) -> usize {
        let n = xs
            .len()
            .min(ys.len())
            .min(values.len())
            .min(gx.len())
            .min(gy.len())
            / 8
            * 8;
        let (w, h) = (img.width, img.height);
        // Inside points have 1 <= x < w - 2 and 1 <= y < h - 2: the 4x4 neighbourhood from
        // index (y - 1) w + x - 1 to (y + 2) w + x + 2 < w h lies in `data`.
        if w < 4 || h < 4 || img.data.len() < w * h || w * h >= i32::MAX as usize {
            return 0;
        }
        // SAFETY: AVX2 is enabled at compile time; loads and stores stay within the slices
        // (i + 8 <= n) and the run's arrays (k + 8 <= len <= RUN, n and so len a multiple of
        // 8); a group is read only when all its points are inside, so every index read is
        // within `data` as explained above.
        unsafe {
            let (ox, oy) = (_mm256_set1_ps(img.x0 as f32), _mm256_set1_ps(img.y0 as f32));
            let inv = _mm256_set1_ps(1.0 / img.scale);
            let one = _mm256_set1_ps(1.0);
            let half = _mm256_set1_ps(0.5 / img.scale);
            let (xmax, ymax) = (
                _mm256_set1_ps(w as f32 - 2.0),
                _mm256_set1_ps(h as f32 - 2.0),
            );
            // Indices of points outside may be negative, and are not read.
            let exact = w * h <= 1 << 24;
            let base = img.data.as_ptr();
            // Where the neighbourhood's rows are read, from its corner (inside `data`: h >= 4).
            let (row0, row1, row2, row3) = (
                base.add(1),
                base.add(w),
                base.add(2 * w),
                base.add(3 * w + 1),
            );
            // A run of points at a time: their indices, fractions and whether each group of
            // eight is inside in one pass, their pixels in a second (as in `values`).
            const RUN: usize = 64;
            let mut at = [0i32; RUN];
            let mut ax_run = [0f32; RUN];
            let mut ay_run = [0f32; RUN];
            let mut inside_run = [false; RUN / 8];
            let mut start = 0;
            while start < n {
                let len = (n - start).min(RUN);
                let mut k = 0;
                while k < len {
                    let i = start + k;
                    let x =
                        _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(xs.as_ptr().add(i)), ox), inv);
                    let y =
                        _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(ys.as_ptr().add(i)), oy), inv);
                    let inside = _mm256_and_ps(
                        _mm256_and_ps(
                            _mm256_cmp_ps::<_CMP_GE_OQ>(x, one),
                            _mm256_cmp_ps::<_CMP_GE_OQ>(y, one),
                        ),
                        _mm256_and_ps(
                            _mm256_cmp_ps::<_CMP_LT_OQ>(x, xmax),
                            _mm256_cmp_ps::<_CMP_LT_OQ>(y, ymax),
                        ),
                    );
                    inside_run[k / 8] = _mm256_movemask_ps(inside) == 0xFF;
                    let (fx, fy) = (_mm256_floor_ps(x), _mm256_floor_ps(y));
                    _mm256_storeu_ps(ax_run.as_mut_ptr().add(k), _mm256_sub_ps(x, fx));
                    _mm256_storeu_ps(ay_run.as_mut_ptr().add(k), _mm256_sub_ps(y, fy));
                    // Indices of points outside are not read (their group takes the general
                    // path).
                    let (fy1, fx1) = (_mm256_sub_ps(fy, one), _mm256_sub_ps(fx, one));
                    let idx = index(fx1, fy1, w, exact);
                    _mm256_storeu_si256(at.as_mut_ptr().add(k) as *mut __m256i, idx);
                    k += 8;
                }
                let mut k = 0;
                while k < len {
                    let i = start + k;
                    if !inside_run[k / 8] {
                        for o in i..i + 8 {
                            (values[o], gx[o], gy[o]) = img.value_gradient_general(xs[o], ys[o]);
                        }
                        k += 8;
                        continue;
                    }
                    let (ax, ay) = (
                        _mm256_loadu_ps(ax_run.as_ptr().add(k)),
                        _mm256_loadu_ps(ay_run.as_ptr().add(k)),
                    );
                    let at = |row: *const f32| -> [*const f32; 8] {
                        std::array::from_fn(|l| row.add(at[k + l] as usize))
                    };
                    // Rows 1 and 2 of each point's 4x4 neighbourhood, columns 0 to 3, and rows 0
                    // and 3, columns 1 and 2: loads of neighbouring pixels, transposed into one
                    // vector per pixel of the cross.
                    let r1 = quads8(at(row1));
                    let r2 = quads8(at(row2));
                    let (r00, r01) = pairs8(at(row0));
                    let (r30, r31) = pairs8(at(row3));
                    let r03 = [r00, r01, r30, r31];
                    let lerp = |a: __m256, b: __m256, t: __m256| {
                        _mm256_fmadd_ps(t, _mm256_sub_ps(b, a), a)
                    };
                    let (h10, h11, h12) = (
                        lerp(r1[0], r1[1], ax),
                        lerp(r1[1], r1[2], ax),
                        lerp(r1[2], r1[3], ax),
                    );
                    let (h20, h21, h22) = (
                        lerp(r2[0], r2[1], ax),
                        lerp(r2[1], r2[2], ax),
                        lerp(r2[2], r2[3], ax),
                    );
                    let (h01, h31) = (lerp(r03[0], r03[1], ax), lerp(r03[2], r03[3], ax));
                    let v = lerp(h11, h21, ay);
                    let right = lerp(h12, h22, ay);
                    let left = lerp(h10, h20, ay);
                    let down = lerp(h21, h31, ay);
                    let up = lerp(h01, h11, ay);
                    _mm256_storeu_ps(values.as_mut_ptr().add(i), v);
                    _mm256_storeu_ps(
                        gx.as_mut_ptr().add(i),
                        _mm256_mul_ps(half, _mm256_sub_ps(right, left)),
                    );
                    _mm256_storeu_ps(
                        gy.as_mut_ptr().add(i),
                        _mm256_mul_ps(half, _mm256_sub_ps(down, up)),
                    );
                    k += 8;
                }
                start += len;
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A view of three planes samples a grid of three equal parts, part `c` from plane `c`
    /// (values and gradients, the same bits as each plane alone); `plane` gives each alone.
    #[test]
    fn a_colour_view_samples_each_part_from_its_plane() {
        let (w, h) = (31, 23);
        let plane = |k: usize| -> Vec<f32> {
            (0..w * h)
                .map(|i| ((i * (7 + 4 * k)) % 97) as f32 + 0.5 * k as f32)
                .collect()
        };
        let (r, g, b) = (plane(0), plane(1), plane(2));
        let view = ImageView::new(&r, w, h, 5, -3)
            .with_planes(&g, &b)
            .with_stamp(9);
        assert_eq!(view.planes(), 3);
        assert_eq!(view.plane(2).planes(), 1);
        assert_eq!(view.plane(1).stamp(), 9);
        let n = 37;
        let xs: Vec<f32> = (0..n).map(|i| 4.0 + (i as f32 * 0.77) % 30.0).collect();
        let ys: Vec<f32> = (0..n).map(|i| -4.0 + (i as f32 * 1.31) % 22.0).collect();
        let (x3, y3) = (xs.repeat(3), ys.repeat(3));
        let mut all = vec![0f32; 3 * n];
        let (mut v, mut gx, mut gy) = (vec![0f32; 3 * n], vec![0f32; 3 * n], vec![0f32; 3 * n]);
        sample_values(&view, &x3, &y3, &mut all);
        sample_values_gradients(&view, &x3, &y3, &mut v, &mut gx, &mut gy);
        for (c, data) in [&r, &g, &b].into_iter().enumerate() {
            let alone = ImageView::new(data, w, h, 5, -3);
            let mut one = vec![0f32; n];
            let (mut ov, mut ogx, mut ogy) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
            sample_values(&alone, &xs, &ys, &mut one);
            sample_values_gradients(&alone, &xs, &ys, &mut ov, &mut ogx, &mut ogy);
            let part = c * n..(c + 1) * n;
            assert_eq!(&all[part.clone()], &one[..], "plane {c}");
            assert_eq!(&v[part.clone()], &ov[..]);
            assert_eq!(&gx[part.clone()], &ogx[..]);
            assert_eq!(&gy[part], &ogy[..]);
            let mut via = vec![0f32; n];
            sample_values(&view.plane(c), &xs, &ys, &mut via);
            assert_eq!(via, one);
        }
    }

    /// The shifted grid reads what point-by-point sampling reads, inside the image and across
    /// its borders.
    #[test]
    fn a_shifted_grid_samples_as_points_do() {
        let mut img = crate::imaging::GrayF32::new(23, 17);
        for (k, v) in img.data.iter_mut().enumerate() {
            *v = ((k * 37) % 101) as f32 + 0.25 * (k % 7) as f32;
        }
        for &(x0, y0) in &[
            (3.3f32, 4.6f32),
            (-2.7, 5.2),
            (15.4, 11.9),
            (-30.0, -30.0),
            (0.0, 0.0),
        ] {
            for (c, r) in [(9, 7), (16, 7), (8, 3)] {
                let mut fast = vec![0f32; c * r];
                assert!(sample_grid_shifted(&img, x0, y0, c, r, &mut fast));
                let xs: Vec<f32> = (0..c * r).map(|k| x0 + (k % c) as f32).collect();
                let ys: Vec<f32> = (0..c * r).map(|k| y0 + (k / c) as f32).collect();
                let mut slow = vec![0f32; c * r];
                sample_values(&img.view(), &xs, &ys, &mut slow);
                for (a, b) in fast.iter().zip(&slow) {
                    assert!((a - b).abs() < 1e-3, "at ({x0}, {y0}): {a} vs {b}");
                }
            }
        }
        assert!(!sample_grid_shifted(
            &img,
            f32::NAN,
            0.0,
            3,
            3,
            &mut [0.0; 9]
        ));
    }
    use crate::rng::Rng;

    /// The reference: bilinear interpolation and central differences written the plain way.
    fn reference(data: &[f32], w: usize, h: usize, x: f32, y: f32) -> (f32, f32, f32) {
        let px = |ix: i64, iy: i64| {
            data[iy.clamp(0, h as i64 - 1) as usize * w + ix.clamp(0, w as i64 - 1) as usize]
        };
        let bil = |x: f32, y: f32| {
            let x = x.clamp(-4.0, w as f32 + 4.0);
            let y = y.clamp(-4.0, h as f32 + 4.0);
            let (fx, fy) = (x.floor(), y.floor());
            let (ix, iy) = (fx as i64, fy as i64);
            let (ax, ay) = (x - fx, y - fy);
            let top = px(ix, iy) * (1.0 - ax) + px(ix + 1, iy) * ax;
            let bot = px(ix, iy + 1) * (1.0 - ax) + px(ix + 1, iy + 1) * ax;
            top * (1.0 - ay) + bot * ay
        };
        (
            bil(x, y),
            0.5 * (bil(x + 1.0, y) - bil(x - 1.0, y)),
            0.5 * (bil(x, y + 1.0) - bil(x, y - 1.0)),
        )
    }

    /// Both samplers (and the one-point sampler) at `xs`, `ys` against the reference at the
    /// window's coordinates `((x - 5) / scale, (y - 7) / scale)` of a view at (5, 7) with that
    /// scale; gradients per frame pixel.
    fn check_against_reference(view: &ImageView, data: &[f32], xs: &[f32], ys: &[f32], what: &str) {
        let n = xs.len();
        let (mut v, mut v2) = (vec![0f32; n], vec![0f32; n]);
        let (mut gx, mut gy) = (vec![0f32; n], vec![0f32; n]);
        sample_values(view, xs, ys, &mut v);
        sample_values_gradients(view, xs, ys, &mut v2, &mut gx, &mut gy);
        let s = view.scale;
        for i in 0..n {
            let (x, y) = ((xs[i] - 5.0) / s, (ys[i] - 7.0) / s);
            let (rv, rgx, rgy) = reference(data, view.width, view.height, x, y);
            let at = format!("{what} {i} at ({}, {})", xs[i], ys[i]);
            assert!((v[i] - rv).abs() < 1e-3, "{at}: value {} vs {rv}", v[i]);
            assert!(
                (v2[i] - rv).abs() < 1e-3,
                "{at}: value+grad {} vs {rv}",
                v2[i]
            );
            assert!(
                (gx[i] - rgx / s).abs() < 1e-3 && (gy[i] - rgy / s).abs() < 1e-3,
                "{at}: gradient"
            );
            assert!(
                (sample_value(view, xs[i], ys[i]) - rv).abs() < 1e-3,
                "{at}: one point"
            );
        }
    }

    /// Beyond 2^24 pixels an index is not exact in f32: the vector paths then compute it in
    /// integers, and the last rows of such an image read the right pixels.
    #[test]
    fn sampling_a_frame_of_more_than_2_24_pixels_reads_the_right_pixels() {
        let (w, h) = (4100usize, 4097usize);
        assert!(w * h > 1 << 24);
        // Neighbouring pixels differ (a hash of the index), so a wrong index shows.
        let data: Vec<f32> = (0..w * h)
            .map(|i| ((i as u64).wrapping_mul(2_654_435_761) >> 13) as f32 % 251.0)
            .collect();
        let view = ImageView::new(&data, w, h, 5, 7);
        let mut rng = Rng::new(23);
        // Rows 4093 and 4094, whose indices are past 2^24 (odd ones have no f32), and the
        // first rows.
        let n = 203;
        let xs: Vec<f32> = (0..n).map(|_| rng.range(6.0, 4000.0) as f32).collect();
        let ys: Vec<f32> = (0..n)
            .map(|i| match i % 4 {
                0 => rng.range(8.0, 20.0) as f32,
                _ => rng.range(7.0 + 4093.0, 7.0 + 4094.0) as f32,
            })
            .collect();
        check_against_reference(&view, &data, &xs, &ys, "large frame point");
    }

    #[test]
    fn sampling_matches_the_reference_inside_at_the_border_and_outside() {
        let mut rng = Rng::new(17);
        let (w, h) = (37usize, 23usize);
        let data: Vec<f32> = (0..w * h).map(|_| rng.range(0.0, 255.0) as f32).collect();
        // The view sits at (5, 7) in the frame.
        let view = ImageView::new(&data, w, h, 5, 7);
        let n = 1001;
        let xs: Vec<f32> = (0..n).map(|_| rng.range(0.0, 50.0) as f32).collect();
        let ys: Vec<f32> = (0..n).map(|_| rng.range(0.0, 38.0) as f32).collect();
        check_against_reference(&view, &data, &xs, &ys, "point");
        // A pyramid level: window pixel i at frame coordinate 5 + 2 i.
        check_against_reference(&view.with_scale(2.0), &data, &xs, &ys, "level point");
        // Runs of points mostly inside (the vector paths' case), longer than a run of the
        // vector loops and not a whole number of groups, every fifth group of eight with one
        // point outside.
        let xs: Vec<f32> = (0..203)
            .map(|i| match i % 40 {
                3 => 2.0,
                _ => rng.range(6.0, 5.0 + w as f64 - 3.0) as f32,
            })
            .collect();
        let ys: Vec<f32> = (0..203)
            .map(|_| rng.range(8.0, 7.0 + h as f64 - 3.0) as f32)
            .collect();
        check_against_reference(&view, &data, &xs, &ys, "run point");
        let mut v = [0f32; 9];
        // NaN coordinates read finite values; a zero border reads 0 far outside.
        let nan = [f32::NAN; 9];
        sample_values(&view, &nan, &nan, &mut v[..9]);
        assert!(v[..9].iter().all(|x| x.is_finite()));
        let zero = view.with_border(Border::Zero);
        assert_eq!(sample_value(&zero, -100.0, -100.0), 0.0);
    }
}
