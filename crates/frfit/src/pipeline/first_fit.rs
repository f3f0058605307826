//! The first fit of a run: the model the diagnosis loop starts from (and, for
//! `frfit fit`, the result).

use super::config::{default_chain, err, PipelineConfig};
use super::context::FitContext;
use super::summarize::error_stats;
use crate::chain::{run_chain, AdditiveOptions};
use crate::FrfitError;
use additive_riv::chain::PROPORTIONAL_RESIDUE_TOL;
use additive_riv::riv::iterate;
use additive_riv::{fit_numerators, AdditiveModel, CmifInitReport, FitterReport, RivReport};
use frf_data::{ChainSettings, Fit, LinkReport, ModelStructure, Precomputed, Timing};
use realize::Hold;
use std::time::Instant;

/// The first fit of a run and where it came from.
pub struct FirstFit {
    /// The additive model the diagnosis continues from.
    pub fit: Fit<AdditiveModel>,
    /// What the fitter found on the way (CMIF peaks, delay estimate, rigid body).
    pub report: FitterReport,
    /// The chain's link names (`["cmif", "riv"]`); empty for a given start model.
    pub chain: Vec<String>,
    /// Each link's report.
    pub links: Vec<LinkReport>,
    /// Every chain tried when `--init` named several initialisers.
    pub chain_runs: Vec<crate::chain::ChainRun>,
}

/// Fits the band of `ctx` with the settings of `cfg`.
///
/// Without [`PipelineConfig::start_model`]: the estimator chain `cfg.init -> cfg.refine`
/// ([`crate::chain::run_chain`]; by default the CMIF initialisation with the convex
/// numerator fit, then the refined IV iterations of Algorithm 1 of the wafer-stage paper
/// with the structure adaptation), with the hold and delay resolved in `ctx`
/// ([`FitContext::fitter_config`]). The diagnosis continues in the chain's own additive
/// structure when its last link has one, otherwise in the structure of the currency
/// model with numerators by eq. (24). With a start model: its numerators refitted
/// (eq. 24) on `ctx.fit_data`, then Algorithm 1 from it; the report is then empty.
pub fn first_fit(ctx: &FitContext, cfg: &PipelineConfig) -> Result<FirstFit, FrfitError> {
    if let Some(m) = &cfg.start_model {
        let mut m = m.clone();
        fit_numerators(&mut m, &ctx.fit_data).map_err(err("fit"))?;
        let f = iterate(m, &ctx.fit_data, &ctx.riv_config(cfg)).map_err(err("fit"))?;
        return Ok(FirstFit {
            fit: f,
            report: FitterReport::default(),
            chain: Vec::new(),
            links: Vec::new(),
            chain_runs: Vec::new(),
        });
    }
    let fc = ctx.fitter_config(cfg);
    starts(ctx, cfg, &fc, false)
}

/// The model `frfit fit` ends with on the band of `ctx` with the options of `cfg`
/// (its delay handling, the SK second start and the first fit's mode completion),
/// quietly: what a diagnosis must not end worse than (see [`crate::run::run`]).
/// `None` when the run starts from a given model (there the two agree).
pub fn fit_reference(
    ctx: &FitContext,
    cfg: &PipelineConfig,
) -> Option<Result<FirstFit, FrfitError>> {
    if cfg.start_model.is_some() {
        return None;
    }
    let fit_cfg = PipelineConfig {
        diagnose: false,
        progress: frf_data::ProgressSink::none(),
        ..cfg.clone()
    };
    // `frfit fit` estimates and refines the delay unless one is given
    let delay = cfg.delay.unwrap_or(additive_riv::DelayChoice::Auto);
    let fc = start_fitter_config(ctx, &fit_cfg, (delay, ctx.hold.unwrap_or_default()), true);
    Some(starts(ctx, &fit_cfg, &fc, true))
}

/// The lowest fraction of the stated sample rate the band must reach for the hold start
/// ([`hold_start_rate`]):
/// there a zero-order hold's droop `sin(pi f / fs) / (pi f / fs)` is 6.5 % (0.68 at
/// 0.47 fs, the top of a band up to 3 kHz at 6400 Hz), far above a measurement's noise.
pub const HOLD_START_FRACTION: f64 = 0.2;

