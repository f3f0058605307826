//! Monte Carlo calibration of the reported uncertainty: one 2 x 2 plant with 3 modes on
//! 400 lines, 50 noise realisations with a known variance (circular complex Gaussian,
//! 0.1 % of `|G|`). For every mode, the spread of the estimates of the natural frequency
//! and of the damping over the realisations must be within 25 % of the median standard
//! deviation the refinement predicts (McKelvey eq. (32) with the true noise model, the
//! Cramer-Rao bound), and the truth must lie inside the 95 % interval
//! `estimate +- 1.96 std` in 90-99 % of the cases, pooled over modes and both
//! quantities.

mod common;
use common::*;
use frf_data::{ChainModel, Estimator, FrfDataset};
use ml_refine::MlRefine;

#[test]
fn predicted_standard_deviations_match_the_monte_carlo_spread() {
    let truth = system(11, 2, 2, 3, false, false);
    let n_modes = truth.modal.pairs.len();
    let seeds = 50;
    // per mode: estimates and predicted std of (f, zeta)
    let mut f_est = vec![Vec::new(); n_modes];
    let mut z_est = vec![Vec::new(); n_modes];
    let mut f_std = vec![Vec::new(); n_modes];
    let mut z_std = vec![Vec::new(); n_modes];
    let mut inside = 0usize;
    let mut cases = 0usize;
    let mut ratios = Vec::new();
    for s in 0..seeds {
        let d = data(&truth, 400, 1e-3, 1000 + s);
        let start = perturbed(&truth, 0.002, 0.1, s);
        let fit = MlRefine::default()
            .estimate(&d, ChainModel::from(start))
            .unwrap();
        assert!(
            fit.convergence.is_converged(),
            "seed {s}: {:?}",
            fit.convergence
        );
        ratios.push(fit.report.cost_ratio);
        for (q, (m, t)) in fit.report.modes.iter().zip(&truth.modal.pairs).enumerate() {
            f_est[q].push(m.f_hz);
            z_est[q].push(m.zeta);
            f_std[q].push(m.f_hz_std);
            z_std[q].push(m.zeta_std);
            for (est, sd, tv) in [
                (m.f_hz, m.f_hz_std, t.f_hz()),
                (m.zeta, m.zeta_std, t.zeta()),
            ] {
                cases += 1;
                if (est - tv).abs() <= 1.959_964 * sd {
                    inside += 1;
                }
            }
        }
    }
    let spread = |v: &[f64]| {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let median = |v: &[f64]| {
        let mut w = v.to_vec();
        w.sort_by(|a, b| a.total_cmp(b));
        w[w.len() / 2]
    };
    let coverage = inside as f64 / cases as f64;
    ratios.sort_by(|a, b| a.total_cmp(b));
    println!(
        "coverage of the 95 % intervals: {inside}/{cases} = {coverage:.3}; cost ratio median {:.4}",
        ratios[ratios.len() / 2]
    );
    for q in 0..n_modes {
        let (sf, mf) = (spread(&f_est[q]), median(&f_std[q]));
        let (sz, mz) = (spread(&z_est[q]), median(&z_std[q]));
        println!(
            "mode {q} ({:.2} Hz, zeta {:.4}): f spread {sf:.3e} vs predicted {mf:.3e} (ratio {:.3}); zeta spread {sz:.3e} vs predicted {mz:.3e} (ratio {:.3})",
            truth.modal.pairs[q].f_hz(),
            truth.modal.pairs[q].zeta(),
            sf / mf,
            sz / mz
        );
        assert!(
            (sf / mf - 1.0).abs() <= 0.25,
            "mode {q}: f spread {sf:.3e}, predicted {mf:.3e}"
        );
        assert!(
            (sz / mz - 1.0).abs() <= 0.25,
            "mode {q}: zeta spread {sz:.3e}, predicted {mz:.3e}"
        );
    }
    assert!((0.90..=0.99).contains(&coverage), "coverage {coverage:.3}");
}

/// Without a variance the criterion is weighted least squares (here eq. (27), `1/|G|^2`,
/// which for noise proportional to `|G|` is the inverse variance up to a scale) and the
/// noise scale comes from the residual: the standard deviations agree with those of the
/// ML fit with the measured variance.
#[test]
fn noise_scale_from_the_residual_gives_the_same_uncertainty() {
    let truth = system(11, 2, 2, 3, false, false);
    let d = data(&truth, 400, 1e-3, 77);
    let bare = frf_data::Frf::new(
        d.freq_hz_slice().to_vec(),
        d.ny(),
        d.nu(),
        d.values().to_vec(),
        None,
    )
    .unwrap();
    let start = perturbed(&truth, 0.002, 0.1, 77);
    let ml = MlRefine::default()
        .estimate(&d, ChainModel::from(start.clone()))
        .unwrap();
    let wls = MlRefine::default()
        .estimate(&bare, ChainModel::from(start))
        .unwrap();
    assert_eq!(wls.report.noise, "estimated from the residual");
    assert!(wls.report.p_value.is_none());
    println!(
        "noise scale from the residual: {:.3e} (relative noise 1e-3)",
        wls.report.covariance_scale.sqrt()
    );
    for (a, b) in ml.report.modes.iter().zip(&wls.report.modes) {
        println!(
            "f std {:.3e} vs {:.3e}, zeta std {:.3e} vs {:.3e}",
            a.f_hz_std, b.f_hz_std, a.zeta_std, b.zeta_std
        );
        assert!(
            (a.f_hz_std / b.f_hz_std - 1.0).abs() < 0.1,
            "{a:?} vs {b:?}"
        );
        assert!(
            (a.zeta_std / b.zeta_std - 1.0).abs() < 0.1,
            "{a:?} vs {b:?}"
        );
    }
}
