//! Benches of the model kernels on the MCU (Cortex-M4F, QEMU `netduinoplus2`), shared by the
//! bench image (`src/main.rs`) and the size probes (`src/bin/part_*.rs`):
//!
//! - [`Cost`]: SysTick ticks around each call (the 24-bit counter counting down at the core
//!   clock, no interrupt), summed, with the largest call. Under `qemu-system-arm -icount
//!   shift=0` one instruction is 1 ns and SysTick counts at 168 MHz, so instructions =
//!   ticks / 0.168 (`cargo xtask bench` does that sum and takes off the cost of [`empty`]).
//! - [`models`]: the firmware's NARMAX models, the very files it compiles in.
//! - [`plain`]: the plain generic f32 NARMAX pass with `libm::tanhf`, frozen here as the
//!   baseline that faster kernels are compared with.
//! - [`inputs`]: the paper's pulse excitation and other changing inputs for the kernels.
//! - [`parts`]: what each size probe links of model-core.
#![no_std]

/// The firmware's NARMAX models (the `pump-models` crate).
pub use pump_models as models;
pub mod plain;

use core::hint::black_box;
use cortex_m::peripheral::{syst::SystClkSource, SYST};

/// SysTick's 24-bit counter mask.
pub const SYST_MASK: u32 = 0x00FF_FFFF;

/// Starts SysTick free-running over its full 24 bits at the core clock, interrupt off.
pub fn start_counter(syst: &mut SYST) {
    syst.disable_interrupt();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(SYST_MASK);
    syst.clear_current();
    syst.enable_counter();
}

/// SysTick ticks of the calls timed so far: their sum, their number and the largest.
#[derive(Debug, Default, Clone, Copy)]
pub struct Cost {
    /// Sum of the ticks of every call.
    pub ticks: u64,
    /// Calls timed.
    pub calls: u32,
    /// Ticks of the longest call.
    pub max: u32,
}

impl Cost {
    /// Runs `f` once between two reads of SysTick (which counts down; calls must be shorter
    /// than its 2²⁴-tick period, 0.1 s) and adds its ticks. `f` should take its inputs
    /// through [`black_box`] and hand its result back, which is passed through
    /// [`black_box`] here, so that nothing is computed outside the two reads or optimised
    /// away.
    ///
    /// A tick is 1/0.168 ≈ 5.95 instructions, so one call's count is off by up to a tick; the
    /// mean is not, because each call starts at another phase of the tick: before it, outside
    /// the timed span, a spin of `calls % 125` two-instruction loops (0.168 = 21/125, so 125
    /// calls in a row start at each 1/125 of a tick once).
    #[inline(always)]
    pub fn time<R>(&mut self, f: impl FnOnce() -> R) -> R {
        spin(self.calls % PHASES);
        let t0 = SYST::get_current();
        let r = black_box(f());
        let t1 = SYST::get_current();
        let dt = t0.wrapping_sub(t1) & SYST_MASK;
        self.ticks += u64::from(dt);
        self.calls += 1;
        self.max = self.max.max(dt);
        r
    }
}

/// Phases of a SysTick tick that [`Cost::time`] starts calls at: 0.168 ticks per
/// instruction = 21/125.
const PHASES: u32 = 125;

/// `n` turns of a two-instruction loop (`subs`, `bne`): 2n instructions under QEMU.
#[inline(always)]
#[allow(unsafe_code)] // the timing loop's `asm!`
fn spin(n: u32) {
    if n > 0 {
        // SAFETY: counts a register down to zero; touches no memory and no stack.
        unsafe {
            core::arch::asm!(
                "2:",
                "subs {0}, #1",
                "bne 2b",
                inout(reg) n => _,
                options(nomem, nostack)
            )
        };
    }
}

/// The empty call: what [`Cost::time`] measures around a call that does nothing (an
/// `#[inline(never)]` function returning its argument). Its cost is taken off every kernel.
#[inline(never)]
#[allow(unsafe_code)] // the empty `asm!` barrier
pub fn empty(x: f32) -> f32 {
    // SAFETY: an empty instruction sequence; it only keeps the call from being removed.
    unsafe { core::arch::asm!("", options(nomem, nostack, preserves_flags)) };
    x
}

/// Changing, reproducible inputs for the kernels.
pub mod inputs {
    use model_core::excitation::{PulseTrain, SplitMix64, SteppedPulses};

    /// The paper's pulse excitation (5..85 %, holds 0.5..3 s, seeded) sampled every
    /// `step_ms` ms: the torque reference to hold over each step, %.
    pub fn pulses(seed: u64, step_ms: u32) -> impl Iterator<Item = f32> {
        SteppedPulses::new(PulseTrain::paper(seed), step_ms).map(|(_, u)| u as f32)
    }

