//! Search methods: the `argmax` of `f(I*, I_t(w(x, p)))`.
//!
//! A search method combines the AM and the SSM by the chain rule,
//! `df/dp = df/dI . dI/dx . dw/dp`, and updates the parameters. It implements one iteration
//! ([`SearchMethod::iterate`], the interface in [`crate::registration`]) and owns its
//! mathematics: the Newton steps of the gradient methods are in [`newton`]. The executor
//! ([`crate::registration::Executor`]) owns the loop, the stop test and the observer; the plan
//! ([`crate::plan`]) the pyramid, the SSM hierarchy, the polish and the loss checks. A method
//! works on a [`Context`]: the problem, the state and the buffers of one tracker's level
//! (allocated once, when the tracker is initialised).
//!
//! Each method is one file and one line in [`REGISTRY`].

mod cascade;
mod esm;
mod falk;
pub mod fclk;
mod grid;
mod ialk;
mod iclk;
pub mod newton;
mod nn;
mod nnic;
mod pf;
mod rklt;
mod robust;

pub use crate::observe::{MethodVisual, ResponseMap};
use crate::params::ParamDef;
pub use crate::registration::{
    Context, Control, Problem, SearchMethod, SmConfig, State, Step, Update, Workspace,
};
use crate::registry::{self, Entry};
pub use crate::status::LossReason;

/// A registry entry's contents: the method's parameters and its constructor.
#[derive(Clone, Copy)]
pub struct SmDef {
    pub params: &'static [ParamDef],
    pub build: fn(&SmConfig) -> crate::Result<Box<dyn SearchMethod>>,
}

/// Every search method. Composites are named `cascade:a+b+...` (each stage in turn, each with
/// the tracker's iteration limit), `parallel:a+b+...` (each from the same start, the best by
/// similarity kept) and `lm:a` (a gradient method with Levenberg-Marquardt damping).
pub const REGISTRY: &[Entry<SmDef>] = &[
    falk::ENTRY,
    ialk::ENTRY,
    fclk::ENTRY,
    iclk::ENTRY,
    esm::ENTRY,
    nn::ENTRY,
    nn::ENTRY_1K,
    nn::ENTRY_10K,
    nnic::ENTRY,
    pf::ENTRY,
    grid::ENTRY,
    rklt::ENTRY,
];

/// The stages of a composite name: `Some(("cascade", ["nn", "iclk"]))`.
fn composite(name: &str) -> Option<(&'static str, Vec<&str>)> {
    let name = name.trim();
    for kind in ["cascade", "parallel", "lm"] {
        if name.len() > kind.len() + 1
            && name[..kind.len()].eq_ignore_ascii_case(kind)
            && name.as_bytes()[kind.len()] == b':'
        {
            return Some((
                kind,
                name[kind.len() + 1..].split('+').map(str::trim).collect(),
            ));
        }
    }
    None
}

/// The canonical name of `name` (an alias resolved, composites stage by stage); an error lists
/// what exists.
pub fn canonical_name(name: &str) -> crate::Result<String> {
    match composite(name) {
        Some((kind, stages)) => {
            if kind == "lm" && stages.len() != 1 {
                return Err(crate::Error::InvalidParameter(format!(
                    "'{name}': lm takes one gradient search method, e.g. lm:iclk"
                )));
            }
            if kind != "lm" && stages.len() < 2 {
                return Err(crate::Error::InvalidParameter(format!(
                    "{kind} '{name}' needs at least two stages joined by '+'"
                )));
            }
            let names = stages
                .iter()
                .map(|s| canonical_name(s))
                .collect::<crate::Result<Vec<_>>>()?;
            Ok(format!("{kind}:{}", names.join("+")))
        }
        None => Ok(registry::lookup(REGISTRY, "search method", name)?
            .name
            .to_string()),
    }
}

/// The parameters of the method `name` (for a composite: those of its stages, each once).
pub fn param_defs(name: &str) -> crate::Result<Vec<&'static ParamDef>> {
    let mut out: Vec<&'static ParamDef> = Vec::new();
    match composite(name) {
        Some((_, stages)) => {
            for s in stages {
                for d in param_defs(s)? {
                    if !out.iter().any(|o| o.name == d.name) {
                        out.push(d);
                    }
                }
            }
        }
        None => out.extend(
            registry::lookup(REGISTRY, "search method", name)?
                .build
                .params
                .iter(),
        ),
    }
    Ok(out)
}

/// The SM called `name` (an alias, or a composite), with its parameters checked.
pub fn build(name: &str, cfg: &SmConfig) -> crate::Result<Box<dyn SearchMethod>> {
    let canonical = canonical_name(name)?;
    cfg.method.validate(
        &format!("search method '{canonical}'"),
        &param_defs(&canonical)?,
    )?;
    build_checked(&canonical, cfg)
}

fn build_checked(name: &str, cfg: &SmConfig) -> crate::Result<Box<dyn SearchMethod>> {
    match composite(name) {
        Some((kind, stages)) => {
            let built = stages
                .iter()
                .map(|s| build_checked(s, cfg))
                .collect::<crate::Result<Vec<_>>>()?;
            // The damping is of a Newton step: a sampling method (NN, PF) has none to damp.
            if kind == "lm"
                && let Some(s) = built.iter().find(|s| !s.requires().derivatives)
            {
                return Err(crate::Error::Incompatible(format!(
                    "'{name}': lm damps the Newton steps of a gradient search method (lm:iclk, \
                     lm:esm ...); {} samples instead of descending a gradient",
                    s.name()
                )));
            }
            Ok(match kind {
                "cascade" => Box::new(cascade::Cascade::new(name.to_string(), built, cfg)),
                "lm" => Box::new(cascade::LevenbergMarquardt::new(name.to_string(), built)),
                _ => Box::new(cascade::Parallel::new(name.to_string(), built, cfg)),
            })
        }
        None => (registry::lookup(REGISTRY, "search method", name)?
            .build
            .build)(cfg),
    }
}
