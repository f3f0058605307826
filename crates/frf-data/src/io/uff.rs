//! Universal File Format dataset 58 (function at nodal DOF), ASCII: the reader
//! [`parse_uff58`].
//!
//! A UFF file is a sequence of datasets, each between two lines holding `-1` in columns
//! 1-6; the line after the opening delimiter holds the dataset number (`58`; `58b` is the
//! binary variant). A dataset 58 holds one function for one response/reference pair:
//!
//! | record | format | content |
//! |---|---|---|
//! | 1-5 | 80A1 | ID lines (description, free text, date, ...) |
//! | 6 | 2(I5,I10),2(1X,10A1,I10,I4) | function type (4 = FRF), function id, version, load case, response entity, node, direction, reference entity, node, direction |
//! | 7 | 3I10,3E13.5 | ordinate data type (2 real single, 4 real double, 5 complex single, 6 complex double), number of points, abscissa spacing (1 even, 0 uneven), abscissa start, increment, z value |
//! | 8-11 | I10,3I5,2(1X,20A1) | data characteristics of the abscissa, ordinate numerator, ordinate denominator, z axis: specific data type, unit exponents (length, force, temperature), axis label, units label |
//! | 12 | see below | the data |
//!
//! Data layouts of record 12 (all Fortran `E` fields, read by their fixed widths, so
//! fields that touch each other are fine):
//!
//! | ordinate | abscissa | per line | fields |
//! |---|---|---|---|
//! | single, real or complex | even or uneven | 6 | E13.5 |
//! | double, real or complex | even | 4 | E20.12 |
//! | double, real | uneven | 2 pairs | (E13.5, E20.12) |
//! | double, complex | uneven | 1 triple | E13.5, 2 E20.12 |
//!
//! With uneven spacing each point is `x, y` (real) or `x, re, im` (complex); with even
//! spacing `x_k = start + k * increment`. When a line does not match the fixed widths
//! (a writer that ignored them), its blank-separated numbers are taken instead.
//! Fortran forms such as `1.5D+03` and `1.5-100` (exponent without `E`) are understood.

use super::uff_binary::{is_binary_number_line, split_lines, BinaryData};
use crate::{FormatProblem, Frf, FrfError, C64};
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};

/// Function type code of an FRF in record 6.
const FUNCTION_FRF: i64 = 4;

/// Name of a function type code of record 6 (for skip notes).
fn function_type_name(code: i64) -> &'static str {
    match code {
        0 => "general or unknown",
        1 => "time response",
        2 => "auto spectrum",
        3 => "cross spectrum",
        4 => "frequency response function",
        5 => "transmissibility",
        6 => "coherence",
        7 => "auto correlation",
        8 => "cross correlation",
        9 => "power spectral density",
        10 => "energy spectral density",
        11 => "probability density function",
        12 => "spectrum",
        13 => "cumulative frequency distribution",
        14 => "peaks valley",
        15 => "stress/cycles",
        16 => "strain/cycles",
        17 => "orbit",
        18 => "mode indicator function",
        19 => "force pattern",
        20 => "partial power",
        21 => "partial coherence",
        22 => "eigenvalue",
        23 => "eigenvector",
        24 => "shock response spectrum",
        25 => "finite impulse response filter",
        26 => "multiple coherence",
        27 => "order function",
        _ => "unknown function type",
    }
}

/// Name of a specific data type code of records 8-11.
fn data_type_name(code: i64) -> &'static str {
    match code {
        0 => "unknown",
        1 => "general",
        2 => "stress",
        3 => "strain",
        5 => "temperature",
        6 => "heat flux",
        8 => "displacement",
        9 => "reaction force",
        11 => "velocity",
        12 => "acceleration",
        13 => "excitation force",
        15 => "pressure",
        16 => "mass",
        17 => "time",
        18 => "frequency",
        19 => "rpm",
        20 => "order",
        _ => "other",
    }
}

/// Short name of a direction code of record 6 (`+Z`, `-RX`, `S` for scalar).
fn direction_name(code: i64) -> String {
    let axis = match code.unsigned_abs() {
        0 => return "S".into(),
        1 => "X",
        2 => "Y",
        3 => "Z",
        4 => "RX",
        5 => "RY",
        6 => "RZ",
        _ => return format!("dir{code}"),
    };
    format!("{}{axis}", if code < 0 { '-' } else { '+' })
}

