//! The subspace step on compressed data, for large MIMO FRFs.
//!
//! The poles are common to every entry, so they can be found from fewer entries than
//! the data hold: the inputs are projected onto `k` fixed directions `V` (`nu x k`,
//! orthonormal), `G(w) V = C (xi I - A)^{-1} (B V) + D V`, a plant with the same states
//! and `k` inputs. A mode whose residue is `c b^T` stays in the compressed data with
//! the residue `c (V^T b)^T`; for random directions `|V^T b|^2` is `|b|^2 k / nu`
//! times a chi-square variable with `k` degrees of freedom over `k`, so with a few
//! directions every mode is kept (the probability that a mode keeps less than a tenth
//! of its average share is below 1e-3 at `k = 8`).
//!
//! With orthonormal directions, white noise stays white: the variance of a compressed
//! entry is `sum_j V_jl^2 var_ij`. The weighted singular values of the projection
//! ([`crate::projection`]) keep their signal-to-noise ratio: the signal of a mode and
//! the noise level both scale with the square root of the columns (`k` instead of
//! `nu` per line), as long as the columns far outnumber the rows. The cost of the
//! projection, and of every residue refit of the order choice, falls by `nu / k`.
//!
//! The least squares (17) for `B` and `D` has a row per line and output: with many
//! outputs it is solved on outputs projected onto `k` directions `U` as well
//! (`U^T C (xi I - A)^{-1} B + U^T D`; `B` is determined as long as every mode is seen
//! through `U^T C`). `B` only weighs the eigenvalues of `A` for the merging of split
//! poles; the currency's residues are refitted on the full data with the poles fixed.

use crate::prepare::Prepared;
use crate::SubspaceError;
use faer::Mat;
use frf_data::{Frf, FrfDataset};
use realize::C64;

