//! The Complex Mode Indicator Function (CMIF) and a mode-aware peak picker.
//!
//! The CMIF (Shih, Tsuei, Allemang and Brown, "Complex mode indication function and its
//! applications to spatial domain parameter estimation", *Mechanical Systems and Signal
//! Processing* 2(4), 1988) is the set of squared singular values of the FRF matrix at each
//! frequency line,
//!
//! `CMIF_i(w_k) = sigma_i(G(w_k))^2`, `i = 1 .. min(ny, nu)`, sorted in descending order.
//!
//! Near a lightly damped mode `r`, `G(w) ~ psi_r L_r^T / (j w - lambda_r)` dominates, so
//! one singular value peaks at the damped natural frequency with left singular vector
//! `~ psi_r` (the mode shape) and right singular vector `~ conj(L_r)` (the modal
//! participation); close modes with different shapes show up as peaks in the second and
//! later singular values. This is how section 4.4 and Fig. 3 of the wafer-stage paper
//! (Additive MIMO identification, `shared/papers/000_*`) count the flexible modes and
//! initialise their frequencies.
//!
//! [`cmif`] computes the curves and keeps the singular vectors (one-sided Jacobi for the
//! small matrices of motion systems, faer's SVD otherwise: [`SvdMethod`]);
//! [`pick_peaks`] selects the peaks that indicate modes. A plain peak search on the
//! sorted curves fails in three ways, and the picker answers each:
//!
//! 1. **Crossing artefacts.** Sorting by magnitude makes curve `i` jump from one mode to
//!    another where two curves cross or nearly cross: the lower curve gets a cusp-shaped
//!    maximum that is no resonance, the upper one a V. Candidates are taken from the
//!    sorted curves and from curves *tracked* through crossings by the similarity of
//!    their singular vectors ([`Cmif::track`], the tracked CMIF of enhanced-CMIF
//!    practice); a candidate sitting under a V of the curve above with a small gap is
//!    dropped, and every candidate must pass the enhanced-FRF test below, which a cusp
//!    (whose singular vectors mix two modes) fails.
//! 2. **Modes hidden in a shoulder.** Close modes that share a mode shape (same sensor
//!    vector, different actuator vectors, as in the wafer stage's 913/928 Hz pair) sit on
//!    one singular value: the weaker shows as a shoulder of a few tenths of a dB. The
//!    *enhanced FRF* of Shih et al. (1988), `e(w) = u^H G(w) v` with the singular vectors
//!    of the candidate's line held fixed ([`Cmif::enhanced_frf`]), projects `G` on the
//!    candidate's mode: its peak is clear when the modes' participation vectors differ.
//!    A candidate counts when `|e|` peaks within 0.4 % of it with enough topographic
//!    prominence (in dB, relative to the higher of the two surrounding minima); the
//!    half-power width of that peak also estimates the damping.
//! 3. **Noise and duplicates.** The prominence is measured after lowering the peak and
//!    raising the col by `noise_sigmas` standard deviations of `e`, from the `_var`
//!    columns or, without them, from the second differences of `e` across the window; a
//!    mode seen on several curves is reported once ([`PeakConfig::merge_similarity`]).

use crate::{FrfDataset, FrfError, C64};
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::svd::{self, ComputeSvdVectors};
use faer::{Mat, MatRef, Par};
use serde::{Deserialize, Serialize};

/// The CMIF of a dataset: squared singular values of `G(w_k)` at every line, in
/// descending order, with the singular vectors (used by [`pick_peaks`] to track curves).
#[derive(Debug, Clone, PartialEq)]
pub struct Cmif {
    /// Frequency of each line, Hz.
    pub freq_hz: Vec<f64>,
    /// `sv2[line][i] = sigma_i^2`, `i = 0 .. min(ny, nu)`, descending at each line.
    pub sv2: Vec<Vec<f64>>,
    ny: usize,
    nu: usize,
    r: usize,
    /// Left singular vectors: line `k`, index `i` at `u[(k * r + i) * ny ..][..ny]`.
    u: Vec<C64>,
    /// Right singular vectors: line `k`, index `i` at `v[(k * r + i) * nu ..][..nu]`.
    v: Vec<C64>,
    /// Per-entry variances, line after line, each line in `vec(G)` order, when the data
    /// carry them.
    var: Option<Vec<f64>>,
}

impl Cmif {
    /// Number of lines.
    pub fn n_lines(&self) -> usize {
        self.freq_hz.len()
    }
    /// Number of singular values per line, `min(ny, nu)`.
    pub fn n_sv(&self) -> usize {
        self.r
    }
    /// True when the data carried a variance (the picker then measures prominences
    /// against the noise).
    pub fn has_variance(&self) -> bool {
        self.var.is_some()
    }
    /// Number of outputs of the data.
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of inputs of the data.
    pub fn nu(&self) -> usize {
        self.nu
    }
    /// `sigma_i^2` at line `k` in dB (`10 log10 sigma_i^2 = 20 log10 sigma_i`); a zero
    /// singular value gives `-inf` clamped to `-400` dB.
    pub fn db(&self, k: usize, i: usize) -> f64 {
        to_db(self.sv2[k][i])
    }
    /// Left singular vector `i` (unit norm, length `ny`) at line `k`.
    pub fn left_vector(&self, k: usize, i: usize) -> &[C64] {
        let s = (k * self.r + i) * self.ny;
        &self.u[s..s + self.ny]
    }
    /// Right singular vector `i` (unit norm, length `nu`) at line `k`.
    pub fn right_vector(&self, k: usize, i: usize) -> &[C64] {
        let s = (k * self.r + i) * self.nu;
        &self.v[s..s + self.nu]
    }
    /// Similarity of singular triplet `i` at line `k` and triplet `j` at line `l`: the
    /// product of the MACs of the left and of the right singular vectors,
    /// `|u_i^H u_j|^2 |v_i^H v_j|^2`, in `[0, 1]` (1 for the same mode shape and
    /// participation, 0 for orthogonal ones). Invariant to the arbitrary phase of
    /// singular vectors.
    pub fn similarity(&self, k: usize, i: usize, l: usize, j: usize) -> f64 {
        mac(self.left_vector(k, i), self.left_vector(l, j))
            * mac(self.right_vector(k, i), self.right_vector(l, j))
    }
    /// The curves tracked from line to line by the similarity of their singular vectors:
    /// `order[k][c]` is the sorted index (0 = largest) that tracked curve `c` takes at
    /// line `k`. At the first line curve `c` is sigma_c; at each next line the
    /// assignment of curves to singular triplets maximises the summed
    /// [`Cmif::similarity`] with the previous line (exhaustively for up to 6 curves,
    /// greedily above), and the sorted order is kept unless the best assignment is better
    /// by more than `hysteresis` (so that curves at the noise floor, whose vectors are
    /// arbitrary, are not shuffled for nothing).
    pub fn track(&self, hysteresis: f64) -> Vec<Vec<usize>> {
        let (n, r) = (self.n_lines(), self.r);
        let mut order = Vec::with_capacity(n);
        if n == 0 {
            return order;
        }
        order.push((0..r).collect::<Vec<_>>());
        let perms = if r <= 6 { permutations(r) } else { Vec::new() };
        let mut sim = vec![0.0; r * r];
        for k in 1..n {
            let prev: &Vec<usize> = &order[k - 1];
            // sim[c * r + j]: curve c (at its previous index) vs triplet j now.
            for c in 0..r {
                for j in 0..r {
                    sim[c * r + j] = self.similarity(k - 1, prev[c], k, j);
                }
            }
            // Keep-sorted candidate: curve c takes the index it had at the previous line
            // (the identity on sorted indices would re-sort every line, which is the plain CMIF).
            let keep: Vec<usize> = prev.clone();
            let keep_score: f64 = (0..r).map(|c| sim[c * r + keep[c]]).sum();
            let best = if r <= 6 {
                let mut best_score = f64::NEG_INFINITY;
                let mut best = keep.clone();
                for p in &perms {
                    let s: f64 = (0..r).map(|c| sim[c * r + p[c]]).sum();
                    if s > best_score {
                        best_score = s;
                        best.clone_from(p);
                    }
                }
                if best_score > keep_score + hysteresis {
                    best
                } else {
                    keep
                }
            } else {
                let g = greedy_assignment(&sim, r);
                let s: f64 = (0..r).map(|c| sim[c * r + g[c]]).sum();
                if s > keep_score + hysteresis {
                    g
                } else {
                    keep
                }
            };
            order.push(best);
        }
        order
    }
}

