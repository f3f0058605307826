//! [`SubspaceInit`]: the frequency-domain subspace fit as an initialiser of the
//! estimator chain (`--init subspace`).

use crate::currency::{classify, eigen_weights, fit_residues, PoleSet, ReflectedPole};
use crate::delay_refine::{
    self, huber, line_residuals, DelayCost, DelayPass, DelayRefinement, RotatedCost,
};
use crate::order::{
    f_critical, f_statistic, f_sweep, largest_gap, numerical_rank, OrderRule, OrderScore,
    SweepSettings, RANK_TOL,
};
use crate::pole_refine::{refine_poles, PoleRefineSettings};
use crate::prepare::{prepare, Prepared, Variable};
use crate::projection::project;
use crate::realization::{bilinear_to_continuous, fit_b_d, shift_a_c};
use crate::SubspaceError;
use frf_data::delay::{estimate_delay, DelayConfig, DelayEstimate};
use frf_data::{
    Convergence, DelayChoice, Estimator, Fit, FrfDataset, Precomputed, ProgressSink, Weighting,
};
use realize::{FrfModel, Hold, KnownFactors, StateSpace, TimeDomain, C64};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Settings of [`SubspaceInit`], with documented defaults.
#[derive(Debug, Clone)]
pub struct SubspaceConfig {
    /// The hold of the sampled measurement. [`Hold::Zoh`] fits in `z = exp(j w Ts)`
    /// (exact); anything else fits a continuous model through the bilinear map. Default:
    /// [`Hold::None`].
    pub hold: Hold,
    /// Delay handling: `Fixed` divides the delay out, `Auto` estimates it first (delay
    /// periodogram of `frf_data::delay`, the hold's half sample taken out) and marks it
    /// as a free parameter for a refiner, `Start` divides out the start value and marks
    /// it free, `None` leaves the data as they are. Default: [`DelayChoice::Auto`].
    pub delay: DelayChoice,
    /// Delay estimator settings. Default: [`DelayConfig::default`].
    pub delay_config: DelayConfig,
    /// Refine a free delay (`Auto` or `Start`) inside the initialiser (see
    /// [`crate::delay_refine`]): with the subspace poles fixed the residue refit is
    /// linear, its cost a function of the delay alone, minimised around the start;
    /// when the delay moved by more than `delay_tol_rad`, the subspace step is repeated
    /// with the refined delay divided out. The model of the lowest cost is kept.
    /// Default: true.
    pub refine_delay: bool,
    /// Most subspace steps of the delay refinement (the first included). Default: 3.
    pub delay_passes: usize,
    /// Half-width of the delay search bracket around each pass's start, seconds;
    /// `None`: a tenth of the period of the highest line (a phase of +-0.63 rad there;
    /// 50 us for a band ending at 2 kHz). Default: `None`.
    pub delay_half_width: Option<f64>,
    /// Points of the scan of the bracket before the slope's zero is found. Default: 21.
    pub delay_grid: usize,
    /// The subspace step is repeated when the delay moved by more than this phase at
    /// the highest line, rad. Default: 1e-4.
    pub delay_tol_rad: f64,
    /// `k` of `(j w)^k`: 0 displacement (default), 1 velocity, 2 accelerance data.
    pub derivative_order: u32,
    /// Weighting: [`Weighting::Uniform`] runs the unweighted algorithm; any other
    /// weighting runs the noise-covariance weighted variant with the inverse weights as
    /// the variance, and weights (17) and the residue fit. Default: [`Weighting::Auto`]
    /// (the data's variance when they carry one, eq. (27) of the wafer-stage paper
    /// otherwise).
    pub weighting: Weighting,
    /// Model order (number of states); `None` chooses it from the singular values
    /// (largest log gap, see [`crate::order`]). Default: `None`.
    pub order: Option<usize>,
    /// Largest order considered when it is chosen from the data. Default: 60. With the
    /// data's variance it is doubled while every singular value up to it is above the
    /// noise threshold (and the lines support the larger order), so that a large plant
    /// is not cut at 60 states.
    pub max_order: usize,
    /// How the order is chosen when it is not given, and whether the significance tests
    /// run (see [`OrderRule`]). Default: [`OrderRule::Auto`] (the order from the
    /// singular values; the rigid-body integrators the singular values missed added by
    /// an F test, without the data's variance only when they also lower the cost 2x,
    /// at once or after passes on the flexible part).
    pub order_rule: OrderRule,
    /// Significance level of the order F test (the diagnosis's and the SK sweep's
    /// default). Default: 1e-3.
    pub order_alpha: f64,
    /// Practical-significance floor of the F statistics of the order sweep and the
    /// integrator test (the diagnosis's `min_f`: measured noise is heavier-tailed than
    /// Gaussian, and a state placed by the subspace step absorbs the misfit of the other
    /// subspace poles, which are not maximum-likelihood estimates; such states reach F
    /// of 2..10, real ones 1e3 and more). Default: 25.
    pub order_min_f: f64,
    /// The F-test sweep starts this many orders below the singular-value proposal.
    /// Default: 4.
    pub sweep_below: usize,
    /// The sweep stops after this many consecutive orders that are not kept (a mode
    /// with a rank-2 residue adds four states; one state of a pair alone may not be
    /// significant). Default: 4.
    pub sweep_patience: usize,
    /// Block rows `r` of the data equation (6); `None`: `2 ceil(n_max / p) + 1` with
    /// `n_max` the given order or `max_order` (about twice what (12) needs: more rows
    /// average the noise better; on the reference wafer stage the median error falls
    /// from 8e-4 at 16 rows to 3.6e-5 at 31 and 2.1e-5 at 60, at a cost growing as
    /// `r^2`). Default: `None`.
    pub block_rows: Option<usize>,
    /// Poles with `|s|` below this fraction of the lowest line are rigid-body
    /// integrators: the data do not resolve poles below the band, and noise splits a
    /// double integrator (a defective pair at `z = 1`) by about the square root of the
    /// noise level (to 0.67 of the lowest line on the reference wafer stage, whose
    /// relative noise is ~1e-3). Default: 0.75.
    pub rigid_fraction: f64,
    /// Poles closer than this (relative) are one pole whose residue has rank > 1 (a
    /// minimal state space repeats such a pole once per rank). Default: 1e-3.
    pub merge_tol: f64,
    /// With the data's own variance as the weighting (the noise part of the weighted
    /// singular values is then about 1), the order is the number of singular values
    /// above this level; otherwise (and when none is above it) the largest gap decides.
    /// Default: 4.
    pub noise_threshold: f64,
    /// Most integrators of the rigid-body part (`1/s`, `1/s^2`, ...). Default: 2.
    pub max_integrators: usize,
    /// Above this many entries (`ny x nu`) the subspace step runs on the data with the
    /// inputs projected onto `compress_directions` fixed orthonormal directions, and the
    /// residues of every entry are refitted on the full data with its poles (see
    /// [`crate::compress`]): the projection's cost and that of the residue refits of the
    /// order choice fall by `nu / compress_directions`, those of (17) by
    /// `ny / compress_directions`. Only with inverse-variance or uniform weighting (which
    /// the compressed data keep exactly); `usize::MAX` never compresses. Default: 100
    /// (the entries above which frfit's default chain is `subspace -> ml`).
    pub compress_above: usize,
    /// Directions of the compressed inputs (and of the outputs of (17)). Default: 8.
    pub compress_directions: usize,
    /// Solve (17), and search the delay ([`crate::delay_refine`]), on the outputs
    /// projected onto this many fixed directions (set by the compressed path; see
    /// [`crate::compress`]): with many outputs both cost `ny / output_directions` times
    /// less, and the residues of every output are refitted with the poles found. `None`
    /// uses every output. Default: `None`.
    pub output_directions: Option<usize>,
    /// Analyses of the data the caller already made (the chain's: the delay estimate),
    /// used instead of computing them again. Default: none.
    pub precomputed: Precomputed,
    /// Progress callback.
    pub progress: ProgressSink,
}

impl Default for SubspaceConfig {
    fn default() -> Self {
        Self {
            hold: Hold::None,
            delay: DelayChoice::Auto,
            delay_config: DelayConfig::default(),
            refine_delay: true,
            delay_passes: 3,
            delay_half_width: None,
            delay_grid: 21,
            delay_tol_rad: 1e-4,
            derivative_order: 0,
            weighting: Weighting::Auto,
            order: None,
            max_order: 60,
            order_rule: OrderRule::Auto,
            order_alpha: 1e-3,
            order_min_f: 25.0,
            sweep_below: 4,
            sweep_patience: 4,
            block_rows: None,
            rigid_fraction: 0.75,
            max_integrators: 2,
            noise_threshold: 4.0,
            merge_tol: 1e-3,
            compress_above: 100,
            compress_directions: 8,
            output_directions: None,
            precomputed: Precomputed::default(),
            progress: ProgressSink::none(),
        }
    }
}

