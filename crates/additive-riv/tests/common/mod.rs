//! Random additive systems with exact answers, shared by the integration tests.

#![allow(dead_code)]

use additive_riv::{AdditiveModel, Domain};
use frf_data::{Frf, ModelStructure, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::TAU;

/// A random system: its true model and the frequencies (Hz) it is sampled at.
pub struct Case {
    pub truth: AdditiveModel,
    pub freqs: Vec<f64>,
    pub mode_f: Vec<f64>,
    pub mode_zeta: Vec<f64>,
    pub rigid: bool,
}

/// A random stable additive system: `n_modes` well separated modes between 20 and
/// 400 Hz, optional rigid body, random real numerators of magnitude ~1/w^2.
pub fn random_case(
    seed: u64,
    ny: usize,
    nu: usize,
    n_modes: usize,
    rigid: bool,
    domain: Domain,
) -> Case {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut m = AdditiveModel::new(ny, nu, domain).unwrap();
    let (lo, hi) = (5.0, 500.0);
    if rigid {
        m.push_rigid_body(2, AdditiveModel::rigid_scale(lo, hi))
            .unwrap();
    }
    // modes spread on a log grid with jitter, at least 8% apart
    let mut fs: Vec<f64> = Vec::new();
    while fs.len() < n_modes {
        let f = 20.0 * (20.0f64).powf(rng.random::<f64>());
        if fs.iter().all(|g| (f / g - 1.0).abs() > 0.08) {
            fs.push(f);
        }
    }
    fs.sort_by(|a, b| a.total_cmp(b));
    let mut zs = Vec::new();
    for &f in &fs {
        let z = 0.005 + 0.03 * rng.random::<f64>();
        zs.push(z);
        m.push_mode(f, z, false).unwrap();
    }
    for sub in &mut m.submodels {
        for b in &mut sub.num {
            for j in 0..nu {
                for i in 0..ny {
                    let mut v: f64 = rng.random::<f64>() * 2.0 - 1.0;
                    if v.abs() < 0.2 {
                        v += 0.4f64.copysign(v);
                    }
                    b[(i, j)] = v;
                }
            }
        }
    }
    let freqs: Vec<f64> = (1..=600)
        .map(|k| lo + (hi - lo) * k as f64 / 600.0)
        .collect();
    Case {
        truth: m,
        freqs,
        mode_f: fs,
        mode_zeta: zs,
        rigid,
    }
}

/// The exact response of `model` at `freqs` (Hz) as an `Frf`, with complex Gaussian
/// noise of relative standard deviation `rel_noise` (per entry, relative to the entry's
/// RMS), and the true noise variance attached when `rel_noise > 0`.
pub fn simulate(model: &AdditiveModel, freqs: &[f64], rel_noise: f64, seed: u64) -> Frf {
    let w: Vec<f64> = freqs.iter().map(|f| TAU * f).collect();
    let g = model.response_at(&w);
    let m = g.ny * g.nu;
    let n = freqs.len();
    let mut rms = vec![0.0; m];
    for k in 0..n {
        for e in 0..m {
            rms[e] += g.values[k * m + e].norm_sqr() / n as f64;
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let mut vals = g.values.clone();
    let mut var = Vec::with_capacity(n * m);
    for k in 0..n {
        for e in 0..m {
            let s2 = (rel_noise * rel_noise) * rms[e];
            let sd = (s2 / 2.0).sqrt();
            let (a, b) = gauss_pair(&mut rng);
            vals[k * m + e] += C64::new(a * sd, b * sd);
            var.push(s2);
        }
    }
    Frf::new(
        freqs.to_vec(),
        g.ny,
        g.nu,
        vals,
        (rel_noise > 0.0).then_some(var),
    )
    .unwrap()
}

fn gauss_pair(rng: &mut ChaCha8Rng) -> (f64, f64) {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random::<f64>();
    let r = (-2.0 * u1.ln()).sqrt();
    (r * (TAU * u2).cos(), r * (TAU * u2).sin())
}

/// The same structure as `case.truth` with every mode frequency multiplied by
/// `1 + shift_k` (`|shift_k| <= max_shift`), damping 0.01, zero numerators.
pub fn perturbed_start(case: &Case, max_shift: f64, seed: u64) -> AdditiveModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xabc);
    let mut m = AdditiveModel::new(case.truth.ny(), case.truth.nu(), case.truth.domain()).unwrap();
    if case.rigid {
        m.push_rigid_body(2, case.truth.submodels[0].scale).unwrap();
    }
    for &f in &case.mode_f {
        let s = (rng.random::<f64>() * 2.0 - 1.0) * max_shift;
        m.push_mode(f * (1.0 + s), 0.01, false).unwrap();
    }
    m
}

/// Largest relative parameter error, per submodel relative to that submodel's norm.
pub fn max_rel_param_error(a: &AdditiveModel, b: &AdditiveModel) -> f64 {
    let mut worst: f64 = 0.0;
    for i in 0..a.submodels.len() {
        let pa = a.submodel_params(i);
        let pb = b.submodel_params(i);
        let sd = a.submodels[i].den.len();
        // denominators and numerators separately (different units)
        let rel = |x: &[f64], y: &[f64]| -> f64 {
            let d: f64 = x
                .iter()
                .zip(y)
                .map(|(u, v)| (u - v).powi(2))
                .sum::<f64>()
                .sqrt();
            let s: f64 = y.iter().map(|v| v * v).sum::<f64>().sqrt();
            d / s.max(1e-300)
        };
        if sd > 0 {
            worst = worst.max(rel(&pa[..sd], &pb[..sd]));
        }
        worst = worst.max(rel(&pa[sd..], &pb[sd..]));
    }
    worst
}
