//! Helpers shared by the subcommands: loading data with clear errors, parsing
//! `--band LO:HI`, selecting a band, formatting numbers.

use frf_data::{Frf, FrfDataset, FrfView};
use frfit::FrfitError;
use std::path::Path;

/// Reads an FRF file (CSV by default, UFF 58 for `.uff`/`.unv`); a missing file gives an
/// error that names the path.
pub fn load_data(path: &Path) -> Result<Frf, FrfitError> {
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

/// A frequency band `LO:HI` in Hz; either side may be left empty (`20:` is from 20 Hz
/// up, `:500` up to 500 Hz).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// Lower edge, Hz (`None`: the first line).
    pub lo_hz: Option<f64>,
    /// Upper edge, Hz (`None`: the last line).
    pub hi_hz: Option<f64>,
}

/// Parses `LO:HI` (Hz) for clap (`value_parser = parse_band`).
pub fn parse_band(s: &str) -> Result<Band, String> {
    let Some((a, b)) = s.split_once(':') else {
        return Err(format!(
            "expected LO:HI in Hz (e.g. 20:2000, 20: or :500), got `{s}`"
        ));
    };
    let side = |t: &str, which: &str| -> Result<Option<f64>, String> {
        let t = t.trim();
        if t.is_empty() {
            return Ok(None);
        }
        let v: f64 = t
            .parse()
            .map_err(|_| format!("{which} edge `{t}` of band `{s}` is not a number"))?;
        if !v.is_finite() || v < 0.0 {
            return Err(format!(
                "{which} edge {v} of band `{s}` must be finite and >= 0 Hz"
            ));
        }
        Ok(Some(v))
    };
    let lo = side(a, "lower")?;
    let hi = side(b, "upper")?;
    if let (Some(l), Some(h)) = (lo, hi) {
        if l >= h {
            return Err(format!("band `{s}`: LO must be below HI"));
        }
    }
    Ok(Band {
        lo_hz: lo,
        hi_hz: hi,
    })
}

/// The lines of `data` inside `band` (all lines for `None`). A band that holds no line of
/// the data is an error naming both the requested band and the range of the data.
pub fn select_band<'a>(data: &'a Frf, band: Option<Band>) -> Result<FrfView<'a>, FrfitError> {
    let view = data.view();
    let n = data.n_lines();
    if n == 0 {
        return Err(FrfitError::argument(
            "data",
            data.source.as_deref().unwrap_or("<data>"),
            "the file holds no frequency lines",
        ));
    }
    let Some(b) = band else { return Ok(view) };
    let (f0, f1) = (data.freq_hz(0), data.freq_hz(n - 1));
    let lo = b.lo_hz.unwrap_or(f0.min(0.0));
    let hi = b.hi_hz.unwrap_or(f64::MAX);
    view.band(lo, hi).map_err(|_| {
        FrfitError::argument(
            "--band",
            format!("{}:{}", fmt_edge(b.lo_hz), fmt_edge(b.hi_hz)),
            format!(
                "the band holds no frequency line of the data, which span {} .. {} Hz",
                fmt_num(f0),
                fmt_num(f1)
            ),
        )
    })
}

fn fmt_edge(v: Option<f64>) -> String {
    v.map(fmt_num).unwrap_or_default()
}

/// A number with 6 significant digits, without trailing zeros.
pub fn fmt_num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-3..1e6).contains(&a) {
        let digits = (5 - a.log10().floor() as i32).clamp(0, 9) as usize;
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        let s = format!("{v:.4e}");
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
}

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
    fn band_parsing() {
        assert_eq!(
            parse_band("20:2000").unwrap(),
            Band {
                lo_hz: Some(20.0),
                hi_hz: Some(2000.0)
            }
        );
        assert_eq!(parse_band("20:").unwrap().hi_hz, None);
        assert_eq!(parse_band(":5").unwrap().lo_hz, None);
        assert!(parse_band("20").is_err());
        assert!(parse_band("30:20").is_err());
        assert!(parse_band("a:20").unwrap_err().contains("not a number"));
        assert!(parse_band("-1:20").is_err());
    }

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
