//! The frfit pipeline: load -> band -> delay -> CMIF -> initialisation -> refinement ->
//! residual analysis -> diagnosis loop -> report (DESIGN.md).
//!
//! [`run`] fits the additive model of the wafer-stage paper (crate `additive-riv`) and,
//! with [`PipelineConfig::diagnose`], closes the loop the users asked for: it compares
//! the residual with the measured noise level (crate `validation`), traces a significant
//! residual to the effects of the catalogue (missed mode, delay, hold, feedthrough,
//! stiffness, input or output dynamics), adds the effect with the strongest evidence to
//! the model structure, refits, and keeps it only when an F test that accounts for the
//! added parameters says it explains more than noise. It stops when the residual is at
//! the noise level (`noise_limited`) or when no candidate helps
//! (`unexplained_residual`), and records every step for the report.

use crate::declared::{declared, Declared};
use crate::summary::*;
use crate::FrfitError;
use additive_riv::augment;
use additive_riv::riv::{iterate, RivConfig};
use additive_riv::significance::{chi2_upper, f_statistic, noise_scale};
use additive_riv::structure::{AdaptConfig, ResidualStats};
use additive_riv::{
    fit_numerators, AdditiveFitter, AdditiveModel, DelayChoice, FactorTarget, FitData,
    FitterConfig, FitterReport, Hold, IvMethod, ModeSelection, SubmodelKind,
};
use frf_data::cmif::{cmif, Cmif, CmifPeak};
use frf_data::{Fit, Frf, FrfDataset, ModelStructure, ProgressSink, Weighting};
use realize::ResponseGrid;
use std::time::Instant;
use validation::noise::{noise_level, NoiseLevel, NoiseSource};
use validation::residual::{analyze_residual, Effect, ResidualAnalysis, ResidualConfig};

/// What the FRF measures: the model is always of the displacement, multiplied by
/// `(j w)^k` for velocity (`k = 1`) or accelerance (`k = 2`) data, so that a free rigid
/// body stays `1/s^2` (and becomes a constant in an accelerance).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrfType {
    /// Displacement (or angle) per force (or current). The default.
    #[default]
    Displacement,
    /// Velocity per force.
    Velocity,
    /// Acceleration per force (accelerance).
    Accelerance,
}

impl FrfType {
    /// `k` of `(j w)^k`.
    pub fn derivative_order(self) -> u32 {
        match self {
            FrfType::Displacement => 0,
            FrfType::Velocity => 1,
            FrfType::Accelerance => 2,
        }
    }
    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            FrfType::Displacement => "displacement",
            FrfType::Velocity => "velocity",
            FrfType::Accelerance => "accelerance",
        }
    }
}

/// Settings of [`run`], with documented defaults.
#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// Band to fit, Hz. Default: the whole data above 0 Hz.
    pub band_hz: Option<(f64, f64)>,
    /// Modes to start from. Default: every CMIF peak.
    pub modes: ModeSelection,
    /// A hold the user declares (`zoh:FS` or `sinc:FS`): modelled from the start, not a
    /// discovery; `Some(Hold::None)` says there is none (overriding a hold the file's
    /// comments declare). Default: `None`, take what the file declares.
    pub hold: Option<Hold>,
    /// Delay handling. `None` (the default) means: for `fit`, estimate it and refine it
    /// in the iterations; for `diagnose`, take the delay the file declares (0 when it
    /// declares none) and let the loop test for more.
    pub delay: Option<DelayChoice>,
    /// Sample rate of the measurement for testing a hold, Hz. Default: from the file's
    /// metadata or comments.
    pub fs_hz: Option<f64>,
    /// What the FRF measures. Default: displacement.
    pub frf_type: FrfType,
    /// Instrument or SK. Default: RIV.
    pub method: IvMethod,
    /// Weighting. Default: inverse variance when the data carry it, eq. (27) otherwise.
    pub weighting: Weighting,
    /// Run the diagnosis loop. Default: false (`frfit fit`).
    pub diagnose: bool,
    /// At most this many effects are added by the loop (each round tests every
    /// candidate, then adds the best). Default: 8.
    pub max_steps: usize,
    /// Significance level of the tests. Default: 1e-3.
    pub alpha: f64,
    /// Practical-significance floor of an effect's F statistic (see
    /// [`AdaptConfig::min_f`]). Default: 25.
    pub min_f: f64,
    /// A model to start from (from `--model MODEL.json`) instead of the CMIF
    /// initialisation.
    pub start_model: Option<AdditiveModel>,
    /// The initialiser of the chain (see [`crate::chain::INITIALIZERS`]). Default: `cmif`.
    pub init: String,
    /// The refiner of the chain (see [`crate::chain::REFINERS`]). Default: `riv`.
    pub refine: String,
    /// Progress callback.
    pub progress: ProgressSink,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            band_hz: None,
            modes: ModeSelection::Auto,
            hold: None,
            delay: None,
            fs_hz: None,
            frf_type: FrfType::Displacement,
            method: IvMethod::Riv,
            weighting: Weighting::Auto,
            diagnose: false,
            max_steps: 8,
            alpha: 1e-3,
            min_f: 25.0,
            start_model: None,
            init: "cmif".into(),
            refine: "riv".into(),
            progress: ProgressSink::none(),
        }
    }
}

/// Everything a run produced: the band, the fit, the noise level, the CMIF, the model
/// responses for the report, and the summary.
pub struct PipelineOutput {
    /// The fitted band (a copy of the data's lines in the band).
    pub band: Frf,
    /// The final fit.
    pub fit: Fit<AdditiveModel>,
    /// What the fitter found on the way.
    pub fitter_report: FitterReport,
    /// The links of the chain that made the first model and their reports (empty when
    /// the run started from a given model).
    pub chain: Vec<String>,
    /// Each link's report.
    pub links: Vec<frf_data::LinkReport>,
    /// The noise level used.
    pub noise: NoiseLevel,
    /// CMIF of the band.
    pub cmif: Cmif,
    /// The picked peaks the fit started from.
    pub peaks: Vec<CmifPeak>,
    /// Response of the model before the diagnosis loop.
    pub initial_response: ResponseGrid,
    /// Response of the final model.
    pub final_response: ResponseGrid,
    /// Per step, the model response before and after.
    pub step_responses: Vec<(ResponseGrid, ResponseGrid)>,
    /// The summary (also written as `summary.json`).
    pub summary: Summary,
}

