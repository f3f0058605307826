//! FRF CSV as spreadsheets and MATLAB write it: every variant is made from a plain CSV
//! in the test and must read the very same numbers (bit for bit).

use frf_data::io::{frf_csv_string, parse_frf_csv, read_frf_csv};
use frf_data::shared_data::require;
use frf_data::{FormatProblem, Frf, FrfDataset, FrfError, C64};

/// A 2 x 2 FRF with awkward numbers (tiny, huge, negative, many digits) and variances.
fn sample() -> Frf {
    let freqs = vec![0.125, 1.0 / 3.0, 2.5, 1999.75, 12345.678901234567];
    let m = 4;
    let vals: Vec<C64> = (0..freqs.len() * m)
        .map(|q| {
            let x = (q as f64 + 0.7).sin();
            C64::new(x * 10f64.powi(q as i32 % 7 - 4), -x.cos() * 1e-9 / 7.0)
        })
        .collect();
    let var: Vec<f64> = (0..freqs.len() * m)
        .map(|q| (q as f64 + 1.0).powi(3) * 1.0e-17)
        .collect();
    let mut f = Frf::new(freqs, 2, 2, vals, Some(var)).unwrap();
    f.units = Some("m/N".into());
    f
}

fn plain() -> String {
    frf_csv_string(&sample(), &["written by the test".to_string()])
}

