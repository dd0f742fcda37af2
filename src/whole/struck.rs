//! Struck, structured output tracking with kernels (Hare, Saffari and Torr, ICCV 2011): instead of
//! a classifier of patches, a function `F(x, y)` of a frame and a displacement `y` of the box,
//! learned so that the true displacement scores above every other by a margin of the loss
//! `1 - IoU` between their boxes (a structured output SVM). `F` is a kernel expansion over
//! support vectors `(pattern, displacement, beta)`; the dual is optimised online by
//! sequential minimal steps on pairs of one pattern's support vectors (the paper's
//! ProcessNew, ProcessOld and Optimize), and a budget bounds the support vectors: past it, the
//! negative one whose removal changes `F` least is folded into its pattern's positive one.
//! Features: the box's 16 x 16 block means (in [0, 1]), a Gaussian kernel. Translation only.

use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::error::Result;
use crate::geometry::Quad;
use crate::imaging::Integral;
use crate::observe::{MethodVisual, Observer};
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::rng::Rng;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// Struck's parameters (the paper's values by default, but the kernel's width).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::float("c", "the SVM's slack penalty C", 0.01, 1e4, 100.0),
    ParamDef::int("budget", "most support vectors kept", 4.0, 1000.0, 100.0),
    ParamDef::float(
        "kernel_sigma",
        "the Gaussian kernel's exp(-sigma |a - b|^2) (chosen on renders: docs/learning.md)",
        1e-4,
        10.0,
        1.0,
    ),
    ParamDef::float(
        "search_radius",
        "the target is searched within this many pixels of its last position",
        2.0,
        200.0,
        30.0,
    ),
    ParamDef::int(
        "coarse_step",
        "the search first visits every this many pixels, then every pixel around the best (1: exhaustive)",
        1.0,
        10.0,
        2.0,
    ),
    ParamDef::int(
        "seed",
        "seed of the choice of old patterns to revisit",
        0.0,
        1e9,
        0.0,
    ),
];

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "struck",
    aliases: &[],
    description: "structured output SVM (Hare et al. 2011): kernel F(x, y) over box displacements, margin 1 - IoU, online SMO with a budget, translation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Translation,
        build,
    },
};

/// Builds a Struck tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    Ok(Box::new(Struck {
        base: Base::new(spec),
        c: g("c"),
        budget: g("budget") as usize,
        sigma: g("kernel_sigma"),
        search_radius: g("search_radius"),
        coarse_step: g("coarse_step") as i64,
        rng: Rng::new(g("seed") as u64),
        box_size: (0, 0),
        outputs: training_outputs(g("search_radius")),
        patterns: Vec::new(),
        svs: Vec::new(),
    }))
}

/// Cells of the feature's grid, a side.
const GRID: usize = 16;
/// Old patterns revisited a frame, and optimisation steps after each (the paper's n_R, n_O).
const REVISITS: usize = 10;
const STEPS: usize = 10;

/// The feature of the box whose top-left is `(x, y)`: its `GRID x GRID` block means / 255.
fn feature(ii: &Integral, (x, y): (i64, i64), (bw, bh): (i64, i64), out: &mut Vec<f32>) {
    out.clear();
    for j in 0..GRID as i64 {
        let (y0, y1) = (y + j * bh / GRID as i64, y + (j + 1) * bh / GRID as i64);
        for i in 0..GRID as i64 {
            let (x0, x1) = (x + i * bw / GRID as i64, x + (i + 1) * bw / GRID as i64);
            let area = ((x1 - x0).max(1) * (y1 - y0).max(1)) as f64;
            out.push((ii.sum(x0, y0, x1.max(x0 + 1), y1.max(y0 + 1)) / area / 255.0) as f32);
        }
    }
}

/// The loss between displacements `a` and `b` of a `w x h` box: 1 - IoU of the boxes.
pub(crate) fn loss(a: (i64, i64), b: (i64, i64), (w, h): (i64, i64)) -> f64 {
    let ox = (w - (a.0 - b.0).abs()).max(0) as f64;
    let oy = (h - (a.1 - b.1).abs()).max(0) as f64;
    let inter = ox * oy;
    1.0 - inter / (2.0 * (w * h) as f64 - inter)
}

/// The displacements a pattern is learned on: the origin and a polar grid of 5 radii and 16
/// angles out to `radius`.
fn training_outputs(radius: f64) -> Vec<(i64, i64)> {
    let mut out = vec![(0, 0)];
    for r in 1..=5 {
        let rad = radius * r as f64 / 5.0;
        for a in 0..16 {
            let t = a as f64 * std::f64::consts::PI / 8.0;
            let p = (
                (rad * t.cos()).round() as i64,
                (rad * t.sin()).round() as i64,
            );
            if !out.contains(&p) {
                out.push(p);
            }
        }
    }
    out
}

