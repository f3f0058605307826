//! validate_frf against known answers: a noise-free MIMO measurement (gamma is the
//! largest singular value of the model error), the SISO closed form, the mu method
//! against the closed form, the verdict for the true model, and bad input.

use frf_data::{Frf, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use realize::ResponseGrid;
use validation::{
    validate_frf, validate_frf_with_model_std, DisturbanceModel, FrfValidationConfig, GammaMethod,
    Verdict,
};

fn c(rng: &mut ChaCha8Rng) -> C64 {
    C64::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5)
}

/// `(truth, model, data)` with `n` lines of `ny x nu`, model error `err_scale`, noise
/// variance `var` per entry.
fn problem(
    n: usize,
    ny: usize,
    nu: usize,
    err_scale: f64,
    var: f64,
    seed: u64,
) -> (Vec<C64>, ResponseGrid, Frf) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let m = ny * nu;
    let truth: Vec<C64> = (0..n * m).map(|_| c(&mut rng) * 4.0).collect();
    let model = ResponseGrid {
        ny,
        nu,
        values: truth.iter().map(|t| t + c(&mut rng) * err_scale).collect(),
    };
    let sd = (var / 2.0).sqrt();
    let data: Vec<C64> = truth
        .iter()
        .map(|t| {
            let a: f64 = StandardNormal.sample(&mut rng);
            let b: f64 = StandardNormal.sample(&mut rng);
            t + C64::new(a, b) * sd
        })
        .collect();
    let freq: Vec<f64> = (1..=n).map(|k| k as f64).collect();
    let frf = Frf::new(freq, ny, nu, data, Some(vec![var; n * m])).unwrap();
    (truth, model, frf)
}

#[test]
fn noise_free_mimo_gamma_is_the_model_error() {
    let (truth, model, data) = problem(20, 3, 2, 0.3, 1e-30, 1);
    let v = validate_frf(&model, &data, None, &FrfValidationConfig::default()).unwrap();
    for (k, l) in v.lines.iter().enumerate() {
        let e = faer::Mat::from_fn(3, 2, |i, j| truth[k * 6 + j * 3 + i] - model.get(k, i, j));
        let s = e.singular_values().unwrap()[0];
        assert!(
            (l.gamma - s).abs() < 1e-9 * (1.0 + s),
            "line {k}: {} vs {s}",
            l.gamma
        );
        assert!(l.gamma_lower <= l.gamma + 1e-12);
    }
    assert_eq!(v.verdict, Verdict::InvalidatedAtZeroUncertainty);
}

#[test]
fn siso_closed_form_and_mu_method() {
    let (_, model, data) = problem(30, 1, 1, 0.2, 0.01, 2);
    let cfg = FrfValidationConfig::default();
    let v = validate_frf(&model, &data, None, &cfg).unwrap();
    let vt = (0.01 * -(1.0f64 - 0.99).ln()).sqrt(); // Prop. 9, one output
    for (k, l) in v.lines.iter().enumerate() {
        let e = (data.values()[k] - model.values[k]).norm();
        let expect = (e - vt).max(0.0);
        assert!((l.gamma - expect).abs() < 1e-12, "{} vs {expect}", l.gamma);
        assert!((l.disturbance_bound - vt).abs() < 1e-12);
    }
    let mu = validate_frf(
        &model,
        &data,
        None,
        &FrfValidationConfig {
            method: GammaMethod::Mu,
            ..cfg
        },
    )
    .unwrap();
    for (a, b) in v.lines.iter().zip(&mu.lines) {
        assert!(
            (a.gamma - b.gamma).abs() < 1e-6 * (1.0 + a.gamma),
            "{} vs {}",
            a.gamma,
            b.gamma
        );
    }
}

/// The true system (zero model error) is not invalidated: over the whole band at the
/// joint level, with probability 0.99 (this seed); its gammas are at the noise level.
#[test]
fn the_true_model_is_not_invalidated() {
    let (truth, _, data) = problem(500, 2, 2, 0.0, 0.04, 3);
    let model = ResponseGrid {
        ny: 2,
        nu: 2,
        values: truth,
    };
    let v = validate_frf(&model, &data, None, &FrfValidationConfig::default()).unwrap();
    assert_eq!(
        v.verdict,
        Verdict::NotInvalidated,
        "{} lines",
        v.lines_invalidated_at_zero
    );
    // per line (alpha = 0.99 per column vector) about 2 % of the lines need a little
    let nonzero = v.lines.iter().filter(|l| l.gamma > 0.0).count();
    assert!(nonzero < 30, "{nonzero} lines with gamma > 0");
    assert!(v.gamma_max < 0.2, "gamma_max {}", v.gamma_max);
}

