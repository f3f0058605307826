//! Shared helpers of the realize integration tests: seeded random models and error
//! measures.
#![allow(dead_code)]

use faer::Mat;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::{ModalModel, PolePair, RealPole, ResponseGrid, StateSpace, TimeDomain, C64};

/// Which rigid-body part a random model gets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rigid {
    /// None.
    None,
    /// `R_2 / s^2` alone (a free mass).
    Mass,
    /// `R_1 / s + R_2 / s^2 + R_3 / s^3` (general nilpotent part).
    General,
}

/// Parameters of [`random_modal`].
#[derive(Debug, Clone, Copy)]
pub struct Spec {
    pub ny: usize,
    pub nu: usize,
    pub pairs: usize,
    pub real_poles: usize,
    pub rigid: Rigid,
    pub feedthrough: bool,
    /// Natural frequencies are log-uniform in `[w_lo, w_hi]` rad/s.
    pub w_lo: f64,
    pub w_hi: f64,
}

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

pub fn gauss(r: &mut ChaCha8Rng) -> f64 {
    // Box-Muller, enough for test data.
    let u1: f64 = r.random_range(1e-12..1.0);
    let u2: f64 = r.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

pub fn log_uniform(r: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    (r.random_range(lo.ln()..hi.ln())).exp()
}

/// A random complex `ny x nu` matrix of rank `rank` (sum of random dyads).
pub fn random_complex_rank(r: &mut ChaCha8Rng, ny: usize, nu: usize, rank: usize) -> Mat<C64> {
    let mut m = Mat::<C64>::zeros(ny, nu);
    for _ in 0..rank {
        let x: Vec<C64> = (0..ny).map(|_| C64::new(gauss(r), gauss(r))).collect();
        let y: Vec<C64> = (0..nu).map(|_| C64::new(gauss(r), gauss(r))).collect();
        for i in 0..ny {
            for j in 0..nu {
                m[(i, j)] += x[i] * y[j];
            }
        }
    }
    m
}

/// A random real `ny x nu` matrix of rank `rank`.
pub fn random_real_rank(r: &mut ChaCha8Rng, ny: usize, nu: usize, rank: usize) -> Mat<f64> {
    let mut m = Mat::<f64>::zeros(ny, nu);
    for _ in 0..rank {
        let x: Vec<f64> = (0..ny).map(|_| gauss(r)).collect();
        let y: Vec<f64> = (0..nu).map(|_| gauss(r)).collect();
        for i in 0..ny {
            for j in 0..nu {
                m[(i, j)] += x[i] * y[j];
            }
        }
    }
    m
}

/// A random stable modal model and the minimal order it should realize with.
pub fn random_modal(seed: u64, spec: Spec) -> (ModalModel, usize) {
    let mut r = rng(seed);
    let (ny, nu) = (spec.ny, spec.nu);
    let maxr = ny.min(nu);
    let mut m = ModalModel::new(ny, nu);
    let mut order = 0;
    for _ in 0..spec.pairs {
        let wn = log_uniform(&mut r, spec.w_lo, spec.w_hi);
        let zeta = log_uniform(&mut r, 1e-3, 0.3);
        let rank = r.random_range(1..=maxr);
        // Residues scaled like a mechanical mode: |R| ~ 1/wn.
        let mut res = random_complex_rank(&mut r, ny, nu, rank);
        for v in res.as_mut().col_iter_mut() {
            for x in v.iter_mut() {
                *x /= wn;
            }
        }
        m.pairs.push(PolePair {
            pole: C64::new(-zeta * wn, wn * (1.0 - zeta * zeta).sqrt()),
            residue: res,
        });
        order += 2 * rank;
    }
    for _ in 0..spec.real_poles {
        let p = -log_uniform(&mut r, spec.w_lo, spec.w_hi);
        let rank = r.random_range(1..=maxr);
        m.real_poles.push(RealPole {
            pole: p,
            residue: random_real_rank(&mut r, ny, nu, rank),
        });
        order += rank;
    }
    match spec.rigid {
        Rigid::None => {}
        Rigid::Mass => {
            let rank = r.random_range(1..=maxr);
            m.rigid = vec![Mat::zeros(ny, nu), random_real_rank(&mut r, ny, nu, rank)];
            order += 2 * rank;
        }
        Rigid::General => {
            // Full-rank generic coefficients: the Hankel rank is 3 min(ny, nu) when
            // R_3 has full rank (R_3 / s^3 needs 3 rank(R_3) states at least, and generic
            // R_1, R_2 add none beyond the block-triangular Hankel's rank).
            let r1 = random_real_rank(&mut r, ny, nu, maxr);
            let r2 = random_real_rank(&mut r, ny, nu, maxr);
            // R_3 is drawn again until its smallest singular value is above 1e-2 of the
            // largest of R_1, R_2 and R_3: the smallest Hankel singular value scales like
            // sigma_min(R_3)^3, and a nearly singular R_3 (seen: condition 6e4), or a
            // scalar one small beside R_2 (seen: 1 x 1, R_3 = 2.4e-5 with R_2 = 1.09, seed
            // 16661605394426419657, realized with 9 states), makes the numerical rank at
            // 1e-12 lower than 3 min(ny, nu), which is then the right minimal order, not
            // the one counted here.
            let largest =
                |x: &Mat<f64>| x.singular_values().expect("SVD of a small finite matrix")[0];
            let scale = largest(&r1).max(largest(&r2));
            let mut r3 = random_real_rank(&mut r, ny, nu, maxr);
            for _ in 0..1000 {
                let sv = r3.singular_values().expect("SVD of a small finite matrix");
                if sv[maxr - 1] > 1e-2 * sv[0].max(scale) {
                    break;
                }
                r3 = random_real_rank(&mut r, ny, nu, maxr);
            }
            m.rigid = vec![r1, r2, r3];
            order += 3 * maxr;
        }
    }
    if spec.feedthrough {
        m.feedthrough = Mat::from_fn(ny, nu, |_, _| 0.1 * gauss(&mut r));
    }
    (m, order)
}

/// `points` log-spaced frequencies in `[lo, hi]` plus the damped natural frequency of
/// every pole pair of `m` (the resonance peaks), sorted.
pub fn grid_with_peaks(m: &ModalModel, lo: f64, hi: f64, points: usize) -> Vec<f64> {
    let mut w: Vec<f64> = (0..points)
        .map(|k| lo * (hi / lo).powf(k as f64 / (points - 1) as f64))
        .collect();
    w.extend(
        m.pairs
            .iter()
            .map(|p| p.pole.im)
            .filter(|&x| x > lo && x < hi),
    );
    w.sort_by(|a, b| a.partial_cmp(b).unwrap());
    w
}

/// Largest over lines of `max_entry |a - b| / max_entry |b|`.
pub fn max_line_rel_err(a: &ResponseGrid, b: &ResponseGrid) -> f64 {
    assert_eq!((a.ny, a.nu, a.len()), (b.ny, b.nu, b.len()));
    let mut worst = 0.0f64;
    for k in 0..a.len() {
        let (la, lb) = (a.line(k), b.line(k));
        let num = la
            .iter()
            .zip(lb)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max);
        let den = lb.iter().map(|y| y.norm()).fold(0.0, f64::max);
        let e = if den > 0.0 { num / den } else { num };
        worst = worst.max(e);
    }
    worst
}

/// A random well-conditioned similarity `T = I + 0.3 G` applied to `ss`:
/// `(T^-1 A T, T^-1 B, C T, D)`.
pub fn random_similarity(ss: &StateSpace, seed: u64) -> StateSpace {
    use faer::linalg::solvers::Solve;
    let mut r = rng(seed);
    let n = ss.n_states();
    let t = Mat::from_fn(n, n, |i, j| {
        (if i == j { 1.0 } else { 0.0 }) + 0.3 * gauss(&mut r) / (n as f64).sqrt()
    });
    let lu = t.partial_piv_lu();
    let at = &ss.a * &t;
    let a = lu.solve(&at);
    let b = lu.solve(&ss.b);
    let c = &ss.c * &t;
    StateSpace::new(a, b, c, ss.d.clone(), TimeDomain::Continuous).unwrap()
}

/// Frobenius norm of `a - b`.
pub fn diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    (a - b).norm_l2()
}
