//! The settings of a run ([`PipelineConfig`], [`FrfType`]) and the estimator chain
//! they default to by the size of the data ([`default_chain`]), with the two small
//! helpers every stage shares: the error of a failed fit step (`err`) and the wall-clock
//! time per stage (`Timings`).

use crate::summary::{ResidualVerdict, StageTime};
use crate::FrfitError;
use additive_riv::{AdditiveModel, DelayChoice, Hold, IvMethod, ModeSelection};
use frf_data::{ProgressSink, Weighting};
use std::time::Instant;

/// What the FRF measures: the model is always of the displacement, multiplied by
/// `(j w)^k` for velocity (`k = 1`) or accelerance (`k = 2`) data, so that a free rigid
/// body stays `1/s^2` (and becomes a constant in an accelerance).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrfType {
    /// Displacement (or angle) per force (or current). The default.
    #[default]
    Displacement,
    /// Velocity per force.
    Velocity,
    /// Acceleration per force (accelerance).
    Accelerance,
}

impl FrfType {
    /// `k` of `(j w)^k`.
    pub fn derivative_order(self) -> u32 {
        match self {
            FrfType::Displacement => 0,
            FrfType::Velocity => 1,
            FrfType::Accelerance => 2,
        }
    }
    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            FrfType::Displacement => "displacement",
            FrfType::Velocity => "velocity",
            FrfType::Accelerance => "accelerance",
        }
    }
}

/// Settings of a run ([`crate::run::run`]), with documented defaults.
#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// Band to fit, Hz. Default: the whole data above 0 Hz.
    pub band_hz: Option<(f64, f64)>,
    /// Modes to start from. Default: every CMIF peak.
    pub modes: ModeSelection,
    /// A hold the user declares (`zoh:FS` or `sinc:FS`): modelled from the start, not a
    /// discovery; `Some(Hold::None)` says there is none (overriding a hold the file's
    /// comments declare). Default: `None`, take what the file declares.
    pub hold: Option<Hold>,
    /// Delay handling. `None` (the default) means: for `fit`, estimate it and refine it
    /// in the iterations; for `diagnose`, take the delay the file declares (0 when it
    /// declares none) and let the loop test for more.
    pub delay: Option<DelayChoice>,
    /// Sample rate of the measurement for testing a hold, Hz. Default: from the file's
    /// metadata or comments.
    pub fs_hz: Option<f64>,
    /// What the FRF measures. Default: displacement.
    pub frf_type: FrfType,
    /// Instrument or SK. Default: RIV.
    pub method: IvMethod,
    /// Weighting. Default: inverse variance when the data carry it, eq. (27) otherwise.
    pub weighting: Weighting,
    /// Run the diagnosis loop. Default: false (`frfit fit`).
    pub diagnose: bool,
    /// Run the final residual analysis (the verdict and its evidence) and compare the
    /// final residual with the line-to-line floor. Default: true. `frfit fit` without
    /// `--report` turns it off: it prints neither, and at 50 x 50 entries they cost
    /// 2.4 s of a 28 s fit. Off, the summary's verdict is [`NOT_ANALYSED`].
    pub final_analysis: bool,
    /// At most this many effects are added by the loop (each round tests every
    /// candidate, then adds the best). Default: 8.
    pub max_steps: usize,
    /// Significance level of the tests. Default: 1e-3.
    pub alpha: f64,
    /// Practical-significance floor of an effect's F statistic (see
    /// [`additive_riv::structure::AdaptConfig::min_f`]). Default: 25.
    pub min_f: f64,
    /// A model to start from (from `--model MODEL.json`) instead of the CMIF
    /// initialisation.
    pub start_model: Option<AdditiveModel>,
    /// The initialiser of the chain (see [`crate::chain::INITIALIZERS`]); empty: by the
    /// size of the data ([`default_chain`]: `cmif` up to 100 entries), with the second
    /// start of [`first_fit`](fn@super::first_fit) when that chain's fit is poor.
    /// Default: empty.
    pub init: String,
    /// The refiner of the chain (see [`crate::chain::REFINERS`]); empty: by the size of
    /// the data ([`default_chain`]: `riv` up to 100 entries). Default: empty.
    pub refine: String,
    /// Model order (number of states) for initialisers that take one (SK, subspace);
    /// `None` lets them choose it from the data. Default: `None`.
    pub order: Option<usize>,
    /// Bayard's multi-band composite fit for the `sk` initialiser (`--bands`); `None`:
    /// one SK fit. Default: `None`.
    pub sk_bands: Option<crate::chain::SkBands>,
    /// Progress callback.
    pub progress: ProgressSink,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            band_hz: None,
            modes: ModeSelection::Auto,
            hold: None,
            delay: None,
            fs_hz: None,
            frf_type: FrfType::Displacement,
            method: IvMethod::Riv,
            weighting: Weighting::Auto,
            diagnose: false,
            final_analysis: true,
            max_steps: 8,
            alpha: 1e-3,
            min_f: 25.0,
            start_model: None,
            init: String::new(),
            refine: String::new(),
            order: None,
            sk_bands: None,
            progress: ProgressSink::none(),
        }
    }
}

