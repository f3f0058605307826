//! A piezo-actuated precision mechanism as users measure it: `3 x 3`, a static gain
//! (the stack's stiffness, a feedthrough), lightly damped modes only in the upper part of
//! the band, a computation and transport delay of about one sample, measured in open
//! loop with orthogonal random-phase multisines (`nu` experiments per realization, each
//! exciting one input), several periods and realizations, and a stochastic nonlinear
//! contribution (the hysteresis of the piezo stack) well above the noise.
//!
//! What it is for: the measured-data path end to end with a known answer (time records,
//! the grouping of experiments into realizations, the split of the total variance into
//! noise and nonlinear parts, the fit of the best linear approximation, the prediction
//! of test records). The best linear approximation is the plant itself
//! ([`ClosedLoopExperiment::true_frf`]); the nonlinear variance of the averaged estimate
//! is `d^2 |P_ij|^2 / R` per entry and line (see
//! [`ExperimentConfig::stochastic_distortion`]).

use super::controller::RigidBodyController;
use super::experiment::{ClosedLoopExperiment, ExperimentConfig};
use super::plant::ModalPlant;
use super::signals::NoiseConfig;
use crate::nonparametric::LineGrid;
use faer::Mat;
use frf_data::FrfError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Settings of [`piezo_experiment`], with documented defaults (those of the measurement
/// the case is modelled on).
#[derive(Debug, Clone, PartialEq)]
pub struct PiezoConfig {
    /// Seed of the plant's mode shapes, the phases and the noise (default 1).
    pub seed: u64,
    /// Sample rate, Hz (default 6400).
    pub fs: f64,
    /// Samples per period (default 8192: 0.78 Hz lines).
    pub period: usize,
    /// Every bin from the first up to this frequency is excited, Hz (default 3000: 3839
    /// lines).
    pub f_max_hz: f64,
    /// Periods per realization (default 2).
    pub periods: usize,
    /// Realizations (default 2).
    pub realizations: usize,
    /// Relative level of the stochastic nonlinear contribution (default 0.03).
    pub distortion: f64,
    /// White output noise, RMS per sample (default 4e-3: the distortion is then 10 to 15
    /// times the noise in amplitude).
    pub noise_rms: f64,
    /// RMS of each experiment's multisine (default 1).
    pub rms: f64,
    /// Seed of the phases, the noise and the distortion when it differs from the plant's
    /// `seed` (default `None`): a test record of the same plant with new multisines.
    pub phase_seed: Option<u64>,
    /// Keep the time records (default false; see
    /// [`ExperimentConfig::keep_time_signals`]).
    pub keep_time_signals: bool,
}

impl Default for PiezoConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            fs: 6400.0,
            period: 8192,
            f_max_hz: 3000.0,
            periods: 2,
            realizations: 2,
            distortion: 0.03,
            noise_rms: 4e-3,
            rms: 1.0,
            phase_seed: None,
            keep_time_signals: false,
        }
    }
}

/// The modes of the mechanism: natural frequency (Hz) and damping. Only the upper part
/// of the band resonates, as in the measurement the case is modelled on (635-2770 Hz).
pub const PIEZO_MODES: [(f64, f64); 5] = [
    (635.0, 0.02),
    (1180.0, 0.015),
    (1710.0, 0.01),
    (2290.0, 0.012),
    (2770.0, 0.02),
];

/// The plant: [`PIEZO_MODES`] with mode shapes drawn from `seed` (sensor and actuator
/// gains in `[-1, 1]` times `w_n`, so that each mode's static contribution `c b^T / w_n^2`
/// is a fraction of the static gain), and a diagonally dominant static gain (feedthrough)
/// `I + 0.3 X` with `X` drawn in `[-1, 1]`.
pub fn piezo_plant(seed: u64) -> Result<ModalPlant, FrfError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5032_7a6f);
    let mut b = ModalPlant::builder(3, 3);
    for &(f, z) in &PIEZO_MODES {
        let w2 = (2.0 * std::f64::consts::PI * f).powi(2);
        // |c_i b_j| / w^2 up to 1 (about 0.25 typically) at the static end: the modes
        // show as peaks of a few to ten times the static gain at resonance
        let scale = w2.sqrt();
        let c: Vec<f64> = (0..3)
            .map(|_| scale * rng.random_range(-1.0..1.0))
            .collect();
        let bb: Vec<f64> = (0..3)
            .map(|_| scale * rng.random_range(-1.0..1.0))
            .collect();
        b = b.mode(f, z, c, bb);
    }
    let d = Mat::from_fn(3, 3, |i, j| {
        (if i == j { 1.0 } else { 0.0 }) + 0.3 * rng.random_range(-1.0..1.0)
    });
    b.feedthrough(d).build()
}

/// The open-loop experiment of `cfg` on [`piezo_plant`]: one experiment per input, every
/// bin up to `f_max_hz` excited, one sample of delay (156 us at 6400 Hz), one transient
/// period discarded. Run it with [`crate::synth::SimulationPath::TimeDomain`] and
/// [`ExperimentConfig::keep_time_signals`] for time records.
pub fn piezo_experiment(cfg: &PiezoConfig) -> Result<ClosedLoopExperiment, FrfError> {
    let plant = piezo_plant(cfg.seed)?;
    let n_bins = (cfg.f_max_hz * cfg.period as f64 / cfg.fs).floor() as usize;
    let grid = LineGrid::from_bins(cfg.fs, cfg.period, (1..=n_bins).collect())?;
    let mut ec = ExperimentConfig::wafer_stage(cfg.phase_seed.unwrap_or(cfg.seed));
    ec.keep_time_signals = cfg.keep_time_signals;
    ec.grid = grid;
    ec.periods = cfg.periods;
    ec.realizations = cfg.realizations;
    ec.transient_periods = 1;
    ec.rms = cfg.rms;
    ec.output_noise = NoiseConfig {
        white_rms: cfg.noise_rms,
        drift_rms: 0.0,
        drift_corner_hz: 1.0,
    };
    ec.stochastic_distortion = cfg.distortion;
    ec.delay_samples = 1.0;
    let k = RigidBodyController::open_loop(3, 3, cfg.fs);
    ClosedLoopExperiment::new(plant, k, ec)
}