/// Reads a Fortran `E`/`D` field: blanks around it are allowed, `D` or `Q` stand for
/// `E`, and an exponent may come without its letter (`1.5-100`). `None` when blank or
/// not a number.
pub(crate) fn parse_fortran_real(field: &str) -> Option<f64> {
    let t = field.trim();
    if t.is_empty() {
        return None;
    }
    if let Ok(x) = t.parse::<f64>() {
        return Some(x);
    }
    let mut buf = String::with_capacity(t.len() + 1);
    let mut prev = ' ';
    for (k, c) in t.chars().enumerate() {
        match c {
            'D' | 'd' | 'Q' | 'q' => buf.push('e'),
            '+' | '-' if k > 0 && !matches!(prev, 'e' | 'E' | 'd' | 'D' | 'q' | 'Q') => {
                buf.push('e');
                buf.push(c);
            }
            _ => buf.push(c),
        }
        prev = c;
    }
    buf.parse().ok()
}

/// The part of `line` in the 0-based byte columns `a..b`; `""` past the end of the line
/// (Fortran reads missing columns as blanks), `None` when the range splits a non-ASCII
/// character.
fn columns(line: &str, a: usize, b: usize) -> Option<&str> {
    let b = b.min(line.len());
    if a >= b {
        return Some("");
    }
    line.get(a..b)
}

/// A Fortran integer field: blank reads as 0.
fn parse_fortran_int(field: &str) -> Option<i64> {
    let t = field.trim();
    if t.is_empty() {
        Some(0)
    } else {
        t.parse().ok()
    }
}

/// The text of the file, split in lines (binary blocks taken out), with error helpers.
struct Lines<'a> {
    file: &'a str,
    lines: Vec<Cow<'a, str>>,
    /// 1-based line number in the file of each entry of `lines`.
    line_no: Vec<usize>,
    /// Decoded record 12 of binary datasets 58, by the index of their marker line.
    binary: HashMap<usize, BinaryData>,
}

impl Lines<'_> {
    fn get(&self, idx: usize) -> Option<&str> {
        self.lines.get(idx).map(|c| c.as_ref())
    }
    /// The 1-based line number in the file of line index `idx`.
    fn no(&self, idx: usize) -> usize {
        self.line_no.get(idx).copied().unwrap_or(idx + 1)
    }
    fn err(
        &self,
        idx: usize,
        column: Option<&str>,
        problem: FormatProblem,
        detail: String,
    ) -> FrfError {
        FrfError::format(self.file, self.no(idx), column, problem, detail)
    }
    fn is_delimiter(&self, idx: usize) -> bool {
        self.get(idx).is_some_and(|l| l.trim() == "-1")
    }
}

/// Integer fields at fixed columns (`(start, end, description)`, 0-based byte columns);
/// when they do not parse and the line has exactly as many blank-separated words as
/// `fallback_words` says, those words at the positions `fallback_pos` are used instead.
fn int_fields<const N: usize>(
    l: &Lines<'_>,
    idx: usize,
    record: &str,
    spec: [(usize, usize, &str); N],
    fallback_words: usize,
    fallback_pos: [usize; N],
) -> Result<[i64; N], FrfError> {
    let line = l.get(idx).unwrap_or("");
    let mut out = [0i64; N];
    let mut failed = None;
    for (q, &(a, b, what)) in spec.iter().enumerate() {
        match columns(line, a, b).and_then(parse_fortran_int) {
            Some(v) => out[q] = v,
            None => {
                failed = Some((a, b, what));
                break;
            }
        }
    }
    let Some((a, b, what)) = failed else {
        return Ok(out);
    };
    let words: Vec<&str> = line.split_whitespace().collect();
    if words.len() == fallback_words {
        let parsed: Option<Vec<i64>> = fallback_pos
            .iter()
            .map(|&p| words[p].parse::<i64>().ok())
            .collect();
        if let Some(p) = parsed {
            out.copy_from_slice(&p);
            return Ok(out);
        }
    }
    let col = format!("{record}, {what} (columns {}-{})", a + 1, b);
    let text = columns(line, a, b).unwrap_or(line).trim();
    Err(l.err(
        idx,
        Some(&col),
        FormatProblem::BadRecord,
        format!("`{text}` is not an integer ({record} of a UFF dataset 58)"),
    ))
}

/// Text field at fixed columns, trimmed (empty when absent or not ASCII-aligned).
fn text_field(line: &str, a: usize, b: usize) -> String {
    columns(line, a, b).unwrap_or("").trim().to_string()
}

/// Data characteristics (records 8-11).
#[derive(Debug, Clone)]
struct AxisInfo {
    data_type: i64,
    label: String,
    units: String,
}

fn axis_info(l: &Lines<'_>, idx: usize, record: &str) -> Result<AxisInfo, FrfError> {
    let [data_type, _, _, _] = int_fields(
        l,
        idx,
        record,
        [
            (0, 10, "specific data type"),
            (10, 15, "length units exponent"),
            (15, 20, "force units exponent"),
            (20, 25, "temperature units exponent"),
        ],
        4,
        [0, 1, 2, 3],
    )?;
    let line = l.get(idx).unwrap_or("");
    Ok(AxisInfo {
        data_type,
        label: text_field(line, 26, 46),
        units: text_field(line, 47, 67),
    })
}

