//! `frfit fit --init sk --bands ...` through the binary: Bayard's multi-band composite
//! fit on the simulated 2 x 3 plant of `common` (free body + modes at 35, 80 and
//! 150 Hz, exact values), and the errors of bad band settings.

mod common;
use common::*;

fn read_json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Given cut-offs: three bands, the rigid body in the lowest, the composite reproduces
/// the exact data, and the band report is in the model file.
#[test]
fn given_cut_offs_fit_the_plant_band_by_band() {
    let dir = temp_dir("bands-given");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("m.json");
    let o = run(&[
        "fit",
        csv.to_str().unwrap(),
        "--delay",
        "none",
        "--init",
        "sk",
        "--refine",
        "none",
        "--bands",
        "60,120",
        "--out",
        model.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m = read_json(&model);
    let link = &m["provenance"]["links"][0];
    assert_eq!(link["link"], "sk");
    let d = &link["details"];
    assert_eq!(d["cut_offs_hz"], serde_json::json!([60.0, 120.0]));
    let bands = d["bands"].as_array().unwrap();
    assert_eq!(bands.len(), 3);
    assert_eq!(bands[0]["integrators"], 2, "{d}");
    assert_eq!(bands[1]["integrators"], 0);
    assert!(bands[2]["feedthrough"].as_bool().unwrap());
    for b in bands {
        assert!(b["pairs"].as_u64().unwrap() >= 1, "{b}");
    }
    let e = d["rel_error"].as_f64().unwrap();
    assert!(e < 1e-4, "relative error {e:.3e}: {d}");
}

/// `--bands` needs the SK initialiser; empty bands and bad values are named.
#[test]
fn bad_band_settings_are_named() {
    let dir = temp_dir("bands-bad");
    let csv = write_plant(&dir, 0.0);
    let model = dir.join("m.json");
    for (init, bands, extra, says) in [
        (
            "cmif",
            "60",
            None,
            "bands are a setting of the SK initialiser (Bayard's multi-band fit, --init sk); the chain's initialiser is cmif",
        ),
        (
            "sk",
            "60,300",
            None,
            "band 3 (300 .. inf Hz) holds no lines (the data span 5 .. 200 Hz",
        ),
        ("sk", "60,abc", None, "cut-off 2 (`abc`) is not a number"),
        ("sk", "120,60", None, "cut-offs must increase strictly"),
        ("sk", "auto", Some("2,1e-4"), "QL 2 in `2,1e-4` must lie in [0, 1]"),
    ] {
        let mut args = vec![
            "fit",
            csv.to_str().unwrap(),
            "--delay",
            "none",
            "--init",
            init,
            "--bands",
            bands,
            "--out",
            model.to_str().unwrap(),
            "--quiet",
        ];
        if let Some(w) = extra {
            args.extend(["--band-weights", w]);
        }
        let o = run(&args);
        assert!(!o.status.success(), "{init} {bands}: should fail");
        let e = stderr(&o);
        assert!(e.contains("band"), "{e}");
        assert!(e.contains(says), "{init} {bands}: {e}");
        assert!(!model.exists(), "no model is written on bad bands");
    }
}
