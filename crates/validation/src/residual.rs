//! The residual `E = G - P` of a model against measured data, judged against the noise
//! level: relative errors, the residual-to-noise ratio per line, a calibrated
//! significance test, and the structure of a significant residual that the
//! residual-diagnosis loop of `frfit` (DESIGN.md, "The residual-diagnosis loop") traces
//! to an effect the model lacks.
//!
//! All statistics are in **noise units**: each line `k` and entry `e` contributes
//! `|E_ke|^2 / var_ke`, which is 1 on average when the model is right and `var` is the
//! true variance of the estimate.
//!
//! # The significance test and its calibration
//!
//! The per-line statistic `s_k = sum_e |E_ke|^2 / var_ke` would be `chi2(2m) / 2`
//! (`m = ny nu` independent circular complex Gaussian errors with known variance), and
//! the lines of a periodic-excitation FRF are independent (McKelvey 2002; Pintelon and
//! Schoukens 2012, ch. 2). Measured FRFs break both assumptions: the errors of one line
//! are correlated across entries (a closed-loop or multi-experiment estimate
//! `G = Y U^-1` mixes the experiments' noise into every entry of a row), and the
//! variance is itself an estimate (a sample variance over `R` realizations), which makes
//! `|E|^2 / var` F-distributed, heavier-tailed than Gaussian and biased upwards by
//! `(R - 1) / (R - 2)`. On the reference wafer stage (`wafer_nominal.csv` against its
//! noiseless truth) the mean of `|E|^2 / var` is 1.13 and the per-line statistic
//! spreads like a chi-square with ~60 instead of 104 degrees of freedom.
//!
//! The test therefore models the per-line statistic as a **scaled chi-square**
//! `s_k ~ c chi2(nu)` and calibrates it robustly on the data:
//!
//! 1. *Shape* `nu`: from the median and the median absolute deviation of
//!    `s_k / L_k`, where `L_k` is the running median of `s` over
//!    [`ResidualConfig::local_half_window`] lines or [`ResidualConfig::local_rel`] of the
//!    frequency, whichever is wider. Dividing by the local level removes
//!    any smooth trend of the residual over frequency (which would otherwise pass for
//!    spread), and the median and MAD ignore the lines of localized effects. `nu` solves
//!    `MAD / median = chi2_mad_ratio(nu)` exactly (not the normal approximation) and is
//!    clamped to `[1, 2m]`.
//! 2. *Scale* `c`: from the global median, `c = median(s) / median(chi2(nu))`. The
//!    implied mean noise energy per entry, `kappa = c nu / m` (1 for exact variances), is
//!    allowed up to [`ResidualConfig::max_noise_scale`] (default 1.5: a variance
//!    estimated from `R >= 4` realizations has `E|E|^2/var = (R-1)/(R-2) <= 1.5`; with
//!    3 realizations raise it to 2); above
//!    it, the median line is itself above the noise (a broadband misfit) and `c` is
//!    capped at `max_noise_scale * m / nu`.
//! 3. *Broadband test*: `S = sum_k s_k` against `c chi2(N nu)` (`N` lines), with the
//!    p-value of the upper tail (the chi-square test of the summed statistic against its
//!    effective degrees of freedom), **and** the *level* of the residual: the mean of
//!    the local levels `L_k` over the null median must exceed `1 + min_excess` (default
//!    5 %) with its own p-value below `alpha`. With `N nu ~ 1e5` degrees of freedom the
//!    chi-square test alone flags the heavy tail of measured noise: the mean of `s`
//!    exceeds the mean of the fitted `c chi2(nu)` by 1-3 % with variances from 10 to 30
//!    realizations and by 5 % with 4 (measured on simulated data), because `|E|^2/var`
//!    is F-distributed. Those tail values are isolated lines; the local medians ignore
//!    them, while an effect, coherent over neighbouring lines, raises them.
//! 4. *Localized test*: the median of three neighbouring lines `s3_k` (a missed mode
//!    raises several neighbouring lines; an F-distributed outlier line, whose variance
//!    estimate happened to be small, raises one) must exceed both the Bonferroni
//!    threshold of the calibrated per-line distribution (`P(med3 > x) ~ 3 P(s > x)^2`,
//!    at `alpha / N`) and [`ResidualConfig::peak_over_local`] times its local level
//!    `L_k`.
//!
//! The residual is `significant` when either test fires. The same calibrated scale gives
//! the p-values of the effect signatures ([`crate::signatures`]): a template with `p`
//! real parameters that lowers the noise-unit energy by `Delta` is tested with
//! `Delta / c ~ chi2(p)`, conservative for correlated errors (the worst-case direction
//! of a line's noise carries energy `2c` per complex degree of freedom).

