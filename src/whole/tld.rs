//! TLD, tracking-learning-detection (Kalal, Mikolajczyk and Matas, PAMI 2012): a median-flow
//! tracker, a detector cascade over a scanning grid (patch variance, an ensemble of random
//! ferns, a nearest-neighbour classifier on normalised patches) and P-N learning, which trains
//! the detector from the trajectory: positives near the validated box, negatives far from it
//! that the detector accepted. The detector re-finds the target after a loss. The output box
//! has the initial aspect ratio (translation and scale).

use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::error::Result;
use crate::geometry::{Point, Quad};
use crate::imaging::flow::{LkParams, Pyramid, ncc, track_forward_backward, window_ncc};
use crate::imaging::{GrayF32, Integral, gaussian_blur, gaussian_kernel, resample_window};
use crate::linalg::median;
use crate::observe::MethodVisual;
use crate::observe::Observer;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::rng::Rng;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// TLD's parameters (the paper's values by default; fewer scales, for speed).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::int("ferns", "ferns in the ensemble", 1.0, 50.0, 10.0),
    ParamDef::int("fern_tests", "pixel comparisons per fern", 2.0, 16.0, 13.0),
    ParamDef::int(
        "scales",
        "scanning-grid scales on each side of the initial size (steps of 1.2)",
        0.0,
        10.0,
        5.0,
    ),
    ParamDef::float(
        "shift",
        "scanning-grid step, as a fraction of the box size",
        0.02,
        0.5,
        0.1,
    ),
    ParamDef::int(
        "min_size",
        "smallest box side scanned (px)",
        8.0,
        200.0,
        20.0,
    ),
    ParamDef::float(
        "nn_threshold",
        "relative similarity above which the detector accepts a patch",
        0.0,
        1.0,
        0.65,
    ),
    ParamDef::float(
        "valid_threshold",
        "conservative similarity above which the tracked box is trusted for learning",
        0.0,
        1.0,
        0.5,
    ),
    ParamDef::float(
        "max_fb",
        "median forward-backward error (px) above which the median-flow tracker has failed",
        0.5,
        100.0,
        10.0,
    ),
    ParamDef::int(
        "seed",
        "seed of the ferns, the warps and the sampled negatives",
        0.0,
        1e9,
        0.0,
    ),
];

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "tld",
    aliases: &["tracking_learning_detection"],
    description: "tracking-learning-detection (Kalal et al. 2012): median flow, a fern and nearest-neighbour detector, P-N learning; re-detects after a loss",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::TranslationScale,
        build,
    },
};

/// Builds a TLD tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    Ok(Box::new(Tld {
        base: Base::new(spec),
        n_ferns: g("ferns") as usize,
        fern_tests: g("fern_tests") as usize,
        scales: g("scales") as i32,
        shift: g("shift"),
        min_size: g("min_size"),
        nn_threshold: g("nn_threshold"),
        valid_threshold: g("valid_threshold"),
        max_fb: g("max_fb"),
        seed: g("seed") as u64,
        lk: LkParams::default(),
        model: None,
        vis_quads: Vec::new(),
        vis_weights: Vec::new(),
        vis_points: Vec::new(),
        vis_point_weights: Vec::new(),
    }))
}

/// An axis-aligned box: top-left corner and size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BBox {
    pub x: f64,
    pub y: f64,
    pub w: f64,
    pub h: f64,
}

impl BBox {
    pub fn centre(&self) -> Point {
        Point {
            x: self.x + 0.5 * self.w,
            y: self.y + 0.5 * self.h,
        }
    }

    /// Intersection over union.
    pub fn overlap(&self, o: &BBox) -> f64 {
        let ix = (self.x + self.w).min(o.x + o.w) - self.x.max(o.x);
        let iy = (self.y + self.h).min(o.y + o.h) - self.y.max(o.y);
        if ix <= 0.0 || iy <= 0.0 {
            return 0.0;
        }
        let i = ix * iy;
        i / (self.w * self.h + o.w * o.h - i)
    }

    fn quad(&self) -> Quad {
        Quad::from_rect(self.x, self.y, self.w, self.h)
    }
}

