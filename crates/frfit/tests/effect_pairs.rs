//! Pairs of effects the nominal model does not declare, on the simulated wafer stage
//! (seed 3, and for the resonance below a mode the plates of seeds 4, 5 and 7; lines
//! 1 Hz apart up to 2 kHz, 4 periods x 10 realizations, exact response known; issue
//! 12's must-show): a suspension with a missed mode, a feedthrough with a
//! sensor-mount resonance, and a sensor resonance inside the band near a mode and one
//! above the band. The loop must name each effect and end within 1e-4 (median relative,
//! over all lines) of the noiseless response.

mod common;

use additive_riv::ModeSelection;
use experiment::synth::FlexibleMode;
use faer::Mat;
use frf_data::Frf;
use frfit::run::PipelineOutput;
use realize::{DynamicsFactor, FactorTarget};

/// The simulation set-up of these tests: 4 periods x 10 realizations, lines 1 Hz apart.
fn sim() -> common::Sim {
    common::Sim {
        period: 20_000,
        periods: 4,
        realizations: 10,
        ..common::Sim::default()
    }
}

/// The final model within 1e-4 (median relative, every line) of the exact response,
/// and the verdict noise-limited.
fn assert_near_truth(out: &PipelineOutput, clean: &Frf) {
    let med = common::median_rel_vs_truth(out, clean, 0.0, f64::MAX);
    println!("  final model vs noiseless: median {med:.3e}");
    assert_eq!(out.summary.verdict, "noise_limited");
    assert!(med <= 1e-4, "median {med:.3e} vs the noiseless response");
}

/// A suspension at 4 Hz (damping 0.05; the plate's rigid body on springs) and an 18th
/// mode at 700 Hz that the nominal mode count (17) leaves out: the loop names the
/// stiffness, and the missed mode is held by the final model (added by the loop or
/// picked at once). The first fit (17 CMIF peaks, the suspension among them, modes
/// declared: no mode added in it) lacks members of close pairs and modes the peaks left
/// out (measured: 391.9, 746.8, 1657.3 and 1881.2 Hz): each is a `missed_mode` step.
/// Once at the noise level, the model holds the suspension as a 4 Hz mode beside a free
/// body that carries nothing: the suspended-body reading replaces both by the
/// suspension.
#[test]
fn a_suspension_with_a_missed_mode() {
    let (f_s, zeta_s) = (4.0, 0.05);
    let f_m = 700.0;
    let hidden = FlexibleMode {
        f_hz: f_m,
        zeta: 0.008,
        c: vec![0.6, -0.2, 0.9, 0.3],
        b: (0..13)
            .map(|j| 0.3 * (0.9 * j as f64 + 0.4).sin())
            .collect(),
    };
    let (data, clean, _) = common::simulate(&common::Sim {
        suspension: Some((f_s, zeta_s)),
        extra_modes: vec![hidden],
        ..sim()
    });
    let out = common::diagnose(&data, "suspension + missed mode", ModeSelection::Count(17));
    assert_near_truth(&out, &clean);
    let stiff = common::accepted(&out, "stiffness");
    assert_eq!(stiff.len(), 1, "one stiffness step");
    let f = stiff[0].fitted.params_json()["f_hz"].as_f64().unwrap();
    assert!(
        (f / f_s - 1.0).abs() < 0.02,
        "suspension at {f:.3} Hz, made {f_s}"
    );
    let near = |f: f64| (f / f_m - 1.0).abs() <= 0.005;
    let in_loop = common::accepted(&out, "missed_mode")
        .iter()
        .any(|s| near(s.fitted.params_json()["f_hz"].as_f64().unwrap()));
    let in_initial = out.summary.initial.modes.iter().any(|m| near(m.f_hz));
    println!("  missed mode: found by the loop {in_loop}, picked at once {in_initial}");
    assert!(in_loop || in_initial, "the mode at {f_m} Hz is found");
    assert!(out.summary.final_model.modes.iter().any(|m| near(m.f_hz)));
    for e in ["delay", "feedthrough", "input_dynamics", "output_dynamics"] {
        assert!(common::accepted(&out, e).is_empty(), "no {e} step");
    }
    // no mode without a step
    let added = common::accepted(&out, "missed_mode").len();
    assert!(
        out.summary.initial.modes.len() + added >= out.summary.final_model.modes.len(),
        "{} modes in the first fit, {added} added by steps, {} in the final model",
        out.summary.initial.modes.len(),
        out.summary.final_model.modes.len()
    );
}

