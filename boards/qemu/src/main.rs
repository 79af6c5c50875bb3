//! The bench controller on QEMU `netduinoplus2` (STM32F405) with the virtual bench on-chip,
//! as an RTIC 2 application with the schedule of the `board-common` crate:
//!
//! | priority | task | here |
//! |---|---|---|
//! | 4 | `usart1`, `usart2` | SCADA and VFD bytes into lock-free receive queues (`board_common::port::RxQueue`), frames out of `heapless` queues |
//! | 3 | `control` (SysTick) | one [`board_common::Controller`] step per elapsed ms, the virtual bench stepped |
//! | 2 | `vfd` | the VFD master, one pass per step |
//! | 1 | `scada`, `log` | the SCADA server, defmt lines |
//! | idle | | `wfi` |
//!
//! - The transmitters, the torque output and the drive are [`VirtualIo`]: the white-box
//!   bench a few percent off the model, transmitter lag, noise and 12-bit ADC codes fed to
//!   the same scaling and fault checks as on a board. QEMU models no usable ADC and no DAC.
//! - SCADA: Modbus RTU slave on USART1 (QEMU's first `-serial`). VFD: the in-process drive,
//!   or with `vfd=uart` the master on USART2 (the second `-serial`).
//! - Logs: defmt over semihosting (QEMU's stdout); `cargo xtask qemu` decodes them.
//!
//! What QEMU 7.2 does not model, and what this board does instead:
//! - **TIM2..5 interrupts** fire at the wrong rate or not at all, but their counters count
//!   QEMU's virtual clock: TIM5 runs free at 1 MHz as the time base (µs, ms) and TIM2 at
//!   1 GHz (virtual ns; instructions under `-icount shift=0`) for the margins. SysTick only
//!   wakes the control task (4 kHz), which steps once per elapsed TIM5 millisecond: in real
//!   time QEMU merges SysTick expiries while its thread waits for the host, so counting them
//!   would lose wall time.
//! - **The RTU silence** (3.5 characters): QEMU's serial lines carry no timing (a byte is
//!   handed over as soon as the last one is read). SCADA requests end by their content
//!   (length and CRC, [`controller::modbus::request_at_end`]) or after [`QEMU_SILENCE_US`],
//!   a request's start after [`board_qemu::QEMU_REQUEST_PATIENCE_US`] (a busy host can hold
//!   a write's bytes up for tens of ms: [`board_qemu::scada_port`]); the Nucleo ends frames
//!   with a timer.
//! - **USART transmit interrupts** (TXE, TC) never fire: a frame is written out from the
//!   handler that starts it (QEMU takes each byte at once).
//! - **RCC PLL**: a PLL-ready wait hangs; the chip stays on its 16 MHz HSI (SysTick and the
//!   timers run on QEMU's clocks whatever the RCC says).
//! - **DWT** (reads 0), **GPIO** (writes ignored), **IWDG** (not modelled: no watchdog here).
#![no_std]
// The board is where the hardware is: register reads and writes the HAL does not wrap, the
// fault handler. Each `unsafe` block says why it is sound.
#![allow(unsafe_code)]
#![no_main]

use board_common::RTU_BAUD as BAUD;
use board_qemu::{args, exit, now_ns, now_us, QEMU_SILENCE_US, QEMU_SYSTICK_HZ, WAKE_HZ};
use stm32f4xx_hal::pac;

/// The timing margins of this run (TIM2 counts: instructions under `-icount shift=0`).
static MARGIN: board_common::Margin = board_common::Margin::new();

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [EXTI0, EXTI1, EXTI2])]
mod app {
    use super::*;
    use board_common::port::{PortIsr, PortTask, RxQueue, RX_QUEUE, TX_QUEUE};
    use board_common::tasks::{
        log_task, scada_server, vfd_master, vfd_pass, LogMsg, LogWait, ScadaWait, ScadaWake,
        StepLinks, VfdWait,
    };
    use board_common::{record_max, Controller};
    use controller::control::{Commands, Config, VfdStatus};
    use controller::link::{ScadaLink, VfdLink};
    use controller::modbus::Frame;
    use controller::rtu::{NoDe, Rs485};
    use controller::types::Published;
    use controller::virtual_bench::{VirtualBench, VirtualBenchConfig, VirtualBoard, VirtualIo};
    use heapless::spsc::Queue;
    use stm32f4xx_hal::serial::{Rx, Tx};

