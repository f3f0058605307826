//! The [`Estimator`] trait, the [`Fit`] result and progress reporting.

use crate::{FrfDataset, ModelStructure};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Duration;

/// Why an iterative estimator stopped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Convergence {
    /// A direct (non-iterative) estimate, such as an initialisation.
    Direct,
    /// The relative parameter change fell below the tolerance.
    ParameterTolerance {
        /// The last relative change.
        relative_change: f64,
    },
    /// The Gauss-Newton step fell below a fraction of the parameters' standard
    /// deviations (a maximum-likelihood refiner: further steps move the estimate by
    /// less than its own uncertainty).
    StepInStandardDeviations {
        /// The last step's size, in standard deviations.
        step_std: f64,
    },
    /// The relative cost change fell below the tolerance.
    CostTolerance {
        /// The last relative change.
        relative_change: f64,
    },
    /// The iteration limit was reached before either tolerance was met.
    MaxIterations {
        /// The limit.
        limit: usize,
    },
    /// The iterations stalled: for several steps in a row the update had to be cut to a
    /// small fraction before it lowered the cost, and it lowered it by almost nothing.
    /// The estimate is where the iterations stood, not an optimum: the iteration's fixed
    /// point is not a minimum of the cost there (an effect the model does not hold, or
    /// a start far from the optimum).
    Stalled {
        /// The consecutive stalled steps before the stop.
        steps: usize,
        /// Their relative cost decrease, in total.
        relative_decrease: f64,
    },
    /// The iterations failed (singular system, non-finite cost, divergence).
    Failed {
        /// What happened.
        reason: String,
    },
}

impl Convergence {
    /// True for the two tolerance-based stops and for direct estimates.
    pub fn is_converged(&self) -> bool {
        matches!(
            self,
            Convergence::Direct
                | Convergence::ParameterTolerance { .. }
                | Convergence::StepInStandardDeviations { .. }
                | Convergence::CostTolerance { .. }
        )
    }
    /// A short human-readable description.
    pub fn describe(&self) -> String {
        match self {
            Convergence::Direct => "direct estimate (no iterations)".into(),
            Convergence::ParameterTolerance { relative_change } => {
                format!("converged: relative parameter change {relative_change:.2e}")
            }
            Convergence::StepInStandardDeviations { step_std } => {
                format!("converged: the last step is {step_std:.2e} standard deviations of the parameters")
            }
            Convergence::CostTolerance { relative_change } => {
                format!("converged: relative cost change {relative_change:.2e}")
            }
            Convergence::MaxIterations { limit } => {
                format!("NOT converged: stopped at the limit of {limit} iterations")
            }
            Convergence::Stalled {
                steps,
                relative_decrease,
            } => format!(
                "NOT converged: stalled ({steps} steps in a row cut to a small fraction of the update lowered the cost by {relative_decrease:.1e} relative in total)"
            ),
            Convergence::Failed { reason } => format!("FAILED: {reason}"),
        }
    }
}

/// Wall-clock time of one stage of an estimator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// The stage.
    pub stage: String,
    /// Seconds.
    pub seconds: f64,
}

/// The result of an [`Estimator`]: the model, the method's own report, and how it was
/// obtained.
///
/// `R` is the estimator's report type ([`Estimator::Report`]): what the method found on
/// the way (CMIF peaks, the chosen order, singular values, parameter covariance...), so
/// that nothing it computed is thrown away. `()` for a fit that carries none.
#[derive(Debug, Clone)]
pub struct Fit<M, R = ()> {
    /// The estimated model.
    pub model: M,
    /// The estimator's own report.
    pub report: R,
    /// The cost after each iteration (the first entry is the cost of the start).
    pub cost_history: Vec<f64>,
    /// Number of iterations run.
    pub iterations: usize,
    /// Why the estimator stopped.
    pub convergence: Convergence,
    /// Time per stage.
    pub timings: Vec<Timing>,
    /// Which estimator produced the fit (for reports), e.g. `"cmif-init"`, `"riv"`.
    pub estimator: String,
    /// Warnings and notes for the user (unstable poles, conditioning...).
    pub messages: Vec<String>,
}

impl<M> Fit<M> {
    /// A fit that only wraps a model (no iterations), e.g. a model read from a file
    /// that a refiner should start from.
    pub fn from_model(model: M, estimator: impl Into<String>) -> Self {
        Self {
            model,
            report: (),
            cost_history: Vec::new(),
            iterations: 0,
            convergence: Convergence::Direct,
            timings: Vec::new(),
            estimator: estimator.into(),
            messages: Vec::new(),
        }
    }
}

