//! `MlRefine::uncertainty_at`: the covariance of the ML criterion at a given estimate,
//! the way the chains without an ML link report their standard deviations (issue 44).
//! At the ML optimum it must reproduce the refinement's own covariance; at another
//! consistent estimate (the truth itself, standing in for a refined-IV estimate) the
//! standard deviations must be those of the optimum to first order; a model with an
//! unstable pole is refused with an error that names the mode.

mod common;
use common::*;
use frf_data::{ChainModel, Estimator};
use ml_refine::{MlError, MlRefine};
use realize::{FrfModel, PolePair};
use std::f64::consts::TAU;

#[test]
fn at_the_ml_optimum_it_reproduces_the_refinements_covariance() {
    let truth = system(11, 2, 2, 3, false, false);
    let d = data(&truth, 400, 1e-3, 5);
    let ml = MlRefine::default()
        .estimate(&d, ChainModel::from(perturbed(&truth, 0.002, 0.1, 5)))
        .unwrap();
    assert!(ml.convergence.is_converged(), "{:?}", ml.convergence);
    let at = MlRefine::default().uncertainty_at(&d, &ml.model).unwrap();
    assert_eq!(at.iterations, 0);
    assert!(!at.converged, "no iterations are run, none are claimed");
    assert_eq!(at.modes.len(), ml.report.modes.len());
    // the optimum's cost and the same information matrix: equal to rounding
    assert!(
        (at.cost / ml.report.cost - 1.0).abs() < 1e-6,
        "{} vs {}",
        at.cost,
        ml.report.cost
    );
    for (a, b) in at.modes.iter().zip(&ml.report.modes) {
        assert!(
            (a.f_hz_std / b.f_hz_std - 1.0).abs() < 1e-4,
            "{a:?} vs {b:?}"
        );
        assert!(
            (a.zeta_std / b.zeta_std - 1.0).abs() < 1e-4,
            "{a:?} vs {b:?}"
        );
    }
    // at the truth (another consistent estimate, a distance of the order of one standard
    // deviation away) the linearisation gives the same standard deviations to first order
    let at_truth = MlRefine::default().uncertainty_at(&d, &truth).unwrap();
    for (a, b) in at_truth.modes.iter().zip(&ml.report.modes) {
        assert!(
            (a.f_hz_std / b.f_hz_std - 1.0).abs() < 0.05,
            "{a:?} vs {b:?}"
        );
        assert!(
            (a.zeta_std / b.zeta_std - 1.0).abs() < 0.05,
            "{a:?} vs {b:?}"
        );
    }
    // the cost test sees data at their noise level at the truth too
    assert!(
        at_truth.p_value.unwrap() > 1e-3,
        "cost ratio {} (expected {})",
        at_truth.cost_ratio,
        at_truth.expected_ratio
    );
}

#[test]
fn an_unstable_pole_is_refused_with_its_mode_named() {
    let truth = system(11, 2, 2, 3, false, false);
    let d = data(&truth, 400, 1e-3, 6);
    let mut bad: FrfModel = truth.clone();
    let p = &mut bad.modal.pairs[1];
    *p = PolePair::from_f_zeta(p.f_hz(), -0.01, p.residue.clone());
    match MlRefine::default().uncertainty_at(&d, &bad) {
        Err(e @ MlError::Unstable { .. }) => {
            let msg = e.to_string();
            let f = format!("mode at {:.3} Hz", truth.modal.pairs[1].f_hz());
            assert!(msg.contains(&f) && msg.contains("-1.000e-2"), "{msg}");
        }
        other => panic!("expected an unstable-pole error, got {other:?}"),
    }
}

