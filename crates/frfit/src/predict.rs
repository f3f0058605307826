//! Prediction of test records (`frfit predict`): a model judged on periodic measurements
//! it never saw, the metric of the system-identification benchmarks.
//!
//! For every experiment of the test records, the period-averaged input spectrum
//! `U(k)` at the excited lines drives the model: the periodic steady-state output is
//! `Y^(k) = G(j w_k) U(k)` (McKelvey, eq. (8): once the transient has decayed, one
//! period's DFT relates input and output exactly at the DFT lines). Against the
//! period-averaged measured output `Y(k)`, each output's normalised root-mean-square
//! error over the excited lines (and experiments, and realizations) is
//!
//! `NRMSE_i = sqrt( sum |Y_i - Y^_i|^2 / sum |Y_i|^2 )`,
//!
//! by Parseval the time-domain NRMSE of the periodic steady state restricted to the
//! excited lines (the lines that carry the output's linear response). The records' own
//! noise floor is the same ratio for the variance of `Y(k)` from the spread over periods,
//! `sum_p |Y_p - Y|^2 / (P (P - 1))`: a model at the floor predicts as well as the
//! records can tell. With one period there is no floor.

use crate::plots::{Axis, LinePlot, PlotGrid, Series};
use crate::FrfitError;
use experiment::nonparametric::PeriodicSpectra;
use frf_data::C64;
use realize::ResponseGrid;
use serde::Serialize;
use std::path::Path;

/// The error of one output.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OutputError {
    /// `NRMSE` of the prediction (see the module documentation).
    pub nrmse: f64,
    /// The records' noise floor on the same scale (`None` with one period).
    pub noise_floor: Option<f64>,
    /// `nrmse / noise_floor`: 1 at the floor.
    pub to_floor: Option<f64>,
}

/// What [`predict`] found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Prediction {
    /// Excited lines, Hz.
    pub freq_hz: Vec<f64>,
    /// Realizations x experiments the error is summed over.
    pub records: usize,
    /// Periods averaged per record.
    pub periods: usize,
    /// Per output.
    pub outputs: Vec<OutputError>,
    /// `|Y|` per output and line, the RMS over records (`[output][line]`).
    #[serde(skip)]
    pub measured: Vec<Vec<f64>>,
    /// `|Y^|` likewise.
    #[serde(skip)]
    pub predicted: Vec<Vec<f64>>,
    /// `|Y - Y^|` likewise.
    #[serde(skip)]
    pub error: Vec<Vec<f64>>,
    /// The noise level of `Y` likewise (empty with one period).
    #[serde(skip)]
    pub noise: Vec<Vec<f64>>,
}

/// [`predict`] with the response of `model` at the lines of `spectra`.
pub fn predict_model(
    model: &additive_riv::AdditiveModel,
    spectra: &PeriodicSpectra,
) -> Result<Prediction, FrfitError> {
    use frf_data::ModelStructure;
    let omega: Vec<f64> = spectra
        .freq_hz
        .iter()
        .map(|f| f * std::f64::consts::TAU)
        .collect();
    predict(&model.response_at(&omega), spectra)
}

