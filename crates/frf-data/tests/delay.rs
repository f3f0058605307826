//! Delay estimation (the delay periodogram of the squared FRF) and compensation: the
//! reference wafer stage (acceptance: hold + computation delay within 10 us of 150 us),
//! simulated plants with known delays through an exact zero-order hold, velocity and
//! acceleration FRFs, noise, and clear errors for configurations without information.

use faer::Mat;
use frf_data::delay::{compensate_delay, estimate_delay, DelayConfig, DelayPhaseKind};
use frf_data::shared_data::require;
use frf_data::{Frf, FrfDataset, FrfError, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use realize::{ModalModel, PolePair};
use std::f64::consts::TAU;

#[test]
fn wafer_nominal_delay_is_150_us() {
    let Some(path) = require("wafer_nominal_delay_is_150_us", "wafer_nominal.csv") else {
        return;
    };
    let frf = frf_data::io::read_frf_csv(&path).unwrap();
    for (what, est) in [
        (
            "all lines",
            estimate_delay(&frf, &DelayConfig::default()).unwrap(),
        ),
        (
            "20..2000 Hz",
            estimate_delay(&frf.band(20.0, 2000.0).unwrap(), &DelayConfig::default()).unwrap(),
        ),
    ] {
        println!(
            "wafer_nominal ({what}): tau = {:.2} us, std {:?} us, coherence {:.3}, {:?}, range {:?} s, grid {:.2} us, resolution {:.3} ns",
            est.tau_s * 1e6,
            est.std_s.map(|s| s * 1e6),
            est.coherence,
            est.kind,
            est.range_s,
            est.grid_step_s * 1e6,
            est.resolution_s * 1e9
        );
        assert!(
            (est.tau_s - 150e-6).abs() < 10e-6,
            "{what}: {} us",
            est.tau_s * 1e6
        );
        assert_eq!(est.kind, DelayPhaseKind::Real);
        assert!(est.coherence > 0.5);
    }
}

/// A random displacement plant: rigid body `R / s^2` and 3..8 lightly damped modes in
/// 30..1800 Hz.
fn random_plant(rng: &mut ChaCha8Rng, ny: usize, nu: usize) -> ModalModel {
    let mut m = ModalModel::new(ny, nu);
    let r = Mat::from_fn(ny, nu, |_, _| {
        let x: f64 = StandardNormal.sample(rng);
        x
    });
    m.rigid = vec![Mat::zeros(ny, nu), r];
    for _ in 0..rng.random_range(3..=8) {
        let f = (30f64.ln() + rng.random::<f64>() * (1800f64 / 30.0).ln()).exp();
        let zeta = rng.random_range(0.002..0.03);
        let c: Vec<f64> = (0..ny).map(|_| StandardNormal.sample(rng)).collect();
        let b: Vec<f64> = (0..nu).map(|_| StandardNormal.sample(rng)).collect();
        let num = Mat::from_fn(ny, nu, |i, j| c[i] * b[j]);
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
    }
    m
}

fn grid() -> (Vec<f64>, Vec<f64>) {
    let f: Vec<f64> = (1..=2000).map(|k| k as f64).collect();
    let w = f.iter().map(|x| TAU * x).collect();
    (f, w)
}

/// The plant sampled through a 10 kHz zero-order hold with `d` samples of extra delay
/// (total delay `(d + 0.5) / 10 kHz`), or in continuous time (no hold, no delay) when
/// `d` is `None`.
fn measure(m: &ModalModel, d: Option<f64>) -> Frf {
    let (f, w) = grid();
    let g = match d {
        Some(d) => m.zoh_response(&w, 1e-4, d).unwrap(),
        None => m.freq_response(&w).unwrap(),
    };
    Frf::from_grid(f, g).unwrap()
}

#[test]
fn simulated_delays_are_recovered() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    // (extra samples, total delay): continuous (no hold), hold only, hold + 1 sample,
    // hold + 3.5 samples.
    let cases = [
        (None, 0.0),
        (Some(0.0), 50e-6),
        (Some(1.0), 150e-6),
        (Some(3.5), 400e-6),
    ];
    let mut errs = Vec::new();
    for trial in 0..12 {
        let (ny, nu) = (rng.random_range(1..=4), rng.random_range(1..=4));
        let m = random_plant(&mut rng, ny, nu);
        for &(d, tau) in &cases {
            let data = measure(&m, d);
            let est = estimate_delay(&data, &DelayConfig::default()).unwrap();
            println!(
                "trial {trial} {ny}x{nu} true {:.1} us: estimate {:.3} us (std {:?} us, coherence {:.3})",
                tau * 1e6,
                est.tau_s * 1e6,
                est.std_s.map(|s| s * 1e6),
                est.coherence
            );
            errs.push((est.tau_s - tau) * 1e6);
            assert!(
                (est.tau_s - tau).abs() < 8e-6,
                "trial {trial} {ny}x{nu}: true {} us, estimate {} us",
                tau * 1e6,
                est.tau_s * 1e6
            );
            assert_eq!(est.kind, DelayPhaseKind::Real);
        }
    }
    errs.sort_by(f64::total_cmp);
    println!("errors (us): {errs:.2?}");
}

