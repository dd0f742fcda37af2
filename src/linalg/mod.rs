//! Small dense linear algebra: the `S x S` (S <= [`MAX_DOF`]) Newton systems of the search
//! methods, the matrix exponential and logarithm used by the SL3 state space model, the median
//! of a sample; the products of patches and pixel Jacobians ([`products`]: `J^T J`, `J^T v`,
//! dot products) and the negative semi-definite part of a Hessian ([`eigen`]).

pub mod eigen;
pub mod products;

pub use eigen::negative_part;
pub use products::{
    accumulate_jtj, accumulate_weighted_jtj, dot, jt_times, jt_times_many, minus_jtj, sum,
};

use nalgebra::{Matrix3, SMatrix};

/// The largest number of warp parameters (the spline and thin-plate spline SSMs' 5 x 5 control
/// points). Parameter vectors hold this many; a Hessian is a [`Square`] whose first `dof x dof`
/// entries are used.
pub const MAX_DOF: usize = 50;

/// A dense matrix of up to `MAX_DOF x MAX_DOF` (a Hessian, row-major; the first `dof x dof`
/// entries with stride `dof`, unless a function says stride [`MAX_DOF`]). At 20 KB it is not
/// made on the stack per iteration: its owner keeps a [`SquareBuf`].
pub type Square = [f64; MAX_DOF * MAX_DOF];

/// A [`Square`] on the heap, allocated with its owner (a workspace, a solver, a model), zeroed.
#[derive(Clone, Debug)]
pub struct SquareBuf(Box<Square>);

impl Default for SquareBuf {
    fn default() -> Self {
        SquareBuf(Box::new([0.0; MAX_DOF * MAX_DOF]))
    }
}

impl std::ops::Deref for SquareBuf {
    type Target = Square;
    fn deref(&self) -> &Square {
        &self.0
    }
}

impl std::ops::DerefMut for SquareBuf {
    fn deref_mut(&mut self) -> &mut Square {
        &mut self.0
    }
}

/// Sets to zero what a `dof x dof` matrix of either stride (`dof` or [`MAX_DOF`]) occupies.
pub fn clear_square(h: &mut Square, dof: usize) {
    if dof > 0 {
        h[..(dof - 1) * MAX_DOF + dof].fill(0.0);
    }
}

/// The load added to the Newton system's diagonal, relative to its largest entry.
pub const RIDGE: f64 = 1e-9;

/// Solves `H x = -g` for the Newton step of a maximisation, with `H` (row-major, `n x n`) the
/// Hessian, normally negative definite. Tries a Cholesky factorisation of `-H`, then LU with
/// partial pivoting; `None` when the system is singular or the result is not finite.
pub fn newton_step(h: &Square, g: &[f64; MAX_DOF], n: usize) -> Option<[f64; MAX_DOF]> {
    NewtonSolver::default().step(h, g, n, 0.0)
}

/// [`newton_step`] that keeps the Cholesky factor of the last Hessian it solved with: a search
/// method whose Hessian is the same from iteration to iteration (ICLK's, made once per
/// template) factors it once. The same steps, bit for bit. Its matrices are its own (allocated
/// once), each used with stride `n`.
#[derive(Clone, Debug, Default)]
pub struct NewtonSolver {
    /// The size of the last Hessian that had a Cholesky factor (`last`, its factor `l`).
    kept: Option<usize>,
    last: SquareBuf,
    l: SquareBuf,
    a: SquareBuf,
}

