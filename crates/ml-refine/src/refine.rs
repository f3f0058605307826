//! [`MlRefine`]: the maximum-likelihood refiner of the estimator chain (`--refine ml`).
//!
//! It minimises McKelvey's criterion (23) with the measured (nonparametric) variance as
//! the fixed noise model, `V = sum_k sum_e |G_ke - P_ke(theta)|^2 / var_ke` (the noise
//! scale `lambda` eliminated, see the errata), over the modal parameters of the model
//! currency, by Levenberg-Marquardt on the variable-projection problem
//! ([`crate::varpro`]). Without a variance, it minimises the weighted least-squares
//! criterion with the data set's weighting and estimates the noise scale from the
//! residual (the report says so).
//!
//! At the optimum, the covariance of the poles (and of the delay and dynamics factors)
//! is the inverse Fisher information, `(J^T W J)^{-1}` (McKelvey eq. (31)-(32): the
//! Cramer-Rao bound when the variance is the true one), scaled by the cost ratio
//! `V / N_dof` when the noise scale is estimated from the residual, and by `max(1,
//! V / N_dof)` with a measured variance (a variance estimated from few realizations
//! makes `E{V / N_dof} = (R - 1) / (R - 2)`; model errors raise it too; the bound is
//! never shrunk). The standard deviations of each mode's natural frequency and damping
//! follow by the delta method.

use crate::lm::{covariance, iterate, LmSettings};
use crate::stats::{chi2_upper_tail, normal_upper_tail};
use crate::varpro::{Layout, Problem, ResidueForm};
use crate::MlError;
use crate::C64;
use frf_data::{ChainModel, Convergence, Estimator, Fit, FrfDataset, ProgressSink, Weighting};
use realize::FrfModel;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::time::Instant;

/// How the covariance of the estimates is scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceScale {
    /// With a measured variance: by `max(1, V / N_dof)`; without: by `V / N_dof` (the
    /// noise scale estimated from the residual). The default.
    #[default]
    Auto,
    /// The inverse Fisher information with the weights as inverse variances, unscaled.
    Fisher,
    /// Always by the cost ratio `V / N_dof`.
    CostRatio,
}

/// Settings of [`MlRefine`], with documented defaults.
#[derive(Debug, Clone)]
pub struct MlConfig {
    /// Weighting of the criterion. Default: [`Weighting::Auto`] (inverse variance, the
    /// ML criterion, when the data carry a variance; eq. (27) of the wafer-stage paper
    /// otherwise, with the noise scale from the residual).
    pub weighting: Weighting,
    /// Parametrisation of the residues. Default: [`ResidueForm::Auto`].
    pub residues: ResidueForm,
    /// Fit a feedthrough `D`. Default: `None`, when the start has a nonzero one.
    pub feedthrough: Option<bool>,
    /// Realizations the variance was estimated from, when known: sets the expected cost
    /// ratio `(R - 1) / (R - 2)` of the cost test. Default: `None` (the variance is
    /// taken as exact).
    pub realizations: Option<usize>,
    /// Covariance scaling. Default: [`CovarianceScale::Auto`].
    pub covariance: CovarianceScale,
    /// Iterations and tolerances. Default: [`LmSettings::default`].
    pub lm: LmSettings,
    /// Damping given to a start pole pair outside the open left half-plane (a real pole
    /// is reflected). Default: 0.01.
    pub zeta_unstable: f64,
    /// Largest condition number of the column-scaled information matrix before a
    /// parameter is called not identifiable. Default: 1e13.
    pub max_condition: f64,
    /// Modes the refinement may add where the residual shows a resonance the start
    /// missed (only with a measured variance, while the cost test rejects the model at
    /// 1e-3), at least: the limit is the larger of this and `add_modes_fraction` of the
    /// start's pole pairs. Several resonances clear of the model's modes are added in one
    /// refinement (see the messages). Default: 4; 0 keeps the start's structure.
    pub add_modes: usize,
    /// The limit of the added modes relative to the start's pole pairs (rounded up),
    /// where that is more than `add_modes`: a start misses modes in proportion to its
    /// size (the subspace start of a large plant merges close pairs; a random 20 x 20
    /// plant with 50 modes and a rigid body, seed 11, started from 45 pairs, took 5
    /// additions and reached the noise level, where 4 left a triple cluster at 213 to
    /// 217 Hz with two modes at 33 times the noise). Default: 0.2.
    pub add_modes_fraction: f64,
    /// Smallest F statistic (cost explained per added parameter over the noise scale)
    /// for an added mode to be kept. Default: 25.
    pub min_f: f64,
    /// Times an optimum with unstable poles, or with a pole the data do not determine
    /// (the weakest direction of an information matrix beyond `max_condition`), is
    /// answered by dropping those poles (the start had a pole too many: an initialiser
    /// fitting noise at a high order) and refining again from the optimum without them;
    /// the cost test may then add a mode back where the residual calls for one. The
    /// drops are reported in the messages. A start with more than 30 pole pairs may be
    /// answered this way once per ten of them (a random 20 x 20 plant with 50 modes
    /// over 10..500 Hz on 2000 uniform lines, seed 32 of `frfit simulate random-modal`,
    /// crowds ten modes into 10..15 Hz at 0.245 Hz line spacing: five of its subspace
    /// start's poles there crossed into the right half-plane in turn, and the fourth
    /// drop ended the fit with an error). Default: 3; 0 reports the unstable or
    /// unidentifiable optimum as an error.
    pub unstable_drops: usize,
    /// With a measured variance, drop a start real pole that explains less than
    /// `min_f` times the noise per parameter (see [`MlRefine`]'s messages). Default:
    /// true.
    pub prune_real_poles: bool,
    /// With a measured variance, test the integrators of the rigid body at the optimum
    /// (after the structure adaptation, before a held delay is freed and again after):
    /// when they explain less than `min_f` times the noise per parameter with the poles
    /// held (the F test of the mode additions), all of them at once, else the highest
    /// alone, they are dropped and the refinement continued without them, and the test
    /// repeated. An initialiser whose start stood far above the noise level keeps
    /// integrators that took up part of its misfit (random 20 x 20 plants without a
    /// rigid body: two, of full rank); at the noise level they explain nothing.
    /// Default: true.
    pub prune_integrators: bool,
    /// Progress callback.
    pub progress: ProgressSink,
}

impl Default for MlConfig {
    fn default() -> Self {
        Self {
            weighting: Weighting::Auto,
            residues: ResidueForm::Auto,
            feedthrough: None,
            realizations: None,
            covariance: CovarianceScale::Auto,
            lm: LmSettings::default(),
            zeta_unstable: 0.01,
            max_condition: 1e13,
            add_modes: 4,
            add_modes_fraction: 0.2,
            min_f: 25.0,
            unstable_drops: 3,
            prune_real_poles: true,
            prune_integrators: true,
            progress: ProgressSink::none(),
        }
    }
}

/// Two modes whose poles are closer than this fraction of their mean `|Re p|` (within
/// each other's half-power half-bandwidth) share one resonance: an added mode that
/// shares one is tested again by a refinement without it ([`retest_mode`]).
const TWIN_FRACTION: f64 = 1.0;

/// The imaginary part of a pole pair, relative to its magnitude, at or below which the
/// pair is critically damped (damping above 0.9998): a pair of real poles whose
/// frequency the data cannot identify (the information matrix is singular there); such
/// a pair at the optimum is dropped and the refinement repeated.
const CRITICAL_IM: f64 = 2e-2;

/// The nonlinear start vector of `model` in the order of `lay`: the poles of the pairs
/// (real and imaginary parts), the real poles, the delay, the dynamics coefficients.
fn nonlinear_start(model: &FrfModel, lay: &Layout) -> Vec<f64> {
    let mut theta = Vec::with_capacity(lay.n_nl());
    for p in &model.modal.pairs {
        theta.push(p.pole.re);
        theta.push(p.pole.im);
    }
    theta.extend(model.modal.real_poles.iter().map(|p| p.pole));
    if lay.delay {
        theta.push(model.factors.delay_s);
    }
    for d in &model.factors.dynamics {
        theta.extend_from_slice(&d.den);
        theta.extend_from_slice(&d.num);
    }
    theta
}

