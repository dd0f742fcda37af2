//! MIL, tracking with online multiple instance learning (Babenko, Yang and Belongie, CVPR 2009):
//! a boosted classifier of Haar-like features learned from *bags*: the patches near the tracked
//! position form one positive bag (at least one of them is the target: the tracker need not
//! know which), each patch of an annulus around it a negative bag. Every feature of a pool has
//! a weak classifier, the log-ratio of two Gaussian class models updated online; each frame
//! the strong classifier is chosen again from the pool, greedily, feature by feature, maximising
//! the bags' log-likelihood under the noisy-OR model (the positive bag is likely when one of its
//! patches is). The target moves to the patch of the search radius the strong classifier rates
//! highest. Translation only.

use super::rct::{Gaussian, Haar};
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

/// MIL's parameters (the paper's values by default).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::int(
        "pool",
        "Haar-like features in the pool",
        10.0,
        1000.0,
        250.0,
    ),
    ParamDef::int(
        "selected",
        "features the strong classifier picks from the pool each frame",
        1.0,
        200.0,
        50.0,
    ),
    ParamDef::float(
        "positive_radius",
        "the positive bag is the patches within this many pixels of the target",
        1.0,
        20.0,
        4.0,
    ),
    ParamDef::float(
        "negative_inner",
        "negative patches are at least this many pixels from the target",
        2.0,
        100.0,
        8.0,
    ),
    ParamDef::float("negative_outer", "and at most this many", 4.0, 200.0, 50.0),
    ParamDef::int(
        "negatives",
        "negative patches sampled per frame",
        5.0,
        1000.0,
        65.0,
    ),
    ParamDef::float(
        "search_radius",
        "the target is searched within this many pixels of its last position",
        2.0,
        200.0,
        35.0,
    ),
    ParamDef::int(
        "coarse_step",
        "the search first visits every this many pixels, then every pixel around the best (1: exhaustive)",
        1.0,
        10.0,
        2.0,
    ),
    ParamDef::float(
        "learning_rate",
        "weight of the old class models in each update",
        0.0,
        1.0,
        0.85,
    ),
    ParamDef::int(
        "seed",
        "seed of the random features and negatives",
        0.0,
        1e9,
        0.0,
    ),
];

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "mil",
    aliases: &["miltrack"],
    description: "online multiple instance learning (Babenko et al. 2009): Haar-like features, Gaussian weak classifiers, MILBoost over bags, translation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Translation,
        build,
    },
};

/// Builds a MIL tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    let (inner, outer) = (g("negative_inner"), g("negative_outer"));
    let (pool, selected) = (g("pool") as usize, g("selected") as usize);
    if inner >= outer || selected > pool {
        return Err(crate::Error::InvalidParameter(format!(
            "tracker 'mil': negative_inner ({inner}) must be below negative_outer ({outer}) and \
             selected ({selected}) must not exceed pool ({pool})"
        )));
    }
    Ok(Box::new(Mil {
        base: Base::new(spec),
        pool,
        selected,
        pos_radius: g("positive_radius"),
        neg_radius: (inner, outer),
        negatives: g("negatives") as usize,
        search_radius: g("search_radius"),
        coarse_step: g("coarse_step") as i64,
        rate: g("learning_rate"),
        seed: g("seed") as u64,
        model: None,
        values: Vec::new(),
    }))
}

/// A weak classifier: the feature's Gaussian models of the target and of the background.
#[derive(Clone, Debug)]
struct Weak {
    feature: Haar,
    pos: Gaussian,
    neg: Gaussian,
}

impl Weak {
    fn value(&self, ii: &Integral, x: i64, y: i64) -> f64 {
        self.feature.value(ii, x, y)
    }

    /// `log p(v | target) - log p(v | background)`.
    fn response(&self, v: f64) -> f64 {
        self.pos.log_density(v) - self.neg.log_density(v)
    }
}

/// `log(1 - sigmoid(z))`, stable: `-softplus(z)`.
fn log_not(z: f64) -> f64 {
    if z > 0.0 {
        -z - (-z).exp().ln_1p()
    } else {
        -(z.exp().ln_1p())
    }
}

