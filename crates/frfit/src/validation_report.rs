//! The written form of a model validation (Oomen-Bosgra, [`crate::validation`]): the
//! verdict in words, gamma against frequency (SVG) and the Markdown report, as
//! `frfit validate`, `frfit diagnose --validate` and `cargo xtask wafer-stage` write them.

use crate::plots::{Axis, LinePlot, Series};
use crate::validation::{FrfValidation, Verdict};
use crate::FrfitError;
use std::fmt::Write as _;
use std::path::Path;

/// Writes `validation.json`, `gamma.svg` and `report.md` of `v` into `dir` (created);
/// `model`, `desc`, `data` and `units` label the report (see [`markdown`]).
pub fn write_validation_dir(
    dir: &Path,
    model: &str,
    desc: &str,
    data: &str,
    v: &FrfValidation,
    units: Option<&str>,
) -> Result<(), FrfitError> {
    std::fs::create_dir_all(dir).map_err(|e| FrfitError::io(dir, e))?;
    let json_path = dir.join("validation.json");
    let json = serde_json::to_string_pretty(v).map_err(|e| FrfitError::Io {
        path: json_path.display().to_string(),
        message: e.to_string(),
    })?;
    std::fs::write(&json_path, json).map_err(|e| FrfitError::io(&json_path, e))?;
    gamma_plot(v).write_svg(dir.join("gamma.svg"), (900, 500))?;
    let md_path = dir.join("report.md");
    std::fs::write(&md_path, markdown(model, desc, data, v, units))
        .map_err(|e| FrfitError::io(&md_path, e))
}

/// The verdict in words.
pub fn verdict_text(v: Verdict) -> &'static str {
    match v {
        Verdict::NotInvalidated => "not invalidated",
        Verdict::InvalidatedAtZeroUncertainty => "invalidated at zero uncertainty",
    }
}

/// Gamma, the model error and the disturbance bound against frequency.
pub fn gamma_plot(v: &FrfValidation) -> LinePlot {
    let f: Vec<f64> = v.lines.iter().map(|l| l.f_hz).collect();
    let plot = LinePlot::new("Minimum additive uncertainty per line")
        .with_y(Axis::log("Magnitude"))
        .with_series(Series::line(
            "|G - P^| (model error seen by the data)",
            f.clone(),
            v.lines.iter().map(|l| l.model_error).collect(),
        ))
        .with_series(
            Series::line(
                "gamma",
                f.clone(),
                v.lines.iter().map(|l| l.gamma).collect(),
            )
            .with_width(2),
        )
        .with_series(Series::dashed(
            "disturbance bound",
            f.clone(),
            v.lines.iter().map(|l| l.disturbance_bound).collect(),
        ));
    if v.beyond_model_uncertainty.is_none() {
        return plot;
    }
    plot.with_series(Series::dashed(
        "model's own bound (its estimation uncertainty)",
        f.clone(),
        v.lines
            .iter()
            .map(|l| l.model_bound.unwrap_or(f64::NAN))
            .collect(),
    ))
    .with_series(Series::line(
        "gamma beyond the model's own uncertainty",
        f,
        v.lines
            .iter()
            .map(|l| l.gamma_beyond_model.unwrap_or(f64::NAN))
            .collect(),
    ))
}