/// A degree of freedom: node and direction code.
type Dof = (i64, i64);

/// One FRF record (dataset 58, function type 4), parsed.
struct Record {
    /// 0-based index of the record 6 line.
    header_idx: usize,
    /// 0-based index of the record 7 line.
    r7_idx: usize,
    id1: String,
    response: Dof,
    reference: Dof,
    ordinate_type: i64,
    even: bool,
    /// Record 12 was binary (`58b`).
    binary: bool,
    freq_hz: Vec<f64>,
    values: Vec<C64>,
    abscissa: AxisInfo,
    numerator: AxisInfo,
    denominator: AxisInfo,
}

/// What a dataset 58 turned out to hold.
enum Parsed58 {
    Frf(Box<Record>),
    /// Not an FRF: a note for the metadata.
    Skipped(String),
}

/// The data layout of record 12: field widths (cycled by the value's index within a
/// point) and values per line.
fn data_layout(ordinate_type: i64, even: bool) -> (&'static [usize], usize) {
    match (ordinate_type, even) {
        (2 | 5, _) => (&[13], 6),
        (4 | 6, true) => (&[20], 4),
        (4, false) => (&[13, 20], 4),
        _ => (&[13, 20, 20], 3),
    }
}

/// Reads the values of one data line into `vals` (`want` of them, the first being the
/// `start`-th value of the record) by the fixed widths; falls back to blank-separated
/// words when the widths do not fit the line.
fn read_data_line(
    l: &Lines<'_>,
    idx: usize,
    widths: &[usize],
    start: usize,
    want: usize,
    remaining: usize,
    vals: &mut Vec<f64>,
) -> Result<(), FrfError> {
    let line = l.get(idx).unwrap_or("");
    let before = vals.len();
    let mut pos = 0;
    let mut failure = None;
    for q in 0..want {
        let w = widths[(start + q) % widths.len()];
        let field = columns(line, pos, pos + w);
        match field.and_then(parse_fortran_real) {
            Some(x) => vals.push(x),
            None => {
                failure = Some((q, pos, w, field.unwrap_or("")));
                break;
            }
        }
        pos += w;
    }
    let trailing_junk = failure.is_none()
        && columns(line, pos, line.len()).is_none_or(|rest| !rest.trim().is_empty());
    if failure.is_none() && !trailing_junk {
        return Ok(());
    }
    vals.truncate(before);
    // Blank-separated fallback.
    let words: Vec<&str> = line.split_whitespace().collect();
    if !words.is_empty() && words.len() <= remaining {
        let parsed: Option<Vec<f64>> = words.iter().map(|w| parse_fortran_real(w)).collect();
        if let Some(p) = parsed {
            vals.extend(p);
            return Ok(());
        }
    }
    let (col, detail) = match failure {
        Some((q, pos, w, text)) => (
            format!(
                "data value {} (columns {}-{})",
                start + q + 1,
                pos + 1,
                pos + w
            ),
            if text.trim().is_empty() {
                format!("blank where data value {} is expected", start + q + 1)
            } else {
                format!("`{}` is not a number", text.trim())
            },
        ),
        None => (
            format!("columns {}-", pos + 1),
            format!(
                "unexpected text after the {want} values this line should hold: `{}`",
                columns(line, pos, line.len()).unwrap_or("").trim()
            ),
        ),
    };
    Err(l.err(idx, Some(&col), FormatProblem::NotANumber, detail))
}

