//! One step of Algorithm 1 (eq. 23 of the wafer-stage paper), in update form.
//!
//! With the pseudo-linear regression of Lemma 1 (eq. 13-15), the diagonal blocks that
//! (23) extracts from `B^<j+1>` equal `beta^<j> + Delta` with
//!
//! `[sum_k Re{ Phi_hat W Phi^T }] Delta = sum_k Re{ Phi_hat W vec(E(beta^<j>)) }`,
//!
//! because each column `i` of `Upsilon^T` is `vec(E) + Phi_i^T theta_i` at the current
//! parameters. The solve therefore only affects the step, never the fixed point, which
//! is the first-order optimality condition (9) whatever the rounding in the solve.
//!
//! `Phi_hat` (the instrument, the gradient (11)-(12)) uses the submodel responses
//! `P_i`; `Phi` (the regressor (14)) uses the residual plants `g~_i = E + P_i` (15).
//! The SK variant (Remark 1) uses `Phi` in both places.
//!
//! **Structure.** The numerator columns of both matrices are `x^r/(pi A) I` (identity
//! blocks: each numerator coefficient touches one entry of `vec(G)`) and the weighting is
//! diagonal, so the normal matrix is block-arrow shaped: one `n_num x n_num` block per
//! entry plus the shared denominator block. Each entry's numerator unknowns are
//! eliminated (Schur complement onto the shared parameters), the shared system is solved,
//! and the numerators follow by back-substitution. One step costs
//! `O(lines * entries * (n_num + n_shared)^2)`: linear in lines and in `ny nu`.

use crate::problem::{Basis, EntryLines, FitData, Layout};
use crate::small::{lu_solve, spd_apply, spd_factor};
use crate::RivError;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use rayon::prelude::*;

/// Which matrix multiplies the residual: the refined instrument (eq. 12) or the
/// regressor itself (SK iterations, Remark 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IvMethod {
    /// Refined instrumental variables: instrument `Phi_hat` (eq. 12). The fixed point is
    /// a stationary point of the weighted criterion (8).
    #[default]
    Riv,
    /// Sanathanan-Koerner: `Phi` in place of `Phi_hat`; cheaper to converge from far
    /// away, but its fixed point is biased by noise.
    Sk,
}

/// How the linear system of a step is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepSolver {
    /// Per-entry elimination of the numerators (the default; linear cost).
    #[default]
    Structured,
    /// The full square system formed and solved densely (reference for small problems).
    Dense,
}

/// The update of one step.
#[derive(Debug, Clone)]
pub struct StepUpdate {
    /// Change of the shared parameters (denominators, then the delay).
    pub d_shared: Vec<f64>,
    /// Change of the numerators, `eta` layout.
    pub d_eta: Vec<f64>,
    /// Condition estimate of the shared (Schur) system.
    pub cond_shared: f64,
    /// Worst condition estimate of the per-entry numerator blocks.
    pub cond_numerator: f64,
}

/// What a step reads: the data, the layout, the model's current basis and numerators.
#[derive(Clone, Copy)]
pub struct StepInputs<'a> {
    /// The prepared data.
    pub data: &'a FitData,
    /// The parameter layout.
    pub lay: &'a Layout,
    /// `(numerator count, denominator count)` per submodel.
    pub subs: &'a [(usize, usize)],
    /// The basis at the current parameters.
    pub basis: &'a Basis,
    /// The current numerators (`eta` layout).
    pub eta: &'a [f64],
    /// Refined IV or SK.
    pub method: IvMethod,
    /// Entries on the rayon pool.
    pub parallel: bool,
}

/// The sizes of a step's problem and its submodels' parameter groups.
struct StepShape {
    /// Lines.
    n: usize,
    /// Entries.
    m: usize,
    /// Numerator parameters per entry.
    nn: usize,
    /// Shared parameters.
    ns: usize,
    /// `(first numerator index, count)` per submodel.
    ng: Vec<(usize, usize)>,
    /// `(first denominator index, count)` per submodel.
    dg: Vec<(usize, usize)>,
}

