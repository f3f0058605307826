//! # sk-fit: Sanathanan-Koerner common-denominator fits
//!
//! Will hold (a later issue): SK iterations (Jue section 2.2, McKelvey eq. (36)-(38)) for
//! a common-denominator MIMO model by stacking, with `1/|d|` and `1/sqrt|d|` weights,
//! the bilinear prewarped basis of `poly-basis`, Bayard multi-band composite fitting
//! with tiered weights, and Gilbert realization to a `realize::StateSpace`, all behind
//! the `frf_data::Estimator` trait.
