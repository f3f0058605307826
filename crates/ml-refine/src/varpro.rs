//! Variable projection for the model currency: the residues, the rigid body, the
//! feedthrough and the crosstalk enter each entry of `P` linearly, so for fixed poles,
//! delay and dynamics factors they are the solution of one small weighted linear
//! least-squares problem per entry; the Gauss-Newton / Levenberg-Marquardt iterations
//! run on the few nonlinear parameters only (Golub and Pereyra; the Jacobian of the
//! reduced problem in Kaufman's form, `J = (I - P_A) dA/dtheta c`).
//!
//! Each entry's linear problem `[A_e | y_e]` (rows: real and imaginary parts of every
//! line, weighted by `sqrt(2 w)`) is solved per evaluation, and `[A_e | dA_e c_e | y_e]`
//! is factorised per Jacobian: the lower-right block of its `R` is the `R` factor of
//! the projected Jacobian and residual of that entry, and the blocks of all entries are
//! merged by one more QR. The work is linear in lines and in entries. Both per-entry
//! factorisations go through the column-scaled Gram matrix where that is accurate
//! (scaled pivots above [`GRAM_MIN_PIVOT`], the evaluation with one step of iterative
//! refinement on the explicit residual: see [`crate::gram`]) and through a Householder
//! QR otherwise; on the wafer stage this makes an iteration several times cheaper than
//! the QR alone, at the same estimates. With the full Jacobian `[J_nl | blockdiag(A_e)]`, the Schur complement of
//! the linear block is exactly `sum_e J_e^T J_e`: the inverse of the merged `R^T R` is the
//! marginal covariance of the nonlinear parameters (McKelvey eq. (31)-(32) with the
//! measured variance as the fixed noise model).
//!
//! When the entries' weights are proportional (one noise level, uniform weights) and
//! no dynamics factor acts on part of the entries, every entry has the same regressor:
//! [`crate::shared`] then factorises once per group of entries instead of once per
//! entry, which is what makes large MIMO FRFs (hundreds of entries) affordable.

use crate::basis::{first_order, first_order_pair, powers, rigid_bases, zoh_ts};
use crate::gram::{gram_lstsq, gram_r, gram_r_with};
use crate::qr::{back_substitute, householder_r};
use crate::weight_groups::Shared;
use crate::C64;
use rayon::prelude::*;
use realize::{FrfModel, PolePair, RealPole};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Smallest scaled pivot of `[A_e | J_e]` for the Gram path of
/// [`Problem::jacobian_r`] (relative error of the information matrix about
/// `k eps / 1e-8`, `k` columns); a smaller one runs the QR.
const GRAM_MIN_PIVOT: f64 = 1e-4;
/// Smallest residual norm relative to the data norm of an entry for the Gram path: the
/// Gauss-Newton right-hand side from the Gram matrix has an absolute error of about
/// `k eps ||y||`, so an entry fitted closer (noise-free data near the optimum) runs
/// the QR.
const GRAM_MIN_RESIDUAL: f64 = 1e-9;

/// The column-major copy of the row-major `rows x cols` matrix `a`.
fn col_major(a: &[f64], rows: usize, cols: usize) -> Vec<f64> {
    let mut out = vec![0.0; rows * cols];
    for (i, row) in a.chunks_exact(cols).enumerate() {
        for (j, &x) in row.iter().enumerate() {
            out[j * rows + i] = x;
        }
    }
    out
}

/// How the residues of a pole pair are parametrised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidueForm {
    /// A constant real numerator per entry, `B / (s^2 + 2 zeta wn s + wn^2)` (the mode
    /// of eq. (26) of the wafer-stage paper) when every start residue is purely
    /// imaginary (which that form gives), general complex residues otherwise. The
    /// default.
    #[default]
    Auto,
    /// A complex residue per entry: `R / (s - p) + conj(R) / (s - conj p)` (2 real
    /// parameters per entry and mode).
    Complex,
    /// A real numerator per entry: `B / ((s - p)(s - conj p))` (1 real parameter per
    /// entry and mode; the residue is `B / (2 j Im p)`).
    ConstantNumerator,
}

/// The structure of the refined model: which terms it has and how they are
/// parametrised.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    pub ny: usize,
    pub nu: usize,
    pub n_pairs: usize,
    pub n_real: usize,
    pub n_rigid: usize,
    pub feedthrough: bool,
    pub crosstalk: bool,
    pub delay: bool,
    /// `(den.len(), num.len())` per dynamics factor.
    pub dynamics: Vec<(usize, usize)>,
    /// True for [`ResidueForm::ConstantNumerator`].
    pub const_num: bool,
}

impl Layout {
    pub fn m(&self) -> usize {
        self.ny * self.nu
    }
    /// Linear columns per pair.
    pub fn cpp(&self) -> usize {
        if self.const_num {
            1
        } else {
            2
        }
    }
    /// Linear columns multiplied by the scalar factor `F` (all but the crosstalk).
    pub fn n_lc(&self) -> usize {
        self.n_pairs * self.cpp() + self.n_real + self.n_rigid + usize::from(self.feedthrough)
    }
    /// Linear parameters per entry.
    pub fn n_lin(&self) -> usize {
        self.n_lc() + usize::from(self.crosstalk)
    }
    /// Nonlinear parameters.
    pub fn n_nl(&self) -> usize {
        2 * self.n_pairs
            + self.n_real
            + usize::from(self.delay)
            + self.dynamics.iter().map(|(a, b)| a + b).sum::<usize>()
    }
    /// Index of the delay in the nonlinear vector.
    pub fn delay_index(&self) -> Option<usize> {
        self.delay.then_some(2 * self.n_pairs + self.n_real)
    }
    /// Index of the first dynamics coefficient in the nonlinear vector (each factor's
    /// denominator then numerator follow, in the factors' order).
    pub fn dynamics_index(&self) -> usize {
        2 * self.n_pairs + self.n_real + usize::from(self.delay)
    }
}

