//! Step 1 of the algorithm: the column space of the extended observability matrix
//! `O_r` from the data equation (8)/(10) of Pintelon & Schoukens (McKelvey, Akcay and
//! Ljung 1996, Algorithm 2), with the input term removed by an orthogonal projection.
//!
//! For FRF data the "input" of line `k` and input `j` is the unit vector `e_j`, so the
//! input rows of the stacked data matrix `[U; Y]` (10) are, after sorting the columns by
//! input, block diagonal with the same block `W = [W_r(1) .. W_r(F)]` (real and imaginary
//! parts side by side) for every input. The projection onto the orthogonal complement of
//! the row space of `U` therefore acts on each input's columns separately with one and
//! the same projector, and
//!
//! `Y Pi^T Y^T = sum_j Y_j Pi_W^T Y_j^T = sum_j R22_j^T R22_j`,
//!
//! where `R22_j` is the lower right block of the R factor of `[W^T, Y_j^T]` (the LQ
//! factorisation of Verhaegen 1994, transposed). Each R factor is accumulated over
//! blocks of lines (a running QR: `[R; next block]` is factored again), so the cost is
//! linear in the lines and the memory does not grow with them; the `R22_j` are stacked
//! and reduced the same way. The left singular vectors of the projected data are then
//! the right singular vectors of the final `rp x rp` triangle.
//!
//! Noise weighting (the noise-covariance weighted variant): every column (line `k`,
//! input `j`) of `[U; Y]` is scaled by `c_kj = 1 / sqrt(mean_o var_koj)`, which leaves
//! the noise-free equation (8) exact (it scales `X` and `U` alike), and the rows by
//! `L^{-1}`, `L = diag(sqrt(t_o))` with `t_o = sum_kj c_kj^2 var_koj` the noise variance
//! of the rows of output `o` (the diagonal of the row noise covariance
//! `sum_kj c_kj^2 Re(W_r(k) W_r(k)^H (x) diag_o var_koj)`, equal for every power since
//! `|xi_k| = 1`): the SVD is taken of `L^{-1} Y Pi`, and `O_r = L U_n`. With the data's
//! true variance the noise part of the weighted singular values is then about 1.

use crate::prepare::Prepared;
use crate::SubspaceError;
use faer::Mat;
use rayon::prelude::*;

/// Lines per block of the running QR.
pub const LINES_PER_BLOCK: usize = 192;

/// The inputs are projected in this many chunks in parallel.
const INPUT_CHUNKS: usize = 2;

/// The weighted, projected data: what the order choice and the realization need.
#[derive(Debug, Clone)]
pub struct Projected {
    /// Block rows `r`.
    pub r: usize,
    /// Outputs `p`.
    pub p: usize,
    /// Singular values of the (weighted) projected data, descending (`rp` of them).
    pub singular_values: Vec<f64>,
    /// Right singular vectors of the weighted triangle (`rp x rp`), columns in the order
    /// of the singular values.
    pub v: Mat<f64>,
    /// Cholesky factor `L` of the row noise covariance (`None`: unweighted).
    pub l: Option<Mat<f64>>,
}

impl Projected {
    /// `O_r` for order `n`: `L V_n` (weighted) or `V_n`.
    pub fn observability(&self, n: usize) -> Mat<f64> {
        let rp = self.r * self.p;
        let vn = Mat::from_fn(rp, n, |i, j| self.v[(i, j)]);
        match &self.l {
            Some(l) => l * &vn,
            None => vn,
        }
    }
}

/// Column weights `c_kj` (1 when unweighted).
fn column_weights(d: &Prepared) -> Vec<f64> {
    let (ny, nu, n) = (d.ny, d.nu, d.n_lines());
    let mut c = vec![1.0; n * nu];
    if d.uniform {
        return c;
    }
    for k in 0..n {
        for j in 0..nu {
            let (mut s, mut cnt) = (0.0, 0usize);
            for o in 0..ny {
                let v = d.var_h(k, j * ny + o);
                if v.is_finite() {
                    s += v;
                    cnt += 1;
                }
            }
            c[k * nu + j] = if cnt > 0 && s > 0.0 {
                1.0 / (s / cnt as f64).sqrt()
            } else {
                0.0
            };
        }
    }
    c
}

/// Upper triangle of the QR of `m` (its first `nc` rows), as an `nc x nc` matrix.
fn r_factor(m: &Mat<f64>, nc: usize) -> Result<Mat<f64>, SubspaceError> {
    let r = m.qr();
    let t = r.thin_R();
    let mut out = Mat::<f64>::zeros(nc, nc);
    for j in 0..nc {
        for i in 0..=j.min(t.nrows().saturating_sub(1)) {
            if i < t.nrows() {
                out[(i, j)] = t[(i, j)];
            }
        }
    }
    if (0..nc).any(|j| (0..=j).any(|i| !out[(i, j)].is_finite())) {
        return Err(SubspaceError::numerical(
            "QR of the data matrix",
            "non-finite values (check the data for NaN or overflow)",
        ));
    }
    Ok(out)
}

/// Running QR: factors `[r; block]` and returns the new triangle.
pub(crate) fn absorb(
    r: &Mat<f64>,
    block: &Mat<f64>,
    rows: usize,
) -> Result<Mat<f64>, SubspaceError> {
    let nc = r.ncols();
    let m = Mat::from_fn(nc + rows, nc, |i, j| {
        if i < nc {
            r[(i, j)]
        } else {
            block[(i - nc, j)]
        }
    });
    r_factor(&m, nc)
}

