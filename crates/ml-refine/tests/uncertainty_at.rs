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
