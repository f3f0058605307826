//! UFF dataset 58 reader: the pyuff-written reference file against its CSV, every data
//! layout of record 12, skipping, and the errors.

use frf_data::io::{parse_uff58, read_frf, read_frf_csv, read_uff58};
use frf_data::shared_data::require;
use frf_data::{FormatProblem, FrfDataset, FrfError, C64};
use proptest::prelude::*;

/// One dataset 58 to write in tests.
#[derive(Clone)]
struct Rec {
    func: i64,
    rsp: (i64, i64),
    refr: (i64, i64),
    /// 2 real single, 4 real double, 5 complex single, 6 complex double.
    ord: i64,
    even: bool,
    freqs: Vec<f64>,
    vals: Vec<C64>,
}

impl Rec {
    fn frf(rsp: (i64, i64), refr: (i64, i64), ord: i64, even: bool, n: usize) -> Rec {
        let freqs: Vec<f64> = (0..n).map(|k| 0.5 + 0.25 * k as f64).collect();
        let vals = (0..n)
            .map(|k| {
                let s = (rsp.0 * 100 + refr.0) as f64;
                let im = if matches!(ord, 5 | 6) {
                    -(k as f64) - 0.5
                } else {
                    0.0
                };
                C64::new(s + k as f64 * 0.125, im)
            })
            .collect();
        Rec {
            func: 4,
            rsp,
            refr,
            ord,
            even,
            freqs,
            vals,
        }
    }
}

/// `x` as a right-aligned `E` field of width `w` with `d` decimals.
fn fe(x: f64, w: usize, d: usize) -> String {
    format!("{:>w$}", format!("{x:.d$E}"))
}

/// The text of one dataset 58 laid out as the UFF specification says.
fn record_text(r: &Rec) -> String {
    let n = r.freqs.len();
    let mut s = String::from("    -1\n    58\n");
    s.push_str(&format!("test record {}:{}\n", r.rsp.0, r.refr.0));
    for _ in 0..4 {
        s.push_str("NONE\n");
    }
    s.push_str(&format!(
        "{:5}{:10}{:5}{:10} {:>10}{:10}{:4} {:>10}{:10}{:4}\n",
        r.func, 0, 0, 0, "stage", r.rsp.0, r.rsp.1, "stage", r.refr.0, r.refr.1
    ));
    let (start, inc) = if r.even {
        (r.freqs[0], r.freqs[1] - r.freqs[0])
    } else {
        (0.0, 0.0)
    };
    s.push_str(&format!(
        "{:10}{:10}{:10}{}{}{}\n",
        r.ord,
        n,
        i32::from(r.even),
        fe(start, 13, 5),
        fe(inc, 13, 5),
        fe(0.0, 13, 5)
    ));
    for (t, lab, units) in [
        (18, "Frequency", "Hz"),
        (8, "Displacement", "m"),
        (13, "Force", "N"),
        (0, "NONE", "NONE"),
    ] {
        s.push_str(&format!(
            "{t:10}{:5}{:5}{:5} {lab:<20} {units:<20}\n",
            0, 0, 0
        ));
    }
    let complex = matches!(r.ord, 5 | 6);
    let mut stream = Vec::new();
    for k in 0..n {
        if !r.even {
            stream.push(r.freqs[k]);
        }
        stream.push(r.vals[k].re);
        if complex {
            stream.push(r.vals[k].im);
        }
    }
    let (widths, per_line): (&[usize], usize) = match (r.ord, r.even) {
        (2 | 5, _) => (&[13], 6),
        (_, true) => (&[20], 4),
        (4, false) => (&[13, 20], 4),
        _ => (&[13, 20, 20], 3),
    };
    for (c, chunk) in stream.chunks(per_line).enumerate() {
        for (q, &x) in chunk.iter().enumerate() {
            let w = widths[(c * per_line + q) % widths.len()];
            let d = if w == 13 { 5 } else { 12 };
            s.push_str(&fe(x, w, d));
        }
        s.push('\n');
    }
    s.push_str("    -1\n");
    s
}

