//! The Newton system of the least-squares AMs from the gradient's moments on the grid: the
//! forward methods' step without the pixel Jacobian.
//!
//! The correlations (ZNCC, NCC) take it too: their Hessian is `J^T J` less outer products of
//! `J^T x` for a few per-pixel vectors `x` (the patch's unit vector, the ones, the template's
//! unit vector for Newton's), and each `J^T x` is a sum of the same kind as `J^T r`
//! ([`GridMoments::jtr`]); the AM assembles it ([`crate::am::Am::hessian_from_projections`],
//! [`crate::sm::newton::moments_system`]).
//!
//! With an AM whose Hessian is `-J^T J` ([`crate::am::Am::hessian_is_minus_jtj`]: SSD, SCV, LSCV), a
//! forward-compositional step needs `J^T J` and `J^T r`, where row `i` of `J` is the warped
//! gradient `g_i` times the SSM's `dw/dp` at the identity, `D(x_i)`, in the normalised
//! coordinates `x`. The grid is regular in the coordinates `u = (u, v)` of the unit square, which
//! the initial quad's homography `G` maps to `x = G(u)`. Every SSM here is a family of
//! homographies, and conjugating by `G` maps an infinitesimal homography to an infinitesimal
//! homography, so `D(G(u)) = dG(u) D_u(u) L`, with `D_u` the full homography's
//! (`(u, v, 1, 0, 0, 0, -u^2, -u v)` for `w_x`, `(0, 0, 0, u, v, 1, -u v, -v^2)` for `w_y`) and
//! `L` a constant `8 x dof` matrix (fitted once per region, by least squares over the grid, and
//! checked). With `g_u = g dG` the gradient with respect to `u` (the warped gradient taken with
//! the pixel matrix times `G`, the same work per sample), `J = J_u L`, so
//! `J^T J = L^T (J_u^T J_u) L` and `J^T r = L^T (J_u^T r)`: the same Newton step.
//!
//! The entries of `J_u^T J_u` are sums over the grid of `a^2, a b, b^2` (`g_u = (a, b)`) times
//! monomials `u^i v^j`, `i + j <= 4`, those of `J_u^T r` sums of `r a, r b` times monomials of
//! degree two at most. On the regular grid each sum separates: down every column, weighted by
//! powers of the row's `v` (21 multiply-adds per sample, eight columns at a time in registers),
//! then across the columns, weighted by powers of the column's `u`. The projection (12
//! operations per sample for the homography), `J^T J` (36) and `J^T r` (8) are not needed.

use crate::linalg::MAX_DOF;

/// The most parameters an SSM with grid moments has: `L` maps the full homography's eight to
/// them, so a model of more (the spline SSMs) has none.
const MOMENTS_DOF: usize = 8;
use crate::spec::GridLayout;
use nalgebra::{Matrix3, SMatrix};

/// Eight f32 lanes (eight neighbouring columns).
type Lanes = [f32; 8];

/// Powers `0..=4` of the row coordinate.
const POWERS: usize = 5;
/// Column sums per block of eight columns: `a^2, a b, b^2` times `v^0..=4` (15), `r a, r b` times
/// `v^0..=2` (6).
const SUMS: usize = 3 * POWERS + 2 * 3;

/// How far `D(G(u))` may be from `dG(u) D_u(u) L` (relative to the largest entry of `D`) for the
/// fit to be used: the SSM is then a family of homographies (f32 rounding is about 1e-7).
const FIT_TOLERANCE: f64 = 1e-5;

/// The Newton system from the gradient's moments on one region's grid (see the module's
/// documentation).
#[derive(Clone, Debug)]
pub struct GridMoments {
    res: usize,
    dof: usize,
    /// `L`, row-major `8 x dof` (stride [`MOMENTS_DOF`]).
    l: [f64; 8 * MOMENTS_DOF],
    /// The unit square's coordinates of the grid's columns and rows.
    u: Vec<f32>,
    /// `v^j` of each row.
    vpow: Vec<[f32; POWERS]>,
    /// `u^i` of each column, `i = 0..=4`, in the lanes of the column blocks (a multiple of eight
    /// long: the last block holds the last eight columns).
    upow: [Vec<f32>; POWERS],
    /// The column sums ([`SUMS`] rows of the padded column count).
    sums: Vec<f32>,
}

impl GridMoments {
    /// The moments of a `res x res` grid of `layout` whose normalised points are `G(u)`, for an
    /// SSM whose `dw/dp` at the identity on the grid is `dwdp0` (layout of
    /// [`crate::ssm::Ssm::jacobian`]); `None` when that is not a family of homographies (the
    /// fit misses) or the system would not be cheaper (fewer than six parameters).
    pub fn new(
        g: &Matrix3<f64>,
        res: usize,
        layout: GridLayout,
        dwdp0: &[f32],
        dof: usize,
    ) -> Option<Self> {
        let n = res * res;
        if !(6..=MOMENTS_DOF).contains(&dof) || res < 8 || dwdp0.len() < 2 * dof * n {
            return None;
        }
        let coords = unit_coordinates(res, layout);
        let l = fit_l(g, &coords, dwdp0, dof)?;
        // Block b's lanes are columns 8 b.. but the last block's, which are the last eight.
        let blocks = res.div_ceil(8);
        let padded = blocks * 8;
        let upow = std::array::from_fn(|i| {
            let mut v = vec![0f32; padded];
            for (slot, o) in v.iter_mut().enumerate() {
                let (block, lane) = (slot / 8, slot % 8);
                let column = (8 * block).min(res - 8) + lane;
                *o = (coords[column] as f32).powi(i as i32);
            }
            v
        });
        let vpow = coords
            .iter()
            .map(|&v| std::array::from_fn(|j| (v as f32).powi(j as i32)))
            .collect();
        Some(GridMoments {
            res,
            dof,
            l,
            u: coords.iter().map(|&u| u as f32).collect(),
            vpow,
            upow,
            sums: vec![0.0; SUMS * padded],
        })
    }

