//! The setup of a run: the band, what the file and the command line declare (hold,
//! delay, sample rate), and what every later stage works from, computed once: the noise
//! level, the CMIF, the weighted fit data, the data's own delay estimate and the
//! angular frequencies.

use super::config::{err, FrfType, PipelineConfig, Timings};
use crate::declared::{declared, Declared};
use crate::FrfitError;
use additive_riv::held_out::halves;
use additive_riv::riv::RivConfig;
use additive_riv::structure::AdaptConfig;
use additive_riv::{AdditiveModel, DelayChoice, FitData, FitterConfig, Hold};
use frf_data::cmif::{cmif, Cmif};
use frf_data::delay::{estimate_delay, DelayEstimate};
use frf_data::{Frf, FrfDataset, ProgressSink, Weighting};
use std::sync::{Arc, OnceLock};
use std::time::Instant;
use validation::distortion::{line_floor_and_noise, LineFloor, LineFloorConfig};
use validation::noise::{noise_level, NoiseLevel, NoiseSource};
use validation::residual::ResidualConfig;

/// Half-width, in lines, of the window of the local line-to-line floor
/// ([`validation::distortion::floor_noise`]): 40, as the noise estimate of
/// `validation::noise` (81 lines hold about 16 independent order-4 stencils, enough for a
/// median within +-30 %, while a floor that changes over a few tens of lines is
/// followed).
pub const FLOOR_HALF_WINDOW: usize = 40;

/// Everything a run works from, computed once by [`FitContext::new`] and shared by the
/// first fit, the diagnosis loop and the summary.
#[derive(Debug, Clone)]
pub struct FitContext {
    /// The fitted band (a copy of the data's lines in the band, never the 0 Hz line).
    pub band: Frf,
    /// What the file declares (sample rate, delay, hold, realizations).
    pub declared: Declared,
    /// The declared (known) effects in words, from the file and the command line.
    pub declared_list: Vec<String>,
    /// Sample rate of the measurement, Hz: the command line's, else the file's.
    pub fs_hz: Option<f64>,
    /// The hold modelled from the start (command line, or a zero-order hold the file
    /// declares with its sample rate); `None` when there is none.
    pub hold: Option<Hold>,
    /// How the first fit treats the delay (see [`PipelineConfig::delay`]).
    pub delay: DelayChoice,
    /// The noise level of the band.
    pub noise: NoiseLevel,
    /// The model-free line-to-line floor of the band against its measured variance
    /// ([`validation::distortion`]); `None` when the variance was not measured (an
    /// estimated noise level is this floor already) or the floor cannot be formed.
    pub line_floor: Option<LineFloor>,
    /// The measured variance raised to the local line-to-line floor
    /// ([`validation::distortion::floor_noise`]), with [`line_floor`](Self::line_floor);
    /// see [`distortion_noise`](Self::distortion_noise).
    pub floor_noise: Option<NoiseLevel>,
    /// CMIF of the band, computed on first use ([`cmif`](Self::cmif)): the CMIF start and
    /// the report read it, a subspace start does not (at 50 x 50 entries it costs
    /// seconds and hundreds of MB).
    pub(crate) cmif: OnceLock<Arc<Cmif>>,
    /// The initialisers' outputs of this run's chains (the starts of `fit`'s default
    /// chain share them: [`crate::chain::StartCache`]).
    pub(crate) starts: crate::chain::StartCache,
    /// The fit data split into their even and odd lines, made on first use
    /// ([`held_out_halves`](Self::held_out_halves)).
    held_out_halves: OnceLock<Arc<[FitData; 2]>>,
    /// The weighting, resolved for the band.
    pub weighting: Weighting,
    /// The band with its weights in the estimator's layout.
    pub fit_data: FitData,
    /// The data's own delay (phase slope of the FRF, default settings of
    /// [`estimate_delay`]); `None` when the estimator fails on these data, or when
    /// nothing reads it: a fit (no diagnosis) whose delay is given rather than
    /// [`DelayChoice::Auto`].
    pub delay_estimate: Option<DelayEstimate>,
    /// Angular frequencies of the band's lines, rad/s.
    pub omega: Vec<f64>,
    /// Real degrees of freedom of the variance, `2 (R - 1)` when it was estimated from
    /// `R >= 3` declared realizations, or those of the pooled variance.
    pub variance_dof: Option<f64>,
    /// How the variance was pooled over neighbouring lines
    /// ([`super::pooled_variance`]), when its declared degrees of freedom were few.
    pub pooled: Option<super::pooled_variance::Pooled>,
    /// The test of the nonlinear part of the variance (total against noise,
    /// [`super::nonlinear`]), when the data carry both and state their realizations and
    /// the final analysis runs ([`PipelineConfig::final_analysis`]).
    pub nonlinear: Option<super::nonlinear::NonlinearTest>,
}

