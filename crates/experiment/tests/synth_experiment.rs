//! Acceptance tests of the simulated closed-loop experiments and the nonparametric
//! estimator (issue: simulated experiments and nonparametric FRF estimation).
//!
//! Most tests use the default wafer stage with a short period (N = 2000 at 10 kHz:
//! 200 odd lines 5..1995 Hz) so that many seeds run in well under a second each.

use ::experiment::nonparametric::{EstimatorConfig, LineGrid, NonparametricFrf};
use ::experiment::synth::*;
use frf_data::{Frf, FrfDataset, FrfError, C64};

fn stage() -> WaferStage {
    WaferStage::build(&WaferStageConfig::default()).unwrap()
}

fn small_config(
    seed: u64,
    periods: usize,
    realizations: usize,
    noise: NoiseConfig,
) -> ExperimentConfig {
    let mut c = ExperimentConfig::wafer_stage(seed);
    c.grid = LineGrid::odd(10_000.0, 2000, 0.0, 2000.0).unwrap();
    c.periods = periods;
    c.realizations = realizations;
    c.output_noise = noise;
    c
}

/// White sensor noise plus a fast drift (corner well above the 5 Hz line spacing, so
/// periods are independent).
fn test_noise() -> NoiseConfig {
    NoiseConfig {
        white_rms: 1e-9,
        drift_rms: 2e-9,
        drift_corner_hz: 50.0,
    }
}

fn experiment(cfg: ExperimentConfig) -> ClosedLoopExperiment {
    let st = stage();
    let k = RigidBodyController::design(&st.plant, &ControllerConfig::default(), st.fs).unwrap();
    ClosedLoopExperiment::new(st.plant, k, cfg).unwrap()
}

fn run(exp: &ClosedLoopExperiment, path: SimulationPath) -> NonparametricFrf {
    exp.estimate(path, &EstimatorConfig::default()).unwrap()
}

/// Largest over lines of ||G_hat - G||_F / ||G||_F.
fn max_rel_line_error(a: &Frf, b: &Frf) -> f64 {
    let m = a.n_entries();
    (0..a.n_lines())
        .map(|k| {
            let (x, y) = (a.line(k), b.line(k));
            let num: f64 = (0..m).map(|e| (x[e] - y[e]).norm_sqr()).sum();
            let den: f64 = (0..m).map(|e| y[e].norm_sqr()).sum();
            (num / den).sqrt()
        })
        .fold(0.0, f64::max)
}

#[test]
fn zero_noise_gives_the_true_sampled_frf() {
    let exp = experiment(small_config(3, 2, 2, NoiseConfig::none()));
    let est = run(&exp, SimulationPath::FrequencyDomain);
    let truth = exp.true_frf().unwrap();
    let e = max_rel_line_error(&est.frf, &truth);
    println!("zero noise, frequency-domain path: max relative line error {e:.2e}");
    assert!(e < 1e-10, "{e}");
    // and the true sampled FRF is the ZOH + one-sample-delay response of the plant
    let zoh = stage()
        .plant
        .sampled_response(exp.freq_hz(), 10_000.0, 1.0)
        .unwrap();
    assert_eq!(truth.values(), &zoh.values[..]);
}

