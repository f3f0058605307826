//! `cargo xtask bench-scale`: wall time, peak memory and accuracy of `frfit fit` on
//! random modal plants of growing size (issue: large MIMO FRFs).
//!
//! For every size `NYxNUxK` a seeded random plant (`experiment::synth::RandomModal`:
//! rank-one modes, 10 % close pairs, `--lines` uniform lines, relative noise with its
//! variance) is written as FRF CSV, and the release `frfit` binary fits it as a user
//! would (`frfit fit DATA --delay none --hold none --init I --refine R`), in a child
//! process: the wall time is the child's, the peak memory its resident high-water mark
//! (`VmHWM` of `/proc/PID/status`, sampled every 20 ms while it runs: Linux only). The
//! fitted model is then compared with the truth: modes found within 0.1 % in frequency
//! (one-to-one, nearest first), spurious modes, and the median relative error of the
//! model against the noiseless response, beside the data's own noise.
//!
//! The table goes to stdout and `OUT/bench-scale.md`.

use crate::{Context, Error};
use clap::Args as ClapArgs;
use experiment::synth::{RandomModal, RandomModalConfig};
use frf_data::{FrfDataset, ModelStructure};
use frfit::additive_riv::ModelFile;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Arguments of `cargo xtask bench-scale`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Sizes `NYxNUxMODES`, comma-separated.
    #[arg(long, default_value = "4x13x17,20x20x50,50x50x100")]
    pub sizes: String,
    /// Lines per plant.
    #[arg(long, default_value_t = 4000)]
    pub lines: usize,
    /// Relative noise (standard deviation over the median magnitude).
    #[arg(long, default_value_t = 1e-3)]
    pub noise: f64,
    /// Seed of the plants.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Band of the lines and the modes, `LO:HI` Hz.
    #[arg(long, default_value = "50:2000")]
    pub band: String,
    /// Give the plants a free rigid body (a double integrator of rank min(3, ny, nu)).
    #[arg(long)]
    pub rigid_body: bool,
    /// Keep each plant's data file (`OUT/SIZE.csv`) for a rerun by hand.
    #[arg(long)]
    pub keep_data: bool,
    /// Initialiser(s) of the chain (`frfit fit --init`).
    #[arg(long, default_value = "subspace")]
    pub init: String,
    /// Refiner of the chain (`frfit fit --refine`).
    #[arg(long, default_value = "ml")]
    pub refine: String,
    /// Extra arguments passed to `frfit fit` (one string, split at blanks).
    #[arg(long, default_value = "")]
    pub fit_args: String,
    /// Output directory (data, models, the table).
    #[arg(long, default_value = "target/bench-scale")]
    pub out: PathBuf,
}

/// One size's result.
struct Row {
    size: String,
    wall_s: f64,
    peak_mb: Option<f64>,
    outcome: Result<Accuracy, String>,
}

struct Accuracy {
    found: usize,
    modes: usize,
    fitted: usize,
    median_error: f64,
    convergence: String,
}

fn parse_size(s: &str) -> Result<(usize, usize, usize), Error> {
    let v: Vec<usize> = s
        .split('x')
        .map(|t| t.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| Error::new("--sizes", format!("`{s}` is not NYxNUxMODES")))?;
    match v.as_slice() {
        [ny, nu, k] if *ny > 0 && *nu > 0 => Ok((*ny, *nu, *k)),
        _ => Err(Error::new("--sizes", format!("`{s}` is not NYxNUxMODES"))),
    }
}

fn parse_band(s: &str) -> Result<(f64, f64), Error> {
    let bad = || {
        Error::new(
            "--band",
            format!("`{s}` is not LO:HI in Hz with 0 < LO < HI"),
        )
    };
    let (lo, hi) = s.split_once(':').ok_or_else(bad)?;
    let lo: f64 = lo.trim().parse().map_err(|_| bad())?;
    let hi: f64 = hi.trim().parse().map_err(|_| bad())?;
    if lo > 0.0 && hi > lo && hi.is_finite() {
        Ok((lo, hi))
    } else {
        Err(bad())
    }
}

