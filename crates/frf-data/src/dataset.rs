//! The [`FrfDataset`] trait: what every estimator reads.

use crate::{Frf, C64};
use faer::Mat;
use std::f64::consts::TAU;

/// A measured (or simulated) frequency response function: `ny x nu` complex matrices at
/// `n_lines` frequency lines, with an optional per-entry variance
/// `E|G_hat - G|^2` of each estimate.
///
/// Implemented by the owning [`Frf`] and by the zero-copy [`crate::FrfView`] (a band
/// and/or a subset of entries of an `Frf`). Entry `(i, j)` is output `i`, input `j`,
/// both 0-based here (the CSV columns are 1-based).
pub trait FrfDataset {
    /// Number of outputs (rows of `G`).
    fn ny(&self) -> usize;
    /// Number of inputs (columns of `G`).
    fn nu(&self) -> usize;
    /// Number of frequency lines.
    fn n_lines(&self) -> usize;
    /// Frequency of line `k`, Hz.
    fn freq_hz(&self, k: usize) -> f64;
    /// Entry `(i, j)` at line `k`.
    fn value(&self, k: usize, i: usize, j: usize) -> C64;
    /// Variance of entry `(i, j)` at line `k`, when the data carry one.
    fn variance(&self, k: usize, i: usize, j: usize) -> Option<f64>;
    /// True when the data carry a variance for every entry and line.
    fn has_variance(&self) -> bool;
    /// Physical units of `G` (for example `m/N`), when known.
    fn units(&self) -> Option<&str>;

    /// Angular frequency of line `k`, rad/s.
    fn omega(&self, k: usize) -> f64 {
        TAU * self.freq_hz(k)
    }
    /// All frequencies, Hz.
    fn freqs_hz(&self) -> Vec<f64> {
        (0..self.n_lines()).map(|k| self.freq_hz(k)).collect()
    }
    /// All angular frequencies, rad/s.
    fn omegas(&self) -> Vec<f64> {
        (0..self.n_lines()).map(|k| self.omega(k)).collect()
    }
    /// Number of entries `ny * nu`.
    fn n_entries(&self) -> usize {
        self.ny() * self.nu()
    }
    /// `vec(G)` of line `k` (column-major, length `ny * nu`) into `out`.
    fn line_into(&self, k: usize, out: &mut [C64]) {
        let ny = self.ny();
        for j in 0..self.nu() {
            for i in 0..ny {
                out[j * ny + i] = self.value(k, i, j);
            }
        }
    }
    /// The variances of line `k` in `vec` order into `out`; false (and `out` untouched)
    /// when the data carry none.
    fn variance_line_into(&self, k: usize, out: &mut [f64]) -> bool {
        if !self.has_variance() {
            return false;
        }
        let ny = self.ny();
        for j in 0..self.nu() {
            for i in 0..ny {
                out[j * ny + i] = self.variance(k, i, j).unwrap_or(f64::NAN);
            }
        }
        true
    }
    /// True when the variance is the total variance of a best linear approximation and
    /// its noise part is known (`_var_noise` columns; several realizations averaged).
    fn has_noise_variance(&self) -> bool {
        false
    }
    /// The noise part of the variance of line `k` in `vec` order into `out`; false (and
    /// `out` untouched) when the data carry none.
    fn noise_variance_line_into(&self, _k: usize, _out: &mut [f64]) -> bool {
        false
    }
    /// The matrix `G` at line `k`.
    fn matrix(&self, k: usize) -> Mat<C64> {
        Mat::from_fn(self.ny(), self.nu(), |i, j| self.value(k, i, j))
    }
    /// All values, line after line, each line `vec(G)` (the layout of
    /// [`realize::ResponseGrid`]).
    fn values_vec(&self) -> Vec<C64> {
        let m = self.n_entries();
        let mut v = vec![C64::new(0.0, 0.0); m * self.n_lines()];
        for k in 0..self.n_lines() {
            self.line_into(k, &mut v[k * m..(k + 1) * m]);
        }
        v
    }
    /// All variances in the layout of [`FrfDataset::values_vec`], when present.
    fn variance_vec(&self) -> Option<Vec<f64>> {
        if !self.has_variance() {
            return None;
        }
        let m = self.n_entries();
        let mut v = vec![0.0; m * self.n_lines()];
        for k in 0..self.n_lines() {
            self.variance_line_into(k, &mut v[k * m..(k + 1) * m]);
        }
        Some(v)
    }
    /// An owned copy (an [`Frf`]) of this dataset.
    fn to_frf(&self) -> Frf {
        let mut f = Frf::new(
            self.freqs_hz(),
            self.ny(),
            self.nu(),
            self.values_vec(),
            self.variance_vec(),
        )
        .expect("a valid dataset copies into a valid Frf");
        if self.has_noise_variance() {
            let m = self.n_entries();
            let mut noise = vec![0.0; m * self.n_lines()];
            for k in 0..self.n_lines() {
                self.noise_variance_line_into(k, &mut noise[k * m..(k + 1) * m]);
            }
            f = f
                .with_noise_variance(Some(noise))
                .expect("a valid dataset's noise variance copies into a valid Frf");
        }
        f.units = self.units().map(str::to_string);
        f
    }
}
