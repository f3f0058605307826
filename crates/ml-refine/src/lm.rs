//! Levenberg-Marquardt iterations on the variable-projection problem, and the
//! covariance of the nonlinear parameters at the optimum.
//!
//! Each step solves `min ||J d - r||^2 + lambda ||D d||^2` (`D`: the column norms of
//! `J`, Marquardt's scaling) by a QR of `[R; sqrt(lambda) D]`, with `R` the merged
//! factor of [`Problem::jacobian_r`]; a step is taken when it lowers the cost, and
//! `lambda` shrinks after a success and grows after a failure.

use crate::qr::{back_substitute, householder_r};
use crate::varpro::{Eval, Problem, Singular};
use frf_data::{Convergence, ProgressSink};
use std::time::Instant;

/// Stopping rules of the iterations, with documented defaults.
#[derive(Debug, Clone)]
pub struct LmSettings {
    /// Iteration limit. Default: 100.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction. Default:
    /// 1e-12.
    pub cost_tol: f64,
    /// Stop when the scaled step `||D d|| / ||D theta||` is below this. Default: 1e-12.
    pub step_tol: f64,
    /// Stop when the linearised decrease `||Q^T r||^2 / ||r||^2` (the part of the
    /// residual the Jacobian can still explain) is below this. Default: 1e-14.
    pub gradient_tol: f64,
    /// Initial damping (relative to the column scaling). Default: 1e-3.
    pub lambda0: f64,
    /// Stop when the Gauss-Newton step is shorter than this many standard deviations of
    /// the estimates: `sqrt(||Q^T r||^2 / sigma^2)` (the step's length in the metric of
    /// the inverse covariance) with the noise scale `sigma^2 = V / N_dof` from the
    /// residual. What is left then moves no estimate by more than this fraction of its
    /// uncertainty (a step of a tenth of a standard deviation left out adds half a
    /// percent to the variance of an estimate). Default: 0.1.
    pub std_step_tol: f64,
    /// With the cost in units of the noise (a measured variance), above this many times
    /// the degrees of freedom (a residual about 32 times the noise at the default) the
    /// model misses structure, not accuracy: the iterations stop when an accepted step
    /// lowers the cost by less than [`Self::misfit_cost_tol`] (the decreases shrink
    /// geometrically there, by a factor of 3 to 10 per step, so what is left is of that
    /// order). The structure adaptation that follows (added modes) refits every
    /// parameter, so the tail of geometrically shrinking decreases is not worth its
    /// Jacobians (a random 20 x 20
    /// plant with 50 modes, seed 11, whose subspace start merged five: the first
    /// refinement ran 8 more iterations at a cost 8e4 times the degrees of freedom,
    /// each lowering it by 4e-5 to 6e-9 of itself). `None`: no such stop (the
    /// default without a measured variance, where the cost has no noise scale).
    /// Default: `Some(1e3)`.
    pub gross_misfit_ratio: Option<f64>,
    /// The relative cost decrease of [`Self::gross_misfit_ratio`]'s stop. Default: 1e-4.
    pub misfit_cost_tol: f64,
}

impl Default for LmSettings {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            cost_tol: 1e-12,
            step_tol: 1e-12,
            gradient_tol: 1e-14,
            lambda0: 1e-3,
            std_step_tol: 0.1,
            gross_misfit_ratio: Some(1e3),
            misfit_cost_tol: 1e-4,
        }
    }
}

/// The outcome of the iterations.
pub(crate) struct LmOutcome {
    pub theta: Vec<f64>,
    pub eval: Eval,
    pub cost_history: Vec<f64>,
    pub iterations: usize,
    pub convergence: Convergence,
    /// The `R` factor of `[J | r]` at `theta`, `(n + 1)^2` column-major.
    pub r: Vec<f64>,
    /// The norms of the Jacobian's columns before the projection at `theta`.
    pub vnorm: Vec<f64>,
    /// Work done: cost evaluations (trial points) and Jacobian factorisations, with the
    /// time spent in each.
    pub work: Work,
}

/// Evaluations and Jacobian factorisations of one or more runs of [`iterate`], with
/// their times.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Work {
    pub evaluations: usize,
    pub evaluation_time: std::time::Duration,
    pub jacobians: usize,
    pub jacobian_time: std::time::Duration,
}

