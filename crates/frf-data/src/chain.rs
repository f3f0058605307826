//! The estimator chain: `data -> [initialiser] -> [refiner] -> ...`, composed by name at
//! run time through object-safe traits.
//!
//! Every link hands the next one a [`ChainModel`]: the model currency
//! ([`realize::FrfModel`]: continuous-time poles with residue matrices, rigid-body
//! integrators, feedthrough and the known factors) and, when the link works in a
//! structure of its own (the additive model of refined IV, say), that structure as
//! well, so that a refiner of the same family continues exactly where the initialiser
//! stopped while any other refiner starts from the currency.
//!
//! - [`Initializer`]: settings in, a [`ChainOutput`] out (`--init cmif|sk|subspace`);
//! - [`Refiner`]: settings and a start in, a [`ChainOutput`] out (`--refine riv|ml`);
//! - [`InitLink`] / [`RefineLink`]: any typed [`Estimator`] with `Start = ()` or
//!   `Start = ChainModel` becomes a link, with its report serialised into the
//!   [`LinkReport`] that the model file and `summary.json` record.

use crate::cmif::{Cmif, PeakConfig};
use crate::delay::DelayEstimate;
use crate::{Convergence, Estimator, Fit, FrfDataset, ModelStructure, ProgressSink, Timing};
use crate::{FrfError, Weighting};
use realize::{FrfModel, Hold};
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

/// Which modes an initialiser that picks peaks starts from.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeSelection {
    /// Every peak the CMIF picker accepts (the default).
    #[default]
    Auto,
    /// The `n` most prominent CMIF peaks (the user declares how many modes to expect).
    Count(usize),
    /// These frequencies (Hz), e.g. from a finite-element model.
    Frequencies(Vec<f64>),
}

/// How the input/output delay is handled.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DelayChoice {
    /// Estimated from the data (delay periodogram), then refined as a free parameter of
    /// the iterations (the default). With the exact hold, the hold's half sample is
    /// taken out of the estimate.
    #[default]
    Auto,
    /// No delay.
    None,
    /// A known delay in seconds (the part not explained by a modelled hold), not refined.
    Fixed {
        /// Seconds.
        seconds: f64,
    },
    /// Start from this delay (seconds, beyond a modelled hold) and refine it: what a
    /// chain uses when a refinement moved the estimate far and the start is redone.
    Start {
        /// Seconds.
        seconds: f64,
    },
}

impl DelayChoice {
    /// True when the delay is a free parameter (estimated or started from a value).
    pub fn is_fitted(&self) -> bool {
        matches!(self, DelayChoice::Auto | DelayChoice::Start { .. })
    }
}

/// What every link of a chain is told: the known factor, the weighting, the modes or
/// order to look for, and where progress goes. Each estimator's own settings (its
/// config struct) are made from these by the registry that names it.
#[derive(Debug, Clone, Default)]
pub struct ChainSettings {
    /// The hold of the sampled measurement. Default: none.
    pub hold: Hold,
    /// Delay handling. Default: estimated and refined.
    pub delay: DelayChoice,
    /// `k` of `(j w)^k`: 0 displacement (default), 1 velocity, 2 accelerance.
    pub derivative_order: u32,
    /// Weighting of the criterion. Default: inverse variance when the data carry one,
    /// eq. (27) of the wafer-stage paper otherwise.
    pub weighting: Weighting,
    /// Modes to start from (peak-picking initialisers). Default: every CMIF peak.
    pub modes: ModeSelection,
    /// CMIF peak picker settings.
    pub peaks: PeakConfig,
    /// Model order (number of states) for initialisers that take one (SK, subspace);
    /// `None` chooses it from the data. Default: `None`.
    pub order: Option<usize>,
    /// Progress callback.
    pub progress: ProgressSink,
    /// Analyses of the data the caller already made (the pipeline makes them once per
    /// band). Default: none.
    pub precomputed: Precomputed,
}

/// Analyses of the chain's data made once by the caller and shared by every link, so
/// that no link computes them again. They must be of the very data the chain runs on;
/// a link checks what it cheaply can (the CMIF's frequency grid) and computes afresh
/// when it does not match.
#[derive(Debug, Clone, Default)]
pub struct Precomputed {
    /// The data's delay estimate ([`crate::delay::estimate_delay`] with the default
    /// settings): used by initialisers when the delay is [`DelayChoice::Auto`].
    pub delay: Option<DelayEstimate>,
    /// The data's CMIF ([`crate::cmif::cmif`]): used by peak-picking initialisers.
    pub cmif: Option<Arc<Cmif>>,
}

