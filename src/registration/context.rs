//! The registration problem of one tracker, `p_t = argmax_p f(I*, I_t(w(x, p)))`: the models,
//! the sampling grid, the template, the current parameters and the buffers of one iteration,
//! shared by the search method and the driver. [`Context::similarity_at`] is the equation's
//! objective evaluated at a warp.

use crate::am::{Am, HessianKind, Wrt, jt_times};
use crate::geometry::{Normaliser, Point, Quad};
use crate::imaging::{ImageView, sample_values, sample_values_gradients};
use crate::linalg::{MAX_DOF, NewtonSolver};
use crate::spec::GridLayout;
use crate::ssm::{Params, Ssm};
use crate::status::LossReason;
use nalgebra::Matrix3;

use super::moments::GridMoments;

/// How a step `dp` changes the parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Update {
    /// `p + dp`.
    Additive,
    /// `w(w(x, dp), p)`: `p` after `dp`.
    Compose,
    /// `w(w(x, dp)^-1, p)`: `p` after the inverse of `dp`.
    ComposeInverse,
}

/// The registration problem of one tracker, shared by its search method and the driver: the
/// models, the sampling grid, the template and the current parameters; the per-iteration
/// buffers are apart, in [`Workspace`].
#[derive(Debug)]
pub struct Context {
    pub ssm: Box<dyn Ssm>,
    pub am: Box<dyn Am>,
    /// The Hessian kind to use (resolved: never [`HessianKind::Default`]).
    pub hessian: HessianKind,
    /// Levenberg-Marquardt damping `lambda` of the Newton steps (0: none); set by `lm:`.
    pub damping: f64,
    pub dof: usize,
    /// Image <-> normalised frame.
    pub norm: Normaliser,
    /// The sampling grid, in normalised coordinates (see [`GridLayout`]).
    pub grid_x: Vec<f32>,
    pub grid_y: Vec<f32>,
    /// The initial quad in normalised coordinates.
    pub template_corners: Quad,
    /// Current parameters.
    pub params: Params,
    /// Template intensities `I*` and their gradient in normalised coordinates.
    pub template: Vec<f32>,
    pub template_gx: Vec<f32>,
    pub template_gy: Vec<f32>,
    /// `dw/dp` at the identity on the grid (layout of [`Ssm::jacobian`]).
    pub dwdp0: Vec<f32>,
    /// Which rows of `dwdp0` (`2 k` for `dw_x/dp_k`, `2 k + 1` for `dw_y/dp_k`) are zero on the
    /// whole grid (half of them for the affine and projective warps): the projection skips them.
    pub dwdp0_zero: [bool; 2 * MAX_DOF],
    /// The grid in the unit square's coordinates, where it is regular, and the homography `G`
    /// from them to the normalised ones (`grid = G(grid_u, grid_v)`).
    pub grid_u: Vec<f32>,
    pub grid_v: Vec<f32>,
    pub unit: Matrix3<f64>,
    /// The template's gradient with respect to the unit square's coordinates (kept only with
    /// `moments`).
    pub template_gu: Vec<f32>,
    pub template_gv: Vec<f32>,
    /// The forward steps' Newton system from the gradient's moments, for the AMs whose Hessian
    /// is `-J^T J` on the SSMs of six or more parameters ([`super::moments`]).
    pub moments: Option<GridMoments>,
    /// Per-iteration buffers.
    pub work: Workspace,
    /// The Newton systems' solver (it keeps the last Hessian's factor).
    pub solver: NewtonSolver,
    /// The last step [`Context::apply`] made, and how: the driver's line search shortens it
    /// when the next iteration finds the similarity lower.
    pub last_step: Option<(Params, Update)>,
}