impl Work {
    /// The sum of two tallies.
    pub fn add(self, o: Work) -> Work {
        Work {
            evaluations: self.evaluations + o.evaluations,
            evaluation_time: self.evaluation_time + o.evaluation_time,
            jacobians: self.jacobians + o.jacobians,
            jacobian_time: self.jacobian_time + o.jacobian_time,
        }
    }
}

/// The relative change of a damped step, in the column scaling, below which a larger
/// damping is taken to leave the step as it was ([`iterate`]): a step that raised the
/// cost by more than [`CLEAR_RISE`] is not evaluated again with a damping that moved
/// it by less than this. On a random 50 x 50 plant with 100 modes (seed 5 of `frfit
/// simulate random-modal --rigid-body --close-pairs 0.2`) the second iteration
/// raised the cost from 1.42e9 to 3.50e9, 3.50e9, 3.50e9, 3.48e9, 3.36e9 and 1.90e9
/// as the damping grew fourfold from 2e-4, before 0.82 lowered it: six evaluations
/// of 0.5 s. The steps at 8e-4 and 3.2e-3 differed from the one at 2e-4 by under 1 %,
/// the one at 1.3e-2 by under 5 %; they are no longer evaluated (the refinement's 14
/// evaluations became 11, the model the same).
const SAME_STEP: f64 = 5e-2;

/// The relative rise of the cost that marks a rejected step as clearly too long (see
/// [`SAME_STEP`]).
const CLEAR_RISE: f64 = 0.1;

