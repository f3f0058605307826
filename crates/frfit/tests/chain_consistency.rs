//! Consistency of every registered estimator chain, through the chain traits only
//! (`frfit::chain::run_chain`): random stable MIMO systems (1-4 outputs and inputs,
//! 1-8 well-separated lightly damped modes (1-6 in most tests, 7-8 in their own), with or without a free rigid body, in
//! continuous time or through an exact zero-order hold) are recovered from noise-free
//! data to 1e-8 relative, and with noise the error against the truth falls with the
//! noise and with the lines. A method that joins the registry joins this test by its
//! name alone: every chain runs in the tests that always run except the known failure
//! (the `cmif` chains in the noise-free property, about 0.2 % of the systems), which
//! runs in an `#[ignore]`d test whose reason gives the numbers.

use faer::Mat;
use frf_data::{ChainSettings, DelayChoice, Frf, FrfDataset, ModelStructure};
use frfit::chain::{run_chain, AdditiveOptions, INITIALIZERS, REFINERS};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use realize::{FrfModel, Hold, ModalModel, PolePair};
use std::f64::consts::TAU;

/// How many modes a random system has and how they are spread.
#[derive(Clone, Copy)]
struct Spread {
    /// Fewest and most modes (inclusive).
    modes: (usize, usize),
    /// Range of the ratio of neighbouring mode frequencies.
    ratio: (f64, f64),
    /// No mode above this, Hz.
    top_hz: f64,
}

/// 1-6 modes, 1.4-1.8 apart, up to 700 Hz: the systems of the seeds the tests name.
const FEW_MODES: Spread = Spread {
    modes: (1, 6),
    ratio: (1.4, 1.8),
    top_hz: 700.0,
};

/// 7 or 8 modes, 1.25-1.4 apart (still separated by many half-power bandwidths), up to
/// 900 Hz: the many-mode end of the 1-8 modes the harness covers.
const MANY_MODES: Spread = Spread {
    modes: (7, 8),
    ratio: (1.25, 1.4),
    top_hz: 900.0,
};

/// A random stable system (seeded) of [`FEW_MODES`].
fn system(seed: u64, hold: bool) -> FrfModel {
    spread_system(seed, hold, FEW_MODES)
}

/// A random stable system (seeded) with its modes spread as `sp` says.
fn spread_system(seed: u64, hold: bool, sp: Spread) -> FrfModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ny = rng.random_range(1..=4);
    let nu = rng.random_range(1..=4);
    let n_modes = rng.random_range(sp.modes.0..=sp.modes.1);
    let mut m = ModalModel::new(ny, nu);
    if rng.random_bool(0.5) {
        let c: Vec<f64> = (0..ny).map(|_| rng.random_range(0.5..1.5)).collect();
        let b: Vec<f64> = (0..nu).map(|_| rng.random_range(0.5..1.5)).collect();
        m.rigid = vec![Mat::zeros(ny, nu), Mat::from_fn(ny, nu, |i, j| c[i] * b[j])];
    }
    // log-spaced, well separated modes from 40..52 Hz up
    let mut f = 40.0 * rng.random_range(1.0..1.3);
    for _ in 0..n_modes {
        let zeta = rng.random_range(0.005..0.04);
        let c: Vec<f64> = (0..ny).map(|_| rng.random_range(-1.0..1.0)).collect();
        let b: Vec<f64> = (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect();
        let num = Mat::from_fn(ny, nu, |i, j| (c[i] * b[j] + 0.05) * (TAU * f).powi(2));
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
        f *= rng.random_range(sp.ratio.0..sp.ratio.1);
        if f > sp.top_hz {
            break;
        }
    }
    let mut fm = FrfModel::new(m);
    if hold {
        fm.factors.hold = Hold::Zoh { fs_hz: 4000.0 };
    }
    fm
}

fn data(truth: &FrfModel, lines: usize, noise: f64, seed: u64) -> Frf {
    // a uniform grid, as periodic excitation gives
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
        let e = frf_data::C64::new(
            rng.random_range(-1.0..1.0) * s * 3f64.sqrt() / 2f64.sqrt(),
            rng.random_range(-1.0..1.0) * s * 3f64.sqrt() / 2f64.sqrt(),
        );
        *v += e;
        var.push(s * s.max(1e-300));
    }
    let ny = truth.ny();
    let nu = truth.nu();
    let frf = Frf::new(f, ny, nu, vals, None).unwrap();
    if noise > 0.0 {
        frf.with_variance(Some(var)).unwrap()
    } else {
        frf
    }
}

