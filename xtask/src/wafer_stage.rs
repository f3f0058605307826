//! `cargo xtask wafer-stage`: the reference pipeline on the simulated wafer stage.
//!
//! 1. simulate the closed-loop multisine experiment (frequency-domain path, seeded) and
//!    estimate the FRF nonparametrically (with its variance);
//! 2. write `frf.csv` and `truth.json`, and read the FRF back as a user would;
//! 3. fit and diagnose it with the frfit pipeline (the user declares the zero-order hold);
//! 4. write `model.json`, `report.md`, the SVG figures and `summary.json`;
//! 5. validate the model against the simulator's noiseless response and true modes,
//!    write `validation.md`;
//! 6. simulate a second experiment of the same plant (new multisine phases and noise)
//!    and validate the model on it as a user would (Oomen-Bosgra, minimum additive
//!    uncertainty per line): `validation-experiment/` (its FRF, `validation.json`,
//!    `gamma.svg`, `report.md`), summarised in `validation.md` and `report.md`.

use crate::validate::{self, Validation};
use crate::{Context, Error};
use clap::Args as ClapArgs;
use experiment::synth::{
    ControllerConfig, ExperimentConfig, WaferStageConfig, WaferStageExperiment,
};
use frf_data::truth::Truth;
use frf_data::ModelStructure;
use frf_data::{FrfDataset, ProgressSink};
use frfit::additive_riv::{Hold, ModelFile};
use frfit::pipeline::PipelineConfig;
use frfit::report::write_report;
use frfit::run::{self, PipelineOutput};
use frfit::validation::{validate_frf, FrfValidationConfig};
use frfit::validation_report::{verdict_text, write_validation_dir};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The FRF file in the output directory; the report and the model name it relative to
/// the directory, so that the directory can be moved as a whole.
const DATA_NAME: &str = "frf.csv";

/// Added to `--seed` for the phases and noise of the second (validation) experiment.
const VALIDATION_SEED_OFFSET: u64 = 1_000_003;

/// Options of `cargo xtask wafer-stage`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Seed of the plant, the multisine phases and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory [default: <workspace>/target/wafer-stage].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Measured periods per realization.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub periods: u64,
    /// Realizations (random-phase multisines); at least 2 for a variance estimate.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(2..))]
    pub realizations: u64,
    /// Band to fit, LO:HI in Hz (either side may be empty) [default: all excited lines].
    #[arg(long, value_name = "LO:HI", value_parser = parse_band)]
    pub band: Option<(f64, f64)>,
}

/// `LO:HI` in Hz, either side optional.
fn parse_band(s: &str) -> Result<(f64, f64), String> {
    let (lo, hi) = s
        .split_once(':')
        .ok_or_else(|| format!("expected LO:HI in Hz (e.g. 20:2000), got `{s}`"))?;
    let side = |t: &str, default: f64| -> Result<f64, String> {
        let t = t.trim();
        if t.is_empty() {
            return Ok(default);
        }
        t.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("`{t}` in `{s}` is not a frequency >= 0 Hz"))
    };
    let (lo, hi) = (side(lo, 0.0)?, side(hi, f64::MAX)?);
    if lo >= hi {
        return Err(format!("the band `{s}` is empty (LO must be below HI)"));
    }
    Ok((lo, hi))
}

/// The workspace root: the parent of this crate's manifest directory.
pub(crate) fn workspace_root() -> PathBuf {
    let xtask_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    xtask_dir
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| xtask_dir.to_path_buf())
}

