//! What the QEMU board's binaries share: the time bases, the fault and panic handlers that
//! report and exit QEMU with status 1, the start-up arguments.
#![no_std]
// The board is where the hardware is: register reads and writes the HAL does not wrap, the
// fault handler. Each `unsafe` block says why it is sound.
#![allow(unsafe_code)]

pub mod args;

use defmt_semihosting as _;
use stm32f4xx_hal::pac;

/// SysTick under QEMU, Hz (QEMU clocks it at 168 MHz whatever the RCC says).
pub const QEMU_SYSTICK_HZ: u32 = 168_000_000;
/// SysTick rate, Hz: four wake-ups per control step (see the module docs).
pub const WAKE_HZ: u32 = 4000;
/// Silence that ends an RTU frame under QEMU, µs: QEMU hands over one byte each time the
/// guest reads the last one, with no line timing, and a busy host can delay a byte by a few
/// milliseconds; 10 ms keeps frames whole and is far below any master's timeout.
pub const QEMU_SILENCE_US: u32 = 10_000;

/// Microseconds from TIM5 running free at 1 MHz (wraps every 71 min).
pub fn now_us() -> u32 {
    // SAFETY: a read of a free-running counter register; TIM5 is set up once in `init` and
    // never written again.
    unsafe { (*pac::TIM5::ptr()).cnt().read().bits() }
}

/// QEMU's virtual nanoseconds from TIM2 running free at 1 GHz (instructions under
/// `-icount shift=0`; wraps every 4.3 s: for differences only).
pub fn now_ns() -> u32 {
    // SAFETY: as for TIM5.
    unsafe { (*pac::TIM2::ptr()).cnt().read().bits() }
}

// Fault report: the HardFault handler's frame (or a stack overflow caught by flip-link's
// layout), logged, then QEMU exits with status 1.
board_common::hard_fault_trampoline!(hard_fault);

/// Logs the fault and exits QEMU with status 1 (`None`: a stack overflow).
fn hard_fault(ef: Option<&board_common::fault::ExceptionFrame>) -> ! {
    board_common::fault::report(ef);
    exit(false)
}

/// A panic is logged once and exits QEMU with status 1.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    use core::sync::atomic::{AtomicBool, Ordering};
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    if !PANICKED.swap(true, Ordering::Relaxed) {
        defmt::error!("panic: {}", defmt::Display2Format(info));
    }
    exit(false)
}

/// Starts TIM5 at 1 MHz ([`now_us`]) and TIM2 at 1 GHz ([`now_ns`]), free-running.
pub fn start_time_bases(rcc: &pac::RCC, tim2: &pac::TIM2, tim5: &pac::TIM5) {
    rcc.apb1enr()
        .modify(|_, w| w.tim2en().set_bit().tim5en().set_bit());
    board_common::free_running!(tim5, 999);
    board_common::free_running!(tim2, 0);
}

/// Ends the QEMU run: exit status 0 (`true`) or 1.
pub use board_common::semihosting::exit;