/// Parses the dataset 58 whose record 1 is at line index `s`; returns it and the index
/// of its closing delimiter.
fn parse_dataset58(
    l: &Lines<'_>,
    s: usize,
    open_idx: usize,
    binary: bool,
) -> Result<(Parsed58, usize), FrfError> {
    // Records 1-11 must all be there and none may be the closing delimiter.
    for r in 0..11 {
        if l.get(s + r).is_none() || l.is_delimiter(s + r) {
            let at = (s + r).min(l.lines.len().saturating_sub(1));
            return Err(l.err(
                at,
                None,
                FormatProblem::BadRecord,
                format!(
                    "dataset 58 opened at line {} ends before its record {} (the header \
                     has 11 records)",
                    l.no(open_idx),
                    r + 1
                ),
            ));
        }
    }
    let id1 = l.get(s).unwrap_or("").trim().to_string();
    let r6 = s + 5;
    // Record 6: 2(I5,I10),2(1X,10A1,I10,I4).
    let [func_type, _, _, _, rsp_node, rsp_dir, ref_node, ref_dir] = int_fields(
        l,
        r6,
        "record 6",
        [
            (0, 5, "function type"),
            (5, 15, "function identification number"),
            (15, 20, "version number"),
            (20, 30, "load case"),
            (41, 51, "response node"),
            (51, 55, "response direction"),
            (66, 76, "reference node"),
            (76, 80, "reference direction"),
        ],
        10,
        [0, 1, 2, 3, 5, 6, 8, 9],
    )?;
    if func_type != FUNCTION_FRF {
        let Some(close) = (s + 11..l.lines.len()).find(|&i| l.is_delimiter(i)) else {
            return Err(l.err(
                l.lines.len().saturating_sub(1),
                None,
                FormatProblem::BadRecord,
                format!(
                    "the file ends inside dataset 58 opened at line {} (no closing `-1`)",
                    l.no(open_idx)
                ),
            ));
        };
        let note = format!(
            "dataset 58 at line {}: function type {func_type} ({}), response {}:{}, \
             reference {}:{}",
            l.no(open_idx),
            function_type_name(func_type),
            rsp_node,
            direction_name(rsp_dir),
            ref_node,
            direction_name(ref_dir)
        );
        return Ok((Parsed58::Skipped(note), close));
    }
    // Record 7: 3I10,3E13.5.
    let r7 = s + 6;
    let line7 = l.get(r7).unwrap_or("");
    let [ordinate_type, n_points, spacing] = int_fields(
        l,
        r7,
        "record 7",
        [
            (0, 10, "ordinate data type"),
            (10, 20, "number of points"),
            (20, 30, "abscissa spacing"),
        ],
        6,
        [0, 1, 2],
    )?;
    let real_field = |q: usize, what: &str| -> Result<f64, FrfError> {
        let (a, b) = (30 + 13 * q, 43 + 13 * q);
        if let Some(x) = columns(line7, a, b).and_then(parse_fortran_real) {
            return Ok(x);
        }
        let words: Vec<&str> = line7.split_whitespace().collect();
        if words.len() == 6 {
            if let Some(x) = parse_fortran_real(words[3 + q]) {
                return Ok(x);
            }
        }
        let col = format!("record 7, {what} (columns {}-{b})", a + 1);
        Err(l.err(
            r7,
            Some(&col),
            FormatProblem::BadRecord,
            format!(
                "`{}` is not a number",
                columns(line7, a, b).unwrap_or(line7).trim()
            ),
        ))
    };
    let start = real_field(0, "abscissa start")?;
    let increment = real_field(1, "abscissa increment")?;
    let bad7 = |what: &str, detail: String| {
        let col = format!("record 7, {what}");
        l.err(r7, Some(&col), FormatProblem::BadRecord, detail)
    };
    if !matches!(ordinate_type, 2 | 4 | 5 | 6) {
        return Err(bad7(
            "ordinate data type (columns 1-10)",
            format!(
                "ordinate data type {ordinate_type} is not one of 2 (real single), 4 (real \
                 double), 5 (complex single), 6 (complex double)"
            ),
        ));
    }
    let even = match spacing {
        1 => true,
        0 => false,
        _ => {
            return Err(bad7(
                "abscissa spacing (columns 21-30)",
                format!("abscissa spacing {spacing} is neither 0 (uneven) nor 1 (even)"),
            ))
        }
    };
    if n_points <= 0 {
        return Err(bad7(
            "number of points (columns 11-20)",
            format!("the record announces {n_points} data points"),
        ));
    }
    if even && !(start.is_finite() && increment.is_finite() && increment > 0.0) {
        return Err(bad7(
            "abscissa start and increment (columns 31-56)",
            format!(
                "an even abscissa needs a finite start and a positive increment, not {start} \
                 and {increment}"
            ),
        ));
    }
    let n = n_points as usize;
    let complex = matches!(ordinate_type, 5 | 6);
    let per_point = usize::from(complex) + 1 + usize::from(!even);
    let Some(n_values) = n.checked_mul(per_point) else {
        return Err(bad7(
            "number of points (columns 11-20)",
            format!("{n_points} points is too many"),
        ));
    };
    let abscissa = axis_info(l, s + 7, "record 8")?;
    let numerator = axis_info(l, s + 8, "record 9")?;
    let denominator = axis_info(l, s + 9, "record 10")?;
    axis_info(l, s + 10, "record 11")?;

    // Record 12.
    let (widths, per_line) = data_layout(ordinate_type, even);
    let data_start = s + 11;
    let available = l.lines.len().saturating_sub(data_start);
    let mut vals: Vec<f64> = Vec::with_capacity(n_values.min(available.saturating_mul(6)));
    let mut line_of_value: Vec<usize> = Vec::new();
    let mut idx = data_start;
    if binary {
        // Record 12 was decoded when the file was split in lines (see `uff_binary`).
        let Some(b) = l.binary.get(&data_start) else {
            return Err(l.err(
                data_start.min(l.lines.len().saturating_sub(1)),
                Some("record 12 (binary data)"),
                FormatProblem::BadRecord,
                format!(
                    "binary dataset 58 opened at line {}: no binary data after its 11 header \
                     records",
                    l.no(open_idx)
                ),
            ));
        };
        if b.values.len() != n_values {
            return Err(l.err(
                data_start,
                Some("record 12 (binary data)"),
                FormatProblem::BadRecord,
                format!(
                    "binary dataset 58 opened at line {}: {} values, record 7 (line {}) \
                     announces {n_values}",
                    l.no(open_idx),
                    b.values.len(),
                    l.no(r7)
                ),
            ));
        }
        vals.clone_from(&b.values);
        line_of_value = vec![data_start; n_values];
        idx = data_start + 1;
    }
    while vals.len() < n_values {
        let Some(line) = l.get(idx) else {
            return Err(l.err(
                idx - 1,
                None,
                FormatProblem::BadRecord,
                format!(
                    "the file ends inside the data of dataset 58 opened at line {}: {} of the \
                     {n_values} values announced in record 7 (line {}) were read",
                    l.no(open_idx),
                    vals.len(),
                    l.no(r7)
                ),
            ));
        };
        if line.trim() == "-1" {
            return Err(l.err(
                idx,
                None,
                FormatProblem::BadRecord,
                format!(
                    "dataset 58 ends after {} of the {n_values} data values announced in \
                     record 7 (line {}: {n_points} points, ordinate type {ordinate_type}, {})",
                    vals.len(),
                    l.no(r7),
                    if even { "even" } else { "uneven" }
                ),
            ));
        }
        if line.trim().is_empty() {
            idx += 1;
            continue;
        }
        let before = vals.len();
        let remaining = n_values - before;
        read_data_line(
            l,
            idx,
            widths,
            before,
            per_line.min(remaining),
            remaining,
            &mut vals,
        )?;
        line_of_value.resize(vals.len(), idx);
        idx += 1;
    }
    // Only blank lines may follow, up to the closing delimiter.
    loop {
        match l.get(idx) {
            None => {
                return Err(l.err(
                    idx - 1,
                    None,
                    FormatProblem::BadRecord,
                    format!(
                        "the file ends inside dataset 58 opened at line {} (no closing `-1`)",
                        l.no(open_idx)
                    ),
                ))
            }
            Some(t) if t.trim() == "-1" => break,
            Some(t) if t.trim().is_empty() => idx += 1,
            Some(_) => {
                return Err(l.err(
                    idx,
                    None,
                    FormatProblem::BadRecord,
                    format!(
                        "more data than the {n_points} points record 7 (line {}) announces",
                        l.no(r7)
                    ),
                ))
            }
        }
    }
    let close = idx;

    // Split into abscissa and ordinate.
    let mut freq_hz = Vec::with_capacity(n);
    let mut values = Vec::with_capacity(n);
    for p in 0..n {
        let v = &vals[p * per_point..(p + 1) * per_point];
        let (x, y) = if even {
            (start + p as f64 * increment, v)
        } else {
            (v[0], &v[1..])
        };
        let z = if complex {
            C64::new(y[0], y[1])
        } else {
            C64::new(y[0], 0.0)
        };
        let at = if even {
            r7
        } else {
            line_of_value[p * per_point]
        };
        if !x.is_finite() || x < 0.0 {
            return Err(l.err(
                at,
                Some("abscissa"),
                FormatProblem::BadFrequency,
                format!("frequency {x} Hz of point {} is not finite and >= 0", p + 1),
            ));
        }
        if let Some(&prev) = freq_hz.last() {
            if x <= prev {
                return Err(l.err(
                    at,
                    Some("abscissa"),
                    FormatProblem::NotIncreasing,
                    format!(
                        "frequencies must increase strictly: point {} is at {x} Hz after {prev} Hz",
                        p + 1
                    ),
                ));
            }
        }
        freq_hz.push(x);
        values.push(z);
    }
    // Non-finite ordinates: reported here unless only the 0 Hz point has them (the
    // caller drops that point, a common export of hammer tests).
    for (p, z) in values.iter().enumerate() {
        if !(z.re.is_finite() && z.im.is_finite()) && freq_hz[p] != 0.0 {
            return Err(l.err(
                line_of_value[p * per_point],
                Some("ordinate"),
                FormatProblem::NonFinite,
                format!(
                    "point {} ({} Hz) has the non-finite value {z}",
                    p + 1,
                    freq_hz[p]
                ),
            ));
        }
    }
    Ok((
        Parsed58::Frf(Box::new(Record {
            header_idx: r6,
            r7_idx: r7,
            id1,
            response: (rsp_node, rsp_dir),
            reference: (ref_node, ref_dir),
            ordinate_type,
            even,
            binary,
            freq_hz,
            values,
            abscissa,
            numerator,
            denominator,
        })),
        close,
    ))
}

