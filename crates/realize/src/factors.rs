//! Known factors of a fitted model: what multiplies (or bypasses) the rational part of
//! an [`crate::FrfModel`] and is not itself a pole/residue term.
//!
//! - [`Hold`]: how the sampled measurement is modelled (exact zero-order hold, its
//!   `sinc` amplitude, or nothing);
//! - [`DynamicsFactor`]: a rational factor of unit static gain on one input column, one
//!   output row, or every entry (actuator, sensor or amplifier dynamics);
//! - [`KnownFactors`]: the delay, the derivative order of the FRF type, the hold, the
//!   dynamics factors and a crosstalk term that bypasses the delay.

use crate::poly::roots_ascending;
use crate::C64;
use faer::Mat;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// How the sampled measurement is modelled.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Hold {
    /// A continuous-time model (any delay is a separate factor). The default.
    #[default]
    None,
    /// The exact zero-order hold at sample rate `fs_hz`: the continuous model is seen
    /// through a sampler and hold, `H(z) = (1 - 1/z) Z{P(s)/s}` at `z = exp(j w / fs)`.
    Zoh {
        /// Sample rate, Hz.
        fs_hz: f64,
    },
    /// The hold's amplitude `sin(w / 2 fs) / (w / 2 fs)` as a known factor on a
    /// continuous model (its half-sample phase belongs to the delay): an approximation
    /// of [`Hold::Zoh`].
    Sinc {
        /// Sample rate, Hz.
        fs_hz: f64,
    },
}

impl Hold {
    /// The sample rate of the hold, when there is one.
    pub fn fs_hz(&self) -> Option<f64> {
        match *self {
            Hold::None => None,
            Hold::Zoh { fs_hz } | Hold::Sinc { fs_hz } => Some(fs_hz),
        }
    }
    /// The name used in files and reports: `none`, `zoh:FS`, `sinc:FS`.
    pub fn name(&self) -> String {
        match *self {
            Hold::None => "none".into(),
            Hold::Zoh { fs_hz } => format!("zoh:{fs_hz}"),
            Hold::Sinc { fs_hz } => format!("sinc:{fs_hz}"),
        }
    }
    /// Parses [`Hold::name`]'s form.
    pub fn parse(s: &str) -> Option<Hold> {
        let s = s.trim();
        if s == "none" {
            return Some(Hold::None);
        }
        let (kind, fs) = s.split_once(':')?;
        let fs_hz: f64 = fs.trim().parse().ok()?;
        if !(fs_hz.is_finite() && fs_hz > 0.0) {
            return None;
        }
        match kind.trim() {
            "zoh" => Some(Hold::Zoh { fs_hz }),
            "sinc" => Some(Hold::Sinc { fs_hz }),
            _ => None,
        }
    }
}

/// Which entries a [`DynamicsFactor`] multiplies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "index", rename_all = "snake_case")]
pub enum FactorTarget {
    /// Column `j` (0-based): the dynamics of actuator `j`.
    Input(usize),
    /// Row `i` (0-based): the dynamics of sensor `i`.
    Output(usize),
    /// Every entry: dynamics common to all actuators (or all sensors).
    All,
}

/// A rational factor of unit static gain, `B(x) / A(x)` with
/// `A(x) = 1 + a~_1 x + ... + a~_n x^n`, `B(x) = 1 + b~_1 x + ...` and `x = s / scale`,
/// multiplying one input column, one output row or every entry: actuator or sensor
/// dynamics (a first- or second-order low-pass, a lead-lag, a mount resonance), which no
/// sum of pole/residue terms can represent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DynamicsFactor {
    /// The entries it multiplies.
    pub target: FactorTarget,
    /// `a~_1 .. a~_n` (scaled).
    pub den: Vec<f64>,
    /// `b~_1 .. b~_m` (scaled); empty for an all-pole factor.
    #[serde(default)]
    pub num: Vec<f64>,
    /// `sigma` of `x = s / sigma`, rad/s.
    pub scale: f64,
}

