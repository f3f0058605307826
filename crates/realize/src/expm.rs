//! The matrix exponential by scaling and squaring with Padé approximants.
//!
//! N. J. Higham, "The scaling and squaring method for the matrix exponential revisited",
//! SIAM J. Matrix Anal. Appl. 26(4), 1179–1193, 2005 (Algorithm 2.3, the algorithm of
//! MATLAB's `expm`): with `theta_m` the largest 1-norm for which the backward error of the
//! diagonal `[m/m]` Padé approximant `r_m` is below the unit roundoff,
//!
//! - if `||A||_1 <= theta_m` for `m` in `3, 5, 7, 9`, return `r_m(A)` for the smallest
//!   such `m`;
//! - otherwise scale `A <- A / 2^s` with `s = ceil(log2(||A||_1 / theta_13))`, evaluate
//!   `r_13(A)` and square the result `s` times.
//!
//! `r_m = q_m(A)^{-1} p_m(A)` is evaluated as `(V - U)^{-1} (V + U)` with `U` the odd and
//! `V` the even part of the numerator polynomial, using the paper's schemes (6 matrix
//! products and one LU solve for `m = 13`).

use crate::RealizeError;
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::Solve;
use faer::{Accum, Mat, MatRef, Par};

/// `theta_m` of Higham (2005), Table 2.3, for `m = 3, 5, 7, 9, 13`.
const THETA: [(usize, f64); 5] = [
    (3, 1.495_585_217_958_292e-2),
    (5, 2.539_398_330_063_23e-1),
    (7, 9.504_178_996_162_932e-1),
    (9, 2.097_847_961_257_068),
    (13, 5.371_920_351_148_152),
];

/// Coefficients `b_0..b_m` of the `[m/m]` Padé numerator `p_m(x) = sum b_i x^i`
/// (the denominator is `p_m(-x)`).
fn pade_coefficients(m: usize) -> &'static [f64] {
    match m {
        3 => &[120.0, 60.0, 12.0, 1.0],
        5 => &[30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0],
        7 => &[
            17_297_280.0,
            8_648_640.0,
            1_995_840.0,
            277_200.0,
            25_200.0,
            1_512.0,
            56.0,
            1.0,
        ],
        9 => &[
            17_643_225_600.0,
            8_821_612_800.0,
            2_075_673_600.0,
            302_702_400.0,
            30_270_240.0,
            2_162_160.0,
            110_880.0,
            3_960.0,
            90.0,
            1.0,
        ],
        _ => &[
            64_764_752_532_480_000.0,
            32_382_376_266_240_000.0,
            7_771_770_303_897_600.0,
            1_187_353_796_428_800.0,
            129_060_195_264_000.0,
            10_559_470_521_600.0,
            670_442_572_800.0,
            33_522_128_640.0,
            1_323_241_920.0,
            40_840_800.0,
            960_960.0,
            16_380.0,
            182.0,
            1.0,
        ],
    }
}

