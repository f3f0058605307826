//! The simulation example of Section 6 of Oomen and Bosgra, "Well-posed model
//! uncertainty estimation by design of validation experiments": the true ARX system (30)
//! `(1 - 0.9 z^-1 + 0.7 z^-2) y = 0.3 z^-2 u + e` with unit-variance white `e`, the
//! nominal model (31) `P^ = 0.3 z^-2 / (1 - z^-1 + 0.7 z^-2)` with additive uncertainty,
//! the multisine (32) `u(t) = sum_i sin(w_i t)` at `w_i = 2 pi p_i / N`, `N = 100`,
//! `p_i = 1, 5, 10, 15, 20, 25, 30, 35, 40, 45` (ERRATA: the paper prints the second 20
//! for 25), `alpha = 0.99`.
//!
//! [`run`] simulates `n_per + 1` periods in the time domain, discards the first (the
//! transient: the poles have modulus `sqrt(0.7)`, `0.84^100 < 1e-7`), estimates the FRF
//! and the disturbance covariance with the nonparametric estimator of the periodic
//! measurement, builds the disturbance model (Prop. 9) in the scaling of the DFT (6) over
//! the whole record (eq. (25): `W` grows as `sqrt(n_per)`, the disturbance does not) and
//! solves the FDMVOP per line by the mu bisection ([`min_gamma`]).

use crate::disturbance::DisturbanceModel;
use crate::invalidation::{min_gamma, min_gamma_additive, GammaConfig, LineData, UncertaintyModel};
use crate::ValidationError;
use experiment::nonparametric::{Accumulator, EstimatorConfig, RealizationSpectra};
use faer::Mat;
use frf_data::C64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::f64::consts::TAU;

/// Period length `N` of Section 6.
pub const N: usize = 100;
/// The validation lines `p_i` (`w_i = 2 pi p_i / N`).
pub const LINES: [usize; 10] = [1, 5, 10, 15, 20, 25, 30, 35, 40, 45];
/// The probability level of Section 6.
pub const ALPHA: f64 = 0.99;

/// `z^-1` at angular frequency `w` (rad/sample).
fn zinv(w: f64) -> C64 {
    C64::new(w.cos(), -w.sin())
}

/// The true system (30) at `w`.
pub fn true_system(w: f64) -> C64 {
    let q = zinv(w);
    0.3 * q * q / (1.0 - 0.9 * q + 0.7 * q * q)
}

/// The noise filter `H = 1 / A` of (30) at `w`.
pub fn true_noise_filter(w: f64) -> C64 {
    let q = zinv(w);
    1.0 / (1.0 - 0.9 * q + 0.7 * q * q)
}

/// The nominal model (31) at `w`.
pub fn nominal_model(w: f64) -> C64 {
    let q = zinv(w);
    0.3 * q * q / (1.0 - q + 0.7 * q * q)
}

/// The result at one validation line.
#[derive(Debug, Clone, PartialEq)]
pub struct Section6Line {
    /// DFT bin `p`.
    pub p: usize,
    /// Number of periods used.
    pub n_per: usize,
    /// The FDMVOP's minimum uncertainty (mu bisection, certified end).
    pub gamma: f64,
    /// The additive closed form `max(0, (|E| - V~) / |W|)`, for comparison.
    pub gamma_closed_form: f64,
    /// `|P0 - P^|`.
    pub true_error: f64,
    /// The estimated disturbance bound `V~` (14), DFT (6) scaling (one period's
    /// covariance, which the whole record's DFT shares).
    pub v_tilde: f64,
    /// `V~` from the true covariance `|H|^2` (unit-variance `e`).
    pub v_tilde_true: f64,
    /// `V~ / |W|` of the whole record: the disturbance's share of the normalised residual
    /// (Prop. 10), FRF units.
    pub disturbance_over_w: f64,
}

