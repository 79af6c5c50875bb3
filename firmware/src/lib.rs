//! What both boards of the bench controller share: the compiled-in NARMAX models, the
//! controller built from them, the RTU framing of a byte queue filled by a USART interrupt,
//! and the run's timing margins.
//!
//! Each board is a crate of its own beside this one (`boards/qemu`, `boards/nucleo-f446re`),
//! with its memory layout, cargo runner, logger and RTIC application. On both the schedule
//! is the same:
//!
//! | priority | task | what |
//! |---|---|---|
//! | 4 (highest) | USART receive / transmit interrupts (and the Nucleo's RTU gap timers) | bytes into and out of `heapless` queues |
//! | 3 | control, every 1 ms | [`controller::control::Controller::step`], torque output, watchdog |
//! | 2 | VFD master | one pass after each control step (a latest-only signal) |
//! | 1 | SCADA server, log | Modbus requests, defmt lines |
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
//! The NARMAX models are the `pump-models` crate (compile-time data made by `pumpbench export`).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub use controller::control::{Commands, Inputs, Outputs, VfdStatus};
use controller::control::{Config, Error, NarmaxModel};
pub use controller::types::Published;
use core::sync::atomic::{AtomicU32, Ordering};
use model_core::narmax::mcu::build_period_ms;

/// The NARMAX models compiled in (the `pump-models` crate, made by `pumpbench export`).
pub use pump_models as models;

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

