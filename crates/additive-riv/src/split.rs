//! Repairs of a refined fit that the structure adaptation ([`crate::structure`]) cannot
//! make, because they need a second mode where the residual shows no separate peak:
//!
//! - **Close pairs** ([`split_close_pairs`]): two modes closer than a few half-power
//!   bandwidths show one CMIF peak on the first singular value (the second mode of the
//!   pair sits on a later singular value, under the first one's flank). The CMIF start
//!   of section 3.3 of the wafer-stage paper then gives the pair one mode, whose
//!   refined pole lands between the two with a widened bandwidth. The residual it leaves
//!   is concentrated around that mode (a peak and a phase wiggle on either side), and
//!   lies under the adaptation's test of a peak over its local median (the misfit raises
//!   the local median itself). Here every mode whose neighbourhood holds much more
//!   residual than the band's quiet lines and than the typical mode's neighbourhood (a
//!   broadband misfit raises them all) is tried with a second mode beside it (at the
//!   residual's largest line in the neighbourhood and one half-power half-width on either
//!   side); the poles are settled by Algorithm 1 (eq. 23), and the best trial is kept
//!   when its F test passes and it removes most of the local residual.
//! - **A mode beyond a band edge** ([`add_out_of_band_mode`]): a mode just above the band
//!   (or below it, when there is no rigid body) has no peak in the band, only a tail
//!   that rises towards the edge. The CMIF start cannot place it (its peaks are in the
//!   band) and a constant feedthrough explains the tail's quasi-static part only. A mode
//!   is started beyond the edge, its pole settled with the others, and kept when it
//!   stays beyond the edge (within the adaptation's band margin), passes the F test and
//!   fits better than a feedthrough in its place.
//!
//! Both are significance decisions by the F test of the added parameters
//! ([`crate::significance`]), with the noise scale estimated from the trial's residual.

use crate::problem::FitData;
use crate::residual_stats::{
    cost_of, floor_t, has_duplicate, line_spacing_near, lines_within, pole_of, typical_mean,
    ResidualStats,
};
use crate::riv::{iterate, RivConfig};
use crate::significance::{f_critical, f_statistic, noise_scale};
use crate::{fit_numerators, AdditiveModel, Domain, RivError, SubmodelKind};
use frf_data::{Convergence, ModelStructure, ProgressSink};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Settings of [`split_close_pairs`] and [`add_out_of_band_mode`], with documented
/// defaults.
#[derive(Debug, Clone)]
pub struct SplitConfig {
    /// A mode (or a band edge) is examined when the mean of the per-line residual
    /// statistic in its neighbourhood is at least this factor above the statistic's
    /// lower quintile over the band. Default: 4 (at the noise level the ratio is 1.1 to
    /// 1.5, depending on the number of entries; a merged close pair leaves 10 to 1e4).
    pub min_excess: f64,
    /// A mode is examined only when the mean statistic of its neighbourhood is also at
    /// least this factor above that of the typical (median) mode's neighbourhood: a
    /// broadband misfit (an undeclared delay or lag) raises them all. Default: 4.
    pub over_typical: f64,
    /// At most this many modes tried for a split per call (each trial settles the whole
    /// model). Default: 4.
    pub max_trials: usize,
    /// Neighbourhood of a mode: this many half-power half-widths `zeta f` either side of
    /// it. Default: 4.
    pub window_half_widths: f64,
    /// The neighbourhood spans at least this relative frequency either side. Default:
    /// 0.01.
    pub min_window: f64,
    /// A kept second mode must leave at most this fraction of the neighbourhood's
    /// residual energy. Default: 0.25 (as [`crate::structure::AdaptConfig::max_local_ratio`]).
    pub max_local_ratio: f64,
    /// Significance level of the F tests. Default: 1e-3.
    pub alpha: f64,
    /// Practical-significance floor of the F statistic (see
    /// [`crate::structure::AdaptConfig::min_f`]). Default: 25.
    pub min_f: f64,
    /// At most this many modes split (or out-of-band modes added) per call. Default: 6.
    pub max_changes: usize,
    /// Band edge zone examined for a mode beyond the edge: the lines within this
    /// fraction of the edge frequency. Default: 0.05.
    pub edge_zone: f64,
    /// Start frequencies of an out-of-band mode, as ratios beyond the edge. Default:
    /// 1.03, 1.08, 1.15.
    pub edge_ratios: Vec<f64>,
    /// Start damping of an out-of-band mode. Default: 0.02.
    pub edge_zeta: f64,
    /// How far beyond the band an out-of-band mode may settle (as
    /// [`crate::structure::AdaptConfig::band_margin`], beyond which the adaptation
    /// removes modes). Default: 1.25.
    pub band_margin: f64,
    /// Relative parameter tolerance of the pole settling of a trial. Default: 1e-4.
    pub coarse_tol: f64,
    /// Iteration limit of the pole settling of a trial. Default: 15.
    pub coarse_max_iterations: usize,
    /// A split trial is first settled for this many iterations (a screening); only the
    /// ones that then lower the cost and leave at most [`SplitConfig::screen_local_ratio`]
    /// of the neighbourhood's residual are settled to the coarse tolerance. Default: 4.
    pub screen_iterations: usize,
    /// The neighbourhood residual fraction a screened split trial may leave and still be
    /// settled further. Default: 0.5 (measured: a merged pair's trials leave 0 to 16 %
    /// after the screen and none once settled; on the reference stage with a lag on one
    /// row the trials left 57 to 92 % after the screen, with a lag on one column 40 to
    /// 77 %, and those settled further ended at 35 to 50 %, above the final
    /// [`SplitConfig::max_local_ratio`] of 0.25).
    pub screen_local_ratio: f64,
}

