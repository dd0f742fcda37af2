//! The problem one registration tracker solves at one level, `argmax_p f(I*, I_t(w(x, p)))`:
//! the models (the SSM's warp `w`, the AM's similarity `f`), the sampling grid `x` and the
//! template `I*`. It is set up when the tracker is initialised ([`Problem::set_region`], then
//! [`super::Context::sample_template`]) and only read while frames are searched, but for the
//! AM's own scratch and the light model it may learn ([`Problem::am_mut`]) and the grid
//! moments' sums ([`Problem::moments_mut`]).

use super::Workspace;
use super::moments::GridMoments;
use super::spi::Selection;
use super::workspace::warp_points;
use crate::am::{Am, HessianKind};
use crate::geometry::{Normaliser, Point, Quad, apply_homography};
use crate::linalg::MAX_DOF;
use crate::spec::GridLayout;
use crate::ssm::{Params, Ssm};
use nalgebra::Matrix3;

/// See the module's documentation.
#[derive(Debug)]
pub struct Problem {
    ssm: Box<dyn Ssm>,
    am: Box<dyn Am>,
    /// The Hessian kind to use (resolved: never [`HessianKind::Default`]).
    hessian: HessianKind,
    dof: usize,
    /// Image <-> normalised frame.
    norm: Normaliser,
    /// The sampling grid, in normalised coordinates (see [`GridLayout`]).
    grid_x: Vec<f32>,
    grid_y: Vec<f32>,
    /// The grid in the unit square's coordinates, where it is regular, and the homography `G`
    /// from them to the normalised ones (`grid = G(grid_u, grid_v)`).
    grid_u: Vec<f32>,
    grid_v: Vec<f32>,
    unit: Matrix3<f64>,
    /// The initial quad in normalised coordinates.
    template_corners: Quad,
    /// Template intensities `I*` and their gradient in normalised coordinates.
    template: Vec<f32>,
    template_gx: Vec<f32>,
    template_gy: Vec<f32>,
    /// The template's gradient with respect to the unit square's coordinates (kept only with
    /// the moments).
    template_gu: Vec<f32>,
    template_gv: Vec<f32>,
    /// `dw/dp` at the identity on the grid (layout of [`Ssm::jacobian`]).
    dwdp0: Vec<f32>,
    /// Which rows of `dwdp0` (`2 k` for `dw_x/dp_k`, `2 k + 1` for `dw_y/dp_k`) are zero on the
    /// whole grid (half of them for the affine and projective warps): projections skip them.
    dwdp0_zero: [bool; 2 * MAX_DOF],
    /// For a non-rigid SSM, the gradients of its basis functions on the grid
    /// ([`Ssm::basis_gradients`], `dof` rows): its point Jacobians at any `p`.
    basis_grad: Vec<f32>,
    /// The weight of a non-rigid SSM's smoothness prior (tracker parameter `smoothness`; -1:
    /// the model's own).
    smoothness: f64,
    /// The forward steps' Newton system from the gradient's moments, for the AMs whose Hessian
    /// is `-J^T J` or made from `J^T J` on the SSMs of six or more parameters
    /// ([`super::moments`]).
    moments: Option<GridMoments>,
    /// Which points the searches read ([`super::spi`]).
    selection: Selection,
    /// The channels sampled (1, 3 for colour, 4 for the descriptor fields): the grid is the `res x res` points once per
    /// channel, channel after channel, each part read from its plane of the frame
    /// ([`crate::imaging::ImageView::with_planes`]).
    channels: usize,
    /// The whole grid and template when the searches read only part of it (the arrays above
    /// then hold that part).
    whole: Option<WholeGrid>,
}

/// The whole grid (normalised coordinates) and its template, kept beside a selection.
#[derive(Debug, Clone)]
struct WholeGrid {
    grid_x: Vec<f32>,
    grid_y: Vec<f32>,
    template: Vec<f32>,
}