    type Virtual = VirtualBoard<
        { board_common::models::pressure::FRAMES },
        { board_common::models::pressure::HIDDEN },
        { board_common::models::flow::FRAMES },
        { board_common::models::flow::HIDDEN },
    >;
    type Port1 = PortIsr<Tx<pac::USART1>, Rx<pac::USART1>, NoDe>;
    type Port2 = PortIsr<Tx<pac::USART2>, Rx<pac::USART2>, NoDe>;

    #[shared]
    struct Shared {
        /// The virtual bench: codes and the torque output (control), the drive (VFD task).
        io: VirtualIo,
        /// SCADA's holding registers, for the control task.
        commands: Commands,
        /// The control task's values, for SCADA.
        published: Published,
        /// The VFD link's state, for the control task.
        vfd_status: VfdStatus,
    }

    #[local]
    struct Local {
        core: Controller,
        ms: board_common::MsClock,
        run_ms: Option<u32>,
        stopped: bool,
        port1: Port1,
        port2: Port2,
        scada_port: PortTask,
        vfd_port: Option<PortTask>,
        scada: ScadaLink,
        vfd: VfdLink,
        step: StepLinks,
        scada_wake_isr: ScadaWake,
        scada_wait: ScadaWait,
        vfd_wait: VfdWait,
        log_wait: LogWait,
    }

    #[init(local = [
        rx1: RxQueue<RX_QUEUE> = RxQueue::new(),
        tx1: Queue<Frame, TX_QUEUE> = Queue::new(),
        rx2: RxQueue<RX_QUEUE> = RxQueue::new(),
        tx2: Queue<Frame, TX_QUEUE> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut buf = [0u8; 256];
        let a = match args::parse_args(args::command_line(&mut buf)) {
            Ok(a) => a,
            Err(word) => {
                defmt::error!(
                    "bad argument '{=[u8]:a}' (see boards/qemu/src/args.rs)",
                    word
                );
                exit(false)
            }
        };
        let config = Config {
            initial_mode: a.mode,
            initial_setpoint_pct: controller::scada::setpoint_pct(a.setpoint),
            profile_seed: u64::from(a.seed),
            initial_arithmetic: a.arithmetic,
            initial_narmax_adapt: a.adapt,
            virtual_bench: true,
            ..Config::bench()
        };
        let fail = |what: &str| -> ! {
            defmt::error!("cannot start: {=str}", what);
            exit(false)
        };
        let core = board_common::build_controller(&config).unwrap_or_else(|_| fail("controller"));
        let scada = ScadaLink::new(&config).unwrap_or_else(|_| fail("SCADA"));
        let vfd = VfdLink::new(config.vfd).unwrap_or_else(|_| fail("VFD link"));
        let bench = VirtualBench::new(VirtualBenchConfig {
            head_factor: a.head_pml as f32 / 1000.0,
            load_torque_factor: a.torque_pml as f32 / 1000.0,
            ..VirtualBenchConfig::default_offsets(u64::from(a.seed))
        })
        .unwrap_or_else(|_| fail("virtual bench"));
        let io = VirtualIo::new(bench, config.vfd).unwrap_or_else(|| fail("VFD map"));

        // The time bases (see the module docs), the clock, the two USARTs.
        let board_qemu::Usarts { tx1, rx1, tx2, rx2 } =
            board_qemu::start_usarts(cx.device, BAUD).unwrap_or_else(|port| fail(port));

        let (p1, c1) = cx.local.rx1.split();
        let (pt1, ct1) = cx.local.tx1.split();
        let (p2, c2) = cx.local.rx2.split();
        let (pt2, ct2) = cx.local.tx2.split();
        // QEMU's USARTs are full duplex (no echo) and have no driver-enable pin.
        let port1 = PortIsr::new(Rs485::full_duplex(tx1, rx1, NoDe), p1, ct1);
        let port2 = PortIsr::new(Rs485::full_duplex(tx2, rx2, NoDe), p2, ct2);
        let scada_port = board_qemu::scada_port(c1, pt1, || rtic::pend(pac::Interrupt::USART1));
        let vfd_port = a.vfd_uart.then(|| {
            PortTask::new(c2, pt2, QEMU_SILENCE_US, None, || {
                rtic::pend(pac::Interrupt::USART2)
            })
        });

        board_common::start_systick(cx.core.SYST, QEMU_SYSTICK_HZ / WAKE_HZ - 1);

