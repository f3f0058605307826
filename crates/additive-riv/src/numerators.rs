//! The convex numerator problem (24)-(25) of the wafer-stage paper: with the
//! denominators fixed, each entry of `vec(G)` is a linear least-squares problem in its own
//! numerator coefficients, solved entry by entry.

use crate::problem::{groups, pack, unpack, Basis, EntryLines, FitData, Layout};
use crate::small::spd_solve;
use crate::{AdditiveModel, RivError};
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::{Solve, SolveLstsq};
use faer::{Accum, Mat, MatRef, Par, Side};
use rayon::prelude::*;

/// Fits every numerator of `model` to `data` with the denominators held fixed
/// (eq. 24 with the regressor (25), weighted by `data.w`, the known factor included in
/// the regressor). Returns the weighted cost `sum w |E|^2` after the fit.
pub fn fit_numerators(model: &mut AdditiveModel, data: &FitData) -> Result<f64, RivError> {
    let lay = Layout::of(model);
    let nn = lay.n_num;
    let n = data.n;
    let m = data.m();
    check_sizes(nn, n)?;
    let basis = Basis::new(model, &lay, &data.omega);
    // Normal equations per entry, formed by one GEMM on the transposed (line-contiguous)
    // regressor and solved by an equilibrated Cholesky: the structure is exploited on
    // purpose (the basis is shared by all entries). When the equilibrated system is
    // ill-conditioned (> 1e10) the entry falls back to a QR of the regressor itself.
    let ng = groups(model, &lay);
    let solve_entry = |e: usize| solve_entry(e, data, &basis, &ng, nn);
    // Entries whose line scales `s = sqrt(w) |F|` are proportional share the regressor
    // up to a scalar, which leaves their solutions unchanged: one Gram matrix and one
    // Cholesky factor per group, all right-hand sides by one GEMM (a large MIMO FRF with
    // one noise level is a single group). Groups of one entry, and a group whose
    // equilibrated Gram matrix is ill-conditioned, are solved entry by entry as above.
    let mut s2 = vec![0.0; n * m];
    for e in 0..m {
        for k in 0..n {
            s2[k * m + e] = (data.sqrt_w[e * n + k] * basis.f_abs[basis.f_offset(e) + k]).powi(2);
        }
    }
    let mut sols: Vec<Option<Vec<f64>>> = vec![None; m];
    for grp in frf_data::proportional_groups(&s2, m, 1e-12) {
        if grp.entries.len() < 2 {
            continue;
        }
        if let Some(x) = solve_group(data, &basis, nn, &grp) {
            for (c, &e) in grp.entries.iter().enumerate() {
                sols[e] = Some(x[c * nn..(c + 1) * nn].to_vec());
            }
        }
    }
    drop(s2);
    // the other entries: their Gram matrices from the shared products (crate::gram),
    // their right-hand sides `U^T S_e^2 y_e` by one product for all of them
    let rest: Vec<usize> = (0..m).filter(|&e| sols[e].is_none()).collect();
    let fast = solve_entries_shared(data, &basis, &ng, nn, &rest);
    for (&e, x) in rest.iter().zip(fast) {
        sols[e] = x;
    }
    let sols: Vec<Vec<f64>> = sols
        .into_par_iter()
        .enumerate()
        .map(|(e, s)| match s {
            Some(s) => Ok(s),
            None => solve_entry(e),
        })
        .collect::<Result<_, _>>()?;
    let (shared, mut eta) = pack(model, &lay);
    for (e, s) in sols.iter().enumerate() {
        eta[e * nn..(e + 1) * nn].copy_from_slice(s);
    }
    unpack(model, &lay, &shared, &eta);
    Ok(crate::problem::cost(data, &lay, &basis, &eta, None, &ng))
}

/// The numerator problem of one entry has `nn` unknowns and `2 n` real equations (`n`
/// lines): an error when there is nothing to fit or fewer equations than unknowns.
fn check_sizes(nn: usize, n: usize) -> Result<(), RivError> {
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
    Ok(())
}

