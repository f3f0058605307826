//! The trials of a diagnosis round: each candidate refitted and F-tested against the
//! current model, the missed modes also jointly, and a delay also by a refit from the
//! start.

use super::candidate::{Candidate, Proposal};
use super::refit::{
    f_test, lacked_light_modes, model_cost, new_modes, refit, unstable_parts, Refitted,
};
use super::restart::{delay_restart, DelayRestart};
use crate::effects::{FittedEffect, Refit};
use crate::pipeline::{FitContext, PipelineConfig};
use additive_riv::residual_stats::{local_energy, ResidualStats};
use additive_riv::riv::{iterate, RivConfig};
use additive_riv::structure::AdaptConfig;
use additive_riv::{AdditiveModel, FitData};
use frf_data::structure::HeldOutCost;
use frf_data::ModelStructure;

/// One tested candidate: the refitted model and its F test against the current model.
#[derive(Debug, Clone)]
pub struct Trial {
    /// The parameters as fitted.
    pub params: FittedEffect,
    /// Why it was tested and what the refit showed.
    pub evidence: String,
    /// The refitted model.
    pub model: AdditiveModel,
    /// Its weighted cost `sum w |E|^2`.
    pub cost: f64,
    /// F statistic of the cost decrease per added parameter.
    pub f: f64,
    /// The critical value it must pass.
    pub f_crit: f64,
    /// Real parameters added.
    pub added: usize,
    /// For the joint missed-mode trial: (frequency, damping) of every mode it added,
    /// each reported as its own `missed_mode` step.
    pub joint_modes: Vec<(f64, f64)>,
    /// Set while the refit stopped at the screening cap before converging: what
    /// [`finish`] needs to continue it.
    pub screened: Option<Screened>,
    /// The candidate refitted, for a trial of one proposed candidate.
    pub candidate: Option<Candidate>,
    /// Its check on interleaved held-out lines ([`additive_riv::held_out`]), when it was the
    /// round's best.
    pub held_out: Option<HeldOutCost>,
}

impl Trial {
    /// The trial of a reading of the current model (the suspended body, a factor read as
    /// a delay): a simpler model in place of parts of it, adding no parameter, with the F
    /// statistic `f` (critical `f_crit`) of the parts it replaces beside it.
    pub fn reading(
        params: FittedEffect,
        evidence: String,
        (model, cost): (AdditiveModel, f64),
        (f, f_crit): (f64, f64),
    ) -> Self {
        Self {
            params,
            evidence,
            model,
            cost,
            f,
            f_crit,
            added: 0,
            joint_modes: Vec::new(),
            screened: None,
            candidate: None,
            held_out: None,
        }
    }
}

/// A candidate refit stopped at the screening cap ([`refit_candidate`] with `cap`).
#[derive(Debug, Clone)]
pub struct Screened {
    /// The candidate.
    pub candidate: Candidate,
    /// The evidence that proposed it.
    pub evidence: String,
    /// Iterations run.
    pub iterations: usize,
    /// The cost decrease still to come, extrapolated from the refit's cost history
    /// ([`super::refit::remaining_decrease`]), in units of [`Trial::cost`]; `None` when
    /// its decreases do not shrink.
    pub remaining: Option<f64>,
}

impl Trial {
    /// A trial that added the modes `joint` ((frequency, damping) each) together, each
    /// reported as its own `missed_mode` step (`first` the trial's own parameters, the
    /// step when `joint` is empty): `model` at weighted cost `cost`, its F test `f`
    /// against `f_crit` for `added` real parameters.
    fn missed_modes(
        first: (f64, f64),
        joint: Vec<(f64, f64)>,
        evidence: String,
        model: AdditiveModel,
        (cost, f, f_crit, added): (f64, f64, f64, usize),
    ) -> Self {
        Trial {
            params: FittedEffect::MissedMode {
                f_hz: first.0,
                zeta: first.1,
            },
            evidence,
            model,
            cost,
            f,
            f_crit,
            added,
            joint_modes: joint,
            screened: None,
            candidate: None,
            held_out: None,
        }
    }

    /// Whether it passes its F test.
    pub fn passes(&self) -> bool {
        self.f > self.f_crit
    }

    /// Holds the trial below its critical value (it cannot be accepted) and appends
    /// `note`, the reason, to its evidence.
    pub fn hold_back(&mut self, note: &str) {
        self.evidence = format!("{}; {note}", self.evidence);
        self.f = self.f.min(self.f_crit * (1.0 - 1e-12));
    }
}

