//! Conversions between [`ModalModel`] and a real [`StateSpace`].
//!
//! - [`ModalModel::to_state_space`]: a real block-diagonal (real modal form) continuous
//!   realization. Each residue is reduced to its numerical rank by an SVD (Gilbert's
//!   realization, E. G. Gilbert, "Controllability and observability in multivariable
//!   control systems", SIAM J. Control 1963): a pole pair with a rank-`r` residue becomes
//!   `r` real `2 x 2` blocks `[[sigma, omega], [-omega, sigma]]`, a real pole with a
//!   rank-`r` residue `r` states. The rigid-body part `sum_k R_k / s^k` is realized
//!   minimally: as `rank(R_l)` integrator chains of length `l` when it is a single term
//!   `R_l / s^l` (a free mass: `R_2 / s^2` gives `rank(R_2)` double integrators), and in
//!   general by the Ho–Kalman algorithm (B. L. Ho and R. E. Kalman, 1966) on the block
//!   Hankel matrix of its Markov parameters `R_1..R_l`, which has finite rank because the
//!   part is nilpotent.
//! - [`StateSpace::to_modal`]: the inverse for a continuous model. The eigenvalues at
//!   (numerically) zero are separated from the rest by a block diagonalisation that never
//!   uses an eigenvector of the zero cluster (which is defective for double integrators):
//!   the eigenvectors of the other eigenvalues span their invariant subspace, its
//!   orthogonal complement completes the basis, and a Sylvester equation removes the
//!   coupling. The nilpotent part then gives `sum_k C0 N^(k-1) B0 / s^k` exactly, and the
//!   rest is read off the eigenvectors (the nonzero part must be diagonalizable).
//!
//! Rank decisions: a singular value counts when it exceeds
//! `max(rank_tol, max(rows, cols) eps)` times the largest singular value of the same
//! matrix, so `rank_tol = 0` gives the numerical rank at working precision.

use crate::{ModalModel, PolePair, RealPole, RealizeError, StateSpace, TimeDomain, C64};
use faer::linalg::solvers::Solve;
use faer::Mat;

/// Default relative tolerance of [`StateSpace::to_modal`]: eigenvalues with
/// `|lambda| <= 1e-4 ||A||_F` are treated as poles at the origin. A Jordan block of size
/// `k` at zero (a chain of `k` integrators) splits in floating point into eigenvalues of
/// size about `eps^(1/k) ||A||`: `1.5e-8 ||A||` for a double integrator, `6e-6 ||A||` for
/// a triple one, both below this. Poles that are genuinely that slow compared with the
/// fastest dynamics need [`StateSpace::to_modal_with_tol`] with a smaller tolerance.
pub const DEFAULT_ZERO_TOL: f64 = 1e-4;

fn check_rank_tol(rank_tol: f64) -> Result<(), RealizeError> {
    if rank_tol.is_finite() && rank_tol >= 0.0 {
        Ok(())
    } else {
        Err(RealizeError::InvalidParameter {
            name: "rank_tol".into(),
            value: rank_tol,
            why: "the rank tolerance must be finite and >= 0".into(),
        })
    }
}

fn svd_failed(what: &str) -> RealizeError {
    RealizeError::Numerical {
        what: format!("SVD of {what}"),
        why: "did not converge".into(),
    }
}

/// One dyad `sigma u v^H` of a truncated SVD.
pub(crate) struct Dyad<T> {
    pub(crate) sigma: f64,
    pub(crate) u: Vec<T>,
    pub(crate) v: Vec<T>,
}

