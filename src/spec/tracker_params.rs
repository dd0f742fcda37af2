//! The parameters every registration tracker has, declared once: each line of
//! [`tracker_params!`] gives a parameter's field, type, range, default and help, and from it
//! follow the [`TrackerParams`] struct (its serde form, which sessions store), the definitions
//! [`TRACKER_PARAMS`] (which `regtrack list`, the command line's flags, `--param`, the
//! inspector's widgets and validation read) and the by-name access ([`TrackerParams::value`],
//! [`TrackerParams::set_value`]).

use crate::am::HessianKind;
use crate::am::ilm::Illumination;
use crate::error::Result;
use crate::params::ParamDef;
use serde::{Deserialize, Serialize};

/// A type a tracker parameter can have: converted to and from the `f64` that definitions,
/// widgets and `--param` use (a choice as its index).
pub trait ParamValue: Sized {
    fn to_param(&self) -> f64;
    /// From a value already checked against the definition.
    fn from_param(v: f64) -> Self;
}

impl ParamValue for usize {
    fn to_param(&self) -> f64 {
        *self as f64
    }
    fn from_param(v: f64) -> Self {
        v.max(0.0) as usize
    }
}
impl ParamValue for u64 {
    fn to_param(&self) -> f64 {
        *self as f64
    }
    fn from_param(v: f64) -> Self {
        v.max(0.0) as u64
    }
}
impl ParamValue for f64 {
    fn to_param(&self) -> f64 {
        *self
    }
    fn from_param(v: f64) -> Self {
        v
    }
}
impl ParamValue for f32 {
    fn to_param(&self) -> f64 {
        *self as f64
    }
    fn from_param(v: f64) -> Self {
        v as f32
    }
}
impl ParamValue for bool {
    fn to_param(&self) -> f64 {
        *self as u8 as f64
    }
    fn from_param(v: f64) -> Self {
        v >= 0.5
    }
}

/// The names of a `bool` parameter's two choices.
pub const OFF_ON: &[&str] = &["off", "on"];

/// A closed set of names used as a choice parameter: `choice_param!(Type { Variant = "name", ...
/// })` implements [`ParamValue`] (the index in this order) and gives `Type::NAMES`, the choice's
/// names in the same order, which must be the serde names.
macro_rules! choice_param {
    ($ty:ty { $($variant:ident = $name:literal),+ $(,)? }) => {
        impl $ty {
            /// The names of the choice, in the order of its indices.
            pub const NAMES: &'static [&'static str] = &[$($name),+];
            const ALL: &'static [$ty] = &[$(<$ty>::$variant),+];
        }
        impl ParamValue for $ty {
            fn to_param(&self) -> f64 {
                Self::ALL.iter().position(|v| v == self).unwrap_or(0) as f64
            }
            fn from_param(v: f64) -> Self {
                Self::ALL.get(v.max(0.0) as usize).copied().unwrap_or(Self::ALL[0])
            }
        }
    };
}

