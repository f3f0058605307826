//! The periodic spectra CSV of `FORMATS.md`: one row per (experiment, realization,
//! period, line) with the DFT of one period of each input and output at the excited
//! lines.
//!
//! ```text
//! # ny=2 nu=1 experiments=1 realizations=1 periods=19
//! freq_hz,experiment,realization,period,U1_re,U1_im,Y1_re,Y1_im,Y2_re,Y2_im
//! ```
//!
//! Columns are found by name in any order; experiment, realization and period are
//! 1-based and must be complete (every combination, every line).

use super::{PeriodicSpectra, RealizationSpectra};
use frf_data::{FormatProblem, FrfError, C64};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

fn ferr(
    file: &str,
    line: usize,
    col: Option<&str>,
    p: FormatProblem,
    d: impl Into<String>,
) -> FrfError {
    FrfError::format(file, line, col, p, d)
}

/// Reads a periodic spectra CSV file.
pub fn read_spectra_csv(path: impl AsRef<Path>) -> Result<PeriodicSpectra, FrfError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| FrfError::Io {
        file: name.clone(),
        message: e.to_string(),
    })?;
    parse_spectra_csv(&text, &name)
}

#[derive(Clone, Copy)]
enum Col {
    Freq,
    Exp,
    Real,
    Period,
    U(usize, bool),
    Y(usize, bool),
    Other,
}

fn parse_col(h: &str) -> Option<Col> {
    match h {
        "freq_hz" => return Some(Col::Freq),
        "experiment" => return Some(Col::Exp),
        "realization" => return Some(Col::Real),
        "period" => return Some(Col::Period),
        _ => {}
    }
    // the first character may be any width (a header is user text): split on chars
    let mut chars = h.chars();
    let kind = chars.next()?;
    let rest = chars.as_str();
    let (idx, part) = rest.split_once('_')?;
    let i: usize = idx.parse().ok()?;
    if i == 0 {
        return None;
    }
    let re = match part {
        "re" => true,
        "im" => false,
        _ => return None,
    };
    match kind {
        'U' => Some(Col::U(i - 1, re)),
        'Y' => Some(Col::Y(i - 1, re)),
        'R' => Some(Col::Other), // reference columns are accepted and not needed
        _ => None,
    }
}

