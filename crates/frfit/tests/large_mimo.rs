//! A plant with more states than the subspace initialiser's default order cap (60): a
//! random 6 x 6 modal plant with 40 rank-one modes (80 states, 10 % close pairs) from
//! `frfit simulate random-modal`'s generator. `--init subspace` finds every mode from
//! the singular values alone (the cap is doubled while all singular values up to it
//! stand above the noise), without peak picking.

use experiment::synth::{RandomModal, RandomModalConfig};
use frf_data::{ChainSettings, DelayChoice, FrfDataset};
use frfit::chain::{run_chain, AdditiveOptions};

/// Modes of `fit` within `tol` (relative) of a true one, matched one-to-one, nearest
/// first.
fn found(true_f: &[f64], fit_f: &[f64], tol: f64) -> usize {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, &t) in true_f.iter().enumerate() {
        for (j, &f) in fit_f.iter().enumerate() {
            let d = (f - t).abs() / t;
            if d <= tol {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut ut, mut uf, mut n) = (vec![false; true_f.len()], vec![false; fit_f.len()], 0);
    for (_, i, j) in pairs {
        if !ut[i] && !uf[j] {
            ut[i] = true;
            uf[j] = true;
            n += 1;
        }
    }
    n
}

/// `--init subspace --refine none` on a random 6 x 6 plant with 40 modes, 1500 lines
/// (seed 3) at relative noise `noise` (0: exact data without a variance): the modes
/// within `tol` of a true one, the modes fitted, and the median error against the
/// noiseless response.
fn subspace_on_6_by_6_with_40_modes(noise: f64, tol: f64) -> (usize, Vec<f64>, f64) {
    faer::set_global_parallelism(faer::Par::Seq);
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 6,
        nu: 6,
        modes: 40,
        lines: 1500,
        noise,
        seed: 3,
        ..RandomModalConfig::default()
    })
    .unwrap();
    assert_eq!(r.measured.variance_vec().is_none(), noise == 0.0);
    let settings = ChainSettings {
        delay: DelayChoice::None,
        ..Default::default()
    };
    let out = run_chain(
        &r.measured,
        "subspace",
        "none",
        &settings,
        &AdditiveOptions::default(),
    )
    .unwrap();
    let model = &out.model.model;
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let fit_f: Vec<f64> = model.modal.pairs.iter().map(|p| p.f_hz()).collect();
    let n = found(&true_f, &fit_f, tol);
    let w = r.noiseless.omegas();
    let g = realize::ResponseGrid {
        ny: 6,
        nu: 6,
        values: r.noiseless.values_vec(),
    };
    let (median, _) = model.relative_error(&w, &g).unwrap();
    (n, fit_f, median)
}

#[test]
fn subspace_finds_all_modes_beyond_the_default_order_cap() {
    let (n, fit_f, median) = subspace_on_6_by_6_with_40_modes(1e-4, 1e-3);
    println!(
        "{n}/40 modes within 0.1 %, {} fitted, median error {median:.3e} vs noiseless (noise 1e-4)",
        fit_f.len()
    );
    assert_eq!(n, 40, "modes found: {fit_f:?}");
    assert_eq!(fit_f.len(), 40);
    assert!(median < 1e-3, "median error {median:.3e}");
}

