//! Each effect signature on a synthetic residual: a known model (the nominal system of
//! `common`) with one effect injected into the "measured" data, the nominal model's
//! response as the model, simulated noise with known variance. The injected effect must
//! be flagged (and be the strongest evidence) with the right parameters; the other
//! effects must not be flagged. On a pure-noise residual nothing may be significant in
//! at least 19 of 20 seeds.

mod common;

use common::*;
use faer::Mat;
use frf_data::{Frf, FrfDataset, C64};
use realize::{ModalModel, PolePair, ResponseGrid};
use std::f64::consts::TAU;
use validation::{
    analyze_residual, noise_level, Effect, ResidualAnalysis, ResidualConfig, TrendClass,
};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Noise {
    /// Independent, exact variance.
    Exact,
    /// Correlated across entries, variance from 10 realizations.
    Measured,
}

fn noisy(f: &[f64], g: &ResponseGrid, kind: Noise, seed: u64) -> Frf {
    match kind {
        Noise::Exact => add_noise(f, g, REL, seed),
        Noise::Measured => add_measured_noise(f, g, REL, 10, seed),
    }
}

fn analyze(data: &Frf, model: &ResponseGrid, cfg: &ResidualConfig) -> ResidualAnalysis {
    let noise = noise_level(data).unwrap();
    analyze_residual(data, model, &noise, cfg).unwrap()
}

fn flagged(a: &ResidualAnalysis) -> Vec<Effect> {
    a.evidence
        .iter()
        .filter(|e| e.significant)
        .map(|e| e.effect)
        .collect()
}

fn summary(name: &str, a: &ResidualAnalysis) {
    println!(
        "{name}: r/n {:.2}, excess ratio {:.1}, trend {:?} (slope {:.2}, low {:.2} high {:.2}), \
         flagged {:?}",
        a.residual_to_noise,
        a.significance.excess_ratio,
        a.magnitude_trend.class,
        a.magnitude_trend.slope_per_decade,
        a.magnitude_trend.low_ratio,
        a.magnitude_trend.high_ratio,
        flagged(a)
    );
    for e in &a.evidence {
        println!(
            "    {:?}: explains {:.3} {} {}",
            e.effect,
            e.explained_fraction,
            if e.significant { "FLAGGED" } else { "-" },
            e.detail
        );
    }
}

/// The injected effect is the only flagged one and the strongest evidence.
fn assert_only(a: &ResidualAnalysis, effect: Effect) {
    assert!(a.significant, "residual not significant");
    assert_eq!(flagged(a), vec![effect], "flagged: {:?}", flagged(a));
    assert_eq!(a.evidence[0].effect, effect);
}

fn cfg() -> ResidualConfig {
    ResidualConfig::default()
}

#[test]
fn pure_noise_nothing_significant_in_19_of_20_seeds() {
    let f = freqs();
    let p = response(&nominal(), &f);
    for kind in [Noise::Exact, Noise::Measured] {
        let mut false_alarms = 0;
        let mut worst_excess: f64 = 0.0;
        for seed in 0..20 {
            let data = noisy(&f, &p, kind, 1000 + seed);
            let a = analyze(&data, &p, &cfg());
            worst_excess = worst_excess.max(a.significance.excess_ratio);
            let any_flag = !flagged(&a).is_empty();
            if a.significant || any_flag || a.residual_cmif.iter().any(|p| p.significant) {
                false_alarms += 1;
                summary(&format!("{kind:?} seed {seed} (false alarm)"), &a);
            }
            assert_eq!(
                a.magnitude_trend.class == TrendClass::NoiseLevel,
                !a.significant
            );
            assert!(a.concentration.dominant_row.is_none() || a.significant);
            if kind == Noise::Exact {
                // Exact variances: the ratio is 1 within the sampling error.
                assert!(
                    (a.residual_to_noise - 1.0).abs() < 0.02,
                    "{}",
                    a.residual_to_noise
                );
            }
        }
        println!(
            "{kind:?} noise: {false_alarms} of 20 seeds significant; largest excess ratio \
             {worst_excess:.4}"
        );
        assert!(false_alarms <= 1, "{kind:?}: {false_alarms} false alarms");
    }
}

