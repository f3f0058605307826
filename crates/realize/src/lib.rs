//! # realize: linear models and their frequency responses
//!
//! The lowest layer of frfit. It holds the model *representations* every estimator
//! converts to, and the exact evaluation of their frequency response:
//!
//! - [`StateSpace`]: `A, B, C, D` (continuous or discrete time) with faer matrices;
//!   frequency response at many points after one Hessenberg reduction of `A`, correct
//!   for defective `A` (double integrators);
//! - [`ModalModel`]: poles with residue matrices plus a real rigid-body (integrator) part
//!   and a feedthrough; its response is a sum of first-order terms and is cheap;
//! - exact zero-order-hold discretization (augmented matrix exponential) and the
//!   frequency response of a continuous model seen through a ZOH sampler with an extra
//!   delay of `d` samples ([`zoh`]), with the matrix exponential of [`expm`] (Higham's
//!   2005 scaling and squaring);
//! - [`FrfModel`]: the model currency of the estimator chain, a [`ModalModel`] with its
//!   [`KnownFactors`] (delay, derivative order, hold, input/output dynamics, crosstalk);
//! - conversions between [`ModalModel`] and a real block-diagonal [`StateSpace`]
//!   ([`convert`]: minimal realization by residue ranks, modal decomposition that
//!   handles integrator chains exactly);
//! - balanced truncation of the stable part with the rigid-body part split off and kept
//!   exactly, Hankel singular values and the a-priori H-infinity error bound
//!   ([`balanced`]).
//!
//! Threading: the frequency responses and [`expm::expm`] are sequential; the SVDs,
//! eigendecompositions and matrix products of the conversions follow faer's global
//! setting, which applications should set to `Par::Seq` on small machines.
//!
//! `realize` depends on no other frfit crate: `experiment` builds its simulated plants
//! in these types, so it sits above this crate.
//!
//! Conventions: frequencies are angular (rad/s) unless a name ends in `_hz`; a
//! [`ResponseGrid`] stores one `ny x nu` complex matrix per frequency point, column-major
//! (`vec(G)`), points one after another.

pub mod balanced;
pub mod convert;
pub mod error;
pub mod expm;
pub mod factors;
pub mod frf_model;
pub mod grid;
pub mod hessenberg;
pub mod modal;
pub mod poly;
pub mod state_space;
pub mod zoh;

pub use balanced::{balanced_truncation, BalancedReduction, BalancedTruncation, HankelAnalysis};
pub use convert::DEFAULT_ZERO_TOL;
pub use error::RealizeError;
pub use factors::{DynamicsFactor, FactorTarget, Hold, KnownFactors};
pub use frf_model::FrfModel;
pub use grid::ResponseGrid;
pub use hessenberg::HessenbergForm;
pub use modal::{ModalModel, PolePair, RealPole};
pub use state_space::{StateSpace, TimeDomain};

/// Complex double, the scalar of every frequency response (the same type as `faer::c64`).
pub type C64 = num_complex::Complex<f64>;