/// A candidate's refit `model` that left modes or factors in the right half-plane,
/// where the current model had none of its own, with those parts removed, the
/// numerators refitted (eq. 24) and the refit continued, and a note saying so; `None`
/// when nothing was to be removed or the result is still unstable. The last
/// `new_factors` dynamics factors of `model` are the candidate's own (an effect whose
/// own factor is unstable is not a fix, and is left for the acceptance to reject); the
/// others were accepted in earlier rounds.
///
/// An effect that explains what a mode held (a sensor-mount resonance that the first
/// fit had made of a mode on that row and of a twin beside the plate's neighbouring
/// mode) leaves that mode nothing to fit: it drifts onto the imaginary axis and across,
/// and the acceptance, which takes no step that adds unstable parts, would reject the
/// effect for it (the simulated stage of seed 5 with a resonance 3 % below its seventh
/// mode: the factor at 691.80 Hz for 691.8 Hz brought the cost to the noise level, and
/// the twin at 707.9 Hz ended at damping -8e-4). The same holds for a factor an earlier
/// round accepted for want of the right effect (plate seed 8 with a resonance 3 % above
/// its fifth mode: a first-order output factor taken at 6.3 kHz while the resonance was
/// unexplained; the resonance's factor at 400.52 Hz then brought the cost from 772 times
/// the noise to 1.06, and the first-order factor ended with its pole at +0.7 Hz in the
/// right half-plane). The trial is then the effect without the redundant parts, as the
/// pruning after an accepted step would leave it; its F test counts the parameters it
/// has, fewer for the removed parts.
fn without_redundant_parts(
    model: &AdditiveModel,
    current: &AdditiveModel,
    new_factors: usize,
    fd: &FitData,
    riv: &RivConfig,
) -> Option<(Refitted, String)> {
    let before = unstable_parts(current);
    if unstable_parts(model) <= before {
        return None;
    }
    let modes = model.modes();
    let mut unstable: Vec<(usize, f64, f64)> = model
        .unstable_submodels()
        .into_iter()
        .filter_map(|k| {
            modes
                .iter()
                .find(|m| m.submodel == k)
                .map(|m| (k, m.f_hz, m.zeta))
        })
        .collect();
    let inherited = model.dynamics.len().saturating_sub(new_factors);
    let factors: Vec<usize> = (0..inherited)
        .filter(|&k| model.dynamics[k].poles().iter().any(|p| p.re >= 0.0))
        .collect();
    if (unstable.is_empty() && factors.is_empty()) || unstable.len() >= modes.len() {
        return None;
    }
    // the highest index first, so that the others keep theirs
    unstable.sort_unstable_by_key(|u| std::cmp::Reverse(u.0));
    let mut m = model.clone();
    for &(k, _, _) in &unstable {
        m.remove_submodel(k);
    }
    let factor_list: Vec<String> = factors
        .iter()
        .map(|&k| {
            let d = &model.dynamics[k];
            let poles: Vec<String> = d
                .poles()
                .iter()
                .map(|p| format!("{:+.3e}{:+.3e}i rad/s", p.re, p.im))
                .collect();
            format!(
                "{:?} of order {} (poles {})",
                d.target,
                d.den.len(),
                poles.join(", ")
            )
        })
        .collect();
    for &k in factors.iter().rev() {
        m.dynamics.remove(k);
    }
    let r = refit(m, fd, riv).ok()?;
    if unstable_parts(&r.model) > before {
        return None;
    }
    let mut parts = Vec::new();
    if !unstable.is_empty() {
        let list: Vec<String> = unstable
            .iter()
            .rev()
            .map(|(_, f, z)| format!("{f:.2} Hz (damping {z:.1e})"))
            .collect();
        parts.push(format!("the mode(s) at {}", list.join(", ")));
    }
    if !factor_list.is_empty() {
        parts.push(format!("the earlier factor(s) {}", factor_list.join(", ")));
    }
    let note = format!(
        "the refit left {} unstable with nothing left to fit: removed as redundant beside the effect, and refitted",
        parts.join(" and ")
    );
    Some((r, note))
}

/// What every trial of a round is tested against.
pub struct Current<'a> {
    /// The current model.
    pub model: &'a AdditiveModel,
    /// Its weighted cost.
    pub cost: f64,
    /// Its residual statistics.
    pub stats: &'a ResidualStats,
}

