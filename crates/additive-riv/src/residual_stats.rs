//! What the structure adaptation steps (completion, pair splits, local pair starts, the
//! drop and add passes) read from a fit before they change it: the weighted cost and
//! residual, the per-line residual statistic with its robustly fitted null distribution
//! ([`ResidualStats`]), a mode's frequency, damping and off-peak significance, and the
//! line ranges and spacings of the data. A leaf of the crate's adaptation modules: it
//! changes no model and calls no iteration, so that every step can use it.

use crate::problem::{cost, groups, pack, Basis, FitData, Layout};
use crate::significance::{
    chi2_upper, f_critical_eff, f_statistic, noise_scale, submodel_cost_increase,
};
use crate::{fit_numerators, AdditiveModel, RivError, SubmodelKind};
use frf_data::{ModelStructure, C64};
use std::f64::consts::TAU;

/// A weighted cost at or below this fraction of the data's weighted energy (a
/// relative misfit of 1e-7 rms, far below any measured noise) is an exact fit of
/// noise-free data up to what the refiner finishes: [`complete_start`] adds no mode to
/// it. The F statistic's noise scale, estimated from such a residual, is round-off and
/// the conditioning of the numerator problem: on a noise-free 2-mode system (the chain
/// harness's seed 8401) modes were added beside the true ones on costs of 1e-15 and
/// the maximum-likelihood refiner then found the duplicates unidentifiable.
pub const EXACT_FIT_REL: f64 = 1e-14;

/// The per-line statistic `2 T_k / s^2` of the weighted residual and its fitted null
/// distribution `c chi2_nu`.
///
/// With independent residuals `nu = 2 ny nu` and `c = 1`; real FRF estimates are
/// correlated across entries (a closed-loop estimate `Y U^-1` mixes the noise of all
/// experiments into every column), which makes the statistic heavier-tailed. `nu` and
/// `c` are therefore fitted robustly from the median and the median absolute deviation
/// of the statistic over all lines (`sqrt(2/nu) = 1.4826 MAD / median`), so that the
/// tests stay calibrated on correlated noise; `nu` never exceeds `2 ny nu`.
#[derive(Debug, Clone)]
pub struct ResidualStats {
    /// `2 T_k / s^2` per line.
    pub t: Vec<f64>,
    /// Effective degrees of freedom of the null distribution.
    pub nu: f64,
    /// Scale of the null distribution.
    pub c: f64,
    /// Noise scale `s^2`.
    pub s2: f64,
}

impl ResidualStats {
    /// Computes the statistics of `model` on `data`.
    pub fn new(model: &AdditiveModel, data: &FitData) -> Self {
        let lay = Layout::of(model);
        let basis = Basis::new(model, &lay, &data.omega);
        let (_, eta) = pack(model, &lay);
        let mut resid = Vec::new();
        let v = cost(
            data,
            &lay,
            &basis,
            &eta,
            Some(&mut resid),
            &groups(model, &lay),
        );
        let s2 = noise_scale(v, data, model.n_params());
        let m = data.m();
        let t: Vec<f64> = (0..data.n)
            .map(|k| {
                (0..m)
                    .map(|e| data.w[k * m + e] * resid[k * m + e].norm_sqr())
                    .sum::<f64>()
                    * 2.0
                    / s2
            })
            .collect();
        let mut sorted = t.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let med = sorted[sorted.len() / 2];
        let mut dev: Vec<f64> = t.iter().map(|x| (x - med).abs()).collect();
        dev.sort_by(|a, b| a.total_cmp(b));
        let mad = 1.4826 * dev[dev.len() / 2];
        let nu_max = 2.0 * m as f64;
        let nu = if med > 0.0 && mad > 0.0 {
            (2.0 * (med / mad).powi(2)).clamp(1.0, nu_max)
        } else {
            nu_max
        };
        let c = if med > 0.0 {
            med / (nu - 2.0 / 3.0).max(0.5)
        } else {
            1.0
        };
        Self { t, nu, c, s2 }
    }

    /// The threshold the statistic exceeds with probability `alpha` under the fitted
    /// null distribution.
    pub fn threshold(&self, alpha: f64) -> f64 {
        self.c * chi2_upper(self.nu, alpha)
    }

