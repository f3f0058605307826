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
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).cloned().unwrap_or("wafer_nominal".into());
    let dir = frf_data::shared_data::shared_data_dir().unwrap();
    let t0 = Instant::now();
    let data = frf_data::io::read_frf_csv(dir.join(format!("{name}.csv"))).unwrap();
    let clean = frf_data::io::read_frf_csv(dir.join("wafer_nominal.noiseless.csv")).unwrap();
    let truth = frf_data::truth::Truth::read(dir.join(format!("{name}.truth.json"))).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let cband = clean.band(20.0, 2000.0).unwrap();
    let mut cfg = FitterConfig::default();
    if args.iter().any(|a| a == "zoh") {
        cfg.hold = Hold::Zoh { fs_hz: 10000.0 };
    }
    if args.iter().any(|a| a == "mag") {
        cfg.riv.weighting = Weighting::InverseMagnitude;
    }
    if args.iter().any(|a| a == "noadapt") {
        cfg.adapt = None;
    }
    if args.iter().any(|a| a == "ft") {
        cfg.feedthrough = true;
    }
    if args.iter().any(|a| a == "truemodes") {
        let t = frf_data::truth::Truth::read(dir.join(format!("{name}.truth.json"))).unwrap();
        cfg.modes = ModeSelection::Frequencies(
            t.model
                .modes
                .iter()
                .map(|m| m.f_hz)
                .filter(|&f| f < 2000.0)
                .collect(),
        );
    }
    if args.iter().any(|a| a == "fixdelay") {
        cfg.delay = DelayChoice::Fixed { seconds: 150e-6 };
    }
    if let Some(n) = args.iter().find_map(|a| a.strip_prefix("modes=")) {
        cfg.modes = ModeSelection::Count(n.parse().unwrap());
    }
    cfg.riv.progress = frf_data::ProgressSink::new(|p| {
        eprintln!(
            "    it {} cost {:.6e} {}",
            p.step,
            p.cost.unwrap_or(0.0),
            p.message
        )
    });
    cfg.progress = frf_data::ProgressSink::new(|p| {
        eprintln!("  [{}] {} {:?} {}", p.stage, p.step, p.cost, p.message)
    });
    let t = Instant::now();
    let (fit, rep) = AdditiveFitter::new(cfg).fit(&band).unwrap();
    eprintln!(
        "fit {:?} (total {:?}): {} its, {:?}",
        t.elapsed(),
        t0.elapsed(),
        fit.iterations,
        fit.convergence
    );
    for m in &fit.messages {
        eprintln!("  msg: {m}");
    }
    eprintln!("  timings: {:?}", fit.timings);
    eprintln!(
        "  cmif peaks: {:?}",
        rep.cmif_peaks
            .iter()
            .map(|p| (p.f_hz * 100.0).round() / 100.0)
            .collect::<Vec<_>>()
    );
    eprintln!(
        "  delay: {:?} fitted {}",
        rep.delay_estimate.as_ref().map(|d| d.tau_s),
        fit.model.factor.delay_s
    );
    eprintln!(
        "  refinements: {:?}",
        rep.adapt.as_ref().map(|a| a.refinements.clone())
    );
    let tf: Vec<f64> = truth.model.modes.iter().map(|m| m.f_hz).collect();
    let tz: Vec<f64> = truth.model.modes.iter().map(|m| m.zeta).collect();
    let mut worst_f: f64 = 0.0;
    let mut worst_z: f64 = 0.0;
    let mut matched = 0;
    for md in fit.model.modes() {
        let mi = (0..tf.len())
            .min_by(|&a, &b| (tf[a] - md.f_hz).abs().total_cmp(&(tf[b] - md.f_hz).abs()))
            .unwrap();
        let ef = (md.f_hz / tf[mi] - 1.0).abs();
        let ez = (md.zeta / tz[mi] - 1.0).abs();
        if ef < 1e-3 {
            matched += 1;
            worst_f = worst_f.max(ef);
            worst_z = worst_z.max(ez);
        } else {
            eprintln!("  unmatched mode {:.2} Hz zeta {:.4}", md.f_hz, md.zeta);
        }
    }
    eprintln!(
        "modes {} matched {matched}/17; worst df {worst_f:.2e} dz {worst_z:.2e}",
        fit.model.modes().len()
    );
    if name == "wafer_nominal" {
        let (a, b) = rel_errs(&fit.model, &cband);
        eprintln!("vs noiseless: median {a:.3e} p95 {b:.3e}");
    }
    let (a, b) = rel_errs(&fit.model, &band);
    eprintln!("vs data: median {a:.3e} p95 {b:.3e}");
    eprintln!("order {}", fit.model.to_modal_model().unwrap().order(1e-6));
    rank_ratios(&fit.model);
}
#[allow(dead_code)]
fn rank_ratios(model: &AdditiveModel) {
    let mm = model.to_modal_model().unwrap();
    for p in &mm.pairs {
        let sv = p.residue.singular_values().unwrap();
        eprintln!(
            "  {:8.2} Hz sv ratios {:?}",
            p.f_hz(),
            sv.iter().map(|s| s / sv[0]).take(3).collect::<Vec<_>>()
        );
    }
    let sv: Vec<f64> = mm.rigid.last().unwrap().singular_values().unwrap();
    eprintln!(
        "  rigid sv ratios {:?}",
        sv.iter().map(|s| s / sv[0]).collect::<Vec<_>>()
    );
}
