//! A whole run of the frfit pipeline: load -> band -> delay -> CMIF -> initialisation ->
//! refinement -> residual analysis -> diagnosis loop -> report (DESIGN.md).
//!
//! This module stands above both [`crate::pipeline`] (the stages a run is made of) and
//! [`crate::diagnose`] (the diagnosis loop, built on those stages). [`run`] sets up a
//! [`FitContext`] (band, declarations, and what every stage works from, computed once),
//! fits the additive model of the wafer-stage paper (crate `additive-riv`) with
//! [`first_fit`] and, with [`PipelineConfig::diagnose`], runs the diagnosis loop of
//! [`crate::diagnose`] from it: it compares the residual with the measured noise level
//! (crate `validation`), traces a significant residual to the effects of the catalogue
//! (missed mode, delay, hold, feedthrough, stiffness, input or output dynamics), adds the
//! effect with the strongest evidence to the model structure, refits, and keeps it only
//! when an F test that accounts for the added parameters says it explains more than
//! noise. It stops when the residual is at the noise level (`noise_limited`) or when no
//! candidate helps (`unexplained_residual`), and records every step for the report. When
//! the residual is above the measured variance but at the data's model-free line-to-line
//! floor, and that floor significantly exceeds the variance, the verdict is
//! `nonlinear_distortion` (`validation::distortion`). A diagnosis that ends worse than
//! `frfit fit`'s model runs again from that model (module `from_fit`, [`ends_worse`]).
//! What a run produced is a [`PipelineOutput`].

mod from_fit;

pub use from_fit::{ends_worse, Standing};
use from_fit::{from_fit_if_worse, FromFit, StartRecord};

use crate::diagnose::{
    better_first_fit, delay_restart, diagnose, first_repairs, worth_a_delay_restart, Diagnosis,
    Restarted,
};
use crate::pipeline::{
    build_summary, cmif_once, distortion_summary, err, error_stats, first_fit,
    information_uncertainty, information_uncertainty_and_response_std, ml_uncertainty,
    response_std, structure_steps, FirstFit, FitContext, PipelineConfig, RunRecord, Timings,
};
use crate::summary::{StageTime, Summary};
use crate::FrfitError;
use additive_riv::{AdditiveModel, FitterReport};
use frf_data::cmif::{Cmif, CmifPeak};
use frf_data::{Fit, Frf, ModelStructure};
use realize::ResponseGrid;
use std::time::Instant;
use validation::analysis::analyze_residual;
use validation::noise::NoiseLevel;

/// The file name of the diagnosis's start model in the report directory
/// ([`PipelineOutput::start_model_file`]; the report links it).
pub use crate::report::START_MODEL_FILE;

/// Everything a run produced: the band, the fit, the noise level, the CMIF, the model
/// responses for the report, and the summary.
pub struct PipelineOutput {
    /// The fitted band (a copy of the data's lines in the band).
    pub band: Frf,
    /// The final fit.
    pub fit: Fit<AdditiveModel>,
    /// What the fitter found on the way.
    pub fitter_report: FitterReport,
    /// The links of the chain that made the first model (empty when the run started from
    /// a given model).
    pub chain: Vec<String>,
    /// Each link's report.
    pub links: Vec<frf_data::LinkReport>,
    /// The noise level used.
    pub noise: NoiseLevel,
    /// CMIF of the band when the run computed it; [`cmif`](Self::cmif) computes it
    /// otherwise.
    cmif: std::sync::OnceLock<std::sync::Arc<Cmif>>,
    /// The picked peaks the fit started from.
    pub peaks: Vec<CmifPeak>,
    /// The model before the diagnosis loop (the first fit, or `fit`'s model when the
    /// diagnosis started again from it); the final model without the loop.
    pub initial_model: AdditiveModel,
    /// Response of the model before the diagnosis loop.
    pub initial_response: ResponseGrid,
    /// Weighted cost of the model before the diagnosis loop on the band's fit data.
    pub initial_cost: f64,
    /// Response of the final model.
    pub final_response: ResponseGrid,
    /// Standard deviation of the final model's response per line and entry (layout
    /// `[k * m + e]`) from the parameters' covariance, when the final analysis ran and a
    /// covariance could be formed (the band on the report's plots).
    pub final_response_std: Option<Vec<f64>>,
    /// Per step, the model response before and after.
    pub step_responses: Vec<(ResponseGrid, ResponseGrid)>,
    /// The summary (also written as `summary.json`).
    pub summary: Summary,
}