/// For `frfit fit`: when the data state their sample rate `fs` (the time records'
/// rate, written by `frfit nonparametric`) but no hold, nothing gives one, the delay is
/// estimated (`--delay auto`, the default) and the band reaches
/// [`HOLD_START_FRACTION`] of `fs`, the hold the fit models is unknown: the converter of
/// a digitally driven actuator holds, and without the hold a fit spends poles on its
/// droop near Nyquist (the simulated piezo mechanism from its time records, 5 modes:
/// 6 to 10 modes, 3 of 8 seeds not converged). Then the starts run twice, without and
/// with the exact zero-order hold at `fs`, and the fit with the smaller final prediction
/// error is kept (the hold adds no parameter; data whose input was measured after the
/// hold keep the fit without it). `None` when the starts run once.
fn hold_start_rate(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    fc: &additive_riv::FitterConfig,
) -> Option<f64> {
    let top = ctx.fit_data.band_hz.1;
    ctx.fs_hz.filter(|&fs| {
        // no hold given or declared (`ctx.hold` is the command line's, else the file's)
        !cfg.diagnose
            && ctx.hold.is_none()
            && fc.delay == additive_riv::DelayChoice::Auto
            && cfg.frf_type == super::config::FrfType::Displacement
            && top >= HOLD_START_FRACTION * fs
            && top < 0.5 * fs
    })
}

/// The starts of a run with the fitter settings `fc`: the chain, then the
/// [`second_start`] and [`third_start`] where they apply; for `frfit fit` on data with
/// a stated sample rate and no hold ([`hold_start_rate`]), all of them without and with
/// the zero-order hold, the one with the smaller final prediction error kept. A better
/// start, not an effect: the messages and `chain_runs` (the held chains with their
/// `hold`) say which ran and which was kept. The diagnosis does not take the hold start:
/// its loop tests a hold as an effect, with its errors before and after.
fn starts(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    fc: &additive_riv::FitterConfig,
    quiet: bool,
) -> Result<FirstFit, FrfitError> {
    let sequence = |hold: Hold| -> Result<FirstFit, FrfitError> {
        let fc = additive_riv::FitterConfig { hold, ..fc.clone() };
        let first = chain_fit(ctx, cfg, &fc)?;
        second_start(ctx, cfg, first, (fc.delay, hold), quiet)
    };
    let plain = sequence(fc.hold);
    let Some(fs) = hold_start_rate(ctx, cfg, fc) else {
        return plain;
    };
    let t = Instant::now();
    let held = sequence(Hold::Zoh { fs_hz: fs });
    let time = Timing {
        stage: format!("hold start: zoh:{fs}"),
        seconds: t.elapsed().as_secs_f64(),
    };
    let why = format!(
        "the data state a sample rate of {fs} Hz without a hold and the band reaches {:.2} of it",
        ctx.fit_data.band_hz.1 / fs
    );
    let fd = &ctx.fit_data;
    // a sequence's runs (its kept fit alone when it ran one chain), the held ones named
    let runs_of = |f: &mut FirstFit, hold: Option<String>| -> Vec<crate::chain::ChainRun> {
        let mut runs = std::mem::take(&mut f.chain_runs);
        if runs.is_empty() {
            let mut r = chain_run_of(fd, f);
            r.kept = true;
            runs.push(r);
        }
        for r in &mut runs {
            r.hold = hold.clone();
        }
        runs
    };
    let fpe_of = |f: &FirstFit| chain_run_of(fd, f).fpe.unwrap_or(f64::INFINITY);
    match (plain, held) {
        (Ok(mut p), Ok(mut h)) => {
            let (fpe_p, fpe_h) = (fpe_of(&p), fpe_of(&h));
            let keep_held = fpe_h < fpe_p;
            let note = format!(
                "hold start: {why}; with a zero-order hold at {fs} Hz the starts ended {} ({}) with final prediction error {fpe_h:.4e} against {fpe_p:.4e} without it ({}, {}): {} kept",
                h.chain.join(" -> "),
                h.fit.convergence.describe(),
                p.chain.join(" -> "),
                p.fit.convergence.describe(),
                if keep_held { "the fit with the hold is" } else { "the fit without it is" }
            );
            let mut runs = runs_of(&mut p, None);
            let mut held_runs = runs_of(&mut h, Some(format!("zoh:{fs}")));
            for r in &mut runs {
                r.kept &= !keep_held;
            }
            for r in &mut held_runs {
                r.kept &= keep_held;
            }
            runs.extend(held_runs);
            let mut kept = if keep_held { h } else { p };
            kept.fit.timings.push(time);
            kept.fit.messages.push(note);
            kept.chain_runs = runs;
            Ok(kept)
        }
        (Ok(mut p), Err(e)) => {
            p.fit.timings.push(time);
            p.fit.messages.push(format!(
                "hold start: {why}; with a zero-order hold at {fs} Hz the chain failed ({e}), so the fit without it is kept"
            ));
            Ok(p)
        }
        (Err(e), Ok(mut h)) => {
            h.fit.timings.push(time);
            h.fit.messages.push(format!(
                "hold start: {why}; without a hold the chain failed ({e}), so the fit with a zero-order hold at {fs} Hz is kept"
            ));
            Ok(h)
        }
        (Err(e), Err(_)) => Err(e),
    }
}

