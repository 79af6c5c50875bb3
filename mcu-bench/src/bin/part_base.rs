//! Size probe: the runtime alone (cortex-m-rt's start-up, a semihosting exit, a panic handler that
//! prints nothing), the floor the other probes are measured from.
//! (`cargo xtask bench` reads its flash and RAM from the ELF; it also runs under QEMU and
//! exits 0).
#![no_std]
#![no_main]

mcu_bench::probe!();
