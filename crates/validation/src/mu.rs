//! Structured singular value bounds: the standard `mu` of a complex matrix and the
//! generalized `mu` of an implicit LFT (Definition 11 of Oomen and Bosgra, "Well-posed
//! model uncertainty estimation by design of validation experiments", after Paganini and
//! Doyle, "Analysis of implicitly defined systems", CDC 1994).
//!
//! **Block structure.** `Delta = diag(Delta_1, ..., Delta_m)` with each block either a
//! complex scalar (`1 x 1`) or a full complex block `Delta_i in C^{r_i x c_i}` (non-square
//! allowed, as the additive model uncertainty `ny x nu`); repeated scalars are not
//! supported (the validation problem does not need them). `Delta` maps `y` (dimension
//! `sum c_i`) to `x` (dimension `sum r_i`); `M` maps `x` to `y`, so `M` is
//! `sum c_i x sum r_i`.
//!
//! **Definition (generalized mu).** With `N` a matrix with `sum r_i` columns,
//! `mu(M, N) = 1 / min { sigma_max(Delta) : Delta in the structure, there is x != 0 with
//! x = Delta M x and N x = 0 }`, and `0` when no structured `Delta` gives such an `x`
//! (ERRATA: the printed kernel condition is garbled). With `N` empty this is the standard
//! `mu(M)` (`det(I - Delta M) = 0`).
//!
//! **Upper bound (D-scaling).** Let `Q` be an orthonormal basis of `ker N` and
//! `D = diag(d_i I)`, `d_i > 0`, on the `x` side (`D_x`, sizes `r_i`) and the `y` side
//! (`D_y`, sizes `c_i`). For every `x = Q z` in the kernel, `x_i = Delta_i y_i` with
//! `sigma_max(Delta_i) <= 1/beta` forces `beta^2 |x_i|^2 <= |y_i|^2`; summing with weights
//! `d_i` (the S-procedure), no such `x` exists when `Q^H M^H D_y M Q < beta^2 Q^H D_x Q`.
//! Hence `mu(M, N) <= beta(d) = sqrt(lambda_max(Q^H M^H D_y M Q, Q^H D_x Q))`, the
//! generalized eigenvalue; for `N` empty it is `sigma_max(D_y^{1/2} M D_x^{-1/2})`, the
//! classical bound. The iteration: (1) **Osborne balancing** of the `m x m` matrix of block
//! Frobenius norms of `M Q Q^H` (the `d` that minimises the Frobenius norm of the scaled
//! block-norm matrix, by Osborne's coordinate-wise update, 20 sweeps) as the starting
//! point; (2) **local minimisation** of `beta(d)^2` over `t = ln d` by BFGS with an Armijo
//! backtracking line search on a soft maximum of the generalized eigenvalues (log-sum-exp
//! with temperature `1e-2 lambda_max`, then `1e-4`, then `1e-7`, which smooths the kinks
//! where the top eigenvalue is repeated). The gradient is analytic:
//! `d lambda_k / d t_i = d_i (|Y_i z_k|^2 - lambda_k |X_i z_k|^2)` with `z_k` the
//! `Q^H D_x Q`-normalised eigenvector, `X_i`, `Y_i` the block rows of `Q` and `M Q`.
//! The reported upper bound is `beta(d)` (the true maximum eigenvalue, not the soft one)
//! at the best `d` found, so it is a valid bound however the optimisation ends. It is
//! exact when the structure has at most three blocks (`2F + S <= 3` with only full and
//! non-repeated scalar blocks; Packard and Doyle, "The complex structured singular
//! value", Automatica 29(1), 1993) and for rank-one `M`.
//!
//! **Lower bound.** Any `x = Q z != 0` gives one: with `y = M x`, the blocks
//! `Delta_i = x_i y_i^H / |y_i|^2` satisfy `x = Delta M x` and `sigma_max(Delta_i) =
//! |x_i| / |y_i|`, so `mu(M, N) >= min_i |y_i| / |x_i|` (blocks with `x_i = 0` take
//! `Delta_i = 0`). The candidates are the top eigenvector of the final D-scaled problem
//! (tight whenever the upper bound's optimum is smooth: the zero gradient is the
//! alignment `|y_i|^2 = beta^2 |x_i|^2`) and the iterates of the **power iteration** of
//! Packard and Doyle for full blocks (`a = M b`, `z_i = (|w_i| / |a_i|) a_i`, `w = M^H z`,
//! `b_i = (|a_i| / |w_i|) w_i`, each normalised; for the generalized problem `b` is
//! projected on `ker N`). The best candidate's `Delta`, scaled to `sigma_max = 1 / lower`,
//! is returned: it is an explicit destabilising (for validation: data-explaining)
//! perturbation.

