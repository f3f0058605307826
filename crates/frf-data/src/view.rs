//! [`FrfView`]: a band and/or a subset of entries of an [`Frf`], without copying data.

use crate::{Frf, FrfDataset, FrfError, C64};
use std::ops::Range;

/// A zero-copy view of an [`Frf`]: a contiguous range of lines and a selection of
/// outputs and inputs (in the order given). Views of views compose.
#[derive(Debug, Clone)]
pub struct FrfView<'a> {
    base: &'a Frf,
    lines: Range<usize>,
    outputs: Vec<usize>,
    inputs: Vec<usize>,
}

impl<'a> FrfView<'a> {
    /// The whole of `base`.
    pub fn full(base: &'a Frf) -> Self {
        Self {
            base,
            lines: 0..base.n_lines(),
            outputs: (0..base.ny()).collect(),
            inputs: (0..base.nu()).collect(),
        }
    }

    /// The underlying dataset.
    pub fn base(&self) -> &'a Frf {
        self.base
    }

    /// The range of lines of the base dataset this view covers.
    pub fn line_range(&self) -> Range<usize> {
        self.lines.clone()
    }

    /// The lines of this view with `lo_hz <= f <= hi_hz`. Fails when none is left, or
    /// when `lo_hz > hi_hz` or either is not finite.
    pub fn band(&self, lo_hz: f64, hi_hz: f64) -> Result<FrfView<'a>, FrfError> {
        if !(lo_hz.is_finite() && hi_hz.is_finite()) || lo_hz > hi_hz {
            return Err(FrfError::invalid(
                "band",
                format!("{lo_hz}:{hi_hz}"),
                "needs finite edges with LO <= HI (Hz)",
            ));
        }
        let f = self.base.freq_hz_slice();
        let slice = &f[self.lines.clone()];
        let start = self.lines.start + slice.partition_point(|&x| x < lo_hz);
        let end = self.lines.start + slice.partition_point(|&x| x <= hi_hz);
        if start >= end {
            let (dlo, dhi) = if slice.is_empty() {
                (f64::NAN, f64::NAN)
            } else {
                (slice[0], slice[slice.len() - 1])
            };
            return Err(FrfError::EmptyBand {
                lo_hz,
                hi_hz,
                data_lo_hz: dlo,
                data_hi_hz: dhi,
            });
        }
        Ok(FrfView {
            base: self.base,
            lines: start..end,
            outputs: self.outputs.clone(),
            inputs: self.inputs.clone(),
        })
    }

    /// A subset of this view's outputs and inputs (0-based indices into this view).
    pub fn select(&self, outputs: &[usize], inputs: &[usize]) -> Result<FrfView<'a>, FrfError> {
        if outputs.is_empty() || inputs.is_empty() {
            return Err(FrfError::invalid(
                "entry selection",
                format!("{} outputs, {} inputs", outputs.len(), inputs.len()),
                "select at least one output and one input",
            ));
        }
        let map = |sel: &[usize], have: &[usize], what: &str| -> Result<Vec<usize>, FrfError> {
            sel.iter()
                .map(|&i| {
                    have.get(i).copied().ok_or_else(|| {
                        FrfError::invalid(
                            what,
                            i + 1,
                            format!("the data have {} {what}s (1-based index)", have.len()),
                        )
                    })
                })
                .collect()
        };
        Ok(FrfView {
            base: self.base,
            lines: self.lines.clone(),
            outputs: map(outputs, &self.outputs, "output")?,
            inputs: map(inputs, &self.inputs, "input")?,
        })
    }
}

impl FrfDataset for FrfView<'_> {
    fn ny(&self) -> usize {
        self.outputs.len()
    }
    fn nu(&self) -> usize {
        self.inputs.len()
    }
    fn n_lines(&self) -> usize {
        self.lines.len()
    }
    #[inline]
    fn freq_hz(&self, k: usize) -> f64 {
        self.base.freq_hz(self.lines.start + k)
    }
    #[inline]
    fn value(&self, k: usize, i: usize, j: usize) -> C64 {
        self.base
            .value(self.lines.start + k, self.outputs[i], self.inputs[j])
    }
    #[inline]
    fn variance(&self, k: usize, i: usize, j: usize) -> Option<f64> {
        self.base
            .variance(self.lines.start + k, self.outputs[i], self.inputs[j])
    }
    fn has_variance(&self) -> bool {
        self.base.has_variance()
    }
    fn units(&self) -> Option<&str> {
        self.base.units()
    }
    fn has_noise_variance(&self) -> bool {
        self.base.has_noise_variance()
    }
    fn noise_variance_line_into(&self, k: usize, out: &mut [f64]) -> bool {
        let Some(v) = self.base.noise_variances() else {
            return false;
        };
        let (bny, bm) = (self.base.ny(), self.base.n_entries());
        let row = &v[(self.lines.start + k) * bm..(self.lines.start + k + 1) * bm];
        let ny = self.outputs.len();
        for (j, &bj) in self.inputs.iter().enumerate() {
            for (i, &bi) in self.outputs.iter().enumerate() {
                out[j * ny + i] = row[bj * bny + bi];
            }
        }
        true
    }
}