/// Human name of an ordinate data type code.
fn ordinate_name(code: i64) -> &'static str {
    match code {
        2 => "real single",
        4 => "real double",
        5 => "complex single",
        _ => "complex double",
    }
}

/// A usable units label (not blank, not `NONE`).
fn units_label(s: &str) -> Option<&str> {
    let t = s.trim();
    (!t.is_empty() && !t.eq_ignore_ascii_case("none")).then_some(t)
}

/// Parses the text of an ASCII UFF file and assembles its dataset-58 FRF records into
/// one `ny x nu` [`Frf`]; `name` stands for the file in errors and becomes
/// [`Frf::source`].
///
/// Rows are the response DOFs (node and direction) and columns the reference DOFs, each
/// **in order of first appearance** in the file (the exporter's channel order; node
/// numbers are often arbitrary labels). Every response/reference pair must appear
/// exactly once, and all records must share one frequency axis. The mapping is in the
/// metadata: `uff.outputs` and `uff.inputs` list `node:direction` per row and column
/// (for example `1:+Z 2:+Z`); `uff.records`, `uff.ordinate`, `uff.abscissa_spacing`,
/// `uff.encoding` (ASCII or binary), the data types `uff.abscissa`, `uff.numerator`,
/// `uff.denominator`, and `uff.id1`
/// (the first record's description line) describe the file. The abscissa is taken to be
/// in Hz; its axis and units labels, when set, are kept in `uff.abscissa_label` and
/// `uff.abscissa_units`. [`Frf::units`] is `numerator/denominator` from the units
/// labels of records 9 and 10 when they are set.
///
/// Other datasets (geometry, units, ...) and dataset 58 records of other function types
/// are skipped and listed in `uff.skipped`. A 0 Hz point whose values are not finite
/// (some exporters write NaN there) is dropped, noted in `uff.dropped`. Binary datasets
/// (`58b`) are read by [`parse_uff58_bytes`] (text cannot hold them).
///
/// Errors are [`FrfError::Format`] with the file, the line and the field: `Empty` for
/// an empty file, `NotFound` when no FRF record is there, `BadRecord` for malformed or
/// inconsistent records, `NotANumber`, `NonFinite`, `BadFrequency`, `NotIncreasing`
/// for bad data, and `MissingEntry` for a response/reference pair without a record.
pub fn parse_uff58(text: &str, name: &str) -> Result<Frf, FrfError> {
    parse_uff58_bytes(text.as_bytes(), name)
}