impl StepInputs<'_> {
    /// The sizes and groups of the problem.
    fn shape(&self) -> StepShape {
        StepShape {
            n: self.data.n,
            m: self.data.m(),
            nn: self.lay.n_num,
            ns: self.lay.n_shared(),
            ng: num_groups(self.subs, self.lay),
            dg: den_groups(self.subs, self.lay),
        }
    }

    /// Entry `e`'s numerators.
    fn be(&self, e: usize) -> &[f64] {
        let nn = self.lay.n_num;
        &self.eta[e * nn..(e + 1) * nn]
    }
}

/// Fills the real instrument `Y = [U | V_hat]` and the regressor's other columns
/// `X' = [V | eps]` (the full regressor is `[U | V | eps]`: its `U` is `Y`'s) of
/// entry `e` for the lines `lines = k0..k1` (rows `k - k0`: real parts of line `k`;
/// rows `len + k - k0`: imaginary parts, `len = k1 - k0`; every row scaled by
/// `s = sqrt(w) |F|`), column by column so that each loop runs over contiguous lines.
/// `y` and `x` need at least `2 len` rows and `nn + ns` and `ns + 1` columns; `el`
/// holds the entry's lines after [`EntryLines::fill`]. The step fills a block of lines
/// at a time and accumulates `Y^T X'` and `V_hat^T U` over the blocks, so that the
/// blocks stay in cache (the `U^T U` block comes from [`crate::gram`]).
///
/// The loops are compiled for the SIMD instruction set of the CPU at run time
/// (`pulp` dispatch: AVX2 or AVX-512 where present, the baseline otherwise).
/// `den_groups` is [`den_groups`] of the inputs' submodels.
#[allow(clippy::too_many_arguments)]
fn fill_entry(
    inp: &StepInputs,
    den_groups: &[(usize, usize)],
    e: usize,
    lines: std::ops::Range<usize>,
    el: &EntryLines,
    regressor: bool,
    y: &mut Mat<f64>,
    x: &mut Mat<f64>,
) {
    pulp::Arch::new().dispatch(FillOp {
        inp,
        den_groups,
        e,
        lines,
        el,
        regressor,
        y,
        x,
    })
}

/// The arguments, so that `with_simd` (inlined into pulp's `target_feature`
/// function) runs the kernel with the CPU's instruction set.
struct FillOp<'a, 'b> {
    inp: &'a StepInputs<'b>,
    den_groups: &'a [(usize, usize)],
    e: usize,
    lines: std::ops::Range<usize>,
    el: &'a EntryLines,
    regressor: bool,
    y: &'a mut Mat<f64>,
    x: &'a mut Mat<f64>,
}
impl pulp::WithSimd for FillOp<'_, '_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        fill_entry_kernel(self)
    }
}

