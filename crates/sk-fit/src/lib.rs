//! # sk-fit: Sanathanan-Koerner common-denominator fits
//!
//! The SK iterations of Jue (sections 2.2 and 2.4, eq. (2) and (4)) and McKelvey
//! (eq. (36)-(38)) for MIMO frequency-response data with one common denominator and a
//! numerator per entry, in a well-conditioned basis of `poly-basis` (the prewarped
//! bilinear map, or the prewarped shift variable when the data were sampled through a
//! zero-order hold, which makes the fit exact for sampled data):
//!
//! - [`sk_denominator`]: Levy start, then SK weights `1/|d|` (classic) or `1/sqrt|d|`
//!   (Jue's default) times the data weight; per-entry numerators eliminated by a QR per
//!   entry (cost linear in entries and lines); real coefficients;
//!   [`sk_denominator_from`] starts from a previous denominator instead of Levy's;
//! - [`fit_residues`]: with the poles fixed, residue matrices, integrators and
//!   feedthrough by linear least squares (continuous or through the exact hold);
//! - [`SkInit`]: the initialiser of the estimator chain (`frfit fit --init sk`): known
//!   factors (delay, hold, derivative order), the order given or chosen by an F-test
//!   sweep, poles mapped back to `s`, the model currency [`realize::FrfModel`].
//!
//! - [`bands::MultiBandSk`]: Bayard's multi-band composite fit with Jue's tiered
//!   weights (section 2.3): bands given or chosen from the CMIF, each band an SK fit of
//!   the data minus the other bands' models, the sum in the model currency.
//!
//! The state space of the result (Gilbert's realization: each residue at its numerical
//! rank) and its balanced truncation are in `realize` (`ModalModel::to_state_space`,
//! `realize::balanced`), for every initialiser's model alike.

pub mod bands;
mod error;
mod init;
mod prepared;
mod qr;
mod residues;
mod sk;
pub mod stats;

pub use error::SkError;
pub use init::{BasisChoice, OrderScore, SkConfig, SkInit, SkReport};
pub use prepared::Prepared;
pub use residues::{fit_residues, PoleSet};
pub use sk::{sk_denominator, sk_denominator_from, SkDenominator, SkIterConfig, SkWeight};
