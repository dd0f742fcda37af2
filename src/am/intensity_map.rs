//! The intensity maps of the SCV family (SCV, RSCV, LSCV): a smooth estimate of the conditional
//! expectation `E[Y | X = x]` of one patch's intensities given the other's, fitted once a frame
//! from the converged patch and held fixed within the frame.
//!
//! ## The map
//!
//! A map is piecewise linear in the intensity, with [`NODES`] nodes at `x_k = k 255 / (K - 1)`
//! (a bin of about 8.2 grey levels), evaluated by linear interpolation between the two nearest
//! nodes and by linear *extrapolation* of the end segments outside `0..255` (so the identity map
//! is the identity everywhere, and the map is continuous with a piecewise-constant slope):
//! `m(x) = sum_k phi_k(x) m_k` with `phi_k` the hat functions (triangular, i.e. linear, bin
//! assignment). The slope `m'(x) = (m_{k+1} - m_k) (K - 1) / 255` is what RSCV needs for its
//! derivatives with respect to the mapped pixels; `m'' = 0` except at the nodes, where the slope
//! jumps (the derivatives below are exact everywhere else).
//!
//! ## The fit: the conditional expectation from the joint histogram
//!
//! SCV replaces the template by `E[I | I*]` read from the joint histogram of `(I*, I)`. The
//! classical estimator, the mean of the current intensities of the pixels whose template
//! intensity falls in a bin, has two faults: it is biased by up to half a bin (the pixels of a bin
//! are not centred on it) and undefined for empty bins. Here the node values solve the weighted
//! least-squares regression of `Y` on the hat functions of `X`:
//!
//! `min_m sum_i w_i (y_i - sum_k phi_k(x_i) m_k)^2 + lambda sum_k (m_{k-1} - 2 m_k + m_{k+1})^2 +
//! eps sum_k (m_k - x_k)^2`.
//!
//! The data term needs exactly the statistics of the linearly binned joint histogram:
//! `sum_i w_i phi_k(x_i) phi_l(x_i)` (the joint histogram of `X` with itself, tridiagonal) and
//! `sum_i w_i phi_k(x_i) y_i`, which equals `sum_c h(k, c) y_c` for the joint histogram `h` of
//! `(X, Y)` with linear binning of `Y` too, since linear binning keeps first moments. Where a node
//! has data the estimate is the local conditional mean; the second-difference penalty (zero on
//! affine maps) bridges empty bins linearly and extrapolates beyond the data linearly; the tiny
//! ridge `eps` towards the identity only makes a degenerate patch (one grey level) solvable. As
//! both extra terms vanish on affine maps, an affine relation `Y = a X + b` is recovered exactly
//! (up to `eps`): SCV is exactly invariant to a global gain and bias, which the bin-mean estimator
//! is not. `lambda` is 1% of the mean data weight of a node (bias small where there is data).
//! The normal equations are a `K x K` pentadiagonal SPD system, solved by a banded Cholesky
//! factorisation (`O(K)`) at each update.

use crate::linalg::MAX_DOF;

/// Number of nodes of a map.
pub(crate) const NODES: usize = 32;
/// Grey levels per map segment.
const STEP: f64 = 255.0 / (NODES - 1) as f64;
/// The smoothness weight, relative to the mean data weight of a node.
const LAMBDA_REL: f64 = 0.01;
/// The ridge towards the identity, relative to the mean data weight of a node.
const EPS_REL: f64 = 1e-10;

/// A piecewise-linear intensity map (node values).
#[derive(Clone, Debug)]
pub(crate) struct PlMap(pub [f64; NODES]);

impl PlMap {
    pub fn identity() -> Self {
        PlMap(std::array::from_fn(|k| k as f64 * STEP))
    }

    /// The segment of `x` and the position in it (outside `0..1` when extrapolating).
    #[inline]
    pub fn locate(x: f64) -> (usize, f64) {
        let s = x / STEP;
        let k = if s.is_finite() {
            (s.floor().max(0.0) as usize).min(NODES - 2)
        } else {
            0
        };
        (k, s - k as f64)
    }

