//! The summary of a run (`summary.json`): the error statistics of a model against the
//! data, the final model briefly, and the verdict from the final residual analysis.

use super::config::{PipelineConfig, NOT_ANALYSED};
use super::context::FitContext;
use crate::effects::{ModeParams, Repair};
use crate::summary::*;
use crate::FrfitError;
use additive_riv::{AdditiveModel, FactorTarget, FitterReport};
use frf_data::{Fit, Frf, FrfDataset};
use realize::ResponseGrid;
use validation::analysis::ResidualAnalysis;
use validation::distortion::residual_ratio;
use validation::noise::{NoiseLevel, NoiseSource};

/// Error statistics of `model` against `data` with `noise`.
pub(crate) fn error_stats(data: &Frf, response: &ResponseGrid, noise: &NoiseLevel) -> ErrorStats {
    let m = data.n_entries();
    let mut rel = Vec::with_capacity(data.n_lines() * m);
    let mut chi = 0.0;
    let mut cnt = 0usize;
    // squared magnitudes throughout (no `hypot` per value, a third of this function's
    // time on the wafer stage): the quantiles of the squared ratios are the squares of
    // the ratios' quantiles
    for k in 0..data.n_lines() {
        let g = data.line(k);
        let p = response.line(k);
        for e in 0..m {
            let d2 = (g[e] - p[e]).norm_sqr();
            let g2 = g[e].norm_sqr();
            if g2 > 0.0 {
                rel.push(d2 / g2);
            }
            let v = noise.variance[k * m + e];
            if v > 0.0 && v.is_finite() {
                chi += d2 / v;
                cnt += 1;
            }
        }
    }
    // the order statistics at the two quantiles by selection, not a full sort (tens of
    // millions of values at 50 x 50 entries): the 95 % one first, then the median among
    // the values below it
    let at = |p: f64| ((rel.len().max(1) - 1) as f64 * p).round() as usize;
    let (i50, i95) = (at(0.5), at(0.95));
    let (median_rel, p95_rel) = if rel.is_empty() {
        (f64::NAN, f64::NAN)
    } else {
        let (below, &mut p95, _) = rel.select_nth_unstable_by(i95, |a, b| a.total_cmp(b));
        let median = if i50 == i95 {
            p95
        } else {
            *below.select_nth_unstable_by(i50, |a, b| a.total_cmp(b)).1
        };
        (median.sqrt(), p95.sqrt())
    };
    ErrorStats {
        median_rel,
        p95_rel,
        residual_to_noise: if cnt > 0 {
            (chi / cnt as f64).sqrt()
        } else {
            f64::NAN
        },
    }
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
        rigid_body_integrators: model.integrators(),
        feedthrough: model.has_feedthrough(),
        dynamics: model
            .dynamics
            .iter()
            .map(|d| {
                let target = factor_target_name(d.target);
                let roots = |r: Vec<realize::C64>| -> String {
                    r.iter()
                        .filter(|p| p.im >= 0.0)
                        .map(|p| match p.im {
                            0.0 => format!("{:.1} Hz", p.norm() / std::f64::consts::TAU),
                            _ => format!(
                                "{:.1} Hz (zeta {:.3})",
                                p.norm() / std::f64::consts::TAU,
                                -p.re / p.norm()
                            ),
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let mut s = format!("{target}: poles at {}", roots(d.poles()));
                if !d.num.is_empty() {
                    s.push_str(&format!(", zeros at {}", roots(d.zeros())));
                    if d.is_non_minimum_phase() {
                        s.push_str(" (non-minimum phase)");
                    }
                }
                s
            })
            .collect(),
        iterations: fit.iterations,
        convergence: fit.convergence.describe(),
    }
}

/// A residual "matches" the line-to-line floor when its robust level (the median of
/// `|G - P|^2 / floor` over `ln 2`, the statistic of the floor itself) is within
/// `[MIN_RESIDUAL_TO_FLOOR, MAX_RESIDUAL_TO_FLOOR]` times the local floor: from
/// `1 / sqrt 2` to `sqrt 3` in amplitude. The local floor is itself an estimate (a
/// median of about 16 independent stencils per window, +-30 %), and the model, fitted
/// with weights from a variance that missed the distortion, need not reach it
/// everywhere: on the motor bench the residual is 2.3 times the floor overall, at the
/// floor above 100 Hz and up to 25 times it around the antiresonance and resonance
/// (47-95 Hz), which the evidence then reports. A residual far below the floor means
/// the floor holds signal (curvature of the response) rather than jitter. Lines where the
/// residual still stands above the floor locally (the localized test of
/// `validation::residual` against the floor) are reported with the verdict.
pub const MIN_RESIDUAL_TO_FLOOR: f64 = 0.5;
/// See [`MIN_RESIDUAL_TO_FLOOR`].
pub const MAX_RESIDUAL_TO_FLOOR: f64 = 3.0;

/// The evidence on distortion: the floor of `ctx`, and the final residual `response`
/// against the measured variance and the floor.
pub(crate) fn distortion_summary(
    ctx: &FitContext,
    response: &ResponseGrid,
) -> Option<DistortionSummary> {
    let fl = ctx.line_floor.as_ref()?;
    let band = &ctx.band;
    let m = band.n_entries();
    let mut residual = Vec::with_capacity(band.n_lines() * m);
    for k in 0..band.n_lines() {
        let g = band.line(k);
        let p = response.line(k);
        residual.extend(g.iter().zip(p).map(|(a, b)| a - b));
    }
    let r = residual_ratio(&residual, &ctx.noise);
    let rf = residual_ratio(&residual, ctx.floor_noise.as_ref()?);
    Some(DistortionSummary {
        order: fl.order,
        floor_to_variance: fl.ratio,
        floor_to_variance_lower: fl.ratio_lower,
        min_ratio: fl.min_ratio,
        exceeds: fl.exceeds,
        variance_median_rel: fl.declared_median_rel,
        floor_median_rel: fl.floor_median_rel,
        residual_to_variance: r,
        residual_to_floor: rf,
        loop_against_floor: ctx.distortion_noise().is_some(),
    })
}

/// The verdict on the final residual: `noise_limited` when it is at the noise level;
/// `nonlinear_distortion` when it is not, but the data's line-to-line floor
/// significantly exceeds the measured variance and the residual matches that floor
/// (within [`MIN_RESIDUAL_TO_FLOOR`]..[`MAX_RESIDUAL_TO_FLOOR`] of it; `floor_analysis`,
/// the residual analysis against the local floor, adds what still stands above it);
/// else `unexplained_residual` with the strongest signatures; with the numbers.
fn verdict(
    analysis: &ResidualAnalysis,
    floor_analysis: Option<&ResidualAnalysis>,
    distortion: Option<&DistortionSummary>,
    final_errors: &ErrorStats,
    nonlinear: Option<&super::nonlinear::NonlinearTest>,
) -> (ResidualVerdict, String) {
    match nonlinear {
        // the residual at the level of a total variance whose nonlinear part is
        // significant: the model is at what a linear model can reach
        Some(t) if !analysis.significant && t.significant => {
            return (
                ResidualVerdict::NonlinearDistortion,
                format!(
                    "the residual is at the level of the total variance (noise and stochastic nonlinear distortion over the realizations): residual-to-noise ratio {:.3} (excess {:.3} of the calibrated energy, p = {:.2e}); {}. No linear model gets closer; more realizations measure the distortion more precisely but do not remove it",
                    final_errors.residual_to_noise,
                    analysis.significance.excess_ratio,
                    analysis.significance.p_value,
                    t.describe()
                ),
            );
        }
        _ => {}
    }
    if !analysis.significant {
        return (
            ResidualVerdict::NoiseLimited,
            format!(
                "the residual is at the noise level: residual-to-noise ratio {:.3} (excess {:.3} of the calibrated noise energy, p = {:.2e})",
                final_errors.residual_to_noise, analysis.significance.excess_ratio, analysis.significance.p_value
            ),
        );
    }
    if let Some(d) = distortion {
        if d.exceeds
            && (MIN_RESIDUAL_TO_FLOOR..=MAX_RESIDUAL_TO_FLOOR).contains(&d.residual_to_floor)
        {
            let local = match floor_analysis {
                Some(fa) if fa.significant => format!(
                    " Against the local floor the residual still stands out (level {:.2} of it{}); strongest signatures there: {}.",
                    fa.significance.level_ratio,
                    if fa.significance.localized {
                        format!(", {} lines of localized excess", fa.significance.localized_lines)
                    } else {
                        String::new()
                    },
                    top_signatures(fa)
                ),
                Some(_) => " Against the local floor the residual is not significant.".into(),
                None => String::new(),
            };
            return (
                ResidualVerdict::NonlinearDistortion,
                format!(
                    "the residual exceeds the measured variance (residual-to-noise ratio {:.3}, p = {:.2e}) but sits at the data's own line-to-line floor: \
                     floor / variance {:.2} (order-{} differences across adjacent lines, model-free; lower bound {:.2}, threshold {}), \
                     residual / variance {:.2}, residual / local floor {:.2} (matches within {}..{}). \
                     The data scatter from line to line {:.1} times more (in amplitude) than the variance says: stochastic nonlinear distortion, \
                     fixed over the periods of one realization and so absent from a variance estimated over them. No linear effect explains it; \
                     averaging over more random-phase realizations reduces it and measures it in the variance.{local}",
                    final_errors.residual_to_noise,
                    analysis.significance.p_value,
                    d.floor_to_variance,
                    d.order,
                    d.floor_to_variance_lower,
                    d.min_ratio,
                    d.residual_to_variance,
                    d.residual_to_floor,
                    MIN_RESIDUAL_TO_FLOOR,
                    MAX_RESIDUAL_TO_FLOOR,
                    d.floor_to_variance.sqrt(),
                ),
            );
        }
    }
    let floor_note = match distortion {
        Some(d) if d.exceeds => format!(
            "; the data's line-to-line floor exceeds the measured variance (floor / variance {:.2}) but the residual stands above it (residual / floor {:.2})",
            d.floor_to_variance, d.residual_to_floor
        ),
        _ => String::new(),
    };
    (
        ResidualVerdict::UnexplainedResidual,
        format!(
            "the residual exceeds the noise (ratio {:.3}, excess {:.3}, p = {:.2e}) and no tested effect explains it significantly; strongest signatures: {}{floor_note}",
            final_errors.residual_to_noise,
            analysis.significance.excess_ratio,
            analysis.significance.p_value,
            top_signatures(analysis)
        ),
    )
}

/// The three strongest effect signatures of `analysis`, in words.
fn top_signatures(analysis: &ResidualAnalysis) -> String {
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
    if top.is_empty() {
        "none".into()
    } else {
        top.join("; ")
    }
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
    /// The restart that replaced the chain's first fit, when one did.
    pub restart: Option<crate::summary::RestartSummary>,
    /// The diagnosis steps.
    pub steps: Vec<StepSummary>,
    /// The final fit.
    pub fit: &'a Fit<AdditiveModel>,
    /// The residual analysis of the final model; `None` when
    /// [`PipelineConfig::final_analysis`] is off.
    pub analysis: Option<&'a ResidualAnalysis>,
    /// The same against the variance raised to the local line-to-line floor, when the floor
    /// exceeds the variance and the residual is significant against the variance.
    pub floor_analysis: Option<&'a ResidualAnalysis>,
    /// The evidence on distortion (see [`distortion_summary`]).
    pub distortion: Option<DistortionSummary>,
    /// The final model's errors.
    pub final_errors: ErrorStats,
    /// Time per stage.
    pub timings: Vec<StageTime>,
    /// The estimator chain of the first fit.
    pub chain: Vec<String>,
    /// The structure steps of the first fit's refiners ([`structure_steps`]).
    pub structure_steps: Vec<crate::summary::StructureStepSummary>,
    /// Every chain tried by a multi-initialiser first fit.
    pub chain_runs: Vec<crate::chain::ChainRun>,
    /// The refiner's uncertainty of the final model, when it has one.
    pub uncertainty: Option<UncertaintySummary>,
    /// The diagnosis ran again from `fit`'s model (`crate::run`'s `from_fit`).
    pub from_fit: Option<crate::summary::FromFitSummary>,
}

/// The uncertainty of the ML link of `links` (its report in `details`), for a final
/// model that is the chain's own (`frfit fit`, no diagnosis steps).
pub(crate) fn ml_uncertainty(links: &[frf_data::LinkReport]) -> Option<UncertaintySummary> {
    let l = links.iter().rev().find(|l| l.link == "ml")?;
    let r = l.details_as::<ml_refine::MlReport>()?;
    Some(uncertainty_summary(ML_METHOD, r))
}

/// The structure steps of the first fit's refiners: the refined-IV structure
/// adaptation's (`adapt`, from the fitter's report) and those of the last ML link of
/// `links` (the refinement whose model the chain returned), in that order.
pub(crate) fn structure_steps(
    adapt: Option<&additive_riv::structure::AdaptReport>,
    links: &[frf_data::LinkReport],
) -> Vec<crate::summary::StructureStepSummary> {
    let tagged = |link: &str, steps: &[frf_data::structure::StructureStep]| {
        steps
            .iter()
            .map(|step| crate::summary::StructureStepSummary {
                link: link.to_string(),
                step: step.clone(),
            })
            .collect::<Vec<_>>()
    };
    let mut out = adapt.map_or_else(Vec::new, |a| tagged("riv", &a.steps));
    if let Some(r) = links
        .iter()
        .rev()
        .find(|l| l.link == "ml")
        .and_then(|l| l.details_as::<ml_refine::MlReport>())
    {
        out.extend(tagged("ml", &r.structure_steps));
    }
    out
}

/// [`UncertaintySummary::method`] of the ML refiner's covariance at its own optimum.
pub const ML_METHOD: &str = "ml";
/// [`UncertaintySummary::method`] of the information of the ML criterion at the final
/// model of any other chain or of a diagnosis ([`information_uncertainty`]).
pub const INFORMATION_METHOD: &str = "information";

fn uncertainty_summary(method: &str, r: &ml_refine::MlReport) -> UncertaintySummary {
    let mut modes: Vec<ModeUncertaintySummary> = r.modes.clone();
    let factors = r
        .factors
        .iter()
        .map(|f| crate::summary::FactorUncertaintySummary {
            target: factor_target_name(f.target),
            poles: f.poles.clone(),
            zeros: f.zeros.clone(),
        })
        .collect();
    modes.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
    UncertaintySummary {
        method: method.into(),
        noise: r.noise.clone(),
        cost_ratio: r.cost_ratio,
        expected_ratio: r.expected_ratio,
        p_value: r.p_value,
        covariance_scale: r.covariance_scale,
        modes,
        delay_s: r.delay_s,
        delay_s_std: r.delay_s_std,
        factors,
    }
}

/// The uncertainty of `model` (the final model of a chain without an ML link, or of a
/// diagnosis) from the information matrix of the maximum-likelihood criterion at it
/// ([`ml_refine::MlRefine::uncertainty_at`]), on the band's data with the fit's
/// weighting and the stated realizations: the asymptotic covariance of an estimate at
/// the ML optimum to first order (the refined IV estimate is asymptotically efficient),
/// scaled up by the cost ratio when the residual exceeds the noise. An error in words
/// when the model has no covariance (an unstable pole, a parameter the data do not
/// determine).
pub(crate) fn information_uncertainty(
    ctx: &FitContext,
    model: &AdditiveModel,
) -> Result<UncertaintySummary, String> {
    use frf_data::ModelStructure;
    let fm = model.to_frf_model().map_err(|e| e.to_string())?;
    let ml = information_refiner(ctx);
    let r = ml
        .uncertainty_at(&ctx.band, &fm)
        .map_err(|e| e.to_string())?;
    Ok(uncertainty_summary(INFORMATION_METHOD, &r))
}

/// [`information_uncertainty`] and, for `entries`, [`response_std`] from one information
/// matrix at `model` (one evaluation, Jacobian and factorisation instead of two).
pub(crate) fn information_uncertainty_and_response_std(
    ctx: &FitContext,
    model: &AdditiveModel,
    entries: &[usize],
) -> Result<(UncertaintySummary, Vec<f64>), String> {
    use frf_data::ModelStructure;
    let fm = model.to_frf_model().map_err(|e| e.to_string())?;
    let (r, std) = information_refiner(ctx)
        .uncertainty_and_response_std_at(&ctx.band, &fm, Some(entries))
        .map_err(|e| e.to_string())?;
    Ok((uncertainty_summary(INFORMATION_METHOD, &r), std))
}

/// The standard deviation of `model`'s response at the band's lines and entries
/// (layout `[k * m + e]`) from the information of the ML criterion at it (the band on
/// the report's plots, [`ml_refine::MlRefine::response_std_at`]); the error in words
/// when no covariance can be formed.
pub(crate) fn response_std(
    ctx: &FitContext,
    model: &AdditiveModel,
    entries: &[usize],
) -> Result<Vec<f64>, String> {
    use frf_data::ModelStructure;
    let fm = model.to_frf_model().map_err(|e| e.to_string())?;
    information_refiner(ctx)
        .response_std_at(&ctx.band, &fm, Some(entries))
        .map_err(|e| e.to_string())
}

/// The standard deviation of `model`'s response at the frequencies `omega` (rad/s),
/// every entry (layout `[k * m + e]`), from the information of the ML criterion on the
/// data it was fitted to: `fit_data` set up as a run with `cfg` sets it up (the band,
/// the pooled variance, the weighting and the stated realizations;
/// [`ml_refine::MlRefine::response_std_at_omegas`]). It is the model's own estimation
/// uncertainty at other lines, e.g. those of an independent validation measurement
/// ([`crate::validation::validate_frf_with_model_std`]). Errors: the band or fit data
/// cannot be formed, or no covariance can be formed at `model` (an unstable pole, a
/// parameter the data do not determine), said in words.
pub fn model_response_std_at(
    model: &AdditiveModel,
    fit_data: &frf_data::Frf,
    cfg: &PipelineConfig,
    omega: &[f64],
) -> Result<Vec<f64>, FrfitError> {
    use frf_data::ModelStructure;
    // the band and its weights only: no delay estimate, no final analysis
    let setup = PipelineConfig {
        band_hz: cfg.band_hz,
        hold: cfg.hold,
        fs_hz: cfg.fs_hz,
        frf_type: cfg.frf_type,
        weighting: cfg.weighting.clone(),
        delay: Some(additive_riv::DelayChoice::None),
        final_analysis: false,
        ..PipelineConfig::default()
    };
    let ctx = FitContext::new(fit_data, &setup)?;
    let why = |e: String| FrfitError::Fit {
        what: "the model's response uncertainty".into(),
        why: e,
    };
    let fm = model.to_frf_model().map_err(|e| why(e.to_string()))?;
    information_refiner(&ctx)
        .response_std_at_omegas(&ctx.band, &fm, omega)
        .map_err(|e| why(e.to_string()))
}

/// The ML refiner whose criterion the information at a final model is formed of: the
/// fit's weighting and the degrees of freedom of the data's variance (the cost test's
/// expectation and the sample-variance factor of the covariance).
fn information_refiner(ctx: &FitContext) -> ml_refine::MlRefine {
    ml_refine::MlRefine::new(ml_refine::MlConfig {
        weighting: ctx.weighting.clone(),
        realizations: ctx.declared.realizations,
        variance_dof: ctx.variance_dof,
        ..Default::default()
    })
}

/// The summary of a run on `ctx` with `cfg`.
pub(crate) fn build_summary(ctx: &FitContext, cfg: &PipelineConfig, run: RunRecord) -> Summary {
    let band = &ctx.band;
    let noise = &ctx.noise;
    let (verdict, verdict_evidence) = match run.analysis {
        Some(a) => verdict(
            a,
            run.floor_analysis,
            run.distortion.as_ref(),
            &run.final_errors,
            ctx.nonlinear.as_ref(),
        ),
        None => (
            NOT_ANALYSED,
            "the final residual analysis was not run (`frfit fit` without `--report`)".into(),
        ),
    };
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
            restart: run.restart,
            repairs: repair_summaries(run.fitter_report.repair.as_ref()),
            structure_steps: run.structure_steps,
            from_fit: run.from_fit,
        },
        steps: run.steps,
        verdict,
        verdict_evidence,
        final_model: final_model_summary(run.fit),
        final_errors: run.final_errors,
        data_noise_median_rel: matches!(noise.source, NoiseSource::Measured)
            .then(|| {
                // the analysis reads it from the same noise and band
                run.analysis
                    .map_or_else(|| noise.median_relative(band), |a| a.median_noise_rel)
            })
            .filter(|v| v.is_finite()),
        timings: run.timings,
        chain: run.chain,
        chain_runs: run.chain_runs,
        uncertainty: run.uncertainty,
        distortion: run.distortion,
    }
}

