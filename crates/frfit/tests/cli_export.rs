//! `frfit export`: the exported state space, evaluated here independently (a complex
//! solve per line, the stated factors applied by hand), equals `frfit eval` of the same
//! model file at every line; the MAT-file holds the same matrices; bad output names are
//! refused.

mod common;
use common::*;
use faer::linalg::solvers::Solve;
use faer::Mat;
use frf_data::shared_data::require;
use frf_data::{FrfDataset, C64};
use frfit::export::StateSpaceExport;
use std::path::Path;

fn mat_c(rows: &[Vec<f64>], r: usize, c: usize) -> Mat<C64> {
    Mat::from_fn(r, c, |i, j| C64::new(rows[i][j], 0.0))
}

/// `C (x I - A)^-1 B + D` at the complex point `x`, by an LU solve.
fn transfer(m: &frfit::export::Matrices, n: usize, ny: usize, nu: usize, x: C64) -> Mat<C64> {
    let a = mat_c(&m.a, n, n);
    let lhs = Mat::from_fn(
        n,
        n,
        |i, j| if i == j { x } else { C64::new(0.0, 0.0) } - a[(i, j)],
    );
    let sol = lhs.partial_piv_lu().solve(mat_c(&m.b, n, nu));
    mat_c(&m.c, ny, n) * sol + mat_c(&m.d, ny, nu)
}

/// The largest relative difference over lines between the export's response (with its
/// factors applied here) and the CSV that `frfit eval` wrote.
fn export_against_eval(e: &StateSpaceExport, eval_csv: &Path) -> f64 {
    let pred = frf_data::io::read_frf_csv(eval_csv).unwrap();
    let (n, ny, nu) = (e.n_states, e.ny, e.nu);
    assert!(
        e.factors.dynamics.is_empty(),
        "no dynamics factors in these fits"
    );
    let mut worst: f64 = 0.0;
    for k in 0..pred.n_lines() {
        let w = pred.omega(k);
        let h = match (&e.discrete, e.factors.hold.starts_with("zoh")) {
            (Some(d), true) => transfer(&d.matrices, n, ny, nu, C64::from_polar(1.0, w * d.ts_s)),
            _ => transfer(&e.continuous, n, ny, nu, C64::new(0.0, w)),
        };
        let f = C64::new(0.0, w).powi(e.factors.derivative_order as i32)
            * C64::from_polar(1.0, -w * e.factors.delay_s);
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for i in 0..ny {
            for j in 0..nu {
                let x = e.factors.crosstalk.as_ref().map_or(0.0, |x| x[i][j]);
                let p = f * h[(i, j)] + x;
                let g = pred.value(k, i, j);
                num = num.max((p - g).norm());
                den = den.max(g.norm());
            }
        }
        worst = worst.max(num / den);
    }
    worst
}

