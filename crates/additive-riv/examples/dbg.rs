use additive_riv::*;
fn main() {
    let p = std::env::args().nth(1).unwrap();
    let data = frf_data::io::read_frf_csv(&p).unwrap();
    for start_us in [80.0, 80.001, 79.9, 62.2] {
        let cfg = FitterConfig {
            delay: DelayChoice::Fixed { seconds: 80e-6 },
            ..Default::default()
        };
        let (f, _) = AdditiveFitter::new(cfg).fit(&data).unwrap();
        let mut m = f.model.clone();
        m.factor.delay_s = start_us * 1e-6;
        m.factor.fit_delay = true;
        let fd = FitData::new(&data, &frf_data::Weighting::InverseMagnitude).unwrap();
        fit_numerators(&mut m, &fd).unwrap();
        let r = AdditiveRiv::new(RivConfig::default())
            .refine(m, &fd)
            .unwrap();
        println!(
            "start {start_us} us -> {:.6} us, cost {:?}, {} its {:?}",
            r.model.factor.delay_s * 1e6,
            r.cost_history.last(),
            r.iterations,
            r.convergence
        );
    }
}