fn file_text(recs: &[Rec]) -> String {
    recs.iter().map(record_text).collect()
}

/// Asserts that `text` fails with `problem` at `line`, with a column starting `column`.
#[track_caller]
fn assert_uff_error(text: &str, problem: FormatProblem, line: usize, column: Option<&str>) {
    match parse_uff58(text, "bad.uff") {
        Ok(f) => panic!(
            "expected {problem:?} at line {line}, got Ok ({} x {})",
            f.ny(),
            f.nu()
        ),
        Err(FrfError::Format {
            file,
            line: l,
            column: c,
            problem: p,
            detail,
        }) => {
            assert_eq!(file, "bad.uff");
            assert_eq!(p, problem, "problem; detail: {detail}");
            assert_eq!(l, line, "line; detail: {detail}");
            match column {
                None => assert_eq!(c, None, "column; detail: {detail}"),
                Some(prefix) => assert!(
                    c.as_deref().is_some_and(|c| c.starts_with(prefix)),
                    "column {c:?} should start with {prefix:?}; detail: {detail}"
                ),
            }
            assert!(!detail.is_empty());
        }
        Err(e) => panic!("expected a format error, got {e:?}"),
    }
}

// ---------------------------------------------------------------------------------------
// The reference file.

/// Significant digits of a field printed by pyuff's `%13.5e` / `%20.11e`.
const ABSCISSA_DIGITS: i32 = 6;
const ORDINATE_DIGITS: i32 = 12;

/// Half a unit in the last printed digit of `x` printed with `digits` significant digits.
fn half_ulp_printed(x: f64, digits: i32) -> f64 {
    if x == 0.0 {
        return 0.0;
    }
    0.5 * 10f64.powi(x.abs().log10().floor() as i32 - (digits - 1))
}

#[test]
fn wafer_uff_matches_csv_within_printed_precision() {
    let Some(csv_path) = require(
        "wafer_uff_matches_csv_within_printed_precision",
        "wafer_nominal.csv",
    ) else {
        return;
    };
    let Some(uff_path) = require(
        "wafer_uff_matches_csv_within_printed_precision",
        "uff/wafer_nominal.uff",
    ) else {
        return;
    };
    let csv = read_frf_csv(&csv_path).unwrap();
    let uff = read_uff58(&uff_path).unwrap();
    assert_eq!(
        (uff.ny(), uff.nu(), uff.n_lines()),
        (csv.ny(), csv.nu(), csv.n_lines())
    );
    assert_eq!((uff.ny(), uff.nu(), uff.n_lines()), (4, 13, 4000));
    assert!(!uff.has_variance());
    for k in 0..csv.n_lines() {
        let (a, b) = (uff.freq_hz(k), csv.freq_hz(k));
        assert!(
            (a - b).abs() <= half_ulp_printed(b, ABSCISSA_DIGITS) * (1.0 + 1e-9),
            "line {k}: {a} vs {b} Hz"
        );
    }
    let mut max_rel: f64 = 0.0;
    for k in 0..csv.n_lines() {
        for j in 0..csv.nu() {
            for i in 0..csv.ny() {
                let (u, c) = (uff.value(k, i, j), csv.value(k, i, j));
                for (x, y) in [(u.re, c.re), (u.im, c.im)] {
                    // Rounding to the printed digits, plus the last bit of both parses.
                    let tol = half_ulp_printed(y, ORDINATE_DIGITS) * (1.0 + 1e-9)
                        + 2.0 * f64::EPSILON * y.abs();
                    assert!(
                        (x - y).abs() <= tol,
                        "line {k} G{}_{}: uff {x:e} vs csv {y:e}",
                        i + 1,
                        j + 1
                    );
                    if y != 0.0 {
                        max_rel = max_rel.max((x - y).abs() / y.abs());
                    }
                }
            }
        }
    }
    println!("wafer_nominal.uff vs .csv: max relative error {max_rel:e}");
    assert_eq!(uff.metadata["uff.outputs"], "1:+Z 2:+Z 3:+Z 4:+Z");
    let inputs: Vec<String> = (101..=113).map(|n| format!("{n}:+Z")).collect();
    assert_eq!(uff.metadata["uff.inputs"], inputs.join(" "));
    assert_eq!(uff.metadata["uff.records"], "52");
    assert_eq!(uff.metadata["uff.ordinate"], "complex double");
    assert_eq!(uff.metadata["uff.abscissa_spacing"], "uneven");
    assert_eq!(uff.metadata["uff.abscissa"], "frequency");
    assert_eq!(uff.metadata["uff.numerator"], "displacement");
    assert_eq!(uff.metadata["uff.denominator"], "excitation force");
    assert_eq!(uff.metadata["uff.id1"], "wafer_nominal G1_1");
    assert_eq!(uff.source, Some(uff_path.display().to_string()));
    // read_frf dispatches on the extension.
    let again = read_frf(&uff_path).unwrap();
    assert_eq!(again.values(), uff.values());
}