/// The groups of entries with proportional weights ([`Shared::new`]) for a problem whose
/// model is `template`: they hold without dynamics factors only.
fn weight_groups(template: &FrfModel, sw: &[f64], g: &[C64], m: usize) -> Option<Arc<Shared>> {
    if template.factors.dynamics.is_empty() {
        Shared::new(sw, g, m).map(Arc::new)
    } else {
        None
    }
}

/// The refinement problem: data, weights and structure.
///
/// The data, weights and weight groups do not change with the structure: they are
/// held behind `Arc`s, so that [`Problem::with_layout`] (a mode added or dropped, the
/// delay held or freed) shares them instead of copying them (at 50 x 50 entries and
/// 4000 lines, 400 MB per copy).
pub(crate) struct Problem {
    pub lay: Layout,
    pub omega: Arc<Vec<f64>>,
    /// Data, line after line, each line `vec(G)`.
    pub g: Arc<Vec<C64>>,
    /// `sqrt(2 w)` per line and entry.
    pub sw: Arc<Vec<f64>>,
    /// The model whose known factors (hold, derivative order, dynamics targets and
    /// scales) the refined model keeps.
    pub template: FrfModel,
    pub ts: Option<f64>,
    /// Rigid-body bases, `N x n_rigid` (fixed).
    rigid: Vec<C64>,
    /// The groups of entries with proportional weights, when sharing pays and there
    /// are no dynamics factors ([`crate::shared`]).
    pub(crate) shared: Option<Arc<Shared>>,
}

/// The per-line values of the bases for one nonlinear parameter vector.
pub(crate) struct Lines {
    /// `F phi_l`, `N x n_lc`.
    pub fphi: Vec<C64>,
    /// `F d phi / d (Re p, Im p)` per pair and column: index
    /// `((k * n_pairs + q) * 2 + ab) * cpp + c`.
    pub dpair: Vec<C64>,
    /// `F d phi / d p` per real pole, `N x n_real`.
    pub dreal: Vec<C64>,
    /// Per dynamics factor and line: `(B/A, A)`, index `k * n_dyn + d`.
    dynv: Vec<(C64, C64)>,
    /// Per dynamics factor, line-major: `x^1..x^n` with `n = max(den, num)`.
    dynx: Vec<Vec<C64>>,
}

/// The cost and the linear parameters at one nonlinear parameter vector.
#[derive(Clone)]
pub(crate) struct Eval {
    /// `sum_k sum_e w |G - P|^2` (half the squared norm of the scaled residual).
    pub cost: f64,
    /// Linear parameters, `m x n_lin`, entry-major.
    pub coef: Vec<f64>,
    /// The cost of each entry.
    pub entry_cost: Vec<f64>,
    /// Per entry, the Gram matrix of `[A_e | y_e]` when the evaluation went through it
    /// (the Jacobian at the same point reuses it).
    pub gram: Vec<Option<Vec<f64>>>,
    /// On shared weights ([`crate::shared`]), the weighted residual of every group, by
    /// chunks of its entries (`2N x chunk`, the group's entry order): the Jacobian at
    /// the same point reuses it. Shared because the iteration keeps two evaluations
    /// alive.
    pub residual: Option<std::sync::Arc<Vec<Vec<faer::Mat<f64>>>>>,
}

/// A linear problem without a unique solution (a basis column of entry `entry` is in
/// the span of the others).
#[derive(Debug, Clone)]
pub(crate) struct Singular {
    pub entry: usize,
    pub column: usize,
    pub ratio: f64,
}

impl Problem {
    /// The same data and weights with another structure `lay` (a mode added or
    /// dropped, the delay held or freed) and template `template`.
    pub fn with_layout(&self, lay: Layout, template: FrfModel) -> Problem {
        // the weight groups depend on the data and weights alone: without dynamics
        // factors on either side they are this problem's (also when sharing did not pay)
        let shared = if self.template.factors.dynamics.is_empty() {
            self.shared
                .clone()
                .filter(|_| template.factors.dynamics.is_empty())
        } else {
            weight_groups(&template, &self.sw, &self.g, lay.m())
        };
        Problem::assemble(
            lay,
            Arc::clone(&self.omega),
            Arc::clone(&self.g),
            Arc::clone(&self.sw),
            template,
            shared,
        )
    }

    pub fn new(
        lay: Layout,
        omega: Vec<f64>,
        g: Vec<C64>,
        sw: Vec<f64>,
        template: FrfModel,
    ) -> Self {
        let shared = weight_groups(&template, &sw, &g, lay.m());
        Problem::assemble(
            lay,
            Arc::new(omega),
            Arc::new(g),
            Arc::new(sw),
            template,
            shared,
        )
    }

    /// The problem of `lay` on shared data, with the rigid-body bases of its layout.
    fn assemble(
        lay: Layout,
        omega: Arc<Vec<f64>>,
        g: Arc<Vec<C64>>,
        sw: Arc<Vec<f64>>,
        template: FrfModel,
        shared: Option<Arc<Shared>>,
    ) -> Self {
        let ts = zoh_ts(&template);
        let mut rigid = Vec::with_capacity(omega.len() * lay.n_rigid);
        let mut rb = Vec::new();
        for &w in omega.iter() {
            rigid_bases(lay.n_rigid, w, ts, &mut rb);
            rigid.extend_from_slice(&rb);
        }
        Self {
            lay,
            omega,
            g,
            sw,
            template,
            ts,
            rigid,
            shared,
        }
    }

