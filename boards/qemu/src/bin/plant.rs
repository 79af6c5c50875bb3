//! The bench controller on QEMU in plant mode (`cargo xtask qemu --plant PTY`): no virtual
//! bench and no VFD link, but an external plant on USART2 (QEMU's second `-serial`) that
//! closes the loop in lockstep, speaking the plant protocol of [`controller::plant`] (text
//! lines; the plant sends a frame, the controller runs its steps on it and answers the
//! torque). The controller steps only on frames, never on a timer: a run is the plant's
//! frames alone, whatever the host's speed, and gives the same replies bit for bit as the
//! same session on the host (`board_common::plant_session`; `cargo xtask plant-check`).
//!
//! | priority | task | here |
//! |---|---|---|
//! | 4 | `usart1`, `usart2` | SCADA and plant bytes into lock-free receive queues (`board_common::port::RxQueue`), answers out of `heapless` queues |
//! | 2 | `plant` | each complete line served ([`controller::plant::PlantSession::feed`]), its reply queued |
//! | 1 | `scada`, `log` | the SCADA server on the session's holding registers, defmt lines |
//! | idle | | `wfi` |
//!
//! The SCADA slave (unit 1, USART1) reads the values of the last step and may write the
//! holding registers; its writes land between two frames when they arrive, so only the
//! plant's in-band `W` lines are deterministic. Its requests end by their content (no step
//! runs between frames to time a silence). A `Q` line ends the run: QEMU exits 0, 250 ms after the `B`
//! (`BYE_READ_NS`: the serial line closes with QEMU).
//!
//! Built only with the `plant` feature (`required-features`): the default image
//! (`pump-qemu`) has none of this. No start-up arguments: the plant sets mode, setpoints and
//! arithmetic with `W` lines; the controller starts as [`board_common::PLANT_CONFIG`] says.
#![no_std]
#![no_main]

use board_common::RTU_BAUD as BAUD;
use board_qemu::{exit, now_ns, now_us, QEMU_SILENCE_US};
use stm32f4xx_hal::pac;

/// How long the board waits after `Q`'s `B` before QEMU exits, ns of its clock (real time in
/// plant mode): QEMU's serial line closes with it, and a `B` the plant had not read yet went
/// with the line (a plant that read its reply 50 ms late lost it in 4 runs of 4; a review saw
/// it in half its sessions under load).
const BYE_READ_NS: u32 = 250_000_000;

/// The timing margins of this run (TIM2 counts: instructions under `-icount shift=0`).
static MARGIN: board_common::Margin = board_common::Margin::new();

/// A reply line: the longest (`T`, an f32 of up to 48 digits and its point) fits.
type ReplyLine = heapless::String<128>;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [EXTI0, EXTI1, EXTI2])]
mod app {
    use super::*;
    use board_common::port::{PortIsr, PortTask, RxQueue, RX_QUEUE, TX_QUEUE};
    use board_common::tasks::{log_task, LogMsg, LogWait, ScadaWait, ScadaWake, StepLinks};
    use board_common::{record_max, Controller};
    use controller::modbus::Frame;
    use controller::plant::{PlantSession, Served};
    use controller::rtu::{NoDe, Rs485};
    use controller::scada::input_registers;
    use controller::types::Published;
    use heapless::spsc::Queue;
    use rtic_sync::channel::{Receiver, Sender};
    use stm32f4xx_hal::serial::{Rx, Tx};

    type Port1 = PortIsr<Tx<pac::USART1>, Rx<pac::USART1>, NoDe>;
    type Port2 = PortIsr<Tx<pac::USART2>, Rx<pac::USART2>, NoDe>;

    #[shared]
    struct Shared {
        /// The plant session: the lockstep and its holding registers (SCADA's too).
        session: PlantSession,
        /// The last step's values, for SCADA.
        published: Published,
    }

    #[local]
    struct Local {
        core: Controller,
        port1: Port1,
        port2: Port2,
        scada_port: PortTask,
        plant_port: PortTask,
        step: StepLinks,
        scada_wake_isr: ScadaWake,
        scada_wait: ScadaWait,
        plant_wake: Sender<'static, (), 1>,
        plant_wait: Receiver<'static, (), 1>,
        log_wait: LogWait,
    }

    #[init(local = [
        rx1: RxQueue<RX_QUEUE> = RxQueue::new(),
        tx1: Queue<Frame, TX_QUEUE> = Queue::new(),
        rx2: RxQueue<RX_QUEUE> = RxQueue::new(),
        tx2: Queue<Frame, TX_QUEUE> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let fail = |what: &str| -> ! {
            defmt::error!("cannot start: {=str}", what);
            exit(false)
        };
        let (core, session) = board_common::plant_session().unwrap_or_else(|_| fail("controller"));

        // The time bases (see the module docs), the clock, the two USARTs.
        let board_qemu::Usarts { tx1, rx1, tx2, rx2 } =
            board_qemu::start_usarts(cx.device, BAUD).unwrap_or_else(|port| fail(port));

