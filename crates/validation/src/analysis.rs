//! The analysis of a residual for the diagnosis loop: the effect catalogue's evidence
//! ([`Effect`], [`EffectEvidence`]) and [`analyze_residual`], which builds the
//! [`Residual`] of [`crate::residual`] once and tests every signature of
//! [`crate::signatures`] on it. The residual and its calibrated test live in
//! [`crate::residual`], the signatures in [`crate::signatures`]; this module is the one
//! that combines them.

use crate::noise::{NoiseLevel, NoiseSource};
use crate::residual::{
    concentration, magnitude_trend, rel_stats, Concentration, MagnitudeTrend, Residual,
    ResidualConfig, Significance,
};
use crate::signatures::{
    common_factor, feedthrough_signature, hold_signature, io_factors, phase_trend, residual_peaks,
    stiffness_signature, FeedthroughSignature, HoldSignature, IoFactor, PhaseTrend, ResidualPeak,
    StiffnessSignature,
};
use crate::ValidationError;
use frf_data::FrfDataset;
use realize::ResponseGrid;
use serde::{Deserialize, Serialize};

/// An effect of the diagnosis loop's catalogue (the names of `summary.json`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// A mode the model lacks (a peak of the residual's CMIF).
    MissedMode,
    /// An uncompensated delay (a linear phase trend).
    Delay,
    /// The zero-order hold of a sampled measurement.
    Hold,
    /// A constant feedthrough / crosstalk.
    Feedthrough,
    /// A stiffness instead of a free rigid body.
    Stiffness,
    /// Dynamics common to one input column.
    InputDynamics,
    /// Dynamics common to one output row.
    OutputDynamics,
}

/// The evidence for one effect, for ranking candidates in the diagnosis loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectEvidence {
    /// The effect.
    pub effect: Effect,
    /// Fraction of the excess energy its signature explains, `[0, 1]`.
    pub explained_fraction: f64,
    /// Whether its signature is flagged.
    pub significant: bool,
    /// One line for a report: the estimated parameters.
    pub detail: String,
}

/// The result of [`analyze_residual`]. Serializable for `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualAnalysis {
    /// Number of lines.
    pub n_lines: usize,
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// Where the noise level came from.
    pub noise_source: NoiseSource,
    /// Median over lines and entries of `|E| / |G|` (entries with `G = 0` skipped).
    #[serde(with = "crate::serde_f64")]
    pub median_rel: f64,
    /// 95th percentile of `|E| / |G|`.
    #[serde(with = "crate::serde_f64")]
    pub p95_rel: f64,
    /// Median over lines and entries of `sqrt(var) / |G|`: the data's own relative noise
    /// level (the yardstick for `median_rel`).
    #[serde(with = "crate::serde_f64")]
    pub median_noise_rel: f64,
    /// `sqrt(mean over lines and entries of |E|^2 / var)`: 1 at the noise level (about
    /// 1.06 for a variance estimated from 10 realizations).
    pub residual_to_noise: f64,
    /// Per line, `sqrt(mean over entries of |E|^2 / var)`.
    pub per_line_ratio: Vec<f64>,
    /// Frequencies of the lines, Hz (for plotting `per_line_ratio`).
    pub freq_hz: Vec<f64>,
    /// The calibrated significance test.
    pub significance: Significance,
    /// `significance.significant`.
    pub significant: bool,
    /// Peaks of the CMIF of the noise-whitened residual (missed modes), highest first.
    pub residual_cmif: Vec<ResidualPeak>,
    /// The delay signature.
    pub phase_trend: PhaseTrend,
    /// Where the ratio is elevated.
    pub magnitude_trend: MagnitudeTrend,
    /// Rows and columns.
    pub concentration: Concentration,
    /// Zero-order-hold signature, when [`ResidualConfig::sample_rate_hz`] is set.
    pub hold: Option<HoldSignature>,
    /// Constant-feedthrough signature.
    pub feedthrough: FeedthroughSignature,
    /// Stiffness-instead-of-free-rigid-body signature.
    pub stiffness: StiffnessSignature,
    /// First-order factor per input column (actuator dynamics).
    pub input_dynamics: Vec<IoFactor>,
    /// First-order factor per output row (sensor dynamics).
    pub output_dynamics: Vec<IoFactor>,
    /// A factor common to every entry (an amplifier's or the sensors' bandwidth).
    pub common_dynamics: IoFactor,
    /// Every effect's evidence, largest explained fraction first.
    pub evidence: Vec<EffectEvidence>,
}

