//! NNIC (the paper's composite): nearest-neighbour search with 1000 samples, then inverse
//! compositional Lucas-Kanade from where it stopped: `cascade:nn+iclk` with NN's parameters.

use super::cascade::Cascade;
use super::iclk::Iclk;
use super::nn::{NN_PARAMS, Nn};
use super::{SearchMethod, SmDef};
use crate::registry::Entry;

pub const ENTRY: Entry<SmDef> = Entry {
    name: "nnic",
    aliases: &[],
    description: "NN1K followed by ICLK (a cascade)",
    build: SmDef {
        params: &NN_PARAMS,
        build: |cfg| {
            let stages: Vec<Box<dyn SearchMethod>> = vec![
                Box::new(Nn::new("nn", &NN_PARAMS, cfg)?),
                Box::new(Iclk::default()),
            ];
            Ok(Box::new(Cascade::new("nnic".into(), stages, cfg)))
        },
    },
};
