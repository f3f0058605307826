//! Initialisation (section 3.3 and 4.4 of the wafer-stage paper): poles from given mode
//! frequencies (the CMIF peaks) with damping 0.01, a rigid body when the low-frequency
//! slope shows one, and the numerators from the convex problem (24)-(25).

use crate::numerators::fit_numerators;
use crate::problem::FitData;
use crate::significance::{f_critical, f_statistic, noise_scale};
use crate::{AdditiveModel, Domain, KnownFactor, RivError};
use frf_data::{Fit, ModelStructure};
use std::f64::consts::TAU;
use std::time::Instant;

/// How many poles at the origin the rigid-body submodel gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RigidBody {
    /// From the low-frequency slope of the data (after the known factor is divided
    /// out): about -40 dB/decade gives 2 (a free mass), -20 dB/decade gives 1, flat
    /// gives none. The default.
    #[default]
    Auto,
    /// No rigid-body submodel.
    None,
    /// This many integrators.
    Integrators(usize),
}

/// Settings of the initialisation.
#[derive(Debug, Clone)]
pub struct InitConfig {
    /// Continuous time (the paper's form) or the exact zero-order hold at a known sample
    /// time. Default: continuous.
    pub domain: Domain,
    /// The known factor (delay, derivative FRF type, sinc hold). Default: none.
    pub factor: KnownFactor,
    /// Rigid-body submodel. Default: [`RigidBody::Auto`].
    pub rigid_body: RigidBody,
    /// Add a feedthrough submodel. Default: false.
    pub feedthrough: bool,
    /// Initial damping of every mode (section 4.4: 0.01). Default: 0.01.
    pub zeta0: f64,
    /// Continuous modes with a first-order numerator `B_0 + B_1 s` (complex residues)
    /// instead of the constant numerator of eq. (26). Default: false.
    pub first_order_numerators: bool,
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            domain: Domain::Continuous,
            factor: KnownFactor::default(),
            rigid_body: RigidBody::Auto,
            feedthrough: false,
            zeta0: 0.01,
            first_order_numerators: false,
        }
    }
}

/// The slope (in decades of magnitude per decade of frequency) of the largest entry
/// magnitude over the lowest lines of the band, after dividing out the known factor.
/// The lines used are those below `min(3 f_lo, f_limit / 2)` (at least the first 5).
pub fn low_frequency_slope(data: &FitData, factor: &KnownFactor, f_limit_hz: f64) -> f64 {
    let m = data.m();
    let f_lo = data.omega[0] / TAU;
    let f_cut = (3.0 * f_lo).min(0.5 * f_limit_hz).max(f_lo);
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for k in 0..data.n {
        let f = data.omega[k] / TAU;
        if f > f_cut && xs.len() >= 5 {
            break;
        }
        let fk = factor.at(data.omega[k]).norm();
        let mut s = 0.0f64;
        for e in 0..m {
            s += (data.g[k * m + e].norm() / fk).powi(2);
        }
        if s > 0.0 {
            xs.push(data.omega[k].log10());
            ys.push(0.5 * s.log10());
        }
    }
    if xs.len() < 2 {
        return 0.0;
    }
    let n = xs.len() as f64;
    let mx = xs.iter().sum::<f64>() / n;
    let my = ys.iter().sum::<f64>() / n;
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    if sxx == 0.0 {
        0.0
    } else {
        sxy / sxx
    }
}

/// The number of integrators that a low-frequency slope suggests.
pub fn integrators_from_slope(slope: f64) -> usize {
    if slope <= -1.5 {
        2
    } else if slope <= -0.5 {
        1
    } else {
        0
    }
}

