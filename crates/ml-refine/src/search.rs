//! The structure steps of one ML refinement ([`crate::MlRefine`]), each a named step
//! apart from the refiner's sequence: the modes added where the residual calls for them
//! ([`add_missed_modes`]), the rigid body chosen again ([`rechoose_integrators`]), a
//! held delay freed ([`free_held_delay`]) and the modes tested again at the final
//! structure ([`retest_modes`]). Each continues the [`Current`] optimum through one
//! [`Setting`], and says what it did in the [`Log`]: in words, and as typed
//! [`StructureStep`]s.

use crate::config::MlConfig;
use crate::lm::{iterate, LmOutcome, LmSettings, Work};
use crate::stats::chi2_upper_tail;
use crate::varpro::{Eval, Layout, Problem};
use crate::C64;
use frf_data::structure::{HeldOutCost, ModeTest, StructureChange, StructureStep};
use realize::FrfModel;
use std::f64::consts::TAU;

/// The fixed setting of one refinement: the settings, the data's size and noise model.
pub(crate) struct Setting<'a> {
    /// The refiner's settings.
    pub cfg: &'a MlConfig,
    /// The iterations' settings (the stop of a gross misfit needs the cost in units of
    /// the noise: only with a measured variance).
    pub lm: LmSettings,
    /// Lines.
    pub n: usize,
    /// Entries.
    pub m: usize,
    /// Whether the weights are the measured variance's.
    pub measured: bool,
    /// The highest line, rad/s.
    pub w_top: f64,
}

impl<'a> Setting<'a> {
    /// The setting of `cfg` on `n` lines of `m` entries.
    pub fn new(cfg: &'a MlConfig, n: usize, m: usize, measured: bool, w_top: f64) -> Self {
        Self {
            cfg,
            lm: LmSettings {
                gross_misfit_ratio: cfg.lm.gross_misfit_ratio.filter(|_| measured),
                ..cfg.lm.clone()
            },
            n,
            m,
            measured,
            w_top,
        }
    }

    /// Complex observations.
    pub fn observations(&self) -> f64 {
        (self.n * self.m) as f64
    }

    /// Complex degrees of freedom left with `n_params` real parameters.
    pub fn dof(&self, n_params: usize) -> f64 {
        self.observations() - n_params as f64 / 2.0
    }

    /// The F statistic ([`nested_f`]) of the smaller structure against the larger.
    pub fn nested_f(&self, small: (f64, usize), large: (f64, usize)) -> f64 {
        nested_f(small, large, self.observations())
    }

    /// Why the parameters `t` of a structure with `np` pairs and `nr` real poles stop
    /// the iterations, if they do: a pole that crossed into the right half-plane, or ran
    /// off beyond 1e4 times the highest line (a constant in the band: the feedthrough's
    /// job); the pole is then dropped (`unstable_drops`).
    pub fn leaving(&self, np: usize, nr: usize) -> impl Fn(&[f64]) -> Option<String> + '_ {
        let w_top = self.w_top;
        move |t: &[f64]| -> Option<String> {
            for q in 0..np {
                if t[2 * q] >= 0.0 {
                    return Some(format!(
                        "the mode at {:.2} Hz crossed into the right half-plane",
                        t[2 * q + 1] / TAU
                    ));
                }
                if t[2 * q + 1] > 1e4 * w_top {
                    return Some(format!(
                        "a mode ran off to {:.3e} Hz (1e4 times the band)",
                        t[2 * q + 1] / TAU
                    ));
                }
            }
            for r in 0..nr {
                let p = t[2 * np + r];
                if p >= 0.0 {
                    return Some(format!(
                        "a real pole crossed into the right half-plane ({p:.3e} rad/s)"
                    ));
                }
                if p < -1e4 * w_top {
                    return Some(format!(
                        "a real pole ran off to {p:.3e} rad/s (1e4 times the band)"
                    ));
                }
            }
            None
        }
    }

    /// One refinement of `p` (structure `l`, `n_params` parameters) from `theta`,
    /// evaluated as `ev`.
    pub fn refine(
        &self,
        p: &Problem,
        theta: Vec<f64>,
        ev: Eval,
        n_params: usize,
        l: &Layout,
    ) -> LmOutcome {
        let np = l.n_pairs;
        let valid =
            move |t: &[f64]| t.iter().all(|x| x.is_finite()) && (0..np).all(|q| t[2 * q + 1] > 0.0);
        iterate(
            p,
            theta,
            ev,
            self.dof(n_params),
            &self.lm,
            valid,
            self.leaving(l.n_pairs, l.n_real),
            &self.cfg.progress,
        )
    }

    /// The cost test of the structure adaptation: with the variance, a cost the noise
    /// does not explain (chi-square p-value below 1e-3) and a ratio `V / N_dof` beyond
    /// `factor` times the expected one (a variance from R realizations alone raises the
    /// ratio to (R-1)/(R-2), 2 for R = 3).
    fn misfit_over(&self, cost: f64, n_params: usize, factor: f64) -> bool {
        let dof = self.dof(n_params);
        self.measured
            && chi2_upper_tail(2.0 * cost, 2.0 * dof) < 1e-3
            && cost / dof > factor * expected_ratio(self.cfg.variance_dof())
    }

    /// A misfit far above the noise (twice the expected ratio): the start holds a free
    /// delay while it lasts.
    pub fn misfit(&self, cost: f64, n_params: usize) -> bool {
        self.misfit_over(cost, n_params, 2.0)
    }

    /// The structure adaptation tries a residual peak from a lower ratio,
    /// [`ADAPT_RATIO`]: the F test of an added mode scales by the residual itself, so a
    /// variance that comes out low (few realizations) costs one refinement that fails
    /// the test, while a model that lacks modes at a higher noise (a random 20 x 20 plant
    /// with 50 modes at 1 % noise, seed 33: three modes missed at a ratio of 1.71) gets
    /// them.
    pub fn lacks_structure(&self, cost: f64, n_params: usize) -> bool {
        self.misfit_over(cost, n_params, ADAPT_RATIO)
    }
}

