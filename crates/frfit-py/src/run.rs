//! `frfit.fit`, `frfit.diagnose`, `frfit.validate`, `frfit.reduce`: the pipeline of the
//! command line on in-memory data, with the GIL released while it runs.

use crate::arrays::real_1d;
use crate::data::FrfData;
use crate::model::{to_python, Model};
use crate::{arg_err, to_py};
use additive_riv::{DelayChoice, ModeSelection};
use frf_data::FrfDataset;
use frfit::options::{
    parse_band, parse_band_weights, parse_bands, parse_delay, parse_frf_type, parse_hold,
    parse_method, parse_modes, parse_weighting, Band, FitSpec,
};
use frfit::run::{self, PipelineOutput};
use frfit::summary::StepSummary;
use frfit::validation::{FrfValidation, GammaMethod};
use frfit::validation_report::{
    validate_model, verdict_text, write_validation_dir, FitDataOfModel,
};
use frfit::FrfitError;
use pyo3::prelude::*;
use std::path::{Path, PathBuf};

/// `band=`: `None`, `"LO:HI"`, or a pair `(lo, hi)` with either side `None`.
fn band_arg(band: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Band>> {
    let Some(b) = band.filter(|b| !b.is_none()) else {
        return Ok(None);
    };
    if let Ok(s) = b.extract::<String>() {
        let s = s.as_str();
        return parse_band(s).map(Some).map_err(|e| arg_err("band", s, e));
    }
    if let Ok(t) = b.extract::<(Option<f64>, Option<f64>)>() {
        return Band::new(t.0, t.1)
            .map(Some)
            .map_err(|e| arg_err("band", format!("{t:?}"), e));
    }
    Err(arg_err(
        "band",
        b.repr().map(|r| r.to_string()).unwrap_or_default(),
        "expected (lo_hz, hi_hz) or \"LO:HI\"",
    ))
}

/// `delay=`: `None`, `"auto"`, `"none"`, `"150us"`, or seconds as a number.
fn delay_arg(delay: Option<&Bound<'_, PyAny>>) -> PyResult<Option<DelayChoice>> {
    let Some(d) = delay.filter(|d| !d.is_none()) else {
        return Ok(None);
    };
    if let Ok(s) = d.extract::<String>() {
        let s = s.as_str();
        return parse_delay(s).map(Some).map_err(|e| arg_err("delay", s, e));
    }
    let v: f64 = d.extract().map_err(|_| {
        arg_err(
            "delay",
            "<object>",
            "expected auto, none, seconds or \"150us\"",
        )
    })?;
    parse_delay(&format!("{v:e}"))
        .map(Some)
        .map_err(|e| arg_err("delay", v, e))
}

/// `modes=`: `None`, `"auto"`, a count, or a list of frequencies (Hz) to start from.
fn modes_arg(modes: Option<&Bound<'_, PyAny>>) -> PyResult<Option<ModeSelection>> {
    let Some(m) = modes.filter(|m| !m.is_none()) else {
        return Ok(None);
    };
    if let Ok(s) = m.extract::<String>() {
        let s = s.as_str();
        return parse_modes(s).map(Some).map_err(|e| arg_err("modes", s, e));
    }
    if let Ok(n) = m.extract::<usize>() {
        return parse_modes(&n.to_string())
            .map(Some)
            .map_err(|e| arg_err("modes", n, e));
    }
    if let Ok(f) = m.extract::<Vec<f64>>() {
        if f.is_empty() || f.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
            return Err(arg_err(
                "modes",
                format!("{f:?}"),
                "frequencies to start from must be finite and > 0 Hz",
            ));
        }
        return Ok(Some(ModeSelection::Frequencies(f)));
    }
    Err(arg_err(
        "modes",
        m.repr().map(|r| r.to_string()).unwrap_or_default(),
        "expected \"auto\", a number of modes, or a list of frequencies in Hz",
    ))
}

