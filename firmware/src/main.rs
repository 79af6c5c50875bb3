//! First cut of the bench controller firmware: runs the paper's white-box bench in f32 and
//! the two NARMAX models (pressure every 50 ms, flow every 100 ms; f32 and fixed point) on a
//! built-in excitation (the paper's pulses, 5..85 %), prints a sample every 500 ms over
//! semihosting, the SysTick cost of each model step, and exits 0. Under QEMU (`cargo qemu`)
//! it needs no board.
//!
//! Each line carries the values in readable units and, after `bits=`, their raw f32 bits:
//! `cargo xtask test` replays the same excitation with model-core on the host and requires
//! the same bits. The NARMAX models are `src/models/*.rs`, made by `pumpbench export`.
#![no_std]
#![no_main]

use core::fmt::Write as _;
use cortex_m::peripheral::{syst::SystClkSource, Peripherals};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hio};
use model_core::excitation::{PulseTrain, SteppedPulses};
use model_core::narmax::fixed::NarmaxQ;
use model_core::{Scheme, WhiteBox};
use panic_semihosting as _;

/// The NARMAX models compiled in (`pumpbench export`).
mod models {
    pub mod flow;
    pub mod pressure;
}

/// Pressure model period, ms.
const PRESSURE_MS: u32 = (models::pressure::SAMPLE_PERIOD_S * 1000.0 + 0.5) as u32;
/// Flow model period, ms.
const FLOW_MS: u32 = (models::flow::SAMPLE_PERIOD_S * 1000.0 + 0.5) as u32;

/// Seed of the built-in excitation.
const SEED: u64 = 1;
/// Simulated time, ms.
const DURATION_MS: u32 = 20_000;
/// Integration step, ms.
const STEP_MS: u32 = 1;
/// Print a sample every this many ms.
const PRINT_EVERY_MS: u32 = 500;
/// SysTick's 24-bit counter mask.
const SYST_MASK: u32 = 0x00FF_FFFF;

/// Writes `x` with `decimals` decimals, rounded, without core's float formatting (≈ 7 KB).
fn fixed(out: &mut impl core::fmt::Write, x: f32, decimals: u32) -> core::fmt::Result {
    let scale = 10i64.pow(decimals);
    let scaled = (x as f64 * scale as f64 + if x < 0.0 { -0.5 } else { 0.5 }) as i64;
    let sign = if scaled < 0 { "-" } else { "" };
    let a = scaled.unsigned_abs();
    let s = scale as u64;
    write!(out, "{sign}{}.{:0w$}", a / s, a % s, w = decimals as usize)
}

/// Elapsed SysTick ticks since `start` (the counter counts down, 24 bits).
fn ticks_since(start: u32) -> u64 {
    u64::from(start.wrapping_sub(cortex_m::peripheral::SYST::get_current()) & SYST_MASK)
}

/// Sum of SysTick ticks and calls, for one model step.
#[derive(Default)]
struct Cost {
    ticks: u64,
    calls: u64,
}

impl Cost {
    /// Runs `f`, adding its SysTick ticks and one call.
    fn time<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let t0 = cortex_m::peripheral::SYST::get_current();
        let r = f();
        self.ticks += ticks_since(t0);
        self.calls += 1;
        r
    }

    fn per_call(&self) -> u64 {
        self.ticks / self.calls.max(1)
    }
}