#[inline(always)]
fn fill_entry_kernel(op: FillOp) {
    let FillOp {
        inp,
        den_groups,
        e,
        lines,
        el,
        regressor,
        y,
        x,
    } = op;
    let StepInputs {
        data,
        lay,
        basis,
        method,
        ..
    } = *inp;
    let be = inp.be(e);
    // the regressor's columns (all but `eps`) are needed by a full step and by SK,
    // whose instrument they are
    let regressor = regressor || method == IvMethod::Sk;
    let n = data.n;
    let (k0, k1) = (lines.start, lines.end);
    let len = k1 - k0;
    let nn = lay.n_num;
    let nd = lay.n_den;
    let ns = lay.n_shared();
    // every per-line slice is cut to exactly `len`: the loops below carry no bounds
    // checks and vectorise (they are most of the time of an iteration)
    let at = |v: &'_ [f64], j: usize| -> std::ops::Range<usize> {
        debug_assert!(v.len() >= (j + 1) * n);
        j * n + k0..j * n + k1
    };
    let s = &el.s[k0..k1];
    let (e_re, e_im) = (&el.e_re[k0..k1], &el.e_im[k0..k1]);
    let (y_re, y_im) = (&el.y_re[k0..k1], &el.y_im[k0..k1]);
    // numerator columns: u * s (instrument = regressor)
    for j in 0..nn {
        let ur = &basis.u_re[at(&basis.u_re, j)];
        let ui = &basis.u_im[at(&basis.u_im, j)];
        let (cr, ci) = y.col_as_slice_mut(j)[..2 * len].split_at_mut(len);
        for k in 0..len {
            cr[k] = ur[k] * s[k];
            ci[k] = ui[k] * s[k];
        }
    }
    // denominator columns: the instrument is d P_i / d a = sum_j B_j d u_j / d a (the
    // gradient (12)); the regressor (14) adds d * E (it uses E + P_i where the
    // instrument uses P_i). SK uses the regressor for both (Remark 1).
    for (d0, cnt) in den_groups.iter().copied() {
        for d in d0..d0 + cnt {
            let dr = &basis.d_re[at(&basis.d_re, d)];
            let di = &basis.d_im[at(&basis.d_im, d)];
            {
                let (ir, ii) = y.col_as_slice_mut(nn + d)[..2 * len].split_at_mut(len);
                ir.fill(0.0);
                ii.fill(0.0);
                for p in basis.pair_range[d].clone() {
                    let b = be[basis.pairs[p].1];
                    let ur = &basis.du_re[at(&basis.du_re, p)];
                    let ui = &basis.du_im[at(&basis.du_im, p)];
                    for k in 0..len {
                        ir[k] += b * ur[k] * s[k];
                        ii[k] += b * ui[k] * s[k];
                    }
                }
            }
            if regressor {
                let (ir, ii) = y.col_as_slice(nn + d)[..2 * len].split_at(len);
                let (cr, ci) = x.col_as_slice_mut(d)[..2 * len].split_at_mut(len);
                for k in 0..len {
                    let er = e_re[k] * s[k];
                    let ei = e_im[k] * s[k];
                    cr[k] = ir[k] + dr[k] * er - di[k] * ei;
                    ci[k] = ii[k] + dr[k] * ei + di[k] * er;
                }
            }
            if method == IvMethod::Sk {
                y.col_as_slice_mut(nn + d)[..2 * len]
                    .copy_from_slice(&x.col_as_slice(d)[..2 * len]);
            }
        }
    }
    // factor parameters (delay, dynamics): d(y - P)/d theta = -y d ln F / d theta, so
    // the regressor is y d ln F and the instrument P d ln F (SK: y d ln F)
    let m = data.m();
    let n_fp = ns - nd;
    // submodels that bypass the known factor depend on the delay as well: their part
    // of the divided model moves with y (d(P_b)/d tau = -P_b d ln F)
    let zeros = vec![0.0; if el.pb_re.is_empty() { len } else { 0 }];
    let (pb_re, pb_im) = if el.pb_re.is_empty() {
        (&zeros[..], &zeros[..])
    } else {
        (&el.pb_re[k0..k1], &el.pb_im[k0..k1])
    };
    for q in 0..n_fp {
        let on = basis.dlnf_mask[q * m + e];
        let dl = &basis.dlnf[q * n + k0..q * n + k1];
        let is_delay = lay.fit_delay && q == 0;
        if regressor {
            let (cr, ci) = x.col_as_slice_mut(nd + q)[..2 * len].split_at_mut(len);
            for k in 0..len {
                if on {
                    let (mut yr, mut yi) = (y_re[k], y_im[k]);
                    if is_delay {
                        yr -= pb_re[k];
                        yi -= pb_im[k];
                    }
                    let (yr, yi) = (yr * s[k], yi * s[k]);
                    cr[k] = dl[k].re * yr - dl[k].im * yi;
                    ci[k] = dl[k].re * yi + dl[k].im * yr;
                } else {
                    cr[k] = 0.0;
                    ci[k] = 0.0;
                }
            }
        }
        let (cr, ci) = y.col_as_slice_mut(nn + nd + q)[..2 * len].split_at_mut(len);
        for k in 0..len {
            if on {
                let (mut pr, mut pi) = if method == IvMethod::Riv {
                    (y_re[k] - e_re[k], y_im[k] - e_im[k])
                } else {
                    (y_re[k], y_im[k])
                };
                if is_delay {
                    pr -= pb_re[k];
                    pi -= pb_im[k];
                }
                let (pr, pi) = (pr * s[k], pi * s[k]);
                cr[k] = dl[k].re * pr - dl[k].im * pi;
                ci[k] = dl[k].re * pi + dl[k].im * pr;
            } else {
                cr[k] = 0.0;
                ci[k] = 0.0;
            }
        }
    }
    let (cr, ci) = x.col_as_slice_mut(ns)[..2 * len].split_at_mut(len);
    for k in 0..len {
        cr[k] = e_re[k] * s[k];
        ci[k] = e_im[k] * s[k];
    }
}

