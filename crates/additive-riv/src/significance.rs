//! Statistics for deciding the model structure: the significance of each submodel
//! (a Wald test on its numerators) and of a residual peak, with F and chi-square
//! thresholds that account for the number of parameters, so that noise is not
//! "explained" by extra modes.
//!
//! Units: with the weighted criterion `V = sum w |E|^2` and weights equal to the inverse
//! variance, each complex residual contributes on average 1 to `V`, and each fitted real
//! parameter removes on average 1/2. With other weightings the same holds up to an
//! unknown scale `s^2`, estimated as `V / (N m - P / 2)`.

use crate::problem::{pack, Basis, FitData, Layout};
use crate::small::spd_solve;
use crate::{AdditiveModel, RivError};
use rayon::prelude::*;

/// The workspace's one normal quantile and the approximate chi-square and F critical
/// values of the structure tests ([`frf_data::stats`]).
pub use frf_data::stats::{
    chi2_upper_approx as chi2_upper, f_critical_effective as f_critical_eff,
    f_critical_many_dof as f_critical, normal_quantile,
};

/// Noise scale `s^2 = V / (N m - P/2)` of a fit with cost `v = sum w |E|^2` (unit when the
/// weights are the inverse variances and the model is adequate).
pub fn noise_scale(v: f64, data: &FitData, n_params: usize) -> f64 {
    let dof = (data.observations() as f64 / 2.0 - n_params as f64 / 2.0).max(1.0);
    v / dof
}

/// Bytes of Gram matrices [`submodel_cost_increase`] forms at once.
const GRAM_CHUNK_BYTES: usize = 64 << 20;

/// Per submodel, the increase of the cost `sum w |E|^2` when its numerators are removed
/// and the other numerators refitted with all denominators held fixed (a Wald statistic,
/// exact for the linear numerator problem (24)).
pub fn submodel_cost_increase(model: &AdditiveModel, data: &FitData) -> Result<Vec<f64>, RivError> {
    let lay = Layout::of(model);
    let nn = lay.n_num;
    let m = data.m();
    let basis = Basis::new(model, &lay, &data.omega);
    let (_, eta) = pack(model, &lay);
    let groups = crate::problem::groups(model, &lay);
    let n = data.n;
    // the Gram matrices U^T S_e^2 U of the entries from the basis products they share
    // (crate::gram), a chunk of entries at a time so that they hold at most
    // GRAM_CHUNK_BYTES
    let s2 = crate::gram::squared_scales(&data.sqrt_w, &basis, m);
    let chunk = (GRAM_CHUNK_BYTES / (8 * nn * nn).max(1)).clamp(1, m.max(1));
    let mut per: Vec<Vec<f64>> = Vec::with_capacity(m);
    for e0 in (0..m).step_by(chunk) {
        let ne = chunk.min(m - e0);
        let grams = crate::gram::numerator_grams(&basis, nn, &s2[e0 * n..(e0 + ne) * n], ne, true);
        let part: Vec<Vec<f64>> = (0..ne)
            .into_par_iter()
            .map(|t| {
                let e = e0 + t;
                entry_cost_increases(
                    &grams[t * nn * nn..(t + 1) * nn * nn],
                    &eta[e * nn..(e + 1) * nn],
                    &groups,
                )
            })
            .collect::<Result<_, _>>()?;
        per.extend(part);
    }
    let mut total = vec![0.0; groups.len()];
    for v in &per {
        for (t, x) in total.iter_mut().zip(v) {
            *t += x;
        }
    }
    Ok(total)
}

/// Per entry, the cost increases of [`submodel_cost_increase`] from the entry's Gram
/// matrix `gram` of the numerator basis.
fn entry_cost_increases(
    gram: &[f64],
    be: &[f64],
    groups: &[(usize, usize)],
) -> Result<Vec<f64>, RivError> {
    let nn = be.len();
    let mut h = gram.to_vec();
    let identity = |nn: usize| {
        let mut inv = vec![0.0; nn * nn];
        for j in 0..nn {
            inv[j * nn + j] = 1.0;
        }
        inv
    };
    let mut inv = identity(nn);
    let h0 = h.clone();
    if spd_solve(&mut h, nn, &mut inv, nn).is_none() {
        // Numerically dependent basis functions: two modes closer than the
        // duplicate test resolves (a rank-2 residue split into two poles a fraction
        // of a bandwidth apart). A ridge of 1e-10 of the largest diagonal keeps the
        // solve defined; a group in the span of the others then gets a cost
        // increase near zero, i.e. it is insignificant, which is the statistical
        // answer for a duplicate.
        let ridge = 1e-10 * (0..nn).map(|j| h0[j * nn + j]).fold(0.0_f64, f64::max);
        h = h0;
        for j in 0..nn {
            h[j * nn + j] += ridge;
        }
        inv = identity(nn);
        spd_solve(&mut h, nn, &mut inv, nn).ok_or_else(|| RivError::Numerical {
            what: "submodel significance".into(),
            why: "dependent numerator basis functions (duplicate modes)".into(),
        })?;
    }
    let mut out = Vec::with_capacity(groups.len());
    for &(off, len) in groups {
        // eta_I^T [ (H^-1)_II ]^-1 eta_I
        let mut blk = vec![0.0; len * len];
        for c in 0..len {
            for r in 0..len {
                blk[c * len + r] = inv[(off + c) * nn + off + r];
            }
        }
        let mut x: Vec<f64> = be[off..off + len].to_vec();
        let val = match spd_solve(&mut blk, len, &mut x, 1) {
            Some(_) => be[off..off + len].iter().zip(&x).map(|(a, b)| a * b).sum(),
            None => f64::INFINITY,
        };
        out.push(val);
    }
    Ok(out)
}

/// The F statistic of adding (or keeping) a group of `p` real parameters that lowers the
/// cost by `dv`, relative to the noise scale `s2`: `(dv / (p/2)) / s2`.
pub fn f_statistic(dv: f64, p: usize, s2: f64) -> f64 {
    (dv / (p as f64 / 2.0)) / s2.max(f64::MIN_POSITIVE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles() {
        assert!((normal_quantile(0.975) - 1.959964).abs() < 1e-5);
        assert!((normal_quantile(0.001) + 3.090232).abs() < 5e-5);
        assert!((normal_quantile(0.999) - 3.090232).abs() < 5e-5);
        // chi2_10 upper 5%: 18.307
        assert!((chi2_upper(10.0, 0.05) - 18.307).abs() < 0.1);
        // chi2_100 upper 0.1%: 149.449
        assert!((chi2_upper(100.0, 0.001) - 149.449).abs() < 0.5);
    }
}
