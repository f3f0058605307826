//! CSV dialects that spreadsheets and MATLAB write, brought to the plain FRF CSV of
//! `FORMATS.md` before parsing: a UTF-8 byte-order mark, CRLF (or old-Mac CR) line ends,
//! quoted fields, blanks around fields, and `;` or tab separators with `,` as the
//! decimal mark (what a spreadsheet writes in locales whose decimal mark is the comma).
//!
//! [`normalize`] detects the dialect from the header line and rewrites the text line by
//! line (the line numbers stay those of the file, so errors still point at the right
//! line); a plain file is passed through without a copy.

use crate::{FormatProblem, FrfError};
use std::borrow::Cow;
use std::fmt;

/// What a CSV file looked like (reported by `frfit info` as the metadata `csv.dialect`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CsvDialect {
    /// The field separator: `,`, `;` or a tab.
    pub separator: char,
    /// Numbers use `,` as the decimal mark (only with a `;` or tab separator, or inside
    /// quoted fields).
    pub decimal_comma: bool,
    /// The file starts with a UTF-8 byte-order mark.
    pub bom: bool,
    /// Line ends: `"LF"`, `"CRLF"` or `"CR"`.
    pub line_end: &'static str,
    /// Some fields are in double quotes.
    pub quoted: bool,
}

impl Default for CsvDialect {
    /// The plain FRF CSV: `,` separator, `.` decimal mark, LF, no BOM, no quotes.
    fn default() -> Self {
        CsvDialect {
            separator: ',',
            decimal_comma: false,
            bom: false,
            line_end: "LF",
            quoted: false,
        }
    }
}

impl fmt::Display for CsvDialect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sep = match self.separator {
            '\t' => "tab",
            ';' => "`;`",
            _ => "`,`",
        };
        write!(
            f,
            "{sep} separator, `{}` decimal mark, {} line ends",
            if self.decimal_comma { ',' } else { '.' },
            self.line_end
        )?;
        if self.quoted {
            f.write_str(", quoted fields")?;
        }
        if self.bom {
            f.write_str(", UTF-8 byte-order mark")?;
        }
        Ok(())
    }
}

fn is_comment_or_blank(line: &str) -> bool {
    let t = line.trim_start();
    t.is_empty() || t.starts_with('#')
}

/// Splits `line` at `sep` outside double quotes. A field's quotes are removed (a doubled
/// quote inside stands for one quote) and blanks around the field and inside the quotes
/// are dropped. `Err(field index)` when a quote is not closed.
fn split_fields(line: &str, sep: char) -> Result<Vec<(String, bool)>, usize> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut in_quotes = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        if in_quotes {
            if c == '"' {
                if chars.peek() == Some(&'"') {
                    cur.push('"');
                    chars.next();
                } else {
                    in_quotes = false;
                }
            } else {
                cur.push(c);
            }
        } else if c == sep {
            out.push((std::mem::take(&mut cur).trim().to_string(), quoted));
            quoted = false;
        } else if c == '"' && cur.trim().is_empty() {
            cur.clear();
            in_quotes = true;
            quoted = true;
        } else {
            cur.push(c);
        }
    }
    if in_quotes {
        return Err(out.len());
    }
    out.push((cur.trim().to_string(), quoted));
    Ok(out)
}

/// Counts `c` outside double quotes.
fn count_outside_quotes(line: &str, c: char) -> usize {
    let mut in_quotes = false;
    let mut n = 0;
    for ch in line.chars() {
        if ch == '"' {
            in_quotes = !in_quotes;
        } else if ch == c && !in_quotes {
            n += 1;
        }
    }
    n
}

