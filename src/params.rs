//! Parameter definitions: the one source of truth for a parameter's name, help, range and
//! default. Validation, the command line (`--param name=value`), `regtrack list`, the
//! inspector's widgets and the sessions all read these tables.
//!
//! The tracker's own parameters are [`crate::tracker::TRACKER_PARAMS`]; each search method lists
//! its parameters in its registry entry ([`crate::sm::SmDef::params`]) and receives their values as
//! [`MethodParams`].

use crate::am::HessianKind;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What values a parameter takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamKind {
    /// A whole number in `min..=max`.
    Int,
    /// A real number in `min..=max`.
    Float,
    /// One of these names; the value is its index.
    Choice(&'static [&'static str]),
}

/// One parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamDef {
    pub name: &'static str,
    /// One line for `--help`, `regtrack list` and tooltips.
    pub help: &'static str,
    pub kind: ParamKind,
    pub min: f64,
    pub max: f64,
    pub default: f64,
}

impl ParamDef {
    /// A whole-number parameter.
    pub const fn int(
        name: &'static str,
        help: &'static str,
        min: f64,
        max: f64,
        default: f64,
    ) -> Self {
        ParamDef {
            name,
            help,
            kind: ParamKind::Int,
            min,
            max,
            default,
        }
    }

    /// A real-valued parameter.
    pub const fn float(
        name: &'static str,
        help: &'static str,
        min: f64,
        max: f64,
        default: f64,
    ) -> Self {
        ParamDef {
            name,
            help,
            kind: ParamKind::Float,
            min,
            max,
            default,
        }
    }

    /// A parameter that is one of `names` (default: the first).
    pub const fn choice(
        name: &'static str,
        help: &'static str,
        names: &'static [&'static str],
    ) -> Self {
        ParamDef {
            name,
            help,
            kind: ParamKind::Choice(names),
            min: 0.0,
            max: (names.len() - 1) as f64,
            default: 0.0,
        }
    }

    /// Checks `v` against the range (and whole-ness); the error names the parameter.
    pub fn check(&self, owner: &str, v: f64) -> Result<()> {
        let whole = !matches!(self.kind, ParamKind::Float);
        if !v.is_finite() || v < self.min || v > self.max || (whole && v.fract() != 0.0) {
            return Err(Error::InvalidParameter(format!(
                "{owner}: {} must be {} in {}..={}, got {}",
                self.name,
                if whole { "a whole number" } else { "a number" },
                self.format(self.min),
                self.format(self.max),
                v
            )));
        }
        Ok(())
    }

    /// Parses a value as typed on the command line (a number, or a choice's name).
    pub fn parse(&self, owner: &str, s: &str) -> Result<f64> {
        let s = s.trim();
        let v = match self.kind {
            ParamKind::Choice(names) => names
                .iter()
                .position(|n| n.eq_ignore_ascii_case(s))
                .map(|i| i as f64)
                .ok_or_else(|| {
                    Error::InvalidParameter(format!(
                        "{owner}: {} must be one of {}, got '{s}'",
                        self.name,
                        names.join(", ")
                    ))
                })?,
            _ => s.parse::<f64>().map_err(|_| {
                Error::InvalidParameter(format!(
                    "{owner}: {} must be a number, got '{s}'",
                    self.name
                ))
            })?,
        };
        self.check(owner, v)?;
        Ok(v)
    }

    /// The value as a person reads it (a choice by its name).
    pub fn format(&self, v: f64) -> String {
        match self.kind {
            ParamKind::Choice(names) => names
                .get(v as usize)
                .map(|n| n.to_string())
                .unwrap_or_else(|| v.to_string()),
            ParamKind::Int => format!("{}", v as i64),
            ParamKind::Float => format!("{v}"),
        }
    }

    /// `name (range, default): help`, for listings.
    pub fn describe(&self) -> String {
        let range = match self.kind {
            ParamKind::Choice(names) => names.join("|"),
            _ => format!("{}..={}", self.format(self.min), self.format(self.max)),
        };
        format!(
            "{} ({range}, default {}): {}",
            self.name,
            self.format(self.default),
            self.help
        )
    }
}

/// The values of a method's own parameters, by name; a missing one takes its default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct MethodParams(pub BTreeMap<String, f64>);

impl MethodParams {
    /// Whether no value is set.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The value of `def` (its default when unset).
    pub fn get(&self, def: &ParamDef) -> f64 {
        self.0.get(def.name).copied().unwrap_or(def.default)
    }

    /// The values whose names `defs` has, and the others.
    pub fn split(&self, defs: &[&ParamDef]) -> (MethodParams, MethodParams) {
        let (mut inside, mut outside) = (MethodParams::default(), MethodParams::default());
        for (k, &v) in &self.0 {
            if defs.iter().any(|d| d.name == k.as_str()) {
                inside.set(k, v);
            } else {
                outside.set(k, v);
            }
        }
        (inside, outside)
    }

    /// Sets a value.
    pub fn set(&mut self, name: &str, v: f64) {
        self.0.insert(name.to_string(), v);
    }

