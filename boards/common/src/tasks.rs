//! The bodies of the RTIC tasks both boards declare, and the channels between them. RTIC 2
//! wants each task declared in the board's app (its binding, priority and resources); its
//! body is one call into here:
//!
//! | task | body |
//! |---|---|
//! | control (priority 3), after each step | [`StepLinks::after_step`] |
//! | VFD master (priority 2) | [`vfd_master`]: [`vfd_pass`] on each [`VfdRequest`] |
//! | SCADA server (priority 1) | [`scada_server`]: [`crate::port::serve_scada`] on each wake-up |
//! | log (priority 1) | [`log_task`]: [`log`] on each [`LogMsg`] |
//!
//! A board's `init` makes the channels once with [`links`] and hands each task its ends.

use crate::port::{serve_scada, PortTask};
use crate::{record_max, Margin};
use controller::control::{Commands, LogLine, Outputs, VfdStatus};
use controller::link::{ScadaLink, VfdLink, VfdPort};
use controller::record::RecordRow;
use controller::types::Published;
use core::sync::atomic::Ordering;
use rtic_core::Mutex;
use rtic_sync::channel::{Receiver, Sender};
use rtic_sync::signal::{SignalReader, SignalWriter};

/// Messages the log channel holds (8 s of once-a-second lines; 0.4 s of record rows).
pub const LOG_CAP: usize = 8;

/// What the control task asks of the VFD master after a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VfdRequest {
    /// The step's time, ms (wrapping).
    pub t_ms: u32,
    /// The requested torque reference, % (0..=100; the link sends 0 % during its alarm).
    pub torque_pct: f32,
}

/// What the log task writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LogMsg {
    /// The once-a-second line (the margins follow it).
    Line(LogLine),
    /// A commissioning record row ([`StepLinks::record`]).
    Record(RecordRow),
    /// An error, logged as it is.
    Error(&'static str),
    /// The end of the run: the totals are logged and [`log`] returns whether it passed.
    Done {
        /// The run failed (e.g. the virtual bench diverged).
        failed: bool,
    },
}

/// Wakes the SCADA server (after a step, or from a port's interrupt when a frame may be
/// complete).
pub type ScadaWake = Sender<'static, (), 1>;
/// The SCADA server's wake-ups.
pub type ScadaWait = Receiver<'static, (), 1>;
/// The control task's end of the VFD master's requests.
pub type VfdSend = SignalWriter<'static, VfdRequest>;
/// The VFD master's requests (latest only).
pub type VfdWait = SignalReader<'static, VfdRequest>;
/// The control task's end of the log.
pub type LogSend = Sender<'static, LogMsg, LOG_CAP>;
/// The log task's messages.
pub type LogWait = Receiver<'static, LogMsg, LOG_CAP>;

/// The ends of the channels between the tasks, one field a task's resource.
pub struct Links {
    /// The control task's.
    pub step: StepLinks,
    /// A second SCADA wake-up, for an interrupt handler that sees a frame end.
    pub scada_wake_isr: ScadaWake,
    /// The SCADA server's.
    pub scada_wait: ScadaWait,
    /// The VFD master's.
    pub vfd_wait: VfdWait,
    /// The log task's.
    pub log_wait: LogWait,
}

/// The channels between the tasks, made once (a board's `init` calls it; a second call
/// panics). They are rtic-sync's `make_signal!` and `make_channel!` statics, whose addresses
/// LTO folds into the code (the same channels as RTIC `init` locals measured 3 to 5
/// instructions more per control step, as did this function not inlined into `init`).
#[inline(always)]
pub fn links() -> Links {
    let (vfd_send, vfd_wait) = rtic_sync::make_signal!(VfdRequest);
    let (scada_wake, scada_wait) = rtic_sync::make_channel!((), 1);
    let (log_send, log_wait) = rtic_sync::make_channel!(LogMsg, LOG_CAP);
    Links {
        scada_wake_isr: scada_wake.clone(),
        step: StepLinks::new(vfd_send, scada_wake, log_send),
        scada_wait,
        vfd_wait,
        log_wait,
    }
}

/// The control task's ends of the links: what it leaves the other tasks, never waiting.
pub struct StepLinks {
    vfd: VfdSend,
    scada_wake: ScadaWake,
    log: LogSend,
    /// The models' sample periods (pressure, flow), ms, while the record is on.
    record: Option<(u32, u32)>,
}

impl StepLinks {
    /// The ends the control task keeps.
    pub fn new(vfd: VfdSend, scada_wake: ScadaWake, log: LogSend) -> Self {
        Self {
            vfd,
            scada_wake,
            log,
            record: None,
        }
    }

