//! Acceptance of the additive-RIV method on the reference wafer stage
//! (`../shared/data/wafer_nominal.csv` with its exact truth). Skipped, with a message,
//! when `../shared/data` is not beside the checkout; the simulated systems of
//! `consistency.rs` cover the same properties without files.

use additive_riv::model_json::RANK_TOL;
use additive_riv::{AdditiveFitter, AdditiveModel, DelayChoice, FitterConfig, Hold};
use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::truth::Truth;
use frf_data::{FrfDataset, ModelStructure, Weighting};

/// Median and 95th percentile of the element-wise relative error of `model` against
/// `reference` (all lines and entries).
fn rel_error_quantiles(model: &AdditiveModel, reference: &dyn FrfDataset) -> (f64, f64) {
    let g = model.response(reference);
    let (ny, nu) = (reference.ny(), reference.nu());
    let m = ny * nu;
    let mut v = Vec::with_capacity(reference.n_lines() * m);
    for k in 0..reference.n_lines() {
        for e in 0..m {
            let t = reference.value(k, e % ny, e / ny);
            v.push((g.values[k * m + e] - t).norm() / t.norm());
        }
    }
    v.sort_by(|a, b| a.total_cmp(b));
    (v[v.len() / 2], v[(v.len() as f64 * 0.95) as usize])
}

/// Worst relative frequency and damping error over the true modes in the band, each
/// matched to the nearest fitted mode; also the number of fitted modes matched within
/// `f_tol` and the number of fitted modes in total.
fn mode_errors(model: &AdditiveModel, truth: &Truth, f_tol: f64) -> (f64, f64, usize, usize) {
    let fitted = model.modes();
    let mut worst_f: f64 = 0.0;
    let mut worst_z: f64 = 0.0;
    let mut matched = 0;
    for tm in truth.model.modes.iter().filter(|m| m.f_hz < 2000.0) {
        let best = fitted
            .iter()
            .min_by(|a, b| {
                (a.f_hz - tm.f_hz)
                    .abs()
                    .total_cmp(&(b.f_hz - tm.f_hz).abs())
            })
            .expect("the fit holds modes");
        let ef = (best.f_hz / tm.f_hz - 1.0).abs();
        let ez = (best.zeta / tm.zeta - 1.0).abs();
        worst_f = worst_f.max(ef);
        worst_z = worst_z.max(ez);
        if ef <= f_tol {
            matched += 1;
        }
    }
    (worst_f, worst_z, matched, fitted.len())
}

/// Section 4 of the wafer-stage paper: delay compensated (150 us, the hold plus one
/// sample of computation), eq. (27) weighting, continuous-time additive model.
#[test]
fn wafer_nominal_delay_compensated_inverse_magnitude() {
    let test = "wafer_nominal_delay_compensated_inverse_magnitude";
    let (Some(data), Some(truth)) = (
        require(test, "wafer_nominal.csv"),
        require(test, "wafer_nominal.truth.json"),
    ) else {
        return;
    };
    let data = read_frf_csv(&data).unwrap();
    let truth = Truth::read(&truth).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let mut cfg = FitterConfig {
        delay: DelayChoice::Fixed { seconds: 150e-6 },
        ..Default::default()
    };
    cfg.riv.weighting = Weighting::InverseMagnitude;
    let (fit, report) = AdditiveFitter::new(cfg).fit(&band).unwrap();
    let (df, dz, matched, n_fitted) = mode_errors(&fit.model, &truth, 1e-3);
    // iterations of Algorithm 1 per refinement: the first from the CMIF start, then one
    // after each structure change (the picker merges the 636/645 Hz pair)
    let refinements = report
        .adapt
        .as_ref()
        .map(|a| a.refinements.clone())
        .unwrap_or_default();
    let last = refinements.last().copied().unwrap_or(fit.iterations);
    let order = fit.model.to_modal_model().unwrap().order(RANK_TOL);
    println!(
        "eq. (27), delay compensated: {matched}/17 modes within 0.1%, {n_fitted} fitted; \
         worst df {df:.2e}, dz {dz:.2e}; {} iterations in all, per refinement {refinements:?} ({:?}); order {order}",
        fit.iterations, fit.convergence
    );
    assert_eq!(matched, 17, "all 17 flexible modes within 0.1%");
    assert_eq!(n_fitted, 17, "no spurious modes");
    assert!(df <= 1e-3, "worst frequency error {df:.2e}");
    assert!(dz <= 0.10, "worst damping error {dz:.2e}");
    assert!(fit.convergence.is_converged(), "{:?}", fit.convergence);
    assert!(last <= 30, "{last} iterations from the final structure");
    assert_eq!(order, 40, "3 rigid-body + 17 rank-one modes");
}