impl Problem {
    /// The problem of the given models on an `res x res` grid (buffers allocated here).
    pub fn new(ssm: Box<dyn Ssm>, am: Box<dyn Am>, hessian: HessianKind, res: usize) -> Self {
        let dof = ssm.dof();
        let hessian = hessian.or(am.default_hessian());
        let n = res * res;
        let z = |len: usize| vec![0.0f32; len];
        Problem {
            ssm,
            am,
            hessian,
            dof,
            norm: Normaliser {
                cx: 0.0,
                cy: 0.0,
                scale: 1.0,
            },
            grid_x: z(n),
            grid_y: z(n),
            grid_u: z(n),
            grid_v: z(n),
            unit: Matrix3::identity(),
            template_corners: Quad::unit_square(),
            template: z(n),
            template_gx: z(n),
            template_gy: z(n),
            template_gu: Vec::new(),
            template_gv: Vec::new(),
            dwdp0: z(2 * n * dof),
            dwdp0_zero: [false; 2 * MAX_DOF],
            basis_grad: Vec::new(),
            smoothness: -1.0,
            moments: None,
            selection: Selection::default(),
            channels: 1,
            whole: None,
        }
    }

    /// Samples `channels` (1, 3 for colour, 4 for the descriptor fields) from the next region on ([`Problem::set_region`]).
    pub fn set_channels(&mut self, channels: usize) {
        self.channels = channels.max(1);
    }

    /// The channels sampled: the grid is [`Problem::len`] / `channels` points once per channel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The channel whose part of the whole template varies most (0 for grey): what a judge
    /// that reads one channel reads (the periodic check, the redetection's ranking).
    pub fn strongest_channel(&self) -> usize {
        let t = self.whole_template();
        let m = t.len() / self.channels.max(1);
        let variance = |part: &[f32]| {
            let n = part.len().max(1) as f64;
            let mean = part.iter().map(|&v| v as f64).sum::<f64>() / n;
            part.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n
        };
        (0..self.channels)
            .map(|c| (c, variance(&t[c * m..(c + 1) * m])))
            .fold((0, f64::NEG_INFINITY), |best, (c, v)| {
                if v > best.1 { (c, v) } else { best }
            })
            .0
    }

    /// Which points the searches read from the next template on ([`super::spi`]).
    pub fn set_selection(&mut self, selection: Selection) {
        self.selection = selection;
    }

    /// The weight of a non-rigid SSM's smoothness prior (tracker parameter `smoothness`).
    pub fn set_smoothness(&mut self, smoothness: f64) {
        self.smoothness = smoothness;
    }

    /// A non-rigid SSM's smoothness prior, when it has a weight: the weight and `R`
    /// ([`Ssm::smoothness`]).
    pub fn smoothness(&self) -> Option<(f64, &[f64])> {
        let r = self.ssm.smoothness()?;
        let weight = if self.smoothness < 0.0 {
            self.ssm.default_smoothness()
        } else {
            self.smoothness
        };
        (weight > 0.0).then_some((weight, r))
    }

    /// Keeps only the points `kept` (ascending indices of the whole grid) for the searches:
    /// the grid, the template, its gradients and `dw/dp` at the identity; the AM gets the
    /// selected template. The whole grid and template are kept for [`Problem::whole_grid`].
    /// The grid moments are left out (they sum over the whole grid's rows).
    pub(super) fn select(&mut self, kept: &[usize]) {
        let n = self.grid_x.len();
        self.whole = Some(WholeGrid {
            grid_x: self.grid_x.clone(),
            grid_y: self.grid_y.clone(),
            template: self.template.clone(),
        });
        for v in self.per_point() {
            for (k, &i) in kept.iter().enumerate() {
                v[k] = v[i];
            }
            v.truncate(kept.len());
        }
        let rows = 2 * self.dof;
        let m = kept.len();
        for r in 0..rows {
            for (k, &i) in kept.iter().enumerate() {
                self.dwdp0[r * m + k] = self.dwdp0[r * n + i];
            }
        }
        self.dwdp0.truncate(rows * m);
        if !self.basis_grad.is_empty() {
            for r in 0..self.dof {
                for (k, &i) in kept.iter().enumerate() {
                    self.basis_grad[r * m + k] = self.basis_grad[r * n + i];
                }
            }
            self.basis_grad.truncate(self.dof * m);
        }
        self.set_zero_rows();
        self.moments = None;
        self.template_gu.clear();
        self.template_gv.clear();
        self.am.set_template(&self.template);
        self.give_motion();
    }