/// The median-flow tracker's step: a 10 x 10 grid of points in `b` tracked forward and back,
/// the half with the smaller forward-backward error and the half with the larger window NCC
/// kept, the box moved by their median displacement and scaled by the median ratio of their
/// pairwise distances. `None` when too few points survive or the median forward-backward error
/// exceeds `max_fb`. Also returns the points kept (for display).
pub fn median_flow(
    prev: (&GrayF32, &Pyramid),
    next: (&GrayF32, &Pyramid),
    b: &BBox,
    lk: &LkParams,
    max_fb: f64,
) -> Option<(BBox, f64, Vec<Point>)> {
    let n = 10;
    let pts: Vec<Point> = (0..n * n)
        .map(|k| Point {
            x: b.x + b.w * ((k % n) as f64 + 0.5) / n as f64,
            y: b.y + b.h * ((k / n) as f64 + 0.5) / n as f64,
        })
        .collect();
    let tracked = track_forward_backward(prev.1, next.1, &pts, lk);
    let mut ok: Vec<(Point, Point, f64, f64)> = Vec::new();
    for (s, t) in pts.iter().zip(&tracked) {
        if let Some((q, fb)) = t {
            let c = window_ncc(prev.0, *s, next.0, *q, 5);
            ok.push((*s, *q, *fb, c));
        }
    }
    if ok.len() < 4 {
        return None;
    }
    let med_fb = median(ok.iter().map(|o| o.2).collect());
    let med_ncc = median(ok.iter().map(|o| o.3).collect());
    let kept: Vec<_> = ok
        .into_iter()
        .filter(|o| o.2 <= med_fb && o.3 >= med_ncc)
        .collect();
    if kept.len() < 2 || med_fb > max_fb {
        return None;
    }
    let mut ratios = Vec::new();
    for i in 0..kept.len() {
        for j in i + 1..kept.len() {
            let d0 = kept[i].0.dist(kept[j].0);
            if d0 > 1e-6 {
                ratios.push(kept[i].1.dist(kept[j].1) / d0);
            }
        }
    }
    let s = if ratios.is_empty() {
        1.0
    } else {
        median(ratios)
    };
    // The new centre as each point predicts it under that scale: the plain median displacement
    // is biased when the points kept are not symmetric about the centre of a zoom.
    let c = b.centre();
    let nx = median(kept.iter().map(|o| o.1.x - s * (o.0.x - c.x)).collect());
    let ny = median(kept.iter().map(|o| o.1.y - s * (o.0.y - c.y)).collect());
    let (w, h) = (b.w * s, b.h * s);
    let out = BBox {
        x: nx - 0.5 * w,
        y: ny - 0.5 * h,
        w,
        h,
    };
    Some((out, med_fb, kept.iter().map(|o| o.1).collect()))
}

/// The ensemble of ferns: each fern compares `tests` pairs of pixels of a (smoothed) patch, the
/// bits index a leaf that counts the positives and negatives that reached it.
#[derive(Clone, Debug)]
pub struct Ferns {
    /// Per fern, per test: the two points in box-relative coordinates (0..1).
    tests: Vec<Vec<[f32; 4]>>,
    pos: Vec<Vec<u32>>,
    neg: Vec<Vec<u32>>,
}

impl Ferns {
    pub fn new(ferns: usize, tests: usize, rng: &mut Rng) -> Self {
        let t = (0..ferns)
            .map(|_| {
                (0..tests)
                    .map(|_| {
                        // Two points on a common row or column (TLD's 2-bit-BP-like tests).
                        let (a, b) = (rng.range(0.05, 0.95) as f32, rng.range(0.05, 0.95) as f32);
                        let c = rng.range(0.05, 0.95) as f32;
                        if rng.uniform() < 0.5 {
                            [a, c, b, c]
                        } else {
                            [c, a, c, b]
                        }
                    })
                    .collect()
            })
            .collect();
        let leaves = 1usize << tests;
        Ferns {
            tests: t,
            pos: vec![vec![0; leaves]; ferns],
            neg: vec![vec![0; leaves]; ferns],
        }
    }

    /// The leaf of every fern for the box `b` of `img`.
    pub fn codes(&self, img: &GrayF32, b: &BBox, out: &mut Vec<usize>) {
        out.clear();
        let px = |u: f32, v: f32| {
            let x = (b.x + u as f64 * b.w)
                .round()
                .clamp(0.0, img.width as f64 - 1.0) as usize;
            let y = (b.y + v as f64 * b.h)
                .round()
                .clamp(0.0, img.height as f64 - 1.0) as usize;
            img.data[y * img.width + x]
        };
        for tests in &self.tests {
            let mut code = 0usize;
            for t in tests {
                code = (code << 1) | usize::from(px(t[0], t[1]) > px(t[2], t[3]));
            }
            out.push(code);
        }
    }

