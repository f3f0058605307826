//! # poly-basis: polynomial bases that keep frequency-domain fits conditioned
//!
//! A rational fit `N / D` with polynomials of degree `n` in the Laplace variable `s`
//! evaluated at `s = j w` leads to Vandermonde matrices whose columns grow like
//! `w^k`: for the 20..2000 Hz band of a wafer stage and `n = 40` no floating-point
//! solver recovers the coefficients (Jue, section 2.2.1). A [`Basis`] replaces `s` by a
//! variable `x(s)` in which the same rational functions are rational of the same degree
//! and whose powers `x^0 .. x^n` stay of unit size on the measured lines:
//!
//! - [`Basis::ScaledMonomial`]: `x = s / scale` (the simplest fix: `|x| <= 1` on the
//!   band, yet the low powers dominate at the low lines; still ill-conditioned for wide
//!   bands and high orders, see the tests);
//! - [`Basis::Bilinear`]: the prewarped bilinear map `x = (a + s) / (a - s)` (McKelvey
//!   eq. (39) with `T = 2 / a`; Jue section 2.2.1 prints the reciprocal
//!   `(s - a) / (s + a)`, which sends the left half-plane outside the unit circle). The
//!   imaginary axis goes to the unit circle, `s = j a` to `x = j`, the open left
//!   half-plane inside the unit disc. Default `a = sqrt(w_1 w_L)` (Jue);
//! - [`Basis::Sampled`]: the shift variable of sampled data `z = exp(s T_s)`, optionally
//!   prewarped by the disc automorphism `x = (z - beta) / (1 - beta z)` (real `beta`,
//!   `|beta| < 1`, chosen like the bilinear prewarp so that the band is spread over the
//!   circle). For a plant seen through a zero-order hold the measured FRF is exactly
//!   rational in `z`, so a fit in this basis is exact for sampled data; poles map back
//!   by the exact inverse `s = ln(z) / T_s`.
//!
//! - [`Orthogonal`]: polynomials of any of these variables that are orthonormal on the
//!   lines in a given weight (Vandermonde with Arnoldi), with their roots from the
//!   recurrence: what keeps high-order fits of lightly damped systems conditioned when
//!   even the powers of a unit-circle variable cancel to rounding.
//!
//! [`Basis::condition_number`] measures the conditioning of the real-stacked
//! Vandermonde matrix of a basis on a set of lines; [`roots`] finds the roots of a
//! polynomial given by its coefficients in the basis (companion-matrix eigenvalues),
//! and [`Basis::to_s`] maps them back to the Laplace variable.

use faer::Mat;
use num_complex::Complex;
use std::f64::consts::PI;

/// Complex double.
pub type C64 = Complex<f64>;

/// What went wrong in this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BasisError {
    /// A parameter of a basis is outside its domain.
    #[error("invalid {name} = {value}: {why}")]
    InvalidParameter {
        /// The parameter.
        name: String,
        /// Its value.
        value: f64,
        /// Why it is invalid.
        why: String,
    },
    /// A numerical step failed (singular value or eigenvalue solver, non-finite input).
    #[error("{what}: {why}")]
    Numerical {
        /// The step.
        what: String,
        /// Why.
        why: String,
    },
    /// A root cannot be mapped back to the Laplace variable (the pole of the map).
    #[error("root {root} of the {basis} basis has no image in s: {why}")]
    Unmappable {
        /// The root.
        root: C64,
        /// The basis name.
        basis: String,
        /// Why.
        why: String,
    },
}

/// A polynomial basis: the variable `x(s)` whose powers `x^0 .. x^n` parametrise the
/// numerator and denominator polynomials of a fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Basis {
    /// `x = s / scale`, `scale` in rad/s.
    ScaledMonomial {
        /// Frequency scale, rad/s (> 0).
        scale: f64,
    },
    /// `x = (a + s) / (a - s)`: the prewarped bilinear map (`s = j a` goes to `x = j`).
    Bilinear {
        /// Prewarp frequency, rad/s (> 0).
        a: f64,
    },
    /// `x = (z - beta) / (1 - beta z)` with `z = exp(s ts)`: the shift variable of data
    /// sampled with period `ts`, prewarped by a real disc automorphism (`beta = 0`: the
    /// plain shift variable).
    Sampled {
        /// Sample time, s (> 0).
        ts: f64,
        /// Prewarp, `|beta| < 1`.
        beta: f64,
    },
}