impl NewtonSolver {
    /// Solves `H x = -g` as [`newton_step`] does; with `damping > 0` (Levenberg-Marquardt) the
    /// diagonal of `H` is first scaled by `1 + damping` (a shorter, more gradient-like step).
    pub fn step(
        &mut self,
        h: &Square,
        g: &[f64; MAX_DOF],
        n: usize,
        damping: f64,
    ) -> Option<[f64; MAX_DOF]> {
        let finite = |x: [f64; MAX_DOF]| x[..n].iter().all(|v| v.is_finite()).then_some(x);
        // The system's matrix, damped.
        let entry = |i: usize, j: usize| {
            let v = h[i * n + j];
            if damping > 0.0 && i == j {
                v * (1.0 + damping)
            } else {
                v
            }
        };
        let same = self.kept == Some(n)
            && (0..n)
                .all(|i| (0..n).all(|j| entry(i, j).to_bits() == self.last[i * n + j].to_bits()));
        if same {
            return finite(cholesky_apply(&self.l, g, n));
        }
        let a = &mut self.a;
        let mut b = [0.0f64; MAX_DOF];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = -entry(i, j);
            }
            b[i] = g[i];
        }
        // A ridge of RIDGE times the largest curvature: a direction the patch does not
        // constrain (stripes along it) gets a step of the size of its gradient's noise over
        // that load, not over a pivot as small as rounding.
        let top = (0..n).map(|i| a[i * n + i]).fold(0.0f64, f64::max);
        for i in 0..n {
            a[i * n + i] += RIDGE * top;
        }
        if cholesky_factor(a, n, &mut self.l) {
            let x = cholesky_apply(&self.l, &b, n);
            for i in 0..n {
                for j in 0..n {
                    self.last[i * n + j] = entry(i, j);
                }
            }
            self.kept = Some(n);
            finite(x)
        } else {
            self.kept = None;
            finite(lu_solve(a, &b, n)?)
        }
    }
}

/// The Cholesky factor `L` (`A = L L^T`, row-major with stride `n`, its lower triangle) of the
/// `n x n` matrix `a` into `l`; `false` if `a` is not clearly positive definite.
fn cholesky_factor(a: &Square, n: usize, l: &mut Square) -> bool {
    let scale = (0..n).map(|i| a[i * n + i].abs()).fold(0.0, f64::max);
    if scale.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return false;
    }
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s <= scale * 1e-13 {
                    return false;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    true
}

/// Solves `L L^T x = b` by the two triangular systems.
fn cholesky_apply(l: &Square, b: &[f64; MAX_DOF], n: usize) -> [f64; MAX_DOF] {
    let mut y = [0.0f64; MAX_DOF];
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    let mut x = [0.0f64; MAX_DOF];
    for i in (0..n).rev() {
        let mut s = y[i];
        for k in i + 1..n {
            s -= l[k * n + i] * x[k];
        }
        x[i] = s / l[i * n + i];
    }
    x
}

/// Solves `A x = b` (`n x n`, stride `n`) by LU with partial pivoting, in place in `m`.
fn lu_solve(m: &mut Square, b: &[f64; MAX_DOF], n: usize) -> Option<[f64; MAX_DOF]> {
    let mut x = *b;
    let scale = m[..n * n].iter().fold(0.0f64, |s, v| s.max(v.abs()));
    if scale.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| m[i * n + c].abs().total_cmp(&m[j * n + c].abs()))?;
        if m[p * n + c].abs() <= scale * 1e-14 {
            return None;
        }
        if p != c {
            for k in 0..n {
                m.swap(p * n + k, c * n + k);
            }
            x.swap(p, c);
        }
        for r in c + 1..n {
            let f = m[r * n + c] / m[c * n + c];
            for k in c..n {
                m[r * n + k] -= f * m[c * n + k];
            }
            x[r] -= f * x[c];
        }
    }
    for i in (0..n).rev() {
        let mut s = x[i];
        for k in i + 1..n {
            s -= m[i * n + k] * x[k];
        }
        x[i] = s / m[i * n + i];
    }
    Some(x)
}

