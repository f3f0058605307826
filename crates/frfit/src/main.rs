//! The `frfit` command-line tool. Each subcommand lives in its own module of `cli/`.

mod cli;

/// mimalloc keeps the pages it frees for the next allocations: a large fit allocates
/// and frees matrices of tens to hundreds of megabytes per iteration, which through
/// the system allocator are fresh mappings every time (the kernel zeroing their pages:
/// 8-10 s of system time in the 50-60 s of CPU time of a 50 x 50 fit).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    // faer's own threads are slower than one on 2-core machines (STACK.md); frfit
    // parallelises over entries with rayon instead.
    faer::set_global_parallelism(faer::Par::Seq);
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