/// A frame learned on: the features of its boxes displaced by each of [`Struck::outputs`] (the
/// first the true one).
#[derive(Debug)]
struct Pattern {
    features: Vec<Vec<f32>>,
}

/// A support vector: a pattern's displacement with its coefficient and the gradient
/// `g = -loss(y, y_true) - F(x, y)`.
#[derive(Clone, Copy, Debug)]
struct Sv {
    pattern: usize,
    output: usize,
    beta: f64,
    grad: f64,
}

/// A Struck tracker.
#[derive(Debug)]
pub struct Struck {
    base: Base,
    c: f64,
    budget: usize,
    sigma: f64,
    search_radius: f64,
    coarse_step: i64,
    rng: Rng,
    box_size: (i64, i64),
    /// The displacements every frame is learned on ([`training_outputs`]).
    outputs: Vec<(i64, i64)>,
    /// Patterns (`None` once no support vector refers to them).
    patterns: Vec<Option<Pattern>>,
    svs: Vec<Sv>,
}

impl Struck {
    fn feat(&self, sv: &Sv) -> &[f32] {
        match &self.patterns[sv.pattern] {
            Some(p) => &p.features[sv.output],
            None => &[],
        }
    }

    fn kernel(&self, a: &[f32], b: &[f32]) -> f64 {
        let d: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
        (-self.sigma * d as f64).exp()
    }

    /// `F` at a feature.
    fn score(&self, f: &[f32]) -> f64 {
        self.svs
            .iter()
            .map(|s| s.beta * self.kernel(self.feat(s), f))
            .sum()
    }

    /// `-loss - F` of output `o` of pattern `p`.
    fn gradient(&self, p: usize, o: usize) -> f64 {
        let Some(pat) = &self.patterns[p] else {
            return 0.0;
        };
        -loss(self.outputs[o], self.outputs[0], self.box_size) - self.score(&pat.features[o])
    }

    /// The index of the support vector of `(p, o)`, added (beta 0) if it is not one.
    fn sv_of(&mut self, p: usize, o: usize) -> usize {
        if let Some(i) = self
            .svs
            .iter()
            .position(|s| s.pattern == p && s.output == o)
        {
            return i;
        }
        let grad = self.gradient(p, o);
        self.svs.push(Sv {
            pattern: p,
            output: o,
            beta: 0.0,
            grad,
        });
        self.svs.len() - 1
    }

    /// One sequential minimal step on the support vectors `i` (up) and `j` (down) of one
    /// pattern.
    fn smo(&mut self, i: usize, j: usize) {
        if i == j {
            return;
        }
        let (fi, fj) = (
            self.feat(&self.svs[i]).to_vec(),
            self.feat(&self.svs[j]).to_vec(),
        );
        let kij = self.kernel(&fi, &fj);
        let denom = 2.0 - 2.0 * kij;
        if denom <= 1e-12 {
            return;
        }
        let (si, sj) = (self.svs[i], self.svs[j]);
        let unc = (si.grad - sj.grad) / denom;
        let bound = if si.output == 0 { self.c } else { 0.0 } - si.beta;
        let l = unc.min(bound).max(0.0);
        if l <= 0.0 {
            return;
        }
        self.svs[i].beta += l;
        self.svs[j].beta -= l;
        let d: Vec<f64> = self
            .svs
            .iter()
            .map(|k| {
                let fk = self.feat(k);
                self.kernel(fk, &fi) - self.kernel(fk, &fj)
            })
            .collect();
        for (k, d) in self.svs.iter_mut().zip(d) {
            k.grad -= l * d;
        }
    }

    /// Drops the support vectors whose coefficient is zero, and the patterns left without any.
    fn prune(&mut self) {
        self.svs.retain(|s| s.beta.abs() > 1e-9);
        for (p, pat) in self.patterns.iter_mut().enumerate() {
            if pat.is_some() && !self.svs.iter().any(|s| s.pattern == p) {
                *pat = None;
            }
        }
    }

