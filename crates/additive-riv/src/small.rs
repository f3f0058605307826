//! Small dense solves used inside the per-entry elimination: an equilibrated Cholesky
//! for the symmetric positive definite numerator blocks and an equilibrated LU (faer)
//! for the shared Schur system.

use faer::linalg::solvers::Solve;
use faer::Mat;

/// Solves `A X = B` for symmetric positive definite `A` (`n x n`, column-major in `a`)
/// and `nrhs` right-hand sides (column-major `n x nrhs` in `b`, overwritten by `X`).
///
/// `A` is first equilibrated to unit diagonal (`D A D`, `D = diag(A)^{-1/2}`), which
/// removes the scale differences between numerator coefficients of submodels with
/// very different gains. Returns an estimate of the condition number of the
/// equilibrated matrix (`(max L_ii / min L_ii)^2`), or `None` when `A` is not positive
/// definite (dependent basis functions: two submodels with the same poles). `a` holds
/// the factor of [`spd_factor`] afterwards.
pub fn spd_solve(a: &mut [f64], n: usize, b: &mut [f64], nrhs: usize) -> Option<f64> {
    let (d, c) = spd_factor(a, n)?;
    spd_apply(a, &d, n, b, nrhs);
    Some(c)
}

/// The equilibrated Cholesky factor of [`spd_solve`]: overwrites the lower triangle of
/// `a` with `L` (`D A D = L L^T`) and returns `D`'s diagonal and the condition estimate,
/// or `None` when `A` is not positive definite. [`spd_apply`] solves with it.
pub fn spd_factor(a: &mut [f64], n: usize) -> Option<(Vec<f64>, f64)> {
    let mut d = vec![0.0; n];
    for i in 0..n {
        let aii = a[i * n + i];
        if aii.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !aii.is_finite() {
            return None;
        }
        d[i] = 1.0 / aii.sqrt();
    }
    for j in 0..n {
        for i in 0..n {
            a[j * n + i] *= d[i] * d[j];
        }
    }
    // Cholesky A = L L^T, L stored in the lower triangle (column-major).
    let (mut lmax, mut lmin) = (0.0f64, f64::INFINITY);
    for j in 0..n {
        let mut s = a[j * n + j];
        for k in 0..j {
            s -= a[k * n + j] * a[k * n + j];
        }
        if s.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let ljj = s.sqrt();
        a[j * n + j] = ljj;
        lmax = lmax.max(ljj);
        lmin = lmin.min(ljj);
        for i in j + 1..n {
            let mut s = a[j * n + i];
            for k in 0..j {
                s -= a[k * n + i] * a[k * n + j];
            }
            a[j * n + i] = s / ljj;
        }
    }
    Some((d, (lmax / lmin).powi(2)))
}

/// Solves `A X = B` (`nrhs` columns of `b`, overwritten) with the factor `l`, `d` of
/// [`spd_factor`].
pub fn spd_apply(l: &[f64], d: &[f64], n: usize, b: &mut [f64], nrhs: usize) {
    for c in 0..nrhs {
        let x = &mut b[c * n..(c + 1) * n];
        for i in 0..n {
            x[i] *= d[i];
        }
        // forward: L y = x
        for i in 0..n {
            let mut s = x[i];
            for k in 0..i {
                s -= l[k * n + i] * x[k];
            }
            x[i] = s / l[i * n + i];
        }
        // backward: L^T z = y
        for i in (0..n).rev() {
            let mut s = x[i];
            for k in i + 1..n {
                s -= l[i * n + k] * x[k];
            }
            x[i] = s / l[i * n + i];
        }
        for i in 0..n {
            x[i] *= d[i];
        }
    }
}

/// Solves the general square system `A x = b` with column equilibration and an LU with
/// partial pivoting. Returns `x` and a rough condition estimate (ratio of the largest to
/// the smallest absolute pivot of the equilibrated matrix), or `None` when singular.
pub fn lu_solve(a: &Mat<f64>, b: &[f64]) -> Option<(Vec<f64>, f64)> {
    let n = a.nrows();
    let mut scale = vec![1.0; n];
    for j in 0..n {
        let mut mx = 0.0f64;
        for i in 0..n {
            mx = mx.max(a[(i, j)].abs());
        }
        if mx == 0.0 || !mx.is_finite() {
            return None;
        }
        scale[j] = 1.0 / mx;
    }
    let mut rs = vec![1.0; n];
    for i in 0..n {
        let mut mx = 0.0f64;
        for j in 0..n {
            mx = mx.max((a[(i, j)] * scale[j]).abs());
        }
        if mx == 0.0 {
            return None;
        }
        rs[i] = 1.0 / mx;
    }
    let ae = Mat::from_fn(n, n, |i, j| a[(i, j)] * scale[j] * rs[i]);
    let lu = ae.partial_piv_lu();
    let u = lu.U();
    let (mut pmax, mut pmin) = (0.0f64, f64::INFINITY);
    for i in 0..n {
        let p = u[(i, i)].abs();
        pmax = pmax.max(p);
        pmin = pmin.min(p);
    }
    if pmin == 0.0 || !pmin.is_finite() {
        return None;
    }
    let rhs = Mat::from_fn(n, 1, |i, _| b[i] * rs[i]);
    let y = lu.solve(&rhs);
    let x: Vec<f64> = (0..n).map(|j| y[(j, 0)] * scale[j]).collect();
    if x.iter().any(|v| !v.is_finite()) {
        return None;
    }
    Some((x, pmax / pmin))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spd_solve_matches_known_solution() {
        // A = M^T M + I with very different column scales
        let n = 5;
        let m = Mat::from_fn(n, n, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 + if i == j { 2.0 } else { 0.0 }
        });
        let s = [1e-6, 1.0, 1e3, 1e6, 1.0];
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let mut v = 0.0;
                for k in 0..n {
                    v += m[(k, i)] * m[(k, j)];
                }
                a[j * n + i] = v * s[i] * s[j];
            }
        }
        let x_true: Vec<f64> = (0..n).map(|i| (i as f64 + 1.0) / s[i]).collect();
        let mut b = vec![0.0; n];
        for i in 0..n {
            for j in 0..n {
                b[i] += a[j * n + i] * x_true[j];
            }
        }
        let mut a2 = a.clone();
        let c = spd_solve(&mut a2, n, &mut b, 1).unwrap();
        assert!(c.is_finite());
        for i in 0..n {
            assert!(
                (b[i] - x_true[i]).abs() <= 1e-9 * x_true[i].abs(),
                "{i}: {} vs {}",
                b[i],
                x_true[i]
            );
        }
        // not positive definite
        let mut z = vec![1.0, 1.0, 1.0, 1.0];
        let mut r = vec![1.0, 1.0];
        assert!(spd_solve(&mut z, 2, &mut r, 1).is_none());
    }

    #[test]
    fn lu_solve_small() {
        let a = Mat::from_fn(3, 3, |i, j| {
            [[0.0, 2.0, 1.0], [1e-8, 1.0, 0.0], [3.0, 0.0, 1e4]][i][j]
        });
        let x_true = [1.0, -2.0, 3e-4];
        let b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a[(i, j)] * x_true[j]).sum())
            .collect();
        let (x, _) = lu_solve(&a, &b).unwrap();
        for i in 0..3 {
            assert!((x[i] - x_true[i]).abs() < 1e-12 * x_true[i].abs().max(1.0));
        }
        assert!(lu_solve(&Mat::zeros(2, 2), &[1.0, 1.0]).is_none());
    }
}