    /// The unit square's coordinate of each column (and row) of the grid.
    pub fn coordinates(&self) -> &[f32] {
        &self.u
    }

    /// `h = -J^T J` (row-major `dof x dof`) and `g = J^T r` for the gradient `(a, b)` with
    /// respect to the unit square's coordinates and the AM's gradient `r`, all on the grid (a
    /// colour grid's parts, the same `res x res` points once per channel, summed: the system
    /// is a sum over the samples).
    pub fn minus_jtj_and_jtr(
        &mut self,
        a: &[f32],
        b: &[f32],
        r: &[f32],
        h: &mut [f64; MAX_DOF * MAX_DOF],
        g: &mut [f64; MAX_DOF],
    ) {
        let n = self.res * self.res;
        let (mut hu, mut gu) = self.unit_system(a, b, r);
        for c in 1..a.len() / n {
            let part = c * n..(c + 1) * n;
            let (hc, gc) = self.unit_system(&a[part.clone()], &b[part.clone()], &r[part]);
            for (row, more) in hu.iter_mut().zip(&hc) {
                for (o, v) in row.iter_mut().zip(more) {
                    *o += v;
                }
            }
            for (o, v) in gu.iter_mut().zip(&gc) {
                *o += v;
            }
        }
        let (dof, l) = (self.dof, &self.l);
        // H = L^T Hu L, g = L^T gu.
        let mut hl = [[0.0f64; MOMENTS_DOF]; 8];
        for (k, row) in hl.iter_mut().enumerate() {
            for (m, o) in row.iter_mut().enumerate().take(dof) {
                *o = (0..8).map(|q| hu[k][q] * l[q * MOMENTS_DOF + m]).sum();
            }
        }
        for i in 0..dof {
            for j in i..dof {
                let v: f64 = (0..8).map(|k| l[k * MOMENTS_DOF + i] * hl[k][j]).sum();
                h[i * dof + j] = -v;
                h[j * dof + i] = -v;
            }
        }
        self.l_transposed(&gu, g);
    }

    /// `g = J^T r` alone, for the gradient `(a, b)` with respect to the unit square's
    /// coordinates and the AM's gradient `r`: ICLK's right-hand side, whose Jacobian is the
    /// template's (its Hessian is kept). Six multiply-adds per sample, and neither `J` (eight
    /// values a sample) nor the AM's kind matter.
    pub fn jtr(&mut self, a: &[f32], b: &[f32], r: &[f32], g: &mut [f64; MAX_DOF]) {
        let n = self.res * self.res;
        let mut gu = self.unit_jtr(a, b, r);
        // A colour grid's other parts (see `minus_jtj_and_jtr`).
        for c in 1..a.len() / n {
            let part = c * n..(c + 1) * n;
            let more = self.unit_jtr(&a[part.clone()], &b[part.clone()], &r[part]);
            for (o, v) in gu.iter_mut().zip(&more) {
                *o += v;
            }
        }
        self.l_transposed(&gu, g);
    }

    /// `J_u^T r` of the full homography on the first `res x res` samples.
    fn unit_jtr(&mut self, a: &[f32], b: &[f32], r: &[f32]) -> [f64; 8] {
        let (res, n) = (self.res, self.res * self.res);
        let (a, b, r) = (&a[..n], &b[..n], &r[..n]);
        let vpow = &self.vpow;
        down_columns(&mut self.sums, res, 3 * POWERS, |c0, skip| {
            column_block_r(a, b, r, res, c0, skip, vpow)
        });
        let mut mom = [[0.0f64; POWERS]; SUMS];
        self.across(3 * POWERS..SUMS, &mut mom);
        unit_gradient_sums(&mom)
    }

    /// `g = L^T gu`: the unit square's gradient sums to the SSM's parameters.
    fn l_transposed(&self, gu: &[f64; 8], g: &mut [f64; MAX_DOF]) {
        for (i, o) in g.iter_mut().enumerate().take(self.dof) {
            *o = (0..8).map(|k| self.l[k * MOMENTS_DOF + i] * gu[k]).sum();
        }
    }

