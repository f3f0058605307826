//! Estimator consistency on random additive systems with exact answers: noise-free data
//! are recovered to near machine precision from a start within 2% of the true mode
//! frequencies, and with noise the error shrinks as the noise shrinks.

mod common;

use additive_riv::{fit_numerators, AdditiveRiv, Domain, FitData, IvMethod, RivConfig, StepSolver};
use common::*;
use frf_data::Weighting;
use proptest::prelude::*;

fn fit(
    case: &Case,
    data: &frf_data::Frf,
    start_seed: u64,
    cfg: &RivConfig,
) -> additive_riv::AdditiveModel {
    let fd = FitData::new(data, &cfg.weighting).unwrap();
    let mut start = perturbed_start(case, 0.02, start_seed);
    fit_numerators(&mut start, &fd).unwrap();
    let f = AdditiveRiv::new(cfg.clone()).refine(start, &fd).unwrap();
    assert!(
        f.convergence.is_converged(),
        "{:?} after {} iterations, costs {:?}",
        f.convergence,
        f.iterations,
        f.cost_history
    );
    f.model
}

#[test]
fn noise_free_recovery_small() {
    let case = random_case(1, 2, 2, 3, true, Domain::Continuous);
    let data = simulate(&case.truth, &case.freqs, 0.0, 1);
    let cfg = RivConfig {
        weighting: Weighting::InverseMagnitude,
        ..Default::default()
    };
    let m = fit(&case, &data, 1, &cfg);
    let err = max_rel_param_error(&m, &case.truth);
    eprintln!("noise-free small: rel err {err:e}");
    assert!(err < 1e-8, "relative parameter error {err:e}");
}

