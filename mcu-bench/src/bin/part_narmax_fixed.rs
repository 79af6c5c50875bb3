//! Size probe: the white-box bench, the NARMAX models' f32 and Q15 passes (compile-time
//! statics, as the controller has them).
//! (`cargo xtask bench` reads its flash and RAM from the ELF; it also runs under QEMU and
//! exits 0).
#![no_std]
#![no_main]

use mcu_bench::parts;

#[cortex_m_rt::entry]
fn main() -> ! {
    parts::exit(
        parts::whitebox()
            .and_then(|()| parts::narmax_f32())
            .and_then(|()| parts::narmax_fixed())
            .is_ok(),
    )
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    parts::exit(false)
}
