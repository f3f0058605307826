//! What the trials, the acceptance and the restarts of the diagnosis share: a
//! candidate's refit ([`refit`]: numerators, then Algorithm 1, with the decrease still to
//! come when it stopped at its cap), the weighted cost of a model ([`model_cost`]) and
//! the F test of a refit against another model ([`f_test`]), and the comparisons of two
//! models they read: the modes one holds that the other lacks ([`new_modes`],
//! [`lacked_light_modes`]) and the parts in the right half-plane ([`unstable_parts`]).
//! It imports nothing else of the diagnosis.

use crate::pipeline::{err, PipelineConfig};
use crate::FrfitError;
use additive_riv::residual_stats::ResidualStats;
use additive_riv::riv::{iterate, RivConfig};
use additive_riv::significance::{f_statistic, noise_scale};
use additive_riv::{fit_numerators, AdditiveModel, FitData};
use frf_data::stats::f_critical_effective;
use frf_data::ModelStructure;

/// The weighted cost `sum w |E|^2` of `model` on `fd`.
pub fn model_cost(model: &AdditiveModel, fd: &FitData) -> f64 {
    additive_riv::residual_stats::cost_of(model, fd)
}

/// The modes of `after` that are not in `before`: each mode of `before` takes the
/// nearest unclaimed mode of `after` within 3 %, the rest are new.
pub fn new_modes(before: &AdditiveModel, after: &AdditiveModel) -> Vec<(f64, f64)> {
    unmatched_modes(&mode_list(after), &mode_list(before))
}

/// (frequency in Hz, damping) of every mode of `model`.
pub fn mode_list(model: &AdditiveModel) -> Vec<(f64, f64)> {
    model.modes().iter().map(|m| (m.f_hz, m.zeta)).collect()
}

/// The modes of `of` that `against` does not hold: each mode of `against` claims the
/// nearest unclaimed mode of `of` within 3 % in frequency; the unclaimed are returned.
pub fn unmatched_modes(of: &[(f64, f64)], against: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut left = of.to_vec();
    for &(f_old, _) in against {
        let nearest = left
            .iter()
            .enumerate()
            .filter(|(_, (f, _))| (f / f_old - 1.0).abs() < 0.03)
            .min_by(|a, b| (a.1 .0 - f_old).abs().total_cmp(&(b.1 .0 - f_old).abs()))
            .map(|(i, _)| i);
        if let Some(i) = nearest {
            left.remove(i);
        }
    }
    left
}

/// The F test of a refit `model` that adds `added` real parameters and lowers the
/// weighted cost from `before` to `after`: the cost explained per added parameter over
/// the noise scale of the larger model, and its critical value at `cfg.alpha` with the
/// effective number of parameters (correlated residuals), floored at `cfg.min_f`.
/// Returns the residual statistics of `model` as well (the local tests use them).
pub fn f_test(
    model: &AdditiveModel,
    fd: &FitData,
    before: f64,
    after: f64,
    added: usize,
    cfg: &PipelineConfig,
) -> (ResidualStats, f64, f64) {
    let stats = ResidualStats::new(model, fd);
    let s2 = noise_scale(after, fd, model.n_params());
    let f = f_statistic(before - after, added, s2);
    let p_eff = stats.effective_params(added, fd.m());
    let f_crit = f_critical_effective(p_eff, cfg.alpha).max(cfg.min_f);
    (stats, f, f_crit)
}

/// Refits a candidate: numerators (eq. 24), then Algorithm 1 to a coarse tolerance.
/// Returns the model, its cost, the iterations run and whether they converged (not
/// stopped by the iteration cap).
pub(super) fn refit(
    model: AdditiveModel,
    fd: &FitData,
    riv: &RivConfig,
) -> Result<Refitted, FrfitError> {
    let mut m = model;
    fit_numerators(&mut m, fd).map_err(err("refit"))?;
    let f = iterate(m, fd, riv).map_err(err("refit"))?;
    // a refit whose iterations failed (singular, no descent) before any step was taken
    // did not fit the effect: its model is the start, not an estimate
    if let (frf_data::Convergence::Failed { reason }, true) =
        (&f.convergence, f.cost_history.len() <= 1)
    {
        return Err(FrfitError::Fit {
            what: "refit".into(),
            why: reason.clone(),
        });
    }
    let capped = matches!(f.convergence, frf_data::Convergence::MaxIterations { .. });
    let c = model_cost(&f.model, fd);
    // the history's costs are the iterations' own scale: the extrapolated decrease is
    // carried over as a fraction of the last one
    let last = f.cost_history.last().copied().unwrap_or(f64::NAN);
    let remaining = remaining_decrease(&f.cost_history).map(|r| r / last * c);
    Ok(Refitted {
        model: f.model,
        cost: c,
        iterations: f.iterations,
        capped,
        remaining,
    })
}