impl DynamicsFactor {
    /// A first-order low-pass with corner `f_hz`: `1 / (1 + s / w_c)`.
    pub fn first_order(target: FactorTarget, f_hz: f64) -> Self {
        Self {
            target,
            den: vec![1.0],
            num: Vec::new(),
            scale: TAU * f_hz,
        }
    }
    /// A second-order low-pass `1 / (1 + 2 zeta s / w + s^2 / w^2)`.
    pub fn second_order(target: FactorTarget, f_hz: f64, zeta: f64) -> Self {
        Self {
            target,
            den: vec![2.0 * zeta, 1.0],
            num: Vec::new(),
            scale: TAU * f_hz,
        }
    }
    /// A first-order lead-lag `(1 + s / w_z) / (1 + s / w_p)` with its zero at `zero_hz`
    /// and its pole at `pole_hz` (`w = 2 pi f`): a phase lead between the two when the
    /// zero is below the pole (an actuator's current-loop lead, a sensor's
    /// compensation), a lag-lead when it is above. `x = s / w_p`, so `A(x) = 1 + x` and
    /// `B(x) = 1 + (w_p / w_z) x`.
    pub fn lead_lag(target: FactorTarget, zero_hz: f64, pole_hz: f64) -> Self {
        Self {
            target,
            den: vec![1.0],
            num: vec![pole_hz / zero_hz],
            scale: TAU * pole_hz,
        }
    }
    /// A general second-order factor of unit static gain,
    /// `(1 + 2 zeta_z s / w_z + s^2 / w_z^2) / (1 + 2 zeta_p s / w_p + s^2 / w_p^2)`:
    /// zeros at `zero_hz` with damping `zero_zeta` (a negative damping puts them in the
    /// right half-plane: non-minimum phase), poles at `pole_hz` with damping `pole_zeta`
    /// (`x = s / w_p`). An anti-resonance/resonance pair of an actuator or sensor mount.
    pub fn second_order_rational(
        target: FactorTarget,
        (zero_hz, zero_zeta): (f64, f64),
        (pole_hz, pole_zeta): (f64, f64),
    ) -> Self {
        let r = pole_hz / zero_hz;
        Self {
            target,
            den: vec![2.0 * pole_zeta, 1.0],
            num: vec![2.0 * zero_zeta * r, r * r],
            scale: TAU * pole_hz,
        }
    }
    /// The same factor with a numerator of its denominator's order whose zeros start at
    /// `zero_hz` (damping `zero_zeta` for a pair; ignored for first order): the
    /// all-pole factor times `B(s)`, which is 1 at `s = 0`. With the zeros far above the
    /// band the factor starts as nearly the all-pole one, and a fit frees them.
    /// An all-pole factor of order 1 or 2 only; `None` otherwise.
    pub fn with_zeros(&self, zero_hz: f64, zero_zeta: f64) -> Option<Self> {
        if !(self.num.is_empty() && zero_hz.is_finite() && zero_hz > 0.0) {
            return None;
        }
        let r = self.scale / (TAU * zero_hz);
        let num = match self.den.len() {
            1 => vec![r],
            2 => vec![2.0 * zero_zeta * r, r * r],
            _ => return None,
        };
        Some(Self {
            num,
            ..self.clone()
        })
    }
    /// True when a zero lies in the closed right half-plane (a non-minimum-phase
    /// factor: physically possible, e.g. a non-collocated sensor mount, but worth a
    /// flag).
    pub fn is_non_minimum_phase(&self) -> bool {
        self.zeros().iter().any(|z| z.re >= 0.0)
    }
    /// `A(j w / scale)`.
    #[inline]
    pub fn den_at(&self, omega: f64) -> C64 {
        poly1_at(&self.den, C64::new(0.0, omega / self.scale))
    }
    /// `B(j w / scale)` (1 for an all-pole factor).
    #[inline]
    pub fn num_at(&self, omega: f64) -> C64 {
        poly1_at(&self.num, C64::new(0.0, omega / self.scale))
    }
    /// The factor `B / A` at `j w`.
    #[inline]
    pub fn at(&self, omega: f64) -> C64 {
        self.num_at(omega) / self.den_at(omega)
    }
    /// True when the factor multiplies entry (`i`, `j`).
    #[inline]
    pub fn affects(&self, i: usize, j: usize) -> bool {
        match self.target {
            FactorTarget::Input(c) => c == j,
            FactorTarget::Output(r) => r == i,
            FactorTarget::All => true,
        }
    }
    /// The poles of the factor, rad/s (empty when the denominator has no roots).
    pub fn poles(&self) -> Vec<C64> {
        scaled_roots(&self.den, self.scale)
    }
    /// The zeros of the factor, rad/s.
    pub fn zeros(&self) -> Vec<C64> {
        scaled_roots(&self.num, self.scale)
    }
    /// True when every pole is in the open left half-plane.
    pub fn is_stable(&self) -> bool {
        self.poles().iter().all(|p| p.re < 0.0)
    }
}

fn scaled_roots(c: &[f64], scale: f64) -> Vec<C64> {
    if c.is_empty() {
        return Vec::new();
    }
    roots_ascending(c)
        .map(|r| r.into_iter().map(|x| x * scale).collect())
        .unwrap_or_default()
}

/// `1 + c_1 x + ... + c_n x^n` by Horner.
#[inline]
fn poly1_at(c: &[f64], x: C64) -> C64 {
    let mut acc = C64::new(0.0, 0.0);
    for &a in c.iter().rev() {
        acc = (acc + a) * x;
    }
    acc + 1.0
}

