//! KCF, the kernelised correlation filter (Henriques, Caseiro, Martins and Batista, PAMI 2015):
//! kernel ridge regression over every cyclic shift of a window around the target, trained and
//! evaluated in the Fourier domain. Translation only: the target keeps its initial size.

use super::cf::{self, Features, Kernel, Window};
use super::{Base, Motion, Pose, WholeDef, WholeTracker, frame_f32};
use crate::crew::{Crew, threads_for};
use crate::error::Result;
use crate::geometry::Quad;
use crate::imaging::fft::{C32, Fft2};
use crate::observe::Observer;
use crate::params::ParamDef;
use crate::registry::Entry;
use crate::spec::WholeSpec;
use crate::status::{FrameOutcome, TrackStatus};
use crate::visual_tracker::{FrameInput, VisualTracker};

/// KCF's parameters (the paper's values for HOG by default).
pub const PARAMS: &[ParamDef] = &[
    ParamDef::choice(
        "features",
        "what the filter sees: 31-channel HOG cells or raw gray levels",
        &["hog", "raw"],
    ),
    ParamDef::choice(
        "kernel",
        "how two windows are compared",
        &["gaussian", "linear"],
    ),
    ParamDef::float(
        "padding",
        "context around the target, as a fraction of its size (1.5: a window 2.5 times the target)",
        0.0,
        4.0,
        1.5,
    ),
    ParamDef::float("lambda", "ridge regularisation", 1e-8, 1.0, 1e-4),
    ParamDef::float(
        "kernel_sigma",
        "Gaussian kernel bandwidth (the paper: 0.5 with HOG, 0.2 with raw pixels)",
        0.01,
        10.0,
        0.5,
    ),
    ParamDef::float(
        "output_sigma",
        "bandwidth of the desired response, as a fraction of the target's size",
        0.01,
        1.0,
        0.1,
    ),
    ParamDef::float(
        "interp",
        "learning rate of the model (the paper: 0.02 with HOG, 0.075 with raw pixels)",
        0.0,
        1.0,
        0.02,
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
        "the window is resampled to at most this many pixels a side (by area)",
        16.0,
        512.0,
        256.0,
    ),
    ParamDef::int(
        "threads",
        "threads making the HOG cells and the channels' transforms (0 = all cores); the result does not depend on it",
        0.0,
        256.0,
        0.0,
    ),
];

/// The registry entry.
pub const ENTRY: Entry<WholeDef> = Entry {
    name: "kcf",
    aliases: &[],
    description: "kernelised correlation filter (Henriques et al. 2015): Gaussian kernel, HOG or raw pixels, translation",
    build: WholeDef {
        params: PARAMS,
        motion: Motion::Translation,
        build,
    },
};

/// Builds a KCF tracker.
pub fn build(spec: &WholeSpec) -> Result<Box<dyn VisualTracker>> {
    let g = |name: &str| super::param(spec, PARAMS, name);
    let kernel = if g("kernel") as usize == 1 {
        Kernel::Linear
    } else {
        Kernel::Gaussian {
            sigma: g("kernel_sigma"),
        }
    };
    Ok(Box::new(Kcf {
        base: Base::new(spec),
        features: Features::from_index(g("features")),
        kernel,
        padding: g("padding"),
        lambda: g("lambda") as f32,
        output_sigma: g("output_sigma"),
        interp: g("interp") as f32,
        cell: g("cell") as usize,
        template_size: g("template_size") as usize,
        threads: g("threads") as usize,
        state: None,
    }))
}

/// A KCF tracker.
#[derive(Debug)]
pub struct Kcf {
    base: Base,
    features: Features,
    kernel: Kernel,
    padding: f64,
    lambda: f32,
    output_sigma: f64,
    interp: f32,
    cell: usize,
    template_size: usize,
    threads: usize,
    state: Option<State>,
}

/// What KCF learns at initialisation and updates on every frame.
#[derive(Debug)]
struct State {
    win: Window,
    fft: Fft2,
    /// The threads that make the features and their transforms, each with its own plans.
    crew: Crew<Fft2>,
    hann: Vec<f32>,
    /// The label's transform.
    yf: Vec<C32>,
    /// The model: the features' transforms (packed two channels to a spectrum) and the dual
    /// coefficients' transform.
    xf: Vec<C32>,
    alphaf: Vec<C32>,
    // Scratch.
    buf: Vec<f32>,
    zf: Vec<C32>,
    kf: Vec<C32>,
    /// The last response, centred (for display).
    response: Vec<f32>,
}