/// `(first denominator index, count)` per submodel.
fn den_groups(model_subs: &[(usize, usize)], lay: &Layout) -> Vec<(usize, usize)> {
    model_subs
        .iter()
        .enumerate()
        .map(|(i, &(_, n_den))| (lay.den_offset[i], n_den))
        .collect()
}

fn num_groups(model_subs: &[(usize, usize)], lay: &Layout) -> Vec<(usize, usize)> {
    model_subs
        .iter()
        .enumerate()
        .map(|(i, &(n_num, _))| (lay.num_offset[i], n_num))
        .collect()
}

/// Fills entry `e`'s instrument and regressor ([`fill_entry`]) a block of
/// [`LINE_BLOCK`] lines at a time and hands each block to `accumulate(rows, acc, y, x)`
/// (`rows` filled rows; `acc` replaces on the first block and adds on the others), so
/// that the products over all lines are accumulated from blocks that stay in cache.
fn for_each_line_block(
    inp: &StepInputs,
    den_groups: &[(usize, usize)],
    e: usize,
    el: &EntryLines,
    regressor: bool,
    (y, x): (&mut Mat<f64>, &mut Mat<f64>),
    mut accumulate: impl FnMut(usize, Accum, &Mat<f64>, &Mat<f64>),
) {
    let n = inp.data.n;
    for (b, k0) in (0..n).step_by(LINE_BLOCK).enumerate() {
        let k1 = (k0 + LINE_BLOCK).min(n);
        fill_entry(inp, den_groups, e, k0..k1, el, regressor, y, x);
        let acc = if b == 0 { Accum::Replace } else { Accum::Add };
        accumulate(2 * (k1 - k0), acc, y, x);
    }
}

/// `per_entry(e, buffers)` for the `m` entries in order, on the rayon pool when
/// `parallel` (one set of buffers from `init` per worker).
fn map_entries<B, T: Send>(
    m: usize,
    parallel: bool,
    init: impl Fn() -> B + Sync + Send,
    per_entry: impl Fn(usize, &mut B) -> Result<T, RivError> + Sync + Send,
) -> Result<Vec<T>, RivError> {
    if parallel && m > 1 {
        (0..m)
            .into_par_iter()
            .map_init(init, |b, e| per_entry(e, b))
            .collect()
    } else {
        let mut b = init();
        (0..m).map(|e| per_entry(e, &mut b)).collect()
    }
}

/// Per-entry result of the elimination.
struct EntryParts {
    /// `K_e = H_nn^{-1} H_ns`, column-major `nn x ns`.
    k_mat: Vec<f64>,
    /// `k_e = H_nn^{-1} g_n`.
    k_vec: Vec<f64>,
    /// `H_ss - H_sn K_e`, column-major `ns x ns`.
    s_mat: Vec<f64>,
    /// `g_s - H_sn k_e`.
    r_vec: Vec<f64>,
    cond: f64,
    /// What a chord step reuses (when asked for): the factor of `H_nn`
    /// ([`spd_factor`]: `L` and the equilibration) and `H_sn = V_hat^T U` (`ns x nn`).
    kept: Option<(Vec<f64>, Vec<f64>, Mat<f64>)>,
}