/// Detects the dialect of FRF CSV `text` and returns the text in the plain dialect (same
/// lines, `,` separators, `.` decimal marks, no quotes, no BOM) with the dialect found.
///
/// The separator is the one of `,`, `;`, tab that occurs most often (outside quotes) in
/// the header line, the first line that is neither blank nor a `#` comment. With a `;`
/// or tab separator every `,` in a field is a decimal mark. With a `,` separator, a
/// quoted number with one `,` and no `.` (`"1,5"`) has a decimal comma.
///
/// Errors ([`FrfError::Format`] with the file, the line and the field): a quote that
/// is not closed on its line, a header name that holds a `,` (it could not be told from
/// two columns).
pub fn normalize<'a>(text: &'a str, name: &str) -> Result<(Cow<'a, str>, CsvDialect), FrfError> {
    let mut d = CsvDialect::default();
    let mut text = text;
    if let Some(t) = text.strip_prefix('\u{feff}') {
        d.bom = true;
        text = t;
    }
    let has_lf = text.contains('\n');
    let first_line_end = text.find('\n');
    if has_lf {
        if first_line_end.is_some_and(|i| i > 0 && text.as_bytes()[i - 1] == b'\r') {
            d.line_end = "CRLF";
        }
    } else if text.contains('\r') {
        d.line_end = "CR";
    }
    let split_char = if d.line_end == "CR" { '\r' } else { '\n' };
    let header = text
        .split(split_char)
        .map(|l| l.strip_suffix('\r').unwrap_or(l))
        .find(|l| !is_comment_or_blank(l));
    if let Some(h) = header {
        let counts = [',', ';', '\t'].map(|c| (count_outside_quotes(h, c), c));
        // The most frequent; `,` wins ties (the default).
        let best = counts.iter().fold(
            (0usize, ','),
            |acc, &(n, c)| if n > acc.0 { (n, c) } else { acc },
        );
        d.separator = best.1;
    }
    d.quoted = text.contains('"');
    if d.separator == ',' && !d.quoted && d.line_end != "CR" {
        return Ok((Cow::Borrowed(text), d));
    }
    let mut out = String::with_capacity(text.len() + 16);
    let mut seen_header = false;
    for (idx, raw) in text.split(split_char).enumerate() {
        if idx > 0 {
            out.push('\n');
        }
        let line = raw.strip_suffix('\r').unwrap_or(raw);
        if is_comment_or_blank(line) {
            out.push_str(line);
            continue;
        }
        let is_header = !seen_header;
        seen_header = true;
        let fields = split_fields(line, d.separator).map_err(|k| {
            let col = format!("field {}", k + 1);
            FrfError::format(
                name,
                idx + 1,
                Some(&col),
                if is_header {
                    FormatProblem::BadHeader
                } else {
                    FormatProblem::NotANumber
                },
                format!(
                    "field {} opens a double quote that is not closed on its line",
                    k + 1
                ),
            )
        })?;
        for (k, (field, quoted)) in fields.iter().enumerate() {
            if k > 0 {
                out.push(',');
            }
            if is_header {
                if field.contains(',') {
                    let col = format!("field {}", k + 1);
                    return Err(FrfError::format(
                        name,
                        idx + 1,
                        Some(&col),
                        FormatProblem::BadHeader,
                        format!("header name `{field}` holds a `,`"),
                    ));
                }
                out.push_str(field);
                continue;
            }
            let decimal_comma = if d.separator == ',' {
                *quoted && field.matches(',').count() == 1 && !field.contains('.')
            } else {
                field.contains(',')
            };
            if decimal_comma {
                d.decimal_comma = true;
                out.push_str(&field.replace(',', "."));
            } else {
                out.push_str(field);
            }
        }
    }
    Ok((Cow::Owned(out), d))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_with_quotes() {
        let f = split_fields(r#" "a" ; "b""c" ;d ; "x;y" "#, ';').unwrap();
        let names: Vec<&str> = f.iter().map(|(s, _)| s.as_str()).collect();
        assert_eq!(names, ["a", "b\"c", "d", "x;y"]);
        assert_eq!(
            f.iter().map(|(_, q)| *q).collect::<Vec<_>>(),
            [true, true, false, true]
        );
        assert_eq!(split_fields(r#"a,"b"#, ','), Err(1));
    }

    #[test]
    fn plain_text_is_not_copied() {
        let t = "# c\nfreq_hz,G1_1_re,G1_1_im\n1,2,3\n";
        let (n, d) = normalize(t, "m").unwrap();
        assert!(matches!(n, Cow::Borrowed(_)));
        assert_eq!(d, CsvDialect::default());
    }

    #[test]
    fn semicolon_decimal_comma() {
        let t = "\u{feff}# c; d\r\n\"freq_hz\";\"G1_1_re\";\"G1_1_im\"\r\n1,5;-2,5E-03;3\r\n";
        let (n, d) = normalize(t, "m").unwrap();
        assert_eq!(n, "# c; d\nfreq_hz,G1_1_re,G1_1_im\n1.5,-2.5E-03,3\n");
        assert_eq!(
            d,
            CsvDialect {
                separator: ';',
                decimal_comma: true,
                bom: true,
                line_end: "CRLF",
                quoted: true
            }
        );
        assert_eq!(
            d.to_string(),
            "`;` separator, `,` decimal mark, CRLF line ends, quoted fields, UTF-8 byte-order mark"
        );
    }

    #[test]
    fn unclosed_quote_is_located() {
        let e = normalize("freq_hz;G1_1_re;G1_1_im\n1;\"2;3\n", "f.csv").unwrap_err();
        assert!(
            matches!(&e, FrfError::Format { line: 2, column: Some(c), .. } if c == "field 2"),
            "{e}"
        );
    }
}
