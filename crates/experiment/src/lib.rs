//! # experiment: periodic experiments, measured or simulated, and their nonparametric FRF
//!
//! The step before a parametric fit: from the time records or spectra of a periodic
//! experiment to an FRF with its variance, and simulated plants and experiments with a
//! known truth to test every estimator against.
//!
//! - [`nonparametric`]: the nonparametric MIMO FRF from periodic experiments
//!   (`P` periods x `R` realizations, closed-loop safe), its noise and total variance and
//!   the output disturbance covariance; the data come from the simulator, a periodic
//!   spectra CSV ([`nonparametric::spectra_csv`]) or measured time records
//!   ([`nonparametric::time_records`], read from MATLAB files by [`matfile`]);
//! - [`synth`]: simulated plants (the additive modal plant, the wafer-stage testbed of
//!   the paper) and closed-loop multisine experiments on them, seeded and portable, with
//!   the truth they write as [`frf_data::truth::Truth`].
//!
//! It depends on `frf-data` (the [`frf_data::Frf`] it produces, the truth JSON, the error
//! type [`frf_data::FrfError`]) and `realize` (exact zero-order-hold discretization);
//! the FFT, the random streams and the MATLAB reader are its own dependencies, so an
//! estimator crate that only fits FRFs does not pull them in. Estimator crates use it
//! as a dev-dependency for their tests against simulated truth.

pub mod matfile;
pub mod nonparametric;
pub mod synth;

pub use nonparametric::{estimate, EstimatorConfig, NonparametricFrf, PeriodicSpectra};
pub use synth::{WaferStageConfig, WaferStageExperiment};
