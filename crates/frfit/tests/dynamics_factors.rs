//! Dynamics factors the nominal model does not declare, on the simulated wafer stage
//! (seed 3, 2000 lines 1 Hz apart up to 2 kHz, 4 periods x 10 realizations, exact
//! response known): an amplifier's
//! bandwidth common to every entry, a sensor-mount resonance on one output row and a
//! lead-lag on one actuator. The loop must name the factor (support, order, poles and
//! zeros) instead of a delay, a feedthrough or a mode, and end within 1e-4 (median
//! relative) of the noiseless response.

mod common;

use additive_riv::ModeSelection;
use realize::{DynamicsFactor, FactorTarget};

/// The run names none of the effects `absent`, ends noise-limited, and its final model is
/// within 1e-4 (median relative) of the noiseless response `clean`.
fn ends_noise_limited_near_truth(
    out: &frfit::run::PipelineOutput,
    clean: &frf_data::Frf,
    absent: &[&str],
) {
    for e in absent {
        assert!(common::accepted(out, e).is_empty(), "no {e} step");
    }
    assert_eq!(out.summary.verdict, "noise_limited");
    let med = common::median_rel_vs_truth(out, clean, 0.0, f64::MAX);
    println!("final model vs noiseless: median {med:.3e}");
    assert!(med <= 1e-4, "median {med:.3e} vs the noiseless response");
}

#[test]
#[ignore = "slow tier (about 36 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_common_amplifier_lag_is_one_input_dynamics_on_all_inputs() {
    let f_c = 2500.0;
    let (data, clean) = common::simulated_wafer_with(
        20_000,
        4,
        10,
        0.0,
        vec![DynamicsFactor::first_order(FactorTarget::All, f_c)],
        1.0,
    );
    let out = common::diagnose(&data, "common lag", ModeSelection::Auto);
    let steps = common::accepted(&out, "input_dynamics");
    assert_eq!(steps.len(), 1, "one input_dynamics step");
    let p = steps[0].fitted.params_json();
    assert_eq!(p["support"], "all");
    assert_eq!(p["order"], 1);
    assert_eq!(p["inputs"].as_array().unwrap().len(), 13);
    let pole = p["poles"][0]["f_hz"].as_f64().unwrap();
    assert!(
        (pole / f_c - 1.0).abs() < 0.03,
        "lag at {pole:.1} Hz, made at {f_c}"
    );
    ends_noise_limited_near_truth(
        &out,
        &clean,
        &["delay", "feedthrough", "output_dynamics", "missed_mode"],
    );
    // the final model's factor reported with its standard deviation, which covers the
    // lag's corner (one seed: within 3 sigma)
    let u = out.summary.uncertainty.as_ref().expect("an uncertainty");
    assert_eq!(u.factors.len(), 1, "{:?}", u.factors);
    assert_eq!(u.factors[0].target, "all entries");
    let corner = u.factors[0].poles[0];
    println!(
        "lag corner {:.3} Hz +- {:.3} Hz (1 sigma), made at {f_c}",
        corner.f_hz, corner.f_hz_std
    );
    assert!(corner.f_hz_std > 0.0 && corner.f_hz_std < 0.01 * f_c);
    assert!(
        (corner.f_hz - f_c).abs() < 3.0 * corner.f_hz_std,
        "corner {:.3} Hz, std {:.3} Hz, made at {f_c}",
        corner.f_hz,
        corner.f_hz_std
    );
}

#[test]
#[ignore = "slow tier (about 37 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_sensor_mount_resonance_is_a_second_order_factor_on_its_row() {
    let (f_r, zeta) = (1450.0, 0.03);
    let (data, clean) = common::simulated_wafer_with(
        20_000,
        4,
        10,
        0.0,
        vec![DynamicsFactor::second_order(
            FactorTarget::Output(1),
            f_r,
            zeta,
        )],
        1.0,
    );
    let out = common::diagnose(&data, "sensor-mount resonance", ModeSelection::Auto);
    common::assert_output_resonance(&out, 2, f_r, zeta);
    for e in ["delay", "feedthrough", "input_dynamics", "missed_mode"] {
        assert!(common::accepted(&out, e).is_empty(), "no {e} step");
    }
    assert_eq!(out.summary.verdict, "noise_limited");
    assert_eq!(
        out.summary.final_model.modes.len(),
        17,
        "the plate's 17 modes"
    );
    let med = common::median_rel_vs_truth(&out, &clean, 0.0, f64::MAX);
    println!("final model vs noiseless: median {med:.3e}");
    assert!(med <= 1e-4, "median {med:.3e} vs the noiseless response");
}

