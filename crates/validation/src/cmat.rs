//! Small dense complex matrices for the per-line computations of [`crate::mu`] and
//! [`crate::invalidation`]: column-major storage, products, the Hermitian eigenvalue
//! decomposition by cyclic Jacobi rotations (accurate to working precision for the
//! matrices of a few to a few tens of rows met here, with no allocation per rotation),
//! and the null space by the eigenvalue decomposition of `N^H N`.

use faer::Mat;
use frf_data::C64;

/// A dense complex matrix, column-major: entry `(i, j)` is `v[j * rows + i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct CMat {
    /// Number of rows.
    pub rows: usize,
    /// Number of columns.
    pub cols: usize,
    /// The entries, column after column.
    pub v: Vec<C64>,
}

const ZERO: C64 = C64::new(0.0, 0.0);

impl CMat {
    /// A matrix of zeros.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            v: vec![ZERO; rows * cols],
        }
    }

    /// The identity.
    pub fn identity(n: usize) -> Self {
        let mut m = Self::zeros(n, n);
        for i in 0..n {
            m.v[i * n + i] = C64::new(1.0, 0.0);
        }
        m
    }

    /// From a function of `(i, j)`.
    pub fn from_fn(rows: usize, cols: usize, mut f: impl FnMut(usize, usize) -> C64) -> Self {
        let mut m = Self::zeros(rows, cols);
        for j in 0..cols {
            for i in 0..rows {
                m.v[j * rows + i] = f(i, j);
            }
        }
        m
    }

    /// From a faer matrix.
    pub fn from_faer(m: &Mat<C64>) -> Self {
        Self::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
    }

    /// To a faer matrix.
    pub fn to_faer(&self) -> Mat<C64> {
        Mat::from_fn(self.rows, self.cols, |i, j| self[(i, j)])
    }

    /// Conjugate transpose.
    pub fn adjoint(&self) -> Self {
        Self::from_fn(self.cols, self.rows, |i, j| self[(j, i)].conj())
    }

    /// `self * b`.
    pub fn mul(&self, b: &CMat) -> CMat {
        debug_assert_eq!(self.cols, b.rows);
        let mut c = CMat::zeros(self.rows, b.cols);
        for j in 0..b.cols {
            let cj = &mut c.v[j * self.rows..(j + 1) * self.rows];
            for l in 0..self.cols {
                let blj = b.v[j * b.rows + l];
                if blj == ZERO {
                    continue;
                }
                let al = &self.v[l * self.rows..(l + 1) * self.rows];
                for (ci, ai) in cj.iter_mut().zip(al) {
                    *ci += ai * blj;
                }
            }
        }
        c
    }

    /// `self * x` for a vector `x`.
    pub fn mul_vec(&self, x: &[C64]) -> Vec<C64> {
        let mut y = vec![ZERO; self.rows];
        for (l, xl) in x.iter().enumerate() {
            let al = &self.v[l * self.rows..(l + 1) * self.rows];
            for (yi, ai) in y.iter_mut().zip(al) {
                *yi += ai * xl;
            }
        }
        y
    }

    /// `self^H * x` for a vector `x`.
    pub fn adjoint_mul_vec(&self, x: &[C64]) -> Vec<C64> {
        (0..self.cols)
            .map(|j| {
                self.v[j * self.rows..(j + 1) * self.rows]
                    .iter()
                    .zip(x)
                    .map(|(a, b)| a.conj() * b)
                    .sum()
            })
            .collect()
    }

    /// Rows `r0..r1` as a new matrix.
    pub fn row_block(&self, r0: usize, r1: usize) -> CMat {
        CMat::from_fn(r1 - r0, self.cols, |i, j| self[(r0 + i, j)])
    }

    /// `self^H self` (Hermitian, `cols x cols`).
    pub fn gram(&self) -> CMat {
        let n = self.cols;
        let mut g = CMat::zeros(n, n);
        for j in 0..n {
            let cj = &self.v[j * self.rows..(j + 1) * self.rows];
            for i in 0..=j {
                let ci = &self.v[i * self.rows..(i + 1) * self.rows];
                let s: C64 = ci.iter().zip(cj).map(|(a, b)| a.conj() * b).sum();
                g.v[j * n + i] = s;
                g.v[i * n + j] = s.conj();
            }
        }
        g
    }

    /// Frobenius norm.
    pub fn norm_fro(&self) -> f64 {
        self.v.iter().map(|z| z.norm_sqr()).sum::<f64>().sqrt()
    }

    /// True when every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.v.iter().all(|z| z.re.is_finite() && z.im.is_finite())
    }

    /// Largest singular value (from the eigenvalues of the smaller Gram matrix).
    pub fn sigma_max(&self) -> f64 {
        if self.rows == 0 || self.cols == 0 {
            return 0.0;
        }
        let g = if self.cols <= self.rows {
            self.gram()
        } else {
            self.adjoint().gram()
        };
        let (w, _) = hermitian_eigen(&g);
        w.last().copied().unwrap_or(0.0).max(0.0).sqrt()
    }
}

