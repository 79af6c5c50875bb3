//! The bench controller on a NUCLEO-F446RE: the real transmitters, the VFD's analog torque
//! reference, the two RS-485 Modbus RTU links, the watchdog, the user LED and defmt logs
//! over RTT (`probe-rs run --chip STM32F446RETx`, this crate's cargo runner), as an RTIC 2
//! application with the schedule of the `board-common` crate:
//!
//! | priority | task | here |
//! |---|---|---|
//! | 4 | `usart1`, `usart6` (RXNE, TC) and `tim6`, `tim7` (the RTU gap) | bytes into lock-free receive queues (`board_common::port::RxQueue`), frames out of `heapless` queues |
//! | 3 | `control` (SysTick, 1 kHz) | one [`board_common::Controller`] step, ADC, DAC, watchdog, LED |
//! | 2 | `vfd` | the VFD master, one pass per step |
//! | 1 | `scada`, `log` | the SCADA server, defmt lines |
//! | idle | | `wfi` |
//!
//! # Serial lines
//! Each USART interrupts on every received byte (RXNE) and, while a frame goes out, on every
//! transmitted one (TC: the next byte is written from the handler, so consecutive bytes are
//! apart by the handler's latency, far below the 1.5 characters the spec allows inside a
//! frame). Every received byte restarts the port's basic timer (TIM6 for SCADA, TIM7 for the
//! VFD) as a one-shot of 3.5 characters ([`controller::rtu::gap_us`]: 2 006 µs at 19 200 baud,
//! 11-bit characters as the Modbus spec counts them); when it expires, the frame is complete.
//! The driver enable (DE and /RE tied) rises with the first byte and falls once the last stop
//! bit is out.
//!
//! # Clocks
//! HSE 8 MHz in bypass mode (the ST-LINK's MCO drives OSC_IN, the board's default), PLL to a
//! 180 MHz SYSCLK (the HAL turns the regulator's over-drive on above 168 MHz); AHB 180 MHz,
//! APB2 90 MHz, APB1 45 MHz (timers 90 MHz). SysTick, from the core clock, starts the control
//! task every 1 ms; the margins are DWT cycle counts.
//!
//! # Wiring
//!
//! | pin  | Nucleo header (Arduino)  | signal | notes |
//! |------|--------------------------|--------|-------|
//! | PA0  | CN8 A0, CN7-28           | pressure transmitter, ADC1_IN0 | 4-20 mA loop through a 150 Ω shunt to GND (0.6-3.0 V; 22 mA = 3.3 V full scale); a series resistor (≈ 1 kΩ) and clamp diodes to 3.3 V / GND protect the pin if the shunt opens |
//! | PA1  | CN8 A1, CN7-30           | flow transmitter, ADC1_IN1 | as PA0 |
//! | PA4  | CN8 A2, CN7-32           | torque reference, DAC_OUT1, 0-3.3 V | DAC output buffer off (rail to rail, up to 15 kΩ source): into an external non-inverting amplifier, gain 1 + R2/R1 = 3.03 (e.g. R1 = 10.0 kΩ, R2 = 20.3 kΩ, E192), single-supply op-amp whose input and output reach 0 V (rail-to-rail, 12-15 V supply), to the VFD's 0-10 V analog input; a 10 MΩ pull-down on the amplifier's input so the VFD sees 0 V while the MCU is in reset (keep the DAC's load ≥ 1.5 MΩ: 10 MΩ costs < 0.2 %) |
//! | PA9  | CN5 D8, CN10-21          | SCADA USART1_TX (AF7) | to DI of an RS-485 transceiver (e.g. MAX3485, 3.3 V) |
//! | PA10 | CN9 D2, CN10-33          | SCADA USART1_RX (AF7) | from RO; internal pull-up on (RO is high-Z while the driver is on) |
//! | PA8  | CN9 D7, CN10-23          | SCADA RS-485 DE | to DE and /RE tied together: high while sending |
//! | PC6  | CN10-4 (morpho only)     | VFD USART6_TX (AF8) | to DI of a second transceiver |
//! | PC7  | CN5 D9, CN10-19          | VFD USART6_RX (AF8) | from RO; internal pull-up on |
//! | PB0  | CN8 A3, CN7-34           | VFD RS-485 DE | DE and /RE tied; PB0 is free on the NUCLEO-F446RE (it only reaches A3 and the morpho pin) |
//! | PA5  | CN5 D13, CN10-11         | user LED LD2 | toggled once a second: the control task runs |
//! | GND  | CN6 GND, CN7-8/19/22     | common | shunts, amplifier, transceivers |
//!
//! Both RS-485 links: 19 200 baud, 8N1, two-wire half duplex; 120 Ω termination across A/B at
//! both ends of each bus, and fail-safe biasing at one end (e.g. 560 Ω A to 3.3 V and B to
//! GND) unless the transceivers are true fail-safe, so that an idle bus reads as marks and not
//! as noise (noise would break the framing by silence).
//!
//! Left as the board ships them: PA2/PA3 (USART2 to the ST-LINK virtual COM port), PA13/PA14
//! (SWD), PC13 (user button), PH0/PH1 (HSE from the ST-LINK MCO).
//!
//! # Faults
//! A HardFault (a panic ends in one: its file and line logged, then `udf`) logs the faulting PC,
//! switches the torque reference off (the DAC channel disabled: the amplifier's pull-down
//! takes the VFD's input to 0 V) and resets the MCU, which starts stopped (mode 0). A control
//! task that stops running is reset by the independent watchdog (≈ 68-190 ms).
#![no_std]
// The board is where the hardware is: register reads and writes the HAL does not wrap, the
// fault handler. Each `unsafe` block says why it is sound.
#![allow(unsafe_code)]
#![no_main]

