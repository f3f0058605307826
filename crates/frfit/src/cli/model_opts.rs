//! Options shared by `fit` and `diagnose`: hold, delay, modes, method, weighting, FRF
//! type, and the progress bar.

use super::common::Band;
use additive_riv::{DelayChoice, Hold, IvMethod, ModeSelection};
use clap::{Args as ClapArgs, ValueEnum};
use frf_data::{ProgressSink, Weighting};
use frfit::options::FitSpec;
use frfit::pipeline::FrfType;
use indicatif::{ProgressBar, ProgressStyle};
use sk_fit::bands::BandSpec;
use std::sync::Mutex;
use std::time::Duration;

pub use frfit::options::{parse_band_weights, parse_bands, parse_delay, parse_hold, parse_modes};

/// `--method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Refined instrumental variables (Algorithm 1 of the wafer-stage paper).
    Riv,
    /// Sanathanan-Koerner iterations (Remark 1).
    Sk,
}

/// `--weighting`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WeightingArg {
    /// Inverse variance when the data carry `_var` (maximum likelihood), else inverse magnitude.
    Auto,
    /// 1 / var (needs `_var` columns).
    Variance,
    /// 1 / |G|^2 (eq. 27 of the wafer-stage paper, relative error).
    Magnitude,
    /// Uniform.
    Uniform,
}

/// `--frf-type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FrfTypeArg {
    /// Displacement (or angle) per force.
    Displacement,
    /// Velocity per force: the model is s times a displacement model.
    Velocity,
    /// Acceleration per force: the model is s^2 times a displacement model.
    Accelerance,
}

/// The fitting options of `fit` and `diagnose`.
#[derive(ClapArgs, Debug, Clone)]
pub struct FitOptions {
    /// Frequency band LO:HI in Hz (either side may be empty).
    #[arg(long, value_parser = super::common::parse_band, value_name = "LO:HI")]
    pub band: Option<Band>,
    /// Delay: `auto` (estimate and refine), `none`, or seconds (`1.5e-4`, `150us`).
    /// Default: `auto` for fit; for diagnose the delay the file declares (the loop
    /// tests for more).
    #[arg(long, value_parser = parse_delay, value_name = "auto|none|SECONDS")]
    pub delay: Option<DelayChoice>,
    /// Sampled-measurement hold: `zoh:FS_HZ` (exact zero-order hold), `sinc:FS_HZ`, `none`.
    #[arg(long, value_parser = parse_hold, value_name = "zoh:FS_HZ|none")]
    pub hold: Option<Hold>,
    /// Modes to start from: `auto` (every CMIF peak) or N (the N most prominent).
    #[arg(long, value_parser = parse_modes, value_name = "auto|N")]
    pub modes: Option<ModeSelection>,
    /// Iterations: refined IV (riv) or SK.
    #[arg(long, value_enum, default_value_t = Method::Riv)]
    pub method: Method,
    /// Initialiser of the estimator chain: `cmif` (CMIF peaks + convex numerators),
    /// `subspace`, `sk`, a comma-separated list of initialisers (each starts a chain; the
    /// one with the smallest final prediction error is kept), or `auto` (every
    /// initialiser). Default: `cmif` up to 100 entries (ny x nu), `subspace` above.
    #[arg(
        long,
        default_value = "",
        hide_default_value = true,
        value_name = "NAME[,NAME..]|auto"
    )]
    pub init: String,
    /// Refiner of the estimator chain: `riv` (refined IV with mode adaptation), `ml`
    /// (maximum likelihood with the standard deviations of the modes) or `none` (the
    /// initialiser's model as it is). Default: `riv` up to 100 entries (ny x nu), `ml`
    /// above.
    #[arg(
        long,
        default_value = "",
        hide_default_value = true,
        value_name = "NAME"
    )]
    pub refine: String,
    /// Model order (number of states) for the initialisers that take one (sk,
    /// subspace); default: chosen from the data.
    #[arg(long, value_name = "N")]
    pub order: Option<usize>,
    /// Bayard's multi-band composite fit of the SK initialiser (Jue 2.3; needs
    /// `--init sk`): `auto` (cut-offs in flat, low valleys of the CMIF between resonance
    /// clusters), `1` (one band), or cut-off frequencies in Hz (`4.6,37`; a single
    /// cut-off at 1 Hz is written `1.0`).
    #[arg(long, value_parser = parse_bands, value_name = "auto|1|F1,F2,..")]
    pub bands: Option<BandSpec>,
    /// Tiered weights of the multi-band fit, `QL,QH`: the weight of the lines below and
    /// above the band being fitted (Jue eq. 3). Default: `0.1,1e-4`.
    #[arg(long, value_parser = parse_band_weights, value_name = "QL,QH", requires = "bands")]
    pub band_weights: Option<(f64, f64)>,
    /// Weighting of the criterion.
    #[arg(long, value_enum, default_value_t = WeightingArg::Auto)]
    pub weighting: WeightingArg,
    /// What the FRF measures.
    #[arg(long, value_enum, default_value_t = FrfTypeArg::Displacement)]
    pub frf_type: FrfTypeArg,
}

