//! Issue 42: `frfit fit --refine ml` on simulated wafer-stage plates without any
//! undeclared effect returns the plate's modes, no more. The CMIF start's delay
//! estimate is a few microseconds off, the start stands about 1000 times above the noise
//! level, and the refinement holds the delay while it adapts the structure: the modes
//! it adds there take up the delay's misfit (seed 4: four, at 123.6, 143.7 and twice
//! 204.09 Hz, none in the plant, with +-1.5 to +-5 Hz standard deviations). Freed, the
//! delay explains that misfit, and the added modes, tested again at the final
//! structure, are dropped. Slow tier (about 3 minutes on 2 cores: the closed-loop
//! experiment and a fit of 4 x 13 entries on 3960 lines).

mod common;

use common::{run, stderr, temp_dir};

fn modes_hz(path: &std::path::Path, key: &str) -> Vec<(f64, f64)> {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let modes = if key.is_empty() {
        &v["modes"]
    } else {
        &v[key]["modes"]
    };
    modes
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["f_hz"].as_f64().unwrap(), m["zeta"].as_f64().unwrap()))
        .collect()
}

#[test]
#[ignore = "slow tier (about 3 minutes on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn ml_refinement_of_a_plate_returns_its_modes_and_no_more() {
    let seed = "4";
    let dir = temp_dir("ml-plate");
    let p = |name: &str| dir.join(name).display().to_string();
    let o = run(&[
        "simulate",
        "wafer-stage",
        "--quiet",
        "--seed",
        seed,
        "--out",
        &p("plate.csv"),
        "--truth",
        &p("truth.json"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&[
        "fit",
        &p("plate.csv"),
        "--band",
        "20:2000",
        "--refine",
        "ml",
        "--out",
        &p("model.json"),
    ]);
    let log = stderr(&o) + &common::stdout(&o);
    assert!(o.status.success(), "{log}");
    println!("{log}");
    let truth: Vec<(f64, f64)> = modes_hz(&dir.join("truth.json"), "model")
        .into_iter()
        .filter(|(f, _)| (20.0..2000.0).contains(f))
        .collect();
    let fit = modes_hz(&dir.join("model.json"), "");
    assert_eq!(fit.len(), truth.len(), "{fit:?}\n{truth:?}\n{log}");
    for (f, z) in &truth {
        let (g, y) = fit
            .iter()
            .min_by(|a, b| (a.0 - f).abs().total_cmp(&(b.0 - f).abs()))
            .unwrap();
        assert!(
            (g - f).abs() < 1e-4 * f && (y - z).abs() < 1e-2 * z,
            "{f:.3} Hz, zeta {z:.5}: nearest fitted {g:.3} Hz, zeta {y:.5}\n{log}"
        );
    }
    // the case the test is about: modes were added under the held delay, then dropped
    assert!(log.contains("the delay was held"), "{log}");
    assert!(log.contains("tested again at the final structure"), "{log}");
}
