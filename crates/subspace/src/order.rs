//! The model order: from the singular values of the projected data, or by an F test on
//! the refitted `B`, `D` (eq. (17)) around the singular-value proposal.
//!
//! Singular values: among the orders `n = 1 ..= n_max`, `n_max = min((r - 1) p,
//! numerical rank, max_order)` (the shift equations (12) need `(r - 1) p >= n`), take the
//! one with the largest gap `ln s_n - ln s_(n+1)` between consecutive singular values.
//! With the data's own variance as the weighting the noise level of the singular values
//! is known (about 1), and the estimator counts the singular values above a multiple of
//! it instead (`SubspaceConfig::noise_threshold`). The numerical rank counts the singular
//! values above [`RANK_TOL`] times the largest: a given order above it is an error (the
//! data do not support that many states).
//!
//! F test ([`f_sweep`]): a singular value aggregates a direction's energy over all
//! lines, so a state whose response is large on a few lines only (a weak rigid body seen
//! at the lowest lines, the weak direction of a rank-2 residue near its resonance) can
//! sit at the noise level of the singular values while it lowers the residual by many
//! standard deviations. The sweep realises every candidate order (A, C by (12), B, D by
//! (17)), refines its poles for the cost of the refit of the residues (the currency's
//! `B`, `D`: with the poles fixed, the residues and feedthrough are linear;
//! [`crate::pole_refine`]) and keeps an order when the F
//! statistic of its cost decrease against the order kept so far exceeds the critical
//! value. The cost of (17) itself is not used: with `C` fixed from the noisy
//! singular vectors its misfit at the true order is well above the noise (3 to 30
//! times on the random systems of the tests), and further states absorb that misfit
//! significantly (on the reference wafer stage the sweep on it kept order 41 where the
//! singular values show 40 with a gap of 67). The test is that of the diagnosis: the nested-model test of the diagnosis
//! (`additive_riv::significance::{f_statistic, f_critical}` and the order sweep of
//! `sk_fit`), restated here in a few lines so that this crate does not depend on them.

use serde::{Deserialize, Serialize};

/// The workspace's one normal quantile and the approximate chi-square and F critical
/// values of the structure tests ([`frf_data::stats`]).
pub use frf_data::stats::{
    chi2_upper_approx as chi2_upper, f_critical_many_dof as f_critical, normal_quantile,
};

/// Relative tolerance of the numerical rank of the projected data.
pub const RANK_TOL: f64 = 1e-12;

/// How the order is chosen when it is not given, and whether the significance tests
/// run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum OrderRule {
    /// The default. The order from the singular values (the count above
    /// `noise_threshold` with the data's variance, the largest gap otherwise), and the
    /// rigid-body integrators the singular values missed added by an F test on the
    /// residue refit (a rigid body weak at the lowest lines sits at the noise level of
    /// the singular values: the random systems of the tests, and a second subspace pass
    /// on the flexible part then). Without the data's variance the F statistic's noise
    /// model is not known to hold, and an integrator must also lower the cost twice
    /// over, at once or after passes on the flexible part with its rigid body
    /// subtracted (a missed rigid body dominates the residual: noise-free 7-8 mode
    /// systems whose largest singular-value gap lies above the rigid body's states);
    /// added integrators replace the states of a split double integrator
    /// (`PoleSet::with_integrators`). The order sweep is not the default: with
    /// rank-2 residues it may keep a mode's noise-split eigenvalues as two modes (see
    /// [`OrderRule::FTest`]), and it refits the residues at every candidate order
    /// (on the reference wafer stage: 20 s against 2.2 s, and order 41 with a real
    /// pole where the singular values show 40 with a gap of 67: the misfit of the
    /// subspace poles there is F = 591 significant, so the median error rises from
    /// 3.6e-5 to 4.4e-5).
    #[default]
    Auto,
    /// The singular values only, no significance test.
    SingularValues,
    /// The F-test sweep ([`f_sweep`]) from `sweep_below` orders under the
    /// singular-value proposal, and the integrator test. Each candidate's poles are
    /// refined by Gauss-Newton on the residue refit's cost first
    /// ([`crate::pole_refine`]): the subspace poles are not least-squares estimates, and
    /// an added state absorbed their misfit with F of 10 to 50. It finds the true order
    /// of random systems with rank-1 residues, noise-free and at 1e-4 relative noise
    /// (300 random cases each). With rank-2 residues a mode whose two eigenvalues are
    /// split beyond the merge tolerance counts as two modes, and the sweep may keep
    /// such an order.
    FTest,
}

