//! What `frfit validate` computes on the reference wafer stage (4 outputs x 13 inputs,
//! 3960 lines in 20..2000 Hz): the minimum additive uncertainty per line of a model
//! against a validation measurement with its variance (`validate_frf`, Oomen-Bosgra).
//!
//! The "model" is the noiseless response of the reference plant
//! (`wafer_nominal.noiseless.csv`) and the validation data are the measurement
//! `wafer_nominal.csv` with its variance: the cost of the validation depends on the
//! sizes only, not on how the model was made. Timed:
//!
//! - `closed_form`: every line, the default method (the target: under 5 s);
//! - `mu_40_lines`: the mu bisection (Proposition 12) on 40 lines spread over the band;
//!   the whole band costs about `nl / 40` times this.
//!
//! Loading the files is outside the timed loop. When the reference data are not there
//! (a fresh clone has no `../shared`), the bench prints why and registers nothing.

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use frf_data::{shared_data, Frf, FrfDataset};
use realize::ResponseGrid;
use std::hint::black_box;
use std::time::Duration;
use validation::{validate_frf, FrfValidationConfig, GammaMethod};

const BAND_HZ: (f64, f64) = (20.0, 2000.0);
const MU_LINES: usize = 40;

/// Reads one reference file cut to the band, or says why not.
fn load(name: &str) -> Option<Frf> {
    shared_data::require_band("validate_wafer_stage", name, BAND_HZ)
}

/// The lines `idx` of `frf` (values and variance) as a new FRF.
fn subset(frf: &Frf, idx: &[usize]) -> Frf {
    let m = frf.ny() * frf.nu();
    let f: Vec<f64> = idx.iter().map(|&k| frf.freq_hz(k)).collect();
    let vals = idx
        .iter()
        .flat_map(|&k| frf.line(k).iter().copied())
        .collect();
    let var = frf.variances().map(|v| {
        idx.iter()
            .flat_map(|&k| v[k * m..(k + 1) * m].iter().copied())
            .collect()
    });
    Frf::new(f, frf.ny(), frf.nu(), vals, None)
        .and_then(|x| x.with_variance(var))
        .expect("a subset of a valid FRF is valid")
}

fn bench_validate(c: &mut Criterion) {
    let (Some(data), Some(truth)) = (
        load("wafer_nominal.csv"),
        load("wafer_nominal.noiseless.csv"),
    ) else {
        return;
    };
    if data.freq_hz_slice() != truth.freq_hz_slice() || !data.has_variance() {
        println!(
            "validate_wafer_stage skipped: the measurement and the noiseless response have \
             different lines, or the measurement has no variance"
        );
        return;
    }
    let grid = ResponseGrid {
        ny: truth.ny(),
        nu: truth.nu(),
        values: truth.values().to_vec(),
    };
    let nl = data.n_lines();
    println!(
        "validate_wafer_stage: {nl} lines, {}x{} entries; mu on {MU_LINES} lines",
        data.ny(),
        data.nu()
    );
    let idx: Vec<usize> = (0..MU_LINES)
        .map(|i| i * (nl - 1) / (MU_LINES - 1))
        .collect();
    let data_mu = subset(&data, &idx);
    let grid_mu = ResponseGrid {
        ny: grid.ny,
        nu: grid.nu,
        values: idx
            .iter()
            .flat_map(|&k| grid.line(k).iter().copied())
            .collect(),
    };
    let closed = FrfValidationConfig::default();
    let mu = FrfValidationConfig {
        method: GammaMethod::Mu,
        ..FrfValidationConfig::default()
    };
    let mut group = c.benchmark_group("validate_wafer_stage");
    group.sample_size(10);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(10));
    group.bench_function("closed_form", |b| {
        b.iter(|| black_box(validate_frf(&grid, &data, None, &closed).expect("validation")))
    });
    group.bench_function("mu_40_lines", |b| {
        b.iter(|| black_box(validate_frf(&grid_mu, &data_mu, None, &mu).expect("validation")))
    });
    group.finish();
}

criterion_group!(benches, bench_validate);
criterion_main!(benches);
