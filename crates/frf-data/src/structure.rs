//! A refiner's changes to the model's structure, typed: what a refinement added,
//! dropped, freed or held, whether it took the change, and the weighted cost
//! `sum w |G - P|^2` before and after (issue 42: a change to the model is a step the
//! summary and the report can show, not only a line of the messages, which say the same
//! in words). The ML refiner (`ml_refine::MlReport::structure_steps`) and the refined-IV
//! structure adaptation (`additive_riv::structure::AdaptReport::steps`) both report
//! them; the summary carries the first fit's as `initial.structure_steps`.

use serde::{Deserialize, Serialize};

/// Why a mode was tested again at the final structure ([`StructureChange::ModeDropped`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeTest {
    /// The refinement added it ([`StructureChange::ModesAdded`]).
    Added,
    /// It shares its resonance with another mode ([`crate::twins`]).
    Twin,
    /// Its half-power bandwidth is narrower than the line spacing around it.
    Narrow,
}

/// One change of the structure. Serialised adjacently tagged, as the catalogue's steps
/// are: `{"change": "modes_added", "params": {...}}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "change", content = "params", rename_all = "snake_case")]
pub enum StructureChange {
    /// Modes added at the residual's peaks, refined together (their start frequencies,
    /// Hz; damping 0.01 at the start).
    ModesAdded {
        /// Start frequencies, Hz.
        start_hz: Vec<f64>,
    },
    /// A mode dropped after it was tested again at the final structure.
    ModeDropped {
        /// Its natural frequency at the optimum it was tested at, Hz.
        f_hz: f64,
        /// Its relative damping there.
        zeta: f64,
        /// Why it was tested.
        tested_as: ModeTest,
    },
    /// The integrators `1/s^(keep+1) .. 1/s^of` dropped (the rigid body chosen again).
    IntegratorsDropped {
        /// Integrators left.
        keep: usize,
        /// Integrators before.
        of: usize,
    },
    /// The delay, held while the start was far above the noise level, freed.
    DelayFreed {
        /// The value it was held at, seconds.
        held_s: f64,
    },
    /// Poles the data do not support (crossed into the right half-plane, ran off beyond
    /// the band, not determined, a real pole that explains too little) dropped; the
    /// refinement continued from that optimum.
    PolesDropped {
        /// The poles, in words (frequency or value).
        poles: Vec<String>,
        /// Why, in words.
        reason: String,
    },
    /// The delay, which the data do not determine, held where it was.
    DelayHeld {
        /// The value it was held at, seconds.
        delay_s: f64,
    },
}

impl StructureChange {
    /// The change's name, as in the files (`modes_added`, `mode_dropped`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            StructureChange::ModesAdded { .. } => "modes_added",
            StructureChange::ModeDropped { .. } => "mode_dropped",
            StructureChange::IntegratorsDropped { .. } => "integrators_dropped",
            StructureChange::DelayFreed { .. } => "delay_freed",
            StructureChange::PolesDropped { .. } => "poles_dropped",
            StructureChange::DelayHeld { .. } => "delay_held",
        }
    }

    /// What the change did, in a few words with its numbers.
    pub fn describe(&self) -> String {
        match self {
            StructureChange::ModesAdded { start_hz } => format!(
                "{} at {} Hz",
                if start_hz.len() == 1 { "mode" } else { "modes" },
                start_hz
                    .iter()
                    .map(|f| format!("{f:.2}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            StructureChange::ModeDropped {
                f_hz,
                zeta,
                tested_as,
            } => format!(
                "{} mode at {f_hz:.2} Hz (zeta {zeta:.2e})",
                match tested_as {
                    ModeTest::Added => "added",
                    ModeTest::Twin => "twin",
                    ModeTest::Narrow => "narrow",
                }
            ),
            StructureChange::IntegratorsDropped { keep, of } => {
                format!("integrators 1/s^{}..1/s^{of}", keep + 1)
            }
            StructureChange::DelayFreed { held_s } => {
                format!("delay held at {:.4} us", held_s * 1e6)
            }
            StructureChange::PolesDropped { poles, reason } => {
                format!("{} ({reason})", poles.join(", "))
            }
            StructureChange::DelayHeld { delay_s } => {
                format!("delay at {:.4} us", delay_s * 1e6)
            }
        }
    }
}

/// One structure step of a refinement: the change, whether it was taken, and its test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StructureStep {
    /// The change and its parameters.
    #[serde(flatten)]
    pub change: StructureChange,
    /// Whether the model took the change.
    pub accepted: bool,
    /// The weighted cost at the optimum the change was tested from.
    pub cost_before: f64,
    /// The cost of the trial structure: refined when a refinement was run, the
    /// linearised or held-poles cost of a score test otherwise; `None` without a trial
    /// (a change forced by poles the data do not support).
    pub cost_after: Option<f64>,
    /// The F statistic of the test (the cost the larger structure explains per pair of
    /// parameters over its noise scale), when one was made.
    pub f_statistic: Option<f64>,
    /// The critical value or floor the F statistic was held against.
    pub f_critical: Option<f64>,
    /// The weighted cost on lines the structures were not fitted to, without and with
    /// the change, when that test was made ([`HeldOutCost`]); absent in files written
    /// before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOutCost>,
}

