//! Balanced truncation of a [`ModalModel`] with its rigid-body part kept exactly.
//!
//! `P(s) = P_rb(s) + P_s(s) + D`, with `P_rb = sum_k R_k / s^k` the rigid-body
//! (integrator) part, `P_s` the strictly stable part (pole pairs and real poles) and `D`
//! the feedthrough. The rigid-body part has infinite Hankel singular values and is no
//! part of the reduction: it is split off first and kept bit for bit, as is `D`; only
//! `P_s` is reduced, by balanced truncation (B. C. Moore, "Principal component analysis
//! in linear systems: controllability, observability, and model reduction", IEEE TAC
//! 26(1), 1981). With the Hankel singular values `sigma_1 >= ... >= sigma_n` of `P_s`
//! and `r` states kept, the a-priori bound
//!
//! `||P - P_r||_inf <= 2 (sigma_{r+1} + ... + sigma_n)`
//!
//! holds (D. Enns, 1984; K. Glover, "All optimal Hankel-norm approximations of linear
//! multivariable systems and their L-infinity error bounds", Int. J. Control 39(6),
//! 1984, Theorem 9.7; each singular value counted with its multiplicity, so the bound is
//! the conservative form). Any pole on or to the right of the imaginary axis other than
//! the rigid-body poles at the origin (an undamped mode, a real pole at `s >= 0`) is an
//! error ([`RealizeError::Unstable`]): it has no finite Hankel singular value and is not
//! an integrator this module knows how to keep.
//!
//! Numerics, in the modal basis where everything is explicit:
//!
//! 1. Realization: each residue is split into its SVD dyads at working precision
//!    (Gilbert's realization, as in [`ModalModel::to_state_space`]); a dyad
//!    `sigma u v^H` of the pair `p` gives the complex diagonal states `(p, conj p)` with
//!    `b = sqrt(sigma) v^H`, `c = sqrt(sigma) u` and their conjugates.
//! 2. Gramians: with `A = diag(lambda)` the Lyapunov equations
//!    `A P + P A^H + B B^H = 0` and `A^H Q + Q A + C^H C = 0` are solved entry by entry,
//!    `P_ij = -(B B^H)_ij / (lambda_i + conj lambda_j)` and
//!    `Q_ij = -(C^H C)_ij / (conj lambda_i + lambda_j)` (the diagonal case of the
//!    Bartels-Stewart algorithm; R. H. Bartels and G. W. Stewart, Comm. ACM 15(9),
//!    1972): one division per entry, relative accuracy at working precision for any
//!    damping (a mode with damping `zeta` has `lambda + conj lambda = -2 zeta |p|`, which
//!    is exact). The unitary `T` that turns each complex pair into the real block
//!    `[[Re p, Im p], [-Im p, Re p]]` makes them real: `P_r = T^H P T`, `Q_r = T^H Q T`.
//! 3. Square roots: each gramian is scaled to unit diagonal, `P = D P~ D`, so that modes
//!    whose gramian entries differ by many decades (lightly damped low modes against
//!    well damped high ones) do not lose digits to each other; `P~ = V L V^T`
//!    (symmetric EVD, roundoff-negative eigenvalues set to zero) gives the factor
//!    `L_c = D V L^(1/2)` with `P = L_c L_c^T`, and likewise `L_o` for `Q`.
//! 4. Balancing by the square-root method (A. J. Laub, M. T. Heath, C. C. Paige and
//!    R. C. Ward, "Computation of system balancing transformations and other
//!    applications of simultaneous diagonalization algorithms", IEEE TAC 32(2), 1987;
//!    M. S. Tombs and I. Postlethwaite, Int. J. Control 46(4), 1987): the SVD
//!    `L_o^T L_c = U S V^T` holds the Hankel singular values in `S`; with the first `r`
//!    columns, `T_l = S_r^(-1/2) U_r^T L_o^T` and `T_r = L_c V_r S_r^(-1/2)`
//!    (`T_l T_r = I`) give `A_r = T_l A T_r`, `B_r = T_l B`, `C_r = C T_r`.
//! 5. The reduced real `(A_r, B_r, C_r)` goes back to modal form by its eigenvectors
//!    ([`StateSpace::to_modal_with_tol`] with tolerance 0: there is no pole at the origin
//!    in it), so the result is again a [`ModalModel`]: the model file's currency. The
//!    conversion is measured, not assumed: [`BalancedReduction::conversion_error`] is
//!    the largest singular value of the difference between the balanced state space and
//!    the modal form on a dense grid (roundoff amplified by the condition of the reduced
//!    eigenvectors, largest when reduced poles nearly coincide).
//!
//! Choice of order. The order `N` of [`BalancedTruncation::reduce`] counts every state of
//! the reduced model, the rigid-body states included (as `balred` counts the unstable
//! part): `N = n_rb + r`. Refused, with an error that says which orders are possible:
//! `N = 0`; `N < n_rb` (the rigid body is kept whole); `N > n_rb + n_s`; an `r` that
//! would keep a Hankel singular value at roundoff level (below
//! [`BalancedTruncation::min_hsv_rel`] of the largest: the balancing transformation
//! divides by its square root); and an `r` that cuts between two equal Hankel singular
//! values (within [`BalancedTruncation::tie_tol`]), where the truncated model is not
//! unique (and for two equal values from a complex pair not even real). The two nearly
//! equal values of one lightly damped mode are not equal in this sense (they differ by
//! about its damping): cutting between them is allowed and is what the bound describes,
//! but it leaves a real pole where the mode was, which is rarely what one wants; the
//! printed list shows the values in pairs.

