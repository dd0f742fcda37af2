//! What the correlation-filter trackers (KCF, DSST) share: the feature window around the target
//! (HOG cells or raw pixels, under a Hann window), the Gaussian label, the kernel correlation in
//! the Fourier domain and the sub-pixel peak of a response.

use crate::crew::{Crew, Shares};
use crate::geometry::Quad;
use crate::imaging::fft::{C32, Fft2};
use crate::imaging::hog::{FHOG_CHANNELS, FeatureMap, fhog, fhog_on};
use crate::imaging::{GrayF32, resample_window, resample_window_on};
use crate::observe::{MethodVisual, ResponseMap};

/// Which features a filter sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Features {
    /// 31-channel HOG cells ([`fhog`]).
    Hog,
    /// The gray levels less their mean over the window, over 255 (one channel, one pixel per
    /// cell).
    Raw,
}

impl Features {
    /// `hog` = 0, `raw` = 1 (the order of the `features` parameter's choices).
    pub fn from_index(i: f64) -> Self {
        if i as usize == 1 {
            Features::Raw
        } else {
            Features::Hog
        }
    }
    pub fn channels(self) -> usize {
        match self {
            Features::Hog => FHOG_CHANNELS,
            Features::Raw => 1,
        }
    }
}

/// What a correlation filter of a `tw x th` target starts from: the window it reads, its
/// Fourier transform, the Hann window and the spectrum of the response it learns to give (a
/// Gaussian `output_sigma` times the target's size wide, in cells).
pub struct Basis {
    pub win: Window,
    pub fft: Fft2,
    pub hann: Vec<f32>,
    pub yf: Vec<C32>,
}

impl Basis {
    /// See [`Basis`]; `padding`, `template_size`, `features` and `cell` as [`Window::new`].
    pub fn new(
        (tw, th): (f64, f64),
        (padding, template_size): (f64, usize),
        (features, cell): (Features, usize),
        output_sigma: f64,
    ) -> Self {
        let win = Window::new(tw, th, padding, template_size, features, cell);
        let (w, h) = win.cells();
        let mut fft = Fft2::new(w, h);
        let sigma = (tw * th).sqrt() * output_sigma / win.cell_px(1.0);
        let mut yf = Vec::new();
        fft.forward_real(&gaussian_label(w, h, sigma), &mut yf);
        Basis {
            win,
            fft,
            hann: hann2(w, h),
            yf,
        }
    }
}

/// The response whose spectrum is `spectrum` (transformed back in place), its real part into
/// `buf`, and its peak (see [`peak`]) on `win`'s cells.
pub fn response_peak(
    fft: &mut Fft2,
    spectrum: &mut [C32],
    buf: &mut Vec<f32>,
    win: &Window,
) -> (f64, f64, f64) {
    fft.inverse(spectrum);
    buf.clear();
    buf.extend(spectrum.iter().map(|v| v.re));
    let (w, h) = win.cells();
    peak(buf, w, h)
}

/// The window a filter reads: `pw x ph` resampled pixels (a whole number of cells) covering
/// `pw * px x ph * px` frame pixels around the target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub pw: usize,
    pub ph: usize,
    pub cell: usize,
    /// Frame pixels per window pixel at scale 1.
    pub px: f64,
    pub features: Features,
}

impl Window {
    /// The window for a `tw x th` target padded by `padding` (1.5 = 2.5 times the target's
    /// size), resampled so that its area is at most `template_size^2` pixels.
    pub fn new(
        tw: f64,
        th: f64,
        padding: f64,
        template_size: usize,
        features: Features,
        cell: usize,
    ) -> Self {
        let cell = if features == Features::Raw {
            1
        } else {
            cell.max(1)
        };
        let (ww, wh) = (tw * (1.0 + padding), th * (1.0 + padding));
        let px = ((ww * wh).sqrt() / template_size as f64).max(1.0);
        // A whole, even number of cells, at least 4 a side.
        let cells = |len: f64| (((len / px / cell as f64) / 2.0).round() as usize * 2).max(4);
        Window {
            pw: cells(ww) * cell,
            ph: cells(wh) * cell,
            cell,
            px,
            features,
        }
    }

    /// Cells across and down (the size of the filter).
    pub fn cells(&self) -> (usize, usize) {
        (self.pw / self.cell, self.ph / self.cell)
    }

