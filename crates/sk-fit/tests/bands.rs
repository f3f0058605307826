//! Bayard's multi-band composite fit (Jue, section 2.3) against known truth: a wide-band
//! plant in the spirit of Jue's Example 2 (section 4.2), generated with the simulator's
//! modal plant builder, fitted with one band and with the cut-offs chosen from the CMIF.

use experiment::synth::{ModalPlant, ModalPlantBuilder};
use frf_data::{DelayChoice, Estimator, Frf, FrfDataset, Weighting};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realize::FrfModel;
use sk_fit::bands::{BandSpec, BandsReport, MultiBandConfig, MultiBandSk};
use sk_fit::SkConfig;
use std::f64::consts::TAU;

/// Jue's Example 2 (Table 1): 3 inputs, 2 outputs, 30 dominant modes with natural
/// frequencies log-uniform in 1..300 rad/s, each with 2 neighbouring modes within 4 %
/// of it (3 modes per cluster: 90 modes, Jue's 180 states), damping log-uniform in
/// 0.01..0.05. Mode shapes uniform in [-1, 1] (the neighbours' actuator gains half as
/// large: the dominant mode dominates its cluster), modal-mass scaled (numerator
/// `w^2 c b^T`: unit static gain per mode). The thesis gives neither the generator nor
/// the grid, so this is a plant of its description, not its plant.
fn jue_example_2(seed: u64) -> ModalPlant {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (ny, nu) = (2, 3);
    let (w_lo, w_hi) = (1.1f64, 270.0f64);
    let mut b = ModalPlantBuilder::new(ny, nu);
    let mut dominant: Vec<f64> = Vec::new();
    while dominant.len() < 30 {
        let w = w_lo * (w_hi / w_lo).powf(rng.random_range(0.0..1.0));
        if dominant.iter().all(|&v: &f64| (w / v).ln().abs() > 0.1) {
            dominant.push(w);
        }
    }
    for &w in &dominant {
        for k in 0..3 {
            let wk = if k == 0 {
                w
            } else {
                // a neighbour 1..4 % below or above
                let s = if k == 1 { -1.0 } else { 1.0 };
                w * (1.0 + s * rng.random_range(0.01..0.04))
            };
            let zeta = 0.01 * 5f64.powf(rng.random_range(0.0..1.0));
            let gain = if k == 0 { 1.0 } else { 0.5 };
            let c: Vec<f64> = (0..ny).map(|_| rng.random_range(-1.0..1.0) * wk).collect();
            let bb: Vec<f64> = (0..nu)
                .map(|_| gain * rng.random_range(-1.0..1.0) * wk)
                .collect();
            b = b.mode(wk / TAU, zeta, c, bb);
        }
    }
    b.build().unwrap()
}

/// The exact response on `lines` log-spaced lines over 1..300 rad/s.
fn exact_data(plant: &ModalPlant, lines: usize) -> Frf {
    let f: Vec<f64> = (0..lines)
        .map(|k| 300f64.powf(k as f64 / (lines - 1) as f64) / TAU)
        .collect();
    let g = plant.continuous_response(&f).unwrap();
    Frf::new(f, plant.ny(), plant.nu(), g.values, None).unwrap()
}

/// `||G - P||_F / ||G||_F` over every line and entry, against the exact response.
fn rel_error(model: &FrfModel, data: &Frf) -> f64 {
    let p = model.freq_response(&data.omegas()).unwrap();
    let g = data.values_vec();
    let (e, n) = g.iter().zip(&p.values).fold((0.0, 0.0), |(e, n), (g, p)| {
        (e + (g - p).norm_sqr(), n + g.norm_sqr())
    });
    (e / n).sqrt()
}