// ---------------------------------------------------------------------------------------
// Layouts and assembly.

#[test]
fn assembles_by_first_appearance() {
    // Records for responses 20 and 10 (in that order) and references 5 and 7 (-Y).
    let recs = [
        Rec::frf((20, 3), (5, 3), 6, true, 5),
        Rec::frf((10, 3), (5, 3), 6, true, 5),
        Rec::frf((10, 3), (7, -2), 6, true, 5),
        Rec::frf((20, 3), (7, -2), 6, true, 5),
    ];
    let f = parse_uff58(&file_text(&recs), "a.uff").unwrap();
    assert_eq!((f.ny(), f.nu(), f.n_lines()), (2, 2, 5));
    assert_eq!(f.freq_hz_slice(), &[0.5, 0.75, 1.0, 1.25, 1.5]);
    assert_eq!(f.value(2, 0, 0), C64::new(2005.25, -2.5));
    assert_eq!(f.value(2, 1, 0), C64::new(1005.25, -2.5));
    assert_eq!(f.value(4, 0, 1), C64::new(2007.5, -4.5));
    assert_eq!(f.value(0, 1, 1), C64::new(1007.0, -0.5));
    assert_eq!(f.metadata["uff.outputs"], "20:+Z 10:+Z");
    assert_eq!(f.metadata["uff.inputs"], "5:+Z 7:-Y");
    assert_eq!(f.metadata["uff.abscissa_spacing"], "even");
    assert_eq!(f.units.as_deref(), Some("m/N"));
    assert_eq!(f.metadata["uff.id1"], "test record 20:5");
    assert_eq!(f.metadata["uff.abscissa_label"], "Frequency");
    assert_eq!(f.metadata["uff.abscissa_units"], "Hz");
    assert!(!f.metadata.contains_key("uff.skipped"));
}

#[test]
fn every_data_layout_reads() {
    // (ordinate type, even, digits kept by the layout)
    for (ord, even) in [
        (2, true),
        (2, false),
        (4, true),
        (4, false),
        (5, true),
        (5, false),
        (6, true),
        (6, false),
    ] {
        // 7 points: partial last lines in every layout.
        let recs = [
            Rec::frf((1, 1), (2, 1), ord, even, 7),
            Rec::frf((3, 1), (2, 1), ord, even, 7),
        ];
        let text = file_text(&recs);
        let f = parse_uff58(&text, "layout.uff")
            .unwrap_or_else(|e| panic!("ord {ord} even {even}: {e}\n{text}"));
        assert_eq!((f.ny(), f.nu(), f.n_lines()), (2, 1, 7), "ord {ord}");
        for k in 0..7 {
            assert_eq!(f.freq_hz(k), 0.5 + 0.25 * k as f64, "ord {ord} even {even}");
            for (i, r) in recs.iter().enumerate() {
                // The test values have few digits: exact in single precision fields too.
                assert_eq!(f.value(k, i, 0), r.vals[k], "ord {ord} even {even} k {k}");
            }
        }
        let expected = match ord {
            2 => "real single",
            4 => "real double",
            5 => "complex single",
            _ => "complex double",
        };
        assert_eq!(f.metadata["uff.ordinate"], expected);
    }
}

