//! The diagnosis loop: from the residual of the first fit to the effects of the
//! catalogue that explain it.
//!
//! Each round compares the residual with the measured noise level (crate
//! `validation`); while it is significant, the round proposes the effects whose
//! signatures the residual shows ([`Candidate`]: missed mode, delay, hold, feedthrough,
//! stiffness, input or output dynamics), refits the model with each
//! (module `trial`: also the missed modes jointly, and a delay by a refit from the start),
//! and keeps the one that explains the most when an F test that accounts for the added
//! parameters says it explains more than noise (module `accept`), then prunes the modes the
//! new structure made redundant. The loop stops when the residual is at the noise level
//! or when no candidate helps; a final refinement converges the last structure, guarded
//! against instability and against ending worse than the first fit. When the data's
//! line-to-line floor significantly exceeds their measured variance (nonlinear
//! distortion that the variance, from the periods of one realization, misses), every
//! residual of the loop is judged against the variance raised to the local floor
//! ([`FitContext::judging_noise`]): the loop then stops once the residual is at the
//! floor instead of chasing the distortion with effects that each explain a little of
//! it. Every tested
//! candidate is recorded as a step of the summary, with its parameters as fitted
//! ([`FittedEffect`]).

mod accept;
mod candidate;
mod delay_reading;
mod fitted;
use additive_riv::held_out;
mod refit;
mod restart;
mod trial;

pub use crate::effects::{FittedEffect, PoleParams, Refit};
pub use candidate::{Candidate, DelayStart, FactorStart, Proposal};
pub use restart::{
    better_first_fit, delay_restart, worth_a_delay_restart, DelayRestart, Restarted,
};
pub use trial::Trial;

use crate::pipeline::{err, error_stats, FitContext, PipelineConfig};
use crate::summary::{effect_name, ErrorStats, StepSummary};
use crate::FrfitError;
use additive_riv::residual_stats::ResidualStats;
use additive_riv::riv::RivConfig;
use additive_riv::AdditiveModel;
use frf_data::{Fit, ModelStructure, ProgressSink};
use rayon::prelude::*;
use realize::ResponseGrid;
use refit::model_cost;
use trial::Current;
use validation::analysis::{analyze_residual, Effect, ResidualAnalysis};

/// What the loop produced.
pub struct Diagnosis {
    /// The final fit (the first fit when the loop ended worse than it).
    pub fit: Fit<AdditiveModel>,
    /// Every tested candidate, in order.
    pub steps: Vec<StepSummary>,
    /// Per step, the model response before and after.
    pub step_responses: Vec<(ResponseGrid, ResponseGrid)>,
    /// Wall time of each round (its trials, the acceptance and the pruning) and of the
    /// final refinement, seconds.
    pub stages: Vec<(String, f64)>,
}

/// The state of the loop between rounds.
struct State {
    model: AdditiveModel,
    cost: f64,
    response: ResponseGrid,
    analysis: ResidualAnalysis,
    tested: Vec<(Effect, String)>,
    restart_tested: bool,
    /// The delay restart made before the loop ([`better_first_fit`]), for round 1.
    delay_restart: Option<DelayRestart>,
    /// The common-denominator start of the band: the restart's, or made once when a
    /// round first has nothing to propose ([`trial::common_denominator_modes`]);
    /// `Some(None)` when it failed.
    sk_start: Option<Option<AdditiveModel>>,
    n_tests: usize,
    n_accepted: usize,
    /// The cost increase over the first fit that the accepted suspended-body readings
    /// ([`suspension_reading`]) were allowed: the simpler model fits a little worse.
    allowed_increase: f64,
    /// Per dynamics factor of `model`, the index in the steps of the accepted step that
    /// added it (`None`: it came with the first fit).
    factor_steps: Vec<Option<usize>>,
    /// The accepted step that made the delay a fitted parameter (its index in the steps)
    /// and the delay before it, seconds.
    delay_step: Option<(usize, f64)>,
    /// Whether the loop tests the repairs' modes ([`trial::repaired_modes`]): when the
    /// first fit did not make them ([`PipelineConfig::first_fit_adds_modes`]) and the
    /// chain refines by Algorithm 1, whose structure they repair.
    loop_repairs: bool,
    /// Whether the repairs are still to be tested on the current model (once per model).
    repairs_due: bool,
    /// The repairs trial made on the first fit before the loop ([`first_repairs`]), for
    /// round 1 (`Some(None)`: the repairs changed nothing).
    repairs_made: Option<Option<Trial>>,
    /// The modes accepted `missed_mode` steps added and the model still holds: (index
    /// in the steps, frequency in Hz, damping).
    mode_steps: Vec<(usize, f64, f64)>,
}

