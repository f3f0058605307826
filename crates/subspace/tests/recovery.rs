//! Random stable MIMO systems (1-3 outputs and inputs, 1-4 lightly damped modes, with
//! or without a free rigid body, continuous or through an exact zero-order hold) are
//! recovered from noise-free data to near machine precision, the error falls with the
//! noise, and bad input gets a clear error.

use faer::Mat;
use frf_data::{DelayChoice, Frf, FrfDataset, Weighting};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::{FrfModel, Hold, ModalModel, PolePair};
use std::f64::consts::TAU;
use subspace::{OrderRule, SubspaceConfig, SubspaceError, SubspaceInit};

fn system(seed: u64, hold: bool, rigid: bool) -> FrfModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ny = rng.random_range(1..=3);
    let nu = rng.random_range(1..=3);
    let n_modes = rng.random_range(1..=4);
    let mut m = ModalModel::new(ny, nu);
    if rigid {
        let c: Vec<f64> = (0..ny).map(|_| rng.random_range(0.5..1.5)).collect();
        let b: Vec<f64> = (0..nu).map(|_| rng.random_range(0.5..1.5)).collect();
        m.rigid = vec![Mat::zeros(ny, nu), Mat::from_fn(ny, nu, |i, j| c[i] * b[j])];
    }
    let mut f = 40.0 * rng.random_range(1.0..1.3);
    for _ in 0..n_modes {
        let zeta = rng.random_range(0.005..0.04);
        let c: Vec<f64> = (0..ny).map(|_| rng.random_range(-1.0..1.0)).collect();
        let b: Vec<f64> = (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect();
        let num = Mat::from_fn(ny, nu, |i, j| (c[i] * b[j] + 0.05) * (TAU * f).powi(2));
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
        f *= rng.random_range(1.4..1.8);
    }
    let mut fm = FrfModel::new(m);
    if hold {
        fm.factors.hold = Hold::Zoh { fs_hz: 4000.0 };
    }
    fm
}

fn data(truth: &FrfModel, lines: usize, noise: f64, seed: u64) -> Frf {
    let f: Vec<f64> = (0..lines)
        .map(|k| 10.0 + 990.0 * k as f64 / (lines - 1) as f64)
        .collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let g = truth.freq_response(&w).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let mut vals = g.values.clone();
    let mut var = Vec::with_capacity(vals.len());
    for v in vals.iter_mut() {
        let s = noise * v.norm();
        // uniform with variance s^2 / 2 per part
        let a = s * 3f64.sqrt() / 2f64.sqrt();
        if a > 0.0 {
            *v += frf_data::C64::new(rng.random_range(-a..a), rng.random_range(-a..a));
        }
        var.push((s * s).max(1e-300));
    }
    let frf = Frf::new(f, truth.ny(), truth.nu(), vals, None).unwrap();
    if noise > 0.0 {
        frf.with_variance(Some(var)).unwrap()
    } else {
        frf
    }
}

fn config(truth: &FrfModel) -> SubspaceConfig {
    SubspaceConfig {
        hold: truth.factors.hold,
        delay: DelayChoice::None,
        ..Default::default()
    }
}