#[test]
fn calibration_of_measured_like_noise() {
    // Correlated entries and variances from 10 realizations: fewer effective degrees of
    // freedom per line than 2m and a mean noise energy per entry near 9/8.
    let f = freqs();
    let p = response(&nominal(), &f);
    let data = noisy(&f, &p, Noise::Measured, 5);
    let a = analyze(&data, &p, &cfg());
    let s = &a.significance;
    println!(
        "measured-like noise: nu {:.1} of {}, kappa {:.3}, excess ratio {:.4}, p {:.3}",
        s.line_dof,
        2 * NY * NU,
        s.noise_scale,
        s.excess_ratio,
        s.p_value
    );
    assert!(s.line_dof < 2.0 * (NY * NU) as f64 * 0.9, "{}", s.line_dof);
    assert!((1.0..1.3).contains(&s.noise_scale), "{}", s.noise_scale);
    assert!(!s.noise_scale_capped);
    assert!(!a.significant);
}

#[test]
fn delay_signature() {
    let f = freqs();
    let w = omegas(&f);
    let p = response(&nominal(), &f);
    for (d, kind) in [
        (20e-6, Noise::Exact),
        (20e-6, Noise::Measured),
        (-8e-6, Noise::Exact),
        (1e-6, Noise::Exact),
    ] {
        let mut g = p.clone();
        scale_lines(&mut g, |k| C64::from_polar(1.0, -w[k] * d));
        let a = analyze(&noisy(&f, &g, kind, 21), &p, &cfg());
        summary(&format!("delay {} us, {kind:?}", d * 1e6), &a);
        let t = &a.phase_trend;
        println!(
            "    delay {:.5} us +- {:.5} (linear {:.5}), z {:.0}",
            t.delay_s * 1e6,
            t.std_s * 1e6,
            t.linear_delay_s * 1e6,
            t.z
        );
        assert_only(&a, Effect::Delay);
        assert!(
            (t.delay_s - d).abs() < 1e-3 * d.abs() + 5.0 * t.std_s,
            "{}",
            t.delay_s
        );
        assert_eq!(t.delay_s > 0.0, d > 0.0);
        assert!(t.fit.explained_fraction > 0.95);
        assert_eq!(a.magnitude_trend.class, TrendClass::HighFrequency);
    }
}

#[test]
fn hold_signature() {
    let f = freqs();
    let model = nominal();
    let p = response(&model, &f);
    let fs = 5000.0;
    // The exact zero-order-hold response (droop and aliasing) with the hold's
    // half-sample delay compensated, as the pipeline's delay compensation leaves it.
    let g = model.zoh_response(&omegas(&f), 1.0 / fs, -0.5).unwrap();
    for kind in [Noise::Exact, Noise::Measured] {
        let cfg = ResidualConfig {
            sample_rate_hz: Some(fs),
            ..cfg()
        };
        let a = analyze(&noisy(&f, &g, kind, 31), &p, &cfg);
        summary(&format!("hold at {fs} Hz, {kind:?}"), &a);
        let h = a.hold.as_ref().unwrap();
        println!(
            "    amplitude {:.4} +- {:.5}, correlation {:.4}, imag fraction {:.4}, apparent fs {:?}",
            h.amplitude, h.amplitude_std, h.correlation, h.imag_fraction, h.apparent_fs_hz
        );
        assert_only(&a, Effect::Hold);
        assert!(h.consistent);
        assert!((h.amplitude - 1.0).abs() < 0.15, "{}", h.amplitude);
        assert!(h.correlation > 0.98, "{}", h.correlation);
        assert!(h.imag_fraction < 0.05, "{}", h.imag_fraction);
        let afs = h.apparent_fs_hz.unwrap();
        assert!((afs / fs - 1.0).abs() < 0.08, "{afs}");
        // A wrong sample rate gives a wrong amplitude (not 'consistent').
        let wrong = validation::hold_signature(
            &validation::Residual::new(&noisy(&f, &g, kind, 31), &p, &noise_of(&g, &f, kind), &cfg)
                .unwrap(),
            2.0 * fs,
        );
        assert!(
            !wrong.consistent && wrong.amplitude > 3.0,
            "{}",
            wrong.amplitude
        );
    }
}