/// Reports the test of `what` in round `round` as progress and counts it in `n_tests`.
fn announce(cfg: &PipelineConfig, n_tests: &mut usize, round: usize, what: &str) {
    *n_tests += 1;
    cfg.progress.step(
        "diagnose",
        *n_tests,
        None,
        None,
        format!("round {round}: testing {what}"),
    );
}

impl State {
    /// Marks the `missed_mode` steps whose modes `before` held (the model before the step
    /// at `step_index` and the modes it added) and `after` (the model once that step and
    /// its pruning are done) no longer holds
    /// ([`refit::unmatched_modes`]) as taken out by that step: a mode accepted for want
    /// of the right effect (two added together, one of them the effect's), removed once
    /// that effect was in. The nearest step mode within 3 % of each removed mode is the
    /// one marked.
    fn mark_removed_modes(
        &mut self,
        before: &[(f64, f64)],
        after: &AdditiveModel,
        step_index: usize,
        steps: &mut [StepSummary],
    ) {
        for (f_gone, _) in refit::unmatched_modes(before, &refit::mode_list(after)) {
            let nearest = self
                .mode_steps
                .iter()
                .enumerate()
                .filter(|(_, &(_, f, _))| (f / f_gone - 1.0).abs() < 0.03)
                .min_by(|a, b| (a.1 .1 - f_gone).abs().total_cmp(&(b.1 .1 - f_gone).abs()))
                .map(|(i, _)| i);
            if let Some(i) = nearest {
                let (j, _, _) = self.mode_steps.remove(i);
                steps[j].superseded_by = Some(step_index + 1);
            }
        }
    }
}

/// The factor steps of `accepted` (the model of the step at index `step`) from those of
/// `before` (`factor_steps`, one per factor of `before`), and the steps whose factor
/// `accepted` no longer holds. Factors are matched by entries and orders (their
/// coefficients move in every refit): each factor of `before` claims the first
/// unclaimed factor of `accepted` with the same target and numerator and denominator
/// orders; an unclaimed factor of `accepted` is the step's own.
fn match_factors(
    before: &AdditiveModel,
    factor_steps: &[Option<usize>],
    accepted: &AdditiveModel,
    step: usize,
) -> (Vec<Option<usize>>, Vec<usize>) {
    let key = |d: &realize::DynamicsFactor| (d.target, d.den.len(), d.num.len());
    let mut claimed: Vec<Option<Option<usize>>> = vec![None; accepted.dynamics.len()];
    let mut gone = Vec::new();
    for (k, d) in before.dynamics.iter().enumerate() {
        let origin = factor_steps.get(k).copied().flatten();
        match (0..accepted.dynamics.len())
            .find(|&j| claimed[j].is_none() && key(&accepted.dynamics[j]) == key(d))
        {
            // `Some(origin)`: claimed, whatever the origin
            Some(j) => claimed[j] = Some(origin),
            None => gone.extend(origin),
        }
    }
    let steps = claimed
        .into_iter()
        .map(|c| c.unwrap_or(Some(step)))
        .collect();
    (steps, gone)
}

impl State {
    /// Makes the model of an accepted reading (`model` at cost `cost`, its response
    /// `response`; step `step`, 1-based) the current one, without the modes it made
    /// redundant ([`accept::prune`], as after the loop's steps: a mode that held part of
    /// the reading's effect, a low mode beside the free body that the suspension replaced).
    fn take_reading(
        &mut self,
        ctx: &FitContext,
        cfg: &PipelineConfig,
        (model, cost): (AdditiveModel, f64),
        response: ResponseGrid,
        step: usize,
        notes: &mut Vec<String>,
    ) -> Result<(), FrfitError> {
        let n_modes = model.modes().len();
        let pruned = accept::prune(ctx, cfg, model, cost, step, notes)?;
        if pruned.modes().len() == n_modes {
            self.cost = cost;
            self.response = response;
        } else {
            self.cost = model_cost(&pruned, &ctx.fit_data);
            self.response = pruned.response_at(&ctx.omega);
        }
        self.model = pruned;
        self.reanalyze(ctx)
    }

    /// The residual analysis of the current model's response, after a change of model.
    fn reanalyze(&mut self, ctx: &FitContext) -> Result<(), FrfitError> {
        self.analysis = analyze_residual(
            &ctx.band,
            &self.response,
            ctx.judging_noise(),
            &ctx.residual_config(&self.model),
        )
        .map_err(err("residual analysis"))?;
        Ok(())
    }
}

