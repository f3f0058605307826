//! The DFT of periodic records (McKelvey, Section 2.2, eq. (8): for a periodic input
//! applied long enough, the DFT of one period at `w_k = 2 pi k / N` relates input and
//! output exactly; the transient term decays) and the grid of excited lines.
//!
//! Convention: unnormalised, `X_k = sum_{t=0}^{N-1} x_t exp(-j 2 pi k t / N)` (as
//! MATLAB's and numpy's `fft`, and the periodic spectra CSV of `FORMATS.md`). Ratios
//! such as `G = Y / U` do not depend on it.

use frf_data::{FrfError, C64};
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// The excited DFT lines of a periodic experiment: sample rate, samples per period and
/// the excited bins `k` (frequency `k fs / N`).
#[derive(Debug, Clone, PartialEq)]
pub struct LineGrid {
    fs: f64,
    period: usize,
    bins: Vec<usize>,
}

impl LineGrid {
    /// A grid of the given bins; checks `fs > 0`, `N >= 4`, at least one bin, bins
    /// strictly increasing and strictly between 0 and `N / 2`.
    pub fn from_bins(fs: f64, period: usize, bins: Vec<usize>) -> Result<Self, FrfError> {
        if !(fs.is_finite() && fs > 0.0) {
            return Err(FrfError::invalid("fs", fs, "must be finite and > 0 Hz"));
        }
        if period < 4 {
            return Err(FrfError::invalid(
                "period",
                period,
                "a period needs at least 4 samples",
            ));
        }
        if bins.is_empty() {
            return Err(FrfError::invalid(
                "excited lines",
                "none",
                "the excitation has no excited lines: widen the band or lengthen the period",
            ));
        }
        for (i, &b) in bins.iter().enumerate() {
            if b == 0 || 2 * b >= period {
                return Err(FrfError::invalid(
                    "excited line",
                    b,
                    format!(
                        "bins must lie strictly between 0 and N/2 = {} (DC and Nyquist are not used)",
                        period / 2
                    ),
                ));
            }
            if i > 0 && b <= bins[i - 1] {
                return Err(FrfError::invalid(
                    "excited lines",
                    b,
                    "bins must be strictly increasing",
                ));
            }
        }
        Ok(Self { fs, period, bins })
    }

    /// The odd lines `k = 1, 3, 5, ...` with `f_min_hz <= k fs / N <= f_max_hz` (an odd
    /// multisine: the even lines stay free to detect even nonlinear distortions). With
    /// `fs = 10 kHz`, `N = 40000` and `f_max = 2000 Hz` these are the 4000 lines
    /// 0.25, 0.75, ..., 1999.75 Hz of the reference wafer-stage data.
    pub fn odd(fs: f64, period: usize, f_min_hz: f64, f_max_hz: f64) -> Result<Self, FrfError> {
        Self::band(fs, period, f_min_hz, f_max_hz, true)
    }

    /// Every line `k >= 1` with `f_min_hz <= k fs / N <= f_max_hz`.
    pub fn full(fs: f64, period: usize, f_min_hz: f64, f_max_hz: f64) -> Result<Self, FrfError> {
        Self::band(fs, period, f_min_hz, f_max_hz, false)
    }

    fn band(fs: f64, period: usize, lo: f64, hi: f64, odd: bool) -> Result<Self, FrfError> {
        if !(fs.is_finite() && fs > 0.0) {
            return Err(FrfError::invalid("fs", fs, "must be finite and > 0 Hz"));
        }
        if !(lo.is_finite() && hi.is_finite() && hi >= lo) {
            return Err(FrfError::invalid(
                "excitation band",
                format!("{lo}..{hi} Hz"),
                "needs finite edges with lo <= hi",
            ));
        }
        let df = fs / period.max(1) as f64;
        let bins: Vec<usize> = (1..period.div_ceil(2))
            .filter(|&k| !odd || k % 2 == 1)
            .filter(|&k| {
                let f = k as f64 * df;
                f >= lo * (1.0 - 1e-12) && f <= hi * (1.0 + 1e-12)
            })
            .collect();
        if bins.is_empty() {
            return Err(FrfError::invalid(
                "excited lines",
                format!("{lo}..{hi} Hz with df = {df} Hz"),
                "no excited lines: the band holds no (odd) DFT line of the period",
            ));
        }
        Self::from_bins(fs, period, bins)
    }

    /// Sample rate, Hz.
    pub fn fs(&self) -> f64 {
        self.fs
    }
    /// Samples per period `N`.
    pub fn period(&self) -> usize {
        self.period
    }
    /// The excited bins.
    pub fn bins(&self) -> &[usize] {
        &self.bins
    }
    /// Number of excited lines.
    pub fn n_lines(&self) -> usize {
        self.bins.len()
    }
    /// Frequency resolution `fs / N`, Hz.
    pub fn df(&self) -> f64 {
        self.fs / self.period as f64
    }
    /// Frequencies of the excited lines, Hz.
    pub fn freq_hz(&self) -> Vec<f64> {
        self.bins.iter().map(|&k| k as f64 * self.df()).collect()
    }
}

/// A planned complex FFT of length `N` used on real records, two at a time.
#[derive(Clone)]
pub(crate) struct RealPairFft {
    n: usize,
    fwd: Arc<dyn Fft<f64>>,
    inv: Arc<dyn Fft<f64>>,
}