/// The per-entry eliminations and the shared Schur system of one full step, kept so
/// that the next steps can reuse them ([`chord_step`]).
///
/// A step solves `M(theta) Delta = Y(theta)^T eps(theta)` (module docs); the fixed point
/// is where the right-hand side vanishes, whatever `M` is. Near the fixed point `M`
/// changes little from one iterate to the next, and a step with the matrix of an
/// earlier iterate and the right-hand side of the current one (the chord method)
/// converges to the same fixed point at a rate set by how much `M` moved, for the price
/// of the instrument's fill and one product with the residual instead of the products
/// `Y^T X` (most of a full step's time).
#[derive(Debug, Clone)]
pub struct StepFactors {
    nn: usize,
    ns: usize,
    /// Per entry.
    entries: Vec<EntryFactor>,
    /// The Schur system `sum_e H_ss - H_sn K_e`.
    schur: Mat<f64>,
    /// The worst condition estimate of the entries' `H_nn` ([`StepUpdate::cond_numerator`]).
    cond_numerator: f64,
}

/// One entry's part of [`StepFactors`] (column-major matrices).
#[derive(Debug, Clone)]
struct EntryFactor {
    /// The factor `L` of the equilibrated `H_nn` (`nn x nn`, [`spd_factor`]).
    l: Vec<f64>,
    /// Its equilibration `D`.
    d: Vec<f64>,
    /// `K_e = H_nn^{-1} H_ns` (`nn x ns`).
    k_mat: Vec<f64>,
    /// `H_sn = V_hat^T U` (`ns x nn`).
    h_sn: Mat<f64>,
}

impl StepFactors {
    /// Bytes the factors of a problem with `m` entries, `nn` numerator and `ns` shared
    /// parameters hold.
    pub fn bytes(m: usize, nn: usize, ns: usize) -> usize {
        8 * (m * (nn * nn + nn + 2 * nn * ns) + ns * ns)
    }

    /// Whether these factors belong to a problem with this layout.
    pub fn fits(&self, lay: &Layout, m: usize) -> bool {
        self.nn == lay.n_num && self.ns == lay.n_shared() && self.entries.len() == m
    }
}

/// Computes the update of one step of Algorithm 1.
///
/// `subs` lists `(numerator count, denominator count)` per submodel.
#[allow(clippy::too_many_arguments)]
pub fn step(
    data: &FitData,
    lay: &Layout,
    subs: &[(usize, usize)],
    basis: &Basis,
    eta: &[f64],
    method: IvMethod,
    solver: StepSolver,
    parallel: bool,
) -> Result<StepUpdate, RivError> {
    let inputs = StepInputs {
        data,
        lay,
        subs,
        basis,
        eta,
        method,
        parallel,
    };
    step_keeping(&inputs, solver, false).map(|r| r.0)
}

/// [`step`], also returning the factors a [`chord_step`] reuses when `keep` is set and
/// the solver is the structured one.
pub fn step_keeping(
    inputs: &StepInputs,
    solver: StepSolver,
    keep: bool,
) -> Result<(StepUpdate, Option<StepFactors>), RivError> {
    match solver {
        StepSolver::Structured => step_structured(inputs, keep),
        StepSolver::Dense => Ok((step_dense(inputs)?, None)),
    }
}

/// Lines per block of the structured step: `2 LINE_BLOCK x (nn + ns)` doubles per
/// matrix stay in the L2 cache for the wafer stage (about 60 columns), where filling
/// the whole `2n`-row matrices first and multiplying them after is bound by memory.
const LINE_BLOCK: usize = 256;

