//! The SK initialiser on the reference wafer stage (`../shared/data/wafer_nominal.csv`,
//! 4 x 13, 17 modes and a free rigid body, sampled at 10 kHz through a zero-order hold
//! with one sample of computation delay): compared with the noiseless response and the
//! truth. Skipped, with a message, when `../shared/data` is not beside the checkout.

use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::truth::Truth;
use frf_data::{Estimator, FrfDataset};
use realize::{FrfModel, Hold};
use sk_fit::{SkConfig, SkInit};

/// Median relative error against `reference` and the number of true modes below
/// 2000 Hz matched by a fitted mode within `f_tol` (relative), with the worst frequency
/// error and the number of fitted modes in the band.
fn compare(model: &FrfModel, reference: &dyn FrfDataset, truth: &Truth, f_tol: f64) -> (f64, f64, usize, f64, usize) {
    let w = reference.omegas();
    let g = realize::ResponseGrid {
        values: reference.values_vec(),
        ..realize::ResponseGrid::zeros(w.len(), reference.ny(), reference.nu())
    };
    let (median, p95) = model.relative_error(&w, &g).unwrap();
    let fitted = model.modal.mode_summaries();
    let mut matched = 0;
    let mut worst: f64 = 0.0;
    for tm in truth.model.modes.iter().filter(|m| m.f_hz < 2000.0) {
        let best = fitted
            .iter()
            .map(|f| (f.f_hz / tm.f_hz - 1.0).abs())
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(best);
        if best <= f_tol {
            matched += 1;
        }
    }
    let in_band = fitted.iter().filter(|f| f.f_hz >= 20.0 && f.f_hz <= 2000.0).count();
    (median, p95, matched, worst, in_band)
}

#[test]
fn wafer_nominal_sk_reaches_the_reference() {
    let test = "wafer_nominal_sk_reaches_the_reference";
    let (Some(data), Some(clean), Some(truth)) = (
        require(test, "wafer_nominal.csv"),
        require(test, "wafer_nominal.noiseless.csv"),
        require(test, "wafer_nominal.truth.json"),
    ) else {
        return;
    };
    faer::set_global_parallelism(faer::Par::Seq);
    let data = read_frf_csv(&data).unwrap();
    let clean = read_frf_csv(&clean).unwrap();
    let truth = Truth::read(&truth).unwrap();
    let src = if std::env::var("SK_CLEAN").is_ok() { &clean } else { &data };
    let band = src.band(20.0, 2000.0).unwrap();
    let order: Option<usize> = std::env::var("SK_ORDER").ok().map(|s| s.parse().unwrap());
    let cfg = SkConfig {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        order,
        delay: if std::env::var("SK_CLEAN").is_ok() { frf_data::DelayChoice::Fixed { seconds: 1e-4 } } else { frf_data::DelayChoice::Auto },
        weighting: if std::env::var("SK_CLEAN").is_ok() { frf_data::Weighting::InverseMagnitude } else { frf_data::Weighting::Auto },
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let fit = SkInit::new(cfg).estimate(&band, ()).unwrap();
    let secs = t.elapsed().as_secs_f64();
    let (median, p95, matched, worst, in_band) =
        compare(&fit.model, &clean.band(20.0, 2000.0).unwrap(), &truth, 1e-3);
    println!(
        "wafer SK: order {} ({} iterations, {:?}), median {median:.3e}, p95 {p95:.3e} vs noiseless; \
         {matched}/17 modes within 0.1% (worst {worst:.2e}), {in_band} fitted modes in band; {secs:.1} s",
        fit.report.order, fit.iterations, fit.convergence
    );
    println!("{:#?}", fit.messages);
    println!("sweep {:?}", fit.report.sweep.iter().map(|s| (s.order, s.cost, s.f, s.chosen)).collect::<Vec<_>>());
    println!("sk cost {:?}", fit.report.sk_cost_history);
}
