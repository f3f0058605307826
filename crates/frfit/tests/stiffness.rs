//! A suspended body: the rigid body of a free stage is `R / s^2`; on springs (a
//! suspension stiffness, the `stiffness` effect of the catalogue) it is
//! `R / (s^2 + 2 zeta w_s s + w_s^2)`. Simulated 2 x 3 system, no files: the loop must
//! replace the free rigid body by the suspension and reach the noise level.

use faer::Mat;
use frf_data::{Frf, C64};
use frfit::pipeline::{run, PipelineConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::{ModalModel, PolePair};
use std::f64::consts::TAU;

/// Suspension at `f_s` Hz (damping 0.05) and three modes at 40, 95 and 210 Hz, measured
/// at 600 log-spaced lines over 4..400 Hz with complex Gaussian noise of 0.2 % of each
/// value, its variance attached.
fn suspended(f_s: f64, seed: u64) -> Frf {
    let (ny, nu) = (2, 3);
    let mut m = ModalModel::new(ny, nu);
    let r = Mat::from_fn(ny, nu, |i, j| 1e-3 * (0.6 + 0.2 * (i + j) as f64));
    m.pairs.push(PolePair::from_second_order(f_s, 0.05, &r));
    let shapes = [
        ([1.0, 0.5], [0.8, -0.4, 0.3]),
        ([0.4, -1.0], [0.3, 1.0, 0.7]),
        ([1.0, 0.9], [-0.6, 0.5, 1.0]),
    ];
    for (f, (c, b)) in [40.0, 95.0, 210.0].iter().zip(shapes) {
        let num = Mat::from_fn(ny, nu, |i, j| 2e-4 * c[i] * b[j] * (TAU * 40.0).powi(2));
        m.pairs.push(PolePair::from_second_order(*f, 0.015, &num));
    }
    let n = 600;
    let freqs: Vec<f64> = (0..n)
        .map(|k| 4.0 * 100f64.powf(k as f64 / (n - 1) as f64))
        .collect();
    let w: Vec<f64> = freqs.iter().map(|f| TAU * f).collect();
    let g = m.freq_response(&w).unwrap();
    let clean = Frf::from_grid(freqs.clone(), g).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut vals = clean.values().to_vec();
    let mut var = Vec::with_capacity(vals.len());
    for v in vals.iter_mut() {
        let s2 = (2e-3 * v.norm()).powi(2);
        let sd = (s2 / 2.0).sqrt();
        let u1: f64 = rng.random::<f64>().max(1e-300);
        let u2: f64 = rng.random::<f64>();
        let rr = (-2.0 * u1.ln()).sqrt();
        *v += C64::new(rr * (TAU * u2).cos() * sd, rr * (TAU * u2).sin() * sd);
        var.push(s2);
    }
    Frf::new(freqs, ny, nu, vals, Some(var)).unwrap()
}

#[test]
fn a_suspension_stiffness_is_found() {
    let f_s = 2.5;
    let data = suspended(f_s, 7);
    let cfg = PipelineConfig {
        diagnose: true,
        ..Default::default()
    };
    let out = run(&data, "suspended", &cfg, "diagnose").unwrap();
    let s = &out.summary;
    println!("initial {:?}", s.initial.errors);
    for st in &s.steps {
        println!(
            "  {} accepted={} F={:.1} {} median {:.3e} -> {:.3e}",
            st.effect,
            st.accepted,
            st.f_statistic,
            st.params,
            st.before.median_rel,
            st.after.median_rel
        );
    }
    println!(
        "verdict {} final {:?}: {}",
        s.verdict, s.final_errors, s.verdict_evidence
    );
    let stiff: Vec<_> = s
        .steps
        .iter()
        .filter(|x| x.accepted && x.effect == "stiffness")
        .collect();
    assert_eq!(stiff.len(), 1, "one stiffness step");
    let f = stiff[0].params["f_hz"].as_f64().unwrap();
    assert!(
        (f / f_s - 1.0).abs() < 0.05,
        "suspension at {f:.3} Hz, made at {f_s}"
    );
    assert_eq!(s.final_model.rigid_body_integrators, 0);
    assert_eq!(s.verdict, "noise_limited");
    assert_eq!(s.final_model.modes.len(), 3);
}