    /// Where each fern's tests read in a `w x h` box of the scanning grid of an image `stride`
    /// pixels wide, as offsets from the box's top-left pixel (fern after fern, two per test):
    /// the pixels [`Ferns::codes`] reads for a box at whole-pixel coordinates. `None` when a
    /// test would read outside the box (where `codes` clamps to the frame instead).
    pub fn offsets(&self, w: i32, h: i32, stride: usize) -> Option<Vec<u32>> {
        let (bw, bh) = (w as f64, h as f64);
        // For a box at whole pixels `x, y >= 0`, `round(x + u w) = x + round(u w)`: the sum is
        // exact in f64 (a 24-bit `u` times a small `w`).
        let at = |u: f32, v: f32| -> Option<u32> {
            let (ox, oy) = ((u as f64 * bw).round(), (v as f64 * bh).round());
            let inside = ox >= 0.0 && oy >= 0.0 && ox < bw && oy < bh;
            inside.then(|| (oy as usize * stride + ox as usize) as u32)
        };
        let mut out =
            Vec::with_capacity(self.tests.len() * self.tests.first().map_or(0, Vec::len) * 2);
        for t in self.tests.iter().flatten() {
            out.push(at(t[0], t[1])?);
            out.push(at(t[2], t[3])?);
        }
        Some(out)
    }

    /// [`Ferns::codes`] for the box whose top-left pixel is `img.data[origin]`, through its
    /// size's [`Ferns::offsets`].
    pub fn codes_at(&self, img: &GrayF32, origin: usize, offsets: &[u32], out: &mut Vec<usize>) {
        out.clear();
        let data = &img.data[origin..];
        let tests = self.tests.first().map_or(0, Vec::len);
        for fern in offsets.chunks_exact(2 * tests.max(1)) {
            let mut code = 0usize;
            for t in fern.chunks_exact(2) {
                code = (code << 1) | usize::from(data[t[0] as usize] > data[t[1] as usize]);
            }
            out.push(code);
        }
    }

    /// A leaf's posterior `P(target | leaf) = pos / (pos + neg)` (0 for an unseen leaf).
    pub fn posterior(&self, fern: usize, code: usize) -> f64 {
        let (p, n) = (self.pos[fern][code] as f64, self.neg[fern][code] as f64);
        if p + n > 0.0 { p / (p + n) } else { 0.0 }
    }

    /// The mean posterior over the ferns.
    pub fn score(&self, codes: &[usize]) -> f64 {
        codes
            .iter()
            .enumerate()
            .map(|(f, &c)| self.posterior(f, c))
            .sum::<f64>()
            / codes.len().max(1) as f64
    }

    /// Counts a labelled example.
    pub fn add(&mut self, codes: &[usize], positive: bool) {
        for (f, &c) in codes.iter().enumerate() {
            if positive {
                self.pos[f][c] += 1;
            } else {
                self.neg[f][c] += 1;
            }
        }
    }
}

/// Side of the nearest-neighbour classifier's patches.
const PATCH: usize = 15;
/// Most examples of each class kept by the nearest-neighbour classifier.
const MAX_EXAMPLES: usize = 150;

/// The nearest-neighbour classifier: zero-mean patches resampled to 15 x 15, compared by NCC.
#[derive(Clone, Debug, Default)]
pub struct NearestNeighbour {
    pub pos: Vec<Vec<f64>>,
    pub neg: Vec<Vec<f64>>,
}

impl NearestNeighbour {
    /// The relative and the conservative similarity of a patch: `S+ / (S+ + S-)`, with `S+`
    /// over all positives for the first and over the older half for the second (a similarity
    /// is `(NCC + 1) / 2`, best over the examples).
    pub fn similarity(&self, p: &[f64]) -> (f64, f64) {
        if self.pos.is_empty() {
            return (0.0, 0.0);
        }
        let s = |e: &Vec<f64>| 0.5 * (ncc(p, e) + 1.0);
        let half = self.pos.len().div_ceil(2);
        let mut sp = 0f64;
        let mut sp_half = 0f64;
        for (i, e) in self.pos.iter().enumerate() {
            let v = s(e);
            sp = sp.max(v);
            if i < half {
                sp_half = sp_half.max(v);
            }
        }
        let sn = self.neg.iter().map(s).fold(0.0, f64::max);
        let rel = |a: f64| {
            let (d1, d2) = (1.0 - a, 1.0 - sn);
            if d1 + d2 > 0.0 { d2 / (d1 + d2) } else { 0.0 }
        };
        (rel(sp), rel(sp_half))
    }
}

