//! The joint-histogram core shared by MI and CCRE: a joint probability of the template and
//! current intensities estimated with a cubic B-spline Parzen window (Dame and Marchand), a
//! similarity `F(p)` of it, and the exact derivatives of `F` with respect to either patch.
//!
//! ## The histogram
//!
//! An intensity `v` is scaled to bin units `s = v (B - 1) / 255` with `B` bins (the parameter
//! `bins` of MI and CCRE, default 16; KLD uses 8; with 8, `0..255` spans `0..7`); the cubic
//! B-spline `beta` (support `(-2, 2)`, C2, a partition of unity: `sum_a beta(a - s) = 1` for every
//! `s`) spreads it over the four bins `floor(s) - 1 .. floor(s) + 2`, Dame and Marchand's "B bins +
//! 3 padding bins" for grey levels in `0..255`. Values outside `0..255` simply use further padding
//! bins (the similarity does not depend on how many empty bins there are), up to `-255..510`,
//! beyond which they are clamped (zero derivative).
//! With `t_i`, `c_i` the scaled template and current intensities:
//!
//! `p(a, b) = 1/N sum_i beta(a - t_i) beta(b - c_i)`, `p_t(a) = sum_b p(a, b)`,
//! `p_c(b) = sum_a p(a, b)`.
//!
//! The weights are f32 (two pixels' four in one 8-lane register); the template's are also kept
//! in f64. Each pixel adds its 16 products `beta(a - t_i) beta(b - c_i)` (exact in f64) into the
//! f64 block of its pair of first bins (four aligned multiply-adds: neighbouring pixels' rows of
//! cells overlap in part, and a row read-modify-write then waits for the last one's store), and
//! the blocks are added into the histogram. The sums stay f64: CCRE's optimum with 8 bins is
//! flat enough for f32 sums to move it.
//!
//! ## Derivatives, for any `F(p)`
//!
//! Write `x_j` for the pixel the derivative is taken with respect to (`c_j` for the current
//! pixels, `t_j` for the template's) and `k = (B - 1) / 255` the scale. Only the 16 cells of
//! pixel `j` move:
//! `dp(a, b)/dx_j = k/N beta(a - t_j) beta'(b - c_j)` (current) or `k/N beta'(a - t_j) beta(b - c_j)`
//! (template), where `beta'` is the derivative with respect to the intensity's bin coordinate.
//! With `G(a, b) = dF/dp(a, b)` (the marginals being functions of `p`):
//!
//! - gradient: `dF/dx_j = sum_ab G(a, b) dp(a, b)/dx_j` (16 terms per pixel);
//! - Hessian: `d2F/dx_j dx_l = delta_jl sum_ab G(a, b) d2p(a, b)/dx_j^2 +
//!   sum_{ab, a'b'} dp(a, b)/dx_j (d2F/dp(a, b) dp(a', b')) dp(a', b')/dx_l`.
//!
//! Projected on the pixel Jacobian `J` (rows `J_j`, `dof` wide) the second term only needs
//! `V(a, b) = sum_j dp(a, b)/dx_j J_j` (one `dof`-vector per cell, `O(16 N dof)`), so that
//! `J^T H J = sum_j D_j J_j J_j^T + Q(V)` with `D_j = sum_ab G(a, b) d2p(a, b)/dx_j^2` and `Q` the
//! quadratic form of `d2F/dp2` applied to `V`: `O(bins^2 dof^2)`, never `N x N`.
//!
//! **MI**: `F = sum_ab p log(p / (p_t p_c))`. `dF/dp(a, b) = log(p(a, b) / (p_t(a) p_c(b))) - 1`;
//! the constant drops out, since `sum_ab dp(a, b)/dx_j = 0` (partition of unity), and so does
//! `log p_t(a)` for the current pixels (`sum_b dp(a, b)/dc_j = 0`: `p_t` does not move), which
//! leaves Dame and Marchand's `sum_ab dp/dc_j log(p / p_c)`. The quadratic form, from the
//! second differential of `sum p log p - sum p_t log p_t - sum p_c log p_c`:
//! `Q = sum_ab V V^T / p - sum_a V_a V_a^T / p_t(a) - sum_b V_b V_b^T / p_c(b)` with
//! `V_a = sum_b V(a, b)` (zero for the current pixels) and `V_b = sum_a V(a, b)`.
//!
//! **CCRE** (cumulative over the template intensity): `P(a, b) = sum_{a' <= a} p(a', b)`,
//! `P_t(a) = sum_b P(a, b)` (the template's cumulative distribution), and
//! `F = sum_ab P log(P / (P_t p_c)) = sum P log P - sum_a P_t log P_t - sum_ab P log p_c`.
//! With `S(b) = sum_a P(a, b)` and `L(a, b) = log(P / (P_t p_c))`:
//! `dF/dp(a, b) = sum_{a' >= a} L(a', b) - S(b) / p_c(b)` (the `+1`s of the entropies cancel);
//! second differential, with `U(a, b) = sum_{a' <= a} V(a', b)`, `U_a = sum_b U(a, b)`,
//! `X_b = sum_a U(a, b)`, `W_b = sum_a V(a, b)`:
//! `Q = sum_ab U U^T / P - sum_a U_a U_a^T / P_t - sum_b (X_b W_b^T + W_b X_b^T) / p_c +
//! sum_b S(b) W_b W_b^T / p_c^2`.
//! Rows of the histogram above the template's data (`P = p_c`, `P_t = 1`) contribute nothing to
//! `F` or its derivatives, so only the bins in use are visited. Cells with `P = 0` (or `p = 0`)
//! contribute `0 log 0 = 0`; their derivatives vanish too (the B-spline and its first two
//! derivatives are zero at the end of its support).
//!
//! ## Hessian kinds
//!
//! - Newton: the above at the current patch.
//! - After convergence: the above with the current patch replaced by the template (its
//!   statistics and the per-pixel diagonal terms are computed once per template and kept).
//!   Both weights of a pixel are then the template's, functions of one fraction `f`: a bin's
//!   16 cells of `V` are fixed combinations of six Bernstein sums `sum_j b_m(f_j) J_j` over the
//!   template's pixels in that bin, summed in registers along the pixels grouped by bin once
//!   per template (`SameBin`).
//! - Gauss-Newton: these models are maximised and their "first-order" term `Q` is positive
//!   semi-definite (by Cauchy-Schwarz for MI), so the least-squares Gauss-Newton idea does not
//!   apply. What is used is the negative semi-definite part of the projected Newton Hessian
//!   (its eigen-decomposition with the positive eigenvalues set to zero): an ascent direction
//!   always, and equal to Newton wherever Newton is already negative semi-definite, as at
//!   convergence.
//!
//! The statistics of the last patch (weights, histogram, `G`) are kept from the similarity or
//! gradient call and reused by the Hessian when it is asked for the same patch (recomputed
//! otherwise, e.g. when a search method asks for a Hessian first). When the Hessians are Newton's
//! at the current patch, the gradient's pass also makes the Hessian's per-pixel diagonal terms.

use crate::linalg::{MAX_DOF, negative_part};

/// The largest number of warp parameters these models take (a cell's lanes, one AVX register).
pub(crate) const PDOF: usize = 8;

/// The paper's and MTF's bins (KLD's, and the weights' default).
pub(crate) const DEFAULT_BINS: usize = 8;
/// Bin units per grey level, with [`DEFAULT_BINS`].
pub(crate) const SCALE: f64 = (DEFAULT_BINS - 1) as f64 / 255.0;
/// Histogram side, with [`DEFAULT_BINS`].
pub(crate) const SIDE: usize = 3 * DEFAULT_BINS + 1;

/// The number of bins, parameter `bins` of MI and CCRE: fewer bins smooth the joint histogram
/// (a wider basin), more bins sharpen it (a less biased optimum, see `tests/it/recovery.rs`).
///
/// The default is 16, not the paper's 8. With 8 bins the optimum of MI under a homography is
/// 1.2 px from the truth on the recovery texture (CCRE 0.7 px), with 16 0.3 px (CCRE 0.1 px).
/// On the evidence set (`regtrack eval --dataset target/evidence/data --reinit --param bins=B`,
/// mean SR, 8 -> 16 bins): FCLK-MI 0.484 -> 0.549, ICLK-MI 0.517 -> 0.560, ESM-MI 0.554 -> 0.544,
/// FCLK-CCRE 0.489 -> 0.568, ICLK-CCRE 0.455 -> 0.526, ESM-CCRE 0.549 -> 0.564, NN10K-MI 0.650 ->
/// 0.705, NNIC-MI 0.610 -> 0.710, NNIC-CCRE 0.492 -> 0.634. 32 bins is no better than 16 there
/// (FCLK-MI 0.526, ESM-CCRE 0.574). `--param bins=8` gives the paper's models.
pub(crate) const BINS_PARAM: crate::params::ParamDef = crate::params::ParamDef::int(
    "bins",
    "histogram bins over the grey levels 0..255 (the paper and MTF: 8; more: a less biased optimum, a narrower basin)",
    4.0,
    64.0,
    16.0,
);

/// The parameters of MI and CCRE: the histogram's bins.
pub(crate) const PARAMS: [crate::params::ParamDef; 1] = [BINS_PARAM];

/// The binning: `B` bins spanning grey levels `0..255`, bin coordinates clamped to
/// `-(B - 1)..2 (B - 1)` (grey levels `-255..510`), histogram index `floor(s) - 1 + B` of the
/// first of a value's four bins, `3 B + 1` histogram cells per side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bins {
    /// Bin units per grey level.
    pub scale: f64,
    s_min: f64,
    s_max: f64,
    offset: i64,
    /// Histogram side.
    pub side: usize,
}

impl Bins {
    pub fn new(bins: usize) -> Self {
        let b = bins.max(2);
        Bins {
            scale: (b - 1) as f64 / 255.0,
            s_min: -((b - 1) as f64),
            s_max: 2.0 * (b - 1) as f64,
            offset: b as i64,
            side: 3 * b + 1,
        }
    }
}

impl Default for Bins {
    fn default() -> Self {
        Bins::new(DEFAULT_BINS)
    }
}

/// Which function of the joint histogram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Measure {
    Mi,
    Ccre,
}

/// The B-spline weights of every pixel of a patch: the first of its four bins, the weights, and
/// their first and second derivatives with respect to the bin coordinate (`d` and `d2` are
/// those of the last values once [`Weights::fill_with`] or [`Weights::fill_derivatives`] ran).
#[derive(Clone, Debug, Default)]
pub(crate) struct Weights {
    pub base: Vec<u32>,
    pub w: Vec<[f32; 4]>,
    pub d: Vec<[f32; 4]>,
    pub d2: Vec<[f32; 4]>,
    /// Range of histogram indices in use (`lo..hi`).
    pub lo: usize,
    pub hi: usize,
    /// Each pixel's fraction of a bin and whether it is inside the bins' range (1 or 0): what
    /// the derivatives are made from.
    fr: Vec<f32>,
    inside: Vec<f32>,
    /// Whether `d`, and `d2`, are those of the values `w` was filled with.
    derivatives: bool,
    second: bool,
    /// The template's `w`, `d`, `d2` in f64 ([`Weights::widen`]): the bilinear forms' left
    /// side, broadcast lane by lane.
    pub w64: Vec<[f64; 4]>,
    pub d64: Vec<[f64; 4]>,
    pub d2_64: Vec<[f64; 4]>,
}

/// The cubic B-spline's four weights as polynomials in the fraction `f` of a bin coordinate:
/// `w_k = A_k + B_k f + C_k f^2 + D_k f^3`, so each of `w`, `dw/df` and `d2w/df2` is one
/// four-lane expression (in f32: two pixels' weights fill one 8-lane register; `V` sums f32
/// products, the histogram exact f64 products of them).
const A: [f32; 4] = [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0, 0.0];
const B: [f32; 4] = [-0.5, 0.0, 0.5, 0.0];
const C: [f32; 4] = [0.5, -1.0, 0.5, 0.0];
const D: [f32; 4] = [-1.0 / 6.0, 0.5, -0.5, 1.0 / 6.0];

