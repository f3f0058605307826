//! Binary UFF 58b (both byte orders, single and double precision, real and complex, even
//! and uneven abscissa, several records in any order among other datasets): files written
//! here from known numbers, compared with the same records in ASCII and with the truth.

use frf_data::io::{parse_uff58_bytes, read_uff58, uff58_bytes, UffEncoding};
use frf_data::shared_data::require;
use frf_data::{FormatProblem, Frf, FrfDataset, FrfError, C64};

/// One dataset 58 to write.
#[derive(Clone)]
struct Rec {
    rsp: i64,
    refr: i64,
    /// 2 real single, 4 real double, 5 complex single, 6 complex double.
    ord: i64,
    even: bool,
    freqs: Vec<f64>,
    vals: Vec<C64>,
}

/// Numbers exact in `f32` and in 6 significant digits, so that every encoding holds them.
fn rec(rsp: i64, refr: i64, ord: i64, even: bool, n: usize) -> Rec {
    let freqs = (0..n)
        .map(|k| {
            if even {
                0.5 + 0.25 * k as f64
            } else {
                1.0 + 0.5 * (k * k) as f64
            }
        })
        .collect();
    let vals = (0..n)
        .map(|k| {
            let re = (rsp * 10 + refr) as f64 + 0.125 * k as f64;
            let im = if matches!(ord, 5 | 6) {
                -0.5 - k as f64
            } else {
                0.0
            };
            C64::new(re, im)
        })
        .collect();
    Rec {
        rsp,
        refr,
        ord,
        even,
        freqs,
        vals,
    }
}

