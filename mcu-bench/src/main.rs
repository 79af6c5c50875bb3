//! The bench image: every kernel of [`ROWS`] called many times on changing inputs, each call
//! timed with SysTick ([`Cost::time`]), one text line per row over semihosting:
//!
//! ```text
//! row name=narmax_pressure_f32 baseline=narmax_pressure_f32_plain calls=400 ticks=… max=…
//! ```
//!
//! `ticks` is the sum over `calls` calls, `max` the longest call, both in SysTick ticks (168 MHz
//! under QEMU; with `-icount shift=0` instructions = ticks / 0.168). The first row, `empty`,
//! is an empty call through the same closure: `cargo xtask bench` takes its mean off every
//! other row. A row with `max_name=` also reports its longest call under that name. The run
//! ends with `done` and exit status 0; a kernel that fails prints `error:` and exits 1.
//!
//! To add a kernel: write a function `fn(&mut Cost, calls) -> Result<(), Error>` that builds
//! its inputs and times each call with `cost.time(|| kernel(black_box(input)))`, and add a
//! [`Row`] for it.
#![no_std]
#![no_main]

use controller::control::{Config, NarmaxModel, ADAPT_TAU_S};
use controller::modbus::{crc16, Frame};
use controller::types::Mode;
use controller::virtual_bench::{VirtualBenchConfig, VirtualBoard};
use core::fmt::Write;
use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::hio;
use mcu_bench::plain::PlainNarmax;
use mcu_bench::{empty, inputs, models, plain_model, start_counter, Cost};
use model_core::dsp::{smlad, smlad_portable};
use model_core::excitation::SplitMix64;
use model_core::monitor::{Monitor, MonitorConfig, MonitorInputs};
use model_core::narmax::adapt::OutputMap;
use model_core::narmax::mcu::build_period_ms;
use model_core::narmax::mcu::{tanh_f32, tanh_q15, I16F16};
use model_core::narmax::{Narmax, Predictor};
use model_core::observer::{Measurements, Observer, ObserverConfig};
use model_core::{BenchState, Scheme, WhiteBox};
use panic_semihosting as _;

/// Why a row could not be measured.
type Error = &'static str;

/// One row of the table: a kernel, how often it is called and what it is compared with.
struct Row {
    /// Name (a key of `mcu.json`'s "kernels").
    name: &'static str,
    /// The row this one is compared with in the table (ratio), if any.
    baseline: Option<&'static str>,
    /// The name under which the longest call is reported, if it is.
    max_name: Option<&'static str>,
    /// Calls measured.
    calls: u32,
    /// Builds the inputs and times `calls` calls.
    run: fn(&mut Cost, u32) -> Result<(), Error>,
}

impl Row {
    const fn new(
        name: &'static str,
        calls: u32,
        run: fn(&mut Cost, u32) -> Result<(), Error>,
    ) -> Self {
        Self {
            name,
            baseline: None,
            max_name: None,
            calls,
            run,
        }
    }
    const fn vs(mut self, baseline: &'static str) -> Self {
        self.baseline = Some(baseline);
        self
    }
    const fn with_max(mut self, max_name: &'static str) -> Self {
        self.max_name = Some(max_name);
        self
    }
}

