//! Integration tests of `frfit info` and `frfit cmif`: the binary runs on a small CSV the
//! test writes (a simulated 2 x 3 plant with three modes) and, when the shared reference
//! data are there, on `wafer_nominal.csv`.

use frf_data::shared_data::require;
use frf_data::Frf;

mod common;
use common::*;

#[test]
fn info_summarises_the_file() {
    let dir = temp_dir("info");
    let csv = write_plant(&dir, 0.0);
    let o = run(&["info", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("2 output(s) x 3 input(s)"), "{out}");
    assert!(out.contains("5 .. 200 Hz"), "{out}");
    assert!(out.contains("lines:        781"), "{out}");
    assert!(out.contains("0.25 Hz (uniform)"), "{out}");
    assert!(out.contains("variance:     present"), "{out}");
    assert!(out.contains("units:        m/N"), "{out}");
    // sqrt(var)/|G| = 1e-3 everywhere.
    assert!(out.contains("median 0.001"), "{out}");
    // JSON form.
    let o = run(&["info", csv.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["ny"], 2);
    assert_eq!(v["nu"], 3);
    assert_eq!(v["n_lines"], 781);
    assert_eq!(v["has_variance"], true);
    let med = v["noise_rel"]["median"].as_f64().unwrap();
    assert!((med - 1e-3).abs() < 1e-9, "{med}");
    let p95 = v["noise_rel"]["p95"].as_f64().unwrap();
    assert!((p95 - 1e-3).abs() < 1e-9, "{p95}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn info_without_variance_says_so() {
    let dir = temp_dir("info-novar");
    let f: Vec<f64> = vec![1.0, 2.0, 4.0];
    let frf = Frf::from_fn(f, 1, 1, |k, _, _| frf_data::C64::new(1.0 + k as f64, 0.0)).unwrap();
    let path = dir.join("tiny.csv");
    frf_data::io::write_frf_csv(&path, &frf, &[]).unwrap();
    let o = run(&["info", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("variance:     absent"), "{out}");
    assert!(out.contains("the data carry no variance"), "{out}");
    assert!(out.contains("non-uniform"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn peaks_of(json: &serde_json::Value) -> Vec<f64> {
    json["peaks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["f_hz"].as_f64().unwrap())
        .collect()
}

#[test]
fn cmif_json_finds_the_modes() {
    let dir = temp_dir("cmif-json");
    let csv = write_plant(&dir, 0.0);
    let o = run(&["cmif", csv.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let peaks = peaks_of(&v);
    assert_eq!(peaks.len(), 3, "{peaks:?}");
    for (p, f) in peaks.iter().zip(MODES_HZ) {
        assert!((p - f).abs() < 0.01 * f, "{p} vs {f}");
    }
    for p in v["peaks"].as_array().unwrap() {
        assert!(p["sv_index"].as_u64().unwrap() < 2);
        assert!(p["prominence"].as_f64().unwrap() > 3.0);
    }
    assert_eq!(v["n_lines"], 781);
    assert_eq!(v["band_hz"][0].as_f64().unwrap(), 5.0);
    assert_eq!(v["band_hz"][1].as_f64().unwrap(), 200.0);

    // A band and a number of modes.
    let o = run(&[
        "cmif",
        csv.to_str().unwrap(),
        "--json",
        "--band",
        "50:200",
        "--modes",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let peaks = peaks_of(&v);
    assert_eq!(peaks.len(), 1, "{peaks:?}");
    assert!(peaks[0] > 50.0);
    assert_eq!(v["band_hz"][0].as_f64().unwrap(), 50.0);
    assert_eq!(v["n_lines"], 601);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cmif_table_and_svg() {
    let dir = temp_dir("cmif-svg");
    let csv = write_plant(&dir, 0.0);
    let svg = dir.join("cmif.svg");
    let o = run(&[
        "cmif",
        csv.to_str().unwrap(),
        "--band",
        "10:",
        "--svg",
        svg.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("prominence [dB]"), "{out}");
    assert!(out.contains("3 peak(s)"), "{out}");
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg"), "not an SVG");
    // The peak labels (frequencies, Hz) are text elements of the figure.
    let texts: Vec<&str> = text
        .split("</text>")
        .filter_map(|t| t.rsplit_once('>').map(|(_, x)| x.trim()))
        .collect();
    for f in ["35.0", "80.0", "150"] {
        assert!(texts.contains(&f), "label {f} missing in {texts:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn errors_are_clear() {
    let dir = temp_dir("errors");
    let csv = write_plant(&dir, 0.0);
    // Missing file: the path is named.
    let missing = dir.join("does-not-exist.csv");
    for cmd in ["info", "cmif"] {
        let o = run(&[cmd, missing.to_str().unwrap()]);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.contains("does-not-exist.csv"), "{e}");
        assert!(e.contains("no such file"), "{e}");
    }
    // Band outside the data: both ranges are named.
    let o = run(&["cmif", csv.to_str().unwrap(), "--band", "300:400"]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("300:400"), "{e}");
    assert!(e.contains("5 .. 200 Hz"), "{e}");
    // Malformed band and modes.
    for bad in [["--band", "20"], ["--band", "30:20"], ["--modes", "0"]] {
        let o = run(&["cmif", csv.to_str().unwrap(), bad[0], bad[1]]);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(!stderr(&o).is_empty());
    }
    // A file that is not an FRF CSV.
    let junk = dir.join("junk.csv");
    std::fs::write(&junk, "hello,world\n1,2\n").unwrap();
    let o = run(&["info", junk.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("junk.csv"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn wafer_nominal_through_the_cli() {
    let Some(path) = require("wafer_nominal_through_the_cli", "wafer_nominal.csv") else {
        return;
    };
    let p = path.to_str().unwrap();
    let o = run(&["info", p]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("4 output(s) x 13 input(s)"), "{out}");
    assert!(out.contains("lines:        4000"), "{out}");
    let o = run(&["cmif", p, "--band", "20:2000", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let peaks = peaks_of(&v);
    assert!((15..=20).contains(&peaks.len()), "{peaks:?}");
    assert_eq!(v["n_lines"], 3960);
}
