//! The FRF CSV format of `FORMATS.md`: reader ([`parse_frf_csv`]) and writer
//! ([`frf_csv_string`]).
//!
//! Layout:
//!
//! ```text
//! # free text; key=value words are metadata: ny=4 nu=13 units=m/N
//! # key: value lines are metadata too
//! freq_hz,G1_1_re,G1_1_im,...,G4_13_im[,G1_1_var,...[,G1_1_var_noise,...]]
//! 2.5e-1,-1.98e-6,1.02e-8,...
//! ```
//!
//! The reader splits lines and commas by hand and parses numbers with
//! `str::parse::<f64>`; the 11 MB, 4000 x 157 reference file reads in a few tens of
//! milliseconds (see `benches/csv_read.rs`).

use crate::{FormatProblem, Frf, FrfDataset, FrfError, C64};
use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;

/// Which part of an entry a column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Part {
    Re,
    Im,
    Var,
    /// The noise part of a total variance (`_var_noise`, FORMATS.md).
    VarNoise,
}

impl Part {
    fn suffix(self) -> &'static str {
        match self {
            Part::Re => "re",
            Part::Im => "im",
            Part::Var => "var",
            Part::VarNoise => "var_noise",
        }
    }
}

/// Where the number of a column goes. Entry indices are `vec(G)` positions `j * ny + i`.
#[derive(Debug, Clone, Copy)]
enum Target {
    Freq,
    Re(usize),
    Im(usize),
    Var(usize),
    VarNoise(usize),
}

/// The name of the column holding `part` of entry `(out, inp)` (1-based indices).
fn column_name(out: usize, inp: usize, part: Part) -> String {
    format!("G{out}_{inp}_{}", part.suffix())
}

/// A 1-based index written as plain decimal digits (at most 9 of them).
fn parse_index(s: &str) -> Option<usize> {
    if s.is_empty() || s.len() > 9 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// Parses `G{out}_{in}_{re|im|var}`; indices may be 0 here (the caller rejects them).
fn parse_entry_column(name: &str) -> Option<(usize, usize, Part)> {
    let rest = name.strip_prefix('G')?;
    if let Some(idx) = rest.strip_suffix("_var_noise") {
        let (out, inp) = idx.split_once('_')?;
        return Some((parse_index(out)?, parse_index(inp)?, Part::VarNoise));
    }
    let (idx, suffix) = rest.rsplit_once('_')?;
    let part = match suffix {
        "re" => Part::Re,
        "im" => Part::Im,
        "var" => Part::Var,
        _ => return None,
    };
    let (out, inp) = idx.split_once('_')?;
    Some((parse_index(out)?, parse_index(inp)?, part))
}

/// A key of a metadata word: letters, digits, `_`, `.`, `-`, starting with a letter or `_`.
fn is_key(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-'))
}

/// Extracts metadata from the text of one comment line (after the `#`) into `md`.
///
/// Two forms: a line `key: value` (the key is a single word ending in `:`; the value is
/// the rest of the line), or free text whose words `key=value` are metadata (a trailing
/// `,` or `;` of the value is dropped).
pub(crate) fn parse_comment_metadata(text: &str, md: &mut BTreeMap<String, String>) {
    let t = text.trim();
    if let Some((key, value)) = t.split_once(':') {
        if is_key(key) && !key.contains('=') {
            md.insert(key.to_string(), value.trim().to_string());
            return;
        }
    }
    for word in t.split_whitespace() {
        if let Some((key, value)) = word.split_once('=') {
            let value = value.trim_end_matches([',', ';']);
            if is_key(key) && !value.is_empty() {
                md.insert(key.to_string(), value.to_string());
            }
        }
    }
}

/// At most 40 characters of a field, for error messages.
fn shown(field: &str) -> String {
    let t = field.trim();
    if t.chars().count() <= 40 {
        t.to_string()
    } else {
        let s: String = t.chars().take(40).collect();
        format!("{s}...")
    }
}

/// The comment text of a `#` line: without the `#` and one following space.
fn comment_text(line: &str) -> &str {
    let t = line.trim_start();
    let t = t.strip_prefix('#').unwrap_or(t);
    t.strip_prefix(' ').unwrap_or(t)
}

/// The parsed header: column targets, dimensions, variance flag.
struct Header<'a> {
    names: Vec<&'a str>,
    targets: Vec<Target>,
    ny: usize,
    nu: usize,
    has_var: bool,
    /// `_var_noise` columns beside the `_var` ones.
    has_noise: bool,
}

