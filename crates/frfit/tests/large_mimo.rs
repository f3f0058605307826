//! A plant with more states than the subspace initialiser's default order cap (60): a
//! random 6 x 6 modal plant with 40 rank-one modes (80 states, 10 % close pairs) from
//! `frfit simulate random-modal`'s generator. `--init subspace` finds every mode from
//! the singular values alone (the cap is doubled while all singular values up to it
//! stand above the noise), without peak picking.

use experiment::synth::{RandomModal, RandomModalConfig};
use frf_data::{ChainSettings, DelayChoice, FrfDataset};
use frfit::chain::{run_chain, AdditiveOptions};

/// Modes of `fit` within `tol` (relative) of a true one, matched one-to-one, nearest
/// first.
fn found(true_f: &[f64], fit_f: &[f64], tol: f64) -> usize {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, &t) in true_f.iter().enumerate() {
        for (j, &f) in fit_f.iter().enumerate() {
            let d = (f - t).abs() / t;
            if d <= tol {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut ut, mut uf, mut n) = (vec![false; true_f.len()], vec![false; fit_f.len()], 0);
    for (_, i, j) in pairs {
        if !ut[i] && !uf[j] {
            ut[i] = true;
            uf[j] = true;
            n += 1;
        }
    }
    n
}

#[test]
fn subspace_finds_all_modes_beyond_the_default_order_cap() {
    faer::set_global_parallelism(faer::Par::Seq);
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 6,
        nu: 6,
        modes: 40,
        lines: 1500,
        noise: 1e-4,
        seed: 3,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let settings = ChainSettings {
        delay: DelayChoice::None,
        ..Default::default()
    };
    let out = run_chain(
        &r.measured,
        "subspace",
        "none",
        &settings,
        &AdditiveOptions::default(),
    )
    .unwrap();
    let model = &out.model.model;
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let fit_f: Vec<f64> = model.modal.pairs.iter().map(|p| p.f_hz()).collect();
    let n = found(&true_f, &fit_f, 1e-3);
    let w = r.noiseless.omegas();
    let g = realize::ResponseGrid {
        ny: 6,
        nu: 6,
        values: r.noiseless.values_vec(),
    };
    let (median, _) = model.relative_error(&w, &g).unwrap();
    println!(
        "{n}/40 modes within 0.1 %, {} fitted, median error {median:.3e} vs noiseless (noise 1e-4)",
        fit_f.len()
    );
    assert_eq!(n, 40, "modes found: {fit_f:?}");
    assert_eq!(fit_f.len(), 40);
    assert!(median < 1e-3, "median error {median:.3e}");
}

/// The chain at scale: `subspace -> ml` on a random 12 x 12 plant with 30 modes and a
/// rigid body at 1e-3 relative noise (with the variance). The ML refinement shares one
/// factorisation among all 144 entries (one noise level), drops the poles the subspace
/// step fitted to noise and adds back a mode it merged; every mode ends within 0.1 %,
/// the cost at the noise level, and the error against the noiseless response below
/// the subspace start's.
#[test]
fn subspace_then_ml_finds_every_mode_at_the_noise_level() {
    faer::set_global_parallelism(faer::Par::Seq);
    let r = RandomModal::generate(&RandomModalConfig {
        ny: 12,
        nu: 12,
        modes: 30,
        lines: 1500,
        noise: 1e-3,
        rigid_body: true,
        seed: 5,
        ..RandomModalConfig::default()
    })
    .unwrap();
    let settings = ChainSettings {
        delay: DelayChoice::None,
        ..Default::default()
    };
    let opts = AdditiveOptions::default();
    let start = run_chain(&r.measured, "subspace", "none", &settings, &opts).unwrap();
    let out = run_chain(&r.measured, "subspace", "ml", &settings, &opts).unwrap();
    let w = r.noiseless.omegas();
    let g = realize::ResponseGrid {
        ny: 12,
        nu: 12,
        values: r.noiseless.values_vec(),
    };
    let (median0, _) = start.model.model.relative_error(&w, &g).unwrap();
    let model = &out.model.model;
    let true_f: Vec<f64> = r.plant.modes.iter().map(|m| m.f_hz).collect();
    let fit_f: Vec<f64> = model.modal.pairs.iter().map(|p| p.f_hz()).collect();
    let n = found(&true_f, &fit_f, 1e-3);
    let (median, _) = model.relative_error(&w, &g).unwrap();
    let last = out.links.last().unwrap();
    println!(
        "{n}/30 modes within 0.1 %, {} fitted, median error {median:.3e} vs noiseless (start {median0:.3e}, noise 1e-3); {}",
        fit_f.len(),
        last.convergence.describe()
    );
    assert!(
        last.convergence.is_converged(),
        "{}",
        last.convergence.describe()
    );
    assert_eq!(n, 30, "modes found: {fit_f:?}");
    assert!(median < 1e-3, "median error {median:.3e}");
    assert!(
        median < median0,
        "{median:.3e} vs the start's {median0:.3e}"
    );
}