/// The log-likelihood of the bags under the noisy-OR model: the positive bag (scores `pos`)
/// is likely when one of its patches is, each negative patch (scores `neg`) a bag of its own.
pub(crate) fn bag_log_likelihood(pos: &[f64], neg: &[f64]) -> f64 {
    // log(1 - prod_j (1 - p_j)) with sum_j -log(1 - p_j) = s.
    let s: f64 = pos.iter().map(|&z| -log_not(z)).sum();
    let positive = if s > 1e-12 {
        (-(-s).exp_m1()).ln()
    } else {
        s.max(1e-300).ln()
    };
    positive + neg.iter().map(|&z| log_not(z)).sum::<f64>()
}

/// The greedy MILBoost choice: `k` of the weak classifiers, each in turn the one whose response
/// added to the strong classifier so far most raises the bags' log-likelihood. `responses[m]`
/// holds classifier `m`'s responses on the positive patches, then the negatives (`n_pos` of
/// the first).
pub(crate) fn choose(responses: &[Vec<f64>], n_pos: usize, k: usize) -> Vec<usize> {
    let n = responses.first().map_or(0, Vec::len);
    let mut strong = vec![0.0; n];
    let mut trial = vec![0.0; n];
    let mut chosen: Vec<usize> = Vec::with_capacity(k);
    for _ in 0..k.min(responses.len()) {
        let mut best = (usize::MAX, f64::NEG_INFINITY);
        for (m, r) in responses.iter().enumerate() {
            if chosen.contains(&m) {
                continue;
            }
            for ((t, s), v) in trial.iter_mut().zip(&strong).zip(r) {
                *t = s + v;
            }
            let l = bag_log_likelihood(&trial[..n_pos], &trial[n_pos..]);
            if l > best.1 {
                best = (m, l);
            }
        }
        if best.0 == usize::MAX {
            break;
        }
        for (s, v) in strong.iter_mut().zip(&responses[best.0]) {
            *s += v;
        }
        chosen.push(best.0);
    }
    chosen
}

#[derive(Debug)]
struct Model {
    bw: i64,
    bh: i64,
    pool: Vec<Weak>,
    selected: Vec<usize>,
    rng: Rng,
    first: bool,
}

/// A MIL tracker.
#[derive(Debug)]
pub struct Mil {
    base: Base,
    pool: usize,
    selected: usize,
    pos_radius: f64,
    neg_radius: (f64, f64),
    negatives: usize,
    search_radius: f64,
    coarse_step: i64,
    rate: f64,
    seed: u64,
    model: Option<Model>,
    /// Each weak classifier's feature values on the frame's samples.
    values: Vec<Vec<f64>>,
}

impl Mil {
    fn top_left(&self, m: &Model) -> (i64, i64) {
        (
            (self.base.pose.cx - 0.5 * m.bw as f64).round() as i64,
            (self.base.pose.cy - 0.5 * m.bh as f64).round() as i64,
        )
    }

    /// Samples the bags around `(x, y)`, updates every weak classifier's class models and
    /// chooses the strong classifier again.
    fn learn(&mut self, ii: &Integral, x: i64, y: i64) {
        let Some(m) = self.model.as_mut() else {
            return;
        };
        let mut at: Vec<(i64, i64)> = Vec::new();
        let r = self.pos_radius.floor() as i64;
        for dy in -r..=r {
            for dx in -r..=r {
                if ((dx * dx + dy * dy) as f64) <= self.pos_radius * self.pos_radius {
                    at.push((x + dx, y + dy));
                }
            }
        }
        let n_pos = at.len();
        let (inner, outer) = self.neg_radius;
        for _ in 0..self.negatives {
            let rad = m.rng.range(inner, outer);
            let a = m.rng.range(0.0, 2.0 * std::f64::consts::PI);
            at.push((
                x + (rad * a.cos()).round() as i64,
                y + (rad * a.sin()).round() as i64,
            ));
        }
        self.values.resize(m.pool.len(), Vec::new());
        let l = if m.first { 0.0 } else { self.rate };
        m.first = false;
        for (w, v) in m.pool.iter_mut().zip(self.values.iter_mut()) {
            v.clear();
            v.extend(at.iter().map(|&(px, py)| w.value(ii, px, py)));
            w.pos.update(&v[..n_pos], l);
            w.neg.update(&v[n_pos..], l);
        }
        // The responses of the updated classifiers, for the choice.
        let responses: Vec<Vec<f64>> = m
            .pool
            .iter()
            .zip(&self.values)
            .map(|(w, v)| v.iter().map(|&f| w.response(f)).collect())
            .collect();
        m.selected = choose(&responses, n_pos, self.selected);
    }
}

