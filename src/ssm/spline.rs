//! The B-spline SSMs: `spline` (3 x 3 control points, 18 DOF) and `spline5` (5 x 5, 50
//! DOF), MTF's `spline`. See [`super::displacement`]. Their bending priors' own weights (`smoothness =
//! -1`) were chosen on the tune half of the bending renders (docs/methods.md).

use super::SsmBuilder;
use super::displacement::{Displacement, Kind, NAMES_3, NAMES_5};
use crate::registry::Entry;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "spline",
    aliases: &["spline3"],
    description: "18 DOF non-rigid warp: clamped B-spline (cubic from 4 a side) displacement of 3 x 3 control points on the target",
    build: || {
        Box::new(Displacement::new(
            ENTRY.name,
            Kind::Spline,
            3,
            &NAMES_3,
            0.05,
        ))
    },
};

pub const ENTRY_5: Entry<SsmBuilder> = Entry {
    name: "spline5",
    aliases: &[],
    description: "50 DOF non-rigid warp: clamped B-spline (cubic from 4 a side) displacement of 5 x 5 control points on the target",
    build: || {
        Box::new(Displacement::new(
            ENTRY_5.name,
            Kind::Spline,
            5,
            &NAMES_5,
            3.0,
        ))
    },
};
