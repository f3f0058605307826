//! Acceptance of a round's best trial, pruning of the modes it made redundant, and the
//! final refinement with its guards (stability, never worse than the first fit).

use super::refit::{f_test, model_cost, refit, unstable_parts, Refitted};
use super::trial::Trial;
use crate::pipeline::{err, FitContext, PipelineConfig};
use crate::FrfitError;
use additive_riv::residual_stats::{close_mode_pairs, mode_f_hz};
use additive_riv::riv::{iterate, RivConfig};
use additive_riv::significance::{f_statistic, noise_scale, submodel_cost_increase};
use additive_riv::structure::{prune_modes, AdaptConfig};
use additive_riv::AdditiveModel;
use frf_data::twins::TWIN_FRACTION;
use frf_data::{Convergence, Fit, ModelStructure};

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

/// `reduced`, a model nested in `model` (at cost `cost`) with some of its parts taken
/// out, refitted (numerators, eq. 24, then Algorithm 1 at `riv`), with the F statistic
/// of the parts taken out and its critical value ([`f_test`] at `cfg.alpha`) when they
/// are not significant beside the rest and the refit adds no unstable part; `None` when
/// they are significant, or the refit fails or adds an unstable part.
fn insignificant_without(
    cfg: &PipelineConfig,
    fd: &additive_riv::FitData,
    riv: &RivConfig,
    (model, cost): (&AdditiveModel, f64),
    reduced: AdditiveModel,
) -> Option<(Refitted, f64, f64)> {
    let r = refit(reduced, fd, riv).ok()?;
    let removed = model.n_params().saturating_sub(r.model.n_params()).max(1);
    let (_, f, f_crit) = f_test(model, fd, r.cost, cost, removed, cfg);
    let stable = unstable_parts(&r.model) <= unstable_parts(model);
    (r.cost.is_finite() && f <= f_crit && stable).then_some((r, f, f_crit))
}

/// The twin pairs of `model` ([`TWIN_FRACTION`], [`close_mode_pairs`]) of stable modes,
/// as submodel indices, closest first (distance over mean `|Re p|`). Two modes are
/// twins when their poles are within each other's half-power half-bandwidth, where two
/// submodels can share one resonance between them (the pruning's duplicate test, at
/// [`additive_riv::residual_stats::DUPLICATE_FRACTION`], holds only poles on practically
/// the same point); the ML refiner's re-test applies the same rule.
fn twin_pairs(model: &AdditiveModel) -> Vec<(usize, usize)> {
    let stable = |i: usize| {
        model
            .upper_pole(&model.submodels[i])
            .is_some_and(|p| p.re < 0.0)
    };
    let mut pairs: Vec<(usize, usize, f64)> = close_mode_pairs(model, TWIN_FRACTION)
        .into_iter()
        .filter(|&(a, b, _)| stable(a) && stable(b))
        .collect();
    pairs.sort_by(|x, y| x.2.total_cmp(&y.2));
    pairs.into_iter().map(|(a, b, _)| (a, b)).collect()
}

/// `model` (at cost `cost`) with twin modes ([`twin_pairs`]) merged: for each pair, the
/// mode whose numerators explain less (the Wald cost increase of removing them,
/// [`submodel_cost_increase`]) is removed and the rest refitted (numerators, eq. 24,
/// then Algorithm 1 at the candidates' tolerance, `riv`); the merge is kept when the
/// removed mode's parameters are not significant beside the refitted one (F test at
/// `cfg.alpha`, [`f_test`]) and the refit adds no unstable part. The pruning after an
/// accepted step refits only the numerators, so it keeps a twin whose pole the other
/// mode would need to move to take its share: an effect accepted after the first fit
/// had split one resonance into two (plate seed 8 with a sensor resonance 3 % above its
/// fifth mode: 388.85 and 389.17 Hz, damping 0.0088 and 0.0092, beside the true
/// 388.85 Hz). A genuine close pair (two shapes) fails the test and stays. What
/// happened goes to `messages`, prefixed by `when` ("after step 3").
pub fn merge_twins(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    mut model: AdditiveModel,
    mut cost: f64,
    when: &str,
    messages: &mut Vec<String>,
) -> Result<(AdditiveModel, f64), FrfitError> {
    let fd = &ctx.fit_data;
    // pairs whose merge failed, by index: valid while the model is unchanged
    let mut tested: Vec<(usize, usize)> = Vec::new();
    // the Wald cost increases of the current model's submodels, formed once per model
    let mut dv: Option<Vec<f64>> = None;
    loop {
        let Some((a, b)) = twin_pairs(&model).into_iter().find(|p| !tested.contains(p)) else {
            return Ok((model, cost));
        };
        tested.push((a, b));
        let wald = match &mut dv {
            Some(v) => v,
            none => none.insert(submodel_cost_increase(&model, fd).map_err(err("twin modes"))?),
        };
        let (keep, go) = if wald[a] >= wald[b] { (a, b) } else { (b, a) };
        let (f_keep, f_go) = (mode_f_hz(&model, keep), mode_f_hz(&model, go));
        let mut merged = model.clone();
        merged.remove_submodel(go);
        if let Some((r, f, f_crit)) = insignificant_without(cfg, fd, riv, (&model, cost), merged) {
            messages.push(format!(
                "{when}: merged the twin modes at {f_keep:.2} and {f_go:.2} Hz (within their half-power bandwidth): the mode at {f_go:.2} Hz is not significant beside the other refitted (F = {f:.2} <= {f_crit:.2})"
            ));
            // a new model: its pairs and their statistics are new
            tested.clear();
            dv = None;
            model = r.model;
            cost = r.cost;
        }
    }
}