fn to_db(sv2: f64) -> f64 {
    if sv2 > 0.0 {
        (10.0 * sv2.log10()).max(-400.0)
    } else {
        -400.0
    }
}

/// Modal assurance criterion of two complex vectors, `|a^H b|^2 / (|a|^2 |b|^2)`.
fn mac(a: &[C64], b: &[C64]) -> f64 {
    let mut ab = C64::new(0.0, 0.0);
    let (mut aa, mut bb) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += x.conj() * y;
        aa += x.norm_sqr();
        bb += y.norm_sqr();
    }
    if aa > 0.0 && bb > 0.0 {
        (ab.norm_sqr() / (aa * bb)).min(1.0)
    } else {
        0.0
    }
}

/// All permutations of `0..r` (Heap's algorithm); `r <= 6` gives at most 720.
fn permutations(r: usize) -> Vec<Vec<usize>> {
    let mut a: Vec<usize> = (0..r).collect();
    let mut out = vec![a.clone()];
    let mut c = vec![0usize; r];
    let mut i = 0;
    while i < r {
        if c[i] < i {
            if i % 2 == 0 {
                a.swap(0, i);
            } else {
                a.swap(c[i], i);
            }
            out.push(a.clone());
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    out
}

/// Greedy assignment on an `r x r` similarity matrix (row = curve, column = triplet):
/// repeatedly takes the largest remaining entry.
fn greedy_assignment(sim: &[f64], r: usize) -> Vec<usize> {
    let mut out = vec![usize::MAX; r];
    let mut used = vec![false; r];
    for _ in 0..r {
        let mut best = (f64::NEG_INFINITY, 0, 0);
        for c in 0..r {
            if out[c] != usize::MAX {
                continue;
            }
            for j in 0..r {
                if !used[j] && sim[c * r + j] > best.0 {
                    best = (sim[c * r + j], c, j);
                }
            }
        }
        out[best.1] = best.2;
        used[best.2] = true;
    }
    out
}

/// How [`cmif_with`] computes the singular value decompositions.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SvdMethod {
    /// [`SvdMethod::Jacobi`] when `min(ny, nu) <= 8` (falling back to faer for a line
    /// where it does not converge), [`SvdMethod::Faer`] otherwise. The default.
    #[default]
    Auto,
    /// faer's thin complex SVD (`faer::linalg::svd::svd`, sequential, reused workspace).
    Faer,
    /// One-sided (Hestenes) Jacobi on the `min(ny, nu)` columns of `G` or `G^H`:
    /// Hestenes (1958), Demmel and Veselić (1992). For the small matrices of a CMIF it is
    /// several times faster than a general SVD (about 1 us instead of 7 us for 4 x 13 in
    /// release builds, measured on the CI-like machine) and has high relative accuracy in
    /// the small singular values.
    Jacobi,
}

/// The CMIF of `data` (Shih et al. 1988; section 4.4 of the wafer-stage paper): the
/// squared singular values of `G(w_k)` at every line, descending, with the left and right
/// singular vectors. Same as [`cmif_with`] with [`SvdMethod::Auto`].
///
/// Errors: no lines; a non-finite value (only possible for a custom [`FrfDataset`], an
/// [`crate::Frf`] is checked when built); an SVD that does not converge.
pub fn cmif(data: &(impl FrfDataset + ?Sized + Sync)) -> Result<Cmif, FrfError> {
    cmif_with(data, SvdMethod::Auto)
}

/// The largest `min(ny, nu)` for which [`SvdMethod::Auto`] uses Jacobi.
const JACOBI_MAX_RANK: usize = 8;
/// Lines x entries x singular values above which the CMIF's lines are decomposed in
/// blocks on the rayon pool (the 4 x 13 wafer stage, 4000 lines: 8e5, one block).
const PARALLEL_WORK: usize = 20_000_000;
/// Lines per block on the rayon pool.
const BLOCK_LINES: usize = 128;

/// [`cmif`] with a choice of SVD algorithm (both give the same values to rounding; a
/// test checks it).
pub fn cmif_with(
    data: &(impl FrfDataset + ?Sized + Sync),
    method: SvdMethod,
) -> Result<Cmif, FrfError> {
    let (n, ny, nu) = (data.n_lines(), data.ny(), data.nu());
    if n == 0 {
        return Err(FrfError::InvalidData {
            why: "the CMIF needs at least one frequency line, the data have none".into(),
        });
    }
    if ny == 0 || nu == 0 {
        return Err(FrfError::invalid(
            "dimensions",
            format!("{ny}x{nu}"),
            "the CMIF needs at least one output and one input",
        ));
    }
    let r = ny.min(nu);
    let m = ny * nu;
    let use_jacobi = match method {
        SvdMethod::Auto => r <= JACOBI_MAX_RANK,
        SvdMethod::Jacobi => true,
        SvdMethod::Faer => false,
    };
    let mut freq_hz = Vec::with_capacity(n);
    let mut sv2: Vec<Vec<f64>> = vec![Vec::new(); n];
    let mut u = vec![C64::new(0.0, 0.0); n * r * ny];
    let mut v = vec![C64::new(0.0, 0.0); n * r * nu];
    // the lines of one block in order, with one SVD workspace (the Jacobi SVD starts
    // each line from the previous line's rotations)
    let run_block = |k0: usize, uc: &mut [C64], vc: &mut [C64], sc: &mut [Vec<f64>]| {
        let mut faer_svd = FaerSvd::new(ny, nu);
        let mut jac = JacobiSvd::new(ny, nu);
        let mut line = vec![C64::new(0.0, 0.0); m];
        let mut s = vec![0.0; r];
        for (i, sv) in sc.iter_mut().enumerate() {
            let k = k0 + i;
            let f = data.freq_hz(k);
            data.line_into(k, &mut line);
            if !f.is_finite() || line.iter().any(|z| !(z.re.is_finite() && z.im.is_finite())) {
                return Err(FrfError::InvalidData {
                    why: format!("non-finite frequency or value at line {k} ({f} Hz)"),
                });
            }
            let uk = &mut uc[i * r * ny..(i + 1) * r * ny];
            let vk = &mut vc[i * r * nu..(i + 1) * r * nu];
            let done = use_jacobi && jac.run(&line, &mut s, uk, vk);
            if !done {
                faer_svd
                    .run(&line, &mut s, uk, vk)
                    .map_err(|e| FrfError::Numerical {
                        what: "CMIF singular value decomposition".into(),
                        why: format!("{e} at line {k} ({f} Hz)"),
                    })?;
            }
            *sv = s.iter().map(|x| x * x).collect();
        }
        Ok(())
    };
    // blocks of lines on the rayon pool when the decompositions are many and large
    // (hundreds of entries: seconds on one thread); one block otherwise
    let block = if n * m * r >= PARALLEL_WORK {
        BLOCK_LINES
    } else {
        n
    };
    {
        use rayon::prelude::*;
        u.par_chunks_mut(block * r * ny)
            .zip(v.par_chunks_mut(block * r * nu))
            .zip(sv2.par_chunks_mut(block))
            .enumerate()
            .map(|(b, ((uc, vc), sc))| run_block(b * block, uc, vc, sc))
            .collect::<Result<(), FrfError>>()?;
    }
    let mut var = vec![0.0; m];
    let mut all_var = data.has_variance().then(|| Vec::with_capacity(n * m));
    for k in 0..n {
        freq_hz.push(data.freq_hz(k));
        if let Some(av) = &mut all_var {
            data.variance_line_into(k, &mut var);
            av.extend(
                var.iter()
                    .map(|&x| if x.is_finite() { x.max(0.0) } else { 0.0 }),
            );
        }
    }
    Ok(Cmif {
        freq_hz,
        sv2,
        ny,
        nu,
        r,
        u,
        v,
        var: all_var,
    })
}

/// faer's thin SVD with a reused workspace; writes descending singular values and the
/// vectors in the layout of [`Cmif`] (`r` columns of `ny`, then `r` columns of `nu`).
struct FaerSvd {
    ny: usize,
    nu: usize,
    buf: MemBuffer,
    s: Diag<C64>,
    um: Mat<C64>,
    vm: Mat<C64>,
}

impl FaerSvd {
    fn new(ny: usize, nu: usize) -> Self {
        let r = ny.min(nu);
        Self {
            ny,
            nu,
            buf: MemBuffer::new(svd::svd_scratch::<C64>(
                ny,
                nu,
                ComputeSvdVectors::Thin,
                ComputeSvdVectors::Thin,
                Par::Seq,
                Default::default(),
            )),
            s: Diag::zeros(r),
            um: Mat::zeros(ny, r),
            vm: Mat::zeros(nu, r),
        }
    }

    fn run(
        &mut self,
        g: &[C64],
        s: &mut [f64],
        u: &mut [C64],
        v: &mut [C64],
    ) -> Result<(), String> {
        let (ny, nu) = (self.ny, self.nu);
        let r = ny.min(nu);
        let a = MatRef::from_column_major_slice(g, ny, nu);
        svd::svd(
            a,
            self.s.as_mut(),
            Some(self.um.as_mut()),
            Some(self.vm.as_mut()),
            Par::Seq,
            MemStack::new(&mut self.buf),
            Default::default(),
        )
        .map_err(|e| format!("{e:?}"))?;
        let sc = self.s.column_vector();
        let vals: Vec<f64> = (0..r).map(|i| sc[i].re.abs()).collect();
        // faer sorts in nonincreasing order; enforce it against rounding.
        let mut idx: Vec<usize> = (0..r).collect();
        idx.sort_by(|&a, &b| vals[b].total_cmp(&vals[a]));
        for (o, &i) in idx.iter().enumerate() {
            s[o] = vals[i];
            for p in 0..ny {
                u[o * ny + p] = self.um[(p, i)];
            }
            for q in 0..nu {
                v[o * nu + q] = self.vm[(q, i)];
            }
        }
        Ok(())
    }
}

/// One-sided (Hestenes) Jacobi SVD for small `ny x nu` complex matrices: the `r =
/// min(ny, nu)` columns of the tall one of `G` and `G^H` are orthogonalised by plane
/// rotations (with a phase that makes each pair's inner product real); their norms are
/// the singular values, the normalised columns one set of singular vectors and the
/// accumulated rotations the other.
struct JacobiSvd {
    ny: usize,
    nu: usize,
    /// The tall working matrix, `mm x r`, column-major.
    a: Vec<C64>,
    /// Accumulated rotations, `r x r`, column-major (kept as the next line's start).
    w: Vec<C64>,
    /// Whether `w` holds the converged rotations of the previous line.
    warm: bool,
    /// Scratch, `mm x r`.
    tmp: Vec<C64>,
}

impl JacobiSvd {
    fn new(ny: usize, nu: usize) -> Self {
        let r = ny.min(nu);
        let mm = ny.max(nu);
        Self {
            ny,
            nu,
            a: vec![C64::new(0.0, 0.0); mm * r],
            w: vec![C64::new(0.0, 0.0); r * r],
            warm: false,
            tmp: Vec::new(),
        }
    }

    /// Decomposes `g` (`vec(G)`, column-major). Returns false when the sweeps do not
    /// converge (the caller falls back to faer).
    fn run(&mut self, g: &[C64], s: &mut [f64], u: &mut [C64], v: &mut [C64]) -> bool {
        let (ny, nu) = (self.ny, self.nu);
        let r = ny.min(nu);
        let mm = ny.max(nu);
        let wide = ny <= nu; // work on A = G^H (nu x ny) when G is wide
        if wide {
            for i in 0..ny {
                for j in 0..nu {
                    self.a[i * mm + j] = g[j * ny + i].conj();
                }
            }
        } else {
            self.a[..mm * r].copy_from_slice(&g[..mm * r]);
        }
        if self.warm && r > 1 {
            // Warm start from the previous line's rotations (consecutive lines have
            // nearly the same singular vectors, so A W_prev is nearly orthogonal and one or
            // two sweeps finish the job): re-orthonormalise W (modified Gram-Schmidt, so
            // that rounding does not accumulate over thousands of lines), then A <- A W.
            if !orthonormalise(&mut self.w, r) {
                identity(&mut self.w, r);
            } else {
                self.tmp.resize(mm * r, C64::new(0.0, 0.0));
                for j in 0..r {
                    for i in 0..mm {
                        let mut acc = C64::new(0.0, 0.0);
                        for l in 0..r {
                            acc += self.a[l * mm + i] * self.w[j * r + l];
                        }
                        self.tmp[j * mm + i] = acc;
                    }
                }
                self.a[..mm * r].copy_from_slice(&self.tmp[..mm * r]);
            }
        } else {
            identity(&mut self.w, r);
        }
        // Stop when every pair is orthogonal to 1e-12 relative: the singular values are then
        // exact to ~1e-24 relative (the error is second order) and the vectors to ~1e-12
        // divided by the relative gap.
        let tol = 1e-12_f64.max(4.0 * f64::EPSILON * (mm as f64).sqrt());
        let mut converged = r < 2;
        // Jacobi converges quadratically: once a sweep starts with every pair orthogonal
        // to sqrt(tol), the sweep ends below tol and no checking sweep is needed.
        let quad = tol.sqrt();
        for _sweep in 0..60 {
            let mut rotated = false;
            let mut max_off: f64 = 0.0;
            for p in 0..r {
                for q in p + 1..r {
                    let (cp, cq) = (&self.a[p * mm..(p + 1) * mm], &self.a[q * mm..(q + 1) * mm]);
                    let mut alpha = 0.0;
                    let mut beta = 0.0;
                    let mut gamma = C64::new(0.0, 0.0);
                    for (x, y) in cp.iter().zip(cq) {
                        alpha += x.norm_sqr();
                        beta += y.norm_sqr();
                        gamma += x.conj() * y;
                    }
                    let gabs = gamma.norm();
                    let rel = gabs / (alpha * beta).sqrt();
                    if gabs == 0.0 || rel <= tol {
                        continue;
                    }
                    max_off = max_off.max(rel);
                    rotated = true;
                    let ph = (gamma / gabs).conj(); // a_q * ph makes a_p^H (a_q ph) = |gamma|
                    let zeta = (beta - alpha) / (2.0 * gabs);
                    let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                    let c = 1.0 / (1.0 + t * t).sqrt();
                    let sn = c * t;
                    rotate(&mut self.a, mm, p, q, ph, c, sn);
                    rotate(&mut self.w, r, p, q, ph, c, sn);
                }
            }
            if !rotated || max_off <= quad {
                converged = true;
                break;
            }
        }
        self.warm = converged;
        if !converged {
            return false;
        }
        // Norms, order, normalisation.
        let norms: Vec<f64> = (0..r)
            .map(|i| {
                self.a[i * mm..(i + 1) * mm]
                    .iter()
                    .map(|x| x.norm_sqr())
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        if norms.iter().any(|x| !x.is_finite()) {
            return false;
        }
        let mut idx: Vec<usize> = (0..r).collect();
        idx.sort_by(|&a, &b| norms[b].total_cmp(&norms[a]));
        // A = (W_a / sigma) Sigma Wr^H, with W_a the orthogonal columns of A and Wr the
        // rotations. For G = A^H (wide G): u = Wr column, v = W_a column / sigma. For
        // G = A (tall G): u = W_a column / sigma, v = Wr column.
        let (long, short): (&mut [C64], &mut [C64]) = if wide { (v, u) } else { (u, v) };
        for (o, &i) in idx.iter().enumerate() {
            let sig = norms[i];
            s[o] = sig;
            let col = &self.a[i * mm..(i + 1) * mm];
            let dst = &mut long[o * mm..(o + 1) * mm];
            if sig > 0.0 {
                for (d, x) in dst.iter_mut().zip(col) {
                    *d = x / sig;
                }
            } else {
                for (t, d) in dst.iter_mut().enumerate() {
                    *d = C64::new(if t == o { 1.0 } else { 0.0 }, 0.0);
                }
            }
            short[o * r..(o + 1) * r].copy_from_slice(&self.w[i * r..(i + 1) * r]);
        }
        true
    }
}

/// Sets the `r x r` column-major `w` to the identity.
fn identity(w: &mut [C64], r: usize) {
    for x in w.iter_mut() {
        *x = C64::new(0.0, 0.0);
    }
    for i in 0..r {
        w[i * r + i] = C64::new(1.0, 0.0);
    }
}

/// Modified Gram-Schmidt on the `r` columns of the `r x r` column-major `w`; false when a
/// column collapses (the caller restarts from the identity).
fn orthonormalise(w: &mut [C64], r: usize) -> bool {
    for j in 0..r {
        for i in 0..j {
            let (lo, hi) = w.split_at_mut(j * r);
            let qi = &lo[i * r..(i + 1) * r];
            let cj = &mut hi[..r];
            let d = dot(qi, cj);
            for (x, y) in cj.iter_mut().zip(qi) {
                *x -= d * y;
            }
        }
        let nrm = w[j * r..(j + 1) * r]
            .iter()
            .map(|x| x.norm_sqr())
            .sum::<f64>()
            .sqrt();
        if !(nrm > 0.5 && nrm.is_finite()) {
            return false;
        }
        for x in &mut w[j * r..(j + 1) * r] {
            *x /= nrm;
        }
    }
    true
}

/// Applies the Jacobi rotation of columns `p, q` (each `m` long) of a column-major
/// matrix: `b = a_q ph`, `a_p <- c a_p - s b`, `a_q <- s a_p + c b`.
fn rotate(a: &mut [C64], m: usize, p: usize, q: usize, ph: C64, c: f64, s: f64) {
    let (lo, hi) = a.split_at_mut(q * m);
    let cp = &mut lo[p * m..(p + 1) * m];
    let cq = &mut hi[..m];
    for (x, y) in cp.iter_mut().zip(cq.iter_mut()) {
        let ap = *x;
        let b = *y * ph;
        *x = ap * c - b * s;
        *y = ap * s + b * c;
    }
}

/// Settings of [`pick_peaks`], with documented defaults ([`PeakConfig::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PeakConfig {
    /// Minimum prominence of a mode, dB: the topographic prominence of the peak of its
    /// enhanced FRF (see [`pick_peaks`]) within the search window. Default 3 dB (a
    /// resonance of relative damping `zeta` rises by about `20 log10(1 / (2 zeta))`,
    /// 28 dB at `zeta = 0.02`, above its surroundings; crossing cusps and noise bumps do
    /// not survive the enhanced FRF).
    pub min_prominence_db: f64,
    /// Return only the `n` most prominent peaks (after every other test), in frequency
    /// order. Default `None`: all that pass.
    pub n_modes: Option<usize>,
    /// Also take candidates from the curves tracked through crossings by their singular
    /// vectors ([`Cmif::track`]), besides the sorted curves. Default `true`.
    pub track: bool,
    /// Hysteresis of the tracking (summed similarity gain needed to reorder curves).
    /// Default 0.1.
    pub track_hysteresis: f64,
    /// Candidates are local maxima of a CMIF curve with at least this topographic
    /// prominence, dB. Default 0.1 dB (low on purpose: the shoulder of a close mode that
    /// shares a singular value with a stronger neighbour rises only a little; the enhanced
    /// FRF decides).
    pub candidate_prominence_db: f64,
    /// Half-width of the window in which the enhanced FRF of a candidate is evaluated,
    /// relative to the candidate's frequency. Default 0.05 (+-5 %; at least 5 lines).
    pub window_rel: f64,
    /// The enhanced FRF must peak within this distance of the candidate, relative to its
    /// frequency (and at least 1.5 lines); otherwise the candidate is a crossing artefact
    /// or the flank of another mode. Default 0.004 (0.4 %).
    pub max_shift_rel: f64,
    /// A candidate on singular value `i > 1` is a crossing artefact when singular value
    /// `i - 1` has a local minimum within [`PeakConfig::merge_lines`] lines and the two
    /// are less than this many dB apart there (the upper curve's V over the lower
    /// curve's cusp where sorting swaps two modes). Default 3 dB.
    pub crossing_gap_db: f64,
    /// Minimum merge distance, lines (see [`PeakConfig::merge_similarity`]). Default 3.
    pub merge_lines: usize,
    /// Two accepted peaks closer than the stronger one's half-power half-width (at least
    /// [`PeakConfig::merge_lines`] lines) are one mode (the more prominent is kept) when
    /// their singular vectors have a similarity ([`Cmif::similarity`]) of at least this,
    /// or when the weaker is more than [`PeakConfig::merge_level_db`] below the stronger.
    /// Otherwise both are kept (repeated roots, close modes with different shapes).
    /// Default 0.5.
    pub merge_similarity: f64,
    /// See [`PeakConfig::merge_similarity`]. Default 20 dB: a coincident peak that much
    /// weaker is the same mode seen through a minor direction of `G`.
    pub merge_level_db: f64,
    /// Ignore candidates whose `sigma^2` is more than this many dB below `sigma_1^2` at the
    /// same line (the numerical floor of rank-deficient data). Default 80 dB.
    pub dynamic_range_db: f64,
    /// With a variance, lower the peak and raise the col of the enhanced FRF by this many
    /// of its noise standard deviations ([`Cmif::enhanced_frf_variance`]) before
    /// measuring the prominence. Default 2.
    pub noise_sigmas: f64,
    /// Without a variance, estimate the noise of each candidate's enhanced FRF from the
    /// data: the robust (median) power of its complex second difference across the
    /// window, `var e ~ median |e_(l+1) - 2 e_l + e_(l-1)|^2 / (6 ln 2)` (white noise of
    /// variance `s^2` gives `6 s^2` on average, exponentially distributed; a resonance
    /// sampled finely barely contributes and a sharp one only at a few lines, which the
    /// median ignores). The prominence is then noise-corrected as with a variance.
    /// Default `true`.
    pub estimate_noise: bool,
}

impl Default for PeakConfig {
    fn default() -> Self {
        Self {
            min_prominence_db: 3.0,
            n_modes: None,
            track: true,
            track_hysteresis: 0.1,
            candidate_prominence_db: 0.1,
            window_rel: 0.05,
            max_shift_rel: 0.004,
            crossing_gap_db: 3.0,
            merge_lines: 3,
            merge_similarity: 0.5,
            merge_level_db: 20.0,
            dynamic_range_db: 80.0,
            noise_sigmas: 2.0,
            estimate_noise: true,
        }
    }
}

/// One picked CMIF peak: a mode indication.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CmifPeak {
    /// Peak frequency, Hz: the maximum of the enhanced FRF, refined by a parabola through
    /// the three lines around it in dB (~ the damped natural frequency).
    pub f_hz: f64,
    /// The line of that maximum (index into [`Cmif::freq_hz`]).
    pub line: usize,
    /// Which singular value the mode was picked on, 0-based (0 = sigma_1, the largest),
    /// at the line of the candidate.
    pub sv_index: usize,
    /// Topographic prominence of the enhanced FRF's peak, dB (of `|e|^2`, equal to dB
    /// of `|e|`): the ratio of the peak to the higher of the two minima that separate it
    /// from higher ground inside the window; after the noise correction when the data
    /// carry a variance.
    pub prominence: f64,
    /// `sigma^2` of the singular value at the candidate line (where the dot goes in
    /// the CMIF plot).
    pub sv2: f64,
    /// The line of the candidate (the CMIF maximum that led to this peak).
    pub candidate_line: usize,
    /// Half-power estimate of the relative damping from the enhanced FRF,
    /// `(f_right - f_left) / (2 f)` at 3 dB below the peak (one side doubled when the
    /// other is masked by a neighbour); `None` when neither side reaches -3 dB inside the
    /// window. Resolution-limited (an upper bound) when the half-power band spans few
    /// lines.
    pub damping: Option<f64>,
}

impl Cmif {
    /// The enhanced FRF (Shih et al. 1988) of singular triplet `j` of line `k` over the
    /// lines `lines`: `e(w_l) = u^H G(w_l) v` with `(u, v)` the singular vectors of
    /// triplet `j` at line `k`, computed from the stored decomposition
    /// (`G(w_l) = U_l S_l V_l^H` exactly). Fixing the vectors at a mode's peak projects
    /// `G` on that mode, so `|e|` is a single-mode resonance curve even where modes are
    /// close or share a singular value. Returns the complex `e` per line; `|e|^2` is in
    /// the CMIF's units, and `|e(w_k)| = sigma_j(w_k)`. Out-of-range indices give zeros.
    pub fn enhanced_frf(&self, k: usize, j: usize, lines: std::ops::Range<usize>) -> Vec<C64> {
        let lines = lines.start.min(self.n_lines())..lines.end.min(self.n_lines());
        if k >= self.n_lines() || j >= self.r {
            return vec![C64::new(0.0, 0.0); lines.len()];
        }
        let (u, v) = (self.left_vector(k, j), self.right_vector(k, j));
        lines
            .map(|l| {
                let mut e = C64::new(0.0, 0.0);
                for i in 0..self.r {
                    let a = dot(u, self.left_vector(l, i));
                    let b = dot(self.right_vector(l, i), v);
                    e += a * b * self.sv2[l][i].sqrt();
                }
                e
            })
            .collect()
    }
}

impl Cmif {
    /// Variance of the enhanced FRF of triplet `j` of line `k` (see
    /// [`Cmif::enhanced_frf`]) at the lines `lines`, for independent entry errors:
    /// `var e(w_l) = sum_(p,q) |u_p|^2 |v_q|^2 var G_pq(w_l)`. `None` without a variance.
    pub fn enhanced_frf_variance(
        &self,
        k: usize,
        j: usize,
        lines: std::ops::Range<usize>,
    ) -> Option<Vec<f64>> {
        let var = self.var.as_ref()?;
        let lines = lines.start.min(self.n_lines())..lines.end.min(self.n_lines());
        if k >= self.n_lines() || j >= self.r {
            return Some(vec![0.0; lines.len()]);
        }
        let m = self.ny * self.nu;
        let u2: Vec<f64> = self
            .left_vector(k, j)
            .iter()
            .map(|x| x.norm_sqr())
            .collect();
        let v2: Vec<f64> = self
            .right_vector(k, j)
            .iter()
            .map(|x| x.norm_sqr())
            .collect();
        Some(
            lines
                .map(|l| {
                    let vl = &var[l * m..(l + 1) * m];
                    let mut acc = 0.0;
                    for (q, vq) in v2.iter().enumerate() {
                        let col = &vl[q * self.ny..(q + 1) * self.ny];
                        acc += vq * col.iter().zip(&u2).map(|(a, b)| a * b).sum::<f64>();
                    }
                    acc
                })
                .collect(),
        )
    }
}

/// `a^H b`.
fn dot(a: &[C64], b: &[C64]) -> C64 {
    a.iter()
        .zip(b)
        .fold(C64::new(0.0, 0.0), |s, (x, y)| s + x.conj() * y)
}

/// A validated peak and the half-power half-width used for merging.
struct Validated {
    peak: CmifPeak,
    half_width_hz: f64,
}

/// Picks the CMIF peaks that indicate modes, in the spirit of the enhanced CMIF of Shih
/// et al. (1988):
///
/// 1. **Candidates**: local maxima of the sorted CMIF curves, and (with
///    [`PeakConfig::track`]) of the curves tracked by their singular vectors, with a
///    curve prominence of at least [`PeakConfig::candidate_prominence_db`], inside the
///    dynamic range.
///    A candidate on `sigma_i`, `i > 1`, right under a V of `sigma_{i-1}` with a gap
///    below [`PeakConfig::crossing_gap_db`] is the cusp of a crossing and is dropped.
/// 2. **Enhanced FRF**: for each candidate, `e(w) = u^H G(w) v` with the candidate's
///    singular vectors, over +-[`PeakConfig::window_rel`] around it
///    ([`Cmif::enhanced_frf`]). A mode makes `|e|` a single resonance peaking at the
///    candidate; a crossing artefact has mixed vectors whose `|e|` peaks at the two
///    modes, away from the candidate, so it is rejected when the nearest maximum of
///    `|e|` (found by climbing from the candidate) is further than
///    [`PeakConfig::max_shift_rel`]. The prominence of that maximum (noise-corrected
///    with a variance) must reach [`PeakConfig::min_prominence_db`]; it also separates
///    close modes that share a singular value (a shoulder of a few tenths of a dB on
///    sigma_1 becomes a clear peak of the enhanced FRF when the modes' participation
///    vectors differ).
/// 3. **Duplicates**: a mode is usually a candidate on several curves; see
///    [`PeakConfig::merge_similarity`].
///
/// Returns the peaks in frequency order; with [`PeakConfig::n_modes`] only the most
/// prominent ones. Never panics; a CMIF with fewer than three lines gives no peak.
pub fn pick_peaks(cmif: &Cmif, cfg: &PeakConfig) -> Vec<CmifPeak> {
    let (n, r) = (cmif.n_lines(), cmif.n_sv());
    if n < 3 || r == 0 {
        return Vec::new();
    }
    let f = &cmif.freq_hz;
    let cands = candidates(cmif, cfg);
    let mut peaks: Vec<Validated> = cands
        .iter()
        .filter_map(|&(k, j)| validate(cmif, cfg, k, j))
        .collect();
    // Duplicates: most prominent first.
    peaks.sort_by(|a, b| b.peak.prominence.total_cmp(&a.peak.prominence));
    let mut accepted: Vec<Validated> = Vec::new();
    for p in peaks {
        let dup = accepted.iter().any(|q| {
            let tol = q
                .half_width_hz
                .max(cfg.merge_lines as f64 * local_spacing(f, q.peak.line));
            if (p.peak.f_hz - q.peak.f_hz).abs() > tol {
                return false;
            }
            let weaker_db = to_db(q.peak.sv2) - to_db(p.peak.sv2);
            weaker_db > cfg.merge_level_db
                || cmif.similarity(
                    p.peak.candidate_line,
                    p.peak.sv_index,
                    q.peak.candidate_line,
                    q.peak.sv_index,
                ) >= cfg.merge_similarity
        });
        if !dup {
            accepted.push(p);
        }
    }
    let mut out: Vec<CmifPeak> = accepted.into_iter().map(|v| v.peak).collect();
    if let Some(nm) = cfg.n_modes {
        out.truncate(nm);
    }
    out.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz).then(a.sv_index.cmp(&b.sv_index)));
    out
}

