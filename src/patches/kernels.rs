//! The many-patch tracker's inner loops, over a patch's per-sample arrays in lanes of eight
//! (every array's length is a multiple of 8: rows are padded, see `Grid`). AVX2 and FMA
//! intrinsics where the build's CPU baseline has them (x86-64-v3), the same arithmetic in
//! plain Rust elsewhere; a test compares the two.

/// Where the template's rows are read and written: the grown grid's samples `ext` (`side + 2`
/// rows of `ext_stride` samples), and the template, its two gradients and the padding's mask
/// (`side` rows of `stride`).
pub(super) struct Rows<'a> {
    pub ext: &'a [f32],
    pub ext_stride: usize,
    pub stride: usize,
    pub side: usize,
    pub mask: &'a [f32],
}

impl Rows<'_> {
    /// Checks the sizes every kernel relies on (the intrinsics' loads stay inside the slices).
    fn check(&self, t: &[f32], tx: &[f32], ty: &[f32]) {
        let (e, sw, side) = (self.ext_stride, self.stride, self.side);
        assert!(sw.is_multiple_of(8) && e >= sw + 2);
        assert!(self.ext.len() > (side + 1) * e + sw);
        let n = side * sw;
        assert!(self.mask.len() >= n && t.len() >= n && tx.len() >= n && ty.len() >= n);
    }
}

/// The template `t` (the grown grid's inside) and its central differences `tx`, `ty`, zero on
/// the padding; returns `[sum tx t, sum ty t, sum tx tx, sum tx ty, sum ty ty]`.
pub(super) fn template_rows(
    rows: &Rows<'_>,
    t: &mut [f32],
    tx: &mut [f32],
    ty: &mut [f32],
) -> [f32; 5] {
    rows.check(t, tx, ty);
    #[cfg(simd = "avx2")]
    {
        simd::template_rows(rows, t, tx, ty)
    }
    #[cfg(not(simd = "avx2"))]
    {
        portable::template_rows(rows, t, tx, ty)
    }
}

/// `(sum a[i] v[i], sum b[i] v[i])` in one pass; the three lengths are equal multiples of 8.
pub(super) fn dot2(a: &[f32], b: &[f32], v: &[f32]) -> (f32, f32) {
    assert!(a.len() == v.len() && b.len() == v.len() && v.len().is_multiple_of(8));
    #[cfg(simd = "avx2")]
    {
        simd::dot2(a, b, v)
    }
    #[cfg(not(simd = "avx2"))]
    {
        portable::dot2(a, b, v)
    }
}

/// `sum a[i] b[i]`; the lengths are equal multiples of 8.
pub(super) fn dot(a: &[f32], b: &[f32]) -> f32 {
    assert!(a.len() == b.len() && b.len().is_multiple_of(8));
    // The lanes and the order of [`dot2`]'s first sum (fused multiply-adds, two sets of lanes
    // over blocks of 16, a last block of 8 to the first), so the two agree bit for bit.
    let mut s = [[0f32; 8]; 2];
    let (ca, cb) = (a.chunks_exact(16), b.chunks_exact(16));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            s[0][l] = x[l].mul_add(y[l], s[0][l]);
            s[1][l] = x[l + 8].mul_add(y[l + 8], s[1][l]);
        }
    }
    for (l, (x, y)) in ra.iter().zip(rb).enumerate() {
        s[0][l] = x.mul_add(*y, s[0][l]);
    }
    lanes_sum(&s[0]) + lanes_sum(&s[1])
}

use crate::linalg::lanes_sum;

#[cfg(simd = "avx2")]
mod simd {
    use super::{Rows, lanes_sum};
    use std::arch::x86_64::*;

    /// The lanes of a register.
    #[inline(always)]
    fn spill(v: __m256) -> [f32; 8] {
        let mut out = [0f32; 8];
        // SAFETY: AVX is enabled at compile time (cfg); `out` holds eight values.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
        out
    }

