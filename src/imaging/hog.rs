//! Histogram-of-oriented-gradient features per cell, in the 31-channel form of Felzenszwalb et
//! al. (PAMI 2010) that the correlation-filter trackers use: 18 contrast-sensitive and 9
//! contrast-insensitive orientation channels, each normalised by the four 2x2-cell blocks around
//! its cell and clipped at 0.2, plus 4 gradient-energy channels.

/// A multi-channel map of `width x height` cells, stored channel by channel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FeatureMap {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl FeatureMap {
    /// Channel `c` (`width * height` values, row-major).
    pub fn channel(&self, c: usize) -> &[f32] {
        let n = self.width * self.height;
        &self.data[c * n..(c + 1) * n]
    }

    /// Mutable [`FeatureMap::channel`].
    pub fn channel_mut(&mut self, c: usize) -> &mut [f32] {
        let n = self.width * self.height;
        &mut self.data[c * n..(c + 1) * n]
    }
}

use crate::crew::{Crew, Shares};

/// Channels of [`fhog`].
pub const FHOG_CHANNELS: usize = 31;

const SIGNED_BINS: usize = 18;
const CLIP: f32 = 0.2;

/// The HOG features of a `w x h` image (row-major, gray levels) with square cells of `cell`
/// pixels: `(w / cell) x (h / cell)` cells, [`FHOG_CHANNELS`] channels. Gradients are central
/// differences (edges replicated); each pixel's magnitude is shared between its two nearest
/// orientation bins and, bilinearly, its four nearest cells.
pub fn fhog(img: &[f32], w: usize, h: usize, cell: usize) -> FeatureMap {
    let cell = cell.max(1);
    let (cw, ch) = ((w / cell).max(1), (h / cell).max(1));
    let mut hist = vec![0f32; cw * ch * SIGNED_BINS];
    histogram_rows(img, (w, h), cell, 0..ch, &mut hist);
    normalise(&hist, cw, ch, cw * ch)
}

/// [`fhog`] with the histograms made by the members of `crew`, each a band of rows of cells
/// (the bits of [`fhog`]: each band's sums are made as the whole map's are).
pub fn fhog_on<S: Send>(
    crew: &mut Crew<S>,
    img: &[f32],
    w: usize,
    h: usize,
    cell: usize,
) -> FeatureMap {
    let cell = cell.max(1);
    let (cw, ch) = ((w / cell).max(1), (h / cell).max(1));
    let mut hist = vec![0f32; cw * ch * SIGNED_BINS];
    let parts = crew.len().min(ch);
    let band = ch.div_ceil(parts.max(1));
    let shares = Shares::new(&mut hist, band * SIGNED_BINS * cw, parts);
    crew.run(&|_, member| {
        while let Some((start, out)) = shares.take(member) {
            let r0 = start / (SIGNED_BINS * cw);
            let r1 = r0 + out.len() / (SIGNED_BINS * cw);
            histogram_rows(img, (w, h), cell, r0..r1, out);
        }
    });
    normalise(&hist, cw, ch, cw * ch)
}

/// Where a pixel's vote goes along one axis: the first of the two cells whose centres surround
/// it and the weights of the two.
#[derive(Clone, Copy)]
struct Share {
    first: i64,
    w0: f32,
    w1: f32,
}

fn shares(len: usize, cell: usize) -> Vec<Share> {
    let inv_cell = 1.0 / cell as f32;
    (0..len)
        .map(|i| {
            let f = (i as f32 + 0.5) * inv_cell - 0.5;
            let fi = f.floor();
            let a = f - fi;
            Share {
                first: fi as i64,
                w0: 1.0 - a,
                w1: a,
            }
        })
        .collect()
}

