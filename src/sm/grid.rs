//! The grid tracker (MTF's `GridTracker`, Singh and Jagersand): a `grid_res x grid_res` lattice
//! of small square patches over the target, each followed from the previous frame by its own
//! translation tracker (inverse-compositional Lucas-Kanade on the patch's pixels), and the
//! target's warp fitted robustly to the patches' motions: the homography that takes where the
//! patches were to where they are now (RANSAC by default, least median of squares, or least
//! squares), applied to the target's corners, the SSM then fitted to them. A patch that leaves
//! the target (an occluder, a specular spot) moves unlike the others and drops out of the fit.
//! Each frame the patches are laid anew on the lattice at the estimate, their templates taken
//! from that frame (MTF's `grid_reset_at_each_frame=1`).
//!
//! It takes one step per frame. Its precision is that of the patches' Lucas-Kanade (a few
//! hundredths of a pixel on a textured target), its basin that of a patch (a few pixels at the
//! sampling methods' smoothing), and it needs no derivatives of the AM: the AM only reports the
//! similarity where it ended. `rklt` refines its estimate with a registration tracker.

use super::robust::{self, Estimator, Robust};
use super::{Context, LossReason, MethodVisual, SearchMethod, SmConfig, SmDef, Step};
use crate::am::Capabilities;
use crate::geometry::{Point, Quad, apply_homography};
use crate::imaging::{ImageView, sample_values, sample_values_gradients};
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::rng::Rng;

/// The grid's parameters (shared with `rklt`).
pub const GRID_PARAMS: [ParamDef; 5] = [
    ParamDef::int(
        "grid_res",
        "patches per side of the grid over the target",
        2.0,
        30.0,
        10.0,
    ),
    ParamDef::int(
        "patch_size",
        "side of a patch (px of the frame)",
        4.0,
        64.0,
        10.0,
    ),
    ParamDef::int(
        "patch_iters",
        "Lucas-Kanade iterations of a patch per frame",
        1.0,
        100.0,
        20.0,
    ),
    ParamDef::choice(
        "estimator",
        "how the target's warp is fitted to the patches' motions: RANSAC, least median of squares, or least squares",
        &Estimator::NAMES,
    ),
    ParamDef::float(
        "inlier_px",
        "RANSAC's inlier threshold (px of reprojection error)",
        0.1,
        100.0,
        2.0,
    ),
];

pub const ENTRY: Entry<SmDef> = Entry {
    name: "grid",
    aliases: &["gt", "grid_tracker"],
    description: "grid of translation patch trackers, the warp fitted robustly (MTF's GridTracker)",
    build: SmDef {
        params: &GRID_PARAMS,
        build: |cfg| Ok(Box::new(Grid::new(cfg))),
    },
};

/// The most minimal samples RANSAC and LMedS draw a frame.
const MAX_SAMPLES: usize = 500;
/// The probability that some minimal sample is all inliers.
const CONFIDENCE: f64 = 0.995;
/// A patch step smaller than this (px) ends its search.
const PATCH_EPS: f64 = 0.01;
/// A patch whose template's smaller structure-tensor eigenvalue per sample is below this (grey
/// levels squared per px squared) is flat: it does not take part.
const MIN_EIGEN: f64 = 0.05;

/// See the module's documentation.
#[derive(Debug)]
pub struct Grid {
    res: usize,
    size: usize,
    iters: usize,
    robust: Robust,
    seed: u64,
    rng: Rng,
    /// The lattice, in the normalised frame of the template.
    lattice: Vec<Point>,
    /// The patches' sample offsets (px), the same for every patch.
    offsets: Vec<(f32, f32)>,
    /// Per patch (`size^2` samples each, patch after patch): the template's values and
    /// gradients.
    tvals: Vec<f32>,
    tgx: Vec<f32>,
    tgy: Vec<f32>,
    /// Per patch: the inverse of its structure tensor `(a, b, c)` for `[[a, b], [b, c]]`, or
    /// `None` for a flat patch.
    hinv: Vec<Option<[f64; 3]>>,
    /// The plane the patches read (a colour tracker's channel of most contrast).
    plane: usize,
    /// Where the templates were taken (frame pixels), and the target's corners then.
    from: Vec<Point>,
    from_corners: Quad,
    /// Where each patch was found this frame (`None`: lost).
    to: Vec<Option<Point>>,
    /// The matches of the fit, compacted, and what the fit made of them.
    src: Vec<Point>,
    dst: Vec<Point>,
    inliers: Vec<bool>,
    errors: Vec<f64>,
    /// A patch's sampling: positions, values, gradients.
    xs: Vec<f32>,
    ys: Vec<f32>,
    vals: Vec<f32>,
    /// What the inspector draws: the patches found, inliers bright.
    vis_points: Vec<Point>,
    vis_weights: Vec<f32>,
}

