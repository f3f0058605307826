//! The nonparametric FRF of periodic measurements for every front end (`frfit
//! nonparametric` and the Python package): time records (MATLAB `.mat` files or arrays)
//! or a periodic spectra CSV in, the FRF with its variance and the comments that say how
//! it was estimated out (crate `experiment`, the estimator of McKelvey and of Pintelon
//! and Schoukens' robust method).

use crate::FrfitError;
use experiment::matfile::MatFile;
use experiment::nonparametric::spectra_csv::read_spectra_csv;
use experiment::nonparametric::time_records::{
    spectra_from_records, ExperimentRecords, RecordConfig,
};
use experiment::nonparametric::{
    estimate, EstimatorConfig, NonparametricFrf, PeriodicSpectra, RealizationSpectra,
};
use std::path::{Path, PathBuf};

/// How to read and cut time records.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSpec {
    /// Input signal names in `.mat` files (`-NAME` flips the sign, `NAME:COL` takes
    /// column `COL`, 1-based, of a matrix variable). Unused for arrays.
    pub inputs: Vec<String>,
    /// Output signal names (same syntax).
    pub outputs: Vec<String>,
    /// Sample rate, Hz. Default: the scalar `fs` of the first `.mat` file.
    pub fs: Option<f64>,
    /// Samples per period. Required.
    pub period: Option<usize>,
    /// Leading periods dropped as transient. Default 0.
    pub drop_periods: usize,
    /// The excited DFT bins (`k` of `f = k fs / N`), when known; otherwise they are
    /// found from the input spectrum. Default: found.
    pub lines: Option<Vec<usize>>,
    /// Window of the line detection, dB below the strongest line. Default 40.
    pub line_threshold_db: f64,
    /// How many random-phase realizations the experiments form (consecutive blocks of
    /// experiments, [`group_realizations`]). Default: blocks of `nu` experiments, one
    /// realization per block (`nu` orthogonal experiments each).
    pub realizations: Option<usize>,
}

impl Default for RecordSpec {
    fn default() -> Self {
        Self {
            inputs: Vec::new(),
            outputs: Vec::new(),
            fs: None,
            period: None,
            drop_periods: 0,
            lines: None,
            line_threshold_db: 40.0,
            realizations: None,
        }
    }
}

impl RecordSpec {
    /// The record configuration at sample rate `fs`.
    fn record_config(&self, fs: f64) -> Result<RecordConfig, FrfitError> {
        if !(fs.is_finite() && fs > 0.0) {
            return Err(FrfitError::argument(
                "--fs",
                fs,
                "must be a sample rate > 0 Hz",
            ));
        }
        let period = self.period.ok_or_else(|| {
            FrfitError::argument(
                "--period",
                "missing",
                "give the number of samples per period",
            )
        })?;
        if period < 2 {
            return Err(FrfitError::argument(
                "--period",
                period,
                "a period holds at least 2 samples",
            ));
        }
        if let Some(l) = &self.lines {
            if let Some(&k) = l.iter().find(|&&k| k == 0 || 2 * k >= period) {
                return Err(FrfitError::argument(
                    "--lines",
                    k,
                    format!(
                        "an excited line is a DFT bin between 1 and {} (below Nyquist for a period of {period} samples)",
                        (period - 1) / 2
                    ),
                ));
            }
        }
        Ok(RecordConfig {
            fs,
            period,
            drop_periods: self.drop_periods,
            bins: self.lines.clone(),
            line_threshold_db: self.line_threshold_db,
        })
    }
}

/// A signal spec with an optional leading `-`: (sign, name).
pub fn signed(spec: &str) -> (f64, &str) {
    match spec.trim().strip_prefix('-') {
        Some(rest) => (-1.0, rest.trim()),
        None => (1.0, spec.trim()),
    }
}

/// Whether `p` has the `.mat` extension.
pub fn is_mat(p: &Path) -> bool {
    has_ext(p, "mat")
}