/// The response's standard deviation (`MlRefine::response_std_at`, the band of the
/// report's plots): summed over every line and entry in units of the noise variance it
/// is the number of parameters (the trace of the hat matrix), and over noise draws the
/// spread of the fitted response around the truth matches it (pooled over lines and
/// entries, 40 draws of 400 lines x 4 entries).
#[test]
fn the_response_std_matches_the_spread_of_the_fitted_response() {
    let truth = system(11, 2, 2, 3, false, false);
    let draws = 40;
    let mut ratio_sum = 0.0;
    let mut count = 0usize;
    let (mut mid_sum, mut mid_count) = (0.0, 0usize);
    for s in 0..draws {
        let d = data(&truth, 400, 1e-3, 300 + s);
        let fit = MlRefine::default()
            .estimate(&d, ChainModel::from(perturbed(&truth, 0.002, 0.1, s)))
            .unwrap();
        assert!(fit.convergence.is_converged(), "{:?}", fit.convergence);
        let std = MlRefine::default()
            .response_std_at(&d, &fit.model, None)
            .unwrap();
        let var = d.variances().unwrap();
        assert_eq!(std.len(), var.len());
        // a subset of entries: the same values there, NaN elsewhere
        let some = MlRefine::default()
            .response_std_at(&d, &fit.model, Some(&[1, 2]))
            .unwrap();
        for (i, (a, b)) in some.iter().zip(&std).enumerate() {
            if matches!(i % 4, 1 | 2) {
                assert_eq!(a, b);
            } else {
                assert!(a.is_nan());
            }
        }
        if s == 0 {
            // the trace of the hat matrix: sum 2 w var(P) / scale = parameters
            let rep = MlRefine::default().uncertainty_at(&d, &fit.model).unwrap();
            let trace: f64 = std
                .iter()
                .zip(var)
                .map(|(sd, v)| 2.0 * sd * sd / v)
                .sum::<f64>()
                / rep.covariance_scale;
            println!("trace {trace:.6} for {} parameters", rep.n_params);
            assert!(
                (trace / rep.n_params as f64 - 1.0).abs() < 1e-6,
                "trace {trace} vs {} parameters",
                rep.n_params
            );
        }
        let omega: Vec<f64> = d.freq_hz_slice().iter().map(|f| TAU * f).collect();
        let p = fit.model.freq_response(&omega).unwrap();
        let p0 = truth.freq_response(&omega).unwrap();
        for ((a, b), sd) in p.values.iter().zip(&p0.values).zip(&std) {
            ratio_sum += (a - b).norm_sqr() / (sd * sd);
            count += 1;
        }
        // at other frequencies (the midpoints between the data's lines, as an
        // independent validation measurement would have them): the same information
        // carried to those lines; at the data's own lines it is the band above
        let own = MlRefine::default()
            .response_std_at_omegas(&d, &fit.model, &omega)
            .unwrap();
        for (a, b) in own.iter().zip(&std) {
            assert!(
                (a - b).abs() <= 1e-9 * b,
                "{a} vs {b} at the data's own lines"
            );
        }
        let mid: Vec<f64> = omega.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        let std_mid = MlRefine::default()
            .response_std_at_omegas(&d, &fit.model, &mid)
            .unwrap();
        assert_eq!(std_mid.len(), mid.len() * 4);
        let p = fit.model.freq_response(&mid).unwrap();
        let p0 = truth.freq_response(&mid).unwrap();
        for ((a, b), sd) in p.values.iter().zip(&p0.values).zip(&std_mid) {
            mid_sum += (a - b).norm_sqr() / (sd * sd);
            mid_count += 1;
        }
    }
    let ratio = ratio_sum / count as f64;
    println!("mean |P - P0|^2 / predicted variance over {count} values: {ratio:.4}");
    assert!((0.85..1.15).contains(&ratio), "{ratio}");
    let mid_ratio = mid_sum / mid_count as f64;
    println!(
        "between the lines: mean |P - P0|^2 / predicted variance over {mid_count} values: \
         {mid_ratio:.4}"
    );
    assert!((0.85..1.15).contains(&mid_ratio), "{mid_ratio}");
}

/// Frequencies that are not positive and finite are refused with the value named.
#[test]
fn the_response_std_at_bad_frequencies_is_refused() {
    let truth = system(11, 2, 2, 3, false, false);
    let d = data(&truth, 400, 1e-3, 5);
    let e = MlRefine::default()
        .response_std_at_omegas(&d, &truth, &[10.0, f64::NAN])
        .unwrap_err();
    assert!(e.to_string().contains("NaN"), "{e}");
}
