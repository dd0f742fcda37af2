//! The confidence of a registration tracker: how much the patch where a search ended shows
//! what the template shows ([`BlockCorrelation`]), block by block, insensitive to light that
//! varies smoothly across the target. The loss checks ([`super::LossCheck`]) judge frames by it.

/// Columns [`BlockCorrelation`]'s moments are summed at a time (four sums each, in registers:
/// two AVX registers a sum).
const MOMENT_COLUMNS: usize = 8;
const _: () = assert!(MOMENT_COLUMNS == 8, "the AVX moments sum eight columns");

/// The most blocks per side of [`block_correlation`].
pub const MAX_BLOCKS: usize = 8;

/// The most channels of a patch (a colour grid's three, the descriptor fields' four;
/// [`crate::registration::Problem::channels`]).
pub const MAX_CHANNELS: usize = crate::imaging::MAX_PLANES;

/// The confidence that `current` shows what `template` shows, both `res x res` patches stored
/// row by row, in -1..1 (see [`BlockCorrelation`], which this makes for one use).
pub fn block_correlation(template: &[f32], current: &[f32], res: usize, cells: usize) -> f64 {
    BlockCorrelation::new(template, res, cells).of(current)
}

/// The confidence that a patch shows what a template shows, both `res x res` stored row by row,
/// in -1..1. The patches are cut into `cells x cells` blocks; in each, a plane (bias and slopes
/// along both axes) is fitted to each patch and removed, and the residuals are correlated. The
/// blocks' correlations are averaged with the template's residual variance as weight. So it is
/// insensitive to light that varies smoothly across the target (a lamp's spot, a face turning
/// to the light: in each block that is nearly a gain, a bias and a slope), and blocks the
/// template has no texture in (only noise) weigh little. 0 when the template is flat.
///
/// A patch of several channels (a colour grid's: `channels` patches of `res x res`, one after
/// the other, as long a template) has its blocks in each channel, all averaged alike.
///
/// What depends on the template and the grid only (each block's plane fit, the template's
/// moments) is computed once, by [`BlockCorrelation::new`]; [`BlockCorrelation::of`] then makes
/// five sums per sample (row segment by row segment, four lanes) and does not allocate.
#[derive(Clone, Debug, Default)]
pub struct BlockCorrelation {
    template: Vec<f32>,
    /// The blocks of each channel in turn.
    blocks: Vec<Block>,
    /// The template's channels (its length over `res x res`, at most [`MAX_CHANNELS`]).
    channels: usize,
    /// What depends on the grid only, kept while `res` and `cells` stay: `(res, cells)` and per
    /// block the sums of 1, x, y, xx, xy, yy (a new template per frame then only sums t, tx,
    /// ty, tt).
    geometry: Option<(usize, usize)>,
    geometry_sums: Vec<[f64; 6]>,
    /// A rectangle of the target left out (left, top, right, bottom in its unit square): the
    /// blocks it covers a tenth or more of are left out of every template set from then on.
    mask: Option<[f64; 4]>,
}

/// One block of [`BlockCorrelation`]: `(M, u_t, v_t, n)` with `M` the plane fit's normal matrix
/// inverted, `u_t` the template's moments `(sum t, sum t x, sum t y)`, `v_t` its residual
/// variance and `n` the block's samples (`None` for a block without texture, left out).
type Block = Option<(nalgebra::Matrix3<f64>, nalgebra::Vector3<f64>, f64, f64)>;

impl BlockCorrelation {
    /// Prepares the confidence against `template` (`res x res`) with `cells x cells` blocks
    /// (at most [`MAX_BLOCKS`] per side); a template shorter than `res x res` gives 0 always.
    pub fn new(template: &[f32], res: usize, cells: usize) -> Self {
        let mut bc = Self::default();
        bc.set_template(template, res, cells);
        bc
    }

    /// Leaves out, from now on, the blocks that `mask` (left, top, right, bottom in the
    /// target's unit square; `None`: none) covers a tenth or more of: a known occluder
    /// (`spi_mask_*`) does not make a frame look lost. Applied to the template already set too.
    pub fn set_mask(&mut self, mask: Option<[f64; 4]>) {
        self.mask = mask;
        self.leave_out_masked();
    }

    /// The blocks the mask covers a tenth or more of, left out.
    fn leave_out_masked(&mut self) {
        let (Some([l, t, r, b]), Some((_, cells))) = (self.mask, self.geometry) else {
            return;
        };
        let side = 1.0 / cells as f64;
        let overlap = |lo: f64, hi: f64, a: f64, z: f64| (hi.min(z) - lo.max(a)).max(0.0);
        for (k, block) in self.blocks.iter_mut().enumerate() {
            let k = k % (cells * cells);
            let (x, y) = ((k % cells) as f64 * side, (k / cells) as f64 * side);
            let covered = overlap(x, x + side, l, r) * overlap(y, y + side, t, b);
            if covered >= 0.1 * side * side {
                *block = None;
            }
        }
    }