#[test]
fn time_domain_path_matches_the_frequency_domain_path() {
    // zero noise: only the transient from rest separates the two
    let mut cfg = small_config(5, 2, 1, NoiseConfig::none());
    cfg.transient_periods = 25;
    let exp = experiment(cfg);
    let a = run(&exp, SimulationPath::FrequencyDomain);
    let b = run(&exp, SimulationPath::TimeDomain);
    let e0 = max_rel_line_error(&b.frf, &a.frf);
    println!("zero noise: path (b) vs (a) max relative line error {e0:.2e}");
    assert!(e0 < 1e-8, "{e0}");

    // with noise: both paths see the same noise records. The time-domain path is the
    // physically exact one: per period, the noise response of the loop is not periodic
    // (the transient term of McKelvey eq. (8)), and through the rigid body's 1/s^2 this
    // leakage dominates the noise of the lowest lines; its own period-to-period variance
    // accounts for it. Path (a) neglects it, so the two agree to (b)'s noise level.
    let mut cfg = small_config(6, 3, 2, test_noise());
    cfg.transient_periods = 25;
    let exp = experiment(cfg);
    let a = run(&exp, SimulationPath::FrequencyDomain);
    let b = run(&exp, SimulationPath::TimeDomain);
    let truth = exp.true_frf().unwrap();
    let vb = b.noise_variance.as_ref().unwrap();
    let m = truth.n_entries();
    let (mut worst, mut num, mut den, mut dev) = (0.0f64, 0.0, 0.0, 0.0);
    let (mut num_hi, mut den_hi) = (0.0, 0.0);
    for k in 0..truth.n_lines() {
        let d: f64 = (0..m)
            .map(|e| (a.frf.line(k)[e] - b.frf.line(k)[e]).norm_sqr())
            .sum();
        let t: f64 = (0..m)
            .map(|e| (b.frf.line(k)[e] - truth.line(k)[e]).norm_sqr())
            .sum();
        let v: f64 = vb[k * m..(k + 1) * m].iter().sum();
        worst = worst.max((d / v).sqrt());
        num += d;
        den += v;
        dev += t;
        if truth.freq_hz(k) >= 50.0 {
            num_hi += d;
            den_hi += v;
        }
    }
    let (rms, rms_hi, rms_dev) = (
        (num / den).sqrt(),
        (num_hi / den_hi).sqrt(),
        (dev / den).sqrt(),
    );
    println!(
        "with noise: |G_a - G_b| / sigma_b: RMS {rms:.3} (above 50 Hz {rms_hi:.3}), worst line \
         {worst:.3}; |G_b - G| / sigma_b RMS {rms_dev:.3}"
    );
    assert!(rms < 1.0 && worst < 2.0, "{rms} {worst}");
    // where the leakage is negligible the two paths coincide far below the noise
    assert!(rms_hi < 0.1, "{rms_hi}");
    // the noise itself is far from zero, and (b)'s variance describes its error
    assert!(rms_dev > 0.3 && rms_dev < 2.0, "{rms_dev}");
}

