//! Adapting the set of modes (the first form of the residual-diagnosis loop, issue
//! "additive-RIV" item 2): after a refinement, modes are added where the weighted
//! residual shows significant peaks (the picker missed close modes) and removed when
//! their numerators are insignificant, duplicated or unstable (the picker saw a
//! spurious peak), then the model is refined again.
//!
//! Detection statistic: per line, `T_k = sum_e w_ke |E_ke|^2` is the sum of the squared
//! singular values of the weighted residual (the residual's CMIF summed over singular
//! values); with an adequate model `2 T_k / s^2` is chi-square with `2 ny nu` degrees of
//! freedom. A peak must exceed the Bonferroni-corrected quantile over all lines. A mode
//! is kept only when the F statistic of its parameters passes at significance `alpha`.

use crate::held_out::{halves, held_out};
use crate::pair_start::with_local_pairs;
use crate::problem::FitData;
use crate::residual_stats::{
    close_mode_pairs, cost_of, line_spacing_near, local_energy, mode_f_hz, significant_off_peak,
    ResidualStats, DUPLICATE_FRACTION, EXACT_FIT_REL,
};
use crate::riv::{iterate_warm, RivConfig};
use crate::significance::{f_critical_eff, f_statistic, submodel_cost_increase};
use crate::{fit_numerators, AdditiveModel, RivError, SubmodelKind};
use frf_data::structure::{StructureChange, StructureStep};
use frf_data::Fit;
use std::f64::consts::TAU;

/// Settings of [`adapt_modes`].
#[derive(Debug, Clone)]
pub struct AdaptConfig {
    /// Rounds of add/drop (each ends with a refinement). Default: 3.
    pub max_rounds: usize,
    /// Significance level of the tests. Default: 1e-3.
    pub alpha: f64,
    /// At most this many modes added per round. Default: 6.
    pub max_new_per_round: usize,
    /// Candidate peaks closer than this relative distance are one candidate (the
    /// strongest): a merged close pair leaves residual peaks on both sides of the fitted
    /// mode, and one new mode per round resolves it. Default: 0.025.
    pub min_separation: f64,
    /// Damping of an added mode. Default: 0.01.
    pub zeta0: f64,
    /// Relative parameter tolerance of the refinements between structure changes (the
    /// last refinement uses the full tolerance of the RIV settings). Default: 1e-4: the
    /// add/drop tests need the poles settled to a fraction of a bandwidth, not more.
    pub coarse_tol: f64,
    /// Iteration limit of the refinements between structure changes. Default: 15.
    pub coarse_max_iterations: usize,
    /// An added mode is kept only when the weighted residual energy within
    /// `local_window` (relative) of the residual peak that called for it falls below this
    /// fraction of what it was before the mode was added. Default: 0.25.
    pub max_local_ratio: f64,
    /// Half-width of that window, relative to the peak frequency. Default: 0.01.
    pub local_window: f64,
    /// Practical-significance floor: a mode is added or kept only when its F statistic
    /// (the cost its parameters explain, in units of what they would absorb of pure
    /// noise) is at least this, on top of the F test at `alpha`. Measured FRF noise is
    /// heavier-tailed than Gaussian (estimated variances, leakage, distortion), so that
    /// spurious modes fitted to noise reach F of 2..5, while real modes reach 1e3 and
    /// more. Default: 25.
    pub min_f: f64,
    /// Modes may sit this factor outside the band (a mode just above the band still
    /// shapes its edge); beyond it they are removed. Default: 1.25.
    pub band_margin: f64,
    /// A residual peak is a mode candidate only when it rises this factor above its
    /// local median (within +-10 % in frequency). Default: [`PEAK_OVER_LOCAL`] (10);
    /// the diagnosis loop uses 5 after a broadband effect was added, where the misfit
    /// of several missing modes raises each other's local level.
    pub peak_over_local: f64,
}

impl Default for AdaptConfig {
    fn default() -> Self {
        Self {
            max_rounds: 3,
            alpha: 1e-3,
            max_new_per_round: 6,
            min_separation: 0.025,
            zeta0: 0.01,
            min_f: 25.0,
            max_local_ratio: 0.25,
            local_window: 0.01,
            coarse_tol: 1e-4,
            coarse_max_iterations: 15,
            band_margin: 1.25,
            peak_over_local: PEAK_OVER_LOCAL,
        }
    }
}