/// The four weights of fraction `f` and their derivatives (times `inside`, 0 or 1).
#[inline(always)]
fn spline(f: f32, inside: f32, w: &mut [f32; 4], d: &mut [f32; 4], d2: &mut [f32; 4]) {
    for k in 0..4 {
        w[k] = D[k].mul_add(f, C[k]).mul_add(f, B[k]).mul_add(f, A[k]);
        d[k] = (3.0 * D[k]).mul_add(f, 2.0 * C[k]).mul_add(f, B[k]) * inside;
        d2[k] = (6.0 * D[k]).mul_add(f, 2.0 * C[k]) * inside;
    }
}

/// Pixels `i` and `i + 1` of `v`.
#[inline(always)]
fn pair(v: &mut [[f32; 4]], i: usize) -> &mut [[f32; 4]; 2] {
    (&mut v[i..i + 2]).try_into().expect("two")
}

/// [`spline`] of two pixels at once (their eight weights in one register; the same bits).
#[inline(always)]
fn spline_pair(
    f: [f32; 2],
    inside: [f32; 2],
    w: &mut [[f32; 4]; 2],
    d: &mut [[f32; 4]; 2],
    d2: &mut [[f32; 4]; 2],
) {
    #[cfg(simd = "avx2")]
    // SAFETY: AVX2 and FMA are enabled at compile time (cfg); each store writes the eight
    // values of a `[[f32; 4]; 2]`, each load reads the four of a `[f32; 4]`.
    unsafe {
        use std::arch::x86_64::*;
        let twice = |a: &[f32; 4]| {
            let q = _mm_loadu_ps(a.as_ptr());
            _mm256_set_m128(q, q)
        };
        let halves = |v: [f32; 2]| _mm256_set_m128(_mm_set1_ps(v[1]), _mm_set1_ps(v[0]));
        let (a, b, c, dd) = (twice(&A), twice(&B), twice(&C), twice(&D));
        let (fv, m) = (halves(f), halves(inside));
        let wv = _mm256_fmadd_ps(_mm256_fmadd_ps(_mm256_fmadd_ps(dd, fv, c), fv, b), fv, a);
        let c2 = _mm256_mul_ps(_mm256_set1_ps(2.0), c);
        let d3 = _mm256_mul_ps(_mm256_set1_ps(3.0), dd);
        let d6 = _mm256_mul_ps(_mm256_set1_ps(6.0), dd);
        let dv = _mm256_fmadd_ps(_mm256_fmadd_ps(d3, fv, c2), fv, b);
        let d2v = _mm256_fmadd_ps(d6, fv, c2);
        _mm256_storeu_ps(w.as_mut_ptr() as *mut f32, wv);
        _mm256_storeu_ps(d.as_mut_ptr() as *mut f32, _mm256_mul_ps(dv, m));
        _mm256_storeu_ps(d2.as_mut_ptr() as *mut f32, _mm256_mul_ps(d2v, m));
    }
    #[cfg(not(simd = "avx2"))]
    for k in 0..2 {
        spline(f[k], inside[k], &mut w[k], &mut d[k], &mut d2[k]);
    }
}

/// A value's first bin, its fraction of a bin and whether it is inside the bins' range (1) or
/// clamped to it (0; a value that is not finite is bin coordinate 0).
#[inline(always)]
fn bin_coordinate(v: f32, bins: &Bins) -> (usize, f32, f32) {
    let raw = v as f64 * bins.scale;
    let s = if raw.is_finite() {
        raw.clamp(bins.s_min, bins.s_max)
    } else {
        0.0
    };
    // Outside the bins' range the derivatives are zero (the value is clamped).
    let inside = if s == raw { 1.0 } else { 0.0 };
    let fl = s.floor();
    (
        (fl as i64 - 1 + bins.offset) as usize,
        (s - fl) as f32,
        inside,
    )
}

/// [`bin_coordinate`] of four values at once (AVX2).
#[cfg(simd = "avx2")]
#[inline(always)]
fn bin_coordinates4(
    v: &[f32; 4],
    bins: &Bins,
    first: &mut [u32; 4],
    fr: &mut [f32; 4],
    inside: &mut [f32; 4],
) {
    // SAFETY: AVX2 is enabled at compile time (cfg); every load and store reads or writes the
    // four values of a fixed-size array.
    unsafe {
        use std::arch::x86_64::*;
        let raw = _mm256_mul_pd(
            _mm256_cvtps_pd(_mm_loadu_ps(v.as_ptr())),
            _mm256_set1_pd(bins.scale),
        );
        // raw - raw is 0 for a finite value, NaN otherwise.
        let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(raw, raw), _mm256_setzero_pd());
        let clamped = _mm256_min_pd(
            _mm256_max_pd(raw, _mm256_set1_pd(bins.s_min)),
            _mm256_set1_pd(bins.s_max),
        );
        let s = _mm256_and_pd(clamped, finite);
        let ins = _mm256_and_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(s, raw), _mm256_set1_pd(1.0));
        let fl = _mm256_floor_pd(s);
        let b = _mm_add_epi32(
            _mm256_cvttpd_epi32(fl),
            _mm_set1_epi32((bins.offset - 1) as i32),
        );
        _mm_storeu_si128(first.as_mut_ptr() as *mut __m128i, b);
        _mm_storeu_ps(fr.as_mut_ptr(), _mm256_cvtpd_ps(_mm256_sub_pd(s, fl)));
        _mm_storeu_ps(inside.as_mut_ptr(), _mm256_cvtpd_ps(ins));
    }
}

/// The joint histogram's 4 x 4 cells of one pair of first bins (template's, current's), row `u`
/// at `4 u`, on a 128-byte boundary: a pixel adds its 16 products with four aligned 4-lane
/// multiply-adds to one block (rather than four read-modify-writes of rows `side` apart, which
/// neighbouring pixels overlap in part, so that each waits for the last one's store to reach
/// the cache). f64: with f32 sums (two 8-lane updates a pixel, no faster in a loop) CCRE with 8
/// bins no longer converged to its own optimum from 3 of 20 starts (`tests/it/recovery.rs`,
/// `more_bins_make_the_histogram_models_less_biased`): its optimum is that flat.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(128))]
struct Block([f64; 16]);

/// `block[4 u + v] += x_u y_v` (each product exact, fused).
#[inline(always)]
fn add_block(block: &mut Block, x: &[f64; 4], y: &[f32; 4]) {
    #[cfg(simd = "avx2")]
    // SAFETY: AVX2 and FMA are enabled at compile time (cfg); the loads read the four values
    // of `x` and `y`, the aligned loads and stores the four rows of the 128-byte aligned block.
    unsafe {
        use std::arch::x86_64::*;
        let yv = _mm256_cvtps_pd(_mm_loadu_ps(y.as_ptr()));
        let q = block.0.as_mut_ptr();
        for (u, xu) in x.iter().enumerate() {
            let r = q.add(4 * u);
            _mm256_store_pd(
                r,
                _mm256_fmadd_pd(_mm256_broadcast_sd(xu), yv, _mm256_load_pd(r)),
            );
        }
    }
    #[cfg(not(simd = "avx2"))]
    add_block_portable(block, x, y);
}

/// `row[0..4] += block row`.
#[inline(always)]
fn add_block_row(row: &mut [f64], block: &[f64]) {
    for (r, &b) in row[..4].iter_mut().zip(&block[..4]) {
        *r += b;
    }
}

/// The joint histogram's sums (not yet divided by the pixels' count) of the template's
/// weights `t` (their f64 copies, [`Weights::widen`]) and the current patch's `c` into `p`
/// (`side x side`; the cells of rows `t.lo..t.hi` and columns `c.lo..c.hi` are set, the others
/// are not touched): each pixel's 16 products into the [`Block`] of its pair of first bins,
/// then each block into its cells.
fn joint_histogram(p: &mut [f64], blocks: &mut Vec<Block>, side: usize, t: &Weights, c: &Weights) {
    let (r0, r1) = (t.lo, t.hi);
    let (c0, c1) = (c.lo, c.hi);
    for a in r0..r1 {
        p[a * side + c0..a * side + c1].fill(0.0);
    }
    // The first bins run over `lo..hi - 3` (`hi` is the last one's fourth bin, plus one).
    if r1 < r0 + 4 || c1 < c0 + 4 {
        return;
    }
    assert_eq!(t.w64.len(), t.base.len(), "the template's weights widened");
    let (rows, cols) = (r1 - 3 - r0, c1 - 3 - c0);
    blocks.clear();
    // As many as any current patch can need (no allocation in a tracker's update once the
    // template is set).
    blocks.reserve(rows * (side - 3));
    blocks.resize(rows * cols, Block::default());
    let bases = t.base.iter().zip(&c.base);
    for ((&ta, &cb), (x, y)) in bases.zip(t.w64.iter().zip(&c.w)) {
        let k = (ta as usize - r0) * cols + (cb as usize - c0);
        add_block(&mut blocks[k], x, y);
    }
    // Block (a, b)'s row u goes to cells (a + u, b..b + 4). Along a row of blocks, every
    // fourth block first (their cells are disjoint), then the next: no update reads cells that
    // the one just before wrote in part. Blocks no pixel fell in are skipped: cell (1, 1) of a
    // pixel's block is `w_1 w_1 >= 1 / 36` (`w_1 = 2/3 - f^2 + f^3 / 2`).
    for (a, line) in blocks.chunks_exact(cols).enumerate() {
        for phase in 0..4 {
            for b in (phase..cols).step_by(4) {
                let block = &line[b].0;
                if block[5] == 0.0 {
                    continue;
                }
                for u in 0..4 {
                    let at = (r0 + a + u) * side + c0 + b;
                    add_block_row(&mut p[at..at + 4], &block[4 * u..4 * u + 4]);
                }
            }
        }
    }
}

/// `sum_uv x_u cells[u side + v] y_v` over the 4 x 4 cells (rows `side` apart) of one pixel.
#[inline(always)]
fn bilinear_form(cells: &[f64], side: usize, x: &[f64; 4], y: &[f32; 4]) -> f64 {
    assert!(cells.len() >= 3 * side + 4);
    #[cfg(simd = "avx2")]
    // SAFETY: AVX2 and FMA are enabled at compile time (cfg); row u reads cells u side ..
    // u side + 4, inside `cells` (asserted above).
    unsafe {
        use std::arch::x86_64::*;
        let p = cells.as_ptr();
        let mut rows = _mm256_mul_pd(_mm256_set1_pd(x[0]), _mm256_loadu_pd(p));
        for u in 1..4 {
            rows = _mm256_fmadd_pd(_mm256_set1_pd(x[u]), _mm256_loadu_pd(p.add(u * side)), rows);
        }
        let mut r = [0.0; 4];
        _mm256_storeu_pd(
            r.as_mut_ptr(),
            _mm256_mul_pd(rows, _mm256_cvtps_pd(_mm_loadu_ps(y.as_ptr()))),
        );
        (r[0] + r[1]) + (r[2] + r[3])
    }
    #[cfg(not(simd = "avx2"))]
    bilinear_form_portable(cells, side, x, y)
}

