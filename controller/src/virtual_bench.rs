//! The virtual bench: what the controller's inputs see when no bench is wired.
//!
//! A white-box bench in f32 whose parameters are a few percent off the model's (so the
//! model's residuals are not zero), stepped at 1 ms with the torque the controller applies;
//! the transmitters add a first-order lag (pressure 20 ms, flow 40 ms, as `pumpbench
//! bench-data`), noise (3 mm of water, 0.02 l/s, 1 σ) and the 4-20 mA loop's saturation at
//! 3.8 / 20.5 mA (NAMUR NE 43 measuring range); the ADC quantises the shunt voltage to its
//! bits. The transmitters, the ADC and the noise are [`crate::analog`]'s model, the one
//! `pumpbench bench-data` uses too. The controller therefore reads raw ADC codes through the
//! same scaling and fault checks as on a board. A loop current can be forced (a broken wire, a short) to exercise
//! the fault path.
//!
//! Its drive limits the speed as real drives do (a maximum speed parameter): above
//! [`VirtualBenchConfig::drive_speed_limit_rpm`] it takes its torque down to 0 over
//! [`DRIVE_SPEED_LIMIT_BAND_RPM`], so a pump that loses its load settles near the limit
//! instead of running away. The controller does not rely on it: its own overspeed
//! protection ([`crate::protect`]) trips well below the drive's default limit.
//!
//! The noise is [`crate::analog::noise`]: the sum of four uniform draws (SplitMix64), scaled
//! to unit variance.

use crate::analog::{self, noise, LoopConfig, FLOW_LOOP, PRESSURE_LOOP};
use crate::control::{
    Commands, Config, Controller, Error, Inputs, NarmaxModel, Outputs, VfdStatus,
};
use crate::link::{ScadaLink, VfdLink, VfdPort};
use crate::modbus::Frame;
use crate::types::InjectedFaults;
use crate::vfd::VfdMap;
use crate::vfdsim::{DriveValues, VfdSim};
use model_core::equations::valve_pressure_mca;
use model_core::excitation::SplitMix64;
use model_core::units::applied_torque_pct;
use model_core::{BenchError, BenchParams, BenchState, Scheme, Signals, WhiteBox};

/// How the virtual bench departs from the model, and its transmitters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualBenchConfig {
    /// Inertia factor (model × this).
    pub inertia_factor: f32,
    /// Load torque factor on β1..β10 (friction and hydraulic torque): the load-torque curve
    /// F_T (eq. 6) times this.
    pub load_torque_factor: f32,
    /// Pump head factor on α1..α10: the head curve F_H (eq. 5) times this (1: the paper's).
    pub head_factor: f32,
    /// Valve coefficient factor on k2.
    pub valve_factor: f32,
    /// Pressure transmitter time constant, s (≥ 0).
    pub pressure_lag_s: f32,
    /// Flow transmitter time constant, s (≥ 0).
    pub flow_lag_s: f32,
    /// Pressure noise, mca (1 σ).
    pub pressure_noise_mca: f32,
    /// Flow noise, l/s (1 σ).
    pub flow_noise_lps: f32,
    /// Pressure loop (span, shunt, ADC).
    pub pressure_loop: LoopConfig,
    /// Flow loop.
    pub flow_loop: LoopConfig,
    /// Noise seed.
    pub seed: u64,
    /// The drive's speed limit, rpm (> 0; infinite: none): above it the drive takes its
    /// torque down to 0 over [`DRIVE_SPEED_LIMIT_BAND_RPM`].
    pub drive_speed_limit_rpm: f32,
}

/// The band over which the drive's speed limiter takes the torque from the reference to 0,
/// rpm.
pub const DRIVE_SPEED_LIMIT_BAND_RPM: f32 = 50.0;

impl VirtualBenchConfig {
    /// J +5 %, load torque +2 %, the paper's head curve, valve k2 +2 %; the bench's transmitters ([`PRESSURE_LOOP`]
    /// 0..10 mca, [`FLOW_LOOP`] 0..30 l/s), lags 20 / 40 ms, noise 3 mm / 0.02 l/s; the drive's
    /// speed limit at 2 100 rpm (120 % of the motor's nominal 1 750).
    pub const fn default_offsets(seed: u64) -> Self {
        Self {
            inertia_factor: 1.05,
            load_torque_factor: 1.02,
            head_factor: 1.0,
            valve_factor: 1.02,
            pressure_lag_s: 0.02,
            flow_lag_s: 0.04,
            pressure_noise_mca: 0.003,
            flow_noise_lps: 0.02,
            pressure_loop: PRESSURE_LOOP,
            flow_loop: FLOW_LOOP,
            seed,
            drive_speed_limit_rpm: 2100.0,
        }
    }
}

