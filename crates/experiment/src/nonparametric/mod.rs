//! Nonparametric FRF estimation from periodic experiments.
//!
//! The data are DFT spectra of whole periods of the reference `r`, the input `u` and the
//! output `y` at the excited lines, for `n_experiments` experiments (one per input in the
//! single-axis MIMO design), `R` realizations of the random-phase multisine and `P`
//! periods each ([`PeriodicSpectra`], [`RealizationSpectra`]). They come from the
//! simulator ([`crate::synth`]), from a periodic spectra CSV ([`spectra_csv`]) or from
//! measured time records ([`time_records`], [`crate::matfile`]).
//!
//! The estimator ([`estimate`], [`Accumulator`]) averages over periods per realization
//! (McKelvey, eq. (21)), forms the MIMO estimate `G = Y U^-1` per line from the
//! experiments (closed-loop safe: the indirect method with the reference `r` gives the
//! same `T_yr T_ur^-1 = Y U^-1`), takes the mean over realizations and reports the
//! variance from the period-to-period spread (noise) and from the realization spread
//! (noise + stochastic nonlinear distortions), and the output disturbance covariance
//! `C_v(w)` per line for the Oomen-Bosgra disturbance model.

pub mod dft;
pub mod estimate;
pub(crate) mod small;
pub mod spectra_csv;
pub mod time_records;

pub use dft::LineGrid;
pub use estimate::{estimate, Accumulator, EstimatorConfig, NonparametricFrf};

use frf_data::{FrfError, C64};

/// Measured time records of one realization, after the transient: per experiment, one
/// record per channel, `P N` samples.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeRecords {
    /// Sample rate, Hz.
    pub fs: f64,
    /// `input[e][j]`: input channel `j` of experiment `e`.
    pub input: Vec<Vec<Vec<f64>>>,
    /// `output[e][i]`: output channel `i` of experiment `e`.
    pub output: Vec<Vec<Vec<f64>>>,
}

/// The spectra of one realization: every experiment and period at every excited line.
///
/// Layout: `input[((e * P + p) * L + k) * nu + j]` is input `j` of experiment `e`,
/// period `p`, line `k`; `output` likewise with `ny`; `reference[(e * L + k) * nu + j]`
/// (the same in every period).
#[derive(Debug, Clone, PartialEq)]
pub struct RealizationSpectra {
    n_experiments: usize,
    periods: usize,
    n_lines: usize,
    ny: usize,
    nu: usize,
    /// Reference spectra, when known (simulations).
    pub reference: Option<Vec<C64>>,
    /// Input spectra.
    pub input: Vec<C64>,
    /// Output spectra.
    pub output: Vec<C64>,
    /// The time records they came from, when kept.
    pub time: Option<TimeRecords>,
}

impl RealizationSpectra {
    /// Checks the lengths against the dimensions.
    pub fn new(
        n_experiments: usize,
        periods: usize,
        n_lines: usize,
        ny: usize,
        nu: usize,
        input: Vec<C64>,
        output: Vec<C64>,
        reference: Option<Vec<C64>>,
    ) -> Result<Self, FrfError> {
        if n_experiments == 0 || periods == 0 || n_lines == 0 || ny == 0 || nu == 0 {
            return Err(FrfError::invalid(
                "spectra dimensions",
                format!(
                    "{n_experiments} experiments, {periods} periods, {n_lines} lines, {ny}x{nu}"
                ),
                "every dimension must be >= 1",
            ));
        }
        let base = n_experiments * periods * n_lines;
        let chk = |what: &str, got: usize, expected: usize| -> Result<(), FrfError> {
            if got == expected {
                Ok(())
            } else {
                Err(FrfError::Dimension {
                    what: what.into(),
                    expected: expected.to_string(),
                    got: got.to_string(),
                })
            }
        };
        chk("input spectra", input.len(), base * nu)?;
        chk("output spectra", output.len(), base * ny)?;
        if let Some(r) = &reference {
            chk("reference spectra", r.len(), n_experiments * n_lines * nu)?;
        }
        for (what, v) in [("input", &input), ("output", &output)] {
            if let Some(i) = v
                .iter()
                .position(|z| !(z.re.is_finite() && z.im.is_finite()))
            {
                return Err(FrfError::InvalidData {
                    why: format!("non-finite {what} spectrum value at index {i}"),
                });
            }
        }
        Ok(Self {
            n_experiments,
            periods,
            n_lines,
            ny,
            nu,
            reference,
            input,
            output,
            time: None,
        })
    }