/// The chain at scale: `subspace -> ml` on a random 12 x 12 plant with 30 modes and a
/// rigid body at 1e-3 relative noise (with the variance). The ML refinement shares one
/// factorisation among all 144 entries (one noise level), drops the poles the subspace
/// step fitted to noise and adds back a mode it merged; every mode ends within 0.1 %,
/// the cost at the noise level, and the error against the noiseless response below
/// the subspace start's.
#[test]
fn subspace_then_ml_finds_every_mode_at_the_noise_level() {
    faer::set_global_parallelism(faer::Par::Seq);
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 12,
        nu: 12,
        modes: 30,
        lines: 1500,
        noise: 1e-3,
        rigid_body: true,
        seed: 5,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let settings = ChainSettings {
        delay: DelayChoice::None,
        ..Default::default()
    };
    let opts = AdditiveOptions::default();
    let start = run_chain(&r.measured, "subspace", "none", &settings, &opts).unwrap();
    let out = run_chain(&r.measured, "subspace", "ml", &settings, &opts).unwrap();
    let w = r.noiseless.omegas();
    let g = realize::ResponseGrid {
        ny: 12,
        nu: 12,
        values: r.noiseless.values_vec(),
    };
    let (median0, _) = start.model.model.relative_error(&w, &g).unwrap();
    let model = &out.model.model;
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let fit_f: Vec<f64> = model.modal.pairs.iter().map(|p| p.f_hz()).collect();
    let n = found(&true_f, &fit_f, 1e-3);
    let (median, _) = model.relative_error(&w, &g).unwrap();
    let last = out.links.last().unwrap();
    println!(
        "{n}/30 modes within 0.1 %, {} fitted, median error {median:.3e} vs noiseless (start {median0:.3e}, noise 1e-3); {}",
        fit_f.len(),
        last.convergence.describe()
    );
    assert!(
        last.convergence.is_converged(),
        "{}",
        last.convergence.describe()
    );
    assert_eq!(n, 30, "modes found: {fit_f:?}");
    assert!(median < 1e-3, "median error {median:.3e}");
    assert!(
        median < median0,
        "{median:.3e} vs the start's {median0:.3e}"
    );
}

/// The compressed subspace step (`subspace::compress`): above 100 entries the poles
/// come from the data with the inputs projected onto 8 fixed directions ((17) on 8
/// output directions) and the residues of all entries from one least squares with them
/// fixed. On a random 16 x 16 plant with 24 rank-one modes it finds every mode within
/// 0.1 % as the full step does, and its error against the noiseless response is
/// within 25 % of the full step's.
#[test]
fn compressed_subspace_matches_the_full_step() {
    use subspace::{SubspaceConfig, SubspaceInit};
    faer::set_global_parallelism(faer::Par::Seq);
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 16,
        nu: 16,
        modes: 24,
        lines: 1200,
        noise: 1e-3,
        seed: 11,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let fit = |compress_above: usize| {
        SubspaceInit::new(SubspaceConfig {
            delay: DelayChoice::None,
            compress_above,
            ..SubspaceConfig::default()
        })
        .identify(&r.measured)
        .unwrap()
    };
    let w = r.noiseless.omegas();
    let g = realize::ResponseGrid {
        ny: 16,
        nu: 16,
        values: r.noiseless.values_vec(),
    };
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let mut medians = Vec::new();
    for (name, above) in [("compressed", 100), ("full", usize::MAX)] {
        let id = fit(above);
        let fit_f: Vec<f64> = id.model.modal.pairs.iter().map(|p| p.f_hz()).collect();
        let n = found(&true_f, &fit_f, 1e-3);
        let (median, _) = id.model.relative_error(&w, &g).unwrap();
        println!(
            "{name}: {n}/24 modes within 0.1 %, {} fitted, median error {median:.3e} vs noiseless (noise 1e-3)",
            fit_f.len()
        );
        assert_eq!(
            id.messages.iter().any(|m| m.contains("fixed directions")),
            above == 100,
            "{name}: {:?}",
            id.messages
        );
        assert_eq!(n, 24, "{name}: modes found: {fit_f:?}");
        medians.push(median);
    }
    assert!(
        medians[0] <= 1.25 * medians[1],
        "compressed {:.3e} vs full {:.3e}",
        medians[0],
        medians[1]
    );
}

