//! The `R` factor and the least-squares solution of a tall matrix from its Gram
//! matrix, where that is accurate: the per-entry factorisations of the evaluation
//! ([`crate::varpro::Problem::evaluate`]) and of the Jacobian step
//! ([`crate::varpro::Problem::jacobian_r`]).
//!
//! `A^T A` is one matrix product (faer's `gemm` kernels: on a tall matrix with few
//! columns, no more floating-point work than a Householder QR at a several times
//! higher rate, and no reflectors to keep), and its Cholesky factor is `R^T` up to
//! signs. Squaring loses accuracy
//! where `A`'s columns are nearly dependent, so the factorisation is done on the
//! column-scaled Gram matrix (unit diagonal) and refused (`None`, the caller runs the
//! QR) when a scaled pivot — the part of a column orthogonal to the ones before it,
//! relative to its norm — falls below `min_pivot`: with a pivot bound `t`, the entries
//! of the computed Schur complement (the information matrix of the nonlinear
//! parameters after the elimination of the linear ones) carry a relative error of
//! about `k eps / t^2` (`k` columns).
//!
//! The last column is the data: its pivot (the residual norm relative to the data
//! norm) is not guarded, since the residual is computed exactly by the evaluation; its
//! entries above the diagonal (the residual's projection on the Jacobian, the
//! Gauss-Newton right-hand side) carry an absolute error of about `k eps ||y||`, so the
//! caller uses this path only while the residual is well above that.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// The Gram matrix `A^T A` of the row-major `rows x cols` matrix `a`.
fn gram(a: &[f64], rows: usize, cols: usize) -> Mat<f64> {
    debug_assert_eq!(a.len(), rows * cols);
    let am = MatRef::from_row_major_slice(a, rows, cols);
    let mut g = Mat::<f64>::zeros(cols, cols);
    matmul(
        g.as_mut(),
        Accum::Replace,
        am.transpose(),
        am,
        1.0,
        Par::Seq,
    );
    g
}

/// The lower Cholesky factor (column-major, `k x k`) of the leading `k x k` block of
/// `D^-1 G D^-1` (`d`: the square roots of `G`'s diagonal), or `None` when a scaled
/// pivot of the first `guard` columns is below `min_pivot` (or a column of `A` is zero
/// and `zero_ok` is false). A zero column (allowed) leaves a zero row and column.
fn scaled_cholesky(
    g: &Mat<f64>,
    d: &[f64],
    k: usize,
    guard: usize,
    min_pivot: f64,
    zero_ok: bool,
) -> Option<Vec<f64>> {
    let mut l = vec![0.0; k * k];
    let min2 = min_pivot * min_pivot;
    for j in 0..k {
        if d[j] == 0.0 {
            if zero_ok {
                continue;
            }
            return None;
        }
        let mut p: f64 = 1.0;
        for c in 0..j {
            p -= l[c * k + j] * l[c * k + j];
        }
        if j < guard && (p.is_nan() || p < min2) {
            return None;
        }
        let ljj = p.max(0.0).sqrt();
        l[j * k + j] = ljj;
        for i in j + 1..k {
            if d[i] == 0.0 {
                continue;
            }
            let mut s = g[(i, j)] / (d[i] * d[j]);
            for c in 0..j {
                s -= l[c * k + i] * l[c * k + j];
            }
            l[j * k + i] = if ljj > 0.0 { s / ljj } else { 0.0 };
        }
    }
    Some(l)
}

/// The upper-triangular `R` (`cols x cols`, column-major) with `R^T R = A^T A` for the
/// row-major `rows x cols` matrix `a`, from the Cholesky factor of the scaled Gram
/// matrix; `None` when a scaled pivot of the first `cols - 1` columns is below
/// `min_pivot` (a zero column is allowed: its row of `R` is zero).
pub(crate) fn gram_r(a: &[f64], rows: usize, cols: usize, min_pivot: f64) -> Option<Vec<f64>> {
    r_of_gram(&gram(a, rows, cols), min_pivot)
}

