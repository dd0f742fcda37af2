//! Particle filter (CONDENSATION, Isard and Blake), the paper's PF1K.
//!
//! The state of each particle is a full set of SSM parameters. Each frame, every particle is
//! moved by a random warp (each corner of the target moved by Gaussian noise of `sigma` target
//! sizes, the SSM fitted to it) composed with its state, and weighted by the AM's similarity of
//! its patch: `w_i ~ exp(-likelihood (f_max - f_i) / mean_j (f_max - f_j))`, a scale-free form
//! so that one setting fits every AM. The estimate is the SSM fitted to the weighted mean of the
//! particles' corners; then the particles are resampled (systematic resampling). When something
//! Each frame runs up to `rounds` rounds, the noise shrinking by `anneal` each round (an annealed
//! filter), so that the estimate settles; the driver's stop test may end the frame earlier. When
//! something else moved the estimate between frames (a cascade's earlier stage, a re-initialisation), the
//! particles start again from it.

use super::{Context, LossReason, MethodVisual, SearchMethod, SmConfig, SmDef, Step};
use crate::am::Capabilities;
use crate::geometry::{Point, Quad};
use crate::imaging::ImageView;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::rng::Rng;
use crate::ssm::{Params, random_warp};

const PARAMS: [ParamDef; 5] = [
    ParamDef::int("particles", "number of particles", 2.0, 100_000.0, 1000.0),
    ParamDef::float(
        "sigma",
        "standard deviation of the corner noise of the motion model, in target sizes",
        0.0001,
        1.0,
        0.04,
    ),
    ParamDef::float(
        "likelihood",
        "sharpness of the weights (higher: only the most similar particles count)",
        0.01,
        1000.0,
        5.0,
    ),
    ParamDef::int(
        "rounds",
        "rounds per frame; round r moves the particles by sigma * anneal^r (annealed filter)",
        1.0,
        100.0,
        5.0,
    ),
    ParamDef::float("anneal", "noise factor between rounds", 0.05, 1.0, 0.5),
];

pub const ENTRY: Entry<SmDef> = Entry {
    name: "pf",
    aliases: &["pf1k"],
    description: "particle filter (CONDENSATION), 1000 particles, seeded",
    build: SmDef {
        params: &PARAMS,
        build: |cfg| Ok(Box::new(Pf::new(cfg))),
    },
};

/// Particle filter.
#[derive(Debug)]
pub struct Pf {
    particles: usize,
    sigma: f64,
    likelihood: f64,
    rounds: usize,
    anneal: f64,
    /// The round of this frame.
    round: usize,
    seed: u64,
    rng: Rng,
    states: Vec<Params>,
    next: Vec<Params>,
    sims: Vec<f64>,
    weights: Vec<f64>,
    /// The estimate given last; a different `ctx.params` at the next frame resets the particles.
    last: Option<Params>,
    vis_quads: Vec<Quad>,
    vis_weights: Vec<f32>,
}

impl Pf {
    fn new(cfg: &SmConfig) -> Self {
        let seed = cfg.tracker.seed;
        Pf {
            particles: cfg.get(&PARAMS[0]) as usize,
            sigma: cfg.get(&PARAMS[1]),
            likelihood: cfg.get(&PARAMS[2]),
            rounds: cfg.get(&PARAMS[3]) as usize,
            anneal: cfg.get(&PARAMS[4]),
            round: 0,
            seed,
            rng: Rng::new(seed),
            states: Vec::new(),
            next: Vec::new(),
            sims: Vec::new(),
            weights: Vec::new(),
            last: None,
            vis_quads: Vec::new(),
            vis_weights: Vec::new(),
        }
    }

    /// Systematic resampling of `states` by `weights` (normalised) into `next`, then swapped.
    fn resample(&mut self) {
        let n = self.states.len();
        let u0 = self.rng.uniform() / n as f64;
        let mut cum = self.weights[0];
        let mut j = 0;
        self.next.clear();
        for i in 0..n {
            let u = u0 + i as f64 / n as f64;
            while u > cum && j + 1 < n {
                j += 1;
                cum += self.weights[j];
            }
            self.next.push(self.states[j]);
        }
        std::mem::swap(&mut self.states, &mut self.next);
    }
}

