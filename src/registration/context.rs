//! What a search method works on: the [`Problem`] (models, grid, template), the [`State`]
//! (parameters, last step) and the [`Workspace`] (buffers, with their own cache), together.
//! [`Context::similarity_at`] is the equation's objective evaluated at a warp. The Newton steps
//! a method takes on it are the method's own ([`crate::sm`]).

use super::workspace::Again;
use super::{Problem, State, Update, Workspace};
use crate::am::{Am, HessianKind};
use crate::geometry::Quad;
use crate::imaging::ImageView;
use crate::spec::GridLayout;
use crate::ssm::{Params, Ssm};
use crate::status::LossReason;
use nalgebra::Matrix3;

/// See the module's documentation.
#[derive(Debug)]
pub struct Context {
    problem: Problem,
    state: State,
    work: Workspace,
}

impl Context {
    /// A context for the given models with an `res x res` grid (buffers allocated here).
    pub fn new(ssm: Box<dyn Ssm>, am: Box<dyn Am>, hessian: HessianKind, res: usize) -> Self {
        let dof = ssm.dof();
        Context {
            problem: Problem::new(ssm, am, hessian, res),
            state: State::default(),
            work: Workspace::new(res * res, dof),
        }
    }

    pub fn problem(&self) -> &Problem {
        &self.problem
    }
    /// The problem, for the AM's scratch and its grid moments' sums.
    pub fn problem_mut(&mut self) -> &mut Problem {
        &mut self.problem
    }
    pub fn state(&self) -> &State {
        &self.state
    }
    pub fn state_mut(&mut self) -> &mut State {
        &mut self.state
    }
    pub fn work(&self) -> &Workspace {
        &self.work
    }
    pub fn work_mut(&mut self) -> &mut Workspace {
        &mut self.work
    }
    /// The three parts at once.
    pub fn parts_mut(&mut self) -> (&mut Problem, &mut State, &mut Workspace) {
        (&mut self.problem, &mut self.state, &mut self.work)
    }

    /// The current parameters.
    pub fn params(&self) -> Params {
        self.state.params()
    }
    /// Moves to `p`.
    pub fn set_params(&mut self, p: Params) {
        self.state.set_params(p);
    }
    /// Applies the step `dp` to the parameters.
    pub fn apply(&mut self, dp: &Params, update: Update) -> Result<(), LossReason> {
        self.state.apply(self.problem.ssm(), dp, update)
    }
    pub fn ssm(&self) -> &dyn Ssm {
        self.problem.ssm()
    }
    pub fn am(&self) -> &dyn Am {
        self.problem.am()
    }
    /// The SSM's parameters.
    pub fn dof(&self) -> usize {
        self.problem.dof()
    }
    /// Number of sampled points.
    pub fn len(&self) -> usize {
        self.problem.len()
    }
    /// Whether the grid is empty.
    pub fn is_empty(&self) -> bool {
        self.problem.is_empty()
    }
    /// The matrix taking normalised template points to frame pixels under `p`.
    pub fn pixel_matrix(&self, p: &Params) -> Matrix3<f64> {
        self.problem.pixel_matrix(p)
    }
    /// The corners under `p`, in frame pixels.
    pub fn corners(&self, p: &Params) -> Quad {
        self.problem.corners(p)
    }
    /// The sampled intensities.
    pub fn values(&self) -> &[f32] {
        self.work.values()
    }

    /// Sets up the grid and the normaliser for the initial quad `q` (image coordinates), and
    /// resets the parameters to the identity.
    pub fn set_region(&mut self, q: &Quad, res: usize, layout: GridLayout) -> crate::Result<()> {
        let identity = self.problem.set_region(q, res, layout)?;
        let n = self.problem.len();
        self.work.resize(n, n, self.problem.dof());
        self.state = State::default();
        self.state.set_params(identity);
        Ok(())
    }

    /// Samples the template (values and normalised gradients) from `img` at the grid under the
    /// current parameters and gives it to the AM.
    pub fn sample_template(&mut self, img: &ImageView) {
        let p = self.params();
        self.work.sample_gradients_at(&self.problem, img, &p);
        if self.problem.moments().is_some() {
            let m = self.unit_matrix(&p);
            self.problem.set_template_unit_gradient(&m, &self.work);
        }
        self.warped_gradient(&p);
        let (gx, gy) = self.work.gradients();
        let values = self.work.values();
        self.problem.set_template(values, (gx, gy));
        // Selective pixel integration: the searches read the points chosen on this template.
        if let Some(kept) = self.problem.selected_points() {
            let whole = self.problem.len();
            self.problem.select(&kept);
            self.work.resize(kept.len(), whole, self.problem.dof());
        }
    }