    /// Frame pixels per cell at `scale`.
    pub fn cell_px(&self, scale: f64) -> f64 {
        self.px * self.cell as f64 * scale
    }

    /// The features of the window centred at `(cx, cy)` at `scale`, each channel multiplied by
    /// `hann` (`cells` long), the HOG cells made by `crew` when given (the same bits). `buf` is
    /// scratch.
    pub fn extract(
        &self,
        img: &GrayF32,
        (cx, cy, scale): (f64, f64, f64),
        hann: &[f32],
        buf: &mut Vec<f32>,
        crew: Option<&mut Crew<Fft2>>,
    ) -> FeatureMap {
        let (sw, sh) = (
            self.pw as f64 * self.px * scale,
            self.ph as f64 * self.px * scale,
        );
        let mut crew = crew;
        match crew.as_deref_mut() {
            Some(crew) => resample_window_on(crew, img, (cx, cy), (sw, sh), self.pw, self.ph, buf),
            None => resample_window(img, cx, cy, sw, sh, self.pw, self.ph, buf),
        }
        let mut f = match self.features {
            Features::Hog => match crew {
                Some(crew) => fhog_on(crew, buf, self.pw, self.ph, self.cell),
                None => fhog(buf, self.pw, self.ph, self.cell),
            },
            Features::Raw => {
                // Zero mean before the window, as the KCF paper's code does.
                let mean = buf.iter().sum::<f32>() / buf.len().max(1) as f32;
                FeatureMap {
                    width: self.pw,
                    height: self.ph,
                    channels: 1,
                    data: buf.iter().map(|v| (v - mean) / 255.0).collect(),
                }
            }
        };
        for c in 0..f.channels {
            for (v, w) in f.channel_mut(c).iter_mut().zip(hann) {
                *v *= w;
            }
        }
        f
    }
}

/// The 2-D Hann window of `w x h` cells.
pub fn hann2(w: usize, h: usize) -> Vec<f32> {
    let hann = |n: usize| -> Vec<f32> {
        (0..n)
            .map(|i| {
                0.5 - 0.5
                    * (2.0 * std::f32::consts::PI * i as f32 / (n as f32 - 1.0).max(1.0)).cos()
            })
            .collect()
    };
    let (hx, hy) = (hann(w), hann(h));
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            out.push(hx[x] * hy[y]);
        }
    }
    out
}

/// The desired response: a Gaussian of `sigma` cells with its peak at `(0, 0)`, wrapped around
/// (a shift of `d` cells reads at index `d mod size`).
pub fn gaussian_label(w: usize, h: usize, sigma: f64) -> Vec<f32> {
    let wrap = |i: usize, n: usize| {
        let i = i as f64;
        if i >= n as f64 / 2.0 { i - n as f64 } else { i }
    };
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (wrap(x, w), wrap(y, h));
            out.push((-0.5 * (dx * dx + dy * dy) / (sigma * sigma)).exp() as f32);
        }
    }
    out
}

/// The transform of every channel of `f`, channel after channel. The channels are real, so two
/// are transformed at once (one as the real part, the other as the imaginary part of one
/// complex transform) and told apart by the symmetry of a real signal's transform,
/// `X(-k) = conj X(k)`.
pub fn transform(fft: &mut Fft2, f: &FeatureMap, out: &mut Vec<C32>) {
    let n = f.width * f.height;
    out.clear();
    out.resize(n * f.channels, C32::default());
    for (k, pair) in out.chunks_mut(2 * n).enumerate() {
        transform_pair(fft, f, 2 * k, pair);
    }
}

/// The transforms of the channels of `f` two at a time, left packed: spectrum `k` is the
/// transform of channel `2k` plus `i` times channel `2k + 1` (the last alone when the count is
/// odd), made by the members of `crew` (each with its own plans). [`kernel_correlation`] takes
/// packed spectra as they are: the real part of a packed pair's cross-correlation is the sum of
/// its two channels' (the cross terms are imaginary), and a packed spectrum's energy is its two
/// channels'. So a filter that only correlates never tells the channels apart.
pub fn transform_packed_on(crew: &mut Crew<Fft2>, f: &FeatureMap, out: &mut Vec<C32>) {
    let n = f.width * f.height;
    out.clear();
    out.resize(n * f.channels.div_ceil(2), C32::default());
    let parts = crew.len();
    let shares = Shares::new(out, n, parts);
    crew.run(&|fft, member| {
        while let Some((start, spectrum)) = shares.take(member) {
            transform_packed(fft, f, 2 * (start / n), spectrum);
        }
    });
}

