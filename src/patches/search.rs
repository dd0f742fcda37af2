//! One patch's search: its warp and grid, its template at every level (values,
//! steepest-descent images, inverse Hessian), inverse-compositional Lucas-Kanade from coarse to
//! fine, and the patch's correlation with its template (NCC).

use super::kernels::{dot, dot2};
use super::*;
use crate::geometry::Point;
use crate::imaging::{self, COARSE_EPS, GrayF32, ImageView};
use crate::status::{LossReason, TrackStatus};
use nalgebra::{Matrix2, SMatrix};

/// A patch's warp: frame point of patch offset `u` at level `l` is `A u + c / 2^l`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Warp {
    pub(super) a: [f64; 4],
    pub(super) c: Point,
}

impl Warp {
    pub(super) fn at(c: Point) -> Self {
        Warp {
            a: [1.0, 0.0, 0.0, 1.0],
            c,
        }
    }

    pub(super) fn is_shift(&self) -> bool {
        self.a == [1.0, 0.0, 0.0, 1.0]
    }
}

/// The sampling grid's offsets from a patch's centre, shared by all patches.
///
/// Every per-sample array of a patch (template, steepest-descent images, samples) is stored
/// row by row with `stride` entries a row: `side` rounded up to lanes of eight, so the loops
/// over them run whole lanes. The entries past `side` are padding: the template and its
/// steepest-descent images are zero there (they weigh nothing in the sums) and `mask` is 0.
#[derive(Clone, Debug)]
pub(super) struct Grid {
    pub(super) side: usize,
    pub(super) half: f64,
    pub(super) stride: usize,
    pub(super) ux: Vec<f32>,
    pub(super) uy: Vec<f32>,
    /// 1 on the grid's samples, 0 on the padding.
    pub(super) mask: Vec<f32>,
    /// The grid grown by one sample on every side (for the template's central differences):
    /// `side + 2` rows of `ext_stride` (at least `stride + 2`, in lanes of eight) samples from
    /// `-half - 1`.
    pub(super) ext_stride: usize,
    pub(super) ex: Vec<f32>,
    pub(super) ey: Vec<f32>,
}

impl Grid {
    pub(super) fn new(side: usize) -> Self {
        let half = (side as f64 - 1.0) / 2.0;
        let stride = side.div_ceil(8) * 8;
        let ext_stride = (stride + 2).div_ceil(8) * 8;
        let offsets = |from: f64, rows: usize, cols: usize| {
            let (mut xs, mut ys) = (Vec::new(), Vec::new());
            for j in 0..rows {
                for i in 0..cols {
                    xs.push((i as f64 - from) as f32);
                    ys.push((j as f64 - from) as f32);
                }
            }
            (xs, ys)
        };
        let (ux, uy) = offsets(half, side, stride);
        let (ex, ey) = offsets(half + 1.0, side + 2, ext_stride);
        let mask = (0..side * stride)
            .map(|k| if k % stride < side { 1.0 } else { 0.0 })
            .collect();
        Grid {
            side,
            half,
            stride,
            ux,
            uy,
            mask,
            ext_stride,
            ex,
            ey,
        }
    }

    /// The grid's samples.
    pub(super) fn len(&self) -> usize {
        self.side * self.side
    }

    /// The entries of a per-sample array, padding included.
    pub(super) fn padded_len(&self) -> usize {
        self.side * self.stride
    }
}

/// The pre-processing's buffers of one thread.
#[derive(Clone, Debug, Default)]
pub(super) struct PrepBuffers {
    pub(super) tmp: Vec<f32>,
    pub(super) line: Vec<f32>,
    pub(super) half: Vec<f32>,
}

/// A template at every level: values, steepest-descent images and the inverse Hessian.
#[derive(Clone, Debug, Default)]
pub(super) struct Template {
    pub(super) t: Vec<f32>,
    pub(super) sd: Vec<f32>,
    /// `SD^T T` per level: the residual's projection is `SD^T I(W(u))` minus this.
    pub(super) sdt: Vec<[f64; 6]>,
    pub(super) hinv: Vec<[f64; 36]>,
    pub(super) usable: Vec<bool>,
}

/// One patch: its state, warp and, when it keeps the first frame's, its template.
#[derive(Clone, Debug)]
pub(super) struct Patch {
    pub(super) state: PatchState,
    pub(super) warp: Warp,
    /// The first frame's template (`template=first`); made again each frame otherwise.
    pub(super) first: Option<Box<Template>>,
}