/// The refits of the loop's candidates: Algorithm 1 to a coarse tolerance, quietly.
fn candidate_riv(ctx: &FitContext, cfg: &PipelineConfig) -> RivConfig {
    RivConfig {
        param_tol: 1e-7,
        max_iterations: 30,
        progress: ProgressSink::none(),
        ..ctx.riv_config(cfg)
    }
}

/// Whether the loop tests the repairs' modes ([`trial::repaired_modes`]): when the first
/// fit does not make them ([`PipelineConfig::first_fit_adds_modes`]) and the chain
/// refines by Algorithm 1, whose structure they repair.
fn loop_repairs(ctx: &FitContext, cfg: &PipelineConfig) -> bool {
    let entries = frf_data::FrfDataset::ny(&ctx.band) * frf_data::FrfDataset::nu(&ctx.band);
    !cfg.first_fit_adds_modes()
        && crate::pipeline::default_chain(&cfg.init, &cfg.refine, entries).1 == "riv"
}

/// The repairs' modes tested on a first fit before the restarts of
/// [`better_first_fit`] (which must then count the modes the first fit lost after
/// them, [`FirstRepairs::modes`]), for the loop's first round.
pub struct FirstRepairs {
    /// The weighted cost of the model the trial was made on (the loop takes the trial
    /// only when it starts from that model).
    base_cost: f64,
    /// The trial, when the repairs changed something.
    trial: Option<Trial>,
}

impl FirstRepairs {
    /// The modes of the repaired model when its trial passes its F test.
    pub fn modes(&self) -> Option<usize> {
        self.trial
            .as_ref()
            .filter(|t| t.passes())
            .map(|t| t.model.modes().len())
    }
}

/// The loop's repairs trial on the first fit `model` when the loop tests the repairs
/// (the modes were declared), else `None`.
pub fn first_repairs(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    model: &AdditiveModel,
) -> Option<FirstRepairs> {
    if !loop_repairs(ctx, cfg) {
        return None;
    }
    let riv = candidate_riv(ctx, cfg);
    let fd = &ctx.fit_data;
    let stats = ResidualStats::new(model, fd);
    let cost = model_cost(model, fd);
    let current = Current {
        model,
        cost,
        stats: &stats,
    };
    let merge = |m: AdditiveModel, c: f64, notes: &mut Vec<String>| {
        accept::merge_twins(ctx, cfg, &riv, m, c, "after the repairs", notes).ok()
    };
    Some(FirstRepairs {
        base_cost: cost,
        trial: trial::repaired_modes(ctx, cfg, &riv, &current, &merge),
    })
}

