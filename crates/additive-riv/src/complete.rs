//! Completion of the CMIF start (the "robust first fit"): the initialisation of section
//! 3.3 and 4.4 of the wafer-stage paper puts one mode at every CMIF peak with damping
//! 0.01 and fits the numerators by the convex problem (24). On well separated but
//! heavily overlapping modes (damping of a few percent, a frequency ratio below 2) the
//! peak picker misses modes whose resonance hides in the flank of a neighbour, a mode
//! with a residue of rank above one shows a peak on two singular values, and the
//! rigid-body choice is made against a residual dominated by the wrong start poles. This
//! module repairs the start before any refiner sees it:
//!
//! 1. **Coincident peaks are one mode** ([`merge_coincident_peaks`]): the numerator of
//!    a mode (eq. 26) is a full `ny x nu` matrix, so peaks of different singular values
//!    within a fraction of the half-power bandwidth (repeated roots, a residue of rank
//!    two) are one submodel; two submodels on practically one pole are not identifiable.
//! 2. **Settled poles** ([`complete_start`]): a few iterations of Algorithm 1 (eq. 23) at
//!    a coarse tolerance put the start poles within a fraction of a bandwidth, so that
//!    the residual shows what is missing rather than what is misplaced.
//! 3. **The rigid body again**: the number of integrators (0, 1 or 2) is chosen anew
//!    with the settled poles, by the F test of the numerator fits (24).
//! 4. **Residual-driven completion**: the residual `G - P` is a frequency response of its
//!    own; its CMIF ([`frf_data::cmif`]) peaks where modes are missing. Candidates come
//!    from two views of it, the weighted residual `sqrt(w) (G - P)` (whose energy is the
//!    cost) and the plain one (where a weighting that follows the data's magnitude,
//!    eq. (27), does not flatten a missing mode's resonance); see
//!    `residual_candidates`. Each candidate becomes a trial mode (a second mode near
//!    an existing one when it lies inside that mode's bandwidth), the poles are settled
//!    again, and the mode is kept only when the cost falls significantly: an F test at
//!    [`CompleteConfig::alpha`] with the noise scale estimated from the trial's residual
//!    (at least [`CompleteConfig::min_f`], and a drop of at least
//!    [`CompleteConfig::min_cost_drop`]); a mode narrower than the line spacing must
//!    pass the same test on the lines off its own resonance (one outlying line is fitted
//!    by such a mode as well as by any). When no residual peak gives a mode that
//!    passes, the trial poles of a matched single-mode scan of the weighted residual
//!    ([`crate::mode_scan`]) are tried under the same tests: a mode between two fitted
//!    ones that their settled poles widened to cover leaves no peak of its own. This
//!    repeats a bounded number of times; the rigid body is chosen again after every
//!    kept mode.