/// What [`adapt_modes`] changed.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdaptReport {
    /// Modes added (frequency in Hz after refinement, F statistic).
    pub added: Vec<(f64, f64)>,
    /// Modes removed (frequency in Hz, reason).
    pub dropped: Vec<(f64, String)>,
    /// Rounds run.
    pub rounds: usize,
    /// Iterations of each refinement, in order.
    pub refinements: Vec<usize>,
    /// The same changes as typed structure steps, in order, with the weighted cost
    /// before and after each: per round, the modes removed by its checks
    /// (`poles_dropped`), the modes added at its residual peaks (`modes_added`, taken
    /// when one of them survived the round) and the added modes its checks removed
    /// again (`poles_dropped`). Empty in reports written before they were recorded.
    #[serde(default)]
    pub steps: Vec<StructureStep>,
}

/// The structure step of modes removed by the adaptation's checks: `removed` holds
/// each mode's frequency (Hz, NaN for real poles) and why; the cost from `before` to
/// `after`.
fn removal_step(removed: &[(f64, String)], before: f64, after: f64) -> StructureStep {
    StructureStep::untested(
        StructureChange::PolesDropped {
            poles: removed
                .iter()
                .map(|(f, why)| {
                    if f.is_finite() {
                        format!("mode at {f:.2} Hz: {why}")
                    } else {
                        format!("real poles: {why}")
                    }
                })
                .collect(),
            reason: "the structure adaptation's checks".into(),
        },
        true,
        before,
        Some(after),
    )
}

/// Candidate frequencies (Hz) of missed modes: local maxima of the per-line weighted
/// residual statistic ([`ResidualStats`]) that exceed both its Bonferroni-corrected
/// threshold and [`PEAK_OVER_LOCAL`] times its local median (within +-10 % in
/// frequency), the largest statistic first, with the ratio to the larger of the two. The local test
/// keeps a broadband misfit (a delay, a hold) from being taken for modes, and measured
/// noise, whose peaks reach about 3 times the local median, from being fitted.
pub fn residual_peaks(
    stats: &ResidualStats,
    data: &FitData,
    alpha: f64,
    min_separation: f64,
) -> Vec<(f64, f64)> {
    residual_peaks_over(stats, data, alpha, min_separation, PEAK_OVER_LOCAL)
}

/// [`residual_peaks`] with the factor over the local median given: `over_local`
/// instead of [`PEAK_OVER_LOCAL`].
pub fn residual_peaks_over(
    stats: &ResidualStats,
    data: &FitData,
    alpha: f64,
    min_separation: f64,
    over_local: f64,
) -> Vec<(f64, f64)> {
    let n = data.n;
    let thr = stats.threshold(alpha / n as f64);
    let t = &stats.t;
    let mut peaks: Vec<(f64, f64, f64)> = Vec::new();
    for k in 0..n {
        if t[k] <= thr {
            continue;
        }
        let f = data.omega[k] / TAU;
        let is_max = (0..n).all(|j| {
            let fj = data.omega[j] / TAU;
            (fj - f).abs() > min_separation * f || t[j] <= t[k]
        });
        if !is_max {
            continue;
        }
        let level = thr.max(over_local * stats.local_median(&data.omega, k, 0.1));
        if t[k] > level {
            peaks.push((f, t[k] / level, t[k]));
        }
    }
    // strongest first: the largest statistic (a strong missed mode also raises its own
    // local level, so the ratio would understate it)
    peaks.sort_by(|a, b| b.2.total_cmp(&a.2));
    peaks.into_iter().map(|(f, r, _)| (f, r)).collect()
}

/// How far above its local median a residual peak must rise to be a mode candidate.
pub const PEAK_OVER_LOCAL: f64 = 10.0;

/// Removed (submodel index, frequency, reason), per-submodel (frequency, F statistic),
/// and, when nothing was removed, the residual statistics of the model as returned (the
/// caller's next residual test reuses them instead of computing them again).
type DropOutcome = (
    Vec<(usize, f64, String)>,
    Vec<(f64, f64)>,
    Option<ResidualStats>,
);

