//! The identified poles in the model currency ([`realize::FrfModel`]).
//!
//! The eigenvalues of the identified `A` are mapped exactly to continuous poles
//! (`s = ln(z)/Ts` through the hold, `s = (2/T)(xi - 1)/(xi + 1)` for the bilinear
//! variable). Poles within a fraction of the lowest line of the origin are the
//! rigid-body integrators (`z = 1`, `s = 0`; a double integrator is a defective pair
//! that noise splits, so the cluster is recognised by its distance, not by exact
//! equality). Unstable poles are reflected into the left half-plane (`s -> -conj(s)`,
//! `z -> 1/conj(z)`) and reported.
//!
//! The residue matrices, the rigid-body coefficients and the feedthrough are then fitted
//! by linear least squares on the data, with the weights of the chain's criterion and
//! the currency's own response (every known factor and the exact hold included), entry
//! by entry (entries whose weights are proportional share one QR of their common
//! regressor, [`frf_data::proportional_groups`]): for a zero-order-hold plant and exact poles this reproduces the data
//! exactly, and it is the best fit of the currency for those poles. The residues are
//! full matrices (their numerical rank is what the data give).

use crate::prepare::Variable;
use crate::realization::condition;
use crate::SubspaceError;
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::SolveLstsq;
use faer::{Accum, Mat, Par};
use rayon::prelude::*;
use realize::{FrfModel, KnownFactors, ModalModel, PolePair, RealPole, C64};
use serde::{Deserialize, Serialize};

/// A pole that was moved into the stable region.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReflectedPole {
    /// The identified pole, real part (rad/s).
    pub re: f64,
    /// The identified pole, imaginary part (rad/s).
    pub im: f64,
    /// Its frequency `|s| / 2 pi`, Hz.
    pub f_hz: f64,
}

/// The poles of the currency.
#[derive(Debug, Clone, Default)]
pub struct PoleSet {
    /// Upper poles of the complex pairs, rad/s.
    pub pairs: Vec<C64>,
    /// Real poles (not at the origin), rad/s.
    pub reals: Vec<f64>,
    /// Eigenvalues recognised as integrators.
    pub at_origin: usize,
    /// Integrators of the rigid-body part.
    pub integrators: usize,
    /// Poles reflected into the left half-plane.
    pub reflected: Vec<ReflectedPole>,
    /// Notes (eigenvalues that have no continuous image).
    pub notes: Vec<String>,
    /// For every pole pair, the eigenvalues (upper, continuous) merged into it (one
    /// for a pole that was not merged).
    pub pair_members: Vec<Vec<C64>>,
}

impl PoleSet {
    /// These poles with `k` integrators in the rigid-body part, where the added ones
    /// (`k` above [`PoleSet::integrators`]) replace up to as many states that stand
    /// below [`SPLIT_INTEGRATOR_REACH`] times the lowest line `omega_min` (rad/s) and
    /// are not lightly damped: real poles, and pairs of damping above
    /// [`SPLIT_INTEGRATOR_DAMPING`] (two states each), the nearest the origin first. A
    /// double integrator is a defective pair at the origin that any perturbation (noise,
    /// or the misfit of a realisation that left out a state) splits by about the square
    /// root of its size: into two real poles or a heavily damped pair, at the lowest
    /// lines or below them (a noise-free 8-mode system of the chain harness, seed 560
    /// through the hold: a pair at 10.9 Hz with damping 0.58 for lines from 10 Hz),
    /// which the integrators must replace for the structure to be the rigid body's.
    pub fn with_integrators(&self, k: usize, omega_min: f64) -> PoleSet {
        let mut out = self.clone();
        let mut states = k.saturating_sub(self.integrators);
        out.integrators = k;
        // (|s|, is a pair, index)
        let mut below: Vec<(f64, bool, usize)> = self
            .pairs
            .iter()
            .enumerate()
            .filter(|(_, p)| {
                p.norm() < SPLIT_INTEGRATOR_REACH * omega_min
                    && -p.re > SPLIT_INTEGRATOR_DAMPING * p.norm()
            })
            .map(|(i, p)| (p.norm(), true, i))
            .chain(
                self.reals
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| r.abs() < SPLIT_INTEGRATOR_REACH * omega_min)
                    .map(|(i, r)| (r.abs(), false, i)),
            )
            .collect();
        below.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut drop_pairs, mut drop_reals) = (Vec::new(), Vec::new());
        for (_, pair, i) in below {
            let n = if pair { 2 } else { 1 };
            if n > states {
                continue;
            }
            states -= n;
            if pair {
                drop_pairs.push(i);
            } else {
                drop_reals.push(i);
            }
        }
        let keep = |i: &usize, drop: &[usize]| !drop.contains(i);
        out.pairs = (0..self.pairs.len())
            .filter(|i| keep(i, &drop_pairs))
            .map(|i| self.pairs[i])
            .collect();
        out.pair_members = (0..self.pair_members.len())
            .filter(|i| keep(i, &drop_pairs))
            .map(|i| self.pair_members[i].clone())
            .collect();
        out.reals = (0..self.reals.len())
            .filter(|i| keep(i, &drop_reals))
            .map(|i| self.reals[i])
            .collect();
        out
    }
}

