//! Parameter definitions: the one source of truth for a parameter's name, help, range and
//! default. Validation, the command line (`--param name=value`), `regtrack list`, the
//! inspector's widgets and the sessions all read these tables.
//!
//! This module is the bottom layer: the definitions and the values. The registration tracker's
//! own parameters are declared in [`crate::spec::TRACKER_PARAMS`]; each method lists its
//! parameters in its registry entry (an SM's, an AM's, a whole tracker's) and receives their
//! values as [`MethodParams`].

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

    /// A choice among `names` whose default is `names[default]`.
    pub const fn choice_default(
        name: &'static str,
        help: &'static str,
        names: &'static [&'static str],
        default: usize,
    ) -> Self {
        let mut def = Self::choice(name, help, names);
        def.default = default as f64;
        def
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
                if v == 0.0 || (1e-3..1e7).contains(&v.abs()) || !v.is_finite() {
                    format!("{v}")
                } else {
                    format!("{v:.3e}")
                }
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
                        "{owner}: {} must be one of {}, got '{}'",
                        self.name,
                        names.join(", "),
                        crate::error::short_text(s)
                    ))
                })?,
            _ => s.parse::<f64>().map_err(|_| {
                Error::InvalidParameter(format!(
                    "{owner}: {} must be a number, got '{}'",
                    self.name,
                    crate::error::short_text(s)
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
        .ok_or_else(|| {
            Error::InvalidParameter(format!(
                "expected name=value, got '{}'",
                crate::error::short_text(s)
            ))
        })
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
