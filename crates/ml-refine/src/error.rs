//! The error type of the crate.

use frf_data::FrfError;
use realize::RealizeError;

/// What can go wrong in a maximum-likelihood refinement.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MlError {
    /// The data or the start model is invalid (shape, values).
    #[error(transparent)]
    Data(#[from] FrfError),
    /// The start model is invalid.
    #[error(transparent)]
    Model(#[from] RealizeError),
    /// A setting or input has an invalid value.
    #[error("invalid {name} = {value}: {why}")]
    Invalid {
        /// What.
        name: String,
        /// Its value, as text.
        value: String,
        /// What is wrong.
        why: String,
    },
    /// The information matrix is singular: a parameter is not identifiable from the data.
    #[error("parameter not identifiable: {what} (information matrix condition {condition:.2e}); try: {hint}")]
    Unidentifiable {
        /// The parameter (or the combination) that the data do not determine.
        what: String,
        /// Condition number of the (column-scaled) information matrix, or of the linear
        /// least-squares problem of one entry.
        condition: f64,
        /// What to try.
        hint: String,
    },
    /// The estimate (the optimum, or the model given to `uncertainty_at`) has poles
    /// outside the open left half-plane.
    #[error("the estimate is unstable: {poles}; try: {hint}")]
    Unstable {
        /// The unstable poles, in words.
        poles: String,
        /// What to try.
        hint: String,
    },
    /// Too few observations for the parameters.
    #[error("{observations} real observations cannot determine {params} parameters; use a wider band, more lines or fewer modes")]
    TooFewData {
        /// Real observations (2 per line and entry).
        observations: usize,
        /// Real parameters.
        params: usize,
    },
}

impl MlError {
    /// An [`MlError::Invalid`].
    pub fn invalid(name: impl Into<String>, value: impl ToString, why: impl Into<String>) -> Self {
        MlError::Invalid {
            name: name.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }
}