use crate::noise::{NoiseLevel, NoiseSource};
use crate::stats::ScaledChi2;
use crate::stats::{
    chi2_isf, chi2_median, chi2_sf, f_isf, mad, median, normal_sf, quantiles_mut,
    running_median_bounded,
};
use crate::ValidationError;
use frf_data::cmif::PeakConfig;
use frf_data::{FrfDataset, C64};
use rayon::prelude::*;
use realize::ResponseGrid;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Settings of [`crate::analysis::analyze_residual`], with documented defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ResidualConfig {
    /// Significance level of every test (the broadband and localized tests, each effect
    /// signature). Default 0.01.
    pub alpha: f64,
    /// The broadband test also needs the level of the residual (the mean of its local
    /// medians) to exceed the calibrated noise level by this fraction (an effect size;
    /// see the module documentation). Default 0.05: under the null the level ratio
    /// stays within 1 % of 1 on the simulated tests.
    pub min_excess: f64,
    /// Largest mean noise energy per entry (`kappa`, in units of the stated variance)
    /// that the calibration accepts as noise; a median line above it is a broadband
    /// misfit. Default 1.5.
    pub max_noise_scale: f64,
    /// Real degrees of freedom of the variance estimate per entry, `2 (R - 1)` for a
    /// mean over `R` realizations (`None`: treat the variance as known, the default).
    /// With few realizations `|E|^2 / var` is F- rather than chi-square-distributed, with
    /// a much heavier tail: the threshold of the localized test then comes from
    /// `F(nu, variance_dof)`, scaled to the calibrated median, and the largest noise
    /// scale accepted ([`max_noise_scale`](Self::max_noise_scale)) grows by the mean of
    /// `F(., variance_dof)`, `d2 / (d2 - 2)`, so that the spread of an estimated variance
    /// is not called an effect.
    pub variance_dof: Option<f64>,
    /// Smallest `kappa` the calibration uses: a residual far below the stated noise
    /// (a noise-free simulation, an overestimated variance) is calibrated at this
    /// fraction of it, so that its rounding-level structure is not called significant.
    /// Default 0.25.
    pub min_noise_scale: f64,
    /// The local level `L_k` of the per-line statistic is its running median over
    /// `+-local_half_window` lines or `+-local_rel * f_k`, whichever is wider. Default
    /// 25 lines.
    pub local_half_window: usize,
    /// See [`ResidualConfig::local_half_window`]. Default 0.1 (+-10 % in frequency: a
    /// missed mode of relative damping up to ~0.02 then still stands well above the
    /// median of its window, which is what the localized test needs).
    pub local_rel: f64,
    /// A localized excess must rise this many times above the local level, and a
    /// missed mode's relative residual this many times above its surroundings on both
    /// sides. Default 4: on the reference data the largest three-line median of pure
    /// noise reaches 2.5 local levels (at most 2.1, 2.7 and 3.4 over 20 simulated seeds
    /// with exact variances and with variances from 10 and from 4 realizations); a
    /// missed mode of the wafer stage reaches thousands.
    pub peak_over_local: f64,
    /// An effect signature is flagged only when it explains at least this fraction of
    /// the residual's excess energy (the energy above the calibrated noise). Default 0.5:
    /// the flagged effect accounts for most of what the model misses; related templates
    /// explain part of another effect's residual (a hold's droop on a rigid body is a
    /// constant at high frequencies, so the feedthrough template explains 25-30 % of it;
    /// the stiffness template 20-26 % of a delay's or an actuator's residual), and the
    /// loop ranks the candidates by this fraction anyway.
    pub min_explained: f64,
    /// A missed-mode peak must have `height_over_noise` (its singular value squared over
    /// the calibrated noise energy of the whole line) above this. Default 1: the mode's
    /// singular direction alone carries more than all the noise of the line (noise alone
    /// gives 0.3-0.6 for sigma_1 of a 3 x 4 or 4 x 13 matrix, also at the lines of
    /// heavy-tailed outliers).
    pub min_peak_height: f64,
    /// The CMIF peak picker run on the residual (see
    /// [`crate::signatures::residual_peaks`]). Default: [`PeakConfig::default`].
    pub peak: PeakConfig,
    /// At most this many residual CMIF peaks are reported (the highest). Default 10.
    pub max_peaks: usize,
    /// Sample rate of the measurement, Hz, when known: [`crate::analysis::analyze_residual`] then
    /// evaluates the zero-order-hold signature ([`hold_signature`]). Default `None`.
    pub sample_rate_hz: Option<f64>,
    /// Variances are floored at this fraction of their entry's median over lines, so
    /// that a zero variance does not make one line infinitely heavy. Default 1e-6 (as in
    /// `frf_data::Weighting::InverseVariance`).
    pub variance_floor: f64,
}

impl Default for ResidualConfig {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            min_excess: 0.05,
            max_noise_scale: 1.5,
            min_noise_scale: 0.25,
            variance_dof: None,
            local_half_window: 25,
            local_rel: 0.1,
            peak_over_local: 4.0,
            min_explained: 0.5,
            min_peak_height: 1.0,
            peak: PeakConfig::default(),
            max_peaks: 10,
            sample_rate_hz: None,
            variance_floor: 1e-6,
        }
    }
}