/// The 18 contrast-sensitive orientation histograms of every cell (row of cells after row of
/// cells, in each the first bin of every cell, then the second, ...: `[(cy * 18 + o) * cw +
/// cx]`), each pixel's gradient magnitude shared between its two nearest bins and its four
/// nearest cells.
///
/// A row of pixels at a time: the per-pixel quantities first (vectorised), then each pixel's
/// four votes (two bins of its two cells) into the row's own histogram of a row of cells, then
/// that histogram, weighted, into the two rows of cells around the row (vectorised): half the
/// scattered additions of voting into the four cells directly. The test compares the values
/// with a pixel-by-pixel loop (the same up to rounding: the sums are made in another order).
///
/// Only the rows of cells `rows` are made, into `hist` (those rows' histograms), from the rows
/// of pixels that vote into them.
fn histogram_rows(
    img: &[f32],
    (w, h): (usize, usize),
    cell: usize,
    rows: std::ops::Range<usize>,
    hist: &mut [f32],
) {
    let (cw, ch) = ((w / cell).max(1), (h / cell).max(1));
    debug_assert_eq!(hist.len(), rows.len() * SIGNED_BINS * cw);
    let (r0, r1) = (rows.start as i64, rows.end as i64);
    let (xn, yn) = (w.min(cw * cell), h.min(ch * cell));
    let (sx, sy) = (shares(xn, cell), shares(yn, cell));
    // Per side (0: the left cell of the pair, 1: the right one): each pixel's cell in a row of
    // cells and the range of pixels whose cell of that side exists.
    let side = |d: i64| {
        let offs: Vec<usize> = sx.iter().map(|s| (s.first + d).max(0) as usize).collect();
        let lo = sx.iter().position(|s| s.first + d >= 0).unwrap_or(xn);
        let hi = sx
            .iter()
            .rposition(|s| s.first + d < cw as i64)
            .map_or(0, |i| i + 1);
        (offs, lo, hi.max(lo))
    };
    let sides = [side(0), side(1)];
    let (wx0, wx1): (Vec<f32>, Vec<f32>) = sx.iter().map(|s| (s.w0, s.w1)).unzip();
    let mut mag = vec![0f32; xn];
    let mut wb = vec![0f32; xn];
    let mut o0 = vec![0i32; xn];
    let mut o1 = vec![0i32; xn];
    let (mut gx, mut gy) = (vec![0f32; xn], vec![0f32; xn]);
    let mut mx = [vec![0f32; xn], vec![0f32; xn]];
    let (mut a0, mut a1) = (vec![0f32; xn], vec![0f32; xn]);
    let mut partial = [vec![0f32; SIGNED_BINS * cw], vec![0f32; SIGNED_BINS * cw]];
    let scale = SIGNED_BINS as f32 / (2.0 * std::f32::consts::PI);
    let two_pi = 2.0 * std::f32::consts::PI;
    for (y, share_y) in sy.iter().enumerate() {
        if share_y.first + 1 < r0 || share_y.first >= r1 {
            continue;
        }
        let row = &img[y * w..(y + 1) * w];
        let up = &img[y.saturating_sub(1) * w..][..w];
        let down = &img[(y + 1).min(h - 1) * w..][..w];
        // Central differences, edges replicated.
        gx[0] = row[1.min(w - 1)] - row[0];
        if xn > 1 {
            let inner = (xn - 1).min(w - 2);
            for ((g, r), l) in gx[1..=inner].iter_mut().zip(&row[2..]).zip(row) {
                *g = r - l;
            }
            for x in inner + 1..xn {
                gx[x] = row[(x + 1).min(w - 1)] - row[x - 1];
            }
        }
        for ((g, d), u) in gy.iter_mut().zip(down).zip(up) {
            *g = d - u;
        }
        // Straight-line arithmetic over arrays (the compiler vectorises it: every slice is
        // cut to `xn` first, so no index is checked).
        let (gx, gy, wb, o0, o1, mag) = (
            &gx[..xn],
            &gy[..xn],
            &mut wb[..xn],
            &mut o0[..xn],
            &mut o1[..xn],
            &mut mag[..xn],
        );
        let [mx0, mx1] = &mut mx;
        let (mx0, mx1, wx0, wx1) = (&mut mx0[..xn], &mut mx1[..xn], &wx0[..xn], &wx1[..xn]);
        for x in 0..xn {
            let (gx, gy) = (gx[x], gy[x]);
            let m = (gx * gx + gy * gy).sqrt();
            let a = atan2_lanes(gy, gx);
            let a = if a < 0.0 { a + two_pi } else { a };
            let b = a * scale;
            let b0 = b.floor();
            wb[x] = b - b0;
            // `b0` is 0..=18 (18 where the angle rounded up to a full turn).
            let o = b0 as i32;
            let o = if o >= SIGNED_BINS as i32 {
                o - SIGNED_BINS as i32
            } else {
                o
            };
            o0[x] = o;
            o1[x] = if o + 1 == SIGNED_BINS as i32 {
                0
            } else {
                o + 1
            };
            mag[x] = m;
            mx0[x] = m * wx0[x];
            mx1[x] = m * wx1[x];
        }
        // The row's votes into its row of cells (each pixel into its two bins of its two
        // cells), then that row's histogram into the two rows of cells around it, weighted.
        // Two partial rows (even and odd pixels) so that neighbours voting into the same bin
        // do not wait on each other.
        let [row_even, row_odd] = &mut partial;
        row_even.fill(0.0);
        row_odd.fill(0.0);
        for d in [1, 0] {
            let (offs, lo, hi) = &sides[d];
            let (lo, hi) = (*lo, *hi);
            let (a0, a1, mxd, wb) = (
                &mut a0[lo..hi],
                &mut a1[lo..hi],
                &mx[d][lo..hi],
                &wb[lo..hi],
            );
            for x in 0..a0.len() {
                let m = mxd[x];
                a0[x] = m * (1.0 - wb[x]);
                a1[x] = m * wb[x];
            }
            let (o0, o1, offs) = (&o0[lo..hi], &o1[lo..hi], &offs[lo..hi]);
            let pairs = a0.len() / 2;
            for p in 0..pairs {
                let (i, j) = (2 * p, 2 * p + 1);
                row_even[o0[i] as usize * cw + offs[i]] += a0[i];
                row_even[o1[i] as usize * cw + offs[i]] += a1[i];
                row_odd[o0[j] as usize * cw + offs[j]] += a0[j];
                row_odd[o1[j] as usize * cw + offs[j]] += a1[j];
            }
            if a0.len() % 2 == 1 {
                let i = a0.len() - 1;
                row_even[o0[i] as usize * cw + offs[i]] += a0[i];
                row_even[o1[i] as usize * cw + offs[i]] += a1[i];
            }
        }
        for (cy, wyy) in [(share_y.first, share_y.w0), (share_y.first + 1, share_y.w1)] {
            if cy < r0 || cy >= r1 {
                continue;
            }
            let row_cells = &mut hist[(cy - r0) as usize * SIGNED_BINS * cw..][..SIGNED_BINS * cw];
            for ((c, e), o) in row_cells.iter_mut().zip(&*row_even).zip(&*row_odd) {
                *c += (e + o) * wyy;
            }
        }
    }
}