/// [`gram_r`] of the row-major `rows x cols` matrix `a` whose first `k` and last
/// columns `B = [A | y]` have the known Gram matrix `gb` (`(k + 1)^2`, column-major):
/// only the products with the middle columns `J` are formed (`J^T a`).
pub(crate) fn gram_r_with(
    a: &[f64],
    rows: usize,
    cols: usize,
    k: usize,
    gb: &[f64],
    min_pivot: f64,
) -> Option<Vec<f64>> {
    let nj = cols - k - 1;
    debug_assert_eq!(gb.len(), (k + 1) * (k + 1));
    let am = MatRef::from_row_major_slice(a, rows, cols);
    let jm = am.subcols(k, nj);
    let mut x = Mat::<f64>::zeros(nj, cols);
    matmul(
        x.as_mut(),
        Accum::Replace,
        jm.transpose(),
        am,
        1.0,
        Par::Seq,
    );
    // the index of column `i` of `a` in `B`, if it is there
    let in_b = |i: usize| {
        if i < k {
            Some(i)
        } else if i == cols - 1 {
            Some(k)
        } else {
            None
        }
    };
    let g = Mat::<f64>::from_fn(cols, cols, |i, j| match (in_b(i), in_b(j)) {
        (Some(p), Some(q)) => gb[q * (k + 1) + p],
        (None, _) => x[(i - k, j)],
        (_, None) => x[(j - k, i)],
    });
    r_of_gram(&g, min_pivot)
}

/// The `R` of [`gram_r`] from the Gram matrix `g`.
fn r_of_gram(g: &Mat<f64>, min_pivot: f64) -> Option<Vec<f64>> {
    let cols = g.nrows();
    let d: Vec<f64> = (0..cols).map(|j| g[(j, j)].max(0.0).sqrt()).collect();
    let l = scaled_cholesky(g, &d, cols, cols.saturating_sub(1), min_pivot, true)?;
    // R = L^T D: row i, column j (j >= i) is L[j, i] d[j]
    let mut r = vec![0.0; cols * cols];
    for j in 0..cols {
        for i in 0..=j {
            r[j * cols + i] = l[i * cols + j] * d[j];
        }
    }
    Some(r)
}

/// Solves `L L^T x = b` in place (`L`: lower, column-major `k x k`).
fn cholesky_solve(l: &[f64], k: usize, b: &mut [f64]) {
    for i in 0..k {
        let mut s = b[i];
        for c in 0..i {
            s -= l[c * k + i] * b[c];
        }
        b[i] = s / l[i * k + i];
    }
    for i in (0..k).rev() {
        let mut s = b[i];
        for c in i + 1..k {
            s -= l[i * k + c] * b[c];
        }
        b[i] = s / l[i * k + i];
    }
}

