//! Nearest-neighbour search (Dick et al., "Realtime registration-based tracking via approximate
//! nearest neighbour search"), as the paper's NN1K / NN10K.
//!
//! At initialisation the method draws `samples` random warps `q_k` around the identity (each
//! corner of the target moved by Gaussian noise of `sigma`, in units of the target's size, and the
//! SSM fitted to the moved corners; with `scales` > 1 the samples alternate between `sigma`,
//! `sigma / 4`, ... so that the iterations refine coarse to fine), samples the initialisation frame under each,
//! `I_0(w(w(x, q_k), p_0))`, and indexes the AM's embeddings of these patches. A frame's patch at
//! `p` that looks like sample `k` means the target sits at `p o q_k^-1`: each iteration finds the
//! nearest sample and composes with its stored inverse. Sample 0 is the identity, so a converged
//! frame stops moving and the executor's stop test ends it.
//!
//! The index: exact brute force over the full embeddings costs `samples x N` multiply-adds per
//! query (25 M for NN10K at 50x50, and 100 MB of samples read per query: memory-bound); the
//! default `projected` index first ranks every sample by a seeded very sparse random projection
//! of the embeddings to `dims` dimensions (Li, Hastie and Church 2006: each dimension a signed
//! sum of `sqrt(N)` random entries, so a query costs `dims sqrt(N)` additions; a distance-preserving
//! Johnson-Lindenstrauss map)
//! (Johnson-Lindenstrauss), then re-ranks the `candidates` best exactly. `regtrack bench` compares
//! the two (`--param index=exact`).
//!
//! Models without an embedding (MI, CCRE, SSIM, SAD, ...: [`Capabilities::distance`] false) are
//! searched by their own similarity: the stored rows are the sample patches themselves, the
//! `projected` index ranks them by the projection of their zero-mean, unit-norm intensities
//! (invariant to gain and bias) and re-ranks the `candidates` best by the model's similarity to
//! the query; `exact` scores every sample by the similarity (slow: `samples` evaluations per
//! query, but exactly the model's nearest neighbour).

use super::{Context, LossReason, MethodVisual, SearchMethod, SmConfig, SmDef, Step, Update};
use crate::am::Capabilities;
use crate::geometry::Quad;
use crate::imaging::ImageView;
use crate::linalg::dot;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::rng::Rng;
use crate::ssm::{Params, random_warp};

/// The most memory NN's sampled patches may take (bytes).
pub const MAX_STORE_BYTES: u64 = 4 << 30;

/// The parameters of the NN family (`samples`'s default differs per entry).
const fn params(samples: f64) -> [ParamDef; 6] {
    [
        ParamDef::int(
            "samples",
            "random warps indexed at initialisation",
            10.0,
            100_000.0,
            samples,
        ),
        ParamDef::float(
            "sigma",
            "standard deviation of the corner noise of the samples, in target sizes",
            0.001,
            1.0,
            0.05,
        ),
        ParamDef::choice(
            "index",
            "projected: random projection then exact re-ranking; exact: brute force",
            &["projected", "exact"],
        ),
        ParamDef::int(
            "dims",
            "dimensions of the projected index",
            4.0,
            1024.0,
            32.0,
        ),
        ParamDef::int(
            "candidates",
            "samples re-ranked exactly after the projected search",
            1.0,
            10_000.0,
            16.0,
        ),
        ParamDef::int(
            "scales",
            "noise scales of the samples: sample k has sigma / 4^(k mod scales), coarse to fine",
            1.0,
            4.0,
            3.0,
        ),
    ]
}

pub(super) const NN_PARAMS: [ParamDef; 6] = params(1000.0);
const NN10K_PARAMS: [ParamDef; 6] = params(10_000.0);

pub const ENTRY: Entry<SmDef> = Entry {
    name: "nn",
    aliases: &[],
    description: "nearest-neighbour search over random warps of the first frame (samples as a parameter)",
    build: SmDef {
        params: &NN_PARAMS,
        build: |cfg| Ok(Box::new(Nn::new("nn", &NN_PARAMS, cfg)?)),
    },
};

pub const ENTRY_1K: Entry<SmDef> = Entry {
    name: "nn1k",
    aliases: &[],
    description: "nearest-neighbour search, 1000 samples",
    build: SmDef {
        params: &NN_PARAMS,
        build: |cfg| Ok(Box::new(Nn::new("nn1k", &NN_PARAMS, cfg)?)),
    },
};