/// `subspace -> ml` with the default delay (`auto`) on delay-free random plants: the
/// ML step fits a delay the data do not need and turns the residues' phases to trade
/// with it; the additive model the pipeline returns must keep those phases (first-order
/// numerators where a constant one would drop them) and end at the noise level, as the
/// same chain with `--delay none` does. Before, these plants ended at 4.8 to 34 times
/// the noise.
#[test]
fn a_fitted_delay_does_not_cost_the_final_model_its_residues() {
    use frfit::pipeline::PipelineConfig;
    use frfit::run::run;
    for seed in 1..=3 {
        let r = RandomModal::generate(&RandomModalConfig {
            ny: 6,
            nu: 6,
            modes: 12,
            lines: 2000,
            noise: 1e-3,
            rigid_body: true,
            seed,
            ..RandomModalConfig::default()
        })
        .unwrap();
        let cfg = PipelineConfig {
            init: "subspace".into(),
            refine: "ml".into(),
            hold: Some(additive_riv::Hold::None),
            ..Default::default()
        };
        let out = run(&r.measured, "random 6 x 6", &cfg, "fit").unwrap();
        let s = &out.summary;
        let delay = out.fit.model.factor.delay_s;
        println!(
            "seed {seed}: residual/noise {:.3}, delay {:.3} us, {} modes",
            s.final_errors.residual_to_noise,
            delay * 1e6,
            s.final_model.modes.len()
        );
        assert!(
            s.final_errors.residual_to_noise < 1.1,
            "seed {seed}: residual/noise {:.3} (delay {:.3} us)",
            s.final_errors.residual_to_noise,
            delay * 1e6
        );
    }
}

/// Exact data without a variance (an FE model's FRF): the subspace step has no noise
/// level to count the singular values against, and the largest-gap rule took an order
/// within the default cap (60) where the 40 rank-one modes need 80 states. With no gap
/// up to the cap, the cap is doubled as with a variance, and every mode is found to
/// round-off.
#[test]
fn exact_data_without_a_variance_get_the_order_cap_they_need() {
    let (n, fit_f, median) = subspace_on_6_by_6_with_40_modes(0.0, 1e-6);
    println!(
        "{n}/40 modes within 1e-6, {} fitted, median error {median:.3e} (exact data)",
        fit_f.len()
    );
    assert_eq!(n, 40, "modes found: {fit_f:?}");
    assert_eq!(fit_f.len(), 40);
    assert!(median < 1e-8, "median error {median:.3e}");
}

/// The default chain (hold none, delay `delay` or the default) on a random 20 x 20
/// plant with 50 modes (`frfit simulate random-modal` seed `seed`, with or without a
/// rigid body, noise `noise` relative to the median magnitude): the pipeline's output,
/// the modes within 0.1 % of a true one, and the fitted modes' frequencies.
fn fit_random_20_by_20(
    seed: u64,
    rigid_body: bool,
    noise: f64,
    delay: Option<DelayChoice>,
) -> (frfit::run::PipelineOutput, usize, Vec<f64>) {
    use frfit::pipeline::PipelineConfig;
    use frfit::run::run;
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 20,
        nu: 20,
        modes: 50,
        rigid_body,
        noise,
        seed,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let cfg = PipelineConfig {
        hold: Some(additive_riv::Hold::None),
        delay,
        ..Default::default()
    };
    let out = run(&r.measured, "random 20 x 20", &cfg, "fit").unwrap();
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let fit_f: Vec<f64> = out
        .summary
        .final_model
        .modes
        .iter()
        .map(|m| m.f_hz)
        .collect();
    let n = found(&true_f, &fit_f, 1e-3);
    (out, n, fit_f)
}

/// The default chain (`subspace -> ml`, delay `auto`) at the size of the large-MIMO
/// issue: a random 20 x 20 plant with 50 modes, no rigid body and no delay (seed 7 of
/// `frfit simulate random-modal`). The subspace start misses four modes and stands far
/// above the noise level; a delay freed from there absorbed their misfit (29 us), and
/// the fit ended with 49 modes at 1900 times the noise. The subspace delay passes now
/// keep the estimate (the cost is flat in the delay there), and the ML refinement holds
/// the delay until its structure adaptation has added the missed modes.
#[test]
#[ignore = "slow tier (about 22 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn the_default_chain_finds_every_mode_of_a_delay_free_20_by_20_plant() {
    let (out, n, fit_f) = fit_random_20_by_20(7, false, 1e-3, None);
    let s = &out.summary;
    let model = &out.fit.model;
    println!(
        "{n}/50 modes within 0.1 %, {} fitted, residual/noise {:.3}, delay {:.3} us",
        fit_f.len(),
        s.final_errors.residual_to_noise,
        model.factor.delay_s * 1e6
    );
    assert_eq!(n, 50, "modes found: {fit_f:?}");
    assert!(
        s.final_errors.residual_to_noise < 1.05,
        "residual/noise {:.3}",
        s.final_errors.residual_to_noise
    );
    assert!(
        model.factor.delay_s.abs() < 10e-6,
        "delay {:.3} us",
        model.factor.delay_s * 1e6
    );
    // the delay held through the structure adaptation stays held: its score test at
    // the adapted optimum is far from significant (F = 0.03 on this plant), so it is not
    // refined in further iterations to an insignificant value
    let msgs: Vec<&String> = out
        .links
        .iter()
        .flat_map(|l| l.messages.iter())
        .chain(out.fit.messages.iter())
        .collect();
    assert!(
        msgs.iter()
            .any(|m| m.contains("stays held after the structure adaptation")),
        "{msgs:#?}"
    );
}