/// A repair's recorded cost before and after (`None` for one read from a report
/// written before it was recorded: both zero).
fn cost_change((before, after): (f64, f64)) -> Option<crate::summary::CostChange> {
    (before > 0.0).then_some(crate::summary::CostChange { before, after })
}

/// What a dynamics factor multiplies, in the summary's words: `input J`, `output I`
/// (1-based, as the steps name them) or `all entries`.
fn factor_target_name(target: FactorTarget) -> String {
    match target {
        FactorTarget::Input(j) => format!("input {}", j + 1),
        FactorTarget::Output(i) => format!("output {}", i + 1),
        FactorTarget::All => "all entries".into(),
    }
}

/// The first fit's repairs ([`additive_riv::split`]) as summary entries.
fn repair_summaries(r: Option<&additive_riv::split::RepairReport>) -> Vec<RepairSummary> {
    let Some(r) = r else {
        return Vec::new();
    };
    let mut out: Vec<RepairSummary> = r
        .out_of_band
        .iter()
        .map(|m| RepairSummary {
            repair: Repair::OutOfBandMode {
                f_hz: m.f_hz,
                zeta: m.zeta,
                edge: m.edge.clone(),
                feedthrough_cost_ratio: m.feedthrough_cost_ratio,
            },
            f_statistic: m.f_stat,
            cost: cost_change(m.cost),
        })
        .collect();
    out.extend(r.splits.iter().map(|s| RepairSummary {
        repair: Repair::ClosePair {
            from_hz: s.from_hz,
            modes: s.into.map(|(f_hz, zeta)| ModeParams { f_hz, zeta }),
        },
        f_statistic: s.f_stat,
        cost: cost_change(s.cost),
    }));
    out
}
