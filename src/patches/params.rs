//! The many-patch tracker's parameters ([`PATCH_PARAMS`], their one definition) and what a
//! patch reports of itself ([`PatchState`]).

use crate::error::{Error, Result};
use crate::geometry::{Point, Quad};
use crate::params::{MethodParams, ParamDef};
use crate::status::TrackStatus;

/// The warps a patch can have.
pub const WARPS: &[&str] = &["translation", "affine"];
/// Where a patch's template comes from.
pub const TEMPLATES: &[&str] = &["previous", "first"];

/// The many-patch tracker's parameters: their one definition (the command line's `--patch
/// name=value`, the Python binding's keywords and `regtrack list` read it).
pub const PATCH_PARAMS: &[ParamDef] = &[
    ParamDef::choice(
        "warp",
        "The warp of each patch: translation (2 parameters) or affine (6)",
        WARPS,
    ),
    ParamDef::int(
        "size",
        "Side of a patch's sampling grid, in pixels of each pyramid level",
        5.0,
        51.0,
        15.0,
    ),
    ParamDef::int(
        "levels",
        "Pyramid levels (1 = full resolution only)",
        1.0,
        6.0,
        3.0,
    ),
    ParamDef::int(
        "iterations",
        "Iterations per pyramid level at most",
        1.0,
        100.0,
        30.0,
    ),
    ParamDef::float(
        "eps",
        "Stop a level's iterations when the patch's corners move less than this (pixels of the level)",
        1e-4,
        1.0,
        0.01,
    ),
    ParamDef::choice(
        "template",
        "The template: the previous frame's patch (KLT) or the first frame's",
        TEMPLATES,
    ),
    ParamDef::float(
        "min_ncc",
        "A patch whose normalised cross-correlation with its template falls below this is lost",
        -1.0,
        1.0,
        0.7,
    ),
    ParamDef::float(
        "min_eigen",
        "A window whose structure tensor's smaller eigenvalue (per pixel, gray levels squared) is below this is flat: lost",
        0.0,
        1e5,
        1.0,
    ),
    ParamDef::float(
        "fb_max",
        "Also track each patch back to the previous frame; lost when it misses its start by more than this (pixels; 0 = no check)",
        0.0,
        1000.0,
        0.0,
    ),
    ParamDef::float(
        "smoothing",
        "Gaussian pre-smoothing of the frame, standard deviation in pixels (0 = none)",
        0.0,
        10.0,
        1.0,
    ),
    ParamDef::float(
        "min_distance",
        "Detected corners are at least this far apart (pixels)",
        0.0,
        1000.0,
        8.0,
    ),
    ParamDef::int(
        "threads",
        "Threads tracking the patches (0 = all cores)",
        0.0,
        1024.0,
        0.0,
    ),
];

/// The warp of a patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatchWarp {
    /// A shift: 2 parameters.
    Translation,
    /// A linear map and a shift: 6 parameters.
    Affine,
}

impl PatchWarp {
    pub(super) fn dof(self) -> usize {
        match self {
            PatchWarp::Translation => 2,
            PatchWarp::Affine => 6,
        }
    }
}

/// Where a patch's template comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TemplateSource {
    /// The patch in the previous frame, where it was tracked (KLT).
    Previous,
    /// The patch in the frame it was initialised on.
    First,
}

/// The many-patch tracker's settings (see [`PATCH_PARAMS`] for each).
#[derive(Clone, Debug, PartialEq)]
pub struct PatchParams {
    pub warp: PatchWarp,
    pub size: usize,
    pub levels: usize,
    pub iterations: usize,
    pub eps: f64,
    pub template: TemplateSource,
    pub min_ncc: f64,
    pub min_eigen: f64,
    pub fb_max: f64,
    pub smoothing: f64,
    pub min_distance: f64,
    pub threads: usize,
}

