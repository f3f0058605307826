//! `summary.json`: the machine-readable result of a fit or a diagnosis, with the same
//! content as `report.md` (schema documented in the README).
//!
//! Schema `frfit-summary`, version 1:
//!
//! ```text
//! { "schema": "frfit-summary", "version": 1,
//!   "command": "diagnose" | "fit",
//!   "data": {path, ny, nu, lines, band_hz: [lo, hi], units, noise_source},
//!   "initial": {modes: [{f_hz, zeta}], cmif_peaks: [{f_hz, sv_index, prominence}],
//!               errors: {median_rel, p95_rel, residual_to_noise},
//!               repairs: [{effect: "out_of_band_mode" | "close_pair", params, f_statistic}]},
//!   "steps": [{effect, accepted, evidence, params, uncertainty, f_statistic, f_critical,
//!              added_params, before: {..errors}, after: {..errors}, figure}],
//!   "verdict": "noise_limited" | "nonlinear_distortion" | "unexplained_residual" | "not_analysed",
//!   "verdict_evidence": "...",
//!   "distortion": {order, floor_to_variance, floor_to_variance_lower, min_ratio, exceeds,
//!                  variance_median_rel, floor_median_rel, residual_to_variance,
//!                  residual_to_floor, loop_against_floor},
//!   "final_model": {modes: [{f_hz, zeta}], order, delay_s, hold, rigid_body_integrators,
//!                   feedthrough, dynamics: [..], iterations, convergence},
//!   "final": {median_rel, p95_rel, residual_to_noise},
//!   "data_noise_median_rel": ..., "timings": [{stage, seconds}],
//!   "uncertainty": {method, noise, cost_ratio, expected_ratio, p_value, covariance_scale,
//!                   modes: [{f_hz, f_hz_std, zeta, zeta_std}], delay_s, delay_s_std} }
//! ```
//!
//! `uncertainty` is present after `frfit fit --refine ml` (the standard deviations of the
//! maximum-likelihood refinement at its optimum); absent otherwise.
//!
//! ```text
//! ```

pub use crate::effects::effect_name;
use crate::effects::{FittedEffect, Repair};
use serde::{Deserialize, Serialize};

/// The schema tag.
pub const SCHEMA: &str = "frfit-summary";
/// The schema version.
pub const VERSION: u32 = 1;

/// Error of a model against the data.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Median over lines and entries of `|G - P| / |G|`.
    pub median_rel: f64,
    /// 95th percentile of `|G - P| / |G|`.
    pub p95_rel: f64,
    /// `sqrt(mean |G - P|^2 / var)`: 1 at the noise level.
    pub residual_to_noise: f64,
}

/// Mode frequency and damping.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModeSummary {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping.
    pub zeta: f64,
}

/// One CMIF peak.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PeakSummary {
    /// Frequency, Hz.
    pub f_hz: f64,
    /// Which singular value (0 = largest).
    pub sv_index: usize,
    /// Prominence, dB.
    pub prominence: f64,
}

/// The data the run worked on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DataSummary {
    /// The file.
    pub path: String,
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// Lines in the band.
    pub lines: usize,
    /// Band fitted, Hz.
    pub band_hz: [f64; 2],
    /// Units, when known.
    pub units: Option<String>,
    /// `measured` (from `_var`) or how it was estimated.
    pub noise_source: String,
    /// The FRF type the model was fitted as (`displacement`, `velocity`, `accelerance`).
    pub frf_type: String,
}

