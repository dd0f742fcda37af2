//! A session of the inspector (its saved state, `sessions/*.toml`): the sequence, the trackers and
//! their parameters, the current frame and the view. Everything else (textures, worker, results)
//! is the inspector's runtime state. In the core (no GUI needed) so that the readers are checked
//! and fuzzed without a window; the inspector re-exports it as `app::state`.

use crate::error::{Error, Result};
use crate::geometry::Quad;
use crate::params::MethodParams;
use crate::spec::DEFAULT_TRACKER;
use crate::tracker::{RegistrationSpec, TrackerSpec};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Where the sequence comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "path")]
pub enum SequenceSource {
    /// The bundled demo (rendered on first use).
    Demo,
    /// A ground-truth file or a folder of frames (any layout the core reads).
    Path(PathBuf),
}

/// How a tracker starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "corners")]
pub enum InitSource {
    /// From the ground truth of the start frame.
    GroundTruth,
    /// From corners the user drew.
    Quad(Quad),
}

/// An RGB colour of exactly three values (serde reads the first three of a longer list into
/// an array and ignores the rest).
fn three_values<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<[u8; 3], D::Error> {
    let v: Vec<u8> = serde::Deserialize::deserialize(d)?;
    let n = v.len();
    <[u8; 3]>::try_from(v).map_err(|_| {
        serde::de::Error::invalid_length(n, &"3 values (red, green, blue, each 0-255)")
    })
}

/// One tracker of the session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerEntry {
    pub spec: TrackerSpec,
    /// Drawing colour (RGB).
    #[serde(deserialize_with = "three_values")]
    pub color: [u8; 3],
    /// Whether it runs.
    pub enabled: bool,
    pub init: InitSource,
}

/// The frame view's zoom and pan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct View {
    /// Screen pixels per image pixel; 0 = fit the frame to the panel.
    pub zoom: f32,
    /// Image point at the centre of the panel (when zoomed).
    pub center: [f32; 2],
    pub show_ground_truth: bool,
    pub show_corner_numbers: bool,
    /// Draw the samples of NN and the particles of PF (newest frame).
    #[serde(default)]
    pub show_samples: bool,
    /// The trackers panel (left) and the plots panel (right) are shown; hiding them gives the
    /// frame the whole window.
    #[serde(default = "yes")]
    pub show_trackers_panel: bool,
    #[serde(default = "yes")]
    pub show_plots_panel: bool,
    /// A/B mode: two trackers side by side (their indices), with the frames where they disagree
    /// most listed.
    #[serde(default)]
    pub ab: Option<(usize, usize)>,
    /// The cost-landscape view is open, and what it sweeps.
    #[serde(default)]
    pub show_landscape: bool,
    #[serde(default)]
    pub landscape: LandscapeSettings,
    /// Zoomed in, the view follows the target from frame to frame: in the ground-truth mode
    /// its ground truth (on by default: stepping frames while annotating, it drifted off
    /// screen), otherwise the inspected tracker.
    #[serde(default = "yes")]
    pub follow_in_gt_mode: bool,
    #[serde(default)]
    pub follow_tracker: bool,
    /// The presentation scale (1 = normal): the frame's labels and quads and the plots' text
    /// and lines, for a class at the back of a room (F4 toggles 1 and 2).
    #[serde(default = "one")]
    pub label_scale: f32,
}

fn one() -> f32 {
    1.0
}

/// The presentation scales [`View::label_scale`] takes.
pub const LABEL_SCALE: std::ops::RangeInclusive<f32> = 0.75..=4.0;

/// What the cost-landscape view sweeps.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LandscapeSettings {
    /// The swept parameters (0-based); the second is optional (a curve or a map).
    pub x: usize,
    pub y: Option<usize>,
    /// Half-width of the sweep, px of corner motion (in [`LANDSCAPE_RADIUS`]).
    pub radius: f64,
    /// Around the ground truth instead of the tracker's estimate.
    pub around_truth: bool,
}

impl Default for LandscapeSettings {
    fn default() -> Self {
        LandscapeSettings {
            x: 0,
            y: None,
            radius: 5.0,
            around_truth: false,
        }
    }
}

/// The half-widths of a landscape sweep the widget and a session allow, px.
pub const LANDSCAPE_RADIUS: std::ops::RangeInclusive<f64> = 0.5..=100.0;