/// The virtual bench.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualBench {
    config: VirtualBenchConfig,
    bench: WhiteBox<f32>,
    state: BenchState<f32>,
    pressure_seen: f32,
    flow_seen: f32,
    rng: SplitMix64,
    /// A forced pressure loop current, mA (a transmitter fault), or `None`.
    pub force_pressure_ma: Option<f32>,
    /// A forced flow loop current, mA, or `None`.
    pub force_flow_ma: Option<f32>,
    /// The pump runs dry (loss of prime): no flow, the outlet at its static level (−c), and
    /// only the friction part of the load curve (β9 ω + β10) left on the shaft.
    pub dry_run: bool,
    /// The torque reference the drive delivered over the last step, %.
    delivered_pct: f32,
}

impl VirtualBench {
    /// A bench at rest (its steady state at 0 % torque).
    #[inline(never)]
    pub fn new(config: VirtualBenchConfig) -> Result<Self, BenchError> {
        let mut p = BenchParams::<f32>::paper();
        p.inertia_kg_m2 *= config.inertia_factor;
        for (a, b) in p.alpha.iter_mut().zip(&mut p.beta) {
            *a *= config.head_factor;
            *b *= config.load_torque_factor;
        }
        p.valve_k2 *= config.valve_factor;
        if !(config.pressure_lag_s >= 0.0 && config.flow_lag_s >= 0.0) {
            return Err(BenchError::InvalidParameter(
                "transmitter lags must be >= 0",
            ));
        }
        if config.drive_speed_limit_rpm.is_nan() || config.drive_speed_limit_rpm <= 0.0 {
            return Err(BenchError::InvalidParameter(
                "the drive's speed limit must be > 0",
            ));
        }
        let bench = WhiteBox::new(p)?;
        let state = bench.steady_state(0.0)?;
        let s = bench.signals(&state);
        Ok(Self {
            config,
            bench,
            state,
            pressure_seen: s.pressure_mca,
            flow_seen: s.flow_lps,
            rng: SplitMix64::new(config.seed),
            force_pressure_ma: None,
            force_flow_ma: None,
            dry_run: false,
            delivered_pct: 0.0,
        })
    }

    /// Sets the valve to `factor` × its configured k2 (the bench's own, a few percent off the
    /// model's); `factor` finite and > 0.
    pub fn set_valve_factor(&mut self, factor: f32) -> Result<(), BenchError> {
        let k2 = BenchParams::<f32>::paper().valve_k2 * self.config.valve_factor * factor;
        let c = self.bench.params().static_head_c_mca;
        self.bench.set_load(k2, c)
    }

    /// The valve coefficient now.
    pub fn valve_k2(&self) -> f32 {
        self.bench.params().valve_k2
    }

    /// The torque reference the drive delivered over the last step, %: the reference, less
    /// what its speed limiter took.
    pub fn delivered_torque_pct(&self) -> f32 {
        self.delivered_pct
    }

    /// Advances the bench by 1 ms with the torque reference `torque_pct` (the torque rule,
    /// [`applied_torque_pct`]: 0..=100 %, NaN as 0) to its drive, which delivers it below its
    /// speed limit.
    pub fn step_1ms(&mut self, torque_pct: f32) -> Result<(), BenchError> {
        let reference = applied_torque_pct(torque_pct);
        let over = self.state.speed_rpm - self.config.drive_speed_limit_rpm;
        let u = if over > 0.0 {
            reference * (1.0 - over / DRIVE_SPEED_LIMIT_BAND_RPM).max(0.0)
        } else {
            reference
        };
        self.delivered_pct = u;
        if self.dry_run {
            self.bench.dry_run_step(&mut self.state, u, 1e-3);
        } else {
            self.bench.step(&mut self.state, u, 1e-3, Scheme::Rk4)?;
        }
        // The transmitters' first-order lags, forward Euler at 1 ms (no `exp` on the MCU).
        let pressure = self.state_pressure();
        analog::lag_1ms(
            &mut self.pressure_seen,
            pressure,
            self.config.pressure_lag_s,
        );
        analog::lag_1ms(
            &mut self.flow_seen,
            self.state.flow_lps,
            self.config.flow_lag_s,
        );
        Ok(())
    }

    fn state_pressure(&self) -> f32 {
        // Hs = k2² Q² − c (eq. 8 inverted), without the full signal set.
        let p = self.bench.params();
        valve_pressure_mca(p.valve_k2, p.static_head_c_mca, self.state.flow_lps)
    }

