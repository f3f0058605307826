//! NumPy arrays to and from the library's layouts.
//!
//! The library stores an FRF line after line, each line column-major (`vec(G)`: entry
//! `(i, j)` of line `k` at `k * ny * nu + j * ny + i`); NumPy users hold `G[k, i, j]` in
//! a C-ordered `(n, ny, nu)` array. Inputs are first made C-contiguous with the dtype
//! the library needs (`numpy.ascontiguousarray`), so lists, real arrays and strided
//! views are all accepted.

use crate::arg_err;
use frf_data::C64;
use numpy::{Element, PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// `numpy.ascontiguousarray(obj, dtype=dtype)`.
pub fn contiguous<'py>(
    py: Python<'py>,
    obj: &Bound<'py, PyAny>,
    dtype: &str,
    name: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let np = py.import("numpy")?;
    let kw = PyDict::new(py);
    kw.set_item("dtype", dtype)?;
    np.call_method("ascontiguousarray", (obj,), Some(&kw))
        .map_err(|e| {
            arg_err(
                name,
                "<array>",
                format!("cannot be read as a {dtype} array: {e}"),
            )
        })
}

/// A C-contiguous array of `T` with its shape.
pub struct Dense<T> {
    /// The shape.
    pub shape: Vec<usize>,
    /// The values in C order.
    pub values: Vec<T>,
}

/// Reads `obj` as a C-contiguous array of `T` (`dtype`: its NumPy name).
fn dense<T: Element + Copy>(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    dtype: &str,
    name: &str,
) -> PyResult<Dense<T>> {
    let a = contiguous(py, obj, dtype, name)?;
    let r: PyReadonlyArrayDyn<'_, T> = a.extract()?;
    let shape = r.shape().to_vec();
    let values = r
        .as_slice()
        .map_err(|e| arg_err(name, "<array>", e.to_string()))?
        .to_vec();
    Ok(Dense { shape, values })
}

/// Reads `obj` as a C-contiguous complex array (`C64` is NumPy's `complex128`).
pub fn complex_array(py: Python<'_>, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Dense<C64>> {
    dense(py, obj, "complex128", name)
}

/// Reads `obj` as a C-contiguous real array.
pub fn real_array(py: Python<'_>, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Dense<f64>> {
    dense(py, obj, "float64", name)
}

/// The `(n, ny, nu)` shape of an FRF array: 3-D as it is, 1-D as `(n, 1, 1)` (a SISO
/// FRF); anything else is an error naming the argument.
pub fn frf_shape(shape: &[usize], name: &str) -> PyResult<(usize, usize, usize)> {
    match *shape {
        [n] => Ok((n, 1, 1)),
        [n, ny, nu] => Ok((n, ny, nu)),
        _ => Err(arg_err(
            name,
            format!("shape {shape:?}"),
            "expected (n_lines, ny, nu), or (n_lines,) for a single entry",
        )),
    }
}

/// C order `(n, ny, nu)` to the library's layout (line after line, column-major).
pub fn to_line_major<T: Copy>(c: &[T], n: usize, ny: usize, nu: usize) -> Vec<T> {
    let m = ny * nu;
    let mut out = Vec::with_capacity(c.len());
    for k in 0..n {
        let line = &c[k * m..(k + 1) * m];
        for j in 0..nu {
            for i in 0..ny {
                out.push(line[i * nu + j]);
            }
        }
    }
    out
}

/// The library's layout to C order `(n, ny, nu)`.
pub fn to_c_order<T: Copy>(v: &[T], n: usize, ny: usize, nu: usize) -> Vec<T> {
    let m = ny * nu;
    let mut out = Vec::with_capacity(v.len());
    for k in 0..n {
        let line = &v[k * m..(k + 1) * m];
        for i in 0..ny {
            for j in 0..nu {
                out.push(line[j * ny + i]);
            }
        }
    }
    out
}

/// An `(n, ny, nu)` array (complex or real) from values in the library's layout.
pub fn array_3d<'py, T: Element + Copy>(
    py: Python<'py>,
    v: &[T],
    n: usize,
    ny: usize,
    nu: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let c = to_c_order(v, n, ny, nu);
    Ok(PyArray1::from_vec(py, c).reshape([n, ny, nu])?.into_any())
}

/// A real 2-D array from rows.
pub fn real_2d<'py>(
    py: Python<'py>,
    rows: &[Vec<f64>],
    ncols: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([rows.len(), ncols])?
        .into_any())
}

/// A real 1-D array.
pub fn real_1d<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}
