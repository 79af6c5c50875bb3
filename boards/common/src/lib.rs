//! What both boards of the bench controller share: the compiled-in NARMAX models, the
//! controller built from them, the RTU framing of a byte queue filled by a USART interrupt,
//! the bodies of the RTIC tasks, the torque reference's DAC code, the fault trampoline, and
//! the run's timing margins. A board is its pins, clocks, HAL set-up and the RTIC app that
//! declares the tasks (RTIC 2 wants them in the app), each task's body one call into here.
//!
//! Each board is a crate of its own beside this one (`boards/qemu`, `boards/nucleo-f446re`),
//! with its chip's memory layout (`boards/chips/`), cargo runner, logger and RTIC
//! application. On both the schedule is the same:
//!
//! | priority | task | what |
//! |---|---|---|
//! | 4 (highest) | USART receive / transmit interrupts (and the Nucleo's RTU gap timers) | bytes into lock-free receive queues (`port::RxQueue`), frames out of `heapless` queues ([`port::PortIsr`]) |
//! | 3 | control, every 1 ms | [`controller::control::Controller::step`], torque output, watchdog; then [`tasks::StepLinks::after_step`] |
//! | 2 | VFD master | one pass after each control step (a latest-only signal): [`tasks::vfd_master`] |
//! | 1 | SCADA server, log | Modbus requests ([`tasks::scada_server`]), defmt lines ([`tasks::log_task`]) |
//! | idle | | `wfi` |
//!
//! The control task never waits for a link: it reads the last [`Commands`] and
//! [`VfdStatus`] and leaves the [`Published`] values and the requested torque behind. A flood
//! of SCADA requests runs below it and below the VFD master, which a busy SCADA server
//! would otherwise hold up (tasks of one priority run in turn). A received byte waits in the
//! USART's data register only while another priority-4 handler runs or interrupts are
//! masked (the logger masks them while it writes a frame): [`Margin`] measures both, and the
//! control task's longest run.
//!
//! Everything but the target-only parts (`hard_fault_trampoline!` and `fault`, `semihosting`,
//! `start_systick`) is plain `no_std` code, tested on the host (`cargo test -p board-common`).
//!
//! The NARMAX models are the `pump-models` crate (compile-time data made by `pumpbench export`).
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

#[cfg(test)]
extern crate std;

pub use controller::control::{Commands, Inputs, Outputs, VfdStatus};
use controller::control::{Config, Error, NarmaxModel};
pub use controller::types::Published;
use core::sync::atomic::{AtomicU32, Ordering};
use model_core::narmax::mcu::build_period_ms;

/// The NARMAX models compiled in (the `pump-models` crate, made by `pumpbench export`).
pub use pump_models as models;

pub mod dac;
#[cfg(target_os = "none")]
pub mod fault;
pub mod port;
pub mod selftest;
#[cfg(all(feature = "semihosting", target_os = "none"))]
pub mod semihosting;
pub mod tasks;

