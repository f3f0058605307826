//! The CMIF of the reference wafer-stage FRF (`wafer_nominal.csv`, 4 x 13, band
//! 20..2000 Hz): the singular value decompositions of every line with each
//! [`SvdMethod`], and the peak picker on the result. Skips (with a message) when the
//! shared data are not there.

use criterion::{criterion_group, criterion_main, Criterion};
use frf_data::cmif::{cmif_with, pick_peaks, PeakConfig, SvdMethod};
use frf_data::shared_data;
use frf_data::FrfDataset;
use std::hint::black_box;

fn cmif(c: &mut Criterion) {
    faer::set_global_parallelism(faer::Par::Seq);
    let Some(band) = shared_data::require_band("bench cmif", "wafer_nominal.csv", (20.0, 2000.0))
    else {
        return;
    };
    let mut g = c.benchmark_group("cmif");
    g.sample_size(20);
    for (name, method) in [("jacobi", SvdMethod::Jacobi), ("faer", SvdMethod::Faer)] {
        g.bench_function(
            format!("svd {name} wafer_nominal 4x13 {} lines", band.n_lines()),
            |b| b.iter(|| cmif_with(black_box(&band), method).expect("cmif")),
        );
    }
    let cm = cmif_with(&band, SvdMethod::Auto).expect("cmif");
    g.bench_function("pick_peaks wafer_nominal", |b| {
        b.iter(|| pick_peaks(black_box(&cm), &PeakConfig::default()))
    });
    g.finish();
}

criterion_group!(benches, cmif);
criterion_main!(benches);