/// Missed modes jointly: close pairs merged into one fitted mode, or several peaks at
/// once, are resolved by adding a mode at every significant residual peak and refining,
/// with the local and F tests of the structure adaptation per mode (what `frfit fit`
/// does); tested as one candidate against the rest. `None` when it adds no mode or
/// does not lower the cost.
pub fn joint_missed_modes(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
) -> Option<Trial> {
    let fd = &ctx.fit_data;
    let acfg = AdaptConfig {
        min_f: cfg.min_f,
        alpha: cfg.alpha,
        // every added mode must still pass the local and F tests
        peak_over_local: 5.0,
        ..Default::default()
    };
    let (af, rep) = additive_riv::adapt_modes(current.model.clone(), fd, riv, &acfg).ok()?;
    let describe = |list: &str| {
        format!(
            "significant residual peaks; modes added at every peak in {} round(s) of add/drop with the local test per mode (removed on the way: {}): {list}",
            rep.rounds,
            rep.dropped.len(),
        )
    };
    let c = model_cost(&af.model, fd);
    new_modes_trial(fd, cfg, current, af.model, c, describe)
}

/// Missed modes from the common-denominator (Sanathanan-Koerner) start `sk`: its lightly
/// damped poles in the band that the current model lacks (none of its modes within 3 %,
/// [`new_modes`]) added together at the start's frequencies and damping, refitted
/// (numerators, eq. 24, then Algorithm 1), and tested as one candidate. The loop tries
/// it when a round has nothing else to propose while the residual is significant: two
/// missed modes close together (6 % apart) raise each other's local median, so the
/// residual's peak test does not single either out (the simulated stage of seed 7 with a
/// sensor resonance, after the factor: 1466 and 1561 Hz missing at 235 times the noise),
/// but a common denominator sees every mode at once. `None` when the start holds no
/// such mode or the refit fails or does not lower the cost.
pub fn common_denominator_modes(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
    sk: &AdditiveModel,
) -> Option<Trial> {
    let fd = &ctx.fit_data;
    let new = lacked_light_modes(current.model, sk, fd.band_hz);
    if new.is_empty() {
        return None;
    }
    let mut aug = current.model.clone();
    for &(f, z) in &new {
        aug = additive_riv::augment::with_mode(&aug, f, z).ok()?;
    }
    let r = refit(aug, fd, riv).ok()?;
    // a NaN cost lowers nothing either
    if r.cost.is_nan() || r.cost >= current.cost {
        return None;
    }
    let added = r
        .model
        .n_params()
        .saturating_sub(current.model.n_params())
        .max(1);
    let (_, f, f_crit) = f_test(&r.model, fd, current.cost, r.cost, added, cfg);
    let joint = new_modes(current.model, &r.model);
    let first = joint.first().copied().unwrap_or(new[0]);
    let list: Vec<String> = new.iter().map(|(f, _)| format!("{f:.2} Hz")).collect();
    let kept: Vec<String> = joint.iter().map(|(f, _)| format!("{f:.2} Hz")).collect();
    let evidence = format!(
        "nothing else proposed while the residual is significant: the common-denominator (sk) start holds lightly damped modes the model lacks at {}; added together and refitted: {}",
        list.join(", "),
        kept.join(", ")
    );
    Some(Trial::missed_modes(
        first,
        joint,
        evidence,
        r.model,
        (r.cost, f, f_crit, added),
    ))
}

/// The trial of `model` (at weighted cost `c`), a refit of the current model that holds
/// modes beyond its ([`new_modes`]), tested together against it ([`f_test`]), each
/// reported as its own `missed_mode` step; the evidence is `describe` of their list.
/// `None` when it holds no new mode, adds no parameter or does not lower the cost.
fn new_modes_trial(
    fd: &FitData,
    cfg: &PipelineConfig,
    current: &Current,
    model: AdditiveModel,
    c: f64,
    describe: impl FnOnce(&str) -> String,
) -> Option<Trial> {
    let joint = new_modes(current.model, &model);
    let added = model.n_params().saturating_sub(current.model.n_params());
    if joint.is_empty() || added == 0 || c.is_nan() || c >= current.cost {
        return None;
    }
    let (_, f, f_crit) = f_test(&model, fd, current.cost, c, added, cfg);
    let list: Vec<String> = joint.iter().map(|(f, _)| format!("{f:.2} Hz")).collect();
    let evidence = describe(&list.join(", "));
    Some(Trial::missed_modes(
        joint[0],
        joint,
        evidence,
        model,
        (c, f, f_crit, added),
    ))
}

