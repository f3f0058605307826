//! Closed-loop periodic experiments on a simulated plant (Section 4.2 of the wafer-stage
//! paper: `nu` single-axis random-phase multisine experiments, `P` periods x `R`
//! realizations, in closed loop with a stabilising controller).
//!
//! The loop: `u = r - K y_m`, `y_m = y + v`, `y = P_d a`, `a = f(u delayed by d
//! samples)`, where `P_d` is the zero-order-hold discretisation of the continuous plant,
//! `f(a) = a + alpha a^3` an optional mild static actuator nonlinearity, `v` coloured
//! output noise and the recorded input is `u` plus optional measurement noise.
//!
//! Two simulation paths:
//! - [`SimulationPath::FrequencyDomain`] (a): the periodic steady state per excited line
//!   exactly, from the DFT relation of McKelvey eq. (8) without transient:
//!   `U = R - K M P R` with `M = (I + P K)^-1`, `Y = P U` (harmonic balance over all
//!   lines when the nonlinearity is on); the noise is generated in the time domain,
//!   transformed per period and passed through the loop per line
//!   (`U += -K M V`, `Y += P (-K M V) + V`, which is `M V`). It neglects the leakage of
//!   the noise response (the transient term of eq. (8) for the non-periodic noise),
//!   which through the rigid body's `1/s^2` dominates the noise at the lowest lines of a
//!   real experiment;
//! - [`SimulationPath::TimeDomain`] (b): the sampled loop simulated sample by sample from
//!   rest with the exact ZOH realisation of the plant, the first `transient_periods`
//!   periods discarded (the transient term of eq. (8) decays with the closed-loop poles).
//!
//! Both use the same random phases and noise records, so (b) equals (a) up to the
//! decayed transient and the leakage of the noise response: exactly without noise, and
//! within (b)'s noise level with it.

use super::controller::RigidBodyController;
use super::plant::ModalPlant;
use super::signals::{
    multisine_spectrum, random_phases, stream_rng, white_noise, NoiseConfig, Stream,
};
use crate::nonparametric::dft::RealPairFft;
use crate::nonparametric::small::invert;
use crate::nonparametric::{
    Accumulator, EstimatorConfig, LineGrid, NonparametricFrf, PeriodicSpectra, RealizationSpectra,
    TimeRecords,
};
use faer::Mat;
use frf_data::{Frf, FrfError, C64};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

/// Which simulation path to run (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimulationPath {
    /// (a) Periodic steady state per line in the frequency domain.
    FrequencyDomain,
    /// (b) Sample-by-sample simulation of the sampled loop from rest.
    TimeDomain,
}

/// The experiment design and disturbances.
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentConfig {
    /// Sample rate, period and excited lines.
    pub grid: LineGrid,
    /// Measured periods per realization, `P >= 1`.
    pub periods: usize,
    /// Realizations (independent random phases), `R >= 1`.
    pub realizations: usize,
    /// Periods simulated and discarded before the measured ones (time-domain path; the
    /// frequency-domain path starts in steady state and only skips their noise).
    pub transient_periods: usize,
    /// RMS of each experiment's multisine, in input units (N).
    pub rms: f64,
    /// Output (sensor) noise.
    pub output_noise: NoiseConfig,
    /// RMS of white measurement noise on the recorded inputs (errors-in-variables).
    pub input_noise_rms: f64,
    /// Coefficient `alpha` of the actuator nonlinearity `a + alpha a^3` (0: linear).
    pub cubic_nonlinearity: f64,
    /// Relative level `d` of a stochastic nonlinear contribution (0: none; on the
    /// time-domain path in open loop only). In realization `r` the plant behaves at the excited lines as
    /// `P + G_S,r`, the best linear approximation plus the stochastic nonlinear
    /// distortions of Pintelon and Schoukens (*System Identification: A Frequency Domain
    /// Approach*, 2nd ed. 2012, sec. 3.4): every entry and line of `G_S,r` is circular
    /// complex Gaussian with standard deviation `d |P_ij(w_k)|`, independent across lines
    /// and entries, new in each realization and the same in all its periods (and in all
    /// its experiments, so that `Y U^-1` of the realization is `P + G_S,r` up to the
    /// noise). The noise variance from the periods of one realization does not see it;
    /// the variance over realizations does.
    pub stochastic_distortion: f64,
    /// Computation delay in samples between the recorded input and the hold (1).
    pub delay_samples: f64,
    /// The input excited by each experiment; `None`: experiment `e` excites input `e`.
    pub excited_inputs: Option<Vec<usize>>,
    /// Dynamics the plant has and its model is not told of (frequency-domain path only;
    /// default none): rational factors of unit static gain
    /// ([`realize::DynamicsFactor`]) on one input column (an actuator), one output row
    /// (a sensor or its mount) or every entry (an amplifier's bandwidth). Each multiplies
    /// the sampled plant at every line by its value at `s = j w` of the line, which is
    /// how the fitted model applies a factor (`frfit`'s `input_dynamics` and
    /// `output_dynamics`), so the noiseless response ([`ClosedLoopExperiment::true_frf`])
    /// holds them exactly. The closed-loop stability check is of the plant without them:
    /// keep their poles well above the rigid-body loop's bandwidth.
    pub plant_dynamics: Vec<realize::DynamicsFactor>,
    /// Seed of the phases and noise.
    pub seed: u64,
    /// Keep the time records (time-domain path only).
    pub keep_time_signals: bool,
}