/// The exact 10 kHz zero-order hold modelled, default (inverse-variance) weighting:
/// the model is compared with the noiseless reference response.
#[test]
fn wafer_nominal_exact_hold_reaches_the_reference() {
    let test = "wafer_nominal_exact_hold_reaches_the_reference";
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
    let cfg = FitterConfig {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        ..Default::default()
    };
    let (fit, _report) = AdditiveFitter::new(cfg).fit(&band).unwrap();
    let (median, p95) = rel_error_quantiles(&fit.model, &clean.band(20.0, 2000.0).unwrap());
    let (df, dz, matched, n_fitted) = mode_errors(&fit.model, &truth, 2e-4);
    let order = fit.model.to_modal_model().unwrap().order(RANK_TOL);
    println!(
        "exact hold: median {median:.3e}, p95 {p95:.3e} vs noiseless; {matched}/17 modes \
         within 0.02%, {n_fitted} fitted; worst df {df:.2e}, dz {dz:.2e}; {} iterations \
         ({:?}); order {order}",
        fit.iterations, fit.convergence
    );
    assert!(median <= 1.5e-5, "median {median:.3e}");
    assert!(p95 <= 2e-4, "p95 {p95:.3e}");
    assert_eq!(matched, 17);
    assert_eq!(n_fitted, 17);
    assert!(dz <= 0.03, "worst damping error {dz:.2e}");
    assert!(fit.convergence.is_converged(), "{:?}", fit.convergence);
}

/// `wafer_nominal.csv` with input 5 passed through a first-order lag at 600 Hz (its
/// variance scaled alike), fitted with the nominal structure (declared hold and delay,
/// inverse-variance weighting): a model that lacks an effect of the data. Algorithm 1's
/// fixed point is then not a minimum of the cost; the iterations crawl with steps cut
/// by the backtracking (they ran to the 50-iteration cap at a cost constant to 5
/// digits) and stop as `Stalled`, not converged and said so (measured: after 40
/// iterations in all, the last 3 lowering the cost by 1.7e-6 relative).
#[test]
fn an_unmodelled_lag_stalls_the_iterations() {
    use frf_data::{Convergence, Frf, C64};
    let test = "an_unmodelled_lag_stalls_the_iterations";
    let Some(data) = require(test, "wafer_nominal.csv") else {
        return;
    };
    let data = read_frf_csv(&data).unwrap();
    let (ny, nu) = (data.ny(), data.nu());
    let m = ny * nu;
    let f = data.freq_hz_slice().to_vec();
    let mut vals = data.values().to_vec();
    let mut var = data.variances().map(|v| v.to_vec()).unwrap();
    for (k, fk) in f.iter().enumerate() {
        let lag = C64::new(1.0, fk / 600.0).inv();
        for e in (4 * ny)..(5 * ny) {
            vals[k * m + e] *= lag;
            var[k * m + e] *= lag.norm_sqr();
        }
    }
    let lagged = Frf::new(f, ny, nu, vals, Some(var)).unwrap();
    let band = lagged.band(20.0, 2000.0).unwrap();
    let cfg = FitterConfig {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Fixed { seconds: 100e-6 },
        ..Default::default()
    };
    let (fit, _report) = AdditiveFitter::new(cfg).fit(&band).unwrap();
    println!(
        "{:?} after {} iterations; {}",
        fit.convergence,
        fit.iterations,
        fit.convergence.describe()
    );
    assert!(
        matches!(fit.convergence, Convergence::Stalled { .. }),
        "{:?}",
        fit.convergence
    );
    assert!(!fit.convergence.is_converged());
    assert!(fit
        .convergence
        .describe()
        .starts_with("NOT converged: stalled"));
    // the stalled steps lowered the cost, by almost nothing
    let h = &fit.cost_history;
    let last = &h[h.len() - 4..];
    assert!(last.windows(2).all(|w| w[1] <= w[0]), "{last:?}");
    assert!((last[0] - last[3]) / last[0] < 1e-5, "{last:?}");
}
