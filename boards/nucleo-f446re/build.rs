//! The chip's memory layout (STM32F446RE) where cortex-m-rt's linker script finds it, and
//! defmt's linker script.

fn main() {
    board_chips::memory_x("stm32f446re");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
