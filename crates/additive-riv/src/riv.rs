//! The refined instrumental-variable estimator: Algorithm 1 (eq. 23) of the wafer-stage
//! paper iterated to convergence, with the weighting of section 4.3 or the
//! maximum-likelihood weighting when the data carry a variance.

use crate::problem::{cost, groups, pack, unpack, Basis, FitData, Layout};
use crate::step::{chord_step, step_keeping, IvMethod, StepFactors, StepInputs, StepSolver};
use crate::{AdditiveModel, RivError};
use frf_data::C64;
use frf_data::{Convergence, Estimator, Fit, FrfDataset, ModelStructure, ProgressSink, Weighting};
use std::time::Instant;

/// Settings of [`AdditiveRiv`].
#[derive(Debug, Clone)]
pub struct RivConfig {
    /// Instrument (eq. 12) or SK (Remark 1). Default: [`IvMethod::Riv`].
    pub method: IvMethod,
    /// Weighting of the criterion (8). Default: [`Weighting::Auto`] (inverse variance
    /// when the data carry `_var`, the maximum-likelihood weighting; eq. (27) otherwise).
    pub weighting: Weighting,
    /// Iteration limit. Default: 50.
    pub max_iterations: usize,
    /// Stop when the relative parameter change of a step is below this. Default: 1e-9.
    pub param_tol: f64,
    /// Stop when the relative cost change stays below this for two steps. Default: 1e-10.
    pub cost_tol: f64,
    /// Stop as [`Convergence::Stalled`] after [`STALL_STEPS`] steps in a row that were
    /// cut to at most [`STALL_STEP_FRACTION`] of the update and each lowered the cost by
    /// less than this, relative. Such steps crawl along a direction that is barely one
    /// of descent (the refined-IV fixed point is not the cost's minimum there: an effect
    /// the model lacks, or a start far off); near the optimum of a model that holds the
    /// data the iterations take full steps and never stall. Default: 1e-6.
    pub stall_tol: f64,
    /// Halve a step (up to 12 times) when it raises the cost; the fixed point is the same
    /// as without. Default: true.
    pub backtracking: bool,
    /// Per-entry elimination or the dense reference solve. Default: structured.
    pub solver: StepSolver,
    /// Near the fixed point, reuse the matrix of the last full step with the current
    /// right-hand side (chord steps, [`crate::step::chord_step`]: the same fixed point
    /// at a fraction of a full step's cost; see [`CHORD_MAX_DRIFT`] and the constants
    /// after it for when). Structured solver only. Default: true.
    pub chord: bool,
    /// Assemble entries on the rayon pool. Default: true.
    pub parallel: bool,
    /// Progress callback (one report per iteration).
    pub progress: ProgressSink,
}

impl Default for RivConfig {
    fn default() -> Self {
        Self {
            method: IvMethod::Riv,
            weighting: Weighting::Auto,
            max_iterations: 50,
            param_tol: 1e-9,
            cost_tol: 1e-10,
            stall_tol: 1e-6,
            backtracking: true,
            solver: StepSolver::Structured,
            chord: true,
            parallel: true,
            progress: ProgressSink::none(),
        }
    }
}

/// The refined-IV refiner: `estimate(&data, start_fit)` iterates Algorithm 1 from the
/// start's model.
#[derive(Debug, Clone, Default)]
pub struct AdditiveRiv {
    /// Settings.
    pub config: RivConfig,
}

impl AdditiveRiv {
    /// A refiner with the given settings.
    pub fn new(config: RivConfig) -> Self {
        Self { config }
    }

    /// Iterates on prepared data (the band and weights already applied).
    pub fn refine(
        &self,
        model: AdditiveModel,
        data: &FitData,
    ) -> Result<Fit<AdditiveModel>, RivError> {
        iterate(model, data, &self.config)
    }
}

impl Estimator for AdditiveRiv {
    type Model = AdditiveModel;
    type Start = Fit<AdditiveModel>;
    type Report = ();
    type Error = RivError;

    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        start: Fit<AdditiveModel>,
    ) -> Result<Fit<AdditiveModel>, RivError> {
        if data.ny() != start.model.ny() || data.nu() != start.model.nu() {
            return Err(RivError::invalid(
                "start model",
                format!("{}x{}", start.model.ny(), start.model.nu()),
                format!("the data are {}x{}", data.ny(), data.nu()),
            ));
        }
        let t0 = Instant::now();
        let fd = FitData::new(data, &self.config.weighting)?;
        let t_prepare = t0.elapsed();
        let mut fit = iterate(start.model, &fd, &self.config)?;
        fit.timings.insert(
            0,
            frf_data::Timing {
                stage: "prepare".into(),
                seconds: t_prepare.as_secs_f64(),
            },
        );
        fit.push_timing("total", t0.elapsed());
        let mut msgs = start.messages;
        msgs.append(&mut fit.messages);
        fit.messages = msgs;
        Ok(fit)
    }
}

