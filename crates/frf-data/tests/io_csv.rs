//! FRF CSV reader and writer: round trips, every bad-input case, the shared data files.

use frf_data::io::{frf_csv_string, parse_frf_csv, read_frf_csv, write_frf_csv};
use frf_data::shared_data::require;
use frf_data::{FormatProblem, Frf, FrfDataset, FrfError, C64};
use proptest::prelude::*;

/// Asserts that `text` fails with `problem` at `line` in `column`.
#[track_caller]
fn assert_format_error(text: &str, problem: FormatProblem, line: usize, column: Option<&str>) {
    match parse_frf_csv(text, "bad.csv") {
        Ok(f) => panic!(
            "expected {problem:?} at line {line}, got Ok with {} lines",
            f.n_lines()
        ),
        Err(FrfError::Format {
            file,
            line: l,
            column: c,
            problem: p,
            detail,
        }) => {
            assert_eq!(file, "bad.csv");
            assert_eq!(p, problem, "problem; detail: {detail}");
            assert_eq!(l, line, "line; detail: {detail}");
            assert_eq!(c.as_deref(), column, "column; detail: {detail}");
            assert!(!detail.is_empty());
        }
        Err(e) => panic!("expected a format error, got {e:?}"),
    }
}

const HEAD_2X1: &str = "freq_hz,G1_1_re,G1_1_im,G2_1_re,G2_1_im\n";

// ---------------------------------------------------------------------------------------
// Reading: the happy path.

#[test]
fn reads_columns_in_any_order_with_comments_and_metadata() {
    let text = "\u{feff}# first comment\r\n\
                # ny=2 nu=2 units=m/N seed=7,\r\n\
                \r\n\
                # name: test file\r\n\
                G2_2_im,G1_1_re,freq_hz,G1_1_im,G2_1_re,G2_1_im,G1_2_re,G1_2_im,G2_2_re\r\n\
                4,1,0.5,2,3,-3,5,6,7\r\n\
                \r\n\
                # a comment between data lines\r\n\
                40,10,1.5,20,30,-30,50,60,70\r\n";
    let f = parse_frf_csv(text, "mem.csv").unwrap();
    assert_eq!((f.ny(), f.nu(), f.n_lines()), (2, 2, 2));
    assert_eq!(f.freq_hz_slice(), &[0.5, 1.5]);
    assert_eq!(f.value(0, 0, 0), C64::new(1.0, 2.0));
    assert_eq!(f.value(0, 1, 0), C64::new(3.0, -3.0));
    assert_eq!(f.value(0, 0, 1), C64::new(5.0, 6.0));
    assert_eq!(f.value(1, 1, 1), C64::new(70.0, 40.0));
    assert!(!f.has_variance());
    assert_eq!(f.units.as_deref(), Some("m/N"));
    assert_eq!(f.metadata["ny"], "2");
    assert_eq!(f.metadata["seed"], "7");
    assert_eq!(f.metadata["name"], "test file");
    assert_eq!(
        f.comments,
        vec![
            "first comment",
            "ny=2 nu=2 units=m/N seed=7,",
            "name: test file",
            "a comment between data lines"
        ]
    );
    assert_eq!(f.source.as_deref(), Some("mem.csv"));
}

#[test]
fn reads_variance_and_blank_padded_fields() {
    let text = "freq_hz, G1_1_re ,G1_1_im,G1_1_var\n 1.0 , 2e-3,-4E+2 ,0\n2,1,1,1e-300\n";
    let f = parse_frf_csv(text, "v.csv").unwrap();
    assert!(f.has_variance());
    assert_eq!(f.variance(0, 0, 0), Some(0.0));
    assert_eq!(f.variance(1, 0, 0), Some(1e-300));
    assert_eq!(f.value(0, 0, 0), C64::new(2e-3, -400.0));
}

