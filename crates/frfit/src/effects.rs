//! The typed effect catalogue of the steps: every effect the diagnosis can add to a
//! model ([`FittedEffect`], one variant per [`Effect`]) with its parameters as fitted,
//! and the repairs of the first fit's modal structure ([`Repair`]). The summary, the
//! report, the CLI and the Python package carry these types; `summary.json` writes each
//! as its `effect` name and `params` object and reads it back from them.

use serde::{Deserialize, Serialize};
pub use validation::analysis::Effect;

/// The summary name of an effect (`missed_mode`, `delay`, ...): the `effect` of a step
/// of `summary.json`.
pub fn effect_name(e: Effect) -> &'static str {
    match e {
        Effect::MissedMode => "missed_mode",
        Effect::Delay => "delay",
        Effect::Hold => "hold",
        Effect::Feedthrough => "feedthrough",
        Effect::Stiffness => "stiffness",
        Effect::InputDynamics => "input_dynamics",
        Effect::OutputDynamics => "output_dynamics",
    }
}

/// Which entries a dynamics factor acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FactorSupport {
    /// Every entry (a common factor).
    All,
    /// The columns of some inputs.
    Inputs,
    /// The rows of some outputs.
    Outputs,
}

/// The refit-from-the-start marker of a delay step (`"refit": "from the start"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Refit {
    /// The model was refitted from the CMIF with the delay estimated from the data.
    #[serde(rename = "from the start")]
    FromTheStart,
}

/// A pole (or zero) of a dynamics factor: `f_hz = |p| / 2 pi`, and, once fitted, its
/// relative damping `-Re p / |p|` and the root itself (rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoleParams {
    /// `|p| / 2 pi`, Hz.
    pub f_hz: f64,
    /// Relative damping `-Re p / |p|` (1 for a real pole in the left half-plane).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeta: Option<f64>,
    /// Real part, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub re: Option<f64>,
    /// Imaginary part, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub im: Option<f64>,
}

/// An effect of the catalogue with its parameters as a refit estimated them: one variant
/// per effect ([`Effect`]). Serialised as the `effect` name and the `params` object of a
/// step of `summary.json` (adjacently tagged: `{"effect": "delay", "params": {...}}`), and
/// read back from them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "effect", content = "params", rename_all = "snake_case")]
pub enum FittedEffect {
    /// `missed_mode`: the added mode.
    MissedMode {
        /// Natural frequency, Hz.
        f_hz: f64,
        /// Relative damping.
        zeta: f64,
    },
    /// `delay`: the delay added and the model's total.
    Delay {
        /// Delay added to the model's, seconds.
        seconds: f64,
        /// The model's delay after the step, seconds.
        total_delay_s: f64,
        /// Set when the model was refitted from the start with the delay.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        refit: Option<Refit>,
    },
    /// `hold`: the exact zero-order hold.
    Hold {
        /// Sample rate, Hz.
        fs_hz: f64,
        /// The delay the model keeps beside the hold, seconds.
        remaining_delay_s: f64,
    },
    /// `feedthrough`: a constant matrix.
    Feedthrough {
        /// RMS of its entries.
        rms: f64,
        /// Whether it bypasses the delay and hold (crosstalk).
        bypasses_delay: bool,
    },
    /// `stiffness`: the suspension of the rigid body.
    Stiffness {
        /// Suspension frequency, Hz.
        f_hz: f64,
        /// Its relative damping.
        zeta: f64,
    },
    /// `input_dynamics`: a factor on one input column, or common to every entry.
    InputDynamics {
        /// The inputs, 1-based (every input for the common factor).
        inputs: Vec<usize>,
        /// The factor ([`FactorSupport::All`] or [`FactorSupport::Inputs`]).
        #[serde(flatten)]
        factor: FactorParams,
    },
    /// `output_dynamics`: a factor on one output row, or common to every entry.
    OutputDynamics {
        /// The outputs, 1-based (every output for the common factor).
        outputs: Vec<usize>,
        /// The factor ([`FactorSupport::All`] or [`FactorSupport::Outputs`]).
        #[serde(flatten)]
        factor: FactorParams,
    },
}

/// A dynamics factor as fitted: where it acts, its order, poles and zeros (the
/// `params` of an `input_dynamics` or `output_dynamics` step beside its inputs or
/// outputs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FactorParams {
    /// [`FactorSupport::All`] for a factor common to every entry, else the side it is on.
    pub support: FactorSupport,
    /// Order of the factor's denominator (1 or 2).
    pub order: usize,
    /// Its poles.
    pub poles: Vec<PoleParams>,
    /// Its zeros (none for an all-pole factor).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub zeros: Vec<PoleParams>,
    /// With zeros: whether one lies in the closed right half-plane (physically
    /// possible, e.g. a non-collocated mount, but worth a look).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub non_minimum_phase: Option<bool>,
}

/// The `params` object of an adjacently tagged catalogue entry, for display.
fn params_of(entry: &impl Serialize) -> serde_json::Value {
    // plain numbers, booleans, strings and lists: serialising cannot fail
    serde_json::to_value(entry)
        .map(|mut v| v["params"].take())
        .unwrap_or(serde_json::Value::Null)
}

impl FittedEffect {
    /// The catalogue effect.
    pub fn effect(&self) -> Effect {
        match self {
            FittedEffect::MissedMode { .. } => Effect::MissedMode,
            FittedEffect::Delay { .. } => Effect::Delay,
            FittedEffect::Hold { .. } => Effect::Hold,
            FittedEffect::Feedthrough { .. } => Effect::Feedthrough,
            FittedEffect::Stiffness { .. } => Effect::Stiffness,
            FittedEffect::InputDynamics { .. } => Effect::InputDynamics,
            FittedEffect::OutputDynamics { .. } => Effect::OutputDynamics,
        }
    }

    /// The summary name of the effect (`missed_mode`, `delay`, ...).
    pub fn name(&self) -> &'static str {
        effect_name(self.effect())
    }

    /// The `params` object of `summary.json`, for display.
    pub fn params_json(&self) -> serde_json::Value {
        params_of(self)
    }
}

/// A repair of the first fit's modal structure ([`additive_riv::split`]): part of the
/// first fit, not a step of the loop. Serialised as the `effect` name and the `params`
/// object of `summary.json`'s `initial.repairs`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "effect", content = "params", rename_all = "snake_case")]
pub enum Repair {
    /// A mode beyond a band edge.
    OutOfBandMode {
        /// Natural frequency, Hz.
        f_hz: f64,
        /// Relative damping.
        zeta: f64,
        /// `upper` or `lower`: the edge it lies beyond.
        edge: String,
        /// The cost of a feedthrough in its place over its own (`None` when the model
        /// has a feedthrough already).
        feedthrough_cost_ratio: Option<f64>,
    },
    /// A mode split into a close pair.
    ClosePair {
        /// Frequency of the mode before the split, Hz.
        from_hz: f64,
        /// The two modes after settling.
        modes: [ModeParams; 2],
    },
}

/// A mode's natural frequency and relative damping.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModeParams {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping.
    pub zeta: f64,
}

impl Repair {
    /// The summary name (`out_of_band_mode`, `close_pair`).
    pub fn name(&self) -> &'static str {
        match self {
            Repair::OutOfBandMode { .. } => "out_of_band_mode",
            Repair::ClosePair { .. } => "close_pair",
        }
    }

    /// The `params` object of `summary.json`, for display.
    pub fn params_json(&self) -> serde_json::Value {
        params_of(self)
    }
}