/// The buffers of one iteration (allocated once, with the grid): the warped grid, the sampled
/// values and gradients, the AM's gradient and the pixel Jacobian. A search method's own state
/// (ESM's mean Jacobian, NN's index, PF's particles) lives in the method.
#[derive(Debug, Default)]
pub struct Workspace {
    /// `dw/dp` at the current parameters.
    pub dwdp: Vec<f32>,
    /// Warped grid in frame pixels.
    pub px: Vec<f32>,
    pub py: Vec<f32>,
    /// Sampled current intensities and gradients.
    pub values: Vec<f32>,
    pub gx: Vec<f32>,
    pub gy: Vec<f32>,
    /// AM gradient with respect to pixels.
    pub grad: Vec<f32>,
    /// Pixel Jacobian `dI/dp` (`N x S`, stored by parameter).
    pub jac: Vec<f32>,
    /// The parameters whose patch `values` holds, when [`Context::sample_at`] or
    /// [`Context::sample_gradients_at`] sampled it and nothing has written `values` since;
    /// cleared by [`Context::sample`] and by whoever changes the frame or region being read
    /// (the driver, when it pre-processes). [`Context::patch_at`] then skips sampling again.
    pub sampled_at: Option<Params>,
    /// How many times [`Context::sample`] has written `values` (what was made of a patch is
    /// that patch's while this has not changed).
    pub samples: u64,
}

impl Context {
    /// A context for the given models with an `res x res` grid (buffers allocated here).
    pub fn new(ssm: Box<dyn Ssm>, am: Box<dyn Am>, hessian: HessianKind, res: usize) -> Self {
        let dof = ssm.dof();
        let hessian = hessian.or(am.default_hessian());
        let n = res * res;
        let z = |len: usize| vec![0.0f32; len];
        Context {
            ssm,
            am,
            hessian,
            damping: 0.0,
            solver: NewtonSolver::default(),
            dof,
            norm: Normaliser {
                cx: 0.0,
                cy: 0.0,
                scale: 1.0,
            },
            grid_x: z(n),
            grid_y: z(n),
            template_corners: Quad::unit_square(),
            params: [0.0; MAX_DOF],
            template: z(n),
            template_gx: z(n),
            template_gy: z(n),
            dwdp0: z(2 * n * dof),
            dwdp0_zero: [false; 2 * MAX_DOF],
            grid_u: z(n),
            grid_v: z(n),
            unit: Matrix3::identity(),
            template_gu: Vec::new(),
            template_gv: Vec::new(),
            moments: None,
            work: Workspace {
                dwdp: z(2 * n * dof),
                px: z(n),
                py: z(n),
                values: z(n),
                gx: z(n),
                gy: z(n),
                grad: z(n),
                jac: z(n * dof),
                sampled_at: None,
                samples: 0,
            },
            last_step: None,
        }
    }

    /// Number of sampled points.
    pub fn len(&self) -> usize {
        self.grid_x.len()
    }

    /// Whether the grid is empty.
    pub fn is_empty(&self) -> bool {
        self.grid_x.is_empty()
    }

    /// The matrix taking normalised template points to frame pixels under `p`.
    pub fn pixel_matrix(&self, p: &Params) -> Matrix3<f64> {
        self.norm.to_image_matrix() * self.ssm.matrix(p)
    }

    /// The corners under `p`, in frame pixels.
    pub fn corners(&self, p: &Params) -> Quad {
        let m = self.pixel_matrix(p);
        self.template_corners
            .map(|c| crate::geometry::apply_homography(&m, c))
    }

    /// Warps the grid by `p` into frame pixels (`px`, `py`).
    pub fn warp_grid(&mut self, p: &Params) {
        let m = self.pixel_matrix(p);
        warp_points(
            &m,
            &self.grid_x,
            &self.grid_y,
            &mut self.work.px,
            &mut self.work.py,
        );
    }

    /// The objective of `p_t = argmax_p f(I*, I_t(w(x, p)))` at `p`: the grid warped by `p`,
    /// the frame sampled there (into `work.values`), and the AM's similarity to the template.
    pub fn similarity_at(&mut self, img: &ImageView, p: &Params) -> f64 {
        self.sample_at(img, p);
        self.am.similarity(&self.work.values)
    }

    /// The patch of `img` under `p`: the grid warped by `p` and the frame's values sampled
    /// there, into `work.values`.
    pub fn sample_at(&mut self, img: &ImageView, p: &Params) {
        self.warp_grid(p);
        self.sample(img, false);
        self.work.sampled_at = Some(*p);
    }

    /// The patch of `img` under `p` in `work.values`, as [`Context::sample_at`] leaves it,
    /// sampled only if `work.values` does not hold it already (`work.sampled_at`; the caller
    /// reads the same view as when it was sampled).
    pub fn patch_at(&mut self, img: &ImageView, p: &Params) {
        if self.work.sampled_at != Some(*p) {
            self.sample_at(img, p);
        }
    }

