//! RCT, the real-time compressive tracker (Zhang, Zhang and Yang, ECCV 2012): each candidate box
//! is described by a few sparse random projections of Haar-like box sums (a very sparse random
//! measurement matrix), classified by a naive Bayes classifier with Gaussian class conditionals
//! that is updated online from positives near the target and negatives around it. Translation
//! only; the search is coarse to fine, as in the fast variant of the same authors.

use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::error::Result;
use crate::geometry::{Point, Quad};
use crate::imaging::Integral;
use crate::observe::MethodVisual;
use crate::observe::Observer;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::rng::Rng;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// RCT's parameters (the paper's values by default).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::int(
        "features",
        "number of compressed features",
        5.0,
        500.0,
        50.0,
    ),
    ParamDef::int(
        "min_rects",
        "fewest Haar-like boxes per feature",
        1.0,
        8.0,
        2.0,
    ),
    ParamDef::int(
        "max_rects",
        "most Haar-like boxes per feature",
        1.0,
        8.0,
        4.0,
    ),
    ParamDef::float(
        "positive_radius",
        "positives are the boxes within this many pixels of the target",
        1.0,
        20.0,
        4.0,
    ),
    ParamDef::float(
        "negative_inner",
        "negatives are at least this many pixels from the target",
        2.0,
        100.0,
        8.0,
    ),
    ParamDef::float("negative_outer", "and at most this many", 4.0, 200.0, 30.0),
    ParamDef::int(
        "negatives",
        "negatives sampled per frame",
        5.0,
        1000.0,
        50.0,
    ),
    ParamDef::float(
        "search_radius",
        "candidates are the boxes within this many pixels of the last position",
        2.0,
        200.0,
        25.0,
    ),
    ParamDef::int(
        "coarse_step",
        "the search first visits every this many pixels, then every pixel around the best (1: exhaustive)",
        1.0,
        10.0,
        4.0,
    ),
    ParamDef::float(
        "learning_rate",
        "weight of the old class model in each update (the paper's lambda)",
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
    name: "rct",
    aliases: &["ct"],
    description: "real-time compressive tracker (Zhang et al. 2012): random Haar-like projections, online naive Bayes, translation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Translation,
        build,
    },
};

/// Builds an RCT tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    let (lo, hi) = (g("min_rects") as usize, g("max_rects") as usize);
    let (inner, outer) = (g("negative_inner"), g("negative_outer"));
    if lo > hi || inner >= outer {
        return Err(crate::Error::InvalidParameter(format!(
            "tracker 'rct': min_rects ({lo}) must not exceed max_rects ({hi}) and negative_inner \
             ({inner}) must be below negative_outer ({outer})"
        )));
    }
    Ok(Box::new(Rct {
        base: Base::new(spec),
        n_features: g("features") as usize,
        rects: (lo, hi),
        pos_radius: g("positive_radius"),
        neg_radius: (inner, outer),
        negatives: g("negatives") as usize,
        search_radius: g("search_radius"),
        coarse_step: g("coarse_step") as i64,
        rate: g("learning_rate"),
        seed: g("seed") as u64,
        model: None,
        vis_quads: Vec::new(),
        vis_weights: Vec::new(),
    }))
}

/// A Haar-like box relative to the target box's top-left corner, with its weight.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x: i64,
    y: i64,
    w: i64,
    h: i64,
    weight: f64,
}

/// A Haar-like feature: the weighted sum of a few boxes of a patch (RCT's compressed features,
/// MIL's weak classifiers' features).
#[derive(Clone, Debug)]
pub(crate) struct Haar(Vec<Rect>);

impl Haar {
    /// `k` boxes of random place and size inside a `bw x bh` patch, each weighted by
    /// `weight(rng)`, drawn after its place.
    pub fn random(
        rng: &mut Rng,
        (bw, bh): (i64, i64),
        k: usize,
        mut weight: impl FnMut(&mut Rng) -> f64,
    ) -> Self {
        Haar(
            (0..k)
                .map(|_| {
                    let x = rng.range(0.0, (bw - 3) as f64) as i64;
                    let y = rng.range(0.0, (bh - 3) as f64) as i64;
                    let w = 1 + rng.range(0.0, (bw - x - 2) as f64) as i64;
                    let h = 1 + rng.range(0.0, (bh - y - 2) as f64) as i64;
                    Rect {
                        x,
                        y,
                        w,
                        h,
                        weight: weight(rng),
                    }
                })
                .collect(),
        )
    }