impl FitOptions {
    /// The options as the library's [`FitSpec`] (one set of rules for the CLI and the
    /// Python package).
    pub fn spec(&self) -> FitSpec {
        FitSpec {
            band: self.band,
            delay: self.delay,
            hold: self.hold,
            modes: self.modes.clone(),
            method: match self.method {
                Method::Riv => IvMethod::Riv,
                Method::Sk => IvMethod::Sk,
            },
            init: self.init.clone(),
            refine: self.refine.clone(),
            order: self.order,
            bands: self.bands.clone(),
            band_weights: self.band_weights,
            weighting: match self.weighting {
                WeightingArg::Auto => Weighting::Auto,
                WeightingArg::Variance => Weighting::InverseVariance,
                WeightingArg::Magnitude => Weighting::InverseMagnitude,
                WeightingArg::Uniform => Weighting::Uniform,
            },
            frf_type: match self.frf_type {
                FrfTypeArg::Displacement => FrfType::Displacement,
                FrfTypeArg::Velocity => FrfType::Velocity,
                FrfTypeArg::Accelerance => FrfType::Accelerance,
            },
            fs_hz: None,
        }
    }
}

/// A spinner for a stage of unknown length.
fn spinner_style() -> ProgressStyle {
    ProgressStyle::with_template("{spinner} [{elapsed_precise}] {prefix} {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_spinner())
}

/// A bar for a stage that reports its length. The lengths the estimators report are
/// upper bounds (the ML iteration cap, the SK sweep's last order; the subspace steps
/// are exact), so the remaining time is one too: iterations that converge end sooner.
fn bar_style() -> ProgressStyle {
    ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {prefix} [{bar:24}] {pos}/{len}, at most {eta} left {msg}",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// Progress on stderr, silent with `--quiet` or when stderr is not a terminal: a bar
/// with the remaining time for a stage that reports its length (each stage starts its
/// own bar, so the estimate is that stage's rate), a spinner for one that does not;
/// the stage's message and cost beside it.
pub fn progress(quiet: bool) -> (ProgressSink, Option<ProgressBar>) {
    if quiet {
        return (ProgressSink::none(), None);
    }
    let bar = ProgressBar::new_spinner();
    bar.set_style(spinner_style());
    bar.enable_steady_tick(Duration::from_millis(120));
    let b = bar.clone();
    let current: Mutex<Option<(String, Option<usize>)>> = Mutex::new(None);
    let sink = ProgressSink::new(move |p| {
        let mut cur = current.lock().unwrap_or_else(|e| e.into_inner());
        let key = (p.stage.clone(), p.total);
        if cur.as_ref() != Some(&key) {
            b.reset();
            match p.total {
                Some(t) => {
                    b.set_style(bar_style());
                    b.set_length(t as u64);
                }
                None => {
                    b.unset_length();
                    b.set_style(spinner_style());
                }
            }
            b.set_prefix(p.stage.clone());
            *cur = Some(key);
        }
        if p.total.is_some() {
            b.set_position(p.step as u64);
        }
        let cost = p.cost.map(|c| format!(" cost {c:.4e}")).unwrap_or_default();
        b.set_message(format!("{}{}", p.message, cost));
    });
    (sink, Some(bar))
}
