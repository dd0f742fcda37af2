//! The non-rigid SSMs: a grid of `c x c` control points laid on the template's quad, each
//! moved by two parameters, and the warp the displacement field that moves them,
//!
//! `w(x, p) = x + sum_k phi_k(x) (p_2k, p_2k+1)`,
//!
//! with `phi_k` the control point's basis function: a tensor-product clamped B-spline of the
//! quad's unit-square coordinates (`spline`, [`Kind::Spline`]) or the thin-plate spline's
//! cardinal function of the control points (`tps`, [`Kind::Tps`]: the smoothest field, in bending
//! energy, that moves the control points by the parameters, Bookstein 1989). The warp is linear in
//! `p`, so `dw/dp` is the basis and does not depend on `p`; it is not projective, so the
//! engine warps the grid and chains the gradients through [`Ssm::basis_gradients`] rather than
//! through a matrix ([`Ssm::projective`] is false).
//!
//! The control points sit on the template's quad (given by [`Ssm::set_base`]; the canonical
//! square `[-0.5, 0.5]^2` until then), at the unit square's points `(i / (c - 1), j / (c - 1))`
//! mapped by the quad's homography, so that the four corner control points are the quad's
//! corners: a corner moves exactly by its control point's parameters in both models. Warps
//! are not closed under composition: [`Ssm::compose`] and [`Ssm::invert`] are the
//! least-squares projections onto the model of the composed (inverted) field on a `(2c + 1)^2`
//! grid of the quad (its corners, control points of the model, kept where the field takes
//! them), and [`Ssm::fit`] projects the homography through the four corners.

use super::{Params, Ssm};
use crate::geometry::{Point, Quad, apply_homography, homography_from_points};
use crate::linalg::MAX_DOF;
use nalgebra::{DMatrix, Matrix3};

/// The most control points (`MAX_DOF / 2`).
pub const MAX_CONTROL: usize = MAX_DOF / 2;

/// How much more than another fit point each of the quad's corners weighs in a projection.
const CORNER_WEIGHT: f64 = 1e6;

/// The largest grid of points the projections are fitted on (`(2c + 1)^2` with `c = 5`).
const MAX_FIT: usize = 121;

/// Which basis the control points have.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Tensor-product clamped uniform B-splines (cubic with four or more control points a
    /// side, else of degree `c - 1`) of the quad's unit-square coordinates.
    Spline,
    /// Thin-plate spline cardinal functions (`U(r) = r^2 log r^2` plus an affine part).
    Tps,
}

/// A displacement model (see the module's documentation).
#[derive(Clone, Debug)]
pub struct Displacement {
    name: &'static str,
    kind: Kind,
    /// Control points a side.
    c: usize,
    names: &'static [&'static str],
    /// The template's quad (normalised frame) and the homography from the unit square
    /// `[0, 1]^2` to it, and back.
    base: [Point; 4],
    from_unit: Matrix3<f64>,
    to_unit: Matrix3<f64>,
    /// The control points (normalised frame), `k = j c + i`.
    control: Vec<Point>,
    /// The clamped knot vector of each side's B-spline (`c + degree + 1` knots).
    knots: Vec<f64>,
    /// The thin-plate spline's inverse system `L^-1` (`(M + 3) x (M + 3)`, row-major), whose
    /// first `M` columns give the cardinal functions.
    tps: Vec<f64>,
    /// The points the projections are fitted on, and the projector `(Phi^T Phi)^-1 Phi^T`
    /// (`M x F`, row-major) of their basis values.
    fit_points: Vec<Point>,
    projector: Vec<f64>,
    /// The prior's weight when the tracker leaves it to the model.
    default_smoothness: f64,
    /// The smoothness prior's matrix `R` (`M x M`, row-major, trace `M`): `d^T R d` of a
    /// field component `d` is its bending (zero for an affine field).
    smooth: Vec<f64>,
}

