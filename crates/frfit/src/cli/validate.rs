//! `frfit validate MODEL.json --data VALIDATION.csv [--alpha 0.99] --out DIR`: the
//! smallest additive uncertainty per line that makes the model consistent with an
//! independent validation measurement (Oomen and Bosgra; `validation::validate_frf`),
//! written as `DIR/validation.json`, `DIR/report.md` and `DIR/gamma.svg`.
//!
//! The validation data must carry a variance (`_var` columns): the periodic measurement's
//! variance of the averaged FRF, from which the disturbance bound of each line follows
//! (Proposition 9, the averaging of Proposition 10 included). Only the model's response
//! at the validation lines is used, so any model the CLI can read can be validated.
//!
//! With `--fit-data FIT.csv` (the data the model was fitted to; the band is the one the
//! model file records) the model's own uncertainty is read next to the data's: the
//! standard deviation of its response at the validation lines from the information on
//! its fit data (`validation::validate_frf_with_model_std`). `frfit diagnose --validate`
//! does this for its final model on its own data.

use super::common::load_data;
use clap::{Args as ClapArgs, ValueEnum};
use frfit::additive_riv::ModelFile;
use frfit::validation::{FrfValidation, GammaMethod};
pub use frfit::validation_report::verdict_text;
use frfit::validation_report::{check_alpha, validate_model, write_validation_dir, FitDataOfModel};
use frfit::FrfitError;
use std::path::PathBuf;
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
    /// The FRF the model was fitted to: its own uncertainty (its response's standard
    /// deviation at the validation lines, from the information on these data) is read
    /// next to the validation data's noise. The band is the one the model file records.
    #[arg(long, value_name = "FIT.csv")]
    pub fit_data: Option<PathBuf>,
}

/// Runs `frfit validate`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let fit = match &args.fit_data {
        Some(p) => Some((load_data(p)?, p.display().to_string())),
        None => None,
    };
    let config = frfit::pipeline::PipelineConfig::default();
    let fitted_on = fit.as_ref().map(|(data, name)| FitDataOfModel {
        data,
        config: &config,
        name: name.clone(),
    });
    validate_into(&args, quiet, fitted_on.as_ref()).map(|_| ())
}

/// Validates `args.model` on `args.data`, writes `validation.json`, `gamma.svg` and
/// `report.md` into `args.out`, and returns the result (`frfit validate`, and
/// `frfit diagnose --validate` for its final model); with `fitted_on`, the model's own
/// uncertainty is read next to the data's.
pub fn validate_into(
    args: &Args,
    quiet: bool,
    fitted_on: Option<&FitDataOfModel>,
) -> Result<FrfValidation, FrfitError> {
    let t0 = Instant::now();
    // before the files are read, as the option is checked
    check_alpha(args.alpha)?;
    let data = load_data(&args.data)?;
    let source = args.model.display().to_string();
    let file = ModelFile::read(&args.model).map_err(|e| FrfitError::Io {
        path: source.clone(),
        message: e.to_string(),
    })?;
    let method = match args.method {
        Method::ClosedForm => GammaMethod::ClosedForm,
        Method::Mu => GammaMethod::Mu,
    };
    let (v, desc) = validate_model(&file, &source, &data, args.alpha, method, fitted_on)?;
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
        if let Some(b) = &v.beyond_model_uncertainty {
            println!(
                "with the model's own uncertainty: {}, gamma beyond it max {:.3e}, median \
                 {:.3e}; its bound against the data's: median ratio {:.3}",
                verdict_text(b.verdict),
                b.gamma_max,
                b.gamma_median,
                b.model_to_disturbance_median
            );
        } else if fitted_on.is_some() {
            println!("{desc}");
        }
        println!("written to {}", args.out.display());
    }
    Ok(v)
}