impl std::ops::Index<(usize, usize)> for CMat {
    type Output = C64;
    #[inline]
    fn index(&self, (i, j): (usize, usize)) -> &C64 {
        &self.v[j * self.rows + i]
    }
}

impl std::ops::IndexMut<(usize, usize)> for CMat {
    #[inline]
    fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut C64 {
        &mut self.v[j * self.rows + i]
    }
}

/// Euclidean norm of a complex vector.
pub fn vnorm(x: &[C64]) -> f64 {
    x.iter().map(|z| z.norm_sqr()).sum::<f64>().sqrt()
}

/// Eigenvalues (ascending) and orthonormal eigenvectors (columns, same order) of a
/// Hermitian matrix, by cyclic Jacobi rotations until the off-diagonal part is below
/// `1e-15` of the Frobenius norm (at most 50 sweeps). Only the upper triangle is read
/// in spirit; the input is assumed Hermitian.
pub fn hermitian_eigen(a: &CMat) -> (Vec<f64>, CMat) {
    let n = a.rows;
    let mut m = a.clone();
    // symmetrise: exact Hermitian storage keeps the rotations consistent
    for j in 0..n {
        m[(j, j)] = C64::new(m[(j, j)].re, 0.0);
        for i in 0..j {
            let s = (m[(i, j)] + m[(j, i)].conj()) * 0.5;
            m[(i, j)] = s;
            m[(j, i)] = s.conj();
        }
    }
    let mut v = CMat::identity(n);
    let total = m.norm_fro();
    if n > 1 && total > 0.0 {
        let tol = 1e-15 * total;
        for _sweep in 0..50 {
            let mut off = 0.0;
            for j in 0..n {
                for i in 0..j {
                    off += m[(i, j)].norm_sqr();
                }
            }
            if off.sqrt() <= tol {
                break;
            }
            for p in 0..n {
                for q in p + 1..n {
                    let apq = m[(p, q)];
                    let r = apq.norm();
                    if r <= 1e-300 || r <= 1e-18 * total {
                        continue;
                    }
                    // unit phase e^{j phi} with a_pq = r e^{j phi}
                    let ph = apq / r;
                    let app = m[(p, p)].re;
                    let aqq = m[(q, q)].re;
                    // real symmetric 2x2 [[app, r], [r, aqq]] rotation
                    let theta = (aqq - app) / (2.0 * r);
                    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                    let t = if theta == 0.0 { 1.0 } else { t };
                    let c = 1.0 / (t * t + 1.0).sqrt();
                    let s = t * c;
                    // J = [[c, s ph], [-s conj(ph), c]] applied as A <- J^H A J on (p, q)
                    let sp = ph * s; // s e^{j phi}
                    for k in 0..n {
                        let akp = m[(k, p)];
                        let akq = m[(k, q)];
                        m[(k, p)] = akp * c - akq * sp.conj();
                        m[(k, q)] = akp * sp + akq * c;
                    }
                    for k in 0..n {
                        let apk = m[(p, k)];
                        let aqk = m[(q, k)];
                        m[(p, k)] = apk * c - aqk * sp;
                        m[(q, k)] = apk * sp.conj() + aqk * c;
                    }
                    m[(p, q)] = ZERO;
                    m[(q, p)] = ZERO;
                    for k in 0..n {
                        let vkp = v[(k, p)];
                        let vkq = v[(k, q)];
                        v[(k, p)] = vkp * c - vkq * sp.conj();
                        v[(k, q)] = vkp * sp + vkq * c;
                    }
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| m[(x, x)].re.total_cmp(&m[(y, y)].re));
    let w: Vec<f64> = order.iter().map(|&i| m[(i, i)].re).collect();
    let vs = CMat::from_fn(n, n, |i, j| v[(i, order[j])]);
    (w, vs)
}

/// An orthonormal basis (columns) of the null space of `n` (`cols x k`), from the
/// eigenvectors of `N^H N` whose eigenvalues are at most `max(tol^2, 1e-14 lambda_max)`
/// (singular values at most `tol`, or below `1e-7 sigma_max(N)`, which the Gram matrix
/// cannot resolve). A matrix with no rows has the whole space as its null
/// space.
pub fn null_space(n: &CMat, tol: f64) -> CMat {
    let c = n.cols;
    if n.rows == 0 {
        return CMat::identity(c);
    }
    let g = n.gram();
    let (w, v) = hermitian_eigen(&g);
    // the eigenvalues of the Gram matrix are accurate to ~1e-16 of the largest, i.e. the
    // singular values to ~1e-8 of the largest: nothing below that is resolved
    let top = w.last().copied().unwrap_or(0.0).max(0.0);
    let cut = (tol * tol).max(1e-14 * top);
    let keep: Vec<usize> = (0..c).filter(|&i| w[i] <= cut).collect();
    CMat::from_fn(c, keep.len(), |i, j| v[(i, keep[j])])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(rng: &mut ChaCha8Rng, r: usize, c: usize) -> CMat {
        CMat::from_fn(r, c, |_, _| {
            C64::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5)
        })
    }

    #[test]
    fn jacobi_reconstructs_hermitian_matrices() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for n in 1..9 {
            let b = random(&mut rng, n + 2, n);
            let a = b.gram();
            let (w, v) = hermitian_eigen(&a);
            // V diag(w) V^H == A and V^H V == I
            let vd = CMat::from_fn(n, n, |i, j| v[(i, j)] * w[j]);
            let back = vd.mul(&v.adjoint());
            let err: f64 = back
                .v
                .iter()
                .zip(&a.v)
                .map(|(x, y)| (x - y).norm())
                .fold(0.0, f64::max);
            assert!(err < 1e-12 * a.norm_fro(), "n={n} err={err}");
            let vv = v.adjoint().mul(&v);
            for i in 0..n {
                for j in 0..n {
                    let e = if i == j { 1.0 } else { 0.0 };
                    assert!((vv[(i, j)] - C64::new(e, 0.0)).norm() < 1e-12);
                }
            }
            assert!(w.windows(2).all(|p| p[0] <= p[1]));
        }
    }

    #[test]
    fn null_space_is_annihilated_and_has_the_right_dimension() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = random(&mut rng, 2, 5);
        let q = null_space(&n, 1e-10 * n.sigma_max());
        assert_eq!(q.cols, 3);
        let nq = n.mul(&q);
        assert!(nq.norm_fro() < 1e-12);
        let qq = q.gram();
        for i in 0..3 {
            assert!((qq[(i, i)].re - 1.0).abs() < 1e-12);
        }
    }
}
