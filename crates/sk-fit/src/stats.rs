//! The quantiles the order test needs.

/// The workspace's one normal quantile and the approximate chi-square and F critical
/// values of the structure tests ([`frf_data::stats`]).
pub use frf_data::stats::{
    chi2_upper_approx as chi2_upper, f_critical_many_dof as f_critical, normal_quantile,
};

/// The F statistic of `dp` parameters that lower the weighted cost from `cost_without`
/// to `cost_with`, the noise scale estimated from `cost_with` over `n_res` real equations
/// and `p_with` parameters, and its critical value at `alpha`: `(F, F_critical)`.
pub fn f_test(
    cost_without: f64,
    cost_with: f64,
    dp: usize,
    n_res: usize,
    p_with: usize,
    alpha: f64,
) -> (f64, f64) {
    let dp = dp.max(1);
    let dof = n_res.saturating_sub(p_with).max(1) as f64;
    let s2 = cost_with / dof;
    let f = ((cost_without - cost_with) / dp as f64) / s2.max(f64::MIN_POSITIVE);
    (f, f_critical(dp, alpha))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_tables() {
        assert!((normal_quantile(0.975) - 1.959_964).abs() < 1e-6);
        assert!((normal_quantile(0.001) + 3.090_232).abs() < 1e-5);
        // chi2_10 upper 5 %: 18.307; chi2_100 upper 0.1 %: 149.449
        assert!((chi2_upper(10.0, 0.05) - 18.307).abs() < 0.1);
        assert!((chi2_upper(100.0, 0.001) - 149.449).abs() < 0.5);
    }
}