#[test]
fn unbiased_and_the_reported_variance_matches_the_empirical_one() {
    let seeds = 40u64;
    let (p, r) = (3, 3);
    let truth = experiment(small_config(0, p, r, test_noise()))
        .true_frf()
        .unwrap();
    let m = truth.values().len();
    let mut sum = vec![C64::new(0.0, 0.0); m];
    let mut sum2 = vec![0.0; m];
    let mut rep_total = vec![0.0; m];
    let mut rep_noise = vec![0.0; m];
    for s in 0..seeds {
        let est = run(
            &experiment(small_config(100 + s, p, r, test_noise())),
            SimulationPath::FrequencyDomain,
        );
        let tv = est.total_variance.as_ref().unwrap();
        let nv = est.noise_variance.as_ref().unwrap();
        for (i, (g, g0)) in est.frf.values().iter().zip(truth.values()).enumerate() {
            let d = g - g0;
            sum[i] += d;
            sum2[i] += d.norm_sqr();
            rep_total[i] += tv[i];
            rep_noise[i] += nv[i];
        }
    }
    let ns = seeds as f64;
    // unbiased: per line and entry, the error averaged over the seeds in units of its
    // standard error; per entry, its mean over the (independent) lines is zero within
    // 4 sigma (each component has variance ~1/2 * 39/37, a t variable with 39 dof)
    let ne = truth.n_entries();
    let nl = truth.n_lines();
    let (mut zr, mut zi) = (vec![0.0; ne], vec![0.0; ne]);
    for i in 0..m {
        let emp = (sum2[i] - sum[i].norm_sqr() / ns) / (ns - 1.0);
        let se = (emp / ns).sqrt();
        zr[i % ne] += sum[i].re / ns / se / nl as f64;
        zi[i % ne] += sum[i].im / ns / se / nl as f64;
    }
    let lim = 4.0 * (0.5 * 39.0 / 37.0 / nl as f64).sqrt();
    let worst = zr.iter().chain(&zi).map(|z| z.abs()).fold(0.0, f64::max);
    println!("largest mean normalised error over entries {worst:.4}, 4-sigma limit {lim:.4}");
    assert!(worst < lim, "{worst} >= {lim}");
    // variance: empirical over seeds vs reported (mean over seeds)
    let emp: f64 = (0..m)
        .map(|i| (sum2[i] - sum[i].norm_sqr() / ns) / (ns - 1.0))
        .sum();
    let tot: f64 = rep_total.iter().sum::<f64>() / ns;
    let noi: f64 = rep_noise.iter().sum::<f64>() / ns;
    println!(
        "variance ratios: total/empirical {:.3}, noise/empirical {:.3}",
        tot / emp,
        noi / emp
    );
    assert!((tot / emp - 1.0).abs() < 0.2, "{}", tot / emp);
    assert!((noi / emp - 1.0).abs() < 0.2, "{}", noi / emp);
    // also per decade of frequency (the noise is coloured and the loop shapes it)
    for (lo, hi) in [(0.0, 100.0), (100.0, 1000.0), (1000.0, 2000.0)] {
        let mut e = 0.0;
        let mut t = 0.0;
        for k in 0..truth.n_lines() {
            let f = truth.freq_hz(k);
            if f < lo || f >= hi {
                continue;
            }
            for j in 0..truth.n_entries() {
                let i = k * truth.n_entries() + j;
                e += (sum2[i] - sum[i].norm_sqr() / ns) / (ns - 1.0);
                t += rep_noise[i] / ns;
            }
        }
        println!("  {lo}..{hi} Hz: noise/empirical {:.3}", t / e);
        assert!((t / e - 1.0).abs() < 0.25, "{lo}..{hi} Hz: {}", t / e);
    }
}

fn mean_variance(p: usize, r: usize, seeds: u64) -> (f64, f64) {
    let (mut t, mut n) = (0.0, 0.0);
    for s in 0..seeds {
        let est = run(
            &experiment(small_config(500 + s, p, r, test_noise())),
            SimulationPath::FrequencyDomain,
        );
        t += est
            .total_variance
            .as_ref()
            .map_or(0.0, |v| v.iter().sum::<f64>());
        n += est.noise_variance.as_ref().unwrap().iter().sum::<f64>();
    }
    (t / seeds as f64, n / seeds as f64)
}

#[test]
fn variance_scales_as_one_over_periods_times_realizations() {
    let (t22, n22) = mean_variance(2, 2, 6);
    let (t42, n42) = mean_variance(4, 2, 6);
    let (t44, n44) = mean_variance(4, 4, 6);
    println!(
        "noise variance ratios: P 2->4: {:.3}, R 2->4: {:.3}; total: {:.3}, {:.3}",
        n22 / n42,
        n42 / n44,
        t22 / t42,
        t42 / t44
    );
    for ratio in [n22 / n42, n42 / n44, t22 / t42, t42 / t44] {
        assert!((ratio / 2.0 - 1.0).abs() < 0.2, "{ratio}");
    }
}

