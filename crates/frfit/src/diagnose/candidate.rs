//! The candidates of a diagnosis round: one variant per effect of the catalogue, with
//! the parameters the refit starts from, proposed from the residual analysis.

use additive_riv::residual_stats::ResidualStats;
use additive_riv::{
    augment, AdditiveModel, DynamicsFactor, FactorTarget, FitData, RivError, SubmodelKind,
};
use frf_data::ModelStructure;
use rayon::prelude::*;
use validation::analysis::{Effect, ResidualAnalysis};

/// Where a delay candidate's start comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DelayStart {
    /// The phase slope of the residual (biased when the model is far off: modes fitted
    /// without the delay absorb part of it).
    ResidualSlope,
    /// The data's own phase slope (the context's delay estimate) beyond the model's
    /// delay and the exact hold's half sample.
    DataSlope,
}

/// One effect of the catalogue to add to the model, with its starting parameters.
#[derive(Debug, Clone, PartialEq)]
pub enum Candidate {
    /// A mode at a significant residual peak.
    MissedMode {
        /// Starting natural frequency, Hz.
        f_hz: f64,
        /// Starting relative damping (from the residual's CMIF, clamped to
        /// `[0.002, 0.2]`).
        zeta: f64,
        /// The residual peak that called for it, Hz: the refit must remove most of the
        /// residual around it.
        peak_hz: f64,
        /// `Some(l)`: proposed beside the free rigid body, as `R / s^l`, as the other
        /// reading of the residual's suspension signature (a low mode rather than a
        /// suspended body, [`propose`]); tested in the same round as that `stiffness`
        /// and judged against it ([`super::trial::mode_or_suspension`]). The body's
        /// integrators are set to `l`: the first fit chose them without the mode, whose
        /// response below it can pass for a body of the other order. `None`: a mode at a
        /// residual peak.
        body_integrators: Option<usize>,
    },
    /// A delay beyond the model's, fitted (refined in the iterations).
    Delay {
        /// Starting delay added to the model's, seconds.
        seconds: f64,
        /// Where the start comes from.
        start: DelayStart,
    },
    /// The exact zero-order hold at the measurement's sample rate.
    Hold {
        /// Sample rate, Hz.
        fs_hz: f64,
    },
    /// A constant feedthrough matrix.
    Feedthrough {
        /// RMS magnitude of the residual's constant part.
        rms: f64,
        /// Crosstalk that bypasses the delay and hold (else inside them, a biproper
        /// plant).
        bypasses_delay: bool,
    },
    /// A stiffness that suspends the rigid body.
    Stiffness {
        /// Suspension frequency, Hz.
        f_hz: f64,
        /// Its relative damping as the signature estimated it (the augmentation
        /// clamps it to `[1e-3, 0.9]`).
        zeta: f64,
        /// The mode (submodel index in the current model) that the suspension replaces:
        /// the first fit took the suspended body for that mode beside a free rigid body
        /// that carries (almost) nothing ([`suspended_body`]); `None` for a suspension
        /// that the residual's low-frequency signature calls for.
        replaces: Option<usize>,
    },
    /// A dynamics factor of unit static gain on one input column (actuator dynamics),
    /// or, when `inputs` holds every input, common to every entry (an amplifier's
    /// bandwidth).
    InputDynamics {
        /// The inputs, 1-based.
        inputs: Vec<usize>,
        /// Order and starting pole.
        start: FactorStart,
    },
    /// A dynamics factor of unit static gain on one output row (sensor or sensor-mount
    /// dynamics); when `outputs` holds every output, common to every entry (the
    /// equivalent form of a common `InputDynamics`).
    OutputDynamics {
        /// The outputs, 1-based.
        outputs: Vec<usize>,
        /// Order and starting pole.
        start: FactorStart,
    },
}

/// The order and starting pole of a dynamics-factor candidate.
#[derive(Debug, Clone, PartialEq)]
pub struct FactorStart {
    /// 1: a lag `1 / (1 + s / w)`; 2: `w^2 / (s^2 + 2 zeta w s + w^2)`.
    pub order: usize,
    /// Corner (order 1) or natural frequency (order 2), Hz.
    pub f_hz: f64,
    /// Relative damping (order 2; ignored for order 1).
    pub zeta: f64,
    /// Submodels (indices in the current model) the factor replaces: modes that live in
    /// the factor's row or column alone, where the first fit took the factor's
    /// resonance for a mode.
    pub replaces: Vec<usize>,
    /// The model delay the factor starts with, seconds, when it takes over part of a
    /// fitted delay ([`traded_common_lag`]); `None`: the delay is left as it is.
    pub delay_s: Option<f64>,
    /// The zeros the factor starts with, `(Hz, damping)` (damping ignored for order 1):
    /// a numerator of the denominator's order (a lead-lag, or a second-order rational
    /// with an anti-resonance), [`DynamicsFactor::with_zeros`]; `None`: an all-pole factor.
    pub zeros: Option<(f64, f64)>,
    /// The model's own all-pole dynamics factor (index in its `dynamics`) that this
    /// factor, with the same poles to start and zeros added, takes the place of: the
    /// accepted factor tried again with a numerator ([`propose_dynamics`]).
    pub replaces_factor: Option<usize>,
}

impl FactorStart {
    /// The start from a signature `f` of the residual at `order`: its corner (1 kHz
    /// when the first-order fit found none) or its second-order frequency and damping
    /// (damping clamped to `[0.005, 1]`).
    pub fn from_signature(f: &validation::IoFactor, order: usize) -> Self {
        if order == 2 && f.second_order.f_hz.is_finite() && f.second_order.f_hz > 0.0 {
            FactorStart {
                order: 2,
                f_hz: f.second_order.f_hz,
                zeta: f.second_order.zeta.clamp(0.005, 1.0),
                replaces: Vec::new(),
                delay_s: None,
                zeros: None,
                replaces_factor: None,
            }
        } else {
            let f_hz = if f.pole_hz.is_finite() && f.pole_hz > 0.0 {
                f.pole_hz
            } else {
                1e3
            };
            FactorStart {
                order: 1,
                f_hz,
                zeta: 1.0,
                replaces: Vec::new(),
                delay_s: None,
                zeros: None,
                replaces_factor: None,
            }
        }
    }

    /// The factor on `target`.
    pub fn factor(&self, target: FactorTarget) -> Result<DynamicsFactor, RivError> {
        if !(self.f_hz.is_finite() && self.f_hz > 0.0) {
            return Err(RivError::invalid(
                "factor frequency",
                self.f_hz,
                "must be > 0 Hz",
            ));
        }
        let all_pole = match self.order {
            1 => DynamicsFactor::first_order(target, self.f_hz),
            2 if self.zeta.is_finite() && self.zeta > 0.0 => {
                DynamicsFactor::second_order(target, self.f_hz, self.zeta)
            }
            2 => {
                return Err(RivError::invalid(
                    "factor damping",
                    self.zeta,
                    "must be > 0",
                ))
            }
            o => return Err(RivError::invalid("factor order", o, "must be 1 or 2")),
        };
        match self.zeros {
            None => Ok(all_pole),
            Some((f, z)) => all_pole.with_zeros(f, z).ok_or_else(|| {
                RivError::invalid("factor zero frequency", f, "must be finite and > 0 Hz")
            }),
        }
    }
}