/// A structure and its optimum: the projected problem, its layout, its real parameter
/// count and the refinement that reached it.
pub(crate) struct Current {
    /// The projected problem of the structure.
    pub prob: Problem,
    /// Its layout.
    pub lay: Layout,
    /// Real parameters (nonlinear and linear).
    pub n_params: usize,
    /// The refinement's outcome at the optimum.
    pub out: LmOutcome,
}

impl Current {
    /// Continues with `next`, a refinement of another structure from this optimum: its
    /// work added to `work`, this one's iterations to its own.
    pub fn continue_with(&mut self, next: Current, work: &mut Work) {
        let iterations = self.out.iterations;
        *work = work.add(next.out.work);
        *self = next;
        self.out.iterations += iterations;
    }
}

/// What a refinement says it did: the messages, in words, and the structure steps,
/// typed (the same changes).
#[derive(Debug, Default)]
pub(crate) struct Log {
    /// Notes for the user.
    pub messages: Vec<String>,
    /// The changes of the structure, in order.
    pub steps: Vec<StructureStep>,
}

impl Log {
    /// Records a change of the structure and says it.
    pub fn step(&mut self, step: StructureStep, message: String) {
        self.steps.push(step);
        self.messages.push(message);
    }
}

/// The cost ratio `V / N_dof`, in units of the expected one, above which the structure
/// adaptation looks for missed modes (with a chi-square p-value below 1e-3).
const ADAPT_RATIO: f64 = 1.2;

/// A further residual peak joins the group of added modes above this fraction of the
/// largest one ([`residual_peaks`]).
const GROUP_PEAK_FRACTION: f64 = 0.05;
/// ... and above this many times the median line's smoothed residual energy.
const GROUP_PEAK_OVER_MEDIAN: f64 = 20.0;
/// Lines either side within which a residual peak must be the largest.
const GROUP_PEAK_HALF_WINDOW: usize = 5;

/// `E{V / N_dof}` with a variance of `d` real degrees of freedom per line
/// ([`MlConfig::variance_dof`]): `d / (d - 2)` (`(R-1)/(R-2)` for `R` realizations), 1
/// when it is taken as exact or `d <= 4`.
pub(crate) fn expected_ratio(variance_dof: Option<f64>) -> f64 {
    match variance_dof {
        Some(d) if d > 4.0 => d / (d - 2.0),
        _ => 1.0,
    }
}

/// The F statistic of the structure tests (a mode added, integrators dropped): the cost
/// the larger structure (`large`: cost, parameters) explains beyond the smaller
/// (`small`), per pair of parameters, over the larger's noise scale `cost / N_dof`, with
/// `observations` complex observations.
fn nested_f(small: (f64, usize), large: (f64, usize), observations: f64) -> f64 {
    let dof = observations - large.1 as f64 / 2.0;
    ((small.0 - large.0) / ((large.1 - small.1) as f64 / 2.0)) / (large.0 / dof)
}