pub const ENTRY_10K: Entry<SmDef> = Entry {
    name: "nn10k",
    aliases: &[],
    description: "nearest-neighbour search, 10000 samples",
    build: SmDef {
        params: &NN10K_PARAMS,
        build: |cfg| Ok(Box::new(Nn::new("nn10k", &NN10K_PARAMS, cfg)?)),
    },
};

/// Nearest-neighbour search method.
#[derive(Debug)]
pub struct Nn {
    name: &'static str,
    samples: usize,
    sigma: f64,
    exact: bool,
    dims: usize,
    candidates: usize,
    scales: usize,
    seed: u64,
    /// Patch length.
    n: usize,
    /// `q_k^-1` per sample.
    inverse: Vec<Params>,
    /// The target's corners under each `q_k^-1` (normalised frame), and the parameters the last
    /// query started from (for the teaching view).
    candidates_quads: Vec<Quad>,
    queried_at: Params,
    /// Embeddings, `samples x n`, and their squared norms.
    data: Vec<f32>,
    norms: Vec<f32>,
    /// Sparse projection: per dimension `per_dim` (entry index, sign) pairs; projected samples
    /// in blocks of eight, dimension by dimension within a block (`reduced[(k / 8) dims 8 +
    /// j 8 + k % 8]`), so that the scan computes eight distances at once; the last block is
    /// padded with copies of sample 0's row.
    proj_idx: Vec<u32>,
    proj_sign: Vec<f32>,
    per_dim: usize,
    reduced: Vec<f32>,
    /// Per query scratch.
    query: Vec<f32>,
    qred: Vec<f32>,
    dist: Vec<f32>,
    order: Vec<u32>,
    best: Vec<f32>,
    chosen: usize,
    /// For models without an embedding: rows are raw patches, ranked by this second instance of
    /// the model (its template set to the query); `unit` is the normalised query.
    scorer: Option<Box<dyn crate::am::Am>>,
    unit: Vec<f32>,
    /// Teaching-view scratch.
    vis_quads: Vec<Quad>,
    vis_weights: Vec<f32>,
}

impl Nn {
    /// The method, if its store of sampled patches (`samples x res^2` values, a colour
    /// tracker's three times as many) fits in
    /// [`MAX_STORE_BYTES`]: parameters that are each in range must not combine into an abort.
    pub(super) fn new(
        name: &'static str,
        defs: &[ParamDef; 6],
        cfg: &SmConfig,
    ) -> crate::error::Result<Self> {
        let samples = cfg.get(&defs[0]) as usize;
        // A colour tracker's patches are its three channels', a field tracker's its four.
        let (res, channels) = (cfg.tracker.res, cfg.tracker.channels.count());
        let bytes = samples as u128 * (res * res * channels) as u128 * 4;
        if bytes > MAX_STORE_BYTES as u128 {
            return Err(crate::Error::InvalidParameter(format!(
                "{name}: {samples} samples of {res}x{res} values{} would need {:.1} GB of \
                 memory, more than the {} GB allowed: lower samples or res",
                if channels > 1 {
                    format!(" in {channels} channels")
                } else {
                    String::new()
                },
                bytes as f64 / 1e9,
                MAX_STORE_BYTES >> 30
            )));
        }
        Ok(Nn {
            name,
            samples,
            sigma: cfg.get(&defs[1]),
            exact: cfg.get(&defs[2]) == 1.0,
            dims: cfg.get(&defs[3]) as usize,
            candidates: cfg.get(&defs[4]) as usize,
            scales: cfg.get(&defs[5]) as usize,
            seed: cfg.tracker.seed,
            n: 0,
            inverse: Vec::new(),
            candidates_quads: Vec::new(),
            queried_at: [0.0; crate::linalg::MAX_DOF],
            data: Vec::new(),
            norms: Vec::new(),
            proj_idx: Vec::new(),
            proj_sign: Vec::new(),
            per_dim: 0,
            reduced: Vec::new(),
            query: Vec::new(),
            qred: Vec::new(),
            dist: Vec::new(),
            order: Vec::new(),
            best: Vec::new(),
            chosen: 0,
            scorer: None,
            unit: Vec::new(),
            vis_quads: Vec::new(),
            vis_weights: Vec::new(),
        })
    }

    /// `out[j] = sum_t sign_jt e[idx_jt]` for every projected dimension.
    fn project(idx: &[u32], sign: &[f32], per_dim: usize, e: &[f32], out: &mut [f32]) {
        for (j, o) in out.iter_mut().enumerate() {
            let r = j * per_dim..(j + 1) * per_dim;
            *o = idx[r.clone()]
                .iter()
                .zip(&sign[r])
                .map(|(&i, &s)| s * e[i as usize])
                .sum();
        }
    }

