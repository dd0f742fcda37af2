//! The buffers of one iteration, allocated once with the grid: the warped grid, the sampled
//! values and gradients, the AM's gradient, `dw/dp` and the pixel Jacobian, and the Newton
//! solver (which keeps the last Hessian's factor). A search method's own state (ESM's best
//! point, NN's index, PF's particles) lives in the method.
//!
//! The workspace keeps its own cache: [`Workspace::patch_at`] skips sampling when `values`
//! already holds the patch of the same view (the same [`ImageView::stamp`], the content it
//! shows) at the same parameters. Every write of `values` by another way forgets it, so no
//! caller has to.

use super::Problem;
use crate::imaging::{ImageView, sample_values, sample_values_gradients};
use crate::linalg::{NewtonSolver, Square, SquareBuf};
use crate::ssm::Params;
use nalgebra::Matrix3;

/// What a projection reads and writes: the gradients `(gx, gy)`, `dw/dp` at the current
/// parameters, and the pixel Jacobian to be written.
pub type Projection<'a> = ((&'a [f32], &'a [f32]), &'a [f32], &'a mut [f32]);

/// The parts of the workspace a Newton step uses ([`Workspace::newton_mut`]).
pub struct NewtonParts<'a> {
    /// The Newton system's matrix.
    pub hessian: &'a mut Square,
    /// A second matrix (`J^T J`, for a Hessian made from it).
    pub scratch: &'a mut Square,
    pub solver: &'a mut NewtonSolver,
    /// The sampled gradients.
    pub gradients: (&'a [f32], &'a [f32]),
    /// The AM's gradient with respect to the pixels.
    pub grad: &'a [f32],
    /// The sampled values.
    pub values: &'a [f32],
    /// The pixel Jacobian.
    pub jac: &'a [f32],
}

/// When [`Workspace::whole_patch`] samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Again {
    /// Always.
    Always,
    /// Unless the patch of the same view at the same parameters is held.
    Unless,
    /// Without a selection never: the search's values were just sampled there.
    Held,
}

/// See the module's documentation.
#[derive(Debug, Default)]
pub struct Workspace {
    /// `dw/dp` at the current parameters.
    dwdp: Vec<f32>,
    /// Warped grid in frame pixels.
    px: Vec<f32>,
    py: Vec<f32>,
    /// Sampled current intensities and gradients.
    values: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    /// AM gradient with respect to pixels.
    grad: Vec<f32>,
    /// Pixel Jacobian `dI/dp` (`N x S`, stored by parameter).
    jac: Vec<f32>,
    /// The stamp of the view and the parameters whose patch `values` holds, when it was
    /// sampled by [`Workspace::sample_at`] or [`Workspace::sample_gradients_at`] from a
    /// stamped view and nothing has written `values` since.
    sampled: Option<(u64, Params)>,
    /// How many times `values` has been sampled (what was made of a patch is that patch's
    /// while this has not changed).
    samples: u64,
    solver: NewtonSolver,
    /// The Newton system's matrix (the AM's Hessian) and a second matrix for what makes it.
    hessian: SquareBuf,
    scratch: SquareBuf,
    /// The patch of the whole grid, when the problem's searches read only part of it
    /// ([`super::spi`]): its warped grid, its values and which view and parameters they are of.
    whole_px: Vec<f32>,
    whole_py: Vec<f32>,
    whole_values: Vec<f32>,
    whole_sampled: Option<(u64, Params)>,
}

impl Workspace {
    /// The buffers of an `n`-point grid and a `dof`-parameter SSM.
    pub fn new(n: usize, dof: usize) -> Self {
        let mut work = Workspace::default();
        work.resize(n, n, dof);
        work
    }

    /// The last patch of the whole grid ([`Workspace::whole_patch`]; the values without a
    /// selection).
    pub fn whole_values(&self, problem: &Problem) -> &[f32] {
        if problem.is_selective() {
            &self.whole_values
        } else {
            &self.values
        }
    }

    /// The buffers of an `n`-point search grid (of a `whole`-point grid: the whole patch's
    /// buffers are kept only when the two differ) and a `dof`-parameter SSM.
    pub fn resize(&mut self, n: usize, whole: usize, dof: usize) {
        for v in [
            &mut self.px,
            &mut self.py,
            &mut self.values,
            &mut self.gx,
            &mut self.gy,
            &mut self.grad,
        ] {
            v.resize(n, 0.0);
        }
        self.dwdp.resize(2 * n * dof, 0.0);
        self.jac.resize(n * dof, 0.0);
        let kept = if whole != n { whole } else { 0 };
        for v in [
            &mut self.whole_px,
            &mut self.whole_py,
            &mut self.whole_values,
        ] {
            v.resize(kept, 0.0);
        }
        self.sampled = None;
        self.whole_sampled = None;
    }

