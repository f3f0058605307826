use additive_riv::*;
use frf_data::{FrfDataset, Weighting};
fn main() {
    faer::set_global_parallelism(faer::Par::Seq);
    let dir = frf_data::shared_data::shared_data_dir().unwrap();
    let data = frf_data::io::read_frf_csv(dir.join("wafer_crosstalk.csv")).unwrap();
    let t = frf_data::truth::Truth::read(dir.join("wafer_crosstalk.truth.json")).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let fd = FitData::new(&band, &Weighting::Auto).unwrap();
    let freqs: Vec<f64> = t
        .model
        .modes
        .iter()
        .map(|m| m.f_hz)
        .filter(|&f| f < 1999.0)
        .collect();
    let cfg = InitConfig {
        domain: Domain::ZohDiscrete { ts: 1e-4 },
        factor: KnownFactor {
            delay_s: 1e-4,
            ..Default::default()
        },
        rigid_body: RigidBody::Integrators(2),
        ..Default::default()
    };
    let mut init = initial_model(&fd, &freqs, &cfg).unwrap();
    if std::env::args().any(|a| a == "truezeta") {
        // exact poles
        let mut m = AdditiveModel::new(4, 13, Domain::ZohDiscrete { ts: 1e-4 })
            .unwrap()
            .with_factor(KnownFactor {
                delay_s: 1e-4,
                ..Default::default()
            })
            .unwrap();
        m.push_rigid_body(2, 1.0).unwrap();
        for md in t.model.modes.iter() {
            m.push_mode(md.f_hz, md.zeta, false).unwrap();
        }
        init.model = m;
    }
    for bypass in [false, true] {
        let m = if bypass {
            augment::with_crosstalk(&init.model).unwrap()
        } else {
            augment::with_feedthrough(&init.model).unwrap()
        };
        let mut m = m;
        fit_numerators(&mut m, &fd).unwrap();
        let c0 = fit_numerators(&mut m.clone(), &fd).unwrap();
        eprintln!(
            "  numerator-only cost {c0:.4e} (noise level ~ {:.3e})",
            (band.n_lines() * 52) as f64
        );
        let m = if std::env::args().any(|a| a == "sk") {
            let f = AdditiveRiv::new(RivConfig {
                method: IvMethod::Sk,
                max_iterations: 10,
                ..Default::default()
            })
            .refine(m, &fd)
            .unwrap();
            eprintln!(
                "  sk: {} its {:?} cost {:?}",
                f.iterations,
                f.convergence,
                f.final_cost()
            );
            f.model
        } else {
            m
        };
        let f = AdditiveRiv::new(RivConfig::default())
            .refine(m, &fd)
            .unwrap();
        eprintln!(
            "bypass {bypass}: {} its {:?} cost {:?}",
            f.iterations,
            f.convergence,
            f.final_cost()
        );
        let g = frf_data::ModelStructure::response(&f.model, &band);
        let mut v: Vec<f64> = (0..band.n_lines() * 52)
            .map(|i| (g.values[i] - band.values_vec()[i]).norm() / band.values_vec()[i].norm())
            .collect();
        v.sort_by(|a, b| a.total_cmp(b));
        eprintln!("  median {:.3e}", v[v.len() / 2]);
    }
}
