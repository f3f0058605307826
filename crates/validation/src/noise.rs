//! The noise level of an FRF: the variance `E|G_hat - G|^2` of every line and entry,
//! from the data's `_var` columns when present, otherwise estimated from the data.
//!
//! **Why an estimate from the data works.** For an FRF measured with periodic
//! excitation (or any estimate whose lines come from disjoint DFT bins), the errors of
//! different frequency lines are asymptotically independent and circular complex
//! Gaussian (McKelvey, "Frequency domain identification methods", *Circuits Systems
//! Signal Process.* 21(1), 2002; Pintelon and Schoukens, *System Identification: A
//! Frequency Domain Approach*, ch. 2 and 7), while the true response is smooth on the
//! scale of the line spacing wherever the lines are dense compared with the modal
//! bandwidths `2 zeta f`. A finite difference of order `p` across neighbouring lines,
//! `D_k = sum_l c_l G_(k+l)`, cancels every polynomial of degree `p - 1` in frequency,
//! so it keeps the noise (`E|D_k|^2 = sum_l c_l^2 sigma^2` for a locally constant
//! `sigma^2`) and nearly none of the signal. For the second difference
//! `G_k - (G_(k-1) + G_(k+1))/2` the factor is `1.5`; [`estimate_noise`] normalises
//! the coefficients to `sum c_l^2 = 1`, so `|D_k|^2` estimates `sigma^2` directly, for
//! any order and for unevenly spaced lines (divided differences on the actual
//! frequencies).
//!
//! `|D_k|^2` of circular Gaussian noise is `sigma^2` times a unit exponential variable,
//! and resonances and the low-frequency end leave signal in a few of them. The estimate
//! is therefore robust, per entry: a pilot **median** over `+-half_window` neighbouring
//! lines divided by `ln 2` (the median of the unit exponential), then the mean of the
//! `|D|^2` in the same window that stay below 4.6 pilots (the 99 % point of the
//! exponential), divided by the mean of the exponential truncated there (0.953). The
//! second step scatters about half as much as the median alone and still drops the
//! lines that carry signal. Where the same estimate over a short window (`+-(order +
//! 1)` lines) is more than 4 times higher, the noise level rises faster than the long
//! window can follow (a narrow noise peak at a lightly damped mode under feedback, the
//! first lines of a closed-loop measurement) and the short-window estimate is used.
//!
//! **Where it is biased** (quantified in the tests):
//! - *Sharp resonances sampled with few lines*: within a few half-power bandwidths of a
//!   resonance the response is not polynomial on the stencil, `|D_k|^2` holds signal and
//!   the estimate is too high (conservative). The median absorbs it while fewer than
//!   half of the window's lines are affected; a mode whose half-power bandwidth spans
//!   only one or two lines, at a high signal-to-noise ratio, inflates the estimate over
//!   roughly `+-(order + 2)` lines around its peak. Higher orders confine the damage to
//!   fewer lines: the signal left in a difference of order `p` at a distance `Delta f`
//!   from a resonance falls like `(df / Delta f)^p`.
//! - *The low-frequency end of a rigid body* (`1/f^2` with `df/f` not small): the first
//!   lines carry curvature that no local polynomial removes; the estimate is too high
//!   there.
//! - *Noise correlated across lines* (windowed, overlapped H1 estimates; leakage of
//!   non-periodic excitation): differences cancel part of the noise and the estimate is
//!   too low.
//! - *Heavy tails*: for noise heavier-tailed than Gaussian the median over-weights the
//!   typical value and underestimates the mean square slightly.
//! - *A noise level that changes quickly across lines* (by more than a factor of ~2
//!   within the window, as under a high-gain controller at low frequency) is smoothed.

use crate::stats::{median_mut, running_median};
use crate::ValidationError;
use frf_data::{FrfDataset, C64};
use serde::{Deserialize, Serialize};

/// Where a [`NoiseLevel`] comes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum NoiseSource {
    /// The data's `_var` columns (the variance of the estimate, for example the sample
    /// variance over realizations divided by their number).
    Measured,
    /// Estimated from the data because they carry no variance; `method` says how (for
    /// reports: the user must know that the noise level was not measured).
    Estimated {
        /// How the variance was estimated.
        method: String,
    },
}