/// A string option parsed by `parse`, errors naming `name`.
fn word<T>(
    name: &str,
    v: Option<&str>,
    parse: fn(&str) -> Result<T, String>,
) -> PyResult<Option<T>> {
    v.map(|s| parse(s).map_err(|e| arg_err(name, s, e)))
        .transpose()
}

/// The options of `fit` and `diagnose` as the library's [`FitSpec`].
#[allow(clippy::too_many_arguments)]
fn spec(
    band: Option<&Bound<'_, PyAny>>,
    init: Option<&str>,
    refine: Option<&str>,
    hold: Option<&str>,
    delay: Option<&Bound<'_, PyAny>>,
    modes: Option<&Bound<'_, PyAny>>,
    method: &str,
    weighting: &str,
    frf_type: &str,
    order: Option<usize>,
    bands: Option<&str>,
    band_weights: Option<&str>,
) -> PyResult<FitSpec> {
    Ok(FitSpec {
        band: band_arg(band)?,
        delay: delay_arg(delay)?,
        hold: word("hold", hold, parse_hold)?,
        modes: modes_arg(modes)?,
        method: word("method", Some(method), parse_method)?.unwrap_or_default(),
        init: init.unwrap_or_default().to_string(),
        refine: refine.unwrap_or_default().to_string(),
        order,
        bands: word("bands", bands, parse_bands)?,
        band_weights: word("band_weights", band_weights, parse_band_weights)?,
        weighting: word("weighting", Some(weighting), parse_weighting)?.unwrap_or_default(),
        frf_type: word("frf_type", Some(frf_type), parse_frf_type)?.unwrap_or_default(),
        fs_hz: None,
    })
}

/// Where the data came from, for the summary and the model's provenance.
fn source_of(data: &FrfData) -> String {
    data.inner
        .source
        .clone()
        .unwrap_or_else(|| "<arrays>".to_string())
}

/// The model of a run.
fn model_of(out: &PipelineOutput, source: &str, producer: &str) -> PyResult<Model> {
    let file = out.model_file(Path::new(source), producer).map_err(|e| {
        to_py(FrfitError::Fit {
            what: "model file".into(),
            why: e.to_string(),
        })
    })?;
    Model::from_file(file, Some(out.summary.clone()), source)
}

/// Fits the additive modal model to `data` as `frfit fit` does (the same chain, the same
/// options; strings where the command line takes strings) and returns the `Model`.
///
/// `band`: `(lo_hz, hi_hz)` or `"LO:HI"`; `init`/`refine`: the chain's links (`cmif`,
/// `subspace`, `sk`, `auto` / `riv`, `ml`, `none`; default by the data's size);
/// `hold`: `"zoh:FS"`, `"sinc:FS"` or `"none"`; `delay`: `"auto"`, `"none"`, seconds or
/// `"150us"`; `modes`: `"auto"`, a count or start frequencies; `method`: `riv` or `sk`;
/// `weighting`: `auto`, `variance`, `magnitude` or `uniform`; `frf_type`:
/// `displacement`, `velocity` or `accelerance`; `order`: states for the initialisers that
/// take one; `bands`, `band_weights`: the multi-band SK fit (`init="sk"`).
#[pyfunction]
#[pyo3(signature = (data, band=None, init=None, refine=None, hold=None, delay=None, modes=None,
    method="riv", weighting="auto", frf_type="displacement", order=None, bands=None, band_weights=None))]
pub fn fit(
    py: Python<'_>,
    data: &FrfData,
    band: Option<&Bound<'_, PyAny>>,
    init: Option<&str>,
    refine: Option<&str>,
    hold: Option<&str>,
    delay: Option<&Bound<'_, PyAny>>,
    modes: Option<&Bound<'_, PyAny>>,
    method: &str,
    weighting: &str,
    frf_type: &str,
    order: Option<usize>,
    bands: Option<&str>,
    band_weights: Option<&str>,
) -> PyResult<Model> {
    let spec = spec(
        band,
        init,
        refine,
        hold,
        delay,
        modes,
        method,
        weighting,
        frf_type,
        order,
        bands,
        band_weights,
    )?;
    spec.check(&data.inner).map_err(to_py)?;
    let mut cfg = spec.pipeline_config();
    // as `frfit fit` without --report: no verdict, no floor comparison
    cfg.final_analysis = false;
    let source = source_of(data);
    let frf = &data.inner;
    let out = py
        .detach(|| run::run(frf, &source, &cfg, "fit"))
        .map_err(to_py)?;
    model_of(&out, &source, "frfit (python) fit")
}

