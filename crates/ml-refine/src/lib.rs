//! # ml-refine: maximum-likelihood refinement with parameter uncertainty
//!
//! Gauss-Newton / Levenberg-Marquardt on McKelvey's frequency-domain ML criterion (23)
//! with the measured variance as the fixed noise model (or the weighted least-squares
//! criterion with the noise scale from the residual when there is no variance), for the
//! model currency of the estimator chain ([`realize::FrfModel`]): pole pairs, real
//! poles, rigid body, feedthrough, crosstalk, delay and dynamics factors, through the
//! exact zero-order hold when the model declares one.
//!
//! - [`MlRefine`] (`--refine ml`): a `frf_data::Estimator` from any chain model, with a
//!   serialisable [`MlReport`] (cost history, cost test, per-mode `f_hz_std` and
//!   `zeta_std`, `delay_s_std`);
//! - [`varpro`]: the residues, rigid body and feedthrough are eliminated per entry
//!   (variable projection), so the work is linear in lines and entries;
//! - [`jacobian`]: the analytic Jacobian of the currency in its parameter order
//!   ([`AnalyticModel`] is the currency with it), checked against finite differences;
//! - covariance at the optimum: the inverse Fisher information (McKelvey eq.
//!   (30)-(32)) and the delta method for frequencies and damping.

mod basis;
pub mod config;
pub mod error;
mod gram;
pub mod jacobian;
pub mod lm;
mod qr;
pub mod refine;
mod search;
mod shared;
pub mod stats;
pub mod varpro;
mod weight_groups;

pub use config::{sample_variance_factor, CovarianceScale, MlConfig};
pub use error::MlError;
/// The typed structure steps ([`MlReport::structure_steps`]), from the workspace's one
/// definition ([`frf_data::structure`]).
pub use frf_data::structure::{ModeTest, StructureChange, StructureStep};
pub use jacobian::{currency_jacobian_into, AnalyticModel};
pub use lm::LmSettings;
pub use refine::{FactorUncertainty, MlRefine, MlReport, ModeUncertainty};
pub use varpro::ResidueForm;

/// Complex double.
pub type C64 = num_complex::Complex<f64>;