impl Default for SplitConfig {
    fn default() -> Self {
        Self {
            min_excess: 4.0,
            over_typical: 4.0,
            max_trials: 4,
            window_half_widths: 4.0,
            min_window: 0.01,
            max_local_ratio: 0.25,
            alpha: 1e-3,
            min_f: 25.0,
            max_changes: 6,
            edge_zone: 0.05,
            edge_ratios: vec![1.03, 1.08, 1.15],
            edge_zeta: 0.02,
            band_margin: 1.25,
            coarse_tol: 1e-4,
            coarse_max_iterations: 15,
            screen_iterations: 4,
            screen_local_ratio: 0.5,
        }
    }
}

/// A mode split into a close pair.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairSplit {
    /// Frequency of the mode before the split, Hz.
    pub from_hz: f64,
    /// The two modes after settling: (frequency in Hz, damping) each.
    pub into: [(f64, f64); 2],
    /// F statistic of the second mode's parameters.
    pub f_stat: f64,
    /// Weighted cost `sum w |E|^2` before and after the split (the pair settled, before
    /// the final refinement).
    #[serde(default)]
    pub cost: (f64, f64),
}

/// A mode added beyond a band edge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutOfBandMode {
    /// Settled natural frequency, Hz.
    pub f_hz: f64,
    /// Settled damping ratio.
    pub zeta: f64,
    /// `"upper"` or `"lower"`: the edge it lies beyond.
    pub edge: String,
    /// F statistic of its parameters.
    pub f_stat: f64,
    /// Cost of a constant feedthrough in its place (the alternative it beat), relative
    /// to its own cost; `None` when the model has a feedthrough already.
    pub feedthrough_cost_ratio: Option<f64>,
    /// Weighted cost `sum w |E|^2` before and after the addition (the mode settled,
    /// before the final refinement).
    #[serde(default)]
    pub cost: (f64, f64),
}

/// What [`split_close_pairs`] and [`add_out_of_band_mode`] did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RepairReport {
    /// Modes split into close pairs.
    pub splits: Vec<PairSplit>,
    /// Modes added beyond a band edge.
    pub out_of_band: Vec<OutOfBandMode>,
    /// Trials not kept: (frequency in Hz, why).
    pub rejected: Vec<(f64, String)>,
}

impl RepairReport {
    /// True when nothing was changed.
    pub fn is_empty(&self) -> bool {
        self.splits.is_empty() && self.out_of_band.is_empty()
    }
}

/// The tests of a repair trial `t` against `cur` (at cost `v0`): its cost, the F
/// statistic of the cost decrease per added parameter and its critical value, and the
/// residual energy left on the lines `a..b` as a fraction of `e0`.
struct Judged {
    cost: f64,
    f: f64,
    f_critical: f64,
    local: f64,
}