    /// `(m(x), m'(x))`.
    #[inline]
    pub fn eval(&self, x: f64) -> (f64, f64) {
        let (k, f) = Self::locate(x);
        self.eval_at(k, f)
    }

    /// [`PlMap::eval`] at the point [`PlMap::locate`] placed (segment `k`, position `f`).
    #[inline]
    pub fn eval_at(&self, k: usize, f: f64) -> (f64, f64) {
        let (a, b) = (self.0[k], self.0[k + 1]);
        (a + f * (b - a), (b - a) / STEP)
    }
}

/// The normal equations of one map fit (the tridiagonal data part and the right-hand side).
#[derive(Clone, Debug)]
pub(crate) struct MapFit {
    diag: [f64; NODES],
    off: [f64; NODES],
    rhs: [f64; NODES],
    weight: f64,
}

impl Default for MapFit {
    fn default() -> Self {
        MapFit {
            diag: [0.0; NODES],
            off: [0.0; NODES],
            rhs: [0.0; NODES],
            weight: 0.0,
        }
    }
}

impl MapFit {
    pub fn clear(&mut self) {
        *self = MapFit::default();
    }

    /// Adds the pair `(x, y)` with weight `w`.
    #[inline]
    pub fn add(&mut self, x: f64, y: f64, w: f64) {
        let (k, f) = PlMap::locate(x);
        self.add_at(k, f, y, w);
    }

    /// [`MapFit::add`] at the point [`PlMap::locate`] placed (segment `k`, position `f`).
    #[inline]
    pub fn add_at(&mut self, k: usize, f: f64, y: f64, w: f64) {
        let (h0, h1) = (1.0 - f, f);
        self.diag[k] += w * h0 * h0;
        self.diag[k + 1] += w * h1 * h1;
        self.off[k] += w * h0 * h1;
        self.rhs[k] += w * h0 * y;
        self.rhs[k + 1] += w * h1 * y;
        self.weight += w;
    }

    /// The normal matrix, pentadiagonal: `(d0, d1, d2)` its diagonal and the two above it
    /// (`d1[k] = A[k][k + 1]`, `d2[k] = A[k][k + 2]`), and the right-hand side.
    fn system(&self) -> ([f64; NODES], [f64; NODES], [f64; NODES], [f64; NODES]) {
        let unit = self.weight / NODES as f64;
        let (lambda, eps) = (LAMBDA_REL * unit, EPS_REL * unit);
        let (mut d0, mut d1, mut d2, mut b) =
            ([0.0; NODES], [0.0; NODES], [0.0; NODES], [0.0; NODES]);
        for k in 0..NODES {
            d0[k] = self.diag[k] + eps;
            d1[k] = self.off[k];
            b[k] = self.rhs[k] + eps * k as f64 * STEP;
        }
        // lambda D^T D with D the second differences (rows (1, -2, 1) at r, r + 1, r + 2).
        const D: [f64; 3] = [1.0, -2.0, 1.0];
        for r in 0..NODES - 2 {
            for i in 0..3 {
                d0[r + i] += lambda * D[i] * D[i];
            }
            for i in 0..2 {
                d1[r + i] += lambda * D[i] * D[i + 1];
            }
            d2[r] += lambda * D[0] * D[2];
        }
        (d0, d1, d2, b)
    }

    /// Solves for the map (a banded Cholesky factorisation of the pentadiagonal normal
    /// equations: `O(NODES)` per fit, so that many regions stay cheap). Leaves `map` unchanged
    /// when there is no data.
    pub fn solve(&self, map: &mut PlMap) {
        if self.weight <= 1e-12 {
            return;
        }
        let (d0, d1, d2, mut b) = self.system();
        if banded_cholesky_solve(&d0, &d1, &d2, &mut b) {
            map.0 = b;
        }
    }
}

