//! Puts the board's memory layout where the cortex-m-rt linker script finds it, and adds
//! defmt's linker script for the boards that log with defmt.
use std::{env, fs, path::PathBuf};

/// STM32F446RE (NUCLEO-F446RE): 512 KiB flash, 128 KiB RAM.
const F446RE: &str = "MEMORY\n{\n  FLASH : ORIGIN = 0x08000000, LENGTH = 512K\n  RAM   : ORIGIN = 0x20000000, LENGTH = 128K\n}\n";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    if env::var_os("CARGO_FEATURE_NUCLEO_F446RE").is_some() {
        fs::write(out.join("memory.x"), F446RE).expect("write memory.x");
        println!("cargo:rustc-link-arg=-Tdefmt.x");
    } else {
        // STM32F405RG as QEMU's netduinoplus2 models it.
        fs::copy("../memory.x", out.join("memory.x")).expect("copy ../memory.x");
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
}
