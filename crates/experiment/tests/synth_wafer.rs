//! The wafer-stage testbed: the plant looks like the reference stage, a seed gives the
//! same plant, the truth JSON round-trips, the default experiment's CMIF shows the 17
//! modes, and the truth of the reference data reproduces its noiseless response.

use ::experiment::nonparametric::EstimatorConfig;
use ::experiment::synth::*;
use faer::Mat;
use frf_data::cmif::{cmif, pick_peaks, PeakConfig};
use frf_data::io::read_frf_csv;
use frf_data::truth::Truth;
use frf_data::FrfDataset;

#[test]
fn the_stage_looks_like_the_reference_and_is_seeded() {
    let a = WaferStage::build(&WaferStageConfig::default()).unwrap();
    let b = WaferStage::build(&WaferStageConfig::default()).unwrap();
    assert_eq!(a, b, "a seed gives the same plant");
    let c = WaferStage::build(&WaferStageConfig {
        seed: 2,
        ..WaferStageConfig::default()
    })
    .unwrap();
    assert_ne!(a.plant.modes, c.plant.modes);
    assert_eq!(a.plant.ny(), 4);
    assert_eq!(a.plant.nu(), 13);
    assert_eq!(a.plant.modes.len(), 17);
    let f: Vec<f64> = a.plant.modes.iter().map(|m| m.f_hz).collect();
    assert!(f[0] >= 130.0 && f[0] <= 150.0, "{f:?}");
    assert!(f[16] >= 1800.0 && f[16] <= 2000.0, "{f:?}");
    assert!(f.windows(2).all(|w| w[1] > w[0]));
    // some close pairs (within 5 %)
    let close = f.windows(2).filter(|w| w[1] / w[0] < 1.05).count();
    assert!(close >= 2, "{f:?}");
    for m in &a.plant.modes {
        assert!(m.zeta >= 0.004 && m.zeta <= 0.02);
    }
    // the rigid-body residue of the reference stage (z, Rx, Ry of a 20 kg plate):
    // compare with wafer_nominal.truth.json's b_rb, which our layout reproduces
    let r = a.plant.rigid.residue().unwrap();
    let want = [
        [
            0.05, 0.125, -0.025, 0.125, -0.025, 0.2, 0.05, -0.1, 0.05, 0.125, 0.05, -0.025, 0.05,
        ],
        [
            0.05, -0.025, 0.125, 0.125, -0.025, 0.05, 0.2, 0.05, -0.1, 0.05, 0.125, 0.05, -0.025,
        ],
        [
            0.05, -0.025, 0.125, -0.025, 0.125, -0.1, 0.05, 0.2, 0.05, -0.025, 0.05, 0.125, 0.05,
        ],
        [
            0.05, 0.125, -0.025, -0.025, 0.125, 0.05, -0.1, 0.05, 0.2, 0.05, -0.025, 0.05, 0.125,
        ],
    ];
    for i in 0..4 {
        for j in 0..13 {
            assert!(
                (r[(i, j)] - want[i][j]).abs() < 1e-12,
                "b_rb[{i}][{j}] = {}",
                r[(i, j)]
            );
        }
    }
    // rank three (z, Rx, Ry)
    let sv = r.singular_values().unwrap();
    assert!(sv[2] > 1e-3 * sv[0] && sv[3] < 1e-12 * sv[0], "{sv:?}");
}

