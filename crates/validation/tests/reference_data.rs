//! The residual analysis on the shared reference data (skipped when `../shared/data` is
//! absent): each file's truth model (from its `truth.json`, without the undeclared
//! effect) against the data, so that the residual holds exactly the effect plus noise.

use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::truth::Truth;
use frf_data::{Frf, FrfDataset, C64};
use realize::ResponseGrid;
use validation::{
    analyze_residual, estimate_noise, noise_level, relative_error_stats, Effect, NoiseConfig,
    ResidualAnalysis, ResidualConfig,
};

const FS: f64 = 1e4;

fn load(test: &str, name: &str) -> Option<(Frf, Truth, ResponseGrid)> {
    let p = require(test, &format!("{name}.csv"))?;
    let t = require(test, &format!("{name}.truth.json"))?;
    let data = read_frf_csv(p).unwrap();
    let truth = Truth::read(t).unwrap();
    // The exact reference response: hold at 10 kHz and one sample of computation delay.
    let model = truth
        .modal_model()
        .unwrap()
        .zoh_response(&data.omegas(), 1.0 / FS, 1.0)
        .unwrap();
    Some((data, truth, model))
}

fn run(data: &Frf, model: &ResponseGrid) -> ResidualAnalysis {
    let cfg = ResidualConfig {
        sample_rate_hz: Some(FS),
        ..Default::default()
    };
    let noise = noise_level(data).unwrap();
    analyze_residual(data, model, &noise, &cfg).unwrap()
}

fn flagged(a: &ResidualAnalysis) -> Vec<Effect> {
    a.evidence
        .iter()
        .filter(|e| e.significant)
        .map(|e| e.effect)
        .collect()
}

fn show(name: &str, a: &ResidualAnalysis) {
    println!(
        "{name}: median rel {:.2e} (noise {:.2e}), p95 {:.2e}, r/n {:.3}, excess {:.4}, level \
         {:.4}, nu {:.1}, kappa {:.3}, significant {}, trend {:?}, flagged {:?}",
        a.median_rel,
        a.median_noise_rel,
        a.p95_rel,
        a.residual_to_noise,
        a.significance.excess_ratio,
        a.significance.level_ratio,
        a.significance.line_dof,
        a.significance.noise_scale,
        a.significant,
        a.magnitude_trend.class,
        flagged(a)
    );
    for e in a.evidence.iter().take(3) {
        println!(
            "    {:?} {:.3}: {}",
            e.effect, e.explained_fraction, e.detail
        );
    }
}

#[test]
fn nominal_truth_residual_is_noise() {
    let Some((data, _, model)) = load("nominal_truth_residual_is_noise", "wafer_nominal") else {
        return;
    };
    let a = run(&data, &model);
    show("wafer_nominal vs truth", &a);
    assert!(!a.significant);
    assert!(flagged(&a).is_empty());
    assert!(a.residual_cmif.is_empty());
    assert!(
        (1.0..1.15).contains(&a.residual_to_noise),
        "{}",
        a.residual_to_noise
    );
    // The noise of 10 realizations: F tail and correlation show in the calibration.
    assert!((1.05..1.2).contains(&a.significance.noise_scale));
    assert!(a.significance.line_dof < 2.0 * 52.0 * 0.8);
    // The model is the noiseless truth: the median relative error is the noise's.
    assert!(a.median_rel < 1.0 * a.median_noise_rel);
    // relative_error_stats agrees with the analysis.
    let (med, p95) = relative_error_stats(&data, &model).unwrap();
    assert_eq!((med, p95), (a.median_rel, a.p95_rel));
    // Against the noiseless file the same holds.
    if let Some(p) = require(
        "nominal_truth_residual_is_noise",
        "wafer_nominal.noiseless.csv",
    ) {
        let nl = read_frf_csv(p).unwrap();
        let grid = ResponseGrid {
            ny: nl.ny(),
            nu: nl.nu(),
            values: nl.values().to_vec(),
        };
        let b = run(&data, &grid);
        assert!(!b.significant);
        let worst = nl
            .values()
            .iter()
            .zip(&model.values)
            .map(|(a, b)| (a - b).norm() / a.norm())
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-6,
            "reference response differs from the noiseless file: {worst}"
        );
    }
}