/// The zero-mean 15 x 15 patch of box `b`.
fn patch(img: &GrayF32, b: &BBox, buf: &mut Vec<f32>) -> Vec<f64> {
    let c = b.centre();
    resample_window(img, c.x, c.y, b.w, b.h, PATCH, PATCH, buf);
    let m = buf.iter().map(|&v| v as f64).sum::<f64>() / buf.len() as f64;
    buf.iter().map(|&v| v as f64 - m).collect()
}

/// Sums and squared sums, for the variance of any box; made once per frame.
struct Moments {
    s: Integral,
    s2: Integral,
}

impl Moments {
    fn new(img: &GrayF32) -> Self {
        Moments {
            s: Integral::new(img),
            s2: Integral::squares(img),
        }
    }

    /// The variance of the pixels of a grid box.
    fn variance(&self, b: &GridBox) -> f64 {
        let (x0, y0, x1, y1) = (
            b.x as i64,
            b.y as i64,
            (b.x + b.w) as i64,
            (b.y + b.h) as i64,
        );
        let n = ((x1 - x0) * (y1 - y0)).max(1) as f64;
        let m = self.s.sum(x0, y0, x1, y1) / n;
        self.s2.sum(x0, y0, x1, y1) / n - m * m
    }
}

/// A box of the scanning grid (whole pixels, inside the frame).
#[derive(Clone, Copy, Debug)]
struct GridBox {
    x: i32,
    y: i32,
    w: i32,
    h: i32,
    /// The index of its size in [`Model::offsets`].
    scale: u8,
}

impl GridBox {
    fn bbox(&self) -> BBox {
        BBox {
            x: self.x as f64,
            y: self.y as f64,
            w: self.w as f64,
            h: self.h as f64,
        }
    }
}

#[derive(Debug)]
struct Model {
    grid: Vec<GridBox>,
    /// Per size of the grid's boxes, where the ferns read ([`Ferns::offsets`]).
    offsets: Vec<Option<Vec<u32>>>,
    ferns: Ferns,
    nn: NearestNeighbour,
    min_variance: f64,
    rng: Rng,
    /// The previous frame, its pyramid and the box in it (`None` after a loss).
    prev: Option<(GrayF32, Pyramid)>,
    bbox: Option<BBox>,
}

impl Model {
    /// The ferns' codes of a grid box of `img` (the fern image, of the frame's size).
    fn grid_codes(&self, img: &GrayF32, g: &GridBox, out: &mut Vec<usize>) {
        match self.offsets.get(g.scale as usize).and_then(Option::as_ref) {
            Some(offsets) => {
                let origin = g.y as usize * img.width + g.x as usize;
                self.ferns.codes_at(img, origin, offsets, out);
            }
            None => self.ferns.codes(img, &g.bbox(), out),
        }
    }
}

/// A TLD tracker.
#[derive(Debug)]
pub struct Tld {
    base: Base,
    n_ferns: usize,
    fern_tests: usize,
    scales: i32,
    shift: f64,
    min_size: f64,
    nn_threshold: f64,
    valid_threshold: f64,
    max_fb: f64,
    seed: u64,
    lk: LkParams,
    model: Option<Model>,
    vis_quads: Vec<Quad>,
    vis_weights: Vec<f32>,
    vis_points: Vec<Point>,
    vis_point_weights: Vec<f32>,
}

/// The smoothing of the image the ferns read (TLD's Gaussian of sigma 3, 7 x 7 here).
fn fern_image(img: &GrayF32) -> GrayF32 {
    gaussian_blur(img, &gaussian_kernel(7, 3.0))
}

impl Tld {
    /// The scanning grid of a frame for a `w x h` target, and the size of its boxes at each
    /// scale kept (what [`GridBox::scale`] indexes).
    fn grid(&self, fw: usize, fh: usize, w: f64, h: f64) -> (Vec<GridBox>, Vec<(i32, i32)>) {
        let mut out = Vec::new();
        let mut sizes = Vec::new();
        for k in -self.scales..=self.scales {
            let s = 1.2f64.powi(k);
            let (bw, bh) = ((w * s).round(), (h * s).round());
            if bw.min(bh) < self.min_size || bw > fw as f64 || bh > fh as f64 {
                continue;
            }
            let scale = sizes.len() as u8;
            sizes.push((bw as i32, bh as i32));
            let (sx, sy) = ((bw * self.shift).max(1.0), (bh * self.shift).max(1.0));
            let mut y = 0.0;
            while y + bh <= fh as f64 {
                let mut x = 0.0;
                while x + bw <= fw as f64 {
                    out.push(GridBox {
                        x: x.round() as i32,
                        y: y.round() as i32,
                        w: bw as i32,
                        h: bh as i32,
                        scale,
                    });
                    x += sx;
                }
                y += sy;
            }
        }
        (out, sizes)
    }