#[test]
fn dc_line_needs_dc_allowed() {
    let body = "0,1,0,1,0\n1,1,0,1,0\n";
    assert_format_error(
        &format!("{HEAD_2X1}{body}"),
        FormatProblem::BadFrequency,
        2,
        Some("freq_hz"),
    );
    let f = parse_frf_csv(&format!("# dc=allowed\n{HEAD_2X1}{body}"), "dc.csv").unwrap();
    assert_eq!(f.freq_hz_slice(), &[0.0, 1.0]);
    // Also when the word sits in a comment after the header but before the line.
    let f = parse_frf_csv(&format!("{HEAD_2X1}# dc=allowed\n{body}"), "dc.csv").unwrap();
    assert_eq!(f.n_lines(), 2);
}

// ---------------------------------------------------------------------------------------
// Reading: one test per bad-input case (problem, line, column).

#[test]
fn empty_file() {
    assert_format_error("", FormatProblem::Empty, 0, None);
    assert_format_error("\n\n  \n", FormatProblem::Empty, 0, None);
    assert_format_error("# only\n# comments\n", FormatProblem::Empty, 0, None);
}

#[test]
fn header_without_data_lines() {
    assert_format_error(
        &format!("# c\n{HEAD_2X1}\n\n"),
        FormatProblem::Empty,
        2,
        None,
    );
}

#[test]
fn unknown_column() {
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G1_1_abs\n1,1,1,1\n",
        FormatProblem::BadHeader,
        1,
        Some("G1_1_abs"),
    );
    assert_format_error(
        "# c\nfrequency,G1_1_re,G1_1_im\n1,1,1\n",
        FormatProblem::BadHeader,
        2,
        Some("frequency"),
    );
}

#[test]
fn zero_based_index_column() {
    assert_format_error(
        "freq_hz,G0_1_re,G0_1_im\n1,1,1\n",
        FormatProblem::BadHeader,
        1,
        Some("G0_1_re"),
    );
}

#[test]
fn duplicate_column() {
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G1_1_re\n1,1,1,1\n",
        FormatProblem::BadHeader,
        1,
        Some("G1_1_re"),
    );
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,freq_hz\n1,1,1,1\n",
        FormatProblem::BadHeader,
        1,
        Some("freq_hz"),
    );
    // The same entry spelled twice.
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G01_1_re\n1,1,1,1\n",
        FormatProblem::BadHeader,
        1,
        Some("G01_1_re"),
    );
}

#[test]
fn no_freq_column() {
    assert_format_error(
        "G1_1_re,G1_1_im\n1,1\n",
        FormatProblem::BadHeader,
        1,
        Some("freq_hz"),
    );
}

#[test]
fn empty_header_field() {
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,\n1,1,1,\n",
        FormatProblem::BadHeader,
        1,
        Some("field 4"),
    );
}

#[test]
fn header_without_entries() {
    assert_format_error("freq_hz\n1\n", FormatProblem::BadHeader, 1, None);
}

#[test]
fn comments_announcing_other_dimensions() {
    assert_format_error(
        &format!("# ny=3 nu=1\n{HEAD_2X1}1,1,1,1,1\n"),
        FormatProblem::BadHeader,
        2,
        None,
    );
}

#[test]
fn missing_entry() {
    // G1_2 and G2_2 exist, so the data are 2 x 2, but G2_1 has no columns.
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G1_2_re,G1_2_im,G2_2_re,G2_2_im\n1,1,1,1,1,1,1\n",
        FormatProblem::MissingEntry,
        1,
        Some("G2_1_re"),
    );
    // Only the imaginary half is missing.
    assert_format_error(
        "# x\nfreq_hz,G1_1_re,G1_1_im,G2_1_re\n1,1,1,1\n",
        FormatProblem::MissingEntry,
        2,
        Some("G2_1_im"),
    );
    // Huge indices: an error, not an allocation.
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G999999999_999999999_re\n1,1,1,1\n",
        FormatProblem::MissingEntry,
        1,
        Some("G2_1_re"),
    );
}