/// A candidate with the evidence that proposed it.
#[derive(Debug, Clone)]
pub struct Proposal {
    /// What to add.
    pub candidate: Candidate,
    /// Why, in words with numbers.
    pub evidence: String,
}

impl Candidate {
    /// The catalogue effect.
    pub fn effect(&self) -> Effect {
        match self {
            Candidate::MissedMode { .. } => Effect::MissedMode,
            Candidate::Delay { .. } => Effect::Delay,
            Candidate::Hold { .. } => Effect::Hold,
            Candidate::Feedthrough { .. } => Effect::Feedthrough,
            Candidate::Stiffness { .. } => Effect::Stiffness,
            Candidate::InputDynamics { .. } => Effect::InputDynamics,
            Candidate::OutputDynamics { .. } => Effect::OutputDynamics,
        }
    }

    /// What identifies the candidate among the tested ones of its effect: the residual
    /// peak to 0.1 Hz, the 0-based input or output, the data's delay start; empty for
    /// the others (tested again whenever proposed).
    pub fn key(&self) -> String {
        match self {
            Candidate::MissedMode {
                peak_hz,
                body_integrators,
                ..
            } => match body_integrators {
                Some(l) => format!("{}:body{l}", mode_key(*peak_hz)),
                None => mode_key(*peak_hz),
            },
            Candidate::InputDynamics { inputs: v, start }
            | Candidate::OutputDynamics { outputs: v, start } => {
                let which = if v.len() > 1 {
                    "all".to_string()
                } else {
                    v.first()
                        .map(|i| format!("{}", i.saturating_sub(1)))
                        .unwrap_or_default()
                };
                let replaced: Vec<String> =
                    start.replaces.iter().map(|i| format!(":m{i}")).collect();
                let traded = if start.delay_s.is_some() { ":d" } else { "" };
                let zeros = if start.zeros.is_some() { ":z" } else { "" };
                let own = start
                    .replaces_factor
                    .map(|k| format!(":f{k}"))
                    .unwrap_or_default();
                format!(
                    "{which}:{}{}{traded}{own}{zeros}",
                    start.order,
                    replaced.concat()
                )
            }
            Candidate::Delay {
                start: DelayStart::DataSlope,
                ..
            } => "data".into(),
            Candidate::Stiffness {
                f_hz,
                replaces: Some(_),
                ..
            } => format!("reading:{}", mode_key(*f_hz)),
            _ => String::new(),
        }
    }

    /// `model` with the effect added at its starting parameters (numerators zero where
    /// the structure changed: refit them).
    pub fn augment(&self, model: &AdditiveModel) -> Result<AdditiveModel, RivError> {
        match self {
            Candidate::MissedMode {
                f_hz,
                zeta,
                body_integrators,
                ..
            } => {
                let mut m = augment::with_mode(model, *f_hz, *zeta)?;
                if let Some(l) = *body_integrators {
                    with_body_integrators(&mut m, l)?;
                }
                Ok(m)
            }
            Candidate::Delay { seconds, .. } => augment::with_fitted_delay(model, *seconds),
            Candidate::Hold { fs_hz } => augment::to_exact_hold(model, *fs_hz),
            Candidate::Feedthrough {
                bypasses_delay: true,
                ..
            } => augment::with_crosstalk(model),
            Candidate::Feedthrough { .. } => augment::with_feedthrough(model),
            Candidate::Stiffness {
                f_hz,
                zeta,
                replaces,
            } => {
                let mut m = model.clone();
                if let Some(i) = *replaces {
                    if m.submodels.get(i).map(|s| s.kind) != Some(SubmodelKind::Mode) {
                        return Err(RivError::Structure(format!(
                            "submodel {i} that the suspension would replace is not a mode"
                        )));
                    }
                    m.remove_submodel(i);
                }
                augment::with_stiffness(&m, *f_hz, zeta.clamp(1e-3, 0.9))
            }
            Candidate::InputDynamics { inputs, start } => {
                dynamics(model, FactorTarget::Input, inputs, model.nu(), start)
            }
            Candidate::OutputDynamics { outputs, start } => {
                dynamics(model, FactorTarget::Output, outputs, model.ny(), start)
            }
        }
    }

    /// The start of a dynamics-factor candidate (`None` for the other effects).
    pub fn factor_start(&self) -> Option<&FactorStart> {
        match self {
            Candidate::InputDynamics { start, .. } | Candidate::OutputDynamics { start, .. } => {
                Some(start)
            }
            _ => None,
        }
    }

    /// The same dynamics-factor candidate (same effect and support) from `start`; any
    /// other candidate is returned as it is.
    pub fn with_start(&self, start: FactorStart) -> Candidate {
        match self {
            Candidate::InputDynamics { inputs, .. } => Candidate::InputDynamics {
                inputs: inputs.clone(),
                start,
            },
            Candidate::OutputDynamics { outputs, .. } => Candidate::OutputDynamics {
                outputs: outputs.clone(),
                start,
            },
            other => other.clone(),
        }
    }

    /// True for a dynamics factor common to every entry.
    pub fn is_common_factor(&self) -> bool {
        match self {
            Candidate::InputDynamics { inputs: v, .. }
            | Candidate::OutputDynamics { outputs: v, .. } => v.len() > 1,
            _ => false,
        }
    }
}

/// The factor `start` on `which` (1-based, one of `n`; all `n` of them: the common
/// factor).
fn dynamics(
    model: &AdditiveModel,
    target: fn(usize) -> FactorTarget,
    which: &[usize],
    n: usize,
    start: &FactorStart,
) -> Result<AdditiveModel, RivError> {
    let target = match which {
        [i] if (1..=n).contains(i) => target(i - 1),
        v if v.len() == n && (1..=n).all(|i| v.contains(&i)) => FactorTarget::All,
        _ => {
            return Err(RivError::Structure(format!(
                "a dynamics candidate needs one input or output (1-based, of {n}) or all of them, got {which:?}"
            )))
        }
    };
    let mut m = model.clone();
    if let Some(k) = start.replaces_factor {
        if k >= m.dynamics.len() {
            return Err(RivError::Structure(format!(
                "dynamics factor {k} that the candidate would replace is not in the model"
            )));
        }
        m.dynamics.remove(k);
    }
    let mut gone = start.replaces.clone();
    gone.sort_unstable();
    gone.dedup();
    for &i in gone.iter().rev() {
        if m.submodels.get(i).map(|s| s.kind) != Some(SubmodelKind::Mode) {
            return Err(RivError::Structure(format!(
                "submodel {i} that the factor would replace is not a mode"
            )));
        }
        m.remove_submodel(i);
    }
    m.push_dynamics(start.factor(target)?)?;
    match start.delay_s {
        Some(d) => {
            let factor = additive_riv::KnownFactor {
                delay_s: d,
                ..m.factor
            };
            m.with_factor(factor)
        }
        None => Ok(m),
    }
}

