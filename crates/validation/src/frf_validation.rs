//! Validation of a model against an independent nonparametric FRF measurement (the
//! FDMVOP of Oomen and Bosgra per line, [`crate::invalidation`]), independent of how the
//! model was made: only its response at the validation lines is needed.
//!
//! **Per line and input.** The validation FRF `G` (period means, `G = Y_bar U_bar^-1`)
//! is read as `nu` experiments, experiment `j` with the unit input `W = e_j` and the
//! measured output `Z_m = G[:, j]`; the nominal residual is `E[:, j] = G[:, j] -
//! P^[:, j]`. Its disturbance is the estimate's noise in that column: with the
//! disturbance covariance `C_v` of the measurement, `C_v s_j` with `s_j` the mean over
//! outputs of `var(G[i, j]) / C_v[i, i]` (the factor `sum_e |U_bar^-1[e, j]|^2 / P` of
//! the estimator, eq. (25)'s averaging included); without it the per-entry variances
//! with `T_V = I`. [`crate::DisturbanceModel`] turns it into radii (Prop. 9, coverage
//! [`Coverage`], default `alpha` for the whole output vector of a column). The smallest
//! additive uncertainty explaining column `j` is `gamma_j` ([`min_gamma_additive`]: exact
//! for additive uncertainty; [`GammaMethod::Mu`] runs the mu bisection of
//! [`min_gamma`] instead, same value to its tolerance where the bounds are tight).
//!
//! **The line's gamma.** One `Delta_u` must explain all columns. Each column needs
//! `|Delta_u e_j| >= gamma_j`, so `gamma_lower = max_j gamma_j` is necessary; the
//! columns `r_j` the uncertainty explains in each column's solution form one admissible
//! `Delta_u = [r_1 ... r_nu]`, so `gamma = sigma_max([r_1 ... r_nu])` suffices (for one
//! input both are the same). [`LineValidation::gamma`] is that certified value.
//!
//! **Verdict.** The model is `invalidated_at_zero_uncertainty` when some line has a
//! column the disturbance cannot explain on its own at the joint level (coverage
//! [`Coverage::JointLines`] over all lines and inputs: the true system is declared
//! invalid with probability at most `1 - alpha` over the whole band), otherwise
//! `not_invalidated`.

use crate::cmat::CMat;
use crate::disturbance::{check_alpha, Coverage, DisturbanceModel};
use crate::invalidation::{min_gamma, min_gamma_additive, GammaConfig, LineData, UncertaintyModel};
use crate::stats::median;
use crate::ValidationError;
use faer::Mat;
use frf_data::{FrfDataset, C64};
use rayon::prelude::*;
use realize::ResponseGrid;
use serde::{Deserialize, Serialize};

/// How each column's minimum `gamma` is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GammaMethod {
    /// The exact additive closed form (default).
    #[default]
    ClosedForm,
    /// The mu bisection (Proposition 12).
    Mu,
}

/// Settings of [`validate_frf`].
#[derive(Debug, Clone, PartialEq)]
pub struct FrfValidationConfig {
    /// Probability level (default 0.99).
    pub alpha: f64,
    /// Coverage of the per-line gammas (default [`Coverage::JointOutputs`]).
    pub coverage: Coverage,
    /// Method (default [`GammaMethod::ClosedForm`]).
    pub method: GammaMethod,
    /// Bisection settings for [`GammaMethod::Mu`].
    pub gamma: GammaConfig,
    /// Real degrees of freedom of the data's variance when it was estimated (`2 (R - 1)`
    /// for `R` realizations); `None` (default): the variance is taken as exact. With an
    /// estimated variance `|e|^2 / var_hat` of a complex Gaussian `e` is `F(2, d)`
    /// distributed, not `chi^2(2) / 2`: the radii use the `F(2, d)` quantile
    /// ([`DisturbanceModel::with_estimated_variance`]), so that a model at the truth is
    /// not invalidated by a variance estimated from few realizations.
    pub variance_dof: Option<f64>,
}