fn fit_export_eval(data: &Path, dir: &Path, fit_args: &[&str]) -> (StateSpaceExport, f64) {
    let model = dir.join("m.json");
    let mut args = vec![
        "fit",
        data.to_str().unwrap(),
        "--out",
        model.to_str().unwrap(),
    ];
    args.extend_from_slice(fit_args);
    args.push("--quiet");
    let o = run(&args);
    assert!(o.status.success(), "fit: {}", stderr(&o));
    let ss = dir.join("ss.json");
    let o = run(&[
        "export",
        model.to_str().unwrap(),
        "--out",
        ss.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "export: {}", stderr(&o));
    let pred = dir.join("pred.csv");
    let o = run(&[
        "eval",
        model.to_str().unwrap(),
        "--at",
        data.to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "eval: {}", stderr(&o));
    let e: StateSpaceExport = serde_json::from_str(&std::fs::read_to_string(&ss).unwrap()).unwrap();
    let err = export_against_eval(&e, &pred);
    (e, err)
}

#[test]
fn continuous_export_equals_eval_and_the_mat_file_holds_the_same_matrices() {
    let dir = temp_dir("export-continuous");
    let csv = write_plant(&dir, 2e-4);
    let (e, err) = fit_export_eval(&csv, &dir, &["--delay", "auto"]);
    assert!(err < 1e-9, "export vs eval: {err:.3e}");
    assert!(e.discrete.is_none());
    // 3 modes of rank 1 and a double integrator of rank 2 (the plant's mass matrix
    // 0.5 + 0.1 (i + 2 j)): 6 + 4 states at least; the fitted residues' tiny further
    // directions are kept at tolerance 0
    assert!(e.n_states >= 10, "{} states", e.n_states);
    assert!(e.factors.delay_s > 1e-4, "delay {}", e.factors.delay_s);
    // the rigid body is kept as integrators: A has a zero eigenvalue block
    let model = dir.join("m.json");
    let mat = dir.join("ss.mat");
    let o = run(&[
        "export",
        model.to_str().unwrap(),
        "--out",
        mat.to_str().unwrap(),
        "--discrete",
        "2000",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let vars = frf_data::io::mat5::parse_mat5(&std::fs::read(&mat).unwrap(), "ss.mat").unwrap();
    let get = |name: &str| {
        vars.iter()
            .find(|v| v.name == name)
            .unwrap_or_else(|| panic!("{name} missing"))
    };
    for name in ["A", "B", "C", "D", "Ad", "Bd", "Cd", "Dd", "Ts", "delay_s"] {
        get(name);
    }
    let a = format!("{:?}", get("A").value);
    assert!(
        a.contains(&format!("{:?}", e.continuous.a[0][1])),
        "A differs"
    );
    // with a rank tolerance the modes and the mass line take the states of their rank
    let ss = dir.join("ss_rank.json");
    let o = run(&[
        "export",
        model.to_str().unwrap(),
        "--out",
        ss.to_str().unwrap(),
        "--rank-tol",
        "1e-6",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r: StateSpaceExport = serde_json::from_str(&std::fs::read_to_string(&ss).unwrap()).unwrap();
    assert_eq!(r.n_states, 10, "{}", r.response);
    let err = export_against_eval(&r, &dir.join("pred.csv"));
    assert!(err < 1e-4, "rank-reduced export vs eval: {err:.3e}");
}

#[test]
fn exact_hold_export_uses_the_discrete_equivalent_and_equals_eval() {
    let dir = temp_dir("export-zoh");
    let csv = write_plant(&dir, 0.0);
    let (e, err) = fit_export_eval(&csv, &dir, &["--delay", "none", "--hold", "zoh:1000"]);
    assert!(err < 1e-9, "export vs eval: {err:.3e}");
    let d = e
        .discrete
        .as_ref()
        .expect("a zoh model has its discrete form");
    assert!((d.ts_s - 1e-3).abs() < 1e-15);
}

#[test]
fn bad_output_names_are_refused() {
    let dir = temp_dir("export-bad");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("m.json");
    let o = run(&[
        "fit",
        csv.to_str().unwrap(),
        "--delay",
        "none",
        "--out",
        model.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for (out, extra, says) in [
        ("ss.txt", None, ".json or .mat"),
        ("ss.json", Some("--discrete=-5"), "positive number of Hz"),
        ("ss.json", Some("--rank-tol=2"), "[0, 1)"),
    ] {
        let out = dir.join(out);
        let mut args = vec![
            "export",
            model.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        if let Some(x) = extra {
            args.push(x);
        }
        let o = run(&args);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(stderr(&o).contains(says), "{}", stderr(&o));
    }
    let o = run(&[
        "export",
        dir.join("missing.json").to_str().unwrap(),
        "--out",
        "x.json",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("missing.json"), "{}", stderr(&o));
}

/// The wafer stage (4 x 13, exact hold declared in the file, delay fitted).
#[test]
fn wafer_export_equals_eval() {
    let Some(data) = require("wafer_export_equals_eval", "wafer_nominal.csv") else {
        return;
    };
    let dir = temp_dir("export-wafer");
    let (e, err) = fit_export_eval(&data, &dir, &["--band", "20:2000"]);
    println!(
        "wafer export: {} states, hold {}, delay {:.3} us, max relative difference to eval {err:.3e}",
        e.n_states,
        e.factors.hold,
        e.factors.delay_s * 1e6
    );
    assert!(e.discrete.is_some(), "hold {}", e.factors.hold);
    assert!(err < 1e-9, "export vs eval: {err:.3e}");
}

/// Issue 44: the modes and their standard deviations go with the export. An ML fit
/// (which computes the covariance) exports `modes` with finite positive `f_hz_std` and
/// `zeta_std` in the JSON and `f_hz_std`, `zeta_std` in the `.mat`; so does a refined-IV
/// fit (its standard deviations from the information matrix at its estimate).
#[test]
fn the_modes_and_their_standard_deviations_go_with_the_export() {
    let dir = temp_dir("export-std");
    let csv = write_plant(&dir, 2e-4);
    let (e, _) = fit_export_eval(&csv, &dir, &["--delay", "auto", "--refine", "ml"]);
    assert_eq!(e.modes.len(), common::MODES_HZ.len(), "{:?}", e.modes);
    for m in &e.modes {
        let (sf, sz) = (m.f_hz_std.unwrap(), m.zeta_std.unwrap());
        assert!(sf.is_finite() && sf > 0.0 && sf < 0.01 * m.f_hz, "{m:?}");
        assert!(sz.is_finite() && sz > 0.0, "{m:?}");
    }
    let mat = dir.join("ss.mat");
    let o = run(&[
        "export",
        dir.join("m.json").to_str().unwrap(),
        "--out",
        mat.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let vars = frf_data::io::mat5::parse_mat5(&std::fs::read(&mat).unwrap(), "ss.mat").unwrap();
    for name in ["f_hz", "zeta", "f_hz_std", "zeta_std"] {
        assert!(vars.iter().any(|v| v.name == name), "{name} missing");
    }
    let (e, _) = fit_export_eval(&csv, &dir, &["--delay", "auto"]);
    assert_eq!(e.modes.len(), common::MODES_HZ.len());
    assert!(e
        .modes
        .iter()
        .all(|m| m.f_hz_std.is_some_and(|s| s > 0.0) && m.zeta_std.is_some_and(|s| s > 0.0)));
}
