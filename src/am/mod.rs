//! Appearance models: the similarity `f(I*, I)` between the template intensities `I*` and the
//! intensities `I` sampled from the current frame at the warped grid (higher is better).
//!
//! An AM knows nothing about geometry. Given whole patches it returns the similarity, its
//! gradient with respect to the current or the template pixels, and the Hessian terms the search
//! methods need, already projected on a pixel Jacobian `J` (`N x S`, row-major:
//! `J[i * S + k] = dI_i / dp_k`) so that its per-pixel loops stay inside the AM:
//! `J^T (d2f/dI2) J`. Models with internal state (joint histograms, intensity maps: SCV, MI, ...)
//! update it only in [`Am::update_model`], never as a side effect of computing a similarity.
//!
//! Each model is one file and one line in [`REGISTRY`].

mod ccre;
pub mod channels;
mod correlation;
pub mod ilm;
mod intensity_map;
mod kld;
mod lscv;
mod mi;
mod ncc;
mod ngf;
mod nssd;
mod parzen;
pub mod pca;
mod riu;
mod rscv;
mod sad;
mod scv;
mod spss;
mod ssd;
mod ssim;
mod zncc;

use crate::linalg::MAX_DOF;
use crate::params::{MethodParams, ParamDef};
use crate::registry::{self, Entry};
use serde::{Deserialize, Serialize};

/// Which pixels a derivative is taken with respect to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrt {
    /// The current frame's pixels `I` (forward methods, ESM).
    Current,
    /// The template's pixels `I*` (inverse methods).
    Template,
}

/// Which second derivative a search method uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HessianKind {
    /// The AM's own default (Gauss-Newton for the L2-type models, after convergence for the
    /// robust ones).
    #[default]
    Default,
    /// Gauss-Newton: the first-order approximation of the AM's least-squares form.
    GaussNewton,
    /// The exact second derivative of `f` with respect to the pixels.
    Newton,
    /// The "Hessian after convergence": the exact second derivative evaluated where the current
    /// patch equals the template; constant over a sequence.
    AfterConvergence,
}

impl HessianKind {
    /// The kind itself, or `default` for [`HessianKind::Default`].
    pub fn or(self, default: HessianKind) -> HessianKind {
        match self {
            HessianKind::Default => default,
            k => k,
        }
    }
}

/// Optional capabilities that only some AMs have; a search method that needs one rejects AMs
/// without it when the tracker is built.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Capabilities {
    /// Has analytic derivatives that a gradient search converges with (the gradient-based search
    /// methods need them). A model may have exact derivatives and still not offer them, when its
    /// optimum is too flat for a Newton step to find (see [`Am::exact_derivatives`]).
    pub derivatives: bool,
    /// Has an embedding ([`Am::embed`]) in which the squared L2 distance ranks patches as the
    /// similarity does (nearest-neighbour search).
    pub distance: bool,
}

impl Capabilities {
    /// Analytic derivatives, no patch embedding (the robust models).
    pub const DERIVATIVES_ONLY: Capabilities = Capabilities {
        derivatives: true,
        distance: false,
    };

    /// What `need` asks for that `self` lacks, in words (`None` when nothing is missing).
    pub fn missing(&self, need: &Capabilities) -> Option<&'static str> {
        if need.derivatives && !self.derivatives {
            Some("analytic derivatives that a gradient search converges with")
        } else if need.distance && !self.distance {
            Some("a patch embedding for nearest-neighbour search")
        } else {
            None
        }
    }
}

/// What computes `J^T x` for per-pixel vectors `x` (one row of the output for each), for
/// [`Am::hessian_from_projections`].
pub type Projections<'a> = &'a mut dyn FnMut(&[&[f32]], &mut [[f64; MAX_DOF]]);