/// The least-squares solution `c` of `A c = y` for the row-major `rows x (k + 1)`
/// matrix `[A | y]`, and the squared residual norm `||y - A c||^2`, by the corrected
/// semi-normal equations: the Cholesky factor of the scaled `A^T A`, then one step of
/// iterative refinement on the residual computed explicitly (as accurate as a QR while
/// `cond(A D^-1)^2 eps` is small, which the pivot bound ensures). The residual norm is
/// that of the returned `c`, computed directly; the Gram matrix of `[A | y]` (column-major)
/// is returned too. `None` when a scaled pivot is below `min_pivot` or a column of `A`
/// is zero.
pub(crate) fn gram_lstsq(
    a: &[f64],
    rows: usize,
    k: usize,
    min_pivot: f64,
) -> Option<(Vec<f64>, f64, Vec<f64>)> {
    let cols = k + 1;
    let g = gram(a, rows, cols);
    let d: Vec<f64> = (0..k).map(|j| g[(j, j)].max(0.0).sqrt()).collect();
    let l = scaled_cholesky(&g, &d, k, k, min_pivot, false)?;
    let solve = |b: &mut Vec<f64>| {
        for (x, dj) in b.iter_mut().zip(&d) {
            *x /= dj;
        }
        cholesky_solve(&l, k, b);
        for (x, dj) in b.iter_mut().zip(&d) {
            *x /= dj;
        }
    };
    let mut c: Vec<f64> = (0..k).map(|j| g[(j, k)]).collect();
    solve(&mut c);
    // one step of refinement: c += (A^T A)^-1 A^T (y - A c)
    let mut atr = vec![0.0; k];
    for row in a.chunks_exact(cols) {
        let r = row[k] - row[..k].iter().zip(&c).map(|(x, y)| x * y).sum::<f64>();
        for (acc, x) in atr.iter_mut().zip(&row[..k]) {
            *acc += x * r;
        }
    }
    solve(&mut atr);
    for (x, dx) in c.iter_mut().zip(&atr) {
        *x += dx;
    }
    let rr: f64 = a
        .chunks_exact(cols)
        .map(|row| {
            let r = row[k] - row[..k].iter().zip(&c).map(|(x, y)| x * y).sum::<f64>();
            r * r
        })
        .sum();
    let gv: Vec<f64> = (0..cols * cols).map(|i| g[(i % cols, i / cols)]).collect();
    Some((c, rr, gv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::qr::householder_r;

    /// Column-major test matrix.
    fn matrix(rows: usize, cols: usize) -> Vec<f64> {
        let mut a: Vec<f64> = (0..rows * cols)
            .map(|k| ((k * 7919 % 1013) as f64 / 1013.0 - 0.5) + 0.1 * (k as f64 * 0.37).sin())
            .collect();
        // widely different column scales
        for x in &mut a[3 * rows..4 * rows] {
            *x *= 1e6;
        }
        a
    }

    fn row_major(a: &[f64], rows: usize, cols: usize) -> Vec<f64> {
        (0..rows * cols)
            .map(|k| a[(k % cols) * rows + k / cols])
            .collect()
    }

    #[test]
    fn corrected_semi_normal_equations_match_the_qr_solution() {
        let (rows, cols) = (300, 6);
        let a = matrix(rows, cols);
        let k = cols - 1;
        let (c, rr, gb) = gram_lstsq(&row_major(&a, rows, cols), rows, k, 1e-4).unwrap();
        // with a middle column added, the factor from the known Gram matrix of the
        // others equals the one from the whole
        let extra: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.05).cos()).collect();
        let mut b = a[..k * rows].to_vec();
        b.extend_from_slice(&extra);
        b.extend_from_slice(&a[k * rows..]);
        let bm = row_major(&b, rows, cols + 1);
        let (r1, r2) = (
            gram_r(&bm, rows, cols + 1, 1e-4).unwrap(),
            gram_r_with(&bm, rows, cols + 1, k, &gb, 1e-4).unwrap(),
        );
        for (u, v) in r1.iter().zip(&r2) {
            assert!((u - v).abs() <= 1e-12 * u.abs().max(1.0), "{u} vs {v}");
        }
        let mut q = a.clone();
        householder_r(&mut q, rows, cols);
        let mut x: Vec<f64> = (0..k).map(|i| q[k * rows + i]).collect();
        crate::qr::back_substitute(&q, rows, 0, k, &mut x);
        for (u, v) in c.iter().zip(&x) {
            assert!((u - v).abs() <= 1e-10 * v.abs().max(1e-12), "{u} vs {v}");
        }
        let rq = q[k * rows + k] * q[k * rows + k];
        assert!((rr - rq).abs() <= 1e-10 * rq, "{rr} vs {rq}");
    }

    #[test]
    fn gram_factor_matches_householder_up_to_row_signs() {
        let (rows, cols) = (300, 6);
        let a = matrix(rows, cols);
        let r = gram_r(&row_major(&a, rows, cols), rows, cols, 1e-4).expect("well conditioned");
        let mut q = a.clone();
        householder_r(&mut q, rows, cols);
        for i in 0..cols {
            let s = if q[i * rows + i] < 0.0 { -1.0 } else { 1.0 };
            for j in i..cols {
                let (x, y) = (r[j * cols + i], s * q[j * rows + i]);
                let scale = (0..=j).map(|k| q[j * rows + k].powi(2)).sum::<f64>().sqrt();
                assert!((x - y).abs() <= 1e-10 * scale, "({i},{j}): {x} vs {y}");
            }
        }
    }

    #[test]
    fn zero_columns_pass_and_dependent_columns_are_refused() {
        let (rows, cols) = (300, 6);
        let mut a = matrix(rows, cols);
        for x in &mut a[2 * rows..3 * rows] {
            *x = 0.0;
        }
        let r =
            gram_r(&row_major(&a, rows, cols), rows, cols, 1e-4).expect("a zero column is allowed");
        for p in 0..cols {
            for q in 0..cols {
                let g: f64 = (0..rows).map(|i| a[p * rows + i] * a[q * rows + i]).sum();
                let rr: f64 = (0..cols).map(|i| r[p * cols + i] * r[q * cols + i]).sum();
                let np: f64 = (0..rows).map(|i| a[p * rows + i].powi(2)).sum::<f64>();
                let nq: f64 = (0..rows).map(|i| a[q * rows + i].powi(2)).sum::<f64>();
                assert!(
                    (g - rr).abs() <= 1e-12 * (np * nq).sqrt(),
                    "({p},{q}): {g} vs {rr}"
                );
            }
        }
        // a column that is a combination of the others to 1e-6: refused at 1e-4
        for i in 0..rows {
            a[4 * rows + i] = a[i] - 2.0 * a[rows + i] + 1e-6 * a[5 * rows + i];
        }
        assert!(gram_r(&row_major(&a, rows, cols), rows, cols, 1e-4).is_none());
        assert!(gram_lstsq(&row_major(&a, rows, cols), rows, cols - 1, 1e-4).is_none());
    }
}
