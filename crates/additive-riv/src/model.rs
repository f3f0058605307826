//! [`AdditiveModel`]: the additive MIMO model (1)-(6) of the wafer-stage paper,
//! `P(s) = F(w) sum_i B_i(x) / (pi_i(x) A_i(x))`, with a known factor `F`.
//!
//! Each submodel `i` is `B_i(x) / (x^l_i A_i(x))` (eq. 2) with the scalar denominator
//! `A_i(x) = 1 + a_i1 x + ... + a_in x^n` (eq. 3) and the matrix numerator
//! `B_i(x) = sum_r B_ir x^r` (eq. 4), in one of two time variables:
//!
//! - [`Domain::Continuous`]: `x = s / sigma_i` with a per-submodel frequency scale
//!   `sigma_i` (rad/s), so that no raw power of `s` at kHz is ever formed; parameters go
//!   in and out in the paper's unscaled form (`a_ir = a~_ir / sigma_i^r`,
//!   `B_ir = B~_ir sigma_i^(l_i - r)`);
//! - [`Domain::ZohDiscrete`]: `x = q = exp(-j w ts)` (the backward shift `1/z`) and the
//!   integrator factor `(1 - q)^l`: the exact zero-order-hold equivalent of a continuous
//!   additive model is again additive, with second-order `q`-numerators per mode. It is
//!   mapped back to continuous time exactly in [`AdditiveModel::to_modal`].
//!
//! The known factor `F(w) = (j w)^k exp(-j w tau) sinc(w / (2 fs))` covers a derivative
//! FRF type (velocity `k = 1`, accelerance `k = 2`: the model is of the displacement,
//! so that a free rigid body stays `1/s^2`), a delay `tau` (optionally a free parameter)
//! and the amplitude of a zero-order hold treated as a known factor.

use crate::RivError;
use faer::Mat;
use frf_data::{FrfError, ModelStructure, C64};
pub use realize::{DynamicsFactor, FactorTarget};
use realize::{ModalModel, PolePair, RealPole};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// The time variable of the submodels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Domain {
    /// Continuous time, polynomials in `s / sigma_i` (the paper's form).
    Continuous,
    /// Exact zero-order hold with sample time `ts` seconds: polynomials in `q = 1/z`.
    ZohDiscrete {
        /// Sample time, seconds.
        ts: f64,
    },
}

/// What a submodel represents (for reports, initialisation and conversions).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SubmodelKind {
    /// Poles at the origin (`1/s^l`, a free rigid body for `l = 2`).
    RigidBody,
    /// A flexible mode (second-order denominator).
    Mode,
    /// A constant, biproper term (feedthrough / crosstalk).
    Feedthrough,
    /// A suspension: the rigid body held by a stiffness, a low-frequency pole pair with
    /// its own numerator.
    Suspension,
    /// Any other submodel.
    General,
}

/// One submodel `B(x) / (x^l A(x))`, stored in the scaled variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Submodel {
    /// What the submodel represents.
    pub kind: SubmodelKind,
    /// `l`: poles at `s = 0` (or `z = 1`).
    pub integrators: usize,
    /// `a~_1 .. a~_n` of `A(x) = 1 + a~_1 x + ...` in the scaled variable.
    pub den: Vec<f64>,
    /// The power of `x` of the first numerator coefficient.
    pub num_start: usize,
    /// `B~_r` for `r = num_start ..`, each `ny x nu`, in the scaled variable.
    pub num: Vec<Mat<f64>>,
    /// `sigma` (rad/s) with `x = s / sigma` (continuous); 1 in discrete time.
    pub scale: f64,
    /// A fixed polynomial factor `c(x)` (ascending coefficients) of the numerator:
    /// the submodel is `c(x) sum_r B~_r x^r / (x^l A(x))`. `[1]` when there is none; the
    /// exact-hold rigid body uses it so that its single numerator matrix is the
    /// continuous-time residue (`zoh(B/s^2) = B ts^2/2 (q + q^2) / (1 - q)^2`).
    pub num_poly: Vec<f64>,
    /// An exact-hold mode with the numerator of a constant continuous numerator: the
    /// submodel is the zero-order-hold image of `B / (s^2 + 2 zeta w s + w^2)`,
    /// `B (beta_1 q + beta_2 q^2) / (1 + a_1 q + a_2 q^2)`, whose `beta`s follow from the
    /// poles ([`zoh_mode_shape`]); `num_poly` then holds `[0, beta_1, beta_2]`, kept in
    /// step with `den` by [`AdditiveModel::sync_shapes`]. One numerator matrix per mode,
    /// as in continuous time (eq. 26), instead of two free ones that could absorb a delay.
    pub zoh_shape: bool,
    /// The submodel bypasses the known factor's delay (and hold and derivative): the
    /// model is `F (sum of the others) + this`. Crosstalk that couples the actuator signal
    /// into the sensor electrically does not see the plant's hold and computation delay.
    pub bypass_factor: bool,
}

/// `(beta_1, beta_2)` of the zero-order-hold image of `1 / ((s - p_1)(s - p_2))` whose
/// discrete poles are the roots `z` of `z^2 + a_1 z + a_2` (`den = [a_1, a_2]`), sample
/// time `ts`: with `p = ln(z) / ts` and `c = (z - 1) / p` (the ZOH gain of `1/(s-p)`),
/// `beta_1 = (c_1 - c_2) / (p_1 - p_2)` and `beta_2 = (c_2 z_1 - c_1 z_2) / (p_1 - p_2)`.
/// `None` for a repeated or non-representable (negative real) discrete pole.
pub fn zoh_mode_shape(den: &[f64], ts: f64) -> Option<[f64; 2]> {
    if den.len() != 2 {
        return None;
    }
    let (a1, a2) = (den[0], den[1]);
    let disc = C64::new(a1 * a1 - 4.0 * a2, 0.0).sqrt();
    let z1 = (-a1 + disc) / 2.0;
    let z2 = (-a1 - disc) / 2.0;
    if (z1 - z2).norm() <= 1e-12 * z1.norm().max(1e-300) {
        return None;
    }
    if [z1, z2]
        .iter()
        .any(|z| z.im.abs() <= 1e-15 * z.norm() && z.re <= 0.0)
    {
        return None;
    }
    let gain = |z: C64| -> (C64, C64) {
        let p = z.ln() / ts;
        let x = p * ts;
        let c = if x.norm() < 1e-6 {
            ts * (C64::new(1.0, 0.0) + x / 2.0)
        } else {
            (z - 1.0) / p
        };
        (p, c)
    };
    let (p1, c1) = gain(z1);
    let (p2, c2) = gain(z2);
    let b1 = (c1 - c2) / (p1 - p2);
    let b2 = (c2 * z1 - c1 * z2) / (p1 - p2);
    let out = [b1.re, b2.re];
    out.iter().all(|v| v.is_finite()).then_some(out)
}