/// `outs[m][i] = (ks[m] * bilinear_form(cells from ta[i] side + cb[i], x[i], ys[m][i])) as f32`
/// for every pixel `i` and each of the `M` right-hand weights: the same sums in the same order
/// as [`bilinear_form`], four pixels at a time (their four horizontal sums in two vector
/// additions), `x`'s half of the form made once for all `M`.
#[allow(clippy::too_many_arguments)]
fn bilinear_forms<const M: usize>(
    cells: &[f64],
    side: usize,
    ta: &[u32],
    cb: &[u32],
    x: &[[f64; 4]],
    ys: [&[[f32; 4]]; M],
    ks: [f64; M],
    outs: [&mut [f32]; M],
) {
    let mut n = ta.len().min(cb.len()).min(x.len());
    for m in 0..M {
        n = n.min(ys[m].len()).min(outs[m].len());
    }
    let span = 3 * side + 4;
    #[allow(unused_mut)]
    let mut done = 0;
    #[cfg(simd = "avx2")]
    // SAFETY: AVX2 and FMA are enabled at compile time (cfg); pixel l's loads read its cells,
    // a bounds-checked slice of `span` cells (row u: cells u side .. u side + 4 < span), its
    // `x` and its `ys[m]` (four f64 each, j < n); the stores write outs[m][done .. done + 4],
    // done + 4 <= n.
    unsafe {
        use std::arch::x86_64::*;
        while done + 4 <= n {
            // Pixel l's sum over u of x_u times row u of its cells.
            let rows: [__m256d; 4] = std::array::from_fn(|l| {
                let j = done + l;
                let at = ta[j] as usize * side + cb[j] as usize;
                let c = cells[at..at + span].as_ptr();
                let xj = &x[j];
                let mut rows = _mm256_mul_pd(_mm256_set1_pd(xj[0]), _mm256_loadu_pd(c));
                for u in 1..4 {
                    rows = _mm256_fmadd_pd(
                        _mm256_set1_pd(xj[u]),
                        _mm256_loadu_pd(c.add(u * side)),
                        rows,
                    );
                }
                rows
            });
            for m in 0..M {
                let y = ys[m];
                let p: [__m256d; 4] = std::array::from_fn(|l| {
                    _mm256_mul_pd(rows[l], _mm256_cvtps_pd(_mm_loadu_ps(y[done + l].as_ptr())))
                });
                // [p0 + p1 of pixels 0, 1, then p2 + p3 of pixels 0, 1] and the same for 2,
                // 3; the halves' sum is (p0 + p1) + (p2 + p3) of each pixel, as
                // `bilinear_form`'s.
                let h01 = _mm256_hadd_pd(p[0], p[1]);
                let h23 = _mm256_hadd_pd(p[2], p[3]);
                let s = _mm256_add_pd(
                    _mm256_permute2f128_pd::<0x20>(h01, h23),
                    _mm256_permute2f128_pd::<0x31>(h01, h23),
                );
                let r = _mm256_cvtpd_ps(_mm256_mul_pd(_mm256_set1_pd(ks[m]), s));
                _mm_storeu_ps(outs[m][done..done + 4].as_mut_ptr(), r);
            }
            done += 4;
        }
    }
    for j in done..n {
        let at = ta[j] as usize * side + cb[j] as usize;
        for m in 0..M {
            outs[m][j] =
                (ks[m] * bilinear_form(&cells[at..at + span], side, &x[j], &ys[m][j])) as f32;
        }
    }
}

/// Eight f32 lanes (one per parameter) on a 32-byte boundary: a vector load or store of a
/// cell never straddles two cache lines (a split store also stalls the next pixel's load of
/// the same cell).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub(crate) struct Lanes(pub [f32; PDOF]);

/// `cells[u side + v] += x_u (y_v jj)` (eight lanes a cell) for the 4 x 4 cells (rows `side`
/// apart) of one pixel: its share of the Newton Hessian's `V`.
#[inline(always)]
fn add_v(cells: &mut [Lanes], side: usize, x: &[f32; 4], y: &[f32; 4], jj: &[f32; PDOF]) {
    assert!(cells.len() >= 3 * side + 4);
    #[cfg(simd = "avx2")]
    if PDOF == 8 {
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); a cell is eight f32 (PDOF
        // == 8), and row u touches cells u side .. u side + 4, inside `cells` (asserted above).
        unsafe {
            use std::arch::x86_64::*;
            let j = _mm256_loadu_ps(jj.as_ptr());
            for (u, &xu) in x.iter().enumerate() {
                let p = cells.as_mut_ptr().add(u * side) as *mut f32;
                for (w, &yw) in y.iter().enumerate() {
                    let c = p.add(w * PDOF);
                    let coef = _mm256_set1_ps(xu * yw);
                    _mm256_storeu_ps(c, _mm256_fmadd_ps(coef, j, _mm256_loadu_ps(c)));
                }
            }
        }
        return;
    }
    add_v_portable(cells, side, x, y, jj);
}

/// `acc[k] += b[k]` in f64 for the eight lanes of a cell, then `b` zeroed: a block's `V`
/// sums folded into the whole patch's.
#[inline(always)]
fn flush_lanes(acc: &mut [f64], b: &mut Lanes) {
    let acc: &mut [f64; PDOF] = acc.try_into().expect("a cell is PDOF lanes");
    #[cfg(simd = "avx2")]
    if PDOF == 8 {
        // SAFETY: AVX2 is enabled at compile time (cfg); `acc` and `b` are eight lanes each
        // (PDOF == 8), `b` on a 32-byte boundary (`Lanes`' alignment).
        unsafe {
            use std::arch::x86_64::*;
            let v = _mm256_load_ps(b.0.as_ptr());
            let p = acc.as_mut_ptr();
            let lo = _mm256_add_pd(
                _mm256_loadu_pd(p),
                _mm256_cvtps_pd(_mm256_castps256_ps128(v)),
            );
            let hi = _mm256_add_pd(
                _mm256_loadu_pd(p.add(4)),
                _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)),
            );
            _mm256_storeu_pd(p, lo);
            _mm256_storeu_pd(p.add(4), hi);
            _mm256_store_ps(b.0.as_mut_ptr(), _mm256_setzero_ps());
        }
        return;
    }
    for (e, q) in acc.iter_mut().zip(b.0.iter_mut()) {
        *e += *q as f64;
        *q = 0.0;
    }
}

/// Polynomial terms of the product of a weight and a weight's derivative (degree 3 + 2).
const MOMENTS: usize = 6;
/// At most this many pixels are summed in f32 before their sum is added in f64 (as `V`'s
/// blocks).
const RUN: usize = 256;

/// The degree-5 Bernstein basis at `f` in `0..1`: six non-negative terms summing to 1.
fn bernstein5(f: f64) -> [f64; MOMENTS] {
    let g = 1.0 - f;
    let (f2, g2) = (f * f, g * g);
    [
        g2 * g2 * g,
        5.0 * f * g2 * g2,
        10.0 * f2 * g2 * g,
        10.0 * f2 * f * g2,
        5.0 * f2 * f2 * g,
        f2 * f2 * f,
    ]
}

/// `x_u(f) y_w(f)` in the degree-5 Bernstein basis, for the 4 x 4 cells of a pixel whose two
/// intensities fall in the same bin at the same fraction `f` (the template against itself):
/// `derivative_right`: `x` the weights and `y` their derivatives (with respect to the current
/// pixels), else the reverse (the template's).
fn same_bin_products(derivative_right: bool) -> [[[f64; MOMENTS]; 4]; 4] {
    // w_u = A + B f + C f^2 + D f^3, dw_u/df = B + 2 C f + 3 D f^2.
    // The weights' f32 coefficients, as the weights are made.
    let w = |u: usize| [A[u], B[u], C[u], D[u]].map(f64::from);
    let d = |u: usize| [B[u], 2.0 * C[u], 3.0 * D[u], 0.0].map(f64::from);
    let choose = |n: usize, k: usize| -> f64 {
        (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
    };
    let mut out = [[[0.0; MOMENTS]; 4]; 4];
    for (u, row) in out.iter_mut().enumerate() {
        for (v, cell) in row.iter_mut().enumerate() {
            let (x, y) = if derivative_right {
                (w(u), d(v))
            } else {
                (d(u), w(v))
            };
            // Monomial coefficients of the product (one factor is at most quadratic).
            let mut a = [0.0; MOMENTS];
            for (i, &xi) in x.iter().enumerate() {
                for (j, &yj) in y.iter().enumerate() {
                    if i + j < MOMENTS {
                        a[i + j] += xi * yj;
                    }
                }
            }
            // f^k = sum_{m >= k} C(m, k) / C(5, k) b_m(f).
            for (m, c) in cell.iter_mut().enumerate() {
                *c = (0..=m)
                    .map(|k| choose(m, k) / choose(MOMENTS - 1, k) * a[k])
                    .sum();
            }
        }
    }
    out
}

/// The template's pixels grouped by their first bin, for the Hessians after convergence.
///
/// There both weights of a pixel are the template's: its 16 products `x_u y_w` are polynomials
/// of degree 5 in the one fraction `f`, so a bin's 16 cells of `V` are fixed combinations of
/// six sums `M_m = sum_j b_m(f_j) J_j` over the pixels `j` of that bin (`b_m` the Bernstein
/// basis: non-negative weights, no cancellation in the sums). With the pixels grouped by bin
/// once per template, the sums run in registers along each group: six multiply-adds of a
/// Jacobian row per pixel instead of sixteen read-modify-writes of histogram cells.
#[derive(Clone, Debug, Default)]
struct SameBin {
    /// Pixel indices grouped by first bin (clamped pixels, whose derivatives are zero, left
    /// out).
    order: Vec<u32>,
    /// Each pixel's Bernstein basis (times `inside`), in `order`.
    basis: Vec<[f32; MOMENTS]>,
    /// Runs of at most [`RUN`] pixels of one bin: (first bin, end in `order`).
    runs: Vec<(u32, u32)>,
    /// The bins in use, ascending.
    bins: Vec<u32>,
    /// [`same_bin_products`] with respect to the current pixels and to the template's.
    products: [[[[f64; MOMENTS]; 4]; 4]; 2],
    valid: bool,
}

impl SameBin {
    /// Groups the pixels of the template's weights `tw` (histogram side `side`).
    fn build(&mut self, tw: &Weights, side: usize) {
        let n = tw.base.len();
        let mut count = vec![0u32; side + 1];
        let kept = |j: usize| tw.inside[j] > 0.0;
        for j in (0..n).filter(|&j| kept(j)) {
            count[tw.base[j] as usize + 1] += 1;
        }
        for b in 0..side {
            count[b + 1] += count[b];
        }
        let total = count[side] as usize;
        self.order.clear();
        self.order.resize(total, 0);
        let mut next = count.clone();
        for j in (0..n).filter(|&j| kept(j)) {
            let b = tw.base[j] as usize;
            self.order[next[b] as usize] = j as u32;
            next[b] += 1;
        }
        self.basis.clear();
        self.basis.extend(
            self.order
                .iter()
                .map(|&j| bernstein5(tw.fr[j as usize] as f64).map(|b| b as f32)),
        );
        self.runs.clear();
        self.bins.clear();
        for b in 0..side {
            let (start, end) = (count[b] as usize, count[b + 1] as usize);
            if start == end {
                continue;
            }
            self.bins.push(b as u32);
            for s in (start..end).step_by(RUN) {
                self.runs.push((b as u32, (s + RUN).min(end) as u32));
            }
        }
        self.products = [same_bin_products(true), same_bin_products(false)];
        self.valid = true;
    }
}

/// `sum_i basis[i][m] rows[order[i]]` for each `m`, in f32 (in registers along the run).
#[inline(always)]
fn run_sums(rows: &[Lanes], order: &[u32], basis: &[[f32; MOMENTS]]) -> [[f32; PDOF]; MOMENTS] {
    let mut acc = [[0f32; PDOF]; MOMENTS];
    #[cfg(simd = "avx2")]
    if PDOF == 8 {
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); a row is eight f32 on a
        // 32-byte boundary (`Lanes`, PDOF == 8), read through a bounds-checked index; each
        // store writes the eight lanes of one `acc[m]`.
        unsafe {
            use std::arch::x86_64::*;
            let mut s = [_mm256_setzero_ps(); MOMENTS];
            for (&j, b) in order.iter().zip(basis) {
                let r = _mm256_load_ps(rows[j as usize].0.as_ptr());
                for (sm, &bm) in s.iter_mut().zip(b) {
                    *sm = _mm256_fmadd_ps(_mm256_set1_ps(bm), r, *sm);
                }
            }
            for (am, sm) in acc.iter_mut().zip(s) {
                _mm256_storeu_ps(am.as_mut_ptr(), sm);
            }
        }
        return acc;
    }
    for (&j, b) in order.iter().zip(basis) {
        let r = &rows[j as usize].0;
        for (am, &bm) in acc.iter_mut().zip(b) {
            for (e, &q) in am.iter_mut().zip(r) {
                *e = bm.mul_add(q, *e);
            }
        }
    }
    acc
}

