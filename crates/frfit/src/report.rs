//! The report of a fit or a diagnosis: `report.md`, its SVG figures and `summary.json`.
//!
//! [`write_report`] writes, into one directory:
//!
//! | file | content |
//! |---|---|
//! | `summary.json` | the [`Summary`] (pretty JSON; the step figures filled in) |
//! | `cmif.svg` | the CMIF of the data with the picked modes (Fig. 3 of the wafer-stage paper) |
//! | `bode_grid.svg` | element-wise Bode magnitude of the data and the final model (Fig. 4) |
//! | `entry.svg` | the worst entry: data, model, residual `abs(G - P)` and noise level (Fig. 5) |
//! | `residual_ratio.svg` | residual-to-noise ratio per line of the initial and final model |
//! | `step_N_EFFECT.svg` | per diagnosis step, the residual before and after the step |
//! | `report.md` | all of the above in words, tables and the embedded figures |
//!
//! The residual-to-noise ratio of a line is `sqrt(mean_e abs(E_e)^2 / var_e)` over the
//! entries `e` with a positive variance (1 at the noise level); without a variance the
//! figures show the rms residual `sqrt(mean_e abs(E_e)^2)` instead and say so.
//!
//! The Bode grid shows every entry up to [`MAX_GRID_PANELS`] entries (rows are outputs
//! and columns inputs; a plant with more than 8 inputs is transposed, a tall grid is
//! folded into side-by-side blocks); above that it shows the [`GRID_SUBSET`] entries with
//! the largest residual energy of the final model, and the caption says so.
//!
//! Series with thousands of lines are decimated to the pixel columns of their panel
//! (first, lowest, highest and last point of each column), so resonance peaks survive and
//! the 4 x 13 wafer-stage report takes a fraction of a second.

use crate::effects::Repair;
use crate::plots::{cmif_plot, Axis, LinePlot, Marker, Series, SharedGrid, PALETTE};
use crate::summary::{DistortionSummary, ErrorStats, StepSummary, Summary};
use crate::FrfitError;
use frf_data::cmif::{Cmif, CmifPeak};
use frf_data::{Frf, FrfDataset, FrfError};
use realize::ResponseGrid;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The file name of the diagnosis's start model in the report directory, beside
/// `report.md` (the run writes it with the report).
pub const START_MODEL_FILE: &str = "start_model.json";

/// Above this many entries the Bode grid shows a subset.
pub const MAX_GRID_PANELS: usize = 60;
/// How many entries the Bode grid shows when the plant has more than
/// [`MAX_GRID_PANELS`].
pub const GRID_SUBSET: usize = 48;

/// The files every report has.
const FIXED_FILES: [&str; 6] = [
    "summary.json",
    "cmif.svg",
    "bode_grid.svg",
    "entry.svg",
    "residual_ratio.svg",
    "report.md",
];

const DATA_COLOR: (u8, u8, u8) = PALETTE[0];
const MODEL_COLOR: (u8, u8, u8) = PALETTE[1];
const RESIDUAL_COLOR: (u8, u8, u8) = PALETTE[3];
const NOISE_COLOR: (u8, u8, u8) = (110, 110, 110);
const MARK_COLOR: (u8, u8, u8) = PALETTE[3];

/// What the report shows besides the [`Summary`]: the data, its CMIF and the model
/// responses at the data's lines.
#[derive(Debug, Clone, Copy)]
pub struct ReportInput<'a> {
    /// The band that was fitted.
    pub data: &'a Frf,
    /// Noise variance per line and entry, layout `[k * m + e]` with `m = ny * nu` and
    /// entry `e = j * ny + i` (the layout of [`Frf::values`]); `None` when not known
    /// (the ratio figures then show the residual itself).
    pub noise_var: Option<&'a [f64]>,
    /// The CMIF of the data.
    pub cmif: &'a Cmif,
    /// The CMIF peaks the initial model started from.
    pub peaks: &'a [CmifPeak],
    /// Response of the initial model at the data's lines.
    pub initial: &'a ResponseGrid,
    /// Response of the final model at the data's lines.
    pub final_model: &'a ResponseGrid,
    /// Standard deviation of the final model's response at the data's lines (layout as
    /// `noise_var`), from its parameters' covariance; `None` when none was formed. The
    /// Bode and entry plots draw the model's `+- 2 sigma` band with it.
    pub final_model_std: Option<&'a [f64]>,
    /// For each `summary.steps[i]`, the model response before and after that step.
    pub steps: &'a [(ResponseGrid, ResponseGrid)],
    /// Title of the report.
    pub title: &'a str,
}

/// Removes the per-step figures (`step_*.svg`) an earlier report left in `dir`, so that
/// a rerun with fewer steps does not leave figures of steps that no longer exist.
fn remove_stale_step_figures(dir: &Path) -> Result<(), FrfitError> {
    let entries = std::fs::read_dir(dir).map_err(|e| FrfitError::io(dir, e))?;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with("step_") && name.ends_with(".svg") {
            let path = entry.path();
            std::fs::remove_file(&path).map_err(|e| FrfitError::io(&path, e))?;
        }
    }
    Ok(())
}