/// A 20 x 20 plant with 50 modes and a free rigid body (seed 11 of `frfit simulate
/// random-modal --rigid-body`, no delay): its close pairs and a triple cluster (213.5,
/// 215.0, 217.2 Hz) are merged by the compressed subspace start (45 pole pairs), and
/// the ML refinement adds the five modes it lacks, one per refinement. With at most 4
/// additions, the limit before `MlConfig::add_modes_fraction`, the cluster kept two
/// modes and the fit ended at 33 times the noise.
#[test]
#[ignore = "slow tier (about 17 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn the_chain_adds_every_mode_a_large_start_merged() {
    let (out, n, fit_f) = fit_random_20_by_20(11, true, 1e-3, Some(DelayChoice::None));
    assert_every_mode_at_the_noise_level(&out, n, &fit_f);
    assert_eq!(
        out.summary.final_model.rigid_body_integrators, 2,
        "the free body"
    );
}

/// Ten times the noise (1 % of the median magnitude, seed 33 of `frfit simulate
/// random-modal --rigid-body --noise 0.01`): the refinement ends its structure
/// adaptation with three modes missed and one spurious while the cost ratio was 1.71,
/// below the twice the expected ratio that the adaptation used to need; from a ratio of
/// 1.2 it adds them and reaches the noise level.
#[test]
#[ignore = "slow tier (about 14 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn the_chain_finds_every_mode_at_ten_times_the_noise() {
    let (out, n, fit_f) = fit_random_20_by_20(33, true, 1e-2, Some(DelayChoice::None));
    assert_every_mode_at_the_noise_level(&out, n, &fit_f);
}

/// All 50 true modes within 0.1 % (`n` of them found among the fitted `fit_f`), no
/// spurious one, and the final residual at the noise level (below 1.05 times it).
fn assert_every_mode_at_the_noise_level(out: &frfit::run::PipelineOutput, n: usize, fit_f: &[f64]) {
    let s = &out.summary;
    println!(
        "{n}/50 modes within 0.1 %, {} fitted, {} integrators, residual/noise {:.3}",
        fit_f.len(),
        s.final_model.rigid_body_integrators,
        s.final_errors.residual_to_noise
    );
    assert_eq!(n, 50, "modes found: {fit_f:?}");
    assert_eq!(fit_f.len(), 50, "no spurious mode");
    assert!(
        s.final_errors.residual_to_noise < 1.05,
        "residual/noise {:.3}",
        s.final_errors.residual_to_noise
    );
}

/// `data` delayed by `tau` (every entry times `exp(-j w tau)`) plus `noise()` per entry
/// (line after line, entries column-major), with the variance `variance` (`None`: the
/// data's).
fn delayed(
    data: &frf_data::Frf,
    tau: f64,
    variance: Option<Vec<f64>>,
    mut noise: impl FnMut() -> num_complex::Complex64,
) -> frf_data::Frf {
    let per_line = data.ny() * data.nu();
    let mut values = data.values_vec();
    for (k, &w) in data.omegas().iter().enumerate() {
        let rot = num_complex::Complex64::from_polar(1.0, -w * tau);
        for v in values[k * per_line..(k + 1) * per_line].iter_mut() {
            *v = *v * rot + noise();
        }
    }
    let freq: Vec<f64> = (0..data.n_lines()).map(|k| data.freq_hz(k)).collect();
    let variance = variance.or_else(|| data.variance_vec());
    frf_data::Frf::new(freq, data.ny(), data.nu(), values, variance).unwrap()
}