impl ResidualConfig {
    fn check(&self) -> Result<(), ValidationError> {
        let bad = |name: &str, v: f64, why: &str| Err(ValidationError::config(name, v, why));
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return bad("alpha", self.alpha, "must be in (0, 1)");
        }
        if !(self.min_excess >= 0.0 && self.min_excess.is_finite()) {
            return bad("min_excess", self.min_excess, "must be finite and >= 0");
        }
        if let Some(d) = self.variance_dof {
            if !(d > 2.0 && d.is_finite()) {
                return bad(
                    "variance_dof",
                    d,
                    "must be finite and > 2 (at least 3 realizations)",
                );
            }
        }
        if !(self.min_noise_scale > 0.0 && self.min_noise_scale <= 1.0) {
            return bad("min_noise_scale", self.min_noise_scale, "must be in (0, 1]");
        }
        if !(self.max_noise_scale >= 1.0 && self.max_noise_scale.is_finite()) {
            return bad(
                "max_noise_scale",
                self.max_noise_scale,
                "must be finite and >= 1",
            );
        }
        if self.local_half_window == 0 {
            return bad("local_half_window", 0.0, "must be at least 1 line");
        }
        if !(self.local_rel >= 0.0 && self.local_rel < 1.0) {
            return bad("local_rel", self.local_rel, "must be in [0, 1)");
        }
        if !(self.peak_over_local >= 1.0 && self.peak_over_local.is_finite()) {
            return bad(
                "peak_over_local",
                self.peak_over_local,
                "must be finite and >= 1",
            );
        }
        if !(self.min_peak_height >= 0.0 && self.min_peak_height.is_finite()) {
            return bad(
                "min_peak_height",
                self.min_peak_height,
                "must be finite and >= 0",
            );
        }
        if !(0.0..=1.0).contains(&self.min_explained) {
            return bad("min_explained", self.min_explained, "must be in [0, 1]");
        }
        if let Some(fs) = self.sample_rate_hz {
            if !(fs.is_finite() && fs > 0.0) {
                return bad("sample_rate_hz", fs, "must be finite and > 0");
            }
        }
        if !(self.variance_floor >= 0.0 && self.variance_floor < 1.0) {
            return bad("variance_floor", self.variance_floor, "must be in [0, 1)");
        }
        Ok(())
    }
}

/// The calibrated significance test of a residual (see the module documentation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Significance {
    /// `S = sum_k sum_e |E_ke|^2 / var_ke`.
    pub statistic: f64,
    /// Number of complex observations `N m`.
    pub n_observations: usize,
    /// Nominal degrees of freedom `2 N m` (independent entries, exact variances).
    pub nominal_dof: f64,
    /// Calibrated degrees of freedom per line, `nu`.
    pub line_dof: f64,
    /// Calibrated scale per line, `c` (`s_k ~ c chi2(nu)`).
    pub line_scale: f64,
    /// Effective degrees of freedom of the broadband test, `N nu`.
    pub effective_dof: f64,
    /// The measured mean noise energy per entry implied by the median line,
    /// `c0 nu / m` before capping (1 for exact variances, ~1.13 for a variance from 10
    /// realizations).
    pub noise_scale: f64,
    /// True when `noise_scale` exceeded [`ResidualConfig::max_noise_scale`] and the
    /// scale was capped (the median line is above the noise: a broadband misfit).
    pub noise_scale_capped: bool,
    /// `S / (c N nu)`: the residual energy over the calibrated noise energy (1 at the
    /// noise level).
    pub excess_ratio: f64,
    /// Upper-tail p-value of `S / c` under `chi2(N nu)`: the chi-square test of the
    /// summed statistic against its (effective) degrees of freedom.
    pub p_value: f64,
    /// The level of the residual: the mean over lines of the local level `L_k` (running
    /// median of `s`) over the calibrated null median `c median(chi2(nu))`; 1 at the
    /// noise level. Unlike `excess_ratio` it ignores the heavy tail of the noise (lines
    /// whose variance estimate happened to be small are isolated, effects are coherent
    /// over neighbouring lines).
    pub level_ratio: f64,
    /// Upper-tail p-value of `level_ratio` (normal, null standard deviation
    /// `sqrt(pi / (2 N)) c sqrt(2 nu) / (c median(chi2(nu)))`).
    pub level_p_value: f64,
    /// The broadband test: `p_value < alpha`, `level_p_value < alpha` and
    /// `level_ratio > 1 + min_excess`.
    pub broadband: bool,
    /// The localized test: at least one line passes (see the module documentation).
    pub localized: bool,
    /// Number of lines that pass the localized test.
    pub localized_lines: usize,
    /// The per-line threshold of the localized test from the calibrated distribution
    /// (before the `peak_over_local` condition), in noise units per line.
    pub localized_threshold: f64,
    /// `broadband || localized`.
    pub significant: bool,
}

/// Where the residual-to-noise ratio is elevated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrendClass {
    /// The residual is not significant.
    NoiseLevel,
    /// Most of the excess energy sits in narrow peaks (missed modes).
    Localized,
    /// Elevated at low frequencies: a stiffness instead of a free rigid body, an
    /// integrator or low-frequency gain mismatch.
    LowFrequency,
    /// Elevated at high frequencies: a hold's droop, feedthrough, actuator or sensor
    /// dynamics, a delay.
    HighFrequency,
    /// Elevated across the band without a clear trend.
    Broadband,
}

/// The magnitude trend of the residual over frequency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MagnitudeTrend {
    /// The classification (see [`TrendClass`]).
    pub class: TrendClass,
    /// Slope of `log10` of the (locally median-smoothed) residual-to-noise amplitude
    /// ratio against `log10 f`, each decade weighted equally: +1 when the ratio grows
    /// tenfold per decade.
    #[serde(with = "crate::serde_f64")]
    pub slope_per_decade: f64,
    /// Calibrated residual-to-noise amplitude ratio `sqrt(mean s_k / (c nu))` over the
    /// lowest third of the band in log frequency (at least 5 lines).
    #[serde(with = "crate::serde_f64")]
    pub low_ratio: f64,
    /// The same over the middle third.
    #[serde(with = "crate::serde_f64")]
    pub mid_ratio: f64,
    /// The same over the highest third.
    #[serde(with = "crate::serde_f64")]
    pub high_ratio: f64,
    /// `[lo, hi]` Hz of the low segment.
    pub low_band_hz: (f64, f64),
    /// `[lo, hi]` Hz of the high segment.
    pub high_band_hz: (f64, f64),
    /// Fraction of the excess energy in localized peaks of the relative residual (the
    /// regions of the localized test, the lines of the test and their elevated
    /// neighbours, above the local level, that hold a peak of the relative residual:
    /// see [`Residual::relative_rise`]; a smooth factor's residual at the model's own
    /// resonances does not count, nor does a region that reaches the first or last line,
    /// which is the end of a trend rather than a peak).
    pub localized_fraction: f64,
}

