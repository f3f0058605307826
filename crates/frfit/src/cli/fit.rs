//! `frfit fit DATA --out MODEL.json [--report DIR]`: the additive model of the
//! wafer-stage paper fitted by refined instrumental variables (crate `additive-riv`),
//! with CMIF initialisation, delay and hold handling, and the adaptation of the modes.

use super::common::load_data;
use super::model_opts::{progress, FitOptions};
use super::output::print_fit;
use clap::Args as ClapArgs;
use frfit::run;
use frfit::FrfitError;
use std::path::PathBuf;

/// Arguments of `frfit fit`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// FRF file (CSV as in FORMATS.md, or UFF 58 with extension .uff/.unv).
    pub data: PathBuf,
    /// Fitting options.
    #[command(flatten)]
    pub opts: FitOptions,
    /// Write the model here (versioned JSON, readable by `frfit eval`).
    #[arg(long, value_name = "MODEL.json")]
    pub out: PathBuf,
    /// Also write a report (report.md, SVG figures, summary.json) into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
}

/// Runs `frfit fit`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let data = load_data(&args.data)?;
    let spec = args.opts.spec();
    spec.check(&data)?;
    let mut cfg = spec.pipeline_config();
    // the verdict and the floor comparison are the report's; `fit` prints neither
    cfg.final_analysis = args.report.is_some();
    let (sink, bar) = progress(quiet);
    cfg.progress = sink;
    let out = run::run(&data, &args.data.display().to_string(), &cfg, "fit");
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let out = out?;
    out.write_outputs(&args.out, args.report.as_deref(), &args.data, "frfit fit")?;
    if !quiet {
        print_fit(&out);
        println!("model written to {}", args.out.display());
        if let Some(d) = &args.report {
            println!("report written to {}", d.join("report.md").display());
        }
        if !out.fit.convergence.is_converged() {
            eprintln!(
                "warning: the iterations did not converge ({}); try --method sk, a narrower --band, or --modes N",
                out.fit.convergence.describe()
            );
        }
    }
    Ok(())
}
