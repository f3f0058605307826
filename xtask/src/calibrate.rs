//! `cargo xtask calibrate`: the Monte Carlo harness of the uncertainty the fits report.
//!
//! One plant of the simulator (`experiment::synth::RandomModal`: a random modal MIMO
//! plant, optionally with close pairs), many noise draws: each draw adds circular complex
//! Gaussian noise of a known standard deviation to the exact response, states its
//! variance in the data (so the fit weighs by it: maximum likelihood), fits with the
//! chain asked for, and compares every true mode's frequency and damping with the fitted
//! mode nearest to it through `z = (estimate - truth) / reported std`. Pooled over modes
//! and draws: the RMS of `z` (1 when the reported standard deviations are right) and the
//! fraction with `|z| < 1.96` (0.95 when they are). The delay (the plant has none) gives
//! one `z` per draw when the fit reports its standard deviation.
//!
//! The `wafer` plant is the simulated wafer stage of the reference pipeline (the plate of
//! `--seed`, 4 x 13, 10 kHz zero-order hold and one sample of delay declared in the
//! data's comments), each draw a new closed-loop experiment (its own noise seed) and its
//! nonparametric estimate with the variance from 10 periods x 10 realizations: the
//! reported standard deviations against the actual spread with the estimated variance.
//!
//! `cargo xtask calibrate --draws 100 --plant random --plant close-pair --plant wafer`

use crate::{Context, Error};
use clap::Args as ClapArgs;
use experiment::synth::{RandomModal, RandomModalConfig};
use frf_data::{Frf, C64};
use frfit::pipeline::PipelineConfig;
use frfit::run;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use std::time::Instant;

/// Arguments of `cargo xtask calibrate`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Plants: `random` (well-separated modes), `close-pair` (30 % of the modes in close
    /// pairs), `wafer` (the simulated wafer stage, nonparametric estimates). Default:
    /// `random` and `close-pair`.
    #[arg(long = "plant", value_name = "random|close-pair")]
    pub plants: Vec<String>,
    /// Noise draws per plant.
    #[arg(long, default_value_t = 100)]
    pub draws: usize,
    /// The first draw's index (default 0): draws `first-draw .. first-draw + draws` run,
    /// each with its own seed, so that one long run can be split into several whose
    /// tables pool exactly (z RMS squared and coverage weighted by their z counts).
    #[arg(long, default_value_t = 0)]
    pub first_draw: usize,
    /// The chain's refiner (`ml` reports standard deviations).
    #[arg(long, default_value = "ml")]
    pub refine: String,
    /// Noise standard deviation relative to the median magnitude.
    #[arg(long, default_value_t = 1e-3)]
    pub noise: f64,
    /// Outputs, inputs, modes and lines of the plant.
    #[arg(long, default_value_t = 4)]
    pub ny: usize,
    /// Inputs.
    #[arg(long, default_value_t = 4)]
    pub nu: usize,
    /// Modes.
    #[arg(long, default_value_t = 10)]
    pub modes: usize,
    /// Lines.
    #[arg(long, default_value_t = 2000)]
    pub lines: usize,
    /// Seed of the plant (the draws use their own seeds).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A transport delay of the `random` and `close-pair` plants, microseconds (default
    /// none): with one the ML chain frees and reports its delay (on a delay-free plant it
    /// holds it at zero, without a standard deviation), so its delay `z` is measured.
    #[arg(long, default_value_t = 0.0)]
    pub delay_us: f64,
    /// A directory to write each draw's data to (`random` and `close-pair` plants:
    /// `<plant>_draw_<d>.csv`), so that a draw the table singles out can be fitted again
    /// with `frfit fit` and its messages read.
    #[arg(long, value_name = "DIR")]
    pub save_data: Option<std::path::PathBuf>,
    /// `wafer` only: each draw simulates another plate (plate seed `seed + draw`), each
    /// against its own truth, instead of new noise on one plate: the intervals' spread
    /// over plates, and the modes beyond each plate's own (the plates of `frfit simulate
    /// wafer-stage --seed S`).
    #[arg(long)]
    pub vary_plate: bool,
    /// `wafer` only: periods of each realization of the experiment (the variance of
    /// the estimate comes from the realizations). Default: 10.
    #[arg(long, default_value_t = 10)]
    pub periods: usize,
    /// `wafer` only: realizations of the experiment, declared in the data's comments as
    /// a measurement states them (from 5 down, the pipeline pools the variance over
    /// neighbouring lines). Default: 10.
    #[arg(long, default_value_t = 10)]
    pub realizations: usize,
}

