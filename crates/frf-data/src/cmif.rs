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
//! [`cmif`] computes the curves and keeps the singular vectors; [`pick_peaks`] selects
//! the peaks that indicate modes. The picker addresses the two classic failure modes of a
//! plain peak search on the sorted curves:
//!
//! 1. **Crossing artefacts.** Sorting by magnitude makes curve `i` jump from one mode to
//!    another where two curves cross (or nearly cross): the lower sorted curve then has a
//!    cusp-shaped maximum that is no resonance. The picker therefore *tracks* the curves
//!    from line to line by the similarity of their singular vectors (the product of the
//!    MACs of the left and of the right singular vectors, the tracked CMIF of Allemang's
//!    enhanced-CMIF practice), so that each tracked curve follows one mode through
//!    a crossing, and it rejects any peak whose singular vectors on its two flanks differ
//!    (a peak made of two different modes, which is what an unresolved avoided crossing
//!    leaves behind).
//! 2. **Duplicates and noise.** A mode can raise more than one curve at the same line; a
//!    peak in a lower curve within a few lines of an accepted peak counts only when its
//!    singular vectors differ from that peak's (a repeated root or a genuinely close
//!    mode). Significance is the topographic prominence of the peak on the log-magnitude
//!    curve relative to the higher of the two surrounding minima (the col), in dB; when
//!    the data carry a variance, the peak is lowered and the col raised by
//!    `noise_sigmas` times the noise level before the prominence is measured, so that
//!    noise bumps do not count.

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
    /// Expected squared Frobenius norm of the noise matrix at each line,
    /// `sum_e var_e` over the `ny * nu` entries, when the data carry a variance. Its square
    /// root bounds the perturbation of every singular value (Weyl: `|d sigma_i| <= ||E||_2
    /// <= ||E||_F`).
    pub noise_f2: Option<Vec<f64>>,
    ny: usize,
    nu: usize,
    r: usize,
    /// Left singular vectors: line `k`, index `i` at `u[(k * r + i) * ny ..][..ny]`.
    u: Vec<C64>,
    /// Right singular vectors: line `k`, index `i` at `v[(k * r + i) * nu ..][..nu]`.
    v: Vec<C64>,
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