/// Step 1 of [`pick_peaks`]: candidate `(line, sorted index)` pairs.
fn candidates(cmif: &Cmif, cfg: &PeakConfig) -> Vec<(usize, usize)> {
    let (n, r) = (cmif.n_lines(), cmif.n_sv());
    let mut sources: Vec<Vec<Vec<usize>>> = vec![(0..n).map(|_| (0..r).collect()).collect()];
    if cfg.track && r > 1 {
        sources.push(cmif.track(cfg.track_hysteresis));
    }
    let mut cands: Vec<(usize, usize)> = Vec::new();
    let mut y = vec![0.0; n];
    for order in &sources {
        for c in 0..r {
            for k in 0..n {
                y[k] = cmif.db(k, order[k][c]);
            }
            for k in 1..n - 1 {
                if !(y[k] > y[k - 1] && y[k] >= y[k + 1]) {
                    continue;
                }
                if y[k] < cmif.db(k, 0) - cfg.dynamic_range_db {
                    continue;
                }
                let Some((col, _)) = col_of(&y, k, 0..n) else {
                    continue;
                };
                let prom = y[k] - y[col];
                if prom.is_nan() || prom < cfg.candidate_prominence_db {
                    continue;
                }
                let j = order[k][c];
                if j > 0 && under_crossing(cmif, k, j, cfg) {
                    continue;
                }
                if !cands.contains(&(k, j)) {
                    cands.push((k, j));
                }
            }
        }
    }
    cands
}

