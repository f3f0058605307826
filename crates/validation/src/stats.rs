//! Small statistical helpers: the regularized incomplete gamma function (chi-square
//! tail probabilities and quantiles), normal tail probabilities, robust location and
//! scale (median, MAD, quantiles), and the calibration of a scaled chi-square
//! distribution `c chi2(nu)` from a median and a median absolute deviation.
//!
//! Everything here is deterministic, allocation-light and never panics on finite input;
//! non-finite input gives NaN, which callers check.

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

/// Standard normal quantile: the `z` with `P(Z <= z) = p`, `0 < p < 1` (bisection on
/// [`normal_sf`]; absolute accuracy 1e-12).
pub fn normal_quantile(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    let q = 1.0 - p;
    let (mut lo, mut hi) = (-40.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        // P(Z > mid) decreases in mid.
        if normal_sf(mid) > q {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-13 {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Median of `v` (reorders `v`); NaN when empty. The mean of the two middle values for
/// an even length.
pub fn median_mut(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    let (_, &mut hi, _) = v.select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b));
    if n % 2 == 1 {
        hi
    } else {
        let lo = v[..n / 2].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lo + hi)
    }
}

/// Median of `v` (copies).
pub fn median(v: &[f64]) -> f64 {
    median_mut(&mut v.to_vec())
}

/// Median absolute deviation from `center` (not scaled to a standard deviation).
pub fn mad(v: &[f64], center: f64) -> f64 {
    let mut d: Vec<f64> = v.iter().map(|x| (x - center).abs()).collect();
    median_mut(&mut d)
}

/// The `p`-quantile of `v` (`0 <= p <= 1`) with linear interpolation between order
/// statistics (type 7 of Hyndman and Fan); reorders `v`; NaN when empty.
pub fn quantile_mut(v: &mut [f64], p: f64) -> f64 {
    let n = v.len();
    if n == 0 || !(0.0..=1.0).contains(&p) {
        return f64::NAN;
    }
    let h = (n - 1) as f64 * p;
    let i = h.floor() as usize;
    let (_, &mut lo, rest) = v.select_nth_unstable_by(i, |a, b| a.total_cmp(b));
    if i + 1 >= n {
        return lo;
    }
    let hi = rest.iter().copied().fold(f64::INFINITY, f64::min);
    lo + (h - i as f64) * (hi - lo)
}

/// Median of a chi-square distribution with `dof` degrees of freedom.
pub fn chi2_median(dof: f64) -> f64 {
    chi2_quantile(0.5, dof)
}

/// The median absolute deviation of a chi-square distribution with `dof` degrees of
/// freedom divided by its median: the `a / m` with `F(m + a) - F(m - a) = 1/2`,
/// `m` the median. Decreases monotonically from ~1 (`dof -> 0`) to
/// `0.6745 sqrt(2 / dof)` for large `dof`.
pub fn chi2_mad_ratio(dof: f64) -> f64 {
    let m = chi2_median(dof);
    let (mut lo, mut hi) = (0.0_f64, m.max(1.0) * 4.0 + 10.0);
    let mass = |a: f64| chi2_cdf(m + a, dof) - chi2_cdf((m - a).max(0.0), dof);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if mass(mid) < 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-10 * m {
            break;
        }
    }
    0.5 * (lo + hi) / m
}

/// A scaled chi-square distribution `c chi2(nu)` fitted to a sample by its median and
/// median absolute deviation (so that a minority of contaminated values does not move
/// it): `nu` solves `MAD / median = chi2_mad_ratio(nu)` (clamped to
/// `[nu_min, nu_max]`), then `c = median / chi2_median(nu)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaledChi2 {
    /// Scale `c`.
    pub c: f64,
    /// Degrees of freedom `nu`.
    pub nu: f64,
}

