//! DSST, the discriminative scale space tracker (Danelljan, Häger, Khan and Felsberg, BMVC
//! 2014): a multi-channel correlation filter for translation and a separate 1-D filter over a
//! pyramid of scales, both learnt online in the Fourier domain (a linear, MOSSE-style filter:
//! numerator and denominator updated as running averages).

use super::cf::{self, Features, Window};
use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::error::Result;
use crate::geometry::Quad;
use crate::imaging::fft::{C32, Fft1, Fft2};
use crate::imaging::hog::fhog;
use crate::imaging::{GrayF32, resample_window};
use crate::observe::Observer;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// DSST's parameters (the paper's values by default).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::float(
        "padding",
        "context around the target, as a fraction of its size (1: a window twice the target)",
        0.0,
        4.0,
        1.0,
    ),
    ParamDef::float("lambda", "regularisation of both filters", 1e-8, 1.0, 1e-2),
    ParamDef::float(
        "output_sigma",
        "bandwidth of the translation filter's desired response, as a fraction of the target's size",
        0.01,
        1.0,
        1.0 / 16.0,
    ),
    ParamDef::float("interp", "learning rate of both filters", 0.0, 1.0, 0.025),
    ParamDef::int(
        "scales",
        "number of scales of the scale filter",
        3.0,
        65.0,
        33.0,
    ),
    ParamDef::float(
        "scale_step",
        "ratio between neighbouring scales",
        1.001,
        1.5,
        1.02,
    ),
    ParamDef::float(
        "scale_sigma",
        "bandwidth of the scale filter's desired response, in scales times sqrt(33) / scales",
        0.01,
        4.0,
        0.25,
    ),
    ParamDef::int(
        "scale_area",
        "the scale filter's samples are resampled to at most this many pixels",
        64.0,
        4096.0,
        512.0,
    ),
    ParamDef::int(
        "cell",
        "HOG cell size, in pixels of the resampled window",
        2.0,
        8.0,
        4.0,
    ),
    ParamDef::int(
        "template_size",
        "the translation window is resampled to at most this many pixels a side (by area)",
        16.0,
        512.0,
        256.0,
    ),
];

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "dsst",
    aliases: &[],
    description: "discriminative scale space tracker (Danelljan et al. 2014): translation filter plus a 1-D scale filter",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::TranslationScale,
        build,
    },
};

/// Builds a DSST tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    Ok(Box::new(Dsst {
        base: Base::new(spec),
        padding: g("padding"),
        lambda: g("lambda") as f32,
        output_sigma: g("output_sigma"),
        interp: g("interp") as f32,
        scales: g("scales") as usize,
        scale_step: g("scale_step"),
        scale_sigma: g("scale_sigma"),
        scale_area: g("scale_area"),
        cell: g("cell") as usize,
        template_size: g("template_size") as usize,
        state: None,
    }))
}

/// A DSST tracker.
#[derive(Debug)]
pub struct Dsst {
    base: Base,
    padding: f64,
    lambda: f32,
    output_sigma: f64,
    interp: f32,
    scales: usize,
    scale_step: f64,
    scale_sigma: f64,
    scale_area: f64,
    cell: usize,
    template_size: usize,
    state: Option<State>,
}

#[derive(Debug)]
struct State {
    win: Window,
    fft: Fft2,
    hann: Vec<f32>,
    yf: Vec<C32>,
    /// Translation filter: numerator per channel, shared denominator.
    num: Vec<C32>,
    den: Vec<f32>,
    scale: ScaleFilter,
    buf: Vec<f32>,
    zf: Vec<C32>,
    acc: Vec<C32>,
    response: Vec<f32>,
}

/// The 1-D filter over scales: each scale's sample is one column of `dim` features.
#[derive(Debug)]
pub(crate) struct ScaleFilter {
    /// Scale factors, smallest first (`step^k`, `k` centred on 0).
    pub factors: Vec<f64>,
    /// Sample size in frame pixels at scale 1, and resampled size.
    pub sample: (f64, f64),
    pub size: (usize, usize),
    pub cell: usize,
    pub window: Vec<f32>,
    pub fft: Fft1,
    pub yf: Vec<C32>,
    /// Numerator (`dim` rows of `n` scales) and denominator (`n`).
    pub num: Vec<C32>,
    pub den: Vec<f32>,
    pub dim: usize,
    z: Vec<C32>,
    buf: Vec<f32>,
    pub response: Vec<f32>,
}

