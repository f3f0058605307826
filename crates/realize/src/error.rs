//! The error type of the `realize` crate.

use thiserror::Error;

/// Everything that can go wrong when building or evaluating a model.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum RealizeError {
    /// Matrix dimensions do not agree.
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    Dimension {
        /// Which matrix or argument.
        what: String,
        /// The expected shape, as text (e.g. "4x13").
        expected: String,
        /// The shape that was given.
        got: String,
    },
    /// A value that must be finite is not.
    #[error("non-finite value in {what}")]
    NonFinite {
        /// Which matrix or argument.
        what: String,
    },
    /// The frequency response was requested at a pole of the model.
    #[error(
        "frequency response evaluated at a pole of the model (point {point}, w = {omega} rad/s)"
    )]
    AtPole {
        /// Index of the evaluation point.
        point: usize,
        /// The angular frequency.
        omega: f64,
    },
    /// A parameter is out of its valid range.
    #[error("invalid parameter {name} = {value}: {why}")]
    InvalidParameter {
        /// Parameter name.
        name: String,
        /// The value given.
        value: f64,
        /// What is wrong with it.
        why: String,
    },
    /// An operation needs a continuous-time (or discrete-time) model and got the other.
    #[error("{op} needs a {needed} model")]
    WrongDomain {
        /// The operation.
        op: String,
        /// "continuous-time" or "discrete-time".
        needed: String,
    },
    /// A numerical decomposition failed (did not converge or is too ill-conditioned).
    #[error("numerical failure in {what}: {why}")]
    Numerical {
        /// The decomposition or algorithm.
        what: String,
        /// Why.
        why: String,
    },
    /// A pole that an operation needs in the open left half-plane is not there.
    #[error("{what}: pole {pole} is not in the open left half-plane; {why}")]
    Unstable {
        /// Which term of the model (e.g. "pairs[3]").
        what: String,
        /// The pole, rad/s.
        pole: crate::C64,
        /// What the operation needs and why.
        why: String,
    },
}