    /// The bench's true signals (no transmitter).
    pub fn signals(&self) -> Signals<f32> {
        self.bench.signals(&self.state)
    }

    /// The ADC code of a transmitter on `loop_` reading `value`, or driving `forced_ma`.
    fn code(loop_: &LoopConfig, value: f32, forced_ma: Option<f32>) -> u16 {
        loop_.code(forced_ma.unwrap_or_else(|| loop_.transmitter_ma(value)))
    }

    /// The pressure transmitter's ADC code now (one noise draw).
    pub fn pressure_code(&mut self) -> u16 {
        let v = self.pressure_seen + noise(&mut self.rng) * self.config.pressure_noise_mca;
        Self::code(&self.config.pressure_loop, v, self.force_pressure_ma)
    }

    /// The flow transmitter's ADC code now (one noise draw).
    pub fn flow_code(&mut self) -> u16 {
        let v = self.flow_seen + noise(&mut self.rng) * self.config.flow_noise_lps;
        Self::code(&self.config.flow_loop, v, self.force_flow_ma)
    }
}

/// The virtual bench as a board: ADC codes from its transmitters, the torque output driving
/// it, and a simulated drive ([`VfdSim`]) answering the VFD link in-process, one tick later.
#[derive(Debug, Clone)]
pub struct VirtualIo {
    /// The bench.
    pub bench: VirtualBench,
    /// The drive's Modbus side.
    pub drive: VfdSim,
    /// `false` cuts the VFD link (the drive gets nothing, answers nothing).
    pub link_up: bool,
    torque_pct: f32,
    valve_factor: f32,
    faults: InjectedFaults,
    answer: Frame,
}

impl VirtualIo {
    /// A virtual bench with a drive at `map`; `None` for an invalid map.
    pub fn new(bench: VirtualBench, map: VfdMap) -> Option<Self> {
        Some(Self {
            bench,
            drive: VfdSim::new(map)?,
            link_up: true,
            torque_pct: 0.0,
            valve_factor: 1.0,
            faults: InjectedFaults::default(),
            answer: Frame::new(),
        })
    }

    /// The torque reference the board outputs, %.
    pub fn torque_ref_pct(&self) -> f32 {
        self.torque_pct
    }

    /// Advances the bench by 1 ms under the torque output.
    pub fn step_1ms(&mut self) -> Result<(), BenchError> {
        self.bench.step_1ms(self.torque_pct)
    }

    /// What the drive reports: the bench's speed and the torque it delivered (the
    /// reference, less what its speed limiter took).
    pub fn drive_values(&self) -> DriveValues {
        DriveValues {
            speed_rpm: self.bench.signals().speed_rpm,
            torque_pct: self.bench.delivered_torque_pct(),
        }
    }
}

impl VirtualIo {
    /// Applies the virtual bench's commands when they change: the valve as a factor of the
    /// nominal k2 (the commands' range, [`crate::types::VALVE_FACTOR_RANGE`], is the SCADA
    /// map's check; a factor the bench refuses, NaN or ≤ 0, leaves the valve as it is) and the
    /// injected faults. Unchanged commands leave the bench alone (tests set its faults
    /// directly).
    pub fn apply(&mut self, valve_factor: f32, faults: InjectedFaults) {
        // The SCADA map checks the range; an invalid factor (NaN, ≤ 0) leaves the valve.
        if valve_factor != self.valve_factor && self.bench.set_valve_factor(valve_factor).is_ok() {
            self.valve_factor = valve_factor;
        }
        if faults == self.faults {
            return;
        }
        self.faults = faults;
        self.bench.dry_run = faults.contains(InjectedFaults::DRY_RUN);
        self.bench.force_pressure_ma = faults.contains(InjectedFaults::PRESSURE_2MA).then_some(2.0);
        self.bench.force_flow_ma = faults.contains(InjectedFaults::FLOW_2MA).then_some(2.0);
        self.link_up = !faults.contains(InjectedFaults::VFD_LINK);
    }
}

impl VirtualIo {
    /// Sets the torque output, % (the torque rule, [`applied_torque_pct`]: 0..=100 %, NaN → 0).
    pub fn set_torque_ref(&mut self, pct: f32) {
        self.torque_pct = applied_torque_pct(pct);
    }
}

