//! The CMIF peak picker on data with known modes: the reference wafer stage (acceptance:
//! at least 15 of its 17 flexible modes within 1 % and at most 3 spurious peaks in
//! 20..2000 Hz), seeded random modal systems through an exact zero-order hold (with and
//! without noise, with and without a variance), and the real measurements of
//! `shared/data/real` (reported, with loose checks against their documented modes).

use faer::Mat;
use frf_data::cmif::{cmif, pick_peaks, CmifPeak, PeakConfig};
use frf_data::shared_data::require;
use frf_data::truth::Truth;
use frf_data::{Frf, FrfDataset, C64};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use realize::{ModalModel, PolePair};
use std::f64::consts::TAU;

/// One-to-one matching of peaks to true frequencies within `rel` (closest pairs first).
/// Returns (matched true modes, spurious peaks, unmatched true modes).
fn score(peaks: &[CmifPeak], truth: &[f64], rel: f64) -> (usize, Vec<f64>, Vec<f64>) {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, p) in peaks.iter().enumerate() {
        for (j, &f) in truth.iter().enumerate() {
            let d = (p.f_hz - f).abs() / f;
            if d <= rel {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut used_p = vec![false; peaks.len()];
    let mut used_t = vec![false; truth.len()];
    let mut hits = 0;
    for (_, i, j) in pairs {
        if !used_p[i] && !used_t[j] {
            used_p[i] = true;
            used_t[j] = true;
            hits += 1;
        }
    }
    let spurious = peaks
        .iter()
        .zip(&used_p)
        .filter(|(_, u)| !**u)
        .map(|(p, _)| p.f_hz)
        .collect();
    let missed = truth
        .iter()
        .zip(&used_t)
        .filter(|(_, u)| !**u)
        .map(|(f, _)| *f)
        .collect();
    (hits, spurious, missed)
}

#[test]
fn wafer_nominal_finds_the_flexible_modes() {
    let Some(path) = require(
        "wafer_nominal_finds_the_flexible_modes",
        "wafer_nominal.csv",
    ) else {
        return;
    };
    let Some(tpath) = require(
        "wafer_nominal_finds_the_flexible_modes",
        "wafer_nominal.truth.json",
    ) else {
        return;
    };
    let frf = frf_data::io::read_frf_csv(&path).unwrap();
    let truth: Vec<f64> = Truth::read(&tpath)
        .unwrap()
        .model
        .modes
        .iter()
        .map(|m| m.f_hz)
        .collect();
    let band = frf.band(20.0, 2000.0).unwrap();
    let c = cmif(&band).unwrap();
    assert_eq!(c.n_sv(), 4);
    let peaks = pick_peaks(&c, &PeakConfig::default());
    let (hits, spurious, missed) = score(&peaks, &truth, 0.01);
    println!(
        "wafer_nominal 20..2000 Hz: {} peaks, {hits}/{} modes within 1 %, spurious {spurious:?}, missed {missed:?}",
        peaks.len(),
        truth.len()
    );
    for p in &peaks {
        println!(
            "  {:8.2} Hz  sigma_{}  prominence {:5.1} dB  damping {:?}",
            p.f_hz,
            p.sv_index + 1,
            p.prominence,
            p.damping
        );
    }
    assert!(hits >= 15, "found {hits} of 17 modes; missed {missed:?}");
    assert!(spurious.len() <= 3, "spurious peaks {spurious:?}");
    // n_modes returns the most prominent ones, in frequency order.
    let top = pick_peaks(
        &c,
        &PeakConfig {
            n_modes: Some(5),
            ..PeakConfig::default()
        },
    );
    assert_eq!(top.len(), 5);
    assert!(top.windows(2).all(|w| w[0].f_hz <= w[1].f_hz));
    let min_top = top
        .iter()
        .map(|p| p.prominence)
        .fold(f64::INFINITY, f64::min);
    let above = peaks.iter().filter(|p| p.prominence > min_top).count();
    assert!(above <= 4, "n_modes did not keep the most prominent peaks");
}

#[test]
fn plain_sorted_search_is_worse_than_the_picker_on_the_wafer() {
    // The motivation for the enhanced-FRF tests: without them (every local maximum of
    // sigma_1 and sigma_2 with a 3 dB curve prominence) crossing cusps show up.
    let Some(path) = require("plain_sorted_search", "wafer_nominal.csv") else {
        return;
    };
    let Some(tpath) = require("plain_sorted_search", "wafer_nominal.truth.json") else {
        return;
    };
    let frf = frf_data::io::read_frf_csv(&path).unwrap();
    let truth: Vec<f64> = Truth::read(&tpath)
        .unwrap()
        .model
        .modes
        .iter()
        .map(|m| m.f_hz)
        .collect();
    let c = cmif(&frf.band(20.0, 2000.0).unwrap()).unwrap();
    let good = pick_peaks(&c, &PeakConfig::default());
    let (hits_good, spur_good, _) = score(&good, &truth, 0.01);
    // Plain search on the sorted curves 1 and 2.
    let mut plain = Vec::new();
    for i in 0..2 {
        let y: Vec<f64> = (0..c.n_lines()).map(|k| c.db(k, i)).collect();
        for k in 1..y.len() - 1 {
            if y[k] > y[k - 1] && y[k] >= y[k + 1] {
                let lmin = y[..k]
                    .iter()
                    .rev()
                    .take(200)
                    .fold(f64::INFINITY, |a, &b| a.min(b));
                let rmin = y[k + 1..]
                    .iter()
                    .take(200)
                    .fold(f64::INFINITY, |a, &b| a.min(b));
                if y[k] - lmin.max(rmin) >= 3.0 {
                    plain.push(CmifPeak {
                        f_hz: c.freq_hz[k],
                        line: k,
                        sv_index: i,
                        prominence: 0.0,
                        sv2: c.sv2[k][i],
                        candidate_line: k,
                        damping: None,
                    });
                }
            }
        }
    }
    let (hits_plain, spur_plain, _) = score(&plain, &truth, 0.01);
    println!(
        "plain sigma_1,2 search: {hits_plain} hits, {} spurious; picker: {hits_good} hits, {} spurious",
        spur_plain.len(),
        spur_good.len()
    );
    assert!(hits_good > hits_plain || spur_good.len() < spur_plain.len());
}

/// A random lightly damped modal system: `ny, nu` in 2..=5, 3..=8 modes log-uniform in
/// 40..1600 Hz at least 15 % apart, damping 0.002..0.02, rank-one residues `c b^T` with
/// standard normal gains, an optional rigid body `R / s^2`.
fn random_system(rng: &mut ChaCha8Rng) -> (ModalModel, Vec<f64>) {
    let ny = rng.random_range(2..=5);
    let nu = rng.random_range(2..=5);
    let n_modes = rng.random_range(3..=8);
    let mut freqs: Vec<f64> = Vec::new();
    while freqs.len() < n_modes {
        let f = (40f64.ln() + rng.random::<f64>() * (1600f64 / 40.0).ln()).exp();
        if freqs.iter().all(|&g| (f / g).ln().abs() > 1.15f64.ln()) {
            freqs.push(f);
        }
    }
    freqs.sort_by(f64::total_cmp);
    let mut m = ModalModel::new(ny, nu);
    if rng.random_bool(0.5) {
        let r = Mat::from_fn(ny, nu, |_, _| {
            let x: f64 = StandardNormal.sample(rng);
            x
        });
        m.rigid = vec![Mat::zeros(ny, nu), r];
    }
    for &f in &freqs {
        let zeta = rng.random_range(0.002..0.02);
        let c: Vec<f64> = (0..ny).map(|_| StandardNormal.sample(rng)).collect();
        let b: Vec<f64> = (0..nu).map(|_| StandardNormal.sample(rng)).collect();
        let num = Mat::from_fn(ny, nu, |i, j| c[i] * b[j]);
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
    }
    (m, freqs)
}

/// The system's response on 10..2000 Hz (0.5 Hz lines) through a 10 kHz zero-order hold
/// and one sample of delay; `noise` is `None` (noiseless) or the relative noise level,
/// with `with_var` deciding whether the variance is attached.
fn simulate(rng: &mut ChaCha8Rng, m: &ModalModel, noise: Option<f64>, with_var: bool) -> Frf {
    let f: Vec<f64> = (0..3981).map(|k| 10.0 + 0.5 * k as f64).collect();
    let w: Vec<f64> = f.iter().map(|x| TAU * x).collect();
    let g = m.zoh_response(&w, 1e-4, 1.0).unwrap();
    let frf = Frf::from_grid(f, g).unwrap();
    let Some(level) = noise else { return frf };
    // Noise standard deviation per entry: `level` times the entry's median magnitude
    // (a flat noise floor, like a closed-loop estimate far from the resonances).
    let (ny, nu, n) = (frf.ny(), frf.nu(), frf.n_lines());
    let mut sd = vec![0.0; ny * nu];
    for e in 0..ny * nu {
        let mut mags: Vec<f64> = (0..n)
            .map(|k| frf.value(k, e % ny, e / ny).norm())
            .collect();
        mags.sort_by(f64::total_cmp);
        sd[e] = level * mags[n / 2];
    }
    let mut vals = frf.values().to_vec();
    let mut var = Vec::with_capacity(vals.len());
    for (idx, v) in vals.iter_mut().enumerate() {
        let s = sd[idx % (ny * nu)];
        let (a, b): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
        *v += C64::new(a, b) * (s / 2f64.sqrt());
        var.push(s * s);
    }
    Frf::new(frf.freqs_hz(), ny, nu, vals, with_var.then_some(var)).unwrap()
}

#[test]
fn random_modal_systems_are_found() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let cfg = PeakConfig::default();
    let (mut total, mut found, mut spurious_total) = (0, 0, 0);
    let mut worst_spurious = 0;
    let mut report = Vec::new();
    let n_cases = 64;
    for case in 0..n_cases {
        let (m, freqs) = random_system(&mut rng);
        // Cycle through noiseless, 1 % noise with and without a variance, 3 % noise
        // without one (relative to each entry's median magnitude: the high-frequency
        // roll-off of a displacement FRF then sits at or below the noise).
        let (noise, with_var) = match case % 4 {
            0 => (None, false),
            1 => (Some(0.01), true),
            2 => (Some(0.01), false),
            _ => (Some(0.03), false),
        };
        let d = simulate(&mut rng, &m, noise, with_var);
        let c = cmif(&d).unwrap();
        let peaks = pick_peaks(&c, &cfg);
        let (hits, spurious, missed) = score(&peaks, &freqs, 0.01);
        total += freqs.len();
        found += hits;
        spurious_total += spurious.len();
        worst_spurious = worst_spurious.max(spurious.len());
        if !missed.is_empty() || !spurious.is_empty() {
            report.push(format!(
                "case {case} ({}x{}, rigid {}, noise {noise:?}, var {with_var}): {hits}/{} missed {missed:.1?} spurious {spurious:.1?}",
                d.ny(),
                d.nu(),
                !m.rigid.is_empty(),
                freqs.len()
            ));
        }
    }
    println!(
        "random systems: {found}/{total} modes within 1 %, {spurious_total} spurious peaks in {n_cases} systems"
    );
    for r in &report {
        println!("  {r}");
    }
    assert!(
        found as f64 >= 0.97 * total as f64,
        "found only {found} of {total} modes:\n{}",
        report.join("\n")
    );
    assert!(
        spurious_total <= n_cases / 8 && worst_spurious <= 2,
        "too many spurious peaks ({spurious_total}, worst {worst_spurious}):\n{}",
        report.join("\n")
    );
}

#[test]
fn real_daisy_flexible_structure() {
    let Some(path) = require("real_daisy", "real/daisy_flexible_structure.csv") else {
        return;
    };
    let frf = frf_data::io::read_frf_csv(&path).unwrap();
    let c = cmif(&frf).unwrap();
    let peaks = pick_peaks(&c, &PeakConfig::default());
    // The file's comments list the CMIF peaks of this structure.
    let listed = [
        62.0, 119.0, 155.0, 193.0, 215.0, 230.0, 239.0, 287.0, 321.0, 334.0, 352.0, 398.0, 417.0,
        468.0,
    ];
    let (hits, spurious, missed) = score(&peaks, &listed, 0.01);
    println!(
        "daisy 28x2: {} peaks; {hits}/14 listed modes within 1 %; other peaks {spurious:.1?}; missed {missed:?}",
        peaks.len()
    );
    for p in &peaks {
        println!(
            "  {:8.2} Hz  sigma_{}  prominence {:5.1} dB  damping {:?}",
            p.f_hz,
            p.sv_index + 1,
            p.prominence,
            p.damping
        );
    }
    assert!(hits >= 12, "daisy: {hits} of 14 listed modes");
    assert!(spurious.len() <= 3, "daisy: extra peaks {spurious:?}");
}

#[test]
fn real_ladisk_beam() {
    let Some(path) = require("real_ladisk", "real/ladisk_beam_accelerance.csv") else {
        return;
    };
    let frf = frf_data::io::read_frf_csv(&path).unwrap();
    let c = cmif(&frf).unwrap();
    assert_eq!(c.n_sv(), 1);
    let peaks = pick_peaks(&c, &PeakConfig::default());
    let listed = [52.0, 142.0, 279.0, 460.0, 687.0, 959.0];
    let (hits, spurious, missed) = score(&peaks, &listed, 0.02);
    println!(
        "ladisk 1x3: {} peaks; {hits}/6 bending modes within 2 %; other peaks {spurious:.1?}; missed {missed:?}",
        peaks.len()
    );
    for p in &peaks {
        println!(
            "  {:8.2} Hz  prominence {:5.1} dB  damping {:?}",
            p.f_hz, p.prominence, p.damping
        );
    }
    assert!(hits >= 6, "ladisk: {hits} of 6 modes");
    assert!(spurious.len() <= 2, "ladisk: extra peaks {spurious:?}");
}