use crate::convert::{truncated_svd_c, truncated_svd_r};
use crate::{ModalModel, RealizeError, ResponseGrid, StateSpace, TimeDomain, C64};
use faer::{Mat, Side};

/// Settings of the balanced truncation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BalancedTruncation {
    /// Two Hankel singular values `s_r >= s_{r+1}` count as equal when
    /// `s_r - s_{r+1} <= tie_tol * s_r`; an order that cuts between them is refused.
    /// Default `1e-8` (far below the relative split `~zeta` of a lightly damped mode's
    /// pair, far above the roundoff of the SVD that computes them).
    pub tie_tol: f64,
    /// Hankel singular values below `min_hsv_rel` times the largest are at roundoff level
    /// (the realization is numerically not minimal there) and cannot be kept. Default
    /// `1e-12`.
    pub min_hsv_rel: f64,
}

impl Default for BalancedTruncation {
    fn default() -> Self {
        Self {
            tie_tol: 1e-8,
            min_hsv_rel: 1e-12,
        }
    }
}

/// The Hankel singular values of a model's stable part and the orders around them.
#[derive(Debug, Clone, PartialEq)]
pub struct HankelAnalysis {
    /// Hankel singular values of the strictly stable part, descending, one per state
    /// of its (working-precision minimal) realization.
    pub hankel_singular_values: Vec<f64>,
    /// States of the rigid-body part, kept exactly (its Hankel singular values are
    /// infinite).
    pub rigid_order: usize,
    /// States of the stable part, `hankel_singular_values.len()`.
    pub stable_order: usize,
}

impl HankelAnalysis {
    /// The a-priori bound `2 sum_{k > r} sigma_k` on the H-infinity norm of the error
    /// when `r` stable states are kept (0 for `r >= stable_order`).
    pub fn error_bound(&self, kept_stable: usize) -> f64 {
        2.0 * self
            .hankel_singular_values
            .iter()
            .skip(kept_stable)
            .fold(0.0, |acc, s| acc + s)
    }
}

