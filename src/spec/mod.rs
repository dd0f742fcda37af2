//! Trackers by name: what sessions, run files, the command line and the inspector store of a
//! tracker ([`TrackerSpec`]: a registration tracker's AM, SSM and SM names with its parameters, or
//! a whole tracker's name), and the registration tracker's parameters ([`TrackerParams`]).
//!
//! Specs are plain data: resolving their names against the registries and building the tracker
//! is the factory's ([`crate::tracker`]).

mod tracker_params;

pub use tracker_params::{
    AUTO_SIGMA_FIELDS, AUTO_SIGMA_GRADIENT, AUTO_SIGMA_SAMPLING, AUTO_SIZE_FIELDS, ChannelModel,
    Channels, GridLayout, LossPolicy, OFF_ON, ParamValue, SecondHypothesis, Spi, TRACKER_FLAGS,
    TRACKER_PARAMS, TrackerParams,
};

/// The tracker used when none is named, as `[sm, am, ssm]`: by `regtrack track`, `eval` and the
/// inspector's first tracker, Python's `Tracker()`; with [`default_params`]. Chosen on the tune
/// half of the held-out renders and reported on the other half (docs/robustness.md, "The default
/// tracker, measured on held-out renders").
pub const DEFAULT_TRACKER: [&str; 3] = ["fclk", "ssd", "homography"];

/// The default tracker's parameters: each parameter's default but a second hypothesis of the
/// other appearance model on the frames that fail the checks (FCLK-SSD holds fast motion and
/// blur best, FCLK-ZNCC the light that SSD drifts under) and `escalate` (a frame pays the
/// pyramid and the polish only when a first search at the finest level did not settle
/// confidently: 1.6 times the speed, the held-out half's SR@5 unchanged, 0.859; the tune
/// half's 0.848 against 0.853). The default tracker has them only when neither its SM nor its
/// AM is named: `--sm fclk --am ssd` is the plain combination.
pub fn default_params() -> TrackerParams {
    TrackerParams {
        second: SecondHypothesis::FclkZncc,
        escalate: true,
        ..TrackerParams::default()
    }
}

/// The default tracker as a person reads it: `fclk ssd homography, second=fclk_zncc` (its
/// methods, then the parameters it sets apart from their defaults).
pub fn default_tracker_text() -> String {
    let (own, plain) = (default_params(), TrackerParams::default());
    let mut text = DEFAULT_TRACKER.join(" ");
    for d in TRACKER_PARAMS {
        let v = own.value(d.name);
        if v != plain.value(d.name) {
            text.push_str(&format!(", {}={}", d.name, d.format(v)));
        }
    }
    text
}

/// The default tracker ([`DEFAULT_TRACKER`] with [`default_params`]) on the state space model
/// `ssm` (not looked up: the factory checks the names when it builds the tracker).
pub fn default_spec(ssm: &str) -> TrackerSpec {
    TrackerSpec::Registration(RegistrationSpec {
        sm: DEFAULT_TRACKER[0].into(),
        am: DEFAULT_TRACKER[1].into(),
        ssm: ssm.into(),
        params: default_params(),
        method: MethodParams::default(),
    })
}

use crate::params::MethodParams;
use serde::{Deserialize, Serialize};

/// A registration tracker by name: search method, appearance model, state space model, the
/// tracker's parameters and the search method's own.
#[derive(Clone, Debug, PartialEq)]
pub struct RegistrationSpec {
    pub sm: String,
    pub am: String,
    pub ssm: String,
    pub params: TrackerParams,
    /// The search method's and the appearance model's own parameters; unset ones take their
    /// defaults.
    pub method: MethodParams,
}

/// A whole tracker by name (one entry of [`crate::whole::REGISTRY`]) with its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct WholeSpec {
    pub tracker: String,
    pub method: MethodParams,
}

/// Any tracker, by name: a registration tracker (AM x SSM x SM) or a whole tracker. Sessions and
/// run files store it as a table: `sm`, `am`, `ssm`, `params`, `method` for the first, `tracker`
/// and `method` for the second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawSpec", into = "RawSpec")]
// A spec is made once per tracker, never per frame: its size does not matter, and every match on
// it reads the registration spec in place.
#[allow(clippy::large_enum_variant)]
pub enum TrackerSpec {
    Registration(RegistrationSpec),
    Whole(WholeSpec),
}

/// The stored form of a [`TrackerSpec`].
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tracker: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sm: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    am: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    ssm: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    params: Option<TrackerParams>,
    #[serde(default, skip_serializing_if = "MethodParams::is_empty")]
    method: MethodParams,
}