/// Simulates `n_per` periods (plus one discarded) with noise seed `seed` and solves the
/// FDMVOP at the ten lines (see the module documentation).
pub fn run(
    n_per: usize,
    seed: u64,
    cfg: &GammaConfig,
) -> Result<Vec<Section6Line>, ValidationError> {
    if n_per < 2 {
        return Err(ValidationError::config(
            "n_per",
            n_per,
            "at least 2 periods (the disturbance covariance is estimated from their spread)",
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let omegas: Vec<f64> = LINES.iter().map(|&p| TAU * p as f64 / N as f64).collect();
    let u_at = |t: usize| -> f64 { omegas.iter().map(|w| (w * t as f64).sin()).sum() };
    let u_period: Vec<f64> = (0..N).map(u_at).collect();
    // DFT kernels at the lines, unnormalised (one sign throughout: e^{-j w t})
    let kern: Vec<Vec<C64>> = omegas
        .iter()
        .map(|w| {
            (0..N)
                .map(|t| C64::from_polar(1.0, -w * t as f64))
                .collect()
        })
        .collect();
    let l = LINES.len();
    let mut input = Vec::with_capacity(n_per * l);
    let mut output = Vec::with_capacity(n_per * l);
    let (mut y1, mut y2, mut u1, mut u2) = (0.0, 0.0, 0.0, 0.0);
    let mut ybuf = vec![0.0; N];
    for period in 0..=n_per {
        for (t, yt) in ybuf.iter_mut().enumerate() {
            let u = u_period[t];
            let e: f64 = StandardNormal.sample(&mut rng);
            let y = 0.9 * y1 - 0.7 * y2 + 0.3 * u2 + e;
            *yt = y;
            (y2, y1) = (y1, y);
            (u2, u1) = (u1, u);
        }
        if period == 0 {
            continue;
        }
        for kk in &kern {
            input.push(kk.iter().zip(&u_period).map(|(k, u)| k * u).sum::<C64>());
            output.push(kk.iter().zip(&ybuf).map(|(k, y)| k * y).sum::<C64>());
        }
    }
    let freq: Vec<f64> = LINES.iter().map(|&p| p as f64 / N as f64).collect();
    let u_bar: Vec<C64> = input[..l].to_vec(); // the input is exactly periodic
    let spectra = RealizationSpectra::new(1, n_per, l, 1, 1, input, output, None)?;
    let mut acc = Accumulator::new(freq, 1, 1, 1, EstimatorConfig::default())?;
    acc.add(&spectra)?;
    let est = acc.finish()?;
    let cv = est.disturbance_covariance.as_ref().ok_or_else(|| {
        ValidationError::invalid_input("simulation", "no disturbance covariance estimated")
    })?;
    let unc = UncertaintyModel::additive(1, 1);
    let scale = ((n_per as f64) / N as f64).sqrt(); // DFT (6) over n_per N samples
    let mut out = Vec::with_capacity(l);
    for (k, &p) in LINES.iter().enumerate() {
        let w = omegas[k];
        let g = est.frf.values()[k];
        let wk = u_bar[k] * scale;
        let phat = nominal_model(w);
        let line = LineData {
            w: vec![wk],
            z_m: vec![g * wk],
            nominal: Mat::from_fn(1, 1, |_, _| phat),
        };
        let cv_paper = cv[k].re / N as f64;
        let dist = DisturbanceModel::scalar(cv_paper, ALPHA)?;
        let mg = min_gamma(&unc, &line, &dist, cfg)?;
        let (closed, _) = min_gamma_additive(&line, &dist)?;
        let true_dist = DisturbanceModel::scalar(true_noise_filter(w).norm_sqr(), ALPHA)?;
        out.push(Section6Line {
            p,
            n_per,
            gamma: mg.gamma,
            gamma_closed_form: closed,
            true_error: (true_system(w) - phat).norm(),
            v_tilde: dist.v_tilde[0],
            v_tilde_true: true_dist.v_tilde[0],
            disturbance_over_w: dist.v_tilde[0] / wk.norm(),
        });
    }
    Ok(out)
}
