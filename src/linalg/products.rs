//! Products of patches and pixel Jacobians, the sums every search method and appearance model
//! makes: `J^T J` (and `J^T diag(d) J`), `J^T v` for one or several vectors, a patch's dot
//! product and sum. Each is summed in f32 within blocks of 256 samples (in the L1 cache while
//! it is read) and in f64 across blocks; the `J^T` kernels are AVX2 and FMA intrinsics where
//! the build has them (the crate's `simd` cfg, see `build.rs`) and the same arithmetic in plain
//! Rust elsewhere, compared by a test.

use super::{MAX_DOF, Square, lanes_sum};

/// `out = -J^T J` (row-major `dof x dof`), the Gauss-Newton Hessian of SSD.
pub fn minus_jtj(jac: &[f32], dof: usize, out: &mut Square) {
    out[..dof * dof].fill(0.0);
    jtj_into(jac, None, dof, dof, out);
    out[..dof * dof].iter_mut().for_each(|v| *v = -*v);
}

/// The dot product of two patches: 32 f32 lanes (four independent vector accumulators) over
/// blocks of 256 pixels, f64 across blocks.
pub fn dot(a: &[f32], b: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for (ca, cb) in a.chunks(256).zip(b.chunks(256)) {
        let mut lanes = [0.0f32; 32];
        let (ea, eb) = (ca.chunks_exact(32), cb.chunks_exact(32));
        let (ra, rb) = (ea.remainder(), eb.remainder());
        for (x, y) in ea.zip(eb) {
            for l in 0..32 {
                lanes[l] += x[l] * y[l];
            }
        }
        let tail: f32 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
        total += (lanes.iter().sum::<f32>() + tail) as f64;
    }
    total
}

/// The sum of a patch (vectorised like [`dot`]).
pub fn sum(a: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for ca in a.chunks(256) {
        let mut lanes = [0.0f32; 32];
        let ea = ca.chunks_exact(32);
        let tail: f32 = ea.remainder().iter().sum();
        for x in ea {
            for l in 0..32 {
                lanes[l] += x[l];
            }
        }
        total += (lanes.iter().sum::<f32>() + tail) as f64;
    }
    total
}

/// Samples per block of [`accumulate_jtj`] and [`jt_times`]: every column's block stays in the
/// L1 cache while it is read; sums within a block are f32, across blocks f64 (as in [`dot`]).
const JT_BLOCK: usize = 256;

/// Eight f32 lanes (one AVX register).
type Lanes = [f32; 8];

/// The columns [`jt_times_many`]'s kernel takes at a time (an accumulator register each).
const COLS: usize = 8;

/// The products' kernels with AVX2 and FMA intrinsics (the build's CPU baseline, x86-64-v3).
#[cfg(simd = "avx2")]
mod simd {
    use super::{COLS, Lanes};

    /// The lane sums of `rows[r] . cols[t]` over the first `full` (a multiple of 8) samples.
    pub(super) fn tile_2x4(rows: [&[f32]; 2], cols: [&[f32]; 4], full: usize) -> [[Lanes; 4]; 2] {
        use std::arch::x86_64::*;
        assert!(rows.iter().chain(&cols).all(|c| c.len() >= full) && full.is_multiple_of(8));
        let mut out = [[[0f32; 8]; 4]; 2];
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); every load reads 8 values from
        // index i with i + 8 <= full <= the slice's length (asserted above).
        unsafe {
            let mut s = [[_mm256_setzero_ps(); 4]; 2];
            let mut i = 0;
            while i < full {
                let x0 = _mm256_loadu_ps(rows[0].as_ptr().add(i));
                let x1 = _mm256_loadu_ps(rows[1].as_ptr().add(i));
                for t in 0..4 {
                    let y = _mm256_loadu_ps(cols[t].as_ptr().add(i));
                    s[0][t] = _mm256_fmadd_ps(x0, y, s[0][t]);
                    s[1][t] = _mm256_fmadd_ps(x1, y, s[1][t]);
                }
                i += 8;
            }
            for r in 0..2 {
                for t in 0..4 {
                    _mm256_storeu_ps(out[r][t].as_mut_ptr(), s[r][t]);
                }
            }
        }
        out
    }

    /// The lane sums of `cols[k] . v` over the first `full` (a multiple of 8) samples.
    pub(super) fn columns_times(cols: &[&[f32]; COLS], v: &[f32], full: usize) -> [Lanes; COLS] {
        use std::arch::x86_64::*;
        assert!(cols.iter().all(|c| c.len() >= full) && v.len() >= full && full.is_multiple_of(8));
        let mut out = [[0f32; 8]; COLS];
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); every load reads 8 values from
        // index i with i + 8 <= full <= the slice's length (asserted above).
        unsafe {
            let mut s = [_mm256_setzero_ps(); COLS];
            let mut i = 0;
            while i < full {
                let x = _mm256_loadu_ps(v.as_ptr().add(i));
                for k in 0..COLS {
                    s[k] = _mm256_fmadd_ps(x, _mm256_loadu_ps(cols[k].as_ptr().add(i)), s[k]);
                }
                i += 8;
            }
            for k in 0..COLS {
                _mm256_storeu_ps(out[k].as_mut_ptr(), s[k]);
            }
        }
        out
    }
}