/// A pair of undeclared effects: the common amplifier lag (2.5 kHz) and a computation
/// delay of 0.6 samples (60 us) beyond the declared 150 us. Both are named, the lag on
/// every input, and the model ends within 1e-4 of the exact response. The delay step
/// (the restart from the data's delay) takes the lag's low-frequency group delay
/// `1 / w_c` (64 us) with the 60 us; the common lag then takes it back (the factor
/// traded against the fitted delay), so the final delay is the one the stage has.
#[test]
#[ignore = "slow tier (about 41 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_common_lag_with_an_undeclared_delay_are_both_found() {
    assert_lag_and_delay_found(2500.0);
}

/// The same pair with the lag's corner inside the band (lines up to 2 kHz), where its
/// roll-off and phase are both in the data: at 1.5 kHz the traded refit used to leave
/// unstable parts and the lag was not found; at 800 Hz the delay restart first takes
/// 336 us (the lag's 199 us of group delay with the 160 us). Both end with the lag
/// within 3 % and the stage's delay.
#[test]
#[ignore = "slow tier (about 110 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn a_common_lag_inside_the_band_with_an_undeclared_delay_are_both_found() {
    for f_c in [1500.0, 800.0] {
        assert_lag_and_delay_found(f_c);
    }
}

/// The simulated stage with a first-order lag at `f_c` Hz common to every entry and 0.6
/// samples of delay beyond the declared: one `input_dynamics` step on every input
/// within 3 % of `f_c`, one `delay` step, the final delay within 2 us of the stage's,
/// noise-limited within 1e-4 of the noiseless response.
fn assert_lag_and_delay_found(f_c: f64) {
    let (data, clean, _) = common::simulate(&common::Sim {
        period: 20_000,
        periods: 4,
        realizations: 10,
        plant_dynamics: vec![DynamicsFactor::first_order(FactorTarget::All, f_c)],
        extra_delay_samples: 0.6,
        ..common::Sim::default()
    });
    let out = common::diagnose(&data, "common lag + delay", ModeSelection::Auto);
    let lag = common::accepted(&out, "input_dynamics");
    assert_eq!(lag.len(), 1, "one input_dynamics step (lag at {f_c} Hz)");
    assert_eq!(lag[0].fitted.params_json()["support"], "all");
    let pole = lag[0].fitted.params_json()["poles"][0]["f_hz"]
        .as_f64()
        .unwrap();
    assert!(
        (pole / f_c - 1.0).abs() < 0.03,
        "lag at {pole:.1} Hz, made at {f_c}"
    );
    let delay = common::accepted(&out, "delay");
    assert_eq!(delay.len(), 1, "one delay step (lag at {f_c} Hz)");
    let total = out.summary.final_model.delay_s;
    // the stage's computation delay and the 0.6 samples undeclared
    let stage = experiment::synth::WaferStageConfig::default();
    let made = (stage.delay_samples + 0.6) / stage.fs;
    println!(
        "lag at {f_c} Hz: final delay {:.2} us, made {:.2} us",
        total * 1e6,
        made * 1e6
    );
    assert!(
        (total - made).abs() < 2e-6,
        "final delay {:.2} us, made {:.2} us (lag at {f_c} Hz)",
        total * 1e6,
        made * 1e6
    );
    ends_noise_limited_near_truth(
        &out,
        &clean,
        &["feedthrough", "output_dynamics", "missed_mode"],
    );
}

/// An actuator with a phase lead, `(1 + s / w_z) / (1 + s / w_p)` with the zero at
/// 300 Hz and the pole at 900 Hz (both inside the 2 kHz band: a lead of up to 30
/// degrees and a gain of 3 at the top), on input 5. No all-pole factor can make a lead:
/// the loop must name an `input_dynamics` on input 5 with a numerator (its zero and
/// pole within 2 %) and end within 1e-4 of the noiseless response.
#[test]
#[ignore = "slow tier (about 27 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn an_actuator_lead_lag_is_an_input_factor_with_a_zero() {
    let (f_z, f_p) = (300.0, 900.0);
    let (data, clean) = common::simulated_wafer_with(
        20_000,
        4,
        10,
        0.0,
        vec![DynamicsFactor::lead_lag(FactorTarget::Input(4), f_z, f_p)],
        1.0,
    );
    let out = common::diagnose(&data, "actuator lead-lag", ModeSelection::Auto);
    let steps = common::accepted(&out, "input_dynamics");
    assert_eq!(steps.len(), 1, "one input_dynamics step");
    let p = steps[0].fitted.params_json();
    assert_eq!(p["support"], "inputs");
    assert_eq!(p["inputs"][0], 5, "the factor is on input 5");
    assert_eq!(p["order"], 1);
    let pole = p["poles"][0]["f_hz"].as_f64().unwrap();
    let zero = p["zeros"][0]["f_hz"].as_f64().unwrap();
    println!("lead-lag found: zero {zero:.3} Hz (made {f_z}), pole {pole:.3} Hz (made {f_p})");
    println!("evidence: {}", steps[0].evidence);
    assert!(
        (zero / f_z - 1.0).abs() < 0.02,
        "zero at {zero:.1} Hz, made at {f_z}"
    );
    assert!(
        (pole / f_p - 1.0).abs() < 0.02,
        "pole at {pole:.1} Hz, made at {f_p}"
    );
    assert_eq!(p["non_minimum_phase"], false);
    ends_noise_limited_near_truth(&out, &clean, &["delay", "feedthrough", "output_dynamics"]);
}