/// How the excess residual energy (noise units, above the calibrated noise) is shared
/// among output rows and input columns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Concentration {
    /// Share of the excess energy per output row (sums to 1 when there is excess).
    pub row_fraction: Vec<f64>,
    /// Share of the excess energy per input column.
    pub col_fraction: Vec<f64>,
    /// The output row (0-based) that holds much more than its share, when the residual
    /// is significant: more than halfway from an equal share to all of it,
    /// `fraction > (1 + 1/ny) / 2` (0.625 for 4 rows, 0.75 for 2). A row factor (sensor
    /// dynamics) puts nearly all the excess in its row; a common effect (delay, hold)
    /// spreads it by the rows' signal-to-noise ratios, which rarely gives one row that
    /// much. `None` with a single row.
    pub dominant_row: Option<usize>,
    /// The input column that holds much more than its share (the same rule with `nu`).
    pub dominant_col: Option<usize>,
}

/// The residual `E = G - P` with its noise weights and calibrated null distribution: the
/// common input of [`crate::analysis::analyze_residual`] and of the signature functions of
/// [`crate::signatures`] (build it once with [`Residual::new`], then test any effect).
#[derive(Debug, Clone)]
pub struct Residual {
    pub(crate) freq_hz: Vec<f64>,
    pub(crate) omega: Vec<f64>,
    pub(crate) ny: usize,
    pub(crate) nu: usize,
    pub(crate) data: Vec<C64>,
    pub(crate) model: Vec<C64>,
    pub(crate) error: Vec<C64>,
    /// `1 / var` (floored variance).
    pub(crate) weight: Vec<f64>,
    /// `s_k`.
    pub(crate) line_stat: Vec<f64>,
    /// Running median of `s_k`.
    pub(crate) local_level: Vec<f64>,
    /// The window of the local level of each line, `lo[k]..hi[k]`.
    pub(crate) window: (Vec<usize>, Vec<usize>),
    /// The relative residual per line, `sum_e |E|^2 / var / sum_e |P|^2 / var`.
    pub(crate) rho: Vec<f64>,
    /// Lines that pass the localized test.
    pub(crate) localized: Vec<bool>,
    pub(crate) null: ScaledChi2,
    pub(crate) significance: Significance,
    pub(crate) cfg: ResidualConfig,
    pub(crate) source: NoiseSource,
}

