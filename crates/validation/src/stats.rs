//! Small statistical helpers: the regularized incomplete gamma function (chi-square
//! tail probabilities and quantiles), normal tail probabilities, robust location and
//! scale (median, MAD, quantiles), and the calibration of a scaled chi-square
//! distribution `c chi2(nu)` from a median and a median absolute deviation.
//!
//! Everything here is deterministic, allocation-light and never panics on finite input;
//! non-finite input gives NaN, which callers check.

pub use frf_data::stats::{
    beta_reg, chi2_cdf, chi2_isf, chi2_quantile, chi2_sf, erfc, f_isf, f_sf, gamma_pq, ln_gamma,
    normal_quantile, normal_sf,
};

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
