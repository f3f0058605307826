//! Binary UFF datasets (`58b`, what Simcenter Test.Lab and other modal software export
//! by default): the line splitting of a UFF file that takes the binary data out.
//!
//! A binary dataset 58 differs from the ASCII one in two places. The dataset number
//! line is a header of its own, `FORMAT(I6,1A1,I6,I6,I12,I12,I6,I6,I12,I12)`:
//!
//! | columns | field |
//! |---|---|
//! | 1-6 | 58 |
//! | 7 | `b` |
//! | 8-13 | byte order: 1 little endian, 2 big endian |
//! | 14-19 | floating-point format: 2 IEEE 754 (1 DEC VMS and 3 IBM 370 are refused) |
//! | 20-31 | number of ASCII lines that follow (11: records 1-11) |
//! | 32-43 | number of bytes of binary data after them |
//!
//! and record 12 is raw binary: 4-byte IEEE floats for the single-precision ordinate
//! types (2, 5), 8-byte doubles for the double ones (4, 6), in the order of the ASCII
//! layout (`x, y` or `x, re, im` per point with uneven abscissa, in the ordinate's
//! precision). The closing `-1` follows the data directly or after a line break.
//!
//! The size of the data is taken from record 7 (points, ordinate type, spacing), not
//! from the byte count of the header: some writers put the number of points times 8
//! there for complex data. [`split_lines`] turns the file into lines for the ASCII
//! parser, replacing each binary block by one line [`BINARY_MARKER`] whose decoded values
//! are in [`UffLines::binary`]; every line keeps the number it has in the file.

use crate::{FormatProblem, FrfError};
use std::borrow::Cow;
use std::collections::HashMap;

/// The line that stands for a binary block (it is neither blank nor a delimiter).
pub(crate) const BINARY_MARKER: &str = "<binary data>";

/// The decoded record 12 of a binary dataset 58.
#[derive(Debug, Clone)]
pub(crate) struct BinaryData {
    /// All values of record 12, in file order, as `f64`.
    pub values: Vec<f64>,
}

/// The lines of a UFF file with its binary blocks taken out.
pub(crate) struct UffLines<'a> {
    /// The text lines (without line ends); a binary block is one [`BINARY_MARKER`].
    pub lines: Vec<Cow<'a, str>>,
    /// 1-based line number in the file of each entry of `lines`.
    pub line_no: Vec<usize>,
    /// Decoded binary blocks by the index of their marker line.
    pub binary: HashMap<usize, BinaryData>,
}

/// True when a dataset-number line marks a binary dataset (`58b`: a `b` right after the
/// number, or in column 7).
pub(crate) fn is_binary_number_line(line: &str) -> bool {
    let word = line.split_whitespace().next().unwrap_or("");
    let digits = word.bytes().take_while(u8::is_ascii_digit).count();
    (digits > 0 && word[digits..].eq_ignore_ascii_case("b"))
        || line
            .as_bytes()
            .get(6)
            .is_some_and(|b| b.eq_ignore_ascii_case(&b'b'))
}

/// Integer at 0-based byte columns `a..b`, or the `word`-th blank-separated word.
fn int_at(line: &str, a: usize, b: usize, word: usize) -> Option<i64> {
    let fixed = line
        .get(a.min(line.len())..b.min(line.len()))
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .and_then(|t| t.parse().ok());
    fixed.or_else(|| line.split_whitespace().nth(word)?.parse().ok())
}