/// The initialiser of the second start ([`second_start`]): Sanathanan-Koerner, whose
/// common denominator sees every mode of the band at once (no peak picking), so it
/// separates close pairs and weak modes that the CMIF start merges or misses.
pub const SECOND_START: &str = "sk";

/// The residual-to-noise ratio (root mean square of the residual over the noise level)
/// above which `frfit fit` runs the second start even after a converged refinement.
pub const SECOND_START_RESIDUAL: f64 = 3.0;

/// For `frfit fit`: a default chain whose refinement did not converge (its iterations
/// failed, stalled or ran out) started too far from an optimum, and so did one that
/// leaves a residual more than [`SECOND_START_RESIDUAL`] times the noise (`fit` has no
/// loop to trace it). The same refiner then runs from the [`SECOND_START`] initialiser, and the
/// fit with the smaller final prediction error (the weighted cost corrected for the
/// parameters spent, as between the chains of `--init A,B`) is the first fit. A better
/// second start is a better first fit, not an effect: the fit's messages and
/// `chain_runs` say which chains ran and which was kept. Nothing changes for the
/// diagnosis (its loop and delay restart test the catalogue's effects first; a common
/// denominator from the start would absorb an undeclared delay in spurious poles), when
/// `--init` was given (an explicit choice is kept), when the default chain does not start
/// from the CMIF peaks (above 100 entries it starts from the subspace step, which needs
/// no peaks either, and SK's common denominator of order ~2x the modes is then
/// ill-determined and slow), or when the first fit converged near the noise level.
/// `delay` is the delay handling of the first chain (the second chain takes the same);
/// `quiet` silences the second chain's progress.
fn second_start(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    first: FirstFit,
    setting: (additive_riv::DelayChoice, Hold),
    quiet: bool,
) -> Result<FirstFit, FrfitError> {
    // The diagnosis does not take the second start: its loop and its delay restart test
    // the effects first, and a common denominator from the start absorbs an undeclared
    // delay in spurious poles.
    if cfg.diagnose
        || !cfg.init.trim().is_empty()
        || first.chain.first().is_none_or(|i| i != "cmif")
    {
        return Ok(first);
    }
    let converged = !did_not_converge(&first.fit.convergence);
    // `fit` has no loop to trace a residual far above the noise: a start that left it
    // there is poor too
    let residual_to_noise = error_stats(
        &ctx.band,
        &first.fit.model.response_at(&ctx.omega),
        &ctx.noise,
    )
    .residual_to_noise;
    if converged && residual_to_noise <= SECOND_START_RESIDUAL {
        return Ok(first);
    }
    let second_cfg = PipelineConfig {
        init: SECOND_START.to_string(),
        refine: first.chain.last().cloned().unwrap_or_default(),
        ..cfg.clone()
    };
    let fd = &ctx.fit_data;
    let why = if converged {
        format!("left a residual {residual_to_noise:.1} times the noise level")
    } else {
        format!("did not converge ({})", first.fit.convergence.describe())
    };
    let mut run_first = chain_run_of(fd, &first);
    let fpe_first = run_first.fpe.unwrap_or(f64::INFINITY);
    let second_fc = start_fitter_config(ctx, &second_cfg, setting, quiet);
    let t = Instant::now();
    let second = chain_fit(ctx, &second_cfg, &second_fc);
    let second_time = Timing {
        stage: format!("second start: {SECOND_START} -> {}", second_cfg.refine),
        seconds: t.elapsed().as_secs_f64(),
    };
    let second = match second {
        Ok(s) => s,
        Err(e) => {
            let mut first = first;
            first.fit.timings.push(second_time);
            first.fit.messages.push(format!(
                "second start: the {} chain {why}; the {SECOND_START} chain from the start failed ({e}), so the first chain's fit is kept",
                first.chain.join(" -> ")
            ));
            return Ok(third_start(ctx, cfg, first, setting, quiet));
        }
    };
    let mut run_second = chain_run_of(fd, &second);
    let fpe_second = run_second.fpe.unwrap_or(f64::INFINITY);
    let keep_second = fpe_second < fpe_first;
    run_first.kept = !keep_second;
    run_second.kept = keep_second;
    let runs = vec![run_first, run_second];
    let note = format!(
        "second start: the {} chain {why}; the {} chain from the start ended with final prediction error {fpe_second:.4e} against {fpe_first:.4e}: {} kept",
        first.chain.join(" -> "),
        second.chain.join(" -> "),
        if keep_second { "it is" } else { "the first is" }
    );
    // the run's stages: the first chain's own and the second start's wall time (the
    // second chain's own stages are inside it)
    let mut stages = first.fit.timings.clone();
    stages.push(second_time);
    let mut kept = if keep_second { second } else { first };
    kept.fit.timings = stages;
    kept.fit.messages.push(note);
    kept.chain_runs = runs;
    Ok(third_start(ctx, cfg, kept, setting, quiet))
}

