//! `frfit eval MODEL.json --at DATA --out PRED.csv`: the model's response at the data's
//! frequencies, with the delay, hold and dynamics it was fitted with, as an FRF CSV that
//! compares directly with DATA.

use super::common::load_data;
use clap::Args as ClapArgs;
use frf_data::{Frf, FrfDataset, ModelStructure};
use frfit::additive_riv::ModelFile;
use frfit::FrfitError;
use std::path::PathBuf;

/// Arguments of `frfit eval`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The model (JSON written by `frfit fit` or `frfit diagnose`).
    pub model: PathBuf,
    /// FRF file whose frequencies to evaluate at (and to compare with).
    #[arg(long, value_name = "DATA")]
    pub at: PathBuf,
    /// Write the model's response here (FRF CSV).
    #[arg(long, value_name = "PRED.csv")]
    pub out: PathBuf,
}

/// Runs `frfit eval`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let file = ModelFile::read(&args.model).map_err(|e| FrfitError::Io {
        path: args.model.display().to_string(),
        message: e.to_string(),
    })?;
    let model = file.to_model().map_err(|e| FrfitError::Io {
        path: args.model.display().to_string(),
        message: e.to_string(),
    })?;
    let data = load_data(&args.at)?;
    if (data.ny(), data.nu()) != (model.ny(), model.nu()) {
        return Err(FrfitError::argument(
            "--at",
            args.at.display(),
            format!(
                "the data are {}x{} but the model is {}x{}",
                data.ny(),
                data.nu(),
                model.ny(),
                model.nu()
            ),
        ));
    }
    let f = data.freq_hz_slice().to_vec();
    if f.first() == Some(&0.0) && file.rigid_body.is_some() {
        return Err(FrfitError::argument(
            "--at",
            args.at.display(),
            "the data hold a 0 Hz line, where the model's rigid body (integrators) is infinite",
        ));
    }
    let grid = model.response_at(&data.omegas());
    let mut pred = Frf::from_grid(f, grid)?;
    pred.units = file.units.clone().or(data.units.clone());
    let comments = vec![
        format!(
            "frfit eval: response of {} at the lines of {}",
            args.model.display(),
            args.at.display()
        ),
        format!(
            "model: {} modes, hold {}, delay {:.4} us, band {:?} Hz; {}",
            file.modes.len(),
            file.hold,
            file.delay_s * 1e6,
            file.band_hz,
            file.provenance.estimator
        ),
    ];
    frf_data::io::write_frf_csv(&args.out, &pred, &comments)?;
    if !quiet {
        let (mut rel, m) = (Vec::new(), data.n_entries());
        for k in 0..data.n_lines() {
            for e in 0..m {
                let g = data.values()[k * m + e];
                if g.norm() > 0.0 {
                    rel.push((pred.values()[k * m + e] - g).norm() / g.norm());
                }
            }
        }
        rel.sort_by(|a, b| a.total_cmp(b));
        if !rel.is_empty() {
            println!(
                "relative error vs {}: median {:.3e}, p95 {:.3e} ({} lines)",
                args.at.display(),
                rel[rel.len() / 2],
                rel[((rel.len() - 1) as f64 * 0.95) as usize],
                data.n_lines()
            );
        }
        println!("prediction written to {}", args.out.display());
    }
    Ok(())
}
