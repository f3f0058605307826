//! Frequency response of a state-space model at many points after one orthogonal
//! reduction of `A` to upper Hessenberg form.
//!
//! The method is Laub's (A. J. Laub, "Efficient multivariable frequency response
//! computations", IEEE Trans. Automat. Control 26(2), 1981): with `H = Q^T A Q` upper
//! Hessenberg (Householder reflections, Golub & Van Loan, *Matrix Computations*, 4th ed.,
//! Alg. 7.4.2), `B~ = Q^T B` and `C~ = C Q`,
//!
//! `G(x) = C (x I - A)^{-1} B + D = C~ (x I - H)^{-1} B~ + D`,
//!
//! and `x I - H` is again upper Hessenberg, so its LU factorization with partial
//! (adjacent-row) pivoting costs `O(n^2)` per point instead of `O(n^3)`, and so does each
//! right-hand side. No eigendecomposition is involved, so defective `A` (double
//! integrators, Jordan blocks) is handled exactly like any other matrix. The smaller of
//! `ny` and `nu` decides which side is solved for: `(xI - H) X = B~` column by column when
//! `nu <= ny`, or `Y (xI - H) = C~` row by row (with the same factors) otherwise.

use crate::{RealizeError, StateSpace, C64};

/// A state-space model reduced to upper Hessenberg form, ready for repeated evaluation of
/// `C~ (x I - H)^{-1} B~ + D` at arbitrary complex points `x`.
#[derive(Debug, Clone, PartialEq)]
pub struct HessenbergForm {
    n: usize,
    ny: usize,
    nu: usize,
    /// `H = Q^T A Q`, row-major, `n x n` (zero below the first subdiagonal).
    h: Vec<f64>,
    /// `B~^T = B^T Q`, row-major, `nu x n` (column `j` of `B~` contiguous).
    bt: Vec<f64>,
    /// `C~ = C Q`, row-major, `ny x n`.
    c: Vec<f64>,
    /// `D`, column-major, `ny x nu`.
    d: Vec<f64>,
    /// Infinity norm of `H` (scale for the pivot test).
    h_norm: f64,
}

/// Reusable per-point work space for [`HessenbergForm::eval_into`]. Complex arrays are
/// stored as separate real and imaginary parts so the inner loops vectorize.
#[derive(Debug, Clone, Default)]
pub(crate) struct HessenbergWork {
    /// The LU factors of `x I - H`, row-major, real parts.
    m_re: Vec<f64>,
    /// Imaginary parts of the factors.
    m_im: Vec<f64>,
    /// Inverse pivots `1 / U[k][k]`.
    inv_piv: Vec<C64>,
    /// Row multipliers of the elimination.
    mult: Vec<C64>,
    /// Whether rows `k` and `k + 1` were swapped at step `k`.
    swap: Vec<bool>,
    /// All right-hand sides, one after another (`n` entries each), real parts.
    x_re: Vec<f64>,
    /// Imaginary parts of the right-hand sides.
    x_im: Vec<f64>,
}

/// Why a point could not be evaluated (internal; mapped to [`RealizeError::AtPole`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Singular;