    /// The same problem without the shared-weight path (tests compare the two).
    #[cfg(test)]
    pub(crate) fn per_entry(mut self) -> Self {
        self.shared = None;
        self
    }

    /// True when the shared-weight path is in use.
    #[cfg(test)]
    pub(crate) fn is_shared(&self) -> bool {
        self.shared.is_some()
    }

    pub fn n_lines(&self) -> usize {
        self.omega.len()
    }

    /// The template's factors with the delay and dynamics coefficients of `theta`.
    fn factors(&self, theta: &[f64]) -> realize::KnownFactors {
        let lay = &self.lay;
        let mut f = self.template.factors.clone();
        if let Some(i) = lay.delay_index() {
            f.delay_s = theta[i];
        }
        let mut off = lay.dynamics_index();
        for d in &mut f.dynamics {
            for v in d.den.iter_mut().chain(d.num.iter_mut()) {
                *v = theta[off];
                off += 1;
            }
        }
        f
    }

    /// `F phi`, `F d phi / d (Re p, Im p)` and `F d phi / d p` (see [`Lines`]) for the
    /// lines `range`.
    fn line_terms(
        &self,
        theta: &[f64],
        f: &realize::KnownFactors,
        range: std::ops::Range<usize>,
    ) -> (Vec<C64>, Vec<C64>, Vec<C64>) {
        let lay = &self.lay;
        let (n_lc, cpp, np) = (lay.n_lc(), lay.cpp(), lay.n_pairs);
        let n = range.len();
        let mut fphi = vec![C64::new(0.0, 0.0); n * n_lc];
        let mut dpair = vec![C64::new(0.0, 0.0); n * np * 2 * cpp];
        let mut dreal = vec![C64::new(0.0, 0.0); n * lay.n_real];
        let j = C64::new(0.0, 1.0);
        for (k, kk) in range.enumerate() {
            let w = self.omega[kk];
            let fs = f.scalar_at(w);
            let row = &mut fphi[k * n_lc..(k + 1) * n_lc];
            let mut col = 0;
            for q in 0..np {
                let p = C64::new(theta[2 * q], theta[2 * q + 1]);
                let [(h, dh), (hc, dhc)] = first_order_pair(p, w, self.ts);
                let base = (k * np + q) * 2 * cpp;
                if lay.const_num {
                    let b = p.im;
                    let phi = (h - hc) / (2.0 * j * b);
                    row[col] = fs * phi;
                    dpair[base] = fs * (dh - dhc) / (2.0 * j * b);
                    dpair[base + 1] = fs * ((dh + dhc) / (2.0 * b) - phi / b);
                    col += 1;
                } else {
                    row[col] = fs * (h + hc);
                    row[col + 1] = fs * j * (h - hc);
                    dpair[base] = fs * (dh + dhc);
                    dpair[base + 1] = fs * j * (dh - dhc);
                    dpair[base + 2] = fs * j * (dh - dhc);
                    dpair[base + 3] = -fs * (dh + dhc);
                    col += 2;
                }
            }
            for r in 0..lay.n_real {
                let p = theta[2 * np + r];
                let (h, dh) = first_order(C64::new(p, 0.0), w, self.ts);
                row[col] = fs * h;
                dreal[k * lay.n_real + r] = fs * dh;
                col += 1;
            }
            for l in 0..lay.n_rigid {
                row[col] = fs * self.rigid[kk * lay.n_rigid + l];
                col += 1;
            }
            if lay.feedthrough {
                row[col] = fs;
            }
        }
        (fphi, dpair, dreal)
    }

    pub(crate) fn lines(&self, theta: &[f64]) -> Lines {
        let n = self.n_lines();
        let f = self.factors(theta);
        let nd = f.dynamics.len();
        // the lines in chunks on the rayon pool
        let chunk = n.div_ceil(8).max(64);
        let parts: Vec<_> = (0..n.div_ceil(chunk))
            .into_par_iter()
            .map(|c| self.line_terms(theta, &f, c * chunk..((c + 1) * chunk).min(n)))
            .collect();
        let mut fphi = Vec::new();
        let mut dpair = Vec::new();
        let mut dreal = Vec::new();
        for (a, b, c) in parts {
            fphi.extend(a);
            dpair.extend(b);
            dreal.extend(c);
        }
        let mut dynv = Vec::with_capacity(n * nd);
        let mut dynx: Vec<Vec<C64>> = vec![Vec::new(); nd];
        for &w in self.omega.iter() {
            for (di, d) in f.dynamics.iter().enumerate() {
                dynv.push((d.at(w), d.den_at(w)));
                let x = C64::new(0.0, w / d.scale);
                dynx[di].extend(powers(x, d.den.len().max(d.num.len())));
            }
        }
        Lines {
            fphi,
            dpair,
            dreal,
            dynv,
            dynx,
        }
    }

    /// The product of the dynamics factors of entry `e` at line `k`, leaving out factor
    /// `skip`.
    fn dprod(&self, lines: &Lines, k: usize, e: usize, skip: Option<usize>) -> C64 {
        let ny = self.lay.ny;
        let (i, jj) = (e % ny, e / ny);
        let nd = self.template.factors.dynamics.len();
        let mut v = C64::new(1.0, 0.0);
        for (di, d) in self.template.factors.dynamics.iter().enumerate() {
            if Some(di) != skip && d.affects(i, jj) {
                v *= lines.dynv[k * nd + di].0;
            }
        }
        v
    }

