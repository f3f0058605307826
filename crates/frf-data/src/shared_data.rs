//! Locating the reference data `../shared/data` that tests and examples may read.
//!
//! CI checks the repository out with `../shared` beside it; a user's fresh clone has no
//! `../shared`. Tests that read it call [`shared_data_dir`] and, when it returns `None`,
//! print why they are skipped (see [`skip_message`]) and pass: the project's own
//! simulator covers the same properties without files.

use crate::FrfDataset;
use std::path::{Path, PathBuf};

/// The environment variable that overrides the location of the shared data directory.
pub const ENV_VAR: &str = "FRFIT_SHARED_DATA";

/// The directory holding `wafer_nominal.csv` etc.: `$FRFIT_SHARED_DATA` when set,
/// otherwise the first `shared/data` found beside the workspace root or one of its
/// parents (`<root>/../shared/data`).
pub fn shared_data_dir() -> Option<PathBuf> {
    if let Ok(p) = std::env::var(ENV_VAR) {
        let p = PathBuf::from(p);
        return p.is_dir().then_some(p);
    }
    // CARGO_MANIFEST_DIR of this crate is <root>/crates/frf-data.
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    for anc in here.ancestors() {
        let cand = anc.join("shared").join("data");
        if cand.join("wafer_nominal.csv").is_file() {
            return Some(cand);
        }
    }
    None
}

/// A file in the shared data directory, when the directory and the file exist.
pub fn shared_file(name: &str) -> Option<PathBuf> {
    shared_data_dir()
        .map(|d| d.join(name))
        .filter(|p| p.is_file())
}

/// The message a test prints when it skips for lack of `name`.
pub fn skip_message(test: &str, name: &str) -> String {
    format!(
        "SKIPPED {test}: reference file `{name}` not found (looked in ${ENV_VAR} and \
         ../shared/data beside the workspace; a fresh clone has no ../shared, CI has it)"
    )
}

/// Looks up `name` in the shared data; prints the skip message and returns `None` when
/// it is not there. Tests use it as
/// `let Some(path) = frf_data::shared_data::require("my_test", "wafer_nominal.csv") else { return };`
pub fn require(test: &str, name: &str) -> Option<PathBuf> {
    let p = shared_file(name);
    if p.is_none() {
        eprintln!("{}", skip_message(test, name));
        println!("{}", skip_message(test, name));
    }
    p
}

/// The reference file `name` read and cut to `band_hz` (Hz), for the benches and tests
/// that time or check a fit on it; prints why `who` is skipped and returns `None` when
/// the file is not there, cannot be read, or holds no lines in the band.
pub fn require_band(who: &str, name: &str, band_hz: (f64, f64)) -> Option<crate::Frf> {
    let path = require(who, name)?;
    let data = match crate::io::read_frf(&path) {
        Ok(d) => d,
        Err(e) => {
            println!("SKIPPED {who}: cannot read {}: {e}", path.display());
            return None;
        }
    };
    match data.band(band_hz.0, band_hz.1) {
        Ok(v) => Some(v.to_frf()),
        Err(e) => {
            println!("SKIPPED {who}: band {band_hz:?} Hz of {name}: {e}");
            None
        }
    }
}
