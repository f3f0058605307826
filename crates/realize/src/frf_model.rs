//! [`FrfModel`]: the model currency of the estimator chain.
//!
//! Every initialiser of frfit (CMIF + convex numerators, Sanathanan-Koerner, frequency-
//! domain subspace) produces, and every refiner (refined IV, maximum likelihood) accepts,
//! this one description of a fitted FRF: a continuous-time [`ModalModel`] (pole pairs and
//! real poles with their residue matrices, rigid-body integrators, feedthrough) and the
//! [`KnownFactors`] that multiply it (delay, derivative order of the FRF type, the hold
//! of the sampled measurement, fitted input/output dynamics, crosstalk that bypasses the
//! delay). Whatever made a model, its response, its state space and its file form are
//! the same.

use crate::factors::{Hold, KnownFactors};
use crate::{ModalModel, RealizeError, ResponseGrid, StateSpace, TimeDomain};

/// A fitted continuous-time model with its known factors:
/// `P(j w) = D(w) .* ( F(w) R(w) + X )` (see [`KnownFactors`]), where `R` is the
/// response of [`FrfModel::modal`] (through an exact zero-order hold for
/// [`Hold::Zoh`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FrfModel {
    /// The rational part, continuous time, of the displacement-type response.
    pub modal: ModalModel,
    /// What multiplies (or bypasses) it.
    pub factors: KnownFactors,
}

