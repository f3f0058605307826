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
//!   (numerically) zero are separated from the rest by a block diagonalisation whose zero
//!   block is exact even for defective `A`: the invariant subspace of the zero eigenvalues
//!   is the orthogonal complement of the *left* invariant subspace of the others, which the
//!   left eigenvectors span. The nilpotent part then gives `sum_k C0 N^(k-1) B0 / s^k`
//!   exactly (double integrators included), and the rest is read off the eigenvectors
//!   (the nonzero part must be diagonalizable).

use crate::{ModalModel, PolePair, RealPole, RealizeError, StateSpace, TimeDomain, C64};
use faer::linalg::solvers::Solve;
use faer::Mat;

/// Default relative tolerance of [`StateSpace::to_modal`]: eigenvalues with
/// `|lambda| <= 1e-6 ||A||_F` are treated as poles at the origin (a double integrator's
/// pair splits by about `sqrt(eps ||A||)` in floating point, a triple one by
/// `(eps ||A||^2)^(1/3)`, both far below this).
pub const DEFAULT_ZERO_TOL: f64 = 1e-6;

/// Relative distance below which eigenvalues of [`StateSpace::to_modal`] are merged into
/// one pole with the summed residue (repeated modes of a block-diagonal realization).
const MERGE_TOL: f64 = 1e-13;

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
struct Dyad<T> {
    sigma: f64,
    u: Vec<T>,
    v: Vec<T>,
}