/// The model before the diagnosis loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InitialSummary {
    /// Modes of the first model.
    pub modes: Vec<ModeSummary>,
    /// The CMIF peaks it started from.
    pub cmif_peaks: Vec<PeakSummary>,
    /// Its error against the data.
    pub errors: ErrorStats,
    /// Declared (known) effects: hold, delay, from the command line or the file.
    pub declared: Vec<String>,
    /// When a restart replaced the estimator chain's first fit (a better first fit, not
    /// an effect): where it started and what it replaced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restart: Option<RestartSummary>,
    /// Repairs of the first fit's modal structure after the refinement: `out_of_band_mode`
    /// (a mode beyond a band edge) and `close_pair` (a mode split into two), with their
    /// fitted parameters. Part of the first fit, not steps of the loop: they are the
    /// plant's modes.
    #[serde(default)]
    pub repairs: Vec<RepairSummary>,
    /// The changes of the first fit's structure that its refiners tested, taken or not,
    /// in order: the refined-IV structure adaptation's (`link`: `riv`) and the ML
    /// refinement's (`ml`), each with its `change` (`modes_added`, `mode_dropped`,
    /// `integrators_dropped`, `delay_freed`, `poles_dropped` or `delay_held`) and
    /// `params`, `accepted`, the weighted cost before and after, and the F statistic with
    /// its critical value where a test was made. The modes a refiner added at residual
    /// peaks and those it dropped are steps a user can see, not only lines of the
    /// messages. Empty when no refiner changed the structure.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub structure_steps: Vec<StructureStepSummary>,
    /// `frfit diagnose` only: the diagnosis from its own first fit ended worse on the
    /// data than the model `frfit fit` gives, so it ran again from that model (the
    /// initial model above is then `fit`'s); what the replaced diagnosis ended with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_fit: Option<FromFitSummary>,
}

/// A restart that replaced the chain's first fit because it ended significantly better.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RestartSummary {
    /// What the restart started from.
    pub from: String,
    /// Modes of the replaced first fit.
    pub replaced_modes: usize,
    /// Errors of the replaced first fit.
    pub replaced_errors: ErrorStats,
    /// F statistic of the restart's cost decrease against the replaced fit.
    pub f_statistic: f64,
    /// Its critical value.
    pub f_critical: f64,
}

/// A diagnosis run again from `frfit fit`'s model (see [`InitialSummary::from_fit`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FromFitSummary {
    /// Why the first diagnosis was replaced: the statistics that ended worse than
    /// `fit`'s model.
    pub reason: String,
    /// The errors of `fit`'s model, the start of the diagnosis reported.
    pub fit_errors: ErrorStats,
    /// The first fit of the replaced diagnosis: its modes and errors.
    pub replaced_initial_modes: usize,
    /// Its errors.
    pub replaced_initial_errors: ErrorStats,
    /// The final model of the replaced diagnosis: its modes.
    pub replaced_final_modes: usize,
    /// Its errors.
    pub replaced_final_errors: ErrorStats,
    /// The effects the replaced diagnosis accepted, in order.
    pub replaced_accepted: Vec<String>,
    /// Whether the diagnosis ran from `fit`'s model with its feedthrough taken out (and
    /// the rest refitted): a feedthrough the diagnosis's own first fit did not hold is a
    /// step of the loop, with its errors before and after, not a part inherited from
    /// `fit`'s second start. The initial model is then that model.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub feedthrough_taken_out: bool,
}

/// One repair of the first fit's modal structure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RepairSummary {
    /// The repair and its parameters (`effect`: `out_of_band_mode` or `close_pair`,
    /// `params`: `f_hz`, `zeta`, `edge`, `feedthrough_cost_ratio` for an out-of-band
    /// mode; `from_hz` and `modes` (`[{f_hz, zeta}, {f_hz, zeta}]`) for a close pair).
    #[serde(flatten)]
    pub repair: Repair,
    /// F statistic of the added mode's parameters.
    pub f_statistic: f64,
    /// The fit's weighted cost `sum w |E|^2` before and after the repair (the added mode
    /// settled, before the first fit's final refinement); absent in files written
    /// before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostChange>,
}

/// One structure step of a refiner of the first fit ([`InitialSummary::structure_steps`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StructureStepSummary {
    /// The link of the chain that made it (`riv` or `ml`).
    pub link: String,
    /// The step.
    #[serde(flatten)]
    pub step: frf_data::structure::StructureStep,
}

/// A weighted cost before and after a change of the model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CostChange {
    /// Before the change.
    pub before: f64,
    /// After it.
    pub after: f64,
}