impl ScaleFilter {
    /// A filter over `n` scales `step` apart for a `tw x th` target, samples resampled to at
    /// most `area` pixels, the desired response a Gaussian of `sigma * n / sqrt(33)` scales.
    pub fn new(n: usize, step: f64, sigma: f64, tw: f64, th: f64, area: f64, cell: usize) -> Self {
        let half = (n as f64 - 1.0) / 2.0;
        let factors: Vec<f64> = (0..n).map(|k| step.powf(k as f64 - half)).collect();
        let shrink = (area / (tw * th)).sqrt().min(1.0);
        let size = (
            ((tw * shrink) as usize).max(2 * cell),
            ((th * shrink) as usize).max(2 * cell),
        );
        let s = sigma * n as f64 / 33f64.sqrt();
        let label: Vec<f32> = (0..n)
            .map(|k| (-0.5 * ((k as f64 - half) / s).powi(2)).exp() as f32)
            .collect();
        let mut fft = Fft1::new(n);
        let mut yf: Vec<C32> = label.iter().map(|&v| C32::new(v, 0.0)).collect();
        fft.forward(&mut yf);
        let window = (0..n)
            .map(|k| {
                0.5 - 0.5
                    * (2.0 * std::f32::consts::PI * k as f32 / (n as f32 - 1.0).max(1.0)).cos()
            })
            .collect();
        let dim = (size.0 / cell) * (size.1 / cell) * crate::imaging::hog::FHOG_CHANNELS;
        ScaleFilter {
            factors,
            sample: (tw, th),
            size,
            cell,
            window,
            fft,
            yf,
            num: vec![C32::default(); dim * n],
            den: vec![0.0; n],
            dim,
            z: Vec::new(),
            buf: Vec::new(),
            response: Vec::new(),
        }
    }

    /// The transform along the scales of the samples at `(cx, cy)` around `scale`, into `z`
    /// (`dim` rows of `n`).
    fn sample(&mut self, img: &GrayF32, cx: f64, cy: f64, scale: f64) {
        let n = self.factors.len();
        self.z.clear();
        self.z.resize(self.dim * n, C32::default());
        for (k, f) in self.factors.iter().enumerate() {
            let s = scale * f;
            resample_window(
                img,
                cx,
                cy,
                self.sample.0 * s,
                self.sample.1 * s,
                self.size.0,
                self.size.1,
                &mut self.buf,
            );
            let h = fhog(&self.buf, self.size.0, self.size.1, self.cell);
            for (d, v) in h.data.iter().take(self.dim).enumerate() {
                self.z[d * n + k] = C32::new(v * self.window[k], 0.0);
            }
        }
        self.fft.forward(&mut self.z);
    }

    /// Learns the samples just taken, blended in at `rate`.
    fn learn(&mut self, rate: f32) {
        let n = self.factors.len();
        let keep = 1.0 - rate;
        for v in self.den.iter_mut() {
            *v *= keep;
        }
        for d in 0..self.dim {
            for k in 0..n {
                let z = self.z[d * n + k];
                let i = d * n + k;
                self.num[i] = self.num[i] * keep + self.yf[k].conj() * z * rate;
                self.den[k] += z.norm_sqr() * rate;
            }
        }
    }

    /// The index of the best scale for the samples just taken.
    fn detect(&mut self, lambda: f32) -> usize {
        let n = self.factors.len();
        let mut acc = vec![C32::default(); n];
        for d in 0..self.dim {
            for k in 0..n {
                acc[k] += self.num[d * n + k].conj() * self.z[d * n + k];
            }
        }
        for k in 0..n {
            acc[k] /= self.den[k] + lambda;
        }
        self.fft.inverse(&mut acc);
        self.response = acc.iter().map(|v| v.re).collect();
        let mut best = n / 2;
        for k in 0..n {
            if self.response[k] > self.response[best] {
                best = k;
            }
        }
        best
    }
}

impl State {
    fn features(&mut self, img: &GrayF32, cx: f64, cy: f64, scale: f64) {
        let f = self
            .win
            .extract(img, (cx, cy, scale), &self.hann, &mut self.buf, None);
        cf::transform(&mut self.fft, &f, &mut self.zf);
    }

    fn learn(&mut self, rate: f32) {
        let n = self.den.len();
        let keep = 1.0 - rate;
        for v in self.den.iter_mut() {
            *v *= keep;
        }
        for c in 0..self.win.features.channels() {
            for i in 0..n {
                let z = self.zf[c * n + i];
                let j = c * n + i;
                self.num[j] = self.num[j] * keep + self.yf[i].conj() * z * rate;
                self.den[i] += z.norm_sqr() * rate;
            }
        }
    }

    fn detect(&mut self, lambda: f32) -> (f64, f64, f64) {
        let n = self.den.len();
        self.acc.clear();
        self.acc.resize(n, C32::default());
        for c in 0..self.win.features.channels() {
            for i in 0..n {
                self.acc[i] += self.num[c * n + i].conj() * self.zf[c * n + i];
            }
        }
        for i in 0..n {
            self.acc[i] /= self.den[i] + lambda;
        }
        cf::response_peak(&mut self.fft, &mut self.acc, &mut self.buf, &self.win)
    }
}