/// A refit's result.
pub(super) struct Refitted {
    pub(super) model: AdditiveModel,
    /// Its weighted cost.
    pub(super) cost: f64,
    pub(super) iterations: usize,
    /// Whether it stopped at its iteration cap before converging.
    pub(super) capped: bool,
    /// The decrease still to come ([`remaining_decrease`]), in units of `cost`.
    pub(super) remaining: Option<f64>,
}

/// The largest ratio of successive cost decreases [`remaining_decrease`] extrapolates
/// with: decreases that shrink more slowly than this are not settling.
const MAX_DECREASE_RATIO: f64 = 0.9;

/// The cost decrease still to come of iterations stopped before convergence, from their
/// cost `history`: the per-iteration decreases extrapolated as a geometric series with
/// the ratio `r` of the last two, `d r / (1 - r)` for the last decrease `d`. `None` with
/// fewer than three costs, a non-finite cost, or decreases that do not shrink (`r` above
/// [`MAX_DECREASE_RATIO`], or a cost that rose): then nothing bounds what is left.
pub fn remaining_decrease(history: &[f64]) -> Option<f64> {
    let [.., a, b, c] = history else {
        return None;
    };
    let (d1, d2) = (a - b, b - c);
    if !(d1.is_finite() && d2.is_finite()) || d1 <= 0.0 || d2 < 0.0 {
        return None;
    }
    let r = d2 / d1;
    (r <= MAX_DECREASE_RATIO).then(|| d2 * r / (1.0 - r))
}

/// Submodels and dynamics factors of `model` with a pole in the closed right half-plane.
pub fn unstable_parts(model: &AdditiveModel) -> usize {
    model.unstable_submodels().len()
        + model
            .dynamics
            .iter()
            .filter(|d| d.poles().iter().any(|p| p.re >= 0.0))
            .count()
}

/// Damping below which a mode of the common-denominator start counts as a structural
/// mode the model may lack ([`super::trial::common_denominator_modes`] and the restart of
/// a first fit that lost modes, [`super::restart`]): the poles a common denominator
/// spends on an undeclared lag, feedthrough or delay are far more damped or lie beyond
/// the band.
pub(super) const LIGHT_DAMPING: f64 = 0.1;

/// Whether a mode at `f_hz` with damping `zeta` is stable, lightly damped (below
/// [`LIGHT_DAMPING`]) and inside `band_hz`.
pub(super) fn light_in_band(f_hz: f64, zeta: f64, band_hz: (f64, f64)) -> bool {
    zeta > 0.0 && zeta < LIGHT_DAMPING && f_hz >= band_hz.0 && f_hz <= band_hz.1
}

/// The lightly damped in-band modes ([`light_in_band`]) of `after` that `before` lacks
/// ([`new_modes`]: none of its modes within 3 %), as `(f_hz, zeta)`.
pub(super) fn lacked_light_modes(
    before: &AdditiveModel,
    after: &AdditiveModel,
    band_hz: (f64, f64),
) -> Vec<(f64, f64)> {
    new_modes(before, after)
        .into_iter()
        .filter(|&(f, z)| light_in_band(f, z, band_hz))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::remaining_decrease;

    #[test]
    fn a_geometric_cost_history_extrapolates_to_its_limit() {
        // costs 1 + 8 (1/2)^k: decreases 4, 2, 1, ... sum to 8 from the start
        let history: Vec<f64> = (0..4).map(|k| 1.0 + 8.0 * 0.5_f64.powi(k)).collect();
        let left = remaining_decrease(&history).unwrap();
        let limit = history[3] - 1.0;
        assert!((left - limit).abs() < 1e-12, "{left} vs {limit}");
    }

    #[test]
    fn decreases_that_do_not_shrink_bound_nothing() {
        assert_eq!(remaining_decrease(&[10.0, 9.0, 8.0]), None);
        assert_eq!(remaining_decrease(&[10.0, 9.0, 9.5]), None);
        assert_eq!(remaining_decrease(&[10.0, 9.0]), None);
        assert_eq!(remaining_decrease(&[10.0, f64::NAN, 8.0]), None);
        // converged: nothing left
        assert_eq!(remaining_decrease(&[10.0, 9.0, 9.0]), Some(0.0));
    }
}
