//! `cargo xtask effects`: the diagnosis on undeclared effects and pairs of them, over
//! many plates of the simulated wafer stage, each against its exact response.
//!
//! The tests hold one plate per case with chosen values (`crates/frfit/tests/
//! effect_pairs.rs`, `dynamics_factors.rs`); this sweep draws the effects' values per
//! plate (plate seed `seed + k`), so that a case that holds only for the values in the
//! tests shows. Each run is judged as the tests judge it: the expected effects named as
//! accepted steps (and not taken out by a later step), no other effect of the catalogue
//! accepted (a `missed_mode` step is listed, not counted against the case: the first fit
//! may lack a member of a close pair), the verdict `noise_limited`, and the final model
//! within 1e-4 (median relative, every line) of the noiseless response.

use crate::{Context, Error};
use experiment::nonparametric::EstimatorConfig;
use experiment::synth::{
    ClosedLoopExperiment, ControllerConfig, FlexibleMode, RigidBody, RigidBodyController,
    SimulationPath, WaferStage, WaferStageConfig,
};
use faer::Mat;
use frf_data::{Frf, FrfDataset, ModelStructure};
use frfit::additive_riv::ModeSelection;
use frfit::pipeline::PipelineConfig;
use frfit::realize::{DynamicsFactor, FactorTarget};
use frfit::run::{self, PipelineOutput};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// The cases of the sweep (`--case`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Case {
    /// A common first-order lag (1.2-2.5 kHz) with an undeclared delay (0.2-0.5 samples).
    LagDelay,
    /// A crosstalk (feedthrough of 1-4 nm/N) with a sensor-mount resonance on one output
    /// (1.2-1.8 kHz, damping 0.02-0.04).
    CrosstalkMount,
    /// A hidden mode 1-2 % beside a mode of the plate, the mode count declared one short.
    HiddenBeside,
    /// A first-order lag on one input (600-1200 Hz) with a mode the declared count leaves
    /// out (300-1500 Hz, at least 5 % from the plate's modes).
    InputLagMode,
    /// A suspension (2-6 Hz, damping 0.03-0.08) with an undeclared delay (0.2-0.5 samples).
    SuspensionDelay,
}

/// Options of `cargo xtask effects`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Cases to run (repeatable). Default: every case.
    #[arg(long = "case", value_enum)]
    cases: Vec<Case>,
    /// First plate seed; plate `seed + k` for run `k`. Default 100 (beyond the tests'
    /// plates).
    #[arg(long, default_value_t = 100)]
    seed: u64,
    /// Plates per case.
    #[arg(long, default_value_t = 3)]
    plates: usize,
    /// Write each run's data (`CASE_SEED.csv`, as `frfit simulate` comments it) and
    /// exact response (`CASE_SEED.noiseless.csv`) here, to diagnose them again with
    /// `frfit diagnose`.
    #[arg(long)]
    save_data: Option<std::path::PathBuf>,
    /// With `--save-data`: write the data only, without diagnosing them.
    #[arg(long, requires = "save_data")]
    save_only: bool,
}

/// What one run is given and what it must name.
struct Setup {
    /// The effects' values, in words.
    what: String,
    /// Effects that must be accepted steps.
    expected: Vec<&'static str>,
    /// The mode count the diagnosis is told (`None`: every CMIF peak).
    modes: Option<usize>,
    sim: Sim,
}

/// The undeclared effects of one simulated measurement.
#[derive(Default)]
struct Sim {
    seed: u64,
    plant_dynamics: Vec<DynamicsFactor>,
    extra_delay_samples: f64,
    suspension: Option<(f64, f64)>,
    extra_modes: Vec<FlexibleMode>,
    feedthrough: Option<Mat<f64>>,
}