/// An appearance model.
///
/// Per iteration a search method calls [`Am::gradient`] (or [`Am::similarity`]) once, then
/// possibly [`Am::hessian`] on the same patch: a model computes the statistics of a patch (means,
/// norms, joint histograms) in the first call and the Hessian reuses them, so they are never built
/// twice. For the models that say so in [`Am::updates_model`], each time the search settles on a
/// frame the executor calls [`Am::update_model`] with the patch sampled there and lets the search go
/// on (up to three times a frame), so that the model follows the light of the frame being tracked.
pub trait Am: CloneAm + Send + Sync + std::fmt::Debug {
    /// The registry name.
    fn name(&self) -> &'static str;
    /// What the model can do.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            derivatives: true,
            distance: true,
        }
    }
    /// Whether [`Am::gradient`] and [`Am::hessian`] are exact (the finite-difference tests check
    /// them): the models that offer [`Capabilities::derivatives`], and those that have them but do
    /// not offer them to the search methods.
    fn exact_derivatives(&self) -> bool {
        self.capabilities().derivatives
    }
    /// The Hessian a search method gets when it asks for [`HessianKind::Default`].
    fn default_hessian(&self) -> HessianKind {
        HessianKind::GaussNewton
    }
    /// Sets the template `I*` (and resets any internal model).
    fn set_template(&mut self, template: &[f32]);
    /// The template.
    fn template(&self) -> &[f32];
    /// The similarity `f(I*, I)`.
    fn similarity(&mut self, current: &[f32]) -> f64;
    /// The similarity and its gradient with respect to the `wrt` pixels, written to `grad`.
    fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64;
    /// `J^T (d2f / dI2) J` with respect to the `wrt` pixels (`J` is `N x dof`), written row-major
    /// into the first `dof * dof` entries of `out`. Called after [`Am::gradient`] with the same
    /// `wrt` and `current` (the statistics computed there may be reused).
    fn hessian(
        &mut self,
        wrt: Wrt,
        kind: HessianKind,
        current: &[f32],
        jac: &[f32],
        dof: usize,
        out: &mut [f64; MAX_DOF * MAX_DOF],
    );
    /// Whether [`Am::hessian`] with respect to the current pixels is `-J^T J` for every kind and
    /// [`Am::gradient`] the plain residual, whatever the patch (the least-squares models): the
    /// forward methods may then form their Newton system from the gradient's moments on the
    /// grid, without `J` ([`crate::registration::moments`]).
    fn hessian_is_minus_jtj(&self) -> bool {
        false
    }
    /// Whether [`Am::hessian_from_projections`] gives the Hessian with respect to the current
    /// pixels (the correlations): the forward methods may then form their Newton system from
    /// the gradient's moments on the grid as for the least-squares models.
    fn hessian_from_jtj(&self) -> bool {
        false
    }
    /// [`Am::hessian`] with respect to the current pixels, from `J^T J` (`jtj`, row-major with
    /// stride [`MAX_DOF`]) and the products `J^T x` of per-pixel vectors `x`, which `project`
    /// writes (one row of `out` for each `x` given), instead of from `J`: for the models whose
    /// Hessian is built from those alone ([`Am::hessian_from_jtj`]). Called after
    /// [`Am::gradient`] on the same patch, as [`Am::hessian`]. Returns `false`, writing nothing,
    /// for the others.
    fn hessian_from_projections(
        &mut self,
        _kind: HessianKind,
        _current: &[f32],
        _jtj: &[f64; MAX_DOF * MAX_DOF],
        _project: Projections<'_>,
        _dof: usize,
        _out: &mut [f64; MAX_DOF * MAX_DOF],
    ) -> bool {
        false
    }
    /// Whether the similarity is built from per-pixel terms only (a sum, or a ratio of sums
    /// such as a correlation), so that an even sub-grid of the patch ranks patches as the whole
    /// grid does, less precisely: a particle filter may then weigh its particles on one (`pf`'s
    /// parameter `stride`). Not so for models fitted to the whole patch (histograms, intensity
    /// maps, blocks, gradient fields), which need every sample.
    fn pixelwise(&self) -> bool {
        false
    }
    /// The most warp parameters the model's Hessian takes (its per-pixel derivative cells hold
    /// this many: MI's, CCRE's and KLD's are eight lanes, one AVX register); an SSM of more is
    /// refused with it when the tracker is built.
    fn max_dof(&self) -> usize {
        MAX_DOF
    }
    /// Whether the model reads the patch as the `res x res` grid it was sampled on (its
    /// neighbours, its regions), so that it cannot score a selection of the grid's points
    /// (selective pixel integration, `spi`, refuses it).
    fn needs_grid(&self) -> bool {
        false
    }
    /// Whether the model bins the patch's values as grey levels `0..255` in a joint histogram
    /// whose gradient it follows (MI's and CCRE's Parzen histograms): it cannot compare descriptor fields (`channels = df`), whose
    /// values are derivatives piled up near zero (a few of the bins hold them all; on the
    /// coffee photograph MI and CCRE recovered almost none of the known warps), and the
    /// factory refuses that pairing.
    fn bins_grey_levels(&self) -> bool {
        false
    }
    /// Whether [`Am::update_model`] does something (the executor then samples the patch where the
    /// search settles for it).
    fn updates_model(&self) -> bool {
        false
    }
    /// Updates an internal model (e.g. the intensity map of SCV) from `current`, the patch of the
    /// frame being tracked where the search has settled.
    fn update_model(&mut self, _current: &[f32]) {}
    /// Whether the model learns the target's appearance from the frames tracked
    /// ([`Am::learn`]; the PCA subspace).
    fn learns(&self) -> bool {
        false
    }
    /// The directions in which the template's pixels change when the target moves: its pixel
    /// Jacobian at the identity (`N x dof`, stored by parameter: `jac[k N + i]`), given after
    /// each template to a model that learns ([`Am::learns`]). What it learns is kept
    /// orthogonal to them: a patch tracked a little off the target must not teach it to ignore
    /// a motion.
    fn set_motion(&mut self, _jac: &[f32], _dof: usize) {}
    /// Learns `patch`, sampled where the tracker's search ended on a frame it accepted: once a
    /// frame (unlike [`Am::update_model`], which follows the light within a frame's search).
    /// A search method that keeps something made from the model is then told
    /// ([`crate::registration::SearchMethod::model_updated`]).
    fn learn(&mut self, _patch: &[f32]) {}
    /// Writes the embedding of `patch` into `out` (same length as the patch): the squared L2
    /// distance between embeddings ranks patches as the similarity does, so that nearest-neighbour
    /// search can index them. Models without [`Capabilities::distance`] leave it unused; the
    /// default is the patch itself (SSD's geometry).
    fn embed(&self, patch: &[f32], out: &mut [f32]) {
        out.copy_from_slice(patch);
    }
}