/// The Jacobian's rows of the pixels `block` (the Jacobian is stored by parameter, `n` pixels a
/// parameter) into `rows[0..]`, eight lanes a pixel, the lanes past `dof` zero.
fn jacobian_rows(
    jac: &[f32],
    n: usize,
    dof: usize,
    block: std::ops::Range<usize>,
    rows: &mut [Lanes],
) {
    let len = block.len();
    assert!(dof <= PDOF && rows.len() >= len && jac.len() >= dof * n && block.end <= n);
    let mut done = 0;
    #[cfg(simd = "avx2")]
    if PDOF == 8 {
        // SAFETY: AVX2 is enabled at compile time (cfg); parameter k's loads read
        // jac[k n + block.start + i .. + 8] with i + 8 <= len (inside, asserted above); the
        // stores write rows[i .. i + 8], each a 32-byte aligned `Lanes`.
        unsafe {
            use std::arch::x86_64::*;
            while done + 8 <= len {
                let at = block.start + done;
                let c: [__m256; 8] = std::array::from_fn(|k| {
                    if k < dof {
                        _mm256_loadu_ps(jac.as_ptr().add(k * n + at))
                    } else {
                        _mm256_setzero_ps()
                    }
                });
                // 8 x 8 transpose: pairs, then quads, then the 128-bit halves.
                let t0 = _mm256_unpacklo_ps(c[0], c[1]);
                let t1 = _mm256_unpackhi_ps(c[0], c[1]);
                let t2 = _mm256_unpacklo_ps(c[2], c[3]);
                let t3 = _mm256_unpackhi_ps(c[2], c[3]);
                let t4 = _mm256_unpacklo_ps(c[4], c[5]);
                let t5 = _mm256_unpackhi_ps(c[4], c[5]);
                let t6 = _mm256_unpacklo_ps(c[6], c[7]);
                let t7 = _mm256_unpackhi_ps(c[6], c[7]);
                let s0 = _mm256_shuffle_ps::<0x44>(t0, t2);
                let s1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
                let s2 = _mm256_shuffle_ps::<0x44>(t1, t3);
                let s3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
                let s4 = _mm256_shuffle_ps::<0x44>(t4, t6);
                let s5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
                let s6 = _mm256_shuffle_ps::<0x44>(t5, t7);
                let s7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
                let r = [
                    _mm256_permute2f128_ps::<0x20>(s0, s4),
                    _mm256_permute2f128_ps::<0x20>(s1, s5),
                    _mm256_permute2f128_ps::<0x20>(s2, s6),
                    _mm256_permute2f128_ps::<0x20>(s3, s7),
                    _mm256_permute2f128_ps::<0x31>(s0, s4),
                    _mm256_permute2f128_ps::<0x31>(s1, s5),
                    _mm256_permute2f128_ps::<0x31>(s2, s6),
                    _mm256_permute2f128_ps::<0x31>(s3, s7),
                ];
                for (i, r) in r.into_iter().enumerate() {
                    _mm256_store_ps(rows[done + i].0.as_mut_ptr(), r);
                }
                done += 8;
            }
        }
    }
    for (i, row) in rows[done..len].iter_mut().enumerate() {
        let at = block.start + done + i;
        row.0 = std::array::from_fn(|k| if k < dof { jac[k * n + at] } else { 0.0 });
    }
}

/// [`add_v`] in plain Rust.
fn add_v_portable(cells: &mut [Lanes], side: usize, x: &[f32; 4], y: &[f32; 4], jj: &[f32; PDOF]) {
    for u in 0..4 {
        for w in 0..4 {
            let (xu, yw) = (x[u], y[w]);
            for (e, &q) in cells[u * side + w].0.iter_mut().zip(jj) {
                *e = xu.mul_add(yw * q, *e);
            }
        }
    }
}

/// [`add_block`] in plain Rust (the same bits: each product exact, fused).
#[cfg(any(test, not(simd = "avx2")))]
fn add_block_portable(block: &mut Block, x: &[f64; 4], y: &[f32; 4]) {
    for u in 0..4 {
        for v in 0..4 {
            let cell = &mut block.0[4 * u + v];
            *cell = x[u].mul_add(y[v] as f64, *cell);
        }
    }
}

/// [`bilinear_form`] in plain Rust.
#[cfg(any(test, not(simd = "avx2")))]
fn bilinear_form_portable(cells: &[f64], side: usize, x: &[f64; 4], y: &[f32; 4]) -> f64 {
    let mut rows = [0.0; 4];
    for u in 0..4 {
        for v in 0..4 {
            rows[v] = x[u].mul_add(cells[u * side + v], rows[v]);
        }
    }
    let y = y.map(f64::from);
    (rows[0] * y[0] + rows[1] * y[1]) + (rows[2] * y[2] + rows[3] * y[3])
}

impl Weights {
    /// The weights of `x` with the default bins.
    pub fn fill(&mut self, x: &[f32]) {
        self.fill_with(x, &Bins::default());
    }

    /// The weights of `x` and their derivatives, in one pass.
    pub fn fill_with(&mut self, x: &[f32], bins: &Bins) {
        self.fill_pass::<true, true>(x, bins);
    }

    /// The weights of `x` and their first derivatives, in one pass (the second derivatives are
    /// made on demand by [`Weights::fill_second`]: a forward step after convergence reads only
    /// the first, and storing the second costs more than making them).
    pub fn fill_first(&mut self, x: &[f32], bins: &Bins) {
        self.fill_pass::<true, false>(x, bins);
    }

    /// The first bins and weights of `x`, without their derivatives (an ICLK iteration reads
    /// only the weights of the current patch; [`Weights::fill_derivatives`] makes them).
    pub fn fill_values(&mut self, x: &[f32], bins: &Bins) {
        self.fill_pass::<false, false>(x, bins);
    }

    /// The first bins and weights of `x`, and with `DERIVATIVES` their first derivatives and
    /// with `SECOND` their second (the same polynomials of the same fraction, stored instead of
    /// dropped).
    fn fill_pass<const DERIVATIVES: bool, const SECOND: bool>(&mut self, x: &[f32], bins: &Bins) {
        let n = x.len();
        self.base.resize(n, 0);
        self.w.resize(n, [0.0; 4]);
        self.fr.resize(n, 0.0);
        self.inside.resize(n, 0.0);
        if DERIVATIVES {
            self.d.resize(n, [0.0; 4]);
        }
        if SECOND {
            self.d2.resize(n, [0.0; 4]);
        }
        self.derivatives = DERIVATIVES;
        self.second = DERIVATIVES && SECOND;
        let (mut lo, mut hi) = (bins.side, 0);
        // Without DERIVATIVES the derivatives go to these locals and are dropped.
        let (mut d, mut d2) = ([0.0; 4], [0.0; 4]);
        #[cfg(simd = "avx2")]
        let (mut ds, mut d2s) = ([[0.0; 4]; 2], [[0.0; 4]; 2]);
        // The bin coordinates of four pixels at a time (first bin, fraction, inside the range),
        // then each pixel's weights.
        let mut done = 0;
        #[cfg(simd = "avx2")]
        {
            use std::arch::x86_64::*;
            // The first bins' range, lane by lane (four minima and maxima in one register each).
            // SAFETY: AVX2 is enabled at compile time (cfg).
            let (mut lo4, mut hi4) = unsafe { (_mm_set1_epi32(-1), _mm_setzero_si128()) };
            let fours = x.chunks_exact(4).zip(self.base.chunks_exact_mut(4));
            let coords = self
                .fr
                .chunks_exact_mut(4)
                .zip(self.inside.chunks_exact_mut(4));
            for ((v, first), (w, (fr, inside))) in fours.zip(self.w.chunks_exact_mut(4).zip(coords))
            {
                let first: &mut [u32; 4] = first.try_into().expect("four");
                let fr: &mut [f32; 4] = fr.try_into().expect("four");
                let inside: &mut [f32; 4] = inside.try_into().expect("four");
                bin_coordinates4(v.try_into().expect("four"), bins, first, fr, inside);
                // SAFETY: AVX2 is enabled at compile time (cfg); the load reads the four u32 of
                // `first`.
                unsafe {
                    let b = _mm_loadu_si128(first.as_ptr() as *const __m128i);
                    lo4 = _mm_min_epu32(lo4, b);
                    hi4 = _mm_max_epu32(hi4, b);
                }
                // Two pixels a register.
                for (k, w) in w.chunks_exact_mut(2).enumerate() {
                    let w: &mut [[f32; 4]; 2] = w.try_into().expect("two");
                    let (f, ins) = (
                        [fr[2 * k], fr[2 * k + 1]],
                        [inside[2 * k], inside[2 * k + 1]],
                    );
                    let i = done + 2 * k;
                    if DERIVATIVES && SECOND {
                        spline_pair(f, ins, w, pair(&mut self.d, i), pair(&mut self.d2, i));
                    } else if DERIVATIVES {
                        spline_pair(f, ins, w, pair(&mut self.d, i), &mut d2s);
                    } else {
                        spline_pair(f, ins, w, &mut ds, &mut d2s);
                    }
                }
                done += 4;
            }
            if done > 0 {
                let (mut l, mut h) = ([0u32; 4], [0u32; 4]);
                // SAFETY: AVX2 is enabled at compile time (cfg); the stores write the four u32
                // of `l` and `h`.
                unsafe {
                    _mm_storeu_si128(l.as_mut_ptr() as *mut __m128i, lo4);
                    _mm_storeu_si128(h.as_mut_ptr() as *mut __m128i, hi4);
                }
                lo = lo.min(*l.iter().min().expect("four") as usize);
                hi = hi.max(*h.iter().max().expect("four") as usize + 4);
            }
        }
        for i in done..n {
            let (b, f, inside) = bin_coordinate(x[i], bins);
            self.base[i] = b as u32;
            (self.fr[i], self.inside[i]) = (f, inside);
            lo = lo.min(b);
            hi = hi.max(b + 4);
            if DERIVATIVES && SECOND {
                spline(f, inside, &mut self.w[i], &mut self.d[i], &mut self.d2[i]);
            } else if DERIVATIVES {
                spline(f, inside, &mut self.w[i], &mut self.d[i], &mut d2);
            } else {
                spline(f, inside, &mut self.w[i], &mut d, &mut d2);
            }
        }
        if lo >= hi {
            (lo, hi) = (0, 0);
        }
        self.lo = lo;
        self.hi = hi;
    }

    /// `w64`, `d64`, `d2_64` from the weights and both derivatives (made first).
    pub fn widen(&mut self) {
        self.fill_derivatives();
        let wide = |from: &[[f32; 4]], to: &mut Vec<[f64; 4]>| {
            to.clear();
            to.extend(from.iter().map(|w| w.map(f64::from)));
        };
        wide(&self.w, &mut self.w64);
        wide(&self.d, &mut self.d64);
        wide(&self.d2, &mut self.d2_64);
    }

    /// The weights' first and second derivatives (`d`, `d2`) of the values last filled, once.
    pub fn fill_derivatives(&mut self) {
        if self.derivatives {
            self.fill_second();
        } else {
            self.derivative_pass::<true>();
        }
    }

    /// The weights' second derivatives (`d2`) of the values last filled, once, when the first
    /// are made already ([`Weights::fill_first`]); else both, as [`Weights::fill_derivatives`].
    pub fn fill_second(&mut self) {
        if !self.derivatives {
            self.derivative_pass::<true>();
        } else if !self.second {
            self.derivative_pass::<false>();
        }
    }

