//! Distributions for the cost test and the confidence intervals, from the workspace's
//! one statistics module ([`frf_data::stats`]: the regularized incomplete gamma function
//! of the chi-square tail, the normal tail through `erfc`), under the names the
//! refinement reads.

pub use frf_data::stats::erfc;

/// `P(Z > z)` for a standard normal `Z` ([`frf_data::stats::normal_sf`]).
pub fn normal_upper_tail(z: f64) -> f64 {
    frf_data::stats::normal_sf(z)
}

/// `P(X > x)` for `X ~ chi-square(k)` ([`frf_data::stats::chi2_sf`]); NaN for `k <= 0`
/// or a non-finite `x`.
pub fn chi2_upper_tail(x: f64, k: f64) -> f64 {
    if k.is_nan() || k <= 0.0 || !x.is_finite() {
        return f64::NAN;
    }
    frf_data::stats::chi2_sf(x, k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        assert!((normal_upper_tail(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_upper_tail(0.0) - 0.5).abs() < 1e-7);
        // chi-square(100): upper 5 % point 124.342
        assert!((chi2_upper_tail(124.342, 100.0) - 0.05).abs() < 1e-5);
        // chi-square(1000): median 999.333
        assert!((chi2_upper_tail(999.333, 1000.0) - 0.5).abs() < 1e-4);
        assert!(chi2_upper_tail(1.0, 0.0).is_nan());
        assert_eq!(chi2_upper_tail(0.0, 3.0), 1.0);
    }
}