impl Submodel {
    /// Number of denominator parameters `n`.
    pub fn n_den(&self) -> usize {
        self.den.len()
    }
    /// Number of numerator coefficient matrices.
    pub fn n_num(&self) -> usize {
        self.num.len()
    }
    /// `c(x)`, the fixed numerator factor, at `x`.
    #[inline]
    pub fn num_poly_at(&self, x: C64) -> C64 {
        let mut acc = C64::new(0.0, 0.0);
        for &c in self.num_poly.iter().rev() {
            acc = acc * x + c;
        }
        acc
    }

    /// The same submodel with the fixed factor multiplied into the numerator
    /// (`num_poly = [1]`, `num_start = 0`).
    pub fn expanded(&self) -> Submodel {
        if self.num_poly == [1.0] && self.num_start == 0 {
            return self.clone();
        }
        let (ny, nu) = (self.num[0].nrows(), self.num[0].ncols());
        let deg = self.num_start + self.num.len() - 1 + self.num_poly.len() - 1;
        let mut num = vec![Mat::<f64>::zeros(ny, nu); deg + 1];
        for (t, b) in self.num.iter().enumerate() {
            for (sdx, &c) in self.num_poly.iter().enumerate() {
                let p = self.num_start + t + sdx;
                for j in 0..nu {
                    for i in 0..ny {
                        num[p][(i, j)] += c * b[(i, j)];
                    }
                }
            }
        }
        // drop leading zero coefficients (keep the power offset)
        let first = num
            .iter()
            .position(|b| (0..nu).any(|j| (0..ny).any(|i| b[(i, j)] != 0.0)))
            .unwrap_or(0);
        let num_start = first;
        let num: Vec<Mat<f64>> = num.into_iter().skip(first).collect();
        Submodel {
            num_start,
            num,
            num_poly: vec![1.0],
            zoh_shape: false,
            bypass_factor: false,
            ..self.clone()
        }
    }

    /// Recomputes the fixed factor of an exact-hold mode from its poles (no-op for other
    /// submodels or when the poles have no exact-hold form).
    pub fn sync_shape(&mut self, ts: f64) {
        if self.zoh_shape {
            if let Some([b1, b2]) = zoh_mode_shape(&self.den, ts) {
                self.num_poly = vec![0.0, b1, b2];
            }
        }
    }

    /// `A(x)` at the complex point `x`.
    #[inline]
    pub fn den_at(&self, x: C64) -> C64 {
        // Horner on 1 + a1 x + ... + an x^n
        let mut acc = C64::new(0.0, 0.0);
        for &a in self.den.iter().rev() {
            acc = (acc + a) * x;
        }
        acc + 1.0
    }
}

/// The known factor `F(w) = (j w)^k exp(-j w tau) sinc(w / (2 fs))` that multiplies the
/// rational model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KnownFactor {
    /// Delay `tau`, seconds (hold + computation delay, or what is left of it).
    pub delay_s: f64,
    /// Whether `tau` is a free parameter (the last entry of the parameter vector).
    pub fit_delay: bool,
    /// `k` of `(j w)^k`: 0 for displacement, 1 for velocity, 2 for accelerance data.
    pub derivative_order: u32,
    /// Sample rate of a zero-order hold whose amplitude `sin(w/2fs)/(w/2fs)` is a known
    /// factor (its half-sample phase belongs in `delay_s`); `None` for no such factor.
    pub sinc_hold_fs: Option<f64>,
}

impl Default for KnownFactor {
    fn default() -> Self {
        Self {
            delay_s: 0.0,
            fit_delay: false,
            derivative_order: 0,
            sinc_hold_fs: None,
        }
    }
}

impl KnownFactor {
    /// `F(w)`.
    #[inline]
    pub fn at(&self, omega: f64) -> C64 {
        let mut f = C64::from_polar(1.0, -omega * self.delay_s);
        match self.derivative_order {
            0 => {}
            1 => f *= C64::new(0.0, omega),
            2 => f *= -omega * omega,
            k => f *= C64::new(0.0, omega).powi(k as i32),
        }
        if let Some(fs) = self.sinc_hold_fs {
            let x = omega / (2.0 * fs);
            if x != 0.0 {
                f *= x.sin() / x;
            }
        }
        f
    }
    /// True when the factor is identically 1.
    pub fn is_identity(&self) -> bool {
        self.delay_s == 0.0
            && !self.fit_delay
            && self.derivative_order == 0
            && self.sinc_hold_fs.is_none()
    }
}

/// Modal summary of a mode submodel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModeInfo {
    /// Index of the submodel.
    pub submodel: usize,
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping (negative when unstable).
    pub zeta: f64,
}

/// The additive MIMO model (eq. 1-6 of the wafer-stage paper) with a known factor.
#[derive(Debug, Clone, PartialEq)]
pub struct AdditiveModel {
    ny: usize,
    nu: usize,
    domain: Domain,
    /// The submodels.
    pub submodels: Vec<Submodel>,
    /// The known factor that multiplies the rational part.
    pub factor: KnownFactor,
    /// Fitted dynamics factors of input columns or output rows.
    pub dynamics: Vec<DynamicsFactor>,
}

impl AdditiveModel {
    /// An empty model (no submodels).
    pub fn new(ny: usize, nu: usize, domain: Domain) -> Result<Self, RivError> {
        if ny == 0 || nu == 0 {
            return Err(RivError::invalid(
                "dimensions",
                format!("{ny}x{nu}"),
                "need at least one output and one input",
            ));
        }
        if let Domain::ZohDiscrete { ts } = domain {
            if !(ts.is_finite() && ts > 0.0) {
                return Err(RivError::invalid("ts", ts, "the sample time must be > 0"));
            }
        }
        Ok(Self {
            ny,
            nu,
            domain,
            submodels: Vec::new(),
            factor: KnownFactor::default(),
            dynamics: Vec::new(),
        })
    }

    /// The time variable.
    pub fn domain(&self) -> Domain {
        self.domain
    }

    /// Sets the known factor (checked: a derivative factor is not allowed in discrete time).
    pub fn with_factor(mut self, factor: KnownFactor) -> Result<Self, RivError> {
        if matches!(self.domain, Domain::ZohDiscrete { .. }) && factor.derivative_order != 0 {
            return Err(RivError::Structure(
                "a derivative FRF type (velocity/accelerance) needs the continuous domain; \
                 the exact zero-order hold model is for displacement-type data"
                    .into(),
            ));
        }
        if factor
            .sinc_hold_fs
            .is_some_and(|fs| !(fs.is_finite() && fs > 0.0))
        {
            return Err(RivError::invalid(
                "sinc hold fs",
                format!("{:?}", factor.sinc_hold_fs),
                "the sample rate must be > 0",
            ));
        }
        if !factor.delay_s.is_finite() {
            return Err(RivError::invalid("delay", factor.delay_s, "must be finite"));
        }
        self.factor = factor;
        Ok(self)
    }