/// The CMIF of `data` (Shih et al. 1988; section 4.4 of the wafer-stage paper): the
/// squared singular values of `G(w_k)` at every line, descending, with the left and right
/// singular vectors. One thin complex SVD (faer, sequential) per line with a reused
/// workspace.
///
/// Errors: no lines; a non-finite value (only possible for a custom [`FrfDataset`], an
/// [`crate::Frf`] is checked when built); an SVD that does not converge.
pub fn cmif(data: &(impl FrfDataset + ?Sized)) -> Result<Cmif, FrfError> {
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
    let par = Par::Seq;
    let mut buf = MemBuffer::new(svd::svd_scratch::<C64>(
        ny,
        nu,
        ComputeSvdVectors::Thin,
        ComputeSvdVectors::Thin,
        par,
        Default::default(),
    ));
    let mut line = vec![C64::new(0.0, 0.0); m];
    let mut var = vec![0.0; m];
    let mut s = Diag::<C64>::zeros(r);
    let mut um = Mat::<C64>::zeros(ny, r);
    let mut vm = Mat::<C64>::zeros(nu, r);
    let mut freq_hz = Vec::with_capacity(n);
    let mut sv2 = Vec::with_capacity(n);
    let mut u = Vec::with_capacity(n * r * ny);
    let mut v = Vec::with_capacity(n * r * nu);
    let mut noise_f2 = data.has_variance().then(|| Vec::with_capacity(n));
    for k in 0..n {
        let f = data.freq_hz(k);
        data.line_into(k, &mut line);
        if !f.is_finite() || line.iter().any(|z| !(z.re.is_finite() && z.im.is_finite())) {
            return Err(FrfError::InvalidData {
                why: format!("non-finite frequency or value at line {k} ({f} Hz)"),
            });
        }
        let a = MatRef::from_column_major_slice(&line, ny, nu);
        svd::svd(
            a,
            s.as_mut(),
            Some(um.as_mut()),
            Some(vm.as_mut()),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|e| FrfError::Numerical {
            what: "CMIF singular value decomposition".into(),
            why: format!("{e:?} at line {k} ({f} Hz)"),
        })?;
        let sc = s.column_vector();
        let mut row: Vec<f64> = (0..r).map(|i| sc[i].re * sc[i].re).collect();
        // faer sorts in nonincreasing order; enforce it against rounding (and keep the
        // vectors consistent with the values).
        let mut idx: Vec<usize> = (0..r).collect();
        idx.sort_by(|&a, &b| row[b].total_cmp(&row[a]));
        row = idx.iter().map(|&i| row[i]).collect();
        for &i in &idx {
            u.extend((0..ny).map(|p| um[(p, i)]));
            v.extend((0..nu).map(|q| vm[(q, i)]));
        }
        freq_hz.push(f);
        sv2.push(row);
        if let Some(nf) = &mut noise_f2 {
            data.variance_line_into(k, &mut var);
            let t: f64 = var.iter().filter(|x| x.is_finite()).sum();
            nf.push(t);
        }
    }
    Ok(Cmif {
        freq_hz,
        sv2,
        noise_f2,
        ny,
        nu,
        r,
        u,
        v,
    })
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
    /// noise standard deviations (`sqrt(sum_e var_e)` of the line, which bounds
    /// `|u^H E v|` for unit vectors) before measuring the prominence. Default 2.
    pub noise_sigmas: f64,
    /// Without a variance, a candidate must also rise above this many times the local
    /// roughness of its CMIF curve (robust standard deviation, dB, of the line-to-line
    /// second difference over +-50 lines, which a smooth resonance barely has and noise
    /// does). Default 4; 0 disables.
    pub roughness_factor: f64,
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
            roughness_factor: 4.0,
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
    /// close or share a singular value. Returns `|e|^2` per line (the CMIF's units).
    pub fn enhanced_frf(&self, k: usize, j: usize, lines: std::ops::Range<usize>) -> Vec<f64> {
        let lines = lines.start.min(self.n_lines())..lines.end.min(self.n_lines());
        if k >= self.n_lines() || j >= self.r {
            return vec![0.0; lines.len()];
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
                e.norm_sqr()
            })
            .collect()
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
///    dynamic range, and above the curve's roughness when the data carry no variance.
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
            let rough = (cmif.noise_f2.is_none() && cfg.roughness_factor > 0.0)
                .then(|| roughness_db(&y, 50));
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
                if let Some(rg) = &rough {
                    if prom.is_nan() || prom < cfg.roughness_factor * rg[k] {
                        continue;
                    }
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
    let e = cmif.enhanced_frf(k, j, lo..hi);
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
    if let (Some(nf), true) = (&cmif.noise_f2, z > 0.0) {
        let sp = e[m].sqrt() - z * nf[ml].sqrt();
        let sc = e[col].sqrt() + z * nf[lo + col].sqrt();
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

/// Local roughness of a curve in dB: the robust standard deviation (median absolute
/// second difference / 0.6745 / sqrt(6)) over `+-half` lines around each line. White
/// noise of standard deviation `s` dB gives `s`; a smooth resonance sampled finely gives
/// about zero.
fn roughness_db(y: &[f64], half: usize) -> Vec<f64> {
    let n = y.len();
    if n < 3 {
        return vec![0.0; n];
    }
    let d2: Vec<f64> = (1..n - 1)
        .map(|k| (y[k + 1] - 2.0 * y[k] + y[k - 1]).abs())
        .collect();
    let mut out = vec![0.0; n];
    let mut buf = Vec::with_capacity(2 * half + 1);
    // Evaluate on a stride and hold, medians are costly and the roughness varies slowly.
    let stride = (half / 5).max(1);
    let mut k = 0;
    while k < n {
        let a = k.saturating_sub(half).min(d2.len() - 1);
        let b = (k + half).min(d2.len() - 1);
        buf.clear();
        buf.extend_from_slice(&d2[a..=b]);
        let mid = buf.len() / 2;
        buf.select_nth_unstable_by(mid, f64::total_cmp);
        let med = buf[mid];
        let s = med / 0.6745 / 6f64.sqrt();
        for o in out.iter_mut().skip(k).take(stride) {
            *o = s;
        }
        k += stride;
    }
    out
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