/// Builds the controller (the models are `static`s the compiler built and checked).
pub fn build_controller(config: &Config) -> Result<Controller, Error> {
    let (p, q) = narmax_models()?;
    Controller::new(config, p, q)
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

/// A USART's interrupt side: its [`Rs485`] port, the receive queue it fills and the transmit
/// queue of whole frames it empties. The board's priority-4 handler calls
/// [`PortIsr::on_interrupt`] and keeps nothing else in it.
pub mod port {
    use super::{Margin, Ordering};
    use controller::control::Commands;
    use controller::link::{ScadaLink, VfdPort};
    use controller::modbus::Frame;
    use controller::rtu::Rs485;
    use controller::rtu::RtuFramer;
    use controller::types::Published;
    use embedded_hal::digital::OutputPin;
    use embedded_hal_nb::serial::{Read, Write};
    use heapless::spsc::{Consumer, Producer};

    /// The receive queue's mark for "the line went silent" (3.5 characters), put there by a
    /// board's gap timer ([`PortIsr::mark_gap`]); every other entry is a byte.
    pub const GAP: u16 = 0x100;

    /// Entries a receive queue holds: more than four longest RTU frames, so a task at the
    /// lowest priority may fall ≈ 500 ms behind a 19 200-baud line before a byte is lost.
    pub const RX_QUEUE: usize = 1024;
    /// Frames a transmit queue holds (a slave answers one request at a time; a master waits
    /// for its answer): two, one going out and one waiting.
    pub const TX_QUEUE: usize = 3;

    /// What one [`PortIsr::on_interrupt`] did.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Activity {
        /// Bytes received (count).
        pub received: u32,
        /// A frame is still going out.
        pub sending: bool,
    }

    /// The interrupt side of one port (the board's priority-4 handler calls it).
    pub struct PortIsr<TX, RX, DE> {
        rs485: Rs485<TX, RX, DE>,
        rx: Producer<'static, u16>,
        tx: Consumer<'static, Frame>,
    }

    impl<TX: Write<u8>, RX: Read<u8>, DE: OutputPin> PortIsr<TX, RX, DE> {
        /// The port with its queues' ends.
        pub fn new(
            rs485: Rs485<TX, RX, DE>,
            rx: Producer<'static, u16>,
            tx: Consumer<'static, Frame>,
        ) -> Self {
            Self { rs485, rx, tx }
        }

        /// The gap timer's interrupt: the line has been silent for 3.5 characters since the
        /// last byte; the frame before it is complete.
        pub fn mark_gap(&mut self, margin: &Margin) {
            if self.rx.enqueue(GAP).is_err() {
                margin.bytes_lost.fetch_add(1, Ordering::Relaxed);
            }
        }

        /// The interrupt's work: every received byte into the receive queue (a byte the full
        /// queue cannot take, and a USART overrun, count in [`Margin::bytes_lost`]); the next
        /// queued frame started once the last one is out, and the bytes the transmitter takes.
        /// Returns what happened: bytes received (a board with a gap timer restarts it) and
        /// whether a frame is still going out (the board keeps its transmit interrupt on, or,
        /// under QEMU where it never fires, calls again at once).
        pub fn on_interrupt(&mut self, margin: &Margin) -> Activity {
            let overruns = self.rs485.errors().overrun;
            let (mut got, mut lost) = (0u32, 0u32);
            let rx = &mut self.rx;
            self.rs485.on_receive(|b| {
                got += 1;
                if rx.enqueue(u16::from(b)).is_err() {
                    lost += 1;
                }
            });
            lost += self.rs485.errors().overrun.wrapping_sub(overruns);
            if got > 0 {
                margin.bytes_received.fetch_add(got, Ordering::Relaxed);
            }
            if lost > 0 {
                margin.bytes_lost.fetch_add(lost, Ordering::Relaxed);
            }
            if !self.rs485.sending() {
                if let Some(frame) = self.tx.dequeue() {
                    self.rs485.send(&frame);
                }
            }
            if self.rs485.sending() {
                self.rs485.on_transmit();
            }
            Activity {
                received: got,
                sending: self.rs485.sending(),
            }
        }

        /// The port's line-error counts.
        pub fn errors(&self) -> controller::rtu::Errors {
            self.rs485.errors()
        }
    }

    /// Where a whole frame starts at the end of the bytes held, found by its content (see
    /// [`RtuFramer::take_if`]).
    pub type FindFrame = fn(&[u8]) -> Option<usize>;

    /// A port's task side: frames out of the receive queue, frames into the transmit queue.
    pub struct PortTask {
        rx: Consumer<'static, u16>,
        tx: Producer<'static, Frame>,
        framer: RtuFramer,
        by_content: Option<FindFrame>,
        pend: fn(),
        /// Time stamp for the bytes taken next, µs (wrapping).
        pub now_us: u32,
    }

    impl PortTask {
        /// The task side of a port whose frames end at a [`GAP`] mark or after `silence_us`
        /// without a byte (timed from when this side takes them); with `by_content`, also by
        /// their content (e.g. [`controller::modbus::request_at_end`], for a line that marks
        /// no silence). `pend` pends the port's interrupt, which starts a queued frame.
        pub fn new(
            rx: Consumer<'static, u16>,
            tx: Producer<'static, Frame>,
            silence_us: u32,
            by_content: Option<FindFrame>,
            pend: fn(),
        ) -> Self {
            Self {
                rx,
                tx,
                framer: RtuFramer::new(silence_us),
                by_content,
                pend,
                now_us: 0,
            }
        }

        /// The next complete frame into `out`; `false` if none (call again while `true`).
        pub fn receive_frame(&mut self, out: &mut Frame) -> bool {
            while let Some(e) = self.rx.dequeue() {
                if e == GAP {
                    if self.framer.end_frame(out) {
                        return true;
                    }
                    continue;
                }
                self.framer.push(e as u8, self.now_us);
                if let Some(find) = self.by_content {
                    if self.framer.take_if(out, find) {
                        return true;
                    }
                }
            }
            self.framer.poll(self.now_us, out)
        }

        /// Queues `frame` for sending and pends the port's interrupt; `false` if the queue is
        /// full (the frame is dropped).
        pub fn send_frame(&mut self, frame: &[u8]) -> bool {
            let mut f = Frame::new();
            if f.extend_from_slice(frame).is_err() || self.tx.enqueue(f).is_err() {
                return false;
            }
            (self.pend)();
            true
        }
    }

    /// The SCADA server's work on a wake-up at `now_us`: every complete request from `port`
    /// answered by `link` from the values `published` gives, its answer queued, and the
    /// holding registers handed to `commands` after each. Returns the answers dropped because
    /// the transmit queue was full (0 unless the line is stuck).
    pub fn serve_scada(
        port: &mut PortTask,
        link: &mut ScadaLink,
        now_us: u32,
        mut published: impl FnMut() -> Published,
        mut commands: impl FnMut(Commands),
    ) -> u32 {
        let (mut frame, mut answer) = (Frame::new(), Frame::new());
        let mut dropped = 0;
        port.now_us = now_us;
        while port.receive_frame(&mut frame) {
            link.publish(&published());
            if let Some(n) = link.handle(&frame, &mut answer) {
                if !port.send_frame(&answer[..n]) {
                    dropped += 1;
                }
            }
            commands(link.commands());
        }
        dropped
    }

    /// The VFD master's frames over a serial port.
    impl VfdPort for PortTask {
        fn send(&mut self, frame: &[u8]) {
            // A full queue means the drive's line is stuck: the request runs into its timeout.
            let _ = self.send_frame(frame);
        }
        fn receive(&mut self, frame: &mut Frame) -> bool {
            self.receive_frame(frame)
        }
    }
}

/// The on-target checks (`boards/qemu`'s `selftest` binary; `cargo xtask test` runs it in
/// QEMU and compares its results with the same functions run on the host, bit for bit).
pub mod selftest {
    use controller::modbus::{crc16, request_at_end, Frame};
    use controller::rtu::{gap_us, RtuFramer};
    use model_core::narmax::mcu::{tanh_f32, tanh_q15, I16F16, TANH_Q15_MAX_ERROR};

