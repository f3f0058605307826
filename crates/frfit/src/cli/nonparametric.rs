//! `frfit nonparametric`: the nonparametric FRF of periodic measurements, from MATLAB
//! `.mat` time records (one file per experiment) or from a periodic spectra CSV, written
//! as an FRF CSV with `_var` columns.
//!
//! `frfit nonparametric rec.mat --input iq_adx --output theta_mx,-theta_my --fs 2500
//! --period 2500 --drop-periods 1 --out frf.csv`: a leading `-` on a signal name flips
//! its sign; `NAME:COL` takes column `COL` (1-based) of a matrix variable.

use clap::Args as ClapArgs;
use experiment::matfile::MatFile;
use experiment::nonparametric::spectra_csv::read_spectra_csv;
use experiment::nonparametric::time_records::{
    spectra_from_records, ExperimentRecords, RecordConfig,
};
use experiment::nonparametric::{estimate, EstimatorConfig, PeriodicSpectra};
use frf_data::FrfDataset;
use frfit::FrfitError;
use std::path::{Path, PathBuf};

/// Arguments of `frfit nonparametric`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Input files: `.mat` time records (one per experiment) or one periodic spectra
    /// `.csv`.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Input signal names in the .mat files, comma separated (`-NAME` flips the sign,
    /// `NAME:COL` takes a matrix column).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub input: Vec<String>,
    /// Output signal names, comma separated (same syntax as `--input`).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub output: Vec<String>,
    /// Sample rate, Hz (default: the scalar `fs` of the .mat file, when it has one).
    #[arg(long)]
    pub fs: Option<f64>,
    /// Samples per period.
    #[arg(long)]
    pub period: Option<usize>,
    /// Leading periods dropped as transient.
    #[arg(long, default_value_t = 0)]
    pub drop_periods: usize,
    /// The excited lines are the top cluster of the period-averaged input power, cut at
    /// the largest drop between lines within this many dB of the strongest.
    #[arg(long, default_value_t = 40.0)]
    pub line_threshold_db: f64,
    /// Output FRF CSV.
    #[arg(long)]
    pub out: PathBuf,
}

fn is_mat(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mat"))
}

/// A signal spec with an optional leading `-`: (sign, name).
fn signed(spec: &str) -> (f64, &str) {
    match spec.trim().strip_prefix('-') {
        Some(rest) => (-1.0, rest.trim()),
        None => (1.0, spec.trim()),
    }
}