impl PipelineConfig {
    /// Whether the first fit adds modes beyond its start: the structure adaptation's
    /// completion at significant residual peaks, and the repairs (a mode beyond a band
    /// edge, close pairs split). Yes, unless a diagnosis was told the modes to expect
    /// (`--modes N` or frequencies): a mode beyond them is then a discovery, a
    /// `missed_mode` step of the loop.
    pub fn first_fit_adds_modes(&self) -> bool {
        !(self.diagnose && self.modes != ModeSelection::Auto)
    }
}

pub(crate) fn err<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> FrfitError + '_ {
    move |e| FrfitError::Fit {
        what: what.to_string(),
        why: e.to_string(),
    }
}

/// Wall-clock time per stage of a run.
#[derive(Debug, Default)]
pub(crate) struct Timings(pub(crate) Vec<StageTime>);

impl Timings {
    /// Records stage `name`, started at `t`.
    pub(crate) fn stage(&mut self, name: &str, t: Instant) {
        self.0.push(StageTime {
            stage: name.to_string(),
            seconds: t.elapsed().as_secs_f64(),
        });
    }
}

/// The summary's verdict when [`PipelineConfig::final_analysis`] is off.
pub const NOT_ANALYSED: ResidualVerdict = ResidualVerdict::NotAnalysed;

/// Entries (`ny x nu`) above which the default chain is `subspace -> ml` ([`default_chain`]).
pub const LARGE_MIMO_ENTRIES: usize = 100;

/// The default chain for an FRF with `entries` entries (`ny x nu`): `cmif -> riv` up to
/// [`LARGE_MIMO_ENTRIES`] (the wafer-stage method: modes from CMIF peaks, refined IV),
/// `subspace -> ml` above. With many entries and modes, peaks are many, close and
/// hidden: the CMIF start misses or merges modes that the refined IV's adaptation does
/// not recover (a 20 x 20 plant with 50 modes: 27 modes, 16 of them right), while the
/// subspace start finds the poles without picking peaks and the ML refinement's cost
/// per iteration is linear in lines x entries (one factorisation per group of entries
/// with the same weights). An explicit `init` or `refine` is kept.
pub fn default_chain(init: &str, refine: &str, entries: usize) -> (String, String) {
    let large = entries > LARGE_MIMO_ENTRIES;
    let pick = |given: &str, small: &str, big: &str| {
        if !given.trim().is_empty() {
            given.to_string()
        } else if large {
            big.to_string()
        } else {
            small.to_string()
        }
    };
    (pick(init, "cmif", "subspace"), pick(refine, "riv", "ml"))
}

#[cfg(test)]
mod default_chain_tests {
    use super::*;

    #[test]
    fn the_default_chain_follows_the_size_and_keeps_explicit_choices() {
        let s = |a: &str, b: &str| (a.to_string(), b.to_string());
        assert_eq!(default_chain("", "", 52), s("cmif", "riv"));
        assert_eq!(default_chain("", "", 100), s("cmif", "riv"));
        assert_eq!(default_chain("", "", 400), s("subspace", "ml"));
        assert_eq!(default_chain("cmif", "", 400), s("cmif", "ml"));
        assert_eq!(default_chain("", "none", 2500), s("subspace", "none"));
        assert_eq!(default_chain("sk", "riv", 4), s("sk", "riv"));
    }
}
