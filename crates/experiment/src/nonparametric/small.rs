//! Small dense complex matrices (a few to a few tens of rows) solved once per frequency
//! line: Gauss-Jordan inversion with partial pivoting and the 1-norm reciprocal
//! condition number. Matrices are column-major slices.

use frf_data::C64;

/// The inverse of the `n x n` column-major matrix `a`, or `None` when a pivot is
/// exactly zero.
pub(crate) fn invert(a: &[C64], n: usize) -> Option<Vec<C64>> {
    // augmented [A | I] stored row-major for cache-friendly row operations
    let w = 2 * n;
    let mut m = vec![C64::new(0.0, 0.0); n * w];
    for i in 0..n {
        for j in 0..n {
            m[i * w + j] = a[j * n + i];
        }
        m[i * w + n + i] = C64::new(1.0, 0.0);
    }
    for k in 0..n {
        let mut p = k;
        let mut best = m[k * w + k].norm();
        for i in k + 1..n {
            let v = m[i * w + k].norm();
            if v > best {
                best = v;
                p = i;
            }
        }
        if best == 0.0 || !best.is_finite() {
            return None;
        }
        if p != k {
            for j in 0..w {
                m.swap(k * w + j, p * w + j);
            }
        }
        let inv_piv = m[k * w + k].inv();
        for j in 0..w {
            m[k * w + j] *= inv_piv;
        }
        for i in 0..n {
            if i == k {
                continue;
            }
            let f = m[i * w + k];
            if f == C64::new(0.0, 0.0) {
                continue;
            }
            for j in k..w {
                let v = m[k * w + j];
                m[i * w + j] -= f * v;
            }
        }
    }
    let mut inv = vec![C64::new(0.0, 0.0); n * n];
    for i in 0..n {
        for j in 0..n {
            inv[j * n + i] = m[i * w + n + j];
        }
    }
    Some(inv)
}

/// The 1-norm (largest column sum of moduli) of an `nr x nc` column-major matrix.
pub(crate) fn norm1(a: &[C64], nr: usize, nc: usize) -> f64 {
    (0..nc)
        .map(|j| {
            a[j * nr..(j + 1) * nr]
                .iter()
                .map(|z| z.norm())
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
}

/// `C = A B` for column-major `A` (`m x k`) and `B` (`k x n`).
pub(crate) fn matmul(a: &[C64], b: &[C64], m: usize, k: usize, n: usize) -> Vec<C64> {
    let mut c = vec![C64::new(0.0, 0.0); m * n];
    for j in 0..n {
        for l in 0..k {
            let blj = b[j * k + l];
            if blj == C64::new(0.0, 0.0) {
                continue;
            }
            let col = &a[l * m..(l + 1) * m];
            let out = &mut c[j * m..(j + 1) * m];
            for i in 0..m {
                out[i] += col[i] * blj;
            }
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_of_a_random_matrix() {
        let n = 7;
        let a: Vec<C64> = (0..n * n)
            .map(|i| C64::new(((i * 37 % 17) as f64) - 8.0, ((i * 11 % 13) as f64) - 6.0))
            .collect();
        let inv = invert(&a, n).unwrap();
        let p = matmul(&a, &inv, n, n, n);
        for i in 0..n {
            for j in 0..n {
                let e = if i == j { 1.0 } else { 0.0 };
                assert!((p[j * n + i] - e).norm() < 1e-12);
            }
        }
        let mut sing = a.clone();
        for i in 0..n {
            sing[n + i] = sing[i] * 2.0;
        }
        let r = invert(&sing, n)
            .map(|inv| 1.0 / (norm1(&sing, n, n) * norm1(&inv, n, n)))
            .unwrap_or(0.0);
        assert!(r < 1e-14, "rcond of a singular matrix {r}");
    }
}
