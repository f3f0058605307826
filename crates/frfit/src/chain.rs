//! The estimator chain of the facade: `data -> [init] -> [refine] -> ...` composed by
//! name (`frfit fit --init cmif --refine riv`), only through the object-safe links of
//! `frf_data::chain` ([`Initializer`], [`Refiner`]).
//!
//! A method plugs in by implementing `frf_data::Estimator` (or the link traits directly)
//! and adding one row to [`INITIALIZERS`] or [`REFINERS`]: a name, a description and a
//! constructor from the [`ChainSettings`] (plus the pipeline's options).
//!
//! [`run_chain`] runs an initialiser and a refiner and applies one rule for every chain:
//! when the delay was estimated and the refinement moved it by more than 5 % (and
//! 2 us) from where the initialiser put it, the choices the initialiser made with the
//! wrong delay (rigid body, numerators, peaks) are redone with the refined delay as the
//! start, and the better of the two chains (weighted cost on the data, the same
//! criterion for every method) is kept; a note says so.
//!
//! `--init` may name several initialisers (`cmif,subspace`) or `auto` (every registered
//! one, in registry order): each starts its own chain with the same refiner, and the
//! chain kept is the one with the smallest final prediction error
//! ([`final_prediction_error`]) on the data, so that a hard case (many modes, close
//! pairs, hidden peaks) where one initialiser starts poorly falls back on another. Every
//! run is reported in [`ChainResult::runs`] and in the notes.

use crate::FrfitError;
use additive_riv::complete::CompleteConfig;
use additive_riv::structure::AdaptConfig;
use additive_riv::{CmifInit, CmifInitConfig, RigidBody, RivConfig, RivRefine, RivRefineConfig};
use frf_data::chain::{weighted_cost, DynData};
use frf_data::{
    ChainModel, ChainOutput, ChainSettings, DelayChoice, InitLink, Initializer, LinkReport,
    RefineLink, Refiner,
};
use ml_refine::{MlConfig, MlRefine};
use sk_fit::bands::{BandSpec, MultiBandConfig, MultiBandSk};
use sk_fit::{SkConfig, SkInit};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// The multi-band composite fit of the SK initialiser (Jue 2.3; `--bands`,
/// `--band-weights`): with it, `--init sk` fits the bands of `spec` with the tiered
/// weights `q_low` below and `q_high` above each band (see [`MultiBandSk`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SkBands {
    /// The bands: `auto`, one, or the cut-offs in Hz.
    pub spec: BandSpec,
    /// `Q_l`, the weight of the lines below a band. Default: 1e-1.
    pub q_low: f64,
    /// `Q_h`, the weight of the lines above a band. Default: 1e-4.
    pub q_high: f64,
}

impl Default for SkBands {
    fn default() -> Self {
        let d = MultiBandConfig::default();
        Self {
            spec: d.bands,
            q_low: d.q_low,
            q_high: d.q_high,
        }
    }
}

/// Options of the links that the pipeline sets beyond [`ChainSettings`] (most of them
/// for the additive links).
#[derive(Debug, Clone)]
pub struct AdditiveOptions {
    /// Refined IV iteration settings (method, tolerances).
    pub riv: RivConfig,
    /// Mode adaptation after the first refinement.
    pub adapt: Option<AdaptConfig>,
    /// Rigid-body choice of the CMIF initialiser.
    pub rigid_body: RigidBody,
    /// Realizations the data's variance was estimated from, when declared (the ML
    /// refiner's cost test expects `V / N_dof = (R - 1) / (R - 2)` then).
    pub realizations: Option<usize>,
    /// Real degrees of freedom of each line's variance when it was estimated (`2 (R - 1)`
    /// from `R` realizations, more when pooled over neighbouring lines): the ML refiner's
    /// cost test and sample-variance factor ([`ml_refine::sample_variance_factor`]).
    /// Default: `None` (from `realizations`).
    pub variance_dof: Option<f64>,
    /// Completion of the CMIF start ([`additive_riv::complete`]): missing modes added
    /// at residual CMIF peaks, the rigid body chosen again with settled poles. Default:
    /// `Some(CompleteConfig::default())`, as [`CmifInitConfig`]; the diagnosis pipeline
    /// passes `None` (its loop adds the modes itself and is validated on the reference
    /// files with the plain start).
    pub complete_start: Option<CompleteConfig>,
    /// The multi-band composite fit of the `sk` initialiser; `None`: one SK fit of the
    /// whole band (the default). Only `sk` takes bands: [`run_chain`] rejects them for a
    /// chain without it.
    pub sk_bands: Option<SkBands>,
    /// The initialisers already run on the same data in this run ([`StartCache`]),
    /// shared by the chains of the pipeline's starts. Default: `None` (every chain runs
    /// its initialiser).
    pub starts: Option<StartCache>,
}