impl ExperimentConfig {
    /// The default wafer-stage experiment of the paper: 10 kHz, period 40000 samples,
    /// the 4000 odd lines 0.25..1999.75 Hz, 10 periods x 10 realizations, 2 N RMS per
    /// experiment, default sensor noise, one sample of computation delay.
    pub fn wafer_stage(seed: u64) -> Self {
        Self {
            grid: LineGrid::odd(10_000.0, 40_000, 0.0, 2000.0).expect("the default grid has lines"),
            periods: 10,
            realizations: 10,
            transient_periods: 1,
            rms: 2.0,
            output_noise: NoiseConfig::default(),
            input_noise_rms: 0.0,
            cubic_nonlinearity: 0.0,
            stochastic_distortion: 0.0,
            delay_samples: 1.0,
            excited_inputs: None,
            plant_dynamics: Vec::new(),
            seed,
            keep_time_signals: false,
        }
    }

    fn validate(&self, ny: usize, nu: usize) -> Result<Vec<usize>, FrfError> {
        if self.periods < 1 {
            return Err(FrfError::invalid(
                "periods",
                self.periods,
                "at least one period must be measured",
            ));
        }
        if self.realizations < 1 {
            return Err(FrfError::invalid(
                "realizations",
                self.realizations,
                "at least one realization is needed",
            ));
        }
        if !(self.rms.is_finite() && self.rms > 0.0) {
            return Err(FrfError::invalid("rms", self.rms, "must be finite and > 0"));
        }
        self.output_noise.validate()?;
        if !(self.input_noise_rms.is_finite() && self.input_noise_rms >= 0.0) {
            return Err(FrfError::invalid(
                "input_noise_rms",
                self.input_noise_rms,
                "must be finite and >= 0",
            ));
        }
        if !self.cubic_nonlinearity.is_finite() {
            return Err(FrfError::invalid(
                "cubic_nonlinearity",
                self.cubic_nonlinearity,
                "must be finite",
            ));
        }
        if !(self.stochastic_distortion.is_finite() && self.stochastic_distortion >= 0.0) {
            return Err(FrfError::invalid(
                "stochastic_distortion",
                self.stochastic_distortion,
                "must be finite and >= 0",
            ));
        }
        for (k, d) in self.plant_dynamics.iter().enumerate() {
            let what = format!("plant_dynamics[{k}]");
            let (index, n) = match d.target {
                realize::FactorTarget::Input(j) => (j, nu),
                realize::FactorTarget::Output(i) => (i, ny),
                realize::FactorTarget::All => (0, 1),
            };
            if index >= n {
                return Err(FrfError::invalid(
                    what,
                    index,
                    format!("the plant has {ny} outputs and {nu} inputs (0-based indices)"),
                ));
            }
            let finite = d.den.iter().chain(&d.num).all(|c| c.is_finite());
            if !(finite && d.scale.is_finite() && d.scale > 0.0) {
                return Err(FrfError::invalid(
                    what,
                    format!("den {:?}, num {:?}, scale {}", d.den, d.num, d.scale),
                    "coefficients must be finite and the scale > 0",
                ));
            }
            if d.den.is_empty() || !d.is_stable() {
                return Err(FrfError::invalid(
                    what,
                    format!("poles {:?} rad/s", d.poles()),
                    "a factor needs a stable denominator (every pole in the left half-plane)",
                ));
            }
        }
        if !(self.delay_samples.is_finite() && self.delay_samples >= 0.0) {
            return Err(FrfError::invalid(
                "delay_samples",
                self.delay_samples,
                "must be finite and >= 0",
            ));
        }
        let inputs = match &self.excited_inputs {
            None => (0..nu).collect(),
            Some(v) => {
                if v.is_empty() {
                    return Err(FrfError::invalid(
                        "excited_inputs",
                        "[]",
                        "at least one experiment is needed",
                    ));
                }
                if let Some(&bad) = v.iter().find(|&&j| j >= nu) {
                    return Err(FrfError::invalid(
                        "excited_inputs",
                        bad,
                        format!("the plant has {nu} inputs (0-based indices)"),
                    ));
                }
                v.clone()
            }
        };
        Ok(inputs)
    }
}

/// Data for the harmonic balance of the nonlinear steady state: the plant and `K M` at
/// every bin `1..N/2` (row `k - 1`).
#[derive(Debug)]
struct AllBins {
    p: Vec<C64>,
    km: Vec<C64>,
    /// Position of each excited line among the bins.
    excited_pos: Vec<usize>,
}

/// A closed-loop periodic experiment on a simulated plant (see the module
/// documentation).
#[derive(Debug)]
pub struct ClosedLoopExperiment {
    plant: ModalPlant,
    controller: RigidBodyController,
    config: ExperimentConfig,
    inputs: Vec<usize>,
    freq_hz: Vec<f64>,
    /// Sampled plant per line, `ny x nu` column-major.
    p_lines: Vec<C64>,
    /// `K M` per line, `nu x ny`.
    km_lines: Vec<C64>,
    spectral_radius: f64,
    fft: RealPairFft,
    all_bins: Option<AllBins>,
}

/// Multiplies the plant response `p` (`ny x nu` column-major per line of `freq_hz`) by
/// the dynamics factors `dynamics`, each at `s = j 2 pi f` of the line, on the entries
/// it targets (see [`ExperimentConfig::plant_dynamics`]).
fn apply_dynamics(
    dynamics: &[realize::DynamicsFactor],
    freq_hz: &[f64],
    ny: usize,
    nu: usize,
    p: &mut [C64],
) {
    for d in dynamics {
        for (k, f) in freq_hz.iter().enumerate() {
            let g = d.at(std::f64::consts::TAU * f);
            for j in 0..nu {
                for i in 0..ny {
                    if d.affects(i, j) {
                        p[k * ny * nu + j * ny + i] *= g;
                    }
                }
            }
        }
    }
}

