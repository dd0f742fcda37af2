//! One frame pre-processed once for every patch: the smoothing and the Gaussian pyramid, padded
//! so that the hot loop never clamps, built in bands of rows by the threads.

use super::*;
use crate::crew::{Crew, Shares};
use crate::imaging::{self, GaussianKernel, GrayF32, ImageRef};

/// One frame, pre-processed once for every patch: the smoothed frame's pyramid.
#[derive(Clone, Debug, Default)]
pub(super) struct Frame {
    pub(super) levels: Vec<GrayF32>,
    /// The levels with a replicated border of [`Frame::border`] pixels: a patch whose centre is
    /// in the frame reads only inside these.
    pub(super) padded: Vec<GrayF32>,
    pub(super) border: usize,
}

impl Frame {
    /// Level `l`, padded, and its border.
    pub(super) fn level(&self, l: usize) -> (&GrayF32, usize) {
        (&self.padded[l], self.border)
    }
}

/// Bands of rows a level is split into, at most (for the threads building a frame).
pub(super) const MAX_BANDS: usize = 16;

/// One band of a level's rows being built: its rows, their pixels and the padded level's rows
/// that copy them (with the top or bottom border when the band has the first or last row).
pub(super) struct Band<'a> {
    pub(super) rows: std::ops::Range<usize>,
    pub(super) out: &'a mut [f32],
    pub(super) pad: &'a mut [f32],
    /// The padded level's first row in `pad`.
    pub(super) pad_from: usize,
}

impl Frame {
    /// The smoothed frame's pyramid of at most `levels` levels and their padded copies. Each
    /// level is split into bands of rows that the crew's threads take as they are free; the
    /// result is the same for any number of threads.
    pub(super) fn build(
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
