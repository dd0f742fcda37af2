//! FragTrack, fragments-based tracking (Adam, Rivlin and Shimshoni, CVPR 2006): the target is
//! covered by overlapping fragments (horizontal and vertical strips here), each described by
//! its intensity histogram, learned on the first frame. Every candidate position within the
//! search radius is scored by each fragment (the earth mover's distance between the fragment's
//! histogram there and its template's, in 1-D the L1 distance of their cumulative histograms),
//! and the fragments' scores are combined robustly: a candidate's score is a low quantile of
//! them, so that fragments hidden by an occluder do not move the target. As the paper's patches
//! vote on scale as well as position, each frame, after the search at the last size, scores the
//! box a step wider, narrower, taller, shorter, larger and smaller around the centre found and
//! keeps the best: the fragments stay on the target while it comes nearer, moves away or turns
//! (a target seen from an angle narrows along one axis), and the centre with them (the tracker
//! reports the centre: its output is a translation of the first box). The histograms come from one integral histogram
//! of the search region (one summed-area table per bin), so a fragment's histogram costs four
//! reads a bin whatever its size.

use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::error::Result;
use crate::geometry::Quad;
use crate::imaging::GrayF32;
use crate::observe::{MethodVisual, Observer};
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// FragTrack's parameters (the paper's values by default).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::int(
        "bins",
        "intensity bins of a fragment's histogram",
        2.0,
        64.0,
        16.0,
    ),
    ParamDef::int(
        "strips",
        "horizontal strips, and as many vertical ones, each overlapping the next by half",
        1.0,
        32.0,
        12.0,
    ),
    ParamDef::float(
        "quantile",
        "a candidate's score is this quantile of its fragments' distances (robust to occlusion of up to 1 - quantile of them; the paper's 0.25)",
        0.0,
        1.0,
        0.5,
    ),
    ParamDef::float(
        "scale_step",
        "each frame the box's width, height or both are also scored this fraction larger and smaller around the centre found, the best size kept (0: one size)",
        0.0,
        0.5,
        0.05,
    ),
    ParamDef::float(
        "search_radius",
        "candidates are the positions within this many pixels of the last one",
        2.0,
        200.0,
        25.0,
    ),
    ParamDef::int(
        "coarse_step",
        "the search first visits every this many pixels, then every pixel around the best (1: exhaustive)",
        1.0,
        10.0,
        2.0,
    ),
];

/// How far (px) from the centre found at the last size the other sizes are scored.
const SIZE_RADIUS: f64 = 1.0;

/// The box is searched at most this many times its first size.
const MOST_SCALE: f64 = 8.0;

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "fragtrack",
    aliases: &["frag"],
    description: "fragments-based tracking (Adam et al. 2006): strip histograms from integral histograms, robust quantile vote, the box's size searched, translation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Translation,
        build,
    },
};

/// Builds a FragTrack tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    Ok(Box::new(FragTrack {
        base: Base::new(spec),
        bins: g("bins") as usize,
        strips: g("strips") as usize,
        quantile: g("quantile"),
        radius: g("search_radius"),
        coarse_step: g("coarse_step") as i64,
        scale_step: g("scale_step"),
        model: None,
        hist: IntegralHistogram::default(),
        scores: Vec::new(),
        vis: Vec::new(),
    }))
}

/// A pixel's weight in the integral histogram's counts: a pixel is shared between its two
/// nearest bins in whole 64ths, so that every count is an exact integer (a fragment's histogram
/// is the same wherever the region it is read from starts).
pub(crate) const UNIT: u32 = 64;

/// Summed-area tables of the bins of a region: `bins` tables of `(w + 1) x (h + 1)` counts (in
/// [`UNIT`]s of a pixel).
#[derive(Clone, Debug, Default)]
pub(crate) struct IntegralHistogram {
    pub w: usize,
    pub h: usize,
    pub bins: usize,
    pub data: Vec<u32>,
}

