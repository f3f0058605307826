//! Validation of a wafer-stage fit against the simulator's truth: the model's response
//! (with its hold and delay, as `frfit eval` evaluates a model file) against the exact
//! noiseless sampled plant at the same lines, the fitted modes against the true ones,
//! the rigid body and the delay; rendered as a console table and as `validation.md`.

use crate::{Context, Error};
use experiment::synth::truth_delay_samples;
use frf_data::truth::Truth;
use frf_data::{Frf, FrfDataset, ModelStructure, C64};
use frfit::additive_riv::{Domain, ModelFile};
use frfit::realize::{ModalModel, ResponseGrid};
use frfit::summary::Summary;
use std::fmt::Write as _;

/// What the validation compares.
pub struct Inputs<'a> {
    /// Seed of the simulation.
    pub seed: u64,
    /// Periods per realization of the experiment.
    pub periods: usize,
    /// Realizations of the experiment.
    pub realizations: usize,
    /// The fitted band of the data.
    pub data: &'a Frf,
    /// Noise variance of `data`, layout `[k * m + e]`.
    pub noise_var: &'a [f64],
    /// The truth, as read back from `truth.json`.
    pub truth: &'a Truth,
    /// The simulator's own exact response at every excited line (a cross-check of
    /// `truth.json`).
    pub simulator_exact: &'a Frf,
    /// The model, as read back from `model.json`.
    pub model_file: &'a ModelFile,
    /// The pipeline's response of the final model at the band's lines.
    pub pipeline_final: &'a ResponseGrid,
    /// The pipeline's summary.
    pub summary: &'a Summary,
}

/// Error of one response against a reference.
#[derive(Debug, Clone)]
pub struct ErrorRow {
    /// What is compared with what.
    pub label: &'static str,
    /// Median over lines and entries of `|x - ref| / |ref|`.
    pub median: f64,
    /// 95th percentile of the same.
    pub p95: f64,
    /// `sqrt(mean |x - ref|^2 / var)`: the error in units of the data's noise standard
    /// deviation (1 for data at their own noise level).
    pub rms_to_noise: f64,
}

/// A true mode and the fitted mode matched to it.
#[derive(Debug, Clone)]
pub struct ModeRow {
    /// True natural frequency, Hz.
    pub f_true: f64,
    /// True relative damping.
    pub zeta_true: f64,
    /// The true frequency lies in the fitted band.
    pub in_band: bool,
    /// The matched fitted mode: frequency, damping and the relative Frobenius error of
    /// its residue matrix.
    pub fitted: Option<(f64, f64, f64)>,
}

/// The result of [`compare`].
#[derive(Debug, Clone)]
pub struct Validation {
    header: Vec<String>,
    errors: Vec<ErrorRow>,
    data_noise_rel: f64,
    modes: Vec<ModeRow>,
    extra_modes: Vec<(f64, f64)>,
    rigid_body_err: Option<f64>,
    delay_true_s: f64,
    delay_model_s: f64,
    hold: String,
    model_delay_s: f64,
    truth_consistency: f64,
    model_roundtrip: f64,
    declared: Vec<String>,
}

/// Rows of a grid, line after line.
fn flatten(g: &ResponseGrid) -> Vec<C64> {
    (0..g.len()).flat_map(|k| g.line(k).to_vec()).collect()
}

/// The value at fraction `p` of the sorted `v` (nearest rank).
fn quantile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn error_row(label: &'static str, x: &[C64], reference: &[C64], var: &[f64]) -> ErrorRow {
    let mut rel = Vec::with_capacity(x.len());
    let (mut chi, mut cnt) = (0.0, 0usize);
    for ((a, b), v) in x.iter().zip(reference).zip(var) {
        let d = (a - b).norm();
        if b.norm() > 0.0 {
            rel.push(d / b.norm());
        }
        if *v > 0.0 && v.is_finite() {
            chi += d * d / v;
            cnt += 1;
        }
    }
    rel.sort_by(|a, b| a.total_cmp(b));
    ErrorRow {
        label,
        median: quantile(&rel, 0.5),
        p95: quantile(&rel, 0.95),
        rms_to_noise: if cnt > 0 {
            (chi / cnt as f64).sqrt()
        } else {
            f64::NAN
        },
    }
}