/// The same kernels in plain Rust: the build for other CPUs, and compared with [`simd`] by a
/// test.
#[cfg(any(test, not(simd = "avx2")))]
mod portable {
    use super::{COLS, Lanes};

    /// `acc += x * y`, lane by lane (fused multiply-adds).
    #[inline(always)]
    fn fma_lanes(acc: &mut Lanes, x: &Lanes, y: &Lanes) {
        for l in 0..8 {
            acc[l] = x[l].mul_add(y[l], acc[l]);
        }
    }

    /// Eight consecutive values from `i`.
    #[inline(always)]
    fn lanes_at(v: &[f32], i: usize) -> &Lanes {
        v[i..i + 8].try_into().expect("eight values")
    }

    /// The lane sums of `rows[r] . cols[t]` over the first `full` (a multiple of 8) samples.
    pub(super) fn tile_2x4(rows: [&[f32]; 2], cols: [&[f32]; 4], full: usize) -> [[Lanes; 4]; 2] {
        let mut s = [[[0f32; 8]; 4]; 2];
        for i in (0..full).step_by(8) {
            let x = [lanes_at(rows[0], i), lanes_at(rows[1], i)];
            for (t, c) in cols.iter().enumerate() {
                let y = lanes_at(c, i);
                fma_lanes(&mut s[0][t], x[0], y);
                fma_lanes(&mut s[1][t], x[1], y);
            }
        }
        s
    }

    /// The lane sums of `cols[k] . v` over the first `full` (a multiple of 8) samples.
    pub(super) fn columns_times(cols: &[&[f32]; COLS], v: &[f32], full: usize) -> [Lanes; COLS] {
        let mut s = [[0f32; 8]; COLS];
        for i in (0..full).step_by(8) {
            let x = lanes_at(v, i);
            for (sk, c) in s.iter_mut().zip(cols) {
                fma_lanes(sk, x, lanes_at(c, i));
            }
        }
        s
    }
}

#[cfg(not(simd = "avx2"))]
use portable::{columns_times, tile_2x4};
#[cfg(simd = "avx2")]
use simd::{columns_times, tile_2x4};

/// Adds `J^T J` into `acc` (stride [`MAX_DOF`]). `J` is stored by parameter: column `k` is
/// `jac[k N..(k + 1) N]` (the layout of [`crate::ssm::Ssm::jacobian`]'s projection).
///
/// Block by block of 256 samples, the upper triangle in tiles of two rows by four
/// columns: each load feeds more than one multiply-add, and the eight accumulators of a tile
/// keep both FMA units busy.
pub fn accumulate_jtj(jac: &[f32], dof: usize, acc: &mut Square) {
    jtj_into(jac, None, dof, MAX_DOF, acc);
}

/// Adds `J^T diag(d) J` into `acc` (stride [`MAX_DOF`]), or `J^T J` without `d`; as
/// [`accumulate_jtj`], each block's rows weighed by `d` once before the tiles read them.
pub fn accumulate_weighted_jtj(jac: &[f32], d: Option<&[f32]>, dof: usize, acc: &mut Square) {
    jtj_into(jac, d, dof, MAX_DOF, acc);
}