/// Error of a model against the data: median and 95th percentile of `|G - P| / |G|`,
/// and `residual_to_noise` (1 at the noise level).
#[pyclass(module = "frfit", name = "ErrorStats", frozen, get_all)]
#[derive(Debug, Clone, Copy)]
pub struct ErrorStats {
    /// Median over lines and entries of `|G - P| / |G|`.
    pub median_rel: f64,
    /// Its 95th percentile.
    pub p95_rel: f64,
    /// `sqrt(mean |G - P|^2 / var)`.
    pub residual_to_noise: f64,
}

impl From<frfit::summary::ErrorStats> for ErrorStats {
    fn from(e: frfit::summary::ErrorStats) -> Self {
        Self {
            median_rel: e.median_rel,
            p95_rel: e.p95_rel,
            residual_to_noise: e.residual_to_noise,
        }
    }
}

#[pymethods]
impl ErrorStats {
    fn __repr__(&self) -> String {
        format!(
            "ErrorStats(median_rel={:.3e}, p95_rel={:.3e}, residual_to_noise={:.4})",
            self.median_rel, self.p95_rel, self.residual_to_noise
        )
    }
}

/// One step of the diagnosis: a candidate effect, tested, with the error before and
/// after its refit.
#[pyclass(module = "frfit", name = "Step", frozen)]
pub struct Step {
    s: StepSummary,
}

#[pymethods]
impl Step {
    /// `missed_mode`, `delay`, `hold`, `feedthrough`, `stiffness`, `input_dynamics`,
    /// `output_dynamics`, ...
    #[getter]
    fn effect(&self) -> String {
        self.s.effect().to_string()
    }
    /// Whether the effect was added to the model.
    #[getter]
    fn accepted(&self) -> bool {
        self.s.accepted
    }
    /// Why it was a candidate, in words with numbers.
    #[getter]
    fn evidence(&self) -> String {
        self.s.evidence.clone()
    }
    /// Its estimated parameters (a dict).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.s.fitted.params_json())
    }
    /// Standard deviations of the parameters, where available (a dict), or `None`.
    #[getter]
    fn uncertainty<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.s.uncertainty)
    }
    /// F statistic of the refit.
    #[getter]
    fn f_statistic(&self) -> f64 {
        self.s.f_statistic
    }
    /// The critical value it had to pass.
    #[getter]
    fn f_critical(&self) -> f64 {
        self.s.f_critical
    }
    /// Real parameters the effect adds.
    #[getter]
    fn added_params(&self) -> usize {
        self.s.added_params
    }
    /// Error before the step.
    #[getter]
    fn before(&self) -> ErrorStats {
        self.s.before.into()
    }
    /// Error after the refit with the effect.
    #[getter]
    fn after(&self) -> ErrorStats {
        self.s.after.into()
    }
    /// The step (1-based) that took this step's factor out of the model again, if any.
    #[getter]
    fn superseded_by(&self) -> Option<usize> {
        self.s.superseded_by
    }
    /// The step's weighted cost on interleaved held-out lines, `(before, after)`: the
    /// model without and with it, each refitted on the even lines and tested on the odd
    /// ones and the reverse (the round's best trial only; `None` otherwise).
    #[getter]
    fn held_out(&self) -> Option<(f64, f64)> {
        self.s.held_out.map(|h| (h.before, h.after))
    }
    fn __repr__(&self) -> String {
        format!(
            "Step({}, {}, F={:.3e} (crit {:.3}), median rel {:.3e} -> {:.3e})",
            self.s.effect(),
            if self.s.accepted {
                "accepted"
            } else {
                "rejected"
            },
            self.s.f_statistic,
            self.s.f_critical,
            self.s.before.median_rel,
            self.s.after.median_rel
        )
    }
}

