//! [`StateSpace`]: `x' = A x + B u, y = C x + D u` (continuous) or
//! `x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]` (discrete).

use crate::RealizeError;
use faer::Mat;

/// Whether a state-space model is continuous or discrete time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeDomain {
    /// Continuous time: the response is evaluated at `s = j w`.
    Continuous,
    /// Discrete time with sample time `ts` seconds: evaluated at `z = exp(j w ts)`.
    Discrete {
        /// Sample time, seconds.
        ts: f64,
    },
}

/// A real state-space model.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    /// State matrix, `n x n`.
    pub a: Mat<f64>,
    /// Input matrix, `n x nu`.
    pub b: Mat<f64>,
    /// Output matrix, `ny x n`.
    pub c: Mat<f64>,
    /// Feedthrough, `ny x nu`.
    pub d: Mat<f64>,
    /// Continuous or discrete time.
    pub domain: TimeDomain,
}

impl StateSpace {
    /// Builds a model after checking that the shapes agree and every entry is finite.
    pub fn new(
        a: Mat<f64>,
        b: Mat<f64>,
        c: Mat<f64>,
        d: Mat<f64>,
        domain: TimeDomain,
    ) -> Result<Self, RealizeError> {
        let n = a.nrows();
        let dim = |what: &str, expected: String, got: String| RealizeError::Dimension {
            what: what.into(),
            expected,
            got,
        };
        if a.ncols() != n {
            return Err(dim("A", format!("{n}x{n}"), format!("{}x{}", n, a.ncols())));
        }
        if b.nrows() != n {
            return Err(dim(
                "B",
                format!("{n}x{}", b.ncols()),
                format!("{}x{}", b.nrows(), b.ncols()),
            ));
        }
        if c.ncols() != n {
            return Err(dim(
                "C",
                format!("{}x{n}", c.nrows()),
                format!("{}x{}", c.nrows(), c.ncols()),
            ));
        }
        if d.nrows() != c.nrows() || d.ncols() != b.ncols() {
            return Err(dim(
                "D",
                format!("{}x{}", c.nrows(), b.ncols()),
                format!("{}x{}", d.nrows(), d.ncols()),
            ));
        }
        for (what, m) in [("A", &a), ("B", &b), ("C", &c), ("D", &d)] {
            if !(0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite())) {
                return Err(RealizeError::NonFinite { what: what.into() });
            }
        }
        if let TimeDomain::Discrete { ts } = domain {
            if !(ts.is_finite() && ts > 0.0) {
                return Err(RealizeError::InvalidParameter {
                    name: "ts".into(),
                    value: ts,
                    why: "the sample time must be finite and > 0".into(),
                });
            }
        }
        Ok(Self { a, b, c, d, domain })
    }

    /// Number of states.
    pub fn n_states(&self) -> usize {
        self.a.nrows()
    }
    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.c.nrows()
    }
    /// Number of inputs.
    pub fn nu(&self) -> usize {
        self.b.ncols()
    }
}