/// Median relative error of `model` against the noise-free truth on the data's lines.
fn error(model: &FrfModel, truth: &FrfModel, data: &Frf) -> f64 {
    let w = data.omegas();
    let g = truth.freq_response(&w).unwrap();
    model.relative_error(&w, &g).unwrap().0
}

fn settings(truth: &FrfModel) -> ChainSettings {
    ChainSettings {
        hold: truth.factors.hold,
        delay: DelayChoice::None,
        ..Default::default()
    }
}

/// Initialisers whose chains fail the noise-free property below on some systems (the
/// reason is in the `#[ignore]` of the test that runs them): their chains run that
/// property only in the ignored test, every other registered chain in the one that
/// always runs.
const KNOWN_FAILING_INITS: &[&str] = &["cmif"];

/// Every registered chain whose last link refines (a chain ending in `none` keeps the
/// initialiser's rough start and is checked elsewhere): with `failing` those of the
/// initialisers in [`KNOWN_FAILING_INITS`], otherwise all the others, so that a newly
/// registered initialiser or refiner joins the tests that run.
fn chains(failing: bool) -> Vec<(&'static str, &'static str)> {
    let mut v = Vec::new();
    for i in INITIALIZERS
        .iter()
        .filter(|i| KNOWN_FAILING_INITS.contains(&i.name) == failing)
    {
        for r in REFINERS.iter().filter(|r| r.make.is_some()) {
            v.push((i.name, r.name));
        }
    }
    v
}

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// Noise-free data of the system of `seed` are recovered to 1e-8 relative (median over
/// the lines) by every chain of `chains`.
fn recovers_noise_free(
    chains: &[(&str, &str)],
    seed: u64,
    hold: bool,
) -> Result<(), TestCaseError> {
    recovers_noise_free_spread(chains, seed, hold, FEW_MODES)
}