/// Where the residual calls for modes the model lacks, strongest first: the line of the
/// largest (five-line smoothed) weighted residual energy away from the model's modes
/// (within two line spacings of a mode its own misfit is the residual's cause), then,
/// up to `max` in all, the other local maxima of that energy that stand clear of every
/// mode (beyond three half-power bandwidths, where the misfit of a mode no longer
/// reaches), above [`GROUP_PEAK_FRACTION`] of the largest and [`GROUP_PEAK_OVER_MEDIAN`]
/// times the median line: resonances the start missed altogether, which one refinement
/// can add together instead of one refinement each. Frequencies in Hz.
fn residual_peaks(prob: &Problem, theta: &[f64], coef: &[f64], w: &[f64], max: usize) -> Vec<f64> {
    let fm = prob.model(theta, coef);
    let Ok(resp) = fm.freq_response(&prob.omega) else {
        return Vec::new();
    };
    let (n, m) = (prob.omega.len(), prob.lay.m());
    if n == 0 || max == 0 {
        return Vec::new();
    }
    let s: Vec<f64> = (0..n)
        .map(|k| {
            (0..m)
                .map(|e| w[k * m + e] * (prob.g[k * m + e] - resp.values[k * m + e]).norm_sqr())
                .sum()
        })
        .collect();
    let smooth: Vec<f64> = (0..n)
        .map(|k| s[k.saturating_sub(2)..(k + 3).min(n)].iter().sum())
        .collect();
    let dw = (prob.omega[n - 1] - prob.omega[0]) / (n.max(2) - 1) as f64;
    let near = |wk: f64| {
        fm.modal
            .pairs
            .iter()
            .any(|p| (p.omega_n() - wk).abs() <= 2.0 * dw)
    };
    let Some(top) = (0..n)
        .filter(|&k| !near(prob.omega[k]))
        .max_by(|&a, &b| smooth[a].total_cmp(&smooth[b]))
    else {
        return Vec::new();
    };
    let mut peaks = vec![top];
    let clear = |wk: f64| {
        fm.modal.pairs.iter().all(|p| {
            let wn = p.omega_n();
            (wn - wk).abs() > (3.0 * p.zeta().abs() * wn).max(2.0 * dw)
        })
    };
    let mut sorted = smooth.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[n / 2];
    let floor = (GROUP_PEAK_FRACTION * smooth[top]).max(GROUP_PEAK_OVER_MEDIAN * median);
    let half = GROUP_PEAK_HALF_WINDOW.max(n / 400);
    let mut others: Vec<usize> = (0..n)
        .filter(|&k| {
            k != top
                && smooth[k] >= floor
                && (k.saturating_sub(half)..(k + half + 1).min(n)).all(|j| smooth[j] <= smooth[k])
                && clear(prob.omega[k])
        })
        .collect();
    others.sort_by(|&a, &b| smooth[b].total_cmp(&smooth[a]));
    for k in others {
        if peaks.len() >= max {
            break;
        }
        if peaks.iter().all(|&q: &usize| q.abs_diff(k) > half) {
            peaks.push(k);
        }
    }
    peaks.into_iter().map(|k| prob.omega[k] / TAU).collect()
}

/// The added modes' limit: the larger of [`MlConfig::add_modes`] and
/// [`MlConfig::add_modes_fraction`] of the start's `pairs` (rounded up); 0 when
/// `add_modes` is 0.
fn max_added(cfg: &MlConfig, pairs: usize) -> usize {
    if cfg.add_modes == 0 {
        0
    } else {
        // `as` saturates (and takes NaN to 0)
        let scaled = (cfg.add_modes_fraction.max(0.0) * pairs as f64).ceil() as usize;
        cfg.add_modes.max(scaled)
    }
}

/// The structure step of the modes added at `start_hz` to the optimum `cur`, refined as
/// `next`, with the F statistic `f_stat` of the addition against the floor `min_f`.
fn added_step(
    cur: &Current,
    next: &Current,
    start_hz: &[f64],
    f_stat: f64,
    min_f: f64,
    accepted: bool,
) -> StructureStep {
    StructureStep::tested(
        StructureChange::ModesAdded {
            start_hz: start_hz.to_vec(),
        },
        accepted,
        (cur.out.eval.cost, next.out.eval.cost),
        (f_stat, min_f),
    )
}

/// `{sep} held-out cost B -> A (F = ...)` when the held-out test `h` was made.
fn held_out_words(h: Option<HeldOutCost>, sep: &str) -> String {
    h.map_or(String::new(), |h| {
        format!(
            "{sep} held-out cost {:.4e} -> {:.4e} (F = {:.1})",
            h.before,
            h.after,
            h.f_statistic.unwrap_or(f64::NAN)
        )
    })
}

