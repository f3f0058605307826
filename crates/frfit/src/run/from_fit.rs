//! A diagnosis never ends worse on the data than `frfit fit` does.
//!
//! `frfit diagnose` starts from its own first fit (the declared delay held, no SK
//! second start, with `--modes N` no mode added), so that an undeclared delay or a
//! missed mode is found as a step. On measured data that start can be far poorer than
//! the model `frfit fit` ends with (a fitted delay, the second start's common
//! denominator, the first fit's completed modes), and the loop, which only adds effects
//! that pass their tests, may not climb back. [`crate::run::run`] therefore compares
//! the diagnosis's final model with `fit`'s model ([`fit_reference`]); when the
//! diagnosis ends worse than it ([`ends_worse`]), the diagnosis runs again from `fit`'s
//! model, and when even that ends worse, `fit`'s model is the final one. The summary
//! says so ([`FromFitSummary`]). A diagnosis whose residual is at the noise level it is
//! judged against needs no comparison (no model is significantly better on the data):
//! `fit`'s model is then not fitted at all.

use crate::diagnose::{diagnose, Diagnosis};
use crate::pipeline::{err, error_stats, fit_reference, FirstFit, FitContext, PipelineConfig};
use crate::summary::{ErrorStats, FromFitSummary};
use crate::FrfitError;
use additive_riv::AdditiveModel;
use frf_data::ModelStructure;
use realize::ResponseGrid;
use validation::analysis::analyze_residual;

/// A model's weighted cost on the band, its parameters and its error statistics.
#[derive(Debug, Clone, Copy)]
pub struct Standing {
    /// Weighted cost on the band's fit data.
    pub cost: f64,
    /// Real parameters.
    pub n_params: usize,
    /// Error statistics against the data.
    pub errors: ErrorStats,
}

impl Standing {
    /// The standing of `model` (whose response at the band's lines is `response`).
    pub fn of(ctx: &FitContext, model: &AdditiveModel, response: &ResponseGrid) -> Self {
        Self {
            cost: additive_riv::residual_stats::cost_of(model, &ctx.fit_data),
            n_params: model.n_params(),
            errors: error_stats(&ctx.band, response, &ctx.noise),
        }
    }
}

/// Whether a chi-squared excess `excess` (a sum of squares in units of the noise
/// variance) between two models is significant when the better one spends `dp` more
/// parameters: above `dp + 5 sqrt(2 dp)`, five standard deviations of `chi2(dp)` above
/// its mean (`dp` at least 1). Under the null that the model with fewer parameters is
/// as good, its excess is `chi2(dp)` distributed.
fn significant_excess(excess: f64, dp: f64) -> bool {
    let dp = dp.max(1.0);
    excess > dp + 5.0 * (2.0 * dp).sqrt()
}

/// Why `a` ends significantly worse on the data than `b`, or `None` when it does not.
/// Two readings of the same residuals, either one suffices:
/// - the weighted cost (the criterion both were fitted by): `(c_a - c_b) / s^2` with
///   `s^2 = c_b / (N - p_b)` the noise scale of `b`, significant by
///   [`significant_excess`] with `dp = p_b - p_a`;
/// - the residual against the noise level (the summary's residual/noise `r`):
///   `N (r_a^2 - r_b^2)` is the same excess in units of the measured or estimated
///   noise variance, whatever the weighting.
///
/// A model with fewer parameters is allowed the cost of the ones it does not spend: two
/// models at the noise level differ by a few percent in `r` without being different.
pub fn ends_worse(a: &Standing, b: &Standing, n_obs: usize) -> Option<String> {
    let n = n_obs as f64;
    let dp = b.n_params as f64 - a.n_params as f64;
    let s2 = b.cost / (n - b.n_params as f64).max(1.0);
    let mut why = Vec::new();
    if s2 > 0.0 && significant_excess((a.cost - b.cost) / s2, dp) {
        why.push(format!(
            "weighted cost {:.4e} against {:.4e}",
            a.cost, b.cost
        ));
    }
    let (ra, rb) = (a.errors.residual_to_noise, b.errors.residual_to_noise);
    if ra.is_finite() && rb.is_finite() && significant_excess(n * (ra * ra - rb * rb), dp) {
        why.push(format!("residual/noise {ra:.4} against {rb:.4}"));
    }
    (!why.is_empty()).then(|| {
        format!(
            "{}; median relative error {:.4} against {:.4}",
            why.join(", "),
            a.errors.median_rel,
            b.errors.median_rel
        )
    })
}

