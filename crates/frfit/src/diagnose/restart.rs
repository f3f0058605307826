//! Restarts are not effects.
//!
//! A delay large enough to matter also misplaces the modes fitted without it, so the
//! loop tests a delay by a fit from the start with the data's delay estimate (the
//! run's estimator chain, the delay refined). Such a restart can also land in a better
//! optimum for reasons that have nothing to do with the delay (a mode the CMIF start
//! merged, a different set of picked peaks): the delay it ends with is then the
//! model's own, and the cost it gains is the restart's. This module separates the two:
//! the restart is refitted with the delay held at the current model's value, and
//!
//! - when that held refit is significantly better than the first fit, it becomes the
//!   first fit (a better first fit, noted in its provenance, not a step);
//! - the `delay` step is the restart with the delay refined, tested against the held
//!   refit too: it passes only when the delay itself explains more than noise.

use super::candidate::delay_proposals;
use super::refit::{f_test, lacked_light_modes, light_in_band, model_cost};
use crate::pipeline::{
    chain_fit, err, FirstFit, FitContext, PipelineConfig, SECOND_START, SECOND_START_RESIDUAL,
};
use crate::summary::RestartSummary;
use crate::FrfitError;
use additive_riv::riv::iterate;
use additive_riv::{fit_numerators, AdditiveModel, DelayChoice};
use frf_data::{Fit, ModelStructure};
use validation::analysis::analyze_residual;

/// A fit from the start with the data's delay estimate, and the same restart with the
/// delay held at the model's value before it.
#[derive(Debug, Clone)]
pub struct DelayRestart {
    /// The chain from the start with the delay estimated from the data and refined.
    pub with_delay: AdditiveModel,
    /// Its weighted cost.
    pub with_delay_cost: f64,
    /// `with_delay` refitted with its delay held at the model's delay before the
    /// restart: what the restart gives without a new delay.
    pub held: Option<(Fit<AdditiveModel>, f64)>,
    /// The data's delay estimate the restart started from, seconds.
    pub estimate_s: Option<f64>,
    /// The delay `held` holds, seconds.
    pub held_delay_s: f64,
}

/// The restart from the start with the data's delay estimate, and its refit with the
/// delay held at `held_delay_s` (the delay of the model it is tested against, not
/// fitted). `None` when the chain fails or ends without a fitted delay.
pub fn delay_restart(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    held_delay_s: f64,
) -> Option<DelayRestart> {
    let fd = &ctx.fit_data;
    let fc = additive_riv::FitterConfig {
        delay: DelayChoice::Auto,
        ..ctx.quiet_fitter_config(cfg)
    };
    let first = chain_fit(ctx, cfg, &fc).ok()?;
    let m = first.fit.model;
    if !m.factor.fit_delay {
        return None;
    }
    let c = model_cost(&m, fd);
    let mut held = m.clone();
    held.factor.fit_delay = false;
    held.factor.delay_s = held_delay_s;
    let held = fit_numerators(&mut held, fd)
        .ok()
        .and_then(|_| iterate(held, fd, &fc.riv).ok())
        .map(|f| {
            let c = model_cost(&f.model, fd);
            (f, c)
        });
    Some(DelayRestart {
        with_delay: m,
        with_delay_cost: c,
        held,
        // the chain's own estimate, or the band's that the chain was handed
        estimate_s: first
            .report
            .delay_estimate
            .as_ref()
            .or(ctx.delay_estimate.as_ref())
            .map(|d| d.tau_s),
        held_delay_s,
    })
}

/// What [`better_first_fit`] found.
pub struct Restarted {
    /// The first fit: the chain's, or the restart that is significantly better.
    pub fit: Fit<AdditiveModel>,
    /// The restart that replaced the chain's first fit, when one did.
    pub summary: Option<RestartSummary>,
    /// The delay restart, for the loop's `delay` trial (computed once).
    pub delay: Option<DelayRestart>,
    /// The common-denominator start alone ([`common_denominator_start`]), when the
    /// restart of a first fit that lost modes made it: the loop's common-denominator
    /// modes read the same start.
    pub sk_start: Option<AdditiveModel>,
}