impl<M, R> Fit<M, R> {
    /// The last cost, when any was recorded.
    pub fn final_cost(&self) -> Option<f64> {
        self.cost_history.last().copied()
    }
    /// Adds a timing entry.
    pub fn push_timing(&mut self, stage: impl Into<String>, d: Duration) {
        self.timings.push(Timing {
            stage: stage.into(),
            seconds: d.as_secs_f64(),
        });
    }
    /// The same fit with another report.
    pub fn with_report<R2>(self, report: R2) -> Fit<M, R2> {
        Fit {
            model: self.model,
            report,
            cost_history: self.cost_history,
            iterations: self.iterations,
            convergence: self.convergence,
            timings: self.timings,
            estimator: self.estimator,
            messages: self.messages,
        }
    }
    /// The same fit with its model mapped by `f`.
    pub fn map_model<M2>(self, f: impl FnOnce(M) -> M2) -> Fit<M2, R> {
        Fit {
            model: f(self.model),
            report: self.report,
            cost_history: self.cost_history,
            iterations: self.iterations,
            convergence: self.convergence,
            timings: self.timings,
            estimator: self.estimator,
            messages: self.messages,
        }
    }
}

impl<M> From<M> for Fit<M> {
    fn from(model: M) -> Self {
        Fit::from_model(model, "given")
    }
}

/// An estimator: data (and a start, for refiners) in, a [`Fit`] out.
///
/// Initialisers use `Start = ()`; refiners use `Start = `[`crate::ChainModel`] (the
/// model currency, [`realize::FrfModel`], with the previous link's own structure when it
/// has one), so that any initialiser feeds any refiner:
///
/// ```text
/// let init = SubspaceInit::default().estimate(&data, ())?;          // crate subspace
/// let fit = MlRefine::default().estimate(&data, ChainModel::of(&init.model)?)?; // ml-refine
/// ```
///
/// The object-safe [`crate::Initializer`] and [`crate::Refiner`] wrap estimators for a
/// chain composed by name at run time (`frfit fit --init X --refine Y`).
pub trait Estimator {
    /// The model family estimated.
    type Model: ModelStructure;
    /// What the estimator starts from: `()` for initialisers, a [`crate::ChainModel`]
    /// for refiners.
    type Start;
    /// The method's own report (kept in [`Fit::report`]).
    type Report: std::fmt::Debug + Clone + Serialize;
    /// The estimator's error type.
    type Error: std::error::Error + Send + Sync + 'static;
    /// Runs the estimator on `data`.
    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        start: Self::Start,
    ) -> Result<Fit<Self::Model, Self::Report>, Self::Error>;
}

/// One progress report from a long-running step.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// The stage, e.g. `"riv"`.
    pub stage: String,
    /// Steps done.
    pub step: usize,
    /// Total steps, when known (an iteration limit counts).
    pub total: Option<usize>,
    /// The current cost, when there is one.
    pub cost: Option<f64>,
    /// A short message.
    pub message: String,
}

/// A progress callback, shared and thread-safe (the CLI turns it into a progress bar).
pub type ProgressFn = Arc<dyn Fn(&Progress) + Send + Sync>;

/// An optional progress callback, cheap to clone and to call when absent.
#[derive(Clone, Default)]
pub struct ProgressSink(Option<ProgressFn>);

impl ProgressSink {
    /// A sink that calls `f`.
    pub fn new(f: impl Fn(&Progress) + Send + Sync + 'static) -> Self {
        Self(Some(Arc::new(f)))
    }
    /// A sink that does nothing.
    pub fn none() -> Self {
        Self(None)
    }
    /// Reports progress (no-op when absent).
    pub fn report(&self, p: Progress) {
        if let Some(f) = &self.0 {
            f(&p);
        }
    }
    /// Reports `step` of `total` of `stage` with an optional cost.
    pub fn step(
        &self,
        stage: &str,
        step: usize,
        total: Option<usize>,
        cost: Option<f64>,
        message: impl Into<String>,
    ) {
        if let Some(f) = &self.0 {
            f(&Progress {
                stage: stage.to_string(),
                step,
                total,
                cost,
                message: message.into(),
            });
        }
    }
}

impl std::fmt::Debug for ProgressSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "ProgressSink(callback)"
        } else {
            "ProgressSink(none)"
        })
    }
}
