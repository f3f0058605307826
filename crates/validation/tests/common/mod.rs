//! A small lightly damped MIMO system, effects injected into it, and simulated noise
//! with known variance, for the tests of the residual analysis.
#![allow(dead_code)]

use faer::Mat;
use frf_data::{Frf, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use realize::{ModalModel, PolePair, ResponseGrid};
use std::f64::consts::TAU;

pub const NY: usize = 3;
pub const NU: usize = 4;

/// Lines 0.5 .. 1000 Hz every 0.5 Hz (2000 lines).
pub fn freqs() -> Vec<f64> {
    (1..=2000).map(|k| 0.5 * k as f64).collect()
}

pub fn omegas(f: &[f64]) -> Vec<f64> {
    f.iter().map(|x| TAU * x).collect()
}

/// Mode frequencies (Hz) and damping of the test system.
pub const MODES: [(f64, f64); 5] = [
    (62.0, 0.015),
    (131.0, 0.01),
    (243.0, 0.02),
    (412.0, 0.012),
    (705.0, 0.015),
];

fn gains(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let x: f64 = rng.sample(StandardNormal);
            x + 0.3 * x.signum()
        })
        .collect()
}

/// The nominal system: a free rigid body `R / s^2` (rank 2) and the modes of [`MODES`]
/// with residues `c b^T` (fixed seed, independent of the noise seeds).
pub fn nominal() -> ModalModel {
    let mut rng = ChaCha8Rng::seed_from_u64(12345);
    let mut m = ModalModel::new(NY, NU);
    let a = gains(&mut rng, NY);
    let b = gains(&mut rng, NU);
    let c = gains(&mut rng, NY);
    let d = gains(&mut rng, NU);
    let r = Mat::from_fn(NY, NU, |i, j| a[i] * b[j] + 0.5 * c[i] * d[j]);
    m.rigid = vec![Mat::zeros(NY, NU), r];
    for &(f, z) in &MODES {
        let c = gains(&mut rng, NY);
        let b = gains(&mut rng, NU);
        let num = Mat::from_fn(NY, NU, |i, j| c[i] * b[j]);
        m.pairs.push(PolePair::from_second_order(f, z, &num));
    }
    m
}

/// The rigid-body residue of [`nominal`].
pub fn rigid_residue() -> Mat<f64> {
    nominal().rigid[1].clone()
}

/// RMS over entries of the rigid-body residue.
pub fn rigid_rms() -> f64 {
    let r = rigid_residue();
    let mut s = 0.0;
    for i in 0..NY {
        for j in 0..NU {
            s += r[(i, j)] * r[(i, j)];
        }
    }
    (s / (NY * NU) as f64).sqrt()
}

/// The noise standard deviation of line `k`: `rel` times the rigid-body envelope
/// `rms(R) / w^2` (a relative noise level of about `rel` wherever the response follows
/// the rigid body's roll-off) plus a floor of a tenth of that envelope at 1 kHz.
pub fn sigma(f_hz: f64, rel: f64) -> f64 {
    let w = TAU * f_hz;
    let wmax = TAU * 1000.0;
    rel * rigid_rms() * (1.0 / (w * w) + 0.1 / (wmax * wmax))
}

/// Default relative noise level.
pub const REL: f64 = 1e-3;

/// A response grid's values with independent circular complex Gaussian noise of
/// standard deviation `sigma(f, rel)` added, and the exact variance.
pub fn add_noise(f: &[f64], g: &ResponseGrid, rel: f64, seed: u64) -> Frf {
    let m = g.ny * g.nu;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut values = g.values.clone();
    let mut var = vec![0.0; values.len()];
    for (k, &fk) in f.iter().enumerate() {
        let s = sigma(fk, rel);
        for e in 0..m {
            let re: f64 = rng.sample(StandardNormal);
            let im: f64 = rng.sample(StandardNormal);
            values[k * m + e] += C64::new(re, im) * (s / std::f64::consts::SQRT_2);
            var[k * m + e] = s * s;
        }
    }
    Frf::new(f.to_vec(), g.ny, g.nu, values, Some(var)).unwrap()
}

/// Like [`add_noise`] but "measured-like": the noise of one line is correlated across
/// entries (each realization is a random mixing `L z` of independent entries, as a
/// multi-experiment estimate mixes its experiments) and the variance is the sample
/// variance over `realizations` realizations divided by their number (so that
/// `|E|^2 / var` is F-distributed, heavier-tailed than Gaussian).
pub fn add_measured_noise(
    f: &[f64],
    g: &ResponseGrid,
    rel: f64,
    realizations: usize,
    seed: u64,
) -> Frf {
    let m = g.ny * g.nu;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Fixed mixing: identity plus a shared component per column and per row.
    let mut values = g.values.clone();
    let mut var = vec![0.0; values.len()];
    let r = realizations.max(2);
    let mut z = vec![C64::new(0.0, 0.0); m * r];
    for (k, &fk) in f.iter().enumerate() {
        let s = sigma(fk, rel) * (r as f64).sqrt();
        for x in z.iter_mut() {
            let re: f64 = rng.sample(StandardNormal);
            let im: f64 = rng.sample(StandardNormal);
            *x = C64::new(re, im) * std::f64::consts::FRAC_1_SQRT_2;
        }
        for e in 0..m {
            let (i, j) = (e % g.ny, e / g.ny);
            let mut mean = C64::new(0.0, 0.0);
            let mut samples = Vec::with_capacity(r);
            for q in 0..r {
                // Correlated with the other entries of its column (a shared input
                // experiment) and of its row (a shared sensor).
                let col = z[q * m + j * g.ny];
                let row = z[q * m + i];
                let own = z[q * m + e];
                let x = (own * 0.8 + col * 0.45 + row * 0.4) * s;
                samples.push(x);
                mean += x;
            }
            mean /= r as f64;
            let sv: f64 =
                samples.iter().map(|x| (x - mean).norm_sqr()).sum::<f64>() / (r - 1) as f64;
            values[k * m + e] += mean;
            var[k * m + e] = sv / r as f64;
        }
    }
    Frf::new(f.to_vec(), g.ny, g.nu, values, Some(var)).unwrap()
}

/// The continuous response of `m` at `f`.
pub fn response(m: &ModalModel, f: &[f64]) -> ResponseGrid {
    m.freq_response(&omegas(f)).unwrap()
}

/// Multiplies every line `k` of `g` by `factor(k)`.
pub fn scale_lines(g: &mut ResponseGrid, factor: impl Fn(usize) -> C64) {
    let n = g.len();
    for k in 0..n {
        let fk = factor(k);
        for v in g.line_mut(k) {
            *v *= fk;
        }
    }
}
