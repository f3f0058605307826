//! The evaluation and the Jacobian of [`crate::varpro::Problem`] when entries share
//! their weights (up to a scalar per entry): the cost stays linear in lines and
//! entries, and the per-entry factorisations are replaced by one per group of entries.
//!
//! Without dynamics factors (which act on some entries only) every entry has the same
//! regressor `A` (the currency's basis at the lines, weighted): the weights of a group
//! ([`frf_data::proportional_groups`]) are `s_e w_k` and the entry's problem is
//! `sqrt(s_e) (A c_e - y_e)` with `y_e` the group-weighted data, whose solution does not
//! depend on `s_e`. One QR of `A` gives every entry's linear parameters (one product
//! `Q^T Y` for all right-hand sides).
//!
//! Kaufman's projected Jacobian of entry `e` (Golub & Pereyra; the form of
//! [`crate::varpro`]) is `J_e = sqrt(s_e) P^perp dA/dtheta c_e`. The derivative of the
//! regressor with respect to one nonlinear parameter `i` touches a few of its columns
//! only, and those derivative columns do not depend on the entry either: with `D` the
//! matrix of all derivative columns (two per pair parameter and residue column, one
//! per real pole, one per linear column for the delay) and `iota(a)` the linear
//! parameter that multiplies derivative column `a`,
//!
//! `sum_e J_e^T J_e [i, j] = sum_{a in S_i, b in S_j} (D^T P^perp D)[a, b] K[iota(a), iota(b)]`,
//! with `K = sum_e s_e c_e c_e^T`,
//!
//! and `sum_e J_e^T r_e [i] = sum_{a in S_i} sum_e s_e c_e[iota(a)] (D^T r_e)[a]` (the
//! residual `r_e` is orthogonal to the columns of `A`) `= sum_{a in S_i} D[:, a]^T
//! W[:, iota(a)]` with `W = R S C^T` (`R`: the residuals as columns, `S`: the scales,
//! `C`: the coefficients as columns): one product of the residuals with the `n_lin`
//! columns of `S C^T` rather than with the `n_D` (about twice as many) derivative
//! columns, on the residuals the evaluation at the same point kept. `D^T P^perp D` is
//! the Gram matrix of the lower-right block of the `R` factor of `[A | D]`: one QR per
//! group and Jacobian, of `2N x (n_lin + n_D)`, instead of one per entry (a two-level
//! QR of blocks of lines on the rayon pool, [`crate::qr::tall_r`]). The information
//! matrix is then factorised by a Cholesky decomposition (column-scaled to unit
//! diagonal); that squares its condition number, which the iteration tolerates (the
//! right-hand side, the gradient, is computed from the explicit residual and keeps its
//! accuracy) and the per-entry path takes over when the decomposition fails.

use crate::varpro::{Eval, Problem, Singular};
use crate::weight_groups::Shared;
use crate::C64;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par, Side};
use rayon::prelude::*;

/// Entries per parallel chunk of a group's right-hand sides.
const CHUNK: usize = 32;

/// One column of the derivative matrix `D`: the nonlinear parameter it belongs to and
/// the linear parameter that multiplies it.
#[derive(Debug, Clone, Copy)]
struct DerivCol {
    param: usize,
    coef: usize,
}

impl Problem {
    /// The derivative columns of the layout, in the order [`Problem::fill_derivatives`]
    /// writes them.
    fn deriv_cols(&self) -> Vec<DerivCol> {
        let lay = &self.lay;
        let (np, cpp) = (lay.n_pairs, lay.cpp());
        let mut out = Vec::new();
        for q in 0..np {
            for ab in 0..2 {
                for cc in 0..cpp {
                    out.push(DerivCol {
                        param: 2 * q + ab,
                        coef: q * cpp + cc,
                    });
                }
            }
        }
        for r in 0..lay.n_real {
            out.push(DerivCol {
                param: 2 * np + r,
                coef: np * cpp + r,
            });
        }
        if let Some(i) = lay.delay_index() {
            out.extend((0..lay.n_lc()).map(|l| DerivCol { param: i, coef: l }));
        }
        out
    }