fn noise_of(g: &ResponseGrid, f: &[f64], kind: Noise) -> validation::NoiseLevel {
    noise_level(&noisy(f, g, kind, 31)).unwrap()
}

#[test]
fn feedthrough_signature() {
    let f = freqs();
    let p = response(&nominal(), &f);
    let wmax = TAU * 1000.0;
    // A real constant of about 2 % of the plant's level at 1 kHz (18 noise standard
    // deviations there).
    let d: Vec<f64> = (0..NY * NU)
        .map(|e| 0.02 * rigid_rms() / (wmax * wmax) * (((e * 7) % 5) as f64 - 2.0))
        .collect();
    let m = NY * NU;
    let mut g = p.clone();
    for k in 0..f.len() {
        for e in 0..m {
            g.values[k * m + e] += d[e];
        }
    }
    for kind in [Noise::Exact, Noise::Measured] {
        let a = analyze(&noisy(&f, &g, kind, 41), &p, &cfg());
        summary(&format!("feedthrough, {kind:?}"), &a);
        assert_only(&a, Effect::Feedthrough);
        let ft = &a.feedthrough;
        let err: f64 =
            ft.d.iter()
                .zip(&d)
                .map(|(x, y)| (x - y).norm_sqr())
                .sum::<f64>()
                .sqrt();
        let norm: f64 = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        println!(
            "    |D_fit - D| / |D| = {:.4}, real fraction {:.4}",
            err / norm,
            ft.real_fraction
        );
        assert!(err / norm < 0.05);
        assert!(ft.real_fraction > 0.99);
        assert_eq!(a.magnitude_trend.class, TrendClass::HighFrequency);
    }
}

#[test]
fn missed_mode_signature() {
    let f = freqs();
    let model = nominal();
    let p = response(&model, &f);
    let mut truth = model.clone();
    let (fm, zm) = (330.0, 0.012);
    let num = Mat::from_fn(NY, NU, |i, j| {
        0.3 * [0.9, -1.2, 0.5][i] * [1.1, 0.4, -0.8, 1.3][j]
    });
    truth.pairs.push(PolePair::from_second_order(fm, zm, &num));
    let g = response(&truth, &f);
    for kind in [Noise::Exact, Noise::Measured] {
        let a = analyze(&noisy(&f, &g, kind, 51), &p, &cfg());
        summary(&format!("missed mode at {fm} Hz, {kind:?}"), &a);
        let pk = a.residual_cmif.iter().find(|p| p.significant).unwrap();
        println!(
            "    peak {:.3} Hz (sigma_{}), {:.1} dB over the noise, rise {:.0}, damping {:?}",
            pk.f_hz,
            pk.sv_index + 1,
            10.0 * pk.height_over_noise.log10(),
            pk.relative_rise,
            pk.damping
        );
        assert_only(&a, Effect::MissedMode);
        assert!((pk.f_hz / fm - 1.0).abs() < 0.005, "{}", pk.f_hz);
        assert_eq!(pk.sv_index, 0);
        if let Some(z) = pk.damping {
            assert!((z / zm - 1.0).abs() < 0.3, "{z}");
        }
        assert_eq!(
            a.residual_cmif.iter().filter(|p| p.significant).count(),
            1,
            "{:?}",
            a.residual_cmif
        );
        assert_eq!(a.magnitude_trend.class, TrendClass::Localized);
    }
}

/// `G` with a first-order factor `1 / (1 + j w tau)` on input column `j` (`col`) or
/// output row `i`.
fn with_factor(p: &ResponseGrid, f: &[f64], index: usize, col: bool, pole_hz: f64) -> ResponseGrid {
    let tau = 1.0 / (TAU * pole_hz);
    let mut g = p.clone();
    for (k, &fk) in f.iter().enumerate() {
        let fac = C64::new(1.0, TAU * fk * tau).inv();
        for e in 0..NY * NU {
            let (i, j) = (e % NY, e / NY);
            if (col && j == index) || (!col && i == index) {
                g.values[k * NY * NU + e] *= fac;
            }
        }
    }
    g
}