fn judge(
    t: &AdditiveModel,
    cur: &AdditiveModel,
    v0: f64,
    data: &FitData,
    cfg: &SplitConfig,
    (a, b): (usize, usize),
    e0: f64,
) -> Judged {
    let vt = cost_of(t, data);
    let added = t.n_params().saturating_sub(cur.n_params()).max(1);
    let s2 = noise_scale(vt, data, t.n_params());
    Judged {
        cost: vt,
        f: f_statistic(v0 - vt, added, s2),
        f_critical: f_critical(added, cfg.alpha).max(cfg.min_f),
        local: energy(&ResidualStats::new(t, data), a, b) / e0.max(f64::MIN_POSITIVE),
    }
}

fn coarse_config(riv: &RivConfig, cfg: &SplitConfig) -> RivConfig {
    RivConfig {
        param_tol: riv.param_tol.max(cfg.coarse_tol),
        cost_tol: riv.cost_tol.max(cfg.coarse_tol * 1e-2),
        max_iterations: riv.max_iterations.min(cfg.coarse_max_iterations),
        progress: ProgressSink::none(),
        ..riv.clone()
    }
}

/// The raw weighted residual energy `sum w |E|^2` of the lines `a..b`.
fn energy(stats: &ResidualStats, a: usize, b: usize) -> f64 {
    stats.t[a..b].iter().sum::<f64>() * stats.s2 / 2.0
}

fn first_order_numerators(model: &AdditiveModel) -> bool {
    matches!(model.domain(), Domain::Continuous)
        && model
            .submodels
            .iter()
            .find(|s| s.kind == SubmodelKind::Mode)
            .is_some_and(|s| s.num.len() == 2)
}

/// `model` with a mode at `f_hz` (damping `zeta`) added, numerators refitted (eq. 24)
/// and poles settled by Algorithm 1; `None` when the structure is impossible (near the
/// Nyquist frequency of a sampled model), the iterations fail, or more submodels end
/// unstable than `model` has.
fn settled_with_mode(
    model: &AdditiveModel,
    data: &FitData,
    f_hz: f64,
    zeta: f64,
    coarse: &RivConfig,
) -> Option<AdditiveModel> {
    if let Domain::ZohDiscrete { ts } = model.domain() {
        if TAU * f_hz * ts >= 0.95 * std::f64::consts::PI {
            return None;
        }
    }
    let mut m = model.clone();
    m.push_mode(f_hz, zeta.clamp(1e-3, 0.3), first_order_numerators(model))
        .ok()?;
    settle(m, data, coarse)
}

fn settle(mut m: AdditiveModel, data: &FitData, coarse: &RivConfig) -> Option<AdditiveModel> {
    let unstable_before = m.unstable_submodels().len();
    fit_numerators(&mut m, data).ok()?;
    let fit = iterate(m, data, coarse).ok()?;
    if matches!(fit.convergence, Convergence::Failed { .. }) && fit.iterations <= 1 {
        return None;
    }
    // a pole that leaves the stable region fails the trial; one that was unstable
    // before (a mode stretched over a tail the model lacks) may stay so
    if fit.model.unstable_submodels().len() > unstable_before {
        return None;
    }
    cost_of(&fit.model, data).is_finite().then_some(fit.model)
}

/// Continues the settling of a screened trial `t` for the iterations of `rest`, from
/// its numerators and poles as the screening left them (Algorithm 1 carries no other
/// state from one iteration to the next, so this follows the path of an uninterrupted
/// settling); `None` when more submodels end unstable than `unstable_before` or the cost
/// is not finite.
fn resume(
    t: AdditiveModel,
    data: &FitData,
    rest: &RivConfig,
    unstable_before: usize,
) -> Option<AdditiveModel> {
    let m = if rest.max_iterations == 0 {
        t
    } else {
        iterate(t, data, rest).ok()?.model
    };
    if m.unstable_submodels().len() > unstable_before {
        return None;
    }
    cost_of(&m, data).is_finite().then_some(m)
}