/// One step of the diagnosis loop: a candidate effect, tested.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepSummary {
    /// The effect and its parameters as fitted (`effect`: `missed_mode`, `delay`,
    /// `hold`, `feedthrough`, `stiffness`, `input_dynamics` or `output_dynamics`;
    /// `params`: `f_hz`, `zeta`; `seconds`; `fs_hz`; `inputs`, `poles`...).
    #[serde(flatten)]
    pub fitted: FittedEffect,
    /// Whether the effect was added to the model.
    pub accepted: bool,
    /// Why the effect was a candidate (what the residual showed), in words with numbers.
    pub evidence: String,
    /// Standard deviations of the parameters where available, by parameter name.
    pub uncertainty: Option<std::collections::BTreeMap<String, f64>>,
    /// F statistic of the refit (the cost explained per added parameter over the noise
    /// scale).
    pub f_statistic: f64,
    /// The critical value it had to pass.
    pub f_critical: f64,
    /// Real parameters the effect adds.
    pub added_params: usize,
    /// Error before the step.
    pub before: ErrorStats,
    /// Error after the refit with the effect (whether or not it was accepted).
    pub after: ErrorStats,
    /// SVG of the residual before and after, relative to the report directory.
    pub figure: Option<String>,
    /// For an accepted dynamics factor that a later accepted step took out of the model
    /// (a factor accepted for want of the right effect, left redundant once that effect
    /// was in, or replaced by its rational twin): that step's number (1-based).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub superseded_by: Option<usize>,
    /// The step's check on data it was not fitted to: the weighted cost on interleaved
    /// held-out lines without and with it (the round's best trial only; a step that
    /// raises it is not accepted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<frf_data::structure::HeldOutCost>,
}

impl StepSummary {
    /// The effect's summary name (`missed_mode`, `delay`, ...).
    pub fn effect(&self) -> &'static str {
        self.fitted.name()
    }
}

/// The final model, briefly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FinalModelSummary {
    /// Modes.
    pub modes: Vec<ModeSummary>,
    /// Minimal real state dimension.
    pub order: usize,
    /// Delay of the known factor, seconds.
    pub delay_s: f64,
    /// Hold: `none`, `zoh:FS`, `sinc:FS`.
    pub hold: String,
    /// Integrators of the rigid body (0 when none).
    pub rigid_body_integrators: usize,
    /// Whether a feedthrough is present.
    pub feedthrough: bool,
    /// Dynamics factors (`input 3: pole -1234 rad/s`, ...).
    pub dynamics: Vec<String>,
    /// Iterations of Algorithm 1: of the fit, or for `diagnose` of the first fit and
    /// the final refinement together.
    pub iterations: usize,
    /// How the last refinement stopped.
    pub convergence: String,
}

/// Wall-clock time of a stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTime {
    /// Stage.
    pub stage: String,
    /// Seconds.
    pub seconds: f64,
}

/// The verdict on the final residual of a run, written in `summary.json` as its
/// snake-case name. It compares with those names (`verdict == "noise_limited"`) and
/// prints as them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualVerdict {
    /// The residual is at the noise level.
    NoiseLimited,
    /// The residual exceeds the measured variance but matches the data's line-to-line
    /// floor, or sits at a total variance whose nonlinear part is significant: no
    /// linear model gets closer.
    NonlinearDistortion,
    /// The residual exceeds the noise and no tested effect explains it.
    UnexplainedResidual,
    /// The final residual analysis was not run (`frfit fit` without `--report`).
    NotAnalysed,
}

impl ResidualVerdict {
    /// The name in `summary.json` (`noise_limited`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::NoiseLimited => "noise_limited",
            Self::NonlinearDistortion => "nonlinear_distortion",
            Self::UnexplainedResidual => "unexplained_residual",
            Self::NotAnalysed => "not_analysed",
        }
    }

    /// The words for a report (`noise-limited`, ...).
    pub fn text(self) -> &'static str {
        match self {
            Self::NoiseLimited => "noise-limited",
            Self::NonlinearDistortion => "nonlinear distortion",
            Self::UnexplainedResidual => "unexplained residual",
            Self::NotAnalysed => "not analysed",
        }
    }
}

