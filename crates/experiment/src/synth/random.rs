//! Random modal plants of any size, with their exact FRF and a noisy measurement of it:
//! `frfit simulate random-modal`, for tests, benchmarks, and users who want to try frfit
//! at the size of their machine.
//!
//! The plant is the additive modal structure of [`ModalPlant`]: `K` lightly damped modes
//! with rank-one residues `c b^T` (sensor and actuator mode-shape gains drawn uniformly
//! in `[-1, 1]`), optionally a free rigid body `b_rb / s^2` of rank `min(3, ny, nu)`.
//! Natural frequencies are log-uniform in the band's inner part; a fraction of them is
//! placed as close pairs (a second mode within 0.1 to 1 % of the first, the hard case of
//! peak picking). The measurement adds circular complex Gaussian noise of standard
//! deviation `noise * median |G|` on every entry and line and states that variance
//! (the `_var` columns of the FRF CSV), as a nonparametric estimate would.

use super::plant::{ModalPlant, ModalPlantBuilder};
use faer::Mat;
use frf_data::{Frf, FrfError, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Settings of [`RandomModal::generate`]; the defaults are documented per field.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomModalConfig {
    /// Outputs (default 4).
    pub ny: usize,
    /// Inputs (default 4).
    pub nu: usize,
    /// Flexible modes (default 10).
    pub modes: usize,
    /// Frequency lines (default 4000).
    pub lines: usize,
    /// Band of the lines, Hz (default 50..2000).
    pub band_hz: (f64, f64),
    /// Natural frequencies are drawn in `[lo (1 + margin), hi / (1 + margin)]` so that
    /// every resonance lies inside the band (default 0.05).
    pub margin: f64,
    /// Relative damping range (default 0.002..0.02).
    pub zeta: (f64, f64),
    /// Fraction of the modes placed as the upper member of a close pair (default 0.1).
    pub close_pair_fraction: f64,
    /// A free rigid body `b_rb / s^2` (default false).
    pub rigid_body: bool,
    /// Noise standard deviation relative to the median magnitude of the response
    /// (default 1e-3; 0 for exact data).
    pub noise: f64,
    /// Logarithmically spaced lines instead of a uniform grid (default false: periodic
    /// excitation gives a uniform grid).
    pub log_grid: bool,
    /// Seed of the plant and the noise (default 1).
    pub seed: u64,
}

impl Default for RandomModalConfig {
    fn default() -> Self {
        Self {
            ny: 4,
            nu: 4,
            modes: 10,
            lines: 4000,
            band_hz: (50.0, 2000.0),
            margin: 0.05,
            zeta: (0.002, 0.02),
            close_pair_fraction: 0.1,
            rigid_body: false,
            noise: 1e-3,
            log_grid: false,
            seed: 1,
        }
    }
}

/// A generated plant with its exact and its measured FRF.
#[derive(Debug, Clone)]
pub struct RandomModal {
    /// The plant (its [`ModalPlant::to_truth`] is the truth JSON).
    pub plant: ModalPlant,
    /// The measured FRF, with its variance when `noise > 0`.
    pub measured: Frf,
    /// The exact response at the same lines.
    pub noiseless: Frf,
    /// The noise standard deviation (absolute).
    pub noise_std: f64,
}

impl RandomModalConfig {
    fn check(&self) -> Result<(), FrfError> {
        let bad = |name: &str, v: String, why: &str| Err(FrfError::invalid(name, v, why));
        if self.ny == 0 || self.nu == 0 {
            return bad(
                "ny, nu",
                format!("{} x {}", self.ny, self.nu),
                "need at least one output and one input",
            );
        }
        if self.lines < 2 {
            return bad("lines", self.lines.to_string(), "need at least 2 lines");
        }
        let (lo, hi) = self.band_hz;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
            return bad(
                "band",
                format!("{lo}:{hi}"),
                "must be LO:HI with 0 < LO < HI (Hz)",
            );
        }
        if !(self.margin.is_finite() && self.margin >= 0.0)
            || lo * (1.0 + self.margin) >= hi / (1.0 + self.margin)
        {
            return bad(
                "margin",
                self.margin.to_string(),
                "the band without the margins at both ends is empty",
            );
        }
        let (z0, z1) = self.zeta;
        if !(z0.is_finite() && z1.is_finite() && z0 > 0.0 && z1 >= z0 && z1 < 1.0) {
            return bad(
                "damping",
                format!("{z0}:{z1}"),
                "must be LO:HI with 0 < LO <= HI < 1",
            );
        }
        if !(0.0..=0.5).contains(&self.close_pair_fraction) {
            return bad(
                "close-pair fraction",
                self.close_pair_fraction.to_string(),
                "must be in [0, 0.5]",
            );
        }
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return bad(
                "noise",
                self.noise.to_string(),
                "must be finite and >= 0 (relative)",
            );
        }
        Ok(())
    }

    /// The lines of the grid, Hz.
    pub fn freq_hz(&self) -> Vec<f64> {
        let (lo, hi) = self.band_hz;
        let n = self.lines;
        (0..n)
            .map(|k| {
                let t = k as f64 / (n - 1) as f64;
                if self.log_grid {
                    lo * (hi / lo).powf(t)
                } else {
                    lo + (hi - lo) * t
                }
            })
            .collect()
    }
}