/// What `frfit.diagnose` found: the final model, the steps, the verdict and its
/// evidence; `report(dir)` writes the report as `frfit diagnose --report` does.
#[pyclass(module = "frfit", name = "Diagnosis", frozen)]
pub struct Diagnosis {
    out: PipelineOutput,
    model: Py<Model>,
    source: String,
    /// The initial and the final model on the test records, when they were given.
    test: Option<frfit::predict::TestRecordPredictions>,
}

#[pymethods]
impl Diagnosis {
    /// The final model.
    #[getter]
    fn model(&self, py: Python<'_>) -> Py<Model> {
        self.model.clone_ref(py)
    }
    /// The model before the diagnosis loop (the first fit, or `fit`'s model when the
    /// diagnosis started again from it).
    #[getter]
    fn initial_model(&self) -> PyResult<Model> {
        let band = self.out.summary.data.band_hz;
        let provenance = additive_riv::Provenance {
            data: Some(self.source.clone()),
            frfit_version: format!(
                "{} (frfit (python) diagnose, the model before the loop)",
                env!("CARGO_PKG_VERSION")
            ),
            ..Default::default()
        };
        let file = additive_riv::ModelFile::from_model(
            &self.out.initial_model,
            self.out.band.units.clone(),
            Some((band[0], band[1])),
            provenance,
        )
        .map_err(|e| {
            to_py(FrfitError::Fit {
                what: "model file".into(),
                why: e.to_string(),
            })
        })?;
        Model::from_file(file, None, &self.source)
    }
    /// `(initial, final)`: the test records given to `diagnose(test_records=...)`
    /// predicted by the model before the loop and by the final model (`Prediction`s:
    /// NRMSE per output and the records' noise floor); `None` without test records.
    #[getter]
    fn test_predictions(&self) -> Option<(Prediction, Prediction)> {
        self.test.as_ref().map(|t| {
            (
                Prediction {
                    p: t.initial.clone(),
                },
                Prediction {
                    p: t.final_model.clone(),
                },
            )
        })
    }
    /// The steps of the loop, in order.
    #[getter]
    fn steps(&self) -> Vec<Step> {
        self.out
            .summary
            .steps
            .iter()
            .map(|s| Step { s: s.clone() })
            .collect()
    }
    /// `noise_limited`, `nonlinear_distortion` or `unexplained_residual`.
    #[getter]
    fn verdict(&self) -> String {
        self.out.summary.verdict.name().to_string()
    }
    /// The evidence for the verdict, in words with numbers.
    #[getter]
    fn verdict_evidence(&self) -> String {
        self.out.summary.verdict_evidence.clone()
    }
    /// Error of the first model (before the loop) against the data.
    #[getter]
    fn initial_errors(&self) -> ErrorStats {
        self.out.summary.initial.errors.into()
    }
    /// Error of the final model against the data.
    #[getter]
    fn final_errors(&self) -> ErrorStats {
        self.out.summary.final_errors.into()
    }
    /// The whole summary (`summary.json`) as a dict.
    #[getter]
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.summary)
    }
    /// Writes `report.md`, its SVG figures, `summary.json` and `model.json` into `dir`;
    /// with test records, also `test_records/initial/` and `final/` and a section of
    /// `report.md` comparing the two models on them.
    fn report(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        let out = &self.out;
        let source = &self.source;
        let test = &self.test;
        py.detach(|| -> Result<(), FrfitError> {
            out.write_outputs(
                &dir.join("model.json"),
                Some(&dir),
                Path::new(source),
                "frfit (python) diagnose",
            )?;
            if let Some(t) = test {
                t.write_into_report(&dir)?;
            }
            Ok(())
        })
        .map_err(to_py)
    }
    fn __repr__(&self) -> String {
        let s = &self.out.summary;
        format!(
            "Diagnosis({}, {} steps ({} accepted), {} modes, median rel {:.3e} -> {:.3e})",
            s.verdict,
            s.steps.len(),
            s.steps.iter().filter(|s| s.accepted).count(),
            s.final_model.modes.len(),
            s.initial.errors.median_rel,
            s.final_errors.median_rel
        )
    }
}