    /// P-N learning at the validated box `b`: fern positives from the grid boxes that overlap
    /// it most (warped `warps` times), fern negatives from the far boxes the ensemble accepted
    /// (all far boxes at initialisation, subsampled), NN positives and negatives where the
    /// classifier was wrong.
    fn learn(
        &mut self,
        img: &GrayF32,
        blurred: &GrayF32,
        mims: &Moments,
        b: &BBox,
        warps: usize,
        first: bool,
    ) {
        let Some(m) = self.model.as_mut() else {
            return;
        };
        let mut codes = Vec::new();
        let mut buf = Vec::new();
        // Positives: the 10 grid boxes closest to b.
        let mut near: Vec<(f64, usize)> = m
            .grid
            .iter()
            .enumerate()
            .map(|(i, g)| (g.bbox().overlap(b), i))
            .filter(|(o, _)| *o > 0.6)
            .collect();
        near.sort_by(|a, c| c.0.total_cmp(&a.0));
        near.truncate(10);
        for &(_, i) in &near {
            let g = m.grid[i];
            let gb = g.bbox();
            for wi in 0..warps.max(1) {
                // Small random similarity warps of the box (position, scale) as new views.
                let wb = if wi == 0 {
                    gb
                } else {
                    let s = 1.0 + m.rng.range(-0.02, 0.02);
                    BBox {
                        x: gb.x + m.rng.range(-0.02, 0.02) * gb.w,
                        y: gb.y + m.rng.range(-0.02, 0.02) * gb.h,
                        w: gb.w * s,
                        h: gb.h * s,
                    }
                };
                if wi == 0 {
                    m.grid_codes(blurred, &g, &mut codes);
                } else {
                    m.ferns.codes(blurred, &wb, &mut codes);
                }
                if first || m.ferns.score(&codes) < 0.5 {
                    m.ferns.add(&codes, true);
                }
            }
        }
        // Negatives: far boxes with enough texture that the ensemble accepts (all of a sample
        // at initialisation).
        let mut neg_patches = Vec::new();
        for i in 0..m.grid.len() {
            let g = m.grid[i];
            let gb = g.bbox();
            if gb.overlap(b) >= 0.2 {
                continue;
            }
            if first && m.rng.uniform() > 0.1 {
                continue;
            }
            if mims.variance(&g) < m.min_variance {
                continue;
            }
            m.grid_codes(blurred, &g, &mut codes);
            let s = m.ferns.score(&codes);
            if first || s > 0.5 {
                m.ferns.add(&codes, false);
                if s > 0.5 || (first && neg_patches.len() < 100) {
                    neg_patches.push(gb);
                }
            }
        }
        // The nearest-neighbour classifier.
        let p = patch(img, b, &mut buf);
        let (rel, _) = m.nn.similarity(&p);
        if first || rel < 0.65 {
            m.nn.pos.push(p);
        }
        for nb in neg_patches.iter().take(100) {
            let q = patch(img, nb, &mut buf);
            let (r, _) = m.nn.similarity(&q);
            if first || r > 0.5 {
                m.nn.neg.push(q);
            }
        }
        // Bounded memory: drop the newest beyond the first half (the older half is the
        // conservative model), and the oldest negatives.
        if m.nn.pos.len() > MAX_EXAMPLES {
            let k = m
                .rng
                .range(MAX_EXAMPLES as f64 / 2.0, m.nn.pos.len() as f64)
                as usize;
            m.nn.pos.remove(k.min(m.nn.pos.len() - 1));
        }
        if m.nn.neg.len() > MAX_EXAMPLES {
            let extra = m.nn.neg.len() - MAX_EXAMPLES;
            m.nn.neg.drain(0..extra);
        }
    }