    /// Writes the weighted basis of entry `e` (`2N x n_lin`) into the first columns of
    /// the row-major `2N x cols` matrix `a` (rows `2k` and `2k + 1`: the real and
    /// imaginary parts of line `k`) and the weighted data into column `ycol`.
    fn fill_basis(&self, lines: &Lines, e: usize, a: &mut [f64], cols: usize, ycol: usize) {
        let lay = &self.lay;
        let (n, m, n_lc) = (self.n_lines(), lay.m(), lay.n_lc());
        for k in 0..n {
            let s = self.sw[k * m + e];
            let d = self.dprod(lines, k, e, None) * s;
            let (re, im) = a[2 * k * cols..(2 * k + 2) * cols].split_at_mut(cols);
            for (l, f) in lines.fphi[k * n_lc..(k + 1) * n_lc].iter().enumerate() {
                let v = d * f;
                re[l] = v.re;
                im[l] = v.im;
            }
            if lay.crosstalk {
                re[n_lc] = d.re;
                im[n_lc] = d.im;
            }
            let y = self.g[k * m + e] * s;
            re[ycol] = y.re;
            im[ycol] = y.im;
        }
    }

    /// Solves the linear problem of every entry at `theta`: the cost and the linear
    /// parameters, or the first entry whose basis is (numerically) rank deficient.
    pub fn evaluate(&self, theta: &[f64]) -> Result<Eval, Singular> {
        if let Some(sh) = &self.shared {
            return self.evaluate_shared(sh, theta);
        }
        let lines = self.lines(theta);
        let lay = &self.lay;
        let (m, n_lin) = (lay.m(), lay.n_lin());
        let rows = 2 * self.n_lines();
        let cols = n_lin + 1;
        type PerEntry = Result<(f64, Vec<f64>, Option<Vec<f64>>), Singular>;
        let per: Vec<PerEntry> = (0..m)
            .into_par_iter()
            .map_init(Vec::new, |buf: &mut Vec<f64>, e| {
                // every element is written: a reused buffer needs no clearing
                buf.resize(rows * cols, 0.0);
                let a = &mut buf[..];
                self.fill_basis(&lines, e, a, cols, n_lin);
                if let Some((c, rr, g)) = gram_lstsq(a, rows, n_lin, GRAM_MIN_PIVOT) {
                    return Ok((0.5 * rr, c, Some(g)));
                }
                // nearly dependent columns: the QR, which also names a singular one
                let mut a = col_major(a, rows, cols);
                let norms: Vec<f64> = (0..n_lin)
                    .map(|l| {
                        a[l * rows..(l + 1) * rows]
                            .iter()
                            .map(|x| x * x)
                            .sum::<f64>()
                            .sqrt()
                    })
                    .collect();
                householder_r(&mut a, rows, cols);
                for (l, &nl) in norms.iter().enumerate() {
                    let r = a[l * rows + l].abs();
                    let ratio = if nl > 0.0 { r / nl } else { 0.0 };
                    if ratio.is_nan() || ratio <= 1e-11 {
                        return Err(Singular {
                            entry: e,
                            column: l,
                            ratio,
                        });
                    }
                }
                let mut c: Vec<f64> = (0..n_lin).map(|i| a[n_lin * rows + i]).collect();
                back_substitute(&a, rows, 0, n_lin, &mut c);
                let rr = a[n_lin * rows + n_lin];
                Ok((0.5 * rr * rr, c, None))
            })
            .collect();
        let mut cost = 0.0;
        let mut coef = Vec::with_capacity(m * n_lin);
        let mut entry_cost = Vec::with_capacity(m);
        let mut gram = Vec::with_capacity(m);
        for r in per {
            let (c2, c, g) = r?;
            cost += c2;
            entry_cost.push(c2);
            coef.extend(c);
            gram.push(g);
        }
        Ok(Eval {
            cost,
            coef,
            entry_cost,
            gram,
            residual: None,
        })
    }

    /// Writes the weighted derivatives of entry `e`'s response with respect to the
    /// nonlinear parameters (poles, real poles, delay, dynamics coefficients), with the
    /// linear parameters `c` of the entry, into columns `n_lin..n_lin + n_nl` of the
    /// row-major `2N x cols` matrix `a` (rows as in [`Problem::fill_basis`]).
    fn fill_nonlinear(
        &self,
        lines: &Lines,
        f: &realize::KnownFactors,
        e: usize,
        c: &[f64],
        a: &mut [f64],
        cols: usize,
    ) {
        let lay = &self.lay;
        let (n, m, n_lin, n_lc) = (self.n_lines(), lay.m(), lay.n_lin(), lay.n_lc());
        let (np, cpp) = (lay.n_pairs, lay.cpp());
        let (i_out, j_in) = (e % lay.ny, e / lay.ny);
        for k in 0..n {
            let s = self.sw[k * m + e];
            let d = self.dprod(lines, k, e, None) * s;
            let (re, im) = a[2 * k * cols..(2 * k + 2) * cols].split_at_mut(cols);
            let mut put = |col: usize, v: C64| {
                re[n_lin + col] = v.re;
                im[n_lin + col] = v.im;
            };
            for q in 0..np {
                for ab in 0..2 {
                    let base = ((k * np + q) * 2 + ab) * cpp;
                    let mut v = C64::new(0.0, 0.0);
                    for cc in 0..cpp {
                        v += lines.dpair[base + cc] * c[q * cpp + cc];
                    }
                    put(2 * q + ab, d * v);
                }
            }
            for r in 0..lay.n_real {
                let v = lines.dreal[k * lay.n_real + r] * c[np * cpp + r];
                put(2 * np + r, d * v);
            }
            if lay.delay || !lay.dynamics.is_empty() {
                let mut fr = C64::new(0.0, 0.0);
                for l in 0..n_lc {
                    fr += lines.fphi[k * n_lc + l] * c[l];
                }
                let mut col = 2 * np + lay.n_real;
                if lay.delay {
                    put(col, C64::new(0.0, -self.omega[k]) * d * fr);
                    col += 1;
                }
                let inner = fr + if lay.crosstalk { c[n_lc] } else { 0.0 };
                let nd = f.dynamics.len();
                for (di, df) in f.dynamics.iter().enumerate() {
                    let (nden, nnum) = (df.den.len(), df.num.len());
                    if df.affects(i_out, j_in) {
                        let (hd, ad) = lines.dynv[k * nd + di];
                        let rest = self.dprod(lines, k, e, Some(di)) * inner * s;
                        let npow = nden.max(nnum);
                        let xs = &lines.dynx[di][k * npow..(k + 1) * npow];
                        for ci in 0..nden {
                            put(col + ci, -rest * hd * xs[ci] / ad);
                        }
                        for ci in 0..nnum {
                            put(col + nden + ci, rest * xs[ci] / ad);
                        }
                    } else {
                        for ci in 0..nden + nnum {
                            put(col + ci, C64::new(0.0, 0.0));
                        }
                    }
                    col += nden + nnum;
                }
            }
        }
    }