impl Residual {
    /// Builds the residual of `model` (the model's response at the data's lines, layout
    /// of [`ResponseGrid`]) against `data` with the noise level `noise`, and calibrates
    /// the significance test.
    ///
    /// Errors: dimensions of data, model and noise that disagree (the message says which
    /// and how); fewer than 3 lines; non-finite values; a variance that is zero for every
    /// line of an entry; an invalid configuration.
    pub fn new(
        data: &(impl FrfDataset + ?Sized),
        model: &ResponseGrid,
        noise: &NoiseLevel,
        cfg: &ResidualConfig,
    ) -> Result<Self, ValidationError> {
        cfg.check()?;
        check_model(data, model)?;
        noise.check_against(data)?;
        let (n, ny, nu) = (data.n_lines(), data.ny(), data.nu());
        let m = ny * nu;
        if n < 3 {
            return Err(ValidationError::TooFewLines {
                what: "residual analysis".into(),
                needed: 3,
                got: n,
            });
        }
        let freq_hz = data.freqs_hz();
        if let Some(k) = freq_hz.iter().position(|f| !f.is_finite()) {
            return Err(ValidationError::invalid_input(
                "data",
                format!("frequency of line {k} is not finite"),
            ));
        }
        let values = data.values_vec();
        if let Some(idx) = values
            .iter()
            .position(|z| !(z.re.is_finite() && z.im.is_finite()))
        {
            return Err(ValidationError::invalid_input(
                "data",
                format!(
                    "non-finite value at line {} ({} Hz), entry {}",
                    idx / m,
                    freq_hz[idx / m],
                    entry_name(idx % m, ny)
                ),
            ));
        }
        let weight = floored_weights(&noise.variance, n, m, ny, cfg.variance_floor)?;
        let error: Vec<C64> = values
            .par_iter()
            .zip(&model.values)
            .map(|(g, p)| g - p)
            .collect();
        let line_stat: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|k| {
                (0..m)
                    .map(|e| error[k * m + e].norm_sqr() * weight[k * m + e])
                    .sum()
            })
            .collect();
        let omega = freq_hz.iter().map(|f| TAU * f).collect();
        let window = local_window(&freq_hz, cfg);
        let local_level = running_median_bounded(&line_stat, &window.0, &window.1);
        let rho: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|k| {
                let pp: f64 = (k * m..(k + 1) * m)
                    .map(|i| model.values[i].norm_sqr() * weight[i])
                    .sum();
                if pp > 0.0 {
                    line_stat[k] / pp
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        let (null, significance, localized) = calibrate(&line_stat, &local_level, m, cfg);
        Ok(Self {
            freq_hz,
            omega,
            ny,
            nu,
            data: values,
            model: model.values.clone(),
            error,
            weight,
            line_stat,
            local_level,
            window,
            rho,
            localized,
            null,
            significance,
            cfg: cfg.clone(),
            source: noise.source.clone(),
        })
    }

    /// Number of lines.
    pub fn n_lines(&self) -> usize {
        self.freq_hz.len()
    }
    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of inputs.
    pub fn nu(&self) -> usize {
        self.nu
    }
    /// Frequencies, Hz.
    pub fn freq_hz(&self) -> &[f64] {
        &self.freq_hz
    }
    /// The data `G`, layout of [`ResponseGrid`].
    pub fn data(&self) -> &[C64] {
        &self.data
    }
    /// The model's response `P`, layout of [`ResponseGrid`].
    pub fn model(&self) -> &[C64] {
        &self.model
    }
    /// The residual `E = G - P`, layout of [`ResponseGrid`].
    pub fn error(&self) -> &[C64] {
        &self.error
    }
    /// The per-line statistic `s_k = sum_e |E_ke|^2 / var_ke`.
    pub fn line_statistic(&self) -> &[f64] {
        &self.line_stat
    }
    /// The local level `L_k` of the per-line statistic (its running median over the
    /// window of [`ResidualConfig::local_half_window`] and
    /// [`ResidualConfig::local_rel`]).
    pub fn local_level(&self) -> &[f64] {
        &self.local_level
    }
    /// The calibrated significance test.
    pub fn significance(&self) -> &Significance {
        &self.significance
    }
    /// The calibrated per-line null distribution `c chi2(nu)`: `(c, nu)`.
    pub fn line_null(&self) -> (f64, f64) {
        (self.null.c, self.null.nu)
    }
    /// The configuration the residual was built with.
    pub fn config(&self) -> &ResidualConfig {
        &self.cfg
    }
    /// The residual energy above the calibrated noise energy, `S - c N nu` (noise
    /// units; 0 when the residual is at or below the noise).
    pub fn excess_energy(&self) -> f64 {
        let s: f64 = self.line_stat.iter().sum();
        (s - self.null.mean() * self.n_lines() as f64).max(0.0)
    }
    /// The two-sided relative rise at line `k`: the relative residual
    /// `rho_k = sum_e |E|^2 / var / sum_e |P|^2 / var` over the median of `rho` on each
    /// side of `k` within its local window, the smaller of the two (0 when a side has
    /// fewer than 3 lines). A missed mode is a resonance of `E` that `P` does not share,
    /// so `rho` falls on both sides of it (rise >> 1); the residual of a smooth factor the
    /// model lacks (a delay, a hold, actuator dynamics) peaks at the model's own
    /// resonances with `rho` smooth (rise ~ 1), and a low-frequency trend (a stiffness)
    /// does not fall towards the band edge.
    pub fn relative_rise(&self, k: usize) -> f64 {
        if k >= self.n_lines() {
            return 0.0;
        }
        let (lo, hi) = (self.window.0[k], self.window.1[k]);
        if k < lo + 3 || hi < k + 4 {
            return 0.0;
        }
        let left = median(&self.rho[lo..k]);
        let right = median(&self.rho[k + 1..hi]);
        let side = left.max(right);
        if side > 0.0 {
            self.rho[k] / side
        } else if self.rho[k] > 0.0 {
            f64::INFINITY
        } else {
            0.0
        }
    }

    /// The calibrated mean noise energy of one entry of one line (`c nu / m`).
    pub fn entry_noise_energy(&self) -> f64 {
        self.null.mean() / (self.ny * self.nu) as f64
    }
}

/// The window of the local level of each line: `+-half_window` lines or `+-rel f_k`,
/// whichever is wider (bounds non-decreasing in `k`).
fn local_window(f: &[f64], cfg: &ResidualConfig) -> (Vec<usize>, Vec<usize>) {
    let n = f.len();
    let h = cfg.local_half_window;
    let lo: Vec<usize> = (0..n)
        .map(|k| {
            let by_f = f.partition_point(|x| *x < f[k] * (1.0 - cfg.local_rel));
            k.saturating_sub(h).min(by_f)
        })
        .collect();
    let hi: Vec<usize> = (0..n)
        .map(|k| {
            let by_f = f.partition_point(|x| *x <= f[k] * (1.0 + cfg.local_rel));
            (k + h + 1).min(n).max(by_f).max(k + 1)
        })
        .collect();
    (lo, hi)
}

/// Name of entry `e` (`vec` order) as `G{out}_{in}`, 1-based.
pub(crate) fn entry_name(e: usize, ny: usize) -> String {
    format!("G{}_{}", e % ny + 1, e / ny + 1)
}

fn check_model(
    data: &(impl FrfDataset + ?Sized),
    model: &ResponseGrid,
) -> Result<(), ValidationError> {
    if model.ny != data.ny() || model.nu != data.nu() {
        return Err(ValidationError::dimension(
            "model response vs data (outputs x inputs)",
            format!("{}x{} (data)", data.ny(), data.nu()),
            format!("{}x{} (model)", model.ny, model.nu),
        ));
    }
    let m = data.n_entries();
    if model.values.len() != data.n_lines() * m {
        return Err(ValidationError::dimension(
            "model response vs data (lines)",
            format!("{} lines (data)", data.n_lines()),
            format!(
                "{} values = {} lines of {}x{} (model)",
                model.values.len(),
                model.values.len() as f64 / m.max(1) as f64,
                model.ny,
                model.nu
            ),
        ));
    }
    if let Some(idx) = model
        .values
        .iter()
        .position(|z| !(z.re.is_finite() && z.im.is_finite()))
    {
        return Err(ValidationError::invalid_input(
            "model response",
            format!(
                "non-finite value at line {} ({} Hz), entry {}",
                idx / m,
                data.freq_hz(idx / m),
                entry_name(idx % m, data.ny())
            ),
        ));
    }
    Ok(())
}

/// `1 / max(var, floor_e)` with `floor_e = rel * median_k var_ke`; fails when an entry's
/// variance is zero at every line.
fn floored_weights(
    var: &[f64],
    n: usize,
    m: usize,
    ny: usize,
    rel: f64,
) -> Result<Vec<f64>, ValidationError> {
    // the median and maximum of every entry's variances: blocks of entries in parallel,
    // each gathering its columns line after line (contiguous reads)
    const BLOCK: usize = 8;
    let stats: Vec<(f64, f64)> = (0..m.div_ceil(BLOCK))
        .into_par_iter()
        .flat_map_iter(|b| {
            let (e0, nb) = (b * BLOCK, BLOCK.min(m - b * BLOCK));
            let mut cols = vec![0.0; nb * n];
            for k in 0..n {
                for eb in 0..nb {
                    cols[eb * n + k] = var[k * m + e0 + eb];
                }
            }
            cols.chunks_mut(n.max(1))
                .map(|col| {
                    let max = col.iter().copied().fold(0.0, f64::max);
                    (crate::stats::median_mut(col), max)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let mut floors = vec![0.0; m];
    for (e, (fl, &(med, max))) in floors.iter_mut().zip(&stats).enumerate() {
        if max <= 0.0 {
            return Err(ValidationError::invalid_input(
                "noise level",
                format!(
                    "the variance of entry {} is zero at every line: the residual cannot be \
                     compared with the noise (give the data _var columns or estimate the noise)",
                    entry_name(e, ny)
                ),
            ));
        }
        // With a zero median, floor relative to the largest variance instead.
        *fl = if med > 0.0 { rel * med } else { rel * max };
    }
    let mut w = vec![0.0; var.len()];
    w.par_chunks_mut(m.max(1))
        .zip(var.par_chunks(m.max(1)))
        .for_each(|(w, v)| {
            for ((w, v), fl) in w.iter_mut().zip(v).zip(&floors) {
                *w = 1.0 / v.max(*fl).max(f64::MIN_POSITIVE);
            }
        });
    Ok(w)
}

/// The calibration and the two tests of the module documentation. Returns the null
/// distribution, the test results and the lines that pass the localized test.
fn calibrate(
    s: &[f64],
    local: &[f64],
    m: usize,
    cfg: &ResidualConfig,
) -> (ScaledChi2, Significance, Vec<bool>) {
    let n = s.len();
    let nu_max = 2.0 * m as f64;
    // 1. Shape from the ratios to the local level.
    let ratios: Vec<f64> = s
        .iter()
        .zip(local)
        .filter(|(_, l)| **l > 0.0)
        .map(|(x, l)| x / l)
        .collect();
    let rmed = median(&ratios);
    let rmad = mad(&ratios, rmed);
    let nu = ScaledChi2::from_median_mad(rmed, rmad, 1.0, nu_max)
        .map(|f| f.nu)
        .unwrap_or(nu_max);
    // 2. Scale from the global median, capped.
    let smed = median(s);
    let c0 = if smed > 0.0 {
        smed / chi2_median(nu)
    } else {
        // A residual that is exactly zero on most lines: nominal scale.
        0.5
    };
    let kappa = c0 * nu / m as f64;
    // an estimated variance inflates the mean noise energy by d2 / (d2 - 2) (the mean
    // of F(., d2)): the cap follows
    let max_scale = cfg.max_noise_scale * cfg.variance_dof.map_or(1.0, |d| d / (d - 2.0));
    let capped = kappa > max_scale;
    let c = if capped {
        max_scale * m as f64 / nu
    } else if kappa < cfg.min_noise_scale {
        cfg.min_noise_scale * m as f64 / nu
    } else {
        c0
    };
    let null = ScaledChi2 { c, nu };
    // 3. Broadband test.
    let total: f64 = s.iter().sum();
    let dof = n as f64 * nu;
    let p_value = chi2_sf(total / c, dof);
    let excess_ratio = total / (c * dof);
    // The level of the residual: mean of the local medians over the null median. Heavy
    // tails of the noise (independent from line to line) barely move local medians, an
    // effect (coherent over neighbouring lines) does. Null standard deviation: the mean
    // of N local medians of windows of W lines, each with variance (pi/2) var(s) / W and
    // correlated over W lines, has variance (pi/2) var(s) / N.
    let null_median = c * chi2_median(nu);
    let level_ratio = local.iter().sum::<f64>() / n as f64 / null_median;
    let level_sd =
        (std::f64::consts::FRAC_PI_2 / n as f64).sqrt() * c * (2.0 * nu).sqrt() / null_median;
    let level_p_value = normal_sf((level_ratio - 1.0) / level_sd);
    let broadband =
        p_value < cfg.alpha && level_p_value < cfg.alpha && level_ratio > 1.0 + cfg.min_excess;
    // 4. Localized test on the three-line median.
    let p3 = (cfg.alpha / (3.0 * n as f64)).sqrt();
    let thr = match cfg.variance_dof {
        None => c * chi2_isf(p3, nu),
        // the same median, the tail of F(nu, d2)
        Some(d2) => c * chi2_median(nu) * f_isf(p3, nu, d2) / f_isf(0.5, nu, d2),
    };
    let mut localized = vec![false; n];
    for k in 0..n {
        let a = k.saturating_sub(1);
        let b = (k + 2).min(n);
        let mut w = [0.0; 3];
        let len = b - a;
        w[..len].copy_from_slice(&s[a..b]);
        let s3 = median(&w[..len]);
        localized[k] = s3 > thr && s3 > cfg.peak_over_local * local[k];
    }
    let localized_lines = localized.iter().filter(|x| **x).count();
    let significance = Significance {
        statistic: total,
        n_observations: n * m,
        nominal_dof: 2.0 * (n * m) as f64,
        line_dof: nu,
        line_scale: c,
        effective_dof: dof,
        noise_scale: kappa,
        noise_scale_capped: capped,
        excess_ratio,
        p_value,
        level_ratio,
        level_p_value,
        broadband,
        localized: localized_lines > 0,
        localized_lines,
        localized_threshold: thr,
        significant: broadband || localized_lines > 0,
    };
    (null, significance, localized)
}

/// Median and 95th percentile of the relative error `|G - P| / |G|` over all lines and
/// entries of `data` (entries with `G = 0` are skipped): the error measure of the
/// diagnosis loop's before/after table (DESIGN.md).
///
/// Errors: the model's dimensions or number of lines disagree with the data; no entry
/// with `G != 0`.
pub fn relative_error_stats(
    data: &(impl FrfDataset + ?Sized),
    model: &ResponseGrid,
) -> Result<(f64, f64), ValidationError> {
    check_model(data, model)?;
    rel_stats(&data.values_vec(), &model.values)
}

pub(crate) fn rel_stats(data: &[C64], model: &[C64]) -> Result<(f64, f64), ValidationError> {
    // Squared ratios (no square roots per entry; quantiles commute with sqrt).
    let mut rel: Vec<f64> = data
        .iter()
        .zip(model)
        .filter_map(|(g, p)| {
            let a = g.norm_sqr();
            (a > 0.0 && a.is_finite()).then(|| (g - p).norm_sqr() / a)
        })
        .collect();
    if rel.is_empty() {
        return Err(ValidationError::invalid_input(
            "data",
            "no line and entry with a non-zero response: the relative error is undefined",
        ));
    }
    let q = quantiles_mut(&mut rel, &[0.5, 0.95]);
    Ok((q[0].sqrt(), q[1].sqrt()))
}

/// The magnitude trend of the residual (see [`MagnitudeTrend`]): segment ratios over the
/// lowest, middle and highest third of the band in log frequency (each at least 5 lines),
/// the slope of the locally smoothed log ratio against log frequency with each decade
/// weighted equally (the weight of a line is its share of `log f`), and the fraction of
/// the excess energy in localized peaks.
///
/// Classification, in order: not significant -> `NoiseLevel`; more than half of the
/// excess in localized peaks -> `Localized`; the high segment's ratio at least twice
/// the low segment's (four times the energy) with a positive slope -> `HighFrequency`;
/// the converse -> `LowFrequency`; otherwise `Broadband`.
pub fn magnitude_trend(res: &Residual) -> MagnitudeTrend {
    let n = res.n_lines();
    let f = &res.freq_hz;
    let mu = res.null.mean();
    // Segments in log frequency (lines with f <= 0 go to the low segment).
    let fpos: Vec<f64> = f.iter().copied().filter(|x| *x > 0.0).collect();
    let (lf_lo, lf_hi) = match (fpos.first(), fpos.last()) {
        (Some(a), Some(b)) => (a.log10(), b.log10()),
        _ => (0.0, 0.0),
    };
    let third = (lf_hi - lf_lo) / 3.0;
    let min_lines = 5.min(n);
    let mut low_end = f.partition_point(|x| *x <= 0.0 || x.log10() < lf_lo + third);
    low_end = low_end.max(min_lines).min(n);
    let mut high_start = f.partition_point(|x| *x <= 0.0 || x.log10() < lf_hi - third);
    high_start = high_start.min(n.saturating_sub(min_lines));
    let seg_ratio = |a: usize, b: usize| -> f64 {
        if b <= a {
            return f64::NAN;
        }
        let s: f64 = res.line_stat[a..b].iter().sum();
        (s / ((b - a) as f64 * mu)).sqrt()
    };
    let low_ratio = seg_ratio(0, low_end);
    let high_ratio = seg_ratio(high_start, n);
    let mid_ratio = if high_start > low_end {
        seg_ratio(low_end, high_start)
    } else {
        f64::NAN
    };
    // Slope of log10 sqrt(L_k / mu) against log10 f, weights = share of log f.
    let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        if f[k] <= 0.0 || res.local_level[k] <= 0.0 {
            continue;
        }
        let lo = if k > 0 && f[k - 1] > 0.0 {
            f[k - 1]
        } else {
            f[k]
        };
        let hi = if k + 1 < n { f[k + 1] } else { f[k] };
        let w = if hi > lo {
            0.5 * (hi / lo).log10()
        } else {
            1e-12
        };
        let x = f[k].log10();
        let y = 0.5 * (res.local_level[k] / mu).log10();
        sw += w;
        sx += w * x;
        sy += w * y;
        sxx += w * x * x;
        sxy += w * x * y;
    }
    let den = sw * sxx - sx * sx;
    let slope = if den > 0.0 && sw > 0.0 {
        (sw * sxy - sx * sy) / den
    } else {
        0.0
    };
    let localized_fraction = localized_fraction(res);
    let class = if !res.significance.significant {
        TrendClass::NoiseLevel
    } else if localized_fraction > 0.5 {
        TrendClass::Localized
    } else if high_ratio >= 2.0 * low_ratio && slope > 0.0 {
        TrendClass::HighFrequency
    } else if low_ratio >= 2.0 * high_ratio && slope < 0.0 {
        TrendClass::LowFrequency
    } else {
        TrendClass::Broadband
    };
    let band = |a: usize, b: usize| -> (f64, f64) {
        if b > a {
            (f[a], f[b - 1])
        } else {
            (f64::NAN, f64::NAN)
        }
    };
    MagnitudeTrend {
        class,
        slope_per_decade: slope,
        low_ratio,
        mid_ratio,
        high_ratio,
        low_band_hz: band(0, low_end),
        high_band_hz: band(high_start, n),
        localized_fraction,
    }
}

/// The regions of localized excess: every line of the localized test, grown on both
/// sides while the line statistic stays above twice the local level.
pub(crate) fn localized_regions(res: &Residual) -> Vec<std::ops::Range<usize>> {
    let n = res.n_lines();
    let mut out: Vec<std::ops::Range<usize>> = Vec::new();
    let mut k = 0;
    while k < n {
        if !res.localized[k] {
            k += 1;
            continue;
        }
        let mut a = k;
        while a > 0 && res.line_stat[a - 1] > 2.0 * res.local_level[a - 1] {
            a -= 1;
        }
        let mut b = k + 1;
        while b < n && (res.localized[b] || res.line_stat[b] > 2.0 * res.local_level[b]) {
            b += 1;
        }
        match out.last_mut() {
            Some(last) if a <= last.end => last.end = last.end.max(b),
            _ => out.push(a..b),
        }
        k = b;
    }
    out
}

/// Excess energy above the local level within `range`, as a fraction of the total
/// excess energy.
pub(crate) fn region_excess_fraction(res: &Residual, range: std::ops::Range<usize>) -> f64 {
    let total = res.excess_energy();
    if total <= 0.0 {
        return 0.0;
    }
    let e: f64 = range
        .map(|k| (res.line_stat[k] - res.local_level[k]).max(0.0))
        .sum();
    (e / total).min(1.0)
}

/// True when the region holds a line whose two-sided relative rise
/// ([`Residual::relative_rise`]) reaches `peak_over_local`: a peak of the relative
/// residual, not a resonance of the model seen through a smooth factor.
pub(crate) fn is_relative_peak(res: &Residual, range: std::ops::Range<usize>) -> bool {
    let k = range
        .clone()
        .max_by(|a, b| res.rho[*a].total_cmp(&res.rho[*b]))
        .unwrap_or(range.start);
    res.relative_rise(k) >= res.cfg.peak_over_local
}

fn localized_fraction(res: &Residual) -> f64 {
    let n = res.n_lines();
    let s = localized_regions(res)
        .into_iter()
        .filter(|r| r.start > 0 && r.end < n && is_relative_peak(res, r.clone()))
        .map(|r| region_excess_fraction(res, r))
        .sum::<f64>();
    // (An empty f64 sum is -0.0.)
    if s > 0.0 {
        s.min(1.0)
    } else {
        0.0
    }
}

/// The concentration of the excess energy in output rows and input columns (see
/// [`Concentration`]). The excess of a row is its noise-unit energy minus the calibrated
/// noise energy of its entries, floored at 0; without any excess the shares are those
/// of the total energy.
pub fn concentration(res: &Residual) -> Concentration {
    let (n, ny, nu) = (res.n_lines(), res.ny, res.nu);
    let m = ny * nu;
    let mut ent = vec![0.0; m];
    for k in 0..n {
        for e in 0..m {
            ent[e] += res.error[k * m + e].norm_sqr() * res.weight[k * m + e];
        }
    }
    let noise_e = res.entry_noise_energy() * n as f64;
    let mut rows = vec![0.0; ny];
    let mut cols = vec![0.0; nu];
    let mut rows_t = vec![0.0; ny];
    let mut cols_t = vec![0.0; nu];
    for (e, v) in ent.iter().enumerate() {
        rows_t[e % ny] += v;
        cols_t[e / ny] += v;
    }
    for i in 0..ny {
        rows[i] = (rows_t[i] - noise_e * nu as f64).max(0.0);
    }
    for j in 0..nu {
        cols[j] = (cols_t[j] - noise_e * ny as f64).max(0.0);
    }
    let share = |x: &[f64], t: &[f64]| -> Vec<f64> {
        let s: f64 = x.iter().sum();
        let st: f64 = t.iter().sum();
        if s > 0.0 {
            x.iter().map(|v| v / s).collect()
        } else if st > 0.0 {
            t.iter().map(|v| v / st).collect()
        } else {
            vec![1.0 / x.len() as f64; x.len()]
        }
    };
    let row_fraction = share(&rows, &rows_t);
    let col_fraction = share(&cols, &cols_t);
    let dominant = |fr: &[f64]| -> Option<usize> {
        let k = fr.len();
        if k < 2 || !res.significance.significant {
            return None;
        }
        let thr = 0.5 * (1.0 + 1.0 / k as f64);
        fr.iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .filter(|(_, v)| **v > thr)
            .map(|(i, _)| i)
    };
    Concentration {
        dominant_row: dominant(&row_fraction),
        dominant_col: dominant(&col_fraction),
        row_fraction,
        col_fraction,
    }
}
