//! `frfit.Model`, `frfit.Mode`, `frfit.StateSpace` and `frfit.load_model`: a fitted
//! model out (its modes with their uncertainty, its response, its state space, the file).

use crate::arrays::{array_3d, real_2d, real_array};
use crate::{arg_err, to_py};
use additive_riv::{AdditiveModel, ModelFile};
use frf_data::ModelStructure;
use frfit::export::{export_state_space, mat_bytes, StateSpaceExport};
use frfit::summary::Summary;
use frfit::FrfitError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Python's `json.loads(text)`: a typed record as plain Python values.
pub fn json_value<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// A serialisable value as plain Python values (dicts, lists, numbers, strings).
pub fn to_python<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let s = serde_json::to_string(v).map_err(|e| {
        to_py(FrfitError::Fit {
            what: "conversion to Python".into(),
            why: e.to_string(),
        })
    })?;
    json_value(py, &s)
}

/// One mode of a model: natural frequency (Hz) and relative damping, with their standard
/// deviations when the fit computed a covariance (`None` otherwise), and the rank of its
/// residue.
#[pyclass(module = "frfit", name = "Mode", frozen, get_all)]
#[derive(Debug, Clone)]
pub struct Mode {
    /// Natural frequency `|p| / 2 pi`, Hz.
    pub f_hz: f64,
    /// Relative damping `-Re p / |p|`.
    pub zeta: f64,
    /// Standard deviation of `f_hz`, Hz, or `None`.
    pub f_hz_std: Option<f64>,
    /// Standard deviation of `zeta`, or `None`.
    pub zeta_std: Option<f64>,
    /// Numerical rank of the residue.
    pub rank: usize,
}

#[pymethods]
impl Mode {
    fn __repr__(&self) -> String {
        let pm = |v: Option<f64>| v.map(|s| format!(" +- {s:.3e}")).unwrap_or_default();
        format!(
            "Mode(f_hz={:.6}{}, zeta={:.6}{}, rank={})",
            self.f_hz,
            pm(self.f_hz_std),
            self.zeta,
            pm(self.zeta_std),
            self.rank
        )
    }
}

/// A fitted model: the additive modal model of the wafer-stage paper (rigid body, one
/// second-order submodel per mode with a residue matrix, feedthrough) with its known
/// factors (delay, hold, derivative order, fitted input/output dynamics), as `frfit fit`
/// writes it to MODEL.json.
#[pyclass(module = "frfit", name = "Model", frozen)]
pub struct Model {
    pub(crate) file: ModelFile,
    pub(crate) model: AdditiveModel,
    pub(crate) summary: Option<Summary>,
}

impl Model {
    /// The model of a file (rebuilt once, for responses).
    pub fn from_file(file: ModelFile, summary: Option<Summary>, source: &str) -> PyResult<Self> {
        let model = file.to_model().map_err(|e| {
            to_py(FrfitError::Io {
                path: source.to_string(),
                message: e.to_string(),
            })
        })?;
        Ok(Self {
            file,
            model,
            summary,
        })
    }

    /// The state space of the model (see `frfit export`).
    fn export(
        &self,
        discrete_fs: Option<f64>,
        rank_tol: f64,
    ) -> Result<StateSpaceExport, FrfitError> {
        let frf_model = self.model.to_frf_model()?;
        export_state_space(&frf_model, discrete_fs, rank_tol, self.file.units.clone())
    }
}

