//! Writing an FRF as Universal File datasets 58 (one per output/input pair), ASCII or
//! binary (`58b`), for `frfit convert` and for tests of the reader.
//!
//! Records 1-11 follow the layout the reader documents (see `uff.rs`). Record 12 holds
//! complex values: double precision (ordinate type 6) in ASCII (`E20.12`, 13 significant
//! digits) and in binary by default, single precision (type 5) in binary on request.
//! The abscissa is written evenly spaced when record 7's start and increment (`E13.5`)
//! give back every frequency to 1e-12 relative, and unevenly otherwise: in binary the
//! frequencies are then stored in the ordinate's precision (exact in double), in ASCII
//! as `E13.5` (6 significant digits), which is refused when that would move a line by
//! more than 1e-9 relative (write binary then).

use crate::{FrfDataset, FrfError, C64};
use std::fmt::Write as _;

/// How [`uff58_bytes`] writes record 12.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UffEncoding {
    /// ASCII dataset 58, complex double (`E20.12`).
    Ascii,
    /// Binary dataset 58b.
    Binary {
        /// Little-endian byte order (code 1) or big-endian (code 2).
        little_endian: bool,
        /// Double precision (ordinate type 6) or single (type 5).
        double: bool,
    },
}

impl Default for UffEncoding {
    /// ASCII: every UFF reader understands it.
    fn default() -> Self {
        UffEncoding::Ascii
    }
}

/// `x` as a Fortran `Ew.d` field: `d` decimals, an exponent of at least two digits with
/// its sign, right-aligned in `w` columns.
pub(crate) fn fortran_e(x: f64, w: usize, d: usize) -> String {
    let s = format!("{x:.d$e}");
    let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let e: i32 = exp.parse().unwrap_or(0);
    let sign = if e < 0 { '-' } else { '+' };
    format!("{:>w$}", format!("{mant}E{sign}{:02}", e.unsigned_abs()))
}

/// Node and direction code of each output and input: from the metadata `uff.outputs` /
/// `uff.inputs` of a file read from UFF (`node:dir`), otherwise node `k` (1-based), scalar
/// direction 0.
fn dofs(meta: Option<&String>, n: usize) -> Vec<(i64, i64)> {
    let parsed: Option<Vec<(i64, i64)>> = meta.and_then(|m| {
        m.split_whitespace()
            .map(|w| {
                let (node, dir) = w.split_once(':')?;
                let node: i64 = node.parse().ok()?;
                let (sign, axis) = match dir.as_bytes().first()? {
                    b'-' => (-1, &dir[1..]),
                    b'+' => (1, &dir[1..]),
                    _ => (1, dir),
                };
                let code = match axis {
                    "S" => 0,
                    "X" => 1,
                    "Y" => 2,
                    "Z" => 3,
                    "RX" => 4,
                    "RY" => 5,
                    "RZ" => 6,
                    _ => return None,
                };
                Some((node, sign * code))
            })
            .collect()
    });
    match parsed {
        Some(p) if p.len() == n => p,
        _ => (1..=n as i64).map(|k| (k, 0)).collect(),
    }
}

/// Record 7's start and increment when the axis is even to 1e-12 relative as printed.
fn even_axis(f: &[f64]) -> Option<(f64, f64)> {
    let n = f.len();
    if n < 2 {
        return None;
    }
    let start: f64 = fortran_e(f[0], 13, 5).trim().parse().ok()?;
    let inc: f64 = fortran_e((f[n - 1] - f[0]) / (n - 1) as f64, 13, 5)
        .trim()
        .parse()
        .ok()?;
    let ok = f.iter().enumerate().all(|(k, &x)| {
        let y = start + k as f64 * inc;
        (x - y).abs() <= 1e-12 * x.abs().max(inc.abs())
    });
    (ok && inc > 0.0).then_some((start, inc))
}

/// Splits `units` like `m/N` into numerator and denominator labels.
fn unit_labels(units: Option<&str>) -> (String, String) {
    let clip = |s: &str| s.trim().chars().take(20).collect::<String>();
    match units.map(str::trim).filter(|u| !u.is_empty()) {
        Some(u) => match u.split_once('/') {
            Some((a, b)) => (clip(a), clip(b)),
            None => (clip(u), "NONE".into()),
        },
        None => ("NONE".into(), "NONE".into()),
    }
}