/// The first fit a diagnosis started from, for the summary of a replaced one.
pub struct StartRecord<'a> {
    /// Its model.
    pub model: &'a AdditiveModel,
    /// Its errors.
    pub errors: ErrorStats,
}

/// What replaced a diagnosis that ended worse than `fit`'s model ([`FromFit::replaced`]):
/// `fit`'s model as the new start.
pub struct Replacement {
    /// `fit`'s first fit, the new start.
    pub reference: FirstFit,
    /// Its response at the band's lines.
    pub response: ResponseGrid,
    /// Its errors.
    pub errors: ErrorStats,
    /// What the summary says.
    pub summary: FromFitSummary,
}

/// What [`from_fit_if_worse`] decided.
pub struct FromFit {
    /// The diagnosis kept: the one given, or the one from `fit`'s model.
    pub diagnosis: Diagnosis,
    /// The response of its final model at the band's lines (computed here, so that the
    /// run does not compute it again).
    pub final_response: ResponseGrid,
    /// The new start when the diagnosis ran again from `fit`'s model.
    pub replaced: Option<Replacement>,
}

/// Keeps `diagnosis` when its final residual is at the noise level it is judged against
/// (no model can then be significantly better on the data) or when it ends no worse
/// ([`ends_worse`]) than `frfit fit`'s model on the same band and options
/// ([`fit_reference`], fitted here only when needed). Otherwise runs the diagnosis
/// again from `fit`'s model and returns it, with that model as its start. When that
/// second diagnosis ends worse than `fit`'s model too (its loop's guard compares weighted
/// costs only), `fit`'s model itself is its final model and its messages say why.
pub fn from_fit_if_worse(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    mut diagnosis: Diagnosis,
    start: StartRecord<'_>,
) -> Result<FromFit, FrfitError> {
    let final_response = diagnosis.fit.model.response_at(&ctx.omega);
    let kept = |diagnosis, final_response| FromFit {
        diagnosis,
        final_response,
        replaced: None,
    };
    let analysis = analyze_residual(
        &ctx.band,
        &final_response,
        ctx.judging_noise(),
        &ctx.residual_config(&diagnosis.fit.model),
    )
    .map_err(err("residual analysis"))?;
    if !analysis.significant {
        return Ok(kept(diagnosis, final_response));
    }
    // `None`: a given start model (the two agree)
    let reference = match fit_reference(ctx, cfg) {
        None => return Ok(kept(diagnosis, final_response)),
        Some(Err(e)) => {
            diagnosis.fit.messages.push(format!(
                "the diagnosis ended above the noise level, but the model `frfit fit` gives could not be fitted to compare with ({e})"
            ));
            return Ok(kept(diagnosis, final_response));
        }
        Some(Ok(r)) => r,
    };
    let n_obs = ctx.fit_data.observations();
    let ours = Standing::of(ctx, &diagnosis.fit.model, &final_response);
    let ref_response = reference.fit.model.response_at(&ctx.omega);
    let theirs = Standing::of(ctx, &reference.fit.model, &ref_response);
    let Some(reason) = ends_worse(&ours, &theirs, n_obs) else {
        return Ok(kept(diagnosis, final_response));
    };
    let replaced_accepted: Vec<String> = diagnosis
        .steps
        .iter()
        .filter(|s| s.accepted)
        .map(|s| s.effect().to_string())
        .collect();
    // a feedthrough that `fit`'s model holds (its common-denominator start is biproper)
    // and the diagnosis's own first fit did not is tested by the loop as a step: the
    // loop starts from `fit`'s model without it
    let without_feedthrough = (reference.fit.model.has_feedthrough()
        && !start.model.has_feedthrough())
    .then(|| feedthrough_taken_out(ctx, cfg, &reference.fit))
    .flatten();
    let summary = FromFitSummary {
        reason: format!(
            "the diagnosis from its own first fit ended worse on the data than the model `frfit fit` gives ({reason}); it ran again from that model"
        ),
        fit_errors: theirs.errors,
        replaced_initial_modes: start.model.modes().len(),
        replaced_initial_errors: start.errors,
        replaced_final_modes: diagnosis.fit.model.modes().len(),
        replaced_final_errors: ours.errors,
        replaced_accepted,
        feedthrough_taken_out: without_feedthrough.is_some(),
    };
    cfg.progress.step(
        "diagnose",
        0,
        None,
        None,
        "starting again from `fit`'s model",
    );
    // the diagnosis from `start` (a fit and its response), with the summary's reason
    // first in its messages: its final response and standing
    let run_from = |start: &frf_data::Fit<AdditiveModel>,
                    response: &ResponseGrid,
                    note: Option<&str>|
     -> Result<(Diagnosis, ResponseGrid, Standing), FrfitError> {
        let mut d = diagnose(ctx, cfg, start.clone(), response, None, None, None)?;
        d.fit.messages.insert(0, summary.reason.clone());
        if let Some(n) = note {
            d.fit.messages.insert(1, n.to_string());
        }
        let r = d.fit.model.response_at(&ctx.omega);
        let s = Standing::of(ctx, &d.fit.model, &r);
        Ok((d, r, s))
    };
    // from `fit`'s model without its feedthrough; when that does not climb back to
    // `fit`'s model, from `fit`'s model as it is
    let mut from_start = None;
    if let Some(f) = without_feedthrough {
        let response = f.model.response_at(&ctx.omega);
        let run = run_from(&f, &response, None)?;
        if ends_worse(&run.2, &theirs, n_obs).is_none() {
            let errors = error_stats(&ctx.band, &response, &ctx.noise);
            from_start = Some((run, (f, response, errors)));
        }
    }
    let feedthrough_taken_out = from_start.is_some();
    let ((mut second, mut final_response, second_standing), (start_fit, start_response, start_errors)) =
        match from_start {
            Some(r) => r,
            None => (
                run_from(
                    &reference.fit,
                    &ref_response,
                    summary.feedthrough_taken_out.then_some(
                        "the diagnosis from `fit`'s model without its feedthrough ended worse than that model; it ran again from `fit`'s model as it is",
                    ),
                )?,
                (reference.fit.clone(), ref_response.clone(), theirs.errors),
            ),
        };
    let mut summary = summary;
    summary.feedthrough_taken_out = feedthrough_taken_out;
    if let Some(why) = ends_worse(&second_standing, &theirs, n_obs) {
        let mut kept = reference.fit.clone();
        kept.messages = std::mem::take(&mut second.fit.messages);
        kept.messages.push(format!(
            "the diagnosis from `fit`'s model ended worse than that model ({why}); `fit`'s model is the final model, and the steps accepted on the way are not in it"
        ));
        second.fit = kept;
        final_response = ref_response.clone();
    }
    let mut reference = reference;
    reference.fit = start_fit;
    Ok(FromFit {
        diagnosis: second,
        final_response,
        replaced: Some(Replacement {
            response: start_response,
            errors: start_errors,
            reference,
            summary,
        }),
    })
}

/// `fit` with its feedthrough taken out and the rest refitted (numerators, eq. 24, then
/// Algorithm 1); `None` when the refit fails.
fn feedthrough_taken_out(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    fit: &frf_data::Fit<AdditiveModel>,
) -> Option<frf_data::Fit<AdditiveModel>> {
    let fd = &ctx.fit_data;
    let mut m = fit.model.clone();
    m.submodels
        .retain(|s| s.kind != additive_riv::SubmodelKind::Feedthrough);
    additive_riv::fit_numerators(&mut m, fd).ok()?;
    let riv = additive_riv::riv::RivConfig {
        progress: frf_data::ProgressSink::none(),
        ..ctx.riv_config(cfg)
    };
    let refit = additive_riv::riv::iterate(m, fd, &riv).ok()?;
    let mut out = fit.clone();
    out.model = refit.model;
    out.messages.push(
        "`fit`'s model with its feedthrough taken out and the rest refitted: the start of the diagnosis, which tests a feedthrough as a step".into(),
    );
    Some(out)
}
