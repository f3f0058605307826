//! `PipelineConfig::final_analysis`: `frfit fit` without `--report` skips the final
//! residual analysis and the line-to-line floor comparison (it prints neither). The
//! model, its errors and the data's noise level are those of the analysed run; only the
//! verdict is `not_analysed`.

mod common;

use frfit::pipeline::{PipelineConfig, NOT_ANALYSED};
use frfit::run::run;

#[test]
fn a_fit_without_the_final_analysis_is_the_same_fit_without_a_verdict() {
    let (data, _, _) = common::simulate(&common::Sim {
        period: 20_000,
        periods: 4,
        realizations: 10,
        ..common::Sim::default()
    });
    let analysed = run(&data, "simulated", &PipelineConfig::default(), "fit").unwrap();
    let cfg = PipelineConfig {
        final_analysis: false,
        ..Default::default()
    };
    let skipped = run(&data, "simulated", &cfg, "fit").unwrap();
    let (a, s) = (&analysed.summary, &skipped.summary);
    println!(
        "verdicts {} / {}; residual/noise {:.4} / {:.4}; data noise {:?} / {:?}",
        a.verdict,
        s.verdict,
        a.final_errors.residual_to_noise,
        s.final_errors.residual_to_noise,
        a.data_noise_median_rel,
        s.data_noise_median_rel
    );
    assert_eq!(a.verdict, "noise_limited");
    assert_eq!(s.verdict, NOT_ANALYSED);
    assert!(s.distortion.is_none());
    assert_eq!(a.final_errors.median_rel, s.final_errors.median_rel);
    assert_eq!(
        a.final_errors.residual_to_noise,
        s.final_errors.residual_to_noise
    );
    assert_eq!(a.data_noise_median_rel, s.data_noise_median_rel);
    assert!(s.data_noise_median_rel.is_some());
    assert_eq!(a.final_model.modes.len(), s.final_model.modes.len());
    for (x, y) in a.final_model.modes.iter().zip(&s.final_model.modes) {
        assert_eq!(x.f_hz, y.f_hz);
    }
}