impl Displacement {
    /// The model with `c x c` control points (2 <= c <= 5) on the canonical square; with
    /// `default_smoothness` the weight of its bending prior when the tracker leaves it to the
    /// model.
    pub fn new(
        name: &'static str,
        kind: Kind,
        c: usize,
        names: &'static [&'static str],
        default_smoothness: f64,
    ) -> Displacement {
        assert!((2..=5).contains(&c) && names.len() == 2 * c * c);
        let degree = (c - 1).min(3);
        let inner = c - degree;
        let mut knots = vec![0.0; degree + 1];
        knots.extend((1..inner).map(|i| i as f64 / inner as f64));
        knots.extend(std::iter::repeat_n(1.0, degree + 1));
        let mut model = Displacement {
            name,
            kind,
            c,
            names,
            base: Quad::unit_square().0,
            from_unit: Matrix3::identity(),
            to_unit: Matrix3::identity(),
            control: Vec::new(),
            knots,
            tps: Vec::new(),
            fit_points: Vec::new(),
            projector: Vec::new(),
            smooth: Vec::new(),
            default_smoothness,
        };
        model.lay(&Quad::unit_square().0);
        model
    }

    /// Where the control points sit along a side of the unit square: evenly spaced for the
    /// thin-plate spline, at the knots' Greville abscissae (the means of `degree` consecutive
    /// inner knots, where a B-spline's control polygon follows its curve) for the B-spline;
    /// both from 0 to 1.
    fn control_abscissae(&self) -> [f64; 5] {
        let c = self.c;
        let mut at = [0.0; 5];
        for (i, a) in at.iter_mut().enumerate().take(c) {
            *a = match self.kind {
                Kind::Tps => i as f64 / (c - 1) as f64,
                Kind::Spline => {
                    let k = self.knots.len() - c - 1;
                    self.knots[i + 1..=i + k].iter().sum::<f64>() / k as f64
                }
            };
        }
        at
    }

    /// The control points (normalised frame), `k = j c + i` for the `i`-th along the quad's
    /// first side and the `j`-th along its second.
    pub fn control_points(&self) -> &[Point] {
        &self.control
    }

    /// Control points.
    fn m(&self) -> usize {
        self.c * self.c
    }

    /// Lays the control points on `base` and makes what depends on them; `false` (and nothing
    /// changed) for a degenerate quad.
    fn lay(&mut self, base: &[Point; 4]) -> bool {
        let unit = [
            Point::new(0.0, 0.0),
            Point::new(1.0, 0.0),
            Point::new(1.0, 1.0),
            Point::new(0.0, 1.0),
        ];
        let Some(from_unit) = homography_from_points(&unit, base) else {
            return false;
        };
        let Some(to_unit) = from_unit.try_inverse() else {
            return false;
        };
        let mut next = self.clone();
        next.base = *base;
        next.from_unit = from_unit;
        next.to_unit = to_unit;
        let c = self.c;
        let at = self.control_abscissae();
        next.control = (0..c * c)
            .map(|k| apply_homography(&from_unit, Point::new(at[k % c], at[k / c])))
            .collect();
        if self.kind == Kind::Tps && !next.solve_tps() {
            return false;
        }
        let f = 2 * c + 1;
        let fstep = 1.0 / (f - 1) as f64;
        next.fit_points = (0..f * f)
            .map(|k| {
                apply_homography(
                    &from_unit,
                    Point::new((k % f) as f64 * fstep, (k / f) as f64 * fstep),
                )
            })
            .collect();
        if !next.make_projector() {
            return false;
        }
        next.make_smoothness();
        *self = next;
        true
    }

    /// The bending prior `R`: for the thin-plate spline its bending energy, the top-left
    /// `M x M` block of `L^-1` (Bookstein); for the B-spline the squared second divided
    /// differences of the control net along each side and twice its twist (the discrete
    /// `f_uu^2 + 2 f_uv^2 + f_vv^2`), at the control points' abscissae. Scaled to trace `M`.
    fn make_smoothness(&mut self) {
        let m = self.m();
        let mut r = vec![0.0; m * m];
        match self.kind {
            Kind::Tps => {
                let s = m + 3;
                for a in 0..m {
                    for b in 0..m {
                        r[a * m + b] = 0.5 * (self.tps[a * s + b] + self.tps[b * s + a]);
                    }
                }
            }
            Kind::Spline => {
                let c = self.c;
                let at = self.control_abscissae();
                let mut add = |terms: &[(usize, f64)]| {
                    for &(a, x) in terms {
                        for &(b, y) in terms {
                            r[a * m + b] += x * y;
                        }
                    }
                };
                let second = |i: usize| {
                    let (h0, h1) = (at[i] - at[i - 1], at[i + 1] - at[i]);
                    let w = 2.0 / (h0 + h1);
                    [w / h0, -w / h0 - w / h1, w / h1]
                };
                for j in 0..c {
                    for i in 1..c - 1 {
                        let [a, b, d] = second(i);
                        add(&[(j * c + i - 1, a), (j * c + i, b), (j * c + i + 1, d)]);
                        add(&[(i * c + j - c, a), (i * c + j, b), (i * c + j + c, d)]);
                    }
                }
                let twist = std::f64::consts::SQRT_2;
                for j in 0..c - 1 {
                    for i in 0..c - 1 {
                        let w = twist / ((at[i + 1] - at[i]) * (at[j + 1] - at[j]));
                        let k = j * c + i;
                        add(&[(k, w), (k + 1, -w), (k + c, -w), (k + c + 1, w)]);
                    }
                }
            }
        }
        let trace: f64 = (0..m).map(|a| r[a * m + a]).sum();
        if trace > 0.0 && trace.is_finite() {
            r.iter_mut().for_each(|v| *v *= m as f64 / trace);
        }
        self.smooth = r;
    }

    /// The thin-plate spline's system `L = [[K, P], [P^T, 0]]` (`K_mn = U(|q_m - q_n|)`, `P`'s
    /// rows `(1, x_m, y_m)`) inverted.
    fn solve_tps(&mut self) -> bool {
        let m = self.m();
        let mut l = DMatrix::<f64>::zeros(m + 3, m + 3);
        for (a, qa) in self.control.iter().enumerate() {
            for (b, qb) in self.control.iter().enumerate() {
                l[(a, b)] = kernel(qa.x - qb.x, qa.y - qb.y);
            }
            for (j, v) in [1.0, qa.x, qa.y].into_iter().enumerate() {
                l[(a, m + j)] = v;
                l[(m + j, a)] = v;
            }
        }
        let Some(inv) = l.try_inverse() else {
            return false;
        };
        self.tps = (0..(m + 3) * (m + 3))
            .map(|k| inv[(k / (m + 3), k % (m + 3))])
            .collect();
        self.tps.iter().all(|v| v.is_finite())
    }

    /// The weighted least-squares projector of the basis values on the fit points
    /// (`(Phi^T W Phi)^-1 Phi^T W`): the quad's four corners weigh [`CORNER_WEIGHT`], so that
    /// a projected field moves them as the field it projects does (to rounding: they are
    /// control points of both models), the rest of the quad as near as the model can.
    fn make_projector(&mut self) -> bool {
        let (m, f) = (self.m(), self.fit_points.len());
        let side = 2 * self.c + 1;
        let corners = [0, side - 1, side * (side - 1), side * side - 1];
        let mut phi = DMatrix::<f64>::zeros(f, m);
        let mut weighted = DMatrix::<f64>::zeros(m, f);
        let mut row = [0.0; MAX_CONTROL];
        for (i, q) in self.fit_points.iter().enumerate() {
            self.basis(q.x, q.y, &mut row, None);
            let w = if corners.contains(&i) {
                CORNER_WEIGHT
            } else {
                1.0
            };
            for k in 0..m {
                phi[(i, k)] = row[k];
                weighted[(k, i)] = w * row[k];
            }
        }
        let Some(inv) = (&weighted * &phi).try_inverse() else {
            return false;
        };
        let projector = inv * weighted;
        self.projector = (0..m * f).map(|k| projector[(k / f, k % f)]).collect();
        self.projector.iter().all(|v| v.is_finite())
    }

    /// The basis functions `phi_k(x, y)` into `phi` and, if asked, their gradients with
    /// respect to `(x, y)` into `grad`.
    fn basis(
        &self,
        x: f64,
        y: f64,
        phi: &mut [f64; MAX_CONTROL],
        grad: Option<&mut [[f64; 2]; MAX_CONTROL]>,
    ) {
        match self.kind {
            Kind::Spline => self.spline_basis(x, y, phi, grad),
            Kind::Tps => self.tps_basis(x, y, phi, grad),
        }
    }

    fn spline_basis(
        &self,
        x: f64,
        y: f64,
        phi: &mut [f64; MAX_CONTROL],
        grad: Option<&mut [[f64; 2]; MAX_CONTROL]>,
    ) {
        let h = &self.to_unit;
        let w = h[(2, 0)] * x + h[(2, 1)] * y + h[(2, 2)];
        let u = (h[(0, 0)] * x + h[(0, 1)] * y + h[(0, 2)]) / w;
        let v = (h[(1, 0)] * x + h[(1, 1)] * y + h[(1, 2)]) / w;
        let (nu, du) = bspline(&self.knots, self.c, u);
        let (nv, dv) = bspline(&self.knots, self.c, v);
        let c = self.c;
        for j in 0..c {
            for i in 0..c {
                phi[j * c + i] = nu[i] * nv[j];
            }
        }
        if let Some(grad) = grad {
            // d(u, v)/d(x, y) of the homography to the unit square.
            let (ux, uy) = (
                (h[(0, 0)] - u * h[(2, 0)]) / w,
                (h[(0, 1)] - u * h[(2, 1)]) / w,
            );
            let (vx, vy) = (
                (h[(1, 0)] - v * h[(2, 0)]) / w,
                (h[(1, 1)] - v * h[(2, 1)]) / w,
            );
            for j in 0..c {
                for i in 0..c {
                    let (pu, pv) = (du[i] * nv[j], nu[i] * dv[j]);
                    grad[j * c + i] = [pu * ux + pv * vx, pu * uy + pv * vy];
                }
            }
        }
    }

    fn tps_basis(
        &self,
        x: f64,
        y: f64,
        phi: &mut [f64; MAX_CONTROL],
        grad: Option<&mut [[f64; 2]; MAX_CONTROL]>,
    ) {
        let m = self.m();
        let s = m + 3;
        let want_grad = grad.is_some();
        // The kernel U = r^2 log r^2 at each control point and, if asked, its gradient
        // 2 (dx, dy) (log r^2 + 1) (both 0 at 0), one logarithm each.
        let mut u = [0.0; MAX_CONTROL];
        let mut du = [[0.0; 2]; MAX_CONTROL];
        for (n, q) in self.control.iter().enumerate() {
            let (dx, dy) = (x - q.x, y - q.y);
            let r2 = dx * dx + dy * dy;
            if r2 > 0.0 {
                let l = r2.ln();
                u[n] = r2 * l;
                if want_grad {
                    let t = 2.0 * (l + 1.0);
                    du[n] = [t * dx, t * dy];
                }
            }
        }
        let inv = &self.tps;
        for k in 0..m {
            let column = |n: usize| inv[n * s + k];
            let affine = column(m) + x * column(m + 1) + y * column(m + 2);
            phi[k] = (0..m).fold(affine, |v, n| v + u[n] * column(n));
        }
        if let Some(grad) = grad {
            for (k, gk) in grad.iter_mut().enumerate().take(m) {
                let column = |n: usize| inv[n * s + k];
                *gk = [column(m + 1), column(m + 2)];
                for n in 0..m {
                    gk[0] += du[n][0] * column(n);
                    gk[1] += du[n][1] * column(n);
                }
            }
        }
    }

    /// The displacement `sum_k phi_k(x) (p_2k, p_2k+1)` at a point.
    fn displace(&self, p: &Params, q: Point) -> Point {
        let mut phi = [0.0; MAX_CONTROL];
        self.basis(q.x, q.y, &mut phi, None);
        let (mut dx, mut dy) = (0.0, 0.0);
        for k in 0..self.m() {
            dx += phi[k] * p[2 * k];
            dy += phi[k] * p[2 * k + 1];
        }
        Point::new(q.x + dx, q.y + dy)
    }

    /// The parameters whose field best fits (least squares on the fit points) the points'
    /// images `to(x_f)`; `None` if one is not finite.
    fn project(&self, to: impl Fn(Point) -> Option<Point>) -> Option<Params> {
        let f = self.fit_points.len();
        let (mut ex, mut ey) = ([0.0; MAX_FIT], [0.0; MAX_FIT]);
        for (i, &x) in self.fit_points.iter().enumerate() {
            let t = to(x)?;
            ex[i] = t.x - x.x;
            ey[i] = t.y - x.y;
        }
        let mut p = [0.0; MAX_DOF];
        for k in 0..self.m() {
            let row = &self.projector[k * f..(k + 1) * f];
            p[2 * k] = row.iter().zip(&ex).map(|(a, b)| a * b).sum();
            p[2 * k + 1] = row.iter().zip(&ey).map(|(a, b)| a * b).sum();
        }
        p.iter().all(|v| v.is_finite()).then_some(p)
    }

    /// The point `y` with `w(y, p) = x` (Newton's iterations from `x`), `None` where the field
    /// folds there.
    fn preimage(&self, p: &Params, x: Point) -> Option<Point> {
        let mut y = x;
        let (mut phi, mut grad) = ([0.0; MAX_CONTROL], [[0.0; 2]; MAX_CONTROL]);
        for _ in 0..30 {
            self.basis(y.x, y.y, &mut phi, Some(&mut grad));
            let (mut wx, mut wy) = (y.x, y.y);
            let (mut a, mut b, mut c, mut d) = (1.0, 0.0, 0.0, 1.0);
            for k in 0..self.m() {
                let (px, py) = (p[2 * k], p[2 * k + 1]);
                wx += phi[k] * px;
                wy += phi[k] * py;
                a += px * grad[k][0];
                b += px * grad[k][1];
                c += py * grad[k][0];
                d += py * grad[k][1];
            }
            let (rx, ry) = (wx - x.x, wy - x.y);
            let det = a * d - b * c;
            if det <= 1e-9 || !det.is_finite() {
                return None;
            }
            let (sx, sy) = ((d * rx - b * ry) / det, (-c * rx + a * ry) / det);
            y = Point::new(y.x - sx, y.y - sy);
            if sx * sx + sy * sy < 1e-26 {
                break;
            }
        }
        (y.x.is_finite() && y.y.is_finite()).then_some(y)
    }
}

