//! Balanced truncation against its a-priori bound: on random stable MIMO modal systems
//! (lightly damped, 1..5000 Hz, with and without a double integrator, with a
//! feedthrough) the H-infinity error measured on a dense grid is at most
//! `2 sum(discarded Hankel singular values)`, the rigid-body part and the feedthrough
//! come back bit for bit, the full order reproduces the model, and bad requests are
//! refused with errors that say why.

use faer::Mat;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::balanced::{hinf_grid, max_sv_difference, max_sv_grid_difference};
use realize::{
    balanced_truncation, BalancedTruncation, ModalModel, PolePair, RealPole, RealizeError,
    ResponseGrid, C64,
};
use std::f64::consts::TAU;

/// A random stable `ny x nu` model: `modes` pole pairs at 1..5000 Hz (log-uniform) with
/// damping 1e-3..0.1, residues of random rank, an optional real pole, an optional double
/// integrator (with a `1/s` term too when `rigid == 2`), a random feedthrough.
fn random_model(seed: u64, ny: usize, nu: usize, modes: usize, rigid: u8) -> ModalModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut m = ModalModel::new(ny, nu);
    let rnd = |rng: &mut ChaCha8Rng| rng.random_range(-1.0..1.0);
    for _ in 0..modes {
        let f = 10f64.powf(rng.random_range(0.0..5000f64.log10()));
        let zeta = 10f64.powf(rng.random_range(-3.0..-1.0));
        let rank = rng.random_range(1..=ny.min(nu));
        let mut res = Mat::<C64>::zeros(ny, nu);
        for _ in 0..rank {
            let u: Vec<C64> = (0..ny)
                .map(|_| C64::new(rnd(&mut rng), rnd(&mut rng)))
                .collect();
            let v: Vec<f64> = (0..nu).map(|_| rnd(&mut rng)).collect();
            for i in 0..ny {
                for j in 0..nu {
                    res[(i, j)] += u[i] * v[j];
                }
            }
        }
        // a modal residue of a mechanical mode scales like 1 / w
        let scale = 1.0 / (TAU * f);
        let res = Mat::from_fn(ny, nu, |i, j| res[(i, j)] * scale);
        m.pairs.push(PolePair::from_f_zeta(f, zeta, res));
    }
    if rng.random_bool(0.5) {
        let p = -TAU * 10f64.powf(rng.random_range(0.0..3.0));
        m.real_poles.push(RealPole {
            pole: p,
            residue: Mat::from_fn(ny, nu, |_, _| rnd(&mut rng) * p.abs() * 1e-3),
        });
    }
    if rigid > 0 {
        let r1 = if rigid == 2 {
            Mat::from_fn(ny, nu, |_, _| rnd(&mut rng))
        } else {
            Mat::zeros(ny, nu)
        };
        m.rigid = vec![r1, Mat::from_fn(ny, nu, |_, _| rnd(&mut rng))];
    }
    m.feedthrough = Mat::from_fn(ny, nu, |_, _| 1e-3 * rnd(&mut rng));
    m
}

/// The stable part alone (what the bound is about, the rigid part being exact).
fn stable_part(m: &ModalModel) -> ModalModel {
    let mut s = m.clone();
    s.rigid.clear();
    s.feedthrough = Mat::zeros(m.ny, m.nu);
    s
}