/// The held-out test ([`HeldOutCost`]) of the step from the optimum `before` to the
/// optimum `after` (structures of the same data): the lines split into the even and the
/// odd ones, each structure refined on one half from its optimum (quietly, the same
/// settings) and its weighted cost taken on the other half with its linear parameters
/// as refined (not refitted there), then the halves swapped; the two costs of each
/// structure summed. An added mode that the data hold lowers the error on the lines it
/// was not fitted to; one that follows the noise of the fitted lines raises it. `None`
/// when the band has too few lines to split or a half cannot carry a structure.
fn held_out(s: &Setting, before: &Current, after: &Current) -> Option<HeldOutCost> {
    use rayon::prelude::*;
    let n = s.n;
    if n < 8 {
        return None;
    }
    let lines: [Vec<usize>; 2] = [(0..n).step_by(2).collect(), (1..n).step_by(2).collect()];
    // the halves' data and weights, once: each structure takes them with its layout
    // (`with_layout` shares them)
    let halves = [
        before.prob.on_lines(&lines[0]),
        before.prob.on_lines(&lines[1]),
    ];
    let quiet = MlConfig {
        progress: frf_data::ProgressSink::none(),
        ..s.cfg.clone()
    };
    let jobs = [(0usize, false), (0, true), (1, false), (1, true)];
    let costs: Vec<Option<(bool, f64)>> = jobs
        .par_iter()
        .map(|&(fold, is_after)| {
            let c = if is_after { after } else { before };
            let (fit_on, test_on) = (&halves[fold], &halves[1 - fold]);
            let n_fit = fit_on.n_lines();
            let hs = Setting::new(&quiet, n_fit, s.m, s.measured, s.w_top);
            if 2 * n_fit * s.m <= c.n_params {
                return None;
            }
            let p_fit = fit_on.with_layout(c.lay.clone(), c.prob.template.clone());
            let ev = p_fit.evaluate(&c.out.theta).ok()?;
            let out = hs.refine(&p_fit, c.out.theta.clone(), ev, c.n_params, &c.lay);
            let fm = p_fit.model(&out.theta, &out.eval.coef);
            let cost = test_on.cost_of_model(&fm)?;
            Some((is_after, cost))
        })
        .collect();
    let mut h = HeldOutCost::from_folds(costs)?;
    h.f_statistic = Some(HeldOutCost::f_of(
        h.before,
        h.after,
        after.n_params.saturating_sub(before.n_params),
        s.observations(),
    ));
    Some(h)
}

/// Whether a held-out test `h` (when one was made) lets a structure step pass: its F
/// statistic above `min_f`, the floor of the step's own F test.
fn held_out_passes(h: Option<HeldOutCost>, min_f: f64) -> bool {
    h.is_none_or(|h| h.f_statistic.is_some_and(|f| f > min_f))
}

/// The modes at the frequencies `new_f` (Hz, damping 0.01) added to the optimum `cur`
/// and refined together, with the F statistic of the addition; `None` when the data
/// cannot carry them.
fn with_modes_at(
    s: &Setting,
    cur: &Current,
    model: &FrfModel,
    new_f: &[f64],
) -> Option<(Current, f64)> {
    let (n, m) = (s.n, s.m);
    let mut lay2 = cur.lay.clone();
    lay2.n_pairs += new_f.len();
    let n_params2 = lay2.n_nl() + m * lay2.n_lin();
    if 2 * n < lay2.n_lin() + lay2.n_nl() + 1 || 2 * n * m <= n_params2 {
        return None;
    }
    let np = cur.lay.n_pairs;
    let z0 = 0.01;
    let mut theta2 = cur.out.theta[..2 * np].to_vec();
    for &f in new_f {
        let wn = TAU * f;
        theta2.extend([-z0 * wn, wn * (1.0 - z0 * z0).sqrt()]);
    }
    theta2.extend_from_slice(&cur.out.theta[2 * np..]);
    let prob2 = cur.prob.with_layout(lay2.clone(), model.clone());
    let ev2 = prob2.evaluate(&theta2).ok()?;
    let out2 = s.refine(&prob2, theta2, ev2, n_params2, &lay2);
    let f_stat = s.nested_f(
        (cur.out.eval.cost, cur.n_params),
        (out2.eval.cost, n_params2),
    );
    Some((
        Current {
            prob: prob2,
            lay: lay2,
            n_params: n_params2,
            out: out2,
        },
        f_stat,
    ))
}