    /// The default frequency scale of a rigid-body submodel for a band `lo..hi` (Hz):
    /// the geometric mean, so that `1/x^2` stays within `[hi/lo]^{+-1}` of 1.
    pub fn rigid_scale(lo_hz: f64, hi_hz: f64) -> f64 {
        TAU * (lo_hz.max(1e-9) * hi_hz.max(1e-9)).sqrt()
    }

    /// Adds a rigid-body submodel `B / s^l` (zero numerator; the initialisation fits it).
    /// Continuous: numerator `B_0` only; discrete: `q (B_1 + B_2 q ...)` with `l`
    /// numerator matrices (the exact ZOH image of `sum_k R_k / s^k`).
    pub fn push_rigid_body(&mut self, integrators: usize, scale: f64) -> Result<usize, RivError> {
        if integrators == 0 {
            return Err(RivError::Structure(
                "a rigid body needs l >= 1 integrators".into(),
            ));
        }
        if self.submodels.iter().any(|s| s.integrators > 0) {
            return Err(RivError::Structure(
                "at most one submodel may have poles at the origin (eq. 2)".into(),
            ));
        }
        // Continuous: B / s^l. Exact hold: the ZOH image of B / s^l, whose numerator
        // shape is fixed (ts q for l = 1, ts^2/2 (q + q^2) for l = 2), so that B is the
        // continuous residue as well.
        let (num_poly, scale) = match self.domain {
            Domain::Continuous => (vec![1.0], check_scale(scale)?),
            Domain::ZohDiscrete { ts } => match integrators {
                1 => (vec![0.0, ts], 1.0),
                2 => (vec![0.0, ts * ts / 2.0, ts * ts / 2.0], 1.0),
                _ => {
                    return Err(RivError::Structure(
                        "the exact-hold model supports at most 2 integrators".into(),
                    ))
                }
            },
        };
        self.submodels.push(Submodel {
            kind: SubmodelKind::RigidBody,
            integrators,
            den: Vec::new(),
            num_start: 0,
            num: vec![Mat::zeros(self.ny, self.nu)],
            scale,
            num_poly,
            zoh_shape: false,
            bypass_factor: false,
        });
        Ok(self.submodels.len() - 1)
    }

    /// Adds a flexible mode with natural frequency `f_hz` and damping `zeta` and a zero
    /// numerator: continuous `B_0 / (s^2/w^2 + 2 zeta s / w + 1)` (eq. 26), or its
    /// exact-ZOH image `(B_1 q + B_2 q^2) / (1 + a_1 q + a_2 q^2)` in discrete time.
    /// `first_order_numerator` adds `B_1 s` in continuous time (a complex residue).
    pub fn push_mode(
        &mut self,
        f_hz: f64,
        zeta: f64,
        first_order_numerator: bool,
    ) -> Result<usize, RivError> {
        if !(f_hz.is_finite() && f_hz > 0.0) {
            return Err(RivError::invalid("mode frequency", f_hz, "must be > 0 Hz"));
        }
        if !(zeta.is_finite() && zeta > 0.0 && zeta < 1.0) {
            return Err(RivError::invalid("mode damping", zeta, "must be in (0, 1)"));
        }
        let wn = TAU * f_hz;
        let sub = match self.domain {
            Domain::Continuous => Submodel {
                kind: SubmodelKind::Mode,
                integrators: 0,
                // x = s / wn: A = 1 + 2 zeta x + x^2
                den: vec![2.0 * zeta, 1.0],
                num_start: 0,
                num: vec![Mat::zeros(self.ny, self.nu); if first_order_numerator { 2 } else { 1 }],
                scale: wn,
                num_poly: vec![1.0],
                zoh_shape: false,
                bypass_factor: false,
            },
            Domain::ZohDiscrete { ts } => {
                if wn * ts >= PI {
                    return Err(RivError::invalid(
                        "mode frequency",
                        f_hz,
                        format!("at or above the Nyquist frequency {} Hz", 0.5 / ts),
                    ));
                }
                let p = C64::new(-zeta * wn, wn * (1.0 - zeta * zeta).sqrt());
                let zp = (p * ts).exp();
                let mut sub = Submodel {
                    kind: SubmodelKind::Mode,
                    integrators: 0,
                    den: vec![-2.0 * zp.re, zp.norm_sqr()],
                    num_start: 0,
                    num: vec![Mat::zeros(self.ny, self.nu)],
                    scale: 1.0,
                    num_poly: vec![1.0],
                    zoh_shape: true,
                    bypass_factor: false,
                };
                sub.sync_shape(ts);
                sub
            }
        };
        self.submodels.push(sub);
        Ok(self.submodels.len() - 1)
    }

    /// Adds a feedthrough that bypasses the known factor (see [`Submodel::bypass_factor`]).
    pub fn push_bypass_feedthrough(&mut self) -> Result<usize, RivError> {
        let i = self.push_feedthrough()?;
        self.submodels[i].bypass_factor = true;
        Ok(i)
    }

    /// Whether the model holds a feedthrough (constant, biproper) submodel.
    pub fn has_feedthrough(&self) -> bool {
        self.submodels
            .iter()
            .any(|s| s.kind == SubmodelKind::Feedthrough)
    }

    /// Adds a feedthrough (constant, biproper) submodel `D`; at most one is allowed.
    pub fn push_feedthrough(&mut self) -> Result<usize, RivError> {
        if self.has_feedthrough() {
            return Err(RivError::Structure(
                "at most one biproper (feedthrough) submodel is allowed".into(),
            ));
        }
        self.submodels.push(Submodel {
            kind: SubmodelKind::Feedthrough,
            integrators: 0,
            den: Vec::new(),
            num_start: 0,
            num: vec![Mat::zeros(self.ny, self.nu)],
            scale: 1.0,
            num_poly: vec![1.0],
            zoh_shape: false,
            bypass_factor: false,
        });
        Ok(self.submodels.len() - 1)
    }

    /// Recomputes the numerator shapes of the exact-hold modes from their poles (after
    /// the denominators changed).
    pub fn sync_shapes(&mut self) {
        if let Domain::ZohDiscrete { ts } = self.domain {
            for s in &mut self.submodels {
                s.sync_shape(ts);
            }
        }
    }

