//! Periodic spectra from measured time records: split into periods, drop the transient
//! periods, DFT per period (McKelvey, eq. (8): once the transient term has decayed, the
//! DFT of one period relates input and output exactly at `w_k = 2 pi k / N`) and find
//! the excited lines from the input spectrum.

use super::dft::{LineGrid, RealPairFft};
use super::{PeriodicSpectra, RealizationSpectra};
use frf_data::{FrfError, C64};

/// How to cut and analyse the records.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordConfig {
    /// Sample rate, Hz.
    pub fs: f64,
    /// Samples per period `N`.
    pub period: usize,
    /// Leading periods dropped as transient.
    pub drop_periods: usize,
    /// The excited bins, when known; otherwise they are found from the input spectrum.
    pub bins: Option<Vec<usize>>,
    /// Window of the line detection: the excited lines are searched among those whose
    /// period-averaged input power is within this many dB of the strongest (default
    /// 40 dB; see [`detect_excited_lines`]).
    pub line_threshold_db: f64,
}

impl RecordConfig {
    /// `fs`, `period`, `drop_periods` with line detection at 40 dB.
    pub fn new(fs: f64, period: usize, drop_periods: usize) -> Self {
        Self {
            fs,
            period,
            drop_periods,
            bins: None,
            line_threshold_db: 40.0,
        }
    }
}

/// One experiment's records: `inputs[j]`, `outputs[i]`, all of the same length.
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentRecords {
    /// Input channels.
    pub inputs: Vec<Vec<f64>>,
    /// Output channels.
    pub outputs: Vec<Vec<f64>>,
}

/// The excited lines of a periodic input from its period-averaged power spectrum (summed
/// over input channels; the average over periods suppresses the non-periodic noise,
/// McKelvey eq. (21)): the bins `1..N/2` sorted by power form a top cluster (a flat
/// multisine) separated from the rest (noise, periodic distortions of a closed loop) by
/// the largest drop between consecutive lines, searched among the lines within
/// `threshold_db` of the strongest; the drop must be at least [`MIN_GAP_DB`].
pub fn detect_excited_lines(
    inputs: &[&[f64]],
    fs: f64,
    period: usize,
    drop_periods: usize,
    threshold_db: f64,
) -> Result<LineGrid, FrfError> {
    let np = count_periods(inputs.iter().map(|x| x.len()), period, drop_periods)?;
    if !(threshold_db.is_finite() && threshold_db > 0.0) {
        return Err(FrfError::invalid(
            "line_threshold_db",
            threshold_db,
            "must be finite and > 0",
        ));
    }
    let fft = RealPairFft::new(period);
    let all: Vec<usize> = (1..period.div_ceil(2)).collect();
    let nb = all.len();
    if nb == 0 {
        return Err(FrfError::invalid(
            "period",
            period,
            "too short to hold a line",
        ));
    }
    let mut power = vec![0.0; nb];
    let mut buf = Vec::with_capacity(period);
    let (mut o1, mut o2) = (vec![C64::new(0.0, 0.0); nb], vec![C64::new(0.0, 0.0); nb]);
    for x in inputs {
        let mut mean = vec![C64::new(0.0, 0.0); nb];
        for p in 0..np {
            let off = (drop_periods + p) * period;
            fft.forward_pair(
                &x[off..off + period],
                None,
                &all,
                &mut buf,
                &mut o1,
                &mut o2,
            );
            for (m, v) in mean.iter_mut().zip(&o1) {
                *m += *v;
            }
        }
        for (pw, m) in power.iter_mut().zip(&mean) {
            *pw += (m / np as f64).norm_sqr();
        }
    }
    let max = power.iter().cloned().fold(0.0, f64::max);
    if max.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(FrfError::invalid(
            "excited lines",
            "none",
            "the input has no periodic content: no excited line found",
        ));
    }
    // lines sorted by power (dB below the strongest); cut at the largest drop between
    // consecutive lines among those within the window
    let mut order: Vec<(f64, usize)> = all
        .iter()
        .zip(&power)
        .map(|(&b, &p)| (10.0 * (p / max).log10(), b))
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut best = (f64::NEG_INFINITY, 0usize);
    for i in 0..order.len() {
        if order[i].0 < -threshold_db {
            break;
        }
        let next = order.get(i + 1).map_or(f64::NEG_INFINITY, |v| v.0);
        let gap = order[i].0 - next;
        if gap > best.0 {
            best = (gap, i);
        }
    }
    if best.0 < MIN_GAP_DB {
        return Err(FrfError::invalid(
            "excited lines",
            format!("largest drop {:.1} dB", best.0),
            format!(
                "no clear separation between excited and other lines within {threshold_db} dB of \
                 the strongest line (need a drop of at least {MIN_GAP_DB} dB): give the excited \
                 lines explicitly"
            ),
        ));
    }
    let mut bins: Vec<usize> = order[..=best.1].iter().map(|v| v.1).collect();
    bins.sort_unstable();
    LineGrid::from_bins(fs, period, bins)
}

