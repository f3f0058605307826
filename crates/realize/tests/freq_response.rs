//! State-space frequency response by Hessenberg reduction: closed forms (defective `A`
//! included), a dense-LU reference, the modal response, poles, discrete time.

mod common;

use common::{gauss, max_line_rel_err, random_modal, random_similarity, rng, Rigid, Spec};
use faer::linalg::solvers::Solve;
use faer::Mat;
use realize::{ModalModel, RealizeError, StateSpace, TimeDomain, C64};

fn ss(a: Mat<f64>, b: Mat<f64>, c: Mat<f64>, d: Mat<f64>) -> StateSpace {
    StateSpace::new(a, b, c, d, TimeDomain::Continuous).unwrap()
}

/// Double integrator plus one damped mode, in companion coordinates: `A` has a Jordan
/// block at 0. `G(s) = 1/s^2 + k / (s^2 + 2 zeta wn s + wn^2)`.
fn defective_plant(wn: f64, zeta: f64, k: f64) -> StateSpace {
    let a = Mat::from_fn(4, 4, |i, j| match (i, j) {
        (0, 1) | (2, 3) => 1.0,
        (3, 2) => -wn * wn,
        (3, 3) => -2.0 * zeta * wn,
        _ => 0.0,
    });
    let b = Mat::from_fn(4, 1, |i, _| match i {
        1 => 1.0,
        3 => k,
        _ => 0.0,
    });
    let c = Mat::from_fn(1, 4, |_, j| if j == 0 || j == 2 { 1.0 } else { 0.0 });
    ss(a, b, c, Mat::zeros(1, 1))
}

/// A random orthogonal matrix: the product of three Householder reflections.
fn random_orthogonal(n: usize, seed: u64) -> Mat<f64> {
    let mut r = rng(seed);
    let mut q = Mat::<f64>::identity(n, n);
    for _ in 0..3 {
        let v: Vec<f64> = (0..n).map(|_| gauss(&mut r)).collect();
        let vv: f64 = v.iter().map(|x| x * x).sum();
        let h = Mat::from_fn(n, n, |i, j| {
            (if i == j { 1.0 } else { 0.0 }) - 2.0 * v[i] * v[j] / vv
        });
        q = &q * &h;
    }
    q
}

#[test]
fn defective_a_matches_closed_form() {
    let (wn, zeta, k): (f64, f64, f64) = (2.0 * std::f64::consts::PI * 150.0, 2e-3, 3e4);
    let omega: Vec<f64> = (0..400)
        .map(|i| 1e-2 * (1e7f64).powf(i as f64 / 399.0))
        .chain([wn * (1.0 - zeta * zeta).sqrt(), wn])
        .collect();
    let s_of = |w: f64| C64::new(0.0, w);

    // Companion coordinates (already Hessenberg): exact to roundoff.
    let plant = defective_plant(wn, zeta, k);
    let g = plant.freq_response(&omega).unwrap();
    for (n, &w) in omega.iter().enumerate() {
        let s = s_of(w);
        let (rigid, mode) = ((s * s).inv(), k / (s * s + 2.0 * zeta * wn * s + wn * wn));
        // Relative to the size of the terms: the sum has a zero (anti-resonance).
        let err = (g.get(n, 0, 0) - (rigid + mode)).norm() / (rigid.norm() + mode.norm());
        assert!(err < 1e-11, "companion, w = {w}: rel. error {err:e}");
    }

    // Jordan block [[0, 1], [0, 0]] plus a mode in real modal coordinates, rotated by a
    // dense orthogonal similarity so that the Householder reduction has work to do and
    // the Jordan block is spread over all states. The response is then exact up to its
    // own sensitivity: a backward error eps ||A|| in the Jordan block moves the double
    // pole by sqrt(eps ||A||), a relative error ~ eps ||A|| / w^2 at low frequency.
    let wd = wn * (1.0 - zeta * zeta).sqrt();
    let a0 = Mat::from_fn(4, 4, |i, j| match (i, j) {
        (0, 1) => 1.0,
        (2, 2) | (3, 3) => -zeta * wn,
        (2, 3) => wd,
        (3, 2) => -wd,
        _ => 0.0,
    });
    let b0 = Mat::from_fn(4, 1, |i, _| match i {
        1 => 1.0,
        3 => k,
        _ => 0.0,
    });
    let c0 = Mat::from_fn(1, 4, |_, j| if j == 0 || j == 2 { 1.0 } else { 0.0 });
    let q = random_orthogonal(4, 3);
    let a = q.transpose() * &a0 * &q;
    let b = q.transpose() * &b0;
    let c = &c0 * &q;
    let rotated = ss(a, b, c, Mat::zeros(1, 1));
    let sens = f64::EPSILON * rotated.a.norm_l2();
    let g = rotated.freq_response(&omega).unwrap();
    for (n, &w) in omega.iter().enumerate() {
        let s = s_of(w);
        let (rigid, mode) = (
            (s * s).inv(),
            k * wd / (s * s + 2.0 * zeta * wn * s + wn * wn),
        );
        let err = (g.get(n, 0, 0) - (rigid + mode)).norm() / (rigid.norm() + mode.norm());
        let bound = 1e-11 + 10.0 * sens / (w * w);
        assert!(
            err < bound,
            "rotated, w = {w}: rel. error {err:e} > {bound:e}"
        );
    }
}