/// The loop's twin merge of a model at a cost, its notes appended to the vector; `None`
/// when it fails.
pub type TwinMerge<'a> =
    dyn Fn(AdditiveModel, f64, &mut Vec<String>) -> Option<(AdditiveModel, f64)> + Sync + 'a;

/// Missed modes that show no residual peak of their own, found by the repairs of
/// [`additive_riv::split`] on the current model: a mode beyond a band edge (a tail
/// rising towards the edge) and close pairs that the start merged into one mode (the
/// second mode of the pair under the first one's flank, its residual a wiggle around
/// the merged mode that raises the local median the peak test compares with). The
/// repairs settle their trials themselves (their own F and local tests); here the
/// repaired model is refitted (Algorithm 1 at the candidates' tolerance), twins a split
/// left are merged by `merge_twins` (the loop's twin merge: a merged pair's misfit can
/// make a neighbouring mode split into twins first), and the modes it holds beyond the current
/// model's ([`new_modes`]: the member of a split pair farther from the merged mode) are
/// tested together as one candidate, each reported as its own `missed_mode` step. The
/// first fit makes these repairs itself unless the modes were declared (`--modes N` or
/// frequencies): a mode beyond the declared ones is then a discovery, tested here.
/// `None` when the repairs change nothing, or the result lowers the cost by no mode.
pub fn repaired_modes(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
    merge_twins: &TwinMerge<'_>,
) -> Option<Trial> {
    use additive_riv::split::{add_out_of_band_mode, split_close_pairs, SplitConfig};
    let fd = &ctx.fit_data;
    let scfg = SplitConfig {
        alpha: cfg.alpha,
        min_f: cfg.min_f,
        ..Default::default()
    };
    let (m, edge) = add_out_of_band_mode(current.model.clone(), fd, riv, &scfg).ok()?;
    let (m, pairs) = split_close_pairs(m, fd, riv, &scfg).ok()?;
    if edge.is_empty() && pairs.is_empty() {
        return None;
    }
    let r = refit(m, fd, riv).ok()?;
    let mut notes = Vec::new();
    let (m, c) = merge_twins(r.model, r.cost, &mut notes)?;
    let mut what: Vec<String> = edge
        .out_of_band
        .iter()
        .map(|e| {
            format!(
                "a tail rising towards the {} band edge: a mode beyond it at {:.2} Hz (zeta {:.4}, F = {:.1}; weighted cost {:.4e} -> {:.4e})",
                e.edge, e.f_hz, e.zeta, e.f_stat, e.cost.0, e.cost.1
            )
        })
        .collect();
    what.extend(pairs.splits.iter().map(|s| {
        format!(
            "the residual around the mode at {:.2} Hz far above the band's quiet lines and the typical mode's: a close pair merged into one mode, split into {:.2} and {:.2} Hz (F = {:.1}; weighted cost {:.4e} -> {:.4e})",
            s.from_hz, s.into[0].0, s.into[1].0, s.f_stat, s.cost.0, s.cost.1
        )
    }));
    what.extend(notes);
    let describe = |list: &str| {
        format!(
            "modes without a residual peak of their own: {}; refitted, the model holds new modes at {list}",
            what.join("; ")
        )
    };
    new_modes_trial(fd, cfg, current, m, c, describe)
}