impl State {
    /// The transforms of the features at `(cx, cy)` into `zf`.
    fn features(&mut self, img: &crate::imaging::GrayF32, cx: f64, cy: f64) {
        let f = self.win.extract(
            img,
            (cx, cy, 1.0),
            &self.hann,
            &mut self.buf,
            Some(&mut self.crew),
        );
        cf::transform_packed_on(&mut self.crew, &f, &mut self.zf);
    }

    /// The number of feature values (cells times channels).
    fn values(&self) -> usize {
        let (w, h) = self.win.cells();
        w * h * self.win.features.channels()
    }

    /// Trains on `zf` (the features just extracted): the dual coefficients
    /// `alpha = y / (k(x, x) + lambda)` in the Fourier domain, blended into the model at `rate`.
    fn learn(&mut self, kernel: Kernel, lambda: f32, rate: f32) {
        let values = self.values();
        cf::kernel_correlation(
            &mut self.fft,
            kernel,
            &self.zf,
            &self.zf,
            values,
            &mut self.kf,
        );
        let keep = 1.0 - rate;
        for i in 0..self.kf.len() {
            let a = self.yf[i] / (self.kf[i] + lambda);
            self.alphaf[i] = self.alphaf[i] * keep + a * rate;
        }
        for (m, z) in self.xf.iter_mut().zip(&self.zf) {
            *m = *m * keep + *z * rate;
        }
    }

    /// The response over every shift of the window at `(cx, cy)` (wrapped), into `kf`'s real
    /// parts; returns its peak shift in cells and value.
    fn detect(&mut self, kernel: Kernel) -> (f64, f64, f64) {
        let values = self.values();
        cf::kernel_correlation(
            &mut self.fft,
            kernel,
            &self.xf,
            &self.zf,
            values,
            &mut self.kf,
        );
        for (k, a) in self.kf.iter_mut().zip(&self.alphaf) {
            *k *= *a;
        }
        cf::response_peak(&mut self.fft, &mut self.kf, &mut self.buf, &self.win)
    }
}

impl WholeTracker for Kcf {
    const MIN_SIDE: f64 = 4.0;

    base_field!();

    fn start(&mut self, input: FrameInput<'_>, _quad: &Quad) -> Result<()> {
        let cf::Basis { win, fft, hann, yf } = cf::Basis::new(
            self.base.size0,
            (self.padding, self.template_size),
            (self.features, self.cell),
            self.output_sigma,
        );
        let (w, h) = win.cells();
        let n = w * h;
        let threads = threads_for(self.threads).clamp(1, h);
        let crew = Crew::start((0..threads).map(|_| Fft2::new(w, h)).collect())?;
        let mut st = State {
            win,
            fft,
            crew,
            hann,
            yf,
            xf: vec![C32::default(); n * win.features.channels().div_ceil(2)],
            alphaf: vec![C32::default(); n],
            buf: Vec::new(),
            zf: Vec::new(),
            kf: Vec::new(),
            response: Vec::new(),
        };
        let img = frame_f32(input);
        st.features(&img, self.base.pose.cx, self.base.pose.cy);
        st.learn(self.kernel, self.lambda, 1.0);
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
        let Pose { cx, cy, .. } = self.base.pose;
        st.features(&img, cx, cy);
        let (dx, dy, value) = st.detect(self.kernel);
        let cp = st.win.cell_px(1.0);
        let pose = Pose {
            cx: cx + dx * cp,
            cy: cy + dy * cp,
            ..self.base.pose
        };
        let want = observer.wants_method_visuals();
        if want {
            let (w, h) = st.win.cells();
            st.response = cf::centred(&st.buf, w, h);
        }
        if pose.cx.is_finite() && pose.cy.is_finite() {
            st.features(&img, pose.cx, pose.cy);
            st.learn(self.kernel, self.lambda, self.interp);
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