/// The outputs of the initialisers already run in one pipeline run, by initialiser,
/// settings and data: a chain that starts from the same initialiser with the same
/// settings on the same data takes its output instead of running it again (the third
/// start's `sk -> ml` after the second start's `sk -> riv`: SK's common denominator took
/// 15 s of a 110 s fit of the DaISy flexible structure). The reused link report says so.
#[derive(Clone, Default)]
pub struct StartCache(Arc<Mutex<HashMap<String, ChainOutput>>>);

impl std::fmt::Debug for StartCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0.lock().map_or(0, |m| m.len());
        write!(f, "StartCache({n} starts)")
    }
}

impl StartCache {
    /// What makes an initialiser's output: its name, every setting it reads, and the
    /// data (lines, band edges, and the sum of the magnitudes and of the variances).
    fn key(init: &str, data: DynData<'_>, s: &ChainSettings, o: &AdditiveOptions) -> String {
        let n = data.n_lines();
        let mut line = vec![realize::C64::new(0.0, 0.0); data.n_entries()];
        let mut sum = 0.0;
        for k in 0..n {
            data.line_into(k, &mut line);
            sum += line.iter().map(|v| v.norm()).sum::<f64>();
        }
        let var: f64 = data.variance_vec().map_or(0.0, |v| v.iter().sum());
        let edges = (n > 0).then(|| (data.freq_hz(0), data.freq_hz(n - 1)));
        format!(
            "{init}|{n}|{edges:?}|{sum:e}|{var:e}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}",
            s.hold,
            s.delay,
            s.derivative_order,
            s.weighting,
            s.modes,
            s.peaks,
            s.order,
            o.rigid_body,
            o.complete_start,
            o.sk_bands
        )
    }

