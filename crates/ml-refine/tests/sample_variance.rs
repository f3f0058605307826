//! The sample-variance factor of the covariance (`ml_refine::sample_variance_factor`),
//! checked by Monte Carlo on the simplest weighted estimate: one complex gain `theta`
//! seen on many lines, each line the mean of `M` noisy realizations weighted by the
//! inverse of its sample variance. The spread of the estimate over the draws is compared
//! with the standard deviation the ML refiner reports (the inverse information with the
//! sample weights, scaled by `max(1, V / N_dof)`), with and without the factor.

use ml_refine::sample_variance_factor;
use num_complex::Complex64 as C64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// z values (real and imaginary part of `theta_hat - theta` over the reported standard
/// deviation without the factor) of `draws` estimates from `m` realizations per line.
fn z_values(m: usize, lines: usize, draws: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let theta = C64::new(0.7, -1.3);
    // a regressor and a noise level that vary over the lines, as an FRF's do
    let a: Vec<C64> = (0..lines)
        .map(|k| C64::from_polar(1.0 + (k % 7) as f64 * 0.3, 0.1 * k as f64))
        .collect();
    let sigma: Vec<f64> = (0..lines).map(|k| 0.05 * (1.0 + (k % 5) as f64)).collect();
    let mut z = Vec::with_capacity(2 * draws);
    for _ in 0..draws {
        let mut mean = Vec::with_capacity(lines);
        let mut w = Vec::with_capacity(lines);
        for k in 0..lines {
            // complex circular noise of variance sigma^2 per realization
            let s = sigma[k] / 2f64.sqrt();
            let x: Vec<C64> = (0..m)
                .map(|_| theta * a[k] + C64::new(s * normal(), s * normal()))
                .collect();
            let xm = x.iter().sum::<C64>() / m as f64;
            // the sample variance of the mean
            let var = x.iter().map(|v| (v - xm).norm_sqr()).sum::<f64>() / ((m * (m - 1)) as f64);
            mean.push(xm);
            w.push(1.0 / var);
        }
        let info: f64 = (0..lines).map(|k| w[k] * a[k].norm_sqr()).sum();
        let est: C64 = (0..lines)
            .map(|k| w[k] * a[k].conj() * mean[k])
            .sum::<C64>()
            / info;
        let cost: f64 = (0..lines)
            .map(|k| w[k] * (mean[k] - est * a[k]).norm_sqr())
            .sum();
        // one complex parameter: N - 1 complex degrees of freedom
        let ratio = cost / (lines as f64 - 1.0);
        // each part's variance: half the complex one
        let sd = (ratio.max(1.0) / info / 2.0).sqrt();
        z.push((est.re - theta.re) / sd);
        z.push((est.im - theta.im) / sd);
    }
    z
}

fn rms(z: &[f64]) -> f64 {
    (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt()
}

/// With sample-variance weights the spread exceeds the information's standard deviation
/// by `sqrt((M - 2) / (M - 3))` (1.069 for 10 realizations, 1.225 for 5), and the factor
/// brings the z RMS to 1.
#[test]
fn the_factor_calibrates_sample_variance_weights() {
    for (m, seed) in [(5usize, 1u64), (10, 2)] {
        let z = z_values(m, 400, 4000, seed);
        let d = 2.0 * (m as f64 - 1.0);
        let factor = sample_variance_factor(Some(d));
        let expected = (m as f64 - 2.0) / (m as f64 - 3.0);
        assert!(
            (factor - expected).abs() < 1e-12,
            "M = {m}: factor {factor}"
        );
        let plain = rms(&z);
        let corrected = plain / factor.sqrt();
        println!(
            "M = {m}: z RMS {plain:.4} without the factor, {corrected:.4} with it (factor {factor:.4}, 8000 z)"
        );
        // 8000 z: the RMS's standard error is about 1 / sqrt(2 * 8000) = 0.008
        assert!((plain - factor.sqrt()).abs() < 0.03, "M = {m}: {plain:.4}");
        assert!((corrected - 1.0).abs() < 0.03, "M = {m}: {corrected:.4}");
    }
}

/// An exact variance and too few degrees of freedom leave the covariance as it is.
#[test]
fn the_factor_is_one_where_it_is_not_defined() {
    assert_eq!(sample_variance_factor(None), 1.0);
    assert_eq!(sample_variance_factor(Some(4.0)), 1.0);
    assert_eq!(sample_variance_factor(Some(2.0)), 1.0);
    assert!((sample_variance_factor(Some(18.0)) - 8.0 / 7.0).abs() < 1e-15);
}
