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

pub use crate::config::{sample_variance_factor, CovarianceScale, MlConfig};
use crate::lm::covariance;
use crate::search::{
    add_missed_modes, free_held_delay, rechoose_integrators, retest_modes, Current, Log, Setting,
};
use crate::stats::{chi2_upper_tail, normal_upper_tail};
use crate::varpro::{Layout, Problem, ResidueForm};
use crate::MlError;
use crate::C64;
use frf_data::structure::{StructureChange, StructureStep};
use frf_data::{ChainModel, Convergence, Estimator, Fit, FrfDataset, Weighting};
use realize::FrfModel;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::time::Instant;

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
pub use frf_data::uncertainty::PoleUncertainty as ModeUncertainty;

/// A dynamics factor's poles and zeros (the upper one of a complex pair; a real root
/// has damping 1) with the standard deviations of their frequency and damping, from
/// the covariance of the factor's coefficients by the delta method.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FactorUncertainty {
    /// What it multiplies.
    pub target: realize::FactorTarget,
    /// The roots of its denominator.
    pub poles: Vec<ModeUncertainty>,
    /// The roots of its numerator (empty for an all-pole factor).
    pub zeros: Vec<ModeUncertainty>,
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
    /// Per dynamics factor, its poles and zeros with standard deviations (in the
    /// model's order).
    #[serde(default)]
    pub factors: Vec<FactorUncertainty>,
    /// Start frequencies (Hz) of the modes the refinement added.
    #[serde(default)]
    pub added_modes_hz: Vec<f64>,
    /// The changes of the structure the refinement tested, in order, taken or not
    /// ([`StructureStep`]); empty in files written before they were recorded.
    #[serde(default)]
    pub structure_steps: Vec<StructureStep>,
    /// Cost evaluations (trial points) of all runs of the iterations.
    #[serde(default)]
    pub evaluations: usize,
    /// Jacobian factorisations of all runs of the iterations.
    #[serde(default)]
    pub jacobians: usize,
}

#[typetag::serde(name = "ml")]
impl frf_data::LinkDetails for MlReport {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// The maximum-likelihood refiner (Gauss-Newton / Levenberg-Marquardt with variable
/// projection) of the chain, from any [`ChainModel`]'s currency.
#[derive(Debug, Clone, Default)]
pub struct MlRefine {
    /// Settings.
    pub config: MlConfig,
}

impl Information {
    /// The report of the information at the estimate: the modes' and the delay's
    /// standard deviations, the cost test, no iterations.
    fn report(&self) -> MlReport {
        let (prob, theta, scale) = (&self.prob, &self.theta, self.scale);
        let lay = &prob.lay;
        let n_nl = lay.n_nl();
        let c = |a: usize, b: usize| self.cov[b * n_nl + a] * scale;
        let modes = mode_uncertainties(theta, lay.n_pairs, &c);
        let factors = factor_uncertainties(
            &prob.model(theta, &self.ev.coef).factors.dynamics,
            lay.dynamics_index(),
            &c,
        );
        let mut messages = Vec::new();
        let (delay_s, delay_s_std) = match lay.delay_index() {
            Some(i) => {
                let fisher = c(i, i).max(0.0).sqrt();
                let (std, _) = delay_std(prob, theta, i, (self.cost, scale), fisher, &mut messages);
                (Some(theta[i]), Some(std))
            }
            None => (None, None),
        };
        MlReport {
            weighting: self.weighting_name.clone(),
            noise: if self.measured {
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
            n_params: self.n_params,
            n_observations: self.n_observations,
            iterations: 0,
            cost_history: vec![self.cost],
            converged: false,
            convergence: format!(
                "not iterated: the information at the given estimate{}",
                if messages.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", messages.join("; "))
                }
            ),
            cost: self.cost,
            dof: self.dof,
            cost_ratio: self.ratio,
            expected_ratio: self.expected,
            p_value: self.p_value,
            covariance_scale: scale,
            information_condition: self.cond,
            modes,
            delay_s,
            delay_s_std,
            factors,
            added_modes_hz: Vec::new(),
            structure_steps: Vec::new(),
            evaluations: 1,
            jacobians: 1,
        }
    }

