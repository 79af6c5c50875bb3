//! Size probe: the white-box bench and the NARMAX models in f32.
//! (`cargo xtask bench` reads its flash and RAM from the ELF; it also runs under QEMU and
//! exits 0).
#![no_std]
#![no_main]

mcu_bench::probe!(whitebox, narmax_f32);