/// The numerators of the entries `entries` (eq. 24 for each entry alone) by their
/// normal equations, with the Gram matrices of all of them from the products of the
/// basis shared by all entries ([`crate::gram::numerator_grams`]) and the right-hand
/// sides `U^T S_e^2 y_e` of all of them by one product; each system is solved by an
/// equilibrated Cholesky. `None` for an entry whose system is ill-conditioned (> 1e10)
/// or not positive definite: [`solve_entry`] then solves it by a QR of its regressor.
fn solve_entries_shared(
    data: &FitData,
    basis: &Basis,
    ng: &[(usize, usize)],
    nn: usize,
    entries: &[usize],
) -> Vec<Option<Vec<f64>>> {
    let n = data.n;
    let ne = entries.len();
    if ne == 0 {
        return Vec::new();
    }
    // the squared scales `s^2` and the divided data scaled twice, `s^2 y` (real parts
    // in `t_re`, imaginary in `t_im`), entry after entry
    let zero = vec![0.0; nn];
    let mut s2 = vec![0.0; ne * n];
    let mut t_re = vec![0.0; ne * n];
    let mut t_im = vec![0.0; ne * n];
    s2.par_chunks_mut(n)
        .zip(t_re.par_chunks_mut(n))
        .zip(t_im.par_chunks_mut(n))
        .zip(entries.par_iter())
        .for_each_init(EntryLines::default, |el, (((a, tr), ti), &e)| {
            el.fill(e, data, basis, ng, &zero);
            for k in 0..n {
                let v = el.s[k] * el.s[k];
                a[k] = v;
                tr[k] = v * el.y_re[k];
                ti[k] = v * el.y_im[k];
            }
        });
    let grams = crate::gram::numerator_grams(basis, nn, &s2, ne, true);
    let u_re = MatRef::from_column_major_slice(&basis.u_re[..nn * n], n, nn);
    let u_im = MatRef::from_column_major_slice(&basis.u_im[..nn * n], n, nn);
    let mut rhs = Mat::<f64>::zeros(nn, ne);
    matmul(
        rhs.as_mut(),
        Accum::Replace,
        u_re.transpose(),
        MatRef::from_column_major_slice(&t_re, n, ne),
        1.0,
        Par::Seq,
    );
    matmul(
        rhs.as_mut(),
        Accum::Add,
        u_im.transpose(),
        MatRef::from_column_major_slice(&t_im, n, ne),
        1.0,
        Par::Seq,
    );
    (0..ne)
        .into_par_iter()
        .map(|c| {
            let mut h = grams[c * nn * nn..(c + 1) * nn * nn].to_vec();
            let mut x = rhs.col_as_slice(c).to_vec();
            let cond = spd_solve(&mut h, nn, &mut x, 1)?;
            (cond < 1e10 && x.iter().all(|v| v.is_finite())).then_some(x)
        })
        .collect()
}

/// The numerators of entry `e` (eq. 24 for that entry alone: the regressor (25) of
/// `basis`, weighted by `data.w`, the entry's factor included): the normal equations,
/// formed by one GEMM on the transposed (line-contiguous) regressor and solved by an
/// equilibrated Cholesky; when that system is ill-conditioned (> 1e10), a QR of the
/// column-equilibrated regressor itself.
fn solve_entry(
    e: usize,
    data: &FitData,
    basis: &Basis,
    ng: &[(usize, usize)],
    nn: usize,
) -> Result<Vec<f64>, RivError> {
    let n = data.n;
    let zero = vec![0.0; nn];
    // columns u * s and the target y * s (the divided problem, see EntryLines)
    let mut el = EntryLines::default();
    el.fill(e, data, basis, ng, &zero[..]);
    let mut ut = basis.scaled_columns(&el.s, nn, 1);
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
}

/// The weighted cost `sum w |E|^2` of the entries `entries` (column-major indices of
/// `vec(G)`) alone after fitting their numerators (eq. 24), the denominators and
/// factors of `model` held fixed; the model is not changed. The numerators of distinct
/// entries are separate least-squares problems, so this is those entries' share of the
/// cost that [`fit_numerators`] returns, at the cost of those entries only: a
/// candidate that changes a few entries (a dynamics factor on one input or output) is
/// screened on them.
pub fn numerator_cost_of_entries(
    model: &AdditiveModel,
    data: &FitData,
    entries: &[usize],
) -> Result<f64, RivError> {
    let lay = Layout::of(model);
    let nn = lay.n_num;
    let m = data.m();
    check_sizes(nn, data.n)?;
    if let Some(&e) = entries.iter().find(|&&e| e >= m) {
        return Err(RivError::invalid(
            "entries",
            e.to_string(),
            format!("the data have {m} entries"),
        ));
    }
    let basis = Basis::new(model, &lay, &data.omega);
    let ng = groups(model, &lay);
    entries
        .par_iter()
        .map(|&e| {
            let x = solve_entry(e, data, &basis, &ng, nn)?;
            let mut el = EntryLines::default();
            el.fill(e, data, &basis, &ng, &x);
            Ok(el.cost())
        })
        .sum()
}

