//! `frfit nonparametric`: the nonparametric FRF of periodic measurements, from MATLAB
//! `.mat` time records (one file per experiment) or from a periodic spectra CSV, written
//! as an FRF CSV with `_var` columns.
//!
//! `frfit nonparametric rec.mat --input iq_adx --output theta_mx,-theta_my --fs 2500
//! --period 2500 --drop-periods 1 --out frf.csv`: a leading `-` on a signal name flips
//! its sign; `NAME:COL` takes column `COL` (1-based) of a matrix variable.

use clap::Args as ClapArgs;
use frf_data::FrfDataset;
use frfit::nonparametric::{
    estimate_described, parse_lines, spectra_from_files, Estimated, RecordSpec,
};
use frfit::FrfitError;
use std::path::PathBuf;

/// How to read and cut time records: the options `frfit nonparametric` and `frfit
/// predict` share.
#[derive(ClapArgs, Debug, Clone)]
pub struct RecordArgs {
    /// Input signal names in the .mat files, comma separated (`-NAME` flips the sign,
    /// `NAME:COL` takes a matrix column); for a `.npz`, the input array's name (default
    /// `u`).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub input: Vec<String>,
    /// Output signal names, comma separated (same syntax as `--input`); for a `.npz`,
    /// the output array's name (default `y`).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub output: Vec<String>,
    /// Sample rate, Hz (default: the scalar `fs` of the .mat file, when it has one).
    #[arg(long)]
    pub fs: Option<f64>,
    /// Samples per period (NumPy records with a periods axis: the first axis's length).
    #[arg(long)]
    pub period: Option<usize>,
    /// Leading periods dropped as transient.
    #[arg(long, default_value_t = 0)]
    pub drop_periods: usize,
    /// The excited lines are the top cluster of the period-averaged input power, cut at
    /// the largest drop between lines within this many dB of the strongest.
    #[arg(long, default_value_t = 40.0)]
    pub line_threshold_db: f64,
    /// The excited DFT bins, when the line detection should not guess them: bins `K`
    /// and ranges `A-B` or `A-B/S` (step S), comma separated (`1-999/2`: the odd bins).
    #[arg(long, value_parser = parse_lines, value_name = "K,A-B/S,..")]
    pub lines: Option<Vec<usize>>,
}

impl RecordArgs {
    /// The record options as the library takes them, with `realizations`.
    pub fn spec(&self, realizations: Option<usize>) -> RecordSpec {
        RecordSpec {
            inputs: self.input.clone(),
            outputs: self.output.clone(),
            fs: self.fs,
            period: self.period,
            drop_periods: self.drop_periods,
            lines: self.lines.clone(),
            line_threshold_db: self.line_threshold_db,
            realizations,
        }
    }
}

/// Arguments of `frfit nonparametric`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Input files: `.mat` time records (one per experiment), NumPy records (one `.npz`
    /// with `u` and `y`, or `u.npy y.npy`) or one periodic spectra `.csv`.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// How to read and cut the records.
    #[command(flatten)]
    pub rec: RecordArgs,
    /// How many random-phase realizations the experiments (files, in the order given)
    /// form, as consecutive blocks. Default: blocks of as many experiments as there are
    /// inputs (6 files of a 3-input system: 2 realizations). With 2 or more the `_var`
    /// columns hold the total variance (noise and nonlinear distortion) and `_var_noise`
    /// its noise part.
    #[arg(long, value_name = "R")]
    pub realizations: Option<usize>,
    /// Output FRF CSV.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `frfit nonparametric`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let spec = args.rec.spec(args.realizations);
    let (spectra, notes) = spectra_from_files(&args.files, &spec)?;
    let sources: Vec<String> = args.files.iter().map(|f| f.display().to_string()).collect();
    let Estimated {
        estimate: est,
        comments,
    } = estimate_described(&spectra, &sources, &spec, notes)?;
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
            rec: RecordArgs {
                input: vec!["iq_adx".into()],
                output: vec!["theta_mx".into(), "-theta_my".into()],
                fs: None,
                period: Some(2500),
                drop_periods: 1,
                line_threshold_db: 40.0,
                lines: None,
            },
            realizations: None,
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
        a.rec.input.clear();
        a.rec.output.clear();
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
        a.rec.output = vec!["ms".into()];
        assert!(run(a, true).unwrap_err().to_string().contains("struct"));
        let mut a = base(vec![mat.clone()], dir.join("x.csv"));
        a.rec.period = None;
        assert!(run(a, true).is_err());
        let mut a = base(vec![mat], dir.join("x.csv"));
        a.rec.input = vec!["nothere".into()];
        assert!(run(a, true).unwrap_err().to_string().contains("nothere"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
