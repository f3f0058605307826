//! `frfit simulate wafer-stage`: the simulated wafer-stage experiment (closed loop,
//! single-axis random-phase odd multisines, `P` periods x `R` realizations) and its
//! nonparametric FRF estimate, written as an FRF CSV with `_var` columns; optionally the
//! truth JSON, the exact noiseless response and the per-period spectra.
//!
//! `frfit simulate random-modal`: a random modal plant of any size
//! (`experiment::synth::RandomModal`), its noisy FRF with the variance, the truth and the
//! exact response.

use super::common::{parse_band, Band};
use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use experiment::nonparametric::spectra_csv::write_spectra_csv;
use experiment::nonparametric::{EstimatorConfig, LineGrid};
use experiment::synth::{
    ControllerConfig, ExperimentConfig, NoiseConfig, RandomModal, RandomModalConfig,
    SimulationPath, WaferStageConfig, WaferStageExperiment,
};
use frf_data::FrfDataset;
use frfit::FrfitError;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `frfit simulate`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// What to simulate.
    #[command(subcommand)]
    pub target: Target,
}

/// Simulated systems.
#[derive(Subcommand, Debug)]
pub enum Target {
    /// The out-of-plane wafer stage (4 sensors x 13 actuators, 17 modes, 10 kHz).
    WaferStage(WaferArgs),
    /// A random modal plant of any size (rank-one modes, optional rigid body, close
    /// pairs), its exact FRF and a noisy measurement with its variance.
    RandomModal(RandomArgs),
    /// A piezo-actuated 3 x 3 mechanism (static gain, modes at 635-2770 Hz, one sample
    /// of delay at 6400 Hz) measured in open loop with orthogonal multisines and a
    /// stochastic nonlinear contribution: the nonparametric estimate (total and noise
    /// variance), and on request the time records and test records as NumPy arrays.
    Piezo(PiezoArgs),
}

/// Arguments of `frfit simulate piezo`.
#[derive(ClapArgs, Debug)]
pub struct PiezoArgs {
    /// Seed of the plant (mode shapes, static gain), the phases and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Measured periods per realization.
    #[arg(long, default_value_t = 2)]
    pub periods: usize,
    /// Realizations (3 orthogonal experiments each).
    #[arg(long, default_value_t = 2)]
    pub realizations: usize,
    /// Stochastic nonlinear contribution, relative standard deviation per entry and line
    /// (new in each realization, the same over its periods).
    #[arg(long, default_value_t = 0.03, value_name = "REL")]
    pub distortion: f64,
    /// White output noise, RMS per sample.
    #[arg(long, default_value_t = 4e-3)]
    pub noise: f64,
    /// Samples per period (6400 Hz sampling).
    #[arg(long, default_value_t = 8192)]
    pub period: usize,
    /// Every bin up to this frequency is excited, Hz.
    #[arg(long, default_value_t = 3000.0)]
    pub f_max: f64,
    /// Output FRF CSV (`_var` the total variance, `_var_noise` its noise part).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the exact noiseless response (the best linear approximation).
    #[arg(long)]
    pub noiseless: Option<PathBuf>,
    /// Also write the time records the estimate came from, as DIR/u.npy and DIR/y.npy
    /// (samples x channels x experiments x periods; experiments in realizations of 3).
    #[arg(long, value_name = "DIR")]
    pub records: Option<PathBuf>,
    /// Also write test records of the same plant (one new realization: new phases,
    /// noise and distortion) as DIR/u.npy and DIR/y.npy, for `frfit predict`.
    #[arg(long, value_name = "DIR")]
    pub test_records: Option<PathBuf>,
}

/// Arguments of `frfit simulate random-modal`.
#[derive(ClapArgs, Debug)]
pub struct RandomArgs {
    /// Outputs.
    #[arg(long, default_value_t = 4)]
    pub ny: usize,
    /// Inputs.
    #[arg(long, default_value_t = 4)]
    pub nu: usize,
    /// Flexible modes.
    #[arg(long, default_value_t = 10)]
    pub modes: usize,
    /// Frequency lines.
    #[arg(long, default_value_t = 4000)]
    pub lines: usize,
    /// Band of the lines, Hz (modes are drawn 5 % inside it).
    #[arg(long, value_parser = parse_band, value_name = "LO:HI", default_value = "50:2000")]
    pub band: Band,
    /// Noise standard deviation relative to the median magnitude (0: exact data).
    #[arg(long, default_value_t = 1e-3)]
    pub noise: f64,
    /// Relative damping range LO:HI (log-uniform).
    #[arg(long, value_name = "LO:HI", default_value = "0.002:0.02")]
    pub damping: String,
    /// Fraction of the modes placed as close pairs (0.1 to 1 % above another mode).
    #[arg(long, default_value_t = 0.1)]
    pub close_pairs: f64,
    /// Add a free rigid body (double integrator of rank min(3, ny, nu)).
    #[arg(long)]
    pub rigid_body: bool,
    /// Logarithmically spaced lines (default: uniform, as periodic excitation gives).
    #[arg(long)]
    pub log_grid: bool,
    /// Seed of the plant and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output FRF CSV (with `_var` columns when the noise is above 0).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the true modal parameters (truth JSON schema of the reference data).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Also write the exact noiseless response at the same lines.
    #[arg(long)]
    pub noiseless: Option<PathBuf>,
}