fn rel_norm(d: &[f64], x: &[f64]) -> f64 {
    let dn: f64 = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    let xn: f64 = x.iter().map(|v| v * v).sum::<f64>().sqrt();
    if xn == 0.0 {
        dn
    } else {
        dn / xn
    }
}

/// Consecutive stalled steps ([`RivConfig::stall_tol`]) after which the iterations stop.
pub const STALL_STEPS: usize = 3;

/// The largest fraction of the full update a step may have been cut to and still count
/// as stalled ([`RivConfig::stall_tol`]): three halvings.
pub const STALL_STEP_FRACTION: f64 = 0.125;

/// SK steps of the rescue when the refined-IV iterations stop far from the optimum.
pub const SK_RESCUE: usize = 10;

/// A step reuses the matrix of the last full step ([`chord_step`]) while the
/// parameters are within this relative distance of the ones it was formed at (the
/// largest relative change of the poles, numerators, delay or factor parameters, as for
/// [`RivConfig::param_tol`]). On the wafer stage the full steps change the parameters
/// by 0.27, 0.065, 0.009, 2e-4 and 2e-5 relative: the chord takes over from the fourth.
pub const CHORD_MAX_DRIFT: f64 = 1e-2;

/// ... and while no submodel's pole has moved by more than this fraction of its
/// half-bandwidth `|Re p|` (the matrix of a lightly damped mode changes with its pole
/// on that scale, whatever the relative change of the parameters as a whole).
pub const CHORD_MAX_POLE_SHIFT: f64 = 0.1;

/// ... and while the cost has fallen by less than this fraction of its value there: the
/// regressor (eq. 14) holds the residual, and a step that removed most of it changed
/// the matrix whatever the parameters did (on the wafer stage, the step after an added
/// mode lowers the cost by 99.8 % and the chord after it contracts by 0.003 where a
/// full step contracts by 3e-5).
pub const CHORD_MAX_COST_FALL: f64 = 0.1;

/// A chord step that changes the parameters by more than this fraction of the step
/// before it did not contract enough: the next step forms the matrix again. A chord
/// step follows a full step only when that step and the one before it were taken at
/// full length and the last was this fraction of the one before it or less (far from
/// the fixed point, where steps are halved or do not shrink, every step is a full one).
/// On the wafer stage the full steps from the CMIF start shrink by 0.25 and 0.14, the
/// chord steps after them by 0.021 and 0.16.
pub const CHORD_MIN_CONTRACTION: f64 = 0.2;

/// Factors a chord step may hold at most (bytes): above this (large problems, where the
/// per-entry blocks grow with the square of the modes) every step is a full one.
pub const CHORD_MAX_BYTES: usize = 256 << 20;

/// The factors of the last full step of Algorithm 1, with the parameters and method
/// they were formed at, for the chord steps of a later refinement of the same structure
/// ([`iterate_warm`]).
#[derive(Debug, Clone)]
pub struct WarmFactors {
    factors: StepFactors,
    method: IvMethod,
    shared: Vec<f64>,
    eta: Vec<f64>,
    /// Upper pole of each submodel at those parameters.
    poles: Vec<Option<C64>>,
    /// The cost there.
    cost: f64,
}

/// The upper pole of each submodel of `model`.
fn upper_poles(model: &AdditiveModel) -> Vec<Option<C64>> {
    model
        .submodels
        .iter()
        .map(|s| model.upper_pole(s))
        .collect()
}

impl WarmFactors {
    /// The largest move of a submodel's pole from where the factors were formed, in
    /// units of its half-power half-bandwidth `|Re p|` (infinite when a submodel's poles
    /// changed between complex and real).
    fn pole_shift(&self, model: &AdditiveModel) -> f64 {
        let now = upper_poles(model);
        if now.len() != self.poles.len() {
            return f64::INFINITY;
        }
        now.iter()
            .zip(&self.poles)
            .map(|(a, b)| match (a, b) {
                (Some(a), Some(b)) => (a - b).norm() / b.re.abs().max(1e-6 * b.norm()),
                (None, None) => 0.0,
                _ => f64::INFINITY,
            })
            .fold(0.0, f64::max)
    }

