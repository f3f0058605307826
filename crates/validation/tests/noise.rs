//! The noise level: measured variance passed through, and the estimate from the data's
//! roughness checked against simulated noise of known variance.

mod common;

use common::*;
use frf_data::Frf;
use validation::{estimate_noise, noise_level, NoiseConfig, NoiseSource, ValidationError};

fn ratio_stats(r: &mut [f64]) -> (f64, f64) {
    r.sort_by(|a, b| a.total_cmp(b));
    let within = r.iter().filter(|x| **x > 1.0 / 1.5 && **x < 1.5).count() as f64 / r.len() as f64;
    (r[r.len() / 2], within)
}

/// Distance (relative) of `f` from the nearest mode.
fn rel_distance_to_mode(f: f64) -> f64 {
    MODES
        .iter()
        .map(|(fm, _)| (f - fm).abs() / fm)
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn measured_variance_is_passed_through() {
    let f = freqs();
    let data = add_noise(&f, &response(&nominal(), &f), REL, 1);
    let nl = noise_level(&data).unwrap();
    assert_eq!(nl.source, NoiseSource::Measured);
    assert_eq!(nl.variance, data.variances().unwrap());
    assert_eq!((nl.ny, nl.nu, nl.n_lines()), (NY, NU, f.len()));
    assert!(!nl.is_estimated());
}

#[test]
fn estimate_within_factor_1_5_away_from_resonances() {
    let f = freqs();
    let truth = response(&nominal(), &f);
    let m = NY * NU;
    let mut medians = Vec::new();
    for seed in 0..3 {
        let noisy = add_noise(&f, &truth, REL, 100 + seed);
        let true_var = noisy.variances().unwrap().to_vec();
        let data = noisy.with_variance(None).unwrap();
        let nl = noise_level(&data).unwrap();
        match &nl.source {
            NoiseSource::Estimated { method } => {
                assert!(
                    method.contains("order-4") && method.contains("+-40"),
                    "{method}"
                )
            }
            s => panic!("expected an estimate, got {s:?}"),
        }
        // Away from resonances (more than 10 % from every mode) and above 5 Hz (the
        // rigid body's lowest lines).
        let mut away = Vec::new();
        let mut near = Vec::new();
        for (k, &fk) in f.iter().enumerate() {
            let d = rel_distance_to_mode(fk);
            for e in 0..m {
                let r = nl.variance[k * m + e] / true_var[k * m + e];
                if fk > 5.0 && d > 0.1 {
                    away.push(r);
                } else if d < 0.01 {
                    near.push(r);
                }
            }
        }
        let (med, within) = ratio_stats(&mut away);
        let (med_near, _) = ratio_stats(&mut near);
        println!(
            "seed {seed}: away from resonances median ratio {med:.3}, {:.1} % within 1.5x; \
             within 1 % of a mode median ratio {med_near:.2}",
            100.0 * within
        );
        assert!((0.85..1.15).contains(&med), "median ratio {med}");
        assert!(within > 0.9, "only {within} within a factor 1.5");
        // The documented bias: near sharp resonances (half-power bandwidths of 2.5 to
        // 10 lines at a relative noise level of 1e-3) the estimate is too high.
        assert!(med_near > 1.1, "near-resonance median ratio {med_near}");
        medians.push(med);
    }
    assert_eq!(medians.len(), 3);
}

#[test]
fn low_noise_resonance_bias_grows_with_signal_to_noise() {
    // The same system with 100 times less noise: the signal left in the differences
    // near resonances dominates over more lines, so the estimate is biased high over a
    // wider band; away from the modes it is still right.
    let f = freqs();
    let truth = response(&nominal(), &f);
    let m = NY * NU;
    let frac_biased = |rel: f64| -> (f64, f64) {
        let noisy = add_noise(&f, &truth, rel, 7);
        let true_var = noisy.variances().unwrap().to_vec();
        let data = noisy.with_variance(None).unwrap();
        let nl = noise_level(&data).unwrap();
        let mut biased = 0usize;
        let mut total = 0usize;
        let mut away = Vec::new();
        for (k, &fk) in f.iter().enumerate() {
            if fk < 5.0 {
                continue;
            }
            for e in 0..m {
                let r = nl.variance[k * m + e] / true_var[k * m + e];
                total += 1;
                if r > 2.0 {
                    biased += 1;
                }
                if rel_distance_to_mode(fk) > 0.1 {
                    away.push(r);
                }
            }
        }
        let (med, _) = ratio_stats(&mut away);
        (biased as f64 / total as f64, med)
    };
    let (b3, med3) = frac_biased(1e-3);
    let (b5, med5) = frac_biased(1e-5);
    println!("share of lines overestimated > 2x: rel 1e-3: {b3:.3}, rel 1e-5: {b5:.3}; away medians {med3:.2} {med5:.2}");
    assert!(b5 > b3, "{b5} vs {b3}");
    assert!((0.8..1.25).contains(&med5), "{med5}");
}

#[test]
fn uneven_lines_use_divided_differences() {
    // Log-spaced lines 2 .. 1000 Hz: the coefficients follow the actual frequencies.
    let n = 2000;
    let f: Vec<f64> = (0..n)
        .map(|k| 2.0 * (500f64).powf(k as f64 / (n - 1) as f64))
        .collect();
    let truth = response(&nominal(), &f);
    let noisy = add_noise(&f, &truth, REL, 3);
    let true_var = noisy.variances().unwrap().to_vec();
    let data = noisy.with_variance(None).unwrap();
    let nl = estimate_noise(&data, &NoiseConfig::default()).unwrap();
    let m = NY * NU;
    let mut away = Vec::new();
    for (k, &fk) in f.iter().enumerate() {
        if fk > 5.0 && rel_distance_to_mode(fk) > 0.1 {
            for e in 0..m {
                away.push(nl.variance[k * m + e] / true_var[k * m + e]);
            }
        }
    }
    let (med, within) = ratio_stats(&mut away);
    println!(
        "log-spaced lines: median ratio {med:.3}, {:.1} % within 1.5x",
        100.0 * within
    );
    assert!((0.85..1.15).contains(&med), "{med}");
    assert!(within > 0.85, "{within}");
}

#[test]
fn noise_peak_narrower_than_the_window_is_followed() {
    // A noise level 30 times higher over 9 lines (as at a lightly damped mode under
    // feedback): the short-window estimate takes over there.
    let f = freqs();
    let truth = response(&nominal(), &f);
    let noisy = add_noise(&f, &truth, REL, 11);
    let m = NY * NU;
    let mut values = noisy.values().to_vec();
    let mut var = noisy.variances().unwrap().to_vec();
    let clean = truth.values.clone();
    for k in 996..1005 {
        for e in 0..m {
            let i = k * m + e;
            values[i] = clean[i] + (values[i] - clean[i]) * 30f64.sqrt();
            var[i] *= 30.0;
        }
    }
    let data = Frf::new(f.clone(), NY, NU, values, None).unwrap();
    let nl = noise_level(&data).unwrap();
    let mut r: Vec<f64> = (998..1003)
        .flat_map(|k| (0..m).map(move |e| k * m + e))
        .map(|i| nl.variance[i] / var[i])
        .collect();
    let (med, _) = ratio_stats(&mut r);
    println!("inside the noise peak: median ratio {med:.2}");
    assert!(med > 0.4, "the peak is missed: {med}");
}

#[test]
fn too_few_lines_and_bad_config() {
    let f = vec![1.0, 2.0, 3.0, 4.0];
    let g = response(&nominal(), &f);
    let data = Frf::from_grid(f, g).unwrap();
    match estimate_noise(&data, &NoiseConfig::default()) {
        Err(ValidationError::TooFewLines { needed, got, .. }) => {
            assert_eq!((needed, got), (5, 4))
        }
        other => panic!("{other:?}"),
    }
    let e = noise_level(&data).unwrap_err();
    assert!(e.to_string().contains("at least 5 frequency lines"), "{e}");
    let cfg = NoiseConfig {
        order: 2,
        half_window: 3,
    };
    let nl = estimate_noise(&data, &cfg).unwrap();
    assert_eq!(nl.variance.len(), 4 * NY * NU);
    assert!(nl.variance.iter().all(|v| v.is_finite() && *v >= 0.0));
    for bad in [
        NoiseConfig {
            order: 0,
            half_window: 3,
        },
        NoiseConfig {
            order: 9,
            half_window: 3,
        },
        NoiseConfig {
            order: 2,
            half_window: 0,
        },
    ] {
        let e = estimate_noise(&data, &bad).unwrap_err();
        assert!(matches!(e, ValidationError::InvalidConfig { .. }), "{e}");
    }
}
