//! What can be built: every appearance model, state space model, search method and whole
//! tracker of the registries, with aliases, capabilities and parameters, and the tracker
//! parameters (`regtrack list`).

use crate::spec::{TRACKER_FLAGS, TRACKER_PARAMS};
use crate::{am, sm, ssm, whole};
use std::fmt::Write as _;

/// The listing `regtrack list` prints.
pub fn listing() -> String {
    let mut out = format!(
        "the default tracker (no --sm and no --am): {}\n",
        crate::spec::default_tracker_text()
    );
    let row = |out: &mut String, name: &str, al: &[&str], desc: &str| {
        let _ = writeln!(out, "  {:<12} {:<22} {}", name, aliases(al), desc);
    };
    let param = |out: &mut String, d: &crate::params::ParamDef| {
        let _ = writeln!(out, "  {:<12}   --param {}", "", d.describe());
    };
    out.push_str("appearance models (--am):\n");
    for e in am::REGISTRY {
        let c = e.build.default_model().capabilities();
        let mut tags = Vec::new();
        if !c.derivatives {
            tags.push("no gradient search");
        }
        if c.distance {
            tags.push("NN");
        }
        let tags = if tags.is_empty() {
            String::new()
        } else {
            format!(" [{}]", tags.join(", "))
        };
        row(
            &mut out,
            e.name,
            e.aliases,
            &format!("{}{tags}", e.description),
        );
        for d in e.build.params {
            param(&mut out, d);
        }
    }
    out.push_str("state space models (--ssm):\n");
    for e in ssm::REGISTRY {
        row(&mut out, e.name, e.aliases, e.description);
    }
    out.push_str(
        "search methods (--sm; composites: cascade:A+B+... stages in turn, parallel:A+B+... the \
         most similar, lm:A Levenberg-Marquardt damping):\n",
    );
    for e in sm::REGISTRY {
        row(&mut out, e.name, e.aliases, e.description);
        for d in e.build.params {
            param(&mut out, d);
        }
    }
    out.push_str("whole trackers (--tracker):\n");
    for e in whole::REGISTRY {
        row(&mut out, e.name, e.aliases, e.description);
        for d in e.build.params {
            param(&mut out, d);
        }
    }
    out.push_str("tracker parameters (--param NAME=VALUE, or --NAME VALUE):\n");
    for d in TRACKER_PARAMS {
        let flags: Vec<String> = TRACKER_FLAGS
            .iter()
            .filter(|(_, n)| *n == d.name)
            .map(|(f, _)| format!("--{f}"))
            .collect();
        let short = if flags.is_empty() {
            String::new()
        } else {
            format!(" [also {}]", flags.join(", "))
        };
        let _ = writeln!(out, "  {}{short}", d.describe());
    }
    out.push_str("many-patch parameters (track --patches N --patch NAME=VALUE):\n");
    for d in crate::patches::PATCH_PARAMS {
        let _ = writeln!(out, "  {}", d.describe());
    }
    out
}

fn aliases(a: &[&str]) -> String {
    if a.is_empty() {
        String::new()
    } else {
        format!("[{}]", a.join(", "))
    }
}