/// Periodic spectra from `.mat` time records, one file per experiment, and notes on what
/// was skipped in the files.
pub fn spectra_from_mat_files(
    files: &[PathBuf],
    spec: &RecordSpec,
) -> Result<(PeriodicSpectra, Vec<String>), FrfitError> {
    if spec.inputs.is_empty() || spec.outputs.is_empty() {
        return Err(FrfitError::argument(
            "--input/--output",
            format!("{:?} / {:?}", spec.inputs, spec.outputs),
            "name the input and output signals of the .mat files (e.g. --input iq_adx --output theta_mx,theta_my)",
        ));
    }
    let mut experiments = Vec::with_capacity(files.len());
    let mut fs_file = None;
    let mut notes = Vec::new();
    for f in files {
        if !is_mat(f) {
            return Err(FrfitError::argument(
                "files",
                f.display(),
                "mix of file kinds: give either .mat files or one periodic spectra .csv",
            ));
        }
        let m = MatFile::read(f)?;
        if fs_file.is_none() {
            fs_file = m.scalar("fs");
        }
        let get = |spec: &String| -> Result<Vec<f64>, FrfitError> {
            let (s, name) = signed(spec);
            let mut x = m.signal(name)?;
            if s < 0.0 {
                x.iter_mut().for_each(|v| *v = -*v);
            }
            Ok(x)
        };
        let inputs = spec.inputs.iter().map(get).collect::<Result<Vec<_>, _>>()?;
        let outputs = spec
            .outputs
            .iter()
            .map(get)
            .collect::<Result<Vec<_>, _>>()?;
        if !m.skipped.is_empty() {
            notes.push(format!(
                "{}: skipped non-numeric variables {}",
                f.display(),
                m.skipped
                    .iter()
                    .map(|(n, k)| format!("{n} ({k})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        experiments.push(ExperimentRecords { inputs, outputs });
    }
    let fs = match (spec.fs, fs_file) {
        (Some(v), _) | (None, Some(v)) => v,
        (None, None) => {
            return Err(FrfitError::argument(
                "--fs",
                "missing",
                "give the sample rate (the .mat file has no scalar `fs`)",
            ))
        }
    };
    let cfg = spec.record_config(fs)?;
    let spectra = spectra_from_records(&experiments, &cfg)?;
    let mut grouped = group_realizations(spectra, spec.realizations)?;
    grouped.comments.push(sampling_comment(fs));
    Ok((grouped, notes))
}

/// Per experiment, per channel, the samples.
pub type Records = Vec<Vec<Vec<f64>>>;

/// Splits a time-record array shaped `(n_samples, channels[, experiments[, periods]])`
/// (C order) into per-experiment channel records; with a periods axis the periods are
/// concatenated and the period length (`n_samples`) is returned beside them. `what`
/// names the array in errors. The layout of the public benchmark data sets and of
/// NumPy users; the Python package and the `.npy`/`.npz` reader share it.
pub fn records_from_array(
    shape: &[usize],
    data: &[f64],
    what: &str,
) -> Result<(Records, Option<usize>), FrfitError> {
    let (ns, nc, ne, np) = match *shape {
        [ns] => (ns, 1, 1, 1),
        [ns, nc] => (ns, nc, 1, 1),
        [ns, nc, ne] => (ns, nc, ne, 1),
        [ns, nc, ne, np] => (ns, nc, ne, np),
        _ => {
            return Err(FrfitError::argument(
                what,
                format!("shape {shape:?}"),
                "expected (n_samples, channels[, experiments[, periods]])",
            ))
        }
    };
    if ns * nc * ne * np != data.len() {
        return Err(FrfitError::argument(
            what,
            format!("shape {shape:?}"),
            format!("the array holds {} values", data.len()),
        ));
    }
    let idx = |t, c, e, p| record_index([ns, nc, ne, np], t, c, e, p);
    let exps = (0..ne)
        .map(|e| {
            (0..nc)
                .map(|c| {
                    (0..np)
                        .flat_map(|p| (0..ns).map(move |t| (t, p)))
                        .map(|(t, p)| data[idx(t, c, e, p)])
                        .collect()
                })
                .collect()
        })
        .collect();
    Ok((exps, (shape.len() == 4).then_some(ns)))
}

/// The position of sample `t` of channel `c`, experiment `e`, period `p` in a C-order
/// array shaped `[n_samples, channels, experiments, periods]` (the layout of
/// [`records_from_array`] and [`array_from_records`]).
fn record_index(shape: [usize; 4], t: usize, c: usize, e: usize, p: usize) -> usize {
    let [_, nc, ne, np] = shape;
    ((t * nc + c) * ne + e) * np + p
}

/// The inverse of [`records_from_array`]: `experiments` (per experiment, per channel,
/// `periods` periods of `period` samples each, concatenated) as a C-order array shaped
/// `[period, channels, experiments, periods]`; the shape and the values. Every
/// experiment must have the channels of the first and `period * periods` samples per
/// channel.
pub fn array_from_records(
    experiments: &[&[Vec<f64>]],
    period: usize,
    periods: usize,
) -> Result<(Vec<usize>, Vec<f64>), FrfitError> {
    let ne = experiments.len();
    let nc = experiments.first().map_or(0, |e| e.len());
    let shape = [period, nc, ne, periods];
    let mut data = vec![0.0; period * nc * ne * periods];
    for (e, chans) in experiments.iter().enumerate() {
        if chans.len() != nc || chans.iter().any(|x| x.len() != period * periods) {
            return Err(FrfitError::argument(
                "records",
                format!("experiment {e}"),
                format!(
                    "expected {nc} channels of {} samples ({periods} periods of {period})",
                    period * periods
                ),
            ));
        }
        for (c, x) in chans.iter().enumerate() {
            for p in 0..periods {
                for t in 0..period {
                    data[record_index(shape, t, c, e, p)] = x[p * period + t];
                }
            }
        }
    }
    Ok((shape.to_vec(), data))
}

/// The experiments of input and output arrays of the same experiment count.
pub fn experiments_from_arrays(
    u: (Records, Option<usize>),
    y: (Records, Option<usize>),
) -> Result<(Vec<ExperimentRecords>, Option<usize>), FrfitError> {
    if u.0.len() != y.0.len() {
        return Err(FrfitError::argument(
            "y",
            format!("{} experiments", y.0.len()),
            format!(
                "u holds {} experiments: u and y must hold the same",
                u.0.len()
            ),
        ));
    }
    let period = u.1.or(y.1);
    let exps =
        u.0.into_iter()
            .zip(y.0)
            .map(|(inputs, outputs)| ExperimentRecords { inputs, outputs })
            .collect();
    Ok((exps, period))
}

/// Periodic spectra from NumPy files: one `.npz` holding the arrays `u` and `y` (or the
/// names `spec.inputs[0]`, `spec.outputs[0]`), or two `.npy` files, inputs first; each
/// shaped `(n_samples, channels[, experiments[, periods]])`. `spec.fs` is required.
pub fn spectra_from_numpy(
    files: &[PathBuf],
    spec: &RecordSpec,
) -> Result<PeriodicSpectra, FrfitError> {
    use frf_data::io::npy::{read_npy, read_npz, NpyArray};
    let name = |v: &[String], d: &str| v.first().cloned().unwrap_or_else(|| d.to_string());
    let (u, y): (NpyArray, NpyArray) = match files {
        [f] if has_ext(f, "npz") => {
            let mut m = read_npz(f)?;
            let (un, yn) = (name(&spec.inputs, "u"), name(&spec.outputs, "y"));
            let mut take = |n: &str, opt: &str| {
                m.remove(n).ok_or_else(|| {
                    FrfitError::argument(
                        opt,
                        n,
                        format!(
                            "{} holds no array `{n}` (it holds {})",
                            f.display(),
                            m.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                    )
                })
            };
            (take(&un, "--input")?, take(&yn, "--output")?)
        }
        [fu, fy] if has_ext(fu, "npy") && has_ext(fy, "npy") => (read_npy(fu)?, read_npy(fy)?),
        _ => {
            return Err(FrfitError::argument(
                "files",
                files.len(),
                "NumPy time records: one .npz with arrays u and y, or two .npy files (inputs, then outputs)",
            ))
        }
    };
    let (exps, period) = experiments_from_arrays(
        records_from_array(&u.shape, &u.data, "u")?,
        records_from_array(&y.shape, &y.data, "y")?,
    )?;
    let spec = RecordSpec {
        period: spec.period.or(period),
        ..spec.clone()
    };
    spectra_from_arrays(&exps, &spec)
}

fn has_ext(p: &Path, ext: &str) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

/// Periodic spectra from time records held in memory: `experiments[e]` holds the input
/// and output channels of experiment `e`; `spec.fs` is required.
pub fn spectra_from_arrays(
    experiments: &[ExperimentRecords],
    spec: &RecordSpec,
) -> Result<PeriodicSpectra, FrfitError> {
    let fs = spec.fs.ok_or_else(|| {
        FrfitError::argument("fs", "missing", "give the sample rate of the records, Hz")
    })?;
    let cfg = spec.record_config(fs)?;
    let spectra = spectra_from_records(experiments, &cfg)?;
    let mut grouped = group_realizations(spectra, spec.realizations)?;
    grouped.comments.push(sampling_comment(fs));
    Ok(grouped)
}

/// The comment that states the records' sample rate in the words `fit` and `diagnose`
/// read ("sampling <fs> Hz"): the diagnosis can then test a zero-order hold (it is not
/// declared: the records do not say whether the actuator's converter holds).
pub fn sampling_comment(fs: f64) -> String {
    format!(
        "sampling {fs} Hz (the sample rate of the time records; a hold is not declared: give --hold zoh:{fs} when the actuator's converter holds)"
    )
}

/// Groups the experiments of time records into random-phase realizations (the robust
/// method of Pintelon and Schoukens, *System Identification: A Frequency Domain
/// Approach*, 2nd ed., section 3.7 and chapter 4): experiment `e` belongs to
/// realization `e / (E / R)` (consecutive blocks). Each realization's `E / R`
/// experiments must excite every input (at least `nu` of them; the estimator checks the
/// rank of the inputs line by line). With `R >= 2` the estimate's variance is the total
/// variance from the spread over realizations (noise and stochastic nonlinear
/// distortion) and its noise part comes from the spread over periods.
///
/// `realizations`: `R`; `None` takes blocks of `nu` experiments (`R = E / nu`), which
/// for 6 experiments of a 3-input system are 2 realizations of 3 orthogonal experiments.
/// Spectra that already hold several realizations (a spectra CSV) are returned as they
/// are when `realizations` is `None` or their count.
pub fn group_realizations(
    spectra: PeriodicSpectra,
    realizations: Option<usize>,
) -> Result<PeriodicSpectra, FrfitError> {
    let have = spectra.realizations.len();
    if have != 1 {
        return match realizations {
            None => Ok(spectra),
            Some(r) if r == have => Ok(spectra),
            Some(r) => Err(FrfitError::argument(
                "--realizations",
                r,
                format!("the spectra already hold {have} realizations"),
            )),
        };
    }
    let (nu, ny) = (spectra.nu, spectra.ny);
    let rs = &spectra.realizations[0];
    let (ne, np, nl) = (rs.n_experiments(), rs.periods(), rs.n_lines());
    let r = match realizations {
        Some(0) => {
            return Err(FrfitError::argument(
                "--realizations",
                0,
                "at least one realization",
            ))
        }
        Some(r) => r,
        None if ne % nu == 0 => ne / nu,
        None => {
            return Err(FrfitError::argument(
                "--realizations",
                "by default: experiments / inputs",
                format!(
                    "{ne} experiment(s) of {nu} input(s) do not form whole realizations of {nu} \
                     experiments each; say how many realizations they are (--realizations R, \
                     R dividing {ne})"
                ),
            ))
        }
    };
    if ne % r != 0 {
        return Err(FrfitError::argument(
            "--realizations",
            r,
            format!("{ne} experiment(s) do not split into {r} realizations of equal size"),
        ));
    }
    let per = ne / r;
    if per < nu {
        return Err(FrfitError::argument(
            "--realizations",
            r,
            format!(
                "each realization would hold {per} experiment(s), fewer than the {nu} inputs: \
                 the inputs of a realization must have full rank"
            ),
        ));
    }
    if r == 1 {
        return Ok(spectra);
    }
    let (bi, bo) = (per * np * nl * nu, per * np * nl * ny);
    let reference = rs.reference.as_ref();
    let groups = (0..r)
        .map(|g| {
            RealizationSpectra::new(
                per,
                np,
                nl,
                ny,
                nu,
                rs.input[g * bi..(g + 1) * bi].to_vec(),
                rs.output[g * bo..(g + 1) * bo].to_vec(),
                reference.map(|x| x[g * per * nl * nu..(g + 1) * per * nl * nu].to_vec()),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut out = PeriodicSpectra::new(spectra.freq_hz.clone(), ny, nu, groups)?;
    out.units = spectra.units.clone();
    out.comments = spectra.comments.clone();
    out.comments.push(format!(
        "{r} realizations of {per} experiment(s) each (consecutive blocks of the {ne} experiments)"
    ));
    Ok(out)
}

/// The periodic spectra of `files`: `.mat` time records (one per experiment), NumPy
/// records (one `.npz`, or two `.npy`: [`spectra_from_numpy`]) or one periodic spectra
/// CSV; notes on what was skipped.
pub fn spectra_from_files(
    files: &[PathBuf],
    spec: &RecordSpec,
) -> Result<(PeriodicSpectra, Vec<String>), FrfitError> {
    for f in files {
        if !f.is_file() {
            return Err(FrfitError::Io {
                path: f.display().to_string(),
                message: "no such file".into(),
            });
        }
    }
    if files.iter().any(|f| is_mat(f)) {
        return spectra_from_mat_files(files, spec);
    }
    if files.iter().any(|f| has_ext(f, "npz") || has_ext(f, "npy")) {
        return Ok((spectra_from_numpy(files, spec)?, Vec::new()));
    }
    if files.len() != 1 {
        return Err(FrfitError::argument(
            "files",
            files.len(),
            "give one periodic spectra CSV (it holds every experiment and realization)",
        ));
    }
    Ok((read_spectra_csv(&files[0])?, Vec::new()))
}

/// The estimate and the comment lines an FRF CSV of it carries (sources, signals, the
/// spectra's own comments, `notes`, and how the variance was estimated).
pub struct Estimated {
    /// The estimate: the FRF with its variance, the separate noise and total variances.
    pub estimate: NonparametricFrf,
    /// Comment lines for the FRF CSV.
    pub comments: Vec<String>,
}

/// Estimates the FRF of `spectra` (every realization, every period) and describes it:
/// `sources` are what the spectra were read from, `spec` the signals.
pub fn estimate_described(
    spectra: &PeriodicSpectra,
    sources: &[String],
    spec: &RecordSpec,
    mut notes: Vec<String>,
) -> Result<Estimated, FrfitError> {
    let est = estimate(spectra, &EstimatorConfig::default())?;
    let mut comments = vec![format!("nonparametric FRF of {}", sources.join(", "))];
    if !spec.inputs.is_empty() {
        comments.push(format!(
            "inputs {}; outputs {}",
            spec.inputs.join(","),
            spec.outputs.join(",")
        ));
    }
    comments.extend(spectra.comments.iter().cloned());
    comments.append(&mut notes);
    // FORMATS.md: the comment words that say what the variances were estimated from
    comments.push(format!(
        "periods={} realizations={} experiments={}",
        est.periods, est.realizations, est.n_experiments
    ));
    comments.push(format!(
        "estimator: G = mean_p(Y_p) mean_p(U_p)^-1 per realization, mean over {} realization(s); {} periods, {} experiment(s); variance: {}",
        est.realizations,
        est.periods,
        est.n_experiments,
        est.frf.metadata.get("variance").cloned().unwrap_or_default()
    ));
    Ok(Estimated {
        estimate: est,
        comments,
    })
}

/// Parses the excited DFT bins: comma-separated bins `K` or ranges `A-B` (inclusive) with
/// an optional step `A-B/S` (`1-999/2`: the odd bins of an odd multisine).
pub fn parse_lines(s: &str) -> Result<Vec<usize>, String> {
    let num = |t: &str, what: &str| -> Result<usize, String> {
        t.trim()
            .parse::<usize>()
            .map_err(|_| format!("{what} `{}` in `{s}` is not a whole number", t.trim()))
    };
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (range, step) = match part.split_once('/') {
            Some((r, st)) => (r, num(st, "step")?),
            None => (part, 1),
        };
        if step == 0 {
            return Err(format!("step 0 in `{part}` of `{s}`"));
        }
        match range.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (num(a, "bin")?, num(b, "bin")?);
                if a > b {
                    return Err(format!("range `{part}` of `{s}` runs downwards"));
                }
                out.extend((a..=b).step_by(step));
            }
            None => out.push(num(range, "bin")?),
        }
    }
    if out.is_empty() {
        return Err(format!("no line in `{s}`"));
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_and_signs() {
        assert_eq!(parse_lines("3,1,2"), Ok(vec![1, 2, 3]));
        assert_eq!(parse_lines("1-9/2"), Ok(vec![1, 3, 5, 7, 9]));
        assert_eq!(parse_lines("5-7, 2"), Ok(vec![2, 5, 6, 7]));
        assert!(parse_lines("x").unwrap_err().contains("whole number"));
        assert!(parse_lines("9-1").unwrap_err().contains("downwards"));
        assert!(parse_lines("1-3/0").is_err());
        assert!(parse_lines(",").is_err());
        assert_eq!(signed("-theta_my"), (-1.0, "theta_my"));
        assert_eq!(signed(" x:3"), (1.0, "x:3"));
        let spec = RecordSpec {
            period: Some(100),
            lines: Some(vec![1, 50]),
            ..Default::default()
        };
        let e = spec.record_config(1000.0).unwrap_err().to_string();
        assert!(e.contains("--lines") && e.contains("50"), "{e}");
        let spec = RecordSpec::default();
        assert!(spec
            .record_config(1000.0)
            .unwrap_err()
            .to_string()
            .contains("--period"));
    }

    /// Spectra of `ne` experiments of a `ny x nu` system in one realization.
    fn one_realization(ne: usize, nu: usize) -> PeriodicSpectra {
        let (ny, np, nl) = (2, 2, 3);
        let z = |i: usize| frf_data::C64::new(1.0 + i as f64, 0.5);
        let input = (0..ne * np * nl * nu).map(z).collect();
        let output = (0..ne * np * nl * ny).map(z).collect();
        let rs = RealizationSpectra::new(ne, np, nl, ny, nu, input, output, None).unwrap();
        PeriodicSpectra::new(vec![1.0, 2.0, 3.0], ny, nu, vec![rs]).unwrap()
    }

    #[test]
    fn experiments_group_into_realizations_of_whole_blocks() {
        // 6 experiments of 3 inputs: 2 realizations by default, the blocks in order
        let s = one_realization(6, 3);
        let g = group_realizations(s.clone(), None).unwrap();
        assert_eq!(g.realizations.len(), 2);
        assert_eq!(g.realizations[0].n_experiments(), 3);
        let half = s.realizations[0].input.len() / 2;
        assert_eq!(g.realizations[1].input[..], s.realizations[0].input[half..]);
        assert_eq!(
            group_realizations(s.clone(), Some(1))
                .unwrap()
                .realizations
                .len(),
            1
        );
        // errors name the option and say why
        let e = group_realizations(s.clone(), Some(4))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--realizations") && e.contains("equal size"),
            "{e}"
        );
        let e = group_realizations(s.clone(), Some(3))
            .unwrap_err()
            .to_string();
        assert!(e.contains("full rank"), "{e}");
        let e = group_realizations(one_realization(4, 3), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("do not form whole realizations"), "{e}");
        // SISO: every experiment is a realization
        assert_eq!(
            group_realizations(one_realization(3, 1), None)
                .unwrap()
                .realizations
                .len(),
            3
        );
        // spectra that hold realizations already are kept
        let two = group_realizations(s, None).unwrap();
        assert_eq!(group_realizations(two.clone(), None).unwrap(), two);
        assert!(group_realizations(two, Some(3)).is_err());
    }

    #[test]
    fn records_written_as_an_array_read_back() {
        // 2 experiments, 3 channels, 2 periods of 4 samples
        let exps: Vec<Vec<Vec<f64>>> = (0..2)
            .map(|e| {
                (0..3)
                    .map(|c| (0..8).map(|t| (100 * e + 10 * c + t) as f64).collect())
                    .collect()
            })
            .collect();
        let refs: Vec<&[Vec<f64>]> = exps.iter().map(|e| e.as_slice()).collect();
        let (shape, data) = array_from_records(&refs, 4, 2).unwrap();
        assert_eq!(shape, vec![4, 3, 2, 2]);
        let (back, period) = records_from_array(&shape, &data, "u").unwrap();
        assert_eq!(back, exps);
        assert_eq!(period, Some(4));
        // a short channel is refused
        let mut bad = exps.clone();
        bad[1][2].pop();
        let refs: Vec<&[Vec<f64>]> = bad.iter().map(|e| e.as_slice()).collect();
        assert!(array_from_records(&refs, 4, 2).is_err());
    }
}