/// Damping above which a pole pair below the band is taken for a split double
/// integrator by [`PoleSet::with_integrators`] (a mode below the band that the data
/// show is lightly damped; a split defective pair at the origin is a pair of damping
/// near 1 or two real poles).
pub const SPLIT_INTEGRATOR_DAMPING: f64 = 0.5;

/// How far above the lowest line (as a factor of it) [`PoleSet::with_integrators`]
/// looks for the states of a split double integrator.
pub const SPLIT_INTEGRATOR_REACH: f64 = 2.0;

/// Classifies the eigenvalues `eig` of the identified `A` (see the module
/// documentation). `omega_min` is the lowest line (rad/s); poles with
/// `|s| < rigid_fraction * omega_min` are integrators, at most `max_integrators` of
/// them in the rigid-body part. Poles within `merge_tol` (relative) of each other are
/// one pole with a residue of higher rank (a minimal state space repeats a pole once
/// per rank of its residue). `weight[i]` is the size `|C u_i|^2 |(U^-1 B)_i|^2` of the
/// residue of eigenvalue `i` ([`eigen_weights`]); merged poles are averaged with these
/// weights. A repeated pole of a residue of rank 2 is split by noise, and the
/// eigenvalue of the weak direction of the residue is determined much less precisely
/// than that of the strong one (its variance scales as the inverse squared residue):
/// the plain mean moved the merged pole by half the split (0.1 % of a lightly damped
/// mode's frequency at a relative noise of 1e-4, i.e. several percent of its
/// half-power bandwidth), the weighted mean stays with the well-determined eigenvalue.
pub fn classify(
    eig: &[C64],
    weight: &[f64],
    variable: Variable,
    omega_min: f64,
    rigid_fraction: f64,
    max_integrators: usize,
    merge_tol: f64,
) -> PoleSet {
    let mut ps = PoleSet::default();
    let (mut pair_w, mut real_w) = (Vec::new(), Vec::new());
    for (i, &l) in eig.iter().enumerate() {
        let wi = weight
            .get(i)
            .copied()
            .filter(|w| w.is_finite() && *w > 0.0)
            .unwrap_or(1.0);
        let is_real_eig = l.im.abs() <= 1e-12 * l.norm();
        if let Variable::Shift { ts } = variable {
            if l.norm() == 0.0 || (is_real_eig && l.re < 0.0) {
                ps.notes.push(format!(
                    "eigenvalue z = {:.4e} has no continuous image through the hold (a real pole at z <= 0, {:.1} Hz): left out",
                    l.re,
                    0.5 / ts
                ));
                continue;
            }
        }
        let mut s = variable.to_s(if is_real_eig { C64::new(l.re, 0.0) } else { l });
        if !(s.re.is_finite() && s.im.is_finite()) {
            ps.notes
                .push(format!("eigenvalue {l} maps to an infinite pole: left out"));
            continue;
        }
        if s.norm() < rigid_fraction * omega_min {
            ps.at_origin += 1;
            continue;
        }
        if s.im < 0.0 && !is_real_eig {
            continue; // the conjugate of an upper pole
        }
        if s.re > 0.0 {
            ps.reflected.push(ReflectedPole {
                re: s.re,
                im: s.im,
                f_hz: s.norm() / std::f64::consts::TAU,
            });
            s.re = -s.re;
        }
        if is_real_eig {
            real_w.push((C64::new(s.re, 0.0), wi));
        } else {
            pair_w.push((s, wi));
        }
    }
    ps.integrators = ps.at_origin.min(max_integrators);
    pair_w.sort_by(|a, b| a.0.norm().total_cmp(&b.0.norm()));
    real_w.sort_by(|a, b| b.0.re.total_cmp(&a.0.re));
    let (pairs, pair_members, merged_p) = merge(&pair_w, merge_tol);
    let (reals, _, merged_r) = merge(&real_w, merge_tol);
    ps.pair_members = pair_members;
    if merged_p + merged_r > 0 {
        ps.notes.push(format!(
            "{} repeated poles (a residue of rank > 1, or a pole split by noise; within {merge_tol:.0e} relative) merged: one residue matrix each",
            merged_p + merged_r
        ));
    }
    ps.pairs = pairs;
    ps.reals = reals.into_iter().map(|z| z.re).collect();
    ps
}