/// The kernels measured, in the table's order. `empty` must stay first.
const ROWS: &[Row] = &[
    Row::new("empty", 1000, empty_call),
    // NARMAX free-run steps, 20 s of the paper's excitation at 50 ms. The plain generic f32
    // pass with libm's tanhf is the baseline the kernels are compared with.
    Row::new("narmax_pressure_f32_plain", 400, pressure_plain),
    Row::new("narmax_pressure_f32", 400, pressure_f32).vs("narmax_pressure_f32_plain"),
    Row::new("narmax_pressure_fixed", 400, pressure_fixed).vs("narmax_pressure_f32_plain"),
    Row::new("narmax_flow_f32_plain", 400, flow_plain),
    Row::new("narmax_flow_f32", 400, flow_f32).vs("narmax_flow_f32_plain"),
    Row::new("narmax_flow_fixed", 400, flow_fixed).vs("narmax_flow_f32_plain"),
    // The output map that makes a model follow the load (holding register 19): its output and
    // its update, once per sample, beside the pressure model's f32 free run.
    Row::new("narmax_adapt", 400, narmax_adapt),
    // tanh on inputs uniform in [-4, 4).
    Row::new("tanhf", 1000, tanhf),
    Row::new("tanh_f32", 1000, tanh_f32_row).vs("tanhf"),
    Row::new("tanh_q15", 1000, tanh_q15_row).vs("tanhf"),
    // Eight chained SMLADs (16 multiply-accumulates) through model-core's audited `asm!`, each
    // result checked against the portable definition.
    Row::new("smlad_x8", 1000, smlad_row),
    // The white-box bench, 5 s of the paper's excitation at 1 ms.
    Row::new("rk4_step", 5000, rk4_step),
    Row::new("heun_step", 5000, heun_step).vs("rk4_step"),
    Row::new("euler_step", 5000, euler_step).vs("rk4_step"),
    Row::new("flow_solve", 5000, flow_solve),
    // The observer every 50 ms on the bench, 20 s of the excitation.
    Row::new("observer_update", 400, observer_update).with_max("observer_update_max"),
    Row::new("monitor_update", 400, monitor_update),
    // The controller's whole 1 ms tick on the virtual bench, profile mode, 20 s.
    Row::new("tick_mean", 20_000, tick).with_max("tick_max"),
    // The pressure loop's period (mode 3, model-based: the warm-started inverse, the
    // linearisation, the PI) on the white-box, pressure steps 2 → 4 → 1 → 3 mca, 5 s each.
    Row::new("regulator_step", 4000, regulator_step).with_max("regulator_step_max"),
    // The whole tick in mode 3 on the virtual bench, the same steps, 20 s: held to the
    // tick's budgets (tick_mean, tick_max).
    Row::new("tick_pressure_mean", 20_000, tick_pressure).with_max("tick_pressure_max"),
    // The whole tick in profile mode with the models following the load (holding register
    // 19 = 1), 20 s: held to the tick's budgets.
    Row::new("tick_adapt_mean", 20_000, tick_adapt).with_max("tick_adapt_max"),
];

/// Seed of the excitation every row follows.
const SEED: u64 = 1;
/// NARMAX sample period, ms.
const NARMAX_MS: u32 = 50;

fn empty_call(c: &mut Cost, n: u32) -> Result<(), Error> {
    for x in inputs::uniform(SEED, -4.0, 4.0).take(n as usize) {
        c.time(|| empty(black_box(x)));
    }
    Ok(())
}

fn pressure(
) -> Result<Narmax<f32, { models::pressure::INPUTS }, { models::pressure::HIDDEN }>, Error> {
    Narmax::from_nnsysid(&models::pressure::MODEL).map_err(|_| "pressure model refused")
}

fn flow() -> Result<Narmax<f32, { models::flow::INPUTS }, { models::flow::HIDDEN }>, Error> {
    Narmax::from_nnsysid(&models::flow::MODEL).map_err(|_| "flow model refused")
}

/// One of model-core's MCU passes (`NarxF32` or `NarxQ15`, the firmware's statics): free-run
/// steps from the output's mean.
fn narmax_pass<P: Predictor<Value = f32>>(m: &P, c: &mut Cost, n: u32) -> Result<(), Error> {
    let mut st = m.state_at(0.0, m.output_mean());
    for u in inputs::pulses(SEED, NARMAX_MS).take(n as usize) {
        c.time(|| m.simulate_step(black_box(&mut st), black_box(u)));
    }
    Ok(())
}

