//! Polynomial roots in the ascending, constant-one form the fitted denominators use.

use crate::{RealizeError, C64};
use faer::Mat;

/// Roots of `1 + c_1 x + ... + c_n x^n` (coefficients ascending, the constant 1
/// implied): closed forms for `n <= 2` (the stable quadratic formula), the eigenvalues
/// of the companion matrix of the monic polynomial otherwise.
pub fn roots_ascending(c: &[f64]) -> Result<Vec<C64>, RealizeError> {
    let n = c.len();
    if n == 0 {
        return Ok(Vec::new());
    }
    let cn = c[n - 1];
    if cn == 0.0 || !cn.is_finite() {
        return Err(RealizeError::Numerical {
            what: "polynomial roots".into(),
            why: format!("leading coefficient is {cn}"),
        });
    }
    match n {
        1 => Ok(vec![C64::new(-1.0 / cn, 0.0)]),
        2 => {
            // cn x^2 + c1 x + 1
            let (a, b) = (cn, c[0]);
            let disc = b * b - 4.0 * a;
            if disc >= 0.0 {
                let sq = disc.sqrt();
                let t = -0.5 * (b + b.signum() * sq);
                let t = if t == 0.0 { -0.5 * sq } else { t };
                Ok(vec![C64::new(t / a, 0.0), C64::new(1.0 / t, 0.0)])
            } else {
                let re = -b / (2.0 * a);
                let im = (-disc).sqrt() / (2.0 * a.abs());
                Ok(vec![C64::new(re, im), C64::new(re, -im)])
            }
        }
        _ => {
            // companion matrix of x^n + (c_{n-1}/c_n) x^{n-1} + ... + 1/c_n
            let mut comp = Mat::<f64>::zeros(n, n);
            for i in 1..n {
                comp[(i, i - 1)] = 1.0;
            }
            for i in 0..n {
                let coef = if i == 0 { 1.0 / cn } else { c[i - 1] / cn };
                comp[(i, n - 1)] = -coef;
            }
            let ev = comp.eigenvalues().map_err(|e| RealizeError::Numerical {
                what: "polynomial roots".into(),
                why: format!("eigenvalues of the companion matrix: {e:?}"),
            })?;
            Ok(ev.into_iter().map(|z| C64::new(z.re, z.im)).collect())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_known_polynomials() {
        // (1 + x/2)(1 + x/3) = 1 + 5/6 x + 1/6 x^2: roots -2, -3
        let mut r = roots_ascending(&[5.0 / 6.0, 1.0 / 6.0]).unwrap();
        r.sort_by(|a, b| a.re.total_cmp(&b.re));
        assert!((r[0] - C64::new(-3.0, 0.0)).norm() < 1e-12);
        assert!((r[1] - C64::new(-2.0, 0.0)).norm() < 1e-12);
        // (1 + x)(1 + x^2) = 1 + x + x^2 + x^3: roots -1, +-j
        let r = roots_ascending(&[1.0, 1.0, 1.0]).unwrap();
        for z in [C64::new(-1.0, 0.0), C64::new(0.0, 1.0), C64::new(0.0, -1.0)] {
            assert!(r.iter().any(|x| (x - z).norm() < 1e-10), "{z} not in {r:?}");
        }
        assert!(roots_ascending(&[1.0, 0.0]).is_err());
        assert!(roots_ascending(&[]).unwrap().is_empty());
    }
}