    /// The detector cascade over the grid: boxes that pass the variance filter, the ensemble
    /// (mean posterior > 0.5; the best 100) and the nearest-neighbour classifier. Returns the
    /// accepted boxes with their relative and conservative similarity.
    fn detect(
        &mut self,
        img: &GrayF32,
        blurred: &GrayF32,
        mims: &Moments,
    ) -> Vec<(BBox, f64, f64)> {
        let Some(m) = self.model.as_mut() else {
            return Vec::new();
        };
        let mut codes = Vec::new();
        let mut passed: Vec<(f64, BBox)> = Vec::new();
        for g in &m.grid {
            if mims.variance(g) < m.min_variance {
                continue;
            }
            m.grid_codes(blurred, g, &mut codes);
            let s = m.ferns.score(&codes);
            if s > 0.5 {
                passed.push((s, g.bbox()));
            }
        }
        passed.sort_by(|a, b| b.0.total_cmp(&a.0));
        passed.truncate(100);
        let mut buf = Vec::new();
        passed
            .into_iter()
            .filter_map(|(_, b)| {
                let (rel, cons) = m.nn.similarity(&patch(img, &b, &mut buf));
                (rel > self.nn_threshold).then_some((b, rel, cons))
            })
            .collect()
    }
}

/// Groups boxes that overlap by more than half (single linkage); each group's mean box and its
/// members' indices.
fn cluster(boxes: &[BBox]) -> Vec<(BBox, Vec<usize>)> {
    let label = super::components(boxes.len(), |i, j| boxes[i].overlap(&boxes[j]) > 0.5);
    let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
    for (i, &r) in label.iter().enumerate() {
        match groups.iter_mut().find(|g| g.0 == r) {
            Some(g) => g.1.push(i),
            None => groups.push((r, vec![i])),
        }
    }
    groups
        .into_iter()
        .map(|(_, idx)| {
            let k = idx.len() as f64;
            let mut m = BBox {
                x: 0.0,
                y: 0.0,
                w: 0.0,
                h: 0.0,
            };
            for &i in &idx {
                m.x += boxes[i].x / k;
                m.y += boxes[i].y / k;
                m.w += boxes[i].w / k;
                m.h += boxes[i].h / k;
            }
            (m, idx)
        })
        .collect()
}