#[test]
fn velocity_and_acceleration_frfs() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let m = random_plant(&mut rng, 2, 3);
    let disp = measure(&m, Some(1.0));
    let w = disp.omegas();
    let times = |p: i32| {
        let mut g = disp.clone();
        g.scale_lines(|k| C64::new(0.0, w[k]).powi(p));
        g
    };
    let vel = estimate_delay(&times(1), &DelayConfig::default()).unwrap();
    assert_eq!(vel.kind, DelayPhaseKind::Imaginary);
    assert!((vel.tau_s - 150e-6).abs() < 8e-6, "{}", vel.tau_s);
    let acc = estimate_delay(&times(2), &DelayConfig::default()).unwrap();
    assert_eq!(acc.kind, DelayPhaseKind::Real);
    assert!((acc.tau_s - 150e-6).abs() < 8e-6, "{}", acc.tau_s);
}

#[test]
fn noisy_data_with_and_without_variance() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let m = random_plant(&mut rng, 3, 3);
    let clean = measure(&m, Some(2.0)); // 250 us
    let (n, e) = (clean.n_lines(), clean.n_entries());
    let mut vals = clean.values().to_vec();
    let mut var = Vec::with_capacity(vals.len());
    for v in vals.iter_mut() {
        // 5 % relative noise.
        let s = 0.05 * v.norm();
        let (a, b): (f64, f64) = (
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
        );
        *v += C64::new(a, b) * (s / 2f64.sqrt());
        var.push(s * s);
    }
    assert_eq!(vals.len(), n * e);
    let noisy = Frf::new(clean.freqs_hz(), 3, 3, vals, Some(var)).unwrap();
    for use_variance in [true, false] {
        let est = estimate_delay(
            &noisy,
            &DelayConfig {
                use_variance,
                ..DelayConfig::default()
            },
        )
        .unwrap();
        println!(
            "5 % noise (use_variance {use_variance}): {:.2} us, std {:?} us",
            est.tau_s * 1e6,
            est.std_s.map(|s| s * 1e6)
        );
        assert!((est.tau_s - 250e-6).abs() < 5e-6, "{}", est.tau_s * 1e6);
        let sd = est.std_s.expect("a maximum has negative curvature");
        assert!(sd > 0.0 && sd < 20e-6, "std {sd}");
    }
}

