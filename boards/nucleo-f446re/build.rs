//! The chip's memory layout (STM32F446RE) where cortex-m-rt's linker script finds it, and
//! defmt's linker script.
include!("../chips/memory_x.rs");

fn main() {
    memory_x("../chips", "stm32f446re");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