    /// Across the columns: `mom[s][i] = sum_c u_c^i S[s][c]` for the column sums' rows `rows`
    /// (weight and power of v) and the powers of u that the system needs (total degree four,
    /// two for `r a`, `r b`), each once, eight columns in lanes.
    fn across(&self, rows: std::ops::Range<usize>, mom: &mut [[f64; POWERS]; SUMS]) {
        let padded = self.upow[0].len();
        for s in rows {
            let (weight, j) = if s < 3 * POWERS {
                (s / POWERS, s % POWERS)
            } else {
                (3, (s - 3 * POWERS) % 3)
            };
            let degree = if weight < 3 { 4 } else { 2 };
            let sums = &self.sums[s * padded..][..padded];
            for (i, o) in mom[s].iter_mut().enumerate().take(degree + 1 - j) {
                let mut lanes: Lanes = [0.0; 8];
                for (cs, cu) in sums.chunks_exact(8).zip(self.upow[i].chunks_exact(8)) {
                    for k in 0..8 {
                        lanes[k] = cs[k].mul_add(cu[k], lanes[k]);
                    }
                }
                *o = lanes.iter().map(|&v| v as f64).sum();
            }
        }
    }

    /// `J_u^T J_u` and `J_u^T r` of the full homography in the unit square's coordinates.
    fn unit_system(&mut self, a: &[f32], b: &[f32], r: &[f32]) -> ([[f64; 8]; 8], [f64; 8]) {
        let (res, n) = (self.res, self.res * self.res);
        let (a, b, r) = (&a[..n], &b[..n], &r[..n]);
        let vpow = &self.vpow;
        // Pairs of blocks in 512-bit registers where the processor has them (the same bits).
        down_columns_wide(
            &mut self.sums,
            res,
            0,
            |c0, skip| column_block(a, b, r, res, c0, skip, vpow),
            |c0, out, stride| column_block16(a, b, r, res, c0, vpow, (out, stride)),
        );
        let mut mom = [[0.0f64; POWERS]; SUMS];
        self.across(0..SUMS, &mut mom);
        // The sums' rows: weight w (0: a^2, 1: a b, 2: b^2) at power j is row w * 5 + j; r a at
        // power j is row 15 + j, r b row 18 + j.
        let ma = |i: usize, j: usize| mom[j][i];
        let mb = |i: usize, j: usize| mom[POWERS + j][i];
        let mc = |i: usize, j: usize| mom[2 * POWERS + j][i];
        // J_u = (a u, a v, a, b u, b v, b, -u s, -v s), s = a u + b v.
        let mut h = [[0.0f64; 8]; 8];
        let mut set = |i: usize, j: usize, v: f64| {
            h[i][j] = v;
            h[j][i] = v;
        };
        set(0, 0, ma(2, 0));
        set(0, 1, ma(1, 1));
        set(0, 2, ma(1, 0));
        set(0, 3, mb(2, 0));
        set(0, 4, mb(1, 1));
        set(0, 5, mb(1, 0));
        set(0, 6, -(ma(3, 0) + mb(2, 1)));
        set(0, 7, -(ma(2, 1) + mb(1, 2)));
        set(1, 1, ma(0, 2));
        set(1, 2, ma(0, 1));
        set(1, 3, mb(1, 1));
        set(1, 4, mb(0, 2));
        set(1, 5, mb(0, 1));
        set(1, 6, -(ma(2, 1) + mb(1, 2)));
        set(1, 7, -(ma(1, 2) + mb(0, 3)));
        set(2, 2, ma(0, 0));
        set(2, 3, mb(1, 0));
        set(2, 4, mb(0, 1));
        set(2, 5, mb(0, 0));
        set(2, 6, -(ma(2, 0) + mb(1, 1)));
        set(2, 7, -(ma(1, 1) + mb(0, 2)));
        set(3, 3, mc(2, 0));
        set(3, 4, mc(1, 1));
        set(3, 5, mc(1, 0));
        set(3, 6, -(mb(3, 0) + mc(2, 1)));
        set(3, 7, -(mb(2, 1) + mc(1, 2)));
        set(4, 4, mc(0, 2));
        set(4, 5, mc(0, 1));
        set(4, 6, -(mb(2, 1) + mc(1, 2)));
        set(4, 7, -(mb(1, 2) + mc(0, 3)));
        set(5, 5, mc(0, 0));
        set(5, 6, -(mb(2, 0) + mc(1, 1)));
        set(5, 7, -(mb(1, 1) + mc(0, 2)));
        set(6, 6, ma(4, 0) + 2.0 * mb(3, 1) + mc(2, 2));
        set(6, 7, ma(3, 1) + 2.0 * mb(2, 2) + mc(1, 3));
        set(7, 7, ma(2, 2) + 2.0 * mb(1, 3) + mc(0, 4));
        let g = unit_gradient_sums(&mom);
        (h, g)
    }
}

/// Down the columns of a `res`-wide grid, eight at a time: `kernel(c0, skip)` gives a block's
/// sums (weighted by the rows' powers of v), stored in `sums` (rows of the padded column count)
/// from row `first` on. The last block is the last eight columns, those of the block before it
/// masked out (`skip`).
fn down_columns<const K: usize>(
    sums: &mut [f32],
    res: usize,
    first: usize,
    kernel: impl Fn(usize, usize) -> [Lanes; K],
) {
    let padded = res.div_ceil(8) * 8;
    for block in 0..res.div_ceil(8) {
        let c0 = (8 * block).min(res - 8);
        for (s, lanes) in kernel(c0, 8 * block - c0).iter().enumerate() {
            sums[(first + s) * padded + 8 * block..][..8].copy_from_slice(lanes);
        }
    }
}

