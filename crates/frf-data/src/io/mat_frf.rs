//! FRFs in MATLAB `.mat` files (level 5, see [`super::mat5`]): an array `G` of size
//! `ny x nu x nf` (complex) and a frequency vector `freq_hz` of `nf` values in Hz,
//! optionally `G_var` (`ny x nu x nf`, real: the variance of each estimate, as the
//! `_var` columns of the FRF CSV).
//!
//! In MATLAB:
//!
//! ```text
//! G = frd_sys.ResponseData;  freq_hz = frd_sys.Frequency / (2*pi);   % frd in rad/s
//! save('frf.mat', 'G', 'freq_hz', '-v7')
//! ```
//!
//! The array may also be named `H` or `FRF`, the frequencies `f`, `freq` or `f_hz` (all in
//! Hz). MATLAB drops trailing singleton dimensions, so a single line is stored as
//! `ny x nu`; a SISO FRF may also be a vector of `nf` values.

use super::mat5::{mat5_bytes, parse_mat5, MatValue, MatVar, MatWrite};
use crate::{FormatProblem, Frf, FrfDataset, FrfError, C64};

/// Names accepted for the FRF array, in order of preference.
pub const FRF_NAMES: [&str; 4] = ["G", "H", "FRF", "frf"];
/// Names accepted for the frequency vector (Hz), in order of preference.
pub const FREQ_NAMES: [&str; 4] = ["freq_hz", "f_hz", "freq", "f"];

fn err(file: &str, var: &str, problem: FormatProblem, detail: String) -> FrfError {
    FrfError::format(file, 0, Some(var), problem, detail)
}

/// What the file holds, for error messages: numeric variables with their size, others
/// with their kind.
fn inventory(vars: &[MatVar]) -> String {
    let list: Vec<String> = vars
        .iter()
        .filter(|v| !v.name.is_empty())
        .map(|v| match &v.value {
            MatValue::Numeric { dims, imag, .. } => format!(
                "`{}` ({} {})",
                v.name,
                dims.iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join("x"),
                if imag.is_some() { "complex" } else { "real" }
            ),
            MatValue::Other(kind) => format!("`{}` ({kind})", v.name),
        })
        .collect();
    if list.is_empty() {
        "no variables".into()
    } else {
        list.join(", ")
    }
}

/// The first variable with one of `names`.
fn find<'a>(vars: &'a [MatVar], names: &[&str]) -> Option<&'a MatVar> {
    names
        .iter()
        .find_map(|n| vars.iter().find(|v| v.name == *n))
}