/// The smallest drop in period-averaged input power (dB) that separates the excited
/// lines from the others in [`detect_excited_lines`].
pub const MIN_GAP_DB: f64 = 6.0;

fn count_periods(
    lens: impl Iterator<Item = usize>,
    period: usize,
    drop: usize,
) -> Result<usize, FrfError> {
    let lens: Vec<usize> = lens.collect();
    if lens.is_empty() {
        return Err(FrfError::invalid("records", 0, "no signal given"));
    }
    if period < 4 {
        return Err(FrfError::invalid(
            "period",
            period,
            "a period needs at least 4 samples",
        ));
    }
    let len = lens[0];
    if let Some(&l) = lens.iter().find(|&&l| l != len) {
        return Err(FrfError::Dimension {
            what: "record lengths".into(),
            expected: len.to_string(),
            got: l.to_string(),
        });
    }
    let total = len / period;
    if total <= drop {
        return Err(FrfError::invalid(
            "periods",
            total.saturating_sub(drop),
            format!(
                "the records hold {total} whole period(s) of {period} samples and {drop} are dropped: \
                 at least one period must remain"
            ),
        ));
    }
    Ok(total - drop)
}

/// Periodic spectra of one or more experiments (one realization) from time records. The
/// excited lines are `config.bins` or are found from the inputs of all experiments.
pub fn spectra_from_records(
    experiments: &[ExperimentRecords],
    config: &RecordConfig,
) -> Result<PeriodicSpectra, FrfError> {
    if experiments.is_empty() {
        return Err(FrfError::invalid("experiments", 0, "no records given"));
    }
    let nu = experiments[0].inputs.len();
    let ny = experiments[0].outputs.len();
    if nu == 0 || ny == 0 {
        return Err(FrfError::invalid(
            "channels",
            format!("{nu} inputs, {ny} outputs"),
            "need at least one input and one output",
        ));
    }
    for (e, ex) in experiments.iter().enumerate() {
        if ex.inputs.len() != nu || ex.outputs.len() != ny {
            return Err(FrfError::Dimension {
                what: format!("channels of experiment {}", e + 1),
                expected: format!("{nu} inputs, {ny} outputs"),
                got: format!("{} inputs, {} outputs", ex.inputs.len(), ex.outputs.len()),
            });
        }
        for (c, x) in ex.inputs.iter().chain(&ex.outputs).enumerate() {
            if let Some(t) = x.iter().position(|v| !v.is_finite()) {
                return Err(FrfError::InvalidData {
                    why: format!(
                        "experiment {}, channel {}: non-finite sample at {t}",
                        e + 1,
                        c + 1
                    ),
                });
            }
        }
    }
    let n = config.period;
    let np = count_periods(
        experiments
            .iter()
            .flat_map(|e| e.inputs.iter().chain(&e.outputs).map(Vec::len)),
        n,
        config.drop_periods,
    )?;
    let grid = match &config.bins {
        Some(b) => LineGrid::from_bins(config.fs, n, b.clone())?,
        None => {
            let ins: Vec<&[f64]> = experiments
                .iter()
                .flat_map(|e| e.inputs.iter().map(Vec::as_slice))
                .collect();
            detect_excited_lines(
                &ins,
                config.fs,
                n,
                config.drop_periods,
                config.line_threshold_db,
            )?
        }
    };
    let ne = experiments.len();
    let nl = grid.n_lines();
    let fft = RealPairFft::new(n);
    let mut input = vec![C64::new(0.0, 0.0); ne * np * nl * nu];
    let mut output = vec![C64::new(0.0, 0.0); ne * np * nl * ny];
    let mut buf = Vec::with_capacity(n);
    let (mut o1, mut o2) = (vec![C64::new(0.0, 0.0); nl], vec![C64::new(0.0, 0.0); nl]);
    for (e, ex) in experiments.iter().enumerate() {
        for p in 0..np {
            let off = (config.drop_periods + p) * n;
            for (chans, dst, nch) in [(&ex.inputs, &mut input, nu), (&ex.outputs, &mut output, ny)]
            {
                let mut c = 0;
                while c < nch {
                    let x1 = &chans[c][off..off + n];
                    let x2 = (c + 1 < nch).then(|| &chans[c + 1][off..off + n]);
                    fft.forward_pair(x1, x2, grid.bins(), &mut buf, &mut o1, &mut o2);
                    for k in 0..nl {
                        let base = ((e * np + p) * nl + k) * nch;
                        dst[base + c] = o1[k];
                        if x2.is_some() {
                            dst[base + c + 1] = o2[k];
                        }
                    }
                    c += 2;
                }
            }
        }
    }
    let rs = RealizationSpectra::new(ne, np, nl, ny, nu, input, output, None)?;
    let mut s = PeriodicSpectra::new(grid.freq_hz(), ny, nu, vec![rs])?;
    s.comments.push(format!(
        "{np} periods of {n} samples at {} Hz after dropping {}; {nl} excited lines {}..{} Hz",
        config.fs,
        config.drop_periods,
        s.freq_hz[0],
        s.freq_hz[nl - 1]
    ));
    Ok(s)
}
