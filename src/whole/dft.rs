//! DFT, tracking with distribution fields (Sevilla-Lara and Learned-Miller, CVPR 2012): the
//! target is described by a *distribution field*, at each pixel a distribution over intensity
//! bins: the image "exploded" into one layer per bin (1 where the pixel falls in the bin),
//! smoothed across the bins (sigma_f, so that near intensities share mass) and in space
//! (sigma_s, so that a pixel's distribution includes its neighbours': a wide basin of
//! attraction that keeps the spatial layout). A candidate's field is compared with the model's
//! by the L1 distance; the search descends that distance from the last position, on a field
//! blurred more in space first (a wider basin), then on the model's own; the model is blended
//! with the field found, `M <- lambda M + (1 - lambda) D`. Translation only. Targets larger than
//! `cells` pixels a side are described on the frame averaged over blocks.

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

/// DFT's parameters (the paper's values by default).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::int(
        "bins",
        "intensity bins of the distribution field",
        2.0,
        64.0,
        16.0,
    ),
    ParamDef::float(
        "spatial_sigma",
        "spatial smoothing of the field (px of the described image)",
        0.0,
        10.0,
        1.0,
    ),
    ParamDef::float(
        "feature_sigma",
        "smoothing across the intensity bins (bins)",
        0.0,
        8.0,
        0.625,
    ),
    ParamDef::float(
        "coarse_sigma",
        "spatial smoothing of the field the search starts on (px of the described image)",
        0.0,
        20.0,
        4.0,
    ),
    ParamDef::float(
        "learning_rate",
        "weight of the old model in each update (the paper's lambda)",
        0.0,
        1.0,
        0.95,
    ),
    ParamDef::float(
        "search_radius",
        "the target is searched within this many pixels of its last position",
        2.0,
        200.0,
        30.0,
    ),
    ParamDef::int(
        "cells",
        "the target's longer side is described in at most this many pixels (larger targets on \
         the frame averaged over blocks)",
        8.0,
        256.0,
        40.0,
    ),
];

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "dft",
    aliases: &["distribution_fields", "df"],
    description: "distribution fields (Sevilla-Lara and Learned-Miller 2012): per-pixel intensity distributions smoothed in space and intensity, L1 descent, translation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Translation,
        build,
    },
};

/// Builds a DFT tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    let bins = g("bins") as usize;
    Ok(Box::new(Dft {
        base: Base::new(spec),
        bins,
        table: bin_weights(bins, g("feature_sigma")),
        kernels: (kernel(g("spatial_sigma")), kernel(g("coarse_sigma"))),
        rate: g("learning_rate"),
        radius: g("search_radius"),
        cells: g("cells") as usize,
        model: None,
        scratch: Scratch::default(),
    }))
}

/// A distribution field over a `w x h` region: `bins` layers of `w * h` values, layer by layer.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Field {
    pub w: usize,
    pub h: usize,
    pub bins: usize,
    pub data: Vec<f32>,
}

impl Field {
    fn at(&self, k: usize, x: usize, y: usize) -> f32 {
        self.data[(k * self.h + y) * self.w + x]
    }
}

/// The weights of intensity `v` (0..=255) over the bins: the one-hot layer of its bin smoothed
/// across the bins by a Gaussian of `sigma_f` bins (no smoothing at 0).
fn bin_weights(bins: usize, sigma_f: f64) -> Vec<f32> {
    let mut table = vec![0f32; 256 * bins];
    for v in 0..256 {
        let b = (v * bins / 256).min(bins - 1);
        let row = &mut table[v * bins..(v + 1) * bins];
        if sigma_f <= 0.0 {
            row[b] = 1.0;
            continue;
        }
        for (k, w) in row.iter_mut().enumerate() {
            let d = k as f64 - b as f64;
            *w = (-0.5 * d * d / (sigma_f * sigma_f)).exp() as f32;
        }
        let s: f32 = row.iter().sum();
        row.iter_mut().for_each(|w| *w /= s);
    }
    table
}

/// A normalised 1-D Gaussian kernel of `sigma` (radius 3 sigma; `[1]` at 0).
fn kernel(sigma: f64) -> Vec<f32> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (3.0 * sigma).ceil() as i64;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-0.5 * (i * i) as f64 / (sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.iter().map(|v| (v / s) as f32).collect()
}

