//! The analytic Jacobian of the model currency against the finite differences of its
//! `ModelStructure` default, for every kind of parameter, in continuous time and
//! through the exact zero-order hold.

use faer::Mat;
use frf_data::{ModelStructure, C64};
use ml_refine::AnalyticModel;
use realize::{DynamicsFactor, FactorTarget, FrfModel, Hold, ModalModel, PolePair, RealPole};
use std::f64::consts::TAU;

fn model(hold: Hold, derivative_order: u32) -> FrfModel {
    let mut mm = ModalModel::new(2, 3);
    mm.rigid = vec![
        Mat::from_fn(2, 3, |i, j| 0.1 * (i as f64 - j as f64) + 0.05),
        Mat::from_fn(2, 3, |i, j| (i + j) as f64 + 0.5),
    ];
    mm.pairs.push(PolePair::from_f_zeta(
        40.0,
        0.03,
        Mat::from_fn(2, 3, |i, j| C64::new(0.1 * i as f64 + 0.2, -1.0 - j as f64)),
    ));
    mm.pairs.push(PolePair::from_f_zeta(
        230.0,
        0.008,
        Mat::from_fn(2, 3, |i, j| C64::new(-0.3 * j as f64 - 0.1, 2.0 + i as f64)),
    ));
    mm.real_poles.push(RealPole {
        pole: -300.0,
        residue: Mat::from_fn(2, 3, |i, j| (i * j) as f64 + 0.3),
    });
    mm.feedthrough = Mat::from_fn(2, 3, |i, j| 0.1 * (1.0 + i as f64 + j as f64));
    let mut fm = FrfModel::new(mm);
    fm.factors.delay_s = 2e-4;
    fm.factors.delay_fitted = true;
    fm.factors.hold = hold;
    fm.factors.derivative_order = derivative_order;
    fm.factors.crosstalk = Some(Mat::from_fn(2, 3, |i, _| 0.2 * (i as f64 + 1.0)));
    fm.factors.dynamics.push(DynamicsFactor::second_order(
        FactorTarget::Output(1),
        200.0,
        0.1,
    ));
    let mut lead = DynamicsFactor::first_order(FactorTarget::Input(2), 500.0);
    lead.num = vec![0.4];
    fm.factors.dynamics.push(lead);
    fm.factors
        .dynamics
        .push(DynamicsFactor::first_order(FactorTarget::All, 900.0));
    fm
}

#[test]
fn analytic_jacobian_matches_finite_differences() {
    for (hold, k) in [
        (Hold::None, 0),
        (Hold::None, 2),
        (Hold::Zoh { fs_hz: 4000.0 }, 0),
        (Hold::Sinc { fs_hz: 4000.0 }, 1),
    ] {
        let fm = model(hold, k);
        let am = AnalyticModel(fm.clone());
        let (m, n) = (6, fm.n_params());
        for f in [12.0, 41.0, 229.0, 777.0] {
            let w = TAU * f;
            let mut fd = vec![C64::new(0.0, 0.0); m * n];
            let mut an = vec![C64::new(0.0, 0.0); m * n];
            fm.jacobian_into(w, &mut fd);
            let mut resp = vec![C64::new(0.0, 0.0); m];
            fm.response_into(w, &mut resp);
            // central differences (step h_p = 1e-6 max(|theta_p|, 1e-6)) lose about
            // eps |P| / h_p to rounding
            let pmax = resp.iter().map(|v| v.norm()).fold(0.0, f64::max);
            let theta = fm.params();
            am.jacobian_into(w, &mut an);
            let mut worst: f64 = 0.0;
            let mut wp = (0, 0.0);
            for p in 0..n {
                let floor = 1e-15 * pmax / (1e-6 * theta[p].abs().max(1e-6));
                let col_norm = (0..m).map(|e| fd[p * m + e].norm_sqr()).sum::<f64>().sqrt();
                for e in 0..m {
                    let d = (fd[p * m + e] - an[p * m + e]).norm();
                    let rel = d / col_norm.max(1e-300);
                    if rel > worst {
                        worst = rel;
                        wp = (p, floor / col_norm.max(1e-300));
                    }
                    assert!(
                        d <= 1e-5 * col_norm + floor,
                        "{hold:?} k={k} f={f} param {p} entry {e}: analytic {} vs fd {}",
                        an[p * m + e],
                        fd[p * m + e]
                    );
                }
            }
            println!("{hold:?} k={k} f={f}: worst relative difference {worst:.2e} (parameter {}, rounding floor {:.1e} of the column)", wp.0, wp.1);
        }
    }
}