impl FitContext {
    /// The setup of a run ([`crate::run::run`]) on `data`: the band, the declarations,
    /// the hold and the delay, then the noise level, CMIF, fit data and delay estimate of
    /// the band.
    ///
    /// Fails when the band is empty or outside the data, or when the noise level, the
    /// CMIF or the fit data cannot be formed (non-finite values, all-zero weights).
    pub fn new(data: &Frf, cfg: &PipelineConfig) -> Result<Self, FrfitError> {
        Self::timed(data, cfg, &mut Timings::default())
    }

    /// [`new`](Self::new), recording the stages in `timings`.
    pub(crate) fn timed(
        data: &Frf,
        cfg: &PipelineConfig,
        timings: &mut Timings,
    ) -> Result<Self, FrfitError> {
        // band (never the 0 Hz line)
        let t = Instant::now();
        let (lo, hi) = match cfg.band_hz {
            Some(b) => b,
            None => {
                let f = data.freq_hz_slice();
                (
                    f.iter().copied().find(|&x| x > 0.0).unwrap_or(f[0]),
                    f[f.len() - 1],
                )
            }
        };
        let lo = if lo <= 0.0 { f64::MIN_POSITIVE } else { lo };
        let band = data.band(lo, hi)?.to_frf();
        let decl: Declared = declared(data);
        let fs_hz = cfg.fs_hz.or(decl.fs_hz);
        // a variance of few degrees of freedom per line, pooled over neighbouring lines
        // before it weighs and tests anything
        // the verdict's test of the nonlinear part, on the variances as estimated (before
        // the pooling); only the final analysis reads it
        let nonlinear = cfg
            .final_analysis
            .then(|| super::nonlinear::test_nonlinear(&band, &decl, cfg.alpha))
            .flatten();
        let (band, pooled) = super::pooled_variance::pool_variance(band, &decl)?;
        let noise = noise_level(&band).map_err(err("noise level"))?;
        // the floor and the local floor as a noise level share one computation of the
        // stencils (seconds at 50 x 50 entries); the report compares the final residual
        // with the local floor whether or not the floor exceeds the variance
        let (line_floor, floor_noise) = match matches!(noise.source, NoiseSource::Measured)
            .then(|| {
                line_floor_and_noise(
                    &band,
                    &noise,
                    &LineFloorConfig::default(),
                    FLOOR_HALF_WINDOW,
                )
                .ok()
            })
            .flatten()
        {
            Some((f, n)) => (Some(f), Some(n)),
            None => (None, None),
        };
        let distortion_noise = match &line_floor {
            Some(f) if f.exceeds => floor_noise.as_ref(),
            _ => None,
        };
        // with distortion that the variance misses, the fits are weighted by the scatter
        // the data show (the local floor): inverse-variance weights from a variance that
        // misses it by factors that change along the band would pull the model towards
        // the lines where it misses the most
        let band = match distortion_noise {
            Some(dn) if band.has_variance() => band
                .with_variance(Some(dn.variance.clone()))
                .map_err(err("noise level"))?,
            _ => band,
        };
        let weighting = cfg.weighting.resolve(&band);
        let fit_data = FitData::new(&band, &weighting).map_err(err("fit"))?;
        let omega = band.omegas();
        timings.stage("load+band", t);
        let mut declared_list = decl.sources.clone();
        if let Some(p) = &pooled {
            declared_list.push(p.describe());
        }
        if let Some(h) = cfg.hold {
            declared_list.push(format!("hold {h:?} (command line)"));
        }
        // a hold the file declares (with its sample rate) is modelled from the start, like
        // one given with --hold; it is not a discovery of the loop
        let hold = cfg.hold.or_else(|| match (decl.zoh, fs_hz) {
            (true, Some(fs))
                if cfg.frf_type == FrfType::Displacement
                    && fs / 2.0 > hi.min(data.freq_hz_slice()[data.n_lines() - 1]) =>
            {
                Some(Hold::Zoh { fs_hz: fs })
            }
            _ => None,
        });
        let delay = match cfg.delay {
            Some(d) => d,
            None if cfg.diagnose => match decl.delay_s {
                Some(s) => DelayChoice::Fixed { seconds: s },
                None => DelayChoice::None,
            },
            None => DelayChoice::Auto,
        };
        let delay = match (delay, hold) {
            // a declared total delay includes the hold's half sample, which the exact hold
            // models itself
            (DelayChoice::Fixed { seconds }, Some(Hold::Zoh { fs_hz })) if cfg.delay.is_none() => {
                DelayChoice::Fixed {
                    seconds: seconds - 0.5 / fs_hz,
                }
            }
            (d, _) => d,
        };
        // a variance estimated from R realizations has 2 (R - 1) real degrees of freedom,
        // a pooled one those of its window
        let variance_dof = match (band.has_variance(), decl.realizations, &pooled) {
            (true, _, Some(p)) => Some(p.dof),
            (true, Some(r), None) if r >= 3 => Some(2.0 * (r as f64 - 1.0)),
            _ => None,
        };
        // the data's delay is read by the chain when it estimates the delay and by the
        // diagnosis (its delay restart and the second starts); a given delay (`--delay
        // none` or seconds) in a plain fit needs none (seconds at 50 x 50 entries)
        let delay_estimate = if cfg.diagnose || delay == DelayChoice::Auto {
            let t = Instant::now();
            let est = estimate_delay(&band, &Default::default()).ok();
            timings.stage("delay estimate", t);
            est
        } else {
            None
        };
        Ok(Self {
            band,
            declared: decl,
            declared_list,
            fs_hz,
            hold,
            delay,
            noise,
            line_floor,
            floor_noise,
            cmif: OnceLock::new(),
            starts: crate::chain::StartCache::default(),
            held_out_halves: OnceLock::new(),
            weighting,
            fit_data,
            delay_estimate,
            omega,
            variance_dof,
            pooled,
            nonlinear,
        })
    }