impl TryFrom<RawSpec> for TrackerSpec {
    type Error = String;
    fn try_from(r: RawSpec) -> std::result::Result<Self, String> {
        match (r.tracker, r.sm, r.am, r.ssm) {
            (Some(tracker), None, None, None) => {
                if r.params.is_some() {
                    return Err(format!(
                        "tracker '{tracker}' takes its parameters in `method`, not `params`"
                    ));
                }
                Ok(TrackerSpec::Whole(WholeSpec {
                    tracker,
                    method: r.method,
                }))
            }
            (None, Some(sm), Some(am), Some(ssm)) => {
                Ok(TrackerSpec::Registration(RegistrationSpec {
                    sm,
                    am,
                    ssm,
                    params: r.params.unwrap_or_default(),
                    method: r.method,
                }))
            }
            (Some(_), _, _, _) => {
                Err("a tracker is either `tracker = NAME` or `sm`, `am` and `ssm`, not both".into())
            }
            _ => Err("a registration tracker needs `sm`, `am` and `ssm`".into()),
        }
    }
}

impl From<TrackerSpec> for RawSpec {
    fn from(s: TrackerSpec) -> Self {
        match s {
            TrackerSpec::Registration(r) => RawSpec {
                sm: Some(r.sm),
                am: Some(r.am),
                ssm: Some(r.ssm),
                params: Some(r.params),
                method: r.method,
                ..Default::default()
            },
            TrackerSpec::Whole(w) => RawSpec {
                tracker: Some(w.tracker),
                method: w.method,
                ..Default::default()
            },
        }
    }
}

impl TrackerSpec {
    /// The registration tracker's names and parameters, if it is one.
    pub fn registration(&self) -> Option<&RegistrationSpec> {
        match self {
            TrackerSpec::Registration(r) => Some(r),
            TrackerSpec::Whole(_) => None,
        }
    }

    /// Mutable [`TrackerSpec::registration`].
    pub fn registration_mut(&mut self) -> Option<&mut RegistrationSpec> {
        match self {
            TrackerSpec::Registration(r) => Some(r),
            TrackerSpec::Whole(_) => None,
        }
    }

    /// The tracker's parameters (a registration tracker's; `None` for a whole tracker).
    pub fn params(&self) -> Option<&TrackerParams> {
        self.registration().map(|r| &r.params)
    }

    /// Mutable [`TrackerSpec::params`].
    pub fn params_mut(&mut self) -> Option<&mut TrackerParams> {
        self.registration_mut().map(|r| &mut r.params)
    }

    /// The method's own parameters.
    pub fn method_params(&self) -> &MethodParams {
        match self {
            TrackerSpec::Registration(r) => &r.method,
            TrackerSpec::Whole(w) => &w.method,
        }
    }

    /// Whether a tracker of this spec reads colour frames (`channels = rgb`).
    pub fn reads_colour(&self) -> bool {
        self.registration()
            .is_some_and(|r| r.params.channels == Channels::Rgb)
    }

    /// `(sm, am, ssm)` as summary columns (a whole tracker: its name, then empty).
    pub fn columns(&self) -> (String, String, String) {
        match self {
            TrackerSpec::Registration(r) => (r.sm.clone(), r.am.clone(), r.ssm.clone()),
            TrackerSpec::Whole(w) => (w.tracker.clone(), String::new(), String::new()),
        }
    }

    /// `sm_am_ssm` (or the whole tracker's name), as used in result file names; a composite's
    /// `cascade:a+b` becomes `cascade-a+b`; a colour tracker's (`channels = rgb`) ends in
    /// `_rgb` (`_rgb_pc` channel by channel), one on descriptor fields in `_df` (`_df_pc`).
    pub fn label(&self) -> String {
        match self {
            TrackerSpec::Registration(r) => {
                // A colour tracker's label says so (its runs beside the grey one's in a table).
                let colour = match (r.params.channels, r.params.channel_model) {
                    (Channels::Gray, _) => "",
                    (Channels::Rgb, ChannelModel::Stacked) => "_rgb",
                    (Channels::Rgb, ChannelModel::PerChannel) => "_rgb_pc",
                    (Channels::Df, ChannelModel::Stacked) => "_df",
                    (Channels::Df, ChannelModel::PerChannel) => "_df_pc",
                };
                format!("{}_{}_{}{colour}", r.sm.replace(':', "-"), r.am, r.ssm)
            }
            TrackerSpec::Whole(w) => w.tracker.clone(),
        }
    }
}