    /// [`Context::sample_at`] with the frame's gradients (frame pixels) too, into `work.gx`,
    /// `work.gy`.
    pub fn sample_gradients_at(&mut self, img: &ImageView, p: &Params) {
        self.warp_grid(p);
        self.sample(img, true);
        self.work.sampled_at = Some(*p);
    }

    /// Samples the frame at the warped grid: values, and gradients (frame pixels) if asked.
    pub fn sample(&mut self, img: &ImageView, gradients: bool) {
        self.work.sampled_at = None;
        self.work.samples = self.work.samples.wrapping_add(1);
        if gradients {
            sample_values_gradients(
                img,
                &self.work.px,
                &self.work.py,
                &mut self.work.values,
                &mut self.work.gx,
                &mut self.work.gy,
            );
        } else {
            sample_values(img, &self.work.px, &self.work.py, &mut self.work.values);
        }
    }

    /// Turns the sampled frame gradients into the gradient of the warped frame
    /// `I_t(pixel(w(x, p)))` with respect to the normalised template point `x` (chain rule
    /// through the warp's point Jacobian), in place in `gx`, `gy`.
    pub fn warped_gradient(&mut self, p: &Params) {
        self.warped_gradient_with::<false>(p);
    }

    /// [`Context::warped_gradient`], then (in the same pass) its mean with the template's
    /// gradient, `(g + g*) / 2`: ESM's gradient.
    pub fn warped_gradient_mean(&mut self, p: &Params) {
        self.warped_gradient_with::<true>(p);
    }

    /// [`Context::warped_gradient`], with or without the mean: the chain rule of
    /// [`unit_gradient_in_place`] through the pixel matrix from the normalised points.
    fn warped_gradient_with<const MEAN: bool>(&mut self, p: &Params) {
        let m = self.pixel_matrix(p).cast::<f32>();
        let n = self.grid_x.len();
        let template = MEAN.then(|| (&self.template_gx[..n], &self.template_gy[..n]));
        unit_gradient_in_place(
            &m,
            (&self.grid_x[..n], &self.grid_y[..n]),
            (&self.work.px[..n], &self.work.py[..n]),
            (&mut self.work.gx[..n], &mut self.work.gy[..n]),
            template,
        );
    }

    /// `jac[k N + i] = gx[i] dw_x/dp_k + gy[i] dw_y/dp_k`, with `dw/dp` in the layout of
    /// [`Ssm::jacobian`].
    pub fn project(gx: &[f32], gy: &[f32], dwdp: &[f32], dof: usize, jac: &mut [f32]) {
        Self::project_skipping(gx, gy, dwdp, &[false; 2 * MAX_DOF], dof, jac);
    }

