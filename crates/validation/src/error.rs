//! The error type of the `validation` crate.

use frf_data::FrfError;
use thiserror::Error;

/// Everything that can go wrong in `validation`.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum ValidationError {
    /// An error of the data layer (reading data, building the residual's CMIF).
    #[error(transparent)]
    Frf(#[from] FrfError),
    /// The data, the model response and the noise level do not describe the same
    /// lines and entries; names which two disagree and how.
    #[error("dimension mismatch: {what}: expected {expected}, got {got}")]
    Dimension {
        /// Which two objects disagree (for example "model response vs data").
        what: String,
        /// What the first one implies.
        expected: String,
        /// What the second one has.
        got: String,
    },
    /// The data do not have enough lines for the operation.
    #[error("{what} needs at least {needed} frequency lines, the data have {got}")]
    TooFewLines {
        /// The operation.
        what: String,
        /// Minimum number of lines.
        needed: usize,
        /// Lines available.
        got: usize,
    },
    /// A value of the data, the model response or the noise level is unusable (not
    /// finite, a negative variance, a variance that is zero everywhere).
    #[error("invalid {what}: {why}")]
    InvalidInput {
        /// Which input.
        what: String,
        /// What is wrong and where.
        why: String,
    },
    /// A configuration value is out of its range.
    #[error("invalid setting {name} = {value}: {why}")]
    InvalidConfig {
        /// The field name.
        name: String,
        /// Its value, as text.
        value: String,
        /// The allowed range.
        why: String,
    },
}

impl ValidationError {
    pub(crate) fn dimension(
        what: impl Into<String>,
        expected: impl Into<String>,
        got: impl Into<String>,
    ) -> Self {
        ValidationError::Dimension {
            what: what.into(),
            expected: expected.into(),
            got: got.into(),
        }
    }

    pub(crate) fn invalid_input(what: impl Into<String>, why: impl Into<String>) -> Self {
        ValidationError::InvalidInput {
            what: what.into(),
            why: why.into(),
        }
    }

    pub(crate) fn config(name: &str, value: impl ToString, why: impl Into<String>) -> Self {
        ValidationError::InvalidConfig {
            name: name.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }
}
