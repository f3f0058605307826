//! The SK initialiser on a real measurement: the DaISy steel subframe
//! (`../shared/data/real/daisy_flexible_structure.csv`, 28 x 2 accelerance, an H1
//! estimate with its variance, 491 lines 10..500 Hz, 14 listed modes). Skipped, with a
//! message, when the file is not there.
//!
//! The statistic is the median over lines and entries of `|G - P| / sqrt(var)`: for a
//! model at the noise level it is `sqrt(ln 2) = 0.83` (the median of a complex Gaussian's
//! magnitude over its standard deviation).

use frf_data::io::read_frf;
use frf_data::shared_data::require;
use frf_data::{Estimator, FrfDataset};
use sk_fit::{SkConfig, SkInit};

/// Order 58 given (what the F-test sweep of the SK fit chose before it was warm-started;
/// the warm-started sweep of `frfit fit --init sk` goes on to 76 and reaches a median of
/// 1.03 too, in about 30 s: too slow for a test). Measured: median 1.034, rms 1.36; the
/// SK iterations do not converge on these data (the cost cycles: H1 leakage near the
/// sharp peaks is not a rational model), which the fit reports.
#[test]
fn daisy_sk_reaches_the_noise_level() {
    let Some(path) = require("daisy_sk", "real/daisy_flexible_structure.csv") else {
        return;
    };
    faer::set_global_parallelism(faer::Par::Seq);
    let data = read_frf(&path).unwrap();
    let cfg = SkConfig {
        // accelerance data
        derivative_order: 2,
        order: Some(58),
        ..Default::default()
    };
    let fit = SkInit::new(cfg).estimate(&data, ()).unwrap();
    let w = data.omegas();
    let p = fit.model.freq_response(&w).unwrap();
    let g = data.values_vec();
    let var = data.variance_vec().expect("the file carries _var columns");
    let mut r: Vec<f64> = p
        .values
        .iter()
        .zip(&g)
        .zip(&var)
        .map(|((p, g), v)| (p - g).norm() / v.sqrt())
        .collect();
    let rms = (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt();
    r.sort_by(|a, b| a.total_cmp(b));
    let median = r[r.len() / 2];
    println!(
        "daisy SK: order {} ({} pairs, {} real poles, {} integrators), {} iterations ({}), \
         median |G - P| / sqrt(var) {median:.3}, rms {rms:.3}",
        fit.report.order,
        fit.report.pairs,
        fit.report.real_poles,
        fit.report.integrators,
        fit.iterations,
        fit.convergence.describe()
    );
    assert!(median <= 1.1, "median |G - P| / sqrt(var) {median:.3}");
    // the 14 listed modes are there (within 1 %)
    let listed = [
        62.0, 119.0, 155.0, 193.0, 215.0, 230.0, 239.0, 287.0, 321.0, 334.0, 352.0, 398.0, 417.0,
        468.0,
    ];
    let fitted = fit.model.modal.mode_summaries();
    for f in listed {
        let best = fitted
            .iter()
            .map(|m| (m.f_hz / f - 1.0).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(
            best <= 0.01,
            "listed mode {f} Hz: nearest fitted {best:.3e} away"
        );
    }
}