#[test]
fn nonlinear_distortions_show_as_excess_total_variance_and_paths_agree() {
    let mut cfg = small_config(9, 3, 4, test_noise());
    cfg.cubic_nonlinearity = 1e-3;
    let nl = run(&experiment(cfg.clone()), SimulationPath::FrequencyDomain);
    let ratio = nl.distortion_ratio_per_line().unwrap();
    let mean_nl = ratio.iter().sum::<f64>() / ratio.len() as f64;
    let lin = run(
        &experiment(small_config(9, 3, 4, test_noise())),
        SimulationPath::FrequencyDomain,
    );
    let ratio_lin = lin.distortion_ratio_per_line().unwrap();
    let mean_lin = ratio_lin.iter().sum::<f64>() / ratio_lin.len() as f64;
    println!("total/noise variance: linear {mean_lin:.2}, cubic actuator {mean_nl:.2}");
    assert!((mean_lin - 1.0).abs() < 0.3, "{mean_lin}");
    assert!(mean_nl > 10.0, "{mean_nl}");
    assert!(nl.nonlinear_distortion().unwrap().iter().sum::<f64>() > 0.0);

    // harmonic balance (a) and the time-domain simulation (b) agree without noise
    cfg.output_noise = NoiseConfig::none();
    cfg.periods = 1;
    cfg.realizations = 1;
    cfg.transient_periods = 25;
    let exp = experiment(cfg);
    let a = run(&exp, SimulationPath::FrequencyDomain);
    let b = run(&exp, SimulationPath::TimeDomain);
    let e = max_rel_line_error(&b.frf, &a.frf);
    let d = max_rel_line_error(&a.frf, &exp.true_frf().unwrap());
    println!("cubic actuator, no noise: (b) vs (a) {e:.2e}; distortion vs linear FRF {d:.2e}");
    assert!(e < 1e-7, "{e}");
    assert!(d > 1e-3, "{d}");
}

#[test]
fn input_noise_and_open_loop_plants_work() {
    // errors-in-variables: noise on the recorded input; the estimate stays within its
    // reported uncertainty
    let mut cfg = small_config(11, 4, 3, test_noise());
    cfg.input_noise_rms = 1e-3;
    let exp = experiment(cfg);
    let est = run(&exp, SimulationPath::FrequencyDomain);
    let truth = exp.true_frf().unwrap();
    let var: f64 = est.noise_variance.as_ref().unwrap().iter().sum();
    let z2: f64 = est
        .frf
        .values()
        .iter()
        .zip(truth.values())
        .map(|(g, g0)| (g - g0).norm_sqr())
        .sum::<f64>()
        / var;
    println!("input noise: sum |e|^2 / sum var = {z2:.3}");
    assert!(z2 > 0.5 && z2 < 2.0, "{z2}");

    // a stable plant without rigid body in open loop (K = 0)
    let plant = ModalPlant::builder(2, 2)
        .mode(50.0, 0.02, vec![1.0, 0.5], vec![0.8, -0.3])
        .mode(180.0, 0.01, vec![-0.4, 1.0], vec![0.2, 0.9])
        .build()
        .unwrap();
    let k = RigidBodyController::open_loop(2, 2, 10_000.0);
    let exp =
        ClosedLoopExperiment::new(plant, k, small_config(12, 2, 1, NoiseConfig::none())).unwrap();
    let est = run(&exp, SimulationPath::FrequencyDomain);
    let e = max_rel_line_error(&est.frf, &exp.true_frf().unwrap());
    assert!(e < 1e-10, "{e}");
}

