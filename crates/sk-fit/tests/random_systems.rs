//! SK on random stable MIMO systems with exact answers: noise-free data are recovered
//! to 1e-8 (continuous time in the bilinear basis, and through an exact zero-order hold
//! in the sampled basis), and the error falls with the noise.

use faer::Mat;
use frf_data::{DelayChoice, Estimator, Frf, FrfDataset};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::{FrfModel, Hold, ModalModel, PolePair};
use sk_fit::{BasisChoice, SkConfig, SkError, SkInit, SkIterConfig, SkReport, SkWeight};
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
        *v += frf_data::C64::new(
            rng.random_range(-1.0..1.0) * a,
            rng.random_range(-1.0..1.0) * a,
        );
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

fn sk_with(truth: &FrfModel, d: &Frf, cfg: SkConfig) -> Result<(FrfModel, SkReport), SkError> {
    let cfg = SkConfig {
        hold: truth.factors.hold,
        delay: DelayChoice::None,
        ..cfg
    };
    let f = SkInit::new(cfg).estimate(d, ())?;
    Ok((f.model, f.report))
}

fn sk(truth: &FrfModel, d: &Frf, order: Option<usize>) -> (FrfModel, SkReport) {
    sk_with(
        truth,
        d,
        SkConfig {
            order,
            ..Default::default()
        },
    )
    .unwrap()
}

fn true_order(truth: &FrfModel) -> usize {
    2 * truth.modal.pairs.len() + truth.modal.real_poles.len() + truth.modal.rigid.len()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 10, ..ProptestConfig::default() })]

    /// Noise-free data of a random system are recovered to 1e-8 (median relative error),
    /// with the order given and with the order chosen by the sweep, which finds the true
    /// order and the rigid body.
    #[test]
    fn noise_free_data_are_recovered(seed in 0u64..10_000, hold in any::<bool>()) {
        let truth = system(seed, hold);
        let d = data(&truth, 600, 0.0, seed);
        let n = true_order(&truth);
        let (m, _) = sk(&truth, &d, Some(n));
        let e = error(&m, &truth, &d);
        prop_assert!(e < 1e-8, "seed {seed}, hold {hold}, order {n} given: median error {e:.3e}");
        let (m, r) = sk(&truth, &d, None);
        let e = error(&m, &truth, &d);
        prop_assert!(e < 1e-8, "seed {seed}, hold {hold}, sweep (order {}): median error {e:.3e}", r.order);
        prop_assert_eq!(r.order, n, "seed {}: sweep {:?}", seed, r.sweep);
        prop_assert_eq!(r.integrators, truth.modal.rigid.len());
    }
}

/// Jue's `1/sqrt|d|` weight reaches the same noise-free fit.
#[test]
fn sqrt_weight_recovers_noise_free_data() {
    for (seed, hold) in [(7u64, false), (8, true)] {
        let truth = system(seed, hold);
        let d = data(&truth, 600, 0.0, seed);
        let cfg = SkConfig {
            order: Some(true_order(&truth)),
            iter: SkIterConfig {
                weight: SkWeight::Sqrt,
                ..Default::default()
            },
            ..Default::default()
        };
        let (m, _) = sk_with(&truth, &d, cfg).unwrap();
        let e = error(&m, &truth, &d);
        assert!(e < 1e-8, "seed {seed}: {e:.3e}");
    }
}

/// With noise the error against the truth falls with the noise: 10x less noise lowers
/// the median error at least 5x (median over three noise realisations).
#[test]
fn error_falls_with_the_noise() {
    for seed in [3u64, 17, 29] {
        let truth = system(seed, seed % 2 == 0);
        let run = |noise: f64| -> f64 {
            let mut errs: Vec<f64> = (0..3)
                .map(|r| {
                    let d = data(&truth, 600, noise, seed * 100 + r);
                    let (m, _) = sk(&truth, &d, None);
                    error(&m, &truth, &d)
                })
                .collect();
            errs.sort_by(|a, b| a.total_cmp(b));
            errs[1]
        };
        let (e3, e4) = (run(1e-3), run(1e-4));
        println!("seed {seed}: noise 1e-3 -> {e3:.3e}, 1e-4 -> {e4:.3e}");
        assert!(
            e3 / e4 >= 5.0,
            "seed {seed}: noise 1e-3 -> {e3:.3e}, 1e-4 -> {e4:.3e}"
        );
        assert!(e3 < 1e-3, "seed {seed}: {e3:.3e} at noise 1e-3");
    }
}

/// Bad input gets a clear error: an order the lines cannot support, a basis that is
/// numerically singular at the order, a sampled basis without a sample rate.
#[test]
fn bad_input_is_reported() {
    let truth = system(5, false);
    let d = data(&truth, 20, 0.0, 5);
    let e = sk_with(
        &truth,
        &d,
        SkConfig {
            order: Some(30),
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            SkError::OrderExceedsData {
                order: 30,
                lines: 20,
                max: 18
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string().contains("larger than the data support"),
        "{e}"
    );

    let d = data(&truth, 600, 0.0, 5);
    let e = sk_with(
        &truth,
        &d,
        SkConfig {
            order: Some(40),
            basis: BasisChoice::ScaledMonomial,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, SkError::SingularBasis { order: 40, .. }), "{e}");
    assert!(e.to_string().contains("numerically singular"), "{e}");

    let e = sk_with(
        &truth,
        &d,
        SkConfig {
            order: Some(6),
            basis: BasisChoice::Sampled,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("sampled basis needs a hold"), "{e}");
}