/// The header of a 1 x 1 complex record with `n` points; data lines follow.
fn header_1x1(ord: i64, n: usize, even: bool) -> String {
    let mut s = String::from("    -1\n    58\nfortran style\nNONE\nNONE\nNONE\nNONE\n");
    s.push_str(&format!(
        "{:5}{:10}{:5}{:10} {:>10}{:10}{:4} {:>10}{:10}{:4}\n",
        4, 1, 1, 0, "NONE", 1, 3, "NONE", 1, 3
    ));
    s.push_str(&format!(
        "{ord:10}{n:10}{:10}  0.10000E+01  0.50000E+00  0.00000E+00\n",
        i32::from(even)
    ));
    for _ in 0..4 {
        s.push_str("         0    0    0    0 NONE                 NONE                \n");
    }
    s
}

#[test]
fn fortran_fields_without_blanks() {
    // Complex single, even: 13-character fields filled to the last column (one more
    // digit than E13.5 leaves room for), so the fields touch.
    let mut text = header_1x1(5, 4, true);
    text.push_str(
        "-1.234500E+01-2.345600E+01 3.456700E-04-4.567800E+03-5.678900E+04 6.789100E+05\n",
    );
    text.push_str("-7.891200E-08-8.912300D-09\n    -1\n");
    let f = parse_uff58(&text, "fortran.uff").unwrap();
    assert_eq!(f.freq_hz_slice(), &[1.0, 1.5, 2.0, 2.5]);
    let expect = [
        C64::new(-12.345, -23.456),
        C64::new(3.4567e-4, -4567.8),
        C64::new(-56789.0, 678910.0),
        C64::new(-7.8912e-8, -8.9123e-9),
    ];
    for (k, z) in expect.iter().enumerate() {
        let v = f.value(k, 0, 0);
        assert!((v - z).norm() <= 1e-12 * z.norm(), "{k}: {v} vs {z}");
    }
    // Complex double, uneven (E13.5, 2E20.12), with 3-digit exponents without the E.
    let mut text = header_1x1(6, 2, false);
    text.push_str("  0.10000E+01-0.1234567890123-100 0.2345678901234+100\n");
    text.push_str("  0.20000E+01 0.3456789012345D+01-0.4567890123456D-01\n    -1\n");
    let f = parse_uff58(&text, "fortran.uff").unwrap();
    assert_eq!(f.freq_hz_slice(), &[1.0, 2.0]);
    assert_eq!(
        f.value(0, 0, 0),
        C64::new(-0.1234567890123e-100, 0.2345678901234e100)
    );
    assert_eq!(
        f.value(1, 0, 0),
        C64::new(0.3456789012345e1, -0.4567890123456e-1)
    );
}

#[test]
fn free_format_lines_are_accepted() {
    // A writer that ignored the field widths: blank-separated numbers.
    let mut text = header_1x1(6, 3, true);
    text.push_str("1.5 -2.5 3.5\n-4.5 5.5 -6.5\n    -1\n");
    let f = parse_uff58(&text, "free.uff").unwrap();
    assert_eq!(f.value(0, 0, 0), C64::new(1.5, -2.5));
    assert_eq!(f.value(1, 0, 0), C64::new(3.5, -4.5));
    assert_eq!(f.value(2, 0, 0), C64::new(5.5, -6.5));
}