impl WholeTracker for Mil {
    const MIN_SIDE: f64 = 6.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let (tw, th) = self.base.size0;
        let (bw, bh) = (tw.round() as i64, th.round() as i64);
        let mut rng = Rng::new(self.seed);
        let g = Gaussian {
            mu: 0.0,
            sigma: 1.0,
        };
        let pool = (0..self.pool)
            .map(|_| {
                // 2 to 4 boxes of random size and place, weights in [-1, 1].
                let k = 2 + (rng.uniform() * 3.0) as usize;
                let feature =
                    Haar::random(&mut rng, (bw, bh), k.min(4), |rng| rng.range(-1.0, 1.0));
                Weak {
                    feature,
                    pos: g,
                    neg: g,
                }
            })
            .collect();
        self.model = Some(Model {
            bw,
            bh,
            pool,
            selected: Vec::new(),
            rng,
            first: true,
        });
        let img = frame_f32(input);
        let ii = Integral::new(&img);
        if let Some(m) = self.model.as_ref() {
            let (x, y) = self.top_left(m);
            self.learn(&ii, x, y);
        }
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.base.status != TrackStatus::Tracking {
            return self.base.idle();
        }
        let Some(m) = self.model.as_ref() else {
            return self.base.idle();
        };
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let ii = Integral::new(&img);
        let preprocess = started.elapsed();
        let (x0, y0) = self.top_left(m);
        let score = |x: i64, y: i64| -> f64 {
            m.selected
                .iter()
                .map(|&k| {
                    let w = &m.pool[k];
                    w.response(w.value(&ii, x, y))
                })
                .sum()
        };
        let best = super::search_disc((x0, y0), self.search_radius, self.coarse_step, score);
        let (bw, bh) = (m.bw as f64, m.bh as f64);
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
        let r = self.search_radius;
        let quads = [Quad::from_rect(
            best.0 as f64 - r,
            best.1 as f64 - r,
            bw + 2.0 * r,
            bh + 2.0 * r,
        )];
        let visual = want.then(|| MethodVisual::quads("search region", &quads, &[1.0], None));
        self.base
            .finish(found, input.size(), started, preprocess, observer, visual)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bag_likelihood_rewards_one_good_positive_and_rejected_negatives() {
        // One confident positive in the bag is enough.
        let one = bag_log_likelihood(&[-5.0, 8.0, -5.0], &[-6.0]);
        let none = bag_log_likelihood(&[-5.0, -5.0, -5.0], &[-6.0]);
        assert!(one > none && one > -0.01, "{one} {none}");
        // A negative rated high costs.
        assert!(bag_log_likelihood(&[8.0], &[6.0]) < bag_log_likelihood(&[8.0], &[-6.0]));
        // Matches the definition where it is not extreme.
        let sig = |z: f64| 1.0 / (1.0 + (-z).exp());
        let p = 1.0 - (1.0 - sig(0.3)) * (1.0 - sig(-1.0));
        let direct = p.ln() + (1.0 - sig(0.5)).ln();
        assert!((bag_log_likelihood(&[0.3, -1.0], &[0.5]) - direct).abs() < 1e-12);
    }

    #[test]
    fn milboost_chooses_the_feature_that_separates_the_bags_first() {
        // Two positives, two negatives; feature 1 separates them, 0 and 2 do not.
        let responses = vec![
            vec![0.1, -0.1, 0.1, -0.1],
            vec![3.0, 2.0, -3.0, -2.0],
            vec![-1.0, -1.0, 1.0, 1.0],
        ];
        let chosen = choose(&responses, 2, 2);
        assert_eq!(chosen[0], 1);
        assert_eq!(chosen.len(), 2);
        assert!(!chosen[1..].contains(&1));
    }
}