/// Pooled z statistics.
#[derive(Default)]
struct Pool {
    z: Vec<f64>,
}

impl Pool {
    fn push(&mut self, z: f64) {
        if z.is_finite() {
            self.z.push(z);
        }
    }
    fn row(&self, name: &str) -> String {
        let n = self.z.len();
        if n == 0 {
            return format!("| {name} | 0 | - | - |");
        }
        let rms = (self.z.iter().map(|z| z * z).sum::<f64>() / n as f64).sqrt();
        let inside = self.z.iter().filter(|z| z.abs() < 1.96).count() as f64 / n as f64;
        format!("| {name} | {n} | {rms:.3} | {inside:.3} |")
    }
}

/// Runs `cargo xtask calibrate`.
pub fn run(a: Args) -> Result<(), Error> {
    let plants = if a.plants.is_empty() {
        vec!["random".to_string(), "close-pair".to_string()]
    } else {
        a.plants.clone()
    };
    for plant in &plants {
        if plant == "wafer" {
            wafer(&a)?;
            continue;
        }
        let close = match plant.as_str() {
            "random" => 0.0,
            "close-pair" => 0.3,
            p => {
                return Err(Error::new(
                    "--plant",
                    format!("unknown plant `{p}`: random, close-pair or wafer"),
                ))
            }
        };
        let cfg = RandomModalConfig {
            ny: a.ny,
            nu: a.nu,
            modes: a.modes,
            lines: a.lines,
            close_pair_fraction: close,
            noise: a.noise,
            seed: a.seed,
            ..RandomModalConfig::default()
        };
        let r = RandomModal::generate(&cfg).stage("simulate")?;
        let truth: Vec<(f64, f64)> = r
            .plant
            .to_truth(a.seed, 0.0, 0.0)
            .model
            .modes
            .iter()
            .map(|m| (m.f_hz, m.zeta))
            .collect();
        let sigma = r.noise_std;
        let delay_s = a.delay_us * 1e-6;
        if !(delay_s.is_finite() && delay_s >= 0.0) {
            return Err(Error::new(
                "--delay-us",
                format!("{}: a delay is finite and not negative", a.delay_us),
            ));
        }
        // the exact response through the delay
        let exact: Vec<C64> = {
            let m = a.ny * a.nu;
            let f = r.noiseless.freq_hz_slice();
            r.noiseless
                .values()
                .iter()
                .enumerate()
                .map(|(i, g)| g * C64::from_polar(1.0, -std::f64::consts::TAU * f[i / m] * delay_s))
                .collect()
        };
        let mut tally = Tally::default();
        let t0 = Instant::now();
        for d in a.first_draw..a.first_draw + a.draws {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                a.seed.wrapping_mul(1_000_003).wrapping_add(d as u64 + 1),
            );
            let s = sigma / std::f64::consts::SQRT_2;
            let values: Vec<C64> = exact
                .iter()
                .map(|g| {
                    let (x, y): (f64, f64) = (
                        StandardNormal.sample(&mut rng),
                        StandardNormal.sample(&mut rng),
                    );
                    g + C64::new(s * x, s * y)
                })
                .collect();
            let n = values.len();
            let data = Frf::new(
                r.noiseless.freq_hz_slice().to_vec(),
                a.ny,
                a.nu,
                values,
                Some(vec![sigma * sigma; n]),
            )
            .stage("data")?;
            if let Some(dir) = &a.save_data {
                std::fs::create_dir_all(dir).stage("--save-data")?;
                frf_data::io::write_frf_csv(
                    dir.join(format!("{plant}_draw_{d}.csv")),
                    &data,
                    &[format!(
                        "calibrate: {plant} plant seed {}, draw {d}, delay {} us",
                        a.seed, a.delay_us
                    )],
                )
                .stage("--save-data")?;
            }
            let pc = PipelineConfig {
                refine: a.refine.clone(),
                final_analysis: false,
                ..PipelineConfig::default()
            };
            let out = run::run(&data, "calibrate", &pc, "fit").stage("fit")?;
            tally.add(d, &out.summary, &truth, delay_s);
            eprint!("\r{plant}: draw {}/{}", d + 1 - a.first_draw, a.draws);
        }
        eprintln!();
        println!(
            "\n{plant} plant (seed {}, {}x{}, {} modes, {} lines, noise {:.1e} of the median magnitude, delay {} us), `--refine {}`, {} draws in {:.1} s:\n",
            a.seed,
            a.ny,
            a.nu,
            truth.len(),
            a.lines,
            a.noise,
            a.delay_us,
            a.refine,
            a.draws,
            t0.elapsed().as_secs_f64()
        );
        tally.print(&format!("delay (truth {} us)", a.delay_us));
    }
    Ok(())
}

