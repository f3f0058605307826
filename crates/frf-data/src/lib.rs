//! # frf-data: FRF datasets and the traits every frfit estimator shares
//!
//! - [`FrfDataset`] (implemented by the owning [`Frf`] and the zero-copy [`FrfView`]):
//!   frequencies, `ny x nu` complex matrices per line, optional per-entry variance;
//! - [`ModelStructure`] and [`Estimator`] with the [`Fit`] result (and the method's own
//!   report); the estimator chain ([`chain`]): [`Initializer`] and [`Refiner`] links that
//!   hand on one model currency, [`realize::FrfModel`] ([`ChainModel`]);
//! - weightings of the least-squares criterion ([`Weighting`]);
//! - formats: the FRF CSV of `FORMATS.md` and UFF 58 ([`io`]), the truth JSON of
//!   simulated and reference plants ([`truth`]);
//! - the CMIF and its peak picker ([`cmif`]), delay estimation and compensation
//!   ([`delay`]);
//! - locating the shared reference data for tests ([`shared_data`]).
//!
//! It depends on `realize` (models) and the numerics only: an estimator crate needs
//! `frf-data` and `realize` and nothing heavier. Simulated plants and experiments and the
//! nonparametric FRF estimation from periodic data (FFT, random streams, MATLAB files)
//! are in the `experiment` crate.

pub mod chain;
pub mod cmif;
pub mod currency;
pub mod dataset;
pub mod delay;
pub mod error;
pub mod estimator;
pub mod frf;
pub mod io;
pub mod model;
pub mod shared_data;
pub mod stats;
pub mod structure;
pub mod truth;
pub mod twins;
pub mod uncertainty;
pub mod view;
pub mod weighting;

pub use chain::{
    ChainError, ChainModel, ChainOutput, ChainSettings, DelayChoice, InitLink, Initializer,
    LinkDetails, LinkReport, ModeSelection, Precomputed, RefineLink, Refiner,
};
pub use dataset::FrfDataset;
pub use error::{FormatProblem, FrfError};
pub use estimator::{Convergence, Estimator, Fit, Progress, ProgressFn, ProgressSink, Timing};
pub use frf::Frf;
pub use model::ModelStructure;
pub use view::FrfView;
pub use weighting::{proportional_groups, WeightGroup, Weighting};

/// Complex double (the same type as `faer::c64` and `realize::C64`).
pub type C64 = num_complex::Complex<f64>;