/// Parses the bytes of a `.mat` file holding an FRF (see the module docs); `file` names
/// it in errors and becomes [`Frf::source`].
///
/// Errors ([`FrfError::Format`] with the variable as the column): `NotFound` when no
/// FRF array or frequency vector is there (the message lists what the file holds);
/// `BadRecord` for an array of the wrong shape or type (the message names the variable
/// and the shape expected), `NonFinite`, `BadFrequency`, `NotIncreasing`,
/// `NegativeVariance` for bad values; the errors of [`parse_mat5`] for a malformed file.
pub fn parse_frf_mat(bytes: &[u8], file: &str) -> Result<Frf, FrfError> {
    let vars = parse_mat5(bytes, file)?;
    let Some(gv) = find(&vars, &FRF_NAMES) else {
        return Err(err(
            file,
            "G",
            FormatProblem::NotFound,
            format!(
                "no FRF array `G` (or {}) in the file, which holds {}; save the complex \
                 ny x nu x nf response as `G` and the frequencies in Hz as `freq_hz` (from an \
                 frd object: G = sys.ResponseData; freq_hz = sys.Frequency/(2*pi) when it is \
                 in rad/s)",
                FRF_NAMES[1..].join(", "),
                inventory(&vars)
            ),
        ));
    };
    let Some(fv) = find(&vars, &FREQ_NAMES) else {
        return Err(err(
            file,
            "freq_hz",
            FormatProblem::NotFound,
            format!(
                "no frequency vector `freq_hz` (or {}) in the file, which holds {}",
                FREQ_NAMES[1..].join(", "),
                inventory(&vars)
            ),
        ));
    };
    let (g, f) = (&gv.name, &fv.name);
    let freq_hz = match &fv.value {
        MatValue::Numeric {
            dims,
            real,
            imag: None,
        } if dims.iter().filter(|&&d| d != 1).count() <= 1 && !real.is_empty() => real.clone(),
        MatValue::Numeric { dims, imag, .. } => {
            return Err(err(
                file,
                f,
                FormatProblem::BadRecord,
                format!(
                    "`{f}` is a {} {:?} array; expected a real vector of nf frequencies in Hz",
                    if imag.is_some() { "complex" } else { "real" },
                    dims
                ),
            ))
        }
        MatValue::Other(kind) => {
            return Err(err(
                file,
                f,
                FormatProblem::BadRecord,
                format!("`{f}` is a {kind}; expected a real vector of frequencies in Hz"),
            ))
        }
    };
    let nf = freq_hz.len();
    for (k, &x) in freq_hz.iter().enumerate() {
        if !x.is_finite() || x < 0.0 {
            return Err(err(
                file,
                f,
                if x.is_finite() {
                    FormatProblem::BadFrequency
                } else {
                    FormatProblem::NonFinite
                },
                format!(
                    "`{f}({})` is {x} Hz: frequencies must be finite and >= 0",
                    k + 1
                ),
            ));
        }
        if k > 0 && x <= freq_hz[k - 1] {
            return Err(err(
                file,
                f,
                FormatProblem::NotIncreasing,
                format!(
                    "`{f}` must increase strictly: `{f}({})` = {x} Hz follows {} Hz",
                    k + 1,
                    freq_hz[k - 1]
                ),
            ));
        }
    }
    let expected = format!(
        "expected a complex ny x nu x nf array with nf = {nf} (the length of `{f}`), or a \
         vector of {nf} values for one output and one input"
    );
    let (dims, real, imag) = match &gv.value {
        MatValue::Numeric {
            dims,
            real,
            imag: Some(imag),
        } => (dims, real, imag),
        MatValue::Numeric { dims, .. } => {
            return Err(err(
                file,
                g,
                FormatProblem::BadRecord,
                format!(
                    "`{g}` ({dims:?}) is real; an FRF is complex (save the complex response, \
                     not its magnitude); {expected}"
                ),
            ))
        }
        MatValue::Other(kind) => {
            return Err(err(
                file,
                g,
                FormatProblem::BadRecord,
                format!("`{g}` is a {kind}; {expected}"),
            ))
        }
    };
    let vector = dims.iter().filter(|&&d| d != 1).count() <= 1;
    let (ny, nu) = match dims.as_slice() {
        [ny, nu, n] if *n == nf => (*ny, *nu),
        [ny, nu] if nf == 1 => (*ny, *nu),
        _ if vector && real.len() == nf => (1, 1),
        _ => {
            return Err(err(
                file,
                g,
                FormatProblem::BadRecord,
                format!("`{g}` is {dims:?}; {expected}"),
            ))
        }
    };
    if ny == 0 || nu == 0 {
        return Err(err(
            file,
            g,
            FormatProblem::BadRecord,
            format!("`{g}` is {dims:?}: no outputs or no inputs"),
        ));
    }
    let values: Vec<C64> = real
        .iter()
        .zip(imag)
        .map(|(&re, &im)| C64::new(re, im))
        .collect();
    let m = ny * nu;
    if let Some(idx) = values
        .iter()
        .position(|z| !(z.re.is_finite() && z.im.is_finite()))
    {
        let (k, e) = (idx / m, idx % m);
        return Err(err(
            file,
            g,
            FormatProblem::NonFinite,
            format!(
                "`{g}({},{},{})` = {} at {} Hz is not finite",
                e % ny + 1,
                e / ny + 1,
                k + 1,
                values[idx],
                freq_hz[k]
            ),
        ));
    }
    let var_name = format!("{g}_var");
    let variance = match vars.iter().find(|v| v.name == var_name).map(|v| &v.value) {
        None => None,
        Some(MatValue::Numeric {
            real: v,
            imag: None,
            ..
        }) if v.len() == nf * m => {
            if let Some(idx) = v.iter().position(|x| !x.is_finite() || *x < 0.0) {
                let (k, e) = (idx / m, idx % m);
                return Err(err(
                    file,
                    &var_name,
                    FormatProblem::NegativeVariance,
                    format!(
                        "`{var_name}({},{},{})` = {}: variances must be finite and >= 0",
                        e % ny + 1,
                        e / ny + 1,
                        k + 1,
                        v[idx]
                    ),
                ));
            }
            Some(v.clone())
        }
        Some(_) => {
            return Err(err(
                file,
                &var_name,
                FormatProblem::BadRecord,
                format!("`{var_name}` must be a real {ny} x {nu} x {nf} array, like `{g}`"),
            ))
        }
    };
    let mut frf = Frf::new(freq_hz, ny, nu, values, variance)?;
    frf.metadata.insert("mat.frf".into(), g.clone());
    frf.metadata.insert("mat.freq".into(), f.clone());
    frf.source = Some(file.to_string());
    Ok(frf)
}