/// One order of the F-test sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OrderScore {
    /// Number of states.
    pub order: usize,
    /// Weighted cost `sum w |h - model|^2` of the state space of (17) at this order
    /// (`None` when the order could not be realised, e.g. a rank-deficient shift
    /// equation).
    pub cost: Option<f64>,
    /// F statistic against the order kept before it (`None` for the first).
    pub f: Option<f64>,
    /// Its critical value.
    pub f_critical: Option<f64>,
    /// Whether this order was kept (replaced the one before).
    pub kept: bool,
}

/// Settings of the F-test sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSettings {
    /// First and last candidate order.
    pub range: (usize, usize),
    /// Complex residuals with a positive weight.
    pub observations: usize,
    /// Significance level.
    pub alpha: f64,
    /// Practical-significance floor of the F statistic (the diagnosis's `min_f`).
    pub min_f: f64,
    /// Consecutive orders that are not kept before the sweep stops.
    pub patience: usize,
    /// A cost at or below this is an exact fit: the sweep stops there.
    pub exact_cost: f64,
}

/// Number of free real parameters of a state space of order `n` with `p` outputs and
/// `m` inputs (observability canonical form: `n p` in `A`, `n m` in `B`, `p m` in `D`).
pub fn n_params(n: usize, p: usize, m: usize) -> usize {
    n * (p + m) + p * m
}

/// The F statistic of `dp` added real parameters that lower the cost `sum w |E|^2` by
/// `dv`, with the noise scale `s2 = V / (N - P/2)` of the larger model (`N` complex
/// residuals, `P` real parameters; each complex residual contributes 1 on average, each
/// fitted real parameter removes 1/2): `(dv / (dp/2)) / s2`. The statistic of
/// `additive_riv::significance::f_statistic` with its noise scale.
pub fn f_statistic(dv: f64, dp: usize, v: f64, observations: usize, params: usize) -> f64 {
    let dof = (observations as f64 - params as f64 / 2.0).max(1.0);
    let s2 = (v / dof).max(f64::MIN_POSITIVE);
    (dv / (dp.max(1) as f64 / 2.0)) / s2
}

/// Numerical rank of `sv` (descending).
pub fn numerical_rank(sv: &[f64]) -> usize {
    let s1 = sv.first().copied().unwrap_or(0.0);
    if s1 <= 0.0 {
        return 0;
    }
    sv.iter().filter(|&&s| s > RANK_TOL * s1).count()
}

/// The order with the largest log gap among `1 ..= n_max` (requires `n_max < sv.len()`
/// and `n_max >= 1`); returns the order and the gap (natural log).
pub fn largest_gap(sv: &[f64], n_max: usize) -> (usize, f64) {
    let s1 = sv.first().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
    let floor = s1 * 1e-300;
    let mut best = (1, f64::NEG_INFINITY);
    for n in 1..=n_max.min(sv.len().saturating_sub(1)) {
        let g = sv[n - 1].max(floor).ln() - sv[n].max(floor).ln();
        if g > best.1 {
            best = (n, g);
        }
    }
    best
}