#[test]
fn actuator_signature() {
    let f = freqs();
    let p = response(&nominal(), &f);
    let (col, pole) = (2, 800.0);
    let g = with_factor(&p, &f, col, true, pole);
    for kind in [Noise::Exact, Noise::Measured] {
        let a = analyze(&noisy(&f, &g, kind, 61), &p, &cfg());
        summary(
            &format!("actuator pole {pole} Hz on input {}, {kind:?}", col + 1),
            &a,
        );
        let io = &a.input_dynamics[col];
        println!(
            "    column fractions {:?}, tau {:.4e} +- {:.1e} s, pole {:.1} Hz",
            a.concentration
                .col_fraction
                .iter()
                .map(|x| (x * 1000.0).round() / 1000.0)
                .collect::<Vec<_>>(),
            io.tau_s,
            io.tau_std_s,
            io.pole_hz
        );
        assert_only(&a, Effect::InputDynamics);
        assert_eq!(a.concentration.dominant_col, Some(col));
        assert!(a.concentration.dominant_row.is_none());
        assert!((io.pole_hz / pole - 1.0).abs() < 0.02, "{}", io.pole_hz);
        assert!(io.fit.significant);
        assert!(a
            .input_dynamics
            .iter()
            .filter(|x| x.index != col)
            .all(|x| !x.fit.significant));
    }
}

#[test]
fn sensor_signature() {
    let f = freqs();
    let p = response(&nominal(), &f);
    let (row, pole) = (1, 600.0);
    let g = with_factor(&p, &f, row, false, pole);
    for kind in [Noise::Exact, Noise::Measured] {
        let a = analyze(&noisy(&f, &g, kind, 71), &p, &cfg());
        summary(
            &format!("sensor pole {pole} Hz on output {}, {kind:?}", row + 1),
            &a,
        );
        let io = &a.output_dynamics[row];
        println!(
            "    row fractions {:?}, tau {:.4e} s, pole {:.1} Hz",
            a.concentration.row_fraction, io.tau_s, io.pole_hz
        );
        assert_only(&a, Effect::OutputDynamics);
        assert_eq!(a.concentration.dominant_row, Some(row));
        assert!(a.concentration.dominant_col.is_none());
        assert!((io.pole_hz / pole - 1.0).abs() < 0.02, "{}", io.pole_hz);
    }
}

/// `G` with `factor(f)` on the entries `on(i, j)` selects.
fn with_dynamics(
    p: &ResponseGrid,
    f: &[f64],
    on: impl Fn(usize, usize) -> bool,
    factor: impl Fn(f64) -> C64,
) -> ResponseGrid {
    let mut g = p.clone();
    for (k, &fk) in f.iter().enumerate() {
        let h = factor(fk);
        for e in 0..NY * NU {
            if on(e % NY, e / NY) {
                g.values[k * NY * NU + e] *= h;
            }
        }
    }
    g
}

/// A first-order lag common to every entry (an amplifier's bandwidth): the common
/// factor's template finds its corner and explains more than the delay template.
#[test]
fn common_lag_signature() {
    let f = freqs();
    let p = response(&nominal(), &f);
    let pole = 700.0;
    let g = with_dynamics(&p, &f, |_, _| true, |fk| C64::new(1.0, fk / pole).inv());
    for kind in [Noise::Exact, Noise::Measured] {
        let a = analyze(&noisy(&f, &g, kind, 83), &p, &cfg());
        summary(&format!("common lag at {pole} Hz, {kind:?}"), &a);
        let c = &a.common_dynamics;
        assert!((c.pole_hz / pole - 1.0).abs() < 0.02, "{}", c.pole_hz);
        assert!(c.fit.significant);
        assert!(c.fit.explained_fraction > 0.95);
        assert!(c.fit.explained_fraction > a.phase_trend.fit.explained_fraction);
        assert_eq!(flagged(&a)[0], Effect::InputDynamics);
        let band = (f[0], f[f.len() - 1]);
        assert_eq!(c.order(a.significance.line_scale, 0.01, band), 1);
    }
}