/// A balanced truncation: the reduced model and what bounds its error.
#[derive(Debug, Clone, PartialEq)]
pub struct BalancedReduction {
    /// The reduced model in modal form: the original rigid-body part and feedthrough
    /// (bit for bit), the reduced stable part (pairs sorted by frequency).
    pub model: ModalModel,
    /// The reduced model as a real continuous state space: the rigid-body block of
    /// [`ModalModel::to_state_space`] followed by [`BalancedReduction::balanced`]; `D`
    /// is the feedthrough.
    pub state_space: StateSpace,
    /// The balanced reduced stable part alone (`A_r`, `B_r`, `C_r` of step 4 of the
    /// [module documentation](self), `D = 0`): the model the bound is about, before the
    /// conversion to modal form.
    pub balanced: StateSpace,
    /// `max sigma_max` of the difference between [`BalancedReduction::balanced`] and the
    /// stable part of [`BalancedReduction::model`] on [`hinf_grid`]`(.., 50)`: what the
    /// conversion to modal form (step 5) changed. Roundoff, amplified by the condition of
    /// the reduced eigenvectors (nearly equal reduced poles, e.g. from a mode with a
    /// rank-2 residue, make it largest); so the modal model's error is at most
    /// `error_bound + conversion_error` on that grid.
    pub conversion_error: f64,
    /// Every Hankel singular value of the original stable part, descending.
    pub hankel_singular_values: Vec<f64>,
    /// `2 sum` of the discarded Hankel singular values: `||P - P_r||_inf <= error_bound`.
    pub error_bound: f64,
    /// States of the reduced model, `rigid_order + stable_order`.
    pub order: usize,
    /// States of the rigid-body part (kept).
    pub rigid_order: usize,
    /// Stable states kept.
    pub stable_order: usize,
}

/// The stable part in both the complex diagonal and the real block-diagonal basis.
struct StableRealization {
    /// Poles, one per state (a pair gives `p, conj p`).
    lambda: Vec<C64>,
    /// Complex diagonal input rows, `n x nu`.
    bc: Mat<C64>,
    /// Complex diagonal output columns, `ny x n`.
    cc: Mat<C64>,
    /// Offsets of the `2 x 2` pair blocks (the other states are real poles).
    pair_offsets: Vec<usize>,
    /// Real block-diagonal `A`, `B`, `C`.
    a: Mat<f64>,
    b: Mat<f64>,
    c: Mat<f64>,
}

fn unstable(what: String, pole: C64) -> RealizeError {
    RealizeError::Unstable {
        what,
        pole,
        why: "balanced truncation reduces the strictly stable part and keeps only the \
              rigid-body poles at the origin exactly"
            .into(),
    }
}

