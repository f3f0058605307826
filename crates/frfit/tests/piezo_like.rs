//! Issue 41: the piezo-like case, simulated with a known answer
//! (`experiment::synth::piezo`): a `3 x 3` mechanism with a static gain, five modes in
//! the upper part of the band (635-2770 Hz), one sample of delay (156 us at 6400 Hz),
//! measured in open loop as time records (3 orthogonal experiments x 2 realizations x
//! 2 periods of 8192 samples, every line to 3 kHz: 3839 lines) with a stochastic
//! nonlinear contribution (3 % of `|P|`) well above the noise. The nonparametric
//! estimate carries the total variance (`_var`) and its noise part.
//!
//! `frfit fit` must end converged with every pole stable, near the best linear
//! approximation (the plant), in seconds; `frfit diagnose` must end no worse on the data
//! than `fit`. No hold is declared here (the estimate states the sample rate, as `frfit
//! nonparametric` does): the refined-IV iterations of both starts stop where no step
//! along their direction lowers the weighted cost, and the third start converges (`sk ->
//! ml` on seed 1, `subspace -> ml` on seed 2).

use experiment::nonparametric::EstimatorConfig;
use experiment::synth::{piezo_experiment, PiezoConfig, SimulationPath};
use frf_data::{Frf, FrfDataset};
use frfit::pipeline::PipelineConfig;
use frfit::run::run;

fn piezo_data(seed: u64) -> (Frf, Frf, f64) {
    let cfg = PiezoConfig {
        seed,
        ..Default::default()
    };
    let exp = piezo_experiment(&cfg).unwrap();
    let est = exp
        .estimate(SimulationPath::TimeDomain, &EstimatorConfig::default())
        .unwrap();
    let truth = exp.true_frf().unwrap();
    // the distortion against the noise, amplitude: sqrt(median total / median noise - 1)
    let mut t = est.total_variance.clone().unwrap();
    let mut n = est.noise_variance.clone().unwrap();
    t.sort_by(f64::total_cmp);
    n.sort_by(f64::total_cmp);
    let ratio = (t[t.len() / 2] / n[n.len() / 2] - 1.0).max(0.0).sqrt();
    // what `frfit nonparametric` writes in the CSV's comments (FORMATS.md)
    let mut frf = est.frf;
    frf.comments.push(format!(
        "periods={} realizations={} experiments={}",
        est.periods, est.realizations, est.n_experiments
    ));
    frf.comments
        .push(frfit::nonparametric::sampling_comment(6400.0));
    (frf, truth, ratio)
}

/// Median over lines and entries of `|P - G0| / |G0|`.
fn median_rel(resp: &realize::ResponseGrid, truth: &Frf) -> f64 {
    let m = truth.n_entries();
    let mut r: Vec<f64> = (0..truth.n_lines())
        .flat_map(|k| {
            let (p, g) = (resp.line(k), truth.line(k));
            (0..m)
                .map(|e| (p[e] - g[e]).norm() / g[e].norm())
                .collect::<Vec<_>>()
        })
        .collect();
    r.sort_by(f64::total_cmp);
    r[r.len() / 2]
}

