//! The on-target checks, in QEMU (`cargo xtask test` runs them and compares the digests with
//! the host's): the bits of `libm`'s f32 functions and of the model's tanh (its Q15 table
//! whole), the tanh table's error, the RTU framer, and the fault handler. A USART loopback is
//! not among them: QEMU 7.2 cannot connect a USART's output to its input.
//!
//! Each check logs `check <name>: ok …` or `check <name>: FAILED …`; the run ends with
//! `selftest: N checks, M failed` and exits 0 only if none failed. With the argument `fault`
//! it instead reads an unmapped address, to show the HardFault handler's report and exit 1.
#![no_std]
// The board is where the hardware is: register reads and writes the HAL does not wrap, the
// fault handler. Each `unsafe` block says why it is sound.
#![allow(unsafe_code)]
#![no_main]

use board_common::selftest;
use board_qemu::{args::command_line, exit};
use stm32f4xx_hal as _; // the device's interrupt vectors

#[cortex_m_rt::entry]
fn main() -> ! {
    let mut buf = [0u8; 64];
    if command_line(&mut buf).ends_with(b"fault") {
        defmt::info!("selftest: reading 0xFFFF_FFF0 (a bus fault)");
        // SAFETY: none; the read faults on purpose, and the HardFault handler ends the run.
        let v = unsafe { core::ptr::read_volatile(0xFFFF_FFF0 as *const u32) };
        defmt::error!("the read returned {=u32}: no fault", v);
        exit(false);
    }
    let mut failed = 0;
    let mut checks = 0;
    for (name, digest) in selftest::digests() {
        checks += 1;
        defmt::info!("digest {=str}={=u32:#010x}", name, digest);
    }
    let mut check = |name: &str, r: Result<(), &'static str>| {
        checks += 1;
        match r {
            Ok(()) => defmt::info!("check {=str}: ok", name),
            Err(why) => {
                failed += 1;
                defmt::error!("check {=str}: FAILED: {=str}", name, why)
            }
        }
    };
    let table = selftest::tanh_table();
    if let Ok(worst) = table {
        defmt::info!("tanh_q15 against libm::tanhf: largest error {=f32}", worst);
    }
    check("tanh_table", table.map(|_| ()));
    check("rtu_framer", selftest::framer());
    defmt::info!("selftest: {=u32} checks, {=u32} failed", checks, failed);
    exit(failed == 0)
}
