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
mod fitted;
mod trial;

pub use candidate::{Candidate, DelayStart, FactorStart, Proposal};
pub use fitted::{FittedEffect, PoleParams, Refit};

use crate::pipeline::{err, error_stats, FitContext, PipelineConfig};
use crate::summary::{ErrorStats, StepSummary};
use crate::FrfitError;
use additive_riv::riv::RivConfig;
use additive_riv::structure::ResidualStats;
use additive_riv::AdditiveModel;
use frf_data::{Fit, ModelStructure, ProgressSink};
use realize::ResponseGrid;
use trial::{model_cost, Current, Trial};
use validation::residual::{analyze_residual, Effect, ResidualAnalysis};

/// The summary name of an effect (`missed_mode`, `delay`, ...).
pub fn effect_name(e: Effect) -> &'static str {
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

/// What the loop produced.
pub struct Diagnosis {
    /// The final fit (the first fit when the loop ended worse than it).
    pub fit: Fit<AdditiveModel>,
    /// Every tested candidate, in order.
    pub steps: Vec<StepSummary>,
    /// Per step, the model response before and after.
    pub step_responses: Vec<(ResponseGrid, ResponseGrid)>,
}

/// The state of the loop between rounds.
struct State {
    model: AdditiveModel,
    cost: f64,
    response: ResponseGrid,
    analysis: ResidualAnalysis,
    tested: Vec<(Effect, String)>,
    restart_tested: bool,
    n_tests: usize,
    n_accepted: usize,
}

/// Runs the diagnosis loop from `first` (the first fit of `ctx.band`, whose response
/// at the band's lines is `first_response`).
pub fn diagnose(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    first: Fit<AdditiveModel>,
    first_response: &ResponseGrid,
) -> Result<Diagnosis, FrfitError> {
    let mut fit = first;
    let fd = &ctx.fit_data;
    // candidate refits: Algorithm 1 to a coarse tolerance, quietly
    let riv = RivConfig {
        param_tol: 1e-7,
        max_iterations: 30,
        progress: ProgressSink::none(),
        ..ctx.riv_config(cfg)
    };
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
        n_tests: 0,
        n_accepted: 0,
    };
    let mut steps: Vec<StepSummary> = Vec::new();
    let mut step_responses = Vec::new();
    while st.analysis.significant && st.n_accepted < cfg.max_steps {
        let Some(trials) = round(ctx, cfg, &riv, &mut st) else {
            break;
        };
        let before = error_stats(&ctx.band, &st.response, &ctx.noise);
        let best = accept::best(&trials, &st.model, st.cost);
        let mut accepted_model = None;
        for (i, tr) in trials.into_iter().enumerate() {
            let after_resp = tr.model.response_at(&ctx.omega);
            let after = error_stats(&ctx.band, &after_resp, &ctx.noise);
            let accepted = Some(i) == best;
            for step in step_summaries(&tr, accepted, before, after) {
                steps.push(step);
                step_responses.push((st.response.clone(), after_resp.clone()));
            }
            if accepted {
                accepted_model = Some((tr.model, tr.cost));
            }
        }
        let Some((accepted, accepted_cost)) = accepted_model else {
            break;
        };
        st.n_accepted += 1;
        let m = accept::prune(
            ctx,
            cfg,
            accepted,
            accepted_cost,
            steps.len(),
            &mut fit.messages,
        )?;
        st.cost = model_cost(&m, fd);
        st.response = m.response_at(&ctx.omega);
        st.model = m;
        st.analysis = analyze_residual(
            &ctx.band,
            &st.response,
            ctx.judging_noise(),
            &ctx.residual_config(&st.model),
        )
        .map_err(err("residual analysis"))?;
    }
    let fit = accept::final_refinement(ctx, cfg, fit, st.model)?;
    Ok(Diagnosis {
        fit,
        steps,
        step_responses,
    })
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
    if proposals.is_empty() {
        return None;
    }
    let current = Current {
        model: &st.model,
        cost: st.cost,
        stats: &stats,
    };
    let round_no = st.n_accepted + 1;
    let mut n_tests = st.n_tests;
    let mut progress = |what: String| {
        n_tests += 1;
        cfg.progress.step(
            "diagnose",
            n_tests,
            None,
            None,
            format!("round {round_no}: testing {what}"),
        );
    };
    let has = |e: Effect| proposals.iter().any(|p| p.candidate.effect() == e);
    let mut trials: Vec<Trial> = Vec::new();
    // When the joint missed-mode trial passes its F test, the single-peak candidates it
    // subsumes are not refitted one by one.
    if has(Effect::MissedMode) {
        progress("missed modes jointly".into());
        trials.extend(trial::joint_missed_modes(ctx, cfg, riv, &current));
    }
    if !st.model.factor.fit_delay && !st.restart_tested && has(Effect::Delay) {
        st.restart_tested = true;
        progress("a delay with a refit from the start".into());
        trials.extend(trial::restart_with_delay(ctx, cfg, &current));
    }
    let joint_passed = trials
        .iter()
        .any(|t| t.passes() && t.params.effect() == Effect::MissedMode);
    for p in proposals {
        let effect = p.candidate.effect();
        if joint_passed && effect == Effect::MissedMode {
            continue;
        }
        st.tested.push((effect, p.candidate.key()));
        progress(effect_name(effect).into());
        trials.extend(trial::refit_candidate(ctx, cfg, riv, &current, p));
    }
    st.n_tests = n_tests;
    (!trials.is_empty()).then_some(trials)
}

/// The steps of `tr`: one, or for a joint missed-mode trial one per mode it added.
fn step_summaries(
    tr: &Trial,
    accepted: bool,
    before: ErrorStats,
    after: ErrorStats,
) -> Vec<StepSummary> {
    let step = |params: &FittedEffect, evidence: String| StepSummary {
        effect: effect_name(params.effect()).to_string(),
        accepted,
        evidence,
        params: params.to_json(),
        uncertainty: None,
        f_statistic: tr.f,
        f_critical: tr.f_crit,
        added_params: tr.added,
        before,
        after,
        figure: None,
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