/// The thin-plate spline's kernel `U = r^2 log r^2` at the offset `(dx, dy)` (0 at 0).
fn kernel(dx: f64, dy: f64) -> f64 {
    let r2 = dx * dx + dy * dy;
    if r2 > 0.0 { r2 * r2.ln() } else { 0.0 }
}

/// The `c` clamped B-spline basis functions of the knot vector `t` at `u` and their
/// derivatives (outside `[0, 1]`, the end pieces' polynomials continued). The Cox-de Boor
/// recursion on the knot span of `u`.
fn bspline(t: &[f64], c: usize, u: f64) -> ([f64; 5], [f64; 5]) {
    let k = t.len() - c - 1;
    // The span [t_s, t_s+1) that holds u, within k..=c-1.
    let mut s = k;
    while s + 1 < c && u >= t[s + 1] {
        s += 1;
    }
    // The degree-j functions N_{s-j..=s} in n[0..=j], built up from degree 0.
    let mut n = [0.0; 5];
    let mut lower = [0.0; 5];
    n[0] = 1.0;
    let (mut left, mut right) = ([0.0; 5], [0.0; 5]);
    for j in 1..=k {
        if j == k {
            lower = n;
        }
        left[j] = u - t[s + 1 - j];
        right[j] = t[s + j] - u;
        let mut saved = 0.0;
        for r in 0..j {
            let tmp = n[r] / (right[r + 1] + left[j - r]);
            n[r] = saved + right[r + 1] * tmp;
            saved = left[j - r] * tmp;
        }
        n[j] = saved;
    }
    let (mut values, mut derivs) = ([0.0; 5], [0.0; 5]);
    for r in 0..=k {
        let i = s - k + r;
        values[i] = n[r];
        if k == 0 {
            continue;
        }
        // N'_{i,k} = k (N_{i,k-1} / (t_{i+k} - t_i) - N_{i+1,k-1} / (t_{i+k+1} - t_{i+1})),
        // with N_{s-k+1+q, k-1} = lower[q].
        let mut d = 0.0;
        if r >= 1 {
            let span = t[i + k] - t[i];
            if span > 0.0 {
                d += lower[r - 1] / span;
            }
        }
        if r < k {
            let span = t[i + k + 1] - t[i + 1];
            if span > 0.0 {
                d -= lower[r] / span;
            }
        }
        derivs[i] = k as f64 * d;
    }
    (values, derivs)
}

