//! Size probe: the runtime and model-core's white-box bench in f32 (steady state, RK4,
//! Heun and Euler steps, signals).
//! (`cargo xtask bench` reads its flash and RAM from the ELF; it also runs under QEMU and
//! exits 0).
#![no_std]
#![no_main]

mcu_bench::probe!(whitebox);