impl Precomputed {
    /// The precomputed CMIF when it is of the grid of `data` (same lines, same
    /// frequencies), `None` otherwise.
    pub fn cmif_of<D: FrfDataset + ?Sized>(&self, data: &D) -> Option<&Cmif> {
        self.cmif.as_deref().filter(|c| {
            c.n_lines() == data.n_lines()
                && (0..data.n_lines()).all(|k| c.freq_hz[k] == data.freq_hz(k))
        })
    }
}

/// The model a link hands on: the currency and, optionally, the link's own structure.
#[derive(Clone)]
pub struct ChainModel {
    /// The model currency.
    pub model: FrfModel,
    /// The link's own model structure (e.g. an `additive_riv::AdditiveModel`), for a
    /// following link of the same family; `None` when the model came from elsewhere (a
    /// file, another method).
    pub native: Option<Arc<dyn Any + Send + Sync>>,
}

impl std::fmt::Debug for ChainModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChainModel")
            .field("model", &self.model)
            .field("native", &self.native.as_ref().map(|_| "(structure)"))
            .finish()
    }
}

impl ChainModel {
    /// The currency of `model` with `model` itself kept as the native structure.
    pub fn of<M: ModelStructure + 'static>(model: &M) -> Result<Self, FrfError> {
        Ok(Self {
            model: model.to_frf_model()?,
            native: Some(Arc::new(model.clone())),
        })
    }
    /// The native structure, when it is a `T`.
    pub fn native<T: 'static>(&self) -> Option<&T> {
        self.native.as_ref().and_then(|n| n.downcast_ref::<T>())
    }
}

impl From<FrfModel> for ChainModel {
    fn from(model: FrfModel) -> Self {
        Self {
            model,
            native: None,
        }
    }
}

/// An estimator's own report (its weighting, the peaks it picked, the modes' standard
/// deviations, ...) as a link carries it: typed, and serialised with its kind in the
/// field `report`, so that the model file reads back into the same type.
///
/// Every estimator crate registers its report type (`#[typetag::serde(name = ...)]`);
/// a reader gets it back with [`LinkReport::details_as`].
#[typetag::serde(tag = "report")]
pub trait LinkDetails: std::fmt::Debug + Send + Sync + Any {
    /// The report as [`Any`], for [`LinkReport::details_as`].
    fn as_any(&self) -> &dyn Any;
}

/// What one link did, as the model file and `summary.json` record it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkReport {
    /// The registered name of the link (`cmif`, `riv`, ...).
    pub link: String,
    /// The estimator's description.
    pub estimator: String,
    /// Iterations run (0 for a direct estimate).
    pub iterations: usize,
    /// Why it stopped.
    pub convergence: Convergence,
    /// The cost after each iteration, in the estimator's own criterion.
    pub cost_history: Vec<f64>,
    /// Time per stage.
    pub timings: Vec<Timing>,
    /// Notes for the user.
    pub messages: Vec<String>,
    /// The estimator's own report, typed ([`LinkReport::details_as`]); `null` in the file
    /// when the link has none, and `None` when read from a file written before the
    /// reports carried their kind (`report`).
    #[serde(default, with = "details_serde")]
    pub details: Option<Arc<dyn LinkDetails>>,
}

impl LinkReport {
    /// The report of `fit` as link `link`.
    pub fn of<M, R: LinkDetails + Clone>(link: &str, fit: &Fit<M, R>) -> Self {
        Self {
            link: link.to_string(),
            estimator: fit.estimator.clone(),
            iterations: fit.iterations,
            convergence: fit.convergence.clone(),
            cost_history: fit.cost_history.clone(),
            timings: fit.timings.clone(),
            messages: fit.messages.clone(),
            details: Some(Arc::new(fit.report.clone())),
        }
    }

    /// The estimator's own report when it is a `T` (e.g. `ml_refine::MlReport` of the
    /// `ml` link).
    pub fn details_as<T: LinkDetails>(&self) -> Option<&T> {
        self.details
            .as_deref()
            .and_then(|r| r.as_any().downcast_ref::<T>())
    }
}

/// Equality of two typed reports: the same kind and the same serialised content.
impl PartialEq for dyn LinkDetails {
    fn eq(&self, other: &Self) -> bool {
        match (serde_json::to_string(self), serde_json::to_string(other)) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        }
    }
}

/// The file form of [`LinkReport::details`]: the typed report, tagged with its kind.
mod details_serde {
    use super::LinkDetails;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};
    use std::sync::Arc;

    pub fn serialize<S: Serializer>(
        report: &Option<Arc<dyn LinkDetails>>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        report.as_deref().serialize(s)
    }

    /// A report of a known kind reads back as its type; one without a kind (files
    /// written before the tag) or of a kind this build does not know reads as `None`,
    /// so that such a file still opens.
    pub fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<Arc<dyn LinkDetails>>, D::Error> {
        let raw = serde_json::value::Value::deserialize(d)?;
        if raw.is_null() {
            return Ok(None);
        }
        Ok(serde_json::from_value::<Box<dyn LinkDetails>>(raw)
            .ok()
            .map(Arc::from))
    }
}

