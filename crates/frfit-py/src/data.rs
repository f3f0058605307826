//! `frfit.FrfData`, `frfit.read` and `frfit.nonparametric`: measured data in.

use crate::arrays::{array_3d, complex_array, frf_shape, real_1d, real_array, to_line_major};
use crate::{arg_err, data_err, to_py};
use experiment::nonparametric::time_records::ExperimentRecords;
use frf_data::{Frf, FrfDataset};
use frfit::nonparametric::{estimate_described, spectra_from_arrays, Estimated, RecordSpec};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyType};
use std::path::PathBuf;

/// A measured frequency response function: `G[k, i, j]` is the response of output `i`
/// to input `j` at `freq_hz[k]`, with optional per-entry variances (`var`: the variance
/// of the estimate, the total variance of a best linear approximation when it was
/// estimated from several realizations; `var_noise`: its noise part).
///
/// `FrfData(freq_hz, G, var=None, var_noise=None, units=None)`: `freq_hz` (n,),
/// strictly increasing, >= 0; `G` complex (n, ny, nu) (or (n,) for one entry); `var` and
/// `var_noise` real, shaped like `G`.
#[pyclass(module = "frfit", name = "FrfData", frozen)]
pub struct FrfData {
    pub(crate) inner: Frf,
}

impl FrfData {
    /// Builds the data from arrays (see the class documentation).
    fn from_arrays(
        py: Python<'_>,
        freq_hz: &Bound<'_, PyAny>,
        g: &Bound<'_, PyAny>,
        var: Option<&Bound<'_, PyAny>>,
        var_noise: Option<&Bound<'_, PyAny>>,
        units: Option<String>,
    ) -> PyResult<Frf> {
        let f = real_array(py, freq_hz, "freq_hz")?;
        if f.shape.len() != 1 {
            return Err(arg_err(
                "freq_hz",
                format!("shape {:?}", f.shape),
                "expected a 1-D array of frequencies in Hz",
            ));
        }
        let gd = complex_array(py, g, "G")?;
        let (n, ny, nu) = frf_shape(&gd.shape, "G")?;
        if n != f.values.len() {
            return Err(arg_err(
                "G",
                format!("shape {:?}", gd.shape),
                format!(
                    "G has {n} lines but freq_hz has {}: G is shaped (n_lines, ny, nu)",
                    f.values.len()
                ),
            ));
        }
        let real = |obj: Option<&Bound<'_, PyAny>>, name: &str| -> PyResult<Option<Vec<f64>>> {
            let Some(obj) = obj.filter(|o| !o.is_none()) else {
                return Ok(None);
            };
            let d = real_array(py, obj, name)?;
            if frf_shape(&d.shape, name)? != (n, ny, nu) {
                return Err(arg_err(
                    name,
                    format!("shape {:?}", d.shape),
                    format!("expected the shape of G, ({n}, {ny}, {nu})"),
                ));
            }
            Ok(Some(to_line_major(&d.values, n, ny, nu)))
        };
        let v = real(var, "var")?;
        let vn = real(var_noise, "var_noise")?;
        let values = to_line_major(&gd.values, n, ny, nu);
        let mut frf = Frf::new(f.values, ny, nu, values, v)
            .and_then(|f| f.with_noise_variance(vn))
            .map_err(data_err)?;
        frf.units = units;
        Ok(frf)
    }
}

#[pymethods]
impl FrfData {
    #[new]
    #[pyo3(signature = (freq_hz, G, var=None, var_noise=None, units=None))]
    #[allow(non_snake_case)]
    fn new(
        py: Python<'_>,
        freq_hz: &Bound<'_, PyAny>,
        G: &Bound<'_, PyAny>,
        var: Option<&Bound<'_, PyAny>>,
        var_noise: Option<&Bound<'_, PyAny>>,
        units: Option<String>,
    ) -> PyResult<Self> {
        Ok(Self {
            inner: Self::from_arrays(py, freq_hz, G, var, var_noise, units)?,
        })
    }

    /// The data of a python-control `FrequencyResponseData` (`frd`): its frequencies
    /// (rad/s) become Hz, its response `(ny, nu, n)` becomes `G (n, ny, nu)`.
    #[classmethod]
    fn from_control(_cls: &Bound<'_, PyType>, frd: &Bound<'_, PyAny>) -> PyResult<Self> {
        let py = frd.py();
        let omega = frd
            .getattr("frequency")
            .or_else(|_| frd.getattr("omega"))
            .map_err(|_| {
                arg_err(
                    "frd",
                    "<object>",
                    "expected a python-control FrequencyResponseData (with `frequency` and `fresp`)",
                )
            })?;
        // `frdata` in python-control >= 0.10.2 (`fresp` is deprecated there)
        let fresp = frd
            .getattr("frdata")
            .or_else(|_| frd.getattr("fresp"))
            .map_err(|_| {
                arg_err(
                    "frd",
                    "<object>",
                    "expected a python-control FrequencyResponseData (it has no `fresp`)",
                )
            })?;
        let np = py.import("numpy")?;
        let w = real_array(py, &omega, "frd.frequency")?;
        let freq: Vec<f64> = w.values.iter().map(|w| w / std::f64::consts::TAU).collect();
        let resp = np.call_method1("asarray", (fresp,))?;
        let ndim: usize = resp.getattr("ndim")?.extract()?;
        // (ny, nu, n) -> (n, ny, nu); a SISO response may come as (n,)
        let g = if ndim == 3 {
            resp.call_method1("transpose", ((2, 0, 1),))?
        } else {
            resp
        };
        Ok(Self {
            inner: Self::from_arrays(py, &real_1d(py, freq), &g, None, None, None)?,
        })
    }