/// The dyads of the SVD of a complex matrix whose singular values exceed
/// `max(rank_tol, max(rows, cols) eps) * sigma_max`: `R ~ sum sigma u v^H`.
pub(crate) fn truncated_svd_c(
    r: &Mat<C64>,
    rank_tol: f64,
    what: &str,
) -> Result<Vec<Dyad<C64>>, RealizeError> {
    if r.nrows() == 0 || r.ncols() == 0 {
        return Ok(Vec::new());
    }
    let svd = r.thin_svd().map_err(|_| svd_failed(what))?;
    let s = svd.S().column_vector();
    let smax = s[0].re;
    let rank_tol = rank_tol.max(r.nrows().max(r.ncols()) as f64 * f64::EPSILON);
    let mut out = Vec::new();
    for k in 0..s.nrows() {
        let sk = s[k].re;
        if sk.is_nan() || sk <= rank_tol * smax || sk == 0.0 {
            break;
        }
        out.push(Dyad {
            sigma: sk,
            u: (0..r.nrows()).map(|i| svd.U()[(i, k)]).collect(),
            v: (0..r.ncols()).map(|j| svd.V()[(j, k)]).collect(),
        });
    }
    Ok(out)
}

/// Real counterpart of [`truncated_svd_c`]: `R ~ sum sigma u v^T`.
pub(crate) fn truncated_svd_r(
    r: &Mat<f64>,
    rank_tol: f64,
    what: &str,
) -> Result<Vec<Dyad<f64>>, RealizeError> {
    if r.nrows() == 0 || r.ncols() == 0 {
        return Ok(Vec::new());
    }
    let svd = r.thin_svd().map_err(|_| svd_failed(what))?;
    let s = svd.S().column_vector();
    let smax = s[0];
    let rank_tol = rank_tol.max(r.nrows().max(r.ncols()) as f64 * f64::EPSILON);
    let mut out = Vec::new();
    for k in 0..s.nrows() {
        let sk = s[k];
        if sk.is_nan() || sk <= rank_tol * smax || sk == 0.0 {
            break;
        }
        out.push(Dyad {
            sigma: sk,
            u: (0..r.nrows()).map(|i| svd.U()[(i, k)]).collect(),
            v: (0..r.ncols()).map(|j| svd.V()[(j, k)]).collect(),
        });
    }
    Ok(out)
}

/// A real block of a block-diagonal realization: `A` (square), `B` rows, `C` columns.
struct Block {
    a: Mat<f64>,
    b: Mat<f64>,
    c: Mat<f64>,
}

/// How the rigid-body part is realized.
enum RigidPlan {
    /// No poles at the origin.
    None,
    /// `R_l / s^l` alone: chains of `l` integrators, one per dyad of `R_l`.
    Chains { l: usize, dyads: Vec<Dyad<f64>> },
    /// General: Ho–Kalman on the block Hankel matrix of `R_1..R_l`.
    Hankel { l: usize },
}

fn fro(m: &Mat<f64>) -> f64 {
    m.norm_l2()
}

impl ModalModel {
    /// Index one past the last nonzero rigid-body coefficient.
    fn rigid_len(&self) -> usize {
        self.rigid
            .iter()
            .rposition(|r| fro(r) > 0.0)
            .map_or(0, |k| k + 1)
    }

    fn rigid_plan(&self, rank_tol: f64) -> Result<RigidPlan, RealizeError> {
        let l = self.rigid_len();
        if l == 0 {
            return Ok(RigidPlan::None);
        }
        let last = fro(&self.rigid[l - 1]);
        if self.rigid[..l - 1]
            .iter()
            .all(|r| fro(r) <= rank_tol * last)
        {
            let dyads = truncated_svd_r(&self.rigid[l - 1], rank_tol, "rigid-body coefficient")?;
            Ok(RigidPlan::Chains { l, dyads })
        } else {
            Ok(RigidPlan::Hankel { l })
        }
    }

    /// The block Hankel matrix `[R_{i+j+1+shift}]_{i,j=0..l-1}` (zero beyond `R_l`).
    fn rigid_hankel(&self, l: usize, shift: usize) -> Mat<f64> {
        let (ny, nu) = (self.ny, self.nu);
        Mat::from_fn(l * ny, l * nu, |r, c| {
            let (bi, i) = (r / ny, r % ny);
            let (bj, j) = (c / nu, c % nu);
            let k = bi + bj + shift;
            match self.rigid.get(k) {
                // (shape-checked here too: `order` runs on unvalidated models)
                Some(r) if k < l && i < r.nrows() && j < r.ncols() => r[(i, j)],
                _ => 0.0,
            }
        })
    }