    /// A 32-bit digest of a stream of words (order-sensitive; for comparing results, not for
    /// security).
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Digest(pub u32);

    impl Digest {
        /// The empty stream's.
        pub const fn new() -> Self {
            Self(0x811C_9DC5)
        }
        /// Takes one word.
        pub fn add(&mut self, w: u32) {
            self.0 = (self.0.rotate_left(5) ^ w).wrapping_mul(0x9E37_79B1);
        }
    }

    impl Default for Digest {
        fn default() -> Self {
            Self::new()
        }
    }

    /// Inputs of the float checks: 4 097 points from −20 to 20 (the NARMAX pre-activations'
    /// range and beyond), then 1 024 points from 1e-6 to 1e4 by factors (positive-only
    /// functions).
    fn grid(i: u32) -> f32 {
        if i <= 4096 {
            -20.0 + 40.0 * i as f32 / 4096.0
        } else {
            1e-6 * libm::powf(10.0, 10.0 * (i - 4097) as f32 / 1023.0)
        }
    }
    /// Points of [`grid`].
    const GRID: u32 = 4097 + 1024;

    /// The digests of the results' bits of `libm`'s `tanhf`, `expf`, `sqrtf` (the ones the
    /// product uses in f32), the model's `tanh_f32`, and `tanh_q15` over every Q16 input in
    /// [−8, 8) (its whole table): `(name, digest)`.
    pub fn digests() -> [(&'static str, u32); 5] {
        let mut d = [Digest::new(); 5];
        for i in 0..GRID {
            let x = grid(i);
            d[0].add(libm::tanhf(x).to_bits());
            d[1].add(libm::expf(x.min(80.0)).to_bits());
            d[2].add(libm::sqrtf(libm::fabsf(x)).to_bits());
            d[3].add(tanh_f32(x).to_bits());
        }
        for x in -(8 << 16)..(8 << 16) {
            d[4].add(tanh_q15(I16F16::from_bits(x)).to_bits() as u16 as u32);
        }
        [
            ("libm_tanhf", d[0].0),
            ("libm_expf", d[1].0),
            ("libm_sqrtf", d[2].0),
            ("tanh_f32", d[3].0),
            ("tanh_q15", d[4].0),
        ]
    }

    /// `tanh_q15` against `libm::tanhf` on 65 536 points of [−8, 8): the largest error must
    /// stay within the table's bound ([`TANH_Q15_MAX_ERROR`]) plus tanhf's own rounding.
    pub fn tanh_table() -> Result<f32, &'static str> {
        let mut worst = 0.0f32;
        for k in 0..65_536i32 {
            let x_q16 = (k - 32_768) * 16;
            let exact = libm::tanhf(x_q16 as f32 / 65_536.0);
            let got = f32::from(tanh_q15(I16F16::from_bits(x_q16)).to_bits()) / 32_768.0;
            worst = worst.max(libm::fabsf(got - exact));
        }
        if worst as f64 <= TANH_Q15_MAX_ERROR + 1e-7 {
            Ok(worst)
        } else {
            Err("tanh_q15 off the table's error bound")
        }
    }

    fn with_crc(body: &[u8]) -> Frame {
        let mut f = Frame::new();
        let _ = f.extend_from_slice(body);
        let _ = f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    /// The RTU framer as the boards use it: a request found by its content right after noise,
    /// a frame ended by the gap mark, a frame ended by silence, time wrapping.
    pub fn framer() -> Result<(), &'static str> {
        let req = with_crc(&[1, 4, 0, 0, 0, 18]);
        let mut out = Frame::new();
        let mut f = RtuFramer::new(10_000);
        for (k, &b) in [0x55u8, 0xAA, 0x13].iter().chain(req.iter()).enumerate() {
            f.push(b, k as u32);
        }
        if !f.take_if(&mut out, request_at_end) || out[..] != req[..] {
            return Err("a request after noise is not found by its content");
        }
        let mut f = RtuFramer::new(gap_us(19_200));
        for &b in req.iter() {
            f.push(b, u32::MAX - 100);
        }
        if f.poll(u32::MAX - 100 + gap_us(19_200) - 1, &mut out) {
            return Err("a frame ended before the gap");
        }
        if !f.poll((u32::MAX - 100).wrapping_add(gap_us(19_200)), &mut out) || out[..] != req[..] {
            return Err("a frame not ended by the gap across the time wrap");
        }
        for &b in req.iter() {
            f.push(b, 0);
        }
        if !f.end_frame(&mut out) || out[..] != req[..] {
            return Err("a frame not ended by the gap timer's mark");
        }
        if gap_us(19_200) != 2006 {
            return Err("3.5 characters at 19 200 baud are not 2 006 µs");
        }
        Ok(())
    }
}