    /// The output of `init` on `data` with `s` and `o`: the one of an earlier run when
    /// there is one (its report with a message saying so), else `run`'s, kept.
    fn get_or_run(
        &self,
        (init, data): (&str, DynData<'_>),
        s: &ChainSettings,
        o: &AdditiveOptions,
        run: impl FnOnce() -> Result<ChainOutput, FrfitError>,
    ) -> Result<ChainOutput, FrfitError> {
        let key = Self::key(init, data, s, o);
        let earlier = self.0.lock().ok().and_then(|m| m.get(&key).cloned());
        if let Some(mut out) = earlier {
            out.report.messages.push(format!(
                "the {init} start of an earlier chain of this run, with the same settings on the same data: reused, not run again"
            ));
            return Ok(out);
        }
        let out = run()?;
        if let Ok(mut m) = self.0.lock() {
            m.insert(key, out.clone());
        }
        Ok(out)
    }
}

impl Default for AdditiveOptions {
    fn default() -> Self {
        Self {
            riv: RivConfig::default(),
            adapt: Some(AdaptConfig::default()),
            rigid_body: RigidBody::Auto,
            realizations: None,
            variance_dof: None,
            complete_start: Some(CompleteConfig::default()),
            sk_bands: None,
            starts: None,
        }
    }
}

/// The constructor of a registered initialiser.
pub type MakeInitializer = fn(&ChainSettings, &AdditiveOptions) -> Box<dyn Initializer>;
/// The constructor of a registered refiner.
pub type MakeRefiner = fn(&ChainSettings, &AdditiveOptions) -> Box<dyn Refiner>;

/// A registered initialiser: name, description, constructor.
pub struct InitEntry {
    /// The name on the command line.
    pub name: &'static str,
    /// What it does.
    pub description: &'static str,
    /// Builds the link.
    pub make: MakeInitializer,
}

/// A registered refiner: name, description, constructor (`None` for `none`).
pub struct RefineEntry {
    /// The name on the command line.
    pub name: &'static str,
    /// What it does.
    pub description: &'static str,
    /// Builds the link; `None` hands the initialiser's model on as it is.
    pub make: Option<MakeRefiner>,
}

fn make_cmif(s: &ChainSettings, o: &AdditiveOptions) -> Box<dyn Initializer> {
    Box::new(InitLink {
        name: "cmif".into(),
        estimator: CmifInit::new(CmifInitConfig {
            modes: s.modes.clone(),
            peaks: s.peaks.clone(),
            hold: s.hold,
            delay: s.delay,
            derivative_order: s.derivative_order,
            rigid_body: o.rigid_body,
            weighting: s.weighting.clone(),
            progress: s.progress.clone(),
            precomputed: s.precomputed.clone(),
            complete: o.complete_start.clone(),
            ..Default::default()
        }),
    })
}

fn make_sk(s: &ChainSettings, o: &AdditiveOptions) -> Box<dyn Initializer> {
    let sk = SkConfig {
        order: s.order,
        peaks: s.peaks.clone(),
        hold: s.hold,
        delay: s.delay,
        derivative_order: s.derivative_order,
        weighting: s.weighting.clone(),
        precomputed: s.precomputed.clone(),
        progress: s.progress.clone(),
        ..Default::default()
    };
    match &o.sk_bands {
        None => Box::new(InitLink {
            name: "sk".into(),
            estimator: SkInit::new(sk),
        }),
        Some(b) => Box::new(InitLink {
            name: "sk".into(),
            estimator: MultiBandSk::new(MultiBandConfig {
                bands: b.spec.clone(),
                q_low: b.q_low,
                q_high: b.q_high,
                sk,
                ..Default::default()
            }),
        }),
    }
}

fn make_subspace(s: &ChainSettings, _o: &AdditiveOptions) -> Box<dyn Initializer> {
    Box::new(InitLink {
        name: "subspace".into(),
        estimator: subspace::SubspaceInit::new(subspace::SubspaceConfig {
            hold: s.hold,
            delay: s.delay,
            derivative_order: s.derivative_order,
            weighting: s.weighting.clone(),
            order: s.order,
            precomputed: s.precomputed.clone(),
            progress: s.progress.clone(),
            ..Default::default()
        }),
    })
}

fn make_riv(s: &ChainSettings, o: &AdditiveOptions) -> Box<dyn Refiner> {
    let mut riv = o.riv.clone();
    riv.weighting = s.weighting.clone();
    riv.progress = s.progress.clone();
    Box::new(RefineLink {
        name: "riv".into(),
        estimator: RivRefine::new(RivRefineConfig {
            riv,
            adapt: o.adapt.clone(),
            ..Default::default()
        }),
    })
}

fn make_ml(s: &ChainSettings, o: &AdditiveOptions) -> Box<dyn Refiner> {
    Box::new(RefineLink {
        name: "ml".into(),
        estimator: MlRefine::new(MlConfig {
            weighting: s.weighting.clone(),
            realizations: o.realizations,
            variance_dof: o.variance_dof,
            progress: s.progress.clone(),
            ..Default::default()
        }),
    })
}

/// The initialisers frfit knows.
pub const INITIALIZERS: &[InitEntry] = &[
    InitEntry {
        name: "cmif",
        description: "CMIF peaks + convex numerators (eq. 24 of the wafer-stage paper)",
        make: make_cmif,
    },
    InitEntry {
        name: "subspace",
        description:
            "frequency-domain subspace (McKelvey): z-domain through the hold, bilinear otherwise",
        make: make_subspace,
    },
    InitEntry {
        name: "sk",
        description: "Sanathanan-Koerner common denominator (Jue 2.2, 2.4), order by F-test sweep, residues by least squares; with --bands, Bayard's multi-band composite (Jue 2.3)",
        make: make_sk,
    },
];

/// The refiners frfit knows.
pub const REFINERS: &[RefineEntry] = &[
    RefineEntry {
        name: "riv",
        description: "refined instrumental variables (Algorithm 1) with mode adaptation",
        make: Some(make_riv),
    },
    RefineEntry {
        name: "none",
        description: "no refinement: the initialiser's model as it is",
        make: None,
    },
    RefineEntry {
        name: "ml",
        description: "maximum likelihood (Levenberg-Marquardt, variable projection) with parameter uncertainty",
        make: Some(make_ml),
    },
];

/// The error of a method name that is not registered, listing those that are.
fn unknown(option: &str, name: &str, known: &[&str]) -> FrfitError {
    FrfitError::argument(
        option,
        name,
        format!("unknown method; available: {}", known.join(", ")),
    )
}

/// The initialiser registered as `name`.
pub fn initializer(
    name: &str,
    s: &ChainSettings,
    o: &AdditiveOptions,
) -> Result<Box<dyn Initializer>, FrfitError> {
    INITIALIZERS
        .iter()
        .find(|e| e.name == name)
        .map(|e| (e.make)(s, o))
        .ok_or_else(|| {
            let known: Vec<&str> = INITIALIZERS.iter().map(|e| e.name).collect();
            unknown("--init", name, &known)
        })
}

/// The refiner registered as `name` (`Ok(None)` for `none`).
pub fn refiner(
    name: &str,
    s: &ChainSettings,
    o: &AdditiveOptions,
) -> Result<Option<Box<dyn Refiner>>, FrfitError> {
    REFINERS
        .iter()
        .find(|e| e.name == name)
        .map(|e| e.make.map(|m| m(s, o)))
        .ok_or_else(|| {
            let known: Vec<&str> = REFINERS.iter().map(|e| e.name).collect();
            unknown("--refine", name, &known)
        })
}

/// What a chain produced: the last link's model and every link's report.
#[derive(Debug, Clone)]
pub struct ChainResult {
    /// The model of the last link.
    pub model: ChainModel,
    /// The names of the links, in order (`["cmif", "riv"]`).
    pub chain: Vec<String>,
    /// Each link's report, in order (a redone chain reports the kept run).
    pub links: Vec<LinkReport>,
    /// Notes of the chain itself (a redone start, the initialisers tried).
    pub notes: Vec<String>,
    /// Every chain of a multi-initialiser run (empty for one initialiser).
    pub runs: Vec<ChainRun>,
}

fn link_err(e: frf_data::ChainError) -> FrfitError {
    FrfitError::Fit {
        what: format!("--init/--refine chain, link `{}`", e.link),
        why: e.source.to_string(),
    }
}

fn run_once(
    data: DynData<'_>,
    init: &str,
    refine: &str,
    s: &ChainSettings,
    o: &AdditiveOptions,
) -> Result<(ChainOutput, Option<ChainOutput>), FrfitError> {
    let run = || initializer(init, s, o)?.initialize(data).map_err(link_err);
    let first = match &o.starts {
        Some(cache) => cache.get_or_run((init, data), s, o, run)?,
        None => run()?,
    };
    let second = match refiner(refine, s, o)? {
        Some(r) => Some(r.refine(data, &first.model).map_err(link_err)?),
        None => None,
    };
    Ok((first, second))
}

/// A weighted cost with the data's own variance within this factor of its expectation
/// at the noise level (between `2 - AT_NOISE_LEVEL` and `AT_NOISE_LEVEL` times it) is
/// at the noise level (`run_single` then runs no chain again from the refined delay:
/// nothing can fit significantly better). Its standard deviation is `1/sqrt(N)` with
/// `N` the lines times entries (below 0.02 from 2500 of them). A cost far below its
/// expectation says that the stated variance overstates the noise (noise-free data
/// with a nominal variance: a fit at 0.009 of it was still 1.5e-5 off, and the run from
/// the start made it exact), and a variance estimated from few realizations raises the
/// expectation by `d2 / (d2 - 2)` (1.08 with 2 periods of 8 realizations): such fits
/// are fitted again as before.
const AT_NOISE_LEVEL: f64 = 1.05;

/// The weighted cost `c` ([`weighted_cost`]) of `model` over its expectation at the
/// noise level, `sum w |E|^2 / (N - p / 2)` with `N` the lines times entries and `p`
/// the model's real parameters, when the weighting is the data's inverse variance;
/// `None` otherwise (the cost then has no known scale) or when `p / 2 >= N`.
fn noise_level_ratio(
    model: &ChainModel,
    c: f64,
    data: DynData<'_>,
    weighting: &frf_data::Weighting,
) -> Option<f64> {
    use frf_data::ModelStructure;
    if weighting.resolve(data) != frf_data::Weighting::InverseVariance || !c.is_finite() {
        return None;
    }
    let n = (data.n_lines() * data.n_entries()) as f64;
    let dof = n - model.model.n_params() as f64 / 2.0;
    (dof > 0.0).then(|| c * 2.0 * data.n_lines() as f64 / dof)
}

/// Runs the initialiser `init` then `refine` on `data` with the delay rule of the module
/// documentation.
fn run_single(
    data: DynData<'_>,
    init: &str,
    refine: &str,
    s: &ChainSettings,
    o: &AdditiveOptions,
) -> Result<ChainResult, FrfitError> {
    let (first, second) = run_once(data, init, refine, s, o)?;
    let mut notes = Vec::new();
    let finish = |first: ChainOutput, second: Option<ChainOutput>| {
        let mut chain = vec![first.report.link.clone()];
        let mut links = vec![first.report.clone()];
        let model = match second {
            Some(r) => {
                chain.push(r.report.link.clone());
                links.push(r.report);
                r.model
            }
            None => {
                chain.push("none".into());
                first.model
            }
        };
        (model, chain, links)
    };
    let (start_delay, end_delay) = (
        first.model.model.factors.delay_s,
        second.as_ref().map(|r| r.model.model.factors.delay_s),
    );
    let redo = match (s.delay, end_delay) {
        (DelayChoice::Auto, Some(end)) if first.model.model.factors.delay_fitted => {
            (end - start_delay).abs() > (0.05 * start_delay.abs()).max(2e-6)
        }
        _ => false,
    };
    let (model, chain, links) = finish(first, second);
    let refined = end_delay.unwrap_or(start_delay);
    let cost =
        |m: &ChainModel| weighted_cost(&m.model, data, &s.weighting).unwrap_or(f64::INFINITY);
    let c1 = if redo { cost(&model) } else { f64::NAN };
    // at the noise level no run can fit significantly better
    let at_noise = redo
        && noise_level_ratio(&model, c1, data, &s.weighting)
            .filter(|r| (r - 1.0).abs() <= AT_NOISE_LEVEL - 1.0)
            .map(|ratio| {
                notes.push(format!(
                    "the delay moved from {:.2} us (start) to {:.2} us in the refinement; no run from the start with it: the fit is at the noise level (weighted cost {ratio:.3} times its expectation)",
                    start_delay * 1e6,
                    refined * 1e6
                ))
            })
            .is_some();
    if !redo || at_noise {
        return Ok(ChainResult {
            model,
            chain,
            links,
            notes,
            runs: Vec::new(),
        });
    }
    let s2 = ChainSettings {
        delay: DelayChoice::Start { seconds: refined },
        ..s.clone()
    };
    match run_once(data, init, refine, &s2, o) {
        Ok((f2, r2)) => {
            let (model2, chain2, links2) = finish(f2, r2);
            let c2 = cost(&model2);
            if c2 < c1 * (1.0 - additive_riv::fitter::RERUN_GAIN) {
                notes.push(format!(
                    "the delay moved from {:.2} us (start) to {:.2} us in the refinement: fitted again from the start with it, the whole chain (cost {c1:.4e} -> {c2:.4e})",
                    start_delay * 1e6,
                    refined * 1e6
                ));
                return Ok(ChainResult {
                    model: model2,
                    chain: chain2,
                    links: links2,
                    notes,
                    runs: Vec::new(),
                });
            }
            notes.push(format!(
                "the delay moved from {:.2} us (start) to {:.2} us in the refinement; a run from the start with it was not better (cost {c2:.4e} against {c1:.4e})",
                start_delay * 1e6,
                refined * 1e6
            ));
        }
        Err(e) => notes.push(format!(
            "the delay moved from {:.2} us to {:.2} us in the refinement; the run from the start with it failed: {e}",
            start_delay * 1e6,
            refined * 1e6
        )),
    }
    Ok(ChainResult {
        model,
        chain,
        links,
        notes,
        runs: Vec::new(),
    })
}

/// The initialisers an `--init` value names: one name, a comma-separated list, or
/// `auto` (every registered initialiser, in registry order). Each name is checked.
pub fn init_names(spec: &str) -> Result<Vec<String>, FrfitError> {
    let names: Vec<String> = if spec.trim() == "auto" {
        INITIALIZERS.iter().map(|e| e.name.to_string()).collect()
    } else {
        spec.split(',').map(|n| n.trim().to_string()).collect()
    };
    let known: Vec<&str> = INITIALIZERS.iter().map(|e| e.name).collect();
    for (k, n) in names.iter().enumerate() {
        if !known.contains(&n.as_str()) {
            return Err(FrfitError::argument(
                "--init",
                spec,
                format!("unknown method `{n}`; available: {}", known.join(", ")),
            ));
        }
        if names[..k].contains(n) {
            return Err(FrfitError::argument(
                "--init",
                spec,
                format!("`{n}` is named twice"),
            ));
        }
    }
    Ok(names)
}

/// Akaike's final prediction error `V (N + p) / (N - p)` of a currency model on `data`:
/// the weighted cost `V` ([`weighted_cost`]) corrected for the `p` real parameters the
/// model spent on `N` real residuals (two per line and entry), so that a chain that
/// fitted noise with more modes does not win by that alone. Infinite when `p >= N` or
/// the model cannot be evaluated.
pub fn final_prediction_error(
    model: &ChainModel,
    data: DynData<'_>,
    weighting: &frf_data::Weighting,
) -> f64 {
    use frf_data::ModelStructure;
    weighted_cost(&model.model, data, weighting).map_or(f64::INFINITY, |v| {
        fpe_of_cost(v, model.model.n_params(), data)
    })
}

/// `V (N + p) / (N - p)` for a weighted cost `V` already evaluated, `p` real parameters
/// and `N` twice the lines times entries of `data`; infinite when `p >= N` or `V` is
/// not finite.
fn fpe_of_cost(v: f64, p: usize, data: DynData<'_>) -> f64 {
    fpe(v, p, data.n_lines() * data.n_entries())
}

/// Akaike's final prediction error `V (N + p) / (N - p)` of a weighted cost `V` with `p`
/// real parameters on `N = 2 lines_x_entries` real residuals; infinite when `p >= N` or
/// `V` is not finite.
pub(crate) fn fpe(v: f64, p: usize, lines_x_entries: usize) -> f64 {
    let n = 2.0 * lines_x_entries as f64;
    let p = p as f64;
    if n > p && v.is_finite() {
        v * (n + p) / (n - p)
    } else {
        f64::INFINITY
    }
}

/// One chain of a multi-initialiser run (`--init cmif,subspace` or `auto`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChainRun {
    /// The chain's link names.
    pub chain: Vec<String>,
    /// Its weighted cost on the data ([`weighted_cost`]); `None` when it failed.
    pub cost: Option<f64>,
    /// Real parameters of its model.
    pub n_params: Option<usize>,
    /// Its final prediction error ([`final_prediction_error`]), the selection criterion.
    pub fpe: Option<f64>,
    /// Why it failed, when it did.
    pub error: Option<String>,
    /// Whether it is the chain kept.
    pub kept: bool,
    /// The hold the chain modelled when it is not the run's (`frfit fit`'s hold start,
    /// e.g. `zoh:6400`); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold: Option<String>,
}