/// The share of each output row (`rows = true`) or input column of a submodel's
/// numerator energy (all numerator matrices, in the scaled variable).
fn numerator_shares(s: &additive_riv::Submodel, rows: bool) -> Vec<f64> {
    let (ny, nu) = s
        .num
        .first()
        .map(|b| (b.nrows(), b.ncols()))
        .unwrap_or((0, 0));
    let mut v = vec![0.0; if rows { ny } else { nu }];
    for b in &s.num {
        for j in 0..nu {
            for i in 0..ny {
                v[if rows { i } else { j }] += b[(i, j)].powi(2);
            }
        }
    }
    let t: f64 = v.iter().sum();
    if t > 0.0 {
        v.iter_mut().for_each(|x| *x /= t);
    }
    v
}

/// Relative frequency within which two screened second-order starts of
/// [`local_modes`] are the same factor: the last grid step of [`screen_second_order`]
/// (`0.08 / 9` in log frequency).
const SAME_FACTOR: f64 = 0.01;

/// Second-order factor candidates from the model itself: a mode whose numerator lives
/// in one output row (or one input column), at least `LOCAL_SHARE` of its energy, where
/// the residual concentrates (the dominant row or column of the residual), is what a
/// first fit makes of a sensor's (actuator's) mount resonance: the resonance seen in
/// that row only. The candidate replaces that mode by a second-order factor on the
/// row; its start is screened on a grid of frequencies around the mode's and of damping
/// values by the cost after the numerator fit (eq. 24: the numerators are linear given
/// the poles and the factor, so each grid point is one convex fit), and the refit and
/// its F test decide between the mode and the factor. At most the two most local modes
/// of the row are tried. `(row or column, start)` per candidate.
fn local_modes(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    fd: &FitData,
    rows: bool,
) -> Vec<(usize, FactorStart)> {
    const LOCAL_SHARE: f64 = 0.8;
    let n = if rows { model.ny() } else { model.nu() };
    let dominant = if rows {
        an.concentration.dominant_row
    } else {
        an.concentration.dominant_col
    };
    let Some(k) = dominant.filter(|_| n >= 2) else {
        return Vec::new();
    };
    let mut local: Vec<(f64, usize, f64, f64)> = model
        .modes()
        .iter()
        .filter(|m| m.zeta > 0.0)
        .filter_map(|m| {
            let share = numerator_shares(&model.submodels[m.submodel], rows)
                .get(k)
                .copied()
                .unwrap_or(0.0);
            (share >= LOCAL_SHARE).then_some((share, m.submodel, m.f_hz, m.zeta))
        })
        .collect();
    local.sort_by(|a, b| b.0.total_cmp(&a.0));
    let target = if rows {
        FactorTarget::Output(k)
    } else {
        FactorTarget::Input(k)
    };
    let mut out: Vec<(usize, FactorStart)> = Vec::new();
    for &(_, sub, f, z) in local.iter().take(2) {
        let mut base = model.clone();
        base.remove_submodel(sub);
        let Some((f_hz, zeta)) = screen_second_order(&base, target, f, z, fd) else {
            continue;
        };
        // two modes of the row that screen to the same factor (a resonance the first fit
        // split in two), within the screen's last grid step (about 1 %), are one
        // candidate; factors a few per cent apart are not (a resonance 3 % below a plate
        // mode whose row-3 twin screens to the plate mode: the two must both be tried)
        if out
            .iter()
            .any(|(_, s)| (s.f_hz / f_hz - 1.0).abs() < SAME_FACTOR)
        {
            continue;
        }
        out.push((
            k,
            FactorStart {
                order: 2,
                f_hz,
                zeta,
                replaces: vec![sub],
                delay_s: None,
                zeros: None,
                replaces_factor: None,
            },
        ));
    }
    out
}

/// The dynamics factor `start` on input `k` (`input`) or output `k` alone (0-based).
fn one_factor(input: bool, k: usize, start: FactorStart) -> Candidate {
    let which = vec![k + 1];
    if input {
        Candidate::InputDynamics {
            inputs: which,
            start,
        }
    } else {
        Candidate::OutputDynamics {
            outputs: which,
            start,
        }
    }
}

/// A second-order factor above the band on the residual's dominant output row (`rows`)
/// or input column: a sensor's or actuator's mount resonance beyond the top line shows
/// in the band only as that row's magnitude rise `1 / (1 - (f / f_r)^2)` with little
/// phase, which the first fit's residues partly absorb (the residual's templates then
/// see a phase-like remainder and propose a first-order lead). No residual peak or local
/// mode calls for it, so its start is screened here: natural frequencies on a log grid
/// from [`ABOVE_BAND`] times the top line, damping 0.005..0.2, by the cost after the
/// numerator fit (eq. 24, one convex fit per point), refined by
/// [`screen_second_order`]. The refit and its F test decide. `(row or column, start)`.
fn above_band(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    fd: &FitData,
    rows: bool,
) -> Option<(usize, FactorStart)> {
    let n = if rows { model.ny() } else { model.nu() };
    let dominant = if rows {
        an.concentration.dominant_row
    } else {
        an.concentration.dominant_col
    };
    let k = dominant.filter(|_| n >= 2 && an.significant)?;
    let f_hi = an.freq_hz.last().copied().filter(|f| *f > 0.0)?;
    let target = if rows {
        FactorTarget::Output(k)
    } else {
        FactorTarget::Input(k)
    };
    let cost = |f: f64, z: f64| -> f64 {
        let mut m = model.clone();
        if m.push_dynamics(DynamicsFactor::second_order(target, f, z))
            .is_err()
        {
            return f64::INFINITY;
        }
        additive_riv::fit_numerators(&mut m, fd).unwrap_or(f64::INFINITY)
    };
    let (lo, hi) = ABOVE_BAND;
    let nf = 12;
    // the grid's numerator fits are independent: both cores share them
    let grid: Vec<(f64, f64)> = (0..nf)
        .flat_map(|a| {
            let f = f_hi * lo * (hi / lo).powf(a as f64 / (nf - 1) as f64);
            [0.01, 0.05, 0.2].map(|z| (f, z))
        })
        .collect();
    let best = grid
        .into_par_iter()
        .map(|(f, z)| (cost(f, z), f, z))
        .reduce(
            || (f64::INFINITY, f_hi, 0.03),
            |a, b| if b.0 < a.0 { b } else { a },
        );
    if !best.0.is_finite() {
        return None;
    }
    let (f_hz, zeta) = screen_second_order(model, target, best.1, best.2, fd)?;
    // a start that the refinement pulled back into the band is the in-band candidates'
    (f_hz > f_hi).then_some((
        k,
        FactorStart {
            order: 2,
            f_hz,
            zeta,
            replaces: Vec::new(),
            delay_s: None,
            zeros: None,
            replaces_factor: None,
        },
    ))
}

/// The span of [`above_band`]'s frequency grid, in multiples of the top line: from just
/// above the band to where the rise in the band falls below a few percent of the
/// factor's own (`(1 / 4)^2` at the top line).
const ABOVE_BAND: (f64, f64) = (1.05, 4.0);