#[test]
fn skips_other_datasets_and_function_types() {
    let mut text = String::from(
        "    -1\n   151\nmodel\nNONE\nNONE\nNONE\nNONE\nNONE\nNONE\n    -1\n\
         \n    -1\n   164\n         1  SI: Meter (newton)         2\n\
         1.0 1.0 1.0\n273.15\n    -1\n",
    );
    let mut time = Rec::frf((1, 3), (1, 3), 4, true, 4);
    time.func = 1;
    text.push_str(&record_text(&time));
    text.push_str(&record_text(&Rec::frf((1, 3), (2, 3), 6, false, 4)));
    let f = parse_uff58(&text, "mixed.unv").unwrap();
    assert_eq!((f.ny(), f.nu(), f.n_lines()), (1, 1, 4));
    let skipped = &f.metadata["uff.skipped"];
    assert!(skipped.contains("dataset 151 at line 1"), "{skipped}");
    assert!(skipped.contains("dataset 164 at line 12"), "{skipped}");
    assert!(
        skipped.contains("dataset 58 at line 18: function type 1 (time response)"),
        "{skipped}"
    );
    assert_eq!(f.metadata["uff.records"], "1");
}

#[test]
fn nan_at_dc_is_dropped() {
    let mut recs = [
        Rec::frf((1, 3), (1, 3), 6, false, 4),
        Rec::frf((1, 3), (2, 3), 6, false, 4),
    ];
    for r in &mut recs {
        r.freqs[0] = 0.0;
    }
    recs[1].vals[0] = C64::new(f64::NAN, f64::NAN);
    let text = file_text(&recs);
    assert!(text.contains("NaN"));
    let f = parse_uff58(&text, "dc.uff").unwrap();
    assert_eq!(f.freq_hz_slice(), &[0.75, 1.0, 1.25]);
    assert_eq!(f.value(0, 0, 1), recs[1].vals[1]);
    assert!(f.metadata.contains_key("uff.dropped"));
    // A finite 0 Hz point stays.
    recs[1].vals[0] = C64::new(1.0, 0.0);
    let f = parse_uff58(&file_text(&recs), "dc.uff").unwrap();
    assert_eq!(f.freq_hz_slice(), &[0.0, 0.75, 1.0, 1.25]);
}

// ---------------------------------------------------------------------------------------
// Errors. Line numbers of a file of `record_text` records: record k (0-based) of n
// points starts at line 1 + k * (14 + data lines); within a record, line 8 is record 6,
// line 9 record 7, line 14 the first data line.

#[test]
fn empty_and_foreign_files() {
    assert_uff_error("", FormatProblem::Empty, 0, None);
    assert_uff_error("\n \n", FormatProblem::Empty, 0, None);
    assert_uff_error(
        "freq_hz,G1_1_re,G1_1_im\n1,1,1\n",
        FormatProblem::BadRecord,
        1,
        None,
    );
    assert_uff_error(
        "    -1\n   151\nmodel\n    -1\n",
        FormatProblem::NotFound,
        0,
        None,
    );
    assert_uff_error("\n    -1\n", FormatProblem::BadRecord, 2, None);
    assert_uff_error(
        "    -1\n  abc\n    -1\n",
        FormatProblem::BadRecord,
        2,
        Some("dataset number"),
    );
    assert_uff_error(
        "    -1\n   151\nmodel without an end\n",
        FormatProblem::BadRecord,
        3,
        None,
    );
}

#[test]
fn binary_58b_cut_after_its_header() {
    // Binary datasets are read (tests/io_uff_binary.rs); one that ends after its header
    // line is an error at that line.
    let text =
        "    -1\n    58b     1     2          11        64     0     0           0           0\n";
    assert_uff_error(text, FormatProblem::BadRecord, 2, None);
}

