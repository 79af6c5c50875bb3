//! The chip's memory layout where cortex-m-rt's linker script finds it: the STM32F405RG as
//! QEMU's netduinoplus2 models it, the QEMU board's (the helper and the layouts are in
//! `boards/chips/`).
include!("../boards/chips/memory_x.rs");

fn main() {
    memory_x("../boards/chips", "stm32f405rg");
}