/// Smooths each layer of `f` in space by the separable `k` (borders replicated). Each pass adds
/// one tap at a time over a whole row (a padded copy of it, or the rows above and below), so
/// that the inner loops vectorise.
fn blur_layers(f: &mut Field, k: &[f32], tmp: &mut Vec<f32>) {
    if k.len() == 1 {
        return;
    }
    let (w, h) = (f.w, f.h);
    let r = k.len() / 2;
    tmp.resize(w * h + w + (w + 2 * r), 0.0);
    let (rows, pad) = tmp.split_at_mut(w * h);
    let (acc, pad) = pad.split_at_mut(w);
    for layer in f.data.chunks_exact_mut(w * h) {
        // Along x: each row padded by its end values.
        for y in 0..h {
            let row = &layer[y * w..(y + 1) * w];
            pad[..r].fill(row[0]);
            pad[r..r + w].copy_from_slice(row);
            pad[r + w..].fill(row[w - 1]);
            let out = &mut rows[y * w..(y + 1) * w];
            out.fill(0.0);
            for (j, kv) in k.iter().enumerate() {
                for (o, v) in out.iter_mut().zip(&pad[j..j + w]) {
                    *o += kv * v;
                }
            }
        }
        // Along y: each output row the weighted sum of the rows around it (clamped).
        for y in 0..h {
            acc.fill(0.0);
            for (j, kv) in k.iter().enumerate() {
                let yy = (y + j).saturating_sub(r).min(h - 1);
                for (o, v) in acc.iter_mut().zip(&rows[yy * w..(yy + 1) * w]) {
                    *o += kv * v;
                }
            }
            layer[y * w..(y + 1) * w].copy_from_slice(acc);
        }
    }
}

/// The distribution field of the `w x h` region of `img` whose top-left pixel is `(x0, y0)`,
/// described on blocks of `step x step` pixels (their mean; pixels beyond the frame replicate
/// its border), with the bin weights `table` and the spatial kernel `k`.
#[cfg(test)]
#[allow(clippy::too_many_arguments)]
fn field_of(
    img: &GrayF32,
    step: usize,
    origin: (i64, i64),
    size: (usize, usize),
    bins: usize,
    table: &[f32],
    k: &[f32],
    out: &mut Field,
    tmp: &mut Vec<f32>,
) {
    explode(img, step, origin, size, bins, table, out);
    blur_layers(out, k, tmp);
}

/// The fields of a region at the smoothings `fine` and `coarse` ([`Dft::kernels`]): the region
/// exploded into its bins once, then smoothed each way.
#[allow(clippy::too_many_arguments)]
fn fields_of(
    img: &GrayF32,
    step: usize,
    origin: (i64, i64),
    size: (usize, usize),
    table: (&[f32], usize),
    (fine_k, fine): (&[f32], &mut Field),
    (coarse_k, coarse): (&[f32], &mut Field),
    tmp: &mut Vec<f32>,
) {
    explode(img, step, origin, size, table.1, table.0, fine);
    coarse.clone_from(fine);
    blur_layers(fine, fine_k, tmp);
    blur_layers(coarse, coarse_k, tmp);
}

/// The unsmoothed field of a region ([`field_of`] before the spatial smoothing): each described
/// pixel's bin weights from `table`.
fn explode(
    img: &GrayF32,
    step: usize,
    (x0, y0): (i64, i64),
    (w, h): (usize, usize),
    bins: usize,
    table: &[f32],
    out: &mut Field,
) {
    out.w = w;
    out.h = h;
    out.bins = bins;
    out.data.clear();
    out.data.resize(bins * w * h, 0.0);
    let (iw, ih) = (img.width as i64, img.height as i64);
    let inv = 1.0 / (step * step) as f32;
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for dy in 0..step as i64 {
                let py = ((y0 + y as i64) * step as i64 + dy).clamp(0, ih - 1) as usize;
                for dx in 0..step as i64 {
                    let px = ((x0 + x as i64) * step as i64 + dx).clamp(0, iw - 1) as usize;
                    s += img.data[py * img.width + px];
                }
            }
            let v = (s * inv).round().clamp(0.0, 255.0) as usize;
            let weights = &table[v * bins..(v + 1) * bins];
            for (b, wgt) in weights.iter().enumerate() {
                if *wgt != 0.0 {
                    out.data[(b * h + y) * w + x] = *wgt;
                }
            }
        }
    }
}

