//! What the inspector keeps between runs besides sessions: the recently opened sequences. It
//! lives in the user's configuration folder, and sessions go to the user's data folder by
//! default (never inside the program's folder, which may be read-only or shared).
//!
//! | | Linux and BSD | macOS | Windows |
//! |---|---|---|---|
//! | preferences | `$XDG_CONFIG_HOME/regtrack` or `~/.config/regtrack` | `~/Library/Application Support/regtrack` | `%APPDATA%\regtrack` |
//! | sessions | `$XDG_DATA_HOME/regtrack/sessions` or `~/.local/share/regtrack/sessions` | `~/Library/Application Support/regtrack/sessions` | `%APPDATA%\regtrack\sessions` |
//!
//! `REGTRACK_CONFIG_DIR` replaces both folders (preferences in it, sessions in its `sessions`).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// How many recent sequences are kept.
pub const RECENT: usize = 8;

/// The preferences file's contents.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Prefs {
    /// Sequences opened, newest first.
    pub recent: Vec<PathBuf>,
    /// Sessions loaded or saved, newest first.
    pub recent_sessions: Vec<PathBuf>,
    /// The side panels' widths as shares of the window (`trackers`, `plots`), as last dragged.
    pub panels: std::collections::BTreeMap<String, f32>,
}

impl Prefs {
    /// Reads the preferences; a missing file is the defaults. A file that cannot be read or
    /// parsed is an error naming it (the inspector then starts with the defaults).
    pub fn load(path: &Path) -> crate::Result<Prefs> {
        match crate::files::read_text_optional(path, crate::files::SETTINGS_LIMIT)? {
            Some(text) => toml::from_str(&text).map_err(|e| crate::Error::Parse {
                path: path.to_path_buf(),
                line: e
                    .span()
                    .map_or(0, |s| text[..s.start].matches('\n').count() + 1),
                message: e.message().to_string(),
            }),
            None => Ok(Prefs::default()),
        }
    }

    /// Writes the preferences (atomically: a crash leaves the old file or the new one).
    pub fn save(&self, path: &Path) -> crate::Result<()> {
        let text = toml::to_string_pretty(self)
            .map_err(|e| crate::Error::InvalidParameter(e.to_string()))?;
        crate::dataset::write_atomic(path, text.as_bytes())
    }

    /// Puts session `p` first in the recent sessions (once), keeping the newest [`RECENT`].
    pub fn add_recent_session(&mut self, p: &Path) {
        self.recent_sessions.retain(|r| r != p);
        self.recent_sessions.insert(0, p.to_path_buf());
        self.recent_sessions.truncate(RECENT);
    }

    /// The sessions to offer: the recent ones, then those of the user's sessions folder and of
    /// `./sessions` (the bundled ones, from a checkout), each once.
    pub fn session_choices(&self) -> Vec<PathBuf> {
        let mut out = self.recent_sessions.clone();
        let folders = [
            default_session_path().parent().map(Path::to_path_buf),
            Some(PathBuf::from("sessions")),
        ];
        for dir in folders.into_iter().flatten() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            let mut found: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "toml") && p.is_file())
                .collect();
            found.sort();
            for p in found {
                let p = std::path::absolute(&p).unwrap_or(p);
                if !out.contains(&p) {
                    out.push(p);
                }
            }
        }
        out.truncate(40);
        out
    }

    /// Puts `p` first in the recent list (once), keeping the newest [`RECENT`].
    pub fn add_recent(&mut self, p: &Path) {
        self.recent.retain(|r| r != p);
        self.recent.insert(0, p.to_path_buf());
        self.recent.truncate(RECENT);
    }
}

fn env_dir(name: &str) -> Option<PathBuf> {
    std::env::var_os(name)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
}

fn home() -> Option<PathBuf> {
    env_dir("HOME").or_else(|| env_dir("USERPROFILE"))
}

/// The folder of the preferences file (see the module's table); `None` without a home folder.
pub fn config_dir() -> Option<PathBuf> {
    if let Some(d) = env_dir("REGTRACK_CONFIG_DIR") {
        return Some(d);
    }
    platform_dir("XDG_CONFIG_HOME", ".config")
}

/// The folder sessions are saved to by default (see the module's table).
pub fn sessions_dir() -> Option<PathBuf> {
    if let Some(d) = env_dir("REGTRACK_CONFIG_DIR") {
        return Some(d.join("sessions"));
    }
    platform_dir("XDG_DATA_HOME", ".local/share").map(|d| d.join("sessions"))
}

/// `regtrack` in the platform's folder for applications: `%APPDATA%` on Windows, `Application
/// Support` on macOS, elsewhere the XDG variable `xdg_var` or `xdg_fallback` in the home folder.
fn platform_dir(xdg_var: &str, xdg_fallback: &str) -> Option<PathBuf> {
    let base = if cfg!(windows) {
        env_dir("APPDATA")
    } else if cfg!(target_os = "macos") {
        home().map(|h| h.join("Library/Application Support"))
    } else {
        env_dir(xdg_var).or_else(|| home().map(|h| h.join(xdg_fallback)))
    };
    base.map(|b| b.join("regtrack"))
}

/// The preferences file, `inspector.toml` in [`config_dir`].
pub fn prefs_path() -> Option<PathBuf> {
    config_dir().map(|d| d.join("inspector.toml"))
}

/// The session file the session field starts with: `my_session.toml` in [`sessions_dir`]
/// (relative to the working folder only when there is no home folder).
pub fn default_session_path() -> PathBuf {
    sessions_dir()
        .unwrap_or_else(|| PathBuf::from("sessions"))
        .join("my_session.toml")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recent_list_keeps_the_newest_once_and_round_trips() {
        let mut p = Prefs::default();
        for i in 0..12 {
            p.add_recent(Path::new(&format!("/seq/{i}")));
        }
        p.add_recent(Path::new("/seq/5"));
        assert_eq!(p.recent.len(), RECENT);
        assert_eq!(p.recent[0], Path::new("/seq/5"));
        assert_eq!(p.recent[1], Path::new("/seq/11"));
        assert_eq!(p.recent.iter().filter(|r| r.ends_with("5")).count(), 1);
        let dir = std::env::temp_dir().join(format!("regtrack-prefs-{}", std::process::id()));
        let path = dir.join("deep/inspector.toml");
        assert_eq!(Prefs::load(&path).unwrap(), Prefs::default());
        p.save(&path).unwrap();
        assert_eq!(Prefs::load(&path).unwrap(), p);
        std::fs::write(&path, "recent = 3\n").unwrap();
        let e = Prefs::load(&path).unwrap_err().to_string();
        assert!(e.contains("inspector.toml") && e.contains(":1"), "{e}");
        let _ = std::fs::remove_dir_all(dir);
    }
}