fn check_band(w_lo: f64, w_hi: f64) -> Result<(), BasisError> {
    if !(w_lo.is_finite() && w_lo > 0.0) {
        return Err(BasisError::InvalidParameter {
            name: "lowest frequency (rad/s)".into(),
            value: w_lo,
            why: "must be finite and > 0".into(),
        });
    }
    if !(w_hi.is_finite() && w_hi >= w_lo) {
        return Err(BasisError::InvalidParameter {
            name: "highest frequency (rad/s)".into(),
            value: w_hi,
            why: format!("must be finite and >= the lowest frequency {w_lo}"),
        });
    }
    Ok(())
}

impl Basis {
    /// Scaled monomials for the band `[w_lo, w_hi]` (rad/s): `scale = w_hi`, so that
    /// `|x| <= 1` on the band.
    pub fn scaled_monomial(w_lo: f64, w_hi: f64) -> Result<Self, BasisError> {
        check_band(w_lo, w_hi)?;
        Ok(Basis::ScaledMonomial { scale: w_hi })
    }

    /// The bilinear map prewarped at the geometric mean `a = sqrt(w_lo w_hi)` of the
    /// band (Jue, section 2.2.1).
    pub fn bilinear(w_lo: f64, w_hi: f64) -> Result<Self, BasisError> {
        check_band(w_lo, w_hi)?;
        Ok(Basis::Bilinear {
            a: (w_lo * w_hi).sqrt(),
        })
    }

    /// The shift variable of data sampled with period `ts`, prewarped so that the band
    /// `[w_lo, w_hi]` (rad/s, below the Nyquist frequency `pi / ts`) is spread over the
    /// upper half circle like the bilinear prewarp does: with
    /// `t(w) = tan(w ts / 2)`, the automorphism maps `tan(phi / 2) = g t(w)` with
    /// `g = (1 + beta) / (1 - beta) = 1 / sqrt(t(w_lo) t(w_hi))`.
    pub fn sampled(ts: f64, w_lo: f64, w_hi: f64) -> Result<Self, BasisError> {
        check_band(w_lo, w_hi)?;
        if !(ts.is_finite() && ts > 0.0) {
            return Err(BasisError::InvalidParameter {
                name: "sample time".into(),
                value: ts,
                why: "must be finite and > 0 s".into(),
            });
        }
        if w_hi * ts >= PI {
            return Err(BasisError::InvalidParameter {
                name: "highest frequency (rad/s)".into(),
                value: w_hi,
                why: format!(
                    "is at or above the Nyquist frequency {} rad/s of the sample time {ts} s",
                    PI / ts
                ),
            });
        }
        let g = 1.0 / ((0.5 * w_lo * ts).tan() * (0.5 * w_hi * ts).tan()).sqrt();
        let beta = (g - 1.0) / (g + 1.0);
        Ok(Basis::Sampled { ts, beta })
    }

    /// A short name for reports, e.g. `bilinear(a=1256.6 rad/s)`.
    pub fn name(&self) -> String {
        match *self {
            Basis::ScaledMonomial { scale } => format!("scaled monomials (s/{scale:.6} rad/s)"),
            Basis::Bilinear { a } => format!("bilinear (a = {a:.6} rad/s)"),
            Basis::Sampled { ts, beta } => {
                format!("sampled z = exp(s ts) (ts = {ts:.6e} s, prewarp beta = {beta:.6})")
            }
        }
    }

    /// Checks the parameters of the basis.
    pub fn validate(&self) -> Result<(), BasisError> {
        let bad = |name: &str, value: f64, why: &str| BasisError::InvalidParameter {
            name: name.into(),
            value,
            why: why.into(),
        };
        match *self {
            Basis::ScaledMonomial { scale } if !(scale.is_finite() && scale > 0.0) => {
                Err(bad("scale", scale, "must be finite and > 0 rad/s"))
            }
            Basis::Bilinear { a } if !(a.is_finite() && a > 0.0) => {
                Err(bad("prewarp a", a, "must be finite and > 0 rad/s"))
            }
            Basis::Sampled { ts, .. } if !(ts.is_finite() && ts > 0.0) => {
                Err(bad("sample time", ts, "must be finite and > 0 s"))
            }
            Basis::Sampled { beta, .. } if !(beta.is_finite() && beta.abs() < 1.0) => {
                Err(bad("prewarp beta", beta, "must satisfy |beta| < 1"))
            }
            _ => Ok(()),
        }
    }

