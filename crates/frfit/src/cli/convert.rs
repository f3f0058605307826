//! `frfit convert IN OUT`: an FRF file from one format to another, each chosen by its
//! extension: `.csv` (FRF CSV, any spreadsheet dialect on input, the plain one on
//! output), `.uff`/`.unv` (UFF dataset 58, ASCII or binary 58b on input; ASCII unless
//! `--uff-binary` on output), `.mat` (MATLAB level 5: `G`, `freq_hz`, `G_var`).
//!
//! CSV and `.mat` hold every bit; ASCII UFF holds 13 significant digits of the values
//! (`E20.12`), binary UFF every bit in double precision, 7 digits in single.

use super::common::load_data;
use clap::Args as ClapArgs;
use frf_data::io::{frf_csv_string, frf_mat_bytes, uff58_bytes, UffEncoding};
use frf_data::FrfDataset;
use frfit::FrfitError;
use std::path::{Path, PathBuf};

/// Arguments of `frfit convert`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Input FRF file: .csv, .uff/.unv or .mat.
    pub input: PathBuf,
    /// Output file: .csv, .uff/.unv or .mat (the format follows the extension).
    pub output: PathBuf,
    /// Write UFF as binary dataset 58b instead of ASCII.
    #[arg(long)]
    pub uff_binary: bool,
    /// With --uff-binary: single precision (4-byte floats) instead of double.
    #[arg(long, requires = "uff_binary")]
    pub single: bool,
    /// With --uff-binary: big-endian byte order instead of little-endian.
    #[arg(long, requires = "uff_binary")]
    pub big_endian: bool,
}

/// The output format of a path, by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OutFormat {
    Csv,
    Uff,
    Mat,
}

fn out_format(path: &Path) -> Result<OutFormat, FrfitError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("csv") => Ok(OutFormat::Csv),
        Some("uff" | "unv") => Ok(OutFormat::Uff),
        Some("mat") => Ok(OutFormat::Mat),
        _ => Err(FrfitError::argument(
            "OUT",
            path.display(),
            "the extension must be .csv, .uff/.unv or .mat",
        )),
    }
}

/// Runs `frfit convert`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let format = out_format(&args.output)?;
    if args.uff_binary && format != OutFormat::Uff {
        return Err(FrfitError::argument(
            "--uff-binary",
            args.output.display(),
            "applies to .uff/.unv output only",
        ));
    }
    let data = load_data(&args.input)?;
    let bytes = match format {
        OutFormat::Csv => {
            let mut comments = data.comments.clone();
            comments.push(format!("converted by frfit from {}", args.input.display()));
            frf_csv_string(&data, &comments).into_bytes()
        }
        OutFormat::Uff => {
            let encoding = if args.uff_binary {
                UffEncoding::Binary {
                    little_endian: !args.big_endian,
                    double: !args.single,
                }
            } else {
                UffEncoding::Ascii
            };
            uff58_bytes(&data, &data.metadata, encoding)?
        }
        OutFormat::Mat => frf_mat_bytes(&data),
    };
    std::fs::write(&args.output, bytes).map_err(|e| FrfitError::io(&args.output, e))?;
    if !quiet {
        let dropped = if data.has_variance() && format == OutFormat::Uff {
            " (UFF 58 holds no variance: the variances were left out)"
        } else {
            ""
        };
        eprintln!(
            "wrote {}: {} x {}, {} lines{dropped}",
            args.output.display(),
            data.ny(),
            data.nu(),
            data.n_lines()
        );
    }
    Ok(())
}
