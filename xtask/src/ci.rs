//! `cargo xtask test`: everything CI checks, in order: rustfmt, clippy `-D warnings` (host,
//! both firmware boards and mcu-bench), the no_std crates built for the MCU, the host tests,
//! docs, the bench and its budgets (both firmware images), the on-target checks, QEMU runs
//! against the host replay (one with the commissioning record's rows), the commissioning
//! procedure end to end (`commission-check`), the plant protocol's check (host and QEMU bit for bit,
//! `examples/plant.py` on both), the end-to-end test with `mbpoll`, and the flood.

use crate::bench;
use crate::board::{build_firmware, firmware_elf, Board};
use crate::commission::commission_check;
use crate::e2e;
use crate::flood::{flood, FLOOD_S};
use crate::plant_session::plant_check;
use crate::replay::{replay, selftest};
use crate::util::{cargo, run, Result, TARGET};
use std::time::Instant;

/// `cargo xtask test`: every step in order, stopping at the first that fails.
pub fn test() -> Result {
    let start = Instant::now();
    run("rustfmt", cargo().args(["fmt", "--all", "--check"]))?;
    run(
        "clippy (host)",
        cargo().args(["clippy", "--all-targets", "--", "-D", "warnings"]),
    )?;
    for board in [Board::Qemu, Board::Nucleo] {
        run(
            &format!("clippy (board {})", board.name()),
            cargo()
                .args(["clippy", "-p", board.package(), "--target", TARGET])
                .args(board.config_args())
                .args(["--profile", "firmware", "--", "-D", "warnings"]),
        )?;
    }
    run(
        "clippy (board nucleo-f446re, the commissioning record over RTT)",
        cargo()
            .args([
                "clippy",
                "-p",
                Board::Nucleo.package(),
                "--features",
                "record",
            ])
            .args(["--target", TARGET])
            .args(Board::Nucleo.config_args())
            .args(["--profile", "firmware", "--", "-D", "warnings"]),
    )?;
    run(
        "clippy (board qemu, plant mode)",
        cargo()
            .args([
                "clippy",
                "-p",
                "board-qemu",
                "--features",
                "plant",
                "--target",
                TARGET,
            ])
            .args(["--profile", "firmware", "--", "-D", "warnings"]),
    )?;
    run(
        "clippy (mcu-bench, profile firmware)",
        cargo().args([
            "clippy",
            "-p",
            "mcu-bench",
            "--target",
            TARGET,
            "--profile",
            "firmware",
            "--",
            "-D",
            "warnings",
        ]),
    )?;
    run(
        "no_std crates build for the MCU (model-core, controller)",
        cargo().args([
            "build",
            "-p",
            "model-core",
            "-p",
            "controller",
            "--target",
            TARGET,
        ]),
    )?;
    run("host tests", cargo().args(["test"]))?;
    run(
        "doc (model-core, controller, warnings denied)",
        cargo()
            .args(["doc", "--no-deps", "-p", "model-core", "-p", "controller"])
            .env("RUSTDOCFLAGS", "-D warnings"),
    )?;
    eprintln!("==> bench: kernels in QEMU, image sizes, budgets");
    bench::run_bench(&bench::Options::default())?;
    let elf = firmware_elf(Board::Qemu);
    build_firmware(Board::Qemu)?;
    eprintln!("==> on-target checks in QEMU (boards/qemu selftest)");
    print!("{}", selftest()?);
    replay(&elf)?;
    eprintln!("==> commissioning end to end: record 600 s, identify, export, rebuild, residuals");
    print!("{}", commission_check()?);
    plant_check()?;
    eprintln!("==> end to end: QEMU in real time, SCADA on a pty, mbpoll as the client");
    print!("{}", e2e::run(&elf)?);
    eprintln!("==> SCADA flooded, the VFD on USART2 busy: in real time, then -icount shift=0");
    print!("{}", flood(&elf, FLOOD_S, false)?);
    print!("{}", flood(&elf, FLOOD_S, true)?);
    eprintln!(
        "all checks passed in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