    /// The CMIF of the band, computed on the first call and kept (the CMIF start, SK's
    /// peaks and the report read it; a subspace start does not).
    pub fn cmif(&self) -> Result<&Arc<Cmif>, FrfitError> {
        cmif_once(&self.cmif, &self.band)
    }

    /// The fit data split into their even and their odd lines ([`halves`]), for the
    /// diagnosis's check of a step on held-out lines ([`additive_riv::held_out`]):
    /// made on the first call and kept (a copy of the fit data, so not made per round).
    pub fn held_out_halves(&self) -> &[FitData; 2] {
        self.held_out_halves
            .get_or_init(|| Arc::new(halves(&self.fit_data)))
    }

    /// The noise level the diagnosis loop judges residuals against: the measured (or
    /// estimated) one, or, when the line-to-line floor significantly exceeds the measured
    /// variance, that variance raised to the local floor. A variance from the periods of one
    /// realization misses the stochastic nonlinear distortions; judged against it, the
    /// distortion would look like a residual that every effect of the catalogue
    /// "explains" a little, and the loop would chase it. Judged against the floor, an
    /// effect is still found where the residual stands above the data's own jitter.
    /// The weights of the fit stay those of the measured variance.
    pub fn judging_noise(&self) -> &NoiseLevel {
        self.distortion_noise().unwrap_or(&self.noise)
    }

