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
/// frame the driver calls [`Am::update_model`] with the patch sampled there and lets the search go
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
    /// Whether [`Am::update_model`] does something (the driver then samples the patch where the
    /// search settles for it).
    fn updates_model(&self) -> bool {
        false
    }
    /// Updates an internal model (e.g. the intensity map of SCV) from `current`, the patch of the
    /// frame being tracked where the search has settled.
    fn update_model(&mut self, _current: &[f32]) {}
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

/// `out = -J^T J` (row-major `dof x dof`), the Gauss-Newton Hessian of SSD.
pub(crate) fn minus_jtj(jac: &[f32], dof: usize, out: &mut [f64; MAX_DOF * MAX_DOF]) {
    let mut acc = [0.0f64; MAX_DOF * MAX_DOF];
    accumulate_jtj(jac, dof, &mut acc);
    for i in 0..dof {
        for j in 0..dof {
            out[i * dof + j] = -acc[i * MAX_DOF + j];
        }
    }
}

/// The dot product of two patches: 32 f32 lanes (four independent vector accumulators) over
/// blocks of 256 pixels, f64 across blocks.
pub fn dot(a: &[f32], b: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for (ca, cb) in a.chunks(256).zip(b.chunks(256)) {
        let mut lanes = [0.0f32; 32];
        let (ea, eb) = (ca.chunks_exact(32), cb.chunks_exact(32));
        let (ra, rb) = (ea.remainder(), eb.remainder());
        for (x, y) in ea.zip(eb) {
            for l in 0..32 {
                lanes[l] += x[l] * y[l];
            }
        }
        let tail: f32 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
        total += (lanes.iter().sum::<f32>() + tail) as f64;
    }
    total
}

/// Columns [`BlockCorrelation`]'s moments are summed at a time (four sums each, in registers:
/// two AVX registers a sum).
const MOMENT_COLUMNS: usize = 8;
const _: () = assert!(MOMENT_COLUMNS == 8, "the AVX moments sum eight columns");

/// The most blocks per side of [`block_correlation`].
pub const MAX_BLOCKS: usize = 8;

/// The confidence that `current` shows what `template` shows, both `res x res` patches stored
/// row by row, in -1..1 (see [`BlockCorrelation`], which this makes for one use).
pub fn block_correlation(template: &[f32], current: &[f32], res: usize, cells: usize) -> f64 {
    BlockCorrelation::new(template, res, cells).of(current)
}

/// The confidence that a patch shows what a template shows, both `res x res` stored row by row,
/// in -1..1. The patches are cut into `cells x cells` blocks; in each, a plane (bias and slopes
/// along both axes) is fitted to each patch and removed, and the residuals are correlated. The
/// blocks' correlations are averaged with the template's residual variance as weight. So it is
/// insensitive to light that varies smoothly across the target (a lamp's spot, a face turning
/// to the light: in each block that is nearly a gain, a bias and a slope), and blocks the
/// template has no texture in (only noise) weigh little. 0 when the template is flat.
///
/// What depends on the template and the grid only (each block's plane fit, the template's
/// moments) is computed once, by [`BlockCorrelation::new`]; [`BlockCorrelation::of`] then makes
/// five sums per sample (row segment by row segment, four lanes) and does not allocate.
#[derive(Clone, Debug, Default)]
pub struct BlockCorrelation {
    template: Vec<f32>,
    blocks: Vec<Block>,
    /// What depends on the grid only, kept while `res` and `cells` stay: `(res, cells)` and per
    /// block the sums of 1, x, y, xx, xy, yy (a new template per frame then only sums t, tx,
    /// ty, tt).
    geometry: Option<(usize, usize)>,
    geometry_sums: Vec<[f64; 6]>,
}

/// One block of [`BlockCorrelation`]: `(M, u_t, v_t, n)` with `M` the plane fit's normal matrix
/// inverted, `u_t` the template's moments `(sum t, sum t x, sum t y)`, `v_t` its residual
/// variance and `n` the block's samples (`None` for a block without texture, left out).
type Block = Option<(nalgebra::Matrix3<f64>, nalgebra::Vector3<f64>, f64, f64)>;

