//! QEMU `netduinoplus2` (STM32F405) glue: the virtual bench on-chip.
//!
//! - The transmitters, the torque output and the drive are
//!   [`controller::bench::VirtualIo`]: the white-box bench a few percent off the model,
//!   transmitter lag, noise and 12-bit ADC codes fed to the same scaling and fault checks as
//!   on a board. QEMU models no usable ADC (the HAL's `Adc::new` faults) and no DAC.
//! - SCADA: Modbus RTU slave on USART1 (QEMU's first `-serial`).
//! - VFD: by default the virtual drive answers in-process; with the argument `vfd=uart` the
//!   master talks on USART2 (the second `-serial`), e.g. to `pumpbench vfd-sim`.
//! - Time: TIM2 runs free at 1 MHz and [`Clock`] turns it into milliseconds; the loop ticks
//!   once per elapsed millisecond of it. SysTick (1 ms; QEMU clocks it at 168 MHz whatever the
//!   RCC says; the RCC is left on HSI, as a PLL-ready wait would hang) only wakes the core: in
//!   real time QEMU merges SysTick expiries that fall while its vCPU thread waits for the host
//!   into one interrupt, so counting them lost 1-6 % of wall time on a busy host (measured
//!   with SCADA traffic or a parallel build). TIM2's counter is computed from QEMU's virtual
//!   clock, so it loses nothing. Between ticks the core sleeps (`wfi`), so
//!   `-icount shift=0,sleep=off` runs the loop faster than real time and deterministically.
//! - Serial: both USARTs receive by interrupt into a queue ([`RX_QUEUE_BYTES`] each, bytes
//!   beyond it dropped and counted). QEMU hands the guest the next byte only once it has read
//!   the last one, so a byte that waits for the next 1 ms tick holds the whole line back
//!   (≈ 1 byte per ms); the interrupt wakes the core for each byte instead. SCADA requests end
//!   by their length and CRC ([`controller::scada::request_complete`]) or after
//!   [`QEMU_IDLE_MS`] of silence (what QEMU's serial lines cannot mark).
//! - Logs: one text line a second over semihosting (no float formatting: see
//!   [`controller::app::write_fixed`]).
//!
//! Arguments, read with semihosting `SYS_GET_CMDLINE` (QEMU: `-semihosting-config
//! enable=on,target=native,arg=firmware,arg=mode=2,…`), each `key=value`:
//! `mode=0|1|2` (start-up mode, default 0 stop), `setpoint=0..10000` (0.01 %), `seed=N`
//! (profile seed, 0..=4294967295, default 1), `narmax=f32|q15` (NARMAX arithmetic), `run_ms=N` (exit 0 after N ms; default: run until QEMU is
//! stopped), `vfd=uart`. A bad argument is reported and the firmware exits with status 1. (The
//! loop's and the models' cost is measured by `mcu-bench`: `cargo xtask bench`.)

use crate::{serve, start_systick, Board};
use controller::app::{AppConfig, Io, LogLine};
use controller::bench::{VirtualBench, VirtualBenchConfig, VirtualIo};
use controller::rtu::{Frame, RtuPort, Uart};
use controller::scada::{Arithmetic, Mode};
use core::cell::RefCell;
use core::fmt::Write as _;
use cortex_m::interrupt::{free, Mutex};
use cortex_m_semihosting::{debug, hio};
use panic_semihosting as _;
use stm32f4xx_hal::pac::{self, interrupt};

/// SysTick under QEMU, Hz.
const QEMU_SYSTICK_HZ: u32 = 168_000_000;
/// HSI: the USART clock with the RCC untouched, Hz.
const HSI_HZ: u32 = 16_000_000;
/// Line speed, baud (QEMU's serial back-ends ignore it; a board uses it).
const BAUD: u32 = 19_200;
/// Silence that ends an RTU frame under QEMU, ms: QEMU hands over one byte each time the guest
/// reads the last one, with no line timing, and a busy host can delay a byte by a few
/// milliseconds; 10 ms keeps frames whole and is far below any master's timeout.
const QEMU_IDLE_MS: u32 = 10;