    /// [`BlockCorrelation::new`] in place: once its buffers have grown to `res x res`, it does
    /// not allocate (the tracker makes one of every frame's patch).
    pub fn set_template(&mut self, template: &[f32], res: usize, cells: usize) {
        if self.set_geometry(template, res, cells) {
            // The template's part: per block, sums of t, tx, ty, tt.
            let m = res * res;
            for c in 0..self.channels {
                let part = &template[c * m..(c + 1) * m];
                let sums = self.moments(part, [part]);
                self.set_template_sums(part, &sums);
            }
        }
    }

    /// [`BlockCorrelation::set_template`] with the template's sums already made: `sums` are
    /// those of `template` on this grid (from [`BlockCorrelation::of_pair`] on a correlation of
    /// the same `res` and `cells`), which are then not summed again. The same result.
    pub fn set_template_from(
        &mut self,
        template: &[f32],
        res: usize,
        cells: usize,
        sums: &PatchSums,
    ) {
        if sums.geometry != Some((res, blocks_per_side(res, cells)))
            || sums.channels != channels_of(template, res)
        {
            return self.set_template(template, res, cells);
        }
        if self.set_geometry(template, res, cells) {
            let m = res * res;
            for c in 0..self.channels {
                self.set_template_sums(&template[c * m..(c + 1) * m], &sums.blocks[c]);
            }
        }
    }

    /// The template-independent part of [`BlockCorrelation::set_template`]: clears the template
    /// and sets the grid; false (the correlation then gives 0) when `template` is too short.
    fn set_geometry(&mut self, template: &[f32], res: usize, cells: usize) -> bool {
        let cells = blocks_per_side(res, cells);
        self.template.clear();
        self.blocks.clear();
        if res == 0 || template.len() < res * res {
            self.geometry = None;
            return false;
        }
        self.channels = channels_of(template, res);
        // The grid's part, once per (res, cells): per block the sums of 1, x, y, xx, xy, yy of
        // the samples' block-local coordinates.
        if self.geometry != Some((res, cells)) {
            self.geometry_sums.clear();
            self.geometry_sums.resize(cells * cells, [0.0; 6]);
            for r in 0..res {
                let br = r * cells / res;
                let y = (r - br * res / cells) as f64;
                for c in 0..res {
                    let bc = c * cells / res;
                    let x = (c - bc * res / cells) as f64;
                    let b = br * cells + bc;
                    let terms = [1.0, x, y, x * x, x * y, y * y];
                    for (a, v) in self.geometry_sums[b].iter_mut().zip(terms) {
                        *a += v;
                    }
                }
            }
            self.geometry = Some((res, cells));
        }
        true
    }

    /// Each block's plane fit and the template's moments from its sums `t, tx, ty, tt` (the
    /// first four of each block's in `sums`), of the next channel (after those set).
    fn set_template_sums(&mut self, template: &[f32], sums: &BlockSums) {
        let acc = self
            .geometry_sums
            .iter()
            .zip(sums)
            .map(|(g, t)| [g[0], g[1], g[2], g[3], g[4], g[5], t[0], t[1], t[2], t[3]]);
        self.blocks.extend(acc.map(|b| {
            let n = b[0];
            if n < 4.0 {
                return None;
            }
            let m = nalgebra::Matrix3::new(b[0], b[1], b[2], b[1], b[3], b[4], b[2], b[4], b[5]);
            let inv = m.try_inverse()?;
            let ut = nalgebra::Vector3::new(b[6], b[7], b[8]);
            let vt = b[9] - ut.dot(&(inv * ut));
            (vt.is_finite() && vt > 1e-6 * n).then_some((inv, ut, vt, n))
        }));
        self.template.extend_from_slice(template);
        self.leave_out_masked();
    }

