//! `frfit cmif DATA`: the complex mode indicator function (Shih et al. 1988; section
//! 4.4 and Fig. 3 of the wafer-stage paper) and the modes its peaks indicate.

use super::common::{fmt_num, load_data, parse_band, select_band, Band};
use clap::Args as ClapArgs;
use frf_data::cmif::{cmif, pick_peaks, PeakConfig};
use frf_data::FrfDataset;
use frfit::FrfitError;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `frfit cmif`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// FRF file (CSV as in FORMATS.md, or UFF 58 with extension .uff/.unv).
    pub data: PathBuf,
    /// Frequency band LO:HI in Hz (either side may be empty: `20:`, `:500`).
    #[arg(long, value_parser = parse_band, value_name = "LO:HI")]
    pub band: Option<Band>,
    /// Report only the N most prominent peaks.
    #[arg(long, value_name = "N")]
    pub modes: Option<usize>,
    /// Minimum prominence of a peak, dB (default: the picker's default, 3 dB).
    #[arg(long, value_name = "DB")]
    pub min_prominence: Option<f64>,
    /// Write the CMIF figure (singular values and picked peaks) to this SVG file.
    #[arg(long, value_name = "FILE")]
    pub svg: Option<PathBuf>,
    /// Print JSON to stdout: {"peaks": [{"f_hz", "sv_index" (0-based), "prominence" (dB),
    /// "damping" (half-power estimate or null), "line", "sv2"}], "band_hz": [lo, hi] (first
    /// and last line used), "n_lines"}.
    #[arg(long)]
    pub json: bool,
}

/// Runs `frfit cmif`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let d = load_data(&args.data)?;
    let view = select_band(&d, args.band)?;
    let mut cfg = PeakConfig {
        n_modes: args.modes,
        ..PeakConfig::default()
    };
    if let Some(p) = args.min_prominence {
        if !p.is_finite() {
            return Err(FrfitError::argument(
                "--min-prominence",
                p,
                "must be a finite number of dB",
            ));
        }
        cfg.min_prominence_db = p;
    }
    if args.modes == Some(0) {
        return Err(FrfitError::argument("--modes", 0, "must be at least 1"));
    }
    let c = cmif(&view)?;
    let peaks = pick_peaks(&c, &cfg);
    let n = view.n_lines();
    let (lo, hi) = (view.freq_hz(0), view.freq_hz(n - 1));
    let title = format!(
        "CMIF of {} ({} x {}, {}..{} Hz)",
        args.data
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| args.data.display().to_string()),
        view.ny(),
        view.nu(),
        fmt_num(lo),
        fmt_num(hi)
    );
    if let Some(svg) = &args.svg {
        frfit::plots::cmif_svg(svg, &c, &peaks, &title)?;
        if !quiet && !args.json {
            eprintln!("wrote {}", svg.display());
        }
    }
    if args.json {
        let v = json!({
            "peaks": peaks.iter().map(|p| json!({
                "f_hz": p.f_hz,
                "sv_index": p.sv_index,
                "prominence": p.prominence,
                "damping": p.damping,
                "line": p.line,
                "sv2": p.sv2,
            })).collect::<Vec<_>>(),
            "band_hz": [lo, hi],
            "n_lines": n,
        });
        println!("{v}");
        return Ok(());
    }
    println!("{title}");
    println!(
        "{} lines, {} singular value(s) per line, variance {}",
        n,
        c.n_sv(),
        if view.has_variance() {
            "present (noise-aware prominence)"
        } else {
            "absent"
        }
    );
    if peaks.is_empty() {
        println!(
            "no peak passed the tests (prominence >= {} dB)",
            cfg.min_prominence_db
        );
        return Ok(());
    }
    println!(
        "{:>4}  {:>12}  {:>6}  {:>16}  {:>8}",
        "#", "f [Hz]", "sigma", "prominence [dB]", "damping"
    );
    for (i, p) in peaks.iter().enumerate() {
        let z = p
            .damping
            .map(|z| format!("{z:.4}"))
            .unwrap_or_else(|| "-".into());
        println!(
            "{:>4}  {:>12.3}  {:>6}  {:>16.1}  {:>8}",
            i + 1,
            p.f_hz,
            p.sv_index + 1,
            p.prominence,
            z
        );
    }
    println!(
        "{} peak(s); sigma: 1-based singular value index; damping: half-power estimate from \
         the enhanced FRF",
        peaks.len()
    );
    Ok(())
}