/// The binary dataset header fields: (dataset number, little endian, ascii lines, bytes).
fn binary_header(
    file: &str,
    line_no: usize,
    line: &str,
) -> Result<(i64, bool, usize, usize), FrfError> {
    let err = |column: &str, detail: String| {
        FrfError::format(
            file,
            line_no,
            Some(column),
            FormatProblem::BadRecord,
            detail,
        )
    };
    // The blank-separated words when column 7 is not the `b`: "58b 1 2 11 N ...".
    let words: Vec<&str> = line.split_whitespace().collect();
    let fixed = line
        .as_bytes()
        .get(6)
        .is_some_and(|b| b.eq_ignore_ascii_case(&b'b'));
    let field = |a: usize, b: usize, w: usize| -> Option<i64> {
        if fixed {
            int_at(line, a, b, usize::MAX)
        } else {
            words.get(w)?.parse().ok()
        }
    };
    let number = words
        .first()
        .map(|w| w.trim_end_matches(['b', 'B']))
        .and_then(|w| w.parse::<i64>().ok())
        .ok_or_else(|| {
            err(
                "dataset number",
                format!("`{}` is not a dataset number", line.trim()),
            )
        })?;
    let order = field(7, 13, 1).ok_or_else(|| {
        err(
            "byte order (columns 8-13)",
            "binary dataset header: the byte order is not an integer".into(),
        )
    })?;
    let little = match order {
        1 => true,
        2 => false,
        o => {
            return Err(err(
                "byte order (columns 8-13)",
                format!("byte order {o} is neither 1 (little endian) nor 2 (big endian)"),
            ))
        }
    };
    let fp = field(13, 19, 2).ok_or_else(|| {
        err(
            "floating-point format (columns 14-19)",
            "binary dataset header: the floating-point format is not an integer".into(),
        )
    })?;
    if fp != 2 {
        return Err(err(
            "floating-point format (columns 14-19)",
            format!(
                "floating-point format {fp} is not supported: only 2 (IEEE 754) is; 1 is DEC \
                 VMS, 3 IBM 370"
            ),
        ));
    }
    let ascii = field(19, 31, 3)
        .filter(|&n| (0..=1000).contains(&n))
        .ok_or_else(|| {
            err(
                "number of ASCII lines (columns 20-31)",
                "binary dataset header: the number of ASCII lines is not an integer in 0..1000"
                    .into(),
            )
        })?;
    let bytes = field(31, 43, 4).filter(|&n| n >= 0).ok_or_else(|| {
        err(
            "number of bytes (columns 32-43)",
            "binary dataset header: the number of bytes is not a non-negative integer".into(),
        )
    })?;
    Ok((number, little, ascii as usize, bytes as usize))
}

/// The byte size and value width of record 12 of a binary dataset 58 from its record 7.
fn data_size(file: &str, line_no: usize, r7: &str) -> Result<(usize, usize), FrfError> {
    let err = |column: &str, detail: String| {
        FrfError::format(
            file,
            line_no,
            Some(column),
            FormatProblem::BadRecord,
            detail,
        )
    };
    let (Some(ord), Some(n), Some(spacing)) = (
        int_at(r7, 0, 10, 0),
        int_at(r7, 10, 20, 1),
        int_at(r7, 20, 30, 2),
    ) else {
        return Err(err(
            "record 7",
            "record 7 of a binary dataset 58 needs the ordinate data type, the number of \
             points and the abscissa spacing as integers"
                .into(),
        ));
    };
    let width = match ord {
        2 | 5 => 4,
        4 | 6 => 8,
        _ => {
            return Err(err(
                "record 7, ordinate data type (columns 1-10)",
                format!(
                    "ordinate data type {ord} is not one of 2 (real single), 4 (real double), 5 \
                     (complex single), 6 (complex double)"
                ),
            ))
        }
    };
    let per_point = 1 + usize::from(matches!(ord, 5 | 6)) + usize::from(spacing == 0);
    let bytes = usize::try_from(n)
        .ok()
        .filter(|&n| n > 0)
        .and_then(|n| n.checked_mul(per_point * width))
        .ok_or_else(|| {
            err(
                "record 7, number of points (columns 11-20)",
                format!("the record announces {n} data points"),
            )
        })?;
    Ok((bytes, width))
}

fn decode(data: &[u8], width: usize, little: bool) -> Vec<f64> {
    if width == 4 {
        data.chunks_exact(4)
            .map(|c| {
                let b = [c[0], c[1], c[2], c[3]];
                f64::from(if little {
                    f32::from_le_bytes(b)
                } else {
                    f32::from_be_bytes(b)
                })
            })
            .collect()
    } else {
        data.chunks_exact(8)
            .map(|c| {
                let b = [c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]];
                if little {
                    f64::from_le_bytes(b)
                } else {
                    f64::from_be_bytes(b)
                }
            })
            .collect()
    }
}