fn parse_header<'a>(file: &str, line_no: usize, line: &'a str) -> Result<Header<'a>, FrfError> {
    let err = |column: Option<&str>, problem, detail: String| {
        FrfError::format(file, line_no, column, problem, detail)
    };
    let names: Vec<&str> = line.split(',').map(str::trim).collect();
    let mut freq_col = None;
    let mut entries: Vec<Option<(usize, usize, Part)>> = Vec::with_capacity(names.len());
    let mut seen_names: HashSet<&str> = HashSet::with_capacity(names.len());
    let mut seen_entries: HashSet<(usize, usize, Part)> = HashSet::with_capacity(names.len());
    let (mut ny, mut nu) = (0usize, 0usize);
    for (c, &name) in names.iter().enumerate() {
        if name.is_empty() {
            let col = format!("field {}", c + 1);
            return Err(err(
                Some(&col),
                FormatProblem::BadHeader,
                format!("header field {} is empty (a stray comma?)", c + 1),
            ));
        }
        if !seen_names.insert(name) {
            return Err(err(
                Some(name),
                FormatProblem::BadHeader,
                format!("duplicate column `{name}` in the header"),
            ));
        }
        if name == "freq_hz" {
            freq_col = Some(c);
            entries.push(None);
            continue;
        }
        let Some((out, inp, part)) = parse_entry_column(name) else {
            return Err(err(
                Some(name),
                FormatProblem::BadHeader,
                format!(
                    "unknown column `{name}` (expected `freq_hz` or `G<out>_<in>_re`, `_im`, `_var`, `_var_noise`)"
                ),
            ));
        };
        if out == 0 || inp == 0 {
            return Err(err(
                Some(name),
                FormatProblem::BadHeader,
                format!("column `{name}`: entry indices are 1-based"),
            ));
        }
        if !seen_entries.insert((out, inp, part)) {
            return Err(err(
                Some(name),
                FormatProblem::BadHeader,
                format!(
                    "column `{name}` duplicates `{}`",
                    column_name(out, inp, part)
                ),
            ));
        }
        ny = ny.max(out);
        nu = nu.max(inp);
        entries.push(Some((out, inp, part)));
    }
    let Some(freq_col) = freq_col else {
        return Err(err(
            Some("freq_hz"),
            FormatProblem::BadHeader,
            "the header has no `freq_hz` column (is this an FRF CSV file?)".into(),
        ));
    };
    if ny == 0 {
        return Err(err(
            None,
            FormatProblem::BadHeader,
            "the header has no `G<out>_<in>_re`/`_im` columns".into(),
        ));
    }
    // Every entry needs its _re and _im columns. The first missing one is found within
    // (number of columns + 1) probes, whatever the (possibly huge) largest indices.
    for inp in 1..=nu {
        for out in 1..=ny {
            for part in [Part::Re, Part::Im] {
                if !seen_entries.contains(&(out, inp, part)) {
                    let col = column_name(out, inp, part);
                    return Err(err(
                        Some(&col),
                        FormatProblem::MissingEntry,
                        format!(
                            "column `{col}` is missing: the header's largest indices make the \
                             data {ny} x {nu}, and every entry needs `_re` and `_im` columns"
                        ),
                    ));
                }
            }
        }
    }
    let n_var = entries
        .iter()
        .filter(|e| matches!(e, Some((_, _, Part::Var))))
        .count();
    let has_var = n_var > 0;
    if has_var {
        for inp in 1..=nu {
            for out in 1..=ny {
                if !seen_entries.contains(&(out, inp, Part::Var)) {
                    let col = column_name(out, inp, Part::Var);
                    return Err(err(
                        Some(&col),
                        FormatProblem::InconsistentVariance,
                        format!(
                            "column `{col}` is missing: {n_var} of the {} entries carry a \
                             `_var` column; either all entries carry one or none does",
                            ny * nu
                        ),
                    ));
                }
            }
        }
    }
    let n_noise = entries
        .iter()
        .filter(|e| matches!(e, Some((_, _, Part::VarNoise))))
        .count();
    let has_noise = n_noise > 0;
    if has_noise {
        if !has_var {
            let col = column_name(1, 1, Part::VarNoise);
            return Err(err(
                Some(&col),
                FormatProblem::InconsistentVariance,
                "`_var_noise` columns (the noise part of a total variance) need the `_var` \
                 columns beside them"
                    .into(),
            ));
        }
        for inp in 1..=nu {
            for out in 1..=ny {
                if !seen_entries.contains(&(out, inp, Part::VarNoise)) {
                    let col = column_name(out, inp, Part::VarNoise);
                    return Err(err(
                        Some(&col),
                        FormatProblem::InconsistentVariance,
                        format!(
                            "column `{col}` is missing: {n_noise} of the {} entries carry a \
                             `_var_noise` column; either all entries carry one or none does",
                            ny * nu
                        ),
                    ));
                }
            }
        }
    }
    let targets = entries
        .iter()
        .enumerate()
        .map(|(c, e)| match *e {
            None => {
                debug_assert_eq!(c, freq_col);
                Target::Freq
            }
            Some((out, inp, part)) => {
                let e = (inp - 1) * ny + (out - 1);
                match part {
                    Part::Re => Target::Re(e),
                    Part::Im => Target::Im(e),
                    Part::Var => Target::Var(e),
                    Part::VarNoise => Target::VarNoise(e),
                }
            }
        })
        .collect();
    Ok(Header {
        names,
        targets,
        ny,
        nu,
        has_var,
        has_noise,
    })
}