/// Declares the tracker's parameters: `field: Type = kind(args...), "help";` with `kind` one
/// of [`ParamDef`]'s constructors (`int`, `float`, `choice`) and its arguments after the name
/// and help; `flag "name"` before the help adds a short command-line flag.
macro_rules! tracker_params {
    ($(
        $(#[doc = $doc:literal])*
        $field:ident : $ty:ty = $kind:ident ( $($arg:expr),* ) $(, flag $flag:literal)? , $help:literal ;
    )*) => {
        /// The parameters every registration tracker has (the paper's defaults), in
        /// [`TRACKER_PARAMS`]' order. Sessions store them by these names.
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct TrackerParams {
            $(
                #[doc = $help]
                $(#[doc = ""] #[doc = $doc])*
                pub $field: $ty,
            )*
        }

        /// The definitions of [`TrackerParams`]: names, ranges, defaults, help.
        pub const TRACKER_PARAMS: &[ParamDef] = &[
            $(ParamDef::$kind(stringify!($field), $help, $($arg),*),)*
        ];

        /// Short command-line flags of some parameters: `(flag, parameter)`.
        pub const TRACKER_FLAGS: &[(&str, &str)] = &[$($(($flag, stringify!($field)),)?)*];

        impl TrackerParams {
            /// The value of the parameter `name` (a choice as its index; `NaN` for an unknown
            /// name).
            pub fn value(&self, name: &str) -> f64 {
                $(if name == stringify!($field) {
                    return self.$field.to_param();
                })*
                f64::NAN
            }

            /// Sets the parameter `name` (unchecked: see [`TrackerParams::validate`]); returns
            /// whether the name exists.
            pub fn set_value(&mut self, name: &str, v: f64) -> bool {
                $(if name == stringify!($field) {
                    self.$field = <$ty as ParamValue>::from_param(v);
                    return true;
                })*
                false
            }
        }

        impl Default for TrackerParams {
            fn default() -> Self {
                let mut defs = TRACKER_PARAMS.iter();
                TrackerParams {
                    $($field: <$ty as ParamValue>::from_param(
                        defs.next().map_or(0.0, |d| d.default),
                    ),)*
                }
            }
        }
    };
}

tracker_params! {
    res: usize = int(2.0, 1000.0, 50.0),
        "sampling resolution: res x res points on the target";
    /// MTF's multi-channel trackers: with `rgb` the grid is sampled in each of the frame's red,
    /// green and blue channels (the same points, smoothed alike), and the AM compares the
    /// three patches channel by channel: the sum of the three similarities (SSD's sum of
    /// squares is the same either way). A grey frame is read as three equal channels; the
    /// learning trackers read grey. With `df` the channels are the grey image's four
    /// descriptor fields (Crivellaro and Lepetit; MTF's `dft`): its x and y derivatives split by
    /// sign, each smoothed by the pre-smoothing kernel ([`crate::imaging::descriptor_fields_into`]).
    channels: Channels = choice(Channels::NAMES),
        "gray (the frame's luma); rgb: sample the red, green and blue channels on the grid (targets that differ from their surroundings in hue); df: the four descriptor fields, the grey image's derivatives split by sign and smoothed (MTF's dft: light changes, shiny or texture-poor targets)";
    /// With `per_channel` each channel's patch has its own copy of the AM (its own means and
    /// norms, its own joint histogram: MTF's "a histogram per channel"), and the similarity is
    /// the sum of the three; with `stacked` the AM sees the three patches as one patch of
    /// three times the points (one mean and norm, one joint histogram), so a channel counts by
    /// its contrast. SSD is the same either way; the models that read the patch as its grid
    /// (NGF's neighbours, LSCV's regions, an illumination model's cells) are always per
    /// channel.
    channel_model: ChannelModel = choice(ChannelModel::NAMES),
        "with channels=rgb or df: stacked (the AM compares the channels' patches as one patch) or per_channel (the AM on each channel's patch, the similarities summed)";
    /// A non-rigid SSM's (`spline`, `tps`) Newton steps maximise the similarity minus
    /// `smoothness x (the data's mean curvature) x` the bending of the control points'
    /// displacements (zero for an affine field): the control points that few pixels see
    /// (at the corners, on a flat part) follow their neighbours instead of the noise. Each
    /// model's own weight was chosen on the tune half of the bending renders
    /// (`docs/heldout.py render-bend`; see docs/methods.md).
    smoothness: f64 = float(-1.0, 1000.0, -1.0),
        "with a non-rigid SSM (spline, tps): weight of the prior against bending, relative to the data's curvature (0 = none); -1 = auto: the model's own (spline 0.05, tps 0.1, tps5 0.2, spline5 3)";
    max_iters: usize = int(1.0, 10_000.0, 30.0),
        "maximum iterations per frame";
    eps: f64 = float(0.0, 1000.0, 0.001),
        "stop when the corners move less than this in an iteration (L2 norm of the 8 coordinates, px)";
    blur_size: usize = int(1.0, 31.0, 5.0), flag "blur",
        "Gaussian pre-smoothing kernel size (1 = none)";
    /// Of the finest level, where each frame's search ends: for the gradient methods light, so
    /// that marks as fine as a
    /// pixel keep their contrast (the paper's 3 smooths a one-pixel mark to a few gray levels,
    /// and under changing light SSD's optimum then leaves a sparse target). The coarser
    /// `pyramid_levels` give the search the basin that heavier smoothing gave.
    /// `-1` (auto) resolves to [`AUTO_SIGMA_GRADIENT`] for the gradient methods and to
    /// [`AUTO_SIGMA_SAMPLING`] for NN and PF ([`TrackerParams::smoothing_sigma`]); on the
    /// descriptor fields to [`AUTO_SIGMA_FIELDS`] for the gradient methods, in a kernel of at
    /// least [`AUTO_SIZE_FIELDS`] ([`TrackerParams::smoothing_size`]).
    blur_sigma: f64 = float(-1.0, 100.0, -1.0), flag "sigma",
        "Gaussian pre-smoothing standard deviation (px) of the finest level; -1 = auto: 0.7 for the gradient methods (their coarse pyramid levels give the basin), 3 (the paper's) for NN and PF; with channels=df 2 for the gradient methods (in a kernel of at least 7)";
    hessian: HessianKind = choice(HessianKind::NAMES),
        "the Hessian of the Newton step (default: the AM's own)";
    roi_margin: f64 = float(0.0, 10.0, 0.25),
        "margin of the pre-processed region around the target, as a fraction of its size";
    /// Each level is half the size of the previous one and has its own template, sampled by a
    /// grid of half the previous level's `res` per side (the same density in its own pixels; at
    /// least 10). A coarse estimate is kept only if the finest level finds it at least as like
    /// the template as where the frame started (a star field's marks vanish at the coarse
    /// levels, whose search then follows the light).
    pyramid_levels: usize = int(1.0, 6.0, 3.0), flag "levels",
        "coarse-to-fine pyramid levels of the gradient methods (1 = none; the paper's: 1; NN and PF search at the finest level)";
    seed: u64 = int(0.0, 9_007_199_254_740_991.0, 0.0),
        "seed of the random generators (NN samples, PF particles)";
    on_loss: LossPolicy = choice_default(LossPolicy::NAMES, 2),
        "after a loss of track: stop (until re-initialised), continue from the last good estimate, or redetect (continue, else search the whole frame for the template)";
    /// The confidence of a frame is the correlation of the patch where the search ended with the
    /// template, block by block (insensitive to light that varies across the target, whatever
    /// the AM). A search that ran out of iterations needs 0.1 more.
    min_confidence: f64 = float(-1.0, 1.0, 0.5),
        "a frame whose confidence (the patch's block-wise correlation with the template, -1..1) is below this is reported lost (-1 = never)";
    /// The median is over the last 10 frames tracked on from a tracked frame. A frame found
    /// again after a loss needs 0.85 times that median (`registration::confidence::RESUME`).
    confidence_drop: f64 = float(0.0, 1.0, 0.75),
        "a frame whose confidence falls below this times the median of the last frames' is reported lost (0 = never)";
    /// Light, blur and scale change little from one frame to the next, so on the target this
    /// stays near 1 where the confidence against the template has fallen; a slip to a
    /// look-alike (the next rows of a brick wall) makes it fall at once.
    min_frame_confidence: f64 = float(-1.0, 1.0, 0.8),
        "a frame whose patch correlates (block-wise) less than this with the previous tracked frame's patch is reported lost (-1 = never)";
    /// MTF's `hrch`: each frame is first searched with the SSMs of 2, 4 and 6 DOF below the
    /// tracker's own, each from the previous one's result.
    ssm_hierarchy: bool = choice(OFF_ON),
        "off, or on: search translation, similitude and affine (those below the tracker's SSM) first, then the tracker's SSM (MTF's hrch)";
    /// Estimated jointly with the warp at every evaluation (see `am::ilm`): `pgb`, a gain and a
    /// bias per cell of an `ilm_cells x ilm_cells` grid; `rbf`, a gain and a bias that vary
    /// smoothly (Gaussian radial basis functions on the cells).
    ilm: Illumination = choice(Illumination::NAMES),
        "illumination model of the least-squares AM (ssd), fitted with the warp: none, pgb (piecewise gain and bias) or rbf (radial basis functions)";
    ilm_cells: usize = int(1.0, 8.0, 3.0),
        "cells per side of the illumination model's grid";
    grid: GridLayout = choice(GridLayout::NAMES),
        "sampling grid: centres (of a res x res tiling, inside the target) or border (corner to corner, as MTF)";
    /// For the Lucas-Kanade methods (FCLK, FALK, ICLK, IALK): when an iteration finds the
    /// similarity lower than where the previous step started, that step is halved from there,
    /// up to four times, and the frame ends at the best point if none helps. Gauss-Newton steps
    /// overshoot when the residual is large (a target that darkened by 40 %) and may then cycle
    /// between two points for all the iterations. ESM has its own rule (`max_falls`).
    line_search: bool = choice_default(OFF_ON, 1),
        "off (the classic methods), or on: a step after which the similarity is lower is halved, up to four times (the Lucas-Kanade methods)";
    /// ICLK, IALK and ESM linearise with the template's gradients: where the frame no longer
    /// looks like the template (light across the target, blur, a change of scale) their fixed
    /// point is not the AM's optimum, and they drift. Polishing takes forward-compositional
    /// steps (FCLK's) from where they converged while the patch grows more like the template
    /// (its confidence), at most `max_iters` of them.
    polish: bool = choice_default(OFF_ON, 1),
        "off (the classic methods), or on: after ICLK, IALK or ESM converge, forward steps toward the AM's own optimum while the patch grows more like the template";
    /// The corners move on at their last velocity, damped by the factor (0, 0.5 or 1) that has
    /// predicted the tracked frames best so far (`plan::predict`); when the search from there
    /// fails the checks, the frame is searched from the last pose too.
    predict: bool = choice_default(OFF_ON, 1),
        "off (each frame's search starts at the last pose), or on: where the target is going (constant velocity, damped, checked against the frames tracked)";
    /// The first attempt is the tracker's search at the finest level with the confidences;
    /// its end stands when it settled at least `plan::escalate::EASY` times as confident as
    /// the track's recent frames and at least `EASY_FRAME` like the last frame's patch
    /// (`plan::escalate`). Off for the plain combinations (on the tune half of the held-out
    /// renders ICLK-ZNCC reports 0.842 of its frames more than 20 px off lost with it, 0.859
    /// without; on the slip test's brick wall the eight combinations 0.939 against 0.950); on
    /// in the default tracker's parameters (`spec::default_params`), whose losses it leaves as
    /// they were (docs/robustness.md).
    escalate: bool = choice_default(OFF_ON, 0),
        "off (every frame runs the pyramid and the polish), or on: each frame is first searched at the finest level alone (at most 10 iterations), and the pyramid and the polish run only when that search did not settle as confidently as the recent frames";
    /// A frame whose search (from the prediction and from the last pose) fails the checks is
    /// searched again by a second tracker of this method and AM from the same start, and the
    /// end more like the template (the first tracker's confidence, both measured alike) is
    /// judged (`plan/second.rs`). While tracking only: a lost tracker's frames do not pay it.
    second: SecondHypothesis = choice(SecondHypothesis::NAMES),
        "none, or the search method and AM of a second hypothesis tried on the frames whose search fails the checks (esm_ssd, fclk_ssd, ...), the more confident end kept";
    /// Selective pixel integration (MTF's SPI): the searches read only part of the grid, the
    /// points chosen once, on the template (`registration::spi`): every level and SSM of the
    /// plan its own. The confidences and what the inspector shows read the whole grid.
    spi: Spi = choice(Spi::NAMES),
        "selective pixel integration: off (every grid point), or gradient: the searches read only the spi_keep fraction of the grid where the template's gradient is largest";
    spi_keep: f64 = float(0.05, 1.0, 0.5),
        "with spi=gradient: the fraction of the grid's points kept";
    /// With `spi_mask_right > spi_mask_left` and `spi_mask_bottom > spi_mask_top`, the grid's
    /// points in that rectangle of the target (fractions of its width and height, from its
    /// first corner) are left out, whatever `spi`.
    spi_mask_left: f64 = float(0.0, 1.0, 0.0),
        "left edge of the part of the target the searches leave out (a known occluder), as a fraction of its width (none while spi_mask_right <= spi_mask_left)";
    spi_mask_top: f64 = float(0.0, 1.0, 0.0),
        "top edge of the part left out, as a fraction of the target's height";
    spi_mask_right: f64 = float(0.0, 1.0, 0.0),
        "right edge of the part left out, as a fraction of the target's width";
    spi_mask_bottom: f64 = float(0.0, 1.0, 0.0),
        "bottom edge of the part left out, as a fraction of the target's height";
}

/// The channels a registration tracker samples (`channels`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Channels {
    /// The frame's grey image (luma).
    #[default]
    Gray,
    /// Red, green and blue, each its patch on the same grid.
    Rgb,
    /// The grey image's four descriptor fields (`[dI/dx]+, [dI/dx]-, [dI/dy]+, [dI/dy]-`),
    /// each smoothed, each its patch on the same grid.
    Df,
}
choice_param!(Channels {
    Gray = "gray",
    Rgb = "rgb",
    Df = "df",
});

impl Channels {
    /// How many planes it samples.
    pub fn count(self) -> usize {
        match self {
            Channels::Gray => 1,
            Channels::Rgb => 3,
            Channels::Df => crate::imaging::FIELDS,
        }
    }
}

/// How an AM compares a colour tracker's channels (`channel_model`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelModel {
    /// The three patches as one.
    #[default]
    Stacked,
    /// Each channel's patch its own model, the similarities summed.
    PerChannel,
}
choice_param!(ChannelModel {
    Stacked = "stacked",
    PerChannel = "per_channel",
});

