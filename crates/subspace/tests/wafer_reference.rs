//! The subspace fit on the reference wafer stage (`../shared/data`, 4 x 13, 17 modes,
//! exact 10 kHz zero-order hold and one sample of computation delay). Skipped, with a
//! message, when the shared data directory is not beside the checkout; the random
//! systems of `recovery.rs` cover the same properties without files.

use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::truth::Truth;
use frf_data::{DelayChoice, FrfDataset};
use realize::{FrfModel, Hold, ResponseGrid};
use subspace::{SubspaceConfig, SubspaceInit};

/// The declared known factor of the reference files: the exact hold at 10 kHz and one
/// sample (100 us) of computation delay beyond it.
fn declared() -> SubspaceConfig {
    SubspaceConfig {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Fixed { seconds: 100e-6 },
        ..Default::default()
    }
}

fn grid(d: &dyn FrfDataset) -> ResponseGrid {
    let mut g = ResponseGrid::zeros(d.n_lines(), d.ny(), d.nu());
    for k in 0..d.n_lines() {
        d.line_into(k, g.line_mut(k));
    }
    g
}

/// `(matched within tol, worst relative frequency error)` of the 17 true modes in the
/// band against the nearest fitted pole pair.
fn modes(model: &FrfModel, truth: &Truth, tol: f64) -> (usize, f64) {
    let fitted = model.modal.mode_summaries();
    let mut worst: f64 = 0.0;
    let mut matched = 0;
    for tm in truth.model.modes.iter().filter(|m| m.f_hz < 2000.0) {
        let e = fitted
            .iter()
            .map(|f| (f.f_hz / tm.f_hz - 1.0).abs())
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(e);
        if e <= tol {
            matched += 1;
        }
    }
    (matched, worst)
}

#[test]
fn noiseless_wafer_is_reproduced() {
    faer::set_global_parallelism(faer::Par::Seq);
    let test = "noiseless_wafer_is_reproduced";
    let Some(clean) = require(test, "wafer_nominal.noiseless.csv") else {
        return;
    };
    let clean = read_frf_csv(&clean).unwrap();
    let band = clean.band(20.0, 2000.0).unwrap();
    let id = SubspaceInit::new(declared()).identify(&band).unwrap();
    let (median, p95) = id
        .model
        .relative_error(&band.omegas(), &grid(&band))
        .unwrap();
    let r = &id.report;
    println!(
        "noiseless wafer: order {} ({}), {} pairs, {} integrators, median {median:.3e}, p95 {p95:.3e}, cond {:?}, timings {:?}",
        r.order, r.order_rule, r.pairs, r.integrators, r.conditioning, id.timings
    );
    println!(
        "singular values: {:?}",
        &r.singular_values[..45.min(r.singular_values.len())]
    );
    assert!(median <= 1e-6, "median relative error {median:.3e}");
}

#[test]
fn noisy_wafer_modes_and_error() {
    faer::set_global_parallelism(faer::Par::Seq);
    let test = "noisy_wafer_modes_and_error";
    let (Some(data), Some(clean), Some(truth)) = (
        require(test, "wafer_nominal.csv"),
        require(test, "wafer_nominal.noiseless.csv"),
        require(test, "wafer_nominal.truth.json"),
    ) else {
        return;
    };
    let data = read_frf_csv(&data).unwrap();
    let clean = read_frf_csv(&clean).unwrap();
    let truth = Truth::read(&truth).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let cband = clean.band(20.0, 2000.0).unwrap();
    let id = SubspaceInit::new(declared()).identify(&band).unwrap();
    let (median, p95) = id
        .model
        .relative_error(&cband.omegas(), &grid(&cband))
        .unwrap();
    let (matched, worst) = modes(&id.model, &truth, 5e-3);
    let r = &id.report;
    println!(
        "noisy wafer: order {} ({}), {} pairs, {} real, {} integrators, {matched}/17 modes within 0.5 % (worst {worst:.2e}), median {median:.3e}, p95 {p95:.3e} vs noiseless, reflected {}, cond {:?}, timings {:?}",
        r.order, r.order_rule, r.pairs, r.real_poles, r.integrators, r.reflected_poles.len(), r.conditioning, id.timings
    );
    println!(
        "singular values: {:?}",
        &r.singular_values[..50.min(r.singular_values.len())]
    );
    assert_eq!(matched, 17, "modes within 0.5 %");
    assert!(median <= 1e-3, "median relative error {median:.3e}");
}