/// Runs the diagnosis loop from `first` (the first fit of `ctx.band`, whose response
/// at the band's lines is `first_response`); `delay_restart` is the delay restart that
/// [`better_first_fit`] made already, if any, `sk_start` the common-denominator
/// start it made, if any, and `repairs` the repairs trial made on the first fit
/// ([`first_repairs`]), if any.
pub fn diagnose(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    first: Fit<AdditiveModel>,
    first_response: &ResponseGrid,
    delay_restart: Option<DelayRestart>,
    sk_start: Option<AdditiveModel>,
    repairs: Option<FirstRepairs>,
) -> Result<Diagnosis, FrfitError> {
    let mut fit = first;
    let fd = &ctx.fit_data;
    let riv = candidate_riv(ctx, cfg);
    let loop_repairs = loop_repairs(ctx, cfg);
    let analysis = analyze_residual(
        &ctx.band,
        first_response,
        ctx.judging_noise(),
        &ctx.residual_config(&fit.model),
    )
    .map_err(err("residual analysis"))?;
    let mut st = State {
        model: fit.model.clone(),
        cost: model_cost(&fit.model, fd),
        response: first_response.clone(),
        analysis,
        tested: Vec::new(),
        restart_tested: false,
        sk_start: sk_start.map(Some),
        delay_restart,
        n_tests: 0,
        n_accepted: 0,
        allowed_increase: 0.0,
        factor_steps: vec![None; fit.model.dynamics.len()],
        delay_step: None,
        loop_repairs,
        repairs_due: loop_repairs,
        repairs_made: None,
        mode_steps: Vec::new(),
    };
    // the repairs trial made on this very model
    st.repairs_made = repairs
        .filter(|r| r.base_cost.to_bits() == st.cost.to_bits())
        .map(|r| r.trial);
    let mut rec = Record::default();
    let mut stages: Vec<(String, f64)> = Vec::new();
    let t_reading = std::time::Instant::now();
    if suspension_reading(ctx, cfg, &riv, &mut st, &mut rec, &mut fit.messages)? {
        stages.push((
            "diagnose: suspended-body reading".into(),
            t_reading.elapsed().as_secs_f64(),
        ));
    }
    let mut n_round = 0;
    while st.analysis.significant && st.n_accepted < cfg.max_steps {
        let t_round = std::time::Instant::now();
        n_round += 1;
        let trials = round(ctx, cfg, &riv, &mut st);
        stages.push((
            format!("diagnose: round {n_round} trials"),
            t_round.elapsed().as_secs_f64(),
        ));
        // the delay restart was made against the first fit: later rounds make their own
        st.delay_restart = None;
        let Some(trials) = trials else {
            break;
        };
        let before = error_stats(&ctx.band, &st.response, &ctx.noise);
        let mut trials = trials;
        let best = best_held_out(ctx, &riv, &mut trials, &st.model, st.cost);
        let mut accepted_model = None;
        for (i, tr) in trials.into_iter().enumerate() {
            let accepted = Some(i) == best;
            let before = (&st.response, before);
            // the index of the accepted trial's (first) step
            let index = rec.steps.len();
            rec.trial(ctx, &tr, accepted, before);
            if accepted {
                accepted_model = Some((tr.model, tr.cost, index));
            }
        }
        let Some((accepted, accepted_cost, step_index)) = accepted_model else {
            break;
        };
        // the modes before the step and those the step added: the ones the step and its
        // pruning take out are marked on the steps that added them
        let mut modes_before = refit::mode_list(&st.model);
        for (j, s) in rec.steps.iter().enumerate().skip(step_index) {
            if let (true, FittedEffect::MissedMode { f_hz, zeta }) = (s.accepted, &s.fitted) {
                st.mode_steps.push((j, *f_hz, *zeta));
                modes_before.push((*f_hz, *zeta));
            }
        }
        // the factors the accepted step took out of the model (redundant beside it, or
        // replaced by their twin) are marked on the steps that added them
        let (factor_steps, gone) =
            match_factors(&st.model, &st.factor_steps, &accepted, step_index);
        for g in gone {
            rec.steps[g].superseded_by = Some(step_index + 1);
        }
        st.factor_steps = factor_steps;
        st.n_accepted += 1;
        let m = accept::prune(
            ctx,
            cfg,
            accepted,
            accepted_cost,
            step_index + 1,
            &mut fit.messages,
        )?;
        let cost = model_cost(&m, fd);
        let (m, cost) = accept::merge_twins(
            ctx,
            cfg,
            &riv,
            m,
            cost,
            &format!("after step {}", step_index + 1),
            &mut fit.messages,
        )?;
        // the delay the step made free, from the value before it
        if m.factor.fit_delay && !st.model.factor.fit_delay {
            st.delay_step = Some((step_index, st.model.factor.delay_s));
        }
        // the effects of earlier steps, tested again beside this one
        let mut earlier: Vec<accept::EarlierStep> = st
            .factor_steps
            .iter()
            .enumerate()
            .filter_map(|(k, o)| {
                o.filter(|&j| j < step_index)
                    .map(|j| (accept::Earlier::Factor(k), j))
            })
            .collect();
        if let Some((j, before_s)) = st.delay_step.filter(|&(j, _)| j < step_index) {
            earlier.push((accept::Earlier::Delay { before_s }, j));
        }
        let (m, cost, dropped) = accept::drop_earlier(
            ctx,
            cfg,
            &riv,
            (m, cost),
            &earlier,
            step_index + 1,
            &mut fit.messages,
        )?;
        for (e, j) in dropped {
            rec.steps[j].superseded_by = Some(step_index + 1);
            match e {
                accept::Earlier::Delay { .. } => st.delay_step = None,
                accept::Earlier::Factor(k) => {
                    st.factor_steps.remove(k);
                }
            }
        }
        st.mark_removed_modes(&modes_before, &m, step_index, &mut rec.steps);
        st.cost = cost;
        st.response = m.response_at(&ctx.omega);
        st.model = m;
        st.repairs_due = st.loop_repairs;
        st.reanalyze(ctx)?;
        // a loop that reaches the noise level can leave the body's low mode beside an
        // empty free body
        suspension_reading(ctx, cfg, &riv, &mut st, &mut rec, &mut fit.messages)?;
    }
    let t_reading = std::time::Instant::now();
    if delay_readings(ctx, cfg, &riv, &mut st, &mut rec, &mut fit.messages)? {
        stages.push((
            "diagnose: common factors read as a delay".into(),
            t_reading.elapsed().as_secs_f64(),
        ));
    }
    let t_final = std::time::Instant::now();
    // twins the first fit left where no step was accepted after them
    let (model, _) = accept::merge_twins(
        ctx,
        cfg,
        &riv,
        st.model,
        st.cost,
        "before the final refinement",
        &mut fit.messages,
    )?;
    let fit = accept::final_refinement(ctx, cfg, fit, model, st.allowed_increase)?;
    stages.push((
        "diagnose: final refinement".into(),
        t_final.elapsed().as_secs_f64(),
    ));
    Ok(Diagnosis {
        fit,
        steps: rec.steps,
        step_responses: rec.responses,
        stages,
    })
}