/// True when sorted curve `j - 1` has a local minimum within `merge_lines` of line `k`
/// where it is less than `crossing_gap_db` above curve `j`.
fn under_crossing(cmif: &Cmif, k: usize, j: usize, cfg: &PeakConfig) -> bool {
    let n = cmif.n_lines();
    let w = cfg.merge_lines.max(1);
    let a = k.saturating_sub(w).max(1);
    let b = (k + w).min(n - 2);
    (a..=b).any(|l| {
        let up = cmif.db(l, j - 1);
        up <= cmif.db(l - 1, j - 1)
            && up <= cmif.db(l + 1, j - 1)
            && up - cmif.db(l, j) < cfg.crossing_gap_db
    })
}

/// Step 2 of [`pick_peaks`]: the enhanced-FRF test of candidate `(k, j)`.
fn validate(cmif: &Cmif, cfg: &PeakConfig, k: usize, j: usize) -> Option<Validated> {
    let n = cmif.n_lines();
    let f = &cmif.freq_hz;
    let half = (cfg.window_rel.max(0.0) * f[k]).max(0.0);
    let lo = f
        .partition_point(|&x| x < f[k] - half)
        .min(k.saturating_sub(5));
    let hi = (f.partition_point(|&x| x <= f[k] + half)).max((k + 6).min(n));
    let ec = cmif.enhanced_frf(k, j, lo..hi);
    let e: Vec<f64> = ec.iter().map(|x| x.norm_sqr()).collect();
    let e_db: Vec<f64> = e.iter().map(|&x| to_db(x)).collect();
    // Climb from the candidate to the nearest maximum of |e|.
    let mut m = k - lo;
    loop {
        let left = m > 0 && e_db[m - 1] > e_db[m];
        let right = m + 1 < e_db.len() && e_db[m + 1] > e_db[m];
        m = match (left, right) {
            (false, false) => break,
            (true, false) => m - 1,
            (false, true) => m + 1,
            (true, true) if e_db[m - 1] >= e_db[m + 1] => m - 1,
            (true, true) => m + 1,
        };
    }
    let ml = lo + m;
    let tol_hz = (cfg.max_shift_rel.max(0.0) * f[k]).max(1.5 * local_spacing(f, k));
    if (f[ml] - f[k]).abs() > tol_hz * (1.0 + 1e-12) {
        return None;
    }
    if m == 0 || m + 1 >= e_db.len() {
        return None; // the maximum sits on the window edge: no resonance inside
    }
    let (col, _) = col_of(&e_db, m, 0..e_db.len())?;
    let mut prom = e_db[m] - e_db[col];
    let z = if cfg.noise_sigmas.is_finite() {
        cfg.noise_sigmas.max(0.0)
    } else {
        0.0
    };
    let ev = match cmif.enhanced_frf_variance(k, j, lo..hi) {
        Some(v) => Some(v),
        None if cfg.estimate_noise => second_difference_variance(&ec).map(|s2| vec![s2; ec.len()]),
        None => None,
    };
    if let (Some(ev), true) = (ev, z > 0.0) {
        let sp = e[m].sqrt() - z * ev[m].sqrt();
        let sc = e[col].sqrt() + z * ev[col].sqrt();
        prom = if sp > 0.0 && sc > 0.0 {
            20.0 * (sp / sc).log10()
        } else {
            f64::NEG_INFINITY
        };
    }
    if prom.is_nan() || prom < cfg.min_prominence_db {
        return None;
    }
    let fw = &f[lo..hi];
    let f_peak = refine_peak(fw, &e_db, m);
    let (left, right) = half_power(fw, &e_db, m);
    let half_width_hz = match (left, right) {
        (Some(a), Some(b)) => Some(0.5 * (b - a)),
        (Some(a), None) => Some(f_peak - a),
        (None, Some(b)) => Some(b - f_peak),
        (None, None) => None,
    }
    .filter(|h| h.is_finite() && *h > 0.0);
    Some(Validated {
        peak: CmifPeak {
            f_hz: f_peak,
            line: ml,
            sv_index: j,
            prominence: prom,
            sv2: cmif.sv2[k][j],
            candidate_line: k,
            damping: half_width_hz.map(|h| h / f_peak),
        },
        half_width_hz: half_width_hz.unwrap_or(0.0),
    })
}

