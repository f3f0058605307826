//! The wafer-stage testbed: a free-floating rectangular plate measured out of plane, as in
//! Section 2.1 and Fig. 2 of the wafer-stage paper (van der Hulst et al.): 4 z-sensors,
//! 13 z-actuators, rigid-body z, Rx, Ry and 17 flexible modes, sampled at 10 kHz through
//! a zero-order hold with one sample of computation delay.
//!
//! Mode shapes are Warburton's products of free-free beam functions
//! `phi_mn(x, y) = X_m(x / Lx) Y_n(y / Ly) / sqrt(mass)` (mass-normalised: the beam
//! functions have unit mean square). `(m, n) = (0, 0), (1, 0), (0, 1)` are the rigid-body
//! translation and rotations, so the rigid-body residue is
//! `b_rb[i][j] = sum phi(sensor_i) phi(actuator_j)` over those three and the flexible
//! residues are `c b^T` with `c_i = phi(sensor_i)`, `b_j = phi(actuator_j)`. Frequencies
//! follow Warburton's approximation of the free plate, sorted, scaled so that the first
//! lands at `first_mode_hz` and the last of the 17 at `last_mode_hz`; a nearly square
//! plate gives the close pairs of the measured stage. Everything random comes from one
//! seeded ChaCha8 stream, so a seed gives the same plant on every platform.

use super::plant::{ModalPlant, ModalPlantBuilder};
use faer::Mat;
use frf_data::truth::Truth;
use frf_data::FrfError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Settings of [`WaferStage::build`]; `Default` is the reference stage of the paper.
#[derive(Debug, Clone, PartialEq)]
pub struct WaferStageConfig {
    /// Seed of every random choice (plate aspect, frequencies, damping, gain errors).
    pub seed: u64,
    /// Number of flexible modes (17).
    pub n_modes: usize,
    /// Range of the first flexible mode, Hz (130..150).
    pub first_mode_hz: (f64, f64),
    /// Range of the last flexible mode, Hz (1800..1950).
    pub last_mode_hz: (f64, f64),
    /// Range of the relative damping (0.004..0.02).
    pub zeta_range: (f64, f64),
    /// Plate mass, kg (20).
    pub mass_kg: f64,
    /// Nominal side of the square plate, m (0.4); the aspect ratio is drawn in
    /// `1 +- aspect_spread`.
    pub side_m: f64,
    /// Half the relative difference of the two sides (drawn in `0.3..1` times this; 0.04).
    pub aspect_spread: f64,
    /// Relative standard deviation of the mode-shape gains (mounting and calibration
    /// errors; 0.05).
    pub gain_spread: f64,
    /// Sample rate, Hz (10 kHz).
    pub fs: f64,
    /// Computation delay in samples on top of the hold (1).
    pub delay_samples: f64,
}

impl Default for WaferStageConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            n_modes: 17,
            first_mode_hz: (130.0, 150.0),
            last_mode_hz: (1800.0, 1950.0),
            zeta_range: (0.004, 0.02),
            mass_kg: 20.0,
            side_m: 0.4,
            aspect_spread: 0.04,
            gain_spread: 0.05,
            fs: 10_000.0,
            delay_samples: 1.0,
        }
    }
}

/// A simulated wafer stage: the plant, the sensor and actuator positions and the
/// sampling of its measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct WaferStage {
    /// The continuous plant (units m/N).
    pub plant: ModalPlant,
    /// Sensor positions `(x, y)` in m from the plate centre.
    pub sensors: Vec<[f64; 2]>,
    /// Actuator positions `(x, y)` in m from the plate centre.
    pub actuators: Vec<[f64; 2]>,
    /// Plate sides `(Lx, Ly)`, m.
    pub sides_m: [f64; 2],
    /// Beam-function indices `(m, n)` of each flexible mode.
    pub mode_indices: Vec<(usize, usize)>,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Computation delay in samples on top of the hold.
    pub delay_samples: f64,
    /// The seed it was built from.
    pub seed: u64,
}