/// Writes the report into `dir` (created if needed): `summary.json`, the figures and
/// `report.md` (see the [module documentation](self)); returns the paths written, in
/// that order.
///
/// Each step figure is named `summary.steps[i].figure` when that is a plain `.svg` file
/// name not used by another figure, else `step_{i+1}_{effect}.svg`; the `summary.json`
/// written holds the names used.
///
/// Fails when the model responses, the noise variance or the steps do not match the data
/// and the summary ([`FrfError::Dimension`]), or when a file cannot be written.
pub fn write_report(
    dir: &Path,
    input: &ReportInput,
    summary: &Summary,
) -> Result<Vec<PathBuf>, FrfitError> {
    check_input(input, summary)?;
    std::fs::create_dir_all(dir).map_err(|e| FrfitError::io(dir, e))?;
    remove_stale_step_figures(dir)?;
    let mut written = Vec::new();

    let mut summary = summary.clone();
    let mut step_files: Vec<String> = Vec::with_capacity(summary.steps.len());
    for (i, step) in summary.steps.iter().enumerate() {
        // A name that collides with another figure falls back to the default one.
        let taken = |f: &String| FIXED_FILES.contains(&f.as_str()) || step_files.contains(f);
        let mut name = step_file_name(i, step);
        if taken(&name) {
            name = default_step_file_name(i, step);
        }
        let mut k = 2;
        while taken(&name) {
            name = format!("step_{}_{k}.svg", i + 1);
            k += 1;
        }
        step_files.push(name);
    }
    for (s, f) in summary.steps.iter_mut().zip(&step_files) {
        s.figure = Some(f.clone());
    }
    let json_path = dir.join("summary.json");
    let json = serde_json::to_string_pretty(&summary).map_err(|e| FrfitError::Io {
        path: json_path.display().to_string(),
        message: format!("summary does not serialise: {e}"),
    })?;
    write_text(&json_path, &(json + "\n"))?;
    written.push(json_path);

    let data = input.data;
    let freqs = data.freq_hz_slice().to_vec();
    let var = input.noise_var;
    let initial = Residual::new(data, input.initial, var);
    let fin = Residual::new(data, input.final_model, var);
    let mut figs = Figures::default();

    // Fig. 1: CMIF with the picked modes.
    let path = dir.join("cmif.svg");
    let cmif_title = format!(
        "CMIF of the data with {} picked mode{}",
        input.peaks.len(),
        plural(input.peaks.len())
    );
    cmif_plot(input.cmif, input.peaks, &cmif_title).write_svg(&path, (1000, 560))?;
    figs.push(
        &path,
        "CMIF",
        format!(
            "CMIF: the squared singular values sigma_i^2 of the FRF at every line, with the \
             {} picked mode{} (dots, labelled in Hz) the initial model started from.",
            input.peaks.len(),
            plural(input.peaks.len())
        ),
    );
    written.push(path);

    // Fig. 2: element-wise Bode magnitude grid.
    let path = dir.join("bode_grid.svg");
    let caption = bode_grid_svg(&path, input, &fin)?;
    figs.push(&path, "Bode magnitude grid", caption);
    written.push(path);

    // Fig. 3: the worst entry.
    let path = dir.join("entry.svg");
    let caption = entry_svg(&path, input, &fin)?;
    figs.push(&path, "worst entry", caption);
    written.push(path);

    // Fig. 4: residual ratio of the initial and the final model.
    let path = dir.join("residual_ratio.svg");
    let mut plot = ratio_plot(
        "Residual per line: initial and final model",
        &freqs,
        var.is_some(),
    );
    plot.series.push(
        Series::line("initial model", freqs.clone(), initial.per_line.clone())
            .with_color(MODEL_COLOR),
    );
    plot.series.push(
        Series::line("final model", freqs.clone(), fin.per_line.clone())
            .with_color(DATA_COLOR)
            .with_width(2),
    );
    add_reference(&mut plot, data, &freqs, var.is_some());
    headroom(&mut plot);
    plot.write_svg(&path, (1000, 480))?;
    figs.push(&path, "residual ratio", ratio_caption(var.is_some()));
    written.push(path);

    // One figure per step.
    let mut step_figs = Vec::new();
    for (i, ((step, (before, after)), file)) in summary
        .steps
        .iter()
        .zip(input.steps)
        .zip(&step_files)
        .enumerate()
    {
        let path = dir.join(file);
        let b = Residual::new(data, before, var);
        let a = Residual::new(data, after, var);
        let mut plot = ratio_plot(&step_title(i, step), &freqs, var.is_some());
        plot.series.push(
            Series::line("before", freqs.clone(), b.per_line.clone()).with_color(MODEL_COLOR),
        );
        plot.series.push(
            Series::line("after", freqs.clone(), a.per_line.clone())
                .with_color(DATA_COLOR)
                .with_width(2),
        );
        let marked = mark_frequencies(
            &mut plot,
            &step.fitted.params_json(),
            &freqs,
            &b.per_line,
            &a.per_line,
        );
        add_reference(&mut plot, data, &freqs, var.is_some());
        headroom(&mut plot);
        plot.write_svg(&path, (1000, 440))?;
        step_figs.push((file.clone(), marked));
        written.push(path);
    }

    let md = markdown(input, &summary, &figs, &step_figs, &fin);
    let md_path = dir.join("report.md");
    write_text(&md_path, &md)?;
    written.push(md_path);
    Ok(written)
}

/// Checks that the responses, the variance and the steps match the data and the summary.
fn check_input(input: &ReportInput, summary: &Summary) -> Result<(), FrfitError> {
    let d = input.data;
    let (n, ny, nu) = (d.n_lines(), d.ny(), d.nu());
    let dim = |what: &str, expected: String, got: String| {
        FrfitError::Data(FrfError::Dimension {
            what: format!("report: {what}"),
            expected,
            got,
        })
    };
    let grid = |what: &str, g: &ResponseGrid| -> Result<(), FrfitError> {
        if g.ny != ny || g.nu != nu || g.values.len() != n * ny * nu {
            return Err(dim(
                what,
                format!("{n} lines of {ny}x{nu} (the data)"),
                format!("{} values of {}x{}", g.values.len(), g.ny, g.nu),
            ));
        }
        Ok(())
    };
    grid("initial model response", input.initial)?;
    grid("final model response", input.final_model)?;
    if input.steps.len() != summary.steps.len() {
        return Err(dim(
            "step responses",
            format!("{} (one pair per summary step)", summary.steps.len()),
            input.steps.len().to_string(),
        ));
    }
    for (i, (b, a)) in input.steps.iter().enumerate() {
        grid(&format!("response before step {}", i + 1), b)?;
        grid(&format!("response after step {}", i + 1), a)?;
    }
    for (what, v) in [
        ("noise variance", input.noise_var),
        ("final model's standard deviation", input.final_model_std),
    ] {
        if let Some(v) = v {
            if v.len() != n * ny * nu {
                return Err(dim(
                    what,
                    format!("{} ({n} lines x {ny}x{nu})", n * ny * nu),
                    v.len().to_string(),
                ));
            }
        }
    }
    Ok(())
}

/// The magnitudes `|P| + 2 sigma` and `|P| - 2 sigma` of entry `e` (layout `[k * m + e]`)
/// of the model response `p` with standard deviation `std`: the model's band. The lower
/// edge is left out (NaN, a gap in the line) where it is not positive.
fn two_sigma_band(p: &ResponseGrid, std: &[f64], e: usize, m: usize) -> (Vec<f64>, Vec<f64>) {
    let n = p.values.len() / m.max(1);
    (0..n)
        .map(|k| {
            let (a, s) = (p.values[k * m + e].norm(), 2.0 * std[k * m + e]);
            (a + s, if a - s > 0.0 { a - s } else { f64::NAN })
        })
        .unzip()
}

fn write_text(path: &Path, text: &str) -> Result<(), FrfitError> {
    std::fs::write(path, text).map_err(|e| FrfitError::io(path, e))
}

