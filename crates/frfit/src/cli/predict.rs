//! `frfit predict MODEL.json --records T1.mat ... --input .. --output .. --period N --out
//! DIR`: the model's periodic steady-state prediction of test records it never saw, the
//! NRMSE per output against the records' own noise floor (see [`frfit::predict`]),
//! written as `DIR/prediction.json` and `DIR/prediction.svg`.

use super::nonparametric::RecordArgs;
use clap::Args as ClapArgs;
use frfit::additive_riv::ModelFile;
use frfit::nonparametric::spectra_from_files;
use frfit::predict::predict;
use frfit::validation_report::model_response;
use frfit::FrfitError;
use std::path::PathBuf;

/// Arguments of `frfit predict`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The model (JSON written by `frfit fit` or `frfit diagnose`).
    pub model: PathBuf,
    /// Test records: `.mat` time records (one file per experiment), NumPy records (one
    /// `.npz`, or `u.npy y.npy`) or one periodic spectra `.csv`.
    #[arg(long, required = true, num_args = 1..)]
    pub records: Vec<PathBuf>,
    /// How to read and cut the records.
    #[command(flatten)]
    pub rec: RecordArgs,
    /// Output directory (prediction.json, prediction.svg).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Runs `frfit predict`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    // every record is compared on its own: the grouping does not matter here
    let spec = args.rec.spec(Some(1));
    let (spectra, _) = spectra_from_files(&args.records, &spec)?;
    let source = args.model.display().to_string();
    let file = ModelFile::read(&args.model).map_err(|e| FrfitError::Io {
        path: source.clone(),
        message: e.to_string(),
    })?;
    let omega: Vec<f64> = spectra
        .freq_hz
        .iter()
        .map(|f| f * std::f64::consts::TAU)
        .collect();
    let (g, desc) = model_response(&file, &source, &omega)?;
    let p = predict(&g, &spectra)?;
    p.write(
        &args.out,
        &format!("frfit predict: {source} on {} test record(s)", p.records),
    )?;
    if !quiet {
        println!(
            "{source} ({desc}) on {} record(s), {} periods, {} lines {:.6}..{:.6} Hz:",
            p.records,
            p.periods,
            p.freq_hz.len(),
            p.freq_hz.first().copied().unwrap_or(f64::NAN),
            p.freq_hz.last().copied().unwrap_or(f64::NAN)
        );
        for (i, o) in p.outputs.iter().enumerate() {
            println!(
                "  output {}: NRMSE {:.4e}{}",
                i + 1,
                o.nrmse,
                match (o.noise_floor, o.to_floor) {
                    (Some(f), Some(r)) => format!(", noise floor {f:.4e} ({r:.2} times the floor)"),
                    _ => " (one period: no noise floor)".into(),
                }
            );
        }
        println!("written to {}", args.out.display());
    }
    Ok(())
}