#[test]
fn bad_input_is_reported() {
    let (_, model, data) = problem(5, 1, 1, 0.1, 0.01, 4);
    let short = ResponseGrid {
        ny: 1,
        nu: 1,
        values: model.values[..4].to_vec(),
    };
    let e = validate_frf(&short, &data, None, &FrfValidationConfig::default()).unwrap_err();
    assert!(
        e.to_string().contains("model response vs validation data"),
        "{e}"
    );
    let nov = Frf::new(vec![1.0; 1], 1, 1, vec![C64::new(1.0, 0.0)], None).unwrap();
    let m1 = ResponseGrid {
        ny: 1,
        nu: 1,
        values: vec![C64::new(1.0, 0.0)],
    };
    let e = validate_frf(&m1, &nov, None, &FrfValidationConfig::default()).unwrap_err();
    assert!(e.to_string().contains("no variance"), "{e}");
    let e = validate_frf(
        &model,
        &data,
        None,
        &FrfValidationConfig {
            alpha: 1.5,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("alpha"), "{e}");
}

/// With a variance estimated from R realizations, the F(2, 2(R-1)) radii cover a
/// complex Gaussian error with probability alpha, where the chi-square radii (variance
/// taken as exact) cover less (Monte Carlo, 20000 draws, R = 4, alpha = 0.99).
#[test]
fn estimated_variance_radii_keep_their_coverage() {
    use validation::disturbance::DisturbanceModel;
    let (alpha, r) = (0.99, 4usize);
    let dof = 2.0 * (r as f64 - 1.0);
    let factor = DisturbanceModel::estimated_variance_factor(alpha, dof);
    assert!(factor > 1.0);
    assert!(DisturbanceModel::estimated_variance_factor(alpha, 1e6) < 1.0 + 1e-3);
    assert!(DisturbanceModel::estimated_variance_factor(alpha, 2.0 * dof) < factor);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let cgauss = |rng: &mut ChaCha8Rng| {
        let (a, b): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
        C64::new(a, b) / 2f64.sqrt() // E|z|^2 = 1
    };
    let n = 20_000;
    let (mut inside_f, mut inside_chi) = (0usize, 0usize);
    for _ in 0..n {
        // R realizations of a unit-variance complex scalar: the mean, its variance
        // estimate (sample variance / R), and an independent error of the mean
        let xs: Vec<C64> = (0..r).map(|_| cgauss(&mut rng)).collect();
        let mean = xs.iter().sum::<C64>() / r as f64;
        let var_hat =
            xs.iter().map(|x| (x - mean).norm_sqr()).sum::<f64>() / (r as f64 - 1.0) / r as f64;
        let e = cgauss(&mut rng) / (r as f64).sqrt();
        let dist = DisturbanceModel::from_variances(&[var_hat], alpha, Default::default()).unwrap();
        let radius = dist.max_radius();
        inside_chi += usize::from(e.norm() <= radius);
        inside_f += usize::from(e.norm() <= radius * factor);
    }
    let (pf, pc) = (inside_f as f64 / n as f64, inside_chi as f64 / n as f64);
    println!("coverage with F radii {pf:.4}, with chi-square radii {pc:.4}");
    assert!((pf - alpha).abs() < 0.004, "F coverage {pf}");
    assert!(pc < alpha - 0.02, "chi-square coverage {pc}");
}

/// The model's own uncertainty next to the data's (`validate_frf_with_model_std`): a
/// model whose response carries an estimation error of known standard deviation (drawn
/// complex Gaussian, 10 times the validation data's noise) is invalidated by the data's
/// disturbance alone, and not invalidated once its own standard deviation is given (the
/// joint level holds with probability alpha over all draws); a model with an error
/// far beyond its standard deviation stays invalidated, with `gamma_beyond_model` near
/// the excess. The data's own reading (verdict, gamma) is the same as `validate_frf`'s.
#[test]
fn the_models_own_uncertainty_explains_its_estimation_error() {
    let (ny, nu, n) = (3, 2, 200);
    let m = ny * nu;
    let var_data: f64 = 1e-6;
    let sd_model = 10.0 * var_data.sqrt();
    let mut invalid_beyond = 0;
    let trials = 20;
    // the model's radius against the data's: 10 times, at the quantile of an error along
    // one direction of the complex plane (the default coverage, per column of 3 outputs)
    let cfg = FrfValidationConfig::default();
    let expected = 10.0
        * DisturbanceModel::non_circular_factor(cfg.coverage.per_component_alpha(cfg.alpha, ny))
            .sqrt();
    for seed in 0..trials {
        let (truth, _, data) = problem(n, ny, nu, 0.0, var_data, 100 + seed);
        let mut rng = ChaCha8Rng::seed_from_u64(900 + seed);
        // the estimate's error: complex Gaussian with E |d|^2 = sd_model^2
        let s = sd_model / 2f64.sqrt();
        let values: Vec<C64> = truth
            .iter()
            .map(|t| {
                let a: f64 = StandardNormal.sample(&mut rng);
                let b: f64 = StandardNormal.sample(&mut rng);
                t + C64::new(a, b) * s
            })
            .collect();
        let model = ResponseGrid { ny, nu, values };
        let sd = vec![sd_model; n * m];
        let plain = validate_frf(&model, &data, None, &cfg).unwrap();
        let v = validate_frf_with_model_std(&model, Some(&sd), &data, None, &cfg).unwrap();
        assert_eq!(plain.verdict, Verdict::InvalidatedAtZeroUncertainty);
        assert_eq!(v.verdict, plain.verdict);
        assert_eq!(v.lines_invalidated_at_zero, plain.lines_invalidated_at_zero);
        for (a, b) in v.lines.iter().zip(&plain.lines) {
            assert!((a.gamma - b.gamma).abs() <= 1e-12 * (1.0 + b.gamma));
            let gb = a.gamma_beyond_model.unwrap();
            assert!(gb <= a.gamma + 1e-15, "{gb} > {}", a.gamma);
            let ratio = a.model_bound.unwrap() / a.disturbance_bound;
            assert!((ratio - expected).abs() < 1e-9, "{ratio} vs {expected}");
        }
        let b = v.beyond_model_uncertainty.as_ref().unwrap();
        assert!((b.model_to_disturbance_median - expected).abs() < 1e-9);
        invalid_beyond += usize::from(b.verdict == Verdict::InvalidatedAtZeroUncertainty);
    }
    // joint coverage alpha = 0.99 over all lines: at most a rare draw invalidates
    println!("invalidated beyond the model's uncertainty in {invalid_beyond} of {trials} draws");
    assert!(invalid_beyond <= 2, "{invalid_beyond} of {trials}");

    // an error of 0.3 per entry, far beyond the stated 1e-2: still invalidated
    let (_, model, data) = problem(n, ny, nu, 0.3, var_data, 7);
    let sd = vec![1e-2; n * m];
    let v = validate_frf_with_model_std(
        &model,
        Some(&sd),
        &data,
        None,
        &FrfValidationConfig::default(),
    )
    .unwrap();
    let b = v.beyond_model_uncertainty.unwrap();
    assert_eq!(b.verdict, Verdict::InvalidatedAtZeroUncertainty);
    assert!(b.gamma_median > 0.5 * v.gamma_median, "{b:?}");
}

/// A model standard deviation of the wrong length or with a NaN is refused, the NaN
/// with its line and entry.
#[test]
fn a_bad_model_std_is_refused_with_its_place() {
    let (_, model, data) = problem(5, 2, 2, 0.1, 1e-4, 3);
    let cfg = FrfValidationConfig::default();
    let e = validate_frf_with_model_std(&model, Some(&[0.1; 3]), &data, None, &cfg).unwrap_err();
    assert!(e.to_string().contains("20 values"), "{e}");
    let mut sd = vec![0.1; 20];
    sd[4 * 2 + 3] = f64::NAN;
    let e = validate_frf_with_model_std(&model, Some(&sd), &data, None, &cfg).unwrap_err();
    let s = e.to_string();
    assert!(s.contains("line 3") && s.contains("entry (2, 2)"), "{s}");
}
