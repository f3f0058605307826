//! A variance with few degrees of freedom, pooled over neighbouring lines.
//!
//! A nonparametric estimate from `R` realizations gives each line a total variance with
//! `2 (R - 1)` real degrees of freedom (with one realization, the noise variance from
//! `P` periods has `2 (P - 1)`). With `R = 2` that is 2: the estimate is exponentially
//! distributed around the truth, a tenth of the lines are under a tenth of it, and the
//! inverse-variance weights of a maximum-likelihood fit then pull the model towards the
//! lines whose variance happened to come out small; the mean of `|G - P|^2 / var`
//! diverges, so residual tests and the residual-to-noise ratio mean nothing. The
//! variance changes slowly from line to line (it follows `|G|^2` for the nonlinear part
//! and the input spectrum for the noise), so the mean of the estimates over `2 h + 1`
//! neighbouring lines (the pooled variance, per entry) estimates it with `2 h + 1` times
//! the degrees of freedom. Pooled are variances below [`POOL_BELOW_DOF`] (`R <= 5`); the
//! window is the narrowest that reaches [`MIN_POOLED_DOF`]; a resonance a few lines wide is smeared over it, which only
//! flattens the weights there (Pintelon and Schoukens, *System Identification: A
//! Frequency Domain Approach*, 2nd ed., on sample variances with few realizations and the
//! smoothing of their weights).

use crate::declared::Declared;
use crate::FrfitError;
use frf_data::{Frf, FrfDataset};

/// Degrees of freedom a pooled variance reaches: 20 (the mean of `F(2, 20)` is 1.11,
/// its variance 1.4; `F(2, 2)` has neither).
pub const MIN_POOLED_DOF: f64 = 20.0;

/// A variance is pooled only below this many degrees of freedom per line: 10 (`R <= 5`
/// realizations). From 10 on, the mean of `F(., d)`, `d / (d - 2)`, is within 25 % of 1
/// and the residual tests correct for it (`ResidualConfig::variance_dof`); the usual
/// 10-realization measurement (18) keeps its per-line variance and its resolution.
pub const POOL_BELOW_DOF: f64 = 10.0;

/// How a variance was pooled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pooled {
    /// Real degrees of freedom of one line's variance before pooling.
    pub dof_per_line: f64,
    /// Half-width of the window, lines.
    pub half_window: usize,
    /// Real degrees of freedom of a pooled variance away from the band edges.
    pub dof: f64,
}

impl Pooled {
    /// In words, for the summary's declared list and the report.
    pub fn describe(&self) -> String {
        format!(
            "variance pooled over {} neighbouring lines: {:.0} degrees of freedom per line before, {:.0} after",
            2 * self.half_window + 1,
            self.dof_per_line,
            self.dof
        )
    }
}

/// Real degrees of freedom of the data's per-line variance from what they declare:
/// `2 (R - 1)` with `R >= 2` realizations, `2 (P - 1)` with one realization of `P >= 2`
/// periods; `None` when the realizations are not stated (the periods alone do not say
/// what the variance was estimated over).
pub fn variance_dof_per_line(decl: &Declared) -> Option<f64> {
    match (decl.realizations, decl.periods) {
        (Some(r), _) if r >= 2 => Some(2.0 * (r as f64 - 1.0)),
        (Some(1), Some(p)) if p >= 2 => Some(2.0 * (p as f64 - 1.0)),
        _ => None,
    }
}

/// The half-width `h` of the narrowest window of `2 h + 1` lines whose pooled variance
/// reaches [`MIN_POOLED_DOF`] from `dof_per_line`; 0 (no pooling) from
/// [`POOL_BELOW_DOF`] on.
pub fn half_window(dof_per_line: f64) -> usize {
    if dof_per_line.is_nan() || dof_per_line <= 0.0 || dof_per_line >= POOL_BELOW_DOF {
        return 0;
    }
    let lines = (MIN_POOLED_DOF / dof_per_line).ceil() as usize;
    lines.saturating_sub(1).div_ceil(2)
}