/// Solves `A x = b` in place for a symmetric positive definite pentadiagonal `A` given by its
/// diagonal `d0` and the two diagonals above it (`d1[k] = A[k][k + 1]`, `d2[k] = A[k][k + 2]`);
/// false if `A` is not positive definite. The Cholesky factor `L` keeps the band: row `j` has
/// `L[j][j - 2]`, `L[j][j - 1]`, `L[j][j]`.
fn banded_cholesky_solve(
    d0: &[f64; NODES],
    d1: &[f64; NODES],
    d2: &[f64; NODES],
    b: &mut [f64; NODES],
) -> bool {
    // (L[j][j - 2], L[j][j - 1], 1 / L[j][j]) per row: the reciprocal of the diagonal, so
    // that the substitutions multiply (one division per row, on the factorisation's chain).
    let mut l = [[0.0f64; 3]; NODES];
    for j in 0..NODES {
        let l2 = if j >= 2 { d2[j - 2] * l[j - 2][2] } else { 0.0 };
        let l1 = if j >= 1 {
            (d1[j - 1] - l2 * l[j - 1][1]) * l[j - 1][2]
        } else {
            0.0
        };
        let d = d0[j] - l1 * l1 - l2 * l2;
        if d.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return false;
        }
        l[j] = [l2, l1, 1.0 / d.sqrt()];
    }
    for j in 0..NODES {
        let mut s = b[j];
        if j >= 1 {
            s -= l[j][1] * b[j - 1];
        }
        if j >= 2 {
            s -= l[j][0] * b[j - 2];
        }
        b[j] = s * l[j][2];
    }
    for j in (0..NODES).rev() {
        let mut s = b[j];
        if j + 1 < NODES {
            s -= l[j + 1][1] * b[j + 1];
        }
        if j + 2 < NODES {
            s -= l[j + 2][0] * b[j + 2];
        }
        b[j] = s * l[j][2];
    }
    true
}

/// `out = J^T diag(d) J` (row-major `dof x dof`, `J` stored by parameter).
pub(crate) fn jt_diag_j(jac: &[f32], d: &[f32], dof: usize, out: &mut [f64; MAX_DOF * MAX_DOF]) {
    out[..dof * dof].fill(0.0);
    crate::linalg::products::jtj_into(jac, Some(d), dof, dof, out);
}

/// The sub-regions of a square `res x res` patch (row-major) for localised maps: `side x side`
/// blocks whose maps are blended bilinearly between the block centres. A pixel's map is
/// `sum_r a_r(x) m_r`, with `a_r` the bilinear weights of the (up to four) nearest centres
/// (clamped at the border blocks, a partition of unity).
#[derive(Clone, Debug, Default)]
pub(crate) struct Regions {
    /// Blocks per side (1: one global map).
    pub side: usize,
    /// Per pixel: up to four `(region, weight)` pairs (weight 0 for unused slots).
    pub weights: Vec<[(u16, f32); 4]>,
}

impl Regions {
    /// `side x side` regions if `n` is a square of a side of at least `2 side`, else one.
    pub fn new(n: usize, side: usize) -> Self {
        let res = (n as f64).sqrt().round() as usize;
        // At least two samples per region a side (fewer regions on a coarse grid).
        let side = if res * res == n {
            side.min(res / 2).max(1)
        } else {
            1
        };
        let mut weights = Vec::with_capacity(n);
        if side == 1 {
            weights.resize(n, [(0, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)]);
            return Regions { side, weights };
        }
        let spacing = res as f64 / side as f64;
        let axis = |x: usize| -> (usize, f64) {
            let c0 = 0.5 * spacing - 0.5;
            let u = ((x as f64 - c0) / spacing).clamp(0.0, (side - 1) as f64);
            let i0 = (u.floor() as usize).min(side - 2);
            (i0, u - i0 as f64)
        };
        for r in 0..res {
            let (ry, fy) = axis(r);
            for c in 0..res {
                let (rx, fx) = axis(c);
                let reg = |y: usize, x: usize| ((ry + y) * side + rx + x) as u16;
                weights.push([
                    (reg(0, 0), ((1.0 - fy) * (1.0 - fx)) as f32),
                    (reg(0, 1), ((1.0 - fy) * fx) as f32),
                    (reg(1, 0), (fy * (1.0 - fx)) as f32),
                    (reg(1, 1), (fy * fx) as f32),
                ]);
            }
        }
        Regions { side, weights }
    }