/// The F-test sweep: orders `range.0 ..= range.1` upwards; the first order that can be
/// realised is kept, and a later order replaces the kept one when the F statistic of
/// its cost decrease against it exceeds the critical value and the floor `min_f` (as in
/// the diagnosis, `additive_riv::structure::AdaptConfig::min_f`: states that absorb
/// misfit rather than noise reach F of a few, real states far more). The sweep stops after
/// `patience` consecutive orders that are not kept, at an exact fit, or at the first
/// order that cannot be realised after one was kept. `cost_at(n)` is the weighted cost
/// of the order-`n` model and its number of free real parameters (`None`: not
/// realisable); an order with no more parameters than the kept one (its poles merge)
/// is kept when its cost is lower.
/// Returns the kept order (or `None` when no order could be realised) and the scores.
pub fn f_sweep(
    s: &SweepSettings,
    mut cost_at: impl FnMut(usize) -> Option<(f64, usize)>,
) -> (Option<usize>, Vec<OrderScore>) {
    let mut scores = Vec::new();
    let mut best: Option<(usize, f64, usize)> = None;
    let mut misses = 0;
    for n in s.range.0..=s.range.1 {
        let Some((v, pn)) = cost_at(n) else {
            scores.push(OrderScore {
                order: n,
                cost: None,
                f: None,
                f_critical: None,
                kept: false,
            });
            if best.is_some() {
                break;
            }
            continue;
        };
        let (f, fc, keep) = match best {
            None => (None, None, true),
            Some((_, vb, pb)) => {
                if pn <= pb {
                    // no more parameters: kept when it fits better (it dominates)
                    (None, None, v < vb)
                } else {
                    let dp = pn - pb;
                    let f = f_statistic(vb - v, dp, v, s.observations, pn);
                    let fc = f_critical(dp, s.alpha).max(s.min_f);
                    (Some(f), Some(fc), f > fc)
                }
            }
        };
        scores.push(OrderScore {
            order: n,
            cost: Some(v),
            f,
            f_critical: fc,
            kept: keep,
        });
        if keep {
            best = Some((n, v, pn));
            misses = 0;
            if v <= s.exact_cost {
                break;
            }
        } else {
            misses += 1;
            if misses >= s.patience {
                break;
            }
        }
    }
    (best.map(|b| b.0), scores)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_and_rank() {
        let sv = [10.0, 9.0, 5.0, 1e-3, 9e-4, 1e-14];
        assert_eq!(numerical_rank(&sv), 5);
        assert_eq!(largest_gap(&sv, 4).0, 3);
        // restricted range: the gap at 5 is not a candidate for n_max = 4
        assert_eq!(largest_gap(&sv, 5).0, 5);
    }

    #[test]
    fn quantiles() {
        assert!((normal_quantile(0.975) - 1.959964).abs() < 1e-5);
        assert!((normal_quantile(0.001) + 3.090232).abs() < 5e-5);
        // chi2_10 upper 5 %: 18.307; chi2_100 upper 0.1 %: 149.449
        assert!((chi2_upper(10.0, 0.05) - 18.307).abs() < 0.1);
        assert!((chi2_upper(100.0, 0.001) - 149.449).abs() < 0.5);
    }

    /// Costs of a model whose true order is 4 with 1000 unit-variance residuals: the
    /// sweep keeps 4 and stops after `patience` orders that only fit noise.
    #[test]
    fn sweep_keeps_the_significant_orders() {
        let s = SweepSettings {
            range: (1, 12),
            observations: 1000,
            alpha: 1e-3,
            min_f: 1.0,
            patience: 3,
            exact_cost: 0.0,
        };
        // each state beyond 4 removes its expected share (one real parameter per
        // state and input/output: 1/2 each) plus a little
        let cost = |n: usize| -> f64 {
            if n < 4 {
                1000.0 + 5000.0 * (4 - n) as f64
            } else {
                1000.0 - 1.2 * (n - 4) as f64
            }
        };
        let (n, scores) = f_sweep(&s, |n| Some((cost(n), n_params(n, 1, 1))));
        assert_eq!(n, Some(4), "{scores:?}");
        assert_eq!(scores.len(), 7);
        assert!(scores[3].kept && !scores[4].kept);
        // an unrealisable order after a kept one ends the sweep
        let (n, scores) = f_sweep(&s, |n| {
            if n <= 2 {
                Some((cost(n), n_params(n, 1, 1)))
            } else {
                None
            }
        });
        assert_eq!(n, Some(2));
        assert_eq!(scores.len(), 3);
        // an exact fit ends it
        let (n, _) = f_sweep(
            &SweepSettings {
                exact_cost: 1e-20,
                ..s
            },
            |n| Some((if n >= 3 { 0.0 } else { 1.0 }, n_params(n, 1, 1))),
        );
        assert_eq!(n, Some(3));
    }
}