fn yes() -> bool {
    true
}

impl Default for View {
    fn default() -> Self {
        View {
            zoom: 0.0,
            center: [0.0, 0.0],
            show_ground_truth: true,
            show_corner_numbers: true,
            show_samples: false,
            show_trackers_panel: true,
            show_plots_panel: true,
            ab: None,
            show_landscape: false,
            landscape: LandscapeSettings::default(),
            follow_in_gt_mode: true,
            follow_tracker: false,
            label_scale: 1.0,
        }
    }
}

/// A session, saved as `sessions/*.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct State {
    pub sequence: SequenceSource,
    pub trackers: Vec<TrackerEntry>,
    /// The frame trackers start from.
    pub start_frame: usize,
    /// The frame shown.
    pub frame: usize,
    /// Playback speed in frames per second (0 = as fast as the trackers go).
    pub playback_fps: f32,
    pub view: View,
    /// The tracker whose iterations the convergence panel shows.
    pub selected_tracker: usize,
    /// The SSM the ground truth is shown and corrected in (`homography` = full 8 DOF).
    pub gt_ssm: String,
    /// The sidebar's many-patch run.
    pub patches: PatchSettings,
}

/// The many-patch run's settings (the sidebar's *Patches*; `regtrack track --patches`): how
/// many corners to track and the patch tracker's parameters by name
/// ([`crate::patches::PATCH_PARAMS`]; unset ones keep their defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PatchSettings {
    pub count: usize,
    pub params: MethodParams,
}

/// How many patches a run may ask for.
pub const PATCH_COUNT: std::ops::RangeInclusive<usize> = 1..=10_000;

impl Default for PatchSettings {
    fn default() -> Self {
        PatchSettings {
            count: 300,
            params: MethodParams::default(),
        }
    }
}

impl PatchSettings {
    /// The patch tracker's parameters (an unknown name or a value out of range is an error
    /// naming it).
    pub fn patch_params(&self) -> Result<crate::patches::PatchParams> {
        crate::patches::PatchParams::from_values(&self.params)
    }
}

/// The frame view's zoom (screen pixels per image pixel) besides 0 (fit): what the scroll wheel
/// reaches and a session may hold.
pub const ZOOM: std::ops::RangeInclusive<f32> = 0.05..=40.0;

/// Playback speeds besides 0 (as fast as the trackers go), frames per second: the speed widget's
/// range and a session's.
pub const PLAYBACK_FPS: std::ops::RangeInclusive<f32> = 0.1..=1000.0;

/// The largest image coordinate a session's view centre may have.
const MAX_CENTER: f32 = 1e7;

/// Distinct colours for trackers.
pub const PALETTE: [[u8; 3]; 8] = [
    [255, 80, 80],
    [80, 160, 255],
    [255, 200, 40],
    [200, 90, 255],
    [40, 220, 220],
    [255, 130, 40],
    [150, 255, 90],
    [255, 100, 200],
];

impl Default for State {
    fn default() -> Self {
        let entry = |spec, color| TrackerEntry {
            spec,
            color,
            enabled: true,
            init: InitSource::GroundTruth,
        };
        State {
            sequence: SequenceSource::Demo,
            trackers: vec![
                // The default tracker, and the paper's classic to compare it with.
                entry(crate::spec::default_spec(DEFAULT_TRACKER[2]), PALETTE[0]),
                entry(
                    TrackerSpec::Registration(RegistrationSpec {
                        sm: "esm".into(),
                        am: "ssd".into(),
                        ssm: DEFAULT_TRACKER[2].into(),
                        params: Default::default(),
                        method: Default::default(),
                    }),
                    PALETTE[1],
                ),
            ],
            start_frame: 0,
            frame: 0,
            playback_fps: 0.0,
            view: View::default(),
            selected_tracker: 0,
            gt_ssm: "homography".into(),
            patches: PatchSettings::default(),
        }
    }
}

