//! Matched single-mode scan of a residual: where, in frequency and damping, would one
//! more lightly damped mode explain most of the weighted residual `G - P`?
//!
//! A missing mode does not always peak in the residual's CMIF: when it lies between
//! two fitted modes, the settled neighbours widen to cover it and the residual it
//! leaves is a broad, two-sided misfit whose largest values sit on the neighbours'
//! flanks (a random 1 x 2 system with modes at 123, 214 and 326 Hz, damping 0.02-0.04:
//! the start settled without the 214 Hz mode, the residual's CMIF had no candidate
//! there). The scan asks the question the completion needs answered directly: for
//! every trial pole on a grid, the residual of every entry is projected onto that
//! pole's second-order mode shapes, and the trial whose projection removes the most
//! weighted residual energy is the candidate. It is the greedy step of a matching
//! pursuit over a dictionary of modes; the candidate only places a trial, which the
//! completion then settles with every other pole free and keeps only when its F test
//! passes.
//!
//! One trial mode contributes `(a w0^2 + b w0 s) / (s^2 + 2 zeta w0 s + w0^2)` to an
//! entry (the real-coefficient numerator of eq. (26) of the wafer-stage paper, scaled
//! so that both shapes are of order `1 / (2 zeta)` at resonance). With `s = j w` the
//! two shapes are orthogonal under any real weighting (their product `phi1 conj(phi2)`
//! is purely imaginary), so the least-squares gain of an entry is
//! `r1^2 / g11 + r2^2 / g22` with `r_i = sum_k w Re(conj(phi_i) e)` and
//! `g_ii = sum_k w |phi_i|^2`: no linear system is solved.

use crate::problem::FitData;
use frf_data::C64;
use rayon::prelude::*;
use std::f64::consts::TAU;

/// Settings of [`scan_residual`], with documented defaults.
#[derive(Debug, Clone)]
pub struct ScanConfig {
    /// Damping ratios of the trial poles. Default: 0.003, 0.01, 0.03, 0.1 (lightly
    /// damped motion systems, up to a well damped mode; the settling adjusts the
    /// damping from there).
    pub dampings: Vec<f64>,
    /// Frequency step of the grid, in half-power half-widths `zeta f` of the trial's
    /// damping. Default: 1 (a trial lands within half a half-width of any mode of that
    /// damping, where its shape still matches).
    pub step_half_widths: f64,
    /// Trials narrower than this fraction of the local line spacing (half-power
    /// half-width `zeta f` against the spacing) are skipped: the data cannot resolve
    /// them, and one outlying line fits such a mode as well as any. Default: 0.5.
    pub min_half_width_lines: f64,
}

impl Default for ScanConfig {
    fn default() -> Self {
        Self {
            dampings: vec![0.003, 0.01, 0.03, 0.1],
            step_half_widths: 1.0,
            min_half_width_lines: 0.5,
        }
    }
}

/// One trial of the scan: a pole (natural frequency, damping) and the weighted residual
/// energy one mode there removes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanHit {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Damping ratio.
    pub zeta: f64,
    /// Weighted residual energy removed by the best mode at this pole (sum over the
    /// entries of `r1^2 / g11 + r2^2 / g22`).
    pub gain: f64,
}

/// The weighted residual energy one mode at natural frequency `w0` (rad/s) and damping
/// `zeta` removes from the residual `resid` (`resid[k * m + e]`, on the lines and with
/// the weights of `data`); see the module documentation.
pub fn mode_gain(resid: &[C64], data: &FitData, w0: f64, zeta: f64) -> f64 {
    let m = data.m();
    // per entry: r1, r2, g11, g22
    let mut acc = vec![[0.0f64; 4]; m];
    for (k, &w) in data.omega.iter().enumerate() {
        let s = C64::new(0.0, w);
        let d = s * s + s * (2.0 * zeta * w0) + w0 * w0;
        let inv = d.inv();
        let phi1 = inv * (w0 * w0);
        let phi2 = inv * s * w0;
        let (n1, n2) = (phi1.norm_sqr(), phi2.norm_sqr());
        for (e, a) in acc.iter_mut().enumerate() {
            let wt = data.w[k * m + e];
            if wt <= 0.0 {
                continue;
            }
            let r = resid[k * m + e];
            a[0] += wt * (phi1.conj() * r).re;
            a[1] += wt * (phi2.conj() * r).re;
            a[2] += wt * n1;
            a[3] += wt * n2;
        }
    }
    acc.iter()
        .map(|a| {
            let t1 = if a[2] > 0.0 { a[0] * a[0] / a[2] } else { 0.0 };
            let t2 = if a[3] > 0.0 { a[1] * a[1] / a[3] } else { 0.0 };
            t1 + t2
        })
        .sum()
}

