//! Structured singular value bounds against cases with known values (one full block,
//! rank-one matrices, diagonal matrices, structures of at most three blocks) and the
//! certificates of the lower bound, on random matrices and block structures.

use faer::Mat;
use frf_data::C64;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use validation::{generalized_mu_bounds, mu_bounds, Block, BlockStructure, MuBounds, MuConfig};

fn cmat(rng: &mut ChaCha8Rng, r: usize, c: usize) -> Mat<C64> {
    Mat::from_fn(r, c, |_, _| {
        C64::new(
            rng.random::<f64>() * 2.0 - 1.0,
            rng.random::<f64>() * 2.0 - 1.0,
        )
    })
}

fn sigma_max(m: &Mat<C64>) -> f64 {
    m.singular_values().unwrap()[0]
}

fn structure(rng: &mut ChaCha8Rng, nblocks: usize) -> BlockStructure {
    BlockStructure::new(
        (0..nblocks)
            .map(|_| {
                if rng.random::<f64>() < 0.5 {
                    Block::Scalar
                } else {
                    Block::Full {
                        rows: rng.random_range(1..4),
                        cols: rng.random_range(1..4),
                    }
                }
            })
            .collect(),
    )
}

/// `x = Delta M x`, `N x = 0`, `sigma_max(Delta_i) <= 1 / lower`: the lower bound's
/// certificate is an exact kernel vector of the implicit LFT.
fn check_certificate(m: &Mat<C64>, n: Option<&Mat<C64>>, s: &BlockStructure, b: &MuBounds) {
    if b.lower == 0.0 {
        return;
    }
    let x = Mat::from_fn(b.x.len(), 1, |i, _| b.x[i]);
    let y = m * &x;
    let (mut ro, mut co) = (0, 0);
    for (blk, d) in s.blocks.iter().zip(&b.delta) {
        let (r, c) = blk.dims();
        assert!(sigma_max(d) <= (1.0 / b.lower) * (1.0 + 1e-9));
        let yi = Mat::from_fn(c, 1, |i, _| y[(co + i, 0)]);
        let dx = d * &yi;
        for i in 0..r {
            assert!(
                (dx[(i, 0)] - x[(ro + i, 0)]).norm() < 1e-9,
                "x != Delta M x"
            );
        }
        ro += r;
        co += c;
    }
    if let Some(n) = n {
        let nx = n * &x;
        for i in 0..nx.nrows() {
            assert!(nx[(i, 0)].norm() < 1e-8 * (1.0 + sigma_max(n)), "N x != 0");
        }
    }
}

#[test]
fn one_full_block_is_the_largest_singular_value() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for (r, c) in [(1, 1), (3, 3), (2, 5), (5, 2)] {
        let m = cmat(&mut rng, c, r);
        let s = BlockStructure::new(vec![Block::Full { rows: r, cols: c }]);
        let b = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
        let sv = sigma_max(&m);
        assert!((b.upper - sv).abs() < 1e-9 * sv, "{} vs {sv}", b.upper);
        assert!((b.lower - sv).abs() < 1e-6 * sv, "{} vs {sv}", b.lower);
        check_certificate(&m, None, &s, &b);
    }
}

#[test]
fn scalar_blocks_of_a_diagonal_matrix_give_the_largest_diagonal_entry() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for n in 1..6 {
        let m = Mat::from_fn(n, n, |i, j| {
            if i == j {
                C64::new(rng.random::<f64>() * 4.0 - 2.0, rng.random::<f64>())
            } else {
                C64::new(0.0, 0.0)
            }
        });
        let exact = (0..n).map(|i| m[(i, i)].norm()).fold(0.0, f64::max);
        let s = BlockStructure::new(vec![Block::Scalar; n]);
        let b = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
        assert!(
            (b.upper - exact).abs() < 1e-6 * exact,
            "{} vs {exact}",
            b.upper
        );
        assert!(
            (b.lower - exact).abs() < 1e-6 * exact,
            "{} vs {exact}",
            b.lower
        );
    }
}