/// Tests the suspended-body reading of the current model
/// ([`candidate::suspended_body`], [`trial::suspended_body`]) once per low mode, when
/// its residual is at the noise level (a significant residual goes to the loop's
/// candidates first, the signature-proposed `stiffness` among them): a model at the
/// noise level can hold a suspension as a mode beside an empty free body, a model that
/// fits as well but names the wrong physics. The trial is recorded as a `stiffness` step; when accepted
/// it becomes the current model. Whether a reading was tested.
fn suspension_reading(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    st: &mut State,
    rec: &mut Record,
    notes: &mut Vec<String>,
) -> Result<bool, FrfitError> {
    if st.analysis.significant || st.n_accepted >= cfg.max_steps {
        return Ok(false);
    }
    let omega_low = ctx.omega.iter().copied().fold(f64::INFINITY, f64::min);
    let Some(p) = candidate::suspended_body(&st.model, omega_low) else {
        return Ok(false);
    };
    let key = (p.candidate.effect(), p.candidate.key());
    if st.tested.contains(&key) {
        return Ok(false);
    }
    st.tested.push(key);
    let fd = &ctx.fit_data;
    let stats = ResidualStats::new(&st.model, fd);
    let current = Current {
        model: &st.model,
        cost: st.cost,
        stats: &stats,
    };
    cfg.progress.step(
        "diagnose",
        st.n_tests + 1,
        None,
        None,
        "testing a suspended body in place of a free body and a low mode".to_string(),
    );
    st.n_tests += 1;
    let Some((mut tr, accepted)) = trial::suspended_body(ctx, cfg, riv, &current, p) else {
        return Ok(true);
    };
    let accepted = accepted && reading_held_out(ctx, riv, &st.model, &mut tr);
    let before = error_stats(&ctx.band, &st.response, &ctx.noise);
    let after_resp = rec.trial(ctx, &tr, accepted, (&st.response, before));
    if accepted {
        st.allowed_increase += (tr.cost - st.cost).max(0.0);
        st.n_accepted += 1;
        st.take_reading(
            ctx,
            cfg,
            (tr.model, tr.cost),
            after_resp,
            rec.steps.len(),
            notes,
        )?;
    }
    Ok(true)
}

/// Tests each common first-order factor that an accepted step added as a delay
/// ([`delay_reading::factor_as_delay`]) once the residual is at the noise level: a
/// model at the noise level can hold an undeclared delay as such a factor, which fits
/// as well but names the wrong physics. Each trial is recorded as a `delay` step; when
/// accepted, the factor's step is marked as taken out by it and the delay is the
/// model's. Whether a reading was tested.
fn delay_readings(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    st: &mut State,
    rec: &mut Record,
    notes: &mut Vec<String>,
) -> Result<bool, FrfitError> {
    let mut tested = false;
    let mut done: Vec<usize> = Vec::new();
    loop {
        if st.analysis.significant || st.n_accepted >= cfg.max_steps {
            return Ok(tested);
        }
        // the next common factor of an accepted step not read yet
        let Some((k, j)) = st.factor_steps.iter().enumerate().find_map(|(k, o)| {
            o.filter(|j| {
                !done.contains(j)
                    && st
                        .model
                        .dynamics
                        .get(k)
                        .is_some_and(delay_reading::reads_as_delay)
            })
            .map(|j| (k, j))
        }) else {
            return Ok(tested);
        };
        done.push(j);
        tested = true;
        cfg.progress.step(
            "diagnose",
            st.n_tests + 1,
            None,
            None,
            format!("testing the common factor of step {} as a delay", j + 1),
        );
        st.n_tests += 1;
        let fd = &ctx.fit_data;
        let stats = ResidualStats::new(&st.model, fd);
        let current = Current {
            model: &st.model,
            cost: st.cost,
            stats: &stats,
        };
        let Some((mut tr, accepted)) =
            delay_reading::factor_as_delay(ctx, cfg, riv, &current, k, j)
        else {
            continue;
        };
        let accepted = accepted && reading_held_out(ctx, riv, &st.model, &mut tr);
        let before = error_stats(&ctx.band, &st.response, &ctx.noise);
        let index = rec.steps.len();
        let after_resp = rec.trial(ctx, &tr, accepted, (&st.response, before));
        if accepted {
            rec.steps[j].superseded_by = Some(index + 1);
            st.factor_steps.remove(k);
            st.delay_step = Some((index, st.model.factor.delay_s));
            st.n_accepted += 1;
            st.take_reading(ctx, cfg, (tr.model, tr.cost), after_resp, index + 1, notes)?;
        }
    }
}