/// Parses the text of a periodic spectra CSV; `name` is used in errors.
pub fn parse_spectra_csv(text: &str, name: &str) -> Result<PeriodicSpectra, FrfError> {
    let mut comments = Vec::new();
    let mut header: Option<(usize, Vec<Col>, Vec<String>)> = None;
    // (e, r, p, freq bits) -> (U, Y)
    type Key = (usize, usize, usize, u64);
    let mut rows: BTreeMap<Key, (Vec<C64>, Vec<C64>)> = BTreeMap::new();
    let (mut ny, mut nu) = (0usize, 0usize);
    for (ln0, raw) in text.lines().enumerate() {
        let ln = ln0 + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            comments.push(c.trim().to_string());
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let Some((_, cols, names)) = &header else {
            let mut cols = Vec::with_capacity(fields.len());
            for f in &fields {
                let c = parse_col(f).ok_or_else(|| {
                    ferr(
                        name,
                        ln,
                        Some(f),
                        FormatProblem::BadHeader,
                        format!("unknown column `{f}`"),
                    )
                })?;
                match c {
                    Col::U(j, _) => nu = nu.max(j + 1),
                    Col::Y(i, _) => ny = ny.max(i + 1),
                    _ => {}
                }
                cols.push(c);
            }
            for label in ["freq_hz", "experiment", "realization", "period"] {
                if !fields.contains(&label) {
                    return Err(ferr(
                        name,
                        ln,
                        Some(label),
                        FormatProblem::BadHeader,
                        format!("no `{label}` column"),
                    ));
                }
            }
            let mut seen = std::collections::BTreeSet::new();
            for f in &fields {
                if !seen.insert(*f) {
                    return Err(ferr(
                        name,
                        ln,
                        Some(f),
                        FormatProblem::BadHeader,
                        format!("duplicate column `{f}`"),
                    ));
                }
            }
            if nu == 0 || ny == 0 {
                return Err(ferr(
                    name,
                    ln,
                    None,
                    FormatProblem::BadHeader,
                    "needs U1_re.. and Y1_re.. columns",
                ));
            }
            for (k, n) in [('U', nu), ('Y', ny)] {
                for i in 1..=n {
                    for part in ["re", "im"] {
                        let c = format!("{k}{i}_{part}");
                        if !fields.contains(&c.as_str()) {
                            return Err(ferr(
                                name,
                                ln,
                                Some(&c),
                                FormatProblem::MissingEntry,
                                format!("column `{c}` is missing"),
                            ));
                        }
                    }
                }
            }
            header = Some((ln, cols, fields.iter().map(|s| s.to_string()).collect()));
            continue;
        };
        if fields.len() != cols.len() {
            return Err(ferr(
                name,
                ln,
                None,
                FormatProblem::FieldCount,
                format!("{} fields, the header has {}", fields.len(), cols.len()),
            ));
        }
        let (mut f, mut e, mut r, mut p) = (f64::NAN, 0usize, 0usize, 0usize);
        let mut u = vec![C64::new(0.0, 0.0); nu];
        let mut y = vec![C64::new(0.0, 0.0); ny];
        for ((c, s), cname) in cols.iter().zip(&fields).zip(names) {
            let num = || -> Result<f64, FrfError> {
                let v: f64 = s.parse().map_err(|_| {
                    ferr(
                        name,
                        ln,
                        Some(cname),
                        FormatProblem::NotANumber,
                        format!("`{s}` is not a number"),
                    )
                })?;
                if !v.is_finite() {
                    return Err(ferr(
                        name,
                        ln,
                        Some(cname),
                        FormatProblem::NonFinite,
                        format!("`{s}` is not finite"),
                    ));
                }
                Ok(v)
            };
            let index = || -> Result<usize, FrfError> {
                let v = num()?;
                if v < 1.0 || v.fract() != 0.0 || v > 1e9 {
                    return Err(ferr(
                        name,
                        ln,
                        Some(cname),
                        FormatProblem::NotANumber,
                        format!("`{s}` is not a 1-based index"),
                    ));
                }
                Ok(v as usize)
            };
            match *c {
                Col::Freq => f = num()?,
                Col::Exp => e = index()?,
                Col::Real => r = index()?,
                Col::Period => p = index()?,
                Col::U(j, re) => {
                    let v = num()?;
                    if re {
                        u[j].re = v
                    } else {
                        u[j].im = v
                    }
                }
                Col::Y(i, re) => {
                    let v = num()?;
                    if re {
                        y[i].re = v
                    } else {
                        y[i].im = v
                    }
                }
                Col::Other => {
                    num()?;
                }
            }
        }
        if f <= 0.0 {
            return Err(ferr(
                name,
                ln,
                Some("freq_hz"),
                FormatProblem::BadFrequency,
                format!("frequency {f} Hz must be > 0"),
            ));
        }
        if rows
            .insert((e - 1, r - 1, p - 1, f.to_bits()), (u, y))
            .is_some()
        {
            return Err(ferr(
                name,
                ln,
                None,
                FormatProblem::BadRecord,
                format!("experiment {e}, realization {r}, period {p} at {f} Hz appears twice"),
            ));
        }
    }
    if header.is_none() || rows.is_empty() {
        return Err(ferr(
            name,
            0,
            None,
            FormatProblem::Empty,
            "no header or no data rows",
        ));
    }
    let mut freqs: Vec<f64> = rows.keys().map(|k| f64::from_bits(k.3)).collect();
    freqs.sort_by(f64::total_cmp);
    freqs.dedup();
    let ne = rows.keys().map(|k| k.0).max().unwrap_or(0) + 1;
    let nr = rows.keys().map(|k| k.1).max().unwrap_or(0) + 1;
    let np = rows.keys().map(|k| k.2).max().unwrap_or(0) + 1;
    let nl = freqs.len();
    if rows.len() != ne * nr * np * nl {
        // find the first missing combination for the message
        for e in 0..ne {
            for r in 0..nr {
                for p in 0..np {
                    for f in &freqs {
                        if !rows.contains_key(&(e, r, p, f.to_bits())) {
                            return Err(ferr(
                                name,
                                0,
                                None,
                                FormatProblem::MissingEntry,
                                format!(
                                    "no row for experiment {}, realization {}, period {} at {f} Hz: \
                                     every combination of experiment, realization, period and line is needed",
                                    e + 1,
                                    r + 1,
                                    p + 1
                                ),
                            ));
                        }
                    }
                }
            }
        }
    }
    let mut reals = Vec::with_capacity(nr);
    for r in 0..nr {
        let mut input = Vec::with_capacity(ne * np * nl * nu);
        let mut output = Vec::with_capacity(ne * np * nl * ny);
        for e in 0..ne {
            for p in 0..np {
                for f in &freqs {
                    let (u, y) = &rows[&(e, r, p, f.to_bits())];
                    input.extend_from_slice(u);
                    output.extend_from_slice(y);
                }
            }
        }
        reals.push(RealizationSpectra::new(
            ne, np, nl, ny, nu, input, output, None,
        )?);
    }
    let mut s = PeriodicSpectra::new(freqs, ny, nu, reals)?;
    s.comments = comments;
    Ok(s)
}