    /// Adds a general submodel (advanced use; validated like the others).
    pub fn push_submodel(&mut self, sub: Submodel) -> Result<usize, RivError> {
        if sub
            .num
            .iter()
            .any(|b| b.nrows() != self.ny || b.ncols() != self.nu)
        {
            return Err(RivError::Structure(format!(
                "numerator matrices must be {}x{}",
                self.ny, self.nu
            )));
        }
        if sub.num.is_empty() {
            return Err(RivError::Structure("a submodel needs a numerator".into()));
        }
        if sub.num_poly.is_empty() || sub.num_poly.iter().any(|c| !c.is_finite()) {
            return Err(RivError::Structure(
                "the fixed numerator factor must be a non-empty finite polynomial".into(),
            ));
        }
        if sub.integrators > 0 && self.submodels.iter().any(|s| s.integrators > 0) {
            return Err(RivError::Structure(
                "at most one submodel may have poles at the origin (eq. 2)".into(),
            ));
        }
        if matches!(self.domain, Domain::Continuous) {
            check_scale(sub.scale)?;
        }
        if sub.zoh_shape {
            let Domain::ZohDiscrete { ts } = self.domain else {
                return Err(RivError::Structure(
                    "an exact-hold mode needs the zoh domain".into(),
                ));
            };
            if sub.den.len() != 2
                || sub.num.len() != 1
                || sub.num_start != 0
                || sub.integrators != 0
            {
                return Err(RivError::Structure(
                    "an exact-hold mode has two denominator coefficients and one numerator".into(),
                ));
            }
            let mut sub = sub;
            sub.sync_shape(ts);
            self.submodels.push(sub);
            return Ok(self.submodels.len() - 1);
        }
        self.submodels.push(sub);
        Ok(self.submodels.len() - 1)
    }

    /// Removes submodel `i`.
    pub fn remove_submodel(&mut self, i: usize) -> Submodel {
        self.submodels.remove(i)
    }

    /// The variable `x` of submodel `sub` at angular frequency `omega`.
    #[inline]
    pub fn variable(&self, sub: &Submodel, omega: f64) -> C64 {
        match self.domain {
            Domain::Continuous => C64::new(0.0, omega / sub.scale),
            Domain::ZohDiscrete { ts } => C64::from_polar(1.0, -omega * ts),
        }
    }

    /// Adds a dynamics factor (checked: target in range, finite coefficients, a
    /// numerator of at most the denominator's order (a proper factor), scale > 0).
    pub fn push_dynamics(&mut self, f: DynamicsFactor) -> Result<usize, RivError> {
        match f.target {
            FactorTarget::Input(j) if j >= self.nu => {
                return Err(RivError::invalid(
                    "factor input",
                    j + 1,
                    format!("the model has {} inputs", self.nu),
                ))
            }
            FactorTarget::Output(i) if i >= self.ny => {
                return Err(RivError::invalid(
                    "factor output",
                    i + 1,
                    format!("the model has {} outputs", self.ny),
                ))
            }
            _ => {}
        }
        if f.den.is_empty() || f.den.iter().chain(&f.num).any(|a| !a.is_finite()) {
            return Err(RivError::Structure(
                "a dynamics factor needs finite coefficients".into(),
            ));
        }
        if f.num.len() > f.den.len() {
            return Err(RivError::Structure(format!(
                "a dynamics factor needs a numerator of at most its denominator's order (got {} over {}): an improper factor grows without bound",
                f.num.len(),
                f.den.len()
            )));
        }
        check_scale(f.scale)?;
        self.dynamics.push(f);
        Ok(self.dynamics.len() - 1)
    }

    /// The factor of entry (`i`, `j`) at `omega`: the known factor times the dynamics
    /// factors that multiply that entry.
    #[inline]
    pub fn entry_factor(&self, omega: f64, i: usize, j: usize) -> C64 {
        let mut f = self.factor.at(omega);
        for d in &self.dynamics {
            if d.affects(i, j) {
                f *= d.at(omega);
            }
        }
        f
    }

    /// The integrator factor `x^l` (continuous) or `(1 - q)^l` (discrete) at `x`.
    #[inline]
    pub fn integrator_factor(&self, l: usize, x: C64) -> C64 {
        if l == 0 {
            return C64::new(1.0, 0.0);
        }
        let base = match self.domain {
            Domain::Continuous => x,
            Domain::ZohDiscrete { .. } => 1.0 - x,
        };
        base.powi(l as i32)
    }

    /// The scalar `x^r / (pi(x) A(x))` of submodel `sub` for each numerator coefficient,
    /// pushed into `out` (the regressor (25) without the identity block).
    #[inline]
    pub fn basis_into(&self, sub: &Submodel, omega: f64, out: &mut Vec<C64>) {
        let x = self.variable(sub, omega);
        let d = sub.num_poly_at(x) / (self.integrator_factor(sub.integrators, x) * sub.den_at(x));
        let mut xr = x.powi(sub.num_start as i32);
        for _ in 0..sub.num.len() {
            out.push(xr * d);
            xr *= x;
        }
    }

    /// Integrators of the rigid-body part (the most of any submodel; 0 without one).
    pub fn integrators(&self) -> usize {
        self.submodels
            .iter()
            .map(|s| s.integrators)
            .max()
            .unwrap_or(0)
    }

    /// Frequencies and damping of the [`SubmodelKind::Mode`] submodels.
    pub fn modes(&self) -> Vec<ModeInfo> {
        self.submodels
            .iter()
            .enumerate()
            .filter(|(_, s)| s.kind == SubmodelKind::Mode && s.den.len() == 2)
            .filter_map(|(i, s)| {
                let p = self.upper_pole(s)?;
                let wn = p.norm();
                Some(ModeInfo {
                    submodel: i,
                    f_hz: wn / TAU,
                    zeta: -p.re / wn,
                })
            })
            .collect()
    }

    /// The continuous-time pole (upper half plane) of a second-order submodel, `None`
    /// when its roots are real.
    pub fn upper_pole(&self, sub: &Submodel) -> Option<C64> {
        if sub.den.len() != 2 {
            return None;
        }
        let (a1, a2) = (sub.den[0], sub.den[1]);
        match self.domain {
            Domain::Continuous => {
                // a2 x^2 + a1 x + 1 = 0, s = sigma x
                let disc = a1 * a1 - 4.0 * a2;
                if disc >= 0.0 || a2 == 0.0 {
                    return None;
                }
                let x = C64::new(-a1 / (2.0 * a2), (-disc).sqrt() / (2.0 * a2.abs()));
                Some(x * sub.scale)
            }
            Domain::ZohDiscrete { ts } => {
                // z^2 + a1 z + a2 = 0
                let disc = a1 * a1 - 4.0 * a2;
                if disc >= 0.0 {
                    return None;
                }
                let z = C64::new(-a1 / 2.0, (-disc).sqrt() / 2.0);
                Some(z.ln() / ts)
            }
        }
    }