/// The structure adaptation: a mode the start missed leaves a resonance in the residual
/// that the cost test rejects ([`Setting::lacks_structure`]); modes are added at its
/// peaks ([`residual_peaks`], `w` the weights per line and entry) and kept when they
/// explain more than noise (F test, floor [`MlConfig::min_f`]), while the refinement
/// converges, up to [`max_added`] of the start's pairs in all. `added` holds the start
/// frequencies of the modes added so far (by the refinements this one restarted from
/// too), and gains this step's.
pub(crate) fn add_missed_modes(
    s: &Setting,
    cur: &mut Current,
    (model, w): (&FrfModel, &[f64]),
    added: &mut Vec<f64>,
    work: &mut Work,
    log: &mut Log,
) {
    let cfg = s.cfg;
    let max_added = max_added(cfg, cur.lay.n_pairs);
    let passes = |o: &LmOutcome, f_stat: f64| {
        !f_stat.is_nan() && f_stat > cfg.min_f && o.convergence.is_converged()
    };
    while added.len() < max_added
        && cur.out.convergence.is_converged()
        && s.lacks_structure(cur.out.eval.cost, cur.n_params)
    {
        let peaks = residual_peaks(
            &cur.prob,
            &cur.out.theta,
            &cur.out.eval.coef,
            w,
            max_added - added.len(),
        );
        if peaks.is_empty() {
            break;
        }
        // several resonances clear of the model's modes: added together first (one
        // refinement instead of one each); when the group does not pass, the strongest
        // alone
        let mut tried = None;
        if peaks.len() > 1 {
            if let Some((next, f_stat)) = with_modes_at(s, cur, model, &peaks) {
                *work = work.add(next.out.work);
                let held = passes(&next.out, f_stat).then(|| held_out(s, cur, &next));
                match held {
                    Some(h) if held_out_passes(h, cfg.min_f) => {
                        tried = Some((peaks.clone(), next, f_stat, h));
                    }
                    _ => {
                        let mut step = added_step(cur, &next, &peaks, f_stat, cfg.min_f, false);
                        step.held_out = held.flatten();
                        log.step(step, format!(
                            "modes added together at {} Hz (the residual's peaks) did not all hold (F = {:.1}, {}{}): the strongest alone is tried",
                            peaks.iter().map(|f| format!("{f:.2}")).collect::<Vec<_>>().join(", "),
                            f_stat,
                            next.out.convergence.describe(),
                            held_out_words(held.flatten(), ",")
                        ));
                    }
                }
            }
        }
        if tried.is_none() {
            let Some((next, f_stat)) = with_modes_at(s, cur, model, &peaks[..1]) else {
                break;
            };
            *work = work.add(next.out.work);
            let held = passes(&next.out, f_stat).then(|| held_out(s, cur, &next));
            let h = match held {
                Some(h) if held_out_passes(h, cfg.min_f) => h,
                _ => {
                    let mut step = added_step(cur, &next, &peaks[..1], f_stat, cfg.min_f, false);
                    step.held_out = held.flatten();
                    log.step(step, if let Some(Some(h)) = held {
                        format!(
                            "a mode added at {:.2} Hz (the residual's peak) explains F = {:.1} on the lines it was fitted to but not on the lines it was not (held-out cost {:.4e} -> {:.4e}, F = {:.2} <= {}): not kept",
                            peaks[0], f_stat, h.before, h.after, h.f_statistic.unwrap_or(f64::NAN), cfg.min_f
                        )
                    } else if next.out.convergence.is_converged() {
                        format!(
                            "a mode added at {:.2} Hz (the residual's peak) did not explain more than noise (F = {:.1}): not kept",
                            peaks[0], f_stat
                        )
                    } else {
                        format!(
                            "a mode added at {:.2} Hz (the residual's peak) did not converge (F = {:.1}, {}): not kept",
                            peaks[0],
                            f_stat,
                            next.out.convergence.describe()
                        )
                    });
                    break;
                }
            };
            tried = Some((peaks[..1].to_vec(), next, f_stat, h));
        }
        let Some((new_f, next, f_stat, h)) = tried else {
            break;
        };
        let mut step = added_step(cur, &next, &new_f, f_stat, cfg.min_f, true);
        step.held_out = h;
        log.step(step, format!(
            "{} added at {} Hz (the residual's {}; the start missed {}): cost {:.4e} -> {:.4e}, F = {f_stat:.1}{}",
            if new_f.len() == 1 { "mode" } else { "modes" },
            new_f.iter().map(|f| format!("{f:.2}")).collect::<Vec<_>>().join(", "),
            if new_f.len() == 1 { "peak" } else { "peaks" },
            if new_f.len() == 1 { "it" } else { "them" },
            cur.out.eval.cost,
            next.out.eval.cost,
            held_out_words(h, ";")
        ));
        added.extend(new_f);
        // the addition's work is counted above
        *cur = next;
    }
}

/// The rigid body chosen again at the optimum ([`MlConfig::prune_integrators`], with a
/// measured variance): all integrators at once first (one refinement), then the
/// highest alone, each by [`drop_integrators`], until one is kept.
pub(crate) fn rechoose_integrators(
    s: &Setting,
    cur: &mut Current,
    model: &FrfModel,
    work: &mut Work,
    log: &mut Log,
) {
    while s.measured
        && s.cfg.prune_integrators
        && cur.lay.n_rigid > 0
        && cur.out.convergence.is_converged()
        && cur.lay.n_pairs + cur.lay.n_real + cur.lay.n_rigid > 1
    {
        let all = if cur.lay.n_rigid > 1 && cur.lay.n_pairs + cur.lay.n_real > 0 {
            drop_integrators(s, cur, 0, model).filter(|step| step.kept.is_some())
        } else {
            None
        };
        let Some(step) = all.or_else(|| drop_integrators(s, cur, cur.lay.n_rigid - 1, model))
        else {
            break;
        };
        log.step(step.step, step.message);
        let Some(next) = step.kept else {
            break;
        };
        cur.continue_with(next, work);
    }
}

