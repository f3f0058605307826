//! `report::write_report`: every file written, the markdown links every figure, one table
//! row per step, `summary.json` round-trips, the SVGs are well-formed, the empty cases
//! (no steps, no variance) and mismatched inputs.
//!
//! `cargo test -p frfit --test report -- --ignored wafer_report` renders the report of the
//! wafer-stage truth against `shared/data/wafer_nominal.csv` into `FRFIT_REPORT_DIR` (or
//! a temporary directory) and prints the time it took.

use faer::Mat;
use frf_data::cmif::{cmif, pick_peaks, PeakConfig};
use frf_data::structure::{StructureChange, StructureStep};
use frf_data::{Frf, FrfDataset, C64};
use frfit::effects::{FactorParams, FactorSupport, FittedEffect, PoleParams};
use frfit::report::{write_report, ReportInput};
use frfit::summary::{
    DataSummary, ErrorStats, FinalModelSummary, InitialSummary, ModeSummary, PeakSummary,
    StageTime, StepSummary, StructureStepSummary, Summary, SCHEMA, VERSION,
};
use realize::{ModalModel, PolePair, ResponseGrid};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh directory under the system temp dir.
fn temp_dir(tag: &str) -> PathBuf {
    static COUNT: AtomicUsize = AtomicUsize::new(0);
    let n = COUNT.fetch_add(1, Ordering::Relaxed);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let dir = std::env::temp_dir().join(format!(
        "frfit-report-{tag}-{}-{nanos}-{n}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Removes a test directory, unless `FRFIT_KEEP_REPORTS` is set (to look at them).
fn cleanup(dir: &Path) {
    if std::env::var_os("FRFIT_KEEP_REPORTS").is_some() {
        println!("kept {}", dir.display());
    } else {
        std::fs::remove_dir_all(dir).ok();
    }
}

/// A `ny x nu` plant with a free-mass rigid body and the given modes.
fn plant(ny: usize, nu: usize, modes: &[(f64, f64)]) -> ModalModel {
    let mut m = ModalModel::new(ny, nu);
    m.rigid = vec![
        Mat::zeros(ny, nu),
        Mat::from_fn(ny, nu, |i, j| 0.02 * (1.0 + i as f64) / (1.0 + j as f64)),
    ];
    for (k, &(f, z)) in modes.iter().enumerate() {
        let num = Mat::from_fn(ny, nu, |i, j| {
            let s = if (i + j + k) % 2 == 0 { 1.0 } else { -0.6 };
            s * (1.0 + 0.3 * i as f64) * (1.0 + 0.2 * j as f64) * (1.0 + k as f64)
        });
        m.pairs.push(PolePair::from_second_order(f, z, &num));
    }
    m
}

/// Deterministic pseudo-random numbers in (-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

fn log_freqs(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}

fn omega(f: &[f64]) -> Vec<f64> {
    f.iter().map(|x| std::f64::consts::TAU * x).collect()
}

/// Data = plant + 1% noise (with its variance), plus the plant's response.
fn synthetic(ny: usize, nu: usize, n: usize) -> (Frf, ResponseGrid, Vec<f64>) {
    let modes = [(35.0, 0.01), (120.0, 0.02), (310.0, 0.005)];
    let truth = plant(ny, nu, &modes);
    let f = log_freqs(2.0, 600.0, n);
    let g = truth.freq_response(&omega(&f)).unwrap();
    let mut rng = Lcg(7);
    let mut values = g.values.clone();
    let mut var = Vec::with_capacity(values.len());
    for v in &mut values {
        let s = 0.01 * v.norm();
        *v += C64::new(s * rng.next(), s * rng.next());
        var.push(s * s * 2.0 / 3.0);
    }
    let mut data = Frf::new(f, ny, nu, values, Some(var.clone())).unwrap();
    data.units = Some("m/N".into());
    data.source = Some("synthetic.csv".into());
    (data, g, var)
}

fn errors(m: f64, p: f64, r: f64) -> ErrorStats {
    ErrorStats {
        median_rel: m,
        p95_rel: p,
        residual_to_noise: r,
    }
}

fn summary(data: &Frf, steps: Vec<StepSummary>, noise: Option<f64>) -> Summary {
    let f = data.freq_hz_slice();
    Summary {
        schema: SCHEMA.into(),
        version: VERSION,
        command: "diagnose".into(),
        data: DataSummary {
            path: "synthetic.csv".into(),
            ny: data.ny(),
            nu: data.nu(),
            lines: data.n_lines(),
            band_hz: [f[0], f[f.len() - 1]],
            units: data.units.clone(),
            noise_source: if noise.is_some() {
                "measured".into()
            } else {
                "none".into()
            },
            frf_type: "displacement".into(),
        },
        initial: InitialSummary {
            modes: vec![
                ModeSummary {
                    f_hz: 35.0,
                    zeta: 0.01,
                },
                ModeSummary {
                    f_hz: 310.0,
                    zeta: 0.005,
                },
            ],
            cmif_peaks: vec![PeakSummary {
                f_hz: 35.0,
                sv_index: 0,
                prominence: 30.0,
            }],
            errors: errors(0.12, 3.4, 25.0),
            declared: vec![],
            restart: None,
            repairs: vec![],
            structure_steps: vec![
                StructureStepSummary {
                    link: "riv".into(),
                    step: StructureStep {
                        change: StructureChange::PolesDropped {
                            poles: vec!["mode at 410.00 Hz: insignificant (F = 1.2 < 9.1)".into()],
                            reason: "the structure adaptation's checks".into(),
                        },
                        accepted: true,
                        cost_before: 2.49e6,
                        cost_after: Some(2.5e6),
                        f_statistic: None,
                        f_critical: None,
                        held_out: None,
                    },
                },
                StructureStepSummary {
                    link: "ml".into(),
                    step: StructureStep {
                        change: StructureChange::ModesAdded {
                            start_hz: vec![121.0],
                        },
                        accepted: true,
                        cost_before: 2.5e6,
                        cost_after: Some(4.1e3),
                        f_statistic: Some(9.7e4),
                        f_critical: Some(25.0),
                        held_out: Some(frf_data::structure::HeldOutCost {
                            before: 2.6e6,
                            after: 4.3e3,
                            f_statistic: Some(8.8e4),
                        }),
                    },
                },
            ],
            from_fit: None,
        },
        steps,
        verdict: frfit::summary::ResidualVerdict::NoiseLimited,
        verdict_evidence: "residual / noise 1.02 after the missed mode at 120.0 Hz".into(),
        final_model: FinalModelSummary {
            modes: vec![
                ModeSummary {
                    f_hz: 35.0,
                    zeta: 0.01,
                },
                ModeSummary {
                    f_hz: 120.0,
                    zeta: 0.02,
                },
                ModeSummary {
                    f_hz: 310.0,
                    zeta: 0.005,
                },
            ],
            order: 10,
            delay_s: 0.0,
            hold: "none".into(),
            rigid_body_integrators: 2,
            feedthrough: false,
            dynamics: vec![],
            iterations: 7,
            convergence: "relative cost change below 1e-9".into(),
        },
        final_errors: errors(0.008, 0.021, 1.02),
        data_noise_median_rel: noise,
        timings: vec![
            StageTime {
                stage: "init".into(),
                seconds: 0.012,
            },
            StageTime {
                stage: "refine".into(),
                seconds: 0.34,
            },
        ],
        chain: vec!["cmif".into(), "riv".into()],
        chain_runs: Vec::new(),
        uncertainty: None,
        distortion: None,
    }
}

fn two_steps() -> Vec<StepSummary> {
    vec![
        StepSummary {
            fitted: FittedEffect::MissedMode {
                f_hz: 120.01,
                zeta: 0.0199,
            },
            accepted: true,
            evidence: "residual CMIF peak at 120.3 Hz, 14 dB above | the noise".into(),
            uncertainty: Some([("f_hz".to_string(), 0.02), ("zeta".to_string(), 0.0004)].into()),
            f_statistic: 812.0,
            f_critical: 3.0,
            added_params: 14,
            before: errors(0.12, 3.4, 25.0),
            after: errors(0.008, 0.021, 1.02),
            figure: None,
            superseded_by: None,
            held_out: None,
        },
        StepSummary {
            fitted: FittedEffect::Delay {
                seconds: 3e-7,
                total_delay_s: 3e-7,
                refit: None,
            },
            accepted: false,
            evidence: "phase trend of 0.3 us across the band".into(),
            uncertainty: None,
            f_statistic: 0.4,
            f_critical: 3.9,
            added_params: 1,
            before: errors(0.008, 0.021, 1.02),
            after: errors(0.008, 0.021, 1.019),
            figure: Some("delay_step.svg".into()),
            superseded_by: None,
            held_out: None,
        },
    ]
}

/// The `(target)` of every `](target)` in the markdown.
fn links(md: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = md;
    while let Some(p) = rest.find("](") {
        let tail = &rest[p + 2..];
        if let Some(end) = tail.find(')') {
            out.push(tail[..end].to_string());
        }
        rest = tail;
    }
    out
}

/// The table rows (after header and separator) of the table whose header starts with
/// `header`.
fn table_rows(md: &str, header: &str) -> usize {
    let mut lines = md.lines().skip_while(|l| !l.starts_with(header));
    assert!(lines.next().is_some(), "no table `{header}`");
    lines.next(); // separator
    lines.take_while(|l| l.starts_with('|')).count()
}

fn check_files(dir: &Path, files: &[PathBuf]) -> String {
    for f in files {
        let meta = std::fs::metadata(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(meta.len() > 0, "{} is empty", f.display());
        assert!(f.starts_with(dir));
        if f.extension().is_some_and(|e| e == "svg") {
            let text = std::fs::read_to_string(f).unwrap();
            let head = text.trim_start();
            assert!(
                head.starts_with("<svg") || head.starts_with("<?xml"),
                "{} does not start like an SVG",
                f.display()
            );
            assert!(text.contains("</svg>"), "{} is not closed", f.display());
        }
    }
    let md_path = dir.join("report.md");
    assert!(files.contains(&md_path));
    let md = std::fs::read_to_string(&md_path).unwrap();
    let linked = links(&md);
    for l in &linked {
        if l.ends_with(".svg") || l.ends_with(".json") {
            assert!(
                dir.join(l).is_file(),
                "report.md links {l}, which is missing"
            );
        }
    }
    for f in files {
        let name = f.file_name().unwrap().to_string_lossy().to_string();
        if name.ends_with(".svg") {
            assert!(
                linked.contains(&name),
                "{name} is written but not shown in report.md"
            );
        }
    }
    assert!(!md.contains("TODO") && !md.contains("NaN"));
    md
}

#[test]
fn full_report_with_steps_and_variance() {
    let (data, truth_g, var) = synthetic(2, 3, 400);
    // The initial model lacks the 120 Hz mode.
    let initial_model = plant(2, 3, &[(35.0, 0.01), (310.0, 0.005)]);
    let initial = initial_model
        .freq_response(&omega(data.freq_hz_slice()))
        .unwrap();
    let mut delayed = truth_g.clone();
    for (k, &f) in data.freq_hz_slice().iter().enumerate() {
        let ph = C64::from_polar(1.0, -std::f64::consts::TAU * f * 3e-7);
        for v in delayed.line_mut(k) {
            *v *= ph;
        }
    }
    let steps = vec![
        (initial.clone(), truth_g.clone()),
        (truth_g.clone(), delayed),
    ];
    let c = cmif(&data).unwrap();
    let peaks = pick_peaks(&c, &PeakConfig::default());
    let s = summary(&data, two_steps(), Some(0.0082));
    let input = ReportInput {
        data: &data,
        noise_var: Some(&var),
        cmif: &c,
        peaks: &peaks,
        initial: &initial,
        final_model: &truth_g,
        final_model_std: None,
        steps: &steps,
        title: "Synthetic 2 x 3 plant",
    };
    let dir = temp_dir("full");
    let files = write_report(&dir, &input, &s).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "summary.json",
            "cmif.svg",
            "bode_grid.svg",
            "entry.svg",
            "residual_ratio.svg",
            "step_1_missed_mode.svg",
            "delay_step.svg",
            "report.md"
        ]
    );
    let md = check_files(&dir, &files);
    assert_eq!(table_rows(&md, "| # | effect"), 2);
    assert_eq!(table_rows(&md, "| mode | f [Hz]"), 3);
    // the first fit's structure steps, with their refiner, costs and test
    assert_eq!(table_rows(&md, "| # | link | change"), 2);
    assert!(
        md.contains(
            "| 2 | ml | `modes_added`: mode at 121.00 Hz | yes | 2.5e6 | 4100 | 97000 (25) | 2.6e6 -> 4300 (88000) |"
        ),
        "{md}"
    );
    assert!(
        md.contains("| 1 | riv | `poles_dropped`: mode at 410.00 Hz: insignificant (F = 1.2 < 9.1) (the structure adaptation's checks) | yes | 2.49e6 | 2.5e6 | - | - |"),
        "{md}"
    );
    assert!(md.contains("**Verdict: noise-limited.**"));
    assert!(
        md.contains("f_hz = 120 ± 0.02, zeta = 0.0199 ± 4e-4"),
        "{md}"
    );
    assert!(md.contains("seconds = 3e-7 s"));
    // A pipe in the evidence does not break the table.
    assert!(md.contains("above \\| the noise"));

    // summary.json is the summary, with the step figures filled in.
    let mut expected = s.clone();
    expected.steps[0].figure = Some("step_1_missed_mode.svg".into());
    let json = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    let back: Summary = serde_json::from_str(&json).unwrap();
    assert_eq!(back, expected);

    // The step figure marks the missed mode's frequency.
    let svg = std::fs::read_to_string(dir.join("step_1_missed_mode.svg")).unwrap();
    assert!(svg.contains("120 Hz"));
    cleanup(&dir);
}

/// Issue 44: with the final model's standard deviation the Bode grid and the entry plot
/// draw its +- 2 sigma band and say so; a standard deviation of the wrong length is an
/// error that names it.
#[test]
fn the_model_band_is_drawn_and_its_length_checked() {
    let (data, truth_g, var) = synthetic(2, 3, 400);
    let c = cmif(&data).unwrap();
    let peaks = pick_peaks(&c, &PeakConfig::default());
    let s = summary(&data, Vec::new(), None);
    let std: Vec<f64> = truth_g.values.iter().map(|v| 0.01 * v.norm()).collect();
    let input = ReportInput {
        data: &data,
        noise_var: Some(&var),
        cmif: &c,
        peaks: &peaks,
        initial: &truth_g,
        final_model: &truth_g,
        final_model_std: Some(&std),
        steps: &[],
        title: "band",
    };
    let dir = temp_dir("band");
    let files = write_report(&dir, &input, &s).unwrap();
    let md = check_files(&dir, &files);
    assert!(md.contains("+- 2 sigma band"), "{md}");
    for svg in ["entry.svg", "bode_grid.svg"] {
        let text = std::fs::read_to_string(dir.join(svg)).unwrap();
        assert!(text.contains("model +- 2 sigma"), "{svg}");
    }
    let short = &std[1..];
    let bad = ReportInput {
        final_model_std: Some(short),
        ..input
    };
    let e = write_report(&dir, &bad, &s).unwrap_err().to_string();
    assert!(e.contains("final model's standard deviation"), "{e}");
    cleanup(&dir);
}

#[test]
fn empty_diagnosis_without_variance() {
    let (data, truth_g, _) = synthetic(2, 3, 200);
    let data = data.with_variance(None).unwrap();
    let c = cmif(&data).unwrap();
    let s = summary(&data, vec![], None);
    let input = ReportInput {
        data: &data,
        noise_var: None,
        cmif: &c,
        peaks: &[],
        initial: &truth_g,
        final_model: &truth_g,
        final_model_std: None,
        steps: &[],
        title: "",
    };
    let dir = temp_dir("empty");
    let files = write_report(&dir, &input, &s).unwrap();
    assert_eq!(files.len(), 6);
    let md = check_files(&dir, &files);
    assert!(md.contains("nothing to add"));
    assert!(md.contains("no variance") || md.contains("carry no variance"));
    assert!(md.starts_with("# frfit report"));
    let json = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    let back: Summary = serde_json::from_str(&json).unwrap();
    assert_eq!(back, s);
    cleanup(&dir);
}

#[test]
fn large_plant_shows_a_documented_subset() {
    let (ny, nu) = (8, 9);
    let f = log_freqs(5.0, 500.0, 60);
    let truth = plant(ny, nu, &[(50.0, 0.02)]);
    let g = truth.freq_response(&omega(&f)).unwrap();
    let data = Frf::new(f, ny, nu, g.values.clone(), None).unwrap();
    let c = cmif(&data).unwrap();
    let s = summary(&data, vec![], None);
    let input = ReportInput {
        data: &data,
        noise_var: None,
        cmif: &c,
        peaks: &[],
        initial: &g,
        final_model: &g,
        final_model_std: None,
        steps: &[],
        title: "8 x 9",
    };
    let dir = temp_dir("large");
    let files = write_report(&dir, &input, &s).unwrap();
    let md = check_files(&dir, &files);
    assert!(md.contains("the 48 of 72 entries"), "{md}");
    let svg = std::fs::read_to_string(dir.join("bode_grid.svg")).unwrap();
    let panel_titles = svg
        .lines()
        .map(str::trim)
        .filter(|l| {
            l.strip_prefix('G')
                .and_then(|r| r.split_once('_'))
                .is_some_and(|(a, b)| a.parse::<usize>().is_ok() && b.parse::<usize>().is_ok())
        })
        .count();
    assert_eq!(panel_titles, 48);
    cleanup(&dir);
}

#[test]
fn mismatched_inputs_are_errors() {
    let (data, truth_g, var) = synthetic(2, 3, 50);
    let c = cmif(&data).unwrap();
    let s = summary(&data, two_steps(), Some(0.01));
    let dir = temp_dir("mismatch");
    // Two steps in the summary, none in the input.
    let input = ReportInput {
        data: &data,
        noise_var: Some(&var),
        cmif: &c,
        peaks: &[],
        initial: &truth_g,
        final_model: &truth_g,
        final_model_std: None,
        steps: &[],
        title: "x",
    };
    let e = write_report(&dir, &input, &s).unwrap_err();
    assert!(e.to_string().contains("step responses"), "{e}");
    // A model response with the wrong number of lines.
    let short = ResponseGrid::zeros(10, 2, 3);
    let s0 = summary(&data, vec![], None);
    let input = ReportInput {
        final_model: &short,
        final_model_std: None,
        steps: &[],
        ..input
    };
    let e = write_report(&dir, &input, &s0).unwrap_err();
    assert!(e.to_string().contains("final model"), "{e}");
    // A variance of the wrong length.
    let input = ReportInput {
        final_model: &truth_g,
        final_model_std: None,
        noise_var: Some(&var[..7]),
        ..input
    };
    assert!(write_report(&dir, &input, &s0).is_err());
    cleanup(&dir);
}

#[test]
fn degenerate_inputs_do_not_panic() {
    // One entry, three lines, a zero variance, a non-finite model value, no peaks.
    let f = vec![0.0, 10.0, 20.0];
    let g = vec![C64::new(1.0, 0.0), C64::new(0.5, -0.1), C64::new(0.0, 0.0)];
    let data = Frf::new(f, 1, 1, g, Some(vec![0.0, 1e-4, 1e-4])).unwrap();
    let c = cmif(&data).unwrap();
    let mut model = ResponseGrid::zeros(3, 1, 1);
    model.values[1] = C64::new(f64::NAN, 0.0);
    let var = data.variances().unwrap().to_vec();
    let mut step = two_steps().remove(0);
    step.figure = Some("../escape.svg".into());
    // a factor far outside the band, with nested parameters
    step.fitted = FittedEffect::InputDynamics {
        inputs: vec![1],
        factor: FactorParams {
            support: FactorSupport::All,
            order: 2,
            poles: vec![PoleParams {
                f_hz: 1e9,
                zeta: Some(-2.5e-7),
                re: Some(-1.0),
                im: None,
            }],
            zeros: Vec::new(),
            non_minimum_phase: None,
        },
    };
    let mut clash = two_steps().remove(1);
    clash.figure = Some("cmif.svg".into());
    let s = summary(&data, vec![step, clash], Some(1e-2));
    let steps = vec![
        (model.clone(), model.clone()),
        (model.clone(), model.clone()),
    ];
    let input = ReportInput {
        data: &data,
        noise_var: Some(&var),
        cmif: &c,
        peaks: &[],
        initial: &model,
        final_model: &model,
        final_model_std: None,
        steps: &steps,
        title: "degenerate",
    };
    let dir = temp_dir("degenerate");
    let files = write_report(&dir, &input, &s).unwrap();
    assert!(files
        .iter()
        .any(|f| f.ends_with("step_1_input_dynamics.svg")));
    // A step figure named like another figure does not overwrite it.
    assert!(files.iter().any(|f| f.ends_with("step_2_delay.svg")));
    assert_eq!(files.iter().filter(|f| f.ends_with("cmif.svg")).count(), 1);
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(
        md.contains("poles = [{f_hz = 1e9, re = -1, zeta = -2.5e-7}]"),
        "{md}"
    );
    for f in &files {
        assert!(std::fs::metadata(f).unwrap().len() > 0);
    }
    cleanup(&dir);
}

/// The wafer-stage truth against the nominal data: the report of a full-size case
/// (4 x 13, 4000 lines) is complete. Set `FRFIT_REPORT_DIR` to keep it and look at it.
/// Skipped, with a message, without `../shared/data`.
#[test]
fn wafer_report() {
    let test = "wafer_report";
    let (Some(data_path), Some(truth_path)) = (
        frf_data::shared_data::require(test, "wafer_nominal.csv"),
        frf_data::shared_data::require(test, "wafer_nominal.truth.json"),
    ) else {
        return;
    };
    let data = frf_data::io::read_frf_csv(data_path).unwrap();
    let truth = frf_data::truth::Truth::read(truth_path).unwrap();
    let model = truth.modal_model().unwrap();
    let w = omega(data.freq_hz_slice());
    let fin = model.zoh_response(&w, 1e-4, 1.0).unwrap();
    let initial = model.freq_response(&w).unwrap();
    let c = cmif(&data).unwrap();
    let peaks = pick_peaks(&c, &PeakConfig::default());
    let var = data.variances().unwrap().to_vec();
    let mut s = summary(&data, vec![], Some(0.01));
    s.data.path = "wafer_nominal.csv".into();
    s.final_model.modes = model
        .mode_summaries()
        .iter()
        .map(|m| ModeSummary {
            f_hz: m.f_hz,
            zeta: m.zeta,
        })
        .collect();
    let mut step = two_steps().remove(0);
    step.fitted = FittedEffect::Hold {
        fs_hz: 10000.0,
        remaining_delay_s: 0.0,
    };
    step.uncertainty = None;
    step.figure = None;
    s.steps = vec![step];
    let steps = vec![(initial.clone(), fin.clone())];
    let input = ReportInput {
        data: &data,
        noise_var: Some(&var),
        cmif: &c,
        peaks: &peaks,
        initial: &initial,
        final_model: &fin,
        final_model_std: None,
        steps: &steps,
        title: "Wafer stage, nominal: truth model",
    };
    let dir = std::env::var_os("FRFIT_REPORT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| temp_dir("wafer"));
    let t = std::time::Instant::now();
    let files = write_report(&dir, &input, &s).unwrap();
    println!(
        "wafer report ({} lines, {}x{}) written to {} in {:.0} ms",
        data.n_lines(),
        data.ny(),
        data.nu(),
        dir.display(),
        t.elapsed().as_secs_f64() * 1e3
    );
    check_files(&dir, &files);
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("hold"), "the step table names the effect");
    assert!(files.iter().any(|f| f.ends_with("bode_grid.svg")));
    if std::env::var_os("FRFIT_REPORT_DIR").is_none() {
        cleanup(&dir);
    }
}

/// A step whose factor a later step took out of the model says so in the table and in
/// its section.
#[test]
fn a_superseded_step_is_marked() {
    let (data, truth_g, var) = synthetic(2, 3, 50);
    let c = cmif(&data).unwrap();
    let mut steps = two_steps();
    steps[0].superseded_by = Some(2);
    let s = summary(&data, steps, Some(0.01));
    let responses = vec![
        (truth_g.clone(), truth_g.clone()),
        (truth_g.clone(), truth_g.clone()),
    ];
    let input = ReportInput {
        data: &data,
        noise_var: Some(&var),
        cmif: &c,
        peaks: &[],
        initial: &truth_g,
        final_model: &truth_g,
        final_model_std: None,
        steps: &responses,
        title: "x",
    };
    let dir = temp_dir("superseded");
    let files = write_report(&dir, &input, &s).unwrap();
    let md = check_files(&dir, &files);
    assert!(
        md.contains("| 1 | missed_mode | yes, removed at step 2 |"),
        "{md}"
    );
    assert!(
        md.contains("### Step 1: missed_mode (accepted, removed at step 2)"),
        "{md}"
    );
    assert!(md.contains("### Step 2: delay (rejected)"), "{md}");
    assert!(
        md.contains("1 added to the model (1 of them taken out again by a later step)"),
        "{md}"
    );
    cleanup(&dir);
}
