//! A change of structure earns its place on data it was not fitted to: interleaved
//! held-out lines (issue 42).
//!
//! The band's lines are split into the even and the odd ones ([`halves`]). The model
//! before the change and the model after it are each refitted (Algorithm 1 from their
//! own parameters) on one half and their weighted cost taken on the other, then the
//! halves swap; the summed held-out costs of the two structures are compared
//! ([`HeldOutCost`]). An effect that the data hold lowers the error on lines it was not
//! fitted to; parameters that only follow the noise or the nonlinear distortion of the
//! fitted lines (both independent from line to line) raise it. Every line is fitted and
//! tested once, so the check needs no data beyond the band, and validation data stay
//! independent for the final validation.
//!
//! Used by the structure adaptation of the first fit (modes added at residual peaks,
//! [`crate::structure::adapt_modes`]) and by the diagnosis's steps and readings.

use crate::riv::{iterate, RivConfig};
use crate::{AdditiveModel, FitData};
use frf_data::structure::HeldOutCost;
use rayon::prelude::*;

/// The lines of `fd` whose index has parity `parity` (0: even, 1: odd), with their
/// weights; the band (the frequency scaling) is that of `fd`.
pub fn interleaved(fd: &FitData, parity: usize) -> FitData {
    let m = fd.m();
    let keep: Vec<usize> = (0..fd.n).filter(|k| k % 2 == parity).collect();
    let omega = keep.iter().map(|&k| fd.omega[k]).collect();
    let g = keep
        .iter()
        .flat_map(|&k| fd.g[k * m..(k + 1) * m].iter().copied())
        .collect();
    let w = keep
        .iter()
        .flat_map(|&k| fd.w[k * m..(k + 1) * m].iter().copied())
        .collect();
    FitData::from_parts(omega, fd.ny, fd.nu, g, w, fd.band_hz)
}

/// The even and the odd lines of `fd` ([`interleaved`]).
pub fn halves(fd: &FitData) -> [FitData; 2] {
    [interleaved(fd, 0), interleaved(fd, 1)]
}

/// The held-out costs of the change from `before` to `after` (summed over the two
/// folds) on the band split into `halves` ([`halves`]; see the module documentation),
/// the refits by `riv`, the four refits in parallel. `None` when the band has too few
/// lines to split or a refit fails (the check is then not made). The F statistic is
/// not formed here (see [`HeldOutCost::f_of`]).
pub fn held_out(
    halves: &[FitData; 2],
    riv: &RivConfig,
    before: &AdditiveModel,
    after: &AdditiveModel,
) -> Option<HeldOutCost> {
    if halves[0].n + halves[1].n < 8 {
        return None;
    }
    let jobs: Vec<(usize, bool)> = vec![(0, false), (0, true), (1, false), (1, true)];
    let costs: Vec<Option<(bool, f64)>> = jobs
        .into_par_iter()
        .map(|(fold, is_after)| {
            let model = if is_after { after } else { before };
            let (fit_on, test_on) = (&halves[fold], &halves[1 - fold]);
            let refit = iterate(model.clone(), fit_on, riv).ok()?;
            let c = crate::residual_stats::cost_of(&refit.model, test_on);
            c.is_finite().then_some((is_after, c))
        })
        .collect();
    HeldOutCost::from_folds(costs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::C64;

    #[test]
    fn interleaved_halves_partition_the_lines() {
        let n = 9;
        let (ny, nu) = (2, 1);
        let omega: Vec<f64> = (1..=n).map(|k| k as f64).collect();
        let g: Vec<C64> = (0..n * 2)
            .map(|i| C64::new(i as f64, -(i as f64)))
            .collect();
        let w: Vec<f64> = (0..n * 2).map(|i| 1.0 + i as f64).collect();
        let fd = FitData::from_parts(omega, ny, nu, g, w, (1.0, 9.0));
        let (even, odd) = (interleaved(&fd, 0), interleaved(&fd, 1));
        assert_eq!((even.n, odd.n), (5, 4));
        assert_eq!(even.omega, vec![1.0, 3.0, 5.0, 7.0, 9.0]);
        assert_eq!(odd.omega, vec![2.0, 4.0, 6.0, 8.0]);
        // line 1 (the first odd one) keeps both entries and their weights
        assert_eq!(odd.g[0], fd.g[2]);
        assert_eq!(odd.g[1], fd.g[3]);
        assert_eq!(odd.w[..2], fd.w[2..4]);
        assert_eq!(even.band_hz, fd.band_hz);
    }
}
