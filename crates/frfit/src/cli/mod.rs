//! Command-line interface: one module per subcommand. Add a subcommand by adding a
//! variant to [`Command`] and a module with `Args` and `run`.

use clap::{Parser, Subcommand};
use frfit::FrfitError;

pub mod cmif;
pub mod common;
pub mod convert;
pub mod diagnose;
pub mod eval;
pub mod export;
pub mod fit;
pub mod info;
pub mod model_opts;
pub mod nonparametric;
pub mod output;
pub mod predict;
pub mod reduce;
pub mod simulate;
pub mod validate;

#[derive(Parser, Debug)]
#[command(
    name = "frfit",
    version,
    about = "Frequency-domain identification of lightly damped MIMO motion systems",
    long_about = None
)]
pub struct Cli {
    /// Silence progress bars and informational messages.
    #[arg(long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Summarise an FRF file: dimensions, band, lines, units, variance and noise level.
    Info(info::Args),
    /// Convert an FRF file between FRF CSV, UFF 58 (ASCII or binary) and MATLAB .mat.
    Convert(convert::Args),
    /// Complex mode indicator function: singular values per line and the picked modes.
    Cmif(cmif::Args),
    /// Simulate an experiment (the wafer stage) and estimate its FRF.
    Simulate(simulate::Args),
    /// Nonparametric FRF from periodic measurements (.mat time records or spectra CSV).
    Nonparametric(nonparametric::Args),
    /// Fit the additive model (rigid body + modes) by refined IV; write MODEL.json.
    Fit(fit::Args),
    /// Evaluate a fitted model at a data file's frequencies; write the response as CSV.
    Eval(eval::Args),
    /// Write a fitted model as a real state space (A, B, C, D) with its factors.
    Export(export::Args),
    /// Fit, then trace the residual to effects the model lacks; write a report.
    Diagnose(diagnose::Args),
    /// Minimum additive uncertainty per line against an independent validation FRF
    /// (Oomen-Bosgra); write DIR/validation.json and DIR/report.md.
    Validate(validate::Args),
    /// Predict periodic test records with a model: the NRMSE per output against the
    /// records' own noise floor; write DIR/prediction.json and DIR/prediction.svg.
    Predict(predict::Args),
    /// Balanced truncation of a model (rigid body kept exactly): print the Hankel
    /// singular values; with --order N write the reduced model and its error bound.
    Reduce(reduce::Args),
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> Result<(), FrfitError> {
    let quiet = cli.quiet;
    match cli.command {
        Command::Info(a) => info::run(a, quiet),
        Command::Convert(a) => convert::run(a, quiet),
        Command::Cmif(a) => cmif::run(a, quiet),
        Command::Simulate(a) => simulate::run(a, quiet),
        Command::Nonparametric(a) => nonparametric::run(a, quiet),
        Command::Fit(a) => fit::run(a, quiet),
        Command::Eval(a) => eval::run(a, quiet),
        Command::Export(a) => export::run(a, quiet),
        Command::Diagnose(a) => diagnose::run(a, quiet),
        Command::Validate(a) => validate::run(a, quiet),
        Command::Reduce(a) => reduce::run(a, quiet),
        Command::Predict(a) => predict::run(a, quiet),
    }
}
