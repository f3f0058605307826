//! Reading measured data for every front end (the CLI and the Python package): an FRF
//! file with errors that name the path.

use crate::FrfitError;
use frf_data::Frf;
use std::path::Path;

/// Reads an FRF file (FRF CSV, UFF 58 `.uff`/`.unv`, MATLAB `.mat`, by extension); a
/// missing file or a directory gives an error that names the path.
pub fn read(path: &Path) -> Result<Frf, FrfitError> {
    if !path.exists() {
        return Err(FrfitError::Io {
            path: path.display().to_string(),
            message: "no such file".into(),
        });
    }
    if path.is_dir() {
        return Err(FrfitError::Io {
            path: path.display().to_string(),
            message: "is a directory, expected an FRF file".into(),
        });
    }
    Ok(frf_data::io::read_frf(path)?)
}

/// The stochastic nonlinear distortion of a best linear approximation against its noise,
/// from the total variance (`_var`, the spread over realizations) and its noise part
/// (`_var_noise`, the spread over periods); levels relative to the BLA itself.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DistortionLevel {
    /// Median over lines of the mean over entries of `(var - var_noise) / |G|^2`, as an
    /// amplitude ratio in dB (`10 log10`; negative estimates count as 0).
    pub nonlinear_db: f64,
    /// The same of `var_noise / |G|^2`.
    pub noise_db: f64,
    /// Median over lines and entries of `var / var_noise`: 1 for a linear system.
    pub total_to_noise: f64,
    /// The line where the nonlinear part is largest relative to the BLA, Hz.
    pub worst_hz: f64,
    /// Its level there, dB under the BLA.
    pub worst_db: f64,
}

/// The distortion level of `data` when it carries both variances, `None` otherwise.
pub fn distortion_level(data: &Frf) -> Option<DistortionLevel> {
    use frf_data::FrfDataset;
    let (var, noise) = (data.variances()?, data.noise_variances()?);
    let m = data.n_entries();
    let (mut nl, mut nz, mut ratio) = (Vec::new(), Vec::new(), Vec::new());
    let mut worst = (f64::NEG_INFINITY, f64::NAN);
    for k in 0..data.n_lines() {
        let (mut a, mut b, mut c) = (0.0, 0.0, 0usize);
        for e in k * m..(k + 1) * m {
            let g2 = data.values()[e].norm_sqr();
            if g2 > 0.0 {
                a += (var[e] - noise[e]).max(0.0) / g2;
                b += noise[e] / g2;
                c += 1;
            }
            if noise[e] > 0.0 {
                ratio.push(var[e] / noise[e]);
            }
        }
        if c > 0 {
            let (a, b) = (a / c as f64, b / c as f64);
            if a > worst.0 {
                worst = (a, data.freq_hz(k));
            }
            nl.push(a);
            nz.push(b);
        }
    }
    let median = |v: &mut Vec<f64>| -> Option<f64> {
        (!v.is_empty()).then(|| validation::stats::median_mut(v))
    };
    let db = |x: f64| 10.0 * x.max(1e-300).log10();
    Some(DistortionLevel {
        nonlinear_db: db(median(&mut nl)?),
        noise_db: db(median(&mut nz)?),
        total_to_noise: median(&mut ratio)?,
        worst_hz: worst.1,
        worst_db: db(worst.0),
    })
}
