//! The data as the fits use them: the known scalar factor divided out, the weights
//! carried along.

use crate::SkError;
use frf_data::{FrfDataset, Weighting};
use realize::{KnownFactors, C64};

/// Data with the known scalar factor `F(w)` (delay, derivative order, `sinc` hold) of
/// [`KnownFactors::scalar_at`] divided out: `G~ = G / F` with weights `w |F|^2`, so that
/// `sum w |G - F P|^2 = sum w~ |G~ - P|^2` (the weighted cost is unchanged).
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Angular frequencies, rad/s.
    pub omegas: Vec<f64>,
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// `G~`, line after line, each line `vec(G)` (column-major).
    pub g: Vec<C64>,
    /// The weights `w~`, same layout.
    pub w: Vec<f64>,
}

impl Prepared {
    /// `data` with `factors`' scalar factor divided out, weighted by `weighting`.
    ///
    /// Fails on a line where the factor vanishes (`w = 0` with a derivative order), on
    /// non-finite data with a non-zero weight, and when the weighting fails.
    pub fn new<D: FrfDataset + ?Sized>(
        data: &D,
        weighting: &Weighting,
        factors: &KnownFactors,
    ) -> Result<Self, SkError> {
        let w0 = weighting.resolve(data).weights(data)?;
        let (l, m) = (data.n_lines(), data.n_entries());
        let omegas = data.omegas();
        let mut g = data.values_vec();
        let mut w = w0;
        for k in 0..l {
            let f = factors.scalar_at(omegas[k]);
            let a = f.norm_sqr();
            if !(a > 0.0 && a.is_finite()) {
                return Err(SkError::config(
                    "known factor",
                    format!("{f} at line {k} ({} Hz)", data.freq_hz(k)),
                    "the delay/derivative/hold factor vanishes or is not finite there: \
                     leave that line out of the band",
                ));
            }
            for e in 0..m {
                let idx = k * m + e;
                if w[idx] > 0.0 && !(g[idx].re.is_finite() && g[idx].im.is_finite()) {
                    return Err(SkError::config(
                        "data value",
                        g[idx],
                        format!(
                            "line {k} ({} Hz), entry ({}, {}) is not finite",
                            data.freq_hz(k),
                            e % data.ny() + 1,
                            e / data.ny() + 1
                        ),
                    ));
                }
                g[idx] /= f;
                w[idx] *= a;
            }
        }
        Ok(Self {
            omegas,
            ny: data.ny(),
            nu: data.nu(),
            g,
            w,
        })
    }

    /// Number of lines.
    pub fn n_lines(&self) -> usize {
        self.omegas.len()
    }

    /// Number of entries `ny nu`.
    pub fn m(&self) -> usize {
        self.ny * self.nu
    }

    /// The weighted energy `sum w |G~|^2` (the cost of the zero model).
    pub fn energy(&self) -> f64 {
        self.g
            .iter()
            .zip(&self.w)
            .map(|(g, w)| w * g.norm_sqr())
            .sum()
    }

    /// Every `step`-th line (the first, then every `step`-th after it): the same data on
    /// a coarser grid (`step` 0 or 1: all lines).
    pub fn every(&self, step: usize) -> Prepared {
        let step = step.max(1);
        let m = self.m();
        let keep: Vec<usize> = (0..self.n_lines()).step_by(step).collect();
        Prepared {
            omegas: keep.iter().map(|&k| self.omegas[k]).collect(),
            ny: self.ny,
            nu: self.nu,
            g: keep
                .iter()
                .flat_map(|&k| self.g[k * m..(k + 1) * m].iter().copied())
                .collect(),
            w: keep
                .iter()
                .flat_map(|&k| self.w[k * m..(k + 1) * m].iter().copied())
                .collect(),
        }
    }

    /// The band, rad/s.
    pub fn band(&self) -> (f64, f64) {
        let lo = self.omegas.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self.omegas.iter().copied().fold(0.0, f64::max);
        (lo, hi)
    }
}