    /// The variable `x(s)` at a complex `s`.
    #[inline]
    pub fn from_s(&self, s: C64) -> C64 {
        match *self {
            Basis::ScaledMonomial { scale } => s / scale,
            Basis::Bilinear { a } => (a + s) / (a - s),
            Basis::Sampled { ts, beta } => {
                let z = (s * ts).exp();
                (z - beta) / (1.0 - beta * z)
            }
        }
    }

    /// The variable at `s = j omega`.
    #[inline]
    pub fn at(&self, omega: f64) -> C64 {
        self.from_s(C64::new(0.0, omega))
    }

    /// The powers `x^0 .. x^(out.len() - 1)` of the variable at `s = j omega`.
    pub fn powers_into(&self, omega: f64, out: &mut [C64]) {
        let x = self.at(omega);
        let mut p = C64::new(1.0, 0.0);
        for o in out.iter_mut() {
            *o = p;
            p *= x;
        }
    }

    /// The shift variable `z` of [`Basis::Sampled`] for a value `x` of the prewarped
    /// variable (the inverse automorphism `z = (x + beta) / (1 + beta x)`); `x` itself
    /// for the other bases.
    pub fn to_z(&self, x: C64) -> C64 {
        match *self {
            Basis::Sampled { beta, .. } => (x + beta) / (1.0 + beta * x),
            _ => x,
        }
    }

    /// The Laplace variable of a value `x` of the basis variable: `s = scale x`,
    /// `s = a (x - 1) / (x + 1)` (exact inverse of the bilinear map), or
    /// `s = ln(z) / ts` with `z` from [`Basis::to_z`] (the exact inverse of
    /// `z = exp(s ts)` on its principal branch, `|Im s| <= pi / ts`).
    ///
    /// Fails at the pole of the inverse map (`x = -1` for the bilinear map, `z = 0` for
    /// the sampled basis) and for non-finite `x`.
    pub fn to_s(&self, x: C64) -> Result<C64, BasisError> {
        if !(x.re.is_finite() && x.im.is_finite()) {
            return Err(BasisError::Unmappable {
                root: x,
                basis: self.name(),
                why: "not finite".into(),
            });
        }
        match *self {
            Basis::ScaledMonomial { scale } => Ok(x * scale),
            Basis::Bilinear { a } => {
                let den = x + 1.0;
                if den.norm() <= 1e-300 {
                    return Err(BasisError::Unmappable {
                        root: x,
                        basis: self.name(),
                        why: "x = -1 is the image of s = infinity".into(),
                    });
                }
                Ok(a * (x - 1.0) / den)
            }
            Basis::Sampled { ts, .. } => {
                let z = self.to_z(x);
                if z.norm() <= 1e-300 || !(z.re.is_finite() && z.im.is_finite()) {
                    return Err(BasisError::Unmappable {
                        root: x,
                        basis: self.name(),
                        why: "z = 0 is the image of Re s = -infinity".into(),
                    });
                }
                Ok(z.ln() / ts)
            }
        }
    }

    /// The real-stacked Vandermonde matrix of degree `degree` on `omegas`: rows
    /// `Re x_k^j` then `Im x_k^j`, columns `j = 0 .. degree`.
    pub fn stacked_vandermonde(&self, omegas: &[f64], degree: usize) -> Mat<f64> {
        let l = omegas.len();
        let mut v = Mat::<f64>::zeros(2 * l, degree + 1);
        let mut row = vec![C64::new(0.0, 0.0); degree + 1];
        for (k, &w) in omegas.iter().enumerate() {
            self.powers_into(w, &mut row);
            for (j, p) in row.iter().enumerate() {
                v[(k, j)] = p.re;
                v[(l + k, j)] = p.im;
            }
        }
        v
    }