    /// Number of experiments.
    pub fn n_experiments(&self) -> usize {
        self.n_experiments
    }
    /// Number of periods.
    pub fn periods(&self) -> usize {
        self.periods
    }
    /// Number of lines.
    pub fn n_lines(&self) -> usize {
        self.n_lines
    }
    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of inputs.
    pub fn nu(&self) -> usize {
        self.nu
    }
    /// The `nu` input spectra of experiment `e`, period `p`, line `k`.
    #[inline]
    pub fn input_at(&self, e: usize, p: usize, k: usize) -> &[C64] {
        let o = ((e * self.periods + p) * self.n_lines + k) * self.nu;
        &self.input[o..o + self.nu]
    }
    /// The `ny` output spectra of experiment `e`, period `p`, line `k`.
    #[inline]
    pub fn output_at(&self, e: usize, p: usize, k: usize) -> &[C64] {
        let o = ((e * self.periods + p) * self.n_lines + k) * self.ny;
        &self.output[o..o + self.ny]
    }
}

/// Periodic spectra of a whole experiment: the excited lines and every realization.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicSpectra {
    /// Frequencies of the excited lines, Hz.
    pub freq_hz: Vec<f64>,
    /// Number of outputs.
    pub ny: usize,
    /// Number of inputs.
    pub nu: usize,
    /// The realizations (each with all experiments and periods).
    pub realizations: Vec<RealizationSpectra>,
    /// Units of `y / u`, when known.
    pub units: Option<String>,
    /// Free comment lines.
    pub comments: Vec<String>,
}

impl PeriodicSpectra {
    /// Checks that every realization has the dimensions of the first and the line count
    /// of `freq_hz`, and that the frequencies are finite, > 0 and increasing.
    pub fn new(
        freq_hz: Vec<f64>,
        ny: usize,
        nu: usize,
        realizations: Vec<RealizationSpectra>,
    ) -> Result<Self, FrfError> {
        if realizations.is_empty() {
            return Err(FrfError::invalid(
                "realizations",
                0,
                "periodic spectra need at least one realization",
            ));
        }
        for (k, &f) in freq_hz.iter().enumerate() {
            if !(f.is_finite() && f > 0.0) || (k > 0 && f <= freq_hz[k - 1]) {
                return Err(FrfError::InvalidData {
                    why: format!("excited line {k} at {f} Hz: lines must be > 0 and increasing"),
                });
            }
        }
        let r0 = &realizations[0];
        for (r, rs) in realizations.iter().enumerate() {
            if rs.ny != ny
                || rs.nu != nu
                || rs.n_lines != freq_hz.len()
                || rs.n_experiments != r0.n_experiments
            {
                return Err(FrfError::Dimension {
                    what: format!("realization {r}"),
                    expected: format!(
                        "{ny}x{nu}, {} lines, {} experiments",
                        freq_hz.len(),
                        r0.n_experiments
                    ),
                    got: format!(
                        "{}x{}, {} lines, {} experiments",
                        rs.ny, rs.nu, rs.n_lines, rs.n_experiments
                    ),
                });
            }
        }
        Ok(Self {
            freq_hz,
            ny,
            nu,
            realizations,
            units: None,
            comments: Vec::new(),
        })
    }

    /// Number of experiments.
    pub fn n_experiments(&self) -> usize {
        self.realizations[0].n_experiments
    }
    /// Number of lines.
    pub fn n_lines(&self) -> usize {
        self.freq_hz.len()
    }
}
