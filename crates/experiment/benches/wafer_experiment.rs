//! The default wafer-stage experiment of the paper (Section 4.2): 13 single-axis
//! closed-loop experiments, 10 periods x 10 realizations of random-phase odd multisines
//! with 4000 lines 0.25..1999.75 Hz at 10 kHz (period 40000 samples), coloured sensor
//! noise generated in the time domain, and the nonparametric MIMO estimate with its
//! variances. Target: under 10 s on 2 cores in release.

use criterion::{criterion_group, criterion_main, Criterion};
use experiment::synth::WaferStageExperiment;
use std::hint::black_box;
use std::time::Duration;

fn wafer_experiment(c: &mut Criterion) {
    // faer's own threading never pays on these small per-line problems
    faer::set_global_parallelism(faer::Par::Seq);
    let mut g = c.benchmark_group("wafer_stage");
    g.sample_size(10);
    g.bench_function(
        "setup (plant, controller, closed-loop poles, loop per line)",
        |b| b.iter(|| WaferStageExperiment::default_with(black_box(1), 10, 10).expect("builds")),
    );
    let w = WaferStageExperiment::default_with(1, 10, 10).expect("builds");
    g.measurement_time(Duration::from_secs(90));
    g.bench_function(
        "default experiment 13 x 10 periods x 10 realizations + estimate",
        |b| b.iter(|| w.run().expect("runs")),
    );
    g.finish();
}

criterion_group!(benches, wafer_experiment);
criterion_main!(benches);
