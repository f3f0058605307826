//! What a trial found: the effect's parameters as fitted, serialised as the `params` of
//! a step of `summary.json` (field names of the README's schema section).

use super::candidate::{Candidate, FactorStart};
use super::refit::new_modes;
use additive_riv::{AdditiveModel, SubmodelKind};
use serde::Serialize;
use std::f64::consts::TAU;
use validation::analysis::Effect;

/// The refit-from-the-start marker of a delay step (`"refit": "from the start"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Refit {
    /// The model was refitted from the CMIF with the delay estimated from the data.
    #[serde(rename = "from the start")]
    FromTheStart,
}

/// A pole (or zero) of a dynamics factor: `f_hz = |p| / 2 pi`, and, once fitted, its
/// relative damping `-Re p / |p|` and the root itself (rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoleParams {
    /// `|p| / 2 pi`, Hz.
    pub f_hz: f64,
    /// Relative damping `-Re p / |p|` (1 for a real pole in the left half-plane).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zeta: Option<f64>,
    /// Real part, rad/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub re: Option<f64>,
    /// Imaginary part, rad/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub im: Option<f64>,
}

/// The parameters of a tested effect as its refit estimated them: one variant per
/// effect of the catalogue. Serialised without a tag (the step's `effect` names it).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
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
        #[serde(skip_serializing_if = "Option::is_none")]
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
        /// `"all"` for a factor common to every entry, `"inputs"` otherwise.
        support: &'static str,
        /// Order of the factor's denominator (1 or 2).
        order: usize,
        /// Its poles.
        poles: Vec<PoleParams>,
        /// Its zeros (none for an all-pole factor).
        #[serde(skip_serializing_if = "Vec::is_empty")]
        zeros: Vec<PoleParams>,
        /// With zeros: whether one lies in the closed right half-plane (physically
        /// possible, e.g. a non-collocated mount, but worth a look).
        #[serde(skip_serializing_if = "Option::is_none")]
        non_minimum_phase: Option<bool>,
    },
    /// `output_dynamics`: a factor on one output row, or common to every entry.
    OutputDynamics {
        /// The outputs, 1-based (every output for the common factor).
        outputs: Vec<usize>,
        /// `"all"` for a factor common to every entry, `"outputs"` otherwise.
        support: &'static str,
        /// Order of the factor's denominator (1 or 2).
        order: usize,
        /// Its poles.
        poles: Vec<PoleParams>,
        /// Its zeros (none for an all-pole factor).
        #[serde(skip_serializing_if = "Vec::is_empty")]
        zeros: Vec<PoleParams>,
        /// With zeros: whether one lies in the closed right half-plane (physically
        /// possible, e.g. a non-collocated mount, but worth a look).
        #[serde(skip_serializing_if = "Option::is_none")]
        non_minimum_phase: Option<bool>,
    },
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

    /// The `params` object of `summary.json`.
    pub fn to_json(&self) -> serde_json::Value {
        // plain numbers, booleans, strings and lists: serialising cannot fail
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }

    /// The delay of `after` as a step beyond `before`.
    pub fn delay(before: &AdditiveModel, after: &AdditiveModel, refit: Option<Refit>) -> Self {
        FittedEffect::Delay {
            seconds: after.factor.delay_s - before.factor.delay_s,
            total_delay_s: after.factor.delay_s,
            refit,
        }
    }

    /// The parameters of `candidate` as fitted in `m`, the refit of `before` with it;
    /// a parameter the refit does not show is reported at its start.
    pub fn of_refit(candidate: &Candidate, before: &AdditiveModel, m: &AdditiveModel) -> Self {
        match candidate {
            Candidate::MissedMode { f_hz: f0, zeta, .. } => {
                // the mode of `m` that `before` does not have: the one nearest the start
                let new = new_modes(before, m)
                    .into_iter()
                    .min_by(|a, b| (a.0 - f0).abs().total_cmp(&(b.0 - f0).abs()));
                let (f_hz, zeta) = new.unwrap_or((*f0, *zeta));
                FittedEffect::MissedMode { f_hz, zeta }
            }
            Candidate::Delay { .. } => Self::delay(before, m, None),
            Candidate::Hold { fs_hz } => FittedEffect::Hold {
                fs_hz: *fs_hz,
                remaining_delay_s: m.factor.delay_s,
            },
            Candidate::Feedthrough { .. } => {
                let rms = m
                    .to_modal_model()
                    .map(|mm| {
                        let mut s = 0.0;
                        for j in 0..mm.nu {
                            for i in 0..mm.ny {
                                s += mm.feedthrough[(i, j)].powi(2);
                            }
                        }
                        (s / (mm.ny * mm.nu) as f64).sqrt()
                    })
                    .unwrap_or(f64::NAN);
                let bypasses_delay = m
                    .submodels
                    .iter()
                    .any(|s| s.kind == SubmodelKind::Feedthrough && s.bypass_factor);
                FittedEffect::Feedthrough {
                    rms,
                    bypasses_delay,
                }
            }
            Candidate::Stiffness { f_hz, zeta, .. } => {
                let s = m
                    .submodels
                    .iter()
                    .find(|s| s.kind == SubmodelKind::Suspension);
                let (f_hz, zeta) = match s.and_then(|s| m.upper_pole(s)) {
                    Some(p) => (p.norm() / TAU, -p.re / p.norm()),
                    None => (*f_hz, *zeta),
                };
                FittedEffect::Stiffness { f_hz, zeta }
            }
            Candidate::InputDynamics { inputs, start } => {
                let (poles, zeros, non_minimum_phase) = fitted_roots(m, start);
                FittedEffect::InputDynamics {
                    inputs: inputs.clone(),
                    support: if candidate.is_common_factor() {
                        "all"
                    } else {
                        "inputs"
                    },
                    order: start.order,
                    poles,
                    zeros,
                    non_minimum_phase,
                }
            }
            Candidate::OutputDynamics { outputs, start } => {
                let (poles, zeros, non_minimum_phase) = fitted_roots(m, start);
                FittedEffect::OutputDynamics {
                    outputs: outputs.clone(),
                    support: if candidate.is_common_factor() {
                        "all"
                    } else {
                        "outputs"
                    },
                    order: start.order,
                    poles,
                    zeros,
                    non_minimum_phase,
                }
            }
        }
    }
}

