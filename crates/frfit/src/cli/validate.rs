//! `frfit validate MODEL.json --data VALIDATION.csv [--alpha 0.99] --out DIR`: the
//! smallest additive uncertainty per line that makes the model consistent with an
//! independent validation measurement (Oomen and Bosgra; `validation::validate_frf`),
//! written as `DIR/validation.json`, `DIR/report.md` and `DIR/gamma.svg`.
//!
//! The validation data must carry a variance (`_var` columns): the periodic measurement's
//! variance of the averaged FRF, from which the disturbance bound of each line follows
//! (Proposition 9, the averaging of Proposition 10 included). Only the model's response
//! at the validation lines is used, so any model the CLI can read can be validated.

use super::common::load_data;
use clap::{Args as ClapArgs, ValueEnum};
use frf_data::{FrfDataset, ModelStructure};
use frfit::additive_riv::ModelFile;
use frfit::realize::ResponseGrid;
use frfit::validation::{validate_frf, FrfValidation, FrfValidationConfig, GammaMethod};
pub use frfit::validation_report::verdict_text;
use frfit::validation_report::write_validation_dir;
use frfit::FrfitError;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How the per-column minimum is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// The exact closed form of additive uncertainty.
    ClosedForm,
    /// Bisection on the generalized structured singular value (Proposition 12).
    Mu,
}

/// Arguments of `frfit validate`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The model (JSON written by `frfit fit` or `frfit diagnose`).
    pub model: PathBuf,
    /// The validation FRF (CSV with `_var` columns), an independent measurement.
    #[arg(long, value_name = "VALIDATION.csv")]
    pub data: PathBuf,
    /// Probability that the disturbance bound of a line holds (for the whole output
    /// vector of each input column).
    #[arg(long, default_value_t = 0.99)]
    pub alpha: f64,
    /// Per-column minimum: closed form (exact for additive uncertainty) or mu bisection.
    #[arg(long, value_enum, default_value_t = Method::ClosedForm)]
    pub method: Method,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// The model's response at `omega` (rad/s) and a one-line description: the only place
/// the CLI reads a model file for validation.
fn model_response(path: &Path, omega: &[f64]) -> Result<(ResponseGrid, String), FrfitError> {
    let io = |e: &dyn std::fmt::Display| FrfitError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let file = ModelFile::read(path).map_err(|e| io(&e))?;
    let model = file.to_model().map_err(|e| io(&e))?;
    if omega.first() == Some(&0.0) && file.rigid_body.is_some() {
        return Err(FrfitError::argument(
            "--data",
            path.display(),
            "the data hold a 0 Hz line, where the model's rigid body (integrators) is infinite",
        ));
    }
    let desc = format!(
        "{} modes, hold {}, delay {:.4} us; {}",
        file.modes.len(),
        file.hold,
        file.delay_s * 1e6,
        file.provenance.estimator
    );
    Ok((model.response_at(omega), desc))
}

/// Runs `frfit validate`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    validate_into(&args, quiet).map(|_| ())
}

/// Validates `args.model` on `args.data`, writes `validation.json`, `gamma.svg` and
/// `report.md` into `args.out`, and returns the result (`frfit validate`, and
/// `frfit diagnose --validate` for its final model).
pub fn validate_into(args: &Args, quiet: bool) -> Result<FrfValidation, FrfitError> {
    let t0 = Instant::now();
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(FrfitError::argument(
            "--alpha",
            args.alpha,
            "a probability strictly between 0 and 1 (for example 0.99)",
        ));
    }
    let data = load_data(&args.data)?;
    let (grid, desc) = model_response(&args.model, &data.omegas())?;
    if (grid.ny, grid.nu) != (data.ny(), data.nu()) {
        return Err(FrfitError::argument(
            "--data",
            args.data.display(),
            format!(
                "the data are {}x{} but the model is {}x{}",
                data.ny(),
                data.nu(),
                grid.ny,
                grid.nu
            ),
        ));
    }
    let cfg = FrfValidationConfig {
        alpha: args.alpha,
        method: match args.method {
            Method::ClosedForm => GammaMethod::ClosedForm,
            Method::Mu => GammaMethod::Mu,
        },
        // a variance estimated from R realizations (the file's comments or metadata say
        // how many) has 2 (R - 1) real degrees of freedom
        variance_dof: frfit::declared::declared(&data)
            .realizations
            .filter(|&r| r >= 2)
            .map(|r| 2.0 * (r as f64 - 1.0)),
        ..Default::default()
    };
    let v = validate_frf(&grid, &data, None, &cfg).map_err(|e| FrfitError::Fit {
        what: "validation".into(),
        why: e.to_string(),
    })?;
    write_validation_dir(
        &args.out,
        &args.model.display().to_string(),
        &desc,
        &args.data.display().to_string(),
        &v,
        data.units.as_deref(),
    )?;
    if !quiet {
        println!(
            "{}: gamma max {:.3e}, median {:.3e} over {} lines ({:.2} s)",
            verdict_text(v.verdict),
            v.gamma_max,
            v.gamma_median,
            v.lines.len(),
            t0.elapsed().as_secs_f64()
        );
        println!("written to {}", args.out.display());
    }
    Ok(v)
}