/// The "added" cell of a diagnosis step: `yes`, `no`, or `yes, removed at step N` for
/// a factor a later step took out of the model.
fn added_cell(t: &crate::summary::StepSummary) -> String {
    match (t.accepted, t.superseded_by) {
        (true, Some(n)) => format!("yes, removed at step {n}"),
        (true, None) => "yes".into(),
        (false, _) => "no".into(),
    }
}
/// The first fit's structure steps ([`crate::summary::StructureStepSummary`]) as a
/// table: the refiner, what each changed, whether it was taken, the weighted cost before
/// and after and the test.
fn structure_steps_table(md: &mut String, steps: &[crate::summary::StructureStepSummary]) {
    if steps.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "**Structure steps of the first fit's refiners** (part of the first fit; the weighted cost `sum w |G - P|^2` of the structure tested from and of the trial, and where it was tested, the cost on lines the structures were not fitted to, without and with the change):\n"
    );
    let _ = writeln!(
        md,
        "| # | link | change | taken | cost before | cost after | F (critical) | held-out cost (F) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
    for (i, s) in steps.iter().enumerate() {
        let st = &s.step;
        let f = match (st.f_statistic, st.f_critical) {
            (Some(f), Some(c)) => format!("{} ({})", fmt_num(f), fmt_num(c)),
            (Some(f), None) => fmt_num(f),
            _ => "-".into(),
        };
        let _ = writeln!(
            md,
            "| {} | {} | `{}`: {} | {} | {} | {} | {f} | {} |",
            i + 1,
            s.link,
            st.change.name(),
            cell(&st.change.describe()),
            if st.accepted { "yes" } else { "no" },
            fmt_num(st.cost_before),
            st.cost_after.map_or("-".into(), fmt_num),
            st.held_out.map_or("-".into(), |h| format!(
                "{} -> {}{}",
                fmt_num(h.before),
                fmt_num(h.after),
                h.f_statistic
                    .map_or(String::new(), |f| format!(" ({})", fmt_num(f)))
            )),
        );
    }
    md.push('\n');
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// The figure file of step `i`: the summary's name when it is a plain `.svg` file name
/// (letters, digits, `_`, `-`, `.`), else [`default_step_file_name`].
fn step_file_name(i: usize, step: &StepSummary) -> String {
    if let Some(f) = &step.figure {
        let plain = f.len() > 4
            && f.ends_with(".svg")
            && !f.starts_with('.')
            && f.chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
        if plain {
            return f.clone();
        }
    }
    default_step_file_name(i, step)
}

/// `step_{i+1}_{effect}.svg` with the effect reduced to `[a-z0-9_]`.
fn default_step_file_name(i: usize, step: &StepSummary) -> String {
    let effect: String = step
        .effect()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .take(40)
        .collect();
    let effect = if effect.is_empty() {
        "effect".to_string()
    } else {
        effect
    };
    format!("step_{}_{}.svg", i + 1, effect)
}

/// The residual of one model against the data.
struct Residual {
    /// Per line: residual-to-noise ratio (with a variance) or rms `abs(E)` (without).
    per_line: Vec<f64>,
    /// Per entry: mean squared residual-to-noise ratio (with a variance) or the relative
    /// residual energy `sum abs(E)^2 / sum abs(G)^2` (without).
    per_entry: Vec<f64>,
}

impl Residual {
    fn new(data: &Frf, model: &ResponseGrid, var: Option<&[f64]>) -> Self {
        let (n, m) = (data.n_lines(), data.n_entries());
        let g = data.values();
        let p = &model.values;
        let mut per_line = Vec::with_capacity(n);
        let mut num = vec![0.0; m];
        let mut den = vec![0.0; m];
        for k in 0..n {
            let (mut acc, mut cnt) = (0.0, 0usize);
            for e in 0..m {
                let idx = k * m + e;
                let (Some(gv), Some(pv)) = (g.get(idx), p.get(idx)) else {
                    continue;
                };
                let r2 = (gv - pv).norm_sqr();
                if !r2.is_finite() {
                    continue;
                }
                match var {
                    Some(v) => {
                        let s = v.get(idx).copied().unwrap_or(f64::NAN);
                        if s.is_finite() && s > 0.0 {
                            acc += r2 / s;
                            cnt += 1;
                            num[e] += r2 / s;
                            den[e] += 1.0;
                        }
                    }
                    None => {
                        acc += r2;
                        cnt += 1;
                        num[e] += r2;
                        den[e] += gv.norm_sqr();
                    }
                }
            }
            per_line.push(if cnt > 0 {
                (acc / cnt as f64).sqrt()
            } else {
                f64::NAN
            });
        }
        let per_entry = num
            .iter()
            .zip(&den)
            .map(|(a, b)| if *b > 0.0 { a / b } else { f64::NAN })
            .collect();
        Self {
            per_line,
            per_entry,
        }
    }

    /// The entry `(i, j)` with the largest score, and the score.
    fn worst_entry(&self, ny: usize) -> (usize, usize, f64) {
        let mut best = (0usize, f64::NEG_INFINITY);
        for (e, &s) in self.per_entry.iter().enumerate() {
            if s.is_finite() && s > best.1 {
                best = (e, s);
            }
        }
        let ny = ny.max(1);
        (best.0 % ny, best.0 / ny, best.1)
    }
}

/// Figures of the report, in order: (file name, alt text, caption).
#[derive(Default)]
struct Figures(Vec<(String, String, String)>);

impl Figures {
    fn push(&mut self, path: &Path, alt: &str, caption: String) {
        let name = path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.0.push((name, alt.to_string(), caption));
    }
}

/// A per-line residual panel: log frequency against the ratio (or rms residual).
fn ratio_plot(title: &str, freqs: &[f64], has_var: bool) -> LinePlot {
    let y = if has_var {
        Axis::log("residual / noise (rms over entries)")
    } else {
        Axis::log("|G - P| (rms over entries)")
    };
    let mut p = LinePlot::new(title).with_y(y);
    if let (Some(&lo), Some(&hi)) = (
        freqs.iter().find(|f| **f > 0.0),
        freqs.iter().rev().find(|f| **f > 0.0),
    ) {
        if hi > lo {
            p.x.range = Some((lo, hi));
        }
    }
    p
}

/// The noise level 1 (with a variance) or the data's rms magnitude for scale (without).
fn add_reference(plot: &mut LinePlot, data: &Frf, freqs: &[f64], has_var: bool) {
    if has_var {
        if let (Some(&lo), Some(&hi)) = (freqs.first(), freqs.last()) {
            plot.series.push(
                Series::dashed("noise level", vec![lo, hi], vec![1.0, 1.0]).with_color((0, 0, 0)),
            );
        }
    } else {
        let m = data.n_entries().max(1);
        let rms = (0..data.n_lines())
            .map(|k| {
                let s: f64 = data.line(k).iter().map(|z| z.norm_sqr()).sum();
                (s / m as f64).sqrt()
            })
            .collect();
        plot.series.push(
            Series::line("|G| (rms, for scale)", freqs.to_vec(), rms).with_color(NOISE_COLOR),
        );
    }
}

/// Fixes the log y range of `plot` to its data (at most 10 decades deep) with a quarter
/// of the height free on top, where the legend goes.
fn headroom(plot: &mut LinePlot) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for s in &plot.series {
        for &v in &s.y {
            if v.is_finite() && v > 0.0 {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !(lo.is_finite() && hi > 0.0) {
        return;
    }
    let lo = lo.max(hi * 1e-10);
    let (l, h) = (lo.log10(), hi.log10());
    let span = (h - l).max(0.5);
    plot.y.range = Some((10f64.powf(l - 0.04 * span), 10f64.powf(h + 0.33 * span)));
}

fn ratio_caption(has_var: bool) -> String {
    if has_var {
        "Residual-to-noise ratio per line, sqrt(mean over entries of |G - P|^2 / var), of \
         the initial and the final model; the dashed line at 1 is the noise level."
            .into()
    } else {
        "Residual |G - P| per line (rms over entries) of the initial and the final model, \
         with the rms magnitude of the data for scale; the data carry no variance, so no \
         noise level can be marked."
            .into()
    }
}

/// Draws the Bode grid; returns its caption.
fn bode_grid_svg(path: &Path, input: &ReportInput, fin: &Residual) -> Result<String, FrfitError> {
    let data = input.data;
    let (ny, nu) = (data.ny(), data.nu());
    let layout = grid_layout(ny, nu, &fin.per_entry);
    let freqs = data.freq_hz_slice();
    let (n, m) = (data.n_lines(), ny * nu);
    let mut top = 0.0f64;
    let mut bottom = f64::INFINITY;
    let mut panels = Vec::with_capacity(layout.cells.len());
    for cell in &layout.cells {
        let Some((i, j)) = *cell else {
            panels.push(None);
            continue;
        };
        let e = j * ny + i;
        let g: Vec<f64> = (0..n).map(|k| data.values()[k * m + e].norm()).collect();
        let p: Vec<f64> = (0..n)
            .map(|k| input.final_model.values[k * m + e].norm())
            .collect();
        for &v in g.iter().chain(&p) {
            if v.is_finite() && v > 0.0 {
                top = top.max(v);
                bottom = bottom.min(v);
            }
        }
        // The model as a wide band under the data: where they agree, a blue line in an
        // orange band; where they differ, both stand out.
        let mut panel = LinePlot::new(format!("G{}_{}", i + 1, j + 1));
        panel.series.push(
            Series::line("final model", freqs.to_vec(), p)
                .with_color(MODEL_COLOR)
                .with_width(3),
        );
        if let Some(std) = input.final_model_std {
            let (hi, lo) = two_sigma_band(input.final_model, std, e, m);
            for (name, v) in [("model +- 2 sigma", hi), ("", lo)] {
                panel.series.push(
                    Series::dashed(name, freqs.to_vec(), v)
                        .with_color(MODEL_COLOR)
                        .with_width(1),
                );
            }
        }
        panel
            .series
            .push(Series::line("data", freqs.to_vec(), g).with_color(DATA_COLOR));
        panels.push(Some(panel));
    }
    let units = data
        .units
        .as_deref()
        .map(|u| format!("Magnitude [{u}]"))
        .unwrap_or_else(|| "Magnitude".into());
    let mut y = Axis::log(units);
    if top > 0.0 && bottom.is_finite() {
        // Shared range: the data's, at most 9 decades deep (zeros and noise floors of
        // cross terms would squash every panel otherwise).
        let lo = bottom.max(top * 1e-9);
        y.range = Some((lo / 1.6, top * 1.6));
    }
    let mut x = Axis::log("Frequency [Hz]");
    if let (Some(&lo), Some(&hi)) = (
        freqs.iter().find(|f| **f > 0.0),
        freqs.iter().rev().find(|f| **f > 0.0),
    ) {
        if hi > lo {
            x.range = Some((lo, hi));
        }
    }
    let pw = (1000 / layout.cols.max(1) as u32).clamp(110, 420);
    let ph = (pw as f64 * 0.52).clamp(68.0, 240.0) as u32;
    let grid = SharedGrid {
        title: format!("Bode magnitude: data and final model ({ny} x {nu})"),
        rows: layout.rows,
        cols: layout.cols,
        panels,
        x,
        y,
        panel_size: (pw, ph),
        legend: true,
    };
    grid.write_svg(path)?;
    let band = if input.final_model_std.is_some() {
        "; the thin dashed orange lines are the model's +- 2 sigma band from the covariance of \
         its parameters (they merge with the model where the data determine it well)"
    } else {
        ""
    };
    Ok(format!(
        "Element-wise Bode magnitude of the data (blue line) and the final model (orange \
         band under it), {}; shared log axes{band}.",
        layout.note
    ))
}

/// Where the Bode grid puts which entry.
struct GridLayout {
    rows: usize,
    cols: usize,
    /// Row after row: the entry `(i, j)` of each cell.
    cells: Vec<Option<(usize, usize)>>,
    /// What is shown and how, for the caption.
    note: String,
}

/// Lays out the entries of an `ny x nu` plant (see the module documentation).
/// The entries (`e = j * ny + i`) the Bode grid shows of a plant with more than
/// [`MAX_GRID_PANELS`] entries: the [`GRID_SUBSET`] with the largest `score`, in
/// output-then-input order.
fn grid_subset(ny: usize, nu: usize, score: &[f64]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..ny * nu).collect();
    let s = |e: usize| {
        score
            .get(e)
            .copied()
            .filter(|v| v.is_finite())
            .unwrap_or(-1.0)
    };
    idx.sort_by(|a, b| s(*b).total_cmp(&s(*a)));
    idx.truncate(GRID_SUBSET);
    idx.sort_by_key(|e| (e % ny, e / ny));
    idx
}

/// The entries (`e = j * ny + i`) the report's figures show of `model` against `data`
/// (with the noise variance `var`): every entry up to [`MAX_GRID_PANELS`], else the Bode
/// grid's subset, which holds the entry plot's worst entry. What the model's band needs
/// to be computed for.
pub fn plotted_entries(data: &Frf, model: &ResponseGrid, var: Option<&[f64]>) -> Vec<usize> {
    let (ny, nu) = (data.ny(), data.nu());
    if ny * nu <= MAX_GRID_PANELS {
        return (0..ny * nu).collect();
    }
    grid_subset(ny, nu, &Residual::new(data, model, var).per_entry)
}

fn grid_layout(ny: usize, nu: usize, score: &[f64]) -> GridLayout {
    let n = ny * nu;
    if n > MAX_GRID_PANELS {
        let idx = grid_subset(ny, nu, score);
        let cols = 8;
        let rows = idx.len().div_ceil(cols);
        let mut cells: Vec<Option<(usize, usize)>> =
            idx.iter().map(|e| Some((e % ny, e / ny))).collect();
        cells.resize(rows * cols, None);
        return GridLayout {
            rows,
            cols,
            cells,
            note: format!(
                "the {} of {n} entries with the largest residual energy of the final model \
                 (a {ny} x {nu} plant has too many entries to show all), in output-then-input \
                 order",
                idx.len()
            ),
        };
    }
    let transpose = nu > 8 && ny < nu;
    let (r_dim, c_dim) = if transpose { (nu, ny) } else { (ny, nu) };
    let fold = if r_dim > 14 {
        (8 / c_dim.max(1)).max(1)
    } else {
        1
    };
    let rows = r_dim.div_ceil(fold).max(1);
    let cols = (c_dim * fold).max(1);
    let mut cells = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let (g, cc) = (c / c_dim.max(1), c % c_dim.max(1));
            let rr = g * rows + r;
            cells.push((rr < r_dim).then_some(if transpose { (cc, rr) } else { (rr, cc) }));
        }
    }
    let (rname, cname) = if transpose {
        ("inputs", "outputs")
    } else {
        ("outputs", "inputs")
    };
    let note = if n == 1 {
        "the only entry".to_string()
    } else if fold > 1 {
        format!(
            "all {n} entries; rows are {rname}, columns {cname}, the {rname} folded into {fold} \
             blocks side by side"
        )
    } else {
        format!("all {n} entries; rows are {rname}, columns {cname}")
    };
    GridLayout {
        rows,
        cols,
        cells,
        note,
    }
}