/// What a thread tracking patches works in, one patch after the other: the template made
/// each frame, the backward one and the samples. Kept by the thread (not by each patch), so
/// it stays in the core's cache.
#[derive(Clone, Debug)]
pub(super) struct Scratch {
    pub(super) fwd: Template,
    pub(super) back: Template,
    pub(super) buf: Buffers,
    pub(super) prep: PrepBuffers,
}

/// The samples of one search or template.
#[derive(Clone, Debug)]
pub(super) struct Buffers {
    pub(super) vals: Vec<f32>,
    pub(super) xs: Vec<f32>,
    pub(super) ys: Vec<f32>,
    /// The template's values on the grown grid.
    pub(super) ext: Vec<f32>,
}

/// Patches a thread takes at a time.
pub(super) const PATCH_BLOCK: usize = 16;

/// Why a search failed.
pub(super) type Search = std::result::Result<(Warp, usize, f64), LossReason>;

impl Template {
    pub(super) fn new(grid: &Grid, levels: usize, dof: usize) -> Self {
        let n = grid.padded_len();
        Template {
            t: vec![0.0; levels * n],
            sd: vec![0.0; levels * dof * n],
            hinv: vec![[0.0; 36]; levels],
            sdt: vec![[0.0; 6]; levels],
            usable: vec![false; levels],
        }
    }
}

impl Scratch {
    pub(super) fn new(grid: &Grid, levels: usize, dof: usize) -> Self {
        let n = grid.padded_len().max(grid.ex.len());
        Scratch {
            fwd: Template::new(grid, levels, dof),
            back: Template::new(grid, levels, dof),
            buf: Buffers {
                vals: vec![0.0; grid.padded_len()],
                xs: vec![0.0; n],
                ys: vec![0.0; n],
                ext: vec![0.0; grid.ex.len()],
            },
            prep: PrepBuffers::default(),
        }
    }
}

impl Patch {
    pub(super) fn new(centre: Point) -> Self {
        Patch {
            state: PatchState {
                centre,
                linear: [1.0, 0.0, 0.0, 1.0],
                status: TrackStatus::Tracking,
                ncc: 1.0,
                fb_error: None,
                iterations: 0,
            },
            warp: Warp::at(centre),
            first: None,
        }
    }
}

/// A grid's layout for [`sample`]: columns (the row stride), rows, the offset of its first
/// sample from the centre (negated) and every sample's offsets.
pub(super) type Layout<'a> = (usize, usize, f64, &'a [f32], &'a [f32]);

/// Samples `img` at the grid warped by `w` at level `l` into `out` (`xs`, `ys` are scratch).
#[allow(clippy::too_many_arguments)]
pub(super) fn sample(
    (img, border): (&GrayF32, usize),
    w: &Warp,
    l: usize,
    (cols, rows, half, ux, uy): Layout<'_>,
    out: &mut [f32],
    xs: &mut [f32],
    ys: &mut [f32],
) {
    let s = (1u32 << l) as f64;
    let b = border as f64;
    let (cx, cy) = (w.c.x / s + b, w.c.y / s + b);
    if w.is_shift()
        && imaging::sample_grid_shifted(
            img,
            (cx - half) as f32,
            (cy - half) as f32,
            cols,
            rows,
            out,
        )
    {
        return;
    }
    let [a, b, c, d] = w.a.map(|v| v as f32);
    let (cx, cy) = (cx as f32, cy as f32);
    let n = cols * rows;
    let (xs, ys, out) = (&mut xs[..n], &mut ys[..n], &mut out[..n]);
    for i in 0..n {
        let (u, v) = (ux[i], uy[i]);
        xs[i] = a * u + b * v + cx;
        ys[i] = c * u + d * v + cy;
    }
    let view = ImageView::new(&img.data, img.width, img.height, 0, 0);
    imaging::sample_values(&view, xs, ys, out);
}

impl Grid {
    /// The grid, for [`sample`].
    pub(super) fn plain(&self) -> Layout<'_> {
        (self.stride, self.side, self.half, &self.ux, &self.uy)
    }

    /// The grid grown by one sample on every side, for [`sample`].
    pub(super) fn grown(&self) -> Layout<'_> {
        (
            self.ext_stride,
            self.side + 2,
            self.half + 1.0,
            &self.ex,
            &self.ey,
        )
    }
}

