//! Special functions of the workspace's statistical tests, in one place: the gamma and
//! incomplete gamma functions (chi-square tails and quantiles), the incomplete beta
//! function (F tails and quantiles), the complementary error function and the normal
//! distribution, and the approximate chi-square and F critical values of the structure
//! tests. `validation::stats` re-exports them beside its robust statistics.
//!
//! Deterministic, allocation-free, never panics on finite input; non-finite input gives
//! NaN, which callers check.

/// `ln Gamma(x)` for `x > 0` (Lanczos approximation, g = 7, n = 9; relative error below
/// 1e-14 over the range used here).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const COEF: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if !(x.is_finite() && x > 0.0) {
        return f64::NAN;
    }
    if x < 0.5 {
        // Reflection: Gamma(x) Gamma(1 - x) = pi / sin(pi x).
        let s = (std::f64::consts::PI * x).sin();
        return std::f64::consts::PI.ln() - s.abs().ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = COEF[0];
    let t = x + G + 0.5;
    for (i, c) in COEF.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularized lower and upper incomplete gamma functions `(P(a, x), Q(a, x))`,
/// `P + Q = 1`, for `a > 0`, `x >= 0`: series for `x < a + 1`, Lentz's continued
/// fraction otherwise (Numerical Recipes, 3rd ed., section 6.2). The complement that is
/// small is computed directly, so tail probabilities keep their relative accuracy.
/// For `a > 2e5` (a chi-square with more than 4e5 degrees of freedom) the
/// Wilson-Hilferty normal approximation is used (relative error of the tail below 1e-3
/// there).
pub fn gamma_pq(a: f64, x: f64) -> (f64, f64) {
    if !(a.is_finite() && a > 0.0) || x.is_nan() {
        return (f64::NAN, f64::NAN);
    }
    if x <= 0.0 {
        return (0.0, 1.0);
    }
    if x == f64::INFINITY {
        return (1.0, 0.0);
    }
    if a > 2e5 {
        // chi2(2a) at 2x: z = ((x/a)^(1/3) - (1 - 1/(9a))) / sqrt(1/(9a)).
        let h = 1.0 / (9.0 * a);
        let z = ((x / a).cbrt() - (1.0 - h)) / h.sqrt();
        let q = normal_sf(z);
        return (1.0 - q, q);
    }
    let ln_pre = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        // P by the series sum x^n / (a (a+1) ... (a+n)).
        let mut ap = a;
        let mut del = 1.0 / a;
        let mut sum = del;
        for _ in 0..100_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        let p = (sum.ln() + ln_pre).exp().clamp(0.0, 1.0);
        (p, 1.0 - p)
    } else {
        // Q by the continued fraction (modified Lentz).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        let q = (h.ln() + ln_pre).exp().clamp(0.0, 1.0);
        (1.0 - q, q)
    }
}

/// Upper tail `P(X > x)` of a chi-square distribution with `dof > 0` degrees of freedom
/// (non-integer allowed).
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    gamma_pq(0.5 * dof, 0.5 * x).1
}

/// `P(X <= x)` of a chi-square distribution with `dof > 0` degrees of freedom.
pub fn chi2_cdf(x: f64, dof: f64) -> f64 {
    gamma_pq(0.5 * dof, 0.5 * x).0
}

/// The `p`-quantile of a chi-square distribution with `dof` degrees of freedom
/// (`0 < p < 1`): bisection on [`chi2_cdf`] in the logarithm of `x`, started from the
/// Wilson-Hilferty approximation; relative accuracy 1e-10. Upper quantiles with
/// `1 - p` below 1e-16 are found through the upper tail ([`chi2_isf`]).
pub fn chi2_quantile(p: f64, dof: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && dof > 0.0 && dof.is_finite()) {
        return f64::NAN;
    }
    if p > 0.5 {
        return chi2_isf(1.0 - p, dof);
    }
    solve_increasing(dof, |x| chi2_cdf(x, dof) - p)
}

