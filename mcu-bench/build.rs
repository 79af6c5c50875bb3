//! The chip's memory layout where cortex-m-rt's linker script finds it: the STM32F405RG as
//! QEMU's netduinoplus2 models it, the QEMU board's (the helper and the layouts are the
//! `board-chips` crate, `boards/chips/`).

fn main() {
    board_chips::memory_x("stm32f405rg");
}
