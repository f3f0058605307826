//! The poles of a candidate order refined by Gauss-Newton with the residues eliminated,
//! for the F test of the order sweep.
//!
//! The F test of [`crate::order::f_sweep`] compares the costs of nested models; its
//! null distribution assumes each cost is the minimum over that model's parameters.
//! The poles of a subspace step are not: with noise they miss the least-squares poles
//! by a few standard deviations, so the residue refit at the true order stays well above
//! the noise (1.2 to 2 times the expected cost on random systems at 1e-4 relative
//! noise), and an added state absorbs part of that misfit with F of 20 to 50 (random
//! systems, seeds 60795 and 30976: a spurious real pole, a spurious mode). Refining the
//! poles of every candidate first makes the costs those of the models the F test
//! compares.
//!
//! With the poles fixed, the residues, rigid-body coefficients and feedthrough enter
//! linearly, entry by entry ([`crate::currency::fit_residues`]); the weighted cost is
//! then a function of the poles alone (variable projection, Golub & Pereyra 1973). Its
//! Gauss-Newton step uses Kaufman's approximation of the projected Jacobian: the
//! derivative of the model response with the linear parameters held, projected onto
//! the orthogonal complement of each entry's regressors, `J_e = -P_e^perp (dPhi/dtheta)
//! x_e`. The derivative of a pole's basis columns is a central difference of the
//! currency's own response (exact zero-order hold and known factors included).
//! Steps that do not lower the cost are halved; a step that would move a pole into
//! the right half-plane (or a pair onto the real axis) is halved too.

use crate::currency::{residue_basis, scale_columns, PoleSet};
use crate::SubspaceError;
use faer::linalg::solvers::SolveLstsq;
use faer::Mat;
use realize::{KnownFactors, C64};

/// Settings of [`refine_poles`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleRefineSettings {
    /// Gauss-Newton iterations at most.
    pub max_iterations: usize,
    /// The iteration stops when an accepted step lowers the cost by less than this
    /// fraction.
    pub rel_tol: f64,
    /// Step halvings tried before the iteration stops.
    pub max_halvings: usize,
}

impl Default for PoleRefineSettings {
    /// 20 iterations, relative tolerance 1e-9, 12 halvings.
    fn default() -> Self {
        Self {
            max_iterations: 20,
            rel_tol: 1e-9,
            max_halvings: 12,
        }
    }
}

/// The result of [`refine_poles`].
#[derive(Debug, Clone)]
pub struct RefinedPoles {
    /// The refined poles (integrators unchanged).
    pub poles: PoleSet,
    /// Weighted cost `sum w |g - model|^2` of the residue refit at the start.
    pub start_cost: f64,
    /// The same at the refined poles.
    pub cost: f64,
    /// Accepted Gauss-Newton steps.
    pub iterations: usize,
}

/// The weighted data of one entry and its regressors.
struct Entries<'a> {
    ny: usize,
    nu: usize,
    omega: &'a [f64],
    g: &'a [C64],
    w: &'a [f64],
    factors: &'a KnownFactors,
}

/// One entry's least-squares fit at fixed poles.
struct EntryFit {
    /// Column-scaled weighted regressors (`2 L x nb`, real and imaginary rows).
    a: Mat<f64>,
    /// Its QR factorisation.
    qr: faer::linalg::solvers::Qr<f64>,
    /// Coefficients of the unscaled basis.
    x: Vec<f64>,
    /// Weighted residual `sqrt(w) (g - Phi x)` (real, imaginary interleaved).
    r: Vec<f64>,
}