impl StableRealization {
    fn new(model: &ModalModel) -> Result<Self, RealizeError> {
        let (ny, nu) = (model.ny, model.nu);
        // (pole, b row, c column) per complex diagonal state
        let mut states: Vec<(C64, Vec<C64>, Vec<C64>)> = Vec::new();
        let mut pair_offsets = Vec::new();
        for (k, p) in model.pairs.iter().enumerate() {
            if p.pole.re >= 0.0 {
                return Err(unstable(format!("pairs[{k}]"), p.pole));
            }
            // the upper pole by convention; a stored lower one is the same pair
            let (pole, conj) = if p.pole.im >= 0.0 {
                (p.pole, false)
            } else {
                (p.pole.conj(), true)
            };
            let res = if conj {
                Mat::from_fn(ny, nu, |i, j| p.residue[(i, j)].conj())
            } else {
                p.residue.clone()
            };
            for d in truncated_svd_c(&res, 0.0, &format!("pairs[{k}].residue"))? {
                let g = d.sigma.sqrt();
                let b: Vec<C64> = d.v.iter().map(|v| v.conj() * g).collect();
                let c: Vec<C64> = d.u.iter().map(|u| u * g).collect();
                pair_offsets.push(states.len());
                let (bb, cb) = (
                    b.iter().map(|x| x.conj()).collect(),
                    c.iter().map(|x| x.conj()).collect(),
                );
                states.push((pole, b, c));
                states.push((pole.conj(), bb, cb));
            }
        }
        for (k, p) in model.real_poles.iter().enumerate() {
            if p.pole >= 0.0 {
                return Err(unstable(format!("real_poles[{k}]"), C64::new(p.pole, 0.0)));
            }
            for d in truncated_svd_r(&p.residue, 0.0, &format!("real_poles[{k}].residue"))? {
                let g = d.sigma.sqrt();
                states.push((
                    C64::new(p.pole, 0.0),
                    d.v.iter().map(|v| C64::new(v * g, 0.0)).collect(),
                    d.u.iter().map(|u| C64::new(u * g, 0.0)).collect(),
                ));
            }
        }
        let n = states.len();
        let lambda: Vec<C64> = states.iter().map(|s| s.0).collect();
        let bc = Mat::from_fn(n, nu, |i, j| states[i].1[j]);
        let cc = Mat::from_fn(ny, n, |i, j| states[j].2[i]);
        // Real block-diagonal form: T^H diag(p, conj p) T = [[Re p, Im p], [-Im p, Re p]],
        // T^H [b; conj b] = sqrt2 [Re b; -Im b], [c, conj c] T = sqrt2 [Re c, Im c].
        let mut a = Mat::zeros(n, n);
        let mut b = Mat::zeros(n, nu);
        let mut c = Mat::zeros(ny, n);
        let s2 = std::f64::consts::SQRT_2;
        let mut is_pair = vec![false; n];
        for &o in &pair_offsets {
            is_pair[o] = true;
            is_pair[o + 1] = true;
            let p = lambda[o];
            a[(o, o)] = p.re;
            a[(o + 1, o + 1)] = p.re;
            a[(o, o + 1)] = p.im;
            a[(o + 1, o)] = -p.im;
            for j in 0..nu {
                b[(o, j)] = s2 * bc[(o, j)].re;
                b[(o + 1, j)] = -s2 * bc[(o, j)].im;
            }
            for i in 0..ny {
                c[(i, o)] = s2 * cc[(i, o)].re;
                c[(i, o + 1)] = s2 * cc[(i, o)].im;
            }
        }
        for k in (0..n).filter(|&k| !is_pair[k]) {
            a[(k, k)] = lambda[k].re;
            for j in 0..nu {
                b[(k, j)] = bc[(k, j)].re;
            }
            for i in 0..ny {
                c[(i, k)] = cc[(i, k)].re;
            }
        }
        Ok(Self {
            lambda,
            bc,
            cc,
            pair_offsets,
            a,
            b,
            c,
        })
    }

    fn n(&self) -> usize {
        self.lambda.len()
    }

    /// `T^H X T` for a complex `X` in the diagonal basis, real part (the imaginary part
    /// is roundoff: the gramians of a real system are real in the real basis).
    fn to_real_basis(&self, x: &Mat<C64>) -> Mat<f64> {
        let n = self.n();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        // T: identity except the pair blocks [[1, -j], [1, j]] / sqrt2
        let mut t = Mat::<C64>::zeros(n, n);
        for k in 0..n {
            t[(k, k)] = C64::new(1.0, 0.0);
        }
        for &o in &self.pair_offsets {
            t[(o, o)] = C64::new(h, 0.0);
            t[(o, o + 1)] = C64::new(0.0, -h);
            t[(o + 1, o)] = C64::new(h, 0.0);
            t[(o + 1, o + 1)] = C64::new(0.0, h);
        }
        let y = t.adjoint() * x * &t;
        // symmetrise: the exact result is symmetric
        Mat::from_fn(n, n, |i, j| 0.5 * (y[(i, j)].re + y[(j, i)].re))
    }

    /// Controllability and observability gramians in the real basis (module docs, step 2).
    fn gramians(&self) -> (Mat<f64>, Mat<f64>) {
        let n = self.n();
        let l = &self.lambda;
        let bbh = &self.bc * self.bc.adjoint();
        let chc = self.cc.adjoint() * &self.cc;
        let p = Mat::from_fn(n, n, |i, j| -bbh[(i, j)] / (l[i] + l[j].conj()));
        let q = Mat::from_fn(n, n, |i, j| -chc[(i, j)] / (l[i].conj() + l[j]));
        (self.to_real_basis(&p), self.to_real_basis(&q))
    }
}

