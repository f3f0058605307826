//! Exact zero-order-hold discretization (augmented matrix exponential) against closed
//! forms, and against the closed-form modal ZOH response.

mod common;

use common::{max_line_rel_err, random_modal, Rigid, Spec};
use faer::Mat;
use proptest::prelude::*;
use realize::{RealizeError, StateSpace, TimeDomain, C64};

fn continuous(a: Mat<f64>, b: Mat<f64>, c: Mat<f64>) -> StateSpace {
    let (ny, nu) = (c.nrows(), b.ncols());
    StateSpace::new(a, b, c, Mat::zeros(ny, nu), TimeDomain::Continuous).unwrap()
}

#[test]
fn double_integrator_closed_form() {
    let a = Mat::from_fn(2, 2, |i, j| if (i, j) == (0, 1) { 1.0 } else { 0.0 });
    let b = Mat::from_fn(2, 1, |i, _| if i == 1 { 1.0 } else { 0.0 });
    let c = Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { 0.0 });
    let sys = continuous(a, b, c);
    for t in [1e-4, 1e-2, 1.0, 37.0] {
        let d = sys.discretize_zoh(t).unwrap();
        assert_eq!(d.domain, TimeDomain::Discrete { ts: t });
        let want_a = [[1.0, t], [0.0, 1.0]];
        let want_b = [t * t / 2.0, t];
        for i in 0..2 {
            for j in 0..2 {
                let e = (d.a[(i, j)] - want_a[i][j]).abs();
                assert!(
                    e <= 4.0 * f64::EPSILON * want_a[i][j].abs(),
                    "T = {t}: Ad[{i},{j}]"
                );
            }
            let e = (d.b[(i, 0)] - want_b[i]).abs() / want_b[i];
            assert!(e <= 4.0 * f64::EPSILON, "T = {t}: Bd[{i}] rel. error {e:e}");
        }
        assert_eq!(d.c, sys.c);
        assert_eq!(d.d, sys.d);
    }
}

#[test]
fn damped_mode_closed_form() {
    // x' = [[s, w], [-w, s]] x + [0; 1] u: Ad = e^{sT} R(wT), Bd = A^{-1} (Ad - I) B.
    let (s, w) = (-0.02 * 300.0, 300.0);
    let a = Mat::from_fn(2, 2, |i, j| match (i, j) {
        (0, 0) | (1, 1) => s,
        (0, 1) => w,
        _ => -w,
    });
    let b = Mat::from_fn(2, 1, |i, _| if i == 1 { 1.0 } else { 0.0 });
    let sys = continuous(a, b, Mat::from_fn(1, 2, |_, _| 1.0));
    for t in [1e-4, 1e-3, 2e-2, 0.5] {
        let d = sys.discretize_zoh(t).unwrap();
        let g = f64::exp(s * t);
        let (c, sn) = (f64::cos(w * t), f64::sin(w * t));
        let ad = [[g * c, g * sn], [-g * sn, g * c]];
        // A^{-1} = [[s, -w], [w, s]] / (s^2 + w^2); (Ad - I) B = [Ad01; Ad11 - 1].
        let m = [ad[0][1], ad[1][1] - 1.0];
        let det = s * s + w * w;
        let bd = [(s * m[0] - w * m[1]) / det, (w * m[0] + s * m[1]) / det];
        for i in 0..2 {
            for j in 0..2 {
                let e = (d.a[(i, j)] - ad[i][j]).abs();
                assert!(e < 1e-14, "T = {t}: Ad[{i},{j}] error {e:e}");
            }
            let e = (d.b[(i, 0)] - bd[i]).abs() / bd[0].abs().max(bd[1].abs());
            assert!(e < 1e-12, "T = {t}: Bd[{i}] rel. error {e:e}");
        }
    }
}

