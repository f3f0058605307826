//! A step earns its place on data it was not fitted to (issue 42): interleaved lines.
//!
//! The band's lines are split into the even and the odd ones
//! ([`crate::pipeline::interleave`]). The model before the step and the model after it
//! are each refitted (Algorithm 1 from their own parameters) on one half and their
//! weighted cost taken on the other, then the halves swap; the step passes when the
//! summed held-out cost after it is below the one before it. An effect that the data
//! hold lowers the error on lines it was not fitted to; parameters that only follow the
//! noise or the nonlinear distortion of the fitted lines (both independent from line to
//! line) raise it. Every line is fitted and tested once, so the check needs no data
//! beyond the band, and the `--validate` data stay independent for the final
//! validation.

use additive_riv::riv::{iterate, RivConfig};
use additive_riv::{AdditiveModel, FitData};
use frf_data::structure::HeldOutCost;
use rayon::prelude::*;

/// The held-out costs of the step (summed over the two folds) from `before` to `after` on the band split into
/// `halves` ([`crate::pipeline::interleave::halves`], made once by
/// [`FitContext::held_out_halves`](crate::pipeline::FitContext::held_out_halves); see
/// the module documentation), the refits by `riv`. `None` when the band has too few
/// lines to split or a refit fails (the check is then not made).
pub fn held_out(
    halves: &[FitData; 2],
    riv: &RivConfig,
    before: &AdditiveModel,
    after: &AdditiveModel,
) -> Option<HeldOutCost> {
    if halves[0].n + halves[1].n < 8 {
        return None;
    }
    let jobs: Vec<(usize, bool)> = vec![(0, false), (0, true), (1, false), (1, true)];
    let costs: Vec<Option<(bool, f64)>> = jobs
        .into_par_iter()
        .map(|(fold, is_after)| {
            let model = if is_after { after } else { before };
            let (fit_on, test_on) = (&halves[fold], &halves[1 - fold]);
            let refit = iterate(model.clone(), fit_on, riv).ok()?;
            let c = additive_riv::residual_stats::cost_of(&refit.model, test_on);
            c.is_finite().then_some((is_after, c))
        })
        .collect();
    HeldOutCost::from_folds(costs)
}