/// `||D (a - b)|| / ||D b||` with the column scaling `D` of the damped steps.
fn scaled_change(a: &[f64], b: &[f64], dcol: &[f64]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .zip(dcol)
        .map(|((x, y), d)| (d * (x - y)).powi(2))
        .sum();
    let den: f64 = b.iter().zip(dcol).map(|(y, d)| (d * y).powi(2)).sum();
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

/// `||Q^T r||^2` of the `R` factor `r` of `[J | r]` (`(n + 1)^2`, column-major) with `n`
/// parameters: the decrease of the squared residual norm (twice the cost) that the
/// Gauss-Newton step predicts.
pub(crate) fn linearised_decrease(r: &[f64], n: usize) -> f64 {
    let nb = n + 1;
    (0..n).map(|i| r[n * nb + i] * r[n * nb + i]).sum()
}

/// One damped step: solves `[R; sqrt(lambda) D] d = [z; 0]` in the least-squares sense.
fn damped_step(r: &[f64], n: usize, lambda: f64, dcol: &[f64]) -> Vec<f64> {
    let nb = n + 1;
    let rows = 2 * n;
    let mut a = vec![0.0; rows * nb];
    for c in 0..n {
        for i in 0..=c {
            a[c * rows + i] = r[c * nb + i];
        }
        a[c * rows + n + c] = lambda.sqrt() * dcol[c];
    }
    for i in 0..n {
        a[n * rows + i] = r[n * nb + i];
    }
    householder_r(&mut a, rows, nb);
    let mut d: Vec<f64> = (0..n).map(|i| a[n * rows + i]).collect();
    back_substitute(&a, rows, 0, n, &mut d);
    d
}

/// Column norms of `R` (the column norms of `J`); 1 for a zero column.
pub(crate) fn column_norms(r: &[f64], n: usize) -> Vec<f64> {
    let nb = n + 1;
    (0..n)
        .map(|c| {
            let s: f64 = (0..=c).map(|i| r[c * nb + i] * r[c * nb + i]).sum();
            if s > 0.0 {
                s.sqrt()
            } else {
                1.0
            }
        })
        .collect()
}

/// A cost at or below this fraction of the weighted data energy is an exact fit to
/// rounding (a relative residual of 1e-12): when no step lowers it, the iteration has
/// converged, whatever the linearisation predicts (on noise-free data the prediction is
/// itself rounding noise: random systems ended at a median error of 1e-16 reported as
/// failed, 13 of 600 in a scan of seeds 9800..9999).
const ROUNDING_COST: f64 = 1e-24;

/// Runs the iterations from `theta0` (whose evaluation is `eval0`); `dof` is the number
/// of residual degrees of freedom `N_dof` of the cost (for the step test in standard
/// deviations). `valid` rejects a trial point outside the parameter domain (a pole
/// pair crossing the real axis). `leaving` names a parameter that has left the region
/// where the model means what it says (a pole crossing into the right half-plane, a
/// real pole running off to infinity): the iteration then stops at once with
/// [`Convergence::Failed`] saying so, and the caller decides (it drops the pole).
pub(crate) fn iterate(
    prob: &Problem,
    theta0: Vec<f64>,
    eval0: Eval,
    dof: f64,
    s: &LmSettings,
    valid: impl Fn(&[f64]) -> bool,
    leaving: impl Fn(&[f64]) -> Option<String>,
    progress: &ProgressSink,
) -> LmOutcome {
    let n = theta0.len();
    let mut theta = theta0;
    let mut ev = eval0;
    let mut hist = vec![ev.cost];
    let mut lambda = s.lambda0;
    let mut it = 0;
    let mut conv = Convergence::MaxIterations {
        limit: s.max_iterations,
    };
    let mut work = Work::default();
    // the weighted energy of the data, on the scale of the cost (`sw = sqrt(2 w)`)
    let data_energy: f64 = prob
        .g
        .iter()
        .zip(prob.sw.iter())
        .map(|(g, s)| (s * g.norm()).powi(2))
        .sum::<f64>()
        / 2.0;
    let jacobian = |theta: &[f64], ev: &Eval, work: &mut Work| {
        let t = Instant::now();
        let out = prob.jacobian_r(theta, ev);
        work.jacobians += 1;
        work.jacobian_time += t.elapsed();
        out
    };
    let (mut r, mut vnorm) = jacobian(&theta, &ev, &mut work);
    if n == 0 {
        return LmOutcome {
            theta,
            eval: ev,
            cost_history: hist,
            iterations: 0,
            convergence: Convergence::Direct,
            r,
            vnorm,
            work,
        };
    }
    while it < s.max_iterations {
        let z2 = linearised_decrease(&r, n);
        let r2 = 2.0 * ev.cost;
        if r2 == 0.0 || z2 <= s.gradient_tol * r2 {
            conv = Convergence::CostTolerance {
                relative_change: if r2 > 0.0 { z2 / r2 } else { 0.0 },
            };
            break;
        }
        // the Gauss-Newton step in standard deviations: z2 / sigma^2, sigma^2 = V / N_dof
        let in_std = (z2 * dof / ev.cost).sqrt();
        if dof > 0.0 && in_std < s.std_step_tol {
            conv = Convergence::StepInStandardDeviations { step_std: in_std };
            break;
        }
        let dcol = column_norms(&r, n);
        it += 1;
        let mut accepted = None;
        // the last step of this iteration that raised the cost clearly
        let mut raised: Option<Vec<f64>> = None;
        while lambda < 1e16 {
            let d = damped_step(&r, n, lambda, &dcol);
            if raised
                .as_ref()
                .is_some_and(|prev| scaled_change(&d, prev, &dcol) < SAME_STEP)
            {
                // the damping has not changed the step yet (it acts only once it
                // reaches the scaled curvature of the weak directions): the step
                // would raise the cost as the last one did, so it is not evaluated
                lambda *= 4.0;
                continue;
            }
            let trial: Vec<f64> = theta.iter().zip(&d).map(|(a, b)| a + b).collect();
            if d.iter().all(|x| x.is_finite()) && valid(&trial) {
                let t = Instant::now();
                let e2 = prob.evaluate(&trial);
                work.evaluations += 1;
                work.evaluation_time += t.elapsed();
                if let Ok(e2) = e2 {
                    if e2.cost.is_finite() && e2.cost < ev.cost {
                        accepted = Some((trial, e2, d));
                        break;
                    }
                    if e2.cost.is_finite() && e2.cost > ev.cost * (1.0 + CLEAR_RISE) {
                        raised = Some(d);
                    }
                }
            }
            lambda *= 4.0;
        }
        let Some((trial, e2, d)) = accepted else {
            // no damped step lowers the cost: a stationary point to rounding, or an
            // exact fit (noise-free data) whose cost is rounding noise, where the
            // linearisation's predicted decrease is rounding noise too
            let pred = z2 / r2;
            let at_rounding = ev.cost <= ROUNDING_COST * data_energy;
            conv = if pred < 1e-8 {
                Convergence::CostTolerance {
                    relative_change: pred,
                }
            } else if at_rounding {
                Convergence::CostTolerance {
                    relative_change: ev.cost / data_energy,
                }
            } else {
                Convergence::Failed {
                    reason: format!(
                        "no step lowers the cost although the linearisation predicts a relative decrease of {pred:.2e}"
                    ),
                }
            };
            break;
        };
        let rel = (ev.cost - e2.cost) / ev.cost;
        let num: f64 = d.iter().zip(&dcol).map(|(a, b)| (a * b).powi(2)).sum();
        let den: f64 = theta.iter().zip(&dcol).map(|(a, b)| (a * b).powi(2)).sum();
        let step = (num / den.max(f64::MIN_POSITIVE)).sqrt();
        theta = trial;
        ev = e2;
        hist.push(ev.cost);
        lambda = (lambda / 5.0).max(1e-12);
        if let Some(reason) = leaving(&theta) {
            conv = Convergence::Failed { reason };
            break;
        }
        (r, vnorm) = jacobian(&theta, &ev, &mut work);
        progress.step(
            "ml",
            it,
            Some(s.max_iterations),
            Some(ev.cost),
            "Levenberg-Marquardt",
        );
        if step < s.step_tol {
            conv = Convergence::ParameterTolerance {
                relative_change: step,
            };
            break;
        }
        if rel < s.cost_tol {
            conv = Convergence::CostTolerance {
                relative_change: rel,
            };
            break;
        }
        let gross = s
            .gross_misfit_ratio
            .is_some_and(|ratio| dof > 0.0 && ev.cost > ratio * dof);
        if gross && rel < s.misfit_cost_tol {
            conv = Convergence::CostTolerance {
                relative_change: rel,
            };
            break;
        }
    }
    LmOutcome {
        theta,
        eval: ev,
        cost_history: hist,
        iterations: it,
        convergence: conv,
        r,
        vnorm,
        work,
    }
}

/// The unscaled covariance `(R^T R)^{-1}` of the nonlinear parameters (`R`: the first
/// `n` columns of the merged factor), by an SVD of `R` with its columns scaled by
/// `scale` (the norms of the Jacobian's columns before the projection, so that a
/// parameter the linear terms can imitate shows as a small singular value), with the
/// condition number of the scaled information matrix and the index of the parameter
/// that dominates its weakest direction.
pub(crate) fn covariance(
    r: &[f64],
    n: usize,
    scale: &[f64],
) -> Result<(Vec<f64>, f64, usize), Singular> {
    let nb = n + 1;
    let dcol: Vec<f64> = scale
        .iter()
        .map(|&x| if x > 0.0 { x } else { 1.0 })
        .collect();
    let rs = faer::Mat::from_fn(
        n,
        n,
        |i, j| if i <= j { r[j * nb + i] / dcol[j] } else { 0.0 },
    );
    let svd = rs.thin_svd().map_err(|_| Singular {
        entry: usize::MAX,
        column: 0,
        ratio: 0.0,
    })?;
    let sv: Vec<f64> = (0..n).map(|i| svd.S()[i]).collect();
    let smax = sv.iter().cloned().fold(0.0, f64::max);
    let (imin, smin) =
        sv.iter().cloned().enumerate().fold(
            (0, f64::INFINITY),
            |a, (i, x)| if x < a.1 { (i, x) } else { a },
        );
    let v = svd.V();
    let weakest = (0..n)
        .max_by(|&a, &b| v[(a, imin)].abs().total_cmp(&v[(b, imin)].abs()))
        .unwrap_or(0);
    let cond = if smin > 0.0 {
        (smax / smin).powi(2)
    } else {
        f64::INFINITY
    };
    let mut cov = vec![0.0; n * n];
    if smin > 0.0 {
        for a in 0..n {
            for b in 0..n {
                let mut s = 0.0;
                for k in 0..n {
                    s += v[(a, k)] * v[(b, k)] / (sv[k] * sv[k]);
                }
                cov[b * n + a] = s / (dcol[a] * dcol[b]);
            }
        }
    }
    Ok((cov, cond, weakest))
}
