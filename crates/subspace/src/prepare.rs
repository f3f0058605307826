//! The data of the subspace fit: the known factor divided out, the frequency variable
//! `xi_k` on the unit circle and the noise "variance" of every entry.
//!
//! - With an exact zero-order hold ([`realize::Hold::Zoh`]) the plant seen through the
//!   hold is exactly a discrete-time state space in `z = exp(j w Ts)`: `xi_k = z_k`.
//! - Otherwise the continuous model is fitted in the bilinear variable of eq. (39) of
//!   McKelvey's chapter, `xi_k = exp(j w_k^d)` with `w_k^d = 2 atan(w_k T / 2)`, and
//!   `s = (2/T)(xi - 1)/(xi + 1)` exactly. `T = 2 / w_c` with `w_c` the geometric mean
//!   of the band edges (the prewarp), so the band is spread symmetrically around
//!   `xi = j` and no power of `s` appears.
//!
//! In both cases `|xi_k| = 1`, so the rows `xi^i` of the data equation (6) are equally
//! scaled.

use crate::SubspaceError;
use frf_data::{FrfDataset, Weighting};
use realize::{Hold, KnownFactors, C64};

/// The variable the state space is identified in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Variable {
    /// `z = exp(j w ts)`: the exact zero-order-hold image, discrete time.
    Shift {
        /// Sample time, seconds.
        ts: f64,
    },
    /// The bilinear variable `xi = (2 + s T)/(2 - s T)` of eq. (39) (McKelvey).
    Bilinear {
        /// The bilinear parameter `T`, seconds (`2/T` is the prewarp frequency, rad/s).
        t: f64,
    },
}

impl Variable {
    /// `xi` at the angular frequency `w` (rad/s).
    pub fn at(&self, w: f64) -> C64 {
        match *self {
            Variable::Shift { ts } => C64::from_polar(1.0, w * ts),
            Variable::Bilinear { t } => C64::from_polar(1.0, 2.0 * (w * t / 2.0).atan()),
        }
    }
    /// The continuous pole `s` of an eigenvalue `xi` of the identified `A`:
    /// `ln(z)/ts` (exact for the hold) or `(2/T)(xi - 1)/(xi + 1)`.
    pub fn to_s(&self, xi: C64) -> C64 {
        match *self {
            Variable::Shift { ts } => xi.ln() / ts,
            Variable::Bilinear { t } => (xi - 1.0) / (xi + 1.0) * (2.0 / t),
        }
    }
    /// A short description for reports.
    pub fn describe(&self) -> String {
        match *self {
            Variable::Shift { ts } => {
                format!("discrete time, z = exp(j w Ts), Ts = {ts:.6e} s (exact zero-order hold)")
            }
            Variable::Bilinear { t } => format!(
                "continuous time through the bilinear map (39), prewarp {:.4} Hz",
                2.0 / t / std::f64::consts::TAU
            ),
        }
    }
}

/// The data in the form the algorithm uses.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// Angular frequencies of the lines, rad/s.
    pub omega: Vec<f64>,
    /// `xi_k`, one per line.
    pub xi: Vec<C64>,
    /// `G_k / F(w_k)` (the known scalar factor divided out), line after line, each line
    /// `vec(G)` column-major.
    pub h: Vec<C64>,
    /// The weights of the criterion on `G` (the chain's weighting), same layout.
    pub w: Vec<f64>,
    /// True when the weighting is uniform (the unweighted algorithm).
    pub uniform: bool,
    /// `|F(w_k)|^2` of the divided-out factor, per line.
    pub fabs2: Vec<f64>,
    /// The variable.
    pub variable: Variable,
}

impl Prepared {
    /// Lines.
    pub fn n_lines(&self) -> usize {
        self.omega.len()
    }

    /// Weighted energy `sum w |h|^2` of the data with the weights of (17) (`1 / var_h`,
    /// or 1 unweighted).
    pub fn energy(&self) -> f64 {
        let m = self.ny * self.nu;
        let mut e = 0.0;
        for k in 0..self.n_lines() {
            for i in 0..m {
                let w = if self.uniform {
                    1.0
                } else {
                    let v = self.var_h(k, i);
                    if v.is_finite() {
                        1.0 / v
                    } else {
                        0.0
                    }
                };
                e += w * self.h[k * m + i].norm_sqr();
            }
        }
        e
    }

    /// `var_ke` of `h` (the inverse weight scaled by `|F|^-2`), infinite for a zero
    /// weight.
    pub fn var_h(&self, k: usize, e: usize) -> f64 {
        let w = self.w[k * self.ny * self.nu + e];
        if w > 0.0 {
            1.0 / (w * self.fabs2[k])
        } else {
            f64::INFINITY
        }
    }
}

/// Divides the known scalar factor `factors.scalar_at` out of `data` and sets up the
/// variable: [`Variable::Shift`] for [`Hold::Zoh`], the prewarped bilinear variable
/// otherwise.
pub fn prepare<D: FrfDataset + ?Sized>(
    data: &D,
    factors: &KnownFactors,
    weighting: &Weighting,
) -> Result<Prepared, SubspaceError> {
    let (ny, nu, n) = (data.ny(), data.nu(), data.n_lines());
    let m = ny * nu;
    let omega = data.omegas();
    if omega.iter().any(|w| !(w.is_finite() && *w > 0.0)) {
        return Err(SubspaceError::invalid(
            "frequency",
            omega.iter().copied().fold(f64::NAN, f64::min) / std::f64::consts::TAU,
            "every line must be at a finite frequency > 0 Hz",
        ));
    }
    let variable = match factors.hold {
        Hold::Zoh { fs_hz } => {
            let hi = omega.last().copied().unwrap_or(0.0) / std::f64::consts::TAU;
            if !(fs_hz.is_finite() && fs_hz > 2.0 * hi) {
                return Err(SubspaceError::invalid(
                    "hold sample rate (Hz)",
                    fs_hz,
                    format!(
                        "the exact hold needs every line below Nyquist; the data reach {hi} Hz"
                    ),
                ));
            }
            Variable::Shift { ts: 1.0 / fs_hz }
        }
        _ => {
            let (lo, hi) = (
                omega.first().copied().unwrap_or(1.0),
                omega.last().copied().unwrap_or(1.0),
            );
            let _ = lo;
            Variable::Bilinear { t: 2.0 / hi }
        }
    };
    let resolved = weighting.resolve(data);
    let w = resolved.weights(data)?;
    let uniform = matches!(resolved, Weighting::Uniform);
    let mut h = data.values_vec();
    let mut fabs2 = Vec::with_capacity(n);
    for k in 0..n {
        let f = factors.scalar_at(omega[k]);
        if f.norm() == 0.0 || !f.norm().is_finite() {
            return Err(SubspaceError::invalid(
                "known factor",
                format!("{f}"),
                format!("it vanishes at line {k} ({} Hz)", data.freq_hz(k)),
            ));
        }
        let inv = f.inv();
        for v in &mut h[k * m..(k + 1) * m] {
            *v *= inv;
        }
        fabs2.push(f.norm_sqr());
    }
    let xi = omega.iter().map(|&wk| variable.at(wk)).collect();
    Ok(Prepared {
        ny,
        nu,
        omega,
        xi,
        h,
        w,
        uniform,
        fabs2,
        variable,
    })
}
