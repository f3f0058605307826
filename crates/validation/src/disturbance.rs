//! Deterministic disturbance models from the stochastic disturbance covariance
//! (Section 3 of Oomen and Bosgra, "Well-posed model uncertainty estimation by design of
//! validation experiments") and their averaging over periods (Section 4).
//!
//! **Proposition 9.** A circular complex normal `V ~ N_c(0, C_v)` (the DFT of a filtered
//! white disturbance, Theorem 8) satisfies `P(|V| < sqrt(C_v c_chi / 2)) = alpha` with
//! `c_chi` the `alpha` quantile of `chi^2(2)`; since `2 |V|^2 / C_v ~ chi^2(2)`, whose
//! quantile is `c_chi = -2 ln(1 - alpha)`, the bound (14) is
//! `V~ = sqrt(C_v c_chi / 2) = sqrt(-C_v ln(1 - alpha))`, and with probability `alpha`
//! `V = delta_v V~`, `|delta_v| < 1` (15).
//!
//! **Multivariable (16)-(18).** For `ny` outputs the Hermitian covariance is diagonalised,
//! `C_v = T_V Lambda T_V^H` with `T_V` unitary (ERRATA: eq. (18) is garbled; this is the
//! factorisation meant). The components of `T_V^H V` are independent circular normals
//! with variances `Lambda_q`, so `V = T_V Delta_v V~ 1` with
//! `Delta_v = diag(delta_q)`, `|delta_q| < 1` and `V~_q = sqrt(Lambda_q c_chi / 2)`.
//!
//! **Joint coverage** ([`Coverage`]). The paper applies `alpha` per component. Because
//! the components are independent, the probability that all `ny` of them lie inside
//! their circles is `alpha_c^ny` for a per-component level `alpha_c`: with
//! [`Coverage::JointOutputs`] (the default) `alpha_c = alpha^(1/ny)`, so that the whole
//! disturbance vector of a line lies in the set with probability `alpha` (exactly, for
//! Gaussian disturbances with the covariance known). The DFT lines are asymptotically
//! independent too (Theorem 8), so [`Coverage::JointLines`] with `n_lines` lines uses
//! `alpha_c = alpha^(1/(ny n_lines))` (Sidak): the statement holds on all lines at once
//! with probability `alpha`. [`Coverage::PerComponent`] is the paper's choice (`alpha_c =
//! alpha`). The covariance is itself estimated; the bounds do not widen for that (with
//! `P` periods the relative error of an estimated variance is about `1/sqrt(P - 1)`).
//!
//! **Proposition 10 and eq. (25).** With `n_per` periods of a periodic input, the DFT (6)
//! over the whole record grows as `sqrt(n_per)` at the excited lines while the
//! disturbance DFT keeps its covariance, so the disturbance admissible in the normalised
//! residual `E / |W|` shrinks by `sqrt(n_per)`. In terms of period means (the
//! nonparametric estimator's `Y_bar`, `U_bar`, whose disturbance covariance is the
//! one-period `C_v / n_per`): [`DisturbanceModel::averaged`] divides `V~` by
//! `sqrt(n_per)`. Scaling: the estimator's `C_v` is that of one period's unnormalised DFT;
//! the paper's DFT (6) has a factor `1/sqrt(N)`. Both `W` and `V` carry the same factor,
//! so `V~ / |W|` (all that matters for `gamma`) is the same in either scaling as long as
//! `W`, `Z_m` and `C_v` use the same one.

use crate::cmat::{hermitian_eigen, CMat};
use crate::ValidationError;
use faer::Mat;
use frf_data::C64;
use serde::{Deserialize, Serialize};

/// How the probability `alpha` is shared between outputs and lines (see the module
/// documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Coverage {
    /// `alpha` per component of `T_V^H V` (the paper).
    PerComponent,
    /// `alpha` for the whole output vector of a line: `alpha^(1/ny)` per component.
    #[default]
    JointOutputs,
    /// `alpha` for all outputs on all `n_lines` lines: `alpha^(1/(ny n_lines))` per
    /// component.
    JointLines {
        /// Number of lines the statement covers.
        n_lines: usize,
    },
}

