//! The chip's memory layout (STM32F405RG, QEMU's netduinoplus2) where cortex-m-rt's linker
//! script finds it, and defmt's linker script.
include!("../chips/memory_x.rs");

fn main() {
    memory_x("../chips", "stm32f405rg");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