/// The warp searched at level `l`: affine patches that follow the previous frame's patch search
/// only a shift, on an image-aligned window, at the coarse levels (between two frames the
/// shape barely changes; the shift is what the coarse levels are for), then the whole affine
/// warp at the finest level. Their coarse levels then cost what a translation patch's do.
pub(super) fn level_warp(prm: &PatchParams, l: usize) -> PatchWarp {
    if l > 0 && prm.warp == PatchWarp::Affine && prm.template == TemplateSource::Previous {
        PatchWarp::Translation
    } else {
        prm.warp
    }
}

/// The window sampled at level `l` for the warp `w`: image-aligned where [`level_warp`] is a
/// shift of an affine patch.
pub(super) fn level_window(prm: &PatchParams, l: usize, w: &Warp) -> Warp {
    if level_warp(prm, l) != prm.warp {
        Warp::at(w.c)
    } else {
        *w
    }
}

/// The template of the patch warped by `w` in `frame`, at every level, into `tp`. Flat levels
/// are marked unusable; `false` when the finest is flat.
pub(super) fn make_template(
    tp: &mut Template,
    b: &mut Buffers,
    frame: &Frame,
    start: &Warp,
    grid: &Grid,
    prm: &PatchParams,
) -> bool {
    let (n, np) = (grid.len(), grid.padded_len());
    let full = prm.warp.dof();
    let min_eigen = prm.min_eigen;
    for l in 0..frame.levels.len() {
        let dof = level_warp(prm, l).dof();
        let w = &level_window(prm, l, start);
        // The values on the grown grid; the template is its inside and the gradients in patch
        // coordinates its central differences (for a shift, exactly the bilinear samples of the
        // frame's central-difference gradients).
        sample(
            frame.level(l),
            w,
            l,
            grid.grown(),
            &mut b.ext,
            &mut b.xs,
            &mut b.ys,
        );
        let t = &mut tp.t[l * np..(l + 1) * np];
        let sd = &mut tp.sd[l * full * np..(l * full + dof) * np];
        let (tx, rest) = sd.split_at_mut(np);
        let (ty, rest) = rest.split_at_mut(np);
        // One pass in lanes of eight: the template, its gradients (zero on the padding) and
        // the sums of their products: SD^T T and the shift's 2x2 Hessian.
        let rows = kernels::Rows {
            ext: &b.ext,
            ext_stride: grid.ext_stride,
            stride: grid.stride,
            side: grid.side,
            mask: &grid.mask,
        };
        let [stx, sty, hxx, hxy, hyy] = kernels::template_rows(&rows, t, tx, ty).map(f64::from);
        if dof == 6 {
            // Columns: tx ux, tx uy, ty ux, ty uy, tx, ty (the shift last).
            let (c0, rest) = rest.split_at_mut(np);
            let (c1, rest) = rest.split_at_mut(np);
            let (c2, c3) = rest.split_at_mut(np);
            for i in 0..np {
                let (u, v) = (grid.ux[i], grid.uy[i]);
                c0[i] = tx[i] * u;
                c1[i] = tx[i] * v;
                c2[i] = ty[i] * u;
                c3[i] = ty[i] * v;
            }
            // Reorder so the shift's columns come last: [c0 c1 c2 c3 tx ty].
            sd.rotate_left(2 * np);
        }
        let sd = &tp.sd[l * full * np..(l * full + dof) * np];
        let col = |k: usize| &sd[k * np..(k + 1) * np];
        let t = &tp.t[l * np..(l + 1) * np];
        for k in 0..dof - 2 {
            tp.sdt[l][k] = dot(col(k), t) as f64;
        }
        tp.sdt[l][dof - 2] = stx;
        tp.sdt[l][dof - 1] = sty;
        let tr = hxx + hyy;
        let det = hxx * hyy - hxy * hxy;
        let min_eig = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt()) / n as f64;
        let mut usable = min_eig >= min_eigen && min_eig > 0.0;
        if usable {
            match dof {
                2 => {
                    let h = Matrix2::new(hxx, hxy, hxy, hyy);
                    match h.try_inverse() {
                        Some(inv) => {
                            tp.hinv[l][..4].copy_from_slice(inv.as_slice());
                        }
                        None => usable = false,
                    }
                }
                _ => {
                    let mut h = SMatrix::<f64, 6, 6>::zeros();
                    for r in 0..6 {
                        for c in r..6 {
                            let v = dot(col(r), col(c)) as f64;
                            h[(r, c)] = v;
                            h[(c, r)] = v;
                        }
                    }
                    match h.try_inverse() {
                        Some(inv) if inv.iter().all(|v| v.is_finite()) => {
                            tp.hinv[l].copy_from_slice(inv.as_slice());
                        }
                        _ => usable = false,
                    }
                }
            }
        }
        tp.usable[l] = usable;
    }
    tp.usable.first().copied().unwrap_or(false)
}

