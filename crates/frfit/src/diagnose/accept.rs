//! Acceptance of a round's best trial, pruning of the modes it made redundant, and the
//! final refinement with its guards (stability, never worse than the first fit).

use super::trial::{model_cost, Trial};
use crate::pipeline::{err, FitContext, PipelineConfig};
use crate::FrfitError;
use additive_riv::riv::{iterate, RivConfig};
use additive_riv::significance::{f_statistic, noise_scale};
use additive_riv::structure::{prune_modes, AdaptConfig};
use additive_riv::AdditiveModel;
use frf_data::{Convergence, Fit, ModelStructure};

/// Submodels and dynamics factors of `model` with a pole in the closed right half-plane.
pub fn unstable_parts(model: &AdditiveModel) -> usize {
    model.unstable_submodels().len()
        + model
            .dynamics
            .iter()
            .filter(|d| d.poles().iter().any(|p| p.re >= 0.0))
            .count()
}

/// Of the trials that pass their F test, lower the cost of `current` (at
/// `current_cost`) and leave no more unstable parts than it has (an effect that leaves
/// a pole in the right half-plane is not a fix), the one that explains the most (the
/// lowest cost): the residual is attributed to the best effect, and the others are
/// tested again against what is left. Its index in `trials`.
pub fn best(trials: &[Trial], current: &AdditiveModel, current_cost: f64) -> Option<usize> {
    trials
        .iter()
        .enumerate()
        .filter(|(_, tr)| {
            tr.passes()
                && tr.cost < current_cost
                && unstable_parts(&tr.model) <= unstable_parts(current)
        })
        .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))
        .map(|(i, _)| i)
}

/// The accepted model `accepted` (at cost `accepted_cost`) without the modes its new
/// structure made redundant (duplicates, unstable, insignificant), numerators refitted;
/// a pruning that costs significantly (F test of the removed parameters above
/// `cfg.min_f`) is not kept. What happened goes to `messages`, as after step `step`.
pub fn prune(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    accepted: AdditiveModel,
    accepted_cost: f64,
    step: usize,
    messages: &mut Vec<String>,
) -> Result<AdditiveModel, FrfitError> {
    let fd = &ctx.fit_data;
    let prune_cfg = AdaptConfig {
        min_f: cfg.min_f,
        alpha: cfg.alpha,
        ..Default::default()
    };
    let mut m = accepted.clone();
    let pruned = prune_modes(&mut m, fd, &prune_cfg).map_err(err("prune"))?;
    if pruned.is_empty() {
        return Ok(m);
    }
    let removed = accepted.n_params().saturating_sub(m.n_params()).max(1);
    let s2 = noise_scale(accepted_cost, fd, accepted.n_params());
    let f_removed = f_statistic(model_cost(&m, fd) - accepted_cost, removed, s2);
    if f_removed > cfg.min_f {
        messages.push(format!(
            "after step {step}: kept {} mode(s) the pruning would remove (their removal raises the cost significantly, F = {f_removed:.1})",
            pruned.len()
        ));
        return Ok(accepted);
    }
    for (f, why) in pruned {
        messages.push(format!(
            "after step {step}: removed mode at {f:.2} Hz: {why}"
        ));
    }
    Ok(m)
}

/// Converges fully (Algorithm 1 at its default tolerances) from `current`, the model
/// of the last accepted step, and returns the diagnosis result: the refined model, or
/// `current` marked as failed when the refinement moved a pole into the right
/// half-plane; `first` (the first fit) when the result fits worse than it by more than
/// `allowed_increase` (the cost the accepted suspended-body readings gave up for a
/// simpler model of the same physics, `super::suspension_reading`). The messages
/// of `first` (with the loop's) go to the result; the iterations of the first fit and
/// of the final refinement are added up (the refits of the candidates are reported per
/// step).
pub fn final_refinement(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    mut first: Fit<AdditiveModel>,
    current: AdditiveModel,
    allowed_increase: f64,
) -> Result<Fit<AdditiveModel>, FrfitError> {
    let fd = &ctx.fit_data;
    let full = RivConfig {
        method: cfg.method,
        weighting: cfg.weighting.clone(),
        ..Default::default()
    };
    let unstable_before = unstable_parts(&current);
    let mut last = iterate(current.clone(), fd, &full).map_err(err("final refinement"))?;
    let mut msgs = std::mem::take(&mut first.messages);
    if unstable_parts(&last.model) > unstable_before {
        msgs.push(
            "the final refinement moved a pole into the right half-plane; the model of the last accepted step is kept".into(),
        );
        let keep = Fit::from_model(current, last.estimator.clone());
        last = Fit {
            cost_history: vec![model_cost(&keep.model, fd) / (2.0 * fd.n as f64)],
            convergence: Convergence::Failed {
                reason:
                    "the final refinement left the stable region; stopped at the last accepted step"
                        .into(),
            },
            ..keep
        };
    }
    // the loop never ends worse than it started
    let initial_cost = model_cost(&first.model, fd);
    let last_cost = model_cost(&last.model, fd);
    if last_cost > initial_cost + allowed_increase {
        msgs.push(format!(
            "the diagnosed model fits worse than the first model (cost {last_cost:.4e} > {initial_cost:.4e}); the first model is kept",
        ));
        first.messages = msgs;
        Ok(first)
    } else {
        last.iterations += first.iterations;
        last.messages = msgs;
        Ok(last)
    }
}