/// The fitter settings of `cfg`'s chain with the delay handling `delay` (that of `fit`,
/// or of the first chain for a further start), quiet (no progress) with `quiet`.
fn start_fitter_config(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    (delay, hold): (additive_riv::DelayChoice, Hold),
    quiet: bool,
) -> additive_riv::FitterConfig {
    let fc = if quiet {
        ctx.quiet_fitter_config(cfg)
    } else {
        ctx.fitter_config(cfg)
    };
    additive_riv::FitterConfig { delay, hold, ..fc }
}

/// The chain's record (cost, parameters, final prediction error) of a fit, unkept.
fn chain_run_of(fd: &additive_riv::FitData, f: &FirstFit) -> crate::chain::ChainRun {
    let cost = additive_riv::residual_stats::cost_of(&f.fit.model, fd);
    let p = frf_data::ModelStructure::n_params(&f.fit.model);
    crate::chain::ChainRun {
        chain: f.chain.clone(),
        cost: Some(cost),
        n_params: Some(p),
        fpe: Some(crate::chain::fpe(cost, p, fd.n * fd.ny * fd.nu)),
        error: None,
        kept: false,
        hold: None,
    }
}

/// The chains of the third start ([`third_start`]), in turn: the common-denominator and
/// the subspace initialiser, each refined by maximum likelihood (Levenberg-Marquardt on
/// the weighted cost).
pub const THIRD_STARTS: [(&str, &str); 2] = [("sk", "ml"), ("subspace", "ml")];

