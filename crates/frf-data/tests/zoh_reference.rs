//! Reference test of the exact zero-order-hold response: the noiseless wafer-stage FRF
//! `wafer_nominal.noiseless.csv` (11 significant digits) must be reproduced from its truth
//! model `wafer_nominal.truth.json` (continuous plant, ZOH at 10 kHz, one sample of
//! computation delay) to 1e-8 relative at every line, both by the closed-form modal ZOH
//! response and by the state-space route (real modal realization, augmented-matrix-
//! exponential discretization, Hessenberg frequency response, times `z^-1`).
//!
//! Skips with a message when the shared data directory is absent (a fresh clone).

use frf_data::io::read_frf_csv;
use frf_data::truth::Truth;
use frf_data::{FrfDataset, C64};
use realize::ResponseGrid;

/// Per line `max_entry |G_model - G_file| / max_entry |G_file|`, and the worst line.
fn worst_line_error(model: &ResponseGrid, file: &frf_data::Frf) -> (f64, usize) {
    let mut worst = (0.0f64, 0usize);
    for k in 0..file.n_lines() {
        let (gm, gf) = (model.line(k), file.line(k));
        let num = gm
            .iter()
            .zip(gf)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        let den = gf.iter().map(|b| b.norm()).fold(0.0, f64::max);
        let e = num / den;
        if e.is_nan() || e > worst.0 {
            worst = (e, k);
        }
    }
    worst
}

#[test]
fn wafer_nominal_noiseless_is_the_zoh_response_of_its_truth_model() {
    let Some(p) = frf_data::shared_data::require("zoh_reference", "wafer_nominal.noiseless.csv")
    else {
        return;
    };
    let Some(tp) = frf_data::shared_data::require("zoh_reference", "wafer_nominal.truth.json")
    else {
        return;
    };
    let frf = read_frf_csv(&p).expect("reading the noiseless CSV");
    let truth = Truth::read(&tp).expect("reading the truth JSON");
    assert_eq!(truth.fs, 1e4, "the reference is sampled at 10 kHz");
    let ts = 1e-4;
    let model = truth.modal_model().expect("truth modal model");
    assert_eq!((model.ny, model.nu), (frf.ny(), frf.nu()));
    let omega = frf.omegas();

    // Closed-form modal ZOH response with one sample of computation delay.
    let g_modal = model
        .zoh_response(&omega, ts, 1.0)
        .expect("modal ZOH response");
    let (e_modal, k_modal) = worst_line_error(&g_modal, &frf);

    // State-space route: realization, exact discretization, response, times z^-1.
    let ss = model.to_state_space(1e-12).expect("real modal realization");
    let sd = ss.discretize_zoh(ts).expect("ZOH discretization");
    let mut g_ss = sd.freq_response(&omega).expect("discrete response");
    for (k, &w) in omega.iter().enumerate() {
        let z_inv = C64::from_polar(1.0, -w * ts);
        for v in g_ss.line_mut(k) {
            *v *= z_inv;
        }
    }
    let (e_ss, k_ss) = worst_line_error(&g_ss, &frf);

    println!(
        "zoh_reference: {} lines, {}x{}, {} states; max line relative error: modal {e_modal:.3e} \
         (at {:.3} Hz), state space {e_ss:.3e} (at {:.3} Hz)",
        frf.n_lines(),
        frf.ny(),
        frf.nu(),
        ss.n_states(),
        frf.freq_hz(k_modal),
        frf.freq_hz(k_ss),
    );
    assert!(
        e_modal < 1e-8,
        "modal ZOH response differs from the file by {e_modal:e} at {} Hz",
        frf.freq_hz(k_modal)
    );
    assert!(
        e_ss < 1e-8,
        "state-space ZOH response differs from the file by {e_ss:e} at {} Hz",
        frf.freq_hz(k_ss)
    );
}
