//! `frfit diagnose DATA --report DIR`: fit, then trace the residual to effects the model
//! lacks (missed mode, delay, hold, feedthrough, stiffness, input or output dynamics),
//! add each one that explains more than noise, and report the error before and after.

use super::common::load_data;
use super::model_opts::{progress, FitOptions};
use super::output::print_fit;
use super::validate;
use clap::Args as ClapArgs;
use frf_data::FrfDataset;
use frfit::additive_riv::ModelFile;
use frfit::run;
use frfit::FrfitError;
use std::path::PathBuf;

/// Arguments of `frfit diagnose`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// FRF file (CSV as in FORMATS.md, or UFF 58 with extension .uff/.unv).
    pub data: PathBuf,
    /// Fitting options.
    #[command(flatten)]
    pub opts: FitOptions,
    /// Start from this model (a `frfit fit` MODEL.json) instead of the CMIF initialisation.
    #[arg(long, value_name = "MODEL.json")]
    pub model: Option<PathBuf>,
    /// Sample rate of the measurement, Hz, for testing a zero-order hold (default: from
    /// the file's metadata or comments, e.g. "sampling 10 kHz").
    #[arg(long, value_name = "HZ")]
    pub fs: Option<f64>,
    /// Write report.md, the SVG figures, model.json and summary.json into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: PathBuf,
    /// Validate the final model on an independent measurement of the same plant (FRF with
    /// `_var` columns): the minimum additive uncertainty per line (as `frfit validate`),
    /// written to DIR/validation/ and summarised in report.md.
    #[arg(long, value_name = "VALIDATION.csv")]
    pub validate: Option<PathBuf>,
    /// Probability level of the validation's disturbance bound.
    #[arg(long, default_value_t = 0.99, requires = "validate")]
    pub alpha: f64,
    /// Test records measured apart from the data (`.mat` time records, one file per
    /// experiment; NumPy records, one `.npz` or `u.npy y.npy`; or a periodic spectra
    /// `.csv`): the initial and the final model predict them, and the NRMSE per output
    /// (as `frfit predict`) goes to DIR/test_records/ and report.md. The records' sample
    /// rate is `--fs`, else the one the data declare (`frfit nonparametric` writes it),
    /// else the .mat file's.
    #[arg(long, num_args = 1.., value_name = "FILE")]
    pub test_records: Vec<PathBuf>,
    /// Input signal names of the test records (as `frfit predict --input`).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub test_input: Vec<String>,
    /// Output signal names of the test records (as `frfit predict --output`).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub test_output: Vec<String>,
    /// Samples per period of the test records (NumPy records with a periods axis: the
    /// first axis's length).
    #[arg(long)]
    pub test_period: Option<usize>,
}

/// Runs `frfit diagnose`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let data = load_data(&args.data)?;
    let mut spec = args.opts.spec();
    spec.fs_hz = args.fs;
    spec.check(&data)?;
    let mut cfg = spec.pipeline_config();
    cfg.diagnose = true;
    if let Some(p) = &args.model {
        let f = ModelFile::read(p)
            .map_err(|e| FrfitError::argument("--model", p.display(), e.to_string()))?;
        let m = f
            .to_model()
            .map_err(|e| FrfitError::argument("--model", p.display(), e.to_string()))?;
        if m_dims(&m) != (data.ny(), data.nu()) {
            return Err(FrfitError::argument(
                "--model",
                p.display(),
                format!(
                    "the model is {}x{} but the data are {}x{}",
                    m_dims(&m).0,
                    m_dims(&m).1,
                    data.ny(),
                    data.nu()
                ),
            ));
        }
        cfg.start_model = Some(m);
    }
    let (sink, bar) = progress(quiet);
    cfg.progress = sink;
    let out = run::run(&data, &args.data.display().to_string(), &cfg, "diagnose");
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let out = out?;
    let model_path = args.report.join("model.json");
    std::fs::create_dir_all(&args.report).map_err(|e| FrfitError::io(&args.report, e))?;
    out.write_outputs(
        &model_path,
        Some(&args.report),
        &args.data,
        "frfit diagnose",
    )?;
    if let Some(vdata) = &args.validate {
        let fitted_on = frfit::validation_report::FitDataOfModel {
            data: &data,
            config: &cfg,
            name: args.data.display().to_string(),
        };
        validate_final_model(&args, vdata, &model_path, &fitted_on, quiet)?;
    }
    if !args.test_records.is_empty() {
        // the records' sample rate: --fs, else the one the data declare
        let fs = args.fs.or(frfit::declared::declared(&data).fs_hz);
        predict_test_records(&args, fs, &out, quiet)?;
    }
    if !quiet {
        print_fit(&out);
        for s in &out.summary.steps {
            println!(
                "  step {:<16} {:<8} F = {:>10.3e} (crit {:.3}) median rel {:.3e} -> {:.3e}  {}",
                s.effect(),
                if s.accepted { "ACCEPTED" } else { "rejected" },
                s.f_statistic,
                s.f_critical,
                s.before.median_rel,
                s.after.median_rel,
                s.fitted.params_json()
            );
        }
        println!(
            "verdict: {} ({})",
            out.summary.verdict, out.summary.verdict_evidence
        );
        println!(
            "report written to {}",
            args.report.join("report.md").display()
        );
    }
    Ok(())
}

