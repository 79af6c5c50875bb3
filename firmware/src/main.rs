//! First cut of the bench controller firmware: runs the paper's white-box bench in f32 on a
//! built-in excitation (the paper's pulses, 5..85 %), prints a sample every 500 ms over
//! semihosting, and exits 0. Under QEMU (`cargo qemu`) it needs no board.
//!
//! Each sample line carries the values in readable units and, after `bits=`, the raw f32 bits
//! of speed, flow and pressure: `cargo xtask test` replays the same excitation with
//! model-core on the host and requires the same bits.
#![no_std]
#![no_main]

use core::fmt::Write as _;
use cortex_m::peripheral::{syst::SystClkSource, Peripherals};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hio};
use model_core::excitation::{PulseTrain, SteppedPulses};
use model_core::{Scheme, WhiteBox};
use panic_semihosting as _;

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

fn run(out: &mut impl core::fmt::Write) -> Result<u32, core::fmt::Error> {
    let mut cp = Peripherals::take().ok_or(core::fmt::Error)?;
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(SYST_MASK);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();

    let bench = WhiteBox::<f32>::paper();
    writeln!(
        out,
        "firmware: white-box bench f32 RK4 step_ms={STEP_MS} seed={SEED} duration_ms={DURATION_MS}"
    )?;
    let mut state = None;
    let mut ticks: u64 = 0;
    let mut steps = 0u32;
    for (t_ms, torque) in SteppedPulses::new(PulseTrain::paper(SEED), STEP_MS) {
        if t_ms > DURATION_MS {
            break;
        }
        let torque_pct = torque as f32;
        let st = match state.as_mut() {
            Some(s) => s,
            None => state.insert(
                bench
                    .steady_state(torque_pct)
                    .map_err(|_| core::fmt::Error)?,
            ),
        };
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
        }
        let start = cortex_m::peripheral::SYST::get_current();
        bench
            .step(st, torque_pct, STEP_MS as f32 * 1e-3, Scheme::Rk4)
            .map_err(|_| core::fmt::Error)?;
        let end = cortex_m::peripheral::SYST::get_current();
        ticks += u64::from(start.wrapping_sub(end) & SYST_MASK);
        steps += 1;
    }
    writeln!(
        out,
        "timing rk4_steps={steps} systick_ticks_per_step={}",
        ticks / u64::from(steps.max(1))
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