    /// The submodels whose denominator roots are not all stable (left half plane, or
    /// inside the unit circle in discrete time, where a root on the negative real axis
    /// counts as unstable too: no continuous-time pole maps there through the hold).
    pub fn unstable_submodels(&self) -> Vec<usize> {
        let mut bad = Vec::new();
        for (i, s) in self.submodels.iter().enumerate() {
            if s.den.is_empty() {
                continue;
            }
            let roots = match poly_roots_ascending(&s.den) {
                Ok(r) => r,
                Err(_) => {
                    bad.push(i);
                    continue;
                }
            };
            let unstable = match self.domain {
                // roots in x of A(x); s = sigma x
                Domain::Continuous => roots.iter().any(|x| x.re >= 0.0),
                // roots in q of A(q); z = 1/q must be inside the unit circle, and off
                // the negative real axis, where no continuous-time pole maps
                Domain::ZohDiscrete { .. } => roots
                    .iter()
                    .any(|q| q.norm() <= 1.0 || (q.im.abs() <= 1e-12 * q.norm() && q.re <= 0.0)),
            };
            if unstable {
                bad.push(i);
            }
        }
        bad
    }

    /// The rational part (without the known factor) at `omega`, into `out` (`vec(P)`).
    pub fn rational_into(&self, omega: f64, out: &mut [C64]) {
        self.rational_part_into(omega, out, false);
    }

    /// Sums the submodels that bypass the factor (`bypass = true`) or the others.
    fn rational_part_into(&self, omega: f64, out: &mut [C64], bypass: bool) {
        let m = self.ny * self.nu;
        out[..m].fill(C64::new(0.0, 0.0));
        let mut basis = Vec::with_capacity(4);
        for sub in self.submodels.iter().filter(|s| s.bypass_factor == bypass) {
            basis.clear();
            self.basis_into(sub, omega, &mut basis);
            for (b, coef) in sub.num.iter().zip(&basis) {
                for j in 0..self.nu {
                    for i in 0..self.ny {
                        out[j * self.ny + i] += *coef * b[(i, j)];
                    }
                }
            }
        }
    }

    /// Number of real parameters of submodel `i` in the parameter vector.
    pub fn n_params_of(&self, i: usize) -> usize {
        let s = &self.submodels[i];
        s.den.len() + s.num.len() * self.ny * self.nu
    }

    /// The rational part as a [`ModalModel`] (the known factor is not rational and is
    /// not included: apply it separately, as `frfit eval` does). Continuous submodels by
    /// partial fractions; discrete (exact-hold) submodels mapped back to continuous time
    /// exactly: a discrete pole `z_p` becomes `p = ln(z_p)/ts` and its residue `R_z`
    /// becomes `R_z p / (z_p - 1)`, the inverse of the ZOH map
    /// `R/(s-p) -> R (e^{p ts} - 1)/p / (z - e^{p ts})`.
    pub fn to_modal_model(&self) -> Result<ModalModel, RivError> {
        let mut mm = ModalModel::new(self.ny, self.nu);
        for (idx, sub) in self.submodels.iter().enumerate() {
            let sub = &sub.expanded();
            match self.domain {
                Domain::Continuous => self.continuous_partial_fractions(sub, &mut mm),
                Domain::ZohDiscrete { ts } => self.discrete_partial_fractions(sub, ts, &mut mm),
            }
            .map_err(|e| match e {
                RivError::Structure(s) => RivError::Structure(format!("submodel {idx}: {s}")),
                other => other,
            })?;
        }
        Ok(mm)
    }

    fn continuous_partial_fractions(
        &self,
        sub: &Submodel,
        mm: &mut ModalModel,
    ) -> Result<(), RivError> {
        let (ny, nu) = (self.ny, self.nu);
        let sigma = sub.scale;
        let l = sub.integrators;
        let n = sub.den.len();
        let deg_num = sub.num_start + sub.num.len() - 1;
        if deg_num > n + l {
            return Err(RivError::Structure(format!(
                "improper submodel (numerator degree {deg_num} > denominator degree {})",
                n + l
            )));
        }
        // Work in x = s / sigma, then map: a term R_x/(x - x_p) = sigma R_x/(s - s_p).
        // Feedthrough: the limit at infinity when biproper.
        if deg_num == n + l {
            let lead = if n == 0 { 1.0 } else { sub.den[n - 1] };
            let b = &sub.num[sub.num.len() - 1];
            for j in 0..nu {
                for i in 0..ny {
                    mm.feedthrough[(i, j)] += b[(i, j)] / lead;
                }
            }
        }
        // Integrator part: Taylor coefficients c_t of N(x)/A(x) at 0, t < l, give
        // c_t x^(t - l) = c_t sigma^(l - t) / s^(l - t).
        if l > 0 {
            let mut c: Vec<Mat<f64>> = Vec::with_capacity(l);
            for t in 0..l {
                let mut ct = if t >= sub.num_start && t - sub.num_start < sub.num.len() {
                    sub.num[t - sub.num_start].clone()
                } else {
                    Mat::zeros(ny, nu)
                };
                for r in 1..=t.min(n) {
                    let a = sub.den[r - 1];
                    let prev = &c[t - r];
                    for j in 0..nu {
                        for i in 0..ny {
                            ct[(i, j)] -= a * prev[(i, j)];
                        }
                    }
                }
                c.push(ct);
            }
            if mm.rigid.len() < l {
                mm.rigid.resize(l, Mat::zeros(ny, nu));
            }
            for (t, ct) in c.iter().enumerate() {
                let k = l - t; // power of 1/s
                let f = sigma.powi(k as i32);
                for j in 0..nu {
                    for i in 0..ny {
                        mm.rigid[k - 1][(i, j)] += f * ct[(i, j)];
                    }
                }
            }
        }
        if n == 0 {
            return Ok(());
        }
        let roots = poly_roots_ascending(&sub.den)?;
        check_distinct(&roots)?;
        // A(x) = a_n prod (x - x_j): A'(x_j) = a_n prod_{i != j} (x_j - x_i)
        let an = sub.den[n - 1];
        let mut used = vec![false; n];
        for j in 0..n {
            if used[j] {
                continue;
            }
            let xj = roots[j];
            let mut dprime = C64::new(an, 0.0);
            for (i, xi) in roots.iter().enumerate() {
                if i != j {
                    dprime *= xj - xi;
                }
            }
            let denom = dprime * xj.powi(l as i32);
            let is_real = xj.im.abs() <= 1e-12 * xj.norm().max(1e-300);
            let sp = xj * sigma;
            // residue in s: sigma * N(x_j) / (x_j^l A'(x_j))
            let res = Mat::from_fn(ny, nu, |i, jj| {
                let mut nval = C64::new(0.0, 0.0);
                let mut xr = xj.powi(sub.num_start as i32);
                for b in &sub.num {
                    nval += xr * b[(i, jj)];
                    xr *= xj;
                }
                nval * sigma / denom
            });
            if is_real {
                mm.real_poles.push(RealPole {
                    pole: sp.re,
                    residue: Mat::from_fn(ny, nu, |i, jj| res[(i, jj)].re),
                });
                used[j] = true;
            } else {
                // mark the conjugate as used
                if let Some(c) = (0..n).find(|&c| {
                    !used[c] && c != j && (roots[c] - xj.conj()).norm() <= 1e-9 * xj.norm()
                }) {
                    used[c] = true;
                }
                used[j] = true;
                if sp.im > 0.0 {
                    mm.pairs.push(PolePair {
                        pole: sp,
                        residue: res,
                    });
                } else {
                    mm.pairs.push(PolePair {
                        pole: sp.conj(),
                        residue: Mat::from_fn(ny, nu, |i, jj| res[(i, jj)].conj()),
                    });
                }
            }
        }
        Ok(())
    }