    /// The local floor ([`floor_noise`](Self::floor_noise)) when the floor significantly
    /// exceeds the measured variance (nonlinear distortion that the variance misses);
    /// `None` otherwise. The diagnosis loop judges the residual against it, see
    /// [`judging_noise`](Self::judging_noise).
    pub fn distortion_noise(&self) -> Option<&NoiseLevel> {
        match &self.line_floor {
            Some(f) if f.exceeds => self.floor_noise.as_ref(),
            _ => None,
        }
    }

    /// The data's total delay (hold + computation + transport), seconds, when estimated.
    pub fn data_delay_s(&self) -> Option<f64> {
        self.delay_estimate.as_ref().map(|d| d.tau_s)
    }

    /// The residual-analysis settings for `model`: the sample rate (for the hold's
    /// droop template) only while the model does not hold the exact hold itself.
    pub fn residual_config(&self, model: &AdditiveModel) -> ResidualConfig {
        ResidualConfig {
            sample_rate_hz: if model.domain() == additive_riv::Domain::Continuous {
                self.fs_hz
            } else {
                None
            },
            variance_dof: self.variance_dof,
            ..Default::default()
        }
    }

    /// Algorithm 1 settings of `cfg` (method, weighting, progress), default tolerances.
    pub fn riv_config(&self, cfg: &PipelineConfig) -> RivConfig {
        RivConfig {
            method: cfg.method,
            weighting: cfg.weighting.clone(),
            progress: cfg.progress.clone(),
            ..Default::default()
        }
    }

    /// The settings of the CMIF-initialised fit of the band: modes, the resolved hold
    /// and delay, the FRF type, Algorithm 1, and the structure adaptation of the first
    /// fit.
    pub fn fitter_config(&self, cfg: &PipelineConfig) -> FitterConfig {
        FitterConfig {
            modes: cfg.modes.clone(),
            hold: self.hold.unwrap_or(Hold::None),
            delay: self.delay,
            derivative_order: cfg.frf_type.derivative_order(),
            riv: self.riv_config(cfg),
            adapt: Some(AdaptConfig {
                min_f: cfg.min_f,
                alpha: cfg.alpha,
                // the first fit completes the modes at significant residual peaks, as
                // `frfit fit` does, unless a diagnosis was told the modes to expect
                max_new_per_round: if cfg.first_fit_adds_modes() { 6 } else { 0 },
                ..Default::default()
            }),
            progress: cfg.progress.clone(),
            ..Default::default()
        }
    }

    /// [`fitter_config`](Self::fitter_config) without progress output (for fits that
    /// the diagnosis loop runs as trials).
    pub fn quiet_fitter_config(&self, cfg: &PipelineConfig) -> FitterConfig {
        let fc = self.fitter_config(cfg);
        FitterConfig {
            progress: ProgressSink::none(),
            riv: RivConfig {
                progress: ProgressSink::none(),
                ..fc.riv.clone()
            },
            ..fc
        }
    }
}

/// The CMIF of `band` kept in `cell`: computed on the first call, read afterwards (the
/// context and the run's output hold the same cell).
pub(crate) fn cmif_once<'a>(
    cell: &'a OnceLock<Arc<Cmif>>,
    band: &Frf,
) -> Result<&'a Arc<Cmif>, FrfitError> {
    if let Some(c) = cell.get() {
        return Ok(c);
    }
    let c = Arc::new(cmif(band)?);
    Ok(cell.get_or_init(|| c))
}