    /// The group-weighted regressor `A` (`2N x n_lin`).
    fn shared_basis(&self, lines: &crate::varpro::Lines, sw: &[f64]) -> Mat<f64> {
        let lay = &self.lay;
        let (n_lc, n_lin) = (lay.n_lc(), lay.n_lin());
        Mat::from_fn(2 * self.n_lines(), n_lin, |r, l| {
            let k = r / 2;
            let v = if l < n_lc {
                lines.fphi[k * n_lc + l] * sw[k]
            } else {
                C64::new(sw[k], 0.0)
            };
            if r % 2 == 0 {
                v.re
            } else {
                v.im
            }
        })
    }

    /// The group-weighted derivative columns `D` (`2N x n_D`, see [`DerivCol`]).
    fn fill_derivatives(&self, lines: &crate::varpro::Lines, sw: &[f64], nd: usize) -> Mat<f64> {
        let lay = &self.lay;
        let (np, cpp, n_lc) = (lay.n_pairs, lay.cpp(), lay.n_lc());
        let n = self.n_lines();
        let mut d = Mat::<f64>::zeros(2 * n, nd);
        for k in 0..n {
            let s = sw[k];
            let mut put = |a: usize, v: C64| {
                d[(2 * k, a)] = v.re * s;
                d[(2 * k + 1, a)] = v.im * s;
            };
            let mut a = 0;
            for q in 0..np {
                for ab in 0..2 {
                    let base = ((k * np + q) * 2 + ab) * cpp;
                    for cc in 0..cpp {
                        put(a, lines.dpair[base + cc]);
                        a += 1;
                    }
                }
            }
            for r in 0..lay.n_real {
                put(a, lines.dreal[k * lay.n_real + r]);
                a += 1;
            }
            if lay.delay {
                let jw = C64::new(0.0, -self.omega[k]);
                for l in 0..n_lc {
                    put(a, jw * lines.fphi[k * n_lc + l]);
                    a += 1;
                }
            }
        }
        d
    }