impl ScaledChi2 {
    /// Fits `c chi2(nu)` to a median and MAD (both of the same sample). Returns `None`
    /// when the median is not positive and finite.
    pub fn from_median_mad(median: f64, mad: f64, nu_min: f64, nu_max: f64) -> Option<Self> {
        if !(median.is_finite() && median > 0.0 && mad.is_finite() && mad >= 0.0) {
            return None;
        }
        let nu_min = nu_min.max(0.1);
        let nu_max = nu_max.max(nu_min);
        let ratio = mad / median;
        let nu = if ratio <= chi2_mad_ratio(nu_max) {
            nu_max
        } else if ratio >= chi2_mad_ratio(nu_min) {
            nu_min
        } else {
            // chi2_mad_ratio decreases in nu: bisection in ln nu.
            let (mut lo, mut hi) = (nu_min, nu_max);
            for _ in 0..60 {
                let mid = (lo * hi).sqrt();
                if chi2_mad_ratio(mid) > ratio {
                    lo = mid;
                } else {
                    hi = mid;
                }
                if hi / lo - 1.0 < 2e-5 {
                    break;
                }
            }
            (lo * hi).sqrt()
        };
        Some(Self {
            c: median / chi2_median(nu),
            nu,
        })
    }

    /// Mean `c nu`.
    pub fn mean(&self) -> f64 {
        self.c * self.nu
    }

    /// Upper tail probability of the value `x`.
    pub fn sf(&self, x: f64) -> f64 {
        chi2_sf(x / self.c, self.nu)
    }

    /// The value exceeded with probability `q`.
    pub fn isf(&self, q: f64) -> f64 {
        self.c * chi2_isf(q, self.nu)
    }
}

/// A sorted sliding window for running medians (insertion and removal by binary search).
pub(crate) struct SortedWindow {
    v: Vec<f64>,
}

impl SortedWindow {
    pub(crate) fn with_capacity(c: usize) -> Self {
        Self {
            v: Vec::with_capacity(c),
        }
    }
    pub(crate) fn insert(&mut self, x: f64) {
        let i = self.v.partition_point(|y| y.total_cmp(&x).is_lt());
        self.v.insert(i, x);
    }
    pub(crate) fn remove(&mut self, x: f64) {
        let i = self.v.partition_point(|y| y.total_cmp(&x).is_lt());
        if i < self.v.len() {
            self.v.remove(i);
        }
    }
    pub(crate) fn median(&self) -> f64 {
        let n = self.v.len();
        if n == 0 {
            return 0.0;
        }
        if n % 2 == 1 {
            self.v[n / 2]
        } else {
            0.5 * (self.v[n / 2 - 1] + self.v[n / 2])
        }
    }
}

/// The running median of `x` over `+-half` neighbours (fewer at the ends).
pub fn running_median(x: &[f64], half: usize) -> Vec<f64> {
    let n = x.len();
    let mut out = Vec::with_capacity(n);
    let mut w = SortedWindow::with_capacity(2 * half + 1);
    for v in &x[..(half + 1).min(n)] {
        w.insert(*v);
    }
    for k in 0..n {
        if k > 0 {
            if k + half < n {
                w.insert(x[k + half]);
            }
            if k > half {
                w.remove(x[k - half - 1]);
            }
        }
        out.push(w.median());
    }
    out
}

/// The running median of `x` over the windows `lo[k]..hi[k]` (both non-decreasing in
/// `k`, `lo[k] <= k < hi[k] <= x.len()`).
pub fn running_median_bounded(x: &[f64], lo: &[usize], hi: &[usize]) -> Vec<f64> {
    let n = x.len();
    let mut out = Vec::with_capacity(n);
    let mut w = SortedWindow::with_capacity(64);
    let (mut a, mut b) = (0usize, 0usize);
    for k in 0..n {
        let (ka, kb) = (lo[k].min(n), hi[k].min(n).max(lo[k].min(n)));
        while b < kb {
            w.insert(x[b]);
            b += 1;
        }
        while a < ka {
            if a < b {
                w.remove(x[a]);
            }
            a += 1;
        }
        b = b.max(a);
        out.push(w.median());
    }
    out
}