    /// The patch of `img` under `p` on the problem's whole grid ([`Problem::whole_grid`]),
    /// sampled as `again` says. Without a selection it is the search's own patch
    /// ([`Workspace::sample_at`], [`Workspace::patch_at`], or the values as they are). Counted
    /// as a sampling ([`Workspace::samples`]) whenever it samples.
    pub fn whole_patch(
        &mut self,
        problem: &Problem,
        img: &ImageView,
        p: &Params,
        again: Again,
    ) -> &[f32] {
        if !problem.is_selective() {
            match again {
                Again::Always => self.sample_at(problem, img, p),
                Again::Unless => self.patch_at(problem, img, p),
                Again::Held => {}
            }
            return &self.values;
        }
        let again = again == Again::Always;
        let stamp = img.stamp();
        if again || stamp == 0 || self.whole_sampled != Some((stamp, *p)) {
            let (gx, gy) = problem.whole_grid();
            problem.warp_points(p, gx, gy, &mut self.whole_px, &mut self.whole_py);
            sample_values(img, &self.whole_px, &self.whole_py, &mut self.whole_values);
            self.samples = self.samples.wrapping_add(1);
            self.whole_sampled = (stamp != 0).then_some((stamp, *p));
        }
        &self.whole_values
    }

    /// The grid warped into frame pixels by the last [`Workspace::warp_grid`].
    pub fn points(&self) -> (&[f32], &[f32]) {
        (&self.px, &self.py)
    }
    /// The sampled intensities (or what a method wrote there).
    pub fn values(&self) -> &[f32] {
        &self.values
    }
    /// The intensities, to be written: the patch they held is forgotten.
    pub fn values_mut(&mut self) -> &mut [f32] {
        self.sampled = None;
        &mut self.values
    }
    /// The sampled gradients (frame pixels), or what a method made of them.
    pub fn gradients(&self) -> (&[f32], &[f32]) {
        (&self.gx, &self.gy)
    }
    pub fn gradients_mut(&mut self) -> (&mut [f32], &mut [f32]) {
        (&mut self.gx, &mut self.gy)
    }
    /// The AM's gradient with respect to the pixels.
    pub fn grad(&self) -> &[f32] {
        &self.grad
    }
    pub fn grad_mut(&mut self) -> &mut [f32] {
        &mut self.grad
    }
    /// The values and, to be written, the AM's gradient (for [`crate::am::Am::gradient`]).
    pub fn values_and_grad_mut(&mut self) -> (&[f32], &mut [f32]) {
        (&self.values, &mut self.grad)
    }
    /// The pixel Jacobian `dI/dp`.
    pub fn jac(&self) -> &[f32] {
        &self.jac
    }
    /// `dw/dp` at the current parameters, to be written.
    pub fn dwdp_mut(&mut self) -> &mut [f32] {
        &mut self.dwdp
    }
    /// The gradients, `dw/dp` and, to be written, the pixel Jacobian (a projection's).
    pub fn projection_mut(&mut self) -> Projection<'_> {
        ((&self.gx, &self.gy), &self.dwdp, &mut self.jac)
    }
    /// What a Newton step reads and writes, each borrowed apart.
    pub fn newton_mut(&mut self) -> NewtonParts<'_> {
        NewtonParts {
            hessian: &mut self.hessian,
            scratch: &mut self.scratch,
            solver: &mut self.solver,
            gradients: (&self.gx, &self.gy),
            grad: &self.grad,
            values: &self.values,
            jac: &self.jac,
        }
    }
    /// How many times the values have been sampled: what was made of a patch is that patch's
    /// while this has not changed.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Warps the problem's grid by `p` into frame pixels.
    pub fn warp_grid(&mut self, problem: &Problem, p: &Params) {
        problem.warp_grid(p, &mut self.px, &mut self.py);
    }

    /// The patch of `img` under `p`: the grid warped by `p` and the frame's values sampled
    /// there, into `values`.
    pub fn sample_at(&mut self, problem: &Problem, img: &ImageView, p: &Params) {
        self.warp_grid(problem, p);
        self.sample(img, false);
        self.remember(img, p);
    }

    /// The patch of `img` under `p` in `values`, as [`Workspace::sample_at`] leaves it,
    /// sampled only if `values` does not hold it already.
    pub fn patch_at(&mut self, problem: &Problem, img: &ImageView, p: &Params) {
        let stamp = img.stamp();
        if stamp == 0 || self.sampled != Some((stamp, *p)) {
            self.sample_at(problem, img, p);
        }
    }

    /// [`Workspace::sample_at`] with the frame's gradients (frame pixels) too.
    pub fn sample_gradients_at(&mut self, problem: &Problem, img: &ImageView, p: &Params) {
        self.warp_grid(problem, p);
        self.sample(img, true);
        self.remember(img, p);
    }

    /// Samples the frame at the warped grid: values, and gradients (frame pixels) if asked.
    pub fn sample(&mut self, img: &ImageView, gradients: bool) {
        self.sampled = None;
        self.samples = self.samples.wrapping_add(1);
        if gradients {
            sample_values_gradients(
                img,
                &self.px,
                &self.py,
                &mut self.values,
                &mut self.gx,
                &mut self.gy,
            );
        } else {
            sample_values(img, &self.px, &self.py, &mut self.values);
        }
    }

    fn remember(&mut self, img: &ImageView, p: &Params) {
        let stamp = img.stamp();
        self.sampled = (stamp != 0).then_some((stamp, *p));
    }

    /// Turns the sampled frame gradients into the gradient of the warped frame
    /// `I_t(pixel(w(x, p)))` with respect to the points `(us, vs)` that `m` takes to the
    /// warped grid (chain rule through the homography's point Jacobian), in place; with
    /// `mean`, then its mean with that gradient `(tx, ty)` (ESM's gradient), in the same pass.
    pub fn chain_gradients(
        &mut self,
        m: &Matrix3<f32>,
        (us, vs): (&[f32], &[f32]),
        mean: Option<(&[f32], &[f32])>,
    ) {
        let n = us.len();
        unit_gradient_in_place(
            m,
            (&us[..n], &vs[..n]),
            (&self.px[..n], &self.py[..n]),
            (&mut self.gx[..n], &mut self.gy[..n]),
            mean,
        );
    }

    /// [`Workspace::chain_gradients`] for a warp that is not projective: the sampled gradient
    /// (frame pixels) times `scale` (pixels per normalised unit) and each point's Jacobian
    /// `jacobian(i)` (`dw/dx`, row-major), then with `mean` its mean with that gradient.
    pub fn chain_point_jacobians(
        &mut self,
        jacobian: impl Fn(usize) -> [f32; 4],
        scale: f32,
        mean: Option<(&[f32], &[f32])>,
    ) {
        for i in 0..self.gx.len() {
            let [a00, a01, a10, a11] = jacobian(i);
            let (g, h) = (self.gx[i] * scale, self.gy[i] * scale);
            let (a, b) = (g * a00 + h * a10, g * a01 + h * a11);
            match mean {
                Some((tx, ty)) => {
                    self.gx[i] = 0.5 * (a + tx[i]);
                    self.gy[i] = 0.5 * (b + ty[i]);
                }
                None => {
                    self.gx[i] = a;
                    self.gy[i] = b;
                }
            }
        }
    }

    /// [`Workspace::chain_gradients`] without the mean, into `out` instead of in place.
    pub fn chain_gradients_into(
        &self,
        m: &Matrix3<f32>,
        (us, vs): (&[f32], &[f32]),
        (ox, oy): (&mut [f32], &mut [f32]),
    ) {
        ox.copy_from_slice(&self.gx);
        oy.copy_from_slice(&self.gy);
        unit_gradient_in_place(m, (us, vs), (&self.px, &self.py), (ox, oy), None);
    }
}

