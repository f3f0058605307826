//! The `frfit` command-line tool. Each subcommand lives in its own module of `cli/`.

mod cli;

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