/// The [`SECOND_START`] (common-denominator) initialiser on the band of `ctx`, refined
/// by `refine` (`"none"`: the start alone, a second or two on the wafer stage), quietly,
/// with the run's hold, delay and weighting.
pub(super) fn common_denominator_start(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    refine: &str,
) -> Result<FirstFit, FrfitError> {
    let c = PipelineConfig {
        init: SECOND_START.to_string(),
        refine: refine.to_string(),
        ..cfg.clone()
    };
    chain_fit(ctx, &c, &ctx.quiet_fitter_config(&c))
}

/// The delay the first fit will hold when the data's own delay estimate is far enough
/// from it to misplace its modes (a phase error above 0.05 rad, about 3 degrees, at the
/// band's top line): then [`delay_restart`] is worth running beside the first fit
/// ([`crate::run::run`] does so in parallel). `None` when the first fit fits the
/// delay itself, the data have no delay estimate, or the two agree.
pub fn worth_a_delay_restart(ctx: &FitContext) -> Option<f64> {
    let held = match ctx.delay {
        DelayChoice::Fixed { seconds } => seconds,
        DelayChoice::None => 0.0,
        _ => return None,
    };
    let hold_half = match ctx.hold {
        Some(additive_riv::Hold::Zoh { fs_hz }) => 0.5 / fs_hz,
        _ => 0.0,
    };
    let total = ctx.data_delay_s()?;
    let w_top = ctx.omega.iter().copied().fold(0.0_f64, f64::max);
    ((total - hold_half - held).abs() * w_top > 0.05).then_some(held)
}

/// Tests restarts of the first fit before the diagnosis loop, in turn:
///
/// 1. when the first fit's residual is significant and calls for a delay (the
///    residual's or the data's phase slope), the fit from the start with the data's
///    delay estimate, refitted with the delay held at the first fit's value
///    ([`delay_restarted`]);
/// 2. when the fit is then still far above the noise, the chain from the
///    common-denominator start ([`common_denominator_restart`]).
///
/// A restart replaces the first fit when its F test (the cost decrease per added
/// parameter, at least one, at `cfg.alpha`) passes. The delay restart (`speculative`
/// when it was made beside the first fit and holds the first fit's delay) is returned
/// for the loop's `delay` trial. `cmif_peaks`: the peaks the first fit's chain started
/// from (0 when it did not start from the CMIF). `repaired_modes`: the modes the first
/// fit holds after the repairs the loop will test on it (a first fit with declared modes
/// makes none itself: close pairs merged by the start are then modes the loop adds, not
/// modes the first fit lost; [`super::first_repairs`]).
pub fn better_first_fit(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    first: Fit<AdditiveModel>,
    speculative: Option<DelayRestart>,
    cmif_peaks: usize,
    repaired_modes: Option<usize>,
) -> Result<Restarted, FrfitError> {
    let unchanged = first.model.modes().len();
    let restarted = delay_restarted(ctx, cfg, first, speculative)?;
    // the repairs were counted on the first fit: a delay restart that replaced it is
    // counted as it is
    let repaired = repaired_modes.filter(|_| restarted.summary.is_none());
    let modes = restarted
        .fit
        .model
        .modes()
        .len()
        .max(repaired.unwrap_or(unchanged));
    common_denominator_restart(ctx, cfg, restarted, cmif_peaks, modes)
}

