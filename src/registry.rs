//! Method registries: every AM, SSM and SM is one entry (name, aliases, description, constructor)
//! in its module's `REGISTRY`. The CLI's `list`, the inspector's dropdowns and the generic tests
//! read them, so a new method appears everywhere by adding its file and one registry line.

use crate::error::{Error, Result};

/// One registered method.
#[derive(Clone, Copy)]
pub struct Entry<B> {
    /// The canonical name (what files and sessions store).
    pub name: &'static str,
    /// Other accepted names, including MTF's short names.
    pub aliases: &'static [&'static str],
    /// One line for `regtrack list` and tooltips.
    pub description: &'static str,
    /// Builds the method.
    pub build: B,
}

impl<B> Entry<B> {
    /// Whether `name` (case-insensitive) is this entry's name or one of its aliases.
    pub fn matches(&self, name: &str) -> bool {
        self.name.eq_ignore_ascii_case(name)
            || self.aliases.iter().any(|a| a.eq_ignore_ascii_case(name))
    }
}

/// Finds the entry called `name` in `entries`, or an error listing what exists.
pub fn lookup<'a, B>(
    entries: &'a [Entry<B>],
    kind: &'static str,
    name: &str,
) -> Result<&'a Entry<B>> {
    let name = name.trim();
    entries
        .iter()
        .find(|e| e.matches(name))
        .ok_or_else(|| Error::UnknownMethod {
            kind,
            name: crate::error::short_text(name),
            available: entries
                .iter()
                .map(|e| {
                    if e.aliases.is_empty() {
                        e.name.to_string()
                    } else {
                        format!("{} ({})", e.name, e.aliases.join(", "))
                    }
                })
                .collect::<Vec<_>>()
                .join(", "),
        })
}