    /// The `R` factor (`(n_nl + 1)^2`, column-major) of the projected Jacobian and
    /// residual `[J | r]` of all entries at `theta`, whose linear parameters `ev` holds,
    /// and the norms of the Jacobian's columns before the projection (a column that the
    /// projection almost cancels belongs to a parameter the linear terms can imitate).
    pub fn jacobian_r(&self, theta: &[f64], ev: &Eval) -> (Vec<f64>, Vec<f64>) {
        if let Some(sh) = &self.shared {
            if let Some(out) = self.jacobian_shared(sh, theta, ev) {
                return out;
            }
        }
        let lines = self.lines(theta);
        let lay = &self.lay;
        let (n, m, n_lin, n_nl) = (self.n_lines(), lay.m(), lay.n_lin(), lay.n_nl());
        let rows = 2 * n;
        let nb = n_nl + 1;
        let f = self.factors(theta);
        let cols = n_lin + n_nl + 1;
        let blocks: Vec<(Vec<f64>, Vec<f64>)> = (0..m)
            .into_par_iter()
            .map_init(Vec::new, |buf: &mut Vec<f64>, e| {
                // every element is written: a reused buffer needs no clearing
                buf.resize(rows * cols, 0.0);
                let a = &mut buf[..];
                let ycol = n_lin + n_nl;
                self.fill_basis(&lines, e, a, cols, ycol);
                let c = &ev.coef[e * n_lin..(e + 1) * n_lin];
                self.fill_nonlinear(&lines, &f, e, c, a, cols);
                let mut vn = vec![0.0; n_nl];
                let mut y2 = 0.0;
                for row in a.chunks_exact(cols) {
                    for (acc, x) in vn.iter_mut().zip(&row[n_lin..ycol]) {
                        *acc += x * x;
                    }
                    y2 += row[ycol] * row[ycol];
                }
                // the lower-right block: R of the projected [J | r], from the Gram
                // matrix while that is accurate (see `crate::gram`), by QR otherwise
                let mut b = vec![0.0; nb * nb];
                let gram = (2.0 * ev.entry_cost[e] > GRAM_MIN_RESIDUAL * GRAM_MIN_RESIDUAL * y2)
                    .then(|| match &ev.gram[e] {
                        Some(gb) => gram_r_with(a, rows, cols, n_lin, gb, GRAM_MIN_PIVOT),
                        None => gram_r(a, rows, cols, GRAM_MIN_PIVOT),
                    })
                    .flatten();
                if let Some(g) = gram {
                    for cj in 0..nb {
                        for ri in 0..=cj {
                            b[cj * nb + ri] = g[(n_lin + cj) * cols + n_lin + ri];
                        }
                    }
                } else {
                    let mut a = col_major(a, rows, cols);
                    householder_r(&mut a, rows, cols);
                    for cj in 0..nb {
                        for ri in 0..=cj.min(rows.saturating_sub(n_lin + 1)) {
                            b[cj * nb + ri] = a[(n_lin + cj) * rows + n_lin + ri];
                        }
                    }
                }
                (b, vn)
            })
            .collect();
        let mut vnorm = vec![0.0; n_nl];
        // merge: stack the blocks and factorise once more
        let srows = m * nb;
        let mut s = vec![0.0; srows * nb];
        for (e, (b, vn)) in blocks.iter().enumerate() {
            for (acc, v) in vnorm.iter_mut().zip(vn) {
                *acc += v;
            }
            for cj in 0..nb {
                for ri in 0..nb {
                    s[cj * srows + e * nb + ri] = b[cj * nb + ri];
                }
            }
        }
        householder_r(&mut s, srows, nb);
        let mut r = vec![0.0; nb * nb];
        for cj in 0..nb {
            for ri in 0..=cj {
                r[cj * nb + ri] = s[cj * srows + ri];
            }
        }
        (r, vnorm.into_iter().map(f64::sqrt).collect())
    }

    /// The variance of the fitted response `P_e(j w_k)` at every line and entry (layout
    /// `[k * m + e]`, `E |P - E P|^2`, the real and imaginary parts' variances summed), to
    /// first order, from the covariance `cov` (`n_nl x n_nl`, column-major, unscaled: the
    /// `(R^T R)^{-1}` of [`Problem::jacobian_r`]) of the nonlinear parameters and the
    /// linear parameters' least-squares fit of each entry at them.
    ///
    /// With the weighted Jacobian of entry `e` split into the linear basis `B` and the
    /// nonlinear columns `D`, the covariance of all parameters gives for the row `[d, b]`
    /// of one real observation `(d - C M^{-1} b)^T cov (d - C M^{-1} b) + b^T M^{-1} b`
    /// (`M = B^T B`, `C = D^T B`): the projected Jacobian's row through the poles'
    /// covariance and the leverage of the linear fit. Summed over every line and entry,
    /// weighted by `2 w`, it is the number of parameters (the trace of the hat matrix).
    /// Multiply by the noise scale ([`crate::MlReport::covariance_scale`]). Only the
    /// entries in `entries` are computed (all with `None`); the others are NaN.
    pub fn response_variance(
        &self,
        theta: &[f64],
        ev: &Eval,
        cov: &[f64],
        entries: Option<&[usize]>,
    ) -> Vec<f64> {
        self.response_variance_on(None, theta, ev, cov, entries)
    }