/// Bytes a USART's receive queue holds: more than four longest RTU frames.
pub const RX_QUEUE_BYTES: usize = 1024;

/// Bytes received by a USART's interrupt, not yet taken by the loop.
struct RxQueue {
    bytes: heapless::Deque<u8, RX_QUEUE_BYTES>,
    /// Bytes dropped because the queue was full (wraps).
    dropped: u32,
}

impl RxQueue {
    const fn new() -> Self {
        Self {
            bytes: heapless::Deque::new(),
            dropped: 0,
        }
    }
}

/// USART1's (SCADA) and USART2's (VFD) receive queues, filled by their interrupts.
static RX: [Mutex<RefCell<RxQueue>>; 2] = [
    Mutex::new(RefCell::new(RxQueue::new())),
    Mutex::new(RefCell::new(RxQueue::new())),
];

/// Moves every received byte of `regs` into `queue` (the interrupt handlers' body).
fn receive_into(regs: &pac::usart1::RegisterBlock, queue: &Mutex<RefCell<RxQueue>>) {
    free(|cs| {
        let mut q = queue.borrow(cs).borrow_mut();
        while regs.sr().read().rxne().bit_is_set() {
            let byte = regs.dr().read().dr().bits() as u8;
            if q.bytes.push_back(byte).is_err() {
                q.dropped = q.dropped.wrapping_add(1);
            }
        }
    });
}

#[interrupt]
fn USART1() {
    // SAFETY: a shared reference to the register block; the loop only writes DR/CR1 and
    // reads SR, and reading DR here is what the receive interrupt is for.
    receive_into(unsafe { &*pac::USART1::ptr() }, &RX[0]);
}

#[interrupt]
fn USART2() {
    // SAFETY: as for USART1.
    receive_into(unsafe { &*pac::USART2::ptr() }, &RX[1]);
}

/// A USART under QEMU (its STM32F2xx USART model: a byte in DR, RXNE, TXE/TC always ready),
/// receiving by interrupt into its [`RxQueue`], transmitting by polling.
struct Usart {
    regs: &'static pac::usart1::RegisterBlock,
    rx: &'static Mutex<RefCell<RxQueue>>,
}

impl Usart {
    /// Sets the USART up (19 200 baud from `pclk_hz`, receive interrupt on) and unmasks its
    /// interrupt `irq`.
    fn new(
        regs: &'static pac::usart1::RegisterBlock,
        rx: &'static Mutex<RefCell<RxQueue>>,
        irq: pac::Interrupt,
        pclk_hz: u32,
    ) -> Self {
        let brr = (pclk_hz + BAUD / 2) / BAUD;
        // SAFETY: BRR takes any 16-bit divider; this is the HAL's own computation.
        regs.brr().write(|w| unsafe { w.bits(brr as u16) });
        regs.cr1().write(|w| {
            w.ue()
                .set_bit()
                .te()
                .set_bit()
                .re()
                .set_bit()
                .rxneie()
                .set_bit()
        });
        // SAFETY: the handler only touches its queue through a critical section.
        unsafe { cortex_m::peripheral::NVIC::unmask(irq) };
        Self { regs, rx }
    }

    /// Bytes dropped because the receive queue was full.
    fn dropped(&self) -> u32 {
        rx_dropped(self.rx)
    }
}

/// Bytes `queue` dropped because it was full.
fn rx_dropped(queue: &Mutex<RefCell<RxQueue>>) -> u32 {
    free(|cs| queue.borrow(cs).borrow().dropped)
}

