//! The analytic Jacobian of the model currency [`FrfModel`] in the parameter order of its
//! [`ModelStructure`] implementation (`frf_data::currency`): pole pairs (`Re p`, `Im p`,
//! `Re R`, `Im R`), real poles (`p`, residue), rigid body, feedthrough, crosstalk, delay
//! and the coefficients of the dynamics factors, through the exact zero-order hold when
//! the model declares one.
//!
//! With `P_e = D_e (F R_e + X_e)` (entry `e`; `F` the delay, derivative and `sinc`
//! factor; `R_e` the rational part; `X_e` the crosstalk; `D_e` the product of the
//! dynamics factors `B_d / A_d` of the entry):
//!
//! - `dP_e / d Re p = D_e F (R h'(p) + conj(R) h'(conj p))`,
//!   `dP_e / d Im p = j D_e F (R h'(p) - conj(R) h'(conj p))`;
//! - `dP_e / d Re R_e = D_e F (h(p) + h(conj p))`, `dP_e / d Im R_e = j D_e F (h(p) - h(conj p))`;
//! - `dP_e / d tau = -j w D_e F R_e`;
//! - `dP_e / d a_i = -P_e x^i / A_d`, `dP_e / d b_i = (P_e / (B_d/A_d)) x^i / A_d` with
//!   `x = j w / scale`.

use crate::basis::{first_order, powers, rigid_bases, zoh_ts};
use crate::C64;
use frf_data::{FrfError, ModelStructure};
use realize::{FrfModel, ModalModel};

