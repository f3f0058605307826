//! The diagnosis loop on the reference wafer-stage cases of `../shared/data`, each with
//! an effect the nominal model does not declare (issue: the frfit pipeline). Skipped,
//! with a message, when `../shared/data` is not beside the checkout; the simulated
//! systems of `no_false_discovery.rs` exercise the loop without files.

use additive_riv::ModeSelection;
use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::{FrfDataset, ModelStructure};
use frfit::pipeline::{run, PipelineConfig, PipelineOutput};

fn diagnose(test: &str, name: &str, modes: ModeSelection) -> Option<PipelineOutput> {
    let path = require(test, name)?;
    let data = read_frf_csv(&path).unwrap();
    let cfg = PipelineConfig {
        band_hz: Some((20.0, 2000.0)),
        modes,
        diagnose: true,
        ..Default::default()
    };
    let out = run(&data, &path.display().to_string(), &cfg, "diagnose").unwrap();
    let s = &out.summary;
    println!("{name}: initial {:?}", s.initial.errors);
    for st in &s.steps {
        println!(
            "  {} accepted={} F={:.3} (crit {:.3}) {} median {:.3e} -> {:.3e}",
            st.effect,
            st.accepted,
            st.f_statistic,
            st.f_critical,
            st.params,
            st.before.median_rel,
            st.after.median_rel
        );
    }
    println!(
        "  verdict {}: {}\n  final {:?}, data noise {:?}",
        s.verdict, s.verdict_evidence, s.final_errors, s.data_noise_median_rel
    );
    Some(out)
}

fn accepted<'a>(out: &'a PipelineOutput, effect: &str) -> Vec<&'a frfit::summary::StepSummary> {
    out.summary
        .steps
        .iter()
        .filter(|s| s.accepted && s.effect == effect)
        .collect()
}

/// After the loop the median relative error against the data is within 1.5x the data's
/// own median noise level.
fn assert_at_noise_level(out: &PipelineOutput) {
    let s = &out.summary;
    let noise = s.data_noise_median_rel.expect("the data carry a variance");
    assert!(
        s.final_errors.median_rel <= 1.5 * noise,
        "final median {:.3e} vs data noise {noise:.3e}",
        s.final_errors.median_rel
    );
    assert!(
        s.steps.iter().all(|st| st.before.median_rel.is_finite()),
        "every step reports its error before"
    );
}

#[test]
fn nominal_adds_nothing_beyond_the_hold() {
    let test = "nominal_adds_nothing_beyond_the_hold";
    let Some(out) = diagnose(test, "wafer_nominal.csv", ModeSelection::Auto) else {
        return;
    };
    let Some(clean) = require(test, "wafer_nominal.noiseless.csv") else {
        return;
    };
    for st in out.summary.steps.iter().filter(|s| s.accepted) {
        assert_eq!(st.effect, "hold", "unexpected discovery {st:?}");
    }
    assert_eq!(out.summary.verdict, "noise_limited");
    assert_at_noise_level(&out);
    // the final model against the exact response: as good as declaring the hold
    let clean = read_frf_csv(&clean).unwrap();
    let clean = clean.band(20.0, 2000.0).unwrap();
    let g = out.fit.model.response(&clean);
    let m = clean.n_entries();
    let mut rel: Vec<f64> = (0..clean.n_lines() * m)
        .map(|idx| {
            let t = clean.value(idx / m, idx % m % clean.ny(), idx % m / clean.ny());
            (g.values[idx] - t).norm() / t.norm()
        })
        .collect();
    rel.sort_by(|a, b| a.total_cmp(b));
    let median = rel[rel.len() / 2];
    println!("final model vs noiseless: median {median:.3e}");
    assert!(
        median <= 3e-5,
        "median {median:.3e} vs the noiseless response"
    );
}

#[test]
fn extra_delay_is_found() {
    let test = "extra_delay_is_found";
    let Some(out) = diagnose(test, "wafer_extra_delay.csv", ModeSelection::Auto) else {
        return;
    };
    let delays = accepted(&out, "delay");
    assert_eq!(delays.len(), 1, "one delay step");
    let seconds = delays[0].params["seconds"].as_f64().unwrap();
    assert!(
        (seconds - 60e-6).abs() <= 5e-6,
        "extra delay {:.2} us, declared effect 60 us",
        seconds * 1e6
    );
    assert!(delays[0].after.median_rel < delays[0].before.median_rel);
    assert_at_noise_level(&out);
}

#[test]
fn hidden_mode_is_held_by_the_final_model() {
    let test = "hidden_mode_is_held_by_the_final_model";
    let Some(out) = diagnose(test, "wafer_hidden_mode.csv", ModeSelection::Count(17)) else {
        return;
    };
    let f_hidden = 520.4861640205804;
    let near = |f: f64| (f / f_hidden - 1.0).abs() <= 0.005;
    let in_loop = accepted(&out, "missed_mode")
        .iter()
        .any(|s| near(s.params["f_hz"].as_f64().unwrap()));
    let in_initial = out.summary.initial.modes.iter().any(|m| near(m.f_hz));
    println!("hidden mode: found by the loop {in_loop}, picked at once {in_initial}");
    assert!(in_loop || in_initial);
    assert!(out.summary.final_model.modes.iter().any(|m| near(m.f_hz)));
    assert_at_noise_level(&out);
}

#[test]
fn crosstalk_feedthrough_is_found() {
    let test = "crosstalk_feedthrough_is_found";
    let Some(out) = diagnose(test, "wafer_crosstalk.csv", ModeSelection::Auto) else {
        return;
    };
    assert!(
        !accepted(&out, "feedthrough").is_empty(),
        "a feedthrough step"
    );
    assert!(out.summary.final_model.feedthrough);
    assert_at_noise_level(&out);
}