/// A mode hidden beside another one, the two a close pair that the CMIF start merges
/// (820 Hz, damping 0.006, 1.2 % above the plate's 810.2 Hz mode, another shape), with
/// the mode count declared one short (`--modes 17` for 18): the mode the start lacks
/// (measured: the CMIF picks both 810 and 820 Hz and merges the plate's pair at
/// 746.8/762.9 Hz) is a `missed_mode` step of the loop, with its errors before and after
/// and its check on held-out lines, not a repair inside the first fit; every mode of the
/// final model beyond the first fit's came with a step, and the final model is at the
/// truth.
#[test]
#[ignore = "slow tier (about 30 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_hidden_mode_beside_a_close_pair_with_one_mode_short() {
    let f_m = 820.0;
    let hidden = FlexibleMode {
        f_hz: f_m,
        zeta: 0.006,
        c: vec![-0.5, 0.8, 0.3, -0.7],
        b: (0..13)
            .map(|j| 0.3 * (1.3 * j as f64 + 1.1).cos())
            .collect(),
    };
    let (data, clean, _) = common::simulate(&common::Sim {
        extra_modes: vec![hidden],
        ..sim()
    });
    let out = common::diagnose(&data, "mode beside a close pair", ModeSelection::Count(17));
    assert_near_truth(&out, &clean);
    assert_eq!(
        out.summary.final_model.modes.len(),
        18,
        "the plate's 17 modes and the hidden one"
    );
    // the start (17 CMIF peaks) merges a close pair of the plate or the hidden one: the
    // mode it lacks is a step
    let added = common::accepted(&out, "missed_mode");
    assert!(!added.is_empty(), "a missed_mode step");
    for step in &added {
        assert!(
            step.after.residual_to_noise < step.before.residual_to_noise,
            "the step lowers the error: {:?} -> {:?}",
            step.before,
            step.after
        );
        let h = step.held_out.expect("the step's held-out check");
        assert!(h.after < h.before, "held out {} -> {}", h.before, h.after);
    }
    let near = |f: f64| (f / f_m - 1.0).abs() <= 0.005;
    assert!(out.summary.final_model.modes.iter().any(|m| near(m.f_hz)));
    // no mode without a step
    assert!(
        out.summary.initial.modes.len() + added.len() >= out.summary.final_model.modes.len(),
        "{} modes in the first fit, {} added by steps, {} in the final model",
        out.summary.initial.modes.len(),
        added.len(),
        out.summary.final_model.modes.len()
    );
    for e in [
        "delay",
        "feedthrough",
        "input_dynamics",
        "output_dynamics",
        "stiffness",
    ] {
        assert!(common::accepted(&out, e).is_empty(), "no {e} step");
    }
}

/// A feedthrough (crosstalk of a few nm/N, inside the hold and delay like the plant)
/// and a sensor-mount resonance on output 2 (1450 Hz, damping 0.03): both named.
#[test]
#[ignore = "slow tier (about 45 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_feedthrough_with_a_sensor_mount_resonance() {
    feedthrough_with_resonance(3, 1450.0);
}

fn feedthrough_with_resonance(seed: u64, f_r: f64) {
    let zeta = 0.03;
    let d = Mat::from_fn(4, 13, |i, j| {
        3e-9 * (1.7 * i as f64 + 0.9 * j as f64 + 0.3).sin()
    });
    let (data, clean, _) = common::simulate(&common::Sim {
        seed,
        feedthrough: Some(d),
        plant_dynamics: vec![DynamicsFactor::second_order(
            FactorTarget::Output(1),
            f_r,
            zeta,
        )],
        ..sim()
    });
    let out = common::diagnose(&data, "feedthrough + sensor resonance", ModeSelection::Auto);
    assert_eq!(
        common::accepted(&out, "feedthrough").len(),
        1,
        "one feedthrough step"
    );
    common::assert_output_resonance(&out, 2, f_r, zeta);
    for e in ["delay", "input_dynamics", "missed_mode"] {
        assert!(common::accepted(&out, e).is_empty(), "no {e} step");
    }
    assert_near_truth(&out, &clean);
}

/// A sensor-mount resonance on output 3 (damping 0.03) 3 % above one of the plate's
/// modes (the tenth, 890.9 Hz): the factor, not a second mode, on its row.
#[test]
#[ignore = "slow tier (about 27 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_near_a_mode() {
    let out = resonance_near_a_mode(3, 9, 1.03, false);
    assert!(out.summary.initial.restart.is_none(), "no restart");
}