/// Entries per block of right-hand sides in [`solve_group`].
const GROUP_BLOCK: usize = 128;

/// The numerators of the entries of `grp` (proportional line scales, see
/// [`fit_numerators`]) by the normal equations of their shared regressor, column-major
/// `nn x entries`: the Gram matrix equilibrated to unit diagonal and factored once (the
/// per-entry path's `spd_solve`), the right-hand sides in blocks of entries, in
/// parallel. `None` when the equilibrated Gram matrix is not positive definite or its
/// condition exceeds 1e10 (the entries are then solved one by one).
fn solve_group(
    data: &FitData,
    basis: &Basis,
    nn: usize,
    grp: &frf_data::WeightGroup,
) -> Option<Vec<f64>> {
    let n = data.n;
    let ne = grp.entries.len();
    let s0: Vec<f64> = grp.line_weights.iter().map(|w| w.sqrt()).collect();
    let ut = basis.scaled_columns(&s0, nn, 0);
    let mut z = Mat::<f64>::zeros(nn, nn);
    matmul(
        z.as_mut(),
        Accum::Replace,
        ut.transpose(),
        ut.as_ref(),
        1.0,
        Par::Seq,
    );
    let mut d = vec![0.0; nn];
    for (i, di) in d.iter_mut().enumerate() {
        let zii = z[(i, i)];
        if !(zii > 0.0 && zii.is_finite()) {
            return None;
        }
        *di = 1.0 / zii.sqrt();
    }
    let zeq = Mat::from_fn(nn, nn, |i, j| z[(i, j)] * d[i] * d[j]);
    let llt = zeq.llt(Side::Lower).ok()?;
    let l = llt.L();
    let (mut lmax, mut lmin) = (0.0f64, f64::INFINITY);
    for i in 0..nn {
        lmax = lmax.max(l[(i, i)]);
        lmin = lmin.min(l[(i, i)]);
    }
    let cond = (lmax / lmin).powi(2);
    if cond.is_nan() || cond >= 1e10 {
        return None;
    }
    let blocks: Vec<Vec<f64>> = grp
        .entries
        .par_chunks(GROUP_BLOCK)
        .map(|entries| {
            // the divided data `G / F` of the block's entries, scaled like the regressor
            let mut y = Mat::<f64>::zeros(2 * n, entries.len());
            for (c, &e) in entries.iter().enumerate() {
                let col = y.col_as_slice_mut(c);
                let (yr, yi) = col.split_at_mut(n);
                for k in 0..n {
                    let (gr, gi, fi) = (
                        data.g_re[e * n + k],
                        data.g_im[e * n + k],
                        basis.f_inv[basis.f_offset(e) + k],
                    );
                    yr[k] = (gr * fi.re - gi * fi.im) * s0[k];
                    yi[k] = (gr * fi.im + gi * fi.re) * s0[k];
                }
            }
            let mut r = Mat::<f64>::zeros(nn, entries.len());
            matmul(
                r.as_mut(),
                Accum::Replace,
                ut.transpose(),
                y.as_ref(),
                1.0,
                Par::Seq,
            );
            for c in 0..entries.len() {
                for i in 0..nn {
                    r[(i, c)] *= d[i];
                }
            }
            let x = llt.solve(&r);
            let mut out = vec![0.0; nn * entries.len()];
            for c in 0..entries.len() {
                for i in 0..nn {
                    out[c * nn + i] = x[(i, c)] * d[i];
                }
            }
            out
        })
        .collect();
    let x: Vec<f64> = blocks.into_iter().flatten().collect();
    debug_assert_eq!(x.len(), nn * ne);
    x.iter().all(|v| v.is_finite()).then_some(x)
}
