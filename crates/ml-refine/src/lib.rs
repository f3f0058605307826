//! # ml-refine: Gauss-Newton / Levenberg-Marquardt on the weighted or ML criterion
//!
//! Will hold (a later issue): a refiner for any `frf_data::ModelStructure` with a
//! Jacobian (analytic or the finite-difference default), minimising the weighted least
//! squares criterion (8) of the wafer-stage paper, which is the maximum-likelihood
//! criterion (McKelvey eq. (23)) with inverse-variance weights; parameter covariance
//! from the Jacobian at the optimum (McKelvey eq. (30)-(32)) and confidence bounds.
