//! The error type of the `subspace` crate.

use thiserror::Error;

/// Everything that can go wrong in a frequency-domain subspace fit.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum SubspaceError {
    /// Data-level problem (band, weighting, delay estimate).
    #[error(transparent)]
    Data(#[from] frf_data::FrfError),
    /// Model conversion problem.
    #[error(transparent)]
    Realize(#[from] realize::RealizeError),
    /// A setting is invalid.
    #[error("invalid {name} = {value}: {why}")]
    InvalidParameter {
        /// The name of the setting.
        name: String,
        /// Its value.
        value: String,
        /// What is wrong.
        why: String,
    },
    /// The data hold too few lines for the requested fit.
    #[error("too few lines: {lines} lines in {band}, the subspace fit with {block_rows} block rows (model order up to {order}) needs at least {needed}; widen the band or ask for a lower order")]
    TooFewLines {
        /// Lines in the data.
        lines: usize,
        /// The band, as text.
        band: String,
        /// Block rows `r` of the data equation (6).
        block_rows: usize,
        /// The largest order considered.
        order: usize,
        /// Lines needed.
        needed: usize,
    },
    /// The requested order exceeds what the data support.
    #[error("order {order} exceeds the numerical rank {rank} of the projected data matrix (singular values above {tol:.1e} of the largest): the data support at most {rank} states; ask for a lower order")]
    OrderExceedsRank {
        /// The requested order (number of states).
        order: usize,
        /// The numerical rank of the projected data.
        rank: usize,
        /// The relative rank tolerance.
        tol: f64,
    },
    /// A dense factorisation failed or gave non-finite numbers.
    #[error("numerical failure in {what}: {why}")]
    Numerical {
        /// The step.
        what: String,
        /// What happened.
        why: String,
    },
}

impl SubspaceError {
    /// An [`SubspaceError::InvalidParameter`].
    pub fn invalid(name: &str, value: impl ToString, why: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name: name.to_string(),
            value: value.to_string(),
            why: why.into(),
        }
    }
    /// A [`SubspaceError::Numerical`].
    pub fn numerical(what: &str, why: impl Into<String>) -> Self {
        Self::Numerical {
            what: what.to_string(),
            why: why.into(),
        }
    }
}