impl Coverage {
    /// The per-component probability level for `ny` outputs.
    pub fn per_component_alpha(&self, alpha: f64, ny: usize) -> f64 {
        match *self {
            Coverage::PerComponent => alpha,
            Coverage::JointOutputs => alpha.powf(1.0 / ny.max(1) as f64),
            Coverage::JointLines { n_lines } => {
                alpha.powf(1.0 / (ny.max(1) * n_lines.max(1)) as f64)
            }
        }
    }
}

/// The `alpha` quantile of the `chi^2(2)` distribution, `-2 ln(1 - alpha)` (exact: the
/// `chi^2(2)` is the exponential distribution with mean 2).
pub fn chi2_2_quantile(alpha: f64) -> f64 {
    -2.0 * (-alpha).ln_1p()
}

/// Checks `0 < alpha < 1`.
pub fn check_alpha(alpha: f64) -> Result<(), ValidationError> {
    if alpha.is_finite() && alpha > 0.0 && alpha < 1.0 {
        Ok(())
    } else {
        Err(ValidationError::config(
            "alpha",
            alpha,
            "a probability strictly between 0 and 1 (for example 0.99)",
        ))
    }
}

/// The deterministic disturbance model `{T_V Delta_v V~ 1 : |delta_q| < 1}` of one
/// line (eq. (16)).
#[derive(Debug, Clone, PartialEq)]
pub struct DisturbanceModel {
    /// The coordinate transformation `T_V` (`ny x ny`; unitary when it comes from a
    /// covariance).
    pub t_v: Mat<C64>,
    /// The radii `V~_q` (the diagonal of `V~`).
    pub v_tilde: Vec<f64>,
}

impl DisturbanceModel {
    /// Proposition 9 for a scalar variance `C_v` at per-component level `alpha_c`.
    pub fn scalar(c_v: f64, alpha_c: f64) -> Result<Self, ValidationError> {
        check_alpha(alpha_c)?;
        if !(c_v.is_finite() && c_v >= 0.0) {
            return Err(ValidationError::invalid_input(
                "disturbance variance",
                format!("{c_v} is not a finite non-negative number"),
            ));
        }
        Ok(Self {
            t_v: Mat::from_fn(1, 1, |_, _| C64::new(1.0, 0.0)),
            v_tilde: vec![(c_v * chi2_2_quantile(alpha_c) / 2.0).sqrt()],
        })
    }

    /// Eqs. (14)-(18): `C_v = T_V Lambda T_V^H` (Hermitian eigen-decomposition, `T_V`
    /// unitary) and `V~_q = sqrt(Lambda_q c_chi / 2)` at the per-component level of
    /// `coverage`. `c_v` is `ny x ny`; negative eigenvalues down to `-1e-12` of the largest
    /// (rounding) are set to zero, larger ones are an error.
    pub fn from_covariance(
        c_v: &Mat<C64>,
        alpha: f64,
        coverage: Coverage,
    ) -> Result<Self, ValidationError> {
        check_alpha(alpha)?;
        let ny = c_v.nrows();
        if ny == 0 || c_v.ncols() != ny {
            return Err(ValidationError::dimension(
                "disturbance covariance",
                "a square matrix with at least one row",
                format!("{} x {}", c_v.nrows(), c_v.ncols()),
            ));
        }
        let c = CMat::from_faer(c_v);
        if !c.is_finite() {
            return Err(ValidationError::invalid_input(
                "disturbance covariance",
                "an entry is not finite",
            ));
        }
        let (w, v) = hermitian_eigen(&c);
        let top = w.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
        if let Some(bad) = w.iter().find(|l| **l < -1e-12 * top.max(f64::MIN_POSITIVE)) {
            return Err(ValidationError::invalid_input(
                "disturbance covariance",
                format!("it is not positive semidefinite (eigenvalue {bad:.3e})"),
            ));
        }
        let c_chi = chi2_2_quantile(coverage.per_component_alpha(alpha, ny));
        Ok(Self {
            t_v: v.to_faer(),
            v_tilde: w
                .iter()
                .map(|l| (l.max(0.0) * c_chi / 2.0).sqrt())
                .collect(),
        })
    }

