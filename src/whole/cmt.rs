//! CMT, consensus-based matching and tracking of keypoints (Nebehay and Pflugfelder, WACV 2014 /
//! CVPR 2015): the target's keypoints, found at initialisation, are followed by optical flow and
//! matched again by their descriptors on every frame; each keypoint then votes for the target's
//! centre given the scale and rotation agreed by all pairs, and the largest cluster of votes
//! decides. Outputs a rotated and scaled quad.

use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::crew::{Crew, threads_for};
use crate::error::Result;
use crate::geometry::{Point, Quad};
use crate::imaging::flow::{LkParams, Pyramid, track_forward_backward};
use crate::imaging::keypoints::{BRIEF_BORDER, Brief, Descriptor, fast_in, hamming, orientation};
use crate::imaging::{GrayF32, gaussian_blur, gaussian_kernel, resample_window};
use crate::linalg::median;
use crate::observe::MethodVisual;
use crate::observe::Observer;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, LossReason, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// CMT's parameters (the paper's values where it gives them).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::float(
        "fast_threshold",
        "FAST corner contrast threshold (gray levels)",
        1.0,
        100.0,
        20.0,
    ),
    ParamDef::int(
        "max_keypoints",
        "most keypoints matched per frame (the strongest around the target, or anywhere when lost)",
        50.0,
        10000.0,
        1000.0,
    ),
    ParamDef::int(
        "model_keypoints",
        "most keypoints of the target's model (the strongest corners), per view",
        10.0,
        10000.0,
        500.0,
    ),
    ParamDef::float(
        "ratio",
        "a match must be this much closer than the second best (Lowe's ratio test)",
        0.1,
        1.0,
        0.8,
    ),
    ParamDef::float(
        "max_distance",
        "largest descriptor distance of a match, as a fraction of its 256 bits",
        0.05,
        0.5,
        0.25,
    ),
    ParamDef::float(
        "cluster_threshold",
        "votes closer than this (px) are clustered together",
        1.0,
        100.0,
        20.0,
    ),
    ParamDef::float(
        "max_fb",
        "forward-backward error (px) above which a tracked keypoint is dropped",
        0.1,
        50.0,
        4.0,
    ),
    ParamDef::float(
        "min_inliers",
        "fewest inliers to keep the target, as a fraction of the model's keypoints (at least 3)",
        0.0,
        1.0,
        0.05,
    ),
    ParamDef::choice("scale", "estimate the scale", &["on", "off"]),
    ParamDef::choice("rotation", "estimate the rotation", &["on", "off"]),
    ParamDef::int("seed", "seed of the descriptor's tests", 0.0, 1e9, 0.0),
    ParamDef::int(
        "threads",
        "threads describing and matching the keypoints (0 = all cores); the result does not depend on it",
        0.0,
        256.0,
        0.0,
    ),
];

/// The scales at which the target's region is also described at initialisation.
const MODEL_SCALES: [f64; 4] = [0.8, 0.64, 0.5, 1.25];
/// Pixels around the target's bounding box in those views.
const MARGIN: f64 = 20.0;

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "cmt",
    aliases: &[],
    description: "consensus-based matching and tracking of keypoints (Nebehay and Pflugfelder 2014): FAST and binary descriptors, optical flow, votes; translation, scale and rotation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Similarity,
        build,
    },
};

/// Builds a CMT tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    Ok(Box::new(Cmt {
        base: Base::new(spec),
        fast_threshold: g("fast_threshold") as f32,
        max_keypoints: g("max_keypoints") as usize,
        model_keypoints: g("model_keypoints") as usize,
        ratio: g("ratio"),
        max_distance: (g("max_distance") * 256.0) as u32,
        cluster_threshold: g("cluster_threshold"),
        max_fb: g("max_fb"),
        min_inliers: g("min_inliers"),
        est_scale: g("scale") == 0.0,
        est_rotation: g("rotation") == 0.0,
        brief: Brief::new(g("seed") as u64),
        lk: LkParams::default(),
        threads: g("threads") as usize,
        crew: None,
        model: None,
        vis_points: Vec::new(),
        vis_weights: Vec::new(),
    }))
}

/// What the votes agree on.
#[derive(Clone, Debug, PartialEq)]
pub struct Consensus {
    pub centre: Point,
    pub scale: f64,
    pub angle: f64,
    /// Indices (into the keypoints given) of the votes in the largest cluster.
    pub inliers: Vec<usize>,
}