/// Draws the entry with the largest residual of the final model; returns the caption.
fn entry_svg(path: &Path, input: &ReportInput, fin: &Residual) -> Result<String, FrfitError> {
    let data = input.data;
    let (ny, nu) = (data.ny(), data.nu());
    let (i, j, score) = fin.worst_entry(ny);
    let (n, m) = (data.n_lines(), ny * nu);
    let e = j * ny + i;
    let freqs = data.freq_hz_slice().to_vec();
    let g: Vec<_> = (0..n).map(|k| data.values()[k * m + e]).collect();
    let p: Vec<_> = (0..n)
        .map(|k| input.final_model.values[k * m + e])
        .collect();
    let name = format!("G{}_{}", i + 1, j + 1);
    let mut plot = LinePlot::new(format!(
        "{name} (output {}, input {}): data, final model, residual",
        i + 1,
        j + 1
    ));
    if let Some(u) = &data.units {
        plot.y.label = format!("Magnitude [{u}]");
    }
    plot.series.push(
        Series::line(
            "final model",
            freqs.clone(),
            p.iter().map(|z| z.norm()).collect(),
        )
        .with_color(MODEL_COLOR)
        .with_width(3),
    );
    plot.series.push(
        Series::line("data", freqs.clone(), g.iter().map(|z| z.norm()).collect())
            .with_color(DATA_COLOR),
    );
    plot.series.push(
        Series::points(
            "|G - P|",
            freqs.clone(),
            g.iter().zip(&p).map(|(a, b)| (a - b).norm()).collect(),
        )
        .with_color(RESIDUAL_COLOR)
        .with_width(2),
    );
    if let Some(v) = input.noise_var {
        let s = (0..n)
            .map(|k| v.get(k * m + e).copied().unwrap_or(f64::NAN).sqrt())
            .collect();
        plot.series
            .push(Series::line("noise std sqrt(var)", freqs.clone(), s).with_color(NOISE_COLOR));
    }
    if let Some(std) = input.final_model_std {
        let (hi, lo) = two_sigma_band(input.final_model, std, e, m);
        for (name, v) in [("model +- 2 sigma", hi), ("", lo)] {
            plot.series.push(
                Series::dashed(name, freqs.clone(), v)
                    .with_color(MODEL_COLOR)
                    .with_width(1),
            );
        }
        // the model's own uncertainty next to the noise and the residual
        let s2 = (0..n).map(|k| 2.0 * std[k * m + e]).collect();
        plot.series.push(
            Series::dashed("model 2 sigma (its uncertainty)", freqs.clone(), s2)
                .with_color(NOISE_COLOR),
        );
    }
    if let (Some(&lo), Some(&hi)) = (
        freqs.iter().find(|f| **f > 0.0),
        freqs.iter().rev().find(|f| **f > 0.0),
    ) {
        if hi > lo {
            plot.x.range = Some((lo, hi));
        }
    }
    headroom(&mut plot);
    plot.write_svg(path, (1000, 560))?;
    let why = if !score.is_finite() {
        "the first entry (no residual could be computed)".to_string()
    } else if input.noise_var.is_some() {
        format!(
            "the entry with the largest residual-to-noise energy of the final model (rms ratio \
             {})",
            fmt_num(score.sqrt())
        )
    } else {
        format!(
            "the entry with the largest relative residual energy of the final model \
             (sum |G - P|^2 / sum |G|^2 = {})",
            fmt_num(score)
        )
    };
    let noise = if input.noise_var.is_some() {
        ", and the noise level sqrt(var) (grey): the residual is significant where the dots \
         stand above the grey line"
    } else {
        ""
    };
    let band = if input.final_model_std.is_some() {
        "; the dashed orange lines are the model's +- 2 sigma band and the dashed grey line \
         its 2 sigma level, from the covariance of its parameters (what the data's noise \
         leaves uncertain in the model, not an error it misses)"
    } else {
        ""
    };
    Ok(format!(
        "Entry {name} (output {}, input {}), {why}: data (blue line), final model (orange \
         band), \
         residual |G - P| (red dots){noise}{band}.",
        i + 1,
        j + 1
    ))
}

