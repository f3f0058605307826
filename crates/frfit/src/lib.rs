//! # frfit: frequency-domain identification of lightly damped MIMO motion systems
//!
//! The facade of the workspace: the pipeline (load -> band -> delay -> CMIF -> init ->
//! refine -> validate -> diagnose -> report), the residual-diagnosis loop, SVG plots and
//! the `frfit` command-line tool. A run ([`run::run`]) stands on the diagnosis loop
//! ([`diagnose`]), which stands on the pipeline's stages ([`pipeline`]). The estimators
//! live in their own crates and are re-exported here so that a user can depend on
//! `frfit` alone.

pub mod chain;
pub mod data;
pub mod declared;
pub mod diagnose;
pub mod effects;
pub mod error;
pub mod export;
pub mod nonparametric;
pub mod options;
pub mod pipeline;
pub mod plots;
pub mod predict;
pub mod reduce;
pub mod report;
pub mod run;
pub mod summary;
pub mod validation_report;

pub use error::FrfitError;

pub use additive_riv;
pub use frf_data;
pub use realize;
pub use validation;