/// The simulated drive, in-process: it answers a request at once (taken by the next
/// [`VfdPort::receive`]); with the link cut it hears nothing.
impl VfdPort for VirtualIo {
    fn send(&mut self, frame: &[u8]) {
        if self.link_up {
            // A new request replaces an answer not yet taken, as on a half-duplex line.
            let values = self.drive_values();
            self.drive.handle(frame, &values, &mut self.answer);
        }
    }
    fn receive(&mut self, frame: &mut Frame) -> bool {
        if self.answer.is_empty() {
            return false;
        }
        core::mem::swap(frame, &mut self.answer);
        self.answer.clear();
        true
    }
}

/// The controller, its two links and the virtual bench in one process, one millisecond at a
/// time in the order the firmware's tasks run them (see [`VirtualBoard::tick`]): the host
/// tests' and the QEMU replay's board.
#[derive(Debug, Clone)]
pub struct VirtualBoard<const NP: usize, const HP: usize, const NF: usize, const HF: usize> {
    /// The real-time core.
    pub controller: Controller<NP, HP, NF, HF>,
    /// The SCADA server.
    pub scada: ScadaLink,
    /// The VFD master.
    pub vfd: VfdLink,
    /// The bench and its drive.
    pub io: VirtualIo,
}

impl<const NP: usize, const HP: usize, const NF: usize, const HF: usize>
    VirtualBoard<NP, HP, NF, HF>
{
    /// The controller, its links and a virtual bench with `bench` offsets, its drive at
    /// `config.vfd`, all at rest.
    pub fn new(
        config: &Config,
        pressure: NarmaxModel<NP, HP>,
        flow: NarmaxModel<NF, HF>,
        bench: VirtualBenchConfig,
    ) -> Result<Self, Error> {
        let bench = VirtualBench::new(bench).map_err(Error::Bench)?;
        Ok(Self {
            controller: Controller::new(config, pressure, flow)?,
            scada: ScadaLink::new(config)?,
            vfd: VfdLink::new(config.vfd)?,
            io: VirtualIo::new(bench, config.vfd).ok_or(Error::Config("VFD map"))?,
        })
    }

    /// The inputs of the next step: the codes due (see [`Controller::samples_due`]) from the
    /// bench's transmitters, the SCADA's `commands` and the VFD link's `vfd` status.
    pub fn inputs(
        controller: &Controller<NP, HP, NF, HF>,
        io: &mut VirtualIo,
        commands: Commands,
        vfd: VfdStatus,
    ) -> Inputs {
        let (p, q) = controller.samples_due();
        Inputs {
            pressure_code: if p { io.bench.pressure_code() } else { 0 },
            flow_code: if q { io.bench.flow_code() } else { 0 },
            commands,
            vfd,
        }
    }

    /// The control task's part of a millisecond: [`Controller::step`], its outputs to the
    /// bench (torque, valve, faults), the bench stepped 1 ms (publishing to SCADA and the VFD
    /// pass are the lower-priority tasks' part, [`Self::tick_with`]).
    // Always inlined (into the QEMU board's control task, its one caller on the MCU): left to
    // LLVM, a change elsewhere in the controller once moved the task's body into SysTick and
    // this function out of it, 1 254 B more flash (`cargo xtask bench`), the image over its
    // budget.
    #[inline(always)]
    pub fn control(
        controller: &mut Controller<NP, HP, NF, HF>,
        io: &mut VirtualIo,
        inputs: &Inputs,
    ) -> Result<Outputs, BenchError> {
        let out = controller.step(inputs);
        Self::after_step(io, &out)?;
        Ok(out)
    }

    /// The step's outputs to the bench (torque, valve, faults), then the bench stepped 1 ms.
    fn after_step(io: &mut VirtualIo, out: &Outputs) -> Result<(), BenchError> {
        io.set_torque_ref(out.torque_ref_pct);
        if let Some(b) = out.bench {
            io.apply(b.valve_factor, b.faults);
        }
        io.step_1ms()
    }

    /// One millisecond: the control task's part (the core's step and what [`Self::control`]
    /// does after it), then SCADA takes the published values and the VFD link its pass at the
    /// step's time with the requested torque, as the firmware's lower-priority tasks do after
    /// each control step.
    pub fn tick(&mut self) -> Result<Outputs, BenchError> {
        self.tick_with(|controller, inputs| controller.step(inputs))
    }

    /// [`Self::tick`] with the core's step made by `step` (the MCU bench times it there):
    /// the inputs gathered, `step`, then everything that follows a step, as the firmware does.
    pub fn tick_with(
        &mut self,
        step: impl FnOnce(&mut Controller<NP, HP, NF, HF>, &Inputs) -> Outputs,
    ) -> Result<Outputs, BenchError> {
        let inputs = Self::inputs(
            &self.controller,
            &mut self.io,
            self.scada.commands(),
            self.vfd.status(),
        );
        let out = step(&mut self.controller, &inputs);
        Self::after_step(&mut self.io, &out)?;
        self.scada.publish(self.controller.published());
        self.vfd
            .poll(out.t_ms, out.requested_torque_pct, &mut self.io);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analog::{AnalogInput, Status};

    #[test]
    fn transmitters_read_the_bench_within_noise_and_a_code() {
        let cfg = VirtualBenchConfig::default_offsets(3);
        let mut vb = VirtualBench::new(cfg).unwrap();
        for _ in 0..5000 {
            vb.step_1ms(50.0).unwrap();
        }
        let s = vb.signals();
        let mut p_in = AnalogInput::new(cfg.pressure_loop).unwrap();
        let mut q_in = AnalogInput::new(cfg.flow_loop).unwrap();
        let (mut p_sum, mut q_sum) = (0.0, 0.0);
        let n = 400;
        for _ in 0..n {
            let p = p_in.sample(vb.pressure_code());
            let q = q_in.sample(vb.flow_code());
            assert_eq!((p.status, q.status), (Status::Ok, Status::Ok));
            assert!(
                (p.value - s.pressure_mca).abs() < 3.5 * 0.003 + 0.004,
                "{p:?} {s:?}"
            );
            p_sum += p.value;
            q_sum += q.value;
        }
        assert!((p_sum / n as f32 - s.pressure_mca).abs() < 0.003);
        assert!((q_sum / n as f32 - s.flow_lps).abs() < 0.01);
    }

    #[test]
    fn at_rest_the_loop_saturates_without_a_fault_and_forced_currents_fault() {
        let cfg = VirtualBenchConfig::default_offsets(1);
        let mut vb = VirtualBench::new(cfg).unwrap();
        assert!(vb.signals().pressure_mca < 0.0, "Hs = -c at rest");
        let mut p_in = AnalogInput::new(cfg.pressure_loop).unwrap();
        let r = p_in.sample(vb.pressure_code());
        assert_eq!((r.status, r.value), (Status::OutOfRange, 0.0));
        vb.force_pressure_ma = Some(0.0);
        assert_eq!(p_in.sample(vb.pressure_code()).status, Status::Fault);
        vb.force_pressure_ma = Some(f32::NAN);
        assert_eq!(vb.pressure_code(), 0);
    }

    /// The drive's speed limit: a dry pump at 50 % settles near it instead of running away
    /// (it reached 6 000 rpm before), and the drive reports the torque it delivers.
    #[test]
    fn the_drive_limits_a_runaway_to_its_speed_limit() {
        let cfg = VirtualBenchConfig::default_offsets(1);
        let mut vb = VirtualBench::new(cfg).unwrap();
        vb.dry_run = true;
        for _ in 0..10_000 {
            vb.step_1ms(50.0).unwrap();
        }
        let w = vb.signals().speed_rpm;
        let limit = cfg.drive_speed_limit_rpm;
        assert!(
            w > limit && w < limit + DRIVE_SPEED_LIMIT_BAND_RPM,
            "{w} rpm"
        );
        let t = vb.delivered_torque_pct();
        assert!(t > 0.0 && t < 50.0, "delivered {t} %");
        // Wet, at 85 %, the limit takes nothing.
        let mut vb = VirtualBench::new(cfg).unwrap();
        for _ in 0..5000 {
            vb.step_1ms(85.0).unwrap();
        }
        assert_eq!(vb.delivered_torque_pct(), 85.0);
        assert!(VirtualBench::new(VirtualBenchConfig {
            drive_speed_limit_rpm: f32::NAN,
            ..cfg
        })
        .is_err());
    }

    #[test]
    fn differs_from_the_model_by_a_few_percent() {
        let mut vb = VirtualBench::new(VirtualBenchConfig::default_offsets(1)).unwrap();
        for _ in 0..5000 {
            vb.step_1ms(50.0).unwrap();
        }
        let model = WhiteBox::<f32>::paper();
        let m = model.signals(&model.steady_state(50.0).unwrap());
        let s = vb.signals();
        let ds = s.speed_rpm / m.speed_rpm - 1.0;
        let dp = s.pressure_mca / m.pressure_mca - 1.0;
        assert!(ds.abs() > 1e-3 && ds.abs() < 0.03, "speed {ds}");
        assert!(dp.abs() > 1e-3 && dp.abs() < 0.05, "pressure {dp}");
    }
}