/// The plain pass; checks that it follows model-core's f32 step (within 0.1 % of the output's
/// standard deviation at every step).
fn narmax_plain<const N: usize, const H: usize>(
    p: Option<PlainNarmax<N, H>>,
    m: &Narmax<f32, N, H>,
    c: &mut Cost,
    n: u32,
) -> Result<(), Error> {
    let p = p.ok_or("plain pass: model shapes do not fit")?;
    let y0 = m.output_mean();
    let (mut st, mut reference) = (p.state_at(0.0, y0), m.state_at(0.0, y0));
    for u in inputs::pulses(SEED, NARMAX_MS).take(n as usize) {
        let (y, _) = c.time(|| p.simulate_step(black_box(&mut st), black_box(u)));
        let y_ref = m.simulate_step(&mut reference, u).y;
        let follows = (y - y_ref).abs() <= 1e-3 * m.output_scaling().std; // false for NaN
        if !follows {
            return Err("the plain pass does not follow model-core's f32 step");
        }
    }
    Ok(())
}

/// The output map beside the pressure model's f32 free run: the plant's pressure 1.3 times the
/// model's and 0.2 mca over it, each sample's map output and update timed.
fn narmax_adapt(c: &mut Cost, n: u32) -> Result<(), Error> {
    let m = &models::pressure::F32;
    let mut map = OutputMap::new(m.output_scaling(), NARMAX_MS as f32 * 1e-3, ADAPT_TAU_S)
        .map_err(|_| "output map refused")?;
    let mut st = m.state_at(0.0, m.output_mean());
    for u in inputs::pulses(SEED, NARMAX_MS).take(n as usize) {
        let y = m.simulate_step(&mut st, u).y;
        let plant = 1.3 * y + 0.2;
        let (out, upd) = c.time(|| {
            let out = map.output(black_box(y));
            (out, map.update(black_box(y), black_box(plant)))
        });
        if !out.is_finite() || upd.diverged {
            return Err("the output map failed");
        }
    }
    Ok(())
}

fn pressure_plain(c: &mut Cost, n: u32) -> Result<(), Error> {
    narmax_plain(plain_model!(pressure), &pressure()?, c, n)
}
fn pressure_f32(c: &mut Cost, n: u32) -> Result<(), Error> {
    narmax_pass(&models::pressure::F32, c, n)
}
fn pressure_fixed(c: &mut Cost, n: u32) -> Result<(), Error> {
    narmax_pass(&models::pressure::Q15, c, n)
}
fn flow_plain(c: &mut Cost, n: u32) -> Result<(), Error> {
    narmax_plain(plain_model!(flow), &flow()?, c, n)
}
fn flow_f32(c: &mut Cost, n: u32) -> Result<(), Error> {
    narmax_pass(&models::flow::F32, c, n)
}
fn flow_fixed(c: &mut Cost, n: u32) -> Result<(), Error> {
    narmax_pass(&models::flow::Q15, c, n)
}

fn tanhf(c: &mut Cost, n: u32) -> Result<(), Error> {
    for x in inputs::uniform(SEED, -4.0, 4.0).take(n as usize) {
        c.time(|| libm::tanhf(black_box(x)));
    }
    Ok(())
}

fn tanh_f32_row(c: &mut Cost, n: u32) -> Result<(), Error> {
    for x in inputs::uniform(SEED, -4.0, 4.0).take(n as usize) {
        c.time(|| tanh_f32(black_box(x)));
    }
    Ok(())
}

fn tanh_q15_row(c: &mut Cost, n: u32) -> Result<(), Error> {
    for x in inputs::uniform(SEED, -4.0, 4.0).take(n as usize) {
        let x = I16F16::from_bits((x * 65536.0) as i32);
        c.time(|| tanh_q15(black_box(x)));
    }
    Ok(())
}

/// Eight chained `smlad`s (the `asm!` on this target) on random words: every result must
/// equal `smlad_portable`'s, the host's definition.
fn smlad_row(c: &mut Cost, n: u32) -> Result<(), Error> {
    let mut rng = SplitMix64::new(SEED);
    for _ in 0..n {
        let r = rng.next_u64();
        let (a, b, acc) = (r as u32, (r >> 32) as u32, rng.next_u64() as i32);
        let chain = |f: fn(u32, u32, i32) -> i32| {
            let mut x = acc;
            for k in 0..8u32 {
                x = f(a.rotate_left(k), b, x);
            }
            x
        };
        let got = c.time(|| {
            let (a, b, mut x) = (black_box(a), black_box(b), black_box(acc));
            x = smlad(a, b, x);
            x = smlad(a.rotate_left(1), b, x);
            x = smlad(a.rotate_left(2), b, x);
            x = smlad(a.rotate_left(3), b, x);
            x = smlad(a.rotate_left(4), b, x);
            x = smlad(a.rotate_left(5), b, x);
            x = smlad(a.rotate_left(6), b, x);
            smlad(a.rotate_left(7), b, x)
        });
        if got != chain(smlad_portable) || got != chain(smlad) {
            return Err("SMLAD differs from its portable definition");
        }
    }
    Ok(())
}

