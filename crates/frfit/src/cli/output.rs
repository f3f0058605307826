//! Printing the summary of a fit (the files are written by
//! [`PipelineOutput::write_outputs`]).

use frfit::run::PipelineOutput;

/// Prints the modes and the error of a fit.
pub fn print_fit(out: &PipelineOutput) {
    let s = &out.summary;
    println!(
        "{}: {}x{}, {} lines, band {:.4}..{:.4} Hz, noise {}",
        s.data.path,
        s.data.ny,
        s.data.nu,
        s.data.lines,
        s.data.band_hz[0],
        s.data.band_hz[1],
        s.data.noise_source
    );
    for m in &out.fit.messages {
        println!("  {m}");
    }
    println!(
        "{} modes, order {}, delay {:.3} us, hold {}; {} iterations, {}",
        s.final_model.modes.len(),
        s.final_model.order,
        s.final_model.delay_s * 1e6,
        s.final_model.hold,
        out.fit.iterations,
        out.fit.convergence.describe()
    );
    if !out.fit.convergence.is_converged() {
        eprintln!(
            "warning: the fit did NOT converge ({}). The model is written, but check it; to try: \
             `--method sk` (more robust far from the optimum), fewer modes (`--modes N`), a \
             narrower band (`--band LO:HI`), or `--weighting magnitude`",
            out.fit.convergence.describe()
        );
    }
    match &s.uncertainty {
        Some(u) => {
            println!("     f [Hz]   +- 2 sigma        zeta   +- 2 sigma");
            for m in &s.final_model.modes {
                match u.mode_std(m.f_hz) {
                    Some((sf, sz)) => println!(
                        "  {:>10.4}  {:>10.2e}  {:>10.5}  {:>10.2e}",
                        m.f_hz,
                        2.0 * sf,
                        m.zeta,
                        2.0 * sz
                    ),
                    None => println!("  {:>10.4}  {:>10}  {:>10.5}", m.f_hz, "", m.zeta),
                }
            }
            for line in u.factor_lines() {
                println!("  dynamics factor, {line}");
            }
            match u.p_value {
                Some(p) => println!(
                    "uncertainty from {} ({}), cost ratio V/N_dof {:.3} (expected {:.3}, p = {p:.2e})",
                    u.source(), u.noise, u.cost_ratio, u.expected_ratio
                ),
                // without a measured variance the ratio is the noise scale itself: it
                // scales the covariance and tests nothing
                None => println!(
                    "uncertainty from {} ({}), noise scale V/N_dof {:.3e} of the weighted residual scales the covariance (no goodness-of-fit test without a measured variance)",
                    u.source(), u.noise, u.cost_ratio
                ),
            }
        }
        None => {
            println!("     f [Hz]      zeta");
            for m in &s.final_model.modes {
                println!("  {:>10.4}  {:>8.5}", m.f_hz, m.zeta);
            }
        }
    }
    println!(
        "error vs data: median {:.3e}, p95 {:.3e}, residual/noise {:.3}{}",
        s.final_errors.median_rel,
        s.final_errors.p95_rel,
        s.final_errors.residual_to_noise,
        s.data_noise_median_rel
            .map(|n| format!(" (data noise median {n:.3e})"))
            .unwrap_or_default()
    );
}