/// The variance of every line and entry of an FRF, in the layout of
/// [`FrfDataset::values_vec`]: line `k`, entry `e = j * ny + i` (output `i`, input `j`)
/// at `variance[k * m + e]`, `m = ny * nu`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseLevel {
    /// `E|G_hat - G|^2` per line and entry, `[k * m + e]`.
    pub variance: Vec<f64>,
    /// Measured or estimated (and how).
    pub source: NoiseSource,
    /// Number of outputs the variance is laid out for.
    pub ny: usize,
    /// Number of inputs the variance is laid out for.
    pub nu: usize,
}

impl NoiseLevel {
    /// Number of entries per line, `ny * nu`.
    pub fn n_entries(&self) -> usize {
        self.ny * self.nu
    }

    /// Number of lines (`variance.len() / (ny * nu)`; 0 for an empty layout).
    pub fn n_lines(&self) -> usize {
        self.variance
            .len()
            .checked_div(self.n_entries())
            .unwrap_or(0)
    }

    /// True when the variance was estimated rather than measured.
    pub fn is_estimated(&self) -> bool {
        matches!(self.source, NoiseSource::Estimated { .. })
    }

    /// The median over lines and entries of `sqrt(variance) / |G|`: the typical relative
    /// noise level of `data` (entries with `G = 0` are skipped; NaN when none is left or
    /// the dimensions disagree).
    pub fn median_relative(&self, data: &(impl FrfDataset + ?Sized)) -> f64 {
        let m = data.n_entries();
        if m != self.n_entries() || data.n_lines() * m != self.variance.len() {
            return f64::NAN;
        }
        let mut line = vec![C64::new(0.0, 0.0); m];
        let mut rel = Vec::with_capacity(self.variance.len());
        for k in 0..data.n_lines() {
            data.line_into(k, &mut line);
            for (e, g) in line.iter().enumerate() {
                let a2 = g.norm_sqr();
                if a2 > 0.0 && a2.is_finite() {
                    rel.push((self.variance[k * m + e].max(0.0) / a2).sqrt());
                }
            }
        }
        median_mut(&mut rel)
    }

    /// Checks that this noise level fits `data` (same outputs, inputs and lines) and
    /// that every variance is finite and `>= 0`.
    pub fn check_against(&self, data: &(impl FrfDataset + ?Sized)) -> Result<(), ValidationError> {
        if self.ny != data.ny() || self.nu != data.nu() {
            return Err(ValidationError::dimension(
                "noise level vs data (outputs x inputs)",
                format!("{}x{} (data)", data.ny(), data.nu()),
                format!("{}x{} (noise level)", self.ny, self.nu),
            ));
        }
        let want = data.n_lines() * data.n_entries();
        if self.variance.len() != want {
            return Err(ValidationError::dimension(
                "noise level vs data (lines x entries)",
                format!(
                    "{want} variances ({} lines x {} entries of the data)",
                    data.n_lines(),
                    data.n_entries()
                ),
                format!("{} variances", self.variance.len()),
            ));
        }
        let m = self.n_entries();
        if let Some((idx, v)) = self
            .variance
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
        {
            let (k, e) = (idx / m, idx % m);
            return Err(ValidationError::invalid_input(
                "noise level",
                format!(
                    "variance {v} at line {k} ({} Hz), entry G{}_{} (must be finite and >= 0)",
                    data.freq_hz(k),
                    e % self.ny + 1,
                    e / self.ny + 1
                ),
            ));
        }
        Ok(())
    }
}

/// Settings of [`estimate_noise`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NoiseConfig {
    /// Order `p` of the finite difference across lines (`p + 1` lines per stencil;
    /// polynomials of degree `p - 1` in frequency cancel). Default 4: on the reference
    /// wafer stage the second difference leaves signal above the noise within ~80 Hz of
    /// every resonance and below ~150 Hz (rigid-body curvature), the fourth within a few
    /// Hz (see the tests); 1 to 8 allowed.
    pub order: usize,
    /// The pilot median and the refined (trimmed) mean run over `+-half_window` lines
    /// (fewer at the band edges). Default 40: with independent Gaussian noise about
    /// 92 % of the lines and entries away from resonances are then within a factor 1.5
    /// of the true variance (the tests; 86 % with 25), and 85-94 % on the reference
    /// wafer stage against its measured variance (neighbouring differences share
    /// noise, so 81 lines hold only about 30 independent estimates), while a noise level
    /// that changes over a few tens of lines is still followed (and a sharper rise by
    /// the short window, see the module documentation).
    pub half_window: usize,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            order: 4,
            half_window: 40,
        }
    }
}

