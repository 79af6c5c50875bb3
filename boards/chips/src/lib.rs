//! The one way an MCU image gets its chip's memory layout: the build scripts of the crates
//! that link one (`boards/*/build.rs`, `mcu-bench/build.rs`) have this crate as a build
//! dependency and call [`memory_x`]. One layout per distinct chip lives in this crate's folder
//! (`<chip>.x`: `stm32f405rg.x` for QEMU's netduinoplus2 and `mcu-bench`, `stm32f446re.x` for
//! the NUCLEO-F446RE); none is called `memory.x`, so no copy at the workspace root (the
//! linker's working directory, searched first) can stand in for the right one.

use std::path::{Path, PathBuf};

/// Copies this crate's `<chip>.x` to `OUT_DIR/memory.x` (the calling build script's), where
/// cortex-m-rt's `link.x` includes it, adds `OUT_DIR` to the link search path and reruns the
/// build script when the layout changes. For build scripts only (it panics with the reason
/// if the layout cannot be copied: a build error).
pub fn memory_x(chip: &str) {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR"));
    let layout = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("{chip}.x"));
    std::fs::copy(&layout, out.join("memory.x"))
        .unwrap_or_else(|e| panic!("copy {} to OUT_DIR/memory.x: {e}", layout.display()));
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", layout.display());
    println!("cargo:rerun-if-changed=build.rs");
}