    /// The second derivatives from the kept fractions, and with `FIRST` the first too (else they
    /// go to a local and are dropped), two pixels a register.
    fn derivative_pass<const FIRST: bool>(&mut self) {
        let n = self.fr.len();
        if FIRST {
            self.d.resize(n, [0.0; 4]);
        }
        self.d2.resize(n, [0.0; 4]);
        let (mut w, mut dropped) = ([[0.0; 4]; 2], [[0.0; 4]; 2]);
        let two = |v: &[f32]| [v[0], v[1]];
        for i in (0..n - n % 2).step_by(2) {
            let (f, inside) = (two(&self.fr[i..]), two(&self.inside[i..]));
            let d = if FIRST {
                pair(&mut self.d, i)
            } else {
                &mut dropped
            };
            spline_pair(f, inside, &mut w, d, pair(&mut self.d2, i));
        }
        if n % 2 == 1 {
            let i = n - 1;
            let d = if FIRST {
                &mut self.d[i]
            } else {
                &mut dropped[0]
            };
            spline(self.fr[i], self.inside[i], &mut w[0], d, &mut self.d2[i]);
        }
        self.derivatives = true;
        self.second = true;
    }
}

/// The statistics of one (template, current) pair: the histogram, its marginals (and cumulative
/// tables for CCRE), the value and `G = dF/dp`. Tables are `side x side`, indexed
/// `[a * side + b]` with `a` the template bin and `b` the current bin.
#[derive(Clone, Debug)]
struct Stats {
    side: usize,
    p: Vec<f64>,
    /// The joint histogram's blocks while it is built (see [`joint_histogram`]).
    blocks: Vec<Block>,
    pt: Vec<f64>,
    pc: Vec<f64>,
    /// CCRE: `P` (cumulative over `a`), `P_t`, `S`.
    cum: Vec<f64>,
    cum_t: Vec<f64>,
    s: Vec<f64>,
    g: Vec<f64>,
    value: f64,
    /// Index ranges in use: template rows and current columns.
    rows: (usize, usize),
    cols: (usize, usize),
}

impl Stats {
    fn new(side: usize) -> Self {
        Stats {
            side,
            p: vec![0.0; side * side],
            blocks: Vec::new(),
            pt: vec![0.0; side],
            pc: vec![0.0; side],
            cum: vec![0.0; side * side],
            cum_t: vec![0.0; side],
            s: vec![0.0; side],
            g: vec![0.0; side * side],
            value: 0.0,
            rows: (0, 0),
            cols: (0, 0),
        }
    }
}

/// `x log x`-safe logarithm ratio: 0 when the numerator is 0.
#[inline]
fn log_ratio(num: f64, den: f64) -> f64 {
    if num > 0.0 && den > 0.0 {
        (num / den).ln()
    } else {
        0.0
    }
}

impl Stats {
    fn compute(&mut self, measure: Measure, t: &Weights, c: &Weights) {
        let side = self.side;
        let (r0, r1) = (t.lo, t.hi);
        let (c0, c1) = (c.lo, c.hi);
        self.rows = (r0, r1);
        self.cols = (c0, c1);
        let n = t.base.len();
        joint_histogram(&mut self.p, &mut self.blocks, side, t, c);
        let inv = 1.0 / n.max(1) as f64;
        self.pt.fill(0.0);
        self.pc.fill(0.0);
        for a in r0..r1 {
            for b in c0..c1 {
                let v = self.p[a * side + b] * inv;
                self.p[a * side + b] = v;
                self.pt[a] += v;
                self.pc[b] += v;
            }
        }
        match measure {
            Measure::Mi => {
                let mut value = 0.0;
                for a in r0..r1 {
                    for b in c0..c1 {
                        let v = self.p[a * side + b];
                        let l = log_ratio(v, self.pt[a] * self.pc[b]);
                        value += v * l;
                        self.g[a * side + b] = l;
                    }
                }
                self.value = value;
            }
            Measure::Ccre => {
                self.cum_t.fill(0.0);
                self.s.fill(0.0);
                for b in c0..c1 {
                    let mut acc = 0.0;
                    for a in r0..r1 {
                        acc += self.p[a * side + b];
                        self.cum[a * side + b] = acc;
                        self.cum_t[a] += acc;
                        self.s[b] += acc;
                    }
                }
                let mut value = 0.0;
                for b in c0..c1 {
                    // G(a, b) = sum_{a' >= a} L(a', b) - S(b) / p_c(b).
                    let shift = if self.pc[b] > 0.0 {
                        self.s[b] / self.pc[b]
                    } else {
                        0.0
                    };
                    let mut acc = 0.0;
                    for a in (r0..r1).rev() {
                        let v = self.cum[a * side + b];
                        let l = log_ratio(v, self.cum_t[a] * self.pc[b]);
                        value += v * l;
                        acc += l;
                        self.g[a * side + b] = acc - shift;
                    }
                }
                self.value = value;
            }
        }
    }
}

/// The MI / CCRE model.
#[derive(Clone, Debug)]
pub(crate) struct Parzen {
    measure: Measure,
    bins: Bins,
    template: Vec<f32>,
    tw: Weights,
    cw: Weights,
    /// Statistics of the last patch, and that patch.
    stats: Stats,
    last: Vec<f32>,
    valid: bool,
    /// Statistics of the template against itself (after convergence).
    self_stats: Stats,
    self_valid: bool,
    /// The template's pixels grouped by bin (after convergence).
    same: SameBin,
    /// Scratch: `V` (`side x side x PDOF`).
    v: Vec<f64>,
    scratch: Scratch,
    /// The Newton Hessian's per-pixel diagonal terms, and which Hessian they are of.
    diag: Vec<f32>,
    diag_of: DiagOf,
    /// The last Hessian was a Newton Hessian with respect to the current pixels, so the next
    /// gradient with respect to them makes `diag` too (FCLK and ESM ask for both each step).
    want_diag: bool,
}

/// Which Newton Hessian [`Parzen`]'s per-pixel diagonal terms are those of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DiagOf {
    /// None that can be reused.
    Stale,
    /// With respect to the current pixels of the last patch's statistics (made with their
    /// gradient, whose pass reads the same cells and template weights, or by the Hessian).
    Current,
    /// After convergence (the template against itself), with respect to the current pixels or
    /// the template's: constant until the template changes.
    AfterConvergence(super::Wrt),
}

impl Parzen {
    pub fn new(measure: Measure, bins: usize) -> Self {
        let bins = Bins::new(bins);
        Parzen {
            measure,
            bins,
            template: Vec::new(),
            tw: Weights::default(),
            cw: Weights::default(),
            stats: Stats::new(bins.side),
            last: Vec::new(),
            valid: false,
            self_stats: Stats::new(bins.side),
            self_valid: false,
            v: vec![0.0; bins.side * bins.side * PDOF],
            same: SameBin::default(),
            scratch: Scratch {
                v_block: vec![Lanes::default(); bins.side * bins.side],
                rows: Vec::new(),
                moments: vec![[0.0; PDOF]; bins.side * MOMENTS],
                lines: vec![[0.0; PDOF]; bins.side],
                terms: Vec::new(),
            },
            diag: Vec::new(),
            diag_of: DiagOf::Stale,
            want_diag: false,
        }
    }

    /// The model with the bins of `params` (see [`PARAMS`]).
    pub fn from_params(measure: Measure, params: &crate::params::MethodParams) -> Self {
        Parzen::new(measure, params.get(&BINS_PARAM) as usize)
    }

    pub fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
        self.tw.fill_with(template, &self.bins);
        self.tw.widen();
        self.valid = false;
        self.self_valid = false;
        self.same.valid = false;
        self.diag_of = DiagOf::Stale;
        self.diag.resize(template.len(), 0.0);
    }

    pub fn template(&self) -> &[f32] {
        &self.template
    }

    /// Makes `stats` those of `current`, and with `derivatives` its weights' derivatives too.
    fn observe(&mut self, current: &[f32], derivatives: bool) {
        if self.valid && self.last.as_slice() == current {
            if derivatives && !self.cw.derivatives {
                self.cw.fill_derivatives();
            }
            return;
        }
        if derivatives {
            self.cw.fill_first(current, &self.bins);
        } else {
            self.cw.fill_values(current, &self.bins);
        }
        self.stats.compute(self.measure, &self.tw, &self.cw);
        if self.diag_of == DiagOf::Current {
            self.diag_of = DiagOf::Stale;
        }
        self.last.clear();
        self.last.extend_from_slice(current);
        self.valid = true;
    }

    pub fn similarity(&mut self, current: &[f32]) -> f64 {
        self.observe(current, false);
        self.stats.value
    }

    pub fn gradient(&mut self, wrt: super::Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        self.observe(current, wrt == super::Wrt::Current);
        let with_diag = self.want_diag && self.diag_of != DiagOf::Current;
        if wrt == super::Wrt::Current && with_diag {
            self.cw.fill_second();
        }
        self.diag.resize(current.len(), 0.0);
        let g = &self.stats.g;
        let side = self.bins.side;
        let k = self.bins.scale / current.len().max(1) as f64;
        let (tw, cw) = (&self.tw, &self.cw);
        match wrt {
            super::Wrt::Current if with_diag => {
                // The Newton diagonal's forms share the gradient's left half (the template's
                // weights): both in one pass.
                let (d, d2) = (&cw.d[..], &cw.d2[..]);
                let diag = &mut self.diag[..];
                bilinear_forms(
                    g,
                    side,
                    &tw.base,
                    &cw.base,
                    &tw.w64,
                    [d, d2],
                    [k, 1.0],
                    [grad, diag],
                );
                self.diag_of = DiagOf::Current;
            }
            super::Wrt::Current => {
                bilinear_forms(g, side, &tw.base, &cw.base, &tw.w64, [&cw.d], [k], [grad]);
            }
            super::Wrt::Template => {
                bilinear_forms(g, side, &tw.base, &cw.base, &tw.d64, [&cw.w], [k], [grad]);
            }
        }
        self.stats.value
    }

    pub fn hessian(
        &mut self,
        wrt: super::Wrt,
        kind: super::HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        use super::HessianKind;
        let after = kind == HessianKind::AfterConvergence;
        if after {
            if !self.self_valid {
                self.self_stats.compute(self.measure, &self.tw, &self.tw);
                self.self_valid = true;
            }
            if !self.same.valid {
                self.same.build(&self.tw, self.bins.side);
            }
        } else {
            self.observe(current, wrt == super::Wrt::Current);
            if wrt == super::Wrt::Current {
                // The Newton diagonal at the current patch reads their second derivatives.
                self.cw.fill_second();
            }
        }
        let (stats, cw) = if after {
            (&self.self_stats, &self.tw)
        } else {
            (&self.stats, &self.cw)
        };
        // The diagonal this Hessian needs: made already (with the gradient, or by an earlier
        // Hessian after convergence), else made below and kept for the next if it can be.
        let needed = match (after, wrt) {
            (true, wrt) => DiagOf::AfterConvergence(wrt),
            (false, super::Wrt::Current) => DiagOf::Current,
            (false, super::Wrt::Template) => DiagOf::Stale,
        };
        let reuse = needed != DiagOf::Stale && self.diag_of == needed;
        newton(
            self.measure,
            &self.bins,
            stats,
            &self.tw,
            cw,
            wrt == super::Wrt::Current,
            jac,
            dof,
            after.then_some(&self.same),
            &mut self.v,
            &mut self.scratch,
            (&mut self.diag, reuse),
            out,
        );
        self.diag_of = needed;
        self.want_diag = needed == DiagOf::Current;
        if kind == HessianKind::GaussNewton {
            negative_part(out, dof);
        }
    }
}

/// Scratch of the Newton Hessian.
#[derive(Clone, Debug)]
struct Scratch {
    /// `V` over one block of pixels, in f32 (one AVX register a cell).
    v_block: Vec<Lanes>,
    /// The Jacobian's rows (a block's, or every pixel's after convergence).
    rows: Vec<Lanes>,
    /// After convergence: each bin's six sums (`side x MOMENTS`).
    moments: Vec<[f64; PDOF]>,
    /// One `dof`-vector per histogram row or column.
    lines: Vec<[f64; PDOF]>,
    /// The Hessian's weighted outer products, as (weight, vector).
    terms: Vec<(f64, [f64; PDOF])>,
}