impl WholeTracker for Dsst {
    const MIN_SIDE: f64 = 4.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let (tw, th) = self.base.size0;
        let cf::Basis { win, fft, hann, yf } = cf::Basis::new(
            (tw, th),
            (self.padding, self.template_size),
            (Features::Hog, self.cell),
            self.output_sigma,
        );
        let (w, h) = win.cells();
        let n = w * h;
        let mut st = State {
            win,
            fft,
            hann,
            yf,
            num: vec![C32::default(); n * win.features.channels()],
            den: vec![0.0; n],
            scale: ScaleFilter::new(
                self.scales,
                self.scale_step,
                self.scale_sigma,
                tw,
                th,
                self.scale_area,
                self.cell,
            ),
            buf: Vec::new(),
            zf: Vec::new(),
            acc: Vec::new(),
            response: Vec::new(),
        };
        let img = frame_f32(input);
        let Pose { cx, cy, scale, .. } = self.base.pose;
        st.features(&img, cx, cy, scale);
        st.learn(1.0);
        st.scale.sample(&img, cx, cy, scale);
        st.scale.learn(1.0);
        self.state = Some(st);
        Ok(())
    }

    fn track(&mut self, input: FrameInput<'_>, observer: &mut dyn Observer) -> FrameOutcome {
        let Some(st) = self.state.as_mut() else {
            return self.base.idle();
        };
        if self.base.status != TrackStatus::Tracking {
            return self.base.idle();
        }
        let started = self.base.begin(observer);
        let img = frame_f32(input);
        let preprocess = started.elapsed();
        let Pose { cx, cy, scale, .. } = self.base.pose;
        // Translation at the current scale.
        st.features(&img, cx, cy, scale);
        let (dx, dy, value) = st.detect(self.lambda);
        let cp = st.win.cell_px(scale);
        let (nx, ny) = (cx + dx * cp, cy + dy * cp);
        let want = observer.wants_method_visuals();
        if want {
            let (w, h) = st.win.cells();
            st.response = cf::centred(&st.buf, w, h);
        }
        // Then the scale, at the new position.
        st.scale.sample(&img, nx, ny, scale);
        let k = st.scale.detect(self.lambda);
        let ns = scale * st.scale.factors[k];
        let pose = Pose {
            cx: nx,
            cy: ny,
            scale: ns,
            ..self.base.pose
        };
        if [nx, ny, ns].iter().all(|v| v.is_finite()) && ns > 0.0 {
            st.features(&img, nx, ny, ns);
            st.learn(self.interp);
            st.scale.sample(&img, nx, ny, ns);
            st.scale.learn(self.interp);
        }
        let visual = want.then(|| cf::response_visual(&st.win, &st.response, cx, cy, cp));
        self.base.finish(
            Ok((pose, value)),
            input.size(),
            started,
            preprocess,
            observer,
            visual,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A textured frame: smoothed noise blobs (so that resampled patches stay comparable).
    fn texture(w: usize, h: usize, seed: u64) -> GrayF32 {
        let mut rng = Rng::new(seed);
        let blobs: Vec<(f64, f64, f64, f64)> = (0..120)
            .map(|_| {
                (
                    rng.range(0.0, w as f64),
                    rng.range(0.0, h as f64),
                    rng.range(3.0, 9.0),
                    rng.range(-80.0, 80.0),
                )
            })
            .collect();
        let mut img = GrayF32::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let mut v = 128.0;
                for &(bx, by, r, a) in &blobs {
                    let d2 = (x as f64 - bx).powi(2) + (y as f64 - by).powi(2);
                    v += a * (-d2 / (2.0 * r * r)).exp();
                }
                img.set(x, y, v as f32);
            }
        }
        img
    }

    /// The scale filter, trained on a target, finds the scale by which it was zoomed.
    #[test]
    fn the_scale_filter_estimates_a_zoom() {
        let img = texture(320, 320, 3);
        let (cx, cy, tw, th) = (160.0, 160.0, 60.0, 50.0);
        let mut f = ScaleFilter::new(33, 1.02, 0.25, tw, th, 512.0, 4);
        f.sample(&img, cx, cy, 1.0);
        f.learn(1.0);
        for (zoom, expect) in [
            (1.0, 1.0),
            (1.02f64.powi(3), 1.02f64.powi(3)),
            (1.02f64.powi(-4), 1.02f64.powi(-4)),
        ] {
            // The frame zoomed by `zoom` about the centre: sampling it at scale s equals
            // sampling the original at s / zoom, so the best s is `zoom`.
            let mut zoomed = GrayF32::new(320, 320);
            let view = img.view();
            for y in 0..320 {
                for x in 0..320 {
                    let (u, v) = (cx + (x as f64 - cx) / zoom, cy + (y as f64 - cy) / zoom);
                    zoomed.set(
                        x,
                        y,
                        crate::imaging::sample_value(&view, u as f32, v as f32),
                    );
                }
            }
            f.sample(&zoomed, cx, cy, 1.0);
            let k = f.detect(1e-2);
            let got = f.factors[k];
            assert!((got / expect - 1.0).abs() < 0.011, "zoom {zoom}: {got}");
        }
    }
}
