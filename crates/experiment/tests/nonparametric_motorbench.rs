//! The real periodic data of the FdiTools motor bench: the nonparametric estimate from
//! the MATLAB time records and from the per-period spectra reproduces the published FRF
//! (`fditools_motorbench_msA.csv`): the same 240 lines 11..250 Hz, `G` within 1e-6
//! relative and the variance within 10 %. The file's comments state `y2 = -theta_my`.

use experiment::matfile::MatFile;
use experiment::nonparametric::spectra_csv::{read_spectra_csv, write_spectra_csv};
use experiment::nonparametric::time_records::{
    spectra_from_records, ExperimentRecords, RecordConfig,
};
use experiment::nonparametric::{estimate, EstimatorConfig};
use frf_data::io::read_frf_csv;
use frf_data::{Frf, FrfDataset};

/// Largest relative error of `G` and of the variance, `sign2` applied to output 2.
fn compare(est: &Frf, reference: &Frf, sign2: f64) -> (f64, f64) {
    assert_eq!(est.freqs_hz(), reference.freqs_hz());
    let (mut eg, mut ev): (f64, f64) = (0.0, 0.0);
    for k in 0..reference.n_lines() {
        for i in 0..2 {
            let s = if i == 1 { sign2 } else { 1.0 };
            let g = est.value(k, i, 0) * s;
            let g0 = reference.value(k, i, 0);
            eg = eg.max((g - g0).norm() / g0.norm());
            let (v, v0) = (
                est.variance(k, i, 0).unwrap(),
                reference.variance(k, i, 0).unwrap(),
            );
            ev = ev.max((v - v0).abs() / v0);
        }
    }
    (eg, ev)
}

#[test]
fn the_mat_file_is_read_and_its_non_numeric_variables_skipped() {
    let Some(p) =
        frf_data::shared_data::require("nonparametric_mat", "real/fditools_motorbench_msA.mat")
    else {
        return;
    };
    let m = MatFile::read(&p).unwrap();
    for n in ["iq_adx", "theta_mx", "theta_my"] {
        assert_eq!(m.signal(n).unwrap().len(), 50_000, "{n}");
    }
    assert_eq!(m.scalar("fs"), Some(2500.0));
    // stored as a compact integer type but a double in MATLAB
    assert_eq!(m.signal("msr").unwrap()[0], 2.0);
    let kinds: Vec<(&str, &str)> = m
        .skipped
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    println!("skipped: {kinds:?}");
    assert!(kinds.contains(&("BA", "object")), "the tf object");
    assert!(kinds.contains(&("ms", "struct")));
    assert!(kinds.contains(&("ctp", "char")));
    let e = m.signal("ms").unwrap_err();
    assert!(e.to_string().contains("struct"), "{e}");
    let e = m.signal("nope").unwrap_err();
    assert!(e.to_string().contains("no variable `nope`"), "{e}");
}

#[test]
fn time_records_reproduce_the_published_frf() {
    let Some(p) =
        frf_data::shared_data::require("nonparametric_mat", "real/fditools_motorbench_msA.mat")
    else {
        return;
    };
    let Some(rp) =
        frf_data::shared_data::require("nonparametric_mat", "real/fditools_motorbench_msA.csv")
    else {
        return;
    };
    let m = MatFile::read(&p).unwrap();
    let rec = ExperimentRecords {
        inputs: vec![m.signal("iq_adx").unwrap()],
        outputs: vec![m.signal("theta_mx").unwrap(), m.signal("theta_my").unwrap()],
    };
    let spectra = spectra_from_records(&[rec], &RecordConfig::new(2500.0, 2500, 1)).unwrap();
    assert_eq!(spectra.n_lines(), 240);
    assert_eq!(spectra.freq_hz[0], 11.0);
    assert_eq!(spectra.freq_hz[239], 250.0);
    assert_eq!(spectra.realizations[0].periods(), 19);
    let est = estimate(&spectra, &EstimatorConfig::default()).unwrap();
    let reference = read_frf_csv(&rp).unwrap();
    let (eg, ev) = compare(&est.frf, &reference, -1.0);
    println!("from the .mat time records: G rel. error {eg:.2e}, variance rel. error {ev:.2e}");
    assert!(eg < 1e-6, "{eg}");
    assert!(ev < 0.1, "{ev}");
    // the line detection has a wide margin: weakest excited vs strongest other line
    let strict = RecordConfig {
        line_threshold_db: 20.0,
        ..RecordConfig::new(2500.0, 2500, 1)
    };
    let rec = ExperimentRecords {
        inputs: vec![m.signal("iq_adx").unwrap()],
        outputs: vec![m.signal("theta_mx").unwrap()],
    };
    assert_eq!(
        spectra_from_records(&[rec], &strict).unwrap().n_lines(),
        240
    );
}

