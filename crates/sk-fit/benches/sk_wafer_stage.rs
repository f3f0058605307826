//! The SK initialiser on the reference wafer-stage FRF (`wafer_nominal.csv`, 4 outputs x
//! 13 inputs), band 20..2000 Hz, with the declared 10 kHz zero-order hold: the SK step of
//! `frfit fit DATA --band 20:2000 --init sk --refine none` (delay estimated, order chosen
//! by the F-test sweep, inverse-variance weighting from the `_var` columns).
//!
//! The data are loaded and cut to the band once; the delay estimate and the CMIF are
//! computed once outside the timed loop and handed over as the CLI does
//! ([`frf_data::Precomputed`]), so what is timed is the SK step itself (order sweep, SK
//! iterations, residues).
//!
//! When the reference data are not there (a fresh clone has no `../shared`), the bench
//! prints why and registers nothing.

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use frf_data::cmif::cmif;
use frf_data::delay::{estimate_delay, DelayConfig};
use frf_data::{shared_data, Estimator, Frf, FrfDataset, Precomputed};
use realize::Hold;
use sk_fit::{SkConfig, SkInit};
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

const FILE: &str = "wafer_nominal.csv";
const BAND_HZ: (f64, f64) = (20.0, 2000.0);
const FS_HZ: f64 = 10_000.0;
const SAMPLES: usize = 10;

/// The band of the reference data, or `None` (with a message) when it is unavailable.
fn load_band() -> Option<Frf> {
    shared_data::require_band("sk_wafer_stage", FILE, BAND_HZ)
}

fn bench_wafer(c: &mut Criterion) {
    let Some(band) = load_band() else {
        return;
    };
    faer::set_global_parallelism(faer::Par::Seq);
    let precomputed = match (estimate_delay(&band, &DelayConfig::default()), cmif(&band)) {
        (Ok(d), Ok(c)) => Precomputed {
            delay: Some(d),
            cmif: Some(Arc::new(c)),
        },
        (Err(e), _) => {
            println!("sk_wafer_stage skipped: delay estimate failed: {e}");
            return;
        }
        (_, Err(e)) => {
            println!("sk_wafer_stage skipped: CMIF failed: {e}");
            return;
        }
    };
    let init = SkInit::new(SkConfig {
        hold: Hold::Zoh { fs_hz: FS_HZ },
        precomputed,
        ..Default::default()
    });
    // one untimed run: says what is being timed, and sizes the measurement
    let t = Instant::now();
    let fit = match init.estimate(&band, ()) {
        Ok(f) => f,
        Err(e) => {
            println!("sk_wafer_stage skipped: the fit failed: {e}");
            return;
        }
    };
    let once = t.elapsed();
    println!(
        "sk_wafer_stage: {} lines, {}x{} entries; one fit {:.2} s: order {} ({} pairs, {} \
         integrators), {} iterations ({}), sweep {:?}",
        band.n_lines(),
        band.ny(),
        band.nu(),
        once.as_secs_f64(),
        fit.report.order,
        fit.report.pairs,
        fit.report.integrators,
        fit.iterations,
        fit.convergence.describe(),
        fit.report.sweep.iter().map(|s| s.order).collect::<Vec<_>>()
    );
    let mut group = c.benchmark_group("sk_wafer_stage");
    group.sample_size(SAMPLES);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(
        once.mul_f64(SAMPLES as f64 * 1.3)
            .max(Duration::from_secs(2)),
    );
    group.bench_function("cli_sk", |b| {
        b.iter(|| black_box(init.estimate(black_box(&band), ())).is_ok())
    });
    group.finish();
}

criterion_group!(benches, bench_wafer);
criterion_main!(benches);