impl NoiseConfig {
    fn check(&self) -> Result<(), ValidationError> {
        if !(1..=8).contains(&self.order) {
            return Err(ValidationError::config(
                "noise.order",
                self.order,
                "the difference order must be 1 to 8",
            ));
        }
        if self.half_window == 0 {
            return Err(ValidationError::config(
                "noise.half_window",
                self.half_window,
                "the median window needs at least one line on each side",
            ));
        }
        Ok(())
    }

    /// The description that goes into [`NoiseSource::Estimated`].
    pub fn method(&self) -> String {
        format!(
            "estimated from the data (no _var columns): order-{} finite differences across \
             neighbouring lines (polynomials of degree {} in frequency cancel), squared \
             magnitude normalised to the noise variance, median over +-{} lines / ln 2 \
             refined by a trimmed mean, per entry; too high near sharp resonances and at a rigid body's lowest lines",
            self.order,
            self.order - 1,
            self.half_window
        )
    }
}

/// The noise level of `data`: its `_var` columns when it carries them
/// ([`NoiseSource::Measured`]), otherwise [`estimate_noise`] with the default
/// [`NoiseConfig`] ([`NoiseSource::Estimated`], saying how).
///
/// Errors: a measured variance that is negative or not finite (only possible for a
/// custom [`FrfDataset`]), and those of [`estimate_noise`].
pub fn noise_level(data: &(impl FrfDataset + ?Sized)) -> Result<NoiseLevel, ValidationError> {
    if let Some(variance) = data.variance_vec() {
        let nl = NoiseLevel {
            variance,
            source: NoiseSource::Measured,
            ny: data.ny(),
            nu: data.nu(),
        };
        nl.check_against(data)?;
        return Ok(nl);
    }
    estimate_noise(data, &NoiseConfig::default())
}

/// Estimates the noise variance of every line and entry of `data` from its roughness
/// across neighbouring lines (see the module documentation), ignoring any `_var`
/// columns. Use it through [`noise_level`], or directly to cross-check a measured
/// variance.
///
/// Errors: fewer than `order + 1` lines; a non-finite frequency or value; an invalid
/// configuration.
pub fn estimate_noise(
    data: &(impl FrfDataset + ?Sized),
    cfg: &NoiseConfig,
) -> Result<NoiseLevel, ValidationError> {
    cfg.check()?;
    let (n, ny, nu) = (data.n_lines(), data.ny(), data.nu());
    let m = ny * nu;
    let p = cfg.order;
    if n < p + 1 {
        return Err(ValidationError::TooFewLines {
            what: format!("estimating the noise with order-{p} differences"),
            needed: p + 1,
            got: n,
        });
    }
    let f = data.freqs_hz();
    let values = data.values_vec();
    if let Some(k) = f.iter().position(|x| !x.is_finite()) {
        return Err(ValidationError::invalid_input(
            "data",
            format!("frequency of line {k} is not finite"),
        ));
    }
    if let Some(idx) = values
        .iter()
        .position(|z| !(z.re.is_finite() && z.im.is_finite()))
    {
        return Err(ValidationError::invalid_input(
            "data",
            format!("non-finite value at line {}, entry {}", idx / m, idx % m),
        ));
    }
    // Raw estimates r[e * n + k] = |D_k|^2 with sum c^2 = 1 (entry-major, so the median
    // windows are contiguous).
    let mut raw = vec![0.0; n * m];
    let mut coef = vec![0.0; p + 1];
    for k in 0..n {
        let start = k.saturating_sub(p / 2).min(n - p - 1);
        if !difference_coefficients(&f[start..start + p + 1], &mut coef) {
            return Err(ValidationError::invalid_input(
                "data",
                format!(
                    "frequencies {}..{} Hz are not distinct",
                    f[start],
                    f[start + p]
                ),
            ));
        }
        for e in 0..m {
            let mut d = C64::new(0.0, 0.0);
            for (l, c) in coef.iter().enumerate() {
                d += values[(start + l) * m + e] * *c;
            }
            raw[e * n + k] = d.norm_sqr();
        }
    }
    let h = cfg.half_window;
    let hs = (p + 1).min(h);
    let mut variance = vec![0.0; n * m];
    for e in 0..m {
        let r = &raw[e * n..(e + 1) * n];
        let long = robust_mean(r, h);
        let short = robust_mean(r, hs);
        for k in 0..n {
            // A noise level that rises sharply within the long window (a narrow peak of
            // the noise at a lightly damped mode under feedback, the first lines of a
            // closed-loop measurement) is missed by the long median: take the short
            // window where it is more than SHORT_OVER_LONG times higher (a stationary
            // noise level does that at ~5e-4 of the lines).
            variance[k * m + e] = if short[k] > SHORT_OVER_LONG * long[k] {
                short[k]
            } else {
                long[k]
            };
        }
    }
    Ok(NoiseLevel {
        variance,
        source: NoiseSource::Estimated {
            method: cfg.method(),
        },
        ny,
        nu,
    })
}