/// Checks the dimensions a comment announces (`ny=`, `nu=`) against the header's.
fn check_announced_dims(
    file: &str,
    line_no: usize,
    md: &BTreeMap<String, String>,
    ny: usize,
    nu: usize,
) -> Result<(), FrfError> {
    for (key, have) in [("ny", ny), ("nu", nu)] {
        if let Some(Ok(said)) = md.get(key).map(|v| v.trim().parse::<usize>()) {
            if said != have {
                return Err(FrfError::format(
                    file,
                    line_no,
                    None,
                    FormatProblem::BadHeader,
                    format!(
                        "the comments say {key}={said}, but the header's columns make the data \
                         {ny} x {nu}"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Parses one numeric field; surrounding blanks are allowed, and so is a Fortran `D`
/// exponent.
#[inline]
fn parse_number(field: &str) -> Option<f64> {
    match field.parse::<f64>() {
        Ok(x) => Some(x),
        Err(_) => {
            let t = field.trim();
            t.parse::<f64>().ok().or_else(|| {
                // Fortran's exponent letter (`1.5D+03`).
                t.contains(['d', 'D'])
                    .then(|| t.replace(['d', 'D'], "e").parse::<f64>().ok())
                    .flatten()
            })
        }
    }
}

/// Parses FRF CSV text (see the module docs and `FORMATS.md`); `name` stands for the
/// file in error messages and becomes [`Frf::source`].
///
/// Comment lines (`#`) before the header and between data lines are kept in
/// [`Frf::comments`] (without the `#` and one following blank); their `key=value` words
/// and `key: value` lines go to [`Frf::metadata`], and `units` also to [`Frf::units`].
/// A 0 Hz line needs `dc=allowed` in a comment before it. Blank lines are skipped.
///
/// Errors are [`FrfError::Format`] naming the file, the 1-based line (0 for a file
/// without a header), the column when there is one, and the [`FormatProblem`]:
/// `Empty` (no header, or a header without data lines), `BadHeader` (empty, unknown or
/// duplicate column, no `freq_hz`, comments announcing other dimensions),
/// `MissingEntry`, `InconsistentVariance`, `FieldCount`, `NotANumber`, `NonFinite`,
/// `NegativeVariance`, `NotIncreasing`, `BadFrequency`.
pub fn parse_frf_csv(text: &str, name: &str) -> Result<Frf, FrfError> {
    let (text, dialect) = super::dialect::normalize(text, name)?;
    let text: &str = &text;
    let mut metadata = BTreeMap::new();
    let mut comments = Vec::new();
    let mut lines = text.split('\n').enumerate();

    // Comments and the header.
    let mut header = None;
    for (idx, raw) in lines.by_ref() {
        let line = raw.strip_suffix('\r').unwrap_or(raw);
        let t = line.trim_start();
        if t.is_empty() {
            continue;
        }
        if t.starts_with('#') {
            let c = comment_text(line);
            parse_comment_metadata(c, &mut metadata);
            comments.push(c.to_string());
            continue;
        }
        header = Some((idx + 1, line));
        break;
    }
    let Some((header_line, header_text)) = header else {
        return Err(FrfError::format(
            name,
            0,
            None,
            FormatProblem::Empty,
            "the file is empty: no header line (only comments or blank lines, if anything)",
        ));
    };
    let Header {
        names,
        targets,
        ny,
        nu,
        has_var,
        has_noise,
    } = parse_header(name, header_line, header_text)?;
    check_announced_dims(name, header_line, &metadata, ny, nu)?;
    let m = ny * nu;

    // Data lines: found in order, parsed in blocks on the rayon pool (a 50 x 50 file
    // with variances holds hundreds of MB of numbers), then checked in order, so that
    // the first problem of the file is the one reported, as a line-by-line reader would.
    let mut items: Vec<(usize, &str, bool)> = Vec::new();
    for (idx, raw) in lines {
        let line = raw.strip_suffix('\r').unwrap_or(raw);
        if line.bytes().all(|b| b.is_ascii_whitespace()) {
            continue;
        }
        let comment = line.trim_start().starts_with('#');
        items.push((idx + 1, line, comment));
    }
    let data_lines: Vec<(usize, &str)> = items
        .iter()
        .filter(|(_, _, c)| !c)
        .map(|&(no, l, _)| (no, l))
        .collect();
    let n_data = data_lines.len();
    let zero = C64::new(0.0, 0.0);
    let mut values: Vec<C64> = vec![zero; n_data * m];
    // per line the variances, then (with `_var_noise`) their noise parts: `w` numbers
    let w = if has_noise { 2 * m } else { m };
    let mut variance: Vec<f64> = vec![0.0; if has_var { n_data * w } else { 0 }];
    let mut parsed_freqs: Vec<f64> = vec![f64::NAN; n_data];
    let ctx = LineParser {
        name,
        names: &names,
        targets: &targets,
        m,
    };
    let first_error = {
        use rayon::prelude::*;
        let block = PARSE_BLOCK_LINES;
        let run = |(b, (vals, fr)): (usize, (&mut [C64], &mut [f64])), var: &mut [f64]| {
            for (i, f) in fr.iter_mut().enumerate() {
                let k = b * block + i;
                let (line_no, line) = data_lines[k];
                let var_row = if has_var {
                    &mut var[i * w..(i + 1) * w]
                } else {
                    &mut []
                };
                match ctx.parse(line_no, line, &mut vals[i * m..(i + 1) * m], var_row) {
                    Ok(x) => *f = x,
                    Err(e) => return Some((k, e)),
                }
            }
            None
        };
        let errors: Vec<(usize, FrfError)> = if has_var {
            values
                .par_chunks_mut(block * m.max(1))
                .zip(parsed_freqs.par_chunks_mut(block))
                .zip(variance.par_chunks_mut(block * w.max(1)))
                .enumerate()
                .filter_map(|(b, ((vals, fr), var))| run((b, (vals, fr)), var))
                .collect()
        } else {
            values
                .par_chunks_mut(block * m.max(1))
                .zip(parsed_freqs.par_chunks_mut(block))
                .enumerate()
                .filter_map(|(b, (vals, fr))| run((b, (vals, fr)), &mut []))
                .collect()
        };
        errors.into_iter().min_by_key(|(k, _)| *k)
    };
    let mut first_error = first_error;
    let mut freqs: Vec<f64> = Vec::with_capacity(n_data);
    let mut dc_allowed: Option<bool> = None;
    for &(line_no, line, comment) in &items {
        if comment {
            let c = comment_text(line);
            parse_comment_metadata(c, &mut metadata);
            comments.push(c.to_string());
            continue;
        }
        let k = freqs.len();
        if first_error.as_ref().is_some_and(|(i, _)| *i == k) {
            if let Some((_, e)) = first_error.take() {
                return Err(e);
            }
        }
        let freq = parsed_freqs[k];
        let freq_err = |problem, detail: String| {
            FrfError::format(name, line_no, Some("freq_hz"), problem, detail)
        };
        if freq < 0.0 {
            return Err(freq_err(
                FormatProblem::BadFrequency,
                format!("frequency {freq} Hz is negative"),
            ));
        }
        if let Some(&prev) = freqs.last() {
            if freq <= prev {
                return Err(freq_err(
                    FormatProblem::NotIncreasing,
                    format!(
                        "frequencies must increase strictly: {freq} Hz follows {prev} Hz on an \
                         earlier line"
                    ),
                ));
            }
        }
        if freq == 0.0 {
            let allowed = *dc_allowed.get_or_insert_with(|| {
                metadata
                    .get("dc")
                    .is_some_and(|v| v.eq_ignore_ascii_case("allowed"))
            });
            if !allowed {
                return Err(freq_err(
                    FormatProblem::BadFrequency,
                    "a 0 Hz line needs `dc=allowed` in a comment line before it".into(),
                ));
            }
        }
        freqs.push(freq);
    }
    if freqs.is_empty() {
        return Err(FrfError::format(
            name,
            header_line,
            None,
            FormatProblem::Empty,
            "the file has a header but no data lines",
        ));
    }
    let noise = has_noise.then(|| {
        let (mut var, mut noise) = (
            Vec::with_capacity(n_data * m),
            Vec::with_capacity(n_data * m),
        );
        for row in variance.chunks(w) {
            var.extend_from_slice(&row[..m]);
            noise.extend_from_slice(&row[m..]);
        }
        variance = var;
        noise
    });
    let mut frf =
        Frf::new(freqs, ny, nu, values, has_var.then_some(variance))?.with_noise_variance(noise)?;
    frf.units = metadata.get("units").cloned();
    metadata.insert("csv.dialect".to_string(), dialect.to_string());
    frf.metadata = metadata;
    frf.comments = comments;
    frf.source = Some(name.to_string());
    Ok(frf)
}

/// Lines per block of the parallel parse of [`parse_frf_csv`].
const PARSE_BLOCK_LINES: usize = 64;

/// What the parse of one data line needs from the header.
struct LineParser<'a> {
    name: &'a str,
    names: &'a [&'a str],
    targets: &'a [Target],
    m: usize,
}

impl LineParser<'_> {
    /// Parses data line `line_no` into its entries' values (and variances, when the
    /// header has them) and returns its frequency; the first bad field is an error
    /// naming the file, line and column.
    fn parse(
        &self,
        line_no: usize,
        line: &str,
        row_values: &mut [C64],
        row_var: &mut [f64],
    ) -> Result<f64, FrfError> {
        let (names, n_cols) = (self.names, self.targets.len());
        debug_assert_eq!(row_values.len(), self.m);
        let err = |c: usize, problem, detail: String| {
            FrfError::format(self.name, line_no, Some(names[c]), problem, detail)
        };
        let mut fields = line.split(',');
        let mut freq = f64::NAN;
        for (c, &target) in self.targets.iter().enumerate() {
            let Some(field) = fields.next() else {
                return Err(err(
                    c,
                    FormatProblem::FieldCount,
                    format!(
                        "the line has {c} fields, the header {n_cols}: no value for column `{}`",
                        names[c]
                    ),
                ));
            };
            let Some(x) = parse_number(field) else {
                let detail = if field.trim().is_empty() {
                    "empty field where a number is expected".to_string()
                } else {
                    format!("`{}` is not a number", shown(field))
                };
                return Err(err(c, FormatProblem::NotANumber, detail));
            };
            if !x.is_finite() {
                let what = if x.is_nan() {
                    "NaN (not a number)"
                } else {
                    "infinite"
                };
                return Err(err(
                    c,
                    FormatProblem::NonFinite,
                    format!(
                        "`{}` is {what}; every value must be a finite number",
                        shown(field)
                    ),
                ));
            }
            match target {
                Target::Freq => freq = x,
                Target::Re(e) => row_values[e].re = x,
                Target::Im(e) => row_values[e].im = x,
                Target::Var(e) => {
                    if x < 0.0 {
                        return Err(err(
                            c,
                            FormatProblem::NegativeVariance,
                            format!("variance {} is negative", shown(field)),
                        ));
                    }
                    row_var[e] = x;
                }
                Target::VarNoise(e) => {
                    if x < 0.0 {
                        return Err(err(
                            c,
                            FormatProblem::NegativeVariance,
                            format!("noise variance {} is negative", shown(field)),
                        ));
                    }
                    row_var[self.m + e] = x;
                }
            }
        }
        if fields.next().is_some() {
            let n_fields = n_cols + 1 + fields.count();
            let col = format!("field {}", n_cols + 1);
            return Err(FrfError::format(
                self.name,
                line_no,
                Some(&col),
                FormatProblem::FieldCount,
                format!("the line has {n_fields} fields, the header {n_cols}"),
            ));
        }
        Ok(freq)
    }
}

/// True for comment lines the writer regenerates itself: a `units: ...` line, or only
/// `key=value` words with keys among `ny`, `nu`, `units`, `dc`.
fn is_generated_line(comment: &str) -> bool {
    if comment.trim_start().starts_with("units:") {
        return true;
    }
    let mut words = comment.split_whitespace().peekable();
    words.peek().is_some()
        && words.all(|w| {
            w.split_once('=')
                .is_some_and(|(k, _)| matches!(k, "ny" | "nu" | "units" | "dc"))
        })
}

/// Units that survive as a `units=...` word: no blanks, no `,`, `;` or `=`.
fn is_word_safe(units: &str) -> bool {
    !units
        .chars()
        .any(|c| c.is_whitespace() || matches!(c, ',' | ';' | '='))
}

/// The FRF CSV text of `data` (see `FORMATS.md`).
///
/// Layout: each of `comments` as `# ` lines (a comment with line breaks becomes several
/// lines; comments made only of `ny=`, `nu=`, `units=`, `dc=` words are left out because
/// the writer regenerates them), then `# ny=.. nu=..` with `units=..` when the data have
/// units (as a separate `# units: ..` line when the units contain blanks, `,`, `;` or
/// `=`) and
/// `dc=allowed` when the first line is at 0 Hz, then the header: `freq_hz`, the
/// `_re`/`_im` pairs column-major by entry (`G1_1`, `G2_1`, ..., `G1_2`, ...), then the
/// `_var` columns in the same order when the data carry variances, and the `_var_noise`
/// columns (the noise part of a total variance) when they carry that too. Numbers use Rust's
/// shortest round-trip formatting (`{:e}`), so [`parse_frf_csv`] gives back the very
/// same bits (non-finite values, which an [`Frf`] cannot hold, would not read back).
pub fn frf_csv_string<D: FrfDataset + ?Sized>(data: &D, comments: &[String]) -> String {
    let (ny, nu, n) = (data.ny(), data.nu(), data.n_lines());
    let m = ny * nu;
    let has_var = data.has_variance();
    let has_noise = has_var && data.has_noise_variance();
    let n_cols = 1 + m * (2 + usize::from(has_var) + usize::from(has_noise));
    let mut s = String::with_capacity(256 + n_cols * 16 + n * n_cols * 24);
    for c in comments {
        if is_generated_line(c) {
            continue;
        }
        if c.is_empty() {
            s.push_str("#\n");
        }
        for l in c.lines() {
            s.push_str("# ");
            s.push_str(l);
            s.push('\n');
        }
    }
    let _ = write!(s, "# ny={ny} nu={nu}");
    let units = data
        .units()
        .map(|u| u.replace(['\n', '\r'], " "))
        .map(|u| u.trim().to_string())
        .filter(|u| !u.is_empty());
    let units_line = match units {
        Some(u) if !is_word_safe(&u) => Some(u),
        Some(u) => {
            let _ = write!(s, " units={u}");
            None
        }
        None => None,
    };
    if n > 0 && data.freq_hz(0) == 0.0 {
        s.push_str(" dc=allowed");
    }
    s.push('\n');
    if let Some(u) = units_line {
        let _ = writeln!(s, "# units: {u}");
    }
    s.push_str("freq_hz");
    for j in 1..=nu {
        for i in 1..=ny {
            let _ = write!(s, ",G{i}_{j}_re,G{i}_{j}_im");
        }
    }
    if has_var {
        for j in 1..=nu {
            for i in 1..=ny {
                let _ = write!(s, ",G{i}_{j}_var");
            }
        }
    }
    if has_noise {
        for j in 1..=nu {
            for i in 1..=ny {
                let _ = write!(s, ",G{i}_{j}_var_noise");
            }
        }
    }
    s.push('\n');
    let mut line = vec![C64::new(0.0, 0.0); m];
    let mut var = vec![0.0; m];
    for k in 0..n {
        let _ = write!(s, "{:e}", data.freq_hz(k));
        data.line_into(k, &mut line);
        for z in &line {
            let _ = write!(s, ",{:e},{:e}", z.re, z.im);
        }
        if has_var && data.variance_line_into(k, &mut var) {
            for v in &var {
                let _ = write!(s, ",{v:e}");
            }
        }
        if has_noise && data.noise_variance_line_into(k, &mut var) {
            for v in &var {
                let _ = write!(s, ",{v:e}");
            }
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file of many blocks of lines (parsed in parallel) with two problems reports the
    /// first in the file, whichever kind each is, and a comment between data lines still
    /// applies to the lines after it.
    #[test]
    fn the_first_problem_of_a_long_file_is_reported() {
        let file = |bad: &[(usize, &str)], dc_comment_at: Option<usize>| {
            let mut t = String::from("freq_hz,G1_1_re,G1_1_im,G1_1_var\n");
            for k in 0..700usize {
                if dc_comment_at == Some(k) {
                    t.push_str("# dc=allowed\n");
                }
                match bad.iter().find(|(line, _)| *line == k) {
                    Some((_, text)) => t.push_str(text),
                    None => t.push_str(&format!("{},1.5,-0.25,1e-6", 1.0 + k as f64)),
                }
                t.push('\n');
            }
            t
        };
        let line_of = |e: FrfError| match e {
            FrfError::Format {
                line,
                column,
                problem,
                ..
            } => (line, column, problem),
            other => panic!("{other}"),
        };
        // data line k is file line k + 2 (the header is line 1)
        let e = parse_frf_csv(
            &file(&[(100, "50,1,1,1e-6"), (450, "451,NaN,1,1e-6")], None),
            "f",
        )
        .unwrap_err();
        assert_eq!(
            line_of(e),
            (102, Some("freq_hz".into()), FormatProblem::NotIncreasing)
        );
        let e = parse_frf_csv(
            &file(&[(300, "301,1,x,1e-6"), (600, "10,1,1,1e-6")], None),
            "f",
        )
        .unwrap_err();
        assert_eq!(
            line_of(e),
            (302, Some("G1_1_im".into()), FormatProblem::NotANumber)
        );
        let e =
            parse_frf_csv(&file(&[(640, "641,1,1,-1"), (650, "651,1,1")], None), "f").unwrap_err();
        assert_eq!(
            line_of(e),
            (
                642,
                Some("G1_1_var".into()),
                FormatProblem::NegativeVariance
            )
        );
        let ok = parse_frf_csv(&file(&[], None), "f").unwrap();
        assert_eq!(ok.n_lines(), 700);
        assert_eq!(ok.freq_hz_slice()[699], 700.0);
        assert_eq!(ok.value(699, 0, 0), C64::new(1.5, -0.25));
        // a 0 Hz first line needs the comment before it
        let dc = |t: String| t.replacen("\n1,1.5", "\n0,1.5", 1);
        assert!(parse_frf_csv(&dc(file(&[], None)), "f").is_err());
        let with = parse_frf_csv(&dc(file(&[], Some(0))), "f").unwrap();
        assert_eq!(with.freq_hz_slice()[0], 0.0);
    }

    #[test]
    fn entry_column_names() {
        assert_eq!(parse_entry_column("G1_1_re"), Some((1, 1, Part::Re)));
        assert_eq!(parse_entry_column("G12_3_var"), Some((12, 3, Part::Var)));
        assert_eq!(parse_entry_column("G0_3_im"), Some((0, 3, Part::Im)));
        for bad in [
            "G1_re",
            "G1_1",
            "G1_1_abs",
            "g1_1_re",
            "G_1_re",
            "G1__re",
            "G+1_1_re",
            "G1_1_1_re",
            "G1234567890_1_re",
            "Gx_1_re",
            "",
        ] {
            assert_eq!(parse_entry_column(bad), None, "{bad}");
        }
    }

    #[test]
    fn comment_metadata_both_forms() {
        let mut md = BTreeMap::new();
        parse_comment_metadata("ny=4 nu=13 units=m/N (displacement per force)", &mut md);
        parse_comment_metadata("name: daisy_flexible_structure", &mut md);
        parse_comment_metadata("freq_range_hz: 10 - 500", &mut md);
        parse_comment_metadata("sampling 10 kHz; delay present: True", &mut md);
        parse_comment_metadata("experiments=1 periods=19; U1 = current", &mut md);
        assert_eq!(md["ny"], "4");
        assert_eq!(md["nu"], "13");
        assert_eq!(md["units"], "m/N");
        assert_eq!(md["name"], "daisy_flexible_structure");
        assert_eq!(md["freq_range_hz"], "10 - 500");
        assert_eq!(md["periods"], "19");
        assert_eq!(md["experiments"], "1");
        assert_eq!(md.len(), 7, "{md:?}");
    }

    #[test]
    fn generated_lines_are_recognised() {
        assert!(is_generated_line("ny=4 nu=13 units=m/N"));
        assert!(is_generated_line("ny=1 nu=1 dc=allowed"));
        assert!(is_generated_line("units: m/s^2 per N"));
        assert!(!is_generated_line("ny: 28"));
        assert!(!is_generated_line(
            "ny=4 nu=13 units=m/N (displacement per force)"
        ));
        assert!(!is_generated_line(""));
        assert!(!is_generated_line("seed=1"));
    }

    #[test]
    fn writer_layout() {
        let f = Frf::from_fn(vec![0.5, 1.0], 2, 1, |k, i, _| {
            C64::new(k as f64 + 0.25, i as f64 - 1.0)
        })
        .unwrap();
        let s = frf_csv_string(&f, &["hello".into(), "two\nlines".into()]);
        let expected = "# hello\n# two\n# lines\n# ny=2 nu=1\n\
                        freq_hz,G1_1_re,G1_1_im,G2_1_re,G2_1_im\n\
                        5e-1,2.5e-1,-1e0,2.5e-1,0e0\n\
                        1e0,1.25e0,-1e0,1.25e0,0e0\n";
        assert_eq!(s, expected);
    }

    #[test]
    fn writer_units_with_blanks_and_dc() {
        let mut f = Frf::from_fn(vec![0.0, 1.0], 1, 1, |_, _, _| C64::new(1.0, 0.0)).unwrap();
        f.units = Some(" m/s^2  per N\n".into());
        let s = frf_csv_string(&f, &[]);
        assert!(
            s.starts_with("# ny=1 nu=1 dc=allowed\n# units: m/s^2  per N\nfreq_hz,"),
            "{s}"
        );
        let back = parse_frf_csv(&s, "mem").unwrap();
        assert_eq!(back.units.as_deref(), Some("m/s^2  per N"));
        f.units = Some("V,A".into());
        let back = parse_frf_csv(&frf_csv_string(&f, &[]), "mem").unwrap();
        assert_eq!(back.units.as_deref(), Some("V,A"));
        assert_eq!(back.freq_hz_slice(), &[0.0, 1.0]);
    }

    /// `_var_noise` columns (the noise part of a total variance) read back bit for bit,
    /// need `_var` beside them and every entry, and are written only when present.
    #[test]
    fn noise_variance_columns_round_trip_and_are_checked() {
        let f = Frf::new(
            vec![1.0, 2.0],
            2,
            1,
            vec![C64::new(1.0, -0.5); 4],
            Some(vec![0.3, 0.1, 0.25, 0.125]),
        )
        .unwrap()
        .with_noise_variance(Some(vec![0.1, 0.05, 0.2, 1e-3]))
        .unwrap();
        let text = frf_csv_string(&f, &[]);
        assert!(text.contains(",G2_1_var_noise\n"), "{text}");
        let back = parse_frf_csv(&text, "t.csv").unwrap();
        assert_eq!(back.variances(), f.variances());
        assert_eq!(back.noise_variances(), f.noise_variances());
        // a band view keeps the noise part
        let band = f.band(1.5, 3.0).unwrap().to_frf();
        assert_eq!(band.noise_variances(), Some(&[0.2, 1e-3][..]));
        // without `_var`
        let e = parse_frf_csv(
            "freq_hz,G1_1_re,G1_1_im,G1_1_var_noise\n1,1,0,0.1\n",
            "t.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("need the `_var` columns"), "{e}");
        // not on every entry
        let e = parse_frf_csv(
            "freq_hz,G1_1_re,G1_1_im,G2_1_re,G2_1_im,G1_1_var,G2_1_var,G1_1_var_noise\n1,1,0,1,0,1,1,0.1\n",
            "t.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("G2_1_var_noise") && e.contains("missing"), "{e}");
        // negative
        let e = parse_frf_csv(
            "freq_hz,G1_1_re,G1_1_im,G1_1_var,G1_1_var_noise\n1,1,0,1,-0.1\n",
            "t.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("negative") && e.contains("G1_1_var_noise"),
            "{e}"
        );
        // data without it write no such column
        let plain = f.clone().with_noise_variance(None).unwrap();
        assert!(!frf_csv_string(&plain, &[]).contains("var_noise"));
    }
}
