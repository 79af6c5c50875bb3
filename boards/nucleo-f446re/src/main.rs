//! NUCLEO-F446RE board glue: the real transmitters, the VFD's analog torque reference, the two
//! RS-485 Modbus RTU links, the watchdog, the user LED and defmt logs over RTT (`probe-rs run
//! --chip STM32F446RETx`).
//!
//! Everything the loop decides lives in the `controller` crate; this module only wires the
//! STM32F446's peripherals to [`Io`] and [`Board`].
//!
//! # Clocks
//!
//! HSE 8 MHz in bypass mode (the ST-LINK's MCO drives OSC_IN, the board's default), PLL to a
//! 180 MHz SYSCLK (the HAL turns the regulator's over-drive on above 168 MHz); AHB 180 MHz,
//! APB2 90 MHz, APB1 45 MHz. SysTick, clocked from the core, makes the loop's 1 ms tick.
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
//! | PA5  | CN5 D13, CN10-11         | user LED LD2 | toggled once a second: the loop is alive |
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
//! # What is not done here
//!
//! No interrupts besides SysTick, no DMA: the loop polls the USARTs on every pass (a character
//! takes 521 µs at 19 200 baud, a pass far less) and never sleeps.

use crate::{Board, Loop};
use controller::app::{AppConfig, Io, LogLine};
use controller::rtu::{Frame, RtuPort, Uart};
use defmt_rtt as _;
use panic_probe as _;
use stm32f4xx_hal::{
    adc::{
        config::{AdcConfig, Clock, SampleTime},
        Adc,
    },
    dac::{DacOut, DacPin, C1},
    gpio::{Analog, AnyPin, Output, PA0, PA1, PA5},
    nb, pac,
    prelude::*,
    rcc::Config as RccConfig,
    serial::{self, Rx, Serial, Tx},
    watchdog::IndependentWatchdog,
};

/// Modbus RTU line speed, bit/s (both links).
const BAUD_BPS: u32 = 19_200;

/// Silence that ends an RTU frame, ms (as `controller::rtu` asks: the next millisecond above
/// 3.5 characters, plus one for the tick's resolution).
///
/// 3.5 characters at 19 200 baud 8N1 are 1.82 ms. Bytes are stamped with the whole
/// millisecond in which the loop reads them, so a measured silence of `n` ms is a real one
/// of more than `n - 1` ms: with 3 the frame ends after more than 2 ms of real silence,
/// never less than the 1.82 ms the spec asks for (with 2 it could end after just over 1 ms:
/// still longer than the 0.78 ms, 1.5 characters, allowed inside a frame, but shorter than
/// the spec's inter-frame gap). The cost is at most 1 ms more per exchange.
const RTU_IDLE_MS: u32 = 3;

/// Watchdog timeout, ms. The IWDG runs from the LSI (17-47 kHz on the F446, 32 kHz
/// nominal), so the real timeout is ≈ 68-190 ms; the loop feeds it every 1 ms.
const WATCHDOG_MS: u32 = 100;

/// LED LD2 toggles every this many loop ticks (1 ms each): once a second.
const LED_TOGGLE_TICKS: u32 = 1000;

/// ADC sampling time of each conversion: 480 ADC clocks.
///
/// Sampling is paced by the 1 ms SysTick loop, not by a timer trigger or DMA: the loop asks
/// for a pressure sample every 50 ms and a flow sample every 100 ms, and the conversion runs in
/// the tick that asks, so the sampling instant jitters by less than 1 ms, under 2 % of the
/// 50 ms period — small against the transmitters' own response (tens of ms and more) and
/// invisible to models identified at 50/100 ms. A conversion takes (480 + 12) ADC clocks /
/// 22.5 MHz (ADCCLK = PCLK2 90 MHz / 4) ≈ 22 µs, busy-waited: twice per 100 ms it costs
/// nothing, and it stays far below the 521 µs character time within which the loop must poll
/// the USARTs. The long sampling time lets the 150 Ω source (plus a protection resistor and a
/// filter capacitor, if fitted) settle fully.
const SAMPLE_TIME: SampleTime = SampleTime::Cycles_480;

