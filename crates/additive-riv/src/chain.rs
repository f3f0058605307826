//! The additive method as two links of the estimator chain:
//!
//! - [`CmifInit`] (`--init cmif`): CMIF peaks, the rigid-body choice and the convex
//!   numerator problem (24)-(25) of the wafer-stage paper (section 3.3 and 4.4): an
//!   initialiser (`Start = ()`);
//! - [`RivRefine`] (`--refine riv`): the refined IV iterations of Algorithm 1 (eq. 23)
//!   with the adaptation of the set of modes, from any [`ChainModel`]: the additive
//!   structure itself when the start carries one, otherwise the structure built from
//!   the currency ([`AdditiveModel::from_frf_model`]: its poles, rigid body, feedthrough
//!   and known factors) with the numerators of eq. (24).

use crate::complete::{complete_start, merge_coincident_peaks, CompleteConfig, CompleteReport};
use crate::init::{check_fs, choose_rigid_body, initial_model, InitConfig, RigidBody};
use crate::numerators::fit_numerators;
use crate::riv::{iterate, RivConfig};
use crate::structure::{adapt_modes, AdaptConfig, AdaptReport};
use crate::{AdditiveModel, Domain, FitData, KnownFactor, RivError, SubmodelKind};
use frf_data::cmif::{cmif, pick_peaks, CmifPeak, PeakConfig};
use frf_data::delay::{estimate_delay, DelayConfig, DelayEstimate};
use frf_data::{
    ChainModel, DelayChoice, Estimator, Fit, FrfDataset, ModeSelection, ModelStructure,
    Precomputed, ProgressSink, Weighting,
};
use realize::{FrfModel, Hold};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Settings of [`CmifInit`], with documented defaults.
#[derive(Debug, Clone)]
pub struct CmifInitConfig {
    /// Modes to start from. Default: every CMIF peak.
    pub modes: ModeSelection,
    /// CMIF peak picker settings. Default: [`PeakConfig::default`].
    pub peaks: PeakConfig,
    /// Model of the sampled measurement. Default: [`Hold::None`].
    pub hold: Hold,
    /// Delay handling. Default: [`DelayChoice::Auto`] (estimated, then a free parameter).
    pub delay: DelayChoice,
    /// Delay estimator settings.
    pub delay_config: DelayConfig,
    /// `k` of `(j w)^k`: 0 displacement (default), 1 velocity, 2 accelerance data.
    pub derivative_order: u32,
    /// Rigid-body submodel. Default: [`RigidBody::Auto`] (chosen by comparing the
    /// initial fits with 0, 1 and 2 integrators, F test at 1e-3).
    pub rigid_body: RigidBody,
    /// Add a feedthrough submodel. Default: false.
    pub feedthrough: bool,
    /// Initial damping of every mode (section 4.4). Default: 0.01.
    pub zeta0: f64,
    /// Weighting of the numerator problem. Default: [`Weighting::Auto`].
    pub weighting: Weighting,
    /// Progress callback.
    pub progress: ProgressSink,
    /// The data's delay estimate and CMIF when the caller already has them (used in
    /// place of estimating the delay with `delay_config` and of computing the CMIF).
    /// Default: none.
    pub precomputed: Precomputed,
    /// Completion of the start ([`crate::complete`]): coincident peaks merged, poles
    /// settled, the rigid body chosen again (with [`RigidBody::Auto`]) and modes added at
    /// significant peaks of the residual's CMIF (with [`ModeSelection::Auto`]). Default:
    /// `Some(CompleteConfig::default())`; `None` gives the plain initialisation of
    /// section 4.4.
    pub complete: Option<CompleteConfig>,
}

impl Default for CmifInitConfig {
    fn default() -> Self {
        Self {
            modes: ModeSelection::Auto,
            peaks: PeakConfig::default(),
            hold: Hold::None,
            delay: DelayChoice::Auto,
            delay_config: DelayConfig::default(),
            derivative_order: 0,
            rigid_body: RigidBody::Auto,
            feedthrough: false,
            zeta0: 0.01,
            weighting: Weighting::Auto,
            progress: ProgressSink::none(),
            precomputed: Precomputed::default(),
            complete: Some(CompleteConfig::default()),
        }
    }
}