fn step_structured(
    inp: &StepInputs,
    keep: bool,
) -> Result<(StepUpdate, Option<StepFactors>), RivError> {
    let StepShape {
        n,
        m,
        nn,
        ns,
        ng,
        dg,
    } = inp.shape();
    let (data, basis, parallel) = (inp.data, inp.basis, inp.parallel);
    // the numerator blocks U^T S_e^2 U of all entries from the basis products they
    // share (crate::gram); the rest of Y_e^T X_e per entry
    let s2 = crate::gram::squared_scales(&data.sqrt_w, basis, m);
    let grams = crate::gram::numerator_grams(basis, nn, &s2, m, parallel);
    drop(s2);
    type Bufs = (Mat<f64>, Mat<f64>, Mat<f64>, Mat<f64>, EntryLines);
    let per_entry = |e: usize, bufs: &mut Bufs| -> Result<EntryParts, RivError> {
        let (y, x, zr, zl, el) = bufs;
        el.fill(e, data, basis, &ng, inp.be(e));
        // Y^T X with Y = [U | V_hat], X = [U | X']: the left block column is U^T U
        // (from `grams`) over V_hat^T U (`zl`), the right one Y^T X' (`zr`)
        for_each_line_block(inp, &dg, e, el, true, (y, x), |rows, acc, y, x| {
            let yb = y.as_ref().subrows(0, rows);
            matmul(
                zr.as_mut(),
                acc,
                yb.transpose(),
                x.as_ref().subrows(0, rows),
                1.0,
                Par::Seq,
            );
            matmul(
                zl.as_mut(),
                acc,
                yb.subcols(nn, ns).transpose(),
                yb.subcols(0, nn),
                1.0,
                Par::Seq,
            );
        });
        let mut h_nn = grams[e * nn * nn..(e + 1) * nn * nn].to_vec();
        // rhs: [H_ns | g_n]
        let mut rhs = vec![0.0; nn * (ns + 1)];
        for c in 0..=ns {
            for i in 0..nn {
                rhs[c * nn + i] = zr[(i, c)];
            }
        }
        let (h_d, cond) = spd_factor(&mut h_nn, nn).ok_or_else(|| RivError::Numerical {
            what: format!(
                "numerator block of entry G{}_{}",
                e % data.ny + 1,
                e / data.ny + 1
            ),
            why: "the numerator basis functions are linearly dependent over the weighted \
                  lines (two submodels with the same poles, or a mode with no weighted \
                  line near it); remove duplicate modes or widen the band"
                .into(),
        })?;
        spd_apply(&h_nn, &h_d, nn, &mut rhs, ns + 1);
        // S_e = H_ss - H_sn K ; r_e = g_s - H_sn k
        let mut s_mat = vec![0.0; ns * ns];
        for c in 0..ns {
            for r in 0..ns {
                let mut v = zr[(nn + r, c)];
                for t in 0..nn {
                    v -= zl[(r, t)] * rhs[c * nn + t];
                }
                s_mat[c * ns + r] = v;
            }
        }
        let k_vec = rhs[ns * nn..].to_vec();
        let r_vec = schur_rhs(zl, |r| zr[(nn + r, ns)], &k_vec);
        rhs.truncate(ns * nn);
        let kept = keep.then(|| (h_nn, h_d, zl.clone()));
        Ok(EntryParts {
            k_mat: rhs,
            k_vec,
            s_mat,
            r_vec,
            cond,
            kept,
        })
    };
    let init = || -> Bufs {
        (
            Mat::<f64>::zeros(2 * LINE_BLOCK.min(n), nn + ns),
            Mat::<f64>::zeros(2 * LINE_BLOCK.min(n), ns + 1),
            Mat::<f64>::zeros(nn + ns, ns + 1),
            Mat::<f64>::zeros(ns, nn),
            EntryLines::default(),
        )
    };
    let parts: Vec<EntryParts> = map_entries(m, parallel, init, per_entry)?;
    let mut s = Mat::<f64>::zeros(ns, ns);
    let mut r = vec![0.0; ns];
    let mut cond_num = 1.0f64;
    for p in &parts {
        for c in 0..ns {
            for rr in 0..ns {
                s[(rr, c)] += p.s_mat[c * ns + rr];
            }
        }
        for (ri, v) in r.iter_mut().zip(&p.r_vec) {
            *ri += v;
        }
        cond_num = cond_num.max(p.cond);
    }
    let (d_shared, cond_shared) = if ns == 0 {
        (Vec::new(), 1.0)
    } else {
        lu_solve(&s, &r).ok_or_else(|| RivError::Numerical {
            what: "shared denominator system (Schur complement)".into(),
            why: "singular: a mode has no weighted data near it, or two modes coincide; \
                  drop modes outside the band or duplicates"
                .into(),
        })?
    };
    let mut d_eta = vec![0.0; m * nn];
    for (e, p) in parts.iter().enumerate() {
        back_substitute(
            &p.k_vec,
            &p.k_mat,
            &d_shared,
            &mut d_eta[e * nn..(e + 1) * nn],
        );
    }
    let update = StepUpdate {
        d_shared,
        d_eta,
        cond_shared,
        cond_numerator: cond_num,
    };
    let factors = keep.then(|| StepFactors {
        nn,
        ns,
        entries: parts
            .into_iter()
            .map(|p| {
                let (l, d, h_sn) = p.kept.expect("kept when asked for");
                EntryFactor {
                    l,
                    d,
                    k_mat: p.k_mat,
                    h_sn,
                }
            })
            .collect(),
        schur: s,
        cond_numerator: cond_num,
    });
    Ok((update, factors))
}