fn err<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> FrfitError + '_ {
    move |e| FrfitError::Fit {
        what: what.to_string(),
        why: e.to_string(),
    }
}

impl PipelineOutput {
    /// The model file of the final fit (modal form, submodels and provenance), as
    /// `frfit fit/diagnose` and `cargo xtask wafer-stage` write it; `producer` names
    /// what ran (e.g. `frfit diagnose`).
    pub fn model_file(
        &self,
        data_path: &std::path::Path,
        producer: &str,
    ) -> Result<additive_riv::ModelFile, additive_riv::RivError> {
        let provenance = additive_riv::Provenance {
            estimator: self.fit.estimator.clone(),
            data: Some(data_path.display().to_string()),
            weighting: self.fitter_report.weighting.clone(),
            iterations: self.fit.iterations,
            convergence: self.fit.convergence.describe(),
            cost: self.fit.final_cost(),
            frfit_version: format!("{} ({producer})", env!("CARGO_PKG_VERSION")),
            notes: self.fit.messages.clone(),
            chain: self.chain.clone(),
            links: self.links.clone(),
        };
        let band = self.summary.data.band_hz;
        additive_riv::ModelFile::from_model(
            &self.fit.model,
            self.band.units.clone(),
            Some((band[0], band[1])),
            provenance,
        )
    }

    /// What [`crate::report::write_report`] needs from this run, under `title`.
    pub fn report_input<'a>(&'a self, title: &'a str) -> crate::report::ReportInput<'a> {
        crate::report::ReportInput {
            data: &self.band,
            noise_var: Some(&self.noise.variance),
            cmif: &self.cmif,
            peaks: &self.peaks,
            initial: &self.initial_response,
            final_model: &self.final_response,
            steps: &self.step_responses,
            title,
        }
    }
}

/// Error statistics of `model` against `data` with `noise`.
fn error_stats(data: &Frf, response: &ResponseGrid, noise: &NoiseLevel) -> ErrorStats {
    let m = data.n_entries();
    let mut rel = Vec::with_capacity(data.n_lines() * m);
    let mut chi = 0.0;
    let mut cnt = 0usize;
    for k in 0..data.n_lines() {
        let g = data.line(k);
        let p = response.line(k);
        for e in 0..m {
            let d = (g[e] - p[e]).norm();
            if g[e].norm() > 0.0 {
                rel.push(d / g[e].norm());
            }
            let v = noise.variance[k * m + e];
            if v > 0.0 && v.is_finite() {
                chi += d * d / v;
                cnt += 1;
            }
        }
    }
    rel.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| -> f64 {
        if rel.is_empty() {
            f64::NAN
        } else {
            rel[((rel.len() - 1) as f64 * p).round() as usize]
        }
    };
    ErrorStats {
        median_rel: q(0.5),
        p95_rel: q(0.95),
        residual_to_noise: if cnt > 0 {
            (chi / cnt as f64).sqrt()
        } else {
            f64::NAN
        },
    }
}

/// Median of `sqrt(var) / |G|`: the data's own relative noise level.
fn data_noise_rel(data: &Frf, noise: &NoiseLevel) -> Option<f64> {
    let m = data.n_entries();
    let mut v: Vec<f64> = (0..data.n_lines())
        .flat_map(|k| {
            let g = data.line(k);
            (0..m).filter_map(move |e| {
                let a = g[e].norm();
                (a > 0.0).then(|| noise.variance[k * m + e].sqrt() / a)
            })
        })
        .collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    Some(v[v.len() / 2])
}

fn mode_summaries(model: &AdditiveModel) -> Vec<ModeSummary> {
    let mut v: Vec<ModeSummary> = model
        .modes()
        .iter()
        .map(|m| ModeSummary {
            f_hz: m.f_hz,
            zeta: m.zeta,
        })
        .collect();
    v.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
    v
}

fn hold_name(model: &AdditiveModel) -> String {
    match (model.domain(), model.factor.sinc_hold_fs) {
        (additive_riv::Domain::ZohDiscrete { ts }, _) => format!("zoh:{}", 1.0 / ts),
        (_, Some(fs)) => format!("sinc:{fs}"),
        _ => "none".into(),
    }
}

/// The final-model summary.
pub fn final_model_summary(fit: &Fit<AdditiveModel>) -> FinalModelSummary {
    let model = &fit.model;
    let order = model
        .to_modal_model()
        .map(|mm| mm.order(additive_riv::model_json::RANK_TOL))
        .unwrap_or(0);
    FinalModelSummary {
        modes: mode_summaries(model),
        order,
        delay_s: model.factor.delay_s,
        hold: hold_name(model),
        rigid_body_integrators: model
            .submodels
            .iter()
            .map(|s| s.integrators)
            .max()
            .unwrap_or(0),
        feedthrough: model
            .submodels
            .iter()
            .any(|s| s.kind == SubmodelKind::Feedthrough),
        dynamics: model
            .dynamics
            .iter()
            .map(|d| {
                let target = match d.target {
                    FactorTarget::Input(j) => format!("input {}", j + 1),
                    FactorTarget::Output(i) => format!("output {}", i + 1),
                    FactorTarget::All => "all entries".into(),
                };
                let poles: Vec<String> = d
                    .poles()
                    .iter()
                    .map(|p| format!("{:.1} Hz", p.norm() / std::f64::consts::TAU))
                    .collect();
                format!("{target}: poles at {}", poles.join(", "))
            })
            .collect(),
        iterations: fit.iterations,
        convergence: fit.convergence.describe(),
    }
}

/// One tested candidate of the loop.
struct Trial {
    effect: Effect,
    evidence: String,
    params: serde_json::Value,
    uncertainty: Option<serde_json::Value>,
    model: AdditiveModel,
    cost: f64,
    f: f64,
    f_crit: f64,
    added: usize,
    /// For the joint missed-mode trial: (frequency, damping) of every mode it added,
    /// each reported as its own `missed_mode` step.
    joint_modes: Vec<(f64, f64)>,
}