impl BlockCorrelation {
    /// Prepares the confidence against `template` (`res x res`) with `cells x cells` blocks
    /// (at most [`MAX_BLOCKS`] per side); a template shorter than `res x res` gives 0 always.
    pub fn new(template: &[f32], res: usize, cells: usize) -> Self {
        let mut bc = Self::default();
        bc.set_template(template, res, cells);
        bc
    }

    /// [`BlockCorrelation::new`] in place: once its buffers have grown to `res x res`, it does
    /// not allocate (the tracker makes one of every frame's patch).
    pub fn set_template(&mut self, template: &[f32], res: usize, cells: usize) {
        if self.set_geometry(template, res, cells) {
            // The template's part: per block, sums of t, tx, ty, tt.
            let template = &template[..res * res];
            let sums = self.moments(template, [template]);
            self.set_template_sums(template, &sums);
        }
    }

    /// [`BlockCorrelation::set_template`] with the template's sums already made: `sums` are
    /// those of `template` on this grid (from [`BlockCorrelation::of_pair`] on a correlation of
    /// the same `res` and `cells`), which are then not summed again. The same result.
    pub fn set_template_from(
        &mut self,
        template: &[f32],
        res: usize,
        cells: usize,
        sums: &PatchSums,
    ) {
        if sums.geometry != Some((res, blocks_per_side(res, cells))) {
            return self.set_template(template, res, cells);
        }
        if self.set_geometry(template, res, cells) {
            self.set_template_sums(&template[..res * res], &sums.blocks);
        }
    }

    /// The template-independent part of [`BlockCorrelation::set_template`]: clears the template
    /// and sets the grid; false (the correlation then gives 0) when `template` is too short.
    fn set_geometry(&mut self, template: &[f32], res: usize, cells: usize) -> bool {
        let cells = blocks_per_side(res, cells);
        self.template.clear();
        self.blocks.clear();
        if res == 0 || template.len() < res * res {
            self.geometry = None;
            return false;
        }
        // The grid's part, once per (res, cells): per block the sums of 1, x, y, xx, xy, yy of
        // the samples' block-local coordinates.
        if self.geometry != Some((res, cells)) {
            self.geometry_sums.clear();
            self.geometry_sums.resize(cells * cells, [0.0; 6]);
            for r in 0..res {
                let br = r * cells / res;
                let y = (r - br * res / cells) as f64;
                for c in 0..res {
                    let bc = c * cells / res;
                    let x = (c - bc * res / cells) as f64;
                    let b = br * cells + bc;
                    let terms = [1.0, x, y, x * x, x * y, y * y];
                    for (a, v) in self.geometry_sums[b].iter_mut().zip(terms) {
                        *a += v;
                    }
                }
            }
            self.geometry = Some((res, cells));
        }
        true
    }

    /// Each block's plane fit and the template's moments from its sums `t, tx, ty, tt` (the
    /// first four of each block's in `sums`).
    fn set_template_sums(&mut self, template: &[f32], sums: &BlockSums) {
        let acc = self
            .geometry_sums
            .iter()
            .zip(sums)
            .map(|(g, t)| [g[0], g[1], g[2], g[3], g[4], g[5], t[0], t[1], t[2], t[3]]);
        self.blocks.extend(acc.map(|b| {
            let n = b[0];
            if n < 4.0 {
                return None;
            }
            let m = nalgebra::Matrix3::new(b[0], b[1], b[2], b[1], b[3], b[4], b[2], b[4], b[5]);
            let inv = m.try_inverse()?;
            let ut = nalgebra::Vector3::new(b[6], b[7], b[8]);
            let vt = b[9] - ut.dot(&(inv * ut));
            (vt.is_finite() && vt > 1e-6 * n).then_some((inv, ut, vt, n))
        }));
        self.template.extend_from_slice(template);
    }

