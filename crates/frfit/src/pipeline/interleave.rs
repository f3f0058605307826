//! The band's lines split into interleaved halves, the even and the odd ones, each with
//! its weights: what the diagnosis's check of a step on held-out lines
//! ([`crate::diagnose::held_out`]) refits on and tests on. The run's [`FitContext`]
//! makes the split once ([`FitContext::held_out_halves`]).
//!
//! [`FitContext`]: super::context::FitContext
//! [`FitContext::held_out_halves`]: super::context::FitContext::held_out_halves

use additive_riv::FitData;

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
