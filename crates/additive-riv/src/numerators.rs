//! The convex numerator problem (24)-(25) of the wafer-stage paper: with the
//! denominators fixed, each entry of `vec(G)` is a linear least-squares problem in its own
//! numerator coefficients, solved by QR (faer) entry by entry.

use crate::problem::{pack, unpack, Basis, FitData, Layout};
use crate::{AdditiveModel, RivError};
use faer::linalg::solvers::SolveLstsq;
use faer::Mat;
use rayon::prelude::*;

/// Fits every numerator of `model` to `data` with the denominators held fixed
/// (eq. 24 with the regressor (25), weighted by `data.w`, the known factor included in
/// the regressor). Returns the weighted cost `sum w |E|^2` after the fit.
pub fn fit_numerators(model: &mut AdditiveModel, data: &FitData) -> Result<f64, RivError> {
    let lay = Layout::of(model);
    let nn = lay.n_num;
    let n = data.n;
    let m = data.m();
    if nn == 0 {
        return Err(RivError::Structure("the model has no submodels".into()));
    }
    if 2 * n < nn {
        return Err(RivError::TooFewData {
            observations: 2 * n,
            lines: n,
            entries: 1,
            parameters: nn,
        });
    }
    let basis = Basis::new(model, &lay, &data.omega);
    let solve_entry = |e: usize| -> Result<Vec<f64>, RivError> {
        let mut a = Mat::<f64>::zeros(2 * n, nn);
        let mut b = Mat::<f64>::zeros(2 * n, 1);
        let mut colscale = vec![0.0f64; nn];
        for k in 0..n {
            let sw = data.w[k * m + e].sqrt();
            let fk = basis.f[k];
            for j in 0..nn {
                let v = basis.u[k * nn + j] * fk * sw;
                a[(k, j)] = v.re;
                a[(n + k, j)] = v.im;
                colscale[j] = colscale[j].max(v.norm());
            }
            let g = data.g[k * m + e] * sw;
            b[(k, 0)] = g.re;
            b[(n + k, 0)] = g.im;
        }
        for (j, c) in colscale.iter_mut().enumerate() {
            if *c == 0.0 {
                return Err(RivError::Numerical {
                    what: "numerator least squares".into(),
                    why: format!("basis function {j} is zero on every weighted line"),
                });
            }
            *c = 1.0 / *c;
            for r in 0..2 * n {
                a[(r, j)] *= *c;
            }
        }
        let x = a.qr().solve_lstsq(&b);
        let sol: Vec<f64> = (0..nn).map(|j| x[(j, 0)] * colscale[j]).collect();
        if sol.iter().any(|v| !v.is_finite()) {
            return Err(RivError::Numerical {
                what: "numerator least squares".into(),
                why: format!(
                    "non-finite solution for entry G{}_{} (dependent basis functions: two modes \
                     at the same frequency?)",
                    e % data.ny + 1,
                    e / data.ny + 1
                ),
            });
        }
        Ok(sol)
    };
    let sols: Vec<Vec<f64>> = (0..m)
        .into_par_iter()
        .map(solve_entry)
        .collect::<Result<_, _>>()?;
    let (shared, mut eta) = pack(model, &lay);
    for (e, s) in sols.iter().enumerate() {
        eta[e * nn..(e + 1) * nn].copy_from_slice(s);
    }
    unpack(model, &lay, &shared, &eta);
    Ok(crate::problem::cost(data, &lay, &basis, &eta, None))
}
