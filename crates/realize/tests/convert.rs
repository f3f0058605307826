//! ModalModel <-> StateSpace conversions: random stable modal systems realized in real
//! block-diagonal form (property test), minimal orders, rank reduction, and the modal
//! decomposition of state-space models with integrators (defective `A`).

mod common;

use common::{
    gauss, grid_with_peaks, max_line_rel_err, random_complex_rank, random_modal, random_similarity,
    rng, Rigid, Spec,
};
use faer::Mat;
use proptest::prelude::*;
use realize::{ModalModel, PolePair, RealizeError, StateSpace, TimeDomain, C64};

fn rigid_strategy() -> impl Strategy<Value = Rigid> {
    prop_oneof![Just(Rigid::None), Just(Rigid::Mass), Just(Rigid::General)]
}

fn spec_strategy() -> impl Strategy<Value = (u64, Spec)> {
    (
        any::<u64>(),
        1usize..4,
        1usize..5,
        1usize..=5,
        0usize..=2,
        rigid_strategy(),
        any::<bool>(),
    )
        .prop_map(|(seed, ny, nu, pairs, real_poles, rigid, feedthrough)| {
            (
                seed,
                Spec {
                    ny,
                    nu,
                    pairs,
                    real_poles,
                    rigid,
                    feedthrough,
                    w_lo: 1.0,
                    w_hi: 1000.0,
                },
            )
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// The real block-diagonal realization has the minimal order and the modal response.
    #[test]
    fn state_space_realization_reproduces_modal_response((seed, spec) in spec_strategy()) {
        let (m, order) = random_modal(seed, spec);
        let s = m.to_state_space(1e-12).unwrap();
        prop_assert_eq!(s.n_states(), order);
        prop_assert_eq!(m.order(1e-12), order);
        let omega = grid_with_peaks(&m, 0.05, 2e4, 150);
        let gm = m.freq_response(&omega).unwrap();
        let gs = s.freq_response(&omega).unwrap();
        let e = max_line_rel_err(&gs, &gm);
        prop_assert!(e < 1e-9, "rel. error {:e}", e);
    }

    /// ModalModel -> StateSpace -> ModalModel keeps the response and the poles.
    #[test]
    fn modal_round_trip((seed, spec) in spec_strategy()) {
        let (m, _) = random_modal(seed, spec);
        let s = m.to_state_space(1e-12).unwrap();
        let back = s.to_modal().unwrap();
        prop_assert_eq!(back.pairs.len(), m.pairs.len());
        prop_assert_eq!(back.real_poles.len(), m.real_poles.len());
        let rigid_len = match spec.rigid { Rigid::None => 0, Rigid::Mass => 2, Rigid::General => 3 };
        prop_assert_eq!(back.rigid.len(), rigid_len);
        for p in &m.pairs {
            let closest = back.pairs.iter().map(|q| (q.pole - p.pole).norm()).fold(f64::INFINITY, f64::min);
            prop_assert!(closest < 1e-12 * p.pole.norm());
        }
        let omega = grid_with_peaks(&m, 0.05, 2e4, 150);
        let gm = m.freq_response(&omega).unwrap();
        let gb = back.freq_response(&omega).unwrap();
        let e = max_line_rel_err(&gb, &gm);
        prop_assert!(e < 1e-9, "rel. error {:e}", e);
    }
}

#[test]
fn to_modal_of_dense_similarity() {
    // The block structure is destroyed by a dense similarity; the modal form comes back.
    for (seed, rigid) in [
        (1u64, Rigid::Mass),
        (2, Rigid::General),
        (3, Rigid::None),
        (4, Rigid::Mass),
    ] {
        let spec = Spec {
            ny: 3,
            nu: 4,
            pairs: 4,
            real_poles: 1,
            rigid,
            feedthrough: true,
            w_lo: 10.0,
            w_hi: 1000.0,
        };
        let (m, _) = random_modal(seed, spec);
        let dense = random_similarity(&m.to_state_space(1e-12).unwrap(), seed + 100);
        let back = dense.to_modal().unwrap();
        assert_eq!(back.pairs.len(), 4);
        assert_eq!(back.real_poles.len(), 1);
        let omega = grid_with_peaks(&m, 0.5, 2e4, 200);
        let e = max_line_rel_err(
            &back.freq_response(&omega).unwrap(),
            &m.freq_response(&omega).unwrap(),
        );
        assert!(e < 1e-8, "seed {seed} ({rigid:?}): {e:e}");
        // The rigid-body coefficients themselves, relative to the largest.
        let scale = m.rigid.iter().map(|r| r.norm_l2()).fold(0.0, f64::max);
        for k in 0..m.rigid.len().max(back.rigid.len()) {
            let want = m.rigid.get(k).cloned().unwrap_or_else(|| Mat::zeros(3, 4));
            let got = back
                .rigid
                .get(k)
                .cloned()
                .unwrap_or_else(|| Mat::zeros(3, 4));
            let e = (&got - &want).norm_l2() / scale;
            assert!(e < 1e-7, "seed {seed}: rigid[{k}] error {e:e}");
        }
    }
}

#[test]
fn double_integrator_and_triple_integrator_chains() {
    // y = 2/s^2 u1 - 1/s^3 u2 in chain coordinates, plus a mode; A is defective with
    // Jordan blocks of sizes 2 and 3 at zero.
    let n = 7;
    let mut a = Mat::<f64>::zeros(n, n);
    a[(0, 1)] = 1.0;
    a[(2, 3)] = 1.0;
    a[(3, 4)] = 1.0;
    a[(5, 5)] = -3.0;
    a[(6, 6)] = -3.0;
    a[(5, 6)] = 200.0;
    a[(6, 5)] = -200.0;
    let mut b = Mat::<f64>::zeros(n, 2);
    b[(1, 0)] = 2.0;
    b[(4, 1)] = -1.0;
    b[(6, 0)] = 1.0;
    let mut c = Mat::<f64>::zeros(1, n);
    c[(0, 0)] = 1.0;
    c[(0, 2)] = 1.0;
    c[(0, 5)] = 1.0;
    let s = StateSpace::new(a, b, c, Mat::zeros(1, 2), TimeDomain::Continuous).unwrap();
    let m = s.to_modal().unwrap();
    assert_eq!(m.rigid.len(), 3);
    let want = [[0.0, 0.0], [2.0, 0.0], [0.0, -1.0]];
    for (k, row) in want.iter().enumerate() {
        for j in 0..2 {
            assert!(
                (m.rigid[k][(0, j)] - row[j]).abs() < 1e-12,
                "rigid[{k}][{j}]"
            );
        }
    }
    assert_eq!(m.pairs.len(), 1);
    assert!((m.pairs[0].pole - C64::new(-3.0, 200.0)).norm() < 1e-12);
    // Residue of [[s, w], [-w, s]] from b = [0; 1], c = [1, 0]: w / ((s-sigma)^2 + w^2)
    // = (1/2j) (1/(s-p) - 1/(s-conj p)), so R = -j/2.
    assert!((m.pairs[0].residue[(0, 0)] - C64::new(0.0, -0.5)).norm() < 1e-12);
    assert!(m.pairs[0].residue[(0, 1)].norm() < 1e-12);
    // And the same after a dense similarity (the Jordan blocks are then hidden).
    let m2 = random_similarity(&s, 5).to_modal().unwrap();
    let omega: Vec<f64> = (0..100).map(|k| 0.1 * 1.1f64.powi(k)).collect();
    let e = max_line_rel_err(
        &m2.freq_response(&omega).unwrap(),
        &s.freq_response(&omega).unwrap(),
    );
    assert!(e < 1e-8, "{e:e}");
    // The minimal realization of the recovered modal model: chains are not applicable
    // (two different powers); with one output, [2/s^2, -1/s^3] = [2s, -1]/s^3 has
    // McMillan degree 3 (the Hankel rank), plus 2 for the mode: the 7-state chain form
    // above was not minimal.
    assert_eq!(m.order(1e-9), 5);
    let back = m.to_state_space(1e-9).unwrap();
    let e = max_line_rel_err(
        &back.freq_response(&omega).unwrap(),
        &s.freq_response(&omega).unwrap(),
    );
    assert!(e < 1e-9, "{e:e}");
}

#[test]
fn rigid_mass_is_realized_by_double_integrator_chains() {
    let mut r = rng(4);
    let (ny, nu) = (4, 6);
    let r2 = common::random_real_rank(&mut r, ny, nu, 3);
    let mut m = ModalModel::new(ny, nu);
    m.rigid = vec![Mat::zeros(ny, nu), r2];
    let s = m.to_state_space(1e-10).unwrap();
    assert_eq!(s.n_states(), 6);
    // Three chains [[0, 1], [0, 0]], nothing else in A; C B = 0 exactly.
    for i in 0..6 {
        for j in 0..6 {
            let want = if i % 2 == 0 && j == i + 1 { 1.0 } else { 0.0 };
            assert_eq!(s.a[(i, j)], want);
        }
    }
    let cb = &s.c * &s.b;
    assert_eq!(cb.norm_l2(), 0.0);
    let cab = &s.c * &s.a * &s.b;
    assert!((&cab - &m.rigid[1]).norm_l2() < 1e-13 * m.rigid[1].norm_l2());
}

#[test]
fn reduce_rank_truncates_residues() {
    let mut r = rng(8);
    let (ny, nu) = (3, 5);
    let base = random_complex_rank(&mut r, ny, nu, 2);
    let noise = Mat::from_fn(ny, nu, |_, _| {
        C64::new(gauss(&mut r), gauss(&mut r)) * 1e-11
    });
    let mut m = ModalModel::new(ny, nu);
    m.pairs.push(PolePair {
        pole: C64::new(-1.0, 100.0),
        residue: &base + &noise,
    });
    assert_eq!(m.order(0.0), 2 * 3);
    assert_eq!(m.order(1e-8), 2 * 2);
    let red = m.reduce_rank(1e-8);
    assert_eq!(red.order(0.0), 2 * 2);
    let e = (&red.pairs[0].residue - &base).norm_l2() / base.norm_l2();
    assert!(e < 1e-10, "{e:e}");
    // The reduced-rank realization is the realization of the reduced model.
    let omega = [10.0, 99.0, 100.0, 300.0];
    let a = m
        .to_state_space(1e-8)
        .unwrap()
        .freq_response(&omega)
        .unwrap();
    let b = red.freq_response(&omega).unwrap();
    assert!(max_line_rel_err(&a, &b) < 1e-12);
}

#[test]
fn rejects_bad_arguments() {
    let m = ModalModel::new(1, 1);
    assert!(matches!(
        m.to_state_space(-1.0),
        Err(RealizeError::InvalidParameter { .. })
    ));
    let mut bad = ModalModel::new(2, 2);
    bad.rigid = vec![Mat::zeros(2, 3)];
    assert!(matches!(
        bad.to_state_space(0.0),
        Err(RealizeError::Dimension { .. })
    ));
    let d = StateSpace::new(
        Mat::from_fn(1, 1, |_, _| 0.5),
        Mat::from_fn(1, 1, |_, _| 1.0),
        Mat::from_fn(1, 1, |_, _| 1.0),
        Mat::zeros(1, 1),
        TimeDomain::Discrete { ts: 0.1 },
    )
    .unwrap();
    assert!(matches!(
        d.to_modal(),
        Err(RealizeError::WrongDomain { .. })
    ));
    // A defective nonzero eigenvalue (Jordan block at -1) is outside the assumption.
    let j = StateSpace::new(
        Mat::from_fn(2, 2, |i, jj| match (i, jj) {
            (0, 0) | (1, 1) => -1.0,
            (0, 1) => 1.0,
            _ => 0.0,
        }),
        Mat::from_fn(2, 1, |_, _| 1.0),
        Mat::from_fn(1, 2, |_, _| 1.0),
        Mat::zeros(1, 1),
        TimeDomain::Continuous,
    )
    .unwrap();
    assert!(matches!(j.to_modal(), Err(RealizeError::Numerical { .. })));
}

#[test]
fn repeated_modes_after_dense_similarity() {
    // A rank-3 residue realizes as three identical 2 x 2 blocks (a triple, semisimple
    // eigenvalue pair) and a rank-2 real residue as a double real pole. After a dense
    // similarity single eigenvectors of these are ill-defined; the null-space bases
    // recover one pole pair and one real pole with the full-rank residues.
    let mut r = rng(31);
    let (ny, nu) = (3, 4);
    let mut m = ModalModel::new(ny, nu);
    m.rigid = vec![
        Mat::zeros(ny, nu),
        common::random_real_rank(&mut r, ny, nu, 2),
    ];
    m.pairs.push(PolePair {
        pole: C64::new(-0.5, 40.0),
        residue: random_complex_rank(&mut r, ny, nu, 3),
    });
    m.pairs.push(PolePair {
        pole: C64::new(-2.0, 90.0),
        residue: random_complex_rank(&mut r, ny, nu, 1),
    });
    m.real_poles.push(realize::RealPole {
        pole: -25.0,
        residue: common::random_real_rank(&mut r, ny, nu, 2),
    });
    let s = m.to_state_space(1e-12).unwrap();
    assert_eq!(s.n_states(), 4 + 6 + 2 + 2);
    let back = random_similarity(&s, 77).to_modal().unwrap();
    assert_eq!(back.pairs.len(), 2);
    assert_eq!(back.real_poles.len(), 1);
    for p in &m.pairs {
        let q = back
            .pairs
            .iter()
            .find(|q| (q.pole - p.pole).norm() < 1e-9 * p.pole.norm())
            .expect("pole recovered");
        let e = (&q.residue - &p.residue).norm_l2() / p.residue.norm_l2();
        assert!(e < 1e-8, "residue of {}: {e:e}", p.pole);
    }
    let e = (&back.real_poles[0].residue - &m.real_poles[0].residue).norm_l2()
        / m.real_poles[0].residue.norm_l2();
    assert!(e < 1e-8, "real residue: {e:e}");
    assert_eq!(back.order(1e-8), s.n_states());
}
