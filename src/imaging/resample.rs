//! Resampling an axis-aligned window of a frame to a fixed size (the trackers that work on
//! boxes: correlation filters, their scale pyramids, the detectors' normalised patches).

use super::GrayF32;
use crate::crew::{Crew, Shares};

/// Fills `out` (`out_w x out_h`, row-major) with the window of `src_w x src_h` frame pixels
/// centred at `(cx, cy)`, resampled bilinearly; outside the frame the edge is replicated. When a
/// window pixel covers more than 1.5 frame pixels, it averages a `k x k` grid of samples over its
/// footprint (an area filter against aliasing).
#[allow(clippy::too_many_arguments)]
pub fn resample_window(
    img: &GrayF32,
    cx: f64,
    cy: f64,
    src_w: f64,
    src_h: f64,
    out_w: usize,
    out_h: usize,
    out: &mut Vec<f32>,
) {
    if let Some(taps) = Taps::for_window(img, (cx, cy), (src_w, src_h), (out_w, out_h), out) {
        taps.fill(img, 0, out);
    }
}

/// [`resample_window`] with the rows of `out` shared among the members of `crew` (the same
/// bits).
pub fn resample_window_on<S: Send>(
    crew: &mut Crew<S>,
    img: &GrayF32,
    (cx, cy): (f64, f64),
    (src_w, src_h): (f64, f64),
    out_w: usize,
    out_h: usize,
    out: &mut Vec<f32>,
) {
    let Some(taps) = Taps::for_window(img, (cx, cy), (src_w, src_h), (out_w, out_h), out) else {
        return;
    };
    let parts = crew.len();
    let shares = Shares::new(out, out_h.div_ceil(parts) * out_w, parts);
    crew.run(&|_, member| {
        while let Some((start, rows)) = shares.take(member) {
            taps.fill(img, start / out_w, rows);
        }
    });
}

/// Where each window pixel samples: sampling is separable, so the `k` sample columns of each
/// output column and the `k` sample rows of each output row, as (first pixel, second pixel,
/// weight of the second) with the edge replicated.
struct Taps {
    k: usize,
    out_w: usize,
    xt: Vec<(usize, usize, f32)>,
    yt: Vec<(usize, usize, f32)>,
}

impl Taps {
    /// `out` made `out_w x out_h` zeros, and the taps of that window (`None` when the image or
    /// the window is empty: nothing to sample).
    fn for_window(
        img: &GrayF32,
        centre: (f64, f64),
        size: (f64, f64),
        (out_w, out_h): (usize, usize),
        out: &mut Vec<f32>,
    ) -> Option<Self> {
        out.clear();
        out.resize(out_w * out_h, 0.0);
        let empty = img.data.is_empty() || out_w == 0 || out_h == 0;
        (!empty).then(|| Taps::new(img, centre, size, (out_w, out_h)))
    }

    fn new(
        img: &GrayF32,
        (cx, cy): (f64, f64),
        (src_w, src_h): (f64, f64),
        (out_w, out_h): (usize, usize),
    ) -> Self {
        let sx = src_w / out_w as f64;
        let sy = src_h / out_h as f64;
        let k = if sx.max(sy) > 1.5 {
            sx.max(sy).ceil().clamp(1.0, 8.0) as usize
        } else {
            1
        };
        let taps = |c: f64, s: f64, n: usize, len: usize| -> Vec<(usize, usize, f32)> {
            let half = 0.5 * n as f64;
            let mut v = Vec::with_capacity(n * k);
            for i in 0..n {
                for a in 0..k {
                    // Window pixel i spans [i, i + 1) in window units; the window's centre is at
                    // n / 2, placed on c (pixel centres are at whole coordinates).
                    let f = (c + s * (i as f64 + (a as f64 + 0.5) / k as f64 - half))
                        .clamp(0.0, (len - 1) as f64);
                    let i0 = f.floor() as usize;
                    let i1 = (i0 + 1).min(len - 1);
                    v.push((i0, i1, (f - i0 as f64) as f32));
                }
            }
            v
        };
        Taps {
            k,
            out_w,
            xt: taps(cx, sx, out_w, img.width),
            yt: taps(cy, sy, out_h, img.height),
        }
    }

    /// The output rows from `first` on into `out` (whole rows, zeroed).
    fn fill(&self, img: &GrayF32, first: usize, out: &mut [f32]) {
        let (k, out_w, w) = (self.k, self.out_w, img.width);
        if k == 1 {
            return self.fill_bilinear(img, first, out);
        }
        let inv = 1.0 / (k * k) as f32;
        for (r, row) in out.chunks_exact_mut(out_w).enumerate() {
            let j = first + r;
            for &(y0, y1, wy) in &self.yt[j * k..(j + 1) * k] {
                let (r0, r1) = (
                    &img.data[y0 * w..(y0 + 1) * w],
                    &img.data[y1 * w..(y1 + 1) * w],
                );
                for (i, o) in row.iter_mut().enumerate() {
                    let mut s = 0.0;
                    for &(x0, x1, wx) in &self.xt[i * k..(i + 1) * k] {
                        let top = r0[x0] + wx * (r0[x1] - r0[x0]);
                        let bot = r1[x0] + wx * (r1[x1] - r1[x0]);
                        s += top + wy * (bot - top);
                    }
                    *o += s * inv;
                }
            }
        }
    }
}