impl Default for PatchParams {
    fn default() -> Self {
        Self::from_values(&MethodParams::default()).unwrap_or_else(|_| unreachable!())
    }
}

impl PatchParams {
    /// The settings from values by name ([`PATCH_PARAMS`]'s defaults for the others); an unknown
    /// name or a value out of range is an error naming it.
    pub fn from_values(v: &MethodParams) -> Result<Self> {
        let defs: Vec<&ParamDef> = PATCH_PARAMS.iter().collect();
        v.validate("patches", &defs)?;
        let get = |name: &str| {
            PATCH_PARAMS
                .iter()
                .find(|d| d.name == name)
                .map_or(0.0, |d| v.get(d))
        };
        Ok(PatchParams {
            warp: if get("warp") == 1.0 {
                PatchWarp::Affine
            } else {
                PatchWarp::Translation
            },
            size: get("size") as usize,
            levels: get("levels") as usize,
            iterations: get("iterations") as usize,
            eps: get("eps"),
            template: if get("template") == 1.0 {
                TemplateSource::First
            } else {
                TemplateSource::Previous
            },
            min_ncc: get("min_ncc"),
            min_eigen: get("min_eigen"),
            fb_max: get("fb_max"),
            smoothing: get("smoothing"),
            min_distance: get("min_distance"),
            threads: get("threads") as usize,
        })
    }

    /// The settings from `name=value` assignments (choices by name).
    pub fn parse(assignments: &[(String, String)]) -> Result<Self> {
        let mut v = MethodParams::default();
        for (name, value) in assignments {
            let def = PATCH_PARAMS
                .iter()
                .find(|d| d.name == name.as_str())
                .ok_or_else(|| {
                    Error::InvalidParameter(format!(
                        "patches have no parameter '{name}'; their parameters: {}",
                        PATCH_PARAMS
                            .iter()
                            .map(|d| d.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            v.set(name, def.parse("patches", value)?);
        }
        Self::from_values(&v)
    }
}

/// What a patch is doing, after a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchState {
    /// The patch's centre in the frame (the last good one when lost).
    pub centre: Point,
    /// The linear part of its warp, `[a00, a01, a10, a11]` (the identity for translation): a
    /// patch offset `(u, v)` sits at `centre + (a00 u + a01 v, a10 u + a11 v)`.
    pub linear: [f64; 4],
    pub status: TrackStatus,
    /// The normalised cross-correlation of the tracked patch with its template (-1..1).
    pub ncc: f64,
    /// The forward-backward error (pixels), when `fb_max` asks for it and the frame was tracked.
    pub fb_error: Option<f64>,
    /// Iterations run on this frame, all levels together.
    pub iterations: usize,
}

impl PatchState {
    /// Whether the patch is followed.
    pub fn tracking(&self) -> bool {
        self.status == TrackStatus::Tracking
    }

    /// The corners of the patch's window (`half` pixels from the centre along each side, before
    /// the linear map): upper left, upper right, lower right, lower left.
    pub fn corners(&self, half: f64) -> Quad {
        let [a, b, c, d] = self.linear;
        let at = |u: f64, v: f64| Point {
            x: self.centre.x + a * u + b * v,
            y: self.centre.y + c * u + d * v,
        };
        Quad([
            at(-half, -half),
            at(half, -half),
            at(half, half),
            at(-half, half),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_and_out_of_range_parameters_are_named() {
        let e = PatchParams::parse(&[("sise".into(), "9".into())]).unwrap_err();
        assert!(e.to_string().contains("sise"), "{e}");
        let e = PatchParams::parse(&[("size".into(), "3".into())]).unwrap_err();
        assert!(e.to_string().contains("size"), "{e}");
        let p = PatchParams::parse(&[
            ("warp".into(), "affine".into()),
            ("template".into(), "first".into()),
        ])
        .unwrap();
        assert_eq!(
            (p.warp, p.template),
            (PatchWarp::Affine, TemplateSource::First)
        );
    }
}
