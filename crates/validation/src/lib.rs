//! # validation: residuals against the noise level, diagnosis evidence, model validation
//!
//! Holds the residual analysis of the residual-diagnosis loop (DESIGN.md, "The
//! residual-diagnosis loop"; step 2 of the pipeline issue): the residual `E = G - P` per
//! line and entry against the noise level, with a calibrated significance test, and the
//! structure of a significant residual for the loop in the `frfit` crate to trace to an
//! effect the model lacks. A later issue adds nonparametric disturbance bounds and
//! mu-based model invalidation (Oomen-Bosgra).
//!
//! - [`noise`]: the noise level per line and entry: the data's `_var` columns, or an
//!   estimate from the roughness of the data across neighbouring lines (say so in
//!   reports: [`NoiseSource`]).
//! - [`residual`]: [`analyze_residual`] (relative errors, residual-to-noise ratio per
//!   line, the calibrated chi-square test, magnitude trend, row/column concentration,
//!   and every signature below, ranked as [`EffectEvidence`]); [`relative_error_stats`]
//!   for the loop's before/after table; [`Residual`], the reusable residual with its
//!   calibrated null distribution.
//! - [`signatures`]: one function per effect of the catalogue, each fitting the shape
//!   the effect's omission leaves in the residual without refitting the model: a delay
//!   ([`phase_trend`]), a zero-order hold ([`hold_signature`]), feedthrough, a stiffness
//!   instead of a free rigid body, first-order actuator/sensor dynamics on one column or
//!   row ([`io_factors`]), and missed modes (CMIF peaks of the whitened residual,
//!   [`residual_peaks`]).
//! - [`stats`]: chi-square and normal tails, robust location and scale, the
//!   scaled-chi-square calibration.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use frf_data::FrfDataset;
//! let data = frf_data::io::read_frf_csv("wafer.csv")?;
//! // The fitted model's response at the data's lines (here an empty model).
//! let model = realize::ModalModel::new(data.ny(), data.nu());
//! let model_response = model.freq_response(&data.omegas())?;
//! let noise = validation::noise_level(&data)?;
//! let cfg = validation::ResidualConfig { sample_rate_hz: Some(10e3), ..Default::default() };
//! let a = validation::analyze_residual(&data, &model_response, &noise, &cfg)?;
//! if a.significant {
//!     for ev in a.evidence.iter().filter(|e| e.significant) {
//!         println!("{:?}: {:.0} % of the excess; {}", ev.effect, 100.0 * ev.explained_fraction, ev.detail);
//!     }
//! }
//! # Ok(()) }
//! ```

pub mod analysis;
pub(crate) mod cmat;
pub mod distortion;
pub mod disturbance;
pub mod error;
pub mod frf_validation;
pub mod invalidation;
pub mod mu;
pub mod noise;
pub mod residual;
pub mod section6;
mod serde_f64;
pub mod signatures;
pub mod stats;

pub use analysis::{analyze_residual, Effect, EffectEvidence, ResidualAnalysis};
pub use distortion::{floor_noise, line_floor, residual_ratio, LineFloor, LineFloorConfig};
pub use disturbance::{chi2_2_quantile, Coverage, DisturbanceModel};
pub use error::ValidationError;
pub use frf_validation::{
    validate_frf, validate_frf_with_model_std, BeyondModelUncertainty, FrfValidation,
    FrfValidationConfig, GammaMethod, LineValidation, Verdict,
};
pub use invalidation::{
    invalidation_mu, min_gamma, min_gamma_additive, GammaConfig, LineData, MinGamma,
    UncertaintyModel,
};
pub use mu::{generalized_mu_bounds, mu_bounds, Block, BlockStructure, MuBounds, MuConfig};
pub use noise::{estimate_noise, noise_level, NoiseConfig, NoiseLevel, NoiseSource};
pub use residual::{
    concentration, magnitude_trend, relative_error_stats, Concentration, MagnitudeTrend, Residual,
    ResidualConfig, Significance, TrendClass,
};
pub use signatures::{
    common_factor, feedthrough_signature, hold_signature, io_factors, mode_signature, phase_trend,
    residual_peaks, stiffness_signature, FeedthroughSignature, HoldSignature, IoFactor, PhaseTrend,
    ResidualPeak, SecondOrderFactor, StiffnessSignature, TemplateFit,
};