/// The compressed subspace step (a 12 x 12 plant: more than 100 entries) searches the
/// delay on the outputs projected onto 8 fixed directions
/// (`SubspaceConfig::output_directions`), at an eighth of the cost on 50 x 50 data
/// (17.6 s -> 3.2 s there). A delay the periodogram estimate misses by a fraction of its
/// resolution is still moved towards: a random plant (seed 2, 20 modes, 1500 lines,
/// relative noise 1e-4) delayed by 13.7 us, estimated at 9.95 us and refined to 15.46 us
/// (on every output: 14.29 us from an estimate of 8.65 us). The subspace poles are not
/// maximum-likelihood estimates; the refiner takes the delay from there.
#[test]
fn the_compressed_delay_search_on_projected_outputs_finds_the_delay() {
    faer::set_global_parallelism(faer::Par::Seq);
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 12,
        nu: 12,
        modes: 20,
        lines: 1500,
        noise: 1e-4,
        seed: 2,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let tau = 13.7e-6;
    let data = delayed(&r.measured, tau, None, || {
        num_complex::Complex64::new(0.0, 0.0)
    });
    let id = subspace::SubspaceInit::new(subspace::SubspaceConfig::default())
        .identify(&data)
        .unwrap();
    let rep = id.report.delay_refinement.clone().unwrap();
    let refined = id.model.factors.delay_s;
    println!(
        "estimate {:.3} us, refined {:.3} us, truth {:.3} us",
        rep.start_s * 1e6,
        refined * 1e6,
        tau * 1e6
    );
    assert!(!rep.passes.is_empty());
    for p in &rep.passes {
        assert_eq!(p.output_directions, Some(8), "{:?}", id.messages);
    }
    assert!(
        (refined - tau).abs() < 0.6 * (rep.start_s - tau).abs(),
        "estimate {:.3} us, refined {:.3} us\n{}",
        rep.start_s * 1e6,
        refined * 1e6,
        id.messages.join("\n")
    );
}