/// The first restart of [`better_first_fit`]: from the data's delay estimate.
fn delay_restarted(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    first: Fit<AdditiveModel>,
    speculative: Option<DelayRestart>,
) -> Result<Restarted, FrfitError> {
    let unchanged = |fit| Restarted {
        fit,
        summary: None,
        delay: None,
        sk_start: None,
    };
    if first.model.factor.fit_delay {
        return Ok(unchanged(first));
    }
    let fd = &ctx.fit_data;
    let response = first.model.response_at(&ctx.omega);
    let an = analyze_residual(
        &ctx.band,
        &response,
        ctx.judging_noise(),
        &ctx.residual_config(&first.model),
    )
    .map_err(err("residual analysis"))?;
    if !an.significant {
        return Ok(unchanged(first));
    }
    // the delay candidates alone: the others' screening is the loop's work
    let calls_for_delay =
        !delay_proposals(&first.model, &an, cfg.alpha, &[], ctx.data_delay_s()).is_empty();
    if !calls_for_delay {
        return Ok(unchanged(first));
    }
    let held_delay = first.model.factor.delay_s;
    let restart = match speculative {
        Some(r) if r.held_delay_s == held_delay => Some(r),
        _ => delay_restart(ctx, cfg, held_delay),
    };
    let Some(restart) = restart else {
        return Ok(unchanged(first));
    };
    let cost = model_cost(&first.model, fd);
    let Some((held, held_cost)) = restart.held.clone() else {
        return Ok(Restarted {
            fit: first,
            summary: None,
            delay: Some(restart),
            sk_start: None,
        });
    };
    let added = held
        .model
        .n_params()
        .saturating_sub(first.model.n_params())
        .max(1);
    let (_, f, f_crit) = f_test(&held.model, fd, cost, held_cost, added, cfg);
    if !(held_cost < cost && f > f_crit) {
        return Ok(Restarted {
            fit: first,
            summary: None,
            delay: Some(restart),
            sk_start: None,
        });
    }
    let before = crate::pipeline::error_stats(&ctx.band, &response, &ctx.noise);
    let from = format!(
        "the estimator chain from the start with the data's delay estimate ({}), the delay then held at {:.2} us",
        restart
            .estimate_s
            .map_or("none could be made".to_string(), |t| format!("{:.2} us", t * 1e6)),
        first.model.factor.delay_s * 1e6
    );
    let summary = RestartSummary {
        from: from.clone(),
        replaced_modes: first.model.modes().len(),
        replaced_errors: before,
        f_statistic: f,
        f_critical: f_crit,
    };
    let mut fit = first;
    fit.messages.push(format!(
        "first fit: a restart from {from} is significantly better (F = {f:.3e} > {f_crit:.3}); it replaces the chain's first fit ({} -> {} modes)",
        fit.model.modes().len(),
        held.model.modes().len()
    ));
    fit.model = held.model;
    fit.cost_history = held.cost_history;
    fit.iterations += held.iterations;
    fit.convergence = held.convergence;
    fit.timings.extend(held.timings);
    fit.estimator = format!(
        "{} (restarted from the data's delay estimate)",
        fit.estimator
    );
    Ok(Restarted {
        fit,
        summary: Some(summary),
        delay: Some(restart),
        sk_start: None,
    })
}

/// Lightly damped modes in the band that the common-denominator start must hold beyond
/// the first fit's for [`common_denominator_restart`] to replace it: one missed mode is
/// the loop's `missed_mode` trial to add; a start that lost several is broken.
const MIN_RECOVERED: usize = 2;