#[test]
#[ignore = "slow tier (about 35 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn the_piezo_like_case_fits_converged_stable_near_the_plant_and_diagnose_is_no_worse() {
    for seed in [1, 2] {
        let (data, truth, ratio) = piezo_data(seed);
        println!(
            "seed {seed}: {} lines, distortion / noise (amplitude, median) {ratio:.1}",
            data.n_lines()
        );
        assert!(
            ratio > 5.0,
            "the case needs distortion well above the noise: {ratio}"
        );
        let t = std::time::Instant::now();
        let fit = run(&data, "piezo", &PipelineConfig::default(), "fit").unwrap();
        let fit_s = t.elapsed().as_secs_f64();
        let fm = &fit.summary.final_model;
        let unstable = fit.fit.model.unstable_submodels().len();
        let med = median_rel(&fit.final_response, &truth);
        println!(
            "  fit: {:.1} s, {} modes, convergence {}, unstable parts {unstable}, delay {:.1} us, \
             median |P - G0| / |G0| {med:.2e}, r {:.3}, e {:.4}",
            fit_s,
            fm.modes.len(),
            fm.convergence,
            1e6 * fm.delay_s,
            fit.summary.final_errors.residual_to_noise,
            fit.summary.final_errors.median_rel,
        );
        for m in &fit.fit.messages {
            println!("    fit: {m}");
        }
        let cfg = PipelineConfig {
            diagnose: true,
            ..Default::default()
        };
        let t = std::time::Instant::now();
        let dia = run(&data, "piezo", &cfg, "diagnose").unwrap();
        let d = &dia.summary;
        println!(
            "  diagnose: {:.1} s, {} modes, verdict {}, r {:.3}, e {:.4}, from fit: {}, accepted {:?}",
            t.elapsed().as_secs_f64(),
            d.final_model.modes.len(),
            d.verdict,
            d.final_errors.residual_to_noise,
            d.final_errors.median_rel,
            d.initial.from_fit.is_some(),
            d.steps
                .iter()
                .filter(|s| s.accepted)
                .map(|s| s.effect())
                .collect::<Vec<_>>()
        );
        let c = fm.convergence.to_ascii_lowercase();
        assert!(!c.contains("not converged") && !c.contains("failed"), "{c}");
        assert_eq!(unstable, 0, "every pole stable");
        assert!(
            med < 0.02,
            "median {med:.3e} from the best linear approximation"
        );
        let (rf, rd) = (
            fit.summary.final_errors.residual_to_noise,
            d.final_errors.residual_to_noise,
        );
        let (ef, ed) = (
            fit.summary.final_errors.median_rel,
            d.final_errors.median_rel,
        );
        assert!(
            rd <= 1.02 * rf || ed <= 1.02 * ef,
            "diagnose r {rd:.3} e {ed:.4} against fit r {rf:.3} e {ef:.4}"
        );
    }
}

/// `fit` on the piezo-like case of other seeds (other mode shapes, static gains, phases,
/// noise and distortion), from the estimate of its time records with the sample rate
/// stated and no hold declared, as `frfit nonparametric` writes it: converged, every
/// pole stable, the 5 modes of the plant and no more (the hold start keeps the
/// zero-order hold; without it 3 of these 6 seeds did not converge and the others spent
/// 6 to 10 modes on the hold's droop), near the plant.
#[test]
#[ignore = "slow tier (about 40 s on 2 cores): cargo test --workspace --release -- --ignored --skip known_failure"]
fn other_piezo_seeds_fit_converged_to_their_five_modes() {
    for seed in 3..=8 {
        let (data, truth, _) = piezo_data(seed);
        let t = std::time::Instant::now();
        let fit = run(&data, "piezo", &PipelineConfig::default(), "fit").unwrap();
        let fm = &fit.summary.final_model;
        let med = median_rel(&fit.final_response, &truth);
        println!(
            "seed {seed}: {:.1} s, {} modes, hold {}, delay {:.2} us, {}, median |P - G0| / |G0| \
             {med:.2e}, r {:.3}",
            t.elapsed().as_secs_f64(),
            fm.modes.len(),
            fm.hold,
            1e6 * fm.delay_s,
            fm.convergence,
            fit.summary.final_errors.residual_to_noise
        );
        let c = fm.convergence.to_ascii_lowercase();
        assert!(
            !c.contains("not converged") && !c.contains("failed"),
            "seed {seed}: {c}"
        );
        assert_eq!(fit.fit.model.unstable_submodels().len(), 0, "seed {seed}");
        assert_eq!(fm.modes.len(), 5, "seed {seed}: {:?}", fm.modes);
        assert!(med < 0.02, "seed {seed}: median {med:.3e}");
    }
}
