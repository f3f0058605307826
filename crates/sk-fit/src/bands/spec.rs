//! The band specification of the multi-band fit (`--bands auto|1|F1,F2,...`) and the
//! assignment of the data's lines to the bands.

use crate::SkError;
use std::fmt;
use std::str::FromStr;

/// How the frequency range is divided into bands (Jue, section 2.3.1).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum BandSpec {
    /// Cut-offs chosen from the CMIF of the data (see [`crate::bands::AutoBands`]); the
    /// default.
    #[default]
    Auto,
    /// One band: the plain SK fit through the same machinery (`--bands 1`).
    Single,
    /// Cut-off frequencies in Hz, strictly increasing and positive: `n` cut-offs make
    /// `n + 1` bands; band `b` holds the lines with `cut[b-1] <= f < cut[b]`.
    Cuts(Vec<f64>),
}

impl BandSpec {
    /// Parses `auto`, `1` (one band) or a comma-separated list of cut-off frequencies
    /// in Hz (`4.6,37`). A single cut-off at 1 Hz is written `1.0`.
    ///
    /// Fails, naming the item, on an empty item, a value that is not a number, a value
    /// that is not finite and positive, and cut-offs that do not increase strictly.
    pub fn parse(s: &str) -> Result<Self, SkError> {
        let t = s.trim();
        let bad = |why: String| SkError::config("bands", s, why);
        if t.eq_ignore_ascii_case("auto") {
            return Ok(BandSpec::Auto);
        }
        if t == "1" {
            return Ok(BandSpec::Single);
        }
        if t.is_empty() {
            return Err(bad(
                "expected `auto`, `1` (one band) or cut-off frequencies in Hz such as `4.6,37`"
                    .into(),
            ));
        }
        let mut cuts = Vec::new();
        for (i, item) in t.split(',').enumerate() {
            let item = item.trim();
            if item.is_empty() {
                return Err(bad(format!("cut-off {} is empty", i + 1)));
            }
            let v: f64 = item.parse().map_err(|_| {
                bad(format!(
                    "cut-off {} (`{item}`) is not a number (expected `auto`, `1` or \
                     frequencies in Hz such as `4.6,37`)",
                    i + 1
                ))
            })?;
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!(
                    "cut-off {} ({item}) must be a finite frequency > 0 Hz",
                    i + 1
                )));
            }
            if let Some(&prev) = cuts.last() {
                if v <= prev {
                    return Err(bad(format!(
                        "cut-offs must increase strictly: cut-off {} ({v} Hz) is not above \
                         cut-off {} ({prev} Hz)",
                        i + 1,
                        i
                    )));
                }
            }
            cuts.push(v);
        }
        Ok(BandSpec::Cuts(cuts))
    }
}

impl FromStr for BandSpec {
    type Err = SkError;
    fn from_str(s: &str) -> Result<Self, SkError> {
        Self::parse(s)
    }
}

impl fmt::Display for BandSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BandSpec::Auto => write!(f, "auto"),
            BandSpec::Single => write!(f, "1"),
            BandSpec::Cuts(c) => {
                let s: Vec<String> = c.iter().map(|v| v.to_string()).collect();
                write!(f, "{}", s.join(","))
            }
        }
    }
}

