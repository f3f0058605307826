//! A variance estimated from few realizations is itself noisy: `|E|^2 / var` follows an
//! F rather than a chi-square distribution, its mean is inflated by `d2 / (d2 - 2)`
//! (2 with 3 realizations) and its tail is polynomial. When the file says how many
//! realizations the variance came from, the residual analysis accounts for it, and a
//! model at the noise level is called noise-limited. Simulated wafer stage, no files.

mod common;

use frf_data::Frf;
use frfit::pipeline::{run, PipelineConfig};

/// The wafer stage (seed 3), 2 periods x 3 realizations, lines up to 2 kHz, with the
/// comments `frfit simulate` writes.
fn three_realizations() -> Frf {
    common::simulated_wafer(2, 3, 0.0).0
}

#[test]
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
            .map(|x| &x.effect)
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
    // sqrt(d2 / (d2 - 2)) = sqrt(2): the inflation of an estimated variance
    assert!((s.final_errors.residual_to_noise - 2f64.sqrt()).abs() < 0.1);

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