/// Builds the initial model: rigid body (per `cfg.rigid_body`), one mode per frequency in
/// `mode_freqs_hz` with damping `cfg.zeta0`, optional feedthrough, and numerators from
/// the convex problem (24). Fails when a mode lies outside the band.
pub fn initial_model(
    data: &FitData,
    mode_freqs_hz: &[f64],
    cfg: &InitConfig,
) -> Result<Fit<AdditiveModel>, RivError> {
    let t0 = Instant::now();
    let (lo, hi) = data.band_hz;
    for &f in mode_freqs_hz {
        if !(f >= lo && f <= hi) {
            return Err(RivError::ModeOutsideBand {
                f_hz: f,
                lo_hz: lo,
                hi_hz: hi,
            });
        }
    }
    if !(cfg.zeta0 > 0.0 && cfg.zeta0 < 1.0) {
        return Err(RivError::invalid(
            "initial damping",
            cfg.zeta0,
            "must be in (0, 1)",
        ));
    }
    let mut model = AdditiveModel::new(data.ny, data.nu, cfg.domain)?.with_factor(cfg.factor)?;
    let mut messages = Vec::new();
    let l = match cfg.rigid_body {
        RigidBody::None => 0,
        RigidBody::Integrators(l) => l,
        RigidBody::Auto => {
            let first = mode_freqs_hz.iter().copied().fold(f64::INFINITY, f64::min);
            let slope = low_frequency_slope(data, &cfg.factor, first);
            let l = integrators_from_slope(slope);
            messages.push(format!(
                "rigid body: low-frequency slope {:.2} decades/decade -> {l} integrator(s)",
                slope
            ));
            l
        }
    };
    if l > 0 {
        model.push_rigid_body(l, AdditiveModel::rigid_scale(lo, hi))?;
    }
    let mut sorted: Vec<f64> = mode_freqs_hz.to_vec();
    sorted.sort_by(|a, b| a.total_cmp(b));
    for &f in &sorted {
        model.push_mode(f, cfg.zeta0, cfg.first_order_numerators)?;
    }
    if cfg.feedthrough {
        model.push_feedthrough()?;
    }
    if model.submodels.is_empty() {
        return Err(RivError::Structure(
            "no submodels: no modes were given and no rigid body was found".into(),
        ));
    }
    let c = fit_numerators(&mut model, data)?;
    let mut fit = Fit::from_model(model, "init (CMIF poles, numerators by eq. 24)");
    fit.cost_history = vec![c / (2.0 * data.n as f64)];
    fit.messages = messages;
    fit.push_timing("init", t0.elapsed());
    Ok(fit)
}

/// Checks the sample rate of a zero-order hold against the band: positive, finite, and
/// above twice the highest line.
pub(crate) fn check_fs(fs_hz: f64, f_max: f64) -> Result<(), RivError> {
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return Err(RivError::invalid(
            "hold sample rate",
            fs_hz,
            "must be > 0 Hz",
        ));
    }
    if f_max >= fs_hz / 2.0 {
        return Err(RivError::invalid(
            "hold sample rate",
            fs_hz,
            format!(
                "the band reaches {f_max} Hz, at or above the Nyquist frequency {} Hz",
                fs_hz / 2.0
            ),
        ));
    }
    Ok(())
}

/// Initialises with 0, 1 and 2 integrators and keeps the simplest one that no richer
/// one beats significantly (F test at 1e-3 on the numerator fit (24)).
pub(crate) fn choose_rigid_body(
    fd: &FitData,
    freqs: &[f64],
    base: &InitConfig,
) -> Result<Fit<AdditiveModel>, RivError> {
    let mut best: Option<Fit<AdditiveModel>> = None;
    let mut tried = Vec::new();
    for l in 0..=2usize {
        let cfg = InitConfig {
            rigid_body: if l == 0 {
                RigidBody::None
            } else {
                RigidBody::Integrators(l)
            },
            ..base.clone()
        };
        let fit = match initial_model(fd, freqs, &cfg) {
            Ok(f) => f,
            Err(RivError::Structure(_)) => continue, // no submodel at all
            Err(e) => return Err(e),
        };
        let v = fit.final_cost().unwrap_or(f64::INFINITY) * 2.0 * fd.n as f64;
        tried.push((l, v));
        best = match best {
            None => Some(fit),
            Some(b) => {
                let vb = b.final_cost().unwrap_or(f64::INFINITY) * 2.0 * fd.n as f64;
                let extra = fit
                    .model
                    .n_params()
                    .saturating_sub(b.model.n_params())
                    .max(1);
                let s2 = noise_scale(v, fd, fit.model.n_params());
                let fs = f_statistic(vb - v, extra, s2);
                if fs > f_critical(extra, 1e-3) && v < vb {
                    Some(fit)
                } else {
                    Some(b)
                }
            }
        };
    }
    let mut best = best.ok_or_else(|| RivError::Structure("no modes and no rigid body".into()))?;
    let l = best.model.integrators();
    best.messages = vec![format!(
        "rigid body: {l} integrator(s), chosen by comparing the initial fits ({})",
        tried
            .iter()
            .map(|(l, v)| format!("l={l}: cost {:.3e}", v / (2.0 * fd.n as f64)))
            .collect::<Vec<_>>()
            .join(", ")
    )];
    Ok(best)
}