impl Uart for Usart {
    fn try_read(&mut self) -> Option<u8> {
        free(|cs| self.rx.borrow(cs).borrow_mut().bytes.pop_front())
    }
    fn try_write(&mut self, byte: u8) -> bool {
        if self.regs.sr().read().txe().bit_is_clear() {
            return false;
        }
        self.regs.dr().write(|w| w.dr().set(u16::from(byte)));
        true
    }
    fn tx_complete(&mut self) -> bool {
        self.regs.sr().read().tc().bit_is_set()
    }
    /// QEMU's serial back-ends are full duplex: no echo, so back-to-back requests are kept.
    fn echoes(&self) -> bool {
        false
    }
}

/// Milliseconds from TIM2 running free at 1 MHz (32 bits: wraps every 71 min, taken care of
/// by counting differences). QEMU's STM32F2xx timer model counts its 1 GHz virtual clock
/// divided by PSC + 1 (real time without `-icount`, one count per instruction with
/// `-icount shift=0`), whatever the RCC says.
pub struct Clock {
    tim: pac::TIM2,
    last: u32,
    ms: u32,
    rest_us: u32,
}

impl Clock {
    /// QEMU's timer input clock, Hz.
    const TIMER_HZ: u32 = 1_000_000_000;

    /// Starts TIM2 from 0 at 1 MHz, no interrupts.
    pub fn start(tim: pac::TIM2, rcc: &pac::RCC) -> Self {
        rcc.apb1enr().modify(|_, w| w.tim2en().set_bit());
        tim.psc()
            .write(|w| w.psc().set((Self::TIMER_HZ / 1_000_000 - 1) as u16));
        tim.arr().write(|w| w.arr().set(u32::MAX));
        tim.egr().write(|w| w.ug().set_bit());
        tim.cr1().modify(|_, w| w.cen().set_bit());
        let last = tim.cnt().read().bits();
        Self {
            tim,
            last,
            ms: 0,
            rest_us: 0,
        }
    }

    /// Milliseconds since [`Self::start`] (wrapping).
    pub fn now_ms(&mut self) -> u32 {
        let cnt = self.tim.cnt().read().bits();
        let us = cnt.wrapping_sub(self.last);
        self.last = cnt;
        let rest = self.rest_us + us % 1000;
        self.ms = self
            .ms
            .wrapping_add(us / 1000)
            .wrapping_add(u32::from(rest >= 1000));
        self.rest_us = rest % 1000;
        self.ms
    }
}

/// Start-up options from the semihosting command line.
struct Args {
    mode: Mode,
    setpoint: u16,
    /// Profile and bench seed: 32 bits, so that no 64-bit division (≈ 1.1 KB) is linked
    /// for printing it.
    seed: u32,
    run_ms: Option<u32>,
    vfd_uart: bool,
    arithmetic: Arithmetic,
}

/// A decimal `u32`, digits only.
fn number(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u32, |n, &d| {
        d.is_ascii_digit()
            .then(|| n.checked_mul(10)?.checked_add(u32::from(d - b'0')))
            .flatten()
    })
}

/// The arguments, as bytes: no UTF-8 validation and no `str::parse` linked (≈ 0.6 KB of
/// flash); a bad word is returned as given.
fn parse_args(line: &[u8]) -> Result<Args, &[u8]> {
    let mut a = Args {
        mode: Mode::Stop,
        setpoint: 0,
        seed: 1,
        run_ms: None,
        vfd_uart: false,
        arithmetic: Arithmetic::F32,
    };
    // The first word is the program name; words are separated by ASCII spaces.
    for word in line.split(|&b| b == b' ').filter(|w| !w.is_empty()).skip(1) {
        let (key, value) = match word.iter().position(|&b| b == b'=') {
            Some(k) => (&word[..k], &word[k + 1..]),
            None => (word, &word[word.len()..]),
        };
        let n = || number(value).ok_or(word);
        match key {
            b"mode" => {
                a.mode = match value {
                    b"0" => Mode::Stop,
                    b"1" => Mode::Manual,
                    b"2" => Mode::Profile,
                    _ => return Err(word),
                }
            }
            b"setpoint" => a.setpoint = u16::try_from(n()?).map_err(|_| word)?,
            b"seed" => a.seed = n()?,
            b"run_ms" => a.run_ms = Some(n()?),
            b"vfd" if value == b"uart" => a.vfd_uart = true,
            b"narmax" => {
                a.arithmetic = match value {
                    b"f32" => Arithmetic::F32,
                    b"q15" => Arithmetic::Fixed,
                    _ => return Err(word),
                }
            }
            _ => return Err(word),
        }
    }
    Ok(a)
}