impl PipelineOutput {
    /// The model file of the final fit (modal form, submodels and provenance), as
    /// `frfit fit/diagnose` and `cargo xtask wafer-stage` write it; `producer` names
    /// what ran (e.g. `frfit diagnose`).
    pub fn model_file(
        &self,
        data_path: &std::path::Path,
        producer: &str,
    ) -> Result<additive_riv::ModelFile, additive_riv::RivError> {
        let provenance = additive_riv::Provenance {
            estimator: self.fit.estimator.clone(),
            data: Some(data_path.display().to_string()),
            weighting: self.fitter_report.weighting.clone(),
            iterations: self.fit.iterations,
            convergence: self.fit.convergence.describe(),
            cost: self.fit.final_cost(),
            frfit_version: format!("{} ({producer})", env!("CARGO_PKG_VERSION")),
            notes: self.fit.messages.clone(),
            chain: self.chain.clone(),
            links: self.links.clone(),
            ..Default::default()
        };
        let band = self.summary.data.band_hz;
        let mut file = additive_riv::ModelFile::from_model(
            &self.fit.model,
            self.band.units.clone(),
            Some((band[0], band[1])),
            provenance,
        )?;
        // the refiner's standard deviations, when it computed a covariance of this model
        if let Some(u) = &self.summary.uncertainty {
            let modes: Vec<additive_riv::ModeStd> = u
                .modes
                .iter()
                .map(|m| additive_riv::ModeStd {
                    f_hz: m.f_hz,
                    f_hz_std: m.f_hz_std,
                    zeta_std: m.zeta_std,
                })
                .collect();
            let delay_std = if file.delay_fitted {
                u.delay_s_std
            } else {
                None
            };
            file.set_uncertainty(&modes, delay_std)?;
            // the dynamics factors' poles and zeros, when the covariance holds every
            // factor of the file (both in the model's order)
            if !u.factors.is_empty() && u.factors.len() == file.dynamics.len() {
                let factors = u
                    .factors
                    .iter()
                    .map(|f| additive_riv::FactorStd {
                        poles: f.poles.clone(),
                        zeros: f.zeros.clone(),
                    })
                    .collect();
                file.set_factor_uncertainty(factors)?;
            }
        }
        Ok(file)
    }

    /// The model file of the model the diagnosis loop started from
    /// ([`PipelineOutput::initial_model`]: the first fit, a restart that replaced it, or
    /// `fit`'s model), in the form of [`PipelineOutput::model_file`] without the final
    /// model's standard deviations, so that a user can compare the two (`frfit eval`,
    /// `frfit validate`).
    pub fn start_model_file(
        &self,
        data_path: &std::path::Path,
        producer: &str,
    ) -> Result<additive_riv::ModelFile, additive_riv::RivError> {
        let provenance = additive_riv::Provenance {
            estimator: format!("{} (the start of the diagnosis)", self.fit.estimator),
            data: Some(data_path.display().to_string()),
            weighting: self.fitter_report.weighting.clone(),
            cost: Some(self.initial_cost),
            frfit_version: format!("{} ({producer})", env!("CARGO_PKG_VERSION")),
            chain: self.chain.clone(),
            ..Default::default()
        };
        let band = self.summary.data.band_hz;
        additive_riv::ModelFile::from_model(
            &self.initial_model,
            self.band.units.clone(),
            Some((band[0], band[1])),
            provenance,
        )
    }

