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
use frfit::plots::{Axis, LinePlot, Series};
use frfit::realize::ResponseGrid;
use frfit::validation::{validate_frf, FrfValidation, FrfValidationConfig, GammaMethod, Verdict};
use frfit::FrfitError;
use std::fmt::Write as _;
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
        ..Default::default()
    };
    let v = validate_frf(&grid, &data, None, &cfg).map_err(|e| FrfitError::Fit {
        what: "validation".into(),
        why: e.to_string(),
    })?;
    std::fs::create_dir_all(&args.out).map_err(|e| FrfitError::io(&args.out, e))?;
    let json_path = args.out.join("validation.json");
    let json = serde_json::to_string_pretty(&v).map_err(|e| FrfitError::Io {
        path: json_path.display().to_string(),
        message: e.to_string(),
    })?;
    std::fs::write(&json_path, json).map_err(|e| FrfitError::io(&json_path, e))?;
    let svg_path = args.out.join("gamma.svg");
    gamma_plot(&v).write_svg(&svg_path, (900, 500))?;
    let md_path = args.out.join("report.md");
    let md = report(args, &desc, &v, data.units.as_deref());
    std::fs::write(&md_path, md).map_err(|e| FrfitError::io(&md_path, e))?;
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

pub fn verdict_text(v: Verdict) -> &'static str {
    match v {
        Verdict::NotInvalidated => "not invalidated",
        Verdict::InvalidatedAtZeroUncertainty => "invalidated at zero uncertainty",
    }
}

/// Gamma, the model error and the disturbance bound against frequency.
fn gamma_plot(v: &FrfValidation) -> LinePlot {
    let f: Vec<f64> = v.lines.iter().map(|l| l.f_hz).collect();
    LinePlot::new("Minimum additive uncertainty per line")
        .with_y(Axis::log("Magnitude"))
        .with_series(Series::line(
            "|G - P^| (model error seen by the data)",
            f.clone(),
            v.lines.iter().map(|l| l.model_error).collect(),
        ))
        .with_series(
            Series::line(
                "gamma",
                f.clone(),
                v.lines.iter().map(|l| l.gamma).collect(),
            )
            .with_width(2),
        )
        .with_series(Series::dashed(
            "disturbance bound",
            f,
            v.lines.iter().map(|l| l.disturbance_bound).collect(),
        ))
}

/// The Markdown report.
fn report(args: &Args, desc: &str, v: &FrfValidation, units: Option<&str>) -> String {
    let u = units.unwrap_or("FRF units");
    let mut s = String::new();
    let _ = writeln!(s, "# Model validation\n");
    let _ = writeln!(s, "- model: `{}` ({desc})", args.model.display());
    let _ = writeln!(s, "- validation data: `{}`", args.data.display());
    let _ = writeln!(
        s,
        "- alpha = {} per line (for each input column's output vector); verdict at the \
         joint level over all lines and inputs",
        v.alpha
    );
    let _ = writeln!(s, "- **verdict: {}**", verdict_text(v.verdict));
    let _ = writeln!(
        s,
        "- lines the disturbance alone does not explain (joint level): {} of {}",
        v.lines_invalidated_at_zero,
        v.lines.len()
    );
    let _ = writeln!(
        s,
        "- gamma: max {:.4e}, median {:.4e} ({u})\n",
        v.gamma_max, v.gamma_median
    );
    let _ = writeln!(
        s,
        "gamma is the smallest norm sigma_max(Delta_u) of an additive uncertainty \
         P^ + Delta_u that, with a disturbance inside the bound, reproduces the validation \
         FRF at the line (Oomen and Bosgra, the FDMVOP). Where gamma stays below the model \
         error |G - P^|, part of the error is attributed to noise; more periods in the \
         validation experiment shrink the disturbance bound and gamma approaches the true \
         model error from below.\n"
    );
    let _ = writeln!(s, "![gamma against frequency](gamma.svg)\n");
    let mut top: Vec<_> = v.lines.iter().collect();
    top.sort_by(|a, b| b.gamma.total_cmp(&a.gamma));
    let _ = writeln!(s, "## Lines with the largest gamma\n");
    let _ = writeln!(s, "| f [Hz] | gamma | model error | disturbance bound |");
    let _ = writeln!(s, "|---:|---:|---:|---:|");
    for l in top.iter().take(10) {
        let _ = writeln!(
            s,
            "| {:.3} | {:.3e} | {:.3e} | {:.3e} |",
            l.f_hz, l.gamma, l.model_error, l.disturbance_bound
        );
    }
    s
}