#[test]
fn inconsistent_variance() {
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G2_1_re,G2_1_im,G1_1_var\n1,1,1,1,1,1\n",
        FormatProblem::InconsistentVariance,
        1,
        Some("G2_1_var"),
    );
}

#[test]
fn not_a_number() {
    assert_format_error(
        &format!("{HEAD_2X1}1,1,1,1,1\n2,1,abc,1,1\n"),
        FormatProblem::NotANumber,
        3,
        Some("G1_1_im"),
    );
    assert_format_error(
        &format!("{HEAD_2X1}1,1,1,,1\n"),
        FormatProblem::NotANumber,
        2,
        Some("G2_1_re"),
    );
    assert_format_error(
        &format!("{HEAD_2X1}1 Hz,1,1,1,1\n"),
        FormatProblem::NotANumber,
        2,
        Some("freq_hz"),
    );
}

#[test]
fn non_finite_values() {
    for bad in ["NaN", "nan", "inf", "-inf", "Infinity", "1e999"] {
        assert_format_error(
            &format!("{HEAD_2X1}1,1,1,1,1\n\n2,1,1,1,{bad}\n"),
            FormatProblem::NonFinite,
            4,
            Some("G2_1_im"),
        );
    }
    assert_format_error(
        &format!("{HEAD_2X1}nan,1,1,1,1\n"),
        FormatProblem::NonFinite,
        2,
        Some("freq_hz"),
    );
    assert_format_error(
        "freq_hz,G1_1_re,G1_1_im,G1_1_var\n1,1,1,inf\n",
        FormatProblem::NonFinite,
        2,
        Some("G1_1_var"),
    );
}

#[test]
fn negative_variance() {
    assert_format_error(
        "freq_hz,G1_1_var,G1_1_re,G1_1_im\n1,0,1,1\n2,-1e-12,1,1\n",
        FormatProblem::NegativeVariance,
        3,
        Some("G1_1_var"),
    );
}

#[test]
fn frequencies_not_strictly_increasing() {
    assert_format_error(
        &format!("{HEAD_2X1}1,1,1,1,1\n2,1,1,1,1\n2,1,1,1,1\n"),
        FormatProblem::NotIncreasing,
        4,
        Some("freq_hz"),
    );
    assert_format_error(
        &format!("# c\n{HEAD_2X1}1,1,1,1,1\n0.5,1,1,1,1\n"),
        FormatProblem::NotIncreasing,
        4,
        Some("freq_hz"),
    );
}

#[test]
fn bad_frequency() {
    assert_format_error(
        &format!("{HEAD_2X1}-1,1,1,1,1\n"),
        FormatProblem::BadFrequency,
        2,
        Some("freq_hz"),
    );
    assert_format_error(
        &format!("{HEAD_2X1}0,1,1,1,1\n"),
        FormatProblem::BadFrequency,
        2,
        Some("freq_hz"),
    );
}

#[test]
fn wrong_field_count() {
    assert_format_error(
        &format!("{HEAD_2X1}1,1,1,1,1\n2,1,1,1\n"),
        FormatProblem::FieldCount,
        3,
        Some("G2_1_im"),
    );
    assert_format_error(
        &format!("{HEAD_2X1}1,1,1,1,1,1\n"),
        FormatProblem::FieldCount,
        2,
        Some("field 6"),
    );
}

#[test]
fn error_messages_name_file_line_and_column() {
    let e = parse_frf_csv(&format!("{HEAD_2X1}1,1,x,1,1\n"), "dir/g.csv").unwrap_err();
    let msg = e.to_string();
    assert!(msg.starts_with("dir/g.csv:2: column G1_1_im: "), "{msg}");
    assert!(msg.contains("`x` is not a number"), "{msg}");
}

#[test]
fn io_errors_name_the_path() {
    let e = read_frf_csv("/nonexistent/dir/frf.csv").unwrap_err();
    assert!(
        matches!(&e, FrfError::Io { file, .. } if file == "/nonexistent/dir/frf.csv"),
        "{e:?}"
    );
}