/// The lines of each band: `ranges[b]` is the index range of band `b` in the data's
/// line order (lines sorted by frequency).
///
/// Fails when a band holds fewer than `min_lines` lines (a band that holds no lines
/// names its range and the range of the data).
pub(crate) fn assign_lines(
    freq_hz: &[f64],
    cuts: &[f64],
    min_lines: usize,
) -> Result<Vec<std::ops::Range<usize>>, SkError> {
    if freq_hz.windows(2).any(|w| w[1] <= w[0]) {
        return Err(SkError::config(
            "bands",
            format!("{} lines", freq_hz.len()),
            "the multi-band fit needs the lines sorted by increasing frequency",
        ));
    }
    let (f_lo, f_hi) = (
        freq_hz.first().copied().unwrap_or(f64::NAN),
        freq_hz.last().copied().unwrap_or(f64::NAN),
    );
    let spec = BandSpec::Cuts(cuts.to_vec()).to_string();
    let mut ranges = Vec::with_capacity(cuts.len() + 1);
    let mut start = 0;
    for b in 0..=cuts.len() {
        let end = match cuts.get(b) {
            Some(&c) => freq_hz.partition_point(|&f| f < c),
            None => freq_hz.len(),
        };
        let lo = if b == 0 { 0.0 } else { cuts[b - 1] };
        let hi = cuts.get(b).copied().unwrap_or(f64::INFINITY);
        let n = end - start;
        if n < min_lines.max(1) {
            let what = if n == 0 {
                "holds no lines".to_string()
            } else {
                format!("holds only {n} line(s); at least {min_lines} are needed")
            };
            return Err(SkError::config(
                "bands",
                spec,
                format!(
                    "band {} ({lo} .. {hi} Hz) {what} (the data span {f_lo} .. {f_hi} Hz in \
                     {} lines)",
                    b + 1,
                    freq_hz.len()
                ),
            ));
        }
        ranges.push(start..end);
        start = end;
    }
    Ok(ranges)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_auto_one_and_cut_offs() {
        assert_eq!(BandSpec::parse("auto").unwrap(), BandSpec::Auto);
        assert_eq!(BandSpec::parse(" AUTO ").unwrap(), BandSpec::Auto);
        assert_eq!(BandSpec::parse("1").unwrap(), BandSpec::Single);
        assert_eq!(
            BandSpec::parse("4.6,37").unwrap(),
            BandSpec::Cuts(vec![4.6, 37.0])
        );
        assert_eq!(BandSpec::parse("1.0").unwrap(), BandSpec::Cuts(vec![1.0]));
        assert_eq!(
            BandSpec::parse(" 2 , 30 ,100").unwrap(),
            BandSpec::Cuts(vec![2.0, 30.0, 100.0])
        );
        assert_eq!("4.6,37".parse::<BandSpec>().unwrap().to_string(), "4.6,37");
    }

    #[test]
    fn bad_cut_offs_are_named() {
        let e = |s: &str| BandSpec::parse(s).unwrap_err().to_string();
        assert!(e("").contains("expected `auto`"), "{}", e(""));
        let m = e("4.6,,37");
        assert!(m.contains("cut-off 2 is empty"), "{m}");
        let m = e("4.6,abc");
        assert!(m.contains("cut-off 2 (`abc`) is not a number"), "{m}");
        let m = e("-3");
        assert!(
            m.contains("cut-off 1 (-3) must be a finite frequency > 0"),
            "{m}"
        );
        let m = e("0,5");
        assert!(m.contains("cut-off 1"), "{m}");
        let m = e("10,inf");
        assert!(m.contains("cut-off 2"), "{m}");
        let m = e("37,4.6");
        assert!(
            m.contains("increase strictly") && m.contains("cut-off 2 (4.6 Hz)"),
            "{m}"
        );
        let m = e("5,5");
        assert!(m.contains("increase strictly"), "{m}");
        assert!(m.starts_with("invalid setting bands = 5,5"), "{m}");
    }

    #[test]
    fn lines_are_assigned_and_empty_bands_named() {
        let f: Vec<f64> = (1..=100).map(|k| k as f64).collect();
        let r = assign_lines(&f, &[10.0, 50.5], 4).unwrap();
        assert_eq!(r, vec![0..9, 9..50, 50..100]);
        assert_eq!(assign_lines(&f, &[], 4).unwrap(), vec![0..100]);
        // a cut-off above the data: the last band holds no lines
        let m = assign_lines(&f, &[10.0, 200.0], 4).unwrap_err().to_string();
        assert!(
            m.contains("band 3 (200 .. inf Hz) holds no lines")
                && m.contains("the data span 1 .. 100 Hz"),
            "{m}"
        );
        // below the data: the first band is empty
        let m = assign_lines(&f, &[0.5], 4).unwrap_err().to_string();
        assert!(m.contains("band 1 (0 .. 0.5 Hz) holds no lines"), "{m}");
        // two cut-offs between the same lines
        let m = assign_lines(&f, &[10.2, 10.7], 4).unwrap_err().to_string();
        assert!(m.contains("band 2 (10.2 .. 10.7 Hz) holds no lines"), "{m}");
        // too few lines
        let m = assign_lines(&f, &[3.0], 4).unwrap_err().to_string();
        assert!(m.contains("band 1") && m.contains("only 2 line(s)"), "{m}");
    }
}