impl WholeTracker for Tld {
    const MIN_SIDE: f64 = 8.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let img = frame_f32(input).into_owned();
        let (tw, th) = self.base.size0;
        let c = self.base.c0;
        let b = BBox {
            x: c.x - 0.5 * tw,
            y: c.y - 0.5 * th,
            w: tw,
            h: th,
        };
        let mut rng = Rng::new(self.seed);
        let ferns = Ferns::new(self.n_ferns, self.fern_tests, &mut rng);
        let (grid, sizes) = self.grid(img.width, img.height, tw, th);
        let offsets = sizes
            .iter()
            .map(|&(w, h)| ferns.offsets(w, h, img.width))
            .collect();
        let mims = Moments::new(&img);
        let var = mims.variance(&GridBox {
            x: b.x.max(0.0) as i32,
            y: b.y.max(0.0) as i32,
            w: b.w.min(img.width as f64 - b.x.max(0.0)).max(1.0) as i32,
            h: b.h.min(img.height as f64 - b.y.max(0.0)).max(1.0) as i32,
            scale: 0,
        });
        let blurred = fern_image(&img);
        let pyr = Pyramid::new(&img, self.lk.levels);
        self.model = Some(Model {
            grid,
            offsets,
            ferns,
            nn: NearestNeighbour::default(),
            min_variance: 0.5 * var,
            rng,
            prev: None,
            bbox: Some(b),
        });
        self.learn(&img, &blurred, &mims, &b, 20, true);
        if let Some(m) = self.model.as_mut() {
            m.prev = Some((img, pyr));
        }
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.base.status == TrackStatus::Uninitialized || self.model.is_none() {
            return self.base.idle();
        }
        let started = self.base.begin(observer);
        let img = frame_f32(input).into_owned();
        let pyr = Pyramid::new(&img, self.lk.levels);
        let blurred = fern_image(&img);
        let mims = Moments::new(&img);
        let preprocess = started.elapsed();
        let want = observer.wants_method_visuals();
        // Tracking.
        let mut flow_points = Vec::new();
        let tracked = match self.model.as_ref() {
            Some(Model {
                prev: Some((pi, pp)),
                bbox: Some(b),
                ..
            }) => median_flow((pi, pp), (&img, &pyr), b, &self.lk, self.max_fb).and_then(
                |(nb, _, pts)| {
                    flow_points = pts;
                    let inside = nb.x + nb.w > 0.0
                        && nb.y + nb.h > 0.0
                        && nb.x < img.width as f64
                        && nb.y < img.height as f64;
                    inside.then_some(nb)
                },
            ),
            _ => None,
        };
        let tracked_conf = tracked.map(|b| {
            let mut buf = Vec::new();
            self.model
                .as_ref()
                .map(|m| m.nn.similarity(&patch(&img, &b, &mut buf)))
                .unwrap_or((0.0, 0.0))
        });
        // Detection.
        let detections = self.detect(&img, &blurred, &mims);
        let boxes: Vec<BBox> = detections.iter().map(|d| d.0).collect();
        let clusters = cluster(&boxes);
        let cluster_conf: Vec<(f64, f64)> = clusters
            .iter()
            .map(|(_, idx)| {
                let k = idx.len() as f64;
                (
                    idx.iter().map(|&i| detections[i].1).sum::<f64>() / k,
                    idx.iter().map(|&i| detections[i].2).sum::<f64>() / k,
                )
            })
            .collect();
        // Integration.
        let mut learn_ok = false;
        let result: Option<BBox> = match (tracked, tracked_conf) {
            (Some(t), Some((_, tc))) => {
                let better: Vec<usize> = (0..clusters.len())
                    .filter(|&k| clusters[k].0.overlap(&t) < 0.5 && cluster_conf[k].1 > tc)
                    .collect();
                if better.len() == 1 {
                    // One confident detection away from the tracker: re-initialise to it.
                    Some(clusters[better[0]].0)
                } else {
                    // The tracker, averaged with the detections close to it (weight 10):
                    // overlapping it and of about its size (the grid's scales are 1.2 apart, a
                    // detection a scale step away would pull the box's size).
                    let close: Vec<&BBox> = boxes
                        .iter()
                        .filter(|d| d.overlap(&t) > 0.7 && (d.w / t.w).ln().abs() < 0.05)
                        .collect();
                    let k = 10.0 + close.len() as f64;
                    let mut m = BBox {
                        x: 10.0 * t.x,
                        y: 10.0 * t.y,
                        w: 10.0 * t.w,
                        h: 10.0 * t.h,
                    };
                    for d in close {
                        m.x += d.x;
                        m.y += d.y;
                        m.w += d.w;
                        m.h += d.h;
                    }
                    learn_ok = tc > self.valid_threshold;
                    Some(BBox {
                        x: m.x / k,
                        y: m.y / k,
                        w: m.w / k,
                        h: m.h / k,
                    })
                }
            }
            _ => {
                // No track: re-detect when the detections form one cluster.
                (clusters.len() == 1).then(|| clusters[0].0)
            }
        };
        if learn_ok && let Some(b) = result {
            self.learn(&img, &blurred, &mims, &b, 1, false);
        }
        if want {
            self.vis_quads = boxes.iter().map(|b| b.quad()).collect();
            self.vis_weights = detections.iter().map(|d| d.1 as f32).collect();
            self.vis_point_weights = vec![1.0; flow_points.len()];
            self.vis_points = flow_points;
        }
        let found = match result {
            Some(b) => {
                let c = b.centre();
                let pose = Pose {
                    cx: c.x,
                    cy: c.y,
                    scale: b.w / self.base.size0.0,
                    angle: 0.0,
                };
                let sim = tracked_conf
                    .map(|c| c.1)
                    .unwrap_or_else(|| cluster_conf.first().map(|c| c.1).unwrap_or(0.0));
                Ok((pose, sim))
            }
            None => Err(LossReason::NotFound),
        };
        if let Some(m) = self.model.as_mut() {
            m.bbox = result;
            m.prev = Some((img, pyr));
        }
        let visual = want.then(|| MethodVisual {
            points: &self.vis_points,
            point_weights: &self.vis_point_weights,
            ..MethodVisual::quads("detections", &self.vis_quads, &self.vis_weights, None)
        });
        let out = self
            .base
            .finish(found, input.size(), started, preprocess, observer, visual);
        if let (Some(m), TrackStatus::Lost(_)) = (self.model.as_mut(), out.status) {
            // A pose rejected by the checks is no box to track from.
            if out.status != TrackStatus::Lost(LossReason::NotFound) {
                m.bbox = None;
            }
        }
        out
    }

    fn corners_set(&mut self) -> Result<()> {
        self.base.pose.angle = 0.0;
        let (w, h) = (
            self.base.size0.0 * self.base.pose.scale,
            self.base.size0.1 * self.base.pose.scale,
        );
        let b = BBox {
            x: self.base.pose.cx - 0.5 * w,
            y: self.base.pose.cy - 0.5 * h,
            w,
            h,
        };
        if let Some(m) = self.model.as_mut() {
            m.bbox = Some(b);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fern_posteriors_count_the_examples_that_reach_a_leaf() {
        let mut rng = Rng::new(1);
        let mut f = Ferns::new(3, 4, &mut rng);
        assert_eq!(f.posterior(0, 5), 0.0, "an unseen leaf");
        f.add(&[5, 1, 2], true);
        f.add(&[5, 1, 3], true);
        f.add(&[5, 0, 3], false);
        assert!((f.posterior(0, 5) - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(f.posterior(1, 1), 1.0);
        assert_eq!(f.posterior(1, 0), 0.0);
        assert!((f.posterior(2, 3) - 0.5).abs() < 1e-12);
        // The ensemble's score is the mean posterior.
        assert!((f.score(&[5, 1, 3]) - (2.0 / 3.0 + 1.0 + 0.5) / 3.0).abs() < 1e-12);
        // Codes are read from the pixels: a box and its copy elsewhere give the same codes.
        let mut img = GrayF32::new(60, 40);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = ((i * 7919) % 251) as f32;
        }
        let mut shifted = GrayF32::new(60, 40);
        for y in 0..40 {
            for x in 0..55 {
                shifted.set(x + 5, y, img.get(x, y));
            }
        }
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let bx = BBox {
            x: 10.0,
            y: 10.0,
            w: 20.0,
            h: 20.0,
        };
        f.codes(&img, &bx, &mut a);
        f.codes(&shifted, &BBox { x: 15.0, ..bx }, &mut b);
        assert_eq!(a, b);
    }

    #[test]
    fn median_flow_moves_and_scales_the_box_and_fails_on_an_unrelated_frame() {
        let tex = |s: f64, dx: f64| {
            let mut img = GrayF32::new(200, 160);
            for y in 0..160 {
                for x in 0..200 {
                    let (u, v) = ((x as f64 - 100.0 - dx) / s, (y as f64 - 80.0) / s);
                    let val = 128.0
                        + 60.0 * (u / 5.0).sin() * (v / 7.0).cos()
                        + 30.0 * ((u - v) / 11.0).sin();
                    img.set(x, y, val as f32);
                }
            }
            img
        };
        let lk = LkParams::default();
        let a = tex(1.0, 0.0);
        let b = tex(1.05, 4.0);
        let (pa, pb) = (Pyramid::new(&a, 3), Pyramid::new(&b, 3));
        let bx = BBox {
            x: 70.0,
            y: 50.0,
            w: 60.0,
            h: 60.0,
        };
        let (nb, fb, _) = median_flow((&a, &pa), (&b, &pb), &bx, &lk, 10.0).expect("tracks");
        assert!(fb < 0.2, "fb {fb}");
        let c = nb.centre();
        // The zoom is about (100, 80) = the box's centre, then a 4 px shift.
        assert!(
            (c.x - 104.0).abs() < 0.3 && (c.y - 80.0).abs() < 0.3,
            "{nb:?}"
        );
        assert!((nb.w / bx.w - 1.05).abs() < 0.01, "{nb:?}");
        // Against unrelated content the forward-backward error is large.
        let mut noise = GrayF32::new(200, 160);
        let mut rng = Rng::new(3);
        for v in noise.data.iter_mut() {
            *v = rng.range(0.0, 255.0) as f32;
        }
        let pn = Pyramid::new(&noise, 3);
        let r = median_flow((&a, &pa), (&noise, &pn), &bx, &lk, 2.0);
        assert!(r.is_none(), "{r:?}");
    }

    #[test]
    fn boxes_cluster_by_overlap_and_the_nn_classifier_prefers_its_positives() {
        let b = |x: f64| BBox {
            x,
            y: 0.0,
            w: 10.0,
            h: 10.0,
        };
        let c = cluster(&[b(0.0), b(1.0), b(50.0), b(2.0)]);
        assert_eq!(c.len(), 2);
        assert_eq!(c[0].1, vec![0, 1, 3]);
        assert!((c[0].0.x - 1.0).abs() < 1e-12);
        let mut nn = NearestNeighbour::default();
        let p: Vec<f64> = (0..20).map(|i| (i as f64).sin()).collect();
        let n: Vec<f64> = (0..20).map(|i| (i as f64 * 0.37).cos()).collect();
        nn.pos.push(p.clone());
        nn.neg.push(n.clone());
        assert!(nn.similarity(&p).0 > 0.9 && nn.similarity(&n).0 < 0.1);
        assert!((median(vec![3.0, 1.0, 2.0]) - 2.0).abs() < 1e-12);
        assert!((median(vec![4.0, 1.0, 2.0, 3.0]) - 2.5).abs() < 1e-12);
    }
}