#[test]
fn truncated_header() {
    let full = record_text(&Rec::frf((1, 3), (1, 3), 6, true, 4));
    let head: String = full.lines().take(9).map(|l| format!("{l}\n")).collect();
    assert_uff_error(&head, FormatProblem::BadRecord, 9, None);
    let closed = format!("{head}    -1\n");
    assert_uff_error(&closed, FormatProblem::BadRecord, 10, None);
}

#[test]
fn truncated_and_overlong_data() {
    // 4 complex double even points: 8 values on 2 lines (14, 15), then -1 on line 16.
    let full = record_text(&Rec::frf((1, 3), (1, 3), 6, true, 4));
    let lines: Vec<&str> = full.lines().collect();
    assert_eq!(lines.len(), 16);
    let cut =
        |keep: &[usize]| -> String { keep.iter().map(|&i| format!("{}\n", lines[i])).collect() };
    // The closing delimiter right after the first data line.
    let mut keep: Vec<usize> = (0..14).collect();
    keep.push(15);
    assert_uff_error(&cut(&keep), FormatProblem::BadRecord, 15, None);
    // The file ends inside the data.
    assert_uff_error(
        &cut(&(0..14).collect::<Vec<_>>()),
        FormatProblem::BadRecord,
        14,
        None,
    );
    // No closing delimiter.
    assert_uff_error(
        &cut(&(0..15).collect::<Vec<_>>()),
        FormatProblem::BadRecord,
        15,
        None,
    );
    // One data line too many.
    let mut keep: Vec<usize> = (0..15).collect();
    keep.extend([14, 15]);
    assert_uff_error(&cut(&keep), FormatProblem::BadRecord, 16, None);
}

#[test]
fn bad_numbers_in_data() {
    let full = record_text(&Rec::frf((1, 3), (1, 3), 6, true, 4));
    let mut lines: Vec<String> = full.lines().map(str::to_string).collect();
    // Line 15, third field (value 7 of the record, columns 41-60).
    lines[14].replace_range(45..50, "x.yzw");
    let text = lines.join("\n");
    assert_uff_error(
        &text,
        FormatProblem::NotANumber,
        15,
        Some("data value 7 (columns 41-60)"),
    );
    // A NaN away from 0 Hz.
    let mut r = Rec::frf((1, 3), (1, 3), 6, false, 4);
    r.vals[2].im = f64::NAN;
    assert_uff_error(
        &record_text(&r),
        FormatProblem::NonFinite,
        16,
        Some("ordinate"),
    );
}

#[test]
fn bad_header_fields() {
    let full = record_text(&Rec::frf((1, 3), (1, 3), 6, true, 4));
    let edit = |line: usize, range: std::ops::Range<usize>, with: &str| -> String {
        let mut lines: Vec<String> = full.lines().map(str::to_string).collect();
        lines[line - 1].replace_range(range, with);
        lines.join("\n") + "\n"
    };
    // Ordinate data type 3 does not exist.
    assert_uff_error(
        &edit(9, 9..10, "3"),
        FormatProblem::BadRecord,
        9,
        Some("record 7, ordinate data type"),
    );
    // Abscissa spacing 2.
    assert_uff_error(
        &edit(9, 29..30, "2"),
        FormatProblem::BadRecord,
        9,
        Some("record 7, abscissa spacing"),
    );
    // No points.
    assert_uff_error(
        &edit(9, 19..20, "0"),
        FormatProblem::BadRecord,
        9,
        Some("record 7, number of points"),
    );
    // Response node not an integer (columns 42-51 of record 6).
    assert_uff_error(
        &edit(8, 45..46, "x"),
        FormatProblem::BadRecord,
        8,
        Some("record 6, response node (columns 42-51)"),
    );
    // Abscissa increment not a number.
    assert_uff_error(
        &edit(9, 46..47, "?"),
        FormatProblem::BadRecord,
        9,
        Some("record 7, abscissa increment"),
    );
}

