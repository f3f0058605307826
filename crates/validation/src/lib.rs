//! # validation: residuals against the noise level, diagnosis evidence, model validation
//!
//! Will hold: residual statistics `E = G - P` per line and entry against the measured
//! noise level with significance tests, the structure of a significant residual (its
//! CMIF and peaks, phase and magnitude trends, concentration in a row or column) for the
//! diagnosis loop of the `frfit` crate, and (a later issue) nonparametric disturbance
//! bounds and mu-based model invalidation (Oomen-Bosgra).