use crate::cmat::{hermitian_eigen, null_space, vnorm, CMat};
use crate::ValidationError;
use faer::Mat;
use frf_data::C64;
use serde::{Deserialize, Serialize};

/// One block of the perturbation structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Block {
    /// A complex scalar `delta in C` (`1 x 1`, not repeated).
    Scalar,
    /// A full complex block `Delta_i in C^{rows x cols}` (`rows` outputs of `Delta`, `cols`
    /// inputs).
    Full {
        /// Rows (the block's share of `x`).
        rows: usize,
        /// Columns (the block's share of `y`).
        cols: usize,
    },
}

impl Block {
    /// `(rows, cols)` of the block.
    pub fn dims(&self) -> (usize, usize) {
        match *self {
            Block::Scalar => (1, 1),
            Block::Full { rows, cols } => (rows, cols),
        }
    }
}

/// A block-diagonal perturbation structure `diag(Delta_1, ..., Delta_m)`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BlockStructure {
    /// The blocks, in order along the diagonal.
    pub blocks: Vec<Block>,
}

impl BlockStructure {
    /// A structure from its blocks.
    pub fn new(blocks: Vec<Block>) -> Self {
        Self { blocks }
    }

    /// Total rows of `Delta` (dimension of `x`, columns of `M`).
    pub fn n_rows(&self) -> usize {
        self.blocks.iter().map(|b| b.dims().0).sum()
    }

    /// Total columns of `Delta` (dimension of `y`, rows of `M`).
    pub fn n_cols(&self) -> usize {
        self.blocks.iter().map(|b| b.dims().1).sum()
    }

    /// Start offsets of the blocks in `x` and in `y`.
    fn offsets(&self) -> (Vec<usize>, Vec<usize>) {
        let mut xo = vec![0];
        let mut yo = vec![0];
        for b in &self.blocks {
            let (r, c) = b.dims();
            xo.push(xo.last().unwrap() + r);
            yo.push(yo.last().unwrap() + c);
        }
        (xo, yo)
    }

    pub(crate) fn check(&self, m: &CMat, n: Option<&CMat>) -> Result<(), ValidationError> {
        if self.blocks.is_empty() {
            return Err(ValidationError::invalid_input(
                "block structure",
                "it has no blocks",
            ));
        }
        if let Some((i, _)) = self
            .blocks
            .iter()
            .enumerate()
            .find(|(_, b)| b.dims().0 == 0 || b.dims().1 == 0)
        {
            return Err(ValidationError::invalid_input(
                "block structure",
                format!("block {i} has a zero dimension"),
            ));
        }
        if m.rows != self.n_cols() || m.cols != self.n_rows() {
            return Err(ValidationError::dimension(
                "M vs block structure",
                format!("{} x {}", self.n_cols(), self.n_rows()),
                format!("{} x {}", m.rows, m.cols),
            ));
        }
        if !m.is_finite() {
            return Err(ValidationError::invalid_input(
                "M",
                "an entry is not finite",
            ));
        }
        if let Some(n) = n {
            if n.cols != self.n_rows() {
                return Err(ValidationError::dimension(
                    "N vs block structure",
                    format!("{} columns", self.n_rows()),
                    format!("{} columns", n.cols),
                ));
            }
            if !n.is_finite() {
                return Err(ValidationError::invalid_input(
                    "N",
                    "an entry is not finite",
                ));
            }
        }
        Ok(())
    }
}

/// Settings of the mu bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct MuConfig {
    /// Maximum BFGS iterations per smoothing level of the upper bound (default 60).
    pub max_iter: usize,
    /// Stop a level when an iteration improves the bound by less than this relative
    /// amount (default `1e-10`).
    pub rel_tol: f64,
    /// Power iterations of the lower bound (default 40).
    pub power_iter: usize,
    /// Relative rank tolerance for the null space of `N` (default `1e-10`).
    pub rank_tol: f64,
}

impl Default for MuConfig {
    fn default() -> Self {
        Self {
            max_iter: 60,
            rel_tol: 1e-10,
            power_iter: 40,
            rank_tol: 1e-10,
        }
    }
}

