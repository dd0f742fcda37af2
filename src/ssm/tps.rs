//! The thin-plate spline SSMs: `tps` (3 x 3 control points, 18 DOF) and `tps5` (5 x 5, 50
//! DOF), MTF's `tps`. See [`super::displacement`]. Their bending priors' own weights (`smoothness =
//! -1`) were chosen on the tune half of the bending renders (docs/methods.md).

use super::SsmBuilder;
use super::displacement::{Displacement, Kind, NAMES_3, NAMES_5};
use crate::registry::Entry;

pub const ENTRY: Entry<SsmBuilder> = Entry {
    name: "tps",
    aliases: &["tps3"],
    description: "18 DOF non-rigid warp: thin-plate spline displacement through 3 x 3 control points on the target",
    build: || Box::new(Displacement::new(ENTRY.name, Kind::Tps, 3, &NAMES_3, 0.1)),
};

pub const ENTRY_5: Entry<SsmBuilder> = Entry {
    name: "tps5",
    aliases: &[],
    description: "50 DOF non-rigid warp: thin-plate spline displacement through 5 x 5 control points on the target",
    build: || Box::new(Displacement::new(ENTRY_5.name, Kind::Tps, 5, &NAMES_5, 0.2)),
};