/// What [`CmifInit`] found.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct CmifInitReport {
    /// The CMIF peaks the initialisation started from.
    pub cmif_peaks: Vec<CmifPeak>,
    /// The delay estimate, when the delay was estimated.
    pub delay_estimate: Option<DelayEstimate>,
    /// Integrators of the rigid-body submodel.
    pub integrators: usize,
    /// The weighting used.
    pub weighting: String,
    /// Weighted cost (8) of the initial model.
    pub init_cost: f64,
    /// Band fitted, Hz.
    pub band_hz: (f64, f64),
    /// What the completion of the start did, when it ran.
    pub completion: Option<CompleteReport>,
}

#[typetag::serde(name = "cmif")]
impl frf_data::LinkDetails for CmifInitReport {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// The CMIF + convex-numerator initialiser (section 3.3 and 4.4 of the wafer-stage
/// paper): poles at the CMIF peaks with damping `zeta0`, a rigid body chosen from the
/// data, numerators from the convex problem (24).
#[derive(Debug, Clone, Default)]
pub struct CmifInit {
    /// Settings.
    pub config: CmifInitConfig,
}

impl CmifInit {
    /// An initialiser with the given settings.
    pub fn new(config: CmifInitConfig) -> Self {
        Self { config }
    }

    /// The part of the delay the exact hold models itself (half a sample).
    pub fn hold_share(&self) -> f64 {
        match self.config.hold {
            Hold::Zoh { fs_hz } => 0.5 / fs_hz,
            _ => 0.0,
        }
    }
}

/// The additive domain of a hold: the exact zero-order hold is fitted in the shift
/// variable; a `sinc` hold is a known factor of a continuous model.
pub fn domain_of(hold: Hold, band_hi_hz: f64) -> Result<(Domain, Option<f64>), RivError> {
    Ok(match hold {
        Hold::None => (Domain::Continuous, None),
        Hold::Zoh { fs_hz } => {
            check_fs(fs_hz, band_hi_hz)?;
            (Domain::ZohDiscrete { ts: 1.0 / fs_hz }, None)
        }
        Hold::Sinc { fs_hz } => {
            check_fs(fs_hz, band_hi_hz)?;
            (Domain::Continuous, Some(fs_hz))
        }
    })
}

impl Estimator for CmifInit {
    type Model = AdditiveModel;
    type Start = ();
    type Report = CmifInitReport;
    type Error = RivError;

    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        _start: (),
    ) -> Result<Fit<AdditiveModel, CmifInitReport>, RivError> {
        let cfg = &self.config;
        let t0 = Instant::now();
        let weighting = cfg.weighting.resolve(data);
        let fd = FitData::new(data, &weighting)?;
        let mut report = CmifInitReport {
            weighting: weighting.name().to_string(),
            band_hz: fd.band_hz,
            ..Default::default()
        };
        cfg.progress
            .step("prepare", 1, Some(5), None, "data and weights");
        let (domain, sinc) = domain_of(cfg.hold, fd.band_hz.1)?;
        let mut timings = Vec::new();
        let (delay_s, fit_delay) = match cfg.delay {
            DelayChoice::None => (0.0, false),
            DelayChoice::Fixed { seconds } => (seconds, false),
            DelayChoice::Start { seconds } => (seconds, true),
            DelayChoice::Auto => {
                let t = Instant::now();
                let est = match &cfg.precomputed.delay {
                    Some(d) => d.clone(),
                    None => estimate_delay(data, &cfg.delay_config)?,
                };
                timings.push(("delay", t.elapsed()));
                let tau = est.tau_s - self.hold_share();
                report.delay_estimate = Some(est);
                (tau, true)
            }
        };
        let factor = KnownFactor {
            delay_s,
            fit_delay,
            derivative_order: cfg.derivative_order,
            sinc_hold_fs: sinc,
        };
        cfg.progress
            .step("cmif", 2, Some(5), None, "mode indicator");
        let t = Instant::now();
        let freqs: Vec<f64> = match &cfg.modes {
            ModeSelection::Frequencies(f) => f.clone(),
            sel => {
                let computed;
                let c = match cfg.precomputed.cmif_of(data) {
                    Some(c) => c,
                    None => {
                        computed = cmif(data)?;
                        &computed
                    }
                };
                let mut pc = cfg.peaks.clone();
                if let ModeSelection::Count(n) = sel {
                    pc.n_modes = Some(*n);
                }
                let peaks = pick_peaks(c, &pc);
                let f = match (&cfg.complete, sel) {
                    (Some(cc), ModeSelection::Auto) => {
                        merge_coincident_peaks(&peaks, cc.merge_fraction, cfg.zeta0)
                    }
                    _ => peaks.iter().map(|p| p.f_hz).collect(),
                };
                report.cmif_peaks = peaks;
                f
            }
        };
        timings.push(("cmif", t.elapsed()));
        let t = Instant::now();
        let base = InitConfig {
            domain,
            factor,
            rigid_body: cfg.rigid_body,
            feedthrough: cfg.feedthrough,
            zeta0: cfg.zeta0,
            first_order_numerators: false,
        };
        let mut init = match cfg.rigid_body {
            RigidBody::Auto => choose_rigid_body(&fd, &freqs, &base)?,
            _ => initial_model(&fd, &freqs, &base)?,
        };
        timings.push(("init", t.elapsed()));
        if let Some(cc) = &cfg.complete {
            let t = Instant::now();
            let add = matches!(cfg.modes, ModeSelection::Auto);
            let unit_variance = matches!(weighting, Weighting::InverseVariance);
            let (model, rep) = complete_start(
                init.model.clone(),
                &fd,
                unit_variance,
                cfg.rigid_body == RigidBody::Auto,
                add,
                cc,
            )?;
            init.model = model;
            init.cost_history
                .push(crate::residual_stats::cost_of(&init.model, &fd) / (2.0 * fd.n as f64));
            init.messages.push(format!(
                "start completed ({} iterations of Algorithm 1 at a coarse tolerance): {}{}",
                rep.iterations,
                if rep.added.is_empty() {
                    "no mode added".to_string()
                } else {
                    format!(
                        "modes added at residual CMIF peaks: {}",
                        rep.added
                            .iter()
                            .map(|f| format!("{f:.2} Hz"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                },
                if rep.integrators.0 != rep.integrators.1 {
                    format!(
                        "; rigid body with the settled poles: {} -> {} integrator(s)",
                        rep.integrators.0, rep.integrators.1
                    )
                } else {
                    String::new()
                }
            ));
            report.completion = Some(rep);
            timings.push(("complete", t.elapsed()));
        }
        report.integrators = init.model.integrators();
        report.init_cost = init.final_cost().unwrap_or(f64::NAN);
        let mut fit = init.with_report(report);
        if let Some(d) = &fit.report.delay_estimate {
            fit.messages.push(format!(
                "delay estimate {:.2} us (coherence {:.2}); {} the iterations",
                d.tau_s * 1e6,
                d.coherence,
                if fit_delay {
                    "refined in"
                } else {
                    "fixed during"
                }
            ));
        }
        fit.messages.push(format!(
            "{} CMIF peaks started the fit; weighting: {}",
            freqs.len(),
            weighting.name()
        ));
        fit.estimator = "CMIF peaks + convex numerators (eq. 24)".into();
        fit.timings.clear();
        for (stage, d) in timings {
            fit.push_timing(stage, d);
        }
        fit.push_timing("total", t0.elapsed());
        Ok(fit)
    }
}

/// Settings of [`RivRefine`], with documented defaults.
#[derive(Debug, Clone)]
pub struct RivRefineConfig {
    /// Iteration settings (method, weighting, tolerances). Default: [`RivConfig::default`].
    pub riv: RivConfig,
    /// Add/drop modes after the first refinement. Default: `Some(default)`; `None` runs
    /// Algorithm 1 once from the start.
    pub adapt: Option<AdaptConfig>,
    /// Initial damping given to a start pole that is not in the open left half-plane
    /// (the additive structure holds stable modes only). Default: 0.01.
    pub zeta_unstable: f64,
}

impl Default for RivRefineConfig {
    fn default() -> Self {
        Self {
            riv: RivConfig::default(),
            adapt: Some(AdaptConfig::default()),
            zeta_unstable: 0.01,
        }
    }
}

/// What [`RivRefine`] did.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RivReport {
    /// The weighting used.
    pub weighting: String,
    /// Whether it continued the additive structure of the start (`native`) or built one
    /// from the model currency (`currency`).
    pub start: String,
    /// Mode additions and removals of the adaptation.
    pub adapt: Option<AdaptReport>,
}

#[typetag::serde(name = "riv")]
impl frf_data::LinkDetails for RivReport {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// The refined-IV refiner of the chain (Algorithm 1 of the wafer-stage paper with the
/// adaptation of the set of modes), from any [`ChainModel`]. From another
/// initialiser's model (the currency start) with the adaptation on, the rigid body
/// (0, 1 or 2 integrators) is chosen again with the refined poles
/// ([`crate::complete::rigid_body_again`]) and the fit refined again when that lowers
/// the cost.
#[derive(Debug, Clone, Default)]
pub struct RivRefine {
    /// Settings.
    pub config: RivRefineConfig,
}

impl RivRefine {
    /// A refiner with the given settings.
    pub fn new(config: RivRefineConfig) -> Self {
        Self { config }
    }
}

impl Estimator for RivRefine {
    type Model = AdditiveModel;
    type Start = ChainModel;
    type Report = RivReport;
    type Error = RivError;

    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        start: ChainModel,
    ) -> Result<Fit<AdditiveModel, RivReport>, RivError> {
        let t0 = Instant::now();
        if data.ny() != start.model.ny() || data.nu() != start.model.nu() {
            return Err(RivError::invalid(
                "start model",
                format!("{}x{}", start.model.ny(), start.model.nu()),
                format!("the data are {}x{}", data.ny(), data.nu()),
            ));
        }
        let weighting = self.config.riv.weighting.resolve(data);
        let fd = FitData::new(data, &weighting)?;
        let mut messages = Vec::new();
        let (model, kind) = match start.native::<AdditiveModel>() {
            Some(m) => (m.clone(), "native"),
            None => {
                let (mut m, notes) = AdditiveModel::from_frf_model(
                    &start.model,
                    fd.band_hz,
                    self.config.zeta_unstable,
                )?;
                messages.extend(notes);
                fit_numerators(&mut m, &fd)?;
                (m, "currency")
            }
        };
        let mut riv = self.config.riv.clone();
        riv.weighting = weighting.clone();
        let mut report = RivReport {
            weighting: weighting.name().to_string(),
            start: kind.to_string(),
            adapt: None,
        };
        let fit = match &self.config.adapt {
            Some(a) => {
                let (f, rep) = adapt_modes(model, &fd, &riv, a)?;
                report.adapt = Some(rep);
                f
            }
            None => iterate(model, &fd, &riv)?,
        };
        let mut fit = fit;
        if kind == "currency" && self.config.adapt.is_some() {
            // the start's rigid body is another method's choice: chosen again with the
            // refined poles
            let before = fit.model.integrators();
            if let Some(m) =
                crate::complete::rigid_body_again(&fit.model, &fd, &CompleteConfig::default())
            {
                let again = iterate(m, &fd, &riv)?;
                let (c0, c1) = (
                    fit.final_cost().unwrap_or(f64::INFINITY),
                    again.final_cost().unwrap_or(f64::INFINITY),
                );
                if c1 < c0 {
                    messages.push(format!(
                        "rigid body chosen again with the refined poles: {before} -> {} integrator(s), cost {c0:.4e} -> {c1:.4e}",
                        again.model.integrators()
                    ));
                    let mut history = std::mem::take(&mut fit.cost_history);
                    history.extend_from_slice(&again.cost_history);
                    let iterations = fit.iterations + again.iterations;
                    let mut notes = std::mem::take(&mut fit.messages);
                    fit = again;
                    notes.append(&mut fit.messages);
                    fit.messages = notes;
                    fit.cost_history = history;
                    fit.iterations = iterations;
                }
            }
        }
        let mut fit = fit.with_report(report);
        messages.append(&mut fit.messages);
        fit.messages = messages;
        fit.estimator = format!(
            "additive {} ({})",
            match riv.method {
                crate::IvMethod::Riv => "RIV, Algorithm 1",
                crate::IvMethod::Sk => "SK iterations",
            },
            weighting.name()
        );
        fit.push_timing("total", t0.elapsed());
        Ok(fit)
    }
}

/// Largest relative real part `||Re r|| / ||r||` (Frobenius) of a pole pair's residue
/// that a constant numerator represents (see [`AdditiveModel::from_frf_model`]).
pub const PROPORTIONAL_RESIDUE_TOL: f64 = 1e-2;

/// True when the residue `r` of a pole pair is (within [`PROPORTIONAL_RESIDUE_TOL`])
/// that of a constant real numerator `B_0 / (s^2 + 2 zeta w s + w^2)`, eq. (26):
/// `r = B_0 / (2 j w_d)`, purely imaginary. A residue with a real part (a mode of a
/// structure whose damping is not proportional, as a common-denominator or subspace
/// fit of real data returns) needs the first-order numerator `B_0 + B_1 s`.
fn is_proportional(r: &faer::Mat<frf_data::C64>, tol: f64) -> bool {
    let (mut re, mut all) = (0.0, 0.0);
    for j in 0..r.ncols() {
        for i in 0..r.nrows() {
            re += r[(i, j)].re * r[(i, j)].re;
            all += r[(i, j)].norm_sqr();
        }
    }
    re <= tol * tol * all
}

impl AdditiveModel {
    /// The additive structure of a currency model, for a refiner: the domain from its
    /// hold (the exact zero-order hold in the shift variable), its known factors, one
    /// rigid-body submodel with as many integrators as its rigid part has terms, one
    /// mode per pole pair (constant numerator, eq. 26; in continuous time `B_0 + B_1 s`
    /// when the pair's residue has a real part above [`PROPORTIONAL_RESIDUE_TOL`] of its
    /// size, which a constant numerator cannot represent), one first-order submodel per
    /// real pole, a feedthrough when it has one and a crosstalk as a feedthrough that
    /// bypasses the delay. The numerators are left at zero: fit them with
    /// [`fit_numerators`] (eq. 24) on the data. `band_hz` sets the rigid body's frequency
    /// scale. A pole pair outside the open left half-plane is given the damping
    /// `zeta_unstable` (and a note says so).
    pub fn from_frf_model(
        fm: &FrfModel,
        band_hz: (f64, f64),
        zeta_unstable: f64,
    ) -> Result<(AdditiveModel, Vec<String>), RivError> {
        Self::from_frf_model_with(fm, band_hz, zeta_unstable, PROPORTIONAL_RESIDUE_TOL)
    }

    /// [`from_frf_model`](Self::from_frf_model) with the largest relative real part of a
    /// residue that a constant numerator represents given as `proportional_tol`. A
    /// constant numerator drops that real part, which changes the mode's contribution
    /// by about `proportional_tol` of itself near its resonance: for a final model,
    /// keep it well below the data's relative noise level (a refiner that fitted a
    /// delay turns the residues' phases by up to `w tau`, a real part of 1e-3 to 1e-2
    /// that the default tolerance would drop: 8 times the noise on a 20 x 20 plant with
    /// noise 1e-3).
    pub fn from_frf_model_with(
        fm: &FrfModel,
        band_hz: (f64, f64),
        zeta_unstable: f64,
        proportional_tol: f64,
    ) -> Result<(AdditiveModel, Vec<String>), RivError> {
        fm.validate()?;
        let f = &fm.factors;
        let (domain, sinc) = domain_of(f.hold, band_hz.1)?;
        let mut notes = Vec::new();
        let mut m = AdditiveModel::new(fm.ny(), fm.nu(), domain)?.with_factor(KnownFactor {
            delay_s: f.delay_s,
            fit_delay: f.delay_fitted,
            derivative_order: f.derivative_order,
            sinc_hold_fs: sinc,
        })?;
        for d in &f.dynamics {
            m.push_dynamics(d.clone())?;
        }
        if !fm.modal.rigid.is_empty() {
            m.push_rigid_body(
                fm.modal.rigid.len(),
                AdditiveModel::rigid_scale(band_hz.0, band_hz.1),
            )?;
        }
        let nyq = match domain {
            Domain::ZohDiscrete { ts } => 0.5 / ts,
            Domain::Continuous => f64::INFINITY,
        };
        let mut pairs: Vec<(f64, f64, bool)> = fm
            .modal
            .pairs
            .iter()
            .map(|p| {
                (
                    p.f_hz(),
                    p.zeta(),
                    domain == Domain::Continuous && !is_proportional(&p.residue, proportional_tol),
                )
            })
            .collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (f_hz, zeta, first_order) in pairs {
            if f_hz >= nyq {
                notes.push(format!(
                    "start mode at {f_hz:.2} Hz is at or above the Nyquist frequency of the hold ({nyq:.1} Hz): left out"
                ));
                continue;
            }
            let z = if zeta > 0.0 && zeta < 1.0 {
                zeta
            } else {
                notes.push(format!(
                    "start mode at {f_hz:.2} Hz has damping {zeta:.3e} (not stable): started with damping {zeta_unstable}"
                ));
                zeta_unstable
            };
            m.push_mode(f_hz, z, first_order)?;
        }
        for rp in &fm.modal.real_poles {
            let p = if rp.pole < 0.0 {
                rp.pole
            } else {
                notes.push(format!(
                    "start real pole at {:.3e} rad/s is not stable: reflected",
                    rp.pole
                ));
                -rp.pole.abs().max(1e-9)
            };
            m.push_real_pole(p)?;
        }
        let has_d = (0..fm.ny()).any(|i| (0..fm.nu()).any(|j| fm.modal.feedthrough[(i, j)] != 0.0));
        if f.crosstalk.is_some() {
            m.push_bypass_feedthrough()?;
            if has_d {
                notes.push(
                    "the start has both a feedthrough and a crosstalk: kept the crosstalk (one biproper submodel)".into(),
                );
            }
        } else if has_d {
            m.push_feedthrough()?;
        }
        if m.submodels.is_empty() {
            return Err(RivError::Structure(
                "the start model has no poles, rigid body or feedthrough".into(),
            ));
        }
        Ok((m, notes))
    }

    /// Adds a first-order submodel `B / (s - p)` for a real stable pole `p` (rad/s), with
    /// its numerator at zero (the exact zero-order-hold image in discrete time).
    pub fn push_real_pole(&mut self, p: f64) -> Result<usize, RivError> {
        if !(p.is_finite() && p < 0.0) {
            return Err(RivError::invalid(
                "real pole",
                p,
                "must be finite and < 0 rad/s",
            ));
        }
        let (ny, nu) = (self.ny(), self.nu());
        let sub = match self.domain() {
            // A(x) = 1 + a x with x = s / |p|: root x = -1/a, s = p for a = 1
            Domain::Continuous => crate::Submodel {
                kind: SubmodelKind::General,
                integrators: 0,
                den: vec![1.0],
                num_start: 0,
                num: vec![faer::Mat::zeros(ny, nu)],
                scale: -p,
                num_poly: vec![1.0],
                zoh_shape: false,
                bypass_factor: false,
            },
            // zoh(1/(s-p)) = c q / (1 - z_p q): A(q) = 1 - z_p q, numerator from q^1
            Domain::ZohDiscrete { ts } => crate::Submodel {
                kind: SubmodelKind::General,
                integrators: 0,
                den: vec![-(p * ts).exp()],
                num_start: 1,
                num: vec![faer::Mat::zeros(ny, nu)],
                scale: 1.0,
                num_poly: vec![1.0],
                zoh_shape: false,
                bypass_factor: false,
            },
        };
        self.push_submodel(sub)
    }

    /// The currency form of this model: the rational part of the submodels that see the
    /// known factor ([`AdditiveModel::to_modal_model`]), the known factor and dynamics,
    /// and the submodels that bypass the factor as the crosstalk.
    pub fn to_frf_model_exact(&self) -> Result<FrfModel, RivError> {
        let mut inner = self.clone();
        inner.submodels.retain(|s| !s.bypass_factor);
        let modal = inner.to_modal_model()?;
        let crosstalk = if self.submodels.iter().any(|s| s.bypass_factor) {
            let mut outer = self.clone();
            outer.submodels.retain(|s| s.bypass_factor);
            let mm = outer.to_modal_model()?;
            if !(mm.pairs.is_empty() && mm.real_poles.is_empty() && mm.rigid.is_empty()) {
                return Err(RivError::Structure(
                    "only a constant (feedthrough) submodel can bypass the known factor".into(),
                ));
            }
            Some(mm.feedthrough)
        } else {
            None
        };
        let hold = match (self.domain(), self.factor.sinc_hold_fs) {
            (Domain::ZohDiscrete { ts }, _) => Hold::Zoh { fs_hz: 1.0 / ts },
            (Domain::Continuous, Some(fs_hz)) => Hold::Sinc { fs_hz },
            (Domain::Continuous, None) => Hold::None,
        };
        Ok(FrfModel {
            modal,
            factors: realize::KnownFactors {
                delay_s: self.factor.delay_s,
                delay_fitted: self.factor.fit_delay,
                derivative_order: self.factor.derivative_order,
                hold,
                dynamics: self.dynamics.clone(),
                crosstalk,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use frf_data::{Frf, Weighting, C64};
    use realize::{FrfModel, ModalModel, PolePair};
    use std::f64::consts::TAU;

    /// A 2 x 1 continuous model with two modes: one of proportional damping (residue
    /// purely imaginary) and one whose residue has a real part (a non-proportional
    /// structure). Its exact response goes through `from_frf_model` and the numerator
    /// fit (eq. 24): the model is reproduced to rounding, the second mode with a
    /// first-order numerator, the first with a constant one.
    #[test]
    fn a_complex_residue_gets_a_first_order_numerator() {
        let mut m = ModalModel::new(2, 1);
        let pole = |f: f64, z: f64| C64::new(-z * TAU * f, TAU * f * (1.0 - z * z).sqrt());
        let imag = Mat::from_fn(2, 1, |i, _| C64::new(0.0, -(1.0 + i as f64) * 100.0));
        let general = Mat::from_fn(2, 1, |i, _| C64::new(40.0 * (1.0 - 2.0 * i as f64), -150.0));
        m.pairs.push(PolePair {
            pole: pole(50.0, 0.02),
            residue: imag,
        });
        m.pairs.push(PolePair {
            pole: pole(180.0, 0.01),
            residue: general,
        });
        let fm = FrfModel::new(m);
        let f: Vec<f64> = (0..400).map(|k| 10.0 + 390.0 * k as f64 / 399.0).collect();
        let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
        let g = fm.freq_response(&w).unwrap();
        let data = Frf::new(f, 2, 1, g.values.clone(), None).unwrap();
        let (mut am, _) = AdditiveModel::from_frf_model(&fm, (10.0, 400.0), 0.01).unwrap();
        let orders: Vec<usize> = am.submodels.iter().map(|s| s.num.len()).collect();
        assert_eq!(orders, vec![1, 2]);
        let fd = FitData::new(&data, &Weighting::Uniform).unwrap();
        fit_numerators(&mut am, &fd).unwrap();
        let back = am.to_frf_model().unwrap();
        let (median, _) = back.relative_error(&w, &g).unwrap();
        assert!(median < 1e-10, "median relative error {median:.3e}");
    }
}
