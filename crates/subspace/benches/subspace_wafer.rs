//! Cost of the subspace fit on the reference wafer stage (`../shared/data/wafer_nominal.csv`,
//! 4 x 13, 3961 lines in 20..2000 Hz, exact 10 kHz hold and one sample of delay
//! declared), single thread:
//!
//! - `projection`: the structured running QR of the data matrix and the SVD
//!   ([`subspace::projection::project`]) with the default 31 block rows;
//! - `identify`: the whole fit (projection, order, A/C, B/D (17), poles and residues);
//! - `identify_delay_refined`: the whole fit as `frfit fit --init subspace` runs it
//!   without `--delay`: the delay estimated (the chain's estimate handed over, as the
//!   pipeline does), refined with the subspace poles fixed, the subspace step repeated
//!   with the refined delay (see `subspace::delay_refine`).
//!
//! Prints a message and measures nothing when the shared data are absent.

use criterion::{criterion_group, criterion_main, Criterion};
use frf_data::delay::{estimate_delay, DelayConfig};
use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::{DelayChoice, Precomputed, Weighting};
use realize::{Hold, KnownFactors};
use std::hint::black_box;
use std::time::Duration;
use subspace::prepare::prepare;
use subspace::projection::project;
use subspace::{SubspaceConfig, SubspaceInit};

fn bench(c: &mut Criterion) {
    faer::set_global_parallelism(faer::Par::Seq);
    let Some(path) = require("subspace_wafer bench", "wafer_nominal.csv") else {
        return;
    };
    let data = read_frf_csv(&path).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let cfg = SubspaceConfig {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Fixed { seconds: 100e-6 },
        ..Default::default()
    };
    let factors = KnownFactors {
        hold: cfg.hold,
        delay_s: 100e-6,
        ..Default::default()
    };
    let prepared = prepare(&band, &factors, &Weighting::Auto).unwrap();
    let mut g = c.benchmark_group("subspace_wafer");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    g.bench_function("projection", |b| {
        b.iter(|| black_box(project(&prepared, 31).unwrap().singular_values[0]))
    });
    let init = SubspaceInit::new(cfg);
    g.bench_function("identify", |b| {
        b.iter(|| black_box(init.identify(&band).unwrap().report.order))
    });
    let auto = SubspaceInit::new(SubspaceConfig {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Auto,
        precomputed: Precomputed {
            delay: Some(estimate_delay(&band, &DelayConfig::default()).unwrap()),
            cmif: None,
        },
        ..Default::default()
    });
    g.bench_function("identify_delay_refined", |b| {
        b.iter(|| black_box(auto.identify(&band).unwrap().model.factors.delay_s))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
