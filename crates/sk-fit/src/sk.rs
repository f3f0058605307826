//! The Sanathanan-Koerner iterations for one common denominator of a MIMO FRF.
//!
//! Jue, eq. (2) and (4), McKelvey eq. (36)-(38): with the denominator `d_i` of the
//! previous iteration fixed, the weighted equation error
//!
//! `e_ke(theta) = q_ke (G_ke d(x_k) - N_e(x_k)) / |d_i(x_k)|^g`
//!
//! is linear in the coefficients of `d` (shared by every entry `e`) and of the
//! numerators `N_e` (one per entry), with `x_k` the basis variable at line `k`,
//! `q_ke = sqrt(w_ke)` the data weight and `g = 1` (classic SK) or `g = 1/2` (Jue's
//! default, section 2.2.3). The first iteration (`d_0 = 1`) is Levy's linearised fit.
//! Real coefficients: every complex equation gives its real and imaginary part as two
//! real rows.
//!
//! The polynomials are expressed, in each iteration, in the basis of
//! [`poly_basis::Orthogonal`] polynomials of the basis variable that are orthonormal on
//! the lines in the weight of the denominator columns, `sum_e w_ke |G_ke|^2 / |d_i|^2g`.
//! The powers of even a well-conditioned variable fail at high order for lightly damped
//! systems: a denominator with 36 roots near the unit circle varies by 1e13 over the
//! lines, its values at the resonances cancel to rounding, and the Levy problem of the
//! wafer stage then has three singular values at rounding level on noise-free data (the
//! SK iterations diverge). In the orthonormal basis the same fit reaches a median error
//! of 1.6e-9 on noise-free data. The roots come from the basis recurrence
//! ([`poly_basis::Orthogonal::roots`]), never from monomial coefficients.
//!
//! The numerators are eliminated per entry (variable projection): the QR factorisation
//! of the entry's block `[A_N | A_D]` (2 L rows) leaves in its `R_22` block the
//! denominator columns projected onto the orthogonal complement of the numerator
//! columns, reduced to `n + 1` rows. The `R_22` blocks of all entries are stacked and
//! the denominator is the right singular vector of the smallest singular value (the
//! normalisation `||d|| = 1`). The cost of one iteration is linear in the entries and
//! the lines: `m` QRs of `2 L x 2 (n + 1)` (in parallel over the entries, each
//! sequential) and one SVD of `m (n + 1) x (n + 1)`. With per-entry weights (a measured
//! variance per entry) the numerator columns differ from entry to entry and nothing is
//! shared; the iterations are what can be saved: [`sk_denominator_from`] starts from a
//! previous denominator (another order, or the same order on a subset of the lines).

use crate::{Prepared, SkError};
use faer::Mat;
use frf_data::Convergence;
use poly_basis::{Basis, Orthogonal};
use rayon::prelude::*;
use realize::C64;
use serde::{Deserialize, Serialize};

/// The SK weight on the previous denominator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SkWeight {
    /// `1 / |d_i|`: the classic SK iteration, whose fixed point approximates the
    /// weighted output-error criterion (the default).
    #[default]
    Classic,
    /// `1 / sqrt|d_i|`: Jue's default (section 2.2.3), a more uniform fit that
    /// de-emphasises the lightly damped modes.
    Sqrt,
}

impl SkWeight {
    fn exponent(self) -> f64 {
        match self {
            SkWeight::Classic => 1.0,
            SkWeight::Sqrt => 0.5,
        }
    }
}

/// Iteration settings of [`sk_denominator`], with documented defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct SkIterConfig {
    /// The SK weight. Default: [`SkWeight::Classic`].
    pub weight: SkWeight,
    /// Iterations after the Levy start, at most. Default: 30.
    pub max_iter: usize,
    /// Stop when the relative change of the SK cost between two iterations,
    /// `|V_i - V_(i-1)| / V_i`, falls below this (the "relative cost" rule of Jue
    /// section 2.2.3, which the thesis does not define further). Default: 1e-6.
    pub cost_tol: f64,
    /// Stop as converged when the SK cost is below this (an exact fit of noise-free
    /// data, where the relative change is rounding noise). Default: 1e-22.
    pub exact_tol: f64,
}

impl Default for SkIterConfig {
    fn default() -> Self {
        Self {
            weight: SkWeight::Classic,
            max_iter: 30,
            cost_tol: 1e-6,
            exact_tol: 1e-22,
        }
    }
}

/// The common denominator found by [`sk_denominator`].
#[derive(Debug, Clone)]
pub struct SkDenominator {
    /// Coefficients of `d(x)` in the orthonormal basis of the last iteration,
    /// `||d|| = 1`.
    pub den: Vec<f64>,
    /// The roots of `d` in the basis variable `x`.
    pub roots: Vec<C64>,
    /// The SK cost after the Levy start and each iteration: the sum of the squared
    /// weighted equation errors (the smallest squared singular value) relative to the
    /// same weighted sum of `|G d|^2`, so that it does not depend on the scale of the
    /// weights `1/|d_prev|` and is 0 for an exact fit.
    pub cost_history: Vec<f64>,
    /// SK iterations after the Levy start.
    pub iterations: usize,
    /// Why the iterations stopped.
    pub convergence: Convergence,
    /// Condition of the reduced denominator problem of the last iteration:
    /// `sigma_max / sigma_(n)` (the second smallest singular value: how well the
    /// minimiser is separated).
    pub ls_condition: f64,
}