/// A TOML or serde message in the words of the settings it is about: "invalid value: integer
/// `-7`, expected usize" reads "frame: -7 is not a whole number of 0 or more".
pub fn plain_message(message: &str, key: Option<&str>) -> String {
    let what = |expected: &str| -> Option<&'static str> {
        Some(match expected.trim().trim_end_matches('.') {
            "usize" | "u64" | "u32" | "u16" => "a whole number of 0 or more",
            "u8" => "a whole number from 0 to 255",
            "i64" | "i32" | "isize" => "a whole number",
            "f32" | "f64" => "a number",
            "a boolean" | "bool" => "true or false",
            "a string" | "string" => "text in quotes",
            "a sequence" | "an array" => "a list in [ ]",
            _ => return None,
        })
    };
    let at = key.map_or(String::new(), |k| format!("{k}: "));
    // "invalid value: integer `-7`, expected usize" / "invalid type: string \"fast\",
    // expected f32".
    for head in ["invalid value: ", "invalid type: "] {
        if let Some(rest) = message.strip_prefix(head)
            && let Some((got, expected)) = rest.rsplit_once(", expected ")
            && let Some(want) = what(expected)
        {
            let got = got
                .trim_start_matches("integer ")
                .trim_start_matches("floating point ")
                .trim_start_matches("string ")
                .trim_start_matches("boolean ")
                .trim_matches('`');
            return format!("{at}{got} is not {want}");
        }
    }
    format!("{at}{}", message.trim_end())
}

impl State {
    /// Reads a session file; relative sequence paths are taken relative to the session's folder.
    pub fn load(path: &Path) -> Result<State> {
        let text = crate::files::read_text(path, crate::files::SETTINGS_LIMIT)?;
        let mut state: State = toml::from_str(&text).map_err(|e| {
            let line = e
                .span()
                .map(|s| {
                    text.as_bytes()[..s.start.min(text.len())]
                        .iter()
                        .filter(|&&b| b == b'\n')
                        .count()
                        + 1
                })
                .unwrap_or(0);
            // The key the error is at, from the line itself (`frame = -7`).
            let key = text
                .lines()
                .nth(line.saturating_sub(1))
                .and_then(|l| l.split_once('='))
                .map(|(k, _)| k.trim().to_string())
                .filter(|k| !k.is_empty() && !k.starts_with('['));
            Error::Parse {
                path: path.to_path_buf(),
                line,
                message: plain_message(e.message(), key.as_deref()),
            }
        })?;
        if let SequenceSource::Path(p) = &state.sequence
            && p.is_relative()
        {
            let base = path.parent().unwrap_or(Path::new("."));
            state.sequence = SequenceSource::Path(base.join(p));
        }
        for (i, t) in state.trackers.iter().enumerate() {
            crate::tracker::Tracker::new(&t.spec).map_err(|e| Error::Parse {
                path: path.to_path_buf(),
                line: tracker_line(&text, i),
                message: format!("tracker {}: {e}", t.spec.label()),
            })?;
            if let InitSource::Quad(q) = &t.init
                && let Some(why) = crate::dataset::unusable_quad(q)
            {
                return Err(Error::Parse {
                    path: path.to_path_buf(),
                    line: tracker_line(&text, i),
                    message: format!("tracker {}: its initial corners: {why}", t.spec.label()),
                });
            }
        }
        state.validate().map_err(|(key, message)| Error::Parse {
            path: path.to_path_buf(),
            line: key_line(&text, &key),
            message,
        })?;
        Ok(state)
    }