#[test]
fn integrator_at_zero_frequency_is_a_pole() {
    let plant = defective_plant(100.0, 0.01, 1.0);
    let err = plant.freq_response(&[1.0, 0.0, 2.0]).unwrap_err();
    assert_eq!(
        err,
        RealizeError::AtPole {
            point: 1,
            omega: 0.0
        }
    );
    // An undamped mode evaluated exactly at its frequency.
    let a = Mat::from_fn(2, 2, |i, j| match (i, j) {
        (0, 1) => 5.0,
        (1, 0) => -5.0,
        _ => 0.0,
    });
    let m = ss(
        a,
        Mat::from_fn(2, 1, |_, _| 1.0),
        Mat::from_fn(1, 2, |_, _| 1.0),
        Mat::zeros(1, 1),
    );
    assert!(matches!(
        m.freq_response(&[5.0]),
        Err(RealizeError::AtPole { point: 0, .. })
    ));
    assert!(matches!(
        m.freq_response(&[f64::NAN]),
        Err(RealizeError::NonFinite { .. })
    ));
}

/// `C (x I - A)^-1 B + D` by a dense complex LU at one point.
fn dense_reference(m: &StateSpace, x: C64) -> Mat<C64> {
    let n = m.n_states();
    let xa = Mat::from_fn(n, n, |i, j| {
        C64::new(-m.a[(i, j)], 0.0) + if i == j { x } else { C64::new(0.0, 0.0) }
    });
    let b = Mat::from_fn(n, m.nu(), |i, j| C64::new(m.b[(i, j)], 0.0));
    let c = Mat::from_fn(m.ny(), n, |i, j| C64::new(m.c[(i, j)], 0.0));
    let xb = xa.partial_piv_lu().solve(&b);
    let mut g = &c * &xb;
    for i in 0..m.ny() {
        for j in 0..m.nu() {
            g[(i, j)] += m.d[(i, j)];
        }
    }
    g
}

/// Asserts that `got(k, i, j)` is the dense reference response of `m` at every point,
/// to 1e-10 of the largest entry at that point.
fn assert_matches_dense(m: &StateSpace, points: &[C64], got: impl Fn(usize, usize, usize) -> C64) {
    let (n, ny, nu) = (m.n_states(), m.ny(), m.nu());
    for (k, &x) in points.iter().enumerate() {
        let want = dense_reference(m, x);
        let scale = (0..ny)
            .flat_map(|i| (0..nu).map(move |j| (i, j)))
            .map(|(i, j)| want[(i, j)].norm())
            .fold(0.0, f64::max);
        for i in 0..ny {
            for j in 0..nu {
                let e = (got(k, i, j) - want[(i, j)]).norm() / scale;
                assert!(e < 1e-10, "n = {n}, {ny}x{nu}, point {k}: {e:e}");
            }
        }
    }
}

#[test]
fn random_dense_models_match_dense_lu_on_both_solve_sides() {
    let mut r = rng(21);
    // (n, ny, nu): ny < nu solves for rows, ny >= nu for columns.
    for &(n, ny, nu) in &[
        (1, 1, 1),
        (2, 3, 1),
        (7, 2, 5),
        (12, 4, 13),
        (15, 6, 2),
        (30, 3, 3),
    ] {
        let a = Mat::from_fn(n, n, |_, _| gauss(&mut r));
        let b = Mat::from_fn(n, nu, |_, _| gauss(&mut r));
        let c = Mat::from_fn(ny, n, |_, _| gauss(&mut r));
        let d = Mat::from_fn(ny, nu, |_, _| gauss(&mut r));
        let m = ss(a, b, c, d);
        // Hessenberg structure of the reduced matrix.
        let hf = m.hessenberg().unwrap();
        for i in 0..n {
            for j in 0..i.saturating_sub(1) {
                assert_eq!(hf.h(i, j), 0.0);
            }
        }
        let points: Vec<C64> = (0..25)
            .map(|_| C64::new(gauss(&mut r), 3.0 * gauss(&mut r)))
            .collect();
        let g = m.freq_response_at(&points).unwrap();
        assert_matches_dense(&m, &points, |k, i, j| g.get(k, i, j));
    }
}

