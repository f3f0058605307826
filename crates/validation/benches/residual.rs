//! The residual analysis at the scale of the wafer stage: 4000 lines x 4 x 13 entries
//! (a synthetic lightly damped stage: a rigid body and 17 modes, seeded), in three
//! situations: a residual at the noise level (the loop's stopping point), a missed mode
//! (localized: the residual CMIF and the mode template run) and an uncompensated delay
//! (broadband, with localized excess at every resonance of the model). Also the noise
//! estimate from data without variance.

use criterion::{criterion_group, criterion_main, Criterion};
use faer::Mat;
use frf_data::{Frf, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use realize::{ModalModel, PolePair, ResponseGrid};
use std::f64::consts::TAU;
use std::hint::black_box;
use validation::{analyze_residual, estimate_noise, noise_level, NoiseConfig, ResidualConfig};

const NY: usize = 4;
const NU: usize = 13;

fn stage(rng: &mut ChaCha8Rng) -> ModalModel {
    let mut g = |n: usize| -> Vec<f64> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    let mut m = ModalModel::new(NY, NU);
    let (a, b) = (g(NY), g(NU));
    m.rigid = vec![Mat::zeros(NY, NU), Mat::from_fn(NY, NU, |i, j| a[i] * b[j])];
    for i in 0..17 {
        let f = 120.0 * (1900.0f64 / 120.0).powf(i as f64 / 16.0);
        let (c, b) = (g(NY), g(NU));
        let num = Mat::from_fn(NY, NU, |p, q| c[p] * b[q]);
        m.pairs.push(PolePair::from_second_order(f, 0.01, &num));
    }
    m
}

fn noisy(f: &[f64], g: &ResponseGrid, rng: &mut ChaCha8Rng) -> Frf {
    let m = NY * NU;
    let mut values = g.values.clone();
    let mut var = vec![0.0; values.len()];
    for (k, fk) in f.iter().enumerate() {
        let w = TAU * fk;
        let s = 1e-3 / (w * w) + 1e-10;
        for e in 0..m {
            let re: f64 = rng.sample(StandardNormal);
            let im: f64 = rng.sample(StandardNormal);
            values[k * m + e] += C64::new(re, im) * (s / std::f64::consts::SQRT_2);
            var[k * m + e] = s * s;
        }
    }
    Frf::new(f.to_vec(), NY, NU, values, Some(var)).expect("valid")
}

fn residual(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let f: Vec<f64> = (0..4000).map(|k| 0.25 + 0.5 * k as f64).collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let model = stage(&mut rng);
    let p = model.freq_response(&w).expect("response");
    let cfg = ResidualConfig {
        sample_rate_hz: Some(1e4),
        ..Default::default()
    };

    let at_noise = noisy(&f, &p, &mut rng);
    let mut with_mode = model.clone();
    let num = Mat::from_fn(NY, NU, |i, j| {
        0.5 * (i as f64 - 1.5) * (j as f64 - 6.0) / 6.0
    });
    with_mode
        .pairs
        .push(PolePair::from_second_order(520.0, 0.008, &num));
    let missed = noisy(
        &f,
        &with_mode.freq_response(&w).expect("response"),
        &mut rng,
    );
    let mut delayed = p.clone();
    for (k, wk) in w.iter().enumerate() {
        let ph = C64::from_polar(1.0, -wk * 20e-6);
        for v in delayed.line_mut(k) {
            *v *= ph;
        }
    }
    let delay = noisy(&f, &delayed, &mut rng);

    let mut g = c.benchmark_group("analyze_residual 4000 lines x 4x13");
    g.sample_size(20);
    for (name, data) in [
        ("at the noise level", &at_noise),
        ("missed mode", &missed),
        ("delay", &delay),
    ] {
        let noise = noise_level(data).expect("measured");
        let a = analyze_residual(data, &p, &noise, &cfg).expect("analysis");
        println!(
            "{name}: significant {}, flagged {:?}",
            a.significant,
            a.evidence
                .iter()
                .filter(|e| e.significant)
                .map(|e| e.effect)
                .collect::<Vec<_>>()
        );
        g.bench_function(name, |b| {
            b.iter(|| analyze_residual(black_box(data), &p, &noise, &cfg).expect("analysis"))
        });
    }
    g.finish();

    let bare = at_noise.clone().with_variance(None).expect("valid");
    let mut g = c.benchmark_group("noise estimate 4000 lines x 4x13");
    g.sample_size(20);
    g.bench_function("estimate_noise (order 4, +-40 lines)", |b| {
        b.iter(|| estimate_noise(black_box(&bare), &NoiseConfig::default()).expect("estimate"))
    });
    g.finish();
}

criterion_group!(benches, residual);
criterion_main!(benches);
