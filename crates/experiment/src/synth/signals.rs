//! Excitation and noise signals of the simulated experiments: random-phase multisines
//! with a flat amplitude spectrum (the excitation of Section 4.2 of the wafer-stage
//! paper) and coloured output noise generated in the time domain (white sensor noise
//! plus a first-order low-frequency drift, the `v = H e` of McKelvey, Section 2.5).
//!
//! Randomness is portable: every stream is a ChaCha8 generator keyed by the seed and a
//! stream number that names its purpose, experiment and realization, so results do not
//! depend on thread scheduling.

use crate::nonparametric::LineGrid;
use frf_data::{FrfError, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::f64::consts::TAU;

/// What a random stream is used for (part of its stream number).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Stream {
    Phases = 1,
    OutputNoise = 2,
    InputNoise = 3,
    Distortion = 4,
}

/// The generator of stream `what` for experiment `e` and realization `r`.
pub(crate) fn stream_rng(seed: u64, what: Stream, e: usize, r: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(((what as u64) << 56) | ((r as u64 & 0xff_ffff) << 24) | (e as u64 & 0xff_ffff));
    rng
}

/// Random phases, uniform in `[0, 2 pi)`, one per excited line.
pub(crate) fn random_phases(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| TAU * rng.random::<f64>()).collect()
}

/// The unnormalised DFT values `X_k = (N / 2) A exp(j phi_k)` of the multisine
/// `x(t) = sum_k A cos(2 pi k t / N + phi_k)` with the flat amplitude `A` giving the RMS
/// value `rms`: `A = rms sqrt(2 / L)`.
pub(crate) fn multisine_spectrum(grid: &LineGrid, rms: f64, phases: &[f64]) -> Vec<C64> {
    let l = grid.n_lines() as f64;
    let a = rms * (2.0 / l).sqrt();
    let half_n = grid.period() as f64 / 2.0;
    phases
        .iter()
        .map(|&p| C64::from_polar(half_n * a, p))
        .collect()
}

/// Coloured noise added to each sensor: white noise of RMS `white_rms` plus a drift
/// `d[t] = a d[t-1] + drift_rms sqrt(1 - a^2) e[t]`, `a = exp(-2 pi f_c / fs)` (a
/// first-order low-pass of corner `drift_corner_hz`, RMS `drift_rms`, started in its
/// stationary distribution).
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseConfig {
    /// RMS of the white sensor noise (output units, m).
    pub white_rms: f64,
    /// RMS of the low-frequency drift.
    pub drift_rms: f64,
    /// Corner frequency of the drift, Hz.
    pub drift_corner_hz: f64,
}

impl Default for NoiseConfig {
    /// 1 nm white sensor noise and 5 nm of drift below 0.5 Hz.
    fn default() -> Self {
        Self {
            white_rms: 1e-9,
            drift_rms: 5e-9,
            drift_corner_hz: 0.5,
        }
    }
}

impl NoiseConfig {
    /// No noise at all.
    pub fn none() -> Self {
        Self {
            white_rms: 0.0,
            drift_rms: 0.0,
            drift_corner_hz: 1.0,
        }
    }
    /// True when both levels are zero.
    pub fn is_zero(&self) -> bool {
        self.white_rms == 0.0 && self.drift_rms == 0.0
    }
    pub(crate) fn validate(&self) -> Result<(), FrfError> {
        for (n, v) in [("white_rms", self.white_rms), ("drift_rms", self.drift_rms)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(FrfError::invalid(
                    format!("noise {n}"),
                    v,
                    "must be finite and >= 0",
                ));
            }
        }
        if self.drift_rms > 0.0 && !(self.drift_corner_hz.is_finite() && self.drift_corner_hz > 0.0)
        {
            return Err(FrfError::invalid(
                "noise drift_corner_hz",
                self.drift_corner_hz,
                "must be finite and > 0",
            ));
        }
        Ok(())
    }

    /// `channels` records of `len` samples at `fs` from `rng` (channel after channel).
    pub(crate) fn generate(
        &self,
        rng: &mut ChaCha8Rng,
        fs: f64,
        channels: usize,
        len: usize,
    ) -> Vec<Vec<f64>> {
        let a = (-TAU * self.drift_corner_hz / fs).exp();
        let drive = self.drift_rms * (1.0 - a * a).max(0.0).sqrt();
        (0..channels)
            .map(|_| {
                let mut out = Vec::with_capacity(len);
                let mut d = if self.drift_rms > 0.0 {
                    self.drift_rms * rng.sample::<f64, _>(StandardNormal)
                } else {
                    0.0
                };
                for _ in 0..len {
                    let mut v = 0.0;
                    if self.white_rms > 0.0 {
                        v += self.white_rms * rng.sample::<f64, _>(StandardNormal);
                    }
                    if self.drift_rms > 0.0 {
                        v += d;
                        d = a * d + drive * rng.sample::<f64, _>(StandardNormal);
                    }
                    out.push(v);
                }
                out
            })
            .collect()
    }
}

/// White noise records of RMS `rms`.
pub(crate) fn white_noise(
    rng: &mut ChaCha8Rng,
    rms: f64,
    channels: usize,
    len: usize,
) -> Vec<Vec<f64>> {
    (0..channels)
        .map(|_| {
            (0..len)
                .map(|_| rms * rng.sample::<f64, _>(StandardNormal))
                .collect()
        })
        .collect()
}