impl SearchMethod for Pf {
    fn name(&self) -> &str {
        ENTRY.name
    }
    fn requires(&self) -> Capabilities {
        Capabilities::default()
    }
    fn initialize(&mut self, ctx: &mut Context, _img: &ImageView) -> Result<(), LossReason> {
        self.rng = Rng::new(self.seed);
        self.states.clear();
        self.states.resize(self.particles, ctx.params);
        self.sims.resize(self.particles, 0.0);
        self.weights
            .resize(self.particles, 1.0 / self.particles as f64);
        self.next.reserve(self.particles);
        self.last = Some(ctx.params);
        Ok(())
    }
    fn start_frame(&mut self, ctx: &mut Context) {
        self.round = 0;
        if self.last != Some(ctx.params) {
            self.states.iter_mut().for_each(|s| *s = ctx.params);
        }
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let base = ctx.template_corners;
        let sigma = self.sigma * self.anneal.powi(self.round as i32);
        self.round += 1;
        // Motion model and measurement.
        let mut best = f64::NEG_INFINITY;
        for i in 0..self.states.len() {
            let moved = random_warp(&*ctx.ssm, &base, sigma, &mut self.rng)
                .and_then(|q| ctx.ssm.compose(&self.states[i], &q));
            if let Some(s) = moved.filter(|s| s.iter().all(|v| v.is_finite())) {
                self.states[i] = s;
            }
            let s = self.states[i];
            let f = ctx.similarity_at(img, &s);
            self.sims[i] = if f.is_finite() { f } else { f64::NEG_INFINITY };
            best = best.max(self.sims[i]);
        }
        if !best.is_finite() {
            return Err(LossReason::NonFinite);
        }
        // Scale-free weights.
        let (mut gap, mut count) = (0.0, 0usize);
        for &f in &self.sims {
            if f.is_finite() {
                gap += best - f;
                count += 1;
            }
        }
        let spread = (gap / count.max(1) as f64).max(1e-12);
        let mut total = 0.0;
        for (w, &f) in self.weights.iter_mut().zip(&self.sims) {
            *w = if f.is_finite() {
                (-self.likelihood * (best - f) / spread).exp()
            } else {
                0.0
            };
            total += *w;
        }
        self.weights.iter_mut().for_each(|w| *w /= total);
        // The estimate: the SSM fitted to the weighted mean of the corners.
        let mut mean = [Point::new(0.0, 0.0); 4];
        for (s, &w) in self.states.iter().zip(&self.weights) {
            let q = crate::ssm::warp_quad(&*ctx.ssm, s, &base);
            for c in 0..4 {
                mean[c].x += w * q.0[c].x;
                mean[c].y += w * q.0[c].y;
            }
        }
        let estimate = ctx
            .ssm
            .fit(&base.0, &Quad(mean).0)
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .ok_or(LossReason::Singular)?;
        // The teaching view before resampling: where the particles were and what they weighed.
        let wmax = self.weights.iter().copied().fold(0.0, f64::max).max(1e-300);
        let m = ctx.pixel_matrix(&ctx.ssm.identity());
        self.vis_quads.clear();
        self.vis_weights.clear();
        for (s, &w) in self.states.iter().zip(&self.weights) {
            let q = crate::ssm::warp_quad(&*ctx.ssm, s, &base);
            self.vis_quads
                .push(q.map(|c| crate::geometry::apply_homography(&m, c)));
            self.vis_weights.push((w / wmax) as f32);
        }
        self.resample();
        ctx.params = estimate;
        self.last = Some(estimate);
        let f = ctx.similarity_at(img, &estimate);
        Ok(if self.round >= self.rounds {
            Step::done(f)
        } else {
            Step::auto(f)
        })
    }
    fn visual(&mut self, _ctx: &Context) -> Option<MethodVisual<'_>> {
        Some(MethodVisual::quads(
            "particles",
            &self.vis_quads,
            &self.vis_weights,
            None,
        ))
    }
}