/// `L` with `G = L L^T` for a symmetric positive semidefinite gramian `G`, by the EVD of
/// its unit-diagonal scaling (module docs, step 3).
fn sqrt_factor(g: &Mat<f64>, what: &str) -> Result<Mat<f64>, RealizeError> {
    let n = g.nrows();
    let d: Vec<f64> = (0..n).map(|i| g[(i, i)].max(0.0).sqrt()).collect();
    if let Some(i) = d.iter().position(|&x| !(x > 0.0 && x.is_finite())) {
        return Err(RealizeError::Numerical {
            what: format!("{what} gramian"),
            why: format!(
                "diagonal entry {i} is {} (a state without input or output)",
                g[(i, i)]
            ),
        });
    }
    let scaled = Mat::from_fn(n, n, |i, j| g[(i, j)] / (d[i] * d[j]));
    let evd = scaled
        .self_adjoint_eigen(Side::Lower)
        .map_err(|_| RealizeError::Numerical {
            what: format!("eigendecomposition of the scaled {what} gramian"),
            why: "did not converge".into(),
        })?;
    let s = evd.S().column_vector();
    let u = evd.U();
    Ok(Mat::from_fn(n, n, |i, k| {
        d[i] * u[(i, k)] * s[k].max(0.0).sqrt()
    }))
}

/// The balancing SVD of a stable realization: `(U, S, V)` of `L_o^T L_c` and the factors.
struct Balancing {
    hsv: Vec<f64>,
    u: Mat<f64>,
    v: Mat<f64>,
    lc: Mat<f64>,
    lo: Mat<f64>,
}

fn balance(sr: &StableRealization) -> Result<Balancing, RealizeError> {
    let n = sr.n();
    if n == 0 {
        return Ok(Balancing {
            hsv: Vec::new(),
            u: Mat::zeros(0, 0),
            v: Mat::zeros(0, 0),
            lc: Mat::zeros(0, 0),
            lo: Mat::zeros(0, 0),
        });
    }
    let (p, q) = sr.gramians();
    let lc = sqrt_factor(&p, "controllability")?;
    let lo = sqrt_factor(&q, "observability")?;
    let m = lo.transpose() * &lc;
    let svd = m.svd().map_err(|_| RealizeError::Numerical {
        what: "SVD of L_o^T L_c (Hankel singular values)".into(),
        why: "did not converge".into(),
    })?;
    let s = svd.S().column_vector();
    let hsv: Vec<f64> = (0..n).map(|k| s[k]).collect();
    if hsv.iter().any(|x| !x.is_finite()) {
        return Err(RealizeError::Numerical {
            what: "Hankel singular values".into(),
            why: "not finite".into(),
        });
    }
    Ok(Balancing {
        hsv,
        u: svd.U().to_owned(),
        v: svd.V().to_owned(),
        lc,
        lo,
    })
}

/// The rigid-body part alone (no stable part, zero feedthrough).
fn rigid_only(model: &ModalModel) -> ModalModel {
    let mut r = ModalModel::new(model.ny, model.nu);
    r.rigid = model.rigid.clone();
    r
}

impl BalancedTruncation {
    fn check(&self) -> Result<(), RealizeError> {
        for (name, v) in [("tie_tol", self.tie_tol), ("min_hsv_rel", self.min_hsv_rel)] {
            if !(v.is_finite() && (0.0..1.0).contains(&v)) {
                return Err(RealizeError::InvalidParameter {
                    name: name.into(),
                    value: v,
                    why: "must be in [0, 1)".into(),
                });
            }
        }
        Ok(())
    }

    /// The Hankel singular values of `model`'s stable part and the state counts, without
    /// reducing anything. Errors as [`BalancedTruncation::reduce`] for unstable poles.
    pub fn analyse(&self, model: &ModalModel) -> Result<HankelAnalysis, RealizeError> {
        self.check()?;
        model.validate()?;
        let sr = StableRealization::new(model)?;
        let bal = balance(&sr)?;
        Ok(HankelAnalysis {
            stable_order: sr.n(),
            hankel_singular_values: bal.hsv,
            rigid_order: rigid_only(model).order(0.0),
        })
    }