/// Simulation path.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathArg {
    /// Periodic steady state per line (fast).
    Frequency,
    /// Sample-by-sample simulation of the sampled loop from rest.
    Time,
}

/// Arguments of `frfit simulate wafer-stage`.
#[derive(ClapArgs, Debug)]
pub struct WaferArgs {
    /// Seed of the plant, the phases and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Measured periods per realization.
    #[arg(long, default_value_t = 10)]
    pub periods: usize,
    /// Realizations (random-phase multisines).
    #[arg(long, default_value_t = 10)]
    pub realizations: usize,
    /// Output FRF CSV (with `_var` columns).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the true modal parameters (truth JSON schema of the reference data).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Also write the exact noiseless sampled response at the same lines.
    #[arg(long)]
    pub noiseless: Option<PathBuf>,
    /// Also write the per-period spectra (periodic spectra CSV; large).
    #[arg(long)]
    pub spectra: Option<PathBuf>,
    /// Highest excited line, Hz (odd lines of 0.25 Hz from 0.25 Hz up).
    #[arg(long, default_value_t = 2000.0)]
    pub f_max: f64,
    /// Samples per period (10 kHz sampling: 40000 gives 0.25 Hz resolution).
    #[arg(long, default_value_t = 40_000)]
    pub period: usize,
    /// RMS force of each experiment's multisine, N.
    #[arg(long, default_value_t = 2.0)]
    pub rms: f64,
    /// White sensor noise RMS, nm.
    #[arg(long, default_value_t = 1.0)]
    pub noise_nm: f64,
    /// Low-frequency drift RMS, nm.
    #[arg(long, default_value_t = 5.0)]
    pub drift_nm: f64,
    /// Drift corner frequency, Hz.
    #[arg(long, default_value_t = 0.5)]
    pub drift_corner_hz: f64,
    /// White measurement noise on the recorded forces, N RMS.
    #[arg(long, default_value_t = 0.0)]
    pub input_noise: f64,
    /// Cubic actuator nonlinearity `alpha` in `f = u + alpha u^3` (1/N^2).
    #[arg(long, default_value_t = 0.0)]
    pub nonlinearity: f64,
    /// Stochastic nonlinear contribution, relative standard deviation per entry and line:
    /// the plant behaves as `P + G_S` with `G_S` new in each realization and the same in
    /// all its periods (0: none). With `--realizations 1` the `_var` columns come from the
    /// periods alone and miss it, as on a measured bench with one multisine realization.
    #[arg(long, default_value_t = 0.0, value_name = "REL")]
    pub distortion: f64,
    /// Crossover of the rigid-body loops, Hz.
    #[arg(long, default_value_t = 20.0)]
    pub bandwidth_hz: f64,
    /// An undeclared factor of unit static gain on every entry (an amplifier's
    /// bandwidth): `F` for a first-order lag `1 / (1 + s / 2 pi F)`, `F:ZETA` for a
    /// second-order `w^2 / (s^2 + 2 ZETA w s + w^2)`, `w = 2 pi F`;
    /// `lead-lag:FZ:FP` for `(1 + s / 2 pi FZ) / (1 + s / 2 pi FP)`;
    /// `rational:FZ:ZZ:FP:ZP` for the second-order factor with zeros at FZ (damping ZZ,
    /// negative: non-minimum phase) and poles at FP (damping ZP). E.g. `2500`.
    #[arg(long, value_name = "F[:ZETA]")]
    pub common_dynamics: Option<String>,
    /// An undeclared factor on one output row (a sensor or its mount), output 1-based:
    /// `I:F` (first-order lag), `I:F:ZETA` (second-order resonance),
    /// `I:lead-lag:FZ:FP` (zero FZ, pole FP, Hz) or `I:rational:FZ:ZZ:FP:ZP`, e.g.
    /// `2:1450:0.03` for a sensor-mount resonance at 1.45 kHz. Repeatable.
    #[arg(long, value_name = "I:F[:ZETA]")]
    pub output_dynamics: Vec<String>,
    /// An undeclared factor on one input column (an actuator or its mount), input
    /// 1-based, in the forms of `--output-dynamics`: e.g. `5:800` (a lag at 800 Hz on
    /// input 5) or `5:lead-lag:300:900` (a phase lead, zero 300 Hz, pole 900 Hz).
    /// Repeatable.
    #[arg(long, value_name = "J:F[:ZETA]")]
    pub input_dynamics: Vec<String>,
    /// Simulation path.
    #[arg(long, value_enum, default_value_t = PathArg::Frequency)]
    pub path: PathArg,
}