    /// Per block, the sums of `p`, `p x`, `p y`, `p p` and `q p` for each `q` of `qs` (one or
    /// two; the last sum zero with one) over its samples (`x`, `y` the block-local coordinates),
    /// `p` and each `q` being `res x res` patches. Per row of blocks, the columns' sums of `p`,
    /// `p y`, `p p` and each `q p` over the block row's rows ([`MOMENT_COLUMNS`] columns at a
    /// time, kept in registers down the rows), then each column's into its block, column after
    /// column (`p x` from the column's `p`). Each sum is made the same way whatever `qs` holds.
    fn moments<const Q: usize>(&self, p: &[f32], qs: [&[f32]; Q]) -> BlockSums {
        let mut acc = [[0.0f64; 6]; MAX_BLOCKS * MAX_BLOCKS];
        let Some((res, cells)) = self.geometry else {
            return acc;
        };
        // The first row (or column) of block b: the first r with r cells / res = b; its
        // block-local coordinate is r - b res / cells.
        let start = |b: usize| (b * res).div_ceil(cells);
        for br in 0..cells {
            let rows = start(br)..start(br + 1).min(res);
            let origin = (br * res / cells) as f64;
            // Each column's sums into its block, in the order of the columns: `c` the next
            // column, `bc` its block, `next` the next block's first column, `x0` the origin of
            // the block-local x (no division per column); the block's sums are kept in `a` until
            // the next block begins.
            let row_acc = &mut acc[br * cells..(br + 1) * cells];
            let (mut c, mut bc, mut next, mut x0) = (0, 0, start(1), 0);
            let mut a = [0.0f64; 6];
            while c < res {
                // Eight columns' sums, of which those from `skip` on are the next to add.
                let (sums, skip) = if c + MOMENT_COLUMNS <= res {
                    (column_sums8(p, qs, res, c, rows.clone(), origin), 0)
                } else if res >= MOMENT_COLUMNS {
                    // The last columns: the last eight summed (each column's sums are its own).
                    let first = res - MOMENT_COLUMNS;
                    (
                        column_sums8(p, qs, res, first, rows.clone(), origin),
                        c - first,
                    )
                } else {
                    let mut one = [[0.0; 5]; MOMENT_COLUMNS];
                    one[MOMENT_COLUMNS - 1] =
                        portable::column_sums::<1, Q>(p, qs, res, c, rows.clone(), origin)[0];
                    (one, MOMENT_COLUMNS - 1)
                };
                for s in &sums[skip..] {
                    while c >= next {
                        row_acc[bc] = std::mem::take(&mut a);
                        bc += 1;
                        next = start(bc + 1);
                        x0 = bc * res / cells;
                    }
                    let x = (c - x0) as f64;
                    a[0] += s[0];
                    a[1] += s[0] * x;
                    a[2] += s[1];
                    a[3] += s[2];
                    a[4] += s[3];
                    a[5] += s[4];
                    c += 1;
                }
            }
            row_acc[bc] = a;
        }
        acc
    }

    /// The confidence of `current` (0 when it is shorter than the template, flat or not finite).
    pub fn of(&self, current: &[f32]) -> f64 {
        let m = self.geometry.map_or(0, |(res, _)| res * res);
        if current.len() < m * self.channels {
            return 0.0;
        }
        let mut parts = (0.0, 0.0);
        for c in 0..self.channels {
            // Per block, sums of: c, cx, cy, cc, tc.
            let r = c * m..(c + 1) * m;
            let acc = self.moments(&current[r.clone()], [&self.template[r]]);
            add(&mut parts, self.of_sums(c, &acc, 4));
        }
        ratio(parts)
    }

    /// [`BlockCorrelation::of`] for this correlation and `other` (the same `res` and cells,
    /// another template), from one pass over `current`, and the patch's sums (for
    /// [`BlockCorrelation::set_template_from`]): the same two values as two calls of `of`.
    pub fn of_pair(
        &self,
        other: &BlockCorrelation,
        current: &[f32],
        sums: &mut PatchSums,
    ) -> (f64, f64) {
        let m = self.geometry.map_or(0, |(res, _)| res * res);
        sums.geometry = None;
        let n = m * self.channels;
        if other.geometry != self.geometry
            || other.channels != self.channels
            || m == 0
            || current.len() < n
        {
            return (self.of(current), other.of(current));
        }
        let (mut mine, mut theirs) = ((0.0, 0.0), (0.0, 0.0));
        for c in 0..self.channels {
            let r = c * m..(c + 1) * m;
            let templates = [&self.template[r.clone()], &other.template[r.clone()]];
            sums.blocks[c] = self.moments(&current[r], templates);
            add(&mut mine, self.of_sums(c, &sums.blocks[c], 4));
            add(&mut theirs, other.of_sums(c, &sums.blocks[c], 5));
        }
        sums.geometry = self.geometry;
        sums.channels = self.channels;
        (ratio(mine), ratio(theirs))
    }

    /// The weighted correlations' sum and the weights' from channel `channel`'s block sums of a
    /// patch, the products with this template being the `cross`-th of each block's.
    fn of_sums(&self, channel: usize, acc: &BlockSums, cross: usize) -> (f64, f64) {
        let (mut num, mut den) = (0.0, 0.0);
        let per = self.blocks.len() / self.channels.max(1);
        let blocks = self.blocks.iter().skip(channel * per).take(per);
        for (block, a) in blocks.zip(acc) {
            let Some((inv, ut, vt, n)) = block else {
                continue;
            };
            let uc = nalgebra::Vector3::new(a[0], a[1], a[2]);
            // Inner products of the residuals after the planes are removed.
            let vc = a[3] - uc.dot(&(inv * uc));
            let cov = a[cross] - ut.dot(&(inv * uc));
            if !(vc.is_finite() && cov.is_finite()) {
                continue;
            }
            let rho = if vc <= 1e-6 * n {
                0.0
            } else {
                (cov / (vt * vc).sqrt()).clamp(-1.0, 1.0)
            };
            num += vt * rho;
            den += vt;
        }
        (num, den)
    }
}

