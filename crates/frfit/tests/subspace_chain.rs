//! `--init subspace` through the chain API on the reference wafer stage
//! (`../shared/data/wafer_nominal.csv`, exact 10 kHz hold and one sample of computation
//! delay declared): with `--refine none` and `--refine riv`, against the noiseless
//! response. Skipped, with a message, when the shared data are not beside the checkout.

use frf_data::io::read_frf_csv;
use frf_data::shared_data::require;
use frf_data::{ChainSettings, DelayChoice, FrfDataset};
use frfit::chain::{run_chain, AdditiveOptions};
use realize::{Hold, ResponseGrid};

fn grid(d: &dyn FrfDataset) -> ResponseGrid {
    let mut g = ResponseGrid::zeros(d.n_lines(), d.ny(), d.nu());
    for k in 0..d.n_lines() {
        d.line_into(k, g.line_mut(k));
    }
    g
}

#[test]
fn subspace_then_riv_on_the_wafer_stage() {
    let test = "subspace_then_riv_on_the_wafer_stage";
    let (Some(data), Some(clean)) = (
        require(test, "wafer_nominal.csv"),
        require(test, "wafer_nominal.noiseless.csv"),
    ) else {
        return;
    };
    faer::set_global_parallelism(faer::Par::Seq);
    let data = read_frf_csv(&data).unwrap();
    let clean = read_frf_csv(&clean).unwrap();
    let band = data.band(20.0, 2000.0).unwrap();
    let cband = clean.band(20.0, 2000.0).unwrap();
    let reference = grid(&cband);
    let settings = ChainSettings {
        hold: Hold::Zoh { fs_hz: 10_000.0 },
        delay: DelayChoice::Fixed { seconds: 100e-6 },
        ..Default::default()
    };
    let mut medians = Vec::new();
    for refine in ["none", "riv"] {
        let t = std::time::Instant::now();
        let r = run_chain(
            &band,
            "subspace",
            refine,
            &settings,
            &AdditiveOptions::default(),
        )
        .unwrap_or_else(|e| panic!("subspace+{refine}: {e}"));
        let (median, p95) = r
            .model
            .model
            .relative_error(&cband.omegas(), &reference)
            .unwrap();
        println!(
            "subspace+{refine}: median {median:.3e}, p95 {p95:.3e} vs noiseless, {} pole pairs, {:.2} s; chain {:?}",
            r.model.model.modal.pairs.len(),
            t.elapsed().as_secs_f64(),
            r.chain
        );
        assert_eq!(r.chain, vec!["subspace".to_string(), refine.to_string()]);
        medians.push(median);
    }
    assert!(
        medians[0] <= 1e-3,
        "subspace alone: median {:.3e}",
        medians[0]
    );
    assert!(
        medians[1] <= 6e-6,
        "subspace + riv: median {:.3e}",
        medians[1]
    );
}
