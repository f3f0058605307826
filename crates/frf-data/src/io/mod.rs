//! File formats: the FRF CSV of `FORMATS.md` (read in every spreadsheet dialect, and
//! written), UFF dataset 58 (ASCII and binary 58b, read and written) and FRFs in MATLAB
//! `.mat` files (read and written).
//!
//! - [`read_frf_csv`] / [`parse_frf_csv`]: FRF CSV from a file / from text, in the
//!   dialect [`dialect::normalize`] detects (BOM, CRLF, quotes, `;` and `,` decimals);
//! - [`write_frf_csv`] / [`frf_csv_string`]: any [`FrfDataset`] to FRF CSV, bit-exact on
//!   reading back;
//! - [`read_uff58`] / [`parse_uff58`] / [`parse_uff58_bytes`]: the FRF records
//!   (function type 4) of a Universal File, ASCII or binary, assembled into one `ny x nu`
//!   [`Frf`]; [`uff58_bytes`] writes one;
//! - [`read_frf_mat`] / [`parse_frf_mat`] / [`frf_mat_bytes`]: `G` and `freq_hz` in a
//!   level-5 `.mat` file, through the own reader [`mat5`];
//! - [`read_frf`]: any of them, by the file's extension.
//!
//! Readers never panic on bad input: they return [`FrfError::Format`] naming the file,
//! the line and the column (the variable or byte offset in binary files), with a
//! [`crate::FormatProblem`] that tells what is wrong.

mod csv;
pub mod dialect;
pub mod mat5;
mod mat_frf;
pub mod npy;
mod uff;
mod uff_binary;
mod uff_write;

pub use csv::{frf_csv_string, parse_frf_csv};
pub use mat_frf::{frf_mat_bytes, parse_frf_mat, FREQ_NAMES, FRF_NAMES};
pub use uff::{parse_uff58, parse_uff58_bytes};
pub use uff_write::{uff58_bytes, UffEncoding};

use crate::{Frf, FrfDataset, FrfError};
use std::path::Path;

/// The text of a file (invalid UTF-8 is replaced, so that the parsers report it where it
/// matters instead of failing on a comment); [`FrfError::Io`] when it cannot be read.
fn read_text(path: &Path) -> Result<String, FrfError> {
    let bytes = std::fs::read(path).map_err(|e| FrfError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })?;
    Ok(match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    })
}

/// Reads an FRF CSV file (see [`parse_frf_csv`] for the format and the errors);
/// [`Frf::source`] is the path.
pub fn read_frf_csv(path: impl AsRef<Path>) -> Result<Frf, FrfError> {
    let path = path.as_ref();
    let text = read_text(path)?;
    parse_frf_csv(&text, &path.display().to_string())
}

/// Writes `data` as an FRF CSV file (see [`frf_csv_string`] for the layout);
/// [`FrfError::Io`] when the file cannot be written.
pub fn write_frf_csv<D: FrfDataset + ?Sized>(
    path: impl AsRef<Path>,
    data: &D,
    comments: &[String],
) -> Result<(), FrfError> {
    let path = path.as_ref();
    std::fs::write(path, frf_csv_string(data, comments)).map_err(|e| FrfError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })
}

/// Reads the FRF records of an ASCII UFF file (dataset 58, function type 4) into one
/// [`Frf`] (see [`parse_uff58`] for the layout, the row/column order and the errors);
/// [`Frf::source`] is the path.
pub fn read_uff58(path: impl AsRef<Path>) -> Result<Frf, FrfError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| FrfError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })?;
    parse_uff58_bytes(&bytes, &path.display().to_string())
}

/// Reads an FRF from a MATLAB `.mat` file (`G`, `freq_hz`: see [`parse_frf_mat`]);
/// [`Frf::source`] is the path.
pub fn read_frf_mat(path: impl AsRef<Path>) -> Result<Frf, FrfError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| FrfError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })?;
    parse_frf_mat(&bytes, &path.display().to_string())
}

/// Reads an FRF file by its extension (case-insensitive): `.csv` as FRF CSV
/// ([`read_frf_csv`]), `.uff` and `.unv` as UFF 58 ([`read_uff58`]), `.mat` as MATLAB
/// ([`read_frf_mat`]). Any other extension gives [`FrfError::InvalidParameter`] naming
/// the path.
pub fn read_frf(path: impl AsRef<Path>) -> Result<Frf, FrfError> {
    let path = path.as_ref();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("csv") => read_frf_csv(path),
        Some("uff" | "unv") => read_uff58(path),
        Some("mat") => read_frf_mat(path),
        _ => Err(FrfError::invalid(
            "FRF file",
            path.display(),
            "the extension must be .csv (FRF CSV), .uff/.unv (UFF dataset 58) or .mat \
             (MATLAB); call read_frf_csv, read_uff58 or read_frf_mat directly for other names",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FormatProblem;

    #[test]
    fn read_frf_rejects_unknown_extensions() {
        for p in ["data.txt", "data", "data.csv.gz"] {
            let e = read_frf(p).unwrap_err();
            assert!(
                matches!(&e, FrfError::InvalidParameter { value, .. } if value == p),
                "{e:?}"
            );
        }
    }

    #[test]
    fn missing_files_give_io_errors() {
        for p in [
            "/nonexistent/x.csv",
            "/nonexistent/x.UFF",
            "/nonexistent/x.unv",
        ] {
            let e = read_frf(p).unwrap_err();
            assert!(
                matches!(&e, FrfError::Io { file, .. } if file == p),
                "{e:?}"
            );
        }
    }

    #[test]
    fn read_frf_dispatches_on_extension() {
        let dir = std::env::temp_dir().join(format!("frf-io-dispatch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = Frf::from_fn(vec![1.0, 2.0], 1, 1, |k, _, _| {
            crate::C64::new(k as f64, 1.0)
        })
        .unwrap();
        let csv = dir.join("a.CSV");
        write_frf_csv(&csv, &f, &[]).unwrap();
        let back = read_frf(&csv).unwrap();
        assert_eq!(back.values(), f.values());
        assert_eq!(
            back.source.as_deref(),
            Some(csv.display().to_string().as_str())
        );
        // The same CSV text named .uff goes to the UFF reader, which rejects it.
        let uff = dir.join("a.uff");
        std::fs::copy(&csv, &uff).unwrap();
        let e = read_frf(&uff).unwrap_err();
        assert_eq!(e.problem(), Some(FormatProblem::BadRecord), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