    /// Turns the commissioning record on: after each step that sampled the pressure, its
    /// [`RecordRow`] to the log task (`periods`: the models' sample periods, ms,
    /// [`controller::control::Controller::sample_periods_ms`]).
    pub fn record(&mut self, periods: (u32, u32)) {
        self.record = Some(periods);
    }
}

impl StepLinks {
    /// What a control step leaves behind, in this order: its `published` values
    /// ([`controller::control::Controller::published`]) to `publish` (the board's shared
    /// resource), the VFD master's request (latest only: when
    /// several late steps run at once, the master's next pass takes the last one's request
    /// and time), the SCADA server woken (its answers read the values just published), the
    /// step counted in [`Margin::steps`], and the once-a-second line queued for the log task
    /// (dropped with a warning if the log task is [`LOG_CAP`] lines behind); with the record
    /// on, the step's row (dropped likewise: its number shows the gap).
    #[inline]
    pub fn after_step(
        &mut self,
        out: &Outputs,
        published: &Published,
        margin: &Margin,
        publish: impl FnOnce(&Published),
    ) {
        publish(published);
        self.vfd.write(VfdRequest {
            t_ms: out.t_ms,
            torque_pct: out.requested_torque_pct,
        });
        let _ = self.scada_wake.try_send(());
        margin.steps.fetch_add(1, Ordering::Relaxed);
        if let Some(line) = out.log {
            if self.log.try_send(LogMsg::Line(line)).is_err() {
                #[cfg(feature = "defmt")]
                defmt::warn!("log line dropped (log task behind)");
            }
        }
        if let Some((p, q)) = self.record {
            if let Some(row) = RecordRow::at_step(out.t_ms, published, p, q) {
                if self.log.try_send(LogMsg::Record(row)).is_err() {
                    #[cfg(feature = "defmt")]
                    defmt::warn!("record row {=u32} dropped (log task behind)", row.seq);
                }
            }
        }
    }

    /// Queues `msg` for the log task; `false` if the log task is [`LOG_CAP`] messages
    /// behind (dropped).
    pub fn log(&mut self, msg: LogMsg) -> bool {
        self.log.try_send(msg).is_ok()
    }
}

/// The VFD master's pass for request `r`: `link` polled at the step's time over `port` (the
/// board's serial [`crate::port::PortTask`], stamped with the time, or an in-process drive),
/// and the link's status for the control task.
#[inline]
pub fn vfd_pass(link: &mut VfdLink, port: &mut impl VfdPort, r: VfdRequest) -> VfdStatus {
    link.poll(r.t_ms, r.torque_pct, port);
    link.status()
}

/// The VFD master task: on each request (waiting for the next; after several steps at once,
/// the last one's), `pass` (e.g. [`vfd_pass`] over the board's port) and its status into
/// `status`, the control task's copy. Never returns.
pub async fn vfd_master(
    wait: &mut VfdWait,
    mut pass: impl FnMut(VfdRequest) -> VfdStatus,
    mut status: impl Mutex<T = VfdStatus>,
) -> ! {
    loop {
        let r = wait.wait().await;
        let s = pass(r);
        status.lock(|x| *x = s);
    }
}

/// The SCADA server task: on each wake-up, every complete request on `port` answered
/// ([`serve_scada`] at `now_us()`, the values from `published`, the holding registers into
/// `commands`). Returns only when every wake-up's sender is gone (never on a board).
pub async fn scada_server<const N: usize>(
    wait: &mut ScadaWait,
    port: &mut PortTask<N>,
    link: &mut ScadaLink,
    now_us: impl Fn() -> u32,
    mut published: impl Mutex<T = Published>,
    mut commands: impl Mutex<T = Commands>,
) {
    while wait.recv().await.is_ok() {
        serve_scada(
            port,
            link,
            now_us(),
            || published.lock(|p| *p),
            |c| commands.lock(|x| *x = c),
        );
    }
}

/// The log task: each message written by [`log`] until the end of the run, then whether it
/// passed (the QEMU board exits with it); `false` if every sender is gone first. On a board
/// whose run does not end, it never returns.
pub async fn log_task(wait: &mut LogWait, margin: &Margin, clock: impl Fn() -> u32) -> bool {
    while let Ok(msg) = wait.recv().await {
        if let Some(passed) = log(msg, margin, &clock) {
            return passed;
        }
    }
    false
}