/// The bytes of a `.mat` file (level 5, readable by MATLAB's `load` and SciPy's
/// `loadmat`) holding `data` as `G` (`ny x nu x nf`, complex), `freq_hz` (`nf x 1`) and,
/// when the data carry variances, `G_var` (`ny x nu x nf`).
pub fn frf_mat_bytes<D: FrfDataset + ?Sized>(data: &D) -> Vec<u8> {
    let (ny, nu, n) = (data.ny(), data.nu(), data.n_lines());
    let m = ny * nu;
    let freqs: Vec<f64> = (0..n).map(|k| data.freq_hz(k)).collect();
    let mut re = Vec::with_capacity(n * m);
    let mut im = Vec::with_capacity(n * m);
    let mut var = Vec::with_capacity(if data.has_variance() { n * m } else { 0 });
    let mut line = vec![C64::new(0.0, 0.0); m];
    let mut vline = vec![0.0; m];
    for k in 0..n {
        data.line_into(k, &mut line);
        re.extend(line.iter().map(|z| z.re));
        im.extend(line.iter().map(|z| z.im));
        if data.has_variance() && data.variance_line_into(k, &mut vline) {
            var.extend_from_slice(&vline);
        }
    }
    let dims = [ny, nu, n];
    let fdims = [n, 1];
    let mut vars = vec![
        MatWrite {
            name: "G",
            dims: &dims,
            real: &re,
            imag: Some(&im),
        },
        MatWrite {
            name: "freq_hz",
            dims: &fdims,
            real: &freqs,
            imag: None,
        },
    ];
    if var.len() == n * m && !var.is_empty() {
        vars.push(MatWrite {
            name: "G_var",
            dims: &dims,
            real: &var,
            imag: None,
        });
    }
    mat5_bytes(&vars)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_bit_exact() {
        let f = Frf::from_fn(vec![0.5, 1.0, 2.5], 2, 3, |k, i, j| {
            C64::new(k as f64 + 0.1 * i as f64, -(j as f64) / 3.0)
        })
        .unwrap()
        .with_variance(Some((0..18).map(|x| x as f64 * 1e-3).collect()))
        .unwrap();
        let back = parse_frf_mat(&frf_mat_bytes(&f), "x.mat").unwrap();
        assert_eq!(back.values(), f.values());
        assert_eq!(back.freq_hz_slice(), f.freq_hz_slice());
        assert_eq!(back.variances(), f.variances());
        assert_eq!((back.ny(), back.nu()), (2, 3));
    }

    fn file(vars: &[MatWrite<'_>]) -> Vec<u8> {
        mat5_bytes(vars)
    }

    #[test]
    fn shapes_and_names() {
        let fr = [1.0, 2.0, 3.0];
        let re = [1.0, 2.0, 3.0];
        let im = [0.0, 1.0, 0.5];
        // A SISO vector named H with frequencies `f`.
        let b = file(&[
            MatWrite {
                name: "H",
                dims: &[3, 1],
                real: &re,
                imag: Some(&im),
            },
            MatWrite {
                name: "f",
                dims: &[1, 3],
                real: &fr,
                imag: None,
            },
        ]);
        let x = parse_frf_mat(&b, "s.mat").unwrap();
        assert_eq!((x.ny(), x.nu(), x.n_lines()), (1, 1, 3));
        // Wrong shape: the message names the variable and the shape expected.
        let b = file(&[
            MatWrite {
                name: "G",
                dims: &[3, 2],
                real: &[0.0; 6],
                imag: Some(&[0.0; 6]),
            },
            MatWrite {
                name: "freq_hz",
                dims: &[3, 1],
                real: &fr,
                imag: None,
            },
        ]);
        let e = parse_frf_mat(&b, "w.mat").unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains("`G` is [3, 2]") && s.contains("ny x nu x nf"),
            "{s}"
        );
        // Real G.
        let b = file(&[
            MatWrite {
                name: "G",
                dims: &[1, 1, 3],
                real: &re,
                imag: None,
            },
            MatWrite {
                name: "freq_hz",
                dims: &[3, 1],
                real: &fr,
                imag: None,
            },
        ]);
        let e = parse_frf_mat(&b, "r.mat").unwrap_err();
        assert!(e.to_string().contains("is real"), "{e}");
        // Nothing usable: the inventory is listed.
        let b = file(&[MatWrite {
            name: "y",
            dims: &[3, 1],
            real: &re,
            imag: None,
        }]);
        let e = parse_frf_mat(&b, "n.mat").unwrap_err();
        assert_eq!(e.problem(), Some(FormatProblem::NotFound));
        assert!(e.to_string().contains("`y` (3x1 real)"), "{e}");
    }
}