/// Runs the initialiser(s) named by `init` (one name, a comma-separated list or `auto`),
/// each followed by `refine`, on `data`, and keeps the chain with the smallest final
/// prediction error (see the module documentation). Names are checked before any work.
/// With one initialiser this is that chain; with several, the run fails only when every
/// chain failed (the errors are named).
pub fn run_chain(
    data: DynData<'_>,
    init: &str,
    refine: &str,
    s: &ChainSettings,
    o: &AdditiveOptions,
) -> Result<ChainResult, FrfitError> {
    let names = init_names(init)?;
    refiner(refine, s, o)?;
    if let Some(b) = &o.sk_bands {
        if !names.iter().any(|n| n == "sk") {
            return Err(FrfitError::argument(
                "--bands",
                b.spec.to_string(),
                format!(
                    "bands are a setting of the SK initialiser (Bayard's multi-band fit, \
                     --init sk); the chain's initialiser is {}",
                    names.join(", ")
                ),
            ));
        }
    }
    if let [one] = names.as_slice() {
        return run_single(data, one, refine, s, o);
    }
    use frf_data::ModelStructure;
    let mut runs: Vec<ChainRun> = Vec::new();
    let mut best: Option<(f64, ChainResult)> = None;
    for name in &names {
        match run_single(data, name, refine, s, o) {
            Ok(r) => {
                // one evaluation of the model on the data serves the cost and the FPE
                let cost = weighted_cost(&r.model.model, data, &s.weighting).ok();
                let n_params = r.model.model.n_params();
                let fpe = cost.map_or(f64::INFINITY, |v| fpe_of_cost(v, n_params, data));
                runs.push(ChainRun {
                    chain: r.chain.clone(),
                    cost,
                    n_params: Some(n_params),
                    fpe: Some(fpe),
                    error: None,
                    kept: false,
                    hold: None,
                });
                if best.as_ref().is_none_or(|(b, _)| fpe < *b) {
                    best = Some((fpe, r));
                }
            }
            Err(e) => runs.push(ChainRun {
                chain: vec![name.clone(), refine.to_string()],
                cost: None,
                n_params: None,
                fpe: None,
                error: Some(e.to_string()),
                kept: false,
                hold: None,
            }),
        }
    }
    let Some((_, mut result)) = best else {
        let why = runs
            .iter()
            .map(|r| {
                format!(
                    "{}: {}",
                    r.chain.join("+"),
                    r.error.as_deref().unwrap_or("")
                )
            })
            .collect::<Vec<_>>()
            .join("; ");
        return Err(FrfitError::Fit {
            what: format!("--init {init}"),
            why: format!("every chain failed ({why})"),
        });
    };
    for r in &mut runs {
        r.kept = r.chain == result.chain && r.error.is_none();
    }
    let listed = runs
        .iter()
        .map(|r| match (r.fpe, &r.error) {
            (Some(f), _) => format!(
                "{} FPE {f:.4e} ({} parameters){}",
                r.chain.join("+"),
                r.n_params.unwrap_or(0),
                if r.kept { ", kept" } else { "" }
            ),
            (None, Some(e)) => format!("{} failed: {e}", r.chain.join("+")),
            (None, None) => r.chain.join("+"),
        })
        .collect::<Vec<_>>()
        .join("; ");
    result.notes.push(format!(
        "initialisers tried (smallest final prediction error kept): {listed}"
    ));
    result.runs = runs;
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::{Frf, Weighting};
    use realize::{FrfModel, ModalModel, PolePair, C64};

    /// The weighted cost of the true model on data with complex noise of the stated
    /// variance is at its expectation (within a few `1/sqrt(N)`), and twice that noise
    /// doubles the ratio; without a variance (or another weighting) there is no ratio.
    #[test]
    fn the_noise_level_ratio_of_the_truth_is_one() {
        use rand::{Rng, SeedableRng};
        let mut m = ModalModel::new(2, 2);
        m.pairs.push(PolePair::from_second_order(
            40.0,
            0.02,
            &faer::Mat::from_fn(2, 2, |i, j| 1e4 * (1.0 + i as f64 + 2.0 * j as f64)),
        ));
        let truth: ChainModel = FrfModel::new(m).into();
        let f: Vec<f64> = (1..=1000).map(|k| 10.0 + 0.1 * k as f64).collect();
        let w: Vec<f64> = f.iter().map(|f| std::f64::consts::TAU * f).collect();
        let g = truth.model.freq_response(&w).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // uniform components of variance s^2 / 2 each: E|e|^2 = s^2
        let mut noisy = |scale: f64| {
            let (mut vals, mut var) = (g.values.clone(), Vec::new());
            for v in vals.iter_mut() {
                let s = 1e-3 * v.norm();
                let a = (1.5f64).sqrt() * s * scale;
                *v += C64::new(rng.random_range(-a..a), rng.random_range(-a..a));
                var.push(s * s);
            }
            Frf::new(f.clone(), 2, 2, vals, None)
                .unwrap()
                .with_variance(Some(var))
                .unwrap()
        };
        let ratio = |d: &Frf, wt: &Weighting| {
            let c = weighted_cost(&truth.model, d, wt).unwrap();
            noise_level_ratio(&truth, c, d, wt)
        };
        let d1 = noisy(1.0);
        let r1 = ratio(&d1, &Weighting::Auto).unwrap();
        assert!((r1 - 1.0).abs() < 0.05, "{r1}");
        let r2 = ratio(&noisy(2.0f64.sqrt()), &Weighting::Auto).unwrap();
        assert!((r2 - 2.0).abs() < 0.1, "{r2}");
        assert!(ratio(&d1, &Weighting::InverseMagnitude).is_none());
    }

    #[test]
    fn init_names_expand_auto_and_check_each_name() {
        let all: Vec<String> = INITIALIZERS.iter().map(|e| e.name.to_string()).collect();
        assert_eq!(init_names("auto").unwrap(), all);
        assert_eq!(init_names("cmif").unwrap(), vec!["cmif".to_string()]);
        let e = init_names("cmif,bogus").unwrap_err().to_string();
        assert!(e.contains("bogus") && e.contains("available: cmif"), "{e}");
        let e = init_names("cmif, cmif").unwrap_err().to_string();
        assert!(e.contains("named twice"), "{e}");
    }

    /// A 1 x 1 one-mode model and its response on 50 lines, with a perturbation of
    /// relative size `eps` on every line.
    fn one_mode(eps: f64) -> (FrfModel, Frf) {
        let mut m = ModalModel::new(1, 1);
        m.pairs.push(PolePair::from_f_zeta(
            10.0,
            0.02,
            faer::Mat::from_fn(1, 1, |_, _| C64::new(0.0, -3.0)),
        ));
        let model = FrfModel::new(m);
        let f: Vec<f64> = (1..=50).map(|k| k as f64 * 0.4).collect();
        let w: Vec<f64> = f.iter().map(|f| std::f64::consts::TAU * f).collect();
        let g = model.freq_response(&w).unwrap();
        let values: Vec<C64> = (0..f.len())
            .map(|k| g.get(k, 0, 0) * (1.0 + eps * if k % 2 == 0 { 1.0 } else { -1.0 }))
            .collect();
        (model, Frf::new(f, 1, 1, values, None).unwrap())
    }

    #[test]
    fn final_prediction_error_is_zero_for_the_exact_model_and_charges_parameters() {
        let (model, data) = one_mode(0.0);
        let cm = ChainModel::from(model.clone());
        assert_eq!(final_prediction_error(&cm, &data, &Weighting::Uniform), 0.0);
        let (_, noisy) = one_mode(1e-3);
        let v = weighted_cost(&model, &noisy, &Weighting::Uniform).unwrap();
        let fpe = final_prediction_error(&cm, &noisy, &Weighting::Uniform);
        // 1 x 1, one pair: p = 2 + 2 + 1 (feedthrough) = 5 real parameters on N = 100
        let (n, p) = (100.0, 5.0);
        assert!(
            (fpe - v * (n + p) / (n - p)).abs() <= 1e-12 * fpe,
            "{fpe} {v}"
        );
        // the same cost with a spare (zero-residue) mode costs more
        let mut bigger = model.clone();
        bigger.modal.pairs.push(PolePair::from_f_zeta(
            15.0,
            0.02,
            faer::Mat::from_fn(1, 1, |_, _| C64::new(0.0, 0.0)),
        ));
        let fpe2 = final_prediction_error(&ChainModel::from(bigger), &noisy, &Weighting::Uniform);
        assert!(fpe2 > fpe, "{fpe2} <= {fpe}");
    }
}