    /// Checks every value against the ranges the widgets allow; the error names the key.
    fn validate(&self) -> std::result::Result<(), (std::borrow::Cow<'static, str>, String)> {
        let fps = self.playback_fps;
        if !(fps == 0.0 || PLAYBACK_FPS.contains(&fps)) {
            return Err((
                "playback_fps".into(),
                format!(
                    "playback_fps = {} must be 0 (as fast as possible) or in {}..={}",
                    crate::error::short_number(fps as f64, 2),
                    PLAYBACK_FPS.start(),
                    PLAYBACK_FPS.end()
                ),
            ));
        }
        let scale = self.view.label_scale;
        if !LABEL_SCALE.contains(&scale) {
            return Err((
                "label_scale".into(),
                format!(
                    "label_scale = {} must be in {}..={}",
                    crate::error::short_number(scale as f64, 2),
                    LABEL_SCALE.start(),
                    LABEL_SCALE.end()
                ),
            ));
        }
        let zoom = self.view.zoom;
        if !(zoom == 0.0 || ZOOM.contains(&zoom)) {
            return Err((
                "zoom".into(),
                format!(
                    "zoom = {} must be 0 (fit) or in {}..={}",
                    crate::error::short_number(zoom as f64, 2),
                    ZOOM.start(),
                    ZOOM.end()
                ),
            ));
        }
        if let Some(c) = self
            .view
            .center
            .iter()
            .find(|c| !c.is_finite() || c.abs() > MAX_CENTER)
        {
            return Err((
                "center".into(),
                format!(
                    "center coordinate {} is not an image position",
                    crate::error::short_number(*c as f64, 2)
                ),
            ));
        }
        if self.selected_tracker > 0 && self.selected_tracker >= self.trackers.len() {
            return Err((
                "selected_tracker".into(),
                format!(
                    "selected_tracker = {} but the session has {} tracker(s)",
                    self.selected_tracker,
                    self.trackers.len()
                ),
            ));
        }
        if let Some((a, b)) = self.view.ab
            && (a >= self.trackers.len() || b >= self.trackers.len())
        {
            return Err((
                "ab".into(),
                format!(
                    "ab = [{a}, {b}] but the session has {} tracker(s)",
                    self.trackers.len()
                ),
            ));
        }
        let l = &self.view.landscape;
        if !LANDSCAPE_RADIUS.contains(&l.radius) {
            return Err((
                "radius".into(),
                format!(
                    "landscape radius = {} must be in {}..={} px",
                    crate::error::short_number(l.radius, 2),
                    LANDSCAPE_RADIUS.start(),
                    LANDSCAPE_RADIUS.end()
                ),
            ));
        }
        // The largest warp has 8 parameters (the inspected tracker's may have fewer: the view
        // clamps to it).
        if let Some(k) = std::iter::once(l.x).chain(l.y).find(|&k| k >= 8) {
            return Err((
                if k == l.x { "x" } else { "y" }.into(),
                format!("landscape parameter {k} does not exist (0..=7)"),
            ));
        }
        crate::gt::ssm_key(&self.gt_ssm).map_err(|e| ("gt_ssm".into(), e.to_string()))?;
        let p = &self.patches;
        if !PATCH_COUNT.contains(&p.count) {
            return Err((
                "count".into(),
                format!(
                    "patches: count = {} must be in {}..={}",
                    p.count,
                    PATCH_COUNT.start(),
                    PATCH_COUNT.end()
                ),
            ));
        }
        for name in p.params.0.keys() {
            let key = name.clone().into();
            let mut one = MethodParams::default();
            one.0.insert(name.clone(), p.params.0[name]);
            crate::patches::PatchParams::from_values(&one).map_err(|e| (key, e.to_string()))?;
        }
        Ok(())
    }

    /// Writes the session atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text =
            toml::to_string_pretty(self).map_err(|e| Error::InvalidParameter(e.to_string()))?;
        crate::dataset::write_atomic(path, text.as_bytes())
    }
}

/// The line (1-based) of the first `key = ...` of a session file (1 if not found).
fn key_line(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|r| r.trim_start().starts_with('='))
        })
        .map_or(1, |n| n + 1)
}

/// The line (1-based) of the `i`-th `[[trackers]]` table of a session file (1 if not found).
fn tracker_line(text: &str, i: usize) -> usize {
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.trim() == "[[trackers]]")
        .nth(i)
        .map_or(1, |(n, _)| n + 1)
}

#[cfg(test)]
mod tests {
    use super::plain_message;

    /// A settings error reads as what the user wrote and what the setting takes.
    #[test]
    fn settings_errors_are_in_the_users_words() {
        assert_eq!(
            plain_message("invalid value: integer `-7`, expected usize", Some("frame")),
            "frame: -7 is not a whole number of 0 or more"
        );
        assert_eq!(
            plain_message(
                "invalid type: string \"fast\", expected f32",
                Some("playback_fps")
            ),
            "playback_fps: \"fast\" is not a number"
        );
        assert_eq!(
            plain_message("invalid type: integer `1`, expected a boolean", None),
            "1 is not true or false"
        );
        // Anything else as it was, at its key.
        assert_eq!(
            plain_message("unknown field `zoomx`", Some("zoomx")),
            "zoomx: unknown field `zoomx`"
        );
    }
}