/// The 31 channels from the histograms (as [`histogram_rows`] lays them out): each
/// cell's histogram normalised by the energies of the four 2x2-cell blocks around it and
/// clipped. A row of cells at a time, each quantity over the row's cells (vectorised); every
/// value is made by the same operations in the same order as a cell-by-cell loop (the test
/// compares the bits with one).
fn normalise(hist: &[f32], cw: usize, ch: usize, ncell: usize) -> FeatureMap {
    let bins = |cy: usize, o: usize| &hist[(cy * SIGNED_BINS + o) * cw..][..cw];
    // Energy of the contrast-insensitive histogram of each cell.
    let mut energy = vec![0f32; ncell];
    for cy in 0..ch {
        let e = &mut energy[cy * cw..(cy + 1) * cw];
        for o in 0..9 {
            let (a, b) = (bins(cy, o), bins(cy, o + 9));
            for x in 0..cw {
                let u = a[x] + b[x];
                e[x] = if o == 0 { -0.0 } else { e[x] } + u * u;
            }
        }
    }
    // The normaliser of every 2x2 block, by its top-left cell (-1..cw, -1..ch; cells outside
    // the map read the nearest).
    let e = |x: i64, y: i64| {
        let x = x.clamp(0, cw as i64 - 1) as usize;
        let y = y.clamp(0, ch as i64 - 1) as usize;
        energy[y * cw + x]
    };
    let bw = cw + 1;
    let mut block = vec![0f32; bw * (ch + 1)];
    for by in -1..ch as i64 {
        for bx in -1..cw as i64 {
            let s = e(bx, by) + e(bx + 1, by) + e(bx, by + 1) + e(bx + 1, by + 1);
            block[(by + 1) as usize * bw + (bx + 1) as usize] = 1.0 / (s + 1e-4).sqrt();
        }
    }
    let mut out = FeatureMap {
        width: cw,
        height: ch,
        channels: FHOG_CHANNELS,
        data: vec![0.0; ncell * FHOG_CHANNELS],
    };
    let mut texture = vec![[0f32; 4]; cw];
    let mut sum = vec![0f32; cw];
    for y in 0..ch {
        // The four blocks around each cell: up-left, up, left, the cell's own.
        let up = &block[y * bw..][..bw];
        let here = &block[(y + 1) * bw..][..bw];
        let norms = |x: usize| [up[x], up[x + 1], here[x], here[x + 1]];
        texture.iter_mut().for_each(|t| *t = [0.0; 4]);
        for o in 0..SIGNED_BINS {
            let h = bins(y, o);
            for x in 0..cw {
                let n = norms(x);
                let mut s = 0.0;
                for j in 0..4 {
                    let v = (h[x] * n[j]).min(CLIP);
                    s += v;
                    texture[x][j] += v;
                }
                sum[x] = 0.5 * s;
            }
            out.data[o * ncell + y * cw..][..cw].copy_from_slice(&sum);
        }
        for o in 0..9 {
            let (a, b) = (bins(y, o), bins(y, o + 9));
            for x in 0..cw {
                let n = norms(x);
                let u = a[x] + b[x];
                let mut s = -0.0;
                for nj in n {
                    s += (u * nj).min(CLIP);
                }
                sum[x] = 0.5 * s;
            }
            out.data[(SIGNED_BINS + o) * ncell + y * cw..][..cw].copy_from_slice(&sum);
        }
        for j in 0..4 {
            for x in 0..cw {
                out.data[(27 + j) * ncell + y * cw + x] = 0.2357 * texture[x][j];
            }
        }
    }
    out
}