/// One round: the candidates of the current residual and their trials; `None` when
/// there is no candidate or no trial succeeded.
fn round(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    st: &mut State,
) -> Option<Vec<Trial>> {
    let fd = &ctx.fit_data;
    let stats = ResidualStats::new(&st.model, fd);
    let proposals = candidate::propose(
        &st.model,
        &st.analysis,
        &stats,
        fd,
        ctx.fs_hz,
        cfg.alpha,
        &st.tested,
        ctx.data_delay_s(),
    );
    let current = Current {
        model: &st.model,
        cost: st.cost,
        stats: &stats,
    };
    let merge = |m: AdditiveModel, c: f64, notes: &mut Vec<String>| {
        accept::merge_twins(ctx, cfg, riv, m, c, "after the repairs", notes).ok()
    };
    let repairs = std::mem::take(&mut st.repairs_due);
    // the trial made before the loop stands for round 1's
    let made = st.repairs_made.take();
    let repairs_trial = || match &made {
        Some(t) => t.clone(),
        None => trial::repaired_modes(ctx, cfg, riv, &current, &merge),
    };
    if proposals.is_empty() {
        // nothing proposed while the residual is significant: modes without a peak of
        // their own (a merged close pair, a mode beyond a band edge) ...
        if repairs {
            let round = st.n_accepted + 1;
            let what = "close pairs and modes beyond the band edges";
            announce(cfg, &mut st.n_tests, round, what);
            if let Some(t) = repairs_trial() {
                return Some(vec![t]);
            }
        }
        // ... and the modes a common denominator sees that the model lacks
        let sk = st
            .sk_start
            .get_or_insert_with(|| {
                restart::common_denominator_start(ctx, cfg, "none")
                    .ok()
                    .map(|f| f.fit.model)
            })
            .as_ref()?;
        let what = "the common-denominator start's modes";
        announce(cfg, &mut st.n_tests, st.n_accepted + 1, what);
        return trial::common_denominator_modes(ctx, cfg, riv, &current, sk).map(|t| vec![t]);
    }
    let round_no = st.n_accepted + 1;
    let n_tests = std::sync::atomic::AtomicUsize::new(st.n_tests);
    let progress = |what: String| {
        let n = n_tests.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        cfg.progress.step(
            "diagnose",
            n,
            None,
            None,
            format!("round {round_no}: testing {what}"),
        );
    };
    let has = |e: Effect| proposals.iter().any(|p| p.candidate.effect() == e);
    // The trials of a round are independent refits of the same current model: they run
    // in parallel (rayon), in two waves. The first holds the joint missed-mode trial,
    // the delay restart and every candidate that is not a single missed mode; the
    // single-peak missed modes follow only when the joint trial did not pass its F
    // test (it subsumes them). Each wave keeps the order of its jobs.
    // The restart is a fit from the start: it holds none of the effects accepted so far,
    // so once a step has been accepted it cannot compete with the current model (and it
    // costs a whole first fit); the incremental `delay` candidate tests the delay then.
    let restart = (!st.model.factor.fit_delay
        && !st.restart_tested
        && st.n_accepted == 0
        && has(Effect::Delay))
    .then(|| st.delay_restart.take());
    st.restart_tested |= restart.is_some();
    // a mode proposed as the other reading of the suspension signature is no residual
    // peak: it runs beside that stiffness in the first wave, judged against it
    let peak_mode = |p: &Proposal| {
        matches!(
            p.candidate,
            Candidate::MissedMode {
                body_integrators: None,
                ..
            }
        )
    };
    let joint = proposals.iter().any(peak_mode);
    let (modes, others): (Vec<Proposal>, Vec<Proposal>) =
        proposals.into_iter().partition(peak_mode);
    let mut first_wave: Vec<Job> = Vec::new();
    if joint {
        first_wave.push(Job::JointModes);
    }
    if let Some(r) = restart {
        first_wave.push(Job::DelayRestart(Box::new(r)));
    }
    if repairs {
        first_wave.push(Job::Repairs);
    }
    first_wave.extend(others.into_iter().map(Job::Candidate));
    let run = |jobs: Vec<Job>| -> Vec<Trial> {
        jobs.into_par_iter()
            .map(|job| match job {
                Job::JointModes => {
                    progress("missed modes jointly".into());
                    trial::joint_missed_modes(ctx, cfg, riv, &current)
                }
                Job::DelayRestart(r) => {
                    progress("a delay with a refit from the start".into());
                    trial::restart_with_delay(ctx, cfg, &current, *r)
                }
                Job::Repairs => {
                    progress("close pairs and modes beyond the band edges".into());
                    repairs_trial()
                }
                Job::Candidate(p) => {
                    progress(effect_name(p.candidate.effect()).into());
                    trial::refit_candidate(ctx, cfg, riv, &current, p, Some(SCREEN_ITERATIONS))
                }
            })
            .collect::<Vec<_>>()
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
    };
    // screened refits that can still be the round's best continue to convergence
    // the rational twins of dynamics factors are judged after the round (their zeros'
    // own F test, `trial::test_zeros`): they set no bar for the others' screening
    let is_twin = |t: &Trial| {
        t.candidate
            .as_ref()
            .and_then(|c| c.factor_start())
            .is_some_and(|s| s.zeros.is_some())
    };
    let finish = |trials: Vec<Trial>| -> Vec<Trial> {
        let best_drop = trials
            .iter()
            .filter(|t| !is_twin(t))
            .map(|t| current.cost - t.cost)
            .fold(0.0_f64, f64::max);
        // a screened cost bounds the converged one from above, so the lowest cost of a
        // passing trial is one the round's best reaches at least
        let best_cost = trials
            .iter()
            .filter(|t| t.passes() && !is_twin(t))
            .map(|t| t.cost)
            .fold(f64::INFINITY, f64::min);
        trials
            .into_par_iter()
            .filter_map(|mut t| {
                let Some(sc) = &t.screened else {
                    return Some(t);
                };
                let drop = current.cost - t.cost;
                let reachable = sc
                    .remaining
                    .is_none_or(|r| t.cost - SCREEN_MARGIN * r <= best_cost);
                if drop >= SCREEN_KEEP * best_drop && reachable {
                    return trial::finish(ctx, cfg, riv, &current, t);
                }
                let why = if reachable {
                    format!(
                        "{:.2}% of the round's best cost decrease",
                        100.0 * drop / best_drop.max(f64::MIN_POSITIVE)
                    )
                } else {
                    format!(
                        "a cost {:.3e} times the round's best passing trial, and its decreases extrapolate to at most {:.3e} of its cost more",
                        t.cost / best_cost,
                        SCREEN_MARGIN * sc.remaining.unwrap_or(f64::NAN) / t.cost
                    )
                };
                t.evidence = format!(
                    "{}; screened: the refit stopped after {} iterations with {why}, so it cannot be the round's best and was not refitted to convergence",
                    t.evidence, sc.iterations,
                );
                t.screened = None;
                Some(t)
            })
            .collect()
    };
    for p in &first_wave {
        if let Job::Candidate(p) = p {
            st.tested.push((p.candidate.effect(), p.candidate.key()));
        }
    }
    let mut trials = finish(run(first_wave));
    let joint_passed = trials
        .iter()
        .any(|t| t.passes() && t.params.effect() == Effect::MissedMode);
    if !joint_passed && !modes.is_empty() {
        for p in &modes {
            st.tested.push((p.candidate.effect(), p.candidate.key()));
        }
        trials.extend(run(modes.into_iter().map(Job::Candidate).collect()));
        trials = finish(trials);
    }
    // a factor's zeros must be significant beside the same factor without them
    trial::test_zeros(&mut trials, fd, cfg, &current);
    // a second-order factor with a pole far beyond the band is the first-order one
    trial::test_far_poles(&mut trials, fd);
    // a low mode beside the free body and a suspended body: the body's parameters decide
    trial::mode_or_suspension(&mut trials, fd, cfg);
    st.n_tests = n_tests.into_inner();
    (!trials.is_empty()).then_some(trials)
}