/// The bounds `lower <= mu <= upper` with their certificates.
#[derive(Debug, Clone, PartialEq)]
pub struct MuBounds {
    /// Upper bound `beta(d)`.
    pub upper: f64,
    /// Lower bound `1 / sigma_max(Delta)` of the perturbation [`MuBounds::delta`].
    pub lower: f64,
    /// The D-scaling `d_i` of the upper bound (one per block, normalised to `max = 1`).
    pub d: Vec<f64>,
    /// The perturbation blocks of the lower bound, `sigma_max(Delta) = 1 / lower`, with
    /// `x = Delta M x`, `N x = 0` for [`MuBounds::x`]; empty when `lower = 0`.
    pub delta: Vec<Mat<C64>>,
    /// The kernel vector `x` of the lower bound (unit norm); empty when `lower = 0`.
    pub x: Vec<C64>,
}

/// Standard mu bounds of `M` for the structure (see the module documentation).
pub fn mu_bounds(
    m: &Mat<C64>,
    structure: &BlockStructure,
    cfg: &MuConfig,
) -> Result<MuBounds, ValidationError> {
    let m = CMat::from_faer(m);
    structure.check(&m, None)?;
    let q = CMat::identity(structure.n_rows());
    Ok(bounds_impl(&m, q, false, structure, cfg, None))
}

/// Generalized mu bounds of the implicit LFT `(M, N)` (Definition 11; see the module
/// documentation). `N` may have zero rows (then this is the standard mu).
pub fn generalized_mu_bounds(
    m: &Mat<C64>,
    n: &Mat<C64>,
    structure: &BlockStructure,
    cfg: &MuConfig,
) -> Result<MuBounds, ValidationError> {
    let m = CMat::from_faer(m);
    let n = CMat::from_faer(n);
    structure.check(&m, Some(&n))?;
    let scale = n.sigma_max();
    let q = null_space(&n, cfg.rank_tol * scale);
    Ok(bounds_impl(&m, q, n.rows > 0, structure, cfg, None))
}

/// The precomputed problem: Gram matrices of the block rows of `Q` and `M Q`.
struct Scaled {
    q: CMat,
    mq: CMat,
    gx: Vec<CMat>,
    gy: Vec<CMat>,
    k: usize,
}

/// Eigen-decomposition of the D-scaled problem at `t = ln d`.
struct Eval {
    lambda: Vec<f64>,
    /// `z_k` as columns (`Q^H D_x Q`-orthonormal).
    z: CMat,
}

impl Scaled {
    fn eval(&self, t: &[f64]) -> Eval {
        let k = self.k;
        let mut r = CMat::zeros(k, k);
        let mut l = CMat::zeros(k, k);
        for (i, ti) in t.iter().enumerate() {
            let d = ti.exp();
            for (a, b) in r.v.iter_mut().zip(&self.gx[i].v) {
                *a += b * d;
            }
            for (a, b) in l.v.iter_mut().zip(&self.gy[i].v) {
                *a += b * d;
            }
        }
        // R^{-1/2} by its eigen-decomposition (R is positive definite: sum d_i X_i^H X_i
        // with sum X_i^H X_i = Q^H Q = I)
        let (wr, vr) = hermitian_eigen(&r);
        let floor = wr.last().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE) * 1e-300;
        let s = CMat::from_fn(k, k, |i, j| {
            let mut acc = C64::new(0.0, 0.0);
            for p in 0..k {
                acc += vr[(i, p)] * vr[(j, p)].conj() / wr[p].max(floor).sqrt();
            }
            acc
        });
        let a = s.mul(&l).mul(&s);
        let (lambda, u) = hermitian_eigen(&a);
        let z = s.mul(&u);
        Eval { lambda, z }
    }

    /// Soft maximum `f = lmax + tau ln sum exp((l_k - lmax)/tau)` and its gradient in `t`.
    fn soft(&self, t: &[f64], tau: f64) -> (f64, Vec<f64>, f64) {
        let e = self.eval(t);
        let lmax = *e.lambda.last().unwrap();
        let w: Vec<f64> = e.lambda.iter().map(|l| ((l - lmax) / tau).exp()).collect();
        let sw: f64 = w.iter().sum();
        let f = lmax + tau * sw.ln();
        let mut g = vec![0.0; t.len()];
        for (kk, wk) in w.iter().enumerate() {
            let wk = wk / sw;
            if wk < 1e-16 {
                continue;
            }
            let zk: Vec<C64> = (0..self.k).map(|r| e.z[(r, kk)]).collect();
            for (i, gi) in g.iter_mut().enumerate() {
                let yz = quad(&self.gy[i], &zk);
                let xz = quad(&self.gx[i], &zk);
                *gi += wk * t[i].exp() * (yz - e.lambda[kk] * xz);
            }
        }
        (f, g, lmax)
    }
}