    /// [`Context::project`] with the rows of `dwdp` marked in `zero` known to be zero (not read).
    fn project_skipping(
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

    /// Projects the gradients in `gx`, `gy` (with respect to the normalised template point) on
    /// `dw/dp` into the pixel Jacobian `jac`: `dw/dp` at the identity (compositional methods)
    /// or, given `p`, at `p` (additive methods).
    pub fn project_gradients(&mut self, at: Option<&Params>) {
        if at.is_none()
            && self.ssm.project_at_identity(
                &self.work.gx,
                &self.work.gy,
                &self.grid_x,
                &self.grid_y,
                &mut self.work.jac,
            )
        {
            return;
        }
        let (dwdp, zero) = match at {
            Some(p) => {
                self.ssm
                    .jacobian(p, &self.grid_x, &self.grid_y, &mut self.work.dwdp);
                (&self.work.dwdp, [false; 2 * MAX_DOF])
            }
            None => (&self.dwdp0, self.dwdp0_zero),
        };
        Self::project_skipping(
            &self.work.gx,
            &self.work.gy,
            dwdp,
            &zero,
            self.dof,
            &mut self.work.jac,
        );
    }

    /// The forward-compositional (FCLK) step from `p`, once the frame's values and gradients
    /// have been sampled there ([`Context::sample_gradients_at`]); returns the similarity at `p`.
    pub fn forward_compositional_step(&mut self, p: &Params) -> Result<f64, LossReason> {
        if self.moments_step() {
            self.unit_gradient(p);
            let f = self
                .am
                .gradient(Wrt::Current, &self.work.values, &mut self.work.grad);
            return self.moments_newton_step(Update::Compose).map(|_| f);
        }
        self.warped_gradient(p);
        self.project_gradients(None);
        self.forward_step(Update::Compose)
    }

    /// Whether the forward steps at the identity form their Newton system from the gradient's
    /// moments ([`super::moments`]; SSD, SCV, LSCV, ZNCC and NCC, with SSMs of six or more
    /// parameters): then [`Context::unit_gradient`] (or its mean with the template's) and
    /// [`Context::moments_newton_step`] stand for the warped gradient, the projection and
    /// [`Context::forward_step_from_gradient`].
    pub fn moments_step(&self) -> bool {
        self.moments.is_some() && (self.am.hessian_is_minus_jtj() || self.am.hessian_from_jtj())
    }

    /// The pixel matrix times the grid's homography: the unit square's coordinates to pixels.
    fn unit_matrix(&self, p: &Params) -> Matrix3<f32> {
        (self.pixel_matrix(p) * self.unit).cast::<f32>()
    }

    /// Like [`Context::warped_gradient`], with respect to the unit square's coordinates
    /// (`grid_u`, `grid_v`) instead of the normalised ones.
    pub fn unit_gradient(&mut self, p: &Params) {
        self.unit_gradient_with(p, false);
    }

    /// [`Context::unit_gradient`], then its mean with the template's (ESM's gradient), in one
    /// pass.
    pub fn unit_gradient_mean(&mut self, p: &Params) {
        self.unit_gradient_with(p, true);
    }

    /// [`Context::unit_gradient`], with or without the mean.
    fn unit_gradient_with(&mut self, p: &Params, mean: bool) {
        let m = self.unit_matrix(p);
        let n = self.grid_u.len();
        let template = mean.then(|| (&self.template_gu[..n], &self.template_gv[..n]));
        unit_gradient_in_place(
            &m,
            (&self.grid_u[..n], &self.grid_v[..n]),
            (&self.work.px[..n], &self.work.py[..n]),
            (&mut self.work.gx[..n], &mut self.work.gy[..n]),
            template,
        );
    }

    /// The Newton step from the gradient with respect to the unit square's coordinates (in
    /// `gx`, `gy`) and the AM's gradient (in `grad`), through the moments; needs
    /// [`Context::moments_step`].
    pub fn moments_newton_step(&mut self, update: Update) -> Result<(), LossReason> {
        let (h, g) = self.moments_system()?;
        self.solve_step(&g, &h, update)
    }

    /// The Newton system of [`Context::moments_newton_step`]: the AM's Hessian (row-major `dof x
    /// dof`) and `J^T g`, from the moments: `-J^T J` for the least-squares models, and for the
    /// correlations their Hessian from `J^T J` and the moments' `J^T x`
    /// ([`crate::am::Am::hessian_from_projections`]).
    pub fn moments_system(
        &mut self,
    ) -> Result<([f64; MAX_DOF * MAX_DOF], [f64; MAX_DOF]), LossReason> {
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        let mut g = [0.0; MAX_DOF];
        let Some(moments) = self.moments.as_mut() else {
            return Err(LossReason::Singular);
        };
        moments.minus_jtj_and_jtr(
            &self.work.gx,
            &self.work.gy,
            &self.work.grad,
            &mut h,
            &mut g,
        );
        if self.am.hessian_is_minus_jtj() {
            return Ok((h, g));
        }
        let dof = self.dof;
        let mut jtj = [0.0; MAX_DOF * MAX_DOF];
        for i in 0..dof {
            for j in 0..dof {
                jtj[i * MAX_DOF + j] = -h[i * dof + j];
            }
        }
        let (gx, gy) = (&self.work.gx, &self.work.gy);
        let mut project = |xs: &[&[f32]], out: &mut [[f64; MAX_DOF]]| {
            for (x, o) in xs.iter().zip(out.iter_mut()) {
                moments.jtr(gx, gy, x, o);
            }
        };
        let kind = self.hessian;
        if self.am.hessian_from_projections(
            kind,
            &self.work.values,
            &jtj,
            &mut project,
            dof,
            &mut h,
        ) {
            Ok((h, g))
        } else {
            Err(LossReason::Singular)
        }
    }

    /// The Newton step of the forward methods: the AM's gradient and Hessian with respect to the
    /// current pixels `values`, through the pixel Jacobian `jac`; returns the similarity before
    /// the step.
    pub fn forward_step(&mut self, update: Update) -> Result<f64, LossReason> {
        let f = self
            .am
            .gradient(Wrt::Current, &self.work.values, &mut self.work.grad);
        self.forward_step_from_gradient(update).map(|_| f)
    }

    /// [`Context::forward_step`] once the AM's gradient with respect to the current pixels is
    /// in `self.work.grad` (for `self.work.values`): the Hessian, the Newton system, the update.
    pub fn forward_step_from_gradient(&mut self, update: Update) -> Result<(), LossReason> {
        let mut h = [0.0; MAX_DOF * MAX_DOF];
        self.am.hessian(
            Wrt::Current,
            self.hessian,
            &self.work.values,
            &self.work.jac,
            self.dof,
            &mut h,
        );
        let jac = std::mem::take(&mut self.work.jac);
        let r = self.step(&jac, &h, update);
        self.work.jac = jac;
        r
    }

    /// Solves the Newton system `H dp = -J^T g` (with `g` the AM gradient in `self.work.grad`) and
    /// applies the step to the parameters.
    pub fn step(
        &mut self,
        jac: &[f32],
        h: &[f64; MAX_DOF * MAX_DOF],
        update: Update,
    ) -> Result<(), LossReason> {
        let mut g = [0.0f64; MAX_DOF];
        jt_times(jac, &self.work.grad, self.dof, &mut g);
        self.solve_step(&g, h, update)
    }

    /// Solves the Newton system `H dp = -g` (damped with `lm:`) and applies the step.
    pub fn solve_step(
        &mut self,
        g: &[f64; MAX_DOF],
        h: &[f64; MAX_DOF * MAX_DOF],
        update: Update,
    ) -> Result<(), LossReason> {
        let dp = if self.damping > 0.0 {
            // Levenberg-Marquardt: the diagonal scaled by 1 + lambda (a shorter, more
            // gradient-like step).
            let mut hd = *h;
            for i in 0..self.dof {
                hd[i * self.dof + i] *= 1.0 + self.damping;
            }
            self.solver.step(&hd, g, self.dof)
        } else {
            self.solver.step(h, g, self.dof)
        }
        .ok_or(LossReason::Singular)?;
        self.apply(&dp, update)
    }

    /// Applies the step `dp` to the parameters.
    pub fn apply(&mut self, dp: &Params, update: Update) -> Result<(), LossReason> {
        let dp = *dp;
        let p = self.params;
        let next = match update {
            Update::Additive => Some(self.ssm.additive_update(&p, &dp)),
            Update::Compose => self.ssm.compose(&p, &dp),
            Update::ComposeInverse => self
                .ssm
                .invert(&dp)
                .and_then(|inv| self.ssm.compose(&p, &inv)),
        }
        .ok_or(LossReason::Singular)?;
        if !next.iter().all(|v| v.is_finite()) {
            return Err(LossReason::NonFinite);
        }
        self.params = next;
        self.last_step = Some((dp, update));
        Ok(())
    }

    /// Sets up the grid and the normaliser for the initial quad `q` (image coordinates), and
    /// resets the parameters to the identity.
    pub fn set_region(&mut self, q: &Quad, res: usize, layout: GridLayout) -> crate::Result<()> {
        q.validate()?;
        self.norm = Normaliser::of_quad(q);
        let nq = q.map(|p| self.norm.to_norm(p));
        let h = crate::geometry::homography_between(&Quad::unit_square(), &nq)
            .ok_or_else(|| crate::Error::InvalidRegion(format!("{q} has no homography")))?;
        // Centres: -0.5 + (k + 1/2) / res; border: -0.5 + k / (res - 1), corners included.
        let (step, offset) = match layout {
            GridLayout::Border if res > 1 => (1.0 / (res - 1) as f64, 0.0),
            _ => (1.0 / res as f64, 0.5),
        };
        for r in 0..res {
            for c in 0..res {
                let u = Point::new(
                    -0.5 + (c as f64 + offset) * step,
                    -0.5 + (r as f64 + offset) * step,
                );
                let p = crate::geometry::apply_homography(&h, u);
                self.grid_x[r * res + c] = p.x as f32;
                self.grid_y[r * res + c] = p.y as f32;
                self.grid_u[r * res + c] = u.x as f32;
                self.grid_v[r * res + c] = u.y as f32;
            }
        }
        self.unit = h;
        self.template_corners = nq;
        self.params = self.ssm.identity();
        let (gx, gy) = (self.grid_x.clone(), self.grid_y.clone());
        self.ssm.jacobian(&self.params, &gx, &gy, &mut self.dwdp0);
        let n = gx.len();
        for (r, z) in self.dwdp0_zero.iter_mut().enumerate() {
            *z = r < 2 * self.dof && self.dwdp0[r * n..(r + 1) * n].iter().all(|&v| v == 0.0);
        }
        self.moments = if self.am.hessian_is_minus_jtj() || self.am.hessian_from_jtj() {
            GridMoments::new(&h, res, layout, &self.dwdp0, self.dof)
        } else {
            None
        };
        let kept = if self.moments.is_some() { n } else { 0 };
        self.template_gu.resize(kept, 0.0);
        self.template_gv.resize(kept, 0.0);
        Ok(())
    }

    /// Samples the template (values and normalised gradients) from `img` at the grid under the
    /// current parameters and gives it to the AM.
    pub fn sample_template(&mut self, img: &ImageView) {
        let p = self.params;
        self.sample_gradients_at(img, &p);
        if self.moments.is_some() {
            let m = self.unit_matrix(&p);
            unit_gradient_into(
                &m,
                (&self.grid_u, &self.grid_v),
                (&self.work.px, &self.work.py),
                (&self.work.gx, &self.work.gy),
                (&mut self.template_gu, &mut self.template_gv),
            );
        }
        self.warped_gradient(&p);
        self.template.copy_from_slice(&self.work.values);
        self.template_gx.copy_from_slice(&self.work.gx);
        self.template_gy.copy_from_slice(&self.work.gy);
        self.am.set_template(&self.template);
    }
}

/// The gradient `(gx, gy)` sampled in pixels at `(px, py)`, the points `(us, vs)` under the
/// homography `m`, turned into the gradient with respect to `(u, v)` (chain rule through the
/// homography's point Jacobian), into `out`.
fn unit_gradient_into(
    m: &Matrix3<f32>,
    (us, vs): (&[f32], &[f32]),
    (px, py): (&[f32], &[f32]),
    (gx, gy): (&[f32], &[f32]),
    (ox, oy): (&mut [f32], &mut [f32]),
) {
    ox.copy_from_slice(gx);
    oy.copy_from_slice(gy);
    unit_gradient_in_place(m, (us, vs), (px, py), (ox, oy), None);
}

/// [`unit_gradient_into`] in place (for any points `(us, vs)` that `m` takes to the pixels
/// `(px, py)`: the unit square's, or the normalised ones with the pixel matrix), then, with
/// `mean`, the mean with that gradient `(tx, ty)`.
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
mod grid_tests {
    use super::*;