/// The log task's work on `msg`, with `clock` the board's margin timer (the margins' unit):
/// - a line: written, its write timed as the longest masked section (the logger masks
///   interrupts while it copies a frame, [`Margin::masked_max`]), then the margins as
///   `margin: steps=… control_max=… usart_max=… masked_max=… rx_wait_bound=… bytes=… lost=…`
///   (`cargo xtask flood` reads it);
/// - a record row: written, timed as a line's write;
/// - an error: written as it is;
/// - the end of the run: `done: steps=… control_max=… rx_wait_bound=… lost=…`, and
///   `Some(passed)`: not failed and no received byte lost (the board then exits).
///
/// `None` but at the end. Without the `defmt` feature nothing is written (the margins are
/// still measured).
#[inline(always)]
pub fn log(msg: LogMsg, margin: &Margin, clock: impl Fn() -> u32) -> Option<bool> {
    match msg {
        LogMsg::Line(line) => {
            let t0 = clock();
            #[cfg(feature = "defmt")]
            defmt::info!("{}", line);
            #[cfg(not(feature = "defmt"))]
            let _ = line;
            record_max(&margin.masked_max, clock().wrapping_sub(t0));
            #[cfg(feature = "defmt")]
            {
                let m = margin.snapshot();
                defmt::info!(
                    "margin: steps={=u32} control_max={=u32} usart_max={=u32} masked_max={=u32} rx_wait_bound={=u32} bytes={=u32} lost={=u32}",
                    m.steps,
                    m.control_max,
                    m.usart_handler_max,
                    m.masked_max,
                    m.rx_wait_bound(),
                    m.bytes_received,
                    m.bytes_lost
                );
            }
            None
        }
        LogMsg::Record(_row) => {
            let t0 = clock();
            #[cfg(feature = "defmt")]
            defmt::info!("{}", _row);
            record_max(&margin.masked_max, clock().wrapping_sub(t0));
            None
        }
        LogMsg::Error(_what) => {
            #[cfg(feature = "defmt")]
            defmt::error!("{=str}", _what);
            None
        }
        LogMsg::Done { failed } => {
            let m = margin.snapshot();
            #[cfg(feature = "defmt")]
            defmt::info!(
                "done: steps={=u32} control_max={=u32} rx_wait_bound={=u32} lost={=u32}",
                m.steps,
                m.control_max,
                m.rx_wait_bound(),
                m.bytes_lost
            );
            Some(!failed && m.bytes_lost == 0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller::control::Config;
    use controller::types::{Arithmetic, Mode};
    use controller::virtual_bench::{VirtualBench, VirtualBenchConfig, VirtualIo};
    use core::future::Future;
    use core::pin::pin;
    use core::task::{Context, Poll, Waker};
    use rtic_core::Exclusive;
    use rtic_sync::channel::Channel;
    use rtic_sync::signal::Signal;
    use std::boxed::Box;
    use std::cell::Cell;

    /// The channels as [`super::links`] makes them, leaked to `'static` instead of its
    /// statics, so that each test has its own.
    fn links() -> Links {
        let (vfd_send, vfd_wait) = Box::leak(Box::new(Signal::new())).split();
        let (scada_wake, scada_wait) = Box::leak(Box::new(Channel::new())).split();
        let (log_send, log_wait) = Box::leak(Box::new(Channel::new())).split();
        Links {
            scada_wake_isr: scada_wake.clone(),
            step: StepLinks::new(vfd_send, scada_wake, log_send),
            vfd_wait,
            scada_wait,
            log_wait,
        }
    }

    /// What a controller publishes at `t_ms`.
    fn values(t_ms: u32) -> Published {
        Published {
            torque_pct: t_ms as f32 / 10.0,
            ..Published::default()
        }
    }

    fn outputs(t_ms: u32, log: bool) -> Outputs {
        Outputs {
            t_ms,
            torque_ref_pct: 12.5,
            requested_torque_pct: t_ms as f32 / 100.0,
            bench: None,
            log: log.then_some(LogLine {
                t_ms,
                mode: Mode::Manual,
                arithmetic: Arithmetic::F32,
                values: values(t_ms),
            }),
        }
    }

    #[test]
    fn after_a_step_each_task_gets_its_share() {
        let mut l = links();
        let margin = Margin::new();
        let mut published = Published::default();
        let out = outputs(7, true);
        l.step
            .after_step(&out, &values(7), &margin, |p| published = *p);
        assert_eq!(published, values(7));
        assert_eq!(
            l.vfd_wait.try_read(),
            Some(VfdRequest {
                t_ms: 7,
                torque_pct: 0.07
            })
        );
        assert!(l.scada_wait.try_recv().is_ok());
        assert!(l.scada_wait.try_recv().is_err(), "one wake-up");
        assert_eq!(margin.snapshot().steps, 1);
        assert_eq!(
            l.log_wait.try_recv().ok(),
            Some(LogMsg::Line(out.log.unwrap()))
        );
        assert!(l.log_wait.try_recv().is_err());
    }

    #[test]
    fn the_vfd_master_takes_the_last_request_and_wake_ups_merge() {
        let mut l = links();
        let margin = Margin::new();
        for t in 1..=5 {
            l.step
                .after_step(&outputs(t, false), &values(t), &margin, |_| {});
        }
        assert_eq!(margin.snapshot().steps, 5);
        assert_eq!(l.vfd_wait.try_read().map(|r| r.t_ms), Some(5));
        assert_eq!(l.vfd_wait.try_read(), None, "read once");
        assert!(l.scada_wait.try_recv().is_ok());
        assert!(l.scada_wait.try_recv().is_err(), "wake-ups merge");
        assert!(l.log_wait.try_recv().is_err(), "no line without one");
        // The interrupts' wake-up reaches the same server.
        assert!(l.scada_wake_isr.try_send(()).is_ok());
        assert!(l.scada_wait.try_recv().is_ok());
    }

    #[test]
    fn a_log_task_behind_loses_lines_not_steps() {
        let mut l = links();
        let margin = Margin::new();
        let n = LOG_CAP as u32 + 3;
        for t in 0..n {
            l.step
                .after_step(&outputs(t, true), &values(t), &margin, |_| {});
        }
        assert_eq!(margin.snapshot().steps, n);
        for t in 0..LOG_CAP as u32 {
            match l.log_wait.try_recv() {
                Ok(LogMsg::Line(line)) => assert_eq!(line.t_ms, t),
                other => panic!("line {t}: {other:?}"),
            }
        }
        assert!(l.log_wait.try_recv().is_err(), "the later lines dropped");
        assert!(l.step.log(LogMsg::Error("e")));
        assert_eq!(l.log_wait.try_recv().ok(), Some(LogMsg::Error("e")));
    }

    #[test]
    fn the_log_times_the_write_and_tells_the_end() {
        let margin = Margin::new();
        let t = Cell::new(0u32);
        // Each reading of the clock advances it by 7 counts: a line's write takes 7.
        let clock = || {
            t.set(t.get().wrapping_add(7));
            t.get()
        };
        let line = outputs(1000, true).log.unwrap();
        assert_eq!(log(LogMsg::Line(line), &margin, clock), None);
        assert_eq!(margin.snapshot().masked_max, 7);
        t.set(u32::MAX - 3); // the timer wraps during the write
        assert_eq!(log(LogMsg::Line(line), &margin, clock), None);
        assert_eq!(margin.snapshot().masked_max, 7);
        assert_eq!(log(LogMsg::Error("x"), &margin, clock), None);
        assert_eq!(
            log(LogMsg::Done { failed: false }, &margin, clock),
            Some(true)
        );
        assert_eq!(
            log(LogMsg::Done { failed: true }, &margin, clock),
            Some(false)
        );
        margin.bytes_lost.fetch_add(1, Ordering::Relaxed);
        assert_eq!(
            log(LogMsg::Done { failed: false }, &margin, clock),
            Some(false)
        );
    }

    /// The VFD master on the virtual bench's in-process drive: the link alarm clears once
    /// the drive answers, and each pass reports the link's status.
    #[test]
    fn vfd_passes_bring_the_link_up() {
        let config = Config::bench();
        let mut link = VfdLink::new(config.vfd).unwrap();
        let bench = VirtualBench::new(VirtualBenchConfig::default_offsets(1)).unwrap();
        let mut io = VirtualIo::new(bench, config.vfd).unwrap();
        let mut status = VfdStatus::START;
        for t_ms in 0..2000 {
            status = vfd_pass(
                &mut link,
                &mut io,
                VfdRequest {
                    t_ms,
                    torque_pct: 30.0,
                },
            );
            assert_eq!(status, link.status());
        }
        assert!(!status.link_alarm, "{status:?}");
        assert!(status.reads_ok > 0);
        assert!(status.readings.is_some());
    }

    /// Polls `f` once (the channels here never need a wake-up: what a test sends is there).
    fn poll_once<F: Future>(f: F) -> Poll<F::Output> {
        pin!(f)
            .as_mut()
            .poll(&mut Context::from_waker(Waker::noop()))
    }

    #[test]
    fn the_vfd_master_task_passes_each_request_and_publishes_the_status() {
        let mut l = links();
        let margin = Margin::new();
        let mut status = VfdStatus::START;
        let mut seen = std::vec::Vec::new();
        for t in [3, 4] {
            l.step
                .after_step(&outputs(t, false), &values(t), &margin, |_| {});
        }
        let task = vfd_master(
            &mut l.vfd_wait,
            |r| {
                seen.push(r.t_ms);
                VfdStatus {
                    reads_ok: r.t_ms,
                    ..VfdStatus::START
                }
            },
            Exclusive(&mut status),
        );
        assert!(
            poll_once(task).is_pending(),
            "it waits for the next request"
        );
        assert_eq!(seen, [4], "only the latest request");
        assert_eq!(status.reads_ok, 4);
    }

    #[test]
    fn the_scada_server_task_serves_each_wake_up_until_its_senders_are_gone() {
        let config = controller::control::Config::bench();
        let mut link = ScadaLink::new(&config).unwrap();
        let rx: &'static mut crate::port::RxQueue<64> =
            Box::leak(Box::new(crate::port::RxQueue::new()));
        let tx: &'static mut heapless::spsc::Queue<controller::modbus::Frame, 3> =
            Box::leak(Box::new(heapless::spsc::Queue::new()));
        let ((mut rx_p, rx_c), (tx_p, mut tx_c)) = (rx.split(), tx.split());
        let mut port = PortTask::new(rx_c, tx_p, 1000, None, || {});
        // A request for the holding registers, ended by the gap mark.
        let body = [config.scada_unit, 3, 0, 0, 0, 1];
        let crc = controller::modbus::crc16(&body).to_le_bytes();
        for &b in body.iter().chain(crc.iter()) {
            rx_p.enqueue(u16::from(b)).unwrap();
        }
        rx_p.enqueue(crate::port::GAP).unwrap();
        let Links {
            step,
            scada_wake_isr,
            mut scada_wait,
            ..
        } = links();
        let mut wake = scada_wake_isr;
        wake.try_send(()).unwrap();
        drop((step, wake));
        let mut published = Published::default();
        let mut commands = Commands {
            setpoint_pct: 12.34,
            ..link.commands()
        };
        let served = poll_once(scada_server(
            &mut scada_wait,
            &mut port,
            &mut link,
            || 77,
            Exclusive(&mut published),
            Exclusive(&mut commands),
        ));
        assert!(served.is_ready(), "no sender left: the task ends");
        assert_eq!(port.now_us, 77);
        let answer = tx_c.dequeue().expect("an answer");
        assert_eq!(answer[..2], [config.scada_unit, 3]);
        assert_eq!(commands, link.commands());
    }

    #[test]
    fn the_log_task_ends_with_the_run() {
        let mut l = links();
        let margin = Margin::new();
        let line = outputs(1000, true).log.unwrap();
        assert!(l.step.log(LogMsg::Line(line)));
        assert!(l.step.log(LogMsg::Done { failed: false }));
        assert_eq!(
            poll_once(log_task(&mut l.log_wait, &margin, || 0)),
            Poll::Ready(true)
        );
        assert!(l.step.log(LogMsg::Done { failed: true }));
        assert_eq!(
            poll_once(log_task(&mut l.log_wait, &margin, || 0)),
            Poll::Ready(false)
        );
        assert!(l.step.log(LogMsg::Error("still running")));
        assert!(poll_once(log_task(&mut l.log_wait, &margin, || 0)).is_pending());
        // Every sender gone before the end: not passed.
        let Links {
            step, mut log_wait, ..
        } = l;
        drop(step);
        assert_eq!(
            poll_once(log_task(&mut log_wait, &margin, || 0)),
            Poll::Ready(false)
        );
    }

    /// The one call of the real [`super::links`] in this process.
    #[test]
    fn the_boards_links_connect_the_tasks() {
        let mut l = super::links();
        let margin = Margin::new();
        l.step
            .after_step(&outputs(9, true), &values(9), &margin, |_| {});
        assert_eq!(l.vfd_wait.try_read().map(|r| r.t_ms), Some(9));
        assert!(l.scada_wait.try_recv().is_ok());
        assert!(l.scada_wake_isr.try_send(()).is_ok());
        assert!(l.scada_wait.try_recv().is_ok());
        assert!(matches!(l.log_wait.try_recv(), Ok(LogMsg::Line(_))));
    }
}