/// For `frfit fit`'s default chain, after [`second_start`]: when the kept fit's
/// refined-IV iterations still did not converge, the chain falls back to further starts
/// rather than returning a non-converged model: the chains of [`THIRD_STARTS`], whose
/// refinement is a descent method on the same weighted cost (the refined-IV iterations
/// are not, and can stop where their step no longer lowers it: the simulated piezo case
/// without its hold declared, 3840 lines, reported FAILED by both refined-IV starts on
/// two seeds). Of those that converged, the one with the smallest final prediction error
/// is kept when that error is no higher than the kept fit's; otherwise the kept fit
/// stays, not converged, and its messages say what was tried.
fn third_start(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    kept: FirstFit,
    setting: (additive_riv::DelayChoice, Hold),
    quiet: bool,
) -> FirstFit {
    if !did_not_converge(&kept.fit.convergence) || kept.chain.last().is_none_or(|r| r != "riv") {
        return kept;
    }
    let fd = &ctx.fit_data;
    let mut kept = kept;
    let why = kept.fit.convergence.describe();
    let mut run_kept = chain_run_of(fd, &kept);
    let fpe_kept = run_kept.fpe.unwrap_or(f64::INFINITY);
    let mut runs: Vec<crate::chain::ChainRun> = std::mem::take(&mut kept.chain_runs);
    if runs.is_empty() {
        run_kept.kept = true;
        runs.push(run_kept);
    }
    let mut tried: Vec<String> = Vec::new();
    // the wall time of each start, added to the stages of the run (the first chain's
    // own stages and the second start's time stay as they are)
    let mut times: Vec<Timing> = Vec::new();
    let mut best: Option<(f64, FirstFit, usize)> = None;
    for (init, refine) in THIRD_STARTS {
        let c = PipelineConfig {
            init: init.to_string(),
            refine: refine.to_string(),
            ..cfg.clone()
        };
        let t = Instant::now();
        let result = chain_fit(ctx, &c, &start_fitter_config(ctx, &c, setting, quiet));
        times.push(Timing {
            stage: format!("third start: {init} -> {refine}"),
            seconds: t.elapsed().as_secs_f64(),
        });
        match result {
            Ok(f) => {
                let run = chain_run_of(fd, &f);
                let fpe = run.fpe.unwrap_or(f64::INFINITY);
                tried.push(format!(
                    "{init} -> {refine} ended {} with final prediction error {fpe:.4e}",
                    f.fit.convergence.describe()
                ));
                runs.push(run);
                if !did_not_converge(&f.fit.convergence)
                    && fpe <= fpe_kept
                    && best.as_ref().is_none_or(|(b, _, _)| fpe < *b)
                {
                    best = Some((fpe, f, runs.len() - 1));
                }
            }
            Err(e) => {
                tried.push(format!("{init} -> {refine} failed ({e})"));
                runs.push(crate::chain::ChainRun {
                    chain: vec![init.to_string(), refine.to_string()],
                    cost: None,
                    n_params: None,
                    fpe: None,
                    error: Some(e.to_string()),
                    kept: false,
                    hold: None,
                });
            }
        }
    }
    let head = format!(
        "third start: the kept {} fit did not converge ({why}; final prediction error {fpe_kept:.4e}); from the start, {}",
        kept.chain.join(" -> "),
        tried.join("; ")
    );
    match best {
        Some((_, mut f, index)) => {
            for (k, r) in runs.iter_mut().enumerate() {
                r.kept = k == index;
            }
            // the second start's note stays with the kept fit
            f.fit.messages.extend(
                kept.fit
                    .messages
                    .iter()
                    .filter(|m| m.starts_with("second start:"))
                    .cloned(),
            );
            f.fit.messages.push(format!(
                "{head}: the converged {} fit is kept",
                f.chain.join(" -> ")
            ));
            // the run's stages: the first chain's and the further starts' (the kept
            // third start's own stages are inside its time)
            f.fit.timings = std::mem::take(&mut kept.fit.timings);
            f.fit.timings.extend(times);
            f.chain_runs = runs;
            f
        }
        None => {
            kept.fit.messages.push(format!(
                "{head}: none converged at a final prediction error no higher, so the non-converged fit is kept"
            ));
            kept.fit.timings.extend(times);
            kept.chain_runs = runs;
            kept
        }
    }
}

/// Whether a convergence is one of the refinement not converging (failed, stalled or
/// out of iterations).
fn did_not_converge(c: &frf_data::Convergence) -> bool {
    matches!(
        c,
        frf_data::Convergence::Failed { .. }
            | frf_data::Convergence::MaxIterations { .. }
            | frf_data::Convergence::Stalled { .. }
    )
}