/// Fits `data` and traces the residual to effects the model lacks, as `frfit diagnose`
/// does (the options of `fit`, plus `fs`: the sample rate to test a hold at, and
/// `start`: a `Model` to start from instead of the first fit). `test_records=(u, y)`:
/// periodic test records (shaped as for `frfit.nonparametric`, sampled at `fs`, else at
/// the rate the data declare; `test_period` samples per period when the arrays do not
/// say) that the initial and the final model predict, as `--test-records` does
/// (`Diagnosis.test_predictions`, and a section of the report).
#[pyfunction]
#[pyo3(signature = (data, band=None, init=None, refine=None, hold=None, delay=None, modes=None,
    method="riv", weighting="auto", frf_type="displacement", order=None, fs=None, start=None,
    test_records=None, test_period=None))]
pub fn diagnose(
    py: Python<'_>,
    data: &FrfData,
    band: Option<&Bound<'_, PyAny>>,
    init: Option<&str>,
    refine: Option<&str>,
    hold: Option<&str>,
    delay: Option<&Bound<'_, PyAny>>,
    modes: Option<&Bound<'_, PyAny>>,
    method: &str,
    weighting: &str,
    frf_type: &str,
    order: Option<usize>,
    fs: Option<f64>,
    start: Option<&Model>,
    test_records: Option<(Bound<'_, PyAny>, Bound<'_, PyAny>)>,
    test_period: Option<usize>,
) -> PyResult<Diagnosis> {
    let mut spec = spec(
        band, init, refine, hold, delay, modes, method, weighting, frf_type, order, None, None,
    )?;
    spec.fs_hz = fs;
    spec.check(&data.inner).map_err(to_py)?;
    let mut cfg = spec.pipeline_config();
    cfg.diagnose = true;
    if let Some(m) = start {
        if (m.file.ny, m.file.nu) != (data.inner.ny(), data.inner.nu()) {
            return Err(arg_err(
                "start",
                format!("{}x{} model", m.file.ny, m.file.nu),
                format!("the data are {}x{}", data.inner.ny(), data.inner.nu()),
            ));
        }
        cfg.start_model = Some(m.model.clone());
    }
    // the test records are read (and their errors raised) before the diagnosis runs
    let test_fs = fs.or(frfit::declared::declared(&data.inner).fs_hz);
    let test = match &test_records {
        Some((u, y)) => {
            let fs = test_fs.ok_or_else(|| {
                arg_err(
                    "test_records",
                    "given",
                    "their sample rate is unknown: pass fs=... (or use data that declare it)",
                )
            })?;
            let (experiments, period_of_arrays) = crate::data::experiments(py, u, y)?;
            let spec = frfit::nonparametric::RecordSpec {
                fs: Some(fs),
                period: test_period.or(period_of_arrays),
                // every record is compared on its own
                realizations: Some(1),
                ..Default::default()
            };
            Some(
                py.detach(|| frfit::nonparametric::spectra_from_arrays(&experiments, &spec))
                    .map_err(to_py)?,
            )
        }
        None => None,
    };
    let source = source_of(data);
    let frf = &data.inner;
    let (out, test) = py
        .detach(|| -> Result<_, FrfitError> {
            let out = run::run(frf, &source, &cfg, "diagnose")?;
            let test = test
                .map(|s| {
                    frfit::predict::TestRecordPredictions::of(&out, &s, "the test_records arrays")
                })
                .transpose()?;
            Ok((out, test))
        })
        .map_err(to_py)?;
    let model = Py::new(py, model_of(&out, &source, "frfit (python) diagnose")?)?;
    Ok(Diagnosis {
        out,
        model,
        source,
        test,
    })
}

