//! # subspace: frequency-domain subspace identification
//!
//! The frequency-domain subspace algorithm for MIMO FRF data (McKelvey, Akcay and Ljung
//! 1996; Pintelon & Schoukens, "Frequency domain subspace algorithms", model (3), data
//! equations (6)-(11), shift structure (12), least squares (17)), as an initialiser of
//! the estimator chain (`frfit fit --init subspace`):
//!
//! 1. [`prepare`]: the known factor (delay, derivative order) divided out; the variable
//!    `z = exp(j w Ts)` for a declared zero-order hold (the ZOH plant is exactly a
//!    discrete state space), otherwise the prewarped bilinear variable of McKelvey's
//!    eq. (39);
//! 2. [`projection`]: the real data matrix (10), the input term removed by a QR that
//!    exploits the input structure and runs over blocks of lines (cost linear in the
//!    lines), optional noise-covariance weighting, one SVD;
//! 3. [`order`]: the order given, from the singular values (noise threshold or largest
//!    gap; the default), or by an F test on the refitted residues around the
//!    singular-value proposal ([`OrderRule::FTest`]), each candidate's poles refined
//!    for that cost first ([`pole_refine`]);
//! 4. [`realization`]: `A`, `C` from (12), `B`, `D` from (17), the exact map back to
//!    continuous time;
//! 5. [`currency`]: exact continuous poles (`s = ln(z)/Ts` or the inverse bilinear map),
//!    rigid-body integrators recognised at `z = 1` / `s = 0`, unstable poles reflected,
//!    residues and feedthrough by linear least squares with the currency's own response;
//!    rigid-body integrators the singular values missed are added by an F test
//!    (without the data's variance they must also halve the cost, at once or after
//!    passes on the flexible part; they replace the states of a split double
//!    integrator) and the subspace step is repeated on the data with the fitted
//!    rigid body subtracted (while the cost falls); a pole merged from eigenvalues that
//!    noise split (a residue of rank > 1) is the candidate with the lowest refit cost;
//! 6. [`delay_refine`]: a free delay (estimated, or given as a start) refined with the
//!    subspace poles fixed (the residue refit is linear, its cost a function of the
//!    delay alone), the subspace step repeated with the refined delay divided out;
//! 7. [`SubspaceInit`]: all of it behind `frf_data::Estimator` (`Start = ()`).
//!
//! Above `SubspaceConfig::compress_above` entries, steps 2-6 run on the data with the
//! inputs projected onto a few fixed directions ([`compress`]: the poles are common to
//! every entry), and the residues of every entry are refitted on the full data with the
//! poles fixed.

pub mod compress;
pub mod currency;
pub mod delay_refine;
pub mod error;
pub mod estimator;
pub mod order;
pub mod pole_refine;
pub mod prepare;
pub mod projection;
pub mod realization;

pub use delay_refine::{DelayPass, DelayRefinement};
pub use error::SubspaceError;
pub use estimator::{Conditioning, Identified, SubspaceConfig, SubspaceInit, SubspaceReport};
pub use order::{OrderRule, OrderScore};