#[test]
fn bad_configurations_give_clear_errors() {
    // no excited lines
    let e = LineGrid::odd(10_000.0, 2000, 6000.0, 7000.0).unwrap_err();
    assert!(matches!(e, FrfError::InvalidParameter { .. }), "{e}");
    assert!(e.to_string().contains("no excited lines"), "{e}");
    // periods < 1
    let st = stage();
    let k = RigidBodyController::design(&st.plant, &ControllerConfig::default(), st.fs).unwrap();
    let mut cfg = small_config(1, 0, 1, NoiseConfig::none());
    let e = ClosedLoopExperiment::new(st.plant.clone(), k.clone(), cfg.clone()).unwrap_err();
    assert!(e.to_string().contains("periods"), "{e}");
    cfg.periods = 1;
    // an actuator that no experiment excites: a singular input matrix at every line
    cfg.excited_inputs = Some((0..12).chain([11]).collect());
    let exp = ClosedLoopExperiment::new(st.plant.clone(), k.clone(), cfg.clone()).unwrap();
    let e = exp
        .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())
        .unwrap_err();
    assert!(matches!(e, FrfError::SingularInput { line: 0, .. }), "{e}");
    println!("{e}");
    // fewer experiments than inputs
    cfg.excited_inputs = Some((0..12).collect());
    let exp = ClosedLoopExperiment::new(st.plant.clone(), k.clone(), cfg.clone()).unwrap();
    let e = exp
        .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())
        .unwrap_err();
    assert!(matches!(e, FrfError::SingularInput { .. }), "{e}");
    cfg.excited_inputs = Some(vec![13]);
    assert!(ClosedLoopExperiment::new(st.plant.clone(), k.clone(), cfg.clone()).is_err());
    cfg.excited_inputs = None;
    // an unstable closed loop: too much gain
    let hot = ControllerConfig {
        gain_scale: 200.0,
        ..ControllerConfig::default()
    };
    let kh = RigidBodyController::design(&st.plant, &hot, st.fs).unwrap();
    let e = ClosedLoopExperiment::new(st.plant.clone(), kh, cfg.clone()).unwrap_err();
    assert!(matches!(e, FrfError::UnstableClosedLoop { .. }), "{e}");
    println!("{e}");
    // a free rigid body without feedback drifts away: unstable too
    let open = RigidBodyController::open_loop(4, 13, st.fs);
    let e = ClosedLoopExperiment::new(st.plant.clone(), open, cfg.clone()).unwrap_err();
    assert!(matches!(e, FrfError::UnstableClosedLoop { .. }), "{e}");
    // the time-domain path needs a whole number of samples of delay
    let mut frac = cfg.clone();
    frac.delay_samples = 0.5;
    let exp = ClosedLoopExperiment::new(st.plant.clone(), k.clone(), frac).unwrap();
    assert!(exp
        .estimate(SimulationPath::TimeDomain, &EstimatorConfig::default())
        .is_err());
    // other bad values
    for f in [
        (|c: &mut ExperimentConfig| c.realizations = 0) as fn(&mut ExperimentConfig),
        |c| c.rms = 0.0,
        |c| c.rms = f64::NAN,
        |c| c.input_noise_rms = -1.0,
        |c| c.output_noise.white_rms = f64::INFINITY,
        |c| c.delay_samples = -1.0,
        |c| c.excited_inputs = Some(vec![]),
    ] {
        let mut c = cfg.clone();
        f(&mut c);
        assert!(ClosedLoopExperiment::new(st.plant.clone(), k.clone(), c).is_err());
    }
    // a nonlinearity too strong for the harmonic balance
    let mut c = cfg.clone();
    c.cubic_nonlinearity = 50.0;
    let exp = ClosedLoopExperiment::new(st.plant.clone(), k, c).unwrap();
    let e = exp
        .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())
        .unwrap_err();
    assert!(e.to_string().contains("did not converge"), "{e}");
}

/// Mean over lines and entries of `a / b` where `b > 0`.
fn mean_ratio(a: &[f64], b: &[f64]) -> f64 {
    let (s, n) = a
        .iter()
        .zip(b)
        .filter(|(_, y)| **y > 0.0)
        .fold((0.0, 0usize), |(s, n), (x, y)| (s + x / y, n + 1));
    s / n as f64
}

