//! A common dynamics factor read as a delay.
//!
//! Over a band below its pole, a first-order factor common to every entry,
//! `1 / (1 + s / w_p)` or the lead-lag `(1 + s / w_z) / (1 + s / w_p)`, turns the phase
//! of every entry as a delay of its low-frequency group delay `1 / w_p - 1 / w_z` does,
//! and the modes' residues absorb most of its magnitude droop. Met with an undeclared
//! delay and a poor first fit, a round can take such a factor where a delay was meant
//! (measured: `cargo xtask effects --case suspension-delay`, plate 100, a suspension with
//! 21 us of undeclared delay: a common lead-lag with its pole at 2772 Hz and its zero at
//! 7998 Hz, 37 us of group delay, accepted before the delay; the model then reached the
//! noise level and the delay was never tested again). Once the model is at the noise
//! level, each common factor that an accepted step added is therefore tested as a delay:
//! the factor taken out, the delay raised by its group delay and freed, and the model
//! refitted. The factor stays only when its parameters beside the delay are significant
//! (F test at the run's level, with its practical floor); otherwise the simpler reading,
//! the delay, is kept. A lag inside the band (an amplifier's bandwidth) passes, since its
//! magnitude and phase over the band are no delay's.

use super::refit::{f_test, refit, unstable_parts, Refitted};
use super::trial::{Current, Trial};
use crate::effects::FittedEffect;
use crate::pipeline::{FitContext, PipelineConfig};
use additive_riv::riv::RivConfig;
use frf_data::ModelStructure;
use realize::{DynamicsFactor, FactorTarget};

/// The low-frequency group delay of a factor `B(x) / A(x)`, `x = s / sigma`:
/// `(a~_1 - b~_1) / sigma` seconds (the phase is `-(a~_1 - b~_1) w / sigma` to first
/// order in `w`).
pub fn group_delay(d: &DynamicsFactor) -> f64 {
    let a1 = d.den.first().copied().unwrap_or(0.0);
    let b1 = d.num.first().copied().unwrap_or(0.0);
    (a1 - b1) / d.scale
}

/// Whether factor `d` can be read as a delay: common to every entry, of first order,
/// with a positive group delay.
pub fn reads_as_delay(d: &DynamicsFactor) -> bool {
    d.target == FactorTarget::All && d.den.len() == 1 && group_delay(d) > 0.0
}

/// The factor `k` of the current model read as a delay (see the module's text): the
/// trial, and whether the delay is kept in its place (the factor's parameters beside
/// the delay not significant, and no more unstable parts). `None` when the factor cannot
/// be read so or the refit fails.
pub fn factor_as_delay(
    ctx: &FitContext,
    cfg: &PipelineConfig,
    riv: &RivConfig,
    current: &Current,
    k: usize,
    factor_step: usize,
) -> Option<(Trial, bool)> {
    let fd = &ctx.fit_data;
    let d = current.model.dynamics.get(k)?;
    if !reads_as_delay(d) {
        return None;
    }
    let tau = group_delay(d);
    let before_s = current.model.factor.delay_s;
    let mut m = current.model.clone();
    m.dynamics.remove(k);
    m.factor.delay_s = before_s + tau;
    m.factor.fit_delay = true;
    let Refitted { model: m, cost, .. } = refit(m, fd, riv).ok()?;
    let removed = current.model.n_params().saturating_sub(m.n_params()).max(1);
    let (_, f, f_crit) = f_test(current.model, fd, cost, current.cost, removed, cfg);
    let stable = unstable_parts(&m) <= unstable_parts(current.model);
    let accepted = f <= f_crit && stable;
    let verdict = if accepted {
        "not significant: the delay is kept in its place"
    } else if stable {
        "significant: the factor stays"
    } else {
        "the delay's refit is unstable: the factor stays"
    };
    let evidence = format!(
        "the common factor of step {} (group delay {:.2} us at low frequency) read as a delay: taken out, the delay raised from {:.2} us by its group delay and refined to {:.2} us; the factor's {removed} parameter{} beside the delay explain F = {f:.3} (critical {f_crit:.3}): {verdict}",
        factor_step + 1,
        tau * 1e6,
        before_s * 1e6,
        m.factor.delay_s * 1e6,
        if removed == 1 { "" } else { "s" },
    );
    let params = FittedEffect::Delay {
        seconds: m.factor.delay_s - before_s,
        total_delay_s: m.factor.delay_s,
        refit: None,
    };
    Some((
        Trial::reading(params, evidence, (m, cost), (f, f_crit)),
        accepted,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The group delay of a lag is `1 / w_p`, of a lead-lag `1 / w_p - 1 / w_z`; a
    /// lead (zero below the pole) has none to read, nor has a factor of one input.
    #[test]
    fn group_delays_of_lags_and_lead_lags() {
        let w = |f: f64| std::f64::consts::TAU * f;
        let lag = DynamicsFactor::first_order(FactorTarget::All, 2000.0);
        assert!((group_delay(&lag) - 1.0 / w(2000.0)).abs() < 1e-15);
        assert!(reads_as_delay(&lag));
        let lead_lag = DynamicsFactor::lead_lag(FactorTarget::All, 8000.0, 2770.0);
        let expected = 1.0 / w(2770.0) - 1.0 / w(8000.0);
        assert!((group_delay(&lead_lag) - expected).abs() < 1e-12 * expected);
        assert!(reads_as_delay(&lead_lag));
        let lead = DynamicsFactor::lead_lag(FactorTarget::All, 300.0, 900.0);
        assert!(group_delay(&lead) < 0.0);
        assert!(!reads_as_delay(&lead));
        assert!(!reads_as_delay(&DynamicsFactor::first_order(
            FactorTarget::Input(2),
            2000.0
        )));
        assert!(!reads_as_delay(&DynamicsFactor::second_order(
            FactorTarget::All,
            2000.0,
            0.5
        )));
    }
}
