//! The structure adaptation ([`additive_riv::adapt_modes`]) reports its changes as typed
//! structure steps (issue 42): a start that misses a mode gets it back at its residual
//! peak, and the step says so with the weighted cost before and after, on the lines it
//! was fitted to and on interleaved held-out lines.

mod common;

use additive_riv::{adapt_modes, fit_numerators, AdaptConfig, Domain, FitData, RivConfig};
use common::*;
use frf_data::structure::StructureChange;
use frf_data::Weighting;

#[test]
fn a_mode_the_start_missed_is_a_modes_added_step_with_its_costs() {
    for seed in [2u64, 5, 9] {
        let case = random_case(seed, 2, 2, 4, false, Domain::Continuous);
        let data = simulate(&case.truth, &case.freqs, 1e-4, seed);
        let fd = FitData::new(&data, &Weighting::InverseVariance).unwrap();
        // the start misses the most lightly damped mode (a resonance that stands out of
        // the residual; a broad one does not pass the adaptation's local peak test)
        let q = (0..case.mode_zeta.len())
            .min_by(|&a, &b| case.mode_zeta[a].total_cmp(&case.mode_zeta[b]))
            .unwrap();
        let mut start = perturbed_start(&case, 0.005, seed);
        start.remove_submodel(q);
        fit_numerators(&mut start, &fd).unwrap();
        let missed = case.mode_f[q];
        println!(
            "modes {:?} zeta {:?} band {:?}, {} submodels in the start",
            case.mode_f,
            case.mode_zeta,
            fd.band_hz,
            start.submodels.len()
        );
        let (fit, report) =
            adapt_modes(start, &fd, &RivConfig::default(), &AdaptConfig::default()).unwrap();
        println!(
            "seed {seed}: missed {missed:.2} Hz; steps {:#?}\n{}",
            report.steps,
            fit.messages.join("\n")
        );
        let added: Vec<_> = report
            .steps
            .iter()
            .filter(|s| s.accepted && matches!(s.change, StructureChange::ModesAdded { .. }))
            .collect();
        assert!(!added.is_empty(), "seed {seed}: no modes_added step");
        let near = added.iter().find(|s| match &s.change {
            StructureChange::ModesAdded { start_hz } => {
                start_hz.iter().any(|f| (f / missed - 1.0).abs() < 0.02)
            }
            _ => false,
        });
        let step = near.unwrap_or_else(|| panic!("seed {seed}: no step at {missed:.2} Hz"));
        let after = step.cost_after.expect("the trial's cost");
        assert!(
            after < 1e-2 * step.cost_before,
            "seed {seed}: cost {:.3e} -> {after:.3e}",
            step.cost_before
        );
        // the addition was checked on interleaved held-out lines, and lowered the cost
        // there too
        let h = step
            .held_out
            .unwrap_or_else(|| panic!("seed {seed}: no held-out check"));
        assert!(
            h.after < 1e-2 * h.before,
            "seed {seed}: held-out cost {:.3e} -> {:.3e}",
            h.before,
            h.after
        );
        // the accepted additions are the modes the report lists as added
        assert_eq!(
            report.added.len(),
            fit.model
                .submodels
                .iter()
                .filter(|s| s.kind == additive_riv::SubmodelKind::Mode)
                .count()
                - 3,
            "seed {seed}"
        );
    }
}