    #[test]
    fn the_grid_lies_inside_or_spans_the_target() {
        let q = Quad::from_rect(10.0, 20.0, 40.0, 30.0);
        for layout in [GridLayout::Centres, GridLayout::Border] {
            let mut ctx = Context::new(
                crate::ssm::build("homography").unwrap(),
                crate::am::build("ssd").unwrap(),
                HessianKind::Default,
                5,
            );
            ctx.set_region(&q, 5, layout).unwrap();
            let m = ctx.pixel_matrix(&ctx.params);
            let px = |i: usize| {
                crate::geometry::apply_homography(
                    &m,
                    Point::new(ctx.grid_x[i] as f64, ctx.grid_y[i] as f64),
                )
            };
            let (first, last) = (px(0), px(24));
            match layout {
                // Cell centres: half a cell (4 x 3 px) inside the corners.
                GridLayout::Centres => {
                    assert!(first.dist(Point::new(14.0, 23.0)) < 1e-4, "{first:?}");
                    assert!(last.dist(Point::new(46.0, 47.0)) < 1e-4, "{last:?}");
                }
                GridLayout::Border => {
                    assert!(first.dist(q.0[0]) < 1e-4, "{first:?}");
                    assert!(last.dist(q.0[2]) < 1e-4, "{last:?}");
                }
            }
        }
    }
}
