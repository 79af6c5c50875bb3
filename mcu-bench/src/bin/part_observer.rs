//! Size probe: the white-box bench, both NARMAX passes, the observer (f32) and the alarm
//! monitor: all of model-core the controller uses.
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
            .and_then(|()| parts::observer())
            .is_ok(),
    )
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    parts::exit(false)
}