/// One white-box step of `scheme` every 1 ms under the excitation, from its first steady
/// state.
fn whitebox_step(scheme: Scheme, c: &mut Cost, n: u32) -> Result<(), Error> {
    let bench = WhiteBox::<f32>::paper();
    let mut torque = inputs::pulses(SEED, 1);
    let u0 = torque.next().ok_or("no excitation")?;
    let mut st = bench.steady_state(u0).map_err(|_| "steady state")?;
    for u in torque.take(n as usize) {
        c.time(|| bench.step(black_box(&mut st), black_box(u), black_box(1e-3), scheme))
            .map_err(|_| "white-box step failed")?;
    }
    Ok(())
}

fn rk4_step(c: &mut Cost, n: u32) -> Result<(), Error> {
    whitebox_step(Scheme::Rk4, c, n)
}
fn heun_step(c: &mut Cost, n: u32) -> Result<(), Error> {
    whitebox_step(Scheme::Heun, c, n)
}
fn euler_step(c: &mut Cost, n: u32) -> Result<(), Error> {
    whitebox_step(Scheme::Euler, c, n)
}

/// The flow solve (`WhiteBox::flow_at`) along an RK4 run: each step's new speed, warm-started
/// from the last step's flow.
fn flow_solve(c: &mut Cost, n: u32) -> Result<(), Error> {
    let bench = WhiteBox::<f32>::paper();
    let mut torque = inputs::pulses(SEED, 1);
    let u0 = torque.next().ok_or("no excitation")?;
    let mut st = bench.steady_state(u0).map_err(|_| "steady state")?;
    for u in torque.take(n as usize) {
        let warm = st.flow_lps;
        rk4_ms(&bench, &mut st, u)?;
        let speed = st.speed_rpm;
        c.time(|| bench.flow_at(black_box(speed), black_box(warm)));
    }
    Ok(())
}

/// One 1 ms RK4 step of the bench, kept out of line: the untimed work around a timed call
/// must not change the registers the call is timed with (the RK4 step's own register
/// pressure once cost the `flow_solve` row three moves).
#[inline(never)]
fn rk4_ms(bench: &WhiteBox<f32>, st: &mut BenchState<f32>, u: f32) -> Result<(), Error> {
    bench
        .step(st, u, 1e-3, Scheme::Rk4)
        .map_err(|_| "white-box step failed")
}

/// The observer every 50 ms on a white-box bench (RK4, 1 ms) under the excitation, with a
/// pressure reading every update, a flow reading every other and the VFD's speed every one
/// (the most an update does); the alarm monitor after each. Times the observer's update into
/// `obs` and the monitor's into `mon`.
fn observer_run(obs: &mut Cost, mon: &mut Cost, n: u32) -> Result<(), Error> {
    let bench = WhiteBox::<f32>::paper();
    let mut torque = inputs::pulses(SEED, NARMAX_MS);
    let u0 = torque.next().ok_or("no excitation")?;
    let mut st = bench.steady_state(u0).map_err(|_| "steady state")?;
    let mut observer =
        Observer::<f32>::new(ObserverConfig::paper(), u0).map_err(|_| "observer refused")?;
    let mut monitor = Monitor::<f32>::new(MonitorConfig::paper());
    for (k, u) in torque.take(n as usize).enumerate() {
        for _ in 0..NARMAX_MS {
            rk4_ms(&bench, &mut st, u)?;
        }
        let s = bench.signals(&st);
        let m = Measurements {
            pressure_mca: Some(s.pressure_mca),
            flow_lps: (k % 2 == 1).then_some(s.flow_lps),
            speed_rpm: Some(s.speed_rpm),
        };
        let e = obs
            .time(|| observer.step(black_box(0.05), black_box(u), black_box(&m)))
            .map_err(|_| "observer step failed")?;
        let inputs = MonitorInputs {
            dt_s: 0.05,
            estimate: e,
            torque_ref_pct: u,
            vfd_torque_pct: Some(u),
            vfd_speed_rpm: Some(s.speed_rpm),
            measured_flow_lps: m.flow_lps,
            pressure_fault: false,
            flow_fault: false,
            vfd_link_alarm: false,
        };
        mon.time(|| monitor.update(black_box(&inputs)));
    }
    Ok(())
}

