//! Reading measured data for every front end (the CLI and the Python package): an FRF
//! file with errors that name the path.

use crate::FrfitError;
use frf_data::Frf;
use std::path::Path;

/// Reads an FRF file (FRF CSV, UFF 58 `.uff`/`.unv`, MATLAB `.mat`, by extension); a
/// missing file or a directory gives an error that names the path.
pub fn read(path: &Path) -> Result<Frf, FrfitError> {
    if !path.exists() {
        return Err(FrfitError::Io {
            path: path.display().to_string(),
            message: "no such file".into(),
        });
    }
    if path.is_dir() {
        return Err(FrfitError::Io {
            path: path.display().to_string(),
            message: "is a directory, expected an FRF file".into(),
        });
    }
    Ok(frf_data::io::read_frf(path)?)
}