/// Fortran `Ew.d`.
fn fe(x: f64, w: usize, d: usize) -> String {
    let s = format!("{x:.d$e}");
    let (m, e) = s.split_once('e').unwrap();
    let e: i32 = e.parse().unwrap();
    format!(
        "{:>w$}",
        format!("{m}E{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
    )
}

#[derive(Clone, Copy, PartialEq)]
enum Enc {
    Ascii,
    /// Binary with this byte order; `pyuff` writes no line break after the data and
    /// `n * 8` as the byte count of complex data.
    Binary {
        little: bool,
        pyuff: bool,
    },
}

fn record(r: &Rec, enc: Enc) -> Vec<u8> {
    let n = r.freqs.len();
    let complex = matches!(r.ord, 5 | 6);
    let single = matches!(r.ord, 2 | 5);
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
    let width = if single { 4 } else { 8 };
    let mut s = String::from("    -1\n");
    match enc {
        Enc::Ascii => s.push_str("    58\n"),
        Enc::Binary { little, pyuff } => {
            let nbytes = if pyuff { n * 8 } else { stream.len() * width };
            s.push_str(&format!(
                "{:>6}b{:>6}{:>6}{:>12}{:>12}{:>6}{:>6}{:>12}{:>12}\n",
                58,
                if little { 1 } else { 2 },
                2,
                11,
                nbytes,
                0,
                0,
                0,
                0
            ));
        }
    }
    s.push_str(&format!(
        "record {}:{}\nNONE\nNONE\nNONE\nNONE\n",
        r.rsp, r.refr
    ));
    s.push_str(&format!(
        "{:5}{:10}{:5}{:10} {:>10}{:10}{:4} {:>10}{:10}{:4}\n",
        4, 0, 0, 0, "stage", r.rsp, 3, "stage", r.refr, 3
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
    let mut out = s.into_bytes();
    match enc {
        Enc::Ascii => {
            let (widths, per_line): (&[usize], usize) = match (r.ord, r.even) {
                (2 | 5, _) => (&[13], 6),
                (_, true) => (&[20], 4),
                (4, false) => (&[13, 20], 4),
                _ => (&[13, 20, 20], 3),
            };
            let mut d = String::new();
            for (c, chunk) in stream.chunks(per_line).enumerate() {
                for (q, &x) in chunk.iter().enumerate() {
                    let w = widths[(c * per_line + q) % widths.len()];
                    d.push_str(&fe(x, w, if w == 13 { 5 } else { 12 }));
                }
                d.push('\n');
            }
            out.extend_from_slice(d.as_bytes());
        }
        Enc::Binary { little, pyuff } => {
            for &x in &stream {
                match (single, little) {
                    (true, true) => out.extend_from_slice(&(x as f32).to_le_bytes()),
                    (true, false) => out.extend_from_slice(&(x as f32).to_be_bytes()),
                    (false, true) => out.extend_from_slice(&x.to_le_bytes()),
                    (false, false) => out.extend_from_slice(&x.to_be_bytes()),
                }
            }
            if !pyuff {
                out.push(b'\n');
            }
        }
    }
    out.extend_from_slice(b"    -1\n");
    out
}

/// Other datasets, as modal software writes them around the FRFs.
fn other_datasets() -> Vec<u8> {
    let mut s = String::new();
    s.push_str("    -1\n   151\nmodel\ndescription\ndb app\n  01-JAN-26 00:00:00\n    -1\n");
    s.push_str("    -1\n   164\n         1  SI - mks (Newton)  2\n  1.00000000000000000D+00  1.00000000000000000D+00  1.00000000000000000D+00\n  2.73149999999999977D+02\n    -1\n");
    s.push_str("    -1\n    15\n         1         0         0         0  0.0000000E+00  0.0000000E+00  0.0000000E+00\n    -1\n");
    s.push_str(
        "    -1\n    82\n         1         2         0\nline\n         1         2\n    -1\n",
    );
    s.push_str("    -1\n  2411\n         1         1         1        11\n   0.0000000000000000E+00   0.0000000000000000E+00   0.0000000000000000E+00\n    -1\n");
    s.into_bytes()
}

/// Records of a 2 x 2 FRF (responses 1, 2; references 1, 2) in a scrambled order, with
/// other datasets before, between and after them.
fn file(ord: i64, even: bool, enc: impl Fn(usize) -> Enc) -> Vec<u8> {
    let order = [(2, 1), (1, 2), (1, 1), (2, 2)];
    let mut out = other_datasets();
    for (q, &(o, i)) in order.iter().enumerate() {
        out.extend(record(&rec(o, i, ord, even, 9), enc(q)));
        if q == 1 {
            out.extend(other_datasets());
        }
    }
    out.extend(other_datasets());
    out
}

#[track_caller]
fn read(bytes: &[u8], what: &str) -> Frf {
    parse_uff58_bytes(bytes, what).unwrap_or_else(|e| panic!("{what}: {e}"))
}

#[test]
fn every_binary_variant_reads_the_ascii_numbers() {
    for ord in [2, 4, 5, 6] {
        for even in [true, false] {
            let ascii = read(&file(ord, even, |_| Enc::Ascii), "ascii");
            assert_eq!((ascii.ny(), ascii.nu()), (2, 2));
            // First appearance: response 2 then 1, reference 1 then 2.
            assert_eq!(ascii.metadata["uff.outputs"], "2:+Z 1:+Z");
            assert_eq!(ascii.metadata["uff.inputs"], "1:+Z 2:+Z");
            // Truth: entry (response 1, reference 2) is row 1, column 1 (0-based).
            let truth = rec(1, 2, ord, even, 9);
            assert_eq!(ascii.freq_hz_slice(), truth.freqs.as_slice());
            for k in 0..9 {
                assert_eq!(ascii.line(k)[2 + 1], truth.vals[k], "ord {ord} line {k}");
            }
            assert!(ascii.metadata["uff.skipped"].contains("dataset 2411"));
            for little in [true, false] {
                for pyuff in [false, true] {
                    let what = format!("ord {ord} even {even} little {little} pyuff {pyuff}");
                    let bin = read(&file(ord, even, |_| Enc::Binary { little, pyuff }), &what);
                    assert_eq!(bin.values(), ascii.values(), "{what}");
                    assert_eq!(bin.freq_hz_slice(), ascii.freq_hz_slice(), "{what}");
                    assert_eq!(bin.metadata["uff.encoding"], "binary (58b)", "{what}");
                    assert_eq!(bin.metadata["uff.outputs"], "2:+Z 1:+Z", "{what}");
                }
            }
            // ASCII and binary records mixed in one file.
            let mixed = read(
                &file(ord, even, |q| {
                    if q % 2 == 0 {
                        Enc::Ascii
                    } else {
                        Enc::Binary {
                            little: q == 1,
                            pyuff: false,
                        }
                    }
                }),
                "mixed",
            );
            assert_eq!(mixed.values(), ascii.values());
            assert_eq!(mixed.metadata["uff.encoding"], "mixed ASCII and binary");
        }
    }
}

#[test]
fn line_breaks_inside_binary_data_keep_line_numbers() {
    // Values whose bytes are all line feeds, then a broken ASCII record: its error must
    // name the line the text editor shows.
    let mut r = rec(1, 1, 6, true, 4);
    let lf = f64::from_bits(0x0A0A_0A0A_0A0A_0A0A);
    r.vals[1] = C64::new(lf, lf);
    let mut bytes = record(
        &r,
        Enc::Binary {
            little: true,
            pyuff: false,
        },
    );
    let ok = read(&bytes, "lf");
    assert_eq!(ok.values()[1], C64::new(lf, lf));
    let broken_at = bytes.iter().filter(|&&b| b == b'\n').count() + 1;
    bytes.extend_from_slice(b"    -1\n  58\nid\n");
    match parse_uff58_bytes(&bytes, "lf.uff") {
        Err(FrfError::Format { line, problem, .. }) => {
            assert_eq!(problem, FormatProblem::BadRecord);
            // The error is at or after the opening `-1` of the broken dataset.
            assert!(
                line >= broken_at && line <= broken_at + 3,
                "{line} vs {broken_at}"
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn truncated_and_foreign_binary_data_are_errors() {
    let full = record(
        &rec(1, 1, 6, true, 8),
        Enc::Binary {
            little: true,
            pyuff: false,
        },
    );
    // Cut inside the binary data (the last 7 bytes are "\n    -1\n", then 16 bytes of
    // data are dropped).
    let cut = &full[..full.len() - 30];
    match parse_uff58_bytes(cut, "cut.uff") {
        Err(FrfError::Format {
            line,
            column,
            problem,
            detail,
            ..
        }) => {
            assert_eq!(problem, FormatProblem::BadRecord);
            assert_eq!(line, 14, "{detail}");
            assert_eq!(column.as_deref(), Some("record 12 (binary data)"));
            assert!(detail.contains("128 bytes"), "{detail}");
        }
        other => panic!("{other:?}"),
    }
    // Every prefix is an error, never a panic (but the last line break is optional).
    for k in 0..full.len() - 1 {
        assert!(
            parse_uff58_bytes(&full[..k], "p.uff").is_err(),
            "prefix {k}"
        );
    }
    assert!(parse_uff58_bytes(&full[..full.len() - 1], "p.uff").is_ok());
    // DEC VMS floating point.
    let text = String::from_utf8_lossy(&full).replacen(
        "     1     2          11",
        "     1     1          11",
        1,
    );
    let e = parse_uff58_bytes(text.as_bytes(), "vms.uff").unwrap_err();
    assert!(e.to_string().contains("DEC VMS"), "{e}");
    assert!(e.to_string().starts_with("vms.uff:2"), "{e}");
}

fn sample() -> Frf {
    let freqs: Vec<f64> = (0..50).map(|k| 1.0 + 0.1 * k as f64).collect();
    Frf::from_fn(freqs, 3, 2, |k, i, j| {
        let x = (k as f64 * 0.37 + i as f64 + 2.0 * j as f64).sin();
        C64::new(x / 3.0, x.cos() * 1e-7)
    })
    .unwrap()
}

#[test]
fn writer_round_trips_in_every_encoding() {
    let f = sample();
    let md = Default::default();
    for little_endian in [true, false] {
        let b = uff58_bytes(
            &f,
            &md,
            UffEncoding::Binary {
                little_endian,
                double: true,
            },
        )
        .unwrap();
        let back = read(&b, "double");
        assert_eq!(back.values(), f.values());
        let b = uff58_bytes(
            &f,
            &md,
            UffEncoding::Binary {
                little_endian,
                double: false,
            },
        )
        .unwrap();
        let back = read(&b, "single");
        for (a, z) in back.values().iter().zip(f.values()) {
            assert_eq!(a.re, z.re as f32 as f64);
            assert_eq!(a.im, z.im as f32 as f64);
        }
    }
    let back = read(&uff58_bytes(&f, &md, UffEncoding::Ascii).unwrap(), "ascii");
    for (a, z) in back.values().iter().zip(f.values()) {
        assert!((a - z).norm() <= 1e-12 * z.norm(), "{a} vs {z}");
    }
    for (a, b) in back.freq_hz_slice().iter().zip(f.freq_hz_slice()) {
        assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    }
}

#[test]
fn wafer_reference_as_binary_reads_the_ascii_numbers() {
    let Some(path) = require(
        "wafer_reference_as_binary_reads_the_ascii_numbers",
        "uff/wafer_nominal.uff",
    ) else {
        return;
    };
    let ascii = read_uff58(&path).unwrap();
    for little_endian in [true, false] {
        let b = uff58_bytes(
            &ascii,
            &ascii.metadata,
            UffEncoding::Binary {
                little_endian,
                double: true,
            },
        )
        .unwrap();
        let bin = read(&b, "wafer 58b");
        assert_eq!(bin.values(), ascii.values());
        assert_eq!(bin.freq_hz_slice(), ascii.freq_hz_slice());
        assert_eq!(bin.metadata["uff.outputs"], ascii.metadata["uff.outputs"]);
        assert_eq!(bin.metadata["uff.inputs"], ascii.metadata["uff.inputs"]);
        assert_eq!((bin.ny(), bin.nu()), (4, 13));
    }
}