/// A mode's neighbourhood: (frequency in Hz, damping, its lines `a..b`, the weighted
/// residual energy there, the mean per-line statistic there).
type Zone = (f64, f64, (usize, usize), f64, f64);

/// Splits modes of a refined `model` that stand for a close pair (see the module
/// documentation): every mode whose neighbourhood (`cfg.window_half_widths` half-power
/// half-widths either side, at least `cfg.min_window` relative) holds a mean residual
/// statistic at least `cfg.min_excess` times the band's lower quintile and
/// `cfg.over_typical` times the typical mode's neighbourhood is tried (at most
/// `cfg.max_trials` modes), the largest local residual energy first, with a second mode
/// at the neighbourhood's largest residual line and one half-width on either side of it
/// (the trials run in parallel). Each trial is screened first: settled for
/// `cfg.screen_iterations` iterations, it continues from there ([`resume`]) to the
/// coarse tolerance only when it lowers the cost and leaves at most `cfg.screen_local_ratio` of the neighbourhood's
/// residual (a broadband misfit that raises a few neighbourhoods, an unmodelled lag on
/// one row say, is not a pair and stops there).
/// The best trial by cost is kept when the cost falls significantly (F test at
/// `cfg.alpha`, at least `cfg.min_f`, noise scale from the trial's residual), no two
/// poles coincide, and the neighbourhood keeps at most `cfg.max_local_ratio` of its
/// residual energy. Returns the model (poles settled at the coarse tolerance of `cfg`
/// when something changed; the caller refines it fully) and the splits.
pub fn split_close_pairs(
    model: AdditiveModel,
    data: &FitData,
    riv: &RivConfig,
    cfg: &SplitConfig,
) -> Result<(AdditiveModel, RepairReport), RivError> {
    let coarse = coarse_config(riv, cfg);
    let mut report = RepairReport::default();
    let mut cur = model;
    // modes already tried (frequency before the trial): not tried again
    let mut tried: Vec<f64> = Vec::new();
    let mut n_tried = 0;
    while report.splits.len() < cfg.max_changes {
        let stats = ResidualStats::new(&cur, data);
        let med = floor_t(&stats);
        if med.is_nan() || med <= 0.0 {
            break;
        }
        let mut cands: Vec<Zone> = (0..cur.submodels.len())
            .filter(|&i| cur.submodels[i].kind == SubmodelKind::Mode)
            .filter_map(|i| {
                let (f, zeta) = pole_of(&cur, i)?;
                if tried.iter().any(|t| (t - f).abs() <= 1e-3 * f) {
                    return None;
                }
                let half = (cfg.window_half_widths * zeta.abs() * f)
                    .max(cfg.min_window * f)
                    .max(3.0 * line_spacing_near(data, f));
                let (a, b) = lines_within(data, f - half, f + half);
                if b - a < 3 {
                    return None;
                }
                let mean = stats.t[a..b].iter().sum::<f64>() / (b - a) as f64;
                Some((f, zeta, (a, b), energy(&stats, a, b), mean))
            })
            .collect();
        // a misfit that raises every mode's neighbourhood alike (a delay, a lag, a
        // hold) is broadband, not a merged pair: a candidate must stand out from the
        // typical neighbourhood as well as from the band's quiet lines
        let typical = typical_mean(cands.iter().map(|c| c.4).collect());
        cands.retain(|c| c.4 >= cfg.min_excess * med && c.4 >= cfg.over_typical * typical);
        if cands.is_empty() || n_tried >= cfg.max_trials {
            break;
        }
        cands.sort_by(|x, y| y.3.total_cmp(&x.3));
        let (f, zeta, (a, b), e0, _) = cands[0];
        tried.push(f);
        n_tried += 1;
        let hw = zeta.abs().max(1e-3) * f;
        // the residual's largest line in the neighbourhood, when off the mode itself
        let kmax = (a..b)
            .max_by(|&x, &y| stats.t[x].total_cmp(&stats.t[y]))
            .unwrap_or(a);
        let fmax = data.omega[kmax] / TAU;
        let mut starts = vec![f - hw, f + hw];
        if (fmax - f).abs() > 0.25 * hw {
            starts.insert(0, fmax);
        }
        let v0 = cost_of(&cur, data);
        let base = &cur;
        // screened: a few iterations first, then the promising trials to the coarse
        // tolerance (most trials on a misfit that is not a pair stop here)
        let screen = RivConfig {
            max_iterations: cfg.screen_iterations.min(coarse.max_iterations),
            ..coarse.clone()
        };
        let unstable_before = cur.unstable_submodels().len();
        // the rest of the coarse settling's iterations
        let rest = RivConfig {
            max_iterations: coarse.max_iterations - screen.max_iterations,
            ..coarse.clone()
        };
        // (start, settled trial, whether it stopped at the screening)
        let trials: Vec<(f64, Option<AdditiveModel>, bool)> = starts
            .par_iter()
            .map(|&fs| {
                let zs = 0.5 * zeta.abs().max(2e-3);
                let Some(t) = settled_with_mode(base, data, fs, zs, &screen) else {
                    return (fs, None, false);
                };
                let j = judge(&t, &cur, v0, data, cfg, (a, b), e0);
                if j.cost < v0 && j.local <= cfg.screen_local_ratio {
                    (fs, resume(t, data, &rest, unstable_before), false)
                } else {
                    (fs, Some(t), true)
                }
            })
            .collect();
        let mut best: Option<(AdditiveModel, f64, f64)> = None;
        for (fs, t, screened) in trials {
            let Some(t) = t else {
                report.rejected.push((
                    fs,
                    format!("split of {f:.2} Hz: the settling failed or left the stable region"),
                ));
                continue;
            };
            if has_duplicate(&t) {
                report.rejected.push((
                    fs,
                    format!("split of {f:.2} Hz: settled on the pole of another mode"),
                ));
                continue;
            }
            let Judged {
                cost: vt,
                f: fstat,
                f_critical: fcrit,
                local,
            } = judge(&t, &cur, v0, data, cfg, (a, b), e0);
            if vt < v0 && fstat > fcrit && local <= cfg.max_local_ratio {
                if best.as_ref().is_none_or(|(_, vb, _)| vt < *vb) {
                    best = Some((t, vt, fstat));
                }
            } else {
                report.rejected.push((
                    fs,
                    format!(
                        "split of {f:.2} Hz: cost {v0:.3e} -> {vt:.3e} (F = {fstat:.1}, needed {fcrit:.1}), {:.0} % of the local residual left{}",
                        100.0 * local,
                        if screened {
                            format!(" after the {} screening iterations", screen.max_iterations)
                        } else {
                            String::new()
                        }
                    ),
                ));
            }
        }
        let Some((t, vt, fstat)) = best else {
            continue;
        };
        // the pair: the two modes of the new model nearest the old one
        let mut near: Vec<(f64, f64)> = (0..t.submodels.len())
            .filter(|&j| t.submodels[j].kind == SubmodelKind::Mode)
            .filter_map(|j| pole_of(&t, j))
            .collect();
        near.sort_by(|x, y| (x.0 - f).abs().total_cmp(&(y.0 - f).abs()));
        if near.len() >= 2 {
            let mut pair = [near[0], near[1]];
            pair.sort_by(|x, y| x.0.total_cmp(&y.0));
            report.splits.push(PairSplit {
                from_hz: f,
                into: pair,
                f_stat: fstat,
                cost: (v0, vt),
            });
        }
        tried.extend(near.iter().take(2).map(|p| p.0));
        cur = t;
    }
    Ok((cur, report))
}