    /// The standard deviation of the estimate's response at every line and the entries
    /// `entries` (all with `None`; the others NaN), [`MlRefine::response_std_at`].
    fn response_std(&self, entries: Option<&[usize]>) -> Vec<f64> {
        let var = self
            .prob
            .response_variance(&self.theta, &self.ev, &self.cov, entries);
        self.scaled_std(var)
    }

    /// [`Information::response_std`] at the frequencies `omega` (rad/s) instead of the
    /// data's lines, every entry ([`MlRefine::response_std_at_omegas`]).
    fn response_std_at_omegas(&self, omega: &[f64]) -> Vec<f64> {
        let at = self.prob.at_lines(omega.to_vec());
        let var = self
            .prob
            .response_variance_at(&at, &self.theta, &self.ev, &self.cov, None);
        self.scaled_std(var)
    }

    /// Unscaled response variances to standard deviations with the covariance scale.
    fn scaled_std(&self, var: Vec<f64>) -> Vec<f64> {
        var.into_iter()
            // NaN (an entry not asked for) stays NaN: `max` would make it 0
            .map(|v| {
                if v.is_nan() {
                    v
                } else {
                    (v * self.scale).max(0.0).sqrt()
                }
            })
            .collect()
    }
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
        self.estimate_from(data, start.model, 0, (Log::default(), Vec::new()))
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
        let (expected, p_value) = cost_test(measured, cfg.variance_dof(), cost, dof);
        let scale = covariance_scale(cfg, measured, ratio);
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
        Ok(self.information_at(data, model)?.report())
    }