/// The smallest model uncertainty per line against an independent validation
/// measurement (Oomen and Bosgra), as `frfit validate` computes it.
#[pyclass(module = "frfit", name = "Validation", frozen)]
pub struct Validation {
    v: FrfValidation,
    model_desc: String,
    data_source: String,
    units: Option<String>,
}

impl Validation {
    /// A per-line value that is there with the model's own uncertainty only.
    fn per_line<'py>(
        &self,
        py: Python<'py>,
        get: impl Fn(&frfit::validation::LineValidation) -> Option<f64>,
    ) -> Option<Bound<'py, PyAny>> {
        self.v.beyond_model_uncertainty.as_ref()?;
        Some(real_1d(
            py,
            self.v
                .lines
                .iter()
                .map(|l| get(l).unwrap_or(f64::NAN))
                .collect(),
        ))
    }
}

#[pymethods]
impl Validation {
    /// `not invalidated` or `invalidated at zero uncertainty`.
    #[getter]
    fn verdict(&self) -> &'static str {
        verdict_text(self.v.verdict)
    }
    /// Whether the model is not invalidated without added uncertainty.
    #[getter]
    fn not_invalidated(&self) -> bool {
        matches!(self.v.verdict, frfit::validation::Verdict::NotInvalidated)
    }
    /// Probability level.
    #[getter]
    fn alpha(&self) -> f64 {
        self.v.alpha
    }
    /// Largest `gamma`.
    #[getter]
    fn gamma_max(&self) -> f64 {
        self.v.gamma_max
    }
    /// Median `gamma`.
    #[getter]
    fn gamma_median(&self) -> f64 {
        self.v.gamma_median
    }
    /// Lines where the disturbance alone does not explain the residual.
    #[getter]
    fn lines_invalidated_at_zero(&self) -> usize {
        self.v.lines_invalidated_at_zero
    }
    /// Frequencies of the lines, Hz.
    #[getter]
    fn freq_hz<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.v.lines.iter().map(|l| l.f_hz).collect())
    }
    /// `gamma` per line: the smallest additive uncertainty for which the model is not
    /// invalidated.
    #[getter]
    fn gamma<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.v.lines.iter().map(|l| l.gamma).collect())
    }
    /// The disturbance bound per line.
    #[getter]
    fn disturbance_bound<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(
            py,
            self.v.lines.iter().map(|l| l.disturbance_bound).collect(),
        )
    }
    /// The model error per line.
    #[getter]
    fn model_error<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.v.lines.iter().map(|l| l.model_error).collect())
    }
    /// With `fit_data`: the reading with the model's own uncertainty next to the data's
    /// (`verdict`, `lines_invalidated_at_zero`, `gamma_max`, `gamma_median`,
    /// `model_bound_max`, `model_to_disturbance_median`) as a dict; `None` without it.
    #[getter]
    fn beyond_model_uncertainty<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.v
            .beyond_model_uncertainty
            .as_ref()
            .map(|b| to_python(py, b))
            .transpose()
    }
    /// With `fit_data`: the largest radius of the model's own uncertainty per line;
    /// `None` without it.
    #[getter]
    fn model_bound<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.per_line(py, |l| l.model_bound)
    }
    /// With `fit_data`: `gamma` beyond the model's own uncertainty per line (what its
    /// structure misses); `None` without it.
    #[getter]
    fn gamma_beyond_model<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.per_line(py, |l| l.gamma_beyond_model)
    }
    /// The whole result (`validation.json`) as a dict.
    #[getter]
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.v)
    }
    /// Writes `validation.json`, `gamma.svg` and `report.md` into `dir`.
    fn report(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| {
            write_validation_dir(
                &dir,
                "model",
                &self.model_desc,
                &self.data_source,
                &self.v,
                self.units.as_deref(),
            )
        })
        .map_err(to_py)
    }
    fn __repr__(&self) -> String {
        format!(
            "Validation({}, gamma max {:.3e}, median {:.3e}, {} lines)",
            verdict_text(self.v.verdict),
            self.v.gamma_max,
            self.v.gamma_median,
            self.v.lines.len()
        )
    }
}