    /// Samples `channels` (1, 3 for colour, 4 for the descriptor fields) from the next region on
    /// ([`Problem::set_channels`]).
    pub fn set_channels(&mut self, channels: usize) {
        self.problem.set_channels(channels);
    }

    /// Which points the searches read from the next template on ([`super::spi`]).
    pub fn set_selection(&mut self, selection: super::spi::Selection) {
        self.problem.set_selection(selection);
    }

    /// The weight of a non-rigid SSM's smoothness prior (tracker parameter `smoothness`).
    pub fn set_smoothness(&mut self, smoothness: f64) {
        self.problem.set_smoothness(smoothness);
    }

    /// The patch of `img` under `p` on the whole grid (the confidences', the inspector's:
    /// also when the searches read part of it, [`super::spi`]), sampled anew.
    pub fn whole_sample_at(&mut self, img: &ImageView, p: &Params) -> &[f32] {
        self.work.whole_patch(&self.problem, img, p, Again::Always)
    }

    /// [`Context::whole_sample_at`], sampled only if not held already.
    pub fn whole_patch_at(&mut self, img: &ImageView, p: &Params) -> &[f32] {
        self.work.whole_patch(&self.problem, img, p, Again::Unless)
    }

    /// [`Context::whole_sample_at`] where the search's patch was just sampled at `p` (without
    /// a selection, that patch).
    pub fn whole_held_at(&mut self, img: &ImageView, p: &Params) -> &[f32] {
        self.work.whole_patch(&self.problem, img, p, Again::Held)
    }

    /// The last patch of the whole grid (without a selection, the sampled values).
    pub fn whole_values(&self) -> &[f32] {
        self.work.whole_values(&self.problem)
    }

    /// The patch of `img` under `p`: the grid warped by `p` and the frame's values sampled
    /// there.
    pub fn sample_at(&mut self, img: &ImageView, p: &Params) {
        self.work.sample_at(&self.problem, img, p);
    }
    /// The patch of `img` under `p`, sampled only if the workspace does not hold it already.
    pub fn patch_at(&mut self, img: &ImageView, p: &Params) {
        self.work.patch_at(&self.problem, img, p);
    }
    /// [`Context::sample_at`] with the frame's gradients (frame pixels) too.
    pub fn sample_gradients_at(&mut self, img: &ImageView, p: &Params) {
        self.work.sample_gradients_at(&self.problem, img, p);
    }
    /// Warps the grid by `p` into frame pixels.
    pub fn warp_grid(&mut self, p: &Params) {
        self.work.warp_grid(&self.problem, p);
    }

    /// The objective of `p_t = argmax_p f(I*, I_t(w(x, p)))` at `p`: the grid warped by `p`,
    /// the frame sampled there, and the AM's similarity to the template.
    pub fn similarity_at(&mut self, img: &ImageView, p: &Params) -> f64 {
        self.sample_at(img, p);
        self.problem.am_mut().similarity(self.work.values())
    }

    /// The AM's gradient with respect to the pixels (into the workspace's `grad`), `wrt` the
    /// sampled patch or the template taking its place; returns the similarity.
    pub fn am_gradient(&mut self, wrt: crate::am::Wrt) -> f64 {
        let (values, grad) = self.work.values_and_grad_mut();
        self.problem.am_mut().gradient(wrt, values, grad)
    }

    /// The AM's model learns the patch of `img` at the current parameters (an intensity map
    /// that follows the light).
    pub fn learn_model(&mut self, img: &ImageView) {
        let p = self.params();
        self.sample_at(img, &p);
        self.problem.am_mut().update_model(self.work.values());
    }

    /// The AM learns the target's appearance from the patch of `img` at `p` ([`Am::learn`]; the
    /// patch sampled there is reused).
    ///
    /// [`Am::learn`]: crate::am::Am::learn
    pub fn learn_appearance(&mut self, img: &ImageView, p: &Params) {
        self.patch_at(img, p);
        self.problem.am_mut().learn(self.work.values());
    }

    /// Turns the sampled frame gradients into the gradient of the warped frame
    /// `I_t(pixel(w(x, p)))` with respect to the normalised template point `x` (chain rule
    /// through the warp's point Jacobian), in place.
    pub fn warped_gradient(&mut self, p: &Params) {
        self.warped_gradient_with(p, false);
    }