/// The consensus of keypoints `pts[i]` whose model offsets from the target's centre are
/// `offsets[model[i]]`: the scale is the median ratio of pairwise distances (now / model), the
/// rotation the median change of pairwise angles; each keypoint votes for the centre
/// `p - s R(a) offset`; the votes are clustered by single linkage at `threshold` px and the
/// largest cluster's median is the centre. `None` with fewer than two keypoints.
pub fn consensus(
    pts: &[Point],
    model: &[usize],
    offsets: &[Point],
    threshold: f64,
    est_scale: bool,
    est_rotation: bool,
) -> Option<Consensus> {
    let n = pts.len();
    if n < 2 {
        return None;
    }
    let mut scales = Vec::with_capacity(n * (n - 1) / 2);
    let mut angles = Vec::with_capacity(n * (n - 1) / 2);
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (offsets[model[i]], offsets[model[j]]);
            let (mx, my) = (b.x - a.x, b.y - a.y);
            let (px, py) = (pts[j].x - pts[i].x, pts[j].y - pts[i].y);
            let dm = (mx * mx + my * my).sqrt();
            if dm < 1e-9 {
                continue;
            }
            if est_scale {
                scales.push((px * px + py * py).sqrt() / dm);
            }
            if est_rotation {
                let d = py.atan2(px) - my.atan2(mx);
                angles.push(
                    (d + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                        - std::f64::consts::PI,
                );
            }
        }
    }
    let scale = if est_scale && !scales.is_empty() {
        median(scales)
    } else {
        1.0
    };
    let angle = if est_rotation && !angles.is_empty() {
        median(angles)
    } else {
        0.0
    };
    let (s, c) = angle.sin_cos();
    let votes: Vec<Point> = (0..n)
        .map(|i| {
            let o = offsets[model[i]];
            Point {
                x: pts[i].x - scale * (c * o.x - s * o.y),
                y: pts[i].y - scale * (s * o.x + c * o.y),
            }
        })
        .collect();
    // Single linkage: connected components of the "closer than threshold" graph.
    let label = super::components(n, |i, j| votes[i].dist(votes[j]) < threshold);
    let mut count = vec![0usize; n];
    for &r in &label {
        count[r] += 1;
    }
    let best = (0..n).max_by_key(|&r| count[r])?;
    let inliers: Vec<usize> = (0..n).filter(|&i| label[i] == best).collect();
    // The component-wise median of the cluster's votes: a few keypoints matched to a
    // neighbouring copy of a repeated texture stay within the cluster threshold but do not bias
    // the centre as they would the mean.
    let centre = Point {
        x: median(inliers.iter().map(|&i| votes[i].x).collect()),
        y: median(inliers.iter().map(|&i| votes[i].y).collect()),
    };
    Some(Consensus {
        centre,
        scale,
        angle,
        inliers,
    })
}

#[derive(Debug)]
struct Model {
    /// The descriptors of the target's keypoints (the first `nfg`) and of the background's
    /// (matches to them are rejected), in one array that each keypoint is compared with.
    descriptors: Vec<Descriptor>,
    nfg: usize,
    /// The target's keypoints' offsets from the initial centre.
    offsets: Vec<Point>,
    /// How many model points were found at the initial scale.
    native: usize,
    /// Each model point's place: points of the scaled views within 3 px of an earlier point
    /// share its place.
    place: Vec<usize>,
    /// The keypoints followed now, with their model index.
    active: Vec<(Point, usize)>,
    prev: Option<Pyramid>,
}

/// A CMT tracker.
#[derive(Debug)]
pub struct Cmt {
    base: Base,
    fast_threshold: f32,
    max_keypoints: usize,
    model_keypoints: usize,
    ratio: f64,
    max_distance: u32,
    cluster_threshold: f64,
    max_fb: f64,
    min_inliers: f64,
    est_scale: bool,
    est_rotation: bool,
    brief: Brief,
    lk: LkParams,
    threads: usize,
    /// The threads that describe and match the keypoints (each with its distances' scratch),
    /// started at the first initialisation.
    crew: Option<Crew<Vec<u32>>>,
    model: Option<Model>,
    vis_points: Vec<Point>,
    vis_weights: Vec<f32>,
}