/// Adds a mode beyond a band edge to a refined `model` when the residual at that edge
/// calls for it (see the module documentation): the lines within `cfg.edge_zone`
/// (relative) of the upper edge (and of the lower one when the model has no rigid body:
/// below the band, a mode of a free body is the suspension stiffness) must hold a mean
/// residual statistic at least `cfg.min_excess` times the band's lower quintile. Trials start a
/// mode at `cfg.edge_ratios` beyond the edge with damping `cfg.edge_zeta`, and a constant
/// feedthrough in its place (when the model has none); all are settled by Algorithm 1 in
/// parallel. The best mode trial that settled beyond the edge (within `cfg.band_margin`)
/// is kept when its F test passes and its cost is below the feedthrough's. Returns the
/// model (poles settled at the coarse tolerance when something changed) and the added
/// modes.
pub fn add_out_of_band_mode(
    model: AdditiveModel,
    data: &FitData,
    riv: &RivConfig,
    cfg: &SplitConfig,
) -> Result<(AdditiveModel, RepairReport), RivError> {
    let coarse = coarse_config(riv, cfg);
    let mut report = RepairReport::default();
    let (lo, hi) = data.band_hz;
    let rigid = model.submodels.iter().any(|s| s.integrators > 0);
    let mut edges = vec![("upper", hi)];
    if !rigid && lo > 0.0 {
        edges.push(("lower", lo));
    }
    let mut cur = model;
    for (edge, fe) in edges {
        let stats = ResidualStats::new(&cur, data);
        let med = floor_t(&stats);
        let (a, b) = if edge == "upper" {
            lines_within(data, fe / (1.0 + cfg.edge_zone), fe)
        } else {
            lines_within(data, fe, fe * (1.0 + cfg.edge_zone))
        };
        if b - a < 3 || med.is_nan() || med <= 0.0 {
            continue;
        }
        let mean = stats.t[a..b].iter().sum::<f64>() / (b - a) as f64;
        if mean < cfg.min_excess * med {
            continue;
        }
        let v0 = cost_of(&cur, data);
        let e0 = energy(&stats, a, b);
        let starts: Vec<f64> = cfg
            .edge_ratios
            .iter()
            .map(|r| if edge == "upper" { fe * r } else { fe / r })
            .collect();
        let base = &cur;
        let has_ft = cur.has_feedthrough();
        let (modes, feed) = rayon::join(
            || -> Vec<(f64, Option<AdditiveModel>)> {
                starts
                    .par_iter()
                    .map(|&fs| {
                        (
                            fs,
                            settled_with_mode(base, data, fs, cfg.edge_zeta, &coarse),
                        )
                    })
                    .collect()
            },
            || -> Option<f64> {
                if has_ft {
                    return None;
                }
                let mut m = base.clone();
                m.push_feedthrough().ok()?;
                settle(m, data, &coarse).map(|m| cost_of(&m, data))
            },
        );
        let mut best: Option<(AdditiveModel, f64, f64, f64, f64)> = None;
        for (fs, t) in modes {
            let Some(t) = t else {
                report.rejected.push((
                    fs,
                    format!(
                        "{edge} out-of-band mode: the settling failed or left the stable region"
                    ),
                ));
                continue;
            };
            let n_old = cur.submodels.len();
            let Some((f, zeta)) =
                pole_of(&t, t.submodels.len() - 1).filter(|_| t.submodels.len() > n_old)
            else {
                continue;
            };
            let outside = if edge == "upper" {
                f > hi && f <= hi * cfg.band_margin
            } else {
                f < lo && f >= lo / cfg.band_margin
            };
            if !outside || has_duplicate(&t) {
                report.rejected.push((
                    f,
                    format!("{edge} out-of-band mode: settled at {f:.2} Hz, not beyond the edge within the band margin"),
                ));
                continue;
            }
            let Judged {
                cost: vt,
                f: fstat,
                f_critical: fcrit,
                local,
            } = judge(&t, &cur, v0, data, cfg, (a, b), e0);
            let beats_ft = feed.is_none_or(|vf| vt < vf);
            if vt < v0 && fstat > fcrit && beats_ft {
                if best.as_ref().is_none_or(|(_, vb, ..)| vt < *vb) {
                    best = Some((t, vt, fstat, f, zeta));
                }
            } else {
                report.rejected.push((
                    f,
                    format!(
                        "{edge} out-of-band mode: cost {v0:.3e} -> {vt:.3e} (F = {fstat:.1}, needed {fcrit:.1}; a feedthrough: {}), {:.0} % of the edge residual left",
                        feed.map_or("none tried".to_string(), |v| format!("{v:.3e}")),
                        100.0 * local
                    ),
                ));
            }
        }
        if let Some((t, vt, fstat, f, zeta)) = best {
            report.out_of_band.push(OutOfBandMode {
                f_hz: f,
                zeta,
                edge: edge.to_string(),
                f_stat: fstat,
                feedthrough_cost_ratio: feed.map(|vf| vf / vt),
                cost: (v0, vt),
            });
            cur = t;
        }
    }
    Ok((cur, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::{Frf, Weighting};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A 2 x 3 continuous plant with the given modes (f Hz, zeta, output shape, input
    /// shape) and an optional constant feedthrough, measured at 0.25 Hz lines over
    /// `lo..hi` Hz with complex Gaussian noise of 0.1 % of each value (its variance
    /// attached).
    fn measured(
        modes: &[(f64, f64, [f64; 2], [f64; 3])],
        feedthrough: Option<f64>,
        lo: f64,
        hi: f64,
        seed: u64,
    ) -> Frf {
        let (ny, nu) = (2, 3);
        let mut m = AdditiveModel::new(ny, nu, Domain::Continuous).unwrap();
        for &(f, z, c, b) in modes {
            let i = m.push_mode(f, z, false).unwrap();
            for r in 0..ny {
                for k in 0..nu {
                    m.submodels[i].num[0][(r, k)] = c[r] * b[k];
                }
            }
        }
        if let Some(d) = feedthrough {
            let i = m.push_feedthrough().unwrap();
            for r in 0..ny {
                for k in 0..nu {
                    m.submodels[i].num[0][(r, k)] = d * (1.0 + 0.3 * (r + 2 * k) as f64);
                }
            }
        }
        let n = ((hi - lo) / 0.25) as usize + 1;
        let f: Vec<f64> = (0..n).map(|k| lo + 0.25 * k as f64).collect();
        let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
        let g = m.response_at(&w);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut vals = g.values.clone();
        let mut var = Vec::with_capacity(vals.len());
        for v in vals.iter_mut() {
            let s2 = (1e-3 * v.norm()).powi(2);
            let sd = (s2 / 2.0).sqrt();
            let u1: f64 = rng.random::<f64>().max(1e-300);
            let u2: f64 = rng.random::<f64>();
            let r = (-2.0 * u1.ln()).sqrt();
            *v += frf_data::C64::new(r * (TAU * u2).cos() * sd, r * (TAU * u2).sin() * sd);
            var.push(s2);
        }
        Frf::new(f, ny, nu, vals, Some(var)).unwrap()
    }

    /// The refined fit of `data` from modes at `start` (damping 0.01).
    fn refined(data: &FitData, start: &[f64]) -> AdditiveModel {
        let mut m = AdditiveModel::new(2, 3, Domain::Continuous).unwrap();
        for &f in start {
            m.push_mode(f, 0.01, false).unwrap();
        }
        fit_numerators(&mut m, data).unwrap();
        iterate(m, data, &RivConfig::default()).unwrap().model
    }

    fn freqs(m: &AdditiveModel) -> Vec<f64> {
        let mut f: Vec<f64> = m.modes().iter().map(|x| x.f_hz).collect();
        f.sort_by(|a, b| a.total_cmp(b));
        f
    }

    const A: ([f64; 2], [f64; 3]) = ([1.0, 0.4], [1.0, -0.5, 0.3]);
    const B: ([f64; 2], [f64; 3]) = ([0.3, -1.0], [0.2, 1.0, 0.8]);
    const C: ([f64; 2], [f64; 3]) = ([1.0, 1.0], [-0.7, 0.4, 1.0]);

    /// A close pair 1.2 % apart (400 and 405 Hz, damping 0.008, different shapes) started
    /// as one mode: the refined single mode leaves its residual around itself, and the
    /// split finds both poles.
    #[test]
    fn a_merged_close_pair_is_split() {
        let modes = [
            (150.0, 0.01, A.0, A.1),
            (400.0, 0.008, B.0, B.1),
            (405.0, 0.008, C.0, C.1),
        ];
        let frf = measured(&modes, None, 50.0, 700.0, 1);
        let data = FitData::new(&frf, &Weighting::InverseVariance).unwrap();
        let merged = refined(&data, &[150.0, 402.5]);
        assert_eq!(merged.modes().len(), 2);
        let (m, rep) = split_close_pairs(
            merged,
            &data,
            &RivConfig::default(),
            &SplitConfig::default(),
        )
        .unwrap();
        let m = iterate(m, &data, &RivConfig::default()).unwrap().model;
        let f = freqs(&m);
        assert_eq!(rep.splits.len(), 1, "{rep:?}");
        assert_eq!(f.len(), 3, "{f:?}");
        for (got, want) in f.iter().zip([150.0, 400.0, 405.0]) {
            assert!((got / want - 1.0).abs() < 1e-3, "{f:?}");
        }
        // at the noise level: the weighted cost per observation is about 1
        let v = cost_of(&m, &data) / (data.observations() as f64 / 2.0);
        assert!(v < 1.2, "cost per observation {v}");
    }

    /// A mode 6 % above the band's upper edge (530 Hz, band 20..500 Hz, modes at 150 and
    /// 300 Hz in it): added beyond the edge at its frequency and damping. With a constant
    /// feedthrough instead (no mode beyond the band), no mode is added: the feedthrough
    /// fits better. The edge gate is off here (`min_excess` 0): with two modes and six
    /// entries the in-band modes spread the tail's misfit over the band, and the edge
    /// zone rises only 1.8 times above the band's lower quintile (the wafer stage's
    /// 52 entries and 16 modes leave it concentrated at the edge); the trials and their
    /// tests are what is checked.
    #[test]
    fn a_mode_above_the_band_is_added_and_a_feedthrough_is_not_taken_for_one() {
        let modes = [
            (150.0, 0.01, A.0, A.1),
            (300.0, 0.008, B.0, B.1),
            (530.0, 0.012, C.0, C.1),
        ];
        let frf = measured(&modes, None, 20.0, 500.0, 2);
        let data = FitData::new(&frf, &Weighting::InverseVariance).unwrap();
        let start = refined(&data, &[150.0, 300.0]);
        assert!(start.unstable_submodels().is_empty());
        let cfg = SplitConfig {
            min_excess: 0.0,
            ..SplitConfig::default()
        };
        let (m, rep) = add_out_of_band_mode(start, &data, &RivConfig::default(), &cfg).unwrap();
        assert_eq!(rep.out_of_band.len(), 1, "{rep:?}");
        let o = &rep.out_of_band[0];
        assert_eq!(o.edge, "upper");
        let m = iterate(m, &data, &RivConfig::default()).unwrap().model;
        let last = *m
            .modes()
            .iter()
            .max_by(|a, b| a.f_hz.total_cmp(&b.f_hz))
            .unwrap();
        assert!((last.f_hz / 530.0 - 1.0).abs() < 2e-3, "{last:?}");
        assert!((last.zeta / 0.012 - 1.0).abs() < 0.1, "{last:?}");
        assert!(o.feedthrough_cost_ratio.is_some_and(|r| r > 2.0), "{o:?}");

        let frf = measured(&modes[..2], Some(2e-8), 20.0, 500.0, 3);
        let data = FitData::new(&frf, &Weighting::InverseVariance).unwrap();
        let start = refined(&data, &[150.0, 300.0]);
        let (_, rep) = add_out_of_band_mode(start, &data, &RivConfig::default(), &cfg).unwrap();
        assert!(rep.out_of_band.is_empty(), "{rep:?}");
    }

    /// A fit at the noise level is left alone by both repairs.
    #[test]
    fn a_fit_at_the_noise_level_is_left_alone() {
        let modes = [
            (150.0, 0.01, A.0, A.1),
            (400.0, 0.008, B.0, B.1),
            (405.0, 0.008, C.0, C.1),
        ];
        let frf = measured(&modes, None, 50.0, 700.0, 4);
        let data = FitData::new(&frf, &Weighting::InverseVariance).unwrap();
        let m = refined(&data, &[150.0, 400.0, 405.0]);
        let cfg = SplitConfig::default();
        let (m2, rep) = split_close_pairs(m.clone(), &data, &RivConfig::default(), &cfg).unwrap();
        assert!(rep.is_empty(), "{rep:?}");
        assert_eq!(m2, m);
        let (m3, rep) =
            add_out_of_band_mode(m.clone(), &data, &RivConfig::default(), &cfg).unwrap();
        assert!(rep.is_empty(), "{rep:?}");
        assert_eq!(m3, m);
    }
}