#[test]
fn truth_json_round_trips_and_has_the_reference_schema() {
    let a = WaferStage::build(&WaferStageConfig::default()).unwrap();
    let t = a.truth();
    assert!((t.delay_s - 150e-6).abs() < 1e-15);
    assert_eq!(t.fs, 10_000.0);
    let text = serde_json::to_string(&t).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v["model"]["b_rb"].as_array().unwrap().len() == 4);
    assert!(v["model"]["modes"][0]["f_hz"].is_number());
    assert_eq!(v["model"]["modes"][0]["c"].as_array().unwrap().len(), 4);
    assert_eq!(v["model"]["modes"][0]["b"].as_array().unwrap().len(), 13);
    let back: Truth = serde_json::from_str(&text).unwrap();
    let p = ModalPlant::from_truth(&back).unwrap();
    // (serde_json's default float parser may differ from the written value in the last
    // ulp)
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-14 * x.abs().max(1e-300);
    assert_eq!(p.modes.len(), a.plant.modes.len());
    for (m, n) in p.modes.iter().zip(&a.plant.modes) {
        assert!(close(m.f_hz, n.f_hz) && close(m.zeta, n.zeta));
        assert!(m
            .c
            .iter()
            .zip(&n.c)
            .chain(m.b.iter().zip(&n.b))
            .all(|(x, y)| close(*x, *y)));
    }
    assert_eq!(truth_delay_samples(&back).unwrap(), 1.0);
    // the plant through the truth's modal model: same sampled response
    let f = [0.25, 143.0, 1999.75];
    let g1 = a.plant.sampled_response(&f, 1e4, 1.0).unwrap();
    let omega: Vec<f64> = f.iter().map(|x| std::f64::consts::TAU * x).collect();
    let g2 = back
        .modal_model()
        .unwrap()
        .zoh_response(&omega, 1e-4, 1.0)
        .unwrap();
    for (x, y) in g1.values.iter().zip(&g2.values) {
        assert!((x - y).norm() <= 1e-12 * y.norm().max(1e-12));
    }
    // suspension and feedthrough survive the round trip as effects
    let susp = ModalPlant::builder(1, 2)
        .suspended_body(Mat::from_fn(1, 2, |_, j| 0.1 + j as f64), 3.0, 0.1)
        .mode(100.0, 0.01, vec![1.0], vec![0.5, -0.5])
        .feedthrough(Mat::from_fn(1, 2, |_, j| 1e-6 * (j as f64 + 1.0)))
        .build()
        .unwrap();
    let t = susp.to_truth(7, 1000.0, 1.5e-3);
    assert!(t.effects.contains_key("suspension") && t.effects.contains_key("crosstalk_D"));
    assert_eq!(ModalPlant::from_truth(&t).unwrap(), susp);
    assert_eq!(truth_delay_samples(&t).unwrap(), 1.0);
}

#[test]
fn plant_builder_rejects_bad_values() {
    let ok = || ModalPlant::builder(2, 3);
    assert!(ok()
        .mode(10.0, 0.01, vec![1.0, 2.0], vec![1.0; 3])
        .build()
        .is_ok());
    assert!(ok()
        .mode(10.0, 0.01, vec![1.0], vec![1.0; 3])
        .build()
        .is_err());
    assert!(ok()
        .mode(-10.0, 0.01, vec![1.0; 2], vec![1.0; 3])
        .build()
        .is_err());
    assert!(ok()
        .mode(10.0, 1.5, vec![1.0; 2], vec![1.0; 3])
        .build()
        .is_err());
    assert!(ok()
        .mode(10.0, 0.01, vec![f64::NAN; 2], vec![1.0; 3])
        .build()
        .is_err());
    assert!(ok().rigid_body(Mat::zeros(3, 2)).build().is_err());
    assert!(ModalPlant::builder(0, 3).build().is_err());
    assert!(WaferStage::build(&WaferStageConfig {
        n_modes: 0,
        ..WaferStageConfig::default()
    })
    .is_err());
    assert!(WaferStage::build(&WaferStageConfig {
        zeta_range: (0.5, 0.1),
        ..WaferStageConfig::default()
    })
    .is_err());
}