/// Starts SysTick from the core clock, interrupting every `reload + 1` core cycles (e.g.
/// `core_hz / 1000 - 1` for 1 ms; `reload` 1..=0xFF_FFFF).
#[cfg(target_os = "none")]
pub fn start_systick(mut syst: cortex_m::peripheral::SYST, reload: u32) {
    syst.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
    syst.set_reload(reload);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Starts the STM32 timer `$tim` (a PAC timer: TIM2 or TIM5, 32-bit) counting up from 0,
/// free-running at its clock / (`$psc` + 1), wrapping at 2³², no interrupts: a time base to
/// read (e.g. at 1 MHz for µs). Its clock must be enabled first (RCC). A macro: each chip's
/// PAC has its own timer types, with the same register API.
#[macro_export]
macro_rules! free_running {
    ($tim:expr, $psc:expr) => {{
        let t = $tim;
        t.psc().write(|w| w.psc().set($psc));
        t.arr().write(|w| w.arr().set(u32::MAX));
        t.egr().write(|w| w.ug().set_bit());
        t.cr1().modify(|_, w| w.cen().set_bit());
    }};
}

/// Modbus RTU line speed of both links (SCADA and VFD), bit/s, 8N1 (QEMU's serial back-ends
/// ignore it).
pub const RTU_BAUD: u32 = 19_200;

/// Pressure model period, ms.
pub const PRESSURE_MS: u32 = build_period_ms(models::pressure::SAMPLE_PERIOD_S);
/// Flow model period, ms.
pub const FLOW_MS: u32 = build_period_ms(models::flow::SAMPLE_PERIOD_S);
// The observer takes a flow sample only on a pressure tick (Controller::new refuses the
// rest at run time; here it is a build error).
const _: () = assert!(
    FLOW_MS.is_multiple_of(PRESSURE_MS),
    "the flow model's period must be a whole multiple of the pressure model's"
);

/// The controller ([`controller::control::Controller`]) with the compiled-in models.
pub type Controller = controller::control::Controller<
    { models::pressure::FRAMES },
    { models::pressure::HIDDEN },
    { models::flow::FRAMES },
    { models::flow::HIDDEN },
>;

/// The compiled-in models, at rest.
pub fn narmax_models() -> Result<
    (
        NarmaxModel<{ models::pressure::FRAMES }, { models::pressure::HIDDEN }>,
        NarmaxModel<{ models::flow::FRAMES }, { models::flow::HIDDEN }>,
    ),
    Error,
> {
    use models::{flow, pressure};
    Ok((
        NarmaxModel::new(&pressure::F32, &pressure::Q15, PRESSURE_MS)?,
        NarmaxModel::new(&flow::F32, &flow::Q15, FLOW_MS)?,
    ))
}

/// Builds the controller (the models are `static`s the compiler built and checked). Not
/// inlined: in the boards' `init`, whose frame holds every resource, the moves of the
/// controller took more code (the QEMU image 80 B smaller out of line).
#[inline(never)]
pub fn build_controller(config: &Config) -> Result<Controller, Error> {
    let (p, q) = narmax_models()?;
    Controller::new(config, p, q)
}

/// The configuration of plant mode (`cargo xtask qemu --plant`, `pumpbench control
/// --plant-stdio`), the protocol's own.
pub use controller::plant::PLANT_CONFIG;

/// The controller and the plant session of plant mode, from [`PLANT_CONFIG`]: the same on
/// the host and the board, so that the same frames give the same replies bit for bit (the
/// protocol: [`controller::plant`]).
pub fn plant_session() -> Result<(Controller, controller::plant::PlantSession), Error> {
    let core = build_controller(&PLANT_CONFIG)?;
    let lockstep = controller::plant::Lockstep::for_config(&PLANT_CONFIG)?;
    Ok((core, controller::plant::PlantSession::new(lockstep)))
}

/// Serves the plant protocol ([`controller::plant`]) on a byte stream: a fresh
/// [`plant_session`], its holding registers first written with `writes` (register, value: as
/// commissioning or a `W` line would, before the first frame; a write the map refuses is an
/// error, nothing served), then every byte of `input` fed to it, each reply written to
/// `output` and flushed at once (the plant waits for it), until `Q` or the end of the input;
/// `each` sees every controller step's outputs and published values. What `cargo xtask
/// plant-stdio` and `pumpbench control --plant-stdio` run on their standard input and output
/// (feature `std`).
#[cfg(feature = "std")]
pub fn serve_plant(
    input: impl std::io::BufRead,
    output: &mut impl std::io::Write,
    writes: &[(u16, u16)],
    mut each: impl FnMut(&controller::control::Outputs, &controller::types::Published),
) -> Result<(), std::string::String> {
    let (mut core, mut session) =
        plant_session().map_err(|e| std::format!("plant session: {e}"))?;
    for &(register, value) in writes {
        session
            .lockstep_mut()
            .write(register, &[value])
            .map_err(|e| std::format!("holding register {register} = {value} refused: {e:?}"))?;
    }
    let mut reply = std::string::String::new();
    for byte in input.bytes() {
        let byte = byte.map_err(|e| std::format!("plant input: {e}"))?;
        reply.clear();
        let served = session
            .feed(byte, &mut core, &mut reply, &mut each)
            .map_err(|_| "reply not written")?;
        if !reply.is_empty() {
            output
                .write_all(reply.as_bytes())
                .and_then(|()| output.flush())
                .map_err(|e| std::format!("plant output: {e}"))?;
        }
        if served == controller::plant::Served::Quit {
            break;
        }
    }
    Ok(())
}

/// Milliseconds from a free-running microsecond counter (32 bits, wrapping), counted by
/// differences: read it at least once per 71 minutes.
#[derive(Debug, Clone, Copy)]
pub struct MsClock {
    last_us: u32,
    ms: u32,
    rest_us: u32,
}

impl MsClock {
    /// Starts at 0 ms with the counter at `now_us`.
    pub const fn new(now_us: u32) -> Self {
        Self {
            last_us: now_us,
            ms: 0,
            rest_us: 0,
        }
    }

    /// Milliseconds since [`Self::new`] (wrapping) with the counter at `now_us`.
    pub fn now_ms(&mut self, now_us: u32) -> u32 {
        let us = now_us.wrapping_sub(self.last_us);
        self.last_us = now_us;
        let rest = self.rest_us + us % 1000;
        self.ms = self
            .ms
            .wrapping_add(us / 1000)
            .wrapping_add(u32::from(rest >= 1000));
        self.rest_us = rest % 1000;
        self.ms
    }
}

/// Raises `max` to `v` if `v` is larger (lock-free: LDREX/STREX on the M4).
pub fn record_max(max: &AtomicU32, v: u32) {
    max.fetch_max(v, Ordering::Relaxed);
}

/// The run's timing margins, in the board's timer counts (see each board for the unit),
/// written from the handlers that measure them and read by the log task.
#[derive(Debug)]
pub struct Margin {
    /// Longest run of a priority-4 (USART) handler: while one runs, a byte arriving at the
    /// other USART waits in its data register.
    pub usart_handler_max: AtomicU32,
    /// Longest section with interrupts masked that the board measures (a log line's write:
    /// the logger masks interrupts while it copies a frame).
    pub masked_max: AtomicU32,
    /// Longest control task run (one or more 1 ms steps).
    pub control_max: AtomicU32,
    /// Control steps run since start (1 per ms).
    pub steps: AtomicU32,
    /// Received bytes lost: a full receive queue or a USART overrun (count; must stay 0).
    pub bytes_lost: AtomicU32,
    /// Bytes received on both ports since start.
    pub bytes_received: AtomicU32,
}

impl Margin {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            usart_handler_max: AtomicU32::new(0),
            masked_max: AtomicU32::new(0),
            control_max: AtomicU32::new(0),
            steps: AtomicU32::new(0),
            bytes_lost: AtomicU32::new(0),
            bytes_received: AtomicU32::new(0),
        }
    }

    /// A copy of the figures.
    pub fn snapshot(&self) -> MarginSnapshot {
        let r = |a: &AtomicU32| a.load(Ordering::Relaxed);
        MarginSnapshot {
            usart_handler_max: r(&self.usart_handler_max),
            masked_max: r(&self.masked_max),
            control_max: r(&self.control_max),
            steps: r(&self.steps),
            bytes_lost: r(&self.bytes_lost),
            bytes_received: r(&self.bytes_received),
        }
    }
}