/// The upper quantile: `x` with `P(X > x) = q` for a chi-square with `dof` degrees of
/// freedom (`0 < q < 1`).
pub fn chi2_isf(q: f64, dof: f64) -> f64 {
    if !(q > 0.0 && q < 1.0 && dof > 0.0 && dof.is_finite()) {
        return f64::NAN;
    }
    // sf is decreasing in x: find the root of q - sf(x), which increases.
    solve_increasing(dof, |x| q - chi2_sf(x, dof))
}

/// The regularized incomplete beta function `I_x(a, b)` (`a, b > 0`, `0 <= x <= 1`),
/// by the continued fraction of the incomplete beta integral (modified Lentz), on the
/// side `x < (a + 1) / (a + b + 2)` where it converges fast and through
/// `I_x(a, b) = 1 - I_{1-x}(b, a)` on the other; relative accuracy about 1e-14.
pub fn beta_reg(a: f64, b: f64, x: f64) -> f64 {
    if !(a > 0.0 && b > 0.0 && (0.0..=1.0).contains(&x)) {
        return f64::NAN;
    }
    if x == 0.0 || x == 1.0 {
        return x;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    if x < (a + 1.0) / (a + b + 2.0) {
        (ln_front.exp() * beta_cf(a, b, x) / a).clamp(0.0, 1.0)
    } else {
        (1.0 - ln_front.exp() * beta_cf(b, a, 1.0 - x) / b).clamp(0.0, 1.0)
    }
}

/// The continued fraction of the incomplete beta function (even and odd steps).
fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let away_from_zero = |v: f64| if v.abs() < TINY { TINY } else { v };
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 / away_from_zero(1.0 - qab * x / qap);
    let mut h = d;
    // one modified-Lentz step with the partial numerator `aa`; returns the factor
    let lentz = |aa: f64, c: &mut f64, d: &mut f64| -> f64 {
        *d = 1.0 / away_from_zero(1.0 + aa * *d);
        *c = away_from_zero(1.0 + aa / *c);
        *d * *c
    };
    for m in 1..=500 {
        let m = m as f64;
        let m2 = 2.0 * m;
        h *= lentz(m * (b - m) * x / ((qam + m2) * (a + m2)), &mut c, &mut d);
        let del = lentz(
            -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)),
            &mut c,
            &mut d,
        );
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Upper tail `P(F > x)` of Snedecor's F distribution with `d1, d2 > 0` degrees of
/// freedom: `I_{d2 / (d2 + d1 x)}(d2 / 2, d1 / 2)`.
pub fn f_sf(x: f64, d1: f64, d2: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    beta_reg(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * x))
}

/// The upper quantile of the F distribution: `x` with `P(F > x) = q` (`0 < q < 1`).
pub fn f_isf(q: f64, d1: f64, d2: f64) -> f64 {
    if !(q > 0.0 && q < 1.0 && d1 > 0.0 && d2 > 0.0 && d1.is_finite() && d2.is_finite()) {
        return f64::NAN;
    }
    solve_increasing(1.0, |x| q - f_sf(x, d1, d2))
}

/// Root of an increasing function of `x > 0` by bisection in `ln x`, bracketing from the
/// scale `start`.
fn solve_increasing(start: f64, f: impl Fn(f64) -> f64) -> f64 {
    let mut lo = start.max(1e-300);
    let mut hi = start.max(1e-300);
    let mut guard = 0;
    while f(lo) > 0.0 && guard < 2000 {
        lo *= 0.5;
        guard += 1;
    }
    guard = 0;
    while f(hi) < 0.0 && guard < 2000 {
        hi *= 2.0;
        guard += 1;
    }
    for _ in 0..200 {
        let mid = (lo * hi).sqrt();
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi / lo - 1.0 < 1e-12 {
            break;
        }
    }
    (lo * hi).sqrt()
}

/// `erfc(x)`, through `erfc(x) = Q(1/2, x^2)` for `x >= 0` (full relative accuracy in
/// the tail) and `2 - erfc(-x)` below.
pub fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x == 0.0 {
        return 1.0;
    }
    // gamma_pq(0.5, ..) never takes the Wilson-Hilferty branch (a = 0.5).
    gamma_pq(0.5, x * x).1
}