    fn discrete_partial_fractions(
        &self,
        sub: &Submodel,
        ts: f64,
        mm: &mut ModalModel,
    ) -> Result<(), RivError> {
        let (ny, nu) = (self.ny, self.nu);
        let l = sub.integrators;
        let n = sub.den.len();
        // H(inf) = B_0 (q -> 0): a feedthrough, which ZOH leaves unchanged.
        if sub.num_start == 0 {
            for j in 0..nu {
                for i in 0..ny {
                    mm.feedthrough[(i, j)] += sub.num[0][(i, j)];
                }
            }
        }
        if l > 0 {
            if n > 0 {
                return Err(RivError::Structure(
                    "the exact-hold model supports integrators only in a submodel without \
                     other poles"
                        .into(),
                ));
            }
            // H = f(z) / (z - 1)^l with f(z) = sum_r B_r z^(l - r); gamma_k is the
            // coefficient of 1/(z-1)^k: gamma_l = f(1), gamma_{l-1} = f'(1).
            let f_at = |deriv: usize| -> Mat<f64> {
                Mat::from_fn(ny, nu, |i, j| {
                    let mut acc = 0.0;
                    for (t, b) in sub.num.iter().enumerate() {
                        let r = sub.num_start + t;
                        if r > l {
                            continue;
                        }
                        let p = (l - r) as f64;
                        let c = if deriv == 0 { 1.0 } else { p };
                        acc += c * b[(i, j)];
                    }
                    acc
                })
            };
            if sub.num_start + sub.num.len() - 1 > l {
                return Err(RivError::Structure(
                    "rigid-body numerator of degree above l in q is not a ZOH image".into(),
                ));
            }
            if mm.rigid.len() < l {
                mm.rigid.resize(l, Mat::zeros(ny, nu));
            }
            let g_l = f_at(0);
            match l {
                1 => {
                    // ZOH(a1/s) = a1 ts / (z - 1)
                    for j in 0..nu {
                        for i in 0..ny {
                            mm.rigid[0][(i, j)] += g_l[(i, j)] / ts;
                        }
                    }
                }
                2 => {
                    // ZOH(a1/s + a2/s^2) = (a1 ts + a2 ts^2/2)/(z-1) + a2 ts^2/(z-1)^2
                    let g_1 = f_at(1);
                    for j in 0..nu {
                        for i in 0..ny {
                            let a2 = g_l[(i, j)] / (ts * ts);
                            let a1 = (g_1[(i, j)] - g_l[(i, j)] / 2.0) / ts;
                            mm.rigid[1][(i, j)] += a2;
                            mm.rigid[0][(i, j)] += a1;
                        }
                    }
                }
                _ => {
                    return Err(RivError::Structure(
                        "the exact-hold model supports at most 2 integrators".into(),
                    ))
                }
            }
            return Ok(());
        }
        if n == 0 {
            if sub.num_start + sub.num.len() > 1 {
                return Err(RivError::Structure(
                    "a pure delay-line numerator (q^r, r >= 1, without poles) has no \
                     continuous-time equivalent"
                        .into(),
                ));
            }
            return Ok(());
        }
        // Poles in q are the roots of A(q); z_j = 1/q_j. Residue of H(z) at z_j:
        // z_j N(1/z_j) / prod_{i != j} (1 - z_i / z_j).
        let qroots = poly_roots_ascending(&sub.den)?;
        check_distinct(&qroots)?;
        let zroots: Vec<C64> = qroots.iter().map(|q| q.inv()).collect();
        let mut used = vec![false; n];
        for j in 0..n {
            if used[j] {
                continue;
            }
            let zj = zroots[j];
            let mut prod = C64::new(1.0, 0.0);
            for (i, zi) in zroots.iter().enumerate() {
                if i != j {
                    prod *= 1.0 - zi / zj;
                }
            }
            let qj = zj.inv();
            let p = zj.ln() / ts;
            if zj.im.abs() <= 1e-12 * zj.norm() && zj.re <= 0.0 {
                return Err(RivError::Structure(format!(
                    "discrete pole at z = {zj} on the negative real axis has no continuous \
                     equivalent"
                )));
            }
            let conv = p / (zj - 1.0);
            let res = Mat::from_fn(ny, nu, |i, jj| {
                let mut nval = C64::new(0.0, 0.0);
                let mut qr = qj.powi(sub.num_start as i32);
                for b in &sub.num {
                    nval += qr * b[(i, jj)];
                    qr *= qj;
                }
                zj * nval / prod * conv
            });
            let is_real = zj.im.abs() <= 1e-12 * zj.norm();
            if is_real {
                used[j] = true;
                mm.real_poles.push(RealPole {
                    pole: p.re,
                    residue: Mat::from_fn(ny, nu, |i, jj| res[(i, jj)].re),
                });
            } else {
                used[j] = true;
                if let Some(c) =
                    (0..n).find(|&c| !used[c] && (zroots[c] - zj.conj()).norm() <= 1e-9 * zj.norm())
                {
                    used[c] = true;
                }
                if p.im > 0.0 {
                    mm.pairs.push(PolePair {
                        pole: p,
                        residue: res,
                    });
                } else {
                    mm.pairs.push(PolePair {
                        pole: p.conj(),
                        residue: Mat::from_fn(ny, nu, |i, jj| res[(i, jj)].conj()),
                    });
                }
            }
        }
        Ok(())
    }