/// [`accumulate_weighted_jtj`] into `acc` with stride `stride`.
pub fn jtj_into(jac: &[f32], d: Option<&[f32]>, dof: usize, stride: usize, acc: &mut [f64]) {
    let dof = dof.min(MAX_DOF);
    if dof == 0 {
        return;
    }
    let n = jac.len() / dof;
    let mut weighed = [[0f32; JT_BLOCK]; 2];
    let mut start = 0;
    while start < n {
        let len = JT_BLOCK.min(n - start);
        let full = len / 8 * 8;
        // Rows and columns past `dof` read the last column; their sums are dropped.
        let col = |k: usize| &jac[k.min(dof - 1) * n + start..][..len];
        for a in (0..dof).step_by(2) {
            let rows: [&[f32]; 2] = match d {
                Some(d) => {
                    let d = &d[start..start + len];
                    for (r, w) in weighed.iter_mut().enumerate() {
                        for ((o, &x), &y) in w.iter_mut().zip(col(a + r)).zip(d) {
                            *o = x * y;
                        }
                    }
                    [&weighed[0][..len], &weighed[1][..len]]
                }
                None => [col(a), col(a + 1)],
            };
            for b in (a / 4 * 4..dof).step_by(4) {
                let cols = [col(b), col(b + 1), col(b + 2), col(b + 3)];
                let s = tile_2x4(rows, cols, full);
                for (r, (row, sr)) in rows.iter().zip(&s).enumerate() {
                    for (t, (c, st)) in cols.iter().zip(sr).enumerate() {
                        let (i, j) = (a + r, b + t);
                        if i < dof && j < dof && j >= i {
                            let mut v = lanes_sum(st);
                            for k in full..len {
                                v = row[k].mul_add(c[k], v);
                            }
                            acc[i * stride + j] += v as f64;
                        }
                    }
                }
            }
        }
        start += len;
    }
    for i in 0..dof {
        for j in 0..i {
            acc[i * stride + j] = acc[j * stride + i];
        }
    }
}

/// `out[k] = sum_i J[k N + i] v[i]` (`J` stored by parameter): every column in one pass over
/// `v`, block by block of 256 samples.
pub fn jt_times(jac: &[f32], v: &[f32], dof: usize, out: &mut [f64; MAX_DOF]) {
    let mut outs = [[0.0; MAX_DOF]];
    jt_times_many(jac, [v], dof, &mut outs);
    *out = outs[0];
}

/// [`jt_times`] of several vectors in one pass over `J` (each block of `J`'s columns is read
/// from memory once and stays in the L1 cache for the others); the same sums, in the same
/// order, as [`jt_times`] of each.
pub fn jt_times_many<const V: usize>(
    jac: &[f32],
    vs: [&[f32]; V],
    dof: usize,
    outs: &mut [[f64; MAX_DOF]; V],
) {
    for o in outs.iter_mut() {
        o.fill(0.0);
    }
    let dof = dof.min(MAX_DOF);
    if dof == 0 {
        return;
    }
    let stride = jac.len() / dof;
    let n = vs.iter().fold(stride, |n, v| n.min(v.len()));
    let mut start = 0;
    while start < n {
        let len = JT_BLOCK.min(n - start);
        let full = len / 8 * 8;
        // The columns in blocks of COLS; past `dof` a block reads the last column, whose
        // sums are dropped.
        for first in (0..dof).step_by(COLS) {
            let cols: [&[f32]; COLS] =
                std::array::from_fn(|k| &jac[(first + k).min(dof - 1) * stride + start..][..len]);
            for (v, out) in vs.iter().zip(outs.iter_mut()) {
                let vv = &v[start..start + len];
                let s = columns_times(&cols, vv, full);
                for k in 0..COLS.min(dof - first) {
                    let mut t = lanes_sum(&s[k]);
                    for q in full..len {
                        t = vv[q].mul_add(cols[k][q], t);
                    }
                    out[first + k] += t as f64;
                }
            }
        }
        start += len;
    }
}

/// `jac[k N + i] = gx[i] dw_x/dp_k + gy[i] dw_y/dp_k`, with `dw/dp` in the layout of
/// `crate::ssm::Ssm::jacobian`: the pixel Jacobian `dI/dp`
/// (the gradient search methods' each iteration, the template's for a model that learns).
pub fn project(gx: &[f32], gy: &[f32], dwdp: &[f32], dof: usize, jac: &mut [f32]) {
    project_skipping(gx, gy, dwdp, &[false; 2 * MAX_DOF], dof, jac);
}

