//! From the common denominator to the model currency: poles sorted into integrators,
//! pole pairs and real poles, then the residue matrices and the feedthrough by linear
//! least squares on the data with the poles fixed.
//!
//! With distinct poles, `N_e / d` for numerators of degree `n` is exactly the span of
//! the partial fractions `1 / (s - p_i)` and a constant, so the numerator fit "given the
//! denominator" (Jue, eq. 2 with `d` fixed) and the residue fit are the same linear
//! least-squares problem; the residue form is what the currency needs and is fitted in
//! it directly (per entry, real and imaginary parts stacked, by QR; entries whose
//! weights are proportional share one QR, [`frf_data::proportional_groups`], and the
//! groups are solved in parallel). For
//! [`Hold::Zoh`] each partial fraction is replaced by its exact zero-order-hold image
//! ([`ModalModel::zoh_response`]), so the residues are those of the continuous plant.

use crate::{Prepared, SkError};
use faer::linalg::triangular_solve::solve_upper_triangular_in_place;
use faer::{Mat, Par};
use rayon::prelude::*;
use realize::{Hold, ModalModel, PolePair, RealPole, C64};

/// Poles of the continuous-time model, sorted.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PoleSet {
    /// Upper poles of the complex pairs, rad/s.
    pub pairs: Vec<C64>,
    /// Real poles, rad/s (not at the origin).
    pub reals: Vec<f64>,
    /// Poles at the origin (integrators).
    pub integrators: usize,
}

impl PoleSet {
    /// Number of poles.
    pub fn order(&self) -> usize {
        2 * self.pairs.len() + self.reals.len() + self.integrators
    }
}

/// The partial-fraction regressors of `poles` at the lines (continuous, or their exact
/// zero-order-hold images), each a column of complex values; the last column is the
/// feedthrough when `feedthrough`. Column order: per pair the `Re R` then the `Im R`
/// column, per real pole one, per integrator `1/s^k` one, then the constant.
fn regressors(
    omegas: &[f64],
    poles: &PoleSet,
    hold: Hold,
    feedthrough: bool,
) -> Result<Vec<Vec<C64>>, SkError> {
    let one = |m: ModalModel| -> Result<Vec<C64>, SkError> {
        let g = match hold {
            Hold::Zoh { fs_hz } => m.zoh_response(omegas, 1.0 / fs_hz, 0.0)?,
            _ => m.freq_response(omegas)?,
        };
        Ok(g.values)
    };
    let unit = |f: &dyn Fn(&mut ModalModel)| {
        let mut m = ModalModel::new(1, 1);
        f(&mut m);
        m
    };
    let mut cols = Vec::new();
    for &p in &poles.pairs {
        for r in [C64::new(1.0, 0.0), C64::new(0.0, 1.0)] {
            cols.push(one(unit(&|m| {
                m.pairs.push(PolePair {
                    pole: p,
                    residue: Mat::from_fn(1, 1, |_, _| r),
                })
            }))?);
        }
    }
    for &p in &poles.reals {
        cols.push(one(unit(&|m| {
            m.real_poles.push(RealPole {
                pole: p,
                residue: Mat::from_fn(1, 1, |_, _| 1.0),
            })
        }))?);
    }
    for k in 0..poles.integrators {
        cols.push(one(unit(&|m| {
            m.rigid = (0..=k)
                .map(|i| Mat::from_fn(1, 1, |_, _| if i == k { 1.0 } else { 0.0 }))
                .collect()
        }))?);
    }
    if feedthrough {
        cols.push(vec![C64::new(1.0, 0.0); omegas.len()]);
    }
    Ok(cols)
}

/// One group's fit: the coefficients of each of its entries, and its weighted cost.
type GroupFit = (Vec<(usize, Vec<f64>)>, f64);