/// Standard normal upper tail `P(Z > z)`.
pub fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Standard normal quantile: the `z` with `P(Z <= z) = p`, `0 < p < 1`; NaN outside.
/// Acklam's rational approximation (relative error 1.15e-9), then one Halley step on
/// [`normal_sf`] (full double accuracy). The one normal quantile of the workspace: the
/// significance tests of `additive-riv`, `sk-fit`, `subspace` and `validation` read it.
pub fn normal_quantile(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
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
    const P_LOW: f64 = 0.02425;
    let tail = |q: f64| {
        let t = (-2.0 * q.ln()).sqrt();
        (((((C[0] * t + C[1]) * t + C[2]) * t + C[3]) * t + C[4]) * t + C[5])
            / ((((D[0] * t + D[1]) * t + D[2]) * t + D[3]) * t + 1.0)
    };
    let x = if p < P_LOW {
        tail(p)
    } else if p > 1.0 - P_LOW {
        -tail(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    // one Halley step on e = Phi(x) - p, written with the tail that does not cancel:
    // Phi(x) = 1 - Q(x) = Q(-x), Q = normal_sf
    let e = if x > 0.0 {
        (1.0 - p) - normal_sf(x)
    } else {
        normal_sf(-x) - p
    };
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (0.5 * x * x).exp();
    x - u / (1.0 + 0.5 * x * u)
}

/// The upper `alpha` quantile of `chi2(dof)` by the Wilson-Hilferty cube-root normal
/// approximation (at the levels of significance tests, relative error up to 3 % at
/// `dof = 1` and below 1 % from `dof = 10`; [`chi2_isf`] is the exact one): the thresholds of the structure tests, where
/// speed matters more than the last digit.
pub fn chi2_upper_approx(dof: f64, alpha: f64) -> f64 {
    let z = normal_quantile(1.0 - alpha);
    let h = 2.0 / (9.0 * dof);
    dof * (1.0 - h + z * h.sqrt()).powi(3).max(0.0)
}

/// The critical value of an F statistic `(dV / p) / s^2` for `p` added parameters at
/// significance `alpha` with many residual degrees of freedom: `chi2_p(alpha) / p`
/// ([`chi2_upper_approx`]; `p` at least 1).
pub fn f_critical_many_dof(p: usize, alpha: f64) -> f64 {
    f_critical_effective(p.max(1) as f64, alpha)
}

/// [`f_critical_many_dof`] for an effective (non-integer) number of parameters `p_eff >
/// 0`: the parameters of `p` entry-wise ones that are independent under correlated
/// noise (`additive-riv`'s residual statistics).
pub fn f_critical_effective(p_eff: f64, alpha: f64) -> f64 {
    chi2_upper_approx(p_eff, alpha) / p_eff
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_quantile_inverts_the_tail_to_full_accuracy() {
        for &p in &[
            1e-12,
            1e-6,
            1e-3,
            0.02,
            0.1,
            0.5,
            0.7,
            0.975,
            0.999,
            1.0 - 1e-9,
        ] {
            let z = normal_quantile(p);
            let back = 1.0 - normal_sf(z);
            let rel = if p < 0.5 {
                (normal_sf(-z) - p).abs() / p
            } else {
                (back - p).abs() / (1.0 - p)
            };
            assert!(rel < 1e-10, "p {p}: z {z}, relative error {rel:.2e}");
        }
        assert!((normal_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-13);
        assert!((normal_quantile(0.999) - 3.090_232_306_167_813_5).abs() < 1e-12);
        assert!(normal_quantile(0.0).is_nan() && normal_quantile(1.0).is_nan());
    }

    #[test]
    fn the_approximate_critical_values_are_near_the_exact_ones() {
        for dof in [1.0, 2.0, 10.0, 100.0] {
            for alpha in [0.05, 1e-3] {
                let (a, e) = (chi2_upper_approx(dof, alpha), chi2_isf(alpha, dof));
                let tol = if dof < 10.0 { 0.04 } else { 0.01 };
                assert!(
                    (a / e - 1.0).abs() < tol,
                    "dof {dof} alpha {alpha}: {a} vs {e}"
                );
            }
        }
        assert_eq!(f_critical_many_dof(0, 0.05), f_critical_many_dof(1, 0.05));
    }
}