impl std::fmt::Debug for RealPairFft {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RealPairFft({})", self.n)
    }
}

impl RealPairFft {
    pub fn new(n: usize) -> Self {
        let mut p = FftPlanner::new();
        Self {
            n,
            fwd: p.plan_fft_forward(n),
            inv: p.plan_fft_inverse(n),
        }
    }

    /// The DFT of the real records `x1` and `x2` (length `N`; `x2` may be absent) at
    /// `bins` into `out1` and `out2`, from one complex FFT of `x1 + j x2`:
    /// `X1_k = (Z_k + conj Z_{N-k}) / 2`, `X2_k = (Z_k - conj Z_{N-k}) / (2 j)`.
    pub fn forward_pair(
        &self,
        x1: &[f64],
        x2: Option<&[f64]>,
        bins: &[usize],
        buf: &mut Vec<C64>,
        out1: &mut [C64],
        out2: &mut [C64],
    ) {
        let n = self.n;
        buf.clear();
        match x2 {
            Some(x2) => buf.extend(x1.iter().zip(x2).map(|(&a, &b)| C64::new(a, b))),
            None => buf.extend(x1.iter().map(|&a| C64::new(a, 0.0))),
        }
        self.fwd.process(buf);
        for (i, &k) in bins.iter().enumerate() {
            let zk = buf[k % n];
            let zc = buf[(n - k % n) % n].conj();
            out1[i] = (zk + zc) * 0.5;
            if x2.is_some() {
                out2[i] = (zk - zc) * C64::new(0.0, -0.5);
            }
        }
    }

    /// Real records from half spectra: `spec1`, `spec2` hold bins `0..=N/2` of two
    /// Hermitian spectra; `x1`, `x2` (length `N`) receive `IDFT / N`.
    pub fn inverse_pair(
        &self,
        spec1: &[C64],
        spec2: Option<&[C64]>,
        buf: &mut Vec<C64>,
        x1: &mut [f64],
        x2: Option<&mut [f64]>,
    ) {
        let n = self.n;
        buf.clear();
        buf.resize(n, C64::new(0.0, 0.0));
        let j = C64::new(0.0, 1.0);
        let half = n / 2;
        for k in 0..=half.min(spec1.len().saturating_sub(1)) {
            let a = spec1[k];
            let b = spec2.map_or(C64::new(0.0, 0.0), |s| s[k]);
            buf[k] = a + j * b;
            if k != 0 && 2 * k != n {
                buf[n - k] = a.conj() + j * b.conj();
            }
        }
        self.inv.process(buf);
        let inv_n = 1.0 / n as f64;
        for t in 0..n {
            x1[t] = buf[t].re * inv_n;
        }
        if let Some(x2) = x2 {
            for t in 0..n {
                x2[t] = buf[t].im * inv_n;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odd_grid_of_the_reference_wafer_stage() {
        let g = LineGrid::odd(10_000.0, 40_000, 0.0, 2000.0).unwrap();
        assert_eq!(g.n_lines(), 4000);
        let f = g.freq_hz();
        assert_eq!(f[0], 0.25);
        assert_eq!(f[1], 0.75);
        assert_eq!(*f.last().unwrap(), 1999.75);
    }

    #[test]
    fn empty_bands_are_errors() {
        assert!(LineGrid::odd(10_000.0, 40_000, 3000.0, 2500.0).is_err());
        assert!(LineGrid::odd(10_000.0, 40_000, 0.3, 0.7).is_err());
        assert!(LineGrid::from_bins(1.0, 10, vec![]).is_err());
        assert!(LineGrid::from_bins(1.0, 10, vec![5]).is_err());
    }

    #[test]
    fn pair_fft_matches_a_direct_dft_and_inverts() {
        let n = 30;
        let x1: Vec<f64> = (0..n).map(|t| ((t * 7 % 11) as f64).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|t| ((t * 3 % 5) as f64) - 2.0).collect();
        let f = RealPairFft::new(n);
        let bins: Vec<usize> = (0..n).collect();
        let (mut o1, mut o2) = (vec![C64::new(0.0, 0.0); n], vec![C64::new(0.0, 0.0); n]);
        let mut buf = Vec::new();
        f.forward_pair(&x1, Some(&x2), &bins, &mut buf, &mut o1, &mut o2);
        for k in 0..n {
            let d = |x: &[f64]| -> C64 {
                (0..n)
                    .map(|t| {
                        x[t] * C64::from_polar(
                            1.0,
                            -std::f64::consts::TAU * (k * t) as f64 / n as f64,
                        )
                    })
                    .sum()
            };
            assert!((o1[k] - d(&x1)).norm() < 1e-12);
            assert!((o2[k] - d(&x2)).norm() < 1e-12);
        }
        let (mut y1, mut y2) = (vec![0.0; n], vec![0.0; n]);
        f.inverse_pair(
            &o1[..=n / 2],
            Some(&o2[..=n / 2]),
            &mut buf,
            &mut y1,
            Some(&mut y2),
        );
        for t in 0..n {
            assert!((y1[t] - x1[t]).abs() < 1e-12 && (y2[t] - x2[t]).abs() < 1e-12);
        }
    }
}