    /// The parameters of submodel `i` in the paper's form (6):
    /// `[a_1 .. a_n, vec(B_r0), ..]`, unscaled.
    pub fn submodel_params(&self, i: usize) -> Vec<f64> {
        let s = &self.submodels[i];
        let mut p = Vec::with_capacity(self.n_params_of(i));
        let sigma = s.scale;
        for (r, a) in s.den.iter().enumerate() {
            p.push(a / sigma.powi(r as i32 + 1));
        }
        for (t, b) in s.num.iter().enumerate() {
            let r = (s.num_start + t) as i32;
            let f = sigma.powi(s.integrators as i32 - r);
            for j in 0..self.nu {
                for ii in 0..self.ny {
                    p.push(b[(ii, j)] * f);
                }
            }
        }
        p
    }

    fn set_submodel_params(&mut self, i: usize, p: &[f64]) {
        let (ny, nu) = (self.ny, self.nu);
        let s = &mut self.submodels[i];
        let sigma = s.scale;
        let mut idx = 0;
        for (r, a) in s.den.iter_mut().enumerate() {
            *a = p[idx] * sigma.powi(r as i32 + 1);
            idx += 1;
        }
        let l = s.integrators as i32;
        let start = s.num_start;
        for (t, b) in s.num.iter_mut().enumerate() {
            let r = (start + t) as i32;
            let f = sigma.powi(r - l);
            for j in 0..nu {
                for ii in 0..ny {
                    b[(ii, j)] = p[idx] * f;
                    idx += 1;
                }
            }
        }
    }
}

fn check_scale(scale: f64) -> Result<f64, RivError> {
    if scale.is_finite() && scale > 0.0 {
        Ok(scale)
    } else {
        Err(RivError::invalid(
            "frequency scale",
            scale,
            "must be finite and > 0 rad/s",
        ))
    }
}

fn check_distinct(roots: &[C64]) -> Result<(), RivError> {
    for i in 0..roots.len() {
        for j in i + 1..roots.len() {
            let scale = roots[i].norm().max(roots[j].norm()).max(1e-300);
            if (roots[i] - roots[j]).norm() <= 1e-10 * scale {
                return Err(RivError::Structure(format!(
                    "repeated denominator root {} has no simple partial fraction",
                    roots[i]
                )));
            }
        }
    }
    Ok(())
}

/// Roots of `1 + c_1 x + ... + c_n x^n` (coefficients ascending, constant 1 implied);
/// see [`realize::poly::roots_ascending`].
pub fn poly_roots_ascending(c: &[f64]) -> Result<Vec<C64>, RivError> {
    realize::poly::roots_ascending(c).map_err(|e| RivError::Numerical {
        what: "denominator roots".into(),
        why: e.to_string(),
    })
}