/// Searches `frame` for the template `tp` (forward or backward) from `start`, coarse to
/// fine. Returns the warp, the iterations and the template's NCC with the last samples.
pub(super) fn search(
    tp: &Template,
    b: &mut Buffers,
    frame: &Frame,
    start: Warp,
    grid: &Grid,
    prm: &PatchParams,
) -> Search {
    let np = grid.padded_len();
    let full = prm.warp.dof();
    let mut w = start;
    let mut iterations = 0;
    let levels = frame.levels.len();
    let mut last_level_sampled = false;
    for l in (0..levels).rev() {
        if !tp.usable[l] {
            continue;
        }
        let s = (1u32 << l) as f64;
        let img = frame.level(l);
        // A coarse level only has to bring the patch within the finer level's basin.
        let eps = if l == 0 {
            prm.eps
        } else {
            prm.eps.max(COARSE_EPS)
        };
        let model = level_warp(prm, l);
        let dof = model.dof();
        for _ in 0..prm.iterations {
            // The window searched (image-aligned for the shift of an affine patch).
            let win = level_window(prm, l, &w);
            sample(
                img,
                &win,
                l,
                grid.plain(),
                &mut b.vals,
                &mut b.xs,
                &mut b.ys,
            );
            iterations += 1;
            // SD^T (I(W(u)) - T), with SD^T T made once per template.
            let sd = &tp.sd[l * full * np..(l * full + dof) * np];
            let mut g = [0f64; 6];
            for k in (0..dof).step_by(2) {
                let (a, b) = dot2(
                    &sd[k * np..(k + 1) * np],
                    &sd[(k + 1) * np..(k + 2) * np],
                    &b.vals,
                );
                g[k] = a as f64 - tp.sdt[l][k];
                g[k + 1] = b as f64 - tp.sdt[l][k + 1];
            }
            let hinv = &tp.hinv[l];
            let mut dp = [0f64; 6];
            for r in 0..dof {
                // Column-major inverse (nalgebra's layout); it is symmetric anyway.
                dp[r] = (0..dof).map(|c| hinv[c * dof + r] * g[c]).sum();
            }
            // W <- W o W(dp)^-1: with W(dp) = M u + t, A' = A M^-1 and c' = c - A' t.
            let (m, t) = match model {
                PatchWarp::Translation => ([1.0, 0.0, 0.0, 1.0], (dp[0], dp[1])),
                PatchWarp::Affine => ([1.0 + dp[0], dp[1], dp[2], 1.0 + dp[3]], (dp[4], dp[5])),
            };
            let det = m[0] * m[3] - m[1] * m[2];
            if !(det.is_finite() && det.abs() > 1e-6) {
                return Err(LossReason::Singular);
            }
            let mi = [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det];
            let a = win.a;
            let na = [
                a[0] * mi[0] + a[1] * mi[2],
                a[0] * mi[1] + a[1] * mi[3],
                a[2] * mi[0] + a[3] * mi[2],
                a[2] * mi[1] + a[3] * mi[3],
            ];
            // The centre at this level, moved; back in frame pixels.
            let (cx, cy) = (
                w.c.x / s - (na[0] * t.0 + na[1] * t.1),
                w.c.y / s - (na[2] * t.0 + na[3] * t.1),
            );
            let next = Warp {
                a: if model == PatchWarp::Translation {
                    w.a
                } else {
                    na
                },
                c: Point {
                    x: cx * s,
                    y: cy * s,
                },
            };
            if !(next.c.is_finite() && next.a.iter().all(|v| v.is_finite())) {
                return Err(LossReason::NonFinite);
            }
            // How far the window's corners moved (pixels of this level).
            let h = grid.half;
            let mut step = 0f64;
            for (u, v) in [(-h, -h), (h, -h), (h, h), (-h, h)] {
                let dx =
                    (next.a[0] - w.a[0]) * u + (next.a[1] - w.a[1]) * v + (next.c.x - w.c.x) / s;
                let dy =
                    (next.a[2] - w.a[2]) * u + (next.a[3] - w.a[3]) * v + (next.c.y - w.c.y) / s;
                step = step.max(dx * dx + dy * dy);
            }
            w = next;
            last_level_sampled = l == 0;
            if step < eps * eps {
                break;
            }
        }
    }
    let ad = w.a[0] * w.a[3] - w.a[1] * w.a[2];
    if !(0.2..=5.0).contains(&ad) {
        return Err(LossReason::Degenerate);
    }
    // The NCC of the finest level's last samples with the template.
    if !last_level_sampled {
        return Err(LossReason::Singular);
    }
    Ok((
        w,
        iterations,
        ncc(&b.vals, &tp.t[..np], &grid.mask, grid.len()),
    ))
}