impl Entries<'_> {
    fn m(&self) -> usize {
        self.ny * self.nu
    }

    fn weighted(&self, basis: &[Vec<C64>], e: usize) -> (Mat<f64>, Mat<f64>) {
        let (nl, m, nb) = (self.omega.len(), self.m(), basis.len());
        let mut a = Mat::<f64>::zeros(2 * nl, nb);
        let mut y = Mat::<f64>::zeros(2 * nl, 1);
        for k in 0..nl {
            let sw = self.w[k * m + e].max(0.0).sqrt();
            for (q, col) in basis.iter().enumerate() {
                a[(2 * k, q)] = col[k].re * sw;
                a[(2 * k + 1, q)] = col[k].im * sw;
            }
            y[(2 * k, 0)] = self.g[k * m + e].re * sw;
            y[(2 * k + 1, 0)] = self.g[k * m + e].im * sw;
        }
        (a, y)
    }

    /// The linear fit of every entry at the poles `ps`, and the total cost.
    fn fit(&self, ps: &PoleSet) -> Result<(Vec<EntryFit>, f64), SubspaceError> {
        let basis = residue_basis(ps, self.factors, self.omega)?;
        let nb = basis.len();
        let mut fits = Vec::with_capacity(self.m());
        let mut cost = 0.0;
        for e in 0..self.m() {
            let (mut a, y) = self.weighted(&basis, e);
            let scale = scale_columns(&mut a);
            let qr = a.qr();
            let xs = qr.solve_lstsq(&y);
            let x: Vec<f64> = (0..nb).map(|q| xs[(q, 0)] / scale[q]).collect();
            if x.iter().any(|v| !v.is_finite()) {
                return Err(SubspaceError::numerical(
                    "pole refinement of the order test",
                    format!("non-finite residue for entry {}", e + 1),
                ));
            }
            let fitted = &a * &xs;
            let r: Vec<f64> = (0..a.nrows()).map(|i| y[(i, 0)] - fitted[(i, 0)]).collect();
            cost += r.iter().map(|v| v * v).sum::<f64>();
            fits.push(EntryFit { a, qr, x, r });
        }
        Ok((fits, cost))
    }
}

/// Which pole a parameter moves: the real or imaginary part of a pair, or a real pole.
#[derive(Debug, Clone, Copy)]
enum Param {
    PairRe(usize),
    PairIm(usize),
    Real(usize),
}

fn params(ps: &PoleSet) -> Vec<Param> {
    let mut p = Vec::new();
    for q in 0..ps.pairs.len() {
        p.push(Param::PairRe(q));
        p.push(Param::PairIm(q));
    }
    p.extend((0..ps.reals.len()).map(Param::Real));
    p
}

/// Index of the first basis column of pair `q` / real pole `q` (the order of
/// `currency::terms_of`: pairs (re, im), reals, integrators, feedthrough).
fn first_column(ps: &PoleSet, p: Param) -> usize {
    match p {
        Param::PairRe(q) | Param::PairIm(q) => 2 * q,
        Param::Real(q) => 2 * ps.pairs.len() + q,
    }
}

/// The pole set with one pole only (no integrators): its basis columns are that
/// pole's columns (and the feedthrough, not used).
fn single(ps: &PoleSet, p: Param, shift: f64) -> PoleSet {
    let mut one = PoleSet::default();
    match p {
        Param::PairRe(q) => one.pairs.push(ps.pairs[q] + C64::new(shift, 0.0)),
        Param::PairIm(q) => one.pairs.push(ps.pairs[q] + C64::new(0.0, shift)),
        Param::Real(q) => one.reals.push(ps.reals[q] + shift),
    }
    one
}

fn moved(ps: &PoleSet, ps_params: &[Param], delta: &[f64]) -> Option<PoleSet> {
    let mut out = ps.clone();
    for (&p, &d) in ps_params.iter().zip(delta) {
        match p {
            Param::PairRe(q) => out.pairs[q].re += d,
            Param::PairIm(q) => out.pairs[q].im += d,
            Param::Real(q) => out.reals[q] += d,
        }
    }
    let ok = out
        .pairs
        .iter()
        .all(|z| z.re < 0.0 && z.im > 0.0 && z.re.is_finite() && z.im.is_finite())
        && out.reals.iter().all(|r| *r < 0.0 && r.is_finite());
    ok.then_some(out)
}