/// Adds a channel's weighted sums into the patch's.
fn add(total: &mut (f64, f64), part: (f64, f64)) {
    total.0 += part.0;
    total.1 += part.1;
}

/// The weighted mean of the blocks' correlations (0 without a weight).
fn ratio((num, den): (f64, f64)) -> f64 {
    if den > 0.0 { num / den } else { 0.0 }
}

/// The channels of a patch as long as `template` on a `res x res` grid: its whole number of
/// `res x res` parts, from 1 to [`MAX_CHANNELS`].
fn channels_of(template: &[f32], res: usize) -> usize {
    (template.len() / (res * res).max(1)).clamp(1, MAX_CHANNELS)
}

/// The blocks per side of a [`BlockCorrelation`] asked for `cells` on a `res x res` grid: at
/// least one, at most [`MAX_BLOCKS`] and `res`.
fn blocks_per_side(res: usize, cells: usize) -> usize {
    cells.clamp(1, MAX_BLOCKS).min(res.max(1))
}

/// Per block (at most [`MAX_BLOCKS`] per side), sums over a patch `c`: `c, c x, c y, c c`, then
/// `t c` for one or two templates `t`.
type BlockSums = [[f64; 6]; MAX_BLOCKS * MAX_BLOCKS];

/// A patch's block sums made by [`BlockCorrelation::of_pair`], kept to make it the template of
/// another correlation of the same grid ([`BlockCorrelation::set_template_from`]) without
/// summing it again.
#[derive(Clone, Debug)]
pub struct PatchSums {
    /// `(res, cells)` of the grid the sums are on (`None`: none made), and its channels.
    geometry: Option<(usize, usize)>,
    channels: usize,
    /// Each channel's.
    blocks: [BlockSums; MAX_CHANNELS],
}

impl Default for PatchSums {
    fn default() -> Self {
        PatchSums {
            geometry: None,
            channels: 0,
            blocks: [[[0.0; 6]; MAX_BLOCKS * MAX_BLOCKS]; MAX_CHANNELS],
        }
    }
}

/// The moments' column sums with AVX2 intrinsics (the build's CPU baseline, x86-64-v3).
#[cfg(simd = "avx2")]
mod simd {
    /// [`super::portable::column_sums`] of eight columns: the column sums in eight AVX
    /// registers down the rows (the same products and sums in the same order, so the same bits).
    pub(super) fn column_sums<const Q: usize>(
        p: &[f32],
        qs: [&[f32]; Q],
        res: usize,
        c0: usize,
        rows: std::ops::Range<usize>,
        origin: f64,
    ) -> [[f64; 5]; 8] {
        use std::arch::x86_64::*;
        assert!((1..=2).contains(&Q), "one or two cross products");
        if let Some(last) = rows.clone().last() {
            let end = last * res + c0 + 8;
            assert!(
                end <= p.len() && qs.iter().all(|q| end <= q.len()),
                "moments beyond the patches"
            );
        }
        let mut s = [[0f64; 5]; 8];
        // SAFETY: AVX2 is enabled at compile time (cfg); every load reads 8 values from
        // r res + c0 with r <= the last row, so up to the end asserted above.
        unsafe {
            let z = _mm256_setzero_pd();
            let (mut sp, mut spy, mut spp) = ([z; 2], [z; 2], [z; 2]);
            let mut sqp = [[z; 2]; Q];
            for r in rows {
                let y = _mm256_set1_pd(r as f64 - origin);
                let pr = p.as_ptr().add(r * res + c0);
                for h in 0..2 {
                    let v = _mm256_cvtps_pd(_mm_loadu_ps(pr.add(4 * h)));
                    sp[h] = _mm256_add_pd(sp[h], v);
                    spy[h] = _mm256_add_pd(spy[h], _mm256_mul_pd(v, y));
                    spp[h] = _mm256_add_pd(spp[h], _mm256_mul_pd(v, v));
                    for (acc, q) in sqp.iter_mut().zip(qs) {
                        let t = _mm256_cvtps_pd(_mm_loadu_ps(q.as_ptr().add(r * res + c0 + 4 * h)));
                        acc[h] = _mm256_add_pd(acc[h], _mm256_mul_pd(t, v));
                    }
                }
            }
            let mut lanes = [[0f64; 8]; 5];
            for (l, acc) in lanes.iter_mut().zip([sp, spy, spp].iter().chain(&sqp)) {
                _mm256_storeu_pd(l.as_mut_ptr(), acc[0]);
                _mm256_storeu_pd(l.as_mut_ptr().add(4), acc[1]);
            }
            for (k, sk) in s.iter_mut().enumerate() {
                *sk = std::array::from_fn(|i| lanes[i][k]);
            }
        }
        s
    }
}

