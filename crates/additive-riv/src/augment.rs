//! Augmentations of an [`AdditiveModel`] for the diagnosis loop's catalogue of effects
//! (DESIGN.md): each returns a new model whose structure holds the effect, with the new
//! parameters at a starting value and the numerators to be refitted (eq. 24) and the
//! whole refined (Algorithm 1) by the caller.

use crate::model::{DynamicsFactor, FactorTarget, SubmodelKind};
use crate::{AdditiveModel, Domain, KnownFactor, RivError};
use frf_data::ModelStructure;
use std::f64::consts::TAU;

/// Adds a mode at `f_hz` with damping `zeta` (a missed mode).
pub fn with_mode(model: &AdditiveModel, f_hz: f64, zeta: f64) -> Result<AdditiveModel, RivError> {
    let mut m = model.clone();
    let first_order = m.submodels.iter().any(|s| {
        s.kind == SubmodelKind::Mode && s.num.len() == 2 && m.domain() == Domain::Continuous
    });
    m.push_mode(f_hz, zeta, first_order)?;
    Ok(m)
}

/// Makes the delay a free parameter starting from its current value (an uncompensated
/// delay); `extra_s` is added to the start.
pub fn with_fitted_delay(model: &AdditiveModel, extra_s: f64) -> Result<AdditiveModel, RivError> {
    if model.factor.fit_delay {
        return Err(RivError::Structure(
            "the delay is already a fitted parameter".into(),
        ));
    }
    let f = KnownFactor {
        delay_s: model.factor.delay_s + extra_s,
        fit_delay: true,
        ..model.factor
    };
    model.clone().with_factor(f)
}

/// Adds a constant feedthrough (crosstalk) submodel.
pub fn with_feedthrough(model: &AdditiveModel) -> Result<AdditiveModel, RivError> {
    let mut m = model.clone();
    m.push_feedthrough()?;
    Ok(m)
}

/// Adds a constant crosstalk that bypasses the known delay and hold (see
/// [`crate::Submodel::bypass_factor`]).
pub fn with_crosstalk(model: &AdditiveModel) -> Result<AdditiveModel, RivError> {
    let mut m = model.clone();
    m.push_bypass_feedthrough()?;
    Ok(m)
}

/// Replaces the free rigid body `B / s^l` (`l` = 2, or 1 when the first fit took the
/// suspension's damped roll-off for one integrator) by a suspended one
/// `B / (s^2 + 2 zeta w_s s + w_s^2)` (a stiffness), kind [`SubmodelKind::Suspension`].
pub fn with_stiffness(
    model: &AdditiveModel,
    f_hz: f64,
    zeta: f64,
) -> Result<AdditiveModel, RivError> {
    let idx = model
        .submodels
        .iter()
        .position(|s| s.kind == SubmodelKind::RigidBody && s.integrators >= 1)
        .ok_or_else(|| RivError::Structure("no rigid body (1/s^l) to suspend".into()))?;
    let mut m = model.clone();
    m.remove_submodel(idx);
    let i = m.push_mode(f_hz, zeta, false)?;
    m.submodels[i].kind = SubmodelKind::Suspension;
    Ok(m)
}

/// Adds a first-order (`order = 1`) or second-order (`order = 2`, damping 0.7)
/// low-pass factor with corner `f_hz` to the entries of `target` (actuator or sensor
/// dynamics).
pub fn with_dynamics(
    model: &AdditiveModel,
    target: FactorTarget,
    order: usize,
    f_hz: f64,
) -> Result<AdditiveModel, RivError> {
    if !(f_hz.is_finite() && f_hz > 0.0) {
        return Err(RivError::invalid("factor corner", f_hz, "must be > 0 Hz"));
    }
    let f = match order {
        1 => DynamicsFactor::first_order(target, f_hz),
        2 => DynamicsFactor::second_order(target, f_hz, 0.7),
        _ => return Err(RivError::invalid("factor order", order, "must be 1 or 2")),
    };
    let mut m = model.clone();
    m.push_dynamics(f)?;
    Ok(m)
}