/// Removes unstable, overdamped, out-of-band, unresolved (a half-power bandwidth below
/// the line spacing and not significant off its own lines, [`significant_off_peak`]) and
/// duplicated modes (checks on the poles), then the modes whose numerators are insignificant (F test at
/// `alpha` with the effective number of parameters, and at least `min_f`). Returns the
/// removed (frequency, reason) pairs and, per submodel of the model as given, its
/// frequency and F statistic (NaN when removed before the test). Numerators are refitted
/// after any removal. Submodels in `protect` are never removed.
fn drop_pass(
    model: &mut AdditiveModel,
    data: &FitData,
    cfg: &AdaptConfig,
    protect: &[usize],
) -> Result<DropOutcome, RivError> {
    let m = data.m();
    let (lo, hi) = data.band_hz;
    let n_sub = model.submodels.len();
    let unstable = model.unstable_submodels();
    let modes: Vec<usize> = (0..n_sub)
        .filter(|&i| model.submodels[i].kind == SubmodelKind::Mode && !protect.contains(&i))
        .collect();
    let mut remove: Vec<(usize, String)> = Vec::new();
    // 1. checks on the poles
    for &i in &modes {
        let f = mode_f_hz(model, i);
        let zeta = model
            .upper_pole(&model.submodels[i])
            .map_or(f64::NAN, |p| -p.re / p.norm());
        if unstable.contains(&i) {
            remove.push((i, "unstable pole (left the stable region)".into()));
        } else if !f.is_finite() {
            remove.push((i, "real (overdamped) poles: not a resonance".into()));
        } else if f < lo / cfg.band_margin || f > hi * cfg.band_margin {
            remove.push((i, format!("moved outside the band {lo:.1}..{hi:.1} Hz")));
        } else if 2.0 * zeta * f < line_spacing_near(data, f)
            && !significant_off_peak(model, data, i, cfg.alpha, cfg.min_f)?
        {
            remove.push((
                i,
                format!(
                    "unresolved: half-power bandwidth {:.3} Hz is below the line spacing {:.3} Hz and the mode is not significant off its own lines",
                    2.0 * zeta * f,
                    line_spacing_near(data, f)
                ),
            ));
        }
    }
    // duplicates: poles within DUPLICATE_FRACTION of their mean |Re p|; the more damped
    // one goes
    for (a, b, _) in close_mode_pairs(model, DUPLICATE_FRACTION) {
        if remove.iter().any(|(r, _)| *r == a || *r == b) {
            continue;
        }
        let damping = |i: usize| {
            model
                .upper_pole(&model.submodels[i])
                .map_or(f64::NAN, |p| p.re.abs())
        };
        let (keep, go) = if damping(a) <= damping(b) {
            (a, b)
        } else {
            (b, a)
        };
        let (keep, go) = if protect.contains(&go) {
            (go, keep)
        } else {
            (keep, go)
        };
        if !protect.contains(&go) {
            remove.push((
                go,
                format!("duplicate of the mode at {:.2} Hz", mode_f_hz(model, keep)),
            ));
        }
    }
    // 2. significance of what is left
    let mut stats: Vec<(f64, f64)> = (0..n_sub)
        .map(|i| (mode_f_hz(model, i), f64::NAN))
        .collect();
    let kept: Vec<usize> = (0..n_sub)
        .filter(|i| !remove.iter().any(|(r, _)| r == i))
        .collect();
    let mut trial = model.clone();
    trial.submodels = kept.iter().map(|&i| model.submodels[i].clone()).collect();
    if !remove.is_empty() {
        fit_numerators(&mut trial, data)?;
    }
    let rstats = ResidualStats::new(&trial, data);
    let dv = submodel_cost_increase(&trial, data)?;
    for (t, &i) in kept.iter().enumerate() {
        let p = trial.submodels[t].den.len() + trial.submodels[t].num.len() * m;
        let fs = f_statistic(dv[t], p, rstats.s2);
        stats[i].1 = fs;
        if modes.contains(&i) {
            let fcrit = f_critical_eff(rstats.effective_params(p, m), cfg.alpha).max(cfg.min_f);
            if fs < fcrit {
                remove.push((i, format!("insignificant (F = {fs:.2} < {fcrit:.2})")));
            }
        }
    }
    remove.sort_by_key(|x| std::cmp::Reverse(x.0));
    remove.dedup_by_key(|x| x.0);
    let mut out = Vec::new();
    for (i, why) in remove {
        let f = mode_f_hz(model, i);
        model.remove_submodel(i);
        out.push((i, f, why));
    }
    if !out.is_empty() {
        fit_numerators(model, data)?;
    }
    // nothing removed: `trial` is the model as returned
    let unchanged = out.is_empty().then_some(rstats);
    Ok((out, stats, unchanged))
}

