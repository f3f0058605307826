//! The first fit of a run: the model the diagnosis loop starts from (and, for
//! `frfit fit`, the result).

use super::{err, FitContext, PipelineConfig};
use crate::FrfitError;
use additive_riv::riv::iterate;
use additive_riv::{fit_numerators, AdditiveFitter, AdditiveModel, FitterReport};
use frf_data::Fit;

/// Fits the band of `ctx` with the settings of `cfg`.
///
/// Without [`PipelineConfig::start_model`]: the CMIF initialisation with the convex
/// numerator fit, the refined IV iterations (Algorithm 1 of the wafer-stage paper) and
/// the structure adaptation, with the hold and delay resolved in `ctx`
/// ([`FitContext::fitter_config`]). With a start model: its numerators refitted
/// (eq. 24) on `ctx.fit_data`, then Algorithm 1 from it; the report is then empty.
pub fn first_fit(
    ctx: &FitContext,
    cfg: &PipelineConfig,
) -> Result<(Fit<AdditiveModel>, FitterReport), FrfitError> {
    match &cfg.start_model {
        None => AdditiveFitter::new(ctx.fitter_config(cfg))
            .fit(&ctx.band)
            .map_err(err("fit")),
        Some(m) => {
            let mut m = m.clone();
            fit_numerators(&mut m, &ctx.fit_data).map_err(err("fit"))?;
            let f = iterate(m, &ctx.fit_data, &ctx.riv_config(cfg)).map_err(err("fit"))?;
            Ok((f, FitterReport::default()))
        }
    }
}