/// Full scale of the 12-bit DAC, code.
const DAC_FULL_SCALE: f32 = 4095.0;

/// One USART behind an RS-485 transceiver whose DE and /RE are tied to one GPIO, polled
/// (no interrupt, no DMA).
pub struct Rs485<U: serial::Instance> {
    /// Transmit half of the USART.
    tx: Tx<U>,
    /// Receive half of the USART.
    rx: Rx<U>,
    /// Driver enable (DE and /RE tied): high while sending.
    de: AnyPin<Output>,
    /// Bytes dropped for a parity, framing, noise or overrun error since start (count).
    rx_errors: u32,
}

impl<U: serial::Instance> Rs485<U> {
    /// The port on `serial` with the driver enable `de` (driven low: receiving).
    pub fn new(serial: Serial<U>, mut de: AnyPin<Output>) -> Self {
        de.set_low();
        let (tx, rx) = serial.split();
        Self {
            tx,
            rx,
            de,
            rx_errors: 0,
        }
    }

    /// Bytes dropped for a line error since start (count); a few after connecting a cable are
    /// normal, a steady rise means noise, a missing termination or a wrong baud rate.
    pub fn rx_errors(&self) -> u32 {
        self.rx_errors
    }
}

impl<U: serial::Instance> Uart for Rs485<U> {
    /// The received byte, if RXNE; a byte with a line error is dropped (the HAL has already
    /// cleared the error by reading DR) and counted; the frame's CRC then fails upstream.
    fn try_read(&mut self) -> Option<u8> {
        match self.rx.read() {
            Ok(byte) => Some(byte),
            Err(nb::Error::WouldBlock) => None,
            Err(nb::Error::Other(_)) => {
                self.rx_errors = self.rx_errors.wrapping_add(1);
                None
            }
        }
    }

    /// Writes `byte` to DR if TXE (the transmit buffer is free); `false` otherwise.
    fn try_write(&mut self, byte: u8) -> bool {
        self.tx.write(byte).is_ok()
    }

    /// `true` once the last stop bit has left the shift register (TC): only then may the
    /// driver be released.
    fn tx_complete(&mut self) -> bool {
        self.tx.flush().is_ok()
    }

    /// DE (and /RE) high while sending, low while listening.
    fn set_driver(&mut self, on: bool) {
        if on {
            self.de.set_high();
        } else {
            self.de.set_low();
        }
    }
}

/// The SCADA link: USART1 (PA9/PA10), DE on PA8.
pub type ScadaUart = Rs485<pac::USART1>;
/// The VFD link: USART6 (PC6/PC7), DE on PB0.
pub type VfdUart = Rs485<pac::USART6>;

/// The NUCLEO-F446RE as the loop's [`Io`] and [`Board`].
pub struct NucleoBoard {
    /// Modbus RTU master port to the VFD (USART6), frames ended by [`RTU_IDLE_MS`] of silence.
    vfd: RtuPort<VfdUart>,
    /// ADC1, one blocking conversion per request (see [`SAMPLE_TIME`]).
    adc: Adc<pac::ADC1>,
    /// Pressure transmitter shunt, A0.
    pressure_pin: PA0<Analog>,
    /// Flow transmitter shunt, A1.
    flow_pin: PA1<Analog>,
    /// DAC channel 1 (PA4), output buffer off: 0-3.3 V torque reference before the ×3.03
    /// amplifier.
    dac: C1,
    /// Independent watchdog, fed after every tick.
    watchdog: IndependentWatchdog,
    /// User LED LD2.
    led: PA5<Output>,
    /// Ticks since the LED last toggled (count, 0..[`LED_TOGGLE_TICKS`]).
    led_ticks: u32,
}