    /// The squared distance between the query and sample `k`, from the stored norm.
    fn exact_distance(&self, k: usize, qnorm: f32) -> f32 {
        let row = &self.data[k * self.n..(k + 1) * self.n];
        (self.norms[k] + qnorm - 2.0 * dot(row, &self.query) as f32).max(0.0)
    }

    /// The rank of sample `k` against the query (lower is nearer): the squared distance of the
    /// embeddings, or the negated similarity of the patches for a model without an embedding.
    fn exact_rank(&mut self, k: usize, qnorm: f32) -> f32 {
        match self.scorer.as_mut() {
            Some(am) => -(am.similarity(&self.data[k * self.n..(k + 1) * self.n]) as f32),
            None => self.exact_distance(k, qnorm),
        }
    }

    /// The index of the nearest sample to `self.query`.
    fn nearest(&mut self) -> usize {
        let qnorm = dot(&self.query, &self.query) as f32;
        if let Some(am) = self.scorer.as_mut() {
            am.set_template(&self.query);
        }
        if self.exact {
            if self.scorer.is_some() {
                for k in 0..self.samples {
                    self.dist[k] = self.exact_rank(k, qnorm);
                }
                return argmin(&self.dist);
            }
            for k in 0..self.samples {
                self.dist[k] = self.exact_distance(k, qnorm);
            }
            return argmin(&self.dist);
        }
        let key = if self.scorer.is_some() {
            unit_patch(&self.query, &mut self.unit);
            &self.unit
        } else {
            &self.query
        };
        Self::project(
            &self.proj_idx,
            &self.proj_sign,
            self.per_dim,
            key,
            &mut self.qred,
        );
        let d = self.dims;
        // The `c` nearest in the projection, kept sorted in `order` (with their distances in
        // `best`) while scanning: most samples are rejected by one comparison.
        let c = self.candidates.min(self.samples).max(1);
        self.order.clear();
        self.best.clear();
        // Eight samples' distances at a time (no horizontal sums), then the `c` smallest: most
        // samples are rejected by one comparison.
        for (block, dk) in self
            .reduced
            .chunks_exact(8 * d)
            .zip(self.dist.chunks_mut(8))
        {
            let mut acc = [0.0f32; 8];
            for (lanes, &q) in block.chunks_exact(8).zip(&self.qred) {
                for l in 0..8 {
                    let e = lanes[l] - q;
                    acc[l] += e * e;
                }
            }
            dk.copy_from_slice(&acc[..dk.len()]);
        }
        let mut worst = f32::INFINITY;
        for (k, &dk) in self.dist.iter().enumerate() {
            if self.order.len() < c || dk < worst {
                let at = self.best.partition_point(|&b| b <= dk);
                if self.order.len() == c {
                    self.order.pop();
                    self.best.pop();
                }
                self.order.insert(at, k as u32);
                self.best.insert(at, dk);
                if self.order.len() == c {
                    worst = self.best[c - 1];
                }
            }
        }
        let mut best = (f32::INFINITY, 0usize);
        for i in 0..self.order.len() {
            let k = self.order[i] as usize;
            let e = self.exact_rank(k, qnorm);
            if e < best.0 {
                best = (e, k);
            }
        }
        best.1
    }
}

/// `out` = `patch` with zero mean and unit norm (zero when the patch is flat).
fn unit_patch(patch: &[f32], out: &mut Vec<f32>) {
    let n = patch.len().max(1) as f64;
    let mean = patch.iter().map(|&v| v as f64).sum::<f64>() / n;
    let norm = patch
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        .sqrt();
    let scale = if norm > 1e-12 { 1.0 / norm } else { 0.0 };
    out.clear();
    out.extend(patch.iter().map(|&v| ((v as f64 - mean) * scale) as f32));
}

fn argmin(v: &[f32]) -> usize {
    let mut best = (f32::INFINITY, 0);
    for (i, &x) in v.iter().enumerate() {
        if x < best.0 {
            best = (x, i);
        }
    }
    best.1
}