        let mut links = board_common::tasks::links();
        if a.record {
            links.step.record(core.sample_periods_ms());
        }
        defmt::info!(
            "firmware: virtual bench, SCADA unit 1 on USART1, VFD {=str}, mode={=u16} setpoint={=u16} seed={=u32} narmax={=str} head={=u32} torque={=u32} record={=bool} adapt={=bool}{=str}",
            if a.vfd_uart { "on USART2" } else { "virtual" },
            controller::scada::mode_register(a.mode),
            a.setpoint,
            a.seed,
            a.arithmetic.name(),
            a.head_pml,
            a.torque_pml,
            a.record,
            a.adapt,
            if a.run_ms.is_some() { "" } else { ", runs until stopped" }
        );
        let _ = scada::spawn();
        let _ = vfd::spawn();
        let _ = log::spawn();
        (
            Shared {
                io,
                commands: scada.commands(),
                published: Published::default(),
                vfd_status: VfdStatus::START,
            },
            Local {
                core,
                ms: board_common::MsClock::new(now_us()),
                run_ms: a.run_ms,
                stopped: false,
                port1,
                port2,
                scada_port,
                vfd_port,
                scada,
                vfd,
                step: links.step,
                scada_wake_isr: links.scada_wake_isr,
                scada_wait: links.scada_wait,
                vfd_wait: links.vfd_wait,
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

    /// The VFD's USART (with `vfd=uart`).
    #[task(binds = USART2, priority = 4, local = [port2])]
    fn usart2(cx: usart2::Context) {
        let t0 = now_ns();
        while cx.local.port2.on_interrupt(&MARGIN).sending {}
        record_max(&MARGIN.usart_handler_max, now_ns().wrapping_sub(t0));
    }

    /// Every elapsed millisecond of TIM5: one controller step, its outputs to the virtual
    /// bench, the bench stepped; then the links are woken with what the step left them.
    #[task(binds = SysTick, priority = 3,
           local = [core, ms, run_ms, stopped, step],
           shared = [io, commands, published, vfd_status])]
    fn control(mut cx: control::Context) {
        let t0 = now_ns();
        let now = cx.local.ms.now_ms(now_us());
        let core = cx.local.core;
        let links = cx.local.step;
        while !*cx.local.stopped && now.wrapping_sub(core.now_ms()) as i32 >= 0 {
            let commands = cx.shared.commands.lock(|c| *c);
            let vfd = cx.shared.vfd_status.lock(|s| *s);
            let out = cx.shared.io.lock(|io| {
                let inputs = Virtual::inputs(core, io, commands, vfd);
                Virtual::control(core, io, &inputs)
            });
            let Ok(out) = out else {
                links.log(LogMsg::Error("the virtual bench diverged"));
                links.log(LogMsg::Done { failed: true });
                *cx.local.stopped = true;
                break;
            };
            // When QEMU catches up several late steps in one run of this task, the VFD
            // master's next pass takes the last one's request and time.
            let published = &mut cx.shared.published;
            links.after_step(&out, core.published(), &MARGIN, |p| {
                published.lock(|x| *x = *p)
            });
            if cx.local.run_ms.is_some_and(|end| out.t_ms + 1 >= end) {
                links.log(LogMsg::Done { failed: false });
                *cx.local.stopped = true;
            }
        }
        record_max(&MARGIN.control_max, now_ns().wrapping_sub(t0));
    }

    /// The SCADA server: requests from USART1's queue, answers back to it.
    #[task(priority = 1, local = [scada, scada_port, scada_wait], shared = [commands, published])]
    async fn scada(cx: scada::Context) {
        let l = cx.local;
        let (port, link) = (l.scada_port, l.scada);
        let (published, commands) = (cx.shared.published, cx.shared.commands);
        scada_server(l.scada_wait, port, link, now_us, published, commands).await
    }

    /// The VFD master: one pass after each control step, at its time, with its request (a
    /// latest-only signal: after steps caught up at once, the last one); over USART2 or to
    /// the in-process drive.
    #[task(priority = 2, local = [vfd, vfd_port, vfd_wait], shared = [io, vfd_status])]
    async fn vfd(cx: vfd::Context) {
        let (link, port, mut io) = (cx.local.vfd, cx.local.vfd_port, cx.shared.io);
        let pass = |r| match port {
            Some(port) => vfd_pass(link, port.at(now_us()), r),
            None => io.lock(|io| vfd_pass(link, io, r)),
        };
        vfd_master(cx.local.vfd_wait, pass, cx.shared.vfd_status).await
    }

    /// The log: the once-a-second line, the margins, errors; the exit at the end of `run_ms`.
    #[task(priority = 1, local = [log_wait])]
    async fn log(cx: log::Context) {
        exit(log_task(cx.local.log_wait, &MARGIN, now_ns).await)
    }
}