/// The modes of `after` that are not in `before`: each mode of `before` takes the
/// nearest unclaimed mode of `after` within 3 %, the rest are new.
fn new_modes(before: &AdditiveModel, after: &AdditiveModel) -> Vec<(f64, f64)> {
    let mut left: Vec<(f64, f64)> = after.modes().iter().map(|m| (m.f_hz, m.zeta)).collect();
    for old in before.modes() {
        let nearest = left
            .iter()
            .enumerate()
            .filter(|(_, (f, _))| (f / old.f_hz - 1.0).abs() < 0.03)
            .min_by(|a, b| {
                (a.1 .0 - old.f_hz)
                    .abs()
                    .total_cmp(&(b.1 .0 - old.f_hz).abs())
            })
            .map(|(i, _)| i);
        if let Some(i) = nearest {
            left.remove(i);
        }
    }
    left
}

fn effect_name(e: Effect) -> &'static str {
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

/// The weighted cost `sum w |E|^2` of `model` on `fd`.
fn model_cost(model: &AdditiveModel, fd: &FitData) -> f64 {
    let lay = additive_riv::problem::Layout::of(model);
    let basis = additive_riv::problem::Basis::new(model, &lay, &fd.omega);
    let (_, eta) = additive_riv::problem::pack(model, &lay);
    let g = additive_riv::problem::groups(model, &lay);
    additive_riv::problem::cost(fd, &lay, &basis, &eta, None, &g)
}

/// A candidate augmentation: the effect, its evidence, its starting parameters, the
/// augmented model, and for a missed mode the residual peak that called for it.
type Candidate = (
    Effect,
    String,
    serde_json::Value,
    Result<AdditiveModel, additive_riv::RivError>,
    Option<f64>,
);

/// A signature worth a refit: significant at `alpha` and explaining at least 2 % of
/// the residual's excess energy (a refit costs about a second on the wafer stage; the
/// F test after it decides).
fn plausible(fit: &validation::signatures::TemplateFit, alpha: f64) -> bool {
    fit.p_value < alpha && fit.explained_fraction >= 0.02
}

/// The evidence line of `effect` in the analysis.
fn detail(an: &ResidualAnalysis, effect: Effect) -> String {
    an.evidence
        .iter()
        .find(|e| e.effect == effect)
        .map(|e| e.detail.clone())
        .unwrap_or_default()
}

/// Candidate augmentations of `model` from the residual: every effect of the catalogue
/// whose signature test is significant at `alpha` (the refit and its F test decide, so
/// the signature need not explain most of the residual), the hold whenever the sample
/// rate is known and the hold is not modelled, and the strongest residual peak as a
/// missed mode.
fn candidates(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    stats: &ResidualStats,
    fd: &FitData,
    fs_hz: Option<f64>,
    alpha: f64,
    tested: &[(Effect, String)],
    data_delay: Option<f64>,
) -> Vec<Candidate> {
    let mut out: Vec<Candidate> = Vec::new();
    let seen = |e: Effect, key: &str| tested.iter().any(|(x, k)| *x == e && k == key);
    // missed mode: the two strongest residual peaks (local and Bonferroni tests)
    let peaks = additive_riv::structure::residual_peaks(stats, fd, alpha, 0.025);
    for &(f, ratio) in peaks.iter().take(2) {
        let key = format!("{:.0}", f * 10.0);
        if !seen(Effect::MissedMode, &key) {
            let zeta = an
                .residual_cmif
                .iter()
                .filter(|p| (p.f_hz - f).abs() < 0.01 * f)
                .find_map(|p| p.damping)
                .unwrap_or(0.01)
                .clamp(0.002, 0.2);
            let ev = format!(
                "residual peak at {f:.2} Hz, {ratio:.1} x its local threshold; {}",
                detail(an, Effect::MissedMode)
            );
            out.push((
                Effect::MissedMode,
                ev,
                serde_json::json!({"f_hz": f, "zeta": zeta}),
                augment::with_mode(model, f, zeta),
                Some(f),
            ));
        }
    }
    if !model.factor.fit_delay && plausible(&an.phase_trend.fit, alpha) {
        let d = an.phase_trend.delay_s;
        out.push((
            Effect::Delay,
            detail(an, Effect::Delay),
            serde_json::json!({"seconds": d}),
            augment::with_fitted_delay(model, d),
            None,
        ));
    }
    // The residual's phase slope is biased when the model is far off (modes fitted
    // without the delay absorb part of it); the data's own phase slope, from the delay
    // estimator of frf-data, is a second start for the same effect.
    if let Some(total) = data_delay {
        let hold_half = match model.domain() {
            additive_riv::Domain::ZohDiscrete { ts } => 0.5 * ts,
            additive_riv::Domain::Continuous => 0.0,
        };
        let d = total - hold_half - model.factor.delay_s;
        let d_trend = an.phase_trend.delay_s;
        if !model.factor.fit_delay
            && an.significant
            && d.abs() > 1e-6
            && (d - d_trend).abs() > 1e-6
            && !seen(Effect::Delay, "data")
        {
            out.push((
                Effect::Delay,
                format!(
                    "phase slope of the data: {:.2} us in all, {:.2} us beyond the model's delay (the residual's slope says {:.2} us)",
                    total * 1e6,
                    d * 1e6,
                    d_trend * 1e6
                ),
                serde_json::json!({"seconds": d, "start": "data"}),
                augment::with_fitted_delay(model, d),
                None,
            ));
        }
    }
    if let (Some(fs), additive_riv::Domain::Continuous) = (fs_hz, model.domain()) {
        if model.factor.derivative_order == 0 {
            let ev = match &an.hold {
                Some(h) => format!(
                    "sample rate {fs} Hz known; droop template amplitude {:.2} (1 = a hold at {fs} Hz), correlation {:.2}, {:.0}% of the excess",
                    h.amplitude,
                    h.correlation,
                    100.0 * h.fit.explained_fraction
                ),
                None => format!("sample rate {fs} Hz known"),
            };
            out.push((
                Effect::Hold,
                ev,
                serde_json::json!({"fs_hz": fs}),
                augment::to_exact_hold(model, fs),
                None,
            ));
        }
    }
    if !model
        .submodels
        .iter()
        .any(|s| s.kind == SubmodelKind::Feedthrough)
        && plausible(&an.feedthrough.fit, alpha)
    {
        // inside the delay and hold (a biproper plant) or bypassing them (crosstalk)
        for bypass in [false, true] {
            out.push((
                Effect::Feedthrough,
                format!(
                    "{}; tested {}",
                    detail(an, Effect::Feedthrough),
                    if bypass {
                        "as crosstalk that bypasses the delay and hold"
                    } else {
                        "inside the delay and hold"
                    }
                ),
                serde_json::json!({"rms": an.feedthrough.rms_magnitude, "bypasses_delay": bypass}),
                if bypass {
                    augment::with_crosstalk(model)
                } else {
                    augment::with_feedthrough(model)
                },
                None,
            ));
        }
    }
    // a suspended body seen from above its suspension frequency looks like 1/s^2 or,
    // with its damping, like 1/s to the first fit: either rigid body can be suspended
    let has_free_rb = model
        .submodels
        .iter()
        .any(|s| s.kind == SubmodelKind::RigidBody && s.integrators >= 1);
    if has_free_rb && plausible(&an.stiffness.fit, alpha) {
        let s = &an.stiffness;
        let f = if s.f_hz.is_finite() && s.f_hz > 0.0 {
            s.f_hz
        } else {
            s.equivalent_f_hz
        };
        if f.is_finite() && f > 0.0 {
            out.push((
                Effect::Stiffness,
                detail(an, Effect::Stiffness),
                serde_json::json!({"f_hz": f, "zeta": s.zeta}),
                augment::with_stiffness(model, f, s.zeta.clamp(1e-3, 0.9)),
                None,
            ));
        }
    }
    for (effect, list, input) in [
        (Effect::InputDynamics, &an.input_dynamics, true),
        (Effect::OutputDynamics, &an.output_dynamics, false),
    ] {
        // the strongest row or column whose first-order factor is significant
        let best = list
            .iter()
            .filter(|f| plausible(&f.fit, alpha))
            .max_by(|a, b| a.fit.explained.total_cmp(&b.fit.explained));
        if let Some(f) = best {
            let key = format!("{}", f.index);
            if seen(effect, &key) {
                continue;
            }
            let target = if input {
                FactorTarget::Input(f.index)
            } else {
                FactorTarget::Output(f.index)
            };
            let pole = if f.pole_hz.is_finite() && f.pole_hz > 0.0 {
                f.pole_hz
            } else {
                1e3
            };
            out.push((
                effect,
                detail(an, effect),
                serde_json::json!({
                    if input { "inputs" } else { "outputs" }: [f.index + 1],
                    "poles": [{"f_hz": pole}]
                }),
                augment::with_dynamics(model, target, 1, pole),
                None,
            ));
        }
    }
    out
}