    pub fn count(&self) -> usize {
        self.side * self.side
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_map_is_the_identity_everywhere() {
        let m = PlMap::identity();
        for x in [-40.0, 0.0, 3.3, 100.0, 254.9, 255.0, 300.0] {
            let (v, s) = m.eval(x);
            assert!(
                (v - x).abs() < 1e-9 && (s - 1.0).abs() < 1e-9,
                "{x}: {v} {s}"
            );
        }
    }

    #[test]
    fn the_banded_solve_matches_a_dense_one() {
        // The same normal equations assembled densely and solved by Gaussian elimination.
        let mut rng = crate::rng::Rng::new(3);
        let mut fit = MapFit::default();
        for _ in 0..300 {
            let x = rng.range(40.0, 140.0);
            fit.add(
                x,
                0.8 * x + 10.0 + rng.range(-15.0, 15.0),
                rng.range(0.2, 1.0),
            );
        }
        let (d0, d1, d2, b) = fit.system();
        let mut a = vec![vec![0.0f64; NODES + 1]; NODES];
        for k in 0..NODES {
            a[k][k] = d0[k];
            a[k][NODES] = b[k];
            if k + 1 < NODES {
                (a[k][k + 1], a[k + 1][k]) = (d1[k], d1[k]);
            }
            if k + 2 < NODES {
                (a[k][k + 2], a[k + 2][k]) = (d2[k], d2[k]);
            }
        }
        for c in 0..NODES {
            for r in c + 1..NODES {
                let f = a[r][c] / a[c][c];
                for k in c..=NODES {
                    a[r][k] -= f * a[c][k];
                }
            }
        }
        let mut x = [0.0f64; NODES];
        for r in (0..NODES).rev() {
            let s: f64 = (r + 1..NODES).map(|k| a[r][k] * x[k]).sum();
            x[r] = (a[r][NODES] - s) / a[r][r];
        }
        let mut map = PlMap::identity();
        fit.solve(&mut map);
        for k in 0..NODES {
            assert!(
                (map.0[k] - x[k]).abs() < 1e-8 * (1.0 + x[k].abs()),
                "{k}: {} {}",
                map.0[k],
                x[k]
            );
        }
    }

    #[test]
    fn fit_recovers_affine_maps_exactly_and_bridges_gaps() {
        let mut fit = MapFit::default();
        let mut map = PlMap::identity();
        // Data only in 30..90 and 160..220: the map is affine everywhere.
        for i in 0..400 {
            let x = if i % 2 == 0 { 30.0 } else { 160.0 } + (i as f64 * 0.37) % 60.0;
            fit.add(x, 0.6 * x + 25.0, 1.0);
        }
        fit.solve(&mut map);
        for x in [-10.0, 0.0, 50.0, 120.0, 200.0, 255.0, 280.0] {
            let (v, s) = map.eval(x);
            assert!((v - (0.6 * x + 25.0)).abs() < 1e-3, "{x}: {v}");
            assert!((s - 0.6).abs() < 1e-4);
        }
        // A non-linear (gamma) relation is followed closely where there is data.
        fit.clear();
        for i in 0..2000 {
            let x = (i as f64 * 0.1277) % 255.0;
            fit.add(x, 255.0 * (x / 255.0).powf(0.5), 1.0);
        }
        fit.solve(&mut map);
        for x in [20.0, 64.0, 128.0, 250.0] {
            let want = 255.0 * (x / 255.0f64).powf(0.5);
            assert!((map.eval(x).0 - want).abs() < 1.5, "{x}: {}", map.eval(x).0);
        }
    }

    #[test]
    fn region_weights_are_a_partition_of_unity() {
        let r = Regions::new(100, 3);
        assert_eq!(r.count(), 9);
        for w in &r.weights {
            let s: f32 = w.iter().map(|p| p.1).sum();
            assert!((s - 1.0).abs() < 1e-6);
        }
        // The centre pixel of the top-left block belongs to it alone.
        let c = (10.0f64 / 3.0 * 0.5 - 0.5).round() as usize;
        assert!(r.weights[c * 10 + c][0].1 > 0.9);
        assert_eq!(Regions::new(40, 3).count(), 1);
    }
}