use crate::mode_scan::{scan_residual, ScanConfig};
use crate::problem::FitData;
use crate::residual_stats::{
    has_duplicate, line_spacing_near, model_cost, significant_off_peak, EXACT_FIT_REL,
};
use crate::riv::{iterate, RivConfig};
use crate::significance::{f_critical, f_statistic, noise_scale, submodel_cost_increase};
use crate::{fit_numerators, AdditiveModel, Domain, RivError, SubmodelKind};
use frf_data::cmif::{cmif, pick_peaks, CmifPeak, PeakConfig};
use frf_data::{Convergence, Frf, ModelStructure, ProgressSink, C64};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Settings of [`complete_start`], with documented defaults.
#[derive(Debug, Clone)]
pub struct CompleteConfig {
    /// Rounds of the residual-driven completion. Default: 6 (the harness's systems hold
    /// up to 6 modes, of which a poor start may miss half).
    pub max_rounds: usize,
    /// At most this many candidates tried per round, one at a time, the strongest
    /// residual peak first; the first that passes is kept. Default: 2.
    pub max_trials_per_round: usize,
    /// Relative parameter tolerance of the pole settling. Default: 1e-4 (a fraction of a
    /// bandwidth is what the residual diagnosis needs).
    pub coarse_tol: f64,
    /// Iteration limit of the pole settling. Default: 15.
    pub coarse_max_iterations: usize,
    /// A residual CMIF peak is a candidate only when its `sigma_1^2` is at least this
    /// factor above the median of the residual's `sigma_1^2` over the band. Default: 10
    /// (as [`crate::structure::PEAK_OVER_LOCAL`]: noise peaks stay below).
    pub peak_over_median: f64,
    /// Residual peaks closer than this relative distance to a stronger one are one
    /// candidate. Default: 0.025 (as [`crate::structure::AdaptConfig::min_separation`]).
    pub min_separation: f64,
    /// Added modes are kept only when the cost falls by at least this fraction. Default:
    /// 0.1: the start is completed with what the data plainly show; weak modes are left
    /// to the refiner's own adaptation.
    pub min_cost_drop: f64,
    /// Practical-significance floor of the F statistics of added modes and of a richer
    /// rigid body, on top of the F test at `alpha` (see
    /// [`crate::structure::AdaptConfig::min_f`]). Default: 25.
    pub min_f: f64,
    /// Significance level of the F tests. Default: 1e-3.
    pub alpha: f64,
    /// A residual peak below this fraction (in amplitude) of the data at its line is
    /// rounding, not a mode: noise-free data fitted exactly leave a residual of the order
    /// of the conditioning of the numerator problem times the machine precision, whose
    /// peaks no statistical test can judge. Default: 1e-10.
    pub rounding_floor: f64,
    /// Peaks of different singular values closer than this fraction of the half-power
    /// half-width `zeta f` are one start mode ([`merge_coincident_peaks`]). Default: 0.25.
    pub merge_fraction: f64,
    /// Damping of an added mode when the residual peak gives no half-power estimate.
    /// Default: 0.01.
    pub zeta0: f64,
    /// The picker on the residual's CMIF. Default: [`PeakConfig::default`] with a
    /// minimum prominence of 1 dB and no noise estimate from the second differences:
    /// the residual of a start that misses overlapping modes is a smooth, broad misfit
    /// whose peaks rise little above their flanks, and the weighting's sharp features
    /// (at the data's resonances) would be taken for noise. The picker only places the
    /// candidates; the cost test of each trial decides. With inverse-variance weights
    /// the residual's unit variance still corrects the prominences.
    pub peaks: PeakConfig,
    /// Trials from the matched single-mode scan of the residual ([`crate::mode_scan`])
    /// per round, tried when none of the residual's peaks gives a mode that passes.
    /// Default: 3. 0 turns the scan off.
    pub scan_trials: usize,
    /// The scan's grid. Default: [`ScanConfig::default`].
    pub scan: ScanConfig,
    /// When no single candidate (residual peak or scan trial) passes, the pairs of the
    /// first three are tried, two modes at once. Default: true.
    pub pair_trials: bool,
    /// When no addition passes, at most this many modes whose damping is at least
    /// [`CompleteConfig::split_zeta`] are each replaced by two modes at their half-power
    /// points `f (1 -+ zeta)` or twice as far apart (the broadest first; see
    /// `split_candidates`). Default: 3.
    /// 0 turns the splits off.
    pub split_trials: usize,
    /// Damping from which a settled mode is a candidate for a split (the F test of the
    /// trial decides). Default: 0.045 (the broadest lightly damped modes of the
    /// harness have 0.04; two modes 1.6x apart that one mode covers settle at 0.1 to
    /// 0.3, and a missed neighbour widens a mode to about 0.05).
    pub split_zeta: f64,
}

impl Default for CompleteConfig {
    fn default() -> Self {
        Self {
            max_rounds: 6,
            max_trials_per_round: 2,
            coarse_tol: 1e-4,
            coarse_max_iterations: 15,
            peak_over_median: 10.0,
            min_cost_drop: 0.1,
            min_separation: 0.025,
            min_f: 25.0,
            alpha: 1e-3,
            merge_fraction: 0.25,
            rounding_floor: 1e-10,
            zeta0: 0.01,
            peaks: PeakConfig {
                min_prominence_db: 1.0,
                estimate_noise: false,
                ..PeakConfig::default()
            },
            scan_trials: 3,
            scan: ScanConfig::default(),
            pair_trials: true,
            split_trials: 3,
            split_zeta: 0.045,
        }
    }
}

/// What [`complete_start`] changed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompleteReport {
    /// Modes added at residual peaks (frequency in Hz after settling).
    pub added: Vec<f64>,
    /// Residual peaks tried and not kept (frequency in Hz, why).
    pub rejected: Vec<(f64, String)>,
    /// Integrators of the rigid body before and after the re-choice.
    pub integrators: (usize, usize),
    /// Rounds of the completion run.
    pub rounds: usize,
    /// Iterations of Algorithm 1 spent settling poles.
    pub iterations: usize,
}

/// The start mode frequencies of `peaks` with coincident peaks merged: two peaks closer
/// than `fraction` times the half-power half-width `zeta f` (the larger of their
/// half-power damping estimates, `zeta0` when neither has one) are one mode at the more
/// prominent peak's frequency. The numerator of a mode (eq. 26) has full rank, so a
/// residue of rank two (or a repeated root), which peaks on two singular values at one
/// frequency, is one submodel. Returns the frequencies in ascending order.
pub fn merge_coincident_peaks(peaks: &[CmifPeak], fraction: f64, zeta0: f64) -> Vec<f64> {
    let mut order: Vec<&CmifPeak> = peaks.iter().collect();
    order.sort_by(|a, b| b.prominence.total_cmp(&a.prominence));
    let mut kept: Vec<&CmifPeak> = Vec::new();
    for p in order {
        let coincident = kept.iter().any(|q| {
            let zeta = match (p.damping, q.damping) {
                (Some(a), Some(b)) => a.max(b),
                (Some(a), None) | (None, Some(a)) => a,
                (None, None) => zeta0,
            };
            (p.f_hz - q.f_hz).abs() < fraction * zeta * 0.5 * (p.f_hz + q.f_hz)
        });
        if !coincident {
            kept.push(p);
        }
    }
    let mut f: Vec<f64> = kept.iter().map(|p| p.f_hz).collect();
    f.sort_by(|a, b| a.total_cmp(b));
    f
}