/// Describes the parameters of the effect as fitted in `m` (the accepted refit).
fn fitted_params(
    effect: Effect,
    before: &AdditiveModel,
    m: &AdditiveModel,
    start: &serde_json::Value,
) -> serde_json::Value {
    match effect {
        Effect::MissedMode => {
            // the mode of `m` that `before` does not have: the one nearest the start
            let f0 = start["f_hz"].as_f64().unwrap_or(0.0);
            let new = new_modes(before, m)
                .into_iter()
                .min_by(|a, b| (a.0 - f0).abs().total_cmp(&(b.0 - f0).abs()));
            match new {
                Some((f_hz, zeta)) => serde_json::json!({"f_hz": f_hz, "zeta": zeta}),
                None => start.clone(),
            }
        }
        Effect::Delay => serde_json::json!({
            "seconds": m.factor.delay_s - before.factor.delay_s,
            "total_delay_s": m.factor.delay_s
        }),
        Effect::Hold => serde_json::json!({
            "fs_hz": start["fs_hz"],
            "remaining_delay_s": m.factor.delay_s
        }),
        Effect::Feedthrough => {
            let d = m
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
            let bypass = m
                .submodels
                .iter()
                .any(|s| s.kind == SubmodelKind::Feedthrough && s.bypass_factor);
            serde_json::json!({"rms": d, "bypasses_delay": bypass})
        }
        Effect::Stiffness => {
            let s = m
                .submodels
                .iter()
                .find(|s| s.kind == SubmodelKind::Suspension);
            match s.and_then(|s| m.upper_pole(s)) {
                Some(p) => {
                    serde_json::json!({"f_hz": p.norm() / std::f64::consts::TAU, "zeta": -p.re / p.norm()})
                }
                None => start.clone(),
            }
        }
        Effect::InputDynamics | Effect::OutputDynamics => {
            let d = m.dynamics.last();
            match d {
                Some(d) => {
                    let (key, idx) = match d.target {
                        FactorTarget::Input(j) => ("inputs", j + 1),
                        FactorTarget::Output(i) => ("outputs", i + 1),
                        FactorTarget::All => ("inputs", 0),
                    };
                    let poles: Vec<serde_json::Value> = d
                        .poles()
                        .iter()
                        .map(|p| serde_json::json!({"f_hz": p.norm() / std::f64::consts::TAU, "re": p.re, "im": p.im}))
                        .collect();
                    serde_json::json!({ key: [idx], "poles": poles })
                }
                None => start.clone(),
            }
        }
    }
}

/// Submodels and dynamics factors of `model` with a pole in the closed right half-plane.
fn unstable_parts(model: &AdditiveModel) -> usize {
    model.unstable_submodels().len()
        + model
            .dynamics
            .iter()
            .filter(|d| d.poles().iter().any(|p| p.re >= 0.0))
            .count()
}

/// The F test of a refit `model` that adds `added` real parameters and lowers the
/// weighted cost from `before` to `after`: the cost explained per added parameter over
/// the noise scale of the larger model, and its critical value at `cfg.alpha` with the
/// effective number of parameters (correlated residuals), floored at `cfg.min_f`.
/// Returns the residual statistics of `model` as well (the local tests use them).
fn f_test(
    model: &AdditiveModel,
    fd: &FitData,
    before: f64,
    after: f64,
    added: usize,
    cfg: &PipelineConfig,
) -> (ResidualStats, f64, f64) {
    let stats = ResidualStats::new(model, fd);
    let s2 = noise_scale(after, fd, model.n_params());
    let f = f_statistic(before - after, added, s2);
    let p_eff = stats.effective_params(added, fd.m());
    let f_crit = (chi2_upper(p_eff, cfg.alpha) / p_eff).max(cfg.min_f);
    (stats, f, f_crit)
}

/// Refits a candidate: numerators (eq. 24), then Algorithm 1 to a coarse tolerance.
fn refit(
    model: AdditiveModel,
    fd: &FitData,
    riv: &RivConfig,
) -> Result<(AdditiveModel, f64), FrfitError> {
    let mut m = model;
    fit_numerators(&mut m, fd).map_err(err("refit"))?;
    let f = iterate(m, fd, riv).map_err(err("refit"))?;
    // a refit whose iterations failed (singular, no descent) before any step was taken
    // did not fit the effect: its model is the start, not an estimate
    if let (frf_data::Convergence::Failed { reason }, true) =
        (&f.convergence, f.cost_history.len() <= 1)
    {
        return Err(FrfitError::Fit {
            what: "refit".into(),
            why: reason.clone(),
        });
    }
    let c = model_cost(&f.model, fd);
    Ok((f.model, c))
}