/// The L1 distance between `model` (the target's size) and the part of `field` whose top-left
/// is `(ox, oy)`.
pub(crate) fn l1_at(model: &Field, field: &Field, ox: usize, oy: usize) -> f64 {
    let mut s = 0.0f64;
    for k in 0..model.bins {
        for y in 0..model.h {
            let m = &model.data[(k * model.h + y) * model.w..][..model.w];
            let f = &field.data[(k * field.h + y + oy) * field.w + ox..][..model.w];
            // Eight partial sums, so that the loop vectorises.
            let mut acc = [0f32; 8];
            let (mc, fc) = (m.chunks_exact(8), f.chunks_exact(8));
            let (mr, fr) = (mc.remainder(), fc.remainder());
            for (a, b) in mc.zip(fc) {
                for i in 0..8 {
                    acc[i] += (a[i] - b[i]).abs();
                }
            }
            let tail: f32 = mr.iter().zip(fr).map(|(a, b)| (a - b).abs()).sum();
            s += (acc.iter().sum::<f32>() + tail) as f64;
        }
    }
    s
}

/// The part of `field` at `(ox, oy)` of the model's size, as a field.
fn crop(field: &Field, ox: usize, oy: usize, w: usize, h: usize, out: &mut Field) {
    out.w = w;
    out.h = h;
    out.bins = field.bins;
    out.data.clear();
    for k in 0..field.bins {
        for y in 0..h {
            for x in 0..w {
                out.data.push(field.at(k, ox + x, oy + y));
            }
        }
    }
}

/// Descends `cost` over integer offsets in `0..=lim` (both axes) from `start`, by moves to the
/// best of the 8 neighbours at each step size of `steps` until none is better. Returns the
/// offset and its cost.
fn descend(
    start: (usize, usize),
    lim: (usize, usize),
    steps: &[usize],
    mut cost: impl FnMut(usize, usize) -> f64,
) -> ((usize, usize), f64) {
    // Each offset's cost once (the neighbourhoods of successive moves overlap).
    let mut seen = vec![f64::NAN; (lim.0 + 1) * (lim.1 + 1)];
    let mut cost = |x: usize, y: usize| {
        let c = &mut seen[y * (lim.0 + 1) + x];
        if c.is_nan() {
            *c = cost(x, y);
        }
        *c
    };
    let mut at = start;
    let mut best = cost(at.0, at.1);
    for &s in steps {
        for _ in 0..200 {
            let mut moved = None;
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let x = at.0 as i64 + dx * s as i64;
                let y = at.1 as i64 + dy * s as i64;
                if x < 0 || y < 0 || x > lim.0 as i64 || y > lim.1 as i64 {
                    continue;
                }
                let c = cost(x as usize, y as usize);
                if c < best {
                    best = c;
                    moved = Some((x as usize, y as usize));
                }
            }
            match moved {
                Some(m) => at = m,
                None => break,
            }
        }
    }
    (at, best)
}