/// The same 3 % below the seventh mode (713.2 Hz) of another plate (seed 5). The CMIF
/// start's first fit ends far from the noise there (8 of the 17 modes after the delay
/// restart, 2460 times the noise); the restart from the common-denominator start keeps the modes, and the
/// factor's refit leaves the twin of the 713.2 Hz mode that held the row's phase
/// unstable, which the trial removes as redundant.
#[test]
#[ignore = "slow tier (about 80 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_just_below_a_mode_of_another_plate() {
    let out = resonance_near_a_mode(5, 6, 0.97, false);
    // the first fit the loop started from is the common-denominator restart's (a better
    // first fit, not a step)
    let restart = out.summary.initial.restart.as_ref().expect("a restart");
    println!(
        "  restart from {} ({} modes replaced)",
        restart.from, restart.replaced_modes
    );
    assert!(
        restart.from.starts_with("the sk -> riv chain"),
        "{}",
        restart.from
    );
    assert!(restart.f_statistic > restart.f_critical);
}

/// The same below the seventh mode of a third plate (seed 4, 703.0 Hz): its first fit
/// also lost modes (11 from 16 CMIF peaks) and is restarted.
#[test]
#[ignore = "slow tier (about 58 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_just_below_a_mode_of_a_third_plate() {
    let out = resonance_near_a_mode(4, 6, 0.97, false);
    assert!(out.summary.initial.restart.is_some(), "a restart");
}

/// The same below the seventh mode of a fourth plate (seed 7, 745.0 Hz): its first fit
/// lost no modes (15 from 15 CMIF peaks: no restart), and after the factor the two
/// modes it missed at 1466 and 1561 Hz, 6 % apart, raise each other's local residual
/// median so that the residual's peak test proposes neither; the round with nothing
/// else to propose tests the modes the common-denominator start holds.
#[test]
#[ignore = "slow tier (about 53 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_below_a_mode_and_two_close_missed_modes() {
    let out = resonance_near_a_mode(7, 6, 0.97, true);
    assert!(out.summary.initial.restart.is_none(), "no restart");
    let added: Vec<f64> = common::accepted(&out, "missed_mode")
        .iter()
        .filter_map(|s| s.fitted.params_json()["f_hz"].as_f64())
        .collect();
    for f in [1466.4, 1560.7] {
        assert!(
            added.iter().any(|a| (a / f - 1.0).abs() < 0.01),
            "a missed mode at {f} Hz: {added:?}"
        );
    }
}

/// A resonance 3 % above the fifth mode of plate seed 8 (400.5 Hz beside 388.9 Hz). The
/// first fit, its residual 1290 times the noise with the resonance unexplained, drops
/// ten true modes above 700 Hz; the loop adds them back and, for want of the resonance,
/// a delay and a first-order output factor. The resonance's factor then brings the
/// residual to the noise level; the earlier factor and delay, tested again beside it,
/// are not significant and are taken out (or the earlier factor, left with its pole in
/// the right half-plane by the trial's refit, is removed there as redundant). The first
/// fit's split of 388.9 Hz can leave a twin 0.3 Hz away, merged after the step.
#[test]
#[ignore = "slow tier (about 81 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_above_a_mode_beside_its_neighbour() {
    let out = resonance_near_a_mode(8, 4, 1.03, true);
    let factors = &out.fit.model.dynamics;
    assert_eq!(
        factors.len(),
        1,
        "one factor in the final model: {factors:?}"
    );
    // a delay accepted before the resonance was explained is taken out again
    let delay = out.fit.model.factor.delay_s;
    assert!(
        (delay / 1e-4 - 1.0).abs() < 1e-9,
        "the declared delay: {delay:e} s"
    );
}

/// A resonance 3 % above the thirteenth mode of plate seed 14 (1369.6 Hz beside
/// 1329.7 Hz), which the first fit holds as a mode and splits its neighbours around.
#[test]
#[ignore = "slow tier (about 59 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_above_a_high_mode() {
    resonance_near_a_mode(14, 12, 1.03, true);
}

/// `missed_modes`: whether the loop may add modes the first fit missed (the plate's
/// own, beside the factor).
fn resonance_near_a_mode(seed: u64, mode: usize, ratio: f64, missed_modes: bool) -> PipelineOutput {
    let plate = experiment::synth::WaferStage::build(&experiment::synth::WaferStageConfig {
        seed,
        ..Default::default()
    })
    .unwrap();
    let f_mode = plate.plant.modes[mode].f_hz;
    let (f_r, zeta) = (ratio * f_mode, 0.03);
    println!("  plate mode {f_mode:.1} Hz, sensor resonance {f_r:.1} Hz");
    let (data, clean, _) = common::simulate(&common::Sim {
        plant_dynamics: vec![DynamicsFactor::second_order(
            FactorTarget::Output(2),
            f_r,
            zeta,
        )],
        seed,
        ..sim()
    });
    let out = common::diagnose(&data, "sensor resonance near a mode", ModeSelection::Auto);
    common::assert_output_resonance(&out, 3, f_r, zeta);
    for e in ["delay", "feedthrough", "input_dynamics", "missed_mode"] {
        if e == "missed_mode" && missed_modes {
            continue;
        }
        assert!(common::accepted(&out, e).is_empty(), "no {e} step");
    }
    assert_eq!(
        out.summary.final_model.modes.len(),
        plate.plant.modes.len(),
        "the plate's modes"
    );
    assert_near_truth(&out, &clean);
    out
}