/// Refines the poles of `ps` (pairs and real poles; the integrators are fixed) for the
/// weighted least-squares cost of the residue refit of [`crate::currency::fit_residues`]
/// on the data `g` (line after line, each `vec(G)`) at `omega` with weights `w`, through
/// the currency's response with `factors` (see the module documentation).
#[allow(clippy::too_many_arguments)]
pub fn refine_poles(
    ny: usize,
    nu: usize,
    omega: &[f64],
    g: &[C64],
    w: &[f64],
    ps: &PoleSet,
    factors: &KnownFactors,
    settings: &PoleRefineSettings,
) -> Result<RefinedPoles, SubspaceError> {
    let ent = Entries {
        ny,
        nu,
        omega,
        g,
        w,
        factors,
    };
    let (mut fits, start_cost) = ent.fit(ps)?;
    let mut cost = start_cost;
    let mut poles = ps.clone();
    let mut iterations = 0;
    let prm = params(&poles);
    if prm.is_empty() {
        return Ok(RefinedPoles {
            poles,
            start_cost,
            cost,
            iterations,
        });
    }
    let (nl, m) = (omega.len(), ny * nu);
    for _ in 0..settings.max_iterations {
        // dPhi/dtheta of each parameter's columns (central differences)
        let mut jac = Mat::<f64>::zeros(2 * nl * m, prm.len());
        for (i, &p) in prm.iter().enumerate() {
            let scale_p = match p {
                Param::PairRe(q) | Param::PairIm(q) => poles.pairs[q].norm(),
                Param::Real(q) => poles.reals[q].abs(),
            };
            let h = 1e-6 * scale_p.max(f64::MIN_POSITIVE);
            let plus = residue_basis(&single(&poles, p, h), factors, omega)?;
            let minus = residue_basis(&single(&poles, p, -h), factors, omega)?;
            let ncols = match p {
                Param::Real(_) => 1,
                _ => 2,
            };
            let c0 = first_column(&poles, p);
            for (e, fit) in fits.iter().enumerate() {
                // derivative of the model with this entry's coefficients held, weighted
                let mut v = Mat::<f64>::zeros(2 * nl, 1);
                for k in 0..nl {
                    let sw = w[k * m + e].max(0.0).sqrt();
                    let mut d = C64::new(0.0, 0.0);
                    for c in 0..ncols {
                        d += (plus[c][k] - minus[c][k]) / (2.0 * h) * fit.x[c0 + c];
                    }
                    v[(2 * k, 0)] = d.re * sw;
                    v[(2 * k + 1, 0)] = d.im * sw;
                }
                // projected onto the complement of the entry's regressors (Kaufman)
                let coef = fit.qr.solve_lstsq(&v);
                let proj = &fit.a * &coef;
                for r in 0..2 * nl {
                    jac[(e * 2 * nl + r, i)] = v[(r, 0)] - proj[(r, 0)];
                }
            }
        }
        let mut res = Mat::<f64>::zeros(2 * nl * m, 1);
        for (e, fit) in fits.iter().enumerate() {
            for (r, &v) in fit.r.iter().enumerate() {
                res[(e * 2 * nl + r, 0)] = v;
            }
        }
        // column-scaled Gauss-Newton step: J delta = r (the model moves by J delta)
        let cs: Vec<f64> = (0..prm.len())
            .map(|i| {
                let s = jac.col(i).norm_l2();
                if s > 0.0 && s.is_finite() {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        for (i, &s) in cs.iter().enumerate() {
            for r in 0..jac.nrows() {
                jac[(r, i)] /= s;
            }
        }
        let ds = jac.qr().solve_lstsq(&res);
        let mut delta: Vec<f64> = (0..prm.len()).map(|i| ds[(i, 0)] / cs[i]).collect();
        if delta.iter().any(|d| !d.is_finite()) {
            break;
        }
        let mut accepted = None;
        for _ in 0..=settings.max_halvings {
            if let Some(trial) = moved(&poles, &prm, &delta) {
                let (tf, tc) = ent.fit(&trial)?;
                if tc < cost {
                    accepted = Some((trial, tf, tc));
                    break;
                }
            }
            delta.iter_mut().for_each(|d| *d *= 0.5);
        }
        let Some((trial, tf, tc)) = accepted else {
            break;
        };
        let gain = (cost - tc) / cost.max(f64::MIN_POSITIVE);
        poles = trial;
        fits = tf;
        cost = tc;
        iterations += 1;
        if gain < settings.rel_tol {
            break;
        }
    }
    Ok(RefinedPoles {
        poles,
        start_cost,
        cost,
        iterations,
    })
}