impl RandomModal {
    /// Draws the plant and its measurement (see the module documentation).
    pub fn generate(cfg: &RandomModalConfig) -> Result<Self, FrfError> {
        cfg.check()?;
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let (ny, nu) = (cfg.ny, cfg.nu);
        let (lo, hi) = (
            cfg.band_hz.0 * (1.0 + cfg.margin),
            cfg.band_hz.1 / (1.0 + cfg.margin),
        );
        // well-separated modes first (at least 0.5 % apart), then the close partners
        let n_close = (cfg.close_pair_fraction * cfg.modes as f64).round() as usize;
        let n_base = cfg.modes - n_close;
        let mut f: Vec<f64> = Vec::with_capacity(cfg.modes);
        let mut tries = 0;
        while f.len() < n_base {
            tries += 1;
            if tries > 1000 * cfg.modes.max(1) {
                return Err(FrfError::invalid(
                    "modes",
                    cfg.modes,
                    format!("{n_base} modes 0.5 % apart do not fit in {lo:.4}..{hi:.4} Hz"),
                ));
            }
            let x = lo * (hi / lo).powf(rng.random_range(0.0..1.0));
            if f.iter().all(|&y| (x / y).ln().abs() > 0.005) {
                f.push(x);
            }
        }
        f.sort_by(f64::total_cmp);
        let mut partners = Vec::with_capacity(n_close);
        for q in 0..n_close {
            // every k-th base mode gets a partner 0.1..1 % above it
            let base = f[(q * n_base) / n_close.max(1)];
            partners.push((base * (1.0 + rng.random_range(0.001..0.01))).min(hi));
        }
        f.extend(partners);
        f.sort_by(f64::total_cmp);
        let mut b = ModalPlantBuilder::new(ny, nu);
        if cfg.rigid_body {
            let rank = ny.min(nu).min(3);
            let cs: Vec<Vec<f64>> = (0..rank)
                .map(|_| (0..ny).map(|_| rng.random_range(-1.0..1.0)).collect())
                .collect();
            let bs: Vec<Vec<f64>> = (0..rank)
                .map(|_| (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect())
                .collect();
            // scaled so that the rigid body is comparable to the modes at the lowest line
            let w0 = std::f64::consts::TAU * cfg.band_hz.0;
            let res = Mat::from_fn(ny, nu, |i, j| {
                (0..rank).map(|r| cs[r][i] * bs[r][j]).sum::<f64>() * 1e-3 * w0 * w0
            });
            b = b.rigid_body(res);
        }
        for &fk in &f {
            let zeta = cfg.zeta.0 * (cfg.zeta.1 / cfg.zeta.0).powf(rng.random_range(0.0..1.0));
            let c: Vec<f64> = (0..ny).map(|_| rng.random_range(-1.0..1.0)).collect();
            let bb: Vec<f64> = (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect();
            // modal mass scaling: unit static gain per mode (residue w^2 c b^T / w^2)
            let w2 = (std::f64::consts::TAU * fk).powi(2);
            let c: Vec<f64> = c.iter().map(|v| v * w2.sqrt() * 1e-3).collect();
            let bb: Vec<f64> = bb.iter().map(|v| v * w2.sqrt()).collect();
            b = b.mode(fk, zeta, c, bb);
        }
        let plant = b.build()?;
        let freq = cfg.freq_hz();
        let exact = plant.continuous_response(&freq)?.values;
        let mut mags: Vec<f64> = exact.iter().map(|v| v.norm()).collect();
        mags.sort_by(f64::total_cmp);
        let median = mags[mags.len() / 2];
        let noise_std = cfg.noise * median;
        let mut noisy = exact.clone();
        if noise_std > 0.0 {
            let mut nrng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x006e_6f69_7365);
            let s = noise_std / std::f64::consts::SQRT_2;
            for v in noisy.iter_mut() {
                let re: f64 = StandardNormal.sample(&mut nrng);
                let im: f64 = StandardNormal.sample(&mut nrng);
                *v += C64::new(re * s, im * s);
            }
        }
        let variance = (noise_std > 0.0).then(|| vec![noise_std * noise_std; noisy.len()]);
        let measured = Frf::new(freq.clone(), ny, nu, noisy, variance)?;
        let noiseless = Frf::new(freq, ny, nu, exact, None)?;
        Ok(Self {
            plant,
            measured,
            noiseless,
            noise_std,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::FrfDataset;

    #[test]
    fn the_plant_has_the_asked_size_and_its_modes_in_the_band() {
        let cfg = RandomModalConfig {
            ny: 3,
            nu: 5,
            modes: 20,
            lines: 500,
            rigid_body: true,
            close_pair_fraction: 0.2,
            ..RandomModalConfig::default()
        };
        let r = RandomModal::generate(&cfg).unwrap();
        assert_eq!(r.plant.modes.len(), 20);
        assert_eq!((r.measured.ny(), r.measured.nu()), (3, 5));
        assert_eq!(r.measured.n_lines(), 500);
        let (lo, hi) = cfg.band_hz;
        assert!(r
            .plant
            .modes
            .iter()
            .all(|m| m.f_hz > lo && m.f_hz < hi && m.zeta >= 0.002 && m.zeta <= 0.02));
        // four close pairs: four modes within 1 % of the one below
        let close = r
            .plant
            .modes
            .windows(2)
            .filter(|w| w[1].f_hz / w[0].f_hz - 1.0 <= 0.01 + 1e-12)
            .count();
        assert!(close >= 4, "{close} close pairs");
        // the noise has the stated size: the standardised residual has unit power
        let var = r.measured.variance_vec().unwrap();
        let g = r.measured.values_vec();
        let g0 = r.noiseless.values_vec();
        let p: f64 = (0..g.len())
            .map(|i| (g[i] - g0[i]).norm_sqr() / var[i])
            .sum::<f64>()
            / g.len() as f64;
        assert!((p - 1.0).abs() < 0.05, "standardised noise power {p}");
        // seeded: the same config gives the same plant and data
        let again = RandomModal::generate(&cfg).unwrap();
        assert_eq!(again.plant, r.plant);
        assert_eq!(again.measured.values_vec(), r.measured.values_vec());
    }

    #[test]
    fn bad_settings_are_named() {
        for (cfg, says) in [
            (
                RandomModalConfig {
                    band_hz: (100.0, 50.0),
                    ..Default::default()
                },
                "band",
            ),
            (
                RandomModalConfig {
                    zeta: (0.0, 0.1),
                    ..Default::default()
                },
                "damping",
            ),
            (
                RandomModalConfig {
                    noise: f64::NAN,
                    ..Default::default()
                },
                "noise",
            ),
            (
                RandomModalConfig {
                    modes: 2000,
                    band_hz: (100.0, 200.0),
                    ..Default::default()
                },
                "modes",
            ),
        ] {
            let e = RandomModal::generate(&cfg).unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
    }
}