/// A mode's natural frequency and damping with their standard deviations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModeUncertainty {
    /// Natural frequency `|p| / 2 pi`, Hz.
    pub f_hz: f64,
    /// Its standard deviation, Hz.
    pub f_hz_std: f64,
    /// Relative damping `-Re p / |p|`.
    pub zeta: f64,
    /// Its standard deviation.
    pub zeta_std: f64,
}

/// What [`MlRefine`] did and found.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MlReport {
    /// The weighting of the criterion.
    pub weighting: String,
    /// `measured variance` (the ML criterion) or `estimated from the residual`.
    pub noise: String,
    /// The residue parametrisation used (`complex` or `constant_numerator`).
    pub residue_form: String,
    /// Real parameters: nonlinear (poles, delay, dynamics) and in all.
    pub n_nonlinear: usize,
    /// Real parameters in all (linear ones included).
    pub n_params: usize,
    /// Real observations (2 per line and entry).
    pub n_observations: usize,
    /// Iterations run.
    pub iterations: usize,
    /// The cost `V` after each iteration (the first is the start's).
    pub cost_history: Vec<f64>,
    /// Whether a tolerance was met.
    pub converged: bool,
    /// Why the iterations stopped, in words.
    pub convergence: String,
    /// The cost at the optimum, `sum w |G - P|^2`.
    pub cost: f64,
    /// Residual degrees of freedom in complex terms, `N_dof = N m - n_params / 2`.
    pub dof: f64,
    /// `V / N_dof`: 1 at the noise level with the true variance (the cost test).
    pub cost_ratio: f64,
    /// Its expected value under the noise model (1, or `(R-1)/(R-2)` with a variance
    /// from `R` realizations).
    pub expected_ratio: f64,
    /// Probability of a cost ratio this large or larger if the model were right and
    /// the variance as assumed (`None` without a measured variance).
    pub p_value: Option<f64>,
    /// The factor the inverse Fisher information was multiplied by.
    pub covariance_scale: f64,
    /// Condition number of the column-scaled information matrix of the nonlinear
    /// parameters.
    pub information_condition: f64,
    /// Per pole pair, in the model's order.
    pub modes: Vec<ModeUncertainty>,
    /// The delay, when it was fitted, seconds.
    pub delay_s: Option<f64>,
    /// Its standard deviation, seconds.
    pub delay_s_std: Option<f64>,
    /// Start frequencies (Hz) of the modes the refinement added.
    #[serde(default)]
    pub added_modes_hz: Vec<f64>,
    /// Cost evaluations (trial points) of all runs of the iterations.
    #[serde(default)]
    pub evaluations: usize,
    /// Jacobian factorisations of all runs of the iterations.
    #[serde(default)]
    pub jacobians: usize,
}

/// The maximum-likelihood refiner (Gauss-Newton / Levenberg-Marquardt with variable
/// projection) of the chain, from any [`ChainModel`]'s currency.
#[derive(Debug, Clone, Default)]
pub struct MlRefine {
    /// Settings.
    pub config: MlConfig,
}

impl MlRefine {
    /// A refiner with the given settings.
    pub fn new(config: MlConfig) -> Self {
        Self { config }
    }
}

fn describe_param(lay: &Layout, theta: &[f64], idx: usize, model: &FrfModel) -> String {
    let np = lay.n_pairs;
    if idx < 2 * np {
        let q = idx / 2;
        let p = C64::new(theta[2 * q], theta[2 * q + 1]);
        return format!(
            "the {} of the mode at {:.3} Hz (damping {:.2e})",
            if idx.is_multiple_of(2) {
                "real part (damping)"
            } else {
                "imaginary part (frequency)"
            },
            p.norm() / TAU,
            -p.re / p.norm()
        );
    }
    let idx = idx - 2 * np;
    if idx < lay.n_real {
        return format!("the real pole at {:.3e} rad/s", theta[2 * np + idx]);
    }
    let mut idx = idx - lay.n_real;
    if lay.delay {
        if idx == 0 {
            return "the delay".into();
        }
        idx -= 1;
    }
    for (k, d) in model.factors.dynamics.iter().enumerate() {
        let n = d.den.len() + d.num.len();
        if idx < n {
            return format!("coefficient {idx} of dynamics factor {k} ({:?})", d.target);
        }
        idx -= n;
    }
    "a parameter".into()
}

/// `E{V / N_dof}` with a variance from `realizations` realizations (`(R-1)/(R-2)`), 1
/// when it is taken as exact.
fn expected_ratio(realizations: Option<usize>) -> f64 {
    match realizations {
        Some(r) if r >= 4 => (r as f64 - 1.0) / (r as f64 - 2.0),
        _ => 1.0,
    }
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

/// The projected problem of a model on the data ([`MlRefine::projected`]).
struct Projected {
    prob: Problem,
    lay: Layout,
    /// The model's nonlinear parameters.
    theta: Vec<f64>,
    /// The linear parameters and the cost at `theta`.
    ev: crate::varpro::Eval,
    weighting: Weighting,
    /// Whether the weights are the measured variance's.
    measured: bool,
    /// Lines.
    n: usize,
    /// Entries.
    m: usize,
    /// Real parameters (nonlinear and linear).
    n_params: usize,
    /// The weights per line and entry (`w`, the problem holds `sqrt(2 w)`).
    w: Vec<f64>,
}

/// The information of the ML criterion at a given estimate ([`MlRefine::information_at`]).
struct Information {
    /// The projected problem at the estimate's structure.
    prob: Problem,
    /// The estimate's nonlinear parameters.
    theta: Vec<f64>,
    /// The linear parameters and cost at `theta`.
    ev: crate::varpro::Eval,
    /// `(R^T R)^{-1}` of the nonlinear parameters, column-major, unscaled.
    cov: Vec<f64>,
    /// Condition number of the scaled information matrix.
    cond: f64,
    cost: f64,
    dof: f64,
    ratio: f64,
    expected: f64,
    p_value: Option<f64>,
    /// The covariance scale ([`MlConfig::covariance`]).
    scale: f64,
    measured: bool,
    weighting_name: String,
    n_params: usize,
    n_observations: usize,
}

impl Estimator for MlRefine {
    type Model = FrfModel;
    type Start = ChainModel;
    type Report = MlReport;
    type Error = MlError;

    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        start: ChainModel,
    ) -> Result<Fit<FrfModel, MlReport>, MlError> {
        self.estimate_from(data, start.model, 0, (Vec::new(), Vec::new()))
    }
}

impl MlRefine {
    /// The parameter layout of `model` under these settings: its poles, rigid body,
    /// feedthrough (fitted when [`MlConfig::feedthrough`] says so or the model has one),
    /// crosstalk, delay (when fitted), dynamics factors, and the residue form
    /// ([`ResidueForm::Auto`]: constant numerators when every residue is imaginary).
    fn layout_of(&self, model: &FrfModel) -> Layout {
        let cfg = &self.config;
        let const_num = match cfg.residues {
            ResidueForm::Complex => false,
            ResidueForm::ConstantNumerator => true,
            ResidueForm::Auto => {
                !model.modal.pairs.is_empty()
                    && model.modal.pairs.iter().all(|p| {
                        let mut mx: f64 = 0.0;
                        let mut re: f64 = 0.0;
                        for j in 0..model.nu() {
                            for i in 0..model.ny() {
                                mx = mx.max(p.residue[(i, j)].norm());
                                re = re.max(p.residue[(i, j)].re.abs());
                            }
                        }
                        re <= 1e-9 * mx
                    })
            }
        };
        let has_d = (0..model.ny())
            .any(|i| (0..model.nu()).any(|j| model.modal.feedthrough[(i, j)] != 0.0));
        Layout {
            ny: model.ny(),
            nu: model.nu(),
            n_pairs: model.modal.pairs.len(),
            n_real: model.modal.real_poles.len(),
            n_rigid: model.modal.rigid.len(),
            feedthrough: cfg.feedthrough.unwrap_or(has_d),
            crosstalk: model.factors.crosstalk.is_some(),
            delay: model.factors.delay_fitted,
            dynamics: model
                .factors
                .dynamics
                .iter()
                .map(|d| (d.den.len(), d.num.len()))
                .collect(),
            const_num,
        }
    }