/// Compares `data` with a model's response `model` (at the same lines) against the
/// noise level `noise`, tests whether the residual is significant, and describes its
/// structure: the CMIF peaks of the whitened residual (missed modes), the phase trend
/// (delay), the magnitude trend (where the ratio is elevated), the concentration in
/// rows and columns, and the signatures of feedthrough, a stiffness, actuator and
/// sensor dynamics and (with [`ResidualConfig::sample_rate_hz`]) a zero-order hold. This
/// is step 2 of the diagnosis loop of DESIGN.md: the loop picks the effect with the
/// strongest significant evidence, adds it to the model and refits.
///
/// Every effect's flag requires the residual to be significant, the signature's own
/// chi-square test at `alpha`, and at least [`ResidualConfig::min_explained`] of the
/// excess energy explained (see [`crate::signatures`]).
///
/// Errors: see [`Residual::new`]; a failure of the CMIF of the residual.
pub fn analyze_residual(
    data: &(impl FrfDataset + ?Sized),
    model: &ResponseGrid,
    noise: &NoiseLevel,
    cfg: &ResidualConfig,
) -> Result<ResidualAnalysis, ValidationError> {
    let res = Residual::new(data, model, noise, cfg)?;
    let (median_rel, p95_rel) = rel_stats(&res.data, &res.model)?;
    let (n, m) = (res.n_lines(), res.ny * res.nu);
    let total: f64 = res.line_stat.iter().sum();
    let residual_to_noise = (total / (n * m) as f64).sqrt();
    let per_line_ratio = res
        .line_stat
        .iter()
        .map(|s| (s / m as f64).sqrt())
        .collect();
    let residual_cmif = residual_peaks(&res)?;
    let phase_trend = phase_trend(&res);
    let magnitude_trend = magnitude_trend(&res);
    let concentration = concentration(&res);
    let hold = cfg.sample_rate_hz.map(|fs| hold_signature(&res, fs));
    let feedthrough = feedthrough_signature(&res);
    let stiffness = stiffness_signature(&res);
    let (input_dynamics, output_dynamics) = io_factors(&res, &concentration);
    let common_dynamics = common_factor(&res);
    let mut evidence = Vec::new();
    if let Some(best) = residual_cmif.iter().find(|p| p.significant) {
        let sig_peaks: Vec<&ResidualPeak> =
            residual_cmif.iter().filter(|p| p.significant).collect();
        // The best single mode's explained share (the loop adds one mode at a time).
        let fraction = sig_peaks
            .iter()
            .map(|p| p.fit.explained_fraction)
            .fold(0.0, f64::max);
        evidence.push(EffectEvidence {
            effect: Effect::MissedMode,
            explained_fraction: fraction,
            significant: true,
            detail: format!(
                "{} significant residual CMIF peak(s); highest at {:.2} Hz on sigma_{} \
                 ({:.1} dB over the line's noise), zeta ~{:.4}",
                sig_peaks.len(),
                best.f_hz,
                best.sv_index + 1,
                10.0 * best.height_over_noise.log10(),
                best.fit_zeta
            ),
        });
    } else {
        evidence.push(EffectEvidence {
            effect: Effect::MissedMode,
            explained_fraction: 0.0,
            significant: false,
            detail: format!(
                "no significant residual CMIF peak ({} localized peak(s) at the model's own \
                 resonances)",
                residual_cmif.len()
            ),
        });
    }
    evidence.push(EffectEvidence {
        effect: Effect::Delay,
        explained_fraction: phase_trend.fit.explained_fraction,
        significant: phase_trend.fit.significant,
        detail: format!(
            "delay {:.3} us +- {:.3} us (model {} the data)",
            phase_trend.delay_s * 1e6,
            phase_trend.std_s * 1e6,
            if phase_trend.delay_s >= 0.0 {
                "leads"
            } else {
                "lags"
            }
        ),
    });
    if let Some(h) = &hold {
        evidence.push(EffectEvidence {
            effect: Effect::Hold,
            explained_fraction: h.fit.explained_fraction,
            significant: h.consistent,
            detail: format!(
                "amplitude {:.3} of the hold at {} Hz (correlation {:.3}, apparent fs {})",
                h.amplitude,
                h.fs_hz,
                h.correlation,
                h.apparent_fs_hz
                    .map_or("undefined".to_string(), |f| format!("{f:.1} Hz"))
            ),
        });
    }
    evidence.push(EffectEvidence {
        effect: Effect::Feedthrough,
        explained_fraction: feedthrough.fit.explained_fraction,
        significant: feedthrough.fit.significant,
        detail: format!(
            "constant residual, rms |D| {:.3e}, real fraction {:.2}",
            feedthrough.rms_magnitude, feedthrough.real_fraction
        ),
    });
    evidence.push(EffectEvidence {
        effect: Effect::Stiffness,
        explained_fraction: stiffness.fit.explained_fraction,
        significant: stiffness.fit.significant,
        detail: format!(
            "suspension ~{:.3} Hz (zeta {:.3})",
            stiffness.f_hz, stiffness.zeta
        ),
    });
    let io_detail = |f: &IoFactor, on: String| -> String {
        format!(
            "factor on {on}: first order tau {:.3e} s (pole {:.1} Hz, {:.0} % of the excess); \
             second order {:.1} Hz, zeta {:.3} ({:.0} % of the excess); {:.0} % of the excess \
             in that support",
            f.tau_s,
            f.pole_hz,
            100.0 * f.fit.explained_fraction,
            f.second_order.f_hz,
            f.second_order.zeta,
            100.0 * f.second_order.fit.explained_fraction,
            100.0 * f.energy_fraction,
        )
    };
    let best_of = |f: &IoFactor| {
        f.fit
            .explained_fraction
            .max(f.second_order.fit.explained_fraction)
    };
    for (kind, list, what) in [
        (Effect::InputDynamics, &input_dynamics, "input"),
        (Effect::OutputDynamics, &output_dynamics, "output"),
    ] {
        if let Some(best) = list.iter().max_by(|a, b| best_of(a).total_cmp(&best_of(b))) {
            evidence.push(EffectEvidence {
                effect: kind,
                explained_fraction: best_of(best),
                significant: best.fit.significant || best.second_order.fit.significant,
                detail: io_detail(best, format!("{what} {}", best.index + 1)),
            });
        }
    }
    // a factor common to every entry is flagged only when it explains more than a delay
    // (its magnitude, unlike a delay's, changes over the band)
    evidence.push(EffectEvidence {
        effect: Effect::InputDynamics,
        explained_fraction: best_of(&common_dynamics),
        significant: (common_dynamics.fit.significant
            || common_dynamics.second_order.fit.significant)
            && best_of(&common_dynamics) > phase_trend.fit.explained_fraction,
        detail: io_detail(&common_dynamics, "every entry".into()),
    });
    evidence.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(b.explained_fraction.total_cmp(&a.explained_fraction))
    });
    Ok(ResidualAnalysis {
        n_lines: n,
        ny: res.ny,
        nu: res.nu,
        noise_source: res.source.clone(),
        median_rel,
        p95_rel,
        median_noise_rel: noise.median_relative(data),
        residual_to_noise,
        per_line_ratio,
        freq_hz: res.freq_hz.clone(),
        significance: res.significance.clone(),
        significant: res.significance.significant,
        residual_cmif,
        phase_trend,
        magnitude_trend,
        concentration,
        hold,
        feedthrough,
        stiffness,
        input_dynamics,
        output_dynamics,
        common_dynamics,
        evidence,
    })
}
