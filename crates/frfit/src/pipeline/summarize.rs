//! The summary of a run (`summary.json`): the error statistics of a model against the
//! data, the final model briefly, and the verdict from the final residual analysis.

use super::{FitContext, PipelineConfig};
use crate::diagnose::effect_name;
use crate::summary::*;
use additive_riv::{AdditiveModel, FactorTarget, FitterReport, SubmodelKind};
use frf_data::{Fit, Frf, FrfDataset};
use realize::ResponseGrid;
use validation::noise::{NoiseLevel, NoiseSource};
use validation::residual::ResidualAnalysis;

/// Error statistics of `model` against `data` with `noise`.
pub(crate) fn error_stats(data: &Frf, response: &ResponseGrid, noise: &NoiseLevel) -> ErrorStats {
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

/// The verdict on the final residual: `noise_limited` when it is at the noise level,
/// else `unexplained_residual` with the strongest signatures; with the numbers.
fn verdict(analysis: &ResidualAnalysis, final_errors: &ErrorStats) -> (&'static str, String) {
    if !analysis.significant {
        return (
            "noise_limited",
            format!(
                "the residual is at the noise level: residual-to-noise ratio {:.3} (excess {:.3} of the calibrated noise energy, p = {:.2e})",
                final_errors.residual_to_noise, analysis.significance.excess_ratio, analysis.significance.p_value
            ),
        );
    }
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
}

/// What a run found, for its summary.
pub(crate) struct RunRecord<'a> {
    /// The data file.
    pub path: &'a str,
    /// `fit` or `diagnose`.
    pub command: &'a str,
    /// The first fit's model.
    pub initial_model: &'a AdditiveModel,
    /// What the first fit found (its CMIF peaks).
    pub fitter_report: &'a FitterReport,
    /// The first model's errors.
    pub initial_errors: ErrorStats,
    /// The diagnosis steps.
    pub steps: Vec<StepSummary>,
    /// The final fit.
    pub fit: &'a Fit<AdditiveModel>,
    /// The residual analysis of the final model.
    pub analysis: &'a ResidualAnalysis,
    /// The final model's errors.
    pub final_errors: ErrorStats,
    /// Time per stage.
    pub timings: Vec<StageTime>,
    /// The estimator chain of the first fit.
    pub chain: Vec<String>,
    /// Every chain tried by a multi-initialiser first fit.
    pub chain_runs: Vec<crate::chain::ChainRun>,
}

/// The summary of a run on `ctx` with `cfg`.
pub(crate) fn build_summary(ctx: &FitContext, cfg: &PipelineConfig, run: RunRecord) -> Summary {
    let band = &ctx.band;
    let noise = &ctx.noise;
    let (verdict, verdict_evidence) = verdict(run.analysis, &run.final_errors);
    Summary {
        schema: SCHEMA.into(),
        version: VERSION,
        command: run.command.into(),
        data: DataSummary {
            path: run.path.into(),
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
            modes: mode_summaries(run.initial_model),
            cmif_peaks: run
                .fitter_report
                .cmif_peaks
                .iter()
                .map(|p| PeakSummary {
                    f_hz: p.f_hz,
                    sv_index: p.sv_index,
                    prominence: p.prominence,
                })
                .collect(),
            errors: run.initial_errors,
            declared: ctx.declared_list.clone(),
        },
        steps: run.steps,
        verdict: verdict.into(),
        verdict_evidence,
        final_model: final_model_summary(run.fit),
        final_errors: run.final_errors,
        data_noise_median_rel: matches!(noise.source, NoiseSource::Measured)
            .then(|| data_noise_rel(band, noise))
            .flatten(),
        timings: run.timings,
        chain: run.chain,
        chain_runs: run.chain_runs,
    }
}