    /// The projected problem of `model` on `data` under these settings: the weighting
    /// (and whether it is the measured variance's), the layout, the nonlinear parameters
    /// and the linear parameters' fit at them ([`Problem::evaluate`]). `what` names the
    /// model in errors (`model`, `start model`), `at` where it is in the message of a
    /// dependent linear term (` at the start`). Errors: no terms, too few data for the
    /// parameters, a linear term that is a combination of the others.
    fn projected<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: &FrfModel,
        what: &str,
        at: &str,
    ) -> Result<Projected, MlError> {
        let weighting = self.config.weighting.resolve(data);
        let measured = matches!(weighting, Weighting::InverseVariance);
        let w = weighting.weights(data)?;
        let sw: Vec<f64> = w.iter().map(|x| (2.0 * x).sqrt()).collect();
        let lay = self.layout_of(model);
        let (n, m) = (data.n_lines(), lay.m());
        let n_params = lay.n_nl() + m * lay.n_lin();
        if lay.n_lin() == 0 {
            return Err(MlError::invalid(
                what,
                "no terms",
                "the model has no poles, rigid body or feedthrough",
            ));
        }
        if 2 * n < lay.n_lin() + lay.n_nl() + 1 || 2 * n * m <= n_params {
            return Err(MlError::TooFewData {
                observations: 2 * n * m,
                params: n_params,
            });
        }
        let theta = nonlinear_start(model, &lay);
        let prob = Problem::new(
            lay.clone(),
            data.omegas(),
            data.values_vec(),
            sw,
            model.clone(),
        );
        let ev = prob.evaluate(&theta).map_err(|s| MlError::Unidentifiable {
            what: format!(
                "linear term {} of entry ({}, {}){at} (it is a combination of the others to {:.1e})",
                s.column,
                s.entry % lay.ny + 1,
                s.entry / lay.ny + 1,
                s.ratio
            ),
            condition: if s.ratio > 0.0 {
                1.0 / s.ratio
            } else {
                f64::INFINITY
            },
            hint: "drop one of two coinciding poles, or a rigid-body or feedthrough term the band does not show".into(),
        })?;
        Ok(Projected {
            prob,
            lay,
            theta,
            ev,
            weighting,
            measured,
            n,
            m,
            n_params,
            w,
        })
    }

    /// The information of the ML criterion at `model` (see [`MlRefine::uncertainty_at`]):
    /// the projected problem at its poles, the unscaled covariance of the nonlinear
    /// parameters, the cost test and the covariance scale; the same checks and errors.
    fn information_at<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: &FrfModel,
    ) -> Result<Information, MlError> {
        let cfg = &self.config;
        if data.ny() != model.ny() || data.nu() != model.nu() {
            return Err(MlError::invalid(
                "model",
                format!("{}x{}", model.ny(), model.nu()),
                format!("the data are {}x{}", data.ny(), data.nu()),
            ));
        }
        model.validate()?;
        let mut bad: Vec<String> = model
            .modal
            .pairs
            .iter()
            .filter(|p| !(p.pole.re < 0.0 && p.pole.im > 0.0))
            .map(|p| format!("mode at {:.3} Hz with damping {:.3e}", p.f_hz(), p.zeta()))
            .collect();
        bad.extend(
            model
                .modal
                .real_poles
                .iter()
                .filter(|p| p.pole >= 0.0 || p.pole.is_nan())
                .map(|p| format!("real pole at {:.3e} rad/s", p.pole)),
        );
        if !bad.is_empty() {
            return Err(MlError::Unstable {
                poles: bad.join(", "),
                hint: "a covariance is formed at a stable estimate only".into(),
            });
        }
        let Projected {
            prob,
            lay,
            theta,
            ev,
            weighting,
            measured,
            n,
            m,
            n_params,
            w: _,
        } = self.projected(data, model, "model", "")?;
        let (r, vnorm) = prob.jacobian_r(&theta, &ev);
        let dof = (n * m) as f64 - n_params as f64 / 2.0;
        let cost = ev.cost;
        let ratio = cost / dof;
        let (expected, p_value) = cost_test(measured, cfg.realizations, cost, dof);
        let scale = covariance_scale(cfg.covariance, measured, ratio);
        let n_nl = lay.n_nl();
        let (cov, cond, weakest) =
            covariance(&r, n_nl, &vnorm).map_err(|_| MlError::Unidentifiable {
                what: "the information matrix could not be factorised".into(),
                condition: f64::INFINITY,
                hint: "check the data for non-finite values".into(),
            })?;
        if n_nl > 0 && (cond.is_nan() || cond > cfg.max_condition) {
            return Err(MlError::Unidentifiable {
                what: describe_param(&lay, &theta, weakest, model),
                condition: cond,
                hint: "the estimate has a parameter the data do not determine: no covariance"
                    .into(),
            });
        }
        Ok(Information {
            prob,
            theta,
            ev,
            cov,
            cond,
            cost,
            dof,
            ratio,
            expected,
            p_value,
            scale,
            measured,
            weighting_name: weighting.name().to_string(),
            n_params,
            n_observations: 2 * n * m,
        })
    }

    /// The covariance of the maximum-likelihood criterion at a given estimate: the
    /// inverse Fisher information `(J^T W J)^{-1}` at `model`'s poles (McKelvey eq.
    /// (31)-(32)), scaled as [`MlConfig::covariance`] says, with no iterations and no
    /// change of structure. The linear parameters (residues, rigid body, feedthrough) are
    /// eliminated by the variable projection as in the refinement (their optimum for
    /// the given poles), so the cost reported is that of the projected problem.
    ///
    /// This is the asymptotic covariance of any consistent estimator that reaches the
    /// ML optimum to first order: the refined instrumental-variable estimate with the
    /// noise's variance as its weighting is one (Pintelon and Schoukens, *System
    /// Identification: A Frequency Domain Approach*, 2nd ed., the asymptotic
    /// efficiency of the refined IV estimator), so the chains without an ML link report
    /// their standard deviations through it. At an estimate away from the ML optimum
    /// (a model with an effect missing) it is a linearisation at that estimate, and the
    /// cost test's `max(1, V / N_dof)` scale widens it.
    ///
    /// Errors: an unstable pole or a pair on the real axis ([`MlError::Unstable`]), a
    /// parameter the data do not determine ([`MlError::Unidentifiable`]), too few
    /// data for the parameters.
    pub fn uncertainty_at<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: &FrfModel,
    ) -> Result<MlReport, MlError> {
        let Information {
            prob,
            theta,
            ev: _,
            cov,
            cond,
            cost,
            dof,
            ratio,
            expected,
            p_value,
            scale,
            measured,
            weighting_name,
            n_params,
            n_observations,
        } = self.information_at(data, model)?;
        let lay = &prob.lay;
        let n_nl = lay.n_nl();
        let c = |a: usize, b: usize| cov[b * n_nl + a] * scale;
        let modes = mode_uncertainties(&theta, lay.n_pairs, &c);
        let mut messages = Vec::new();
        let (delay_s, delay_s_std) = match lay.delay_index() {
            Some(i) => {
                let fisher = c(i, i).max(0.0).sqrt();
                let (std, _) = delay_std(&prob, &theta, i, (cost, scale), fisher, &mut messages);
                (Some(theta[i]), Some(std))
            }
            None => (None, None),
        };
        Ok(MlReport {
            weighting: weighting_name,
            noise: if measured {
                "measured variance".into()
            } else {
                "estimated from the residual".into()
            },
            residue_form: if lay.const_num {
                "constant_numerator".into()
            } else {
                "complex".into()
            },
            n_nonlinear: n_nl,
            n_params,
            n_observations,
            iterations: 0,
            cost_history: vec![cost],
            converged: false,
            convergence: format!(
                "not iterated: the information at the given estimate{}",
                if messages.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", messages.join("; "))
                }
            ),
            cost,
            dof,
            cost_ratio: ratio,
            expected_ratio: expected,
            p_value,
            covariance_scale: scale,
            information_condition: cond,
            modes,
            delay_s,
            delay_s_std,
            added_modes_hz: Vec::new(),
            evaluations: 1,
            jacobians: 1,
        })
    }

    /// The standard deviation of `model`'s response at every line of `data` and entry
    /// (layout `[k * m + e]` as [`FrfDataset::values`]), `sqrt(E |P - E P|^2)` to first
    /// order, from the same information and scale as [`MlRefine::uncertainty_at`]: the
    /// poles' covariance through the projected Jacobian plus the leverage of each
    /// entry's linear fit ([`crate::varpro::Problem::response_variance`]). It is what
    /// the data's noise leaves uncertain in the model's response (the band on the
    /// report's Bode and entry plots), not the model's error against a truth it misses.
    /// Only the entries in `entries` (`e = j * ny + i`) are computed, all with `None`;
    /// the others are NaN (at 20 x 20 entries and 50 modes all of them cost 9.7 s, a
    /// report shows 48). Same errors as `uncertainty_at`.
    pub fn response_std_at<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: &FrfModel,
        entries: Option<&[usize]>,
    ) -> Result<Vec<f64>, MlError> {
        let info = self.information_at(data, model)?;
        let var = info
            .prob
            .response_variance(&info.theta, &info.ev, &info.cov, entries);
        Ok(var
            .into_iter()
            // NaN (an entry not asked for) stays NaN: `max` would make it 0
            .map(|v| {
                if v.is_nan() {
                    v
                } else {
                    (v * info.scale).max(0.0).sqrt()
                }
            })
            .collect())
    }

    /// [`Estimator::estimate`] from `model`, after `drops` refinements that ended
    /// unstable (see [`MlConfig::unstable_drops`]) whose messages are `carried`; the
    /// last `added_before.len()` pole pairs of `model` are modes an earlier refinement
    /// added (their start frequencies): they count against the limit of additions and
    /// are tested again at the final structure like the modes this refinement adds.
    fn estimate_from<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: FrfModel,
        drops: usize,
        (carried, added_before): (Vec<String>, Vec<f64>),
    ) -> Result<Fit<FrfModel, MlReport>, MlError> {
        let t0 = Instant::now();
        let cfg = &self.config;
        let mut model = model;
        if data.ny() != model.ny() || data.nu() != model.nu() {
            return Err(MlError::invalid(
                "start model",
                format!("{}x{}", model.ny(), model.nu()),
                format!("the data are {}x{}", data.ny(), data.nu()),
            ));
        }
        model.validate()?;
        let mut messages = carried;
        // the start: stable poles, pairs above the real axis
        for p in &mut model.modal.pairs {
            if p.pole.im.is_nan() || p.pole.im <= 0.0 {
                return Err(MlError::invalid(
                    "start pole pair",
                    p.pole,
                    "the pole of a pair must have a positive imaginary part",
                ));
            }
            if p.pole.re >= 0.0 {
                let wn = p.pole.norm();
                let z = cfg.zeta_unstable;
                messages.push(format!(
                    "start mode at {:.2} Hz has damping {:.3e} (not stable): started with damping {z}",
                    wn / TAU,
                    -p.pole.re / wn
                ));
                p.pole = C64::new(-z * wn, wn * (1.0 - z * z).sqrt());
            }
        }
        for p in &mut model.modal.real_poles {
            if p.pole >= 0.0 {
                messages.push(format!(
                    "start real pole at {:.3e} rad/s is not stable: reflected",
                    p.pole
                ));
                p.pole = -p.pole.abs().max(1e-9);
            }
        }
        let Projected {
            prob,
            lay,
            theta,
            ev: eval0,
            weighting,
            measured,
            n,
            m,
            n_params,
            w,
        } = self.projected(data, &model, "start model", " at the start")?;
        let const_num = lay.const_num;
        if measured && cfg.prune_real_poles && !model.modal.real_poles.is_empty() {
            // a start real pole that explains less than `min_f` times the noise per
            // parameter (the residues of every entry and the pole) is dropped before the
            // iterations: an initialiser at a high order fits noise with real poles,
            // which the iterations then push unstable or off to infinity
            let mut weakest: Option<(usize, f64)> = None;
            for r in 0..model.modal.real_poles.len() {
                let mut m2 = model.clone();
                m2.modal.real_poles.remove(r);
                let lay2 = Layout {
                    n_real: lay.n_real - 1,
                    ..lay.clone()
                };
                let p2 = prob.with_layout(lay2.clone(), m2.clone());
                if let Ok(ev2) = p2.evaluate(&nonlinear_start(&m2, &lay2)) {
                    let f = (ev2.cost - eval0.cost) / (lay.m() + 1) as f64;
                    if weakest.is_none_or(|(_, fw)| f < fw) {
                        weakest = Some((r, f));
                    }
                }
            }
            if let Some((r, f)) = weakest.filter(|(_, f)| *f < cfg.min_f) {
                let pole = model.modal.real_poles[r].pole;
                let mut m2 = model.clone();
                m2.modal.real_poles.remove(r);
                if m2.modal.pairs.len() + m2.modal.real_poles.len() + m2.modal.rigid.len() > 0 {
                    messages.push(format!(
                            "start real pole at {pole:.3e} rad/s explains {f:.2} times the noise per parameter (< {}): dropped before the iterations",
                            cfg.min_f
                        ));
                    return self.estimate_from(data, m2, drops, (messages, added_before));
                }
            }
        }
        let valid = |np: usize| {
            move |t: &[f64]| t.iter().all(|x| x.is_finite()) && (0..np).all(|q| t[2 * q + 1] > 0.0)
        };
        // a pole that crosses into the right half-plane, or a real pole beyond 1e4 times
        // the highest line (a constant in the band: the feedthrough's job), stops the
        // iterations; the pole is then dropped (`unstable_drops`)
        let w_top = data.omegas().iter().cloned().fold(0.0f64, f64::max);
        let leaving = |np: usize, nr: usize| {
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
        };
        // the cost test of the structure adaptation: with the variance, a cost the noise
        // does not explain (a variance from R realizations alone raises the ratio to
        // (R-1)/(R-2), 2 for R = 3: only a ratio beyond twice the expected one counts)
        let misfit_over = |cost: f64, n_params: usize, factor: f64| {
            let dof = (n * m) as f64 - n_params as f64 / 2.0;
            measured
                && chi2_upper_tail(2.0 * cost, 2.0 * dof) < 1e-3
                && cost / dof > factor * expected_ratio(cfg.realizations)
        };
        let misfit = |cost: f64, n_params: usize| misfit_over(cost, n_params, 2.0);
        // the structure adaptation tries a residual peak from a lower ratio: the F test
        // of an added mode scales by the residual itself, so a variance that comes out
        // low (few realizations) costs one refinement that fails the test, while a
        // model that lacks modes at a higher noise (a random 20 x 20 plant with 50 modes
        // at 1 % noise, seed 33: three modes missed at a ratio of 1.71) gets them
        let lacks_structure = |cost: f64, n_params: usize| misfit_over(cost, n_params, ADAPT_RATIO);
        // the stop of a gross misfit needs the cost in units of the noise: a measured
        // variance
        let lm = LmSettings {
            gross_misfit_ratio: cfg.lm.gross_misfit_ratio.filter(|_| measured),
            ..cfg.lm.clone()
        };
        // one refinement of `p` (structure `l`, `n_params` parameters) from `theta`,
        // evaluated as `ev`
        let refine = |p: &Problem, theta: Vec<f64>, ev, n_params: usize, l: &Layout| {
            iterate(
                p,
                theta,
                ev,
                (n * m) as f64 - n_params as f64 / 2.0,
                &lm,
                valid(l.n_pairs),
                leaving(l.n_pairs, l.n_real),
                &cfg.progress,
            )
        };
        // A free delay is held at the start's value while the start is far above the
        // noise level, through the iterations and the structure adaptation, and freed
        // after them when its score test passes: the delay otherwise absorbs the misfit
        // of the modes the start missed and settles where the added modes no longer fit
        // (a random 20 x 20 plant with 50 modes and no delay, seed 7: a 29 us delay, 49
        // modes, 1900 times the noise; with the delay held, every mode and the noise
        // level).
        let eval_start_cost = eval0.cost;
        let (prob, theta, eval0, lay, n_params, held_delay) =
            if lay.delay && misfit(eval0.cost, n_params) {
                let lay_h = Layout {
                    delay: false,
                    ..lay.clone()
                };
                let theta_h = nonlinear_start(&model, &lay_h);
                let prob_h = prob.with_layout(lay_h.clone(), model.clone());
                match prob_h.evaluate(&theta_h) {
                    Ok(ev) => {
                        let np = lay_h.n_nl() + m * lay_h.n_lin();
                        (prob_h, theta_h, ev, lay_h, np, true)
                    }
                    Err(_) => (prob, theta, eval0, lay, n_params, false),
                }
            } else {
                (prob, theta, eval0, lay, n_params, false)
            };
        let t_iter = Instant::now();
        let mut out = refine(&prob, theta, eval0, n_params, &lay);
        let mut work = out.work;
        let mut prob = prob;
        let mut lay = lay;
        let mut n_params = n_params;
        let mut added = added_before;
        // structure adaptation: a mode the start missed leaves a resonance in the residual
        // that the cost test rejects; add a mode at its peak and keep it when it explains
        // more than noise (F test, floor `min_f`)
        let max_added = if cfg.add_modes == 0 {
            0
        } else {
            // `as` saturates (and takes NaN to 0)
            let scaled = (cfg.add_modes_fraction.max(0.0) * lay.n_pairs as f64).ceil() as usize;
            cfg.add_modes.max(scaled)
        };
        while added.len() < max_added
            && out.convergence.is_converged()
            && lacks_structure(out.eval.cost, n_params)
        {
            let peaks = residual_peaks(
                &prob,
                &out.theta,
                &out.eval.coef,
                &w,
                max_added - added.len(),
            );
            if peaks.is_empty() {
                break;
            }
            // the modes at the given peaks added to the current optimum and refined
            // together; `None` when the data cannot carry them
            let refine_with = |new_f: &[f64]| {
                let mut lay2 = lay.clone();
                lay2.n_pairs += new_f.len();
                let n_params2 = lay2.n_nl() + m * lay2.n_lin();
                if 2 * n < lay2.n_lin() + lay2.n_nl() + 1 || 2 * n * m <= n_params2 {
                    return None;
                }
                let np = lay.n_pairs;
                let z0 = 0.01;
                let mut theta2 = out.theta[..2 * np].to_vec();
                for &f in new_f {
                    let wn = TAU * f;
                    theta2.extend([-z0 * wn, wn * (1.0 - z0 * z0).sqrt()]);
                }
                theta2.extend_from_slice(&out.theta[2 * np..]);
                let prob2 = prob.with_layout(lay2.clone(), model.clone());
                let ev2 = prob2.evaluate(&theta2).ok()?;
                let out2 = refine(&prob2, theta2, ev2, n_params2, &lay2);
                let f_stat = nested_f(
                    (out.eval.cost, n_params),
                    (out2.eval.cost, n_params2),
                    (n * m) as f64,
                );
                Some((prob2, lay2, n_params2, out2, f_stat))
            };
            let passes = |o: &crate::lm::LmOutcome, f_stat: f64| {
                !f_stat.is_nan() && f_stat > cfg.min_f && o.convergence.is_converged()
            };
            // several resonances clear of the model's modes: added together first (one
            // refinement instead of one each); when the group does not pass, the
            // strongest alone
            let mut tried = None;
            if peaks.len() > 1 {
                if let Some(t) = refine_with(&peaks) {
                    work = work.add(t.3.work);
                    if passes(&t.3, t.4) {
                        tried = Some((peaks.clone(), t));
                    } else {
                        messages.push(format!(
                            "modes added together at {} Hz (the residual's peaks) did not all hold (F = {:.1}, {}): the strongest alone is tried",
                            peaks.iter().map(|f| format!("{f:.2}")).collect::<Vec<_>>().join(", "),
                            t.4,
                            t.3.convergence.describe()
                        ));
                    }
                }
            }
            if tried.is_none() {
                let Some(t) = refine_with(&peaks[..1]) else {
                    break;
                };
                work = work.add(t.3.work);
                if !passes(&t.3, t.4) {
                    messages.push(if t.3.convergence.is_converged() {
                        format!(
                            "a mode added at {:.2} Hz (the residual's peak) did not explain more than noise (F = {:.1}): not kept",
                            peaks[0], t.4
                        )
                    } else {
                        format!(
                            "a mode added at {:.2} Hz (the residual's peak) did not converge (F = {:.1}, {}): not kept",
                            peaks[0],
                            t.4,
                            t.3.convergence.describe()
                        )
                    });
                    break;
                }
                tried = Some((peaks[..1].to_vec(), t));
            }
            let Some((new_f, (prob2, lay2, n_params2, out2, f_stat))) = tried else {
                break;
            };
            messages.push(format!(
                "{} added at {} Hz (the residual's {}; the start missed {}): cost {:.4e} -> {:.4e}, F = {f_stat:.1}",
                if new_f.len() == 1 { "mode" } else { "modes" },
                new_f.iter().map(|f| format!("{f:.2}")).collect::<Vec<_>>().join(", "),
                if new_f.len() == 1 { "peak" } else { "peaks" },
                if new_f.len() == 1 { "it" } else { "them" },
                out.eval.cost,
                out2.eval.cost
            ));
            added.extend(new_f);
            prob = prob2;
            lay = lay2;
            n_params = n_params2;
            out = out2;
        }
        // the rigid body chosen again (`prune_integrators`) at the optimum, before a
        // held delay is freed (one refinement then continues both) and after
        let mut delay_freed = !held_delay;
        loop {
            while measured
                && cfg.prune_integrators
                && lay.n_rigid > 0
                && out.convergence.is_converged()
                && lay.n_pairs + lay.n_real + lay.n_rigid > 1
            {
                let test = |keep: usize| {
                    drop_integrators(
                        &prob,
                        &out,
                        (&lay, n_params),
                        keep,
                        &model,
                        (n * m) as f64,
                        cfg,
                        refine,
                    )
                };
                // all of them at once first (one refinement), then the highest alone
                let all = if lay.n_rigid > 1 && lay.n_pairs + lay.n_real > 0 {
                    test(0).filter(|s| s.kept.is_some())
                } else {
                    None
                };
                let Some(step) = all.or_else(|| test(lay.n_rigid - 1)) else {
                    break;
                };
                messages.push(step.message);
                let Some((prob_d, lay_d, n_params_d, out_d)) = step.kept else {
                    break;
                };
                out = continued(out, out_d, &mut work);
                prob = prob_d;
                lay = lay_d;
                n_params = n_params_d;
            }
            if delay_freed {
                break;
            }
            delay_freed = true;
            if held_delay && leaving(lay.n_pairs, lay.n_real)(&out.theta).is_none() {
                // the delay freed at the adapted structure's optimum (a refinement that
                // stopped on a pole leaving the stable region is refined again from its
                // optimum with the pole dropped, and the delay held again)
                let lay_f = Layout {
                    delay: true,
                    ..lay.clone()
                };
                let mut theta_f = out.theta.clone();
                let at = lay_f.delay_index().unwrap_or(theta_f.len());
                theta_f.insert(at, model.factors.delay_s);
                let prob_f = prob.with_layout(lay_f.clone(), model.clone());
                let n_params_f = lay_f.n_nl() + m * lay_f.n_lin();
                // the score test of the delay at the held optimum: the Gauss-Newton
                // decrease of the cost with the delay free, from one Jacobian; a delay
                // that would explain less than `min_f` times the noise (the test of the
                // added modes and integrators) stays held instead of being refined in
                // several iterations to an insignificant value
                let score = prob_f.evaluate(&theta_f).ok().map(|ev| {
                    let (r, _) = prob_f.jacobian_r(&theta_f, &ev);
                    let z2 = crate::lm::linearised_decrease(&r, theta_f.len());
                    let f_stat = nested_f(
                        (ev.cost, n_params),
                        ((ev.cost - 0.5 * z2).max(0.0), n_params_f),
                        (n * m) as f64,
                    );
                    (ev, f_stat)
                });
                if let Some((_, f_stat)) = score
                    .as_ref()
                    .filter(|(_, f)| f.is_nan() || *f <= cfg.min_f)
                {
                    messages.push(format!(
                        "the delay was held at {:.4} us while the start was far above the noise level (cost {:.4e}), and stays held after the structure adaptation: freed, it would explain {f_stat:.2} times the noise (the linearised decrease at the optimum, F <= {})",
                        model.factors.delay_s * 1e6,
                        eval_start_cost,
                        cfg.min_f
                    ));
                } else if let Some((ev, _)) = score {
                    let out_f = refine(&prob_f, theta_f, ev, n_params_f, &lay_f);
                    messages.push(format!(
                        "the delay was held at {:.4} us while the start was far above the noise level (cost {:.4e}), and freed after the structure adaptation: cost {:.4e} -> {:.4e}",
                        model.factors.delay_s * 1e6,
                        eval_start_cost,
                        out.eval.cost,
                        out_f.eval.cost
                    ));
                    out = continued(out, out_f, &mut work);
                    prob = prob_f;
                    lay = lay_f;
                    n_params = n_params_f;
                }
            }
        }
        // the added modes, and the modes that share a resonance or are narrower than the
        // line spacing, tested again at the final structure (the delay freed, the
        // integrators chosen again, the later additions in): an addition judged while
        // the delay was held far from its value took up the delay's misfit (simulated
        // wafer-stage plates, seed 4: four modes added at 1000 times the noise, two of
        // them one pole, none of them in the plant), and a start mode it displaced can
        // end as a spike beside the resonance the addition took over
        let mut first_added = lay.n_pairs - added.len();
        // pairs tested and kept, and whether the refinement without them failed (those are
        // tested again after a later drop: another spurious mode that ran off in that
        // refinement may be the one that went)
        let mut tested: Vec<(usize, bool)> = Vec::new();
        loop {
            if !measured {
                break;
            }
            let Some(step) = retest_mode(
                &prob,
                &out,
                (&lay, n_params, first_added),
                &tested,
                &model,
                (n * m) as f64,
                cfg,
                refine,
            ) else {
                break;
            };
            messages.push(step.message);
            let Some((prob_d, lay_d, n_params_d, out_d)) = step.dropped else {
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
            out = continued(out, out_d, &mut work);
            prob = prob_d;
            lay = lay_d;
            n_params = n_params_d;
        }
        let np = lay.n_pairs;
        let iter_time = t_iter.elapsed();
        let fitted = prob.model(&out.theta, &out.eval.coef);
        // the added modes (start frequencies) among the optimum's pairs that `keep` keeps
        let added_kept = |keep: &dyn Fn(&realize::PolePair) -> bool| -> Vec<f64> {
            fitted.modal.pairs[first_added..]
                .iter()
                .zip(&added)
                .filter(|(p, _)| keep(p))
                .map(|(_, f)| *f)
                .collect()
        };
        // unstable optimum
        let mut bad = Vec::new();
        for p in &fitted.modal.pairs {
            if p.pole.re >= 0.0 {
                bad.push(format!(
                    "mode at {:.3} Hz with damping {:.3e}",
                    p.f_hz(),
                    p.zeta()
                ));
            }
        }
        for p in &fitted.modal.real_poles {
            if p.pole >= 0.0 {
                bad.push(format!("real pole at {:.3e} rad/s", p.pole));
            }
        }
        for (k, d) in fitted.factors.dynamics.iter().enumerate() {
            if !d.is_stable() {
                bad.push(format!("dynamics factor {k} ({:?})", d.target));
            }
        }
        let dynamics_stable = fitted.factors.dynamics.iter().all(|d| d.is_stable());
        // a larger start has more poles that a noisy or crowded stretch of the band cannot
        // carry: the limit grows with it (one drop per ten pole pairs beyond the default)
        let drop_limit = if cfg.unstable_drops == 0 {
            0
        } else {
            cfg.unstable_drops.max(model.modal.pairs.len().div_ceil(10))
        };
        let w_top = data.omegas().iter().cloned().fold(0.0f64, f64::max);
        // a pair the data can carry: within 1e4 times the band, not critically damped
        let pair_supported = |p: &realize::PolePair| {
            p.pole.im <= 1e4 * w_top && p.pole.im > CRITICAL_IM * p.pole.norm()
        };
        let far: Vec<String> = fitted
            .modal
            .real_poles
            .iter()
            .filter(|p| p.pole < -1e4 * w_top)
            .map(|p| {
                format!(
                    "real pole at {:.3e} rad/s, 1e4 times beyond the band",
                    p.pole
                )
            })
            .chain(
                fitted
                    .modal
                    .pairs
                    .iter()
                    .filter(|p| !pair_supported(p))
                    .map(|p| {
                        if p.pole.im > 1e4 * w_top {
                            format!("mode at {:.3e} Hz, 1e4 times beyond the band", p.f_hz())
                        } else {
                            format!(
                                "mode at {:.3} Hz with damping {:.6} (critically damped: its frequency is not identifiable)",
                                p.f_hz(),
                                p.zeta()
                            )
                        }
                    }),
            )
            .collect();
        if !(bad.is_empty() && far.is_empty()) && drops < drop_limit && dynamics_stable {
            let mut next = fitted.clone();
            next.modal
                .pairs
                .retain(|p| p.pole.re < 0.0 && pair_supported(p));
            next.modal
                .real_poles
                .retain(|p| p.pole < 0.0 && p.pole >= -1e4 * w_top);
            if next.modal.pairs.len() + next.modal.real_poles.len() + next.modal.rigid.len() > 0 {
                messages.push(format!(
                    "the optimum had poles the data do not support ({}) after {} iterations ({}): dropped, and refined again from that optimum",
                    bad.iter().chain(&far).cloned().collect::<Vec<_>>().join(", "),
                    out.iterations,
                    out.convergence.describe()
                ));
                let carried =
                    added_kept(&|p: &realize::PolePair| p.pole.re < 0.0 && pair_supported(p));
                return self.estimate_from(data, next, drops + 1, (messages, carried));
            }
        }
        if !bad.is_empty() {
            return Err(MlError::Unstable {
                poles: bad.join(", "),
                hint: "start from another initialiser (--init), drop the mode from the start (--modes), or narrow the band to where the mode is excited".into(),
            });
        }
        // statistics
        let dof = (n * m) as f64 - n_params as f64 / 2.0;
        let cost = out.eval.cost;
        let ratio = cost / dof;
        let (expected, p_value) = cost_test(measured, cfg.realizations, cost, dof);
        let scale = covariance_scale(cfg.covariance, measured, ratio);
        let n_nl = lay.n_nl();
        let (cov, cond, weakest) =
            covariance(&out.r, n_nl, &out.vnorm).map_err(|_| MlError::Unidentifiable {
                what: "the information matrix could not be factorised".into(),
                condition: f64::INFINITY,
                hint: "check the data for non-finite values".into(),
            })?;
        let unidentifiable = n_nl > 0 && (cond.is_nan() || cond > cfg.max_condition);
        if unidentifiable && drops < drop_limit && lay.delay_index() == Some(weakest) {
            // a delay the data do not determine: with complex residues and a feedthrough,
            // a delay change `d` is taken up to first order by the residues (`-p_k r_k d`)
            // and the feedthrough (`sum_k r_k d`) of a strictly proper plant, so that
            // near exact data its information vanishes (a random 4 x 4 plant with 8
            // modes and relative noise 1e-6: condition 8.9e16); held where it is
            let mut next = fitted.clone();
            next.factors.delay_fitted = false;
            messages.push(format!(
                "the delay is not determined by the data (information matrix condition {cond:.2e}; with complex residues and a feedthrough it trades with the residues' phases) after {} iterations ({}): held at {:.4} us and refined again; give it with --delay SECONDS if it is known",
                out.iterations,
                out.convergence.describe(),
                fitted.factors.delay_s * 1e6
            ));
            return self.estimate_from(data, next, drops + 1, (messages, added));
        }
        if unidentifiable && drops < drop_limit && weakest < 2 * np + lay.n_real {
            // a pole the data do not determine (a spurious real pole running off to
            // infinity, a mode without residue): dropped, and refined again
            let mut next = fitted.clone();
            let what = describe_param(&lay, &out.theta, weakest, &fitted);
            let mut carried = added.clone();
            if weakest < 2 * np {
                next.modal.pairs.remove(weakest / 2);
                if weakest / 2 >= first_added {
                    carried.remove(weakest / 2 - first_added);
                }
            } else {
                next.modal.real_poles.remove(weakest - 2 * np);
            }
            if next.modal.pairs.len() + next.modal.real_poles.len() + next.modal.rigid.len() > 0 {
                messages.push(format!(
                    "{what} is not determined by the data (information matrix condition {cond:.2e}) after {} iterations ({}): dropped, and refined again from that optimum",
                    out.iterations,
                    out.convergence.describe()
                ));
                return self.estimate_from(data, next, drops + 1, (messages, carried));
            }
        }
        if unidentifiable {
            return Err(MlError::Unidentifiable {
                what: describe_param(&lay, &out.theta, weakest, &fitted),
                condition: cond,
                hint: "drop the mode or term from the start, fix the delay (--delay SECONDS), or widen the band".into(),
            });
        }
        let c = |a: usize, b: usize| cov[b * n_nl + a] * scale;
        let modes = mode_uncertainties(&out.theta, np, &c);
        let (delay_s, delay_s_std) = match lay.delay_index() {
            Some(i) => {
                let fisher = c(i, i).max(0.0).sqrt();
                let (delay_std, profile) = delay_std(
                    &prob,
                    &out.theta,
                    i,
                    (out.eval.cost, scale),
                    fisher,
                    &mut messages,
                );
                if let Some((d, c)) = profile.lower {
                    messages.push(format!(
                        "the cost (poles held) is lower {:.3} us from the returned delay ({:.6e} against {:.6e}): the refinement stopped short of the delay's optimum, where the cost is nearly flat in it",
                        d * 1e6,
                        c,
                        out.eval.cost
                    ));
                }
                (Some(out.theta[i]), Some(delay_std))
            }
            None => (None, None),
        };
        if !out.convergence.is_converged() {
            messages.push(format!(
                "ML refinement {}: the uncertainty holds at an optimum only; try more iterations, a start from another initialiser, or fewer modes",
                out.convergence.describe()
            ));
        }
        if measured {
            if let Some(p) = p_value {
                if p < 1e-3 {
                    messages.push(format!(
                        "cost test: V/N_dof = {ratio:.3} (expected {expected:.3}, p = {p:.1e}): the residual exceeds the noise model (model error, or a variance estimated from few realizations); the standard deviations are scaled by sqrt({scale:.3})"
                    ));
                }
            }
        } else {
            messages.push(format!(
                "no measured variance: weighted least squares ({}), the noise scale estimated from the residual (V/N_dof = {ratio:.3e}) scales the covariance",
                weighting.name()
            ));
        }
        let report = MlReport {
            weighting: weighting.name().to_string(),
            noise: if measured {
                "measured variance".into()
            } else {
                "estimated from the residual".into()
            },
            residue_form: if const_num {
                "constant_numerator".into()
            } else {
                "complex".into()
            },
            n_nonlinear: n_nl,
            n_params,
            n_observations: 2 * n * m,
            iterations: out.iterations,
            cost_history: out.cost_history.clone(),
            converged: out.convergence.is_converged(),
            convergence: out.convergence.describe(),
            cost,
            dof,
            cost_ratio: ratio,
            expected_ratio: expected,
            p_value,
            covariance_scale: scale,
            information_condition: cond,
            modes,
            delay_s,
            delay_s_std,
            added_modes_hz: added,
            evaluations: work.evaluations,
            jacobians: work.jacobians,
        };
        let mut fit = Fit {
            model: fitted,
            report,
            cost_history: out.cost_history,
            iterations: out.iterations,
            convergence: out.convergence,
            timings: Vec::new(),
            estimator: format!(
                "maximum likelihood, Levenberg-Marquardt with variable projection ({})",
                weighting.name()
            ),
            messages,
        };
        fit.push_timing("iterations", iter_time);
        fit.push_timing("evaluations", work.evaluation_time);
        fit.push_timing("jacobians", work.jacobian_time);
        fit.push_timing("total", t0.elapsed());
        if let Convergence::Failed { .. } = fit.convergence {
            fit.messages
                .push("the iterations failed: see the convergence reason".into());
        }
        Ok(fit)
    }
}