/// Settles the poles of `model` by Algorithm 1 at the coarse tolerance; `None` when the
/// iterations fail or end with unstable submodels (the caller keeps what it had).
fn settle_once(
    model: AdditiveModel,
    data: &FitData,
    coarse: &RivConfig,
    iterations: &mut usize,
) -> Result<AdditiveModel, Option<AdditiveModel>> {
    let fit = iterate(model, data, coarse);
    let fit = fit.map_err(|_| None)?;
    *iterations += fit.iterations;
    if matches!(fit.convergence, Convergence::Failed { .. }) && fit.iterations <= 1 {
        return Err(None);
    }
    if !fit.model.unstable_submodels().is_empty() {
        return Err(Some(fit.model));
    }
    let c = model_cost(&fit.model, data, None);
    if c.is_finite() {
        Ok(fit.model)
    } else {
        Err(None)
    }
}

/// Settles the poles of `model` by Algorithm 1 at the coarse tolerance. A mode whose
/// pole leaves the stable region while settling is not supported where the start put
/// it (typically a start mode pulled towards a stronger mode the start lacks): it is
/// removed, the numerators refitted (eq. 24), and the rest settled once more; the
/// residual-driven completion then adds modes where the data show them. `None` when the
/// iterations fail, or when the second settling fails too, or when removing the
/// unstable modes would leave no mode (the caller keeps what it had).
fn settle(
    model: AdditiveModel,
    data: &FitData,
    coarse: &RivConfig,
    iterations: &mut usize,
) -> Option<AdditiveModel> {
    match settle_once(model, data, coarse, iterations) {
        Ok(m) => Some(m),
        Err(None) => None,
        Err(Some(mut m)) => {
            let mut bad = m.unstable_submodels();
            bad.retain(|&i| m.submodels[i].kind == SubmodelKind::Mode);
            if bad.is_empty() || bad.len() >= m.modes().len() {
                return None;
            }
            bad.sort_unstable_by(|a, b| b.cmp(a));
            for i in bad {
                m.remove_submodel(i);
            }
            fit_numerators(&mut m, data).ok()?;
            settle_once(m, data, coarse, iterations).ok()
        }
    }
}

/// `model` with its rigid body replaced by one of `l` integrators (none for 0), placed
/// first, and the numerators refitted (eq. 24); `None` when the structure is not
/// possible or the numerator problem fails.
fn with_rigid_body(
    model: &AdditiveModel,
    l: usize,
    data: &FitData,
) -> Option<(AdditiveModel, f64)> {
    let mut m = model.clone();
    m.submodels.retain(|s| s.integrators == 0);
    if l > 0 {
        let (lo, hi) = data.band_hz;
        let i = m
            .push_rigid_body(l, AdditiveModel::rigid_scale(lo, hi))
            .ok()?;
        let rb = m.submodels.remove(i);
        m.submodels.insert(0, rb);
    }
    if m.submodels.is_empty() {
        return None;
    }
    let v = fit_numerators(&mut m, data).ok()?;
    v.is_finite().then_some((m, v))
}

/// The number of integrators (0, 1, 2) chosen with the poles of `model` held: the
/// simplest whose numerator fit (24) no richer one beats by an F test at `alpha` with
/// at least `min_f`. Returns the model with that rigid body and its numerators refitted.
fn rechoose_rigid_body(
    model: &AdditiveModel,
    data: &FitData,
    cfg: &CompleteConfig,
) -> Option<AdditiveModel> {
    let mut best: Option<(AdditiveModel, f64)> = None;
    for l in 0..=2usize {
        let Some((m, v)) = with_rigid_body(model, l, data) else {
            continue;
        };
        best = match best {
            None => Some((m, v)),
            Some((b, vb)) => {
                let extra = m.n_params().saturating_sub(b.n_params()).max(1);
                let s2 = noise_scale(v, data, m.n_params());
                let fs = f_statistic(vb - v, extra, s2);
                if v < vb && fs > f_critical(extra, cfg.alpha).max(cfg.min_f) {
                    Some((m, v))
                } else {
                    Some((b, vb))
                }
            }
        };
    }
    best.map(|(m, _)| m)
}

/// The refinement settings that settle poles at the coarse tolerance of `cfg`.
fn coarse_config(cfg: &CompleteConfig) -> RivConfig {
    RivConfig {
        param_tol: cfg.coarse_tol,
        cost_tol: cfg.coarse_tol * 1e-2,
        max_iterations: cfg.coarse_max_iterations,
        progress: ProgressSink::none(),
        ..RivConfig::default()
    }
}