impl Default for FrfValidationConfig {
    fn default() -> Self {
        Self {
            alpha: 0.99,
            coverage: Coverage::JointOutputs,
            method: GammaMethod::ClosedForm,
            gamma: GammaConfig::default(),
            variance_dof: None,
        }
    }
}

/// The verdict of the validation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The disturbance model explains the residual on every line.
    NotInvalidated,
    /// Some line needs a nonzero uncertainty.
    InvalidatedAtZeroUncertainty,
}

/// The result at one line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineValidation {
    /// Frequency, Hz.
    pub f_hz: f64,
    /// Certified minimum additive uncertainty `sigma_max(Delta_u)`.
    pub gamma: f64,
    /// Necessary minimum (`max_j gamma_j`).
    pub gamma_lower: f64,
    /// The largest disturbance radius of the line (`max_j max_q V~_q`, FRF units).
    pub disturbance_bound: f64,
    /// `sigma_max(G - P^)`, the nominal model error seen by the data.
    pub model_error: f64,
    /// With the model's own uncertainty ([`validate_frf_with_model_std`]): the largest
    /// radius of the line that the model's response variance alone gives (FRF units,
    /// the same coverage as `disturbance_bound`). `None` without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_bound: Option<f64>,
    /// With the model's own uncertainty: the certified minimum additive uncertainty
    /// beyond the data's disturbance and the model's own estimation error (the residual
    /// `G - P^` read with the covariance of both): what the model's structure misses.
    /// `None` without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gamma_beyond_model: Option<f64>,
}

/// The validation read with the model's own uncertainty next to the data's
/// ([`validate_frf_with_model_std`]): the residual `G - P^` of an independent
/// measurement has the covariance of the data's disturbance plus that of the model's
/// response (the model's estimation error, independent of the validation data).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BeyondModelUncertainty {
    /// The verdict when the residual may also be the model's own estimation error: a
    /// model whose residual both explain is not invalidated.
    pub verdict: Verdict,
    /// Lines the data's disturbance and the model's uncertainty together do not explain
    /// (joint level).
    pub lines_invalidated_at_zero: usize,
    /// Largest `gamma_beyond_model`.
    pub gamma_max: f64,
    /// Median `gamma_beyond_model`.
    pub gamma_median: f64,
    /// Largest `model_bound` over the lines.
    pub model_bound_max: f64,
    /// Median over the lines of the model's largest radius against the data's
    /// (`model_bound / disturbance_bound`): below 1 the validation data's noise
    /// dominates, above 1 the model's own uncertainty does.
    pub model_to_disturbance_median: f64,
}

/// The result of [`validate_frf`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrfValidation {
    /// Probability level.
    pub alpha: f64,
    /// Per line.
    pub lines: Vec<LineValidation>,
    /// Verdict at the joint level (see the module documentation).
    pub verdict: Verdict,
    /// Largest `gamma`.
    pub gamma_max: f64,
    /// Median `gamma`.
    pub gamma_median: f64,
    /// Lines where the disturbance alone does not explain the residual at the joint
    /// level (the verdict's evidence).
    pub lines_invalidated_at_zero: usize,
    /// Degrees of freedom of the estimated variance the radii account for (`None`: the
    /// variance was taken as exact).
    #[serde(default)]
    pub variance_dof: Option<f64>,
    /// The same validation with the model's own uncertainty next to the data's
    /// ([`validate_frf_with_model_std`]); `None` when the model's response standard
    /// deviation was not given. `verdict` and `gamma` above are the data's alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beyond_model_uncertainty: Option<BeyondModelUncertainty>,
}

/// One line's validation, whether some column is unexplained at the joint level by the
/// data's disturbance, and by it with the model's own uncertainty (when given).
type LineOutcome = (LineValidation, bool, Option<bool>);

/// Validates the model response `model` (at the data's lines) against the validation
/// FRF `data` with its variance, optionally with the disturbance covariance `C_v` per
/// line (`ny x ny` column-major, line after line, as the nonparametric estimator gives
/// it). See the module documentation.
pub fn validate_frf(
    model: &ResponseGrid,
    data: &(impl FrfDataset + Sync + ?Sized),
    covariance: Option<&[C64]>,
    cfg: &FrfValidationConfig,
) -> Result<FrfValidation, ValidationError> {
    validate_frf_with_model_std(model, None, data, covariance, cfg)
}