/// Keypoints of a frame (of `region` of it, `x0, y0, x1, y1`, if given) with their
/// descriptors: every corner `keep` accepts and the `max` strongest of the others. A strongly
/// textured background would otherwise take every place from a weakly textured target.
fn describe_frame(
    crew: &mut Crew<Vec<u32>>,
    img: &GrayF32,
    brief: &Brief,
    threshold: f32,
    max: usize,
    region: Option<(f64, f64, f64, f64)>,
    keep: impl Fn(Point) -> bool,
) -> Vec<(Point, Descriptor)> {
    let (w, h) = (img.width, img.height);
    let r = region.map_or((0, 0, w, h), |(x0, y0, x1, y1)| {
        let c = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
        (c(x0, w), c(y0, h), c(x1, w), c(y1, h))
    });
    // Only the region (plus the descriptors' reach) is smoothed.
    let pad = BRIEF_BORDER + 3;
    let (sx0, sy0) = (r.0.saturating_sub(pad), r.1.saturating_sub(pad));
    let (sx1, sy1) = ((r.2 + pad).min(w), (r.3 + pad).min(h));
    let crop = GrayF32 {
        width: sx1 - sx0,
        height: sy1 - sy0,
        data: (sy0..sy1)
            .flat_map(|y| img.data[y * w + sx0..y * w + sx1].iter().copied())
            .collect(),
    };
    let smoothed = gaussian_blur(&crop, &gaussian_kernel(5, 2.0));
    let mut others = 0;
    let kept: Vec<_> = fast_in(img, threshold, BRIEF_BORDER, usize::MAX, r)
        .into_iter()
        .filter(|k| {
            keep(k.point()) || {
                others += 1;
                others <= max
            }
        })
        .collect();
    // Each keypoint described on its own, shared among the crew.
    let mut out = vec![None; kept.len()];
    crew.fill(&mut out, 16, &|_, i| {
        let k = &kept[i];
        // In the smoothed crop's pixels.
        let (x, y) = (k.x - sx0 as f64, k.y - sy0 as f64);
        let a = orientation(&smoothed, x as usize, y as usize, 15);
        brief.describe(&smoothed, x, y, a).map(|d| (k.point(), d))
    });
    out.into_iter().flatten().collect()
}

/// The best match of descriptor `d` among `descriptors` (the first `nfg` the target's, with
/// their `place`s) and the best of another place: `(best, second, index of the best)`. `dist`
/// is scratch.
fn best_two(
    d: &Descriptor,
    descriptors: &[Descriptor],
    nfg: usize,
    places: &[usize],
    dist: &mut Vec<u32>,
) -> (u32, u32, usize) {
    // Every distance first (a loop the compiler vectorises), then the best and the second best
    // of another place in one pass: a model point described at another scale is the same place
    // (no rival in the ratio test); each background keypoint is a place of its own.
    dist.clear();
    dist.extend(descriptors.iter().map(|e| hamming(d, e)));
    let (mut best, mut idx, mut place) = (u32::MAX, usize::MAX, usize::MAX);
    let mut second = u32::MAX;
    // Nothing changes for a distance of at least `second` (`best <= second`): a block whose
    // least distance is that large is passed over whole.
    const BLOCK: usize = 32;
    for (b, block) in dist.chunks(BLOCK).enumerate() {
        if block.iter().copied().min().unwrap_or(u32::MAX) >= second {
            continue;
        }
        for (k, &h) in block.iter().enumerate() {
            let i = b * BLOCK + k;
            let pl = if i < nfg {
                places[i]
            } else {
                usize::MAX - 1 - i
            };
            if pl == place {
                if h < best {
                    best = h;
                    idx = i;
                }
            } else if h < best {
                second = best;
                best = h;
                idx = i;
                place = pl;
            } else if h < second {
                second = h;
            }
        }
    }
    (best, second, idx)
}

