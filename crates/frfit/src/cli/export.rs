//! `frfit export MODEL.json --out SS.json|SS.mat`: the fitted model as a real state space
//! (modal block form, integrators included) with its known factors stated beside it,
//! for controller design in MATLAB (`ss(A, B, C, D)`) or python-control (see
//! [`frfit::export`]).

use clap::Args as ClapArgs;
use frf_data::ModelStructure;
use frfit::additive_riv::ModelFile;
use frfit::export::{export_state_space, mat_bytes};
use frfit::FrfitError;
use std::path::PathBuf;

/// Arguments of `frfit export`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The model (JSON written by `frfit fit` or `frfit diagnose`).
    pub model: PathBuf,
    /// Output: `.json` (frfit-state-space, every factor, the modes and the dynamics
    /// factors' poles and zeros with their standard deviations) or `.mat` (MATLAB level 5: A, B, C, D, delay_s, derivative_order;
    /// Ad, Bd, Cd, Dd, Ts with a discrete form; f_hz, zeta, and f_hz_std, zeta_std,
    /// delay_s_std when the model holds them).
    #[arg(long, value_name = "SS.json|SS.mat")]
    pub out: PathBuf,
    /// Also write the exact zero-order-hold equivalent at this sample rate, Hz (a model
    /// fitted with the exact hold always has it, at its own rate).
    #[arg(long, value_name = "FS_HZ")]
    pub discrete: Option<f64>,
    /// Relative rank tolerance of each mode's residue: singular values below it times the
    /// largest are dropped (fewer states, a response that differs by about that much).
    /// Default 0: every direction above working precision, the model exactly.
    #[arg(long, default_value_t = 0.0, value_name = "TOL")]
    pub rank_tol: f64,
}

/// Runs `frfit export`.
pub fn run(args: Args, quiet: bool) -> Result<(), FrfitError> {
    let bad_model = |e: &dyn std::fmt::Display| FrfitError::Io {
        path: args.model.display().to_string(),
        message: e.to_string(),
    };
    let file = ModelFile::read(&args.model).map_err(|e| bad_model(&e))?;
    let model = file
        .to_model()
        .map_err(|e| bad_model(&e))?
        .to_frf_model()
        .map_err(|e| bad_model(&e))?;
    let mut e = export_state_space(&model, args.discrete, args.rank_tol, file.units.clone())?;
    // the modal parameters with the standard deviations the model file holds (issue 44)
    e.modes = file
        .modes
        .iter()
        .map(|m| frfit::export::ExportedMode {
            f_hz: m.f_hz,
            zeta: m.zeta,
            f_hz_std: m.f_hz_std,
            zeta_std: m.zeta_std,
        })
        .collect();
    e.delay_s_std = file.delay_s_std;
    // ... and the dynamics factors' poles and zeros (the JSON form; the .mat holds the
    // modes' and the delay's)
    if file.dynamics_std.len() == e.factors.dynamics.len() {
        e.dynamics_std = file.dynamics_std.clone();
    }
    let ext = args
        .out
        .extension()
        .and_then(|x| x.to_str())
        .map(str::to_ascii_lowercase);
    let bytes = match ext.as_deref() {
        Some("json") => serde_json::to_vec_pretty(&e).map_err(|err| FrfitError::Io {
            path: args.out.display().to_string(),
            message: err.to_string(),
        })?,
        Some("mat") => mat_bytes(&e),
        _ => {
            return Err(FrfitError::argument(
                "--out",
                args.out.display(),
                "the output format follows the extension: .json or .mat",
            ))
        }
    };
    std::fs::write(&args.out, bytes).map_err(|err| FrfitError::io(&args.out, err))?;
    if !quiet {
        eprintln!(
            "{} states ({}x{}), {}; written to {}",
            e.n_states,
            e.ny,
            e.nu,
            e.response,
            args.out.display()
        );
        if !e.factors.dynamics.is_empty() && ext.as_deref() == Some("mat") {
            eprintln!(
                "note: the model has {} dynamics factor(s); they are in the .json export only",
                e.factors.dynamics.len()
            );
        }
    }
    Ok(())
}