/// [`atan2_approx`] without branches, so that a loop over arrays of it is vectorised: the same
/// bits (compared by a test).
#[inline(always)]
fn atan2_lanes(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let swap = ax < ay;
    let mn = if swap { ax } else { ay };
    let mx = if swap { ay } else { ax };
    let t = mn / mx;
    let t2 = t * t;
    let r = t
        * (0.999_866
            + t2 * (-0.330_299_5 + t2 * (0.180_141 + t2 * (-0.085_133 + t2 * 0.020_835_1))));
    let r = if ay > ax { FRAC_PI_2 - r } else { r };
    let r = if x < 0.0 { PI - r } else { r };
    let r = if y < 0.0 { -r } else { r };
    if mx == 0.0 { 0.0 } else { r }
}

/// `atan2(y, x)` within 1e-4 rad (a minimax polynomial for the arctangent on [0, 1]), several
/// times faster than the library's; the orientation bins are 20 degrees wide.
#[inline(always)]
pub fn atan2_approx(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (mn, mx) = if ax < ay { (ax, ay) } else { (ay, ax) };
    if mx == 0.0 {
        return 0.0;
    }
    let t = mn / mx;
    let t2 = t * t;
    let mut r = t
        * (0.999_866
            + t2 * (-0.330_299_5 + t2 * (0.180_141 + t2 * (-0.085_133 + t2 * 0.020_835_1))));
    if ay > ax {
        r = FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    if y < 0.0 { -r } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_approximate_arctangent_is_within_a_tenth_of_a_milliradian() {
        for k in 0..3600 {
            let a = k as f32 * 0.1f32.to_radians() - std::f32::consts::PI;
            for r in [0.01f32, 1.0, 300.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                let d = atan2_approx(y, x) - y.atan2(x);
                let d = (d + std::f32::consts::PI).rem_euclid(2.0 * std::f32::consts::PI)
                    - std::f32::consts::PI;
                assert!(d.abs() < 1e-4, "{a}: {d}");
            }
        }
    }

    /// The first version of [`fhog`], pixel by pixel and cell by cell: the faster one must give
    /// the same values up to rounding (its sums are made in another order).
    fn reference_fhog(img: &[f32], w: usize, h: usize, cell: usize) -> FeatureMap {
        let cell = cell.max(1);
        let (cw, ch) = ((w / cell).max(1), (h / cell).max(1));
        let ncell = cw * ch;
        let mut hist = vec![0f32; ncell * SIGNED_BINS];
        let px = |x: usize, y: usize| img[y.min(h - 1) * w + x.min(w - 1)];
        let inv_cell = 1.0 / cell as f32;
        for y in 0..h.min(ch * cell) {
            for x in 0..w.min(cw * cell) {
                let gx = px(x + 1, y) - px(x.saturating_sub(1), y);
                let gy = px(x, y + 1) - px(x, y.saturating_sub(1));
                let mag = (gx * gx + gy * gy).sqrt();
                if mag <= 0.0 {
                    continue;
                }
                let mut a = atan2_approx(gy, gx);
                if a < 0.0 {
                    a += 2.0 * std::f32::consts::PI;
                }
                let b = a * (SIGNED_BINS as f32 / (2.0 * std::f32::consts::PI));
                let b0 = b.floor();
                let wb = b - b0;
                let o0 = (b0 as usize) % SIGNED_BINS;
                let o1 = (o0 + 1) % SIGNED_BINS;
                // Bilinear over the cells whose centres surround the pixel.
                let fx = (x as f32 + 0.5) * inv_cell - 0.5;
                let fy = (y as f32 + 0.5) * inv_cell - 0.5;
                let (ix, iy) = (fx.floor(), fy.floor());
                let (wx, wy) = (fx - ix, fy - iy);
                for (dy, wyy) in [(0i64, 1.0 - wy), (1, wy)] {
                    let cy = iy as i64 + dy;
                    if cy < 0 || cy >= ch as i64 {
                        continue;
                    }
                    for (dx, wxx) in [(0i64, 1.0 - wx), (1, wx)] {
                        let cx = ix as i64 + dx;
                        if cx < 0 || cx >= cw as i64 {
                            continue;
                        }
                        let base = (cy as usize * cw + cx as usize) * SIGNED_BINS;
                        let m = mag * wxx * wyy;
                        hist[base + o0] += m * (1.0 - wb);
                        hist[base + o1] += m * wb;
                    }
                }
            }
        }
        // Energy of the contrast-insensitive histogram of each cell.
        let energy: Vec<f32> = (0..ncell)
            .map(|c| {
                let hc = &hist[c * SIGNED_BINS..(c + 1) * SIGNED_BINS];
                (0..9).map(|o| (hc[o] + hc[o + 9]).powi(2)).sum()
            })
            .collect();
        let e = |x: i64, y: i64| {
            let x = x.clamp(0, cw as i64 - 1) as usize;
            let y = y.clamp(0, ch as i64 - 1) as usize;
            energy[y * cw + x]
        };
        let mut out = FeatureMap {
            width: cw,
            height: ch,
            channels: FHOG_CHANNELS,
            data: vec![0.0; ncell * FHOG_CHANNELS],
        };
        for y in 0..ch {
            for x in 0..cw {
                let (xi, yi) = (x as i64, y as i64);
                // The four 2x2 blocks that contain this cell.
                let mut norms = [0f32; 4];
                for (j, (dx, dy)) in [(-1, -1), (0, -1), (-1, 0), (0, 0)].into_iter().enumerate() {
                    let s = e(xi + dx, yi + dy)
                        + e(xi + dx + 1, yi + dy)
                        + e(xi + dx, yi + dy + 1)
                        + e(xi + dx + 1, yi + dy + 1);
                    norms[j] = 1.0 / (s + 1e-4).sqrt();
                }
                let c = y * cw + x;
                let hc = &hist[c * SIGNED_BINS..(c + 1) * SIGNED_BINS];
                let mut texture = [0f32; 4];
                for o in 0..SIGNED_BINS {
                    let mut s = 0.0;
                    for (j, n) in norms.iter().enumerate() {
                        let v = (hc[o] * n).min(CLIP);
                        s += v;
                        texture[j] += v;
                    }
                    out.data[o * ncell + c] = 0.5 * s;
                }
                for o in 0..9 {
                    let u = hc[o] + hc[o + 9];
                    let s: f32 = norms.iter().map(|n| (u * n).min(CLIP)).sum();
                    out.data[(SIGNED_BINS + o) * ncell + c] = 0.5 * s;
                }
                for (j, t) in texture.iter().enumerate() {
                    out.data[(27 + j) * ncell + c] = 0.2357 * t;
                }
            }
        }
        out
    }

    #[test]
    fn the_branch_free_arctangent_gives_the_same_bits() {
        let mut rng = crate::rng::Rng::new(3);
        let mut pairs: Vec<(f32, f32)> = (0..100_000)
            .map(|_| ((rng.normal() * 100.0) as f32, (rng.normal() * 100.0) as f32))
            .collect();
        for a in [0.0f32, -0.0, 1.0, -1.0, 255.0, -255.0] {
            for b in [0.0f32, -0.0, 1.0, -1.0, 255.0, -255.0] {
                pairs.push((a, b));
            }
        }
        for (y, x) in pairs {
            assert_eq!(
                atan2_lanes(y, x).to_bits(),
                atan2_approx(y, x).to_bits(),
                "{y} {x}"
            );
        }
    }

    #[test]
    fn the_row_passes_give_the_pixel_loops_values() {
        let mut rng = crate::rng::Rng::new(7);
        for (w, h, cell) in [(64, 48, 4), (37, 29, 4), (10, 7, 3), (3, 2, 4), (24, 24, 1)] {
            let img: Vec<f32> = (0..w * h).map(|_| (rng.uniform() * 255.0) as f32).collect();
            let want = reference_fhog(&img, w, h, cell);
            let mut crew = Crew::new(vec![(); 3]);
            let banded = fhog_on(&mut crew, &img, w, h, cell);
            assert_eq!(banded, fhog(&img, w, h, cell));
            let got = banded;
            assert_eq!(
                (got.width, got.height, got.data.len()),
                (want.width, want.height, want.data.len())
            );
            for (i, (a, b)) in got.data.iter().zip(&want.data).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
                    "{w}x{h}/{cell}: value {i}: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn a_flat_image_has_no_features_and_an_edge_votes_for_its_orientation() {
        let (w, h) = (32, 32);
        let flat = vec![100.0; w * h];
        let f = fhog(&flat, w, h, 4);
        assert_eq!((f.width, f.height, f.channels), (8, 8, FHOG_CHANNELS));
        assert!(f.data.iter().all(|&v| v == 0.0));
        // A vertical edge, dark to bright: gradients point along +x (signed bin 0,
        // contrast-insensitive bin 0); the mirrored edge votes for signed bin 9 instead.
        let edge: Vec<f32> = (0..w * h)
            .map(|i| if i % w >= 16 { 200.0 } else { 20.0 })
            .collect();
        let f = fhog(&edge, w, h, 4);
        let c = 3 * 8 + 3; // the cell left of the edge, in a middle row
        let best = (0..18)
            .max_by(|&a, &b| f.channel(a)[c].total_cmp(&f.channel(b)[c]))
            .unwrap_or(99);
        assert_eq!(best, 0);
        assert!(f.channel(18)[c] > 0.1 && f.channel(18 + 4)[c] < 1e-6);
        let mirrored: Vec<f32> = edge.iter().map(|v| 220.0 - v).collect();
        let g = fhog(&mirrored, w, h, 4);
        assert!(g.channel(9)[c] > 0.1 && g.channel(0)[c] < 1e-6);
        // The contrast-insensitive channel is the same for both.
        assert!((g.channel(18)[c] - f.channel(18)[c]).abs() < 1e-6);
        // Far from the edge nothing votes.
        assert_eq!(f.channel(0)[3 * 8], 0.0);
    }
}