use defmt_rtt as _;
use stm32f4xx_hal::pac;

/// Modbus RTU line speed, bit/s (both links).
const BAUD_BPS: u32 = board_common::RTU_BAUD;
/// Core clock, Hz.
const SYSCLK_HZ: u32 = 180_000_000;
/// Watchdog timeout, ms. The IWDG runs from the LSI (17-47 kHz on the F446, 32 kHz nominal),
/// so the real timeout is ≈ 68-190 ms; the control task feeds it every 1 ms.
const WATCHDOG_MS: u32 = 100;
/// LED LD2 toggles every this many control steps (1 ms each): once a second.
const LED_TOGGLE_STEPS: u32 = 1000;
/// Silence after which a frame still held is given up, µs (the gap timer ends frames; this
/// only clears what a lost timer event would leave behind).
const STALE_FRAME_US: u32 = 20_000;

/// Microseconds from TIM5 running free at 1 MHz (32 bits, wraps every 71 min).
fn now_us() -> u32 {
    // SAFETY: a read of a free-running counter register; TIM5 is set up once in `init` and
    // never written again.
    unsafe { (*pac::TIM5::ptr()).cnt().read().bits() }
}

/// The cycle counter (DWT CYCCNT, 180 MHz): the margins' unit.
fn cycles() -> u32 {
    cortex_m::peripheral::DWT::cycle_count()
}

// HardFault (a stack overflow too: see the trampoline).
board_common::hard_fault_trampoline!(hard_fault);

/// Takes the torque reference to 0 V, logs the fault (`None`: a stack overflow) and resets
/// the MCU.
fn hard_fault(ef: Option<&board_common::fault::ExceptionFrame>) -> ! {
    // SAFETY: the DAC's control and data registers, written once with every task stopped
    // (a HardFault preempts them all): channel 1 off, its code 0.
    unsafe {
        let dac = &*pac::DAC::ptr();
        dac.dhr12r1().write(|w| w.daccdhr().set(0));
        dac.cr().modify(|_, w| w.en1().clear_bit());
    }
    board_common::fault::report(ef);
    defmt::error!("torque reference off, reset");
    cortex_m::peripheral::SCB::sys_reset()
}