/// Frequencies where `y` (dB) has fallen 3 dB below its maximum at `m`, on each side
/// (linear interpolation between lines); `None` on a side where the curve rises again
/// (a neighbour) or the window ends first.
fn half_power(f: &[f64], y: &[f64], m: usize) -> (Option<f64>, Option<f64>) {
    let target = y[m] - 3.0103;
    let cross = |a: usize, b: usize| -> f64 {
        let t = (y[a] - target) / (y[a] - y[b]);
        f[a] + t * (f[b] - f[a])
    };
    let mut left = None;
    let mut i = m;
    while i > 0 {
        if y[i - 1] > y[i] {
            break;
        }
        if y[i - 1] <= target {
            left = Some(cross(i, i - 1));
            break;
        }
        i -= 1;
    }
    let mut right = None;
    let mut i = m;
    while i + 1 < y.len() {
        if y[i + 1] > y[i] {
            break;
        }
        if y[i + 1] <= target {
            right = Some(cross(i, i + 1));
            break;
        }
        i += 1;
    }
    (left, right)
}

/// Mean spacing of the lines around `k`, Hz.
fn local_spacing(f: &[f64], k: usize) -> f64 {
    let n = f.len();
    if n < 2 {
        return 0.0;
    }
    let a = k.saturating_sub(1);
    let b = (k + 1).min(n - 1);
    if b > a {
        (f[b] - f[a]) / (b - a) as f64
    } else {
        0.0
    }
}

