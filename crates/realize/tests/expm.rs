//! The matrix exponential (Higham 2005 scaling and squaring) against closed forms and a
//! Taylor-series reference.

mod common;

use common::{gauss, rng};
use faer::Mat;
use realize::expm::expm;
use realize::RealizeError;

fn rel(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    (a - b).norm_l2() / b.norm_l2()
}

/// `sum_k A^k / k!` with `terms` terms, summed in the order of increasing k. Only for
/// `||A|| <~ 1` where the series does not cancel.
fn taylor(a: &Mat<f64>, terms: usize) -> Mat<f64> {
    let n = a.nrows();
    let mut sum = Mat::<f64>::identity(n, n);
    let mut term = Mat::<f64>::identity(n, n);
    for k in 1..terms {
        term = &term * a;
        term = Mat::from_fn(n, n, |i, j| term[(i, j)] / k as f64);
        sum += &term;
    }
    sum
}

#[test]
fn rotation_generator_gives_rotation() {
    // exp([[0, t], [-t, 0]]) = [[cos t, sin t], [-sin t, cos t]], for angles that use
    // every Pade degree and heavy squaring.
    for t in [1e-3, 0.1, 0.9, 2.0, 5.0, 10.0, 100.0, 1e4] {
        let a = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 1) => t,
            (1, 0) => -t,
            _ => 0.0,
        });
        let e = expm(a.as_ref()).unwrap();
        let (c, s) = (f64::cos(t), f64::sin(t));
        let want = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) | (1, 1) => c,
            (0, 1) => s,
            _ => -s,
        });
        // Squaring s times amplifies the rounding error of the scaled exponential.
        let tol = 1e-14 * (1.0 + t);
        assert!(rel(&e, &want) < tol, "t = {t}: {:e}", rel(&e, &want));
    }
}

#[test]
fn damped_rotation_matches_closed_form() {
    // exp([[s, w], [-w, s]] t) = e^{s t} [[cos wt, sin wt], [-sin wt, cos wt]].
    let (s, w) = (-0.7, 3.0);
    for t in [0.01, 0.5, 4.0] {
        let a = Mat::from_fn(2, 2, |i, j| {
            t * match (i, j) {
                (0, 0) | (1, 1) => s,
                (0, 1) => w,
                _ => -w,
            }
        });
        let e = expm(a.as_ref()).unwrap();
        let g = f64::exp(s * t);
        let (c, sn) = (f64::cos(w * t), f64::sin(w * t));
        let want = Mat::from_fn(2, 2, |i, j| {
            g * match (i, j) {
                (0, 0) | (1, 1) => c,
                (0, 1) => sn,
                _ => -sn,
            }
        });
        assert!(rel(&e, &want) < 1e-14, "t = {t}: {:e}", rel(&e, &want));
    }
}

#[test]
fn nilpotent_gives_finite_series() {
    // Strictly upper triangular N (N^4 = 0): exp(N) = I + N + N^2/2 + N^3/6, exactly,
    // including entries large enough to force scaling and squaring.
    for scale in [1e-3, 1.0, 30.0] {
        let n = Mat::from_fn(4, 4, |i, j| {
            if j > i {
                scale * (1.0 + (i + 2 * j) as f64)
            } else {
                0.0
            }
        });
        let n2 = &n * &n;
        let n3 = &n2 * &n;
        let want = Mat::from_fn(4, 4, |i, j| {
            (if i == j { 1.0 } else { 0.0 }) + n[(i, j)] + n2[(i, j)] / 2.0 + n3[(i, j)] / 6.0
        });
        let e = expm(n.as_ref()).unwrap();
        // Squaring a highly non-normal matrix (the 2005 algorithm's known overscaling)
        // costs a few digits more than the normal cases above.
        assert!(
            rel(&e, &want) < 1e-13,
            "scale {scale}: {:e}",
            rel(&e, &want)
        );
    }
    // The double integrator: exp([[0, T], [0, 0]]) = [[1, T], [0, 1]].
    let t = 0.37;
    let a = Mat::from_fn(2, 2, |i, j| if (i, j) == (0, 1) { t } else { 0.0 });
    let e = expm(a.as_ref()).unwrap();
    assert_eq!((e[(0, 0)], e[(1, 0)], e[(1, 1)]), (1.0, 0.0, 1.0));
    assert!((e[(0, 1)] - t).abs() < 2.0 * f64::EPSILON * t);
}