    /// The 2-norm condition number `sigma_max / sigma_min` of
    /// [`Basis::stacked_vandermonde`]: how much the least-squares problem of a
    /// polynomial of degree `degree` in this basis on the lines `omegas` amplifies
    /// rounding errors. `inf` when the matrix is rank deficient (fewer than
    /// `(degree + 2) / 2` lines, or lines the variable maps onto the same point).
    ///
    /// What the tests show (20..2000 Hz, 400 log-spaced lines, degree 40): scaled
    /// monomials 9e14 (numerically singular), the plain shift variable of 10 kHz data
    /// 1e16 (the band covers only 0.013..1.26 rad of the circle), while the bilinear
    /// and the prewarped sampled basis stay at 19 and 15.
    pub fn condition_number(&self, omegas: &[f64], degree: usize) -> Result<f64, BasisError> {
        self.validate()?;
        if let Some(w) = omegas.iter().find(|w| !w.is_finite()) {
            return Err(BasisError::InvalidParameter {
                name: "frequency".into(),
                value: *w,
                why: "must be finite".into(),
            });
        }
        let v = self.stacked_vandermonde(omegas, degree);
        if v.nrows() < v.ncols() {
            return Ok(f64::INFINITY);
        }
        let sv = v.singular_values().map_err(|e| BasisError::Numerical {
            what: "singular values of the basis matrix".into(),
            why: format!("{e:?}"),
        })?;
        let max = sv.iter().copied().fold(0.0, f64::max);
        let min = sv.iter().copied().fold(f64::INFINITY, f64::min);
        Ok(if min > 0.0 { max / min } else { f64::INFINITY })
    }
}

/// Polynomials orthonormal on a set of points (Vandermonde with Arnoldi; Forsythe's
/// three-term idea generalised to points off the real line, as in Brubeck, Nakatsukasa
/// and Trefethen, "Vandermonde with Arnoldi", SIAM Review 2021).
///
/// With points `x_k` of a [`Basis`] at the lines and weights `w_k >= 0`, the real inner
/// product `<p, q> = sum_k w_k Re(p(x_k) conj q(x_k))` (the points and their
/// conjugates: polynomials with real coefficients) gives polynomials `q_0 .. q_n` with
/// real coefficients, `<q_i, q_j> = delta_ij`, and the Hessenberg recurrence
/// `x q_j = sum_(i <= j + 1) H[i, j] q_i`. A least-squares problem in this basis has
/// condition number 1 in the weighted norm whatever the degree, and a polynomial that is
/// tiny at some points (a denominator with lightly damped roots near the lines) is
/// represented without cancellation when the weights are large there. Only the values
/// at the points and `H` are kept: roots come from [`Orthogonal::roots`].
#[derive(Debug, Clone)]
pub struct Orthogonal {
    /// Number of points.
    pub n_points: usize,
    /// Degree.
    pub degree: usize,
    /// `q_j(x_k)`, point after point (`k * (degree + 1) + j`).
    pub values: Vec<C64>,
    /// The recurrence, `(degree + 1) x degree`.
    pub h: Mat<f64>,
}

impl Orthogonal {
    /// The orthonormal polynomials of degree `0..=degree` on `points` with `weights`.
    ///
    /// Fails (the basis is numerically singular) when the points cannot carry a
    /// polynomial of that degree: fewer distinct points (with their conjugates) than
    /// `degree + 1`, zero weights, or the Arnoldi step losing its new direction to
    /// rounding (`H[j + 1, j]` below `1e-13` of the norm of `x q_j`).
    pub fn new(points: &[C64], weights: &[f64], degree: usize) -> Result<Self, BasisError> {
        let l = points.len();
        if weights.len() != l {
            return Err(BasisError::InvalidParameter {
                name: "weights".into(),
                value: weights.len() as f64,
                why: format!("one weight per point expected ({l})"),
            });
        }
        if let Some(k) = (0..l)
            .find(|&k| !(weights[k] >= 0.0 && weights[k].is_finite() && points[k].is_finite()))
        {
            return Err(BasisError::InvalidParameter {
                name: format!("point/weight {k}"),
                value: weights[k],
                why: "points must be finite and weights finite and >= 0".into(),
            });
        }
        let nc = degree + 1;
        let dot = |a: &[C64], b: &[C64]| -> f64 {
            let mut s = 0.0;
            for k in 0..l {
                s += weights[k] * (a[k].re * b[k].re + a[k].im * b[k].im);
            }
            s
        };
        let mut cols: Vec<Vec<C64>> = Vec::with_capacity(nc);
        let w0: f64 = weights.iter().sum();
        if w0.is_nan() || w0 <= 0.0 {
            return Err(BasisError::Numerical {
                what: "orthogonal basis".into(),
                why: "every weight is zero".into(),
            });
        }
        cols.push(vec![C64::new(1.0 / w0.sqrt(), 0.0); l]);
        let mut h = Mat::<f64>::zeros(nc, degree);
        for j in 0..degree {
            let mut v: Vec<C64> = (0..l).map(|k| points[k] * cols[j][k]).collect();
            let norm0 = dot(&v, &v).sqrt();
            // classical Gram-Schmidt, twice (re-orthogonalisation)
            for _ in 0..2 {
                for (i, q) in cols.iter().enumerate() {
                    let c = dot(&v, q);
                    h[(i, j)] += c;
                    for k in 0..l {
                        v[k] -= q[k] * c;
                    }
                }
            }
            let nv = dot(&v, &v).sqrt();
            if nv.is_nan() || nv <= 1e-13 * norm0 {
                return Err(BasisError::Numerical {
                    what: format!("orthogonal basis of degree {degree}"),
                    why: format!(
                        "numerically singular at degree {}: the {l} points (with their \
                         conjugates) and weights do not determine a polynomial of that degree",
                        j + 1
                    ),
                });
            }
            h[(j + 1, j)] = nv;
            for x in v.iter_mut() {
                *x /= nv;
            }
            cols.push(v);
        }
        let mut values = vec![C64::new(0.0, 0.0); l * nc];
        for (j, c) in cols.iter().enumerate() {
            for k in 0..l {
                values[k * nc + j] = c[k];
            }
        }
        Ok(Self {
            n_points: l,
            degree,
            values,
            h,
        })
    }