/// Applies `f` to every non-comment line's fields (split at `,`), joining with `sep`.
fn map_fields(text: &str, sep: &str, f: impl Fn(usize, &str) -> String) -> String {
    text.lines()
        .map(|l| {
            if l.starts_with('#') {
                l.to_string()
            } else {
                l.split(',')
                    .enumerate()
                    .map(|(c, x)| f(c, x))
                    .collect::<Vec<_>>()
                    .join(sep)
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

fn is_header(x: &str) -> bool {
    x.starts_with('G') || x == "freq_hz"
}

/// `x` with 17 significant digits in the C `printf("%.16e")` form (`1.2345e+03`).
fn c_printf(x: f64) -> String {
    let s = format!("{x:.16e}");
    let (m, e) = s.split_once('e').unwrap();
    let e: i32 = e.parse().unwrap();
    format!("{m}e{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
}

#[track_caller]
fn assert_same(variant: &str, text: &str, dialect_has: &[&str]) {
    let want = parse_frf_csv(&plain(), "plain.csv").unwrap();
    let got = parse_frf_csv(text, variant).unwrap_or_else(|e| panic!("{variant}: {e}"));
    assert_eq!(got.freq_hz_slice(), want.freq_hz_slice(), "{variant}");
    assert_eq!(got.values(), want.values(), "{variant}");
    assert_eq!(got.variances(), want.variances(), "{variant}");
    assert_eq!(got.units, want.units, "{variant}");
    let d = &got.metadata["csv.dialect"];
    for s in dialect_has {
        assert!(d.contains(s), "{variant}: dialect `{d}` should say {s}");
    }
}

#[test]
fn byte_order_mark_and_line_ends() {
    let p = plain();
    assert_same("bom", &format!("\u{feff}{p}"), &["byte-order mark"]);
    assert_same("crlf", &p.replace('\n', "\r\n"), &["CRLF"]);
    assert_same("cr", &p.replace('\n', "\r"), &["CR line"]);
    assert_same(
        "bom+crlf",
        &format!("\u{feff}{}", p.replace('\n', "\r\n")),
        &["CRLF", "byte-order mark"],
    );
    // The plain file says so too.
    assert_same("plain", &p, &["`,` separator", "`.` decimal", "LF"]);
}

#[test]
fn quoted_names_and_fields_and_blanks() {
    let p = plain();
    let quoted_header = map_fields(&p, ",", |_, x| {
        if is_header(x) {
            format!("\"{x}\"")
        } else {
            x.to_string()
        }
    });
    assert_same("quoted header", &quoted_header, &["quoted"]);
    let all_quoted = map_fields(&p, ",", |_, x| format!("\"{x}\""));
    assert_same("all quoted", &all_quoted, &["quoted"]);
    let spaces = map_fields(&p, ",", |c, x| {
        if c % 2 == 0 {
            format!("  {x} ")
        } else {
            format!("\t{x}")
        }
    });
    assert_same("blanks", &spaces, &["`,` separator"]);
    let quoted_spaced = map_fields(&p, " , ", |_, x| format!(" \" {x} \" "));
    assert_same("quoted with blanks", &quoted_spaced, &["quoted"]);
}

#[test]
fn semicolons_with_decimal_commas() {
    let p = plain();
    // A spreadsheet in a comma-decimal locale: `;` separators, `,` decimals, quoted
    // header, CRLF, BOM.
    let excel = map_fields(&p, ";", |_, x| {
        if is_header(x) {
            format!("\"{x}\"")
        } else {
            x.replace('.', ",")
        }
    });
    let excel = format!("\u{feff}{}", excel.replace('\n', "\r\n"));
    assert_same(
        "excel-de",
        &excel,
        &[
            "`;` separator",
            "`,` decimal",
            "CRLF",
            "quoted",
            "byte-order mark",
        ],
    );
    let tabs = map_fields(&p, "\t", |_, x| x.replace('.', ","));
    assert_same("tabs", &tabs, &["tab separator", "`,` decimal"]);
    // `;` with `.` decimals.
    let semis = map_fields(&p, ";", |_, x| x.to_string());
    assert_same("semicolons", &semis, &["`;` separator", "`.` decimal"]);
    // Comma-separated with quoted decimal-comma numbers.
    let quoted_commas = map_fields(&p, ",", |_, x| {
        if is_header(x) {
            x.to_string()
        } else {
            format!("\"{}\"", x.replace('.', ","))
        }
    });
    // Every number has at most one `.`, so each quoted `,` is a decimal mark.
    assert_same("quoted decimal commas", &quoted_commas, &["quoted"]);
}

/// A way of printing a number.
type Format = fn(f64) -> String;

#[test]
fn every_form_of_scientific_notation() {
    let p = plain();
    let forms: [(&str, Format); 6] = [
        ("rust {:e}", |x| format!("{x:e}")),
        ("rust {:E}", |x| format!("{x:E}")),
        ("plain decimal", |x| format!("{x}")),
        ("C printf %.16e", c_printf),
        ("upper printf", |x| c_printf(x).to_uppercase()),
        ("Fortran D", |x| c_printf(x).replace('e', "D")),
    ];
    for (name, form) in forms {
        let text = map_fields(&p, ",", |_, x| {
            if is_header(x) {
                x.to_string()
            } else {
                form(x.parse::<f64>().unwrap())
            }
        });
        assert_same(name, &text, &[]);
    }
    // Hand-written forms of one number.
    for s in [
        "1500",
        "1.5e3",
        "1.5E3",
        "1.5e+3",
        "1.5E+03",
        "+1.5e+003",
        "15e2",
        ".15e4",
        "1500.",
        "1.5D3",
        "1.5d+03",
        "0.0015e6",
    ] {
        let t = format!("freq_hz,G1_1_re,G1_1_im\n1,{s},0\n");
        let f = parse_frf_csv(&t, "x").unwrap_or_else(|e| panic!("{s}: {e}"));
        assert_eq!(f.values()[0].re, 1500.0, "{s}");
    }
}

#[test]
fn inf_and_nan_are_refused_by_name() {
    for (s, word) in [
        ("NaN", "NaN"),
        ("nan", "NaN"),
        ("Inf", "infinite"),
        ("-Inf", "infinite"),
        ("inf", "infinite"),
        ("Infinity", "infinite"),
        ("1e999", "infinite"),
    ] {
        for sep in [",", ";"] {
            let t = format!("freq_hz{sep}G1_1_re{sep}G1_1_im\n1{sep}2{sep}0\n2{sep}{s}{sep}0\n");
            match parse_frf_csv(&t, "v.csv") {
                Err(FrfError::Format {
                    file,
                    line,
                    column,
                    problem,
                    detail,
                }) => {
                    assert_eq!(file, "v.csv");
                    assert_eq!(line, 3, "{s}");
                    assert_eq!(column.as_deref(), Some("G1_1_re"), "{s}");
                    assert_eq!(problem, FormatProblem::NonFinite, "{s}");
                    assert!(detail.contains(word), "{s}: {detail}");
                }
                other => panic!("{s}: {other:?}"),
            }
        }
    }
}

#[test]
fn unclosed_quotes_are_located() {
    let t = "freq_hz;G1_1_re;G1_1_im\n1;\"2,5;0\n";
    let e = parse_frf_csv(t, "q.csv").unwrap_err();
    assert!(
        matches!(&e, FrfError::Format { line: 2, column: Some(c), .. } if c == "field 2"),
        "{e:?}"
    );
}

#[test]
fn wafer_reference_in_a_spreadsheet_dialect_reads_the_same() {
    let Some(path) = require(
        "wafer_reference_in_a_spreadsheet_dialect_reads_the_same",
        "wafer_nominal.csv",
    ) else {
        return;
    };
    let plain = std::fs::read_to_string(&path).unwrap();
    let want = read_frf_csv(&path).unwrap();
    let excel = map_fields(&plain, ";", |_, x| {
        if is_header(x) {
            format!("\"{x}\"")
        } else {
            x.replace('.', ",")
        }
    })
    .replace('\n', "\r\n");
    let got = parse_frf_csv(&format!("\u{feff}{excel}"), "excel.csv").unwrap();
    assert_eq!(got.values(), want.values());
    assert_eq!(got.freq_hz_slice(), want.freq_hz_slice());
    assert_eq!(got.variances(), want.variances());
    assert_eq!((got.ny(), got.nu()), (4, 13));
}
