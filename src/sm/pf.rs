//! Particle filter (CONDENSATION, Isard and Blake), the paper's PF1K.
//!
//! The state of each particle is a full set of SSM parameters. Each frame, every particle is
//! moved by a random warp (each corner of the target moved by Gaussian noise of `sigma` target
//! sizes, the SSM fitted to it) composed with its state, and weighted by the AM's similarity of
//! its patch: `w_i ~ exp(-likelihood (f_max - f_i) / mean_j (f_max - f_j))`, a scale-free form
//! so that one setting fits every AM. The estimate is the SSM fitted to the weighted mean of the
//! particles' corners; then the particles are resampled (systematic resampling). When something
//!
//! The particles are weighed on a sub-grid, every `stride`-th sample of the tracker's grid in
//! each direction, with a copy of the AM whose template is the sub-grid's; the estimate's
//! similarity, which the plan judges, is on the whole grid. By default the per-pixel AMs
//! ([`crate::am::Am::pixelwise`]: SSD, ZNCC, ...) take every other sample, a quarter of them (25 x
//! 25 of the paper's 50 x 50): the frame is already smoothed by the tracker's pre-smoothing, so
//! the sub-grid sees what the grid sees, less densely. The models fitted to the whole patch (MI's
//! and CCRE's histograms, the SCV family's maps) keep every sample: on 25 x 25, PF-MI missed one
//! of ten trials of the recovery test on the projective warps and settled 1.36 px from the truth
//! instead of 1.00. The particles are
//! moved and weighed over `threads` threads (a [`Crew`] started at initialisation, each member
//! with its own copy of the AM); each particle draws its move from its own random stream, seeded
//! from the tracker's generator, so the result is the same, bit for bit, with any number of
//! threads.
//! Each frame runs up to `rounds` rounds, the noise shrinking by `anneal` each round (an annealed
//! filter), so that the estimate settles; the executor's stop test may end the frame earlier. When
//! something else moved the estimate between frames (a cascade's earlier stage, a re-initialisation), the
//! particles start again from it.

use super::{Context, LossReason, MethodVisual, SearchMethod, SmConfig, SmDef, Step};
use crate::am::{Am, Capabilities};
use crate::crew::{Crew, threads_for};
use crate::geometry::{Point, Quad};
use crate::imaging::{ImageView, sample_values};
use crate::params::ParamDef;
use crate::registration::warp_points;
use crate::registry::Entry;
use crate::rng::Rng;
use crate::ssm::{Params, random_warp};
use nalgebra::Matrix3;