/// Runs the sweep and prints its table.
pub fn run(a: Args) -> Result<(), Error> {
    let cases = if a.cases.is_empty() {
        vec![
            Case::LagDelay,
            Case::CrosstalkMount,
            Case::HiddenBeside,
            Case::InputLagMode,
            Case::SuspensionDelay,
        ]
    } else {
        a.cases.clone()
    };
    println!("| case | plate | effects | steps accepted | verdict | final vs noiseless | modes (true) | time | ok |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let (mut n, mut ok) = (0, 0);
    for &case in &cases {
        for k in 0..a.plates {
            let seed = a.seed + k as u64;
            let plate = WaferStage::build(&WaferStageConfig {
                seed,
                ..WaferStageConfig::default()
            })
            .stage("plate")?;
            let setup = draw(case, seed, &plate);
            let t = Instant::now();
            let (data, clean, true_modes) = simulate(&setup.sim).stage("simulate")?;
            if let Some(dir) = &a.save_data {
                std::fs::create_dir_all(dir).stage("--save-data")?;
                let name = format!("{case:?}_{seed}");
                let note = format!("xtask effects: {case:?}, plate {seed}: {}", setup.what);
                let mut comments = data.comments.clone();
                comments.push(note.clone());
                frf_data::io::write_frf_csv(dir.join(format!("{name}.csv")), &data, &comments)
                    .stage("--save-data")?;
                frf_data::io::write_frf_csv(
                    dir.join(format!("{name}.noiseless.csv")),
                    &clean,
                    &[note],
                )
                .stage("--save-data")?;
                if a.save_only {
                    continue;
                }
            }
            let cfg = PipelineConfig {
                diagnose: true,
                modes: setup
                    .modes
                    .map_or(ModeSelection::Auto, ModeSelection::Count),
                ..PipelineConfig::default()
            };
            let out = run::run(&data, "effects", &cfg, "diagnose").stage("diagnose")?;
            let secs = t.elapsed().as_secs_f64();
            let med = median_rel(&out, &clean);
            let named: Vec<&str> = out
                .summary
                .steps
                .iter()
                .filter(|s| s.accepted && s.superseded_by.is_none())
                .map(|s| s.effect())
                .collect();
            let missing: Vec<&&str> = setup
                .expected
                .iter()
                .filter(|e| !named.contains(e))
                .collect();
            let wrong: Vec<&&str> = named
                .iter()
                .filter(|e| **e != "missed_mode" && !setup.expected.contains(e))
                .collect();
            let fitted_modes = out.summary.final_model.modes.len();
            let pass = missing.is_empty()
                && wrong.is_empty()
                && out.summary.verdict == frfit::summary::ResidualVerdict::NoiseLimited
                && med <= 1e-4
                && fitted_modes == true_modes;
            n += 1;
            ok += usize::from(pass);
            println!(
                "| {case:?} | {seed} | {} | {} | {} | {med:.2e} | {fitted_modes} ({true_modes}) | {secs:.0} s | {} |",
                setup.what,
                named.join(", "),
                out.summary.verdict,
                if pass {
                    "yes".to_string()
                } else {
                    format!("no (missing {missing:?}, other {wrong:?})")
                }
            );
        }
    }
    println!("\n{ok} of {n} runs named their effects and ended at the truth");
    Ok(())
}

/// The effects of `case` on plate `seed`, drawn from a stream of their own.
fn draw(case: Case, seed: u64, plate: &WaferStage) -> Setup {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(7919).wrapping_add(case as u64));
    let modes: Vec<f64> = plate.plant.modes.iter().map(|m| m.f_hz).collect();
    let n = modes.len();
    let sim = Sim {
        seed,
        ..Sim::default()
    };
    match case {
        Case::LagDelay => {
            let f = rng.random_range(1200.0..2500.0);
            let d = rng.random_range(0.2..0.5);
            Setup {
                what: format!("common lag {f:.0} Hz, delay +{d:.2} samples"),
                expected: vec!["input_dynamics", "delay"],
                modes: None,
                sim: Sim {
                    plant_dynamics: vec![DynamicsFactor::first_order(FactorTarget::All, f)],
                    extra_delay_samples: d,
                    ..sim
                },
            }
        }
        Case::CrosstalkMount => {
            let level = rng.random_range(1e-9..4e-9);
            let (p1, p2) = (rng.random_range(0.0..6.0), rng.random_range(0.0..6.0));
            let d = Mat::from_fn(4, 13, |i, j| {
                level
                    * (1.7 * i as f64 + 0.9 * j as f64 + p1).sin()
                    * (0.5 + 0.5 * (p2 + j as f64).cos().abs())
            });
            let row = rng.random_range(0..4);
            let f = rng.random_range(1200.0..1800.0);
            let z = rng.random_range(0.02..0.04);
            Setup {
                what: format!(
                    "feedthrough {:.1} nm/N, output {} resonance {f:.0} Hz / {z:.3}",
                    level * 1e9,
                    row + 1
                ),
                expected: vec!["feedthrough", "output_dynamics"],
                modes: None,
                sim: Sim {
                    feedthrough: Some(d),
                    plant_dynamics: vec![DynamicsFactor::second_order(
                        FactorTarget::Output(row),
                        f,
                        z,
                    )],
                    ..sim
                },
            }
        }
        Case::HiddenBeside => {
            let k = rng.random_range(4..n.saturating_sub(2).max(5));
            let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let f = modes[k] * (1.0 + side * rng.random_range(0.01..0.02));
            let hidden = mode_at(&mut rng, f, 0.008);
            Setup {
                what: format!(
                    "hidden mode {f:.1} Hz beside {:.1} Hz, --modes {n}",
                    modes[k]
                ),
                expected: vec!["missed_mode"],
                modes: Some(n),
                sim: Sim {
                    extra_modes: vec![hidden],
                    ..sim
                },
            }
        }
        Case::InputLagMode => {
            let input = rng.random_range(0..13);
            let f_lag = rng.random_range(600.0..1200.0);
            let f = loop {
                let f: f64 = rng.random_range(300.0..1500.0);
                if modes.iter().all(|m| (f / m - 1.0).abs() >= 0.05) {
                    break f;
                }
            };
            let hidden = mode_at(&mut rng, f, 0.01);
            Setup {
                what: format!(
                    "input {} lag {f_lag:.0} Hz, missed mode {f:.1} Hz, --modes {n}",
                    input + 1
                ),
                expected: vec!["input_dynamics", "missed_mode"],
                modes: Some(n),
                sim: Sim {
                    plant_dynamics: vec![DynamicsFactor::first_order(
                        FactorTarget::Input(input),
                        f_lag,
                    )],
                    extra_modes: vec![hidden],
                    ..sim
                },
            }
        }
        Case::SuspensionDelay => {
            let f = rng.random_range(2.0..6.0);
            let z = rng.random_range(0.03..0.08);
            let d = rng.random_range(0.2..0.5);
            Setup {
                what: format!("suspension {f:.2} Hz / {z:.3}, delay +{d:.2} samples"),
                expected: vec!["stiffness", "delay"],
                modes: None,
                sim: Sim {
                    suspension: Some((f, z)),
                    extra_delay_samples: d,
                    ..sim
                },
            }
        }
    }
}

