//! The error type of the crate.

use frf_data::FrfError;
use poly_basis::BasisError;
use realize::RealizeError;

/// What went wrong in a Sanathanan-Koerner fit.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SkError {
    /// The data (weights, delay estimate, shapes) were rejected.
    #[error(transparent)]
    Data(#[from] FrfError),
    /// The polynomial basis was rejected.
    #[error("basis: {0}")]
    Basis(#[from] BasisError),
    /// Building the model currency failed.
    #[error("model: {0}")]
    Model(#[from] RealizeError),
    /// The requested order needs more lines than the data hold.
    #[error(
        "order {order} (number of poles) is larger than the data support: {lines} lines \
         determine at most order {max} (an order-n common denominator with per-entry \
         numerators of degree n needs at least n + 2 lines)"
    )]
    OrderExceedsData {
        /// The order asked for.
        order: usize,
        /// Lines in the band.
        lines: usize,
        /// The largest order the lines support.
        max: usize,
    },
    /// The basis is numerically singular on the lines at this order.
    #[error(
        "the {basis} basis is numerically singular at order {order} on these lines: \
         condition number {condition:.3e} exceeds the limit {limit:.1e} (use the bilinear \
         basis, a narrower band or a lower order)"
    )]
    SingularBasis {
        /// The basis name.
        basis: String,
        /// The order.
        order: usize,
        /// Its condition number on the lines.
        condition: f64,
        /// The configured limit.
        limit: f64,
    },
    /// A setting is outside its domain.
    #[error("invalid setting {name} = {value}: {why}")]
    InvalidConfig {
        /// The setting.
        name: String,
        /// Its value.
        value: String,
        /// Why it is invalid.
        why: String,
    },
    /// A numerical step failed.
    #[error("{what}: {why}")]
    Numerical {
        /// The step.
        what: String,
        /// Why.
        why: String,
    },
}

impl SkError {
    pub(crate) fn config(name: &str, value: impl ToString, why: impl Into<String>) -> Self {
        SkError::InvalidConfig {
            name: name.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }
    pub(crate) fn numerical(what: &str, why: impl Into<String>) -> Self {
        SkError::Numerical {
            what: what.into(),
            why: why.into(),
        }
    }
}