/// The second restart of [`better_first_fit`]: the default chain's refiner from the
/// common-denominator (Sanathanan-Koerner) start, which sees every mode of the band at
/// once instead of picking CMIF peaks, for a first fit that lost modes.
///
/// An undeclared effect the nominal model cannot hold (a sensor resonance on one row
/// just below a mode: residues no longer purely imaginary) can drive the CMIF start's
/// structure adaptation into an optimum with modes missing (the simulated stage of seed
/// 5 with a resonance 3 % below its seventh mode: 8 of 17 modes, 2460 times the noise),
/// from which no single catalogue effect passes; the common-denominator start keeps the
/// modes, and the loop then names the effect. But a common denominator also takes up
/// the undeclared effects themselves (a delay in spurious poles, a suspension as a
/// mode, a feedthrough in a mode's residues), which are the loop's to name. So the
/// restart is a repair of a first fit that lost modes, not a second opinion:
///
/// - it runs when the first fit (after the delay restart) is more than
///   [`SECOND_START_RESIDUAL`] times the noise the loop judges by and holds at least
///   [`MIN_RECOVERED`] modes fewer than the `cmif_peaks` its chain started from
///   (`modes`: its modes, or more after the repairs the loop tests on it; its
///   refinement lost modes the CMIF showed: with a residual far above the noise, the
///   structure adaptation's F tests drop true modes; a first fit that misplaced its
///   modes for an undeclared delay, or fits a distorted measurement with the modes
///   its CMIF shows, lost none);
/// - the start alone (no refinement: a second or two) must hold at least
///   [`MIN_RECOVERED`] more lightly damped modes (damping below
///   [`super::refit::LIGHT_DAMPING`]) in the band than the first fit, or the refinement
///   is not run;
/// - the refined restart replaces the first fit when it still holds that many more, is
///   significantly better (the F test of [`better_first_fit`]) and also fits better
///   than the delay restart with its delay refined (that delay is the loop's `delay`
///   step to test).
///
/// Without the count of lost modes the restart took up the effects it is meant to
/// leave to the loop: on `wafer_nominal.csv` without its declarations (the delay and
/// hold undeclared) it absorbed both in 18 modes at the noise level, and on the motor
/// bench it fitted the distortion with 6 modes where the loop finds a delay.
///
/// Only the default small-plant chain (`cmif` start, no `--init` given) is restarted:
/// an explicit start is kept, and above 100 entries the default chain starts from the
/// subspace step, which picks no peaks either.
fn common_denominator_restart(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    restarted: Restarted,
    cmif_peaks: usize,
    modes: usize,
) -> Result<Restarted, FrfitError> {
    let entries = frf_data::FrfDataset::ny(&ctx.band) * frf_data::FrfDataset::nu(&ctx.band);
    let (init, refine) = crate::pipeline::default_chain(&cfg.init, &cfg.refine, entries);
    if !cfg.init.trim().is_empty() || init != "cmif" {
        return Ok(restarted);
    }
    // the count of lost modes first: it needs no response
    if cmif_peaks.saturating_sub(modes) < MIN_RECOVERED {
        return Ok(restarted);
    }
    let Restarted {
        mut fit,
        summary,
        delay,
        sk_start: _,
    } = restarted;
    let kept = |fit, summary, delay, sk_start| {
        Ok(Restarted {
            fit,
            summary,
            delay,
            sk_start,
        })
    };
    let response = fit.model.response_at(&ctx.omega);
    let before = crate::pipeline::error_stats(&ctx.band, &response, ctx.judging_noise());
    if before.residual_to_noise.is_nan() || before.residual_to_noise <= SECOND_START_RESIDUAL {
        return kept(fit, summary, delay, None);
    }
    let band = ctx.fit_data.band_hz;
    let light = |m: &AdditiveModel| -> usize {
        m.modes()
            .iter()
            .filter(|x| light_in_band(x.f_hz, x.zeta, band))
            .count()
    };
    let n_first = light(&fit.model);
    // the lightly damped modes in the band beyond the first fit's, and those of them it
    // lacks
    let recovered = |m: &AdditiveModel| -> (usize, Vec<(f64, f64)>) {
        (
            light(m).saturating_sub(n_first),
            lacked_light_modes(&fit.model, m, band),
        )
    };
    let list = |v: &[(f64, f64)]| -> String {
        v.iter()
            .map(|(f, _)| format!("{f:.1}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let lead = format!(
        "first fit: {:.1} times the noise level ({} modes from {cmif_peaks} CMIF peaks)",
        before.residual_to_noise,
        fit.model.modes().len()
    );
    // the start alone first: a second or two, where the refinement costs tens
    let start = match common_denominator_start(ctx, cfg, "none") {
        Ok(s) => s.fit.model,
        Err(e) => {
            fit.messages.push(format!(
                "{lead}; the {SECOND_START} start failed ({e}): no restart from it"
            ));
            return kept(fit, summary, delay, None);
        }
    };
    let (more_in_start, in_start) = recovered(&start);
    if more_in_start < MIN_RECOVERED {
        fit.messages.push(format!(
            "{lead}; the {SECOND_START} start holds {more_in_start} lightly damped mode(s) in the band beyond its {n_first} (a restart needs {MIN_RECOVERED}): not restarted"
        ));
        return kept(fit, summary, delay, Some(start));
    }
    let fd = &ctx.fit_data;
    let chain = match common_denominator_start(ctx, cfg, &refine) {
        Ok(c) => c,
        Err(e) => {
            fit.messages.push(format!(
                "{lead}; the restart from the {SECOND_START} start failed ({e}): the first fit is kept"
            ));
            return kept(fit, summary, delay, Some(start));
        }
    };
    let cost = model_cost(&fit.model, fd);
    let restart_cost = model_cost(&chain.fit.model, fd);
    let added = chain
        .fit
        .model
        .n_params()
        .saturating_sub(fit.model.n_params())
        .max(1);
    let (_, f, f_crit) = f_test(&chain.fit.model, fd, cost, restart_cost, added, cfg);
    let delay_cost = delay.as_ref().map(|d| d.with_delay_cost);
    let beats_delay = delay_cost.is_none_or(|c| restart_cost < c);
    let (more_after, after) = recovered(&chain.fit.model);
    let from = format!("the {} chain from the start", chain.chain.join(" -> "));
    if !(restart_cost < cost && f > f_crit && beats_delay && more_after >= MIN_RECOVERED) {
        let why = if more_after < MIN_RECOVERED {
            format!(
                "after the refinement it holds {more_after} lightly damped mode(s) in the band beyond the first fit's {n_first}"
            )
        } else if !beats_delay {
            format!(
                "the restart with the data's delay estimate, its delay refined, ends lower ({:.4e}): the delay is the loop's to test",
                delay_cost.unwrap_or(f64::NAN)
            )
        } else {
            format!("F = {f:.3e} against {f_crit:.3}")
        };
        fit.messages.push(format!(
            "{lead}; a restart from {from} (its start holds modes the first fit lacks at {} Hz) ended at cost {restart_cost:.4e} against {cost:.4e} with {} modes and is not kept: {why}",
            list(&in_start),
            chain.fit.model.modes().len()
        ));
        return kept(fit, summary, delay, Some(start));
    }
    let from = match &summary {
        Some(s) => format!("{from} (after a restart from {})", s.from),
        None => from,
    };
    let new_summary = RestartSummary {
        from: from.clone(),
        replaced_modes: fit.model.modes().len(),
        replaced_errors: crate::pipeline::error_stats(&ctx.band, &response, &ctx.noise),
        f_statistic: f,
        f_critical: f_crit,
    };
    let mut messages = std::mem::take(&mut fit.messages);
    messages.push(format!(
        "{lead}; a restart from {from} holds the modes it lacks at {} Hz and is significantly better (cost {cost:.4e} -> {restart_cost:.4e}, F = {f:.3e} > {f_crit:.3}): it replaces the first fit ({} -> {} modes)",
        list(&after),
        fit.model.modes().len(),
        chain.fit.model.modes().len()
    ));
    let mut new_fit = chain.fit;
    messages.extend(new_fit.messages.drain(..).map(|m| format!("restart: {m}")));
    new_fit.messages = messages;
    new_fit.estimator = format!(
        "{} (a restart from the common-denominator start, better than the {} first fit)",
        new_fit.estimator, fit.estimator
    );
    Ok(Restarted {
        fit: new_fit,
        summary: Some(new_summary),
        delay,
        sk_start: Some(start),
    })
}
