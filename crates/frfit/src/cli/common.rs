//! Helpers shared by the subcommands: loading data with clear errors, parsing
//! `--band LO:HI`, selecting a band, formatting numbers.

use frf_data::Frf;
use frfit::FrfitError;
use std::path::Path;

/// Reads an FRF file ([`frfit::data::read`]).
pub fn load_data(path: &Path) -> Result<Frf, FrfitError> {
    frfit::data::read(path)
}

pub use frfit::options::{fmt_num, parse_band, select_band, Band};

/// The `q`-quantile (0..1) of `v` by linear interpolation; `None` for no values.
pub fn quantile(v: &mut [f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let i = pos.floor() as usize;
    let j = (i + 1).min(v.len() - 1);
    let t = pos - i as f64;
    Some(v[i] * (1.0 - t) + v[j] * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_numbers() {
        let mut v = vec![3.0, 1.0, 2.0, 4.0, 5.0];
        assert_eq!(quantile(&mut v, 0.5), Some(3.0));
        assert_eq!(quantile(&mut v, 1.0), Some(5.0));
        assert_eq!(quantile(&mut [], 0.5), None);
        assert_eq!(fmt_num(0.25), "0.25");
        assert_eq!(fmt_num(1999.75), "1999.75");
        assert_eq!(fmt_num(1.5e-7), "1.5e-7");
        assert_eq!(fmt_num(2.31204e-4), "2.312e-4");
    }
}