impl WholeTracker for Cmt {
    const MIN_SIDE: f64 = 8.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, quad: &Quad) -> Result<()> {
        let img = frame_f32(input);
        let threads = threads_for(self.threads);
        let crew = match &mut self.crew {
            Some(crew) if crew.len() == threads => crew,
            slot => slot.insert(Crew::start(vec![Vec::new(); threads])?),
        };
        let inside = |p: Point| point_in_quad(quad, p);
        let kps = describe_frame(
            crew,
            &img,
            &self.brief,
            self.fast_threshold,
            self.max_keypoints,
            None,
            inside,
        );
        let c = self.base.c0;
        let (mut fg, mut offsets, mut bg, mut active) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (p, d) in kps {
            if inside(p) {
                // The strongest corners come first: the model keeps the best ones.
                if active.len() >= self.model_keypoints {
                    continue;
                }
                active.push((p, fg.len()));
                fg.push(d);
                offsets.push(Point {
                    x: p.x - c.x,
                    y: p.y - c.y,
                });
            } else {
                bg.push(d);
            }
        }
        // The target seen smaller and larger (its region resampled): descriptors are not
        // scale-invariant, so these views let matching find the target again after a zoom.
        // They are extra model points whose offsets are in the initial frame's pixels.
        let crate::geometry::Rect { x0, y0, x1, y1 } = quad.bbox();
        let (bw, bh) = (x1 - x0 + 2.0 * MARGIN, y1 - y0 + 2.0 * MARGIN);
        let (bx, by) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let mut buf = Vec::new();
        for f in MODEL_SCALES {
            let (ow, oh) = ((bw * f).round() as usize, (bh * f).round() as usize);
            resample_window(&img, bx, by, bw, bh, ow, oh, &mut buf);
            let view = GrayF32 {
                width: ow,
                height: oh,
                data: std::mem::take(&mut buf),
            };
            let to_frame = |p: Point| Point {
                x: bx + (p.x + 0.5 - 0.5 * ow as f64) * (bw / ow as f64),
                y: by + (p.y + 0.5 - 0.5 * oh as f64) * (bh / oh as f64),
            };
            let cap = self.model_keypoints;
            for (p, d) in describe_frame(
                crew,
                &view,
                &self.brief,
                self.fast_threshold,
                0,
                None,
                |p| inside(to_frame(p)),
            )
            .into_iter()
            .take(cap)
            {
                let q = to_frame(p);
                fg.push(d);
                offsets.push(Point {
                    x: q.x - c.x,
                    y: q.y - c.y,
                });
            }
            buf = view.data;
        }
        if active.len() < 3 {
            return Err(crate::Error::InvalidRegion(format!(
                "cmt: only {} keypoints in the target (at least 3 are needed); lower fast_threshold",
                active.len()
            )));
        }
        let mut place: Vec<usize> = Vec::with_capacity(offsets.len());
        for i in 0..offsets.len() {
            let same = (0..i).find(|&j| offsets[j].dist(offsets[i]) < 3.0);
            place.push(same.map_or(i, |j| place[j]));
        }
        let nfg = fg.len();
        let mut descriptors = fg;
        descriptors.extend(bg);
        self.model = Some(Model {
            native: active.len(),
            place,
            descriptors,
            nfg,
            offsets,
            active,
            prev: Some(Pyramid::new(&img, self.lk.levels)),
        });
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        if self.base.status == TrackStatus::Uninitialized {
            return self.base.idle();
        }
        let (Some(m), Some(crew)) = (self.model.as_mut(), self.crew.as_mut()) else {
            return self.base.idle();
        };
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let pyr = Pyramid::new(&img, self.lk.levels);
        let preprocess = started.elapsed();
        // Optical flow of the active keypoints.
        let mut fused: Vec<(Point, usize)> = Vec::new();
        if let Some(prev) = &m.prev {
            let pts: Vec<Point> = m.active.iter().map(|a| a.0).collect();
            for (a, t) in m
                .active
                .iter()
                .zip(track_forward_backward(prev, &pyr, &pts, &self.lk))
            {
                if let Some((q, fb)) = t
                    && fb <= self.max_fb
                {
                    fused.push((q, a.1));
                }
            }
        }
        // Global matching against the target's and the background's descriptors.
        let lost = m.active.is_empty();
        let (c, r) = (
            Point {
                x: self.base.pose.cx,
                y: self.base.pose.cy,
            },
            self.base.pose.scale * self.base.size0.0.max(self.base.size0.1),
        );
        // The `max_keypoints` strongest within twice the target's size of its last position, or
        // of the whole frame once lost (for the global matching to find the target again).
        let region = (!lost).then_some((c.x - r, c.y - r, c.x + r, c.y + r));
        let kps = describe_frame(
            crew,
            &img,
            &self.brief,
            self.fast_threshold,
            self.max_keypoints,
            region,
            |_| false,
        );
        let nfg = m.nfg;
        let mut taken = vec![false; nfg];
        for f in &fused {
            taken[f.1] = true;
        }
        let mut matches = vec![(u32::MAX, u32::MAX, usize::MAX); kps.len()];
        crew.fill(&mut matches, 8, &|dist, i| {
            best_two(&kps[i].1, &m.descriptors, nfg, &m.place, dist)
        });
        for ((p, _), &(best, second, idx)) in kps.iter().zip(&matches) {
            let good = idx < nfg
                && best <= self.max_distance
                && (best as f64) < self.ratio * second as f64;
            // A match adds a model point that is not tracked (one lost, or found again); a
            // tracked point passed the forward-backward check and is kept (on a repeated
            // texture a match may be a neighbouring copy).
            if good && !taken[idx] {
                taken[idx] = true;
                fused.push((*p, idx));
            }
        }
        let pts: Vec<Point> = fused.iter().map(|f| f.0).collect();
        let model_idx: Vec<usize> = fused.iter().map(|f| f.1).collect();
        let cons = consensus(
            &pts,
            &model_idx,
            &m.offsets,
            self.cluster_threshold,
            self.est_scale,
            self.est_rotation,
        );
        let need = ((self.min_inliers * m.native as f64).ceil() as usize).max(3);
        let found = match &cons {
            Some(c) if c.inliers.len() >= need => Ok((
                Pose {
                    cx: c.centre.x,
                    cy: c.centre.y,
                    scale: c.scale,
                    angle: c.angle,
                },
                (c.inliers.len() as f64 / m.native as f64).min(1.0),
            )),
            _ => Err(LossReason::NotFound),
        };
        m.active = match &cons {
            Some(c) if found.is_ok() => c.inliers.iter().map(|&i| fused[i]).collect(),
            _ => Vec::new(),
        };
        m.prev = Some(pyr);
        let want = observer.wants_method_visuals();
        if want {
            let inl: std::collections::HashSet<usize> = cons
                .as_ref()
                .map(|c| c.inliers.iter().copied().collect())
                .unwrap_or_default();
            self.vis_points = pts;
            self.vis_weights = (0..fused.len())
                .map(|i| if inl.contains(&i) { 1.0 } else { 0.15 })
                .collect();
        }
        let visual = want.then(|| MethodVisual {
            points: &self.vis_points,
            point_weights: &self.vis_weights,
            ..MethodVisual::quads("keypoints", &[], &[], None)
        });
        self.base
            .finish(found, input.size(), started, preprocess, observer, visual)
    }

    fn corners_set(&mut self) -> Result<()> {
        // The active keypoints belong to the old position: matching finds them again.
        if let Some(m) = self.model.as_mut() {
            m.active.clear();
        }
        Ok(())
    }
}