/// Condition numbers of the linear problems of the fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Conditioning {
    /// Of `O_r` without its last block row (the shift equations (12)).
    pub shift: f64,
    /// Worst over the inputs of the column-scaled regressor of (17).
    pub b_d: f64,
    /// Worst over the entries of the column-scaled regressor of the residue fit.
    pub residues: f64,
}

/// What [`SubspaceInit`] found.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SubspaceReport {
    /// The variable of the fit (discrete through the hold, or bilinear).
    pub domain: String,
    /// The weighting.
    pub weighting: String,
    /// Whether the noise-covariance weighted variant ran.
    pub noise_weighted: bool,
    /// Block rows `r`.
    pub block_rows: usize,
    /// Singular values of the (weighted) projected data, descending. With the data's
    /// true variance as weighting the noise part is about 1.
    pub singular_values: Vec<f64>,
    /// Numerical rank of the projected data.
    pub rank: usize,
    /// The order (states) of the state space.
    pub order: usize,
    /// How it was chosen: `given`, the singular-value rule (threshold or largest gap,
    /// with the values), or the F test (with its range and the statistic of the first
    /// order not kept after the chosen one).
    pub order_rule: String,
    /// The F-test sweep (empty when it did not run): cost, F statistic and critical
    /// value of every candidate order.
    #[serde(default)]
    pub order_sweep: Vec<OrderScore>,
    /// Condition numbers.
    pub conditioning: Conditioning,
    /// Poles reflected into the stable region.
    pub reflected_poles: Vec<ReflectedPole>,
    /// Eigenvalues recognised as rigid-body integrators, and integrators kept.
    pub at_origin: usize,
    /// Integrators of the rigid-body part of the currency.
    pub integrators: usize,
    /// Pole pairs and real poles of the currency.
    pub pairs: usize,
    /// Real poles of the currency.
    pub real_poles: usize,
    /// The delay estimate, when the delay was estimated.
    pub delay_estimate: Option<DelayEstimate>,
    /// The delay divided out before the subspace step of the state space returned,
    /// seconds (beyond the hold). The model's own delay (`factors.delay_s`) is the
    /// refined one when the delay was refined.
    pub delay_s: f64,
    /// The delay refinement (see [`crate::delay_refine`]), when it ran.
    #[serde(default)]
    pub delay_refinement: Option<DelayRefinement>,
    /// Weighted cost of the state space of (17) on the data.
    pub state_space_cost: f64,
    /// Weighted cost of the currency model (residues refitted) on the data.
    pub cost: f64,
    /// Band, Hz.
    pub band_hz: (f64, f64),
}

#[typetag::serde(name = "subspace")]
impl frf_data::LinkDetails for SubspaceReport {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// The identified state space and everything the fit found, for callers below the
/// chain ([`SubspaceInit::identify`]).
#[derive(Debug, Clone)]
pub struct Identified {
    /// The state space: discrete in `z` (sample time of the hold) for [`Hold::Zoh`],
    /// continuous (mapped back exactly from the bilinear variable) otherwise. It
    /// describes the data with the known factors divided out.
    pub state_space: StateSpace,
    /// The model in the currency.
    pub model: FrfModel,
    /// The report.
    pub report: SubspaceReport,
    /// Notes.
    pub messages: Vec<String>,
    /// Stage timings (stage, seconds).
    pub timings: Vec<(String, f64)>,
}

/// The frequency-domain subspace initialiser (McKelvey, Akcay and Ljung 1996;
/// Pintelon & Schoukens, eq. (3)-(17)).
#[derive(Debug, Clone, Default)]
pub struct SubspaceInit {
    /// Settings.
    pub config: SubspaceConfig,
}

impl SubspaceInit {
    /// An initialiser with the given settings.
    pub fn new(config: SubspaceConfig) -> Self {
        Self { config }
    }

    fn check(&self) -> Result<(), SubspaceError> {
        let c = &self.config;
        if !(c.rigid_fraction.is_finite() && (0.0..1.0).contains(&c.rigid_fraction)) {
            return Err(SubspaceError::invalid(
                "rigid_fraction",
                c.rigid_fraction,
                "must be in [0, 1)",
            ));
        }
        if c.order == Some(0) {
            return Err(SubspaceError::invalid("order", 0, "must be >= 1 state"));
        }
        if c.compress_directions == 0 {
            return Err(SubspaceError::invalid(
                "compress_directions",
                0,
                "must be >= 1 direction",
            ));
        }
        if c.output_directions == Some(0) {
            return Err(SubspaceError::invalid(
                "output_directions",
                0,
                "must be >= 1 direction",
            ));
        }
        if !(c.merge_tol.is_finite() && (0.0..0.1).contains(&c.merge_tol)) {
            return Err(SubspaceError::invalid(
                "merge_tol",
                c.merge_tol,
                "must be in [0, 0.1)",
            ));
        }
        if !(c.noise_threshold.is_finite() && c.noise_threshold > 0.0) {
            return Err(SubspaceError::invalid(
                "noise_threshold",
                c.noise_threshold,
                "must be finite and > 0",
            ));
        }
        if !(c.order_alpha.is_finite() && c.order_alpha > 0.0 && c.order_alpha < 0.5) {
            return Err(SubspaceError::invalid(
                "order_alpha",
                c.order_alpha,
                "the significance level must be in (0, 0.5)",
            ));
        }
        if !(c.order_min_f.is_finite() && c.order_min_f >= 0.0) {
            return Err(SubspaceError::invalid(
                "order_min_f",
                c.order_min_f,
                "must be finite and >= 0",
            ));
        }
        if let Some(h) = c.delay_half_width {
            if !(h.is_finite() && h > 0.0) {
                return Err(SubspaceError::invalid(
                    "delay_half_width (s)",
                    h,
                    "must be finite and > 0",
                ));
            }
        }
        if !(c.delay_tol_rad.is_finite() && c.delay_tol_rad >= 0.0) {
            return Err(SubspaceError::invalid(
                "delay_tol_rad",
                c.delay_tol_rad,
                "must be finite and >= 0",
            ));
        }
        if c.order.is_none() && c.max_order == 0 {
            return Err(SubspaceError::invalid("max_order", 0, "must be >= 1"));
        }
        if matches!(c.hold, Hold::Zoh { .. }) && c.derivative_order != 0 {
            return Err(SubspaceError::invalid(
                "derivative order",
                c.derivative_order,
                "the exact zero-order hold model is for displacement-type data",
            ));
        }
        Ok(())
    }

    /// Runs the whole fit on `data`: the state space, the currency model and the report.
    pub fn identify<D: FrfDataset + ?Sized>(&self, data: &D) -> Result<Identified, SubspaceError> {
        self.check()?;
        let cfg = &self.config;
        let weighting = cfg.weighting.resolve(data);
        if data.ny() * data.nu() > cfg.compress_above
            && matches!(weighting, Weighting::InverseVariance | Weighting::Uniform)
        {
            return self.identify_compressed(data, weighting);
        }
        let t0 = Instant::now();
        let mut timings = Vec::new();
        let mut messages = Vec::new();
        let nl = data.n_lines();
        let band = if nl > 0 {
            (data.freq_hz(0), data.freq_hz(nl - 1))
        } else {
            (f64::NAN, f64::NAN)
        };
        let band_txt = format!("{:.4}..{:.4} Hz", band.0, band.1);
        if nl < 2 {
            return Err(SubspaceError::TooFewLines {
                lines: nl,
                band: band_txt,
                block_rows: 0,
                order: cfg.order.unwrap_or(cfg.max_order),
                needed: 2,
            });
        }
        // 1. the known factor
        cfg.progress
            .step("subspace", 1, Some(4), None, "known factor");
        let hold_share = match cfg.hold {
            Hold::Zoh { fs_hz } => 0.5 / fs_hz,
            _ => 0.0,
        };
        let mut delay_estimate = None;
        let (delay_s, fitted) = match cfg.delay {
            DelayChoice::None => (0.0, false),
            DelayChoice::Fixed { seconds } => (seconds, false),
            DelayChoice::Start { seconds } => (seconds, true),
            DelayChoice::Auto => {
                let t = Instant::now();
                let est = match &cfg.precomputed.delay {
                    Some(d) => d.clone(),
                    None => estimate_delay(data, &cfg.delay_config)?,
                };
                timings.push(("delay".to_string(), t.elapsed().as_secs_f64()));
                let tau = est.tau_s - hold_share;
                messages.push(format!(
                    "delay estimate {:.2} us (coherence {:.2}), {:.2} us divided out beyond the hold",
                    est.tau_s * 1e6,
                    est.coherence,
                    tau * 1e6
                ));
                delay_estimate = Some(est);
                (tau, true)
            }
        };
        if !delay_s.is_finite() {
            return Err(SubspaceError::invalid(
                "delay (s)",
                delay_s,
                "must be finite",
            ));
        }
        let first = self.subspace_step(
            data,
            delay_s,
            fitted,
            delay_estimate,
            messages.clone(),
            timings,
        )?;
        self.refine_delay(data, first, delay_s, fitted, &messages, t0)
    }

