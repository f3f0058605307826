//! Shared by the CLI integration tests: running the binary, temporary directories,
//! and a small simulated plant written as FRF CSV.

#![allow(dead_code)]

use experiment::nonparametric::{EstimatorConfig, LineGrid};
use experiment::synth::{
    ClosedLoopExperiment, ControllerConfig, ExperimentConfig, FlexibleMode, NoiseConfig, RigidBody,
    RigidBodyController, SimulationPath, WaferStage, WaferStageConfig,
};
use faer::Mat;
use frf_data::{Frf, FrfDataset};
use realize::{ModalModel, PolePair};
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The flexible modes of [`write_plant`], Hz.
pub const MODES_HZ: [f64; 3] = [35.0, 80.0, 150.0];

/// The `frfit` binary of this build.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_frfit"))
}

/// Runs the binary with `args`.
pub fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("the frfit binary runs")
}

/// Its standard output as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Its standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A unique temporary directory for one test.
pub fn temp_dir(test: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let d = std::env::temp_dir().join(format!("frfit-cli-{test}-{}-{nanos}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The 2 x 3 plant of the CLI tests: a double integrator of rank 2 and modes at
/// [`MODES_HZ`] (damping 0.01, rank-one residues), no feedthrough.
pub fn plant() -> ModalModel {
    let (ny, nu) = (2, 3);
    let mut m = ModalModel::new(ny, nu);
    m.rigid = vec![
        Mat::zeros(ny, nu),
        Mat::from_fn(ny, nu, |i, j| 0.5 + 0.1 * (i + 2 * j) as f64),
    ];
    let shapes = [
        ([1.0, 0.4], [1.0, -0.5, 0.3]),
        ([0.3, -1.0], [0.2, 1.0, 0.8]),
        ([1.0, 1.0], [-0.7, 0.4, 1.0]),
    ];
    for (f, (c, b)) in MODES_HZ.iter().zip(shapes) {
        let num = Mat::from_fn(ny, nu, |i, j| c[i] * b[j] * (TAU * f).powi(2) * 2.0);
        m.pairs.push(PolePair::from_second_order(*f, 0.01, &num));
    }
    m
}

/// Writes a 2 x 3 plant (free body + modes at 35, 80 and 150 Hz, damping 0.01),
/// 5..200 Hz in 0.25 Hz lines, delayed by `delay_s`, with a variance of
/// `(1e-3 |G|)^2` attached (the values themselves are exact), to `dir/plant.csv`.
pub fn write_plant(dir: &Path, delay_s: f64) -> PathBuf {
    let m = plant();
    let (ny, nu) = (m.ny, m.nu);
    let f: Vec<f64> = (0..781).map(|k| 5.0 + 0.25 * k as f64).collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let g = m.freq_response(&w).unwrap();
    let frf = Frf::from_grid(f, g).unwrap();
    let frf = Frf::from_fn(frf.freq_hz_slice().to_vec(), ny, nu, |k, i, j| {
        frf.value(k, i, j) * frf_data::C64::from_polar(1.0, -w[k] * delay_s)
    })
    .unwrap();
    let mut frf = with_relative_variance(frf, 1e-3);
    frf.units = Some("m/N".into());
    let path = dir.join("plant.csv");
    frf_data::io::write_frf_csv(
        &path,
        &frf,
        &["simulated 2x3 plant for the CLI tests".into()],
    )
    .unwrap();
    path
}

/// `frf` (its values unchanged) with the variance `(rel |G|)^2` attached.
pub fn with_relative_variance(frf: Frf, rel: f64) -> Frf {
    let var: Vec<f64> = frf
        .values()
        .iter()
        .map(|z| (rel * z.norm()).powi(2))
        .collect();
    frf.with_variance(Some(var)).unwrap()
}

/// The simulated wafer stage (seed 3), `periods` x `realizations`, lines up to 2 kHz,
/// with a stochastic nonlinear contribution of relative level `distortion` (new in each
/// realization), estimated in the frequency domain and commented as `frfit simulate`
/// writes; the estimate and the exact response.
pub fn simulated_wafer(periods: usize, realizations: usize, distortion: f64) -> (Frf, Frf) {
    simulated_wafer_with(40_000, periods, realizations, distortion, Vec::new(), 1.0)
}

/// [`simulated_wafer`] with the sensor noise (white and drift) `noise_gain` times the
/// simulator's default (1 nm white, 5 nm drift RMS).
pub fn noisy_simulated_wafer(
    periods: usize,
    realizations: usize,
    distortion: f64,
    noise_gain: f64,
) -> (Frf, Frf) {
    simulated_wafer_with(
        40_000,
        periods,
        realizations,
        distortion,
        Vec::new(),
        noise_gain,
    )
}

/// [`simulated_wafer`] with `period` samples per period (40000: lines 0.5 Hz apart,
/// 20000: 1 Hz), undeclared dynamics factors `plant_dynamics` (see
/// `experiment::synth::ExperimentConfig::plant_dynamics`), in the estimate and the exact
/// response alike, and the sensor noise `noise_gain` times the default.
pub fn simulated_wafer_with(
    period: usize,
    periods: usize,
    realizations: usize,
    distortion: f64,
    plant_dynamics: Vec<realize::DynamicsFactor>,
    noise_gain: f64,
) -> (Frf, Frf) {
    let (data, clean, _) = simulate(&Sim {
        period,
        periods,
        realizations,
        distortion,
        plant_dynamics,
        noise_gain,
        ..Sim::default()
    });
    (data, clean)
}

/// A simulated wafer-stage measurement (the plate of `seed`), as `frfit simulate
/// wafer-stage` makes it.
#[derive(Debug, Clone)]
pub struct Sim {
    /// Seed of the plate, the phases and the noise. Default 3.
    pub seed: u64,
    /// Samples per period (10 kHz sampling: 40000 gives lines 0.5 Hz apart). Default
    /// 40000.
    pub period: usize,
    /// Measured periods per realization. Default 10.
    pub periods: usize,
    /// Realizations. Default 10.
    pub realizations: usize,
    /// Relative level of a stochastic nonlinear contribution. Default 0.
    pub distortion: f64,
    /// Undeclared dynamics factors of the plant. Default none.
    pub plant_dynamics: Vec<realize::DynamicsFactor>,
    /// Sensor noise (white and drift) over the default 1 nm / 5 nm. Default 1.
    pub noise_gain: f64,
    /// Highest excited line, Hz. Default 2000.
    pub f_max: f64,
    /// Computation delay beyond the stage's one sample that the comments do not declare,
    /// samples. Default 0.
    pub extra_delay_samples: f64,
    /// A suspension `(f_hz, zeta)` of the rigid body (the catalogue's `stiffness`): the
    /// plate's rigid-body residue over `s^2 + 2 zeta w s + w^2` instead of `s^2`.
    /// Default none (a free plate).
    pub suspension: Option<(f64, f64)>,
    /// Modes added to the plate's (a mode the first fit may miss). Default none.
    pub extra_modes: Vec<FlexibleMode>,
    /// A feedthrough `D` (4 x 13) of the plant. Default none.
    pub feedthrough: Option<Mat<f64>>,
}

impl Default for Sim {
    fn default() -> Self {
        Self {
            seed: 3,
            period: 40_000,
            periods: 10,
            realizations: 10,
            distortion: 0.0,
            plant_dynamics: Vec::new(),
            noise_gain: 1.0,
            f_max: 2000.0,
            extra_delay_samples: 0.0,
            suspension: None,
            extra_modes: Vec::new(),
            feedthrough: None,
        }
    }
}

/// Runs the simulation of `sim`: the frequency-domain estimate commented as `frfit
/// simulate` writes, the exact response, and the plate's highest true mode, Hz.
pub fn simulate(sim: &Sim) -> (Frf, Frf, f64) {
    let nominal = WaferStageConfig::default();
    let stage = WaferStageConfig {
        seed: sim.seed,
        delay_samples: nominal.delay_samples + sim.extra_delay_samples,
        ..nominal
    };
    let (periods, realizations) = (sim.periods, sim.realizations);
    let exp = ExperimentConfig {
        grid: LineGrid::odd(stage.fs, sim.period, 0.0, sim.f_max).unwrap(),
        periods,
        realizations,
        transient_periods: 1,
        rms: 2.0,
        output_noise: NoiseConfig {
            white_rms: 1e-9 * sim.noise_gain,
            drift_rms: 5e-9 * sim.noise_gain,
            drift_corner_hz: 0.5,
        },
        input_noise_rms: 0.0,
        cubic_nonlinearity: 0.0,
        stochastic_distortion: sim.distortion,
        delay_samples: stage.delay_samples,
        excited_inputs: None,
        plant_dynamics: sim.plant_dynamics.clone(),
        seed: sim.seed,
        keep_time_signals: false,
    };
    let mut plate = WaferStage::build(&stage).unwrap();
    let plant = &mut plate.plant;
    if let Some((f_hz, zeta)) = sim.suspension {
        let residue = plant.rigid.residue().unwrap().clone();
        plant.rigid = RigidBody::Suspended {
            residue,
            f_hz,
            zeta,
        };
    }
    plant.modes.extend(sim.extra_modes.iter().cloned());
    plant.modes.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
    if let Some(d) = &sim.feedthrough {
        plant.feedthrough = Some(d.clone());
    }
    let last = plant.modes.iter().map(|m| m.f_hz).fold(0.0f64, f64::max);
    let k = RigidBodyController::design(plant, &ControllerConfig::default(), stage.fs).unwrap();
    let experiment = ClosedLoopExperiment::new(plant.clone(), k, exp).unwrap();
    let mut est = experiment
        .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())
        .unwrap();
    est.frf.comments = vec![
        "sampling 10 kHz; zero-order hold + 1 sample(s) computation delay (150 us)".into(),
        format!("closed-loop indirect estimate, {periods} periods x {realizations} realizations"),
    ];
    (est.frf, experiment.true_frf().unwrap(), last)
}

/// The median over lines and entries of `|P - G| / |G|`: the final model of `out`
/// against the exact response `clean`, on `clean`'s lines in `lo..hi` Hz.
pub fn median_rel_vs_truth(out: &frfit::run::PipelineOutput, clean: &Frf, lo: f64, hi: f64) -> f64 {
    use frf_data::{FrfDataset, ModelStructure};
    let clean = clean.band(lo, hi).unwrap();
    let g = out.fit.model.response(&clean);
    let m = clean.n_entries();
    let mut rel: Vec<f64> = (0..clean.n_lines() * m)
        .map(|idx| {
            let t = clean.value(idx / m, idx % m % clean.ny(), idx % m / clean.ny());
            (g.values[idx] - t).norm() / t.norm()
        })
        .collect();
    rel.sort_by(|a, b| a.total_cmp(b));
    rel[rel.len() / 2]
}

/// Prints the first fit's errors, every step of the diagnosis of `out` and its verdict,
/// under `name`.
pub fn print_steps(name: &str, out: &frfit::run::PipelineOutput) {
    let s = &out.summary;
    println!("{name}: initial {:?}", s.initial.errors);
    for st in &s.steps {
        println!(
            "  {} accepted={}{} F={:.3} (crit {:.3}) {} median {:.3e} -> {:.3e}",
            st.effect(),
            st.accepted,
            st.superseded_by
                .map_or(String::new(), |n| format!(" (removed at step {n})")),
            st.f_statistic,
            st.f_critical,
            st.fitted.params_json(),
            st.before.median_rel,
            st.after.median_rel
        );
    }
    println!(
        "  verdict {}: {}\n  final {:?}, data noise {:?}",
        s.verdict, s.verdict_evidence, s.final_errors, s.data_noise_median_rel
    );
    let stages: Vec<String> = s
        .timings
        .iter()
        .map(|t| format!("{} {:.2} s", t.stage, t.seconds))
        .collect();
    println!("  timings: {}", stages.join("; "));
}

/// The one accepted second-order `output_dynamics` step of `out`: on output `row`
/// (1-based), at `f_r` (within 1 %) with damping `zeta` (within 10 %).
pub fn assert_output_resonance(out: &frfit::run::PipelineOutput, row: usize, f_r: f64, zeta: f64) {
    let steps = accepted(out, "output_dynamics");
    assert_eq!(steps.len(), 1, "one output_dynamics step");
    let p = steps[0].fitted.params_json();
    assert_eq!(p["support"], "outputs");
    assert_eq!(p["order"], 2);
    assert_eq!(p["outputs"][0], row, "the resonance is on output {row}");
    let pole = &p["poles"][0];
    let (f, z) = (
        pole["f_hz"].as_f64().unwrap(),
        pole["zeta"].as_f64().unwrap(),
    );
    assert!(
        (f / f_r - 1.0).abs() < 0.01,
        "resonance at {f:.1} Hz, made at {f_r}"
    );
    assert!((z / zeta - 1.0).abs() < 0.1, "damping {z:.4}, made {zeta}");
}

/// The accepted steps of `out` that add `effect`, except those a later step took out of
/// the model (`superseded_by`).
pub fn accepted<'a>(
    out: &'a frfit::run::PipelineOutput,
    effect: &str,
) -> Vec<&'a frfit::summary::StepSummary> {
    out.summary
        .steps
        .iter()
        .filter(|s| s.accepted && s.superseded_by.is_none() && s.effect() == effect)
        .collect()
}

/// Runs the diagnosis on `data` (default settings, modes from `modes`) and prints its
/// steps and how long it took.
pub fn diagnose(
    data: &Frf,
    name: &str,
    modes: additive_riv::ModeSelection,
) -> frfit::run::PipelineOutput {
    let cfg = frfit::pipeline::PipelineConfig {
        diagnose: true,
        modes,
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let out = frfit::run::run(data, name, &cfg, "diagnose").unwrap();
    print_steps(name, &out);
    println!("  diagnosis took {:.1} s", t.elapsed().as_secs_f64());
    out
}