impl IntegralHistogram {
    /// The integral histogram of the `w x h` region of `img` whose top-left is `(x0, y0)`
    /// (pixels beyond the frame replicate its border).
    pub fn build(
        &mut self,
        img: &GrayF32,
        (x0, y0): (i64, i64),
        (w, h): (usize, usize),
        bins: usize,
    ) {
        self.w = w;
        self.h = h;
        self.bins = bins;
        let stride = (w + 1) * (h + 1);
        self.data.clear();
        self.data.resize(bins * stride, 0);
        let (iw, ih) = (img.width as i64, img.height as i64);
        let mut row = vec![0u32; bins];
        let width = 256.0 / bins as f32;
        for y in 0..h {
            row.iter_mut().for_each(|c| *c = 0);
            let py = (y0 + y as i64).clamp(0, ih - 1) as usize;
            for x in 0..w {
                let px = (x0 + x as i64).clamp(0, iw - 1) as usize;
                // Shared by the two nearest bins by distance to their centres (a pixel's
                // weight moves smoothly between bins as its value does).
                let t = (img.data[py * img.width + px].clamp(0.0, 255.0) / width - 0.5)
                    .clamp(0.0, (bins - 1) as f32);
                let b = (t.floor() as usize).min(bins - 1);
                let upper = ((t - b as f32) * UNIT as f32).round() as u32;
                row[b] += UNIT - upper;
                if b + 1 < bins {
                    row[b + 1] += upper;
                }
                for (b, count) in row.iter().enumerate() {
                    let t = &mut self.data[b * stride..(b + 1) * stride];
                    t[(y + 1) * (w + 1) + x + 1] = t[y * (w + 1) + x + 1] + count;
                }
            }
        }
    }

    /// The count of bin `b` in the rectangle `[x0, x1) x [y0, y1)` of the region, in [`UNIT`]s.
    #[inline]
    pub fn count(&self, b: usize, x0: usize, y0: usize, x1: usize, y1: usize) -> u32 {
        let t = &self.data[b * (self.w + 1) * (self.h + 1)..];
        let at = |x: usize, y: usize| t[y * (self.w + 1) + x];
        // Exact: the rectangle's count is what is left, whatever the order of the terms.
        (at(x1, y1) + at(x0, y0)).wrapping_sub(at(x1, y0) + at(x0, y1))
    }
}

/// A fragment: a rectangle of the target box (offsets from its top-left, whole pixels).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Fragment {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

/// `n` horizontal strips and `n` vertical ones over a `w x h` box, each overlapping the next by
/// half (a strip is `2 / (n + 1)` of the side).
fn strips(w: usize, h: usize, n: usize) -> Vec<Fragment> {
    let span = |side: usize, k: usize| {
        let a = side * k / (n + 1);
        let b = (side * (k + 2) / (n + 1)).max(a + 1).min(side);
        (a, b)
    };
    let mut out = Vec::with_capacity(2 * n);
    for k in 0..n {
        let (y0, y1) = span(h, k);
        out.push(Fragment {
            x0: 0,
            y0,
            x1: w,
            y1,
        });
    }
    for k in 0..n {
        let (x0, x1) = span(w, k);
        out.push(Fragment {
            x0,
            y0: 0,
            x1,
            y1: h,
        });
    }
    out
}

/// The cumulative normalised histogram of a fragment placed at `(ox, oy)` in the region.
fn cumulative(ih: &IntegralHistogram, f: &Fragment, ox: usize, oy: usize, out: &mut [f32]) {
    let area = ((f.x1 - f.x0) * (f.y1 - f.y0)) as f32 * UNIT as f32;
    let mut c = 0u32;
    for (b, o) in out.iter_mut().enumerate() {
        c += ih.count(b, ox + f.x0, oy + f.y0, ox + f.x1, oy + f.y1);
        *o = c as f32 / area;
    }
}

/// The 1-D earth mover's distance of two histograms: the L1 distance of their cumulatives.
pub(crate) fn emd(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).sum()
}