    /// Per block, the sums of `p`, `p x`, `p y`, `p p` and `q p` for each `q` of `qs` (one or
    /// two; the last sum zero with one) over its samples (`x`, `y` the block-local coordinates),
    /// `p` and each `q` being `res x res` patches. Per row of blocks, the columns' sums of `p`,
    /// `p y`, `p p` and each `q p` over the block row's rows ([`MOMENT_COLUMNS`] columns at a
    /// time, kept in registers down the rows), then each column's into its block, column after
    /// column (`p x` from the column's `p`). Each sum is made the same way whatever `qs` holds.
    fn moments<const Q: usize>(&self, p: &[f32], qs: [&[f32]; Q]) -> BlockSums {
        let mut acc = [[0.0f64; 6]; MAX_BLOCKS * MAX_BLOCKS];
        let Some((res, cells)) = self.geometry else {
            return acc;
        };
        // The first row (or column) of block b: the first r with r cells / res = b; its
        // block-local coordinate is r - b res / cells.
        let start = |b: usize| (b * res).div_ceil(cells);
        for br in 0..cells {
            let rows = start(br)..start(br + 1).min(res);
            let origin = (br * res / cells) as f64;
            // Each column's sums into its block, in the order of the columns: `c` the next
            // column, `bc` its block, `next` the next block's first column, `x0` the origin of
            // the block-local x (no division per column); the block's sums are kept in `a` until
            // the next block begins.
            let row_acc = &mut acc[br * cells..(br + 1) * cells];
            let (mut c, mut bc, mut next, mut x0) = (0, 0, start(1), 0);
            let mut a = [0.0f64; 6];
            while c < res {
                // Eight columns' sums, of which those from `skip` on are the next to add.
                let (sums, skip) = if c + MOMENT_COLUMNS <= res {
                    (column_sums8(p, qs, res, c, rows.clone(), origin), 0)
                } else if res >= MOMENT_COLUMNS {
                    // The last columns: the last eight summed (each column's sums are its own).
                    let first = res - MOMENT_COLUMNS;
                    (
                        column_sums8(p, qs, res, first, rows.clone(), origin),
                        c - first,
                    )
                } else {
                    let mut one = [[0.0; 5]; MOMENT_COLUMNS];
                    one[MOMENT_COLUMNS - 1] =
                        portable::column_sums::<1, Q>(p, qs, res, c, rows.clone(), origin)[0];
                    (one, MOMENT_COLUMNS - 1)
                };
                for s in &sums[skip..] {
                    while c >= next {
                        row_acc[bc] = std::mem::take(&mut a);
                        bc += 1;
                        next = start(bc + 1);
                        x0 = bc * res / cells;
                    }
                    let x = (c - x0) as f64;
                    a[0] += s[0];
                    a[1] += s[0] * x;
                    a[2] += s[1];
                    a[3] += s[2];
                    a[4] += s[3];
                    a[5] += s[4];
                    c += 1;
                }
            }
            row_acc[bc] = a;
        }
        acc
    }

    /// The confidence of `current` (0 when it is shorter than the template, flat or not finite).
    pub fn of(&self, current: &[f32]) -> f64 {
        let n = self.geometry.map_or(0, |(res, _)| res * res);
        if current.len() < n {
            return 0.0;
        }
        // Per block, sums of: c, cx, cy, cc, tc.
        let acc = self.moments(&current[..n], [&self.template]);
        self.of_sums(&acc, 4)
    }

    /// [`BlockCorrelation::of`] for this correlation and `other` (the same `res` and cells,
    /// another template), from one pass over `current`, and the patch's sums (for
    /// [`BlockCorrelation::set_template_from`]): the same two values as two calls of `of`.
    pub fn of_pair(
        &self,
        other: &BlockCorrelation,
        current: &[f32],
        sums: &mut PatchSums,
    ) -> (f64, f64) {
        let n = self.geometry.map_or(0, |(res, _)| res * res);
        sums.geometry = None;
        if other.geometry != self.geometry || n == 0 || current.len() < n {
            return (self.of(current), other.of(current));
        }
        sums.blocks = self.moments(&current[..n], [&self.template, &other.template]);
        sums.geometry = self.geometry;
        (
            self.of_sums(&sums.blocks, 4),
            other.of_sums(&sums.blocks, 5),
        )
    }