impl Grid {
    pub fn new(cfg: &SmConfig) -> Self {
        let get = |k: usize| cfg.get(&GRID_PARAMS[k]);
        Grid {
            res: get(0) as usize,
            size: get(1) as usize,
            iters: get(2) as usize,
            robust: Robust {
                estimator: Estimator::from_index(get(3)),
                threshold: get(4),
                max_samples: MAX_SAMPLES,
                confidence: CONFIDENCE,
            },
            seed: cfg.tracker.seed,
            rng: Rng::new(cfg.tracker.seed),
            lattice: Vec::new(),
            offsets: Vec::new(),
            tvals: Vec::new(),
            tgx: Vec::new(),
            tgy: Vec::new(),
            hinv: Vec::new(),
            plane: 0,
            from: Vec::new(),
            from_corners: Quad::default(),
            to: Vec::new(),
            src: Vec::new(),
            dst: Vec::new(),
            inliers: Vec::new(),
            errors: Vec::new(),
            xs: Vec::new(),
            ys: Vec::new(),
            vals: Vec::new(),
            vis_points: Vec::new(),
            vis_weights: Vec::new(),
        }
    }

    /// The patches per frame.
    fn patches(&self) -> usize {
        self.res * self.res
    }

    /// Lays the patches on the lattice under the context's parameters and takes their templates
    /// from `img` (the frame the estimate is on).
    pub fn retemplate(&mut self, ctx: &Context, img: &ImageView) {
        // The patches of a colour tracker read its channel of most contrast.
        self.plane = ctx.problem().strongest_channel();
        let img = &img.plane(self.plane);
        let p = ctx.params();
        let m = ctx.pixel_matrix(&p);
        let s2 = self.size * self.size;
        for k in 0..self.patches() {
            let c = apply_homography(&m, self.lattice[k]);
            self.from[k] = c;
            self.place(c);
            let at = k * s2..(k + 1) * s2;
            sample_values_gradients(
                img,
                &self.xs,
                &self.ys,
                &mut self.tvals[at.clone()],
                &mut self.tgx[at.clone()],
                &mut self.tgy[at.clone()],
            );
            self.hinv[k] = inverse_tensor(&self.tgx[at.clone()], &self.tgy[at]);
        }
        self.from_corners = ctx.corners(&p);
    }

    /// The sample positions of a patch centred at `c`.
    fn place(&mut self, c: Point) {
        for ((x, y), &(ox, oy)) in self
            .xs
            .iter_mut()
            .zip(self.ys.iter_mut())
            .zip(&self.offsets)
        {
            *x = c.x as f32 + ox;
            *y = c.y as f32 + oy;
        }
    }

    /// Patch `k`'s search from `start`: where its template is in `img` (`None` when it does not
    /// settle, leaves far, or is flat).
    fn track_patch(&mut self, img: &ImageView, k: usize, start: Point) -> Option<Point> {
        let img = &img.plane(self.plane);
        let [a, b, c] = self.hinv[k]?;
        let s2 = self.size * self.size;
        let far = 2.0 * self.size as f64;
        let at = k * s2..(k + 1) * s2;
        let Grid {
            tvals,
            tgx,
            tgy,
            offsets,
            xs,
            ys,
            vals,
            iters,
            ..
        } = self;
        let (tv, tx, ty) = (&tvals[at.clone()], &tgx[at.clone()], &tgy[at]);
        let mut t = start;
        for _ in 0..*iters {
            for ((x, y), &(ox, oy)) in xs.iter_mut().zip(ys.iter_mut()).zip(offsets.iter()) {
                *x = t.x as f32 + ox;
                *y = t.y as f32 + oy;
            }
            sample_values(img, xs, ys, vals);
            let (mut bx, mut by) = (0.0f64, 0.0f64);
            for j in 0..s2 {
                let e = (vals[j] - tv[j]) as f64;
                bx += tx[j] as f64 * e;
                by += ty[j] as f64 * e;
            }
            let (dx, dy) = (a * bx + b * by, b * bx + c * by);
            t = Point::new(t.x - dx, t.y - dy);
            if !t.is_finite() || t.dist(start) > far {
                return None;
            }
            if dx * dx + dy * dy < PATCH_EPS * PATCH_EPS {
                break;
            }
        }
        Some(t)
    }
}

