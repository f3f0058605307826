//! The maximum-likelihood refinement (`--refine ml`) of the reference wafer-stage FRF
//! (`wafer_nominal.csv`, 4 outputs x 13 inputs, 3960 lines in 20..2000 Hz) from the CMIF
//! initialisation, with the exact 10 kHz zero-order hold and the fitted delay: the
//! refinement `frfit fit DATA --band 20:2000 --init cmif --refine ml` runs.
//!
//! The data are loaded and cut to the band, and the CMIF start is computed, once outside
//! the timed loop; `ml_refine` times [`MlRefine`] from that start (Levenberg-Marquardt
//! on the variable-projection problem, the mode the start missed added, the covariance
//! and the standard deviations at the optimum). Before timing, one run prints the work
//! done (iterations, evaluations, Jacobians) and the time per stage.
//!
//! When the reference data are not there (a fresh clone has no `../shared`), the bench
//! prints why and registers nothing.

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use frf_data::{shared_data, ChainModel, ChainSettings, DelayChoice, Estimator, Frf};
use frfit::chain::{run_chain, AdditiveOptions};
use ml_refine::{MlConfig, MlRefine};
use realize::Hold;
use std::hint::black_box;
use std::time::{Duration, Instant};

const FILE: &str = "wafer_nominal.csv";
const BAND_HZ: (f64, f64) = (20.0, 2000.0);
/// The file's comments declare 10 realizations (as `frfit fit` reads them).
const REALIZATIONS: usize = 10;

/// The band of the reference data, or `None` (with a message) when it is unavailable.
fn load_band() -> Option<Frf> {
    shared_data::require_band("ml_wafer_stage", FILE, BAND_HZ)
}

fn bench(c: &mut Criterion) {
    let Some(band) = load_band() else {
        return;
    };
    let settings = ChainSettings {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Auto,
        ..Default::default()
    };
    let opts = AdditiveOptions {
        realizations: Some(REALIZATIONS),
        ..Default::default()
    };
    let start: ChainModel = match run_chain(&band, "cmif", "none", &settings, &opts) {
        Ok(r) => r.model,
        Err(e) => {
            println!("ml_wafer_stage skipped: the CMIF start failed: {e}");
            return;
        }
    };
    let ml = MlRefine::new(MlConfig {
        weighting: settings.weighting.clone(),
        realizations: Some(REALIZATIONS),
        ..Default::default()
    });
    let t = Instant::now();
    match ml.estimate(&band, start.clone()) {
        Ok(fit) => println!(
            "ml_wafer_stage: one run {:.2} s: {} modes, {} iterations, {} evaluations, {} \
             Jacobians, cost ratio {:.4}; stages {:?}",
            t.elapsed().as_secs_f64(),
            fit.report.modes.len(),
            fit.report.iterations,
            fit.report.evaluations,
            fit.report.jacobians,
            fit.report.cost_ratio,
            fit.timings
                .iter()
                .map(|s| format!("{} {:.2} s", s.stage, s.seconds))
                .collect::<Vec<_>>()
        ),
        Err(e) => {
            println!("ml_wafer_stage skipped: the refinement failed: {e}");
            return;
        }
    }
    let mut g = c.benchmark_group("ml_wafer_stage");
    g.sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_millis(1))
        .measurement_time(Duration::from_secs(20));
    g.bench_function("ml_refine", |b| {
        b.iter(|| black_box(ml.estimate(&band, start.clone()).map(|f| f.report.cost)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
