//! Random stable systems and their (noisy) frequency responses for the tests.
#![allow(dead_code)]

use faer::Mat;
use frf_data::{Frf, FrfDataset};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use realize::{FrfModel, Hold, ModalModel, PolePair};
use std::f64::consts::TAU;

/// A random stable `ny x nu` system with `n_modes` well-separated modes (constant
/// numerators, eq. (26) of the wafer-stage paper) in 40..700 Hz, optionally a free
/// rigid body, an exact 4 kHz zero-order hold and a delay.
pub fn system(
    seed: u64,
    ny: usize,
    nu: usize,
    n_modes: usize,
    rigid: bool,
    hold: bool,
) -> FrfModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut m = ModalModel::new(ny, nu);
    if rigid {
        let c: Vec<f64> = (0..ny).map(|_| rng.random_range(0.5..1.5)).collect();
        let b: Vec<f64> = (0..nu).map(|_| rng.random_range(0.5..1.5)).collect();
        m.rigid = vec![Mat::zeros(ny, nu), Mat::from_fn(ny, nu, |i, j| c[i] * b[j])];
    }
    let mut f = 40.0 * rng.random_range(1.0..1.3);
    for _ in 0..n_modes {
        let zeta = rng.random_range(0.005..0.04);
        let c: Vec<f64> = (0..ny).map(|_| rng.random_range(-1.0..1.0)).collect();
        let b: Vec<f64> = (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect();
        let num = Mat::from_fn(ny, nu, |i, j| (c[i] * b[j] + 0.05) * (TAU * f).powi(2));
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
        f *= rng.random_range(1.4..1.8);
    }
    let mut fm = FrfModel::new(m);
    if hold {
        fm.factors.hold = Hold::Zoh { fs_hz: 4000.0 };
    }
    fm
}

/// The response of `truth` on `lines` uniform lines in 10..1000 Hz, with circular
/// complex Gaussian noise of variance `(noise |G|)^2` (stored as the variance) when
/// `noise > 0`.
pub fn data(truth: &FrfModel, lines: usize, noise: f64, seed: u64) -> Frf {
    let f: Vec<f64> = (0..lines)
        .map(|k| 10.0 + 990.0 * k as f64 / (lines - 1) as f64)
        .collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let g = truth.freq_response(&w).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_1234);
    let mut vals = g.values.clone();
    let mut var = Vec::with_capacity(vals.len());
    for v in vals.iter_mut() {
        let s = noise * v.norm();
        let (a, b): (f64, f64) = (
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
        );
        *v += frf_data::C64::new(a, b) * (s / 2f64.sqrt());
        var.push(s * s);
    }
    let frf = Frf::new(f, truth.ny(), truth.nu(), vals, None).unwrap();
    if noise > 0.0 {
        frf.with_variance(Some(var)).unwrap()
    } else {
        frf
    }
}

/// The response of `truth` on `lines` uniform lines in 10..1000 Hz with circular complex
/// Gaussian noise of one standard deviation for every entry and line, `noise` times the
/// median magnitude (a measurement's noise floor, not a fraction of each value), stated
/// as the variance.
pub fn data_floor(truth: &FrfModel, lines: usize, noise: f64, seed: u64) -> Frf {
    let clean = data(truth, lines, 0.0, seed);
    let mut mags: Vec<f64> = clean.values_vec().iter().map(|v| v.norm()).collect();
    mags.sort_by(f64::total_cmp);
    let s = noise * mags[mags.len() / 2];
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xf100_4000);
    let vals: Vec<_> = clean
        .values_vec()
        .iter()
        .map(|v| {
            let (a, b): (f64, f64) = (
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            );
            v + frf_data::C64::new(a, b) * (s / 2f64.sqrt())
        })
        .collect();
    let n = vals.len();
    Frf::new(
        clean.freq_hz_slice().to_vec(),
        truth.ny(),
        truth.nu(),
        vals,
        None,
    )
    .unwrap()
    .with_variance(Some(vec![s * s; n]))
    .unwrap()
}

/// `truth` with its poles moved (frequencies by up to `df` relative, damping by up to
/// `dz` relative) and its residues halved: a start for a refiner.
pub fn perturbed(truth: &FrfModel, df: f64, dz: f64, seed: u64) -> FrfModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xabcd);
    let mut s = truth.clone();
    for p in &mut s.modal.pairs {
        let f = p.f_hz() * (1.0 + rng.random_range(-df..df));
        let z = p.zeta() * (1.0 + rng.random_range(-dz..dz));
        let res = Mat::from_fn(truth.ny(), truth.nu(), |i, j| p.residue[(i, j)] * 0.5);
        *p = PolePair::from_f_zeta(f, z, res);
    }
    s
}

/// Median relative error of `model` against `truth` on the lines of `d`.
pub fn error(model: &FrfModel, truth: &FrfModel, d: &Frf) -> f64 {
    let w = d.omegas();
    let g = truth.freq_response(&w).unwrap();
    model.relative_error(&w, &g).unwrap().0
}