/// The first fit through the estimator chain `cfg.init -> cfg.refine` ([`crate::chain`]):
/// the additive model the diagnosis continues from (the chain's own additive structure
/// when its last link has one, otherwise the currency's structure with numerators by
/// eq. 24), what the fitter found on the way, the chain's names and each link's report.
fn first_fit_by_chain(
    band: &Frf,
    fitter_cfg: &FitterConfig,
    cfg: &PipelineConfig,
) -> Result<
    (
        Fit<AdditiveModel>,
        FitterReport,
        Vec<String>,
        Vec<frf_data::LinkReport>,
    ),
    FrfitError,
> {
    let settings = frf_data::ChainSettings {
        hold: fitter_cfg.hold,
        delay: fitter_cfg.delay,
        derivative_order: fitter_cfg.derivative_order,
        weighting: fitter_cfg.riv.weighting.clone(),
        modes: fitter_cfg.modes.clone(),
        peaks: fitter_cfg.peaks.clone(),
        order: None,
        progress: fitter_cfg.progress.clone(),
    };
    let opts = crate::chain::AdditiveOptions {
        riv: fitter_cfg.riv.clone(),
        adapt: fitter_cfg.adapt.clone(),
        rigid_body: fitter_cfg.rigid_body,
    };
    let result = crate::chain::run_chain(band, &cfg.init, &cfg.refine, &settings, &opts)?;
    let model = match result.model.native::<AdditiveModel>() {
        Some(m) => m.clone(),
        None => {
            let fd =
                FitData::new(band, &fitter_cfg.riv.weighting.resolve(band)).map_err(err("fit"))?;
            let (mut m, _) = AdditiveModel::from_frf_model(&result.model.model, fd.band_hz, 0.01)
                .map_err(err("fit"))?;
            fit_numerators(&mut m, &fd).map_err(err("fit"))?;
            m
        }
    };
    let mut report = FitterReport::default();
    for l in &result.links {
        if let Ok(r) = serde_json::from_value::<additive_riv::CmifInitReport>(l.details.clone()) {
            report.cmif_peaks = r.cmif_peaks;
            report.delay_estimate = r.delay_estimate;
            report.integrators = r.integrators;
            report.weighting = r.weighting;
            report.init_cost = r.init_cost;
            report.band_hz = r.band_hz;
        } else if let Ok(r) = serde_json::from_value::<additive_riv::RivReport>(l.details.clone()) {
            report.weighting = r.weighting;
            report.adapt = r.adapt;
        }
    }
    let last = result
        .links
        .last()
        .cloned()
        .ok_or_else(|| FrfitError::Fit {
            what: "chain".into(),
            why: "no link ran".into(),
        })?;
    let mut messages: Vec<String> = result
        .links
        .iter()
        .flat_map(|l| l.messages.clone())
        .collect();
    messages.extend(result.notes.iter().cloned());
    let fit = Fit {
        model,
        report: (),
        cost_history: last.cost_history.clone(),
        iterations: result.links.iter().map(|l| l.iterations).sum(),
        convergence: last.convergence.clone(),
        timings: result
            .links
            .iter()
            .flat_map(|l| l.timings.clone())
            .collect(),
        estimator: result
            .links
            .iter()
            .map(|l| format!("{}: {}", l.link, l.estimator))
            .collect::<Vec<_>>()
            .join(" -> "),
        messages,
    };
    Ok((fit, report, result.chain, result.links))
}