/// The round's best trial ([`accept::best`]) that also lowers the error on interleaved
/// held-out lines ([`held_out::held_out`]): a best trial that raises it is held back
/// (its evidence says why) and the next best is checked. A check that cannot be made
/// (too few lines, a failed refit) does not hold a trial back.
fn best_held_out(
    ctx: &FitContext,
    riv: &RivConfig,
    trials: &mut [Trial],
    current: &AdditiveModel,
    current_cost: f64,
) -> Option<usize> {
    loop {
        let i = accept::best(trials, current, current_cost)?;
        let h = held_out::held_out(ctx.held_out_halves(), riv, current, &trials[i].model);
        trials[i].held_out = h;
        match h {
            Some(h) if !h.lowers() => trials[i].hold_back(&raises_held_out_cost(&h)),
            _ => return Some(i),
        }
    }
}

/// A reading that its F test accepted (a simpler model in place of `current`: a
/// suspended body for a free body and a low mode, a delay for a common factor) checked
/// on interleaved held-out lines ([`held_out::held_out`]) as a loop step is: it is kept
/// only when the simpler model's held-out cost is below the current model's (the
/// parameters it drops then followed only the fitted lines). A reading that raises it
/// is not accepted, and its evidence says so. A check that cannot be made (too few
/// lines, a failed refit) does not hold the reading back.
fn reading_held_out(
    ctx: &FitContext,
    riv: &RivConfig,
    current: &AdditiveModel,
    tr: &mut Trial,
) -> bool {
    let h = held_out::held_out(ctx.held_out_halves(), riv, current, &tr.model);
    tr.held_out = h;
    match h {
        Some(h) if !h.lowers() => {
            tr.evidence = format!("{}; {}", tr.evidence, raises_held_out_cost(&h));
            false
        }
        _ => true,
    }
}