/// Noise variance of a complex sequence estimated from its second differences:
/// `median |x_(l+1) - 2 x_l + x_(l-1)|^2 / (6 ln 2)` (for white complex noise of variance
/// `s^2` the second difference has variance `6 s^2` and its power is exponentially
/// distributed, with median `6 s^2 ln 2`). `None` with fewer than 5 values.
fn second_difference_variance(x: &[C64]) -> Option<f64> {
    if x.len() < 5 {
        return None;
    }
    let mut d2: Vec<f64> = x
        .windows(3)
        .map(|w| (w[2] - w[1] * 2.0 + w[0]).norm_sqr())
        .collect();
    let mid = d2.len() / 2;
    d2.select_nth_unstable_by(mid, f64::total_cmp);
    let v = d2[mid] / (6.0 * std::f64::consts::LN_2);
    v.is_finite().then_some(v)
}

/// The col of the peak at `k` on `y`, searching only inside `range`: on each side, the
/// minimum between `k` and the first strictly higher point (or the end of the range);
/// the col is the higher of the two minima. Returns its index and value; `None` when `k`
/// has no neighbour on a side.
fn col_of(y: &[f64], k: usize, range: std::ops::Range<usize>) -> Option<(usize, f64)> {
    if k <= range.start || k + 1 >= range.end.min(y.len()) {
        return None;
    }
    let end = range.end.min(y.len());
    let mut lmin = (k - 1, y[k - 1]);
    let mut i = k;
    while i > range.start {
        i -= 1;
        if y[i] > y[k] {
            break;
        }
        if y[i] < lmin.1 {
            lmin = (i, y[i]);
        }
    }
    let mut rmin = (k + 1, y[k + 1]);
    let mut i = k;
    while i + 1 < end {
        i += 1;
        if y[i] > y[k] {
            break;
        }
        if y[i] < rmin.1 {
            rmin = (i, y[i]);
        }
    }
    Some(if lmin.1 >= rmin.1 { lmin } else { rmin })
}