/// Runs the pipeline on `data` (read from `path`) for `command` (`fit` or `diagnose`).
pub fn run(
    data: &Frf,
    path: &str,
    cfg: &PipelineConfig,
    command: &str,
) -> Result<PipelineOutput, FrfitError> {
    let t0 = Instant::now();
    let mut timings: Vec<StageTime> = Vec::new();
    let mut stage = |name: &str, t: Instant| {
        timings.push(StageTime {
            stage: name.to_string(),
            seconds: t.elapsed().as_secs_f64(),
        })
    };
    // band (never the 0 Hz line)
    let t = Instant::now();
    let (lo, hi) = match cfg.band_hz {
        Some(b) => b,
        None => {
            let f = data.freq_hz_slice();
            (
                f.iter().copied().find(|&x| x > 0.0).unwrap_or(f[0]),
                f[f.len() - 1],
            )
        }
    };
    let lo = if lo <= 0.0 { f64::MIN_POSITIVE } else { lo };
    let band = data.band(lo, hi)?.to_frf();
    let decl: Declared = declared(data);
    let fs_hz = cfg.fs_hz.or(decl.fs_hz);
    let noise = noise_level(&band).map_err(err("noise level"))?;
    stage("load+band", t);
    // the model and its first fit
    let t = Instant::now();
    let c = cmif(&band)?;
    stage("cmif", t);
    let mut declared_list = decl.sources.clone();
    if let Some(h) = cfg.hold {
        declared_list.push(format!("hold {h:?} (command line)"));
    }
    // a hold the file declares (with its sample rate) is modelled from the start, like
    // one given with --hold; it is not a discovery of the loop
    let hold = cfg.hold.or_else(|| match (decl.zoh, fs_hz) {
        (true, Some(fs))
            if cfg.frf_type == FrfType::Displacement
                && fs / 2.0 > hi.min(data.freq_hz_slice()[data.n_lines() - 1]) =>
        {
            Some(Hold::Zoh { fs_hz: fs })
        }
        _ => None,
    });
    let delay = match cfg.delay {
        Some(d) => d,
        None if cfg.diagnose => match decl.delay_s {
            Some(s) => DelayChoice::Fixed { seconds: s },
            None => DelayChoice::None,
        },
        None => DelayChoice::Auto,
    };
    let delay = match (delay, hold) {
        // a declared total delay includes the hold's half sample, which the exact hold
        // models itself
        (DelayChoice::Fixed { seconds }, Some(Hold::Zoh { fs_hz })) if cfg.delay.is_none() => {
            DelayChoice::Fixed {
                seconds: seconds - 0.5 / fs_hz,
            }
        }
        (d, _) => d,
    };
    let mut riv = RivConfig {
        method: cfg.method,
        weighting: cfg.weighting.clone(),
        progress: cfg.progress.clone(),
        ..Default::default()
    };
    let fitter_cfg = FitterConfig {
        modes: cfg.modes.clone(),
        hold: hold.unwrap_or(Hold::None),
        delay,
        derivative_order: cfg.frf_type.derivative_order(),
        riv: riv.clone(),
        adapt: Some(AdaptConfig {
            min_f: cfg.min_f,
            alpha: cfg.alpha,
            // The first fit completes the modes at significant residual peaks, as
            // `frfit fit` does, unless the user declared the modes to expect
            // (`--modes N` or frequencies): then a mode beyond them is a discovery of
            // the diagnosis loop, reported as a step.
            max_new_per_round: if cfg.diagnose && cfg.modes != ModeSelection::Auto {
                0
            } else {
                6
            },
            ..Default::default()
        }),
        progress: cfg.progress.clone(),
        ..Default::default()
    };
    let t = Instant::now();
    let fresh_cfg = FitterConfig {
        progress: ProgressSink::none(),
        riv: RivConfig {
            progress: ProgressSink::none(),
            ..fitter_cfg.riv.clone()
        },
        ..fitter_cfg.clone()
    };
    let mut chain_names = Vec::new();
    let mut chain_links = Vec::new();
    let (mut fit, fitter_report) = match &cfg.start_model {
        None => {
            let r = first_fit_by_chain(&band, &fitter_cfg, cfg)?;
            chain_names = r.2;
            chain_links = r.3;
            (r.0, r.1)
        }
        Some(m) => {
            let fd = FitData::new(&band, &cfg.weighting.resolve(&band)).map_err(err("fit"))?;
            let mut m = m.clone();
            fit_numerators(&mut m, &fd).map_err(err("fit"))?;
            let f = iterate(m, &fd, &riv).map_err(err("fit"))?;
            (f, FitterReport::default())
        }
    };
    stage("fit", t);
    let weighting = cfg.weighting.resolve(&band);
    let fd = FitData::new(&band, &weighting).map_err(err("fit"))?;
    let omega = band.omegas();
    let initial_model = fit.model.clone();
    let initial_response = initial_model.response_at(&omega);
    let initial_errors = error_stats(&band, &initial_response, &noise);
    let mut steps: Vec<StepSummary> = Vec::new();
    let mut step_responses = Vec::new();
    // a variance estimated from R realizations has 2 (R - 1) real degrees of freedom
    let variance_dof = match (band.has_variance(), decl.realizations) {
        (true, Some(r)) if r >= 3 => Some(2.0 * (r as f64 - 1.0)),
        _ => None,
    };
    let rcfg = |model: &AdditiveModel| ResidualConfig {
        sample_rate_hz: if model.domain() == additive_riv::Domain::Continuous {
            fs_hz
        } else {
            None
        },
        variance_dof,
        ..Default::default()
    };
    let mut analysis = analyze_residual(&band, &initial_response, &noise, &rcfg(&fit.model))
        .map_err(err("residual analysis"))?;
    // the diagnosis loop
    if cfg.diagnose {
        let t = Instant::now();
        riv.param_tol = 1e-7;
        riv.max_iterations = 30;
        let prune_cfg = AdaptConfig {
            min_f: cfg.min_f,
            alpha: cfg.alpha,
            ..Default::default()
        };
        riv.progress = ProgressSink::none();
        let mut tested: Vec<(Effect, String)> = Vec::new();
        let mut fresh_delay_tested = false;
        // the data's own delay (phase slope of the FRF), a start for the delay effect
        let data_delay = frf_data::delay::estimate_delay(&band, &Default::default())
            .ok()
            .map(|d| d.tau_s);
        let mut current = fit.model.clone();
        let mut current_cost = model_cost(&current, &fd);
        let mut response = initial_response.clone();
        let mut n_tests = 0;
        let mut n_accepted = 0;
        while analysis.significant && n_accepted < cfg.max_steps {
            let stats_before = ResidualStats::new(&current, &fd);
            let cands = candidates(
                &current,
                &analysis,
                &stats_before,
                &fd,
                fs_hz,
                cfg.alpha,
                &tested,
                data_delay,
            );
            if cands.is_empty() {
                break;
            }
            let before = error_stats(&band, &response, &noise);
            let mut trials: Vec<Trial> = Vec::new();
            let tested_missed_mode_now = cands.iter().any(|c| c.0 == Effect::MissedMode);
            // Missed modes jointly: close pairs merged into one fitted mode, or several
            // peaks at once, are resolved by adding a mode at every significant residual
            // peak and refining, with the local and F tests of the structure adaptation
            // per mode (what `frfit fit` does); tested as one candidate against the rest.
            // When it passes its F test, the single-peak candidates it subsumes are
            // not refitted one by one.
            if tested_missed_mode_now {
                let acfg = AdaptConfig {
                    min_f: cfg.min_f,
                    alpha: cfg.alpha,
                    // every added mode must still pass the local and F tests
                    peak_over_local: 5.0,
                    ..Default::default()
                };
                n_tests += 1;
                cfg.progress.step(
                    "diagnose",
                    n_tests,
                    None,
                    None,
                    format!("round {}: testing missed modes jointly", n_accepted + 1),
                );
                if let Ok((af, rep)) = additive_riv::adapt_modes(current.clone(), &fd, &riv, &acfg)
                {
                    let m = af.model;
                    let c = model_cost(&m, &fd);
                    let joint = new_modes(&current, &m);
                    let added = m.n_params().saturating_sub(current.n_params());
                    if !joint.is_empty() && added > 0 && c < current_cost {
                        let (_, f, f_crit) = f_test(&m, &fd, current_cost, c, added, cfg);
                        let list: Vec<String> =
                            joint.iter().map(|(f, _)| format!("{f:.2} Hz")).collect();
                        let evidence = format!(
                            "significant residual peaks; modes added at every peak in {} round(s) of add/drop with the local test per mode (removed on the way: {}): {}",
                            rep.rounds,
                            rep.dropped.len(),
                            list.join(", ")
                        );
                        trials.push(Trial {
                            effect: Effect::MissedMode,
                            evidence,
                            params: serde_json::json!({"f_hz": joint[0].0, "zeta": joint[0].1}),
                            uncertainty: None,
                            model: m,
                            cost: c,
                            f,
                            f_crit,
                            added,
                            joint_modes: joint,
                        });
                    }
                }
            }
            // A delay large enough to matter also misplaces the modes fitted without
            // it; refitting from the start (CMIF, delay estimated from the data's
            // phase slope and refined, mode adaptation) is tested beside the
            // incremental refit.
            if !current.factor.fit_delay
                && !fresh_delay_tested
                && cands.iter().any(|c| c.0 == Effect::Delay)
            {
                fresh_delay_tested = true;
                n_tests += 1;
                cfg.progress.step(
                    "diagnose",
                    n_tests,
                    None,
                    None,
                    format!(
                        "round {}: testing a delay with a refit from the start",
                        n_accepted + 1
                    ),
                );
                let fc = FitterConfig {
                    delay: DelayChoice::Auto,
                    ..fresh_cfg.clone()
                };
                if let Ok((f, rep)) = AdditiveFitter::new(fc).fit(&band) {
                    let m = f.model;
                    let c = model_cost(&m, &fd);
                    if c < current_cost && m.factor.fit_delay {
                        let added = m.n_params().saturating_sub(current.n_params()).max(1);
                        let (_, f, f_crit) = f_test(&m, &fd, current_cost, c, added, cfg);
                        let evidence = format!(
                            "the residual's phase slope; refitted from the start with the delay estimated from the data ({:.2} us) and refined to {:.2} us, {} modes",
                            rep.delay_estimate.as_ref().map_or(f64::NAN, |d| d.tau_s * 1e6),
                            m.factor.delay_s * 1e6,
                            m.modes().len()
                        );
                        trials.push(Trial {
                            effect: Effect::Delay,
                            evidence,
                            params: serde_json::json!({
                                "seconds": m.factor.delay_s - current.factor.delay_s,
                                "total_delay_s": m.factor.delay_s,
                                "refit": "from the start"
                            }),
                            uncertainty: None,
                            model: m,
                            cost: c,
                            f,
                            f_crit,
                            added,
                            joint_modes: Vec::new(),
                        });
                    }
                }
            }
            let joint_passed = trials
                .iter()
                .any(|t| t.f > t.f_crit && t.effect == Effect::MissedMode);
            let cands: Vec<Candidate> = cands
                .into_iter()
                .filter(|c| !(joint_passed && c.0 == Effect::MissedMode))
                .collect();
            for (effect, evidence, params, aug, peak) in cands {
                n_tests += 1;
                let key = match effect {
                    Effect::MissedMode => {
                        format!("{:.0}", params["f_hz"].as_f64().unwrap_or(0.0) * 10.0)
                    }
                    Effect::InputDynamics | Effect::OutputDynamics => params
                        .get("inputs")
                        .or_else(|| params.get("outputs"))
                        .and_then(|v| v[0].as_u64())
                        .map(|i| format!("{}", i - 1))
                        .unwrap_or_default(),
                    Effect::Delay => params
                        .get("start")
                        .and_then(|v| v.as_str())
                        .unwrap_or_default()
                        .to_string(),
                    _ => String::new(),
                };
                tested.push((effect, key));
                cfg.progress.step(
                    "diagnose",
                    n_tests,
                    None,
                    None,
                    format!("round {}: testing {}", n_accepted + 1, effect_name(effect)),
                );
                let Ok(aug) = aug else { continue };
                let added = aug.n_params().saturating_sub(current.n_params()).max(1);
                let Ok((m, c)) = refit(aug, &fd, &riv) else {
                    continue;
                };
                let (stats, mut f, f_crit) = f_test(&m, &fd, current_cost, c, added, cfg);
                let mut evidence = evidence;
                if let Some(fp) = peak {
                    // a missed mode must also remove most of the residual around its peak
                    let half = 0.01 * fp;
                    let ratio = additive_riv::structure::local_energy(&stats, &fd, fp, half)
                        / additive_riv::structure::local_energy(&stats_before, &fd, fp, half)
                            .max(f64::MIN_POSITIVE);
                    evidence = format!(
                        "{evidence}; after the refit {:.0}% of the residual within 1% of the peak remains",
                        100.0 * ratio
                    );
                    if ratio > 0.25 {
                        f = f.min(f_crit * (1.0 - 1e-12));
                    }
                }
                let fitted = fitted_params(effect, &current, &m, &params);
                trials.push(Trial {
                    effect,
                    evidence,
                    params: fitted,
                    uncertainty: None,
                    model: m,
                    cost: c,
                    f,
                    f_crit,
                    added,
                    joint_modes: Vec::new(),
                });
            }
            if trials.is_empty() {
                break;
            }
            // of the candidates that pass their F test, accept the one that explains
            // the most (the largest decrease of the cost): the residual is attributed
            // to the best effect, and the others are tested again against what is left
            let best = trials
                .iter()
                .enumerate()
                .filter(|(_, tr)| {
                    // an effect that leaves a pole in the right half-plane is not a fix
                    tr.f > tr.f_crit
                        && tr.cost < current_cost
                        && unstable_parts(&tr.model) <= unstable_parts(&current)
                })
                .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))
                .map(|(i, _)| i);
            let mut accepted_model = None;
            for (i, tr) in trials.into_iter().enumerate() {
                let after_resp = tr.model.response_at(&omega);
                let after = error_stats(&band, &after_resp, &noise);
                let accepted = Some(i) == best;
                // a joint missed-mode trial reports each mode it added as a step
                let per_step: Vec<(serde_json::Value, String)> = if tr.joint_modes.is_empty() {
                    vec![(tr.params.clone(), tr.evidence.clone())]
                } else {
                    let n = tr.joint_modes.len();
                    tr.joint_modes
                        .iter()
                        .enumerate()
                        .map(|(k, (f, z))| {
                            (
                                serde_json::json!({"f_hz": f, "zeta": z}),
                                format!("mode {} of {n} added together; {}", k + 1, tr.evidence),
                            )
                        })
                        .collect()
                };
                for (params, evidence) in per_step {
                    steps.push(StepSummary {
                        effect: effect_name(tr.effect).to_string(),
                        accepted,
                        evidence,
                        params,
                        uncertainty: tr.uncertainty.clone(),
                        f_statistic: tr.f,
                        f_critical: tr.f_crit,
                        added_params: tr.added,
                        before,
                        after,
                        figure: None,
                    });
                    step_responses.push((response.clone(), after_resp.clone()));
                }
                if accepted {
                    accepted_model = Some((tr.model, tr.cost, after_resp));
                }
            }
            match accepted_model {
                Some((accepted_m, accepted_cost, _)) => {
                    n_accepted += 1;
                    // modes that the new structure made redundant go (duplicates,
                    // unstable, insignificant), then the numerators are refitted; a
                    // pruning that costs significantly (F test of the removed
                    // parameters) is not kept
                    let mut m = accepted_m.clone();
                    let pruned = additive_riv::structure::prune_modes(&mut m, &fd, &prune_cfg)
                        .map_err(err("prune"))?;
                    if !pruned.is_empty() {
                        let removed = accepted_m.n_params().saturating_sub(m.n_params()).max(1);
                        let s2 = noise_scale(accepted_cost, &fd, accepted_m.n_params());
                        let f_removed =
                            f_statistic(model_cost(&m, &fd) - accepted_cost, removed, s2);
                        if f_removed > cfg.min_f {
                            fit.messages.push(format!(
                                "after step {}: kept {} mode(s) the pruning would remove (their removal raises the cost significantly, F = {f_removed:.1})",
                                steps.len(),
                                pruned.len()
                            ));
                            m = accepted_m;
                        } else {
                            for (f, why) in pruned {
                                fit.messages.push(format!(
                                    "after step {}: removed mode at {f:.2} Hz: {why}",
                                    steps.len()
                                ));
                            }
                        }
                    }
                    current_cost = model_cost(&m, &fd);
                    response = m.response_at(&omega);
                    current = m;
                    analysis = analyze_residual(&band, &response, &noise, &rcfg(&current))
                        .map_err(err("residual analysis"))?;
                }
                None => break,
            }
        }
        // converge fully from the final structure
        let full = RivConfig {
            method: cfg.method,
            weighting: cfg.weighting.clone(),
            ..Default::default()
        };
        let unstable_before = unstable_parts(&current);
        let mut last = iterate(current.clone(), &fd, &full).map_err(err("final refinement"))?;
        let mut msgs = std::mem::take(&mut fit.messages);
        if unstable_parts(&last.model) > unstable_before {
            msgs.push(
                "the final refinement moved a pole into the right half-plane; the model of the last accepted step is kept".into(),
            );
            let keep = Fit::from_model(current, last.estimator.clone());
            last = Fit {
                cost_history: vec![model_cost(&keep.model, &fd) / (2.0 * fd.n as f64)],
                convergence: frf_data::Convergence::Failed {
                    reason: "the final refinement left the stable region; stopped at the last accepted step".into(),
                },
                ..keep
            };
        }
        // the loop never ends worse than it started
        let initial_cost = model_cost(&initial_model, &fd);
        if model_cost(&last.model, &fd) > initial_cost {
            msgs.push(format!(
                "the diagnosed model fits worse than the first model (cost {:.4e} > {initial_cost:.4e}); the first model is kept",
                model_cost(&last.model, &fd)
            ));
            fit.messages = msgs;
        } else {
            // iterations of the first fit and of the final refinement (the refits of
            // the candidates are reported per step)
            let first = fit.iterations;
            fit = last;
            fit.iterations += first;
            fit.messages = msgs;
        }
        stage("diagnose", t);
    }
    let final_response = fit.model.response_at(&omega);
    analysis = analyze_residual(&band, &final_response, &noise, &rcfg(&fit.model))
        .map_err(err("residual analysis"))?;
    let final_errors = error_stats(&band, &final_response, &noise);
    let (verdict, verdict_evidence) = if !analysis.significant {
        (
            "noise_limited",
            format!(
                "the residual is at the noise level: residual-to-noise ratio {:.3} (excess {:.3} of the calibrated noise energy, p = {:.2e})",
                final_errors.residual_to_noise, analysis.significance.excess_ratio, analysis.significance.p_value
            ),
        )
    } else {
        let top: Vec<String> = analysis
            .evidence
            .iter()
            .take(3)
            .map(|e| {
                format!(
                    "{} ({:.0}% of the excess{})",
                    effect_name(e.effect),
                    100.0 * e.explained_fraction,
                    if e.significant { ", flagged" } else { "" }
                )
            })
            .collect();
        (
            "unexplained_residual",
            format!(
                "the residual exceeds the noise (ratio {:.3}, excess {:.3}, p = {:.2e}) and no tested effect explains it significantly; strongest signatures: {}",
                final_errors.residual_to_noise,
                analysis.significance.excess_ratio,
                analysis.significance.p_value,
                if top.is_empty() { "none".into() } else { top.join("; ") }
            ),
        )
    };
    timings.push(StageTime {
        stage: "total".into(),
        seconds: t0.elapsed().as_secs_f64(),
    });
    let summary = Summary {
        schema: SCHEMA.into(),
        version: VERSION,
        command: command.into(),
        data: DataSummary {
            path: path.into(),
            ny: band.ny(),
            nu: band.nu(),
            lines: band.n_lines(),
            band_hz: [band.freq_hz(0), band.freq_hz(band.n_lines() - 1)],
            units: band.units.clone(),
            noise_source: match &noise.source {
                NoiseSource::Measured => "measured (_var columns)".into(),
                NoiseSource::Estimated { method } => format!("estimated: {method}"),
            },
            frf_type: cfg.frf_type.name().into(),
        },
        initial: InitialSummary {
            modes: mode_summaries(&initial_model),
            cmif_peaks: fitter_report
                .cmif_peaks
                .iter()
                .map(|p| PeakSummary {
                    f_hz: p.f_hz,
                    sv_index: p.sv_index,
                    prominence: p.prominence,
                })
                .collect(),
            errors: initial_errors,
            declared: declared_list,
        },
        steps,
        verdict: verdict.into(),
        verdict_evidence,
        final_model: final_model_summary(&fit),
        final_errors,
        data_noise_median_rel: matches!(noise.source, NoiseSource::Measured)
            .then(|| data_noise_rel(&band, &noise))
            .flatten(),
        timings,
        chain: chain_names.clone(),
    };
    let peaks = fitter_report.cmif_peaks.clone();
    Ok(PipelineOutput {
        band,
        fit,
        fitter_report,
        chain: chain_names,
        links: chain_links,
        noise,
        cmif: c,
        peaks,
        initial_response,
        final_response,
        step_responses,
        summary,
    })
}