/// Runs `frfit simulate`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    match args.target {
        Target::WaferStage(a) => run_wafer(a, quiet),
        Target::RandomModal(a) => run_random(a, quiet),
        Target::Piezo(a) => run_piezo(a, quiet),
    }
}

/// Writes the time records of `spectra` (every realization's experiments in order) as
/// `dir/u.npy` and `dir/y.npy`, shaped `(samples of a period, channels, experiments,
/// periods)` in C order, the layout `frfit nonparametric` and `frfit predict` read.
fn write_time_records(
    dir: &std::path::Path,
    spectra: &experiment::nonparametric::PeriodicSpectra,
    period: usize,
    periods: usize,
) -> Result<(), FrfitError> {
    std::fs::create_dir_all(dir).map_err(|e| FrfitError::io(dir, e))?;
    let records: Vec<&experiment::nonparametric::TimeRecords> = spectra
        .realizations
        .iter()
        .map(|r| {
            r.time.as_ref().ok_or_else(|| FrfitError::Fit {
                what: "time records".into(),
                why: "the simulation kept no time records".into(),
            })
        })
        .collect::<Result<_, _>>()?;
    let write = |name: &str,
                 pick: &dyn Fn(&experiment::nonparametric::TimeRecords) -> &Vec<Vec<Vec<f64>>>|
     -> Result<(), FrfitError> {
        let per_exp: Vec<&[Vec<f64>]> = records
            .iter()
            .flat_map(|r| pick(r).iter().map(|e| e.as_slice()))
            .collect();
        let (shape, data) = frfit::nonparametric::array_from_records(&per_exp, period, periods)?;
        let a = frf_data::io::npy::NpyArray { shape, data };
        Ok(frf_data::io::npy::write_npy(dir.join(name), &a)?)
    };
    write("u.npy", &|r| &r.input)?;
    write("y.npy", &|r| &r.output)?;
    Ok(())
}

