//! The two boards' firmware images: which crate and binary, their flash and RAM budgets, and
//! their build (profile `firmware`, with `flip-link` as the linker).

use crate::util::{cargo, run, target_dir, Result, TARGET};
use std::path::PathBuf;
use std::process::Command;

/// A board's firmware image (profile `firmware`).
pub fn firmware_elf(board: Board) -> PathBuf {
    target_dir()
        .join(TARGET)
        .join("firmware")
        .join(board.binary())
}

/// Flash and static RAM budget of an image, bytes.
#[derive(Clone, Copy)]
pub struct Budget {
    /// Flash (text + rodata + data), bytes.
    pub flash: u64,
    /// Static RAM (data + bss), bytes.
    pub ram: u64,
}

/// The QEMU image's budget (the issue's: 64 KiB flash, 16 KiB static RAM).
pub const QEMU_BUDGET: Budget = Budget {
    flash: 64 * 1024,
    ram: 16 * 1024,
};
/// The NUCLEO-F446RE image's budget.
pub const NUCLEO_BUDGET: Budget = Budget {
    flash: 64 * 1024,
    ram: 16 * 1024,
};

/// The two boards the firmware builds for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Board {
    /// `boards/qemu`: the STM32F405 of QEMU's netduinoplus2.
    Qemu,
    /// `boards/nucleo-f446re`.
    Nucleo,
}

impl Board {
    /// The board as the steps name it.
    pub fn name(self) -> &'static str {
        match self {
            Board::Qemu => "qemu (STM32F405 netduinoplus2)",
            Board::Nucleo => "nucleo-f446re",
        }
    }
    /// The image's key in `mcu.json`.
    pub fn key(self) -> &'static str {
        match self {
            Board::Qemu => "qemu",
            Board::Nucleo => "nucleo-f446re",
        }
    }
    /// The image's flash and RAM budget.
    pub fn budget(self) -> Budget {
        match self {
            Board::Qemu => QEMU_BUDGET,
            Board::Nucleo => NUCLEO_BUDGET,
        }
    }
    /// The board's crate.
    pub fn package(self) -> &'static str {
        match self {
            Board::Qemu => "board-qemu",
            Board::Nucleo => "board-nucleo-f446re",
        }
    }
    /// What the board's own `.cargo/config.toml` adds, for builds from the workspace root
    /// (the Nucleo: `-C target-cpu=cortex-m4`), with the trimmed paths
    /// ([`crate::util::mcu_rustflags`]: one `--config` for the target's flags).
    pub fn config_args(self) -> Vec<String> {
        match self {
            Board::Qemu => vec![],
            Board::Nucleo => crate::util::mcu_rustflags(&["-C", "target-cpu=cortex-m4"]),
        }
    }
    /// The board's firmware binary.
    pub fn binary(self) -> &'static str {
        match self {
            Board::Qemu => "pump-qemu",
            Board::Nucleo => "pump-nucleo-f446re",
        }
    }
}

/// `flip-link` (the linker `.cargo/config.toml` names for the MCU: it puts the stack below
/// the static data, so an overflow faults instead of corrupting them), installed with
/// `cargo install --locked` (≈ 10 s) if it is not on the PATH.
pub fn ensure_flip_link() -> Result {
    if Command::new("flip-link").arg("--version").output().is_ok() {
        return Ok(());
    }
    run(
        "install flip-link (the MCU images' linker)",
        cargo().args(["install", "--locked", "flip-link"]),
    )
}

/// Builds `board`'s firmware image (profile `firmware`, defmt level `info`) at
/// [`firmware_elf`].
pub fn build_firmware(board: Board) -> Result {
    build_with(board, &[])
}

/// The NUCLEO-F446RE image with feature `record` (the commissioning record over RTT), at
/// [`firmware_elf`] in place of the ordinary one.
pub fn build_nucleo_record() -> Result {
    build_with(Board::Nucleo, &["--features", "record"])
}

/// [`build_firmware`] with cargo's `extra` arguments.
fn build_with(board: Board, extra: &[&str]) -> Result {
    ensure_flip_link()?;
    run(
        &format!(
            "firmware build for {} (profile firmware: opt-level s, LTO)",
            board.name()
        ),
        cargo()
            .args([
                "build",
                "-p",
                board.package(),
                "--profile",
                "firmware",
                "--target",
                TARGET,
            ])
            .args(extra)
            .args(board.config_args())
            .env("DEFMT_LOG", "info"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boards() {
        assert_eq!(Board::Qemu.binary(), "pump-qemu");
        assert_eq!(Board::Nucleo.binary(), "pump-nucleo-f446re");
        for b in [Board::Qemu, Board::Nucleo] {
            let elf = firmware_elf(b);
            assert!(elf.ends_with(format!("{TARGET}/firmware/{}", b.binary())));
            // The board's crate is a workspace member of that name.
            let dir = match b {
                Board::Qemu => "qemu",
                Board::Nucleo => "nucleo-f446re",
            };
            let manifest = std::fs::read_to_string(
                crate::util::root()
                    .join("boards")
                    .join(dir)
                    .join("Cargo.toml"),
            )
            .unwrap();
            assert!(manifest.contains(&format!("name = \"{}\"", b.package())));
            assert!(manifest.contains(&format!("name = \"{}\"", b.binary())));
        }
        // Only the Nucleo adds the CPU (the QEMU images are measured without it).
        assert!(Board::Qemu.config_args().is_empty());
        let nucleo = Board::Nucleo.config_args().concat();
        assert!(nucleo.contains("target-cpu=cortex-m4") && nucleo.contains("--remap-path-prefix"));
    }
}