/// Wall time per stage, with the stage names announced on stderr.
struct Stages {
    total: usize,
    done: Vec<(&'static str, f64)>,
}

impl Stages {
    fn run<T>(
        &mut self,
        name: &'static str,
        what: &str,
        f: impl FnOnce() -> Result<T, Error>,
    ) -> Result<T, Error> {
        eprintln!("[{}/{}] {name}: {what}", self.done.len() + 1, self.total);
        let t = Instant::now();
        let r = f();
        let s = t.elapsed().as_secs_f64();
        match &r {
            Ok(_) => eprintln!("      {name} done in {s:.2} s"),
            Err(_) => eprintln!("      {name} failed after {s:.2} s"),
        }
        self.done.push((name, s));
        r
    }
}

/// Prints the pipeline's progress on stderr: each new stage once, and every candidate
/// test of the diagnosis loop.
fn progress_sink() -> ProgressSink {
    let last = Arc::new(Mutex::new(String::new()));
    ProgressSink::new(move |p| {
        let Ok(mut last) = last.lock() else { return };
        if p.stage == "diagnose" {
            eprintln!("      diagnose: {}", p.message);
        } else if *last != p.stage {
            eprintln!("      {}: {}", p.stage, p.message);
        }
        if *last != p.stage {
            last.clone_from(&p.stage);
        }
    })
}

fn write_text(path: &Path, text: &str) -> Result<(), Error> {
    std::fs::write(path, text).map_err(|e| Error::new(path.display().to_string(), e.to_string()))
}

/// Model file and report of a pipeline run, as `frfit diagnose --report DIR` writes them.
fn write_model_and_report(
    out: &PipelineOutput,
    dir: &Path,
    data_path: &Path,
    seed: u64,
) -> Result<Vec<PathBuf>, Error> {
    let file = out
        .model_file(data_path, "cargo xtask wafer-stage")
        .stage("model file")?;
    let model_path = dir.join("model.json");
    file.write(&model_path).stage("model file")?;
    let title = format!(
        "Simulated wafer stage (seed {seed}): frfit diagnose of {}",
        data_path.display()
    );
    let input = out.report_input(&title).stage("report")?;
    let mut written = vec![model_path];
    written.extend(write_report(dir, &input, &out.summary).stage("report")?);
    Ok(written)
}

/// Runs `cargo xtask wafer-stage`.
pub fn run(args: Args) -> Result<(), Error> {
    let t_all = Instant::now();
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| workspace_root().join("target").join("wafer-stage"));
    std::fs::create_dir_all(&dir).stage(&format!("output directory {}", dir.display()))?;
    let csv_path = dir.join(DATA_NAME);
    let truth_path = dir.join("truth.json");
    let validation_path = dir.join("validation.md");
    let periods = usize::try_from(args.periods).stage("--periods")?;
    let realizations = usize::try_from(args.realizations).stage("--realizations")?;
    let mut stages = Stages {
        total: 6,
        done: Vec::new(),
    };
    let mut written: Vec<PathBuf> = Vec::new();

    // 1. the experiment and its nonparametric FRF
    let stage_cfg = WaferStageConfig {
        seed: args.seed,
        ..WaferStageConfig::default()
    };
    let (sim, est) = stages.run(
        "simulate",
        &format!(
            "wafer stage seed {}, closed-loop multisines, {periods} periods x {realizations} realizations, frequency-domain path; nonparametric FRF",
            args.seed
        ),
        || {
            let mut exp = ExperimentConfig::wafer_stage(args.seed);
            exp.periods = periods;
            exp.realizations = realizations;
            let sim = WaferStageExperiment::new(&stage_cfg, &ControllerConfig::default(), exp)
                .stage("simulate")?;
            let est = sim.run().stage("simulate")?;
            Ok((sim, est))
        },
    )?;
    let fs = sim.stage.fs;
    let delay_samples = sim.stage.delay_samples;