/// Removes unstable, overdamped, out-of-band, unresolved, duplicated and insignificant
/// modes of `model` (see the checks of [`adapt_modes`]) and refits the numerators;
/// returns what was removed (frequency in Hz, NaN when the poles were real, and why).
pub fn prune_modes(
    model: &mut AdditiveModel,
    data: &FitData,
    cfg: &AdaptConfig,
) -> Result<Vec<(f64, String)>, RivError> {
    let (removed, _, _) = drop_pass(model, data, cfg, &[])?;
    Ok(removed.into_iter().map(|(_, f, why)| (f, why)).collect())
}

/// Refines `start` with RIV, then adds modes at significant residual peaks and removes
/// insignificant, duplicate or unstable ones, refining after each change, until nothing
/// changes or `cfg.max_rounds` rounds have run. A round's additions that pass their
/// tests on the data must also lower the weighted cost on interleaved held-out lines
/// ([`crate::held_out`]): additions that raise it (modes that follow the noise or the
/// nonlinear distortion of the lines they were fitted to) are taken out again, the
/// structure step says so with both costs, and the structure is final.
pub fn adapt_modes(
    start: AdditiveModel,
    data: &FitData,
    riv: &RivConfig,
    cfg: &AdaptConfig,
) -> Result<(Fit<AdditiveModel>, AdaptReport), RivError> {
    let mut report = AdaptReport::default();
    // Refinements between structure changes only need to settle the poles well enough
    // for the tests; the last one converges to the full tolerance.
    let coarse = RivConfig {
        param_tol: riv.param_tol.max(cfg.coarse_tol),
        cost_tol: riv.cost_tol.max(cfg.coarse_tol * 1e-2),
        max_iterations: riv.max_iterations.min(cfg.coarse_max_iterations),
        ..riv.clone()
    };
    // the factors of the last full refined-IV step: a refinement of an unchanged
    // structure starts with chord steps from them (`iterate_warm`)
    let mut warm = None;
    let mut fit = iterate_warm(start, data, &coarse, &mut warm)?;
    report.refinements.push(fit.iterations);
    let mut total_iterations = fit.iterations;
    let mut history = fit.cost_history.clone();
    // the data's even and odd lines, made when a round's additions are first checked
    let mut held_out_halves: Option<[FitData; 2]> = None;
    for round in 0..cfg.max_rounds {
        let mut held_back = false;
        report.rounds = round + 1;
        let previous = fit.clone();
        let previous_cost = cost_of(&previous.model, data);
        let mut model = fit.model.clone();
        // 1. remove what does not belong
        let (dropped, _, kept_stats) = drop_pass(&mut model, data, cfg, &[])?;
        let mut changed = !dropped.is_empty();
        let round_start = report.dropped.len();
        report
            .dropped
            .extend(dropped.iter().map(|(_, f, why)| (*f, why.clone())));
        // the removals of this round's added modes follow in `report.dropped`
        let additions_start = report.dropped.len();
        // 2. add modes at residual peaks
        let n_old = model.submodels.len();
        let (lo, hi) = data.band_hz;
        // an exact fit's residual is round-off: its peaks are no modes, whatever their
        // F statistic against it (see `EXACT_FIT_REL`)
        let cost_now = if dropped.is_empty() {
            previous_cost
        } else {
            cost_of(&model, data)
        };
        if !dropped.is_empty() {
            let step = removal_step(
                &report.dropped[round_start..additions_start],
                previous_cost,
                cost_now,
            );
            report.steps.push(step);
        }
        let exact = cost_now <= EXACT_FIT_REL * data.weighted_energy();
        let first_order = model_first_order(&model);
        let stats = kept_stats.unwrap_or_else(|| ResidualStats::new(&model, data));
        let mut peak_at = Vec::new();
        // the structure the round's additions are held against on held-out lines
        let before_adds = model.clone();
        for &(f, _) in residual_peaks_over(
            &stats,
            data,
            cfg.alpha,
            cfg.min_separation,
            cfg.peak_over_local,
        )
        .iter()
        .filter(|(f, _)| !exact && *f > lo && *f < hi)
        .take(cfg.max_new_per_round)
        {
            model.push_mode(f, cfg.zeta0, first_order)?;
            peak_at.push(f);
        }
        let added: Vec<usize> = (n_old..model.submodels.len()).collect();
        if added.is_empty() && !changed {
            break;
        }
        changed |= !added.is_empty();
        // A round whose new modes make the problem singular (a peak of a residual at
        // rounding level, a mode on top of another) is undone, not an error of the fit.
        // an added mode inside a fitted mode's bandwidth (a merged close pair) starts
        // from the pair settled on its own lines when that lowers the cost
        // ([`crate::pair_start`])
        let attempt = fit_numerators(&mut model, data).and_then(|_| {
            if let Some(better) = with_local_pairs(&model, data, &stats, n_old, &added, riv) {
                model = better;
            }
            iterate_warm(model, data, &coarse, &mut warm)
        });
        let mut refit = match attempt {
            Ok(f) => f,
            Err(RivError::Numerical { why, .. }) => {
                report.steps.push(StructureStep::untested(
                    StructureChange::ModesAdded {
                        start_hz: peak_at.clone(),
                    },
                    false,
                    cost_now,
                    None,
                ));
                report.dropped.push((
                    f64::NAN,
                    format!(
                        "round {} undone: the added modes made the fit singular ({why})",
                        round + 1
                    ),
                ));
                fit = previous;
                break;
            }
            Err(e) => return Err(e),
        };
        report.refinements.push(refit.iterations);
        total_iterations += refit.iterations;
        history.extend_from_slice(&refit.cost_history);
        // 3. keep only the added modes that are significant and that remove most of
        //    the residual around them (a missed mode leaves only noise behind; a mode
        //    fitted to a broadband misfit only reshapes it)
        // the round's additions as a structure step (taken when one survives), and the
        // added modes its checks remove again
        let mut added_step = (!added.is_empty()).then(|| {
            StructureStep::untested(
                StructureChange::ModesAdded {
                    start_hz: peak_at.clone(),
                },
                false,
                cost_now,
                Some(cost_of(&refit.model, data)),
            )
        });
        if !added.is_empty() {
            let mut model = refit.model.clone();
            let after = ResidualStats::new(&model, data);
            let mut local_reject: Vec<(usize, f64, String)> = Vec::new();
            for (t, &i) in added.iter().enumerate() {
                let f = mode_f_hz(&model, i);
                // the residual around the peak that called for the mode must drop
                let fp = peak_at[t];
                let half = cfg.local_window * fp;
                let ratio = local_energy(&after, data, fp, half)
                    / local_energy(&stats, data, fp, half).max(f64::MIN_POSITIVE);
                if ratio > cfg.max_local_ratio {
                    local_reject.push((
                        i,
                        f,
                        format!(
                            "leaves {:.0}% of the local residual (a missed mode removes more than {:.0}%)",
                            100.0 * ratio,
                            100.0 * (1.0 - cfg.max_local_ratio)
                        ),
                    ));
                }
            }
            local_reject.sort_by_key(|a| std::cmp::Reverse(a.0));
            for (i, _, _) in &local_reject {
                model.remove_submodel(*i);
            }
            let kept_added: Vec<usize> = added
                .iter()
                .copied()
                .filter(|i| !local_reject.iter().any(|r| r.0 == *i))
                .collect();
            // indices of the kept added modes after the removals
            let remap = |i: usize| i - local_reject.iter().filter(|r| r.0 < i).count();
            if !local_reject.is_empty() {
                fit_numerators(&mut model, data)?;
                report
                    .dropped
                    .extend(local_reject.iter().map(|(_, f, why)| (*f, why.clone())));
            }
            let protect: Vec<usize> = (0..n_old).collect();
            let (dropped_new, stats, _) = drop_pass(&mut model, data, cfg, &protect)?;
            let added_before = report.added.len();
            for &i in &kept_added {
                let j = remap(i);
                if !dropped_new.iter().any(|d| d.0 == j) {
                    report.added.push(stats[j]);
                }
            }
            if !local_reject.is_empty() && dropped_new.is_empty() {
                refit.model = model.clone();
            }
            // nothing new survived and nothing was removed: the structure is final
            let survived = kept_added
                .iter()
                .any(|&i| !dropped_new.iter().any(|d| d.0 == remap(i)));
            if let Some(st) = added_step.as_mut() {
                st.accepted = survived;
            }
            if !survived && dropped.is_empty() {
                changed = false;
            }
            if !dropped_new.is_empty() {
                // the numerators were refitted without them; the next round (or the
                // final refinement) settles the poles
                report
                    .dropped
                    .extend(dropped_new.into_iter().map(|(_, f, why)| (f, why)));
                refit.model = model;
            }
            // the surviving additions must also lower the error on the lines they
            // were not fitted to
            if survived {
                let halves = held_out_halves.get_or_insert_with(|| halves(data));
                let h = held_out(halves, &coarse, &before_adds, &refit.model);
                if let Some(st) = added_step.as_mut() {
                    st.held_out = h;
                }
                if let Some(h) = h.filter(|h| !h.lowers()) {
                    let rejected: Vec<(f64, f64)> = report.added.drain(added_before..).collect();
                    report.dropped.extend(rejected.iter().map(|&(f, fs)| {
                        (
                            f,
                            format!(
                                "added at a residual peak (F = {fs:.1}), but on interleaved held-out lines (refitted on the even lines and tested on the odd ones, and the reverse) the round's additions raise the weighted cost from {:.4e} to {:.4e}",
                                h.before, h.after
                            ),
                        )
                    }));
                    if let Some(st) = added_step.as_mut() {
                        st.accepted = false;
                    }
                    // back to the round's structure without its additions
                    refit = if dropped.is_empty() {
                        previous.clone()
                    } else {
                        let back = iterate_warm(before_adds.clone(), data, &coarse, &mut warm)?;
                        report.refinements.push(back.iterations);
                        total_iterations += back.iterations;
                        history.extend_from_slice(&back.cost_history);
                        back
                    };
                    held_back = true;
                }
            }
        }
        fit = refit;
        let cost_end = cost_of(&fit.model, data);
        let undone = cost_end > previous_cost * (1.0 + 1e-9);
        if let Some(mut st) = added_step {
            st.accepted &= !undone;
            report.steps.push(st);
        }
        if report.dropped.len() > additions_start {
            let before = report
                .steps
                .last()
                .and_then(|s| s.cost_after)
                .unwrap_or(cost_now);
            let mut st = removal_step(&report.dropped[additions_start..], before, cost_end);
            st.accepted = !undone;
            report.steps.push(st);
        }
        // a round that ends worse than it started (the refit went astray) is undone
        if undone {
            report.dropped.push((
                f64::NAN,
                format!("round {} undone: it raised the cost", round + 1),
            ));
            fit = previous;
            break;
        }
        // additions held back on held-out lines would be proposed again at the same
        // peaks: the structure is final
        if !changed || held_back {
            break;
        }
    }
    // converge fully from the last structure
    let last = iterate_warm(fit.model, data, riv, &mut warm)?;
    report.refinements.push(last.iterations);
    total_iterations += last.iterations;
    history.extend_from_slice(&last.cost_history);
    fit = last;
    fit.iterations = total_iterations;
    fit.cost_history = history;
    // the last refinement's own warnings, plus the structure changes
    for (f, why) in &report.dropped {
        if f.is_finite() {
            fit.messages
                .push(format!("removed mode at {f:.2} Hz: {why}"));
        } else {
            fit.messages
                .push(format!("removed a candidate mode: {why}"));
        }
    }
    for (f, fs) in &report.added {
        fit.messages.push(format!(
            "added mode at {f:.2} Hz from a residual peak (F = {fs:.1})"
        ));
    }
    Ok((fit, report))
}

fn model_first_order(model: &AdditiveModel) -> bool {
    model
        .submodels
        .iter()
        .find(|s| s.kind == SubmodelKind::Mode)
        .is_some_and(|s| matches!(model.domain(), crate::Domain::Continuous) && s.num.len() == 2)
}