/// Merges poles (sorted by modulus) closer than `tol` relative to a group's weighted
/// mean into that mean (weights: the residue sizes, see [`classify`]); returns the
/// poles and how many were merged away.
fn merge(poles: &[(C64, f64)], tol: f64) -> (Vec<C64>, Vec<Vec<C64>>, usize) {
    // (weighted sum, weight sum, members)
    let mut out: Vec<(C64, f64, Vec<C64>)> = Vec::new();
    let mut merged = 0;
    for &(p, w) in poles {
        if let Some(last) = out
            .iter_mut()
            .find(|(q, c, _)| ((*q / *c) - p).norm() <= tol * p.norm())
        {
            last.0 += p * w;
            last.1 += w;
            last.2.push(p);
            merged += 1;
        } else {
            out.push((p * w, w, vec![p]));
        }
    }
    let poles = out.iter().map(|(s, c, _)| s / c).collect();
    let members = out.into_iter().map(|(_, _, m)| m).collect();
    (poles, members, merged)
}

/// The eigenvalues of `A` and the sizes of their residues in `C (xi I - A)^-1 B`:
/// with `A = U diag(l) U^-1`, the residue of `l_i` is `(C u_i)(U^-1 B)_i`, of size
/// `|C u_i|^2 |(U^-1 B)_i|^2`. Falls back to unit weights when the eigenvectors are
/// singular (a defective `A`).
pub fn eigen_weights(
    a: &Mat<f64>,
    b: &Mat<f64>,
    c: &Mat<f64>,
) -> Result<(Vec<C64>, Vec<f64>), SubspaceError> {
    use faer::linalg::solvers::Solve;
    let n = a.nrows();
    let e = a
        .eigen()
        .map_err(|e| SubspaceError::numerical("eigendecomposition of A", format!("{e:?}")))?;
    let s = e.S().column_vector();
    let eig: Vec<C64> = (0..n).map(|i| C64::new(s[i].re, s[i].im)).collect();
    if eig.iter().any(|z| !(z.re.is_finite() && z.im.is_finite())) {
        return Err(SubspaceError::numerical(
            "eigenvalues of A",
            "non-finite eigenvalues",
        ));
    }
    let u = e.U().to_owned();
    let bc = Mat::from_fn(n, b.ncols(), |i, j| faer::c64::new(b[(i, j)], 0.0));
    let x = u.partial_piv_lu().solve(&bc);
    let weight: Vec<f64> = (0..n)
        .map(|i| {
            let cu: f64 = (0..c.nrows())
                .map(|o| {
                    (0..n)
                        .map(|l| u[(l, i)] * c[(o, l)])
                        .fold(faer::c64::new(0.0, 0.0), |acc, v| acc + v)
                        .norm_sqr()
                })
                .sum();
            let xb: f64 = (0..b.ncols()).map(|j| x[(i, j)].norm_sqr()).sum();
            cu * xb
        })
        .collect();
    let ok = weight.iter().all(|w| w.is_finite() && *w > 0.0);
    Ok((eig, if ok { weight } else { vec![1.0; n] }))
}

/// One basis term of the currency: which coefficient it multiplies.
#[derive(Debug, Clone, Copy)]
enum Term {
    PairRe(usize),
    PairIm(usize),
    Real(usize),
    Rigid(usize),
    Feedthrough,
}

