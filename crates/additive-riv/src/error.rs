//! The error type of the `additive-riv` crate.

use thiserror::Error;

/// Everything that can go wrong when building, initialising or fitting an additive model.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum RivError {
    /// Data-level problem (bad input, band, weighting).
    #[error(transparent)]
    Data(#[from] frf_data::FrfError),
    /// Model conversion problem.
    #[error(transparent)]
    Realize(#[from] realize::RealizeError),
    /// The model structure is invalid (e.g. two rigid-body submodels).
    #[error("invalid model structure: {0}")]
    Structure(String),
    /// A parameter or setting is invalid.
    #[error("invalid {name} = {value}: {why}")]
    InvalidParameter {
        /// The name of the parameter or option.
        name: String,
        /// Its value.
        value: String,
        /// What is wrong.
        why: String,
    },
    /// The data hold fewer real observations than the model has parameters.
    #[error("too few data: {observations} real observations ({lines} lines x {entries} entries x 2) for {parameters} parameters; widen the band or use fewer modes")]
    TooFewData {
        /// Real observations, `2 * lines * entries` (weights > 0 only).
        observations: usize,
        /// Lines in the band.
        lines: usize,
        /// Entries `ny * nu`.
        entries: usize,
        /// Free parameters.
        parameters: usize,
    },
    /// A requested mode lies outside the band being fitted.
    #[error("mode at {f_hz} Hz is outside the fitted band {lo_hz}..{hi_hz} Hz")]
    ModeOutsideBand {
        /// The mode frequency.
        f_hz: f64,
        /// The band's lower edge.
        lo_hz: f64,
        /// The band's upper edge.
        hi_hz: f64,
    },
    /// A linear system in the iterations is singular or too ill-conditioned to trust.
    #[error("numerical failure in {what}: {why}")]
    Numerical {
        /// The step.
        what: String,
        /// Why (with a condition estimate when known) and what to try.
        why: String,
    },
    /// The model JSON could not be read or written.
    #[error("model file {path}: {why}")]
    ModelFile {
        /// The path.
        path: String,
        /// What is wrong.
        why: String,
    },
}

impl RivError {
    /// Shorthand for an [`RivError::InvalidParameter`].
    pub fn invalid(name: &str, value: impl ToString, why: impl Into<String>) -> Self {
        RivError::InvalidParameter {
            name: name.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }
}