/// Matrix exponential by scaling and squaring with a Taylor series.
pub fn expm<const D: usize>(a: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    let norm = a.iter().fold(0.0f64, |s, v| s + v.abs());
    if !norm.is_finite() {
        return SMatrix::<f64, D, D>::from_element(f64::NAN);
    }
    let mut k = 0;
    let mut scaled = *a;
    if norm > 0.25 {
        k = ((norm / 0.25).log2().ceil() as i32).min(1000);
        scaled = a / 2f64.powi(k);
    }
    let mut term = SMatrix::<f64, D, D>::identity();
    let mut sum = term;
    for i in 1..=14 {
        term = term * scaled / i as f64;
        sum += term;
    }
    for _ in 0..k {
        sum = sum * sum;
    }
    sum
}

/// Principal matrix logarithm of a 3x3 matrix by inverse scaling and squaring (Denman-Beavers
/// square roots, then the Mercator series). `None` when it does not converge (an eigenvalue on
/// the closed negative real axis).
pub fn logm3(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let id = Matrix3::identity();
    let mut x = *m;
    let mut k = 0;
    while (x - id).norm() > 0.2 {
        // Denman-Beavers iteration for sqrt(x).
        let mut y = x;
        let mut z = id;
        for _ in 0..60 {
            let yi = y.try_inverse()?;
            let zi = z.try_inverse()?;
            let y2 = 0.5 * (y + zi);
            let z2 = 0.5 * (z + yi);
            let done = (y2 - y).norm() <= 1e-15 * y2.norm();
            y = y2;
            z = z2;
            if done {
                break;
            }
        }
        x = y;
        k += 1;
        if k > 40 || !x.iter().all(|v| v.is_finite()) {
            return None;
        }
    }
    let e = x - id;
    let mut term = e;
    let mut sum = Matrix3::zeros();
    for i in 1..=40 {
        let t = term / i as f64;
        if i % 2 == 1 {
            sum += t;
        } else {
            sum -= t;
        }
        term *= e;
        if t.norm() < 1e-18 {
            break;
        }
    }
    let out = sum * 2f64.powi(k);
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The Fréchet derivative of the exponential at `a` in direction `e`: `d/dt exp(a + t e)` at 0,
/// from the exponential of the block matrix `[[a, e], [0, a]]`.
pub fn expm3_frechet(a: &Matrix3<f64>, e: &Matrix3<f64>) -> Matrix3<f64> {
    let mut big = SMatrix::<f64, 6, 6>::zeros();
    big.fixed_view_mut::<3, 3>(0, 0).copy_from(a);
    big.fixed_view_mut::<3, 3>(3, 3).copy_from(a);
    big.fixed_view_mut::<3, 3>(0, 3).copy_from(e);
    let ex = expm(&big);
    ex.fixed_view::<3, 3>(0, 3).into_owned()
}

/// The sum of eight f32 lanes (one AVX register's) in a fixed order: the vectorised sums'
/// last step.
#[inline(always)]
pub fn lanes_sum(a: &[f32; 8]) -> f32 {
    ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7]))
}