/// Frequency of the vertex of the parabola through `(f, y)` at `k - 1, k, k + 1`
/// (non-uniform spacing allowed), clamped to the two neighbouring lines; `f[k]` at the
/// ends.
fn refine_peak(f: &[f64], y: &[f64], k: usize) -> f64 {
    if k == 0 || k + 1 >= f.len().min(y.len()) {
        return f.get(k).copied().unwrap_or(f64::NAN);
    }
    let (x0, x1, x2) = (f[k - 1], f[k], f[k + 1]);
    let (y0, y1, y2) = (y[k - 1], y[k], y[k + 1]);
    let d1 = (y1 - y0) / (x1 - x0);
    let d2 = (y2 - y1) / (x2 - x1);
    let a = (d2 - d1) / (x2 - x0);
    if !(a < 0.0 && a.is_finite()) {
        return x1;
    }
    // y = y1 + b (x - x1) + a (x - x1)^2 with b the slope at x1.
    let b = d1 + a * (x1 - x0);
    let xv = x1 - b / (2.0 * a);
    if xv.is_finite() {
        xv.clamp(x0, x2)
    } else {
        x1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Frf;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_frf(rng: &mut ChaCha8Rng, n: usize, ny: usize, nu: usize) -> Frf {
        let f: Vec<f64> = (1..=n).map(|k| k as f64).collect();
        let mut vals = Vec::new();
        for k in 0..n {
            for _ in 0..ny * nu {
                // Mix scales, and make some lines rank deficient.
                let scale = if k % 5 == 0 { 1e-6 } else { 1.0 };
                vals.push(C64::new(
                    rng.random_range(-1.0..1.0) * scale,
                    rng.random_range(-1.0..1.0),
                ));
            }
            if k % 7 == 3 && nu > 1 {
                // column 1 = 2 * column 0: rank drops by one
                let base = vals.len() - ny * nu;
                for i in 0..ny {
                    vals[base + ny + i] = vals[base + i] * 2.0;
                }
            }
        }
        Frf::new(f, ny, nu, vals, None).unwrap()
    }

    /// A CMIF large enough to be decomposed in blocks on the rayon pool equals, line for
    /// line, the CMIF of each line on its own (one block, one thread), and keeps the
    /// lines' order and frequencies.
    #[test]
    fn blocks_on_the_pool_match_line_by_line() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (n, ny, nu) = (2600, 20, 20);
        assert!(n * ny * nu * ny.min(nu) >= PARALLEL_WORK);
        let d = random_frf(&mut rng, n, ny, nu);
        let all = cmif(&d).unwrap();
        assert_eq!(all.freq_hz, d.freq_hz_slice());
        for k in (0..n).step_by(97).chain([n - 1]) {
            let one = Frf::new(
                vec![d.freq_hz(k)],
                ny,
                nu,
                (0..nu)
                    .flat_map(|q| (0..ny).map(move |p| (p, q)))
                    .map(|(p, q)| d.value(k, p, q))
                    .collect(),
                None,
            )
            .unwrap();
            let c = cmif(&one).unwrap();
            for i in 0..ny.min(nu) {
                let (x, y) = (all.sv2[k][i], c.sv2[0][i]);
                assert!(
                    (x - y).abs() <= 1e-12 * c.sv2[0][0],
                    "line {k} sv {i}: {x} vs {y}"
                );
            }
        }
    }

    #[test]
    fn jacobi_matches_faer_and_reconstructs() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for &(ny, nu) in &[
            (1, 1),
            (1, 3),
            (3, 1),
            (2, 2),
            (4, 13),
            (13, 4),
            (28, 2),
            (8, 8),
        ] {
            let d = random_frf(&mut rng, 20, ny, nu);
            let a = cmif_with(&d, SvdMethod::Jacobi).unwrap();
            let b = cmif_with(&d, SvdMethod::Faer).unwrap();
            let r = ny.min(nu);
            for k in 0..20 {
                let s1 = a.sv2[k][0].sqrt();
                for i in 0..r {
                    let (x, y) = (a.sv2[k][i].sqrt(), b.sv2[k][i].sqrt());
                    assert!(
                        (x - y).abs() <= 1e-12 * s1,
                        "{ny}x{nu} line {k} sv {i}: {x} vs {y}"
                    );
                    if i > 0 {
                        assert!(a.sv2[k][i] <= a.sv2[k][i - 1], "not descending");
                    }
                }
                // G = U S V^H from the Jacobi vectors.
                for p in 0..ny {
                    for q in 0..nu {
                        let mut g = C64::new(0.0, 0.0);
                        for i in 0..r {
                            g += a.left_vector(k, i)[p]
                                * a.sv2[k][i].sqrt()
                                * a.right_vector(k, i)[q].conj();
                        }
                        let want = d.value(k, p, q);
                        assert!(
                            (g - want).norm() <= 1e-12 * s1.max(1e-300),
                            "{ny}x{nu} reconstruct"
                        );
                    }
                }
                // Unit vectors.
                for i in 0..r {
                    let nu2: f64 = a.left_vector(k, i).iter().map(|x| x.norm_sqr()).sum();
                    assert!((nu2 - 1.0).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn zero_matrix_and_errors() {
        let d = Frf::new(vec![1.0, 2.0], 2, 3, vec![C64::new(0.0, 0.0); 12], None).unwrap();
        let c = cmif(&d).unwrap();
        assert_eq!(c.sv2[0], vec![0.0, 0.0]);
        assert!(pick_peaks(&c, &PeakConfig::default()).is_empty());
        let empty = Frf::new(vec![], 2, 3, vec![], None).unwrap();
        assert!(matches!(cmif(&empty), Err(FrfError::InvalidData { .. })));
    }

    #[test]
    fn permutations_are_complete() {
        for r in 1..=5 {
            let p = permutations(r);
            let fact: usize = (1..=r).product();
            assert_eq!(p.len(), fact);
            let mut q = p.clone();
            q.sort();
            q.dedup();
            assert_eq!(q.len(), fact);
        }
    }

    #[test]
    fn parabola_vertex() {
        let f = [1.0, 2.0, 4.0];
        // y = -(x - 2.5)^2
        let y: Vec<f64> = f.iter().map(|x| -(x - 2.5) * (x - 2.5)).collect();
        assert!((refine_peak(&f, &y, 1) - 2.5).abs() < 1e-12);
    }
}
