//! `frfit reduce MODEL.json [--order N --out R.json]`: balanced truncation of a model
//! (see [`frfit::reduce`]). Without `--order` it prints the Hankel singular values of the
//! stable part with the bound each order would have, and writes nothing: the order is
//! the user's choice (a gap in the values, or the largest bound one can accept). With
//! `--order N` (states in all, the rigid body's included) it writes the reduced model to
//! `R.json` with `hankel_singular_values` and `error_bound` in its provenance, and
//! prints the bound and the H-infinity error measured on a dense grid.

use super::common::fmt_num;
use clap::Args as ClapArgs;
use frfit::additive_riv::ModelFile;
use frfit::reduce::{analyse_file, reduce_file};
use frfit::FrfitError;
use std::path::PathBuf;

/// Arguments of `frfit reduce`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The model (JSON written by `frfit fit`, `frfit diagnose` or `frfit reduce`).
    pub model: PathBuf,
    /// States of the reduced model in all, the rigid-body states (kept exactly)
    /// included. Omitted: print the Hankel singular values and the bound of every
    /// order, write nothing.
    #[arg(long, value_name = "N", requires = "out")]
    pub order: Option<usize>,
    /// Write the reduced model here (model JSON).
    #[arg(long, value_name = "R.json", requires = "order")]
    pub out: Option<PathBuf>,
}

/// Runs `frfit reduce`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let bad_model = |e: &dyn std::fmt::Display| FrfitError::Io {
        path: args.model.display().to_string(),
        message: e.to_string(),
    };
    let file = ModelFile::read(&args.model).map_err(|e| bad_model(&e))?;
    let a = analyse_file(&file).map_err(|e| bad_model(&e))?;
    let h = &a.hankel;
    let (n_rb, n_s) = (h.rigid_order, h.stable_order);
    println!(
        "{}: {}x{}, {} states: {n_rb} rigid-body (kept exactly) and {n_s} stable",
        args.model.display(),
        file.ny,
        file.nu,
        n_rb + n_s
    );
    if args.order.is_none() || !quiet {
        println!("Hankel singular values of the stable part; `bound` is 2 x the sum of those");
        println!("discarded when the reduced model has `order` states in all:");
        println!("  order   Hankel s.v.        bound");
        println!(
            "  {n_rb:>5}   {:>11}  {:>11}",
            "",
            fmt_num(h.error_bound(0))
        );
        for (k, s) in h.hankel_singular_values.iter().enumerate() {
            println!(
                "  {:>5}   {:>11}  {:>11}",
                n_rb + k + 1,
                fmt_num(*s),
                fmt_num(h.error_bound(k + 1))
            );
        }
    }
    let (Some(order), Some(out)) = (args.order, args.out.as_ref()) else {
        if !quiet {
            eprintln!(
                "no --order given: nothing written (choose N and add --order N --out R.json)"
            );
        }
        return Ok(());
    };
    let r = reduce_file(&file, order, &args.model.display().to_string()).map_err(|e| match e {
        FrfitError::Realize(realize::RealizeError::InvalidParameter { name, value, why })
            if name == "order" =>
        {
            FrfitError::argument("--order", value, why)
        }
        other => other,
    })?;
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| FrfitError::io(parent, e))?;
    }
    r.file.write(out).map_err(|e| FrfitError::Io {
        path: out.display().to_string(),
        message: e.to_string(),
    })?;
    println!(
        "reduced to {order} states ({} rigid-body, {} stable): a-priori bound {}, measured \
         H-infinity error {} ({} points)",
        r.reduction.rigid_order,
        r.reduction.stable_order,
        fmt_num(r.reduction.error_bound),
        fmt_num(r.measured_error),
        r.grid_points
    );
    println!(
        "{} modes, {} real poles; written to {}",
        r.reduction.model.pairs.len(),
        r.reduction.model.real_poles.len(),
        out.display()
    );
    Ok(())
}