/// A step's standard deviations as the JSON object [`fmt_params`] reads.
fn uncertainty_json(step: &StepSummary) -> Option<Value> {
    step.uncertainty
        .as_ref()
        .and_then(|u| serde_json::to_value(u).ok())
}

fn step_title(i: usize, step: &StepSummary) -> String {
    let mut t = format!(
        "Step {}: {} ({})",
        i + 1,
        step.effect(),
        if step.accepted {
            "accepted"
        } else {
            "rejected"
        }
    );
    let params = fmt_params(&step.fitted.params_json(), None);
    if !params.is_empty() {
        t.push_str(": ");
        t.push_str(&params);
    }
    if t.chars().count() > 110 {
        t = t.chars().take(107).collect::<String>() + "...";
    }
    t
}

/// Marks every frequency parameter (`*_hz`; `fs_hz` as its Nyquist frequency) inside the
/// band with a dashed vertical line and a label on the `before` curve; true when it
/// marked one.
fn mark_frequencies(
    plot: &mut LinePlot,
    params: &Value,
    freqs: &[f64],
    before: &[f64],
    after: &[f64],
) -> bool {
    let (Some(&lo), Some(&hi)) = (freqs.first(), freqs.last()) else {
        return false;
    };
    let mut marked = false;
    let mut marks = Vec::new();
    collect_hz(params, "", &mut marks);
    let (mut ymin, mut ymax) = (f64::INFINITY, 0.0f64);
    for &v in before.iter().chain(after) {
        if v.is_finite() && v > 0.0 {
            ymin = ymin.min(v);
            ymax = ymax.max(v);
        }
    }
    if !(ymin.is_finite() && ymax > 0.0) {
        return false;
    }
    for mark in marks {
        let (f, label) = match mark {
            HzMark::SampleRate(fs) => (fs / 2.0, format!("fs/2 = {} Hz", fmt_num(fs / 2.0))),
            HzMark::Frequency(f) => (f, format!("{} Hz", fmt_num(f))),
        };
        if !(f.is_finite() && f >= lo && f <= hi && f > 0.0) {
            continue;
        }
        plot.series
            .push(Series::dashed("", vec![f, f], vec![ymin, ymax]).with_color(MARK_COLOR));
        // The label sits on the `before` curve at the nearest line.
        let k = freqs.partition_point(|x| *x < f).min(freqs.len() - 1);
        let y = before
            .get(k)
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
            .unwrap_or(ymax);
        plot.markers.push(Marker {
            x: f,
            y,
            label: Some(label),
            color: Some(MARK_COLOR),
        });
        marked = true;
    }
    marked
}

/// A frequency parameter of a step, as marked in its figure.
#[derive(Debug, Clone, Copy, PartialEq)]
enum HzMark {
    /// A frequency (`*_hz`), marked where it is.
    Frequency(f64),
    /// A sample rate (`*fs_hz`), marked at its Nyquist frequency.
    SampleRate(f64),
}

