//! A pole's frequency and damping with their standard deviations: the one form in
//! which the ML refiner reports its modes and the dynamics factors' roots, the summary
//! carries them and the model file stores the factors'.

use serde::{Deserialize, Serialize};

/// A pole's (a mode's, or a root of a dynamics factor's denominator or numerator)
/// natural frequency and relative damping with their standard deviations; a real root
/// has damping 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoleUncertainty {
    /// Natural frequency `|p| / 2 pi`, Hz.
    pub f_hz: f64,
    /// Its standard deviation, Hz.
    pub f_hz_std: f64,
    /// Relative damping `-Re p / |p|`.
    pub zeta: f64,
    /// Its standard deviation.
    pub zeta_std: f64,
}