fn observer_update(c: &mut Cost, n: u32) -> Result<(), Error> {
    observer_run(c, &mut Cost::default(), n)
}
fn monitor_update(c: &mut Cost, n: u32) -> Result<(), Error> {
    observer_run(&mut Cost::default(), c, n)
}

/// Pressure model period, ms (as the firmware has it).
const PRESSURE_MS: u32 = build_period_ms(models::pressure::SAMPLE_PERIOD_S);
/// Flow model period, ms.
const FLOW_MS: u32 = build_period_ms(models::flow::SAMPLE_PERIOD_S);

/// The control task's core, [`Controller::step`](controller::control::Controller::step), on
/// the virtual bench in profile mode (the paper's excitation), NARMAX in f32, as the QEMU
/// firmware runs it. The inputs (ADC codes, commands, VFD status) are made outside the timed
/// call, and the links and the bench's 1 ms step run between calls, untimed.
fn tick(c: &mut Cost, n: u32) -> Result<(), Error> {
    tick_in(Mode::Profile, false, c, n)
}

/// [`tick`] with the NARMAX models following the load (holding register 19 = 1).
fn tick_adapt(c: &mut Cost, n: u32) -> Result<(), Error> {
    tick_in(Mode::Profile, true, c, n)
}

/// [`tick`] in mode 3 (pressure control), the setpoint stepping 2 → 4 → 1 → 3 mca every 5 s
/// (the SCADA's holding register, as a user writes it).
fn tick_pressure(c: &mut Cost, n: u32) -> Result<(), Error> {
    tick_in(Mode::Pressure, false, c, n)
}

/// Pressure setpoints of the loop rows, mca, each for [`LOOP_STEP_MS`].
const LOOP_SETPOINTS_MCA: [f32; 4] = [2.0, 4.0, 1.0, 3.0];
/// How long each loop setpoint holds, ms.
const LOOP_STEP_MS: u32 = 5000;

/// The loop's period on the white-box bench: pressure steps 2 → 4 → 1 → 3 mca, the load as
/// the observer gives it, a new estimate every 50 ms (k2 wandering ±1 %, so the feedforward's
/// load change enters every 10th period, as in the firmware: between moves the last period's
/// solution is the old load's, during a move it is moved along the model's gain), the speed
/// the bench's.
fn regulator_step(c: &mut Cost, n: u32) -> Result<(), Error> {
    use controller::regulate::{Controlled, Regulator, CONTROL_PERIOD_MS};
    use controller::types::ControlSettings;
    use model_core::inverse::Load;
    let bench = WhiteBox::<f32>::paper();
    let p = *bench.params();
    let mut load = Load {
        valve_k2: p.valve_k2,
        head_scale: 1.0,
        torque_scale: 1.0,
    };
    let mut st = bench.steady_state(40.0).map_err(|_| "steady state")?;
    let mut reg = Regulator::new(
        Controlled::Pressure,
        bench.signals(&st).pressure_mca,
        40.0,
        st.speed_rpm,
    );
    let s = ControlSettings::DEFAULT;
    let per_step = LOOP_STEP_MS / CONTROL_PERIOD_MS;
    let per_estimate = NARMAX_MS / CONTROL_PERIOD_MS;
    let mut rng = SplitMix64::new(SEED);
    for k in 0..n {
        let sp = LOOP_SETPOINTS_MCA[((k / per_step) % 4) as usize];
        if k % per_estimate == 0 {
            let unit = (rng.next_u64() >> 40) as f32 / (1u32 << 24) as f32;
            load.valve_k2 = p.valve_k2 * (1.0 + 0.02 * (unit - 0.5));
        }
        let y = bench.signals(&st).pressure_mca;
        // The speed as the controller gives it every period (no speed limit here).
        reg.set_speed_limit(0.0, st.speed_rpm);
        let o = c.time(|| {
            reg.step(
                black_box(&p),
                black_box(load),
                &s,
                black_box(sp),
                black_box(y),
            )
        });
        for _ in 0..CONTROL_PERIOD_MS {
            rk4_ms(&bench, &mut st, o.torque_pct)?;
        }
    }
    Ok(())
}