/// A panic logs its file and line ([`board_common::fault::report_panic`]: not its message,
/// whose formatting would link `core::fmt`, ≈ 1.4 KB), then ends in the HardFault handler
/// (torque reference off, reset).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    board_common::fault::report_panic(info);
    cortex_m::asm::udf()
}

/// The timing margins (DWT cycles at 180 MHz).
static MARGIN: board_common::Margin = board_common::Margin::new();

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [EXTI0, EXTI1, EXTI2])]
mod app {
    use super::*;
    use board_common::dac::{torque_code, DAC12_FULL_SCALE};
    use board_common::port::{PortIsr, PortTask, RxQueue, RX_QUEUE, TX_QUEUE};
    use board_common::tasks::{
        log_task, scada_server, vfd_master, vfd_pass, LogWait, ScadaWait, ScadaWake, StepLinks,
        VfdWait,
    };
    use board_common::{record_max, Controller};
    use controller::control::{Commands, Config, Inputs, VfdStatus};
    use controller::link::{ScadaLink, VfdLink};
    use controller::modbus::Frame;
    use controller::rtu::{gap_us, Rs485};
    use controller::types::Published;
    use heapless::spsc::Queue;
    use stm32f4xx_hal::{
        adc::{
            config::{AdcConfig, Clock, SampleTime},
            Adc,
        },
        dac::{DacOut, DacPin, C1},
        gpio::{Analog, Output, PushPull, PA0, PA1, PA5, PA8, PB0},
        prelude::*,
        rcc::Config as RccConfig,
        serial::{self, Rx, Serial, Tx},
        timer::{self, CounterUs, Event, Flag},
        watchdog::IndependentWatchdog,
    };

    /// ADC sampling time of each conversion: 480 ADC clocks, (480 + 12) / 22.5 MHz ≈ 22 µs,
    /// busy-waited in the control task when a sample is due (twice per 100 ms); the long
    /// sampling lets the 150 Ω source (and a protection resistor and filter capacitor, if
    /// fitted) settle fully. The sampling instant is the control step's, within its jitter.
    const SAMPLE_TIME: SampleTime = SampleTime::Cycles_480;

    type ScadaIsr = PortIsr<Tx<pac::USART1>, Rx<pac::USART1>, PA8<Output<PushPull>>>;
    type VfdIsr = PortIsr<Tx<pac::USART6>, Rx<pac::USART6>, PB0<Output<PushPull>>>;

    /// A port's interrupt side and its gap timer `T`, shared by the USART's and the timer's
    /// handlers (both priority 4: the lock costs nothing).
    pub struct Line<P, T> {
        port: P,
        gap: CounterUs<T>,
    }

    impl<TX, RX, DE, T> Line<PortIsr<TX, RX, DE>, T>
    where
        TX: embedded_hal_nb::serial::Write<u8>,
        RX: embedded_hal_nb::serial::Read<u8>,
        DE: embedded_hal::digital::OutputPin,
        T: timer::Instance,
    {
        /// The USART's interrupt: the port's work, the gap timer restarted by a received
        /// byte. Returns whether a frame is still going out (the TC interrupt stays on).
        fn on_usart(&mut self) -> bool {
            let done = self.port.on_interrupt(&MARGIN);
            if done.received > 0 {
                let _ = self.gap.start(gap_us(BAUD_BPS).micros());
            }
            done.sending
        }

        /// The gap timer's interrupt: the line has been silent for 3.5 characters, the frame
        /// is complete.
        fn on_gap(&mut self) {
            self.gap.clear_flags(Flag::Update);
            let _ = self.gap.cancel();
            self.port.mark_gap(&MARGIN);
        }
    }

    #[shared]
    struct Shared {
        scada_line: Line<ScadaIsr, pac::TIM6>,
        vfd_line: Line<VfdIsr, pac::TIM7>,
        commands: Commands,
        published: Published,
        vfd_status: VfdStatus,
    }

