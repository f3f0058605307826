//! The terms of the modal (partial-fraction) model at one frequency line, with their
//! derivatives with respect to the poles: the building blocks of the analytic Jacobian
//! ([`crate::jacobian`]) and of the variable-projection solver ([`crate::varpro`]).
//!
//! A pole `p` enters through `h(p) = 1 / (j w - p)` in continuous time, or through its
//! exact zero-order-hold image `h(p) = ((e^{p T} - 1) / p) / (z - e^{p T})` at
//! `z = e^{j w T}` (the discretisation [`realize::ModalModel::zoh_response`] uses); both
//! are analytic in `p`, so `d h / d Re p = h'(p)` and `d h / d Im p = j h'(p)`.

use crate::C64;
use realize::{FrfModel, Hold};

/// `h(p)` and `h'(p) = d h / d p` at `omega` (rad/s): continuous time for `ts = None`,
/// the exact zero-order-hold image with sample time `ts` otherwise.
#[inline]
pub(crate) fn first_order(p: C64, omega: f64, ts: Option<f64>) -> (C64, C64) {
    match ts {
        None => {
            let h = (C64::new(0.0, omega) - p).inv();
            (h, h * h)
        }
        Some(t) => {
            let z = C64::from_polar(1.0, omega * t);
            let x = p * t;
            let zp = x.exp();
            // num = (e^x - 1) / p and its derivative, by series for small |x|
            let (num, dnum) = if x.norm_sqr() < 1e-6 {
                (
                    t * (1.0 + x / 2.0 + x * x / 6.0 + x * x * x / 24.0),
                    t * t * (0.5 + x / 3.0 + x * x / 8.0 + x * x * x / 30.0),
                )
            } else {
                ((zp - 1.0) / p, (t * zp * p - (zp - 1.0)) / (p * p))
            };
            let d = (z - zp).inv();
            (num * d, dnum * d + num * t * zp * d * d)
        }
    }
}

/// `first_order` of a pole `p` and of its conjugate at `omega`, sharing the work: the
/// hold's `z = e^{j w T}` once, and `e^{conj(p) T} = conj(e^{p T})`.
#[inline]
pub(crate) fn first_order_pair(p: C64, omega: f64, ts: Option<f64>) -> [(C64, C64); 2] {
    match ts {
        None => {
            let jw = C64::new(0.0, omega);
            let h = (jw - p).inv();
            let hc = (jw - p.conj()).inv();
            [(h, h * h), (hc, hc * hc)]
        }
        Some(t) => {
            let z = C64::from_polar(1.0, omega * t);
            let x = p * t;
            if x.norm_sqr() < 1e-6 {
                return [first_order(p, omega, ts), first_order(p.conj(), omega, ts)];
            }
            let zp = x.exp();
            let one = |p: C64, zp: C64| {
                let num = (zp - 1.0) / p;
                let dnum = (t * zp * p - (zp - 1.0)) / (p * p);
                let d = (z - zp).inv();
                (num * d, dnum * d + num * t * zp * d * d)
            };
            [one(p, zp), one(p.conj(), zp.conj())]
        }
    }
}

/// Eulerian numbers: the coefficients (highest power first) of `E_k(z)` in
/// `Z{zoh(1/s^k)} = T^k / k! E_k(z) / (z - 1)^k`.
fn eulerian_row(k: usize) -> Vec<f64> {
    let mut row = vec![1.0];
    for n in 2..=k {
        let mut next = vec![0.0; n];
        for (m, v) in next.iter_mut().enumerate() {
            let a = if m >= 1 && m - 1 < row.len() {
                (n - m) as f64 * row[m - 1]
            } else {
                0.0
            };
            let b = if m < row.len() {
                (m + 1) as f64 * row[m]
            } else {
                0.0
            };
            *v = a + b;
        }
        row = next;
    }
    row
}