/// A delay held while the start was far above the noise level (cost
/// `eval_start_cost`), freed at the adapted structure's optimum `cur` (held at
/// `model`'s value) when its score test passes: the Gauss-Newton decrease of the cost
/// with the delay free, from one Jacobian. A delay that would explain less than
/// [`MlConfig::min_f`] times the noise (the test of the added modes and integrators)
/// stays held instead of being refined in several iterations to an insignificant
/// value. An optimum with a pole leaving the stable region is left as it is (the
/// refiner drops the pole and refines again from that optimum, the delay held again).
pub(crate) fn free_held_delay(
    s: &Setting,
    cur: &mut Current,
    (model, eval_start_cost): (&FrfModel, f64),
    work: &mut Work,
    log: &mut Log,
) {
    if s.leaving(cur.lay.n_pairs, cur.lay.n_real)(&cur.out.theta).is_some() {
        return;
    }
    let lay_f = Layout {
        delay: true,
        ..cur.lay.clone()
    };
    let mut theta_f = cur.out.theta.clone();
    let at = lay_f.delay_index().unwrap_or(theta_f.len());
    theta_f.insert(at, model.factors.delay_s);
    let prob_f = cur.prob.with_layout(lay_f.clone(), model.clone());
    let n_params_f = lay_f.n_nl() + s.m * lay_f.n_lin();
    let score = prob_f.evaluate(&theta_f).ok().map(|ev| {
        let (r, _) = prob_f.jacobian_r(&theta_f, &ev);
        let z2 = crate::lm::linearised_decrease(&r, theta_f.len());
        let linearised = (ev.cost - 0.5 * z2).max(0.0);
        let f_stat = s.nested_f((ev.cost, cur.n_params), (linearised, n_params_f));
        (ev, linearised, f_stat)
    });
    let step = |accepted: bool, cost_after: f64, f_stat: f64| {
        StructureStep::tested(
            StructureChange::DelayFreed {
                held_s: model.factors.delay_s,
            },
            accepted,
            (cur.out.eval.cost, cost_after),
            (f_stat, s.cfg.min_f),
        )
    };
    match score {
        Some((_, linearised, f_stat)) if f_stat.is_nan() || f_stat <= s.cfg.min_f => {
            let step = step(false, linearised, f_stat);
            log.step(step, format!(
                "the delay was held at {:.4} us while the start was far above the noise level (cost {:.4e}), and stays held after the structure adaptation: freed, it would explain {f_stat:.2} times the noise (the linearised decrease at the optimum, F <= {})",
                model.factors.delay_s * 1e6,
                eval_start_cost,
                s.cfg.min_f
            ));
        }
        Some((ev, _, f_stat)) => {
            let out_f = s.refine(&prob_f, theta_f, ev, n_params_f, &lay_f);
            // the score test's F: the refinement's own cost is the step's after-cost
            let step = step(true, out_f.eval.cost, f_stat);
            log.step(step, format!(
                "the delay was held at {:.4} us while the start was far above the noise level (cost {:.4e}), and freed after the structure adaptation: cost {:.4e} -> {:.4e}",
                model.factors.delay_s * 1e6,
                eval_start_cost,
                cur.out.eval.cost,
                out_f.eval.cost
            ));
            cur.continue_with(
                Current {
                    prob: prob_f,
                    lay: lay_f,
                    n_params: n_params_f,
                    out: out_f,
                },
                work,
            );
        }
        None => {}
    }
}

/// The added modes (the last `added.len()` pairs of `cur`), and the modes that share a
/// resonance or are narrower than the line spacing, tested again at the final
/// structure (the delay freed, the integrators chosen again, the later additions in),
/// one [`retest_mode`] at a time, with a measured variance: an addition judged while
/// the delay was held far from its value took up the delay's misfit (simulated
/// wafer-stage plates, seed 4: four modes added at 1000 times the noise, two of them
/// one pole, none of them in the plant), and a start mode it displaced can end as a
/// spike beside the resonance the addition took over. A dropped added mode leaves
/// `added`. Returns the index of the first added pair.
pub(crate) fn retest_modes(
    s: &Setting,
    cur: &mut Current,
    model: &FrfModel,
    added: &mut Vec<f64>,
    work: &mut Work,
    log: &mut Log,
) -> usize {
    let mut first_added = cur.lay.n_pairs - added.len();
    // pairs tested and kept, and whether the refinement without them failed (those are
    // tested again after a later drop: another spurious mode that ran off in that
    // refinement may be the one that went)
    let mut tested: Vec<(usize, bool)> = Vec::new();
    if !s.measured {
        return first_added;
    }
    loop {
        let Some(step) = retest_mode(s, cur, first_added, &tested, model) else {
            break;
        };
        log.step(step.step, step.message);
        let Some(next) = step.dropped else {
            tested.push((step.pair, step.failed));
            continue;
        };
        let q = step.pair;
        if q >= first_added {
            added.remove(q - first_added);
        } else {
            first_added -= 1;
        }
        tested = tested
            .into_iter()
            .filter(|t| !t.1)
            .map(|(k, f)| (if k > q { k - 1 } else { k }, f))
            .collect();
        cur.continue_with(next, work);
    }
    first_added
}

