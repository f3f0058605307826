//! [`ModelStructure`] for the model currency [`FrfModel`]: the modal parametrisation
//! that any refiner can work in, whatever produced the model.
//!
//! Parameter order (all real):
//!
//! 1. per pole pair: `Re p`, `Im p` (rad/s), then `Re R` and `Im R` of the residue of the
//!    upper pole, each `ny x nu` column-major;
//! 2. per real pole: `p` (rad/s), then its real residue;
//! 3. the rigid-body coefficients `R_1 .. R_l` of `1/s^k`, each column-major;
//! 4. the feedthrough, column-major;
//! 5. the crosstalk, column-major, when present;
//! 6. the delay (seconds), when it is a fitted parameter;
//! 7. per dynamics factor: its denominator coefficients, then its numerator
//!    coefficients, both in the scaled variable `x = s / scale`.

use crate::{FrfError, ModelStructure, C64};
use faer::Mat;
use realize::{FrfModel, ModalModel};

fn push_real(p: &mut Vec<f64>, m: &Mat<f64>) {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            p.push(m[(i, j)]);
        }
    }
}

fn take_real(m: &mut Mat<f64>, p: &[f64], off: &mut usize) {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            m[(i, j)] = p[*off];
            *off += 1;
        }
    }
}

impl ModelStructure for FrfModel {
    fn ny(&self) -> usize {
        self.modal.ny
    }
    fn nu(&self) -> usize {
        self.modal.nu
    }
    fn n_params(&self) -> usize {
        let m = self.modal.ny * self.modal.nu;
        let f = &self.factors;
        self.modal.pairs.len() * (2 + 2 * m)
            + self.modal.real_poles.len() * (1 + m)
            + self.modal.rigid.len() * m
            + m
            + if f.crosstalk.is_some() { m } else { 0 }
            + usize::from(f.delay_fitted)
            + f.dynamics
                .iter()
                .map(|d| d.den.len() + d.num.len())
                .sum::<usize>()
    }
    fn params(&self) -> Vec<f64> {
        let mm = &self.modal;
        let mut p = Vec::with_capacity(self.n_params());
        for pair in &mm.pairs {
            p.push(pair.pole.re);
            p.push(pair.pole.im);
            for part in [0, 1] {
                for j in 0..mm.nu {
                    for i in 0..mm.ny {
                        let r = pair.residue[(i, j)];
                        p.push(if part == 0 { r.re } else { r.im });
                    }
                }
            }
        }
        for rp in &mm.real_poles {
            p.push(rp.pole);
            push_real(&mut p, &rp.residue);
        }
        for r in &mm.rigid {
            push_real(&mut p, r);
        }
        push_real(&mut p, &mm.feedthrough);
        if let Some(x) = &self.factors.crosstalk {
            push_real(&mut p, x);
        }
        if self.factors.delay_fitted {
            p.push(self.factors.delay_s);
        }
        for d in &self.factors.dynamics {
            p.extend_from_slice(&d.den);
            p.extend_from_slice(&d.num);
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
        let (ny, nu) = (self.modal.ny, self.modal.nu);
        let mut off = 0;
        for pair in &mut self.modal.pairs {
            pair.pole = C64::new(params[off], params[off + 1]);
            off += 2;
            let m = ny * nu;
            for j in 0..nu {
                for i in 0..ny {
                    let e = j * ny + i;
                    pair.residue[(i, j)] = C64::new(params[off + e], params[off + m + e]);
                }
            }
            off += 2 * m;
        }
        for rp in &mut self.modal.real_poles {
            rp.pole = params[off];
            off += 1;
            take_real(&mut rp.residue, params, &mut off);
        }
        for r in &mut self.modal.rigid {
            take_real(r, params, &mut off);
        }
        take_real(&mut self.modal.feedthrough, params, &mut off);
        if let Some(x) = &mut self.factors.crosstalk {
            take_real(x, params, &mut off);
        }
        if self.factors.delay_fitted {
            self.factors.delay_s = params[off];
            off += 1;
        }
        for d in &mut self.factors.dynamics {
            for v in d.den.iter_mut().chain(d.num.iter_mut()) {
                *v = params[off];
                off += 1;
            }
        }
        debug_assert_eq!(off, n);
        Ok(())
    }
    fn response_into(&self, omega: f64, out: &mut [C64]) {
        match self.freq_response(&[omega]) {
            Ok(g) => out.copy_from_slice(g.line(0)),
            Err(_) => out.fill(C64::new(f64::NAN, f64::NAN)),
        }
    }
    fn response_at(&self, omega: &[f64]) -> realize::ResponseGrid {
        self.freq_response(omega).unwrap_or_else(|_| {
            let mut g = realize::ResponseGrid::zeros(omega.len(), self.ny(), self.nu());
            g.values.fill(C64::new(f64::NAN, f64::NAN));
            g
        })
    }
    fn to_modal(&self) -> Result<ModalModel, FrfError> {
        Ok(self.modal.clone())
    }
    fn to_frf_model(&self) -> Result<FrfModel, FrfError> {
        Ok(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realize::{DynamicsFactor, FactorTarget, PolePair, RealPole};

    fn model() -> FrfModel {
        let mut mm = ModalModel::new(2, 3);
        mm.rigid = vec![
            Mat::zeros(2, 3),
            Mat::from_fn(2, 3, |i, j| (i + j) as f64 + 0.5),
        ];
        mm.pairs.push(PolePair::from_f_zeta(
            40.0,
            0.03,
            Mat::from_fn(2, 3, |i, j| C64::new(0.1 * i as f64, -1.0 - j as f64)),
        ));
        mm.real_poles.push(RealPole {
            pole: -300.0,
            residue: Mat::from_fn(2, 3, |i, j| (i * j) as f64),
        });
        let mut fm = FrfModel::new(mm);
        fm.factors.delay_s = 2e-4;
        fm.factors.delay_fitted = true;
        fm.factors.crosstalk = Some(Mat::from_fn(2, 3, |i, _| 1e-3 * i as f64));
        fm.factors.dynamics.push(DynamicsFactor::second_order(
            FactorTarget::Output(1),
            200.0,
            0.1,
        ));
        fm
    }

    #[test]
    fn params_round_trip() {
        let fm = model();
        let p = fm.params();
        assert_eq!(p.len(), fm.n_params());
        assert_eq!(p.len(), (2 + 12) + (1 + 6) + 12 + 6 + 6 + 1 + 2);
        let mut g = fm.clone();
        let q: Vec<f64> = p.iter().map(|v| v * 1.01 + 1e-3).collect();
        g.set_params(&q).unwrap();
        assert_eq!(g.params(), q);
        g.set_params(&p).unwrap();
        assert_eq!(g, fm);
        assert!(g.set_params(&p[1..]).is_err());
    }

    #[test]
    fn finite_difference_jacobian_of_the_delay() {
        let mut fm = model();
        fm.factors.crosstalk = None; // it bypasses the delay
        let (m, n) = (6, fm.n_params());
        let w = 2.0 * std::f64::consts::PI * 55.0;
        let mut jac = vec![C64::new(0.0, 0.0); m * n];
        fm.jacobian_into(w, &mut jac);
        let mut p0 = vec![C64::new(0.0, 0.0); m];
        fm.response_into(w, &mut p0);
        // d P / d tau = -j w P
        let col = n - 3;
        for e in 0..m {
            let expect = C64::new(0.0, -w) * p0[e];
            assert!((jac[col * m + e] - expect).norm() <= 1e-5 * expect.norm().max(1e-12));
        }
    }
}