/// Why a step or a reading whose held-out check `h` raised the cost is not accepted.
fn raises_held_out_cost(h: &frf_data::structure::HeldOutCost) -> String {
    format!(
        "not accepted: on interleaved held-out lines (refitted on the even lines and tested on the odd ones, and the reverse) it raises the weighted cost from {:.4e} to {:.4e}",
        h.before, h.after
    )
}

/// Iterations of a candidate's screening refit: a refit that has not converged by then
/// continues only when its cost decrease is at least [`SCREEN_KEEP`] of the round's best
/// (most of a refit's decrease comes in its first iterations; the rest are spent on
/// candidates that cannot win the round).
const SCREEN_ITERATIONS: usize = 4;

/// The fraction of the round's best cost decrease a screened refit must reach to be
/// refitted to convergence.
const SCREEN_KEEP: f64 = 0.25;

/// How many times its extrapolated remaining decrease ([`refit::remaining_decrease`]) a
/// screened refit is granted: it continues only when its cost, lowered by that much,
/// reaches the round's best passing cost (the extrapolation assumes geometrically
/// shrinking decreases; the margin covers refits that settle more slowly).
const SCREEN_MARGIN: f64 = 3.0;

/// One trial of a round, run on its own thread.
enum Job {
    /// The missed modes jointly ([`trial::joint_missed_modes`]).
    JointModes,
    /// The delay by a refit from the start ([`trial::restart_with_delay`]), with the
    /// restart made before the loop when there is one.
    DelayRestart(Box<Option<DelayRestart>>),
    /// One proposed candidate ([`trial::refit_candidate`]).
    Candidate(Proposal),
    /// The modes of the repairs: close pairs, a mode beyond a band edge
    /// ([`trial::repaired_modes`]).
    Repairs,
}

/// The run's steps as the loop and the readings record them, each with the model
/// response before it and after it (for the report's figures).
#[derive(Default)]
struct Record {
    steps: Vec<StepSummary>,
    responses: Vec<(ResponseGrid, ResponseGrid)>,
}

impl Record {
    /// Records trial `tr` (accepted or not) as its steps, each with the response before
    /// it (`before`: the response and its error statistics) and the one after it;
    /// returns the response after it.
    fn trial(
        &mut self,
        ctx: &FitContext,
        tr: &Trial,
        accepted: bool,
        (before_resp, before): (&ResponseGrid, ErrorStats),
    ) -> ResponseGrid {
        let after_resp = tr.model.response_at(&ctx.omega);
        let after = error_stats(&ctx.band, &after_resp, &ctx.noise);
        for step in step_summaries(tr, accepted, before, after) {
            self.steps.push(step);
            self.responses
                .push((before_resp.clone(), after_resp.clone()));
        }
        after_resp
    }
}

/// The steps of `tr`: one, or for a joint missed-mode trial one per mode it added.
fn step_summaries(
    tr: &Trial,
    accepted: bool,
    before: ErrorStats,
    after: ErrorStats,
) -> Vec<StepSummary> {
    let step = |params: &FittedEffect, evidence: String| StepSummary {
        fitted: params.clone(),
        accepted,
        evidence,
        uncertainty: None,
        f_statistic: tr.f,
        f_critical: tr.f_crit,
        added_params: tr.added,
        before,
        after,
        figure: None,
        superseded_by: None,
        held_out: tr.held_out,
    };
    if tr.joint_modes.is_empty() {
        return vec![step(&tr.params, tr.evidence.clone())];
    }
    let n = tr.joint_modes.len();
    tr.joint_modes
        .iter()
        .enumerate()
        .map(|(k, &(f_hz, zeta))| {
            step(
                &FittedEffect::MissedMode { f_hz, zeta },
                format!("mode {} of {n} added together; {}", k + 1, tr.evidence),
            )
        })
        .collect()
}