    /// Balanced truncation of `model` to `order` states in all (the rigid-body states
    /// included, see the [module documentation](self) for which orders are refused):
    /// the rigid-body part and the feedthrough are kept exactly, the stable part is
    /// reduced to `order - rigid_order` states.
    pub fn reduce(
        &self,
        model: &ModalModel,
        order: usize,
    ) -> Result<BalancedReduction, RealizeError> {
        self.check()?;
        model.validate()?;
        let (ny, nu) = (model.ny, model.nu);
        let sr = StableRealization::new(model)?;
        let n = sr.n();
        let rigid_ss = rigid_only(model).to_state_space(0.0)?;
        let n_rb = rigid_ss.n_states();
        let bad = |why: String| RealizeError::InvalidParameter {
            name: "order".into(),
            value: order as f64,
            why,
        };
        if order == 0 {
            return Err(bad(format!(
                "a model needs at least one state (this one has {n_rb} rigid-body and {n} \
                 stable states)"
            )));
        }
        if order < n_rb {
            return Err(bad(format!(
                "the rigid-body part alone has {n_rb} states, which are kept exactly: the \
                 order must be at least {n_rb}"
            )));
        }
        if order > n_rb + n {
            return Err(bad(format!(
                "the model has {} states ({n_rb} rigid-body, {n} stable): the order must be \
                 at most {}",
                n_rb + n,
                n_rb + n
            )));
        }
        let r = order - n_rb;
        let bal = balance(&sr)?;
        let hsv = &bal.hsv;
        if r > 0 {
            let top = hsv[0];
            let m = hsv
                .iter()
                .take_while(|&&s| s > self.min_hsv_rel * top)
                .count();
            if r > m {
                return Err(bad(format!(
                    "it keeps a Hankel singular value at roundoff level ({:.3e}, below \
                     {:.0e} of the largest): the numerically minimal order is {}",
                    hsv[r - 1],
                    self.min_hsv_rel,
                    n_rb + m
                )));
            }
            if r < n && hsv[r - 1] - hsv[r] <= self.tie_tol * hsv[r - 1] {
                return Err(bad(format!(
                    "it cuts between two equal Hankel singular values ({:.6e} and {:.6e}): \
                     the truncation is not unique there; choose {} or {}",
                    hsv[r - 1],
                    hsv[r],
                    order - 1,
                    order + 1
                )));
            }
        }
        let error_bound = 2.0 * hsv[r..].iter().fold(0.0, |acc, s| acc + s);

        // Reduced stable part (step 4), then its modal form (step 5).
        let (ar, br, cr) = if r == 0 {
            (Mat::zeros(0, 0), Mat::zeros(0, nu), Mat::zeros(ny, 0))
        } else {
            let w: Vec<f64> = hsv[..r].iter().map(|s| 1.0 / s.sqrt()).collect();
            // T_l = S^-1/2 U_r^T L_o^T (r x n), T_r = L_c V_r S^-1/2 (n x r)
            let ut = Mat::from_fn(r, n, |k, i| w[k] * bal.u[(i, k)]);
            let tl = &ut * bal.lo.transpose();
            let vr = Mat::from_fn(n, r, |i, k| bal.v[(i, k)] * w[k]);
            let tr = &bal.lc * &vr;
            (&tl * &sr.a * &tr, &tl * &sr.b, &sr.c * &tr)
        };
        let reduced = StateSpace::new(ar, br, cr, Mat::zeros(ny, nu), TimeDomain::Continuous)?;
        let mut stable = reduced.to_modal_with_tol(0.0)?;
        if !stable.rigid.is_empty() {
            return Err(RealizeError::Numerical {
                what: "balanced truncation".into(),
                why: "the reduced stable part has a pole at the origin".into(),
            });
        }
        if let Some((k, p)) = stable
            .pairs
            .iter()
            .enumerate()
            .find(|(_, p)| p.pole.re >= 0.0)
        {
            return Err(RealizeError::Numerical {
                what: "balanced truncation".into(),
                why: format!(
                    "the reduced pole pair {k} at {} is not stable (roundoff at a near tie \
                     of Hankel singular values?)",
                    p.pole
                ),
            });
        }
        if let Some(p) = stable.real_poles.iter().find(|p| p.pole >= 0.0) {
            return Err(RealizeError::Numerical {
                what: "balanced truncation".into(),
                why: format!("the reduced real pole {} is not stable", p.pole),
            });
        }
        stable
            .pairs
            .sort_by(|a, b| a.pole.norm().total_cmp(&b.pole.norm()));
        stable.real_poles.sort_by(|a, b| b.pole.total_cmp(&a.pole));
        let reduced_model = ModalModel {
            ny,
            nu,
            rigid: model.rigid.clone(),
            pairs: stable.pairs,
            real_poles: stable.real_poles,
            feedthrough: model.feedthrough.clone(),
        };
        let state_space = block_diag(&rigid_ss, &reduced, &model.feedthrough)?;
        let stable_modal = ModalModel {
            rigid: Vec::new(),
            feedthrough: Mat::zeros(ny, nu),
            ..reduced_model.clone()
        };
        let conversion_error = if r == 0 {
            0.0
        } else {
            let grid = hinf_grid(&[model, &reduced_model], 50);
            let g_ss = reduced.freq_response(&grid)?;
            max_sv_grid_difference(&g_ss, &stable_modal.freq_response(&grid)?)?
        };
        Ok(BalancedReduction {
            model: reduced_model,
            state_space,
            balanced: reduced,
            conversion_error,
            hankel_singular_values: bal.hsv,
            error_bound,
            order,
            rigid_order: n_rb,
            stable_order: r,
        })
    }
}