/// The cost test of a weighted cost `cost` with `dof` complex degrees of freedom: its
/// expected ratio `V / N_dof` (1, or `d2 / (d2 - 2)` with `d2 = 2 (R - 1)` for a variance
/// from `R >= 4` realizations) and the p-value of the observed one (`None` without a
/// measured variance).
fn cost_test(
    measured: bool,
    realizations: Option<usize>,
    cost: f64,
    dof: f64,
) -> (f64, Option<f64>) {
    let ratio = cost / dof;
    if !measured {
        return (1.0, None);
    }
    match realizations {
        Some(r) if r >= 4 => {
            let d2 = 2.0 * (r as f64 - 1.0);
            let mu = d2 / (d2 - 2.0);
            let var = d2.powi(3) / ((d2 - 2.0).powi(2) * (d2 - 4.0));
            (
                mu,
                Some(normal_upper_tail((ratio - mu) / (var / dof).sqrt())),
            )
        }
        _ => (1.0, Some(chi2_upper_tail(2.0 * cost, 2.0 * dof))),
    }
}

/// The factor the inverse Fisher information is multiplied by ([`CovarianceScale`]).
fn covariance_scale(rule: CovarianceScale, measured: bool, ratio: f64) -> f64 {
    match (rule, measured) {
        (CovarianceScale::Fisher, _) => 1.0,
        (CovarianceScale::CostRatio, _) | (CovarianceScale::Auto, false) => ratio,
        (CovarianceScale::Auto, true) => ratio.max(1.0),
    }
}