/// [`parse_uff58`] on the bytes of a file, which may hold binary datasets (`58b`, both
/// byte orders, single or double precision: see `uff_binary`); invalid UTF-8 in text
/// lines is replaced, so that it is reported where it matters.
pub fn parse_uff58_bytes(bytes: &[u8], name: &str) -> Result<Frf, FrfError> {
    let split = split_lines(bytes, name)?;
    let l = Lines {
        file: name,
        lines: split.lines,
        line_no: split.line_no,
        binary: split.binary,
    };
    let mut records: Vec<Record> = Vec::new();
    let mut skipped: Vec<String> = Vec::new();
    let mut i = 0;
    let mut any_content = false;
    while i < l.lines.len() {
        let t = l.lines[i].trim();
        if t.is_empty() {
            i += 1;
            continue;
        }
        any_content = true;
        if t != "-1" {
            return Err(l.err(
                i,
                None,
                FormatProblem::BadRecord,
                format!(
                    "expected a dataset delimiter `-1`, found `{}` (is this a UFF file?)",
                    t.chars().take(40).collect::<String>()
                ),
            ));
        }
        let open = i;
        let Some(number_line) = l.get(i + 1) else {
            return Err(l.err(
                i,
                None,
                FormatProblem::BadRecord,
                "the file ends after a dataset delimiter `-1`".into(),
            ));
        };
        let word = number_line.split_whitespace().next().unwrap_or("");
        let digits: String = word.chars().take_while(char::is_ascii_digit).collect();
        let binary = is_binary_number_line(number_line);
        let Ok(number) = digits.parse::<u32>() else {
            return Err(l.err(
                i + 1,
                Some("dataset number"),
                FormatProblem::BadRecord,
                format!("`{}` is not a dataset number", number_line.trim()),
            ));
        };
        if number == 58 {
            let (parsed, close) = parse_dataset58(&l, i + 2, open, binary)?;
            match parsed {
                Parsed58::Frf(r) => records.push(*r),
                Parsed58::Skipped(note) => skipped.push(note),
            }
            i = close + 1;
        } else {
            let Some(close) = (i + 2..l.lines.len()).find(|&k| l.is_delimiter(k)) else {
                return Err(l.err(
                    l.lines.len().saturating_sub(1),
                    None,
                    FormatProblem::BadRecord,
                    format!(
                        "the file ends inside dataset {number} opened at line {} (no closing `-1`)",
                        l.no(open)
                    ),
                ));
            };
            skipped.push(format!("dataset {number} at line {}", l.no(open)));
            i = close + 1;
        }
    }
    if !any_content {
        return Err(FrfError::format(
            name,
            0,
            None,
            FormatProblem::Empty,
            "the file is empty",
        ));
    }
    if records.is_empty() {
        let what = if skipped.is_empty() {
            String::new()
        } else {
            format!(" (skipped: {})", skipped.join("; "))
        };
        return Err(FrfError::format(
            name,
            0,
            None,
            FormatProblem::NotFound,
            format!("no dataset 58 with function type 4 (FRF) in the file{what}"),
        ));
    }
    assemble(&l, records, skipped)
}