// ---------------------------------------------------------------------------------------
// Writing and round trips.

/// Finite doubles of every magnitude, including subnormals, zeros and huge exponents.
fn any_finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO,
        (-1e3..1e3f64, -300i32..300).prop_map(|(m, e)| m * 10f64.powi(e)),
        Just(f64::MAX),
        Just(f64::MIN_POSITIVE),
        Just(-0.0),
    ]
    .prop_filter("finite", |x| x.is_finite())
}

fn nonneg_finite() -> impl Strategy<Value = f64> {
    any_finite().prop_map(f64::abs)
}

prop_compose! {
    /// A random dataset: ny, nu in 1..5, a random number of strictly increasing positive
    /// lines (optionally a 0 Hz line first), random values, optional variance and units.
    fn arb_frf()(ny in 1usize..5, nu in 1usize..5, dc in any::<bool>(),
                 freqs in prop::collection::vec(
                     (prop::num::f64::POSITIVE | prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL)
                         .prop_filter("finite", |x| x.is_finite()), 1..25),
                 with_var in any::<bool>(),
                 units in prop::option::of(prop_oneof![Just("m/N"), Just("rad/A"), Just("m/s^2 per N")]))
        (ny in Just(ny), nu in Just(nu), dc in Just(dc), freqs in Just(freqs), units in Just(units),
         with_var in Just(with_var),
         values in prop::collection::vec((any_finite(), any_finite()), ny * nu * 25),
         variance in prop::collection::vec(nonneg_finite(), if with_var { ny * nu * 25 } else { 0 }))
        -> Frf
    {
        let mut f: Vec<f64> = freqs;
        f.sort_by(f64::total_cmp);
        f.dedup();
        if dc {
            f.insert(0, 0.0);
        }
        let m = ny * nu;
        let n = f.len();
        let vals: Vec<C64> = values[..n * m].iter().map(|&(a, b)| C64::new(a, b)).collect();
        let var = with_var.then(|| variance[..n * m].to_vec());
        let mut frf = Frf::new(f, ny, nu, vals, var).unwrap();
        frf.units = units.map(str::to_string);
        frf
    }
}