/// The frequency parameters (`*_hz` keys, at any depth) of a step's `params`.
fn collect_hz(v: &Value, key: &str, out: &mut Vec<HzMark>) {
    match v {
        Value::Object(map) => {
            for (k, x) in map {
                collect_hz(x, k, out);
            }
        }
        Value::Array(xs) => {
            for x in xs {
                collect_hz(x, key, out);
            }
        }
        Value::Number(x) if key.ends_with("_hz") => {
            if let Some(f) = x.as_f64() {
                out.push(if key.ends_with("fs_hz") {
                    HzMark::SampleRate(f)
                } else {
                    HzMark::Frequency(f)
                });
            }
        }
        _ => {}
    }
}

/// A number for humans: 4 significant digits between 0.001 and 1e5 (trailing zeros
/// dropped: `0.02`, `142.9`, `0.004633`), else scientific with 3 (`4.63e-4`, `1.2e6`).
pub fn fmt_num(v: f64) -> String {
    if v.is_nan() {
        return "n/a".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf" } else { "-inf" }.into();
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        trim_zeros(format!("{v:.digits$}"))
    } else {
        let s = format!("{v:.2e}");
        match s.split_once('e') {
            Some((mantissa, exp)) => format!("{}e{exp}", trim_zeros(mantissa.to_string())),
            None => s,
        }
    }
}