#[test]
fn nominal_with_estimated_noise_is_not_significant() {
    let Some((data, _, model)) = load("nominal_with_estimated_noise", "wafer_nominal") else {
        return;
    };
    let bare = data.clone().with_variance(None).unwrap();
    let nl = noise_level(&bare).unwrap();
    assert!(nl.is_estimated());
    let a = analyze_residual(&bare, &model, &nl, &ResidualConfig::default()).unwrap();
    show("wafer_nominal vs truth, estimated noise", &a);
    assert!(!a.significant);
    // The estimate against the measured variance: medians per band.
    let var = data.variances().unwrap();
    let m = data.n_entries();
    // 50-200 Hz holds seven of the 17 modes (118-215 Hz): the estimate is biased high
    // there (the documented bias near resonances, the conservative direction).
    for (lo, hi, range) in [
        (50.0, 200.0, 0.8..2.0),
        (200.0, 1000.0, 0.8..1.25),
        (1000.0, 2000.0, 0.8..1.25),
    ] {
        let mut r: Vec<f64> = (0..data.n_lines())
            .filter(|k| (lo..hi).contains(&data.freq_hz(*k)))
            .flat_map(|k| (0..m).map(move |e| k * m + e))
            .map(|i| nl.variance[i] / var[i])
            .collect();
        r.sort_by(|a, b| a.total_cmp(b));
        let med = r[r.len() / 2];
        println!("{lo}-{hi} Hz: median estimated / measured variance {med:.3}");
        assert!(range.contains(&med), "{med}");
    }
    // A second-order difference is badly biased on this lightly damped, high-SNR data.
    let nl2 = estimate_noise(
        &bare,
        &NoiseConfig {
            order: 2,
            ..Default::default()
        },
    )
    .unwrap();
    let k = data
        .omegas()
        .partition_point(|w| *w < std::f64::consts::TAU * 100.0);
    assert!(nl2.variance[k * m] > 10.0 * var[k * m]);
}

#[test]
fn nominal_without_hold_shows_the_hold() {
    let Some((data, truth, _)) = load("nominal_without_hold", "wafer_nominal") else {
        return;
    };
    // The continuous model with the hold's and the computation's delay (1.5 samples)
    // but without the hold's droop.
    let w = data.omegas();
    let mut model = truth.modal_model().unwrap().freq_response(&w).unwrap();
    let m = data.n_entries();
    for k in 0..data.n_lines() {
        let ph = C64::from_polar(1.0, -w[k] * truth.delay_s);
        for v in &mut model.values[k * m..(k + 1) * m] {
            *v *= ph;
        }
    }
    let a = run(&data, &model);
    show("wafer_nominal vs continuous truth", &a);
    let h = a.hold.as_ref().unwrap();
    println!(
        "    hold amplitude {:.4}, correlation {:.4}, explains {:.4}",
        h.amplitude, h.correlation, h.fit.explained_fraction
    );
    assert_eq!(flagged(&a), vec![Effect::Hold]);
    assert!(h.consistent && (0.9..1.15).contains(&h.amplitude));
}

#[test]
fn extra_delay_is_found() {
    let Some((data, truth, model)) = load("extra_delay_is_found", "wafer_extra_delay") else {
        return;
    };
    let declared = truth.effects["extra_delay_us"].as_f64().unwrap() * 1e-6;
    let a = run(&data, &model);
    show("wafer_extra_delay vs truth", &a);
    println!(
        "    delay {:.4} us +- {:.4} us (declared {:.1} us)",
        a.phase_trend.delay_s * 1e6,
        a.phase_trend.std_s * 1e6,
        declared * 1e6
    );
    assert_eq!(flagged(&a), vec![Effect::Delay]);
    assert!((a.phase_trend.delay_s - declared).abs() < 0.5e-6);
}

#[test]
fn crosstalk_is_feedthrough() {
    let Some((data, truth, model)) = load("crosstalk_is_feedthrough", "wafer_crosstalk") else {
        return;
    };
    let d: Vec<Vec<f64>> = serde_json::from_value(truth.effects["crosstalk_D"].clone()).unwrap();
    let a = run(&data, &model);
    show("wafer_crosstalk vs truth", &a);
    assert_eq!(flagged(&a), vec![Effect::Feedthrough]);
    let ny = data.ny();
    let (mut err, mut norm) = (0.0, 0.0);
    for (e, z) in a.feedthrough.d.iter().enumerate() {
        let t = d[e % ny][e / ny];
        err += (z - t).norm_sqr();
        norm += t * t;
    }
    println!("    |D_fit - D| / |D| = {:.4}", (err / norm).sqrt());
    assert!((err / norm).sqrt() < 0.05);
}

#[test]
fn hidden_mode_is_a_residual_cmif_peak() {
    let Some((data, truth, model)) = load("hidden_mode_is_a_peak", "wafer_hidden_mode") else {
        return;
    };
    let f_true = truth.effects["hidden_mode"]["f_hz"].as_f64().unwrap();
    let z_true = truth.effects["hidden_mode"]["zeta"].as_f64().unwrap();
    let a = run(&data, &model);
    show("wafer_hidden_mode vs truth", &a);
    let p = a.residual_cmif.iter().find(|p| p.significant).unwrap();
    println!(
        "    peak {:.3} Hz (true {f_true:.3}), zeta {:.5} (true {z_true:.5}), {:.1} dB over the noise",
        p.f_hz,
        p.fit_zeta,
        10.0 * p.height_over_noise.log10()
    );
    assert_eq!(flagged(&a), vec![Effect::MissedMode]);
    assert!((p.f_hz / f_true - 1.0).abs() < 0.005);
    assert!((p.fit_zeta / z_true - 1.0).abs() < 0.2);
}