fn run_piezo(a: PiezoArgs, quiet: bool) -> Result<(), FrfitError> {
    use experiment::synth::{piezo_experiment, PiezoConfig};
    let t0 = Instant::now();
    let cfg = PiezoConfig {
        seed: a.seed,
        fs: 6400.0,
        period: a.period,
        f_max_hz: a.f_max,
        periods: a.periods,
        realizations: a.realizations,
        distortion: a.distortion,
        noise_rms: a.noise,
        keep_time_signals: a.records.is_some(),
        ..PiezoConfig::default()
    };
    let exp = piezo_experiment(&cfg)?;
    let spectra = exp.run(SimulationPath::TimeDomain)?;
    let est = experiment::nonparametric::estimate(&spectra, &EstimatorConfig::default())?;
    let comments = vec![
        format!("synthetic piezo-actuated 3 x 3 mechanism, seed {}", a.seed),
        format!(
            "open loop, orthogonal random-phase multisines, every line to {} Hz; sampling {} Hz with one sample of computation delay and a zero-order hold",
            a.f_max, cfg.fs
        ),
        format!(
            "periods={} realizations={} experiments={}",
            est.periods, est.realizations, est.n_experiments
        ),
        format!(
            "stochastic nonlinear contribution: relative std {} per entry and line, new in each realization",
            a.distortion
        ),
    ];
    frf_data::io::write_frf_csv(&a.out, &est.frf, &comments)?;
    if let Some(p) = &a.noiseless {
        frf_data::io::write_frf_csv(
            p,
            &exp.true_frf()?,
            &[format!(
                "synthetic piezo mechanism, seed {}: exact noiseless response (the best linear approximation)",
                a.seed
            )],
        )?;
    }
    if let Some(dir) = &a.records {
        write_time_records(dir, &spectra, a.period, a.periods)?;
    }
    if let Some(dir) = &a.test_records {
        let test = piezo_experiment(&PiezoConfig {
            realizations: 1,
            phase_seed: Some(a.seed.wrapping_add(1_000_003)),
            keep_time_signals: true,
            ..cfg.clone()
        })?;
        let spectra = test.run(SimulationPath::TimeDomain)?;
        write_time_records(dir, &spectra, a.period, a.periods)?;
    }
    if !quiet {
        eprintln!(
            "wrote {} ({} lines, {} periods x {} realizations) in {:.1} s",
            a.out.display(),
            est.frf.n_lines(),
            est.periods,
            est.realizations,
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// Writes a truth JSON file (the schema of the reference data's `*.truth.json`).
fn write_truth(path: &std::path::Path, truth: &frf_data::truth::Truth) -> Result<(), FrfitError> {
    let text = serde_json::to_string_pretty(truth).map_err(|e| FrfitError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    std::fs::write(path, text + "\n").map_err(|e| FrfitError::io(path, e))
}

fn run_random(a: RandomArgs, quiet: bool) -> Result<(), FrfitError> {
    let t0 = Instant::now();
    let damping = {
        let bad = || FrfitError::Argument {
            name: "--damping".into(),
            value: a.damping.clone(),
            why: "expected LO:HI relative damping, e.g. 0.002:0.02".into(),
        };
        let (l, h) = a.damping.split_once(':').ok_or_else(bad)?;
        (
            l.trim().parse::<f64>().map_err(|_| bad())?,
            h.trim().parse::<f64>().map_err(|_| bad())?,
        )
    };
    let (Some(lo), Some(hi)) = (a.band.lo_hz, a.band.hi_hz) else {
        return Err(FrfitError::Argument {
            name: "--band".into(),
            value: format!("{:?}:{:?}", a.band.lo_hz, a.band.hi_hz),
            why: "random-modal needs both edges, LO:HI in Hz".into(),
        });
    };
    let cfg = RandomModalConfig {
        ny: a.ny,
        nu: a.nu,
        modes: a.modes,
        lines: a.lines,
        band_hz: (lo, hi),
        zeta: damping,
        close_pair_fraction: a.close_pairs,
        rigid_body: a.rigid_body,
        noise: a.noise,
        log_grid: a.log_grid,
        seed: a.seed,
        ..RandomModalConfig::default()
    };
    let r = RandomModal::generate(&cfg)?;
    let what = format!(
        "random modal plant, seed {}: {} x {}, {} modes ({:.0} % close pairs){}, {} lines {lo}..{hi} Hz",
        a.seed,
        a.ny,
        a.nu,
        a.modes,
        100.0 * a.close_pairs,
        if a.rigid_body { ", free rigid body" } else { "" },
        a.lines
    );
    let comments = vec![
        what.clone(),
        format!(
            "continuous time, no delay; noise: circular complex Gaussian, std {:.4e} ({} x the median magnitude), stated in the _var columns",
            r.noise_std, a.noise
        ),
    ];
    frf_data::io::write_frf_csv(&a.out, &r.measured, &comments)?;
    if let Some(t) = &a.truth {
        write_truth(t, &r.plant.to_truth(a.seed, 0.0, 0.0))?;
    }
    if let Some(p) = &a.noiseless {
        frf_data::io::write_frf_csv(
            p,
            &r.noiseless,
            &[format!("{what}: exact noiseless response")],
        )?;
    }
    if !quiet {
        eprintln!(
            "{what}: noise std {:.3e}, {:.2} s -> {}",
            r.noise_std,
            t0.elapsed().as_secs_f64(),
            a.out.display()
        );
    }
    Ok(())
}

/// A factor of `--common-dynamics` (`indexed` = false: `F[:ZETA]`,
/// `lead-lag:FZ:FP`, `rational:FZ:ZZ:FP:ZP`) or of `--input-dynamics`/`--output-dynamics`
/// (the same after `I:`, 1-based), on `target`.
fn parse_factor(
    option: &str,
    value: &str,
    target: fn(usize) -> realize::FactorTarget,
    indexed: bool,
) -> Result<realize::DynamicsFactor, FrfitError> {
    let bad = |why: &str| FrfitError::Argument {
        name: option.into(),
        value: value.into(),
        why: why.into(),
    };
    let parts: Vec<&str> = value.split(':').map(str::trim).collect();
    let (index, rest) = if indexed {
        let i: usize = parts
            .first()
            .and_then(|x| x.parse().ok())
            .filter(|i| *i >= 1)
            .ok_or_else(|| bad("expected I:F[:ZETA] with I a 1-based index"))?;
        (i - 1, &parts[1..])
    } else {
        (0, &parts[..])
    };
    let num = |x: &str| x.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0);
    match rest {
        ["lead-lag", fz, fp] => {
            let fz = num(fz).ok_or_else(|| bad("the zero frequency FZ must be > 0 Hz"))?;
            let fp = num(fp).ok_or_else(|| bad("the pole frequency FP must be > 0 Hz"))?;
            Ok(realize::DynamicsFactor::lead_lag(target(index), fz, fp))
        }
        ["rational", fz, zz, fp, zp] => {
            let fz = num(fz).ok_or_else(|| bad("the zero frequency FZ must be > 0 Hz"))?;
            let zz = zz
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v != 0.0)
                .ok_or_else(|| bad("the zero damping ZZ must be finite and not 0"))?;
            let fp = num(fp).ok_or_else(|| bad("the pole frequency FP must be > 0 Hz"))?;
            let zp = num(zp).ok_or_else(|| bad("the pole damping ZP must be > 0"))?;
            Ok(realize::DynamicsFactor::second_order_rational(
                target(index),
                (fz, zz),
                (fp, zp),
            ))
        }
        ["lead-lag", ..] => Err(bad("expected lead-lag:FZ:FP (zero and pole, Hz)")),
        ["rational", ..] => Err(bad(
            "expected rational:FZ:ZZ:FP:ZP (zeros FZ Hz with damping ZZ, poles FP Hz with damping ZP)",
        )),
        [f] => {
            let f = num(f).ok_or_else(|| bad("the corner frequency F must be > 0 Hz"))?;
            Ok(realize::DynamicsFactor::first_order(target(index), f))
        }
        [f, z] => {
            let f = num(f).ok_or_else(|| bad("the frequency F must be > 0 Hz"))?;
            let z = num(z).ok_or_else(|| bad("the damping ZETA must be > 0"))?;
            Ok(realize::DynamicsFactor::second_order(target(index), f, z))
        }
        _ => Err(bad(if indexed {
            "expected I:F (first order), I:F:ZETA (second order), I:lead-lag:FZ:FP or I:rational:FZ:ZZ:FP:ZP"
        } else {
            "expected F (first order), F:ZETA (second order), lead-lag:FZ:FP or rational:FZ:ZZ:FP:ZP"
        })),
    }
}

/// The undeclared dynamics factors of `a`.
fn wafer_factors(a: &WaferArgs) -> Result<Vec<realize::DynamicsFactor>, FrfitError> {
    let mut out = Vec::new();
    if let Some(v) = &a.common_dynamics {
        out.push(parse_factor(
            "--common-dynamics",
            v,
            |_| realize::FactorTarget::All,
            false,
        )?);
    }
    for v in &a.output_dynamics {
        out.push(parse_factor(
            "--output-dynamics",
            v,
            realize::FactorTarget::Output,
            true,
        )?);
    }
    for v in &a.input_dynamics {
        out.push(parse_factor(
            "--input-dynamics",
            v,
            realize::FactorTarget::Input,
            true,
        )?);
    }
    Ok(out)
}

/// A factor in words: `first-order lag at 2500 Hz on every entry`.
fn describe_factor(d: &realize::DynamicsFactor) -> String {
    let f_hz = d.scale / std::f64::consts::TAU;
    let what = match (d.den.as_slice(), d.num.as_slice()) {
        ([_], []) => format!("first-order lag at {f_hz} Hz"),
        ([two_zeta, _], []) => {
            format!("second-order factor at {f_hz} Hz, zeta {}", 0.5 * two_zeta)
        }
        ([_], [b]) => format!("lead-lag, zero at {} Hz, pole at {f_hz} Hz", f_hz / b),
        ([two_zeta, _], [b1, b2]) => {
            // B = 1 + 2 zeta_z (s / w_z) + (s / w_z)^2 with s / w_z = x sqrt(b2)
            let r = b2.sqrt();
            format!(
                "second-order rational, zeros at {} Hz (zeta {}), poles at {f_hz} Hz (zeta {})",
                f_hz / r,
                0.5 * b1 / r,
                0.5 * two_zeta
            )
        }
        _ => format!("factor of order {} over {}", d.num.len(), d.den.len()),
    };
    let on = match d.target {
        realize::FactorTarget::All => "every entry".to_string(),
        realize::FactorTarget::Output(i) => format!("output {}", i + 1),
        realize::FactorTarget::Input(j) => format!("input {}", j + 1),
    };
    format!("{what} on {on}")
}

fn run_wafer(a: WaferArgs, quiet: bool) -> Result<(), FrfitError> {
    let t0 = Instant::now();
    let factors = wafer_factors(&a)?;
    let stage = WaferStageConfig {
        seed: a.seed,
        ..WaferStageConfig::default()
    };
    let grid = LineGrid::odd(stage.fs, a.period, 0.0, a.f_max)?;
    let exp = ExperimentConfig {
        grid,
        periods: a.periods,
        realizations: a.realizations,
        transient_periods: 1,
        rms: a.rms,
        output_noise: NoiseConfig {
            white_rms: a.noise_nm * 1e-9,
            drift_rms: a.drift_nm * 1e-9,
            drift_corner_hz: a.drift_corner_hz,
        },
        input_noise_rms: a.input_noise,
        cubic_nonlinearity: a.nonlinearity,
        stochastic_distortion: a.distortion,
        delay_samples: stage.delay_samples,
        excited_inputs: None,
        plant_dynamics: factors.clone(),
        seed: a.seed,
        keep_time_signals: false,
    };
    let ctrl = ControllerConfig {
        bandwidth_hz: a.bandwidth_hz,
        ..ControllerConfig::default()
    };
    let w = WaferStageExperiment::new(&stage, &ctrl, exp)?;
    let path = match a.path {
        PathArg::Frequency => SimulationPath::FrequencyDomain,
        PathArg::Time => SimulationPath::TimeDomain,
    };
    let est_cfg = EstimatorConfig::default();
    let mut est = if let Some(sp) = &a.spectra {
        let spectra = w.experiment.run(path)?;
        write_spectra_csv(
            sp,
            &spectra,
            &[format!(
                "synthetic wafer stage, seed {}: per-period spectra",
                a.seed
            )],
        )?;
        experiment::nonparametric::estimate(&spectra, &est_cfg)?
    } else {
        w.experiment.estimate(path, &est_cfg)?
    };
    est.frf.units = Some("m/N".into());
    let comments = vec![
        format!("synthetic wafer stage, seed {}", a.seed),
        "units=m/N (displacement per force)".into(),
        format!(
            "sampling {} kHz; zero-order hold + {} sample(s) computation delay ({} us)",
            w.stage.fs / 1000.0,
            w.stage.delay_samples,
            (0.5 + w.stage.delay_samples) / w.stage.fs * 1e6
        ),
        format!(
            "closed-loop indirect estimate, {} periods x {} realizations, {} single-axis experiments, {:?} path",
            a.periods,
            a.realizations,
            w.experiment.n_experiments(),
            path
        ),
        format!(
            "variance: {}",
            est.frf
                .metadata
                .get("variance")
                .cloned()
                .unwrap_or_else(|| "none".into())
        ),
    ];
    let mut comments = comments;
    if a.distortion > 0.0 {
        comments.push(format!(
            "stochastic nonlinear contribution: relative std {} per entry and line, new in each realization, the same over its periods{}",
            a.distortion,
            if a.realizations < 2 {
                " (the variance, from the periods of one realization, does not hold it)"
            } else {
                ""
            }
        ));
    }
    for d in &factors {
        comments.push(format!(
            "undeclared dynamics (simulated, not in the nominal model): {}",
            describe_factor(d)
        ));
    }
    frf_data::io::write_frf_csv(&a.out, &est.frf, &comments)?;
    if let Some(t) = &a.truth {
        let mut truth = w.stage.truth();
        if !factors.is_empty() {
            let list: Vec<serde_json::Value> = factors
                .iter()
                .map(|d| {
                    serde_json::json!({
                        "factor": d,
                        "description": describe_factor(d),
                    })
                })
                .collect();
            truth
                .effects
                .insert("dynamics".into(), serde_json::Value::Array(list));
        }
        write_truth(t, &truth)?;
    }
    if let Some(p) = &a.noiseless {
        let mut f = w.experiment.true_frf()?;
        f.units = Some("m/N".into());
        frf_data::io::write_frf_csv(
            p,
            &f,
            &[format!(
                "synthetic wafer stage, seed {}: exact noiseless response (zero-order hold + delay{})",
                a.seed,
                if factors.is_empty() {
                    ""
                } else {
                    " + the undeclared dynamics"
                }
            )],
        )?;
    }
    if !quiet {
        eprintln!(
            "simulated wafer stage seed {}: {} lines {}..{} Hz, {}x{}, spectral radius {:.6}, {:.2} s -> {}",
            a.seed,
            est.frf.n_lines(),
            est.frf.freq_hz(0),
            est.frf.freq_hz(est.frf.n_lines() - 1),
            est.frf.ny(),
            est.frf.nu(),
            w.experiment.spectral_radius(),
            t0.elapsed().as_secs_f64(),
            a.out.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::truth::Truth;

    fn args(dir: &std::path::Path) -> WaferArgs {
        WaferArgs {
            seed: 3,
            periods: 2,
            realizations: 2,
            out: dir.join("ws.csv"),
            truth: Some(dir.join("ws.truth.json")),
            noiseless: Some(dir.join("ws.noiseless.csv")),
            spectra: Some(dir.join("ws.spectra.csv")),
            f_max: 500.0,
            period: 2000,
            rms: 2.0,
            noise_nm: 1.0,
            drift_nm: 5.0,
            drift_corner_hz: 0.5,
            input_noise: 0.0,
            nonlinearity: 0.0,
            distortion: 0.0,
            bandwidth_hz: 20.0,
            common_dynamics: None,
            output_dynamics: Vec::new(),
            input_dynamics: Vec::new(),
            path: PathArg::Frequency,
        }
    }

    #[test]
    fn writes_the_estimate_truth_noiseless_response_and_spectra() {
        let dir = std::env::temp_dir().join(format!("frfit_simulate_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let a = args(&dir);
        run(
            Args {
                target: Target::WaferStage(a),
            },
            true,
        )
        .unwrap();
        let est = frf_data::io::read_frf_csv(dir.join("ws.csv")).unwrap();
        assert_eq!((est.ny(), est.nu(), est.n_lines()), (4, 13, 50));
        assert!(est.has_variance());
        assert_eq!(est.units(), Some("m/N"));
        let truth = Truth::read(dir.join("ws.truth.json")).unwrap();
        assert_eq!(truth.seed, 3);
        assert_eq!(truth.model.modes.len(), 17);
        let exact = frf_data::io::read_frf_csv(dir.join("ws.noiseless.csv")).unwrap();
        // the estimate is within a few standard deviations of the exact response
        let (mut e, mut v) = (0.0, 0.0);
        for k in 0..est.n_lines() {
            for i in 0..4 {
                for j in 0..13 {
                    e += (est.value(k, i, j) - exact.value(k, i, j)).norm_sqr();
                    v += est.variance(k, i, j).unwrap();
                }
            }
        }
        assert!(e / v < 4.0, "{}", e / v);
        let spectra =
            experiment::nonparametric::spectra_csv::read_spectra_csv(dir.join("ws.spectra.csv"))
                .unwrap();
        assert_eq!(spectra.realizations.len(), 2);
        assert_eq!(spectra.n_experiments(), 13);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The random plant's files: the measurement with its variance, the truth (its modes
    /// rebuild the noiseless response exactly) and the noiseless response.
    #[test]
    fn random_modal_writes_data_truth_and_noiseless_response() {
        let dir = std::env::temp_dir().join(format!("frfit_simulate_rm_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let a = RandomArgs {
            ny: 3,
            nu: 2,
            modes: 6,
            lines: 300,
            band: parse_band("20:1000").unwrap(),
            noise: 1e-3,
            damping: "0.005:0.01".into(),
            close_pairs: 0.2,
            rigid_body: true,
            log_grid: false,
            seed: 9,
            out: dir.join("rm.csv"),
            truth: Some(dir.join("rm.truth.json")),
            noiseless: Some(dir.join("rm.noiseless.csv")),
        };
        run(
            Args {
                target: Target::RandomModal(a),
            },
            true,
        )
        .unwrap();
        let d = frf_data::io::read_frf_csv(dir.join("rm.csv")).unwrap();
        assert_eq!((d.ny(), d.nu(), d.n_lines()), (3, 2, 300));
        assert!(d.has_variance());
        let truth = Truth::read(dir.join("rm.truth.json")).unwrap();
        assert_eq!(truth.model.modes.len(), 6);
        assert!(truth
            .model
            .modes
            .iter()
            .all(|m| (0.005..=0.01).contains(&m.zeta) && m.f_hz > 20.0 && m.f_hz < 1000.0));
        let plant = experiment::synth::ModalPlant::from_truth(&truth).unwrap();
        let exact = frf_data::io::read_frf_csv(dir.join("rm.noiseless.csv")).unwrap();
        let g = plant.continuous_response(&exact.freqs_hz()).unwrap().values;
        let worst = g
            .iter()
            .zip(exact.values_vec())
            .map(|(a, b)| (a - b).norm() / b.norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "truth vs noiseless file: {worst:e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The undeclared factors multiply the noiseless response entry by entry, on the
    /// entries they target, and are written to the truth file.
    #[test]
    fn undeclared_dynamics_are_in_the_noiseless_response_and_the_truth() {
        let dir = std::env::temp_dir().join(format!("frfit_simulate_dyn_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let plain = args(&dir);
        let mut with = args(&dir);
        with.out = dir.join("dyn.csv");
        with.noiseless = Some(dir.join("dyn.noiseless.csv"));
        with.truth = Some(dir.join("dyn.truth.json"));
        with.spectra = None;
        with.common_dynamics = Some("2500".into());
        with.output_dynamics = vec!["2:450:0.03".into()];
        with.input_dynamics = vec!["3:lead-lag:300:900".into()];
        for a in [plain, with] {
            run(
                Args {
                    target: Target::WaferStage(a),
                },
                true,
            )
            .unwrap();
        }
        let g0 = frf_data::io::read_frf_csv(dir.join("ws.noiseless.csv")).unwrap();
        let g1 = frf_data::io::read_frf_csv(dir.join("dyn.noiseless.csv")).unwrap();
        let mut worst = 0.0f64;
        for k in 0..g0.n_lines() {
            let s = frf_data::C64::new(0.0, g0.freq_hz(k) / 2500.0);
            let lag = (s + 1.0).inv();
            let w = g0.freq_hz(k) / 450.0;
            let res = frf_data::C64::new(1.0 - w * w, 0.06 * w).inv();
            for i in 0..4 {
                for j in 0..13 {
                    let mut f = if i == 1 { lag * res } else { lag };
                    if j == 2 {
                        let s = frf_data::C64::new(0.0, g0.freq_hz(k));
                        f *= (s / 300.0 + 1.0) / (s / 900.0 + 1.0);
                    }
                    let want = g0.value(k, i, j) * f;
                    worst = worst.max((g1.value(k, i, j) - want).norm() / want.norm());
                }
            }
        }
        assert!(worst < 1e-9, "factors in the noiseless response: {worst:e}");
        let truth = Truth::read(dir.join("dyn.truth.json")).unwrap();
        let list = truth.effects["dynamics"].as_array().unwrap();
        assert_eq!(list.len(), 3);
        assert_eq!(list[1]["factor"]["target"]["index"], 1);
        assert_eq!(list[2]["factor"]["target"]["index"], 2);
        assert_eq!(list[2]["factor"]["num"].as_array().unwrap().len(), 1);
        assert!(list[2]["description"]
            .as_str()
            .unwrap()
            .contains("zero at 300 Hz"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_settings_are_errors() {
        let dir = std::env::temp_dir().join(format!("frfit_simulate_bad_{}", std::process::id()));
        for f in [
            (|a: &mut WaferArgs| a.periods = 0) as fn(&mut WaferArgs),
            |a| a.f_max = 0.1,
            |a| a.bandwidth_hz = 400.0,
            |a| a.rms = -1.0,
            |a| a.distortion = -1e-3,
            |a| {
                a.distortion = 1e-3;
                a.path = PathArg::Time;
            },
            |a| a.common_dynamics = Some("0".into()),
            |a| a.common_dynamics = Some("2500:0.7:1".into()),
            |a| a.output_dynamics = vec!["5:1450:0.03".into()],
            |a| a.input_dynamics = vec!["0:1000".into()],
            |a| a.input_dynamics = vec!["2:1000:-0.1".into()],
            |a| a.input_dynamics = vec!["2:lead-lag:300".into()],
            |a| a.input_dynamics = vec!["2:lead-lag:0:900".into()],
            |a| a.output_dynamics = vec!["1:rational:800:0:1200:0.03".into()],
            |a| a.common_dynamics = Some("rational:800:0.1:1200:-0.03".into()),
            |a| {
                a.common_dynamics = Some("2500".into());
                a.path = PathArg::Time;
            },
        ] {
            let mut a = args(&dir);
            f(&mut a);
            let e = run(
                Args {
                    target: Target::WaferStage(a),
                },
                true,
            );
            assert!(e.is_err());
        }
    }
}