    /// `q_0(x_k) .. q_n(x_k)` at point `k`.
    pub fn row(&self, k: usize) -> &[C64] {
        let nc = self.degree + 1;
        &self.values[k * nc..(k + 1) * nc]
    }

    /// `sum_j c_j q_j(x_k)`.
    pub fn eval_at(&self, c: &[f64], k: usize) -> C64 {
        self.row(k)
            .iter()
            .zip(c)
            .fold(C64::new(0.0, 0.0), |acc, (q, a)| acc + q * *a)
    }

    /// The roots of `sum_j c_j q_j(x)`: the eigenvalues of the Hessenberg recurrence
    /// with its last column corrected by the coefficients (the "confederate" matrix
    /// `K = H[0..n, 0..n] - H[n, n-1] / c_n c e_(n-1)^T`). Negligible trailing
    /// coefficients (`|c_j| <= 1e-14 max |c|`) lower the degree first (roots at
    /// infinity).
    pub fn roots(&self, c: &[f64]) -> Result<Vec<C64>, BasisError> {
        if c.len() != self.degree + 1 || c.iter().any(|v| !v.is_finite()) {
            return Err(BasisError::Numerical {
                what: "roots in the orthogonal basis".into(),
                why: format!(
                    "{} finite coefficients expected, got {}",
                    self.degree + 1,
                    c.len()
                ),
            });
        }
        let max = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if max == 0.0 {
            return Err(BasisError::Numerical {
                what: "roots in the orthogonal basis".into(),
                why: "every coefficient is zero".into(),
            });
        }
        let mut n = self.degree;
        while n > 0 && c[n].abs() <= 1e-14 * max {
            n -= 1;
        }
        if n == 0 {
            return Ok(Vec::new());
        }
        let mut k = Mat::<f64>::from_fn(n, n, |i, j| self.h[(i, j)]);
        let t = self.h[(n, n - 1)] / c[n];
        for i in 0..n {
            k[(i, n - 1)] -= t * c[i];
        }
        let ev = k.eigenvalues().map_err(|e| BasisError::Numerical {
            what: "roots in the orthogonal basis".into(),
            why: format!("eigenvalues of the recurrence matrix: {e:?}"),
        })?;
        Ok(ev.into_iter().map(|z| C64::new(z.re, z.im)).collect())
    }
}