/// The semihosting command line into `buf`; empty if the host gives none.
fn command_line(buf: &mut [u8]) -> &[u8] {
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: SYS_GET_CMDLINE writes at most `block[1]` bytes to `block[0]`, a live buffer,
    // and the length it wrote back to `block[1]`.
    let failed = unsafe {
        cortex_m_semihosting::syscall1(
            cortex_m_semihosting::nr::GET_CMDLINE,
            core::ptr::addr_of_mut!(block) as usize,
        )
    } != 0;
    let n = if failed { 0 } else { block[1].min(buf.len()) };
    // The line is NUL-terminated; QEMU 7.2 reports the buffer's length, not the line's.
    let n = buf[..n].iter().position(|&b| b == 0).unwrap_or(n);
    &buf[..n]
}

/// The virtual bench as the board.
struct QemuBoard {
    clock: Clock,
    virt: VirtualIo,
    vfd_port: Option<RtuPort<Usart>>,
    out: hio::HostStream,
    run_ms: Option<u32>,
    failed: bool,
    /// SCADA bytes dropped, as last logged.
    scada_dropped: u32,
}

impl Io for QemuBoard {
    fn pressure_code(&mut self) -> u16 {
        self.virt.pressure_code()
    }
    fn flow_code(&mut self) -> u16 {
        self.virt.flow_code()
    }
    fn set_torque_ref(&mut self, pct: f32) {
        self.virt.set_torque_ref(pct);
    }
    fn vfd_send(&mut self, frame: &[u8]) {
        match &mut self.vfd_port {
            Some(port) => {
                port.send(frame);
            }
            None => self.virt.vfd_send(frame),
        }
    }
    fn virtual_bench(&mut self, valve_permille: u16, faults: u16) {
        self.virt.apply(valve_permille, faults);
    }
    fn vfd_receive(&mut self, now_ms: u32, frame: &mut Frame) -> bool {
        match &mut self.vfd_port {
            Some(port) => port.receive(now_ms, frame),
            None => self.virt.vfd_receive(now_ms, frame),
        }
    }
}

impl Board for QemuBoard {
    fn now_ms(&mut self) -> u32 {
        self.clock.now_ms()
    }

    fn poll(&mut self, now_ms: u32) {
        if let Some(port) = &mut self.vfd_port {
            port.poll(now_ms);
        }
    }

    fn after_tick(&mut self, log: Option<&LogLine>) -> bool {
        if self.virt.step_1ms().is_err() {
            let _ = writeln!(self.out, "error: the virtual bench diverged");
            self.failed = true;
            return false;
        }
        if let Some(line) = log {
            let _ = line.write_text(&mut self.out);
            let _ = writeln!(self.out);
            let dropped = rx_dropped(&RX[0]);
            if dropped != self.scada_dropped {
                self.scada_dropped = dropped;
                let _ = writeln!(
                    self.out,
                    "SCADA: {dropped} received bytes dropped so far (queue full)"
                );
            }
        }
        match self.run_ms {
            Some(end) => self.clock.now_ms() < end,
            None => true,
        }
    }

    fn idle(&mut self) {
        cortex_m::asm::wfi();
    }

    /// QEMU's serial lines carry no timing: requests end by their content too.
    fn frames_by_content(&self) -> bool {
        true
    }
}