    pub(super) fn template_rows(
        rows: &Rows<'_>,
        t: &mut [f32],
        tx: &mut [f32],
        ty: &mut [f32],
    ) -> [f32; 5] {
        let (e, sw) = (rows.ext_stride, rows.stride);
        let ext = rows.ext.as_ptr();
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg). `Rows::check` (called by the
        // dispatcher) asserted sw % 8 == 0, e >= sw + 2, ext.len() > (side + 1) e + sw and
        // side * sw entries in t, tx, ty and the mask: the furthest read is the lower row's
        // (side + 1) e + 1 + sw - 1, and row j's writes end at j sw + sw <= side sw.
        unsafe {
            let half = _mm256_set1_ps(0.5);
            let mut acc = [_mm256_setzero_ps(); 5];
            for j in 0..rows.side {
                let up = ext.add(j * e + 1);
                let row = ext.add((j + 1) * e);
                let down = ext.add((j + 2) * e + 1);
                let base = j * sw;
                let mut o = 0;
                while o < sw {
                    let l = _mm256_loadu_ps(row.add(o));
                    let c = _mm256_loadu_ps(row.add(o + 1));
                    let r = _mm256_loadu_ps(row.add(o + 2));
                    let u = _mm256_loadu_ps(up.add(o));
                    let d = _mm256_loadu_ps(down.add(o));
                    let m = _mm256_loadu_ps(rows.mask.as_ptr().add(base + o));
                    let v = _mm256_mul_ps(c, m);
                    let gx = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(r, l), half), m);
                    let gy = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(d, u), half), m);
                    _mm256_storeu_ps(t.as_mut_ptr().add(base + o), v);
                    _mm256_storeu_ps(tx.as_mut_ptr().add(base + o), gx);
                    _mm256_storeu_ps(ty.as_mut_ptr().add(base + o), gy);
                    acc[0] = _mm256_fmadd_ps(gx, v, acc[0]);
                    acc[1] = _mm256_fmadd_ps(gy, v, acc[1]);
                    acc[2] = _mm256_fmadd_ps(gx, gx, acc[2]);
                    acc[3] = _mm256_fmadd_ps(gx, gy, acc[3]);
                    acc[4] = _mm256_fmadd_ps(gy, gy, acc[4]);
                    o += 8;
                }
            }
            acc.map(|a| lanes_sum(&spill(a)))
        }
    }

    pub(super) fn dot2(a: &[f32], b: &[f32], v: &[f32]) -> (f32, f32) {
        let n = v.len();
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); the dispatcher asserted the
        // three lengths equal and a multiple of 8, and every load reads i..i + 8 with i + 8 <= n.
        unsafe {
            let mut s = [_mm256_setzero_ps(); 4];
            let mut i = 0;
            while i + 16 <= n {
                let x0 = _mm256_loadu_ps(v.as_ptr().add(i));
                let x1 = _mm256_loadu_ps(v.as_ptr().add(i + 8));
                s[0] = _mm256_fmadd_ps(_mm256_loadu_ps(a.as_ptr().add(i)), x0, s[0]);
                s[1] = _mm256_fmadd_ps(_mm256_loadu_ps(a.as_ptr().add(i + 8)), x1, s[1]);
                s[2] = _mm256_fmadd_ps(_mm256_loadu_ps(b.as_ptr().add(i)), x0, s[2]);
                s[3] = _mm256_fmadd_ps(_mm256_loadu_ps(b.as_ptr().add(i + 8)), x1, s[3]);
                i += 16;
            }
            if i < n {
                let x0 = _mm256_loadu_ps(v.as_ptr().add(i));
                s[0] = _mm256_fmadd_ps(_mm256_loadu_ps(a.as_ptr().add(i)), x0, s[0]);
                s[2] = _mm256_fmadd_ps(_mm256_loadu_ps(b.as_ptr().add(i)), x0, s[2]);
            }
            let s = s.map(spill);
            (
                lanes_sum(&s[0]) + lanes_sum(&s[1]),
                lanes_sum(&s[2]) + lanes_sum(&s[3]),
            )
        }
    }
}

/// The kernels in plain Rust, lane for lane as the intrinsics compute them: the build for
/// other CPUs, and compared with [`simd`] by a test.
#[cfg(any(test, not(simd = "avx2")))]
mod portable {
    use super::{Rows, lanes_sum};

    pub(super) fn template_rows(
        rows: &Rows<'_>,
        t: &mut [f32],
        tx: &mut [f32],
        ty: &mut [f32],
    ) -> [f32; 5] {
        let (e, sw) = (rows.ext_stride, rows.stride);
        let mut acc = [[0f32; 8]; 5];
        for j in 0..rows.side {
            let (up, row, down) = (
                &rows.ext[j * e + 1..][..sw],
                &rows.ext[(j + 1) * e..][..sw + 2],
                &rows.ext[(j + 2) * e + 1..][..sw],
            );
            for i in 0..sw {
                let k = j * sw + i;
                let m = rows.mask[k];
                let v = row[i + 1] * m;
                let gx = (row[i + 2] - row[i]) * 0.5 * m;
                let gy = (down[i] - up[i]) * 0.5 * m;
                (t[k], tx[k], ty[k]) = (v, gx, gy);
                let q = i % 8;
                acc[0][q] = gx.mul_add(v, acc[0][q]);
                acc[1][q] = gy.mul_add(v, acc[1][q]);
                acc[2][q] = gx.mul_add(gx, acc[2][q]);
                acc[3][q] = gx.mul_add(gy, acc[3][q]);
                acc[4][q] = gy.mul_add(gy, acc[4][q]);
            }
        }
        acc.map(|a| lanes_sum(&a))
    }

