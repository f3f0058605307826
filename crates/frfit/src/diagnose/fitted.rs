//! What a trial found: the effect's parameters as fitted, serialised as the `params` of
//! a step of `summary.json` (field names of the README's schema section).

use super::candidate::{Candidate, FactorStart};
use super::refit::new_modes;
use crate::effects::{FactorParams, FactorSupport, FittedEffect, PoleParams, Refit};
use additive_riv::{AdditiveModel, SubmodelKind};
use std::f64::consts::TAU;

impl FittedEffect {
    /// The delay of `after` as a step beyond `before`.
    pub fn delay(before: &AdditiveModel, after: &AdditiveModel, refit: Option<Refit>) -> Self {
        FittedEffect::Delay {
            seconds: after.factor.delay_s - before.factor.delay_s,
            total_delay_s: after.factor.delay_s,
            refit,
        }
    }

    /// The parameters of `candidate` as fitted in `m`, the refit of `before` with it;
    /// a parameter the refit does not show is reported at its start.
    pub fn of_refit(candidate: &Candidate, before: &AdditiveModel, m: &AdditiveModel) -> Self {
        match candidate {
            Candidate::MissedMode { f_hz: f0, zeta, .. } => {
                // the mode of `m` that `before` does not have: the one nearest the start
                let new = new_modes(before, m)
                    .into_iter()
                    .min_by(|a, b| (a.0 - f0).abs().total_cmp(&(b.0 - f0).abs()));
                let (f_hz, zeta) = new.unwrap_or((*f0, *zeta));
                FittedEffect::MissedMode { f_hz, zeta }
            }
            Candidate::Delay { .. } => Self::delay(before, m, None),
            Candidate::Hold { fs_hz } => FittedEffect::Hold {
                fs_hz: *fs_hz,
                remaining_delay_s: m.factor.delay_s,
            },
            Candidate::Feedthrough { .. } => {
                let rms = m
                    .to_modal_model()
                    .map(|mm| {
                        let mut s = 0.0;
                        for j in 0..mm.nu {
                            for i in 0..mm.ny {
                                s += mm.feedthrough[(i, j)].powi(2);
                            }
                        }
                        (s / (mm.ny * mm.nu) as f64).sqrt()
                    })
                    .unwrap_or(f64::NAN);
                let bypasses_delay = m
                    .submodels
                    .iter()
                    .any(|s| s.kind == SubmodelKind::Feedthrough && s.bypass_factor);
                FittedEffect::Feedthrough {
                    rms,
                    bypasses_delay,
                }
            }
            Candidate::Stiffness { f_hz, zeta, .. } => {
                let s = m
                    .submodels
                    .iter()
                    .find(|s| s.kind == SubmodelKind::Suspension);
                let (f_hz, zeta) = match s.and_then(|s| m.upper_pole(s)) {
                    Some(p) => (p.norm() / TAU, -p.re / p.norm()),
                    None => (*f_hz, *zeta),
                };
                FittedEffect::Stiffness { f_hz, zeta }
            }
            Candidate::InputDynamics { inputs, start } => FittedEffect::InputDynamics {
                inputs: inputs.clone(),
                factor: factor_params(candidate, start, FactorSupport::Inputs, m),
            },
            Candidate::OutputDynamics { outputs, start } => FittedEffect::OutputDynamics {
                outputs: outputs.clone(),
                factor: factor_params(candidate, start, FactorSupport::Outputs, m),
            },
        }
    }
}

/// The dynamics factor of `candidate` (started from `start`) as fitted in `m`: on every
/// entry for a common factor, else on `side`.
fn factor_params(
    candidate: &Candidate,
    start: &FactorStart,
    side: FactorSupport,
    m: &AdditiveModel,
) -> FactorParams {
    let (poles, zeros, non_minimum_phase) = fitted_roots(m, start);
    FactorParams {
        support: if candidate.is_common_factor() {
            FactorSupport::All
        } else {
            side
        },
        order: start.order,
        poles,
        zeros,
        non_minimum_phase,
    }
}

/// A root (rad/s) as reported.
fn root_params(p: &realize::C64) -> PoleParams {
    let f = p.norm();
    PoleParams {
        f_hz: f / TAU,
        zeta: (f > 0.0).then(|| -p.re / f),
        re: Some(p.re),
        im: Some(p.im),
    }
}

/// The poles and zeros of the newest dynamics factor of `m` (the candidate's; one of
/// each complex pair, the upper; lowest frequency first), or the starting pole when it
/// has none; with zeros, whether one is in the closed right half-plane.
fn fitted_roots(
    m: &AdditiveModel,
    start: &FactorStart,
) -> (Vec<PoleParams>, Vec<PoleParams>, Option<bool>) {
    // lowest frequency first: the factor's corner, then any far pole
    let upper = |v: Vec<realize::C64>| -> Vec<PoleParams> {
        let mut r: Vec<PoleParams> = v.iter().filter(|p| p.im >= 0.0).map(root_params).collect();
        r.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
        r
    };
    match m.dynamics.last() {
        Some(d) => (
            upper(d.poles()),
            upper(d.zeros()),
            (!d.num.is_empty()).then(|| d.is_non_minimum_phase()),
        ),
        None => (
            vec![PoleParams {
                f_hz: start.f_hz,
                zeta: (start.order == 2).then_some(start.zeta),
                re: None,
                im: None,
            }],
            Vec::new(),
            None,
        ),
    }
}
