//! `cargo xtask oomen-bosgra`: Section 6 of Oomen and Bosgra, "Well-posed model
//! uncertainty estimation by design of validation experiments", reproduced (the
//! simulation and the validation live in `validation::section6`).
//!
//! Writes `gamma.csv` (`p,n_per,gamma,true_error`: the minimum additive uncertainty per
//! validation line and the true model error `|P0 - P^|`), `disturbance.csv`
//! (`p,n_per,v_tilde,v_tilde_true,disturbance_over_w`) and `figure5.svg` (the disturbance
//! model per `n_per` on top, `gamma` per `n_per` with the true error below, as Figure 5).

use crate::{Context, Error};
use clap::Args as ClapArgs;
use frfit::plots::{Axis, LinePlot, PlotGrid, Series, PALETTE};
use frfit::validation::section6::{self, Section6Line, N};
use frfit::validation::GammaConfig;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Options of `cargo xtask oomen-bosgra`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Output directory [default: <workspace>/target/oomen-bosgra].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Noise seed (each n_per uses seed + its index).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// The numbers of periods of Figure 5.
const N_PER: [usize; 3] = [100, 1000, 10_000];

/// Runs the task.
pub fn run(args: Args) -> Result<(), Error> {
    let dir = args.out.unwrap_or_else(|| {
        crate::wafer_stage::workspace_root()
            .join("target")
            .join("oomen-bosgra")
    });
    std::fs::create_dir_all(&dir).stage(&format!("output directory {}", dir.display()))?;
    let cfg = GammaConfig::default();
    let mut all: Vec<Vec<Section6Line>> = Vec::new();
    for (i, n_per) in N_PER.into_iter().enumerate() {
        all.push(section6::run(n_per, args.seed + i as u64, &cfg).stage("simulation")?);
    }
    let mut gamma_csv = String::from("p,n_per,gamma,true_error\n");
    let mut dist_csv = String::from("p,n_per,v_tilde,v_tilde_true,disturbance_over_w\n");
    for l in all.iter().flatten() {
        let _ = writeln!(
            gamma_csv,
            "{},{},{:.9e},{:.9e}",
            l.p, l.n_per, l.gamma, l.true_error
        );
        let _ = writeln!(
            dist_csv,
            "{},{},{:.9e},{:.9e},{:.9e}",
            l.p, l.n_per, l.v_tilde, l.v_tilde_true, l.disturbance_over_w
        );
    }
    let gpath = dir.join("gamma.csv");
    std::fs::write(&gpath, gamma_csv).stage(&format!("writing {}", gpath.display()))?;
    let dpath = dir.join("disturbance.csv");
    std::fs::write(&dpath, dist_csv).stage(&format!("writing {}", dpath.display()))?;

    // Figure 5
    let omega = |ls: &[Section6Line]| -> Vec<f64> {
        ls.iter()
            .map(|l| std::f64::consts::TAU * l.p as f64 / N as f64)
            .collect()
    };
    let x_axis = Axis::linear("Frequency [rad/sample]");
    let mut top = LinePlot::new("Disturbance model V~ (14)")
        .with_x(x_axis.clone())
        .with_y(Axis::log("V~"));
    let mut bottom = LinePlot::new("Minimum-norm validating uncertainty (FDMVOP)")
        .with_x(x_axis)
        .with_y(Axis::log("gamma"));
    for (i, ls) in all.iter().enumerate() {
        let c = PALETTE[i];
        let name = format!("n_per = {}", ls[0].n_per);
        let x = omega(ls);
        top = top
            .with_series(
                Series::line(
                    name.clone(),
                    x.clone(),
                    ls.iter().map(|l| l.v_tilde).collect(),
                )
                .with_color(c),
            )
            .with_series(
                Series::points("", x.clone(), ls.iter().map(|l| l.v_tilde).collect()).with_color(c),
            );
        bottom = bottom
            .with_series(
                Series::line(name, x.clone(), ls.iter().map(|l| l.gamma).collect()).with_color(c),
            )
            .with_series(Series::points("", x, ls.iter().map(|l| l.gamma).collect()).with_color(c));
    }
    let x = omega(&all[0]);
    top = top.with_series(
        Series::dashed(
            "true (|H|^2)",
            x.clone(),
            all[0].iter().map(|l| l.v_tilde_true).collect(),
        )
        .with_color((0, 0, 0)),
    );
    bottom = bottom.with_series(
        Series::dashed(
            "|P0 - P^|",
            x,
            all[0].iter().map(|l| l.true_error).collect(),
        )
        .with_color((0, 0, 0))
        .with_width(2),
    );
    let fig = PlotGrid {
        title: "Oomen & Bosgra, Section 6 (Figure 5)".into(),
        rows: 2,
        cols: 1,
        panels: vec![top, bottom],
        panel_size: (800, 380),
    };
    let spath = dir.join("figure5.svg");
    fig.write_svg(&spath).stage("figure")?;

    // summary
    println!(
        "Oomen-Bosgra Section 6 (alpha = {}, N = {N})",
        section6::ALPHA
    );
    println!(
        "{:>3} {:>12} {:>12} {:>12} {:>12}",
        "p", "|P0-P^|", "gamma 100", "gamma 1000", "gamma 10000"
    );
    for k in 0..all[0].len() {
        println!(
            "{:>3} {:>12.5} {:>12.5} {:>12.5} {:>12.5}",
            all[0][k].p, all[0][k].true_error, all[0][k].gamma, all[1][k].gamma, all[2][k].gamma
        );
    }
    let last = &all[2];
    let inside = last
        .iter()
        .filter(|l| l.gamma <= l.true_error && l.gamma >= l.true_error - 2.0 * l.disturbance_over_w)
        .count();
    println!(
        "n_per = 10000: {inside} of {} lines with |P0-P^| - 2 V~/|W| <= gamma <= |P0-P^|",
        last.len()
    );
    println!(
        "wrote {}, {}, {}",
        gpath.display(),
        dpath.display(),
        spath.display()
    );
    Ok(())
}