const PARAMS: [ParamDef; 7] = [
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
    ParamDef::int(
        "stride",
        "the particles are weighed on every stride-th sample of the grid in each direction \
         (0: 2 for the per-pixel AMs, 1 for the others)",
        0.0,
        16.0,
        0.0,
    ),
    ParamDef::int(
        "threads",
        "threads weighing the particles (0 = all cores); the result does not depend on it",
        0.0,
        256.0,
        0.0,
    ),
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
    /// The particles' corners in the template's normalised frame.
    corners: Vec<Quad>,
    weights: Vec<f64>,
    /// The estimate given last; a different `ctx.params` at the next frame resets the particles.
    last: Option<Params>,
    stride: usize,
    threads: usize,
    /// What weighs the particles, one scorer per thread (made at initialisation).
    crew: Option<Crew<Scorer>>,
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
            stride: cfg.get(&PARAMS[5]) as usize,
            threads: cfg.get(&PARAMS[6]) as usize,
            crew: None,
            round: 0,
            seed,
            rng: Rng::new(seed),
            states: Vec::new(),
            next: Vec::new(),
            sims: Vec::new(),
            corners: Vec::new(),
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

/// What weighs the particles: the sub-grid, a copy of the AM whose template is the template on
/// it, and the buffers of one patch.
#[derive(Debug)]
struct Scorer {
    /// The sub-grid's samples among the grid's (row-major indices).
    index: Vec<usize>,
    grid_x: Vec<f32>,
    grid_y: Vec<f32>,
    am: Box<dyn Am>,
    px: Vec<f32>,
    py: Vec<f32>,
    values: Vec<f32>,
    /// This scorer's share of the particles, moved, their corners (normalised frame) and their
    /// similarities.
    moved: Vec<Params>,
    corners: Vec<Quad>,
    out: Vec<f64>,
}

impl Scorer {
    /// Every `stride`-th sample of `ctx`'s square grid in each direction (0: the AM's choice),
    /// centred (the whole grid if it is too small for two samples a side), with a copy of
    /// `ctx`'s AM.
    fn new(ctx: &Context, stride: usize, particles: usize) -> Self {
        let res = (ctx.len() as f64).sqrt().round() as usize;
        let square = res * res == ctx.len();
        let stride = match stride {
            0 if ctx.am().pixelwise() => 2,
            0 => 1,
            s => s,
        };
        let stride = if square && res >= 2 * stride {
            stride
        } else {
            1
        };
        let index: Vec<usize> = if stride == 1 {
            (0..ctx.len()).collect()
        } else {
            let side = (res - 1) / stride + 1;
            let offset = (res - 1 - (side - 1) * stride) / 2;
            let at = |k: usize| offset + k * stride;
            (0..side)
                .flat_map(|r| (0..side).map(move |c| at(r) * res + at(c)))
                .collect()
        };
        let pick = |v: &[f32]| index.iter().map(|&i| v[i]).collect::<Vec<f32>>();
        let mut am = ctx.am().clone_am();
        am.set_template(&pick(ctx.problem().template()));
        if am.learns() {
            // What it learns is kept orthogonal to the motion, as the tracker's model's is:
            // the template's pixel Jacobian at the sub-grid's points.
            let jac = ctx.problem().template_motion();
            let sub: Vec<f32> = jac.chunks_exact(ctx.len()).flat_map(pick).collect();
            am.set_motion(&sub, ctx.dof());
        }
        let n = index.len();
        let (grid_x, grid_y) = ctx.problem().grid();
        Scorer {
            grid_x: pick(grid_x),
            grid_y: pick(grid_y),
            index,
            am,
            px: vec![0.0; n],
            py: vec![0.0; n],
            values: vec![0.0; n],
            moved: Vec::with_capacity(particles),
            corners: Vec::with_capacity(particles),
            out: Vec::with_capacity(particles),
        }
    }

    /// The similarity of the patch of `img` under the pixel matrix `m` on the sub-grid
    /// (`-inf` if it is not finite).
    fn similarity(&mut self, img: &ImageView, m: &Matrix3<f64>) -> f64 {
        warp_points(m, &self.grid_x, &self.grid_y, &mut self.px, &mut self.py);
        sample_values(img, &self.px, &self.py, &mut self.values);
        let f = self.am.similarity(&self.values);
        if f.is_finite() { f } else { f64::NEG_INFINITY }
    }

    /// The AM's model learns `patch` (on the whole grid), as the tracker's did: the light of
    /// a frame (`update_model`), or the appearance of a frame tracked (`learn`).
    fn update_model(&mut self, patch: &[f32]) {
        for (v, &i) in self.values.iter_mut().zip(&self.index) {
            *v = patch[i];
        }
        if self.am.learns() {
            self.am.learn(&self.values);
        } else {
            self.am.update_model(&self.values);
        }
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
        self.states.resize(self.particles, ctx.params());
        self.sims.resize(self.particles, 0.0);
        self.corners.resize(self.particles, Quad::unit_square());
        self.weights
            .resize(self.particles, 1.0 / self.particles as f64);
        self.next.reserve(self.particles);
        self.last = Some(ctx.params());
        let threads = threads_for(self.threads).clamp(1, self.particles);
        let scorer = || Scorer::new(ctx, self.stride, self.particles.div_ceil(threads));
        match self.crew.as_mut() {
            // Re-initialised: the threads stay, the scorers take the new template.
            Some(crew) if crew.len() == threads => crew.states().for_each(|mut s| *s = scorer()),
            _ => self.crew = Some(Crew::new((0..threads).map(|_| scorer()).collect())),
        }
        Ok(())
    }
    fn model_updated(&mut self, ctx: &mut Context) {
        // The executor sampled the patch its model learnt into the workspace's values.
        if let Some(crew) = self.crew.as_mut()
            && (ctx.am().updates_model() || ctx.am().learns())
        {
            crew.states().for_each(|mut s| s.update_model(ctx.values()));
        }
    }
    fn start_frame(&mut self, ctx: &mut Context) {
        self.round = 0;
        let p = ctx.params();
        if self.last != Some(p) {
            self.states.iter_mut().for_each(|s| *s = p);
        }
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let base = *ctx.problem().template_corners();
        let sigma = self.sigma * self.anneal.powi(self.round as i32);
        self.round += 1;
        // Motion model and measurement, member k of the crew moving and weighing the k-th
        // share of the particles. Particle i of this round draws from its own stream, seeded
        // from the tracker's generator and i: the same numbers whichever thread draws them.
        let round_seed = self.rng.next_u64();
        let crew = self.crew.as_mut().ok_or(LossReason::Singular)?;
        let (states, members, shared) = (&self.states, crew.len(), ctx.problem());
        crew.run(&|scorer: &mut Scorer, k| {
            let mine = share(states.len(), members, k);
            scorer.out.clear();
            scorer.moved.clear();
            scorer.corners.clear();
            for i in mine {
                let mut rng = Rng::new(round_seed.wrapping_add(i as u64));
                let moved = random_warp(shared.ssm(), &base, sigma, &mut rng)
                    .and_then(|q| shared.ssm().compose(&states[i], &q))
                    .filter(|s| s.iter().all(|v| v.is_finite()))
                    .unwrap_or(states[i]);
                let f = scorer.similarity(img, &shared.pixel_matrix(&moved));
                scorer.moved.push(moved);
                scorer
                    .corners
                    .push(crate::ssm::warp_quad(shared.ssm(), &moved, &base));
                scorer.out.push(f);
            }
        });
        let mut filled = 0;
        for scorer in crew.states() {
            let range = filled..filled + scorer.out.len();
            self.sims[range.clone()].copy_from_slice(&scorer.out);
            self.states[range.clone()].copy_from_slice(&scorer.moved);
            self.corners[range].copy_from_slice(&scorer.corners);
            filled += scorer.out.len();
        }
        let best = self.sims.iter().copied().fold(f64::NEG_INFINITY, f64::max);
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
        for (q, &w) in self.corners.iter().zip(&self.weights) {
            for c in 0..4 {
                mean[c].x += w * q.0[c].x;
                mean[c].y += w * q.0[c].y;
            }
        }
        let estimate = ctx
            .ssm()
            .fit(&base.0, &Quad(mean).0)
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .ok_or(LossReason::Singular)?;
        // `corners` and `weights` stay those of the particles before resampling (the teaching
        // view).
        self.resample();
        ctx.set_params(estimate);
        self.last = Some(estimate);
        let f = ctx.similarity_at(img, &estimate);
        Ok(if self.round >= self.rounds {
            Step::done(f)
        } else {
            Step::auto(f)
        })
    }
    fn visual(&mut self, ctx: &Context) -> Option<MethodVisual<'_>> {
        // Where the particles of the last round were (their corners, kept in the order of the
        // weights) and what they weighed.
        let wmax = self.weights.iter().copied().fold(0.0, f64::max).max(1e-300);
        let m = ctx.pixel_matrix(&ctx.ssm().identity());
        self.vis_quads.clear();
        self.vis_weights.clear();
        for (q, &w) in self.corners.iter().zip(&self.weights) {
            self.vis_quads
                .push(q.map(|c| crate::geometry::apply_homography(&m, c)));
            self.vis_weights.push((w / wmax) as f32);
        }
        Some(MethodVisual::quads(
            "particles",
            &self.vis_quads,
            &self.vis_weights,
            None,
        ))
    }
}