/// `1.500` -> `1.5`, `3.000` -> `3`; integers unchanged.
fn trim_zeros(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A duration in seconds for humans (`60.00 us`, `12.30 ms`, `1.234 s`).
fn fmt_seconds(s: f64) -> String {
    let a = s.abs();
    if !s.is_finite() || a >= 1.0 || s == 0.0 {
        format!("{} s", fmt_num(s))
    } else if a >= 1e-3 {
        format!("{} ms", fmt_num(s * 1e3))
    } else if a >= 1e-6 {
        format!("{} us", fmt_num(s * 1e6))
    } else {
        format!("{} s", fmt_num(s))
    }
}

/// `key = value ± sd, ...` of a parameter object (any JSON shape).
fn fmt_params(params: &Value, unc: Option<&Value>) -> String {
    match params {
        Value::Object(map) => map
            .iter()
            .map(|(k, v)| format!("{k} = {}", fmt_value(v, unc.and_then(|u| u.get(k)), k)))
            .collect::<Vec<_>>()
            .join(", "),
        Value::Null => String::new(),
        other => fmt_value(other, unc, ""),
    }
}

fn fmt_value(v: &Value, unc: Option<&Value>, key: &str) -> String {
    let seconds = key == "seconds" || key.ends_with("_s");
    match v {
        Value::Number(x) => {
            let s = match (x.as_i64(), x.as_f64()) {
                (Some(i), _) if !seconds => i.to_string(),
                (_, Some(f)) if seconds => fmt_seconds(f),
                (_, Some(f)) => fmt_num(f),
                _ => x.to_string(),
            };
            match unc.and_then(Value::as_f64) {
                Some(u) if seconds => format!("{s} ± {}", fmt_seconds(u)),
                Some(u) => format!("{s} ± {}", fmt_num(u)),
                None => s,
            }
        }
        Value::Array(xs) => {
            let items: Vec<String> = xs
                .iter()
                .enumerate()
                .map(|(i, x)| fmt_value(x, unc.and_then(|u| u.get(i)), key))
                .collect();
            format!("[{}]", items.join(", "))
        }
        Value::Object(_) => format!("{{{}}}", fmt_params(v, unc)),
        Value::String(s) => s.clone(),
        Value::Bool(b) => if *b { "yes" } else { "no" }.into(),
        Value::Null => "none".into(),
    }
}

/// Text for a markdown table cell: no pipes, no line breaks.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// The line-to-line floor against the measured variance, and the final residual
/// against both: the evidence for (or against) nonlinear distortion.
fn distortion_section(md: &mut String, d: &DistortionSummary) {
    let _ = writeln!(md, "## Line-to-line floor (nonlinear distortion)\n");
    let _ = writeln!(md, "| level | relative to the measured variance |");
    let _ = writeln!(md, "|---|---:|");
    let _ = writeln!(
        md,
        "| measured variance (median sqrt(var) / \\|G\\| {}) | 1 |",
        fmt_num(d.variance_median_rel)
    );
    let _ = writeln!(
        md,
        "| line-to-line floor, order-{} differences (median relative level {}) | {} (lower bound {}) |",
        d.order,
        fmt_num(d.floor_median_rel),
        fmt_num(d.floor_to_variance),
        fmt_num(d.floor_to_variance_lower)
    );
    let _ = writeln!(
        md,
        "| final residual | {} ({} of the floor) |\n",
        fmt_num(d.residual_to_variance),
        fmt_num(d.residual_to_floor)
    );
    let _ = writeln!(
        md,
        "Ratios of variances: medians over lines and entries of the per-line ratio, over \
         ln 2 (1 when the measured variance explains the scatter). The floor is \
         model-free: differences across adjacent lines cancel the smooth response and keep \
         the jitter, which is independent from line to line for noise and for the \
         stochastic nonlinear distortions of a random-phase multisine alike. {}\n",
        if d.exceeds {
            format!(
                "It exceeds the measured variance (threshold {}): the variance misses part \
                 of the scatter, as one estimated over the periods of one realization \
                 misses the distortion. The diagnosis judged residuals against the \
                 local floor{}.",
                fmt_num(d.min_ratio),
                if d.loop_against_floor {
                    ""
                } else {
                    " (not here)"
                }
            )
        } else {
            format!(
                "It does not exceed the measured variance significantly (threshold {}): \
                 no sign of distortion that the variance misses.",
                fmt_num(d.min_ratio)
            )
        }
    );
}

fn errors_row(name: &str, e: &ErrorStats) -> String {
    format!(
        "| {name} | {} | {} | {} |",
        fmt_num(e.median_rel),
        fmt_num(e.p95_rel),
        fmt_num(e.residual_to_noise)
    )
}

fn arrow(a: f64, b: f64) -> String {
    format!("{} → {}", fmt_num(a), fmt_num(b))
}

/// The text of `report.md`.
fn markdown(
    input: &ReportInput,
    s: &Summary,
    figs: &Figures,
    step_figs: &[(String, bool)],
    fin: &Residual,
) -> String {
    let mut md = String::new();
    let title = if input.title.trim().is_empty() {
        "frfit report"
    } else {
        input.title.trim()
    };
    let _ = writeln!(md, "# {title}\n");

    // The data.
    let d = &s.data;
    let units = d
        .units
        .as_deref()
        .map(|u| format!("units {u}"))
        .unwrap_or_else(|| "units not given".into());
    let _ = writeln!(
        md,
        "**Data:** `{}`: {} x {} ({} output{}, {} input{}), {} lines, {}–{} Hz, {units}, \
         fitted as {}; noise: {}.\n",
        d.path,
        d.ny,
        d.nu,
        d.ny,
        plural(d.ny),
        d.nu,
        plural(d.nu),
        d.lines,
        fmt_num(d.band_hz[0]),
        fmt_num(d.band_hz[1]),
        d.frf_type,
        d.noise_source
    );
    let declared = if s.initial.declared.is_empty() {
        "none".to_string()
    } else {
        s.initial.declared.join(", ")
    };
    let _ = writeln!(
        md,
        "**Command:** `frfit {}`. **Initial model:** {} mode{} from {} CMIF peak{}; declared \
         effects: {declared}.\n",
        s.command,
        s.initial.modes.len(),
        plural(s.initial.modes.len()),
        s.initial.cmif_peaks.len(),
        plural(s.initial.cmif_peaks.len()),
    );
    if let Some(r) = &s.initial.restart {
        let _ = writeln!(
            md,
            "**Better first fit.** A restart from {} ended significantly better than the \
             chain's first fit (F = {:.3e}, critical {:.3}) and replaced it: {} mode{} with \
             residual/noise {:.3} before. A restart is not an effect: it is not a step.\n",
            r.from,
            r.f_statistic,
            r.f_critical,
            r.replaced_modes,
            plural(r.replaced_modes),
            r.replaced_errors.residual_to_noise
        );
    }
    if let Some(f) = &s.initial.from_fit {
        let _ = writeln!(
            md,
            "**Started from `fit`'s model.** The diagnosis from its own first fit ({} mode{}, \
             residual/noise {:.3}, median relative error {:.4}) ended at {} mode{}, residual/noise \
             {:.3}, median relative error {:.4} (accepted: {}), worse on the data than the model \
             `frfit fit` gives (residual/noise {:.3}, median relative error {:.4}). The diagnosis \
             below ran again from that model{}.\n",
            f.replaced_initial_modes,
            plural(f.replaced_initial_modes),
            f.replaced_initial_errors.residual_to_noise,
            f.replaced_initial_errors.median_rel,
            f.replaced_final_modes,
            plural(f.replaced_final_modes),
            f.replaced_final_errors.residual_to_noise,
            f.replaced_final_errors.median_rel,
            if f.replaced_accepted.is_empty() {
                "none".to_string()
            } else {
                f.replaced_accepted.join(", ")
            },
            f.fit_errors.residual_to_noise,
            f.fit_errors.median_rel,
            if f.feedthrough_taken_out {
                " with its feedthrough taken out and the rest refitted (the diagnosis's own \
                 first fit held none: a feedthrough is a step of the loop, not a part of the \
                 start); the initial model above is that model"
            } else {
                "; the initial model above is `fit`'s"
            },
        );
    }
    if !s.initial.repairs.is_empty() {
        let list: Vec<String> = s
            .initial
            .repairs
            .iter()
            .map(|r| {
                let cost = r.cost.map_or(String::new(), |c| {
                    format!(
                        ", weighted cost {} -> {}",
                        fmt_num(c.before),
                        fmt_num(c.after)
                    )
                });
                match &r.repair {
                    Repair::OutOfBandMode {
                        f_hz, zeta, edge, ..
                    } => format!(
                        "`out_of_band_mode` at {f_hz:.2} Hz (zeta {zeta:.4}, beyond the {edge} edge; F = {:.1}{cost})",
                        r.f_statistic
                    ),
                    Repair::ClosePair { from_hz, modes } => format!(
                        "`close_pair`: the mode at {from_hz:.2} Hz split in two, {:.2} and {:.2} Hz (F = {:.1}{cost})",
                        modes[0].f_hz, modes[1].f_hz, r.f_statistic
                    ),
                }
            })
            .collect();
        let _ = writeln!(
            md,
            "**First-fit repairs** (modes of the plant, not effects): {}.\n",
            list.join("; ")
        );
    }

    structure_steps_table(&mut md, &s.initial.structure_steps);

    // The verdict.
    let _ = writeln!(
        md,
        "**Verdict: {}.** {}\n",
        s.verdict.text(),
        s.verdict_evidence.trim()
    );

    // Errors.
    let _ = writeln!(md, "## Error against the data\n");
    let _ = writeln!(
        md,
        "| model | median rel. error | 95th pct. rel. error | residual / noise |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|");
    let _ = writeln!(md, "{}", errors_row("initial", &s.initial.errors));
    let _ = writeln!(md, "{}", errors_row("final", &s.final_errors));
    match s.data_noise_median_rel {
        Some(n) => {
            let _ = writeln!(
                md,
                "| data noise level, median sqrt(var) / \\|G\\| | {} | | 1 |\n",
                fmt_num(n)
            );
            if n > 0.0 && s.final_errors.median_rel.is_finite() {
                let _ = writeln!(
                    md,
                    "The final median relative error is {}x the data's own noise level.\n",
                    fmt_num(s.final_errors.median_rel / n)
                );
            }
        }
        None => {
            let _ = writeln!(
                md,
                "\nThe data carry no variance: their noise level is not known.\n"
            );
        }
    }
    let _ = writeln!(
        md,
        "Relative error: |G - P| / |G| over all lines and entries. Residual / noise: \
         sqrt(mean |G - P|^2 / var), 1 at the noise level.\n"
    );
    if let Some(d) = &s.distortion {
        distortion_section(&mut md, d);
    }

    // Figures.
    if s.command == "diagnose" {
        let _ = writeln!(
            md,
            "The initial model, the one the diagnosis started from, is `{}` beside this \
             report (the final one is the model file), for `frfit eval` or `frfit validate`.\n",
            START_MODEL_FILE
        );
    }
    let _ = writeln!(md, "## Figures\n");
    for (n, (file, alt, caption)) in figs.0.iter().enumerate() {
        let _ = writeln!(md, "![{alt}]({file})\n");
        let _ = writeln!(md, "*Fig. {}. {caption}*\n", n + 1);
    }

    // Diagnosis.
    let _ = writeln!(md, "## Diagnosis steps\n");
    if s.steps.is_empty() {
        let _ = writeln!(
            md,
            "No diagnosis step was taken: nothing to add to the model.\n"
        );
    } else {
        let accepted = s.steps.iter().filter(|t| t.accepted).count();
        let removed = s
            .steps
            .iter()
            .filter(|t| t.accepted && t.superseded_by.is_some())
            .count();
        let removed = if removed > 0 {
            format!(" ({removed} of them taken out again by a later step)")
        } else {
            String::new()
        };
        let _ = writeln!(
            md,
            "{} candidate effect{} tested, {accepted} added to the model{removed}. An effect \
             is added when its F statistic (the cost it explains per added parameter over \
             the noise scale) passes the critical value.\n",
            s.steps.len(),
            plural(s.steps.len())
        );
        let _ = writeln!(
            md,
            "| # | effect | added | evidence | parameters | F (critical) | median rel. error | \
             95th pct. rel. error | residual / noise |"
        );
        let _ = writeln!(md, "|---:|---|---|---|---|---:|---:|---:|---:|");
        for (i, t) in s.steps.iter().enumerate() {
            let params = fmt_params(&t.fitted.params_json(), uncertainty_json(t).as_ref());
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} ({}, {} param{}) | {} | {} | {} |",
                i + 1,
                cell(t.effect()),
                added_cell(t),
                cell(t.evidence.trim()),
                cell(if params.is_empty() { "none" } else { &params }),
                fmt_num(t.f_statistic),
                fmt_num(t.f_critical),
                t.added_params,
                plural(t.added_params),
                arrow(t.before.median_rel, t.after.median_rel),
                arrow(t.before.p95_rel, t.after.p95_rel),
                arrow(t.before.residual_to_noise, t.after.residual_to_noise),
            );
        }
        let _ = writeln!(md);
        let fig0 = figs.0.len();
        for (i, (t, (file, marked))) in s.steps.iter().zip(step_figs).enumerate() {
            let _ = writeln!(
                md,
                "### Step {}: {} ({})\n",
                i + 1,
                t.effect(),
                match (t.accepted, t.superseded_by) {
                    (true, Some(n)) => format!("accepted, removed at step {n}"),
                    (true, None) => "accepted".into(),
                    (false, _) => "rejected".into(),
                }
            );
            let _ = writeln!(md, "{}\n", t.evidence.trim());
            let params = fmt_params(&t.fitted.params_json(), uncertainty_json(t).as_ref());
            if !params.is_empty() {
                let _ = writeln!(md, "Parameters: {params}.\n");
            }
            let _ = writeln!(
                md,
                "F = {} against {} for {} added parameter{}; median relative error {}, 95th \
                 percentile {}, residual / noise {}.\n",
                fmt_num(t.f_statistic),
                fmt_num(t.f_critical),
                t.added_params,
                plural(t.added_params),
                arrow(t.before.median_rel, t.after.median_rel),
                arrow(t.before.p95_rel, t.after.p95_rel),
                arrow(t.before.residual_to_noise, t.after.residual_to_noise),
            );
            let what = if input.noise_var.is_some() {
                "residual-to-noise ratio per line"
            } else {
                "residual |G - P| per line (rms over entries; no variance known)"
            };
            let _ = writeln!(md, "![step {}: {}]({file})\n", i + 1, t.effect());
            let _ = writeln!(
                md,
                "*Fig. {}. Step {}: {what} before (orange) and after (blue) the refit with {}{}.*\n",
                fig0 + i + 1,
                i + 1,
                t.effect(),
                if *marked {
                    "; the dashed red line marks its frequency"
                } else {
                    ""
                }
            );
        }
    }

    // Final model.
    let f = &s.final_model;
    let _ = writeln!(md, "## Final model\n");
    if f.modes.is_empty() {
        let _ = writeln!(md, "No flexible modes.\n");
    } else {
        match &s.uncertainty {
            Some(u) => {
                let _ = writeln!(
                    md,
                    "| mode | f [Hz] | +- 2 sigma [Hz] | zeta | +- 2 sigma |"
                );
                let _ = writeln!(md, "|---:|---:|---:|---:|---:|");
                for (k, mo) in f.modes.iter().enumerate() {
                    let (sf, sz) = u
                        .mode_std(mo.f_hz)
                        .map(|(a, b)| (fmt_num(2.0 * a), fmt_num(2.0 * b)))
                        .unwrap_or_default();
                    let _ = writeln!(
                        md,
                        "| {} | {} | {} | {} | {} |",
                        k + 1,
                        fmt_num(mo.f_hz),
                        sf,
                        fmt_num(mo.zeta),
                        sz
                    );
                }
                let test = match u.p_value {
                    Some(p) => format!(
                        "cost ratio V/N_dof {} against the expected {}, p = {p:.2e}",
                        fmt_num(u.cost_ratio),
                        fmt_num(u.expected_ratio)
                    ),
                    None => format!(
                        "noise scale V/N_dof {} of the weighted residual; without a measured variance there is no goodness-of-fit test",
                        fmt_num(u.cost_ratio)
                    ),
                };
                let factor_lines = u.factor_lines();
                if !factor_lines.is_empty() {
                    let _ = writeln!(md, "\nDynamics factors (+- 2 sigma):\n");
                    for line in &factor_lines {
                        let _ = writeln!(md, "- {line}");
                    }
                }
                let _ = writeln!(
                    md,
                    "\nStandard deviations from {} ({}; {test}; covariance scaled by {}).",
                    u.source(),
                    u.noise,
                    fmt_num(u.covariance_scale)
                );
            }
            None => {
                let _ = writeln!(md, "| mode | f [Hz] | zeta |");
                let _ = writeln!(md, "|---:|---:|---:|");
                for (k, mo) in f.modes.iter().enumerate() {
                    let _ = writeln!(
                        md,
                        "| {} | {} | {} |",
                        k + 1,
                        fmt_num(mo.f_hz),
                        fmt_num(mo.zeta)
                    );
                }
            }
        }
        let _ = writeln!(md);
    }
    let rigid = match f.rigid_body_integrators {
        0 => "none".to_string(),
        1 => "1 integrator (1/s)".to_string(),
        2 => "2 integrators (free mass, 1/s^2)".to_string(),
        k => format!("{k} integrators"),
    };
    let dynamics = if f.dynamics.is_empty() {
        "none".to_string()
    } else {
        f.dynamics.join("; ")
    };
    let _ = writeln!(md, "| part | value |");
    let _ = writeln!(md, "|---|---|");
    let _ = writeln!(md, "| flexible modes | {} |", f.modes.len());
    let _ = writeln!(md, "| order (real states) | {} |", f.order);
    let _ = writeln!(md, "| delay | {} |", fmt_seconds(f.delay_s));
    let _ = writeln!(md, "| hold | {} |", cell(&f.hold));
    let _ = writeln!(md, "| rigid body | {rigid} |");
    let _ = writeln!(
        md,
        "| feedthrough | {} |",
        if f.feedthrough { "yes" } else { "no" }
    );
    let _ = writeln!(md, "| dynamics factors | {} |", cell(&dynamics));
    let _ = writeln!(md, "| iterations | {} |", f.iterations);
    let _ = writeln!(md, "| convergence | {} |", cell(&f.convergence));
    let _ = writeln!(
        md,
        "| final error | median {}, 95th pct. {}, residual / noise {} |\n",
        fmt_num(s.final_errors.median_rel),
        fmt_num(s.final_errors.p95_rel),
        fmt_num(s.final_errors.residual_to_noise)
    );
    let (wi, wj, _) = fin.worst_entry(input.data.ny());
    let _ = writeln!(
        md,
        "Worst entry of the final model: G{}_{} (Fig. 3).\n",
        wi + 1,
        wj + 1
    );

    // Timings.
    let _ = writeln!(md, "## Timings\n");
    if s.timings.is_empty() {
        let _ = writeln!(md, "No stage times were recorded.\n");
    } else {
        let _ = writeln!(md, "| stage | time |");
        let _ = writeln!(md, "|---|---:|");
        // the run's own `total` stage (from the start of the setup to the summary) is
        // the total; summing it with the stages it holds would count them twice
        let run_total = s.timings.iter().find(|t| t.stage == "total");
        let mut total = 0.0;
        for t in s.timings.iter().filter(|t| t.stage != "total") {
            if t.seconds.is_finite() {
                total += t.seconds;
            }
            let _ = writeln!(md, "| {} | {} |", cell(&t.stage), fmt_seconds(t.seconds));
        }
        let total = run_total.map_or(total, |t| t.seconds);
        let _ = writeln!(md, "| **total** | **{}** |\n", fmt_seconds(total));
    }
    let _ = writeln!(
        md,
        "The same content, machine-readable: [summary.json](summary.json) (schema \
         `{}` version {}).",
        s.schema, s.version
    );
    md
}