/// A delay large enough to matter also misplaces the modes fitted without it: the fit
/// from the start (the run's estimator chain, `--init`/`--refine`, with the delay
/// estimated from the data's phase slope and refined, [`super::restart::delay_restart`];
/// `restart` when it was made already), tested beside the incremental refit. A restart
/// can also gain for reasons of its own (another optimum), so the trial passes only
/// when it beats the current model AND the restart refitted with the delay held at the
/// current value (the delay itself explains more than noise). `None` when the restart
/// fails, does not lower the cost or ends without a fitted delay.
pub fn restart_with_delay(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    current: &Current,
    restart: Option<DelayRestart>,
) -> Option<Trial> {
    let fd = &ctx.fit_data;
    let r = match restart {
        Some(r) => r,
        None => delay_restart(ctx, cfg, current.model.factor.delay_s)?,
    };
    let (m, c) = (r.with_delay, r.with_delay_cost);
    if c >= current.cost {
        return None;
    }
    let added = m.n_params().saturating_sub(current.model.n_params()).max(1);
    let (_, mut f, f_crit) = f_test(&m, fd, current.cost, c, added, cfg);
    let mut evidence = format!(
        "the residual's phase slope; refitted from the start with the delay estimated from the data ({:.2} us) and refined to {:.2} us, {} modes",
        r.estimate_s.map_or(f64::NAN, |t| t * 1e6),
        m.factor.delay_s * 1e6,
        m.modes().len()
    );
    if let Some((held, held_cost)) = &r.held {
        // the delay's own test: the same restart with the delay held at the current value
        let (_, f_delay, f_delay_crit) = f_test(&m, fd, *held_cost, c, 1, cfg);
        evidence = format!(
            "{evidence}; against the same restart with the delay held at {:.2} us ({} modes): F = {f_delay:.3e} (critical {f_delay_crit:.3})",
            current.model.factor.delay_s * 1e6,
            held.model.modes().len()
        );
        if !(*held_cost > c && f_delay > f_delay_crit) {
            evidence.push_str(": the restart's gain is not the delay's");
            f = f.min(f_crit * (1.0 - 1e-12));
        }
    }
    Some(Trial {
        params: FittedEffect::delay(current.model, &m, Some(Refit::FromTheStart)),
        evidence,
        model: m,
        cost: c,
        f,
        f_crit,
        added,
        joint_modes: Vec::new(),
        screened: None,
        candidate: None,
        held_out: None,
    })
}

/// The candidate of `proposal` added to the current model, refitted and F-tested;
/// `None` when the augmentation or the refit fails. With `cap`, the refit stops after
/// that many iterations (a screening: [`Trial::screened`] is set when it had not
/// converged, and [`finish`] continues it). A missed mode must also remove most (75 %)
/// of the residual within 1 % of its peak, or its F statistic is held below the
/// critical value.
pub fn refit_candidate(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
    proposal: Proposal,
    cap: Option<usize>,
) -> Option<Trial> {
    let fd = &ctx.fit_data;
    let Proposal {
        candidate,
        evidence,
    } = proposal;
    let aug = candidate.augment(current.model).ok()?;
    let riv_capped = RivConfig {
        max_iterations: cap.map_or(riv.max_iterations, |c| c.min(riv.max_iterations)),
        ..riv.clone()
    };
    let mut r = refit(aug, fd, &riv_capped).ok()?;
    let mut evidence = evidence;
    let new_factors = usize::from(candidate.factor_start().is_some());
    if let Some((without, note)) =
        without_redundant_parts(&r.model, current.model, new_factors, fd, &riv_capped)
    {
        r = Refitted {
            iterations: r.iterations + without.iterations,
            ..without
        };
        evidence = format!("{evidence}; {note}");
    }
    let Refitted {
        model: m,
        cost: c,
        iterations,
        capped,
        remaining,
    } = r;
    let screened = (cap.is_some() && capped).then(|| Screened {
        candidate: candidate.clone(),
        evidence: evidence.clone(),
        iterations,
        remaining,
    });
    let mut tr = judge(cfg, fd, current, &candidate, evidence, m, c);
    tr.screened = screened;
    Some(tr)
}

/// The suspended-body reading ([`super::candidate::suspended_body`]) tested: the
/// suspension in place of the free rigid body and the lowest mode, refitted
/// (numerators, eq. 24, then Algorithm 1 to a coarse tolerance), against the current
/// model, which is the suspension plus the free body's parameters (the suspension is the
/// current model with the rigid body's numerator at zero: the two are nested). The F
/// statistic is that of the free body's parameters beside the suspension (the cost they
/// explain per parameter over the noise scale of the current model) with its critical
/// value at `cfg.alpha`; the reading is accepted (`true`) when they are not significant
/// (F at most critical) and the refit leaves no more unstable parts: the simpler
/// model, the body on its suspension, is kept. A genuine low mode beside a free body
/// fails it, since the body's `1 / s^2` carries the lowest lines. `None` when the
/// augmentation or the refit fails.
pub fn suspended_body(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
    proposal: Proposal,
) -> Option<(Trial, bool)> {
    let fd = &ctx.fit_data;
    let Proposal {
        candidate,
        evidence,
    } = proposal;
    let aug = candidate.augment(current.model).ok()?;
    let Refitted { model: m, cost, .. } = refit(aug, fd, riv).ok()?;
    let removed = current.model.n_params().saturating_sub(m.n_params()).max(1);
    let (_, f, f_crit) = f_test(current.model, fd, cost, current.cost, removed, cfg);
    let stable = unstable_parts(&m) <= unstable_parts(current.model);
    let accepted = f <= f_crit && stable;
    let verdict = if accepted {
        "not significant: the body on its suspension is kept"
    } else if stable {
        "significant: the free body stays, the mode is a mode"
    } else {
        "the suspension's refit is unstable: the free body stays"
    };
    let evidence = format!(
        "{evidence} The free rigid body's {removed} parameters beside the suspension explain F = {f:.3} (critical {f_crit:.3}): {verdict}"
    );
    let params = FittedEffect::of_refit(&candidate, current.model, &m);
    Some((
        Trial::reading(params, evidence, (m, cost), (f, f_crit)),
        accepted,
    ))
}