/// The states' response in the Hessenberg coordinates, mapped back with `C~ = C Q`,
/// is the model's response: `C~ Z(x) + D = G(x)`; with `C = I`, `C~` is orthogonal
/// and `Q Z(x)` is `(x I - A)^{-1} B` itself.
#[test]
fn states_in_hessenberg_coordinates_give_the_response() {
    let mut r = rng(33);
    for &(n, ny, nu) in &[(1, 1, 1), (9, 3, 2), (16, 2, 5), (40, 40, 8)] {
        let a = Mat::from_fn(n, n, |_, _| gauss(&mut r));
        let b = Mat::from_fn(n, nu, |_, _| gauss(&mut r));
        let c = if ny == n {
            Mat::identity(n, n)
        } else {
            Mat::from_fn(ny, n, |_, _| gauss(&mut r))
        };
        let d = Mat::from_fn(ny, nu, |_, _| gauss(&mut r));
        let m = ss(a, b, c, d);
        let hf = m.hessenberg().unwrap();
        let ct = hf.c_tilde();
        if ny == n {
            let qtq = ct.transpose() * &ct;
            for i in 0..n {
                for j in 0..n {
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((qtq[(i, j)] - want).abs() < 1e-12, "Q^T Q ({i}, {j})");
                }
            }
        }
        let points: Vec<C64> = (0..20)
            .map(|_| C64::new(gauss(&mut r), 3.0 * gauss(&mut r)))
            .collect();
        let z = hf.states_at(&points).unwrap();
        assert_eq!((z.ny, z.nu, z.len()), (n, nu, points.len()));
        assert_matches_dense(&m, &points, |k, i, j| {
            let mut g = C64::new(m.d[(i, j)], 0.0);
            for l in 0..n {
                g += z.get(k, l, j) * ct[(i, l)];
            }
            g
        });
    }
    // a pole is an error, not a NaN
    let m = ss(
        Mat::from_fn(1, 1, |_, _| 0.0),
        Mat::from_fn(1, 1, |_, _| 1.0),
        Mat::from_fn(1, 1, |_, _| 1.0),
        Mat::from_fn(1, 1, |_, _| 0.0),
    );
    let err = m
        .hessenberg()
        .unwrap()
        .states_at(&[C64::new(0.0, 1.0), C64::new(0.0, 0.0)])
        .unwrap_err();
    assert!(
        matches!(err, RealizeError::AtPole { point: 1, .. }),
        "{err}"
    );
}

#[test]
fn modal_and_state_space_responses_agree_for_wide_and_tall_systems() {
    for (seed, ny, nu) in [(1, 4, 13), (2, 13, 4), (3, 1, 1), (4, 3, 3)] {
        let spec = Spec {
            ny,
            nu,
            pairs: 6,
            real_poles: 1,
            rigid: Rigid::Mass,
            feedthrough: true,
            w_lo: 10.0,
            w_hi: 1e4,
        };
        let (m, order) = random_modal(seed, spec);
        let s = m.to_state_space(1e-12).unwrap();
        assert_eq!(s.n_states(), order);
        let omega = common::grid_with_peaks(&m, 0.5, 3e4, 300);
        let gm = m.freq_response(&omega).unwrap();
        let gs = s.freq_response(&omega).unwrap();
        let e = max_line_rel_err(&gs, &gm);
        assert!(e < 1e-9, "{ny}x{nu}: {e:e}");
        // A dense similarity of the block-diagonal realization changes nothing.
        let gd = random_similarity(&s, seed).freq_response(&omega).unwrap();
        let e = max_line_rel_err(&gd, &gm);
        assert!(e < 1e-8, "{ny}x{nu} after similarity: {e:e}");
    }
}