impl StructureStep {
    /// A change the refinement made without a test (poles the data do not support
    /// dropped, a delay they do not determine held), from an optimum of cost
    /// `cost_before`.
    pub fn forced(change: StructureChange, cost_before: f64) -> Self {
        Self::untested(change, true, cost_before, None)
    }

    /// A change judged by other checks than an F test of its own (the refined-IV
    /// structure adaptation's per-mode tests): taken or not (`accepted`), the cost from
    /// `cost_before` to `cost_after` when a trial was made.
    pub fn untested(
        change: StructureChange,
        accepted: bool,
        cost_before: f64,
        cost_after: Option<f64>,
    ) -> Self {
        Self {
            change,
            accepted,
            cost_before,
            cost_after,
            f_statistic: None,
            f_critical: None,
            held_out: None,
        }
    }

    /// A change tested by a trial structure: taken or not (`accepted`), the cost from
    /// `cost_before` to the trial's `cost_after`, and the F statistic `f` against
    /// `f_critical`.
    pub fn tested(
        change: StructureChange,
        accepted: bool,
        (cost_before, cost_after): (f64, f64),
        (f, f_critical): (f64, f64),
    ) -> Self {
        Self {
            change,
            accepted,
            cost_before,
            cost_after: Some(cost_after),
            f_statistic: Some(f),
            f_critical: Some(f_critical),
            held_out: None,
        }
    }
}

/// The held-out test of a structure step: the lines split into the even and the odd
/// ones, the structure without and with the change each refined on one half and its
/// weighted cost taken on the other, the halves swapped, and the two costs summed. A
/// change the data hold lowers the error on lines it was not fitted to; parameters that
/// only follow the noise of the fitted lines raise it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeldOutCost {
    /// Without the change.
    pub before: f64,
    /// With it.
    pub after: f64,
    /// The held-out F statistic ([`HeldOutCost::f_of`]), when it was formed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f_statistic: Option<f64>,
}

impl HeldOutCost {
    /// Whether the change lowers the error on the held-out lines.
    pub fn lowers(&self) -> bool {
        self.after < self.before
    }

    /// The held-out costs summed over the folds: each fold's cost of the structure
    /// without the change (`false`) or with it (`true`); `None` when a fold could not be
    /// costed (the test is then not made). No F statistic yet.
    pub fn from_folds(folds: impl IntoIterator<Item = Option<(bool, f64)>>) -> Option<Self> {
        let mut h = Self {
            before: 0.0,
            after: 0.0,
            f_statistic: None,
        };
        for fold in folds {
            let (with_change, cost) = fold?;
            if with_change {
                h.after += cost;
            } else {
                h.before += cost;
            }
        }
        Some(h)
    }

    /// The F statistic of the held-out costs: the decrease per pair of the
    /// `added_params` real parameters the change adds, over the noise scale of the
    /// held-out residual with the change (`after` over the `observations` complex
    /// observations held out, each once). A disturbance that neither structure predicts
    /// (a spike on one line) stays in that scale, so a change that lowers the held-out
    /// cost by about what chance gives is not significant; a mode the data hold lowers it
    /// by far more.
    pub fn f_of(before: f64, after: f64, added_params: usize, observations: f64) -> f64 {
        ((before - after) / (added_params.max(1) as f64 / 2.0)) / (after / observations)
    }
}