    /// [`Context::warped_gradient`], then (in the same pass) its mean with the template's
    /// gradient, `(g + g*) / 2`: ESM's gradient.
    pub fn warped_gradient_mean(&mut self, p: &Params) {
        self.warped_gradient_with(p, true);
    }

    fn warped_gradient_with(&mut self, p: &Params, mean: bool) {
        if !self.problem.ssm().projective() {
            let problem = &self.problem;
            let template = mean.then(|| problem.template_gradient());
            let scale = problem.norm().scale as f32;
            self.work
                .chain_point_jacobians(|i| problem.point_jacobian(p, i), scale, template);
            return;
        }
        let m = self.pixel_matrix(p).cast::<f32>();
        let template = mean.then(|| self.problem.template_gradient());
        self.work.chain_gradients(&m, self.problem.grid(), template);
    }

    /// The pixel matrix times the grid's homography: the unit square's coordinates to pixels.
    fn unit_matrix(&self, p: &Params) -> Matrix3<f32> {
        (self.pixel_matrix(p) * self.problem.unit()).cast::<f32>()
    }

    /// Like [`Context::warped_gradient`], with respect to the unit square's coordinates
    /// instead of the normalised ones (for the grid moments).
    pub fn unit_gradient(&mut self, p: &Params) {
        self.unit_gradient_with(p, false);
    }

    /// [`Context::unit_gradient`], then its mean with the template's (ESM's gradient), in one
    /// pass.
    pub fn unit_gradient_mean(&mut self, p: &Params) {
        self.unit_gradient_with(p, true);
    }

    fn unit_gradient_with(&mut self, p: &Params, mean: bool) {
        let m = self.unit_matrix(p);
        let template = mean.then(|| self.problem.template_unit_gradient());
        self.work
            .chain_gradients(&m, self.problem.unit_grid(), template);
    }
}

#[cfg(test)]
mod grid_tests {
    use super::*;
    use crate::geometry::Point;

    /// A colour grid is the `res x res` points once per channel, each part sampled from its
    /// plane; the channel of most contrast is the one whose template varies most.
    #[test]
    fn a_colour_grid_samples_each_channel_and_knows_its_strongest() {
        let (w, h) = (40, 30);
        let plane = |amp: f32| -> Vec<f32> {
            (0..w * h)
                .map(|i| 100.0 + amp * (((i % w) as f32) * 0.7).sin())
                .collect()
        };
        let (r, g, b) = (plane(5.0), plane(1.0), plane(30.0));
        let view = ImageView::new(&r, w, h, 0, 0).with_planes(&g, &b);
        let mut ctx = Context::new(
            crate::ssm::build("homography").unwrap(),
            crate::am::build("zncc").unwrap(),
            HessianKind::Default,
            6,
        );
        ctx.set_channels(3);
        ctx.set_region(
            &Quad::from_rect(8.0, 6.0, 20.0, 15.0),
            6,
            GridLayout::Centres,
        )
        .unwrap();
        assert_eq!((ctx.len(), ctx.problem().channels()), (108, 3));
        let (gx, gy) = ctx.problem().grid();
        assert_eq!((&gx[..36], &gy[..36]), (&gx[72..], &gy[72..]));
        let (gx, gy) = (gx.to_vec(), gy.to_vec());
        ctx.sample_template(&view);
        let t = ctx.problem().template();
        for (c, data) in [&r, &g, &b].into_iter().enumerate() {
            let mut one = vec![0f32; 36];
            let m = ctx.pixel_matrix(&ctx.params());
            let (mut px, mut py) = (vec![0f32; 36], vec![0f32; 36]);
            super::super::workspace::warp_points(&m, &gx[..36], &gy[..36], &mut px, &mut py);
            crate::imaging::sample_values(&ImageView::new(data, w, h, 0, 0), &px, &py, &mut one);
            assert_eq!(&t[c * 36..(c + 1) * 36], &one[..], "channel {c}");
        }
        assert_eq!(ctx.problem().strongest_channel(), 2);
    }

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
            let m = ctx.pixel_matrix(&ctx.params());
            let (gx, gy) = ctx.problem().grid();
            let px = |i: usize| {
                crate::geometry::apply_homography(&m, Point::new(gx[i] as f64, gy[i] as f64))
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
