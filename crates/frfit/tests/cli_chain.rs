//! The estimator chain through the binary: `--init` / `--refine` names, the chain in
//! the model file and `summary.json`, and `--refine none` writing the initialiser's
//! model, on the simulated 2 x 3 plant of `common` (no shared files needed).

mod common;
use common::*;

fn read_json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn unknown_methods_name_the_choices() {
    let dir = temp_dir("chain-names");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("m.json");
    for (opt, name, says) in [
        (
            "--init",
            "bogus",
            "unknown method `bogus`; available: cmif, subspace, sk",
        ),
        (
            "--init",
            "cmif,bogus",
            "unknown method `bogus`; available: cmif, subspace, sk",
        ),
        ("--refine", "bogus", "available: riv, none, ml"),
    ] {
        let o = run(&[
            "fit",
            csv.to_str().unwrap(),
            opt,
            name,
            "--out",
            model.to_str().unwrap(),
            "--quiet",
        ]);
        assert_eq!(o.status.code(), Some(1), "{opt} {name}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(
            e.contains(opt) && e.contains(name) && e.contains(says),
            "{e}"
        );
        assert!(!model.exists(), "no model is written on a bad chain");
    }
}

#[test]
fn the_chain_is_recorded_and_refine_none_writes_the_start() {
    let dir = temp_dir("chain-record");
    let csv = write_plant(&dir, 0.0);
    let refined = dir.join("riv.json");
    let start = dir.join("none.json");
    let report = dir.join("report");
    for (refine, path) in [("riv", &refined), ("none", &start)] {
        let mut args = vec![
            "fit",
            csv.to_str().unwrap(),
            "--delay",
            "none",
            "--init",
            "cmif",
            "--refine",
            refine,
            "--out",
            path.to_str().unwrap(),
            "--quiet",
        ];
        if refine == "riv" {
            args.extend(["--report", report.to_str().unwrap()]);
        }
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let r = read_json(&refined);
    assert_eq!(r["provenance"]["chain"], serde_json::json!(["cmif", "riv"]));
    let links = r["provenance"]["links"].as_array().unwrap();
    assert_eq!(links.len(), 2);
    assert_eq!(links[0]["link"], "cmif");
    assert_eq!(links[0]["iterations"], 0);
    assert!(links[0]["details"]["cmif_peaks"].as_array().unwrap().len() >= 3);
    assert_eq!(links[1]["link"], "riv");
    assert!(links[1]["iterations"].as_u64().unwrap() > 0);
    let summary = read_json(&report.join("summary.json"));
    assert_eq!(summary["chain"], serde_json::json!(["cmif", "riv"]));

    let n = read_json(&start);
    assert_eq!(
        n["provenance"]["chain"],
        serde_json::json!(["cmif", "none"])
    );
    assert_eq!(n["provenance"]["links"].as_array().unwrap().len(), 1);
    // the start keeps the CMIF damping of section 4.4; the refinement moves it
    let zetas = |v: &serde_json::Value| -> Vec<f64> {
        v["modes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["zeta"].as_f64().unwrap())
            .collect()
    };
    assert!(
        zetas(&n).iter().all(|z| (z - 0.01).abs() < 1e-9),
        "{:?}",
        zetas(&n)
    );
    // the true damping is 0.01 as well, so compare the frequencies: the refined ones
    // are exact, the start's are the CMIF peaks on the 0.25 Hz grid
    let freqs = |v: &serde_json::Value| -> Vec<f64> {
        v["modes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["f_hz"].as_f64().unwrap())
            .collect()
    };
    for (f, t) in freqs(&r).iter().zip(MODES_HZ) {
        assert!((f / t - 1.0).abs() < 1e-6, "refined {f} vs {t}");
    }
    for (f, t) in freqs(&n).iter().zip(MODES_HZ) {
        assert!((f / t - 1.0).abs() < 0.01, "start {f} vs {t}");
    }
}

#[test]
fn refine_ml_reports_the_uncertainty_of_the_modes() {
    let dir = temp_dir("chain-ml");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("ml.json");
    let report = dir.join("report");
    let o = run(&[
        "fit",
        csv.to_str().unwrap(),
        "--delay",
        "none",
        "--refine",
        "ml",
        "--out",
        model.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m = read_json(&model);
    assert_eq!(m["provenance"]["chain"], serde_json::json!(["cmif", "ml"]));
    let s = read_json(&report.join("summary.json"));
    let u = &s["uncertainty"];
    assert_eq!(u["method"], "ml");
    let modes = u["modes"].as_array().unwrap();
    assert_eq!(modes.len(), 3, "{u}");
    for (mo, t) in modes.iter().zip(MODES_HZ) {
        let f = mo["f_hz"].as_f64().unwrap();
        let sf = mo["f_hz_std"].as_f64().unwrap();
        assert!((f / t - 1.0).abs() < 1e-6, "{f} vs {t}");
        assert!(sf > 0.0 && sf < 1e-2, "{mo}");
        assert!(mo["zeta_std"].as_f64().unwrap() > 0.0, "{mo}");
    }
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        md.contains("+- 2 sigma"),
        "the fit table shows the intervals"
    );
}

/// `--refine ml` writes each mode's `f_hz_std` and `zeta_std` and the fitted delay's
/// `delay_s_std` to the model file, equal to what `summary.json` reports; `frfit eval`
/// and `frfit export` read the file; `--refine riv` writes them too (issue 44), from the
/// information matrix at its own estimate, within a factor of two of the ML fit's.
#[test]
fn refine_ml_writes_the_standard_deviations_to_the_model_file() {
    let dir = temp_dir("chain-ml-model");
    let csv = write_plant(&dir, 2e-4);
    let report = dir.join("report");
    let (ml, riv) = (dir.join("ml.json"), dir.join("riv.json"));
    for (refine, path) in [("ml", &ml), ("riv", &riv)] {
        let o = run(&[
            "fit",
            csv.to_str().unwrap(),
            "--delay",
            "auto",
            "--refine",
            refine,
            "--out",
            path.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
            "--quiet",
        ]);
        assert!(o.status.success(), "{refine}: {}", stderr(&o));
        if refine == "ml" {
            let m = read_json(&ml);
            let s = read_json(&report.join("summary.json"));
            let u = &s["uncertainty"];
            let modes = m["modes"].as_array().unwrap();
            assert_eq!(modes.len(), MODES_HZ.len(), "{m}");
            for mo in modes {
                let f = mo["f_hz"].as_f64().unwrap();
                let (sf, sz) = (
                    mo["f_hz_std"].as_f64().expect("f_hz_std"),
                    mo["zeta_std"].as_f64().expect("zeta_std"),
                );
                assert!(
                    sf.is_finite() && sf > 0.0 && sz.is_finite() && sz > 0.0,
                    "{mo}"
                );
                let us = u["modes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|x| (x["f_hz"].as_f64().unwrap() / f - 1.0).abs() < 1e-9)
                    .unwrap_or_else(|| panic!("mode at {f} Hz in summary.json: {u}"));
                assert_eq!(us["f_hz_std"].as_f64(), Some(sf), "{us} vs {mo}");
                assert_eq!(us["zeta_std"].as_f64(), Some(sz), "{us} vs {mo}");
            }
            assert_eq!(m["delay_fitted"], true);
            let sd = m["delay_s_std"].as_f64().expect("delay_s_std");
            assert!(sd.is_finite() && sd > 0.0, "{sd}");
            assert_eq!(u["delay_s_std"].as_f64(), Some(sd));
            // the true delay is inside a few standard deviations
            let d = m["delay_s"].as_f64().unwrap();
            assert!((d - 2e-4).abs() < 5.0 * sd, "delay {d} +- {sd}");
        } else {
            // issue 44: the refined-IV chain reports the asymptotic covariance of the ML
            // criterion at its own estimate ("information"); its standard deviations are
            // those of the ML fit to within the small difference of the two estimates
            let (m, mm) = (read_json(&riv), read_json(&ml));
            let s = read_json(&report.join("summary.json"));
            assert_eq!(
                s["uncertainty"]["method"], "information",
                "{}",
                s["uncertainty"]
            );
            let sd = m["delay_s_std"]
                .as_f64()
                .expect("delay_s_std of the riv fit");
            let sd_ml = mm["delay_s_std"].as_f64().unwrap();
            assert!(
                sd / sd_ml > 0.5 && sd / sd_ml < 2.0,
                "delay std {sd} vs ml {sd_ml}"
            );
            let ml_modes = mm["modes"].as_array().unwrap();
            for mo in m["modes"].as_array().unwrap() {
                let f = mo["f_hz"].as_f64().unwrap();
                let sf = mo["f_hz_std"].as_f64().expect("f_hz_std of the riv fit");
                let sz = mo["zeta_std"].as_f64().expect("zeta_std of the riv fit");
                let twin = ml_modes
                    .iter()
                    .min_by(|a, b| {
                        let da = (a["f_hz"].as_f64().unwrap() - f).abs();
                        let db = (b["f_hz"].as_f64().unwrap() - f).abs();
                        da.total_cmp(&db)
                    })
                    .unwrap();
                let (tf, tz) = (
                    twin["f_hz_std"].as_f64().unwrap(),
                    twin["zeta_std"].as_f64().unwrap(),
                );
                assert!(sf / tf > 0.5 && sf / tf < 2.0, "{mo} vs {twin}");
                assert!(sz / tz > 0.5 && sz / tz < 2.0, "{mo} vs {twin}");
            }
        }
    }
    // the file with standard deviations is read by eval and export
    let pred = dir.join("pred.csv");
    let o = run(&[
        "eval",
        ml.to_str().unwrap(),
        "--at",
        csv.to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "eval: {}", stderr(&o));
    let ss = dir.join("ss.json");
    let o = run(&[
        "export",
        ml.to_str().unwrap(),
        "--out",
        ss.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "export: {}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--init cmif,subspace`: both chains run, the one with the smallest final prediction
/// error is kept, and every run is in summary.json's `chain_runs`.
#[test]
fn several_initialisers_keep_the_smallest_final_prediction_error() {
    let dir = temp_dir("chain-several");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("m.json");
    let report = dir.join("report");
    let o = run(&[
        "fit",
        csv.to_str().unwrap(),
        "--delay",
        "none",
        "--init",
        "cmif,subspace",
        "--refine",
        "riv",
        "--out",
        model.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = read_json(&report.join("summary.json"));
    let runs = summary["chain_runs"].as_array().expect("chain_runs");
    assert_eq!(runs.len(), 2, "{runs:?}");
    assert_eq!(runs[0]["chain"], serde_json::json!(["cmif", "riv"]));
    assert_eq!(runs[1]["chain"], serde_json::json!(["subspace", "riv"]));
    let kept: Vec<&serde_json::Value> = runs.iter().filter(|r| r["kept"] == true).collect();
    assert_eq!(kept.len(), 1, "{runs:?}");
    let fpe = |r: &serde_json::Value| r["fpe"].as_f64().unwrap();
    assert!(runs.iter().all(|r| fpe(kept[0]) <= fpe(r)), "{runs:?}");
    assert_eq!(summary["chain"], kept[0]["chain"]);
    let m = read_json(&model);
    assert_eq!(m["provenance"]["chain"], kept[0]["chain"]);
    assert!(
        m["provenance"]["notes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().contains("initialisers tried")),
        "{}",
        m["provenance"]["notes"]
    );
}