fn error(model: &FrfModel, truth: &FrfModel, d: &Frf) -> f64 {
    let w = d.omegas();
    let g = truth.freq_response(&w).unwrap();
    model.relative_error(&w, &g).unwrap().0
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, ..ProptestConfig::default() })]

    #[test]
    fn noise_free_systems_are_recovered(seed in 0u64..100_000, hold in any::<bool>(), rigid in any::<bool>()) {
        faer::set_global_parallelism(faer::Par::Seq);
        let truth = system(seed, hold, rigid);
        let d = data(&truth, 400, 0.0, seed);
        let id = SubspaceInit::new(config(&truth)).identify(&d).unwrap();
        let e = error(&id.model, &truth, &d);
        let n_true = 2 * truth.modal.pairs.len() + if rigid { 2 * truth.ny().min(truth.nu()).min(1) } else { 0 };
        prop_assert!(e < 1e-8, "seed {seed} hold {hold} rigid {rigid}: median error {e:.3e}, order {} ({}), true {n_true}", id.report.order, id.report.order_rule);
        prop_assert_eq!(id.model.modal.pairs.len(), truth.modal.pairs.len());
        prop_assert_eq!(id.model.modal.rigid.is_empty(), !rigid);
        // the state space itself reproduces the data with the factor divided out
        let w = d.omegas();
        let g_ss = match truth.factors.hold {
            Hold::Zoh { .. } => id.state_space.freq_response(&w).unwrap(),
            _ => id.state_space.freq_response(&w).unwrap(),
        };
        let g = truth.freq_response(&w).unwrap();
        let mut rel: Vec<f64> = g_ss.values.iter().zip(&g.values).map(|(a, b)| (a - b).norm() / b.norm()).collect();
        rel.sort_by(|a, b| a.total_cmp(b));
        let med = rel[rel.len() / 2];
        prop_assert!(med < 1e-7, "state space median error {med:.3e}");
    }
}

/// Median (over 3 noise realisations) error at relative noise 1e-3, 1e-4, 1e-5.
fn errors(seed: u64, hold: bool, rigid: bool) -> [f64; 3] {
    faer::set_global_parallelism(faer::Par::Seq);
    let truth = system(seed, hold, rigid);
    let run = |noise: f64| -> f64 {
        let mut e: Vec<f64> = (0..3)
            .map(|r| {
                let d = data(&truth, 600, noise, seed * 100 + r);
                let id = SubspaceInit::new(config(&truth)).identify(&d).unwrap();
                error(&id.model, &truth, &d)
            })
            .collect();
        e.sort_by(|a, b| a.total_cmp(b));
        e[1]
    };
    let e = [run(1e-3), run(1e-4), run(1e-5)];
    println!(
        "seed {seed} hold {hold} rigid {rigid}: noise 1e-3 -> {:.3e}, 1e-4 -> {:.3e}, 1e-5 -> {:.3e}",
        e[0], e[1], e[2]
    );
    e
}

fn error_falls(seed: u64, hold: bool, rigid: bool) {
    let [e3, e4, e5] = errors(seed, hold, rigid);
    assert!(e3 / e4 >= 5.0, "seed {seed}: {e3:.3e} -> {e4:.3e}");
    assert!(e4 / e5 >= 5.0, "seed {seed}: {e4:.3e} -> {e5:.3e}");
}

#[test]
fn the_error_falls_with_the_noise_through_the_hold() {
    error_falls(3, true, true);
}

/// These systems failed before the merged poles were chosen by the residue refit and the
/// rigid-body integrators were F-tested, with passes on the flexible part (seed 29:
/// 5.4e-5 -> 7.6e-5 -> 2.7e-5, a weak rigid body never found and a rank-2 residue's
/// pole moved by the plain mean of its split eigenvalues; seed 21 5.8e-5 -> 2.4e-5 ->
/// 6.7e-7, the plain mean; seed 17 5.5e-5 -> 2.0e-5 -> 3.7e-7, one state of a double
/// integrator; seeds 95102 and 72253 (random, through the hold) 6.0e-5 -> 3.4e-5 ->
/// 3.9e-6 and 3.6e-5 -> 1.2e-5 -> 5.7e-6, the rigid body subtracted once was not
/// enough).
#[test]
fn the_error_falls_with_the_noise_on_more_systems() {
    error_falls(29, true, true);
    error_falls(21, false, false);
    error_falls(17, false, true);
    error_falls(95102, true, true);
    error_falls(72253, true, true);
}

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(6), ..ProptestConfig::default() })]

    /// The error falls with the noise on random systems: at least 5x per decade of
    /// noise from 1e-3 to 1e-5 (the estimate is consistent, so the error is
    /// proportional to the noise once the structure is found).
    #[test]
    #[ignore = "fails on seed 59664 (2 x 2 through the hold, no rigid body): median error 2.7e-4 -> 1.0e-5 -> 2.1e-6 for noise 1e-3 -> 1e-4 -> 1e-5; at 1e-5 the subspace poles of its lowest mode (40 Hz, rank-2 residue, split by the noise) stay 2.4e-5 relative off and the residue refit ends at 13 to 26 times the noise cost: the subspace estimate is not efficient there, a pole refinement (riv/ml in the chain) is. On other random seeds the ratio is marginal: seed 99836 (hold) 5.2e-5 -> 4.5e-6 -> 9.4e-7 (4.8x), seed 99447 (hold) 4.4e-5 -> 9.4e-6 -> 4.8e-7 (4.7x); one run of 100 cases passed, another failed after 41 (run with PROPTEST_CASES=100 --ignored)"]
    fn known_failure_the_error_falls_with_the_noise(seed in 0u64..100_000, hold in any::<bool>(), rigid in any::<bool>()) {
        let [e3, e4, e5] = errors(seed, hold, rigid);
        prop_assert!(e3 / e4 >= 5.0 && e4 / e5 >= 5.0, "seed {seed} hold {hold} rigid {rigid}: {e3:.3e} -> {e4:.3e} -> {e5:.3e}");
    }
}

