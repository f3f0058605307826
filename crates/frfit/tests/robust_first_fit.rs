//! On wafer-stage plates without any undeclared effect the first fit reaches the noise
//! level and the diagnosis loop adds nothing. The simulator varies the plate with the
//! seed (aspect ratio, mode frequencies, close pairs, damping); the band ends at 1.8 kHz,
//! below the plate's last mode (1.8 to 1.95 kHz): a mode beyond the band edge whose tail
//! the first fit must hold as a mode (not the loop as a feedthrough). Simulated here, no
//! files.

mod common;

use frf_data::Frf;
use frfit::pipeline::PipelineConfig;
use frfit::run::run;

/// Upper band edge of the fit, Hz: below every plate's last mode.
const BAND_HI: f64 = 1800.0;

/// The wafer stage of `seed` measured with `periods` x `realizations` multisine
/// periods up to 1.9 kHz (1 nm sensor noise, 5 nm drift), with the comments
/// `frfit simulate` writes (hold, delay, realizations), and the last true mode, Hz.
fn plate(seed: u64, periods: usize, realizations: usize) -> (Frf, f64) {
    let (data, _, last) = common::simulate(&common::Sim {
        seed,
        periods,
        realizations,
        f_max: 1900.0,
        ..common::Sim::default()
    });
    (data, last)
}

/// Diagnoses each plate of `seeds` over 20 Hz .. [`BAND_HI`]; returns one line per
/// plate that failed (first-fit residual/noise above `max_ratio`, or an effect added).
fn failures(seeds: &[u64], periods: usize, realizations: usize, max_ratio: f64) -> Vec<String> {
    let mut bad = Vec::new();
    for &seed in seeds {
        let (data, last) = plate(seed, periods, realizations);
        let cfg = PipelineConfig {
            band_hz: Some((20.0, BAND_HI)),
            diagnose: true,
            ..Default::default()
        };
        let out = run(&data, &format!("plate {seed}"), &cfg, "diagnose").unwrap();
        let s = &out.summary;
        let added: Vec<&str> = s
            .steps
            .iter()
            .filter(|x| x.accepted)
            .map(|x| x.effect())
            .collect();
        let line = format!(
            "plate {seed} (last mode {last:.1} Hz): first fit residual/noise {:.3} with {} \
             modes (beyond the band: {:?}), added {added:?}, final {:.3}",
            s.initial.errors.residual_to_noise,
            s.initial.modes.len(),
            s.initial
                .modes
                .iter()
                .filter(|m| m.f_hz > BAND_HI)
                .map(|m| format!("{:.1} Hz", m.f_hz))
                .collect::<Vec<_>>(),
            s.final_errors.residual_to_noise,
        );
        println!("{line}");
        if s.initial.errors.residual_to_noise > max_ratio || !added.is_empty() {
            bad.push(line);
        }
    }
    bad
}

/// Six plates, 2 periods x 8 realizations (an estimated variance inflates the residual
/// ratio by `sqrt(d2 / (d2 - 2))` = 1.08 with `d2 = 14`).
#[test]
#[ignore = "slow tier (about 27 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn plates_without_effects_start_at_the_noise_level() {
    let bad = failures(&[21, 22, 23, 24, 25, 26], 2, 8, 1.2);
    assert!(bad.is_empty(), "{bad:#?}");
}

/// The extended set: twenty plates (about two minutes in release on two cores).
#[test]
#[ignore = "slow tier (about 120 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn twenty_plates_without_effects_start_at_the_noise_level() {
    let seeds: Vec<u64> = (1..=20).collect();
    let bad = failures(&seeds, 2, 8, 1.2);
    assert!(bad.is_empty(), "{bad:#?}");
}