    #[local]
    struct Local {
        core: Controller,
        adc: Adc<pac::ADC1>,
        pressure_pin: PA0<Analog>,
        flow_pin: PA1<Analog>,
        dac: C1,
        watchdog: IndependentWatchdog,
        led: PA5<Output<PushPull>>,
        scada_port: PortTask,
        vfd_port: PortTask,
        scada: ScadaLink,
        vfd: VfdLink,
        step: StepLinks,
        scada_wake_gap: ScadaWake,
        scada_wait: ScadaWait,
        vfd_wait: VfdWait,
        log_wait: LogWait,
    }

    #[init(local = [
        rx1: RxQueue<RX_QUEUE> = RxQueue::new(),
        tx1: Queue<Frame, TX_QUEUE> = Queue::new(),
        rx6: RxQueue<RX_QUEUE> = RxQueue::new(),
        tx6: Queue<Frame, TX_QUEUE> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut cp = cx.core;
        let config = Config::bench();
        // A configuration the controller refuses is a build-time mistake: the panic handler logs
        // it and the HardFault handler resets with the torque reference off.
        let core = board_common::build_controller(&config).unwrap_or_else(|_| panic!("controller"));
        let scada = ScadaLink::new(&config).unwrap_or_else(|_| panic!("SCADA"));
        let vfd = VfdLink::new(config.vfd).unwrap_or_else(|_| panic!("VFD map"));

        let mut rcc = dp.RCC.freeze(
            RccConfig::hse(8.MHz())
                .bypass_hse_oscillator()
                .sysclk(SYSCLK_HZ.Hz()),
        );
        // TIM5 free-running at 1 MHz from the 90 MHz timer clock (APB1 × 2): the links' µs.
        // SAFETY: RCC's APB1 enable register, read-modify-written once before any task runs.
        unsafe {
            (*pac::RCC::ptr())
                .apb1enr()
                .modify(|_, w| w.tim5en().set_bit())
        };
        board_common::free_running!(&dp.TIM5, 89);
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();

        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let gpioc = dp.GPIOC.split(&mut rcc);

        // The torque reference first, at 0 V.
        let mut dac = dp.DAC.constrain(gpioa.pa4.into_analog(), &mut rcc);
        // Output buffer off (BOFF1): the buffered output only spans 0.2 V..VDDA - 0.2 V, so
        // 0 % would reach the VFD as ≈ 0.6 V (≈ 6 % torque) and 100 % as ≈ 9.4 V.
        // SAFETY: one read-modify-write of DAC_CR during start-up, before the channel is
        // enabled and before any task runs; the HAL's `C1` writes the same register.
        unsafe { (*pac::DAC::ptr()).cr().modify(|_, w| w.boff1().set_bit()) };
        dac.set_value(0);
        dac.enable();

        let adc = Adc::new(
            dp.ADC1,
            true,
            AdcConfig::default().clock(Clock::Pclk2_div_4),
            &mut rcc,
        );

        let mut s1: Serial<pac::USART1> = Serial::new(
            dp.USART1,
            (
                gpioa.pa9.into_alternate::<7>(),
                gpioa.pa10.into_alternate::<7>().internal_pull_up(true),
            ),
            serial::Config::default().baudrate(BAUD_BPS.bps()),
            &mut rcc,
        )
        .unwrap_or_else(|_| panic!("USART1"));
        let mut s6: Serial<pac::USART6> = Serial::new(
            dp.USART6,
            (
                gpioc.pc6.into_alternate::<8>(),
                gpioc.pc7.into_alternate::<8>().internal_pull_up(true),
            ),
            serial::Config::default().baudrate(BAUD_BPS.bps()),
            &mut rcc,
        )
        .unwrap_or_else(|_| panic!("USART6"));
        s1.listen(serial::Event::RxNotEmpty);
        s6.listen(serial::Event::RxNotEmpty);
        let (tx1, rx1) = s1.split();
        let (tx6, rx6) = s6.split();