/// The dyads of the SVD of a complex matrix whose singular values exceed
/// `rank_tol * sigma_max` (all nonzero ones when `rank_tol = 0`): `R ~ sum sigma u v^H`.
fn truncated_svd_c(
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
    let mut out = Vec::new();
    for k in 0..s.nrows() {
        let sk = s[k].re;
        if !(sk > rank_tol * smax) || sk == 0.0 {
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
fn truncated_svd_r(
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
    let mut out = Vec::new();
    for k in 0..s.nrows() {
        let sk = s[k];
        if !(sk > rank_tol * smax) || sk == 0.0 {
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
            if k < l {
                self.rigid[k][(i, j)]
            } else {
                0.0
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
    /// are dropped (`rank_tol = 0` keeps every nonzero one), so the state dimension is
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

/// Eigenvalues and eigenvectors of a real matrix, split into the near-zero ones (indices
/// only) and the others: `pairs` (Im > 0) and `reals` (Im = 0).
struct SplitEigen {
    values: Vec<C64>,
    vectors: Mat<C64>,
    zero: usize,
    pairs: Vec<usize>,
    reals: Vec<usize>,
}

fn split_eigen(a: &Mat<f64>, thresh: f64, what: &str) -> Result<SplitEigen, RealizeError> {
    let e = a.eigen().map_err(|_| evd_failed(what))?;
    let n = a.nrows();
    let s = e.S().column_vector();
    let values: Vec<C64> = (0..n).map(|i| s[i]).collect();
    let vectors = Mat::from_fn(n, n, |i, j| e.U()[(i, j)]);
    let mut zero = 0;
    let mut pairs = Vec::new();
    let mut reals = Vec::new();
    let mut lower = 0;
    for (i, l) in values.iter().enumerate() {
        if !(l.re.is_finite() && l.im.is_finite()) {
            return Err(evd_failed(what));
        }
        if l.norm() <= thresh {
            zero += 1;
        } else if l.im > 0.0 {
            pairs.push(i);
        } else if l.im == 0.0 {
            reals.push(i);
        } else {
            lower += 1;
        }
    }
    if lower != pairs.len() {
        return Err(RealizeError::Numerical {
            what: format!("eigendecomposition of {what}"),
            why: "complex eigenvalues are not in conjugate pairs".into(),
        });
    }
    Ok(SplitEigen {
        values,
        vectors,
        zero,
        pairs,
        reals,
    })
}

/// Real basis of the span of the selected eigenvectors: `[Re v, Im v]` per pair, `Re v`
/// per real eigenvalue.
fn realify(e: &SplitEigen) -> Mat<f64> {
    let n = e.vectors.nrows();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    for &j in &e.pairs {
        cols.push((0..n).map(|i| e.vectors[(i, j)].re).collect());
        cols.push((0..n).map(|i| e.vectors[(i, j)].im).collect());
    }
    for &j in &e.reals {
        cols.push((0..n).map(|i| e.vectors[(i, j)].re).collect());
    }
    Mat::from_fn(n, cols.len(), |i, j| cols[j][i])
}

impl StateSpace {
    /// [`StateSpace::to_modal_with_tol`] with [`DEFAULT_ZERO_TOL`].
    pub fn to_modal(&self) -> Result<ModalModel, RealizeError> {
        self.to_modal_with_tol(DEFAULT_ZERO_TOL)
    }

    /// The modal (partial-fraction) form of a continuous model.
    ///
    /// Eigenvalues with `|lambda| <= zero_tol ||A||_F` are poles at the origin. With `U0`
    /// an orthonormal basis of their invariant subspace (the orthogonal complement of the
    /// left eigenvectors of the other eigenvalues, so no eigenvector of the possibly
    /// defective zero cluster is ever used) and `V1` the real and imaginary parts of the
    /// right eigenvectors of the others, `T = [U0, V1]` block-diagonalises `A`:
    /// `T^-1 A T = diag(N, Lambda)`. The nilpotent block gives the rigid-body part
    /// `rigid[k-1] = C U0 N^(k-1) (T^-1 B)_0` exactly (Jordan chains such as double
    /// integrators included; terms at roundoff level of their factors are set to zero and
    /// trailing zero terms dropped); every other eigenvalue `lambda` with right
    /// eigenvector `v` gives the residue `(C v) (w^T B)` with `w^T` the matching row of
    /// `T^-1` (for a pair the rows of `Re v` and `Im v` combine to `(r_re - j r_im) / 2`).
    /// Complex eigenvalues become [`PolePair`]s (`Im > 0`), real ones [`RealPole`]s;
    /// eigenvalues equal to `1e-13` relative are merged (residues summed). `D` becomes
    /// the feedthrough. The nonzero eigenvalues must be non-defective.
    pub fn to_modal_with_tol(&self, zero_tol: f64) -> Result<ModalModel, RealizeError> {
        if self.domain != TimeDomain::Continuous {
            return Err(RealizeError::WrongDomain {
                op: "to_modal".into(),
                needed: "continuous-time".into(),
            });
        }
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
        let thresh = zero_tol * self.a.norm_l2();
        let right = split_eigen(&self.a, thresh, "A")?;
        let m = right.zero;
        // Orthonormal basis U0 of the zero-eigenvalue invariant subspace.
        let u0: Mat<f64> = if m == 0 {
            Mat::zeros(n, 0)
        } else if m == n {
            Mat::identity(n, n)
        } else {
            let at = self.a.transpose().to_owned();
            let left = split_eigen(&at, thresh, "A^T")?;
            if left.zero != m {
                return Err(RealizeError::Numerical {
                    what: "to_modal".into(),
                    why: format!(
                        "A has {m} eigenvalues below the zero threshold {thresh:e} but A^T has \
                         {}; choose another zero_tol",
                        left.zero
                    ),
                });
            }
            let w = realify(&left);
            let svd = w.svd().map_err(|_| svd_failed("left eigenvectors"))?;
            let s = svd.S().column_vector();
            let k = n - m;
            if !(s[k - 1] > 1e3 * f64::EPSILON * n as f64 * s[0]) {
                return Err(RealizeError::Numerical {
                    what: "to_modal".into(),
                    why: "the left eigenvectors of the nonzero eigenvalues are linearly \
                          dependent (defective nonzero eigenvalue)"
                        .into(),
                });
            }
            Mat::from_fn(n, m, |i, j| svd.U()[(i, k + j)])
        };
        let v1 = realify(&right);
        let t = Mat::from_fn(n, n, |i, j| if j < m { u0[(i, j)] } else { v1[(i, j - m)] });
        let au0 = &self.a * &u0;
        let rhs = Mat::from_fn(n, nu + m, |i, j| {
            if j < nu {
                self.b[(i, j)]
            } else {
                au0[(i, j - nu)]
            }
        });
        let sol = t.partial_piv_lu().solve(&rhs);
        if !(0..sol.ncols()).all(|j| (0..n).all(|i| sol[(i, j)].is_finite())) {
            return Err(RealizeError::Numerical {
                what: "to_modal".into(),
                why: "the modal transformation is singular (defective nonzero eigenvalue)".into(),
            });
        }

        // Rigid-body part: C0 N^(k-1) B0.
        if m > 0 {
            let nmat = Mat::from_fn(m, m, |i, j| sol[(i, nu + j)]);
            let b0 = Mat::from_fn(m, nu, |i, j| sol[(i, j)]);
            let c0 = &self.c * &u0;
            let (nc, nb, nn) = (c0.norm_l2(), b0.norm_l2(), nmat.norm_l2());
            let mut rigid = Vec::with_capacity(m);
            let mut x = b0.clone();
            let mut bound = nc * nb;
            for _ in 0..m {
                let r = &c0 * &x;
                if r.norm_l2() <= 1e-12 * bound {
                    rigid.push(Mat::zeros(ny, nu));
                } else {
                    rigid.push(r);
                }
                x = &nmat * &x;
                bound *= nn;
            }
            while rigid.last().is_some_and(|r| fro(r) == 0.0) {
                rigid.pop();
            }
            model.rigid = rigid;
        }

        // Flexible part.
        let cc = Mat::from_fn(ny, n, |i, j| C64::new(self.c[(i, j)], 0.0));
        let cv = &cc * &right.vectors;
        let mut pairs: Vec<PolePair> = Vec::new();
        for (q, &j) in right.pairs.iter().enumerate() {
            let (r_re, r_im) = (m + 2 * q, m + 2 * q + 1);
            let residue = Mat::from_fn(ny, nu, |i, jj| {
                let w = C64::new(sol[(r_re, jj)], -sol[(r_im, jj)]) * 0.5;
                cv[(i, j)] * w
            });
            push_merged_pair(&mut pairs, right.values[j], residue);
        }
        let mut reals: Vec<RealPole> = Vec::new();
        let off = m + 2 * right.pairs.len();
        for (q, &j) in right.reals.iter().enumerate() {
            let residue = Mat::from_fn(ny, nu, |i, jj| cv[(i, j)].re * sol[(off + q, jj)]);
            push_merged_real(&mut reals, right.values[j].re, residue);
        }
        model.pairs = pairs;
        model.real_poles = reals;
        model.validate()?;
        Ok(model)
    }
}

fn push_merged_pair(pairs: &mut Vec<PolePair>, pole: C64, residue: Mat<C64>) {
    if let Some(p) = pairs
        .iter_mut()
        .find(|p| (p.pole - pole).norm() <= MERGE_TOL * pole.norm())
    {
        p.residue += residue;
    } else {
        pairs.push(PolePair { pole, residue });
    }
}

fn push_merged_real(reals: &mut Vec<RealPole>, pole: f64, residue: Mat<f64>) {
    if let Some(p) = reals
        .iter_mut()
        .find(|p| (p.pole - pole).abs() <= MERGE_TOL * pole.abs())
    {
        p.residue += residue;
    } else {
        reals.push(RealPole { pole, residue });
    }
}