/// The estimator chain `cfg.init -> cfg.refine` on the band of `ctx` with the fitter
/// settings `fc` (hold, delay, modes, weighting, adaptation, progress), the band's delay
/// estimate and CMIF taken from `ctx`. The model is the chain's own additive structure
/// when its last link has one, otherwise the structure of the currency model with
/// numerators by eq. (24). Used by [`first_fit`] and by the diagnosis's restart trial.
pub fn chain_fit(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    fc: &additive_riv::FitterConfig,
) -> Result<FirstFit, FrfitError> {
    let (init, refine) = default_chain(
        &cfg.init,
        &cfg.refine,
        frf_data::FrfDataset::ny(&ctx.band) * frf_data::FrfDataset::nu(&ctx.band),
    );
    let settings = ChainSettings {
        hold: fc.hold,
        delay: fc.delay,
        derivative_order: fc.derivative_order,
        weighting: fc.riv.weighting.clone(),
        modes: fc.modes.clone(),
        peaks: fc.peaks.clone(),
        order: cfg.order,
        progress: fc.progress.clone(),
        // the band's delay estimate and CMIF, made once in the context (the CMIF only
        // for the initialisers that read it)
        precomputed: Precomputed {
            delay: ctx.delay_estimate.clone(),
            cmif: reads_cmif(&init).then(|| ctx.cmif().cloned()).transpose()?,
        },
    };
    let opts = AdditiveOptions {
        riv: fc.riv.clone(),
        adapt: fc.adapt.clone(),
        rigid_body: fc.rigid_body,
        realizations: ctx.declared.realizations,
        variance_dof: ctx.variance_dof,
        // the plain CMIF start: with the completion the loop's steps change on the
        // reference files (a spurious second input_dynamics step on the input-lag case)
        complete_start: None,
        sk_bands: cfg.sk_bands.clone(),
        starts: Some(ctx.starts.clone()),
    };
    let result = run_chain(&ctx.band, &init, &refine, &settings, &opts)?;
    let t_numerators = std::time::Instant::now();
    let model = match result.model.native::<AdditiveModel>() {
        Some(m) => m.clone(),
        None => {
            let fm = &result.model.model;
            let convert = |tol: f64| -> Result<(AdditiveModel, f64), FrfitError> {
                let (mut m, _) =
                    AdditiveModel::from_frf_model_with(fm, ctx.fit_data.band_hz, 0.01, tol)
                        .map_err(err("fit"))?;
                let cost = fit_numerators(&mut m, &ctx.fit_data).map_err(err("fit"))?;
                Ok((m, cost))
            };
            let (mut m, cost) = convert(PROPORTIONAL_RESIDUE_TOL)?;
            if fm.factors.delay_s != 0.0 {
                // A refiner that fitted a delay turns the residues' phases by up to
                // `w tau` to trade with it: real parts of 1e-3..1e-2 of the residues that
                // a constant numerator (the default tolerance) drops, 8 times the noise
                // on a 20 x 20 plant with noise 1e-3. The structure with `B_0 + B_1 s`
                // wherever the real part exceeds a tenth of the data's relative noise
                // level is fitted too and kept when it is significantly better.
                let noise_rel = ctx.line_floor.as_ref().map_or_else(
                    || ctx.noise.median_relative(&ctx.band),
                    |f| f.declared_median_rel,
                );
                if noise_rel.is_finite() && 0.1 * noise_rel < PROPORTIONAL_RESIDUE_TOL {
                    let (m2, cost2) = convert(0.1 * noise_rel)?;
                    if significantly_better(&ctx.fit_data, (&m, cost), (&m2, cost2)) {
                        m = m2;
                    }
                }
            }
            m
        }
    };
    let numerators_s = t_numerators.elapsed().as_secs_f64();
    let refined_by_riv = result.chain.last().is_some_and(|l| l == "riv");
    let mut report = FitterReport::default();
    for l in &result.links {
        if let Some(r) = l.details_as::<CmifInitReport>() {
            report.cmif_peaks = r.cmif_peaks.clone();
            report.delay_estimate = r.delay_estimate.clone();
            report.integrators = r.integrators;
            report.weighting = r.weighting.clone();
            report.init_cost = r.init_cost;
            report.band_hz = r.band_hz;
        } else if let Some(r) = l.details_as::<RivReport>() {
            report.weighting = r.weighting.clone();
            report.adapt = r.adapt.clone();
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
    let mut fit = Fit {
        model,
        report: (),
        cost_history: last.cost_history.clone(),
        iterations: result.links.iter().map(|l| l.iterations).sum(),
        convergence: last.convergence.clone(),
        timings: result
            .links
            .iter()
            .flat_map(|l| {
                l.timings.iter().map(|t| frf_data::Timing {
                    stage: format!("{}: {}", l.link, t.stage),
                    seconds: t.seconds,
                })
            })
            .chain(
                result
                    .model
                    .native::<AdditiveModel>()
                    .is_none()
                    .then(|| frf_data::Timing {
                        stage: "additive model: numerators".into(),
                        seconds: numerators_s,
                    }),
            )
            .collect(),
        estimator: result
            .links
            .iter()
            .map(|l| format!("{}: {}", l.link, l.estimator))
            .collect::<Vec<_>>()
            .join(" -> "),
        messages,
    };
    // with declared modes a diagnosis tests the repairs in its loop (they add modes)
    if refined_by_riv && cfg.first_fit_adds_modes() {
        let repair;
        (fit, repair) = repair_fit(fit, &ctx.fit_data, &fc.riv)?;
        report.repair = Some(repair);
    }
    Ok(FirstFit {
        fit,
        report,
        chain: result.chain,
        links: result.links,
        chain_runs: result.runs,
    })
}

/// The repairs of a refined fit that the structure adaptation cannot make
/// ([`additive_riv::split`]): a mode beyond a band edge (a tail rising towards the edge,
/// which the loop would otherwise explain by a feedthrough), then close pairs that the
/// CMIF start merged into one mode. The model and the close pairs are the plant's modal
/// structure, not effects the model lacks, so they belong to the first fit: the
/// diagnosis loop then starts at the noise level. When something changed, Algorithm 1
/// converges fully (`riv`) from the repaired structure; the fit's messages say what was
/// done.
fn repair_fit(
    fit: Fit<AdditiveModel>,
    data: &additive_riv::FitData,
    riv: &additive_riv::RivConfig,
) -> Result<(Fit<AdditiveModel>, additive_riv::split::RepairReport), FrfitError> {
    use additive_riv::split::{add_out_of_band_mode, split_close_pairs, SplitConfig};
    let cfg = SplitConfig::default();
    let (model, mut report) =
        add_out_of_band_mode(fit.model.clone(), data, riv, &cfg).map_err(err("fit"))?;
    let (model, pairs) = split_close_pairs(model, data, riv, &cfg).map_err(err("fit"))?;
    report.splits = pairs.splits;
    report.rejected.extend(pairs.rejected);
    if report.is_empty() {
        return Ok((fit, report));
    }
    let refined = iterate(model, data, riv).map_err(err("fit"))?;
    let mut out = fit;
    out.model = refined.model;
    out.cost_history.extend_from_slice(&refined.cost_history);
    out.iterations += refined.iterations;
    out.convergence = refined.convergence;
    out.estimator
        .push_str(" -> repairs (out-of-band mode, close pairs)");
    for m in &report.out_of_band {
        out.messages.push(format!(
            "added an out-of-band mode at {:.2} Hz (zeta {:.4}, beyond the {} band edge; F = {:.1}; weighted cost {:.4e} -> {:.4e})",
            m.f_hz, m.zeta, m.edge, m.f_stat, m.cost.0, m.cost.1
        ));
    }
    for s in &report.splits {
        out.messages.push(format!(
            "split the mode at {:.2} Hz into a close pair at {:.2} and {:.2} Hz (F = {:.1}; weighted cost {:.4e} -> {:.4e})",
            s.from_hz, s.into[0].0, s.into[1].0, s.f_stat, s.cost.0, s.cost.1
        ));
    }
    Ok((out, report))
}

/// True when one of the initialisers of `init` (a name, a list `a,b` or `auto`) reads
/// the band's CMIF: the CMIF start picks its peaks, SK its order from them.
fn reads_cmif(init: &str) -> bool {
    init.split(',')
        .map(str::trim)
        .any(|n| matches!(n, "cmif" | "sk" | "auto" | ""))
}

/// Whether the numerators of `(m2, cost2)` (a structure with more numerator terms than
/// `(m1, cost1)`, fitted to the same data by [`fit_numerators`]) fit significantly
/// better: the F statistic `((c1 - c2) / dp) / (c2 / (N - p2))` over the added numerator
/// parameters `dp` (`N` real residuals) above `1 + 5 sqrt(2 / dp)`, five standard
/// deviations of `F(dp, N - p2)` under the null for `N >> p2` (its mean is 1, its
/// variance about `2 / dp`).
fn significantly_better(
    data: &additive_riv::problem::FitData,
    (m1, cost1): (&AdditiveModel, f64),
    (m2, cost2): (&AdditiveModel, f64),
) -> bool {
    let entries = data.m() as f64;
    let n_num = |m: &AdditiveModel| -> f64 {
        m.submodels.iter().map(|s| s.n_num()).sum::<usize>() as f64 * entries
    };
    let (p1, p2) = (n_num(m1), n_num(m2));
    let dp = p2 - p1;
    let n_obs = 2.0 * data.n as f64 * entries;
    if dp <= 0.0 || n_obs <= p2 || cost2.is_nan() || cost2 <= 0.0 || !cost1.is_finite() {
        return false;
    }
    let f = ((cost1 - cost2) / dp) / (cost2 / (n_obs - p2));
    f > 1.0 + 5.0 * (2.0 / dp).sqrt()
}