#[test]
fn inconsistent_record_sets() {
    // 2 responses x 2 references with (2, 2) missing.
    let recs = [
        Rec::frf((1, 3), (1, 3), 6, true, 4),
        Rec::frf((2, 3), (1, 3), 6, true, 4),
        Rec::frf((1, 3), (2, 3), 6, true, 4),
    ];
    assert_uff_error(
        &file_text(&recs),
        FormatProblem::MissingEntry,
        0,
        Some("response 2:+Z / reference 2:+Z"),
    );
    // The same pair twice: the second record's record 6 is line 16 + 8.
    let recs = [
        Rec::frf((1, 3), (1, 3), 6, true, 4),
        Rec::frf((1, 3), (1, 3), 6, true, 4),
    ];
    assert_uff_error(
        &file_text(&recs),
        FormatProblem::BadRecord,
        24,
        Some("record 6"),
    );
    // Different frequency axes: the second record's record 7 is line 16 + 9.
    let mut other = Rec::frf((2, 3), (1, 3), 6, true, 4);
    for f in &mut other.freqs {
        *f *= 2.0;
    }
    let recs = [Rec::frf((1, 3), (1, 3), 6, true, 4), other];
    assert_uff_error(
        &file_text(&recs),
        FormatProblem::BadRecord,
        25,
        Some("record 7"),
    );
    // Another number of points.
    let recs = [
        Rec::frf((1, 3), (1, 3), 6, true, 4),
        Rec::frf((2, 3), (1, 3), 6, true, 5),
    ];
    assert_uff_error(
        &file_text(&recs),
        FormatProblem::BadRecord,
        25,
        Some("record 7"),
    );
}

#[test]
fn bad_abscissa() {
    // Uneven abscissa going back: the third point (line 16) repeats the second.
    let mut r = Rec::frf((1, 3), (1, 3), 6, false, 4);
    r.freqs[2] = r.freqs[1];
    assert_uff_error(
        &record_text(&r),
        FormatProblem::NotIncreasing,
        16,
        Some("abscissa"),
    );
    let mut r = Rec::frf((1, 3), (1, 3), 6, false, 4);
    r.freqs[0] = -1.0;
    assert_uff_error(
        &record_text(&r),
        FormatProblem::BadFrequency,
        14,
        Some("abscissa"),
    );
}

#[test]
fn io_error_names_the_path() {
    let e = read_uff58("/nonexistent/x.uff").unwrap_err();
    assert!(
        matches!(&e, FrfError::Io { file, .. } if file == "/nonexistent/x.uff"),
        "{e:?}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Arbitrary damage to a valid file never panics the reader.
    #[test]
    fn damaged_files_never_panic(
        ord in prop::sample::select(vec![2i64, 4, 5, 6]),
        even in any::<bool>(),
        edits in prop::collection::vec((any::<prop::sample::Index>(), prop_oneof![
            Just("-1"), Just("\n"), Just("    -1\n"), Just("9"), Just("-"), Just("E"),
            Just("D"), Just(""), Just(" "), Just("é"), Just("nan"), Just("58b"), Just("0")
        ]), 1..6),
    ) {
        let recs = [
            Rec::frf((1, 3), (1, 3), ord, even, 5),
            Rec::frf((2, 3), (1, 3), ord, even, 5),
        ];
        let mut text = file_text(&recs);
        for (at, s) in edits {
            let mut pos = at.index(text.len() + 1);
            while !text.is_char_boundary(pos) {
                pos -= 1;
            }
            let end = text[pos..].chars().next().map_or(pos, |c| pos + c.len_utf8());
            text.replace_range(pos..end, s);
        }
        match parse_uff58(&text, "fuzz.uff") {
            Ok(f) => prop_assert!(f.n_lines() > 0),
            Err(e) => prop_assert!(e.problem().is_some(), "{e:?}"),
        }
    }
}