/// Adds `V` after convergence into `v` (see [`SameBin`]): the Jacobian's rows, each bin's six
/// sums along its runs, then the bin's 16 cells from them.
#[allow(clippy::too_many_arguments)]
fn same_bin_v(
    same: &SameBin,
    current: bool,
    side: usize,
    jac: &[f32],
    n: usize,
    dof: usize,
    scratch: &mut Scratch,
    v: &mut [f64],
) {
    scratch.rows.resize(n, Lanes::default());
    jacobian_rows(jac, n, dof, 0..n, &mut scratch.rows);
    let moments = &mut scratch.moments;
    for &b in &same.bins {
        let b = b as usize;
        moments[b * MOMENTS..(b + 1) * MOMENTS].fill([0.0; PDOF]);
    }
    let mut start = 0;
    for &(b, end) in &same.runs {
        let (b, end) = (b as usize, end as usize);
        let sums = run_sums(
            &scratch.rows,
            &same.order[start..end],
            &same.basis[start..end],
        );
        for (acc, s) in moments[b * MOMENTS..(b + 1) * MOMENTS]
            .iter_mut()
            .zip(&sums)
        {
            for (e, &q) in acc.iter_mut().zip(s) {
                *e += q as f64;
            }
        }
        start = end;
    }
    let products = &same.products[if current { 0 } else { 1 }];
    for &b in &same.bins {
        let b = b as usize;
        let m: &[[f64; PDOF]; MOMENTS] = moments[b * MOMENTS..(b + 1) * MOMENTS]
            .try_into()
            .expect("MOMENTS sums a bin");
        for (u, row) in products.iter().enumerate() {
            for (w, coefficients) in row.iter().enumerate() {
                let at = ((b + u) * side + b + w) * PDOF;
                let cell: &mut [f64; PDOF] = (&mut v[at..at + PDOF])
                    .try_into()
                    .expect("a cell is PDOF lanes");
                add_cell(cell, coefficients, m);
            }
        }
    }
}

/// `cell += sum_m c[m] moments[m]` (eight lanes), the sum made in registers first.
#[inline(always)]
fn add_cell(cell: &mut [f64; PDOF], c: &[f64; MOMENTS], moments: &[[f64; PDOF]; MOMENTS]) {
    #[cfg(simd = "avx2")]
    if PDOF == 8 {
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); each load or store reads or
        // writes four of the eight lanes (PDOF == 8) of a cell or of a moment.
        unsafe {
            use std::arch::x86_64::*;
            let (mut lo, mut hi) = (_mm256_setzero_pd(), _mm256_setzero_pd());
            for (mm, &cm) in moments.iter().zip(c) {
                let k = _mm256_set1_pd(cm);
                lo = _mm256_fmadd_pd(k, _mm256_loadu_pd(mm.as_ptr()), lo);
                hi = _mm256_fmadd_pd(k, _mm256_loadu_pd(mm.as_ptr().add(4)), hi);
            }
            let p = cell.as_mut_ptr();
            _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), lo));
            _mm256_storeu_pd(p.add(4), _mm256_add_pd(_mm256_loadu_pd(p.add(4)), hi));
        }
        return;
    }
    let mut sum = [0.0; PDOF];
    for (mm, &cm) in moments.iter().zip(c) {
        for (e, &q) in sum.iter_mut().zip(mm) {
            *e = cm.mul_add(q, *e);
        }
    }
    for (e, s) in cell.iter_mut().zip(sum) {
        *e += s;
    }
}

/// The projected Newton Hessian `J^T (d2F/dx2) J` for the statistics `st` of the patches with
/// weights `tw`, `cw`; `current`: with respect to the current pixels (else the template's).
#[allow(clippy::too_many_arguments)]
fn newton(
    measure: Measure,
    bins: &Bins,
    st: &Stats,
    tw: &Weights,
    cw: &Weights,
    current: bool,
    jac: &[f32],
    dof: usize,
    same: Option<&SameBin>,
    v: &mut [f64],
    scratch: &mut Scratch,
    (diag, diag_ready): (&mut [f32], bool),
    out: &mut [f64; MAX_DOF * MAX_DOF],
) {
    const BLOCK: usize = 256;
    let n = tw.base.len();
    let (side, scale) = (bins.side, bins.scale);
    let inv_n = 1.0 / n.max(1) as f64;
    let (r0, r1) = st.rows;
    let (c0, c1) = st.cols;
    // V(a, b) = sum_j dp(a, b)/dx_j J_j (without the factor k/N, applied below), and the
    // per-pixel diagonal D_j = sum_ab G d2p/dx_j^2 (without k^2/N). V is summed in f32 over
    // blocks of pixels (16 cells a pixel, one 8-lane multiply-add each), then in f64 across
    // blocks, as `jt_times` does.
    for a in r0..r1 {
        v[(a * side + c0) * PDOF..(a * side + c1) * PDOF].fill(0.0);
    }
    let g = &st.g;
    match same {
        Some(same) => {
            // After convergence: V from each bin's six sums (see `SameBin`).
            if !diag_ready {
                let (x2, y2) = if current {
                    (&tw.w64, &cw.d2)
                } else {
                    (&tw.d2_64, &cw.w)
                };
                bilinear_forms(g, side, &tw.base, &cw.base, x2, [y2], [1.0], [diag]);
            }
            same_bin_v(same, current, side, jac, n, dof, scratch, v);
        }
        None => {
            let (v_block, rows) = (&mut scratch.v_block, &mut scratch.rows);
            rows.resize(BLOCK, Lanes::default());
            for a in r0..r1 {
                v_block[a * side + c0..a * side + c1].fill(Lanes::default());
            }
            for start in (0..n).step_by(BLOCK) {
                let end = (start + BLOCK).min(n);
                // The block's Jacobian rows (eight lanes a pixel; those past `dof` zero), read
                // column by column (the Jacobian is stored by parameter).
                jacobian_rows(jac, n, dof, start..end, rows);
                // The template's and the current patch's weights of the block: `x` and `y` for
                // `V`, `x2` and `y2` for the diagonal.
                let block = start..end;
                let (ta, cb) = (&tw.base[block.clone()], &cw.base[block.clone()]);
                let (x, y, x2, y2) = if current {
                    (
                        &tw.w[block.clone()],
                        &cw.d[block.clone()],
                        &tw.w64[block.clone()],
                        &cw.d2[block.clone()],
                    )
                } else {
                    (
                        &tw.d[block.clone()],
                        &cw.w[block.clone()],
                        &tw.d2_64[block.clone()],
                        &cw.w[block.clone()],
                    )
                };
                // The diagonal in a pass of its own, four pixels at a time (unless made already).
                if !diag_ready {
                    bilinear_forms(g, side, ta, cb, x2, [y2], [1.0], [&mut diag[block]]);
                }
                // All PDOF lanes of a row (those past `dof` are zero and never read).
                for ((((jj, &ta), &cb), x), y) in rows.iter().zip(ta).zip(cb).zip(x).zip(y) {
                    let at = ta as usize * side + cb as usize;
                    add_v(&mut v_block[at..at + 3 * side + 4], side, x, y, &jj.0);
                }
                for a in r0..r1 {
                    let cells = a * side + c0..a * side + c1;
                    let sums = &mut v[cells.start * PDOF..cells.end * PDOF];
                    for (acc, vb) in sums.chunks_exact_mut(PDOF).zip(&mut v_block[cells]) {
                        flush_lanes(acc, vb);
                    }
                }
            }
        }
    }
    let lines = &mut scratch.lines[..];
    let kn = scale * inv_n;
    // Diagonal part: k^2/N sum_j D_j J_j J_j^T.
    super::intensity_map::jt_diag_j(jac, diag, dof, out);
    let s_diag = scale * scale * inv_n;
    // The second-order part, `sum_c w_c t_c t_c^T` over histogram cells, rows and columns:
    // the terms first, then their weighted Gram matrix. Every lane (those past `dof` are zero
    // in `V` and so in every sum of its cells).
    let cell = |a: usize, b: usize| -> [f64; PDOF] {
        let at = (a * side + b) * PDOF;
        v[at..at + PDOF].try_into().expect("a cell is PDOF lanes")
    };
    let terms = &mut scratch.terms;
    terms.clear();
    // At most a term a cell, three a column and one a row (no allocation once made).
    terms.reserve(side * side + 4 * side);
    match measure {
        Measure::Mi => {
            let col = lines;
            col.fill([0.0; PDOF]);
            for a in r0..r1 {
                let mut row = [0.0f64; PDOF];
                for b in c0..c1 {
                    let vab = cell(a, b);
                    let p = st.p[a * side + b];
                    if p > 0.0 {
                        terms.push((1.0 / p, vab));
                    }
                    for k in 0..PDOF {
                        row[k] += vab[k];
                        col[b][k] += vab[k];
                    }
                }
                if st.pt[a] > 0.0 {
                    terms.push((-1.0 / st.pt[a], row));
                }
            }
            for b in c0..c1 {
                if st.pc[b] > 0.0 {
                    terms.push((-1.0 / st.pc[b], col[b]));
                }
            }
        }
        Measure::Ccre => {
            let rows = lines;
            rows.fill([0.0; PDOF]);
            for b in c0..c1 {
                let (mut u, mut x, mut w) = ([0.0f64; PDOF], [0.0f64; PDOF], [0.0; PDOF]);
                for a in r0..r1 {
                    let vab = cell(a, b);
                    for k in 0..PDOF {
                        u[k] += vab[k];
                        w[k] += vab[k];
                        x[k] += u[k];
                        rows[a][k] += u[k];
                    }
                    let pc = st.cum[a * side + b];
                    if pc > 0.0 {
                        terms.push((1.0 / pc, u));
                    }
                }
                let pb = st.pc[b];
                if pb > 0.0 {
                    // -(x w^T + w x^T) / pb = ((x - w)(x - w)^T - (x + w)(x + w)^T) / (2 pb).
                    let (sum, diff) = (
                        std::array::from_fn(|k| x[k] + w[k]),
                        std::array::from_fn(|k| x[k] - w[k]),
                    );
                    terms.push((-0.5 / pb, sum));
                    terms.push((0.5 / pb, diff));
                    terms.push((st.s[b] / (pb * pb), w));
                }
            }
            for a in r0..r1 {
                if st.cum_t[a] > 0.0 {
                    terms.push((-1.0 / st.cum_t[a], rows[a]));
                }
            }
        }
    }
    let q = weighted_gram(terms);
    for i in 0..dof {
        for j in 0..dof {
            out[i * dof + j] = s_diag * out[i * dof + j] + kn * kn * q[i * PDOF + j];
        }
    }
}

