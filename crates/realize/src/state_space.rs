//! [`StateSpace`]: `x' = A x + B u, y = C x + D u` (continuous) or
//! `x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]` (discrete).

use crate::hessenberg::{eval_grid, HessenbergForm};
use crate::{RealizeError, ResponseGrid, C64};
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
        let s = Self { a, b, c, d, domain };
        s.validate()?;
        Ok(s)
    }

    /// Checks what [`StateSpace::new`] checks: the shapes of `A, B, C, D` agree, every
    /// entry is finite and a discrete sample time is finite and positive. The fields are
    /// public, so every method that computes with them calls this first.
    pub fn validate(&self) -> Result<(), RealizeError> {
        let (a, b, c, d) = (&self.a, &self.b, &self.c, &self.d);
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
        for (what, m) in [("A", a), ("B", b), ("C", c), ("D", d)] {
            if !(0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite())) {
                return Err(RealizeError::NonFinite { what: what.into() });
            }
        }
        if let TimeDomain::Discrete { ts } = self.domain {
            if !(ts.is_finite() && ts > 0.0) {
                return Err(RealizeError::InvalidParameter {
                    name: "ts".into(),
                    value: ts,
                    why: "the sample time must be finite and > 0".into(),
                });
            }
        }
        Ok(())
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

    /// The sample time of a discrete-time model, `None` for a continuous one.
    pub fn sample_time(&self) -> Option<f64> {
        match self.domain {
            TimeDomain::Continuous => None,
            TimeDomain::Discrete { ts } => Some(ts),
        }
    }

    /// The orthogonal Hessenberg reduction of this model (Laub 1981), for evaluating
    /// the response at many points; see [`crate::hessenberg`].
    pub fn hessenberg(&self) -> Result<HessenbergForm, RealizeError> {
        HessenbergForm::new(self)
    }

    /// The frequency response at the angular frequencies `omega` (rad/s): at `s = j w`
    /// for a continuous model and at `z = exp(j w ts)` for a discrete one.
    ///
    /// `A` is reduced once to upper Hessenberg form by an orthogonal similarity
    /// (Householder), and each point costs one `O(n^2)` Hessenberg LU factorization with
    /// partial pivoting plus `O(n^2)` per right-hand side (Laub 1981; see
    /// [`crate::hessenberg`]). No eigendecomposition is used, so defective `A` (double
    /// integrators) is exact. Fails with [`RealizeError::AtPole`] when a point is a pole
    /// of the model to working precision (e.g. `w = 0` with an integrator).
    pub fn freq_response(&self, omega: &[f64]) -> Result<ResponseGrid, RealizeError> {
        if let Some(k) = omega.iter().position(|w| !w.is_finite()) {
            return Err(RealizeError::NonFinite {
                what: format!("omega[{k}]"),
            });
        }
        let hf = self.hessenberg()?;
        match self.domain {
            TimeDomain::Continuous => {
                eval_grid(&hf, omega.iter().map(|&w| C64::new(0.0, w)), |k| omega[k])
            }
            TimeDomain::Discrete { ts } => eval_grid(
                &hf,
                omega.iter().map(|&w| C64::from_polar(1.0, w * ts)),
                |k| omega[k],
            ),
        }
    }

    /// `C (x I - A)^{-1} B + D` at arbitrary complex points `x` (the Laplace variable for
    /// a continuous model, `z` for a discrete one), by the same Hessenberg method as
    /// [`StateSpace::freq_response`]. When a point is a pole the error reports, as
    /// `omega`, `Im x` for a continuous model and `arg(x) / ts` for a discrete one.
    pub fn freq_response_at(&self, points: &[C64]) -> Result<ResponseGrid, RealizeError> {
        let hf = self.hessenberg()?;
        let domain = self.domain;
        eval_grid(&hf, points.iter().copied(), |k| match domain {
            TimeDomain::Continuous => points[k].im,
            TimeDomain::Discrete { ts } => points[k].arg() / ts,
        })
    }

    /// Exact zero-order-hold discretization with sample time `ts`: the input is held
    /// constant over each sample interval, and `x[k+1] = Ad x[k] + Bd u[k]` with
    ///
    /// `expm([[A, B], [0, 0]] ts) = [[Ad, Bd], [0, I]]`
    ///
    /// (Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 23(3),
    /// 1978; the exponential by [`crate::expm::expm`], Higham 2005). `C` and `D` are
    /// unchanged. Valid for singular `A` (rigid bodies): no inverse of `A` is formed.
    pub fn discretize_zoh(&self, ts: f64) -> Result<StateSpace, RealizeError> {
        crate::zoh::discretize_zoh(self, ts)
    }

    /// The frequency response of this continuous model seen through a zero-order-hold
    /// sampler with sample time `ts` and an extra delay of `delay_samples` samples:
    /// `H_zoh(z) z^-d` at `z = exp(j w ts)` for each `w` in `omega` (rad/s), where
    /// `H_zoh` is the transfer function of [`StateSpace::discretize_zoh`].
    pub fn zoh_response(
        &self,
        omega: &[f64],
        ts: f64,
        delay_samples: usize,
    ) -> Result<ResponseGrid, RealizeError> {
        crate::zoh::zoh_response(self, omega, ts, delay_samples)
    }
}
