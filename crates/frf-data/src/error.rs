//! The error type of the `frf-data` crate.

use realize::RealizeError;
use thiserror::Error;

/// What is wrong with a file (the `problem` of [`FrfError::Format`]); tests match on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum FormatProblem {
    /// The file has no header or no data rows.
    Empty,
    /// The header does not parse (unknown column name, duplicate column, no `freq_hz`).
    BadHeader,
    /// An entry of the `ny x nu` matrix (or its `_re`/`_im` half) has no column.
    MissingEntry,
    /// Some entries carry a `_var` column and others do not.
    InconsistentVariance,
    /// A row has more or fewer fields than the header.
    FieldCount,
    /// A field is not a number.
    NotANumber,
    /// A field is NaN or infinite.
    NonFinite,
    /// A variance is negative.
    NegativeVariance,
    /// Frequencies are not strictly increasing.
    NotIncreasing,
    /// A frequency is zero (without `dc=allowed`) or negative.
    BadFrequency,
    /// A record of a structured format (UFF, .mat) is malformed or not supported.
    BadRecord,
    /// A named variable, record or entry is not in the file.
    NotFound,
}

/// Everything that can go wrong in `frf-data`.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum FrfError {
    /// A file could not be opened or read.
    #[error("{file}: {message}")]
    Io {
        /// The path.
        file: String,
        /// The operating system's message.
        message: String,
    },
    /// A file's content is wrong: names the file, the 1-based line (0 when the problem
    /// is not tied to a line) and the column when there is one.
    #[error("{}", format_location(file, *line, column.as_deref(), detail))]
    Format {
        /// The path (or a name given by the caller for in-memory text).
        file: String,
        /// 1-based line number, 0 when not tied to a line.
        line: usize,
        /// Column name (CSV) or field description, when there is one.
        column: Option<String>,
        /// Which kind of problem.
        problem: FormatProblem,
        /// A sentence for the user.
        detail: String,
    },
    /// Dimensions do not agree.
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    Dimension {
        /// What was being combined.
        what: String,
        /// Expected shape.
        expected: String,
        /// Given shape.
        got: String,
    },
    /// A requested frequency band holds no lines of the data.
    #[error("band {lo_hz}..{hi_hz} Hz holds no lines of the data, which span {data_lo_hz}..{data_hi_hz} Hz")]
    EmptyBand {
        /// Requested lower edge, Hz.
        lo_hz: f64,
        /// Requested upper edge, Hz.
        hi_hz: f64,
        /// Lowest line of the data, Hz.
        data_lo_hz: f64,
        /// Highest line of the data, Hz.
        data_hi_hz: f64,
    },
    /// A parameter or setting has an invalid value.
    #[error("invalid {name} = {value}: {why}")]
    InvalidParameter {
        /// The parameter or option name.
        name: String,
        /// Its value, as text.
        value: String,
        /// What is wrong.
        why: String,
    },
    /// Invalid data values (non-finite, negative variance...) in an in-memory dataset.
    #[error("invalid data: {why}")]
    InvalidData {
        /// What is wrong and where.
        why: String,
    },
    /// The data carry no variance but the operation needs it.
    #[error("{what} needs a variance (`_var` columns), and the data carry none")]
    NoVariance {
        /// The operation.
        what: String,
    },
    /// A numerical step failed or was too ill-conditioned to trust.
    #[error("numerical failure in {what}: {why}")]
    Numerical {
        /// The step.
        what: String,
        /// Why, with the condition number when known.
        why: String,
    },
    /// A model-level error from `realize`.
    #[error(transparent)]
    Realize(#[from] RealizeError),
    /// The input matrix of a MIMO FRF estimate is singular at a line (an input that no
    /// experiment excites independently).
    #[error("singular input matrix at line {line} ({freq_hz} Hz), realization {realization}: reciprocal condition {rcond:.1e}; {why}")]
    SingularInput {
        /// 0-based line index.
        line: usize,
        /// Its frequency, Hz.
        freq_hz: f64,
        /// 0-based realization.
        realization: usize,
        /// 1-norm reciprocal condition number of the input matrix.
        rcond: f64,
        /// What it means for the experiment design.
        why: String,
    },
    /// A simulated closed loop is unstable.
    #[error("the closed loop is unstable: a closed-loop pole has modulus {spectral_radius:.6} >= 1 (near {pole_hz:.1} Hz); lower the controller bandwidth or gain")]
    UnstableClosedLoop {
        /// The largest modulus of the discrete closed-loop poles.
        spectral_radius: f64,
        /// Frequency of that pole, Hz (`arg(z) fs / 2 pi`).
        pole_hz: f64,
    },
}

fn format_location(file: &str, line: usize, column: Option<&str>, detail: &str) -> String {
    let mut s = String::from(file);
    if line > 0 {
        s.push_str(&format!(":{line}"));
    }
    if let Some(c) = column {
        s.push_str(&format!(": column {c}"));
    }
    s.push_str(": ");
    s.push_str(detail);
    s
}

impl FrfError {
    /// Shorthand for a [`FrfError::Format`].
    pub fn format(
        file: impl Into<String>,
        line: usize,
        column: Option<&str>,
        problem: FormatProblem,
        detail: impl Into<String>,
    ) -> Self {
        FrfError::Format {
            file: file.into(),
            line,
            column: column.map(str::to_string),
            problem,
            detail: detail.into(),
        }
    }

    /// Shorthand for an [`FrfError::InvalidParameter`].
    pub fn invalid(name: impl Into<String>, value: impl ToString, why: impl Into<String>) -> Self {
        FrfError::InvalidParameter {
            name: name.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }

    /// The [`FormatProblem`] when this is a format error.
    pub fn problem(&self) -> Option<FormatProblem> {
        match self {
            FrfError::Format { problem, .. } => Some(*problem),
            _ => None,
        }
    }
}