/// The residue matrices (and the feedthrough when `feedthrough`) of the model with the
/// given `poles` that fits `data` best in the weighted least-squares sense, and its
/// weighted cost `sum w |G - P|^2`.
///
/// Fails when the regressors are not finite (a pole on a measured line) or when there
/// are more regressors than real equations per entry.
pub fn fit_residues(
    data: &Prepared,
    poles: &PoleSet,
    hold: Hold,
    feedthrough: bool,
) -> Result<(ModalModel, f64), SkError> {
    let l = data.n_lines();
    let (ny, nu, m) = (data.ny, data.nu, data.m());
    let cols = regressors(&data.omegas, poles, hold, feedthrough)?;
    let p = cols.len();
    if 2 * l < p {
        return Err(SkError::OrderExceedsData {
            order: poles.order(),
            lines: l,
            max: l.saturating_sub(2),
        });
    }
    if cols
        .iter()
        .flatten()
        .any(|v| !(v.re.is_finite() && v.im.is_finite()))
    {
        return Err(SkError::numerical(
            "residue fit",
            "a partial fraction is not finite on the lines (a pole on the measured axis)",
        ));
    }
    // entries whose weights are proportional share their regressor up to a scale that
    // does not change the solution: one QR per group, the groups in parallel
    let groups = frf_data::proportional_groups(&data.w, m, 1e-12);
    let solved: Vec<GroupFit> = groups
        .par_iter()
        .map(|grp| {
            let ne = grp.entries.len();
            // [A | B]: the regressors, then the entries' data; the QR of the whole gives
            // the solutions (R_11 x = R_12) and the residual norms (the part of each
            // data column below row p of R) in one factorisation
            let mut a = Mat::<f64>::zeros(2 * l, p + ne);
            let q: Vec<f64> = grp.line_weights.iter().map(|w| w.sqrt()).collect();
            for (j, c) in cols.iter().enumerate() {
                for k in 0..l {
                    a[(k, j)] = q[k] * c[k].re;
                    a[(l + k, j)] = q[k] * c[k].im;
                }
            }
            for (i, &e) in grp.entries.iter().enumerate() {
                for k in 0..l {
                    let g = data.g[k * m + e] * q[k];
                    a[(k, p + i)] = g.re;
                    a[(l + k, p + i)] = g.im;
                }
            }
            // column scaling keeps the QR well scaled whatever the residue sizes
            let scale: Vec<f64> = (0..p)
                .map(|j| {
                    let n = a.col(j).norm_l2();
                    if n > 0.0 {
                        1.0 / n
                    } else {
                        1.0
                    }
                })
                .collect();
            for (j, &sc) in scale.iter().enumerate() {
                a.col_mut(j).iter_mut().for_each(|v| *v *= sc);
            }
            crate::qr::r_in_place(a.as_mut());
            let r11 = Mat::<f64>::from_fn(p, p, |i, j| if j >= i { a[(i, j)] } else { 0.0 });
            let mut x = Mat::<f64>::from_fn(p, ne, |i, j| a[(i, p + j)]);
            solve_upper_triangular_in_place(r11.as_ref(), x.as_mut(), Par::Seq);
            // the weighted residual of entry i: rows p..p+i of its column of R, in the
            // weights of the entry (the group's line weights times the entry's scale)
            let mut cost = 0.0;
            let mut out = Vec::with_capacity(ne);
            for (i, &e) in grp.entries.iter().enumerate() {
                let rows = p..(p + i + 1).min(2 * l);
                let res2: f64 = rows.map(|r| a[(r, p + i)] * a[(r, p + i)]).sum();
                cost += grp.scales[i] * res2;
                out.push((e, (0..p).map(|j| x[(j, i)] * scale[j]).collect()));
            }
            (out, cost)
        })
        .collect();
    let mut coef = vec![vec![0.0; p]; m];
    let mut cost = 0.0;
    for (out, c) in solved {
        cost += c;
        for (e, x) in out {
            coef[e] = x;
        }
    }
    if coef.iter().flatten().any(|c| !c.is_finite()) {
        return Err(SkError::numerical(
            "residue fit",
            "non-finite residues (singular regressors)",
        ));
    }
    let mut model = ModalModel::new(ny, nu);
    let at = |e: usize, j: usize| coef[e][j];
    let entry = |i: usize, jj: usize| jj * ny + i;
    let mut col = 0;
    for &pole in &poles.pairs {
        let residue = Mat::from_fn(ny, nu, |i, j| {
            let e = entry(i, j);
            C64::new(at(e, col), at(e, col + 1))
        });
        model.pairs.push(PolePair { pole, residue });
        col += 2;
    }
    for &pole in &poles.reals {
        let residue = Mat::from_fn(ny, nu, |i, j| at(entry(i, j), col));
        model.real_poles.push(RealPole { pole, residue });
        col += 1;
    }
    for _ in 0..poles.integrators {
        let c = col;
        model
            .rigid
            .push(Mat::from_fn(ny, nu, |i, j| at(entry(i, j), c)));
        col += 1;
    }
    if feedthrough {
        model.feedthrough = Mat::from_fn(ny, nu, |i, j| at(entry(i, j), col));
    }
    Ok((model, cost))
}