    /// The feature of the patch whose top-left pixel is `(x, y)`.
    pub fn value(&self, ii: &Integral, x: i64, y: i64) -> f64 {
        self.0
            .iter()
            .map(|r| r.weight * ii.sum(x + r.x, y + r.y, x + r.x + r.w, y + r.y + r.h))
            .sum()
    }
}

/// The Gaussian class conditional of one feature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Gaussian {
    pub mu: f64,
    pub sigma: f64,
}

impl Gaussian {
    /// The running update of the paper: `mu <- l mu + (1-l) mu'`, and the variance blended with
    /// the spread between the means.
    pub fn update(&mut self, values: &[f64], l: f64) {
        let n = values.len().max(1) as f64;
        let mu = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / n;
        let s2 =
            l * self.sigma * self.sigma + (1.0 - l) * var + l * (1.0 - l) * (self.mu - mu).powi(2);
        self.mu = l * self.mu + (1.0 - l) * mu;
        self.sigma = s2.max(0.0).sqrt();
    }

    /// The log-density at `v` (up to the shared constant).
    pub(crate) fn log_density(&self, v: f64) -> f64 {
        let s = self.sigma + 1e-6;
        -s.ln() - 0.5 * ((v - self.mu) / s).powi(2)
    }
}

/// The naive Bayes classifier over compressed features.
#[derive(Clone, Debug)]
pub(crate) struct Classifier {
    pub pos: Vec<Gaussian>,
    pub neg: Vec<Gaussian>,
}

impl Classifier {
    /// `sum_i log p(v_i | target) - log p(v_i | background)` (equal priors).
    pub fn score(&self, v: &[f64]) -> f64 {
        v.iter()
            .zip(self.pos.iter().zip(&self.neg))
            .map(|(&x, (p, n))| p.log_density(x) - n.log_density(x))
            .sum()
    }
}

#[derive(Debug)]
struct Model {
    /// The box's size (whole pixels).
    bw: i64,
    bh: i64,
    features: Vec<Haar>,
    classifier: Classifier,
    rng: Rng,
    first: bool,
}

/// An RCT tracker.
#[derive(Debug)]
pub struct Rct {
    base: Base,
    n_features: usize,
    rects: (usize, usize),
    pos_radius: f64,
    neg_radius: (f64, f64),
    negatives: usize,
    search_radius: f64,
    coarse_step: i64,
    rate: f64,
    seed: u64,
    model: Option<Model>,
    vis_quads: Vec<Quad>,
    vis_weights: Vec<f32>,
}

impl Model {
    /// The compressed features of the box whose top-left pixel is `(x, y)`.
    fn describe(&self, ii: &Integral, x: i64, y: i64, out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.features.iter().map(|f| f.value(ii, x, y)));
    }
}

impl Rct {
    /// The top-left pixel of the box at the current pose.
    fn top_left(&self, m: &Model) -> (i64, i64) {
        (
            (self.base.pose.cx - 0.5 * m.bw as f64).round() as i64,
            (self.base.pose.cy - 0.5 * m.bh as f64).round() as i64,
        )
    }

    /// Updates the class models from positives within the positive radius of `(x, y)` and
    /// negatives sampled in the annulus around it.
    fn learn(&mut self, ii: &Integral, x: i64, y: i64) {
        let Some(m) = self.model.as_mut() else {
            return;
        };
        let nf = m.features.len();
        let mut pos: Vec<Vec<f64>> = vec![Vec::new(); nf];
        let mut neg: Vec<Vec<f64>> = vec![Vec::new(); nf];
        let mut v = Vec::new();
        let r = self.pos_radius.floor() as i64;
        for dy in -r..=r {
            for dx in -r..=r {
                if ((dx * dx + dy * dy) as f64) <= self.pos_radius * self.pos_radius {
                    m.describe(ii, x + dx, y + dy, &mut v);
                    for (i, f) in v.iter().enumerate() {
                        pos[i].push(*f);
                    }
                }
            }
        }
        let (inner, outer) = self.neg_radius;
        for _ in 0..self.negatives {
            let rad = m.rng.range(inner, outer);
            let a = m.rng.range(0.0, 2.0 * std::f64::consts::PI);
            let (dx, dy) = (
                (rad * a.cos()).round() as i64,
                (rad * a.sin()).round() as i64,
            );
            m.describe(ii, x + dx, y + dy, &mut v);
            for (i, f) in v.iter().enumerate() {
                neg[i].push(*f);
            }
        }
        let l = if m.first { 0.0 } else { self.rate };
        m.first = false;
        for i in 0..nf {
            m.classifier.pos[i].update(&pos[i], l);
            m.classifier.neg[i].update(&neg[i], l);
        }
    }
}