/// The matrix 1-norm (maximum absolute column sum).
pub(crate) fn norm1(a: MatRef<'_, f64>) -> f64 {
    (0..a.ncols())
        .map(|j| (0..a.nrows()).map(|i| a[(i, j)].abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

fn mul(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut c = Mat::zeros(a.nrows(), b.ncols());
    matmul(c.as_mut(), Accum::Replace, a, b, 1.0, Par::Seq);
    c
}

/// `sum_i c_i M_i` plus `c0 I`.
fn lincomb(n: usize, c0: f64, terms: &[(f64, &Mat<f64>)]) -> Mat<f64> {
    Mat::from_fn(n, n, |i, j| {
        let mut s = if i == j { c0 } else { 0.0 };
        for (c, m) in terms {
            s += c * m[(i, j)];
        }
        s
    })
}

/// The `[m/m]` Padé approximant `r_m(A)` by Higham's (2005) evaluation schemes.
fn pade(a: MatRef<'_, f64>, m: usize) -> Mat<f64> {
    let n = a.nrows();
    let b = pade_coefficients(m);
    let a2 = mul(a, a.as_ref());
    let (u, v) = if m == 13 {
        let a4 = mul(a2.as_ref(), a2.as_ref());
        let a6 = mul(a4.as_ref(), a2.as_ref());
        let inner_u = lincomb(n, 0.0, &[(b[13], &a6), (b[11], &a4), (b[9], &a2)]);
        let mut w = mul(a6.as_ref(), inner_u.as_ref());
        w += lincomb(n, b[1], &[(b[7], &a6), (b[5], &a4), (b[3], &a2)]);
        let u = mul(a, w.as_ref());
        let inner_v = lincomb(n, 0.0, &[(b[12], &a6), (b[10], &a4), (b[8], &a2)]);
        let mut v = mul(a6.as_ref(), inner_v.as_ref());
        v += lincomb(n, b[0], &[(b[6], &a6), (b[4], &a4), (b[2], &a2)]);
        (u, v)
    } else {
        // Powers A^2, A^4, .., A^(m-1); U = A sum_k b_{2k+1} A^{2k}, V = sum_k b_{2k} A^{2k}.
        let mut powers: Vec<Mat<f64>> = vec![a2];
        while 2 * (powers.len() + 1) < m {
            let next = mul(powers[powers.len() - 1].as_ref(), powers[0].as_ref());
            powers.push(next);
        }
        let odd: Vec<(f64, &Mat<f64>)> = powers
            .iter()
            .enumerate()
            .map(|(k, p)| (b[2 * k + 3], p))
            .collect();
        let even: Vec<(f64, &Mat<f64>)> = powers
            .iter()
            .enumerate()
            .map(|(k, p)| (b[2 * k + 2], p))
            .collect();
        let w = lincomb(n, b[1], &odd);
        let u = mul(a, w.as_ref());
        let v = lincomb(n, b[0], &even);
        (u, v)
    };
    let p = &v + &u;
    let q = &v - &u;
    q.partial_piv_lu().solve(&p)
}

/// The matrix exponential `e^A` of a real square matrix by scaling and squaring with
/// Padé approximants of degree up to 13 (Higham 2005, Algorithm 2.3; see the
/// [module documentation](self)).
///
/// Errors: [`RealizeError::Dimension`] for a non-square matrix,
/// [`RealizeError::NonFinite`] for non-finite entries, and [`RealizeError::Numerical`]
/// when the result overflows.
pub fn expm(a: MatRef<'_, f64>) -> Result<Mat<f64>, RealizeError> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(RealizeError::Dimension {
            what: "expm argument".into(),
            expected: format!("{n}x{n}"),
            got: format!("{}x{}", n, a.ncols()),
        });
    }
    if !(0..n).all(|j| (0..n).all(|i| a[(i, j)].is_finite())) {
        return Err(RealizeError::NonFinite {
            what: "expm argument".into(),
        });
    }
    let nrm = norm1(a);
    let mut result = None;
    for &(m, theta) in &THETA[..4] {
        if nrm <= theta {
            result = Some(pade(a, m));
            break;
        }
    }
    let e = match result {
        Some(e) => e,
        None => {
            let theta13 = THETA[4].1;
            let s = (nrm / theta13).log2().ceil().max(0.0);
            if s > 1100.0 {
                return Err(RealizeError::Numerical {
                    what: "expm".into(),
                    why: format!("the 1-norm {nrm:e} is too large"),
                });
            }
            let s = s as i32;
            let scale = 2f64.powi(-s);
            let scaled = Mat::from_fn(n, n, |i, j| a[(i, j)] * scale);
            let mut e = pade(scaled.as_ref(), 13);
            for _ in 0..s {
                e = mul(e.as_ref(), e.as_ref());
            }
            e
        }
    };
    if (0..n).all(|j| (0..n).all(|i| e[(i, j)].is_finite())) {
        Ok(e)
    } else {
        Err(RealizeError::Numerical {
            what: "expm".into(),
            why: "the exponential overflows or the Padé denominator is singular".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pade_degrees_agree_on_small_argument() {
        // Every r_m is accurate to roundoff when ||A|| <= theta_3.
        let a = Mat::from_fn(3, 3, |i, j| 1e-3 * ((i * 3 + j) as f64 - 4.0));
        let r13 = pade(a.as_ref(), 13);
        for m in [3, 5, 7, 9] {
            let r = pade(a.as_ref(), m);
            let d = (&r - &r13).norm_l2();
            assert!(d < 1e-15, "m = {m}: {d:e}");
        }
    }

    #[test]
    fn one_by_one_matches_exp() {
        for x in [-30.0, -2.0, -1e-3, 0.0, 0.5, 3.0, 20.0] {
            let a = Mat::from_fn(1, 1, |_, _| x);
            let e = expm(a.as_ref()).unwrap();
            let r = (e[(0, 0)] - f64::exp(x)).abs() / f64::exp(x);
            // Each squaring doubles the relative error of the scaled exponential.
            assert!(r < 2e-15 * (1.0 + x.abs()), "x = {x}: rel. error {r:e}");
        }
    }
}