/// The roots of the polynomial `c_0 + c_1 x + ... + c_n x^n` (coefficients ascending,
/// real): the eigenvalues of the companion matrix of the monic polynomial. Trailing
/// coefficients that are negligible (`|c_j| <= 1e-14 max |c|`) are dropped first (roots
/// at infinity of the variable). An all-zero polynomial is an error.
pub fn roots(c: &[f64]) -> Result<Vec<C64>, BasisError> {
    if c.iter().any(|v| !v.is_finite()) {
        return Err(BasisError::Numerical {
            what: "polynomial roots".into(),
            why: "a coefficient is not finite".into(),
        });
    }
    let max = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if max == 0.0 {
        return Err(BasisError::Numerical {
            what: "polynomial roots".into(),
            why: "every coefficient is zero".into(),
        });
    }
    let mut n = c.len() - 1;
    while n > 0 && c[n].abs() <= 1e-14 * max {
        n -= 1;
    }
    if n == 0 {
        return Ok(Vec::new());
    }
    let cn = c[n];
    let mut comp = Mat::<f64>::zeros(n, n);
    for i in 1..n {
        comp[(i, i - 1)] = 1.0;
    }
    for i in 0..n {
        comp[(i, n - 1)] = -c[i] / cn;
    }
    let ev = comp.eigenvalues().map_err(|e| BasisError::Numerical {
        what: "polynomial roots".into(),
        why: format!("eigenvalues of the companion matrix: {e:?}"),
    })?;
    Ok(ev.into_iter().map(|z| C64::new(z.re, z.im)).collect())
}