    /// The arrays with a value per grid point (what a selection keeps part of).
    fn per_point(&mut self) -> [&mut Vec<f32>; 7] {
        [
            &mut self.grid_x,
            &mut self.grid_y,
            &mut self.grid_u,
            &mut self.grid_v,
            &mut self.template,
            &mut self.template_gx,
            &mut self.template_gy,
        ]
    }

    /// The selection the problem would make of its whole template, if any ([`super::spi`]).
    pub(super) fn selected_points(&self) -> Option<Vec<usize>> {
        if self.selection.is_whole() || self.whole.is_some() {
            return None;
        }
        let c = self.channels.max(1);
        if c == 1 {
            return self.selection.points(
                (&self.grid_u, &self.grid_v),
                (&self.template_gx, &self.template_gy),
            );
        }
        // Several channels (colour, descriptor fields): the same points of each channel's
        // part, chosen on a point's gradient over all of them, so that every part keeps as many
        // points and the sampler's equal parts are the channels.
        let m = self.grid_u.len() / c;
        let (gx, gy) = (&self.template_gx, &self.template_gy);
        let energy: Vec<f32> = (0..m)
            .map(|i| {
                let e: f32 = (0..c)
                    .map(|k| gx[k * m + i].powi(2) + gy[k * m + i].powi(2))
                    .sum();
                e.sqrt()
            })
            .collect();
        let zero = vec![0.0; m];
        let kept = self
            .selection
            .points((&self.grid_u[..m], &self.grid_v[..m]), (&energy, &zero))?;
        Some(
            (0..c)
                .flat_map(|k| kept.iter().map(move |&i| k * m + i))
                .collect(),
        )
    }

    /// Which rows of `dw/dp` at the identity are zero on the whole grid.
    fn set_zero_rows(&mut self) {
        let n = self.grid_x.len();
        for (r, z) in self.dwdp0_zero.iter_mut().enumerate() {
            *z = r < 2 * self.dof && self.dwdp0[r * n..(r + 1) * n].iter().all(|&v| v == 0.0);
        }
    }