/// [`down_columns`] with a kernel that sums two neighbouring blocks at once wherever both are
/// whole (not the last, overlapping block): `wide(c0, out, stride)` writes the sixteen columns
/// from `c0` of each of the `K` sums, sum `s` at `out[s * stride + c0..]`, or returns `false`
/// (no such kernel here). Each block's sums are those `kernel` gives it, when `wide` makes the
/// same sums lane by lane.
fn down_columns_wide<const K: usize>(
    sums: &mut [f32],
    res: usize,
    first: usize,
    kernel: impl Fn(usize, usize) -> [Lanes; K],
    wide: impl Fn(usize, &mut [f32], usize) -> bool,
) {
    let padded = res.div_ceil(8) * 8;
    let mut block = 0;
    while block < res.div_ceil(8) {
        let c0 = 8 * block;
        if c0 + 16 <= res && wide(c0, &mut sums[first * padded..], padded) {
            block += 2;
            continue;
        }
        let c0 = c0.min(res - 8);
        for (s, lanes) in kernel(c0, 8 * block - c0).iter().enumerate() {
            sums[(first + s) * padded + 8 * block..][..8].copy_from_slice(lanes);
        }
        block += 1;
    }
}

/// `J_u^T r` from the moments of `r a` and `r b` (rows `15..21` of `mom`, see
/// [`GridMoments::unit_system`]): `J_u = (a u, a v, a, b u, b v, b, -u s, -v s)`, `s = a u + b v`.
fn unit_gradient_sums(mom: &[[f64; POWERS]; SUMS]) -> [f64; 8] {
    let ra = |i: usize, j: usize| mom[3 * POWERS + j][i];
    let rb = |i: usize, j: usize| mom[3 * POWERS + 3 + j][i];
    [
        ra(1, 0),
        ra(0, 1),
        ra(0, 0),
        rb(1, 0),
        rb(0, 1),
        rb(0, 0),
        -(ra(2, 0) + rb(1, 1)),
        -(ra(1, 1) + rb(0, 2)),
    ]
}

/// A column kernel's call: its bounds checked (the kernels read eight values from `row * res +
/// c0` for every row), then the AVX version where the build has AVX2 and FMA, the plain one
/// elsewhere.
macro_rules! kernel {
    ($simd:path, $plain:path, ($a:expr, $b:expr, $r:expr, $res:expr, $c0:expr, $skip:expr, $vpow:expr)) => {{
        let end = ($vpow.len().max(1) - 1) * $res + $c0 + 8;
        assert!(
            $c0 + 8 <= $res && end <= $a.len() && end <= $b.len() && end <= $r.len() && $skip < 8
        );
        #[cfg(simd = "avx2")]
        {
            $simd($a, $b, $r, $res, $c0, $skip, $vpow)
        }
        #[cfg(not(simd = "avx2"))]
        {
            $plain($a, $b, $r, $res, $c0, $skip, $vpow)
        }
    }};
}

/// The column sums of the eight columns from `c0` down every row of a `res`-wide grid (`c0 + 8
/// <= res`), the first `skip` lanes left out: rows `0..5` `a^2 v^j`, `5..10` `a b v^j`, `10..15`
/// `b^2 v^j`, `15..18` `r a v^j`, `18..21` `r b v^j`.
fn column_block(
    a: &[f32],
    b: &[f32],
    r: &[f32],
    res: usize,
    c0: usize,
    skip: usize,
    vpow: &[[f32; POWERS]],
) -> [Lanes; SUMS] {
    kernel!(
        simd::column_block,
        column_block_portable,
        (a, b, r, res, c0, skip, vpow)
    )
}

/// [`column_block`] of the sixteen columns from `c0` (`c0 + 16 <= res`, no lane skipped) in
/// 512-bit registers, the same products and sums lane by lane, sum `s` written to
/// `out[s * stride + c0..][..16]`; `false` (nothing written) where the build or the processor
/// has no AVX-512 ([`crate::cpu::avx512`]).
#[allow(unused_variables)]
fn column_block16(
    a: &[f32],
    b: &[f32],
    r: &[f32],
    res: usize,
    c0: usize,
    vpow: &[[f32; POWERS]],
    (out, stride): (&mut [f32], usize),
) -> bool {
    #[cfg(simd = "avx2")]
    if crate::cpu::avx512() {
        let end = (vpow.len().max(1) - 1) * res + c0 + 16;
        assert!(c0 + 16 <= res && end <= a.len() && end <= b.len() && end <= r.len());
        assert!(stride >= c0 + 16 && out.len() >= (SUMS - 1) * stride + c0 + 16);
        // SAFETY: the processor has AVX-512F (checked above); the kernel reads sixteen values
        // from row * res + c0 for every row below vpow.len(), within the slices, and writes
        // sixteen from s * stride + c0 for each sum s, within `out` (both asserted).
        unsafe { simd::column_block16(a, b, r, res, c0, vpow, (out, stride)) };
        return true;
    }
    false
}