/// Whether `p` is inside the convex quad `q` (either orientation).
fn point_in_quad(q: &Quad, p: Point) -> bool {
    let mut sign = 0.0;
    for k in 0..4 {
        let (a, b) = (q.0[k], q.0[(k + 1) % 4]);
        let cross = (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
        if cross != 0.0 {
            if sign != 0.0 && cross.signum() != sign {
                return false;
            }
            sign = cross.signum();
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Keypoints moved by a similarity (scale 1.3, rotation 0.4, centre (200, 150)) plus a few
    /// outliers: the consensus recovers the similarity and leaves the outliers out.
    #[test]
    fn the_consensus_recovers_a_similarity_and_rejects_outliers() {
        let mut rng = Rng::new(4);
        let offsets: Vec<Point> = (0..30)
            .map(|_| Point {
                x: rng.range(-40.0, 40.0),
                y: rng.range(-30.0, 30.0),
            })
            .collect();
        let (s, a, cx, cy) = (1.3f64, 0.4f64, 200.0, 150.0);
        let mut pts: Vec<Point> = offsets
            .iter()
            .map(|o| Point {
                x: cx + s * (a.cos() * o.x - a.sin() * o.y) + 0.3 * rng.normal(),
                y: cy + s * (a.sin() * o.x + a.cos() * o.y) + 0.3 * rng.normal(),
            })
            .collect();
        let mut model: Vec<usize> = (0..30).collect();
        // Four keypoints matched to the wrong place.
        for k in 0..4 {
            pts.push(Point {
                x: 50.0 + 60.0 * k as f64,
                y: 300.0,
            });
            model.push(k * 5);
        }
        let c = consensus(&pts, &model, &offsets, 20.0, true, true).expect("consensus");
        assert!(
            (c.scale - s).abs() < 0.02 && (c.angle - a).abs() < 0.02,
            "{c:?}"
        );
        assert!(
            c.centre.dist(Point { x: cx, y: cy }) < 0.5,
            "{:?}",
            c.centre
        );
        assert_eq!(c.inliers, (0..30).collect::<Vec<_>>());
        // Without the rotation estimate, a rotated target's votes spread out (by up to
        // 2 sin(0.2) * 50 px): single linkage at 5 px splits them.
        let c = consensus(&pts, &model, &offsets, 5.0, true, false).unwrap();
        assert!(c.inliers.len() < 30, "{}", c.inliers.len());
        assert!(consensus(&pts[..1], &model[..1], &offsets, 20.0, true, true).is_none());
    }

    #[test]
    fn points_inside_a_quad() {
        let q = Quad::from_rect(0.0, 0.0, 10.0, 5.0);
        assert!(point_in_quad(&q, Point { x: 5.0, y: 2.0 }));
        assert!(!point_in_quad(&q, Point { x: 11.0, y: 2.0 }));
    }
}