#[test]
fn off_axis_points_match_modal_evaluation() {
    let spec = Spec {
        ny: 2,
        nu: 3,
        pairs: 3,
        real_poles: 1,
        rigid: Rigid::General,
        feedthrough: true,
        w_lo: 1.0,
        w_hi: 100.0,
    };
    let (m, _) = random_modal(5, spec);
    let s = m.to_state_space(0.0).unwrap();
    let points: Vec<C64> = (1..40)
        .map(|k| C64::new(0.3 * (k as f64).sin(), 0.5 * k as f64))
        .collect();
    let g = s.freq_response_at(&points).unwrap();
    let mut want = vec![C64::new(0.0, 0.0); 6];
    for (k, &x) in points.iter().enumerate() {
        m.eval_s_into(x, &mut want);
        let scale = want.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for (a, b) in g.line(k).iter().zip(&want) {
            assert!((a - b).norm() < 1e-10 * scale, "point {x}");
        }
    }
}

#[test]
fn discrete_double_integrator_matches_z_transform() {
    // Ad = [[1, T], [0, 1]], Bd = [T^2/2, T], C = [1, 0]: H(z) = T^2 (z+1) / (2 (z-1)^2).
    let t = 1e-3;
    let a = Mat::from_fn(2, 2, |i, j| match (i, j) {
        (0, 0) | (1, 1) => 1.0,
        (0, 1) => t,
        _ => 0.0,
    });
    let b = Mat::from_fn(2, 1, |i, _| if i == 0 { t * t / 2.0 } else { t });
    let c = Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { 0.0 });
    let m = StateSpace::new(a, b, c, Mat::zeros(1, 1), TimeDomain::Discrete { ts: t }).unwrap();
    let omega: Vec<f64> = (1..200).map(|k| k as f64 * 15.0).collect();
    let g = m.freq_response(&omega).unwrap();
    for (k, &w) in omega.iter().enumerate() {
        let z = C64::from_polar(1.0, w * t);
        let want = (z + 1.0) * t * t / (2.0 * (z - 1.0) * (z - 1.0));
        let e = (g.get(k, 0, 0) - want).norm() / want.norm();
        assert!(e < 1e-11, "w = {w}: {e:e}");
    }
    // z = 1 (w = 0) and z = 1 again at w = 2 pi / T are poles.
    assert!(matches!(
        m.freq_response(&[0.0]),
        Err(RealizeError::AtPole { point: 0, .. })
    ));
}

#[test]
fn empty_state_gives_feedthrough() {
    let d = Mat::from_fn(2, 3, |i, j| (i + 10 * j) as f64);
    let m = ss(
        Mat::zeros(0, 0),
        Mat::zeros(0, 3),
        Mat::zeros(2, 0),
        d.clone(),
    );
    let g = m.freq_response(&[0.0, 1.0]).unwrap();
    for k in 0..2 {
        for i in 0..2 {
            for j in 0..3 {
                assert_eq!(g.get(k, i, j), C64::new(d[(i, j)], 0.0));
            }
        }
    }
    // Same from the (empty) modal model.
    let mut mm = ModalModel::new(2, 3);
    mm.feedthrough = d;
    assert_eq!(mm.to_state_space(0.0).unwrap().n_states(), 0);
}

#[test]
fn inconsistent_public_fields_are_errors_not_panics() {
    // The fields are public: a model assembled by hand with mismatched shapes.
    let bad = StateSpace {
        a: Mat::zeros(3, 3),
        b: Mat::zeros(2, 1),
        c: Mat::zeros(1, 3),
        d: Mat::zeros(1, 1),
        domain: TimeDomain::Continuous,
    };
    for r in [
        bad.freq_response(&[1.0]).map(|_| ()),
        bad.freq_response_at(&[C64::new(0.0, 1.0)]).map(|_| ()),
        bad.discretize_zoh(0.1).map(|_| ()),
        bad.to_modal().map(|_| ()),
        bad.hessenberg().map(|_| ()),
    ] {
        assert!(matches!(r, Err(RealizeError::Dimension { .. })), "{r:?}");
    }
    let mut m = ModalModel::new(2, 2);
    m.rigid = vec![Mat::zeros(2, 2), Mat::from_fn(3, 1, |_, _| 1.0)];
    assert!(matches!(
        m.freq_response(&[1.0]),
        Err(RealizeError::Dimension { .. })
    ));
    assert!(matches!(
        m.zoh_response(&[1.0], 1e-3, 0.0),
        Err(RealizeError::Dimension { .. })
    ));
    // `order` and `reduce_rank` are infallible and must not panic either.
    let _ = m.order(0.0);
    let _ = m.reduce_rank(0.0);
}