/// `z^H G z` for Hermitian `G`.
fn quad(g: &CMat, z: &[C64]) -> f64 {
    let gz = g.mul_vec(z);
    z.iter().zip(&gz).map(|(a, b)| (a.conj() * b).re).sum()
}

/// The bounds for `x = Q z` (`Q` an orthonormal basis of `ker N`; `project`: `Q` is not
/// the identity); `t0` warm-starts the D-scaling (`ln d`).
pub(crate) fn bounds_impl(
    m: &CMat,
    q: CMat,
    project: bool,
    structure: &BlockStructure,
    cfg: &MuConfig,
    t0: Option<&[f64]>,
) -> MuBounds {
    let nb = structure.blocks.len();
    let (xo, yo) = structure.offsets();
    let k = q.cols;
    let zero = MuBounds {
        upper: 0.0,
        lower: 0.0,
        d: vec![1.0; nb],
        delta: Vec::new(),
        x: Vec::new(),
    };
    if k == 0 {
        return zero;
    }
    let mq = m.mul(&q);
    if mq.norm_fro() == 0.0 {
        return zero;
    }
    let gx: Vec<CMat> = (0..nb)
        .map(|i| q.row_block(xo[i], xo[i + 1]).gram())
        .collect();
    let gy: Vec<CMat> = (0..nb)
        .map(|i| mq.row_block(yo[i], yo[i + 1]).gram())
        .collect();
    let sc = Scaled { q, mq, gx, gy, k };

    // (1) starting point: Osborne balancing of the block-norm matrix of M Q Q^H
    let mut t = match t0 {
        Some(t0) if t0.len() == nb => t0.to_vec(),
        _ => osborne(&sc.mq.mul(&sc.q.adjoint()), &xo, &yo),
    };
    // (2) BFGS on the soft maximum, three smoothing levels
    let mut best_t = t.clone();
    let mut best = sc.eval(&t).lambda.last().copied().unwrap_or(0.0);
    // the unscaled bound (d = 1) is a candidate too: the result never exceeds it
    let unscaled = vec![0.0; nb];
    let l1 = sc.eval(&unscaled).lambda.last().copied().unwrap_or(0.0);
    if l1 < best {
        best = l1;
        best_t = unscaled;
        t = best_t.clone();
    }
    if nb > 1 {
        for rel_tau in [1e-2, 1e-4, 1e-7] {
            let (bt, bl) = bfgs(&sc, &t, rel_tau, cfg);
            if bl < best {
                best = bl;
                best_t = bt.clone();
            }
            t = bt;
        }
    }
    let upper = best.max(0.0).sqrt();

    // lower bound candidates
    let e = sc.eval(&best_t);
    let mut best_lb = (0.0, Vec::new());
    let consider = |x: Vec<C64>, best_lb: &mut (f64, Vec<C64>)| {
        let lb = lower_from(m, &x, &xo, &yo);
        if lb > best_lb.0 {
            *best_lb = (lb, x);
        }
    };
    for c in (0..k).rev().take(2) {
        let zc: Vec<C64> = (0..k).map(|r| e.z[(r, c)]).collect();
        consider(sc.q.mul_vec(&zc), &mut best_lb);
    }
    // power iteration from the top eigenvector
    let zc: Vec<C64> = (0..k).map(|r| e.z[(r, k - 1)]).collect();
    let mut b = sc.q.mul_vec(&zc);
    normalize(&mut b);
    let mut w = b.clone();
    for _ in 0..cfg.power_iter {
        let mut a = m.mul_vec(&b);
        if vnorm(&a) == 0.0 {
            break;
        }
        normalize(&mut a);
        let mut z = vec![C64::new(0.0, 0.0); a.len()];
        for i in 0..nb {
            let wn = vnorm(&w[xo[i]..xo[i + 1]]);
            let an = vnorm(&a[yo[i]..yo[i + 1]]);
            let f = if an > 0.0 { wn / an } else { 0.0 };
            for r in yo[i]..yo[i + 1] {
                z[r] = a[r] * f;
            }
        }
        w = m.adjoint_mul_vec(&z);
        if vnorm(&w) == 0.0 {
            break;
        }
        normalize(&mut w);
        for i in 0..nb {
            let wn = vnorm(&w[xo[i]..xo[i + 1]]);
            let an = vnorm(&a[yo[i]..yo[i + 1]]);
            let f = if wn > 0.0 { an / wn } else { 0.0 };
            for r in xo[i]..xo[i + 1] {
                b[r] = w[r] * f;
            }
        }
        if project {
            let c = sc.q.adjoint_mul_vec(&b);
            b = sc.q.mul_vec(&c);
        }
        if vnorm(&b) == 0.0 {
            break;
        }
        normalize(&mut b);
        consider(b.clone(), &mut best_lb);
    }
    let (lower, x) = best_lb;
    let lower = lower.min(upper.max(lower));
    let d_raw: Vec<f64> = best_t.iter().map(|v| v.exp()).collect();
    let dmax = d_raw.iter().copied().fold(0.0, f64::max);
    let d = d_raw.iter().map(|v| v / dmax).collect();
    let delta = if lower > 0.0 {
        delta_from(m, &x, structure, &xo, &yo)
    } else {
        Vec::new()
    };
    MuBounds {
        upper,
        lower,
        d,
        delta,
        x: if lower > 0.0 { x } else { Vec::new() },
    }
}