/// The `R_22` block of the QR factorisation of entry `e`'s `[A_N | A_D]`: its
/// denominator columns projected onto the orthogonal complement of its numerator
/// columns (`None` when every weight of the entry is zero). `cols[j][k]` is the basis
/// polynomial `q_j` at line `k` (column after column: the block is filled column by
/// column, contiguously).
fn reduced_block(data: &Prepared, cols: &[Vec<C64>], skw: &[f64], e: usize) -> Option<Mat<f64>> {
    let l = data.n_lines();
    let m = data.m();
    let nc = cols.len();
    let q: Vec<f64> = (0..l).map(|k| data.w[k * m + e].sqrt() * skw[k]).collect();
    if !q.iter().any(|&v| v > 0.0) {
        return None;
    }
    let g: Vec<C64> = (0..l).map(|k| data.g[k * m + e] * q[k]).collect();
    let mut block = Mat::<f64>::zeros(2 * l, 2 * nc);
    for (j, p) in cols.iter().enumerate() {
        let col = block.col_mut(j).try_as_col_major_mut().expect("contiguous");
        let col = col.as_slice_mut();
        let (re, im) = col.split_at_mut(l);
        for k in 0..l {
            let a = p[k] * q[k];
            re[k] = a.re;
            im[k] = a.im;
        }
        let col = block
            .col_mut(nc + j)
            .try_as_col_major_mut()
            .expect("contiguous");
        let col = col.as_slice_mut();
        let (re, im) = col.split_at_mut(l);
        for k in 0..l {
            let b = -(p[k] * g[k]);
            re[k] = b.re;
            im[k] = b.im;
        }
    }
    crate::qr::r_in_place(block.as_mut());
    Some(Mat::from_fn(nc, nc, |i, j| {
        if j >= i {
            block[(nc + i, nc + j)]
        } else {
            0.0
        }
    }))
}

/// SK iterations for the order-`n` common denominator of `data` in `basis` (see the
/// module documentation), from Levy's start.
pub fn sk_denominator(
    data: &Prepared,
    basis: &Basis,
    n: usize,
    cfg: &SkIterConfig,
) -> Result<SkDenominator, SkError> {
    sk_denominator_from(data, basis, n, cfg, None)
}

