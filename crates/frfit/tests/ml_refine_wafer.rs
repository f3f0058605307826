//! `--init cmif --refine ml` on the reference wafer stage through the chain API:
//! the maximum-likelihood refinement against the noiseless response, and the standard
//! deviations of the 17 modes. Skipped, with a message, when `../shared/data` is absent.

use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::{ChainSettings, DelayChoice, FrfDataset};
use frfit::chain::{run_chain, AdditiveOptions};
use ml_refine::MlReport;
use realize::Hold;
use std::time::Instant;

#[test]
fn wafer_nominal_cmif_then_ml() {
    let test = "wafer_nominal_cmif_then_ml";
    let (Some(data), Some(clean)) = (
        require(test, "wafer_nominal.csv"),
        require(test, "wafer_nominal.noiseless.csv"),
    ) else {
        return;
    };
    let data = read_frf_csv(&data).unwrap();
    let clean = read_frf_csv(&clean).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let clean = clean.band(20.0, 2000.0).unwrap();
    let settings = ChainSettings {
        // the file declares the 10 kHz hold in its comments; `frfit fit` models it
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Auto,
        ..Default::default()
    };
    let t = Instant::now();
    // the file's comments declare 10 realizations, as `frfit fit` reads them
    let opts = AdditiveOptions {
        realizations: Some(10),
        ..Default::default()
    };
    let r = run_chain(&band, "cmif", "ml", &settings, &opts).unwrap();
    let secs = t.elapsed().as_secs_f64();
    let w = clean.omegas();
    let g = realize::ResponseGrid {
        ny: clean.ny(),
        nu: clean.nu(),
        values: clean.values_vec(),
    };
    let (median, p95) = r.model.model.relative_error(&w, &g).unwrap();
    let ml = r.links.iter().find(|l| l.link == "ml").unwrap();
    let rep: &MlReport = ml.details_as().unwrap();
    let ml_secs = ml
        .timings
        .iter()
        .find(|t| t.stage == "total")
        .map(|t| t.seconds)
        .unwrap_or(f64::NAN);
    println!(
        "cmif+ml: median {median:.3e}, p95 {p95:.3e} vs noiseless; {} modes; {} iterations ({}); \
         cost ratio {:.4} (p {:?}), scale {:.3}, condition {:.2e}; ml {ml_secs:.2} s, chain {secs:.2} s; \
         delay {:?} +- {:?}; residues {}; notes {:?}",
        rep.modes.len(),
        rep.iterations,
        rep.convergence,
        rep.cost_ratio,
        rep.p_value,
        rep.covariance_scale,
        rep.information_condition,
        rep.delay_s,
        rep.delay_s_std,
        rep.residue_form,
        r.notes
    );
    for note in &ml.messages {
        println!("  ml: {note}");
    }
    println!("  cost history {:?}", rep.cost_history);
    for m in &rep.modes {
        println!(
            "  f {:10.4} +- {:.2e} Hz   zeta {:.5} +- {:.2e}",
            m.f_hz, m.f_hz_std, m.zeta, m.zeta_std
        );
    }
    assert!(rep.converged, "{}", rep.convergence);
    assert_eq!(rep.modes.len(), 17);
    for m in &rep.modes {
        assert!(m.f_hz_std.is_finite() && m.f_hz_std > 0.0, "{m:?}");
        assert!(m.zeta_std.is_finite() && m.zeta_std > 0.0, "{m:?}");
    }
    assert!(median <= 6e-6, "median {median:.3e}");
    // at the noise level of a 10-realization variance: E{V/N_dof} = 9/8
    assert!(
        (rep.cost_ratio / rep.expected_ratio - 1.0).abs() < 0.02,
        "{}",
        rep.cost_ratio
    );
}