/// Measured error of a reduction against its bound; asserts the rigid body and
/// feedthrough are bit for bit the original's.
fn check_reduction(m: &ModalModel, order: usize) -> Result<(f64, f64), TestCaseError> {
    let red = balanced_truncation(m, order).map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert_eq!(&red.model.rigid, &m.rigid);
    prop_assert_eq!(&red.model.feedthrough, &m.feedthrough);
    prop_assert_eq!(red.order, order);
    prop_assert_eq!(red.state_space.n_states(), order);
    let hsv = &red.hankel_singular_values;

    prop_assert!(hsv.windows(2).all(|w| w[0] >= w[1]), "HSVs not descending");
    let grid = hinf_grid(&[m, &red.model], 300);
    let top = hsv.first().copied().unwrap_or(0.0);
    // the balanced state space (what the bound is about) against the stable part
    let g_s = stable_part(m).freq_response(&grid).unwrap();
    let err_ss = max_sv_grid_difference(&g_s, &red.balanced.freq_response(&grid).unwrap()).unwrap();
    prop_assert!(
        err_ss <= red.error_bound * (1.0 + 1e-6) + 1e-10 * top,
        "order {order}: balanced state space: measured {err_ss:.6e} > bound {:.6e} (HSVs {hsv:?})",
        red.error_bound
    );
    // the modal form, rigid body and feedthrough included, within its reported
    // conversion error of that
    let err = max_sv_difference(m, &red.model, &grid).unwrap();
    prop_assert!(
        red.conversion_error <= 1e-6 * top,
        "conversion error {:.3e} of {top:.3e}",
        red.conversion_error
    );
    prop_assert!(
        err <= red.error_bound * (1.0 + 1e-6) + 2.0 * red.conversion_error + 1e-10 * top,
        "order {order}: modal: measured {err:.6e} > bound {:.6e} + 2 x conversion error {:.3e} (HSVs {hsv:?})",
        red.error_bound, red.conversion_error
    );
    // the full state-space form is the same model as the modal form (at the original
    // modes: an odd cut can leave a very slow real pole, and with integrators the
    // grid's lowest points are then numerically at a pole)
    let w: Vec<f64> = m.pairs.iter().map(|p| p.pole.norm()).collect();
    let g_ss = red.state_space.freq_response(&w).unwrap();
    let g_m = red.model.freq_response(&w).unwrap();
    for (x, y) in g_ss.values.iter().zip(&g_m.values) {
        prop_assert!(
            (x - y).norm() <= 2.0 * red.conversion_error + 1e-10 * (top + y.norm()),
            "ss {x} vs modal {y}"
        );
    }
    Ok((err, red.error_bound))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn measured_error_is_within_the_bound(
        seed in 0u64..1_000_000,
        ny in 1usize..4,
        nu in 1usize..5,
        modes in 1usize..7,
        rigid in 0u8..3,
        pick in 0.0f64..1.0,
    ) {
        let m = random_model(seed, ny, nu, modes, rigid);
        let an = BalancedTruncation::default().analyse(&m).unwrap();
        let (n_rb, n_s) = (an.rigid_order, an.stable_order);
        prop_assert_eq!(n_s, an.hankel_singular_values.len());
        prop_assert_eq!(n_rb + n_s, m.order(0.0));
        // a random order that keeps at least the rigid body (and one state)
        let lo = n_rb.max(1);
        let order = lo + ((n_rb + n_s - lo) as f64 * pick).round() as usize;
        match check_reduction(&m, order) {
            Ok(_) => {}
            // a tie or a roundoff-level value at the cut is refused, which is allowed
            Err(e) if e.to_string().contains("equal Hankel") || e.to_string().contains("roundoff level") => {}
            Err(e) => return Err(e),
        }
        // full order: the model itself, to roundoff (the balanced state space, and the
        // modal form within its conversion error of that)
        let h = &an.hankel_singular_values;
        if h.last().is_some_and(|&x| x <= 1e-12 * h[0]) {
            // HSVs spread over more than 12 decades: the full order keeps roundoff
            let e = balanced_truncation(&m, n_rb + n_s).unwrap_err().to_string();
            prop_assert!(e.contains("roundoff level"), "{}", e);
            return Ok(());
        }
        let full = balanced_truncation(&m, n_rb + n_s).unwrap();
        prop_assert_eq!(full.error_bound, 0.0);
        let grid = hinf_grid(&[&m], 100);
        let g_s = stable_part(&m).freq_response(&grid).unwrap();
        let peak = max_sv_grid_difference(&g_s, &ResponseGrid::zeros(grid.len(), m.ny, m.nu)).unwrap();
        let err_ss = max_sv_grid_difference(&g_s, &full.balanced.freq_response(&grid).unwrap()).unwrap();
        // roundoff of the balancing transformation grows with its condition, about the
        // square root of the HSVs' spread (seed 23979, 3 x 3, 4 modes: spread 1.2e8,
        // error 1.1e-10 of the peak)
        let spread = (h[0] / h[h.len() - 1]).sqrt();
        let tol = 1e-10 * (spread / 1e3).max(1.0);
        prop_assert!(
            err_ss <= tol * peak,
            "full order: balanced error {err_ss:.3e} of peak {peak:.3e} (tolerance {tol:.1e}; HSVs {h:?})"
        );
        let err = max_sv_difference(&m, &full.model, &grid).unwrap();
        prop_assert!(
            err <= 1e-10 * peak + 2.0 * full.conversion_error && full.conversion_error <= 1e-8 * peak,
            "full order: modal error {err:.3e}, conversion error {:.3e}, of peak {peak:.3e}",
            full.conversion_error
        );
    }
}