/// A sensor-mount resonance `w^2 / (s^2 + 2 zeta w s + w^2)` on one output row, inside
/// the band and above it: the row's second-order template finds its frequency and
/// damping, and the order test prefers it to the first-order lag.
#[test]
fn second_order_sensor_signature() {
    let f = freqs();
    let p = response(&nominal(), &f);
    let row = 2;
    for (f0, zeta) in [(420.0, 0.03), (1400.0, 0.05)] {
        let g = with_dynamics(
            &p,
            &f,
            |i, _| i == row,
            |fk| {
                let x = fk / f0;
                C64::new(1.0 - x * x, 2.0 * zeta * x).inv()
            },
        );
        for kind in [Noise::Exact, Noise::Measured] {
            let a = analyze(&noisy(&f, &g, kind, 97), &p, &cfg());
            summary(
                &format!(
                    "resonance {f0} Hz zeta {zeta} on output {}, {kind:?}",
                    row + 1
                ),
                &a,
            );
            let io = &a.output_dynamics[row];
            let so = &io.second_order;
            println!(
                "    second order {:.2} Hz zeta {:.4}, explains {:.3} (first order {:.3})",
                so.f_hz, so.zeta, so.fit.explained_fraction, io.fit.explained_fraction
            );
            assert_eq!(a.concentration.dominant_row, Some(row));
            assert!((so.f_hz / f0 - 1.0).abs() < 0.01, "{}", so.f_hz);
            assert!((so.zeta / zeta - 1.0).abs() < 0.1, "{}", so.zeta);
            assert!(so.fit.significant);
            let band = (f[0], f[f.len() - 1]);
            assert_eq!(io.order(a.significance.line_scale, 0.01, band), 2);
            assert!(a
                .output_dynamics
                .iter()
                .filter(|x| x.index != row)
                .all(|x| !x.fit.significant && !x.second_order.fit.significant));
        }
    }
}

#[test]
fn stiffness_signature() {
    let f = freqs();
    let model = nominal();
    let p = response(&model, &f);
    let (f0, z0) = (2.0, 0.05);
    let mut truth: ModalModel = model.clone();
    let r = truth.rigid[1].clone();
    truth.rigid.clear();
    truth.pairs.push(PolePair::from_second_order(f0, z0, &r));
    let g = response(&truth, &f);
    for kind in [Noise::Exact, Noise::Measured] {
        let a = analyze(&noisy(&f, &g, kind, 81), &p, &cfg());
        summary(
            &format!("stiffness {f0} Hz instead of a free body, {kind:?}"),
            &a,
        );
        let s = &a.stiffness;
        let gmean = s.gains.iter().sum::<f64>() / s.gains.len() as f64;
        println!(
            "    f0 {:.4} Hz, zeta {:.4}, mean gain {gmean:.3}, equivalent {:.4} Hz",
            s.f_hz, s.zeta, s.equivalent_f_hz
        );
        // The suspension inside the band is also a resonance the model lacks, so the
        // missed-mode template may be flagged at it too; but the stiffness explains the
        // residual (the free body's 1/s^2 below f0 as well) and ranks first.
        assert!(a.significant);
        assert_eq!(a.evidence[0].effect, Effect::Stiffness);
        assert!(a.stiffness.fit.significant && s.fit.explained_fraction > 0.99);
        for e in a.evidence.iter().skip(1) {
            assert!(
                !e.significant
                    || (e.effect == Effect::MissedMode
                        && e.explained_fraction < s.fit.explained_fraction - 0.2),
                "{e:?}"
            );
        }
        assert!((s.f_hz / f0 - 1.0).abs() < 0.05, "{}", s.f_hz);
        assert!((s.zeta / z0 - 1.0).abs() < 0.3, "{}", s.zeta);
        assert_eq!(a.magnitude_trend.class, TrendClass::LowFrequency);
    }
}

