//! Clear errors when data, model and noise disagree; no panic on bad user input; views
//! of a dataset work like the dataset.

mod common;

use common::*;
use frf_data::{Frf, FrfDataset, FrfError, C64};
use realize::ResponseGrid;
use validation::{
    analyze_residual, hold_signature, noise_level, relative_error_stats, NoiseLevel, NoiseSource,
    Residual, ResidualConfig, ValidationError,
};

fn setup() -> (Frf, ResponseGrid, NoiseLevel) {
    let f: Vec<f64> = freqs().into_iter().take(200).collect();
    let p = response(&nominal(), &f);
    let data = add_noise(&f, &p, REL, 1);
    let noise = noise_level(&data).unwrap();
    (data, p, noise)
}

fn err(data: &Frf, model: &ResponseGrid, noise: &NoiseLevel) -> ValidationError {
    analyze_residual(data, model, noise, &ResidualConfig::default()).unwrap_err()
}

#[test]
fn model_dimensions_are_named() {
    let (data, p, noise) = setup();
    let wrong = ResponseGrid::zeros(p.len(), NU, NY);
    let e = err(&data, &wrong, &noise);
    assert!(matches!(e, ValidationError::Dimension { .. }));
    let msg = e.to_string();
    assert!(
        msg.contains("model response vs data (outputs x inputs)"),
        "{msg}"
    );
    assert!(
        msg.contains("3x4 (data)") && msg.contains("4x3 (model)"),
        "{msg}"
    );
    let short = ResponseGrid::zeros(p.len() - 1, NY, NU);
    let msg = err(&data, &short, &noise).to_string();
    assert!(
        msg.contains("model response vs data (lines)") && msg.contains("200 lines"),
        "{msg}"
    );
    let mut nan = p.clone();
    nan.values[5 * NY * NU + 4] = C64::new(f64::NAN, 0.0);
    let msg = err(&data, &nan, &noise).to_string();
    assert!(
        msg.contains("model response") && msg.contains("line 5") && msg.contains("G2_2"),
        "{msg}"
    );
    assert!(relative_error_stats(&data, &short).is_err());
}

#[test]
fn noise_dimensions_are_named() {
    let (data, p, noise) = setup();
    let swapped = NoiseLevel {
        ny: NU,
        nu: NY,
        ..noise.clone()
    };
    let msg = err(&data, &p, &swapped).to_string();
    assert!(
        msg.contains("noise level vs data (outputs x inputs)"),
        "{msg}"
    );
    let mut short = noise.clone();
    short.variance.truncate(100);
    let msg = err(&data, &p, &short).to_string();
    assert!(
        msg.contains("noise level vs data (lines x entries)") && msg.contains("2400"),
        "{msg}"
    );
    let mut neg = noise.clone();
    neg.variance[7] = -1.0;
    let e = err(&data, &p, &neg);
    assert!(matches!(e, ValidationError::InvalidInput { .. }), "{e}");
    assert!(e.to_string().contains("G2_3"), "{e}");
    let mut zero = noise.clone();
    for k in 0..data.n_lines() {
        zero.variance[k * NY * NU + 2] = 0.0;
    }
    let msg = err(&data, &p, &zero).to_string();
    assert!(
        msg.contains("G3_1") && msg.contains("zero at every line"),
        "{msg}"
    );
    // Isolated zeros are floored, not infinite.
    let mut some = noise.clone();
    some.variance[3] = 0.0;
    let a = analyze_residual(&data, &p, &some, &ResidualConfig::default()).unwrap();
    assert!(a.residual_to_noise.is_finite());
}

#[test]
fn too_few_lines_and_bad_settings() {
    let f = vec![10.0, 20.0];
    let p = response(&nominal(), &f);
    let data = add_noise(&f, &p, REL, 1);
    let noise = noise_level(&data).unwrap();
    match err(&data, &p, &noise) {
        ValidationError::TooFewLines {
            needed: 3, got: 2, ..
        } => {}
        e => panic!("{e}"),
    }
    let (data, p, noise) = setup();
    for cfg in [
        ResidualConfig {
            alpha: 0.0,
            ..Default::default()
        },
        ResidualConfig {
            max_noise_scale: 0.5,
            ..Default::default()
        },
        ResidualConfig {
            min_explained: 1.5,
            ..Default::default()
        },
        ResidualConfig {
            sample_rate_hz: Some(-1.0),
            ..Default::default()
        },
        ResidualConfig {
            local_half_window: 0,
            ..Default::default()
        },
        ResidualConfig {
            peak_over_local: f64::NAN,
            ..Default::default()
        },
    ] {
        let e = analyze_residual(&data, &p, &noise, &cfg).unwrap_err();
        assert!(matches!(e, ValidationError::InvalidConfig { .. }), "{e}");
    }
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let (data, p, noise) = setup();
    // A zero model: the residual is the data.
    let zero = ResponseGrid::zeros(p.len(), NY, NU);
    let a = analyze_residual(&data, &zero, &noise, &ResidualConfig::default()).unwrap();
    assert!(a.significant);
    assert!(a.median_rel > 0.99 && a.median_rel < 1.01);
    assert_eq!(a.phase_trend.delay_s, 0.0);
    // Data equal to the model: no residual at all.
    let exact = Frf::new(
        data.freqs_hz(),
        NY,
        NU,
        p.values.clone(),
        Some(noise.variance.clone()),
    )
    .unwrap();
    let a = analyze_residual(&exact, &p, &noise, &ResidualConfig::default()).unwrap();
    assert!(!a.significant);
    assert_eq!(a.residual_to_noise, 0.0);
    serde_json::to_string(&a).unwrap();
    // An invalid sample rate gives an unflagged hold signature.
    let res = Residual::new(&data, &p, &noise, &ResidualConfig::default()).unwrap();
    for fs in [0.0, f64::NAN, -3.0] {
        let h = hold_signature(&res, fs);
        assert!(!h.consistent && h.apparent_fs_hz.is_none());
    }
    // All-zero data: the relative error is undefined.
    let z = Frf::from_grid(data.freqs_hz(), zero.clone()).unwrap();
    assert!(relative_error_stats(&z, &zero).is_err());
}

#[test]
fn views_work_like_datasets() {
    let (data, p, _) = setup();
    let view = data.band(20.0, 60.0).unwrap();
    let n = view.n_lines();
    let start = view.line_range().start;
    let m = NY * NU;
    let sub = ResponseGrid {
        ny: NY,
        nu: NU,
        values: p.values[start * m..(start + n) * m].to_vec(),
    };
    let noise = noise_level(&view).unwrap();
    assert_eq!(noise.source, NoiseSource::Measured);
    let a = analyze_residual(&view, &sub, &noise, &ResidualConfig::default()).unwrap();
    assert_eq!(a.n_lines, n);
    assert!(!a.significant);
    let sel = data.select(&[0, 2], &[1]).unwrap();
    let mut vals = Vec::new();
    for k in 0..sel.n_lines() {
        vals.push(p.get(k, 0, 1));
        vals.push(p.get(k, 2, 1));
    }
    let grid = ResponseGrid {
        ny: 2,
        nu: 1,
        values: vals,
    };
    let noise = noise_level(&sel).unwrap();
    let a = analyze_residual(&sel, &grid, &noise, &ResidualConfig::default()).unwrap();
    assert_eq!((a.ny, a.nu), (2, 1));
    assert!(!a.significant);
    // The crate's error wraps the data layer's.
    let e: ValidationError = FrfError::NoVariance { what: "x".into() }.into();
    assert!(matches!(e, ValidationError::Frf(_)));
}