impl Default for Margin {
    fn default() -> Self {
        Self::new()
    }
}

/// [`Margin`]'s figures at one time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MarginSnapshot {
    /// See [`Margin::usart_handler_max`].
    pub usart_handler_max: u32,
    /// See [`Margin::masked_max`].
    pub masked_max: u32,
    /// See [`Margin::control_max`].
    pub control_max: u32,
    /// See [`Margin::steps`].
    pub steps: u32,
    /// See [`Margin::bytes_lost`].
    pub bytes_lost: u32,
    /// See [`Margin::bytes_received`].
    pub bytes_received: u32,
}

impl MarginSnapshot {
    /// The longest a received byte can wait before its interrupt reads it, timer counts: one
    /// priority-4 handler of the other port plus the longest masked section (the interrupt's
    /// own entry, 12 cycles, aside). Under 521 µs at 19 200 baud, no byte is lost.
    pub fn rx_wait_bound(&self) -> u32 {
        self.usart_handler_max.saturating_add(self.masked_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift32) for irregular read intervals.
    fn xorshift(s: &mut u32) -> u32 {
        *s ^= *s << 13;
        *s ^= *s >> 17;
        *s ^= *s << 5;
        *s
    }

    #[test]
    fn ms_clock_counts_whole_milliseconds_and_carries_the_rest() {
        let mut c = MsClock::new(1_000);
        assert_eq!(c.now_ms(1_000), 0);
        assert_eq!(c.now_ms(1_999), 0);
        assert_eq!(c.now_ms(2_000), 1);
        // 400 µs at a time: the remainders add up.
        let mut c = MsClock::new(0);
        let got: std::vec::Vec<u32> = (1..=6).map(|k| c.now_ms(400 * k)).collect();
        assert_eq!(got, [0, 0, 1, 1, 2, 2]);
        // The same instant read twice.
        assert_eq!(c.now_ms(2_400), 2);
    }

    #[test]
    fn ms_clock_across_the_counter_wrap() {
        let start = u32::MAX - 499;
        let mut c = MsClock::new(start);
        assert_eq!(c.now_ms(start.wrapping_add(999)), 0);
        assert_eq!(c.now_ms(start.wrapping_add(1_000)), 1);
        assert_eq!(c.now_ms(start.wrapping_add(123_456)), 123);
        // The longest gap between reads it allows: 2³² − 1 µs (71 min).
        let mut c = MsClock::new(7);
        assert_eq!(c.now_ms(6), u32::MAX / 1000);
    }

    /// Over irregular reads (some a few µs apart, some seconds), the clock is always the
    /// exact whole milliseconds elapsed, wrapping at 2³² ms like the controller's time.
    #[test]
    fn ms_clock_is_the_elapsed_time_over_any_reads() {
        for seed in [1u32, 0x9E37_79B9, 12_345] {
            let mut s = seed;
            let start = xorshift(&mut s);
            let mut c = MsClock::new(start);
            let (mut now, mut total_us) = (start, 0u64);
            for _ in 0..100_000 {
                let r = xorshift(&mut s);
                let step = match r % 4 {
                    0 => r % 7,
                    1 => r % 1_001,
                    2 => r % 4_000_000,
                    _ => r % 100_000_000,
                };
                now = now.wrapping_add(step);
                total_us += u64::from(step);
                assert_eq!(
                    u64::from(c.now_ms(now)),
                    (total_us / 1000) % (1 << 32),
                    "seed {seed}, {total_us} µs"
                );
            }
        }
    }

    #[test]
    fn record_max_keeps_the_largest() {
        let m = AtomicU32::new(0);
        for v in [5, 3, 9, 9, 1, u32::MAX, 0] {
            record_max(&m, v);
        }
        assert_eq!(m.load(Ordering::Relaxed), u32::MAX);
        let m = AtomicU32::new(0);
        for v in [5, 3, 9, 1] {
            record_max(&m, v);
        }
        assert_eq!(m.load(Ordering::Relaxed), 9);
    }

    #[test]
    fn margin_snapshot_and_the_wait_bound() {
        let m = Margin::default();
        assert_eq!(m.snapshot(), MarginSnapshot::default());
        record_max(&m.usart_handler_max, 120);
        record_max(&m.masked_max, 4_000);
        record_max(&m.control_max, 9_000);
        m.steps.fetch_add(3, Ordering::Relaxed);
        m.bytes_lost.fetch_add(1, Ordering::Relaxed);
        m.bytes_received.fetch_add(40, Ordering::Relaxed);
        let s = m.snapshot();
        assert_eq!(
            s,
            MarginSnapshot {
                usart_handler_max: 120,
                masked_max: 4_000,
                control_max: 9_000,
                steps: 3,
                bytes_lost: 1,
                bytes_received: 40,
            }
        );
        assert_eq!(s.rx_wait_bound(), 4_120);
        let huge = MarginSnapshot {
            usart_handler_max: u32::MAX - 1,
            masked_max: 5,
            ..s
        };
        assert_eq!(huge.rx_wait_bound(), u32::MAX, "saturates");
    }

    #[test]
    fn the_compiled_in_controller_builds() {
        assert!(FLOW_MS.is_multiple_of(PRESSURE_MS) && PRESSURE_MS > 0);
        assert!(build_controller(&Config::bench()).is_ok());
    }

    /// The plant session answers a hello and a frame (the protocol's own tests are in
    /// `controller::plant`).
    #[test]
    fn the_plant_session_serves_lines() {
        let (mut core, mut session) = plant_session().unwrap();
        let mut out = std::string::String::new();
        for &b in b"H 1\nW 1 1\nS 745 745 0 0\n" {
            session.feed(b, &mut core, &mut out, |_, _| {}).unwrap();
        }
        let lines: std::vec::Vec<&str> = out.lines().collect();
        assert_eq!(lines[..2], ["H 1 5", "K"]);
        assert!(lines[2].starts_with("T 4 "), "{out}");
        assert_eq!(session.lockstep().scada().holding()[1], 1);
    }

    /// The on-target checks pass on the host too (`cargo xtask replay` compares the digests).
    #[test]
    fn the_selftest_checks_pass_on_the_host() {
        assert_eq!(selftest::framer(), Ok(()));
        let worst = selftest::tanh_table().unwrap();
        assert!(worst > 0.0);
    }
}