    pub(super) fn dot2(a: &[f32], b: &[f32], v: &[f32]) -> (f32, f32) {
        let mut s = [[0f32; 8]; 4];
        for i in 0..v.len() {
            // Blocks of 16 go to two sets of lanes; a last block of 8 to the first.
            let set = usize::from(i % 16 >= 8 && i - i % 16 + 16 <= v.len());
            s[set][i % 8] = a[i].mul_add(v[i], s[set][i % 8]);
            s[2 + set][i % 8] = b[i].mul_add(v[i], s[2 + set][i % 8]);
        }
        (
            lanes_sum(&s[0]) + lanes_sum(&s[1]),
            lanes_sum(&s[2]) + lanes_sum(&s[3]),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wave(n: usize, f: f32) -> Vec<f32> {
        (0..n)
            .map(|i| 50.0 * (i as f32 * f).sin() + 100.0)
            .collect()
    }

    /// The kernels equal their definitions written plainly (and, on this CPU, the portable
    /// versions the intrinsics).
    #[test]
    fn kernels_equal_their_definitions() {
        for n in [8, 16, 24, 40, 504] {
            let (a, b, v) = (wave(n, 0.37), wave(n, 0.11), wave(n, 0.7));
            let plain = |x: &[f32]| x.iter().zip(&v).map(|(x, y)| (x * y) as f64).sum::<f64>();
            let (s, t) = dot2(&a, &b, &v);
            let (ps, pt) = portable::dot2(&a, &b, &v);
            for (got, want) in [
                (s, plain(&a)),
                (t, plain(&b)),
                (ps, plain(&a)),
                (pt, plain(&b)),
            ] {
                assert!(
                    ((got as f64) - want).abs() <= 1e-5 * want.abs(),
                    "{got} vs {want}"
                );
            }
            assert_eq!(dot(&a, &v), s);
        }
        for (side, sw) in [(5usize, 8usize), (21, 24), (16, 16)] {
            let e = (sw + 2).div_ceil(8) * 8;
            let ext = wave((side + 2) * e + 8, 0.23);
            let mask: Vec<f32> = (0..side * sw)
                .map(|k| if k % sw < side { 1.0 } else { 0.0 })
                .collect();
            let rows = Rows {
                ext: &ext,
                ext_stride: e,
                stride: sw,
                side,
                mask: &mask,
            };
            let n = side * sw;
            let (mut t, mut tx, mut ty) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            let sums = template_rows(&rows, &mut t, &mut tx, &mut ty);
            let (mut t2, mut tx2, mut ty2) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            let sums2 = portable::template_rows(&rows, &mut t2, &mut tx2, &mut ty2);
            let mut want = [0f64; 5];
            for j in 0..side {
                for i in 0..sw {
                    let k = j * sw + i;
                    let g = |r: usize, c: usize| ext[r * e + c];
                    let (v, gx, gy) = if i < side {
                        (
                            g(j + 1, i + 1),
                            0.5 * (g(j + 1, i + 2) - g(j + 1, i)),
                            0.5 * (g(j + 2, i + 1) - g(j, i + 1)),
                        )
                    } else {
                        (0.0, 0.0, 0.0)
                    };
                    assert_eq!((t[k], tx[k], ty[k]), (v, gx, gy), "sample {k}");
                    assert_eq!((t2[k], tx2[k], ty2[k]), (v, gx, gy), "sample {k}");
                    let (v, gx, gy) = (v as f64, gx as f64, gy as f64);
                    for (w, p) in want
                        .iter_mut()
                        .zip([gx * v, gy * v, gx * gx, gx * gy, gy * gy])
                    {
                        *w += p;
                    }
                }
            }
            for c in 0..5 {
                let tol = 1e-5 * want[c].abs().max(1.0);
                assert!(
                    (sums[c] as f64 - want[c]).abs() <= tol,
                    "{c}: {} vs {}",
                    sums[c],
                    want[c]
                );
                assert!(
                    (sums2[c] as f64 - want[c]).abs() <= tol,
                    "{c}: {} vs {}",
                    sums2[c],
                    want[c]
                );
            }
        }
    }
}