impl Io for NucleoBoard {
    /// ADC code of the pressure shunt (0..=4095; 4 mA ≈ 745, 20 mA ≈ 3723), one blocking
    /// conversion ([`SAMPLE_TIME`]).
    fn pressure_code(&mut self) -> u16 {
        self.adc.convert(&self.pressure_pin, SAMPLE_TIME)
    }

    /// ADC code of the flow shunt (0..=4095), one blocking conversion ([`SAMPLE_TIME`]).
    fn flow_code(&mut self) -> u16 {
        self.adc.convert(&self.flow_pin, SAMPLE_TIME)
    }

    /// Torque reference `pct` % (0..=100) as a DAC code, rounded: 0 % → 0 V, 100 % → 3.3 V
    /// at PA4, ×3.03 → 0-10 V at the VFD. Out-of-range values are clamped, NaN gives 0.
    fn set_torque_ref(&mut self, pct: f32) {
        let code = (pct.clamp(0.0, 100.0) / 100.0 * DAC_FULL_SCALE + 0.5) as u16;
        self.dac.set_value(code);
    }

    /// Starts sending `frame` to the VFD (the bytes go out as [`Board::poll`] runs).
    fn vfd_send(&mut self, frame: &[u8]) {
        self.vfd.send(frame);
    }

    /// A complete frame from the VFD, if the line has been silent for [`RTU_IDLE_MS`].
    fn vfd_receive(&mut self, now_ms: u32, frame: &mut Frame) -> bool {
        self.vfd.receive(now_ms, frame)
    }
}

impl Board for NucleoBoard {
    /// SysTick interrupts counted (none is lost on silicon: nothing masks them for 1 ms).
    fn now_ms(&mut self) -> u32 {
        crate::now_ms()
    }

    /// Moves the VFD port's bytes.
    fn poll(&mut self, now_ms: u32) {
        self.vfd.poll(now_ms);
    }

    /// Feeds the watchdog, blinks LD2, logs the once-a-second line over RTT; always `true`.
    fn after_tick(&mut self, log: Option<&LogLine>) -> bool {
        self.watchdog.feed();
        self.led_ticks += 1;
        if self.led_ticks >= LED_TOGGLE_TICKS {
            self.led_ticks = 0;
            self.led.toggle();
        }
        if let Some(log) = log {
            let v = &log.values;
            defmt::info!(
                "t_ms={=u32} mode={=u8} narmax={=u8} u_pct={=f32} p_mca={=f32} q_lps={=f32} wb_rpm={=f32} wb_p_mca={=f32} wb_q_lps={=f32} nx_p_mca={=f32} nx_q_lps={=f32} res_wb_p={=f32} res_wb_q={=f32} res_nx_p={=f32} res_nx_q={=f32} vfd_rpm={=f32} vfd_torque_pct={=f32} status={=u16:#x} vfd_rx_errors={=u32}",
                log.t_ms,
                log.mode as u8,
                log.arithmetic as u8,
                v.torque_pct,
                v.pressure_mca,
                v.flow_lps,
                v.whitebox_speed_rpm,
                v.whitebox_pressure_mca,
                v.whitebox_flow_lps,
                v.narmax_pressure_mca,
                v.narmax_flow_lps,
                v.whitebox_pressure_residual_mca,
                v.whitebox_flow_residual_lps,
                v.narmax_pressure_residual_mca,
                v.narmax_flow_residual_lps,
                v.vfd_speed_rpm,
                v.vfd_torque_pct,
                v.status.bits(),
                self.vfd.uart().rx_errors()
            );
        }
        true
    }

    /// Nothing: the loop must poll the USARTs at least once per character time (521 µs), so
    /// it never sleeps (no WFI).
    fn idle(&mut self) {}
}

