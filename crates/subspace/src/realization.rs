//! Steps 2 and 3 of the algorithm: `A` and `C` from the shift structure (12) of the
//! estimated `O_r`, then `B` and `D` by the weighted linear least squares (17) (which
//! estimates `(B, D)`; the copy prints `(C, D)`), and the exact map of a bilinear-domain
//! model back to continuous time.

use crate::prepare::Prepared;
use crate::SubspaceError;
use faer::linalg::solvers::{Solve, SolveLstsq};
use faer::Mat;
use realize::{StateSpace, TimeDomain};

/// Condition number `s_max / s_min` of `m` (infinite when rank deficient).
pub fn condition(m: &Mat<f64>) -> f64 {
    match m.singular_values() {
        Ok(s) if !s.is_empty() => {
            let (hi, lo) = (s[0], s[s.len() - 1]);
            if lo > 0.0 {
                hi / lo
            } else {
                f64::INFINITY
            }
        }
        _ => f64::INFINITY,
    }
}

/// `A` and `C` from `O_r` (`rp x n`) with `p` outputs: `O_[1:r-1] A = O_[2:r]` in least
/// squares (QR), `C` the first block row. Returns `(A, C, cond(O_[1:r-1]))`.
pub fn shift_a_c(o: &Mat<f64>, p: usize) -> Result<(Mat<f64>, Mat<f64>, f64), SubspaceError> {
    let (rows, n) = (o.nrows(), o.ncols());
    let up = Mat::from_fn(rows - p, n, |i, j| o[(i, j)]);
    let down = Mat::from_fn(rows - p, n, |i, j| o[(i + p, j)]);
    let cond = condition(&up);
    if !cond.is_finite() || cond > 1e14 {
        return Err(SubspaceError::numerical(
            "shift equations (12)",
            format!("O_r without its last block row is rank deficient (condition {cond:.2e}); ask for a lower order"),
        ));
    }
    let a = up.qr().solve_lstsq(&down);
    let c = Mat::from_fn(p, n, |i, j| o[(i, j)]);
    Ok((a, c, cond))
}