/// Continues a screened trial's refit to convergence from where the screening stopped
/// and tests it again; a trial that is not screened is returned as it is. `None` when
/// the continued refit fails.
pub fn finish(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
    tr: Trial,
) -> Option<Trial> {
    let Some(sc) = tr.screened else {
        return Some(tr);
    };
    let fd = &ctx.fit_data;
    let f = iterate(tr.model, fd, riv).ok()?;
    let new_factors = usize::from(sc.candidate.factor_start().is_some());
    let (model, c, evidence) =
        match without_redundant_parts(&f.model, current.model, new_factors, fd, riv) {
            Some((r, note)) => (r.model, r.cost, format!("{}; {note}", sc.evidence)),
            None => {
                let c = model_cost(&f.model, fd);
                (f.model, c, sc.evidence)
            }
        };
    Some(judge(cfg, fd, current, &sc.candidate, evidence, model, c))
}

/// The trial of `candidate` refitted to `m` (cost `c`): its F test against the current
/// model and, for a missed mode, the local test at its peak.
fn judge(
    cfg: &PipelineConfig,
    fd: &FitData,
    current: &Current,
    candidate: &Candidate,
    mut evidence: String,
    m: AdditiveModel,
    c: f64,
) -> Trial {
    let added = m.n_params().saturating_sub(current.model.n_params()).max(1);
    let (stats, mut f, f_crit) = f_test(&m, fd, current.cost, c, added, cfg);
    if let Candidate::MissedMode { peak_hz: fp, .. } = candidate {
        let half = 0.01 * fp;
        let ratio = local_energy(&stats, fd, *fp, half)
            / local_energy(current.stats, fd, *fp, half).max(f64::MIN_POSITIVE);
        evidence = format!(
            "{evidence}; after the refit {:.0}% of the residual within 1% of the peak remains",
            100.0 * ratio
        );
        if ratio > 0.25 {
            f = f.min(f_crit * (1.0 - 1e-12));
        }
    }
    let params = FittedEffect::of_refit(candidate, current.model, &m);
    Trial {
        params,
        evidence,
        model: m,
        cost: c,
        f,
        f_crit,
        added,
        joint_modes: Vec::new(),
        screened: None,
        candidate: Some(candidate.clone()),
        held_out: None,
    }
}