/// Sets up the virtual bench and runs the loop; exits QEMU at the end of `run_ms`.
pub fn run() -> ! {
    let code = match hio::hstdout() {
        Ok(mut out) => match start(&mut out) {
            Ok(()) => debug::EXIT_SUCCESS,
            Err(()) => debug::EXIT_FAILURE,
        },
        Err(()) => debug::EXIT_FAILURE,
    };
    debug::exit(code);
    #[allow(clippy::empty_loop)]
    loop {}
}

fn start(out: &mut hio::HostStream) -> Result<(), ()> {
    let mut buf = [0u8; 256];
    let args = match parse_args(command_line(&mut buf)) {
        Ok(a) => a,
        Err(word) => {
            let _ = out.write_all(b"error: bad argument '");
            let _ = out.write_all(word);
            let _ = out.write_all(b"' (see firmware/src/qemu.rs)\n");
            return Err(());
        }
    };
    let config = AppConfig {
        initial_mode: args.mode,
        initial_setpoint: args.setpoint,
        profile_seed: u64::from(args.seed),
        initial_arithmetic: args.arithmetic,
        virtual_bench: true,
        ..AppConfig::bench()
    };
    let fail = |out: &mut hio::HostStream, e: &dyn core::fmt::Display| {
        let _ = writeln!(out, "error: {e}");
    };
    let mut app = match crate::build_loop(config) {
        Ok(app) => app,
        Err(e) => {
            fail(out, &e);
            return Err(());
        }
    };
    let bench = match VirtualBench::new(VirtualBenchConfig::default_offsets(u64::from(args.seed))) {
        Ok(b) => b,
        Err(e) => {
            fail(out, &e);
            return Err(());
        }
    };
    let virt = VirtualIo::new(bench, config.vfd).ok_or(())?;
    let cp = cortex_m::Peripherals::take().ok_or(())?;
    let dp = pac::Peripherals::take().ok_or(())?;
    dp.RCC.apb2enr().modify(|_, w| w.usart1en().set_bit());
    dp.RCC.apb1enr().modify(|_, w| w.usart2en().set_bit());
    // SAFETY (both): the register blocks live at fixed addresses for the whole program, and
    // each is used by exactly one `Usart` from here on.
    let usart1: &'static pac::usart1::RegisterBlock = unsafe { &*pac::USART1::ptr() };
    let usart2: &'static pac::usart1::RegisterBlock = unsafe { &*pac::USART2::ptr() };
    let mut scada = RtuPort::new(
        Usart::new(usart1, &RX[0], pac::Interrupt::USART1, HSI_HZ),
        QEMU_IDLE_MS,
    );
    let vfd_port = args.vfd_uart.then(|| {
        RtuPort::new(
            Usart::new(usart2, &RX[1], pac::Interrupt::USART2, HSI_HZ),
            QEMU_IDLE_MS,
        )
    });
    let _ = writeln!(
        out,
        "firmware: virtual bench, SCADA unit 1 on USART1, VFD {}, mode={} setpoint={} seed={} narmax={}{}",
        if args.vfd_uart {
            "on USART2"
        } else {
            "virtual"
        },
        args.mode as u8,
        args.setpoint,
        args.seed,
        args.arithmetic.name(),
        if args.run_ms.is_some() { "" } else { ", runs until stopped" }
    );
    let clock = Clock::start(dp.TIM2, &dp.RCC);
    let mut board = QemuBoard {
        clock,
        virt,
        vfd_port,
        out: *out,
        run_ms: args.run_ms,
        failed: false,
        scada_dropped: 0,
    };
    start_systick(cp.SYST, QEMU_SYSTICK_HZ);
    serve(&mut app, &mut scada, &mut board);
    let dropped = scada.uart().dropped();
    if dropped > 0 {
        let _ = writeln!(out, "SCADA: {dropped} received bytes dropped (queue full)");
    }
    let _ = writeln!(out, "done");
    if board.failed {
        Err(())
    } else {
        Ok(())
    }
}