/// A fitted mode no true mode took: frequency (Hz), damping, frequency standard
/// deviation (Hz).
type UntakenMode = (f64, f64, f64);

/// What the draws of one plant gave.
#[derive(Default)]
struct Tally {
    f: Pool,
    zeta: Pool,
    delay: Pool,
    missed: usize,
    spurious: usize,
    /// The draws with fitted modes beyond the truth's count: the draw, and the fitted
    /// modes no true mode took.
    spurious_draws: Vec<(usize, Vec<UntakenMode>)>,
    no_std: usize,
}

impl Tally {
    /// Adds draw `draw`'s summary against the true modes `(f_hz, zeta)` and delay.
    fn add(
        &mut self,
        draw: usize,
        s: &frfit::summary::Summary,
        truth: &[(f64, f64)],
        delay_s: f64,
    ) {
        let Some(u) = &s.uncertainty else {
            self.no_std += 1;
            return;
        };
        let extra = u.modes.len().saturating_sub(truth.len());
        self.spurious += extra;
        let mut taken = vec![false; u.modes.len()];
        for &(f, z) in truth {
            let Some((k, m)) = u
                .modes
                .iter()
                .enumerate()
                .min_by(|x, y| (x.1.f_hz - f).abs().total_cmp(&(y.1.f_hz - f).abs()))
                .filter(|(_, m)| (m.f_hz - f).abs() < 0.01 * f)
            else {
                self.missed += 1;
                continue;
            };
            taken[k] = true;
            self.f.push((m.f_hz - f) / m.f_hz_std);
            self.zeta.push((m.zeta - z) / m.zeta_std);
        }
        if extra > 0 {
            let untaken = u
                .modes
                .iter()
                .zip(&taken)
                .filter(|(_, &t)| !t)
                .map(|(m, _)| (m.f_hz, m.zeta, m.f_hz_std))
                .collect();
            self.spurious_draws.push((draw, untaken));
        }
        if let (Some(t), Some(st)) = (u.delay_s, u.delay_s_std) {
            self.delay.push((t - delay_s) / st);
        }
    }