/// The Markdown report of `v`: the model (`model`, described by `desc`) against the
/// validation data `data`, with `gamma.svg` beside it.
pub fn markdown(
    model: &str,
    desc: &str,
    data: &str,
    v: &FrfValidation,
    units: Option<&str>,
) -> String {
    let u = units.unwrap_or("FRF units");
    let mut s = String::new();
    let _ = writeln!(s, "# Model validation\n");
    let _ = writeln!(s, "- model: `{model}` ({desc})");
    let _ = writeln!(s, "- validation data: `{data}`");
    let _ = writeln!(
        s,
        "- alpha = {} per line (for each input column's output vector); verdict at the \
         joint level over all lines and inputs",
        v.alpha
    );
    let _ = writeln!(
        s,
        "- variance: {}",
        v.variance_dof.map_or_else(
            || "taken as exact (the file does not say how many realizations it was estimated from)"
                .to_string(),
            |d| format!("estimated with {d} degrees of freedom (F(2, {d}) radii)")
        )
    );
    let _ = writeln!(s, "- **verdict: {}**", verdict_text(v.verdict));
    let _ = writeln!(
        s,
        "- lines the disturbance alone does not explain (joint level): {} of {}",
        v.lines_invalidated_at_zero,
        v.lines.len()
    );
    let _ = writeln!(
        s,
        "- gamma: max {:.4e}, median {:.4e} ({u})\n",
        v.gamma_max, v.gamma_median
    );
    let _ = writeln!(
        s,
        "gamma is the smallest norm sigma_max(Delta_u) of an additive uncertainty \
         P^ + Delta_u that, with a disturbance inside the bound, reproduces the validation \
         FRF at the line (Oomen and Bosgra, the FDMVOP). Where gamma stays below the model \
         error |G - P^|, part of the error is attributed to noise; more periods in the \
         validation experiment shrink the disturbance bound and gamma approaches the true \
         model error from below.\n"
    );
    if let Some(b) = &v.beyond_model_uncertainty {
        let _ = writeln!(s, "## With the model's own uncertainty\n");
        let _ = writeln!(
            s,
            "The model's response has a standard deviation of its own (the fit data's noise \
             carried through the parameters' covariance), independent of the validation \
             data's noise: the residual of a model at the truth has the covariance of both. \
             Read with both:\n"
        );
        let _ = writeln!(s, "- **verdict: {}**", verdict_text(b.verdict));
        let _ = writeln!(
            s,
            "- lines neither explains (joint level): {} of {}",
            b.lines_invalidated_at_zero,
            v.lines.len()
        );
        let _ = writeln!(
            s,
            "- gamma beyond the model's own uncertainty (what its structure misses): max \
             {:.4e}, median {:.4e} ({u})",
            b.gamma_max, b.gamma_median
        );
        let _ = writeln!(
            s,
            "- the model's own bound: max {:.4e} ({u}); median ratio to the data's \
             disturbance bound {:.3} ({})\n",
            b.model_bound_max,
            b.model_to_disturbance_median,
            if b.model_to_disturbance_median < 1.0 {
                "the validation data's noise dominates"
            } else {
                "the model's own uncertainty dominates"
            }
        );
        let _ = writeln!(
            s,
            "gamma above is the uncertainty a robust design must cover (everything beyond the \
             validation data's noise, the model's estimation error included); gamma beyond \
             the model's own uncertainty is the part its estimation error does not explain.\n"
        );
    }
    let _ = writeln!(s, "![gamma against frequency](gamma.svg)\n");
    let mut top: Vec<_> = v.lines.iter().collect();
    top.sort_by(|a, b| b.gamma.total_cmp(&a.gamma));
    let _ = writeln!(s, "## Lines with the largest gamma\n");
    let _ = writeln!(s, "| f [Hz] | gamma | model error | disturbance bound |");
    let _ = writeln!(s, "|---:|---:|---:|---:|");
    for l in top.iter().take(10) {
        let _ = writeln!(
            s,
            "| {:.3} | {:.3e} | {:.3e} | {:.3e} |",
            l.f_hz, l.gamma, l.model_error, l.disturbance_bound
        );
    }
    s
}

/// The model's response at `omega` (rad/s) and a one-line description of it; `source`
/// names the model in errors. A 0 Hz line is refused when the model has a rigid body
/// (its integrators are infinite there).
pub fn model_response(
    file: &additive_riv::ModelFile,
    source: &str,
    omega: &[f64],
) -> Result<(realize::ResponseGrid, String), FrfitError> {
    use frf_data::ModelStructure;
    let model = file.to_model().map_err(|e| FrfitError::Io {
        path: source.to_string(),
        message: e.to_string(),
    })?;
    if omega.first() == Some(&0.0) && file.rigid_body.is_some() {
        return Err(FrfitError::argument(
            "data",
            source,
            "the data hold a 0 Hz line, where the model's rigid body (integrators) is infinite",
        ));
    }
    let desc = format!(
        "{} modes, hold {}, delay {:.4} us; {}",
        file.modes.len(),
        file.hold,
        file.delay_s * 1e6,
        file.provenance.estimator
    );
    Ok((model.response_at(omega), desc))
}