/// Predicts the outputs of the test records `spectra` with the model response `g` at
/// their lines (`g` in the layout of [`ResponseGrid`], one matrix per line of
/// `spectra.freq_hz`) and compares them with the measured outputs.
pub fn predict(g: &ResponseGrid, spectra: &PeriodicSpectra) -> Result<Prediction, FrfitError> {
    let (ny, nu, nl) = (spectra.ny, spectra.nu, spectra.n_lines());
    if (g.ny, g.nu) != (ny, nu) {
        return Err(FrfitError::argument(
            "--records",
            format!("{ny} outputs, {nu} inputs"),
            format!("the model is {}x{}", g.ny, g.nu),
        ));
    }
    if g.len() != nl {
        return Err(FrfitError::Fit {
            what: "prediction".into(),
            why: format!("the model response has {} lines, the records {nl}", g.len()),
        });
    }
    let np = spectra.realizations[0].periods();
    let m = ny * nu;
    let zero = C64::new(0.0, 0.0);
    // sums over records per (output, line)
    let (mut sy, mut sp, mut se, mut sn) = (
        vec![0.0; ny * nl],
        vec![0.0; ny * nl],
        vec![0.0; ny * nl],
        vec![0.0; ny * nl],
    );
    let mut records = 0;
    // the period-averaged input and output of one record at one line
    let (mut u, mut y) = (vec![zero; nu], vec![zero; ny]);
    for rs in &spectra.realizations {
        for e in 0..rs.n_experiments() {
            records += 1;
            for k in 0..nl {
                u.fill(zero);
                y.fill(zero);
                for p in 0..np {
                    for (a, b) in u.iter_mut().zip(rs.input_at(e, p, k)) {
                        *a += *b / np as f64;
                    }
                    for (a, b) in y.iter_mut().zip(rs.output_at(e, p, k)) {
                        *a += *b / np as f64;
                    }
                }
                let gk = &g.values[k * m..(k + 1) * m];
                for i in 0..ny {
                    let yhat: C64 = (0..nu).map(|j| gk[j * ny + i] * u[j]).sum();
                    let idx = i * nl + k;
                    sy[idx] += y[i].norm_sqr();
                    sp[idx] += yhat.norm_sqr();
                    se[idx] += (y[i] - yhat).norm_sqr();
                    if np >= 2 {
                        let spread: f64 = (0..np)
                            .map(|p| (rs.output_at(e, p, k)[i] - y[i]).norm_sqr())
                            .sum();
                        sn[idx] += spread / (np * (np - 1)) as f64;
                    }
                }
            }
        }
    }
    let outputs = (0..ny)
        .map(|i| {
            let sum = |v: &[f64]| v[i * nl..(i + 1) * nl].iter().sum::<f64>();
            let ys = sum(&sy);
            let nrmse = if ys > 0.0 {
                (sum(&se) / ys).sqrt()
            } else {
                f64::NAN
            };
            let noise_floor = (np >= 2 && ys > 0.0).then(|| (sum(&sn) / ys).sqrt());
            OutputError {
                nrmse,
                noise_floor,
                to_floor: noise_floor.filter(|f| *f > 0.0).map(|f| nrmse / f),
            }
        })
        .collect();
    let rms = |v: &[f64]| -> Vec<Vec<f64>> {
        (0..ny)
            .map(|i| {
                v[i * nl..(i + 1) * nl]
                    .iter()
                    .map(|s| (s / records as f64).sqrt())
                    .collect()
            })
            .collect()
    };
    Ok(Prediction {
        freq_hz: spectra.freq_hz.clone(),
        records,
        periods: np,
        outputs,
        measured: rms(&sy),
        predicted: rms(&sp),
        error: rms(&se),
        noise: if np >= 2 { rms(&sn) } else { Vec::new() },
    })
}

impl Prediction {
    /// Measured, predicted and error spectra per output (one panel each), with the
    /// records' noise level.
    pub fn plot(&self, title: &str) -> PlotGrid {
        let panels = (0..self.outputs.len())
            .map(|i| {
                let f = self.freq_hz.clone();
                let o = &self.outputs[i];
                let mut p = LinePlot::new(format!(
                    "output {}: NRMSE {:.3e}{}",
                    i + 1,
                    o.nrmse,
                    o.noise_floor
                        .map(|n| format!(" (noise floor {n:.3e})"))
                        .unwrap_or_default()
                ))
                .with_y(Axis::log("|Y|"))
                .with_series(Series::line(
                    "measured",
                    f.clone(),
                    self.measured[i].clone(),
                ))
                .with_series(Series::dashed(
                    "predicted",
                    f.clone(),
                    self.predicted[i].clone(),
                ))
                .with_series(Series::line("error", f.clone(), self.error[i].clone()).with_width(2));
                if !self.noise.is_empty() {
                    p = p.with_series(Series::dashed(
                        "noise level (period spread)",
                        f,
                        self.noise[i].clone(),
                    ));
                }
                p
            })
            .collect();
        let n = self.outputs.len().max(1);
        let cols = n.min(2);
        PlotGrid {
            title: title.to_string(),
            rows: n.div_ceil(cols),
            cols,
            panels,
            panel_size: (640, 380),
        }
    }

