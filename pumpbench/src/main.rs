//! `pumpbench`: the host tool for the pump bench models.
//!
//! Exit codes: 0 success; 2 bad command line or bad input file (one-line error on stderr,
//! no output file left behind), including an output that is one of the inputs or that cannot
//! be written (checked before any input is read); 1 any other failure (e.g. writing the output
//! fails part way).

// `!(x > 0.0)` is deliberate: unlike `x <= 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod benchdata;
mod cli;
mod commands;
mod control;
mod error;
mod excite;
mod export;
mod input;
mod modelfile;
mod narmaxcmd;
mod num;
mod observe;
mod output;
mod plant;
mod plots;
mod sensorlag;
mod simulate;
mod study;
mod train;
mod vfdsim;

use clap::Parser;
use cli::{Cli, Command};
use error::Failure;
use std::process::ExitCode;

/// Runs `command`.
fn run(command: Command) -> Result<(), Failure> {
    match command {
        Command::Identify(a) => commands::identify(a),
        Command::Validate(a) => commands::validate(a),
        Command::Observe(a) => observe::command(&a.data, a.precision, a.output.as_deref()),
        Command::Excite(a) => commands::excite(a),
        Command::VfdSim(a) => commands::vfd_sim(a),
        Command::Export(a) => commands::export(a),
        Command::BenchData(a) => commands::bench_data(a),
        Command::Study(a) => commands::study(a),
        Command::Simulate(a) => commands::simulate(a),
        Command::Steady(a) => commands::steady(a),
        Command::Control(a) => control::command(a),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("pumpbench: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}