/// The trials of the scan over `data`'s band, the largest gain first, at most one per
/// relative distance `min_separation` in frequency (the strongest trial stands for its
/// neighbours, whatever their damping). The grid holds, for every damping of `cfg`,
/// frequencies from the band's lower to its upper edge spaced
/// `cfg.step_half_widths * zeta f` apart, without those narrower than the line spacing
/// allows (`cfg.min_half_width_lines`). Trials run in parallel (they are independent).
pub fn scan_residual(
    resid: &[C64],
    data: &FitData,
    cfg: &ScanConfig,
    min_separation: f64,
) -> Vec<ScanHit> {
    let (lo, hi) = data.band_hz;
    if !(lo > 0.0 && hi > lo) || data.n < 3 {
        return Vec::new();
    }
    let f_lines: Vec<f64> = data.omega.iter().map(|w| w / TAU).collect();
    let spacing_near = |f: f64| -> f64 {
        let k = f_lines
            .partition_point(|&x| x < f)
            .clamp(1, f_lines.len() - 1);
        (f_lines[k] - f_lines[k - 1]).abs()
    };
    let mut grid: Vec<(f64, f64)> = Vec::new();
    for &zeta in &cfg.dampings {
        if !(zeta > 0.0 && zeta < 1.0) {
            continue;
        }
        let ratio = 1.0 + cfg.step_half_widths.max(1e-3) * zeta;
        let mut f = lo;
        while f <= hi {
            if zeta * f >= cfg.min_half_width_lines * spacing_near(f) {
                grid.push((f, zeta));
            }
            f *= ratio;
        }
    }
    let mut hits: Vec<ScanHit> = grid
        .par_iter()
        .map(|&(f, zeta)| ScanHit {
            f_hz: f,
            zeta,
            gain: mode_gain(resid, data, TAU * f, zeta),
        })
        .filter(|h| h.gain.is_finite() && h.gain > 0.0)
        .collect();
    hits.sort_by(|a, b| b.gain.total_cmp(&a.gain));
    let mut out: Vec<ScanHit> = Vec::new();
    for h in hits {
        if out
            .iter()
            .all(|o| (h.f_hz - o.f_hz).abs() > min_separation * o.f_hz)
        {
            out.push(h);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::{Frf, Weighting};

    /// A residual that is exactly one mode (180 Hz, damping 0.02) on a 2 x 1 grid: the
    /// scan's best trial is at that pole and removes (almost) all of its energy; a
    /// trial far from it removes little.
    #[test]
    fn a_pure_mode_residual_is_found_at_its_pole() {
        let f: Vec<f64> = (0..800).map(|k| 10.0 + 990.0 * k as f64 / 799.0).collect();
        let (w0, zeta) = (TAU * 180.0, 0.02);
        let mut g = Vec::new();
        for &fk in &f {
            let s = C64::new(0.0, TAU * fk);
            let d = s * s + s * (2.0 * zeta * w0) + w0 * w0;
            g.push(C64::new(3.0 * w0 * w0, 0.0) / d);
            g.push((s * (-2.0 * w0) + w0 * w0 * 0.5) / d);
        }
        let frf = Frf::new(f, 2, 1, g.clone(), None).unwrap();
        let data = FitData::new(&frf, &Weighting::Uniform).unwrap();
        let energy: f64 = g.iter().map(|x| x.norm_sqr()).sum();
        let hits = scan_residual(&g, &data, &ScanConfig::default(), 0.025);
        let best = hits[0];
        assert!((best.f_hz - 180.0).abs() < 0.02 * 180.0, "{best:?}");
        assert!(best.gain > 0.9 * energy, "{} of {energy}", best.gain);
        // the exact pole removes everything
        let exact = mode_gain(&g, &data, w0, zeta);
        assert!(
            (exact - energy).abs() < 1e-9 * energy,
            "{exact} vs {energy}"
        );
        let far = mode_gain(&g, &data, TAU * 700.0, 0.02);
        assert!(far < 0.05 * energy, "{far} of {energy}");
    }
}