/// Selective pixel integration (`spi`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Spi {
    /// Every grid point.
    #[default]
    Off,
    /// The points where the template's gradient is largest (`spi_keep` of them).
    Gradient,
}
choice_param!(Spi {
    Off = "off",
    Gradient = "gradient",
});

impl TrackerParams {
    /// The rectangle of the target the searches leave out (`spi_mask_*`: left, top, right,
    /// bottom in the unit square of the target), if any.
    pub fn spi_mask(&self) -> Option<[f64; 4]> {
        let m = [
            self.spi_mask_left,
            self.spi_mask_top,
            self.spi_mask_right,
            self.spi_mask_bottom,
        ];
        (m[2] > m[0] && m[3] > m[1]).then_some(m)
    }

    /// Whether the searches read only part of the grid (`spi` or a mask).
    pub fn selective(&self) -> bool {
        self.spi != Spi::Off || self.spi_mask().is_some()
    }
}

choice_param!(Illumination {
    None = "none",
    Pieces = "pgb",
    Radial = "rbf",
});

choice_param!(HessianKind {
    Default = "default",
    GaussNewton = "gauss_newton",
    Newton = "newton",
    AfterConvergence = "after_convergence",
});

/// Where a tracker's sampling grid lies on the target.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GridLayout {
    /// The centres of a `res x res` tiling: every sample inside the target.
    #[default]
    Centres,
    /// `res` points from edge to edge on each axis, corners included: the outer samples lie on
    /// the target's border (and see the background when smoothed).
    Border,
}
choice_param!(GridLayout {
    Centres = "centres",
    Border = "border",
});