    /// The relative distance of the parameters `(shared, eta)` from the ones the factors
    /// were formed at, or `None` when they belong to another structure or method.
    fn drift(
        &self,
        lay: &Layout,
        m: usize,
        method: IvMethod,
        shared: &[f64],
        eta: &[f64],
    ) -> Option<f64> {
        // the same layout means the same lengths of `shared` and `eta`
        if method != self.method || !self.factors.fits(lay, m) {
            return None;
        }
        let ds: Vec<f64> = shared
            .iter()
            .zip(&self.shared)
            .map(|(a, b)| a - b)
            .collect();
        let de: Vec<f64> = eta.iter().zip(&self.eta).map(|(a, b)| a - b).collect();
        Some(relative_change(lay, &ds, shared, &de, eta))
    }
}

/// The relative size of the change `(d_s, d_e)` of the parameters `(shared, eta)`: the
/// largest over the numerators, the denominators, the delay (against 1 us at least) and
/// the factor parameters.
fn relative_change(lay: &Layout, d_s: &[f64], shared: &[f64], d_e: &[f64], eta: &[f64]) -> f64 {
    let mut rel = rel_norm(d_e, eta);
    if lay.n_den > 0 {
        rel = rel.max(rel_norm(&d_s[..lay.n_den], &shared[..lay.n_den]));
    }
    if lay.fit_delay {
        let tau = shared[lay.n_den];
        rel = rel.max(d_s[lay.n_den].abs() / tau.abs().max(1e-6));
    }
    if lay.n_factor > 0 {
        let f0 = lay.n_shared() - lay.n_factor;
        rel = rel.max(rel_norm(&d_s[f0..], &shared[f0..]));
    }
    rel
}

/// The iterations of Algorithm 1 from `model` on `data`.
///
/// Far from the optimum the refined instrument can point uphill, and the iterations
/// then stop with no descent. In that case (with the RIV method) they are restarted
/// from `model` with up to [`SK_RESCUE`] Sanathanan-Koerner iterations (Remark 1: the
/// regressor as its own instrument, robust far away but biased at its fixed point),
/// followed by Algorithm 1 again, whose fixed point is the optimum of (8); the fit's
/// messages say so.
pub fn iterate(
    model: AdditiveModel,
    data: &FitData,
    cfg: &RivConfig,
) -> Result<Fit<AdditiveModel>, RivError> {
    iterate_warm(model, data, cfg, &mut None)
}

/// [`iterate`], starting with the factors of an earlier refinement of the same
/// structure on the same `data` when `warm` holds them and the parameters are close to
/// theirs (its steps are then chord steps until the matrix must be formed again), and
/// leaving the factors of its last full step in `warm`.
pub fn iterate_warm(
    model: AdditiveModel,
    data: &FitData,
    cfg: &RivConfig,
    warm: &mut Option<WarmFactors>,
) -> Result<Fit<AdditiveModel>, RivError> {
    let first = iterate_core(model.clone(), data, cfg, warm)?;
    let stalled =
        matches!(first.convergence, Convergence::Failed { .. }) && cfg.method == IvMethod::Riv;
    if !stalled {
        return Ok(first);
    }
    let sk_cfg = RivConfig {
        method: IvMethod::Sk,
        max_iterations: SK_RESCUE,
        progress: ProgressSink::none(),
        ..cfg.clone()
    };
    *warm = None;
    let sk = iterate_core(model, data, &sk_cfg, &mut None)?;
    let mut second = iterate_core(sk.model, data, cfg, warm)?;
    let c_first = first.final_cost().unwrap_or(f64::INFINITY);
    let c_second = second.final_cost().unwrap_or(f64::INFINITY);
    if c_second > c_first {
        return Ok(first);
    }
    let mut history = first.cost_history.clone();
    history.extend_from_slice(&sk.cost_history);
    history.extend_from_slice(&second.cost_history);
    second.cost_history = history;
    second.iterations += first.iterations + sk.iterations;
    second.messages.insert(
        0,
        format!(
            "the refined-IV iterations stopped far from the optimum ({}); restarted with {} SK \
             iterations, then refined-IV again",
            first.convergence.describe(),
            sk.iterations
        ),
    );
    Ok(second)
}