/// The start of a second-order factor on `target` added to `base`: the frequency and
/// damping, on a grid of `f_hz` times 0.92..1.08 and damping 0.005..0.2 refined once
/// around its best point, with the least cost after the numerator fit. `None` when no
/// grid point could be fitted.
fn screen_second_order(
    base: &AdditiveModel,
    target: FactorTarget,
    f_hz: f64,
    zeta: f64,
    fd: &FitData,
) -> Option<(f64, f64)> {
    let cost = |f: f64, z: f64| -> f64 {
        let mut m = base.clone();
        if m.push_dynamics(DynamicsFactor::second_order(target, f, z))
            .is_err()
        {
            return f64::INFINITY;
        }
        additive_riv::fit_numerators(&mut m, fd).unwrap_or(f64::INFINITY)
    };
    let mut best = (f64::INFINITY, f_hz, zeta.clamp(0.005, 0.2));
    let (mut lf, mut lz) = (f_hz.ln(), best.2.ln());
    let (mut hf, mut hz) = (0.08f64, (0.2f64 / 0.005).ln() / 2.0);
    let (mut cf, mut cz) = (lf, (0.005f64 * 0.2).sqrt().ln());
    for _ in 0..2 {
        for a in -3..=3 {
            for b in -2..=2 {
                let f = (cf + hf * a as f64 / 3.0).exp();
                let z = (cz + hz * b as f64 / 2.0).exp().clamp(0.002, 1.0);
                let c = cost(f, z);
                if c < best.0 {
                    best = (c, f, z);
                    (lf, lz) = (f.ln(), z.ln());
                }
            }
        }
        (cf, cz) = (lf, lz);
        hf /= 3.0;
        hz /= 2.0;
    }
    best.0.is_finite().then_some((best.1, best.2))
}

/// The span of [`traded_common_lag`]'s corner grid, in multiples of the top line: a
/// lag whose corner is far below the top line shows its own curvature to the
/// first-order signature; one far above it leaves a roll-off below the noise.
const TRADED_LAG: (f64, f64) = (0.25, 16.0);

/// A first-order factor common to every entry (an amplifier's or sensor's bandwidth)
/// that takes over part of the model's fitted delay. A lag `1 / (1 + s / w_c)` and a
/// delay share the phase slope at low frequency: the lag's group delay there is
/// `1 / w_c`, so a delay fitted without the lag holds it as well, and what the residual
/// keeps is the lag's magnitude roll-off (`1 / sqrt(1 + (w / w_c)^2)`) against a phase
/// the delay over-corrects at the top of the band. The common factor tested before the
/// delay was fitted started from a delay without that share, so it is tried again from
/// the traded start: corners on a log grid of [`TRADED_LAG`] times the top line,
/// refined twice around the best, each with the delay lowered by `1 / w_c` (never below
/// zero) and screened by the cost after the numerator fit (eq. 24: the numerators are
/// linear given the poles, the delay and the factor). The refit then frees the corner
/// and the delay together. Returns the start (its `delay_s` set), the numerator-fit
/// cost of the model as it is and the screened cost; `None` when the model's delay is
/// not fitted, it already has a common factor, or no grid point fits better.
fn traded_common_lag(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    fd: &FitData,
) -> Option<(FactorStart, f64, f64)> {
    let common = model.dynamics.iter().any(|d| d.target == FactorTarget::All);
    if !model.factor.fit_delay || common || model.nu() < 2 || !an.significant {
        return None;
    }
    let f_top = an.freq_hz.last().copied().filter(|f| *f > 0.0)?;
    let d = model.factor.delay_s;
    let cost = |f: f64| -> f64 {
        let traded = d - 1.0 / (std::f64::consts::TAU * f);
        if traded < 0.0 {
            return f64::INFINITY;
        }
        let mut m = model.clone();
        m.factor.delay_s = traded;
        if m.push_dynamics(DynamicsFactor::first_order(FactorTarget::All, f))
            .is_err()
        {
            return f64::INFINITY;
        }
        additive_riv::fit_numerators(&mut m, fd).unwrap_or(f64::INFINITY)
    };
    let base = additive_riv::fit_numerators(&mut model.clone(), fd).ok()?;
    let (lo, hi) = TRADED_LAG;
    let n = 13;
    let step = (hi / lo).ln() / (n - 1) as f64;
    let grid: Vec<f64> = (0..n)
        .map(|a| f_top * lo * (step * a as f64).exp())
        .collect();
    let pick = |pts: Vec<f64>| -> (f64, f64) {
        pts.into_par_iter().map(|f| (cost(f), f)).reduce(
            || (f64::INFINITY, f_top),
            |a, b| if b.0 < a.0 { b } else { a },
        )
    };
    let mut best = pick(grid);
    let mut h = step;
    for _ in 0..2 {
        h /= 3.0;
        let c = best.1.ln();
        let around = pick([-2.0, -1.0, 1.0, 2.0].map(|k| (c + k * h).exp()).to_vec());
        if around.0 < best.0 {
            best = around;
        }
    }
    let (c, f_hz) = best;
    (c.is_finite() && c < base).then(|| {
        (
            FactorStart {
                order: 1,
                f_hz,
                zeta: 1.0,
                replaces: Vec::new(),
                delay_s: Some(d - 1.0 / (std::f64::consts::TAU * f_hz)),
                zeros: None,
                replaces_factor: None,
            },
            base,
            c,
        )
    })
}

/// The share of the model's response at `omega` (rational part, Frobenius norm) that
/// submodel `sub` carries.
fn response_share(model: &AdditiveModel, sub: &additive_riv::Submodel, omega: f64) -> f64 {
    let (ny, nu) = (model.ny(), model.nu());
    let mut total = vec![realize::C64::new(0.0, 0.0); ny * nu];
    model.rational_into(omega, &mut total);
    let mut basis = Vec::new();
    model.basis_into(sub, omega, &mut basis);
    let mut part = vec![realize::C64::new(0.0, 0.0); ny * nu];
    for (b, coef) in sub.num.iter().zip(&basis) {
        for j in 0..nu {
            for i in 0..ny {
                part[j * ny + i] += *coef * b[(i, j)];
            }
        }
    }
    let norm = |v: &[realize::C64]| v.iter().map(|z| z.norm_sqr()).sum::<f64>().sqrt();
    norm(&part) / norm(&total).max(f64::MIN_POSITIVE)
}

/// The share of the lowest line's response a mode must carry for [`suspended_body`]:
/// it is what the data show of the body at the bottom of the band.
const BODY_SHARE: f64 = 0.5;

/// A mode below the suspension candidate of [`suspended_body`] that carries more than
/// this fraction of the candidate's share of the lowest line is a flexible mode below
/// it, not a weak duplicate of the first fit: there is no suspended body.
const DUPLICATE_SHARE: f64 = 0.2;

/// The suspended-body reading ([`suspended_body`]) applies to a mode at most this many
/// times the lowest line's frequency: above, the data show the mode's static
/// compliance flat over more than a decade below it, not a body a first fit could take
/// for a free one.
const SUSPENSION_MAX_OVER_LOWEST_LINE: f64 = 20.0;