impl std::fmt::Display for ResidualVerdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl PartialEq<str> for ResidualVerdict {
    fn eq(&self, other: &str) -> bool {
        self.name() == other
    }
}

impl PartialEq<&str> for ResidualVerdict {
    fn eq(&self, other: &&str) -> bool {
        self.name() == *other
    }
}

/// The whole summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `frfit-summary`.
    pub schema: String,
    /// 1.
    pub version: u32,
    /// `fit` or `diagnose`.
    pub command: String,
    /// The data.
    pub data: DataSummary,
    /// The first model.
    pub initial: InitialSummary,
    /// The diagnosis steps, in order.
    pub steps: Vec<StepSummary>,
    /// The verdict on the final residual (`noise_limited`, `nonlinear_distortion`,
    /// `unexplained_residual`, or `not_analysed` in the file).
    pub verdict: ResidualVerdict,
    /// The evidence for the verdict.
    pub verdict_evidence: String,
    /// The final model.
    pub final_model: FinalModelSummary,
    /// Its error against the data.
    #[serde(rename = "final")]
    pub final_errors: ErrorStats,
    /// The data's own noise level: median over lines and entries of `sqrt(var) / |G|`
    /// (`None` without a variance).
    pub data_noise_median_rel: Option<f64>,
    /// Time per stage.
    pub timings: Vec<StageTime>,
    /// The estimator chain that made the first model (`["cmif", "riv"]`); empty when the
    /// run started from a given model. Each link's report is in the model file's
    /// `provenance.links`.
    #[serde(default)]
    pub chain: Vec<String>,
    /// Every chain tried when `--init` named several initialisers (`auto`), with its
    /// cost, parameter count and final prediction error, and which was kept; empty
    /// otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub chain_runs: Vec<crate::chain::ChainRun>,
    /// Standard deviations of the final model's parameters, when the refiner computed
    /// them (`--refine ml` in `frfit fit`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<UncertaintySummary>,
    /// The data's model-free line-to-line floor against the measured variance and the
    /// final residual against both (present when the data carry a measured variance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<DistortionSummary>,
}

/// The evidence for or against nonlinear distortion: the data's line-to-line floor
/// (`validation::distortion`, model-free) against their measured variance, and the final
/// residual against both. All ratios are of variances (energies), robust (medians over
/// lines and entries of the per-line ratios, divided by `ln 2`): 1 when the measured
/// variance explains the scatter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DistortionSummary {
    /// Order of the differences across adjacent lines.
    pub order: usize,
    /// The line-to-line floor over the measured variance.
    pub floor_to_variance: f64,
    /// Its lower confidence bound.
    pub floor_to_variance_lower: f64,
    /// The floor significantly exceeds the variance at `floor_to_variance >= min_ratio`
    /// (and a lower bound above 1).
    pub min_ratio: f64,
    /// Whether it does.
    pub exceeds: bool,
    /// Median over lines and entries of `sqrt(var) / |G|`.
    pub variance_median_rel: f64,
    /// The floor as a relative level: `sqrt(floor_to_variance)` times the above.
    pub floor_median_rel: f64,
    /// The final residual over the measured variance (median of `|G - P|^2 / var` over
    /// `ln 2`).
    pub residual_to_variance: f64,
    /// The final residual over the local floor (the measured variance raised to the
    /// model-free estimate of `validation::noise::estimate_noise` where that is higher):
    /// median of `|G - P|^2 / floor` over `ln 2`.
    pub residual_to_floor: f64,
    /// Whether the diagnosis loop judged residuals against the local floor (it does
    /// when the floor exceeds the variance).
    pub loop_against_floor: bool,
}

/// A mode with the standard deviations of its frequency and damping (the refiner's
/// own form).
pub use frf_data::uncertainty::PoleUncertainty as ModeUncertaintySummary;

