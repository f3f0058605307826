//! The wafer stage validated as a user would: a model fitted to the reference measurement
//! (`wafer_nominal.csv`), validated (Oomen-Bosgra, closed form) on a second measurement of
//! the same plant (its noiseless response plus a new complex Gaussian noise of the same
//! variance). The per-line uncertainty `gamma` must sit at the level of the model's true
//! error `sigma_max(P0 - P^)` where that error stands above the noise, and a model with
//! one mode removed must get a `gamma` at that mode of at least half the removed mode's
//! response there.

mod common;
use common::*;
use frf_data::shared_data::require;
use frf_data::{Frf, FrfDataset, ModelStructure, C64};
use frfit::additive_riv::{AdditiveModel, ModelFile};
use frfit::validation::{validate_frf, FrfValidationConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::ResponseGrid;

/// A second measurement: the noiseless response plus complex Gaussian noise of the
/// reference file's variance (Box-Muller), with that variance.
fn second_measurement(clean: &Frf, var: &[f64], seed: u64) -> Frf {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut gauss = || {
        let (u1, u2): (f64, f64) = (rng.random_range(f64::EPSILON..1.0), rng.random());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let values: Vec<C64> = clean
        .values()
        .iter()
        .zip(var)
        .map(|(g, v)| g + C64::new(gauss(), gauss()) * (v / 2.0).sqrt())
        .collect();
    Frf::new(
        clean.freq_hz_slice().to_vec(),
        clean.ny(),
        clean.nu(),
        values,
        Some(var.to_vec()),
    )
    .unwrap()
}

fn sigma_max(m: faer::Mat<C64>) -> f64 {
    m.singular_values().unwrap()[0]
}

#[test]
fn gamma_follows_the_true_error_and_finds_a_removed_mode() {
    let test = "gamma_follows_the_true_error_and_finds_a_removed_mode";
    let (Some(data), Some(clean_path)) = (
        require(test, "wafer_nominal.csv"),
        require(test, "wafer_nominal.noiseless.csv"),
    ) else {
        return;
    };
    let dir = temp_dir("wafer-validation");
    let model_path = dir.join("m.json");
    let o = run(&[
        "fit",
        data.to_str().unwrap(),
        "--band",
        "20:2000",
        "--out",
        model_path.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let model: AdditiveModel = ModelFile::read(&model_path).unwrap().to_model().unwrap();

    // the fitted band, with the variance (`FrfDataset::to_frf` copies it)
    let band = |f: &Frf| f.band(20.0, 2000.0).unwrap().to_frf();
    let measured = band(&frf_data::io::read_frf_csv(&data).unwrap());
    let clean = band(&frf_data::io::read_frf_csv(&clean_path).unwrap());
    let var = measured
        .variance_vec()
        .expect("the reference file has _var columns");
    let validation = second_measurement(&clean, &var, 7);
    let omega = validation.omegas();
    let cfg = FrfValidationConfig::default();

    // 1. the fitted model is at the noise floor: the uncertainty explains no more than
    // the true error (gamma <= sigma_max(P0 - P^)) wherever every column's disturbance
    // bound holds, which each does with probability alpha: so at all but a fraction
    // 1 - alpha^nu of the lines (12 % for 13 inputs at alpha = 0.99)
    let p_hat: ResponseGrid = model.response_at(&omega);
    let v = validate_frf(&p_hat, &validation, None, &cfg).unwrap();
    let true_err = |p: &ResponseGrid, k: usize| {
        sigma_max(faer::Mat::from_fn(clean.ny(), clean.nu(), |i, j| {
            clean.value(k, i, j) - p.get(k, i, j)
        }))
    };
    let above = (0..v.lines.len())
        .filter(|&k| v.lines[k].gamma > true_err(&p_hat, k) * (1.0 + 1e-9))
        .count();
    println!(
        "fitted model: gamma max {:.3e}, median {:.3e}; gamma above the true error at {above} of {} lines",
        v.gamma_max,
        v.gamma_median,
        v.lines.len()
    );
    let allowed = 1.0 - cfg.alpha.powi(clean.nu() as i32);
    assert!(
        (above as f64) <= allowed * v.lines.len() as f64,
        "gamma above the true error at {above} lines (allowed fraction {allowed:.3})"
    );

    // 2. one mode removed: gamma at its frequency is at least half its response there
    let modes = model.modes();
    let target = &modes[modes.len() / 2];
    let mut reduced = model.clone();
    reduced.remove_submodel(target.submodel);
    let k0 = (0..omega.len())
        .min_by(|&a, &b| {
            (validation.freq_hz(a) - target.f_hz)
                .abs()
                .total_cmp(&(validation.freq_hz(b) - target.f_hz).abs())
        })
        .unwrap();
    let p_red = reduced.response_at(&omega);
    let removed = sigma_max(faer::Mat::from_fn(clean.ny(), clean.nu(), |i, j| {
        p_hat.get(k0, i, j) - p_red.get(k0, i, j)
    }));
    let vr = validate_frf(&p_red, &validation, None, &cfg).unwrap();
    let g = vr.lines[k0].gamma;
    println!(
        "mode at {:.2} Hz removed: gamma there {g:.3e}, the removed mode's response {removed:.3e}",
        target.f_hz
    );
    assert!(g >= 0.5 * removed, "gamma {g:.3e} < half of {removed:.3e}");

    // 3. where the reduced model's true error stands above the noise (around the removed
    // mode), gamma is at its level: within a factor 3 at 90 % of those lines
    let (mut checked, mut within) = (0usize, 0usize);
    for (k, line) in vr.lines.iter().enumerate() {
        let e = true_err(&p_red, k);
        if e > 3.0 * line.disturbance_bound {
            checked += 1;
            if (e / 3.0..=3.0 * e).contains(&line.gamma) {
                within += 1;
            }
        }
    }
    println!(
        "reduced model: {checked} lines with the true error above 3x the disturbance bound, {within} with gamma within a factor 3 of it"
    );
    assert!(checked >= 10, "only {checked} lines above the noise");
    assert!(
        within as f64 >= 0.9 * checked as f64,
        "{within} of {checked} lines within a factor 3"
    );
}