impl WholeTracker for Rct {
    const MIN_SIDE: f64 = 6.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let (tw, th) = self.base.size0;
        let (bw, bh) = (tw.round() as i64, th.round() as i64);
        let mut rng = Rng::new(self.seed);
        let features = (0..self.n_features)
            .map(|_| {
                let k = self.rects.0
                    + (rng.uniform() * (self.rects.1 - self.rects.0 + 1) as f64) as usize;
                let k = k.min(self.rects.1).max(1);
                Haar::random(&mut rng, (bw, bh), k, |rng| {
                    let sign = if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
                    sign / (k as f64).sqrt()
                })
            })
            .collect();
        let g = Gaussian {
            mu: 0.0,
            sigma: 1.0,
        };
        self.model = Some(Model {
            bw,
            bh,
            features,
            classifier: Classifier {
                pos: vec![g; self.n_features],
                neg: vec![g; self.n_features],
            },
            rng,
            first: true,
        });
        let img = frame_f32(input);
        let ii = Integral::new(&img);
        let Some(m) = self.model.as_ref() else {
            return Ok(());
        };
        let (x, y) = self.top_left(m);
        self.learn(&ii, x, y);
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.base.status != TrackStatus::Tracking || self.model.is_none() {
            return self.base.idle();
        }
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let ii = Integral::new(&img);
        let preprocess = started.elapsed();
        let Some(m) = self.model.as_ref() else {
            return self.base.idle();
        };
        let (x0, y0) = self.top_left(m);
        let want = observer.wants_method_visuals();
        let mut v = Vec::new();
        let mut visited: Vec<(i64, i64, f64)> = Vec::new();
        let best = super::search_disc((x0, y0), self.search_radius, self.coarse_step, |x, y| {
            m.describe(&ii, x, y, &mut v);
            let s = m.classifier.score(&v);
            if want {
                visited.push((x, y, s));
            }
            s
        });
        let (bw, bh) = (m.bw, m.bh);
        let pose = Pose {
            cx: self.base.pose.cx + (best.0 - x0) as f64,
            cy: self.base.pose.cy + (best.1 - y0) as f64,
            ..self.base.pose
        };
        let found = if best.2.is_finite() {
            Ok((pose, best.2))
        } else {
            Err(crate::status::LossReason::NonFinite)
        };
        if found.is_ok() {
            self.learn(&ii, best.0, best.1);
        }
        self.vis_quads.clear();
        self.vis_weights.clear();
        if want && !visited.is_empty() {
            // Each visited candidate's centre, weighted by its score relative to the best.
            let top = best.2;
            let lo = visited.iter().map(|c| c.2).fold(f64::INFINITY, f64::min);
            for &(x, y, s) in &visited {
                let c = Point {
                    x: x as f64 + 0.5 * bw as f64,
                    y: y as f64 + 0.5 * bh as f64,
                };
                self.vis_quads
                    .push(Quad::from_rect(c.x - 0.5, c.y - 0.5, 1.0, 1.0));
                self.vis_weights
                    .push(((s - lo) / (top - lo).max(1e-9)).clamp(0.0, 1.0) as f32);
            }
        }
        let visual = want
            .then(|| MethodVisual::quads("candidates", &self.vis_quads, &self.vis_weights, None));
        self.base
            .finish(found, input.size(), started, preprocess, observer, visual)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_running_gaussian_update_matches_the_paper_and_the_classifier_prefers_its_class() {
        let mut g = Gaussian {
            mu: 0.0,
            sigma: 1.0,
        };
        g.update(&[2.0, 4.0], 0.0);
        assert_eq!(
            g,
            Gaussian {
                mu: 3.0,
                sigma: 1.0
            }
        );
        g.update(&[5.0, 5.0], 0.5);
        // mu = 0.5*3 + 0.5*5; var = 0.5*1 + 0.5*0 + 0.25*(3-5)^2.
        assert!((g.mu - 4.0).abs() < 1e-12 && (g.sigma - 1.5f64.sqrt()).abs() < 1e-12);
        let c = Classifier {
            pos: vec![
                Gaussian {
                    mu: 10.0,
                    sigma: 2.0
                };
                3
            ],
            neg: vec![
                Gaussian {
                    mu: 0.0,
                    sigma: 2.0
                };
                3
            ],
        };
        assert!(c.score(&[9.0, 11.0, 10.0]) > 0.0 && c.score(&[1.0, -1.0, 0.0]) < 0.0);
        // Equidistant from both means with equal spreads: no preference.
        assert!(c.score(&[5.0, 5.0, 5.0]).abs() < 1e-9);
    }
}