    /// Minimal realization of the rigid-body part (see the module documentation).
    fn rigid_block(&self, rank_tol: f64) -> Result<Option<Block>, RealizeError> {
        let (ny, nu) = (self.ny, self.nu);
        match self.rigid_plan(rank_tol)? {
            RigidPlan::None => Ok(None),
            RigidPlan::Chains { l, dyads } => {
                let r = dyads.len();
                let n = l * r;
                let mut a = Mat::zeros(n, n);
                let mut b = Mat::zeros(n, nu);
                let mut c = Mat::zeros(ny, n);
                for (q, d) in dyads.iter().enumerate() {
                    let o = q * l;
                    for i in 0..l - 1 {
                        a[(o + i, o + i + 1)] = 1.0;
                    }
                    let g = d.sigma.sqrt();
                    for j in 0..nu {
                        b[(o + l - 1, j)] = g * d.v[j];
                    }
                    for i in 0..ny {
                        c[(i, o)] = g * d.u[i];
                    }
                }
                Ok(Some(Block { a, b, c }))
            }
            RigidPlan::Hankel { l } => {
                let h = self.rigid_hankel(l, 0);
                let hs = self.rigid_hankel(l, 1);
                let dyads = truncated_svd_r(&h, rank_tol, "rigid-body Hankel matrix")?;
                let n = dyads.len();
                // O = U S^1/2, Ctrb = S^1/2 V^T, A = S^-1/2 U^T H_shift V S^-1/2.
                let c = Mat::from_fn(ny, n, |i, k| dyads[k].u[i] * dyads[k].sigma.sqrt());
                let b = Mat::from_fn(n, nu, |k, j| dyads[k].v[j] * dyads[k].sigma.sqrt());
                let a = Mat::from_fn(n, n, |p, q| {
                    let (dp, dq) = (&dyads[p], &dyads[q]);
                    let mut s = 0.0;
                    for (r, &up) in dp.u.iter().enumerate() {
                        if up == 0.0 {
                            continue;
                        }
                        for (cc, &vq) in dq.v.iter().enumerate() {
                            s += up * hs[(r, cc)] * vq;
                        }
                    }
                    s / (dp.sigma.sqrt() * dq.sigma.sqrt())
                });
                Ok(Some(Block { a, b, c }))
            }
        }
    }