/// `band` with its variance pooled over neighbouring lines when the declared degrees of
/// freedom per line are below [`POOL_BELOW_DOF`] (see the module documentation), and how;
/// `band` unchanged otherwise. Each entry's pooled variance at line `k` is the mean of
/// its positive finite variances at lines `k - h ..= k + h` (fewer at the band edges).
pub fn pool_variance(band: Frf, decl: &Declared) -> Result<(Frf, Option<Pooled>), FrfitError> {
    let Some(dof_per_line) = variance_dof_per_line(decl) else {
        return Ok((band, None));
    };
    let h = half_window(dof_per_line);
    let Some(var) = band.variances().filter(|_| h > 0) else {
        return Ok((band, None));
    };
    let (n, m) = (band.n_lines(), band.n_entries());
    let mut pooled = vec![0.0; n * m];
    for k in 0..n {
        let (lo, hi) = (k.saturating_sub(h), (k + h).min(n - 1));
        for e in 0..m {
            let (s, c) = (lo..=hi)
                .map(|j| var[j * m + e])
                .filter(|v| v.is_finite() && *v > 0.0)
                .fold((0.0, 0usize), |(s, c), v| (s + v, c + 1));
            pooled[k * m + e] = if c > 0 { s / c as f64 } else { var[k * m + e] };
        }
    }
    let how = Pooled {
        dof_per_line,
        half_window: h,
        dof: dof_per_line * (2 * h + 1) as f64,
    };
    let band = band
        .with_variance(Some(pooled))
        .map_err(super::config::err("pooled variance"))?;
    Ok((band, Some(how)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_reaches_the_degrees_of_freedom() {
        assert_eq!(half_window(2.0), 5); // 11 lines, 22 dof
        assert_eq!(half_window(4.0), 2); // 5 lines, 20 dof
        assert_eq!(half_window(8.0), 1); // 3 lines, 24 dof
        assert_eq!(half_window(10.0), 0);
        assert_eq!(half_window(18.0), 0);
        assert_eq!(half_window(36.0), 0);
        for d in [2.0, 4.0, 6.0, 8.0] {
            let h = half_window(d);
            assert!(d * (2 * h + 1) as f64 >= MIN_POOLED_DOF, "{d}");
            assert!(h == 0 || d * ((2 * h - 1) as f64) < MIN_POOLED_DOF, "{d}");
        }
    }

    #[test]
    fn the_degrees_of_freedom_come_from_realizations_then_periods() {
        let d = |r: Option<usize>, p: Option<usize>| Declared {
            realizations: r,
            periods: p,
            ..Default::default()
        };
        assert_eq!(variance_dof_per_line(&d(Some(2), Some(2))), Some(2.0));
        assert_eq!(variance_dof_per_line(&d(Some(10), Some(10))), Some(18.0));
        assert_eq!(variance_dof_per_line(&d(Some(1), Some(19))), Some(36.0));
        assert_eq!(variance_dof_per_line(&d(None, Some(2))), None);
        assert_eq!(variance_dof_per_line(&d(None, None)), None);
    }

    #[test]
    fn pooling_averages_each_entry_over_its_window() {
        // 1 x 1, 13 lines, variances 1..13; 2 realizations: 11-line windows
        let n = 13;
        let freq: Vec<f64> = (1..=n).map(|k| k as f64).collect();
        let values = vec![frf_data::C64::new(1.0, 0.0); n];
        let var: Vec<f64> = (1..=n).map(|k| k as f64).collect();
        let band = Frf::new(freq, 1, 1, values, Some(var)).unwrap();
        let decl = Declared {
            realizations: Some(2),
            ..Default::default()
        };
        let (pooled, how) = pool_variance(band, &decl).unwrap();
        let how = how.unwrap();
        assert_eq!(how.half_window, 5);
        assert_eq!(how.dof, 22.0);
        let v = pooled.variances().unwrap();
        // line 6 (index 6): lines 1..=11 of 0-based 1..=11 -> values 2..=12, mean 7
        assert_eq!(v[6], 7.0);
        // line 0: lines 0..=5 -> values 1..=6, mean 3.5
        assert_eq!(v[0], 3.5);
    }
}