/// The rigid body of a refined `model` chosen again (0, 1 or 2 integrators, by the
/// F test of the numerator fits with its poles held, as step 3 of the completion),
/// the poles settled around a changed one at the coarse tolerance of `cfg`. Returns the
/// settled model when the choice changed and the settled cost is below that of
/// `model`; `None` otherwise. A refiner that continues another initialiser's model
/// keeps its rigid-body structure; the initialiser may have missed integrators whose
/// states stood at the noise or round-off level of its own order selection.
pub fn rigid_body_again(
    model: &AdditiveModel,
    data: &FitData,
    cfg: &CompleteConfig,
) -> Option<AdditiveModel> {
    let coarse = coarse_config(cfg);
    let v = model_cost(model, data, None);
    if !(v.is_finite() && v > EXACT_FIT_REL * data.weighted_energy()) {
        return None;
    }
    let m = rechoose_rigid_body(model, data, cfg)?;
    if m.integrators() == model.integrators() {
        return None;
    }
    let mut its = 0;
    let m = settle(m, data, &coarse, &mut its)?;
    (model_cost(&m, data, None) < v).then_some(m)
}

/// Natural frequency (Hz) and damping of every mode of `model`.
fn mode_list(model: &AdditiveModel) -> Vec<(f64, f64)> {
    model.modes().iter().map(|m| (m.f_hz, m.zeta)).collect()
}

/// Removes the modes of `model` whose numerators are not significant (F statistic of
/// the Wald cost increase below the F test at `alpha` and below `min_f`), the weakest
/// first and one at a time, settling the poles after each removal; a removal that
/// raises the cost by more than [`CompleteConfig::min_cost_drop`] is not made (and
/// the pruning ends there). A mode whose cost
/// increase is below the rounding floor ([`CompleteConfig::rounding_floor`], squared, of
/// the weighted data's energy) counts as insignificant. A mode added where
/// the residual was largest may become redundant once the others are in place (two
/// candidates in one broad misfit); on noise-free data such a mode only fits rounding.
fn prune_insignificant(
    mut cur: AdditiveModel,
    data: &FitData,
    cfg: &CompleteConfig,
    coarse: &RivConfig,
    its: &mut usize,
    report: &mut CompleteReport,
) -> AdditiveModel {
    let m = data.m();
    let n_modes = cur.modes().len();
    // the weighted data's energy: a mode that explains less than the rounding floor of
    // it explains nothing, whatever its F statistic against a rounding-level residual
    let energy = data.weighted_energy();
    for _ in 0..n_modes {
        let Ok(dv) = submodel_cost_increase(&cur, data) else {
            break;
        };
        let v = model_cost(&cur, data, None);
        let s2 = noise_scale(v, data, cur.n_params());
        let rounding = cfg.rounding_floor * cfg.rounding_floor * energy;
        let weakest = (0..cur.submodels.len())
            .filter(|&i| cur.submodels[i].kind == SubmodelKind::Mode)
            .map(|i| {
                let p = cur.submodels[i].den.len() + cur.submodels[i].num.len() * m;
                let fs = f_statistic(dv[i], p, s2);
                let ratio = if dv[i] < rounding {
                    0.0
                } else {
                    fs / f_critical(p, cfg.alpha).max(cfg.min_f)
                };
                (i, fs, ratio)
            })
            .min_by(|a, b| a.2.total_cmp(&b.2));
        let Some((i, fs, ratio)) = weakest else {
            break;
        };
        if ratio >= 1.0 || cur.modes().len() <= 1 {
            break;
        }
        let f = cur
            .upper_pole(&cur.submodels[i])
            .map_or(f64::NAN, |p| p.norm() / TAU);
        let mut trial = cur.clone();
        trial.remove_submodel(i);
        if fit_numerators(&mut trial, data).is_err() {
            break;
        }
        let trial = settle(trial.clone(), data, coarse, its).unwrap_or(trial);
        // the noise scale of the test is estimated from the residual, which a misfit
        // elsewhere (a mode still missing) inflates: a mode whose removal raises the
        // cost by more than `min_cost_drop` explains plainly what it fits and stays
        if model_cost(&trial, data, None) > (1.0 + cfg.min_cost_drop) * v {
            break;
        }
        cur = trial;
        if let Some(k) = report.added.iter().position(|a| (a - f).abs() <= 0.05 * f) {
            report.added.remove(k);
        }
        report.rejected.push((
            f,
            format!("not significant once the others were in (F = {fs:.2})"),
        ));
    }
    cur
}

