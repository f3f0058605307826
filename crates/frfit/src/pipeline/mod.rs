//! The stages of the frfit pipeline that a run is made of, below the diagnosis loop
//! (DESIGN.md): the settings ([`PipelineConfig`]), the setup of a run ([`FitContext`]:
//! band, declarations, noise level, delay estimate, and what every stage works from,
//! computed once), the first fit of the additive model of the wafer-stage paper (crate
//! `additive-riv`, [`first_fit`](fn@first_fit), with its second and third starts and
//! the default chain), the error statistics of a model against the data and the
//! building of the summary (`summary.json`). The diagnosis loop ([`crate::diagnose`]) builds on these
//! stages; the whole run that calls both ([`crate::run::run`]) stands above them.

mod config;
mod context;
mod first_fit;
pub mod nonlinear;
pub mod pooled_variance;
mod summarize;

pub use config::{default_chain, FrfType, PipelineConfig, LARGE_MIMO_ENTRIES, NOT_ANALYSED};
pub(crate) use config::{err, Timings};
pub(crate) use context::cmif_once;
pub use context::FitContext;
pub use first_fit::{
    chain_fit, first_fit, fit_reference, FirstFit, SECOND_START, SECOND_START_RESIDUAL,
};
pub(crate) use summarize::{
    build_summary, distortion_summary, error_stats, information_uncertainty,
    information_uncertainty_and_response_std, ml_uncertainty, response_std, structure_steps,
    RunRecord,
};
pub use summarize::{final_model_summary, model_response_std_at};
