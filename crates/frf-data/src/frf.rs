//! [`Frf`]: the owning FRF container.

use crate::{FrfDataset, FrfError, FrfView, C64};
use realize::ResponseGrid;
use std::collections::BTreeMap;

/// An owned FRF: frequencies (Hz), one `ny x nu` complex matrix per line, an optional
/// per-entry variance, units and free metadata.
///
/// Values are stored line after line, each line column-major (`vec(G)`): entry
/// `(i, j)` of line `k` is `values[k * ny * nu + j * ny + i]`, the layout of
/// [`realize::ResponseGrid`].
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    freq_hz: Vec<f64>,
    ny: usize,
    nu: usize,
    values: Vec<C64>,
    variance: Option<Vec<f64>>,
    /// The noise part of `variance` (from the spread over periods) when `variance` is the
    /// total variance of a best linear approximation (from the spread over
    /// realizations): `variance - noise_variance` is the nonlinear distortion's part.
    noise_variance: Option<Vec<f64>>,
    /// Units of `G`, for example `m/N`.
    pub units: Option<String>,
    /// Free `key=value` metadata (from CSV comment lines, UFF headers, the simulator).
    pub metadata: BTreeMap<String, String>,
    /// Free-text comment lines (without the leading `#`).
    pub comments: Vec<String>,
    /// Where the data came from (a path), when known.
    pub source: Option<String>,
}

impl Frf {
    /// Builds an FRF after checking it: `values.len() == n * ny * nu`, frequencies finite,
    /// `>= 0` and strictly increasing, values finite, variances finite and `>= 0`.
    pub fn new(
        freq_hz: Vec<f64>,
        ny: usize,
        nu: usize,
        values: Vec<C64>,
        variance: Option<Vec<f64>>,
    ) -> Result<Self, FrfError> {
        let n = freq_hz.len();
        let m = ny * nu;
        if m == 0 {
            return Err(FrfError::invalid(
                "dimensions",
                format!("{ny}x{nu}"),
                "an FRF needs at least one output and one input",
            ));
        }
        if values.len() != n * m {
            return Err(FrfError::Dimension {
                what: "FRF values".into(),
                expected: format!("{} ({} lines x {ny}x{nu})", n * m, n),
                got: values.len().to_string(),
            });
        }
        if let Some(v) = &variance {
            check_variance_len(v, n * m, "FRF variance")?;
        }
        for (k, &f) in freq_hz.iter().enumerate() {
            if !f.is_finite() || f < 0.0 {
                return Err(FrfError::InvalidData {
                    why: format!("frequency of line {k} is {f} Hz (must be finite and >= 0)"),
                });
            }
            if k > 0 && f <= freq_hz[k - 1] {
                return Err(FrfError::InvalidData {
                    why: format!(
                        "frequencies not strictly increasing at line {k}: {} then {f} Hz",
                        freq_hz[k - 1]
                    ),
                });
            }
        }
        for (idx, z) in values.iter().enumerate() {
            if !(z.re.is_finite() && z.im.is_finite()) {
                let (k, e) = (idx / m, idx % m);
                return Err(FrfError::InvalidData {
                    why: format!(
                        "non-finite value {z} at line {k} ({} Hz), entry G{}_{}",
                        freq_hz[k],
                        e % ny + 1,
                        e / ny + 1
                    ),
                });
            }
        }
        if let Some(v) = &variance {
            check_variance_values(v, &freq_hz, ny, nu, "variance")?;
        }
        Ok(Self {
            freq_hz,
            ny,
            nu,
            values,
            variance,
            noise_variance: None,
            units: None,
            metadata: BTreeMap::new(),
            comments: Vec::new(),
            source: None,
        })
    }

    /// Builds an FRF from a function of `(line, output, input)`.
    pub fn from_fn(
        freq_hz: Vec<f64>,
        ny: usize,
        nu: usize,
        f: impl Fn(usize, usize, usize) -> C64,
    ) -> Result<Self, FrfError> {
        let n = freq_hz.len();
        let mut values = Vec::with_capacity(n * ny * nu);
        for k in 0..n {
            for j in 0..nu {
                for i in 0..ny {
                    values.push(f(k, i, j));
                }
            }
        }
        Self::new(freq_hz, ny, nu, values, None)
    }

    /// Wraps a model response (for example [`realize::ModalModel::zoh_response`]) at the
    /// frequencies `freq_hz`.
    pub fn from_grid(freq_hz: Vec<f64>, grid: ResponseGrid) -> Result<Self, FrfError> {
        Self::new(freq_hz, grid.ny, grid.nu, grid.values, None)
    }

    /// Sets (or removes) the variance; checked like in [`Frf::new`]. A noise variance is
    /// kept when the new variance is present (and removed with it).
    pub fn with_variance(self, variance: Option<Vec<f64>>) -> Result<Self, FrfError> {
        let Frf {
            freq_hz,
            ny,
            nu,
            values,
            noise_variance,
            units,
            metadata,
            comments,
            source,
            ..
        } = self;
        let keep_noise = variance.is_some();
        let mut f = Frf::new(freq_hz, ny, nu, values, variance)?;
        if keep_noise {
            f.noise_variance = noise_variance;
        }
        f.units = units;
        f.metadata = metadata;
        f.comments = comments;
        f.source = source;
        Ok(f)
    }