/// A dynamics factor's poles and zeros with standard deviations (a real root has
/// damping 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FactorUncertaintySummary {
    /// What it multiplies: `input j` or `output i` (1-based, as the steps name them) or
    /// `all entries`, as `final_model.dynamics` names it.
    pub target: String,
    /// The roots of its denominator.
    pub poles: Vec<ModeUncertaintySummary>,
    /// The roots of its numerator (empty for an all-pole factor).
    pub zeros: Vec<ModeUncertaintySummary>,
}

/// The uncertainty of the final model from the refiner's covariance at its optimum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UncertaintySummary {
    /// How it was computed: `ml`, the ML refiner's covariance at its own optimum (a
    /// chain ending in `ml`, without diagnosis steps); `information`, the information
    /// matrix of the ML criterion at the final model (any other chain, and every
    /// diagnosis: the asymptotic covariance of an estimate at the ML optimum to first
    /// order).
    pub method: String,
    /// `measured variance` (maximum likelihood) or `estimated from the residual`.
    pub noise: String,
    /// The cost test: `V / N_dof` at the optimum.
    pub cost_ratio: f64,
    /// Its expected value under the noise model.
    pub expected_ratio: f64,
    /// Its p-value (`None` without a measured variance).
    pub p_value: Option<f64>,
    /// The factor the inverse Fisher information was scaled by.
    pub covariance_scale: f64,
    /// Per mode, in increasing frequency.
    pub modes: Vec<ModeUncertaintySummary>,
    /// The fitted delay, seconds.
    pub delay_s: Option<f64>,
    /// Its standard deviation, seconds.
    pub delay_s_std: Option<f64>,
    /// Per dynamics factor of the final model, its poles and zeros with standard
    /// deviations (in the model's order; absent in files written before they were
    /// reported).
    #[serde(default)]
    pub factors: Vec<FactorUncertaintySummary>,
}

impl UncertaintySummary {
    /// The dynamics factors' poles and zeros with `+- 2 sigma`, one line each, for the
    /// terminal and the report: `input 0: pole 1807.2 Hz +- 3.1 Hz (zeta 1)`.
    pub fn factor_lines(&self) -> Vec<String> {
        let mut out = Vec::new();
        for f in &self.factors {
            for (kind, roots) in [("pole", &f.poles), ("zero", &f.zeros)] {
                for r in roots.iter() {
                    let zeta = if r.zeta >= 1.0 - 1e-12 {
                        "real".to_string()
                    } else {
                        format!("zeta {:.4} +- {:.2e}", r.zeta, 2.0 * r.zeta_std)
                    };
                    out.push(format!(
                        "{}: {kind} {:.4} Hz +- {:.2e} Hz ({zeta})",
                        f.target,
                        r.f_hz,
                        2.0 * r.f_hz_std
                    ));
                }
            }
        }
        out
    }

    /// Where the standard deviations come from, in words.
    pub fn source(&self) -> String {
        match self.method.as_str() {
            "ml" => "the covariance of the ML refinement at its optimum".into(),
            "information" => "the information matrix of the ML criterion at the final model (the asymptotic covariance; the chain has no ML link, or the diagnosis refitted the model)".into(),
            other => format!("the {other} refinement"),
        }
    }