    /// The paper's ProcessNew (`old` false: the new pattern, up on its true output) or
    /// ProcessOld (a pattern seen before, up on its best support vector): down on its output
    /// of least gradient.
    fn process(&mut self, p: usize, old: bool) {
        if self.patterns[p].is_none() {
            return;
        }
        let n = self.outputs.len();
        let grads: Vec<f64> = (0..n).map(|o| self.gradient(p, o)).collect();
        let down = (0..n)
            .min_by(|&a, &b| grads[a].total_cmp(&grads[b]))
            .unwrap_or(0);
        let up = if old {
            let c = self.c;
            match self
                .svs
                .iter()
                .enumerate()
                .filter(|(_, s)| s.pattern == p && s.beta < if s.output == 0 { c } else { 0.0 })
                .max_by(|a, b| a.1.grad.total_cmp(&b.1.grad))
            {
                Some((_, s)) => s.output,
                None => return,
            }
        } else {
            0
        };
        let i = self.sv_of(p, up);
        let j = self.sv_of(p, down);
        self.smo(i, j);
    }

    /// The paper's Optimize: a step between two of a pattern's support vectors.
    fn optimize(&mut self, p: usize) {
        let c = self.c;
        let mine: Vec<usize> = (0..self.svs.len())
            .filter(|&k| self.svs[k].pattern == p)
            .collect();
        let up = mine
            .iter()
            .copied()
            .filter(|&k| {
                let s = &self.svs[k];
                s.beta < if s.output == 0 { c } else { 0.0 }
            })
            .max_by(|&a, &b| self.svs[a].grad.total_cmp(&self.svs[b].grad));
        let down = mine
            .iter()
            .copied()
            .min_by(|&a, &b| self.svs[a].grad.total_cmp(&self.svs[b].grad));
        if let (Some(i), Some(j)) = (up, down) {
            self.smo(i, j);
        }
    }

    /// Past the budget: the negative support vector whose removal changes `F` least is folded
    /// into its pattern's positive one.
    fn enforce_budget(&mut self) {
        while self.svs.len() > self.budget {
            let mut best: Option<(usize, usize, f64)> = None;
            for (r, s) in self.svs.iter().enumerate() {
                if s.beta >= 0.0 {
                    continue;
                }
                let Some(pos) = self
                    .svs
                    .iter()
                    .position(|t| t.pattern == s.pattern && t.output == 0)
                else {
                    continue;
                };
                let k = self.kernel(self.feat(s), self.feat(&self.svs[pos]));
                let change = s.beta * s.beta * (2.0 - 2.0 * k);
                if best.is_none_or(|b| change < b.2) {
                    best = Some((r, pos, change));
                }
            }
            let Some((r, pos, _)) = best else { break };
            let (fr, fp) = (
                self.feat(&self.svs[r]).to_vec(),
                self.feat(&self.svs[pos]).to_vec(),
            );
            let b = self.svs[r].beta;
            self.svs[pos].beta += b;
            let d: Vec<f64> = self
                .svs
                .iter()
                .map(|k| {
                    let fk = self.feat(k);
                    self.kernel(fk, &fp) - self.kernel(fk, &fr)
                })
                .collect();
            for (k, d) in self.svs.iter_mut().zip(d) {
                k.grad -= b * d;
            }
            self.svs.swap_remove(r);
            self.prune();
        }
    }

    /// Learns the frame with the target's box at `(x, y)`.
    fn learn(&mut self, ii: &Integral, x: i64, y: i64) {
        let mut features = Vec::with_capacity(self.outputs.len());
        let mut f = Vec::new();
        for &(dx, dy) in &self.outputs {
            feature(ii, (x + dx, y + dy), self.box_size, &mut f);
            features.push(f.clone());
        }
        let p = match self.patterns.iter().position(Option::is_none) {
            Some(free) => free,
            None => {
                self.patterns.push(None);
                self.patterns.len() - 1
            }
        };
        self.patterns[p] = Some(Pattern { features });
        self.process(p, false);
        self.prune();
        self.enforce_budget();
        for _ in 0..REVISITS {
            let live: Vec<usize> = (0..self.patterns.len())
                .filter(|&q| self.patterns[q].is_some())
                .collect();
            if live.is_empty() {
                break;
            }
            let q = live[((self.rng.uniform() * live.len() as f64) as usize).min(live.len() - 1)];
            self.process(q, true);
            self.prune();
            self.enforce_budget();
            for _ in 0..STEPS {
                let live: Vec<usize> = (0..self.patterns.len())
                    .filter(|&q| self.patterns[q].is_some())
                    .collect();
                if live.is_empty() {
                    break;
                }
                let q =
                    live[((self.rng.uniform() * live.len() as f64) as usize).min(live.len() - 1)];
                self.optimize(q);
                self.prune();
            }
        }
    }

