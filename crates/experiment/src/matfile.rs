//! Reading numeric time records from MATLAB `.mat` (level 5 / v7, compressed or not)
//! files, as `FORMATS.md` describes them: numeric vectors and matrices among other
//! variables (structs, cells, strings, MCOS objects such as `tf`) that are skipped.
//!
//! The parsing is done by [`frf_data::io::mat5`] (a reader of the level-5 subset written for
//! this project, which returns errors instead of panicking on damaged files): MCOS
//! objects (for example the `tf` object in `fditools_motorbench_msA.mat`) and other
//! non-numeric variables are listed as skipped, and doubles stored in a compact integer
//! type are read.

use frf_data::{FormatProblem, FrfError};
use std::collections::BTreeMap;
use std::path::Path;

/// A real or complex numeric array (column-major, converted to `f64`).
#[derive(Debug, Clone, PartialEq)]
pub struct MatArray {
    /// Variable name.
    pub name: String,
    /// Dimensions (at least two).
    pub dims: Vec<usize>,
    /// Real part, column-major.
    pub real: Vec<f64>,
    /// Imaginary part, when the array is complex.
    pub imag: Option<Vec<f64>>,
}

impl MatArray {
    /// Rows (first dimension).
    pub fn nrows(&self) -> usize {
        self.dims.first().copied().unwrap_or(0)
    }
    /// Columns (product of the other dimensions).
    pub fn ncols(&self) -> usize {
        self.dims.iter().skip(1).product()
    }
    /// True for a row or column vector.
    pub fn is_vector(&self) -> bool {
        self.dims.iter().filter(|&&d| d != 1).count() <= 1
    }
}

/// The numeric variables of a `.mat` file and the names of those skipped.
#[derive(Debug, Clone, PartialEq)]
pub struct MatFile {
    path: String,
    arrays: BTreeMap<String, MatArray>,
    /// Variables that are not numeric arrays, with their kind (`struct`, `cell`,
    /// `char`, `object`, `sparse`, `logical`).
    pub skipped: Vec<(String, String)>,
}

impl MatFile {
    /// Reads `path`. Errors name the file; a file that is not a level-5 MAT-file (or is
    /// a v7.3 HDF5 one) is a [`FormatProblem::BadRecord`].
    pub fn read(path: impl AsRef<Path>) -> Result<Self, FrfError> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|e| FrfError::Io {
            file: name.clone(),
            message: e.to_string(),
        })?;
        Self::from_bytes(&bytes, &name)
    }

    /// Parses the bytes of a `.mat` file; `name` is used in errors.
    pub fn from_bytes(bytes: &[u8], name: &str) -> Result<Self, FrfError> {
        // Our own level-5 reader: it returns an error, never panics, on any input.
        let vars = frf_data::io::mat5::parse_mat5(bytes, name)?;
        let mut arrays = BTreeMap::new();
        let mut skipped = Vec::new();
        for v in vars {
            use frf_data::io::mat5::MatValue;
            if v.name.is_empty() {
                // the subsystem data of MCOS objects: no user variable
                continue;
            }
            match v.value {
                MatValue::Numeric { dims, real, imag } => {
                    arrays.insert(
                        v.name.clone(),
                        MatArray {
                            name: v.name,
                            dims,
                            real,
                            imag,
                        },
                    );
                }
                MatValue::Other(kind) => skipped.push((v.name, kind.to_string())),
            }
        }
        Ok(Self {
            path: name.to_string(),
            arrays,
            skipped,
        })
    }

    /// The path (or name) the file was read from.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Names of the numeric variables.
    pub fn names(&self) -> Vec<&str> {
        self.arrays.keys().map(String::as_str).collect()
    }

    /// The numeric variable `name`.
    pub fn array(&self, name: &str) -> Result<&MatArray, FrfError> {
        self.arrays.get(name).ok_or_else(|| {
            let why = match self.skipped.iter().find(|(n, _)| n == name) {
                Some((_, kind)) => format!("variable `{name}` is a {kind}, not a numeric array"),
                None => format!(
                    "no variable `{name}`; numeric variables: {}",
                    self.names().join(", ")
                ),
            };
            FrfError::format(&self.path, 0, Some(name), FormatProblem::NotFound, why)
        })
    }

    /// A real signal: `name` (a vector) or `name:c` (1-based column `c` of a matrix).
    pub fn signal(&self, spec: &str) -> Result<Vec<f64>, FrfError> {
        let (name, col) = match spec.rsplit_once(':') {
            Some((n, c)) => {
                let c: usize = c.trim().parse().map_err(|_| {
                    FrfError::invalid(
                        "signal",
                        spec,
                        "expected NAME or NAME:COLUMN with a 1-based column number",
                    )
                })?;
                (n.trim(), Some(c))
            }
            None => (spec.trim(), None),
        };
        let a = self.array(name)?;
        if a.imag.is_some() {
            return Err(FrfError::format(
                &self.path,
                0,
                Some(name),
                FormatProblem::BadRecord,
                format!("variable `{name}` is complex; a time record must be real"),
            ));
        }
        match col {
            None if a.is_vector() => Ok(a.real.clone()),
            None => Err(FrfError::format(
                &self.path,
                0,
                Some(name),
                FormatProblem::BadRecord,
                format!(
                    "variable `{name}` is a {:?} matrix; name a column as `{name}:COLUMN`",
                    a.dims
                ),
            )),
            Some(c) => {
                let (nr, nc) = (a.nrows(), a.ncols());
                if c == 0 || c > nc {
                    return Err(FrfError::format(
                        &self.path,
                        0,
                        Some(name),
                        FormatProblem::NotFound,
                        format!("column {c} of `{name}` does not exist (it has {nc} columns)"),
                    ));
                }
                Ok(a.real[(c - 1) * nr..c * nr].to_vec())
            }
        }
    }

    /// A numeric scalar (for example `fs`), when the file holds one of that name.
    pub fn scalar(&self, name: &str) -> Option<f64> {
        self.arrays
            .get(name)
            .filter(|a| a.real.len() == 1)
            .map(|a| a.real[0])
    }
}
