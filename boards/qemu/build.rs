//! The chip's memory layout (STM32F405RG, QEMU's netduinoplus2) where cortex-m-rt's linker
//! script finds it, and defmt's linker script.

fn main() {
    board_chips::memory_x("stm32f405rg");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