    /// [`Problem::evaluate`] on shared weights (see the module documentation).
    pub(crate) fn evaluate_shared(&self, sh: &Shared, theta: &[f64]) -> Result<Eval, Singular> {
        let lines = self.lines(theta);
        let (m, n_lin) = (self.lay.m(), self.lay.n_lin());
        let mut coef = vec![0.0; m * n_lin];
        let mut entry_cost = vec![0.0; m];
        let mut residuals = Vec::with_capacity(sh.groups.len());
        for grp in &sh.groups {
            let mut a = self.shared_basis(&lines, &grp.sw);
            // column scaling, then the QR; a (scaled) pivot below 1e-11 is a column in the
            // span of the others (the test of the per-entry path)
            let cn: Vec<f64> = (0..n_lin)
                .map(|l| {
                    let s = a.col(l).norm_l2();
                    if s > 0.0 {
                        s
                    } else {
                        1.0
                    }
                })
                .collect();
            for (l, &s) in cn.iter().enumerate() {
                for r in 0..a.nrows() {
                    a[(r, l)] /= s;
                }
            }
            let qr = a.qr();
            let rf = qr.thin_R().to_owned();
            for l in 0..n_lin {
                let ratio = rf[(l, l)].abs();
                if ratio.is_nan() || ratio <= 1e-11 {
                    return Err(Singular {
                        entry: grp.entries[0],
                        column: l,
                        ratio,
                    });
                }
            }
            let q1 = qr.compute_thin_Q();
            // per chunk of entries: its first entry, coefficients, costs and residual (kept
            // for the Jacobian at this point)
            type Chunk = (usize, Vec<f64>, Vec<f64>, Mat<f64>);
            let chunks: Vec<Chunk> = (0..grp.entries.len())
                .step_by(CHUNK)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|c0| {
                    let c1 = (c0 + CHUNK).min(grp.entries.len());
                    let y = grp.y.subcols(c0, c1 - c0);
                    let mut z = Mat::<f64>::zeros(n_lin, c1 - c0);
                    matmul(z.as_mut(), Accum::Replace, q1.transpose(), y, 1.0, Par::Seq);
                    let mut res = y.to_owned();
                    matmul(
                        res.as_mut(),
                        Accum::Add,
                        q1.as_ref(),
                        z.as_ref(),
                        -1.0,
                        Par::Seq,
                    );
                    faer::linalg::triangular_solve::solve_upper_triangular_in_place(
                        rf.as_ref(),
                        z.as_mut(),
                        Par::Seq,
                    );
                    let mut cs = vec![0.0; (c1 - c0) * n_lin];
                    let mut costs = vec![0.0; c1 - c0];
                    for c in 0..c1 - c0 {
                        for l in 0..n_lin {
                            cs[c * n_lin + l] = z[(l, c)] / cn[l];
                        }
                        costs[c] = 0.5 * grp.scale[c0 + c] * res.col(c).squared_norm_l2();
                    }
                    (c0, cs, costs, res)
                })
                .collect();
            let mut res = Vec::with_capacity(chunks.len());
            for (c0, cs, costs, r) in chunks {
                for (c, cost) in costs.into_iter().enumerate() {
                    let e = grp.entries[c0 + c];
                    entry_cost[e] = cost;
                    coef[e * n_lin..(e + 1) * n_lin]
                        .copy_from_slice(&cs[c * n_lin..(c + 1) * n_lin]);
                }
                res.push(r);
            }
            residuals.push(res);
        }
        if coef.iter().any(|x| !x.is_finite()) {
            return Err(Singular {
                entry: 0,
                column: 0,
                ratio: f64::NAN,
            });
        }
        Ok(Eval {
            cost: entry_cost.iter().sum(),
            coef,
            entry_cost,
            gram: vec![None; m],
            residual: Some(std::sync::Arc::new(residuals)),
        })
    }

    /// [`Problem::jacobian_r`] on shared weights (see the module documentation), or
    /// `None` when the information matrix is not numerically positive definite or `ev`
    /// holds no residual of these groups (not an evaluation on shared weights): the
    /// caller then runs the per-entry path.
    pub(crate) fn jacobian_shared(
        &self,
        sh: &Shared,
        theta: &[f64],
        ev: &Eval,
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let lines = self.lines(theta);
        let lay = &self.lay;
        let (n_lin, n_nl) = (lay.n_lin(), lay.n_nl());
        let cols = self.deriv_cols();
        let nd = cols.len();
        let rows = 2 * self.n_lines();
        if rows < n_lin + nd {
            return None;
        }
        let mut jtj = Mat::<f64>::zeros(n_nl, n_nl);
        let mut jtr = vec![0.0; n_nl];
        let mut vn2 = vec![0.0; n_nl];
        let mut rtr = 0.0;
        for (gi, grp) in sh.groups.iter().enumerate() {
            let a = self.shared_basis(&lines, &grp.sw);
            let d = self.fill_derivatives(&lines, &grp.sw, nd);
            // R of [A | D]: its lower-right block is the R factor of P^perp D
            let mut ad = Mat::<f64>::zeros(rows, n_lin + nd);
            ad.subcols_mut(0, n_lin).copy_from(&a);
            ad.subcols_mut(n_lin, nd).copy_from(&d);
            let rf = crate::qr::tall_r(ad.as_ref());
            let r12 = rf.submatrix(0, n_lin, n_lin, nd);
            let r22 = rf.submatrix(n_lin, n_lin, nd, nd);
            let mut mproj = Mat::<f64>::zeros(nd, nd);
            matmul(
                mproj.as_mut(),
                Accum::Replace,
                r22.transpose(),
                r22,
                1.0,
                Par::Seq,
            );
            let mut gd = mproj.clone();
            matmul(gd.as_mut(), Accum::Add, r12.transpose(), r12, 1.0, Par::Seq);
            // the coefficients C (`n_lin x entries`) and C S (`S`: the entries' scales)
            let ne = grp.entries.len();
            let coef_of = |c: usize| {
                let e = grp.entries[c];
                &ev.coef[e * n_lin..(e + 1) * n_lin]
            };
            let cm = Mat::from_fn(n_lin, ne, |l, c| coef_of(c)[l]);
            let sct = Mat::from_fn(ne, n_lin, |c, l| cm[(l, c)] * grp.scale[c]);
            // `sum_e s_e c_e[l] (D^T r_e)[a] = D[:, a]^T W[:, l]` with `W = R S C^T`: one
            // product of the residual with `n_lin` columns (not with the `n_D`
            // derivative columns), by chunks of entries on the rayon pool, on the
            // residual the evaluation at the same point kept (every evaluation on shared
            // weights keeps it; without it the per-entry path runs)
            let res = ev.residual.as_ref()?.get(gi)?;
            if res.len() != ne.div_ceil(CHUNK) {
                return None;
            }
            // one accumulator per thread, over a contiguous run of chunks
            let runs = rayon::current_num_threads().clamp(1, res.len().max(1));
            let w = (0..runs)
                .into_par_iter()
                .map(|t| {
                    let mut w = Mat::<f64>::zeros(rows, n_lin);
                    for ci in t * res.len() / runs..(t + 1) * res.len() / runs {
                        let r = &res[ci];
                        matmul(
                            w.as_mut(),
                            Accum::Add,
                            r.as_ref(),
                            sct.subrows(ci * CHUNK, r.ncols()),
                            1.0,
                            Par::Seq,
                        );
                    }
                    w
                })
                .reduce(|| Mat::<f64>::zeros(rows, n_lin), |a, b| a + b);
            for (aa, dc) in cols.iter().enumerate() {
                jtr[dc.param] += d.col(aa).transpose() * w.col(dc.coef);
            }
            let mut k = Mat::<f64>::zeros(n_lin, n_lin);
            matmul(
                k.as_mut(),
                Accum::Replace,
                cm.as_ref(),
                sct.as_ref(),
                1.0,
                Par::Seq,
            );
            // `s_e ||r_e||^2` is twice the entry's cost
            rtr += grp
                .entries
                .iter()
                .map(|&e| 2.0 * ev.entry_cost[e])
                .sum::<f64>();
            for (aa, ca) in cols.iter().enumerate() {
                for (bb, cb) in cols.iter().enumerate() {
                    let kk = k[(ca.coef, cb.coef)];
                    jtj[(ca.param, cb.param)] += mproj[(aa, bb)] * kk;
                    if ca.param == cb.param {
                        vn2[ca.param] += gd[(aa, bb)] * kk;
                    }
                }
            }
        }
        // R of [J | r] from the Gram matrix: Cholesky of the column-scaled J^T J
        let ds: Vec<f64> = (0..n_nl)
            .map(|i| {
                let v = jtj[(i, i)];
                if v > 0.0 && v.is_finite() {
                    v.sqrt()
                } else {
                    1.0
                }
            })
            .collect();
        let scaled = Mat::from_fn(n_nl, n_nl, |i, j| {
            0.5 * (jtj[(i, j)] + jtj[(j, i)]) / (ds[i] * ds[j])
        });
        let nb = n_nl + 1;
        let mut r = vec![0.0; nb * nb];
        let z = match scaled.llt(Side::Lower) {
            Ok(llt) => {
                let l = llt.L();
                for c in 0..n_nl {
                    for i in 0..=c {
                        r[c * nb + i] = l[(c, i)] * ds[c];
                    }
                }
                // z: R^T z = J^T r (forward substitution)
                let mut z = vec![0.0; n_nl];
                for i in 0..n_nl {
                    let mut s = jtr[i];
                    for (j, zj) in z.iter().enumerate().take(i) {
                        s -= r[i * nb + j] * zj;
                    }
                    z[i] = s / r[i * nb + i];
                }
                z
            }
            // not numerically positive definite (a parameter the data do not determine):
            // a square root that keeps the singular directions singular, so that the
            // damped steps stay defined and the covariance names the parameter
            Err(_) => square_root_factor(&scaled, &ds, &jtr, &mut r)?,
        };
        let z2: f64 = z.iter().map(|v| v * v).sum();
        for (i, &zi) in z.iter().enumerate() {
            r[n_nl * nb + i] = zi;
        }
        r[n_nl * nb + n_nl] = (rtr - z2).max(0.0).sqrt();
        if r.iter().any(|v| !v.is_finite()) {
            return None;
        }
        Some((r, vn2.into_iter().map(|v| v.max(0.0).sqrt()).collect()))
    }
}

