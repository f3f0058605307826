//! The delay estimate of the reference wafer-stage FRF (`wafer_nominal.csv`, 4 x 13,
//! band 20..2000 Hz, with its variance): the coarse periodogram scan, the golden-section
//! search and the robust refinement with the default settings, as `frfit fit` runs them
//! before the first fit; and the plain periodogram alone (`robust_power = 0`). Skips
//! (with a message) when the shared data are not there.

use criterion::{criterion_group, criterion_main, Criterion};
use frf_data::delay::{estimate_delay, DelayConfig};
use frf_data::shared_data;
use frf_data::FrfDataset;
use std::hint::black_box;

fn delay(c: &mut Criterion) {
    let Some(band) = shared_data::require_band("bench delay", "wafer_nominal.csv", (20.0, 2000.0))
    else {
        return;
    };
    let mut g = c.benchmark_group("delay");
    g.sample_size(20);
    let n = band.n_lines();
    for (name, cfg) in [
        ("robust", DelayConfig::default()),
        (
            "periodogram",
            DelayConfig {
                robust_power: 0,
                ..DelayConfig::default()
            },
        ),
    ] {
        let est = estimate_delay(&band, &cfg).expect("the delay estimate");
        println!(
            "delay/{name}: {:.3} us on {n} lines x {} entries",
            est.tau_s * 1e6,
            band.n_entries()
        );
        g.bench_function(format!("{name} wafer_nominal 4x13 {n} lines"), |b| {
            b.iter(|| estimate_delay(black_box(&band), &cfg).expect("the delay estimate"))
        });
    }
    g.finish();
}

criterion_group!(benches, delay);
criterion_main!(benches);
