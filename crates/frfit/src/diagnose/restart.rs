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

use super::trial::{f_test, model_cost};
use crate::pipeline::{chain_fit, err, FitContext, PipelineConfig};
use crate::summary::RestartSummary;
use crate::FrfitError;
use additive_riv::riv::iterate;
use additive_riv::{fit_numerators, AdditiveModel, DelayChoice};
use frf_data::{Fit, ModelStructure};
use validation::residual::analyze_residual;

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
        estimate_s: first.report.delay_estimate.as_ref().map(|d| d.tau_s),
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
}

/// The delay the first fit will hold when the data's own delay estimate is far enough
/// from it to misplace its modes (a phase error above 0.05 rad, about 3 degrees, at the
/// band's top line): then [`delay_restart`] is worth running beside the first fit
/// (`crate::pipeline::run` does so in parallel). `None` when the first fit fits the
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

/// Tests restarts of the first fit before the diagnosis loop: when the first fit's
/// residual is significant and calls for a delay (the residual's or the data's phase
/// slope), the fit from the start with the data's delay estimate, refitted with the
/// delay held at the first fit's value, replaces the first fit when its F test (the
/// cost decrease per added parameter, at least one, at `cfg.alpha`) passes. The delay
/// restart (`speculative` when it was made beside the first fit and holds the first
/// fit's delay) is returned for the loop's `delay` trial.
pub fn better_first_fit(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    first: Fit<AdditiveModel>,
    speculative: Option<DelayRestart>,
) -> Result<Restarted, FrfitError> {
    let unchanged = |fit| Restarted {
        fit,
        summary: None,
        delay: None,
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
        !super::candidate::delay_proposals(&first.model, &an, cfg.alpha, &[], ctx.data_delay_s())
            .is_empty();
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
        });
    }
    let before = crate::pipeline::error_stats(&ctx.band, &response, &ctx.noise);
    let from = format!(
        "the estimator chain from the start with the data's delay estimate ({:.2} us), the delay then held at {:.2} us",
        restart.estimate_s.map_or(f64::NAN, |t| t * 1e6),
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
    })
}