/// The particles member `k` of `members` weighs: a contiguous share, the same whatever the
/// thread timing.
fn share(particles: usize, members: usize, k: usize) -> std::ops::Range<usize> {
    k * particles / members..(k + 1) * particles / members
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::am::HessianKind;
    use crate::spec::GridLayout;

    /// A learning model's copies learn what the tracker's does, at their points: its
    /// template's motion left out (the model given the sub-grid's rows of the template's pixel
    /// Jacobian).
    #[test]
    fn the_scorers_copies_of_a_learning_model_leave_the_motion_out() {
        let data = frame();
        let img = ImageView::new(&data, 160, 120, 0, 0);
        let q = Quad::from_rect(40.0, 30.0, 60.0, 50.0);
        let mut ctx = Context::new(
            crate::ssm::build("homography").unwrap(),
            crate::am::build("pca").unwrap(),
            HessianKind::Default,
            50,
        );
        ctx.set_region(&q, 50, GridLayout::Centres).unwrap();
        ctx.sample_template(&img);
        let mut scorer = Scorer::new(&ctx, 2, 10);
        let index = scorer.index.clone();
        let pick = |v: &[f32]| index.iter().map(|&i| v[i]).collect::<Vec<f32>>();
        let jac = ctx.problem().template_motion();
        let dof = ctx.dof();
        let sub: Vec<f32> = jac.chunks_exact(ctx.len()).flat_map(pick).collect();
        let template = pick(ctx.problem().template());
        let mut constrained = crate::am::build("pca").unwrap();
        constrained.set_template(&template);
        constrained.set_motion(&sub, dof);
        let mut free = crate::am::build("pca").unwrap();
        free.set_template(&template);
        // Patches a little off the target (moved, and lit differently), learnt by all three.
        let mut p = ctx.ssm().identity();
        for k in 0..4 {
            p[0] += 0.004;
            p[5] -= 0.003;
            ctx.sample_at(&img, &p);
            let patch: Vec<f32> = ctx
                .values()
                .iter()
                .map(|v| v * (1.0 + 0.02 * k as f32))
                .collect();
            scorer.update_model(&patch);
            let mine = pick(&patch);
            constrained.learn(&mine);
            free.learn(&mine);
        }
        ctx.sample_at(&img, &p);
        let probe = pick(ctx.values());
        let got = scorer.am.similarity(&probe);
        assert_eq!(got, constrained.similarity(&probe));
        assert!((got - free.similarity(&probe)).abs() > 1e-6 * got.abs().max(1.0));
    }

    /// A smooth texture, 160 x 120.
    fn frame() -> Vec<f32> {
        (0..120)
            .flat_map(|y| {
                (0..160).map(move |x| {
                    let (x, y) = (x as f32, y as f32);
                    128.0
                        + 60.0 * (x / 5.0).sin() * (y / 7.0).cos()
                        + 30.0 * (x / 11.0 + y / 13.0).sin()
                })
            })
            .collect()
    }

    #[test]
    fn the_sub_grid_weighs_the_grids_own_samples() {
        let data = frame();
        let img = ImageView::new(&data, 160, 120, 0, 0);
        let q = Quad::from_rect(40.0, 30.0, 60.0, 50.0);
        for am in ["ssd", "zncc", "mi", "lscv"] {
            let mut ctx = Context::new(
                crate::ssm::build("homography").unwrap(),
                crate::am::build(am).unwrap(),
                HessianKind::Default,
                50,
            );
            ctx.set_region(&q, 50, GridLayout::Centres).unwrap();
            ctx.sample_template(&img);
            let auto = Scorer::new(&ctx, 0, 10);
            let expected = if ctx.am().pixelwise() { 625 } else { 2500 };
            assert_eq!(auto.index.len(), expected, "{am}");
            let mut p = ctx.ssm().identity();
            p[0] += 0.02;
            p[7] -= 0.01;
            let m = ctx.pixel_matrix(&p);
            // Every sample: the tracker's similarity itself.
            let mut all = Scorer::new(&ctx, 1, 10);
            assert_eq!(
                all.similarity(&img, &m),
                ctx.similarity_at(&img, &p),
                "{am}"
            );
            // Every other one: the grid's samples there, against the template there.
            let mut half = Scorer::new(&ctx, 2, 10);
            let f = half.similarity(&img, &m);
            assert_eq!(half.index.len(), 625);
            let pick = |v: &[f32]| half.index.iter().map(|&i| v[i]).collect::<Vec<f32>>();
            let (px, py) = ctx.work().points();
            for (k, &i) in half.index.iter().enumerate() {
                assert!((half.px[k] - px[i]).abs() < 1e-4);
                assert!((half.py[k] - py[i]).abs() < 1e-4);
            }
            let mut model = crate::am::build(am).unwrap();
            model.set_template(&pick(ctx.problem().template()));
            let reference = model.similarity(&pick(ctx.values()));
            assert!(
                (f - reference).abs() <= 1e-9 * reference.abs().max(1.0),
                "{am}: {f} {reference}"
            );
        }
    }
}
