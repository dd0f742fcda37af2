//! An appearance model applied channel by channel (`channels = rgb`): the patch of a colour grid
//! is the `res x res` patch of each channel in turn ([`crate::registration::Problem::channels`]),
//! and [`PerChannel`] gives each part its own copy of the model, so that a model of the patch
//! as a whole (ZNCC's means and norms, SCV's and MI's joint histograms, LSCV's regions, NGF's
//! neighbours, PCA's subspace) sees one channel at a time, as MTF's multi-channel models do
//! with a histogram per channel. The similarity is the sum of the channels' similarities; its
//! gradient is the channels' gradients side by side and its Hessian the sum of theirs (each
//! channel's pixels depend on the warp through that channel's rows of `J`).
//!
//! Not a registry entry: the factory wraps the tracker's AM in it for colour, except a model
//! whose similarity is already a sum over the pixels with no statistic of the patch (SSD,
//! [`super::Am::hessian_is_minus_jtj`]), for which the sum over channels is the model itself.

use super::{Am, Capabilities, HessianKind, Wrt};
use crate::linalg::{MAX_DOF, SquareBuf, clear_square};

/// See the module's documentation.
#[derive(Debug)]
pub struct PerChannel {
    /// One copy of the model per channel.
    models: Vec<Box<dyn Am>>,
    /// The whole template, channel after channel.
    template: Vec<f32>,
    /// One channel's rows of `J` (scratch of [`Am::hessian`], sized with the template).
    jac: Vec<f32>,
    /// One channel's Hessian (scratch of [`Am::hessian`]).
    one: SquareBuf,
}

impl Clone for PerChannel {
    fn clone(&self) -> Self {
        PerChannel {
            models: self.models.iter().map(|m| m.clone_am()).collect(),
            template: self.template.clone(),
            jac: self.jac.clone(),
            one: self.one.clone(),
        }
    }
}

impl PerChannel {
    /// `model` applied to each of `channels` parts of the patch.
    pub fn new(model: Box<dyn Am>, channels: usize) -> Self {
        let mut models = Vec::with_capacity(channels.max(1));
        for _ in 1..channels.max(1) {
            models.push(model.clone_am());
        }
        models.push(model);
        PerChannel {
            models,
            template: Vec::new(),
            jac: Vec::new(),
            one: SquareBuf::default(),
        }
    }

    /// The length of one channel's part of a patch of `n` values.
    fn part(&self, n: usize) -> usize {
        n / self.models.len()
    }

    /// The first model (what the others are copies of).
    fn first(&self) -> &dyn Am {
        &*self.models[0]
    }
}

/// Copies channel `c`'s rows of `J` (`dof` rows of `n` values, by parameter) into `out` (`dof`
/// rows of `m`).
fn channel_rows(jac: &[f32], n: usize, m: usize, c: usize, dof: usize, out: &mut [f32]) {
    for k in 0..dof {
        out[k * m..(k + 1) * m].copy_from_slice(&jac[k * n + c * m..][..m]);
    }
}

impl Am for PerChannel {
    fn name(&self) -> &'static str {
        self.first().name()
    }
    fn capabilities(&self) -> Capabilities {
        self.first().capabilities()
    }
    fn exact_derivatives(&self) -> bool {
        self.first().exact_derivatives()
    }
    fn default_hessian(&self) -> HessianKind {
        self.first().default_hessian()
    }
    fn set_template(&mut self, template: &[f32]) {
        self.template.clear();
        self.template.extend_from_slice(template);
        let m = self.part(template.len());
        for (c, model) in self.models.iter_mut().enumerate() {
            model.set_template(&template[c * m..(c + 1) * m]);
        }
        self.jac.resize(m * MAX_DOF, 0.0);
    }
    fn template(&self) -> &[f32] {
        &self.template
    }
    fn similarity(&mut self, current: &[f32]) -> f64 {
        let m = self.part(current.len());
        let parts = current.chunks_exact(m.max(1));
        self.models
            .iter_mut()
            .zip(parts)
            .map(|(model, part)| model.similarity(part))
            .sum()
    }
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
        let m = self.part(current.len()).max(1);
        let parts = current.chunks_exact(m).zip(grad.chunks_exact_mut(m));
        self.models
            .iter_mut()
            .zip(parts)
            .map(|(model, (part, g))| model.gradient(wrt, part, g))
            .sum()
    }
    fn hessian(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    ) {
        let n = current.len();
        let m = self.part(n);
        out[..dof * dof].fill(0.0);
        let one = &mut self.one;
        clear_square(one, dof);
        for (c, model) in self.models.iter_mut().enumerate() {
            let rows = &mut self.jac[..m * dof];
            channel_rows(jac, n, m, c, dof, rows);
            model.hessian(wrt, kind, &current[c * m..(c + 1) * m], rows, dof, one);
            for (o, v) in out[..dof * dof].iter_mut().zip(&one[..dof * dof]) {
                *o += v;
            }
        }
    }
    fn hessian_is_minus_jtj(&self) -> bool {
        // The sum of the channels' `-J_c^T J_c` is `-J^T J`, their residuals side by side the
        // whole residual.
        self.first().hessian_is_minus_jtj()
    }
    fn pixelwise(&self) -> bool {
        // A sub-grid of the whole patch would cut across the channels' parts.
        false
    }
    fn max_dof(&self) -> usize {
        self.first().max_dof()
    }
    fn needs_grid(&self) -> bool {
        self.first().needs_grid()
    }
    fn bins_grey_levels(&self) -> bool {
        self.first().bins_grey_levels()
    }
    fn updates_model(&self) -> bool {
        self.first().updates_model()
    }
    fn update_model(&mut self, current: &[f32]) {
        let m = self.part(current.len()).max(1);
        for (model, part) in self.models.iter_mut().zip(current.chunks_exact(m)) {
            model.update_model(part);
        }
    }
    fn learns(&self) -> bool {
        self.first().learns()
    }
    fn set_motion(&mut self, jac: &[f32], dof: usize) {
        let n = self.template.len();
        let m = self.part(n);
        let mut rows = vec![0.0f32; m * dof];
        for (c, model) in self.models.iter_mut().enumerate() {
            channel_rows(jac, n, m, c, dof, &mut rows);
            model.set_motion(&rows, dof);
        }
    }
    fn learn(&mut self, patch: &[f32]) {
        let m = self.part(patch.len()).max(1);
        for (model, part) in self.models.iter_mut().zip(patch.chunks_exact(m)) {
            model.learn(part);
        }
    }
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        let m = self.part(patch.len()).max(1);
        let parts = patch.chunks_exact(m).zip(out.chunks_exact_mut(m));
        for (model, (part, o)) in self.models.iter().zip(parts) {
            model.embed(part, o);
        }
    }
}