/// An effect an earlier step accepted that [`drop_earlier`] tests again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Earlier {
    /// The dynamics factor at this index of the model.
    Factor(usize),
    /// The fitted delay, which the step made free from `before_s` (seconds).
    Delay {
        /// The delay before the step, held again without it.
        before_s: f64,
    },
}

/// An earlier effect with the index of the step that accepted it.
pub type EarlierStep = (Earlier, usize);

/// `model` without the earlier effect `e` ([`Earlier`]); `None` when it is not there.
fn without_earlier(model: &AdditiveModel, e: Earlier) -> Option<AdditiveModel> {
    match e {
        Earlier::Factor(k) => {
            let mut m = model.clone();
            (k < m.dynamics.len()).then(|| {
                m.dynamics.remove(k);
                m
            })
        }
        Earlier::Delay { before_s } => {
            if !model.factor.fit_delay {
                return None;
            }
            let factor = additive_riv::KnownFactor {
                delay_s: before_s,
                fit_delay: false,
                ..model.factor
            };
            model.clone().with_factor(factor).ok()
        }
    }
}

/// The earlier effects of `earlier` (each with the index of the step that accepted it)
/// tested again beside the model `model` (at cost `cost`) of a later accepted step:
/// each removed in turn and the rest refitted (numerators, eq. 24, then Algorithm 1 at
/// the candidates' tolerance, `riv`), and dropped when its parameters are not
/// significant beside the rest (F test at `cfg.alpha`, [`f_test`]) and the refit adds
/// no unstable part. An effect accepted while a larger one was unexplained was tested
/// against a residual that effect dominated; once the larger one is in, the smaller
/// can be noise (plate seed 8 with a sensor resonance 3 % above its fifth mode: a delay
/// of 6.7 us and a first-order output factor at 15.9 kHz, accepted before the
/// resonance's factor brought the residual to the noise level). Factors are tested from
/// the last one, so that the indices of the others hold. Returns the model, its cost
/// and the dropped effects with the step indices that accepted them, in the order they
/// were dropped (factors from the highest index: each index holds when they are removed
/// in that order); what happened goes to `messages`, as after step `step`.
pub fn drop_earlier(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    (mut model, mut cost): (AdditiveModel, f64),
    earlier: &[EarlierStep],
    step: usize,
    messages: &mut Vec<String>,
) -> Result<(AdditiveModel, f64, Vec<EarlierStep>), FrfitError> {
    let fd = &ctx.fit_data;
    let mut order: Vec<EarlierStep> = earlier.to_vec();
    // factors from the highest index, then the delay
    order.sort_by_key(|(e, _)| match e {
        Earlier::Factor(k) => std::cmp::Reverse(*k as i64),
        Earlier::Delay { .. } => std::cmp::Reverse(-1),
    });
    let mut dropped = Vec::new();
    for (e, origin) in order {
        let Some(reduced) = without_earlier(&model, e) else {
            continue;
        };
        if let Some((r, f, f_crit)) = insignificant_without(cfg, fd, riv, (&model, cost), reduced) {
            let what = match e {
                Earlier::Factor(k) => format!(
                    "the dynamics factor of step {} ({:?}, order {})",
                    origin + 1,
                    model.dynamics[k].target,
                    model.dynamics[k].den.len()
                ),
                Earlier::Delay { before_s } => format!(
                    "the delay of step {} ({:.2} us, back to {:.2} us)",
                    origin + 1,
                    model.factor.delay_s * 1e6,
                    before_s * 1e6
                ),
            };
            messages.push(format!(
                "after step {step}: removed {what}: not significant beside the later steps (F = {f:.2} <= {f_crit:.2})"
            ));
            dropped.push((e, origin));
            model = r.model;
            cost = r.cost;
        }
    }
    Ok((model, cost, dropped))
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