    /// The confidence from a patch's block sums, the products with this template being the
    /// `cross`-th of each block's.
    fn of_sums(&self, acc: &BlockSums, cross: usize) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (block, a) in self.blocks.iter().zip(acc) {
            let Some((inv, ut, vt, n)) = block else {
                continue;
            };
            let uc = nalgebra::Vector3::new(a[0], a[1], a[2]);
            // Inner products of the residuals after the planes are removed.
            let vc = a[3] - uc.dot(&(inv * uc));
            let cov = a[cross] - ut.dot(&(inv * uc));
            if !(vc.is_finite() && cov.is_finite()) {
                continue;
            }
            let rho = if vc <= 1e-6 * n {
                0.0
            } else {
                (cov / (vt * vc).sqrt()).clamp(-1.0, 1.0)
            };
            num += vt * rho;
            den += vt;
        }
        if den > 0.0 { num / den } else { 0.0 }
    }
}

/// The blocks per side of a [`BlockCorrelation`] asked for `cells` on a `res x res` grid: at
/// least one, at most [`MAX_BLOCKS`] and `res`.
fn blocks_per_side(res: usize, cells: usize) -> usize {
    cells.clamp(1, MAX_BLOCKS).min(res.max(1))
}

/// Per block (at most [`MAX_BLOCKS`] per side), sums over a patch `c`: `c, c x, c y, c c`, then
/// `t c` for one or two templates `t`.
type BlockSums = [[f64; 6]; MAX_BLOCKS * MAX_BLOCKS];

/// A patch's block sums made by [`BlockCorrelation::of_pair`], kept to make it the template of
/// another correlation of the same grid ([`BlockCorrelation::set_template_from`]) without
/// summing it again.
#[derive(Clone, Debug)]
pub struct PatchSums {
    /// `(res, cells)` of the grid the sums are on (`None`: none made).
    geometry: Option<(usize, usize)>,
    blocks: BlockSums,
}

impl Default for PatchSums {
    fn default() -> Self {
        PatchSums {
            geometry: None,
            blocks: [[0.0; 6]; MAX_BLOCKS * MAX_BLOCKS],
        }
    }
}

/// The sum of a patch (vectorised like [`dot`]).
pub fn sum(a: &[f32]) -> f64 {
    let mut total = 0.0f64;
    for ca in a.chunks(256) {
        let mut lanes = [0.0f32; 32];
        let ea = ca.chunks_exact(32);
        let tail: f32 = ea.remainder().iter().sum();
        for x in ea {
            for l in 0..32 {
                lanes[l] += x[l];
            }
        }
        total += (lanes.iter().sum::<f32>() + tail) as f64;
    }
    total
}

/// Samples per block of [`accumulate_jtj`] and [`jt_times`]: every column's block stays in the
/// L1 cache while it is read; sums within a block are f32, across blocks f64 (as in [`dot`]).
const JT_BLOCK: usize = 256;

/// Eight f32 lanes (one AVX register).
type Lanes = [f32; 8];

use crate::linalg::lanes_sum;

/// The products' kernels with AVX2 and FMA intrinsics (the build's CPU baseline, x86-64-v3).
#[cfg(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
))]
mod simd {
    use super::{Lanes, MAX_DOF};