    /// [`Problem::response_variance`] at the lines of `at` instead of this problem's
    /// (a problem of the same layout and template at other frequencies, with unit
    /// weights: [`Problem::at_lines`]): the same covariance of the parameters, formed
    /// on this problem's data, carried to the response at `at`'s lines. The row of a
    /// line of `at` is `[d, b]` unweighted; its variance is
    /// `(d - b M^{-1} B^T D) cov (d - b M^{-1} B^T D)^T + b M^{-1} b^T` with `M`, `B`
    /// and `D` of this problem (the linear parameters' dependence on the poles through
    /// their least-squares fit). Layout `[k * m + e]` over `at`'s lines; unscaled.
    pub fn response_variance_at(
        &self,
        at: &Problem,
        theta: &[f64],
        ev: &Eval,
        cov: &[f64],
        entries: Option<&[usize]>,
    ) -> Vec<f64> {
        self.response_variance_on(Some(at), theta, ev, cov, entries)
    }

    /// The same structure and template on some of this problem's lines (`lines`: their
    /// indices, increasing), with their data and weights: one half of the held-out test
    /// of a structure step.
    pub fn on_lines(&self, lines: &[usize]) -> Problem {
        let m = self.lay.m();
        let omega: Vec<f64> = lines.iter().map(|&k| self.omega[k]).collect();
        let g: Vec<C64> = lines
            .iter()
            .flat_map(|&k| self.g[k * m..(k + 1) * m].iter().copied())
            .collect();
        let sw: Vec<f64> = lines
            .iter()
            .flat_map(|&k| self.sw[k * m..(k + 1) * m].iter().copied())
            .collect();
        Problem::new(self.lay.clone(), omega, g, sw, self.template.clone())
    }

    /// The weighted cost `sum w |G - P|^2` of the model `fm` on this problem's lines,
    /// its linear parameters as they are (not refitted to these data, as
    /// [`Problem::evaluate`] does): the error of a model on lines it was not fitted to.
    /// `None` when its response cannot be evaluated.
    pub fn cost_of_model(&self, fm: &FrfModel) -> Option<f64> {
        let resp = fm.freq_response(&self.omega).ok()?;
        let c: f64 = self
            .g
            .iter()
            .zip(&resp.values)
            .zip(self.sw.iter())
            .map(|((g, p), sw)| 0.5 * sw * sw * (g - p).norm_sqr())
            .sum();
        c.is_finite().then_some(c)
    }

    /// This problem's layout and template at the lines `omega` (rad/s), with unit
    /// weights and no data: the rows at which [`Problem::response_variance_at`]
    /// evaluates the response's variance.
    pub fn at_lines(&self, omega: Vec<f64>) -> Problem {
        let n = omega.len();
        let m = self.lay.m();
        Problem::assemble(
            self.lay.clone(),
            Arc::new(omega),
            Arc::new(vec![C64::new(0.0, 0.0); n * m]),
            Arc::new(vec![1.0; n * m]),
            self.template.clone(),
            None,
        )
    }