/// The median (the mean of the two middle values for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    // Selection, not a sort: CMT takes medians over every pair of its keypoints.
    let (m, odd) = (v.len() / 2, v.len() % 2 == 1);
    let (lower, mid, _) = v.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    let mid = *mid;
    if odd {
        mid
    } else {
        let below = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (below + mid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newton_step_solves_negative_definite_and_indefinite_systems() {
        // H = -[[4,1],[1,3]], g = [1,2]: x = [[4,1],[1,3]]^-1 [1,2] = [1/11, 7/11].
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        h[..4].copy_from_slice(&[-4.0, -1.0, -1.0, -3.0]);
        let mut g = [0.0; MAX_DOF];
        g[0] = 1.0;
        g[1] = 2.0;
        let x = newton_step(&h, &g, 2).unwrap();
        // The ridge (1e-9 of the largest curvature) moves the solution by about as much.
        assert!((x[0] - 1.0 / 11.0).abs() < 1e-8 && (x[1] - 7.0 / 11.0).abs() < 1e-8);
        // Indefinite: falls back to LU.
        h[..4].copy_from_slice(&[1.0, 0.0, 0.0, -1.0]);
        let x = newton_step(&h, &g, 2).unwrap();
        assert!((x[0] + 1.0).abs() < 1e-8 && (x[1] - 2.0).abs() < 1e-8);
        // Singular.
        h[..4].copy_from_slice(&[1.0, 1.0, 1.0, 1.0]);
        assert!(newton_step(&h, &g, 2).is_none());
        // A direction with no curvature but rounding, and a gradient of noise along it (a
        // patch of stripes): the step along it is the noise over the ridge, not over the
        // rounding.
        h[..4].copy_from_slice(&[-1e4, 0.0, 0.0, -1e-12]);
        g[0] = 0.0;
        g[1] = 1e-9;
        let x = newton_step(&h, &g, 2).unwrap();
        assert!(x[1].abs() < 1e-3, "{}", x[1]);
    }

    /// The solver that keeps the last factor gives, call after call, the steps `newton_step`
    /// gives: for a Hessian repeated (the factor reused), changed by one entry, of another size,
    /// indefinite (LU) and singular.
    #[test]
    fn a_kept_factor_gives_the_same_steps() {
        // Values in [-1, 1) from a fixed sequence (linalg sits below `rng`).
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let negative_definite = |next: &mut dyn FnMut() -> f64, n: usize| {
            let m: Vec<f64> = (0..n * n).map(|_| next()).collect();
            let mut h = [0.0; MAX_DOF * MAX_DOF];
            for i in 0..n {
                for j in 0..n {
                    let mtm: f64 = (0..n).map(|k| m[k * n + i] * m[k * n + j]).sum();
                    h[i * n + j] = -mtm - if i == j { 0.5 } else { 0.0 };
                }
            }
            h
        };
        let h8 = negative_definite(&mut next, 8);
        let mut h8b = h8;
        h8b[9] -= 0.25;
        let h6 = negative_definite(&mut next, 6);
        let mut indefinite = h6;
        indefinite[0] = 3.0;
        let singular = [0.0; MAX_DOF * MAX_DOF];
        let systems = [
            (h8, 8),
            (h8, 8),
            (h8b, 8),
            (h8b, 8),
            (h8, 6),
            (h6, 6),
            (h6, 6),
            (indefinite, 6),
            (indefinite, 6),
            (singular, 6),
            (h6, 6),
            (h8, 8),
        ];
        let mut solver = NewtonSolver::default();
        for (k, (h, n)) in systems.into_iter().enumerate() {
            let g: [f64; MAX_DOF] = std::array::from_fn(|_| 2.0 * next());
            let kept = solver.step(&h, &g, n, 0.0).map(|x| x.map(f64::to_bits));
            let fresh = newton_step(&h, &g, n).map(|x| x.map(f64::to_bits));
            assert_eq!(kept, fresh, "system {k}");
            assert_eq!(kept.is_some(), k != 9, "system {k}");
        }
    }

    #[test]
    fn exp_and_log_are_inverse() {
        let a = Matrix3::new(0.3, -0.7, 0.2, 0.5, 0.1, -0.4, 0.05, 0.02, -0.4);
        let e = expm(&a);
        let l = logm3(&e).unwrap();
        assert!((l - a).norm() < 1e-10, "{l} vs {a}");
        // Rotation by 2 rad: far from the identity.
        let (c, s) = (2f64.cos(), 2f64.sin());
        let r = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        let l = logm3(&r).unwrap();
        assert!((l[(1, 0)] - 2.0).abs() < 1e-10 && (expm(&l) - r).norm() < 1e-10);
    }

    #[test]
    fn frechet_derivative_matches_finite_differences() {
        let a = Matrix3::new(0.3, -0.2, 0.1, 0.4, -0.1, 0.2, 0.05, -0.03, -0.2);
        let e = Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0);
        let h = 1e-6;
        let fd = (expm(&(a + e * h)) - expm(&(a - e * h))) / (2.0 * h);
        assert!((fd - expm3_frechet(&a, &e)).norm() < 1e-7);
    }
}