#[pymethods]
impl Model {
    /// The modes, in increasing frequency.
    #[getter]
    fn modes(&self) -> Vec<Mode> {
        self.file
            .modes
            .iter()
            .map(|m| Mode {
                f_hz: m.f_hz,
                zeta: m.zeta,
                f_hz_std: m.f_hz_std,
                zeta_std: m.zeta_std,
                rank: m.rank,
            })
            .collect()
    }
    /// Outputs.
    #[getter]
    fn ny(&self) -> usize {
        self.file.ny
    }
    /// Inputs.
    #[getter]
    fn nu(&self) -> usize {
        self.file.nu
    }
    /// The delay of the known factor `exp(-j w delay_s)`, seconds.
    #[getter]
    fn delay_s(&self) -> f64 {
        self.file.delay_s
    }
    /// Its standard deviation, seconds, when the fit computed one.
    #[getter]
    fn delay_s_std(&self) -> Option<f64> {
        self.file.delay_s_std
    }
    /// Whether the delay was a fitted parameter.
    #[getter]
    fn delay_fitted(&self) -> bool {
        self.file.delay_fitted
    }
    /// The hold: `"zoh:FS"` (exact), `"sinc:FS"` or `"none"`.
    #[getter]
    fn hold(&self) -> String {
        self.file.hold.clone()
    }
    /// `k` of the factor `(j w)^k` (0 displacement, 1 velocity, 2 accelerance).
    #[getter]
    fn derivative_order(&self) -> u32 {
        self.file.derivative_order
    }
    /// Minimal number of real states.
    #[getter]
    fn order(&self) -> usize {
        self.file.order
    }
    /// Units of the modelled FRF, when known.
    #[getter]
    fn units(&self) -> Option<String> {
        self.file.units.clone()
    }
    /// The band the model was fitted on, Hz.
    #[getter]
    fn band_hz(&self) -> Option<(f64, f64)> {
        self.file.band_hz.map(|b| (b[0], b[1]))
    }
    /// Whether the model has a rigid-body part (integrators).
    #[getter]
    fn rigid_body(&self) -> bool {
        self.file.rigid_body.is_some()
    }
    /// The feedthrough `D` (ny, nu), or `None`.
    #[getter]
    fn feedthrough<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.file
            .feedthrough
            .as_ref()
            .map(|d| real_2d(py, d, self.file.nu))
            .transpose()
    }
    /// The fitted dynamics factors of input columns or output rows (dicts), if any.
    #[getter]
    fn dynamics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.file.dynamics)
    }
    /// How the fit stopped (`converged ...` or why not).
    #[getter]
    fn convergence(&self) -> String {
        self.file.provenance.convergence.clone()
    }
    /// Whether the fit converged.
    #[getter]
    fn converged(&self) -> bool {
        self.file.provenance.convergence.starts_with("converged")
    }
    /// The estimator chain that made the model (`["cmif", "riv"]`).
    #[getter]
    fn chain(&self) -> Vec<String> {
        self.file.provenance.chain.clone()
    }
    /// The fit's notes (what the fitter did on the way).
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.file.provenance.notes.clone()
    }
    /// The summary of the run that made the model (`summary.json` as a dict), or `None`
    /// for a model read from a file.
    #[getter]
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.summary.as_ref().map(|s| to_python(py, s)).transpose()
    }

    /// The model's response at `freq_hz` (Hz), complex `(n, ny, nu)`, with every factor
    /// it was fitted with (delay, hold, derivative order, dynamics).
    fn response<'py>(
        &self,
        py: Python<'py>,
        freq_hz: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let f = real_array(py, freq_hz, "freq_hz")?;
        if f.shape.len() > 1 {
            return Err(arg_err(
                "freq_hz",
                format!("shape {:?}", f.shape),
                "expected a 1-D array of frequencies in Hz",
            ));
        }
        if let Some(x) = f.values.iter().find(|x| !x.is_finite()) {
            return Err(arg_err("freq_hz", x, "frequencies must be finite"));
        }
        let omega: Vec<f64> = f.values.iter().map(|f| f * std::f64::consts::TAU).collect();
        let model = &self.model;
        let grid = py.detach(|| model.response_at(&omega));
        array_3d(py, &grid.values, f.values.len(), grid.ny, grid.nu)
    }

    /// The model as a real state space (modal block form, rigid-body integrators
    /// included) with its factors stated beside it: the response is
    /// `(j w)^k exp(-j w delay_s) [C (j w I - A)^-1 B + D]` (for a model fitted with the
    /// exact hold, `Cd (z I - Ad)^-1 Bd + Dd` at `z = exp(j w Ts)`), plus a crosstalk and
    /// times the dynamics factors when the model has them. `rank_tol`: relative rank
    /// tolerance of the residues (0: the model exactly); `discrete_fs`: also the exact
    /// zero-order-hold equivalent at this rate, Hz.
    #[pyo3(signature = (rank_tol=0.0, discrete_fs=None))]
    fn state_space(
        &self,
        py: Python<'_>,
        rank_tol: f64,
        discrete_fs: Option<f64>,
    ) -> PyResult<StateSpace> {
        if !(rank_tol.is_finite() && (0.0..1.0).contains(&rank_tol)) {
            return Err(arg_err(
                "rank_tol",
                rank_tol,
                "a relative tolerance in [0, 1)",
            ));
        }
        let e = py
            .detach(|| self.export(discrete_fs, rank_tol))
            .map_err(to_py)?;
        Ok(StateSpace { e })
    }

    /// The model as a python-control `StateSpace`: discrete with `dt` for a model fitted
    /// with the exact zero-order hold, continuous otherwise. What a state space cannot
    /// hold is stated beside it as attributes of the returned system, never dropped:
    /// `delay_s` (apply `exp(-j w delay_s)`), `derivative_order` (times `(j w)^k`),
    /// `frfit_factors` (crosstalk and dynamics factors); with `warn=True` a warning says
    /// when any of them is not trivial.
    #[pyo3(signature = (warn=true))]
    fn to_control<'py>(&self, py: Python<'py>, warn: bool) -> PyResult<Bound<'py, PyAny>> {
        self.state_space(py, 0.0, None)?.to_control(py, warn)
    }

    /// Writes the model file (MODEL.json, readable by `frfit eval` and `load_model`).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let file = &self.file;
        py.detach(|| file.write(&path)).map_err(|e| {
            to_py(FrfitError::Io {
                path: path.display().to_string(),
                message: e.to_string(),
            })
        })
    }

    /// Writes the state space as `frfit export` does: `.json` (every factor) or `.mat`
    /// (`A, B, C, D, delay_s, derivative_order`; `Ad, Bd, Cd, Dd, Ts` with a discrete
    /// form).
    #[pyo3(signature = (path, discrete_fs=None, rank_tol=0.0))]
    fn export_state_space(
        &self,
        py: Python<'_>,
        path: PathBuf,
        discrete_fs: Option<f64>,
        rank_tol: f64,
    ) -> PyResult<()> {
        let ss = self.state_space(py, rank_tol, discrete_fs)?;
        ss.save(py, path)
    }

    /// The model file as JSON text.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.file).map_err(|e| {
            to_py(FrfitError::Fit {
                what: "model file".into(),
                why: e.to_string(),
            })
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({}x{}, {} modes, order {}, delay {:.4} us, hold {}, {})",
            self.file.ny,
            self.file.nu,
            self.file.modes.len(),
            self.file.order,
            self.file.delay_s * 1e6,
            self.file.hold,
            self.file.provenance.convergence
        )
    }
}