#[test]
fn structured_and_dense_steps_agree() {
    let case = random_case(5, 2, 3, 2, true, Domain::Continuous);
    let data = simulate(&case.truth, &case.freqs, 0.01, 5);
    for method in [IvMethod::Riv, IvMethod::Sk] {
        let fd = FitData::new(&data, &Weighting::Auto).unwrap();
        let mut start = perturbed_start(&case, 0.02, 3);
        fit_numerators(&mut start, &fd).unwrap();
        let cfg_s = RivConfig {
            method,
            max_iterations: 3,
            param_tol: 0.0,
            cost_tol: 0.0,
            backtracking: false,
            ..Default::default()
        };
        let cfg_d = RivConfig {
            solver: StepSolver::Dense,
            ..cfg_s.clone()
        };
        let a = AdditiveRiv::new(cfg_s).refine(start.clone(), &fd).unwrap();
        let b = AdditiveRiv::new(cfg_d).refine(start, &fd).unwrap();
        let err = max_rel_param_error(&a.model, &b.model);
        assert!(
            err < 1e-9,
            "{method:?}: structured vs dense differ by {err:e}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]

    #[test]
    fn noise_free_data_recovered(seed in 0u64..10_000, ny in 1usize..=3, nu in 1usize..=3,
                                  n_modes in 1usize..=4, rigid in any::<bool>(), zoh in any::<bool>()) {
        let domain = if zoh { Domain::ZohDiscrete { ts: 1.0 / 2000.0 } } else { Domain::Continuous };
        let case = random_case(seed, ny, nu, n_modes, rigid, domain);
        let data = simulate(&case.truth, &case.freqs, 0.0, seed);
        let cfg = RivConfig { weighting: Weighting::InverseMagnitude, ..Default::default() };
        let m = fit(&case, &data, seed, &cfg);
        let err = max_rel_param_error(&m, &case.truth);
        prop_assert!(err < 1e-8, "relative parameter error {:e}", err);
    }
}

/// With noise, the parameter error shrinks with the noise level (checked at three
/// levels, averaged over seeds): the estimator is consistent.
#[test]
fn error_shrinks_with_noise() {
    let levels = [1e-2, 1e-3, 1e-4];
    let mut errs = Vec::new();
    for &lvl in &levels {
        let mut acc = 0.0;
        for seed in 0..6u64 {
            let case = random_case(100 + seed, 2, 2, 3, seed % 2 == 0, Domain::Continuous);
            let data = simulate(&case.truth, &case.freqs, lvl, 7 + seed);
            let cfg = RivConfig::default(); // inverse variance: the data carry it
            let m = fit(&case, &data, seed, &cfg);
            acc += max_rel_param_error(&m, &case.truth);
        }
        errs.push(acc / 6.0);
    }
    eprintln!("mean relative parameter error at noise {levels:?}: {errs:?}");
    for w in errs.windows(2) {
        assert!(
            w[1] < w[0] / 3.0,
            "error did not shrink with the noise: {errs:?}"
        );
    }
}

/// A first-order actuator factor on one input column and a delay, both fitted as shared
/// parameters, are recovered from noise-free data.
#[test]
fn dynamics_factor_and_delay_recovered() {
    use additive_riv::{DynamicsFactor, FactorTarget, KnownFactor};
    use frf_data::ModelStructure;
    for (seed, target) in [
        (11u64, FactorTarget::Input(1)),
        (12, FactorTarget::Output(0)),
        (13, FactorTarget::All),
    ] {
        let case = random_case(seed, 2, 3, 3, true, Domain::Continuous);
        let mut truth = case
            .truth
            .clone()
            .with_factor(KnownFactor {
                delay_s: 3e-4,
                fit_delay: true,
                ..Default::default()
            })
            .unwrap();
        truth
            .push_dynamics(DynamicsFactor::first_order(target, 150.0))
            .unwrap();
        let data = simulate(&truth, &case.freqs, 0.0, seed);
        let fd = FitData::new(&data, &Weighting::InverseMagnitude).unwrap();
        let mut start = perturbed_start(&case, 0.01, seed)
            .with_factor(KnownFactor {
                delay_s: 2.5e-4,
                fit_delay: true,
                ..Default::default()
            })
            .unwrap();
        start
            .push_dynamics(DynamicsFactor::first_order(target, 120.0))
            .unwrap();
        fit_numerators(&mut start, &fd).unwrap();
        let f = AdditiveRiv::new(RivConfig::default())
            .refine(start, &fd)
            .unwrap();
        assert!(
            f.convergence.is_converged(),
            "{target:?}: {:?}",
            f.convergence
        );
        let (p, q) = (f.model.params(), truth.params());
        let n = p.len();
        // delay and the factor coefficient are the last two parameters
        assert!(
            (p[n - 2] - q[n - 2]).abs() < 1e-12,
            "{target:?}: delay {} vs {}",
            p[n - 2],
            q[n - 2]
        );
        assert!(
            (p[n - 1] / q[n - 1] - 1.0).abs() < 1e-8,
            "{target:?}: factor {} vs {}",
            p[n - 1],
            q[n - 1]
        );
        assert!(max_rel_param_error(&f.model, &truth) < 1e-8);
    }
}

/// A crosstalk that bypasses the delay is recovered together with the delay.
#[test]
fn bypass_feedthrough_with_fitted_delay_recovered() {
    use additive_riv::KnownFactor;
    use frf_data::ModelStructure;
    let case = random_case(21, 2, 2, 3, true, Domain::ZohDiscrete { ts: 1.0 / 2000.0 });
    let mut truth = case
        .truth
        .clone()
        .with_factor(KnownFactor {
            delay_s: 5e-4,
            fit_delay: true,
            ..Default::default()
        })
        .unwrap();
    let i = truth.push_bypass_feedthrough().unwrap();
    for j in 0..2 {
        for r in 0..2 {
            truth.submodels[i].num[0][(r, j)] = 1e-2 * (1.0 + r as f64 - j as f64);
        }
    }
    let data = simulate(&truth, &case.freqs, 0.0, 21);
    let fd = FitData::new(&data, &Weighting::InverseMagnitude).unwrap();
    let mut start = perturbed_start(&case, 0.01, 21)
        .with_factor(KnownFactor {
            delay_s: 4.7e-4,
            fit_delay: true,
            ..Default::default()
        })
        .unwrap();
    start.push_bypass_feedthrough().unwrap();
    fit_numerators(&mut start, &fd).unwrap();
    let f = AdditiveRiv::new(RivConfig::default())
        .refine(start, &fd)
        .unwrap();
    assert!(f.convergence.is_converged(), "{:?}", f.convergence);
    let (p, q) = (f.model.params(), truth.params());
    let n = p.len();
    assert!(
        (p[n - 1] - q[n - 1]).abs() < 1e-12,
        "delay {} vs {}",
        p[n - 1],
        q[n - 1]
    );
    assert!(max_rel_param_error(&f.model, &truth) < 1e-8);
}