fn load_mat_records(args: &Args) -> Result<(PeriodicSpectra, Vec<String>), FrfitError> {
    if args.input.is_empty() || args.output.is_empty() {
        return Err(FrfitError::argument(
            "--input/--output",
            format!("{:?} / {:?}", args.input, args.output),
            "name the input and output signals of the .mat files (e.g. --input iq_adx --output theta_mx,theta_my)",
        ));
    }
    let mut experiments = Vec::with_capacity(args.files.len());
    let mut fs_file = None;
    let mut notes = Vec::new();
    for f in &args.files {
        if !is_mat(f) {
            return Err(FrfitError::argument(
                "files",
                f.display(),
                "mix of file kinds: give either .mat files or one periodic spectra .csv",
            ));
        }
        let m = MatFile::read(f)?;
        if fs_file.is_none() {
            fs_file = m.scalar("fs");
        }
        let get = |spec: &String| -> Result<Vec<f64>, FrfitError> {
            let (s, name) = signed(spec);
            let mut x = m.signal(name)?;
            if s < 0.0 {
                x.iter_mut().for_each(|v| *v = -*v);
            }
            Ok(x)
        };
        let inputs = args.input.iter().map(get).collect::<Result<Vec<_>, _>>()?;
        let outputs = args.output.iter().map(get).collect::<Result<Vec<_>, _>>()?;
        if !m.skipped.is_empty() {
            notes.push(format!(
                "{}: skipped non-numeric variables {}",
                f.display(),
                m.skipped
                    .iter()
                    .map(|(n, k)| format!("{n} ({k})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        experiments.push(ExperimentRecords { inputs, outputs });
    }
    let fs = match (args.fs, fs_file) {
        (Some(v), _) => v,
        (None, Some(v)) => v,
        (None, None) => {
            return Err(FrfitError::argument(
                "--fs",
                "missing",
                "give the sample rate (the .mat file has no scalar `fs`)",
            ))
        }
    };
    let period = args.period.ok_or_else(|| {
        FrfitError::argument(
            "--period",
            "missing",
            "give the number of samples per period",
        )
    })?;
    let cfg = RecordConfig {
        fs,
        period,
        drop_periods: args.drop_periods,
        bins: None,
        line_threshold_db: args.line_threshold_db,
    };
    let spectra = spectra_from_records(&experiments, &cfg)?;
    Ok((spectra, notes))
}

/// Runs `frfit nonparametric`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    for f in &args.files {
        if !f.is_file() {
            return Err(FrfitError::Io {
                path: f.display().to_string(),
                message: "no such file".into(),
            });
        }
    }
    let (spectra, mut notes) = if args.files.iter().any(|f| is_mat(f)) {
        load_mat_records(&args)?
    } else {
        if args.files.len() != 1 {
            return Err(FrfitError::argument(
                "files",
                args.files.len(),
                "give one periodic spectra CSV (it holds every experiment and realization)",
            ));
        }
        (read_spectra_csv(&args.files[0])?, Vec::new())
    };
    let est = estimate(&spectra, &EstimatorConfig::default())?;
    let sources: Vec<String> = args.files.iter().map(|f| f.display().to_string()).collect();
    let mut comments = vec![format!("nonparametric FRF of {}", sources.join(", "))];
    if !args.input.is_empty() {
        comments.push(format!(
            "inputs {}; outputs {}",
            args.input.join(","),
            args.output.join(",")
        ));
    }
    comments.extend(spectra.comments.iter().cloned());
    comments.append(&mut notes);
    comments.push(format!(
        "estimator: G = mean_p(Y_p) mean_p(U_p)^-1 per realization, mean over {} realization(s); {} periods, {} experiment(s); variance: {}",
        est.realizations,
        est.periods,
        est.n_experiments,
        est.frf.metadata.get("variance").cloned().unwrap_or_default()
    ));
    frf_data::io::write_frf_csv(&args.out, &est.frf, &comments)?;
    if !quiet {
        let n = est.frf.n_lines();
        eprintln!(
            "{} lines {}..{} Hz, {}x{}, {} periods x {} realization(s) -> {}",
            n,
            est.frf.freq_hz(0),
            est.frf.freq_hz(n - 1),
            est.frf.ny(),
            est.frf.nu(),
            est.periods,
            est.realizations,
            args.out.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base(files: Vec<PathBuf>, out: PathBuf) -> Args {
        Args {
            files,
            input: vec!["iq_adx".into()],
            output: vec!["theta_mx".into(), "-theta_my".into()],
            fs: None,
            period: Some(2500),
            drop_periods: 1,
            line_threshold_db: 40.0,
            out,
        }
    }

    #[test]
    fn reproduces_the_motor_bench_frf_from_the_mat_file_and_the_spectra() {
        let Some(mat) =
            frf_data::shared_data::require("cli_nonparametric", "real/fditools_motorbench_msA.mat")
        else {
            return;
        };
        let Some(per) = frf_data::shared_data::require(
            "cli_nonparametric",
            "real/fditools_motorbench_msA.periods.csv",
        ) else {
            return;
        };
        let Some(refp) =
            frf_data::shared_data::require("cli_nonparametric", "real/fditools_motorbench_msA.csv")
        else {
            return;
        };
        let reference = frf_data::io::read_frf_csv(&refp).unwrap();
        let dir = std::env::temp_dir().join(format!("frfit_np_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // fs from the file's scalar `fs`, y2 sign flipped as in the reference
        let out = dir.join("mat.csv");
        run(base(vec![mat.clone()], out.clone()), true).unwrap();
        let out2 = dir.join("per.csv");
        let mut a = base(vec![per], out2.clone());
        a.input.clear();
        a.output.clear();
        run(a, true).unwrap();
        for o in [out, out2] {
            let est = frf_data::io::read_frf_csv(&o).unwrap();
            assert_eq!(est.freqs_hz(), reference.freqs_hz());
            for k in 0..est.n_lines() {
                for i in 0..2 {
                    let (g, g0) = (est.value(k, i, 0), reference.value(k, i, 0));
                    assert!((g - g0).norm() < 1e-6 * g0.norm());
                    let (v, v0) = (
                        est.variance(k, i, 0).unwrap(),
                        reference.variance(k, i, 0).unwrap(),
                    );
                    assert!((v - v0).abs() < 0.1 * v0);
                }
            }
        }
        // errors: a struct variable, no period, unknown signal
        let mut a = base(vec![mat.clone()], dir.join("x.csv"));
        a.output = vec!["ms".into()];
        assert!(run(a, true).unwrap_err().to_string().contains("struct"));
        let mut a = base(vec![mat.clone()], dir.join("x.csv"));
        a.period = None;
        assert!(run(a, true).is_err());
        let mut a = base(vec![mat], dir.join("x.csv"));
        a.input = vec!["nothere".into()];
        assert!(run(a, true).unwrap_err().to_string().contains("nothere"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn signed_names() {
        assert_eq!(signed("-theta_my"), (-1.0, "theta_my"));
        assert_eq!(signed("theta_mx"), (1.0, "theta_mx"));
        assert_eq!(signed(" x:3"), (1.0, "x:3"));
    }
}