    /// A real block-diagonal continuous [`StateSpace`] realization of this model (see the
    /// [module documentation](crate::convert)): the rigid-body part first, then one
    /// `2 x 2` block `[[sigma, omega], [-omega, sigma]]` per retained singular value of
    /// each pole pair's residue (`p = sigma + j omega`), then the real poles; `D` is the
    /// feedthrough. Singular values below `rank_tol` times the largest of the same matrix
    /// are dropped (`rank_tol = 0`: the numerical rank at working precision, see the
    /// [module documentation](crate::convert)), so the state dimension is
    /// [`ModalModel::order`]`(rank_tol)`.
    pub fn to_state_space(&self, rank_tol: f64) -> Result<StateSpace, RealizeError> {
        check_rank_tol(rank_tol)?;
        self.validate()?;
        let (ny, nu) = (self.ny, self.nu);
        let mut blocks: Vec<Block> = Vec::new();
        if let Some(b) = self.rigid_block(rank_tol)? {
            blocks.push(b);
        }
        for (k, p) in self.pairs.iter().enumerate() {
            let (sigma, omega) = (p.pole.re, p.pole.im);
            for d in truncated_svd_c(&p.residue, rank_tol, &format!("pairs[{k}].residue"))? {
                // R/(s-p) + conj(R)/(s - conj p) with R = x y^T, x = sqrt(2 sigma) u,
                // y = sqrt(sigma / 2) conj(v): C = [Re x, Im x], B = [2 Re y; -2 Im y].
                let g = (2.0 * d.sigma).sqrt();
                let a = Mat::from_fn(2, 2, |i, j| match (i, j) {
                    (0, 0) | (1, 1) => sigma,
                    (0, 1) => omega,
                    _ => -omega,
                });
                let b = Mat::from_fn(2, nu, |i, j| {
                    let y = d.v[j].conj();
                    if i == 0 {
                        g * y.re
                    } else {
                        -g * y.im
                    }
                });
                let c = Mat::from_fn(ny, 2, |i, j| {
                    let x = d.u[i];
                    if j == 0 {
                        g * x.re
                    } else {
                        g * x.im
                    }
                });
                blocks.push(Block { a, b, c });
            }
        }
        for (k, p) in self.real_poles.iter().enumerate() {
            for d in truncated_svd_r(&p.residue, rank_tol, &format!("real_poles[{k}].residue"))? {
                let g = d.sigma.sqrt();
                blocks.push(Block {
                    a: Mat::from_fn(1, 1, |_, _| p.pole),
                    b: Mat::from_fn(1, nu, |_, j| g * d.v[j]),
                    c: Mat::from_fn(ny, 1, |i, _| g * d.u[i]),
                });
            }
        }
        let n: usize = blocks.iter().map(|b| b.a.nrows()).sum();
        let mut a = Mat::zeros(n, n);
        let mut b = Mat::zeros(n, nu);
        let mut c = Mat::zeros(ny, n);
        let mut o = 0;
        for blk in &blocks {
            let m = blk.a.nrows();
            for i in 0..m {
                for j in 0..m {
                    a[(o + i, o + j)] = blk.a[(i, j)];
                }
                for j in 0..nu {
                    b[(o + i, j)] = blk.b[(i, j)];
                }
            }
            for i in 0..ny {
                for j in 0..m {
                    c[(i, o + j)] = blk.c[(i, j)];
                }
            }
            o += m;
        }
        StateSpace::new(a, b, c, self.feedthrough.clone(), TimeDomain::Continuous)
    }

    /// The number of states of [`ModalModel::to_state_space`]`(rank_tol)`, the minimal
    /// order at that tolerance: `2 rank(R)` per pole pair, `rank(R)` per real pole, and
    /// for the rigid-body part `l rank(R_l)` when it is `R_l / s^l` alone, the rank of
    /// the block Hankel matrix of `R_1..R_l` otherwise. A residue whose SVD fails to
    /// converge (non-finite entries) counts with full rank `min(ny, nu)`.
    pub fn order(&self, rank_tol: f64) -> usize {
        let full = self.ny.min(self.nu);
        let rank_c = |r: &Mat<C64>| truncated_svd_c(r, rank_tol, "").map_or(full, |d| d.len());
        let rank_r = |r: &Mat<f64>| truncated_svd_r(r, rank_tol, "").map_or(full, |d| d.len());
        let rigid = match self.rigid_plan(rank_tol) {
            Ok(RigidPlan::None) => 0,
            Ok(RigidPlan::Chains { l, dyads }) => l * dyads.len(),
            Ok(RigidPlan::Hankel { l }) => truncated_svd_r(&self.rigid_hankel(l, 0), rank_tol, "")
                .map_or(l * full, |d| d.len()),
            Err(_) => self.rigid_len() * full,
        };
        rigid
            + self
                .pairs
                .iter()
                .map(|p| 2 * rank_c(&p.residue))
                .sum::<usize>()
            + self
                .real_poles
                .iter()
                .map(|p| rank_r(&p.residue))
                .sum::<usize>()
    }