/// Root of `cosh(b) cos(b) = 1` near `(2k + 1) pi / 2`: the `k`-th elastic free-free beam
/// eigenvalue (`k >= 1`: 4.7300, 7.8532, 10.9956, ...).
fn beam_eigenvalue(k: usize) -> f64 {
    let mut b = (2 * k + 1) as f64 * std::f64::consts::FRAC_PI_2;
    // f(b) = cos(b) - 1/cosh(b); Newton on it is well conditioned.
    for _ in 0..50 {
        let f = b.cos() - 1.0 / b.cosh();
        let df = -b.sin() + b.tanh() / b.cosh();
        let step = f / df;
        b -= step;
        if step.abs() < 1e-15 * b {
            break;
        }
    }
    b
}

/// The free-free beam function `X_m(xi)`, `xi` in `[0, 1]`, unit mean square:
/// `X_0 = 1`, `X_1 = sqrt(3) (2 xi - 1)`, and for `m >= 2` with `b = beta_{m-1}`:
/// `cosh(b xi) + cos(b xi) - sigma (sinh(b xi) + sin(b xi))`,
/// `sigma = (cosh b - cos b) / (sinh b - sin b)`, evaluated without cancellation.
pub fn beam_function(m: usize, xi: f64) -> f64 {
    match m {
        0 => 1.0,
        1 => 3f64.sqrt() * (2.0 * xi - 1.0),
        _ => {
            let b = beam_eigenvalue(m - 1);
            let x = b * xi;
            let (sh, ch) = (b.sinh(), b.cosh());
            let denom = sh - b.sin();
            let sigma = (ch - b.cos()) / denom;
            // 1 - sigma computed exactly: (sinh b - sin b - cosh b + cos b) / denom
            let one_minus_sigma = (-(-b).exp() - b.sin() + b.cos()) / denom;
            // cosh x - sigma sinh x = e^x (1 - sigma) / 2 + e^-x (1 + sigma) / 2
            let hyper = 0.5 * x.exp() * one_minus_sigma + 0.5 * (-x).exp() * (1.0 + sigma);
            hyper + x.cos() - sigma * x.sin()
        }
    }
}

/// Warburton's coefficients `(G, H, J)` of a free-free beam function of index `m`.
fn warburton(m: usize) -> (f64, f64, f64) {
    use std::f64::consts::PI;
    match m {
        0 => (0.0, 0.0, 0.0),
        1 => (0.0, 0.0, 12.0 / (PI * PI)),
        2 => (1.506, 1.248, 5.017),
        _ => {
            let g = m as f64 - 0.5;
            (
                g,
                g * g * (1.0 - 2.0 / (g * PI)),
                g * g * (1.0 + 6.0 / (g * PI)),
            )
        }
    }
}

/// Warburton's frequency parameter of the free plate mode `(m, n)` with side ratio
/// `r = Lx / Ly` (Poisson ratio 0.3); frequencies are proportional to it.
fn plate_lambda(m: usize, n: usize, r: f64) -> f64 {
    let nu_p = 0.3;
    let (gx, hx, jx) = warburton(m);
    let (gy, hy, jy) = warburton(n);
    (gx.powi(4) + gy.powi(4) * r.powi(4) + 2.0 * r * r * (nu_p * hx * hy + (1.0 - nu_p) * jx * jy))
        .sqrt()
}

/// Sensor positions as fractions of the half sides: near the four corners.
const SENSOR_POS: [[f64; 2]; 4] = [[0.96, 0.96], [-0.96, 0.96], [-0.96, -0.96], [0.96, -0.96]];
/// Actuator positions as fractions of the half sides: centre, four on the axes, four on
/// the outer and four on the inner diagonals (the layout of the paper's Fig. 2; with the
/// sensors above this gives the rigid-body residue of the reference data).
const ACTUATOR_POS: [[f64; 2]; 13] = [
    [0.0, 0.0],
    [A_OUT, 0.0],
    [-A_OUT, 0.0],
    [0.0, A_OUT],
    [0.0, -A_OUT],
    [A_OUT, A_OUT],
    [-A_OUT, A_OUT],
    [-A_OUT, -A_OUT],
    [A_OUT, -A_OUT],
    [A_IN, A_IN],
    [-A_IN, A_IN],
    [-A_IN, -A_IN],
    [A_IN, -A_IN],
];
/// Outer actuator ring (fraction of the half side).
const A_OUT: f64 = 0.5 / 0.96;
/// Inner actuator ring.
const A_IN: f64 = 0.25 / 0.96;

