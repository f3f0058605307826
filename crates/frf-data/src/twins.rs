//! When two modes share one resonance: the rule that the ML refiner's re-test of its
//! modes (`ml_refine`) and the diagnosis's twin merge (`frfit`) both apply, stated once.

use num_complex::Complex64;

/// Two modes whose upper poles are closer than this fraction of their mean `|Re p|`
/// (within each other's half-power half-bandwidth) share one resonance: twins.
pub const TWIN_FRACTION: f64 = 1.0;

/// The distance of two upper poles over their mean `|Re p|` (their mean half-power
/// half-bandwidth, rad/s): below [`TWIN_FRACTION`] they are twins. NaN or infinite when
/// both poles lie on the imaginary axis.
pub fn pole_separation(a: Complex64, b: Complex64) -> f64 {
    (a - b).norm() / (0.5 * (a.re.abs() + b.re.abs()))
}

/// Whether the modes with upper poles `a` and `b` are twins ([`TWIN_FRACTION`]).
pub fn are_twins(a: Complex64, b: Complex64) -> bool {
    pole_separation(a, b) < TWIN_FRACTION
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poles_within_their_half_bandwidth_are_twins() {
        // 100 Hz and 100.5 Hz at 1 % damping: half-power half-bandwidth 6.3 rad/s, 3.1
        // rad/s apart
        let pole = |f: f64, z: f64| {
            let w = std::f64::consts::TAU * f;
            Complex64::new(-z * w, w * (1.0 - z * z).sqrt())
        };
        assert!(are_twins(pole(100.0, 0.01), pole(100.5, 0.01)));
        assert!(!are_twins(pole(100.0, 0.01), pole(102.0, 0.01)));
        let s = pole_separation(pole(100.0, 0.01), pole(100.5, 0.01));
        assert!((s - 0.5).abs() < 0.01, "{s}");
        assert!(!are_twins(
            Complex64::new(0.0, 1.0),
            Complex64::new(0.0, 1.0)
        ));
    }
}