/// Reads a model file written by `frfit fit`, `frfit diagnose`, `frfit reduce` or
/// `Model.save`.
#[pyfunction]
pub fn load_model(py: Python<'_>, path: PathBuf) -> PyResult<Model> {
    let file = py.detach(|| ModelFile::read(&path)).map_err(|e| {
        to_py(FrfitError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })
    })?;
    Model::from_file(file, None, &path.display().to_string())
}

/// A model as a real state space with its factors (see `Model.state_space`).
#[pyclass(module = "frfit", name = "StateSpace", frozen)]
pub struct StateSpace {
    e: StateSpaceExport,
}

#[pymethods]
impl StateSpace {
    /// State matrix `A` (n, n) of the continuous realization.
    #[getter(A)]
    fn a<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        real_2d(py, &self.e.continuous.a, self.e.n_states)
    }
    /// Input matrix `B` (n, nu).
    #[getter(B)]
    fn b<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        real_2d(py, &self.e.continuous.b, self.e.nu)
    }
    /// Output matrix `C` (ny, n).
    #[getter(C)]
    fn c<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        real_2d(py, &self.e.continuous.c, self.e.n_states)
    }
    /// Feedthrough `D` (ny, nu).
    #[getter(D)]
    fn d<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        real_2d(py, &self.e.continuous.d, self.e.nu)
    }
    /// `(Ad, Bd, Cd, Dd)` of the exact zero-order-hold equivalent, or `None`.
    #[getter]
    fn discrete<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let Some(d) = &self.e.discrete else {
            return Ok(None);
        };
        let m = &d.matrices;
        let t = (
            real_2d(py, &m.a, self.e.n_states)?,
            real_2d(py, &m.b, self.e.nu)?,
            real_2d(py, &m.c, self.e.n_states)?,
            real_2d(py, &m.d, self.e.nu)?,
        );
        Ok(Some(t.into_pyobject(py)?.into_any()))
    }
    /// Sample time of the discrete form, seconds, or `None`.
    #[getter]
    fn dt(&self) -> Option<f64> {
        self.e.discrete.as_ref().map(|d| d.ts_s)
    }
    /// The delay beyond the rational part (beyond the hold for the exact hold), seconds.
    #[getter]
    fn delay_s(&self) -> f64 {
        self.e.factors.delay_s
    }
    /// `k` of `(j w)^k`.
    #[getter]
    fn derivative_order(&self) -> u32 {
        self.e.factors.derivative_order
    }
    /// The hold the model was fitted with.
    #[getter]
    fn hold(&self) -> String {
        self.e.factors.hold.clone()
    }
    /// States of the continuous realization.
    #[getter]
    fn n_states(&self) -> usize {
        self.e.n_states
    }
    /// The response formula the matrices and factors make.
    #[getter]
    fn formula(&self) -> String {
        self.e.response.clone()
    }
    /// The crosstalk `X` (ny, nu) that bypasses the delay, or `None`.
    #[getter]
    fn crosstalk<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.e
            .factors
            .crosstalk
            .as_ref()
            .map(|x| real_2d(py, x, self.e.nu))
            .transpose()
    }
    /// The dynamics factors (dicts).
    #[getter]
    fn dynamics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.e.factors.dynamics)
    }

    /// Writes `.json` (frfit-state-space) or `.mat` (MATLAB level 5).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let ext = path
            .extension()
            .and_then(|x| x.to_str())
            .map(str::to_ascii_lowercase);
        let bytes = match ext.as_deref() {
            Some("json") => serde_json::to_vec_pretty(&self.e).map_err(|err| {
                to_py(FrfitError::Io {
                    path: path.display().to_string(),
                    message: err.to_string(),
                })
            })?,
            Some("mat") => mat_bytes(&self.e),
            _ => {
                return Err(arg_err(
                    "path",
                    path.display(),
                    "the output format follows the extension: .json or .mat",
                ))
            }
        };
        py.detach(|| std::fs::write(&path, bytes))
            .map_err(|err| to_py(FrfitError::io(&path, err)))
    }

    /// A python-control `StateSpace` of the rational part (discrete with `dt` when the
    /// model was fitted with the exact hold); the factors as attributes (see
    /// `Model.to_control`).
    #[pyo3(signature = (warn=true))]
    fn to_control<'py>(&self, py: Python<'py>, warn: bool) -> PyResult<Bound<'py, PyAny>> {
        let control = py.import("control").map_err(|_| {
            pyo3::exceptions::PyImportError::new_err(
                "python-control is not installed: pip install control (or pip install frfit[control])",
            )
        })?;
        let sys = match &self.e.discrete {
            Some(d) => {
                let m = &d.matrices;
                control.call_method1(
                    "ss",
                    (
                        real_2d(py, &m.a, self.e.n_states)?,
                        real_2d(py, &m.b, self.e.nu)?,
                        real_2d(py, &m.c, self.e.n_states)?,
                        real_2d(py, &m.d, self.e.nu)?,
                        d.ts_s,
                    ),
                )?
            }
            None => {
                control.call_method1("ss", (self.a(py)?, self.b(py)?, self.c(py)?, self.d(py)?))?
            }
        };
        let f = &self.e.factors;
        sys.setattr("delay_s", f.delay_s)?;
        sys.setattr("derivative_order", f.derivative_order)?;
        let factors = PyDict::new(py);
        factors.set_item("hold", &f.hold)?;
        factors.set_item("crosstalk", self.crosstalk(py)?)?;
        factors.set_item("dynamics", self.dynamics(py)?)?;
        factors.set_item("formula", &self.e.response)?;
        sys.setattr("frfit_factors", factors)?;
        if warn {
            let mut beside = Vec::new();
            if f.delay_s != 0.0 {
                beside.push(format!("a delay of {:.6e} s (sys.delay_s)", f.delay_s));
            }
            if f.derivative_order != 0 {
                beside.push(format!(
                    "the factor (jw)^{} (sys.derivative_order)",
                    f.derivative_order
                ));
            }
            if f.crosstalk.is_some() {
                beside.push("a crosstalk that bypasses the delay (sys.frfit_factors)".into());
            }
            if !f.dynamics.is_empty() {
                beside.push(format!(
                    "{} dynamics factor(s) (sys.frfit_factors)",
                    f.dynamics.len()
                ));
            }
            if !beside.is_empty() {
                let msg = format!(
                    "the StateSpace holds the rational part of the model; the model also has {}: apply them to match Model.response",
                    beside.join(", ")
                );
                let w = py.get_type::<pyo3::exceptions::PyUserWarning>();
                PyErr::warn(py, &w, &std::ffi::CString::new(msg).unwrap_or_default(), 1)?;
            }
        }
        Ok(sys)
    }

    /// The continuous `(A, B, C, D)` and the factors as a dict of NumPy arrays.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("A", self.a(py)?)?;
        d.set_item("B", self.b(py)?)?;
        d.set_item("C", self.c(py)?)?;
        d.set_item("D", self.d(py)?)?;
        d.set_item("delay_s", self.e.factors.delay_s)?;
        d.set_item("derivative_order", self.e.factors.derivative_order)?;
        d.set_item("hold", &self.e.factors.hold)?;
        d.set_item("dt", self.dt())?;
        d.set_item("discrete", self.discrete(py)?)?;
        d.set_item("crosstalk", self.crosstalk(py)?)?;
        d.set_item("dynamics", self.dynamics(py)?)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "StateSpace({} states, {}x{}, delay {:.4} us, hold {}{})",
            self.e.n_states,
            self.e.ny,
            self.e.nu,
            self.e.factors.delay_s * 1e6,
            self.e.factors.hold,
            self.e
                .discrete
                .as_ref()
                .map(|d| format!(", dt {:.6e} s", d.ts_s))
                .unwrap_or_default()
        )
    }
}