/// Sets up the board and runs the loop forever.
///
/// Order: clocks, SysTick, GPIO, ADC, DAC (at 0 %), both RS-485 ports, the loop (models
/// checked and quantised), and only then the watchdog, so that a slow start-up cannot reset
/// the board in a loop.
pub fn run() -> ! {
    let dp = pac::Peripherals::take().expect("device peripherals taken once");
    let cp = cortex_m::Peripherals::take().expect("core peripherals taken once");

    let mut rcc = dp.RCC.freeze(
        RccConfig::hse(8.MHz())
            .bypass_hse_oscillator()
            .sysclk(180.MHz()),
    );
    crate::start_systick(cp.SYST, rcc.clocks.sysclk().raw());

    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);

    let adc = Adc::new(
        dp.ADC1,
        true,
        AdcConfig::default().clock(Clock::Pclk2_div_4),
        &mut rcc,
    );

    let mut dac = dp.DAC.constrain(gpioa.pa4.into_analog(), &mut rcc);
    // Output buffer off (BOFF1): the buffered output only spans 0.2 V..VDDA - 0.2 V, so 0 %
    // would reach the VFD as ≈ 0.6 V (≈ 6 % torque) and 100 % as ≈ 9.4 V; unbuffered it spans
    // 0..VDDA, which the ×3.03 amplifier's high-impedance input can take.
    // SAFETY: one read-modify-write of DAC_CR during single-threaded start-up, before the
    // channel is enabled; no interrupt touches the DAC, and the HAL's `C1` writes the same
    // register the same way (through the same pointer).
    unsafe { (*pac::DAC::ptr()).cr().modify(|_, w| w.boff1().set_bit()) };
    dac.set_value(0);
    dac.enable();

    let scada_serial: Serial<pac::USART1> = Serial::new(
        dp.USART1,
        (
            gpioa.pa9.into_alternate::<7>(),
            gpioa.pa10.into_alternate::<7>().internal_pull_up(true),
        ),
        serial::Config::default().baudrate(BAUD_BPS.bps()),
        &mut rcc,
    )
    .unwrap_or_else(|_| panic!("USART1 configuration"));
    let scada_uart: ScadaUart = Rs485::new(scada_serial, gpioa.pa8.into_push_pull_output().erase());
    let mut scada_port = RtuPort::new(scada_uart, RTU_IDLE_MS);

    let vfd_serial: Serial<pac::USART6> = dp
        .USART6
        .serial(
            (
                gpioc.pc6.into_alternate::<8>(),
                gpioc.pc7.into_alternate::<8>().internal_pull_up(true),
            ),
            BAUD_BPS.bps(),
            &mut rcc,
        )
        .unwrap_or_else(|_| panic!("USART6 configuration"));
    let vfd_uart: VfdUart = Rs485::new(vfd_serial, gpiob.pb0.into_push_pull_output().erase());

    let mut app: Loop = match crate::build_loop(AppConfig::bench()) {
        Ok(app) => app,
        Err(e) => {
            defmt::error!("cannot build the loop: {}", defmt::Display2Format(&e));
            panic!("cannot build the loop");
        }
    };

    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    // Freeze the watchdog while a debugger halts the core (probe-rs breakpoints).
    watchdog.stop_on_debug(&dp.DBGMCU, true);
    watchdog.start(WATCHDOG_MS.millis());

    let mut board = NucleoBoard {
        vfd: RtuPort::new(vfd_uart, RTU_IDLE_MS),
        adc,
        pressure_pin: gpioa.pa0.into_analog(),
        flow_pin: gpioa.pa1.into_analog(),
        dac,
        watchdog,
        led: gpioa.pa5.into_push_pull_output(),
        led_ticks: 0,
    };

    defmt::info!(
        "NUCLEO-F446RE bench controller: sysclk {=u32} Hz, RTU {=u32} baud",
        rcc.clocks.sysclk().raw(),
        BAUD_BPS
    );
    crate::serve(&mut app, &mut scada_port, &mut board);
    // `serve` never returns on this board; if it did, the unfed watchdog resets the MCU.
    loop {
        cortex_m::asm::nop();
    }
}