/// The second hypothesis of a tracker (`second`): none, or a search method and an AM.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SecondHypothesis {
    #[default]
    None,
    EsmSsd,
    EsmZncc,
    FclkSsd,
    FclkZncc,
    IclkSsd,
    IclkZncc,
}

choice_param!(SecondHypothesis {
    None = "none",
    EsmSsd = "esm_ssd",
    EsmZncc = "esm_zncc",
    FclkSsd = "fclk_ssd",
    FclkZncc = "fclk_zncc",
    IclkSsd = "iclk_ssd",
    IclkZncc = "iclk_zncc",
});

impl SecondHypothesis {
    /// The search method and the AM, if any.
    pub fn names(self) -> Option<(&'static str, &'static str)> {
        let name = Self::NAMES[self.to_param() as usize];
        name.split_once('_')
            .filter(|_| self != SecondHypothesis::None)
    }
}

/// What a tracker does after a loss of track.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LossPolicy {
    /// Stays lost until it is initialised again (or moved with `set_corners`); the evaluation's
    /// reinit protocol restarts it from the ground truth.
    Stop,
    /// Keeps searching each frame from the last good estimate, reporting `Lost` until a frame
    /// passes the checks again (as MTF does).
    Continue,
    /// As `Continue`, and when that fails, searches the whole frame for the template (the last
    /// good quad moved over the frame at three scales, ranked by confidence), refines the best
    /// candidates and resumes with the first that passes the checks (the default: a lost
    /// tracker comes back when the target does, as a live user expects).
    #[default]
    Redetect,
}
choice_param!(LossPolicy {
    Stop = "stop",
    Continue = "continue",
    Redetect = "redetect",
});