/// The transform of channel `c` of `f` plus `i` times channel `c + 1` (zero past the last
/// channel) into `out` (`n` long).
fn transform_packed(fft: &mut Fft2, f: &FeatureMap, c: usize, out: &mut [C32]) {
    match (c + 1 < f.channels).then(|| f.channel(c + 1)) {
        Some(second) => {
            for ((v, &x), &y) in out.iter_mut().zip(f.channel(c)).zip(second) {
                *v = C32::new(x, y);
            }
        }
        None => {
            for (v, &x) in out.iter_mut().zip(f.channel(c)) {
                *v = C32::new(x, 0.0);
            }
        }
    }
    fft.forward(out);
}

/// The transforms of channels `c` and `c + 1` of `f` into `out` (`2 n` long; `n` long for the
/// last channel alone).
fn transform_pair(fft: &mut Fft2, f: &FeatureMap, c: usize, out: &mut [C32]) {
    let (w, h) = (f.width, f.height);
    let n = w * h;
    if out.len() == n {
        transform_packed(fft, f, c, out);
        return;
    }
    let (a, b) = out.split_at_mut(n);
    transform_packed(fft, f, c, a);
    // Z = X + i Y: X(k) = (Z(k) + conj Z(-k)) / 2, Y(k) = (Z(k) - conj Z(-k)) / 2i. Each pair
    // (k, -k) is read before either is written.
    for v in 0..h {
        let vm = (h - v) % h;
        for u in 0..w {
            let um = (w - u) % w;
            let (i, j) = (v * w + u, vm * w + um);
            if j < i {
                continue;
            }
            let (zi, zj) = (a[i], a[j]);
            let x = |p: C32, q: C32| C32::new(0.5 * (p.re + q.re), 0.5 * (p.im - q.im));
            let y = |p: C32, q: C32| C32::new(0.5 * (p.im + q.im), 0.5 * (q.re - p.re));
            a[i] = x(zi, zj);
            b[i] = y(zi, zj);
            a[j] = x(zj, zi);
            b[j] = y(zj, zi);
        }
    }
}

