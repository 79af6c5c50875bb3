//! Size probe: the white-box bench, the NARMAX models' f32 and Q15 passes (compile-time
//! statics, as the controller has them).
//! (`cargo xtask bench` reads its flash and RAM from the ELF; it also runs under QEMU and
//! exits 0).
#![no_std]
#![no_main]

mcu_bench::probe!(whitebox, narmax_f32, narmax_fixed);
