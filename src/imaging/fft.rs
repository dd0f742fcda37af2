//! Discrete Fourier transforms of images (rustfft) for the correlation-filter trackers: 2-D
//! transforms of `w x h` row-major buffers and batches of 1-D transforms, with the plans made
//! once.

use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// A complex number of two `f32`.
pub type C32 = Complex32;

/// Forward and inverse 2-D transforms of one size. The inverse is normalised (`1 / (w h)`), so
/// `inverse(forward(x)) == x`.
pub struct Fft2 {
    w: usize,
    h: usize,
    row_f: Arc<dyn Fft<f32>>,
    row_i: Arc<dyn Fft<f32>>,
    col_f: Arc<dyn Fft<f32>>,
    col_i: Arc<dyn Fft<f32>>,
    t: Vec<C32>,
    scratch: Vec<C32>,
}

impl std::fmt::Debug for Fft2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Fft2({}x{})", self.w, self.h)
    }
}

impl Fft2 {
    /// Plans for `w x h` buffers (`w, h >= 1`).
    pub fn new(w: usize, h: usize) -> Self {
        let mut p = FftPlanner::new();
        let (row_f, row_i) = (p.plan_fft_forward(w), p.plan_fft_inverse(w));
        let (col_f, col_i) = (p.plan_fft_forward(h), p.plan_fft_inverse(h));
        let len = [&row_f, &row_i, &col_f, &col_i]
            .iter()
            .map(|f| f.get_inplace_scratch_len())
            .max()
            .unwrap_or(0);
        Fft2 {
            w,
            h,
            row_f,
            row_i,
            col_f,
            col_i,
            t: vec![C32::default(); w * h],
            scratch: vec![C32::default(); len],
        }
    }

    /// `(w, h)`.
    pub fn size(&self) -> (usize, usize) {
        (self.w, self.h)
    }

    /// In-place forward transform of a `w x h` buffer.
    pub fn forward(&mut self, data: &mut [C32]) {
        let (rf, cf) = (self.row_f.clone(), self.col_f.clone());
        self.apply(data, &*rf, &*cf);
    }

    /// In-place normalised inverse transform.
    pub fn inverse(&mut self, data: &mut [C32]) {
        let (ri, ci) = (self.row_i.clone(), self.col_i.clone());
        self.apply(data, &*ri, &*ci);
        let k = 1.0 / (self.w * self.h) as f32;
        for v in data.iter_mut() {
            *v *= k;
        }
    }

    /// The forward transform of a real buffer into `out` (resized to `w h`).
    pub fn forward_real(&mut self, src: &[f32], out: &mut Vec<C32>) {
        out.clear();
        out.extend(src.iter().map(|&v| C32::new(v, 0.0)));
        out.resize(self.w * self.h, C32::default());
        self.forward(out);
    }

    fn apply(&mut self, data: &mut [C32], row: &dyn Fft<f32>, col: &dyn Fft<f32>) {
        let (w, h) = (self.w, self.h);
        debug_assert_eq!(data.len(), w * h);
        // Every row, then every column (as rows of the transpose).
        row.process_with_scratch(data, &mut self.scratch);
        transpose(data, &mut self.t, w, h);
        col.process_with_scratch(&mut self.t, &mut self.scratch);
        transpose(&self.t, data, h, w);
    }
}

/// `dst` (h x w) = transpose of `src` (w x h, row-major).
fn transpose(src: &[C32], dst: &mut [C32], w: usize, h: usize) {
    // In tiles of 8 x 8, so that both sides stay in the cache.
    const T: usize = 8;
    let (src, dst) = (&src[..w * h], &mut dst[..w * h]);
    for y0 in (0..h).step_by(T) {
        for x0 in (0..w).step_by(T) {
            for y in y0..(y0 + T).min(h) {
                for x in x0..(x0 + T).min(w) {
                    dst[x * h + y] = src[y * w + x];
                }
            }
        }
    }
}

/// Forward and inverse 1-D transforms of length `n`, applied to every `n`-long chunk of a buffer.
pub struct Fft1 {
    n: usize,
    f: Arc<dyn Fft<f32>>,
    i: Arc<dyn Fft<f32>>,
    scratch: Vec<C32>,
}

impl std::fmt::Debug for Fft1 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Fft1({})", self.n)
    }
}

impl Fft1 {
    /// Plans for length `n >= 1`.
    pub fn new(n: usize) -> Self {
        let mut p = FftPlanner::new();
        let (f, i) = (p.plan_fft_forward(n), p.plan_fft_inverse(n));
        let len = f.get_inplace_scratch_len().max(i.get_inplace_scratch_len());
        Fft1 {
            n,
            f,
            i,
            scratch: vec![C32::default(); len],
        }
    }

    /// In-place forward transform of each `n`-long chunk.
    pub fn forward(&mut self, data: &mut [C32]) {
        self.f.process_with_scratch(data, &mut self.scratch);
    }

    /// In-place normalised inverse transform of each chunk.
    pub fn inverse(&mut self, data: &mut [C32]) {
        self.i.process_with_scratch(data, &mut self.scratch);
        let k = 1.0 / self.n as f32;
        for v in data.iter_mut() {
            *v *= k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_2d_transform_matches_the_definition_and_inverts() {
        let (w, h) = (6, 5);
        let x: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919) % 23) as f32 - 11.0)
            .collect();
        let mut f = Fft2::new(w, h);
        let mut xf = Vec::new();
        f.forward_real(&x, &mut xf);
        for (v, u) in [(0, 0), (1, 2), (4, 3)] {
            let mut s = C32::default();
            for y in 0..h {
                for xx in 0..w {
                    let a = -2.0
                        * std::f32::consts::PI
                        * (u as f32 * xx as f32 / w as f32 + v as f32 * y as f32 / h as f32);
                    s += C32::new(a.cos(), a.sin()) * x[y * w + xx];
                }
            }
            assert!(
                (s - xf[v * w + u]).norm() < 1e-3,
                "{s} vs {}",
                xf[v * w + u]
            );
        }
        f.inverse(&mut xf);
        for (a, b) in x.iter().zip(&xf) {
            assert!((a - b.re).abs() < 1e-4 && b.im.abs() < 1e-4);
        }
    }
}