/// One step of the rigid-body re-choice of [`MlConfig::prune_integrators`]: its message,
/// and the refinement without the integrators when they were dropped.
struct IntegratorStep {
    message: String,
    step: StructureStep,
    kept: Option<Current>,
}

/// The integrators `1/s^(keep+1) .. 1/s^k` of the optimum `out` (structure `lay` with
/// `k` integrators and `n_params` parameters, `observations` complex observations)
/// tested by the F test of the mode additions: the cost with them dropped and the poles
/// held (the linear parameters refitted: variable projection) against the optimum's.
/// Below [`MlConfig::min_f`] the refinement continues without them (`refine`, given the
/// parameter count), and they stay dropped when that refinement converges to a cost they
/// do not significantly lower. `None` when they explain more, or the problem without
/// them cannot be evaluated.
fn drop_integrators(
    s: &Setting,
    cur: &Current,
    keep: usize,
    model: &FrfModel,
) -> Option<IntegratorStep> {
    let (prob, out, lay, n_params, cfg) = (&cur.prob, &cur.out, &cur.lay, cur.n_params, s.cfg);
    let k = lay.n_rigid;
    let lay_d = Layout {
        n_rigid: keep,
        ..lay.clone()
    };
    let n_params_d = lay_d.n_nl() + lay.m() * lay_d.n_lin();
    let prob_d = prob.with_layout(lay_d.clone(), model.clone());
    let ev_d = prob_d.evaluate(&out.theta).ok()?;
    let f_of = |cost_d: f64| s.nested_f((cost_d, n_params_d), (out.eval.cost, n_params));
    let f_held = f_of(ev_d.cost);
    if f_held.is_nan() || f_held >= cfg.min_f {
        return None;
    }
    let (what, verb) = if keep + 1 == k {
        (format!("the integrator 1/s^{k}"), "explains")
    } else {
        (
            format!(
                "the integrators {}",
                (keep + 1..=k)
                    .map(|p| format!("1/s^{p}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            "explain",
        )
    };
    let out_d = s.refine(&prob_d, out.theta.clone(), ev_d, n_params_d, &lay_d);
    let f_refined = f_of(out_d.eval.cost);
    let step = |accepted: bool| {
        StructureStep::tested(
            StructureChange::IntegratorsDropped { keep, of: k },
            accepted,
            (out.eval.cost, out_d.eval.cost),
            (f_refined, cfg.min_f),
        )
    };
    if !out_d.convergence.is_converged() || f_refined >= cfg.min_f {
        return Some(IntegratorStep {
            step: step(false),
            message: format!(
                "{what} {verb} {f_held:.2} times the noise per parameter with the poles held (< {}), but the refinement without them {} (F = {f_refined:.2}): kept",
                cfg.min_f,
                if out_d.convergence.is_converged() {
                    "ended higher".to_string()
                } else {
                    out_d.convergence.describe()
                }
            ),
            kept: None,
        });
    }
    Some(IntegratorStep {
        step: step(true),
        message: format!(
            "{what} {verb} {f_held:.2} times the noise per parameter at the optimum (< {}): dropped, cost {:.4e} -> {:.4e} after {} further iterations (F = {f_refined:.2})",
            cfg.min_f,
            out.eval.cost,
            out_d.eval.cost,
            out_d.iterations
        ),
        kept: Some(Current {
            prob: prob_d,
            lay: lay_d,
            n_params: n_params_d,
            out: out_d,
        }),
    })
}

/// One step of the re-test of [`retest_mode`]: its message, the pair tested, and the
/// refinement without it when it was dropped.
struct ModeRetest {
    message: String,
    step: StructureStep,
    pair: usize,
    /// The refinement without the mode did not converge.
    failed: bool,
    dropped: Option<Current>,
}

/// One mode of the optimum `out` (structure `lay`, `n_params` parameters) tested again by
/// the F test of the mode additions: an added one (pairs `first_added..`), or one that
/// shares its resonance with another mode (poles within [`frf_data::twins::TWIN_FRACTION`] of their mean
/// `|Re p|`: a twin) or is narrower than the line spacing around it (half-power
/// bandwidth `2 zeta f`: a spike, which can fit the noise of one or two lines), not among
/// the pairs already `tested` and kept (pair index, and whether that refinement failed).
/// Added modes and twins come first, then the others by the cost they explain with the
/// other poles held (the linear parameters refitted). An added mode, a twin, or another
/// candidate below [`MlConfig::min_f`] with the poles held, is tested by the refinement
/// without it: it is dropped when that refinement converges to a cost the mode does not
/// significantly lower. Two poles that close act together as one pole moved (a double
/// pole's derivative term), so holding the other where the pair put it overstates what
/// one of them explains. An added mode can end beside a mode of the start just beyond
/// the twins' distance and still share its resonance (random 4 x 4 plant, seed 1, 100 us
/// of delay, draw 3 of `cargo xtask calibrate`: a mode added at 1218.63 Hz while the
/// delay was held ended at 1214.71 Hz, zeta 8.1e-4, beside the plant's mode at 1214.90
/// Hz, zeta 2.7e-3: 1.07 mean half-bandwidths apart, and held-pole F far above the
/// floor), so an added mode is never judged with the poles held. `None` when no candidate
/// is left to test.
fn retest_mode(
    s: &Setting,
    cur: &Current,
    first_added: usize,
    tested: &[(usize, bool)],
    model: &FrfModel,
) -> Option<ModeRetest> {
    let (prob, out, lay, n_params, cfg) = (&cur.prob, &cur.out, &cur.lay, cur.n_params, s.cfg);
    if lay.n_pairs + lay.n_real + lay.n_rigid < 2 {
        return None;
    }
    let lay_d = Layout {
        n_pairs: lay.n_pairs - 1,
        ..lay.clone()
    };
    let n_params_d = lay_d.n_nl() + lay.m() * lay_d.n_lin();
    let prob_d = prob.with_layout(lay_d.clone(), model.clone());
    let f_of = |cost_d: f64| s.nested_f((cost_d, n_params_d), (out.eval.cost, n_params));
    let pole = |q: usize| C64::new(out.theta[2 * q], out.theta[2 * q + 1]);
    let twin = |q: usize| {
        (0..lay.n_pairs).filter(|&r| r != q).any(|r| {
            let (a, b) = (pole(q), pole(r));
            frf_data::twins::are_twins(a, b)
        })
    };
    let omega = &prob.omega;
    let narrow = |q: usize| {
        let p = pole(q);
        let k = omega.partition_point(|&w| w < p.norm());
        let spacing = match (k.checked_sub(1), omega.get(k)) {
            (Some(a), Some(&b)) => b - omega[a],
            _ => return false,
        };
        2.0 * p.re.abs() < spacing
    };
    let without = |q: usize| {
        let mut t = out.theta.clone();
        t.drain(2 * q..2 * q + 2);
        t
    };
    // added modes and twins first, then by the cost explained with the other poles held
    let (q, theta_d, ev_d, f_held, suspect) = (0..lay.n_pairs)
        .filter(|&q| !tested.iter().any(|&(k, _)| k == q))
        .filter_map(|q| {
            // an added mode and a twin are tested by the refinement without them
            let suspect = q >= first_added || twin(q);
            if !suspect && !narrow(q) {
                return None;
            }
            let t = without(q);
            let ev = prob_d.evaluate(&t).ok()?;
            let f = f_of(ev.cost);
            (!f.is_nan()).then_some((q, t, ev, f, suspect))
        })
        .min_by(|a, b| b.4.cmp(&a.4).then(a.3.total_cmp(&b.3)))?;
    if f_held >= cfg.min_f && !suspect {
        return None;
    }
    let what = if q >= first_added {
        "the added mode"
    } else if suspect {
        "the mode that shares its resonance with another"
    } else {
        "the mode narrower than the line spacing"
    };
    let f_hz = pole(q).norm() / TAU;
    let out_d = s.refine(&prob_d, theta_d, ev_d, n_params_d, &lay_d);
    let f_refined = f_of(out_d.eval.cost);
    let step = |accepted: bool| {
        StructureStep::tested(
            StructureChange::ModeDropped {
                f_hz,
                zeta: -pole(q).re / pole(q).norm(),
                tested_as: if q >= first_added {
                    ModeTest::Added
                } else if suspect {
                    ModeTest::Twin
                } else {
                    ModeTest::Narrow
                },
            },
            accepted,
            (out.eval.cost, out_d.eval.cost),
            (f_refined, cfg.min_f),
        )
    };
    if !out_d.convergence.is_converged() || f_refined >= cfg.min_f {
        return Some(ModeRetest {
            step: step(false),
            message: format!(
                "{what} at {f_hz:.2} Hz, tested again at the final structure, explains {f_held:.2} times the noise per parameter with the other poles held, and the refinement without it {} (F = {f_refined:.2}): kept",
                if out_d.convergence.is_converged() {
                    "ended higher".to_string()
                } else {
                    out_d.convergence.describe()
                }
            ),
            pair: q,
            failed: !out_d.convergence.is_converged(),
            dropped: None,
        });
    }
    Some(ModeRetest {
        step: step(true),
        message: format!(
            "{what} at {f_hz:.2} Hz, tested again at the final structure, explains {f_held:.2} times the noise per parameter with the other poles held: dropped, cost {:.4e} -> {:.4e} after {} further iterations (F = {f_refined:.2} < {})",
            out.eval.cost,
            out_d.eval.cost,
            out_d.iterations,
            cfg.min_f
        ),
        pair: q,
        failed: false,
        dropped: Some(Current {
            prob: prob_d,
            lay: lay_d,
            n_params: n_params_d,
            out: out_d,
        }),
    })
}