        let (p1, c1) = cx.local.rx1.split();
        let (pt1, ct1) = cx.local.tx1.split();
        let (p6, c6) = cx.local.rx6.split();
        let (pt6, ct6) = cx.local.tx6.split();
        // DE and /RE tied: the transceiver hears its own transmission (dropped as the echo).
        let scada_isr = PortIsr::new(
            Rs485::half_duplex(tx1, rx1, gpioa.pa8.into_push_pull_output()),
            p1,
            ct1,
        );
        let vfd_isr = PortIsr::new(
            Rs485::half_duplex(tx6, rx6, gpiob.pb0.into_push_pull_output()),
            p6,
            ct6,
        );
        let mut gap1 = dp.TIM6.counter_us(&mut rcc);
        let mut gap7 = dp.TIM7.counter_us(&mut rcc);
        gap1.listen(Event::Update);
        gap7.listen(Event::Update);
        let scada_port = PortTask::new(c1, pt1, STALE_FRAME_US, None, || {
            rtic::pend(pac::Interrupt::USART1)
        });
        let vfd_port = PortTask::new(c6, pt6, STALE_FRAME_US, None, || {
            rtic::pend(pac::Interrupt::USART6)
        });

        board_common::start_systick(cp.SYST, SYSCLK_HZ / 1000 - 1);

        #[cfg_attr(not(feature = "record"), allow(unused_mut))]
        let mut links = board_common::tasks::links();
        // The commissioning record (`cargo xtask record --nucleo`): a row per pressure
        // sample over RTT, in the image built with feature `record` only.
        #[cfg(feature = "record")]
        links.step.record(core.sample_periods_ms());

        // The watchdog last, so that a slow start-up cannot reset the board in a loop;
        // frozen while a debugger halts the core.
        let mut watchdog = IndependentWatchdog::new(dp.IWDG);
        watchdog.stop_on_debug(&dp.DBGMCU, true);
        watchdog.start(WATCHDOG_MS.millis());