/// The two Hankel singular values of one lightly damped mode are close (their split is
/// about the damping), and the pair of the larger mode comes first; the numbers hold at
/// damping 1e-3 from 1 Hz to 5 kHz.
#[test]
fn lightly_damped_modes_from_1_hz_to_5_khz() {
    let mut m = ModalModel::new(1, 1);
    for (f, zeta) in [(1.0, 1e-3), (70.0, 1e-3), (5000.0, 1e-3)] {
        let num = Mat::from_fn(1, 1, |_, _| 1.0);
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
    }
    let an = BalancedTruncation::default().analyse(&m).unwrap();
    let h = &an.hankel_singular_values;
    assert_eq!(h.len(), 6);
    // 1/(s^2 + 2 zeta w s + w^2): H-inf norm 1/(2 zeta w^2); each mode's two HSVs sum to
    // about that, close to each other
    for (k, f) in [1.0f64, 70.0, 5000.0].iter().enumerate() {
        let w = TAU * f;
        let peak = 1.0 / (2.0 * 1e-3 * w * w);
        let (a, b) = (h[2 * k], h[2 * k + 1]);
        assert!(
            ((a + b) - peak).abs() < 0.01 * peak,
            "{f} Hz: {a:e} + {b:e} vs {peak:e}"
        );
        assert!((a - b) / a < 3e-3 && a > b, "{f} Hz: {a:e}, {b:e}");
    }
    for order in [2, 4] {
        let red = balanced_truncation(&m, order).unwrap();
        let grid = hinf_grid(&[&m, &red.model], 400);
        let err = max_sv_difference(&m, &red.model, &grid).unwrap();
        assert!(
            err <= red.error_bound * (1.0 + 1e-6),
            "{err:e} > {:e}",
            red.error_bound
        );
        // the kept modes are the original ones
        assert_eq!(red.model.pairs.len(), order / 2);
        for (p, q) in red.model.pairs.iter().zip(&m.pairs) {
            assert!(
                (p.pole - q.pole).norm() < 1e-6 * q.pole.norm(),
                "{} vs {}",
                p.pole,
                q.pole
            );
        }
        // a discarded mode's peak is the sum of its two HSVs, half its share of the
        // bound: with well separated modes the measured error is close to half the bound
        assert!(
            err > 0.45 * red.error_bound,
            "{err:e} vs {:e}",
            red.error_bound
        );
    }
}

#[test]
fn bad_requests_are_refused_with_reasons() {
    let m = random_model(7, 2, 3, 3, 1);
    let an = BalancedTruncation::default().analyse(&m).unwrap();
    let (n_rb, n_s) = (an.rigid_order, an.stable_order);
    assert_eq!(n_rb, 4, "a rank-2 double integrator: two chains of two");
    let msg = |order: usize| balanced_truncation(&m, order).unwrap_err().to_string();
    let e = msg(n_rb + n_s + 1);
    assert!(e.contains("order") && e.contains("at most"), "{e}");
    let e = msg(n_rb - 1);
    assert!(e.contains("rigid-body") && e.contains("at least 4"), "{e}");
    let e = msg(0);
    assert!(e.contains("order"), "{e}");
    // the rigid body alone is a valid reduction: the bound is twice the sum of all HSVs
    let rb = balanced_truncation(&m, n_rb).unwrap();
    assert!(rb.model.pairs.is_empty() && rb.model.real_poles.is_empty());
    assert!(
        (rb.error_bound - 2.0 * an.hankel_singular_values.iter().sum::<f64>()).abs()
            < 1e-12 * rb.error_bound
    );

    // an unstable pair, an undamped mode, a real pole at 0: named, not reduced
    for pole in [C64::new(1.0, 100.0), C64::new(0.0, 100.0)] {
        let mut u = m.clone();
        u.pairs[1].pole = pole;
        let e = balanced_truncation(&u, n_rb + 2).unwrap_err();
        assert!(matches!(e, RealizeError::Unstable { .. }), "{e}");
        assert!(e.to_string().contains("pairs[1]"), "{pole}: {e}");
    }
    let mut u = m.clone();
    u.real_poles = vec![RealPole {
        pole: 0.0,
        residue: Mat::from_fn(2, 3, |_, _| 1.0),
    }];
    let e = BalancedTruncation::default()
        .analyse(&u)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("real_poles[0]") && e.contains("left half-plane"),
        "{e}"
    );

    // two identical subsystems: equal HSVs in pairs; cutting between equal ones is refused
    let mut twin = ModalModel::new(2, 2);
    let num = Mat::from_fn(2, 2, |i, j| if i == j { 1.0 } else { 0.0 });
    twin.pairs
        .push(PolePair::from_second_order(50.0, 0.02, &num));
    let an = BalancedTruncation::default().analyse(&twin).unwrap();
    let h = &an.hankel_singular_values;
    assert!((h[0] - h[1]).abs() <= 1e-12 * h[0], "{h:?}");
    let e = balanced_truncation(&twin, 1).unwrap_err().to_string();
    assert!(e.contains("equal Hankel"), "{e}");
    let ok = balanced_truncation(&twin, 2).unwrap();
    assert!(ok.error_bound > 0.0);
}