/// The value of `c_0 + c_1 x + ... + c_n x^n` at `x` (Horner).
#[inline]
pub fn eval(c: &[f64], x: C64) -> C64 {
    let mut acc = C64::new(0.0, 0.0);
    for &a in c.iter().rev() {
        acc = acc * x + a;
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn band(n: usize) -> Vec<f64> {
        // 20..2000 Hz, log-spaced
        (0..n)
            .map(|k| TAU * 20.0 * 100f64.powf(k as f64 / (n - 1) as f64))
            .collect()
    }

    #[test]
    fn bilinear_maps_left_half_plane_inside_and_axis_onto_circle() {
        let b = Basis::bilinear(TAU * 20.0, TAU * 2000.0).unwrap();
        let Basis::Bilinear { a } = b else { panic!() };
        // the erratum: s = -a/2 must map inside (|x| = 1/3), not to -3
        assert!((b.from_s(C64::new(-a / 2.0, 0.0)).norm() - 1.0 / 3.0).abs() < 1e-14);
        assert!((b.at(a) - C64::new(0.0, 1.0)).norm() < 1e-14);
        for w in band(50) {
            assert!((b.at(w).norm() - 1.0).abs() < 1e-13);
        }
        for s in [
            C64::new(-3.0, 700.0),
            C64::new(-100.0, 0.0),
            C64::new(5.0, 9e3),
        ] {
            let x = b.from_s(s);
            assert_eq!(x.norm() < 1.0, s.re < 0.0);
            assert!((b.to_s(x).unwrap() - s).norm() <= 1e-11 * s.norm());
        }
        assert!(b.to_s(C64::new(-1.0, 0.0)).is_err());
    }

    #[test]
    fn sampled_basis_inverts_exactly_and_spreads_the_band() {
        let ts = 1e-4;
        let b = Basis::sampled(ts, TAU * 20.0, TAU * 2000.0).unwrap();
        for s in [
            C64::new(-3.0, 700.0),
            C64::new(-100.0, 0.0),
            C64::new(-50.0, 2e4),
        ] {
            let x = b.from_s(s);
            assert!(x.norm() < 1.0);
            assert!((b.to_s(x).unwrap() - s).norm() <= 1e-10 * s.norm());
        }
        // geometric-mean line at x = j, band ends symmetric about it
        let lo = b.at(TAU * 20.0).arg();
        let hi = b.at(TAU * 2000.0).arg();
        assert!((lo + hi - PI).abs() < 1e-12, "{lo} {hi}");
        assert!(Basis::sampled(ts, 1.0, PI / ts).is_err());
    }

    #[test]
    fn roots_of_a_known_polynomial() {
        // (x - 0.5)(x^2 + 0.2 x + 0.9) = x^3 - 0.3 x^2 + 0.8 x - 0.45
        let r = roots(&[-0.45, 0.8, -0.3, 1.0]).unwrap();
        assert_eq!(r.len(), 3);
        for z in &r {
            assert!(eval(&[-0.45, 0.8, -0.3, 1.0], *z).norm() < 1e-13);
        }
        // negligible leading coefficient: a root at infinity dropped
        assert_eq!(roots(&[1.0, 2.0, 1e-30]).unwrap().len(), 1);
        assert!(roots(&[0.0, 0.0]).is_err());
    }

    #[test]
    fn orthogonal_basis_is_orthonormal_and_finds_roots() {
        let w = band(300);
        let b = Basis::bilinear(w[0], w[w.len() - 1]).unwrap();
        let x: Vec<C64> = w.iter().map(|&o| b.at(o)).collect();
        // weights with a dynamic range of 1e12, as 1/|d|^2 near lightly damped roots
        let wt: Vec<f64> = (0..x.len())
            .map(|k| 10f64.powf(12.0 * ((k * 7) % 13) as f64 / 12.0))
            .collect();
        let n = 60;
        let o = Orthogonal::new(&x, &wt, n).unwrap();
        let mut worst: f64 = 0.0;
        for i in 0..=n {
            for j in 0..=n {
                let mut s = 0.0;
                for k in 0..x.len() {
                    let (a, c) = (o.row(k)[i], o.row(k)[j]);
                    s += wt[k] * (a.re * c.re + a.im * c.im);
                }
                worst = worst.max((s - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
        assert!(worst < 1e-10, "orthonormality {worst:e}");
        // a polynomial with known roots, fitted in the basis, gives them back
        let r0 = [C64::new(0.3, 0.9), C64::new(0.3, -0.9), C64::new(-0.5, 0.0)];
        let p = |z: C64| r0.iter().fold(C64::new(1.0, 0.0), |a, r| a * (z - r));
        let o3 = Orthogonal::new(&x, &wt, 3).unwrap();
        let c: Vec<f64> = (0..=3)
            .map(|j| {
                (0..x.len())
                    .map(|k| {
                        let (q, v) = (o3.row(k)[j], p(x[k]));
                        wt[k] * (q.re * v.re + q.im * v.im)
                    })
                    .sum()
            })
            .collect();
        let mut r = o3.roots(&c).unwrap();
        r.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        assert_eq!(r.len(), 3);
        assert!((r[0] - r0[2]).norm() < 1e-10, "{r:?}");
        assert!(
            (r[1] - r0[1]).norm() < 1e-10 && (r[2] - r0[0]).norm() < 1e-10,
            "{r:?}"
        );
        // too few points for the degree: numerically singular, a clear error
        let e = Orthogonal::new(&x[..5], &wt[..5], 12).unwrap_err();
        assert!(e.to_string().contains("numerically singular"), "{e}");
    }

    /// The condition numbers that motivate the bases (20..2000 Hz, 400 log-spaced
    /// lines, degree 40; measured: 9.3e14, 19, 15 and 9.8e15): scaled monomials are
    /// numerically singular; the bilinear and the prewarped sampled basis (10 kHz) stay
    /// below 1e3; the plain shift variable (`beta = 0`), whose band covers only
    /// 0.013..1.26 rad of the circle, is singular too: the prewarp is what makes the
    /// sampled basis usable.
    #[test]
    fn condition_numbers_of_the_bases() {
        let w = band(400);
        let (lo, hi) = (w[0], w[w.len() - 1]);
        let mono = Basis::scaled_monomial(lo, hi).unwrap();
        let bil = Basis::bilinear(lo, hi).unwrap();
        let samp = Basis::sampled(1e-4, lo, hi).unwrap();
        let plain = Basis::Sampled {
            ts: 1e-4,
            beta: 0.0,
        };
        let c = |b: &Basis, n| b.condition_number(&w, n).unwrap();
        let (m4, m40) = (c(&mono, 4), c(&mono, 40));
        let (b40, s40, p40) = (c(&bil, 40), c(&samp, 40), c(&plain, 40));
        println!(
            "monomial n=4 {m4:.2e}, n=40 {m40:.2e}; bilinear n=40 {b40:.2e}; \
             sampled prewarped n=40 {s40:.2e}; sampled plain n=40 {p40:.2e}"
        );
        assert!(m40 > 1e12, "{m40:e}");
        assert!(b40 < 1e3, "{b40:e}");
        assert!(s40 < 1e3, "{s40:e}");
        assert!(p40 > 1e3 * s40, "{p40:e} vs {s40:e}");
        // too few lines: rank deficient
        assert!(c(&bil, 40).is_finite());
        assert_eq!(bil.condition_number(&w[..10], 40).unwrap(), f64::INFINITY);
    }
}