fn assert_bit_exact(a: &Frf, b: &Frf) {
    assert_eq!((a.ny(), a.nu(), a.n_lines()), (b.ny(), b.nu(), b.n_lines()));
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(a.freq_hz_slice()), bits(b.freq_hz_slice()));
    let cbits = |x: &[C64]| {
        x.iter()
            .map(|z| (z.re.to_bits(), z.im.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(cbits(a.values()), cbits(b.values()));
    assert_eq!(a.variances().map(bits), b.variances().map(bits));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn write_read_round_trip_is_bit_exact(
        frf in arb_frf(),
        comments in prop::collection::vec("[a-zA-Z0-9 ,.()]{0,30}", 0..3),
    ) {
        let text = frf_csv_string(&frf, &comments);
        let back = parse_frf_csv(&text, "rt.csv").unwrap();
        assert_bit_exact(&frf, &back);
        prop_assert_eq!(back.units.as_deref(), frf.units.as_deref());
        // The comments come back in order, followed by the writer's own line(s).
        prop_assert_eq!(&back.comments[..comments.len()], &comments[..]);
        prop_assert_eq!(back.metadata["ny"].as_str(), frf.ny().to_string());
        prop_assert_eq!(back.metadata["nu"].as_str(), frf.nu().to_string());
        // Writing what was read gives the same text (the writer's lines are not doubled).
        prop_assert_eq!(frf_csv_string(&back, &back.comments), text);
    }

    /// Arbitrary damage to a valid file never panics the reader.
    #[test]
    fn damaged_files_never_panic(
        frf in arb_frf(),
        edits in prop::collection::vec((any::<prop::sample::Index>(), prop_oneof![
            Just(","), Just("\n"), Just("#"), Just("-"), Just("e"), Just("nan"), Just(""),
            Just("G9_9_re"), Just("\r"), Just("é"), Just("0"), Just("freq_hz"), Just(" ")
        ]), 1..6),
    ) {
        let mut text = frf_csv_string(&frf, &[]);
        for (at, s) in edits {
            let mut pos = at.index(text.len() + 1);
            while !text.is_char_boundary(pos) {
                pos -= 1;
            }
            // Replace one character (or insert at the end).
            let end = text[pos..].chars().next().map_or(pos, |c| pos + c.len_utf8());
            text.replace_range(pos..end, s);
        }
        match parse_frf_csv(&text, "fuzz.csv") {
            Ok(f) => prop_assert!(f.n_lines() > 0),
            Err(e) => prop_assert!(e.problem().is_some(), "{e:?}"),
        }
    }
}

#[test]
fn writer_header_order_matches_formats_md() {
    let f = Frf::from_fn(vec![1.0], 2, 2, |_, i, j| C64::new(i as f64, j as f64))
        .unwrap()
        .with_variance(Some(vec![1.0; 4]))
        .unwrap();
    let s = frf_csv_string(&f, &[]);
    let header = s.lines().find(|l| !l.starts_with('#')).unwrap();
    assert_eq!(
        header,
        "freq_hz,G1_1_re,G1_1_im,G2_1_re,G2_1_im,G1_2_re,G1_2_im,G2_2_re,G2_2_im,\
         G1_1_var,G2_1_var,G1_2_var,G2_2_var"
    );
    assert_eq!(s.lines().next(), Some("# ny=2 nu=2"));
}

#[test]
fn writes_views_and_trait_objects() {
    let f = Frf::from_fn(vec![1.0, 2.0, 3.0], 2, 3, |k, i, j| {
        C64::new((k * 100 + i * 10 + j) as f64, -1.0)
    })
    .unwrap();
    let view = f.band(1.5, 3.0).unwrap().select(&[1], &[2, 0]).unwrap();
    let dynamic: &dyn FrfDataset = &view;
    let back = parse_frf_csv(&frf_csv_string(dynamic, &[]), "view.csv").unwrap();
    assert_eq!((back.ny(), back.nu(), back.n_lines()), (1, 2, 2));
    assert_eq!(back.freq_hz_slice(), &[2.0, 3.0]);
    assert_eq!(back.value(0, 0, 0), C64::new(112.0, -1.0));
    assert_eq!(back.value(1, 0, 1), C64::new(210.0, -1.0));
}

#[test]
fn write_file_then_read_file() {
    let mut f = Frf::from_fn(vec![0.25, 0.75], 1, 2, |k, _, j| {
        C64::new(1.0 / (k + 3) as f64, -(j as f64) / 7.0)
    })
    .unwrap();
    f.units = Some("m/N".into());
    let path = std::env::temp_dir().join(format!("frf-io-csv-{}.csv", std::process::id()));
    write_frf_csv(&path, &f, &["written by a test".to_string()]).unwrap();
    let back = read_frf_csv(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_bit_exact(&f, &back);
    assert_eq!(back.units.as_deref(), Some("m/N"));
    assert_eq!(back.comments[0], "written by a test");
    assert_eq!(back.source, Some(path.display().to_string()));
    let e = write_frf_csv("/nonexistent/dir/out.csv", &f, &[]).unwrap_err();
    assert!(matches!(e, FrfError::Io { .. }), "{e:?}");
}

// ---------------------------------------------------------------------------------------
// The shared reference data.

/// (file, ny, nu, lines, has variance)
const REAL_FILES: &[(&str, usize, usize, usize, bool)] = &[
    ("daisy_flexible_structure.csv", 28, 2, 491, true),
    ("ladisk_beam_accelerance.csv", 1, 3, 1000, false),
    ("fditools_motorbench_msA.csv", 2, 1, 240, true),
];

#[test]
fn reads_every_shared_frf_csv() {
    let Some(nominal) = require("reads_every_shared_frf_csv", "wafer_nominal.csv") else {
        return;
    };
    let dir = nominal.parent().unwrap().to_path_buf();
    let mut paths = Vec::new();
    for d in [dir.clone(), dir.join("real")] {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            // The periods file is the periodic spectra CSV, not an FRF CSV.
            if name.ends_with(".csv") && !name.ends_with(".periods.csv") {
                paths.push(p);
            }
        }
    }
    paths.sort();
    assert!(paths.len() >= 5, "{paths:?}");
    for p in &paths {
        let f = read_frf_csv(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        assert!(f.n_lines() > 0, "{name}");
        // The dimensions the comments announce are the header's.
        assert_eq!(f.metadata["ny"], f.ny().to_string(), "{name}");
        assert_eq!(f.metadata["nu"], f.nu().to_string(), "{name}");
        assert_eq!(f.source, Some(p.display().to_string()));
        if name.starts_with("wafer_") {
            assert_eq!((f.ny(), f.nu(), f.n_lines()), (4, 13, 4000), "{name}");
            assert_eq!(f.units.as_deref(), Some("m/N"), "{name}");
            assert_eq!(f.freq_hz(0), 0.25);
            assert_eq!(f.freq_hz(3999), 1999.75);
            assert_eq!(f.has_variance(), !name.contains("noiseless"), "{name}");
        }
        if let Some(&(_, ny, nu, n, var)) = REAL_FILES.iter().find(|r| r.0 == name) {
            assert_eq!(
                (f.ny(), f.nu(), f.n_lines(), f.has_variance()),
                (ny, nu, n, var)
            );
            assert_eq!(f.metadata["name"], name.trim_end_matches(".csv"));
            assert!(f.comments.len() > 5, "{name}");
        }
    }
    for (name, ..) in REAL_FILES {
        assert!(
            paths.iter().any(|p| p.ends_with(name)),
            "{name} not in the shared data"
        );
    }
}

#[test]
fn wafer_nominal_values_and_bit_exact_rewrite() {
    let Some(p) = require(
        "wafer_nominal_values_and_bit_exact_rewrite",
        "wafer_nominal.csv",
    ) else {
        return;
    };
    let f = read_frf_csv(&p).unwrap();
    // The first data line of the file: 2.5000000000e-01,-2.0283682624e-02,1.1031733193e-04,
    // -2.0156579614e-02,3.8608708153e-05,...
    assert_eq!(
        f.value(0, 0, 0),
        C64::new(-2.0283682624e-02, 1.1031733193e-04)
    );
    assert_eq!(
        f.value(0, 1, 0),
        C64::new(-2.0156579614e-02, 3.8608708153e-05)
    );
    let text = frf_csv_string(&f, &f.comments);
    let back = parse_frf_csv(&text, "rewritten.csv").unwrap();
    assert_bit_exact(&f, &back);
    // The file's comments, then the writer's own line.
    assert_eq!(back.comments[..f.comments.len()], f.comments[..]);
    assert_eq!(back.comments[f.comments.len()..], ["ny=4 nu=13 units=m/N"]);
    assert_eq!(back.metadata, f.metadata);
    // Rewriting what was read is stable.
    assert_eq!(frf_csv_string(&back, &back.comments), text);
}

#[test]
fn periods_csv_is_not_an_frf_csv() {
    let Some(p) = require(
        "periods_csv_is_not_an_frf_csv",
        "real/fditools_motorbench_msA.periods.csv",
    ) else {
        return;
    };
    let e = read_frf_csv(&p).unwrap_err();
    let FrfError::Format {
        problem,
        line,
        column,
        ..
    } = &e
    else {
        panic!("{e:?}");
    };
    assert_eq!(*problem, FormatProblem::BadHeader, "{e}");
    assert_eq!(*line, 4, "{e}");
    assert_eq!(column.as_deref(), Some("experiment"), "{e}");
}