/// The six sums of [`column_block`] that `J^T r` needs (its rows `15..21`: `r a v^j`, `r b v^j`,
/// `j = 0..=2`).
fn column_block_r(
    a: &[f32],
    b: &[f32],
    r: &[f32],
    res: usize,
    c0: usize,
    skip: usize,
    vpow: &[[f32; POWERS]],
) -> [Lanes; 6] {
    kernel!(
        simd::column_block_r,
        column_block_r_portable,
        (a, b, r, res, c0, skip, vpow)
    )
}

/// [`column_block_r`] without vector instructions (the same bits).
#[cfg(any(test, not(simd = "avx2")))]
fn column_block_r_portable(
    a: &[f32],
    b: &[f32],
    r: &[f32],
    res: usize,
    c0: usize,
    skip: usize,
    vpow: &[[f32; POWERS]],
) -> [Lanes; 6] {
    let mut acc = [[0f32; 8]; 6];
    for (row, vp) in vpow.iter().enumerate() {
        for k in skip..8 {
            let i = row * res + c0 + k;
            let (ra, rb) = (r[i] * a[i], r[i] * b[i]);
            for j in 0..3 {
                acc[j][k] = ra.mul_add(vp[j], acc[j][k]);
                acc[3 + j][k] = rb.mul_add(vp[j], acc[3 + j][k]);
            }
        }
    }
    acc
}

/// [`column_block`] without vector instructions: the same products and sums, lane by lane, in
/// the same order (so the same bits).
#[cfg(any(test, not(simd = "avx2")))]
fn column_block_portable(
    a: &[f32],
    b: &[f32],
    r: &[f32],
    res: usize,
    c0: usize,
    skip: usize,
    vpow: &[[f32; POWERS]],
) -> [Lanes; SUMS] {
    let mut acc = [[0f32; 8]; SUMS];
    for (row, vp) in vpow.iter().enumerate() {
        for k in skip..8 {
            let i = row * res + c0 + k;
            let w = [
                a[i] * a[i],
                a[i] * b[i],
                b[i] * b[i],
                r[i] * a[i],
                r[i] * b[i],
            ];
            for j in 0..POWERS {
                for (t, &wt) in w.iter().enumerate().take(3) {
                    acc[t * POWERS + j][k] = wt.mul_add(vp[j], acc[t * POWERS + j][k]);
                }
            }
            for j in 0..3 {
                acc[3 * POWERS + j][k] = w[3].mul_add(vp[j], acc[3 * POWERS + j][k]);
                acc[3 * POWERS + 3 + j][k] = w[4].mul_add(vp[j], acc[3 * POWERS + 3 + j][k]);
            }
        }
    }
    acc
}

#[cfg(simd = "avx2")]
mod simd {
    use super::{Lanes, POWERS, SUMS};
    use std::arch::x86_64::*;