#[test]
fn the_default_experiment_shows_the_17_modes_in_its_cmif() {
    let w = WaferStageExperiment::default_with(1, 10, 10).unwrap();
    let est = w.run().unwrap();
    let frf = &est.frf;
    assert_eq!(frf.n_lines(), 4000);
    assert_eq!(frf.freq_hz(0), 0.25);
    assert_eq!(frf.freq_hz(3999), 1999.75);
    // the CMIF and its peak picker (frf_data::cmif)
    let c = cmif(frf).unwrap();
    let picked = pick_peaks(&c, &PeakConfig::default());
    let modes: Vec<f64> = w.stage.plant.modes.iter().map(|m| m.f_hz).collect();
    println!(
        "picked {} peaks: {:?}",
        picked.len(),
        picked
            .iter()
            .map(|p| (p.f_hz * 10.0).round() / 10.0)
            .collect::<Vec<_>>()
    );
    let mut found = 0;
    for &fm in &modes {
        // a picked peak within 1 % (the damped peak of a mode of zeta <= 0.02 sits
        // within zeta^2 of its natural frequency; the line spacing is 0.5 Hz)
        if picked.iter().any(|p| (p.f_hz - fm).abs() < 0.01 * fm + 0.5) {
            found += 1;
        } else {
            println!("mode at {fm:.1} Hz not picked in the CMIF");
        }
    }
    println!("{found} of {} modes visible in the CMIF", modes.len());
    assert_eq!(found, 17);
    // and the estimate is close to the truth: median relative error of the entries
    let truth = w.experiment.true_frf().unwrap();
    let mut rel: Vec<f64> = frf
        .values()
        .iter()
        .zip(truth.values())
        .map(|(a, b)| (a - b).norm() / b.norm())
        .collect();
    rel.sort_by(f64::total_cmp);
    println!("median relative error {:.2e}", rel[rel.len() / 2]);
    assert!(rel[rel.len() / 2] < 1e-2);
}

#[test]
fn the_reference_truth_reproduces_its_noiseless_response() {
    let Some(tp) =
        frf_data::shared_data::require("synth_wafer_reference", "wafer_nominal.truth.json")
    else {
        return;
    };
    let Some(np) =
        frf_data::shared_data::require("synth_wafer_reference", "wafer_nominal.noiseless.csv")
    else {
        return;
    };
    let truth = Truth::read(&tp).unwrap();
    let noiseless = read_frf_csv(&np).unwrap();
    let plant = ModalPlant::from_truth(&truth).unwrap();
    let d = truth_delay_samples(&truth).unwrap();
    assert_eq!(d, 1.0);
    // the closed-loop experiment on the reference plant, zero noise, one period
    let k = RigidBodyController::design(&plant, &ControllerConfig::default(), truth.fs).unwrap();
    let mut cfg = ExperimentConfig::wafer_stage(1);
    cfg.periods = 1;
    cfg.realizations = 1;
    cfg.output_noise = NoiseConfig::none();
    cfg.delay_samples = d;
    let exp = ClosedLoopExperiment::new(plant, k, cfg).unwrap();
    let est = exp
        .estimate(SimulationPath::FrequencyDomain, &EstimatorConfig::default())
        .unwrap();
    assert_eq!(est.frf.freqs_hz(), noiseless.freqs_hz());
    // per line: largest entry error over the largest entry (the file has 11 digits)
    let err = |g: &[frf_data::C64], k: usize| -> f64 {
        let b = noiseless.line(k);
        let num = g
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max);
        num / b.iter().map(|y| y.norm()).fold(0.0, f64::max)
    };
    let direct = exp.true_frf().unwrap();
    let (mut worst, mut worst_direct, mut at) = (0.0f64, 0.0f64, 0);
    for k in 0..noiseless.n_lines() {
        let e = err(est.frf.line(k), k);
        if e > worst {
            worst = e;
            at = k;
        }
        worst_direct = worst_direct.max(err(direct.line(k), k));
    }
    println!(
        "reference plant vs noiseless reference: sampled response {worst_direct:.2e}; \
         simulated closed loop + estimate {worst:.2e} (at {} Hz)",
        noiseless.freq_hz(at)
    );
    assert!(worst_direct < 1e-8, "{worst_direct}");
    assert!(worst < 1e-8, "{worst}");
    // the reference noisy estimate lies within its own variance of it, as ours would
    let Some(nom) = frf_data::shared_data::require("synth_wafer_reference", "wafer_nominal.csv")
    else {
        return;
    };
    let nominal = read_frf_csv(&nom).unwrap();
    let var: f64 = nominal.variances().unwrap().iter().sum();
    let err: f64 = nominal
        .values()
        .iter()
        .zip(est.frf.values())
        .map(|(a, b)| (a - b).norm_sqr())
        .sum();
    println!("reference estimate: sum |e|^2 / sum var = {:.3}", err / var);
    assert!(err / var < 3.0);
}