/// The smoothing of the gradient methods' finest level when `blur_sigma` is auto (px).
pub const AUTO_SIGMA_GRADIENT: f64 = 0.7;
/// The smoothing of the sampling methods (NN, PF) when `blur_sigma` is auto: the paper's. Their
/// samples need a smooth cost: at 0.7 the particle filter held SR@5 0.62 of the evidence set
/// against 0.71 at 3 (NN1K: 0.62 and 0.61).
pub const AUTO_SIGMA_SAMPLING: f64 = 3.0;

/// The smoothing of the descriptor fields (`channels = df`) for the gradient methods when
/// `blur_sigma` is auto (px): chosen on the tune half of the held-out renders under changing
/// light (ESM SSD / ZNCC SR@5 0.749 / 0.735 at 0.7, 0.758 / 0.758 at 1, 0.776 / 0.774 at 1.5,
/// 0.795 / 0.792 at 2 in a kernel of 7, 0.765 / 0.759 at 3 in a kernel of 9; with the
/// confidence over all four fields 1.5 and 2 tie, 0.790 / 0.781 and 0.792 / 0.778;
/// docs/methods.md).
/// Crivellaro and Lepetit's point: the fields may be smoothed more than the image, since
/// smoothing no longer cancels opposite edges.
pub const AUTO_SIGMA_FIELDS: f64 = 2.0;
/// The least kernel size of the descriptor fields' auto smoothing (2 at 1.5 sigma each side):
/// with 5, SR@5 0.770 / 0.783 on the same renders.
pub const AUTO_SIZE_FIELDS: usize = 7;