/// The inverse of the structure tensor `sum [gx gx, gx gy; gx gy, gy gy]` of a patch's gradients,
/// `None` when its smaller eigenvalue is below [`MIN_EIGEN`] per sample (a flat patch, or an edge
/// along one direction only).
fn inverse_tensor(gx: &[f32], gy: &[f32]) -> Option<[f64; 3]> {
    let (mut a, mut b, mut c) = (0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in gx.iter().zip(gy) {
        let (x, y) = (x as f64, y as f64);
        a += x * x;
        b += x * y;
        c += y * y;
    }
    let det = a * c - b * b;
    let half = 0.5 * (a + c);
    let smaller = half - (half * half - det).max(0.0).sqrt();
    if !crate::registration::at_least(smaller, MIN_EIGEN * gx.len() as f64) || det <= 0.0 {
        return None;
    }
    Some([c / det, -b / det, a / det])
}

impl SearchMethod for Grid {
    fn name(&self) -> &str {
        ENTRY.name
    }
    fn requires(&self) -> Capabilities {
        // The patches' own SSD: the AM only reports the similarity.
        Capabilities::default()
    }
    fn initialize(&mut self, ctx: &mut Context, img: &ImageView) -> Result<(), LossReason> {
        let (n, s) = (self.patches(), self.size);
        let unit = *ctx.problem().unit();
        self.lattice.clear();
        for j in 0..self.res {
            for i in 0..self.res {
                let u = Point::new(
                    -0.5 + (i as f64 + 0.5) / self.res as f64,
                    -0.5 + (j as f64 + 0.5) / self.res as f64,
                );
                self.lattice.push(apply_homography(&unit, u));
            }
        }
        let half = (s as f32 - 1.0) / 2.0;
        self.offsets = (0..s * s)
            .map(|j| ((j % s) as f32 - half, (j / s) as f32 - half))
            .collect();
        let z = |len: usize| vec![0.0f32; len];
        (self.tvals, self.tgx, self.tgy) = (z(n * s * s), z(n * s * s), z(n * s * s));
        (self.xs, self.ys, self.vals) = (z(s * s), z(s * s), z(s * s));
        self.hinv = vec![None; n];
        self.from = vec![Point::default(); n];
        self.to = vec![None; n];
        self.src = Vec::with_capacity(n);
        self.dst = Vec::with_capacity(n);
        self.inliers = vec![false; n];
        self.errors = vec![0.0; n];
        self.vis_points = Vec::with_capacity(n);
        self.vis_weights = Vec::with_capacity(n);
        self.rng = Rng::new(self.seed);
        self.retemplate(ctx, img);
        if self.hinv.iter().filter(|h| h.is_some()).count() < 4 {
            return Err(LossReason::Singular);
        }
        Ok(())
    }
    fn iterate(&mut self, ctx: &mut Context, img: &ImageView) -> Result<Step, LossReason> {
        let p = ctx.params();
        let m = ctx.pixel_matrix(&p);
        for k in 0..self.patches() {
            let start = apply_homography(&m, self.lattice[k]);
            self.to[k] = self.track_patch(img, k, start);
        }
        self.src.clear();
        self.dst.clear();
        for k in 0..self.patches() {
            if let Some(t) = self.to[k] {
                self.src.push(self.from[k]);
                self.dst.push(t);
            }
        }
        let found = self.src.len();
        let h = robust::fit(
            &self.src,
            &self.dst,
            &self.robust,
            &mut self.rng,
            (&mut self.inliers[..found], &mut self.errors[..found]),
        )
        .ok_or(LossReason::Singular)?;
        self.vis_points.clear();
        self.vis_weights.clear();
        for (d, &inlier) in self.dst.iter().zip(&self.inliers[..found]) {
            self.vis_points.push(*d);
            self.vis_weights.push(if inlier { 1.0 } else { 0.2 });
        }
        let corners = self.from_corners.map(|c| robust::apply(&h, c));
        let q = ctx.problem().fit(&corners).ok_or(LossReason::Singular)?;
        if !q.iter().all(|v| v.is_finite()) {
            return Err(LossReason::NonFinite);
        }
        ctx.set_params(q);
        self.retemplate(ctx, img);
        let f = ctx.similarity_at(img, &q);
        Ok(Step::done(f))
    }
    fn visual(&mut self, _ctx: &Context) -> Option<MethodVisual<'_>> {
        Some(MethodVisual {
            points: &self.vis_points,
            point_weights: &self.vis_weights,
            ..MethodVisual::quads("patches", &[], &[], None)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_patch_or_an_edge_is_left_out() {
        let n = 100;
        // A corner-like patch: gradients in both directions.
        let gx: Vec<f32> = (0..n)
            .map(|j| if j % 2 == 0 { 10.0 } else { -3.0 })
            .collect();
        let gy: Vec<f32> = (0..n).map(|j| if j % 3 == 0 { 8.0 } else { 2.0 }).collect();
        let [a, b, c] = inverse_tensor(&gx, &gy).unwrap();
        // The inverse times the tensor is the identity.
        let (sa, sb, sc) = gx.iter().zip(&gy).fold((0.0, 0.0, 0.0), |s, (&x, &y)| {
            let (x, y) = (x as f64, y as f64);
            (s.0 + x * x, s.1 + x * y, s.2 + y * y)
        });
        assert!((a * sa + b * sb - 1.0).abs() < 1e-9 && (a * sb + b * sc).abs() < 1e-9);
        assert!((b * sb + c * sc - 1.0).abs() < 1e-9);
        // Flat, and an edge (gradients all along one direction).
        assert!(inverse_tensor(&vec![0.0; n], &vec![0.0; n]).is_none());
        let edge: Vec<f32> = (0..n).map(|j| j as f32).collect();
        assert!(inverse_tensor(&edge, &edge).is_none());
    }
}