    /// [`Self::identify`] on the data with the inputs projected onto
    /// `compress_directions` directions (when there are more inputs) and (17) on as
    /// many output directions (when there are more outputs), then the residues of every
    /// entry by one least squares with the poles fixed (see [`crate::compress`]).
    fn identify_compressed<D: FrfDataset + ?Sized>(
        &self,
        data: &D,
        weighting: Weighting,
    ) -> Result<Identified, SubspaceError> {
        let cfg = &self.config;
        let t0 = Instant::now();
        let (ny, nu, k) = (data.ny(), data.nu(), cfg.compress_directions);
        let inner = SubspaceInit::new(SubspaceConfig {
            compress_above: usize::MAX,
            weighting: weighting.clone(),
            output_directions: (ny > k).then_some(k),
            ..cfg.clone()
        });
        if nu <= k {
            let mut id = inner.identify(data)?;
            id.messages.push(format!(
                "(17) solved on the outputs projected onto {k} of {ny} directions"
            ));
            return Ok(id);
        }
        let v = crate::compress::directions(nu, k, COMPRESS_SEED);
        let compressed = crate::compress::compress_inputs(data, &v)?;
        let t_compress = t0.elapsed().as_secs_f64();
        let mut id = inner.identify(&compressed)?;
        // the residues of every entry with the poles of the compressed fit
        let t = Instant::now();
        let m = &id.model.modal;
        let ps = PoleSet {
            pairs: m.pairs.iter().map(|p| p.pole).collect(),
            reals: m.real_poles.iter().map(|p| p.pole).collect(),
            at_origin: m.rigid.len(),
            integrators: m.rigid.len(),
            reflected: Vec::new(),
            notes: Vec::new(),
            pair_members: m.pairs.iter().map(|p| vec![p.pole]).collect(),
        };
        let w = weighting.weights(data)?;
        let (model, cond, cost) = fit_residues(
            ny,
            nu,
            &data.omegas(),
            &data.values_vec(),
            &w,
            &ps,
            &id.model.factors,
        )?;
        id.messages.push(format!(
            "poles from the data with the inputs projected onto {k} of {nu} fixed directions ((17) on {} of {ny} output directions); the residues of all {} entries refitted with them: cost {:.4e} (compressed data {:.4e})",
            k.min(ny),
            ny * nu,
            cost,
            id.report.cost
        ));
        id.report.cost = cost;
        id.report.conditioning.residues = cond;
        id.model = model;
        // the state space of the compressed inputs, back through V^T (least norm)
        let vt = v.transpose().to_owned();
        let ss = &id.state_space;
        id.state_space = StateSpace::new(
            ss.a.clone(),
            &ss.b * &vt,
            ss.c.clone(),
            &ss.d * &vt,
            ss.domain,
        )?;
        let total = id.timings.iter().position(|(s, _)| s == "total");
        if let Some(i) = total {
            id.timings.remove(i);
        }
        id.timings
            .insert(0, ("compress inputs".to_string(), t_compress));
        id.timings.push((
            "residues of all entries".to_string(),
            t.elapsed().as_secs_f64(),
        ));
        id.timings
            .push(("total".to_string(), t0.elapsed().as_secs_f64()));
        Ok(id)
    }

    /// (17) on the prepared data, on `output_directions` output directions when
    /// set (see [`crate::compress`]; `D` back through `U`).
    fn b_d(
        &self,
        prepared: &crate::prepare::Prepared,
        a: &faer::Mat<f64>,
        c: &faer::Mat<f64>,
    ) -> Result<(faer::Mat<f64>, faer::Mat<f64>, f64, f64), SubspaceError> {
        match self.config.output_directions {
            Some(k) if k < prepared.ny => {
                let u = crate::compress::directions(prepared.ny, k, COMPRESS_SEED + 1);
                let pu = crate::compress::project_outputs(prepared, &u);
                let cu = u.transpose() * c;
                let (b, du, cond, cost) = fit_b_d(&pu, a, &cu)?;
                Ok((b, &u * &du, cond, cost))
            }
            _ => fit_b_d(prepared, a, c),
        }
    }

    /// The delay refinement of a free delay (`Auto`, `Start`; see
    /// [`crate::delay_refine`]): with the poles of the subspace step fixed, the delay
    /// minimising the residue-refit cost in a bracket around the delay divided out;
    /// when it moved by more than `delay_tol_rad` at the highest line, the subspace step
    /// again with the refined delay divided out, and the delay refined with its poles;
    /// at most `delay_passes` subspace steps. The pass of the lowest cost is returned,
    /// its model with the refined delay (still a free parameter, `delay_fitted`, for a
    /// refiner). Without a free delay, or with `refine_delay` off, `first` as it is.
    fn refine_delay<D: FrfDataset + ?Sized>(
        &self,
        data: &D,
        first: (Identified, PoleSet),
        start: f64,
        fitted: bool,
        pre: &[String],
        t0: Instant,
    ) -> Result<Identified, SubspaceError> {
        let cfg = &self.config;
        let (mut cur, mut poles) = first;
        if !(fitted && cfg.refine_delay && cfg.delay_passes > 0) {
            cur.timings
                .push(("total".to_string(), t0.elapsed().as_secs_f64()));
            return Ok(cur);
        }
        let omega = data.omegas();
        let g = data.values_vec();
        let weighting = cfg.weighting.resolve(data);
        let inverse_variance = matches!(weighting, Weighting::InverseVariance);
        let w = weighting.weights(data)?;
        // the data of the search: every output, or the outputs projected (see
        // `output_directions`; the residue refits at the start and at the refined delay
        // are then both made on the projected data, so the test compares like with like)
        let projected = match cfg.output_directions {
            Some(k) if k < data.ny() => {
                let u = crate::compress::directions(data.ny(), k, COMPRESS_SEED + 2);
                let pd = crate::compress::compress_outputs(data, &u)?;
                let pw = weighting.weights(&pd)?;
                Some((pd.values_vec(), pw, k))
            }
            _ => None,
        };
        let (sny, sg, sw) = match &projected {
            Some((pg, pw, k)) => (*k, pg.as_slice(), pw.as_slice()),
            None => (data.ny(), g.as_slice(), w.as_slice()),
        };
        let observations = sw.iter().filter(|&&x| x > 0.0).count();
        let w_max = omega.iter().copied().fold(0.0, f64::max);
        let half_width = cfg
            .delay_half_width
            .unwrap_or(0.1 * std::f64::consts::TAU / w_max);
        let tol = cfg.delay_tol_rad / w_max;
        let mut passes: Vec<DelayPass> = Vec::new();
        let mut notes = Vec::new();
        let mut extra_timings = Vec::new();
        let mut search_s = 0.0;
        let mut best: Option<(Identified, usize, f64)> = None;
        let mut tau_div = start;
        let mut threshold = None;
        for pass in 1..=cfg.delay_passes {
            let ts = Instant::now();
            let dc = DelayCost {
                ny: sny,
                nu: data.nu(),
                omega: &omega,
                g: sg,
                w: sw,
                poles: &poles,
                factors: &cur.model.factors,
            };
            // the start: the subspace model, or its poles' residue refit on the projection
            let start_projected = projected.as_ref().map(|_| dc.at(tau_div)).transpose()?;
            let (start_model, start_cost) = match &start_projected {
                Some(p) => (&p.model, p.cost),
                None => (&cur.model, cur.report.cost),
            };
            let (rw, med_start) =
                delay_refine::robust_weights(start_model, &omega, sg, sw, ROBUST_LINE_C)?;
            // the threshold of the robust cost that compares the passes: fixed by the first
            let thr = *threshold.get_or_insert(ROBUST_LINE_C * med_start);
            let robust_start = huber(&line_residuals(start_model, &omega, sg, sw)?, thr);
            let fast = RotatedCost::new(&dc, rw)?.expanded(tau_div, half_width);
            let min = delay_refine::minimise(|t| fast.at(t), tau_div, half_width, cfg.delay_grid);
            let exact = dc.at(min.tau)?;
            let robust_refined = huber(&line_residuals(&exact.model, &omega, sg, sw)?, thr);
            search_s += ts.elapsed().as_secs_f64();
            let rec = DelayPass {
                divided_out_s: tau_div,
                output_directions: projected.as_ref().map(|p| p.2),
                subspace_cost: start_cost,
                subspace_robust_cost: robust_start,
                refined_s: min.tau,
                refined_cost: exact.cost,
                refined_robust_cost: robust_refined,
                evaluations: min.evaluations,
                at_edge: min.at_edge,
            };
            notes.push(format!(
                "delay pass {pass}: {:.4} us divided out, cost {:.4e} (robust {:.4e}); with its poles fixed the robust residue refit is best at {:.4} us, cost {:.4e} (robust {:.4e}; {} evaluations{}{})",
                rec.divided_out_s * 1e6,
                rec.subspace_cost,
                rec.subspace_robust_cost,
                rec.refined_s * 1e6,
                rec.refined_cost,
                rec.refined_robust_cost,
                rec.evaluations,
                if rec.at_edge {
                    format!(", at the edge of the bracket +-{:.3} us", half_width * 1e6)
                } else {
                    String::new()
                },
                match rec.output_directions {
                    Some(k) => format!(
                        "; costs of the outputs projected onto {k} of {} directions",
                        data.ny()
                    ),
                    None => String::new(),
                }
            ));
            passes.push(rec);
            let mut score = robust_start;
            if delay_move_material(
                (robust_start, robust_refined),
                (start_cost, exact.cost),
                (observations, omega.len()),
                inverse_variance,
                cfg,
            ) {
                // the residues of every output at the refined delay
                let exact = match projected {
                    Some(_) => DelayCost {
                        ny: data.ny(),
                        g: &g,
                        w: &w,
                        ..dc
                    }
                    .at(min.tau)?,
                    None => exact,
                };
                cur.model = exact.model;
                cur.report.cost = exact.cost;
                cur.report.conditioning.residues = exact.cond;
                score = robust_refined;
            }
            let refined = cur.model.factors.delay_s;
            if best.as_ref().is_none_or(|(_, _, b)| score < *b) {
                best = Some((cur.clone(), pass, score));
            }
            if (refined - tau_div).abs() <= tol || pass == cfg.delay_passes {
                break;
            }
            tau_div = refined;
            let ts = Instant::now();
            match self.subspace_step(
                data,
                tau_div,
                true,
                cur.report.delay_estimate.clone(),
                pre.to_vec(),
                Vec::new(),
            ) {
                Ok((next, p)) => {
                    cur = next;
                    poles = p;
                    extra_timings.push((
                        format!("subspace step, delay pass {}", pass + 1),
                        ts.elapsed().as_secs_f64(),
                    ));
                }
                Err(e) => {
                    notes.push(format!(
                        "delay pass {}: the subspace step with {:.4} us divided out failed ({e}); the earlier passes stand",
                        pass + 1,
                        tau_div * 1e6
                    ));
                    break;
                }
            }
        }
        let Some((mut out, chosen, _)) = best else {
            unreachable!("the first delay pass always runs")
        };
        let refinement = DelayRefinement {
            start_s: start,
            refined_s: out.model.factors.delay_s,
            half_width_s: half_width,
            passes,
            chosen_pass: chosen,
        };
        out.messages.extend(notes);
        out.messages.push(format!(
            "delay refined with the subspace poles fixed: {:.4} us -> {:.4} us beyond the hold (pass {chosen} of {} kept, {:.4} us divided out for its state space); it stays a free parameter for a refiner",
            refinement.start_s * 1e6,
            refinement.refined_s * 1e6,
            refinement.passes.len(),
            out.report.delay_s * 1e6
        ));
        out.report.delay_refinement = Some(refinement);
        out.timings.extend(extra_timings);
        out.timings.push(("delay refinement".to_string(), search_s));
        out.timings
            .push(("total".to_string(), t0.elapsed().as_secs_f64()));
        Ok(out)
    }

