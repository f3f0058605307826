//! Distributions for the cost test and the confidence intervals: the standard normal
//! tail and the chi-square tail (Wilson-Hilferty cube-root approximation, accurate to
//! a few parts in a thousand of the p-value for the hundreds-plus degrees of freedom of
//! an FRF fit).

/// `erfc(x)`, fractional error below 1.2e-7 (Chebyshev fit of Numerical Recipes,
/// `erfcc`).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let ans = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 {
        ans
    } else {
        2.0 - ans
    }
}

/// `P(Z > z)` for a standard normal `Z`.
pub fn normal_upper_tail(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// `P(X > x)` for `X ~ chi-square(k)` (Wilson-Hilferty).
pub fn chi2_upper_tail(x: f64, k: f64) -> f64 {
    if k.is_nan() || k <= 0.0 || !x.is_finite() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    let a = 2.0 / (9.0 * k);
    let z = ((x / k).cbrt() - (1.0 - a)) / a.sqrt();
    normal_upper_tail(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        assert!((normal_upper_tail(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_upper_tail(0.0) - 0.5).abs() < 1e-7);
        // chi-square(100): upper 5 % point 124.342
        assert!((chi2_upper_tail(124.342, 100.0) - 0.05).abs() < 5e-4);
        // chi-square(1000): median ~ 999.33
        assert!((chi2_upper_tail(999.333, 1000.0) - 0.5).abs() < 1e-3);
    }
}