/// Why the modes of `model` from submodel `first` on are not kept, when one of them
/// is unresolved (its half-power bandwidth `2 zeta f` below the line spacing) and not
/// significant off its own lines ([`significant_off_peak`]: its
/// numerators refitted without the lines within one line spacing of it, the F test at
/// `cfg.alpha` and at least `cfg.min_f`, with the noise scale of that residual).
fn unresolved_spike(
    model: &AdditiveModel,
    data: &FitData,
    first: usize,
    cfg: &CompleteConfig,
) -> Result<Option<String>, RivError> {
    for i in first..model.submodels.len() {
        if model.submodels[i].kind != SubmodelKind::Mode {
            continue;
        }
        let Some(p) = model.upper_pole(&model.submodels[i]) else {
            continue;
        };
        let (f, bw) = (p.norm() / TAU, 2.0 * p.re.abs() / TAU);
        let df = line_spacing_near(data, f);
        if bw < df && !significant_off_peak(model, data, i, cfg.alpha, cfg.min_f)? {
            return Ok(Some(format!(
                "unresolved: half-power bandwidth {bw:.3} Hz below the line spacing {df:.3} Hz \
                 and not significant off its own lines"
            )));
        }
    }
    Ok(None)
}

/// Candidate new modes, the most likely first, as (frequency in Hz, damping estimate):
/// CMIF peaks inside the band of two views of the residual `G - P` (`resid`, of `model`
/// on `data`), taken alternately
/// (the strongest of each view first, then the second of each, ...; a peak within
/// `cfg.min_separation` of one already listed is the same misfit):
///
/// - the weighted residual `sqrt(w) (G - P)`, the residual whose energy is the cost:
///   it shows a misfit where the criterion feels it (a merged close pair, a mode whose
///   numerator is poor);
/// - the residual `G - P` itself, the frequency response of the dynamics the model
///   lacks, which peaks at a missing mode's resonance. A weighting that follows the
///   data's magnitude (eq. 27, or inverse variances of noise proportional to it)
///   divides that peak by the data's own resonance peak: where a missing mode dominates
///   the response from its resonance upwards (a well damped mode above the others), the
///   weighted residual is flat there and shows no peak at all.
///
/// Peaks of the plain view within the half-power half-width `zeta f` of a fitted mode
/// are left to the weighted view. In each view a peak is a candidate when its `sigma_1^2` is at least
/// `cfg.peak_over_median` times the view's median `sigma_1^2` and above the rounding
/// floor of the data there. The candidates only place trials; whether a mode is added
/// is decided by the significance tests of [`complete_start`]. With `unit_variance` the
/// weighted residual has unit variance per entry (inverse-variance weights) and the
/// picker measures its prominences against it.
fn residual_candidates(
    model: &AdditiveModel,
    resid: &[C64],
    data: &FitData,
    unit_variance: bool,
    cfg: &CompleteConfig,
) -> Vec<(f64, Option<f64>)> {
    let weighted = view_candidates(resid, data, true, unit_variance, cfg);
    let mut plain = view_candidates(resid, data, false, false, cfg);
    // in the plain view a fitted mode's own coarse misfit peaks at its resonance, where
    // the data are largest; the split of a mode that is really two shows in the
    // weighted view
    let modes = mode_list(model);
    plain.retain(|(f, _)| modes.iter().all(|(fm, zm)| (f - fm).abs() > zm * fm));
    let mut out: Vec<(f64, Option<f64>)> = Vec::new();
    for k in 0..weighted.len().max(plain.len()) {
        for p in [plain.get(k), weighted.get(k)].into_iter().flatten() {
            if out
                .iter()
                .all(|(f, _)| (p.0 - f).abs() > cfg.min_separation * f)
            {
                out.push(*p);
            }
        }
    }
    out
}

/// The candidates of one view of the residual `resid` (weighted by `sqrt(w)` when
/// `weighted`), the strongest first; see [`residual_candidates`].
fn view_candidates(
    resid: &[C64],
    data: &FitData,
    weighted: bool,
    unit_variance: bool,
    cfg: &CompleteConfig,
) -> Vec<(f64, Option<f64>)> {
    let scale = |i: usize| -> f64 {
        if weighted {
            data.w[i].max(0.0)
        } else {
            1.0
        }
    };
    let view: Vec<C64> = resid
        .iter()
        .enumerate()
        .map(|(i, e)| *e * scale(i).sqrt())
        .collect();
    let f: Vec<f64> = data.omega.iter().map(|w| w / TAU).collect();
    let var = unit_variance.then(|| vec![1.0; view.len()]);
    let Ok(frf) = Frf::new(f, data.ny, data.nu, view, var) else {
        return Vec::new();
    };
    let Ok(c) = cmif(&frf) else {
        return Vec::new();
    };
    let mut s1: Vec<f64> = c.sv2.iter().map(|s| s[0]).collect();
    s1.sort_by(|a, b| a.total_cmp(b));
    let median = s1[s1.len() / 2];
    let (lo, hi) = data.band_hz;
    let m = data.m();
    // the data's energy at a line in the same view (an upper bound of its sigma_1^2)
    let level = |k: usize| -> f64 {
        (0..m)
            .map(|e| scale(k * m + e) * data.g[k * m + e].norm_sqr())
            .sum::<f64>()
    };
    let floor = cfg.rounding_floor * cfg.rounding_floor;
    let mut peaks: Vec<CmifPeak> = pick_peaks(&c, &cfg.peaks)
        .into_iter()
        .filter(|p| {
            p.f_hz > lo
                && p.f_hz < hi
                && p.sv2 >= cfg.peak_over_median * median
                && p.sv2 >= floor * level(p.candidate_line)
        })
        .collect();
    peaks.sort_by(|a, b| b.sv2.total_cmp(&a.sv2));
    // one candidate per misfit: a broad residual bump is picked on several lines and
    // singular values; the strongest pick stands for the others nearby
    let mut out: Vec<(f64, Option<f64>)> = Vec::new();
    for p in peaks {
        if out
            .iter()
            .all(|(f, _)| (p.f_hz - f).abs() > cfg.min_separation * f)
        {
            out.push((p.f_hz, p.damping));
        }
    }
    out
}