    /// The data of a scikit-rf `Network`: `ntwk.f` (Hz) and its `param` matrix
    /// (`"s"`, `"z"`, `"y"`, ...; shaped `(n, ports, ports)`).
    #[classmethod]
    #[pyo3(signature = (ntwk, param="s"))]
    fn from_network(
        _cls: &Bound<'_, PyType>,
        ntwk: &Bound<'_, PyAny>,
        param: &str,
    ) -> PyResult<Self> {
        let py = ntwk.py();
        if !matches!(param, "s" | "z" | "y" | "a" | "t" | "h" | "g") {
            return Err(arg_err(
                "param",
                param,
                "a network parameter: s, z, y, a, t, h or g",
            ));
        }
        let f = ntwk.getattr("f").map_err(|_| {
            arg_err(
                "ntwk",
                "<object>",
                "expected a scikit-rf Network (it has no `f`)",
            )
        })?;
        let g = ntwk.getattr(param).map_err(|e| {
            arg_err(
                "param",
                param,
                format!("the network has no `{param}` matrix: {e}"),
            )
        })?;
        Ok(Self {
            inner: Self::from_arrays(py, &f, &g, None, None, None)?,
        })
    }

    /// Frequencies, Hz, `(n,)`.
    #[getter]
    fn freq_hz<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.inner.freq_hz_slice().to_vec())
    }
    /// Frequencies, rad/s, `(n,)`.
    #[getter]
    fn omega<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        real_1d(py, self.inner.omegas())
    }
    /// The response, complex `(n, ny, nu)`.
    #[getter(G)]
    fn g<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let f = &self.inner;
        array_3d(py, f.values(), f.n_lines(), f.ny(), f.nu())
    }
    /// The variance of each entry, `(n, ny, nu)`, or `None`.
    #[getter]
    fn var<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let f = &self.inner;
        f.variances()
            .map(|v| array_3d(py, v, f.n_lines(), f.ny(), f.nu()))
            .transpose()
    }
    /// The noise part of the variance, `(n, ny, nu)`, or `None` (see the class).
    #[getter]
    fn var_noise<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let f = &self.inner;
        f.noise_variances()
            .map(|v| array_3d(py, v, f.n_lines(), f.ny(), f.nu()))
            .transpose()
    }
    /// The nonlinear distortion against the noise (a dict: `nonlinear_db`, `noise_db` dB
    /// under the BLA, `total_to_noise`, `worst_hz`, `worst_db`), when the data carry the
    /// total variance and its noise part; `None` otherwise.
    #[getter]
    fn distortion<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        frfit::data::distortion_level(&self.inner)
            .map(|l| crate::model::to_python(py, &l))
            .transpose()
    }
    /// Outputs.
    #[getter]
    fn ny(&self) -> usize {
        self.inner.ny()
    }
    /// Inputs.
    #[getter]
    fn nu(&self) -> usize {
        self.inner.nu()
    }
    /// Lines.
    #[getter]
    fn n_lines(&self) -> usize {
        self.inner.n_lines()
    }
    fn __len__(&self) -> usize {
        self.inner.n_lines()
    }
    /// Units of `G`, when known.
    #[getter]
    fn units(&self) -> Option<String> {
        self.inner.units.clone()
    }
    /// Free `key=value` metadata (from the file's comments, the estimator).
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.inner.metadata {
            d.set_item(k, v)?;
        }
        Ok(d)
    }
    /// Comment lines (of the file, or of the estimate).
    #[getter]
    fn comments<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, &self.inner.comments)
    }
    /// The file the data were read from, when they were.
    #[getter]
    fn source(&self) -> Option<String> {
        self.inner.source.clone()
    }
    /// Writes the data as an FRF CSV (FORMATS.md: `_var` and `_var_noise` columns when
    /// present, the comments as comment lines).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let f = &self.inner;
        py.detach(|| frf_data::io::write_frf_csv(&path, f, &f.comments))
            .map_err(data_err)
    }
    fn __repr__(&self) -> String {
        let f = &self.inner;
        let n = f.n_lines();
        let band = if n > 0 {
            format!("{:.6}..{:.6} Hz", f.freq_hz(0), f.freq_hz(n - 1))
        } else {
            "no lines".into()
        };
        format!(
            "FrfData({}x{}, {n} lines, {band}, variance: {}{})",
            f.ny(),
            f.nu(),
            if f.noise_variances().is_some() {
                "total and noise"
            } else if f.has_variance() {
                "yes"
            } else {
                "no"
            },
            f.units
                .as_ref()
                .map(|u| format!(", units {u}"))
                .unwrap_or_default()
        )
    }
}