        let (p1, c1) = cx.local.rx1.split();
        let (pt1, ct1) = cx.local.tx1.split();
        let (p2, c2) = cx.local.rx2.split();
        let (pt2, ct2) = cx.local.tx2.split();
        let port1 = PortIsr::new(Rs485::full_duplex(tx1, rx1, NoDe), p1, ct1);
        let port2 = PortIsr::new(Rs485::full_duplex(tx2, rx2, NoDe), p2, ct2);
        let scada_port = board_qemu::scada_port(c1, pt1, || rtic::pend(pac::Interrupt::USART1));
        // Lines, not frames: the framer is unused (bytes are taken one by one).
        let plant_port = PortTask::new(c2, pt2, QEMU_SILENCE_US, None, || {
            rtic::pend(pac::Interrupt::USART2)
        });

        let links = board_common::tasks::links();
        let (plant_wake, plant_wait) = rtic_sync::make_channel!((), 1);
        defmt::info!(
            "firmware: plant mode, protocol {=u16} (frames of {=u32} ms) on USART2, SCADA unit 1 on USART1",
            controller::plant::PROTOCOL_VERSION,
            controller::plant::FRAME_PERIOD_MS
        );
        let _ = scada::spawn();
        let _ = plant::spawn();
        let _ = log::spawn();
        (
            Shared {
                session,
                published: Published::default(),
            },
            Local {
                core,
                port1,
                port2,
                scada_port,
                plant_port,
                step: links.step,
                scada_wake_isr: links.scada_wake_isr,
                scada_wait: links.scada_wait,
                plant_wake,
                plant_wait,
                log_wait: links.log_wait,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// SCADA's USART: bytes into the queue, the answer out; wakes the SCADA task.
    #[task(binds = USART1, priority = 4, local = [port1, scada_wake_isr])]
    fn usart1(cx: usart1::Context) {
        let t0 = now_ns();
        // QEMU: the transmit interrupts never fire, so a frame is written out here at once.
        while cx.local.port1.on_interrupt(&MARGIN).sending {}
        let _ = cx.local.scada_wake_isr.try_send(());
        record_max(&MARGIN.usart_handler_max, now_ns().wrapping_sub(t0));
    }

    /// The plant's USART: bytes into the queue, replies out; wakes the plant task.
    #[task(binds = USART2, priority = 4, local = [port2, plant_wake])]
    fn usart2(cx: usart2::Context) {
        let t0 = now_ns();
        let a = cx.local.port2.on_interrupt(&MARGIN);
        let mut sending = a.sending;
        while sending {
            sending = cx.local.port2.on_interrupt(&MARGIN).sending;
        }
        if a.received > 0 {
            let _ = cx.local.plant_wake.try_send(());
        }
        record_max(&MARGIN.usart_handler_max, now_ns().wrapping_sub(t0));
    }

    /// The plant: every received byte fed to the session; each line's reply queued on
    /// USART2; each step's values published and its log line queued. After `Q`, the end.
    #[task(priority = 2, local = [core, plant_port, plant_wait, step], shared = [session, published])]
    async fn plant(cx: plant::Context) {
        let l = cx.local;
        let (mut session, mut published) = (cx.shared.session, cx.shared.published);
        let mut ended = false;
        while !ended && l.plant_wait.recv().await.is_ok() {
            while let Some(byte) = l.plant_port.take_byte() {
                let mut reply = ReplyLine::new();
                let served = session.lock(|s| {
                    s.feed(byte, l.core, &mut reply, |out, values| {
                        l.step
                            .after_step(out, values, &MARGIN, |p| published.lock(|x| *x = *p))
                    })
                });
                if !reply.is_empty() && !l.plant_port.send_frame(reply.as_bytes()) {
                    l.step
                        .log(LogMsg::Error("plant reply dropped (transmit queue full)"));
                }
                if served != Ok(Served::Continue) {
                    if served.is_err() {
                        l.step
                            .log(LogMsg::Error("plant reply longer than its buffer"));
                    }
                    l.step.log(LogMsg::Done {
                        failed: served.is_err(),
                    });
                    ended = true;
                    break;
                }
            }
        }
    }

    /// The SCADA server: requests from USART1's queue, answered against the session's
    /// holding registers and the last step's values.
    #[task(priority = 1, local = [scada_port, scada_wait], shared = [session, published])]
    async fn scada(cx: scada::Context) {
        let (port, wait) = (cx.local.scada_port, cx.local.scada_wait);
        let (mut session, mut published) = (cx.shared.session, cx.shared.published);
        let (mut frame, mut answer) = (Frame::new(), Frame::new());
        while wait.recv().await.is_ok() {
            port.now_us = now_us();
            while port.receive_frame(&mut frame) {
                let inputs = input_registers(&published.lock(|p| *p));
                let n = session.lock(|s| {
                    s.lockstep_mut()
                        .scada_mut()
                        .handle(&frame, &inputs, &mut answer)
                });
                if let Some(n) = n {
                    let _ = port.send_frame(&answer[..n]);
                }
            }
        }
    }

    /// The log: the once-a-second line (of the controller's time), errors; the exit at `Q`,
    /// [`BYE_READ_NS`] after the `B` went out.
    #[task(priority = 1, local = [log_wait])]
    async fn log(cx: log::Context) {
        let passed = log_task(cx.local.log_wait, &MARGIN, now_ns).await;
        let t0 = now_ns();
        while now_ns().wrapping_sub(t0) < BYE_READ_NS {}
        exit(passed)
    }
}