/// The `frfit` binary beside this one (both are built in the release profile).
pub(crate) fn frfit_binary() -> Result<PathBuf, Error> {
    let me = std::env::current_exe().stage("frfit binary")?;
    let dir = me
        .parent()
        .ok_or_else(|| Error::new("frfit binary", "no directory"))?;
    let bin = dir.join(format!("frfit{}", std::env::consts::EXE_SUFFIX));
    if !bin.exists() {
        let st = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
            .args(["build", "--release", "-p", "frfit", "--bin", "frfit"])
            .status()
            .stage("cargo build -p frfit")?;
        if !st.success() || !bin.exists() {
            return Err(Error::new(
                "frfit binary",
                format!("{} was not built", bin.display()),
            ));
        }
    }
    Ok(bin)
}

/// Runs `cmd`, returning its success, wall time and peak resident memory (MB).
pub(crate) fn run_measured(cmd: &mut Command) -> Result<(bool, f64, Option<f64>), Error> {
    let t0 = Instant::now();
    let mut child = cmd.spawn().stage("frfit fit")?;
    let status_file = format!("/proc/{}/status", child.id());
    let mut peak_kb: Option<f64> = None;
    let status = loop {
        if let Ok(text) = std::fs::read_to_string(&status_file) {
            if let Some(kb) = text
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
            {
                peak_kb = Some(peak_kb.map_or(kb, |p: f64| p.max(kb)));
            }
        }
        if let Some(st) = child.try_wait().stage("frfit fit")? {
            break st;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Ok((
        status.success(),
        t0.elapsed().as_secs_f64(),
        peak_kb.map(|k| k / 1024.0),
    ))
}

fn accuracy(model: &Path, r: &RandomModal) -> Result<Accuracy, Error> {
    let mf = ModelFile::read(model).stage("model.json")?;
    let m = mf.to_model().stage("model.json")?;
    let omega = r.noiseless.omegas();
    let pred = m.response_at(&omega);
    let exact = r.noiseless.values_vec();
    let (ny, nu) = (r.noiseless.ny(), r.noiseless.nu());
    // median over lines of the relative Frobenius error per line
    let mut e: Vec<f64> = (0..omega.len())
        .map(|k| {
            let (mut num, mut den) = (0.0, 0.0);
            for i in 0..ny {
                for j in 0..nu {
                    let g0 = exact[k * ny * nu + j * ny + i];
                    num += (pred.line(k)[j * ny + i] - g0).norm_sqr();
                    den += g0.norm_sqr();
                }
            }
            (num / den.max(f64::MIN_POSITIVE)).sqrt()
        })
        .collect();
    e.sort_by(f64::total_cmp);
    let median_error = e[e.len() / 2];
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let fit_f: Vec<f64> = mf.modes.iter().map(|m| m.f_hz).collect();
    // one-to-one, nearest first (the matching of the wafer-stage validation); the
    // matches within 0.1 % are the same as those of a matching within 0.1 %, since the
    // closest pairs are taken first
    let found = crate::validate::match_modes(&true_f, &fit_f)
        .iter()
        .zip(&true_f)
        .filter(|(m, &ft)| m.is_some_and(|j| (fit_f[j] - ft).abs() / ft <= 1e-3))
        .count();
    Ok(Accuracy {
        found,
        modes: true_f.len(),
        fitted: fit_f.len(),
        median_error,
        convergence: mf.provenance.convergence.clone(),
    })
}

/// Runs the benchmark.
pub fn run(a: Args) -> Result<(), Error> {
    let sizes: Vec<(usize, usize, usize)> = a
        .sizes
        .split(',')
        .map(parse_size)
        .collect::<Result<_, _>>()?;
    let band_hz = parse_band(&a.band)?;
    std::fs::create_dir_all(&a.out).stage("output directory")?;
    let bin = frfit_binary()?;
    let mut rows = Vec::new();
    for &(ny, nu, k) in &sizes {
        let size = format!("{ny}x{nu}x{k}");
        eprintln!("bench-scale {size}: simulating {} lines", a.lines);
        let cfg = RandomModalConfig {
            ny,
            nu,
            modes: k,
            lines: a.lines,
            band_hz,
            rigid_body: a.rigid_body,
            noise: a.noise,
            seed: a.seed,
            ..RandomModalConfig::default()
        };
        let r = RandomModal::generate(&cfg).stage("simulate")?;
        let data = a.out.join(format!("{size}.csv"));
        frf_data::io::write_frf_csv(&data, &r.measured, &[format!("bench-scale {size}")])
            .stage("write data")?;
        let model = a.out.join(format!("{size}.model.json"));
        let log = a.out.join(format!("{size}.log"));
        let log_file = std::fs::File::create(&log).stage("log file")?;
        let mut cmd = Command::new(&bin);
        cmd.arg("fit")
            .arg(&data)
            .args(["--delay", "none", "--hold", "none", "--quiet"])
            .args(["--init", &a.init, "--refine", &a.refine])
            .args(a.fit_args.split_whitespace())
            .arg("--out")
            .arg(&model)
            .stdout(log_file.try_clone().stage("log file")?)
            .stderr(log_file);
        eprintln!(
            "bench-scale {size}: frfit fit --init {} --refine {}",
            a.init, a.refine
        );
        let (ok, wall_s, peak_mb) = run_measured(&mut cmd)?;
        let outcome = if ok {
            accuracy(&model, &r).map_err(|e| e.to_string())
        } else {
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            Err(text
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("failed")
                .to_string())
        };
        rows.push(Row {
            size,
            wall_s,
            peak_mb,
            outcome,
        });
        if !a.keep_data {
            std::fs::remove_file(&data).ok();
        }
    }
    let mut md = format!(
        "# frfit fit at scale\n\n`--init {} --refine {}`, {} uniform lines {}..{} Hz, relative noise {:.0e}, seed {}, rank-one modes with 10 % close pairs{} (`frfit simulate random-modal`).\n\n| size (ny x nu x modes) | wall [s] | peak RSS [MB] | modes within 0.1 % | fitted modes | median error vs noiseless | noise std / median abs | last link |\n|---|---|---|---|---|---|---|---|\n",
        a.init,
        a.refine,
        a.lines,
        band_hz.0,
        band_hz.1,
        a.noise,
        a.seed,
        if a.rigid_body {
            ", a free rigid body"
        } else {
            ""
        }
    );
    for r in &rows {
        let mem = r.peak_mb.map_or("n/a".into(), |m| format!("{m:.0}"));
        match &r.outcome {
            Ok(acc) => {
                let _ = writeln!(
                    md,
                    "| {} | {:.1} | {mem} | {}/{} | {} | {:.2e} | {:.0e} | {} |",
                    r.size,
                    r.wall_s,
                    acc.found,
                    acc.modes,
                    acc.fitted,
                    acc.median_error,
                    a.noise,
                    acc.convergence.replace('|', "/")
                );
            }
            Err(e) => {
                let _ = writeln!(
                    md,
                    "| {} | {:.1} | {mem} | failed: {} | | | | |",
                    r.size,
                    r.wall_s,
                    e.replace('|', "/")
                );
            }
        }
    }
    print!("{md}");
    std::fs::write(a.out.join("bench-scale.md"), &md).stage("write table")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_bad_ones_are_named() {
        assert_eq!(parse_size("20x20x50").unwrap(), (20, 20, 50));
        for bad in ["20x20", "ax2x3", "0x2x3", "1x2x3x4"] {
            let e = parse_size(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }
}