/// The suspended-body reading of `model`: a body on a suspension whose frequency lies
/// in the band is, to a first fit that declares a free rigid body, a low mode with the
/// body's response below it (the body's static compliance `R / w_s^2` instead of the
/// free body's `R / (j w)^2`), and the rigid body is left with (almost) nothing. When
/// a mode (the one that carries the most there) carries at least [`BODY_SHARE`] of the response at the lowest line
/// (`omega_low`, rad/s), where a free body would dominate, and the free rigid body at
/// most half of that mode's share, the candidate is the `stiffness` of the catalogue in
/// place of both: the suspension `R / (s^2 + 2 zeta w_s s + w_s^2)` at the mode's
/// frequency and damping. It is tested by the parsimony side of the F test
/// ([`super::trial::suspended_body`]): the free body's parameters beside the
/// suspension must not be significant. `None` when the model has no free rigid body or
/// no mode, or the lowest line does not show the body in the mode.
pub fn suspended_body(model: &AdditiveModel, omega_low: f64) -> Option<Proposal> {
    let rb = model
        .submodels
        .iter()
        .find(|s| s.kind == SubmodelKind::RigidBody && s.integrators >= 1)?;
    if model
        .submodels
        .iter()
        .any(|s| s.kind == SubmodelKind::Suspension)
    {
        return None;
    }
    // the mode that carries the lowest line (not merely the lowest one: a first fit can
    // put a weak duplicate just below it)
    let shares: Vec<_> = model
        .modes()
        .into_iter()
        .filter(|m| m.zeta > 0.0)
        .map(|m| {
            let share = response_share(model, &model.submodels[m.submodel], omega_low);
            (m, share)
        })
        .collect();
    let (low, mode_share) = shares
        .iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(m, s)| (*m, *s))?;
    let rb_share = response_share(model, rb, omega_low);
    if !(mode_share >= BODY_SHARE && rb_share <= 0.5 * mode_share) {
        return None;
    }
    // A suspension is the body's lowest resonance: the flexible modes lie above it. A
    // mode below the candidate that carries more than a weak duplicate's share of the
    // lowest line makes the reading a structure's static compliance (the sum of its
    // modes' `R / w^2`, largest for a stiff high mode) rather than a suspended body: the
    // simulated piezo mechanism (no free body, modes 635-2770 Hz) had its 2770 Hz mode
    // read as a suspension beside a free rigid body of the first fit that carried 0.06 %
    // of its cost, and ended with 4 modes for 5.
    if shares
        .iter()
        .any(|(m, s)| m.f_hz < low.f_hz && *s > DUPLICATE_SHARE * mode_share)
    {
        return None;
    }
    // Lines far below the mode show its flat static compliance over decades, which no
    // free body has: a first fit had no reason to take a free body there, and the
    // "suspension" would be a mode under another name (the piezo mechanism on another
    // seed: its 635 Hz mode, lines from 0.78 Hz, again beside a free body of 0.03 % of
    // the cost). The tested suspensions lie at 0.4 to 8 times the lowest line.
    if low.f_hz > SUSPENSION_MAX_OVER_LOWEST_LINE * omega_low / std::f64::consts::TAU {
        return None;
    }
    let evidence = format!(
        "at the lowest line ({:.2} Hz) the mode at {:.3} Hz (zeta {:.4}) carries {:.0}% of the response and the free rigid body ({} integrator{}) {:.1}%: a body suspended at {:.3} Hz rather than a free one beside a mode?",
        omega_low / std::f64::consts::TAU,
        low.f_hz,
        low.zeta,
        100.0 * mode_share,
        rb.integrators,
        if rb.integrators == 1 { "" } else { "s" },
        100.0 * rb_share,
        low.f_hz
    );
    Some(Proposal {
        candidate: Candidate::Stiffness {
            f_hz: low.f_hz,
            zeta: low.zeta,
            replaces: Some(low.submodel),
        },
        evidence,
    })
}

/// The free rigid body of `model` as `R / s^l` (numerator zero when `l` changes: refit
/// it), at the body's own scale; an error when `model` has no free rigid body.
fn with_body_integrators(model: &mut AdditiveModel, l: usize) -> Result<(), RivError> {
    let i = model
        .submodels
        .iter()
        .position(|s| s.kind == SubmodelKind::RigidBody && s.integrators >= 1)
        .ok_or_else(|| RivError::Structure("no free rigid body (1/s^l) to keep".into()))?;
    if model.submodels[i].integrators == l {
        return Ok(());
    }
    let scale = model.submodels[i].scale;
    model.remove_submodel(i);
    model.push_rigid_body(l, scale)?;
    Ok(())
}

/// The key of a missed mode at `f_hz` (its frequency to 0.1 Hz).
fn mode_key(f_hz: f64) -> String {
    format!("{:.0}", f_hz * 10.0)
}

/// A signature worth a refit: significant at `alpha` and explaining at least 2 % of
/// the residual's excess energy (a refit costs about a second on the wafer stage; the
/// F test after it decides).
fn plausible(fit: &validation::signatures::TemplateFit, alpha: f64) -> bool {
    fit.p_value < alpha && fit.explained_fraction >= 0.02
}

/// The evidence line of `effect` in the analysis.
fn detail(an: &ResidualAnalysis, effect: Effect) -> String {
    an.evidence
        .iter()
        .find(|e| e.effect == effect)
        .map(|e| e.detail.clone())
        .unwrap_or_default()
}