/// `r_e = g_s - H_sn k_e`: the entry's right-hand side of the shared (Schur) system,
/// with `g_s(r)` the shared rows of `Y^T eps` and `k_e = H_nn^{-1} g_n`.
fn schur_rhs(h_sn: &Mat<f64>, g_s: impl Fn(usize) -> f64, k: &[f64]) -> Vec<f64> {
    (0..h_sn.nrows())
        .map(|r| {
            let mut v = g_s(r);
            for (t, kt) in k.iter().enumerate() {
                v -= h_sn[(r, t)] * kt;
            }
            v
        })
        .collect()
}

/// `d_eta_e = k_e - K_e d_shared` (the back-substitution of the eliminated numerators).
fn back_substitute(k_vec: &[f64], k_mat: &[f64], d_shared: &[f64], out: &mut [f64]) {
    let nn = k_vec.len();
    for t in 0..nn {
        let mut v = k_vec[t];
        for (c, ds) in d_shared.iter().enumerate() {
            v -= k_mat[c * nn + t] * ds;
        }
        out[t] = v;
    }
}

/// One step of Algorithm 1 with the matrix of an earlier iterate (`factors`, from
/// [`step_keeping`]) and the right-hand side `Y^T eps` of the current one: the chord
/// method (see [`StepFactors`]). Its fixed point is that of [`step`]; its cost is the
/// instrument's fill and one product with the residual per entry.
pub fn chord_step(inp: &StepInputs, factors: &StepFactors) -> Result<StepUpdate, RivError> {
    let StepShape {
        n,
        m,
        nn,
        ns,
        ng,
        dg,
    } = inp.shape();
    let (data, lay, basis, parallel) = (inp.data, inp.lay, inp.basis, inp.parallel);
    if !factors.fits(lay, m) {
        return Err(RivError::invalid(
            "step factors",
            format!(
                "{} x ({} + {})",
                factors.entries.len(),
                factors.nn,
                factors.ns
            ),
            format!("the problem is {m} x ({nn} + {ns})"),
        ));
    }
    type Bufs = (Mat<f64>, Mat<f64>, Mat<f64>, EntryLines);
    // per entry: k_e = H_nn^{-1} g_n and r_e = g_s - H_sn k_e
    let per_entry = |e: usize, bufs: &mut Bufs| -> Result<(Vec<f64>, Vec<f64>), RivError> {
        let (y, x, g, el) = bufs;
        el.fill(e, data, basis, &ng, inp.be(e));
        for_each_line_block(inp, &dg, e, el, false, (y, x), |rows, acc, y, x| {
            let (yb, eps) = (
                y.as_ref().subrows(0, rows),
                x.as_ref().subrows(0, rows).subcols(ns, 1),
            );
            matmul(g.as_mut(), acc, yb.transpose(), eps, 1.0, Par::Seq);
        });
        let ef = &factors.entries[e];
        let mut k: Vec<f64> = (0..nn).map(|i| g[(i, 0)]).collect();
        spd_apply(&ef.l, &ef.d, nn, &mut k, 1);
        let r = schur_rhs(&ef.h_sn, |row| g[(nn + row, 0)], &k);
        Ok((k, r))
    };
    let init = || -> Bufs {
        (
            Mat::<f64>::zeros(2 * LINE_BLOCK.min(n), nn + ns),
            Mat::<f64>::zeros(2 * LINE_BLOCK.min(n), ns + 1),
            Mat::<f64>::zeros(nn + ns, 1),
            EntryLines::default(),
        )
    };
    let parts: Vec<(Vec<f64>, Vec<f64>)> = map_entries(m, parallel, init, per_entry)?;
    let mut r = vec![0.0; ns];
    for (_, re) in &parts {
        for (ri, v) in r.iter_mut().zip(re) {
            *ri += v;
        }
    }
    let (d_shared, cond_shared) = if ns == 0 {
        (Vec::new(), 1.0)
    } else {
        lu_solve(&factors.schur, &r).ok_or_else(|| RivError::Numerical {
            what: "shared denominator system (Schur complement) of the chord step".into(),
            why: "singular".into(),
        })?
    };
    let mut d_eta = vec![0.0; m * nn];
    for (e, (k, _)) in parts.iter().enumerate() {
        back_substitute(
            k,
            &factors.entries[e].k_mat,
            &d_shared,
            &mut d_eta[e * nn..(e + 1) * nn],
        );
    }
    Ok(StepUpdate {
        d_shared,
        d_eta,
        cond_shared,
        cond_numerator: factors.cond_numerator,
    })
}