impl Taps {
    /// [`Taps::fill`] with one tap a side (bilinear), each frame row's horizontal
    /// interpolation made once and kept while the next output row reads it too (the rows
    /// run top to bottom): the same operations, so the same bits, as the general loop.
    fn fill_bilinear(&self, img: &GrayF32, first: usize, out: &mut [f32]) {
        let (out_w, w) = (self.out_w, img.width);
        // Two frame rows' interpolations, by row index.
        let mut kept: [(usize, Vec<f32>); 2] = [
            (usize::MAX, vec![0.0; out_w]),
            (usize::MAX, vec![0.0; out_w]),
        ];
        let across = |y: usize, into: &mut Vec<f32>| {
            let r = &img.data[y * w..(y + 1) * w];
            for (o, &(x0, x1, wx)) in into.iter_mut().zip(&self.xt) {
                *o = r[x0] + wx * (r[x1] - r[x0]);
            }
        };
        for (r, row) in out.chunks_exact_mut(out_w).enumerate() {
            let (y0, y1, wy) = self.yt[first + r];
            // Keep whichever kept row is still needed; make the other.
            for y in [y0, y1] {
                if kept[0].0 != y && kept[1].0 != y {
                    let slot = usize::from(kept[0].0 == y0 || kept[0].0 == y1);
                    kept[slot].0 = y;
                    across(y, &mut kept[slot].1);
                }
            }
            let top = if kept[0].0 == y0 {
                &kept[0].1
            } else {
                &kept[1].1
            };
            let bot = if kept[0].0 == y1 {
                &kept[0].1
            } else {
                &kept[1].1
            };
            for ((o, &t), &b) in row.iter_mut().zip(top).zip(bot) {
                *o += t + wy * (b - t);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_at_its_own_size_is_a_crop_and_a_halved_one_averages() {
        let (w, h) = (20, 16);
        let img = GrayF32 {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| (i % w) as f32 + 100.0 * (i / w) as f32)
                .collect(),
        };
        let mut out = Vec::new();
        // A 6x4 window centred between pixels 9, 10 and 7, 8: pixels 7..13 x 6..10.
        resample_window(&img, 9.5, 7.5, 6.0, 4.0, 6, 4, &mut out);
        assert_eq!(out[0], img.get(7, 6));
        assert_eq!(out[23], img.get(12, 9));
        // Half size: each output pixel is the mean of a 2x2 block (a linear image: its centre).
        resample_window(&img, 9.5, 7.5, 8.0, 8.0, 4, 4, &mut out);
        let expect = 0.5 * (img.get(6, 4) + img.get(7, 5));
        assert!((out[0] - expect).abs() < 1e-3, "{} vs {expect}", out[0]);
        // One tap a side (bilinear) at sub-pixel positions: exact on a linear image, the edge
        // replicated outside it.
        for (cx, cy) in [(9.3, 7.8), (4.71, 3.05), (14.5, 11.25)] {
            resample_window(&img, cx, cy, 7.0, 5.0, 7, 5, &mut out);
            for j in 0..5 {
                for i in 0..7 {
                    let fx = (cx + i as f64 + 0.5 - 3.5).clamp(0.0, (w - 1) as f64);
                    let fy = (cy + j as f64 + 0.5 - 2.5).clamp(0.0, (h - 1) as f64);
                    let want = fx + 100.0 * fy;
                    let got = out[j * 7 + i] as f64;
                    assert!(
                        (got - want).abs() < 1e-3,
                        "({cx}, {cy}) {i} {j}: {got} vs {want}"
                    );
                }
            }
        }
        // The kept rows give the bits of interpolating every pixel afresh.
        let taps = Taps::new(&img, (8.37, 6.91), (13.0, 11.0), (10, 9));
        assert_eq!(taps.k, 1);
        resample_window(&img, 8.37, 6.91, 13.0, 11.0, 10, 9, &mut out);
        for (j, &(y0, y1, wy)) in taps.yt.iter().enumerate() {
            for (i, &(x0, x1, wx)) in taps.xt.iter().enumerate() {
                let (a, b) = (img.get(x0, y0), img.get(x1, y0));
                let (c, d) = (img.get(x0, y1), img.get(x1, y1));
                let (top, bot) = (a + wx * (b - a), c + wx * (d - c));
                assert_eq!(
                    out[j * 10 + i].to_bits(),
                    (top + wy * (bot - top)).to_bits()
                );
            }
        }
        // Rows shared among threads: the same bits.
        let mut crew = Crew::new(vec![(); 3]);
        for (c, size, n) in [
            ((9.5, 7.5), (8.0, 8.0), (4, 4)),
            ((3.2, 11.7), (13.0, 5.0), (7, 9)),
        ] {
            resample_window(&img, c.0, c.1, size.0, size.1, n.0, n.1, &mut out);
            let mut banded = Vec::new();
            resample_window_on(&mut crew, &img, c, size, n.0, n.1, &mut banded);
            assert_eq!(banded, out);
        }
    }
}