/// Largest `|x - ref| / |ref|`.
fn max_rel(x: &[C64], reference: &[C64]) -> f64 {
    x.iter()
        .zip(reference)
        .filter(|(_, b)| b.norm() > 0.0)
        .map(|(a, b)| (a - b).norm() / b.norm())
        .fold(0.0, f64::max)
}

/// Relative Frobenius distance of two `ny x nu` matrices given by accessors.
fn rel_frobenius(
    ny: usize,
    nu: usize,
    a: impl Fn(usize, usize) -> C64,
    b: impl Fn(usize, usize) -> C64,
) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for i in 0..ny {
        for j in 0..nu {
            num += (a(i, j) - b(i, j)).norm_sqr();
            den += b(i, j).norm_sqr();
        }
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else {
        f64::NAN
    }
}

/// One-to-one matching of fitted to true modes by nearest relative frequency (closest
/// pairs first), within 5 %: for each true mode the index of its fitted mode.
pub(crate) fn match_modes(true_f: &[f64], fit_f: &[f64]) -> Vec<Option<usize>> {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, &ft) in true_f.iter().enumerate() {
        for (j, &ff) in fit_f.iter().enumerate() {
            let d = (ff - ft).abs() / ft;
            if d < 0.05 {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut of_true = vec![None; true_f.len()];
    let mut used = vec![false; fit_f.len()];
    for (_, i, j) in pairs {
        if of_true[i].is_none() && !used[j] {
            of_true[i] = Some(j);
            used[j] = true;
        }
    }
    of_true
}

/// Compares the fit with the truth.
pub fn compare(inp: &Inputs) -> Result<Validation, Error> {
    let truth_mm: ModalModel = inp.truth.modal_model().stage("truth")?;
    let truth_delay = truth_delay_samples(inp.truth).stage("truth")?;
    let ts = 1.0 / inp.truth.fs;
    let (ny, nu) = inp.truth.dims();
    if (ny, nu) != (inp.data.ny(), inp.data.nu()) {
        return Err(Error::new(
            "validate",
            format!(
                "the truth is {ny}x{nu} but the data are {}x{}",
                inp.data.ny(),
                inp.data.nu()
            ),
        ));
    }

    // the noiseless sampled plant at the band's lines, from truth.json
    let omega = inp.data.omegas();
    let exact = flatten(
        &truth_mm
            .zoh_response(&omega, ts, truth_delay)
            .stage("truth response")?,
    );
    // truth.json against the simulator's own exact response (all excited lines)
    let all = truth_mm
        .zoh_response(&inp.simulator_exact.omegas(), ts, truth_delay)
        .stage("truth response")?;
    let truth_consistency = max_rel(&flatten(&all), inp.simulator_exact.values());

    // the model as `frfit eval` evaluates model.json
    let model = inp.model_file.to_model().stage("model.json")?;
    let pred = flatten(&model.response_at(&omega));
    let model_roundtrip = max_rel(&pred, &flatten(inp.pipeline_final));

    let data = inp.data.values();
    let var = inp.noise_var;
    let errors = vec![
        error_row("model vs noiseless truth", &pred, &exact, var),
        error_row("data vs noiseless truth", data, &exact, var),
        error_row("model vs data", &pred, data, var),
    ];
    let mut noise_rel: Vec<f64> = data
        .iter()
        .zip(var)
        .filter(|(g, _)| g.norm() > 0.0)
        .map(|(g, v)| v.sqrt() / g.norm())
        .collect();
    noise_rel.sort_by(|a, b| a.total_cmp(b));
    let data_noise_rel = quantile(&noise_rel, 0.5);

    // modes
    let band = inp.summary.data.band_hz;
    let fit_mm = model.to_modal_model().stage("model.json")?;
    let mut true_pairs = truth_mm.pairs.clone();
    true_pairs.sort_by(|a, b| a.f_hz().total_cmp(&b.f_hz()));
    let true_f: Vec<f64> = true_pairs.iter().map(|p| p.f_hz()).collect();
    let fit_f: Vec<f64> = fit_mm.pairs.iter().map(|p| p.f_hz()).collect();
    let matched = match_modes(&true_f, &fit_f);
    let modes: Vec<ModeRow> = true_pairs
        .iter()
        .zip(&matched)
        .map(|(tp, m)| ModeRow {
            f_true: tp.f_hz(),
            zeta_true: tp.zeta(),
            in_band: (band[0]..=band[1]).contains(&tp.f_hz()),
            fitted: m.map(|j| {
                let fp = &fit_mm.pairs[j];
                let r = rel_frobenius(ny, nu, |i, k| fp.residue[(i, k)], |i, k| tp.residue[(i, k)]);
                (fp.f_hz(), fp.zeta(), r)
            }),
        })
        .collect();
    let mut extra_modes: Vec<(f64, f64)> = fit_mm
        .pairs
        .iter()
        .enumerate()
        .filter(|(j, _)| !matched.contains(&Some(*j)))
        .map(|(_, p)| (p.f_hz(), p.zeta()))
        .collect();
    extra_modes.sort_by(|a, b| a.0.total_cmp(&b.0));

    // rigid body: the 1/s^2 residue
    let rigid_body_err = match (truth_mm.rigid.get(1), fit_mm.rigid.get(1)) {
        (Some(t), Some(f)) => Some(rel_frobenius(
            ny,
            nu,
            |i, j| C64::new(f[(i, j)], 0.0),
            |i, j| C64::new(t[(i, j)], 0.0),
        )),
        _ => None,
    };

    // delay: the model's total delay includes the exact hold's half sample
    let half_sample = match model.domain() {
        Domain::ZohDiscrete { ts } => 0.5 * ts,
        _ => 0.0,
    };
    let delay_model_s = inp.model_file.delay_s + half_sample;

    let s = inp.summary;
    let header = vec![
        format!(
            "Simulated wafer stage, seed {}: {}x{}, {} rigid-body + {} flexible modes, sampled at {} kHz (zero-order hold + {} sample of computation delay).",
            inp.seed,
            ny,
            nu,
            if truth_mm.rigid.len() >= 2 { "free" } else { "no" },
            true_pairs.len(),
            inp.truth.fs / 1e3,
            truth_delay
        ),
        format!(
            "Experiment: closed loop, {} periods x {} realizations of random-phase odd multisines; fitted band {:.4}..{:.4} Hz, {} lines.",
            inp.periods, inp.realizations, s.data.band_hz[0], s.data.band_hz[1], s.data.lines
        ),
        format!(
            "Model: {} modes, order {}, hold {}, delay {:.3} us; diagnosis verdict `{}`.",
            s.final_model.modes.len(),
            s.final_model.order,
            s.final_model.hold,
            s.final_model.delay_s * 1e6,
            s.verdict
        ),
    ];
    Ok(Validation {
        header,
        errors,
        data_noise_rel,
        modes,
        extra_modes,
        rigid_body_err,
        delay_true_s: inp.truth.delay_s,
        delay_model_s,
        hold: inp.model_file.hold.clone(),
        model_delay_s: inp.model_file.delay_s,
        truth_consistency,
        model_roundtrip,
        declared: s.initial.declared.clone(),
    })
}

impl Validation {
    /// Largest `|df| / f` and `|dzeta| / zeta` over the matched modes, how many of the
    /// true modes in the fitted band were matched, and how many lie in the band.
    pub fn mode_extremes(&self) -> (f64, f64, usize, usize) {
        let mut df: f64 = 0.0;
        let mut dz: f64 = 0.0;
        let mut n = 0;
        let in_band = self.modes.iter().filter(|m| m.in_band).count();
        for m in &self.modes {
            if let Some((f, z, _)) = m.fitted {
                df = df.max((f - m.f_true).abs() / m.f_true);
                dz = dz.max((z - m.zeta_true).abs() / m.zeta_true);
                n += usize::from(m.in_band);
            }
        }
        (df, dz, n, in_band)
    }

    fn mode_lines(&self, md: bool) -> Vec<String> {
        let mut out = Vec::new();
        for (i, m) in self.modes.iter().enumerate() {
            let (f, z, df, dz, r) = match m.fitted {
                Some((f, z, r)) => (
                    format!("{f:.4}"),
                    format!("{z:.5}"),
                    format!("{:+.2e}", (f - m.f_true) / m.f_true),
                    format!("{:+.2e}", (z - m.zeta_true) / m.zeta_true),
                    format!("{r:.2e}"),
                ),
                None => (
                    if m.in_band { "missed" } else { "off-band" }.into(),
                    "-".into(),
                    "-".into(),
                    "-".into(),
                    "-".into(),
                ),
            };
            out.push(if md {
                format!(
                    "| {} | {:.4} | {} | {} | {:.5} | {} | {} | {} |",
                    i + 1,
                    m.f_true,
                    f,
                    df,
                    m.zeta_true,
                    z,
                    dz,
                    r
                )
            } else {
                format!(
                    "  {:>2}  {:>10.4}  {:>10}  {:>9}  {:>9.5}  {:>8}  {:>10}  {:>8}",
                    i + 1,
                    m.f_true,
                    f,
                    df,
                    m.zeta_true,
                    z,
                    dz,
                    r
                )
            });
        }
        out
    }

    fn summary_lines(&self) -> Vec<String> {
        let (df, dz, n, in_band) = self.mode_extremes();
        let off_band = self.modes.len() - in_band;
        let mut v = vec![format!(
            "{n} of the {in_band} true modes in the fitted band matched{} (max |df|/f {df:.2e}, max |dzeta|/zeta {dz:.2e}); {} extra fitted mode(s){}",
            if off_band > 0 {
                format!(", {off_band} true mode(s) outside the band")
            } else {
                String::new()
            },
            self.extra_modes.len(),
            if self.extra_modes.is_empty() {
                String::new()
            } else {
                format!(
                    ": {}",
                    self.extra_modes
                        .iter()
                        .map(|(f, z)| format!("{f:.2} Hz (zeta {z:.4})"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        )];
        v.push(match self.rigid_body_err {
            Some(e) => format!("rigid body: relative error of the 1/s^2 residue matrix {e:.2e}"),
            None => "rigid body: the truth or the model has no 1/s^2 term".into(),
        });
        v.push(format!(
            "delay: truth {:.3} us (hold + computation); model {:.3} us (hold {} + {:.3} us)",
            self.delay_true_s * 1e6,
            self.delay_model_s * 1e6,
            self.hold,
            self.model_delay_s * 1e6
        ));
        v
    }

    /// The short table printed at the end of the run.
    pub fn console_table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "validation against the simulated truth");
        let _ = writeln!(
            s,
            "  {:<26} {:>10} {:>10} {:>12}",
            "response error", "median", "p95", "rms/noise"
        );
        for r in &self.errors {
            let _ = writeln!(
                s,
                "  {:<26} {:>10.3e} {:>10.3e} {:>12.3}",
                r.label, r.median, r.p95, r.rms_to_noise
            );
        }
        let _ = writeln!(
            s,
            "  {:<26} {:>10.3e}   (median sqrt(var)/|G|)",
            "data noise level", self.data_noise_rel
        );
        let _ = writeln!(
            s,
            "\n   #   f true Hz    f fit Hz       df/f  zeta true  zeta fit  dzeta/zeta   residue"
        );
        for l in self.mode_lines(false) {
            let _ = writeln!(s, "{l}");
        }
        for l in self.summary_lines() {
            let _ = writeln!(s, "  {l}");
        }
        s
    }

    /// `validation.md`.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# Validation against the simulated truth\n");
        for h in &self.header {
            let _ = writeln!(s, "{h}");
        }
        if !self.declared.is_empty() {
            let _ = writeln!(s, "\nDeclared to the pipeline (not discovered):\n");
            for d in &self.declared {
                let _ = writeln!(s, "- {d}");
            }
        }
        let _ = writeln!(s, "\n## Frequency response\n");
        let _ = writeln!(
            s,
            "Relative error `|x - ref| / |ref|` over all lines and entries of the fitted band; \
             the model is evaluated from `model.json` with its hold and delay (as `frfit eval` does), \
             the truth is the exact zero-order-hold response of `truth.json` with its delay. \
             `rms/noise` is `sqrt(mean |x - ref|^2 / var)` with the data's variance.\n"
        );
        let _ = writeln!(s, "| compared | median | p95 | rms/noise |");
        let _ = writeln!(s, "|---|---:|---:|---:|");
        for r in &self.errors {
            let _ = writeln!(
                s,
                "| {} | {:.3e} | {:.3e} | {:.3} |",
                r.label, r.median, r.p95, r.rms_to_noise
            );
        }
        let _ = writeln!(
            s,
            "| data noise level, median `sqrt(var)/abs(G)` | {:.3e} | | |",
            self.data_noise_rel
        );
        let _ = writeln!(s, "\n## Modes\n");
        let _ = writeln!(
            s,
            "True modes matched one-to-one to fitted modes by nearest frequency (within 5 %); \
             `off-band`: the true mode lies outside the fitted band. \
             `residue` is the relative Frobenius error of the mode's complex residue matrix.\n"
        );
        let _ = writeln!(
            s,
            "| # | f true [Hz] | f fit [Hz] | df/f | zeta true | zeta fit | dzeta/zeta | residue |"
        );
        let _ = writeln!(s, "|---:|---:|---:|---:|---:|---:|---:|---:|");
        for l in self.mode_lines(true) {
            let _ = writeln!(s, "{l}");
        }
        let _ = writeln!(s, "\n## Summary\n");
        for l in self.summary_lines() {
            let _ = writeln!(s, "- {l}");
        }
        let _ = writeln!(s, "\n## Consistency checks\n");
        let _ = writeln!(
            s,
            "- `truth.json` response vs the simulator's exact response: max relative difference {:.2e}",
            self.truth_consistency
        );
        let _ = writeln!(
            s,
            "- `model.json` response vs the pipeline's final response: max relative difference {:.2e}",
            self.model_roundtrip
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_match_one_to_one_nearest_first() {
        // 100 and 101 compete for 100.5; 100 is taken by 100.2, 101 by 100.5
        let m = match_modes(
            &[100.0, 101.0, 500.0, 900.0],
            &[100.5, 100.2, 505.0, 2000.0],
        );
        assert_eq!(m, vec![Some(1), Some(0), Some(2), None]);
    }

    #[test]
    fn error_rows_and_quantiles() {
        let reference = vec![C64::new(1.0, 0.0); 4];
        let x = vec![
            C64::new(1.0, 0.0),
            C64::new(1.1, 0.0),
            C64::new(1.0, 0.2),
            C64::new(0.7, 0.0),
        ];
        let r = error_row("x", &x, &reference, &[0.01; 4]);
        assert!((r.median - 0.2).abs() < 1e-12, "{}", r.median);
        assert!((r.p95 - 0.3).abs() < 1e-12);
        let want = ((0.0 + 0.01 + 0.04 + 0.09) / 4.0 / 0.01f64).sqrt();
        assert!((r.rms_to_noise - want).abs() < 1e-12);
        assert!(quantile(&[], 0.5).is_nan());
        assert!((max_rel(&x, &reference) - 0.3).abs() < 1e-12);
    }
}