fn run(out: &mut impl core::fmt::Write) -> Result<u32, core::fmt::Error> {
    let mut cp = Peripherals::take().ok_or(core::fmt::Error)?;
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(SYST_MASK);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();

    let bench = WhiteBox::<f32>::paper();
    let bad = |_| core::fmt::Error;
    let p_f32 = models::pressure::model().map_err(bad)?;
    let f_f32 = models::flow::model().map_err(bad)?;
    let p_q15 = NarmaxQ::quantize(&p_f32).map_err(bad)?;
    let f_q15 = NarmaxQ::quantize(&f_f32).map_err(bad)?;
    let (mut p, mut pq, mut f, mut fq) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let (mut c_p, mut c_pq, mut c_f, mut c_fq) = (
        Cost::default(),
        Cost::default(),
        Cost::default(),
        Cost::default(),
    );
    writeln!(
        out,
        "firmware: white-box bench f32 RK4 step_ms={STEP_MS} seed={SEED} duration_ms={DURATION_MS}"
    )?;
    let mut schedule = SteppedPulses::new(PulseTrain::paper(SEED), STEP_MS).peekable();
    let u0 = schedule.peek().map_or(0.0, |&(_, u)| u as f32);
    // The bench starts at the steady state of the first torque; the NARMAX histories start
    // at that state's pressure and flow (as if seeded from measurements).
    let st = &mut bench.steady_state(u0).map_err(|_| core::fmt::Error)?;
    let s0 = bench.signals(st);
    let p_st = &mut p_f32.state_at(u0, s0.pressure_mca);
    let pq_st = &mut p_q15.state_at(u0, s0.pressure_mca);
    let f_st = &mut f_f32.state_at(u0, s0.flow_lps);
    let fq_st = &mut f_q15.state_at(u0, s0.flow_lps);
    let mut ticks: u64 = 0;
    let mut steps = 0u32;
    for (t_ms, torque) in schedule {
        if t_ms > DURATION_MS {
            break;
        }
        let torque_pct = torque as f32;
        if t_ms % PRESSURE_MS == 0 {
            p = c_p.time(|| p_f32.simulate_step(p_st, torque_pct).y);
            pq = c_pq.time(|| p_q15.simulate_step(pq_st, torque_pct).y);
        }
        if t_ms % FLOW_MS == 0 {
            f = c_f.time(|| f_f32.simulate_step(f_st, torque_pct).y);
            fq = c_fq.time(|| f_q15.simulate_step(fq_st, torque_pct).y);
        }
        if t_ms % PRINT_EVERY_MS == 0 {
            let s = bench.signals(st);
            write!(out, "sample t_ms={t_ms} u_pct=")?;
            fixed(out, torque_pct, 2)?;
            write!(out, " speed_rpm=")?;
            fixed(out, s.speed_rpm, 1)?;
            write!(out, " flow_lps=")?;
            fixed(out, s.flow_lps, 2)?;
            write!(out, " pressure_mca=")?;
            fixed(out, s.pressure_mca, 3)?;
            writeln!(
                out,
                " bits={:08x},{:08x},{:08x}",
                s.speed_rpm.to_bits(),
                s.flow_lps.to_bits(),
                s.pressure_mca.to_bits()
            )?;
            write!(out, "narmax t_ms={t_ms} pressure_mca=")?;
            fixed(out, p, 3)?;
            write!(out, " pressure_q15_mca=")?;
            fixed(out, pq, 3)?;
            write!(out, " flow_lps=")?;
            fixed(out, f, 2)?;
            write!(out, " flow_q15_lps=")?;
            fixed(out, fq, 2)?;
            writeln!(
                out,
                " bits={:08x},{:08x},{:08x},{:08x}",
                p.to_bits(),
                pq.to_bits(),
                f.to_bits(),
                fq.to_bits()
            )?;
        }
        let start = cortex_m::peripheral::SYST::get_current();
        bench
            .step(st, torque_pct, STEP_MS as f32 * 1e-3, Scheme::Rk4)
            .map_err(|_| core::fmt::Error)?;
        ticks += ticks_since(start);
        steps += 1;
    }
    writeln!(
        out,
        "timing rk4_steps={steps} systick_ticks_per_step={}",
        ticks / u64::from(steps.max(1))
    )?;
    writeln!(
        out,
        "timing narmax_steps={} systick_ticks_per_step pressure_f32={} pressure_q15={} flow_f32={} flow_q15={}",
        c_p.calls,
        c_p.per_call(),
        c_pq.per_call(),
        c_f.per_call(),
        c_fq.per_call()
    )?;
    Ok(steps)
}

#[entry]
fn main() -> ! {
    let code = match hio::hstdout() {
        Ok(mut out) => match run(&mut out) {
            Ok(_) => {
                let _ = writeln!(out, "done");
                debug::EXIT_SUCCESS
            }
            Err(_) => debug::EXIT_FAILURE,
        },
        Err(_) => debug::EXIT_FAILURE,
    };
    debug::exit(code);
    #[allow(clippy::empty_loop)]
    loop {}
}