    fn response_variance_on(
        &self,
        at: Option<&Problem>,
        theta: &[f64],
        ev: &Eval,
        cov: &[f64],
        entries: Option<&[usize]>,
    ) -> Vec<f64> {
        use faer::linalg::matmul::matmul;
        use faer::linalg::solvers::Solve;
        use faer::{Accum, Mat, Par, Side};
        let lines = self.lines(theta);
        let at_lines = at.map(|p| p.lines(theta));
        let f = self.factors(theta);
        let lay = &self.lay;
        let (n, m, n_lin, n_nl) = (self.n_lines(), lay.m(), lay.n_lin(), lay.n_nl());
        let n_out = at.map_or(n, Problem::n_lines);
        let rows = 2 * n;
        let cols = n_lin + n_nl + 1;
        let covm = Mat::from_fn(n_nl, n_nl, |i, j| cov[j * n_nl + i]);
        let wanted: Vec<usize> = match entries {
            Some(list) => list.iter().copied().filter(|&e| e < m).collect(),
            None => (0..m).collect(),
        };
        let per: Vec<Vec<f64>> = wanted
            .par_iter()
            .map_init(Vec::new, |buf: &mut Vec<f64>, &e| {
                buf.resize(rows * cols, 0.0);
                let a = &mut buf[..];
                self.fill_basis(&lines, e, a, cols, n_lin + n_nl);
                let c = &ev.coef[e * n_lin..(e + 1) * n_lin];
                self.fill_nonlinear(&lines, &f, e, c, a, cols);
                // the basis with unit columns (the Gram matrix's conditioning)
                let norms: Vec<f64> = (0..n_lin)
                    .map(|l| {
                        let s = a.chunks_exact(cols).map(|r| r[l] * r[l]).sum::<f64>();
                        if s > 0.0 {
                            s.sqrt()
                        } else {
                            1.0
                        }
                    })
                    .collect();
                let b = Mat::from_fn(rows, n_lin, |r, l| a[r * cols + l] / norms[l]);
                let d = Mat::from_fn(rows, n_nl, |r, l| a[r * cols + n_lin + l]);
                let gram = b.transpose() * &b;
                let eye = Mat::<f64>::identity(n_lin, n_lin);
                let minv = match gram.llt(Side::Lower) {
                    Ok(l) => l.solve(&eye),
                    // nearly dependent columns: the eigen-decomposition's pseudo-inverse
                    Err(_) => match gram.self_adjoint_eigen(Side::Lower) {
                        Ok(evd) => {
                            let (u, sv) = (evd.U(), evd.S());
                            let top = (0..n_lin).map(|i| sv[i]).fold(0.0, f64::max);
                            Mat::from_fn(n_lin, n_lin, |i, j| {
                                (0..n_lin)
                                    .filter(|&k| sv[k] > 1e-13 * top)
                                    .map(|k| u[(i, k)] * u[(j, k)] / sv[k])
                                    .sum()
                            })
                        }
                        Err(_) => return vec![f64::NAN; n_out],
                    },
                };
                // H = B M^-1: leverage h_r = H_r . B_r; U = D - H (B^T D), at the rows
                // the variance is read at: this problem's (weighted), or those of `at`
                // (unit weights) through this problem's fit
                let btd = b.transpose() * &d;
                let (h, b, u, sw) = match (at, &at_lines) {
                    (Some(at), Some(at_lines)) => {
                        let na = at.n_lines();
                        let mut a2 = vec![0.0; 2 * na * cols];
                        at.fill_basis(at_lines, e, &mut a2, cols, n_lin + n_nl);
                        at.fill_nonlinear(at_lines, &f, e, c, &mut a2, cols);
                        let b2 = Mat::from_fn(2 * na, n_lin, |r, l| a2[r * cols + l] / norms[l]);
                        let d2 = Mat::from_fn(2 * na, n_nl, |r, l| a2[r * cols + n_lin + l]);
                        let h2 = &b2 * &minv;
                        let mut u2 = d2;
                        matmul(u2.as_mut(), Accum::Add, &h2, &btd, -1.0, Par::Seq);
                        (h2, b2, u2, &at.sw)
                    }
                    _ => {
                        let h = &b * &minv;
                        let mut u = d;
                        matmul(u.as_mut(), Accum::Add, &h, &btd, -1.0, Par::Seq);
                        (h, b, u, &self.sw)
                    }
                };
                let w = &u * &covm;
                (0..n_out)
                    .map(|k| {
                        let s = sw[k * m + e];
                        let mut v = 0.0;
                        for r in [2 * k, 2 * k + 1] {
                            for l in 0..n_lin {
                                v += h[(r, l)] * b[(r, l)];
                            }
                            for l in 0..n_nl {
                                v += w[(r, l)] * u[(r, l)];
                            }
                        }
                        if s > 0.0 {
                            v / (s * s)
                        } else {
                            f64::NAN
                        }
                    })
                    .collect()
            })
            .collect();
        let mut out = vec![f64::NAN; n_out * m];
        for (&e, v) in wanted.iter().zip(per) {
            for (k, x) in v.into_iter().enumerate() {
                out[k * m + e] = x;
            }
        }
        out
    }