/// The robust mean of the raw estimates `r` (`sigma^2` times unit exponentials) over
/// `+-h` lines: a pilot running median / ln 2, then the mean of the values below
/// [`TRIM_AT`] pilots divided by the mean of the truncated unit exponential (the pilot
/// where fewer than half the values are kept).
fn robust_mean(r: &[f64], h: usize) -> Vec<f64> {
    let n = r.len();
    let t = TRIM_AT;
    let keep_mean = 1.0 - t * (-t).exp() / (1.0 - (-t).exp());
    let pilot = running_median(r, h);
    (0..n)
        .map(|k| {
            let pk = pilot[k] / std::f64::consts::LN_2;
            let a = k.saturating_sub(h);
            let b = (k + h + 1).min(n);
            let cut = t * pk;
            let (mut s, mut c) = (0.0, 0usize);
            for &x in &r[a..b] {
                if x <= cut {
                    s += x;
                    c += 1;
                }
            }
            if 2 * c >= b - a && c > 0 {
                s / c as f64 / keep_mean
            } else {
                pk
            }
        })
        .collect()
}

/// See [`estimate_noise`]: the short-window estimate replaces the long one where it is
/// this many times higher.
const SHORT_OVER_LONG: f64 = 4.0;

/// Raw estimates above this many pilot variances are left out of the refined mean: the
/// unit exponential exceeds 4.6 with probability 1 %, so noise loses little, while lines
/// that carry signal (resonances) are dropped.
const TRIM_AT: f64 = 4.6;

/// The coefficients of the divided difference of order `x.len() - 1` on the abscissae
/// `x` (`c_l = 1 / prod_(m != l) (x_l - x_m)`, which annihilates every polynomial of
/// degree below the order), normalised to `sum c_l^2 = 1`. False when two abscissae
/// coincide.
pub(crate) fn difference_coefficients(x: &[f64], c: &mut [f64]) -> bool {
    let q = x.len();
    // Normalised abscissae for conditioning.
    let x0 = x[0];
    let span = x[q - 1] - x0;
    if !(span > 0.0 && span.is_finite()) {
        return false;
    }
    for l in 0..q {
        let mut prod = 1.0;
        for mm in 0..q {
            if mm != l {
                prod *= (x[l] - x[mm]) / span;
            }
        }
        if prod == 0.0 || !prod.is_finite() {
            return false;
        }
        c[l] = 1.0 / prod;
    }
    let norm = c.iter().map(|v| v * v).sum::<f64>().sqrt();
    for v in c.iter_mut() {
        *v /= norm;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coefficients_cancel_polynomials() {
        let x = [1.0, 1.5, 2.5, 2.75, 4.0];
        let mut c = [0.0; 5];
        assert!(difference_coefficients(&x, &mut c));
        assert!((c.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
        for deg in 0..4 {
            let s: f64 = x.iter().zip(&c).map(|(xi, ci)| ci * xi.powi(deg)).sum();
            assert!(s.abs() < 1e-10, "degree {deg}: {s}");
        }
        let s4: f64 = x.iter().zip(&c).map(|(xi, ci)| ci * xi.powi(4)).sum();
        assert!(s4.abs() > 1e-3);
        // Uniform second difference: (1, -2, 1) / sqrt(6), i.e. the G_k - (G_k-1 +
        // G_k+1)/2 of the module documentation up to its factor 1.5.
        let mut c3 = [0.0; 3];
        assert!(difference_coefficients(&[0.0, 1.0, 2.0], &mut c3));
        let r = 6f64.sqrt();
        assert!((c3[0].abs() - 1.0 / r).abs() < 1e-12 && (c3[1].abs() - 2.0 / r).abs() < 1e-12);
        assert!(!difference_coefficients(&[1.0, 1.0, 2.0], &mut c3));
    }
}