impl Ssm for Displacement {
    fn name(&self) -> &'static str {
        self.name
    }
    fn dof(&self) -> usize {
        2 * self.m()
    }
    fn param_names(&self) -> &'static [&'static str] {
        self.names
    }
    fn projective(&self) -> bool {
        false
    }
    fn smoothness(&self) -> Option<&[f64]> {
        Some(&self.smooth)
    }
    fn default_smoothness(&self) -> f64 {
        self.default_smoothness
    }
    fn set_base(&mut self, corners: &[Point; 4]) {
        self.lay(corners);
    }
    fn matrix(&self, p: &Params) -> Matrix3<f64> {
        // The homography through the moved corners (the corners' control points).
        let moved: [Point; 4] = std::array::from_fn(|k| self.displace(p, self.base[k]));
        homography_from_points(&self.base, &moved)
            .unwrap_or_else(|| Matrix3::from_element(f64::NAN))
    }
    fn params_from_matrix(&self, m: &Matrix3<f64>) -> Option<Params> {
        self.project(|x| {
            let q = apply_homography(m, x);
            (q.x.is_finite() && q.y.is_finite()).then_some(q)
        })
    }
    fn jacobian(&self, _p: &Params, xs: &[f32], ys: &[f32], out: &mut [f32]) {
        let n = xs.len();
        let m = self.m();
        let mut phi = [0.0; MAX_CONTROL];
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            self.basis(x as f64, y as f64, &mut phi, None);
            for k in 0..m {
                let v = phi[k] as f32;
                super::put(out, n, i, 2 * k, v, 0.0);
                super::put(out, n, i, 2 * k + 1, 0.0, v);
            }
        }
    }
    fn basis_gradients(&self, xs: &[f32], ys: &[f32], out: &mut [f32]) -> bool {
        let n = xs.len();
        let (mut phi, mut grad) = ([0.0; MAX_CONTROL], [[0.0; 2]; MAX_CONTROL]);
        for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
            self.basis(x as f64, y as f64, &mut phi, Some(&mut grad));
            for k in 0..self.m() {
                out[2 * k * n + i] = grad[k][0] as f32;
                out[(2 * k + 1) * n + i] = grad[k][1] as f32;
            }
        }
        true
    }
    fn fit(&self, src: &[Point; 4], dst: &[Point; 4]) -> Option<Params> {
        self.params_from_matrix(&homography_from_points(src, dst)?)
    }
    fn compose(&self, p: &Params, q: &Params) -> Option<Params> {
        self.project(|x| Some(self.displace(p, self.displace(q, x))))
    }
    fn invert(&self, p: &Params) -> Option<Params> {
        self.project(|x| self.preimage(p, x))
    }
    fn then_matrix(&self, p: &Params, m: &Matrix3<f64>) -> Option<Params> {
        self.project(|x| {
            let q = apply_homography(m, self.displace(p, x));
            (q.x.is_finite() && q.y.is_finite()).then_some(q)
        })
    }
    fn warp_points(&self, p: &Params, pts: &[Point], out: &mut [Point]) {
        for (o, &q) in out.iter_mut().zip(pts) {
            *o = self.displace(p, q);
        }
    }
}

