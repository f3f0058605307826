//! # additive-riv: the additive MIMO model and refined instrumental variables
//!
//! The central method of van der Hulst et al., "Frequency domain identification for
//! multivariable motion control systems: applied to a prototype wafer stage"
//! (`shared/papers/000_1df773b97bbe4ed7.txt`, sections 2.2 to 4.4):
//!
//! - [`AdditiveModel`]: `P = F(w) sum_i B_i / (x^l_i A_i)` (eq. 1-6): a rigid body,
//!   flexible modes with constant matrix numerators (eq. 26), an optional feedthrough,
//!   in continuous time (scaled per submodel) or as the exact zero-order-hold image in
//!   the shift variable, with a known factor (delay, hold, derivative FRF type);
//! - [`init`]: CMIF initialisation with damping 0.01 and the convex numerator problem
//!   (24)-(25);
//! - [`riv`]: the refined instrumental-variable iterations of Algorithm 1 (eq. 23), with
//!   the SK variant (Remark 1), solved by eliminating the per-entry numerator
//!   parameters (a Schur complement onto the shared denominators), so that an iteration
//!   costs O(lines x entries);
//! - [`complete`]: completion of the CMIF start (coincident peaks merged, poles
//!   settled, the rigid body chosen again, modes added at peaks of the residual's CMIF);
//! - [`structure`]: adding modes at peaks of the residual's CMIF and dropping
//!   insignificant ones, so that a plain fit holds every mode the data show.

pub mod augment;
pub mod chain;
pub mod complete;
pub mod error;
pub mod fitter;
pub mod gram;
pub mod held_out;
pub mod init;
pub mod mode_scan;
pub mod model;
pub mod model_json;

pub use chain::{CmifInit, CmifInitConfig, CmifInitReport, RivRefine, RivRefineConfig, RivReport};
pub use error::RivError;
pub use model::{
    AdditiveModel, Domain, DynamicsFactor, FactorTarget, KnownFactor, ModeInfo, Submodel,
    SubmodelKind,
};
pub mod numerators;
pub mod pair_start;
pub mod problem;
pub mod residual_stats;
pub mod riv;
pub mod significance;
pub mod small;
pub mod split;
pub mod step;
pub mod structure;

pub use fitter::{AdditiveFitter, DelayChoice, FitterConfig, FitterReport, Hold, ModeSelection};
pub use init::{initial_model, InitConfig, RigidBody};
pub use model_json::{FactorStd, ModeStd, ModelFile, Provenance};
pub use numerators::fit_numerators;
pub use problem::FitData;
pub use riv::{AdditiveRiv, RivConfig};
pub use step::{IvMethod, StepSolver};
pub use structure::{adapt_modes, AdaptConfig, AdaptReport};
