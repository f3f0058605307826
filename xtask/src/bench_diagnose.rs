//! `cargo xtask bench-diagnose`: the wall time of `frfit diagnose` against one `frfit fit`
//! on the same data (issue: diagnosis, "at most 5x the time of one fit").
//!
//! On each reference case of `../shared/data` (the nominal wafer stage and the three
//! with an undeclared effect) the release `frfit` binary runs as a user would, in a
//! child process, `--repeat` times each: `frfit fit DATA --band 20:2000` and
//! `frfit diagnose DATA --band 20:2000 --report DIR` (`--modes 17` on the hidden-mode
//! case, as its test does). The table gives the median wall times, their ratio and the
//! steps the loop accepted; the last row the median ratio over the cases. Written to
//! stdout and `OUT/bench-diagnose.md`. Without `../shared/data` the task says so and
//! stops.

use crate::bench_scale::{frfit_binary, run_measured};
use crate::{Context, Error};
use clap::Args as ClapArgs;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::Command;

/// Arguments of `cargo xtask bench-diagnose`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Runs of each command per case (the median is reported).
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Only the cases whose file name contains this.
    #[arg(long)]
    pub only: Option<String>,
    /// Output directory (models, reports, the table).
    #[arg(long, default_value = "target/bench-diagnose")]
    pub out: PathBuf,
}

/// The reference cases: file and extra arguments of both commands.
const CASES: [(&str, &[&str]); 4] = [
    ("wafer_nominal.csv", &[]),
    ("wafer_extra_delay.csv", &[]),
    ("wafer_hidden_mode.csv", &["--modes", "17"]),
    ("wafer_crosstalk.csv", &[]),
];

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Runs `cmd` `repeat` times; the median wall time, seconds.
fn timed(mut make: impl FnMut() -> Command, repeat: usize, what: &str) -> Result<f64, Error> {
    let mut t = Vec::new();
    for _ in 0..repeat.max(1) {
        let (ok, wall, _) = run_measured(&mut make())?;
        if !ok {
            return Err(Error::new(what, "the command failed"));
        }
        t.push(wall);
    }
    Ok(median(t))
}

/// The accepted steps of a diagnosis report's `summary.json`.
fn accepted_steps(report: &std::path::Path) -> Result<String, Error> {
    let text = std::fs::read_to_string(report.join("summary.json")).stage("summary.json")?;
    let v: serde_json::Value = serde_json::from_str(&text).stage("summary.json")?;
    let steps: Vec<String> = v["steps"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter(|s| s["accepted"].as_bool() == Some(true))
                .filter_map(|s| s["effect"].as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default();
    let restart = if v["initial"]["restart"].is_object() {
        " (first fit restarted)"
    } else {
        ""
    };
    Ok(format!(
        "{}{restart}; {}",
        if steps.is_empty() {
            "none".to_string()
        } else {
            steps.join(", ")
        },
        v["verdict"].as_str().unwrap_or("?")
    ))
}

/// Runs the benchmark.
pub fn run(a: Args) -> Result<(), Error> {
    let Some(dir) = frf_data::shared_data::shared_data_dir() else {
        println!("bench-diagnose: skipped, ../shared/data (the reference cases) is not beside the checkout");
        return Ok(());
    };
    let bin = frfit_binary()?;
    std::fs::create_dir_all(&a.out).stage("output directory")?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "| case | fit, s | diagnose, s | ratio | accepted steps; verdict |\n|---|---:|---:|---:|---|"
    );
    let mut ratios = Vec::new();
    for (name, extra) in CASES {
        if a.only.as_deref().is_some_and(|o| !name.contains(o)) {
            continue;
        }
        let data = dir.join(name);
        if !data.exists() {
            println!(
                "bench-diagnose: {name} not found in {}, skipped",
                dir.display()
            );
            continue;
        }
        let stem = name.trim_end_matches(".csv");
        let model = a.out.join(format!("{stem}.model.json"));
        let report = a.out.join(format!("{stem}-report"));
        let base = |cmd: &str| {
            let mut c = Command::new(&bin);
            c.arg(cmd)
                .arg(&data)
                .args(["--band", "20:2000", "--quiet"])
                .args(extra);
            c
        };
        let fit_s = timed(
            || {
                let mut c = base("fit");
                c.arg("--out").arg(&model);
                c
            },
            a.repeat,
            "frfit fit",
        )?;
        let diag_s = timed(
            || {
                let mut c = base("diagnose");
                c.arg("--report").arg(&report);
                c
            },
            a.repeat,
            "frfit diagnose",
        )?;
        let ratio = diag_s / fit_s;
        ratios.push(ratio);
        let row = format!(
            "| {stem} | {fit_s:.1} | {diag_s:.1} | {ratio:.2} | {} |",
            accepted_steps(&report)?
        );
        println!("{row}");
        let _ = writeln!(md, "{row}");
    }
    let last = format!("| median ratio | | | {:.2} | |", median(ratios));
    println!("{last}");
    let _ = writeln!(md, "{last}");
    std::fs::write(a.out.join("bench-diagnose.md"), md).stage("bench-diagnose.md")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(Vec::new()).is_nan());
    }
}