fn unit_model(ps: &PoleSet, term: Term) -> ModalModel {
    let one = |z: C64| Mat::from_fn(1, 1, |_, _| z);
    let mut m = ModalModel::new(1, 1);
    match term {
        Term::PairRe(q) => m.pairs.push(PolePair {
            pole: ps.pairs[q],
            residue: one(C64::new(1.0, 0.0)),
        }),
        Term::PairIm(q) => m.pairs.push(PolePair {
            pole: ps.pairs[q],
            residue: one(C64::new(0.0, 1.0)),
        }),
        Term::Real(q) => m.real_poles.push(RealPole {
            pole: ps.reals[q],
            residue: Mat::from_fn(1, 1, |_, _| 1.0),
        }),
        Term::Rigid(k) => {
            m.rigid = (0..=k)
                .map(|i| Mat::from_fn(1, 1, |_, _| if i == k { 1.0 } else { 0.0 }))
                .collect()
        }
        Term::Feedthrough => m.feedthrough = Mat::from_fn(1, 1, |_, _| 1.0),
    }
    m
}

/// The linear terms of the residue fit of `ps`, in the order of [`residue_basis`].
fn terms_of(ps: &PoleSet) -> Vec<Term> {
    let mut terms = Vec::new();
    for q in 0..ps.pairs.len() {
        terms.push(Term::PairRe(q));
        terms.push(Term::PairIm(q));
    }
    terms.extend((0..ps.reals.len()).map(Term::Real));
    terms.extend((0..ps.integrators).map(Term::Rigid));
    terms.push(Term::Feedthrough);
    terms
}

/// The basis of the residue fit of [`fit_residues`]: the currency's own response
/// (with `factors`) at `omega` of each unit term (the real and the imaginary part of
/// the residue of every pair, every real pole, every integrator, the feedthrough).
pub fn residue_basis(
    ps: &PoleSet,
    factors: &KnownFactors,
    omega: &[f64],
) -> Result<Vec<Vec<C64>>, SubspaceError> {
    let terms = terms_of(ps);
    let mut basis = Vec::with_capacity(terms.len());
    for &t in &terms {
        let fm = FrfModel {
            modal: unit_model(ps, t),
            factors: KnownFactors {
                dynamics: Vec::new(),
                crosstalk: None,
                ..factors.clone()
            },
        };
        basis.push(fm.freq_response(omega)?.values);
    }
    Ok(basis)
}

/// Scales every column of `a` to unit norm (a zero column stays) and returns the
/// scales: the least-squares solution of the scaled regressor divided by them is that of
/// `a`.
pub(crate) fn scale_columns(a: &mut Mat<f64>) -> Vec<f64> {
    let scale: Vec<f64> = (0..a.ncols())
        .map(|q| {
            let s = a.col(q).norm_l2();
            if s > 0.0 {
                s
            } else {
                1.0
            }
        })
        .collect();
    for (q, &s) in scale.iter().enumerate() {
        for r in 0..a.nrows() {
            a[(r, q)] /= s;
        }
    }
    scale
}

/// Fewest entries per chunk of right-hand sides in [`fit_residues`].
const RHS_CHUNK_MIN: usize = 32;