/// The offset of a parabola's minimum through `(-1, a)`, `(0, b)`, `(1, c)`, within half a step.
fn vertex(a: f64, b: f64, c: f64) -> f64 {
    let d = a - 2.0 * b + c;
    if d > 1e-12 {
        (0.5 * (a - c) / d).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

#[derive(Debug)]
struct Model {
    /// Pixels of the frame per described pixel.
    step: usize,
    /// The target's size in described pixels.
    bw: usize,
    bh: usize,
    /// The model's field, at the model's smoothing and at the coarse one.
    fine: Field,
    coarse: Field,
    /// The centre's offset (frame px) from the described box's centre, fixed at the start.
    offset: (f64, f64),
}

#[derive(Debug, Default)]
struct Scratch {
    fine: Field,
    coarse: Field,
    found: Field,
    /// The model's box with the pixels around it, at the start.
    wide: (Field, Field),
    tmp: Vec<f32>,
}

/// A DFT tracker.
#[derive(Debug)]
pub struct Dft {
    base: Base,
    bins: usize,
    /// The bin weights of each intensity ([`bin_weights`]).
    table: Vec<f32>,
    /// The spatial kernels of the model's field and of the coarse one the search starts on.
    kernels: (Vec<f32>, Vec<f32>),
    rate: f64,
    radius: f64,
    cells: usize,
    model: Option<Model>,
    scratch: Scratch,
}

impl Dft {
    /// The described box's top-left (described px) for the centre `(cx, cy)`, and the box's
    /// centre in frame px.
    fn box_at(&self, m: &Model, cx: f64, cy: f64) -> ((i64, i64), (f64, f64)) {
        let s = m.step as f64;
        let x = ((cx - m.offset.0) / s - 0.5 * m.bw as f64).round() as i64;
        let y = ((cy - m.offset.1) / s - 0.5 * m.bh as f64).round() as i64;
        (
            (x, y),
            (
                (x as f64 + 0.5 * m.bw as f64) * s + m.offset.0,
                (y as f64 + 0.5 * m.bh as f64) * s + m.offset.1,
            ),
        )
    }
}

impl WholeTracker for Dft {
    const MIN_SIDE: f64 = 6.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let (tw, th) = self.base.size0;
        let step = (tw.max(th) / self.cells as f64).ceil().max(1.0) as usize;
        let (bw, bh) = (
            ((tw / step as f64).round() as usize).max(3),
            ((th / step as f64).round() as usize).max(3),
        );
        let img = frame_f32(input);
        let mut m = Model {
            step,
            bw,
            bh,
            fine: Field::default(),
            coarse: Field::default(),
            offset: (0.0, 0.0),
        };
        let (cx, cy) = (self.base.pose.cx, self.base.pose.cy);
        let (tl, centre) = self.box_at(&m, cx, cy);
        m.offset = (cx - centre.0, cy - centre.1);
        let sc = &mut self.scratch;
        // Described with the pixels around the box, as a frame's region is: the smoothing near
        // the box's edges reads beyond it (a kernel's radius and one more).
        let (kf, kc) = (&self.kernels.0, &self.kernels.1);
        let r = kf.len().max(kc.len()) / 2 + 1;
        let (wide_fine, wide_coarse) = &mut sc.wide;
        fields_of(
            &img,
            step,
            (tl.0 - r as i64, tl.1 - r as i64),
            (bw + 2 * r, bh + 2 * r),
            (&self.table, self.bins),
            (kf, wide_fine),
            (kc, wide_coarse),
            &mut sc.tmp,
        );
        crop(wide_fine, r, r, bw, bh, &mut m.fine);
        crop(wide_coarse, r, r, bw, bh, &mut m.coarse);
        self.model = Some(m);
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        let Some(m) = self.model.as_ref() else {
            return self.base.idle();
        };
        if self.base.status != TrackStatus::Tracking {
            return self.base.idle();
        }
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let preprocess = started.elapsed();
        let margin = (self.radius / m.step as f64).ceil() as usize + 1;
        let ((x0, y0), _) = self.box_at(m, self.base.pose.cx, self.base.pose.cy);
        let origin = (x0 - margin as i64, y0 - margin as i64);
        let region = (m.bw + 2 * margin, m.bh + 2 * margin);
        let sc = &mut self.scratch;
        // The region's fields, smoothed as the model's were.
        fields_of(
            &img,
            m.step,
            origin,
            region,
            (&self.table, self.bins),
            (&self.kernels.0, &mut sc.fine),
            (&self.kernels.1, &mut sc.coarse),
            &mut sc.tmp,
        );
        let lim = (2 * margin, 2 * margin);
        let steps: Vec<usize> = [4usize, 2, 1]
            .into_iter()
            .filter(|&s| s <= margin.max(1))
            .collect();
        let (at, _) = descend((margin, margin), lim, &steps, |x, y| {
            l1_at(&m.coarse, &sc.coarse, x, y)
        });
        let (at, best) = descend(at, lim, &[1], |x, y| l1_at(&m.fine, &sc.fine, x, y));
        // Sub-pixel: a parabola through the neighbours on each axis.
        let c = |x: usize, y: usize| l1_at(&m.fine, &sc.fine, x, y);
        let sx = if at.0 > 0 && at.0 < lim.0 {
            vertex(c(at.0 - 1, at.1), best, c(at.0 + 1, at.1))
        } else {
            0.0
        };
        let sy = if at.1 > 0 && at.1 < lim.1 {
            vertex(c(at.0, at.1 - 1), best, c(at.0, at.1 + 1))
        } else {
            0.0
        };
        let s = m.step as f64;
        let pose = Pose {
            cx: (origin.0 as f64 + at.0 as f64 + sx + 0.5 * m.bw as f64) * s + m.offset.0,
            cy: (origin.1 as f64 + at.1 as f64 + sy + 0.5 * m.bh as f64) * s + m.offset.1,
            ..self.base.pose
        };
        // The similarity reported: 1 minus the L1 distance per pixel over its largest (2).
        let sim = 1.0 - best / (2.0 * (m.bw * m.bh) as f64);
        let found = if best.is_finite() {
            Ok((pose, sim))
        } else {
            Err(LossReason::NonFinite)
        };
        // The model follows: blended with the fields found.
        let (bw, bh) = (m.bw, m.bh);
        let l = self.rate as f32;
        if let Some(m) = self.model.as_mut() {
            for (field, model) in [(&sc.fine, &mut m.fine), (&sc.coarse, &mut m.coarse)] {
                crop(field, at.0, at.1, bw, bh, &mut sc.found);
                for (a, b) in model.data.iter_mut().zip(&sc.found.data) {
                    *a = l * *a + (1.0 - l) * b;
                }
            }
        }
        let want = observer.wants_method_visuals();
        let quads = [Quad::from_rect(
            (origin.0 as f64) * s,
            (origin.1 as f64) * s,
            region.0 as f64 * s,
            region.1 as f64 * s,
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
    fn a_field_is_a_distribution_at_each_pixel_and_smoothing_keeps_it_one() {
        let img = GrayF32 {
            width: 8,
            height: 6,
            data: (0..48).map(|i| (i * 5) as f32).collect(),
        };
        let table = bin_weights(8, 0.625);
        let (mut f, mut tmp) = (Field::default(), Vec::new());
        field_of(
            &img,
            1,
            (0, 0),
            (8, 6),
            8,
            &table,
            &kernel(1.0),
            &mut f,
            &mut tmp,
        );
        for y in 0..6 {
            for x in 0..8 {
                let s: f32 = (0..8).map(|k| f.at(k, x, y)).sum();
                assert!((s - 1.0).abs() < 1e-5, "{s} at {x},{y}");
            }
        }
        // Without smoothing, a pixel's mass is all in its own bin.
        let table = bin_weights(8, 0.0);
        field_of(
            &img,
            1,
            (0, 0),
            (8, 6),
            8,
            &table,
            &kernel(0.0),
            &mut f,
            &mut tmp,
        );
        assert_eq!(f.at(3, 4, 2), 1.0, "pixel 20 is 100: bin 3");
        assert_eq!(f.at(2, 4, 2), 0.0);
    }

    #[test]
    fn the_descent_finds_a_shifted_copy_and_l1_is_zero_there() {
        // A smooth blob; its field at a 3, 2 offset inside a larger region.
        let img = GrayF32 {
            width: 40,
            height: 30,
            data: (0..1200)
                .map(|i| {
                    let (x, y) = ((i % 40) as f64, (i / 40) as f64);
                    (255.0 * (-((x - 20.0).powi(2) + (y - 14.0).powi(2)) / 40.0).exp()) as f32
                })
                .collect(),
        };
        let table = bin_weights(16, 0.625);
        let k = kernel(1.0);
        let (mut wide, mut model, mut region, mut tmp) = (
            Field::default(),
            Field::default(),
            Field::default(),
            Vec::new(),
        );
        // The model: the box at (13, 8) of a field of the pixels around it (as `start` makes it).
        field_of(
            &img,
            1,
            (8, 4),
            (24, 20),
            16,
            &table,
            &k,
            &mut wide,
            &mut tmp,
        );
        crop(&wide, 5, 4, 12, 10, &mut model);
        field_of(
            &img,
            1,
            (10, 6),
            (20, 16),
            16,
            &table,
            &k,
            &mut region,
            &mut tmp,
        );
        let (at, best) = descend((4, 4), (8, 6), &[2, 1], |x, y| l1_at(&model, &region, x, y));
        assert_eq!(at, (3, 2));
        // Zero but for the region's border (the smoothing replicates it one row above the box).
        let start = l1_at(&model, &region, 4, 4);
        assert!(best < 0.1 && best < 0.01 * start, "{best} (start {start})");
        assert_eq!(vertex(2.0, 1.0, 2.0), 0.0);
        assert!((vertex(3.0, 1.0, 2.0) - 1.0 / 6.0).abs() < 1e-12);
    }
}