/// Everything of a model that is not a pole/residue term of its rational part:
///
/// `P(j w) = D(w) .* ( F(w) R(w) + X )`, with `R` the rational part (continuous, or its
/// exact zero-order-hold image for [`Hold::Zoh`]), `F(w) = (j w)^k exp(-j w tau)`
/// (times `sinc(w / 2 fs)` for [`Hold::Sinc`]), `X` a crosstalk feedthrough that
/// bypasses the delay and hold, and `D(w)` the product of the dynamics factors of each
/// entry.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct KnownFactors {
    /// Delay `tau`, seconds (with [`Hold::Zoh`]: what is left beyond the hold itself).
    pub delay_s: f64,
    /// Whether the delay was estimated (a free parameter of the fit).
    pub delay_fitted: bool,
    /// `k` of `(j w)^k`: 0 for displacement, 1 for velocity, 2 for accelerance data (the
    /// rational part is always of the displacement).
    pub derivative_order: u32,
    /// The hold of the sampled measurement.
    pub hold: Hold,
    /// Fitted dynamics factors (input columns, output rows, or every entry).
    pub dynamics: Vec<DynamicsFactor>,
    /// A real `ny x nu` feedthrough that bypasses the delay, hold and derivative factor
    /// (electrical crosstalk from the actuator signal to the sensor), when present.
    pub crosstalk: Option<Mat<f64>>,
}

impl KnownFactors {
    /// `F(w)`: the delay, the derivative factor and a `sinc` hold amplitude (the exact
    /// hold is applied to the rational part itself, not here).
    #[inline]
    pub fn scalar_at(&self, omega: f64) -> C64 {
        let mut f = C64::from_polar(1.0, -omega * self.delay_s);
        match self.derivative_order {
            0 => {}
            1 => f *= C64::new(0.0, omega),
            2 => f *= -omega * omega,
            k => f *= C64::new(0.0, omega).powi(k as i32),
        }
        if let Hold::Sinc { fs_hz } = self.hold {
            let x = omega / (2.0 * fs_hz);
            if x != 0.0 {
                f *= x.sin() / x;
            }
        }
        f
    }
    /// True when nothing but the rational part remains (`P = R`).
    pub fn is_identity(&self) -> bool {
        self.delay_s == 0.0
            && self.derivative_order == 0
            && self.hold == Hold::None
            && self.dynamics.is_empty()
            && self.crosstalk.is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lead_lag_is_its_zero_over_its_pole() {
        let d = DynamicsFactor::lead_lag(FactorTarget::Input(0), 300.0, 900.0);
        for f in [1.0, 300.0, 900.0, 5e3] {
            let s = C64::new(0.0, TAU * f);
            let want = (1.0 + s / (TAU * 300.0)) / (1.0 + s / (TAU * 900.0));
            assert!((d.at(TAU * f) - want).norm() <= 1e-14 * want.norm());
        }
        assert!((d.zeros()[0].re + TAU * 300.0).abs() < 1e-9);
        assert!((d.poles()[0].re + TAU * 900.0).abs() < 1e-9);
        assert!(d.is_stable() && !d.is_non_minimum_phase());
        let a = DynamicsFactor::first_order(FactorTarget::Input(0), 900.0);
        let b = a.with_zeros(300.0, 1.0).unwrap();
        assert_eq!(b, d);
        assert!(b.with_zeros(300.0, 1.0).is_none());
    }

    #[test]
    fn second_order_rational_has_its_zeros_and_poles() {
        let d = DynamicsFactor::second_order_rational(
            FactorTarget::Output(1),
            (800.0, -0.05),
            (1200.0, 0.03),
        );
        let s = C64::new(0.0, TAU * 1000.0);
        let (wz, wp) = (TAU * 800.0, TAU * 1200.0);
        let want =
            (1.0 - 0.1 * s / wz + s * s / (wz * wz)) / (1.0 + 0.06 * s / wp + s * s / (wp * wp));
        assert!((d.at(TAU * 1000.0) - want).norm() <= 1e-13 * want.norm());
        let z = d.zeros();
        assert_eq!(z.len(), 2);
        for r in &z {
            assert!((r.norm() / wz - 1.0).abs() < 1e-12);
            assert!((r.re / r.norm() - 0.05).abs() < 1e-12);
        }
        assert!(d.is_stable() && d.is_non_minimum_phase());
        let all_pole = DynamicsFactor::second_order(FactorTarget::Output(1), 1200.0, 0.03);
        assert_eq!(all_pole.with_zeros(800.0, -0.05).unwrap(), d);
        assert_eq!(d.at(0.0), C64::new(1.0, 0.0));
    }
}
