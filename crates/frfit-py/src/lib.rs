//! `frfit._frfit`: the PyO3 extension behind the Python package `frfit`.
//!
//! A thin layer over the `frfit` facade: every function here converts NumPy arrays and
//! Python values into the library's types, runs the same code as the `frfit` command
//! line (the option words are parsed by [`frfit::options`], the nonparametric estimate by
//! [`frfit::nonparametric`], the validation by [`frfit::validation_report`]), releases
//! the GIL while it computes, and converts the result back. Errors become
//! `frfit.FrfitError` with the command line's message (file, line, column, option).
//!
//! Arrays: an FRF `G` is shaped `(n_lines, ny, nu)` (complex), its variances alike
//! (real); time records are shaped `(n_samples, channels[, experiments[, periods]])`.

mod arrays;
mod data;
mod model;
mod run;

use pyo3::prelude::*;

/// The allocator of the `frfit` binary: a fit allocates and frees large matrices per
/// iteration, which mimalloc keeps for the next allocation instead of returning them to
/// the kernel (see `crates/frfit/src/main.rs`).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

pyo3::create_exception!(
    _frfit,
    FrfitError,
    pyo3::exceptions::PyValueError,
    "An error of frfit: bad data, a bad option, a file that cannot be read, or a fit that failed. The message names what is wrong and where (file, line, column, option)."
);

/// Converts a library error into `frfit.FrfitError` with the same message as the CLI.
pub(crate) fn to_py(e: frfit::FrfitError) -> PyErr {
    FrfitError::new_err(e.to_string())
}

/// Converts a data-layer error into `frfit.FrfitError`.
pub(crate) fn data_err(e: frf_data::FrfError) -> PyErr {
    to_py(frfit::FrfitError::from(e))
}

/// An argument error (`invalid NAME `VALUE`: WHY`), as the CLI prints it.
pub(crate) fn arg_err(name: &str, value: impl ToString, why: impl Into<String>) -> PyErr {
    to_py(frfit::FrfitError::argument(name, value, why))
}

#[pymodule]
fn _frfit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // faer's own threads are slower than one on small machines (STACK.md); frfit
    // parallelises over entries with rayon instead, as the binary does
    faer::set_global_parallelism(faer::Par::Seq);
    m.add("FrfitError", m.py().get_type::<FrfitError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<data::FrfData>()?;
    m.add_class::<model::Model>()?;
    m.add_class::<model::Mode>()?;
    m.add_class::<model::StateSpace>()?;
    m.add_class::<run::Diagnosis>()?;
    m.add_class::<run::Step>()?;
    m.add_class::<run::ErrorStats>()?;
    m.add_class::<run::Validation>()?;
    m.add_class::<run::Reduction>()?;
    m.add_class::<run::Prediction>()?;
    m.add_function(wrap_pyfunction!(data::read, m)?)?;
    m.add_function(wrap_pyfunction!(data::nonparametric, m)?)?;
    m.add_function(wrap_pyfunction!(data::simulate_random_modal, m)?)?;
    m.add_function(wrap_pyfunction!(model::load_model, m)?)?;
    m.add_function(wrap_pyfunction!(run::fit, m)?)?;
    m.add_function(wrap_pyfunction!(run::diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(run::validate, m)?)?;
    m.add_function(wrap_pyfunction!(run::reduce, m)?)?;
    m.add_function(wrap_pyfunction!(run::predict, m)?)?;
    Ok(())
}