/// `sum_i w_i t_i t_i^T` over `terms` (row-major, `PDOF x PDOF`). With AVX2 and eight
/// lanes, the upper triangle's 4 x 4 blocks (twelve registers) accumulate along the terms, each
/// row's factor `w t_i` broadcast from a register; the lower triangle is the upper's mirror.
fn weighted_gram(terms: &[(f64, [f64; PDOF])]) -> [f64; PDOF * PDOF] {
    let mut q = [0.0; PDOF * PDOF];
    #[cfg(simd = "avx2")]
    if PDOF == 8 {
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); the loads read the eight
        // lanes of a term (PDOF == 8), the stores write the four lanes at 8 i and 8 i + 4 of
        // row i < 8 of `q`.
        unsafe {
            use std::arch::x86_64::*;
            let z = _mm256_setzero_pd();
            let (mut l0, mut l1, mut l2, mut l3) = (z, z, z, z);
            let (mut h0, mut h1, mut h2, mut h3) = (z, z, z, z);
            let (mut h4, mut h5, mut h6, mut h7) = (z, z, z, z);
            for (w, t) in terms {
                let (xl, xh) = (
                    _mm256_loadu_pd(t.as_ptr()),
                    _mm256_loadu_pd(t.as_ptr().add(4)),
                );
                let wv = _mm256_set1_pd(*w);
                let (wl, wh) = (_mm256_mul_pd(wv, xl), _mm256_mul_pd(wv, xh));
                let b = _mm256_permute4x64_pd::<0x00>(wl);
                (l0, h0) = (_mm256_fmadd_pd(b, xl, l0), _mm256_fmadd_pd(b, xh, h0));
                let b = _mm256_permute4x64_pd::<0x55>(wl);
                (l1, h1) = (_mm256_fmadd_pd(b, xl, l1), _mm256_fmadd_pd(b, xh, h1));
                let b = _mm256_permute4x64_pd::<0xAA>(wl);
                (l2, h2) = (_mm256_fmadd_pd(b, xl, l2), _mm256_fmadd_pd(b, xh, h2));
                let b = _mm256_permute4x64_pd::<0xFF>(wl);
                (l3, h3) = (_mm256_fmadd_pd(b, xl, l3), _mm256_fmadd_pd(b, xh, h3));
                h4 = _mm256_fmadd_pd(_mm256_permute4x64_pd::<0x00>(wh), xh, h4);
                h5 = _mm256_fmadd_pd(_mm256_permute4x64_pd::<0x55>(wh), xh, h5);
                h6 = _mm256_fmadd_pd(_mm256_permute4x64_pd::<0xAA>(wh), xh, h6);
                h7 = _mm256_fmadd_pd(_mm256_permute4x64_pd::<0xFF>(wh), xh, h7);
            }
            let p = q.as_mut_ptr();
            for (i, (l, h)) in [(l0, h0), (l1, h1), (l2, h2), (l3, h3)]
                .into_iter()
                .enumerate()
            {
                _mm256_storeu_pd(p.add(8 * i), l);
                _mm256_storeu_pd(p.add(8 * i + 4), h);
            }
            for (i, h) in [h4, h5, h6, h7].into_iter().enumerate() {
                _mm256_storeu_pd(p.add(8 * (i + 4) + 4), h);
            }
        }
        mirror(&mut q);
        return q;
    }
    weighted_gram_portable(terms, &mut q);
    q
}

/// [`weighted_gram`] in plain Rust (the same bits: the upper triangle's blocks made as there,
/// then mirrored; also where `PDOF` is not eight).
fn weighted_gram_portable(terms: &[(f64, [f64; PDOF])], q: &mut [f64; PDOF * PDOF]) {
    let half = PDOF / 2;
    for (w, t) in terms {
        for i in 0..PDOF {
            let b = w * t[i];
            // Rows of the first half: every column; of the second: the second half's.
            let from = if i < half { 0 } else { half };
            for j in from..PDOF {
                q[i * PDOF + j] = b.mul_add(t[j], q[i * PDOF + j]);
            }
        }
    }
    mirror(q);
}