/// Fits the residues, rigid-body coefficients and feedthrough of the poles `ps` to the
/// data `g` (line after line, each `vec(G)`) at `omega` with weights `w` (same layout),
/// through the currency's response with `factors`. Returns the model, the worst
/// condition number of the (column-scaled) regressors, and the weighted cost of the
/// model against `g`, `sum w |g - P|^2 / (2 N)` (the normalisation of
/// `frf_data::weighted_cost`), from the explicit least-squares residual: the model's
/// response need not be computed again.
pub fn fit_residues(
    ny: usize,
    nu: usize,
    omega: &[f64],
    g: &[C64],
    w: &[f64],
    ps: &PoleSet,
    factors: &KnownFactors,
) -> Result<(FrfModel, f64, f64), SubspaceError> {
    let terms = terms_of(ps);
    let (nl, nb, m) = (omega.len(), terms.len(), ny * nu);
    if 2 * nl < nb {
        return Err(SubspaceError::TooFewLines {
            lines: nl,
            band: "the data".into(),
            block_rows: 0,
            order: nb,
            needed: nb.div_ceil(2),
        });
    }
    let basis = residue_basis(ps, factors, omega)?;
    let mut modal = ModalModel::new(ny, nu);
    modal.pairs = ps
        .pairs
        .iter()
        .map(|&pole| PolePair {
            pole,
            residue: Mat::zeros(ny, nu),
        })
        .collect();
    modal.real_poles = ps
        .reals
        .iter()
        .map(|&pole| RealPole {
            pole,
            residue: Mat::zeros(ny, nu),
        })
        .collect();
    modal.rigid = (0..ps.integrators).map(|_| Mat::zeros(ny, nu)).collect();
    // entries with proportional weights share their regressor: one QR per group, the
    // groups in parallel
    let groups = frf_data::proportional_groups(w, m, 1e-12);
    // per group: the coefficients, the condition number and the weighted residual
    type Solved = Result<(Mat<f64>, f64, f64), SubspaceError>;
    let solved: Vec<Solved> = groups
        .par_iter()
        .map(|grp| {
            let mut a = Mat::<f64>::zeros(2 * nl, nb);
            for k in 0..nl {
                let sw = grp.line_weights[k].sqrt();
                for (q, col) in basis.iter().enumerate() {
                    a[(2 * k, q)] = col[k].re * sw;
                    a[(2 * k + 1, q)] = col[k].im * sw;
                }
            }
            let scale = scale_columns(&mut a);
            let qr = a.qr();
            let cond = condition(&qr.thin_R().to_owned());
            // the right-hand sides (the group's entries) in chunks on the rayon pool: with
            // one noise level all entries are one group, and applying Q^T to thousands of
            // columns is the cost
            let chunk = grp
                .entries
                .len()
                .div_ceil(rayon::current_num_threads().max(1));
            let parts: Vec<(Mat<f64>, f64)> = grp
                .entries
                .par_chunks(chunk.max(RHS_CHUNK_MIN))
                .zip(grp.scales.par_chunks(chunk.max(RHS_CHUNK_MIN)))
                .map(|(entries, scales)| {
                    let mut y = Mat::<f64>::zeros(2 * nl, entries.len());
                    for k in 0..nl {
                        let sw = grp.line_weights[k].sqrt();
                        for (c, &e) in entries.iter().enumerate() {
                            y[(2 * k, c)] = g[k * m + e].re * sw;
                            y[(2 * k + 1, c)] = g[k * m + e].im * sw;
                        }
                    }
                    let x = qr.solve_lstsq(&y);
                    // the residual, explicitly (no cancellation at an exact fit)
                    matmul(
                        y.as_mut(),
                        Accum::Add,
                        a.as_ref(),
                        x.as_ref(),
                        -1.0,
                        Par::Seq,
                    );
                    // the entry's weights are its scale times the group's line weights
                    let rr = (0..y.ncols())
                        .map(|c| scales[c] * y.col(c).squared_norm_l2())
                        .sum();
                    (x, rr)
                })
                .collect();
            let mut x = Mat::<f64>::zeros(nb, grp.entries.len());
            let mut c0 = 0;
            let mut rr = 0.0;
            for (part, part_rr) in &parts {
                for c in 0..part.ncols() {
                    for q in 0..nb {
                        x[(q, c0 + c)] = part[(q, c)] / scale[q];
                    }
                }
                c0 += part.ncols();
                rr += part_rr;
            }
            Ok((x, cond, rr))
        })
        .collect();
    let mut worst = 1.0f64;
    let mut rr = 0.0;
    for (grp, res) in groups.iter().zip(solved) {
        let (x, cond, grp_rr) = res?;
        worst = worst.max(cond);
        rr += grp_rr;
        for (c, &e) in grp.entries.iter().enumerate() {
            let (i, j) = (e % ny, e / ny);
            let mut re_part = vec![0.0; ps.pairs.len()];
            for (q, t) in terms.iter().enumerate() {
                let v = x[(q, c)];
                if !v.is_finite() {
                    return Err(SubspaceError::numerical(
                        "least squares of the residues",
                        format!("non-finite coefficient for entry ({}, {})", i + 1, j + 1),
                    ));
                }
                match *t {
                    Term::PairRe(p) => re_part[p] = v,
                    Term::PairIm(p) => modal.pairs[p].residue[(i, j)] = C64::new(re_part[p], v),
                    Term::Real(p) => modal.real_poles[p].residue[(i, j)] = v,
                    Term::Rigid(kk) => modal.rigid[kk][(i, j)] = v,
                    Term::Feedthrough => modal.feedthrough[(i, j)] = v,
                }
            }
        }
    }
    let model = FrfModel {
        modal,
        factors: factors.clone(),
    };
    model.validate()?;
    Ok((model, worst, rr / (2.0 * nl.max(1) as f64)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pole(f_hz: f64, zeta: f64) -> C64 {
        let w = std::f64::consts::TAU * f_hz;
        C64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt())
    }

    /// The cost from the least-squares residual is the model's weighted cost against
    /// the data, with entries of different weight scales (one proportional group) and
    /// a second group of other line weights.
    #[test]
    fn the_residual_cost_is_the_weighted_cost_of_the_fitted_model() {
        let (ny, nu, nl) = (2, 3, 40);
        let m = ny * nu;
        let omega: Vec<f64> = (0..nl).map(|k| 20.0 + 7.0 * k as f64).collect();
        let ps = PoleSet {
            pairs: vec![pole(30.0, 0.02), pole(41.0, 0.05)],
            reals: vec![-90.0],
            integrators: 1,
            at_origin: 1,
            ..PoleSet::default()
        };
        let g: Vec<C64> = (0..nl * m)
            .map(|i| C64::new((i as f64 * 0.37).sin(), (i as f64 * 0.11).cos()))
            .collect();
        let w: Vec<f64> = (0..nl * m)
            .map(|i| {
                let (k, e) = (i / m, i % m);
                let line = 1.0 + (k as f64 * 0.3).cos().abs();
                if e < 4 {
                    line * (1.0 + e as f64)
                } else {
                    1.0 + k as f64
                }
            })
            .collect();
        let factors = KnownFactors::default();
        let (model, _, cost) = fit_residues(ny, nu, &omega, &g, &w, &ps, &factors).unwrap();
        let p = model.freq_response(&omega).unwrap();
        let mut want = 0.0;
        for k in 0..nl {
            for e in 0..m {
                want += w[k * m + e] * (g[k * m + e] - p.line(k)[e]).norm_sqr();
            }
        }
        want /= 2.0 * nl as f64;
        assert!((cost - want).abs() <= 1e-10 * want, "{cost} against {want}");
    }

    /// Lines from 10 Hz: a heavily damped pair at 10.9 Hz (a split double integrator)
    /// is replaced by two integrators, a lightly damped pair at 12 Hz and the modes in
    /// the band are kept, and one added integrator replaces one real pole but not half
    /// a pair.
    #[test]
    fn added_integrators_replace_the_states_of_a_split_double_integrator() {
        let omega_min = std::f64::consts::TAU * 10.0;
        let ps = PoleSet {
            pairs: vec![pole(10.9, 0.58), pole(12.0, 0.01), pole(45.0, 0.02)],
            reals: vec![-30.0, -5000.0],
            pair_members: vec![vec![pole(10.9, 0.58)], vec![], vec![]],
            ..PoleSet::default()
        };
        let two = ps.with_integrators(2, omega_min);
        assert_eq!(two.integrators, 2);
        // the nearest the origin first: the real pole at 30 rad/s (one state), then
        // the pair does not fit in the one state left
        assert_eq!(two.reals, vec![-5000.0]);
        assert_eq!(two.pairs.len(), 3);
        // from the set without that real pole, the pair goes
        let mut no_real = ps.clone();
        no_real.reals = vec![-5000.0];
        let two = no_real.with_integrators(2, omega_min);
        assert_eq!(two.pairs, vec![pole(12.0, 0.01), pole(45.0, 0.02)]);
        assert_eq!(two.pair_members.len(), 2);
        assert_eq!(two.pair_members[0], Vec::<C64>::new());
        let one = no_real.with_integrators(1, omega_min);
        assert_eq!((one.integrators, one.pairs.len()), (1, 3));
        // nothing is replaced when no integrator is added
        let same = ps.with_integrators(0, omega_min);
        assert_eq!((same.pairs.len(), same.reals.len()), (3, 2));
    }
}