/// `alpha`, the probability level of a validation, is strictly between 0 and 1.
pub fn check_alpha(alpha: f64) -> Result<(), FrfitError> {
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(FrfitError::argument(
            "--alpha",
            alpha,
            "a probability strictly between 0 and 1 (for example 0.99)",
        ));
    }
    Ok(())
}

/// Where the model's own uncertainty in a validation comes from: the data it was fitted
/// to, set up as the run that fitted it set them up (band, weighting;
/// [`crate::pipeline::model_response_std_at`]), and a name for the report.
pub struct FitDataOfModel<'a> {
    /// The FRF the model was fitted to.
    pub data: &'a frf_data::Frf,
    /// The run's settings (only the band, hold, sample rate, FRF type and weighting are
    /// read; without a band, the one the model file records).
    pub config: &'a crate::pipeline::PipelineConfig,
    /// The data's name in the report (a file name).
    pub name: String,
}

/// Validates a model on an independent measurement `data` (with `_var` columns): the
/// smallest additive uncertainty per line for which the model is not invalidated with
/// probability `alpha` (Oomen and Bosgra; [`crate::validation::validate_frf`]). The
/// variance's degrees of freedom come from the number of realizations `data` declares
/// (its comments or metadata): with `R` of them the disturbance radii use the
/// `F(2, 2(R-1))` quantile. With `fitted_on`, the model's own uncertainty at the
/// validation lines (its response's standard deviation from the information on the data
/// it was fitted to) is read next to the data's
/// ([`crate::validation::validate_frf_with_model_std`]); when no covariance can be
/// formed (an unstable pole, a parameter the data do not determine) the validation runs
/// without it and the description says why. `source` names the model in errors.
/// Returns the validation and a one-line description of the model.
pub fn validate_model(
    file: &additive_riv::ModelFile,
    source: &str,
    data: &frf_data::Frf,
    alpha: f64,
    method: crate::validation::GammaMethod,
    fitted_on: Option<&FitDataOfModel>,
) -> Result<(FrfValidation, String), FrfitError> {
    use frf_data::FrfDataset;
    check_alpha(alpha)?;
    let omega = data.omegas();
    let (grid, mut desc) = model_response(file, source, &omega)?;
    if (grid.ny, grid.nu) != (data.ny(), data.nu()) {
        return Err(FrfitError::argument(
            "--data",
            data.source.as_deref().unwrap_or("<data>"),
            format!(
                "the data are {}x{} but the model is {}x{}",
                data.ny(),
                data.nu(),
                grid.ny,
                grid.nu
            ),
        ));
    }
    let model_std = match fitted_on {
        Some(f) => {
            let model = file.to_model().map_err(|e| FrfitError::Io {
                path: source.to_string(),
                message: e.to_string(),
            })?;
            // the band the run fitted, else the one the model file records
            let config = crate::pipeline::PipelineConfig {
                band_hz: f.config.band_hz.or(file.band_hz.map(|b| (b[0], b[1]))),
                ..f.config.clone()
            };
            match crate::pipeline::model_response_std_at(&model, f.data, &config, &omega) {
                Ok(sd) => {
                    desc.push_str(&format!(
                        "; its own uncertainty from the information on `{}`",
                        f.name
                    ));
                    Some(sd)
                }
                Err(e) => {
                    desc.push_str(&format!("; its own uncertainty is not included: {e}"));
                    None
                }
            }
        }
        None => None,
    };
    let cfg = crate::validation::FrfValidationConfig {
        alpha,
        method,
        // a variance estimated from R realizations (the file's comments or metadata say
        // how many) has 2 (R - 1) real degrees of freedom
        variance_dof: crate::declared::declared(data)
            .realizations
            .filter(|&r| r >= 2)
            .map(|r| 2.0 * (r as f64 - 1.0)),
        ..Default::default()
    };
    let v = crate::validation::validate_frf_with_model_std(
        &grid,
        model_std.as_deref(),
        data,
        None,
        &cfg,
    )
    .map_err(|e| FrfitError::Fit {
        what: "validation".into(),
        why: e.to_string(),
    })?;
    Ok((v, desc))
}
