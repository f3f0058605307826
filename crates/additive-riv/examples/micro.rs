use additive_riv::problem::*;
use additive_riv::*;
use frf_data::Weighting;
use std::time::Instant;
fn main() {
    let dir = frf_data::shared_data::shared_data_dir().unwrap();
    let data = frf_data::io::read_frf_csv(dir.join("wafer_nominal.csv")).unwrap();
    let truth = frf_data::truth::Truth::read(dir.join("wafer_nominal.truth.json")).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let tf: Vec<f64> = truth.model.modes.iter().map(|m| m.f_hz).collect();
    let fd = FitData::new(&band, &Weighting::Auto).unwrap();
    let cfg = InitConfig {
        domain: Domain::ZohDiscrete { ts: 1e-4 },
        factor: KnownFactor {
            delay_s: 1e-4,
            ..Default::default()
        },
        rigid_body: RigidBody::Integrators(2),
        ..Default::default()
    };
    let init = initial_model(&fd, &tf, &cfg).unwrap();
    let lay = Layout::of(&init.model);
    let t = Instant::now();
    let basis = Basis::new(&init.model, &lay, &fd.omega);
    println!("basis {:?}", t.elapsed());
    let g = groups(&init.model, &lay);
    let (_, eta) = pack(&init.model, &lay);
    let mut el = EntryLines::default();
    let t = Instant::now();
    for r in 0..1000 {
        el.fill(
            r % 52,
            &fd,
            &basis,
            &g,
            &eta[(r % 52) * lay.n_num..(r % 52 + 1) * lay.n_num],
        );
    }
    println!("fill {:?} per call", t.elapsed() / 1000);
    let t = Instant::now();
    for _ in 0..10 {
        std::hint::black_box(cost(&fd, &lay, &basis, &eta, None, &g));
    }
    println!("cost {:?} per call", t.elapsed() / 10);
    let subs: Vec<(usize, usize)> = init
        .model
        .submodels
        .iter()
        .map(|s| (s.num.len(), s.den.len()))
        .collect();
    for par in [false, true] {
        let t = Instant::now();
        for _ in 0..3 {
            std::hint::black_box(
                additive_riv::step::step(
                    &fd,
                    &lay,
                    &subs,
                    &basis,
                    &eta,
                    IvMethod::Riv,
                    StepSolver::Structured,
                    par,
                )
                .unwrap(),
            );
        }
        println!("step (parallel {par}) {:?} per call", t.elapsed() / 3);
    }
}