/// Several quantiles of `v` at once (`ps` ascending, each in `[0, 1]`), each selected
/// within the part of `v` above the previous one; reorders `v`. Type 7 like
/// [`quantile_mut`].
pub fn quantiles_mut(v: &mut [f64], ps: &[f64]) -> Vec<f64> {
    let n = v.len();
    let mut out = Vec::with_capacity(ps.len());
    let mut start = 0usize;
    for &p in ps {
        if n == 0 || !(0.0..=1.0).contains(&p) {
            out.push(f64::NAN);
            continue;
        }
        let h = (n - 1) as f64 * p;
        let i = h.floor() as usize;
        let lo = if i >= start {
            let (_, x, _) = v[start..].select_nth_unstable_by(i - start, |a, b| a.total_cmp(b));
            *x
        } else {
            v[start..]
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
                .min(v[i])
        };
        let hi = if i + 1 < n {
            v[i + 1..].iter().copied().fold(f64::INFINITY, f64::min)
        } else {
            lo
        };
        out.push(lo + (h - i as f64) * (hi - lo));
        start = start.max(i);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_gamma_known_values() {
        assert!((ln_gamma(1.0)).abs() < 1e-14);
        assert!((ln_gamma(5.0) - 24.0_f64.ln()).abs() < 1e-13);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-13);
        assert!((ln_gamma(100.0) - 359.134_205_369_575_4).abs() < 1e-9);
        assert!(ln_gamma(-1.0).is_nan());
    }

    #[test]
    fn f_distribution_matches_closed_forms() {
        // I_x(1, 1) = x; I_x(a, 1) = x^a.
        for x in [0.0, 0.1, 0.5, 0.93, 1.0] {
            assert!((beta_reg(1.0, 1.0, x) - x).abs() < 1e-14);
            assert!((beta_reg(2.5, 1.0, x) - x.powf(2.5)).abs() < 1e-13);
        }
        // F(2, d2): P(F > x) = (1 + 2 x / d2)^(-d2 / 2), both sides of the switch of
        // the continued fraction and deep in the tail.
        for d2 in [4.0f64, 18.0, 60.0] {
            for x in [0.05, 0.7, 3.0, 25.0, 400.0] {
                let exact = (1.0 + 2.0 * x / d2).powf(-d2 / 2.0);
                let s = f_sf(x, 2.0, d2);
                assert!(
                    (s / exact - 1.0).abs() < 1e-11,
                    "d2 {d2}, x {x}: {s} vs {exact}"
                );
                let back = f_isf(exact, 2.0, d2);
                assert!((back / x - 1.0).abs() < 1e-9, "isf: {back} vs {x}");
            }
        }
        // F(d1, 2): P(F > x) = 1 - (d1 x / (d1 x + 2))^(d1 / 2).
        for d1 in [3.0f64, 10.0] {
            for x in [0.2, 1.0, 8.0] {
                let exact = 1.0 - (d1 * x / (d1 * x + 2.0)).powf(d1 / 2.0);
                assert!((f_sf(x, d1, 2.0) / exact - 1.0).abs() < 1e-11);
            }
        }
        // d2 -> infinity: d1 F -> chi2(d1).
        for x in [0.5, 2.0, 4.0] {
            let s = f_sf(x, 6.0, 1e8);
            assert!((s / chi2_sf(6.0 * x, 6.0) - 1.0).abs() < 1e-5, "{s}");
        }
        assert!(f_isf(0.0, 2.0, 4.0).is_nan());
        assert!(beta_reg(-1.0, 1.0, 0.5).is_nan());
    }

    #[test]
    fn chi2_tails_match_references() {
        // chi2(2): sf(x) = exp(-x/2).
        for x in [0.1, 1.0, 5.0, 40.0, 200.0] {
            let s = chi2_sf(x, 2.0);
            assert!((s / (-x / 2.0_f64).exp() - 1.0).abs() < 1e-12, "{x}: {s}");
        }
        // Tabulated: chi2(10) 0.99 quantile 23.209; chi2(1) 0.95 quantile 3.8415.
        assert!((chi2_quantile(0.99, 10.0) - 23.209_251).abs() < 1e-5);
        assert!((chi2_quantile(0.95, 1.0) - 3.841_459).abs() < 1e-5);
        assert!((chi2_quantile(0.05, 1.0) - 0.003_932_14).abs() < 1e-7);
        // Large dof: normal limit.
        let nu: f64 = 1e6;
        let z = 2.0;
        let x = nu + z * (2.0 * nu).sqrt();
        assert!((chi2_sf(x, nu) - normal_sf(z)).abs() < 2e-3);
        // Continuity across the Wilson-Hilferty switch at dof = 4e5.
        let a = chi2_sf(4e5 + 1000.0, 399_999.0);
        let b = chi2_sf(4e5 + 1000.0, 400_001.0);
        assert!((a - b).abs() < 5e-3, "{a} {b}");
    }

    #[test]
    fn normal_tails() {
        assert!((normal_sf(0.0) - 0.5).abs() < 1e-15);
        assert!((normal_sf(1.959_963_984_540_054) - 0.025).abs() < 1e-12);
        assert!((normal_sf(-3.0) - 0.998_650_101_968_369_9).abs() < 1e-12);
        assert!((normal_sf(10.0) / 7.619_853_024_160_527e-24 - 1.0).abs() < 1e-8);
        assert!((normal_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-9);
        assert!(normal_quantile(1.0).is_nan());
    }

    #[test]
    fn quantiles_and_median() {
        let v = [5.0, 1.0, 3.0, 2.0, 4.0];
        assert_eq!(median(&v), 3.0);
        assert_eq!(median(&[1.0, 2.0, 3.0, 10.0]), 2.5);
        assert!(median(&[]).is_nan());
        assert_eq!(mad(&v, 3.0), 1.0);
        let mut w = v.to_vec();
        assert_eq!(quantile_mut(&mut w, 0.0), 1.0);
        assert_eq!(quantile_mut(&mut w, 1.0), 5.0);
        assert!((quantile_mut(&mut w, 0.95) - 4.8).abs() < 1e-12);
    }

    #[test]
    fn running_median_matches_direct() {
        let x: Vec<f64> = (0..40)
            .map(|i| ((i * 37) % 11) as f64 + 0.1 * i as f64)
            .collect();
        for half in [1, 3, 7, 50] {
            let r = running_median(&x, half);
            for k in 0..x.len() {
                let a = k.saturating_sub(half);
                let b = (k + half + 1).min(x.len());
                assert_eq!(r[k], median(&x[a..b]), "half {half} k {k}");
            }
        }
        assert!(running_median(&[], 3).is_empty());
    }

    #[test]
    fn bounded_running_median_and_quantiles() {
        let x: Vec<f64> = (0..30)
            .map(|i| ((i * 17) % 7) as f64 + 0.01 * i as f64)
            .collect();
        let lo: Vec<usize> = (0..30usize).map(|k| k.saturating_sub(k / 3)).collect();
        let hi: Vec<usize> = (0..30).map(|k| (k + 1 + k / 4).min(30)).collect();
        let r = running_median_bounded(&x, &lo, &hi);
        for k in 0..30 {
            assert_eq!(r[k], median(&x[lo[k]..hi[k]]), "k {k}");
        }
        let mut v: Vec<f64> = (0..101).map(|i| ((i * 37) % 101) as f64).collect();
        let q = quantiles_mut(&mut v, &[0.5, 0.95, 1.0]);
        assert_eq!(q, vec![50.0, 95.0, 100.0]);
        let mut w = vec![3.0, 1.0, 2.0, 4.0];
        let q = quantiles_mut(&mut w, &[0.5, 0.95]);
        assert!(
            (q[0] - 2.5).abs() < 1e-12 && (q[1] - 3.85).abs() < 1e-12,
            "{q:?}"
        );
    }

    #[test]
    fn scaled_chi2_recovers_parameters() {
        for &(c, nu) in &[(0.5, 104.0), (0.9, 62.0), (3.0, 4.0), (0.01, 1.5)] {
            let med = c * chi2_median(nu);
            let mad = chi2_mad_ratio(nu) * med;
            let f = ScaledChi2::from_median_mad(med, mad, 0.5, 1000.0).unwrap();
            assert!((f.nu / nu - 1.0).abs() < 1e-4, "{nu}: {}", f.nu);
            assert!((f.c / c - 1.0).abs() < 1e-4, "{c}: {}", f.c);
        }
        // Large dof: MAD / median -> 0.6745 sqrt(2 / nu).
        let r = chi2_mad_ratio(1e4);
        assert!(
            (r / (0.674_489_75 * (2e-4_f64).sqrt()) - 1.0).abs() < 0.01,
            "{r}"
        );
        // Clamped.
        let f = ScaledChi2::from_median_mad(10.0, 0.0, 1.0, 50.0).unwrap();
        assert_eq!(f.nu, 50.0);
        assert!(ScaledChi2::from_median_mad(0.0, 1.0, 1.0, 50.0).is_none());
    }
}