#[test]
fn compensation_removes_the_delay_and_keeps_the_variance() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let m = random_plant(&mut rng, 2, 2);
    let cont = measure(&m, None);
    let w = cont.omegas();
    let tau = 123e-6;
    let mut delayed = cont.clone();
    delayed.scale_lines(|k| C64::from_polar(1.0, -w[k] * tau));
    let var: Vec<f64> = (0..delayed.values().len())
        .map(|i| 1e-6 * (1 + i % 7) as f64)
        .collect();
    let mut delayed = delayed.with_variance(Some(var.clone())).unwrap();
    delayed.units = Some("m/N".into());
    delayed.metadata.insert("source".into(), "test".into());
    let back = compensate_delay(&delayed, tau);
    for (a, b) in back.values().iter().zip(cont.values()) {
        assert!((a - b).norm() <= 1e-12 * b.norm().max(1e-300));
    }
    for (a, b) in back.variances().unwrap().iter().zip(&var) {
        assert!((a - b).abs() <= 1e-15 * b);
    }
    assert_eq!(back.units.as_deref(), Some("m/N"));
    assert_eq!(
        back.metadata.get("source").map(String::as_str),
        Some("test")
    );
    // Compensation shifts the periodogram exactly: the estimates of the delayed and of
    // the compensated data differ by tau (whatever the small bias of the method).
    let cfg = DelayConfig {
        min_s: -1e-3,
        ..DelayConfig::default()
    };
    let est = estimate_delay(&delayed, &cfg).unwrap();
    let est0 = estimate_delay(&back, &cfg).unwrap();
    assert!(
        (est.tau_s - est0.tau_s - tau).abs() < 1e-8,
        "{} - {} vs {tau}",
        est.tau_s,
        est0.tau_s
    );
    assert!((est.tau_s - tau).abs() < 8e-6, "{}", est.tau_s);
    // A view compensates too, and a non-finite delay changes nothing.
    let view = delayed.band(100.0, 200.0).unwrap();
    let vb = compensate_delay(&view, tau);
    assert_eq!(vb.n_lines(), view.n_lines());
    assert!(
        (vb.value(0, 0, 0) - cont.value(99, 0, 0)).norm() < 1e-12 * cont.value(99, 0, 0).norm()
    );
    assert_eq!(
        compensate_delay(&delayed, f64::NAN).values(),
        delayed.values()
    );
}

#[test]
fn configurations_without_information_are_clear_errors() {
    let none = Frf::new(vec![], 1, 1, vec![], None).unwrap();
    let err = estimate_delay(&none, &DelayConfig::default()).unwrap_err();
    assert!(matches!(err, FrfError::InvalidData { .. }), "{err}");
    assert!(err.to_string().contains("at least"), "{err}");
    let one = Frf::new(vec![10.0], 1, 1, vec![C64::new(1.0, 0.0)], None).unwrap();
    let err = estimate_delay(&one, &DelayConfig::default()).unwrap_err();
    assert!(
        err.to_string().contains("has 1") || err.to_string().contains("have 1"),
        "{err}"
    );
    // Lines at 0 Hz or with a zero response carry no phase.
    let zeros = Frf::new(
        vec![0.0, 1.0, 2.0, 3.0, 4.0],
        1,
        1,
        vec![C64::new(0.0, 0.0); 5],
        None,
    )
    .unwrap();
    assert!(estimate_delay(&zeros, &DelayConfig::default()).is_err());
    // Bad settings.
    let (f, w) = grid();
    let g: Vec<C64> = w
        .iter()
        .map(|x| C64::from_polar(1.0 / x, -x * 1e-4))
        .collect();
    let d = Frf::new(f, 1, 1, g, None).unwrap();
    for cfg in [
        DelayConfig {
            max_s: Some(-1.0),
            ..DelayConfig::default()
        },
        DelayConfig {
            grid_step_s: Some(0.0),
            ..DelayConfig::default()
        },
        DelayConfig {
            tolerance_s: f64::NAN,
            ..DelayConfig::default()
        },
        DelayConfig {
            min_s: 0.0,
            max_s: Some(1.0),
            grid_step_s: Some(1e-9),
            ..DelayConfig::default()
        },
    ] {
        let e = estimate_delay(&d, &cfg).unwrap_err();
        assert!(matches!(e, FrfError::InvalidParameter { .. }), "{e}");
    }
    // ... and the default works on it: 100 us.
    let est = estimate_delay(&d, &DelayConfig::default()).unwrap();
    assert!((est.tau_s - 1e-4).abs() < 1e-8);
}