/// The `ln d` of the upper bound at the end (for warm starts).
pub(crate) fn ln_d(b: &MuBounds) -> Vec<f64> {
    b.d.iter().map(|v| v.max(1e-300).ln()).collect()
}

fn normalize(v: &mut [C64]) {
    let s = vnorm(v);
    if s > 0.0 {
        v.iter_mut().for_each(|z| *z /= s);
    }
}

/// `min_i |y_i| / |x_i|` with `y = M x` (0 when some block has `x_i != 0`, `y_i = 0`).
fn lower_from(m: &CMat, x: &[C64], xo: &[usize], yo: &[usize]) -> f64 {
    let xn = vnorm(x);
    if xn == 0.0 || !xn.is_finite() {
        return 0.0;
    }
    let y = m.mul_vec(x);
    let mut lb = f64::INFINITY;
    for i in 0..xo.len() - 1 {
        let nx = vnorm(&x[xo[i]..xo[i + 1]]);
        if nx == 0.0 {
            continue;
        }
        let ny = vnorm(&y[yo[i]..yo[i + 1]]);
        lb = lb.min(ny / nx);
    }
    if lb.is_finite() {
        lb
    } else {
        0.0
    }
}

/// The blocks `Delta_i = x_i y_i^H / |y_i|^2` of the lower bound.
fn delta_from(
    m: &CMat,
    x: &[C64],
    s: &BlockStructure,
    xo: &[usize],
    yo: &[usize],
) -> Vec<Mat<C64>> {
    let y = m.mul_vec(x);
    s.blocks
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let (r, c) = b.dims();
            let yi = &y[yo[i]..yo[i + 1]];
            let xi = &x[xo[i]..xo[i + 1]];
            let ny2: f64 = yi.iter().map(|z| z.norm_sqr()).sum();
            Mat::from_fn(r, c, |a, bb| {
                if ny2 > 0.0 {
                    xi[a] * yi[bb].conj() / ny2
                } else {
                    C64::new(0.0, 0.0)
                }
            })
        })
        .collect()
}

