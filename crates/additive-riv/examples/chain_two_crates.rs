//! A program that depends on two frfit crates only (`frf-data` and `additive-riv`) and
//! chains an initialiser into a refiner through the shared `Estimator` trait:
//!
//! ```sh
//! cargo run --release -p additive-riv --example chain_two_crates -- DATA.csv 20 2000
//! ```
//!
//! Any refiner takes the model currency (`ChainModel`), so the CMIF start could come
//! from another initialiser as well; `fit.model.to_frf_model()` gives the currency
//! (`realize::FrfModel`) of the result.

use additive_riv::{CmifInit, RivRefine};
use frf_data::io::read_frf_csv;
use frf_data::{ChainModel, Estimator, ModelStructure};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 4 {
        eprintln!("usage: chain_two_crates DATA.csv LO_HZ HI_HZ");
        std::process::exit(2);
    }
    let data = read_frf_csv(&args[1])?;
    let band = data.band(args[2].parse()?, args[3].parse()?)?;
    let init = CmifInit::default().estimate(&band, ())?;
    println!(
        "init: {} CMIF peaks, {} modes",
        init.report.cmif_peaks.len(),
        init.model.modes().len()
    );
    let fit = RivRefine::default().estimate(&band, ChainModel::of(&init.model)?)?;
    let currency = fit.model.to_frf_model()?;
    println!(
        "riv: {} iterations, {}; {} modes, delay {:.2} us",
        fit.iterations,
        fit.convergence.describe(),
        currency.modal.pairs.len(),
        currency.factors.delay_s * 1e6
    );
    for p in &currency.modal.pairs {
        println!("  {:9.3} Hz  zeta {:.5}", p.f_hz(), p.zeta());
    }
    Ok(())
}
