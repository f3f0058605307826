use additive_riv::*;
use frf_data::{FrfDataset, ModelStructure, Weighting};
use std::time::Instant;

fn rel_errs(model: &AdditiveModel, truth: &frf_data::FrfView) -> (f64, f64) {
    let g = model.response(truth);
    let m = truth.n_entries();
    let mut v = Vec::new();
    for k in 0..truth.n_lines() {
        for e in 0..m {
            let t = truth.value(k, e % truth.ny(), e / truth.ny());
            v.push((g.values[k * m + e] - t).norm() / t.norm());
        }
    }
    v.sort_by(|a, b| a.total_cmp(b));
    (v[v.len() / 2], v[(v.len() as f64 * 0.95) as usize])
}

fn main() {
    faer::set_global_parallelism(faer::Par::Seq);
    let dir = frf_data::shared_data::shared_data_dir().unwrap();
    let t = Instant::now();
    let data = frf_data::io::read_frf_csv(dir.join("wafer_nominal.csv")).unwrap();
    let clean = frf_data::io::read_frf_csv(dir.join("wafer_nominal.noiseless.csv")).unwrap();
    eprintln!("read {:?}", t.elapsed());
    let truth = frf_data::truth::Truth::read(dir.join("wafer_nominal.truth.json")).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let cband = clean.band(20.0, 2000.0).unwrap();
    let tf: Vec<f64> = truth.model.modes.iter().map(|m| m.f_hz).collect();
    let tz: Vec<f64> = truth.model.modes.iter().map(|m| m.zeta).collect();
    let args: Vec<String> = std::env::args().collect();
    let zoh = args.iter().any(|a| a == "zoh");
    let wname = args
        .iter()
        .find(|a| a.starts_with("w="))
        .cloned()
        .unwrap_or("w=auto".into());
    let weighting = match wname.as_str() {
        "w=mag" => Weighting::InverseMagnitude,
        "w=var" => Weighting::InverseVariance,
        _ => Weighting::Auto,
    };
    let init_cfg = if zoh {
        InitConfig {
            domain: Domain::ZohDiscrete { ts: 1e-4 },
            factor: KnownFactor {
                delay_s: 1e-4,
                ..Default::default()
            },
            rigid_body: RigidBody::Integrators(2),
            ..Default::default()
        }
    } else {
        InitConfig {
            factor: KnownFactor {
                delay_s: 150e-6,
                ..Default::default()
            },
            rigid_body: RigidBody::Integrators(2),
            ..Default::default()
        }
    };
    let t = Instant::now();
    let fd = FitData::new(&band, &weighting).unwrap();
    let mut shift: Vec<f64> = tf
        .iter()
        .enumerate()
        .map(|(i, f)| f * (1.0 + 0.005 * ((i as f64 * 1.7).sin())))
        .collect();
    if args.iter().any(|a| a == "missing") {
        shift.remove(8);
        shift.remove(1);
        shift.push(333.0);
        shift.push(1500.0);
    }
    if args.iter().any(|a| a == "missing2") {
        shift.remove(8);
        shift.remove(1);
        shift.remove(3);
    }
    let init = initial_model(&fd, &shift, &init_cfg).unwrap();
    eprintln!(
        "init {:?} cost {:?} {:?}",
        t.elapsed(),
        init.cost_history,
        init.messages
    );
    let t = Instant::now();
    let cfg = RivConfig {
        weighting: weighting.clone(),
        progress: frf_data::ProgressSink::new(|p| {
            eprintln!("  it {} cost {:?} {}", p.step, p.cost, p.message)
        }),
        ..Default::default()
    };
    let fit = if args.iter().any(|a| a == "adapt") {
        let (f, rep) = adapt_modes(init.model, &fd, &cfg, &AdaptConfig::default()).unwrap();
        eprintln!("adapt: {:?}", rep);
        f
    } else {
        AdditiveRiv::new(cfg).refine(init.model, &fd).unwrap()
    };
    eprintln!(
        "riv {:?}: {} its, {:?} {:?}",
        t.elapsed(),
        fit.iterations,
        fit.convergence,
        fit.messages
    );
    let modes = fit.model.modes();
    let mut worst_f: f64 = 0.0;
    let mut worst_z: f64 = 0.0;
    for md in modes.iter() {
        let mi = (0..tf.len())
            .min_by(|&a, &b| (tf[a] - md.f_hz).abs().total_cmp(&(tf[b] - md.f_hz).abs()))
            .unwrap();
        let ef = (md.f_hz / tf[mi] - 1.0).abs();
        let ez = (md.zeta / tz[mi] - 1.0).abs();
        worst_f = worst_f.max(ef);
        worst_z = worst_z.max(ez);
        eprintln!(
            "  mode {:7.2} Hz (true {:7.2}) df {:.2e} zeta {:.5} (true {:.5}) dz {:.2e}",
            md.f_hz, tf[mi], ef, md.zeta, tz[mi], ez
        );
    }
    let (med, p95) = rel_errs(&fit.model, &cband);
    eprintln!(
        "worst df {worst_f:.2e} dz {worst_z:.2e}; vs noiseless: median {med:.3e} p95 {p95:.3e}"
    );
    let (med, p95) = rel_errs(&fit.model, &band);
    eprintln!("vs data: median {med:.3e} p95 {p95:.3e}");
    eprintln!("order {}", fit.model.to_modal_model().unwrap().pairs.len());
    fstats(&fit.model, &fd);
}
#[allow(dead_code)]
fn fstats(model: &AdditiveModel, fd: &FitData) {
    let dv = additive_riv::significance::submodel_cost_increase(model, fd).unwrap();
    let st = additive_riv::structure::ResidualStats::new(model, fd);
    eprintln!("s2 {} nu {} c {}", st.s2, st.nu, st.c);
    for (i, s) in model.submodels.iter().enumerate() {
        let p = s.den.len() + s.num.len() * fd.m();
        let f = model
            .upper_pole(s)
            .map(|p| p.norm() / std::f64::consts::TAU)
            .unwrap_or(0.0);
        eprintln!(
            "  sub {i} f {f:.2} F {:.1}",
            additive_riv::significance::f_statistic(dv[i], p, st.s2)
        );
    }
}