/// `[[A1, 0], [0, A2]]`, `[B1; B2]`, `[C1, C2]`, `D`.
fn block_diag(s1: &StateSpace, s2: &StateSpace, d: &Mat<f64>) -> Result<StateSpace, RealizeError> {
    let (n1, n2) = (s1.n_states(), s2.n_states());
    let n = n1 + n2;
    let a = Mat::from_fn(n, n, |i, j| match (i < n1, j < n1) {
        (true, true) => s1.a[(i, j)],
        (false, false) => s2.a[(i - n1, j - n1)],
        _ => 0.0,
    });
    let b = Mat::from_fn(n, d.ncols(), |i, j| {
        if i < n1 {
            s1.b[(i, j)]
        } else {
            s2.b[(i - n1, j)]
        }
    });
    let c = Mat::from_fn(d.nrows(), n, |i, j| {
        if j < n1 {
            s1.c[(i, j)]
        } else {
            s2.c[(i, j - n1)]
        }
    });
    StateSpace::new(a, b, c, d.clone(), TimeDomain::Continuous)
}

/// [`BalancedTruncation::reduce`] with the default settings.
pub fn balanced_truncation(
    model: &ModalModel,
    order: usize,
) -> Result<BalancedReduction, RealizeError> {
    BalancedTruncation::default().reduce(model, order)
}