/// Validates `model` on an independent measurement `data` (with a variance): the
/// minimum additive uncertainty per line (Oomen and Bosgra). `method`: `"closed-form"`
/// (exact for additive uncertainty) or `"mu"` (the structured singular value bisection).
/// `fit_data`: the data the model was fitted to (its band is the one the model records);
/// the model's own uncertainty at the validation lines is then read next to the data's
/// (`Validation.beyond_model_uncertainty`).
#[pyfunction]
#[pyo3(signature = (model, data, alpha=0.99, method="closed-form", fit_data=None))]
pub fn validate(
    py: Python<'_>,
    model: &Model,
    data: &FrfData,
    alpha: f64,
    method: &str,
    fit_data: Option<&FrfData>,
) -> PyResult<Validation> {
    let method = match method.to_ascii_lowercase().replace('_', "-").as_str() {
        "closed-form" => GammaMethod::ClosedForm,
        "mu" => GammaMethod::Mu,
        _ => return Err(arg_err("method", method, "expected closed-form or mu")),
    };
    let (file, frf) = (&model.file, &data.inner);
    let config = frfit::pipeline::PipelineConfig::default();
    let fitted_on = fit_data.map(|d| FitDataOfModel {
        data: &d.inner,
        config: &config,
        name: source_of(d),
    });
    let (v, model_desc) = py
        .detach(|| validate_model(file, "model", frf, alpha, method, fitted_on.as_ref()))
        .map_err(to_py)?;
    Ok(Validation {
        v,
        model_desc,
        data_source: source_of(data),
        units: data.inner.units.clone(),
    })
}

/// A balanced truncation (`frfit.reduce`): the Hankel singular values of the stable
/// part, the a-priori bound of each order, and with an order the reduced model.
#[pyclass(module = "frfit", name = "Reduction", frozen)]
pub struct Reduction {
    hankel: Vec<f64>,
    bounds: Vec<f64>,
    rigid_order: usize,
    stable_order: usize,
    model: Option<Py<Model>>,
    error_bound: Option<f64>,
    measured_error: Option<f64>,
}

#[pymethods]
impl Reduction {
    /// Hankel singular values of the stable part, decreasing.
    #[getter]
    fn hankel_singular_values<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.hankel.clone())
    }
    /// `bounds[k]`: the a-priori H-infinity error bound with `rigid_order + k` states.
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.bounds.clone())
    }
    /// Rigid-body states (kept exactly).
    #[getter]
    fn rigid_order(&self) -> usize {
        self.rigid_order
    }
    /// Stable states of the full model.
    #[getter]
    fn stable_order(&self) -> usize {
        self.stable_order
    }
    /// The reduced model, when an order was given.
    #[getter]
    fn model(&self, py: Python<'_>) -> Option<Py<Model>> {
        self.model.as_ref().map(|m| m.clone_ref(py))
    }
    /// The a-priori bound of the reduced model.
    #[getter]
    fn error_bound(&self) -> Option<f64> {
        self.error_bound
    }
    /// The H-infinity error measured on a dense grid.
    #[getter]
    fn measured_error(&self) -> Option<f64> {
        self.measured_error
    }
    fn __repr__(&self) -> String {
        format!(
            "Reduction({} rigid-body + {} stable states{})",
            self.rigid_order,
            self.stable_order,
            self.error_bound
                .map(|b| format!(", reduced with bound {b:.3e}"))
                .unwrap_or_default()
        )
    }
}