    /// Sets up the grid and the normaliser for the initial quad `q` (image coordinates); returns
    /// the SSM's identity, where the template is.
    pub fn set_region(
        &mut self,
        q: &Quad,
        res: usize,
        layout: GridLayout,
    ) -> crate::Result<Params> {
        q.validate()?;
        // The whole grid again (a selection is made on each template), once per channel.
        let n = res * res * self.channels;
        self.whole = None;
        for v in self.per_point() {
            v.resize(n, 0.0);
        }
        self.dwdp0.resize(2 * n * self.dof, 0.0);
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
                let p = apply_homography(&h, u);
                self.grid_x[r * res + c] = p.x as f32;
                self.grid_y[r * res + c] = p.y as f32;
                self.grid_u[r * res + c] = u.x as f32;
                self.grid_v[r * res + c] = u.y as f32;
            }
        }
        // The other channels' parts: the same points.
        let one = res * res;
        for v in [
            &mut self.grid_x,
            &mut self.grid_y,
            &mut self.grid_u,
            &mut self.grid_v,
        ] {
            for c in 1..self.channels {
                v.copy_within(0..one, c * one);
            }
        }
        self.unit = h;
        self.template_corners = nq;
        self.ssm.set_base(&nq.0);
        let identity = self.ssm.identity();
        self.ssm
            .jacobian(&identity, &self.grid_x, &self.grid_y, &mut self.dwdp0);
        self.basis_grad.clear();
        if !self.ssm.projective() {
            self.basis_grad.resize(self.dof * n, 0.0);
            self.ssm
                .basis_gradients(&self.grid_x, &self.grid_y, &mut self.basis_grad);
        }
        self.set_zero_rows();
        // The moments of one `res x res` grid (a colour grid's parts are summed), from the
        // first part's rows of `dw/dp`.
        let moments = self.am.hessian_is_minus_jtj() || self.am.hessian_from_jtj();
        self.moments = if !moments {
            None
        } else if self.channels == 1 {
            GridMoments::new(&h, res, layout, &self.dwdp0, self.dof)
        } else {
            let first: Vec<f32> = self
                .dwdp0
                .chunks_exact(n)
                .flat_map(|row| &row[..one])
                .copied()
                .collect();
            GridMoments::new(&h, res, layout, &first, self.dof)
        };
        let kept = if self.moments.is_some() { n } else { 0 };
        self.template_gu.resize(kept, 0.0);
        self.template_gv.resize(kept, 0.0);
        Ok(identity)
    }

    /// Keeps `values` as the template, with its gradient in normalised coordinates `(gx, gy)`,
    /// and gives it to the AM. The gradient in the unit square's coordinates is set apart
    /// ([`Problem::set_template_unit_gradient`]).
    pub(super) fn set_template(&mut self, values: &[f32], (gx, gy): (&[f32], &[f32])) {
        self.template.copy_from_slice(values);
        self.template_gx.copy_from_slice(gx);
        self.template_gy.copy_from_slice(gy);
        self.am.set_template(&self.template);
        self.give_motion();
    }

    /// Gives a model that learns the template's pixel Jacobian at the identity
    /// ([`Am::set_motion`]).
    fn give_motion(&mut self) {
        if !self.am.learns() {
            return;
        }
        let jac = self.template_motion();
        self.am.set_motion(&jac, self.dof);
    }

    /// The template's pixel Jacobian at the identity, as [`Am::set_motion`] takes it (at the
    /// points the searches read; `dof` rows of one value a point): what a model that learns
    /// keeps out of what it learns. Search methods that score with copies of the model on part
    /// of the grid give their copies its rows at their points.
    pub fn template_motion(&self) -> Vec<f32> {
        let mut jac = vec![0.0f32; self.template.len() * self.dof];
        crate::linalg::products::project_skipping(
            &self.template_gx,
            &self.template_gy,
            &self.dwdp0,
            &self.dwdp0_zero,
            self.dof,
            &mut jac,
        );
        jac
    }

    /// Keeps the gradient the workspace sampled as the template's in the unit square's
    /// coordinates (`m`: those coordinates to pixels); only with the moments.
    pub(super) fn set_template_unit_gradient(&mut self, m: &Matrix3<f32>, work: &Workspace) {
        work.chain_gradients_into(
            m,
            (&self.grid_u, &self.grid_v),
            (&mut self.template_gu, &mut self.template_gv),
        );
    }

    /// The template's gradients in both coordinates, set by a test (the normalised ones and the
    /// unit square's).
    #[cfg(test)]
    pub(crate) fn template_gradients_mut(&mut self) -> [&mut [f32]; 4] {
        [
            &mut self.template_gx,
            &mut self.template_gy,
            &mut self.template_gu,
            &mut self.template_gv,
        ]
    }

    pub fn ssm(&self) -> &dyn Ssm {
        &*self.ssm
    }
    pub fn am(&self) -> &dyn Am {
        &*self.am
    }
    /// The AM, for what changes in it: its scratch, and the model it learns
    /// ([`Am::update_model`]).
    pub fn am_mut(&mut self) -> &mut dyn Am {
        &mut *self.am
    }
    /// The Hessian kind of the Newton steps (resolved: never [`HessianKind::Default`]).
    pub fn hessian(&self) -> HessianKind {
        self.hessian
    }
    /// The SSM's parameters.
    pub fn dof(&self) -> usize {
        self.dof
    }
    /// Number of sampled points.
    pub fn len(&self) -> usize {
        self.grid_x.len()
    }
    /// Whether the grid is empty.
    pub fn is_empty(&self) -> bool {
        self.grid_x.is_empty()
    }
    /// Image <-> normalised frame.
    pub fn norm(&self) -> &Normaliser {
        &self.norm
    }
    /// The sampling grid, in normalised coordinates.
    pub fn grid(&self) -> (&[f32], &[f32]) {
        (&self.grid_x, &self.grid_y)
    }
    /// The grid in the unit square's coordinates.
    pub fn unit_grid(&self) -> (&[f32], &[f32]) {
        (&self.grid_u, &self.grid_v)
    }
    /// The homography from the unit square's coordinates to the normalised ones.
    pub fn unit(&self) -> &Matrix3<f64> {
        &self.unit
    }
    /// The initial quad in normalised coordinates.
    pub fn template_corners(&self) -> &Quad {
        &self.template_corners
    }
    /// The template's intensities (at the points the searches read).
    pub fn template(&self) -> &[f32] {
        &self.template
    }
    /// The whole template, `res x res` once per channel (also when the searches read part of
    /// it).
    pub fn whole_template(&self) -> &[f32] {
        self.whole.as_ref().map_or(&self.template, |w| &w.template)
    }
    /// The whole sampling grid, `res x res` in normalised coordinates once per channel (also
    /// when the searches read part of it: [`Problem::grid`] is then that part).
    pub fn whole_grid(&self) -> (&[f32], &[f32]) {
        self.whole
            .as_ref()
            .map_or((&self.grid_x, &self.grid_y), |w| (&w.grid_x, &w.grid_y))
    }
    /// Whether the searches read only part of the grid ([`super::spi`]).
    pub fn is_selective(&self) -> bool {
        self.whole.is_some()
    }
    /// The template's gradient in normalised coordinates.
    pub fn template_gradient(&self) -> (&[f32], &[f32]) {
        (&self.template_gx, &self.template_gy)
    }
    /// The template's gradient in the unit square's coordinates (empty without the moments).
    pub fn template_unit_gradient(&self) -> (&[f32], &[f32]) {
        (&self.template_gu, &self.template_gv)
    }
    /// `dw/dp` at the identity on the grid, and which of its rows are zero on the whole grid.
    pub fn dwdp0(&self) -> (&[f32], &[bool; 2 * MAX_DOF]) {
        (&self.dwdp0, &self.dwdp0_zero)
    }
    /// The grid moments, where the region has them.
    pub fn moments(&self) -> Option<&GridMoments> {
        self.moments.as_ref()
    }
    /// The grid moments, for their sums.
    pub fn moments_mut(&mut self) -> Option<&mut GridMoments> {
        self.moments.as_mut()
    }
    /// The AM and the template, at once (for the AM's derivatives at the template).
    pub fn am_and_template_mut(&mut self) -> (&mut dyn Am, &[f32]) {
        (&mut *self.am, &self.template)
    }
    /// The AM and the grid moments, at once.
    pub fn am_and_moments_mut(&mut self) -> (&mut dyn Am, Option<&mut GridMoments>) {
        (&mut *self.am, self.moments.as_mut())
    }
    /// The moments and what their sums read, at once.
    pub fn moments_and_unit_gradient(&mut self) -> (Option<&mut GridMoments>, (&[f32], &[f32])) {
        (
            self.moments.as_mut(),
            (&self.template_gu, &self.template_gv),
        )
    }

    /// The matrix taking normalised template points to frame pixels under `p`.
    pub fn pixel_matrix(&self, p: &Params) -> Matrix3<f64> {
        self.norm.to_image_matrix() * self.ssm.matrix(p)
    }

    /// The corners under `p`, in frame pixels.
    pub fn corners(&self, p: &Params) -> Quad {
        if !self.ssm.projective() {
            return self.normalised_corners(p).map(|c| self.norm.to_image(c));
        }
        let m = self.pixel_matrix(p);
        self.template_corners.map(|c| apply_homography(&m, c))
    }

    /// The corners under `p`, in the normalised frame.
    pub fn normalised_corners(&self, p: &Params) -> Quad {
        if !self.ssm.projective() {
            let mut out = [Point::default(); 4];
            self.ssm.warp_points(p, &self.template_corners.0, &mut out);
            return Quad(out);
        }
        let m = self.ssm.matrix(p);
        self.template_corners.map(|c| apply_homography(&m, c))
    }

    /// The grid the searches read warped by `p`, in frame pixels, into `(px, py)`: through the
    /// pixel matrix, or for a non-rigid SSM its displacement `x + sum_k p_k dw/dp_k(x)` (the
    /// warp is linear in `p`) from `dw/dp` on the grid.
    pub fn warp_grid(&self, p: &Params, px: &mut [f32], py: &mut [f32]) {
        if self.ssm.projective() {
            let m = self.pixel_matrix(p);
            warp_points(&m, &self.grid_x, &self.grid_y, px, py);
            return;
        }
        let n = self.grid_x.len();
        let (px, py) = (&mut px[..n], &mut py[..n]);
        px.copy_from_slice(&self.grid_x);
        py.copy_from_slice(&self.grid_y);
        for k in 0..self.dof {
            let v = p[k] as f32;
            for (row, out) in [(2 * k, &mut *px), (2 * k + 1, &mut *py)] {
                if v == 0.0 || self.dwdp0_zero[row] {
                    continue;
                }
                for (o, &d) in out.iter_mut().zip(&self.dwdp0[row * n..(row + 1) * n]) {
                    *o += v * d;
                }
            }
        }
        let (s, cx, cy) = (
            self.norm.scale as f32,
            self.norm.cx as f32,
            self.norm.cy as f32,
        );
        for (x, y) in px.iter_mut().zip(py.iter_mut()) {
            *x = *x * s + cx;
            *y = *y * s + cy;
        }
    }

    /// Any points of the normalised template frame warped by `p`, in frame pixels (the
    /// whole grid, a detector's): as [`Problem::warp_grid`] warps the grid, the non-rigid
    /// SSMs' point by point.
    pub fn warp_points(&self, p: &Params, xs: &[f32], ys: &[f32], px: &mut [f32], py: &mut [f32]) {
        if self.ssm.projective() {
            warp_points(&self.pixel_matrix(p), xs, ys, px, py);
            return;
        }
        for (((&x, &y), ox), oy) in xs.iter().zip(ys).zip(px.iter_mut()).zip(py.iter_mut()) {
            let mut out = [Point::default()];
            self.ssm
                .warp_points(p, &[Point::new(x as f64, y as f64)], &mut out);
            let q = self.norm.to_image(out[0]);
            *ox = q.x as f32;
            *oy = q.y as f32;
        }
    }

    /// The point Jacobian `dw/dx` (normalised frame, row-major `[a00, a01, a10, a11]`) of a
    /// non-rigid SSM's warp by `p` at grid point `i`: `I + sum_k (p_2k, p_2k+1)^T grad phi_k`.
    #[inline]
    pub fn point_jacobian(&self, p: &Params, i: usize) -> [f32; 4] {
        let n = self.grid_x.len();
        let [mut a00, mut a01, mut a10, mut a11] = [1.0f32, 0.0, 0.0, 1.0];
        for k in 0..self.dof / 2 {
            let (bx, by) = (
                self.basis_grad[2 * k * n + i],
                self.basis_grad[(2 * k + 1) * n + i],
            );
            let (u, v) = (p[2 * k] as f32, p[2 * k + 1] as f32);
            a00 += u * bx;
            a01 += u * by;
            a10 += v * bx;
            a11 += v * by;
        }
        [a00, a01, a10, a11]
    }

    /// The SSM's parameters whose corners best fit `q` (frame pixels), `None` if it cannot.
    pub fn fit(&self, q: &Quad) -> Option<Params> {
        self.fit_normalised(&q.map(|p| self.norm.to_norm(p)))
    }

    /// The parameters `p` moved so that its corners `from` (frame pixels) go to `to`: for a
    /// non-rigid SSM the homography between them after `p` ([`Ssm::then_matrix`]: the warp's
    /// shape between the corners kept), for the others the fit of `to` (`None` if it cannot).
    pub fn moved(&self, p: &Params, from: &Quad, to: &Quad) -> Option<Params> {
        if self.ssm.projective() {
            return self.fit(to);
        }
        let (a, b) = (
            from.map(|c| self.norm.to_norm(c)),
            to.map(|c| self.norm.to_norm(c)),
        );
        let m = crate::geometry::homography_from_points(&a.0, &b.0)?;
        self.ssm.then_matrix(p, &m)
    }

    /// The SSM's parameters whose corners best fit `q` (normalised frame).
    pub fn fit_normalised(&self, q: &Quad) -> Option<Params> {
        self.ssm.fit(&self.template_corners.0, &q.0)
    }

    /// `dw/dp` at `p` on the grid, into `out` (layout of [`Ssm::jacobian`]).
    pub fn jacobian(&self, p: &Params, out: &mut [f32]) {
        self.ssm.jacobian(p, &self.grid_x, &self.grid_y, out);
    }
}