/// The column sums in plain Rust: any number of columns (the last columns of a grid narrower
/// than [`MOMENT_COLUMNS`] on every build), the build for other CPUs, and compared with [`simd`]
/// by a test.
mod portable {
    /// The sums of `p`, `p y`, `p p` and `q p` for each `q` of `qs` (one or two, the rest of
    /// the five sums zero) down `W` neighbouring columns of `res x res` patches from `c0`, over
    /// `rows` (`y = r - origin`): the columns side by side in registers, row after row.
    #[inline(always)]
    pub(super) fn column_sums<const W: usize, const Q: usize>(
        p: &[f32],
        qs: [&[f32]; Q],
        res: usize,
        c0: usize,
        rows: std::ops::Range<usize>,
        origin: f64,
    ) -> [[f64; 5]; W] {
        let (mut sp, mut spy, mut spp) = ([0.0f64; W], [0.0f64; W], [0.0f64; W]);
        let mut sqp = [[0.0f64; W]; Q];
        for r in rows {
            let y = r as f64 - origin;
            let pr: &[f32; W] = p[r * res + c0..][..W].try_into().expect("W values");
            for k in 0..W {
                let v = pr[k] as f64;
                sp[k] += v;
                spy[k] += v * y;
                spp[k] += v * v;
                for (acc, q) in sqp.iter_mut().zip(qs) {
                    acc[k] += q[r * res + c0 + k] as f64 * v;
                }
            }
        }
        std::array::from_fn(|k| {
            let mut out = [sp[k], spy[k], spp[k], 0.0, 0.0];
            for (o, acc) in out[3..].iter_mut().zip(&sqp) {
                *o = acc[k];
            }
            out
        })
    }
}