/// Candidate augmentations of `model` from the residual: every effect of the catalogue
/// whose signature test is significant at `alpha` (the refit and its F test decide, so
/// the signature need not explain most of the residual), the hold whenever the sample
/// rate is known and the hold is not modelled, and the two strongest residual peaks as
/// missed modes. `data_delay_s` is the data's own total delay (a second start for the
/// delay); what `tested` holds is not proposed again.
pub fn propose(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    stats: &ResidualStats,
    fd: &FitData,
    fs_hz: Option<f64>,
    alpha: f64,
    tested: &[(Effect, String)],
    data_delay_s: Option<f64>,
) -> Vec<Proposal> {
    let mut out: Vec<Proposal> = Vec::new();
    let mut push = |candidate: Candidate, evidence: String| {
        out.push(Proposal {
            candidate,
            evidence,
        })
    };
    let seen = |e: Effect, key: &str| tested.iter().any(|(x, k)| *x == e && k == key);
    // missed mode: the two strongest residual peaks (local and Bonferroni tests)
    let peaks = additive_riv::structure::residual_peaks(stats, fd, alpha, 0.025);
    for &(f, ratio) in peaks.iter().take(2) {
        if !seen(Effect::MissedMode, &mode_key(f)) {
            let zeta = an
                .residual_cmif
                .iter()
                .filter(|p| (p.f_hz - f).abs() < 0.01 * f)
                .find_map(|p| p.damping)
                .unwrap_or(0.01)
                .clamp(0.002, 0.2);
            let ev = format!(
                "residual peak at {f:.2} Hz, {ratio:.1} x its local threshold; {}",
                detail(an, Effect::MissedMode)
            );
            push(
                Candidate::MissedMode {
                    f_hz: f,
                    zeta,
                    peak_hz: f,
                    body_integrators: None,
                },
                ev,
            );
        }
    }
    for p in delay_proposals(model, an, alpha, tested, data_delay_s) {
        push(p.candidate, p.evidence);
    }
    if let (Some(fs), additive_riv::Domain::Continuous) = (fs_hz, model.domain()) {
        if model.factor.derivative_order == 0 {
            let ev = match &an.hold {
                Some(h) => format!(
                    "sample rate {fs} Hz known; droop template amplitude {:.2} (1 = a hold at {fs} Hz), correlation {:.2}, {:.0}% of the excess",
                    h.amplitude,
                    h.correlation,
                    100.0 * h.fit.explained_fraction
                ),
                None => format!("sample rate {fs} Hz known"),
            };
            push(Candidate::Hold { fs_hz: fs }, ev);
        }
    }
    if !model.has_feedthrough() && plausible(&an.feedthrough.fit, alpha) {
        // inside the delay and hold (a biproper plant) or bypassing them (crosstalk)
        for bypass in [false, true] {
            push(
                Candidate::Feedthrough {
                    rms: an.feedthrough.rms_magnitude,
                    bypasses_delay: bypass,
                },
                format!(
                    "{}; tested {}",
                    detail(an, Effect::Feedthrough),
                    if bypass {
                        "as crosstalk that bypasses the delay and hold"
                    } else {
                        "inside the delay and hold"
                    }
                ),
            );
        }
    }
    // a suspended body seen from above its suspension frequency looks like 1/s^2 or,
    // with its damping, like 1/s to the first fit: either rigid body can be suspended
    let has_free_rb = model
        .submodels
        .iter()
        .any(|s| s.kind == SubmodelKind::RigidBody && s.integrators >= 1);
    if has_free_rb && plausible(&an.stiffness.fit, alpha) {
        let s = &an.stiffness;
        let f = if s.f_hz.is_finite() && s.f_hz > 0.0 {
            s.f_hz
        } else {
            s.equivalent_f_hz
        };
        if f.is_finite() && f > 0.0 {
            push(
                Candidate::Stiffness {
                    f_hz: f,
                    zeta: s.zeta,
                    replaces: None,
                },
                detail(an, Effect::Stiffness),
            );
            // The same signature read as a low mode beside the free body: a suspension
            // replaces the body's `R / s^l` by `R / (s^2 + 2 zeta w s + w^2)`, a low mode
            // keeps the body and adds the resonance. The two refits are nested (the free
            // body's parameters at zero give the suspension), so the round decides
            // between them by the F test of the body's parameters. The body is tried as
            // `R / s` and `R / s^2` (velocity or displacement of a free body).
            for l in [1, 2] {
                let c = Candidate::MissedMode {
                    f_hz: f,
                    zeta: s.zeta.clamp(0.002, 0.2),
                    peak_hz: f,
                    body_integrators: Some(l),
                };
                if !seen(Effect::MissedMode, &c.key()) {
                    push(
                        c,
                        format!(
                            "the suspension signature at {f:.3} Hz read as a mode beside the free rigid body R / s^{l}; {}",
                            detail(an, Effect::Stiffness)
                        ),
                    );
                }
            }
        }
    }
    propose_dynamics(model, an, fd, alpha, &seen, &mut push);
    out
}

/// The `delay` candidates of `propose` alone (cheap: no refit, no screening), for the
/// restart test before the loop ([`super::better_first_fit`]): the residual's phase slope
/// when it is plausible, and the data's own phase slope (`data_delay_s`, the total
/// delay of the data) beyond the model's delay and hold.
pub fn delay_proposals(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    alpha: f64,
    tested: &[(Effect, String)],
    data_delay_s: Option<f64>,
) -> Vec<Proposal> {
    let mut out: Vec<Proposal> = Vec::new();
    if !model.factor.fit_delay && plausible(&an.phase_trend.fit, alpha) {
        out.push(Proposal {
            candidate: Candidate::Delay {
                seconds: an.phase_trend.delay_s,
                start: DelayStart::ResidualSlope,
            },
            evidence: detail(an, Effect::Delay),
        });
    }
    // The residual's phase slope is biased when the model is far off (modes fitted
    // without the delay absorb part of it); the data's own phase slope, from the delay
    // estimator of frf-data, is a second start for the same effect.
    if let Some(total) = data_delay_s {
        let hold_half = match model.domain() {
            additive_riv::Domain::ZohDiscrete { ts } => 0.5 * ts,
            additive_riv::Domain::Continuous => 0.0,
        };
        let d = total - hold_half - model.factor.delay_s;
        let d_trend = an.phase_trend.delay_s;
        if !model.factor.fit_delay
            && an.significant
            && d.abs() > 1e-6
            && (d - d_trend).abs() > 1e-6
            && !tested
                .iter()
                .any(|(e, k)| *e == Effect::Delay && k == "data")
        {
            out.push(Proposal {
                candidate: Candidate::Delay {
                    seconds: d,
                    start: DelayStart::DataSlope,
                },
                evidence: format!(
                    "phase slope of the data: {:.2} us in all, {:.2} us beyond the model's delay (the residual's slope says {:.2} us)",
                    total * 1e6,
                    d * 1e6,
                    d_trend * 1e6
                ),
            });
        }
    }
    out
}

