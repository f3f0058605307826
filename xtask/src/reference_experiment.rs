//! The closed-loop experiment of the reference wafer stage as the sweeps simulate it:
//! odd lines up to 2 kHz, multisines of 2 N RMS, 1 nm of white sensor noise and 5 nm of
//! drift below 0.5 Hz, one transient period.

use experiment::nonparametric::LineGrid;
use experiment::synth::{ExperimentConfig, NoiseConfig};
use frfit::realize::DynamicsFactor;

/// The experiment at sample rate `fs` with `period` samples per period, `periods x
/// realizations`, the loop's computation delay `delay_samples`, undeclared plant
/// dynamics `plant_dynamics` and the noise seed `seed`.
pub fn reference_experiment(
    fs: f64,
    period: usize,
    (periods, realizations): (usize, usize),
    delay_samples: f64,
    plant_dynamics: Vec<DynamicsFactor>,
    seed: u64,
) -> Result<ExperimentConfig, frf_data::FrfError> {
    Ok(ExperimentConfig {
        grid: LineGrid::odd(fs, period, 0.0, 2000.0)?,
        periods,
        realizations,
        transient_periods: 1,
        rms: 2.0,
        output_noise: NoiseConfig {
            white_rms: 1e-9,
            drift_rms: 5e-9,
            drift_corner_hz: 0.5,
        },
        input_noise_rms: 0.0,
        cubic_nonlinearity: 0.0,
        stochastic_distortion: 0.0,
        delay_samples,
        excited_inputs: None,
        plant_dynamics,
        seed,
        keep_time_signals: false,
    })
}