    /// The lane sums of `rows[r] . cols[t]` over the first `full` (a multiple of 8) samples.
    pub(super) fn tile_2x4(rows: [&[f32]; 2], cols: [&[f32]; 4], full: usize) -> [[Lanes; 4]; 2] {
        use std::arch::x86_64::*;
        assert!(rows.iter().chain(&cols).all(|c| c.len() >= full) && full.is_multiple_of(8));
        let mut out = [[[0f32; 8]; 4]; 2];
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); every load reads 8 values from
        // index i with i + 8 <= full <= the slice's length (asserted above).
        unsafe {
            let mut s = [[_mm256_setzero_ps(); 4]; 2];
            let mut i = 0;
            while i < full {
                let x0 = _mm256_loadu_ps(rows[0].as_ptr().add(i));
                let x1 = _mm256_loadu_ps(rows[1].as_ptr().add(i));
                for t in 0..4 {
                    let y = _mm256_loadu_ps(cols[t].as_ptr().add(i));
                    s[0][t] = _mm256_fmadd_ps(x0, y, s[0][t]);
                    s[1][t] = _mm256_fmadd_ps(x1, y, s[1][t]);
                }
                i += 8;
            }
            for r in 0..2 {
                for t in 0..4 {
                    _mm256_storeu_ps(out[r][t].as_mut_ptr(), s[r][t]);
                }
            }
        }
        out
    }

    /// The lane sums of `cols[k] . v` over the first `full` (a multiple of 8) samples.
    pub(super) fn columns_times(
        cols: &[&[f32]; MAX_DOF],
        v: &[f32],
        full: usize,
    ) -> [Lanes; MAX_DOF] {
        use std::arch::x86_64::*;
        assert!(cols.iter().all(|c| c.len() >= full) && v.len() >= full && full.is_multiple_of(8));
        let mut out = [[0f32; 8]; MAX_DOF];
        // SAFETY: AVX2 and FMA are enabled at compile time (cfg); every load reads 8 values from
        // index i with i + 8 <= full <= the slice's length (asserted above).
        unsafe {
            let mut s = [_mm256_setzero_ps(); MAX_DOF];
            let mut i = 0;
            while i < full {
                let x = _mm256_loadu_ps(v.as_ptr().add(i));
                for k in 0..MAX_DOF {
                    s[k] = _mm256_fmadd_ps(x, _mm256_loadu_ps(cols[k].as_ptr().add(i)), s[k]);
                }
                i += 8;
            }
            for k in 0..MAX_DOF {
                _mm256_storeu_ps(out[k].as_mut_ptr(), s[k]);
            }
        }
        out
    }

    /// [`super::portable::column_sums`] of eight columns: the column sums in eight AVX
    /// registers down the rows (the same products and sums in the same order, so the same bits).
    pub(super) fn column_sums<const Q: usize>(
        p: &[f32],
        qs: [&[f32]; Q],
        res: usize,
        c0: usize,
        rows: std::ops::Range<usize>,
        origin: f64,
    ) -> [[f64; 5]; 8] {
        use std::arch::x86_64::*;
        assert!((1..=2).contains(&Q), "one or two cross products");
        if let Some(last) = rows.clone().last() {
            let end = last * res + c0 + 8;
            assert!(
                end <= p.len() && qs.iter().all(|q| end <= q.len()),
                "moments beyond the patches"
            );
        }
        let mut s = [[0f64; 5]; 8];
        // SAFETY: AVX2 is enabled at compile time (cfg); every load reads 8 values from
        // r res + c0 with r <= the last row, so up to the end asserted above.
        unsafe {
            let z = _mm256_setzero_pd();
            let (mut sp, mut spy, mut spp) = ([z; 2], [z; 2], [z; 2]);
            let mut sqp = [[z; 2]; Q];
            for r in rows {
                let y = _mm256_set1_pd(r as f64 - origin);
                let pr = p.as_ptr().add(r * res + c0);
                for h in 0..2 {
                    let v = _mm256_cvtps_pd(_mm_loadu_ps(pr.add(4 * h)));
                    sp[h] = _mm256_add_pd(sp[h], v);
                    spy[h] = _mm256_add_pd(spy[h], _mm256_mul_pd(v, y));
                    spp[h] = _mm256_add_pd(spp[h], _mm256_mul_pd(v, v));
                    for (acc, q) in sqp.iter_mut().zip(qs) {
                        let t = _mm256_cvtps_pd(_mm_loadu_ps(q.as_ptr().add(r * res + c0 + 4 * h)));
                        acc[h] = _mm256_add_pd(acc[h], _mm256_mul_pd(t, v));
                    }
                }
            }
            let mut lanes = [[0f64; 8]; 5];
            for (l, acc) in lanes.iter_mut().zip([sp, spy, spp].iter().chain(&sqp)) {
                _mm256_storeu_pd(l.as_mut_ptr(), acc[0]);
                _mm256_storeu_pd(l.as_mut_ptr().add(4), acc[1]);
            }
            for (k, sk) in s.iter_mut().enumerate() {
                *sk = std::array::from_fn(|i| lanes[i][k]);
            }
        }
        s
    }
}

/// The same kernels in plain Rust: the build for other CPUs, and compared with [`simd`] by a
/// test.
#[cfg_attr(
    all(
        target_arch = "x86_64",
        target_feature = "avx2",
        target_feature = "fma"
    ),
    allow(dead_code)
)]
mod portable {
    use super::{Lanes, MAX_DOF};

    /// `acc += x * y`, lane by lane (fused multiply-adds).
    #[inline(always)]
    fn fma_lanes(acc: &mut Lanes, x: &Lanes, y: &Lanes) {
        for l in 0..8 {
            acc[l] = x[l].mul_add(y[l], acc[l]);
        }
    }