/// `B` and `D` by the weighted least squares (17) on the prepared data (weights of the
/// criterion on `h`), one small problem per input (`B` and `D` column `j` only see input
/// `j`). Returns `(B, D, worst condition, weighted cost sum w |h - model|^2 / (2 F))`.
pub fn fit_b_d(
    d: &Prepared,
    a: &Mat<f64>,
    c: &Mat<f64>,
) -> Result<(Mat<f64>, Mat<f64>, f64, f64), SubspaceError> {
    let (p, nu, nl, n) = (d.ny, d.nu, d.n_lines(), a.nrows());
    // Phi_k = C (xi_k I - A)^{-1} (p x n), Hessenberg evaluation (defective A is fine),
    // as the transpose (xi_k I - A^T)^{-1} C^T: p right-hand sides per line, not n. With
    // A^T = Q H Q^T, Phi_k = Z_k^T Q^T for Z_k = (xi_k I - H)^{-1} Q^T C^T: the least
    // squares is solved for B' = Q^T B with the regressor Z_k^T, and B = Q B' at the end
    // (no n x n product per line; Q is orthogonal, so the problem is the same).
    let ss = StateSpace::new(
        a.transpose().to_owned(),
        c.transpose().to_owned(),
        Mat::identity(n, n),
        Mat::zeros(n, p),
        TimeDomain::Discrete { ts: 1.0 },
    )?;
    let hf = ss.hessenberg()?;
    let q = hf.c_tilde();
    let z = hf.states_at(&d.xi)?;
    let phi = |k: usize, o: usize, l: usize| z.get(k, l, o);
    let mut b = Mat::<f64>::zeros(n, nu);
    let mut dd = Mat::<f64>::zeros(p, nu);
    let mut worst = 1.0f64;
    let mut cost = 0.0;
    let nc = n + p;
    // column scales (norms of the weighted regressor columns), then a running QR of the
    // augmented regressor [M | y] over blocks of lines: R holds the solution and the
    // residual norm, and nothing grows with the lines
    let blk = crate::projection::LINES_PER_BLOCK;
    let weight = |k: usize, e: usize| -> f64 {
        if d.uniform {
            1.0
        } else {
            let v = d.var_h(k, e);
            if v.is_finite() {
                1.0 / v
            } else {
                0.0
            }
        }
    };
    // input columns whose weights are proportional share the regressor (phi does not
    // depend on the column): one running QR with their data as right-hand sides
    let mut wcols = vec![0.0; nl * p * nu];
    for k in 0..nl {
        for o in 0..p {
            for j in 0..nu {
                wcols[(k * p + o) * nu + j] = weight(k, j * p + o);
            }
        }
    }
    for grp in frf_data::proportional_groups(&wcols, nu, 1e-12) {
        let lw = |k: usize, o: usize| grp.line_weights[k * p + o];
        let ng = grp.entries.len();
        let mut scale = vec![0.0; nc];
        for k in 0..nl {
            for o in 0..p {
                let w = lw(k, o);
                for l in 0..n {
                    scale[l] += w * phi(k, o, l).norm_sqr();
                }
                scale[n + o] += w;
            }
        }
        for s in scale.iter_mut() {
            *s = if *s > 0.0 { s.sqrt() } else { 1.0 };
        }
        // the triangle of the lines k_lo..k_hi, absorbed block after block
        let triangle = |k_lo: usize, k_hi: usize| -> Result<Mat<f64>, SubspaceError> {
            let mut r = Mat::<f64>::zeros(nc + ng, nc + ng);
            let mut block = Mat::<f64>::zeros(2 * blk * p, nc + ng);
            let mut k0 = k_lo;
            while k0 < k_hi {
                let k1 = (k0 + blk).min(k_hi);
                for k in k0..k1 {
                    for o in 0..p {
                        let sw = lw(k, o).sqrt();
                        let (re, im) = (2 * ((k - k0) * p + o), 2 * ((k - k0) * p + o) + 1);
                        for l in 0..n {
                            let f = phi(k, o, l) * (sw / scale[l]);
                            block[(re, l)] = f.re;
                            block[(im, l)] = f.im;
                        }
                        for q in 0..p {
                            let v = if q == o { sw / scale[n + o] } else { 0.0 };
                            block[(re, n + q)] = v;
                            block[(im, n + q)] = 0.0;
                        }
                        for (c, &j) in grp.entries.iter().enumerate() {
                            let h = d.h[k * p * nu + j * p + o] * sw;
                            block[(re, nc + c)] = h.re;
                            block[(im, nc + c)] = h.im;
                        }
                    }
                }
                r = crate::projection::absorb(&r, &block, 2 * p * (k1 - k0))?;
                k0 = k1;
            }
            Ok(r)
        };
        // the two halves of the band on the two threads, their triangles then combined
        // (the triangle of all lines, to rounding): seconds at hundreds of states
        let r = if nl >= 4 * blk {
            let mid = nl / 2;
            let (r1, r2) = rayon::join(|| triangle(0, mid), || triangle(mid, nl));
            crate::projection::absorb(&r1?, &r2?, nc + ng)?
        } else {
            triangle(0, nl)?
        };
        let rr = Mat::from_fn(nc, nc, |a, b| r[(a, b)]);
        worst = worst.max(condition(&rr));
        for (c, &j) in grp.entries.iter().enumerate() {
            // back substitution R x = R[:, nc + c]
            let mut x = vec![0.0; nc];
            for i in (0..nc).rev() {
                let mut acc = r[(i, nc + c)];
                for q in i + 1..nc {
                    acc -= r[(i, q)] * x[q];
                }
                x[i] = acc / r[(i, i)];
            }
            for l in 0..n {
                b[(l, j)] = x[l] / scale[l];
            }
            for o in 0..p {
                dd[(o, j)] = x[n + o] / scale[n + o];
            }
        }
        // the residuals of the group: the lower-right triangle (Frobenius norm), each
        // column back at its own weight scale
        for c in 0..ng {
            let col2: f64 = (nc..=nc + c).map(|i| r[(i, nc + c)].powi(2)).sum();
            cost += col2 * grp.scales[c];
        }
    }
    // B = Q B'
    let b = &q * &b;
    if (0..nu).any(|j| (0..n).any(|l| !b[(l, j)].is_finite())) {
        return Err(SubspaceError::numerical(
            "least squares (17) for B and D",
            "non-finite solution",
        ));
    }
    Ok((b, dd, worst, cost / (2.0 * nl.max(1) as f64)))
}

/// The continuous state space whose response at `s` equals that of the discrete
/// `(A, B, C, D)` at `xi = (2 + s T)/(2 - s T)` (the inverse of the bilinear map (39)),
/// exactly: with `a = 2/T` and `M = (I + A)^{-1}`,
/// `Ac = a M (A - I)`, `Bc = sqrt(2a) M B`, `Cc = sqrt(2a) C M`, `Dc = D - C M B`.
pub fn bilinear_to_continuous(
    a: &Mat<f64>,
    b: &Mat<f64>,
    c: &Mat<f64>,
    d: &Mat<f64>,
    t: f64,
) -> Result<StateSpace, SubspaceError> {
    let n = a.nrows();
    let alpha = 2.0 / t;
    let ipa = Mat::<f64>::identity(n, n) + a;
    let cond = condition(&ipa);
    if !cond.is_finite() || cond > 1e14 {
        return Err(SubspaceError::numerical(
            "inverse bilinear map",
            format!("I + A is singular (a pole at s = infinity, condition {cond:.2e})"),
        ));
    }
    let lu = ipa.partial_piv_lu();
    let amb = a - Mat::<f64>::identity(n, n);
    let ac = lu.solve(&amb) * faer::Scale(alpha);
    let mb = lu.solve(b);
    let g = (2.0 * alpha).sqrt();
    let bc = &mb * faer::Scale(g);
    // C M = (M^T C^T)^T
    let cm = ipa
        .transpose()
        .to_owned()
        .partial_piv_lu()
        .solve(&c.transpose().to_owned())
        .transpose()
        .to_owned();
    let cc = &cm * faer::Scale(g);
    let dc = d - c * &mb;
    Ok(StateSpace::new(ac, bc, cc, dc, TimeDomain::Continuous)?)
}
