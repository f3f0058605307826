//! `frfit fit`'s hold start (issue 41): data that state their sample rate but no hold
//! (what `frfit nonparametric` writes from time records) and reach far toward Nyquist
//! are fitted without and with the exact zero-order hold, and the fit with the smaller
//! final prediction error is kept. A plant measured through a converter's hold gets the
//! hold and its modes, no more; the same plant measured without a hold keeps the fit
//! without it. The modes of the CLI tests' 2 x 3 plant (35, 80, 150 Hz), 5..200 Hz, a
//! sample rate of 500 Hz (the band reaches 0.4 of it), exact values with a variance of
//! `(1e-3 |G|)^2`.

mod common;
use common::*;
use frf_data::Frf;
use frfit::pipeline::PipelineConfig;
use frfit::run::run;
use realize::{FrfModel, Hold};
use std::f64::consts::TAU;

const FS: f64 = 500.0;

/// The plant's modes seen through `hold`, with the comment `frfit nonparametric` writes
/// for records at [`FS`].
fn data(hold: Hold) -> Frf {
    let mut modal = plant();
    modal.rigid.clear();
    let mut m = FrfModel::new(modal);
    m.factors.hold = hold;
    let f: Vec<f64> = (0..781).map(|k| 5.0 + 0.25 * k as f64).collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let frf = Frf::from_grid(f, m.freq_response(&w).unwrap()).unwrap();
    let mut frf = with_relative_variance(frf, 1e-3);
    frf.comments
        .push(frfit::nonparametric::sampling_comment(FS));
    frf
}

fn fit(data: &Frf) -> frfit::run::PipelineOutput {
    let out = run(data, "plant", &PipelineConfig::default(), "fit").unwrap();
    for m in &out.fit.messages {
        println!("  {m}");
    }
    out
}

fn assert_modes(out: &frfit::run::PipelineOutput) {
    let fm = &out.summary.final_model;
    let f: Vec<f64> = fm.modes.iter().map(|m| m.f_hz).collect();
    assert_eq!(f.len(), MODES_HZ.len(), "{f:?}");
    for (a, b) in f.iter().zip(MODES_HZ) {
        assert!((a / b - 1.0).abs() < 1e-6, "{f:?}");
    }
    let c = fm.convergence.to_ascii_lowercase();
    assert!(!c.contains("not converged") && !c.contains("failed"), "{c}");
}

#[test]
fn a_plant_measured_through_a_hold_gets_the_hold_and_its_modes() {
    let out = fit(&data(Hold::Zoh { fs_hz: FS }));
    assert_eq!(out.summary.final_model.hold, format!("zoh:{FS}"));
    assert_modes(&out);
    assert!(
        out.fit
            .messages
            .iter()
            .any(|m| m.starts_with("hold start:") && m.contains("the fit with the hold is kept")),
        "{:?}",
        out.fit.messages
    );
    // both runs are on the record, the held one named and kept
    let runs = &out.summary.chain_runs;
    assert!(
        runs.iter()
            .any(|r| r.kept && r.hold.as_deref() == Some("zoh:500")),
        "{runs:?}"
    );
    assert!(runs.iter().any(|r| r.hold.is_none()), "{runs:?}");
}

#[test]
fn a_plant_measured_without_a_hold_keeps_the_fit_without_it() {
    let out = fit(&data(Hold::None));
    assert_eq!(out.summary.final_model.hold, "none");
    assert_modes(&out);
    assert!(
        out.fit
            .messages
            .iter()
            .any(|m| m.starts_with("hold start:") && m.contains("the fit without it is kept")),
        "{:?}",
        out.fit.messages
    );
}