    /// This model with every residue (pole pairs, real poles, and each rigid-body
    /// coefficient separately) replaced by its SVD truncated at `rank_tol` times its
    /// largest singular value. A matrix whose SVD fails to converge is kept as it is.
    pub fn reduce_rank(&self, rank_tol: f64) -> ModalModel {
        let tol = if rank_tol.is_finite() && rank_tol >= 0.0 {
            rank_tol
        } else {
            0.0
        };
        let trunc_c = |r: &Mat<C64>| match truncated_svd_c(r, tol, "") {
            Ok(d) => Mat::from_fn(r.nrows(), r.ncols(), |i, j| {
                d.iter()
                    .map(|d| d.u[i] * d.v[j].conj() * d.sigma)
                    .sum::<C64>()
            }),
            Err(_) => r.clone(),
        };
        let trunc_r = |r: &Mat<f64>| match truncated_svd_r(r, tol, "") {
            Ok(d) => Mat::from_fn(r.nrows(), r.ncols(), |i, j| {
                d.iter().map(|d| d.u[i] * d.v[j] * d.sigma).sum::<f64>()
            }),
            Err(_) => r.clone(),
        };
        ModalModel {
            ny: self.ny,
            nu: self.nu,
            rigid: self.rigid.iter().map(trunc_r).collect(),
            pairs: self
                .pairs
                .iter()
                .map(|p| PolePair {
                    pole: p.pole,
                    residue: trunc_c(&p.residue),
                })
                .collect(),
            real_poles: self
                .real_poles
                .iter()
                .map(|p| RealPole {
                    pole: p.pole,
                    residue: trunc_r(&p.residue),
                })
                .collect(),
            feedthrough: self.feedthrough.clone(),
        }
    }
}

fn evd_failed(what: &str) -> RealizeError {
    RealizeError::Numerical {
        what: format!("eigendecomposition of {what}"),
        why: "did not converge".into(),
    }
}

/// Relative distance below which eigenvalues form one (semisimple, repeated) pole.
const CLUSTER_TOL: f64 = 1e-10;

/// Largest acceptable condition number of the (column-normalised) eigenvector basis.
const MAX_EIGVEC_COND: f64 = 1e10;

/// A group of (numerically) equal eigenvalues: the pole and a basis of its eigenspace.
struct Cluster {
    pole: C64,
    /// Eigenvectors, `n` entries each (complex for a pair, real parts for a real pole).
    vectors: Vec<Vec<C64>>,
}