/// The dynamics-factor candidates: the row or column whose factor (of the order its
/// signature supports, [`validation::IoFactor::order`]) explains the most, and the
/// factor common to every entry, proposed with it (the trial tests both supports and
/// the refits' F tests decide) or on its own signature. A common factor is proposed as
/// `input_dynamics` with every input.
fn propose_dynamics(
    model: &AdditiveModel,
    an: &ResidualAnalysis,
    fd: &FitData,
    alpha: f64,
    seen: &dyn Fn(Effect, &str) -> bool,
    push: &mut dyn FnMut(Candidate, String),
) {
    let c = an.significance.line_scale;
    let band = (
        an.freq_hz.first().copied().unwrap_or(0.0),
        an.freq_hz.last().copied().unwrap_or(0.0),
    );
    let order_of = |f: &validation::IoFactor| f.order(c, alpha, band);
    let explained = |f: &validation::IoFactor| match order_of(f) {
        2 => f.second_order.fit.explained,
        _ => f.fit.explained,
    };
    let supported = |f: &validation::IoFactor| match order_of(f) {
        2 => plausible(&f.second_order.fit, alpha),
        _ => plausible(&f.fit, alpha),
    };
    let describe = |f: &validation::IoFactor, on: String, start: &FactorStart| -> String {
        let shape = if start.order == 2 {
            format!(
                "second order at {:.1} Hz, zeta {:.3} ({:.0}% of the excess; first order {:.0}%)",
                start.f_hz,
                start.zeta,
                100.0 * f.second_order.fit.explained_fraction,
                100.0 * f.fit.explained_fraction
            )
        } else {
            format!(
                "first order, corner {:.1} Hz ({:.0}% of the excess; second order {:.0}%)",
                start.f_hz,
                100.0 * f.fit.explained_fraction,
                100.0 * f.second_order.fit.explained_fraction
            )
        };
        format!(
            "factor on {on}: {shape}; {:.0}% of the excess in that support",
            100.0 * f.energy_fraction
        )
    };
    let mut any_support = false;
    // the all-pole candidates from the residual's signatures, to be tried with zeros too
    let mut twins: Vec<(Candidate, String)> = Vec::new();
    // the keys proposed in this round (a start above the band may repeat a signature's)
    let mut pushed: Vec<(Effect, String)> = Vec::new();
    for (effect, list, input) in [
        (Effect::InputDynamics, &an.input_dynamics, true),
        (Effect::OutputDynamics, &an.output_dynamics, false),
    ] {
        // the strongest row or column whose factor is significant
        let best = list
            .iter()
            .filter(|f| supported(f))
            .max_by(|a, b| explained(a).total_cmp(&explained(b)));
        let Some(f) = best else { continue };
        any_support = true;
        let start = FactorStart::from_signature(f, order_of(f));
        let on = format!("{} {}", if input { "input" } else { "output" }, f.index + 1);
        let ev = describe(f, on, &start);
        let candidate = one_factor(input, f.index, start);
        twins.push((candidate.clone(), ev.clone()));
        if seen(effect, &candidate.key()) {
            continue;
        }
        pushed.push((effect, candidate.key()));
        push(candidate, ev);
    }
    for (effect, input) in [
        (Effect::InputDynamics, true),
        (Effect::OutputDynamics, false),
    ] {
        for (k, start) in local_modes(model, an, fd, !input) {
            let candidate = one_factor(input, k, start.clone());
            if seen(effect, &candidate.key()) {
                continue;
            }
            any_support = true;
            let freqs: Vec<String> = start
                .replaces
                .iter()
                .filter_map(|&i| model.submodels.get(i))
                .filter_map(|s| model.upper_pole(s))
                .map(|p| format!("{:.1} Hz", p.norm() / std::f64::consts::TAU))
                .collect();
            let (what, share) = if input {
                ("input", an.concentration.col_fraction[k])
            } else {
                ("output", an.concentration.row_fraction[k])
            };
            let ev = format!(
                "the mode at {} lives in {what} {} alone, where {:.0}% of the residual's excess is: a resonance of that {what}'s dynamics rather than of the structure? second-order factor in its place, started at {:.1} Hz, zeta {:.3} (screened by the numerator fit)",
                freqs.join(", "),
                k + 1,
                100.0 * share,
                start.f_hz,
                start.zeta
            );
            pushed.push((effect, candidate.key()));
            push(candidate, ev);
        }
    }
    for (effect, input) in [
        (Effect::InputDynamics, true),
        (Effect::OutputDynamics, false),
    ] {
        let Some((k, start)) = above_band(model, an, fd, !input) else {
            continue;
        };
        let candidate = one_factor(input, k, start.clone());
        if seen(effect, &candidate.key()) || pushed.contains(&(effect, candidate.key())) {
            continue;
        }
        let what = if input { "input" } else { "output" };
        let ev = format!(
            "the residual concentrates in {what} {}: a resonance of that {what}'s dynamics above the band (top line {:.1} Hz)? second-order factor started at {:.1} Hz, zeta {:.3} (screened by the numerator fit)",
            k + 1,
            an.freq_hz.last().copied().unwrap_or(0.0),
            start.f_hz,
            start.zeta
        );
        push(candidate, ev);
    }
    if let Some((start, base, screened)) = traded_common_lag(model, an, fd) {
        let ev = format!(
            "the fitted delay ({:.2} us) may hold the low-frequency group delay 1/w_c of a lag common to every entry (an amplifier's bandwidth), whose magnitude roll-off the residual keeps: a first-order factor at {:.1} Hz with the delay lowered by 1/w_c = {:.2} us to {:.2} us lowers the cost after the numerator fit from {base:.4e} to {screened:.4e}; the refit frees the corner and the delay together",
            model.factor.delay_s * 1e6,
            start.f_hz,
            1e6 / (std::f64::consts::TAU * start.f_hz),
            start.delay_s.unwrap_or(f64::NAN) * 1e6
        );
        let candidate = Candidate::InputDynamics {
            inputs: (1..=model.nu()).collect(),
            start,
        };
        if !seen(Effect::InputDynamics, &candidate.key()) {
            push(candidate, ev);
        }
    }
    let common = &an.common_dynamics;
    if (any_support || supported(common)) && model.nu() > 1 {
        let start = FactorStart::from_signature(common, order_of(common));
        let ev = describe(common, "every entry (common to all inputs)".into(), &start);
        let candidate = Candidate::InputDynamics {
            inputs: (1..=model.nu()).collect(),
            start,
        };
        twins.push((candidate.clone(), ev.clone()));
        if !seen(Effect::InputDynamics, &candidate.key()) {
            push(candidate, ev);
        }
    }
    // the model's own all-pole factors (accepted in an earlier round), tried again with
    // a numerator of their order in their place
    for (k, d) in model.dynamics.iter().enumerate() {
        if !d.num.is_empty() || !(1..=2).contains(&d.den.len()) {
            continue;
        }
        let Some(p) = d.poles().into_iter().max_by(|a, b| a.im.total_cmp(&b.im)) else {
            continue;
        };
        let start = FactorStart {
            order: d.den.len(),
            f_hz: p.norm() / std::f64::consts::TAU,
            zeta: if d.den.len() == 2 {
                -p.re / p.norm()
            } else {
                1.0
            },
            replaces: Vec::new(),
            delay_s: None,
            zeros: None,
            replaces_factor: Some(k),
        };
        // an overdamped pair (two real poles) has no (frequency, damping) start of the
        // same factor
        if start.order == 2 && !(p.im > 0.0 && start.zeta > 0.0) {
            continue;
        }
        let candidate = match d.target {
            FactorTarget::Input(j) => one_factor(true, j, start),
            FactorTarget::Output(i) => one_factor(false, i, start),
            FactorTarget::All => Candidate::InputDynamics {
                inputs: (1..=model.nu()).collect(),
                start,
            },
        };
        twins.push((
            candidate,
            format!("the model's factor {} ({:?}, all-pole)", k + 1, d.target),
        ));
    }
    let f_top = band.1;
    for (all_pole, ev) in twins {
        let t_screen = std::time::Instant::now();
        let Some((twin, base, screened)) = with_numerator(model, fd, &all_pole, f_top) else {
            continue;
        };
        let t_screen = t_screen.elapsed().as_secs_f64();
        if seen(twin.effect(), &twin.key()) {
            continue;
        }
        let Some(start) = twin.factor_start() else {
            continue;
        };
        let (zf, zz) = start.zeros.unwrap_or((f64::NAN, f64::NAN));
        // a screened zero on its pole cancels the factor: nothing for a refit to test
        if screened >= base || (start.order == 1 && (zf / start.f_hz).ln().abs() < 0.05) {
            continue;
        }
        let shape = if start.order == 1 {
            format!("zero at {zf:.1} Hz, pole at {:.1} Hz", start.f_hz)
        } else {
            format!(
                "zeros at {zf:.1} Hz (zeta {zz:.3}), poles at {:.1} Hz (zeta {:.3})",
                start.f_hz, start.zeta
            )
        };
        let ev = format!(
            "{ev}; with a numerator of its order (a {}): {shape}, screened by the cost after the numerator fit ({screened:.4e}, the all-pole start {base:.4e}; {t_screen:.1} s); its zeros must be significant beside the all-pole factor",
            if start.order == 1 {
                "lead-lag"
            } else {
                "second-order rational"
            }
        );
        push(twin, ev);
    }
}