/// Osborne balancing of the block Frobenius norms `B_ij` of `A` (block rows in `y`,
/// block columns in `x`): `d_i <- sqrt(sum_j B_ji^2 d_j / sum_j B_ij^2 / d_j)` (`j != i`),
/// the coordinate-wise minimiser of `sum_ij B_ij^2 d_i / d_j`, 20 sweeps. Returns `ln d`.
fn osborne(a: &CMat, xo: &[usize], yo: &[usize]) -> Vec<f64> {
    let nb = xo.len() - 1;
    let mut b2 = vec![0.0; nb * nb];
    for i in 0..nb {
        for j in 0..nb {
            let mut s = 0.0;
            for c in xo[j]..xo[j + 1] {
                for r in yo[i]..yo[i + 1] {
                    s += a[(r, c)].norm_sqr();
                }
            }
            b2[i * nb + j] = s;
        }
    }
    let mut d = vec![1.0; nb];
    for _ in 0..20 {
        for i in 0..nb {
            let mut num = 0.0;
            let mut den = 0.0;
            for j in 0..nb {
                if j == i {
                    continue;
                }
                num += b2[j * nb + i] * d[j];
                den += b2[i * nb + j] / d[j];
            }
            if num > 0.0 && den > 0.0 {
                d[i] = (num / den).sqrt();
            }
        }
        let dm = d.iter().copied().fold(0.0, f64::max);
        d.iter_mut().for_each(|v| *v = (*v / dm).max(1e-12));
    }
    d.iter().map(|v| v.ln()).collect()
}

/// BFGS on the soft maximum of the generalized eigenvalues over `t = ln d`, with Armijo
/// backtracking; `t` is kept in `[-60, 60]`. Returns the best `t` by the true maximum
/// eigenvalue and that eigenvalue.
fn bfgs(sc: &Scaled, t0: &[f64], rel_tau: f64, cfg: &MuConfig) -> (Vec<f64>, f64) {
    let n = t0.len();
    let mut t = t0.to_vec();
    let lmax0 = sc.eval(&t).lambda.last().copied().unwrap_or(0.0);
    if lmax0 <= 0.0 {
        return (t, lmax0.max(0.0));
    }
    let tau = rel_tau * lmax0;
    let (mut f, mut g, mut lmax) = sc.soft(&t, tau);
    let mut best = (t.clone(), lmax);
    let mut h = vec![0.0; n * n];
    let reset = |h: &mut Vec<f64>| {
        h.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..n {
            h[i * n + i] = 1.0;
        }
    };
    reset(&mut h);
    let scale = 1.0 / lmax0;
    for _ in 0..cfg.max_iter {
        // direction p = -H g (in units where the objective is O(1))
        let mut p: Vec<f64> = (0..n)
            .map(|i| -(0..n).map(|j| h[i * n + j] * g[j] * scale).sum::<f64>())
            .collect();
        let mut slope: f64 = p.iter().zip(&g).map(|(a, b)| a * b).sum();
        if slope >= 0.0 {
            reset(&mut h);
            p = g.iter().map(|v| -v * scale).collect();
            slope = p.iter().zip(&g).map(|(a, b)| a * b).sum();
        }
        let pn = p.iter().map(|v| v * v).sum::<f64>().sqrt();
        if pn == 0.0 || slope >= 0.0 {
            break;
        }
        let mut step = if pn > 5.0 { 5.0 / pn } else { 1.0 };
        let mut accepted = None;
        for _ in 0..30 {
            let tn: Vec<f64> = t
                .iter()
                .zip(&p)
                .map(|(a, b)| (a + step * b).clamp(-60.0, 60.0))
                .collect();
            let (fn_, gn, ln_) = sc.soft(&tn, tau);
            if fn_ <= f + 1e-4 * step * slope {
                accepted = Some((tn, fn_, gn, ln_));
                break;
            }
            step *= 0.5;
        }
        let Some((tn, fn_, gn, ln_)) = accepted else {
            break;
        };
        let s: Vec<f64> = tn.iter().zip(&t).map(|(a, b)| a - b).collect();
        let yv: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| (a - b) * scale).collect();
        let sy: f64 = s.iter().zip(&yv).map(|(a, b)| a * b).sum();
        let improvement = (f - fn_) / f.abs().max(f64::MIN_POSITIVE);
        t = tn;
        f = fn_;
        g = gn;
        lmax = ln_;
        if lmax < best.1 {
            best = (t.clone(), lmax);
        }
        if sy > 1e-16 {
            // H <- (I - rho s y^T) H (I - rho y s^T) + rho s s^T
            let rho = 1.0 / sy;
            let hy: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| h[i * n + j] * yv[j]).sum())
                .collect();
            let yhy: f64 = yv.iter().zip(&hy).map(|(a, b)| a * b).sum();
            for i in 0..n {
                for j in 0..n {
                    h[i * n + j] += -rho * (hy[i] * s[j] + s[i] * hy[j])
                        + (rho * rho * yhy + rho) * s[i] * s[j];
                }
            }
        }
        if improvement < cfg.rel_tol {
            break;
        }
    }
    let _ = f;
    best
}
