//! A local start for a mode added beside a fitted one.
//!
//! When the CMIF start gives a close pair one mode, the refined pole of that mode lands
//! between the two with a widened bandwidth, and the residual peak that calls for the
//! missed mode ([`crate::structure::adapt_modes`]) lies inside that bandwidth. Started at
//! the peak beside the merged pole, the pair takes Algorithm 1 (eq. 23 of the
//! wafer-stage paper) several halved steps to pull apart, each one an iteration over
//! every line and entry of the band (on the reference wafer stage: the 636 / 644 Hz pair,
//! 7 iterations with 3 halved steps from that start).
//!
//! The pair is a local question, so it is first answered locally: on the lines around
//! the merged mode, the data minus the response of every other submodel (`G - P_far`,
//! the residual plant (15) of the two) is fitted by the two modes alone, their poles
//! settled by Algorithm 1 on those lines (a few dozen lines instead of the band: a
//! fraction of one global iteration). The two settled modes (poles and numerators)
//! replace the naive start only when the weighted cost of the whole band is lower: the
//! global refinement then starts from the better of the two, and its fixed point is the
//! same optimum of (8). On the reference wafer stage the refinement after the added mode
//! takes 2 iterations instead of 7, to the same cost.

use crate::problem::FitData;
use crate::residual_stats::{
    cost_of, floor_t, line_spacing_near, lines_within, pole_of, typical_mean, ResidualStats,
};
use crate::riv::{iterate, RivConfig};
use crate::{fit_numerators, AdditiveModel, Submodel, SubmodelKind};
use frf_data::{Convergence, ModelStructure, ProgressSink};
use std::f64::consts::TAU;

/// A fitted mode is the merged partner of a residual peak when the peak lies within this
/// many of its half-power half-widths `zeta f`.
pub const PARTNER_HALF_WIDTHS: f64 = 3.0;

/// The local lines span this many half-power half-widths of the merged mode beyond the
/// pair on either side.
pub const WINDOW_HALF_WIDTHS: f64 = 4.0;

/// The local fit needs at least this many lines (more are taken symmetrically when the
/// window holds fewer).
pub const MIN_LINES: usize = 40;

/// The two settled modes must lie at least this many of the larger half-power
/// half-width `zeta f` apart.
pub const MIN_SEPARATION_HALF_WIDTHS: f64 = 0.5;

/// The local pair start is taken only when the weighted cost of the band falls below
/// this fraction of the naive start's, that is when the pair is most of what the start
/// misses (the merged 636 / 644 Hz pair of the wafer stage: 1/100). Otherwise the
/// naive start is refined as before: a pair that is a small part of the misfit, or a
/// local fit of a misfit that is no pair (a sensor resonance on one row 3 % above a
/// plate mode of the simulated stage, seed 3: 1/5, after which the first fit ended
/// worse than without it; an actuator lag on one column: 2 %), is left to the global
/// refinement.
pub const MAX_COST_RATIO: f64 = 0.1;

/// Natural frequency (Hz) and damping of submodel `i`, when it is a mode.
fn resonance(model: &AdditiveModel, i: usize) -> Option<(f64, f64)> {
    (model.submodels[i].kind == SubmodelKind::Mode)
        .then(|| pole_of(model, i))
        .flatten()
}