    /// Independent outputs with variances `var_q` (`T_V = I`), as when only per-entry
    /// variances are known.
    pub fn from_variances(
        var: &[f64],
        alpha: f64,
        coverage: Coverage,
    ) -> Result<Self, ValidationError> {
        check_alpha(alpha)?;
        if let Some((q, v)) = var
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
        {
            return Err(ValidationError::invalid_input(
                "disturbance variance",
                format!("output {} has variance {v}", q + 1),
            ));
        }
        let c_chi = chi2_2_quantile(coverage.per_component_alpha(alpha, var.len()));
        Ok(Self {
            t_v: Mat::from_fn(var.len(), var.len(), |i, j| {
                C64::new(if i == j { 1.0 } else { 0.0 }, 0.0)
            }),
            v_tilde: var.iter().map(|v| (v * c_chi / 2.0).sqrt()).collect(),
        })
    }

    /// The factor on the radii when the variance was estimated with `dof` real degrees
    /// of freedom instead of known, at per-component level `alpha_c`: a complex Gaussian
    /// `e` with variance `s^2` has `2 |e|^2 / s^2 ~ chi^2(2)`, the estimate `v` (independent
    /// of the mean) has `dof v / s^2 ~ chi^2(dof)`, so `|e|^2 / v ~ F(2, dof)` and the
    /// radius `sqrt(v F_{2,dof}(alpha_c))` replaces `sqrt(v c_chi / 2)`. The factor is
    /// `sqrt(2 F_{2,dof}(alpha_c) / c_chi) >= 1`, tending to 1 as `dof` grows.
    pub fn estimated_variance_factor(alpha_c: f64, dof: f64) -> f64 {
        let c_chi = chi2_2_quantile(alpha_c);
        let c_f = crate::stats::f_isf(1.0 - alpha_c, 2.0, dof);
        if c_f.is_finite() && c_chi > 0.0 {
            (2.0 * c_f / c_chi).sqrt().max(1.0)
        } else {
            1.0
        }
    }

    /// The factor on a variance whose error need not be circular, at per-component
    /// level `alpha_c`: a complex Gaussian error whose variance lies along one direction
    /// of the complex plane (a model's response error from a few parameters often does)
    /// has `|e|^2 / v ~ chi^2(1)`, not `chi^2(2) / 2`; its `alpha_c` quantile
    /// `z^2` (`z` the normal quantile of `(1 + alpha_c) / 2`) over `c_chi / 2` is the
    /// factor (1.49 at `alpha_c = 0.995`, 1.72 at `1 - 2e-6`), the worst case over the
    /// shapes of the error's real covariance. `>= 1`.
    pub fn non_circular_factor(alpha_c: f64) -> f64 {
        let c_chi = chi2_2_quantile(alpha_c);
        let z = crate::stats::normal_quantile(0.5 * (1.0 + alpha_c));
        if c_chi > 0.0 && z.is_finite() {
            (2.0 * z * z / c_chi).max(1.0)
        } else {
            1.0
        }
    }

    /// The same model with every radius times `factor`.
    pub fn scaled(mut self, factor: f64) -> Self {
        for v in &mut self.v_tilde {
            *v *= factor;
        }
        self
    }