/// A dense logarithmic grid (rad/s) for measuring the H-infinity norm of a difference of
/// modal models: `per_decade` points per decade from a decade below the slowest to a
/// decade above the fastest pole of any of `models` (1 rad/s .. 10 rad/s for models
/// without poles), and, since the peaks of lightly damped modes are narrow, for each
/// pole pair `p` the points `Im p` and `Im p (1 +- k zeta / 4)`, `k = 1..4`, and `|p|`.
pub fn hinf_grid(models: &[&ModalModel], per_decade: usize) -> Vec<f64> {
    let mut mags: Vec<f64> = Vec::new();
    let mut w: Vec<f64> = Vec::new();
    for m in models {
        for p in &m.pairs {
            let wn = p.pole.norm();
            if wn > 0.0 && wn.is_finite() {
                mags.push(wn);
                let wd = p.pole.im.abs();
                let zeta = (-p.pole.re / wn).clamp(0.0, 1.0);
                w.push(wn);
                for k in -4..=4 {
                    let x = wd * (1.0 + k as f64 * zeta / 4.0);
                    if x > 0.0 {
                        w.push(x);
                    }
                }
            }
        }
        mags.extend(
            m.real_poles
                .iter()
                .map(|p| p.pole.abs())
                .filter(|x| *x > 0.0 && x.is_finite()),
        );
    }
    let lo = mags.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = mags.iter().copied().fold(0.0, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > 0.0 {
        (lo / 10.0, hi * 10.0)
    } else {
        (1.0, 10.0)
    };
    let decades = (hi / lo).log10();
    let n = ((decades * per_decade.max(1) as f64).ceil() as usize).max(2);
    for k in 0..=n {
        w.push(lo * 10f64.powf(decades * k as f64 / n as f64));
    }
    w.sort_by(f64::total_cmp);
    w.dedup();
    w
}

/// `max_k sigma_max(P_a(j w_k) - P_b(j w_k))`: the H-infinity norm of the difference
/// measured on the grid `omega` (a lower bound of the true norm, which the grid's
/// density makes tight). The difference is evaluated as one model (rigid-body
/// coefficients and feedthroughs subtracted, the poles of both with the residues of `b`
/// negated), so that equal integrators cancel exactly instead of leaving the roundoff of
/// two large `R / w^2` at low frequencies.
pub fn max_sv_difference(
    a: &ModalModel,
    b: &ModalModel,
    omega: &[f64],
) -> Result<f64, RealizeError> {
    if (a.ny, a.nu) != (b.ny, b.nu) {
        return Err(RealizeError::Dimension {
            what: "second model".into(),
            expected: format!("{}x{}", a.ny, a.nu),
            got: format!("{}x{}", b.ny, b.nu),
        });
    }
    a.validate()?;
    b.validate()?;
    let (ny, nu) = (a.ny, a.nu);
    let l = a.rigid.len().max(b.rigid.len());
    let zero = Mat::<f64>::zeros(ny, nu);
    let mut diff = ModalModel::new(ny, nu);
    diff.rigid = (0..l)
        .map(|k| {
            let (ra, rb) = (
                a.rigid.get(k).unwrap_or(&zero),
                b.rigid.get(k).unwrap_or(&zero),
            );
            ra - rb
        })
        .collect();
    while diff.rigid.last().is_some_and(|r| r.norm_l2() == 0.0) {
        diff.rigid.pop();
    }
    diff.pairs = a.pairs.clone();
    diff.pairs.extend(b.pairs.iter().map(|p| crate::PolePair {
        pole: p.pole,
        residue: Mat::from_fn(ny, nu, |i, j| -p.residue[(i, j)]),
    }));
    diff.real_poles = a.real_poles.clone();
    diff.real_poles
        .extend(b.real_poles.iter().map(|p| crate::RealPole {
            pole: p.pole,
            residue: Mat::from_fn(ny, nu, |i, j| -p.residue[(i, j)]),
        }));
    diff.feedthrough = &a.feedthrough - &b.feedthrough;
    let g = diff.freq_response(omega)?;
    max_sv_grid_difference(&g, &ResponseGrid::zeros(omega.len(), ny, nu))
}

/// `max_k sigma_max(G_a[k] - G_b[k])` of two responses on the same grid.
pub fn max_sv_grid_difference(ga: &ResponseGrid, gb: &ResponseGrid) -> Result<f64, RealizeError> {
    if (ga.len(), ga.ny, ga.nu) != (gb.len(), gb.ny, gb.nu) {
        return Err(RealizeError::Dimension {
            what: "second response".into(),
            expected: format!("{} points of {}x{}", ga.len(), ga.ny, ga.nu),
            got: format!("{} points of {}x{}", gb.len(), gb.ny, gb.nu),
        });
    }
    let (ny, nu) = (ga.ny, ga.nu);
    let mut worst: f64 = 0.0;
    for k in 0..ga.len() {
        let (la, lb) = (ga.line(k), gb.line(k));
        let d = Mat::from_fn(ny, nu, |i, j| la[j * ny + i] - lb[j * ny + i]);
        let s = d.singular_values().map_err(|_| RealizeError::Numerical {
            what: "SVD of the response difference".into(),
            why: "did not converge".into(),
        })?;
        worst = worst.max(s.first().copied().unwrap_or(0.0));
    }
    Ok(worst)
}