    /// Sets (or removes) the noise part of the variance (see [`Frf::noise_variances`]):
    /// it needs the (total) variance beside it, the same layout, finite values `>= 0`.
    pub fn with_noise_variance(mut self, noise: Option<Vec<f64>>) -> Result<Self, FrfError> {
        if let Some(v) = &noise {
            if self.variance.is_none() {
                return Err(FrfError::invalid(
                    "noise variance",
                    "given",
                    "a noise variance (`_var_noise`) needs the total variance (`_var`) beside it",
                ));
            }
            check_variance_len(
                v,
                self.freq_hz.len() * self.ny * self.nu,
                "FRF noise variance",
            )?;
            check_variance_values(v, &self.freq_hz, self.ny, self.nu, "noise variance")?;
        }
        self.noise_variance = noise;
        Ok(self)
    }

    /// The noise part of the variance (layout of [`Frf::values`]) when the variance is
    /// the total variance of a best linear approximation estimated from several
    /// realizations; `None` otherwise (then the variance, if any, is what it is).
    pub fn noise_variances(&self) -> Option<&[f64]> {
        self.noise_variance.as_deref()
    }

    /// The frequencies, Hz.
    pub fn freq_hz_slice(&self) -> &[f64] {
        &self.freq_hz
    }
    /// The values in the layout described on [`Frf`].
    pub fn values(&self) -> &[C64] {
        &self.values
    }
    /// The variances in the layout of [`Frf::values`], when present.
    pub fn variances(&self) -> Option<&[f64]> {
        self.variance.as_deref()
    }
    /// `vec(G)` of line `k` as a slice.
    pub fn line(&self, k: usize) -> &[C64] {
        let m = self.ny * self.nu;
        &self.values[k * m..(k + 1) * m]
    }
    /// A view of the whole dataset.
    pub fn view(&self) -> FrfView<'_> {
        FrfView::full(self)
    }
    /// A zero-copy view of the lines with `lo_hz <= f <= hi_hz`.
    pub fn band(&self, lo_hz: f64, hi_hz: f64) -> Result<FrfView<'_>, FrfError> {
        self.view().band(lo_hz, hi_hz)
    }
    /// A zero-copy view of the given outputs and inputs (0-based indices).
    pub fn select(&self, outputs: &[usize], inputs: &[usize]) -> Result<FrfView<'_>, FrfError> {
        self.view().select(outputs, inputs)
    }
    /// Multiplies line `k` by `factor(k)` (for example a delay compensation
    /// `exp(j w tau)`); variances scale by `|factor|^2`.
    pub fn scale_lines(&mut self, factor: impl Fn(usize) -> C64) {
        let m = self.ny * self.nu;
        for k in 0..self.freq_hz.len() {
            let f = factor(k);
            for v in &mut self.values[k * m..(k + 1) * m] {
                *v *= f;
            }
            let s = f.norm_sqr();
            for var in [&mut self.variance, &mut self.noise_variance]
                .into_iter()
                .flatten()
            {
                for v in &mut var[k * m..(k + 1) * m] {
                    *v *= s;
                }
            }
        }
    }
}

/// `v` holds `expected` values (the layout of [`Frf::values`]).
fn check_variance_len(v: &[f64], expected: usize, what: &str) -> Result<(), FrfError> {
    if v.len() != expected {
        return Err(FrfError::Dimension {
            what: what.into(),
            expected: expected.to_string(),
            got: v.len().to_string(),
        });
    }
    Ok(())
}

/// Every value of `v` (a variance `what` in the layout of [`Frf::values`]) is finite
/// and `>= 0`; the first that is not is an error naming its line and entry.
fn check_variance_values(
    v: &[f64],
    freq_hz: &[f64],
    ny: usize,
    nu: usize,
    what: &str,
) -> Result<(), FrfError> {
    let m = ny * nu;
    match v.iter().position(|x| !x.is_finite() || *x < 0.0) {
        Some(idx) => {
            let (k, e) = (idx / m, idx % m);
            Err(FrfError::InvalidData {
                why: format!(
                    "{what} {} at line {k} ({} Hz), entry G{}_{} (must be finite and >= 0)",
                    v[idx],
                    freq_hz[k],
                    e % ny + 1,
                    e / ny + 1
                ),
            })
        }
        None => Ok(()),
    }
}

impl FrfDataset for Frf {
    fn ny(&self) -> usize {
        self.ny
    }
    fn nu(&self) -> usize {
        self.nu
    }
    fn n_lines(&self) -> usize {
        self.freq_hz.len()
    }
    #[inline]
    fn freq_hz(&self, k: usize) -> f64 {
        self.freq_hz[k]
    }
    #[inline]
    fn value(&self, k: usize, i: usize, j: usize) -> C64 {
        self.values[k * self.ny * self.nu + j * self.ny + i]
    }
    #[inline]
    fn variance(&self, k: usize, i: usize, j: usize) -> Option<f64> {
        self.variance
            .as_ref()
            .map(|v| v[k * self.ny * self.nu + j * self.ny + i])
    }
    fn has_variance(&self) -> bool {
        self.variance.is_some()
    }
    fn units(&self) -> Option<&str> {
        self.units.as_deref()
    }
    fn line_into(&self, k: usize, out: &mut [C64]) {
        out.copy_from_slice(self.line(k));
    }
    fn freqs_hz(&self) -> Vec<f64> {
        self.freq_hz.clone()
    }
    fn values_vec(&self) -> Vec<C64> {
        self.values.clone()
    }
    fn variance_vec(&self) -> Option<Vec<f64>> {
        self.variance.clone()
    }
    fn to_frf(&self) -> Frf {
        self.clone()
    }
    fn has_noise_variance(&self) -> bool {
        self.noise_variance.is_some()
    }
    fn noise_variance_line_into(&self, k: usize, out: &mut [f64]) -> bool {
        let Some(v) = &self.noise_variance else {
            return false;
        };
        let m = self.ny * self.nu;
        out.copy_from_slice(&v[k * m..(k + 1) * m]);
        true
    }
}
