//! Frequency response of a 40-state 4 x 13 wafer-stage-like model at 4000 points: the
//! modal sum against the Hessenberg state-space method (Laub 1981), continuous and
//! through a zero-order hold.
//!
//! Model: a free mass `R_2 / s^2` of rank 4 (8 states, double-integrator chains) plus 16
//! lightly damped modes with rank-1 residues (32 states), modes between 100 Hz and 3 kHz.

use criterion::{criterion_group, criterion_main, Criterion};
use faer::Mat;
use realize::{ModalModel, PolePair, C64};
use std::hint::black_box;

/// A deterministic pseudo-random stream (SplitMix64) so the bench needs no RNG crate.
struct Stream(u64);

impl Stream {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

fn wafer_like() -> ModalModel {
    let (ny, nu) = (4, 13);
    let mut r = Stream(2024);
    let mut m = ModalModel::new(ny, nu);
    m.rigid = vec![Mat::zeros(ny, nu), Mat::from_fn(ny, nu, |_, _| r.next())];
    for k in 0..16 {
        let f = 100.0 * 30f64.powf(k as f64 / 15.0);
        let zeta = 0.002 + 0.01 * r.next().abs();
        let c: Vec<f64> = (0..ny).map(|_| r.next()).collect();
        let b: Vec<f64> = (0..nu).map(|_| r.next()).collect();
        let num = Mat::from_fn(ny, nu, |i, j| c[i] * b[j] * 1e3);
        m.pairs.push(PolePair::from_second_order(f, zeta, &num));
    }
    m
}

fn bench(c: &mut Criterion) {
    faer::set_global_parallelism(faer::Par::Seq);
    let m = wafer_like();
    let ss = m.to_state_space(1e-12).expect("realization");
    assert_eq!(ss.n_states(), 40);
    let omega: Vec<f64> = (0..4000)
        .map(|k| std::f64::consts::TAU * (1.0 + k as f64 * 1.25))
        .collect();
    // Transposed system (13 x 4): the solve runs over columns instead of rows.
    let sst = realize::StateSpace::new(
        ss.a.transpose().to_owned(),
        ss.c.transpose().to_owned(),
        ss.b.transpose().to_owned(),
        ss.d.transpose().to_owned(),
        realize::TimeDomain::Continuous,
    )
    .expect("transposed model");

    let mut g = c.benchmark_group("freq_response_40x(4x13)x4000");
    g.sample_size(20);
    g.bench_function("modal", |b| {
        b.iter(|| black_box(&m).freq_response(black_box(&omega)).unwrap())
    });
    g.bench_function("state_space_hessenberg", |b| {
        b.iter(|| black_box(&ss).freq_response(black_box(&omega)).unwrap())
    });
    g.bench_function("state_space_hessenberg_transposed_13x4", |b| {
        b.iter(|| black_box(&sst).freq_response(black_box(&omega)).unwrap())
    });
    g.bench_function("modal_zoh", |b| {
        b.iter(|| {
            black_box(&m)
                .zoh_response(black_box(&omega), 1e-4, 1.0)
                .unwrap()
        })
    });
    g.bench_function("state_space_discretize_zoh", |b| {
        b.iter(|| {
            black_box(&ss)
                .zoh_response(black_box(&omega), 1e-4, 1)
                .unwrap()
        })
    });
    g.finish();

    // Sanity (not timed): both methods agree.
    let gm = m.freq_response(&omega).unwrap();
    let gs = ss.freq_response(&omega).unwrap();
    let worst = (0..omega.len())
        .map(|k| {
            let num = gm
                .line(k)
                .iter()
                .zip(gs.line(k))
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            num / gm
                .line(k)
                .iter()
                .map(|a: &C64| a.norm())
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max);
    eprintln!("max line relative difference modal vs state space: {worst:e}");
}

criterion_group!(benches, bench);
criterion_main!(benches);
