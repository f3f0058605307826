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

use crate::FrfitError;
use additive_riv::structure::AdaptConfig;
use additive_riv::{CmifInit, CmifInitConfig, RigidBody, RivConfig, RivRefine, RivRefineConfig};
use frf_data::chain::{weighted_cost, DynData};
use frf_data::{
    ChainModel, ChainOutput, ChainSettings, DelayChoice, InitLink, Initializer, LinkReport,
    RefineLink, Refiner,
};
use ml_refine::{MlConfig, MlRefine};

/// Options of the additive links that the pipeline sets beyond [`ChainSettings`].
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
}

impl Default for AdditiveOptions {
    fn default() -> Self {
        Self {
            riv: RivConfig::default(),
            adapt: Some(AdaptConfig::default()),
            rigid_body: RigidBody::Auto,
            realizations: None,
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
            progress: s.progress.clone(),
            ..Default::default()
        }),
    })
}

/// The initialisers frfit knows.
pub const INITIALIZERS: &[InitEntry] = &[InitEntry {
    name: "cmif",
    description: "CMIF peaks + convex numerators (eq. 24 of the wafer-stage paper)",
    make: make_cmif,
}];

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

/// Methods of the design that are not implemented yet, named in the error so that a
/// user knows they are planned and what to use instead.
const PLANNED_INIT: &[&str] = &["sk", "subspace"];
const PLANNED_REFINE: &[&str] = &[];

fn unknown(option: &str, name: &str, known: &[&str], planned: &[&str]) -> FrfitError {
    let why = if planned.contains(&name) {
        format!(
            "`{name}` is not implemented in this version of frfit; available: {}",
            known.join(", ")
        )
    } else {
        format!("unknown method; available: {}", known.join(", "))
    };
    FrfitError::argument(option, name, &why)
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
            unknown("--init", name, &known, PLANNED_INIT)
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
            unknown("--refine", name, &known, PLANNED_REFINE)
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
    /// Notes of the chain itself (a redone start).
    pub notes: Vec<String>,
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
    let first = initializer(init, s, o)?
        .initialize(data)
        .map_err(link_err)?;
    let second = match refiner(refine, s, o)? {
        Some(r) => Some(r.refine(data, &first.model).map_err(link_err)?),
        None => None,
    };
    Ok((first, second))
}

/// Runs `init` then `refine` on `data` (see the module documentation for the delay
/// rule).
pub fn run_chain(
    data: DynData<'_>,
    init: &str,
    refine: &str,
    s: &ChainSettings,
    o: &AdditiveOptions,
) -> Result<ChainResult, FrfitError> {
    // names are checked before any work
    initializer(init, s, o)?;
    refiner(refine, s, o)?;
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
    if !redo {
        return Ok(ChainResult {
            model,
            chain,
            links,
            notes,
        });
    }
    let refined = end_delay.unwrap_or(start_delay);
    let s2 = ChainSettings {
        delay: DelayChoice::Start { seconds: refined },
        ..s.clone()
    };
    let cost =
        |m: &ChainModel| weighted_cost(&m.model, data, &s.weighting).unwrap_or(f64::INFINITY);
    let c1 = cost(&model);
    match run_once(data, init, refine, &s2, o) {
        Ok((f2, r2)) => {
            let (model2, chain2, links2) = finish(f2, r2);
            let c2 = cost(&model2);
            if c2 < c1 {
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
    })
}
