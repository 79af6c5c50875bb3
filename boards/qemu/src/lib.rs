//! What the QEMU board's binaries share: the time bases, the fault and panic handlers that
//! report and exit QEMU with status 1, the start-up arguments.
#![no_std]
// The board is where the hardware is: register reads and writes the HAL does not wrap, the
// fault handler. Each `unsafe` block says why it is sound.
#![allow(unsafe_code)]

pub mod args;

use defmt_semihosting as _;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::serial::{Rx, Serial, Tx};

/// SysTick under QEMU, Hz (QEMU clocks it at 168 MHz whatever the RCC says).
pub const QEMU_SYSTICK_HZ: u32 = 168_000_000;
/// SysTick rate, Hz: four wake-ups per control step (see the module docs).
pub const WAKE_HZ: u32 = 4000;
/// Silence that ends an RTU frame under QEMU, µs: QEMU hands over one byte each time the
/// guest reads the last one, with no line timing, and a busy host can delay a byte by a few
/// milliseconds; 10 ms keeps frames whole and is far below any master's timeout.
pub const QEMU_SILENCE_US: u32 = 10_000;
/// Silence after which the start of a SCADA request is given up under QEMU, µs: in real
/// time a busy host can hold QEMU's bytes up longer than [`QEMU_SILENCE_US`] inside one
/// write (a request torn by 50 ms went unanswered, and a CI flood lost one so), while a
/// master waits about 1 s for an answer (mbpoll's and the xtask checks' timeout). Bytes
/// that cannot start a request by their form
/// ([`controller::modbus::request_may_grow`]) are still dropped at [`QEMU_SILENCE_US`].
pub const QEMU_REQUEST_PATIENCE_US: u32 = 1_000_000;

/// The SCADA port's task side under QEMU, from its receive queue's consumer `rx` and its
/// transmit queue's producer `tx`: requests end by their content, or after
/// [`QEMU_SILENCE_US`] (a request's start after [`QEMU_REQUEST_PATIENCE_US`]); `pend` pends
/// USART1's interrupt.
pub fn scada_port(
    rx: board_common::port::RxConsumer<'static, { board_common::port::RX_QUEUE }>,
    tx: heapless::spsc::Producer<'static, controller::modbus::Frame>,
    pend: fn(),
) -> board_common::port::PortTask {
    let requests = board_common::port::ByContent::requests(QEMU_REQUEST_PATIENCE_US);
    board_common::port::PortTask::new(rx, tx, QEMU_SILENCE_US, Some(requests), pend)
}

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

/// A panic is logged once, with its source location
/// ([`board_common::fault::report_panic`]), and exits QEMU with status 1.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    board_common::fault::report_panic(info);
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

/// The board's two serial ports, receive interrupts on: USART1 (SCADA) and USART2 (the VFD
/// link, or the plant line of the plant-mode image).
pub struct Usarts {
    /// USART1's transmitter.
    pub tx1: Tx<pac::USART1>,
    /// USART1's receiver.
    pub rx1: Rx<pac::USART1>,
    /// USART2's transmitter.
    pub tx2: Tx<pac::USART2>,
    /// USART2's receiver.
    pub rx2: Rx<pac::USART2>,
}

/// The start both images share: the time bases ([`start_time_bases`]), the clock on the HSI
/// (16 MHz: QEMU hangs on a PLL-ready wait), USART1 on PA9/PA10 and USART2 on PA2/PA3 at
/// `baud` with their receive interrupts on. The error names the port that refused.
pub fn start_usarts(dp: pac::Peripherals, baud: u32) -> Result<Usarts, &'static str> {
    use stm32f4xx_hal::prelude::*;
    start_time_bases(&dp.RCC, &dp.TIM2, &dp.TIM5);
    let mut rcc = dp.RCC.freeze(stm32f4xx_hal::rcc::Config::hsi());
    let gpioa = dp.GPIOA.split(&mut rcc);
    let s1 = Serial::new(dp.USART1, (gpioa.pa9, gpioa.pa10), baud.bps(), &mut rcc)
        .map_err(|_| "USART1")?;
    let s2 = Serial::new(dp.USART2, (gpioa.pa2, gpioa.pa3), baud.bps(), &mut rcc)
        .map_err(|_| "USART2")?;
    let (tx1, mut rx1) = s1.split();
    let (tx2, mut rx2) = s2.split();
    rx1.listen();
    rx2.listen();
    Ok(Usarts { tx1, rx1, tx2, rx2 })
}