/// `n x k` orthonormal directions (`k <= n`): the Q factor of a Gaussian matrix drawn
/// from a fixed seed (splitmix64 and the Box-Muller transform), so that a fit is
/// reproducible.
pub fn directions(n: usize, k: usize, seed: u64) -> Mat<f64> {
    let k = k.min(n);
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        // uniform in (0, 1]
        ((z >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    };
    let mut g = Mat::<f64>::zeros(n, k);
    for j in 0..k {
        for i in 0..n {
            let (u1, u2) = (next(), next());
            g[(i, j)] = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        }
    }
    g.qr().compute_thin_Q()
}

/// The data with the inputs projected onto the columns of `v` (`nu x k`): `G(w) V`,
/// with the variance `sum_j v_jl^2 var_ij` of each compressed entry when the data
/// carry one.
pub fn compress_inputs<D: FrfDataset + ?Sized>(
    data: &D,
    v: &Mat<f64>,
) -> Result<Frf, SubspaceError> {
    project(data, v, Side::Inputs)
}

/// The data with the outputs projected onto the columns of `u` (`ny x k`): `U^T G(w)`,
/// with the variance `sum_o u_ol^2 var_oj` of each projected entry when the data carry
/// one. The delay search of the compressed path runs on it (see
/// [`crate::SubspaceConfig::output_directions`]).
pub fn compress_outputs<D: FrfDataset + ?Sized>(
    data: &D,
    u: &Mat<f64>,
) -> Result<Frf, SubspaceError> {
    project(data, u, Side::Outputs)
}

/// The side of the data [`project`] projects.
#[derive(Clone, Copy)]
enum Side {
    Inputs,
    Outputs,
}

/// The data with the inputs (`G V`, `v` is `nu x k`) or the outputs (`V^T G`, `v` is
/// `ny x k`) projected onto the columns of `v`, with the variance `sum_q v_ql^2 var` of
/// each projected entry when the data carry one.
fn project<D: FrfDataset + ?Sized>(
    data: &D,
    v: &Mat<f64>,
    side: Side,
) -> Result<Frf, SubspaceError> {
    let (ny, nu, nl, k) = (data.ny(), data.nu(), data.n_lines(), v.ncols());
    let (n, what) = match side {
        Side::Inputs => (nu, "input"),
        Side::Outputs => (ny, "output"),
    };
    if v.nrows() != n {
        return Err(SubspaceError::invalid(
            &format!("{what} directions"),
            format!("{} x {k}", v.nrows()),
            format!("the data have {n} {what}s"),
        ));
    }
    // the projected data's outputs and inputs
    let (py, pu) = match side {
        Side::Inputs => (ny, k),
        Side::Outputs => (k, nu),
    };
    let g = data.values_vec();
    let var = data.variance_vec();
    let (m, mc) = (ny * nu, py * pu);
    let mut values = vec![C64::new(0.0, 0.0); nl * mc];
    let mut variance = var.as_ref().map(|_| vec![0.0; nl * mc]);
    for line in 0..nl {
        for b in 0..pu {
            for a in 0..py {
                let (mut s, mut sv) = (C64::new(0.0, 0.0), 0.0);
                for q in 0..n {
                    // direction `l` and the source entry summed over `q`
                    let (l, e) = match side {
                        Side::Inputs => (b, q * ny + a),
                        Side::Outputs => (a, b * ny + q),
                    };
                    let c = v[(q, l)];
                    s += g[line * m + e] * c;
                    if let Some(src) = var.as_ref() {
                        sv += c * c * src[line * m + e];
                    }
                }
                values[line * mc + b * py + a] = s;
                if let Some(out) = variance.as_mut() {
                    out[line * mc + b * py + a] = sv;
                }
            }
        }
    }
    let freq: Vec<f64> = (0..nl).map(|line| data.freq_hz(line)).collect();
    let mut out = Frf::new(freq, py, pu, values, variance)?;
    out.units = data.units().map(str::to_string);
    Ok(out)
}

/// The prepared data with the outputs projected onto the columns of `u` (`ny x k`):
/// `U^T h` per line and input, the variance `sum_o u_ol^2 var_oj` (the weights of the
/// criterion follow from it).
pub(crate) fn project_outputs(d: &Prepared, u: &Mat<f64>) -> Prepared {
    let (ny, nu, nl, k) = (d.ny, d.nu, d.n_lines(), u.ncols());
    let (m, mc) = (ny * nu, k * nu);
    let mut h = vec![C64::new(0.0, 0.0); nl * mc];
    let mut w = vec![0.0; nl * mc];
    for line in 0..nl {
        for j in 0..nu {
            for l in 0..k {
                let (mut s, mut var) = (C64::new(0.0, 0.0), 0.0);
                for o in 0..ny {
                    let c = u[(o, l)];
                    s += d.h[line * m + j * ny + o] * c;
                    var += c * c * d.var_h(line, j * ny + o);
                }
                h[line * mc + j * k + l] = s;
                // back to the weights of the criterion on G (`var_h` divides by |F|^2)
                w[line * mc + j * k + l] = if d.uniform {
                    1.0
                } else if var.is_finite() && var > 0.0 {
                    1.0 / (var * d.fabs2[line])
                } else {
                    0.0
                };
            }
        }
    }
    Prepared {
        ny: k,
        nu,
        omega: d.omega.clone(),
        xi: d.xi.clone(),
        h,
        w,
        uniform: d.uniform,
        fabs2: d.fabs2.clone(),
        variable: d.variable,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_are_orthonormal_and_reproducible() {
        let v = directions(50, 8, 7);
        let g = v.transpose() * &v;
        for i in 0..8 {
            for j in 0..8 {
                let e = if i == j { 1.0 } else { 0.0 };
                assert!((g[(i, j)] - e).abs() < 1e-12, "{i} {j} {}", g[(i, j)]);
            }
        }
        assert_eq!(v, directions(50, 8, 7));
        assert_ne!(v, directions(50, 8, 8));
    }

    #[test]
    fn projected_outputs_are_the_product_and_carry_the_variance() {
        let (ny, nu, nl) = (5, 3, 4);
        let freq: Vec<f64> = (1..=nl).map(|k| k as f64).collect();
        let values: Vec<C64> = (0..nl * ny * nu)
            .map(|i| C64::new(0.3 * i as f64 - 2.0, i as f64))
            .collect();
        let var: Vec<f64> = (0..nl * ny * nu).map(|i| 2.0 + i as f64).collect();
        let data = Frf::new(freq, ny, nu, values.clone(), Some(var.clone())).unwrap();
        let u = directions(ny, 2, 3);
        let c = compress_outputs(&data, &u).unwrap();
        assert_eq!((c.ny(), c.nu(), c.n_lines()), (2, nu, nl));
        for k in 0..nl {
            for l in 0..2 {
                for j in 0..nu {
                    let (mut s, mut sv) = (C64::new(0.0, 0.0), 0.0);
                    for o in 0..ny {
                        s += values[k * ny * nu + j * ny + o] * u[(o, l)];
                        sv += u[(o, l)].powi(2) * var[k * ny * nu + j * ny + o];
                    }
                    assert!((c.value(k, l, j) - s).norm() < 1e-12);
                    assert!((c.variance(k, l, j).unwrap() - sv).abs() < 1e-12);
                }
            }
        }
        assert!(compress_outputs(&data, &directions(4, 2, 3)).is_err());
    }

    #[test]
    fn compressed_inputs_are_the_product_and_carry_the_variance() {
        let (ny, nu, nl) = (3, 5, 4);
        let freq: Vec<f64> = (1..=nl).map(|k| k as f64).collect();
        let values: Vec<C64> = (0..nl * ny * nu)
            .map(|i| C64::new(i as f64, 0.5 * i as f64 - 1.0))
            .collect();
        let var: Vec<f64> = (0..nl * ny * nu).map(|i| 1.0 + i as f64).collect();
        let data = Frf::new(freq, ny, nu, values.clone(), Some(var.clone())).unwrap();
        let v = directions(nu, 2, 1);
        let c = compress_inputs(&data, &v).unwrap();
        assert_eq!((c.ny(), c.nu(), c.n_lines()), (ny, 2, nl));
        for k in 0..nl {
            for i in 0..ny {
                for l in 0..2 {
                    let (mut s, mut sv) = (C64::new(0.0, 0.0), 0.0);
                    for j in 0..nu {
                        s += values[k * ny * nu + j * ny + i] * v[(j, l)];
                        sv += v[(j, l)].powi(2) * var[k * ny * nu + j * ny + i];
                    }
                    assert!((c.value(k, i, l) - s).norm() < 1e-12);
                    assert!((c.variance(k, i, l).unwrap() - sv).abs() < 1e-12);
                }
            }
        }
    }
}