/// Issue 41: time records of a MIMO open-loop experiment with a known stochastic
/// nonlinear contribution (the piezo-like mechanism, shortened to 1024-sample periods),
/// R = 2, 4, 8 realizations and P = 2, 4 periods. Checked against the known answer:
/// - the nonlinear variance of the averaged estimate (total minus noise) against its
///   truth `d^2 |P|^2 / R`: the mean ratio over the 1440 (entry, line) pairs of 160 lines
///   within 4.5 sampling standard deviations of 1 (each line's total variance has
///   `2 (R - 1)` real degrees of freedom; its noise part is small beside it);
/// - the noise variance is the same with and without the distortion (it is periodic,
///   so the period-to-period spread does not see it): equal to rounding;
/// - the best linear approximation against the plant: `|G - P|^2` over its true variance
///   averages 1 within the same spread, and so does the estimated total variance.
#[test]
fn time_records_with_stochastic_distortion_split_the_variance_as_the_truth_says() {
    for (r, p) in [(2, 2), (2, 4), (4, 2), (8, 2), (8, 4)] {
        let cfg = PiezoConfig {
            seed: 7 + r as u64,
            period: 1024,
            f_max_hz: 1000.0,
            periods: p,
            realizations: r,
            ..Default::default()
        };
        let exp = piezo_experiment(&cfg).unwrap();
        let est = exp
            .estimate(SimulationPath::TimeDomain, &EstimatorConfig::default())
            .unwrap();
        let truth = exp.true_frf().unwrap();
        let total = est.total_variance.clone().unwrap();
        let noise = est.noise_variance.clone().unwrap();
        let nl = est.nonlinear_distortion().unwrap();
        let d2 = cfg.distortion * cfg.distortion;
        let nl_true: Vec<f64> = truth
            .values()
            .iter()
            .map(|g| d2 * g.norm_sqr() / r as f64)
            .collect();
        let ratio_nl = mean_ratio(&nl, &nl_true);
        let err2: Vec<f64> = est
            .frf
            .values()
            .iter()
            .zip(truth.values())
            .map(|(g, g0)| (g - g0).norm_sqr())
            .collect();
        // against the true total variance (the nonlinear truth plus the small noise
        // part): with R = 2 the estimated total variance of a line has 2 degrees of
        // freedom, and the mean of |e|^2 over it diverges
        let total_true: Vec<f64> = nl_true.iter().zip(&noise).map(|(a, b)| a + b).collect();
        let z2 = mean_ratio(&err2, &total_true);
        let total_to_truth = mean_ratio(&total, &total_true);
        let noise_to_nl = mean_ratio(&noise, &nl_true);
        // the same experiment without the distortion: the same noise records
        let lin = piezo_experiment(&PiezoConfig {
            distortion: 0.0,
            ..cfg.clone()
        })
        .unwrap()
        .estimate(SimulationPath::TimeDomain, &EstimatorConfig::default())
        .unwrap();
        let noise_lin = lin.noise_variance.unwrap();
        let noise_change = noise
            .iter()
            .zip(&noise_lin)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        let pairs = nl.len() as f64;
        let sd = (1.0 / ((r - 1) as f64 * pairs)).sqrt();
        println!(
            "R = {r}, P = {p}: nonlinear variance / truth {ratio_nl:.3}, |G - P|^2 / total \
             variance {z2:.3}, estimated / true total variance {total_to_truth:.3} (sampling sd \
             {sd:.3}); noise / nonlinear {noise_to_nl:.4}; \
             noise variance change with the distortion {noise_change:.1e}"
        );
        assert_eq!(est.realizations, r);
        assert_eq!(est.periods, p);
        assert!((ratio_nl - 1.0).abs() < 4.5 * sd + 0.02, "{ratio_nl}");
        assert!((z2 - 1.0).abs() < 4.5 * sd + 0.05, "{z2}");
        assert!(
            (total_to_truth - 1.0).abs() < 4.5 * sd + 0.05,
            "{total_to_truth}"
        );
        assert!(noise_change < 1e-6, "{noise_change}");
    }
    // the closed-loop time path refuses the distortion with a clear error
    let mut cfg = small_config(3, 2, 2, NoiseConfig::none());
    cfg.stochastic_distortion = 0.1;
    let e = experiment(cfg)
        .estimate(SimulationPath::TimeDomain, &EstimatorConfig::default())
        .unwrap_err();
    assert!(e.to_string().contains("open loop"), "{e}");
}