    /// The local level of the statistic around line `k`: its median over the lines within
    /// `rel` (relative frequency) of line `k`, at least 10 lines each side.
    pub fn local_median(&self, omega: &[f64], k: usize, rel: f64) -> f64 {
        let n = self.t.len();
        let lo_w = omega[k] * (1.0 - rel);
        let hi_w = omega[k] * (1.0 + rel);
        let a = omega
            .partition_point(|&w| w < lo_w)
            .min(k.saturating_sub(10));
        let b = omega.partition_point(|&w| w <= hi_w).max((k + 11).min(n));
        let mut win: Vec<f64> = self.t[a..b].to_vec();
        win.sort_by(|x, y| x.total_cmp(y));
        win[win.len() / 2]
    }

    /// The effective number of independent parameters among `p` entry-wise parameters of
    /// `m` entries: `p nu / (2 m)`, at least 1.
    pub fn effective_params(&self, p: usize, m: usize) -> f64 {
        (p as f64 * self.nu / (2.0 * m as f64)).max(1.0)
    }
}

/// Two modes are one when their poles are closer than this fraction of their mean
/// `|Re p|` (half the half-power bandwidth): close modes with different shapes are
/// often nearer than a bandwidth and must stay apart, but two submodels on practically
/// the same pole are not identifiable.
pub const DUPLICATE_FRACTION: f64 = 0.05;

/// The raw weighted residual energy `sum_k T_k` of the lines within `half_hz` of `f_hz`.
pub fn local_energy(stats: &ResidualStats, data: &FitData, f_hz: f64, half_hz: f64) -> f64 {
    let (lo, hi) = (TAU * (f_hz - half_hz), TAU * (f_hz + half_hz));
    let a = data.omega.partition_point(|&w| w < lo);
    let b = data.omega.partition_point(|&w| w <= hi);
    stats.t[a..b].iter().sum::<f64>() * stats.s2 / 2.0
}

/// The spacing (Hz) of the lines of `data` around `f_hz`.
pub fn line_spacing_near(data: &FitData, f_hz: f64) -> f64 {
    let w = TAU * f_hz;
    let k = data.omega.partition_point(|&x| x < w).min(data.n - 1);
    let (a, b) = if k == 0 {
        (0, 1.min(data.n - 1))
    } else {
        (k - 1, k)
    };
    if a == b {
        return f64::INFINITY;
    }
    (data.omega[b] - data.omega[a]) / TAU
}

/// The natural frequency of submodel `i` of `model` (its upper pole's `|p| / 2 pi`), Hz;
/// NaN when it has none.
pub fn mode_f_hz(model: &AdditiveModel, i: usize) -> f64 {
    model
        .upper_pole(&model.submodels[i])
        .map(|p| p.norm() / TAU)
        .unwrap_or(f64::NAN)
}

/// True when mode `i` of `model` is significant on the lines outside its own
/// resonance: its numerators are refitted with the lines within one line spacing of its
/// frequency left out (zero weight), and its F statistic on the remaining lines passes
/// the F test at `alpha` (and reaches at least `min_f`), its noise scale estimated from
/// the residual on those lines. A mode narrower than
/// the line spacing that fits one or two outlying lines (a spike of the noise) explains
/// nothing elsewhere; a real lightly damped mode sampled coarsely shapes its flanks over
/// many lines and is identified by them.
pub(crate) fn significant_off_peak(
    model: &AdditiveModel,
    data: &FitData,
    i: usize,
    alpha: f64,
    min_f: f64,
) -> Result<bool, RivError> {
    let f = mode_f_hz(model, i);
    let df = line_spacing_near(data, f);
    if !(f.is_finite() && df.is_finite()) {
        return Ok(false);
    }
    let m = data.m();
    let mut w = data.w.clone();
    for k in 0..data.n {
        if (data.omega[k] / TAU - f).abs() <= df * (1.0 + 1e-9) {
            w[k * m..(k + 1) * m].iter_mut().for_each(|x| *x = 0.0);
        }
    }
    let off = FitData::from_parts(
        data.omega.clone(),
        data.ny,
        data.nu,
        data.g.clone(),
        w,
        data.band_hz,
    );
    let mut trial = model.clone();
    let v = match fit_numerators(&mut trial, &off) {
        Ok(v) => v,
        Err(RivError::Numerical { .. }) => return Ok(false),
        Err(e) => return Err(e),
    };
    let dv = match submodel_cost_increase(&trial, &off) {
        Ok(dv) => dv,
        Err(RivError::Numerical { .. }) => return Ok(false),
        Err(e) => return Err(e),
    };
    let p = trial.submodels[i].den.len() + trial.submodels[i].num.len() * m;
    let s2 = noise_scale(v, &off, trial.n_params());
    let fs = f_statistic(dv[i], p, s2);
    Ok(fs >= f_critical_eff(p as f64, alpha).max(min_f))
}