    fn print(&self, delay_name: &str) {
        println!("| | z values | z RMS (1 if calibrated) | inside +-1.96 sigma (0.95) |");
        println!("|---|---|---|---|");
        println!("{}", self.f.row("frequency"));
        println!("{}", self.zeta.row("damping"));
        println!("{}", self.delay.row(delay_name));
        println!(
            "\ntrue modes without a fitted mode within 1 %: {}; fitted modes beyond the truth's count: {}; draws without standard deviations: {}",
            self.missed, self.spurious, self.no_std
        );
        for (d, modes) in &self.spurious_draws {
            println!(
                "draw {d}: fitted modes no true mode took: {}",
                modes
                    .iter()
                    .map(|(f, z, sf)| format!("{f:.2} Hz (zeta {z:.2e}, +-{sf:.2} Hz)"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
    }
}

/// The wafer-stage plant: a new closed-loop experiment per draw, of one plate or (with
/// `--vary-plate`) of another plate each draw.
fn wafer(a: &Args) -> Result<(), Error> {
    use experiment::nonparametric::EstimatorConfig;
    use experiment::synth::{
        ControllerConfig, SimulationPath, WaferStageConfig, WaferStageExperiment,
    };
    let (periods, realizations) = (a.periods, a.realizations);
    if periods < 2 || realizations < 2 {
        return Err(Error::new(
            "calibrate",
            format!("--periods {periods} and --realizations {realizations}: the wafer plant needs at least 2 of each (the variance comes from the realizations)"),
        ));
    }
    let mut tally = Tally::default();
    // the plates' true mode counts, fewest and most
    let mut modes = (usize::MAX, 0);
    let t0 = Instant::now();
    for d in a.first_draw..a.first_draw + a.draws {
        let stage = WaferStageConfig {
            seed: if a.vary_plate {
                a.seed.wrapping_add(d as u64)
            } else {
                a.seed
            },
            ..WaferStageConfig::default()
        };
        let exp = crate::reference_experiment::reference_experiment(
            stage.fs,
            40_000,
            (periods, realizations),
            stage.delay_samples,
            Vec::new(),
            a.seed.wrapping_mul(1_000_003).wrapping_add(d as u64 + 1),
        )
        .stage("experiment")?;
        let w = WaferStageExperiment::new(&stage, &ControllerConfig::default(), exp)
            .stage("wafer stage")?;
        let t = w.stage.truth();
        let truth: Vec<(f64, f64)> = t.model.modes.iter().map(|m| (m.f_hz, m.zeta)).collect();
        // the fit's delay is the one beyond the exact hold's half sample
        let delay_truth = t.delay_s - 0.5 / w.stage.fs;
        modes = (modes.0.min(truth.len()), modes.1.max(truth.len()));
        let mut est = w
            .experiment
            .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())
            .stage("estimate")?;
        est.frf.comments = vec![
            format!(
                "sampling {} kHz; zero-order hold + {} sample(s) computation delay",
                w.stage.fs / 1000.0,
                w.stage.delay_samples
            ),
            format!("{periods} periods x {realizations} realizations"),
        ];
        let pc = PipelineConfig {
            refine: a.refine.clone(),
            final_analysis: false,
            band_hz: Some((20.0, 2000.0)),
            ..PipelineConfig::default()
        };
        let out = run::run(&est.frf, "calibrate", &pc, "fit").stage("fit")?;
        tally.add(d, &out.summary, &truth, delay_truth);
        eprint!("\rwafer: draw {}/{}", d + 1 - a.first_draw, a.draws);
    }
    eprintln!();
    println!(
        "\nwafer plant ({}, 4x13, {} modes, nonparametric estimates of {periods} periods x {realizations} realizations, band 20..2000 Hz), `--refine {}`, {} draws in {:.1} s:\n",
        if a.vary_plate {
            format!(
                "plate seeds {}..{}, one per draw",
                a.seed.wrapping_add(a.first_draw as u64),
                a.seed
                    .wrapping_add((a.first_draw + a.draws).saturating_sub(1) as u64)
            )
        } else {
            format!("plate seed {}", a.seed)
        },
        if modes.0 == modes.1 {
            modes.0.to_string()
        } else {
            format!("{}-{}", modes.0, modes.1)
        },
        a.refine,
        a.draws,
        t0.elapsed().as_secs_f64()
    );
    tally.print("delay (truth: one sample)");
    Ok(())
}