    /// [`super::column_block`] in AVX registers: two passes down the rows (ten sums, then
    /// eleven), so that every sum stays in a register.
    pub(super) fn column_block(
        a: &[f32],
        b: &[f32],
        r: &[f32],
        res: usize,
        c0: usize,
        skip: usize,
        vpow: &[[f32; POWERS]],
    ) -> [Lanes; SUMS] {
        let mut out = [[0f32; 8]; SUMS];
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); every load reads eight values
        // from row * res + c0 for a row below vpow.len(), within the slices (the caller asserts
        // it); the stores write the local array.
        unsafe {
            // Lanes below `skip` are zero (their columns belong to the block before).
            let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let keep =
                _mm256_castsi256_ps(_mm256_cmpgt_epi32(lane, _mm256_set1_epi32(skip as i32 - 1)));
            let load = |x: &[f32], row: usize| {
                _mm256_and_ps(_mm256_loadu_ps(x.as_ptr().add(row * res + c0)), keep)
            };
            let z = _mm256_setzero_ps();
            let (mut saa, mut sab) = ([z; POWERS], [z; POWERS]);
            for (row, vp) in vpow.iter().enumerate() {
                let (la, lb) = (load(a, row), load(b, row));
                let (aa, ab) = (_mm256_mul_ps(la, la), _mm256_mul_ps(la, lb));
                for j in 0..POWERS {
                    let v = _mm256_set1_ps(vp[j]);
                    saa[j] = _mm256_fmadd_ps(aa, v, saa[j]);
                    sab[j] = _mm256_fmadd_ps(ab, v, sab[j]);
                }
            }
            let (mut sbb, mut sra, mut srb) = ([z; POWERS], [z; 3], [z; 3]);
            for (row, vp) in vpow.iter().enumerate() {
                let (la, lb, lr) = (load(a, row), load(b, row), load(r, row));
                let (bb, ra, rb) = (
                    _mm256_mul_ps(lb, lb),
                    _mm256_mul_ps(lr, la),
                    _mm256_mul_ps(lr, lb),
                );
                for j in 0..POWERS {
                    let v = _mm256_set1_ps(vp[j]);
                    sbb[j] = _mm256_fmadd_ps(bb, v, sbb[j]);
                    if j < 3 {
                        sra[j] = _mm256_fmadd_ps(ra, v, sra[j]);
                        srb[j] = _mm256_fmadd_ps(rb, v, srb[j]);
                    }
                }
            }
            let all = saa.iter().chain(&sab).chain(&sbb).chain(&sra).chain(&srb);
            for (o, v) in out.iter_mut().zip(all) {
                _mm256_storeu_ps(o.as_mut_ptr(), *v);
            }
        }
        out
    }

    /// [`super::column_block`] of sixteen columns in 512-bit registers, in one pass down the
    /// rows (32 registers hold the 21 sums): in each lane the same products and multiply-adds,
    /// in the same order, as the AVX2 kernel's.
    ///
    /// # Safety
    /// The processor must have AVX-512F, every input slice must hold sixteen values from
    /// `row * res + c0` for each row below `vpow.len()`, and `out` sixteen from
    /// `s * stride + c0` for each sum `s`.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn column_block16(
        a: &[f32],
        b: &[f32],
        r: &[f32],
        res: usize,
        c0: usize,
        vpow: &[[f32; POWERS]],
        (out, stride): (&mut [f32], usize),
    ) {
        // SAFETY: the caller's contract.
        unsafe {
            let load = |x: &[f32], row: usize| _mm512_loadu_ps(x.as_ptr().add(row * res + c0));
            let z = _mm512_setzero_ps();
            let (mut saa, mut sab, mut sbb) = ([z; POWERS], [z; POWERS], [z; POWERS]);
            let (mut sra, mut srb) = ([z; 3], [z; 3]);
            for (row, vp) in vpow.iter().enumerate() {
                let (la, lb, lr) = (load(a, row), load(b, row), load(r, row));
                let (aa, ab, bb) = (
                    _mm512_mul_ps(la, la),
                    _mm512_mul_ps(la, lb),
                    _mm512_mul_ps(lb, lb),
                );
                let (ra, rb) = (_mm512_mul_ps(lr, la), _mm512_mul_ps(lr, lb));
                for j in 0..POWERS {
                    let v = _mm512_set1_ps(vp[j]);
                    saa[j] = _mm512_fmadd_ps(aa, v, saa[j]);
                    sab[j] = _mm512_fmadd_ps(ab, v, sab[j]);
                    sbb[j] = _mm512_fmadd_ps(bb, v, sbb[j]);
                    if j < 3 {
                        sra[j] = _mm512_fmadd_ps(ra, v, sra[j]);
                        srb[j] = _mm512_fmadd_ps(rb, v, srb[j]);
                    }
                }
            }
            let all = saa.iter().chain(&sab).chain(&sbb).chain(&sra).chain(&srb);
            for (s, v) in all.enumerate() {
                _mm512_storeu_ps(out.as_mut_ptr().add(s * stride + c0), *v);
            }
        }
    }

    /// [`super::column_block_r`] in AVX registers.
    pub(super) fn column_block_r(
        a: &[f32],
        b: &[f32],
        r: &[f32],
        res: usize,
        c0: usize,
        skip: usize,
        vpow: &[[f32; POWERS]],
    ) -> [Lanes; 6] {
        let mut out = [[0f32; 8]; 6];
        // SAFETY: as in `column_block`.
        unsafe {
            let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let keep =
                _mm256_castsi256_ps(_mm256_cmpgt_epi32(lane, _mm256_set1_epi32(skip as i32 - 1)));
            let load = |x: &[f32], row: usize| _mm256_loadu_ps(x.as_ptr().add(row * res + c0));
            let z = _mm256_setzero_ps();
            let (mut sra, mut srb) = ([z; 3], [z; 3]);
            for (row, vp) in vpow.iter().enumerate() {
                let lr = _mm256_and_ps(load(r, row), keep);
                let (ra, rb) = (
                    _mm256_mul_ps(lr, load(a, row)),
                    _mm256_mul_ps(lr, load(b, row)),
                );
                for j in 0..3 {
                    let v = _mm256_set1_ps(vp[j]);
                    sra[j] = _mm256_fmadd_ps(ra, v, sra[j]);
                    srb[j] = _mm256_fmadd_ps(rb, v, srb[j]);
                }
            }
            for (o, v) in out.iter_mut().zip(sra.iter().chain(&srb)) {
                _mm256_storeu_ps(o.as_mut_ptr(), *v);
            }
        }
        out
    }
}

/// The unit square's coordinates of a grid's columns (the same for its rows), as
/// [`crate::registration::Context::set_region`] lays them out.
pub fn unit_coordinates(res: usize, layout: GridLayout) -> Vec<f64> {
    let (step, offset) = match layout {
        GridLayout::Border if res > 1 => (1.0 / (res - 1) as f64, 0.0),
        _ => (1.0 / res as f64, 0.5),
    };
    (0..res)
        .map(|k| -0.5 + (k as f64 + offset) * step)
        .collect()
}

/// The full homography's `dw/dp` at the identity at `(u, v)`: `(dw_x/dp, dw_y/dp)`.
fn unit_dwdp(u: f64, v: f64) -> ([f64; 8], [f64; 8]) {
    (
        [u, v, 1.0, 0.0, 0.0, 0.0, -u * u, -u * v],
        [0.0, 0.0, 0.0, u, v, 1.0, -u * v, -v * v],
    )
}