/// A lag-lead on one actuator, `(1 + s / w_z) / (1 + s / w_p)` with the pole at 600 Hz
/// and the zero at 2.4 kHz (above the 2 kHz band: most of it looks like a first-order
/// lag), on input 5: the factor is named on input 5 with its zero, and the model ends
/// within 1e-4 of the noiseless response.
#[test]
#[ignore = "slow tier (about 27 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn an_actuator_lag_lead_keeps_its_zero_above_the_band() {
    let (f_z, f_p) = (2400.0, 600.0);
    let (data, clean) = common::simulated_wafer_with(
        20_000,
        4,
        10,
        0.0,
        vec![DynamicsFactor::lead_lag(FactorTarget::Input(4), f_z, f_p)],
        1.0,
    );
    let out = common::diagnose(&data, "actuator lag-lead", ModeSelection::Auto);
    let steps = common::accepted(&out, "input_dynamics");
    for s in &steps {
        println!("evidence: {}", s.evidence);
    }
    let last = steps.last().expect("an input_dynamics step");
    let p = last.fitted.params_json();
    assert_eq!(p["inputs"][0], 5, "the factor is on input 5");
    let pole = p["poles"][0]["f_hz"].as_f64().unwrap();
    let zero = p["zeros"][0]["f_hz"].as_f64().unwrap();
    println!("lag-lead found: zero {zero:.3} Hz (made {f_z}), pole {pole:.3} Hz (made {f_p})");
    assert!(
        (zero / f_z - 1.0).abs() < 0.02,
        "zero at {zero:.1} Hz, made at {f_z}"
    );
    assert!(
        (pole / f_p - 1.0).abs() < 0.02,
        "pole at {pole:.1} Hz, made at {f_p}"
    );
    ends_noise_limited_near_truth(&out, &clean, &[]);
}

/// A first-order lag at 700 Hz on input 4 of another plate (seed 29, the simulator's
/// defaults: lines 0.25 Hz apart, 10 periods x 10 realizations), band 20..2000 Hz as
/// `frfit diagnose --band 20:2000` runs it. The first fit takes the lag for a mode that
/// lives in input 4 alone, so the round refits both a first-order factor and a
/// second-order one in the mode's place; the second-order refit splits its poles into
/// 700 Hz and tens of MHz, where the band cannot see a pole
/// (`trial::test_far_poles`). The summary must say what the plant has: one first-order
/// `input_dynamics` on input 4 with its corner within 0.1 % of 700 Hz, no pole beyond
/// the band, and the model within 1e-4 of the noiseless response.
#[test]
#[ignore = "slow tier (about 169 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn an_actuator_lag_is_first_order_even_where_a_second_order_fits_as_well() {
    let f_c = 700.0;
    let (data, clean, _) = common::simulate(&common::Sim {
        seed: 29,
        plant_dynamics: vec![DynamicsFactor::first_order(FactorTarget::Input(3), f_c)],
        ..common::Sim::default()
    });
    let cfg = frfit::pipeline::PipelineConfig {
        band_hz: Some((20.0, 2000.0)),
        diagnose: true,
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let out = frfit::run::run(&data, "lag on input 4, plate 29", &cfg, "diagnose").unwrap();
    common::print_steps("lag on input 4, plate 29", &out);
    println!("  diagnosis took {:.1} s", t.elapsed().as_secs_f64());
    let steps = common::accepted(&out, "input_dynamics");
    assert_eq!(steps.len(), 1, "one input_dynamics step");
    let p = steps[0].fitted.params_json();
    println!("evidence: {}", steps[0].evidence);
    assert_eq!(p["support"], "inputs");
    assert_eq!(p["inputs"][0], 4, "the factor is on input 4");
    assert_eq!(p["order"], 1, "a first-order factor");
    let poles = p["poles"].as_array().unwrap();
    assert_eq!(poles.len(), 1, "one pole: {poles:?}");
    let pole = poles[0]["f_hz"].as_f64().unwrap();
    assert!(
        (pole / f_c - 1.0).abs() < 1e-3,
        "lag at {pole:.3} Hz, made at {f_c}"
    );
    ends_noise_limited_near_truth(&out, &clean, &["delay", "feedthrough", "output_dynamics"]);
}