impl HessenbergForm {
    /// Reduces `A` of `ss` to upper Hessenberg form by Householder similarity
    /// transformations and applies them to `B` and `C`. Fails when `ss` does not pass
    /// [`StateSpace::validate`].
    pub fn new(ss: &StateSpace) -> Result<Self, RealizeError> {
        ss.validate()?;
        let n = ss.n_states();
        let (ny, nu) = (ss.ny(), ss.nu());
        let mut h: Vec<f64> = (0..n * n).map(|idx| ss.a[(idx / n, idx % n)]).collect();
        let mut b: Vec<f64> = (0..n * nu).map(|idx| ss.b[(idx / nu, idx % nu)]).collect();
        let mut c: Vec<f64> = (0..ny * n).map(|idx| ss.c[(idx / n, idx % n)]).collect();
        let d: Vec<f64> = (0..ny * nu).map(|idx| ss.d[(idx % ny, idx / ny)]).collect();

        let mut v = vec![0.0; n];
        let mut tmp = vec![0.0; n.max(nu).max(ny)];
        for k in 0..n.saturating_sub(2) {
            // Householder vector annihilating h[k+2.., k].
            let len = n - k - 1;
            let x = |i: usize| h[(k + 1 + i) * n + k];
            let sigma: f64 = {
                let scale = (0..len).fold(0.0f64, |m, i| m.max(x(i).abs()));
                if scale == 0.0 {
                    0.0
                } else {
                    scale
                        * (0..len)
                            .map(|i| (x(i) / scale) * (x(i) / scale))
                            .sum::<f64>()
                            .sqrt()
                }
            };
            if sigma == 0.0 {
                continue;
            }
            let x0 = x(0);
            let alpha = if x0 >= 0.0 { -sigma } else { sigma };
            for i in 0..len {
                v[i] = x(i);
            }
            v[0] -= alpha;
            let vtv: f64 = v[..len].iter().map(|t| t * t).sum();
            if vtv == 0.0 {
                continue;
            }
            let beta = 2.0 / vtv;
            let v = &v[..len];
            // Left: rows k+1.., columns k.. of H.
            for j in k..n {
                let mut s = 0.0;
                for i in 0..len {
                    s += v[i] * h[(k + 1 + i) * n + j];
                }
                let s = beta * s;
                for i in 0..len {
                    h[(k + 1 + i) * n + j] -= s * v[i];
                }
            }
            // Right: all rows, columns k+1.. of H.
            for r in 0..n {
                let row = &mut h[r * n + k + 1..r * n + n];
                let s = beta * row.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
                for (a, vi) in row.iter_mut().zip(v) {
                    *a -= s * vi;
                }
            }
            h[(k + 1) * n + k] = alpha;
            for i in 1..len {
                h[(k + 1 + i) * n + k] = 0.0;
            }
            // B~ = Q^T B: rows k+1..
            tmp[..nu].fill(0.0);
            for i in 0..len {
                for j in 0..nu {
                    tmp[j] += v[i] * b[(k + 1 + i) * nu + j];
                }
            }
            for i in 0..len {
                for j in 0..nu {
                    b[(k + 1 + i) * nu + j] -= beta * tmp[j] * v[i];
                }
            }
            // C~ = C Q: columns k+1..
            for r in 0..ny {
                let row = &mut c[r * n + k + 1..r * n + n];
                let s = beta * row.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
                for (a, vi) in row.iter_mut().zip(v) {
                    *a -= s * vi;
                }
            }
        }
        let h_norm = (0..n)
            .map(|i| h[i * n..(i + 1) * n].iter().map(|t| t.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let bt = (0..nu * n).map(|idx| b[(idx % n) * nu + idx / n]).collect();
        Ok(Self {
            n,
            ny,
            nu,
            h,
            bt,
            c,
            d,
            h_norm,
        })
    }

    /// `C~ = C Q` (`ny x n`): with `C = I` this is the orthogonal `Q` of `H = Q^T A Q`.
    pub fn c_tilde(&self) -> faer::Mat<f64> {
        faer::Mat::from_fn(self.ny, self.n, |i, j| self.c[i * self.n + j])
    }

    /// The states' response `Z(x) = (x I - H)^{-1} B~` (`n x nu`) at every point, in the
    /// Hessenberg coordinates `z = Q^T x`, as a grid with `n` "outputs": the model's
    /// response is `C~ Z(x) + D`. A least squares whose regressor is `C (x I - A)^{-1}`
    /// can use `Z^T` and solve for `Q^T B` instead: no `n x n` product per point.
    /// Fails with [`RealizeError::AtPole`] at a pole (`omega` reports `Im x`).
    pub fn states_at(&self, points: &[C64]) -> Result<crate::ResponseGrid, RealizeError> {
        grid_of(
            self,
            points.iter().copied(),
            |k| points[k].im,
            (self.n, self.nu),
            HessenbergForm::states_into,
        )
    }

    /// Number of states.
    pub fn n_states(&self) -> usize {
        self.n
    }

    /// `H[(i, j)]` of the Hessenberg form (for tests and diagnostics).
    pub fn h(&self, i: usize, j: usize) -> f64 {
        self.h[i * self.n + j]
    }

    /// `vec(C~ (x I - H)^{-1} B~ + D)` (column-major, length `ny * nu`) into `out`.
    /// Fails when `x I - H` is singular to working precision (a pivot of the LU
    /// factorization below `eps (|x| + ||H||_inf)`) or the result is not finite, i.e. when
    /// `x` is (numerically) a pole.
    pub(crate) fn eval_into(
        &self,
        x: C64,
        work: &mut HessenbergWork,
        out: &mut [C64],
    ) -> Result<(), Singular> {
        let (n, ny, nu) = (self.n, self.ny, self.nu);
        debug_assert_eq!(out.len(), ny * nu);
        for (o, &dv) in out.iter_mut().zip(&self.d) {
            *o = C64::new(dv, 0.0);
        }
        if n == 0 || ny == 0 || nu == 0 {
            return Ok(());
        }
        self.factor(x, work)?;
        if nu <= ny {
            // Columns: (xI - H) X = B~, then G += C~ X.
            self.solve_columns(work);
            let (xr_all, xi_all) = (&work.x_re, &work.x_im);
            for j in 0..nu {
                let (xr, xi) = (&xr_all[j * n..(j + 1) * n], &xi_all[j * n..(j + 1) * n]);
                for i in 0..ny {
                    let crow = &self.c[i * n..(i + 1) * n];
                    let (mut sr, mut si) = (0.0, 0.0);
                    for q in 0..n {
                        sr += crow[q] * xr[q];
                        si += crow[q] * xi[q];
                    }
                    out[j * ny + i] += C64::new(sr, si);
                }
            }
        } else {
            // Rows: Y (xI - H) = C~, i.e. Y = (C~ U^-1) E, then G += Y B~.
            let HessenbergWork {
                m_re,
                m_im,
                inv_piv,
                mult,
                swap,
                x_re,
                x_im,
            } = work;
            x_re.clear();
            x_re.extend_from_slice(&self.c);
            x_im.clear();
            x_im.resize(ny * n, 0.0);
            for i in 0..ny {
                let (yr, yi) = (&mut x_re[i * n..(i + 1) * n], &mut x_im[i * n..(i + 1) * n]);
                // w U = c (forward, row-oriented axpy).
                for k in 0..n {
                    let w = C64::new(yr[k], yi[k]) * inv_piv[k];
                    yr[k] = w.re;
                    yi[k] = w.im;
                    let (ur, ui) = (
                        &m_re[k * n + k + 1..(k + 1) * n],
                        &m_im[k * n + k + 1..(k + 1) * n],
                    );
                    let (vr, vi) = (&mut yr[k + 1..], &mut yi[k + 1..]);
                    for q in 0..ur.len() {
                        vr[q] -= w.re * ur[q] - w.im * ui[q];
                        vi[q] -= w.re * ui[q] + w.im * ur[q];
                    }
                }
                // y = w E_{n-2} ... E_0.
                for k in (0..n - 1).rev() {
                    let l = mult[k];
                    let (tr, ti) = (yr[k + 1], yi[k + 1]);
                    yr[k] -= l.re * tr - l.im * ti;
                    yi[k] -= l.re * ti + l.im * tr;
                    if swap[k] {
                        yr.swap(k, k + 1);
                        yi.swap(k, k + 1);
                    }
                }
                for j in 0..nu {
                    let bcol = &self.bt[j * n..(j + 1) * n];
                    let (mut sr, mut si) = (0.0, 0.0);
                    for q in 0..n {
                        sr += yr[q] * bcol[q];
                        si += yi[q] * bcol[q];
                    }
                    out[j * ny + i] += C64::new(sr, si);
                }
            }
        }
        if out.iter().all(|v| v.re.is_finite() && v.im.is_finite()) {
            Ok(())
        } else {
            Err(Singular)
        }
    }

    /// `(x I - H)^{-1} B~` (`n x nu`, column-major) into `out`: the response of the
    /// states in the Hessenberg coordinates `z = Q^T x` (so that `G(x) = C~ Z + D`).
    /// Fails as [`eval_into`](Self::eval_into) does at a pole.
    pub(crate) fn states_into(
        &self,
        x: C64,
        work: &mut HessenbergWork,
        out: &mut [C64],
    ) -> Result<(), Singular> {
        let n = self.n;
        debug_assert_eq!(out.len(), n * self.nu);
        if n == 0 || self.nu == 0 {
            return Ok(());
        }
        self.factor(x, work)?;
        self.solve_columns(work);
        for (o, (&re, &im)) in out.iter_mut().zip(work.x_re.iter().zip(&work.x_im)) {
            *o = C64::new(re, im);
        }
        if out.iter().all(|v| v.re.is_finite() && v.im.is_finite()) {
            Ok(())
        } else {
            Err(Singular)
        }
    }

    /// Solves `(x I - H) X = B~` with the factors in `work` (from [`factor`](Self::factor)),
    /// column after column, into `work.x_re` / `work.x_im` (`n` entries per column).
    fn solve_columns(&self, work: &mut HessenbergWork) {
        let (n, nu) = (self.n, self.nu);
        let HessenbergWork {
            m_re,
            m_im,
            inv_piv,
            mult,
            swap,
            x_re,
            x_im,
        } = work;
        x_re.clear();
        x_re.extend_from_slice(&self.bt);
        x_im.clear();
        x_im.resize(nu * n, 0.0);
        for j in 0..nu {
            let (xr, xi) = (&mut x_re[j * n..(j + 1) * n], &mut x_im[j * n..(j + 1) * n]);
            for k in 0..n - 1 {
                if swap[k] {
                    xr.swap(k, k + 1);
                    xi.swap(k, k + 1);
                }
                let l = mult[k];
                let (tr, ti) = (xr[k], xi[k]);
                xr[k + 1] -= l.re * tr - l.im * ti;
                xi[k + 1] -= l.re * ti + l.im * tr;
            }
            for k in (0..n).rev() {
                let (ur, ui) = (
                    &m_re[k * n + k + 1..(k + 1) * n],
                    &m_im[k * n + k + 1..(k + 1) * n],
                );
                let (vr, vi) = (&xr[k + 1..], &xi[k + 1..]);
                let mut sr = 0.0;
                let mut si = 0.0;
                for q in 0..ur.len() {
                    sr += ur[q] * vr[q] - ui[q] * vi[q];
                    si += ur[q] * vi[q] + ui[q] * vr[q];
                }
                let t = C64::new(xr[k] - sr, xi[k] - si) * inv_piv[k];
                xr[k] = t.re;
                xi[k] = t.im;
            }
        }
    }

    /// LU factorization of `x I - H` with adjacent-row partial pivoting, in `work`.
    fn factor(&self, x: C64, work: &mut HessenbergWork) -> Result<(), Singular> {
        let n = self.n;
        work.m_re.resize(n * n, 0.0);
        work.m_im.resize(n * n, 0.0);
        work.inv_piv.resize(n, C64::new(0.0, 0.0));
        work.mult.resize(n, C64::new(0.0, 0.0));
        work.swap.resize(n, false);
        let (m_re, m_im) = (&mut work.m_re, &mut work.m_im);
        for i in 0..n {
            let lo = i.saturating_sub(1);
            for j in lo..n {
                m_re[i * n + j] = -self.h[i * n + j];
                m_im[i * n + j] = 0.0;
            }
            m_re[i * n + i] += x.re;
            m_im[i * n + i] += x.im;
        }
        let tol = f64::EPSILON * (x.norm() + self.h_norm);
        for k in 0..n {
            let kk = k * n + k;
            if k + 1 < n {
                let k1 = (k + 1) * n + k;
                let a2 = m_re[kk] * m_re[kk] + m_im[kk] * m_im[kk];
                let b2 = m_re[k1] * m_re[k1] + m_im[k1] * m_im[k1];
                let swap = b2 > a2;
                work.swap[k] = swap;
                if swap {
                    for j in k..n {
                        m_re.swap(k * n + j, (k + 1) * n + j);
                        m_im.swap(k * n + j, (k + 1) * n + j);
                    }
                }
            }
            let p = C64::new(m_re[kk], m_im[kk]);
            let pn = p.norm();
            if pn.is_nan() || pn <= tol {
                return Err(Singular);
            }
            let ip = p.inv();
            work.inv_piv[k] = ip;
            if k + 1 < n {
                let k1 = (k + 1) * n + k;
                let l = C64::new(m_re[k1], m_im[k1]) * ip;
                work.mult[k] = l;
                m_re[k1] = 0.0;
                m_im[k1] = 0.0;
                let (top_re, bot_re) = m_re.split_at_mut((k + 1) * n);
                let (top_im, bot_im) = m_im.split_at_mut((k + 1) * n);
                let (ur, ui) = (&top_re[kk + 1..(k + 1) * n], &top_im[kk + 1..(k + 1) * n]);
                let (vr, vi) = (&mut bot_re[k + 1..n], &mut bot_im[k + 1..n]);
                for q in 0..ur.len() {
                    vr[q] -= l.re * ur[q] - l.im * ui[q];
                    vi[q] -= l.re * ui[q] + l.im * ur[q];
                }
            }
        }
        Ok(())
    }
}

/// Evaluates `hf` at every point of `points` into a grid; `omega_of(k)` is the angular
/// frequency reported when point `k` is a pole. Large grids (many points of a large
/// state) are evaluated in blocks of points on the rayon pool: the points are
/// independent.
pub(crate) fn eval_grid(
    hf: &HessenbergForm,
    points: impl ExactSizeIterator<Item = C64>,
    omega_of: impl Fn(usize) -> f64 + Sync,
) -> Result<crate::ResponseGrid, RealizeError> {
    grid_of(
        hf,
        points,
        omega_of,
        (hf.ny, hf.nu),
        HessenbergForm::eval_into,
    )
}

/// The grid of `eval(hf, x, work, out)` at every point (each an `rows x cols` matrix,
/// column-major), as [`eval_grid`] describes.
fn grid_of(
    hf: &HessenbergForm,
    points: impl ExactSizeIterator<Item = C64>,
    omega_of: impl Fn(usize) -> f64 + Sync,
    (rows, cols): (usize, usize),
    eval: impl Fn(&HessenbergForm, C64, &mut HessenbergWork, &mut [C64]) -> Result<(), Singular> + Sync,
) -> Result<crate::ResponseGrid, RealizeError> {
    let pts: Vec<C64> = points.collect();
    let mut g = crate::ResponseGrid::zeros(pts.len(), rows, cols);
    if let Some(k) = pts
        .iter()
        .position(|x| !(x.re.is_finite() && x.im.is_finite()))
    {
        return Err(RealizeError::NonFinite {
            what: format!("evaluation point {k}"),
        });
    }
    let m = rows * cols;
    // about n^2 (nu + 1) flops per point: blocks only where the work is worth a thread
    let work_per_point = hf.n * hf.n * (hf.nu + 1);
    let block = if m == 0 || work_per_point * pts.len() < PARALLEL_WORK {
        pts.len().max(1)
    } else {
        PARALLEL_POINTS
    };
    let eval_block = |(b, out): (usize, &mut [C64])| -> Result<(), RealizeError> {
        let mut work = HessenbergWork::default();
        for (i, line) in out.chunks_mut(m.max(1)).enumerate() {
            let k = b * block + i;
            eval(hf, pts[k], &mut work, line).map_err(|Singular| RealizeError::AtPole {
                point: k,
                omega: omega_of(k),
            })?;
        }
        Ok(())
    };
    if m == 0 {
        return Ok(g);
    }
    if block >= pts.len() {
        eval_block((0, &mut g.values[..]))?;
    } else {
        use rayon::prelude::*;
        g.values
            .par_chunks_mut(block * m)
            .enumerate()
            .try_for_each(eval_block)?;
    }
    Ok(g)
}

/// Work (flops) of a grid below which [`eval_grid`] stays on the calling thread.
const PARALLEL_WORK: usize = 20_000_000;
/// Points per parallel block of [`eval_grid`].
const PARALLEL_POINTS: usize = 128;