    /// Proposition 10 / eq. (25): the model of the mean over `n_per` periods (radii
    /// divided by `sqrt(n_per)`).
    pub fn averaged(&self, n_per: usize) -> Self {
        let s = 1.0 / (n_per.max(1) as f64).sqrt();
        Self {
            t_v: self.t_v.clone(),
            v_tilde: self.v_tilde.iter().map(|v| v * s).collect(),
        }
    }

    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.v_tilde.len()
    }

    /// The largest radius `max_q V~_q`.
    pub fn max_radius(&self) -> f64 {
        self.v_tilde.iter().copied().fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// An error along one real direction with complex variance `v` (`|e|^2 / v ~
    /// chi^2(1)`) lies inside the radius `sqrt(kappa v c_chi / 2)` with probability
    /// exactly `alpha_c`; the factor is 1.49 at 0.995 and grows in the tail.
    #[test]
    fn the_non_circular_factor_covers_an_error_along_one_direction() {
        for alpha_c in [0.9, 0.995, 1.0 - 2e-6] {
            let kappa = DisturbanceModel::non_circular_factor(alpha_c);
            let r = (kappa * chi2_2_quantile(alpha_c) / 2.0).sqrt();
            let outside = 2.0 * crate::stats::normal_sf(r);
            assert!(
                (outside - (1.0 - alpha_c)).abs() < 1e-6 * (1.0 - alpha_c),
                "{alpha_c}: {outside}"
            );
            assert!(kappa >= 1.0);
        }
        assert!((DisturbanceModel::non_circular_factor(0.995) - 1.487).abs() < 2e-3);
    }

    #[test]
    fn chi2_2_quantile_matches_the_general_quantile() {
        for a in [0.5, 0.9, 0.95, 0.99, 0.999] {
            let q = chi2_2_quantile(a);
            assert!((crate::stats::chi2_cdf(q, 2.0) - a).abs() < 1e-10);
        }
    }

    /// Proposition 9 by simulation: circular normal draws fall inside the radius with
    /// frequency alpha; the multivariable model covers the whole vector with frequency
    /// alpha under JointOutputs.
    #[test]
    fn coverage_of_the_disturbance_model_is_alpha() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut n = || -> f64 { StandardNormal.sample(&mut rng) };
        let alpha = 0.9;
        let trials = 40_000;
        // SISO with variance 3
        let m = DisturbanceModel::scalar(3.0, alpha).unwrap();
        let mut inside = 0;
        for _ in 0..trials {
            let v = C64::new(n(), n()) * (3.0_f64 / 2.0).sqrt();
            if v.norm() < m.v_tilde[0] {
                inside += 1;
            }
        }
        let f = inside as f64 / trials as f64;
        assert!((f - alpha).abs() < 0.006, "SISO coverage {f}");
        // 2 outputs, correlated: C = L L^H
        let l = [[1.0, 0.0], [0.8, 0.5]];
        let c = Mat::from_fn(2, 2, |i, j| {
            C64::new((0..2).map(|k| l[i][k] * l[j][k]).sum::<f64>(), 0.0)
        });
        let m = DisturbanceModel::from_covariance(&c, alpha, Coverage::JointOutputs).unwrap();
        let mut inside = 0;
        for _ in 0..trials {
            let e = [
                C64::new(n(), n()) / 2f64.sqrt(),
                C64::new(n(), n()) / 2f64.sqrt(),
            ];
            let v: Vec<C64> = (0..2).map(|i| l[i][0] * e[0] + l[i][1] * e[1]).collect();
            // components in the T_V basis
            let ok = (0..2).all(|q| {
                let c: C64 = (0..2).map(|i| m.t_v[(i, q)].conj() * v[i]).sum();
                c.norm() < m.v_tilde[q]
            });
            if ok {
                inside += 1;
            }
        }
        let f = inside as f64 / trials as f64;
        assert!((f - alpha).abs() < 0.006, "joint coverage {f}");
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(DisturbanceModel::scalar(-1.0, 0.9).is_err());
        assert!(DisturbanceModel::scalar(1.0, 1.0).is_err());
        let c = Mat::from_fn(2, 2, |i, j| C64::new(if i == j { 0.0 } else { 1.0 }, 0.0));
        let e = DisturbanceModel::from_covariance(&c, 0.9, Coverage::PerComponent).unwrap_err();
        assert!(e.to_string().contains("positive semidefinite"), "{e}");
    }
}