/// A root (rad/s) as reported.
fn root_params(p: &realize::C64) -> PoleParams {
    let f = p.norm();
    PoleParams {
        f_hz: f / TAU,
        zeta: (f > 0.0).then(|| -p.re / f),
        re: Some(p.re),
        im: Some(p.im),
    }
}

/// The poles and zeros of the newest dynamics factor of `m` (the candidate's; one of
/// each complex pair, the upper; lowest frequency first), or the starting pole when it
/// has none; with zeros, whether one is in the closed right half-plane.
fn fitted_roots(
    m: &AdditiveModel,
    start: &FactorStart,
) -> (Vec<PoleParams>, Vec<PoleParams>, Option<bool>) {
    // lowest frequency first: the factor's corner, then any far pole
    let upper = |v: Vec<realize::C64>| -> Vec<PoleParams> {
        let mut r: Vec<PoleParams> = v.iter().filter(|p| p.im >= 0.0).map(root_params).collect();
        r.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
        r
    };
    match m.dynamics.last() {
        Some(d) => (
            upper(d.poles()),
            upper(d.zeros()),
            (!d.num.is_empty()).then(|| d.is_non_minimum_phase()),
        ),
        None => (
            vec![PoleParams {
                f_hz: start.f_hz,
                zeta: (start.order == 2).then_some(start.zeta),
                re: None,
                im: None,
            }],
            Vec::new(),
            None,
        ),
    }
}