    /// Writes the model file to `model_path` (its folder created) and, with `report`,
    /// the report into that directory (`report.md`, the figures, `summary.json`, and for
    /// a diagnosis `start_model.json`, the model its loop started from), as
    /// `frfit fit`, `frfit diagnose` and the Python package write them; `data_path`
    /// names the data in the provenance and the report's title, `producer` what ran.
    pub fn write_outputs(
        &self,
        model_path: &std::path::Path,
        report: Option<&std::path::Path>,
        data_path: &std::path::Path,
        producer: &str,
    ) -> Result<(), FrfitError> {
        let file = self
            .model_file(data_path, producer)
            .map_err(err("model file"))?;
        if let Some(parent) = model_path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| FrfitError::io(parent, e))?;
        }
        file.write(model_path).map_err(|e| FrfitError::Io {
            path: model_path.display().to_string(),
            message: e.to_string(),
        })?;
        if let Some(dir) = report {
            let title = format!("frfit {} of {}", self.summary.command, data_path.display());
            let input = self.report_input(&title)?;
            crate::report::write_report(dir, &input, &self.summary)?;
            if self.summary.command == "diagnose" {
                let path = dir.join(START_MODEL_FILE);
                self.start_model_file(data_path, producer)
                    .map_err(err("start model file"))?
                    .write(&path)
                    .map_err(|e| FrfitError::Io {
                        path: path.display().to_string(),
                        message: e.to_string(),
                    })?;
            }
        }
        Ok(())
    }

    /// The CMIF of the band (computed on the first call when the run did not need it).
    pub fn cmif(&self) -> Result<&Cmif, FrfitError> {
        Ok(cmif_once(&self.cmif, &self.band)?)
    }

    /// What [`crate::report::write_report`] needs from this run, under `title`.
    pub fn report_input<'a>(
        &'a self,
        title: &'a str,
    ) -> Result<crate::report::ReportInput<'a>, FrfitError> {
        Ok(crate::report::ReportInput {
            data: &self.band,
            noise_var: Some(&self.noise.variance),
            cmif: self.cmif()?,
            peaks: &self.peaks,
            initial: &self.initial_response,
            final_model: &self.final_response,
            final_model_std: self.final_response_std.as_deref(),
            steps: &self.step_responses,
            title,
        })
    }
}