#[test]
fn period_spectra_csv_reproduces_the_published_frf_and_round_trips() {
    let Some(p) = frf_data::shared_data::require(
        "nonparametric_csv",
        "real/fditools_motorbench_msA.periods.csv",
    ) else {
        return;
    };
    let Some(rp) =
        frf_data::shared_data::require("nonparametric_csv", "real/fditools_motorbench_msA.csv")
    else {
        return;
    };
    let spectra = read_spectra_csv(&p).unwrap();
    assert_eq!((spectra.ny, spectra.nu, spectra.n_lines()), (2, 1, 240));
    let est = estimate(&spectra, &EstimatorConfig::default()).unwrap();
    assert_eq!(est.periods, 19);
    let reference = read_frf_csv(&rp).unwrap();
    // the spectra file already carries y2 = -theta_my
    let (eg, ev) = compare(&est.frf, &reference, 1.0);
    println!("from the periods CSV: G rel. error {eg:.2e}, variance rel. error {ev:.2e}");
    assert!(eg < 1e-6, "{eg}");
    assert!(ev < 0.1, "{ev}");
    // the disturbance covariance is Hermitian with the period variances on its diagonal
    let cv = est.disturbance_at(0).unwrap();
    assert!(cv[0].re > 0.0 && cv[3].re > 0.0);
    assert!((cv[1] - cv[2].conj()).norm() <= 1e-12 * cv[0].norm());
    // write and read back
    let dir = std::env::temp_dir().join(format!("frfit_spectra_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("spectra.csv");
    write_spectra_csv(&out, &spectra, &["round trip".to_string()]).unwrap();
    let back = read_spectra_csv(&out).unwrap();
    assert_eq!(back.freq_hz, spectra.freq_hz);
    let a = &back.realizations[0];
    let b = &spectra.realizations[0];
    for (x, y) in a
        .input
        .iter()
        .chain(&a.output)
        .zip(b.input.iter().chain(&b.output))
    {
        assert!((x - y).norm() <= 1e-9 * y.norm());
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_records_give_clear_errors() {
    let x: Vec<f64> = (0..100).map(|t| (t as f64 * 0.3).sin()).collect();
    let rec = |n: usize| ExperimentRecords {
        inputs: vec![x[..n].to_vec()],
        outputs: vec![x[..n].to_vec()],
    };
    // fewer whole periods than dropped
    let e = spectra_from_records(&[rec(100)], &RecordConfig::new(100.0, 50, 2)).unwrap_err();
    assert!(
        e.to_string().contains("at least one period must remain"),
        "{e}"
    );
    // different lengths
    let mut r = rec(100);
    r.outputs[0].pop();
    assert!(spectra_from_records(&[r], &RecordConfig::new(100.0, 50, 0)).is_err());
    // an input without periodic content
    let zero = ExperimentRecords {
        inputs: vec![vec![0.0; 100]],
        outputs: vec![x.clone()],
    };
    let e = spectra_from_records(&[zero], &RecordConfig::new(100.0, 50, 0)).unwrap_err();
    assert!(e.to_string().contains("no excited line"), "{e}");
    // a file that is not a .mat
    let e = MatFile::from_bytes(b"not a mat file at all", "x.mat").unwrap_err();
    assert!(e.to_string().contains("x.mat"), "{e}");
    let junk = vec![7u8; 4096];
    assert!(MatFile::from_bytes(&junk, "junk.mat").is_err());
}