    /// The subspace step with the delay `delay_s` (beyond the hold) divided out: the
    /// projection, the order, (12), (17), the poles and the residue refit of the
    /// currency. Returns the result and its poles.
    fn subspace_step<D: FrfDataset + ?Sized>(
        &self,
        data: &D,
        delay_s: f64,
        fitted: bool,
        delay_estimate: Option<DelayEstimate>,
        mut messages: Vec<String>,
        mut timings: Vec<(String, f64)>,
    ) -> Result<(Identified, PoleSet), SubspaceError> {
        let cfg = &self.config;
        let t0 = Instant::now();
        let (ny, nu, nl) = (data.ny(), data.nu(), data.n_lines());
        let band = (data.freq_hz(0), data.freq_hz(nl - 1));
        let band_txt = format!("{:.4}..{:.4} Hz", band.0, band.1);
        let factors = KnownFactors {
            delay_s,
            delay_fitted: fitted,
            derivative_order: cfg.derivative_order,
            hold: cfg.hold,
            dynamics: Vec::new(),
            crosstalk: None,
        };
        let prepared = prepare(data, &factors, &cfg.weighting)?;
        let weighting = cfg.weighting.resolve(data);

        // 2. the projection and the order. With the data's variance, when the count of
        // singular values above the noise threshold reaches the cap `max_order`, there
        // are more states in the data than the cap allows (a large MIMO plant: 50 modes
        // of rank one are 100 states): the cap is doubled and the projection repeated,
        // while the lines support it. Without the variance the same holds when the
        // singular values up to the cap have no gap (`NO_GAP_RATIO`).
        let inverse_variance = matches!(weighting, Weighting::InverseVariance);
        let mut max_order = cfg.max_order;
        let (r, proj, sv, rank) = loop {
            let n_upper = cfg.order.unwrap_or(max_order);
            let r = match cfg.block_rows {
                Some(r) => {
                    if r < 2 || (r - 1) * ny < n_upper {
                        return Err(SubspaceError::invalid(
                            "block rows",
                            r,
                            format!(
                                "the shift equations (12) need (r - 1) p >= n: at least {} for order {n_upper} with {ny} outputs",
                                n_upper.div_ceil(ny) + 1
                            ),
                        ));
                    }
                    r
                }
                None => 2 * n_upper.div_ceil(ny) + 1,
            };
            let needed = (r + 1).max((n_upper + 4).div_ceil(2));
            if nl < needed {
                return Err(SubspaceError::TooFewLines {
                    lines: nl,
                    band: band_txt,
                    block_rows: r,
                    order: n_upper,
                    needed,
                });
            }
            cfg.progress
                .step("subspace", 2, Some(4), None, "QR of the data matrix");
            let t = Instant::now();
            let proj = project(&prepared, r)?;
            timings.push(("qr+svd".to_string(), t.elapsed().as_secs_f64()));
            let sv = proj.singular_values.clone();
            let rank = numerical_rank(&sv);
            if rank == 0 {
                return Err(SubspaceError::invalid(
                    "data",
                    "all zero",
                    "the projected data matrix is zero: nothing to identify",
                ));
            }
            let n_cap = ((r - 1) * ny).min(rank).min(max_order);
            if cfg.order.is_none() && cfg.block_rows.is_none() && n_cap == max_order && rank > n_cap
            {
                let next = 2 * max_order;
                let r_next = 2 * next.div_ceil(ny) + 1;
                let lines_next = (r_next + 1).max((next + 4).div_ceil(2));
                let why = if inverse_variance {
                    let above = sv[..n_cap]
                        .iter()
                        .filter(|&&x| x > cfg.noise_threshold)
                        .count();
                    (above >= n_cap).then(|| {
                        format!(
                            "all {n_cap} singular values up to the order cap are above {} times the noise level",
                            cfg.noise_threshold
                        )
                    })
                } else {
                    // without the variance: no gap up to the cap that the largest-gap
                    // rule could take for the order
                    let (n_gap, gap) = largest_gap(&sv, n_cap);
                    (gap.exp() < NO_GAP_RATIO).then(|| {
                        format!(
                            "the singular values up to the order cap have no gap (the largest, s_{n_gap}/s_{} = {:.3}, is below {NO_GAP_RATIO})",
                            n_gap + 1,
                            gap.exp()
                        )
                    })
                };
                if let (Some(why), true) = (why, nl >= lines_next) {
                    messages.push(format!("{why}: the cap doubled to {next}"));
                    max_order = next;
                    continue;
                }
            }
            break (r, proj, sv, rank);
        };
        let n_max = ((r - 1) * ny).min(rank).min(max_order);
        let mut order_sweep = Vec::new();
        let (n, order_rule) = match cfg.order {
            Some(n) => {
                if n > rank {
                    return Err(SubspaceError::OrderExceedsRank {
                        order: n,
                        rank,
                        tol: RANK_TOL,
                    });
                }
                (n, "given".to_string())
            }
            None => {
                let (n0, sv_rule) = sv_proposal(&sv, n_max, inverse_variance, cfg.noise_threshold);
                if cfg.order_rule == OrderRule::FTest {
                    let t = Instant::now();
                    let settings = SweepSettings {
                        range: (n0.saturating_sub(cfg.sweep_below).max(1), n_max),
                        observations: prepared.w.iter().filter(|&&w| w > 0.0).count(),
                        alpha: cfg.order_alpha,
                        min_f: cfg.order_min_f,
                        patience: cfg.sweep_patience.max(1),
                        exact_cost: EXACT_REL_COST * prepared.energy(),
                    };
                    let g = data.values_vec();
                    let (chosen, scores) = f_sweep(&settings, |n| {
                        let ps = self.poles_at(&prepared, &proj, n)?;
                        // the candidate's poles refined (the F test compares minima);
                        // where the refinement fails numerically, the subspace poles
                        let poles = refine_poles(
                            ny,
                            nu,
                            &prepared.omega,
                            &g,
                            &prepared.w,
                            &ps,
                            &factors,
                            &PoleRefineSettings::default(),
                        )
                        .map_or(ps.clone(), |r| r.poles);
                        let (_, _, cost) = fit_residues(
                            ny,
                            nu,
                            &prepared.omega,
                            &g,
                            &prepared.w,
                            &poles,
                            &factors,
                        )
                        .ok()?;
                        Some((cost * 2.0 * nl as f64, currency_params(&ps, ny * nu)))
                    });
                    timings.push(("order F test".to_string(), t.elapsed().as_secs_f64()));
                    order_sweep = scores;
                    match chosen {
                        Some(n) => {
                            let last = order_sweep.iter().rev().find(|s| s.order > n);
                            (
                                n,
                                format!(
                                    "F test on the residue refits of the poles of (12) with B, D of (17), poles refined by Gauss-Newton, alpha {:.0e}, orders {}..={} from {sv_rule}{}",
                                    cfg.order_alpha,
                                    settings.range.0,
                                    order_sweep.last().map_or(n, |s| s.order),
                                    match last {
                                        Some(OrderScore { order, f: Some(f), f_critical: Some(fc), .. }) =>
                                            format!("; order {order} after it: F = {f:.3e} below {fc:.3}"),
                                        _ => String::new(),
                                    }
                                ),
                            )
                        }
                        None => (n0, format!("{sv_rule} (the F test realised no order)")),
                    }
                } else if cfg.order_rule == OrderRule::Auto && !inverse_variance {
                    self.later_orders(
                        &prepared,
                        &proj,
                        &sv,
                        (n0, n_max),
                        &factors,
                        data,
                        sv_rule,
                        &mut messages,
                    )
                } else {
                    (n0, sv_rule)
                }
            }
        };

        // 3. A, C from the shift structure, B, D from (17)
        cfg.progress
            .step("subspace", 3, Some(4), None, "state space");
        let t = Instant::now();
        let o = proj.observability(n);
        let (a, c, cond_shift) = shift_a_c(&o, ny)?;
        timings.push(("A, C (12)".to_string(), t.elapsed().as_secs_f64()));
        let t = Instant::now();
        let (b, d, cond_bd, ss_cost) = self.b_d(&prepared, &a, &c)?;
        let (eig, eig_weight) = eigen_weights(&a, &b, &c)?;
        let state_space = match prepared.variable {
            Variable::Shift { ts } => {
                StateSpace::new(a.clone(), b, c, d, TimeDomain::Discrete { ts })?
            }
            Variable::Bilinear { t } => bilinear_to_continuous(&a, &b, &c, &d, t)?,
        };
        timings.push(("B, D (17)".to_string(), t.elapsed().as_secs_f64()));

        // 4. the currency: exact poles, residues by least squares
        cfg.progress
            .step("subspace", 4, Some(4), None, "poles and residues");
        let t = Instant::now();
        let mut ps = classify(
            &eig,
            &eig_weight,
            prepared.variable,
            prepared.omega[0],
            cfg.rigid_fraction,
            cfg.max_integrators,
            cfg.merge_tol,
        );
        messages.extend(ps.notes.iter().cloned());
        for rp in &ps.reflected {
            messages.push(format!(
                "unstable pole {:.4e} {:+.4e}j rad/s ({:.2} Hz) reflected into the left half-plane",
                rp.re, rp.im, rp.f_hz
            ));
        }
        if ps.at_origin > ps.integrators {
            messages.push(format!(
                "{} eigenvalues at the origin: a rigid-body part with {} integrators (coefficients of 1/s^k fitted as full matrices)",
                ps.at_origin, ps.integrators
            ));
        }
        let g = data.values_vec();
        let (mut model, mut cond_res, mut cost) =
            fit_residues(ny, nu, &prepared.omega, &g, &prepared.w, &ps, &factors)?;
        let significance_tests = match cfg.order_rule {
            OrderRule::Auto | OrderRule::FTest => true,
            OrderRule::SingularValues => false,
        };
        let raw = |c: f64| c * 2.0 * nl as f64;
        if significance_tests && cfg.order.is_none() && ps.integrators > 0 {
            if let Some((tm, tc, t_cost, why)) =
                self.integrators_not_supported((&prepared, &g, &factors), &ps, cost, raw)?
            {
                messages.push(format!(
                    "rigid body: the {} integrators of the singular values left out ({why}; cost {cost:.4e} -> {t_cost:.4e})",
                    ps.integrators
                ));
                ps.integrators = 0;
                model = tm;
                cond_res = tc;
                cost = t_cost;
            }
        }
        // Without the data's variance the F statistic's noise estimate (the larger
        // model's residual) is not known to be white under the weighting: an added
        // integrator must also lower the cost by `INTEGRATOR_MIN_DROP`.
        let min_drop = if inverse_variance || cfg.order_rule == OrderRule::FTest {
            1.0
        } else {
            INTEGRATOR_MIN_DROP
        };
        if significance_tests
            && ps.integrators < cfg.max_integrators
            && raw(cost) > EXACT_REL_COST * prepared.energy()
        {
            // the rigid-body integrators the singular values missed (see `integrator_test`)
            let m = ny * nu;
            let observations = prepared.w.iter().filter(|&&w| w > 0.0).count();
            let params = |ps: &PoleSet| currency_params(ps, m);
            let pass_inputs = PassInputs {
                prepared: &prepared,
                orders: (r, max_order),
                inverse_variance,
                g: &g,
                factors: &factors,
            };
            let k0 = ps.integrators;
            // the poles the integrators are added to: those of the singular values
            // (a trial of 2 integrators replaces a split double integrator that one
            // added integrator could not), or those of an accepted pass
            let mut base = ps.clone();
            for k in k0 + 1..=cfg.max_integrators {
                let trial = base.with_integrators(k, prepared.omega[0]);
                let (tm, tc, t_cost) =
                    fit_residues(ny, nu, &prepared.omega, &g, &prepared.w, &trial, &factors)?;
                // states below the band that the integrators replace (see
                // `PoleSet::with_integrators`) count against the added parameters
                let replaced = ps.pairs.len().saturating_sub(trial.pairs.len()) * 2
                    + ps.reals.len().saturating_sub(trial.reals.len());
                let dp = params(&trial).saturating_sub(params(&ps));
                let (significant, test) = if dp == 0 {
                    // no more parameters: the lower cost decides
                    (
                        t_cost < cost,
                        "no more parameters than without them".to_string(),
                    )
                } else {
                    let f = f_statistic(
                        raw(cost) - raw(t_cost),
                        dp,
                        raw(t_cost),
                        observations,
                        params(&trial),
                    );
                    let fc = f_critical(dp, cfg.order_alpha).max(cfg.order_min_f);
                    (
                        f > fc,
                        format!(
                            "F = {f:.3e} {} {fc:.3} (alpha {:.0e})",
                            if f > fc { ">" } else { "<=" },
                            cfg.order_alpha
                        ),
                    )
                };
                let drop_ok = t_cost * min_drop <= cost;
                messages.push(format!(
                    "rigid body: {k} integrators against {}{}: {test}, cost {:.4e} -> {:.4e}{}",
                    ps.integrators,
                    if replaced > 0 {
                        format!(" (replacing {replaced} states below the lowest line)")
                    } else {
                        String::new()
                    },
                    cost,
                    t_cost,
                    if min_drop > 1.0 && significant && !drop_ok {
                        format!(" (without the variance a fall of {min_drop}x is needed)")
                    } else {
                        String::new()
                    }
                ));
                if significant && drop_ok {
                    ps = trial;
                    model = tm;
                    cond_res = tc;
                    cost = t_cost;
                } else if significant && cfg.order.is_none() {
                    // The flexible poles were estimated with the rigid body missing,
                    // and their bias can hold the fall below `min_drop` (seed 2150 of
                    // the chain harness through the hold: 1.23x with F = 274). The
                    // trial is judged after passes on the data with its rigid body
                    // subtracted (repeated while they lower the cost), against one pass
                    // without the added integrators (a pass alone can lower the cost).
                    let best =
                        self.flexible_passes(&pass_inputs, (&tm, &trial, t_cost), |_, _, _, _| {})?;
                    if let Some(next) = best {
                        let without = self
                            .flexible_pass(&pass_inputs, &model, &ps)?
                            .map_or(cost, |b| b.cost.min(cost));
                        let kept = next.cost * min_drop <= without;
                        messages.push(format!(
                            "rigid body: {k} integrators after a pass on the flexible part (order {}): cost {:.4e} against {without:.4e} without them ({})",
                            next.order,
                            next.cost,
                            if kept { "kept" } else { "not kept" }
                        ));
                        if kept {
                            base = next.poles.clone();
                            ps = next.poles;
                            model = next.model;
                            cond_res = next.cond;
                            cost = next.cost;
                        }
                    }
                }
            }
            if ps.integrators > k0 {
                messages.push(format!(
                    "{} integrators added to the rigid-body part by the F test (the singular values gave {k0}: a rigid body weak at the lowest lines hides in the noise of the singular values)",
                    ps.integrators - k0
                ));
                // Second pass: the flexible poles of the first were estimated with the
                // rigid body missing or only partly in the states (one state for a
                // double integrator), which biases them. The fitted rigid-body part is
                // subtracted and the subspace step repeated on the flexible part alone.
                if cfg.order.is_none() {
                    let t2 = Instant::now();
                    // each pass subtracts the rigid body fitted with the previous pass's
                    // flexible poles
                    let best = self.flexible_passes(
                        &pass_inputs,
                        (&model, &ps, cost),
                        |i, before, next, kept| {
                            messages.push(format!(
                                "pass {} on the data with the rigid body subtracted: order {} for the flexible part, cost {before:.4e} -> {:.4e} ({})",
                                i + 2,
                                next.order,
                                next.cost,
                                if kept { "kept" } else { "not kept" }
                            ))
                        },
                    )?;
                    if let Some(next) = best {
                        ps = next.poles;
                        model = next.model;
                        cond_res = next.cond;
                        cost = next.cost;
                    }
                    timings.push(("flexible pass".to_string(), t2.elapsed().as_secs_f64()));
                }
            }
        }
        // the merged poles, decided with the final rigid-body part
        let (m2, c2, cost2) =
            self.choose_merged(&prepared, &g, &factors, &mut ps, &mut messages)?;
        if let Some(m2) = m2 {
            model = m2;
            cond_res = c2;
            cost = cost2;
        }
        timings.push(("residues".to_string(), t.elapsed().as_secs_f64()));
        timings.push(("subspace step".to_string(), t0.elapsed().as_secs_f64()));
        messages.push(format!(
            "order {n} ({order_rule}); {} pole pairs, {} real poles, {} integrators; weighting: {}",
            ps.pairs.len(),
            ps.reals.len(),
            ps.integrators,
            weighting.name()
        ));
        let shown = (n + 6).min(sv.len());
        messages.push(format!(
            "singular values s_1..s_{shown} of the {}projected data: {}",
            if prepared.uniform { "" } else { "weighted " },
            sv[..shown]
                .iter()
                .map(|s| format!("{s:.3e}"))
                .collect::<Vec<_>>()
                .join(" ")
        ));
        if let Some(sc) = order_sweep.iter().find(|s| s.order == n) {
            if let Some(c) = sc.cost {
                messages.push(format!(
                    "order F test: cost {c:.4e} at order {n}; {}",
                    order_sweep
                        .iter()
                        .map(|s| format!(
                            "{}{}",
                            s.order,
                            match (s.f, s.f_critical) {
                                (Some(f), Some(fc)) => format!(
                                    ": F {f:.2e} {} {fc:.2}",
                                    if s.kept { ">" } else { "<=" }
                                ),
                                _ if s.cost.is_none() => ": not realisable".to_string(),
                                _ if s.kept && s.order == order_sweep[0].order =>
                                    ": start".to_string(),
                                _ if s.kept => ": no more parameters, lower cost".to_string(),
                                _ => ": no more parameters".to_string(),
                            }
                        ))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
        }
        let report = SubspaceReport {
            domain: prepared.variable.describe(),
            weighting: weighting.name().to_string(),
            noise_weighted: !prepared.uniform,
            block_rows: r,
            singular_values: sv,
            rank,
            order: n,
            order_rule,
            order_sweep,
            conditioning: Conditioning {
                shift: cond_shift,
                b_d: cond_bd,
                residues: cond_res,
            },
            reflected_poles: ps.reflected.clone(),
            at_origin: ps.at_origin,
            integrators: ps.integrators,
            pairs: ps.pairs.len(),
            real_poles: ps.reals.len(),
            delay_estimate,
            delay_s,
            delay_refinement: None,
            state_space_cost: ss_cost,
            cost,
            band_hz: band,
        };
        let out = Identified {
            state_space,
            model,
            report,
            messages,
            timings,
        };
        Ok((out, ps))
    }
}

/// Lines whose weighted squared residual exceeds this multiple of the median are
/// down-weighted in the delay search (see [`delay_refine::robust_weights`]): a 3-sigma
/// Huber threshold in amplitude.
const ROBUST_LINE_C: f64 = 9.0;

/// Whether a delay pass moves the delay: the robust cost of the residue refit at the
/// refined delay (`robust`: at the start, refined) falls by `DELAY_MIN_FALL` of itself,
/// or, for a start near the noise level of the data's variance (`NEAR_NOISE_COST`), the
/// plain weighted cost (`cost`: at the start, refined) falls significantly by the F
/// test of one parameter. Far above the noise level the cost of the residue refit is
/// nearly flat in the delay, and its minimum is where the delay absorbs a little of the
/// other poles' misfit: on random 20 x 20 plants with 50 modes and no delay (`frfit
/// simulate random-modal`, seeds 1..7) the subspace start's robust cost fell by 4e-5 to
/// 8.4e-4 at refined delays of 4 to 25 us, from which the ML refinement ended with
/// spurious modes. A delay the periodogram estimate missed by a fraction of its
/// resolution lowers it by 0.9 to 2.3 % (the reference wafer stages: 2.3 to 2.7 us).
fn delay_move_material(
    robust: (f64, f64),
    cost: (f64, f64),
    (observations, lines): (usize, usize),
    inverse_variance: bool,
    cfg: &SubspaceConfig,
) -> bool {
    if robust.1 <= robust.0 * (1.0 - DELAY_MIN_FALL) {
        return true;
    }
    if !inverse_variance || cost.1 >= cost.0 {
        return false;
    }
    // `weighted_cost` divides by twice the lines; the F test takes the sum
    let raw = |c: f64| c * 2.0 * lines as f64;
    raw(cost.0) <= NEAR_NOISE_COST * observations as f64
        && f_statistic(raw(cost.0) - raw(cost.1), 1, raw(cost.1), observations, 0)
            > f_critical(1, cfg.order_alpha).max(cfg.order_min_f)
}

/// Without the data's variance, the ratio of the largest singular-value gap up to the
/// order cap below which the cap is doubled (with the variance the count above the
/// noise threshold decides). An order the cap holds shows a gap at the data's noise
/// floor (round-off for exact data: ten orders of magnitude); exact data of a random
/// 20 x 20 plant with 50 modes (100 states) had none up to 60 (largest 1.17).
const NO_GAP_RATIO: f64 = 2.0;

/// The relative fall of the robust cost by which a delay pass moves the delay (see
/// [`delay_move_material`]).
const DELAY_MIN_FALL: f64 = 2e-3;

/// Seed of the fixed directions of the compressed data (see [`crate::compress`]).
const COMPRESS_SEED: u64 = 0x5EED_0001;

/// Most passes on the flexible part after the first (see `SubspaceInit::identify`).
const FLEXIBLE_PASSES: usize = 8;

/// Relative cost (to the weighted energy of the data) at or below which the F-test
/// sweep takes a fit as exact (a relative rms error of 1e-8) and stops: beyond it the
/// residual is roundoff, not noise.
const EXACT_REL_COST: f64 = 1e-16;

impl SubspaceInit {
    /// The rigid-body part that the singular values gave (`ps.integrators` at the
    /// origin) tested against the same poles without it: it is left out when the fit
    /// without it is exact (noise-free data whose largest singular-value gap lies below
    /// two round-off states at the origin: a 1 x 1 system with two modes, residues of
    /// 1e-13 on a rigid body it does not have) or when its coefficients fail the F test
    /// of the structure tests ([`crate::order::f_statistic`]). Returns the model without
    /// it, its conditioning and cost, and the reason.
    fn integrators_not_supported(
        &self,
        (prepared, g, factors): (&Prepared, &[C64], &KnownFactors),
        ps: &PoleSet,
        cost: f64,
        raw: impl Fn(f64) -> f64,
    ) -> Result<Option<(FrfModel, f64, f64, String)>, SubspaceError> {
        let cfg = &self.config;
        let (ny, nu) = (prepared.ny, prepared.nu);
        let mut trial = ps.clone();
        trial.integrators = 0;
        let (tm, tc, t_cost) =
            fit_residues(ny, nu, &prepared.omega, g, &prepared.w, &trial, factors)?;
        if raw(t_cost) <= EXACT_REL_COST * prepared.energy() {
            return Ok(Some((
                tm,
                tc,
                t_cost,
                "the fit without them is exact".to_string(),
            )));
        }
        let m = ny * nu;
        let observations = prepared.w.iter().filter(|&&w| w > 0.0).count();
        let dp = currency_params(ps, m) - currency_params(&trial, m);
        let f = f_statistic(
            raw(t_cost) - raw(cost),
            dp,
            raw(cost),
            observations,
            currency_params(ps, m),
        );
        let fc = f_critical(dp, cfg.order_alpha).max(cfg.order_min_f);
        Ok((f <= fc).then(|| {
            (
                tm,
                tc,
                t_cost,
                format!(
                    "their coefficients are not significant: F = {f:.3e} <= {fc:.3} (alpha {:.0e})",
                    cfg.order_alpha
                ),
            )
        }))
    }
}

/// Without the data's variance, the factor by which an integrator of the rigid-body
/// test must lower the weighted cost besides passing the F test. A rigid body the
/// singular values missed leaves a misfit that dominates the residual (on a noise-free
/// 8-mode system of the chain harness, seed 3711 through the hold, the double
/// integrator lowers the cost 2.6x with F = 941, before the second pass re-estimates
/// the biased flexible poles), while an integrator that only absorbs noise or the
/// misfit of the other subspace poles changes it by a few per cent.
const INTEGRATOR_MIN_DROP: f64 = 2.0;

/// With the data's variance, the weighted cost (relative to its expectation at the
/// noise level) up to which a delay pass may move the delay on the F test of its fall
/// (see [`delay_move_material`]).
const NEAR_NOISE_COST: f64 = 2.0;

/// Without the data's variance, the factor by which the orders above the largest
/// singular-value gap must lower the weighted cost of its order (see
/// `SubspaceInit::later_orders`).
const NO_VARIANCE_MIN_DROP: f64 = 10.0;

/// Without the data's variance, the singular values more than this many times the
/// smallest one computed stand above the floor of the projected data (round-off for
/// exact data: about 1e-12 of the largest); see `SubspaceInit::later_orders`. The
/// last state of a weak double integrator stood at 3-4x it on noise-free 7-8 mode
/// systems of the chain harness (seeds 141, 289, 657 through the hold) and was not
/// tried at 5x; the round-off states themselves stay within 1.5x of it.
const FLOOR_FACTOR: f64 = 2.5;

/// Without the data's variance, the most orders above the largest-gap proposal whose
/// residue refits `SubspaceInit::later_orders` compares.
const LATER_ORDERS: usize = 8;

/// Free real parameters of the currency with the poles `ps` and `m` entries: a pole
/// pair 2 and a complex residue per entry, a real pole 1 and a real residue per entry,
/// an integrator and the feedthrough a coefficient per entry.
fn currency_params(ps: &PoleSet, m: usize) -> usize {
    2 * ps.pairs.len() * (1 + m) + ps.reals.len() * (1 + m) + (ps.integrators + 1) * m
}

/// The singular-value proposal of the order (see [`crate::order`]): the count above
/// `threshold` times the noise level with inverse-variance weighting (when there is
/// one), the largest gap otherwise; with its description.
fn sv_proposal(
    sv: &[f64],
    n_max: usize,
    inverse_variance: bool,
    threshold: f64,
) -> (usize, String) {
    let above = sv[..n_max].iter().filter(|&&s| s > threshold).count();
    if inverse_variance && above > 0 {
        (
            above,
            format!(
                "singular values above {threshold} times the noise level (inverse-variance weighting): s_{above} = {:.3e}, s_{} = {:.3e}",
                sv[above - 1],
                above + 1,
                sv[above]
            ),
        )
    } else {
        let (n, gap) = largest_gap(sv, n_max);
        (
            n,
            format!(
                "largest gap of the singular values in 1..={n_max}: s_{n}/s_{} = {:.3e}",
                n + 1,
                gap.exp()
            ),
        )
    }
}

/// The fixed inputs of the passes on the flexible part
/// ([`SubspaceInit::flexible_pass`], [`SubspaceInit::flexible_passes`]).
#[derive(Clone, Copy)]
struct PassInputs<'a> {
    /// The prepared data (the delay divided out, weighted).
    prepared: &'a crate::prepare::Prepared,
    /// The block rows of the projection and the order cap.
    orders: (usize, usize),
    /// Whether the weighting is the inverse variance (the singular values' noise rule).
    inverse_variance: bool,
    /// The data, line after line, each `vec(G)` column-major.
    g: &'a [C64],
    /// The known factors of the currency.
    factors: &'a KnownFactors,
}

/// The result of [`SubspaceInit::flexible_pass`].
struct FlexiblePass {
    order: usize,
    poles: PoleSet,
    model: FrfModel,
    cond: f64,
    cost: f64,
}

impl SubspaceInit {
    /// For every pole pair merged from several eigenvalues (a residue of rank > 1 whose
    /// repeated pole noise split), the pole among the merged eigenvalues, their
    /// residue-weighted mean and their plain mean that gives the lowest cost of the
    /// residue refit (one group after the other). Near-repeated eigenvalues have nearly
    /// parallel eigenvectors, so their residue weights are unreliable, and the
    /// eigenvalue of the weak direction of the residue can be far off: the refit decides.
    /// Returns the new model, its condition number and cost when a candidate other than
    /// the weighted mean won.
    #[allow(clippy::too_many_arguments)]
    fn choose_merged(
        &self,
        prepared: &crate::prepare::Prepared,
        g: &[C64],
        factors: &KnownFactors,
        ps: &mut PoleSet,
        messages: &mut Vec<String>,
    ) -> Result<(Option<FrfModel>, f64, f64), SubspaceError> {
        let (ny, nu) = (prepared.ny, prepared.nu);
        let mut best: Option<(FrfModel, f64, f64)> = None;
        for q in 0..ps.pairs.len() {
            let members = ps.pair_members.get(q).cloned().unwrap_or_default();
            if members.len() < 2 {
                continue;
            }
            let plain =
                members.iter().fold(C64::new(0.0, 0.0), |a, &b| a + b) / members.len() as f64;
            let current = ps.pairs[q];
            let base_cost = match &best {
                Some((_, _, c)) => *c,
                None => fit_residues(ny, nu, &prepared.omega, g, &prepared.w, ps, factors)?.2,
            };
            let mut chosen: Option<(C64, FrfModel, f64, f64)> = None;
            for cand in members.iter().copied().chain(std::iter::once(plain)) {
                let mut trial = ps.clone();
                trial.pairs[q] = cand;
                let (m, cond, c) =
                    fit_residues(ny, nu, &prepared.omega, g, &prepared.w, &trial, factors)?;
                let better = c < chosen.as_ref().map_or(base_cost, |x| x.3);
                if better {
                    chosen = Some((cand, m, cond, c));
                }
            }
            if let Some((cand, m, cond, c)) = chosen {
                messages.push(format!(
                    "merged pole at {:.4} Hz: {:.6} Hz of its {} eigenvalues (refit cost {:.4e} against {:.4e} with the residue-weighted mean {:.6} Hz)",
                    current.norm() / std::f64::consts::TAU,
                    cand.norm() / std::f64::consts::TAU,
                    members.len(),
                    c,
                    base_cost,
                    current.norm() / std::f64::consts::TAU
                ));
                ps.pairs[q] = cand;
                best = Some((m, cond, c));
            }
        }
        Ok(match best {
            Some((m, cond, c)) => (Some(m), cond, c),
            None => (None, 0.0, 0.0),
        })
    }

    /// The poles of the order-`n` realisation of the projection: `A`, `C` by the shift
    /// equations (12), `B` by (17), the eigenvalues classified into pole pairs, real
    /// poles and integrators; `None` when a step fails numerically (a rank-deficient
    /// shift equation).
    fn poles_at(
        &self,
        prepared: &crate::prepare::Prepared,
        proj: &crate::projection::Projected,
        n: usize,
    ) -> Option<PoleSet> {
        let cfg = &self.config;
        let o = proj.observability(n);
        let (a, c, _) = shift_a_c(&o, prepared.ny).ok()?;
        let (b, _, _, _) = self.b_d(prepared, &a, &c).ok()?;
        let (eig, w) = eigen_weights(&a, &b, &c).ok()?;
        Some(classify(
            &eig,
            &w,
            prepared.variable,
            prepared.omega[0],
            cfg.rigid_fraction,
            cfg.max_integrators,
            cfg.merge_tol,
        ))
    }

    /// Without the data's variance: the orders above the largest-gap proposal `n0`
    /// whose singular values stand above the floor of the projected data (more than
    /// [`FLOOR_FACTOR`] times the smallest positive singular value computed, or the
    /// numerical rank's tolerance when that is larger; at most
    /// [`LATER_ORDERS`] of them) are realised and their residue refits compared. When
    /// the lowest cost among them is [`NO_VARIANCE_MIN_DROP`] times below that of `n0`
    /// (which must not be an exact fit already), the smallest order within twice that
    /// lowest cost is taken. States that the largest gap leaves below it (the rigid body
    /// and the weak directions of the rank-2 residues of noise-free 7-8 mode systems:
    /// the largest gap after 24 of 30 states, or after 32 of 34 with the 34th at 9x the
    /// round-off floor) bias every pole of the proposal, so its misfit dominates the
    /// residual; round-off states of an exact fit are not tried, and states that only
    /// absorb noise do not lower the cost tenfold. Returns the order and its description.
    #[allow(clippy::too_many_arguments)]
    fn later_orders<D: FrfDataset + ?Sized>(
        &self,
        prepared: &crate::prepare::Prepared,
        proj: &crate::projection::Projected,
        sv: &[f64],
        (n0, n_max): (usize, usize),
        factors: &KnownFactors,
        data: &D,
        sv_rule: String,
        messages: &mut Vec<String>,
    ) -> (usize, String) {
        let s1 = sv.first().copied().unwrap_or(0.0);
        let floor = sv
            .iter()
            .copied()
            .filter(|&x| x > 0.0)
            .fold(f64::INFINITY, f64::min)
            .max(RANK_TOL * s1);
        let n_top = sv
            .iter()
            .take_while(|&&x| x > FLOOR_FACTOR * floor)
            .count()
            .min(n_max)
            .min(n0 + LATER_ORDERS);
        if n_top <= n0 {
            return (n0, sv_rule);
        }
        let (ny, nu, nl) = (prepared.ny, prepared.nu, prepared.n_lines());
        let g = data.values_vec();
        let cost_at = |n: usize| -> Option<f64> {
            let ps = self.poles_at(prepared, proj, n)?;
            fit_residues(ny, nu, &prepared.omega, &g, &prepared.w, &ps, factors)
                .ok()
                .map(|(_, _, c)| c)
        };
        let Some(c0) = cost_at(n0) else {
            return (n0, sv_rule);
        };
        if c0 * 2.0 * nl as f64 <= EXACT_REL_COST * prepared.energy() {
            return (n0, sv_rule);
        }
        let costs: Vec<(usize, f64)> = (n0 + 1..=n_top)
            .filter_map(|n| cost_at(n).map(|c| (n, c)))
            .collect();
        let Some(c_min) = costs.iter().map(|c| c.1).min_by(|a, b| a.total_cmp(b)) else {
            return (n0, sv_rule);
        };
        let listed = costs
            .iter()
            .map(|(n, c)| format!("{n}: {c:.3e}"))
            .collect::<Vec<_>>()
            .join(", ");
        if c_min * NO_VARIANCE_MIN_DROP > c0 {
            messages.push(format!(
                "orders {}..={n_top} above the singular values' floor ({floor:.3e}) do not lower the residue-refit cost {c0:.4e} of order {n0} tenfold ({listed}): order {n0} kept",
                n0 + 1
            ));
            return (n0, sv_rule);
        }
        let n = costs
            .iter()
            .find(|c| c.1 <= 2.0 * c_min)
            .map_or(n0, |c| c.0);
        messages.push(format!(
            "order {n}: the residue refits of the orders above the largest gap's {n0} (cost {c0:.4e}) and above the singular values' floor ({floor:.3e}) gave {listed}; the smallest order within twice the lowest cost taken"
        ));
        (
            n,
            format!("{sv_rule}; order {n} by the residue-refit costs of the orders above it"),
        )
    }

    /// The subspace step repeated on the data with the rigid-body part of `model`
    /// subtracted: projection, order from the singular values, (12), (17), poles; the
    /// integrators of `ps` are kept and all residues refitted on the full data.
    fn flexible_pass(
        &self,
        inputs: &PassInputs<'_>,
        model: &FrfModel,
        ps: &PoleSet,
    ) -> Result<Option<FlexiblePass>, SubspaceError> {
        let cfg = &self.config;
        let PassInputs {
            prepared,
            orders: (r, max_order),
            inverse_variance,
            g,
            factors,
        } = *inputs;
        let ny = prepared.ny;
        let mut rigid = FrfModel {
            modal: realize::ModalModel::new(model.ny(), model.nu()),
            factors: factors.clone(),
        };
        rigid.modal.rigid = model.modal.rigid.clone();
        let gr = rigid.freq_response(&prepared.omega)?;
        let mut flex = prepared.clone();
        let m = prepared.ny * prepared.nu;
        for k in 0..prepared.n_lines() {
            let inv = factors.scalar_at(prepared.omega[k]).inv();
            let line = gr.line(k);
            for e in 0..m {
                flex.h[k * m + e] -= line[e] * inv;
            }
        }
        let proj = project(&flex, r)?;
        let sv = &proj.singular_values;
        let rank = numerical_rank(sv);
        if rank == 0 {
            return Ok(None);
        }
        let n_max = ((r - 1) * ny).min(rank).min(max_order);
        let (n, _) = sv_proposal(sv, n_max, inverse_variance, cfg.noise_threshold);
        // a pass that cannot be realised is not used
        let Some(mut poles) = self.poles_at(&flex, &proj, n) else {
            return Ok(None);
        };
        poles.integrators = poles.integrators.max(ps.integrators);
        let (mut model, mut cond, mut cost) = fit_residues(
            model.ny(),
            model.nu(),
            &prepared.omega,
            g,
            &prepared.w,
            &poles,
            factors,
        )?;
        let mut notes = Vec::new();
        let (m2, c2, cost2) = self.choose_merged(prepared, g, factors, &mut poles, &mut notes)?;
        if let Some(m2) = m2 {
            model = m2;
            cond = c2;
            cost = cost2;
        }
        Ok(Some(FlexiblePass {
            order: n,
            poles,
            model,
            cond,
            cost,
        }))
    }
}

impl SubspaceInit {
    /// Passes on the flexible part ([`flexible_pass`](Self::flexible_pass)) from
    /// `start` (model, poles, cost), each from the last one kept, while they lower the
    /// cost: at most [`FLEXIBLE_PASSES`], ending after a pass that lowers it by less
    /// than 1 %. `seen(i, cost before, pass, kept)` is told of every pass made (`i`
    /// from 0). Returns the last pass kept, `None` when none lowered the cost.
    fn flexible_passes(
        &self,
        inputs: &PassInputs<'_>,
        start: (&FrfModel, &PoleSet, f64),
        mut seen: impl FnMut(usize, f64, &FlexiblePass, bool),
    ) -> Result<Option<FlexiblePass>, SubspaceError> {
        let mut best: Option<FlexiblePass> = None;
        for i in 0..FLEXIBLE_PASSES {
            let (model, ps, before) = match &best {
                Some(b) => (&b.model, &b.poles, b.cost),
                None => start,
            };
            let Some(next) = self.flexible_pass(inputs, model, ps)? else {
                break;
            };
            let kept = next.cost < before;
            seen(i, before, &next, kept);
            if !kept {
                break;
            }
            let gain = 1.0 - next.cost / before;
            best = Some(next);
            if gain < 0.01 {
                break;
            }
        }
        Ok(best)
    }
}

impl Estimator for SubspaceInit {
    type Model = FrfModel;
    type Start = ();
    type Report = SubspaceReport;
    type Error = SubspaceError;

    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        _start: (),
    ) -> Result<Fit<FrfModel, SubspaceReport>, SubspaceError> {
        let id = self.identify(data)?;
        let mut fit = Fit::from_model(id.model, "frequency-domain subspace (McKelvey)")
            .with_report(id.report);
        fit.cost_history = vec![fit.report.cost];
        fit.convergence = Convergence::Direct;
        fit.messages = id.messages;
        for (stage, s) in id.timings {
            fit.timings.push(frf_data::Timing { stage, seconds: s });
        }
        Ok(fit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 4000 lines x 400 entries with the variance: the noise level of the weighted cost
    /// is 200 (`weighted_cost` divides the sum by twice the lines).
    const OBS: (usize, usize) = (1_600_000, 4000);

    #[test]
    fn a_delay_moves_only_when_it_explains_more_than_the_misfit_of_the_poles() {
        let cfg = SubspaceConfig::default();
        // far above the noise level (a biased start): a fall of 4e-5 is the delay
        // absorbing the misfit (seed 1 of the 20 x 20 random plant), 1 % a delay error
        let far = 9.2e6;
        assert!(!delay_move_material(
            (2.2481e9, 2.2480e9),
            (far, far * (1.0 - 5e-5)),
            OBS,
            true,
            &cfg
        ));
        assert!(delay_move_material(
            (2.2481e9, 2.2481e9 * 0.99),
            (far, far * 0.999),
            OBS,
            true,
            &cfg
        ));
        // near the noise level a significant fall of the plain cost moves it (F = 16000
        // for a fall of 1 in 200), an insignificant one does not (F = 16 < 25)
        assert!(delay_move_material(
            (1e6, 1e6),
            (201.0, 200.0),
            OBS,
            true,
            &cfg
        ));
        assert!(!delay_move_material(
            (1e6, 1e6),
            (200.001, 200.0),
            OBS,
            true,
            &cfg
        ));
        // without the variance only the robust fall counts
        assert!(!delay_move_material(
            (1e6, 1e6),
            (201.0, 200.0),
            OBS,
            false,
            &cfg
        ));
    }
}