/// The exact zero-order-hold form of a continuous model at sample rate `fs_hz`: the
/// same modes (frequency and damping), rigid body, feedthrough and dynamics factors in
/// the shift variable, the delay reduced by the hold's half sample (the hold's phase is
/// now modelled), the sinc factor dropped. Numerators are zero: refit them.
pub fn to_exact_hold(model: &AdditiveModel, fs_hz: f64) -> Result<AdditiveModel, RivError> {
    if model.domain() != Domain::Continuous {
        return Err(RivError::Structure(
            "the model already holds the exact zero-order hold".into(),
        ));
    }
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return Err(RivError::invalid(
            "hold sample rate",
            fs_hz,
            "must be > 0 Hz",
        ));
    }
    if model.factor.derivative_order != 0 {
        return Err(RivError::Structure(
            "the exact hold is for displacement-type data (no derivative factor)".into(),
        ));
    }
    let ts = 1.0 / fs_hz;
    let mut m = AdditiveModel::new(model.ny(), model.nu(), Domain::ZohDiscrete { ts })?
        .with_factor(KnownFactor {
            delay_s: model.factor.delay_s - 0.5 * ts,
            sinc_hold_fs: None,
            ..model.factor
        })?;
    for s in &model.submodels {
        match s.kind {
            SubmodelKind::RigidBody => {
                m.push_rigid_body(s.integrators, 1.0)?;
            }
            SubmodelKind::Feedthrough if s.bypass_factor => {
                m.push_bypass_feedthrough()?;
            }
            SubmodelKind::Feedthrough => {
                m.push_feedthrough()?;
            }
            SubmodelKind::Mode | SubmodelKind::Suspension | SubmodelKind::General => {
                match model.upper_pole(s) {
                    Some(p) => {
                        let f = p.norm() / TAU;
                        let zeta = (-p.re / p.norm()).clamp(1e-4, 0.99);
                        if f >= 0.5 * fs_hz {
                            return Err(RivError::Structure(format!(
                                "mode at {f:.1} Hz is above the Nyquist frequency of the hold"
                            )));
                        }
                        let i = m.push_mode(f, zeta, false)?;
                        m.submodels[i].kind = s.kind;
                    }
                    None => {
                        return Err(RivError::Structure(
                            "a submodel with real poles has no exact-hold form here".into(),
                        ))
                    }
                }
            }
        }
    }
    for d in &model.dynamics {
        m.push_dynamics(d.clone())?;
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> AdditiveModel {
        let mut m = AdditiveModel::new(2, 2, Domain::Continuous).unwrap();
        m.push_rigid_body(2, 300.0).unwrap();
        m.push_mode(120.0, 0.01, false).unwrap();
        m.with_factor(KnownFactor {
            delay_s: 1.5e-4,
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn exact_hold_keeps_modes_and_moves_half_a_sample() {
        let h = to_exact_hold(&base(), 1e4).unwrap();
        assert!((h.factor.delay_s - 1e-4).abs() < 1e-15);
        assert!((h.modes()[0].f_hz - 120.0).abs() < 1e-9);
        assert!(to_exact_hold(&h, 1e4).is_err());
    }

    #[test]
    fn stiffness_replaces_the_rigid_body() {
        let s = with_stiffness(&base(), 5.0, 0.05).unwrap();
        assert!(s
            .submodels
            .iter()
            .all(|x| x.kind != SubmodelKind::RigidBody));
        assert!(s
            .submodels
            .iter()
            .any(|x| x.kind == SubmodelKind::Suspension));
        assert!(with_stiffness(&s, 5.0, 0.05).is_err());
    }

    #[test]
    fn other_augmentations() {
        let b = base();
        assert_eq!(with_feedthrough(&b).unwrap().submodels.len(), 3);
        assert!(with_fitted_delay(&b, 0.0).unwrap().factor.fit_delay);
        let d = with_dynamics(&b, FactorTarget::Input(1), 1, 300.0).unwrap();
        assert_eq!(d.n_params(), b.n_params() + 1);
        assert!(with_dynamics(&b, FactorTarget::Input(5), 1, 300.0).is_err());
        assert_eq!(with_mode(&b, 400.0, 0.01).unwrap().modes().len(), 2);
    }
}