    // 2. the files a user would start from; the FRF is read back from its CSV
    let (data, truth) = stages.run("write data", "frf.csv and truth.json", || {
        let total_delay_us = (0.5 + delay_samples) / fs * 1e6;
        let comments = vec![
            format!("simulated wafer stage, seed {} (cargo xtask wafer-stage)", args.seed),
            format!(
                "sampling {} kHz through a zero-order hold; total delay {total_delay_us} us (hold + {delay_samples} sample(s) of computation)",
                fs / 1e3
            ),
            format!(
                "closed-loop indirect estimate: {} single-axis experiments, {} periods x {} realizations; variance: {}",
                est.n_experiments,
                est.periods,
                est.realizations,
                est.frf
                    .metadata
                    .get("variance")
                    .map(String::as_str)
                    .unwrap_or("none")
            ),
        ];
        frf_data::io::write_frf_csv(&csv_path, &est.frf, &comments).stage("frf.csv")?;
        let truth = sim.stage.truth();
        let json = serde_json::to_string_pretty(&truth).stage("truth.json")?;
        write_text(&truth_path, &(json + "\n"))?;
        let data = frf_data::io::read_frf_csv(&csv_path).stage("frf.csv")?;
        let truth = Truth::read(&truth_path).stage("truth.json")?;
        Ok((data, truth))
    })?;
    written.push(csv_path.clone());
    written.push(truth_path.clone());

    // 3. fit and diagnose
    let cfg = PipelineConfig {
        diagnose: true,
        hold: Some(Hold::Zoh { fs_hz: fs }),
        fs_hz: Some(fs),
        band_hz: args.band,
        progress: progress_sink(),
        ..PipelineConfig::default()
    };
    let out = stages.run(
        "fit + diagnose",
        &format!(
            "frfit pipeline on {} lines {}..{} Hz, declared hold zoh:{fs}",
            data.n_lines(),
            data.freq_hz(0),
            data.freq_hz(data.n_lines() - 1)
        ),
        || run::run(&data, DATA_NAME, &cfg, "diagnose").stage("pipeline"),
    )?;

    // 4. model.json, report.md, figures, summary.json
    let report_files = stages.run(
        "report",
        "model.json, report.md, SVG figures, summary.json",
        || write_model_and_report(&out, &dir, Path::new(DATA_NAME), args.seed),
    )?;
    written.extend(report_files);

    // 5. validation against the truth
    let validation: Validation = stages.run(
        "validate",
        "model vs noiseless truth, fitted vs true modes",
        || {
            let exact = sim.experiment.true_frf().stage("validate")?;
            let model_file = ModelFile::read(dir.join("model.json")).stage("validate")?;
            let v = validate::compare(&validate::Inputs {
                seed: args.seed,
                periods,
                realizations,
                data: &out.band,
                noise_var: &out.noise.variance,
                truth: &truth,
                simulator_exact: &exact,
                model_file: &model_file,
                pipeline_final: &out.final_response,
                summary: &out.summary,
            })?;
            write_text(&validation_path, &v.markdown())?;
            Ok(v)
        },
    )?;

