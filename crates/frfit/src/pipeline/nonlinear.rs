//! Is the nonlinear part of a best linear approximation's variance significant?
//!
//! With `R >= 2` realizations of `P >= 2` periods, the nonparametric estimate carries
//! the total variance (`_var`, the spread over realizations: noise and stochastic
//! nonlinear distortion) and its noise part (`_var_noise`, the spread over periods).
//! For a linear system the two estimate the same variance, and their ratio at each line
//! and entry follows `F(2 (R - 1), 2 R (P - 1))` (real degrees of freedom of the two
//! sample variances of a complex mean; Pintelon and Schoukens, *System Identification:
//! A Frequency Domain Approach*, 2nd ed., the robust method for periodic random-phase
//! multisines). The test counts the (line, entry) pairs whose ratio exceeds the
//! `1 - alpha` quantile of that distribution: `N alpha` are expected without distortion;
//! more than `N alpha + 5 sqrt(N alpha) + 1` (five standard deviations of the count) is
//! significant. The test is made on the variances as estimated, before any pooling
//! ([`super::pooled_variance`]). The verdict `nonlinear_distortion` of a residual at the
//! level of the total variance reads it.

use crate::data::{distortion_level, DistortionLevel};
use crate::declared::Declared;
use frf_data::{Frf, FrfDataset};
use validation::stats::f_isf;

/// The test of the nonlinear part and its evidence.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NonlinearTest {
    /// Real degrees of freedom of the total variance, `2 (R - 1)`.
    pub dof_total: f64,
    /// Real degrees of freedom of the noise variance, `2 R (P - 1)` (`P = 2` assumed
    /// when the data do not state the periods: the smallest, so the most cautious).
    pub dof_noise: f64,
    /// Significance level of the per-pair test.
    pub alpha: f64,
    /// The critical ratio, the `1 - alpha` quantile of `F(dof_total, dof_noise)`.
    pub critical: f64,
    /// Pairs (line, entry) above it.
    pub exceeding: usize,
    /// Pairs tested.
    pub pairs: usize,
    /// Whether the count is significant (see the module documentation).
    pub significant: bool,
    /// Median over pairs of total / noise variance.
    pub total_to_noise: f64,
    /// Median over lines of the nonlinear variance relative to `|G|^2`, dB.
    pub nonlinear_db: f64,
    /// The same of the noise variance, dB.
    pub noise_db: f64,
    /// The line where the nonlinear part is largest relative to the BLA, Hz.
    pub worst_hz: f64,
    /// Its level there, dB.
    pub worst_db: f64,
    /// Lines where the nonlinear variance exceeds the noise variance (mean over entries).
    pub lines_dominated: usize,
    /// Lines.
    pub lines: usize,
}

impl NonlinearTest {
    /// The evidence in words.
    pub fn describe(&self) -> String {
        format!(
            "the nonlinear part of the variance is significant: total / noise variance median {:.1} \
             ({} of {} line-entry pairs above the {:.0e} critical value {:.2} of F({:.0}, {:.0}), \
             {:.1} expected without distortion); stochastic nonlinear distortion at {:.1} dB under \
             the BLA (noise at {:.1} dB), dominating the noise on {} of {} lines, largest at {:.1} Hz \
             ({:.1} dB)",
            self.total_to_noise,
            self.exceeding,
            self.pairs,
            self.alpha,
            self.critical,
            self.dof_total,
            self.dof_noise,
            self.alpha * self.pairs as f64,
            -self.nonlinear_db,
            -self.noise_db,
            self.lines_dominated,
            self.lines,
            self.worst_hz,
            -self.worst_db
        )
    }
}

/// The test on `band` (its variances as estimated) with the realizations and periods
/// `decl` states, at level `alpha`; `None` without both variances or with fewer than 2
/// stated realizations.
pub fn test_nonlinear(band: &Frf, decl: &Declared, alpha: f64) -> Option<NonlinearTest> {
    let r = decl.realizations.filter(|&r| r >= 2)? as f64;
    let p = decl.periods.filter(|&p| p >= 2).unwrap_or(2) as f64;
    let (total, noise) = (band.variances()?, band.noise_variances()?);
    let (dof_total, dof_noise) = (2.0 * (r - 1.0), 2.0 * r * (p - 1.0));
    let critical = f_isf(alpha, dof_total, dof_noise);
    if !critical.is_finite() {
        return None;
    }
    let (mut exceeding, mut pairs) = (0usize, 0usize);
    for (t, n) in total.iter().zip(noise) {
        if *n > 0.0 && t.is_finite() {
            pairs += 1;
            exceeding += usize::from(t / n > critical);
        }
    }
    if pairs == 0 {
        return None;
    }
    let m = band.n_entries();
    let lines_dominated = (0..band.n_lines())
        .filter(|&k| {
            let (mut nl, mut nz) = (0.0, 0.0);
            for e in k * m..(k + 1) * m {
                nl += (total[e] - noise[e]).max(0.0);
                nz += noise[e];
            }
            nl > nz
        })
        .count();
    let expected = alpha * pairs as f64;
    let DistortionLevel {
        nonlinear_db,
        noise_db,
        total_to_noise,
        worst_hz,
        worst_db,
    } = distortion_level(band)?;
    Some(NonlinearTest {
        dof_total,
        dof_noise,
        alpha,
        critical,
        exceeding,
        pairs,
        significant: exceeding as f64 > expected + 5.0 * expected.sqrt() + 1.0,
        total_to_noise,
        nonlinear_db,
        noise_db,
        worst_hz,
        worst_db,
        lines_dominated,
        lines: band.n_lines(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::C64;
    use rand::{Rng, SeedableRng};

    /// Variances drawn as the estimator's: total ~ s_t^2 chi2(dt) / dt, noise ~ s_n^2
    /// chi2(dn) / dn (sums of squared normals), with s_t = s_n (linear) or s_t = 10 s_n.
    fn band(ratio: f64, seed: u64) -> Frf {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = 2000;
        let (dt, dn) = (2usize, 4usize); // R = 2, P = 2
        let mut chi2 = |d: usize| -> f64 {
            (0..d)
                .map(|_| {
                    // Box-Muller
                    let (u1, u2): (f64, f64) = (rng.random(), rng.random());
                    let z = (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                    z * z
                })
                .sum::<f64>()
                / d as f64
        };
        let (mut t, mut nz) = (Vec::new(), Vec::new());
        for _ in 0..n {
            t.push(ratio * chi2(dt));
            nz.push(chi2(dn));
        }
        let freq: Vec<f64> = (1..=n).map(|k| k as f64).collect();
        Frf::new(freq, 1, 1, vec![C64::new(1.0, 0.0); n], Some(t))
            .unwrap()
            .with_noise_variance(Some(nz))
            .unwrap()
    }

    fn decl() -> Declared {
        Declared {
            realizations: Some(2),
            periods: Some(2),
            ..Default::default()
        }
    }

    #[test]
    fn a_linear_system_is_not_significant_and_a_distorted_one_is() {
        for seed in 0..20 {
            let t = test_nonlinear(&band(1.0, seed), &decl(), 1e-3).unwrap();
            assert!(!t.significant, "seed {seed}: {t:?}");
        }
        let t = test_nonlinear(&band(100.0, 1), &decl(), 1e-3).unwrap();
        assert!(t.significant, "{t:?}");
        assert!(t.describe().contains("significant"));
        assert_eq!((t.dof_total, t.dof_noise), (2.0, 4.0));
        // without the realizations stated there is no test
        assert!(test_nonlinear(&band(100.0, 1), &Declared::default(), 1e-3).is_none());
    }
}