/// The start of the order-(n/n) rational twin of the all-pole dynamics candidate
/// `all_pole`: for order 1 the lead-lag `(1 + s / w_z) / (1 + s / w_p)` with its zero
/// and pole on a log grid of [`NUMERATOR_GRID`] times the top line `f_top` (a lead,
/// which no all-pole factor makes, and a lag-lead alike), for order 2 the candidate's
/// poles with zeros on the same frequency grid and damping 0.02..0.7; each point scored
/// by the cost after the numerator fit (eq. 24: the submodel numerators are linear given
/// the poles and the factor, so each point is one convex fit), refined three times on a
/// 3 x 3 pattern of halving steps around the best (60 fits for order 1, 48 for order
/// 2); a factor on some rows or columns is scored on their entries alone
/// ([`additive_riv::numerators::numerator_cost_of_entries`]: the other entries' fits do
/// not change). The refit then frees zeros and poles, and the trial's F test of the
/// zeros against the all-pole refit decides. Returns the twin, the numerator-fit cost
/// of the all-pole start and the screened one (both of every entry); `None` when
/// nothing could be fitted.
fn with_numerator(
    model: &AdditiveModel,
    fd: &FitData,
    all_pole: &Candidate,
    f_top: f64,
) -> Option<(Candidate, f64, f64)> {
    let start = all_pole.factor_start()?;
    if start.zeros.is_some() || !(f_top.is_finite() && f_top > 0.0) {
        return None;
    }
    let twin = |pole_hz: f64, zero_hz: f64, zero_zeta: f64| -> Candidate {
        let mut s = start.clone();
        if s.order == 1 {
            s.f_hz = pole_hz;
        }
        s.zeros = Some((zero_hz, zero_zeta));
        all_pole.with_start(s)
    };
    // every point changes the same entries (the factor's row or column): the grid is
    // scored on those entries alone, the others' share of the cost is the same at every
    // point
    let entries = factor_entries(all_pole, fd.ny, fd.nu);
    let cost = |c: &Candidate| -> f64 {
        match (c.augment(model), &entries) {
            (Ok(m), Some(es)) => additive_riv::numerators::numerator_cost_of_entries(&m, fd, es)
                .unwrap_or(f64::INFINITY),
            (Ok(mut m), None) => additive_riv::fit_numerators(&mut m, fd).unwrap_or(f64::INFINITY),
            (Err(_), _) => f64::INFINITY,
        }
    };
    let base = cost(all_pole);
    // the other entries' share, for the totals the evidence reports
    let others = match (&entries, all_pole.augment(model)) {
        (Some(_), Ok(mut m)) => {
            additive_riv::fit_numerators(&mut m, fd).unwrap_or(f64::INFINITY) - base
        }
        (Some(_), Err(_)) => f64::INFINITY,
        (None, _) => 0.0,
    };
    let (lo, hi) = NUMERATOR_GRID;
    let n = 6;
    let step = (hi / lo).ln() / (n - 1) as f64;
    let freqs: Vec<f64> = (0..n)
        .map(|a| f_top * lo * (step * a as f64).exp())
        .collect();
    // (log of the first coordinate, log of the second): order 1 (pole, zero) in Hz,
    // order 2 (zero Hz, zero damping)
    let point = |u: f64, v: f64| -> Candidate {
        if start.order == 1 {
            twin(u.exp(), v.exp(), 1.0)
        } else {
            twin(start.f_hz, u.exp(), v.exp().min(1.0))
        }
    };
    let grid: Vec<(f64, f64)> = if start.order == 1 {
        freqs
            .iter()
            .flat_map(|&p| freqs.iter().map(move |&z| (p.ln(), z.ln())))
            .collect()
    } else {
        freqs
            .iter()
            .flat_map(|&z| [0.02f64, 0.1, 0.3, 0.7].map(|d| (z.ln(), d.ln())))
            .collect()
    };
    let pick = |pts: Vec<(f64, f64)>| -> (f64, f64, f64) {
        pts.into_par_iter()
            .map(|(u, v)| (cost(&point(u, v)), u, v))
            .reduce(
                || (f64::INFINITY, 0.0, 0.0),
                |a, b| if b.0 < a.0 { b } else { a },
            )
    };
    let mut best = pick(grid);
    let (mut hu, mut hv) = (step, if start.order == 1 { step } else { 0.6 });
    for _ in 0..3 {
        hu /= 2.0;
        hv /= 2.0;
        let (u0, v0) = (best.1, best.2);
        let around: Vec<(f64, f64)> = (-1..=1)
            .flat_map(|a| (-1..=1).map(move |b| (u0 + hu * a as f64, v0 + hv * b as f64)))
            .filter(|&(a, b)| (a, b) != (u0, v0))
            .collect();
        let r = pick(around);
        if r.0 < best.0 {
            best = r;
        }
    }
    (best.0.is_finite() && others.is_finite())
        .then(|| (point(best.1, best.2), base + others, best.0 + others))
}

/// The entries (column-major indices `j ny + i` of `vec(G)`) that the dynamics-factor
/// candidate `c` changes, when they are some rows or columns only; `None` when it
/// changes every entry, the delay, or the model's submodels (a factor that replaces
/// modes).
fn factor_entries(c: &Candidate, ny: usize, nu: usize) -> Option<Vec<usize>> {
    let start = c.factor_start()?;
    if !start.replaces.is_empty() || start.delay_s.is_some() {
        return None;
    }
    match c {
        Candidate::InputDynamics { inputs, .. } if inputs.len() < nu => Some(
            inputs
                .iter()
                .filter(|&&j| (1..=nu).contains(&j))
                .flat_map(|&j| (0..ny).map(move |i| (j - 1) * ny + i))
                .collect(),
        ),
        Candidate::OutputDynamics { outputs, .. } if outputs.len() < ny => Some(
            outputs
                .iter()
                .filter(|&&i| (1..=ny).contains(&i))
                .flat_map(|&i| (0..nu).map(move |j| j * ny + i - 1))
                .collect(),
        ),
        _ => None,
    }
}

/// The span of [`with_numerator`]'s frequency grid, in multiples of the top line: from
/// a corner near the bottom of a typical motion band to a zero far enough above the top
/// line that the factor is nearly all-pole there.
const NUMERATOR_GRID: (f64, f64) = (0.02, 4.0);