/// The gradient `(gx, gy)` sampled in pixels at `(px, py)`, the points `(us, vs)` under the
/// homography `m` (the unit square's, or the normalised ones with the pixel matrix), turned in
/// place into the gradient with respect to `(u, v)`, then, with `mean`, its mean with that
/// gradient `(tx, ty)`.
fn unit_gradient_in_place(
    m: &Matrix3<f32>,
    (us, vs): (&[f32], &[f32]),
    (px, py): (&[f32], &[f32]),
    (gx, gy): (&mut [f32], &mut [f32]),
    mean: Option<(&[f32], &[f32])>,
) {
    match mean {
        None => chain_unit::<false>(m, (us, vs), (px, py), (gx, gy), (&[], &[])),
        Some(t) => chain_unit::<true>(m, (us, vs), (px, py), (gx, gy), t),
    }
}

/// [`unit_gradient_in_place`]'s loop, with or without the mean.
fn chain_unit<const MEAN: bool>(
    m: &Matrix3<f32>,
    (us, vs): (&[f32], &[f32]),
    (px, py): (&[f32], &[f32]),
    (gx, gy): (&mut [f32], &mut [f32]),
    (tx, ty): (&[f32], &[f32]),
) {
    let n = gx.len();
    let (us, vs, px, py, gy) = (&us[..n], &vs[..n], &px[..n], &py[..n], &mut gy[..n]);
    let (tx, ty) = if MEAN {
        (&tx[..n], &ty[..n])
    } else {
        (&[][..], &[][..])
    };
    let (m00, m01, m10, m11) = (m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]);
    let (m20, m21, m22) = (m[(2, 0)], m[(2, 1)], m[(2, 2)]);
    for i in 0..n {
        let iw = 1.0 / (m20 * us[i] + m21 * vs[i] + m22);
        let (x, y) = (px[i], py[i]);
        let a00 = (m00 - x * m20) * iw;
        let a01 = (m01 - x * m21) * iw;
        let a10 = (m10 - y * m20) * iw;
        let a11 = (m11 - y * m21) * iw;
        let (g, h) = (gx[i], gy[i]);
        let (a, b) = (g * a00 + h * a10, g * a01 + h * a11);
        if MEAN {
            gx[i] = 0.5 * (a + tx[i]);
            gy[i] = 0.5 * (b + ty[i]);
        } else {
            gx[i] = a;
            gy[i] = b;
        }
    }
}