/// Projects the data (see the module documentation) with `r` block rows and returns
/// the singular values and vectors.
pub fn project(d: &Prepared, r: usize) -> Result<Projected, SubspaceError> {
    let (p, nu, n) = (d.ny, d.nu, d.n_lines());
    let rp = r * p;
    let nc = r + rp;
    let cw = column_weights(d);
    // powers xi_k^i, line after line
    let mut pw = vec![num_complex::Complex::new(0.0, 0.0); n * r];
    for k in 0..n {
        let mut x = num_complex::Complex::new(1.0, 0.0);
        for i in 0..r {
            pw[k * r + i] = x;
            x *= d.xi[k];
        }
    }
    // lines per block of the running QR: at least as many rows as the triangle it
    // carries, so that refactoring the triangle costs at most half of the new rows
    let lpb = LINES_PER_BLOCK.max(nc.div_ceil(2) * 2);
    // the inputs in a fixed number of interleaved chunks, in parallel (a fixed count,
    // not the thread count, so that the result does not depend on the machine)
    let chunks = INPUT_CHUNKS.min(nu).max(1);
    let parts: Vec<Result<Mat<f64>, SubspaceError>> = (0..chunks)
        .into_par_iter()
        .map(|chunk| {
            let mut acc = Mat::<f64>::zeros(rp, rp);
            let mut block = Mat::<f64>::zeros(2 * lpb, nc);
            for j in (chunk..nu).step_by(chunks) {
                let mut rj = Mat::<f64>::zeros(nc, nc);
                let mut k0 = 0;
                while k0 < n {
                    let k1 = (k0 + lpb).min(n);
                    for k in k0..k1 {
                        let c = cw[k * nu + j];
                        let (re, im) = (2 * (k - k0), 2 * (k - k0) + 1);
                        for i in 0..r {
                            let x = pw[k * r + i] * c;
                            block[(re, i)] = x.re;
                            block[(im, i)] = x.im;
                            for o in 0..p {
                                let y = x * d.h[k * p * nu + j * p + o];
                                block[(re, r + i * p + o)] = y.re;
                                block[(im, r + i * p + o)] = y.im;
                            }
                        }
                    }
                    rj = absorb(&rj, &block, 2 * (k1 - k0))?;
                    k0 = k1;
                }
                let r22 = Mat::from_fn(rp, rp, |a, b| rj[(r + a, r + b)]);
                acc = absorb(&acc, &r22, rp)?;
            }
            Ok(acc)
        })
        .collect();
    let mut acc = Mat::<f64>::zeros(rp, rp);
    for part in parts {
        acc = absorb(&acc, &part?, rp)?;
    }
    let l = if d.uniform {
        None
    } else {
        Some(noise_cholesky(d, r, &cw)?)
    };
    let m = match &l {
        // M = R_S L^{-T}: solve L M^T = R_S^T column by column (forward substitution)
        Some(l) => {
            let mut mt = acc.transpose().to_owned();
            for col in 0..rp {
                for i in 0..rp {
                    let mut s = mt[(i, col)];
                    for q in 0..i {
                        s -= l[(i, q)] * mt[(q, col)];
                    }
                    mt[(i, col)] = s / l[(i, i)];
                }
            }
            mt.transpose().to_owned()
        }
        None => acc,
    };
    let svd = m
        .thin_svd()
        .map_err(|e| SubspaceError::numerical("SVD of the projected data", format!("{e:?}")))?;
    let s = svd.S().column_vector();
    let singular_values: Vec<f64> = (0..rp).map(|i| s[i]).collect();
    if singular_values.iter().any(|x| !x.is_finite()) {
        return Err(SubspaceError::numerical(
            "SVD of the projected data",
            "non-finite singular values",
        ));
    }
    Ok(Projected {
        r,
        p,
        singular_values,
        v: svd.V().to_owned(),
        l,
    })
}

/// Square root of the diagonal of the row noise covariance (a diagonal `L`): the
/// noise variance of the rows of output `o` is `t_o = sum_kj c_kj^2 var_koj` for every
/// power of `xi` (since `|xi_k| = 1`). The off-diagonal (Toeplitz) part is left out:
/// with the lines on an arc of the unit circle it is close to singular for more than a
/// few block rows, and its inverse square root would amplify directions that hold
/// neither signal nor noise.
fn noise_cholesky(d: &Prepared, r: usize, cw: &[f64]) -> Result<Mat<f64>, SubspaceError> {
    let (p, nu, n) = (d.ny, d.nu, d.n_lines());
    let mut t = vec![0.0; p];
    for k in 0..n {
        for (o, to) in t.iter_mut().enumerate() {
            for j in 0..nu {
                let c = cw[k * nu + j];
                let var = d.var_h(k, j * p + o);
                if c > 0.0 && var.is_finite() {
                    *to += c * c * var;
                }
            }
        }
    }
    if let Some(o) = t.iter().position(|&x| !(x > 0.0 && x.is_finite())) {
        return Err(SubspaceError::numerical(
            "noise weighting of the rows",
            format!(
                "output {} has no line with a finite, positive variance",
                o + 1
            ),
        ));
    }
    let rp = r * p;
    Ok(Mat::from_fn(rp, rp, |a, b| {
        if a == b {
            t[a % p].sqrt()
        } else {
            0.0
        }
    }))
}