/// A random 4 x 4 plant with 8 modes (seed 5, 1000 lines), delayed by 13.7 us, with
/// circular Gaussian noise of `scale` times the simulator's level (a fixed generator),
/// and the delay.
fn delayed_4_by_4_data(scale: f64) -> (frf_data::Frf, f64) {
    faer::set_global_parallelism(faer::Par::Seq);
    let (ny, nu) = (4, 4);
    let r = RandomModal::generate(&RandomModalConfig {
        ny,
        nu,
        modes: 8,
        lines: 1000,
        noise: 1e-3,
        seed: 5,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let tau = 13.7e-6;
    let m = &r.noiseless;
    let sd = r.noise_std * scale;
    let mut state = 12345u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    };
    let var = vec![sd * sd; m.n_lines() * ny * nu];
    let data = delayed(m, tau, Some(var), || {
        let (u1, u2) = (uniform(), uniform());
        num_complex::Complex64::from_polar(
            (-2.0 * u1.ln()).sqrt() * sd / std::f64::consts::SQRT_2,
            std::f64::consts::TAU * u2,
        )
    });
    (data, tau)
}

/// [`delayed_4_by_4_data`] fitted by `subspace -> ml` with the delay free: the final
/// model and the ML link's messages and details.
fn delayed_4_by_4(scale: f64) -> (frfit::chain::ChainResult, f64) {
    let (data, tau) = delayed_4_by_4_data(scale);
    let settings = ChainSettings {
        delay: DelayChoice::Auto,
        ..Default::default()
    };
    let out = run_chain(
        &data,
        "subspace",
        "ml",
        &settings,
        &AdditiveOptions::default(),
    )
    .unwrap();
    (out, tau)
}

/// With complex residues and a feedthrough, a delay change is taken up to first order
/// by the residues and the feedthrough of a strictly proper plant: near exact data (a
/// thousandth of the simulator's noise) the delay's information is of second order,
/// and the ML step used to end with an error. Two outcomes are right, and which one
/// comes depends on the last digits of the information matrix:
///
/// - at the optimum (cost 1.58074e4, 13.19 us) its condition is 1.5e12, below the
///   limit (1e13): the delay is fitted and reported with the width of its profile
///   (0.42 us; the truth 0.49 us away);
/// - where the iterations stopped short of it (6 cost units above, before the
///   Jacobian's gradient took the residuals the evaluation keeps) the condition was
///   8.9e16: the delay is held where it is (13.69 us) and the messages say so.
#[test]
fn a_delay_the_residues_take_up_near_exact_data_is_held_or_reported_with_its_profile() {
    let (out, tau) = delayed_4_by_4(1e-3);
    let ml = out.links.last().unwrap();
    let msgs = ml.messages.join("\n");
    let f = &out.model.model.factors;
    println!("delay {:.3} us\n{msgs}", f.delay_s * 1e6);
    assert!(ml.convergence.is_converged(), "{msgs}");
    if msgs.contains("the delay is not determined by the data") {
        assert!(!f.delay_fitted, "{msgs}");
        assert!(
            (f.delay_s - tau).abs() < 0.3e-6,
            "{:.3} us",
            f.delay_s * 1e6
        );
    } else {
        assert!(f.delay_fitted, "{msgs}");
        let std = ml
            .details_as::<ml_refine::MlReport>()
            .unwrap()
            .delay_s_std
            .unwrap();
        assert!(msgs.contains("the delay's profile is flatter"), "{msgs}");
        assert!(std < 1e-6, "std {:.3} us", std * 1e6);
        assert!(
            (f.delay_s - tau).abs() < 2.5 * std,
            "{:.3} us from the truth, std {:.3} us",
            (f.delay_s - tau) * 1e6,
            std * 1e6
        );
    }
}

/// The branch the near-exact case took before the gradient change: a delay whose
/// information matrix is beyond `max_condition` (here lowered to 1e11, below the 1.5e12
/// of that optimum) is held where it is, the messages say so, and the refinement
/// converges without it.
#[test]
fn a_delay_beyond_the_condition_limit_is_held_and_said() {
    use frf_data::Estimator;
    let (data, tau) = delayed_4_by_4_data(1e-3);
    let (out, _) = delayed_4_by_4(1e-3);
    assert!(out.model.model.factors.delay_fitted);
    let ml = ml_refine::MlRefine::new(ml_refine::MlConfig {
        max_condition: 1e11,
        ..Default::default()
    });
    let fit = ml.estimate(&data, out.model.clone()).unwrap();
    let msgs = fit.messages.join("\n");
    println!("{msgs}");
    assert!(
        msgs.contains("the delay is not determined by the data"),
        "{msgs}"
    );
    assert!(!fit.model.factors.delay_fitted, "{msgs}");
    assert!((fit.model.factors.delay_s - tau).abs() < 1e-6, "{msgs}");
    assert!(fit.convergence.is_converged(), "{msgs}");
}

/// At the simulator's noise level (1e-3) the delay of the same plant is determined,
/// but its cost is quartic rather than quadratic near the optimum: the information
/// matrix's standard deviation (1.6 us) is a third of the estimate's distance from the
/// truth (-5.1 us; over 8 noise realizations the estimates spread 4.8 us around the
/// truth). The reported standard deviation comes from the delay's profile (the cost's
/// rise of 1/2, poles held), and says so.
#[test]
fn a_flat_delay_profile_widens_the_reported_uncertainty() {
    let (out, tau) = delayed_4_by_4(1.0);
    let ml = out.links.last().unwrap();
    let msgs = ml.messages.join("\n");
    let delay = out.model.model.factors.delay_s;
    let std = ml
        .details_as::<ml_refine::MlReport>()
        .unwrap()
        .delay_s_std
        .unwrap();
    println!(
        "delay {:.3} us, std {:.3} us\n{msgs}",
        delay * 1e6,
        std * 1e6
    );
    assert!(msgs.contains("the delay's profile is flatter"), "{msgs}");
    assert!(std > 3e-6, "std {:.3} us", std * 1e6);
    assert!(
        (delay - tau).abs() < 2.5 * std,
        "{:.3} us from the truth, std {:.3} us",
        (delay - tau) * 1e6,
        std * 1e6
    );
}