    /// Eight consecutive values from `i`.
    #[inline(always)]
    fn lanes_at(v: &[f32], i: usize) -> &Lanes {
        v[i..i + 8].try_into().expect("eight values")
    }

    /// The lane sums of `rows[r] . cols[t]` over the first `full` (a multiple of 8) samples.
    pub(super) fn tile_2x4(rows: [&[f32]; 2], cols: [&[f32]; 4], full: usize) -> [[Lanes; 4]; 2] {
        let mut s = [[[0f32; 8]; 4]; 2];
        for i in (0..full).step_by(8) {
            let x = [lanes_at(rows[0], i), lanes_at(rows[1], i)];
            for (t, c) in cols.iter().enumerate() {
                let y = lanes_at(c, i);
                fma_lanes(&mut s[0][t], x[0], y);
                fma_lanes(&mut s[1][t], x[1], y);
            }
        }
        s
    }

    /// The lane sums of `cols[k] . v` over the first `full` (a multiple of 8) samples.
    pub(super) fn columns_times(
        cols: &[&[f32]; MAX_DOF],
        v: &[f32],
        full: usize,
    ) -> [Lanes; MAX_DOF] {
        let mut s = [[0f32; 8]; MAX_DOF];
        for i in (0..full).step_by(8) {
            let x = lanes_at(v, i);
            for (sk, c) in s.iter_mut().zip(cols) {
                fma_lanes(sk, x, lanes_at(c, i));
            }
        }
        s
    }

    /// The sums of `p`, `p y`, `p p` and `q p` for each `q` of `qs` (one or two, the rest of
    /// the five sums zero) down `W` neighbouring columns of `res x res` patches from `c0`, over
    /// `rows` (`y = r - origin`): the columns side by side in registers, row after row.
    #[inline(always)]
    pub(super) fn column_sums<const W: usize, const Q: usize>(
        p: &[f32],
        qs: [&[f32]; Q],
        res: usize,
        c0: usize,
        rows: std::ops::Range<usize>,
        origin: f64,
    ) -> [[f64; 5]; W] {
        let (mut sp, mut spy, mut spp) = ([0.0f64; W], [0.0f64; W], [0.0f64; W]);
        let mut sqp = [[0.0f64; W]; Q];
        for r in rows {
            let y = r as f64 - origin;
            let pr: &[f32; W] = p[r * res + c0..][..W].try_into().expect("W values");
            for k in 0..W {
                let v = pr[k] as f64;
                sp[k] += v;
                spy[k] += v * y;
                spp[k] += v * v;
                for (acc, q) in sqp.iter_mut().zip(qs) {
                    acc[k] += q[r * res + c0 + k] as f64 * v;
                }
            }
        }
        std::array::from_fn(|k| {
            let mut out = [sp[k], spy[k], spp[k], 0.0, 0.0];
            for (o, acc) in out[3..].iter_mut().zip(&sqp) {
                *o = acc[k];
            }
            out
        })
    }
}

#[cfg(not(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
)))]
use portable::{columns_times, tile_2x4};
#[cfg(not(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
)))]
fn column_sums8<const Q: usize>(
    p: &[f32],
    qs: [&[f32]; Q],
    res: usize,
    c0: usize,
    rows: std::ops::Range<usize>,
    origin: f64,
) -> [[f64; 5]; MOMENT_COLUMNS] {
    portable::column_sums::<MOMENT_COLUMNS, Q>(p, qs, res, c0, rows, origin)
}
#[cfg(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
))]
use simd::column_sums as column_sums8;
#[cfg(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
))]
use simd::{columns_times, tile_2x4};

/// Adds `J^T J` into `acc` (stride [`MAX_DOF`]). `J` is stored by parameter: column `k` is
/// `jac[k N..(k + 1) N]` (the layout of [`crate::ssm::Ssm::jacobian`]'s projection).
///
/// Block by block of 256 samples, the upper triangle in tiles of two rows by four
/// columns: each load feeds more than one multiply-add, and the eight accumulators of a tile
/// keep both FMA units busy.
pub fn accumulate_jtj(jac: &[f32], dof: usize, acc: &mut [f64; MAX_DOF * MAX_DOF]) {
    accumulate_weighted_jtj(jac, None, dof, acc);
}