#[test]
fn diagonal_gives_exponentials() {
    let d = [-50.0, -3.0, -1e-6, 0.0, 0.25, 2.0, 7.5];
    let a = Mat::from_fn(d.len(), d.len(), |i, j| if i == j { d[i] } else { 0.0 });
    let e = expm(a.as_ref()).unwrap();
    for i in 0..d.len() {
        for j in 0..d.len() {
            if i == j {
                let r = (e[(i, i)] - d[i].exp()).abs() / d[i].exp();
                assert!(r < 1e-14, "d = {}: {r:e}", d[i]);
            } else {
                assert_eq!(e[(i, j)], 0.0);
            }
        }
    }
}

#[test]
fn small_random_matrices_match_taylor_series() {
    // Norms from below theta_3 to above theta_13 (the Taylor reference is evaluated on
    // A / 2^k and squared back for the larger ones, with enough terms to be exact).
    let mut r = rng(7);
    for (case, &target) in [0.01, 0.2, 0.8, 1.9, 4.0, 12.0]
        .iter()
        .cycle()
        .take(36)
        .enumerate()
    {
        let n = 1 + case % 6;
        let g = Mat::from_fn(n, n, |_, _| gauss(&mut r));
        let nrm = (0..n)
            .map(|j| (0..n).map(|i| g[(i, j)].abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let a = Mat::from_fn(n, n, |i, j| g[(i, j)] * target / nrm);
        let squarings = if target > 1.0 {
            (target.log2().ceil()) as i32
        } else {
            0
        };
        let scaled = Mat::from_fn(n, n, |i, j| a[(i, j)] / 2f64.powi(squarings));
        let mut want = taylor(&scaled, 40);
        for _ in 0..squarings {
            want = &want * &want;
        }
        let e = expm(a.as_ref()).unwrap();
        let err = rel(&e, &want);
        assert!(
            err < 1e-13 * (1.0 + target),
            "n = {n}, |A|_1 = {target}: {err:e}"
        );
    }
}

#[test]
fn exponential_of_minus_a_is_the_inverse() {
    let mut r = rng(11);
    for n in [3, 8, 20] {
        let a = Mat::from_fn(n, n, |_, _| 2.0 * gauss(&mut r));
        let ma = Mat::from_fn(n, n, |i, j| -a[(i, j)]);
        let e = expm(a.as_ref()).unwrap();
        let f = expm(ma.as_ref()).unwrap();
        let p = &e * &f;
        let id = Mat::<f64>::identity(n, n);
        // The product's error is ~ eps cond(e^A) ||...||; a loose but failing-capable bound.
        let err = (&p - &id).norm_l2();
        assert!(err < 1e-6, "n = {n}: {err:e}");
    }
}

#[test]
fn rejects_bad_input() {
    let a = Mat::<f64>::zeros(2, 3);
    assert!(matches!(
        expm(a.as_ref()),
        Err(RealizeError::Dimension { .. })
    ));
    let a = Mat::from_fn(2, 2, |i, j| if i == j { f64::NAN } else { 0.0 });
    assert!(matches!(
        expm(a.as_ref()),
        Err(RealizeError::NonFinite { .. })
    ));
    let a = Mat::from_fn(1, 1, |_, _| 1e5);
    assert!(matches!(
        expm(a.as_ref()),
        Err(RealizeError::Numerical { .. })
    ));
    let empty = Mat::<f64>::zeros(0, 0);
    assert_eq!(expm(empty.as_ref()).unwrap().nrows(), 0);
}