/// Balanced truncation of `model` (rigid body kept exactly): without `order` the Hankel
/// singular values and the bound of each order; with `order` (states in all) also the
/// reduced model.
#[pyfunction]
#[pyo3(signature = (model, order=None))]
pub fn reduce(py: Python<'_>, model: &Model, order: Option<usize>) -> PyResult<Reduction> {
    let file = &model.file;
    let a = py
        .detach(|| frfit::reduce::analyse_file(file))
        .map_err(to_py)?;
    let h = &a.hankel;
    let bounds = (0..=h.hankel_singular_values.len())
        .map(|k| h.error_bound(k))
        .collect();
    let mut r = Reduction {
        hankel: h.hankel_singular_values.clone(),
        bounds,
        rigid_order: h.rigid_order,
        stable_order: h.stable_order,
        model: None,
        error_bound: None,
        measured_error: None,
    };
    if let Some(order) = order {
        let red = py
            .detach(|| frfit::reduce::reduce_file(file, order, "model"))
            .map_err(|e| match e {
                FrfitError::Realize(realize::RealizeError::InvalidParameter {
                    name,
                    value,
                    why,
                }) if name == "order" => arg_err("order", value, why),
                other => to_py(other),
            })?;
        r.error_bound = Some(red.reduction.error_bound);
        r.measured_error = Some(red.measured_error);
        r.model = Some(Py::new(
            py,
            Model::from_file(red.file, None, "reduced model")?,
        )?);
    }
    Ok(r)
}

/// The prediction of test records by a model (`frfit.predict`): per output the NRMSE
/// over the excited lines against the records' own noise floor.
#[pyclass(module = "frfit", name = "Prediction", frozen)]
pub struct Prediction {
    p: frfit::predict::Prediction,
}

#[pymethods]
impl Prediction {
    /// NRMSE per output.
    #[getter]
    fn nrmse<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.p.outputs.iter().map(|o| o.nrmse).collect())
    }
    /// The records' noise floor per output (NaN with one period).
    #[getter]
    fn noise_floor<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(
            py,
            self.p
                .outputs
                .iter()
                .map(|o| o.noise_floor.unwrap_or(f64::NAN))
                .collect(),
        )
    }
    /// The excited lines, Hz.
    #[getter]
    fn freq_hz<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.p.freq_hz.clone())
    }
    /// Records (experiments) compared.
    #[getter]
    fn records(&self) -> usize {
        self.p.records
    }
    /// Writes `prediction.json` and `prediction.svg` into `dir`.
    fn report(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| self.p.write(&dir, "frfit predict"))
            .map_err(to_py)
    }
    fn __repr__(&self) -> String {
        format!(
            "Prediction({} records, NRMSE {:?})",
            self.p.records,
            self.p.outputs.iter().map(|o| o.nrmse).collect::<Vec<_>>()
        )
    }
}

/// Predicts periodic test records with `model`, as `frfit predict` does: `u` and `y`
/// time records shaped as for `frfit.nonparametric`; the periodic steady state
/// `Y(k) = G(k) U(k)` on the excited lines against the measured outputs.
#[pyfunction]
#[pyo3(signature = (model, u, y, fs, period=None, drop_periods=0, lines=None))]
pub fn predict(
    py: Python<'_>,
    model: &Model,
    u: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    fs: f64,
    period: Option<usize>,
    drop_periods: usize,
    lines: Option<Vec<usize>>,
) -> PyResult<Prediction> {
    let (experiments, period_of_arrays) = crate::data::experiments(py, u, y)?;
    let spec = frfit::nonparametric::RecordSpec {
        fs: Some(fs),
        period: period.or(period_of_arrays),
        drop_periods,
        lines,
        realizations: Some(1),
        ..Default::default()
    };
    let m = &model.model;
    let p = py
        .detach(|| -> Result<_, FrfitError> {
            let spectra = frfit::nonparametric::spectra_from_arrays(&experiments, &spec)?;
            let omega: Vec<f64> = spectra
                .freq_hz
                .iter()
                .map(|f| f * std::f64::consts::TAU)
                .collect();
            let g = frf_data::ModelStructure::response_at(m, &omega);
            frfit::predict::predict(&g, &spectra)
        })
        .map_err(to_py)?;
    Ok(Prediction { p })
}