    /// Values uniform in `[lo, hi)`, seeded.
    pub fn uniform(seed: u64, lo: f32, hi: f32) -> impl Iterator<Item = f32> {
        let mut rng = SplitMix64::new(seed);
        core::iter::repeat_with(move || rng.uniform(f64::from(lo), f64::from(hi)) as f32)
    }
}

/// A size probe's `main` and panic handler: runs the [`parts`] named, in turn, each only if
/// the ones before passed, and exits 0 if all did (QEMU's exit status), 1 on failure or panic.
/// `probe!()` links the runtime only.
#[macro_export]
macro_rules! probe {
    ($($part:ident),*) => {
        #[cortex_m_rt::entry]
        fn main() -> ! {
            $crate::parts::exit(
                Ok::<(), $crate::parts::Error>(())
                    $(.and_then(|()| $crate::parts::$part()))*
                    .is_ok(),
            )
        }

        #[panic_handler]
        fn panic(_: &core::panic::PanicInfo) -> ! {
            $crate::parts::exit(false)
        }
    };
}

/// What each size probe (`src/bin/part_*.rs`) links: each part uses one piece of model-core
/// the way the controller does, on inputs it cannot see through ([`black_box`]); a probe calls
/// the parts before its own, so that each image holds one piece more than the last.
pub mod parts {
    use crate::models::{flow, pressure};
    use core::hint::black_box;
    use model_core::monitor::{Monitor, MonitorConfig, MonitorInputs};
    use model_core::narmax::Predictor;
    use model_core::observer::{Measurements, Observer, ObserverConfig};
    use model_core::{BenchState, Scheme, WhiteBox};

    /// Why a part failed (the probes only exit with it).
    pub type Error = &'static str;

    /// The white-box bench in f32: the steady state, a step of each scheme, the signals.
    pub fn whitebox() -> Result<(), Error> {
        let bench = WhiteBox::<f32>::paper();
        let mut st = bench
            .steady_state(black_box(40.0))
            .unwrap_or(BenchState::at_rest());
        for scheme in [Scheme::Rk4, Scheme::Heun, Scheme::Euler] {
            bench
                .step(&mut st, black_box(60.0), black_box(1e-3), black_box(scheme))
                .map_err(|_| "white-box step")?;
        }
        black_box(bench.signals(&st));
        Ok(())
    }

    /// Both models of one pass (`F32` or `Q15`, the firmware's statics): a free-run and a
    /// one-step-ahead step each.
    macro_rules! step_both {
        ($pass:ident) => {{
            let (p, q) = (black_box(&pressure::$pass), black_box(&flow::$pass));
            let (mut sp, mut sq) = (p.state_at(50.0, 2.6), q.state_at(50.0, 15.8));
            black_box(p.simulate_step(&mut sp, black_box(55.0)));
            black_box(p.predict_step(&mut sp, black_box(55.0), black_box(2.7)));
            black_box(q.simulate_step(&mut sq, black_box(55.0)));
            black_box(q.predict_step(&mut sq, black_box(55.0), black_box(16.0)));
            Ok(())
        }};
    }

    /// The NARMAX models' f32 passes.
    pub fn narmax_f32() -> Result<(), Error> {
        step_both!(F32)
    }

    /// The NARMAX models' Q15 passes.
    pub fn narmax_fixed() -> Result<(), Error> {
        step_both!(Q15)
    }

    /// The observer (f32) and the alarm monitor: built, one update each.
    pub fn observer() -> Result<(), Error> {
        let mut obs = Observer::<f32>::new(ObserverConfig::paper(), black_box(50.0))
            .map_err(|_| "observer")?;
        let mut mon = Monitor::<f32>::new(MonitorConfig::paper());
        let m = Measurements {
            pressure_mca: Some(black_box(2.7)),
            flow_lps: Some(black_box(15.8)),
            speed_rpm: Some(black_box(1230.0)),
        };
        let e = obs
            .step(black_box(0.05), black_box(50.0), &m)
            .map_err(|_| "observer step")?;
        black_box(mon.update(&MonitorInputs {
            dt_s: 0.05,
            estimate: e,
            torque_ref_pct: 50.0,
            vfd_torque_pct: Some(black_box(50.0)),
            vfd_speed_rpm: m.speed_rpm,
            measured_flow_lps: m.flow_lps,
            pressure_fault: black_box(false),
            flow_fault: false,
            vfd_link_alarm: false,
        }));
        Ok(())
    }

    /// Ends the program (QEMU exits 0 on success, 1 on failure); a probe's panic handler
    /// calls it too.
    pub use board_common::semihosting::exit;
}