    /// The standard deviations `(f_hz_std, zeta_std)` of the mode nearest `f_hz` (within
    /// 1e-6 relative), when there is one.
    pub fn mode_std(&self, f_hz: f64) -> Option<(f64, f64)> {
        self.modes
            .iter()
            .filter(|m| (m.f_hz - f_hz).abs() <= 1e-6 * f_hz.abs())
            .min_by(|a, b| (a.f_hz - f_hz).abs().total_cmp(&(b.f_hz - f_hz).abs()))
            .map(|m| (m.f_hz_std, m.zeta_std))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::{FactorParams, FactorSupport, ModeParams, PoleParams, Refit};

    /// The file holds the verdict as its name, and reads back into the same verdict.
    #[test]
    fn verdicts_are_written_and_read_as_their_names() {
        for v in [
            ResidualVerdict::NoiseLimited,
            ResidualVerdict::NonlinearDistortion,
            ResidualVerdict::UnexplainedResidual,
            ResidualVerdict::NotAnalysed,
        ] {
            let text = serde_json::to_string(&v).unwrap();
            assert_eq!(text, format!("\"{}\"", v.name()));
            assert_eq!(serde_json::from_str::<ResidualVerdict>(&text).unwrap(), v);
            assert_eq!(v, v.name());
            assert_eq!(v.to_string(), v.name());
        }
        assert!(serde_json::from_str::<ResidualVerdict>("\"noise limited\"").is_err());
    }

    fn step(fitted: FittedEffect) -> StepSummary {
        let e = ErrorStats {
            median_rel: 1e-3,
            p95_rel: 1e-2,
            residual_to_noise: 1.1,
        };
        StepSummary {
            fitted,
            accepted: true,
            evidence: "why".into(),
            uncertainty: Some([("f_hz".to_string(), 0.5)].into()),
            f_statistic: 40.0,
            f_critical: 3.0,
            added_params: 2,
            before: e,
            after: e,
            figure: None,
            superseded_by: None,
            held_out: None,
        }
    }

    /// Each effect is written as its `effect` name and `params` object, the schema of
    /// `summary.json`, and read back as the same typed effect, also where two effects
    /// have the same parameter names (a missed mode and a stiffness).
    #[test]
    fn steps_and_repairs_round_trip_through_their_json_schema() {
        let effects = [
            FittedEffect::MissedMode {
                f_hz: 120.0,
                zeta: 0.02,
            },
            FittedEffect::Stiffness {
                f_hz: 3.0,
                zeta: 0.1,
            },
            FittedEffect::Delay {
                seconds: 1e-5,
                total_delay_s: 1.2e-4,
                refit: Some(Refit::FromTheStart),
            },
            FittedEffect::Hold {
                fs_hz: 1e4,
                remaining_delay_s: 0.0,
            },
            FittedEffect::Feedthrough {
                rms: 0.3,
                bypasses_delay: true,
            },
            FittedEffect::OutputDynamics {
                outputs: vec![2],
                factor: FactorParams {
                    support: FactorSupport::Outputs,
                    order: 2,
                    poles: vec![PoleParams {
                        f_hz: 1700.0,
                        zeta: Some(0.05),
                        re: None,
                        im: None,
                    }],
                    zeros: Vec::new(),
                    non_minimum_phase: None,
                },
            },
        ];
        for e in effects {
            let s = step(e.clone());
            let v = serde_json::to_value(&s).unwrap();
            assert_eq!(v["effect"], e.name());
            assert!(v["params"].is_object(), "{v}");
            assert_eq!(v["params"], e.params_json());
            if let FittedEffect::OutputDynamics { .. } = e {
                // the factor's parameters sit beside `outputs`, as the schema has them
                assert_eq!(v["params"]["support"], "outputs", "{v}");
                assert_eq!(v["params"]["order"], 2, "{v}");
                assert_eq!(v["params"]["poles"][0]["f_hz"], 1700.0, "{v}");
                assert_eq!(v["params"]["outputs"][0], 2, "{v}");
            }
            let back: StepSummary = serde_json::from_value(v).unwrap();
            assert_eq!(back, s);
        }
        let r = RepairSummary {
            repair: Repair::ClosePair {
                from_hz: 636.6,
                modes: [
                    ModeParams {
                        f_hz: 636.0,
                        zeta: 0.01,
                    },
                    ModeParams {
                        f_hz: 637.2,
                        zeta: 0.012,
                    },
                ],
            },
            f_statistic: 80.0,
            cost: Some(CostChange {
                before: 2.0e5,
                after: 4.1e3,
            }),
        };
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["effect"], "close_pair");
        assert_eq!(v["cost"]["after"], 4.1e3);
        assert_eq!(v["params"]["modes"][1]["f_hz"], 637.2);
        assert_eq!(serde_json::from_value::<RepairSummary>(v).unwrap(), r);
    }
}
