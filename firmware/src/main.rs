//! The bench controller firmware: the controller loop of the `controller` crate (SCADA Modbus
//! slave, VFD Modbus master, 4-20 mA inputs, torque output, the white-box and NARMAX models)
//! run once per millisecond of the board's clock (SysTick wakes the core every 1 ms), on one
//! of two boards chosen by a cargo feature:
//!
//! - `qemu` (default): QEMU `netduinoplus2` (STM32F405) with the on-chip virtual bench; text
//!   logs over semihosting ([`qemu`]);
//! - `nucleo-f446re`: a NUCLEO-F446RE with the real transmitters, DAC and RS-485 links; defmt
//!   logs over RTT ([`nucleo`]).
//!
//! The NARMAX models are `src/models/*.rs`, made by `pumpbench export`.
#![no_std]
#![no_main]

#[cfg(all(feature = "qemu", feature = "nucleo-f446re"))]
compile_error!(
    "choose one board: the default (qemu) or `--no-default-features --features nucleo-f446re`"
);
#[cfg(not(any(feature = "qemu", feature = "nucleo-f446re")))]
compile_error!("choose a board: `--features qemu` or `--features nucleo-f446re`");

use controller::app::{App, AppConfig, AppError, Io, LogLine, NarmaxModel};
use controller::rtu::{Frame, RtuPort, Uart};
use controller::scada::Response;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m_rt::{entry, exception};

/// The NARMAX models compiled in (`pumpbench export`).
mod models {
    pub mod flow;
    pub mod pressure;
}

#[cfg(feature = "nucleo-f446re")]
mod nucleo;
#[cfg(feature = "qemu")]
mod qemu;

/// Pressure model period, ms.
const PRESSURE_MS: u32 = (models::pressure::SAMPLE_PERIOD_S * 1000.0 + 0.5) as u32;
/// Flow model period, ms.
const FLOW_MS: u32 = (models::flow::SAMPLE_PERIOD_S * 1000.0 + 0.5) as u32;

/// The controller loop with the compiled-in models.
pub type Loop = App<
    { models::pressure::FRAMES },
    { models::pressure::HIDDEN },
    { models::flow::FRAMES },
    { models::flow::HIDDEN },
>;

/// Builds the loop (the models are `static`s the compiler built, checked and quantised).
pub fn build_loop(config: AppConfig) -> Result<Loop, AppError> {
    use models::{flow, pressure};
    App::new(
        config,
        NarmaxModel::new(&pressure::F32, &pressure::Q15, PRESSURE_MS)?,
        NarmaxModel::new(&flow::F32, &flow::Q15, FLOW_MS)?,
    )
}

/// Milliseconds since SysTick started (wraps after 49 days; the loop uses wrapping time).
static TICKS: AtomicU32 = AtomicU32::new(0);

/// The 1 ms time base.
#[exception]
fn SysTick() {
    TICKS.fetch_add(1, Ordering::Relaxed);
}

/// Milliseconds since start.
pub fn now_ms() -> u32 {
    TICKS.load(Ordering::Relaxed)
}

/// Starts SysTick at 1 ms from a core clock of `core_hz`.
pub fn start_systick(mut syst: cortex_m::peripheral::SYST, core_hz: u32) {
    use cortex_m::peripheral::syst::SystClkSource;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(core_hz / 1000 - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// What a board adds to [`Io`] for [`serve`].
pub trait Board: Io {
    /// Milliseconds since start (wrapping), the loop's time base. The Nucleo counts SysTick
    /// interrupts; QEMU reads a free-running timer, as it drops SysTick interrupts when the
    /// host is busy (see `qemu.rs`).
    fn now_ms(&mut self) -> u32;
    /// Moves serial bytes (the VFD port); called on every pass of the loop.
    fn poll(&mut self, now_ms: u32);
    /// After each 1 ms tick, with its log line if it made one; `false` ends [`serve`].
    fn after_tick(&mut self, log: Option<&LogLine>) -> bool;
    /// Nothing to do until the next event (QEMU: `wfi`; a board polling a line at 19 200 baud
    /// returns at once).
    fn idle(&mut self) {}
    /// `true` if SCADA requests may also end by their content (length and CRC), for a line
    /// that marks no silence (QEMU). A real RS-485 line frames by silence only: on a shared
    /// bus, content framing could take a request out of another slave's traffic.
    fn frames_by_content(&self) -> bool {
        false
    }
}

/// The loop: SCADA frames answered as they complete (by their length and CRC, or by the
/// line's silence), one [`App::tick`] per elapsed millisecond of [`Board::now_ms`] (late
/// ticks are caught up, none is skipped), the board polled in between. Returns when the
/// board's [`Board::after_tick`] says so.
pub fn serve<S: Uart, B: Board>(app: &mut Loop, scada: &mut RtuPort<S>, board: &mut B) {
    let mut frame = Frame::new();
    let mut response = Response::new();
    loop {
        let now = board.now_ms();
        board.poll(now);
        let complete = if board.frames_by_content() {
            scada.receive_complete(now, &mut frame, controller::scada::request_at_end)
        } else {
            scada.receive(now, &mut frame)
        };
        if complete {
            if let Some(n) = app.scada_frame(&frame, &mut response) {
                scada.send(&response[..n]);
            }
        }
        let mut ticked = false;
        while now.wrapping_sub(app.now_ms()) as i32 >= 0 {
            let log = app.tick(board);
            if !board.after_tick(log.as_ref()) {
                return;
            }
            ticked = true;
        }
        scada.poll(now);
        if !ticked && !scada.sending() {
            board.idle();
        }
    }
}

#[entry]
fn main() -> ! {
    #[cfg(feature = "qemu")]
    qemu::run();
    #[cfg(feature = "nucleo-f446re")]
    nucleo::run();
}