/// The weighted cost `sum w |E|^2` of `model` on `data`, with the residual `E` when asked.
pub(crate) fn model_cost(
    model: &AdditiveModel,
    data: &FitData,
    resid: Option<&mut Vec<C64>>,
) -> f64 {
    let lay = Layout::of(model);
    let basis = Basis::new(model, &lay, &data.omega);
    let (_, eta) = pack(model, &lay);
    cost(data, &lay, &basis, &eta, resid, &groups(model, &lay))
}

/// The weighted cost `sum w |E|^2` of `model` on `data`.
pub fn cost_of(model: &AdditiveModel, data: &FitData) -> f64 {
    model_cost(model, data, None)
}

/// The pairs of modes of `model` (submodel indices `a < b`, in index order) whose upper
/// poles are closer than `fraction` of their mean `|Re p|`, with that distance over
/// the mean `|Re p|`: [`DUPLICATE_FRACTION`] finds the poles two submodels cannot both
/// hold (the drop pass), a fraction of 1 the modes within each other's half-power
/// half-bandwidth ([`frf_data::twins::TWIN_FRACTION`], the diagnosis's twin merge).
pub fn close_mode_pairs(model: &AdditiveModel, fraction: f64) -> Vec<(usize, usize, f64)> {
    let poles: Vec<(usize, C64)> = model
        .submodels
        .iter()
        .enumerate()
        .filter(|(_, s)| s.kind == SubmodelKind::Mode)
        .filter_map(|(i, s)| model.upper_pole(s).map(|p| (i, p)))
        .collect();
    let mut pairs = Vec::new();
    for (k, &(a, pa)) in poles.iter().enumerate() {
        for &(b, pb) in &poles[k + 1..] {
            let separation = frf_data::twins::pole_separation(pa, pb);
            if separation < fraction {
                pairs.push((a, b, separation));
            }
        }
    }
    pairs
}

/// True when two modes of `model` sit on practically one pole (closer than
/// [`DUPLICATE_FRACTION`] of their mean `|Re p|`): not identifiable.
pub(crate) fn has_duplicate(model: &AdditiveModel) -> bool {
    !close_mode_pairs(model, DUPLICATE_FRACTION).is_empty()
}

/// Natural frequency (Hz) and damping of submodel `i`, when it is a resonance.
pub(crate) fn pole_of(model: &AdditiveModel, i: usize) -> Option<(f64, f64)> {
    let p = model.upper_pole(&model.submodels[i])?;
    let f = p.norm() / TAU;
    (f.is_finite() && f > 0.0).then(|| (f, -p.re / p.norm()))
}

/// The line range `[a, b)` of `data` within `lo_hz..=hi_hz`.
pub(crate) fn lines_within(data: &FitData, lo_hz: f64, hi_hz: f64) -> (usize, usize) {
    let a = data.omega.partition_point(|&w| w < TAU * lo_hz);
    let b = data.omega.partition_point(|&w| w <= TAU * hi_hz);
    (a, b.max(a))
}

/// The typical neighbourhood among the modes' mean statistics `means`: their lower
/// median (a model of two modes, one of them merged, has the other as its typical
/// neighbourhood); 0 with fewer than two modes.
pub(crate) fn typical_mean(mut means: Vec<f64>) -> f64 {
    means.sort_by(|x, y| x.total_cmp(y));
    if means.len() >= 2 {
        means[(means.len() - 1) / 2]
    } else {
        0.0
    }
}

/// The reference level of the per-line statistic: its lower quintile over the band. A
/// model that misfits much of the band (a mode's tail reshaping its neighbours) raises
/// the median too; the lines it fits at the noise level still set the lower quintile.
pub(crate) fn floor_t(stats: &ResidualStats) -> f64 {
    let mut s = stats.t.clone();
    s.sort_by(|a, b| a.total_cmp(b));
    s[s.len() / 5]
}
