//! Developer tasks of the frfit workspace, run as `cargo xtask <task>` (the alias in
//! `.cargo/config.toml` builds this crate in release).
//!
//! - `wafer-stage`: the full reference pipeline without input files: simulate the
//!   wafer-stage experiment, estimate its FRF, fit and diagnose it with frfit, and
//!   validate the model against the simulator's truth.
//! - `oomen-bosgra`: Section 6 of Oomen and Bosgra (model validation with disturbance
//!   models from periodic averaging): `gamma.csv` and Figure 5.
//! - `fuzz READER --runs N`: coverage-guided fuzzing of one reader (see `fuzz.rs`).
//! - `bench-scale`: wall time, peak memory and accuracy of `frfit fit` on random modal
//!   plants of growing size (see `bench_scale.rs`).
//! - `calibrate`: the Monte Carlo harness of the reported uncertainty (z-scores of the
//!   modes' frequency and damping over noise draws of one plant; see `calibrate.rs`).
//! - `bench-diagnose`: wall time of `frfit diagnose` against one `frfit fit` on the
//!   reference cases (see `bench_diagnose.rs`).

mod bench_diagnose;
mod bench_scale;
mod calibrate;
mod effects;
mod fuzz;
mod oomen_bosgra;
mod reference_experiment;
mod validate;
mod wafer_stage;

use clap::{CommandFactory, Parser, Subcommand};
use std::fmt;
use std::process::ExitCode;

/// `cargo xtask`: developer tasks of the frfit workspace.
#[derive(Parser, Debug)]
#[command(
    name = "xtask",
    bin_name = "cargo xtask",
    about = "Developer tasks of the frfit workspace",
    after_help = "Run `cargo xtask <TASK> --help` for the options of a task."
)]
struct Cli {
    #[command(subcommand)]
    task: Option<Task>,
}

#[derive(Subcommand, Debug)]
enum Task {
    /// Reference pipeline on the simulated wafer stage: simulate, estimate the FRF, fit
    /// and diagnose, validate against the known truth (no input files needed).
    WaferStage(wafer_stage::Args),
    /// Section 6 of Oomen and Bosgra: the minimum uncertainty per validation line for
    /// 100, 1000 and 10000 periods against the true model error (gamma.csv, Figure 5).
    OomenBosgra(oomen_bosgra::Args),
    /// Coverage-guided fuzzing of one reader (csv, uff, spectra, mat, model-json) with
    /// libFuzzer through cargo-fuzz, corpus seeded from ../shared/data.
    Fuzz(fuzz::Args),
    /// Wall time, peak memory and accuracy of `frfit fit` on random modal plants of
    /// growing size (4x13x17, 20x20x50, 50x50x100 by default).
    BenchScale(bench_scale::Args),
    /// Wall time of `frfit diagnose` against one `frfit fit` on the reference cases of
    /// ../shared/data (median ratio over the cases).
    BenchDiagnose(bench_diagnose::Args),
    /// Monte Carlo calibration of the reported standard deviations: z RMS and coverage
    /// of the modes' frequency and damping over noise draws of a random plant.
    Calibrate(calibrate::Args),
    /// The diagnosis on undeclared effects and pairs of them (a lag with a delay, a
    /// crosstalk with a sensor-mount resonance, a hidden mode beside another, ...), their
    /// values drawn per plate, each run against the plate's exact response.
    Effects(effects::Args),
}

/// An error of a task: which stage failed and why.
#[derive(Debug)]
pub struct Error {
    stage: String,
    message: String,
}

impl Error {
    /// An error of `stage`.
    pub fn new(stage: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            stage: stage.into(),
            message: message.into(),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.stage, self.message)
    }
}

/// Attaches the stage name to any displayable error.
pub trait Context<T> {
    /// Maps the error to an [`Error`] of `stage`.
    fn stage(self, stage: &str) -> Result<T, Error>;
}

impl<T, E: fmt::Display> Context<T> for Result<T, E> {
    fn stage(self, stage: &str) -> Result<T, Error> {
        self.map_err(|e| Error::new(stage, e.to_string()))
    }
}

fn main() -> ExitCode {
    // faer's own threads are slower than one on 2-core machines (STACK.md); the
    // simulator and frfit parallelise over experiments and entries with rayon instead.
    faer::set_global_parallelism(faer::Par::Seq);
    let cli = Cli::parse();
    let result = match cli.task {
        Some(Task::WaferStage(args)) => wafer_stage::run(args),
        Some(Task::OomenBosgra(args)) => oomen_bosgra::run(args),
        Some(Task::Fuzz(args)) => fuzz::run(args),
        Some(Task::BenchScale(args)) => bench_scale::run(args),
        Some(Task::BenchDiagnose(args)) => bench_diagnose::run(args),
        Some(Task::Calibrate(args)) => calibrate::run(args),
        Some(Task::Effects(args)) => effects::run(args),
        None => {
            let mut cmd = Cli::command();
            match cmd.print_help() {
                Ok(()) => {
                    println!();
                    return ExitCode::SUCCESS;
                }
                Err(e) => Err(Error::new("help", e.to_string())),
            }
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