/// A mode at `f_hz` with damping drawn in `0.004..zeta_max` and mode shapes of random
/// signs and magnitudes (0.3-1 of 0.8 at the sensors, of 0.3 at the actuators), drawn
/// from `rng` in that order.
fn mode_at(rng: &mut ChaCha8Rng, f_hz: f64, zeta_max: f64) -> FlexibleMode {
    let zeta = rng.random_range(0.004..zeta_max);
    let mut shape = |len: usize, amp: f64| -> Vec<f64> {
        (0..len)
            .map(|_| {
                amp * rng.random_range(0.3..1.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 }
            })
            .collect()
    };
    let c = shape(4, 0.8);
    let b = shape(13, 0.3);
    FlexibleMode { f_hz, zeta, c, b }
}

/// The closed-loop experiment of `sim` (lines 1 Hz apart to 2 kHz, 4 periods x 10
/// realizations, as the tests of effect pairs): its nonparametric estimate commented as
/// `frfit simulate` writes it, the exact response and the plant's mode count.
fn simulate(sim: &Sim) -> Result<(Frf, Frf, usize), frf_data::FrfError> {
    let nominal = WaferStageConfig::default();
    let stage = WaferStageConfig {
        seed: sim.seed,
        delay_samples: nominal.delay_samples + sim.extra_delay_samples,
        ..nominal
    };
    let (periods, realizations) = (4, 10);
    let exp = crate::reference_experiment::reference_experiment(
        stage.fs,
        20_000,
        (periods, realizations),
        stage.delay_samples,
        sim.plant_dynamics.clone(),
        sim.seed,
    )?;
    let mut plate = WaferStage::build(&stage)?;
    let plant = &mut plate.plant;
    if let Some((f_hz, zeta)) = sim.suspension {
        if let Some(residue) = plant.rigid.residue().cloned() {
            plant.rigid = RigidBody::Suspended {
                residue,
                f_hz,
                zeta,
            };
        }
    }
    plant.modes.extend(sim.extra_modes.iter().cloned());
    plant.modes.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
    if let Some(d) = &sim.feedthrough {
        plant.feedthrough = Some(d.clone());
    }
    let n_modes = plant.modes.len();
    let k = RigidBodyController::design(plant, &ControllerConfig::default(), stage.fs)?;
    let experiment = ClosedLoopExperiment::new(plant.clone(), k, exp)?;
    let mut est =
        experiment.estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())?;
    est.frf.comments = vec![
        // the hold and the stage's own computation delay declared (the extra delay not)
        format!(
            "sampling {} kHz; zero-order hold + {} sample(s) computation delay ({} us)",
            stage.fs / 1000.0,
            nominal.delay_samples,
            (0.5 + nominal.delay_samples) / stage.fs * 1e6
        ),
        format!("closed-loop indirect estimate, {periods} periods x {realizations} realizations"),
    ];
    Ok((est.frf, experiment.true_frf()?, n_modes))
}

/// The median over lines and entries of `|P - G| / |G|`, the final model of `out`
/// against the exact response `clean`.
fn median_rel(out: &PipelineOutput, clean: &Frf) -> f64 {
    let g = out.fit.model.response(clean);
    let m = clean.n_entries();
    let ny = clean.ny();
    let mut rel: Vec<f64> = (0..clean.n_lines() * m)
        .map(|idx| {
            let t = clean.value(idx / m, idx % m % ny, idx % m / ny);
            (g.values[idx] - t).norm() / t.norm()
        })
        .collect();
    rel.sort_by(|a, b| a.total_cmp(b));
    rel[rel.len() / 2]
}