/// Writes `spectra` as a periodic spectra CSV with the given comment lines.
pub fn write_spectra_csv(
    path: impl AsRef<Path>,
    spectra: &PeriodicSpectra,
    comments: &[String],
) -> Result<(), FrfError> {
    let path = path.as_ref();
    let (ny, nu) = (spectra.ny, spectra.nu);
    let ne = spectra.n_experiments();
    let np = spectra.realizations[0].periods();
    let mut s = String::new();
    for c in comments {
        let _ = writeln!(s, "# {c}");
    }
    let _ = writeln!(
        s,
        "# ny={ny} nu={nu} experiments={ne} realizations={} periods={np}",
        spectra.realizations.len()
    );
    s.push_str("freq_hz,experiment,realization,period");
    for j in 1..=nu {
        let _ = write!(s, ",U{j}_re,U{j}_im");
    }
    for i in 1..=ny {
        let _ = write!(s, ",Y{i}_re,Y{i}_im");
    }
    s.push('\n');
    for (r, rs) in spectra.realizations.iter().enumerate() {
        for e in 0..ne {
            for p in 0..rs.periods() {
                for (k, f) in spectra.freq_hz.iter().enumerate() {
                    let _ = write!(s, "{f:.10e},{},{},{}", e + 1, r + 1, p + 1);
                    for z in rs.input_at(e, p, k).iter().chain(rs.output_at(e, p, k)) {
                        let _ = write!(s, ",{:.10e},{:.10e}", z.re, z.im);
                    }
                    s.push('\n');
                }
            }
        }
    }
    std::fs::write(path, s).map_err(|e| FrfError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let text = "# ny=1 nu=1\nfreq_hz,experiment,realization,period,U1_re,U1_im,Y1_re,Y1_im\n\
                    1,1,1,1,1,0,2,0\n2,1,1,1,1,0,4,1\n1,1,1,2,1,0,2,0\n2,1,1,2,1,0,4,1\n";
        let s = parse_spectra_csv(text, "t").unwrap();
        assert_eq!(s.freq_hz, vec![1.0, 2.0]);
        assert_eq!(s.realizations[0].periods(), 2);
        assert_eq!(s.realizations[0].output_at(0, 1, 1)[0], C64::new(4.0, 1.0));
        let missing = "freq_hz,experiment,realization,period,U1_re,U1_im,Y1_re,Y1_im\n\
                       1,1,1,1,1,0,2,0\n2,1,1,2,1,0,4,1\n";
        assert_eq!(
            parse_spectra_csv(missing, "t").unwrap_err().problem(),
            Some(FormatProblem::MissingEntry)
        );
        let bad =
            "freq_hz,experiment,realization,period,U1_re,U1_im,Y1_re,Y1_im\n1,1,1,1,x,0,2,0\n";
        let e = parse_spectra_csv(bad, "t").unwrap_err();
        assert_eq!(e.problem(), Some(FormatProblem::NotANumber));
        assert!(e.to_string().contains("t:2: column U1_re"), "{e}");
        let nocol = "freq_hz,experiment,realization,period,U1_re,Y1_re,Y1_im\n";
        assert_eq!(
            parse_spectra_csv(nocol, "t").unwrap_err().problem(),
            Some(FormatProblem::MissingEntry)
        );
        assert_eq!(
            parse_spectra_csv("# only\n", "t").unwrap_err().problem(),
            Some(FormatProblem::Empty)
        );
    }

    /// Found by the fuzz target `spectra`: a header whose first character is wider than
    /// one byte (`\u{fffd}` from invalid UTF-8, or any non-ASCII name) panicked on a
    /// byte slice; it is an unknown column, named with its line.
    #[test]
    fn a_multibyte_header_is_an_unknown_column() {
        for h in ["\u{fffd}1_re", "Ü1_re", "€"] {
            let text = format!("freq_hz,experiment,realization,period,{h}\n1,1,1,1,0\n");
            let e = parse_spectra_csv(&text, "t").unwrap_err();
            assert_eq!(e.problem(), Some(FormatProblem::BadHeader), "{e}");
            assert!(
                e.to_string().contains(&format!("unknown column `{h}`")),
                "{e}"
            );
            assert!(e.to_string().contains("t:1"), "{e}");
        }
        // the fuzzer's input itself, as the reader gets it (lossy UTF-8)
        let bytes = include_bytes!("../../tests/fuzz_regressions/spectra-multibyte-header.bin");
        let text = String::from_utf8_lossy(bytes);
        assert!(parse_spectra_csv(&text, "fuzz.csv").is_err());
    }
}