/// `d vec(P(j w)) / d theta` of `model` at `omega` into `jac` (column-major,
/// `(ny nu) x n_params`), analytically, in the order of the currency's
/// [`ModelStructure::params`].
pub fn currency_jacobian_into(model: &FrfModel, omega: f64, jac: &mut [C64]) {
    let mm = &model.modal;
    let f = &model.factors;
    let (ny, nu) = (mm.ny, mm.nu);
    let m = ny * nu;
    let n = model.n_params();
    debug_assert_eq!(jac.len(), m * n);
    jac.fill(C64::new(0.0, 0.0));
    let ts = zoh_ts(model);
    let fs = f.scalar_at(omega);
    // rational part R_e and its terms
    let mut r = vec![C64::new(0.0, 0.0); m];
    let pair_terms: Vec<_> = mm
        .pairs
        .iter()
        .map(|p| {
            let (h, dh) = first_order(p.pole, omega, ts);
            let (hc, dhc) = first_order(p.pole.conj(), omega, ts);
            (h, dh, hc, dhc)
        })
        .collect();
    let real_terms: Vec<_> = mm
        .real_poles
        .iter()
        .map(|p| first_order(C64::new(p.pole, 0.0), omega, ts))
        .collect();
    let mut rb = Vec::new();
    rigid_bases(mm.rigid.len(), omega, ts, &mut rb);
    for j in 0..nu {
        for i in 0..ny {
            let e = j * ny + i;
            let mut v = C64::new(mm.feedthrough[(i, j)], 0.0);
            for (l, rg) in mm.rigid.iter().enumerate() {
                v += rb[l] * rg[(i, j)];
            }
            for (p, t) in mm.pairs.iter().zip(&pair_terms) {
                let res = p.residue[(i, j)];
                v += res * t.0 + res.conj() * t.2;
            }
            for (p, t) in mm.real_poles.iter().zip(&real_terms) {
                v += t.0 * p.residue[(i, j)];
            }
            r[e] = v;
        }
    }
    // dynamics factors per entry
    let dyn_vals: Vec<(C64, C64)> = f
        .dynamics
        .iter()
        .map(|d| (d.at(omega), d.den_at(omega)))
        .collect();
    let dprod = |i: usize, j: usize, skip: Option<usize>| -> C64 {
        let mut v = C64::new(1.0, 0.0);
        for (k, d) in f.dynamics.iter().enumerate() {
            if Some(k) != skip && d.affects(i, j) {
                v *= dyn_vals[k].0;
            }
        }
        v
    };
    let x = f.crosstalk.as_ref();
    let mut col = 0;
    let mut put = |col: usize, e: usize, v: C64| jac[col * m + e] = v;
    for (q, p) in mm.pairs.iter().enumerate() {
        let (h, dh, hc, dhc) = pair_terms[q];
        for j in 0..nu {
            for i in 0..ny {
                let e = j * ny + i;
                let g = dprod(i, j, None) * fs;
                let res = p.residue[(i, j)];
                let a = res * dh;
                let b = res.conj() * dhc;
                put(col, e, g * (a + b));
                put(col + 1, e, g * C64::new(0.0, 1.0) * (a - b));
                put(col + 2 + e, e, g * (h + hc));
                put(col + 2 + m + e, e, g * C64::new(0.0, 1.0) * (h - hc));
            }
        }
        col += 2 + 2 * m;
    }
    for (q, p) in mm.real_poles.iter().enumerate() {
        let (h, dh) = real_terms[q];
        for j in 0..nu {
            for i in 0..ny {
                let e = j * ny + i;
                let g = dprod(i, j, None) * fs;
                put(col, e, g * dh * p.residue[(i, j)]);
                put(col + 1 + e, e, g * h);
            }
        }
        col += 1 + m;
    }
    for rbl in rb.iter().take(mm.rigid.len()) {
        for j in 0..nu {
            for i in 0..ny {
                let e = j * ny + i;
                put(col + e, e, dprod(i, j, None) * fs * rbl);
            }
        }
        col += m;
    }
    for j in 0..nu {
        for i in 0..ny {
            let e = j * ny + i;
            put(col + e, e, dprod(i, j, None) * fs);
        }
    }
    col += m;
    if x.is_some() {
        for j in 0..nu {
            for i in 0..ny {
                let e = j * ny + i;
                put(col + e, e, dprod(i, j, None));
            }
        }
        col += m;
    }
    if f.delay_fitted {
        for j in 0..nu {
            for i in 0..ny {
                let e = j * ny + i;
                put(
                    col,
                    e,
                    C64::new(0.0, -omega) * dprod(i, j, None) * fs * r[e],
                );
            }
        }
        col += 1;
    }
    for (k, d) in f.dynamics.iter().enumerate() {
        let xs = C64::new(0.0, omega / d.scale);
        let pw = powers(xs, d.den.len().max(d.num.len()));
        let a = dyn_vals[k].1;
        for j in 0..nu {
            for i in 0..ny {
                if !d.affects(i, j) {
                    continue;
                }
                let e = j * ny + i;
                let inner = fs * r[e] + x.map_or(0.0, |xm| xm[(i, j)]);
                let rest = dprod(i, j, Some(k)) * inner;
                let pe = rest * dyn_vals[k].0;
                for (c, xp) in pw.iter().take(d.den.len()).enumerate() {
                    put(col + c, e, -pe * xp / a);
                }
                for (c, xp) in pw.iter().take(d.num.len()).enumerate() {
                    put(col + d.den.len() + c, e, rest * xp / a);
                }
            }
        }
        col += d.den.len() + d.num.len();
    }
    debug_assert_eq!(col, n);
}

/// The model currency with the analytic Jacobian of [`currency_jacobian_into`] (the
/// currency's own [`ModelStructure`] implementation uses finite differences): the same
/// parameters, response and conversions.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalyticModel(pub FrfModel);

impl ModelStructure for AnalyticModel {
    fn ny(&self) -> usize {
        self.0.ny()
    }
    fn nu(&self) -> usize {
        self.0.nu()
    }
    fn n_params(&self) -> usize {
        self.0.n_params()
    }
    fn params(&self) -> Vec<f64> {
        self.0.params()
    }
    fn set_params(&mut self, params: &[f64]) -> Result<(), FrfError> {
        self.0.set_params(params)
    }
    fn response_into(&self, omega: f64, out: &mut [C64]) {
        self.0.response_into(omega, out)
    }
    fn response_at(&self, omega: &[f64]) -> realize::ResponseGrid {
        self.0.response_at(omega)
    }
    fn to_modal(&self) -> Result<ModalModel, FrfError> {
        Ok(self.0.modal.clone())
    }
    fn to_frf_model(&self) -> Result<FrfModel, FrfError> {
        Ok(self.0.clone())
    }
    fn jacobian_into(&self, omega: f64, jac: &mut [C64]) {
        currency_jacobian_into(&self.0, omega, jac)
    }
}
