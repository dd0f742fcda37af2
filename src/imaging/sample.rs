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

/// A read-only window of a float image placed at `(x0, y0)` in frame coordinates: points are
/// given in frame coordinates and sampled from the window.
#[derive(Clone, Copy, Debug)]
pub struct ImageView<'a> {
    data: &'a [f32],
    width: usize,
    height: usize,
    x0: i64,
    y0: i64,
    border: Border,
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
            border: Border::Replicate,
        }
    }

    /// The same view with another border policy.
    pub fn with_border(mut self, border: Border) -> Self {
        self.border = border;
        self
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
        (x - self.x0 as f32, y - self.y0 as f32)
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
pub fn sample_values(img: &ImageView, xs: &[f32], ys: &[f32], out: &mut [f32]) {
    debug_assert!(xs.len() == ys.len() && out.len() == xs.len());
    if !(img.border == Border::Replicate && img.width >= 2 && img.height >= 2) {
        for ((o, &x), &y) in out.iter_mut().zip(xs).zip(ys) {
            *o = sample_value(img, x, y);
        }
        return;
    }
    let w = img.width;
    let (ox, oy) = (img.x0 as f32, img.y0 as f32);
    let (wm, hm) = ((img.width - 1) as f32, (img.height - 1) as f32);
    let (wm2, hm2) = ((img.width - 2) as f32, (img.height - 2) as f32);
    let mut idx = [0u32; BLOCK];
    let mut ax = [0f32; BLOCK];
    let mut ay = [0f32; BLOCK];
    for ((xb, yb), ob) in xs
        .chunks(BLOCK)
        .zip(ys.chunks(BLOCK))
        .zip(out.chunks_mut(BLOCK))
    {
        let n = xb.len();
        for i in 0..n {
            // Clamped into the window (NaN goes to 0): replicate border, every read in bounds.
            let x = (xb[i] - ox).max(0.0).min(wm);
            let y = (yb[i] - oy).max(0.0).min(hm);
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

/// Samples values and gradients (in frame pixels) at frame points `(xs[i], ys[i])`.
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
    if img.is_empty() {
        values.fill(0.0);
        gx.fill(0.0);
        gy.fill(0.0);
        return;
    }
    if img.width < 4 || img.height < 4 {
        for o in 0..xs.len() {
            let (lx, ly) = img.local(xs[o], ys[o]);
            let (lx, ly) = clamp_far(lx, ly, img);
            (values[o], gx[o], gy[o]) = img.value_gradient_local(lx, ly);
        }
        return;
    }
    let w = img.width;
    let (ox, oy) = (img.x0 as f32, img.y0 as f32);
    // The fast path needs the 4x4 neighbourhood inside: 1 <= x < w - 2, 1 <= y < h - 2.
    let (xmax, ymax) = (img.width as f32 - 2.0, img.height as f32 - 2.0);
    let mut idx = [0u32; BLOCK];
    let mut ax = [0f32; BLOCK];
    let mut ay = [0f32; BLOCK];
    let mut inside = [false; BLOCK];
    let mut start = 0;
    while start < xs.len() {
        let n = (xs.len() - start).min(BLOCK);
        for i in 0..n {
            let (x, y) = (xs[start + i] - ox, ys[start + i] - oy);
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
                (v, 0.5 * (right - left), 0.5 * (down - up))
            } else {
                let (lx, ly) = img.local(xs[o], ys[o]);
                let (lx, ly) = clamp_far(lx, ly, img);
                img.value_gradient_local(lx, ly)
            };
            values[o] = v;
            gx[o] = dx;
            gy[o] = dy;
        }
        start += n;
    }
}