/// The bytes of a UFF file holding `data` as datasets 58 (function type 4), one per
/// entry, column-major (`G1_1`, `G2_1`, ..., `G1_2`, ...). Rows and columns keep their
/// node/direction labels when `data` was read from UFF. [`FrfError::InvalidData`] when
/// ASCII cannot hold the frequency axis to 1e-9 (see the module docs).
pub fn uff58_bytes<D: FrfDataset + ?Sized>(
    data: &D,
    metadata: &std::collections::BTreeMap<String, String>,
    encoding: UffEncoding,
) -> Result<Vec<u8>, FrfError> {
    let (ny, nu, n) = (data.ny(), data.nu(), data.n_lines());
    let freqs: Vec<f64> = (0..n).map(|k| data.freq_hz(k)).collect();
    let even = even_axis(&freqs);
    if encoding == UffEncoding::Ascii && even.is_none() {
        for &x in &freqs {
            let y: f64 = fortran_e(x, 13, 5).trim().parse().unwrap_or(f64::NAN);
            if (x - y).abs() > 1e-9 * x.abs() {
                return Err(FrfError::InvalidData {
                    why: format!(
                        "the frequencies are not evenly spaced and {x} Hz needs more than the \
                         6 significant digits an ASCII UFF 58 abscissa holds; write binary \
                         UFF (58b) instead"
                    ),
                });
            }
        }
    }
    let outputs = dofs(metadata.get("uff.outputs"), ny);
    let inputs = dofs(metadata.get("uff.inputs"), nu);
    let (num_units, den_units) = unit_labels(data.units());
    let m = ny * nu;
    let mut cols: Vec<Vec<C64>> = vec![Vec::with_capacity(n); m];
    let mut line = vec![C64::new(0.0, 0.0); m];
    for k in 0..n {
        data.line_into(k, &mut line);
        for (e, z) in line.iter().enumerate() {
            cols[e].push(*z);
        }
    }
    let mut out: Vec<u8> = Vec::new();
    for j in 0..nu {
        for i in 0..ny {
            let vals = &cols[j * ny + i];
            let (ord, width) = match encoding {
                UffEncoding::Binary { double: false, .. } => (5, 4),
                _ => (6, 8),
            };
            let per_point = if even.is_some() { 2 } else { 3 };
            let mut s = String::from("    -1\n");
            match encoding {
                UffEncoding::Ascii => s.push_str(&format!("{:>6}{:74}\n", 58, "")),
                UffEncoding::Binary { little_endian, .. } => {
                    let _ = writeln!(
                        s,
                        "{:>6}b{:>6}{:>6}{:>12}{:>12}{:>6}{:>6}{:>12}{:>12}",
                        58,
                        if little_endian { 1 } else { 2 },
                        2,
                        11,
                        n * per_point * width,
                        0,
                        0,
                        0,
                        0
                    );
                }
            }
            let _ = writeln!(s, "{:<80}", format!("G{}_{}", i + 1, j + 1));
            for _ in 0..4 {
                let _ = writeln!(s, "{:<80}", "NONE");
            }
            let (rn, rd) = outputs[i];
            let (qn, qd) = inputs[j];
            let _ = writeln!(
                s,
                "{:>5}{:>10}{:>5}{:>10} {:<10}{:>10}{:>4} {:<10}{:>10}{:>4}",
                4, 0, 0, 0, "NONE", rn, rd, "NONE", qn, qd
            );
            let (start, inc) = even.unwrap_or((0.0, 0.0));
            let _ = writeln!(
                s,
                "{:>10}{:>10}{:>10}{}{}{}",
                ord,
                n,
                i32::from(even.is_some()),
                fortran_e(start, 13, 5),
                fortran_e(inc, 13, 5),
                fortran_e(0.0, 13, 5)
            );
            for (t, lab, units) in [
                (18, "Frequency", "Hz"),
                (0, "Response", num_units.as_str()),
                (0, "Reference", den_units.as_str()),
                (0, "NONE", "NONE"),
            ] {
                let _ = writeln!(s, "{t:>10}{:>5}{:>5}{:>5} {lab:<20} {units:<20}", 0, 0, 0);
            }
            out.extend_from_slice(s.as_bytes());
            let mut flat: Vec<f64> = Vec::with_capacity(n * per_point);
            for (k, z) in vals.iter().enumerate() {
                if even.is_none() {
                    flat.push(freqs[k]);
                }
                flat.push(z.re);
                flat.push(z.im);
            }
            match encoding {
                UffEncoding::Ascii => {
                    let mut d = String::new();
                    if even.is_some() {
                        for chunk in flat.chunks(4) {
                            for &x in chunk {
                                d.push_str(&fortran_e(x, 20, 12));
                            }
                            d.push('\n');
                        }
                    } else {
                        for p in flat.chunks(3) {
                            d.push_str(&fortran_e(p[0], 13, 5));
                            d.push_str(&fortran_e(p[1], 20, 12));
                            d.push_str(&fortran_e(p[2], 20, 12));
                            d.push('\n');
                        }
                    }
                    out.extend_from_slice(d.as_bytes());
                }
                UffEncoding::Binary {
                    little_endian,
                    double,
                } => {
                    for &x in &flat {
                        match (double, little_endian) {
                            (true, true) => out.extend_from_slice(&x.to_le_bytes()),
                            (true, false) => out.extend_from_slice(&x.to_be_bytes()),
                            (false, true) => out.extend_from_slice(&(x as f32).to_le_bytes()),
                            (false, false) => out.extend_from_slice(&(x as f32).to_be_bytes()),
                        }
                    }
                    out.push(b'\n');
                }
            }
            out.extend_from_slice(b"    -1\n");
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Frf;

    #[test]
    fn fortran_fields() {
        assert_eq!(fortran_e(0.25, 13, 5), "  2.50000E-01");
        assert_eq!(fortran_e(-1999.75, 20, 12), " -1.999750000000E+03");
        assert_eq!(fortran_e(0.0, 13, 5), "  0.00000E+00");
        assert_eq!(fortran_e(1e-100, 13, 5), " 1.00000E-100");
    }

    #[test]
    fn even_axis_detection() {
        assert_eq!(even_axis(&[0.25, 0.5, 0.75]), Some((0.25, 0.25)));
        assert_eq!(even_axis(&[1.0, 2.0, 4.0]), None);
        assert_eq!(even_axis(&[1.0]), None);
        // An increment that E13.5 cannot hold.
        assert_eq!(even_axis(&[0.0, 1.0 / 3.0, 2.0 / 3.0]), None);
    }

    #[test]
    fn ascii_refuses_an_axis_it_cannot_hold() {
        let f = Frf::from_fn(vec![1.0, 1.0 + 1e-7, 3.0], 1, 1, |_, _, _| {
            C64::new(1.0, 0.0)
        })
        .unwrap();
        let e = uff58_bytes(&f, &Default::default(), UffEncoding::Ascii).unwrap_err();
        assert!(e.to_string().contains("binary"), "{e}");
        let b = uff58_bytes(
            &f,
            &Default::default(),
            UffEncoding::Binary {
                little_endian: true,
                double: true,
            },
        );
        assert!(b.is_ok());
    }
}