/// Without a rigid body: a weak double integrator below the band (1/s^2 some 2000 times
/// below the modes at the lowest line) is projected away to roundoff level in the
/// unweighted variant (poles outside the arc of the lines are nearly polynomial on it),
/// so the unweighted fit misses it; the weighted variant (the default) finds it.
#[test]
fn unweighted_variant_recovers_too() {
    faer::set_global_parallelism(faer::Par::Seq);
    let truth = system(11, false, false);
    let d = data(&truth, 300, 0.0, 11);
    let cfg = SubspaceConfig {
        weighting: Weighting::Uniform,
        ..config(&truth)
    };
    let id = SubspaceInit::new(cfg).identify(&d).unwrap();
    assert!(!id.report.noise_weighted);
    let e = error(&id.model, &truth, &d);
    assert!(e < 1e-8, "median error {e:.3e}");
}

#[test]
fn order_above_the_data_support_is_an_error() {
    let truth = system(5, true, false);
    let d = data(&truth, 300, 0.0, 5);
    let n = 2 * truth.modal.pairs.len() + 20;
    let cfg = SubspaceConfig {
        order: Some(n),
        ..config(&truth)
    };
    let e = SubspaceInit::new(cfg).identify(&d).unwrap_err();
    assert!(
        matches!(e, SubspaceError::OrderExceedsRank { order, rank, .. } if order == n && rank < n),
        "{e}"
    );
    assert!(e.to_string().contains("exceeds the numerical rank"), "{e}");
}

