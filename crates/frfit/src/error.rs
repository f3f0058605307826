//! The error type of the `frfit` facade and CLI.

use thiserror::Error;

/// Everything the facade and the CLI report to a user.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FrfitError {
    /// Reading, writing or checking data.
    #[error(transparent)]
    Data(#[from] frf_data::FrfError),
    /// Building or evaluating a model.
    #[error(transparent)]
    Realize(#[from] realize::RealizeError),
    /// A file could not be written or read.
    #[error("{path}: {message}")]
    Io {
        /// The path.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// A command-line argument is invalid.
    #[error("invalid {name} `{value}`: {why}")]
    Argument {
        /// The option.
        name: String,
        /// The value given.
        value: String,
        /// What is wrong and what is expected.
        why: String,
    },
    /// A fit, refinement or analysis failed.
    #[error("{what}: {why}")]
    Fit {
        /// The stage.
        what: String,
        /// What went wrong and what to try.
        why: String,
    },
    /// A plot could not be drawn.
    #[error("plot {path}: {message}")]
    Plot {
        /// The SVG path.
        path: String,
        /// What went wrong.
        message: String,
    },
}

impl FrfitError {
    /// Shorthand for an [`FrfitError::Argument`].
    pub fn argument(name: &str, value: impl ToString, why: impl Into<String>) -> Self {
        FrfitError::Argument {
            name: name.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }
    /// Shorthand for an [`FrfitError::Io`] from a `std::io::Error`.
    pub fn io(path: impl AsRef<std::path::Path>, e: std::io::Error) -> Self {
        FrfitError::Io {
            path: path.as_ref().display().to_string(),
            message: e.to_string(),
        }
    }
}
