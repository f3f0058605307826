//! A Householder QR of a tall column-major matrix, in place, sequential: the per-entry
//! factorisations of the variable-projection solver run on the rayon pool, one matrix
//! per task, so the factorisation itself stays single-threaded (faer's blocked QR with
//! `Par::Seq`).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor::{
    qr_in_place, qr_in_place_scratch, recommended_block_size,
};
use faer::{Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

/// The `R` factor (`cols x cols`, upper triangular, rows of either sign) of a tall
/// matrix by a two-level (tall-skinny) QR on the rayon pool: the QR of each of a few
/// blocks of rows in parallel, then the QR of their stacked `R` factors. The same
/// `R^T R` as one QR of the whole matrix (the Householder QR of a stack of orthogonal
/// transformations), at one block's cost per thread. One QR when the matrix is not
/// tall enough for two blocks of at least twice as many rows as columns.
pub(crate) fn tall_r(a: MatRef<'_, f64>) -> Mat<f64> {
    let (rows, cols) = (a.nrows(), a.ncols());
    let blocks = rayon::current_num_threads().min(rows / (2 * cols).max(1));
    if blocks < 2 {
        return a.qr().thin_R().to_owned();
    }
    let bounds: Vec<(usize, usize)> = (0..blocks)
        .map(|b| (b * rows / blocks, (b + 1) * rows / blocks))
        .collect();
    let parts: Vec<Mat<f64>> = bounds
        .par_iter()
        .map(|&(r0, r1)| a.subrows(r0, r1 - r0).qr().thin_R().to_owned())
        .collect();
    let mut stacked = Mat::<f64>::zeros(blocks * cols, cols);
    for (b, part) in parts.iter().enumerate() {
        stacked.subrows_mut(b * cols, cols).copy_from(part);
    }
    stacked.qr().thin_R().to_owned()
}

/// Householder QR of the column-major `rows x cols` matrix `a` in place: on return the
/// upper triangle of its first `min(rows, cols)` rows holds `R` (the reflectors are
/// discarded). Row `i` of `R` is `a[c * rows + i]` for `c >= i`.
pub(crate) fn householder_r(a: &mut [f64], rows: usize, cols: usize) {
    debug_assert_eq!(a.len(), rows * cols);
    let k = rows.min(cols);
    if k == 0 {
        return;
    }
    let bs = recommended_block_size::<f64>(rows, cols);
    let mut q = Mat::<f64>::zeros(bs, k);
    let mut buf = MemBuffer::new(qr_in_place_scratch::<f64>(
        rows,
        cols,
        bs,
        Par::Seq,
        Default::default(),
    ));
    qr_in_place(
        MatMut::from_column_major_slice_mut(a, rows, cols),
        q.as_mut(),
        Par::Seq,
        MemStack::new(&mut buf),
        Default::default(),
    );
    // the reflectors below the diagonal are not needed
    for j in 0..k {
        for x in a[j * rows + j + 1..(j + 1) * rows].iter_mut() {
            *x = 0.0;
        }
    }
}

/// The unblocked Householder QR [`householder_r`] replaced (kept for the test that
/// compares the two).
#[cfg(test)]
fn householder_r_unblocked(a: &mut [f64], rows: usize, cols: usize) {
    debug_assert_eq!(a.len(), rows * cols);
    for j in 0..rows.min(cols) {
        let (head, tail) = a.split_at_mut((j + 1) * rows);
        let v = &mut head[j * rows + j..(j + 1) * rows];
        let norm2: f64 = v.iter().map(|x| x * x).sum();
        if norm2 == 0.0 {
            continue;
        }
        let norm = norm2.sqrt();
        let x0 = v[0];
        let alpha = if x0 >= 0.0 { -norm } else { norm };
        let v0 = x0 - alpha;
        let vnorm2 = norm2 - x0 * x0 + v0 * v0;
        v[0] = v0;
        if vnorm2 > 0.0 {
            for k in 0..cols - j - 1 {
                let c = &mut tail[k * rows + j..(k + 1) * rows];
                let dot: f64 = v.iter().zip(c.iter()).map(|(a, b)| a * b).sum();
                let tau = 2.0 * dot / vnorm2;
                for (ci, vi) in c.iter_mut().zip(v.iter()) {
                    *ci -= tau * vi;
                }
            }
        }
        v[0] = alpha;
        for x in v[1..].iter_mut() {
            *x = 0.0;
        }
    }
}

/// Solves the upper-triangular `R x = b` (`R` is `n x n` inside the column-major
/// `rows x _` matrix `a`, starting at row and column `off`), in place in `b`.
pub(crate) fn back_substitute(a: &[f64], rows: usize, off: usize, n: usize, b: &mut [f64]) {
    for i in (0..n).rev() {
        let mut s = b[i];
        for c in i + 1..n {
            s -= a[(off + c) * rows + off + i] * b[c];
        }
        b[i] = s / a[(off + i) * rows + off + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tall_r_reproduces_the_gram_matrix_of_one_qr() {
        // tall enough for two blocks on a pool of two threads, and a matrix too short
        for rows in [400usize, 37] {
            let cols = 9;
            let a = Mat::<f64>::from_fn(rows, cols, |i, j| {
                ((i * 7 + j * 13) % 17) as f64 - 8.0 + 0.1 * (i as f64).sin() * j as f64
            });
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap();
            let r = pool.install(|| tall_r(a.as_ref()));
            assert_eq!((r.nrows(), r.ncols()), (cols, cols));
            let g = r.transpose() * &r;
            let g0 = a.transpose() * &a;
            let scale = g0.norm_l2();
            for i in 0..cols {
                for j in 0..cols {
                    assert!((g[(i, j)] - g0[(i, j)]).abs() <= 1e-12 * scale, "{i} {j}");
                    if i > j {
                        assert_eq!(r[(i, j)], 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn r_reproduces_the_gram_matrix() {
        let (rows, cols) = (7, 3);
        let a0: Vec<f64> = (0..rows * cols)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) * 0.3 + (k as f64).sin())
            .collect();
        let mut a = a0.clone();
        householder_r(&mut a, rows, cols);
        let mut b = a0.clone();
        householder_r_unblocked(&mut b, rows, cols);
        for j in 0..cols {
            for i in 0..=j.min(rows - 1) {
                let (x, y) = (a[j * rows + i].abs(), b[j * rows + i].abs());
                assert!(
                    (x - y).abs() < 1e-12 * x.max(1.0),
                    "|R| ({i},{j}): {x} vs {y}"
                );
            }
        }
        for p in 0..cols {
            for q in 0..cols {
                let g: f64 = (0..rows).map(|i| a0[p * rows + i] * a0[q * rows + i]).sum();
                let r: f64 = (0..cols).map(|i| a[p * rows + i] * a[q * rows + i]).sum();
                assert!(
                    (g - r).abs() < 1e-12 * g.abs().max(1.0),
                    "{p} {q}: {g} vs {r}"
                );
            }
        }
        // least squares through R: solve against the last column
        let mut b: Vec<f64> = (0..2).map(|i| a[2 * rows + i]).collect();
        back_substitute(&a, rows, 0, 2, &mut b);
        let resid: Vec<f64> = (0..rows)
            .map(|i| a0[2 * rows + i] - a0[i] * b[0] - a0[rows + i] * b[1])
            .collect();
        for c in 0..2 {
            let d: f64 = (0..rows).map(|i| resid[i] * a0[c * rows + i]).sum();
            assert!(d.abs() < 1e-10, "normal equations hold: {d}");
        }
    }
}