/// The rigid-body bases `1 / s^l`, `l = 1..=n`, at `omega` (or their exact
/// zero-order-hold images).
pub(crate) fn rigid_bases(n: usize, omega: f64, ts: Option<f64>, out: &mut Vec<C64>) {
    out.clear();
    match ts {
        None => {
            let inv = C64::new(0.0, omega).inv();
            let mut pw = inv;
            for _ in 0..n {
                out.push(pw);
                pw *= inv;
            }
        }
        Some(t) => {
            let z = C64::from_polar(1.0, omega * t);
            let zm1 = z - 1.0;
            let mut fact = 1.0;
            for l in 1..=n {
                fact *= l as f64;
                let mut e = C64::new(0.0, 0.0);
                for &c in &eulerian_row(l) {
                    e = e * z + c;
                }
                out.push(e * t.powi(l as i32) / fact / zm1.powi(l as i32));
            }
        }
    }
}

/// The sample time of an exact zero-order hold, when the model declares one.
pub(crate) fn zoh_ts(model: &FrfModel) -> Option<f64> {
    match model.factors.hold {
        Hold::Zoh { fs_hz } => Some(1.0 / fs_hz),
        _ => None,
    }
}

/// `x^1 .. x^n` for a dynamics factor's scaled variable `x = j w / scale`.
pub(crate) fn powers(x: C64, n: usize) -> Vec<C64> {
    let mut v = Vec::with_capacity(n);
    let mut p = x;
    for _ in 0..n {
        v.push(p);
        p *= x;
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use realize::{ModalModel, PolePair};

    #[test]
    fn zoh_terms_match_the_realize_discretisation() {
        let ts = 1e-4;
        let mut m = ModalModel::new(1, 1);
        m.rigid = vec![
            Mat::from_fn(1, 1, |_, _| 0.3),
            Mat::from_fn(1, 1, |_, _| 2.0),
            Mat::from_fn(1, 1, |_, _| -0.7),
        ];
        m.pairs.push(PolePair {
            pole: C64::new(-30.0, 900.0),
            residue: Mat::from_fn(1, 1, |_, _| C64::new(0.2, -1.5)),
        });
        let w = [50.0, 700.0, 9000.0];
        let g = m.zoh_response(&w, ts, 0.0).unwrap();
        let mut rb = Vec::new();
        for (k, &wk) in w.iter().enumerate() {
            let p = m.pairs[0].pole;
            let r = m.pairs[0].residue[(0, 0)];
            let (h, _) = first_order(p, wk, Some(ts));
            let (hc, _) = first_order(p.conj(), wk, Some(ts));
            rigid_bases(3, wk, Some(ts), &mut rb);
            let v = r * h + r.conj() * hc + 0.3 * rb[0] + 2.0 * rb[1] - 0.7 * rb[2];
            let e = g.get(k, 0, 0);
            assert!((v - e).norm() <= 1e-10 * e.norm(), "{v} vs {e}");
        }
    }

    #[test]
    fn pair_terms_equal_the_single_ones() {
        for ts in [None, Some(1e-4)] {
            for p in [C64::new(-20.0, 600.0), C64::new(-1e-3, 2.0)] {
                let [a, b] = first_order_pair(p, 640.0, ts);
                let (c, d) = (first_order(p, 640.0, ts), first_order(p.conj(), 640.0, ts));
                for (u, v) in [(a.0, c.0), (a.1, c.1), (b.0, d.0), (b.1, d.1)] {
                    assert!((u - v).norm() <= 1e-13 * v.norm(), "{ts:?} {p}: {u} vs {v}");
                }
            }
        }
    }

    #[test]
    fn pole_derivatives_match_finite_differences() {
        for ts in [None, Some(1e-4)] {
            for p in [
                C64::new(-20.0, 600.0),
                C64::new(-1e-3, 0.0),
                C64::new(-5e3, 0.0),
            ] {
                let w = 640.0;
                let (_, dh) = first_order(p, w, ts);
                let d = 1e-6 * p.norm().max(1.0);
                let (a, _) = first_order(p + d, w, ts);
                let (b, _) = first_order(p - d, w, ts);
                let fd = (a - b) / (2.0 * d);
                assert!(
                    (fd - dh).norm() <= 1e-6 * dh.norm(),
                    "{ts:?} {p}: {fd} vs {dh}"
                );
            }
        }
    }
}
