//! Cost of one refined-IV iteration (one update of Algorithm 1, eq. 23) against the
//! number of frequency lines: 1000, 2000, 4000 and 8000 lines of a simulated 4x13
//! system (rigid body with two integrators, 8 lightly damped modes, a fitted delay, the
//! exact 10 kHz zero-order hold, as in the wafer-stage fit), its exact response on a
//! logarithmic grid 20..2000 Hz, no noise, no files.
//!
//! The iterations start from a model whose mode frequencies, dampings and delay are off
//! the truth (numerators fitted to the data by the convex problem (24)-(25)), so that
//! each step does real work. Timed per line count (throughput in lines, so that a linear
//! cost shows as a constant rate):
//!
//! - `step`: [`additive_riv::step::step`], the structured solve of one update, with the
//!   entries on the rayon pool as [`RivConfig::default`] does;
//! - `step_seq`: the same on one thread;
//! - `iteration`: [`additive_riv::riv::iterate`] limited to one iteration: the basis and
//!   cost at the start, the step, the new basis and the cost check of the update.

use additive_riv::problem::{pack, Basis, Layout};
use additive_riv::riv::{iterate, RivConfig};
use additive_riv::step::{step, IvMethod, StepSolver};
use additive_riv::{fit_numerators, AdditiveModel, Domain, FitData, KnownFactor};
use criterion::{
    criterion_group, criterion_main, BenchmarkId, Criterion, SamplingMode, Throughput,
};
use frf_data::{Convergence, Frf, ModelStructure, Weighting};
use std::hint::black_box;
use std::time::Duration;

const NY: usize = 4;
const NU: usize = 13;
const FS_HZ: f64 = 10_000.0;
const BAND_HZ: (f64, f64) = (20.0, 2000.0);
const LINES: [usize; 4] = [1000, 2000, 4000, 8000];
/// Natural frequency (Hz) and damping of the flexible modes.
const MODES: [(f64, f64); 8] = [
    (95.0, 0.012),
    (160.0, 0.008),
    (245.0, 0.015),
    (380.0, 0.006),
    (560.0, 0.010),
    (810.0, 0.020),
    (1150.0, 0.007),
    (1580.0, 0.012),
];
const DELAY_S: f64 = 80e-6;

/// A fixed, sign-varying pattern in [-1, 1] with no entry near 0, per submodel.
fn pattern(sub: usize, i: usize, j: usize) -> f64 {
    let v = ((1 + sub) as f64 * 0.73 + i as f64 * 1.91 + j as f64 * 0.37).sin();
    if v.abs() < 0.25 {
        0.25f64.copysign(v)
    } else {
        v
    }
}

/// The system with its mode frequencies scaled by `f_scale`, its dampings by `z_scale`
/// and its delay by `d_scale`; numerators `B` (rigid body) and `0.3 B` (modes), so that
/// every mode stands out of the rigid-body line by tens of dB at its resonance.
fn system(f_scale: f64, z_scale: f64, d_scale: f64) -> AdditiveModel {
    let mut m = AdditiveModel::new(NY, NU, Domain::ZohDiscrete { ts: 1.0 / FS_HZ })
        .and_then(|m| {
            m.with_factor(KnownFactor {
                delay_s: DELAY_S * d_scale,
                fit_delay: true,
                ..Default::default()
            })
        })
        .expect("a valid model");
    m.push_rigid_body(2, AdditiveModel::rigid_scale(BAND_HZ.0, BAND_HZ.1))
        .expect("rigid body");
    for (f, z) in MODES {
        m.push_mode(f * f_scale, z * z_scale, false)
            .expect("a mode below Nyquist");
    }
    for (s, sub) in m.submodels.iter_mut().enumerate() {
        let gain = if s == 0 { 1.0 } else { 0.3 };
        for b in &mut sub.num {
            for j in 0..NU {
                for i in 0..NY {
                    b[(i, j)] = gain * pattern(s, i, j);
                }
            }
        }
    }
    m
}

/// `n` lines log-spaced over the band.
fn log_grid(n: usize) -> Vec<f64> {
    let (lo, hi) = BAND_HZ;
    (0..n)
        .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}

/// One problem size: the data, the start model and the solver's view of it.
struct Case {
    data: FitData,
    start: AdditiveModel,
    lay: Layout,
    subs: Vec<(usize, usize)>,
    basis: Basis,
    eta: Vec<f64>,
}

fn case(n: usize) -> Case {
    let truth = system(1.0, 1.0, 1.0);
    let freqs = log_grid(n);
    let omega: Vec<f64> = freqs.iter().map(|f| std::f64::consts::TAU * f).collect();
    let frf = Frf::from_grid(freqs, truth.response_at(&omega)).expect("finite response");
    let weighting = Weighting::Auto.resolve(&frf);
    let data = FitData::new(&frf, &weighting).expect("fit data");
    let mut start = system(1.004, 1.3, 0.9);
    fit_numerators(&mut start, &data).expect("numerators of the start model");
    let lay = Layout::of(&start);
    let subs = start
        .submodels
        .iter()
        .map(|s| (s.num.len(), s.den.len()))
        .collect();
    let (_, eta) = pack(&start, &lay);
    let basis = Basis::new(&start, &lay, &data.omega);
    Case {
        data,
        start,
        lay,
        subs,
        basis,
        eta,
    }
}

fn bench_scaling(c: &mut Criterion) {
    let one_iteration = RivConfig {
        max_iterations: 1,
        ..Default::default()
    };
    let parallel = RivConfig::default().parallel;
    let mut group = c.benchmark_group("riv_iteration_scaling");
    group.sample_size(10);
    // flat: the same number of calls per sample, so that 10 samples of the largest case
    // fit in the measurement time
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(3));
    for n in LINES {
        let cs = case(n);
        // the step must succeed and the iteration must lower the cost (no SK rescue, no
        // backtracking to nothing), or the timings would not be of a normal iteration
        let fit = iterate(cs.start.clone(), &cs.data, &one_iteration).expect("one iteration");
        let h = &fit.cost_history;
        assert!(
            matches!(fit.convergence, Convergence::MaxIterations { .. })
                && h.len() == 2
                && h[1] < h[0],
            "{n} lines: not a plain descent iteration: {:?}, costs {h:?}",
            fit.convergence
        );
        println!(
            "riv_iteration_scaling/{n}: {} entries, {} parameters, cost {:.3e} -> {:.3e}",
            cs.data.m(),
            cs.start.n_params(),
            h[0],
            h[1]
        );
        group.throughput(Throughput::Elements(n as u64));
        for (name, par) in [("step", parallel), ("step_seq", false)] {
            group.bench_with_input(BenchmarkId::new(name, n), &cs, |b, cs| {
                b.iter(|| {
                    step(
                        black_box(&cs.data),
                        &cs.lay,
                        &cs.subs,
                        &cs.basis,
                        black_box(&cs.eta),
                        IvMethod::Riv,
                        StepSolver::Structured,
                        par,
                    )
                    .expect("step")
                })
            });
        }
        group.bench_with_input(BenchmarkId::new("iteration", n), &cs, |b, cs| {
            b.iter(|| {
                iterate(
                    black_box(cs.start.clone()),
                    black_box(&cs.data),
                    &one_iteration,
                )
                .expect("iteration")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_scaling);
criterion_main!(benches);