/// [`recovers_noise_free`] on the systems of `sp`.
fn recovers_noise_free_spread(
    chains: &[(&str, &str)],
    seed: u64,
    hold: bool,
    sp: Spread,
) -> Result<(), TestCaseError> {
    let truth = spread_system(seed, hold, sp);
    let d = data(&truth, 600, 0.0, seed);
    for &(init, refine) in chains {
        let r = run_chain(
            &d,
            init,
            refine,
            &settings(&truth),
            &AdditiveOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{init}+{refine} on seed {seed}: {e}"));
        let e = error(&r.model.model, &truth, &d);
        prop_assert!(
            e < 1e-8,
            "{init}+{refine}, seed {seed}, hold {hold}: median error {e:.3e}"
        );
        prop_assert_eq!(r.model.model.n_params() > 0, true);
    }
    Ok(())
}

/// The systems of the error-falls property: seeds 3, 17 and 29 (through the hold for
/// the even ones).
const ERROR_FALLS_SEEDS: [u64; 3] = [3, 17, 29];

/// The (initialiser, refiner, seed) cases of the error-falls property: every refining
/// chain (those of [`KNOWN_FAILING_INITS`] too: their failures are on other systems) on
/// every seed of [`ERROR_FALLS_SEEDS`], so that a newly registered chain joins the test.
fn error_falls_cases() -> Vec<(&'static str, &'static str, u64)> {
    let mut v = Vec::new();
    for seed in ERROR_FALLS_SEEDS {
        for (init, refine) in chains(false).into_iter().chain(chains(true)) {
            v.push((init, refine, seed));
        }
    }
    v
}

/// Noise realisations of the lines criterion: the error of one realisation spreads by
/// a factor of 2 to 4 (seed 3, subspace+riv, 600 lines: 1.8e-5 .. 4.8e-5), so the
/// ratio of two medians of 3 realisations spread from 1.26 to 2.2 on the same chain and
/// seed; the root mean square of 12 keeps most chains within about 10 % of their
/// expectation, but not all: on seed 3 four chains fell 1.57x with 12 and pass with 48.
const LINES_REALISATIONS: u64 = 12;

/// Realisations of the lines criterion when [`LINES_REALISATIONS`] leave the ratio
/// below its bound: the criterion is then decided on this many (the first ones
/// included), whose root mean square is twice as precise.
const LINES_REALISATIONS_CONFIRM: u64 = 48;

/// For every case (initialiser, refiner, seed) of `cases`: the median error against the
/// truth (the middle of three noise realisations) falls at least 5x when the noise
/// falls 10x (1e-3 -> 1e-4, 600 lines), and the root-mean-square error over
/// [`LINES_REALISATIONS`] realisations (or [`LINES_REALISATIONS_CONFIRM`] when those
/// leave it below the bound) falls at least 1.6x with 4x the lines (600 -> 2400, noise
/// 1e-3; sqrt(4) = 2 for a consistent estimator whose error variance falls as 1 / lines).
fn error_falls(cases: &[(&str, &str, u64)]) {
    for &(init, refine, seed) in cases {
        let truth = system(seed, seed % 2 == 0);
        // realisations are independent: both cores run them
        let run = |lines: usize, noise: f64, realisations: std::ops::Range<u64>| -> Vec<f64> {
            realisations
                .into_par_iter()
                .map(|r| {
                    let d = data(&truth, lines, noise, seed * 100 + r);
                    let out = run_chain(
                        &d,
                        init,
                        refine,
                        &settings(&truth),
                        &AdditiveOptions::default(),
                    )
                    .unwrap_or_else(|e| panic!("{init}+{refine} on seed {seed}: {e}"));
                    error(&out.model.model, &truth, &d)
                })
                .collect()
        };
        let median3 = |mut errs: Vec<f64>| -> f64 {
            errs.truncate(3);
            errs.sort_by(|a, b| a.total_cmp(b));
            errs[1]
        };
        let rms = |errs: &[f64]| -> f64 {
            (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
        };
        let mut few = run(600, 1e-3, 0..LINES_REALISATIONS);
        let (e3, e4) = (median3(few.clone()), median3(run(600, 1e-4, 0..3)));
        assert!(
            e3 / e4 >= 5.0,
            "{init}+{refine} seed {seed}: noise 1e-3 -> {e3:.3e}, 1e-4 -> {e4:.3e}"
        );
        let mut many = run(2400, 1e-3, 0..LINES_REALISATIONS);
        let mut used = LINES_REALISATIONS;
        if rms(&few) / rms(&many) < 1.6 {
            // in doubt: decide on more realisations, the first ones included
            let more = LINES_REALISATIONS..LINES_REALISATIONS_CONFIRM;
            few.extend(run(600, 1e-3, more.clone()));
            many.extend(run(2400, 1e-3, more));
            used = LINES_REALISATIONS_CONFIRM;
        }
        let (r_few, r_many) = (rms(&few), rms(&many));
        println!(
            "{init}+{refine} seed {seed}: noise 1e-3 -> 1e-4: {:.2}x; 600 -> 2400 lines: {:.2}x (rms of {used})",
            e3 / e4,
            r_few / r_many
        );
        assert!(
            r_few / r_many >= 1.6,
            "{init}+{refine} seed {seed}: rms error over {used} realisations \
             600 lines {r_few:.3e}, 2400 lines {r_many:.3e}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(6), ..ProptestConfig::default() })]

    /// Every registered refining chain but those of [`KNOWN_FAILING_INITS`] recovers
    /// noise-free data.
    #[test]
    fn noise_free_data_are_recovered(seed in 0u64..10_000, hold in any::<bool>()) {
        recovers_noise_free(&chains(false), seed, hold)?;
    }

    /// The same with 7 or 8 modes ([`MANY_MODES`]). Swept over seeds 0..800, both
    /// holds: 1 of 1600 systems fails, seed 769 through the hold, for `subspace+ml`
    /// only (4.0e-6: a double integrator of F = 37 that neither the orders above the
    /// gap, 8.7x lower cost where 10x is asked, nor the passes on the flexible part,
    /// 3.8e-9 against 1.2e-9, bring into the subspace start, and the maximum-likelihood
    /// refiner keeps the start's rigid-body structure; the refined-IV refiner chooses
    /// it again, see [`refined_iv_chooses_the_rigid_body_of_another_start_again`]).
    /// Seed 6809 through the hold fails the same way for `subspace+ml` (2.1e-6; met by a
    /// random run on 2026-12-06, before and after that day's changes to the ML refiner
    /// alike): the property holds for about 999 of 1000 systems, and a run of 6 cases
    /// meets such a system about once in 100 runs.
    #[test]
    fn noise_free_data_with_7_or_8_modes_are_recovered(seed in 0u64..10_000, hold in any::<bool>()) {
        recovers_noise_free_spread(&chains(false), seed, hold, MANY_MODES)?;
    }

    /// The chains of [`KNOWN_FAILING_INITS`].
    #[test]
    #[ignore = "fails for the cmif chains on about 0.2 % of the systems: seeds 0..300, both holds, cmif+riv and cmif+ml: 4 of 1200 runs (seeds 128 and 144 through the hold, 1.2e-1 and 2.7e-2: a missing mode the completion's additions and splits do not recover; 144 leaves 76.9 and 193.8 Hz at damping 0.14 and 0.15 whose splits settle onto a neighbour), 10 of 1200 before the split trials; seeds 300..700: 2 of 1600 (663 through the hold, 3.0e-1), 4 of 1600 before; seeds 73, 170, 253, 275 that failed before pass (cmif_start_completion_recovers_missed_modes); run with --ignored"]
    fn known_failure_noise_free_data_are_recovered_by_the_cmif_chains(seed in 0u64..10_000, hold in any::<bool>()) {
        recovers_noise_free(&chains(true), seed, hold)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// The fallback the multi-initialiser chain gives: `--init auto --refine riv` (every
    /// initialiser, the smallest final prediction error kept) recovers noise-free data
    /// where the CMIF start alone does not (seeds 1-12, 1142, 1149, 1575 of the ignored
    /// property: cmif+riv 1.9e-6 .. 1.3e-1, auto+riv below 1.5e-14).
    #[test]
    fn auto_chain_recovers_noise_free_data(seed in 0u64..10_000, hold in any::<bool>()) {
        let truth = system(seed, hold);
        let d = data(&truth, 600, 0.0, seed);
        let r = run_chain(&d, "auto", "riv", &settings(&truth), &AdditiveOptions::default())
            .unwrap_or_else(|e| panic!("auto+riv on seed {seed}: {e}"));
        let e = error(&r.model.model, &truth, &d);
        prop_assert!(e < 1e-8, "auto+riv, seed {seed}, hold {hold}: median error {e:.3e}");
        prop_assert_eq!(r.runs.len(), INITIALIZERS.len());
    }
}

/// Every registered refining chain on every seed: the error falls with the noise and
/// with the lines.
#[test]
#[ignore = "slow tier (about 54 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn error_falls_with_the_noise_and_with_the_lines() {
    let cases = error_falls_cases();
    assert!(cases.iter().any(|c| c.0 == "subspace"));
    error_falls(&cases);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// The `sk` initialiser alone (`--init sk --refine none`) recovers noise-free data
    /// to 1e-8 through the chain traits, its order chosen by its sweep (the property
    /// above covers the refining chains and is ignored for `cmif`).
    #[test]
    fn sk_alone_recovers_noise_free_data(seed in 0u64..10_000, hold in any::<bool>()) {
        let truth = system(seed, hold);
        let d = data(&truth, 600, 0.0, seed);
        let r = run_chain(&d, "sk", "none", &settings(&truth), &AdditiveOptions::default())
            .unwrap_or_else(|e| panic!("sk+none on seed {seed}: {e}"));
        let e = error(&r.model.model, &truth, &d);
        prop_assert!(e < 1e-8, "sk+none, seed {seed}, hold {hold}: median error {e:.3e}");
    }
}

/// The completion of the CMIF start (`additive_riv::complete`, on by default) on the
/// systems where the plain CMIF start missed or merged modes and the refiners did not
/// recover them (found by the property above): both `cmif` chains recover the
/// noise-free data to 1e-8. Seed 5675 is a well damped mode above the others that
/// dominates the response from its resonance up, so that the eq. (27)-weighted residual
/// shows no peak there (the plain residual does); seed 16 starts from 2 of 4 modes.
/// Seeds 19, 59 and 141 need the residual scan ([`additive_riv::mode_scan`]): a mode
/// between two others that their settled poles widened to cover (19: 214 Hz between
/// 123 and 326 Hz), or that a start mode left for a mode the CMIF did not show (59).
/// Seeds 73, 170 and 275 need the split trials: one settled mode covered two true ones
/// as a broad resonance (73 through the hold: 84.8 Hz at damping 0.30 over 74.1 and
/// 104.4 Hz). Seed 253 through the hold is exact from the start: the completion adds
/// nothing to an exact fit (before, a mode at damping 0.76 was added on costs of 1e-25
/// and the refined-IV link drove it onto the negative real axis).
#[test]
fn cmif_start_completion_recovers_missed_modes() {
    for seed in [
        16u64, 19, 59, 73, 141, 170, 253, 275, 1142, 1149, 1575, 5675,
    ] {
        for hold in [false, true] {
            let truth = system(seed, hold);
            let d = data(&truth, 600, 0.0, seed);
            for refine in ["riv", "ml"] {
                let r = run_chain(
                    &d,
                    "cmif",
                    refine,
                    &settings(&truth),
                    &AdditiveOptions::default(),
                )
                .unwrap_or_else(|e| panic!("cmif+{refine} on seed {seed}: {e}"));
                let e = error(&r.model.model, &truth, &d);
                assert!(
                    e < 1e-8,
                    "cmif+{refine}, seed {seed}, hold {hold}: median error {e:.3e}"
                );
            }
        }
    }
}

/// The subspace chains on the 7-8 mode systems whose rigid body the singular values
/// missed (no variance: noise-free data), all through the hold: seed 6846 (7 rank-2
/// modes and a double integrator; the largest singular-value gap is after 24 of 30
/// states) and 9264 (one of two integrators found). The integrator test of the
/// subspace initialiser adds the rigid body when it lowers the cost tenfold. Seeds
/// 141, 289 and 657 leave the last integrator state at 3-4x the round-off floor of the
/// singular values (the orders above the gap are realised from 2.5x it); 2150 finds
/// one integrator and the second lowers the cost only 1.23x with the biased flexible
/// poles (judged after a pass on the flexible part: 6.3e-10 against 2.8e-9); 560
/// realises the double integrator as a pair at 10.9 Hz, damping 0.58, that the two
/// integrators replace. Before, they ended at 1.6e-6 .. 5.6e-6.
#[test]
fn subspace_chains_find_a_rigid_body_the_singular_values_missed() {
    let chains: Vec<_> = chains(false)
        .into_iter()
        .filter(|(i, _)| *i == "subspace")
        .collect();
    assert!(!chains.is_empty());
    for seed in [6846u64, 9264, 3711, 141, 289, 560, 657, 2150] {
        recovers_noise_free_spread(&chains, seed, true, MANY_MODES)
            .unwrap_or_else(|e| panic!("{e}"));
    }
}

/// An exact fit is not given modes at the peaks of its round-off residual: the
/// refined-IV refiner's adaptation adds none (seed 560 of the 7-8 mode systems through
/// the hold: `sk+riv` added a ninth mode, `subspace+riv` five, on costs of 1e-26 with
/// F statistics of 50 to 3000 against that residual), and the refinement at round-off
/// ends converged, not failed.
#[test]
fn an_exact_fit_gets_no_modes_from_its_round_off_residual() {
    let truth = spread_system(560, true, MANY_MODES);
    let d = data(&truth, 600, 0.0, 560);
    for init in ["sk", "subspace"] {
        let r = run_chain(
            &d,
            init,
            "riv",
            &settings(&truth),
            &AdditiveOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{init}+riv: {e}"));
        let e = error(&r.model.model, &truth, &d);
        assert!(e < 1e-8, "{init}+riv: median error {e:.3e}");
        assert_eq!(
            r.model.model.modal.pairs.len(),
            truth.modal.pairs.len(),
            "{init}+riv"
        );
        let riv = r.links.last().unwrap();
        assert!(
            !matches!(riv.convergence, frf_data::Convergence::Failed { .. }),
            "{init}+riv: {:?}",
            riv.convergence
        );
    }
}

/// The refined-IV refiner chooses the rigid body of another initialiser's start again
/// with its refined poles: on seed 769 of the 7-8 mode systems through the hold the
/// subspace start has no integrator (the double integrator's states stand at the
/// round-off level of its singular values, and its trials fall short of their
/// thresholds); `subspace+riv` ended at 4.3e-6, and now adds the two integrators
/// (cost 1.3e-9 -> 4.9e-27) and recovers the system.
#[test]
fn refined_iv_chooses_the_rigid_body_of_another_start_again() {
    let truth = spread_system(769, true, MANY_MODES);
    let d = data(&truth, 600, 0.0, 769);
    let r = run_chain(
        &d,
        "subspace",
        "riv",
        &settings(&truth),
        &AdditiveOptions::default(),
    )
    .unwrap_or_else(|e| panic!("subspace+riv: {e}"));
    let e = error(&r.model.model, &truth, &d);
    assert!(e < 1e-8, "subspace+riv: median error {e:.3e}");
    assert_eq!(r.model.model.modal.rigid.len(), 2);
    assert!(
        r.links[1]
            .messages
            .iter()
            .any(|m| m.starts_with("rigid body chosen again")),
        "{:?}",
        r.links[1].messages
    );
}