impl WaferStage {
    /// Builds the stage of `config` (see the module documentation).
    pub fn build(config: &WaferStageConfig) -> Result<Self, FrfError> {
        let c = config;
        let range_ok =
            |(lo, hi): (f64, f64)| lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi;
        if c.n_modes == 0 || c.n_modes > 60 {
            return Err(FrfError::invalid("n_modes", c.n_modes, "must be in 1..=60"));
        }
        if !range_ok(c.first_mode_hz)
            || !range_ok(c.last_mode_hz)
            || c.first_mode_hz.1 >= c.last_mode_hz.0
        {
            return Err(FrfError::invalid(
                "mode frequency ranges",
                format!("{:?} .. {:?}", c.first_mode_hz, c.last_mode_hz),
                "need 0 < first range < last range",
            ));
        }
        if !range_ok(c.zeta_range) || c.zeta_range.1 >= 1.0 {
            return Err(FrfError::invalid(
                "zeta_range",
                format!("{:?}", c.zeta_range),
                "need 0 < lo <= hi < 1",
            ));
        }
        if !(c.mass_kg.is_finite() && c.mass_kg > 0.0 && c.side_m.is_finite() && c.side_m > 0.0) {
            return Err(FrfError::invalid(
                "plate mass / side",
                format!("{} kg / {} m", c.mass_kg, c.side_m),
                "must be finite and > 0",
            ));
        }
        let spread_ok = |v: f64| v.is_finite() && (0.0..0.5).contains(&v);
        if !spread_ok(c.aspect_spread) || !spread_ok(c.gain_spread) {
            return Err(FrfError::invalid(
                "aspect_spread / gain_spread",
                format!("{} / {}", c.aspect_spread, c.gain_spread),
                "must be in [0, 0.5)",
            ));
        }
        let fs_ok = c.fs.is_finite() && c.fs > 0.0;
        let delay_ok = c.delay_samples.is_finite() && c.delay_samples >= 0.0;
        if !fs_ok || !delay_ok {
            return Err(FrfError::invalid(
                "fs / delay_samples",
                format!("{} / {}", c.fs, c.delay_samples),
                "fs must be > 0 and the delay >= 0",
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(c.seed);
        rng.set_stream(0x57a6e); // the plant's own stream
        let normal = rand_distr::StandardNormal;

        let aspect = c.aspect_spread * rng.random_range(0.3..=1.0);
        let lx = c.side_m * (1.0 + aspect);
        let ly = c.side_m * (1.0 - aspect);
        let sensors: Vec<[f64; 2]> = SENSOR_POS
            .iter()
            .map(|p| [p[0] * lx / 2.0, p[1] * ly / 2.0])
            .collect();
        let actuators: Vec<[f64; 2]> = ACTUATOR_POS
            .iter()
            .map(|p| [p[0] * lx / 2.0, p[1] * ly / 2.0])
            .collect();
        let (ny, nu) = (sensors.len(), actuators.len());
        let inv_sqrt_m = 1.0 / c.mass_kg.sqrt();
        let shape = |m: usize, n: usize, p: &[f64; 2]| {
            beam_function(m, p[0] / lx + 0.5) * beam_function(n, p[1] / ly + 0.5) * inv_sqrt_m
        };

        // rigid body: z, Ry (x-slope, index (1,0)) and Rx (y-slope, index (0,1))
        let rigid = [(0usize, 0usize), (1, 0), (0, 1)];
        let b_rb = Mat::from_fn(ny, nu, |i, j| {
            rigid
                .iter()
                .map(|&(m, n)| shape(m, n, &sensors[i]) * shape(m, n, &actuators[j]))
                .sum::<f64>()
        });

        // flexible modes by Warburton's frequency parameter
        let r = lx / ly;
        let mut cand: Vec<(f64, usize, usize)> = Vec::new();
        for m in 0..12 {
            for n in 0..12 {
                if rigid.contains(&(m, n)) {
                    continue;
                }
                cand.push((plate_lambda(m, n, r), m, n));
            }
        }
        cand.sort_by(|a, b| a.0.total_cmp(&b.0));
        cand.truncate(c.n_modes);
        let f_first = rng.random_range(c.first_mode_hz.0..=c.first_mode_hz.1);
        let f_last = rng.random_range(c.last_mode_hz.0..=c.last_mode_hz.1);
        let l1 = cand[0].0;
        let ln = cand[cand.len() - 1].0;
        let beta = if cand.len() > 1 && ln > l1 {
            (f_last / f_first).ln() / (ln / l1).ln()
        } else {
            1.0
        };
        let mut builder = ModalPlantBuilder::new(ny, nu).rigid_body(b_rb);
        let mut indices = Vec::with_capacity(cand.len());
        let mut freqs: Vec<f64> = Vec::with_capacity(cand.len());
        for (k, &(lam, m, n)) in cand.iter().enumerate() {
            // a small seeded detuning keeps the sorted order but splits exact ties
            let detune = if k == 0 || k + 1 == cand.len() {
                1.0
            } else {
                1.0 + 0.01 * rng.random_range(-1.0..=1.0)
            };
            let mut f = f_first * (lam / l1).powf(beta) * detune;
            // close pairs stay at least 1.2 % apart (resolvable in the CMIF, like the
            // pairs of the measured stage)
            if let Some(&prev) = freqs.last() {
                f = f.max(prev * 1.012);
            }
            freqs.push(f);
            let zeta = rng.random_range(c.zeta_range.0..=c.zeta_range.1);
            let gain = |v: f64, rng: &mut ChaCha8Rng| {
                let e: f64 = rng.sample(normal);
                v * (1.0 + c.gain_spread * e)
            };
            let cv: Vec<f64> = sensors
                .iter()
                .map(|p| shape(m, n, p))
                .collect::<Vec<_>>()
                .into_iter()
                .map(|v| gain(v, &mut rng))
                .collect();
            let bv: Vec<f64> = actuators
                .iter()
                .map(|p| shape(m, n, p))
                .collect::<Vec<_>>()
                .into_iter()
                .map(|v| gain(v, &mut rng))
                .collect();
            builder = builder.mode(f, zeta, cv, bv);
            indices.push((m, n));
        }
        let plant = builder.build()?;
        Ok(Self {
            plant,
            sensors,
            actuators,
            sides_m: [lx, ly],
            mode_indices: indices,
            fs: c.fs,
            delay_samples: c.delay_samples,
            seed: c.seed,
        })
    }

    /// The truth JSON of this stage: `delay_s = (0.5 + delay_samples) / fs` (hold plus
    /// computation, 150 us for the default).
    pub fn truth(&self) -> Truth {
        self.plant
            .to_truth(self.seed, self.fs, (0.5 + self.delay_samples) / self.fs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beam_eigenvalues_match_the_tables() {
        assert!((beam_eigenvalue(1) - 4.730_040_745).abs() < 1e-8);
        assert!((beam_eigenvalue(2) - 7.853_204_624).abs() < 1e-8);
        assert!((beam_eigenvalue(3) - 10.995_607_838).abs() < 1e-8);
    }

    #[test]
    fn beam_functions_have_unit_mean_square_and_free_end_value_two() {
        for m in 0..9 {
            let n = 20000;
            let ms: f64 = (0..n)
                .map(|k| {
                    let xi = (k as f64 + 0.5) / n as f64;
                    beam_function(m, xi).powi(2)
                })
                .sum::<f64>()
                / n as f64;
            assert!((ms - 1.0).abs() < 1e-6, "m = {m}: mean square {ms}");
            if m >= 2 {
                assert!((beam_function(m, 0.0).abs() - 2.0).abs() < 1e-9);
                assert!((beam_function(m, 1.0).abs() - 2.0).abs() < 1e-9);
            }
        }
    }
}
