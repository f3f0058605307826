//! The model order from the singular values of the projected data.
//!
//! Rule: among the orders `n = 1 ..= n_max`, `n_max = min((r - 1) p, numerical rank,
//! max_order)` (the shift equations (12) need `(r - 1) p >= n`), take the one with the
//! largest gap `ln s_n - ln s_(n+1)` between consecutive singular values. With the
//! data's own variance as the weighting the noise level of the singular values is
//! known (about 1), and the estimator counts the singular values above a multiple of
//! it instead (`SubspaceConfig::noise_threshold`). The numerical rank counts the singular values
//! above [`RANK_TOL`] times the largest: a given order above it is an error (the data
//! do not support that many states).

/// Relative tolerance of the numerical rank of the projected data.
pub const RANK_TOL: f64 = 1e-12;

/// Numerical rank of `sv` (descending).
pub fn numerical_rank(sv: &[f64]) -> usize {
    let s1 = sv.first().copied().unwrap_or(0.0);
    if s1 <= 0.0 {
        return 0;
    }
    sv.iter().filter(|&&s| s > RANK_TOL * s1).count()
}

/// The order with the largest log gap among `1 ..= n_max` (requires `n_max < sv.len()`
/// and `n_max >= 1`); returns the order and the gap (natural log).
pub fn largest_gap(sv: &[f64], n_max: usize) -> (usize, f64) {
    let s1 = sv.first().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
    let floor = s1 * 1e-300;
    let mut best = (1, f64::NEG_INFINITY);
    for n in 1..=n_max.min(sv.len().saturating_sub(1)) {
        let g = sv[n - 1].max(floor).ln() - sv[n].max(floor).ln();
        if g > best.1 {
            best = (n, g);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_and_rank() {
        let sv = [10.0, 9.0, 5.0, 1e-3, 9e-4, 1e-14];
        assert_eq!(numerical_rank(&sv), 5);
        assert_eq!(largest_gap(&sv, 4).0, 3);
        // restricted range: the gap at 5 is not a candidate for n_max = 4
        assert_eq!(largest_gap(&sv, 5).0, 5);
    }
}