/// A copy of a boxed model, its parameters and state included: a search method that scores
/// patches apart from the [`crate::registration::Context`] (PF's particles on a sub-grid, NN's
/// exact ranking) keeps its own. Every `Clone` model has it.
pub trait CloneAm {
    /// The copy.
    fn clone_am(&self) -> Box<dyn Am>;
}

impl<T: Am + Clone + 'static> CloneAm for T {
    fn clone_am(&self) -> Box<dyn Am> {
        Box::new(self.clone())
    }
}

/// Implements the [`Am`] methods that a newtype model (`struct M(Engine)`) forwards to its
/// engine: the template, the similarity and its derivatives.
macro_rules! forward_to_engine {
    () => {
        fn set_template(&mut self, template: &[f32]) {
            self.0.set_template(template)
        }
        fn template(&self) -> &[f32] {
            self.0.template()
        }
        fn similarity(&mut self, current: &[f32]) -> f64 {
            self.0.similarity(current)
        }
        fn gradient(&mut self, wrt: Wrt, current: &[f32], grad: &mut [f32]) -> f64 {
            self.0.gradient(wrt, current, grad)
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
            self.0.hessian(wrt, kind, current, jac, dof, out)
        }
    };
}
use forward_to_engine;

/// Implements [`Am::hessian_from_jtj`] and [`Am::hessian_from_projections`] for a newtype model
/// whose engine is a [`correlation::Correlation`].
macro_rules! forward_projections {
    () => {
        fn hessian_from_jtj(&self) -> bool {
            true
        }
        fn hessian_from_projections(
            &mut self,
            kind: HessianKind,
            current: &[f32],
            jtj: &[f64; MAX_DOF * MAX_DOF],
            project: $crate::am::Projections<'_>,
            dof: usize,
            out: &mut [f64; MAX_DOF * MAX_DOF],
        ) -> bool {
            self.0
                .hessian_from_projections(kind, current, jtj, project, dof, out);
            true
        }
    };
}
use forward_projections;

/// How to build an AM: its parameters (most have none) and its constructor, which gets them
/// validated, unset ones at their defaults.
#[derive(Clone, Copy)]
pub struct AmBuilder {
    pub params: &'static [ParamDef],
    pub build: fn(&MethodParams) -> Box<dyn Am>,
}

impl AmBuilder {
    /// A model without parameters.
    pub const fn plain(build: fn(&MethodParams) -> Box<dyn Am>) -> Self {
        AmBuilder { params: &[], build }
    }

    /// The model with its default parameters.
    pub fn default_model(&self) -> Box<dyn Am> {
        (self.build)(&MethodParams::default())
    }
}

/// Every appearance model.
pub const REGISTRY: &[Entry<AmBuilder>] = &[
    ssd::ENTRY,
    zncc::ENTRY,
    ncc::ENTRY,
    scv::ENTRY,
    rscv::ENTRY,
    lscv::ENTRY,
    mi::ENTRY,
    ccre::ENTRY,
    ssim::ENTRY,
    spss::ENTRY,
    riu::ENTRY,
    ngf::ENTRY,
    sad::ENTRY,
    nssd::ENTRY,
    kld::ENTRY,
    pca::ENTRY,
];

/// The AM called `name` (or one of its aliases), with its default parameters.
pub fn build(name: &str) -> crate::Result<Box<dyn Am>> {
    build_with(name, &MethodParams::default())
}

/// The AM called `name` with `params`: those among them that the model has (the others belong
/// to the search method) are checked against its definitions.
pub fn build_with(name: &str, params: &MethodParams) -> crate::Result<Box<dyn Am>> {
    let entry = registry::lookup(REGISTRY, "appearance model", name)?;
    let defs: Vec<&ParamDef> = entry.build.params.iter().collect();
    let own = params.split(&defs).0;
    own.validate(&format!("appearance model '{}'", entry.name), &defs)?;
    Ok((entry.build.build)(&own))
}

/// The parameters of the AM called `name`.
pub fn param_defs(name: &str) -> crate::Result<&'static [ParamDef]> {
    Ok(registry::lookup(REGISTRY, "appearance model", name)?
        .build
        .params)
}

#[cfg(test)]
pub(crate) mod tests;