#[test]
fn modal_closed_form_equals_discretized_state_space() {
    let ts = 1e-3;
    let cases = [
        (1u64, 1, 1, Rigid::Mass, 0),
        (2, 4, 13, Rigid::Mass, 1),
        (3, 3, 2, Rigid::General, 0),
        (4, 2, 4, Rigid::None, 2),
        (5, 4, 4, Rigid::General, 1),
        (6, 3, 1, Rigid::Mass, 3),
    ];
    for (seed, ny, nu, rigid, delay) in cases {
        let spec = Spec {
            ny,
            nu,
            pairs: 5,
            real_poles: (seed % 2) as usize,
            rigid,
            feedthrough: seed % 3 == 0,
            // Up to |p ts| = 3: modes near and above Nyquist (pi / ts) alias.
            w_lo: 5.0,
            w_hi: 3000.0,
        };
        let (m, _) = random_modal(seed, spec);
        let omega: Vec<f64> = (1..=600).map(|k| k as f64 * 5.2).collect();
        let gm = m.zoh_response(&omega, ts, delay as f64).unwrap();
        let s = m.to_state_space(1e-12).unwrap();
        let gs = s.zoh_response(&omega, ts, delay).unwrap();
        let e = max_line_rel_err(&gs, &gm);
        assert!(e < 1e-10, "seed {seed} ({ny}x{nu}, {rigid:?}): {e:e}");
    }
}

#[test]
fn delay_multiplies_by_z_to_the_minus_d() {
    let spec = Spec {
        ny: 2,
        nu: 2,
        pairs: 2,
        real_poles: 0,
        rigid: Rigid::Mass,
        feedthrough: true,
        w_lo: 10.0,
        w_hi: 500.0,
    };
    let s = random_modal(9, spec).0.to_state_space(0.0).unwrap();
    let ts = 2e-3;
    let omega = [3.0, 40.0, 700.0, 1500.0];
    let g0 = s.zoh_response(&omega, ts, 0).unwrap();
    let g3 = s.zoh_response(&omega, ts, 3).unwrap();
    for (k, &w) in omega.iter().enumerate() {
        let f = C64::from_polar(1.0, -3.0 * w * ts);
        for (a, b) in g3.line(k).iter().zip(g0.line(k)) {
            assert!((a - b * f).norm() <= 1e-15 * b.norm());
        }
    }
    // The discretized model evaluated directly is the d = 0 response.
    let d = s.discretize_zoh(ts).unwrap();
    assert_eq!(d.freq_response(&omega).unwrap(), g0);
}

#[test]
fn rejects_bad_sample_time_and_discrete_input() {
    let s = continuous(
        Mat::from_fn(1, 1, |_, _| -1.0),
        Mat::from_fn(1, 1, |_, _| 1.0),
        Mat::from_fn(1, 1, |_, _| 1.0),
    );
    for ts in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            s.discretize_zoh(ts),
            Err(RealizeError::InvalidParameter { .. })
        ));
    }
    let d = s.discretize_zoh(0.1).unwrap();
    assert!(matches!(
        d.discretize_zoh(0.1),
        Err(RealizeError::WrongDomain { .. })
    ));
    assert!(matches!(
        d.zoh_response(&[1.0], 0.1, 1),
        Err(RealizeError::WrongDomain { .. })
    ));
    // A discrete first-order lag e^{-T}: pole at z = e^{-0.1}, gain (1 - e^{-T}).
    let z = C64::from_polar(1.0, 0.3);
    let want = (1.0 - f64::exp(-0.1)) / (z - f64::exp(-0.1));
    let got = d.freq_response(&[3.0]).unwrap().get(0, 0, 0);
    assert!((got - want).norm() < 1e-15 * want.norm());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Random systems and sample times: closed-form modal ZOH = discretized state space.
    #[test]
    fn modal_zoh_equals_state_space_zoh(
        seed in any::<u64>(),
        ny in 1usize..4,
        nu in 1usize..5,
        pairs in 1usize..=5,
        real_poles in 0usize..=2,
        rigid in prop_oneof![Just(Rigid::None), Just(Rigid::Mass), Just(Rigid::General)],
        // |p| ts between 1e-3 and 3 for the fastest pole.
        ts_scale in 1e-3f64..3.0,
        delay in 0usize..3,
    ) {
        let spec = Spec { ny, nu, pairs, real_poles, rigid, feedthrough: seed % 2 == 0, w_lo: 1.0, w_hi: 1000.0 };
        let (m, _) = random_modal(seed, spec);
        let ts = ts_scale / 1000.0;
        let nyquist = std::f64::consts::PI / ts;
        let omega: Vec<f64> = (1..=200).map(|k| nyquist * k as f64 / 201.0).collect();
        let gm = m.zoh_response(&omega, ts, delay as f64).unwrap();
        let gs = m.to_state_space(1e-12).unwrap().zoh_response(&omega, ts, delay).unwrap();
        let e = max_line_rel_err(&gs, &gm);
        prop_assert!(e < 1e-10, "ts = {:e}: rel. error {:e}", ts, e);
    }
}
