//! Size probe: the white-box bench, both NARMAX passes, the observer (f32) and the alarm
//! monitor: all of model-core the controller uses.
//! (`cargo xtask bench` reads its flash and RAM from the ELF; it also runs under QEMU and
//! exits 0).
#![no_std]
#![no_main]

mcu_bench::probe!(whitebox, narmax_f32, narmax_fixed, observer);