/// `--validate`: the final model against the validation FRF (DIR/validation/), and a
/// section of report.md with the verdict and gamma.
fn validate_final_model(
    args: &Args,
    vdata: &std::path::Path,
    model_path: &std::path::Path,
    fitted_on: &frfit::validation_report::FitDataOfModel,
    quiet: bool,
) -> Result<(), FrfitError> {
    let vargs = validate::Args {
        model: model_path.to_path_buf(),
        data: vdata.to_path_buf(),
        alpha: args.alpha,
        method: validate::Method::ClosedForm,
        out: args.report.join("validation"),
        fit_data: None,
    };
    let v = validate::validate_into(&vargs, true, Some(fitted_on))?;
    let md_path = args.report.join("report.md");
    let mut md = std::fs::read_to_string(&md_path).map_err(|e| FrfitError::io(&md_path, e))?;
    md.push_str(&format!(
        "\n## Validation on an independent measurement\n\n\
         The final model against `{}` (Oomen-Bosgra, minimum additive uncertainty per line, \
         alpha = {}): **{}**; gamma max {:.4e}, median {:.4e}; {} of {} lines the \
         disturbance alone does not explain (joint level). Details: \
         [validation/report.md](validation/report.md).\n\n\
         ![gamma against frequency](validation/gamma.svg)\n",
        vdata.display(),
        v.alpha,
        validate::verdict_text(v.verdict),
        v.gamma_max,
        v.gamma_median,
        v.lines_invalidated_at_zero,
        v.lines.len()
    ));
    let beyond = v.beyond_model_uncertainty.as_ref().map(|b| {
        format!(
            "with the model's own uncertainty (from the information on the fit data) next \
             to the data's: **{}**, {} lines neither explains, gamma beyond it max {:.4e}, \
             median {:.4e}; the model's bound against the data's disturbance bound: median \
             ratio {:.3}",
            validate::verdict_text(b.verdict),
            b.lines_invalidated_at_zero,
            b.gamma_max,
            b.gamma_median,
            b.model_to_disturbance_median
        )
    });
    if let Some(t) = &beyond {
        md.push_str(&format!("\n{}.\n", capitalised(t)));
    }
    std::fs::write(&md_path, md).map_err(|e| FrfitError::io(&md_path, e))?;
    if !quiet {
        println!(
            "validation on {}: {}, gamma max {:.3e}, median {:.3e}",
            vdata.display(),
            validate::verdict_text(v.verdict),
            v.gamma_max,
            v.gamma_median
        );
        if let Some(t) = beyond {
            println!("  {}", t.replace("**", ""));
        }
    }
    Ok(())
}

/// `s` with its first letter in upper case.
fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// `--test-records`: the initial and the final model predict the test records
/// (DIR/test_records/initial/ and final/), and a section of report.md compares them.
fn predict_test_records(
    args: &Args,
    fs: Option<f64>,
    out: &run::PipelineOutput,
    quiet: bool,
) -> Result<(), FrfitError> {
    use frfit::nonparametric::{spectra_from_files, RecordSpec};
    use frfit::predict::TestRecordPredictions;
    let spec = RecordSpec {
        inputs: args.test_input.clone(),
        outputs: args.test_output.clone(),
        fs,
        period: args.test_period,
        // every record is compared on its own
        realizations: Some(1),
        ..RecordSpec::default()
    };
    let (spectra, _) = spectra_from_files(&args.test_records, &spec)?;
    let names: Vec<String> = args
        .test_records
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let p = TestRecordPredictions::of(out, &spectra, &names.join(", "))?;
    p.write_into_report(&args.report)?;
    let (initial, last) = (&p.initial, &p.final_model);
    if !quiet {
        for (i, (a, b)) in initial.outputs.iter().zip(&last.outputs).enumerate() {
            println!(
                "test records, output {}: NRMSE initial {:.4e}, final {:.4e}{}",
                i + 1,
                a.nrmse,
                b.nrmse,
                b.noise_floor
                    .map_or_else(String::new, |f| format!(" (noise floor {f:.4e})"))
            );
        }
    }
    Ok(())
}

fn m_dims(m: &frfit::additive_riv::AdditiveModel) -> (usize, usize) {
    use frf_data::ModelStructure;
    (m.ny(), m.nu())
}