/// The zeros of a dynamics factor tested beside the same factor without them: for every
/// trial whose candidate is the order-(n/n) rational twin of an all-pole candidate of
/// the round (same effect, support and order), the F test of the `n` numerator
/// coefficients (the two models are nested: zeros at infinity give the all-pole factor)
/// on the cost the twin lowers below the all-pole refit. A twin whose zeros are not
/// significant there, or that fits no better, is held below its critical value: the
/// all-pole factor is the simpler model of the same physics. An all-pole refit that left
/// a pole in the right half-plane (a lead that only an unstable pole can mimic) is no
/// reference: the twin is then tested against the current model alone. A twin common to
/// every entry whose refit put a zero in the right half-plane is held back too: there
/// `(1 - s / w_z) / (1 + s / w_p)` is the Pade form of a delay, which the catalogue's
/// `delay` (one parameter) explains more simply (on the simulated stage with a common
/// lag and an undeclared delay, such a twin at 2.7 kHz took the delay's place).
pub fn test_zeros(trials: &mut [Trial], fd: &FitData, cfg: &PipelineConfig, current: &Current) {
    let stable = unstable_parts(current.model);
    let siblings: Vec<(String, f64, validation::analysis::Effect)> = trials
        .iter()
        .filter_map(|t| {
            let c = t.candidate.as_ref()?;
            let start = c.factor_start()?;
            (start.zeros.is_none() && unstable_parts(&t.model) <= stable)
                .then(|| (c.key(), t.cost, c.effect()))
        })
        .collect();
    for t in trials.iter_mut() {
        let Some(c) = &t.candidate else { continue };
        let Some(start) = c.factor_start() else {
            continue;
        };
        if start.zeros.is_none() {
            continue;
        }
        let rhp_zero = t
            .model
            .dynamics
            .last()
            .is_some_and(|d| d.is_non_minimum_phase());
        // a zero the refit moved beyond the screening grid's top (4 times the top line)
        // does not show in the band: what it gained is the misfit of the rest of the
        // model (on the reference plate with an output lag and four missed modes, a
        // zero at 43 kHz moved the lag from 900 to 933 Hz)
        let f_far = 4.0 * fd.band_hz.1;
        let far_zero = t.model.dynamics.last().is_some_and(|d| {
            d.zeros()
                .iter()
                .any(|z| z.norm() / std::f64::consts::TAU > f_far)
        });
        if far_zero {
            t.hold_back(&format!(
                "its refit put a zero above {f_far:.0} Hz, beyond what the band shows; not accepted"
            ));
            continue;
        }
        if c.is_common_factor() && rhp_zero {
            t.hold_back(
                "its refit put a zero in the right half-plane on every entry: the Pade form of a delay, which the delay explains with one parameter; not accepted",
            );
            continue;
        }
        let key = c.key();
        let base_key = key.strip_suffix(":z").unwrap_or(&key);
        let Some((_, all_pole_cost, _)) = siblings
            .iter()
            .find(|(k, _, e)| k == base_key && *e == c.effect())
        else {
            continue;
        };
        let n = start.order;
        let (_, f, f_crit) = f_test(&t.model, fd, *all_pole_cost, t.cost, n, cfg);
        let significant = t.cost < *all_pole_cost && f > f_crit;
        t.evidence = format!(
            "{}; its {n} zero coefficient(s) beside the all-pole factor's refit (cost {all_pole_cost:.4e} -> {:.4e}): F = {f:.3e} (critical {f_crit:.3}){}",
            t.evidence,
            t.cost,
            if significant {
                ""
            } else {
                ": not significant, the all-pole factor is kept"
            }
        );
        if !significant {
            t.f = t.f.min(t.f_crit * (1.0 - 1e-12));
        }
    }
}

/// How far above the band's top line a pole of a refitted factor may lie before the
/// band cannot tell it from none: at 100 times the top line its phase there is below
/// 0.6 degrees and its magnitude change below 5e-5, what a delay of a few nanoseconds
/// or the noise explains.
pub const FAR_POLE_OVER_TOP: f64 = 100.0;

/// A second-order all-pole factor whose refit split its poles into one real pole the band
/// shows and one beyond [`FAR_POLE_OVER_TOP`] times the top line is a first-order factor
/// with a second pole the data cannot see (on a simulated stage with a 700 Hz lag on one
/// input, seed 29: poles at 700.002 Hz and 83 MHz). When the first-order factor on the
/// same support passes as well, that reading is the one reported: the second-order trial
/// is held back, and the round's best passing trial is the first-order factor (on that
/// stage the two refits ended at residual/noise 1.05745 and 1.05736, median relative
/// error against the data 5.834e-4 and 5.833e-4).
pub fn test_far_poles(trials: &mut [Trial], fd: &FitData) {
    let f_far = FAR_POLE_OVER_TOP * fd.band_hz.1;
    // (effect, support) of the passing first-order all-pole factors
    let first_order: Vec<(validation::analysis::Effect, String)> = trials
        .iter()
        .filter(|t| t.passes())
        .filter_map(|t| {
            let c = t.candidate.as_ref()?;
            let start = c.factor_start()?;
            (start.order == 1 && start.zeros.is_none()).then(|| (c.effect(), support_of(&c.key())))
        })
        .collect();
    for t in trials.iter_mut() {
        if !t.passes() {
            continue;
        }
        let Some(c) = &t.candidate else { continue };
        let Some(start) = c.factor_start() else {
            continue;
        };
        if start.order != 2 || start.zeros.is_some() {
            continue;
        }
        let support = support_of(&c.key());
        if !first_order
            .iter()
            .any(|(e, s)| *e == c.effect() && *s == support)
        {
            continue;
        }
        let Some(poles) = t.model.dynamics.last().map(|d| d.poles()) else {
            continue;
        };
        let hz = |p: &frf_data::C64| p.norm() / std::f64::consts::TAU;
        let far = poles.iter().filter(|p| hz(p) > f_far).count();
        let real = poles.iter().all(|p| p.im.abs() <= 1e-9 * p.norm());
        if poles.len() == 2 && real && far == 1 {
            let f_far_pole = poles.iter().map(hz).fold(0.0, f64::max);
            t.hold_back(&format!(
                "its refit put one of its two real poles at {f_far_pole:.3e} Hz, beyond \
                 {FAR_POLE_OVER_TOP} times the top line, where the band cannot see it: the \
                 first-order factor on the same support, which passes too, is the reading"
            ));
        }
    }
}