    /// Writes `prediction.json` and `prediction.svg` into `dir` (created).
    pub fn write(&self, dir: &Path, title: &str) -> Result<(), FrfitError> {
        std::fs::create_dir_all(dir).map_err(|e| FrfitError::io(dir, e))?;
        let json_path = dir.join("prediction.json");
        let json = serde_json::to_string_pretty(self).map_err(|e| FrfitError::Io {
            path: json_path.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(&json_path, json).map_err(|e| FrfitError::io(&json_path, e))?;
        self.plot(title).write_svg(dir.join("prediction.svg"))
    }
}

/// Test records predicted by a diagnosis's initial and final model (`frfit diagnose
/// --test-records`, `frfit.diagnose(test_records=...)`): whether the diagnosis's changes
/// earn their place on records the fit never saw.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TestRecordPredictions {
    /// Where the records came from (file names, or a description of arrays).
    pub source: String,
    /// The model before the diagnosis loop on the records.
    pub initial: Prediction,
    /// The final model on the records.
    pub final_model: Prediction,
}

impl TestRecordPredictions {
    /// Both models of `out` on the test records `spectra` (from `source`).
    pub fn of(
        out: &crate::run::PipelineOutput,
        spectra: &PeriodicSpectra,
        source: &str,
    ) -> Result<Self, FrfitError> {
        Ok(Self {
            source: source.to_string(),
            initial: predict_model(&out.initial_model, spectra)?,
            final_model: predict_model(&out.fit.model, spectra)?,
        })
    }

    /// Writes `report_dir/test_records/initial/` and `final/` (each as `frfit predict`
    /// writes them) and appends a section to `report_dir/report.md` (which must exist:
    /// write the report first) with the NRMSE per output of both models and the records'
    /// noise floor.
    pub fn write_into_report(&self, report_dir: &Path) -> Result<(), FrfitError> {
        let dir = report_dir.join("test_records");
        self.initial.write(
            &dir.join("initial"),
            &format!("initial model on the test records {}", self.source),
        )?;
        self.final_model.write(
            &dir.join("final"),
            &format!("final model on the test records {}", self.source),
        )?;
        let md_path = report_dir.join("report.md");
        let mut md = std::fs::read_to_string(&md_path).map_err(|e| FrfitError::io(&md_path, e))?;
        let last = &self.final_model;
        md.push_str(&format!(
            "\n## Prediction of test records\n\n\
             The initial and the final model predict the periodic steady state of `{}` ({} \
             record(s), {} periods, {} excited lines): NRMSE per output over the excited \
             lines, and the records' own noise floor (the spread over periods).\n\n\
             | output | initial NRMSE | final NRMSE | noise floor |\n|---|---|---|---|\n",
            self.source,
            last.records,
            last.periods,
            last.freq_hz.len()
        ));
        for (i, (a, b)) in self.initial.outputs.iter().zip(&last.outputs).enumerate() {
            md.push_str(&format!(
                "| {} | {:.4e} | {:.4e} | {} |\n",
                i + 1,
                a.nrmse,
                b.nrmse,
                b.noise_floor
                    .map_or_else(|| "(one period)".to_string(), |f| format!("{f:.4e}"))
            ));
        }
        md.push_str(
            "\n![final model: measured, predicted and error spectra](test_records/final/prediction.svg)\n",
        );
        std::fs::write(&md_path, md).map_err(|e| FrfitError::io(&md_path, e))
    }
}