    // 6. a second experiment of the same plant, and the model validated on it
    let vdir = dir.join("validation-experiment");
    let vseed = args.seed.wrapping_add(VALIDATION_SEED_OFFSET);
    let gamma = stages.run(
        "validate (2nd)",
        &format!("second experiment of the same plant (phases and noise seed {vseed}), minimum additive uncertainty per line"),
        || {
            let mut exp = ExperimentConfig::wafer_stage(vseed);
            exp.periods = periods;
            exp.realizations = realizations;
            let sim2 = WaferStageExperiment::new(&stage_cfg, &ControllerConfig::default(), exp)
                .stage("validation experiment")?;
            let est2 = sim2.run().stage("validation experiment")?;
            let (lo, hi) = (out.band.freq_hz(0), out.band.freq_hz(out.band.n_lines() - 1));
            let band = est2
                .frf
                .band(lo, hi)
                .stage("validation experiment band")?;
            let lines = band.line_range();
            let vdata = band.to_frf();
            std::fs::create_dir_all(&vdir).stage("validation-experiment directory")?;
            frf_data::io::write_frf_csv(
                vdir.join(DATA_NAME),
                &vdata,
                &[format!(
                    "second simulated experiment of the wafer stage seed {}, phases and noise seed {vseed}; {periods} periods x {realizations} realizations",
                    args.seed
                )],
            )
            .stage("validation-experiment/frf.csv")?;
            let model = ModelFile::read(dir.join("model.json"))
                .stage("model.json")?
                .to_model()
                .stage("model.json")?;
            let grid = model.response_at(&vdata.omegas());
            let vcfg = FrfValidationConfig {
                // the variance is estimated from the realizations of the experiment
                variance_dof: Some(2.0 * (realizations as f64 - 1.0)),
                ..FrfValidationConfig::default()
            };
            // the estimator's disturbance covariance C_v of the band's lines: the shape
            // across outputs of each line's disturbance model (Prop. 9, eqs. 16-18)
            let m = vdata.ny() * vdata.ny();
            let cv = est2
                .disturbance_covariance
                .as_deref()
                .and_then(|c| c.get(lines.start * m..lines.end * m));
            if cv.is_none() {
                eprintln!(
                    "note: the second experiment gives no disturbance covariance; the \
                     per-entry variances are used"
                );
            }
            let v = validate_frf(&grid, &vdata, cv, &vcfg).stage("validation")?;
            write_validation_dir(
                &vdir,
                "../model.json",
                &format!("{} modes, the diagnosed model", model.modes().len()),
                DATA_NAME,
                &v,
                vdata.units.as_deref(),
            )
            .stage("validation-experiment")?;
            let section = format!(
                "\n## Validation on a second experiment\n\n\
                 A second simulated experiment of the same plant (phases and noise seed \
                 {vseed}, {periods} periods x {realizations} realizations), the model \
                 validated on it (Oomen-Bosgra, minimum additive uncertainty per line, alpha \
                 = {}): **{}**; gamma max {:.4e}, median {:.4e}; {} of {} lines the \
                 disturbance alone does not explain (joint level). Details: \
                 [validation-experiment/report.md](validation-experiment/report.md).\n\n\
                 ![gamma against frequency](validation-experiment/gamma.svg)\n",
                v.alpha,
                verdict_text(v.verdict),
                v.gamma_max,
                v.gamma_median,
                v.lines_invalidated_at_zero,
                v.lines.len()
            );
            for name in ["validation.md", "report.md"] {
                let path = dir.join(name);
                let mut text = std::fs::read_to_string(&path).stage(name)?;
                text.push_str(&section);
                write_text(&path, &text)?;
            }
            Ok(v)
        },
    )?;
    written.push(validation_path);
    written.push(vdir);

    println!("{}", validation.console_table());
    println!(
        "validation on a second experiment: {}, gamma max {:.3e}, median {:.3e} over {} lines",
        verdict_text(gamma.verdict),
        gamma.gamma_max,
        gamma.gamma_median,
        gamma.lines.len()
    );
    println!(
        "verdict of the diagnosis: {} ({} step(s) tested, {} accepted)",
        out.summary.verdict,
        out.summary.steps.len(),
        out.summary.steps.iter().filter(|s| s.accepted).count()
    );
    println!();
    println!("written:");
    for p in &written {
        println!("  {}", p.display());
    }
    println!();
    println!("wall time per stage:");
    for (name, s) in &stages.done {
        println!("  {name:<16} {s:>7.2} s");
    }
    println!("  {:<16} {:>7.2} s", "total", t_all.elapsed().as_secs_f64());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_parse_with_open_sides_and_reject_nonsense() {
        assert_eq!(parse_band("20:2000"), Ok((20.0, 2000.0)));
        assert_eq!(parse_band(":500"), Ok((0.0, 500.0)));
        assert_eq!(parse_band("100:"), Ok((100.0, f64::MAX)));
        for bad in ["", "20", "2000:20", "a:b", "-1:5", "5:5"] {
            assert!(parse_band(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_default_output_is_under_the_workspace_target() {
        let root = workspace_root();
        assert!(root.join("Cargo.toml").is_file());
        assert!(root.join("xtask").is_dir());
    }
}