impl ModelStructure for AdditiveModel {
    fn ny(&self) -> usize {
        self.ny
    }
    fn nu(&self) -> usize {
        self.nu
    }
    fn n_params(&self) -> usize {
        (0..self.submodels.len())
            .map(|i| self.n_params_of(i))
            .sum::<usize>()
            + usize::from(self.factor.fit_delay)
            + self
                .dynamics
                .iter()
                .map(|d| d.den.len() + d.num.len())
                .sum::<usize>()
    }
    /// Per submodel the paper's form (6) `[a_1..a_n, vec(B_0), ..]` (unscaled), in
    /// submodel order, then the delay (seconds) when it is a free parameter, then per
    /// dynamics factor its denominator coefficients `a_r` and numerator coefficients
    /// `b_r` (unscaled, `s^r` units).
    fn params(&self) -> Vec<f64> {
        let mut p = Vec::with_capacity(self.n_params());
        for i in 0..self.submodels.len() {
            p.extend(self.submodel_params(i));
        }
        if self.factor.fit_delay {
            p.push(self.factor.delay_s);
        }
        for d in &self.dynamics {
            for c in [&d.den, &d.num] {
                for (r, a) in c.iter().enumerate() {
                    p.push(a / d.scale.powi(r as i32 + 1));
                }
            }
        }
        p
    }
    fn set_params(&mut self, params: &[f64]) -> Result<(), FrfError> {
        let n = self.n_params();
        if params.len() != n {
            return Err(FrfError::invalid(
                "parameter vector length",
                params.len(),
                format!("the model has {n} parameters"),
            ));
        }
        if let Some(k) = params.iter().position(|x| !x.is_finite()) {
            return Err(FrfError::invalid(
                format!("parameter {k}"),
                params[k],
                "must be finite",
            ));
        }
        let mut off = 0;
        for i in 0..self.submodels.len() {
            let np = self.n_params_of(i);
            self.set_submodel_params(i, &params[off..off + np]);
            off += np;
        }
        self.sync_shapes();
        if self.factor.fit_delay {
            self.factor.delay_s = params[off];
            off += 1;
        }
        for d in &mut self.dynamics {
            let scale = d.scale;
            for c in [&mut d.den, &mut d.num] {
                for (r, a) in c.iter_mut().enumerate() {
                    *a = params[off] * scale.powi(r as i32 + 1);
                    off += 1;
                }
            }
        }
        Ok(())
    }
    /// The response at `omega`, the lines in blocks on the rayon pool when the grid is
    /// large (thousands of lines of hundreds of entries).
    fn response_at(&self, omega: &[f64]) -> realize::ResponseGrid {
        let mut g = realize::ResponseGrid::zeros(omega.len(), self.ny, self.nu);
        let coefficients: usize = self.submodels.iter().map(|s| s.num.len()).sum();
        g.fill_lines(8 * (coefficients + 1) * self.ny * self.nu, |k, line| {
            self.response_into(omega[k], line)
        });
        g
    }
    fn response_into(&self, omega: f64, out: &mut [C64]) {
        self.rational_part_into(omega, out, false);
        if !self.factor.is_identity() {
            let f = self.factor.at(omega);
            for v in out.iter_mut() {
                *v *= f;
            }
        }
        if self.submodels.iter().any(|s| s.bypass_factor) {
            let mut extra = vec![C64::new(0.0, 0.0); out.len()];
            self.rational_part_into(omega, &mut extra, true);
            for (o, x) in out.iter_mut().zip(&extra) {
                *o += x;
            }
        }
        for d in &self.dynamics {
            let h = d.at(omega);
            for j in 0..self.nu {
                for i in 0..self.ny {
                    if d.affects(i, j) {
                        out[j * self.ny + i] *= h;
                    }
                }
            }
        }
    }
    fn to_frf_model(&self) -> Result<realize::FrfModel, FrfError> {
        self.to_frf_model_exact().map_err(|e| match e {
            RivError::Data(d) => d,
            RivError::Realize(r) => FrfError::Realize(r),
            other => FrfError::Numerical {
                what: "additive model to the model currency".into(),
                why: other.to_string(),
            },
        })
    }
    fn to_modal(&self) -> Result<ModalModel, FrfError> {
        self.to_modal_model().map_err(|e| match e {
            RivError::Data(d) => d,
            RivError::Realize(r) => FrfError::Realize(r),
            other => FrfError::Numerical {
                what: "additive model to modal form".into(),
                why: other.to_string(),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(mut m: AdditiveModel, seed: u64) -> AdditiveModel {
        let mut s = seed;
        let mut rnd = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for sub in &mut m.submodels {
            for b in &mut sub.num {
                for j in 0..b.ncols() {
                    for i in 0..b.nrows() {
                        b[(i, j)] = rnd();
                    }
                }
            }
        }
        m
    }

    #[test]
    fn params_round_trip_and_paper_form() {
        let mut m = AdditiveModel::new(2, 3, Domain::Continuous).unwrap();
        m.push_rigid_body(2, 100.0).unwrap();
        m.push_mode(50.0, 0.02, false).unwrap();
        m.push_mode(80.0, 0.01, true).unwrap();
        m.push_feedthrough().unwrap();
        let m = filled(m, 3);
        let p = m.params();
        assert_eq!(p.len(), 6 + 2 + 6 + 2 + 12 + 6);
        // paper's form of the first mode: a1 = 2 zeta / w, a2 = 1 / w^2
        let w = TAU * 50.0;
        assert!((p[6] - 2.0 * 0.02 / w).abs() < 1e-15);
        assert!((p[7] - 1.0 / (w * w)).abs() < 1e-18);
        let mut m2 = m.clone();
        m2.set_params(&p).unwrap();
        for (a, b) in m2.params().iter().zip(&p) {
            assert!((a - b).abs() <= 1e-14 * b.abs().max(1e-300));
        }
        assert!(m2.set_params(&p[1..]).is_err());
    }

    #[test]
    fn continuous_modal_conversion_matches_response() {
        let mut m = AdditiveModel::new(2, 2, Domain::Continuous).unwrap();
        m.push_rigid_body(2, 300.0).unwrap();
        m.push_mode(120.0, 0.03, true).unwrap();
        m.push_mode(400.0, 0.005, false).unwrap();
        m.push_feedthrough().unwrap();
        let m = filled(m, 7);
        let mm = m.to_modal_model().unwrap();
        assert_eq!(mm.pairs.len(), 2);
        let w: Vec<f64> = (1..200).map(|k| TAU * 5.0 * k as f64).collect();
        let g = mm.freq_response(&w).unwrap();
        let h = m.response_at(&w);
        for (a, b) in g.values.iter().zip(&h.values) {
            assert!((a - b).norm() <= 1e-10 * b.norm().max(1e-12), "{a} vs {b}");
        }
        let modes = m.modes();
        assert!((modes[0].f_hz - 120.0).abs() < 1e-9 && (modes[0].zeta - 0.03).abs() < 1e-12);
    }

    #[test]
    fn discrete_modal_conversion_is_the_exact_zoh_inverse() {
        let ts = 1e-4;
        let mut m = AdditiveModel::new(2, 3, Domain::ZohDiscrete { ts }).unwrap();
        m.push_rigid_body(2, 1.0).unwrap();
        m.push_mode(640.0, 0.01, false).unwrap();
        m.push_mode(1900.0, 0.02, false).unwrap();
        m.push_feedthrough().unwrap();
        let m = filled(m, 11);
        let mm = m.to_modal_model().unwrap();
        let w: Vec<f64> = (1..400).map(|k| TAU * 5.0 * k as f64).collect();
        let g = mm.zoh_response(&w, ts, 0.0).unwrap();
        let h = m.response_at(&w);
        for (a, b) in g.values.iter().zip(&h.values) {
            assert!((a - b).norm() <= 1e-9 * b.norm().max(1e-12), "{a} vs {b}");
        }
        let modes = m.modes();
        assert!((modes[0].f_hz - 640.0).abs() < 1e-8, "{:?}", modes[0]);
        assert!((modes[1].zeta - 0.02).abs() < 1e-10);
    }

    #[test]
    fn known_factor_delay_and_derivative() {
        let mut m = AdditiveModel::new(1, 1, Domain::Continuous).unwrap();
        m.push_rigid_body(2, 10.0).unwrap();
        m.submodels[0].num[0][(0, 0)] = 1.0;
        let m = m
            .with_factor(KnownFactor {
                delay_s: 1e-3,
                derivative_order: 2,
                ..Default::default()
            })
            .unwrap();
        // (j w)^2 * sigma^2/(j w)^2 * e^{-j w tau}: B~ = 1 at x = s/10 means B = 100
        let mut out = [C64::new(0.0, 0.0)];
        m.response_into(50.0, &mut out);
        let expect = C64::from_polar(100.0, -50.0 * 1e-3);
        assert!((out[0] - expect).norm() < 1e-12);
    }

    #[test]
    fn structure_rules() {
        let mut m = AdditiveModel::new(1, 1, Domain::Continuous).unwrap();
        m.push_rigid_body(2, 1.0).unwrap();
        assert!(m.push_rigid_body(1, 1.0).is_err());
        m.push_feedthrough().unwrap();
        assert!(m.push_feedthrough().is_err());
        assert!(m.push_mode(-1.0, 0.1, false).is_err());
        assert!(m.push_mode(1.0, 1.5, false).is_err());
        let mut d = AdditiveModel::new(1, 1, Domain::ZohDiscrete { ts: 1e-3 }).unwrap();
        assert!(d.push_mode(600.0, 0.01, false).is_err());
        assert!(d
            .clone()
            .with_factor(KnownFactor {
                derivative_order: 2,
                ..Default::default()
            })
            .is_err());
    }

    #[test]
    fn unstable_detection() {
        let mut m = AdditiveModel::new(1, 1, Domain::Continuous).unwrap();
        m.push_mode(10.0, 0.1, false).unwrap();
        assert!(m.unstable_submodels().is_empty());
        m.submodels[0].den[0] = -0.2;
        assert_eq!(m.unstable_submodels(), vec![0]);
        let mut d = AdditiveModel::new(1, 1, Domain::ZohDiscrete { ts: 1e-3 }).unwrap();
        d.push_mode(10.0, 0.1, false).unwrap();
        assert!(d.unstable_submodels().is_empty());
        let zp = C64::from_polar(1.01, 0.3);
        d.submodels[0].den = vec![-2.0 * zp.re, zp.norm_sqr()];
        assert_eq!(d.unstable_submodels(), vec![0]);
    }
}
