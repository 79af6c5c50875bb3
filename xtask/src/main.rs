//! Project tasks, run as `cargo xtask <task>`:
//!
//! - `qemu`: build the firmware for QEMU and run it on the virtual bench: a deterministic run
//!   (`-icount`), or with `--scada-pty` in real time until stopped, the SCADA slave on a
//!   pseudo-terminal.
//! - `record`: the commissioning record ([`record`](mod@record)): the controller in the
//!   excitation mode, a row per pressure sample, to the CSV `pumpbench identify` reads.
//! - `bench`: the kernels' instructions per call on the MCU (mcu-bench under QEMU), the
//!   images' and model-core's parts' size from their ELF, checked against
//!   `bench/baseline.json` and the size budgets (see [`bench`](mod@bench)).
//! - `test`: everything CI checks: rustfmt, clippy `-D warnings` (host, both firmware boards
//!   and mcu-bench), the no_std crates built for the MCU, the host tests, docs, the bench and
//!   its budgets (both firmware images), QEMU runs whose every log line must equal the same
//!   loop replayed on the host bit for bit, and an end-to-end test with `mbpoll` on the SCADA
//!   port.
//!
//! - `replay`, `e2e`, `flood`: one part of `test` alone (the on-target checks and the QEMU
//!   runs against the host replay; the end-to-end test; the flood).
//!
//! - `plant-check`: the plant protocol ([`plant_session`]): a scenario plant against the host's
//!   session and the QEMU board in plant mode, every reply identical bit for bit, and
//!   `examples/plant.py` against both (part of `test`); `plant-stdio`: the controller's side
//!   of the protocol on standard input and output, for a plant that runs it as its child.
//!
//! Needs `qemu-system-arm` and `mbpoll` on the PATH (Debian packages of the same names).
//!
//! This file only dispatches. The tasks: [`qemu_task`], [`bench`](mod@bench), [`ci`] (`test`),
//! [`replay`], [`e2e`] (with [`observe_session`], [`protection_session`] and [`line`](mod@line)'s
//! checks, `mbpoll` through [`mbpoll`]), [`flood`](mod@flood). What they share: [`util`] (cargo, paths,
//! a step run, `key=value` fields), [`board`] (the boards' images and their build), [`qemu`]
//! (QEMU's runs, deterministic or real time), [`defmt_log`] (the logs decoded), [`bridge`]
//! (the SCADA pty's bridge), [`elf`] (an image's sizes and symbols).

mod bench;
mod board;
mod bridge;
mod ci;
mod commission;
mod defmt_log;
mod e2e;
mod elf;
mod flood;
mod line;
mod mbpoll;
mod observe_session;
mod plant_session;
mod protection_session;
mod qemu;
mod qemu_task;
mod record;
mod replay;
mod util;

use board::{build_firmware, firmware_elf, Board};
use flood::{flood, FLOOD_S};
use std::process::ExitCode;
use util::Result;

/// `cargo xtask`'s usage (with no task or an unknown one).
fn usage() -> String {
    format!("usage: cargo xtask <qemu|record|commission-check|bench|test|replay|e2e|flood|plant-check|plant-stdio>\n  qemu   build the firmware and run it in QEMU on the virtual bench\n  record the commissioning record: the controller's samples in the excitation mode to a CSV for pumpbench identify\n  commission-check  the commissioning procedure end to end: record 600 s, identify, export, rebuild; the residuals must drop\n  bench  the kernels' instructions per call on the MCU, image sizes, checked against bench/baseline.json and the budgets\n  test   fmt, clippy, tests, the bench and its budgets, QEMU runs against the host, mbpoll end to end\n  replay only the on-target checks and the QEMU runs against the host replay\n  e2e    only the mbpoll end-to-end test\n  flood  only the margins under a SCADA flood with the VFD link busy\n  plant-check  the plant protocol: a scenario plant against the host and the QEMU board, bit for bit; examples/plant.py against both\n  plant-stdio  the controller's side of the plant protocol on stdin/stdout (e.g. python3 examples/plant.py -- cargo xtask plant-stdio)\n{}\n{}", qemu_task::QEMU_USAGE, bench::BENCH_USAGE)
}

/// Runs the task `args[0]` with its arguments.
fn dispatch(args: &[String]) -> Result {
    match args.first().map(String::as_str) {
        Some("qemu") => qemu_task::qemu(&args[1..]),
        Some("test") => ci::test(),
        Some("plant-stdio") => plant_session::plant_stdio(),
        Some("plant-check") => plant_session::plant_check(),
        Some("record") => record::record(&args[1..]),
        Some("commission-check") => commission::commission_check().map(|r| print!("{r}")),
        Some("bench") => bench::run_bench(&bench::Options::parse(&args[1..])?),
        Some("flood") => build_firmware(Board::Qemu).and_then(|()| {
            print!("{}", flood(&firmware_elf(Board::Qemu), FLOOD_S, false)?);
            print!("{}", flood(&firmware_elf(Board::Qemu), FLOOD_S, true)?);
            Ok(())
        }),
        Some("replay") => build_firmware(Board::Qemu).and_then(|()| {
            print!("{}", replay::selftest()?);
            replay::replay(&firmware_elf(Board::Qemu))
        }),
        Some("e2e") => build_firmware(Board::Qemu).and_then(|()| {
            print!("{}", e2e::run(&firmware_elf(Board::Qemu))?);
            Ok(())
        }),
        _ => Err(usage()),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match dispatch(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::args;

    #[test]
    fn usage_and_bad_arguments() {
        // Nothing is built or run before the arguments are checked.
        assert_eq!(dispatch(&[]), Err(usage()));
        assert_eq!(dispatch(&args("tests")), Err(usage()));
        let u = usage();
        for task in [
            "qemu",
            "record",
            "commission-check",
            "bench",
            "test",
            "replay",
            "e2e",
            "flood",
            "plant-check",
            "plant-stdio",
        ] {
            assert!(u.contains(&format!("\n  {task} ")), "{task}");
        }
        assert!(u.ends_with(bench::BENCH_USAGE));
        assert!(u.contains(qemu_task::QEMU_USAGE));
        let e = dispatch(&args("bench --check")).unwrap_err();
        assert!(
            e.starts_with("unknown option '--check'\nusage: cargo xtask bench"),
            "{e}"
        );
        let e = dispatch(&args("qemu --seconds 2 --verbose")).unwrap_err();
        assert!(
            e.starts_with("unknown option '--verbose'\nusage: cargo xtask qemu"),
            "{e}"
        );
    }
}