/// Candidate new modes from the matched single-mode scan of the weighted residual
/// `resid` of `model` ([`crate::mode_scan`]), as (frequency in Hz, damping): the `cfg.scan_trials` trial
/// poles that remove the most weighted residual energy, each farther than
/// `cfg.min_separation` from the candidates `tried` already (the residual's peaks) and
/// than two half-power half-widths from a fitted mode (there the scan sees the mode's
/// own coarse misfit; the split of a mode that is really two is the peaks' case).
fn scan_candidates(
    model: &AdditiveModel,
    resid: &[C64],
    data: &FitData,
    tried: &[(f64, Option<f64>)],
    cfg: &CompleteConfig,
) -> Vec<(f64, Option<f64>)> {
    let modes = mode_list(model);
    scan_residual(resid, data, &cfg.scan, cfg.min_separation)
        .into_iter()
        .filter(|h| {
            tried
                .iter()
                .all(|(f, _)| (h.f_hz - f).abs() > cfg.min_separation * f)
                && modes
                    .iter()
                    .all(|(fm, zm)| (h.f_hz - fm).abs() > 2.0 * zm * fm)
        })
        .take(cfg.scan_trials)
        .map(|h| (h.f_hz, Some(h.zeta)))
        .collect()
}

/// A trial of [`complete_start`]: the submodel it replaces (a split), and the modes it
/// adds (frequency in Hz, damping when known).
type Trial = (Option<usize>, Vec<(f64, Option<f64>)>);

/// The split trials of [`complete_start`]: the modes of `model` whose damping is at
/// least [`CompleteConfig::split_zeta`], the broadest first (at most
/// [`CompleteConfig::split_trials`]), each as the mode to replace and two modes at its
/// half-power points `f (1 -+ zeta)`, and at twice that distance, with a third of its
/// damping. On a start that missed modes, the pole settling lets one mode cover
/// two neighbours (1.4-1.8 apart) as a broad resonance at damping 0.1 to 0.3; the
/// residual then shows no peak of its own at either, and a mode added beside the broad
/// one settles onto its pole.
fn split_candidates(model: &AdditiveModel, cfg: &CompleteConfig) -> Vec<Trial> {
    let modes: Vec<(usize, f64, f64)> = model
        .submodels
        .iter()
        .enumerate()
        .filter(|(_, s)| s.kind == SubmodelKind::Mode)
        .filter_map(|(i, s)| {
            let p = model.upper_pole(s)?;
            let w = p.norm();
            (w > 0.0).then(|| (i, w / TAU, -p.re / w))
        })
        .collect();
    let mut broad: Vec<&(usize, f64, f64)> =
        modes.iter().filter(|m| m.2 >= cfg.split_zeta).collect();
    broad.sort_by(|a, b| b.2.total_cmp(&a.2));
    broad
        .into_iter()
        .take(cfg.split_trials)
        .flat_map(|&(i, f, z)| {
            // at the half-power points, and twice as far apart (a broad mode may sit
            // nearer one of the two it covers)
            [1.0, 2.0].into_iter().filter_map(move |k| {
                let d = k * z;
                (d < 0.7).then(|| {
                    (
                        Some(i),
                        vec![
                            (f * (1.0 - d), Some(z / 3.0)),
                            (f * (1.0 + d), Some(z / 3.0)),
                        ],
                    )
                })
            })
        })
        .collect()
}

/// Adds a mode at `f_hz` with damping `zeta` to `model`; a frequency inside the
/// bandwidth of an existing mode (closer than `DUPLICATE` of its half-power half-width)
/// is moved half a half-width away from it on its own side, so that the two poles start
/// apart (the split of a mode that is really two).
fn push_candidate(model: &mut AdditiveModel, f_hz: f64, zeta: f64) -> Result<(), RivError> {
    const DUPLICATE: f64 = 0.25;
    let mut f = f_hz;
    for (fm, zm) in mode_list(model) {
        let half = zm.max(1e-4) * fm;
        if (f - fm).abs() < DUPLICATE * half {
            f = if f >= fm {
                fm + 0.5 * half
            } else {
                fm - 0.5 * half
            };
        }
    }
    if let Domain::ZohDiscrete { ts } = model.domain() {
        if TAU * f * ts >= 0.95 * std::f64::consts::PI {
            return Err(RivError::invalid(
                "mode frequency",
                f,
                "near the Nyquist frequency",
            ));
        }
    }
    model.push_mode(f, zeta, false)?;
    Ok(())
}