/// [`project`] with the rows of `dwdp` marked in `zero` known to be zero (not read).
pub fn project_skipping(
    gx: &[f32],
    gy: &[f32],
    dwdp: &[f32],
    zero: &[bool; 2 * MAX_DOF],
    dof: usize,
    jac: &mut [f32],
) {
    let n = gx.len();
    for k in 0..dof.min(MAX_DOF) {
        let dx = &dwdp[2 * k * n..(2 * k + 1) * n];
        let dy = &dwdp[(2 * k + 1) * n..(2 * k + 2) * n];
        let jk = &mut jac[k * n..(k + 1) * n];
        match (zero[2 * k], zero[2 * k + 1]) {
            (false, false) => {
                for ((((j, &a), &b), &u), &v) in jk.iter_mut().zip(gx).zip(gy).zip(dx).zip(dy) {
                    *j = a * u + b * v;
                }
            }
            (false, true) => {
                for ((j, &a), &u) in jk.iter_mut().zip(gx).zip(dx) {
                    *j = a * u;
                }
            }
            (true, false) => {
                for ((j, &b), &v) in jk.iter_mut().zip(gy).zip(dy) {
                    *j = b * v;
                }
            }
            (true, true) => jk.fill(0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// `J^T J` and `J^T v` against plain double-precision sums, for every number of parameters and
    /// lengths with and without a tail after the last whole group of eight and block of 256; the
    /// portable kernels against the SIMD ones.
    #[test]
    fn the_jacobian_products_match_plain_sums() {
        let mut rng = Rng::new(31);
        // Every size of one block of columns and past it, to MAX_DOF.
        for dof in (1..=10).chain([17, 18, 32, MAX_DOF]) {
            for n in [1, 7, 8, 50, 257, 2500] {
                let jac: Vec<f32> = (0..n * dof).map(|_| rng.range(-2.0, 2.0) as f32).collect();
                let v: Vec<f32> = (0..n).map(|_| rng.range(-50.0, 50.0) as f32).collect();
                let col = |k: usize| &jac[k * n..(k + 1) * n];
                let plain = |a: &[f32], b: &[f32]| -> f64 {
                    a.iter().zip(b).map(|(&x, &y)| x as f64 * y as f64).sum()
                };
                let mut h = [0.0; MAX_DOF * MAX_DOF];
                accumulate_jtj(&jac, dof, &mut h);
                let mut g = [0.0; MAX_DOF];
                jt_times(&jac, &v, dof, &mut g);
                // Several vectors in one pass: the same sums as one at a time.
                let w: Vec<f32> = v.iter().map(|x| 0.5 - x).collect();
                let (mut gw, mut many) = ([0.0; MAX_DOF], [[1.0; MAX_DOF]; 2]);
                jt_times(&jac, &w, dof, &mut gw);
                jt_times_many(&jac, [&v, &w], dof, &mut many);
                assert_eq!(many, [g, gw], "dof {dof}, n {n}");
                for a in 0..dof {
                    let want = plain(col(a), &v);
                    assert!(
                        (g[a] - want).abs() <= 1e-5 * (1.0 + want.abs()) * n as f64,
                        "J^T v"
                    );
                    for b in 0..dof {
                        let want = plain(col(a), col(b));
                        // Within f32's rounding of the sum of the products' sizes.
                        let size: f64 = col(a)
                            .iter()
                            .zip(col(b))
                            .map(|(&x, &y)| (x as f64 * y as f64).abs())
                            .sum();
                        let got = h[a * MAX_DOF + b];
                        assert!(
                            (got - want).abs() <= 1e-5 * (1.0 + size),
                            "dof {dof}, n {n}, H[{a},{b}]: {got} vs {want}"
                        );
                    }
                }
                // Entries past dof are left alone.
                assert!(h[dof..MAX_DOF].iter().all(|&x| x == 0.0));
                let full = n / 8 * 8;
                let cols: [&[f32]; COLS] = std::array::from_fn(|k| col(k.min(dof - 1)));
                assert_eq!(
                    super::columns_times(&cols, &v, full),
                    super::portable::columns_times(&cols, &v, full)
                );
                let rows = [col(0), col(dof.min(2) - 1)];
                let four = [cols[0], cols[1], cols[2], cols[3]];
                let (simd, portable) = (
                    super::tile_2x4(rows, four, full),
                    super::portable::tile_2x4(rows, four, full),
                );
                for (x, y) in simd
                    .iter()
                    .flatten()
                    .flatten()
                    .zip(portable.iter().flatten().flatten())
                {
                    assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()), "{x} vs {y}");
                }
            }
        }
    }
}