/// Runs the pipeline on `data` (read from `path`) for `command` (`fit` or `diagnose`):
/// the setup ([`FitContext::new`]), the first fit ([`first_fit`]), with
/// [`PipelineConfig::diagnose`] the diagnosis loop, then the final residual analysis
/// and the summary.
pub fn run(
    data: &Frf,
    path: &str,
    cfg: &PipelineConfig,
    command: &str,
) -> Result<PipelineOutput, FrfitError> {
    let t0 = Instant::now();
    let mut timings = Timings::default();
    let ctx = FitContext::timed(data, cfg, &mut timings)?;
    let t = Instant::now();
    // When the data's delay is far from the one the first fit holds, the diagnosis will
    // test a restart from the data's delay estimate: it runs beside the first fit.
    let speculate = (cfg.diagnose && cfg.start_model.is_none())
        .then(|| worth_a_delay_restart(&ctx))
        .flatten();
    let (first, speculative) = match speculate {
        Some(held) => rayon::join(|| first_fit(&ctx, cfg), || delay_restart(&ctx, cfg, held)),
        None => (first_fit(&ctx, cfg), None),
    };
    let FirstFit {
        fit,
        report: mut fitter_report,
        chain: mut first_chain,
        links: mut first_links,
        chain_runs: mut first_chain_runs,
    } = first?;
    timings.stage(
        if speculate.is_some() {
            "fit (with the delay restart beside it)"
        } else {
            "fit"
        },
        t,
    );
    // the first fit's own stages (per link of the chain), under the `fit` stage
    for st in &fit.timings {
        timings.0.push(StageTime {
            stage: format!("  fit / {}", st.stage),
            seconds: st.seconds,
        });
    }
    // a restart that ends significantly better is a better first fit, not an effect
    let mut repairs = None;
    let Restarted {
        fit,
        summary: restart,
        delay: delay_restart,
        sk_start,
    } = if cfg.diagnose && cfg.start_model.is_none() {
        let t = Instant::now();
        // with declared modes the repairs are the loop's first trial: made here, the
        // restarts count the modes the first fit lost after them
        repairs = first_repairs(&ctx, cfg, &fit.model);
        let repaired = repairs.as_ref().and_then(|r| r.modes());
        let r = better_first_fit(
            &ctx,
            cfg,
            fit,
            speculative,
            fitter_report.cmif_peaks.len(),
            repaired,
        )?;
        timings.stage("restart", t);
        r
    } else {
        Restarted {
            fit,
            summary: None,
            delay: None,
            sk_start: None,
        }
    };
    let t = Instant::now();
    let mut initial_model = fit.model.clone();
    let mut initial_response = initial_model.response_at(&ctx.omega);
    let mut initial_errors = error_stats(&ctx.band, &initial_response, &ctx.noise);
    timings.stage("response and errors", t);
    let mut from_fit = None;
    // the final model's response, when the diagnosis computed it
    let mut diagnosed_response = None;
    let Diagnosis {
        mut fit,
        steps,
        step_responses,
        stages,
    } = if cfg.diagnose {
        let t = Instant::now();
        let d = diagnose(
            &ctx,
            cfg,
            fit,
            &initial_response,
            delay_restart,
            sk_start,
            repairs,
        )?;
        timings.stage("diagnose", t);
        let t = Instant::now();
        let start = StartRecord {
            model: &initial_model,
            errors: initial_errors,
        };
        let FromFit {
            diagnosis,
            final_response,
            replaced,
        } = from_fit_if_worse(&ctx, cfg, d, start)?;
        timings.stage("diagnose: comparison with fit's model", t);
        if let Some(r) = replaced {
            initial_model = r.reference.fit.model;
            initial_response = r.response;
            initial_errors = r.errors;
            fitter_report = r.reference.report;
            first_chain = r.reference.chain;
            first_links = r.reference.links;
            first_chain_runs = r.reference.chain_runs;
            from_fit = Some(r.summary);
        }
        diagnosed_response = Some(final_response);
        diagnosis
    } else {
        Diagnosis {
            fit,
            steps: Vec::new(),
            step_responses: Vec::new(),
            stages: Vec::new(),
        }
    };
    for (stage, seconds) in stages {
        timings.0.push(StageTime { stage, seconds });
    }
    let t = Instant::now();
    // the diagnosis computed its final model's response (`from_fit_if_worse`); without
    // the loop the final model is the first fit's: its response and errors are those
    // computed above (at 50 x 50 x 4000 lines a response costs seconds)
    let final_response = diagnosed_response.unwrap_or_else(|| initial_response.clone());
    // the residual analysis and the line-to-line floor read the same residual: side by
    // side on the two threads (seconds each at 50 x 50 entries)
    let analyses = || -> Result<_, FrfitError> {
        let analysis = analyze_residual(
            &ctx.band,
            &final_response,
            &ctx.noise,
            &ctx.residual_config(&fit.model),
        )
        .map_err(err("residual analysis"))?;
        // the residual against the variance raised to the local line-to-line floor, when
        // the floor exceeds the variance and the residual is above the variance (the
        // verdict `nonlinear_distortion` needs it)
        let floor_analysis = match ctx.distortion_noise() {
            Some(n) if analysis.significant => Some(
                analyze_residual(
                    &ctx.band,
                    &final_response,
                    n,
                    &ctx.residual_config(&fit.model),
                )
                .map_err(err("residual analysis"))?,
            ),
            _ => None,
        };
        Ok((analysis, floor_analysis))
    };
    let (analysis, floor_analysis, distortion) = if cfg.final_analysis {
        let (analyses, distortion) =
            rayon::join(analyses, || distortion_summary(&ctx, &final_response));
        let (analysis, floor_analysis) = analyses?;
        (Some(analysis), floor_analysis, distortion)
    } else {
        (None, None, None)
    };
    let final_errors = if cfg.diagnose {
        error_stats(&ctx.band, &final_response, &ctx.noise)
    } else {
        initial_errors
    };
    timings.stage("residual analysis and line-to-line floor", t);
    // the ML link's covariance at its optimum when the final model is the chain's own;
    // otherwise (another refiner, or a diagnosis that refitted the model) the information
    // of the ML criterion at the final model
    let t = Instant::now();
    let ml_link = (!cfg.diagnose)
        .then(|| ml_uncertainty(&first_links))
        .flatten();
    // the entries the report's figures show (all up to 60, else 48 of them), when the
    // report is written: the response's standard deviation is computed for them (at 50 x
    // 50 entries all of them cost a pass over the data)
    let band_entries = cfg.final_analysis.then(|| {
        crate::report::plotted_entries(&ctx.band, &final_response, Some(&ctx.noise.variance))
    });
    // without the ML link's covariance, one information matrix at the final model gives
    // both the standard deviations and the band
    let mut band: Option<Result<Vec<f64>, String>> = None;
    let uncertainty = match ml_link {
        Some(u) => Some(u),
        None => {
            let information = match &band_entries {
                Some(entries) => information_uncertainty_and_response_std(
                    &ctx, &fit.model, entries,
                )
                .map(|(u, std)| {
                    band = Some(Ok(std));
                    u
                }),
                None => information_uncertainty(&ctx, &fit.model),
            };
            match information {
                Ok(u) => Some(u),
                Err(why) => {
                    fit.messages
                        .push(format!("no standard deviations for the final model: {why}"));
                    None
                }
            }
        }
    };
    timings.stage("uncertainty", t);
    // the band beside the ML link's covariance (only when the report is written)
    if let (None, Some(entries), true) = (&band, &band_entries, uncertainty.is_some()) {
        let t = Instant::now();
        band = Some(response_std(&ctx, &fit.model, entries));
        timings.stage("response uncertainty", t);
    }
    let final_response_std = match band {
        Some(Ok(s)) => Some(s),
        Some(Err(why)) => {
            fit.messages
                .push(format!("no uncertainty band for the final response: {why}"));
            None
        }
        None => None,
    };
    timings.stage("total", t0);
    let summary = build_summary(
        &ctx,
        cfg,
        RunRecord {
            path,
            command,
            initial_model: &initial_model,
            fitter_report: &fitter_report,
            initial_errors,
            restart,
            steps,
            fit: &fit,
            analysis: analysis.as_ref(),
            floor_analysis: floor_analysis.as_ref(),
            distortion,
            final_errors,
            timings: timings.0,
            chain: first_chain.clone(),
            structure_steps: structure_steps(fitter_report.adapt.as_ref(), &first_links),
            chain_runs: first_chain_runs,
            from_fit,
            uncertainty,
        },
    );
    let peaks = fitter_report.cmif_peaks.clone();
    let initial_cost = additive_riv::residual_stats::cost_of(&initial_model, &ctx.fit_data);
    let FitContext {
        band, noise, cmif, ..
    } = ctx;
    Ok(PipelineOutput {
        band,
        fit,
        fitter_report,
        chain: first_chain,
        links: first_links,
        noise,
        cmif,
        peaks,
        initial_model,
        initial_response,
        initial_cost,
        final_response,
        final_response_std,
        step_responses,
        summary,
    })
}