/// Splits the bytes of a UFF file into lines (see the module docs); a UTF-8 byte-order
/// mark is dropped, invalid UTF-8 in text lines is replaced. Errors name the file and
/// the line: a binary dataset header that does not parse, a foreign floating-point
/// format, binary data cut short by the end of the file.
pub(crate) fn split_lines<'a>(bytes: &'a [u8], file: &str) -> Result<UffLines<'a>, FrfError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut out = UffLines {
        lines: Vec::new(),
        line_no: Vec::new(),
        binary: HashMap::new(),
    };
    let mut pos = 0;
    let mut line_no = 1;
    // Reads one text line at `pos`.
    let next_line = |pos: &mut usize| -> Cow<'a, str> {
        let end = bytes[*pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |k| *pos + k);
        let raw = &bytes[*pos..end];
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        *pos = (end + 1).min(bytes.len());
        String::from_utf8_lossy(raw)
    };
    let mut prev_delimiter = false;
    while pos < bytes.len() {
        let line = next_line(&mut pos);
        let this_no = line_no;
        line_no += 1;
        let binary = prev_delimiter && is_binary_number_line(&line);
        prev_delimiter = line.trim() == "-1";
        if !binary {
            out.lines.push(line);
            out.line_no.push(this_no);
            continue;
        }
        let (number, little, n_ascii, n_bytes) = binary_header(file, this_no, &line)?;
        out.lines.push(line);
        out.line_no.push(this_no);
        let first_ascii = out.lines.len();
        for _ in 0..n_ascii {
            if pos >= bytes.len() {
                return Err(FrfError::format(
                    file,
                    line_no.saturating_sub(1),
                    None,
                    FormatProblem::BadRecord,
                    format!(
                        "binary dataset {number} (line {this_no}) announces {n_ascii} ASCII \
                         lines; the file ends before them"
                    ),
                ));
            }
            out.lines.push(next_line(&mut pos));
            out.line_no.push(line_no);
            line_no += 1;
        }
        let (size, width) = if number == 58 {
            let r7 = first_ascii + 6;
            let Some(text) = out.lines.get(r7) else {
                return Err(FrfError::format(
                    file,
                    this_no,
                    None,
                    FormatProblem::BadRecord,
                    format!("binary dataset 58 announces {n_ascii} ASCII lines; it needs 11"),
                ));
            };
            data_size(file, out.line_no[r7], text)?
        } else {
            (n_bytes, 1)
        };
        if bytes.len() - pos < size {
            return Err(FrfError::format(
                file,
                line_no,
                Some("record 12 (binary data)"),
                FormatProblem::BadRecord,
                format!(
                    "binary dataset {number} (line {this_no}) needs {size} bytes of data after \
                     its ASCII lines; the file ends after {}",
                    bytes.len() - pos
                ),
            ));
        }
        let data = &bytes[pos..pos + size];
        pos += size;
        let marker = out.lines.len();
        out.lines.push(Cow::Borrowed(BINARY_MARKER));
        out.line_no.push(line_no);
        line_no += data.iter().filter(|&&b| b == b'\n').count();
        if number == 58 {
            out.binary.insert(
                marker,
                BinaryData {
                    values: decode(data, width, little),
                },
            );
        }
        // The rest of the line the data end on (usually nothing or the delimiter) is
        // read as a line of its own, unless the data end exactly at a line break.
        if bytes.get(pos) == Some(&b'\n') {
            pos += 1;
            line_no += 1;
        } else if bytes.get(pos..pos + 2) == Some(&b"\r\n"[..]) {
            pos += 2;
            line_no += 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_binary_number_lines() {
        assert!(is_binary_number_line(
            "    58b     1     2          11        64     0     0           0           0"
        ));
        assert!(is_binary_number_line("58b 1 2 11 64 0 0 0 0"));
        assert!(!is_binary_number_line("    58"));
        assert!(!is_binary_number_line("   151"));
    }

    #[test]
    fn header_fields() {
        let (n, little, a, b) = binary_header(
            "f",
            2,
            "    58b     2     2          11        64     0     0           0           0",
        )
        .unwrap();
        assert_eq!((n, little, a, b), (58, false, 11, 64));
        let (n, little, a, b) = binary_header("f", 2, "58b 1 2 11 64 0 0 0 0").unwrap();
        assert_eq!((n, little, a, b), (58, true, 11, 64));
        let e = binary_header("f", 2, "    58b     1     1          11        64").unwrap_err();
        assert!(e.to_string().contains("DEC VMS"), "{e}");
        let e = binary_header("f", 2, "    58b     3     2          11        64").unwrap_err();
        assert!(e.to_string().contains("byte order 3"), "{e}");
    }

    #[test]
    fn text_lines_are_split_like_text() {
        let u = split_lines(b"a\r\nb\n\nc\n", "f").unwrap();
        let l: Vec<&str> = u.lines.iter().map(|c| c.as_ref()).collect();
        assert_eq!(l, ["a", "b", "", "c"]);
        assert_eq!(u.line_no, [1, 2, 3, 4]);
    }
}