/// The Jacobian of the homography `g` at `(u, v)`: `[[dX/du, dX/dv], [dY/du, dY/dv]]`.
pub fn homography_jacobian(g: &Matrix3<f64>, u: f64, v: f64) -> [[f64; 2]; 2] {
    let w = g[(2, 0)] * u + g[(2, 1)] * v + g[(2, 2)];
    let x = (g[(0, 0)] * u + g[(0, 1)] * v + g[(0, 2)]) / w;
    let y = (g[(1, 0)] * u + g[(1, 1)] * v + g[(1, 2)]) / w;
    [
        [
            (g[(0, 0)] - x * g[(2, 0)]) / w,
            (g[(0, 1)] - x * g[(2, 1)]) / w,
        ],
        [
            (g[(1, 0)] - y * g[(2, 0)]) / w,
            (g[(1, 1)] - y * g[(2, 1)]) / w,
        ],
    ]
}

/// `L` with `D(G(u)) = dG(u) D_u(u) L` on the grid (least squares, checked), row-major
/// `8 x dof` with stride [`MOMENTS_DOF`].
fn fit_l(
    g: &Matrix3<f64>,
    coords: &[f64],
    dwdp0: &[f32],
    dof: usize,
) -> Option<[f64; 8 * MOMENTS_DOF]> {
    let res = coords.len();
    let n = res * res;
    // The rows of E = dG D_u (two per point) and of D, for the normal equations.
    let mut ete = SMatrix::<f64, 8, 8>::zeros();
    let mut etd = SMatrix::<f64, 8, MOMENTS_DOF>::zeros();
    let rows = |i: usize| -> ([[f64; 8]; 2], [[f64; MOMENTS_DOF]; 2]) {
        let (u, v) = (coords[i % res], coords[i / res]);
        let j = homography_jacobian(g, u, v);
        let (dx, dy) = unit_dwdp(u, v);
        let e = [
            std::array::from_fn(|k| j[0][0] * dx[k] + j[0][1] * dy[k]),
            std::array::from_fn(|k| j[1][0] * dx[k] + j[1][1] * dy[k]),
        ];
        let d = [
            std::array::from_fn(|k| {
                if k < dof {
                    dwdp0[2 * k * n + i] as f64
                } else {
                    0.0
                }
            }),
            std::array::from_fn(|k| {
                if k < dof {
                    dwdp0[(2 * k + 1) * n + i] as f64
                } else {
                    0.0
                }
            }),
        ];
        (e, d)
    };
    // The normal equations from about 256 of the points (the fit is exact); the check below
    // takes them all.
    let mut largest = 0.0f64;
    for i in (0..n).step_by((n / 256).max(1)) {
        let (e, d) = rows(i);
        for t in 0..2 {
            for p in 0..8 {
                for q in 0..8 {
                    ete[(p, q)] += e[t][p] * e[t][q];
                }
                for m in 0..dof {
                    etd[(p, m)] += e[t][p] * d[t][m];
                }
            }
            largest = d[t].iter().fold(largest, |acc, v| acc.max(v.abs()));
        }
    }
    let l = ete.cholesky()?.solve(&etd);
    if !l.iter().all(|v| v.is_finite()) || largest == 0.0 {
        return None;
    }

    // The fit must be exact (to rounding) at every point: the SSM is a family of homographies.
    for i in 0..n {
        let (e, d) = rows(i);
        for t in 0..2 {
            for m in 0..dof {
                let fitted: f64 = (0..8).map(|k| e[t][k] * l[(k, m)]).sum();
                if (fitted - d[t][m]).abs() > FIT_TOLERANCE * largest {
                    return None;
                }
            }
        }
    }
    let mut out = [0.0; 8 * MOMENTS_DOF];
    for k in 0..8 {
        for m in 0..dof {
            out[k * MOMENTS_DOF + m] = l[(k, m)];
        }
    }
    Some(out)
}

