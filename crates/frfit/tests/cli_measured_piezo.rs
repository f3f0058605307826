//! Issue 41, end to end as a user with time records works: `frfit simulate piezo` writes
//! the time records of a piezo-actuated 3 x 3 mechanism (2 realizations x 3 orthogonal
//! experiments x 2 periods of 8192 samples at 6400 Hz, a stochastic nonlinear
//! contribution of 3 % of `|P|`, 10 to 15 times the noise) and separate test records;
//! `frfit nonparametric` groups the experiments into realizations and splits the total
//! variance from its noise part; `frfit fit` and `frfit diagnose` fit the estimate;
//! `frfit predict` predicts the test records with each model, and `diagnose
//! --test-records` reports the initial and the final model's prediction of them.
//!
//! What must hold: the estimate's comments state the periods, the realizations and the
//! sample rate; the diagnosis names the delay, the static gain (a feedthrough) and the
//! zero-order hold, and ends with the 5 modes of the plant at the level of the total
//! variance, whose nonlinear part is significant (`nonlinear_distortion`); on the
//! test records it is no worse than `fit`, at the level the distortion sets for any
//! linear model (NRMSE within 1.5 times the 3 % distortion).

mod common;

use common::{run, stderr, temp_dir};

fn ok(args: &[&str]) -> String {
    let o = run(args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    stderr(&o) + &common::stdout(&o)
}

fn nrmse(path: &std::path::Path) -> Vec<f64> {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    v["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["nrmse"].as_f64().unwrap())
        .collect()
}

#[test]
fn time_records_to_a_diagnosed_model_that_predicts_test_records() {
    let dir = temp_dir("measured-piezo");
    let p = |name: &str| dir.join(name).display().to_string();
    ok(&[
        "simulate",
        "piezo",
        "--out",
        &p("sim.csv"),
        "--records",
        &p("rec"),
        "--test-records",
        &p("test"),
    ]);
    ok(&[
        "nonparametric",
        &p("rec/u.npy"),
        &p("rec/y.npy"),
        "--fs",
        "6400",
        "--out",
        &p("est.csv"),
    ]);
    let est = std::fs::read_to_string(dir.join("est.csv")).unwrap();
    assert!(
        est.contains("periods=2 realizations=2 experiments=3"),
        "{est:.600}"
    );
    assert!(est.contains("# sampling 6400 Hz"), "{est:.600}");
    assert!(
        est.lines().any(|l| l.contains("_var_noise")),
        "no _var_noise column"
    );

    ok(&["fit", &p("est.csv"), "--out", &p("fit.json")]);
    ok(&[
        "diagnose",
        &p("est.csv"),
        "--report",
        &p("dia"),
        "--test-records",
        &p("test/u.npy"),
        &p("test/y.npy"),
    ]);
    // the initial and the final model on the test records, in the report
    let report = std::fs::read_to_string(dir.join("dia/report.md")).unwrap();
    assert!(
        report.contains("## Prediction of test records"),
        "no section"
    );
    let (initial, last) = (
        nrmse(&dir.join("dia/test_records/initial/prediction.json")),
        nrmse(&dir.join("dia/test_records/final/prediction.json")),
    );
    println!("diagnose --test-records: initial {initial:.4?}, final {last:.4?}");
    for (a, b) in initial.iter().zip(&last) {
        assert!(
            b < a,
            "the final model predicts worse than the initial one: {b} > {a}"
        );
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("dia/summary.json")).unwrap())
            .unwrap();
    let accepted: Vec<&str> = summary["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["accepted"].as_bool() == Some(true))
        .map(|s| s["effect"].as_str().unwrap())
        .collect();
    let modes = summary["final_model"]["modes"].as_array().unwrap().len();
    println!(
        "diagnose: verdict {}, {modes} modes, accepted {accepted:?}, declared {}",
        summary["verdict"], summary["initial"]["declared"]
    );
    // the residual sits at the total variance, whose nonlinear part is significant
    assert_eq!(summary["verdict"], "nonlinear_distortion");
    let evidence = summary["verdict_evidence"].as_str().unwrap();
    assert!(
        evidence.contains("nonlinear part of the variance is significant"),
        "{evidence}"
    );
    for e in ["delay", "feedthrough", "hold"] {
        assert!(accepted.contains(&e), "{e} in {accepted:?}");
    }
    assert_eq!(modes, 5);

    for (model, out) in [("fit.json", "pred_fit"), ("dia/model.json", "pred_dia")] {
        ok(&[
            "predict",
            &p(model),
            "--records",
            &p("test/u.npy"),
            &p("test/y.npy"),
            "--fs",
            "6400",
            "--out",
            &p(out),
        ]);
    }
    let (f, d) = (
        nrmse(&dir.join("pred_fit/prediction.json")),
        nrmse(&dir.join("pred_dia/prediction.json")),
    );
    println!("test-record NRMSE per output: fit {f:.4?}, diagnose {d:.4?}");
    for (a, b) in f.iter().zip(&d) {
        assert!(*b <= 1.02 * a, "diagnose {b:.4} against fit {a:.4}");
        assert!(
            *b < 1.5 * 0.03,
            "diagnose {b:.4}: beyond the distortion's level"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Other plants of the same physics (`frfit simulate piezo --seed 3` and `4`: other mode
/// shapes, static gains, phases and noise). Both first fits take a free rigid body the
/// mechanism does not have (two integrators for 0.06 % of the cost on seed 3; the delay
/// restart's refit on seed 4), and the suspended-body reading then relabelled a real mode
/// (2770 Hz, the highest, and 635 Hz, far above the lowest line at 0.78 Hz) as a
/// `stiffness`, ending with 4 modes for 5. The diagnosis must name the delay, the static
/// gain and the hold, hold the plant's 5 modes, and accept no stiffness.
#[test]
#[ignore = "slow tier: two simulations and diagnoses, about 25 s"]
fn other_piezo_plants_keep_their_modes_and_take_no_suspension() {
    for seed in ["3", "4"] {
        let dir = temp_dir(&format!("measured-piezo-seed{seed}"));
        let p = |name: &str| dir.join(name).display().to_string();
        ok(&[
            "simulate",
            "piezo",
            "--seed",
            seed,
            "--out",
            &p("sim.csv"),
            "--records",
            &p("rec"),
        ]);
        ok(&[
            "nonparametric",
            &p("rec/u.npy"),
            &p("rec/y.npy"),
            "--fs",
            "6400",
            "--out",
            &p("est.csv"),
        ]);
        ok(&["diagnose", &p("est.csv"), "--report", &p("dia")]);
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("dia/summary.json")).unwrap())
                .unwrap();
        let accepted: Vec<&str> = summary["steps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["accepted"].as_bool() == Some(true))
            .map(|s| s["effect"].as_str().unwrap())
            .collect();
        let modes = summary["final_model"]["modes"].as_array().unwrap().len();
        println!("seed {seed}: {modes} modes, accepted {accepted:?}");
        for e in ["delay", "feedthrough", "hold"] {
            assert!(accepted.contains(&e), "seed {seed}: {e} in {accepted:?}");
        }
        assert!(
            !accepted.contains(&"stiffness"),
            "seed {seed}: {accepted:?}"
        );
        assert_eq!(modes, 5, "seed {seed}: {accepted:?}");
        assert_eq!(summary["verdict"], "nonlinear_distortion", "seed {seed}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