/// `sum |v|^2` in f64, over four running sums (so the additions need not wait on each other).
fn energy(v: &[C32]) -> f64 {
    let mut acc = [0f64; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    for q in chunks {
        for (a, z) in acc.iter_mut().zip(q) {
            *a += z.norm_sqr() as f64;
        }
    }
    let tail: f64 = rest.iter().map(|z| z.norm_sqr() as f64).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Which kernel compares two feature windows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kernel {
    /// `exp(-|x - z|^2 / (sigma^2 N))`, `N` the number of feature values.
    Gaussian { sigma: f64 },
    /// `x . z / N`.
    Linear,
}

/// The transform of the kernel correlation `k(x, z)[d] = kernel(x, z shifted by d)` (`z(p + d)`
/// against `x(p)`, cyclic) of all cyclic shifts `d`, from the transforms `xf`, `zf` of the
/// channels (`n = w h` values each, one after the other; or packed two to a spectrum by
/// [`transform_packed_on`]) with one inverse and one forward transform. `values` is the number of
/// feature values, `n` times the number of channels (the kernel's normaliser `N`).
pub fn kernel_correlation(
    fft: &mut Fft2,
    kernel: Kernel,
    xf: &[C32],
    zf: &[C32],
    values: usize,
    out: &mut Vec<C32>,
) {
    let (w, h) = fft.size();
    let n = w * h;
    let spectra = xf.len() / n;
    debug_assert_eq!(xf.len(), zf.len());
    out.clear();
    out.resize(n, C32::default());
    for c in 0..spectra {
        let (xc, zc) = (&xf[c * n..(c + 1) * n], &zf[c * n..(c + 1) * n]);
        for ((o, x), z) in out.iter_mut().zip(xc).zip(zc) {
            *o += x.conj() * z;
        }
    }
    let xx = energy(&xf[..n * spectra]);
    // The kernel of a window with itself (training) needs its energy once.
    let zz = if std::ptr::eq(xf, zf) {
        xx
    } else {
        energy(&zf[..n * spectra])
    };
    // Parseval: the transform's energy is n times the signal's.
    let (xx, zz) = (xx / n as f64, zz / n as f64);
    fft.inverse(out);
    let count = values as f64;
    match kernel {
        Kernel::Gaussian { sigma } => {
            let k = 1.0 / (sigma * sigma * count);
            for v in out.iter_mut() {
                let d2 = (xx + zz - 2.0 * v.re as f64).max(0.0);
                *v = C32::new((-d2 * k).exp() as f32, 0.0);
            }
        }
        Kernel::Linear => {
            for v in out.iter_mut() {
                *v = C32::new((v.re as f64 / count) as f32, 0.0);
            }
        }
    }
    fft.forward(out);
}

/// The peak of a wrapped `w x h` response: its shift `(dx, dy)` in cells (sub-cell by a parabola
/// through the neighbours along each axis) and its value.
pub fn peak(response: &[f32], w: usize, h: usize) -> (f64, f64, f64) {
    let mut best = 0;
    for (i, v) in response.iter().enumerate() {
        if *v > response[best] {
            best = i;
        }
    }
    let (x, y) = (best % w, best / w);
    let at = |x: usize, y: usize| response[y * w + x] as f64;
    let sub = |l: f64, c: f64, r: f64| {
        let den = l - 2.0 * c + r;
        if den < -1e-12 {
            (0.5 * (l - r) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    };
    let c = at(x, y);
    let ox = sub(at((x + w - 1) % w, y), c, at((x + 1) % w, y));
    let oy = sub(at(x, (y + h - 1) % h), c, at(x, (y + 1) % h));
    let wrap = |i: usize, n: usize| {
        if i as f64 > n as f64 / 2.0 {
            i as f64 - n as f64
        } else {
            i as f64
        }
    };
    (wrap(x, w) + ox, wrap(y, h) + oy, c)
}

/// What a filter shows: its centred response (`w x h` cells of `cp` frame pixels, see
/// [`centred`]) over the window whose shift 0 is at `(cx, cy)`.
pub fn response_visual<'a>(
    win: &Window,
    response: &'a [f32],
    cx: f64,
    cy: f64,
    cp: f64,
) -> MethodVisual<'a> {
    let (w, h) = win.cells();
    let (x0, y0) = (
        cx - ((w / 2) as f64 + 0.5) * cp,
        cy - ((h / 2) as f64 + 0.5) * cp,
    );
    MethodVisual {
        map: Some(ResponseMap {
            width: w,
            height: h,
            values: response,
            at: Quad::from_rect(x0, y0, w as f64 * cp, h as f64 * cp),
        }),
        ..MethodVisual::quads("response", &[], &[], None)
    }
}

/// `response` re-ordered so that shift `(0, 0)` is at the centre of the map (for display).
pub fn centred(response: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[((y + h / 2) % h) * w + (x + w / 2) % w] = response[y * w + x];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn random_map(w: usize, h: usize, channels: usize, seed: u64) -> FeatureMap {
        let mut rng = Rng::new(seed);
        FeatureMap {
            width: w,
            height: h,
            channels,
            data: (0..w * h * channels).map(|_| rng.normal() as f32).collect(),
        }
    }

    /// The kernel correlation through the Fourier domain equals the kernel evaluated directly
    /// on every cyclic shift.
    #[test]
    fn the_fourier_kernel_correlation_equals_the_direct_one() {
        let (w, h, ch) = (10, 8, 3);
        let x = random_map(w, h, ch, 1);
        let z = random_map(w, h, ch, 2);
        let mut fft = Fft2::new(w, h);
        let (mut xf, mut zf, mut kf) = (Vec::new(), Vec::new(), Vec::new());
        let (mut xp, mut zp, mut kp) = (Vec::new(), Vec::new(), Vec::new());
        transform(&mut fft, &x, &mut xf);
        transform(&mut fft, &z, &mut zf);
        let mut crew = Crew::new(vec![Fft2::new(w, h)]);
        transform_packed_on(&mut crew, &x, &mut xp);
        transform_packed_on(&mut crew, &z, &mut zp);
        assert_eq!(xp.len(), w * h * ch.div_ceil(2));
        for kernel in [Kernel::Gaussian { sigma: 0.7 }, Kernel::Linear] {
            kernel_correlation(&mut fft, kernel, &xf, &zf, w * h * ch, &mut kf);
            fft.inverse(&mut kf);
            // Packed spectra give the same kernel.
            kernel_correlation(&mut fft, kernel, &xp, &zp, w * h * ch, &mut kp);
            fft.inverse(&mut kp);
            for (a, b) in kf.iter().zip(&kp) {
                assert!((a - b).norm() < 1e-5, "{kernel:?}: {a} vs {b}");
            }
            let n = (w * h * ch) as f64;
            for (dx, dy) in [(0, 0), (3, 1), (9, 7), (5, 4)] {
                let (mut d2, mut dot) = (0.0, 0.0);
                for c in 0..ch {
                    for y in 0..h {
                        for xx in 0..w {
                            let a = x.channel(c)[y * w + xx] as f64;
                            let b = z.channel(c)[((y + dy) % h) * w + (xx + dx) % w] as f64;
                            d2 += (a - b) * (a - b);
                            dot += a * b;
                        }
                    }
                }
                let direct = match kernel {
                    Kernel::Gaussian { sigma } => (-d2 / (sigma * sigma * n)).exp(),
                    Kernel::Linear => dot / n,
                };
                let got = kf[dy * w + dx];
                assert!(
                    (got.re as f64 - direct).abs() < 1e-4 * (1.0 + direct.abs()),
                    "{kernel:?} at ({dx}, {dy}): {} vs {direct}",
                    got.re
                );
                assert!(got.im.abs() < 1e-4);
            }
        }
    }

    /// Two real channels transformed at once give each channel's own transform.
    #[test]
    fn channels_transformed_in_pairs_match_one_at_a_time() {
        for (w, h, ch) in [(10, 8, 3), (7, 5, 2), (6, 9, 1), (56, 74, 31)] {
            let x = random_map(w, h, ch, 5);
            let mut fft = Fft2::new(w, h);
            let mut got = Vec::new();
            transform(&mut fft, &x, &mut got);
            // Packed, by a crew of two: each spectrum is its pair's transforms recombined,
            // `X + i Y`, on any number of members.
            let mut packed = Vec::new();
            transform_packed_on(&mut Crew::new(vec![Fft2::new(w, h)]), &x, &mut packed);
            let mut crew = Crew::new((0..2).map(|_| Fft2::new(w, h)).collect());
            let mut banded = Vec::new();
            transform_packed_on(&mut crew, &x, &mut banded);
            assert_eq!(banded, packed);
            let n = w * h;
            for (k, p) in packed.chunks(n).enumerate() {
                for i in 0..n {
                    let (a, b) = (got[2 * k * n + i], got.get((2 * k + 1) * n + i));
                    let want = a + b.map_or(C32::default(), |b| C32::new(-b.im, b.re));
                    assert!((p[i] - want).norm() < 1e-4 * (1.0 + want.norm()));
                }
            }
            for c in 0..ch {
                let mut want = Vec::new();
                fft.forward_real(x.channel(c), &mut want);
                for (g, e) in got[c * w * h..(c + 1) * w * h].iter().zip(&want) {
                    assert!(
                        (g - e).norm() < 1e-4 * (1.0 + e.norm()),
                        "{w}x{h} channel {c}: {g} vs {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_peak_of_a_shifted_label_is_its_shift() {
        let (w, h) = (16, 12);
        let y = gaussian_label(w, h, 2.0);
        assert_eq!(y[0], 1.0);
        // Shift the label by (-3, 2) cells plus a third of a cell along x (sampled analytically).
        let wrap = |i: usize, n: usize| {
            let i = i as f64;
            if i >= n as f64 / 2.0 { i - n as f64 } else { i }
        };
        let mut r = vec![0f32; w * h];
        for yy in 0..h {
            for x in 0..w {
                let (dx, dy) = (wrap(x, w) + 3.0 - 0.3, wrap(yy, h) - 2.0);
                r[yy * w + x] = (-0.5 * (dx * dx + dy * dy) / 4.0).exp() as f32;
            }
        }
        let (px, py, v) = peak(&r, w, h);
        assert!(
            (px - -2.7).abs() < 0.05 && (py - 2.0).abs() < 1e-9,
            "{px} {py}"
        );
        assert!(v > 0.9);
        let c = centred(&r, w, h);
        assert_eq!(c[(h / 2 + 2) * w + w / 2 - 3], r[2 * w + (w - 3)]);
    }
}
