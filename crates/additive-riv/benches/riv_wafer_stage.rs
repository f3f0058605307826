//! The whole additive-RIV fit of the reference wafer-stage FRF (`wafer_nominal.csv`,
//! 4 outputs x 13 inputs), band 20..2000 Hz, with the exact 10 kHz zero-order hold
//! modelled: what `frfit fit DATA --band 20:2000 --hold zoh:10000` runs.
//!
//! Two configurations are timed on the same data (loaded and cut to the band once,
//! outside the timed loop):
//!
//! - `cli_fit`: the fitter exactly as the CLI configures it (delay estimated and refined,
//!   CMIF peaks, rigid body chosen automatically, Algorithm 1 to convergence, then the
//!   adaptation rounds that add and drop modes);
//! - `init_riv`: the same without the adaptation (`adapt: None`): CMIF initialisation
//!   followed by Algorithm 1 to convergence once.
//!
//! When the reference data are not there (a fresh clone has no `../shared`), the bench
//! prints why and registers nothing.

use additive_riv::riv::RivConfig;
use additive_riv::structure::AdaptConfig;
use additive_riv::{AdditiveFitter, DelayChoice, FitterConfig, Hold, IvMethod, ModeSelection};
use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use frf_data::{shared_data, Frf, FrfDataset, Weighting};
use std::hint::black_box;
use std::time::{Duration, Instant};

const FILE: &str = "wafer_nominal.csv";
const BAND_HZ: (f64, f64) = (20.0, 2000.0);
const FS_HZ: f64 = 10_000.0;
const SAMPLES: usize = 10;

/// The band of the reference data, or `None` (with a message) when it is unavailable.
fn load_band() -> Option<Frf> {
    shared_data::require_band("riv_wafer_stage", FILE, BAND_HZ)
}

/// The fitter settings of `frfit fit DATA --band 20:2000 --hold zoh:10000` (see
/// `frfit::run::run`: no diagnosis, so the delay is estimated and refined and the
/// adaptation may add up to 6 modes per round); `adapt = false` leaves the adaptation out.
fn cli_config(adapt: bool) -> FitterConfig {
    FitterConfig {
        modes: ModeSelection::Auto,
        hold: Hold::Zoh { fs_hz: FS_HZ },
        delay: DelayChoice::Auto,
        derivative_order: 0,
        riv: RivConfig {
            method: IvMethod::Riv,
            weighting: Weighting::Auto,
            ..Default::default()
        },
        adapt: adapt.then(|| AdaptConfig {
            min_f: 25.0,
            alpha: 1e-3,
            max_new_per_round: 6,
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn bench_wafer(c: &mut Criterion) {
    let Some(band) = load_band() else {
        return;
    };
    println!(
        "riv_wafer_stage: {} lines, {}x{} entries, {:.0}..{:.0} Hz",
        band.freq_hz_slice().len(),
        band.ny(),
        band.nu(),
        band.freq_hz_slice()[0],
        band.freq_hz_slice()[band.freq_hz_slice().len() - 1]
    );
    let mut group = c.benchmark_group("riv_wafer_stage");
    group.sample_size(SAMPLES);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_millis(500));
    for (name, adapt) in [("cli_fit", true), ("init_riv", false)] {
        let fitter = AdditiveFitter::new(cli_config(adapt));
        // one untimed run: says what is being timed, and sizes the measurement so that
        // the samples fit in it without criterion's "unable to complete" warning
        let t = Instant::now();
        let (fit, report) = match fitter.fit(&band) {
            Ok(r) => r,
            Err(e) => {
                println!("riv_wafer_stage/{name} skipped: the fit failed: {e}");
                continue;
            }
        };
        let once = t.elapsed();
        println!(
            "riv_wafer_stage/{name}: one fit {:.2} s; {} modes, {} integrator(s), {} \
             iterations ({}), cost {:.4e}, weighting {}",
            once.as_secs_f64(),
            fit.model.modes().len(),
            report.integrators,
            fit.iterations,
            fit.convergence.describe(),
            fit.final_cost().unwrap_or(f64::NAN),
            report.weighting
        );
        let stages: Vec<String> = fit
            .timings
            .iter()
            .map(|t| format!("{} {:.3} s", t.stage, t.seconds))
            .collect();
        println!("riv_wafer_stage/{name}: stages: {}", stages.join(", "));
        group.measurement_time(
            once.mul_f64(SAMPLES as f64 * 1.3)
                .max(Duration::from_secs(2)),
        );
        group.bench_function(name, |b| {
            b.iter(|| black_box(fitter.fit(black_box(&band))).is_ok())
        });
    }
    group.finish();
}

criterion_group!(benches, bench_wafer);
criterion_main!(benches);