/// A sensor-mount resonance on output 2 at 2.9 kHz (damping 0.03), above the band's
/// top edge (2 kHz): in the band it is a magnitude rise `1 / (1 - (f / f_r)^2)` on that
/// row with little phase.
#[test]
#[ignore = "slow tier (about 23 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_resonance_above_the_band() {
    resonance_above_the_band(3, 2900.0);
}

fn resonance_above_the_band(seed: u64, f_r: f64) {
    let zeta = 0.03;
    let (data, clean, _) = common::simulate(&common::Sim {
        seed,
        plant_dynamics: vec![DynamicsFactor::second_order(
            FactorTarget::Output(1),
            f_r,
            zeta,
        )],
        ..sim()
    });
    let out = common::diagnose(
        &data,
        "sensor resonance above the band",
        ModeSelection::Auto,
    );
    let steps = common::accepted(&out, "output_dynamics");
    assert_eq!(steps.len(), 1, "one output_dynamics step");
    let p = steps[0].fitted.params_json();
    assert_eq!(p["order"], 2);
    assert_eq!(p["outputs"][0], 2, "the resonance is on output 2");
    let f = p["poles"][0]["f_hz"].as_f64().unwrap();
    assert!(
        (f / f_r - 1.0).abs() < 0.1,
        "resonance at {f:.1} Hz, made at {f_r}"
    );
    for e in ["delay", "feedthrough", "input_dynamics", "missed_mode"] {
        assert!(common::accepted(&out, e).is_empty(), "no {e} step");
    }
    assert_near_truth(&out, &clean);
}

/// A suspension with an undeclared delay on plate `seed` (`cargo xtask effects --case
/// suspension-delay`): the `stiffness` and the `delay` named, no dynamics factor or
/// feedthrough left, the plate's 17 modes, the delay within 2 us of the truth, and the
/// final model at the truth.
fn suspension_with_delay(seed: u64, (f_s, zeta_s): (f64, f64), extra_samples: f64) {
    let (data, clean, _) = common::simulate(&common::Sim {
        seed,
        suspension: Some((f_s, zeta_s)),
        extra_delay_samples: extra_samples,
        ..sim()
    });
    let out = common::diagnose(&data, "suspension + delay", ModeSelection::Auto);
    assert_eq!(
        common::accepted(&out, "stiffness").len(),
        1,
        "one stiffness step"
    );
    let delay = common::accepted(&out, "delay");
    assert_eq!(delay.len(), 1, "one delay step");
    for e in ["feedthrough", "input_dynamics", "output_dynamics"] {
        assert!(common::accepted(&out, e).is_empty(), "no {e} step left");
    }
    // the stage's one sample of computation delay and the extra, beyond the hold
    let truth_s = (1.0 + extra_samples) / 10_000.0;
    let fitted = out.summary.final_model.delay_s;
    assert!(
        (fitted - truth_s).abs() < 2e-6,
        "delay {:.2} us for {:.2} us",
        fitted * 1e6,
        truth_s * 1e6
    );
    assert_eq!(
        out.summary.final_model.modes.len(),
        17,
        "the plate's 17 modes"
    );
    assert_near_truth(&out, &clean);
}

/// Plate 100, a suspension at 5.78 Hz (damping 0.058) with 21 us of undeclared delay:
/// its first fit is 1048 times the noise, and a round took a common lead-lag (37 us of
/// group delay) where the delay was meant. Once the model is at the noise level the
/// factor is read as a delay (`diagnose::delay_reading`) and the delay takes its place
/// (before: `input_dynamics` and `stiffness`, 9.9e-5 from the truth).
#[test]
#[ignore = "slow tier (about 40 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_suspension_with_a_delay_that_a_common_factor_held_first() {
    suspension_with_delay(100, (5.78, 0.058), 0.21);
}

/// Plate 102, a suspension at 4.35 Hz (damping 0.066) with 32 us of undeclared delay: the
/// delay restart's start holds two modes beside the plate's 134.4 Hz mode; the pruning
/// after the `stiffness` reading removes them (before: 19 modes for 17).
#[test]
#[ignore = "slow tier (about 80 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_suspension_with_a_delay_leaves_no_mode_beside_the_first() {
    suspension_with_delay(102, (4.35, 0.066), 0.32);
}