/// The dense reference: forms the full `(ns + m nn)` square system from the same
/// columns (entries stacked), and solves it by an equilibrated LU. For small problems
/// and tests only: its cost grows with the square of `m nn`.
fn step_dense(inp: &StepInputs) -> Result<StepUpdate, RivError> {
    let StepShape {
        n,
        m,
        nn,
        ns,
        ng,
        dg,
    } = inp.shape();
    let (data, basis) = (inp.data, inp.basis);
    let ptot = ns + m * nn;
    // Full instrument and regressor: rows 2n per entry, columns [shared | eta_0 | ..].
    let mut yf = Mat::<f64>::zeros(2 * n * m, ptot);
    let mut xf = Mat::<f64>::zeros(2 * n * m, ptot + 1);
    let mut y = Mat::<f64>::zeros(2 * n, nn + ns);
    let mut x = Mat::<f64>::zeros(2 * n, ns + 1);
    let mut el = EntryLines::default();
    for e in 0..m {
        el.fill(e, data, basis, &ng, inp.be(e));
        fill_entry(inp, &dg, e, 0..n, &el, true, &mut y, &mut x);
        for row in 0..2 * n {
            let rr = e * 2 * n + row;
            for c in 0..ns {
                yf[(rr, c)] = y[(row, nn + c)];
                xf[(rr, c)] = x[(row, c)];
            }
            for t in 0..nn {
                yf[(rr, ns + e * nn + t)] = y[(row, t)];
                xf[(rr, ns + e * nn + t)] = y[(row, t)];
            }
            xf[(rr, ptot)] = x[(row, ns)];
        }
    }
    let mut z = Mat::<f64>::zeros(ptot, ptot + 1);
    matmul(
        z.as_mut(),
        Accum::Replace,
        yf.transpose(),
        xf.as_ref(),
        1.0,
        Par::Seq,
    );
    let a = Mat::from_fn(ptot, ptot, |i, j| z[(i, j)]);
    let b: Vec<f64> = (0..ptot).map(|i| z[(i, ptot)]).collect();
    let (sol, cond) = lu_solve(&a, &b).ok_or_else(|| RivError::Numerical {
        what: "dense step system".into(),
        why: "singular".into(),
    })?;
    Ok(StepUpdate {
        d_shared: sol[..ns].to_vec(),
        d_eta: sol[ns..].to_vec(),
        cond_shared: cond,
        cond_numerator: cond,
    })
}