        defmt::info!(
            "NUCLEO-F446RE bench controller: sysclk {=u32} Hz, RTU {=u32} baud, gap {=u32} µs, margins in DWT cycles",
            rcc.clocks.sysclk().raw(),
            BAUD_BPS,
            gap_us(BAUD_BPS)
        );
        let _ = scada::spawn();
        let _ = vfd::spawn();
        let _ = log::spawn();
        (
            Shared {
                scada_line: Line {
                    port: scada_isr,
                    gap: gap1,
                },
                vfd_line: Line {
                    port: vfd_isr,
                    gap: gap7,
                },
                commands: scada.commands(),
                published: Published::default(),
                vfd_status: VfdStatus::START,
            },
            Local {
                core,
                adc,
                pressure_pin: gpioa.pa0.into_analog(),
                flow_pin: gpioa.pa1.into_analog(),
                dac,
                watchdog,
                led: gpioa.pa5.into_push_pull_output(),
                scada_port,
                vfd_port,
                scada,
                vfd,
                step: links.step,
                scada_wake_gap: links.scada_wake_isr,
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

    /// Turns the transmission-complete interrupt of a USART on while it sends.
    macro_rules! tc_interrupt {
        ($usart:ty, $on:expr) => {
            // SAFETY: one read-modify-write of CR1's TCIE bit from the port's own priority-4
            // handlers, which never preempt each other; the HAL's halves only touch CR1 at
            // start-up.
            unsafe { (*<$usart>::ptr()).cr1().modify(|_, w| w.tcie().bit($on)) }
        };
    }

    /// SCADA's USART: received bytes into the queue (each restarts the gap timer), the answer
    /// out byte by byte on TC.
    #[task(binds = USART1, priority = 4, shared = [scada_line])]
    fn usart1(mut cx: usart1::Context) {
        let t0 = cycles();
        let sending = cx.shared.scada_line.lock(|l| l.on_usart());
        tc_interrupt!(pac::USART1, sending);
        record_max(&MARGIN.usart_handler_max, cycles().wrapping_sub(t0));
    }

    /// SCADA's line has been silent for 3.5 characters: the frame is complete.
    #[task(binds = TIM6_DAC, priority = 4, shared = [scada_line], local = [scada_wake_gap])]
    fn tim6(mut cx: tim6::Context) {
        cx.shared.scada_line.lock(|l| l.on_gap());
        let _ = cx.local.scada_wake_gap.try_send(());
    }

    /// The VFD's USART, as USART1.
    #[task(binds = USART6, priority = 4, shared = [vfd_line])]
    fn usart6(mut cx: usart6::Context) {
        let t0 = cycles();
        let sending = cx.shared.vfd_line.lock(|l| l.on_usart());
        tc_interrupt!(pac::USART6, sending);
        record_max(&MARGIN.usart_handler_max, cycles().wrapping_sub(t0));
    }

    /// The VFD's line has been silent for 3.5 characters.
    #[task(binds = TIM7, priority = 4, shared = [vfd_line])]
    fn tim7(mut cx: tim7::Context) {
        cx.shared.vfd_line.lock(|l| l.on_gap());
    }

    /// Every 1 ms: the due ADC conversions, one controller step, the torque reference to the
    /// DAC, the watchdog fed; then the links are woken with what the step left them.
    #[task(binds = SysTick, priority = 3,
           local = [core, adc, pressure_pin, flow_pin, dac, watchdog, led, step,
                    steps: u32 = 0],
           shared = [commands, published, vfd_status])]
    fn control(mut cx: control::Context) {
        let t0 = cycles();
        let l = cx.local;
        let (p_due, q_due) = l.core.samples_due();
        let inputs = Inputs {
            pressure_code: if p_due {
                l.adc.convert(l.pressure_pin, SAMPLE_TIME)
            } else {
                0
            },
            flow_code: if q_due {
                l.adc.convert(l.flow_pin, SAMPLE_TIME)
            } else {
                0
            },
            commands: cx.shared.commands.lock(|c| *c),
            vfd: cx.shared.vfd_status.lock(|s| *s),
        };
        let out = l.core.step(&inputs);
        // 0 % → 0 V, 100 % → 3.3 V at PA4 (×3.03 → 0-10 V at the VFD).
        l.dac
            .set_value(torque_code(out.torque_ref_pct, DAC12_FULL_SCALE));
        l.watchdog.feed();
        *l.steps = l.steps.wrapping_add(1);
        if l.steps.is_multiple_of(LED_TOGGLE_STEPS) {
            l.led.toggle();
        }
        let published = &mut cx.shared.published;
        l.step.after_step(&out, l.core.published(), &MARGIN, |p| {
            published.lock(|x| *x = *p)
        });
        record_max(&MARGIN.control_max, cycles().wrapping_sub(t0));
    }

    /// The SCADA server.
    #[task(priority = 1, local = [scada, scada_port, scada_wait], shared = [commands, published])]
    async fn scada(cx: scada::Context) {
        let l = cx.local;
        let (port, link) = (l.scada_port, l.scada);
        let (published, commands) = (cx.shared.published, cx.shared.commands);
        scada_server(l.scada_wait, port, link, now_us, published, commands).await
    }

    /// The VFD master: one pass after each control step, at its time (a latest-only signal).
    #[task(priority = 2, local = [vfd, vfd_port, vfd_wait], shared = [vfd_status])]
    async fn vfd(cx: vfd::Context) {
        let (link, port) = (cx.local.vfd, cx.local.vfd_port);
        let pass = |r| vfd_pass(link, port.at(now_us()), r);
        vfd_master(cx.local.vfd_wait, pass, cx.shared.vfd_status).await
    }

    /// The once-a-second line and the margins (DWT cycles at 180 MHz), over RTT. The run
    /// does not end here (no `Done` is sent).
    #[task(priority = 1, local = [log_wait])]
    async fn log(cx: log::Context) {
        log_task(cx.local.log_wait, &MARGIN, cycles).await;
    }
}