#[test]
fn stiffness_below_the_band() {
    // A suspension below the lowest line: only the tail (w0 / w)^2 is seen; the
    // equivalent frequency is still right.
    let f: Vec<f64> = freqs().into_iter().filter(|x| *x >= 2.0).collect();
    let model = nominal();
    let p = response(&model, &f);
    let f0 = 0.5;
    let mut truth = model.clone();
    let r = truth.rigid[1].clone();
    truth.rigid.clear();
    truth.pairs.push(PolePair::from_second_order(f0, 0.05, &r));
    let g = response(&truth, &f);
    let a = analyze(&noisy(&f, &g, Noise::Exact, 82), &p, &cfg());
    summary("stiffness 0.5 Hz below a band from 2 Hz", &a);
    println!(
        "    f0 {:.4} Hz, equivalent {:.4} Hz",
        a.stiffness.f_hz, a.stiffness.equivalent_f_hz
    );
    assert_only(&a, Effect::Stiffness);
    assert!((a.stiffness.equivalent_f_hz / f0 - 1.0).abs() < 0.15);
}

#[test]
fn two_effects_rank_by_explained_energy() {
    // A delay and a missed mode together: both flagged, the loop gets both.
    let f = freqs();
    let w = omegas(&f);
    let model = nominal();
    let p = response(&model, &f);
    let mut truth = model.clone();
    let num = Mat::from_fn(NY, NU, |i, j| {
        0.3 * [0.9, -1.2, 0.5][i] * [1.1, 0.4, -0.8, 1.3][j]
    });
    truth
        .pairs
        .push(PolePair::from_second_order(330.0, 0.012, &num));
    let mut g = response(&truth, &f);
    scale_lines(&mut g, |k| C64::from_polar(1.0, -w[k] * 3e-6));
    let a = analyze(&noisy(&f, &g, Noise::Exact, 91), &p, &cfg());
    summary("delay 3 us and a missed mode", &a);
    let fl = flagged(&a);
    assert!(fl.contains(&Effect::MissedMode), "{fl:?}");
    assert!(
        fl.contains(&Effect::Delay) || a.phase_trend.z > 10.0,
        "{fl:?}"
    );
}

#[test]
fn summary_serializes() {
    let f = freqs();
    let p = response(&nominal(), &f);
    let data = noisy(&f, &p, Noise::Exact, 3);
    let a = analyze(&data, &p, &cfg());
    let json = serde_json::to_string(&a).unwrap();
    assert!(json.contains("\"median_rel\"") && json.contains("\"residual_to_noise\""));
    assert!(
        json.contains("\"noise_level\""),
        "trend class in snake_case"
    );
    let back: ResidualAnalysis = serde_json::from_str(&json).unwrap();
    assert_eq!(back.n_lines, data.n_lines());
    assert_eq!(back.significant, a.significant);
}

#[test]
fn pure_noise_with_variance_from_few_realizations() {
    // The heavier the F tail (fewer realizations behind each variance), the more the
    // summed statistic exceeds the calibrated chi-square; the level test ignores it.
    let f = freqs();
    let p = response(&nominal(), &f);
    for (r, allowed) in [(4usize, 2usize), (6, 1), (30, 1)] {
        let mut alarms = 0;
        let mut worst_level: f64 = 0.0;
        let mut worst_excess: f64 = 0.0;
        for seed in 0..20 {
            let data = add_measured_noise(&f, &p, REL, r, 500 + seed);
            let a = analyze(&data, &p, &cfg());
            worst_level = worst_level.max(a.significance.level_ratio);
            worst_excess = worst_excess.max(a.significance.excess_ratio);
            if a.significant || !flagged(&a).is_empty() {
                alarms += 1;
            }
            assert!(
                flagged(&a).is_empty(),
                "R={r} seed {seed}: {:?}",
                flagged(&a)
            );
        }
        println!(
            "variance from {r} realizations: {alarms}/20 significant, largest level ratio \
             {worst_level:.4}, largest excess ratio {worst_excess:.4}"
        );
        assert!(alarms <= allowed, "R={r}: {alarms}");
        assert!(worst_level < 1.03);
    }
}