/// The support part of a dynamics factor candidate's key (`3` for input or output 4,
/// `all` for a common factor), see [`Candidate::key`].
fn support_of(key: &str) -> String {
    key.split(':').next().unwrap_or_default().to_string()
}

/// A low mode beside the free rigid body or a suspended body: for a round that refitted
/// both readings of the residual's suspension signature (the `stiffness` and the
/// `missed_mode` proposed beside the free body, [`super::candidate::propose`]) and both
/// passed, the free body's parameters decide. The two models are nested: the mode's
/// model with the free body's residues at zero is the suspension's (a pair in place of
/// `R / s^2`), so the F test of those parameters (the cost the mode's model lowers
/// below the suspension's, per parameter it has more) at `cfg` tells them apart:
///
/// - significant: the body is free and the resonance a mode beside it; the stiffness is
///   held below its critical value;
/// - not significant, or the mode's model fits no better: the suspension is the simpler
///   model of the same physics; the mode is held below its critical value.
///
/// On a body suspended at 2.5 Hz (lines from 4 Hz) the mode beside the free body fits
/// as well as the suspension with more parameters; on a free body with a mode at 3 Hz
/// of five times its residue (lines from 2 Hz) the suspension leaves the body's part
/// unexplained.
pub fn mode_or_suspension(trials: &mut [Trial], fd: &FitData, cfg: &PipelineConfig) {
    let beside_body = |t: &Trial| {
        matches!(
            t.candidate,
            Some(Candidate::MissedMode {
                body_integrators: Some(_),
                ..
            })
        )
    };
    let suspension = |t: &Trial| {
        matches!(
            t.candidate,
            Some(Candidate::Stiffness { replaces: None, .. })
        )
    };
    let Some(si) = trials.iter().position(|t| suspension(t) && t.passes()) else {
        return;
    };
    // the better of the two free bodies
    let Some(mi) = (0..trials.len())
        .filter(|&i| beside_body(&trials[i]) && trials[i].passes())
        .min_by(|&a, &b| trials[a].cost.total_cmp(&trials[b].cost))
    else {
        return;
    };
    let (mode, susp) = (&trials[mi], &trials[si]);
    let extra = mode.model.n_params().saturating_sub(susp.model.n_params());
    let (f, f_crit) = if extra > 0 && mode.cost < susp.cost {
        let (_, f, f_crit) = f_test(&mode.model, fd, susp.cost, mode.cost, extra, cfg);
        (f, f_crit)
    } else {
        (0.0, f64::INFINITY)
    };
    if f > f_crit {
        let note = format!(
            "the free rigid body beside the mode at {:.3} Hz is significant ({extra} parameter(s), cost {:.4e} -> {:.4e}, F = {f:.3e} > {f_crit:.3}): a mode beside a free body, not a suspension; not accepted",
            match mode.params {
                FittedEffect::MissedMode { f_hz, .. } => f_hz,
                _ => f64::NAN,
            },
            susp.cost,
            mode.cost
        );
        trials[si].hold_back(&note);
    } else {
        let note = format!(
            "beside the suspension's refit (cost {:.4e}) the free rigid body's {extra} parameter(s) are not significant (F = {f:.3e}, critical {f_crit:.3}): the suspension is the simpler model; not accepted",
            susp.cost
        );
        for t in trials.iter_mut().filter(|t| beside_body(t)) {
            t.hold_back(&note);
        }
    }
}