#[test]
fn too_few_lines_is_an_error() {
    let truth = system(5, false, false);
    let d = data(&truth, 6, 0.0, 5);
    let e = SubspaceInit::new(config(&truth)).identify(&d).unwrap_err();
    assert!(
        matches!(e, SubspaceError::TooFewLines { lines: 6, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("too few lines: 6 lines"), "{e}");
    let one = data(&truth, 2, 0.0, 5);
    let e = SubspaceInit::new(SubspaceConfig {
        order: Some(2),
        ..config(&truth)
    })
    .identify(&one)
    .unwrap_err();
    assert!(matches!(e, SubspaceError::TooFewLines { .. }), "{e}");
}

#[test]
fn bad_settings_are_named() {
    let truth = system(5, false, false);
    let d = data(&truth, 100, 0.0, 5);
    for (cfg, says) in [
        (
            SubspaceConfig {
                order: Some(0),
                ..config(&truth)
            },
            "order",
        ),
        (
            SubspaceConfig {
                block_rows: Some(1),
                ..config(&truth)
            },
            "block rows",
        ),
        (
            SubspaceConfig {
                hold: Hold::Zoh { fs_hz: 1000.0 },
                ..config(&truth)
            },
            "hold sample rate",
        ),
        (
            SubspaceConfig {
                order_alpha: 0.7,
                ..config(&truth)
            },
            "order_alpha",
        ),
        (
            SubspaceConfig {
                order_min_f: f64::NAN,
                ..config(&truth)
            },
            "order_min_f",
        ),
    ] {
        let e = SubspaceInit::new(cfg).identify(&d).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
}

/// The minimal order of [`system`]: a mode's residue `c b^T + 0.05` has rank
/// `min(2, ny, nu)`, the rigid body `1/s^2` of rank one two states.
fn true_order(truth: &FrfModel) -> usize {
    let rank = truth.ny().min(truth.nu()).min(2);
    2 * rank * truth.modal.pairs.len() + if truth.modal.rigid.is_empty() { 0 } else { 2 }
}

fn f_test_config(truth: &FrfModel) -> SubspaceConfig {
    SubspaceConfig {
        order_rule: OrderRule::FTest,
        ..config(truth)
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(8), ..ProptestConfig::default() })]

    /// The F-test order rule chooses the true order on noise-free data (the sweep stops
    /// at the exact fit), on systems with rank-1 residues (one output or one input; no
    /// rigid body). With rank-2 residues it does not (see `OrderRule::FTest`): the sweep
    /// compares currency refits with full residue matrices, and at orders where a
    /// mode's two eigenvalues are split by more than the merge tolerance the currency
    /// holds them as two modes and fits as well (seed 7734: order 15 with 7 pairs for 4
    /// modes, cost 5.6e-24).
    #[test]
    fn the_f_test_chooses_the_true_order(seed in 0u64..100_000, hold in any::<bool>()) {
        f_test_order(seed, hold, 0.0)?;
    }

    /// The same with a relative noise of 1e-4 and its variance (without the
    /// practical-significance floor `order_min_f` the sweep kept spurious states here:
    /// seed 33525, true order 6, kept 8 with F = 9.9 and ended at 13).
    #[test]
    fn the_f_test_chooses_the_true_order_with_noise(seed in 0u64..100_000, hold in any::<bool>()) {
        f_test_order(seed, hold, 1e-4)?;
    }
}

fn f_test_order(seed: u64, hold: bool, noise: f64) -> Result<(), TestCaseError> {
    faer::set_global_parallelism(faer::Par::Seq);
    let truth = system(seed, hold, false);
    prop_assume!(truth.ny().min(truth.nu()) == 1);
    let n_true = true_order(&truth);
    let d = data(&truth, if noise > 0.0 { 600 } else { 400 }, noise, seed);
    let id = SubspaceInit::new(f_test_config(&truth))
        .identify(&d)
        .unwrap();
    let r = &id.report;
    let what = format!(
        "noise {noise:.0e}: order {} ({}), true {n_true}, {:?}",
        r.order, r.order_rule, r.order_sweep
    );
    prop_assert_eq!(r.order, n_true, "{}", what);
    prop_assert_eq!(
        id.model.modal.pairs.len(),
        truth.modal.pairs.len(),
        "{}",
        what
    );
    prop_assert!(r.order_rule.starts_with("F test"), "{}", what);
    prop_assert!(id
        .messages
        .iter()
        .any(|m| m.starts_with("singular values s_1..")));
    prop_assert!(id.messages.iter().any(|m| m.starts_with("order F test:")));
    let e = error(&id.model, &truth, &d);
    prop_assert!(
        e < if noise == 0.0 { 1e-8 } else { 3e-5 },
        "error {e:.3e}; {}",
        what
    );
    Ok(())
}

/// With a rigid body the F-test order rule and the default both give the modes and the
/// integrators, and the report names the rule.
#[test]
fn the_f_test_reports_its_decision() {
    faer::set_global_parallelism(faer::Par::Seq);
    let truth = system(17, false, true);
    let d = data(&truth, 600, 1e-5, 1700);
    for cfg in [f_test_config(&truth), config(&truth)] {
        let rule = cfg.order_rule;
        let id = SubspaceInit::new(cfg).identify(&d).unwrap();
        println!(
            "{rule:?}: order {} ({}); {:?}",
            id.report.order, id.report.order_rule, id.messages
        );
        assert_eq!(id.model.modal.pairs.len(), truth.modal.pairs.len());
        assert_eq!(id.report.integrators, 2);
        assert!(error(&id.model, &truth, &d) < 3e-6);
        if rule == OrderRule::FTest {
            assert!(
                id.report.order_rule.starts_with("F test"),
                "{}",
                id.report.order_rule
            );
            // 3 x 3 with a rank-2 residue: one eigenvalue of the mode is enough for the
            // currency, the rigid body needs its two states
            let o = id.report.order;
            assert!((4..=true_order(&truth)).contains(&o), "order {o}");
        }
    }
}

/// A delay started a few us off the truth (as an estimate would be) is refined inside
/// the initialiser: with the subspace poles fixed the residue refit's cost is minimised
/// over the delay, the subspace step repeated with the refined delay divided out. On
/// noise-free data the delay and the response are recovered to roundoff. Through an
/// exact zero-order hold (the wafer stage's case): without a hold, the continuous state
/// space of the bilinear fit absorbs a delay error of a few us almost exactly (seed 11
/// continuous: cost 9e-15 at 2.5 us off), so the delay is barely identifiable there.
#[test]
fn a_delay_started_off_is_refined_to_the_truth() {
    faer::set_global_parallelism(faer::Par::Seq);
    for (seed, hold, off_us) in [(3u64, true, 3.0), (11, true, -2.5), (42, true, 4.0)] {
        let mut truth = system(seed, hold, false);
        let tau = 100e-6;
        truth.factors.delay_s = tau;
        let d = data(&truth, 400, 0.0, seed);
        let start = tau + off_us * 1e-6;
        let cfg = SubspaceConfig {
            delay: DelayChoice::Start { seconds: start },
            ..config(&truth)
        };
        let id = SubspaceInit::new(cfg).identify(&d).unwrap();
        let refinement = id.report.delay_refinement.clone().unwrap();
        for m in &id.messages {
            println!("  {m}");
        }
        let e = error(&id.model, &truth, &d);
        println!(
            "seed {seed} hold {hold}: start {:.4} us, refined {:.9} us, {} passes, chosen {}, median error {e:.3e}",
            start * 1e6,
            id.model.factors.delay_s * 1e6,
            refinement.passes.len(),
            refinement.chosen_pass
        );
        assert!(id.model.factors.delay_fitted);
        assert_eq!(refinement.start_s, start);
        assert_eq!(refinement.refined_s, id.model.factors.delay_s);
        assert!(
            (id.model.factors.delay_s - tau).abs() < 1e-12,
            "seed {seed}: refined delay {:.6e} s, truth {tau:.6e} s",
            id.model.factors.delay_s
        );
        assert!(e < 1e-9, "seed {seed}: median error {e:.3e}");
        assert!(refinement.passes.len() >= 2, "the subspace step ran again");
        // without the refinement the delay stays where it started, and the model is poor
        let cfg = SubspaceConfig {
            delay: DelayChoice::Start { seconds: start },
            refine_delay: false,
            ..config(&truth)
        };
        let id = SubspaceInit::new(cfg).identify(&d).unwrap();
        assert!(id.report.delay_refinement.is_none());
        assert_eq!(id.model.factors.delay_s, start);
        assert!(error(&id.model, &truth, &d) > 1e-6);
    }
}

/// The seeds on which the F test kept a state too many before the candidate poles were
/// refined (`subspace::pole_refine`): at 1e-4 noise a spurious real pole (seed 60795,
/// order 9 for 8, F = 33.6) and a spurious mode (seed 30976, order 6 for 4, F = 49.9)
/// absorbed the misfit of the subspace poles; noise-free, seed 97124 (through the
/// hold), where a failed refinement must fall back to the subspace poles.
#[test]
fn the_f_test_keeps_no_state_that_absorbs_the_misfit_of_subspace_poles() {
    for (seed, hold, noise) in [
        (60795u64, true, 1e-4),
        (30976, true, 1e-4),
        (97124, true, 0.0),
    ] {
        if let Err(e) = f_test_order(seed, hold, noise) {
            panic!("seed {seed}, hold {hold}, noise {noise:.0e}: {e}");
        }
    }
}