fn config(bands: BandSpec) -> MultiBandConfig {
    MultiBandConfig {
        bands,
        sk: SkConfig {
            delay: DelayChoice::None,
            weighting: Weighting::Uniform,
            // exact data: every order is significant, so the sweeps stop at a 3 % fit
            // (weighted cost 1e-3 of the weighted energy) or at order 50 (every SK fit,
            // one band or several, at most 50 poles: a test of seconds, not minutes)
            exact_rel_cost: 1e-3,
            max_order: 50,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn fit(data: &Frf, bands: BandSpec) -> (FrfModel, BandsReport, f64) {
    let t = std::time::Instant::now();
    let f = MultiBandSk::new(config(bands)).estimate(data, ()).unwrap();
    let s = t.elapsed().as_secs_f64();
    for m in &f.messages {
        println!("  {m}");
    }
    (f.model, f.report, s)
}

/// Jue's Example 2: the multi-band fit with the cut-offs from the CMIF is better than
/// the single-band fit, and below Jue's three-band result (0.17).
#[test]
fn auto_bands_beat_one_band_on_a_wide_band_plant() {
    let plant = jue_example_2(2);
    let data = exact_data(&plant, 400);
    let (one, r1, s1) = fit(&data, BandSpec::Single);
    let e1 = rel_error(&one, &data);
    println!(
        "one band: relative error {e1:.4} (order {}), {s1:.2} s",
        r1.order
    );
    let (multi, rm, sm) = fit(&data, BandSpec::Auto);
    let em = rel_error(&multi, &data);
    println!(
        "auto bands {:?} Hz: relative error {em:.4} (order {}), passes {:?}, {sm:.2} s",
        rm.cut_offs_hz,
        rm.order,
        rm.passes
            .iter()
            .map(|p| (p.rel_error, p.sk_iterations.clone()))
            .collect::<Vec<_>>()
    );
    assert!((e1 - r1.rel_error).abs() < 1e-9 * e1.max(1.0));
    assert!((em - rm.rel_error).abs() < 1e-9 * em.max(1.0));
    assert!(rm.bands.len() >= 2, "{rm:?}");
    assert_eq!(r1.bands.len(), 1);
    // every band holds poles, and the passes kept the best total error
    assert!(rm.bands.iter().all(|b| b.pairs > 0), "{:?}", rm.bands);
    let best = rm
        .passes
        .iter()
        .map(|p| p.rel_error)
        .fold(f64::INFINITY, f64::min);
    assert!((rm.passes[rm.kept_pass - 1].rel_error - best).abs() <= 1e-12);
    assert!(multi.is_stable() && one.is_stable());
    assert!(em < e1, "multi-band {em:.4} is not below one band {e1:.4}");
    assert!(em < 0.17, "multi-band {em:.4} is not below Jue's 0.17");
}

/// A 1 x 2 plant with a free rigid body and two clusters of three modes (2-4 Hz and
/// 40-80 Hz), exact data on 300 lines over 0.5..150 Hz.
fn two_clusters() -> (ModalPlant, Frf) {
    let mut b = ModalPlantBuilder::new(1, 2)
        .rigid_body(faer::Mat::from_fn(1, 2, |_, j| [0.3, -0.2][j] * 100.0));
    for (f, z, c, bb) in [
        (2.0, 0.02, 1.0, [1.0, 0.5]),
        (3.1, 0.03, -0.8, [0.7, 1.0]),
        (4.2, 0.02, 0.6, [1.0, -0.4]),
        (40.0, 0.01, 1.0, [0.5, 1.0]),
        (57.0, 0.02, -0.7, [1.0, 0.8]),
        (80.0, 0.015, 0.9, [-0.6, 1.0]),
    ] {
        let w = TAU * f;
        b = b.mode(f, z, vec![c * w], vec![bb[0] * w, bb[1] * w]);
    }
    let plant = b.build().unwrap();
    let f: Vec<f64> = (0..300)
        .map(|k| 0.5 * 300f64.powf(k as f64 / 299.0))
        .collect();
    let g = plant.continuous_response(&f).unwrap();
    let data = Frf::new(f, 1, 2, g.values, None).unwrap();
    (plant, data)
}

/// Given cut-offs: each cluster is fitted in its band, the rigid body in the lowest band
/// only, and the sum reproduces the exact data.
#[test]
fn given_cut_offs_fit_each_cluster_in_its_band() {
    let (_, data) = two_clusters();
    let mut cfg = config("10".parse().unwrap());
    cfg.sk.exact_rel_cost = 1e-16;
    cfg.sk.max_order = 16;
    let f = MultiBandSk::new(cfg).estimate(&data, ()).unwrap();
    let r = &f.report;
    for m in &f.messages {
        println!("  {m}");
    }
    assert_eq!(r.cut_offs_hz, vec![10.0]);
    assert_eq!(r.bands.len(), 2);
    assert_eq!(r.bands[0].integrators, 2, "{:?}", r.bands[0]);
    assert_eq!(r.bands[1].integrators, 0);
    assert!(r.bands[1].feedthrough && !r.bands[0].feedthrough);
    assert_eq!(f.model.modal.rigid.len(), 2);
    let e = rel_error(&f.model, &data);
    assert!(e < 1e-6, "relative error {e:.3e}");
    assert!(f.model.is_stable());
    // each band's resonances are the ones of its cluster
    let in_band = |b: usize, lo: f64, hi: f64| {
        f.model
            .modal
            .pairs
            .iter()
            .filter(|p| {
                p.residue.norm_l2() > 1e-6 * p.pole.norm() && {
                    let fh = p.f_hz();
                    fh > lo && fh < hi
                }
            })
            .count()
            >= 3
            && r.bands[b].pairs >= 3
    };
    assert!(
        in_band(0, 1.9, 4.3) && in_band(1, 39.0, 81.0),
        "{:?}",
        f.model.modal.mode_summaries()
    );
}

/// Cut-offs outside the data name the empty band; one order for several bands and a
/// tiered weight outside [0, 1] are rejected.
#[test]
fn bad_band_settings_are_named() {
    let (_, data) = two_clusters();
    let err = |cfg: MultiBandConfig| {
        MultiBandSk::new(cfg)
            .estimate(&data, ())
            .unwrap_err()
            .to_string()
    };
    let e = err(config("10,200".parse().unwrap()));
    assert!(
        e.contains("band 3 (200 .. inf Hz) holds no lines") && e.contains("150"),
        "{e}"
    );
    let e = err(config("0.1,0.2".parse().unwrap()));
    assert!(e.contains("band 1 (0 .. 0.1 Hz) holds no lines"), "{e}");
    let mut cfg = config("10".parse().unwrap());
    cfg.sk.order = Some(12);
    let e = err(cfg);
    assert!(e.contains("one order for 2 bands is ambiguous"), "{e}");
    let mut cfg = config("10".parse().unwrap());
    cfg.orders = vec![12];
    assert!(err(cfg).contains("one order per band is needed: 2 band(s)"));
    let mut cfg = config(BandSpec::Auto);
    cfg.q_high = 2.0;
    assert!(err(cfg).contains("q_high"));
}

/// `auto` leaves out a cut that would make a band of fewer than `min_band_lines` lines:
/// with one CMIF peak per band the two clusters' peaks are a few lines apart, and a
/// large minimum merges the bands of each cluster.
#[test]
fn auto_cuts_keep_every_band_above_the_line_minimum() {
    let (_, data) = two_clusters();
    let mut cfg = config(BandSpec::Auto);
    cfg.auto.modes_per_band = 1;
    cfg.auto.max_bands = 10;
    cfg.min_band_lines = 100;
    cfg.sk.max_order = 16;
    let f = MultiBandSk::new(cfg).estimate(&data, ()).unwrap();
    let r = &f.report;
    // some of the cuts between neighbouring peaks were left out, none of the bands is
    // short
    let peaks = r.cmif_peaks.unwrap();
    assert!(
        peaks >= 3 && r.bands.len() < peaks,
        "{peaks} peaks: {:?}",
        r.bands
    );
    assert!(r.bands.iter().all(|b| b.lines >= 100), "{:?}", r.bands);
    assert_eq!(r.cut_offs_hz.len(), r.bands.len() - 1);
    assert_eq!(r.auto_cuts.len(), r.cut_offs_hz.len());
}