/// Assembles the records into one [`Frf`] (see [`parse_uff58`]).
fn assemble(l: &Lines<'_>, records: Vec<Record>, skipped: Vec<String>) -> Result<Frf, FrfError> {
    let mut outputs: Vec<Dof> = Vec::new();
    let mut inputs: Vec<Dof> = Vec::new();
    for r in &records {
        if !outputs.contains(&r.response) {
            outputs.push(r.response);
        }
        if !inputs.contains(&r.reference) {
            inputs.push(r.reference);
        }
    }
    let (ny, nu) = (outputs.len(), inputs.len());
    let first = &records[0];
    let n = first.freq_hz.len();
    let mut slot: Vec<Option<usize>> = vec![None; ny * nu];
    let dof = |d: Dof| format!("{}:{}", d.0, direction_name(d.1));
    for (q, r) in records.iter().enumerate() {
        let i = outputs.iter().position(|&d| d == r.response).unwrap_or(0);
        let j = inputs.iter().position(|&d| d == r.reference).unwrap_or(0);
        if let Some(prev) = slot[j * ny + i] {
            return Err(l.err(
                r.header_idx,
                Some("record 6, response and reference node/direction"),
                FormatProblem::BadRecord,
                format!(
                    "a second FRF for response {} / reference {} (the first is the dataset \
                     whose record 6 is line {})",
                    dof(r.response),
                    dof(r.reference),
                    l.no(records[prev].header_idx)
                ),
            ));
        }
        slot[j * ny + i] = Some(q);
        let same_axis = r.freq_hz.len() == n
            && r.freq_hz
                .iter()
                .zip(&first.freq_hz)
                .all(|(&a, &b)| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()));
        if !same_axis {
            let span = |f: &[f64]| match (f.first(), f.last()) {
                (Some(a), Some(b)) => format!("{} points from {a} to {b} Hz", f.len()),
                _ => "no points".into(),
            };
            return Err(l.err(
                r.r7_idx,
                Some("record 7 / abscissa"),
                FormatProblem::BadRecord,
                format!(
                    "this record's frequency axis ({}) differs from the first FRF record's \
                     (line {}: {}); all records must share one axis",
                    span(&r.freq_hz),
                    l.no(first.r7_idx),
                    span(&first.freq_hz)
                ),
            ));
        }
    }
    for j in 0..nu {
        for i in 0..ny {
            if slot[j * ny + i].is_none() {
                let col = format!(
                    "response {} / reference {}",
                    dof(outputs[i]),
                    dof(inputs[j])
                );
                return Err(FrfError::format(
                    l.file,
                    0,
                    Some(&col),
                    FormatProblem::MissingEntry,
                    format!(
                        "no FRF record for response {} (output {}) and reference {} (input \
                         {}); the file has {} responses and {} references, so {} records are \
                         needed, found {}",
                        dof(outputs[i]),
                        i + 1,
                        dof(inputs[j]),
                        j + 1,
                        ny,
                        nu,
                        ny * nu,
                        records.len()
                    ),
                ));
            }
        }
    }
    // Drop a 0 Hz point with non-finite values (the parser let only that one through).
    let m = ny * nu;
    let drop_dc = first.freq_hz[0] == 0.0
        && records
            .iter()
            .any(|r| !(r.values[0].re.is_finite() && r.values[0].im.is_finite()));
    let k0 = usize::from(drop_dc);
    if drop_dc && n == 1 {
        return Err(l.err(
            first.r7_idx,
            Some("ordinate"),
            FormatProblem::NonFinite,
            "the only point (0 Hz) has non-finite values".into(),
        ));
    }
    let freq_hz = first.freq_hz[k0..].to_vec();
    let mut values = vec![C64::new(0.0, 0.0); (n - k0) * m];
    for (e, s) in slot.iter().enumerate() {
        let r = &records[s.unwrap_or(0)];
        for k in k0..n {
            values[(k - k0) * m + e] = r.values[k];
        }
    }
    let mut frf = Frf::new(freq_hz, ny, nu, values, None)?;
    let mut md = BTreeMap::new();
    let list = |d: &[Dof]| d.iter().map(|&x| dof(x)).collect::<Vec<_>>().join(" ");
    md.insert("uff.outputs".to_string(), list(&outputs));
    md.insert("uff.inputs".to_string(), list(&inputs));
    md.insert("uff.records".to_string(), records.len().to_string());
    let ordinate = if records
        .iter()
        .all(|r| r.ordinate_type == first.ordinate_type)
    {
        ordinate_name(first.ordinate_type).to_string()
    } else {
        "mixed".to_string()
    };
    md.insert("uff.ordinate".to_string(), ordinate);
    let spacing = if records.iter().all(|r| r.even == first.even) {
        if first.even {
            "even"
        } else {
            "uneven"
        }
    } else {
        "mixed"
    };
    md.insert("uff.abscissa_spacing".to_string(), spacing.to_string());
    let encoding = if records.iter().all(|r| r.binary == first.binary) {
        if first.binary {
            "binary (58b)"
        } else {
            "ASCII"
        }
    } else {
        "mixed ASCII and binary"
    };
    md.insert("uff.encoding".to_string(), encoding.to_string());
    md.insert(
        "uff.abscissa".to_string(),
        data_type_name(first.abscissa.data_type).to_string(),
    );
    md.insert(
        "uff.numerator".to_string(),
        data_type_name(first.numerator.data_type).to_string(),
    );
    md.insert(
        "uff.denominator".to_string(),
        data_type_name(first.denominator.data_type).to_string(),
    );
    if units_label(&first.id1).is_some() {
        md.insert("uff.id1".to_string(), first.id1.clone());
    }
    if let Some(lab) = units_label(&first.abscissa.label) {
        md.insert("uff.abscissa_label".to_string(), lab.to_string());
    }
    if let Some(lab) = units_label(&first.abscissa.units) {
        md.insert("uff.abscissa_units".to_string(), lab.to_string());
    }
    if !skipped.is_empty() {
        md.insert("uff.skipped".to_string(), skipped.join("; "));
    }
    if drop_dc {
        md.insert(
            "uff.dropped".to_string(),
            "the 0 Hz point: it has non-finite values".to_string(),
        );
    }
    frf.units = match (
        units_label(&first.numerator.units),
        units_label(&first.denominator.units),
    ) {
        (Some(a), Some(b)) => Some(format!("{a}/{b}")),
        (Some(a), None) => Some(a.to_string()),
        (None, Some(b)) => Some(format!("1/{b}")),
        (None, None) => None,
    };
    if let Some(u) = &frf.units {
        md.insert("units".to_string(), u.clone());
    }
    frf.metadata = md;
    frf.source = Some(l.file.to_string());
    Ok(frf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fortran_reals() {
        assert_eq!(parse_fortran_real("  2.50000e-01"), Some(0.25));
        assert_eq!(parse_fortran_real("-1.5D+03"), Some(-1500.0));
        assert_eq!(parse_fortran_real("1.5d3"), Some(1500.0));
        assert_eq!(parse_fortran_real(" 1.5-100"), Some(1.5e-100));
        assert_eq!(parse_fortran_real("-1.5+100"), Some(-1.5e100));
        assert_eq!(parse_fortran_real("  0.12345E+02"), Some(12.345));
        assert_eq!(parse_fortran_real("   "), None);
        assert_eq!(parse_fortran_real("1.0.0"), None);
        assert_eq!(parse_fortran_real("abc"), None);
        assert!(parse_fortran_real("nan").is_some_and(f64::is_nan));
    }

    #[test]
    fn fixed_columns() {
        assert_eq!(columns("abcdef", 2, 4), Some("cd"));
        assert_eq!(columns("abcdef", 4, 10), Some("ef"));
        assert_eq!(columns("abc", 5, 10), Some(""));
        assert_eq!(columns("aé", 1, 2), None);
        assert_eq!(parse_fortran_int("    "), Some(0));
        assert_eq!(parse_fortran_int("  -3"), Some(-3));
        assert_eq!(parse_fortran_int(" 3x"), None);
    }

    #[test]
    fn direction_names() {
        assert_eq!(direction_name(3), "+Z");
        assert_eq!(direction_name(-4), "-RX");
        assert_eq!(direction_name(0), "S");
        assert_eq!(direction_name(9), "dir9");
    }

    #[test]
    fn layouts() {
        assert_eq!(data_layout(5, false), (&[13usize][..], 6));
        assert_eq!(data_layout(2, true), (&[13usize][..], 6));
        assert_eq!(data_layout(6, true), (&[20usize][..], 4));
        assert_eq!(data_layout(4, false), (&[13usize, 20][..], 4));
        assert_eq!(data_layout(6, false), (&[13usize, 20, 20][..], 3));
    }
}