/// The value at quantile `q` of `v` (sorted in place; `q` = 0: the smallest).
fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let i = ((v.len() as f64 - 1.0) * q).round() as usize;
    v[i.min(v.len() - 1)]
}

#[derive(Debug)]
struct Model {
    /// The first frame's box (px).
    size0: (f64, f64),
    /// Strips a side.
    strips: usize,
    /// The box's width and height now, relative to the first frame's (searched each frame).
    scale: (f64, f64),
    /// The least scale: the strips at least two pixels wide (the largest is [`MOST_SCALE`]).
    least: f64,
    /// Each fragment's template cumulative histogram (`bins` values), in the order of
    /// [`strips`]' fragments.
    templates: Vec<Vec<f32>>,
    /// The centre's offset from the whole-pixel box's centre, fixed at the start.
    offset: (f64, f64),
}

impl Model {
    /// The whole-pixel box at `scale` (of the width, of the height).
    fn size(&self, scale: (f64, f64)) -> (usize, usize) {
        (
            (self.size0.0 * scale.0).round().max(2.0) as usize,
            (self.size0.1 * scale.1).round().max(2.0) as usize,
        )
    }

    /// The frame position of the top-left of the box of size `(bw, bh)` around `pose`.
    fn top_left(&self, pose: &Pose, (bw, bh): (usize, usize)) -> (i64, i64) {
        (
            (pose.cx - self.offset.0 - 0.5 * bw as f64).round() as i64,
            (pose.cy - self.offset.1 - 0.5 * bh as f64).round() as i64,
        )
    }
}

/// One size's candidate: the box, its fragments and where its search starts in the region.
#[derive(Clone, Debug, Default)]
struct Candidate {
    scale: (f64, f64),
    fragments: Vec<Fragment>,
    /// The box's top-left in the region at the last pose.
    start: (i64, i64),
}

/// A FragTrack tracker.
#[derive(Debug)]
pub struct FragTrack {
    base: Base,
    bins: usize,
    strips: usize,
    quantile: f64,
    radius: f64,
    coarse_step: i64,
    scale_step: f64,
    model: Option<Model>,
    hist: IntegralHistogram,
    scores: Vec<f64>,
    vis: Vec<Quad>,
}

impl FragTrack {
    /// The robust score of `fragments` with their top-left at `(ox, oy)` of the region (lower
    /// is better).
    fn score(
        &mut self,
        fragments: &[Fragment],
        templates: &[Vec<f32>],
        (ox, oy): (usize, usize),
        cdf: &mut [f32],
    ) -> f64 {
        self.scores.clear();
        for (f, t) in fragments.iter().zip(templates) {
            cumulative(&self.hist, f, ox, oy, cdf);
            self.scores.push(emd(cdf, t));
        }
        quantile(&mut self.scores, self.quantile)
    }
}