/// The lower triangle from the upper (exactly symmetric).
fn mirror(q: &mut [f64; PDOF * PDOF]) {
    for i in 1..PDOF {
        for j in 0..i {
            q[i * PDOF + j] = q[j * PDOF + i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bspline_weights_are_a_partition_of_unity_with_consistent_derivatives() {
        let mut w = Weights::default();
        let xs: Vec<f32> = (0..200).map(|i| -30.0 + i as f32 * 1.77).collect();
        w.fill(&xs);
        for i in 0..xs.len() {
            // f32 weights.
            let s: f64 = w.w[i].iter().map(|&v| v as f64).sum();
            let d: f64 = w.d[i].iter().map(|&v| v as f64).sum();
            let d2: f64 = w.d2[i].iter().map(|&v| v as f64).sum();
            assert!((s - 1.0).abs() < 1e-6 && d.abs() < 1e-6 && d2.abs() < 1e-6);
        }
        // Derivatives by finite differences in the bin coordinate (away from bin edges; a
        // step of 0.006 bins, the f32 weights' rounding 1e-5 of the difference).
        let (x, h) = (100.3f32, 0.1f32);
        let mut p = Weights::default();
        let mut m = Weights::default();
        w.fill(&[x]);
        p.fill(&[x + h]);
        m.fill(&[x - h]);
        let ds = ((x + h) as f64 - (x - h) as f64) * SCALE;
        for u in 0..4 {
            let fd = (p.w[0][u] - m.w[0][u]) as f64 / ds;
            let d = w.d[0][u] as f64;
            assert!((fd - d).abs() < 1e-4, "{u}: {fd} {d}");
            let fd2 = (p.d[0][u] - m.d[0][u]) as f64 / ds;
            assert!((fd2 - w.d2[0][u] as f64).abs() < 1e-4, "{u}: {fd2}");
        }
    }

    /// The vectorised kernels equal their plain versions, and the weights their textbook form.
    #[test]
    fn kernels_equal_their_plain_versions() {
        let mut rng = crate::rng::Rng::new(7);
        #[cfg(simd = "avx2")]
        for bins in [Bins::default(), Bins::new(16)] {
            let odd = [
                f32::NAN,
                f32::INFINITY,
                -f32::INFINITY,
                -300.0,
                600.0,
                0.0,
                255.0,
            ];
            let values: Vec<f32> = (0..400)
                .map(|i| {
                    odd.get(i)
                        .copied()
                        .unwrap_or(rng.range(-400.0, 700.0) as f32)
                })
                .collect();
            for four in values.chunks_exact(4) {
                let (mut first, mut fr, mut inside) = ([0u32; 4], [0.0; 4], [0.0; 4]);
                bin_coordinates4(
                    four.try_into().unwrap(),
                    &bins,
                    &mut first,
                    &mut fr,
                    &mut inside,
                );
                for k in 0..4 {
                    let (b, f, i) = bin_coordinate(four[k], &bins);
                    assert_eq!(
                        (first[k] as usize, fr[k], inside[k]),
                        (b, f, i),
                        "{}",
                        four[k]
                    );
                }
            }
        }
        for _ in 0..200 {
            let f = rng.uniform() as f32;
            let inside = if rng.uniform() < 0.8 { 1.0 } else { 0.0 };
            let (mut w, mut d, mut d2) = ([0.0; 4], [0.0; 4], [0.0; 4]);
            spline(f, inside, &mut w, &mut d, &mut d2);
            // Two at a time: the same bits, in both lanes.
            let (f2, inside2) = (rng.uniform() as f32, 1.0 - inside);
            let (mut pw, mut pd, mut pd2) = ([[0.0; 4]; 2], [[0.0; 4]; 2], [[0.0; 4]; 2]);
            spline_pair([f, f2], [inside, inside2], &mut pw, &mut pd, &mut pd2);
            let (mut w2, mut d_2, mut d2_2) = ([0.0; 4], [0.0; 4], [0.0; 4]);
            spline(f2, inside2, &mut w2, &mut d_2, &mut d2_2);
            let bits = |v: [[f32; 4]; 2]| v.map(|r| r.map(f32::to_bits));
            assert_eq!(bits(pw), bits([w, w2]));
            assert_eq!(bits(pd), bits([d, d_2]));
            assert_eq!(bits(pd2), bits([d2, d2_2]));
            let (f, w) = (f as f64, w.map(f64::from));
            let g = 1.0 - f;
            let book = [
                g * g * g / 6.0,
                2.0 / 3.0 - f * f + 0.5 * f * f * f,
                2.0 / 3.0 - g * g + 0.5 * g * g * g,
                f * f * f / 6.0,
            ];
            for k in 0..4 {
                assert!((w[k] - book[k]).abs() < 1e-6, "{f}: {w:?} {book:?}");
            }
            let side = 7;
            let x: [f32; 4] = std::array::from_fn(|_| rng.uniform() as f32);
            let y: [f32; 4] = std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32);
            let x64 = x.map(f64::from);
            let cells: Vec<f64> = (0..3 * side + 4).map(|_| rng.range(-2.0, 2.0)).collect();
            let (a, b) = (
                bilinear_form(&cells, side, &x64, &y),
                bilinear_form_portable(&cells, side, &x64, &y),
            );
            assert!((a - b).abs() < 1e-12, "{a} {b}");
            let start = Block(std::array::from_fn(|_| rng.range(0.0, 3.0)));
            let (mut b1, mut b2) = (start, start);
            add_block(&mut b1, &x64, &y);
            add_block_portable(&mut b2, &x64, &y);
            assert_eq!(b1.0.map(f64::to_bits), b2.0.map(f64::to_bits));
            let jj: [f32; PDOF] = std::array::from_fn(|_| rng.range(-3.0, 3.0) as f32);
            let mut v1 = vec![Lanes([0.5f32; PDOF]); 3 * side + 4];
            let mut v2 = v1.clone();
            add_v(&mut v1, side, &x, &y, &jj);
            add_v_portable(&mut v2, side, &x, &y, &jj);
            for (p, q) in v1.iter().flat_map(|c| c.0).zip(v2.iter().flat_map(|c| c.0)) {
                assert!((p - q).abs() < 1e-5, "{p} {q}");
            }
            let mut acc: [f64; PDOF] = std::array::from_fn(|_| rng.range(-1.0, 1.0));
            let before = acc;
            let mut lanes = Lanes(std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32));
            let added = lanes;
            flush_lanes(&mut acc, &mut lanes);
            for k in 0..PDOF {
                assert_eq!(acc[k], before[k] + added.0[k] as f64);
            }
            assert_eq!(lanes.0, [0.0; PDOF]);
        }
        // The weighted Gram matrix: the portable one's bits, symmetric, and the plain sum.
        for count in [0usize, 1, 7, 40] {
            let terms: Vec<(f64, [f64; PDOF])> = (0..count)
                .map(|_| {
                    let t = std::array::from_fn(|_| rng.range(-2.0, 2.0));
                    (rng.range(-3.0, 3.0), t)
                })
                .collect();
            let q = weighted_gram(&terms);
            let mut p = [0.0; PDOF * PDOF];
            weighted_gram_portable(&terms, &mut p);
            assert_eq!(q.map(f64::to_bits), p.map(f64::to_bits), "{count} terms");
            for i in 0..PDOF {
                for j in 0..PDOF {
                    let plain: f64 = terms.iter().map(|(w, t)| w * t[i] * t[j]).sum();
                    let got = q[i * PDOF + j];
                    assert!((got - plain).abs() < 1e-10, "({i}, {j}): {got} {plain}");
                    assert_eq!(got, q[j * PDOF + i]);
                }
            }
        }
        // Four pixels' forms at a time: the same values, to the bit, as one at a time.
        let side = 7;
        let cells: Vec<f64> = (0..side * side).map(|_| rng.range(-2.0, 2.0)).collect();
        for n in [0usize, 3, 4, 9, 16] {
            let ta: Vec<u32> = (0..n)
                .map(|_| (rng.next_u64() % (side as u64 - 3)) as u32)
                .collect();
            let cb: Vec<u32> = (0..n)
                .map(|_| (rng.next_u64() % (side as u64 - 3)) as u32)
                .collect();
            let x: Vec<[f64; 4]> = (0..n)
                .map(|_| std::array::from_fn(|_| rng.uniform()))
                .collect();
            let y: Vec<[f32; 4]> = (0..n)
                .map(|_| std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32))
                .collect();
            let mut out = vec![0f32; n];
            bilinear_forms(&cells, side, &ta, &cb, &x, [&y], [0.37], [&mut out]);
            for j in 0..n {
                let at = ta[j] as usize * side + cb[j] as usize;
                let one = (0.37 * bilinear_form(&cells[at..], side, &x[j], &y[j])) as f32;
                assert_eq!(out[j].to_bits(), one.to_bits(), "pixel {j} of {n}");
            }
        }
        // The Jacobian's rows of a block: every parameter's value in its lane, zeros past `dof`,
        // for blocks with and without a tail of fewer than eight pixels.
        for (n, dof, block) in [(37, 8, 3..37), (40, 6, 8..40), (19, 2, 0..19), (8, 8, 0..8)] {
            let jac: Vec<f32> = (0..dof * n).map(|_| rng.range(-5.0, 5.0) as f32).collect();
            let mut rows = vec![Lanes([9.0; PDOF]); block.len()];
            jacobian_rows(&jac, n, dof, block.clone(), &mut rows);
            for (i, row) in rows.iter().enumerate() {
                for k in 0..PDOF {
                    let want = if k < dof {
                        jac[k * n + block.start + i]
                    } else {
                        0.0
                    };
                    assert_eq!(row.0[k], want, "pixel {i}, parameter {k} of {dof}");
                }
            }
        }
    }

    /// Weights filled without their derivatives (or without the second), then the derivatives
    /// made on demand, equal those filled at once, for new values too (the derivatives of older
    /// values are not kept).
    #[test]
    fn derivatives_made_on_demand_are_those_of_the_last_values() {
        let bins = Bins::new(DEFAULT_BINS);
        let a: Vec<f32> = (0..23).map(|i| -40.0 + i as f32 * 15.3).collect();
        let b: Vec<f32> = (0..23).map(|i| 300.0 - i as f32 * 11.1).collect();
        let mut whole = Weights::default();
        whole.fill_with(&b, &bins);
        let mut lazy = Weights::default();
        lazy.fill_with(&a, &bins);
        lazy.fill_values(&b, &bins);
        assert_eq!(
            (lazy.base.clone(), lazy.w.clone()),
            (whole.base.clone(), whole.w.clone())
        );
        assert_eq!((lazy.lo, lazy.hi), (whole.lo, whole.hi));
        lazy.fill_derivatives();
        assert_eq!(
            (lazy.d.clone(), lazy.d2.clone()),
            (whole.d.clone(), whole.d2.clone())
        );
        // The first derivatives with the values, the second on demand (over another patch's).
        let mut first = Weights::default();
        first.fill_with(&a, &bins);
        first.fill_first(&b, &bins);
        assert_eq!(
            (first.base.clone(), first.w.clone(), first.d.clone()),
            (whole.base.clone(), whole.w.clone(), whole.d.clone())
        );
        assert_ne!(first.d2, whole.d2, "the older patch's second derivatives");
        first.fill_second();
        assert_eq!(first.d2, whole.d2);
        // Values only, then the second derivatives: both made.
        let mut second = Weights::default();
        second.fill_values(&b, &bins);
        second.fill_second();
        assert_eq!((&second.d, &second.d2), (&whole.d, &whole.d2));
    }

    /// The Newton diagonal made in the gradient's pass (FCLK's and ESM's order: gradient, then
    /// Hessian, each step) gives the Hessian bit for bit that of a model making it in the
    /// Hessian's own pass, and so does the diagonal kept after convergence; neither is reused
    /// for another patch, side or kind.
    #[test]
    fn a_diagonal_made_with_the_gradient_gives_the_same_hessian() {
        use super::super::{HessianKind, Wrt};
        let mut rng = crate::rng::Rng::new(11);
        let n = 257;
        let t: Vec<f32> = (0..n).map(|_| rng.range(0.0, 255.0) as f32).collect();
        let patches: Vec<Vec<f32>> = (0..3)
            .map(|_| {
                t.iter()
                    .map(|&v| 0.8 * v + 15.0 + rng.range(-12.0, 12.0) as f32)
                    .collect()
            })
            .collect();
        let dof = 8;
        let jac: Vec<f32> = (0..dof * n).map(|_| rng.range(-3.0, 3.0) as f32).collect();
        for measure in [Measure::Mi, Measure::Ccre] {
            let mut steps = Parzen::new(measure, DEFAULT_BINS);
            steps.set_template(&t);
            // (the template, the patch, with respect to what, the kind) of each call, in the
            // order of a run that also switches side, kind and template.
            let calls = [
                (0, 0, Wrt::Current, HessianKind::Newton),
                (0, 1, Wrt::Current, HessianKind::Newton),
                (0, 1, Wrt::Current, HessianKind::Newton),
                (0, 2, Wrt::Template, HessianKind::Newton),
                (0, 2, Wrt::Current, HessianKind::Newton),
                (0, 2, Wrt::Current, HessianKind::AfterConvergence),
                (0, 2, Wrt::Current, HessianKind::Newton),
                (0, 2, Wrt::Current, HessianKind::AfterConvergence),
                (0, 0, Wrt::Current, HessianKind::AfterConvergence),
                (0, 1, Wrt::Template, HessianKind::AfterConvergence),
                (0, 0, Wrt::Template, HessianKind::AfterConvergence),
                (0, 1, Wrt::Current, HessianKind::AfterConvergence),
                (0, 0, Wrt::Current, HessianKind::GaussNewton),
                (0, 2, Wrt::Current, HessianKind::Newton),
                (0, 1, Wrt::Current, HessianKind::AfterConvergence),
                // Another template: what was kept of the first is not reused.
                (1, 1, Wrt::Current, HessianKind::AfterConvergence),
                (1, 2, Wrt::Current, HessianKind::AfterConvergence),
            ];
            let templates = [&t, &patches[0]];
            let mut template = 0;
            for (i, &(tpl, k, wrt, kind)) in calls.iter().enumerate() {
                if tpl != template {
                    steps.set_template(templates[tpl]);
                    template = tpl;
                }
                let (mut g1, mut g2) = (vec![0f32; n], vec![0f32; n]);
                let (mut h1, mut h2) = ([0.0; MAX_DOF * MAX_DOF], [0.0; MAX_DOF * MAX_DOF]);
                steps.gradient(wrt, &patches[k], &mut g1);
                steps.hessian(wrt, kind, &patches[k], &jac, dof, &mut h1);
                let mut fresh = Parzen::new(measure, DEFAULT_BINS);
                fresh.set_template(templates[tpl]);
                fresh.gradient(wrt, &patches[k], &mut g2);
                fresh.hessian(wrt, kind, &patches[k], &jac, dof, &mut h2);
                assert_eq!(g1, g2, "{measure:?} call {i}: gradient");
                assert_eq!(
                    h1.map(f64::to_bits),
                    h2.map(f64::to_bits),
                    "{measure:?} call {i}: Hessian"
                );
            }
        }
    }

    /// After convergence, `V` made from each bin's six Bernstein sums along the pixels grouped
    /// by bin gives the Hessian summed cell by cell (16 products a pixel), for both measures,
    /// sides, bins and fewer parameters than lanes, with pixels clamped or not finite, and long
    /// runs of one bin (a ramp) as well as short ones.
    #[test]
    fn hessians_after_convergence_from_bin_sums_are_those_summed_cell_by_cell() {
        let mut rng = crate::rng::Rng::new(13);
        let n = 911;
        let mut t: Vec<f32> = (0..n).map(|_| rng.range(0.0, 255.0) as f32).collect();
        for (i, v) in t[300..900].iter_mut().enumerate() {
            *v = 40.0 + i as f32 * 0.05;
        }
        (t[3], t[10], t[20], t[21]) = (-400.0, 900.0, f32::NAN, 255.0);
        for dof in [8, 4] {
            let jac: Vec<f32> = (0..dof * n).map(|_| rng.range(-3.0, 3.0) as f32).collect();
            for measure in [Measure::Mi, Measure::Ccre] {
                for bins in [8, 16] {
                    let mut m = Parzen::new(measure, bins);
                    m.set_template(&t);
                    let mut st = Stats::new(m.bins.side);
                    st.compute(measure, &m.tw, &m.tw);
                    let mut same = SameBin::default();
                    same.build(&m.tw, m.bins.side);
                    assert!(
                        same.runs.len() > same.bins.len(),
                        "runs split at RUN pixels"
                    );
                    for current in [true, false] {
                        let mut h = [[0.0; MAX_DOF * MAX_DOF]; 2];
                        let mut diag = [vec![0f32; n], vec![0f32; n]];
                        for (k, (h, diag)) in h.iter_mut().zip(&mut diag).enumerate() {
                            let by_bin = (k == 0).then_some(&same);
                            let (tw, v, scratch) = (&m.tw, &mut m.v, &mut m.scratch);
                            let bins = &m.bins;
                            newton(
                                measure,
                                bins,
                                &st,
                                tw,
                                tw,
                                current,
                                &jac,
                                dof,
                                by_bin,
                                v,
                                scratch,
                                (diag, false),
                                h,
                            );
                        }
                        assert_eq!(diag[0], diag[1]);
                        let scale = h[1].iter().fold(0.0f64, |a, &x| a.max(x.abs()));
                        assert!(scale > 0.0);
                        for (a, b) in h[0].iter().zip(&h[1]) {
                            assert!(
                                (a - b).abs() <= 1e-5 * scale,
                                "{measure:?} bins {bins} dof {dof} current {current}: {a} {b}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// The joint histogram (built in blocks of pairs of first bins, then added into the
    /// cells) is the plain sum of every pixel's weight products, and MI is its definition over
    /// that histogram: few pixels, random ones, and 2,500 of a smooth patch (long runs of one
    /// block) with values beyond the bins' range and not finite.
    #[test]
    fn the_joint_histogram_and_mi_are_their_definitions() {
        let mut rng = crate::rng::Rng::new(5);
        for n in [1usize, 2, 37, 256, 2500] {
            let t: Vec<f32> = (0..n)
                .map(|i| match (n, i) {
                    (2500, 7) => f32::NAN,
                    (2500, 8) => -400.0,
                    (2500, 9) => 700.0,
                    (2500, _) => (128.0 + 100.0 * ((i % 50) as f64 / 9.0).sin()) as f32,
                    _ => rng.range(0.0, 255.0) as f32,
                })
                .collect();
            let c: Vec<f32> = t
                .iter()
                .map(|&v| 0.7 * v + 20.0 + rng.range(-10.0, 10.0) as f32)
                .collect();
            let bins = Bins::new(DEFAULT_BINS);
            let side = bins.side;
            let (mut tw, mut cw) = (Weights::default(), Weights::default());
            tw.fill_with(&t, &bins);
            cw.fill_with(&c, &bins);
            let mut p = vec![0.0f64; side * side];
            for j in 0..n {
                for u in 0..4 {
                    for v in 0..4 {
                        let at = (tw.base[j] as usize + u) * side + cw.base[j] as usize + v;
                        p[at] += tw.w[j][u] as f64 * cw.w[j][v] as f64 / n as f64;
                    }
                }
            }
            let (mut pt, mut pc) = (vec![0.0; side], vec![0.0; side]);
            for a in 0..side {
                for b in 0..side {
                    pt[a] += p[a * side + b];
                    pc[b] += p[a * side + b];
                }
            }
            let mut mi = 0.0;
            for a in 0..side {
                for b in 0..side {
                    let v = p[a * side + b];
                    if v > 0.0 {
                        mi += v * (v / (pt[a] * pc[b])).ln();
                    }
                }
            }
            for measure in [Measure::Mi, Measure::Ccre] {
                let mut model = Parzen::new(measure, DEFAULT_BINS);
                model.set_template(&t);
                let value = model.similarity(&c);
                let st = &model.stats;
                for a in 0..side {
                    for b in 0..side {
                        let inside = (st.rows.0..st.rows.1).contains(&a)
                            && (st.cols.0..st.cols.1).contains(&b);
                        let got = if inside { st.p[a * side + b] } else { 0.0 };
                        assert!(
                            (got - p[a * side + b]).abs() < 1e-12,
                            "{n} pixels, cell ({a}, {b}): {got} vs {}",
                            p[a * side + b]
                        );
                    }
                }
                if measure == Measure::Mi {
                    assert!((value - mi).abs() < 1e-9, "{n} pixels: MI {value} vs {mi}");
                }
            }
        }
    }

    #[test]
    fn negative_part_of_a_matrix() {
        // diag(-3, 2) rotated by 30 degrees: the negative part is -3 u u^T.
        let (c, s) = (0.75f64.sqrt(), 0.5);
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        let (l1, l2) = (-3.0, 2.0);
        h[0] = l1 * c * c + l2 * s * s;
        h[1] = (l1 - l2) * c * s;
        h[2] = h[1];
        h[3] = l1 * s * s + l2 * c * c;
        negative_part(&mut h, 2);
        let want = [l1 * c * c, l1 * c * s, l1 * c * s, l1 * s * s];
        for i in 0..4 {
            assert!((h[i] - want[i]).abs() < 1e-12, "{i}: {} {}", h[i], want[i]);
        }
    }
}