/// Adds `J^T diag(d) J` into `acc` (stride [`MAX_DOF`]), or `J^T J` without `d`; as
/// [`accumulate_jtj`], each block's rows weighed by `d` once before the tiles read them.
pub fn accumulate_weighted_jtj(
    jac: &[f32],
    d: Option<&[f32]>,
    dof: usize,
    acc: &mut [f64; MAX_DOF * MAX_DOF],
) {
    let dof = dof.min(MAX_DOF);
    if dof == 0 {
        return;
    }
    let n = jac.len() / dof;
    let mut weighed = [[0f32; JT_BLOCK]; 2];
    let mut start = 0;
    while start < n {
        let len = JT_BLOCK.min(n - start);
        let full = len / 8 * 8;
        // Rows and columns past `dof` read the last column; their sums are dropped.
        let col = |k: usize| &jac[k.min(dof - 1) * n + start..][..len];
        for a in (0..dof).step_by(2) {
            let rows: [&[f32]; 2] = match d {
                Some(d) => {
                    let d = &d[start..start + len];
                    for (r, w) in weighed.iter_mut().enumerate() {
                        for ((o, &x), &y) in w.iter_mut().zip(col(a + r)).zip(d) {
                            *o = x * y;
                        }
                    }
                    [&weighed[0][..len], &weighed[1][..len]]
                }
                None => [col(a), col(a + 1)],
            };
            for b in (a / 4 * 4..dof).step_by(4) {
                let cols = [col(b), col(b + 1), col(b + 2), col(b + 3)];
                let s = tile_2x4(rows, cols, full);
                for (r, (row, sr)) in rows.iter().zip(&s).enumerate() {
                    for (t, (c, st)) in cols.iter().zip(sr).enumerate() {
                        let (i, j) = (a + r, b + t);
                        if i < dof && j < dof && j >= i {
                            let mut v = lanes_sum(st);
                            for k in full..len {
                                v = row[k].mul_add(c[k], v);
                            }
                            acc[i * MAX_DOF + j] += v as f64;
                        }
                    }
                }
            }
        }
        start += len;
    }
    for i in 0..dof {
        for j in 0..i {
            acc[i * MAX_DOF + j] = acc[j * MAX_DOF + i];
        }
    }
}

/// `out[k] = sum_i J[k N + i] v[i]` (`J` stored by parameter): every column in one pass over
/// `v`, block by block of 256 samples.
pub fn jt_times(jac: &[f32], v: &[f32], dof: usize, out: &mut [f64; MAX_DOF]) {
    let mut outs = [[0.0; MAX_DOF]];
    jt_times_many(jac, [v], dof, &mut outs);
    *out = outs[0];
}

/// [`jt_times`] of several vectors in one pass over `J` (each block of `J`'s columns is read
/// from memory once and stays in the L1 cache for the others); the same sums, in the same
/// order, as [`jt_times`] of each.
pub fn jt_times_many<const V: usize>(
    jac: &[f32],
    vs: [&[f32]; V],
    dof: usize,
    outs: &mut [[f64; MAX_DOF]; V],
) {
    for o in outs.iter_mut() {
        o.fill(0.0);
    }
    let dof = dof.min(MAX_DOF);
    if dof == 0 {
        return;
    }
    let stride = jac.len() / dof;
    let n = vs.iter().fold(stride, |n, v| n.min(v.len()));
    let mut start = 0;
    while start < n {
        let len = JT_BLOCK.min(n - start);
        let full = len / 8 * 8;
        let cols: [&[f32]; MAX_DOF] =
            std::array::from_fn(|k| &jac[k.min(dof - 1) * stride + start..][..len]);
        for (v, out) in vs.iter().zip(outs.iter_mut()) {
            let vv = &v[start..start + len];
            let s = columns_times(&cols, vv, full);
            for k in 0..dof {
                let mut t = lanes_sum(&s[k]);
                for q in full..len {
                    t = vv[q].mul_add(cols[k][q], t);
                }
                out[k] += t as f64;
            }
        }
        start += len;
    }
}

#[cfg(test)]
mod tests;