/// Groups `idx` (indices into `values`) into clusters of equal eigenvalues.
fn cluster(values: &[C64], idx: &[usize]) -> Vec<Vec<usize>> {
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for &i in idx {
        let l = values[i];
        match groups
            .iter_mut()
            .find(|g| (values[g[0]] - l).norm() <= CLUSTER_TOL * l.norm())
        {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    groups
}

/// Eigenvectors of the cluster `members` of `a`: the computed eigenvector for a simple
/// eigenvalue; for a repeated one the null space of `A - lambda I` (right singular
/// vectors of its `k` smallest singular values), which is well defined where single
/// eigenvectors are not. Fails when the null space is smaller than the multiplicity
/// (a defective eigenvalue).
fn cluster_basis(
    a: &Mat<f64>,
    values: &[C64],
    vectors: &Mat<C64>,
    members: &[usize],
) -> Result<Cluster, RealizeError> {
    let n = a.nrows();
    let k = members.len();
    let pole = members.iter().map(|&i| values[i]).sum::<C64>() / k as f64;
    if k == 1 {
        let j = members[0];
        return Ok(Cluster {
            pole,
            vectors: vec![(0..n).map(|i| vectors[(i, j)]).collect()],
        });
    }
    let defective = || RealizeError::Numerical {
        what: "to_modal".into(),
        why: format!(
            "the eigenvalue {pole} of multiplicity {k} is defective (A is not \
             diagonalizable away from 0)"
        ),
    };
    if pole.im == 0.0 {
        let shifted = Mat::from_fn(n, n, |i, j| a[(i, j)] - if i == j { pole.re } else { 0.0 });
        let svd = shifted.svd().map_err(|_| svd_failed("A - lambda I"))?;
        let s = svd.S().column_vector();
        let small = s[n - k];
        if small.is_nan() || small > 1e-8 * s[0].max(pole.norm()) {
            return Err(defective());
        }
        let v = svd.V();
        Ok(Cluster {
            pole,
            vectors: (n - k..n)
                .map(|c| (0..n).map(|i| C64::new(v[(i, c)], 0.0)).collect())
                .collect(),
        })
    } else {
        let shifted = Mat::from_fn(n, n, |i, j| {
            C64::new(a[(i, j)], 0.0) - if i == j { pole } else { C64::new(0.0, 0.0) }
        });
        let svd = shifted.svd().map_err(|_| svd_failed("A - lambda I"))?;
        let s = svd.S().column_vector();
        let small = s[n - k].re;
        if small.is_nan() || small > 1e-8 * s[0].re.max(pole.norm()) {
            return Err(defective());
        }
        let v = svd.V();
        Ok(Cluster {
            pole,
            vectors: (n - k..n)
                .map(|c| (0..n).map(|i| v[(i, c)]).collect())
                .collect(),
        })
    }
}

impl StateSpace {
    /// [`StateSpace::to_modal_with_tol`] with [`DEFAULT_ZERO_TOL`].
    pub fn to_modal(&self) -> Result<ModalModel, RealizeError> {
        self.to_modal_with_tol(DEFAULT_ZERO_TOL)
    }

    /// The modal (partial-fraction) form of a continuous model.
    ///
    /// 1. Eigenvalues (faer's real EVD) with `|lambda| <= zero_tol ||A||_F` are the poles
    ///    at the origin (`m` of them); the others are grouped into clusters of equal
    ///    eigenvalues (relative distance `1e-10`: repeated modes). Each cluster's
    ///    eigenspace is the computed eigenvector for a simple eigenvalue and the null
    ///    space of `A - lambda I` (SVD) for a repeated one.
    /// 2. `V` = the real and imaginary parts of these eigenvectors (`n - m` columns) span
    ///    the invariant subspace of the nonzero eigenvalues; `Z` = an orthonormal basis
    ///    of its orthogonal complement. With `T = [Z, V]`,
    ///    `T^-1 A T = [[N, 0], [X, Lambda]]` is block lower triangular with `N` holding
    ///    the zero eigenvalues (exactly, even for defective `A`: no eigenvector of the
    ///    zero cluster is used) and `Lambda` real block diagonal.
    /// 3. The Sylvester equation `Lambda Y - Y N + X = 0` decouples the blocks (it
    ///    separates into one small `m x m` solve per eigenvector, since `Lambda` is block
    ///    diagonal; Golub & Van Loan, *Matrix Computations*, 4th ed., sec. 7.6.3, block
    ///    diagonalization). Then the rigid-body part is
    ///    `rigid[k-1] = (C Z + C V Y) N^(k-1) B_Z`, `k = 1..m`, exactly (double and triple
    ///    integrators included; terms at roundoff level of their factors are set to zero
    ///    and trailing zero terms dropped), and an eigenvalue `lambda` with eigenvectors
    ///    `v_i` has the residue `sum_i (C v_i) (r_re,i - j r_im,i) / 2`, where
    ///    `r_re,i, r_im,i` are the rows of `B_V - Y B_Z` of `Re v_i` and `Im v_i`
    ///    (`(C v_i) r_i` for a real pole).
    ///
    /// Complex eigenvalues become [`PolePair`]s (`Im > 0`), real ones [`RealPole`]s, `D`
    /// the feedthrough. The nonzero eigenvalues must be non-defective: a defective
    /// repeated eigenvalue, or an eigenvector basis with condition number above `1e10`,
    /// is a [`RealizeError::Numerical`].
    pub fn to_modal_with_tol(&self, zero_tol: f64) -> Result<ModalModel, RealizeError> {
        if self.domain != TimeDomain::Continuous {
            return Err(RealizeError::WrongDomain {
                op: "to_modal".into(),
                needed: "continuous-time".into(),
            });
        }
        self.validate()?;
        if !(zero_tol.is_finite() && zero_tol >= 0.0) {
            return Err(RealizeError::InvalidParameter {
                name: "zero_tol".into(),
                value: zero_tol,
                why: "the tolerance must be finite and >= 0".into(),
            });
        }
        let (n, ny, nu) = (self.n_states(), self.ny(), self.nu());
        let mut model = ModalModel::new(ny, nu);
        model.feedthrough = self.d.clone();
        if n == 0 {
            return Ok(model);
        }
        let a = &self.a;
        let thresh = zero_tol * a.norm_l2();

        // 1. Eigenvalues, the zero cluster, and eigenspaces of the others.
        let e = a.eigen().map_err(|_| evd_failed("A"))?;
        let values: Vec<C64> = (0..n).map(|i| e.S().column_vector()[i]).collect();
        let vectors = Mat::from_fn(n, n, |i, j| e.U()[(i, j)]);
        let (mut upper, mut reals, mut lower, mut m) = (Vec::new(), Vec::new(), 0usize, 0usize);
        for (i, l) in values.iter().enumerate() {
            if !(l.re.is_finite() && l.im.is_finite()) {
                return Err(evd_failed("A"));
            }
            if l.norm() <= thresh {
                m += 1;
            } else if l.im > 0.0 {
                upper.push(i);
            } else if l.im == 0.0 {
                reals.push(i);
            } else {
                lower += 1;
            }
        }
        if lower != upper.len() {
            return Err(RealizeError::Numerical {
                what: "eigendecomposition of A".into(),
                why: "complex eigenvalues are not in conjugate pairs".into(),
            });
        }
        let pair_clusters = cluster(&values, &upper)
            .iter()
            .map(|g| cluster_basis(a, &values, &vectors, g))
            .collect::<Result<Vec<_>, _>>()?;
        let real_clusters = cluster(&values, &reals)
            .iter()
            .map(|g| cluster_basis(a, &values, &vectors, g))
            .collect::<Result<Vec<_>, _>>()?;

        // 2. V (realified eigenvectors, interleaved Re/Im per vector), Z, T = [Z, V].
        // Each eigenvector is scaled to unit norm as a whole (Re v and Im v by the same
        // factor, which keeps the 2 x 2 block structure of Lambda).
        let unit = |v: &Vec<C64>| -> Vec<C64> {
            let nrm = v.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt();
            let f = if nrm > 0.0 { 1.0 / nrm } else { 1.0 };
            v.iter().map(|x| x * f).collect()
        };
        let mut vcols: Vec<Vec<f64>> = Vec::with_capacity(n - m);
        for c in &pair_clusters {
            for v in c.vectors.iter().map(unit) {
                vcols.push(v.iter().map(|x| x.re).collect());
                vcols.push(v.iter().map(|x| x.im).collect());
            }
        }
        for c in &real_clusters {
            for v in c.vectors.iter().map(unit) {
                vcols.push(v.iter().map(|x| x.re).collect());
            }
        }
        if vcols.len() + m != n {
            return Err(RealizeError::Numerical {
                what: "to_modal".into(),
                why: "eigenvector count does not match the number of states".into(),
            });
        }
        let nv = n - m;
        let v = Mat::from_fn(n, nv, |i, j| vcols[j][i]);
        let z: Mat<f64> = if nv == 0 {
            Mat::identity(n, n)
        } else {
            let svd = v.svd().map_err(|_| svd_failed("eigenvector basis"))?;
            let s = svd.S().column_vector();
            if s[nv - 1].is_nan() || s[nv - 1] * MAX_EIGVEC_COND <= s[0] {
                return Err(RealizeError::Numerical {
                    what: "to_modal".into(),
                    why: format!(
                        "the eigenvectors of the nonzero eigenvalues are (nearly) dependent \
                         (condition number {:e}): A is not diagonalizable away from 0",
                        s[0] / s[nv - 1]
                    ),
                });
            }
            Mat::from_fn(n, m, |i, j| svd.U()[(i, nv + j)])
        };
        let t = Mat::from_fn(n, n, |i, j| if j < m { z[(i, j)] } else { v[(i, j - m)] });
        let az = a * &z;
        let rhs = Mat::from_fn(n, nu + m, |i, j| {
            if j < nu {
                self.b[(i, j)]
            } else {
                az[(i, j - nu)]
            }
        });
        let sol = t.partial_piv_lu().solve(&rhs);
        if !(0..sol.ncols()).all(|j| (0..n).all(|i| sol[(i, j)].is_finite())) {
            return Err(RealizeError::Numerical {
                what: "to_modal".into(),
                why: "the modal transformation is singular".into(),
            });
        }
        let bz = Mat::from_fn(m, nu, |i, j| sol[(i, j)]);
        let nmat = Mat::from_fn(m, m, |i, j| sol[(i, nu + j)]);
        let x = Mat::from_fn(nv, m, |i, j| sol[(m + i, nu + j)]);

        // 3. Y from Lambda Y - Y N + X = 0, row (pair of rows) by row.
        let mut y = Mat::<f64>::zeros(nv, m);
        if m > 0 {
            let mut row = 0;
            let poles = pair_clusters
                .iter()
                .flat_map(|c| c.vectors.iter().map(move |_| (c.pole, true)))
                .chain(
                    real_clusters
                        .iter()
                        .flat_map(|c| c.vectors.iter().map(move |_| (c.pole, false))),
                );
            for (pole, is_pair) in poles {
                // u (lambda I - N) = -(x_p - j x_q) (pair) or -x_p (real).
                let lhs = Mat::from_fn(m, m, |i, j| {
                    (if i == j { pole } else { C64::new(0.0, 0.0) }) - nmat[(j, i)]
                });
                let r = Mat::from_fn(m, 1, |i, _| {
                    let xq = if is_pair { x[(row + 1, i)] } else { 0.0 };
                    -C64::new(x[(row, i)], -xq)
                });
                let u = lhs.partial_piv_lu().solve(&r);
                for i in 0..m {
                    y[(row, i)] = u[(i, 0)].re;
                    if is_pair {
                        y[(row + 1, i)] = -u[(i, 0)].im;
                    }
                }
                row += if is_pair { 2 } else { 1 };
            }
        }
        let bv = Mat::from_fn(nv, nu, |i, j| sol[(m + i, j)]);
        let bv = if m > 0 { &bv - &y * &bz } else { bv };
        let cv = &self.c * &v;

        // Rigid-body part: (C Z + C V Y) N^(k-1) B_Z.
        if m > 0 {
            let cz = &self.c * &z + &cv * &y;
            let (nc, nb, nn) = (cz.norm_l2(), bz.norm_l2(), nmat.norm_l2());
            let mut rigid = Vec::with_capacity(m);
            let mut xk = bz.clone();
            let mut bound = nc * nb;
            for _ in 0..m {
                let r = &cz * &xk;
                if r.norm_l2() <= 1e-12 * bound {
                    rigid.push(Mat::zeros(ny, nu));
                } else {
                    rigid.push(r);
                }
                xk = &nmat * &xk;
                bound *= nn;
            }
            while rigid.last().is_some_and(|r| fro(r) == 0.0) {
                rigid.pop();
            }
            model.rigid = rigid;
        }

        // Residues.
        let mut col = 0;
        for c in &pair_clusters {
            let mut residue = Mat::<C64>::zeros(ny, nu);
            for _ in &c.vectors {
                for i in 0..ny {
                    let cvi = C64::new(cv[(i, col)], cv[(i, col + 1)]);
                    for j in 0..nu {
                        residue[(i, j)] += cvi * C64::new(bv[(col, j)], -bv[(col + 1, j)]) * 0.5;
                    }
                }
                col += 2;
            }
            model.pairs.push(PolePair {
                pole: c.pole,
                residue,
            });
        }
        for c in &real_clusters {
            let mut residue = Mat::<f64>::zeros(ny, nu);
            for _ in &c.vectors {
                for i in 0..ny {
                    for j in 0..nu {
                        residue[(i, j)] += cv[(i, col)] * bv[(col, j)];
                    }
                }
                col += 1;
            }
            model.real_poles.push(RealPole {
                pole: c.pole.re,
                residue,
            });
        }
        model.validate()?;
        Ok(model)
    }
}