    /// Every value known to `defs` and in range; an unknown name is an error listing the known
    /// ones.
    pub fn validate(&self, owner: &str, defs: &[&ParamDef]) -> Result<()> {
        for (name, &v) in &self.0 {
            match defs.iter().find(|d| d.name == name) {
                Some(d) => d.check(owner, v)?,
                None => {
                    return Err(Error::InvalidParameter(format!(
                        "{owner} has no parameter '{name}'{}",
                        if defs.is_empty() {
                            " (it has none)".to_string()
                        } else {
                            format!(
                                "; its parameters: {}",
                                defs.iter().map(|d| d.name).collect::<Vec<_>>().join(", ")
                            )
                        }
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Splits `name=value` (as typed after `--param`).
pub fn split_assignment(s: &str) -> Result<(&str, &str)> {
    s.split_once('=')
        .map(|(a, b)| (a.trim(), b.trim()))
        .filter(|(a, _)| !a.is_empty())
        .ok_or_else(|| Error::InvalidParameter(format!("expected name=value, got '{s}'")))
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEFS: &[ParamDef] = &[
        ParamDef::int("samples", "samples", 10.0, 100.0, 20.0),
        ParamDef::float("sigma", "spread", 0.0, 1.0, 0.5),
        ParamDef::choice("kind", "which", &["a", "b"]),
    ];

    #[test]
    fn values_are_checked_parsed_and_listed() {
        let defs: Vec<&ParamDef> = DEFS.iter().collect();
        let mut p = MethodParams::default();
        assert_eq!(p.get(&DEFS[0]), 20.0);
        p.set("samples", 50.0);
        assert!(p.validate("nn", &defs).is_ok());
        p.set("samples", 50.5);
        assert!(
            p.validate("nn", &defs)
                .unwrap_err()
                .to_string()
                .contains("whole")
        );
        p.set("samples", 500.0);
        assert!(
            p.validate("nn", &defs)
                .unwrap_err()
                .to_string()
                .contains("10..=100")
        );
        let mut q = MethodParams::default();
        q.set("particles", 3.0);
        let e = q.validate("nn", &defs).unwrap_err().to_string();
        assert!(
            e.contains("'particles'") && e.contains("samples, sigma, kind"),
            "{e}"
        );
        assert_eq!(DEFS[2].parse("x", "B").unwrap(), 1.0);
        assert!(DEFS[2].parse("x", "c").is_err());
        assert!(DEFS[1].parse("x", "two").is_err());
        assert_eq!(DEFS[2].format(1.0), "b");
        assert!(
            DEFS[0]
                .describe()
                .starts_with("samples (10..=100, default 20)")
        );
        assert_eq!(split_assignment("a = 3").unwrap(), ("a", "3"));
        assert!(split_assignment("=3").is_err());
    }
}

/// The parameters every registration tracker has (the paper's defaults), in
/// [`TRACKER_PARAMS`]' order. Sessions store them by these names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerParams {
    /// Sampling resolution: `res x res` points on the target.
    pub res: usize,
    /// Maximum iterations per frame.
    pub max_iters: usize,
    /// Stop when the L2 norm of the change of the corners in an iteration is below this (px).
    pub eps: f64,
    /// Gaussian pre-smoothing kernel size (1 = none).
    pub blur_size: usize,
    /// Gaussian pre-smoothing standard deviation (px).
    pub blur_sigma: f32,
    /// Which Hessian the search method uses.
    pub hessian: HessianKind,
    /// Margin of the pre-processed region around the target, as a fraction of its size.
    pub roi_margin: f64,
    /// Coarse-to-fine search over this many pyramid levels (1 = the frame only), each half the
    /// size of the previous; each level has its own template.
    pub pyramid_levels: usize,
    /// Seed of the random generators of the sampling search methods (NN, PF).
    pub seed: u64,
    /// What a tracker does after it lost the target.
    pub on_loss: LossPolicy,
    /// Hierarchical search over SSMs (MTF's `hrch`): each frame is first searched with the SSMs
    /// of 2, 4 and 6 DOF below the tracker's own, each from the previous one's result.
    pub ssm_hierarchy: bool,
    /// Where the `res x res` samples lie: at the centres of a tiling of the target (inside it,
    /// the default) or spanning it from corner to corner (on its border too, as MTF samples).
    pub grid: GridLayout,
}

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

/// What a tracker does after a loss of track.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LossPolicy {
    /// Stays lost until it is initialised again (or moved with `set_corners`); the evaluation's
    /// reinit protocol restarts it from the ground truth.
    #[default]
    Stop,
    /// Keeps searching each frame from the last good estimate, reporting `Lost` until a frame
    /// passes the checks again (as MTF does).
    Continue,
}

/// The Hessian kinds in [`TRACKER_PARAMS`]' `hessian` choice order.
const HESSIANS: [HessianKind; 4] = [
    HessianKind::Default,
    HessianKind::GaussNewton,
    HessianKind::Newton,
    HessianKind::AfterConvergence,
];

/// The definitions of [`TrackerParams`]: names, ranges, defaults.
pub const TRACKER_PARAMS: &[ParamDef] = &[
    ParamDef::int(
        "res",
        "sampling resolution: res x res points on the target",
        2.0,
        1000.0,
        50.0,
    ),
    ParamDef::int(
        "max_iters",
        "maximum iterations per frame",
        1.0,
        10_000.0,
        30.0,
    ),
    ParamDef::float(
        "eps",
        "stop when the corners move less than this in an iteration (L2 norm of the 8 coordinates, px)",
        0.0,
        1000.0,
        0.001,
    ),
    ParamDef::int(
        "blur_size",
        "Gaussian pre-smoothing kernel size (1 = none)",
        1.0,
        31.0,
        5.0,
    ),
    ParamDef::float(
        "blur_sigma",
        "Gaussian pre-smoothing standard deviation (px)",
        0.0,
        100.0,
        3.0,
    ),
    ParamDef::choice(
        "hessian",
        "the Hessian of the Newton step (default: the AM's own)",
        &["default", "gauss_newton", "newton", "after_convergence"],
    ),
    ParamDef::float(
        "roi_margin",
        "margin of the pre-processed region around the target, as a fraction of its size",
        0.0,
        10.0,
        0.25,
    ),
    ParamDef::int(
        "pyramid_levels",
        "coarse-to-fine pyramid levels (1 = none)",
        1.0,
        6.0,
        1.0,
    ),
    ParamDef::int(
        "seed",
        "seed of the random generators (NN samples, PF particles)",
        0.0,
        9_007_199_254_740_991.0,
        0.0,
    ),
    ParamDef::choice(
        "on_loss",
        "after a loss of track: stop (until re-initialised) or continue from the last good estimate",
        &["stop", "continue"],
    ),
    ParamDef::choice(
        "ssm_hierarchy",
        "off, or on: search translation, similitude and affine (those below the tracker's SSM) first, then the tracker's SSM (MTF's hrch)",
        &["off", "on"],
    ),
    ParamDef::choice(
        "grid",
        "sampling grid: centres (of a res x res tiling, inside the target) or border (corner to corner, as MTF)",
        &["centres", "border"],
    ),
];

impl Default for TrackerParams {
    fn default() -> Self {
        let mut p = TrackerParams {
            res: 0,
            max_iters: 0,
            eps: 0.0,
            blur_size: 0,
            blur_sigma: 0.0,
            hessian: HessianKind::Default,
            roi_margin: 0.0,
            pyramid_levels: 0,
            seed: 0,
            on_loss: LossPolicy::Stop,
            ssm_hierarchy: false,
            grid: GridLayout::Centres,
        };
        for d in TRACKER_PARAMS {
            p.set_value(d.name, d.default);
        }
        p
    }
}

impl TrackerParams {
    /// The definition called `name`.
    pub fn def(name: &str) -> Option<&'static ParamDef> {
        TRACKER_PARAMS.iter().find(|d| d.name == name)
    }

    /// The value of the parameter `name` (a choice as its index; `NaN` for an unknown name).
    pub fn value(&self, name: &str) -> f64 {
        match name {
            "res" => self.res as f64,
            "max_iters" => self.max_iters as f64,
            "eps" => self.eps,
            "blur_size" => self.blur_size as f64,
            "blur_sigma" => self.blur_sigma as f64,
            "hessian" => HESSIANS
                .iter()
                .position(|&h| h == self.hessian)
                .unwrap_or(0) as f64,
            "roi_margin" => self.roi_margin,
            "pyramid_levels" => self.pyramid_levels as f64,
            "seed" => self.seed as f64,
            "ssm_hierarchy" => self.ssm_hierarchy as u8 as f64,
            "grid" => self.grid as u8 as f64,
            "on_loss" => match self.on_loss {
                LossPolicy::Stop => 0.0,
                LossPolicy::Continue => 1.0,
            },
            _ => f64::NAN,
        }
    }

    /// Sets the parameter `name` (unchecked: see [`TrackerParams::validate`]); returns whether
    /// the name exists.
    pub fn set_value(&mut self, name: &str, v: f64) -> bool {
        let whole = v.max(0.0) as usize;
        match name {
            "res" => self.res = whole,
            "max_iters" => self.max_iters = whole,
            "eps" => self.eps = v,
            "blur_size" => self.blur_size = whole,
            "blur_sigma" => self.blur_sigma = v as f32,
            "hessian" => self.hessian = HESSIANS.get(whole).copied().unwrap_or_default(),
            "roi_margin" => self.roi_margin = v,
            "pyramid_levels" => self.pyramid_levels = whole,
            "seed" => self.seed = v.max(0.0) as u64,
            "ssm_hierarchy" => self.ssm_hierarchy = whole == 1,
            "grid" => {
                self.grid = if whole == 1 {
                    GridLayout::Border
                } else {
                    GridLayout::Centres
                }
            }
            "on_loss" => {
                self.on_loss = if whole == 1 {
                    LossPolicy::Continue
                } else {
                    LossPolicy::Stop
                }
            }
            _ => return false,
        }
        true
    }

    /// Sets a parameter from its typed form (`hessian=newton`, `res=80`), checked.
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
