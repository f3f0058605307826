//! Integration tests of `frfit fit`, `frfit eval` and `frfit diagnose` through the
//! binary, on a simulated 2 x 3 plant the test writes (no shared files needed), and the
//! errors a user sees.

use faer::Mat;
use frf_data::io::read_frf_csv;
use frf_data::{Frf, FrfDataset};
use realize::{ModalModel, PolePair};
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_frfit"))
        .args(args)
        .output()
        .expect("the frfit binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn temp_dir(test: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let d = std::env::temp_dir().join(format!(
        "frfit-cli-fit-{test}-{}-{nanos}",
        std::process::id()
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 2 x 3 plant (free body + modes at 35, 80 and 150 Hz), 5..200 Hz in 0.25 Hz lines,
/// optionally delayed, with a variance of (1e-3 |G|)^2 attached.
fn write_plant(dir: &Path, delay_s: f64) -> PathBuf {
    let (ny, nu) = (2, 3);
    let mut m = ModalModel::new(ny, nu);
    m.rigid = vec![
        Mat::zeros(ny, nu),
        Mat::from_fn(ny, nu, |i, j| 0.5 + 0.1 * (i + 2 * j) as f64),
    ];
    let shapes = [
        ([1.0, 0.4], [1.0, -0.5, 0.3]),
        ([0.3, -1.0], [0.2, 1.0, 0.8]),
        ([1.0, 1.0], [-0.7, 0.4, 1.0]),
    ];
    for (f, (c, b)) in [35.0, 80.0, 150.0].iter().zip(shapes) {
        let num = Mat::from_fn(ny, nu, |i, j| c[i] * b[j] * (TAU * f).powi(2) * 2.0);
        m.pairs.push(PolePair::from_second_order(*f, 0.01, &num));
    }
    let f: Vec<f64> = (0..781).map(|k| 5.0 + 0.25 * k as f64).collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let g = m.freq_response(&w).unwrap();
    let frf = Frf::from_grid(f, g).unwrap();
    let frf = Frf::from_fn(frf.freq_hz_slice().to_vec(), ny, nu, |k, i, j| {
        frf.value(k, i, j) * frf_data::C64::from_polar(1.0, -w[k] * delay_s)
    })
    .unwrap();
    let var: Vec<f64> = frf
        .values()
        .iter()
        .map(|z| (1e-3 * z.norm()).powi(2))
        .collect();
    let mut frf = frf.with_variance(Some(var)).unwrap();
    frf.units = Some("m/N".into());
    let path = dir.join("plant.csv");
    frf_data::io::write_frf_csv(&path, &frf, &["simulated 2x3 plant".into()]).unwrap();
    path
}

/// Median relative difference of two FRFs on the same lines.
fn median_rel(a: &Frf, b: &Frf) -> f64 {
    assert_eq!(a.n_lines(), b.n_lines());
    let mut v: Vec<f64> = a
        .values()
        .iter()
        .zip(b.values())
        .map(|(x, y)| (x - y).norm() / y.norm())
        .collect();
    v.sort_by(|x, y| x.total_cmp(y));
    v[v.len() / 2]
}

#[test]
fn fit_then_eval_reproduces_the_data() {
    let dir = temp_dir("fit-eval");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("model.json");
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
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let modes: Vec<f64> = json["modes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["f_hz"].as_f64().unwrap())
        .collect();
    assert_eq!(modes.len(), 3, "{modes:?}");
    for (f, t) in modes.iter().zip([35.0, 80.0, 150.0]) {
        assert!((f / t - 1.0).abs() < 1e-6, "{f} vs {t}");
    }
    let pred = dir.join("pred.csv");
    let o = run(&[
        "eval",
        model.to_str().unwrap(),
        "--at",
        csv.to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = median_rel(&read_frf_csv(&pred).unwrap(), &read_frf_csv(&csv).unwrap());
    assert!(e < 1e-8, "median relative error {e:e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fit_accepts_a_hold_and_a_delay_and_writes_a_report() {
    let dir = temp_dir("hold");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("model.json");
    let report = dir.join("report");
    let o = run(&[
        "fit",
        csv.to_str().unwrap(),
        "--hold",
        "zoh:4000",
        "--delay",
        "150us",
        "--band",
        "10:190",
        "--out",
        model.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert!(
        json["hold"].to_string().contains("4000"),
        "{}",
        json["hold"]
    );
    assert!(report.join("report.md").is_file());
    assert!(report.join("summary.json").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn diagnose_finds_an_undeclared_delay_and_eval_includes_it() {
    let dir = temp_dir("diagnose");
    let csv = write_plant(&dir, 80e-6);
    let report = dir.join("report");
    let o = run(&[
        "diagnose",
        csv.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in ["report.md", "summary.json", "model.json"] {
        assert!(report.join(f).is_file(), "{f} written");
    }
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("summary.json")).unwrap())
            .unwrap();
    let steps = s["steps"].as_array().unwrap();
    let delay = steps
        .iter()
        .find(|st| st["effect"] == "delay" && st["accepted"] == true)
        .expect("an accepted delay step");
    let d = delay["params"]["seconds"].as_f64().unwrap();
    assert!((d - 80e-6).abs() < 1e-7, "delay {d:e}");
    assert!(delay["before"]["median_rel"].as_f64().unwrap() > 0.01);
    assert!(delay["after"]["median_rel"].as_f64().unwrap() < 1e-3);
    // (the data are noise-free with a stated variance of 1e-3 relative: the residual
    // ends far below the noise)
    assert!(s["final"]["residual_to_noise"].as_f64().unwrap() < 1.0);
    // the final model's response includes the delay the loop added
    let pred = dir.join("pred.csv");
    let o = run(&[
        "eval",
        report.join("model.json").to_str().unwrap(),
        "--at",
        csv.to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = median_rel(&read_frf_csv(&pred).unwrap(), &read_frf_csv(&csv).unwrap());
    assert!(e < 1e-4, "median relative error {e:e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn user_errors_are_clear() {
    let dir = temp_dir("errors");
    let csv = write_plant(&dir, 0.0);
    let csv = csv.to_str().unwrap();
    let out = dir.join("m.json");
    let out = out.to_str().unwrap();
    // a missing file is named
    let o = run(&["fit", "/no/such/file.csv", "--out", out]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/no/such/file.csv"), "{}", stderr(&o));
    let o = run(&["diagnose", "/no/such/file.csv", "--report", out]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/no/such/file.csv"), "{}", stderr(&o));
    // a band outside the data says where the data are
    let o = run(&["fit", csv, "--band", "500:900", "--out", out]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("band") && e.contains("200"), "{e}");
    // a malformed hold, delay or mode count names the option
    for (opt, val) in [
        ("--hold", "zoh:abc"),
        ("--delay", "soon"),
        ("--modes", "-3"),
    ] {
        let o = run(&["fit", csv, opt, val, "--out", out]);
        assert!(!o.status.success(), "{opt} {val}");
        let e = stderr(&o);
        assert!(e.contains(opt) || e.contains(val), "{opt} {val}: {e}");
        assert!(!e.contains("panicked"), "{e}");
    }
    // a requested mode outside the band
    let o = run(&["fit", csv, "--band", "5:100", "--modes", "3", "--out", out]);
    assert!(!e_contains_panic(&o));
    // eval of a missing model
    let o = run(&["eval", "/no/model.json", "--at", csv, "--out", out]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/no/model.json"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

fn e_contains_panic(o: &Output) -> bool {
    stderr(o).contains("panicked")
}