/// `M = (I + P K)^-1` and `K M` from `vec(P)` (`ny x nu`) and `vec(K)` (`nu x ny`).
fn loop_maps(p: &[C64], k: &[C64], ny: usize, nu: usize) -> Option<(Vec<C64>, Vec<C64>)> {
    let mut ipk = vec![C64::new(0.0, 0.0); ny * ny];
    for b in 0..ny {
        for a in 0..ny {
            let mut s = C64::new(if a == b { 1.0 } else { 0.0 }, 0.0);
            for j in 0..nu {
                s += p[j * ny + a] * k[b * nu + j];
            }
            ipk[b * ny + a] = s;
        }
    }
    let m = invert(&ipk, ny)?;
    let mut km = vec![C64::new(0.0, 0.0); nu * ny];
    for b in 0..ny {
        for j in 0..nu {
            let mut s = C64::new(0.0, 0.0);
            for a in 0..ny {
                s += k[a * nu + j] * m[b * ny + a];
            }
            km[b * nu + j] = s;
        }
    }
    Some((m, km))
}

impl ClosedLoopExperiment {
    /// Checks the configuration, the closed-loop stability (the poles of the sampled
    /// loop: plant realisation, delay line and controller) and precomputes the loop per
    /// line.
    ///
    /// Errors: [`FrfError::InvalidParameter`] for a bad configuration (no excited lines
    /// cannot occur: [`LineGrid`] refuses them; periods < 1; an input index out of range),
    /// [`FrfError::UnstableClosedLoop`] when a closed-loop pole has modulus >= 1.
    pub fn new(
        plant: ModalPlant,
        controller: RigidBodyController,
        config: ExperimentConfig,
    ) -> Result<Self, FrfError> {
        let (ny, nu) = (plant.ny(), plant.nu());
        if controller.ny() != ny || controller.nu() != nu {
            return Err(FrfError::Dimension {
                what: "controller".into(),
                expected: format!("{nu}x{ny}"),
                got: format!("{}x{}", controller.nu(), controller.ny()),
            });
        }
        if (controller.fs - config.grid.fs()).abs() > 1e-9 * config.grid.fs() {
            return Err(FrfError::invalid(
                "controller fs",
                controller.fs,
                format!("differs from the experiment's {} Hz", config.grid.fs()),
            ));
        }
        let inputs = config.validate(ny, nu)?;
        let fs = config.grid.fs();
        let spectral_radius =
            closed_loop_spectral_radius(&plant, &controller, fs, config.delay_samples)?;
        let freq_hz = config.grid.freq_hz();
        let grid = plant.sampled_response(&freq_hz, fs, config.delay_samples)?;
        let mut p_lines = grid.values;
        apply_dynamics(&config.plant_dynamics, &freq_hz, ny, nu, &mut p_lines);
        let n = freq_hz.len();
        let mut km_lines = vec![C64::new(0.0, 0.0); n * nu * ny];
        let mut kbuf = vec![C64::new(0.0, 0.0); nu * ny];
        for k in 0..n {
            controller.response_into(freq_hz[k], &mut kbuf);
            let (_, km) = loop_maps(&p_lines[k * ny * nu..(k + 1) * ny * nu], &kbuf, ny, nu)
                .ok_or_else(|| FrfError::Numerical {
                    what: "closed-loop map (I + P K)^-1".into(),
                    why: format!("singular at {} Hz", freq_hz[k]),
                })?;
            km_lines[k * nu * ny..(k + 1) * nu * ny].copy_from_slice(&km);
        }
        let fft = RealPairFft::new(config.grid.period());
        let all_bins = if config.cubic_nonlinearity != 0.0 {
            let period = config.grid.period();
            let nb = period.div_ceil(2) - 1; // bins 1..=nb are strictly below N/2
            let df = config.grid.df();
            let f_all: Vec<f64> = (1..=nb).map(|b| b as f64 * df).collect();
            let mut p = plant
                .sampled_response(&f_all, fs, config.delay_samples)?
                .values;
            apply_dynamics(&config.plant_dynamics, &f_all, ny, nu, &mut p);
            let mut km = vec![C64::new(0.0, 0.0); nb * nu * ny];
            for b in 0..nb {
                controller.response_into(f_all[b], &mut kbuf);
                let (_, kmb) = loop_maps(&p[b * ny * nu..(b + 1) * ny * nu], &kbuf, ny, nu)
                    .ok_or_else(|| FrfError::Numerical {
                        what: "closed-loop map (I + P K)^-1".into(),
                        why: format!("singular at {} Hz", f_all[b]),
                    })?;
                km[b * nu * ny..(b + 1) * nu * ny].copy_from_slice(&kmb);
            }
            let excited_pos = config.grid.bins().iter().map(|&b| b - 1).collect();
            Some(AllBins { p, km, excited_pos })
        } else {
            None
        };
        Ok(Self {
            plant,
            controller,
            config,
            inputs,
            freq_hz,
            p_lines,
            km_lines,
            spectral_radius,
            fft,
            all_bins,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ExperimentConfig {
        &self.config
    }
    /// The plant.
    pub fn plant(&self) -> &ModalPlant {
        &self.plant
    }
    /// The controller.
    pub fn controller(&self) -> &RigidBodyController {
        &self.controller
    }
    /// Frequencies of the excited lines, Hz.
    pub fn freq_hz(&self) -> &[f64] {
        &self.freq_hz
    }
    /// Largest modulus of the closed-loop poles (< 1: stable).
    pub fn spectral_radius(&self) -> f64 {
        self.spectral_radius
    }
    /// Number of experiments.
    pub fn n_experiments(&self) -> usize {
        self.inputs.len()
    }

    /// The true sampled plant (ZOH + delay) at the excited lines.
    pub fn true_frf(&self) -> Result<Frf, FrfError> {
        let mut f = Frf::new(
            self.freq_hz.clone(),
            self.plant.ny(),
            self.plant.nu(),
            self.p_lines.clone(),
            None,
        )?;
        f.comments
            .push("exact sampled response (zero-order hold + delay)".into());
        Ok(f)
    }

    /// Simulates realization `r` (all experiments, in parallel).
    pub fn realization(
        &self,
        r: usize,
        path: SimulationPath,
    ) -> Result<RealizationSpectra, FrfError> {
        let (ny, nu) = (self.plant.ny(), self.plant.nu());
        let ne = self.inputs.len();
        let (np, nl) = (self.config.periods, self.freq_hz.len());
        let parts: Vec<ExperimentSpectra> = (0..ne)
            .into_par_iter()
            .map(|e| match path {
                SimulationPath::FrequencyDomain => self.experiment_frequency_domain(e, r),
                SimulationPath::TimeDomain => self.experiment_time_domain(e, r),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut input = Vec::with_capacity(ne * np * nl * nu);
        let mut output = Vec::with_capacity(ne * np * nl * ny);
        let mut reference = Vec::with_capacity(ne * nl * nu);
        let mut time = TimeRecords {
            fs: self.config.grid.fs(),
            input: Vec::new(),
            output: Vec::new(),
        };
        let keep = self.config.keep_time_signals && path == SimulationPath::TimeDomain;
        for part in parts {
            input.extend_from_slice(&part.input);
            output.extend_from_slice(&part.output);
            reference.extend_from_slice(&part.reference);
            if let Some((u, y)) = part.time {
                time.input.push(u);
                time.output.push(y);
            }
        }
        let mut rs = RealizationSpectra::new(ne, np, nl, ny, nu, input, output, Some(reference))?;
        if keep {
            rs.time = Some(time);
        }
        Ok(rs)
    }

    /// Simulates every realization and keeps all spectra (memory: `16 R ne P L (nu + ny)`
    /// bytes; use [`ClosedLoopExperiment::estimate`] for large experiments).
    pub fn run(&self, path: SimulationPath) -> Result<PeriodicSpectra, FrfError> {
        let reals = (0..self.config.realizations)
            .map(|r| self.realization(r, path))
            .collect::<Result<Vec<_>, _>>()?;
        let mut s = PeriodicSpectra::new(
            self.freq_hz.clone(),
            self.plant.ny(),
            self.plant.nu(),
            reals,
        )?;
        s.comments.push(format!(
            "simulated closed-loop experiment, seed {}, {:?} path",
            self.config.seed, path
        ));
        Ok(s)
    }

    /// Simulates every realization and feeds it to the nonparametric estimator as it
    /// comes (only one realization's spectra in memory at a time).
    pub fn estimate(
        &self,
        path: SimulationPath,
        est: &EstimatorConfig,
    ) -> Result<NonparametricFrf, FrfError> {
        let mut acc = Accumulator::new(
            self.freq_hz.clone(),
            self.plant.ny(),
            self.plant.nu(),
            self.inputs.len(),
            est.clone(),
        )?;
        for r in 0..self.config.realizations {
            let rs = self.realization(r, path)?;
            acc.add(&rs)?;
        }
        acc.finish()
    }

    fn reference_spectrum(&self, e: usize, r: usize) -> Vec<C64> {
        let mut rng = stream_rng(self.config.seed, Stream::Phases, e, r);
        let phases = random_phases(&mut rng, self.freq_hz.len());
        multisine_spectrum(&self.config.grid, self.config.rms, &phases)
    }

    /// Noise records (output, input) over transient + measured periods.
    fn noise_records(&self, e: usize, r: usize) -> (Vec<Vec<f64>>, Option<Vec<Vec<f64>>>) {
        let (ny, nu) = (self.plant.ny(), self.plant.nu());
        let len = (self.config.transient_periods + self.config.periods) * self.config.grid.period();
        let fs = self.config.grid.fs();
        let v = if self.config.output_noise.is_zero() {
            Vec::new()
        } else {
            let mut rng = stream_rng(self.config.seed, Stream::OutputNoise, e, r);
            self.config.output_noise.generate(&mut rng, fs, ny, len)
        };
        let nu_rec = (self.config.input_noise_rms > 0.0).then(|| {
            let mut rng = stream_rng(self.config.seed, Stream::InputNoise, e, r);
            white_noise(&mut rng, self.config.input_noise_rms, nu, len)
        });
        (v, nu_rec)
    }

    /// DFT at the excited lines of `records[ch][offset..offset + N]` into
    /// `out[k * nch + ch]`.
    fn period_spectra(
        &self,
        records: &[Vec<f64>],
        offset: usize,
        buf: &mut Vec<C64>,
        out: &mut [C64],
    ) {
        let n = self.config.grid.period();
        let bins = self.config.grid.bins();
        let nl = bins.len();
        let nch = records.len();
        let mut o1 = vec![C64::new(0.0, 0.0); nl];
        let mut o2 = vec![C64::new(0.0, 0.0); nl];
        let mut ch = 0;
        while ch < nch {
            let x1 = &records[ch][offset..offset + n];
            let x2 = (ch + 1 < nch).then(|| &records[ch + 1][offset..offset + n]);
            self.fft.forward_pair(x1, x2, bins, buf, &mut o1, &mut o2);
            for k in 0..nl {
                out[k * nch + ch] = o1[k];
                if x2.is_some() {
                    out[k * nch + ch + 1] = o2[k];
                }
            }
            ch += 2;
        }
    }

    /// The stochastic nonlinear contribution of realization `r` (see
    /// [`ExperimentConfig::stochastic_distortion`]), `ny x nu` column-major per line: the
    /// same for every experiment and period of the realization. `None` when it is off.
    fn distortion_lines(&self, r: usize) -> Option<Vec<C64>> {
        let d = self.config.stochastic_distortion;
        if d == 0.0 {
            return None;
        }
        let mut rng = stream_rng(self.config.seed, Stream::Distortion, 0, r);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        Some(
            self.p_lines
                .iter()
                .map(|p| {
                    let re: f64 = rng.sample(StandardNormal);
                    let im: f64 = rng.sample(StandardNormal);
                    C64::new(re, im) * (d * s * p.norm())
                })
                .collect(),
        )
    }

    /// `yss + G_S,r uss` per line (the steady-state output of realization `r` with its
    /// stochastic nonlinear contribution), or `yss` when it is off.
    fn add_stochastic_distortion(&self, r: usize, uss: &[C64], mut yss: Vec<C64>) -> Vec<C64> {
        let Some(gs) = self.distortion_lines(r) else {
            return yss;
        };
        let (ny, nu) = (self.plant.ny(), self.plant.nu());
        for k in 0..self.freq_hz.len() {
            let g = &gs[k * ny * nu..(k + 1) * ny * nu];
            for j in 0..nu {
                let u = uss[k * nu + j];
                for i in 0..ny {
                    yss[k * ny + i] += g[j * ny + i] * u;
                }
            }
        }
        yss
    }

    /// Path (a) for experiment `e`, realization `r`.
    fn experiment_frequency_domain(
        &self,
        e: usize,
        r: usize,
    ) -> Result<ExperimentSpectra, FrfError> {
        let (ny, nu) = (self.plant.ny(), self.plant.nu());
        let (np, nl, n) = (
            self.config.periods,
            self.freq_hz.len(),
            self.config.grid.period(),
        );
        let a = self.inputs[e];
        let rk = self.reference_spectrum(e, r);
        // steady state at the excited lines
        let (uss, yss) = match &self.all_bins {
            None => {
                let mut uss = vec![C64::new(0.0, 0.0); nl * nu];
                let mut yss = vec![C64::new(0.0, 0.0); nl * ny];
                for k in 0..nl {
                    let p = &self.p_lines[k * ny * nu..(k + 1) * ny * nu];
                    let km = &self.km_lines[k * nu * ny..(k + 1) * nu * ny];
                    // u = e_a r - K M P e_a r; y = P u (computed from the same u, so that
                    // Y U^-1 = P to rounding even where the loop gain makes U small)
                    let pa = &p[a * ny..(a + 1) * ny];
                    for j in 0..nu {
                        let mut s = C64::new(if j == a { 1.0 } else { 0.0 }, 0.0);
                        for b in 0..ny {
                            s -= km[b * nu + j] * pa[b];
                        }
                        uss[k * nu + j] = s * rk[k];
                    }
                    for j in 0..nu {
                        let u = uss[k * nu + j];
                        for i in 0..ny {
                            yss[k * ny + i] += p[j * ny + i] * u;
                        }
                    }
                }
                (uss, yss)
            }
            Some(ab) => self.harmonic_balance(ab, a, &rk)?,
        };
        let yss = self.add_stochastic_distortion(r, &uss, yss);
        let (v, nurec) = self.noise_records(e, r);
        let mut input = vec![C64::new(0.0, 0.0); np * nl * nu];
        let mut output = vec![C64::new(0.0, 0.0); np * nl * ny];
        let mut buf = Vec::with_capacity(n);
        let mut vk = vec![C64::new(0.0, 0.0); nl * ny];
        let mut nk = vec![C64::new(0.0, 0.0); nl * nu];
        let t0 = self.config.transient_periods * n;
        for p in 0..np {
            let u_out = &mut input[p * nl * nu..(p + 1) * nl * nu];
            let y_out = &mut output[p * nl * ny..(p + 1) * nl * ny];
            u_out.copy_from_slice(&uss);
            y_out.copy_from_slice(&yss);
            if !v.is_empty() {
                self.period_spectra(&v, t0 + p * n, &mut buf, &mut vk);
                // the noise through the loop: u += du = -K M V, y += P du + V (the plant
                // relation y = P u + v holds exactly line by line)
                let mut du = vec![C64::new(0.0, 0.0); nu];
                for k in 0..nl {
                    let pk = &self.p_lines[k * ny * nu..(k + 1) * ny * nu];
                    let km = &self.km_lines[k * nu * ny..(k + 1) * nu * ny];
                    let vv = &vk[k * ny..(k + 1) * ny];
                    for j in 0..nu {
                        let mut s = C64::new(0.0, 0.0);
                        for b in 0..ny {
                            s -= km[b * nu + j] * vv[b];
                        }
                        du[j] = s;
                        u_out[k * nu + j] += s;
                    }
                    for i in 0..ny {
                        let mut s = vv[i];
                        for j in 0..nu {
                            s += pk[j * ny + i] * du[j];
                        }
                        y_out[k * ny + i] += s;
                    }
                }
            }
            if let Some(nr) = &nurec {
                self.period_spectra(nr, t0 + p * n, &mut buf, &mut nk);
                for (u, d) in u_out.iter_mut().zip(&nk) {
                    *u += *d;
                }
            }
        }
        let mut reference = vec![C64::new(0.0, 0.0); nl * nu];
        for k in 0..nl {
            reference[k * nu + a] = rk[k];
        }
        Ok(ExperimentSpectra {
            input,
            output,
            reference,
            time: None,
        })
    }

    /// Noise-free periodic steady state with the actuator nonlinearity by harmonic
    /// balance: `u = S_i r - K M P n(u)`, `n(u) = alpha u^3`, iterated over all bins
    /// `1..N/2` (a contraction for a mild nonlinearity; the linear loop is the
    /// preconditioner). The DC component of `n(u)` is dropped (it is zero for the odd
    /// multisines; otherwise the integral action rejects it). Returns `(U, Y)` at the
    /// excited lines.
    fn harmonic_balance(
        &self,
        ab: &AllBins,
        a: usize,
        rk: &[C64],
    ) -> Result<(Vec<C64>, Vec<C64>), FrfError> {
        let (ny, nu) = (self.plant.ny(), self.plant.nu());
        let n = self.config.grid.period();
        let nb = ab.km.len() / (nu * ny);
        let alpha = self.config.cubic_nonlinearity;
        // linear solution at every bin (nonzero only at excited lines): u_lin = e_a r - K M P e_a r
        let mut ulin = vec![C64::new(0.0, 0.0); nb * nu];
        for (k, &b) in ab.excited_pos.iter().enumerate() {
            let p = &ab.p[b * ny * nu..(b + 1) * ny * nu];
            let km = &ab.km[b * nu * ny..(b + 1) * nu * ny];
            let pa = &p[a * ny..(a + 1) * ny];
            for j in 0..nu {
                let mut s = C64::new(if j == a { 1.0 } else { 0.0 }, 0.0);
                for i in 0..ny {
                    s -= km[i * nu + j] * pa[i];
                }
                ulin[b * nu + j] = s * rk[k];
            }
        }
        let mut u = ulin.clone();
        let mut nlin = vec![C64::new(0.0, 0.0); nb * nu];
        let mut buf = Vec::with_capacity(n);
        let half = n / 2 + 1;
        let mut spec1 = vec![C64::new(0.0, 0.0); half];
        let mut spec2 = vec![C64::new(0.0, 0.0); half];
        let mut x1 = vec![0.0; n];
        let mut x2 = vec![0.0; n];
        let all_bins: Vec<usize> = (1..=nb).collect();
        let mut o1 = vec![C64::new(0.0, 0.0); nb];
        let mut o2 = vec![C64::new(0.0, 0.0); nb];
        let scale = u
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE);
        let mut converged = false;
        for _iter in 0..200 {
            // n(u) = alpha u(t)^3 per channel, two channels per FFT
            let mut ch = 0;
            while ch < nu {
                spec1.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
                spec2.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
                for b in 0..nb {
                    spec1[b + 1] = u[b * nu + ch];
                    if ch + 1 < nu {
                        spec2[b + 1] = u[b * nu + ch + 1];
                    }
                }
                let two = ch + 1 < nu;
                self.fft.inverse_pair(
                    &spec1,
                    two.then_some(&spec2[..]),
                    &mut buf,
                    &mut x1,
                    two.then_some(&mut x2[..]),
                );
                x1.iter_mut().for_each(|v| *v = alpha * *v * *v * *v);
                if two {
                    x2.iter_mut().for_each(|v| *v = alpha * *v * *v * *v);
                }
                self.fft.forward_pair(
                    &x1,
                    two.then_some(&x2[..]),
                    &all_bins,
                    &mut buf,
                    &mut o1,
                    &mut o2,
                );
                for b in 0..nb {
                    nlin[b * nu + ch] = o1[b];
                    if two {
                        nlin[b * nu + ch + 1] = o2[b];
                    }
                }
                ch += 2;
            }
            // u_new = u_lin - K M P n
            let mut change: f64 = 0.0;
            for b in 0..nb {
                let p = &ab.p[b * ny * nu..(b + 1) * ny * nu];
                let km = &ab.km[b * nu * ny..(b + 1) * nu * ny];
                let nv = &nlin[b * nu..(b + 1) * nu];
                let mut pn = vec![C64::new(0.0, 0.0); ny];
                for j in 0..nu {
                    for i in 0..ny {
                        pn[i] += p[j * ny + i] * nv[j];
                    }
                }
                for j in 0..nu {
                    let mut s = ulin[b * nu + j];
                    for i in 0..ny {
                        s -= km[i * nu + j] * pn[i];
                    }
                    let c = (s - u[b * nu + j]).norm();
                    // NaN must count as divergence (f64::max would ignore it)
                    change = if c.is_nan() {
                        f64::INFINITY
                    } else {
                        change.max(c)
                    };
                    u[b * nu + j] = s;
                }
            }
            if !change.is_finite() {
                break;
            }
            if change <= 1e-14 * scale {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(FrfError::invalid(
                "cubic_nonlinearity",
                alpha,
                "the harmonic balance of the nonlinear periodic steady state did not converge: \
                 the nonlinearity is too strong for a mild-distortion simulation",
            ));
        }
        // final n(u) is consistent with u up to the tolerance; Y = P (u + n)
        let nl = ab.excited_pos.len();
        let mut uo = vec![C64::new(0.0, 0.0); nl * nu];
        let mut yo = vec![C64::new(0.0, 0.0); nl * ny];
        for (k, &b) in ab.excited_pos.iter().enumerate() {
            let p = &ab.p[b * ny * nu..(b + 1) * ny * nu];
            for j in 0..nu {
                let w = u[b * nu + j] + nlin[b * nu + j];
                uo[k * nu + j] = u[b * nu + j];
                for i in 0..ny {
                    yo[k * ny + i] += p[j * ny + i] * w;
                }
            }
        }
        Ok((uo, yo))
    }

    /// Path (b) for experiment `e`, realization `r`.
    fn experiment_time_domain(&self, e: usize, r: usize) -> Result<ExperimentSpectra, FrfError> {
        let (ny, nu) = (self.plant.ny(), self.plant.nu());
        let cfg = &self.config;
        let (np, nl, n) = (cfg.periods, self.freq_hz.len(), cfg.grid.period());
        if cfg.stochastic_distortion != 0.0 && self.controller.rank() != 0 {
            return Err(FrfError::invalid(
                "stochastic_distortion",
                cfg.stochastic_distortion,
                "is simulated on the time-domain path in open loop only (a plant without \
                 rigid body, RigidBodyController::open_loop): in closed loop the distortion \
                 would circulate through the controller",
            ));
        }
        if !cfg.plant_dynamics.is_empty() {
            return Err(FrfError::invalid(
                "plant_dynamics",
                cfg.plant_dynamics.len(),
                "undeclared dynamics factors are simulated on the frequency-domain path only",
            ));
        }
        let d = cfg.delay_samples;
        if d.fract() != 0.0 {
            return Err(FrfError::invalid(
                "delay_samples",
                d,
                "the time-domain path needs a whole number of samples of delay",
            ));
        }
        let d = d as usize;
        if d == 0 && self.plant.feedthrough.is_some() {
            return Err(FrfError::invalid(
                "delay_samples",
                0,
                "a plant with feedthrough needs at least one sample of delay in the loop \
                 (an algebraic loop otherwise)",
            ));
        }
        let a_in = self.inputs[e];
        let rk = self.reference_spectrum(e, r);
        // reference time signal from its spectrum at the excited lines
        let half = n / 2 + 1;
        let mut spec = vec![C64::new(0.0, 0.0); half];
        for (k, &b) in cfg.grid.bins().iter().enumerate() {
            spec[b] = rk[k];
        }
        let mut buf = Vec::with_capacity(n);
        let mut rt = vec![0.0; n];
        self.fft.inverse_pair(&spec, None, &mut buf, &mut rt, None);
        // The stochastic nonlinear contribution (open loop): in steady state the input at
        // the excited lines is the reference on input `a_in`, so the contribution to
        // output `i` is the periodic signal with spectrum `G_S,r[i, a_in](k) R(k)`, the
        // same in every period (as on the frequency-domain path, where it multiplies the
        // steady-state input).
        let distortion: Vec<Vec<f64>> = match self.distortion_lines(r) {
            None => Vec::new(),
            Some(gs) => (0..ny)
                .map(|i| {
                    let mut spec = vec![C64::new(0.0, 0.0); half];
                    for (k, &b) in cfg.grid.bins().iter().enumerate() {
                        spec[b] = gs[k * ny * nu + a_in * ny + i] * rk[k];
                    }
                    let mut out = vec![0.0; n];
                    self.fft.inverse_pair(&spec, None, &mut buf, &mut out, None);
                    out
                })
                .collect(),
        };
        let (v, nurec) = self.noise_records(e, r);
        let total = (cfg.transient_periods + np) * n;
        let t0 = cfg.transient_periods * n;
        let dp = self.plant.discretize(1.0 / cfg.grid.fs())?;
        let mut x = dp.zero_state();
        let mut xk = self.controller.zero_state();
        let mut delay = vec![vec![0.0; nu]; d.max(1)];
        let mut head = 0usize;
        let mut u_rec = vec![vec![0.0; np * n]; nu];
        let mut y_rec = vec![vec![0.0; np * n]; ny];
        let mut y = vec![0.0; ny];
        let mut ym = vec![0.0; ny];
        let mut fb = vec![0.0; nu];
        let mut act = vec![0.0; nu];
        let mut u = vec![0.0; nu];
        let alpha = cfg.cubic_nonlinearity;
        let zero_u = vec![0.0; nu];
        for t in 0..total {
            if d > 0 {
                for j in 0..nu {
                    let a = delay[head][j];
                    act[j] = a + alpha * a * a * a;
                }
                dp.output(&x, &act, &mut y);
            } else {
                dp.output(&x, &zero_u, &mut y);
            }
            for i in 0..ny {
                ym[i] = y[i]
                    + if v.is_empty() { 0.0 } else { v[i][t] }
                    + distortion.get(i).map_or(0.0, |d| d[t % n]);
            }
            self.controller.step(&mut xk, &ym, &mut fb);
            u.copy_from_slice(&fb);
            u[a_in] += rt[t % n];
            if d > 0 {
                delay[head].copy_from_slice(&u);
                head = (head + 1) % d;
            } else {
                for j in 0..nu {
                    act[j] = u[j] + alpha * u[j] * u[j] * u[j];
                }
            }
            dp.step(&mut x, &act);
            if t >= t0 {
                let tt = t - t0;
                for j in 0..nu {
                    u_rec[j][tt] = u[j] + nurec.as_ref().map_or(0.0, |nr| nr[j][t]);
                }
                for i in 0..ny {
                    y_rec[i][tt] = ym[i];
                }
            }
            if t % 4096 == 0 && !(y.iter().all(|v| v.is_finite())) {
                return Err(FrfError::Numerical {
                    what: "time-domain simulation".into(),
                    why: format!("the output became non-finite at sample {t}"),
                });
            }
        }
        let mut input = vec![C64::new(0.0, 0.0); np * nl * nu];
        let mut output = vec![C64::new(0.0, 0.0); np * nl * ny];
        for p in 0..np {
            self.period_spectra(
                &u_rec,
                p * n,
                &mut buf,
                &mut input[p * nl * nu..(p + 1) * nl * nu],
            );
            self.period_spectra(
                &y_rec,
                p * n,
                &mut buf,
                &mut output[p * nl * ny..(p + 1) * nl * ny],
            );
        }
        let mut reference = vec![C64::new(0.0, 0.0); nl * nu];
        for k in 0..nl {
            reference[k * nu + a_in] = rk[k];
        }
        let time = cfg.keep_time_signals.then_some((u_rec, y_rec));
        Ok(ExperimentSpectra {
            input,
            output,
            reference,
            time,
        })
    }
}

/// Time records, one per channel.
type Records = Vec<Vec<f64>>;

/// One experiment's spectra, layout `[p][k][ch]`.
struct ExperimentSpectra {
    input: Vec<C64>,
    output: Vec<C64>,
    reference: Vec<C64>,
    time: Option<(Records, Records)>,
}

/// The largest modulus of the poles of the sampled closed loop `u = r - K y`
/// (McKelvey, Section 3.5): plant realisation (exact ZOH, the discrete system of
/// eq. (6)), `ceil(delay)` samples of delay on every input (a fractional delay is
/// rounded up for this check), the controller. The periodic steady state of eq. (8)
/// exists only when it is `< 1`; otherwise this fails with
/// [`FrfError::UnstableClosedLoop`] (threshold `1 - 1e-12`).
pub fn closed_loop_spectral_radius(
    plant: &ModalPlant,
    controller: &RigidBodyController,
    fs: f64,
    delay_samples: f64,
) -> Result<f64, FrfError> {
    let (ny, nu) = (plant.ny(), plant.nu());
    let dp = plant.discretize(1.0 / fs)?;
    let (ap, bp, cp, dpm) = dp.real_matrices();
    let (ak, bk, ck, dk) = controller.real_matrices();
    let d = delay_samples.ceil() as usize;
    let has_ft = plant.feedthrough.is_some();
    if d == 0 && has_ft {
        return Err(FrfError::invalid(
            "delay_samples",
            delay_samples,
            "a plant with feedthrough needs at least one sample of delay in the loop",
        ));
    }
    let (npx, nkx) = (ap.nrows(), ak.nrows());
    let n = npx + d * nu + nkx;
    let mut a = Mat::<f64>::zeros(n, n);
    let ko = npx + d * nu; // controller offset
                           // y = Cp xp + Dp z_d (d >= 1) or Cp xp (d == 0)
    if d == 0 {
        // u = Ck xk + Dk Cp xp; xp' = Ap xp + Bp u; xk' = Ak xk + Bk Cp xp
        let dkcp = &dk * &cp;
        let apx = &ap + &bp * &dkcp;
        let bpck = &bp * &ck;
        let bkcp = &bk * &cp;
        for i in 0..npx {
            for j in 0..npx {
                a[(i, j)] = apx[(i, j)];
            }
            for j in 0..nkx {
                a[(i, ko + j)] = bpck[(i, j)];
            }
        }
        for i in 0..nkx {
            for j in 0..npx {
                a[(ko + i, j)] = bkcp[(i, j)];
            }
            for j in 0..nkx {
                a[(ko + i, ko + j)] = ak[(i, j)];
            }
        }
    } else {
        let zd = npx + (d - 1) * nu; // offset of z_d (oldest)
        let dkcp = &dk * &cp;
        let dkdp = &dk * &dpm;
        let bkcp = &bk * &cp;
        let bkdp = &bk * &dpm;
        for i in 0..npx {
            for j in 0..npx {
                a[(i, j)] = ap[(i, j)];
            }
            for j in 0..nu {
                a[(i, zd + j)] = bp[(i, j)];
            }
        }
        // z_1' = u = Ck xk + Dk (Cp xp + Dp z_d)
        for i in 0..nu {
            for j in 0..npx {
                a[(npx + i, j)] = dkcp[(i, j)];
            }
            for j in 0..nu {
                a[(npx + i, zd + j)] += dkdp[(i, j)];
            }
            for j in 0..nkx {
                a[(npx + i, ko + j)] = ck[(i, j)];
            }
        }
        // z_q' = z_{q-1}
        for q in 1..d {
            for i in 0..nu {
                a[(npx + q * nu + i, npx + (q - 1) * nu + i)] = 1.0;
            }
        }
        for i in 0..nkx {
            for j in 0..npx {
                a[(ko + i, j)] = bkcp[(i, j)];
            }
            for j in 0..nu {
                a[(ko + i, zd + j)] = bkdp[(i, j)];
            }
            for j in 0..nkx {
                a[(ko + i, ko + j)] = ak[(i, j)];
            }
        }
    }
    let _ = ny;
    let ev = a.eigenvalues().map_err(|e| FrfError::Numerical {
        what: "closed-loop poles (eigenvalues)".into(),
        why: format!("{e:?}"),
    })?;
    let (mut rho, mut arg) = (0.0f64, 0.0f64);
    for z in &ev {
        let m = (z.re * z.re + z.im * z.im).sqrt();
        if m > rho {
            rho = m;
            arg = z.im.atan2(z.re);
        }
    }
    if !rho.is_finite() || rho >= 1.0 - 1e-12 {
        return Err(FrfError::UnstableClosedLoop {
            spectral_radius: rho,
            pole_hz: arg.abs() * fs / std::f64::consts::TAU,
        });
    }
    Ok(rho)
}