/// The mode among the first `n_old` submodels of `model` whose half-power bandwidth holds
/// a residual peak at `f_hz` ([`PARTNER_HALF_WIDTHS`]), the nearest in units of its
/// half-width; `None` when no fitted mode is that close.
pub fn merged_partner(model: &AdditiveModel, n_old: usize, f_hz: f64) -> Option<usize> {
    (0..n_old.min(model.submodels.len()))
        .filter_map(|i| {
            let (f, zeta) = resonance(model, i)?;
            let hw = zeta.abs() * f;
            let d = (f - f_hz).abs() / hw;
            (hw > 0.0 && d <= PARTNER_HALF_WIDTHS).then_some((i, d))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// The lines `a..b` of `data` around the pair: [`WINDOW_HALF_WIDTHS`] half-widths of the
/// merged mode beyond both, at least [`MIN_LINES`] lines.
fn window(data: &FitData, f_lo: f64, f_hi: f64, hw: f64) -> (usize, usize) {
    let lo = TAU * (f_lo - WINDOW_HALF_WIDTHS * hw);
    let hi = TAU * (f_hi + WINDOW_HALF_WIDTHS * hw);
    let mut a = data.omega.partition_point(|&w| w < lo);
    let mut b = data.omega.partition_point(|&w| w <= hi);
    while b - a < MIN_LINES && (a > 0 || b < data.n) {
        a = a.saturating_sub(1);
        b = (b + 1).min(data.n);
    }
    (a, b)
}

/// The submodels `old` and `new` of `model` settled on the lines around them (see the
/// module documentation), or `None` when the local problem cannot be posed (dynamics
/// factors, which the local fit would refit on a few lines; too few lines) or its fit
/// fails, ends unstable or with the two poles closer than
/// [`MIN_SEPARATION_HALF_WIDTHS`].
pub fn local_pair(
    model: &AdditiveModel,
    data: &FitData,
    old: usize,
    new: usize,
    riv: &RivConfig,
) -> Option<(Submodel, Submodel)> {
    if !model.dynamics.is_empty() || old == new {
        return None;
    }
    let (f_old, zeta_old) = resonance(model, old)?;
    let (f_new, _) = resonance(model, new)?;
    let hw = zeta_old.abs() * f_old;
    let (a, b) = window(data, f_old.min(f_new), f_old.max(f_new), hw);
    let m = data.m();
    let n_local = b - a;
    // two modes: their numerators per entry and four denominator parameters, with at
    // least four real observations per parameter
    let per_entry: usize = [old, new]
        .iter()
        .map(|&i| model.submodels[i].num.len())
        .sum();
    if 2 * n_local * m <= 4 * (per_entry * m + 4) {
        return None;
    }
    let omega = data.omega[a..b].to_vec();
    let mut far = model.clone();
    let mut local = model.clone();
    for i in (0..model.submodels.len()).rev() {
        if i == old || i == new {
            far.remove_submodel(i);
        } else {
            local.remove_submodel(i);
        }
    }
    local.factor.fit_delay = false;
    let p_far = far.response_at(&omega);
    let g: Vec<_> = data.g[a * m..b * m]
        .iter()
        .zip(&p_far.values)
        .map(|(g, p)| g - p)
        .collect();
    let w = data.w[a * m..b * m].to_vec();
    let local_data = FitData::from_parts(omega, data.ny, data.nu, g, w, data.band_hz);
    fit_numerators(&mut local, &local_data).ok()?;
    let cfg = RivConfig {
        max_iterations: riv.max_iterations.min(30),
        progress: ProgressSink::none(),
        ..riv.clone()
    };
    let fit = iterate(local, &local_data, &cfg).ok()?;
    if matches!(fit.convergence, Convergence::Failed { .. }) {
        return None;
    }
    let settled = fit.model;
    if !settled.unstable_submodels().is_empty() {
        return None;
    }
    // `local` kept the two in their order in `model`
    let (i_old, i_new) = if old < new { (0, 1) } else { (1, 0) };
    let (fa, za) = resonance(&settled, i_old)?;
    let (fb, zb) = resonance(&settled, i_new)?;
    // a pair closer than half a half-width is not resolved by its lines: two modes on
    // practically one pole share a misfit between them (a lag or a factor the model
    // lacks), they are not a pair the data show
    if (fa - fb).abs() < MIN_SEPARATION_HALF_WIDTHS * (za * fa).max(zb * fb) {
        return None;
    }
    Some((
        settled.submodels[i_old].clone(),
        settled.submodels[i_new].clone(),
    ))
}

/// A merged pair's partner must hold at least this factor more residual around it (the
/// mean per-line statistic of [`ResidualStats`]) than the typical fitted mode's
/// neighbourhood, as [`crate::split::SplitConfig::over_typical`]: a misfit that raises
/// every mode's neighbourhood alike (a lag or a delay the model lacks) is broadband, and
/// a mode added there is not half of a pair, whatever a local fit would make of it.
pub const OVER_TYPICAL: f64 = 4.0;

/// ... and at least this factor more than the band's quiet lines (the statistic's lower
/// quintile), as [`crate::split::SplitConfig::min_excess`].
pub const MIN_EXCESS: f64 = 4.0;

/// What [`with_local_pairs`] compares a partner's neighbourhood with, from the residual
/// statistic `stats` of the model before the modes were added: the mean per-line
/// statistic around each of the first `n_old` submodels that is a mode (its
/// neighbourhood: [`WINDOW_HALF_WIDTHS`] half-widths either side, at least 1 % of its
/// frequency and 3 lines, as the close-pair split's), the typical one among them and
/// the band's quiet level.
struct Neighbourhoods {
    means: Vec<Option<f64>>,
    typical: f64,
    quiet: f64,
}

impl Neighbourhoods {
    fn new(model: &AdditiveModel, data: &FitData, stats: &ResidualStats, n_old: usize) -> Self {
        let means: Vec<Option<f64>> = (0..n_old.min(model.submodels.len()))
            .map(|i| {
                let (f, zeta) = resonance(model, i)?;
                let half = (WINDOW_HALF_WIDTHS * zeta.abs() * f)
                    .max(0.01 * f)
                    .max(3.0 * line_spacing_near(data, f));
                let (a, b) = lines_within(data, f - half, f + half);
                (b > a).then(|| stats.t[a..b].iter().sum::<f64>() / (b - a) as f64)
            })
            .collect();
        let typical = typical_mean(means.iter().flatten().copied().collect());
        Self {
            means,
            typical,
            quiet: floor_t(stats),
        }
    }

    /// True when the residual around fitted mode `partner` stands out
    /// ([`OVER_TYPICAL`], [`MIN_EXCESS`]).
    fn stands_out(&self, partner: usize) -> bool {
        let Some(Some(mine)) = self.means.get(partner).copied() else {
            return false;
        };
        mine >= OVER_TYPICAL * self.typical && mine >= MIN_EXCESS * self.quiet
    }
}

/// `model` (numerators fitted) with each added mode (indices `added`, each started at
/// the residual peak that called for it) that lies within the bandwidth of a fitted mode
/// ([`merged_partner`]) settled with that mode on their lines ([`local_pair`]), the
/// other numerators as in `model`. Only partners whose neighbourhood stands out in
/// `before` (the residual statistic of the model without the added modes; see
/// [`OVER_TYPICAL`]) are settled so. `None` when no pair was settled or the result does
/// not lower the weighted cost of `model` below [`MAX_COST_RATIO`] of itself.
pub fn with_local_pairs(
    model: &AdditiveModel,
    data: &FitData,
    before: &ResidualStats,
    n_old: usize,
    added: &[usize],
    riv: &RivConfig,
) -> Option<AdditiveModel> {
    let mut trial = model.clone();
    let mut used = Vec::new();
    let hoods = Neighbourhoods::new(model, data, before, n_old);
    for &i in added {
        let Some((f, _)) = resonance(&trial, i) else {
            continue;
        };
        let Some(old) = merged_partner(&trial, n_old, f) else {
            continue;
        };
        if used.contains(&old) || !hoods.stands_out(old) {
            continue;
        }
        if let Some((s_old, s_new)) = local_pair(&trial, data, old, i, riv) {
            trial.submodels[old] = s_old;
            trial.submodels[i] = s_new;
            used.push(old);
        }
    }
    if used.is_empty() {
        return None;
    }
    // the other numerators stay as the naive start fitted them: the refinement that
    // follows solves for all of them, so a refit here (one more numerator problem of the
    // band) would only sharpen the comparison
    let (c_trial, c_model) = (cost_of(&trial, data), cost_of(model, data));
    (c_trial.is_finite() && c_trial < MAX_COST_RATIO * c_model).then_some(trial)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Domain;
    use faer::Mat;

    /// A 2 x 3 continuous plant with the given modes (f Hz, zeta, output shape, input
    /// shape), noise-free on 0.25 Hz lines over `lo..hi` Hz, unit weights.
    fn plant(modes: &[(f64, f64, [f64; 2], [f64; 3])], lo: f64, hi: f64) -> FitData {
        let (ny, nu) = (2, 3);
        let mut m = AdditiveModel::new(ny, nu, Domain::Continuous).unwrap();
        for &(f, z, c, b) in modes {
            let i = m.push_mode(f, z, false).unwrap();
            m.submodels[i].num[0] = Mat::from_fn(ny, nu, |r, k| c[r] * b[k]);
        }
        let n = ((hi - lo) / 0.25) as usize + 1;
        let omega: Vec<f64> = (0..n).map(|k| TAU * (lo + 0.25 * k as f64)).collect();
        let g = m.response_at(&omega).values;
        let w = vec![1.0; g.len()];
        FitData::from_parts(omega, ny, nu, g, w, (lo, hi))
    }

    const A: ([f64; 2], [f64; 3]) = ([1.0, 0.4], [1.0, -0.5, 0.3]);
    const B: ([f64; 2], [f64; 3]) = ([0.3, -1.0], [0.2, 1.0, 0.8]);
    const C: ([f64; 2], [f64; 3]) = ([1.0, 1.0], [-0.7, 0.4, 1.0]);

    /// The modes (Hz, damping) of `m`, by frequency.
    fn poles(m: &AdditiveModel) -> Vec<(f64, f64)> {
        let mut p: Vec<(f64, f64)> = m.modes().iter().map(|x| (x.f_hz, x.zeta)).collect();
        p.sort_by(|a, b| a.0.total_cmp(&b.0));
        p
    }

    /// A start that merged the pair (one mode between them, widened) plus the mode the
    /// residual peak calls for, numerators fitted; the far mode at 150 Hz then set to
    /// its truth (so that the local data `G - P_far` are exact).
    fn merged_start(data: &FitData, merged: (f64, f64), peak_hz: f64) -> AdditiveModel {
        let mut m = AdditiveModel::new(2, 3, Domain::Continuous).unwrap();
        m.push_mode(150.0, 0.01, false).unwrap();
        m.push_mode(merged.0, merged.1, false).unwrap();
        m.push_mode(peak_hz, 0.01, false).unwrap();
        fit_numerators(&mut m, data).unwrap();
        m.submodels[0].num[0] = Mat::from_fn(2, 3, |r, k| A.0[r] * A.1[k]);
        m
    }

    /// Noise-free data of a pair 1.3 % apart with a far mode exactly in place: the local
    /// fit of the two on their lines recovers both poles to the solver's precision (with
    /// the far mode's numerators as a fit left them, to their error instead).
    #[test]
    fn the_local_fit_recovers_a_merged_pair_exactly() {
        let data = plant(
            &[
                (150.0, 0.01, A.0, A.1),
                (636.0, 0.008, B.0, B.1),
                (644.5, 0.009, C.0, C.1),
            ],
            100.0,
            800.0,
        );
        let start = merged_start(&data, (639.3, 0.0144), 642.75);
        assert_eq!(merged_partner(&start, 2, 642.75), Some(1));
        let (a, b) =
            local_pair(&start, &data, 1, 2, &RivConfig::default()).expect("the pair settles");
        let mut settled = start.clone();
        settled.submodels[1] = a;
        settled.submodels[2] = b;
        let p = poles(&settled);
        for (got, want) in p[1..].iter().zip([(636.0, 0.008), (644.5, 0.009)]) {
            assert!(
                (got.0 / want.0 - 1.0).abs() < 1e-9 && (got.1 / want.1 - 1.0).abs() < 1e-6,
                "{got:?} against {want:?} (all: {p:?})"
            );
        }
        // and the whole model starts from there, far below the naive start
        let before = {
            let mut m = start.clone();
            m.remove_submodel(2);
            fit_numerators(&mut m, &data).unwrap();
            ResidualStats::new(&m, &data)
        };
        let better = with_local_pairs(&start, &data, &before, 2, &[2], &RivConfig::default())
            .expect("the local pair lowers the cost");
        assert!(cost_of(&better, &data) < 1e-6 * cost_of(&start, &data));
    }

    /// A mode added far from every fitted one (a missed mode, not half of a merged pair)
    /// has no partner, and the start is left as it is.
    #[test]
    fn a_mode_far_from_the_others_has_no_partner() {
        let data = plant(
            &[(150.0, 0.01, A.0, A.1), (400.0, 0.01, B.0, B.1)],
            100.0,
            600.0,
        );
        let mut m = AdditiveModel::new(2, 3, Domain::Continuous).unwrap();
        m.push_mode(150.0, 0.01, false).unwrap();
        m.push_mode(400.0, 0.01, false).unwrap();
        let n_old = m.submodels.len();
        m.push_mode(300.0, 0.01, false).unwrap();
        fit_numerators(&mut m, &data).unwrap();
        assert_eq!(merged_partner(&m, n_old, 300.0), None);
        let before = ResidualStats::new(&m, &data);
        assert!(with_local_pairs(&m, &data, &before, n_old, &[2], &RivConfig::default()).is_none());
    }

    /// Only fitted modes are partners (not the added ones, not a rigid body), and the
    /// nearest in half-widths wins.
    #[test]
    fn the_partner_is_the_nearest_fitted_mode_in_half_widths() {
        let mut m = AdditiveModel::new(2, 3, Domain::Continuous).unwrap();
        m.push_rigid_body(2, AdditiveModel::rigid_scale(10.0, 1000.0))
            .unwrap();
        m.push_mode(500.0, 0.02, false).unwrap(); // half-width 10 Hz
        m.push_mode(520.0, 0.002, false).unwrap(); // half-width 1.04 Hz
        m.push_mode(505.0, 0.01, false).unwrap(); // added
                                                  // 505 Hz: 0.5 half-widths from 500 Hz, 14 from 520 Hz
        assert_eq!(merged_partner(&m, 3, 505.0), Some(1));
        // 519 Hz: 1.0 from 520 Hz, 1.9 from 500 Hz
        assert_eq!(merged_partner(&m, 3, 519.0), Some(2));
        // beyond 3 half-widths of both
        assert_eq!(merged_partner(&m, 3, 460.0), None);
        // the added mode itself is not a partner
        assert_eq!(merged_partner(&m, 3, 505.5).map(|i| i < 3), Some(true));
    }
}