fn tick_in(mode: Mode, adapt: bool, c: &mut Cost, n: u32) -> Result<(), Error> {
    let config = Config {
        initial_mode: mode,
        profile_seed: SEED,
        virtual_bench: true,
        ..Config::bench()
    };
    let p = NarmaxModel::new(&models::pressure::F32, &models::pressure::Q15, PRESSURE_MS)
        .map_err(|_| "pressure model")?;
    let q = NarmaxModel::new(&models::flow::F32, &models::flow::Q15, FLOW_MS)
        .map_err(|_| "flow model")?;
    let mut b = VirtualBoard::new(&config, p, q, VirtualBenchConfig::default_offsets(SEED))
        .map_err(|_| "controller refused its configuration")?;
    if adapt {
        // FC 06 to holding register 19, as a SCADA writes it.
        let body = [1, 6, 0, 19, 0, 1];
        let [c0, c1] = crc16(&body).to_le_bytes();
        b.scada
            .handle(&[1, 6, 0, 19, 0, 1, c0, c1], &mut Frame::new())
            .ok_or("no answer to the write of register 19")?;
        if !b.scada.commands().narmax_adapt {
            return Err("adaptation refused");
        }
    }
    for k in 0..n {
        if k % LOOP_STEP_MS == 0 {
            let sp = LOOP_SETPOINTS_MCA[((k / LOOP_STEP_MS) % 4) as usize];
            // FC 06 to holding register 8 (0.001 mca), as a SCADA writes it.
            let [hi, lo] = ((sp * 1000.0) as u16).to_be_bytes();
            let body = [1, 6, 0, 8, hi, lo];
            let [c0, c1] = crc16(&body).to_le_bytes();
            let request = [1, 6, 0, 8, hi, lo, c0, c1];
            b.scada
                .handle(&request, &mut Frame::new())
                .ok_or("setpoint refused")?;
        }
        b.tick_with(|controller, inputs| c.time(|| controller.step(black_box(inputs))))
            .map_err(|_| "virtual bench step failed")?;
    }
    Ok(())
}

fn run(out: &mut impl Write) -> Result<(), core::fmt::Error> {
    let Some(mut cp) = cortex_m::Peripherals::take() else {
        writeln!(out, "error: core peripherals taken")?;
        return Err(core::fmt::Error);
    };
    start_counter(&mut cp.SYST);
    writeln!(
        out,
        "mcu-bench: SysTick ticks per kernel (168 MHz; under -icount shift=0 instructions = ticks / 0.168)"
    )?;
    for row in ROWS {
        let mut cost = Cost::default();
        if let Err(e) = (row.run)(&mut cost, row.calls) {
            writeln!(out, "error: {}: {e}", row.name)?;
            return Err(core::fmt::Error);
        }
        write!(out, "row name={}", row.name)?;
        if let Some(b) = row.baseline {
            write!(out, " baseline={b}")?;
        }
        if let Some(m) = row.max_name {
            write!(out, " max_name={m}")?;
        }
        writeln!(
            out,
            " calls={} ticks={} max={}",
            cost.calls, cost.ticks, cost.max
        )?;
    }
    writeln!(out, "done")
}

#[entry]
fn main() -> ! {
    let ok = match hio::hstdout() {
        Ok(mut out) => run(&mut out).is_ok(),
        Err(()) => false,
    };
    mcu_bench::parts::exit(ok)
}