/// Each pole pair's natural frequency `f = |p| / 2 pi` and damping `zeta = -Re p / |p|`
/// with their standard deviations by the delta method from the covariance `c(a, b)` of
/// the pairs' real and imaginary parts (the first `2 np` entries of `theta`, McKelvey eq.
/// (31)-(32)).
fn mode_uncertainties(
    theta: &[f64],
    np: usize,
    c: &dyn Fn(usize, usize) -> f64,
) -> Vec<ModeUncertainty> {
    (0..np)
        .map(|q| {
            let (a, b) = (theta[2 * q], theta[2 * q + 1]);
            let r = (a * a + b * b).sqrt();
            // f = r / 2 pi, zeta = -a / r
            let gf = [a / (r * TAU), b / (r * TAU)];
            let gz = [-b * b / (r * r * r), a * b / (r * r * r)];
            let quad = |g: [f64; 2]| {
                let (i, j) = (2 * q, 2 * q + 1);
                (g[0] * g[0] * c(i, i) + 2.0 * g[0] * g[1] * c(i, j) + g[1] * g[1] * c(j, j))
                    .max(0.0)
                    .sqrt()
            };
            ModeUncertainty {
                f_hz: r / TAU,
                f_hz_std: quad(gf),
                zeta: -a / r,
                zeta_std: quad(gz),
            }
        })
        .collect()
}

