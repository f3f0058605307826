//! Simulated plants and experiments with a known truth.
//!
//! - [`ModalPlant`]: the additive modal plant (rigid body or suspension, flexible modes
//!   with rank-one residues `c b^T`, optional feedthrough), its exact sampled response
//!   and an exact ZOH realisation for time-domain simulation;
//! - [`RandomModal`]: random modal plants of any size (`frfit simulate random-modal`),
//!   their exact FRF and a noisy measurement with its variance;
//! - [`WaferStage`]: the wafer-stage testbed (free plate, 4 sensors, 13 actuators,
//!   17 modes, 10 kHz, ZOH + one sample of computation delay), seeded;
//! - [`RigidBodyController`]: a stabilising decoupling controller in rigid-body
//!   coordinates;
//! - [`ClosedLoopExperiment`]: single-axis random-phase odd multisine experiments,
//!   `P` periods x `R` realizations, coloured noise, optional input noise and actuator
//!   nonlinearity, simulated in the frequency domain (a) or the time domain (b);
//! - [`piezo_experiment`]: a piezo-actuated `3 x 3` mechanism in open loop with a
//!   stochastic nonlinear contribution, as time records;
//! - [`WaferStageExperiment`]: all of it with the defaults of the paper's Section 4.2.

pub mod controller;
pub mod experiment;
pub mod piezo;
pub mod plant;
pub mod random;
pub mod signals;
pub mod wafer;

pub use controller::{ControllerConfig, ControllerState, RigidBodyController};
pub use experiment::{
    closed_loop_spectral_radius, ClosedLoopExperiment, ExperimentConfig, SimulationPath,
};
pub use piezo::{piezo_experiment, piezo_plant, PiezoConfig, PIEZO_MODES};
pub use plant::{
    truth_delay_samples, DiscreteModalPlant, DiscreteModalState, FlexibleMode, ModalPlant,
    ModalPlantBuilder, RigidBody,
};
pub use random::{RandomModal, RandomModalConfig};
pub use signals::NoiseConfig;
pub use wafer::{beam_function, WaferStage, WaferStageConfig};

use crate::nonparametric::{EstimatorConfig, NonparametricFrf};
use frf_data::FrfError;

/// The wafer-stage testbed in its closed-loop experiment.
#[derive(Debug)]
pub struct WaferStageExperiment {
    /// The simulated stage (plant, geometry, sampling).
    pub stage: WaferStage,
    /// The experiment (holds the plant and the controller).
    pub experiment: ClosedLoopExperiment,
}

impl WaferStageExperiment {
    /// Builds the stage of `stage`, designs the controller of `controller` and sets up
    /// the experiment `experiment` (whose delay is set to the stage's).
    pub fn new(
        stage: &WaferStageConfig,
        controller: &ControllerConfig,
        mut experiment: ExperimentConfig,
    ) -> Result<Self, FrfError> {
        let st = WaferStage::build(stage)?;
        if (experiment.grid.fs() - st.fs).abs() > 1e-9 * st.fs {
            return Err(FrfError::invalid(
                "experiment fs",
                experiment.grid.fs(),
                format!("differs from the stage's sample rate {} Hz", st.fs),
            ));
        }
        experiment.delay_samples = st.delay_samples;
        let k = RigidBodyController::design(&st.plant, controller, st.fs)?;
        let exp = ClosedLoopExperiment::new(st.plant.clone(), k, experiment)?;
        Ok(Self {
            stage: st,
            experiment: exp,
        })
    }

    /// The default experiment of the paper for `seed` with `periods` x `realizations`.
    pub fn default_with(seed: u64, periods: usize, realizations: usize) -> Result<Self, FrfError> {
        let stage = WaferStageConfig {
            seed,
            ..WaferStageConfig::default()
        };
        let mut exp = ExperimentConfig::wafer_stage(seed);
        exp.periods = periods;
        exp.realizations = realizations;
        Self::new(&stage, &ControllerConfig::default(), exp)
    }

    /// Simulates (frequency-domain path) and estimates the FRF.
    pub fn run(&self) -> Result<NonparametricFrf, FrfError> {
        let mut out = self
            .experiment
            .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())?;
        out.frf.units = Some("m/N".into());
        Ok(out)
    }
}
