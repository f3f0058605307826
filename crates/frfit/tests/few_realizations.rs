//! A variance estimated from few realizations is itself noisy: `|E|^2 / var` follows an
//! F rather than a chi-square distribution, its mean is inflated by `d2 / (d2 - 2)`
//! (2 with 3 realizations) and its tail is polynomial. When the file says how many
//! realizations the variance came from, the variance is pooled over neighbouring lines
//! (`pipeline::pooled_variance`: 5 lines, 20 degrees of freedom for 3 realizations), the
//! residual analysis accounts for the pooled degrees of freedom, and a model at the noise
//! level is called noise-limited. Simulated wafer stage, no files.

mod common;

use frf_data::Frf;
use frfit::pipeline::PipelineConfig;
use frfit::run::run;

/// The wafer stage (seed 3), 2 periods x 3 realizations, lines up to 2 kHz, with the
/// comments `frfit simulate` writes.
fn three_realizations() -> Frf {
    common::simulated_wafer(2, 3, 0.0).0
}

#[test]
#[ignore = "slow tier (about 14 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn three_realizations_are_noise_limited_when_declared() {
    let data = three_realizations();
    let cfg = || PipelineConfig {
        band_hz: Some((20.0, 2000.0)),
        diagnose: true,
        ..Default::default()
    };
    let out = run(&data, "simulated R=3", &cfg(), "diagnose").unwrap();
    let s = &out.summary;
    println!(
        "declared R = 3: verdict {}, {} modes, residual/noise {:.3}, accepted {:?}",
        s.verdict,
        s.final_model.modes.len(),
        s.final_errors.residual_to_noise,
        s.steps
            .iter()
            .filter(|x| x.accepted)
            .map(|x| x.effect())
            .collect::<Vec<_>>()
    );
    assert!(s
        .initial
        .declared
        .iter()
        .any(|d| d.contains("3 realizations")));
    assert_eq!(s.verdict, "noise_limited");
    assert!(s.steps.iter().all(|x| !x.accepted), "nothing added");
    assert_eq!(s.final_model.modes.len(), 17);
    // the variance of 3 realizations (4 degrees of freedom per line) is pooled over 5
    // neighbouring lines (20): the residual/noise ratio at the truth is
    // sqrt(d2 / (d2 - 2)) = sqrt(20 / 18) = 1.054, where the per-line variance gave
    // sqrt(2)
    assert!(s
        .initial
        .declared
        .iter()
        .any(|d| d.contains("pooled over 5 neighbouring lines")));
    assert!(
        (s.final_errors.residual_to_noise - (20f64 / 18.0).sqrt()).abs() < 0.05,
        "{}",
        s.final_errors.residual_to_noise
    );

    // The counter-check: the same data without the declaration are taken as having a
    // known variance, and the inflated residual is (wrongly, but as documented) not
    // noise-limited: the declaration is what changes the verdict.
    let mut bare = data.clone();
    bare.comments.retain(|c| !c.contains("realizations"));
    bare.metadata.retain(|k, _| !k.contains("realization"));
    let out = run(&bare, "simulated, R undeclared", &cfg(), "diagnose").unwrap();
    println!(
        "undeclared R: verdict {} (declared: {:?})",
        out.summary.verdict, out.summary.initial.declared
    );
    assert_eq!(out.summary.verdict, "unexplained_residual");
}

/// Ten times the sensor noise (10 nm white, 50 nm drift RMS; 10 periods x 10
/// realizations): the noise hides nothing the nominal model lacks, so the loop adds
/// nothing beyond what the data declare, and the final model keeps the 17 modes.
#[test]
fn ten_times_the_noise_adds_nothing() {
    let (data, truth) = common::noisy_simulated_wafer(10, 10, 0.0, 10.0);
    let cfg = PipelineConfig {
        band_hz: Some((20.0, 2000.0)),
        diagnose: true,
        ..Default::default()
    };
    let out = run(&data, "simulated, 10x noise", &cfg, "diagnose").unwrap();
    let s = &out.summary;
    let accepted: Vec<&str> = s
        .steps
        .iter()
        .filter(|x| x.accepted)
        .map(|x| x.effect())
        .collect();
    println!(
        "10x noise: verdict {}, {} modes, residual/noise {:.3}, accepted {accepted:?}, restart {:?}",
        s.verdict,
        s.final_model.modes.len(),
        s.final_errors.residual_to_noise,
        s.initial.restart.as_ref().map(|r| &r.from)
    );
    assert!(accepted.is_empty(), "nothing added: {accepted:?}");
    assert_eq!(s.verdict, "noise_limited");
    // the model against the exact response: well below the data's own noise
    let err = common::median_rel_vs_truth(&out, &truth, 20.0, 2000.0);
    let noise = s.data_noise_median_rel.unwrap();
    println!("10x noise: final model vs exact median {err:.3e}, data noise {noise:.3e}");
    assert!(
        err < 0.5 * noise,
        "{err:.3e} vs the data's noise {noise:.3e}"
    );
}