/// The F statistic of the structure tests (a mode added, integrators dropped): the cost
/// the larger structure (`large`: cost, parameters) explains beyond the smaller
/// (`small`), per pair of parameters, over the larger's noise scale `cost / N_dof`, with
/// `observations` complex observations.
fn nested_f(small: (f64, usize), large: (f64, usize), observations: f64) -> f64 {
    let dof = observations - large.1 as f64 / 2.0;
    ((small.0 - large.0) / ((large.1 - small.1) as f64 / 2.0)) / (large.0 / dof)
}

/// The refinement `next` that continued from the optimum `prev` with another structure:
/// its work added to `work`, and `prev`'s iterations to its own.
fn continued(
    prev: crate::lm::LmOutcome,
    mut next: crate::lm::LmOutcome,
    work: &mut crate::lm::Work,
) -> crate::lm::LmOutcome {
    *work = work.add(next.work);
    next.iterations += prev.iterations;
    next
}

/// One step of the rigid-body re-choice of [`MlConfig::prune_integrators`]: its message,
/// and the refinement without the integrators when they were dropped.
struct IntegratorStep {
    message: String,
    kept: Option<(Problem, Layout, usize, crate::lm::LmOutcome)>,
}

/// The integrators `1/s^(keep+1) .. 1/s^k` of the optimum `out` (structure `lay` with
/// `k` integrators and `n_params` parameters, `observations` complex observations)
/// tested by the F test of the mode additions: the cost with them dropped and the poles
/// held (the linear parameters refitted: variable projection) against the optimum's.
/// Below [`MlConfig::min_f`] the refinement continues without them (`refine`, given the
/// parameter count), and they stay dropped when that refinement converges to a cost they
/// do not significantly lower. `None` when they explain more, or the problem without
/// them cannot be evaluated.
#[allow(clippy::too_many_arguments)]
fn drop_integrators(
    prob: &Problem,
    out: &crate::lm::LmOutcome,
    (lay, n_params): (&Layout, usize),
    keep: usize,
    model: &FrfModel,
    observations: f64,
    cfg: &MlConfig,
    refine: impl Fn(&Problem, Vec<f64>, crate::varpro::Eval, usize, &Layout) -> crate::lm::LmOutcome,
) -> Option<IntegratorStep> {
    let k = lay.n_rigid;
    let lay_d = Layout {
        n_rigid: keep,
        ..lay.clone()
    };
    let n_params_d = lay_d.n_nl() + lay.m() * lay_d.n_lin();
    let prob_d = prob.with_layout(lay_d.clone(), model.clone());
    let ev_d = prob_d.evaluate(&out.theta).ok()?;
    let f_of = |cost_d: f64| {
        nested_f(
            (cost_d, n_params_d),
            (out.eval.cost, n_params),
            observations,
        )
    };
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
    let out_d = refine(&prob_d, out.theta.clone(), ev_d, n_params_d, &lay_d);
    let f_refined = f_of(out_d.eval.cost);
    if !out_d.convergence.is_converged() || f_refined >= cfg.min_f {
        return Some(IntegratorStep {
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
        message: format!(
            "{what} {verb} {f_held:.2} times the noise per parameter at the optimum (< {}): dropped, cost {:.4e} -> {:.4e} after {} further iterations (F = {f_refined:.2})",
            cfg.min_f,
            out.eval.cost,
            out_d.eval.cost,
            out_d.iterations
        ),
        kept: Some((prob_d, lay_d, n_params_d, out_d)),
    })
}

/// One step of the re-test of [`retest_mode`]: its message, the pair tested, and the
/// refinement without it when it was dropped.
struct ModeRetest {
    message: String,
    pair: usize,
    /// The refinement without the mode did not converge.
    failed: bool,
    dropped: Option<(Problem, Layout, usize, crate::lm::LmOutcome)>,
}

/// One mode of the optimum `out` (structure `lay`, `n_params` parameters) tested again by
/// the F test of the mode additions: an added one (pairs `first_added..`), or one that
/// shares its resonance with another mode (poles within [`TWIN_FRACTION`] of their mean
/// `|Re p|`: a twin) or is narrower than the line spacing around it (half-power
/// bandwidth `2 zeta f`: a spike, which can fit the noise of one or two lines), not among
/// the pairs already `tested` and kept (pair index, and whether that refinement failed). Twins come first, then the others by the cost
/// they explain with the other poles held (the linear parameters refitted). A twin, or
/// another candidate below [`MlConfig::min_f`] with the poles held, is tested by the
/// refinement without it: it is dropped when that refinement converges to a cost the
/// mode does not significantly lower. Two poles that close act together as one pole
/// moved (a double pole's derivative term), so holding the other where the pair put it
/// overstates what one of them explains. `None` when no candidate is left to test.
#[allow(clippy::too_many_arguments)]
fn retest_mode(
    prob: &Problem,
    out: &crate::lm::LmOutcome,
    (lay, n_params, first_added): (&Layout, usize, usize),
    tested: &[(usize, bool)],
    model: &FrfModel,
    observations: f64,
    cfg: &MlConfig,
    refine: impl Fn(&Problem, Vec<f64>, crate::varpro::Eval, usize, &Layout) -> crate::lm::LmOutcome,
) -> Option<ModeRetest> {
    if lay.n_pairs + lay.n_real + lay.n_rigid < 2 {
        return None;
    }
    let lay_d = Layout {
        n_pairs: lay.n_pairs - 1,
        ..lay.clone()
    };
    let n_params_d = lay_d.n_nl() + lay.m() * lay_d.n_lin();
    let prob_d = prob.with_layout(lay_d.clone(), model.clone());
    let f_of = |cost_d: f64| {
        nested_f(
            (cost_d, n_params_d),
            (out.eval.cost, n_params),
            observations,
        )
    };
    let pole = |q: usize| C64::new(out.theta[2 * q], out.theta[2 * q + 1]);
    let twin = |q: usize| {
        (0..lay.n_pairs).filter(|&r| r != q).any(|r| {
            let (a, b) = (pole(q), pole(r));
            (a - b).norm() < TWIN_FRACTION * 0.5 * (a.re.abs() + b.re.abs())
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
    // twins first, then by the cost explained with the other poles held
    let (q, theta_d, ev_d, f_held, suspect) = (0..lay.n_pairs)
        .filter(|&q| !tested.iter().any(|&(k, _)| k == q))
        .filter_map(|q| {
            let suspect = twin(q);
            if q < first_added && !suspect && !narrow(q) {
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
    let out_d = refine(&prob_d, theta_d, ev_d, n_params_d, &lay_d);
    let f_refined = f_of(out_d.eval.cost);
    if !out_d.convergence.is_converged() || f_refined >= cfg.min_f {
        return Some(ModeRetest {
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
        message: format!(
            "{what} at {f_hz:.2} Hz, tested again at the final structure, explains {f_held:.2} times the noise per parameter with the other poles held: dropped, cost {:.4e} -> {:.4e} after {} further iterations (F = {f_refined:.2} < {})",
            out.eval.cost,
            out_d.eval.cost,
            out_d.iterations,
            cfg.min_f
        ),
        pair: q,
        failed: false,
        dropped: Some((prob_d, lay_d, n_params_d, out_d)),
    })
}

/// The delay's profile of [`delay_profile`].
struct DelayProfile {
    /// The larger of the two offsets from the optimum at which the cost (poles held)
    /// has risen by 1/2 (the one-standard-deviation interval of a likelihood profile),
    /// seconds.
    half_width: f64,
    /// False when a side did not reach the rise within the search (`half_width` is then
    /// a lower bound).
    reached: bool,
    /// A lower cost found on the way: its offset and cost.
    lower: Option<(f64, f64)>,
}

/// The delay's profile with the poles held (the linear parameters refitted at each
/// delay: variable projection), a cheap stand-in for the likelihood profile: per side,
/// the offset from the optimum at which the cost over the covariance's `scale` (`-log L`
/// up to a constant) has risen by 1/2, by doubling from `start` (at most
/// [`PROFILE_DOUBLINGS`] times) and interpolating linearly in `sqrt(2 dV)`. Holding the poles can only raise the cost, so the offsets
/// are lower bounds of those of the full profile. Near a quadratic optimum they equal
/// the standard deviation of the information matrix; where the delay trades with other
/// parameters to first order the profile is flatter (quartic) and wider.
/// The delay's reported standard deviation: the information matrix's `fisher`, or the
/// half width of its profile ([`delay_profile`]) when that is over 1.5 times larger,
/// with a message in `messages` saying so; and the profile.
fn delay_std(
    prob: &Problem,
    theta: &[f64],
    i: usize,
    (cost, scale): (f64, f64),
    fisher: f64,
    messages: &mut Vec<String>,
) -> (f64, DelayProfile) {
    let profile = delay_profile(prob, theta, i, (cost, scale), fisher);
    if profile.half_width <= 1.5 * fisher {
        return (fisher, profile);
    }
    messages.push(format!(
        "the delay's profile is flatter than its curvature says: the cost (poles held) rises by 1/2 only {:.3} us from the estimate{}, where the information matrix gives a standard deviation of {:.3} us; reported: {:.3} us (with complex residues and a feedthrough a delay trades with the residues' phases to first order)",
        profile.half_width * 1e6,
        if profile.reached { "" } else { " (at least: not reached)" },
        fisher * 1e6,
        profile.half_width * 1e6
    ));
    (profile.half_width, profile)
}

fn delay_profile(
    prob: &Problem,
    theta: &[f64],
    i: usize,
    (cost, scale): (f64, f64),
    start: f64,
) -> DelayProfile {
    let mut profile = DelayProfile {
        half_width: 0.0,
        reached: start.is_finite() && start > 0.0,
        lower: None,
    };
    if !profile.reached {
        return profile;
    }
    for side in [-1.0, 1.0] {
        let (mut h_lo, mut r_lo) = (0.0, 0.0);
        let mut h = start;
        let mut side_w = None;
        for _ in 0..=PROFILE_DOUBLINGS {
            let mut t = theta.to_vec();
            t[i] += side * h;
            let Ok(ev) = prob.evaluate(&t) else { break };
            let c = ev.cost;
            if c < cost && profile.lower.is_none_or(|(_, lc)| c < lc) {
                profile.lower = Some((side * h, c));
            }
            let r = (2.0 * (c - cost) / scale).max(0.0).sqrt();
            if r >= 1.0 {
                side_w = Some(h_lo + (h - h_lo) * (1.0 - r_lo) / (r - r_lo));
                break;
            }
            (h_lo, r_lo) = (h, r);
            h *= 2.0;
        }
        profile.reached &= side_w.is_some();
        profile.half_width = profile.half_width.max(side_w.unwrap_or(h_lo));
    }
    profile
}

/// Most doublings of the step of [`delay_profile`] per side (the search reaches 64
/// times the information matrix's standard deviation).
const PROFILE_DOUBLINGS: usize = 6;