impl TrackerParams {
    /// The standard deviation of the pre-smoothing (px): `blur_sigma`, or when it is auto (-1)
    /// the default of a search method that descends a gradient (`gradient`) or samples (on
    /// the descriptor fields, [`AUTO_SIGMA_FIELDS`] for a gradient method).
    pub fn smoothing_sigma(&self, gradient: bool) -> f64 {
        match self.blur_sigma {
            s if s >= 0.0 => s,
            _ if gradient && self.channels == Channels::Df => AUTO_SIGMA_FIELDS,
            _ if gradient => AUTO_SIGMA_GRADIENT,
            _ => AUTO_SIGMA_SAMPLING,
        }
    }

    /// The size of the pre-smoothing kernel: `blur_size`, at least [`AUTO_SIZE_FIELDS`] for
    /// the descriptor fields' auto smoothing (as [`TrackerParams::smoothing_sigma`]).
    pub fn smoothing_size(&self, gradient: bool) -> usize {
        let auto = self.blur_sigma < 0.0 && gradient && self.channels == Channels::Df;
        if auto && self.blur_size > 1 {
            self.blur_size.max(AUTO_SIZE_FIELDS)
        } else {
            self.blur_size
        }
    }

    /// The definition called `name`.
    pub fn def(name: &str) -> Option<&'static ParamDef> {
        TRACKER_PARAMS.iter().find(|d| d.name == name)
    }

    /// Sets a parameter from its typed form (`hessian=newton`, `res=80`), checked; returns
    /// whether the name is a tracker parameter.
    pub fn assign(&mut self, name: &str, value: &str) -> Result<bool> {
        match Self::def(name) {
            Some(d) => {
                let v = d.parse("tracker", value)?;
                self.set_value(name, v);
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// Checks every value against [`TRACKER_PARAMS`]; the error says which parameter is wrong.
    pub fn validate(&self) -> Result<()> {
        for d in TRACKER_PARAMS {
            d.check("tracker", self.value(d.name))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_parameter_reads_back_what_was_set_and_defaults_match_the_definitions() {
        let mut p = TrackerParams::default();
        for d in TRACKER_PARAMS {
            assert_eq!(p.value(d.name), d.default, "{}", d.name);
            let other = if d.max > d.default { d.max } else { d.min };
            assert!(p.set_value(d.name, other), "{}", d.name);
            assert_eq!(p.value(d.name), other, "{}", d.name);
        }
        assert!(!p.set_value("nope", 1.0));
        assert!(p.value("nope").is_nan());
        // Every flag names a parameter.
        for (_, name) in TRACKER_FLAGS {
            assert!(TrackerParams::def(name).is_some(), "{name}");
        }
    }

    #[test]
    fn choice_names_are_the_serde_names() {
        fn serde_name<T: Serialize>(v: &T) -> String {
            serde_json::to_value(v)
                .unwrap()
                .as_str()
                .unwrap()
                .to_string()
        }
        for (i, n) in HessianKind::NAMES.iter().enumerate() {
            assert_eq!(serde_name(&HessianKind::from_param(i as f64)), *n);
        }
        for (i, n) in GridLayout::NAMES.iter().enumerate() {
            assert_eq!(serde_name(&GridLayout::from_param(i as f64)), *n);
        }
        for (i, n) in LossPolicy::NAMES.iter().enumerate() {
            assert_eq!(serde_name(&LossPolicy::from_param(i as f64)), *n);
        }
    }
}
