//! `frfit info DATA`: what a dataset holds (dimensions, band, lines, spacing, units,
//! variance and noise level, metadata).

use super::common::{fmt_num, load_data, quantile};
use clap::Args as ClapArgs;
use frf_data::{Frf, FrfDataset};
use frfit::FrfitError;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `frfit info`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// FRF file: CSV as in FORMATS.md (any spreadsheet dialect), UFF 58 (.uff/.unv,
    /// ASCII or binary) or MATLAB (.mat with `G` and `freq_hz`).
    pub data: PathBuf,
    /// Print a JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Summary statistics of a dataset, computed once for both outputs.
struct Summary {
    n_lines: usize,
    f_lo: f64,
    f_hi: f64,
    /// (min, median, max) line spacing, Hz, when there are two lines or more.
    spacing: Option<(f64, f64, f64)>,
    uniform: bool,
    /// median and 95th percentile of sqrt(var)/|G| over lines and entries.
    noise: Option<(f64, f64)>,
}

fn summarise(d: &Frf) -> Summary {
    let n = d.n_lines();
    let f = d.freq_hz_slice();
    let (f_lo, f_hi) = if n > 0 {
        (f[0], f[n - 1])
    } else {
        (f64::NAN, f64::NAN)
    };
    let mut df: Vec<f64> = f.windows(2).map(|w| w[1] - w[0]).collect();
    let spacing = if df.is_empty() {
        None
    } else {
        let lo = df.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = df.iter().copied().fold(0.0, f64::max);
        quantile(&mut df, 0.5).map(|med| (lo, med, hi))
    };
    let uniform = spacing.is_some_and(|(lo, med, hi)| hi - lo <= 1e-6 * med.abs().max(1e-300));
    let noise = d.variances().and_then(|var| {
        let mut r: Vec<f64> = d
            .values()
            .iter()
            .zip(var)
            .filter_map(|(g, v)| {
                let a = g.norm();
                (a > 0.0).then(|| v.sqrt() / a)
            })
            .collect();
        let med = quantile(&mut r, 0.5)?;
        let p95 = quantile(&mut r, 0.95)?;
        Some((med, p95))
    });
    Summary {
        n_lines: n,
        f_lo,
        f_hi,
        spacing,
        uniform,
        noise,
    }
}

/// The file format and variant that was read, from the reader's metadata.
fn format_read(d: &Frf) -> String {
    let md = &d.metadata;
    if let Some(dialect) = md.get("csv.dialect") {
        format!("FRF CSV ({dialect})")
    } else if let Some(enc) = md.get("uff.encoding") {
        format!(
            "UFF dataset 58, {enc}, {}",
            md.get("uff.ordinate").map_or("", String::as_str)
        )
    } else if let (Some(g), Some(f)) = (md.get("mat.frf"), md.get("mat.freq")) {
        format!("MATLAB .mat (level 5), `{g}` and `{f}`")
    } else {
        "unknown".into()
    }
}

/// A relative level in dB (`20 log10`).
fn fmt_db(r: f64) -> String {
    if r > 0.0 && r.is_finite() {
        format!("{:.1} dB", 20.0 * r.log10())
    } else {
        "-inf dB".into()
    }
}

/// Runs `frfit info`.
pub fn run(args: Args, _quiet: bool) -> Result<(), FrfitError> {
    let d = load_data(&args.data)?;
    let s = summarise(&d);
    let path = args.data.display().to_string();
    if args.json {
        let v = json!({
            "file": path,
            "format": format_read(&d),
            "ny": d.ny(),
            "nu": d.nu(),
            "n_lines": s.n_lines,
            "band_hz": [s.f_lo, s.f_hi],
            "line_spacing_hz": s.spacing.map(|(lo, med, hi)| json!({"min": lo, "median": med, "max": hi, "uniform": s.uniform})),
            "has_variance": d.has_variance(),
            "units": d.units(),
            "noise_rel": s.noise.map(|(m, p)| json!({"median": m, "p95": p})),
            "nonlinear_distortion": frfit::data::distortion_level(&d),
            "metadata": d.metadata,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&v).unwrap_or_else(|_| v.to_string())
        );
        return Ok(());
    }
    println!("file:         {path}");
    println!("format:       {}", format_read(&d));
    println!(
        "dimensions:   {} output(s) x {} input(s) ({} entries)",
        d.ny(),
        d.nu(),
        d.n_entries()
    );
    println!(
        "band:         {} .. {} Hz",
        fmt_num(s.f_lo),
        fmt_num(s.f_hi)
    );
    println!("lines:        {}", s.n_lines);
    match s.spacing {
        None => println!("line spacing: - (a single line)"),
        Some((_, med, _)) if s.uniform => println!("line spacing: {} Hz (uniform)", fmt_num(med)),
        Some((lo, med, hi)) => println!(
            "line spacing: non-uniform: min {} Hz, median {} Hz, max {} Hz",
            fmt_num(lo),
            fmt_num(med),
            fmt_num(hi)
        ),
    }
    println!("units:        {}", d.units().unwrap_or("not given"));
    if d.has_noise_variance() {
        println!(
            "variance:     present: total (_var, spread over realizations) and its noise part (_var_noise)"
        );
    } else if d.has_variance() {
        println!("variance:     present (_var columns)");
    } else {
        println!("variance:     absent");
    }
    match s.noise {
        Some((m, p)) => println!(
            "noise:        sqrt(var)/|G| median {} ({}), 95th percentile {} ({}) over all lines and entries",
            fmt_num(m),
            fmt_db(m),
            fmt_num(p),
            fmt_db(p)
        ),
        None if d.has_variance() => {
            println!("noise:        variance present but every |G| is zero; no relative level")
        }
        None => println!("noise:        unknown: the data carry no variance"),
    }
    if let Some(l) = frfit::data::distortion_level(&d) {
        println!(
            "distortion:   nonlinear part {:+.1} dB relative to the BLA (median over lines), noise part {:+.1} dB; total/noise variance {:.3} (1 for a linear system); largest {:+.1} dB at {} Hz",
            l.nonlinear_db,
            l.noise_db,
            l.total_to_noise,
            l.worst_db,
            fmt_num(l.worst_hz)
        );
    } else if d.has_variance() {
        println!(
            "distortion:   unknown: the variance has no noise part (_var_noise; one realization, or not stated)"
        );
    }
    if d.metadata.is_empty() {
        println!("metadata:     none");
    } else {
        println!("metadata:");
        for (k, v) in &d.metadata {
            println!("  {k} = {v}");
        }
    }
    Ok(())
}