/// Completes the start `model` (the CMIF initialisation with its numerators fitted):
/// settles its poles, chooses the rigid body again when `rigid_auto`, and (when
/// `add_modes`) adds modes at significant peaks of the residual's CMIF, as the module
/// documentation describes. Returns the completed model, which is never worse in cost
/// than the settled start, and what was done. `unit_variance` says that the weights are
/// the inverse variances.
pub fn complete_start(
    model: AdditiveModel,
    data: &FitData,
    unit_variance: bool,
    rigid_auto: bool,
    add_modes: bool,
    cfg: &CompleteConfig,
) -> Result<(AdditiveModel, CompleteReport), RivError> {
    let coarse = coarse_config(cfg);
    let mut report = CompleteReport {
        integrators: (model.integrators(), model.integrators()),
        ..Default::default()
    };
    let mut its = 0;
    // the rigid body is chosen again only against settled poles: a start whose poles
    // did not settle (the iterations failed or left the stable region) misfits so
    // grossly that the F test's noise scale, estimated from that misfit, finds no
    // rigid body significant, and the choice made by comparing the initial fits stands
    let (mut cur, mut settled) = match settle(model.clone(), data, &coarse, &mut its) {
        Some(m) => (m, true),
        None => (model, false),
    };
    let mut v = model_cost(&cur, data, None);
    let rechoose = |cur: AdditiveModel, v: f64, its: &mut usize| -> (AdditiveModel, f64) {
        let l_now = cur.integrators();
        let Some(m) = rechoose_rigid_body(&cur, data, cfg) else {
            return (cur, v);
        };
        if m.integrators() == l_now {
            return (cur, v);
        }
        // the new rigid body stands only with poles that settle around it
        let Some(m) = settle(m, data, &coarse, its) else {
            return (cur, v);
        };
        let vm = model_cost(&m, data, None);
        (m, vm)
    };
    if rigid_auto && settled {
        (cur, v) = rechoose(cur, v, &mut its);
    }
    // the weighted energy of the data (the cost of the zero model): a fit at the
    // round-off level of it is exact, and no statistical test can judge a mode added
    // to it (on a noise-free single-mode system an added mode at damping 0.76 passed
    // the F test on costs of 1e-25, and the refiner drove it off the stable region)
    let energy = data.weighted_energy();
    let exact = |v: f64| v <= EXACT_FIT_REL * energy;
    if add_modes {
        for round in 0..cfg.max_rounds {
            if exact(v) {
                break;
            }
            report.rounds = round + 1;
            // the residual of the round's model serves the peaks and the scan
            let mut resid = Vec::new();
            model_cost(&cur, data, Some(&mut resid));
            let mut cands = residual_candidates(&cur, &resid, data, unit_variance, cfg);
            cands.truncate(cfg.max_trials_per_round);
            // one candidate at a time, the strongest first: the first that lowers the
            // cost significantly is kept (a broad misfit has side peaks that a mode at
            // its centre removes too); when no residual peak gives one, the scan's
            // best trial poles are tried (a missing mode the settled neighbours
            // covered leaves no peak)
            let mut accepted = None;
            let mut trials: Vec<Trial> = cands.iter().map(|c| (None, vec![*c])).collect();
            let mut scanned = cfg.scan_trials == 0;
            let mut paired = !cfg.pair_trials;
            let mut split = cfg.split_trials == 0;
            let mut c = 0;
            loop {
                if c == trials.len() && !scanned {
                    scanned = true;
                    let more = scan_candidates(&cur, &resid, data, &cands, cfg);
                    cands.extend(more.iter().copied());
                    trials.extend(more.into_iter().map(|c| (None, vec![c])));
                }
                if c == trials.len() && !paired {
                    // two missing modes that the settled neighbours share between them
                    // (one broad mode over both) are found together or not at all
                    paired = true;
                    let k = cands.len().min(3);
                    for a in 0..k {
                        for b in a + 1..k {
                            trials.push((None, vec![cands[a], cands[b]]));
                        }
                    }
                }
                if c == trials.len() && !split {
                    // a broad mode that settled over two true ones is split in two
                    split = true;
                    trials.extend(split_candidates(&cur, cfg));
                }
                if c == trials.len() {
                    break;
                }
                let (replaced, cand) = &trials[c];
                c += 1;
                let mut trial = cur.clone();
                if let Some(i) = *replaced {
                    trial.remove_submodel(i);
                }
                let n_old = trial.submodels.len();
                let mut ok = true;
                for &(f, z) in cand.iter() {
                    let zeta = z.unwrap_or(cfg.zeta0).clamp(1e-3, 0.2);
                    if push_candidate(&mut trial, f, zeta).is_err() {
                        ok = false;
                    }
                }
                if !ok
                    || trial.submodels.len() == n_old
                    || fit_numerators(&mut trial, data).is_err()
                {
                    continue;
                }
                let Some(trial) = settle(trial, data, &coarse, &mut its) else {
                    continue;
                };
                if has_duplicate(&trial) {
                    for &(f, _) in cand.iter() {
                        report
                            .rejected
                            .push((f, "settled on the pole of another mode".into()));
                    }
                    continue;
                }
                let vt = model_cost(&trial, data, None);
                let added = trial.n_params().saturating_sub(cur.n_params()).max(1);
                let s2 = noise_scale(vt, data, trial.n_params());
                let fs = f_statistic(v - vt, added, s2);
                let fcrit = f_critical(added, cfg.alpha).max(cfg.min_f);
                if vt < (1.0 - cfg.min_cost_drop) * v && fs > fcrit {
                    // an added mode narrower than the line spacing must explain the
                    // residual off its own lines: one outlying line (a noise spike, or a
                    // line where the weighting amplifies the noise, as eq. (27) does at
                    // an anti-resonance) is fitted by such a mode as well as by any
                    if let Some(why) = unresolved_spike(&trial, data, n_old, cfg)? {
                        for &(f, _) in cand.iter() {
                            report.rejected.push((f, why.clone()));
                        }
                        continue;
                    }
                    accepted = Some((trial, vt, n_old));
                    break;
                }
                for &(f, _) in cand.iter() {
                    report.rejected.push((
                        f,
                        format!("cost {v:.3e} -> {vt:.3e} (F = {fs:.1}, needed {fcrit:.1} and a {:.0} % drop)", 100.0 * cfg.min_cost_drop),
                    ));
                }
            }
            let Some((mut trial, mut vt, n_old)) = accepted else {
                break;
            };
            // drop the added modes that are not significant on their own
            let dv = submodel_cost_increase(&trial, data).unwrap_or_default();
            let s2 = noise_scale(vt, data, trial.n_params());
            let m = data.m();
            let mut weak: Vec<usize> = (n_old..trial.submodels.len())
                .filter(|&i| {
                    let p = trial.submodels[i].den.len() + trial.submodels[i].num.len() * m;
                    dv.get(i).is_some_and(|&d| {
                        f_statistic(d, p, s2) < f_critical(p, cfg.alpha).max(cfg.min_f)
                    })
                })
                .collect();
            weak.sort_unstable_by(|a, b| b.cmp(a));
            if !weak.is_empty() && weak.len() < trial.submodels.len() - n_old {
                for &i in &weak {
                    let f = trial
                        .upper_pole(&trial.submodels[i])
                        .map_or(f64::NAN, |p| p.norm() / TAU);
                    report
                        .rejected
                        .push((f, "not significant on its own".into()));
                    trial.remove_submodel(i);
                }
                if let Ok(c) = fit_numerators(&mut trial, data) {
                    vt = c;
                }
            }
            for i in n_old..trial.submodels.len() {
                if trial.submodels[i].kind == SubmodelKind::Mode {
                    report.added.push(
                        trial
                            .upper_pole(&trial.submodels[i])
                            .map_or(f64::NAN, |p| p.norm() / TAU),
                    );
                }
            }
            cur = trial;
            v = vt;
            settled = true;
            if rigid_auto && settled {
                (cur, v) = rechoose(cur, v, &mut its);
            }
        }
    }
    if add_modes {
        cur = prune_insignificant(cur, data, cfg, &coarse, &mut its, &mut report);
    }
    report.integrators.1 = cur.integrators();
    report.iterations = its;
    Ok((cur, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peak(f: f64, prom: f64, zeta: Option<f64>, sv: usize) -> CmifPeak {
        CmifPeak {
            f_hz: f,
            line: 0,
            sv_index: sv,
            prominence: prom,
            sv2: 1.0,
            candidate_line: 0,
            damping: zeta,
        }
    }

    #[test]
    fn coincident_peaks_merge_and_close_modes_stay() {
        // one mode of damping 0.02 at 200 Hz seen on two singular values (0.46 Hz apart,
        // 0.11 half-widths), and a separate mode 2 % higher (one bandwidth away)
        let p = [
            peak(200.0, 5.0, Some(0.02), 0),
            peak(200.46, 4.0, Some(0.02), 1),
            peak(208.0, 6.0, Some(0.02), 1),
        ];
        assert_eq!(merge_coincident_peaks(&p, 0.25, 0.01), vec![200.0, 208.0]);
        // without damping estimates the default damping sets the scale
        let p = [peak(100.0, 3.0, None, 0), peak(100.1, 4.0, None, 1)];
        assert_eq!(merge_coincident_peaks(&p, 0.25, 0.01), vec![100.1]);
    }
}