/// A skewed quad, for the tests of the moments and of the Newton systems made of them.
#[cfg(test)]
pub(crate) fn skewed() -> crate::geometry::Quad {
    use crate::geometry::{Point, Quad};
    Quad([
        Point::new(100.0, 80.0),
        Point::new(190.0, 95.0),
        Point::new(175.0, 170.0),
        Point::new(92.0, 150.0),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::{self, HessianKind};
    use crate::registration::Problem;
    use crate::rng::Rng;
    use crate::ssm;

    /// The vector kernel of the column sums is the plain one, bit for bit, masked lanes included.
    #[test]
    fn the_column_kernel_is_the_plain_one() {
        let mut rng = Rng::new(3);
        let res = 13;
        let n = res * res;
        let mut draw = || -> Vec<f32> { (0..n).map(|_| (10.0 * rng.normal()) as f32).collect() };
        let (a, b, r) = (draw(), draw(), draw());
        let vpow: Vec<[f32; POWERS]> = unit_coordinates(res, GridLayout::Centres)
            .iter()
            .map(|&v| std::array::from_fn(|j| (v as f32).powi(j as i32)))
            .collect();
        for (c0, skip) in [(0, 0), (5, 3), (5, 0)] {
            let fast = column_block(&a, &b, &r, res, c0, skip, &vpow);
            let plain = column_block_portable(&a, &b, &r, res, c0, skip, &vpow);
            for (f, p) in fast.iter().zip(&plain) {
                for (x, y) in f.iter().zip(p) {
                    assert_eq!(x.to_bits(), y.to_bits(), "block at {c0}, {skip} skipped");
                }
            }
            assert!(fast.iter().all(|l| l[..skip].iter().all(|&v| v == 0.0)));
            let fast = column_block_r(&a, &b, &r, res, c0, skip, &vpow);
            let plain = column_block_r_portable(&a, &b, &r, res, c0, skip, &vpow);
            for (f, p) in fast.iter().zip(&plain) {
                for (x, y) in f.iter().zip(p) {
                    assert_eq!(x.to_bits(), y.to_bits(), "r block at {c0}, {skip} skipped");
                }
            }
            // The gradient's sums are the full kernel's (its rows 15..21).
            let full = column_block(&a, &b, &r, res, c0, skip, &vpow);
            assert_eq!(fast[..], full[3 * POWERS..]);
            assert!(fast.iter().all(|l| l[..skip].iter().all(|&v| v == 0.0)));
        }
    }

    /// Summing pairs of column blocks at once gives every block the sums the one-block kernel
    /// gives it, bit for bit: the pairing (two blocks from the kernel's own sums, on any
    /// processor) and the 512-bit kernel (where the processor has AVX-512), at widths where
    /// the last block overlaps and where it does not.
    #[test]
    fn the_wide_column_sums_are_the_narrow_ones() {
        let mut rng = Rng::new(11);
        for res in [8, 13, 16, 17, 24, 31, 50, 64] {
            let n = res * res;
            let mut draw =
                || -> Vec<f32> { (0..n).map(|_| (10.0 * rng.normal()) as f32).collect() };
            let (a, b, r) = (draw(), draw(), draw());
            let vpow: Vec<[f32; POWERS]> = unit_coordinates(res, GridLayout::Centres)
                .iter()
                .map(|&v| std::array::from_fn(|j| (v as f32).powi(j as i32)))
                .collect();
            let kernel = |c0, skip| column_block(&a, &b, &r, res, c0, skip, &vpow);
            let padded = res.div_ceil(8) * 8;
            let mut narrow = vec![f32::NAN; SUMS * padded];
            down_columns(&mut narrow, res, 0, kernel);
            let paired = |c0: usize, out: &mut [f32], stride: usize| {
                let (lo, hi) = (kernel(c0, 0), kernel(c0 + 8, 0));
                for s in 0..SUMS {
                    out[s * stride + c0..][..8].copy_from_slice(&lo[s]);
                    out[s * stride + c0 + 8..][..8].copy_from_slice(&hi[s]);
                }
                true
            };
            let wide = |c0, out: &mut [f32], stride| {
                column_block16(&a, &b, &r, res, c0, &vpow, (out, stride))
            };
            for (what, sums) in [
                ("paired", {
                    let mut o = vec![f32::NAN; SUMS * padded];
                    down_columns_wide(&mut o, res, 0, kernel, paired);
                    o
                }),
                ("512-bit", {
                    let mut o = vec![f32::NAN; SUMS * padded];
                    down_columns_wide(&mut o, res, 0, kernel, wide);
                    o
                }),
            ] {
                for (i, (x, y)) in sums.iter().zip(&narrow).enumerate() {
                    assert_eq!(x.to_bits(), y.to_bits(), "{what}, res {res}, sum {i}");
                }
            }
        }
    }

    /// Only the models whose Hessian is `-J^T J` or made from `J^T J` and projections (the
    /// correlations) take the moments, on grids of eight columns or more, and a `dw/dp` that is
    /// not a family of homographies is refused (the fit is checked, not trusted).
    #[test]
    fn the_moments_are_refused_where_they_do_not_hold() {
        let problem = |am_name: &str, res: usize| {
            let mut p = Problem::new(
                ssm::build("homography").unwrap(),
                am::build(am_name).unwrap(),
                HessianKind::Default,
                res,
            );
            p.set_region(&skewed(), res, GridLayout::Centres).unwrap();
            p
        };
        assert!(problem("ssd", 7).moments().is_none());
        let res = 9;
        assert!(problem("mi", res).moments().is_none());
        assert!(problem("zncc", res).moments().is_some());
        let ssd = problem("ssd", res);
        let fits = |dwdp: &[f32]| GridMoments::new(ssd.unit(), res, GridLayout::Centres, dwdp, 8);
        let dwdp0 = ssd.dwdp0().0;
        assert!(fits(dwdp0).is_some());
        // dw_x/dp_0 = x^2 y: no homography moves points so.
        let n = res * res;
        let mut bent = dwdp0.to_vec();
        let (gx, gy) = ssd.grid();
        for i in 0..n {
            let (x, y) = (gx[i], gy[i]);
            bent[i] = x * x * y;
        }
        assert!(fits(&bent).is_none());
    }
}
