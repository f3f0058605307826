//! The numerator Gram matrices of all entries at once.
//!
//! Every entry's numerator block of the normal equations, in the convex numerator
//! problem (24) and in a step of Algorithm 1 (the `Phi^T W Phi` block of the identity
//! columns of (12)/(14)), is
//!
//! `H_e = sum_k s_ek^2 (Re u(k) Re u(k)^T + Im u(k) Im u(k)^T)`,
//!
//! with the numerator basis `u(k)` shared by all entries and only the line scales
//! `s_e = sqrt(w_e) |F_e|` differing (the variance of each entry). The products
//! `p_ij(k) = Re u_i Re u_j + Im u_i Im u_j` (`i <= j`, symmetric) do not depend on the
//! entry, so all `H_e` follow from one product `P^T S2` of the `n x nn (nn + 1) / 2`
//! products and the `n x m` squared scales: `n nn^2 m` flops instead of the
//! `4 n nn^2 m` of one `2n`-row Gram per entry, and no scaled copy of the basis per
//! entry.

use crate::problem::Basis;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use rayon::prelude::*;

/// Lines per block of products: the block (`GRAM_BLOCK x nn (nn + 1) / 2` doubles,
/// 680 kB for the wafer stage's 36 numerator coefficients) stays in the L2 cache.
const GRAM_BLOCK: usize = 128;

/// Lines per chunk: each chunk sums its own blocks, and the chunks are added in line
/// order, so the result does not depend on the number of threads.
const GRAM_CHUNK: usize = 1024;

/// The numerator Gram matrices `H_e` (module docs) of `ne` entries, for the first `nn`
/// basis functions of `basis`. `s2[e * n + k]` is entry `e`'s squared line scale
/// `s_ek^2` at line `k`. Returns `ne` symmetric `nn x nn` matrices, column-major, one
/// after the other (`[e * nn * nn + j * nn + i]`). Chunks of lines run on the rayon
/// pool when `parallel`.
pub fn numerator_grams(
    basis: &Basis,
    nn: usize,
    s2: &[f64],
    ne: usize,
    parallel: bool,
) -> Vec<f64> {
    let n = basis.n;
    assert!(
        s2.len() >= ne * n,
        "s2 holds {} of {} values",
        s2.len(),
        ne * n
    );
    let np = nn * (nn + 1) / 2;
    let chunk = |k0: usize| -> Mat<f64> {
        let k1 = (k0 + GRAM_CHUNK).min(n);
        let mut acc = Mat::<f64>::zeros(np, ne);
        let mut pb = Mat::<f64>::zeros(GRAM_BLOCK, np);
        let mut wb = Mat::<f64>::zeros(GRAM_BLOCK, ne);
        for (b, b0) in (k0..k1).step_by(GRAM_BLOCK).enumerate() {
            let len = GRAM_BLOCK.min(k1 - b0);
            let mut p = 0;
            for j in 0..nn {
                let ujr = &basis.u_re[j * n + b0..][..len];
                let uji = &basis.u_im[j * n + b0..][..len];
                for i in 0..=j {
                    let uir = &basis.u_re[i * n + b0..][..len];
                    let uii = &basis.u_im[i * n + b0..][..len];
                    let col = &mut pb.col_as_slice_mut(p)[..len];
                    for k in 0..len {
                        col[k] = uir[k] * ujr[k] + uii[k] * uji[k];
                    }
                    p += 1;
                }
            }
            for e in 0..ne {
                wb.col_as_slice_mut(e)[..len].copy_from_slice(&s2[e * n + b0..][..len]);
            }
            matmul(
                acc.as_mut(),
                if b == 0 { Accum::Replace } else { Accum::Add },
                pb.as_ref().subrows(0, len).transpose(),
                wb.as_ref().subrows(0, len),
                1.0,
                Par::Seq,
            );
        }
        acc
    };
    let starts: Vec<usize> = (0..n).step_by(GRAM_CHUNK).collect();
    let parts: Vec<Mat<f64>> = if parallel && starts.len() > 1 {
        starts.par_iter().map(|&k0| chunk(k0)).collect()
    } else {
        starts.iter().map(|&k0| chunk(k0)).collect()
    };
    let mut out = vec![0.0; ne * nn * nn];
    for (e, h) in out.chunks_exact_mut(nn * nn).enumerate() {
        let mut p = 0;
        for j in 0..nn {
            for i in 0..=j {
                let v: f64 = parts.iter().map(|a| a[(p, e)]).sum();
                h[j * nn + i] = v;
                h[i * nn + j] = v;
                p += 1;
            }
        }
    }
    out
}

/// Squared line scales `s_ek^2 = w_ek |F_ek|^2` of every entry, `[e * n + k]` (the
/// scales of [`crate::problem::EntryLines`], squared).
pub fn squared_scales(sqrt_w: &[f64], basis: &Basis, m: usize) -> Vec<f64> {
    let n = basis.n;
    let mut s2 = vec![0.0; m * n];
    for e in 0..m {
        let fa = &basis.f_abs[basis.f_offset(e)..][..n];
        let sw = &sqrt_w[e * n..][..n];
        for (k, v) in s2[e * n..][..n].iter_mut().enumerate() {
            let s = sw[k] * fa[k];
            *v = s * s;
        }
    }
    s2
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shared products give each entry's Gram matrix of its scaled basis columns
    /// (a rigid body and three modes, 2500 lines: one partial chunk and one partial
    /// block).
    #[test]
    fn grams_match_each_entrys_scaled_columns() {
        use crate::problem::Layout;
        use crate::{AdditiveModel, Domain};
        let (n, ne) = (2500, 3);
        let mut model = AdditiveModel::new(1, ne, Domain::Continuous).unwrap();
        model
            .push_rigid_body(2, AdditiveModel::rigid_scale(10.0, 1000.0))
            .unwrap();
        for f in [50.0, 220.0, 700.0] {
            model.push_mode(f, 0.01, false).unwrap();
        }
        let lay = Layout::of(&model);
        let nn = lay.n_num;
        let omega: Vec<f64> = (0..n)
            .map(|k| 2.0 * std::f64::consts::PI * (10.0 + 0.4 * k as f64))
            .collect();
        let basis = Basis::new(&model, &lay, &omega);
        let sqrt_w: Vec<f64> = (0..ne * n).map(|i| 0.5 + (i % 13) as f64 / 7.0).collect();
        let s2 = squared_scales(&sqrt_w, &basis, ne);
        for parallel in [false, true] {
            let h = numerator_grams(&basis, nn, &s2, ne, parallel);
            for e in 0..ne {
                let se: Vec<f64> = s2[e * n..][..n].iter().map(|v| v.sqrt()).collect();
                let cols = basis.scaled_columns(&se, nn, 0);
                let direct = cols.transpose() * &cols;
                for j in 0..nn {
                    for i in 0..nn {
                        let (a, b) = (h[e * nn * nn + j * nn + i], direct[(i, j)]);
                        let scale = (direct[(i, i)] * direct[(j, j)]).sqrt();
                        assert!(
                            (a - b).abs() <= 1e-12 * scale,
                            "entry {e} ({i}, {j}): {a} against {b}"
                        );
                    }
                }
            }
        }
    }
}