    /// The model at `theta` with the linear parameters `coef`.
    pub fn model(&self, theta: &[f64], coef: &[f64]) -> FrfModel {
        let lay = &self.lay;
        let (ny, nu, m, n_lin, n_lc, cpp) =
            (lay.ny, lay.nu, lay.m(), lay.n_lin(), lay.n_lc(), lay.cpp());
        let mut fm = self.template.clone();
        fm.factors = self.factors(theta);
        let cf = |e: usize, l: usize| coef[e * n_lin + l];
        fm.modal.pairs = (0..lay.n_pairs)
            .map(|q| {
                let pole = C64::new(theta[2 * q], theta[2 * q + 1]);
                let residue = faer::Mat::from_fn(ny, nu, |i, j| {
                    let e = j * ny + i;
                    if lay.const_num {
                        C64::new(0.0, -cf(e, q) / (2.0 * pole.im))
                    } else {
                        C64::new(cf(e, 2 * q), cf(e, 2 * q + 1))
                    }
                });
                PolePair { pole, residue }
            })
            .collect();
        let off = lay.n_pairs * cpp;
        fm.modal.real_poles = (0..lay.n_real)
            .map(|r| RealPole {
                pole: theta[2 * lay.n_pairs + r],
                residue: faer::Mat::from_fn(ny, nu, |i, j| cf(j * ny + i, off + r)),
            })
            .collect();
        let off = off + lay.n_real;
        fm.modal.rigid = (0..lay.n_rigid)
            .map(|l| faer::Mat::from_fn(ny, nu, |i, j| cf(j * ny + i, off + l)))
            .collect();
        let off = off + lay.n_rigid;
        fm.modal.feedthrough = if lay.feedthrough {
            faer::Mat::from_fn(ny, nu, |i, j| cf(j * ny + i, off))
        } else {
            faer::Mat::zeros(ny, nu)
        };
        if lay.crosstalk {
            fm.factors.crosstalk = Some(faer::Mat::from_fn(ny, nu, |i, j| cf(j * ny + i, n_lc)));
        }
        debug_assert_eq!(m * n_lin, coef.len());
        fm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realize::ModalModel;

    /// The scaled residual vector at `theta` (linear parameters eliminated).
    fn residual(p: &Problem, theta: &[f64]) -> Vec<f64> {
        let ev = p.evaluate(theta).unwrap();
        let fm = p.model(theta, &ev.coef);
        let g = fm.freq_response(&p.omega).unwrap();
        let m = p.lay.m();
        let mut r = Vec::new();
        for e in 0..m {
            for k in 0..p.omega.len() {
                let v = (p.g[k * m + e] - g.values[k * m + e]) * p.sw[k * m + e];
                r.push(v.re);
                r.push(v.im);
            }
        }
        r
    }

    #[test]
    fn projected_jacobian_matches_finite_differences_at_zero_residual() {
        for (const_num, delay, ts, small, dynx) in [
            (false, true, None, true, false),
            (false, true, None, false, false),
            (true, true, None, false, false),
            (false, false, Some(2.5e-4), false, false),
            (true, true, Some(2.5e-4), false, false),
            (false, true, None, false, true),
            (true, false, Some(2.5e-4), false, true),
        ] {
            let ny = if small { 1 } else { 2 };
            let mut mm = ModalModel::new(ny, 1);
            mm.pairs.push(PolePair::from_f_zeta(
                120.0,
                0.02,
                faer::Mat::from_fn(ny, 1, |i, _| {
                    C64::new(if const_num { 0.0 } else { 0.3 }, -1.0 - i as f64)
                }),
            ));
            if !small {
                mm.pairs.push(PolePair::from_f_zeta(
                    410.0,
                    0.01,
                    faer::Mat::from_fn(ny, 1, |i, _| {
                        C64::new(if const_num { 0.0 } else { -0.1 }, 2.0 + i as f64)
                    }),
                ));
                mm.real_poles.push(RealPole {
                    pole: -900.0,
                    residue: faer::Mat::from_fn(ny, 1, |i, _| 50.0 + i as f64),
                });
            }
            let mut fm = FrfModel::new(mm);
            fm.factors.delay_s = 1.5e-4;
            fm.factors.delay_fitted = delay;
            if let Some(t) = ts {
                fm.factors.hold = realize::Hold::Zoh { fs_hz: 1.0 / t };
            }
            if dynx {
                fm.factors
                    .dynamics
                    .push(realize::DynamicsFactor::second_order(
                        realize::FactorTarget::Output(1),
                        300.0,
                        0.2,
                    ));
                let mut lead =
                    realize::DynamicsFactor::first_order(realize::FactorTarget::All, 700.0);
                lead.num = vec![0.3];
                fm.factors.dynamics.push(lead);
                fm.factors.crosstalk =
                    Some(faer::Mat::from_fn(ny, 1, |i, _| 0.01 * (i as f64 + 1.0)));
            }
            let omega: Vec<f64> = (1..200)
                .map(|k| 2.0 * std::f64::consts::PI * 5.0 * k as f64)
                .collect();
            let g = fm.freq_response(&omega).unwrap().values;
            let lay = Layout {
                ny,
                nu: 1,
                n_pairs: if small { 1 } else { 2 },
                n_real: if small { 0 } else { 1 },
                n_rigid: 0,
                feedthrough: false,
                crosstalk: dynx,
                delay,
                dynamics: if dynx { vec![(2, 0), (1, 1)] } else { vec![] },
                const_num,
            };
            let sw: Vec<f64> = g.iter().map(|v| 2f64.sqrt() / v.norm()).collect();
            let p = Problem::new(lay.clone(), omega, g, sw, fm.clone());
            let mut theta = vec![fm.modal.pairs[0].pole.re, fm.modal.pairs[0].pole.im];
            if !small {
                theta.extend([fm.modal.pairs[1].pole.re, fm.modal.pairs[1].pole.im, -900.0]);
            }
            if delay {
                theta.push(1.5e-4);
            }
            for d in &fm.factors.dynamics {
                theta.extend_from_slice(&d.den);
                theta.extend_from_slice(&d.num);
            }
            let n = theta.len();
            if delay && !dynx {
                // one Gauss-Newton step from a delay 1e-8 s off returns to the truth
                let mut t1 = theta.clone();
                t1[n - 1] += 1e-8;
                let ev1 = p.evaluate(&t1).unwrap();
                let (r1, _) = p.jacobian_r(&t1, &ev1);
                let mut z: Vec<f64> = (0..n).map(|i| r1[n * (n + 1) + i]).collect();
                crate::qr::back_substitute(&r1, n + 1, 0, n, &mut z);
                let err = t1[n - 1] + z[n - 1] - theta[n - 1];
                assert!(
                    err.abs() < 1e-12,
                    "{const_num} {ts:?}: GN step {:.3e}, left {err:.3e}",
                    z[n - 1]
                );
            }
            let ev = p.evaluate(&theta).unwrap();
            assert!(ev.cost < 1e-20, "{}", ev.cost);
            let (r, _) = p.jacobian_r(&theta, &ev);
            let mut cols = Vec::new();
            for i in 0..n {
                let h = 1e-6 * theta[i].abs();
                let mut tp = theta.clone();
                tp[i] += h;
                let mut tm = theta.clone();
                tm[i] -= h;
                let (a, b) = (residual(&p, &tp), residual(&p, &tm));
                cols.push(
                    a.iter()
                        .zip(&b)
                        .map(|(x, y)| -(x - y) / (2.0 * h))
                        .collect::<Vec<f64>>(),
                );
            }
            for a in 0..n {
                for b in 0..n {
                    let fd: f64 = cols[a].iter().zip(&cols[b]).map(|(x, y)| x * y).sum();
                    let an: f64 = (0..n)
                        .map(|i| r[a * (n + 1) + i] * r[b * (n + 1) + i])
                        .sum();
                    let scale = (cols[a].iter().map(|x| x * x).sum::<f64>()
                        * cols[b].iter().map(|x| x * x).sum::<f64>())
                    .sqrt();
                    assert!(
                        (fd - an).abs() <= 1e-6 * scale,
                        "{const_num} {delay} {ts:?} ({a},{b}): fd {fd:.6e} vs R^T R {an:.6e}"
                    );
                }
            }
        }
    }
}