#[cfg(not(simd = "avx2"))]
fn column_sums8<const Q: usize>(
    p: &[f32],
    qs: [&[f32]; Q],
    res: usize,
    c0: usize,
    rows: std::ops::Range<usize>,
    origin: f64,
) -> [[f64; 5]; MOMENT_COLUMNS] {
    portable::column_sums::<MOMENT_COLUMNS, Q>(p, qs, res, c0, rows, origin)
}
#[cfg(simd = "avx2")]
use simd::column_sums as column_sums8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::tests::{patch, smooth_patch};
    use crate::rng::Rng;

    #[test]
    fn the_block_correlation_ignores_light_that_varies_smoothly_and_sees_anything_else() {
        let mut rng = Rng::new(11);
        let res = 50;
        let t = patch(&mut rng, res * res);
        let same = block_correlation(&t, &t, res, 4);
        assert!((same - 1.0).abs() < 1e-9, "{same}");
        // A light field over the patch: a gain from 0.6 to 1.4 and a bias from -30 to +40 that vary
        // smoothly across it (a lamp's spot): within a block nearly a gain, a bias and a slope.
        let lit: Vec<f32> = (0..res * res)
            .map(|i| {
                let (x, y) = ((i % res) as f32 / res as f32, (i / res) as f32 / res as f32);
                let gain = 0.6 + 0.8 * x * y;
                let bias =
                    -30.0 + 70.0 * (-(x - 0.6).powi(2) / 0.1 - (y - 0.4).powi(2) / 0.1).exp();
                gain * t[i] + bias
            })
            .collect();
        let c = block_correlation(&t, &lit, res, 4);
        assert!(c > 0.97, "lit: {c}");
        // Without blocks (one block) the same light lowers it more.
        assert!(block_correlation(&t, &lit, res, 1) < c);
        // Another patch, or the same one shifted by a few samples: near 0.
        let other = patch(&mut rng, res * res);
        assert!(block_correlation(&t, &other, res, 4).abs() < 0.15);
        let shifted: Vec<f32> = (0..res * res).map(|i| t[(i + 3) % (res * res)]).collect();
        assert!(block_correlation(&t, &shifted, res, 4).abs() < 0.15);
        // The negative, -1; flat patches, 0; never NaN.
        let neg: Vec<f32> = t.iter().map(|v| 255.0 - v).collect();
        assert!((block_correlation(&t, &neg, res, 4) + 1.0).abs() < 1e-9);
        let flat = vec![100.0f32; res * res];
        assert_eq!(block_correlation(&flat, &t, res, 4), 0.0);
        assert_eq!(block_correlation(&t, &flat, res, 4), 0.0);
        let nan = vec![f32::NAN; res * res];
        assert_eq!(block_correlation(&t, &nan, res, 4), 0.0);
        // Too many blocks for the patch, or a short patch: still defined.
        assert!(block_correlation(&t[..16], &t[..16], 4, 8).is_finite());
        assert_eq!(block_correlation(&t[..10], &t[..10], 50, 4), 0.0);
    }

    /// The block moments are their definition: per block, sums over its samples.
    /// A mask leaves out the blocks it covers a tenth or more of: a patch that differs from
    /// the template only there is then the template; the mask stays for the templates set
    /// after it (the previous frame's patch each frame).
    #[test]
    fn a_mask_leaves_its_blocks_out() {
        let mut rng = Rng::new(12);
        let res = 40;
        let t = smooth_patch(&mut rng, res);
        // The left 30 % replaced by noise.
        let mut c = t.clone();
        for (i, v) in c.iter_mut().enumerate() {
            if ((i % res) as f64 + 0.5) / (res as f64) < 0.3 {
                *v = rng.range(0.0, 255.0) as f32;
            }
        }
        let mut bc = BlockCorrelation::new(&t, res, 4);
        let whole = bc.of(&c);
        assert!(whole < 0.8, "{whole}");
        bc.set_mask(Some([0.0, 0.0, 0.3, 1.0]));
        assert!(bc.of(&c) > 0.999, "{}", bc.of(&c));
        bc.set_template(&t, res, 4);
        assert!(bc.of(&c) > 0.999);
        // Blocks covered less than a tenth are kept (this one covers a twentieth of the third
        // column of blocks, whose noise is then seen).
        let mut thin = BlockCorrelation::new(&t, res, 4);
        thin.set_mask(Some([0.0, 0.0, 0.2625, 1.0]));
        assert!(thin.of(&c) < 0.999);
        bc.set_mask(None);
        bc.set_template(&t, res, 4);
        assert_eq!(bc.of(&c), whole);
    }

    #[test]
    fn block_moments_are_sums_over_each_blocks_samples() {
        let mut rng = crate::rng::Rng::new(3);
        for (res, cells) in [(50, 4), (7, 3), (130, 8), (64, 5), (3, 3)] {
            let p: Vec<f32> = (0..res * res)
                .map(|_| rng.range(0.0, 255.0) as f32)
                .collect();
            let q: Vec<f32> = (0..res * res)
                .map(|_| rng.range(0.0, 255.0) as f32)
                .collect();
            let q2: Vec<f32> = (0..res * res)
                .map(|_| rng.range(0.0, 255.0) as f32)
                .collect();
            let bc = BlockCorrelation::new(&q, res, cells);
            let got = bc.moments(&p, [&q]);
            // With a second cross product, every other sum is the same, bit for bit.
            let both = bc.moments(&p, [&q, &q2]);
            for (g, b) in got.iter().zip(&both) {
                assert_eq!(g[..5], b[..5], "{res} {cells}");
                assert_eq!(g[5], 0.0);
            }
            // The eight-column kernel (AVX where built for it): the plain sums, bit for bit.
            if res >= 8 {
                for (c0, rows) in [(0, 0..res), (res - 8, 1..res.min(5)), (res / 3, 2..2)] {
                    assert_eq!(
                        super::column_sums8(&p, [&q], res, c0, rows.clone(), 1.5),
                        super::portable::column_sums::<8, 1>(&p, [&q], res, c0, rows.clone(), 1.5),
                        "{res} from column {c0}"
                    );
                    assert_eq!(
                        super::column_sums8(&p, [&q, &q2], res, c0, rows.clone(), 1.5),
                        super::portable::column_sums::<8, 2>(&p, [&q, &q2], res, c0, rows, 1.5),
                        "{res} from column {c0}, two templates"
                    );
                }
            }
            let mut want = [[0.0f64; 6]; super::MAX_BLOCKS * super::MAX_BLOCKS];
            for r in 0..res {
                for c in 0..res {
                    let (br, bcol) = (r * cells / res, c * cells / res);
                    let y = (r - br * res / cells) as f64;
                    let x = (c - bcol * res / cells) as f64;
                    let (v, t) = (p[r * res + c] as f64, q[r * res + c] as f64);
                    let t2 = q2[r * res + c] as f64;
                    let a = &mut want[br * cells + bcol];
                    for (s, term) in a.iter_mut().zip([v, v * x, v * y, v * v, t * v, t2 * v]) {
                        *s += term;
                    }
                }
            }
            for (g, w) in both.iter().zip(&want) {
                for (a, b) in g.iter().zip(w) {
                    assert!(
                        (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                        "{res} {cells}: {a} {b}"
                    );
                }
            }
        }
    }

    /// One pass for two correlations of the same grid gives what each gives alone, bit for bit,
    /// and its sums make the patch another's template as `set_template` makes it; correlations of
    /// other grids, or without a template, fall back to a pass each.
    #[test]
    fn a_pair_of_confidences_in_one_pass_is_each_alone() {
        let mut rng = crate::rng::Rng::new(5);
        let mut draw = |n: usize| -> Vec<f32> {
            (0..n * n)
                .map(|i| ((i % n) as f32 * 0.3).sin() * 40.0 + rng.normal() as f32 * 5.0 + 100.0)
                .collect()
        };
        for (res, cells) in [(50, 4), (13, 3), (24, 8), (12, 3)] {
            let (t, prev, cur) = (draw(res), draw(res), draw(res));
            let a = BlockCorrelation::new(&t, res, cells);
            let b = BlockCorrelation::new(&prev, res, cells);
            let mut sums = PatchSums::default();
            let (ca, cb) = a.of_pair(&b, &cur, &mut sums);
            assert_eq!(ca.to_bits(), a.of(&cur).to_bits(), "{res} {cells}");
            assert_eq!(cb.to_bits(), b.of(&cur).to_bits(), "{res} {cells}");
            assert!(ca.abs() > 0.0 && ca != cb, "{res} {cells}: {ca} {cb}");
            // The patch as the next template, from its sums and summed again.
            let mut from = b.clone();
            from.set_template_from(&cur, res, cells, &sums);
            let mut again = b.clone();
            again.set_template(&cur, res, cells);
            let next = draw(res);
            assert_eq!(from.of(&next).to_bits(), again.of(&next).to_bits());
            assert_eq!(from.of(&cur), again.of(&cur));
            // Sums of another grid are not used.
            let mut other = BlockCorrelation::default();
            other.set_template_from(&cur[..res * res - res], res - 1, cells, &sums);
            let fresh = BlockCorrelation::new(&cur[..(res - 1) * (res - 1)], res - 1, cells);
            let probe = &next[..(res - 1) * (res - 1)];
            assert_eq!(other.of(probe).to_bits(), fresh.of(probe).to_bits());
        }
        // Another grid, or no template: each alone.
        let (t, cur) = (draw(20), draw(20));
        let a = BlockCorrelation::new(&t, 20, 4);
        let b = BlockCorrelation::new(&t, 20, 5);
        let mut sums = PatchSums::default();
        assert_eq!(a.of_pair(&b, &cur, &mut sums), (a.of(&cur), b.of(&cur)));
        let empty = BlockCorrelation::default();
        assert_eq!(a.of_pair(&empty, &cur, &mut sums), (a.of(&cur), 0.0));
    }

    /// A colour patch (three `res x res` channels one after the other): each channel's blocks
    /// count as a grey patch's, so a channel flat in the template adds nothing (the other
    /// channels' confidence, to the bit), one shown negated pulls it down, and the pair in one
    /// pass, the sums kept for the next template and a mask work on every channel.
    #[test]
    fn a_colour_patch_is_its_channels_blocks() {
        let mut rng = crate::rng::Rng::new(17);
        let (res, cells) = (30, 4);
        let mut draw = || -> Vec<f32> {
            (0..res * res)
                .map(|_| rng.range(20.0, 230.0) as f32)
                .collect()
        };
        let (r, g, b) = (draw(), draw(), draw());
        let colour = |a: &[f32], b: &[f32], c: &[f32]| -> Vec<f32> {
            a.iter().chain(b).chain(c).copied().collect()
        };
        let t = colour(&r, &g, &b);
        let same = BlockCorrelation::new(&t, res, cells).of(&t);
        assert!((same - 1.0).abs() < 1e-9, "{same}");
        // Flat green and blue in the template: red's confidence alone, whatever they show.
        let flat = vec![90.0f32; res * res];
        let red_only = BlockCorrelation::new(&colour(&r, &flat, &flat), res, cells);
        let seen = colour(&g, &b, &r);
        let grey = BlockCorrelation::new(&r, res, cells);
        assert_eq!(red_only.of(&seen).to_bits(), grey.of(&g).to_bits());
        // Blue negated: about (1 + 1 - 1) / 3.
        let neg: Vec<f32> = b.iter().map(|v| 255.0 - v).collect();
        let c = BlockCorrelation::new(&t, res, cells).of(&colour(&r, &g, &neg));
        assert!((c - 1.0 / 3.0).abs() < 0.05, "{c}");
        // A short patch: 0.
        assert_eq!(
            BlockCorrelation::new(&t, res, cells).of(&t[..2 * res * res]),
            0.0
        );
        // The pair in one pass, and its sums as the next template.
        let (a, prev) = (BlockCorrelation::new(&t, res, cells), colour(&b, &r, &g));
        let bc = BlockCorrelation::new(&prev, res, cells);
        let cur = colour(&draw(), &g, &r);
        let mut sums = PatchSums::default();
        let (ca, cb) = a.of_pair(&bc, &cur, &mut sums);
        assert_eq!(
            (ca.to_bits(), cb.to_bits()),
            (a.of(&cur).to_bits(), bc.of(&cur).to_bits())
        );
        let mut from = bc.clone();
        from.set_template_from(&cur, res, cells, &sums);
        let again = BlockCorrelation::new(&cur, res, cells);
        assert_eq!(from.of(&t).to_bits(), again.of(&t).to_bits());
        // A mask over the left half: a patch that differs only there, in every channel, is the
        // template.
        let mut masked = BlockCorrelation::new(&t, res, cells);
        masked.set_mask(Some([0.0, 0.0, 0.5, 1.0]));
        let mut left = t.clone();
        for (i, v) in left.iter_mut().enumerate() {
            if i % res < res / 2 - 1 {
                *v = 255.0 - *v;
            }
        }
        assert!(
            (masked.of(&left) - 1.0).abs() < 1e-9,
            "{}",
            masked.of(&left)
        );
    }

    /// A [`BlockCorrelation`] set again to other templates (as the tracker does every frame,
    /// keeping the grid's sums) gives exactly what a fresh one gives, also when the grid changes.
    #[test]
    fn block_correlation_reused_equals_fresh() {
        let mut rng = crate::rng::Rng::new(7);
        let patch = |n: usize, rng: &mut crate::rng::Rng| -> Vec<f32> {
            (0..n * n)
                .map(|i| ((i % n) as f32 * 0.3).sin() * 40.0 + rng.normal() as f32 * 5.0 + 100.0)
                .collect()
        };
        let mut reused = BlockCorrelation::default();
        for (res, cells) in [(50, 4), (50, 4), (21, 3), (50, 4), (9, 8)] {
            let (t, c) = (patch(res, &mut rng), patch(res, &mut rng));
            reused.set_template(&t, res, cells);
            let fresh = BlockCorrelation::new(&t, res, cells);
            assert_eq!(
                reused.of(&c).to_bits(),
                fresh.of(&c).to_bits(),
                "{res} {cells}"
            );
            assert_eq!(
                reused.of(&t).to_bits(),
                fresh.of(&t).to_bits(),
                "{res} {cells}"
            );
        }
    }

    /// The block correlation against its definition written plainly: per block, a plane fitted to
    /// each patch by least squares (global coordinates: the fit does not depend on the origin), the
    /// residuals correlated, the blocks averaged with the template's residual variance as weight.
    #[test]
    fn the_block_correlation_is_its_definition() {
        let mut rng = Rng::new(5);
        for &(res, cells) in &[(50usize, 4usize), (13, 3), (7, 7), (21, 8), (5, 4)] {
            let t = smooth_patch(&mut rng, res);
            let c: Vec<f32> = t
                .iter()
                .enumerate()
                .map(|(i, &v)| 0.8 * v + 0.3 * (i % res) as f32 + rng.range(-9.0, 9.0) as f32)
                .collect();
            let mut blocks: Vec<Vec<(f64, f64, f64, f64)>> = vec![Vec::new(); cells * cells];
            for r in 0..res {
                for col in 0..res {
                    let b = (r * cells / res) * cells + col * cells / res;
                    let i = r * res + col;
                    blocks[b].push((col as f64, r as f64, t[i] as f64, c[i] as f64));
                }
            }
            let residuals = |pts: &[(f64, f64, f64, f64)],
                             pick: fn(&(f64, f64, f64, f64)) -> f64| {
                let a =
                    nalgebra::DMatrix::from_fn(pts.len(), 3, |i, k| [1.0, pts[i].0, pts[i].1][k]);
                let z = nalgebra::DVector::from_iterator(pts.len(), pts.iter().map(pick));
                // A block one sample wide or high has no plane: it is left out.
                let inv = (a.transpose() * &a).try_inverse()?;
                let coef = inv * a.transpose() * &z;
                Some(z - a * coef)
            };
            let (mut num, mut den) = (0.0, 0.0);
            for pts in blocks.iter().filter(|b| b.len() >= 4) {
                let (Some(rt), Some(rc)) = (residuals(pts, |p| p.2), residuals(pts, |p| p.3))
                else {
                    continue;
                };
                let (vt, vc) = (rt.dot(&rt), rc.dot(&rc));
                num += vt * rt.dot(&rc) / (vt * vc).sqrt();
                den += vt;
            }
            // No block with a plane: 0.
            let want = if den > 0.0 { num / den } else { 0.0 };
            let got = block_correlation(&t, &c, res, cells);
            assert!((got - want).abs() < 1e-9, "{res} {cells}: {got} vs {want}");
        }
    }
}