    /// [`MlRefine::uncertainty_at`] and [`MlRefine::response_std_at`] (for `entries`)
    /// from one information matrix: one evaluation, one Jacobian and one factorisation
    /// instead of two of each (0.2-0.5 s on the reference files). Same errors.
    pub fn uncertainty_and_response_std_at<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: &FrfModel,
        entries: Option<&[usize]>,
    ) -> Result<(MlReport, Vec<f64>), MlError> {
        let info = self.information_at(data, model)?;
        Ok((info.report(), info.response_std(entries)))
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
        Ok(self.information_at(data, model)?.response_std(entries))
    }

    /// The standard deviation of `model`'s response at the frequencies `omega` (rad/s;
    /// any lines, e.g. those of an independent validation measurement), every entry
    /// (layout `[k * m + e]`), from the information of the criterion on `data` (the data
    /// the model was fitted to): [`MlRefine::response_std_at`] carried to other lines,
    /// what the fit data's noise leaves uncertain in the model's response there. Same
    /// errors as [`MlRefine::uncertainty_at`].
    pub fn response_std_at_omegas<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: &FrfModel,
        omega: &[f64],
    ) -> Result<Vec<f64>, MlError> {
        if let Some(w) = omega.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
            return Err(MlError::invalid(
                "frequencies of the response's standard deviation",
                format!("{w} rad/s"),
                "finite and positive",
            ));
        }
        Ok(self
            .information_at(data, model)?
            .response_std_at_omegas(omega))
    }

    /// [`Estimator::estimate`] from `model`, after `drops` refinements that ended
    /// unstable (see [`MlConfig::unstable_drops`]) whose messages and structure steps are
    /// `carried`; the
    /// last `added_before.len()` pole pairs of `model` are modes an earlier refinement
    /// added (their start frequencies): they count against the limit of additions and
    /// are tested again at the final structure like the modes this refinement adds.
    fn estimate_from<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        model: FrfModel,
        drops: usize,
        (carried, added_before): (Log, Vec<f64>),
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
        let mut log = carried;
        stabilise_start(&mut model, cfg.zeta_unstable, &mut log.messages)?;
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
        if measured && cfg.prune_real_poles {
            if let Some(m2) =
                without_weak_real_pole((&prob, &lay), &eval0, &model, cfg.min_f, &mut log)
            {
                return self.estimate_from(data, m2, drops, (log, added_before));
            }
        }
        let w_top = data.omegas().iter().cloned().fold(0.0f64, f64::max);
        let s = Setting::new(cfg, n, m, measured, w_top);
        let eval_start_cost = eval0.cost;
        let (start, held_delay) = hold_delay_while_far(
            &s,
            Start {
                prob,
                lay,
                theta,
                ev: eval0,
                n_params,
            },
            &model,
        );
        let t_iter = Instant::now();
        let out = s.refine(
            &start.prob,
            start.theta,
            start.ev,
            start.n_params,
            &start.lay,
        );
        let mut work = out.work;
        let mut cur = Current {
            prob: start.prob,
            lay: start.lay,
            n_params: start.n_params,
            out,
        };
        let mut added = added_before;
        add_missed_modes(&s, &mut cur, (&model, &w), &mut added, &mut work, &mut log);
        // the rigid body chosen again at the optimum, before a held delay is freed (one
        // refinement then continues both) and after
        rechoose_integrators(&s, &mut cur, &model, &mut work, &mut log);
        if held_delay {
            free_held_delay(&s, &mut cur, (&model, eval_start_cost), &mut work, &mut log);
            rechoose_integrators(&s, &mut cur, &model, &mut work, &mut log);
        }
        let first_added = retest_modes(&s, &mut cur, &model, &mut added, &mut work, &mut log);
        let Current {
            prob,
            lay,
            n_params,
            out,
        } = cur;
        let np = lay.n_pairs;
        let iter_time = t_iter.elapsed();
        let fitted = prob.model(&out.theta, &out.eval.coef);
        // a larger start has more poles that a noisy or crowded stretch of the band cannot
        // carry: the limit grows with it (one drop per ten pole pairs beyond the default)
        let drop_limit = if cfg.unstable_drops == 0 {
            0
        } else {
            cfg.unstable_drops.max(model.modal.pairs.len().div_ceil(10))
        };
        let unsupported = Unsupported::of(&fitted, w_top);
        let dynamics_stable = fitted.factors.dynamics.iter().all(|d| d.is_stable());
        if !unsupported.is_empty() && drops < drop_limit && dynamics_stable {
            let next = unsupported.dropped_from(&fitted);
            if next.modal.pairs.len() + next.modal.real_poles.len() + next.modal.rigid.len() > 0 {
                let step = StructureStep::forced(
                    StructureChange::PolesDropped {
                        poles: unsupported.all(),
                        reason: "the data do not support them".into(),
                    },
                    out.eval.cost,
                );
                log.step(step, format!(
                    "the optimum had poles the data do not support ({}) after {} iterations ({}): dropped, and refined again from that optimum",
                    unsupported.all().join(", "),
                    out.iterations,
                    out.convergence.describe()
                ));
                // the added modes (start frequencies) that stay
                let carried: Vec<f64> = fitted.modal.pairs[first_added..]
                    .iter()
                    .zip(&added)
                    .filter(|(p, _)| unsupported.keeps(p))
                    .map(|(_, f)| *f)
                    .collect();
                return self.estimate_from(data, next, drops + 1, (log, carried));
            }
        }
        if !unsupported.unstable.is_empty() {
            return Err(MlError::Unstable {
                poles: unsupported.unstable.join(", "),
                hint: "start from another initialiser (--init), drop the mode from the start (--modes), or narrow the band to where the mode is excited".into(),
            });
        }
        // statistics
        let dof = s.dof(n_params);
        let cost = out.eval.cost;
        let ratio = cost / dof;
        let (expected, p_value) = cost_test(measured, cfg.variance_dof(), cost, dof);
        let scale = covariance_scale(cfg, measured, ratio);
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
            let step = StructureStep::forced(
                StructureChange::DelayHeld {
                    delay_s: fitted.factors.delay_s,
                },
                out.eval.cost,
            );
            log.step(step, format!(
                "the delay is not determined by the data (information matrix condition {cond:.2e}; with complex residues and a feedthrough it trades with the residues' phases) after {} iterations ({}): held at {:.4} us and refined again; give it with --delay SECONDS if it is known",
                out.iterations,
                out.convergence.describe(),
                fitted.factors.delay_s * 1e6
            ));
            return self.estimate_from(data, next, drops + 1, (log, added));
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
                let step = StructureStep::forced(
                    StructureChange::PolesDropped {
                        poles: vec![what.clone()],
                        reason: format!(
                            "not determined by the data: information matrix condition {cond:.2e}"
                        ),
                    },
                    out.eval.cost,
                );
                log.step(step, format!(
                    "{what} is not determined by the data (information matrix condition {cond:.2e}) after {} iterations ({}): dropped, and refined again from that optimum",
                    out.iterations,
                    out.convergence.describe()
                ));
                return self.estimate_from(data, next, drops + 1, (log, carried));
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
        let factors = factor_uncertainties(&fitted.factors.dynamics, lay.dynamics_index(), &c);
        let (delay_s, delay_s_std) = match lay.delay_index() {
            Some(i) => {
                let fisher = c(i, i).max(0.0).sqrt();
                let (delay_std, profile) = delay_std(
                    &prob,
                    &out.theta,
                    i,
                    (out.eval.cost, scale),
                    fisher,
                    &mut log.messages,
                );
                if let Some((d, c)) = profile.lower {
                    log.messages.push(format!(
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
            log.messages.push(format!(
                "ML refinement {}: the uncertainty holds at an optimum only; try more iterations, a start from another initialiser, or fewer modes",
                out.convergence.describe()
            ));
        }
        if measured {
            let factor = sample_variance_factor(cfg.variance_dof());
            if factor > 1.0 && cfg.covariance != CovarianceScale::Fisher {
                log.messages.push(format!(
                    "the variance was estimated with {:.0} degrees of freedom per line: the covariance is {factor:.3} times the information's with these weights (the loss of efficiency of sample-variance weights)",
                    cfg.variance_dof().unwrap_or(f64::NAN)
                ));
            }
            if let Some(p) = p_value {
                if p < 1e-3 {
                    log.messages.push(format!(
                        "cost test: V/N_dof = {ratio:.3} (expected {expected:.3}, p = {p:.1e}): the residual exceeds the noise model (model error, or a variance estimated from few realizations); the standard deviations are scaled by sqrt({scale:.3})"
                    ));
                }
            }
        } else {
            log.messages.push(format!(
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
            factors,
            added_modes_hz: added,
            structure_steps: std::mem::take(&mut log.steps),
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
            messages: log.messages,
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

/// The start's poles made stable: a pair outside the open left half-plane gets the
/// damping `zeta_unstable` at its natural frequency, a real pole is reflected, each with
/// a message; a pair below the real axis is an error.
fn stabilise_start(
    model: &mut FrfModel,
    zeta_unstable: f64,
    messages: &mut Vec<String>,
) -> Result<(), MlError> {
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
            let z = zeta_unstable;
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
    Ok(())
}

/// The start `model` without its weakest real pole, when that pole explains less than
/// `min_f` times the noise per parameter (the residues of every entry and the pole; the
/// start problem `prob` with layout `lay`, evaluated as `eval0`) and the model keeps a
/// pole: an initialiser at a high order fits noise with real poles, which the
/// iterations then push unstable or off to infinity. `None` otherwise.
fn without_weak_real_pole(
    (prob, lay): (&Problem, &Layout),
    eval0: &crate::varpro::Eval,
    model: &FrfModel,
    min_f: f64,
    log: &mut Log,
) -> Option<FrfModel> {
    let mut weakest: Option<(usize, f64, f64)> = None;
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
            if weakest.is_none_or(|(_, fw, _)| f < fw) {
                weakest = Some((r, f, ev2.cost));
            }
        }
    }
    let (r, f, cost_without) = weakest.filter(|(_, f, _)| *f < min_f)?;
    let pole = model.modal.real_poles[r].pole;
    let mut m2 = model.clone();
    m2.modal.real_poles.remove(r);
    if m2.modal.pairs.len() + m2.modal.real_poles.len() + m2.modal.rigid.len() == 0 {
        return None;
    }
    let step = StructureStep::tested(
        StructureChange::PolesDropped {
            poles: vec![format!("real pole at {pole:.3e} rad/s")],
            reason: "the start's real pole explains too little".into(),
        },
        true,
        (eval0.cost, cost_without),
        (f, min_f),
    );
    log.step(step, format!(
        "start real pole at {pole:.3e} rad/s explains {f:.2} times the noise per parameter (< {min_f}): dropped before the iterations"
    ));
    Some(m2)
}

/// The start of the iterations: the projected problem, its layout, the nonlinear
/// parameters, their evaluation and the real parameter count.
struct Start {
    prob: Problem,
    lay: Layout,
    theta: Vec<f64>,
    ev: crate::varpro::Eval,
    n_params: usize,
}

/// A free delay held at the start's value while the start is far above the noise level
/// ([`Setting::misfit`]), through the iterations and the structure adaptation, and freed
/// after them when its score test passes ([`free_held_delay`]): the delay otherwise
/// absorbs the misfit of the modes the start missed and settles where the added modes
/// no longer fit (a random 20 x 20 plant with 50 modes and no delay, seed 7: a 29 us
/// delay, 49 modes, 1900 times the noise; with the delay held, every mode and the noise
/// level). Returns the start to iterate from and whether the delay is held.
fn hold_delay_while_far(s: &Setting, start: Start, model: &FrfModel) -> (Start, bool) {
    if !(start.lay.delay && s.misfit(start.ev.cost, start.n_params)) {
        return (start, false);
    }
    let lay = Layout {
        delay: false,
        ..start.lay.clone()
    };
    let theta = nonlinear_start(model, &lay);
    let prob = start.prob.with_layout(lay.clone(), model.clone());
    match prob.evaluate(&theta) {
        Ok(ev) => {
            let n_params = lay.n_nl() + s.m * lay.n_lin();
            (
                Start {
                    prob,
                    lay,
                    theta,
                    ev,
                    n_params,
                },
                true,
            )
        }
        Err(_) => (start, false),
    }
}

/// The poles of an optimum the data do not support: unstable ones (and unstable dynamics
/// factors), and those beyond 1e4 times the highest line `w_top` or critically damped
/// ([`CRITICAL_IM`]), each described for the messages.
struct Unsupported {
    /// Poles and factors outside the stable region.
    unstable: Vec<String>,
    /// Stable poles the data cannot carry.
    far: Vec<String>,
    /// The highest line, rad/s.
    w_top: f64,
}

impl Unsupported {
    fn of(fitted: &FrfModel, w_top: f64) -> Self {
        let mut unstable = Vec::new();
        for p in &fitted.modal.pairs {
            if p.pole.re >= 0.0 {
                unstable.push(format!(
                    "mode at {:.3} Hz with damping {:.3e}",
                    p.f_hz(),
                    p.zeta()
                ));
            }
        }
        for p in &fitted.modal.real_poles {
            if p.pole >= 0.0 {
                unstable.push(format!("real pole at {:.3e} rad/s", p.pole));
            }
        }
        for (k, d) in fitted.factors.dynamics.iter().enumerate() {
            if !d.is_stable() {
                unstable.push(format!("dynamics factor {k} ({:?})", d.target));
            }
        }
        let me = Self {
            unstable,
            far: Vec::new(),
            w_top,
        };
        let far = fitted
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
                    .filter(|p| !me.supported(p))
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
        Self { far, ..me }
    }

    /// A pair the data can carry: within 1e4 times the band, not critically damped.
    fn supported(&self, p: &realize::PolePair) -> bool {
        p.pole.im <= 1e4 * self.w_top && p.pole.im > CRITICAL_IM * p.pole.norm()
    }

    /// A pair that stays: stable and supported.
    fn keeps(&self, p: &realize::PolePair) -> bool {
        p.pole.re < 0.0 && self.supported(p)
    }

    fn is_empty(&self) -> bool {
        self.unstable.is_empty() && self.far.is_empty()
    }

    fn all(&self) -> Vec<String> {
        self.unstable.iter().chain(&self.far).cloned().collect()
    }

    /// `fitted` without the poles that do not stay.
    fn dropped_from(&self, fitted: &FrfModel) -> FrfModel {
        let mut next = fitted.clone();
        next.modal.pairs.retain(|p| self.keeps(p));
        let w_top = self.w_top;
        next.modal
            .real_poles
            .retain(|p| p.pole < 0.0 && p.pole >= -1e4 * w_top);
        next
    }
}

/// The cost test of a weighted cost `cost` with `dof` complex degrees of freedom: its
/// expected ratio `V / N_dof` (1, or `d / (d - 2)` for a variance of `d > 4` real
/// degrees of freedom per line, `d = 2 (R - 1)` from `R >= 4` realizations) and the
/// p-value of the observed one (`None` without a measured variance).
fn cost_test(measured: bool, variance_dof: Option<f64>, cost: f64, dof: f64) -> (f64, Option<f64>) {
    let ratio = cost / dof;
    if !measured {
        return (1.0, None);
    }
    match variance_dof {
        Some(d2) if d2 > 4.0 => {
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

/// The factor the inverse Fisher information is multiplied by ([`CovarianceScale`]);
/// with a measured variance estimated with `d` degrees of freedom, unless the rule is
/// the plain Fisher information, also by [`sample_variance_factor`].
fn covariance_scale(cfg: &MlConfig, measured: bool, ratio: f64) -> f64 {
    let by_cost = match (cfg.covariance, measured) {
        (CovarianceScale::Fisher, _) => return 1.0,
        (CovarianceScale::CostRatio, _) | (CovarianceScale::Auto, false) => ratio,
        (CovarianceScale::Auto, true) => ratio.max(1.0),
    };
    if measured {
        by_cost * sample_variance_factor(cfg.variance_dof())
    } else {
        by_cost
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

/// The poles and zeros of `dynamics` (the fitted factors, whose coefficients are the
/// nonlinear parameters from index `first` on, [`Layout::dynamics_index`], each
/// factor's denominator then numerator) with their standard deviations, `c` the scaled covariance of the
/// nonlinear parameters. A root `x` of `1 + c_1 x + ... + c_n x^n` moves by
/// `dx/dc_i = -x^i / P'(x)`; the root in rad/s is `sigma x`, and its frequency and
/// damping follow as a mode's ([`mode_uncertainties`]).
fn factor_uncertainties(
    dynamics: &[realize::DynamicsFactor],
    first: usize,
    c: &dyn Fn(usize, usize) -> f64,
) -> Vec<FactorUncertainty> {
    let mut off = first;
    let mut roots_of = |coef: &[f64], sigma: f64| -> Vec<ModeUncertainty> {
        let at = off;
        off += coef.len();
        let Ok(roots) = realize::poly::roots_ascending(coef) else {
            return Vec::new();
        };
        roots
            .into_iter()
            .filter(|x| x.im >= 0.0)
            .map(|x| {
                // P'(x) and dx/dc_i
                let dp: C64 = coef
                    .iter()
                    .enumerate()
                    .map(|(i, &ci)| ci * (i + 1) as f64 * x.powu(i as u32))
                    .sum();
                let dx: Vec<C64> = (0..coef.len())
                    .map(|i| -x.powu(i as u32 + 1) / dp)
                    .collect();
                let s = x * sigma;
                let (a, b) = (s.re, s.im);
                let r = s.norm();
                // f = r / 2 pi, zeta = -a / r, through (a, b) = sigma (Re x, Im x)
                let gf = [a / (r * TAU), b / (r * TAU)];
                let gz = [-b * b / (r * r * r), a * b / (r * r * r)];
                let grad = |g: [f64; 2]| -> Vec<f64> {
                    dx.iter()
                        .map(|d| sigma * (g[0] * d.re + g[1] * d.im))
                        .collect()
                };
                let quad = |g: Vec<f64>| {
                    let mut v = 0.0;
                    for (i, gi) in g.iter().enumerate() {
                        for (j, gj) in g.iter().enumerate() {
                            v += gi * gj * c(at + i, at + j);
                        }
                    }
                    v.max(0.0).sqrt()
                };
                ModeUncertainty {
                    f_hz: r / TAU,
                    f_hz_std: quad(grad(gf)),
                    zeta: -a / r,
                    zeta_std: quad(grad(gz)),
                }
            })
            .collect()
    };
    dynamics
        .iter()
        .map(|d| {
            let poles = roots_of(&d.den, d.scale);
            let zeros = roots_of(&d.num, d.scale);
            FactorUncertainty {
                target: d.target,
                poles,
                zeros,
            }
        })
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use realize::{DynamicsFactor, FactorTarget};

    /// The standard deviations of a factor's root frequency and damping against the
    /// delta method by finite differences of the roots, for a first-order lag, a
    /// second-order factor and a lead-lag's zero, with a full covariance.
    #[test]
    fn factor_roots_carry_the_coefficients_covariance() {
        let lag = DynamicsFactor::first_order(FactorTarget::Input(1), 1800.0);
        let mount = DynamicsFactor::second_order(FactorTarget::Output(0), 1700.0, 0.05);
        let lead = DynamicsFactor::lead_lag(FactorTarget::All, 300.0, 900.0);
        let dynamics = vec![lag, mount, lead];
        // coefficients from index 3 on: lag a1; mount a1, a2; lead a1, b1
        let first = 3;
        let n = first + 5;
        let sd = [0.0, 0.0, 0.0, 2e-3, 4e-3, 3e-3, 1e-3, 5e-3];
        let corr = |i: usize, j: usize| if i == j { 1.0 } else { 0.3 };
        let c = |i: usize, j: usize| sd[i] * sd[j] * corr(i, j);
        let got = factor_uncertainties(&dynamics, first, &c);
        assert_eq!(got.len(), 3);
        assert_eq!(got[0].target, FactorTarget::Input(1));
        assert!((got[0].poles[0].f_hz - 1800.0).abs() < 1e-9);
        // first order: f = sigma / (2 pi a1), std f = f std(a1) / a1 (a1 = 1)
        assert!((got[0].poles[0].f_hz_std - 1800.0 * 2e-3).abs() < 1e-9);
        assert!((got[1].poles[0].zeta - 0.05).abs() < 1e-12);
        assert_eq!(got[2].zeros.len(), 1);
        assert!((got[2].zeros[0].f_hz - 300.0).abs() < 1e-9);
        // finite differences of (f, zeta) of each root in the coefficients
        let roots = |d: &[DynamicsFactor]| -> Vec<(f64, f64)> {
            d.iter()
                .flat_map(|f| {
                    f.poles()
                        .into_iter()
                        .chain(f.zeros())
                        .filter(|p| p.im >= 0.0)
                        .map(|p| (p.norm() / TAU, -p.re / p.norm()))
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let base = roots(&dynamics);
        let h = 1e-7;
        let mut grads = vec![vec![(0.0, 0.0); n]; base.len()];
        for i in first..n {
            let mut d = dynamics.clone();
            let mut k = first;
            for f in &mut d {
                for v in f.den.iter_mut().chain(f.num.iter_mut()) {
                    if k == i {
                        *v += h;
                    }
                    k += 1;
                }
            }
            for (r, moved) in roots(&d).into_iter().enumerate() {
                grads[r][i] = ((moved.0 - base[r].0) / h, (moved.1 - base[r].1) / h);
            }
        }
        let got_roots: Vec<&ModeUncertainty> = got
            .iter()
            .flat_map(|f| f.poles.iter().chain(&f.zeros))
            .collect();
        assert_eq!(got_roots.len(), base.len());
        for (r, g) in grads.iter().enumerate() {
            let var = |pick: &dyn Fn((f64, f64)) -> f64| {
                let mut v = 0.0;
                for i in first..n {
                    for j in first..n {
                        v += pick(g[i]) * pick(g[j]) * c(i, j);
                    }
                }
                v.sqrt()
            };
            let (sf, sz) = (var(&|x| x.0), var(&|x| x.1));
            let u = got_roots[r];
            assert!(
                (u.f_hz_std - sf).abs() <= 1e-4 * sf.max(1e-9),
                "root {r}: f std {} against {sf}",
                u.f_hz_std
            );
            assert!(
                (u.zeta_std - sz).abs() <= 1e-4 * sz.max(1e-6) + 1e-9,
                "root {r}: zeta std {} against {sz}",
                u.zeta_std
            );
        }
    }
}