/// The parameters' names of a 3 x 3 model: control point `(i, j)`'s displacement, `i` along the
/// target's first side, `j` along its second.
pub const NAMES_3: [&str; 18] = [
    "dx00", "dy00", "dx10", "dy10", "dx20", "dy20", "dx01", "dy01", "dx11", "dy11", "dx21", "dy21",
    "dx02", "dy02", "dx12", "dy12", "dx22", "dy22",
];

/// The parameters' names of a 5 x 5 model.
pub const NAMES_5: [&str; 50] = [
    "dx00", "dy00", "dx10", "dy10", "dx20", "dy20", "dx30", "dy30", "dx40", "dy40", "dx01", "dy01",
    "dx11", "dy11", "dx21", "dy21", "dx31", "dy31", "dx41", "dy41", "dx02", "dy02", "dx12", "dy12",
    "dx22", "dy22", "dx32", "dy32", "dx42", "dy42", "dx03", "dy03", "dx13", "dy13", "dx23", "dy23",
    "dx33", "dy33", "dx43", "dy43", "dx04", "dy04", "dx14", "dy14", "dx24", "dy24", "dx34", "dy34",
    "dx44", "dy44",
];

#[cfg(test)]
mod tests {
    use super::*;

    /// The B-spline functions sum to one, reproduce `u` (linear precision) and their
    /// derivatives are the finite differences', inside and past the ends.
    #[test]
    fn the_bspline_basis_is_a_partition_of_unity_with_its_derivatives() {
        for c in 2..=5 {
            let model = Displacement::new("t", Kind::Spline, c, NAMES_FOR_TESTS[c], 0.0);
            let t = &model.knots;
            for k in 0..=40 {
                let u = -0.1 + 1.2 * k as f64 / 40.0;
                let (n, d) = bspline(t, c, u);
                let sum: f64 = n[..c].iter().sum();
                assert!((sum - 1.0).abs() < 1e-12, "c {c} u {u}: sum {sum}");
                let h = 1e-6;
                let (np, _) = bspline(t, c, u + h);
                let (nm, _) = bspline(t, c, u - h);
                for i in 0..c {
                    let fd = (np[i] - nm[i]) / (2.0 * h);
                    // Away from the knots (where a derivative of a cubic is continuous anyway).
                    assert!(
                        (fd - d[i]).abs() < 1e-5 * (1.0 + fd.abs()),
                        "c {c} u {u} N{i}': {} vs {fd}",
                        d[i]
                    );
                }
            }
        }
    }

    /// Names enough for the tests' models.
    const NAMES_FOR_TESTS: [&[&str]; 6] = [&[], &[], &["p"; 8], &["p"; 18], &["p"; 32], &["p"; 50]];

    /// The thin-plate spline moves each control point by its parameters.
    #[test]
    fn the_tps_interpolates_the_control_points() {
        let mut model = Displacement::new("t", Kind::Tps, 3, NAMES_FOR_TESTS[3], 0.0);
        let skewed = [
            Point::new(-0.6, -0.4),
            Point::new(0.5, -0.5),
            Point::new(0.55, 0.6),
            Point::new(-0.45, 0.5),
        ];
        assert!(model.lay(&skewed));
        let mut p = [0.0; MAX_DOF];
        for (k, v) in p.iter_mut().take(18).enumerate() {
            *v = 0.01 * ((k * 7 % 5) as f64 - 2.0);
        }
        for (k, q) in model.control.clone().iter().enumerate() {
            let w = model.displace(&p, *q);
            assert!((w.x - q.x - p[2 * k]).abs() < 1e-9 && (w.y - q.y - p[2 * k + 1]).abs() < 1e-9);
        }
    }
}
