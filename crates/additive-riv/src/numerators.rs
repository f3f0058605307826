//! The convex numerator problem (24)-(25) of the wafer-stage paper: with the
//! denominators fixed, each entry of `vec(G)` is a linear least-squares problem in its own
//! numerator coefficients, solved entry by entry.

use crate::problem::{groups, pack, unpack, Basis, EntryLines, FitData, Layout};
use crate::small::spd_solve;
use crate::{AdditiveModel, RivError};
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::SolveLstsq;
use faer::{Accum, Mat, Par};
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
    // Normal equations per entry, formed by one GEMM on the transposed (line-contiguous)
    // regressor and solved by an equilibrated Cholesky: the structure is exploited on
    // purpose (the basis is shared by all entries). When the equilibrated system is
    // ill-conditioned (> 1e10) the entry falls back to a QR of the regressor itself.
    let ng = groups(model, &lay);
    let zero = vec![0.0; nn];
    let solve_entry = |e: usize| -> Result<Vec<f64>, RivError> {
        // columns u * s and the target y * s (the divided problem, see EntryLines)
        let mut el = EntryLines::default();
        el.fill(e, data, &basis, &ng, &zero[..]);
        let mut ut = Mat::<f64>::zeros(2 * n, nn + 1);
        for j in 0..nn {
            let col = ut.col_as_slice_mut(j);
            let (cr, ci) = col.split_at_mut(n);
            for k in 0..n {
                cr[k] = basis.u_re[j * n + k] * el.s[k];
                ci[k] = basis.u_im[j * n + k] * el.s[k];
            }
        }
        {
            let col = ut.col_as_slice_mut(nn);
            let (cr, ci) = col.split_at_mut(n);
            for k in 0..n {
                cr[k] = el.y_re[k] * el.s[k];
                ci[k] = el.y_im[k] * el.s[k];
            }
        }
        let mut z = Mat::<f64>::zeros(nn + 1, nn + 1);
        matmul(
            z.as_mut(),
            Accum::Replace,
            ut.transpose(),
            ut.as_ref(),
            1.0,
            Par::Seq,
        );
        let mut h = vec![0.0; nn * nn];
        let mut rhs = vec![0.0; nn];
        for j in 0..nn {
            for i in 0..nn {
                h[j * nn + i] = z[(i, j)];
            }
            rhs[j] = z[(j, nn)];
        }
        if let Some(c) = spd_solve(&mut h, nn, &mut rhs, 1) {
            if c < 1e10 && rhs.iter().all(|v| v.is_finite()) {
                return Ok(rhs);
            }
        }
        // QR fallback on the column-equilibrated regressor.
        let mut colscale = vec![0.0f64; nn];
        let mut a = Mat::<f64>::zeros(2 * n, nn);
        for (j, cs) in colscale.iter_mut().enumerate() {
            let src = ut.col_as_slice(j);
            let mx = src.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
            if mx == 0.0 {
                return Err(RivError::Numerical {
                    what: "numerator least squares".into(),
                    why: format!("basis function {j} is zero on every weighted line"),
                });
            }
            *cs = 1.0 / mx;
            for (d, v) in a.col_as_slice_mut(j).iter_mut().zip(src) {
                *d = v * *cs;
            }
        }
        let b = Mat::from_fn(2 * n, 1, |r, _| ut[(r, nn)]);
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
    Ok(crate::problem::cost(data, &lay, &basis, &eta, None, &ng))
}