/// The points `(xs, ys)` under the homography `m`, into `(px, py)` (computed in `f32`).
pub fn warp_points(m: &Matrix3<f64>, xs: &[f32], ys: &[f32], px: &mut [f32], py: &mut [f32]) {
    let m = m.cast::<f32>();
    let (m00, m01, m02) = (m[(0, 0)], m[(0, 1)], m[(0, 2)]);
    let (m10, m11, m12) = (m[(1, 0)], m[(1, 1)], m[(1, 2)]);
    let (m20, m21, m22) = (m[(2, 0)], m[(2, 1)], m[(2, 2)]);
    let n = xs.len();
    let (ys, px, py) = (&ys[..n], &mut px[..n], &mut py[..n]);
    for i in 0..n {
        let (x, y) = (xs[i], ys[i]);
        let w = 1.0 / (m20 * x + m21 * y + m22);
        px[i] = (m00 * x + m01 * y + m02) * w;
        py[i] = (m10 * x + m11 * y + m12) * w;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::HessianKind;
    use crate::geometry::Quad;
    use crate::spec::GridLayout;

    /// `patch_at` samples again unless the workspace holds the patch of the same content (the
    /// view's stamp) at the same parameters: not for another stamp, not for an unstamped view,
    /// not once the values were written another way.
    #[test]
    fn a_patch_is_reused_only_from_the_same_content_at_the_same_parameters() {
        let mut problem = Problem::new(
            crate::ssm::build("translation").unwrap(),
            crate::am::build("ssd").unwrap(),
            HessianKind::Default,
            4,
        );
        let p = problem
            .set_region(&Quad::from_rect(2.0, 2.0, 8.0, 8.0), 4, GridLayout::Centres)
            .unwrap();
        let data: Vec<f32> = (0..144).map(|i| i as f32).collect();
        let view = ImageView::new(&data, 12, 12, 0, 0);
        let (a, b) = (view.with_stamp(8), view.with_stamp(16));
        let mut work = Workspace::new(16, 2);
        work.patch_at(&problem, &a, &p);
        assert_eq!(work.samples(), 1);
        work.patch_at(&problem, &a, &p);
        assert_eq!(work.samples(), 1, "the same content at the same parameters");
        let mut q = p;
        q[0] += 0.1;
        work.patch_at(&problem, &a, &q);
        assert_eq!(work.samples(), 2, "other parameters");
        work.patch_at(&problem, &b, &q);
        assert_eq!(work.samples(), 3, "other content");
        work.patch_at(&problem, &view, &q);
        work.patch_at(&problem, &view, &q);
        assert_eq!(work.samples(), 5, "unknown content");
        work.patch_at(&problem, &b, &q);
        let before = work.values().to_vec();
        work.values_mut()[0] = -1.0;
        work.patch_at(&problem, &b, &q);
        assert_eq!(work.samples(), 7, "values written since");
        assert_eq!(work.values(), &before[..]);
    }
}