impl WholeTracker for FragTrack {
    const MIN_SIDE: f64 = 6.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let (tw, th) = self.base.size0;
        let (bw, bh) = (tw.round().max(2.0) as usize, th.round().max(2.0) as usize);
        let n = self.strips.min(bw.min(bh) / 2).max(1);
        let fragments = strips(bw, bh, n);
        let (x, y) = (
            (self.base.pose.cx - 0.5 * bw as f64).round() as i64,
            (self.base.pose.cy - 0.5 * bh as f64).round() as i64,
        );
        let img = frame_f32(input);
        self.hist.build(&img, (x, y), (bw, bh), self.bins);
        let mut cdf = vec![0f32; self.bins];
        let templates = fragments
            .iter()
            .map(|f| {
                cumulative(&self.hist, f, 0, 0, &mut cdf);
                cdf.clone()
            })
            .collect();
        // The least scale keeps a strip (2 / (n + 1) of the side) at least two pixels wide.
        let least = (n as f64 + 1.0) / bw.min(bh) as f64;
        self.model = Some(Model {
            size0: (bw as f64, bh as f64),
            strips: n,
            scale: (1.0, 1.0),
            least: least.min(1.0),
            templates,
            offset: (
                self.base.pose.cx - (x as f64 + 0.5 * bw as f64),
                self.base.pose.cy - (y as f64 + 0.5 * bh as f64),
            ),
        });
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.base.status != TrackStatus::Tracking {
            return self.base.idle();
        }
        let Some(mut m) = self.model.take() else {
            return self.base.idle();
        };
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let r = self.radius.ceil() as i64;
        // The sizes tried: the last one first (it wins ties), then its width, height or both a
        // step larger and smaller.
        let mut scales = vec![m.scale];
        if self.scale_step > 0.0 {
            let (up, (sx, sy)) = (1.0 + self.scale_step, m.scale);
            // The width, the height, or both a step larger or smaller: a target seen from an
            // angle narrows along one axis.
            for (fx, fy) in [
                (up, up),
                (1.0 / up, 1.0 / up),
                (up, 1.0),
                (1.0 / up, 1.0),
                (1.0, up),
                (1.0, 1.0 / up),
            ] {
                let s = (
                    (sx * fx).clamp(m.least, MOST_SCALE),
                    (sy * fy).clamp(m.least, MOST_SCALE),
                );
                if !scales.iter().any(|&t| m.size(t) == m.size(s)) {
                    scales.push(s);
                }
            }
        }
        // One region holds every size's search: the largest box plus the radius around it.
        let boxes: Vec<((usize, usize), (i64, i64))> = scales
            .iter()
            .map(|&s| {
                let size = m.size(s);
                (size, m.top_left(&self.base.pose, size))
            })
            .collect();
        let (x0, y0, x1, y1) = boxes.iter().fold(
            (i64::MAX, i64::MAX, i64::MIN, i64::MIN),
            |(a, b, c, d), &((w, h), (x, y))| {
                (a.min(x), b.min(y), c.max(x + w as i64), d.max(y + h as i64))
            },
        );
        let (x0, y0, x1, y1) = (x0 - r, y0 - r, x1 + r, y1 + r);
        let (rw, rh) = ((x1 - x0) as usize, (y1 - y0) as usize);
        self.hist.build(&img, (x0, y0), (rw, rh), self.bins);
        let preprocess = started.elapsed();
        let mut cdf = vec![0f32; self.bins];
        let (radius, step) = (self.radius, self.coarse_step);
        let templates = std::mem::take(&mut m.templates);
        let mut best: Option<(f64, Candidate, (i64, i64))> = None;
        for (&scale, &(size, (bx, by))) in scales.iter().zip(&boxes) {
            let c = Candidate {
                scale,
                fragments: strips(size.0, size.1, m.strips),
                start: (bx - x0, by - y0),
            };
            let (xmax, ymax) = ((rw - size.0) as i64, (rh - size.1) as i64);
            // The last size searches the disc; the others are scored around the best centre found
            // so far (within SIZE_RADIUS): each at its own best position, a smaller box, free to
            // slide inside the target, would win by the least of more near-equal scores.
            let (centre, radius, step) = match &best {
                Some((_, b, at)) => (
                    (c.start.0 + at.0 - b.start.0, c.start.1 + at.1 - b.start.1),
                    SIZE_RADIUS,
                    1,
                ),
                None => (c.start, radius, step),
            };
            // Lower distances are better: the search maximises their negative.
            let (x, y, neg) = super::search_disc(centre, radius, step, |x, y| {
                if x < 0 || y < 0 || x > xmax || y > ymax {
                    return f64::NEG_INFINITY;
                }
                -self.score(&c.fragments, &templates, (x as usize, y as usize), &mut cdf)
            });
            if best.as_ref().is_none_or(|b| -neg < b.0) {
                best = Some((-neg, c, (x, y)));
            }
        }
        m.templates = templates;
        let (s, c, at) = best.unwrap_or((f64::NAN, Candidate::default(), (0, 0)));
        let found = if s.is_finite() {
            m.scale = c.scale;
            let pose = Pose {
                cx: self.base.pose.cx + (at.0 - c.start.0) as f64,
                cy: self.base.pose.cy + (at.1 - c.start.1) as f64,
                ..self.base.pose
            };
            // The similarity reported: 1 minus the robust distance over its largest (the bins).
            Ok((pose, 1.0 - s / self.bins as f64))
        } else {
            Err(LossReason::NonFinite)
        };
        let want = observer.wants_method_visuals();
        self.vis.clear();
        if want {
            let (tx, ty) = (x0 + at.0, y0 + at.1);
            self.vis.extend(c.fragments.iter().map(|f| {
                Quad::from_rect(
                    (tx + f.x0 as i64) as f64,
                    (ty + f.y0 as i64) as f64,
                    (f.x1 - f.x0) as f64,
                    (f.y1 - f.y0) as f64,
                )
            }));
        }
        self.model = Some(m);
        let weights = vec![0.5f32; self.vis.len()];
        let visual = want.then(|| MethodVisual::quads("fragments", &self.vis, &weights, None));
        self.base
            .finish(found, input.size(), started, preprocess, observer, visual)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integral_histograms_count_each_rectangle_and_strips_overlap_by_half() {
        // Values at the bins' centres (32, 96, 160, 224 for 4 bins) fall in one bin each.
        let centres = [32.0, 96.0, 160.0, 224.0];
        let img = GrayF32 {
            width: 6,
            height: 4,
            data: (0..24).map(|i| centres[i % 4]).collect(),
        };
        let mut ih = IntegralHistogram::default();
        ih.build(&img, (0, 0), (6, 4), 4);
        assert_eq!(ih.count(0, 0, 0, 6, 4), 6 * UNIT);
        assert_eq!(
            ih.count(1, 0, 0, 2, 1),
            UNIT,
            "pixels 0 and 1: one in bin 1"
        );
        // Between two centres a pixel is shared by its two bins; the mass is kept.
        let img = GrayF32 {
            width: 6,
            height: 4,
            data: (0..24).map(|i| (i * 10) as f32).collect(),
        };
        ih.build(&img, (0, 0), (6, 4), 4);
        let total: u32 = (0..4).map(|b| ih.count(b, 0, 0, 6, 4)).sum();
        assert_eq!(total, 24 * UNIT);
        // 10 is below the first centre (32): all in bin 0. 50 is 0.28 of the way from the
        // first centre to the second: 18 64ths in bin 1.
        assert_eq!(ih.count(0, 1, 0, 2, 1), UNIT);
        assert_eq!((ih.count(0, 5, 0, 6, 1), ih.count(1, 5, 0, 6, 1)), (46, 18));
        let s = strips(12, 9, 2);
        assert_eq!(s.len(), 4);
        assert_eq!((s[0].y0, s[0].y1, s[1].y0, s[1].y1), (0, 6, 3, 9));
        assert_eq!((s[2].x0, s[2].x1, s[3].x0, s[3].x1), (0, 8, 4, 12));
        assert_eq!(emd(&[0.5, 1.0], &[0.0, 1.0]), 0.5);
        assert_eq!(quantile(&mut [4.0, 1.0, 3.0, 2.0, 9.0], 0.25), 2.0);
    }

    #[test]
    fn a_rectangle_counts_the_same_wherever_its_region_starts() {
        // Values off the bins' centres (shared between two bins) on a large region: f32
        // summed-area tables would round the large sums differently at each origin.
        let img = GrayF32 {
            width: 300,
            height: 200,
            data: (0..60_000)
                .map(|i| ((i * 7919) % 251) as f32 + 0.37)
                .collect(),
        };
        let (mut a, mut b) = (IntegralHistogram::default(), IntegralHistogram::default());
        a.build(&img, (0, 0), (300, 200), 16);
        b.build(&img, (250, 150), (40, 40), 16);
        for bin in 0..16 {
            assert_eq!(
                a.count(bin, 260, 160, 280, 190),
                b.count(bin, 10, 10, 30, 40),
                "bin {bin}"
            );
        }
    }
}