impl SearchMethod for Nn {
    fn name(&self) -> &str {
        self.name
    }
    fn requires(&self) -> Capabilities {
        // Models without an embedding are ranked by their similarity.
        Capabilities::default()
    }
    fn initialize(&mut self, ctx: &mut Context, img: &ImageView) -> Result<(), LossReason> {
        let n = ctx.len();
        self.scorer = if ctx.am().capabilities().distance {
            None
        } else {
            // A copy: the tracker's model with its parameters.
            Some(ctx.am().clone_am())
        };
        let s = self.samples;
        self.n = n;
        let mut rng = Rng::new(self.seed);
        let identity = ctx.ssm().identity();
        self.inverse.clear();
        self.candidates_quads.clear();
        self.data.resize(s * n, 0.0);
        self.norms.resize(s, 0.0);
        self.dist.resize(s, 0.0);
        self.query.resize(n, 0.0);
        let base = *ctx.problem().template_corners();
        for k in 0..s {
            // Sample 0 is the identity; a warp the SSM cannot fit or invert is drawn again.
            let (q, inv) = if k == 0 {
                (identity, identity)
            } else {
                let mut tries = 0;
                loop {
                    tries += 1;
                    let sigma = self.sigma / 4f64.powi((k % self.scales.max(1)) as i32);
                    let q = random_warp(ctx.ssm(), &base, sigma, &mut rng);
                    if let Some((q, inv)) = q.and_then(|q| ctx.ssm().invert(&q).map(|i| (q, i))) {
                        break (q, inv);
                    }
                    if tries > 100 {
                        return Err(LossReason::Singular);
                    }
                }
            };
            ctx.sample_at(img, &q);
            let row = &mut self.data[k * n..(k + 1) * n];
            if self.scorer.is_some() {
                row.copy_from_slice(ctx.values());
            } else {
                ctx.am().embed(ctx.values(), row);
            }
            self.norms[k] = dot(row, row) as f32;
            self.inverse.push(inv);
            self.candidates_quads
                .push(crate::ssm::warp_quad(ctx.ssm(), &inv, &base));
        }
        if !self.exact {
            let d = self.dims;
            let per = ((n as f64).sqrt().ceil() as usize).clamp(1, n);
            let scale = (1.0 / per as f64).sqrt() as f32;
            self.per_dim = per;
            self.proj_idx.clear();
            self.proj_sign.clear();
            for _ in 0..d * per {
                self.proj_idx
                    .push(((rng.uniform() * n as f64) as usize).min(n - 1) as u32);
                self.proj_sign
                    .push(if rng.uniform() < 0.5 { -scale } else { scale });
            }
            let blocks = s.div_ceil(8);
            self.reduced.clear();
            self.reduced.resize(blocks * 8 * d, 0.0);
            self.qred.resize(d, 0.0);
            let mut out = vec![0.0f32; d];
            for k in 0..blocks * 8 {
                // The padding of the last block repeats sample 0 (its distances are not read).
                let src = if k < s { k } else { 0 };
                let mut row = &self.data[src * n..(src + 1) * n];
                if self.scorer.is_some() {
                    unit_patch(row, &mut self.unit);
                    row = &self.unit;
                }
                Self::project(&self.proj_idx, &self.proj_sign, per, row, &mut out);
                let block = &mut self.reduced[(k / 8) * 8 * d..][..8 * d];
                for (j, &v) in out.iter().enumerate() {
                    block[j * 8 + k % 8] = v;
                }
            }
            self.order.reserve(self.candidates + 1);
            self.best.reserve(self.candidates + 1);
        }
        if self.data.iter().any(|v| !v.is_finite()) {
            return Err(LossReason::NonFinite);
        }
        Ok(())
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let p = ctx.params();
        let f = ctx.similarity_at(img, &p);
        if self.scorer.is_some() {
            self.query.copy_from_slice(ctx.values());
        } else {
            ctx.am().embed(ctx.values(), &mut self.query);
        }
        let k = self.nearest();
        self.chosen = k;
        self.queried_at = p;
        ctx.apply(&self.inverse[k], Update::Compose)?;
        Ok(Step::auto(f))
    }
    fn visual(&mut self, ctx: &Context) -> Option<MethodVisual<'_>> {
        // Where each sample would put the target, from where the last query started; weighted
        // by how close its patch was to the query (1 = the nearest).
        let m = ctx.pixel_matrix(&self.queried_at);
        self.vis_quads.clear();
        self.vis_quads.extend(
            self.candidates_quads
                .iter()
                .map(|q| q.map(|c| crate::geometry::apply_homography(&m, c))),
        );
        let lo = self.dist.iter().copied().fold(f32::INFINITY, f32::min);
        let mean = self.dist.iter().sum::<f32>() / self.dist.len().max(1) as f32;
        let spread = (mean - lo).max(1e-12);
        self.vis_weights.clear();
        self.vis_weights
            .extend(self.dist.iter().map(|&d| (-(d - lo) / spread * 3.0).exp()));
        Some(MethodVisual::quads(
            "samples",
            &self.vis_quads,
            &self.vis_weights,
            Some(self.chosen),
        ))
    }
}
