//! Cost of the loop and of each model step on the target, in SysTick ticks (168 MHz under
//! QEMU; with `-icount shift=0` one instruction is 1 ns, so instructions = ticks / 0.168).
//! QEMU has no cycle model and no DWT counter: these are instruction counts, not cycles.

use crate::{models, Loop};
use controller::bench::VirtualIo;
use core::fmt::Write;
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use model_core::monitor::{Monitor, MonitorConfig, MonitorInputs};
use model_core::observer::{Measurements, Observer, ObserverConfig};
use model_core::{Scheme, WhiteBox};

/// SysTick's 24-bit counter mask.
const SYST_MASK: u32 = 0x00FF_FFFF;
/// Loop time measured, ms.
const LOOP_MS: u32 = 20_000;
/// Calls per model measured.
const MODEL_CALLS: u32 = 400;

/// Sum of SysTick ticks and calls, and the largest call.
#[derive(Default)]
struct Cost {
    ticks: u64,
    calls: u64,
    max: u32,
}

impl Cost {
    /// Runs `f`, adding its SysTick ticks (the counter counts down, 24 bits, no interrupt).
    fn time<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let t0 = SYST::get_current();
        let r = f();
        let dt = t0.wrapping_sub(SYST::get_current()) & SYST_MASK;
        self.ticks += u64::from(dt);
        self.calls += 1;
        self.max = self.max.max(dt);
        r
    }

    fn mean(&self) -> u64 {
        self.ticks / self.calls.max(1)
    }
}

/// Measures and prints; the bench stays virtual, nothing is paced.
pub fn report(
    mut syst: SYST,
    app: &mut Loop,
    mut virt: VirtualIo,
    out: &mut impl Write,
) -> Result<(), core::fmt::Error> {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(SYST_MASK);
    syst.clear_current();
    syst.enable_counter();

    // A tick's cost includes the virtual bench's I/O it calls (ADC codes, the in-process
    // drive's answers); the bench's own 1 ms step is left out.
    let mut tick = Cost::default();
    for _ in 0..LOOP_MS {
        tick.time(|| app.tick(&mut virt));
        virt.step_1ms().map_err(|_| core::fmt::Error)?;
    }
    writeln!(
        out,
        "timing loop_ticks={} systick_ticks_per_tick mean={} max={}",
        tick.calls,
        tick.mean(),
        tick.max
    )?;

    let bad = |_| core::fmt::Error;
    let bench = WhiteBox::<f32>::paper();
    let mut st = bench.steady_state(50.0).map_err(bad)?;
    let mut rk4 = Cost::default();
    for k in 0..MODEL_CALLS {
        let u = if k % 200 < 100 { 30.0 } else { 70.0 };
        rk4.time(|| bench.step(&mut st, u, 1e-3, Scheme::Rk4))
            .map_err(bad)?;
    }
    let (p, pq) = (&models::pressure::F32, &models::pressure::Q15);
    let (q, qq) = (&models::flow::F32, &models::flow::Q15);
    let (mut sp, mut spq) = (p.state_at(50.0, 2.66), pq.state_at(50.0, 2.66));
    let (mut sq, mut sqq) = (q.state_at(50.0, 15.8), qq.state_at(50.0, 15.8));
    let mut c = [
        Cost::default(),
        Cost::default(),
        Cost::default(),
        Cost::default(),
    ];
    for k in 0..MODEL_CALLS {
        let u = 30.0 + (k % 40) as f32;
        c[0].time(|| p.simulate_step(&mut sp, u));
        c[1].time(|| pq.simulate_step(&mut spq, u));
        c[2].time(|| q.simulate_step(&mut sq, u));
        c[3].time(|| qq.simulate_step(&mut sqq, u));
    }
    // The observer on a bench of its own, the torque stepping 30 ↔ 70 % every 2 s: each
    // update with a pressure reading, every other with flow, every one with the VFD's speed
    // (the most a 50 ms update does).
    let mut obs =
        Observer::<f32>::new(ObserverConfig::paper(), 30.0).map_err(|_| core::fmt::Error)?;
    let mut mon = Monitor::<f32>::new(MonitorConfig::paper());
    let mut st = bench.steady_state(30.0).map_err(bad)?;
    let (mut upd, mut alarms) = (Cost::default(), Cost::default());
    for k in 0..MODEL_CALLS {
        let u = if k % 80 < 40 { 30.0 } else { 70.0 };
        for _ in 0..50 {
            bench.step(&mut st, u, 1e-3, Scheme::Rk4).map_err(bad)?;
        }
        let s = bench.signals(&st);
        let m = Measurements {
            pressure_mca: Some(s.pressure_mca),
            flow_lps: (k % 2 == 1).then_some(s.flow_lps),
            speed_rpm: Some(s.speed_rpm),
        };
        let e = upd
            .time(|| obs.step(0.05, u, &m))
            .map_err(|_| core::fmt::Error)?;
        alarms.time(|| {
            mon.update(&MonitorInputs {
                dt_s: 0.05,
                estimate: e,
                torque_ref_pct: u,
                vfd_torque_pct: Some(u),
                vfd_speed_rpm: Some(s.speed_rpm),
                measured_flow_lps: m.flow_lps,
                pressure_fault: false,
                flow_fault: false,
                vfd_link_alarm: false,
            })
        });
    }
    writeln!(out, "timing rk4 systick_ticks_per_step={}", rk4.mean())?;
    writeln!(
        out,
        "timing observer systick_ticks_per_update mean={} max={} monitor={}",
        upd.mean(),
        upd.max,
        alarms.mean()
    )?;
    writeln!(
        out,
        "timing narmax systick_ticks_per_step pressure_f32={} pressure_q15={} flow_f32={} flow_q15={}",
        c[0].mean(),
        c[1].mean(),
        c[2].mean(),
        c[3].mean()
    )?;
    Ok(())
}