/// The output of a link: the model handed on and what the link did.
#[derive(Debug, Clone)]
pub struct ChainOutput {
    /// The model for the next link.
    pub model: ChainModel,
    /// The link's report.
    pub report: LinkReport,
}

/// The error of a link: which link failed and why.
#[derive(Debug, thiserror::Error)]
#[error("{link}: {source}")]
pub struct ChainError {
    /// The registered name of the link.
    pub link: String,
    /// What went wrong.
    #[source]
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

impl ChainError {
    /// An error of link `link`.
    pub fn new(link: &str, source: impl std::error::Error + Send + Sync + 'static) -> Self {
        Self {
            link: link.to_string(),
            source: Box::new(source),
        }
    }
}

/// A data set as the object-safe links take it.
pub type DynData<'a> = &'a (dyn FrfDataset + Sync + 'a);

/// An initialiser of a chain: data in, a model out, no start (`--init NAME`).
pub trait Initializer: Send + Sync {
    /// The registered name.
    fn name(&self) -> &str;
    /// Runs the initialiser.
    fn initialize(&self, data: DynData<'_>) -> Result<ChainOutput, ChainError>;
}

/// A refiner of a chain: data and a start in, a model out (`--refine NAME`).
pub trait Refiner: Send + Sync {
    /// The registered name.
    fn name(&self) -> &str;
    /// Runs the refiner from `start`.
    fn refine(&self, data: DynData<'_>, start: &ChainModel) -> Result<ChainOutput, ChainError>;
}

/// A typed initialiser ([`Estimator`] with `Start = ()`) as a chain link.
pub struct InitLink<E> {
    /// The registered name.
    pub name: String,
    /// The estimator.
    pub estimator: E,
}

/// A typed refiner ([`Estimator`] with `Start = ChainModel`) as a chain link.
pub struct RefineLink<E> {
    /// The registered name.
    pub name: String,
    /// The estimator.
    pub estimator: E,
}

fn output<M: ModelStructure + 'static, R: LinkDetails + Clone>(
    name: &str,
    fit: Fit<M, R>,
) -> Result<ChainOutput, ChainError> {
    let report = LinkReport::of(name, &fit);
    let model = ChainModel::of(&fit.model).map_err(|e| ChainError::new(name, e))?;
    Ok(ChainOutput { model, report })
}

impl<E> Initializer for InitLink<E>
where
    E: Estimator<Start = ()> + Send + Sync,
    E::Model: 'static,
    E::Report: LinkDetails,
{
    fn name(&self) -> &str {
        &self.name
    }
    fn initialize(&self, data: DynData<'_>) -> Result<ChainOutput, ChainError> {
        let fit = self
            .estimator
            .estimate(data, ())
            .map_err(|e| ChainError::new(&self.name, e))?;
        output(&self.name, fit)
    }
}

impl<E> Refiner for RefineLink<E>
where
    E: Estimator<Start = ChainModel> + Send + Sync,
    E::Model: 'static,
    E::Report: LinkDetails,
{
    fn name(&self) -> &str {
        &self.name
    }
    fn refine(&self, data: DynData<'_>, start: &ChainModel) -> Result<ChainOutput, ChainError> {
        let fit = self
            .estimator
            .estimate(data, start.clone())
            .map_err(|e| ChainError::new(&self.name, e))?;
        output(&self.name, fit)
    }
}

/// The weighted least-squares cost `sum_k sum_e w_ke |G_ke - P_ke|^2 / (2 n)` of a
/// currency model on `data` with `weighting` (resolved against the data): the one
/// criterion in which links of different methods are compared.
pub fn weighted_cost<D: FrfDataset + ?Sized>(
    model: &FrfModel,
    data: &D,
    weighting: &Weighting,
) -> Result<f64, FrfError> {
    let w = weighting.resolve(data).weights(data)?;
    let p = model.freq_response(&data.omegas())?;
    let m = data.n_entries();
    let mut line = vec![realize::C64::new(0.0, 0.0); m];
    let mut sum = 0.0;
    for k in 0..data.n_lines() {
        data.line_into(k, &mut line);
        let pk = p.line(k);
        for e in 0..m {
            sum += w[k * m + e] * (line[e] - pk[e]).norm_sqr();
        }
    }
    Ok(sum / (2.0 * data.n_lines().max(1) as f64))
}
