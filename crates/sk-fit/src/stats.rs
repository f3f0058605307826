//! The quantiles the order test needs.

/// The standard normal quantile (Acklam's rational approximation, relative error below
/// 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let pl = 0.02425;
    if p < pl {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - pl {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        let q = (-2.0 * (1.0 - p).ln()).sqrt();
        -(((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    }
}

/// The upper `alpha` quantile of the chi-square distribution with `k` degrees of
/// freedom (Wilson-Hilferty: accurate to about 1 % for `k >= 3`).
pub fn chi2_upper(k: f64, alpha: f64) -> f64 {
    let z = normal_quantile(1.0 - alpha);
    let h = 2.0 / (9.0 * k);
    k * (1.0 - h + z * h.sqrt()).powi(3).max(0.0)
}

/// The critical value of the F statistic `(dV / p) / s^2` for `p` added parameters at
/// significance `alpha`, with many residual degrees of freedom: `chi2_p(alpha) / p`.
pub fn f_critical(p: usize, alpha: f64) -> f64 {
    let p = p.max(1) as f64;
    chi2_upper(p, alpha) / p
}

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