/// Reads an FRF file: FRF CSV, UFF 58 (`.uff`/`.unv`, ASCII or binary) or MATLAB `.mat`
/// (`G`, `freq_hz`, optionally `G_var`), chosen by the extension.
#[pyfunction]
pub fn read(py: Python<'_>, path: PathBuf) -> PyResult<FrfData> {
    let frf = py.detach(|| frfit::data::read(&path)).map_err(to_py)?;
    Ok(FrfData { inner: frf })
}

/// The experiments of the input and output record arrays `u` and `y`, each shaped
/// `(n_samples, channels[, experiments[, periods]])`
/// ([`frfit::nonparametric::records_from_array`]), and the period the arrays imply.
pub(crate) fn experiments(
    py: Python<'_>,
    u: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
) -> PyResult<(Vec<ExperimentRecords>, Option<usize>)> {
    let records = |obj: &Bound<'_, PyAny>, name: &str| -> PyResult<_> {
        let d = real_array(py, obj, name)?;
        frfit::nonparametric::records_from_array(&d.shape, &d.values, name).map_err(to_py)
    };
    frfit::nonparametric::experiments_from_arrays(records(u, "u")?, records(y, "y")?).map_err(to_py)
}

/// The nonparametric FRF of periodic experiments from time records (McKelvey; the
/// robust method of Pintelon and Schoukens with several realizations).
///
/// `u` and `y` are shaped `(n_samples, channels)`, `(n_samples, channels,
/// experiments)` or `(n_samples, channels, experiments, periods)` (then a period is
/// `n_samples` long and `period` may be omitted). `fs` is the sample rate, Hz; `period`
/// the samples per period; `drop_periods` leading periods are dropped as transient;
/// `lines` gives the excited DFT bins (else they are found from the input spectrum);
/// `realizations` how many random-phase realizations the experiments form, as
/// consecutive blocks (default: blocks of `nu` experiments). With two or more, `var` is
/// the total variance (noise and nonlinear distortion) and `var_noise` its noise part.
#[pyfunction]
#[pyo3(signature = (u, y, fs, period=None, drop_periods=0, lines=None, line_threshold_db=40.0, realizations=None))]
pub fn nonparametric(
    py: Python<'_>,
    u: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    fs: f64,
    period: Option<usize>,
    drop_periods: usize,
    lines: Option<Vec<usize>>,
    line_threshold_db: f64,
    realizations: Option<usize>,
) -> PyResult<FrfData> {
    let (experiments, period_of_arrays) = experiments(py, u, y)?;
    let spec = RecordSpec {
        fs: Some(fs),
        period: period.or(period_of_arrays),
        drop_periods,
        lines,
        line_threshold_db,
        realizations,
        ..Default::default()
    };
    let Estimated { estimate, comments } = py
        .detach(|| {
            let spectra = spectra_from_arrays(&experiments, &spec)?;
            estimate_described(&spectra, &["arrays".to_string()], &spec, Vec::new())
        })
        .map_err(to_py)?;
    let mut frf = estimate.frf;
    frf.comments = comments;
    Ok(FrfData { inner: frf })
}

/// A random lightly damped modal plant from the project's simulator (the plant `frfit
/// simulate random-modal` writes), for tests and examples with an exact truth: returns
/// `(measured, noiseless, truth)` where `measured` carries circular complex Gaussian
/// noise of std `noise` times the median magnitude (stated in its `var`), `noiseless`
/// is the exact response and `truth` a dict with the modes (`f_hz`, `zeta`, residues).
#[pyfunction]
#[pyo3(signature = (ny=4, nu=4, modes=10, lines=4000, band=(50.0, 2000.0), noise=1e-3,
    rigid_body=false, close_pairs=0.1, damping=(0.002, 0.02), seed=1))]
pub fn simulate_random_modal<'py>(
    py: Python<'py>,
    ny: usize,
    nu: usize,
    modes: usize,
    lines: usize,
    band: (f64, f64),
    noise: f64,
    rigid_body: bool,
    close_pairs: f64,
    damping: (f64, f64),
    seed: u64,
) -> PyResult<(FrfData, FrfData, Bound<'py, PyAny>)> {
    let cfg = experiment::synth::RandomModalConfig {
        ny,
        nu,
        modes,
        lines,
        band_hz: band,
        zeta: damping,
        close_pair_fraction: close_pairs,
        rigid_body,
        noise,
        seed,
        ..Default::default()
    };
    let r = py
        .detach(|| experiment::synth::RandomModal::generate(&cfg))
        .map_err(data_err)?;
    let truth = crate::model::to_python(py, &r.plant.to_truth(seed, 0.0, 0.0))?;
    Ok((
        FrfData { inner: r.measured },
        FrfData { inner: r.noiseless },
        truth,
    ))
}