/// A fixed example of the paper's kind: `M` = a rank-one matrix with three scalar blocks,
/// `mu = sum_i |a_i| |b_i|` (Packard and Doyle 1993, rank-one case).
#[test]
fn rank_one_closed_form_example() {
    let a = [C64::new(1.0, 1.0), C64::new(-2.0, 0.5), C64::new(0.3, 0.0)];
    let bb = [C64::new(0.5, 0.0), C64::new(0.0, 1.0), C64::new(-1.0, 2.0)];
    let m = Mat::from_fn(3, 3, |i, j| a[i] * bb[j].conj());
    let exact: f64 = (0..3).map(|i| a[i].norm() * bb[i].norm()).sum();
    let s = BlockStructure::new(vec![Block::Scalar; 3]);
    let b = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
    assert!(
        (b.upper - exact).abs() < 1e-6 * exact,
        "{} vs {exact}",
        b.upper
    );
    assert!(
        (b.lower - exact).abs() < 1e-6 * exact,
        "{} vs {exact}",
        b.lower
    );
    // sigma_max(M) = |a| |b| is a strictly worse (larger) bound
    assert!(sigma_max(&m) > 1.2 * exact);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// upper >= lower on random matrices and structures, upper <= sigma_max(M) (D = I),
    /// and the lower bound's certificate is exact.
    #[test]
    fn upper_bounds_lower_on_random_structures(seed in 0u64..10_000, nb in 1usize..6) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let s = structure(&mut rng, nb);
        let m = cmat(&mut rng, s.n_cols(), s.n_rows());
        let b = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
        prop_assert!(b.upper >= b.lower * (1.0 - 1e-9), "upper {} < lower {}", b.upper, b.lower);
        prop_assert!(b.upper <= sigma_max(&m) * (1.0 + 1e-9));
        prop_assert!(b.lower > 0.0);
        check_certificate(&m, None, &s, &b);
    }

    /// Rank-one `M = a b^H`: `mu = sum_i |a_i| |b_i|` for any structure of full and
    /// scalar blocks; both bounds reach it.
    #[test]
    fn rank_one_matrices_are_tight(seed in 0u64..10_000, nb in 1usize..6) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let s = structure(&mut rng, nb);
        let a = cmat(&mut rng, s.n_cols(), 1);
        let bv = cmat(&mut rng, s.n_rows(), 1);
        let m = &a * bv.adjoint();
        let (mut ro, mut co) = (0, 0);
        let mut exact = 0.0;
        for blk in &s.blocks {
            let (r, c) = blk.dims();
            let na: f64 = (0..c).map(|i| a[(co + i, 0)].norm_sqr()).sum::<f64>().sqrt();
            let nbv: f64 = (0..r).map(|i| bv[(ro + i, 0)].norm_sqr()).sum::<f64>().sqrt();
            exact += na * nbv;
            ro += r;
            co += c;
        }
        let b = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
        prop_assert!((b.upper - exact).abs() < 1e-5 * exact, "upper {} exact {exact}", b.upper);
        prop_assert!((b.lower - exact).abs() < 1e-5 * exact, "lower {} exact {exact}", b.lower);
    }

    /// At most three blocks (only full and non-repeated scalar blocks): the D-scaled
    /// upper bound equals mu, and the lower bound meets it.
    #[test]
    fn up_to_three_blocks_are_tight(seed in 0u64..10_000, nb in 1usize..4) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let s = structure(&mut rng, nb);
        let m = cmat(&mut rng, s.n_cols(), s.n_rows());
        let b = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
        prop_assert!(b.lower >= b.upper * (1.0 - 1e-4), "lower {} upper {}", b.lower, b.upper);
    }

    /// The generalized mu with a constraint `N x = 0`: bounds ordered, certificate exact,
    /// and never above the unconstrained mu's upper bound... (the constraint can only
    /// remove kernel vectors: generalized mu <= standard mu <= its upper bound).
    #[test]
    fn generalized_bounds_on_random_implicit_lfts(seed in 0u64..10_000, nb in 2usize..6, nrows in 0usize..3) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let s = structure(&mut rng, nb);
        let nrows = nrows.min(s.n_rows() - 1);
        let m = cmat(&mut rng, s.n_cols(), s.n_rows());
        let n = cmat(&mut rng, nrows, s.n_rows());
        let g = generalized_mu_bounds(&m, &n, &s, &MuConfig::default()).unwrap();
        let st = mu_bounds(&m, &s, &MuConfig::default()).unwrap();
        prop_assert!(g.upper >= g.lower * (1.0 - 1e-9), "upper {} < lower {}", g.upper, g.lower);
        prop_assert!(g.lower <= st.upper * (1.0 + 1e-9));
        check_certificate(&m, Some(&n), &s, &g);
    }
}

#[test]
fn bad_dimensions_are_reported() {
    let s = BlockStructure::new(vec![Block::Scalar, Block::Full { rows: 2, cols: 1 }]);
    let m = Mat::<C64>::zeros(3, 3);
    let e = mu_bounds(&m, &s, &MuConfig::default()).unwrap_err();
    assert!(e.to_string().contains("M vs block structure"), "{e}");
    let mut m = Mat::<C64>::zeros(2, 3);
    m[(0, 0)] = C64::new(f64::NAN, 0.0);
    let e = mu_bounds(&m, &s, &MuConfig::default()).unwrap_err();
    assert!(e.to_string().contains("not finite"), "{e}");
}