/// [`validate_frf`] with the model's own uncertainty next to the data's: `model_std` is
/// the standard deviation of the model's response at the data's lines and entries
/// (layout `[k * m + e]`, `e = j * ny + i`, `sqrt(E |P^ - E P^|^2)`, from the
/// parameters' covariance on the data the model was fitted to). The estimate's error
/// is independent of the validation measurement's noise, so the residual `G - P^` of a
/// model at the truth has the covariance of both: each column's disturbance gets the
/// model's variances on its diagonal. The model's error comes from a few parameters and
/// need not be circular in the complex plane: its variances are taken at the quantile of
/// an error along one direction ([`DisturbanceModel::non_circular_factor`], the worst
/// case over the error's shape; without it a fitted model's error exceeded its circular
/// radius about three times as often as the coverage says). The data's own verdict and `gamma` are computed
/// as [`validate_frf`] does; [`FrfValidation::beyond_model_uncertainty`] and the
/// lines' `gamma_beyond_model` and `model_bound` hold the reading with both. A NaN or
/// negative standard deviation is an error that names the line and entry.
pub fn validate_frf_with_model_std(
    model: &ResponseGrid,
    model_std: Option<&[f64]>,
    data: &(impl FrfDataset + Sync + ?Sized),
    covariance: Option<&[C64]>,
    cfg: &FrfValidationConfig,
) -> Result<FrfValidation, ValidationError> {
    check_alpha(cfg.alpha)?;
    let (ny, nu, nl) = (data.ny(), data.nu(), data.n_lines());
    let m = ny * nu;
    if model.len() != nl || model.ny != ny || model.nu != nu {
        return Err(ValidationError::dimension(
            "model response vs validation data",
            format!("{nl} lines of {ny} x {nu}"),
            format!("{} lines of {} x {}", model.len(), model.ny, model.nu),
        ));
    }
    if nl == 0 {
        return Err(ValidationError::TooFewLines {
            what: "validation".into(),
            needed: 1,
            got: 0,
        });
    }
    if !data.has_variance() {
        return Err(ValidationError::invalid_input(
            "validation data",
            "no variance: validation needs the `_var` columns of a periodic (averaged) \
             measurement to bound the disturbance",
        ));
    }
    if let Some(c) = covariance {
        if c.len() != nl * ny * ny {
            return Err(ValidationError::dimension(
                "disturbance covariance vs validation data",
                format!("{} values ({nl} lines of {ny} x {ny})", nl * ny * ny),
                format!("{} values", c.len()),
            ));
        }
    }
    if let Some(sd) = model_std {
        if sd.len() != nl * m {
            return Err(ValidationError::dimension(
                "model response standard deviation vs validation data",
                format!("{} values ({nl} lines of {ny} x {nu})", nl * m),
                format!("{} values", sd.len()),
            ));
        }
        if let Some((idx, v)) = sd
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
        {
            let (k, e) = (idx / m, idx % m);
            return Err(ValidationError::invalid_input(
                "model response standard deviation",
                format!(
                    "line {} ({} Hz), entry ({}, {}): {v}",
                    k + 1,
                    data.freq_hz(k),
                    e % ny + 1,
                    e / ny + 1
                ),
            ));
        }
    }
    let joint = Coverage::JointLines { n_lines: nl * nu };
    if let Some(d) = cfg.variance_dof {
        if !(d.is_finite() && d > 0.0) {
            return Err(ValidationError::config(
                "variance_dof",
                d,
                "degrees of freedom of the variance estimate must be > 0 (2 (R - 1) for R realizations)",
            ));
        }
    }
    // the widening of the radii for an estimated variance, once per coverage
    let widen = |cov: Coverage| {
        cfg.variance_dof.map_or(1.0, |d| {
            DisturbanceModel::estimated_variance_factor(cov.per_component_alpha(cfg.alpha, ny), d)
        })
    };
    let (widen_line, widen_joint) = (widen(cfg.coverage), widen(joint));
    let unc = UncertaintyModel::additive(ny, nu);
    // one line at a time, independent of the others: the lines run in parallel (the mu
    // bisection costs milliseconds per column); the first failing line is reported
    let one_line = |k: usize| -> Result<LineOutcome, ValidationError> {
        let mut var = vec![0.0; m];
        let f = data.freq_hz(k);
        data.variance_line_into(k, &mut var);
        if let Some((e, v)) = var
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
        {
            return Err(ValidationError::invalid_input(
                "validation data",
                format!(
                    "line {} ({f} Hz), entry ({}, {}): variance {v}",
                    k + 1,
                    e % ny + 1,
                    e / ny + 1
                ),
            ));
        }
        let g = data.matrix(k);
        let p = model.matrix(k);
        if !CMat::from_faer(&g).is_finite() || !CMat::from_faer(&p).is_finite() {
            return Err(ValidationError::invalid_input(
                "validation line",
                format!(
                    "line {} ({f} Hz): a data or model value is not finite",
                    k + 1
                ),
            ));
        }
        let err = Mat::from_fn(ny, nu, |i, j| g[(i, j)] - p[(i, j)]);
        let model_error = CMat::from_faer(&err).sigma_max();
        let model_var: Option<Vec<f64>> =
            model_std.map(|sd| sd[k * m..(k + 1) * m].iter().map(|s| s * s).collect());
        // the data's disturbance of column `j` at `coverage`, widened by `widen` for an
        // estimated variance, plus the model's variances `add` (not widened: they are
        // not estimated from the validation data)
        let column_model = |j: usize,
                            coverage: Coverage,
                            widen: f64,
                            add: Option<&[f64]>|
         -> Result<DisturbanceModel, ValidationError> {
            let colvar = &var[j * ny..(j + 1) * ny];
            let w2 = widen * widen;
            // the model's error need not be circular: its variance at the 1-D quantile
            let kappa =
                DisturbanceModel::non_circular_factor(coverage.per_component_alpha(cfg.alpha, ny));
            match covariance {
                Some(c) => {
                    let cv = &c[k * ny * ny..(k + 1) * ny * ny];
                    let (mut s, mut n) = (0.0, 0);
                    for i in 0..ny {
                        let cii = cv[i * ny + i].re;
                        if cii > 0.0 {
                            s += colvar[i] / cii;
                            n += 1;
                        }
                    }
                    let s = if n > 0 { s / n as f64 } else { 0.0 };
                    let mm = Mat::from_fn(ny, ny, |a, b| {
                        let extra = match add {
                            Some(mv) if a == b => kappa * mv[j * ny + a],
                            _ => 0.0,
                        };
                        cv[b * ny + a] * (s * w2) + C64::new(extra, 0.0)
                    });
                    DisturbanceModel::from_covariance(&mm, cfg.alpha, coverage)
                }
                None => {
                    let v: Vec<f64> = (0..ny)
                        .map(|i| colvar[i] * w2 + add.map_or(0.0, |mv| kappa * mv[j * ny + i]))
                        .collect();
                    DisturbanceModel::from_variances(&v, cfg.alpha, coverage)
                }
            }
        };
        // gamma (certified and necessary), the largest radius, and whether some column
        // is not explained at the joint level, with the model's variances `add` or not
        let read = |add: Option<&[f64]>| -> Result<(f64, f64, f64, bool), ValidationError> {
            let mut r = CMat::zeros(ny, nu);
            let mut gamma_lower: f64 = 0.0;
            let mut dbound: f64 = 0.0;
            let mut invalid_here = false;
            for j in 0..nu {
                let dist = column_model(j, cfg.coverage, widen_line, add)?;
                let line = LineData {
                    w: (0..nu)
                        .map(|c| C64::new(if c == j { 1.0 } else { 0.0 }, 0.0))
                        .collect(),
                    z_m: (0..ny).map(|i| g[(i, j)]).collect(),
                    nominal: p.clone(),
                };
                dbound = dbound.max(dist.max_radius());
                let (gj_lower, rj) = match cfg.method {
                    GammaMethod::ClosedForm => min_gamma_additive(&line, &dist)?,
                    GammaMethod::Mu => {
                        let m = min_gamma(&unc, &line, &dist, &cfg.gamma)?;
                        (m.gamma_lower, m.explained_by_uncertainty)
                    }
                };
                gamma_lower = gamma_lower.max(gj_lower);
                for i in 0..ny {
                    r[(i, j)] = rj[i];
                }
                // the verdict at the joint level: does the disturbance alone explain it?
                let dj = column_model(j, joint, widen_joint, add)?;
                let (g0, _) = min_gamma_additive(&line, &dj)?;
                if g0 > 0.0 {
                    invalid_here = true;
                }
            }
            Ok((
                r.sigma_max().max(gamma_lower),
                gamma_lower,
                dbound,
                invalid_here,
            ))
        };
        let (gamma, gamma_lower, dbound, invalid_here) = read(None)?;
        let (model_bound, beyond) = match &model_var {
            Some(mv) => {
                let mut bound: f64 = 0.0;
                let kappa = DisturbanceModel::non_circular_factor(
                    cfg.coverage.per_component_alpha(cfg.alpha, ny),
                );
                for j in 0..nu {
                    let col: Vec<f64> =
                        mv[j * ny..(j + 1) * ny].iter().map(|v| kappa * v).collect();
                    let d = DisturbanceModel::from_variances(&col, cfg.alpha, cfg.coverage)?;
                    bound = bound.max(d.max_radius());
                }
                let (g_b, _, _, inv_b) = read(Some(mv))?;
                (Some(bound), Some((g_b, inv_b)))
            }
            None => (None, None),
        };
        Ok((
            LineValidation {
                f_hz: f,
                gamma,
                gamma_lower,
                disturbance_bound: dbound,
                model_error,
                model_bound,
                gamma_beyond_model: beyond.map(|b| b.0),
            },
            invalid_here,
            beyond.map(|b| b.1),
        ))
    };
    let results: Vec<Result<LineOutcome, ValidationError>> =
        (0..nl).into_par_iter().map(one_line).collect();
    let mut lines = Vec::with_capacity(nl);
    let mut n_invalid = 0;
    let mut n_invalid_beyond = 0;
    for r in results {
        let (line, invalid_here, invalid_beyond) = r?;
        n_invalid += usize::from(invalid_here);
        n_invalid_beyond += usize::from(invalid_beyond == Some(true));
        lines.push(line);
    }
    let verdict_of = |n: usize| {
        if n > 0 {
            Verdict::InvalidatedAtZeroUncertainty
        } else {
            Verdict::NotInvalidated
        }
    };
    let gammas: Vec<f64> = lines.iter().map(|l| l.gamma).collect();
    let beyond_model_uncertainty = model_std.map(|_| {
        let gb: Vec<f64> = lines.iter().filter_map(|l| l.gamma_beyond_model).collect();
        let bounds: Vec<f64> = lines.iter().filter_map(|l| l.model_bound).collect();
        let ratios: Vec<f64> = lines
            .iter()
            .filter(|l| l.disturbance_bound > 0.0)
            .filter_map(|l| l.model_bound.map(|b| b / l.disturbance_bound))
            .collect();
        BeyondModelUncertainty {
            verdict: verdict_of(n_invalid_beyond),
            lines_invalidated_at_zero: n_invalid_beyond,
            gamma_max: gb.iter().copied().fold(0.0, f64::max),
            gamma_median: median(&gb),
            model_bound_max: bounds.iter().copied().fold(0.0, f64::max),
            model_to_disturbance_median: if ratios.is_empty() {
                f64::NAN
            } else {
                median(&ratios)
            },
        }
    });
    Ok(FrfValidation {
        alpha: cfg.alpha,
        gamma_max: gammas.iter().copied().fold(0.0, f64::max),
        gamma_median: median(&gammas),
        verdict: verdict_of(n_invalid),
        lines_invalidated_at_zero: n_invalid,
        lines,
        variance_dof: cfg.variance_dof,
        beyond_model_uncertainty,
    })
}