impl FrfModel {
    /// A model without known factors.
    pub fn new(modal: ModalModel) -> Self {
        Self {
            modal,
            factors: KnownFactors::default(),
        }
    }

    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.modal.ny
    }

    /// Number of inputs.
    pub fn nu(&self) -> usize {
        self.modal.nu
    }

    /// Checks shapes, finiteness and the factors (a positive sample rate, a crosstalk of
    /// the model's shape, dynamics factors on existing rows and columns).
    pub fn validate(&self) -> Result<(), RealizeError> {
        self.modal.validate()?;
        let f = &self.factors;
        if !f.delay_s.is_finite() {
            return Err(RealizeError::NonFinite {
                what: "delay_s".into(),
            });
        }
        if let Some(fs) = f.hold.fs_hz() {
            if !(fs.is_finite() && fs > 0.0) {
                return Err(RealizeError::InvalidParameter {
                    name: "hold sample rate".into(),
                    value: fs,
                    why: "must be finite and > 0 Hz".into(),
                });
            }
        }
        if matches!(f.hold, Hold::Zoh { .. }) && f.derivative_order != 0 {
            return Err(RealizeError::InvalidParameter {
                name: "derivative_order".into(),
                value: f.derivative_order as f64,
                why: "the exact zero-order hold model is for displacement-type data".into(),
            });
        }
        if let Some(x) = &f.crosstalk {
            if x.nrows() != self.ny() || x.ncols() != self.nu() {
                return Err(RealizeError::Dimension {
                    what: "crosstalk".into(),
                    expected: format!("{}x{}", self.ny(), self.nu()),
                    got: format!("{}x{}", x.nrows(), x.ncols()),
                });
            }
        }
        for (k, d) in f.dynamics.iter().enumerate() {
            let bad_index = match d.target {
                crate::FactorTarget::Input(j) => j >= self.nu(),
                crate::FactorTarget::Output(i) => i >= self.ny(),
                crate::FactorTarget::All => false,
            };
            let finite = d.scale.is_finite()
                && d.scale > 0.0
                && d.den.iter().chain(&d.num).all(|v| v.is_finite());
            if bad_index || !finite {
                return Err(RealizeError::InvalidParameter {
                    name: format!("dynamics[{k}]"),
                    value: d.scale,
                    why: if bad_index {
                        format!(
                            "targets {:?} of a {}x{} model",
                            d.target,
                            self.ny(),
                            self.nu()
                        )
                    } else {
                        "scale must be > 0 and every coefficient finite".into()
                    },
                });
            }
        }
        Ok(())
    }

    /// The frequency response at the angular frequencies `omega` (rad/s), every known
    /// factor included. Fails at a pole (`w = 0` with integrators, `z = 1` through the
    /// hold) and on an invalid model.
    pub fn freq_response(&self, omega: &[f64]) -> Result<ResponseGrid, RealizeError> {
        self.validate()?;
        let mut g = match self.factors.hold {
            Hold::Zoh { fs_hz } => self.modal.zoh_response(omega, 1.0 / fs_hz, 0.0)?,
            _ => self.modal.freq_response(omega)?,
        };
        self.apply_factors(omega, &mut g);
        Ok(g)
    }

    /// Multiplies the rational response `g` (at `omega`) by the known factors in place.
    pub fn apply_factors(&self, omega: &[f64], g: &mut ResponseGrid) {
        let f = &self.factors;
        let (ny, nu) = (self.ny(), self.nu());
        let scalar = f.delay_s != 0.0 || f.derivative_order != 0 || f.hold.fs_hz().is_some();
        for (k, &w) in omega.iter().enumerate() {
            let line = g.line_mut(k);
            if scalar {
                let s = f.scalar_at(w);
                for v in line.iter_mut() {
                    *v *= s;
                }
            }
            if let Some(x) = &f.crosstalk {
                for j in 0..nu {
                    for i in 0..ny {
                        line[j * ny + i] += x[(i, j)];
                    }
                }
            }
            for d in &f.dynamics {
                let h = d.at(w);
                for j in 0..nu {
                    for i in 0..ny {
                        if d.affects(i, j) {
                            line[j * ny + i] *= h;
                        }
                    }
                }
            }
        }
    }

    /// A model from a continuous-time state space (the modal decomposition of
    /// [`StateSpace::to_modal`]) with the given factors.
    pub fn from_state_space(ss: &StateSpace, factors: KnownFactors) -> Result<Self, RealizeError> {
        if ss.domain != TimeDomain::Continuous {
            return Err(RealizeError::WrongDomain {
                op: "FrfModel::from_state_space".into(),
                needed: "continuous-time".into(),
            });
        }
        let model = Self {
            modal: ss.to_modal()?,
            factors,
        };
        model.validate()?;
        Ok(model)
    }

    /// True when every pole of the rational part and of the dynamics factors is in the
    /// open left half-plane (integrators excepted).
    pub fn is_stable(&self) -> bool {
        self.modal.is_stable() && self.factors.dynamics.iter().all(|d| d.is_stable())
    }

    /// The relative error `|P - G| / |G|` at every line and entry against a reference
    /// response `g` on the same grid: `(median, 95th percentile)` over entries with
    /// `|G| > 0`.
    pub fn relative_error(
        &self,
        omega: &[f64],
        g: &ResponseGrid,
    ) -> Result<(f64, f64), RealizeError> {
        let p = self.freq_response(omega)?;
        let mut rel: Vec<f64> = p
            .values
            .iter()
            .zip(&g.values)
            .filter(|(_, b)| b.norm() > 0.0)
            .map(|(a, b)| (a - b).norm() / b.norm())
            .collect();
        if rel.is_empty() {
            return Ok((f64::NAN, f64::NAN));
        }
        rel.sort_by(|a, b| a.total_cmp(b));
        let q = |p: f64| rel[((rel.len() - 1) as f64 * p).round() as usize];
        Ok((q(0.5), q(0.95)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::factors::{DynamicsFactor, FactorTarget};
    use crate::{PolePair, C64};
    use faer::Mat;
    use std::f64::consts::TAU;

    fn plant() -> ModalModel {
        let mut m = ModalModel::new(2, 2);
        m.rigid = vec![
            Mat::zeros(2, 2),
            Mat::from_fn(2, 2, |i, j| 1.0 + (i + 2 * j) as f64),
        ];
        m.pairs.push(PolePair::from_f_zeta(
            120.0,
            0.02,
            Mat::from_fn(2, 2, |i, j| C64::new(0.0, -1.0 - (i * j) as f64)),
        ));
        m
    }

    #[test]
    fn factors_multiply_as_documented() {
        let mut fm = FrfModel::new(plant());
        fm.factors.delay_s = 1e-4;
        fm.factors
            .dynamics
            .push(DynamicsFactor::first_order(FactorTarget::Input(1), 300.0));
        fm.factors.crosstalk = Some(Mat::from_fn(2, 2, |i, j| 1e-3 * (i + j) as f64));
        let w: Vec<f64> = (1..50).map(|k| TAU * 10.0 * k as f64).collect();
        let g = fm.freq_response(&w).unwrap();
        let r = fm.modal.freq_response(&w).unwrap();
        for (k, &wk) in w.iter().enumerate() {
            for j in 0..2 {
                for i in 0..2 {
                    let mut e =
                        r.get(k, i, j) * C64::from_polar(1.0, -wk * 1e-4) + 1e-3 * (i + j) as f64;
                    if j == 1 {
                        e /= C64::new(1.0, wk / (TAU * 300.0));
                    }
                    assert!((g.get(k, i, j) - e).norm() <= 1e-14 * e.norm());
                }
            }
        }
    }

    #[test]
    fn state_space_round_trip() {
        let fm = FrfModel::new(plant());
        let ss = fm.modal.to_state_space(0.0).unwrap();
        let back = FrfModel::from_state_space(&ss, KnownFactors::default()).unwrap();
        let w: Vec<f64> = (1..40).map(|k| TAU * 7.0 * k as f64).collect();
        let (a, b) = (
            fm.freq_response(&w).unwrap(),
            back.freq_response(&w).unwrap(),
        );
        for (x, y) in a.values.iter().zip(&b.values) {
            assert!((x - y).norm() <= 1e-9 * x.norm());
        }
    }

    #[test]
    fn invalid_factors_are_named() {
        let mut fm = FrfModel::new(plant());
        fm.factors
            .dynamics
            .push(DynamicsFactor::first_order(FactorTarget::Output(5), 300.0));
        let e = fm.validate().unwrap_err().to_string();
        assert!(e.contains("dynamics[0]"), "{e}");
        let mut fm = FrfModel::new(plant());
        fm.factors.hold = Hold::Zoh { fs_hz: 1e4 };
        fm.factors.derivative_order = 2;
        assert!(fm.validate().is_err());
    }
}