    fn top_left(&self) -> (i64, i64) {
        (
            (self.base.pose.cx - 0.5 * self.box_size.0 as f64).round() as i64,
            (self.base.pose.cy - 0.5 * self.box_size.1 as f64).round() as i64,
        )
    }
}

impl WholeTracker for Struck {
    const MIN_SIDE: f64 = 8.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let (tw, th) = self.base.size0;
        self.box_size = (tw.round() as i64, th.round() as i64);
        self.patterns.clear();
        self.svs.clear();
        let img = frame_f32(input);
        let ii = Integral::new(&img);
        let (x, y) = self.top_left();
        self.learn(&ii, x, y);
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.base.status != TrackStatus::Tracking {
            return self.base.idle();
        }
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let ii = Integral::new(&img);
        let preprocess = started.elapsed();
        let (x0, y0) = self.top_left();
        let mut f = Vec::new();
        let best = super::search_disc((x0, y0), self.search_radius, self.coarse_step, |x, y| {
            feature(&ii, (x, y), self.box_size, &mut f);
            self.score(&f)
        });
        let pose = Pose {
            cx: self.base.pose.cx + (best.0 - x0) as f64,
            cy: self.base.pose.cy + (best.1 - y0) as f64,
            ..self.base.pose
        };
        let found = if best.2.is_finite() {
            Ok((pose, best.2))
        } else {
            Err(LossReason::NonFinite)
        };
        if found.is_ok() {
            self.learn(&ii, best.0, best.1);
        }
        let want = observer.wants_method_visuals();
        // The first support vectors, as the boxes their displacements put around the target.
        let quads: Vec<Quad> = if want {
            self.svs
                .iter()
                .take(8)
                .map(|s| {
                    let (dx, dy) = self.outputs[s.output];
                    Quad::from_rect(
                        (best.0 + dx) as f64,
                        (best.1 + dy) as f64,
                        self.box_size.0 as f64,
                        self.box_size.1 as f64,
                    )
                })
                .collect()
        } else {
            Vec::new()
        };
        let weights = vec![0.5f32; quads.len()];
        let visual = want.then(|| MethodVisual::quads("support vectors", &quads, &weights, None));
        self.base
            .finish(found, input.size(), started, preprocess, observer, visual)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loss_is_one_minus_the_boxes_iou_and_the_grid_is_polar() {
        assert_eq!(loss((0, 0), (0, 0), (10, 10)), 0.0);
        assert_eq!(loss((10, 0), (0, 0), (10, 10)), 1.0);
        // Half overlap in x: IoU = 50 / 150.
        assert!((loss((5, 0), (0, 0), (10, 10)) - (1.0 - 50.0 / 150.0)).abs() < 1e-12);
        let o = training_outputs(30.0);
        assert_eq!(o[0], (0, 0));
        assert_eq!(o.len(), 81);
        assert!(
            o.iter()
                .all(|&(x, y)| ((x * x + y * y) as f64).sqrt() <= 30.5)
        );
    }

    #[test]
    fn a_learned_frame_scores_the_true_box_above_the_displaced_ones() {
        use crate::imaging::GrayF32;
        let img = GrayF32 {
            width: 120,
            height: 100,
            data: (0..12000)
                .map(|i| {
                    let (x, y) = ((i % 120) as f64, (i / 120) as f64);
                    (128.0 + 100.0 * (x / 5.0).sin() * (y / 7.0).cos()) as f32
                })
                .collect(),
        };
        let ii = Integral::new(&img);
        let spec = WholeSpec {
            tracker: "struck".into(),
            method: crate::params::MethodParams::default(),
        };
        let mut s = Struck {
            base: Base::new(&spec),
            c: 100.0,
            budget: 100,
            sigma: 0.2,
            search_radius: 30.0,
            coarse_step: 2,
            rng: Rng::new(0),
            box_size: (30, 24),
            outputs: training_outputs(30.0),
            patterns: Vec::new(),
            svs: Vec::new(),
        };
        s.learn(&ii, 45, 38);
        // Sum of the coefficients is zero per pattern; the true output's is positive.
        let sum: f64 = s.svs.iter().map(|v| v.beta).sum();
        assert!(sum.abs() < 1e-9 && s.svs.iter().any(|v| v.output == 0 && v.beta > 0.0));
        let mut f = Vec::new();
        feature(&ii, (45, 38), (30, 24), &mut f);
        let at = s.score(&f);
        for d in [(6, 0), (0, -6), (10, 10)] {
            feature(&ii, (45 + d.0, 38 + d.1), (30, 24), &mut f);
            assert!(s.score(&f) < at, "{d:?}");
        }
        assert!(s.svs.len() <= 100);
    }
}