fn iterate_core(
    mut model: AdditiveModel,
    data: &FitData,
    cfg: &RivConfig,
    warm: &mut Option<WarmFactors>,
) -> Result<Fit<AdditiveModel>, RivError> {
    let t0 = Instant::now();
    if model.ny() != data.ny || model.nu() != data.nu {
        return Err(RivError::invalid(
            "model",
            format!("{}x{}", model.ny(), model.nu()),
            format!("the data are {}x{}", data.ny, data.nu),
        ));
    }
    let lay = Layout::of(&model);
    let m = data.m();
    let n_params = lay.n_total(m);
    if data.observations() <= n_params {
        return Err(RivError::TooFewData {
            observations: data.observations(),
            lines: data.n,
            entries: m,
            parameters: n_params,
        });
    }
    let subs: Vec<(usize, usize)> = model
        .submodels
        .iter()
        .map(|s| (s.num.len(), s.den.len()))
        .collect();
    let (mut shared, mut eta) = pack(&model, &lay);
    let mut basis = Basis::new(&model, &lay, &data.omega);
    let norm = 1.0 / (2.0 * data.n as f64);
    let ng = groups(&model, &lay);
    let mut c = cost(data, &lay, &basis, &eta, None, &ng);
    if !c.is_finite() {
        return Err(RivError::Numerical {
            what: "initial cost".into(),
            why: "not finite (a pole on a data line?)".into(),
        });
    }
    let mut history = vec![c * norm];
    let mut messages = Vec::new();
    let mut convergence = Convergence::MaxIterations {
        limit: cfg.max_iterations,
    };
    let mut iterations = 0;
    let mut small_cost_steps = 0;
    let mut worst_cond: f64 = 1.0;
    let mut non_descent = 0;
    // consecutive stalled steps and their relative cost decrease in total
    let (mut stalled, mut stalled_decrease) = (0, 0.0);
    let method = cfg.method;
    let keep = cfg.chord
        && cfg.solver == StepSolver::Structured
        && StepFactors::bytes(m, lay.n_num, lay.n_shared()) <= CHORD_MAX_BYTES;
    // the relative change of the last step, and whether a chord step may follow it
    let (mut last_rel, mut chord_ok) = (f64::INFINITY, true);
    // whether the last step was taken at full length
    let mut last_full_length = false;
    for it in 1..=cfg.max_iterations {
        iterations = it;
        // a chord step while the parameters are near those of the kept factors; one
        // that is not accepted at its full length gives way to a full step
        let mut chord = keep
            && chord_ok
            && warm.as_ref().is_some_and(|w| {
                w.drift(&lay, m, method, &shared, &eta)
                    .is_some_and(|d| d <= CHORD_MAX_DRIFT)
                    && w.pole_shift(&model) <= CHORD_MAX_POLE_SHIFT
                    && c >= (1.0 - CHORD_MAX_COST_FALL) * w.cost
            });
        let (upd, alpha, accepted) = loop {
            let inputs = StepInputs {
                data,
                lay: &lay,
                subs: &subs,
                basis: &basis,
                eta: &eta,
                method,
                parallel: cfg.parallel,
            };
            let upd = if chord {
                let w = warm.as_ref().expect("checked above");
                chord_step(&inputs, &w.factors)
            } else {
                step_keeping(&inputs, cfg.solver, keep).map(|(u, f)| {
                    *warm = f.map(|factors| WarmFactors {
                        factors,
                        method,
                        shared: shared.clone(),
                        eta: eta.clone(),
                        poles: upper_poles(&model),
                        cost: c,
                    });
                    u
                })
            };
            let upd = match upd {
                Ok(u) => u,
                Err(RivError::Numerical { .. }) if chord => {
                    chord = false;
                    continue;
                }
                Err(e) => break (Err(e), 1.0, None),
            };
            let mut alpha = 1.0;
            let mut accepted = None;
            for _ in 0..=if chord { 0 } else { 12 } {
                let s_new: Vec<f64> = shared
                    .iter()
                    .zip(&upd.d_shared)
                    .map(|(a, d)| a + alpha * d)
                    .collect();
                let e_new: Vec<f64> = eta
                    .iter()
                    .zip(&upd.d_eta)
                    .map(|(a, d)| a + alpha * d)
                    .collect();
                let mut trial = model.clone();
                unpack(&mut trial, &lay, &s_new, &e_new);
                let b_new = Basis::new(&trial, &lay, &data.omega);
                let c_new = cost(data, &lay, &b_new, &e_new, None, &ng);
                let ok = c_new.is_finite() && (!cfg.backtracking || c_new <= c * (1.0 + 1e-10));
                if ok {
                    accepted = Some((s_new, e_new, trial, b_new, c_new));
                    break;
                }
                alpha *= 0.5;
            }
            if chord && accepted.is_none() {
                chord = false;
                continue;
            }
            break (Ok(upd), alpha, accepted);
        };
        let upd = match upd {
            Ok(u) => u,
            Err(RivError::Numerical { what, why }) => {
                convergence = Convergence::Failed {
                    reason: format!("iteration {it}: {what}: {why}"),
                };
                break;
            }
            Err(e) => return Err(e),
        };
        worst_cond = worst_cond.max(upd.cond_shared);
        let (s_new, e_new, trial, b_new, c_new) = match accepted {
            Some(a) => a,
            None => {
                // No halving lowered the cost: the iterate is stationary along the
                // refined-IV direction (converged up to the noise) or the direction is
                // not a descent direction here. Stop rather than take a step that raises
                // the cost; say which.
                non_descent += 1;
                let rel_full = rel_norm(&upd.d_shared, &shared).max(rel_norm(&upd.d_eta, &eta));
                // at the round-off level of the data's energy no step can lower the
                // cost reliably: an exact fit, not a failure
                let exact = c <= crate::residual_stats::EXACT_FIT_REL * data.weighted_energy();
                convergence = if rel_full < 1e-6 || exact {
                    Convergence::CostTolerance {
                        relative_change: 0.0,
                    }
                } else {
                    Convergence::Failed {
                        reason: format!(
                            "iteration {it}: no step along the refined-IV direction (relative size \
                             {rel_full:.1e}) lowers the cost; the start may be too far from the \
                             optimum (try --method sk or fewer modes)"
                        ),
                    }
                };
                break;
            }
        };
        let d_s: Vec<f64> = upd.d_shared.iter().map(|d| alpha * d).collect();
        let d_e: Vec<f64> = upd.d_eta.iter().map(|d| alpha * d).collect();
        let rel = relative_change(&lay, &d_s, &shared, &d_e, &eta);
        // a chord step must contract like the iterations it replaces; otherwise the
        // next step forms the matrix again; and a chord step follows a full one only
        // when the iterations are in their contracting regime (a full-length step
        // smaller than the one before it by that factor)
        chord_ok = rel <= CHORD_MIN_CONTRACTION * last_rel
            && (chord || (alpha == 1.0 && last_full_length && last_rel.is_finite()));
        last_rel = rel;
        last_full_length = alpha == 1.0;
        let rel_cost = (c - c_new).abs() / c.max(f64::MIN_POSITIVE);
        shared = s_new;
        eta = e_new;
        model = trial;
        basis = b_new;
        c = c_new;
        history.push(c * norm);
        cfg.progress.step(
            "riv",
            it,
            Some(cfg.max_iterations),
            Some(c * norm),
            if alpha < 1.0 {
                format!("relative change {rel:.2e} (step {alpha:.3e} of the full update)")
            } else if chord {
                format!("relative change {rel:.2e} (chord step)")
            } else {
                format!("relative change {rel:.2e}")
            },
        );
        if rel < cfg.param_tol {
            convergence = Convergence::ParameterTolerance {
                relative_change: rel,
            };
            break;
        }
        if alpha <= STALL_STEP_FRACTION && rel_cost < cfg.stall_tol {
            stalled += 1;
            stalled_decrease += rel_cost;
            if stalled >= STALL_STEPS {
                convergence = Convergence::Stalled {
                    steps: stalled,
                    relative_decrease: stalled_decrease,
                };
                break;
            }
        } else {
            (stalled, stalled_decrease) = (0, 0.0);
        }
        if rel_cost < cfg.cost_tol {
            small_cost_steps += 1;
            if small_cost_steps >= 2 {
                convergence = Convergence::CostTolerance {
                    relative_change: rel_cost,
                };
                break;
            }
        } else {
            small_cost_steps = 0;
        }
    }
    if non_descent > 0 {
        messages.push(
            "the iterations stopped where no halving of the refined-IV step lowered the cost"
                .to_string(),
        );
    }
    if worst_cond > 1e12 {
        messages.push(format!(
            "the shared denominator system was ill-conditioned (condition ~{worst_cond:.1e}): \
             parameters of close or weakly excited modes are uncertain"
        ));
    }
    let unstable = model.unstable_submodels();
    if !unstable.is_empty() {
        messages.push(format!(
            "submodel(s) {unstable:?} have poles outside the stable region; they are reported \
             as estimated, not reflected"
        ));
    }
    let mut fit = Fit::from_model(
        model,
        match cfg.method {
            IvMethod::Riv => "riv",
            IvMethod::Sk => "sk",
        },
    );
    fit.cost_history = history;
    fit.iterations = iterations;
    fit.convergence = convergence;
    fit.messages = messages;
    fit.push_timing("iterations", t0.elapsed());
    Ok(fit)
}