/// The zero-mean normalised cross-correlation of two equally long vectors over the entries
/// where `mask` is 1 (`mask` is 0 or 1; 0 when either is flat). One pass over eight lanes, on
/// values shifted by the first of `b` (gray levels are small enough that the single-precision
/// sums keep the correlation to about 1e-4).
pub(super) fn ncc(a: &[f32], b: &[f32], mask: &[f32], count: usize) -> f64 {
    let n = a.len().min(b.len()).min(mask.len());
    let Some(&k) = b.first() else {
        return 0.0;
    };
    let mut acc = [[0f32; 8]; 5];
    let (ca, cb, cm) = (
        a[..n].chunks_exact(8),
        b[..n].chunks_exact(8),
        mask[..n].chunks_exact(8),
    );
    let (ra, rb, rm) = (ca.remainder(), cb.remainder(), cm.remainder());
    for ((x, y), m) in ca.zip(cb).zip(cm) {
        for l in 0..8 {
            let (x, y) = ((x[l] - k) * m[l], (y[l] - k) * m[l]);
            acc[0][l] += x;
            acc[1][l] += y;
            acc[2][l] += x * x;
            acc[3][l] += y * y;
            acc[4][l] += x * y;
        }
    }
    let mut s = acc.map(|a| a.iter().map(|&v| v as f64).sum::<f64>());
    for ((&x, &y), &m) in ra.iter().zip(rb).zip(rm) {
        let (x, y) = (((x - k) * m) as f64, ((y - k) * m) as f64);
        s[0] += x;
        s[1] += y;
        s[2] += x * x;
        s[3] += y * y;
        s[4] += x * y;
    }
    let nf = count.max(1) as f64;
    let aa = s[2] - s[0] * s[0] / nf;
    let bb = s[3] - s[1] * s[1] / nf;
    let ab = s[4] - s[0] * s[1] / nf;
    if aa <= 1e-6 * nf || bb <= 1e-6 * nf {
        0.0
    } else {
        (ab / (aa * bb).sqrt()).clamp(-1.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ncc_is_one_up_to_gain_and_bias_and_zero_for_a_flat_patch() {
        let a: Vec<f32> = (0..441)
            .map(|i| 100.0 + 60.0 * (i as f32 * 0.3).sin())
            .collect();
        let b: Vec<f32> = a.iter().map(|v| 0.5 * v + 40.0).collect();
        let m = vec![1.0; 441];
        let r = ncc(&a, &b, &m, 441);
        assert!((r - 1.0).abs() < 1e-4, "{r}");
        let c: Vec<f32> = a.iter().map(|v| 255.0 - v).collect();
        assert!((ncc(&a, &c, &m, 441) + 1.0).abs() < 1e-4);
        assert_eq!(ncc(&a, &vec![7.0; 441], &m, 441), 0.0);
        // The masked entries do not count, whatever they hold.
        let mut d = b.clone();
        let mut half = m.clone();
        for k in (1..441).step_by(3) {
            d[k] = -1e4;
            half[k] = 0.0;
        }
        assert!((ncc(&a, &d, &half, 294) - 1.0).abs() < 1e-4);
    }
}