/// An upper-triangular `R` (written into the first `n` columns of the `(n + 1)^2`
/// column-major `r`) with `R^T R = D S D` for the column-scaled symmetric positive
/// semi-definite `S` and the scales `ds` (`D = diag(ds)`), and `z` with `R^T z = J^T r`
/// in the least-squares sense: `S = V L V^T` (eigenvalues below zero, rounding, are
/// set to zero), `L^(1/2) V^T D = Q R` by a QR, `z = Q^T L^(+1/2) V^T D^-1 J^T r`.
fn square_root_factor(s: &Mat<f64>, ds: &[f64], jtr: &[f64], r: &mut [f64]) -> Option<Vec<f64>> {
    let n = s.nrows();
    let nb = n + 1;
    let evd = s.self_adjoint_eigen(Side::Lower).ok()?;
    let (u, lam) = (evd.U(), evd.S());
    let lmax = (0..n).map(|i| lam[i]).fold(0.0f64, f64::max);
    let sq: Vec<f64> = (0..n)
        .map(|i| {
            let l = lam[i];
            if l > lmax * 1e-30 {
                l.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    let rt = Mat::from_fn(n, n, |i, j| sq[i] * u[(j, i)] * ds[j]);
    let qr = rt.qr();
    let rr = qr.thin_R();
    let q = qr.compute_thin_Q();
    for c in 0..n {
        for i in 0..=c {
            r[c * nb + i] = rr[(i, c)];
        }
    }
    // w = L^(+1/2) V^T D^-1 J^T r
    let w: Vec<f64> = (0..n)
        .map(|i| {
            if sq[i] > 0.0 {
                (0..n).map(|j| u[(j, i)] * jtr[j] / ds[j]).sum::<f64>() / sq[i]
            } else {
                0.0
            }
        })
        .collect();
    Some(
        (0..n)
            .map(|c| (0..n).map(|i| q[(i, c)] * w[i]).sum())
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use crate::varpro::{Layout, Problem};
    use crate::C64;
    use faer::Mat;
    use realize::{FrfModel, ModalModel, PolePair, RealPole};

    /// `R^T R` (the information matrix with the residual column) of an `R` factor.
    fn gram_of(r: &[f64], nb: usize) -> Vec<f64> {
        let mut g = vec![0.0; nb * nb];
        for a in 0..nb {
            for b in 0..nb {
                g[a * nb + b] = (0..nb).map(|i| r[a * nb + i] * r[b * nb + i]).sum();
            }
        }
        g
    }

    /// The square root of a singular information matrix reproduces it, and solves the
    /// normal equations for a right-hand side in its range.
    #[test]
    fn the_square_root_of_a_singular_information_matrix_reproduces_it() {
        // S = B B^T with B 4 x 2 (rank 2), unit diagonal after scaling
        let b = Mat::from_fn(4, 2, |i, j| ((i * 3 + j * 5) as f64 * 0.7).sin() + 0.1);
        let raw = &b * b.transpose();
        let ds: Vec<f64> = vec![2.0, 0.5, 3.0, 1.0];
        let s = Mat::from_fn(4, 4, |i, j| {
            raw[(i, j)] / (raw[(i, i)] * raw[(j, j)]).sqrt()
        });
        let jtj = Mat::from_fn(4, 4, |i, j| ds[i] * s[(i, j)] * ds[j]);
        // a right-hand side in the range: J^T r = J^T J x
        let x = [0.3, -1.0, 0.2, 0.7];
        let g: Vec<f64> = (0..4)
            .map(|i| (0..4).map(|j| jtj[(i, j)] * x[j]).sum())
            .collect();
        let mut r = vec![0.0; 25];
        let z = super::square_root_factor(&s, &ds, &g, &mut r).unwrap();
        for i in 0..4 {
            for j in 0..4 {
                let rtr: f64 = (0..4).map(|k| r[i * 5 + k] * r[j * 5 + k]).sum();
                assert!(
                    (rtr - jtj[(i, j)]).abs() < 1e-12 * 10.0,
                    "({i},{j}) {rtr} vs {}",
                    jtj[(i, j)]
                );
            }
            let rtz: f64 = (0..4).map(|k| r[i * 5 + k] * z[k]).sum();
            assert!((rtz - g[i]).abs() < 1e-10, "{i}: {rtz} vs {}", g[i]);
            for k in i + 1..4 {
                assert_eq!(r[i * 5 + k], 0.0, "not upper triangular");
            }
        }
    }

    /// The shared-weight evaluation and Jacobian equal the per-entry ones, on noisy
    /// data away from the optimum (a 3 x 2 plant with pairs, a real pole, a rigid body,
    /// a feedthrough, a crosstalk and a delay; weights proportional per entry).
    #[test]
    fn shared_weights_give_the_per_entry_cost_coefficients_and_information() {
        for (const_num, delay, crosstalk) in [(false, true, false), (true, false, true)] {
            let (ny, nu) = (3, 2);
            let mut mm = ModalModel::new(ny, nu);
            for (q, (f, z)) in [(80.0, 0.02), (230.0, 0.01), (610.0, 0.005)]
                .iter()
                .enumerate()
            {
                mm.pairs.push(PolePair::from_f_zeta(
                    *f,
                    *z,
                    faer::Mat::from_fn(ny, nu, |i, j| {
                        let re = if const_num {
                            0.0
                        } else {
                            0.2 * (i as f64 - j as f64)
                        };
                        C64::new(re, -1.0 - (i + 2 * j + q) as f64 * 0.3)
                    }),
                ));
            }
            mm.real_poles.push(RealPole {
                pole: -1500.0,
                residue: faer::Mat::from_fn(ny, nu, |i, j| 40.0 + (i + j) as f64),
            });
            mm.rigid = vec![faer::Mat::from_fn(ny, nu, |i, j| {
                1e3 * (1.0 + (i * j) as f64)
            })];
            mm.feedthrough = faer::Mat::from_fn(ny, nu, |i, j| 1e-4 * (i as f64 - j as f64));
            let mut fm = FrfModel::new(mm);
            fm.factors.delay_s = 1e-4;
            fm.factors.delay_fitted = delay;
            if crosstalk {
                fm.factors.crosstalk = Some(faer::Mat::from_fn(ny, nu, |i, _| 1e-3 * i as f64));
            }
            let omega: Vec<f64> = (1..300)
                .map(|k| 2.0 * std::f64::consts::PI * 3.0 * k as f64)
                .collect();
            let m = ny * nu;
            // deterministic "noise" and weights proportional per entry
            let mut g = fm.freq_response(&omega).unwrap().values;
            for (i, v) in g.iter_mut().enumerate() {
                let t = i as f64;
                *v += C64::new((t * 0.7).sin(), (t * 1.3).cos()) * 1e-3 * v.norm();
            }
            let sw: Vec<f64> = (0..g.len())
                .map(|i| {
                    let (k, e) = (i / m, i % m);
                    (1.0 + e as f64) * (1.0 + (k as f64 * 0.01).sin().abs())
                })
                .collect();
            let lay = Layout {
                ny,
                nu,
                n_pairs: 3,
                n_real: 1,
                n_rigid: 1,
                feedthrough: true,
                crosstalk,
                delay,
                dynamics: vec![],
                const_num,
            };
            let shared = Problem::new(
                lay.clone(),
                omega.clone(),
                g.clone(),
                sw.clone(),
                fm.clone(),
            );
            assert!(shared.is_shared());
            let plain = Problem::new(lay, omega, g, sw, fm.clone()).per_entry();
            // a point away from the optimum
            let mut theta = Vec::new();
            for p in &fm.modal.pairs {
                theta.extend([p.pole.re * 1.1, p.pole.im * 1.002]);
            }
            theta.push(-1400.0);
            if delay {
                theta.push(1.2e-4);
            }
            let (e1, e2) = (
                shared.evaluate(&theta).unwrap(),
                plain.evaluate(&theta).unwrap(),
            );
            assert!(
                (e1.cost - e2.cost).abs() <= 1e-9 * e2.cost,
                "{} vs {}",
                e1.cost,
                e2.cost
            );
            let cmax = e2.coef.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            for (a, b) in e1.coef.iter().zip(&e2.coef) {
                assert!((a - b).abs() <= 1e-8 * cmax, "{a} vs {b}");
            }
            let n = theta.len();
            let nb = n + 1;
            let (r1, v1) = shared
                .jacobian_shared(shared.shared.as_ref().unwrap(), &theta, &e1)
                .unwrap();
            let (r2, v2) = plain.jacobian_r(&theta, &e2);
            let (g1, g2) = (gram_of(&r1, nb), gram_of(&r2, nb));
            for a in 0..nb {
                for b in 0..nb {
                    let scale = (g2[a * nb + a] * g2[b * nb + b]).sqrt();
                    assert!(
                        (g1[a * nb + b] - g2[a * nb + b]).abs() <= 1e-7 * scale,
                        "{const_num} {delay} ({a},{b}): {:.6e} vs {:.6e}",
                        g1[a * nb + b],
                        g2[a * nb + b]
                    );
                }
            }
            for (a, b) in v1.iter().zip(&v2) {
                assert!((a - b).abs() <= 1e-8 * b, "vnorm {a} vs {b}");
            }
        }
    }
}