/// [`sk_denominator`] warm-started: the first iteration is weighted by a previous
/// denominator given by its roots `start` in the basis variable (`|d_0(x_k)| =
/// prod_i |x_k - r_i|`, up to a scale that the weights do not see) instead of Levy's
/// `d_0 = 1`. The SK iteration (Jue eq. (4)) only needs `d_(i-1)` on the lines, so a
/// denominator of another order (the previous order of a sweep) or fitted on other
/// lines (a subset) is a valid start; from a good start the iterations converge in a
/// few steps instead of climbing out of Levy's bias towards the lightly damped peaks.
/// `None` (or no roots) is Levy's start.
pub fn sk_denominator_from(
    data: &Prepared,
    basis: &Basis,
    n: usize,
    cfg: &SkIterConfig,
    start: Option<&[C64]>,
) -> Result<SkDenominator, SkError> {
    let l = data.n_lines();
    let m = data.m();
    let nc = n + 1;
    if l < n + 2 {
        return Err(SkError::OrderExceedsData {
            order: n,
            lines: l,
            max: l.saturating_sub(2),
        });
    }
    let x: Vec<C64> = data.omegas.iter().map(|&w| basis.at(w)).collect();
    // sum_e w_ke |G_ke|^2: the basis weight of the Levy start
    let mut gw: Vec<f64> = (0..l)
        .map(|k| {
            (0..m)
                .map(|e| data.w[k * m + e] * data.g[k * m + e].norm_sqr())
                .sum()
        })
        .collect();
    // only relative weights matter: scaled to a largest value of 1
    let gmax = gw.iter().copied().fold(0.0, f64::max);
    if !(gmax > 0.0 && gmax.is_finite()) {
        return Err(SkError::numerical(
            "SK iteration",
            "the weighted data are all zero or not finite: nothing to fit",
        ));
    }
    gw.iter_mut().for_each(|g| *g /= gmax);
    let gamma = cfg.weight.exponent();
    // |d_prev(x_k)|^-gamma, 1 for the Levy start
    let mut skw = vec![1.0; l];
    if let Some(roots) = start.filter(|r| !r.is_empty()) {
        // -gamma log |d_0(x_k)| (the product of up to 80 factors is summed in logs),
        // then scaled to a largest weight of 1 (only relative weights matter)
        let logw: Vec<f64> = x
            .iter()
            .map(|xk| -gamma * roots.iter().map(|r| (xk - r).norm().ln()).sum::<f64>())
            .collect();
        if logw.iter().any(|v| !v.is_finite()) {
            return Err(SkError::numerical(
                "SK warm start",
                "the start denominator vanishes on a line (a root on the measured axis) or \
                 has a root that is not finite",
            ));
        }
        let top = logw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        for (w, v) in skw.iter_mut().zip(&logw) {
            *w = (v - top).exp();
        }
    }
    let mut stacked = Mat::<f64>::zeros(m * nc, nc);
    let mut history = Vec::new();
    let mut den = vec![0.0; nc];
    let mut ortho = None;
    let mut ls_condition = f64::NAN;
    let mut convergence = Convergence::MaxIterations {
        limit: cfg.max_iter,
    };
    let mut iterations = 0;
    for it in 0..=cfg.max_iter {
        // the basis orthonormal in the weight of this iteration's denominator columns
        let bw: Vec<f64> = (0..l).map(|k| gw[k] * skw[k] * skw[k]).collect();
        let ob = Orthogonal::new(&x, &bw, n)?;
        let cols: Vec<Vec<C64>> = (0..nc)
            .map(|j| (0..l).map(|k| ob.row(k)[j]).collect())
            .collect();
        let blocks: Vec<Option<Mat<f64>>> = (0..m)
            .into_par_iter()
            .map(|e| reduced_block(data, &cols, &skw, e))
            .collect();
        let mut used = 0;
        for r22 in blocks.into_iter().flatten() {
            for i in 0..nc {
                for j in 0..nc {
                    stacked[(used * nc + i, j)] = r22[(i, j)];
                }
            }
            used += 1;
        }
        if used == 0 {
            return Err(SkError::numerical(
                "SK iteration",
                "every weight is zero: nothing to fit",
            ));
        }
        let svd = stacked
            .as_ref()
            .subrows(0, used * nc)
            .thin_svd()
            .map_err(|e| SkError::numerical("SK denominator (SVD)", format!("{e:?}")))?;
        let s = svd.S().column_vector();
        let v = svd.V();
        // faer sorts singular values in non-increasing order
        let smin = s[nc - 1];
        let cost = smin * smin;
        ls_condition = if nc >= 2 && s[nc - 2] > 0.0 {
            s[0] / s[nc - 2]
        } else {
            f64::INFINITY
        };
        for j in 0..nc {
            den[j] = v[(j, nc - 1)];
        }
        if den.iter().any(|d| !d.is_finite()) || !cost.is_finite() {
            return Err(SkError::numerical(
                "SK denominator",
                format!("non-finite coefficients at iteration {it}"),
            ));
        }
        // sign: the largest coefficient positive (the same polynomial either way)
        let jmax = (0..nc)
            .max_by(|&a, &b| den[a].abs().total_cmp(&den[b].abs()))
            .unwrap_or(0);
        if den[jmax] < 0.0 {
            den.iter_mut().for_each(|d| *d = -*d);
        }
        let ob = &*ortho.insert(ob);
        // the basis is orthonormal in the weights of the denominator columns and
        // ||d|| = 1: the cost is relative to the weighted size of G d (scale-free across
        // iterations, 0 for an exact fit)
        history.push(cost);
        iterations = it;
        if it > 0 {
            if cost <= cfg.exact_tol {
                convergence = Convergence::CostTolerance {
                    relative_change: 0.0,
                };
                break;
            }
            let prev = history[history.len() - 2];
            let rel = (cost - prev).abs() / cost.max(f64::MIN_POSITIVE);
            if rel < cfg.cost_tol {
                convergence = Convergence::CostTolerance {
                    relative_change: rel,
                };
                break;
            }
        }
        // the next weights
        for k in 0..l {
            let d = ob.eval_at(&den, k).norm();
            if !(d > 0.0 && d.is_finite()) {
                return Err(SkError::numerical(
                    "SK weights",
                    format!(
                        "the denominator vanishes at line {k} ({:.6} rad/s): a pole on the \
                         measured axis",
                        data.omegas[k]
                    ),
                ));
            }
            skw[k] = d.powf(-gamma);
        }
        // only relative weights matter: scaled to a largest value of 1 (the scale of
        // d in the orthonormal basis would otherwise drift from one iteration to the next)
        let smax = skw.iter().copied().fold(0.0, f64::max);
        if !(smax.is_finite() && smax > 0.0) {
            return Err(SkError::numerical(
                "SK weights",
                format!("the weights 1/|d| are not finite at iteration {it}"),
            ));
        }
        skw.iter_mut().for_each(|w| *w /= smax);
    }
    let ob = ortho.ok_or_else(|| SkError::numerical("SK iteration", "no iteration ran"))?;
    let roots = ob.roots(&den)?;
    Ok(SkDenominator {
        den,
        roots,
        cost_history: history,
        iterations,
        convergence,
        ls_condition,
    })
}
