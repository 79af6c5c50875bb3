//! The real-time core: [`Controller::step`] once per millisecond, a pure function of its
//! state and [`Inputs`] (ADC codes, the SCADA's [`Commands`], the VFD link's [`VfdStatus`]),
//! giving [`Outputs`] (the torque reference, what SCADA publishes, the log line). It does no
//! I/O and owns no link: the SCADA server ([`crate::link::ScadaLink`]) and the VFD master
//! ([`crate::link::VfdLink`]) run apart from it (on the MCU at a lower priority) and exchange
//! these small `Copy` structs with it.
//!
//! Each step:
//! 0. the protections ([`crate::protect`]): the speed (the drive's last reading, else the
//!    observer's) against the overspeed limit, a SCADA write of mode 0 acknowledging the
//!    latched alarms and the trip, and the trip itself: while tripped (or not yet restarted
//!    after a trip) the mode is taken as stop, whatever the commanded mode;
//! 1. the torque requested by the mode ([`Mode`]: stop → 0 %, manual → the setpoint in %,
//!    profile → the paper's pulses, restarted from its seed on entry);
//! 2. the applied reference: the requested one, or the safe value 0 % while the VFD link
//!    alarm stands (the reference cannot be delivered, see [`crate::vfd`]); it goes to the
//!    torque output (DAC / PWM) and, as requested, to the VFD link;
//! 3. every pressure period (50 ms) the pressure transmitter's code, every flow period
//!    (100 ms) the flow transmitter's ([`Controller::samples_due`] says which a board must
//!    convert); each NARMAX model steps with its sample: one-step-ahead on the measurement, or
//!    free run on its own predictions while the transmitter is in fault (NAMUR NE 43, flagged
//!    on the sample that shows it); residuals (measured − predicted) for the white-box and
//!    NARMAX models;
//! 4. with each pressure sample (50 ms), the observer ([`model_core::observer`], f32) steps
//!    with the mean applied torque since the last one and takes the pressure, the flow (when
//!    it was sampled) and the VFD's speed (when a read brought a fresh one), each unless in
//!    fault; the alarms ([`model_core::monitor`]) follow;
//! 5. the white-box bench (f32, RK4) one 1 ms step with the applied reference;
//! 6. the published values (SCADA input registers) and, once a second, a [`LogLine`].
//!
//! Nothing here touches hardware, so the core runs in host tests and in the host replay of
//! the QEMU run, bit for bit.

use crate::analog::{AnalogInput, LoopConfig, Status as InputStatus, FLOW_LOOP, PRESSURE_LOOP};
use crate::protect::{Protection, ProtectionConfig, TRIP_OVERSPEED};
use crate::regulate::{
    Controlled, Regulator, CONTROL_PERIOD_MS, CONTROL_PHASE_MS, MOVING_FRACTION,
};
use crate::types::{
    Arithmetic, ControlLaw, ControlSettings, InjectedFaults, Mode, Published, Status,
};
use crate::vfd::{VfdMap, VfdReadings};
use model_core::drive_lag::DriveLagProbe;
use model_core::excitation::McuPulses;
use model_core::inertia::InertiaProbe;
use model_core::inverse::Load;
use model_core::monitor::{Monitor, MonitorConfig, MonitorInputs};
use model_core::narmax::adapt::OutputMap;
use model_core::narmax::mcu::{NarxF32, NarxF32State, NarxQ15, NarxQ15State, MAX_PERIOD_MS};
use model_core::narmax::{NarmaxError, NarmaxOutput, Predictor, Scaling};
use model_core::observer::{
    Measurements, Observer, ObserverConfig, ObserverError, PAPER_PRESSURE_LAG_SD_S,
};
use model_core::{BenchError, BenchState, Real, Scheme, Signals, WhiteBox};

/// Step period, ms: one [`Controller::step`].
pub const TICK_MS: u32 = 1;
/// A log line every this many ms.
pub const LOG_EVERY_MS: u32 = 1000;
/// The protections use the drive's speed reading up to this age, ms; older (reads failing),
/// the observer's speed.
pub const DRIVE_READING_FRESH_MS: u32 = 100;

/// The observer's pressure stands in for a pressure transmitter in fault (mode 3) only while
/// its standard deviation is at most this fraction of the setpoint (5 %; and at least
/// [`VIRTUAL_PRESSURE_MIN_SD_MCA`]): else the loop holds its last torque and alarms. Measured
/// with `pumpbench control` (the transmitter lost at 3 mca, then the valve ×1.3;
/// docs/control.md): right after the valve step the observer's σ rises over it for ≈ 0.5 s
/// while its k2 converges; at 0.05 mca (1.7 %) it stayed over it for seconds, and the held
/// torque left the pressure 23 % high. The σ is the observer's own: on a plant whose curves
/// differ from the model's in shape, not only in scale, it can be small and wrong
/// (docs/control.md, Limits).
pub const VIRTUAL_PRESSURE_MAX_SD_FRACTION: f32 = 0.05;

/// The least standard deviation [`VIRTUAL_PRESSURE_MAX_SD_FRACTION`] allows, mca (3 ADC codes
/// of the bench's 0..10 mca loop): at a setpoint near 0 the observer is still usable.
pub const VIRTUAL_PRESSURE_MIN_SD_MCA: f32 = 0.01;

/// A mode switch (and the VFD link's return) moves the torque at the loop's rate (holding
/// register 12) or at this one, %/s, the faster: a stop takes at most 2 s from 100 %, whatever
/// the loop's rate.
pub const SWITCH_RATE_MIN_PCT_PER_S: f32 = 50.0;

/// A failed white-box step shows in status bit 1 (any alarm) for this long, ms.
pub const MODEL_FAULT_SHOWN_MS: u32 = 2000;
/// The largest static head the models take, either sign, mca ([`Commands::static_head_mca`];
/// holding register 20 in 0.001 mca).
pub const STATIC_HEAD_MAX_MCA: f32 = 10.0;

/// Holding register 20's default as the core takes it, mca: the paper's static head, −c
/// (−0.252). While register 20 holds it the controller learns the system's own
/// (`LiftProbe`); any other value written stands.
pub const STATIC_HEAD_DEFAULT_MCA: f32 = -model_core::BenchParams::<f32>::PAPER.static_head_c_mca;
/// Control periods a model-law loop holds one setpoint before its readings count as a
/// settled operating point (1 s): the readings' means over its two halves within
/// [`LIFT_STEADY_FRACTION`] of each other (a flow meter damped longer than the pressure loop
/// settles still moves), and the controlled reading within [`MOVING_FRACTION`] of the
/// setpoint at the check (a loop held off it at a torque limit or the speed cap is not in
/// control: random valve moves during moves, paired with such points, taught a lift of
/// 1.0 mca on a bench with none). Means, not single readings within 2 % of the setpoint as
/// before: a transmitter's noise of 1 % of a low setpoint took single readings off that
/// band every few periods (a judge's plant with 0.01 mca of noise never settled at 1 mca,
/// and its lift was never learnt); a mean's noise is a tenth of a reading's.
pub const LIFT_SETTLED_PERIODS: u16 = 200;
/// How far a settled point's readings (the pressure, the flow squared), averaged over each
/// half of [`LIFT_SETTLED_PERIODS`], may move from one half to the next, as a fraction of
/// themselves; and how far the readings since the last check may be from the settled
/// point's when the setpoint moves, for the point to pair with the next (a valve moved
/// since: a review's valve × 1.1 0.3 s before each move taught 0.44 mca on a bench with
/// none). (At 5 % for the flow squared, a flow meter lagging 0.5..1 s, still closing on its
/// reading, taught lifts 0.13..0.33 mca low: a review.)
pub const LIFT_STEADY_FRACTION: f32 = 0.01;
/// The least flow squared a settled point needs, (l/s)² (1 l/s): under a lift no water
/// moves, and the pressure then tells nothing of the system curve.
pub const LIFT_MIN_FLOW_SQ: f32 = 1.0;
/// The least pressure reading a settled point needs, mca: a transmitter at the floor of its
/// span reads 0 whatever the system asks below it (a review: c = 0.081 mca learnt from a
/// reading clamped at 0 at 3 l/s on the paper's bench, whose pressure there is −0.15).
pub const LIFT_MIN_PRESSURE_MCA: f32 = 0.1;
/// The smallest spread of the squared flows, and of the pressures, of two settled points that
/// gives a static head: this fraction of the larger (at less, noise or a valve's move between
/// them would dominate the slope).
pub const LIFT_MIN_SPREAD: f32 = 0.2;
/// The static heads c a pair may give, mca (−10..=1: a lift of up to 10 mca); outside, the
/// pair is no system curve of one valve (the valve moved between them).
pub const LIFT_C_RANGE: (f32, f32) = (-STATIC_HEAD_MAX_MCA, 1.0);
/// How close two pairs in a row must agree on the static head for it to be taken, mca
/// (`LiftProbe::agrees`).
pub const LIFT_AGREEMENT_MCA: f32 = 0.1;
/// How far a pair's static head must be from the one held to be taken, mca: single readings
/// put the pairs within ±0.015 mca of the paper's bench's c (the means closer), and within
/// it nothing changes (a lift under ≈ 0.35 mca is not learnt; it moves the loops' figures
/// little).
pub const LIFT_DEAD_BAND_MCA: f32 = 0.1;

/// Learns the system's static head c (eq. (8) at the pressure transmitter: `p = k2² Q² − c`)
/// from two settled operating points of the model law's loops either side of a setpoint
/// move, the pressure and the flow both measured: the system curve through them, if the
/// valve stayed. The observer cannot: at one operating point a lift and a valve give the
/// same readings. The pump's curves do not enter: the pair is the system's. A pair is made
/// only with the point confirmed just before the move: a control period not fed (a stop, a
/// trip, a VFD link cut, a transmitter in fault, the PI alone), a move from a setpoint not
/// confirmed, or a move after the readings left the point forgets it (the valve may have
/// moved meanwhile); a pair's head is taken once the next agrees ([`LiftProbe::agrees`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LiftProbe {
    /// The time of the last period fed, ms, modulo 2¹⁶ (a gap of a multiple of 327.68 s
    /// passes for none; the struct stays 36 bytes: 8 more moved the fields of the controller
    /// and cost every 1 ms step ≈ 10 instructions on the M4, `cargo xtask bench`).
    fed_ms: u16,
    /// The periods since the last check.
    settled: u8,
    /// The anchor is of the setpoint held now (false: of the one before the last move).
    here: bool,
    /// The setpoint of the points being settled at.
    setpoint: f32,
    /// Since the last check, the sums of the pressure (mca) and the flow squared ((l/s)²).
    sums: (f32, f32),
    /// The pressure (mca) and the flow squared ((l/s)²) averaged over the half before the
    /// last check (NaN at the first after a setpoint's change: the second check, half a
    /// settling later, is the first that can hold).
    mid: (f32, f32),
    /// The last settled point: its pressure and flow squared (NaN: none).
    anchor: (f32, f32),
    /// The static head the last pair gave, mca (NaN: none yet; [`LiftProbe::agrees`]).
    pending: f32,
}

impl LiftProbe {
    const NEW: Self = Self {
        fed_ms: 0,
        settled: 0,
        here: false,
        setpoint: f32::NAN,
        sums: (0.0, 0.0),
        mid: (f32::NAN, f32::NAN),
        anchor: (f32::NAN, f32::NAN),
        pending: f32::NAN,
    };

    /// One control period at `now_ms` and `setpoint`, with the readings `p` (mca) and `q`
    /// (l/s), `off` the setpoint less the controlled reading: the static head c (mca) a pair
    /// of settled points gives, once, as the loop settles at a setpoint other than the last
    /// settled point's. Every half of [`LIFT_SETTLED_PERIODS`] at one setpoint the readings'
    /// means over it are checked against the last half's, and taken as the anchor while
    /// they hold.
    #[inline(never)]
    fn period(&mut self, now_ms: u32, setpoint: f32, off: f32, p: f32, q: f32) -> Option<f32> {
        const HALF: u8 = (LIFT_SETTLED_PERIODS / 2) as u8;
        let now = now_ms as u16;
        let gap = now.wrapping_sub(self.fed_ms) != CONTROL_PERIOD_MS as u16;
        self.fed_ms = now;
        let moved = setpoint != self.setpoint;
        // The anchor pairs only with the point confirmed just before the move (the anchor at
        // the setpoint the loop leaves, the readings since its check still on it): it is
        // dropped on a gap, on a move from a setpoint not confirmed (a move before the last
        // one settled), and on a move after the readings left it (a valve moved: the point
        // after it is confirmed afresh). (A review: pairs with a point 16 s old, or from
        // before a valve's step, learnt lifts of 1.3..1.7 mca on a bench with none.) (The
        // anchor's pressure NaN: no pair with it; no reading since the check: it holds.)
        if gap || (moved && !(self.here && self.still_at_anchor())) {
            self.anchor.0 = f32::NAN;
        }
        if gap || moved {
            // (The last half's mean NaN: the next check does not hold.)
            (self.setpoint, self.settled, self.mid.0) = (setpoint, 0, f32::NAN);
            self.sums = (0.0, 0.0);
            // After a move the anchor, if kept, is of the setpoint before it.
            self.here &= !moved;
            return None;
        }
        self.sums.0 += p;
        self.sums.1 += q * q;
        self.settled += 1;
        if self.settled < HALF {
            return None;
        }
        // Every half a settling from here on: the means against the last check's.
        self.settled = 0;
        let n = 1.0 / f32::from(HALF);
        let (p, q2) = core::mem::replace(&mut self.sums, (0.0, 0.0));
        let (p, q2) = (p * n, q2 * n);
        let (p1, q21) = core::mem::replace(&mut self.mid, (p, q2));
        if !((p - p1).abs() <= LIFT_STEADY_FRACTION * p
            && (q2 - q21).abs() <= LIFT_STEADY_FRACTION * q2
            && q2 >= LIFT_MIN_FLOW_SQ
            && p >= LIFT_MIN_PRESSURE_MCA
            && off.abs() <= MOVING_FRACTION * setpoint)
        {
            // Still moving (a flow meter damped longer than the loop settles), no flow, a
            // pressure at the transmitter's floor, or a loop held off its setpoint.
            return None;
        }
        let before = !core::mem::replace(&mut self.here, true);
        let (p0, q20) = core::mem::replace(&mut self.anchor, (p, q2));
        let dq2 = q2 - q20;
        let k = (p - p0) / dq2;
        let c = k * q2 - p;
        // (No anchor yet: NaN, and every comparison below false.)
        // Both apart: the flows (the slope's divisor) and the pressures (a setpoint nudged
        // with a valve's step gave a flat slope, a lift near the setpoint: a review).
        (before
            && dq2.abs() > LIFT_MIN_SPREAD * Real::max(q2, q20)
            && (p - p0).abs() > LIFT_MIN_SPREAD * Real::max(p, p0)
            && k > 0.0
            && c >= LIFT_C_RANGE.0
            && c <= LIFT_C_RANGE.1)
            .then_some(c)
    }

    /// Whether the readings since the last check (their sums over `settled` periods) are
    /// within [`LIFT_STEADY_FRACTION`] of the anchor's, each (none since the check: they
    /// are; no anchor, NaN: they are not, and it stays none). Called only at a move.
    fn still_at_anchor(&self) -> bool {
        let k = f32::from(self.settled);
        (self.sums.0 - k * self.anchor.0).abs() <= LIFT_STEADY_FRACTION * self.sums.0
            && (self.sums.1 - k * self.anchor.1).abs() <= LIFT_STEADY_FRACTION * self.sums.1
    }

    /// A pair's static head `c` (mca) is taken only when the pair before it gave one within
    /// [`LIFT_AGREEMENT_MCA`]: a valve that moves during a setpoint move (before the second
    /// point settles) cannot be told from a lift by one pair (a review: a valve × 1.3 0.8 s
    /// into a 3.9 → 2.7 mca move taught a lift of 1.8 mca on a bench with none, and the later
    /// steps overshot up to 84 %); two such coincidences agreeing are unlikely. `c` becomes
    /// the pair before the next.
    fn agrees(&mut self, c: f32) -> bool {
        (c - core::mem::replace(&mut self.pending, c)).abs() <= LIFT_AGREEMENT_MCA
    }
}

/// How far the observer takes its pressure transmitter's lag (`lag_s`,
/// `ObserverConfig::pressure_lag_s`, 20 ms) to be off, s (1 σ): the plant's lag the pressure
/// loop measured beyond it (`measured_s`, [`Controller::measured_lag_s`]), at least the
/// 40 ms of `ObserverConfig::paper` ([`PAPER_PRESSURE_LAG_SD_S`]). Behind a transmitter much
/// slower than the observer's, the observer read the reading's delay as the valve moving
/// (its k2 over 10 % off during a setpoint step): the loop's probe took its lesson for a
/// valve step and undid it, and the feedforward carried a wrong load. With the uncertainty
/// it weighs a moving reading less, so its k2 stays put through the step. The observer's
/// lag itself is not changed: the probe's estimate moves during a step, and a lag changed
/// mid-step settled some first steps later than the PI alone; nor is it taken from
/// register 15, which also holds the drive's and other lags the observer models apart
/// (docs/control.md, Limits).
pub fn observer_pressure_lag_sd_s(measured_s: f32, lag_s: f32) -> f32 {
    (measured_s - lag_s).max(PAPER_PRESSURE_LAG_SD_S as f32)
}

/// One 1 ms white-box step with the applied torque `u` (finite, 0..=100 %); `false` if it
/// failed, which can only mean a diverged state: the step leaves it unchanged, so it would
/// fail on every step after (the fault latched forever). The model restarts at its steady
/// state for `u` instead.
#[inline]
fn step_or_restart(whitebox: &WhiteBox<f32>, state: &mut BenchState<f32>, u: f32) -> bool {
    if whitebox
        .step(state, u, TICK_MS as f32 * 1e-3, Scheme::Rk4)
        .is_ok()
    {
        return true;
    }
    if let Ok(rest) = whitebox.steady_state(u) {
        *state = rest;
    }
    false
}

/// Configuration of the controller and its links.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Pressure transmitter loop (mca at 4 and 20 mA).
    pub pressure_loop: LoopConfig,
    /// Flow transmitter loop (l/s at 4 and 20 mA).
    pub flow_loop: LoopConfig,
    /// VFD register map and link settings.
    pub vfd: VfdMap,
    /// SCADA unit address (1..=247).
    pub scada_unit: u8,
    /// Seed of the built-in excitation profile (mode 2).
    pub profile_seed: u64,
    /// Mode at start-up.
    pub initial_mode: Mode,
    /// Torque setpoint at start-up, % (0..=100; the SCADA register holds it to 0.01 %).
    pub initial_setpoint_pct: f32,
    /// NARMAX arithmetic at start-up.
    pub initial_arithmetic: Arithmetic,
    /// The NARMAX models follow the load from start-up (holding register 19 at 1).
    pub initial_narmax_adapt: bool,
    /// The board has a virtual bench: SCADA holding registers 3 (valve) and 4 (fault
    /// injection) exist and are handed on in [`Outputs::bench`] every step.
    pub virtual_bench: bool,
    /// The protections at start-up (SCADA holding registers 5..=7).
    pub protection: ProtectionConfig,
}

impl Config {
    /// The bench's transmitters (pressure 0..10 mca, flow 0..30 l/s: [`PRESSURE_LOOP`],
    /// [`FLOW_LOOP`]), the [`VfdMap::example_16384`] drive, SCADA unit 1, profile seed 1,
    /// stopped, NARMAX in f32 and not following the load, no virtual bench.
    pub const fn bench() -> Self {
        Self {
            pressure_loop: PRESSURE_LOOP,
            flow_loop: FLOW_LOOP,
            vfd: VfdMap::example_16384(),
            scada_unit: 1,
            profile_seed: 1,
            initial_mode: Mode::Stop,
            initial_setpoint_pct: 0.0,
            initial_arithmetic: Arithmetic::F32,
            initial_narmax_adapt: false,
            virtual_bench: false,
            protection: ProtectionConfig::DEFAULT,
        }
    }
}

/// Why the controller or a link could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Error {
    /// A configuration value is out of range; the text says which.
    Config(&'static str),
    /// The white-box bench refused its parameters.
    Bench(BenchError),
    /// A NARMAX model could not be quantised.
    Narmax(NarmaxError),
    /// The observer refused its configuration.
    Observer(ObserverError),
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Config(what) => write!(f, "bad configuration: {what}"),
            Error::Bench(e) => write!(f, "white-box bench: {e}"),
            Error::Narmax(e) => write!(f, "NARMAX model: {e}"),
            Error::Observer(e) => write!(f, "{e}"),
        }
    }
}

/// One NARMAX model in both arithmetics (compile-time data, `pumpbench export`), with the
/// history of each: `F` frames, `H` hidden units.
#[derive(Debug, Clone)]
pub struct NarmaxModel<const F: usize, const H: usize> {
    float: &'static NarxF32<F, H>,
    q15: &'static NarxQ15<F, H>,
    st: NarxF32State<F>,
    st_q: NarxQ15State<F>,
    period_ms: u32,
    last: f32,
    follow: Follow,
}

/// A model following the load: its output map while on, the measurement it takes next, and
/// its fallback's alarm. Apart from the generic [`NarmaxModel`] and out of line, so that both
/// models share one copy of its code.
#[derive(Debug, Clone)]
struct Follow {
    /// The model's output scaling (its training's), for the map.
    scaling: Scaling<f32>,
    /// The model's sample period, s.
    period_s: f32,
    /// The map, while following (built when turned on: forgotten when turned off).
    map: Option<OutputMap<f32>>,
    /// The last sample's (network output, measurement), for [`Self::settle`].
    pending: Option<(f32, f32)>,
    /// Samples left during which the map's last fallback shows as the model-residual alarm.
    fallback_left: u16,
    /// [`Commands::narmax_adapt_offs`] at the last sample.
    offs_seen: u16,
}

impl Follow {
    /// Not following, for a model with this output `scaling` sampled every `period_s`.
    fn new(scaling: Scaling<f32>, period_s: f32) -> Self {
        Self {
            scaling,
            period_s,
            map: None,
            pending: None,
            fallback_left: 0,
            offs_seen: 0,
        }
    }

    /// One sample of the network's free-run output `network`: the adapted output while `on`;
    /// `in_span` waits for [`Self::settle`]. Turned on, the map starts at the identity;
    /// turned off (or `offs`, the count of register 19's writes of 0, changed since the last
    /// sample: a 0 however soon followed by a 1), it is forgotten. Out of line, and called on
    /// every sample, so that the 1 ms step holds only the call.
    #[inline(never)]
    fn sample(&mut self, on: bool, offs: u16, network: f32, in_span: Option<f32>) -> f32 {
        if !on || offs != self.offs_seen {
            self.forget();
            self.offs_seen = offs;
            if !on {
                return network;
            }
        }
        self.fallback_left = self.fallback_left.saturating_sub(1);
        if self.map.is_none() {
            // Never refused for a model built by model-core: its output's std is checked
            // finite and > 0 when it is built, its period is 1..=1000 ms, the memory a
            // constant in range. (Refused, the model would run free as identified.)
            self.map = OutputMap::new(self.scaling, self.period_s, ADAPT_TAU_S).ok();
        }
        self.pending = in_span.map(|m| (network, m));
        self.map.as_ref().map_or(network, |m| m.output(network))
    }

    /// The map, the reading waiting and the fallback's alarm forgotten.
    fn forget(&mut self) {
        (self.map, self.pending, self.fallback_left) = (None, None, 0);
    }

    /// The map takes the last sample's measurement, on the tick after it (the sample's tick
    /// also runs the observer: the update kept out of the longest tick); nothing if following
    /// was turned `off` since.
    #[inline(never)]
    fn settle(&mut self, on: bool) {
        let pending = self.pending.take().filter(|_| on);
        if let (Some(map), Some((network, m))) = (&mut self.map, pending) {
            if map.update(network, m).diverged {
                self.fallback_left = ADAPT_FALLBACK_SHOWN_SAMPLES;
            }
        }
    }
}

/// The output map's memory, s ([`model_core::narmax::adapt`]): long against the bench's
/// time constants (0.2..0.7 s), so the map cannot stand in for the network's dynamics; short
/// against a valve's move being followed (segments of the records settle within it).
pub const ADAPT_TAU_S: f32 = 2.0;

/// How long a fallback of the output map shows as the model-residual alarm, samples.
pub const ADAPT_FALLBACK_SHOWN_SAMPLES: u16 = 60;

impl<const F: usize, const H: usize> NarmaxModel<F, H> {
    /// The model sampled every `period_ms` ms (1..=[`MAX_PERIOD_MS`], the firmware's rule for a
    /// model's period, `model_core::narmax::mcu::firmware_period_ms`); `float` and `q15` are the same model's two passes (both made by
    /// `pumpbench export`).
    pub fn new(
        float: &'static NarxF32<F, H>,
        q15: &'static NarxQ15<F, H>,
        period_ms: u32,
    ) -> Result<Self, Error> {
        if !(1..=MAX_PERIOD_MS).contains(&period_ms) {
            return Err(Error::Config("NARMAX period must be 1..=1000 ms"));
        }
        let (u0, y0) = (0.0, float.output_mean());
        Ok(Self {
            st: float.state_at(u0, y0),
            st_q: q15.state_at(u0, y0),
            float,
            q15,
            period_ms,
            last: y0,
            follow: Follow::new(float.output_scaling(), period_ms as f32 * 1e-3),
        })
    }

    /// Sample period, ms.
    pub fn period_ms(&self) -> u32 {
        self.period_ms
    }

    /// Fills the history of `arith` with `(u, y)`.
    fn reseed(&mut self, arith: Arithmetic, u: f32, y: f32) {
        match arith {
            Arithmetic::F32 => self.st = self.float.state_at(u, y),
            Arithmetic::Q15 => self.st_q = self.q15.state_at(u, y),
        }
        self.last = y;
    }

    /// One sample: one-step-ahead with a measurement, free run without.
    fn step(&mut self, arith: Arithmetic, u: f32, measured: Option<f32>) -> NarmaxOutput<f32> {
        let out = match arith {
            Arithmetic::F32 => self.float.step(&mut self.st, u, measured),
            Arithmetic::Q15 => self.q15.step(&mut self.st_q, u, measured),
        };
        self.last = out.y;
        out
    }

    /// The sample's output `y` of a free run through the output map while register 19 says
    /// so ([`Follow::sample`]; `in_span`: the reading, if inside its span, that the map takes
    /// on the next tick).
    #[inline(always)]
    fn follow(&mut self, c: &Commands, y: f32, in_span: Option<f32>) -> f32 {
        self.follow
            .sample(c.narmax_adapt, c.narmax_adapt_offs, y, in_span)
    }
}

/// A line of the once-a-second log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogLine {
    /// Loop time, ms.
    pub t_ms: u32,
    /// Mode.
    pub mode: Mode,
    /// NARMAX arithmetic.
    pub arithmetic: Arithmetic,
    /// What the controller publishes.
    pub values: Published,
}

/// The names of [`LogLine::fields`], in their order (unit in the name).
const LOG_FIELD_NAMES: [&str; 16] = [
    "u_pct", "p_mca", "q_lps", "wb_rpm", "wb_p", "wb_q", "nx_p", "nx_q", "res_wb_p", "res_wb_q",
    "res_nx_p", "res_nx_q", "vfd_rpm", "ob_rpm", "ob_q", "ob_k2",
];

impl LogLine {
    /// The line's values, each with its name (unit in the name), in the order they are
    /// logged: torque, measured, white-box and NARMAX values, residuals, the drive's speed and
    /// the observer's estimates.
    pub fn fields(&self) -> [(&'static str, f32); 16] {
        let v = self.values();
        core::array::from_fn(|i| (LOG_FIELD_NAMES[i], v[i]))
    }

    /// The values of [`Self::fields`] without their names (what the defmt line sends: the
    /// names are in its format string).
    pub fn values(&self) -> [f32; 16] {
        let v = &self.values;
        [
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
            v.observer_speed_rpm,
            v.observer_flow_lps,
            v.observer_valve_k2,
        ]
    }
}

/// The line as defmt sends it: `t_s=3 mode=manual narmax=f32 u_pct=50.0 p_mca=… alarms=0
/// status=9`. The values travel as f32 bits; the host prints them in their shortest exact
/// form (`ryu`, as defmt's decoder does), so the QEMU check compares every bit.
#[cfg(feature = "defmt")]
impl defmt::Format for LogLine {
    fn format(&self, f: defmt::Formatter) {
        // One format string (interned: only the values travel), the names of
        // [`LogLine::fields`] in their order; the QEMU check rebuilds the line from them.
        // (`values`, not `fields`: the names' pointers were built on the stack for nothing,
        // ≈ 0.3 KB of flash.)
        let [u, p, q, wb_rpm, wb_p, wb_q, nx_p, nx_q, r_wb_p, r_wb_q, r_nx_p, r_nx_q, vfd, ob_rpm, ob_q, ob_k2] =
            self.values();
        defmt::write!(
            f,
            "t_s={=u32} mode={=str} narmax={=str} u_pct={=f32} p_mca={=f32} q_lps={=f32} wb_rpm={=f32} wb_p={=f32} wb_q={=f32} nx_p={=f32} nx_q={=f32} res_wb_p={=f32} res_wb_q={=f32} res_nx_p={=f32} res_nx_q={=f32} vfd_rpm={=f32} ob_rpm={=f32} ob_q={=f32} ob_k2={=f32} alarms={=u16} status={=u16}",
            self.t_ms / 1000,
            self.mode.name(),
            self.arithmetic.name(),
            u, p, q, wb_rpm, wb_p, wb_q, nx_p, nx_q, r_wb_p, r_wb_q, r_nx_p, r_nx_q, vfd, ob_rpm, ob_q, ob_k2,
            self.values.alarms,
            self.values.status
        );
    }
}

/// What the SCADA holding registers ask of the controller, in the core's units (decoded by
/// [`crate::scada::ScadaSlave::commands`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Commands {
    /// Mode.
    pub mode: Mode,
    /// Torque setpoint, % (0..=100, finite; the torque requested in manual mode).
    pub setpoint_pct: f32,
    /// NARMAX arithmetic.
    pub arithmetic: Arithmetic,
    /// The NARMAX models follow the load (holding register 19): each runs free and an affine
    /// map of its output is fitted to the measurements ([`model_core::narmax::adapt`]);
    /// `false`: one-step-ahead on the measurements.
    pub narmax_adapt: bool,
    /// Writes of 0 to holding register 19 so far (wraps): a change forgets the maps, however
    /// soon a 1 follows (a 0 held for less than a sample would not be seen otherwise).
    pub narmax_adapt_offs: u16,
    /// Virtual bench valve, × nominal k2 ([`crate::types::VALVE_FACTOR_RANGE`]).
    pub valve_factor: f32,
    /// Faults injected into the virtual bench.
    pub faults: InjectedFaults,
    /// Writes of mode 0 (stop) so far (wraps): a change acknowledges the latched alarms
    /// and a trip.
    pub stop_writes: u16,
    /// Writes of the manual setpoint so far (wraps): a change releases manual mode's hold of
    /// the torque an automatic mode had (even a write of the value already there).
    pub setpoint_writes: u8,
    /// The protections (holding registers 5..=7).
    pub protection: ProtectionConfig,
    /// The pressure and flow loops' settings (holding registers 8..=18).
    pub control: ControlSettings,
    /// The system's static head as the models take it, mca (holding register 20,
    /// ±[`STATIC_HEAD_MAX_MCA`]): the pressure the system curve asks at no flow, `−c` of
    /// eq. (8) (the paper's bench −0.252; a lift is positive). A write (of any value:
    /// [`Commands::static_head_writes`]) moves the white-box bench's, the observer's
    /// ([`Observer::set_static_head`]) and the loops' model (bumpless); a value outside the
    /// range (or not finite) is refused, the models keep theirs. While it holds its default
    /// ([`STATIC_HEAD_DEFAULT_MCA`]) the controller learns the system's own from the model
    /// law's settled points (`LiftProbe`); a write of the default starts that afresh.
    pub static_head_mca: f32,
    /// Writes of holding register 20 so far (wraps).
    pub static_head_writes: u8,
}

/// What the VFD link last established (see [`crate::vfd::VfdMaster`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VfdStatus {
    /// The link alarm: the torque reference cannot be delivered; 0 % is applied.
    pub link_alarm: bool,
    /// The drive's readings; `None` while they are invalid (reads fail).
    pub readings: Option<VfdReadings>,
    /// Successful reads so far (wraps): a change means fresh readings.
    pub reads_ok: u32,
}

impl VfdStatus {
    /// Before the link has answered: in alarm, no readings.
    pub const START: Self = Self {
        link_alarm: true,
        readings: None,
        reads_ok: 0,
    };

    /// The torque reference applied for a requested one, %: 0 during the link alarm (and
    /// for NaN), else the request clamped to 0..=100 ([`crate::vfd::applied_torque_pct`]).
    pub fn applied_torque_pct(&self, requested_pct: f32) -> f32 {
        crate::vfd::applied_torque_pct(self.link_alarm, requested_pct)
    }
}

/// The inputs of one [`Controller::step`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Inputs {
    /// Raw ADC code of the pressure transmitter's shunt; read only when
    /// [`Controller::samples_due`] says so (any value otherwise).
    pub pressure_code: u16,
    /// Raw ADC code of the flow transmitter's shunt; as `pressure_code`.
    pub flow_code: u16,
    /// The SCADA's holding registers.
    pub commands: Commands,
    /// The VFD link's state.
    pub vfd: VfdStatus,
}

/// A virtual bench's settings (from SCADA's holding registers 3 and 4).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BenchCommands {
    /// Valve, × nominal k2 ([`crate::types::VALVE_FACTOR_RANGE`]).
    pub valve_factor: f32,
    /// Injected faults.
    pub faults: InjectedFaults,
}

/// The outputs of one [`Controller::step`]. What the SCADA input registers publish is
/// [`Controller::published`], read after the step: not copied here (the copy was ≈ 64
/// instructions of every 1 ms step on the M4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outputs {
    /// Step time, ms (wraps after 49 days).
    pub t_ms: u32,
    /// The applied torque reference, % (0..=100): the analog output's.
    pub torque_ref_pct: f32,
    /// The requested torque reference, %: what the VFD link writes (it substitutes 0 % by
    /// itself while in alarm).
    pub requested_torque_pct: f32,
    /// The virtual bench's settings; `None` on a board without one.
    pub bench: Option<BenchCommands>,
    /// Once a second, the log line.
    pub log: Option<LogLine>,
}

/// The controller: models, observer, alarms and the 4-20 mA inputs, stepped every 1 ms.
#[derive(Debug, Clone)]
pub struct Controller<const NP: usize, const HP: usize, const NF: usize, const HF: usize> {
    whitebox: WhiteBox<f32>,
    wb: BenchState<f32>,
    pressure: NarmaxModel<NP, HP>,
    flow: NarmaxModel<NF, HF>,
    arithmetic: Arithmetic,
    pressure_in: AnalogInput,
    flow_in: AnalogInput,
    profile_seed: u64,
    profile: Option<McuPulses>,
    t_ms: u32,
    /// How long the white-box model's last failed step still shows as an alarm, ms.
    model_fault_ms: u32,
    wb_extrapolating: bool,
    nx_clamped: [bool; 2],
    /// [`model_core::monitor::MODEL_RESIDUAL`] while a NARMAX output map's fallback shows,
    /// else 0 (set on the models' samples, added to the alarm bits every step).
    adapt_alarm: u16,
    /// A model sampled with its output map on (or its alarm showing): the maps settle on the
    /// next step.
    follow_due: bool,
    observer: Observer<f32>,
    monitor: Monitor<f32>,
    /// The rotor's inertia, measured on the drive's readings as the monitor takes them.
    inertia: InertiaProbe<f32>,
    /// Its factor, × the paper's J, as of the last drive reading.
    inertia_factor: f32,
    /// The drive's speed reading's lag it measured, s, as of the last drive reading.
    speed_lag_s: f32,
    /// The drive's torque lag, measured on its torque readings against the references sent
    /// (the readings taken on the loops' control ticks), and [`VfdStatus::reads_ok`] at the
    /// last reading it took.
    drive_lag: DriveLagProbe<f32>,
    drive_lag_reads: u32,
    /// Applied torque summed since the last observer step, % · ticks, and the ticks.
    torque_sum: f32,
    torque_ticks: u32,
    /// [`VfdStatus::reads_ok`] at the last observer step.
    vfd_reads_seen: u32,
    /// [`Commands::stop_writes`] last acknowledged.
    stop_writes_seen: u16,
    /// The overspeed limit last handed to the monitor, rpm (0: none yet).
    overspeed_set_rpm: u16,
    /// The speed the protection checked this step, rpm.
    protect_speed_rpm: f32,
    protection: Protection,
    /// The torque is held at 0 % this step (tripped, or not yet restarted).
    hold: bool,
    /// [`VfdStatus::reads_ok`] seen by the protections, and the step it changed at.
    protect_reads: (u32, u32),
    virtual_bench: bool,
    out: Published,
    /// The pressure or flow loop (modes 3 and 4), from its first control period on.
    regulator: Option<Regulator>,
    /// The plant's lag beyond the model each loop took last (pressure, flow), s: measured on
    /// its setpoint steps or raised by its ring watch; kept across the loops' restarts (a mode
    /// switch, a law change).
    measured_lag_s: [f32; 2],
    /// The mode acted on at the last step (stop while held); `None` before the first.
    last_mode: Option<Mode>,
    /// The loops' law at the last step.
    last_law: ControlLaw,
    /// Manual mode entered from a running automatic mode: the torque held then, and the
    /// count of manual setpoint writes then ([`Commands::setpoint_writes`]: a write, of any
    /// value, ends the hold).
    manual_hold: Option<(f32, u8)>,
    /// [`Commands::setpoint_writes`] as the last step saw it: a write that came with the
    /// switch into manual (the same frame, one multi-register write) ends the hold at once.
    setpoint_writes_seen: u8,
    /// The mode acts in closed loop (the last step's): the next control ticks sample.
    regulating: bool,
    /// After a mode switch, the torque moves from the last applied one toward the new mode's
    /// at the rate limit until it gets there.
    transfer: bool,
    /// The applied torque of the last step, %.
    last_applied_pct: f32,
    /// The requested torque of the last step, %.
    last_requested_pct: f32,
    /// The VFD link was in alarm at the last step.
    link_was_down: bool,
    /// The link came back: the loop resumes at its next control tick.
    resume: bool,
    /// The observer's last estimate, as the loops use it.
    view: LoopView,
    /// The loop's flags this step: acting on the observer's value, holding for lack of one.
    virtual_measurement: bool,
    control_held: bool,
    /// Holding register 20 as last taken: its value, mca, and its writes
    /// ([`Commands::static_head_mca`], [`Commands::static_head_writes`]).
    static_head_set: (f32, u8),
    /// Learns the static head while register 20 holds its default.
    lift: LiftProbe,
}

/// What the loops take from the observer's last estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LoopView {
    load: Load<f32>,
    speed_rpm: f32,
    flow_lps: f32,
    pressure_mca: f32,
    pressure_sd_mca: f32,
}

impl<const NP: usize, const HP: usize, const NF: usize, const HF: usize>
    Controller<NP, HP, NF, HF>
{
    /// The controller with the paper's white-box bench and the two NARMAX models, at rest.
    #[inline(never)]
    pub fn new(
        config: &Config,
        pressure: NarmaxModel<NP, HP>,
        flow: NarmaxModel<NF, HF>,
    ) -> Result<Self, Error> {
        if !flow.period_ms.is_multiple_of(pressure.period_ms) {
            // The observer steps with each pressure sample and takes the flow sampled on
            // that tick: a flow period off the pressure period's multiples would skip flow
            // readings without a word.
            return Err(Error::Config(
                "the flow period must be a whole multiple of the pressure period",
            ));
        }
        if !config.protection.is_valid() {
            return Err(Error::Config("protection settings out of range"));
        }
        let pressure_in =
            AnalogInput::new(config.pressure_loop).ok_or(Error::Config("pressure loop"))?;
        let flow_in = AnalogInput::new(config.flow_loop).ok_or(Error::Config("flow loop"))?;
        let observer = Observer::new(ObserverConfig::paper(), 0.0).map_err(Error::Observer)?;
        let whitebox = WhiteBox::<f32>::paper();
        let wb = whitebox.steady_state(0.0).map_err(Error::Bench)?;
        let paper_k2 = whitebox.params().valve_k2;
        let mut c = Self {
            whitebox,
            wb,
            pressure,
            flow,
            arithmetic: Arithmetic::F32,
            pressure_in,
            flow_in,
            profile_seed: config.profile_seed,
            profile: None,
            t_ms: 0,
            model_fault_ms: 0,
            wb_extrapolating: false,
            nx_clamped: [false; 2],
            adapt_alarm: 0,
            follow_due: false,
            observer,
            monitor: {
                let mut m = Monitor::new(MonitorConfig::paper());
                m.set_inertia(None);
                m
            },
            inertia: InertiaProbe::new(),
            drive_lag: DriveLagProbe::new(),
            drive_lag_reads: 0,
            inertia_factor: 1.0,
            speed_lag_s: 0.0,
            torque_sum: 0.0,
            torque_ticks: 0,
            vfd_reads_seen: 0,
            stop_writes_seen: 0,
            overspeed_set_rpm: 0,
            protect_speed_rpm: 0.0,
            protection: Protection::new(),
            hold: false,
            protect_reads: (0, 0),
            virtual_bench: config.virtual_bench,
            out: Published::default(),
            regulator: None,
            measured_lag_s: [0.0; 2],
            last_mode: None,
            last_law: ControlLaw::Model,
            manual_hold: None,
            setpoint_writes_seen: 0,
            regulating: false,
            transfer: false,
            last_applied_pct: 0.0,
            last_requested_pct: 0.0,
            link_was_down: false,
            resume: false,
            view: LoopView {
                load: Load {
                    valve_k2: paper_k2,
                    head_scale: 1.0,
                    torque_scale: 1.0,
                },
                speed_rpm: 0.0,
                flow_lps: 0.0,
                pressure_mca: 0.0,
                pressure_sd_mca: f32::INFINITY,
            },
            virtual_measurement: false,
            control_held: false,
            static_head_set: (STATIC_HEAD_DEFAULT_MCA, 0),
            lift: LiftProbe::NEW,
        };
        let s = c.whitebox.signals(&c.wb);
        c.pressure.reseed(Arithmetic::F32, 0.0, s.pressure_mca);
        c.flow.reseed(Arithmetic::F32, 0.0, s.flow_lps);
        Ok(c)
    }

    /// The models take the static head `c_mca` (eq. (8)'s c, mca; [`Commands::static_head_mca`]
    /// negated): the white-box bench at its nominal valve, the observer (its k2 moved so the
    /// operating point stays), the loop's feedforward solved again at the next period, its
    /// change taken by the integral. A `c_mca` outside ±[`STATIC_HEAD_MAX_MCA`] (or NaN)
    /// changes nothing.
    #[inline(never)]
    fn take_static_head(&mut self, c_mca: f32) {
        // (NaN passes here: the white-box bench refuses it.)
        if c_mca.abs() > STATIC_HEAD_MAX_MCA {
            return;
        }
        let k2 = self.whitebox.params().valve_k2;
        if self.whitebox.set_load(k2, c_mca).is_ok() && self.observer.set_static_head(c_mca).is_ok()
        {
            if let Some(r) = self.regulator.as_mut() {
                r.model_changed();
            }
        }
    }

    /// One model-law loop period with both transmitters' readings `p` (mca) and `q` (l/s) at
    /// `setpoint`, `off` the setpoint less the controlled reading, for the [`LiftProbe`]:
    /// while register 20 holds its default, a static head it gives more than
    /// [`LIFT_DEAD_BAND_MCA`] from the models' is taken as a write of it would be, once two
    /// pairs in a row agree ([`LiftProbe::agrees`]: one pair spanning a valve's move during
    /// the setpoint's is wrong).
    #[inline(never)]
    fn learn_lift(&mut self, setpoint: f32, off: f32, p: f32, q: f32) {
        if self.static_head_set.0 == STATIC_HEAD_DEFAULT_MCA {
            if let Some(c) = self.lift.period(self.t_ms, setpoint, off, p, q) {
                if self.lift.agrees(c)
                    && (c - self.whitebox.params().static_head_c_mca).abs() > LIFT_DEAD_BAND_MCA
                {
                    self.take_static_head(c);
                }
            }
        }
    }

    /// The observer takes the uncertainty of its pressure transmitter's lag of
    /// [`observer_pressure_lag_sd_s`] (the pressure loop's measured lag, just taken) when it
    /// changed.
    #[inline(never)]
    fn follow_pressure_lag(&mut self) {
        let c = self.observer.config();
        let sd = observer_pressure_lag_sd_s(self.measured_lag_s[0], c.pressure_lag_s);
        if sd != c.pressure_lag_sd_s {
            // (A refused value, NaN, leaves the observer's.)
            let _ = self.observer.set_pressure_lag_sd_s(sd);
        }
    }

    /// Time of the next step, ms (steps since start).
    pub fn now_ms(&self) -> u32 {
        self.t_ms
    }

    /// Which transmitters the next step samples: (pressure, flow). A board converts only
    /// those (a virtual bench draws its noise only for those): each model's own period, and
    /// both on every control tick while a loop acts (modes 3 and 4).
    pub fn samples_due(&self) -> (bool, bool) {
        let control = self.control_due();
        (
            control || self.t_ms.is_multiple_of(self.pressure.period_ms),
            control || self.t_ms.is_multiple_of(self.flow.period_ms),
        )
    }

    /// The models' sample periods, ms: (pressure, flow), the flow's a multiple of the
    /// pressure's (the commissioning record's, [`crate::record::RecordRow::at_step`]).
    pub fn sample_periods_ms(&self) -> (u32, u32) {
        (self.pressure.period_ms, self.flow.period_ms)
    }

    /// The next step is a loop's control tick ([`crate::regulate::CONTROL_PHASE_MS`]).
    fn control_due(&self) -> bool {
        self.regulating && self.t_ms % CONTROL_PERIOD_MS == CONTROL_PHASE_MS
    }

    /// The pressure or flow loop, while one acts.
    pub fn regulator(&self) -> Option<&Regulator> {
        self.regulator.as_ref()
    }

    /// The plant's lag beyond the model the pressure and flow loops took last, s
    /// (`Regulator::lag_s`: measured on the model-based law's setpoint steps, or raised by its
    /// ring watch, `Regulator::watch_ring`; 0 until either).
    pub fn measured_lag_s(&self) -> [f32; 2] {
        self.measured_lag_s
    }

    /// The rotor's inertia measured from the drive's readings, as a factor of the paper's
    /// ([`model_core::inertia::InertiaProbe::factor`]: 1 until a move has shown it).
    pub fn inertia_factor(&self) -> f32 {
        self.inertia_factor
    }

    /// The static head the models take now, mca (`−c`: register 20's value as last written,
    /// or, while it holds its default, the one learnt from the loops' settled points,
    /// `LiftProbe`; the paper's −0.252 until either).
    pub fn static_head_mca(&self) -> f32 {
        -self.whitebox.params().static_head_c_mca
    }

    /// The drive's torque lag measured from its torque readings, s
    /// ([`model_core::drive_lag::DriveLagProbe::lag_s`]: 0 until the torque has moved).
    pub fn drive_lag_s(&self) -> f32 {
        self.drive_lag.lag_s()
    }

    /// The drive's speed reading's lag measured with the inertia, s
    /// ([`model_core::inertia::InertiaProbe::speed_lag_s`]: 0 until a move has shown one).
    pub fn speed_lag_s(&self) -> f32 {
        self.speed_lag_s
    }

    /// What the SCADA registers hold now.
    pub fn published(&self) -> &Published {
        &self.out
    }

    /// The white-box model's signals now.
    pub fn whitebox_signals(&self) -> Signals<f32> {
        self.whitebox.signals(&self.wb)
    }

    /// The observer (its state, covariance and last estimate).
    pub fn observer(&self) -> &Observer<f32> {
        &self.observer
    }

    /// The alarms.
    pub fn monitor(&self) -> &Monitor<f32> {
        &self.monitor
    }

    /// The trip state.
    pub fn protection(&self) -> &Protection {
        &self.protection
    }

    /// The protections' part of a step: the overspeed check on the speed now, the
    /// operator's acknowledge, the trip. Returns `true` if the torque is held at 0 %.
    fn protect(&mut self, inp: &Inputs) -> bool {
        let c = &inp.commands;
        let dt = TICK_MS as f32 * 1e-3;
        // The drive's reading while reads come in (one every 2 VFD cycles, 20 ms by
        // default), else the observer's speed: the protection must not depend on a link that
        // may be down, nor sit on a reading that failing reads leave standing (the link
        // takes 3 failed exchanges, up to ≈ 0.9 s, to call the readings invalid).
        if inp.vfd.reads_ok != self.protect_reads.0 {
            self.protect_reads = (inp.vfd.reads_ok, self.t_ms);
        }
        let age_ms = self.t_ms.wrapping_sub(self.protect_reads.1);
        let speed = match inp.vfd.readings {
            Some(r) if age_ms <= DRIVE_READING_FRESH_MS => r.speed_rpm,
            _ => self.out.observer_speed_rpm,
        };
        // The limit to the monitor when SCADA changes it (a conversion and a check saved on
        // the other steps).
        if c.protection.overspeed_rpm != self.overspeed_set_rpm {
            self.overspeed_set_rpm = c.protection.overspeed_rpm;
            self.monitor
                .set_overspeed_limit_rpm(f32::from(c.protection.overspeed_rpm));
        }
        self.monitor.check_speed(dt, speed);
        self.protect_speed_rpm = speed;
        let ack = c.stop_writes != self.stop_writes_seen;
        if ack {
            // SCADA wrote "stop": the operator's acknowledge of latched alarms and a trip,
            // kept by each until its cause has gone.
            self.stop_writes_seen = c.stop_writes;
            self.monitor.acknowledge();
        }
        let bits = self.monitor.bits();
        // Published as they are now; an observer step later in this step updates them.
        self.out.alarms = bits | self.adapt_alarm;
        self.protection
            .update(&c.protection, dt, bits, c.mode == Mode::Stop, ack)
    }

    /// The torque the mode asks for this step, before the link's substitution, with the
    /// transfer ramp after a mode switch. `readings` are this step's control samples
    /// (pressure, flow: `Some` on a control tick, the reading unless in fault).
    fn requested_torque_pct(
        &mut self,
        inp: &Inputs,
        readings: Option<(Option<f32>, Option<f32>)>,
    ) -> f32 {
        let c = &inp.commands;
        let mode = if self.hold { Mode::Stop } else { c.mode };
        if self.last_mode != Some(mode) || self.last_law != c.control.law {
            // A switch (a trip's hold included), or the loop's law changed: the loop restarts
            // bumplessly, the torque moves at the switch rate (a trip's 0 % excepted, below).
            // Into manual from a running automatic mode, the torque stays where it was until
            // the manual setpoint is written (register 0 does not follow the automatic modes).
            // (A loop's first step too: from the drive's 0 %, up to a low limit at the rate.)
            self.transfer = self.last_mode.is_some() || mode.regulates();
            self.manual_hold = match (self.last_mode, mode) {
                (Some(Mode::Profile | Mode::Pressure | Mode::Flow), Mode::Manual) => {
                    Some((self.last_applied_pct, self.setpoint_writes_seen))
                }
                (_, Mode::Manual) => self.manual_hold,
                _ => None,
            };
            self.regulator = None;
            self.last_mode = Some(mode);
            self.last_law = c.control.law;
            // The loop's flags and published parts, until a loop sets them again (once here,
            // not every step: the tick's mean is within a few instructions of its budget).
            self.virtual_measurement = false;
            self.control_held = false;
            let o = &mut self.out;
            (
                o.active_setpoint,
                o.control_error,
                o.feedforward_pct,
                o.integral_pct,
            ) = (0.0, 0.0, 0.0, 0.0);
        }
        // The reference was not delivered while the link was down (0 % applied): the loop,
        // frozen meanwhile, goes on from the applied torque at its next control tick
        // (`regulate`), and in every mode the torque comes back at the switch rate.
        let link_back = self.link_was_down && !inp.vfd.link_alarm;
        self.link_was_down = inp.vfd.link_alarm;
        if link_back {
            self.resume = true;
            self.transfer = true;
        }
        self.setpoint_writes_seen = c.setpoint_writes;
        let wanted = match mode {
            Mode::Stop => {
                self.profile = None;
                0.0
            }
            Mode::Manual => {
                self.profile = None;
                match self.manual_hold {
                    Some((held, at)) if at == c.setpoint_writes => held,
                    hold => {
                        // The hold's end is the switch it put off: at the switch rate.
                        if hold.is_some() {
                            self.manual_hold = None;
                            self.transfer = true;
                        }
                        c.setpoint_pct
                    }
                }
            }
            Mode::Profile => {
                let seed = self.profile_seed;
                let p = self
                    .profile
                    .get_or_insert_with(|| McuPulses::paper(seed, TICK_MS));
                p.next().map_or(0.0, |(_, u)| u)
            }
            Mode::Pressure | Mode::Flow => {
                self.profile = None;
                self.regulate(mode, inp, readings)
            }
        };
        if self.hold {
            // A trip: 0 % at once, never ramped.
            self.transfer = false;
            return 0.0;
        }
        let s = &c.control;
        let from = self.last_applied_pct;
        let regulates = mode.regulates();
        if !(regulates || self.transfer) {
            return wanted;
        }
        // The loop's torque changes once a period; the output moves toward it at the rate
        // limit every ms (a ramp, not a 1 % step every 5 ms). After a switch or the link's
        // return: from the torque the drive had, at the loop's rate or
        // SWITCH_RATE_MIN_PCT_PER_S, the faster (a stop never takes minutes). In the loops a
        // low limit above the torque is reached at that rate too, not in a step (a review:
        // 0 → 50.6 % in one step into mode 3 with the low limit at 50 %, on the link's return,
        // and 20 → 90 % when it was written under a running loop); the high limit applies at
        // once (it protects the drive).
        let rate = if self.transfer {
            s.rate_pct_per_s.max(SWITCH_RATE_MIN_PCT_PER_S)
        } else {
            s.rate_pct_per_s
        };
        let step = rate * TICK_MS as f32 * 1e-3;
        let target = if regulates {
            wanted.max(s.torque_min_pct)
        } else {
            wanted
        };
        let moved = target.max(from - step).min(from + step);
        if moved == target {
            self.transfer = false;
        }
        if regulates {
            moved.min(s.torque_max_pct)
        } else {
            moved
        }
    }

    /// The loop's torque this step (modes 3 and 4): a new one on a control tick, else the
    /// last (the torque applied before the loop's first period, for a bumpless start).
    fn regulate(
        &mut self,
        mode: Mode,
        inp: &Inputs,
        readings: Option<(Option<f32>, Option<f32>)>,
    ) -> f32 {
        if inp.vfd.link_alarm {
            // Nothing delivered: 0 % applied and asked (so the drive gets no old reference
            // when the link returns), the loop frozen until then, restarted from 0 % after.
            if let Some(r) = self.regulator.as_mut() {
                r.hold();
            }
            return 0.0;
        }
        let Some((pressure, flow)) = readings else {
            return self
                .regulator
                .as_ref()
                .map_or(self.last_requested_pct, |r| r.last().torque_pct);
        };
        let s = &inp.commands.control;
        let v = self.view;
        let (controlled, setpoint, measured) = match mode {
            Mode::Flow => {
                // The virtual flow meter: the observer's flow when the meter is in fault.
                self.virtual_measurement = flow.is_none();
                (
                    Controlled::Flow,
                    s.flow_setpoint_lps,
                    flow.unwrap_or(v.flow_lps),
                )
            }
            _ => {
                let limit = (VIRTUAL_PRESSURE_MAX_SD_FRACTION * s.pressure_setpoint_mca.abs())
                    .max(VIRTUAL_PRESSURE_MIN_SD_MCA);
                let virtual_ok = v.pressure_sd_mca <= limit;
                self.virtual_measurement = pressure.is_none() && virtual_ok;
                self.control_held = pressure.is_none() && !virtual_ok;
                let measured =
                    pressure.unwrap_or(if virtual_ok { v.pressure_mca } else { f32::NAN });
                (Controlled::Pressure, s.pressure_setpoint_mca, measured)
            }
        };
        if self.control_held {
            // Nothing to act on: the last torque, the loop frozen.
            return self
                .regulator
                .as_mut()
                .map_or(self.last_requested_pct, |r| r.hold().torque_pct);
        }
        let applied = self.last_applied_pct;
        if core::mem::take(&mut self.resume) {
            if let Some(r) = self.regulator.as_mut() {
                r.resume(measured, applied);
            }
        }
        let k = usize::from(controlled == Controlled::Flow);
        let lag_s = self.measured_lag_s[k];
        let r = self.regulator.get_or_insert_with(|| {
            Regulator::new(controlled, measured, applied, v.speed_rpm).with_lag(lag_s)
        });
        r.set_inertia(self.inertia_factor);
        // A fresh torque reading teaches the drive's lag (here, off the observer's tick: the
        // tick's longest).
        if inp.vfd.reads_ok != self.drive_lag_reads {
            self.drive_lag_reads = inp.vfd.reads_ok;
            if let Some(d) = inp.vfd.readings {
                self.drive_lag
                    .read(d.torque_pct, &self.whitebox.params().gamma);
            }
        }
        r.set_drive_lag(self.drive_lag.lag_s(), self.speed_lag_s);
        // The cap keeps the pump out of the overspeed trip: none where overspeed only warns
        // (holding register 6; a review: it cost 10.6 % of the pressure there for nothing).
        let p = &inp.commands.protection;
        let limit = if p.trip_on & TRIP_OVERSPEED != 0 {
            f32::from(p.overspeed_rpm)
        } else {
            0.0
        };
        r.set_speed_limit(limit, self.protect_speed_rpm);
        r.guard_speed(self.whitebox.params(), s);
        let o = r.step(self.whitebox.params(), v.load, s, setpoint, measured);
        r.watch_ring(s);
        self.measured_lag_s[k] = r.lag_s();
        // The static head, learnt where register 20 holds its default, from the two
        // transmitters (a setpoint move's pair of settled points; docs/control.md).
        if let (Some(p), Some(q), ControlLaw::Model) = (pressure, flow, s.law) {
            self.learn_lift(setpoint, setpoint - measured, p, q);
        }
        if k == 0 {
            // Where the measured lag changes, on a loop's tick: never an observer step's,
            // whose worst case stays where it was.
            self.follow_pressure_lag();
        }
        o.torque_pct
    }

    /// One observer step over the pressure period, then the alarms.
    fn observe(&mut self, pressure: Option<f32>, flow: Option<f32>, inp: &Inputs) {
        let dt = self.pressure.period_ms as f32 * 1e-3;
        let torque = if self.torque_ticks > 0 {
            self.torque_sum / self.torque_ticks as f32
        } else {
            0.0
        };
        (self.torque_sum, self.torque_ticks) = (0.0, 0);
        let fresh = inp.vfd.reads_ok != self.vfd_reads_seen;
        self.vfd_reads_seen = inp.vfd.reads_ok;
        let drive = inp.vfd.readings.filter(|_| fresh);
        let m = Measurements {
            pressure_mca: pressure,
            flow_lps: flow,
            speed_rpm: drive.map(|r| r.speed_rpm),
        };
        // dt is the pressure period (≥ 1 ms, ≤ 10 s for any sane model): a refused step keeps
        // the last estimate.
        // While the VFD link is down the observer only predicts, on the 0 % sent, and takes no
        // reading: no speed is read and the torque is the drive's own (its stop or coast), so
        // the readings cannot teach it the load. (Corrected by them, the model's rotor
        // coasting against a rotor 4 × the paper's took the mismatch for a valve: k2 ran to
        // twice the valve's over a 2 s cut, and the loop carried its way back into the
        // integral on the link's return. Not stepped at all, its state was stale on the
        // return, and a water column's plant (P5, P1) came back worse than the PI alone.)
        // (Written so, not as `Option::filter`s on each reading: those cost the QEMU image
        // 216 B, code placement.)
        let none = Measurements {
            pressure_mca: None,
            flow_lps: None,
            speed_rpm: None,
        };
        let e = self
            .observer
            .step(dt, torque, if inp.vfd.link_alarm { &none } else { &m })
            .unwrap_or_else(|_| self.observer.estimate_now());
        self.monitor.update(&MonitorInputs {
            dt_s: dt,
            estimate: e,
            torque_ref_pct: torque,
            vfd_torque_pct: drive.map(|r| r.torque_pct),
            vfd_speed_rpm: drive.map(|r| r.speed_rpm),
            measured_flow_lps: flow,
            pressure_fault: self.pressure_in.faulted(),
            flow_fault: self.flow_in.faulted(),
            vfd_link_alarm: inp.vfd.link_alarm,
        });
        if let Some(d) = self.monitor.motion() {
            // In the loops, only the moves they make teach the inertia: a valve step's new
            // load torque shows in the flow reading late (a first version that learnt from
            // valve steps read 1.03..1.12 × on the paper's rotor).
            // Nor while a protection holds 0 %: a dry pump's coast (its load not the
            // curve's) read 4 × the paper's rotor within 1 s, and the dry-run rule, told it,
            // took 13..18 s to rise instead of 2 (a review, on the virtual board).
            let learn =
                d.turning && !self.hold && self.regulator.as_ref().is_none_or(Regulator::moving);
            self.inertia.update(learn, d.moved, d.predicted_rpm_per_s);
            let (factor, lag) = self.inertia.measured();
            (self.inertia_factor, self.speed_lag_s) = (factor.unwrap_or(1.0), lag);
            // Until the probe has measured, the dry-run rule reads a coast on the heaviest
            // rotor (`Monitor::set_inertia`).
            self.monitor.set_inertia(factor);
        }
        self.view = LoopView {
            load: Load {
                valve_k2: e.valve_k2,
                head_scale: e.head_scale,
                torque_scale: e.torque_scale,
            },
            speed_rpm: e.speed_rpm,
            flow_lps: e.flow_lps,
            pressure_mca: e.pressure_mca,
            pressure_sd_mca: e.pressure_sd_mca,
        };
        let o = &mut self.out;
        o.alarms = self.monitor.bits() | self.adapt_alarm;
        o.observer_speed_rpm = e.speed_rpm;
        o.observer_flow_lps = e.flow_lps;
        o.observer_valve_k2 = e.valve_k2;
        o.observer_flow_sd_lps = e.flow_sd_lps;
    }

    /// One millisecond (see the module docs).
    // Inlined always: each board's image calls it from one place, its control task (the
    // plant protocol's session is a test image's). Left to LLVM, the ring watch's call
    // (`Regulator::watch_ring`) made it keep this out of line and split the task: the QEMU
    // image grew 1.5 KB past its 64 KiB (`cargo xtask bench`).
    #[inline(always)]
    pub fn step(&mut self, inp: &Inputs) -> Outputs {
        let now = self.t_ms;
        let adapt = inp.commands.narmax_adapt;
        if self.follow_due {
            // The output maps take the last samples' measurements (see `Follow::settle`).
            self.follow_due = false;
            self.pressure.follow.settle(adapt);
            self.flow.follow.settle(adapt);
            let shown =
                self.pressure.follow.fallback_left > 0 || self.flow.follow.fallback_left > 0;
            self.adapt_alarm = if shown {
                model_core::monitor::MODEL_RESIDUAL
            } else {
                0
            };
        }
        let set = (
            inp.commands.static_head_mca,
            inp.commands.static_head_writes,
        );
        if set != self.static_head_set {
            // Written: it stands, and the probe starts afresh (for the default).
            (self.static_head_set, self.lift) = (set, LiftProbe::NEW);
            self.take_static_head(-set.0);
        }
        let control = self.control_due();
        let take_p = now.is_multiple_of(self.pressure.period_ms);
        let take_q = now.is_multiple_of(self.flow.period_ms);
        self.hold = self.protect(inp);
        // A control tick is never a model's sample tick (CONTROL_PHASE_MS): its samples are
        // the loop's alone, read before the torque they decide.
        let readings = control.then(|| {
            let p = self.pressure_in.peek(inp.pressure_code);
            let q = self.flow_in.peek(inp.flow_code);
            self.out.pressure_mca = p.value;
            self.out.flow_lps = q.value;
            (
                (p.status != InputStatus::Fault).then_some(p.value),
                (q.status != InputStatus::Fault).then_some(q.value),
            )
        });
        let requested = self.requested_torque_pct(inp, readings);
        let u = inp.vfd.applied_torque_pct(requested);
        self.last_applied_pct = u;
        self.last_requested_pct = requested;
        self.torque_sum += u;
        self.torque_ticks += 1;
        // The drive's lag learns only in the loops (its readings are taken there): outside
        // them the sum would only be thrown away at the next reading.
        if self.regulator.is_some() {
            self.drive_lag.applied(1e-3, u);
        }

        if inp.commands.arithmetic != self.arithmetic {
            // The other arithmetic's history is stale: start it at the last predictions.
            self.arithmetic = inp.commands.arithmetic;
            let (p, q) = (self.pressure.last, self.flow.last);
            self.pressure.reseed(self.arithmetic, u, p);
            self.flow.reseed(self.arithmetic, u, q);
        }

        if take_p || take_q {
            let wb = self.whitebox.signals(&self.wb);
            self.wb_extrapolating = wb.extrapolation.any();
            let o = &mut self.out;
            o.whitebox_speed_rpm = wb.speed_rpm;
            o.whitebox_pressure_mca = wb.pressure_mca;
            o.whitebox_flow_lps = wb.flow_lps;
            let mut pressure_measured = None;
            if take_p {
                let r = self.pressure_in.sample(inp.pressure_code);
                let good = r.status != InputStatus::Fault;
                // The observer takes only readings inside the span (4..20 mA): outside it the
                // value is clamped, a bound rather than a measurement (at rest the outlet
                // sits below the span's 0).
                pressure_measured = (r.status == InputStatus::Ok).then_some(r.value);
                let nx = self.pressure.step(
                    self.arithmetic,
                    u,
                    good.then_some(r.value).filter(|_| !adapt),
                );
                let y = self.pressure.follow(&inp.commands, nx.y, pressure_measured);
                self.follow_due |= adapt || self.adapt_alarm != 0;
                self.nx_clamped[0] = nx.clamped;
                o.pressure_mca = r.value;
                o.narmax_pressure_mca = y;
                (
                    o.whitebox_pressure_residual_mca,
                    o.narmax_pressure_residual_mca,
                ) = if good {
                    (r.value - wb.pressure_mca, r.value - y)
                } else {
                    (0.0, 0.0)
                };
                o.sample = o.sample.wrapping_add(1);
            }
            let mut flow_measured = None;
            if take_q {
                let r = self.flow_in.sample(inp.flow_code);
                let good = r.status != InputStatus::Fault;
                flow_measured = (r.status == InputStatus::Ok).then_some(r.value);
                let nx = self.flow.step(
                    self.arithmetic,
                    u,
                    good.then_some(r.value).filter(|_| !adapt),
                );
                let y = self.flow.follow(&inp.commands, nx.y, flow_measured);
                self.follow_due |= adapt || self.adapt_alarm != 0;
                self.nx_clamped[1] = nx.clamped;
                o.flow_lps = r.value;
                o.narmax_flow_lps = y;
                (o.whitebox_flow_residual_lps, o.narmax_flow_residual_lps) = if good {
                    (r.value - wb.flow_lps, r.value - y)
                } else {
                    (0.0, 0.0)
                };
            }
            if take_p {
                self.observe(pressure_measured, flow_measured, inp);
            }
        }

        if step_or_restart(&self.whitebox, &mut self.wb, u) {
            self.model_fault_ms = self.model_fault_ms.saturating_sub(TICK_MS);
        } else {
            self.model_fault_ms = MODEL_FAULT_SHOWN_MS;
        }
        let model_fault = self.model_fault_ms > 0;

        let link_ok = !inp.vfd.link_alarm;
        let (p_fault, q_fault) = (self.pressure_in.faulted(), self.flow_in.faulted());
        // Stale readings are never published: invalid readings read 0, with status bit 6.
        let blind = inp.vfd.readings.is_none();
        let readings = inp.vfd.readings.unwrap_or_default();
        let o = &mut self.out;
        o.trip_causes = self.protection.causes();
        o.status = Status {
            // Running while commanded so, or while a torque is still applied (a stop's ramp).
            running: (inp.commands.mode != Mode::Stop && !self.hold) || u > 0.0,
            any_alarm: !link_ok
                || blind
                || p_fault
                || q_fault
                || model_fault
                || self.protection.tripped()
                || self.control_held
                || o.alarms & !model_core::monitor::LOAD_CHANGED != 0,
            extrapolating: self.wb_extrapolating || self.nx_clamped.iter().any(|&c| c),
            vfd_link_ok: link_ok,
            pressure_fault: p_fault,
            flow_fault: q_fault,
            vfd_readings_invalid: blind,
            // Held at 0 % by a protection: tripped, or cleared and waiting for mode 0 (a
            // review: a mode written before the trip cleared left the pump at 0 % with no bit).
            tripped: self.hold,
            in_control: self.regulator.is_some() && link_ok && !self.control_held && !self.hold,
            limited: self.regulator.as_ref().is_some_and(|r| r.last().limited),
            virtual_measurement: self.virtual_measurement,
            control_held: self.control_held,
            holds_flow: self
                .regulator
                .as_ref()
                .is_some_and(|r| r.controlled() == Controlled::Flow),
        }
        .bits();
        if let Some(r) = &self.regulator {
            let l = r.last();
            o.active_setpoint = l.reference;
            o.control_error = l.error;
            o.feedforward_pct = l.feedforward_pct;
            o.integral_pct = l.integral_pct;
        }
        o.torque_pct = u;
        o.vfd_speed_rpm = readings.speed_rpm;
        o.vfd_torque_pct = readings.torque_pct;
        o.vfd_status = readings.status;
        o.uptime_s = (now / 1000) as u16;

        self.regulating = !self.hold && inp.commands.mode.regulates();
        self.t_ms = now.wrapping_add(TICK_MS);
        Outputs {
            t_ms: now,
            torque_ref_pct: u,
            requested_torque_pct: requested,
            bench: self.virtual_bench.then_some(BenchCommands {
                valve_factor: inp.commands.valve_factor,
                faults: inp.commands.faults,
            }),
            log: now.is_multiple_of(LOG_EVERY_MS).then_some(LogLine {
                t_ms: now,
                mode: inp.commands.mode,
                arithmetic: self.arithmetic,
                values: self.out,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Periods of `probe` settled at `setpoint` on the system curve `p = k q² − c` from
    /// `*t` ms on (one a control period), the flow reading `drift` × the curve's (1:
    /// settled), each period's drift compounding; the static heads the probe gave.
    fn settle_at(
        probe: &mut LiftProbe,
        t: &mut u32,
        setpoint: f32,
        (k, c): (f32, f32),
        drift: f32,
    ) -> Vec<f32> {
        let q = ((setpoint + c) / k).sqrt();
        let mut f = 1.0;
        (0..3 * LIFT_SETTLED_PERIODS)
            .filter_map(|_| {
                f *= drift;
                *t += CONTROL_PERIOD_MS;
                probe.period(*t, setpoint, 0.0, setpoint, q * f)
            })
            .collect()
    }

    /// Two settled points of one system curve give its static head, once per move; a flow
    /// reading still moving, two flows or two pressures too close, no flow, a pressure at the
    /// transmitter's floor, a pair of two valves, a pair with a period not fed between, with
    /// a move between that never settled, or with the first point left by a valve's step
    /// give none; a reading off its setpoint by more than 2 % starts the settling again.
    #[test]
    fn the_lift_probe_finds_the_static_head_of_two_settled_points() {
        let lift = (0.0117, -1.5);
        let fresh = || (LiftProbe::NEW, 0u32);
        let (mut probe, mut t) = fresh();
        assert!(
            settle_at(&mut probe, &mut t, 2.0, lift, 1.0).is_empty(),
            "no anchor yet"
        );
        let c = settle_at(&mut probe, &mut t, 4.0, lift, 1.0);
        assert_eq!(c.len(), 1, "{c:?}");
        assert!((c[0] - lift.1).abs() < 1e-3, "{c:?}");
        // The paper's own c.
        let paper = (0.0117, 0.252);
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, paper, 1.0);
        let c = settle_at(&mut probe, &mut t, 3.0, paper, 1.0);
        assert!(c.len() == 1 && (c[0] - 0.252).abs() < 1e-3, "{c:?}");
        // The flow reading drifting 1 % per 100 periods (a damped meter; 2 % squared): nothing.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        assert!(settle_at(&mut probe, &mut t, 4.0, lift, 1.0001).is_empty());
        // A loop held 10 % under its setpoint (at a torque limit), steady on the curve: no
        // point.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        let q = ((3.6 + lift.1) / lift.0).sqrt();
        let held = (0..3 * LIFT_SETTLED_PERIODS).filter_map(|_| {
            t += CONTROL_PERIOD_MS;
            probe.period(t, 4.0, 0.4, 3.6, q)
        });
        assert_eq!(held.count(), 0);
        // Two flows too close (4.0 and 4.1 mca: 5 % apart squared).
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 4.0, lift, 1.0);
        assert!(settle_at(&mut probe, &mut t, 4.1, lift, 1.0).is_empty());
        // No flow (under 1 l/s): no anchor, so no pair after it either.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 1.51, lift, 1.0);
        assert!(settle_at(&mut probe, &mut t, 4.0, lift, 1.0).is_empty());
        // A reading at the floor (0.05 mca, as at 0 on a curve that asks less): no anchor.
        let low = (0.0117, 0.2);
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 0.05, low, 1.0);
        assert!(settle_at(&mut probe, &mut t, 3.0, low, 1.0).is_empty());
        // The valve closed between the points: more pressure at less flow.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        assert!(settle_at(&mut probe, &mut t, 3.0, (4.0 * lift.0, lift.1), 1.0).is_empty());
        // A period not fed between the points (a stop, a cut, a fault): the anchor is gone.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        t += 2 * CONTROL_PERIOD_MS;
        assert!(settle_at(&mut probe, &mut t, 4.0, lift, 1.0).is_empty());
        // A setpoint nudged 1.7 % down with the valve's k2 × 1.3 (the flows squared 41 %
        // apart, the pressures 1.7 %: a lift of 2.9 mca without the pressures' spread): no pair.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 3.0, paper, 1.0);
        assert!(settle_at(&mut probe, &mut t, 2.95, (paper.0 * 1.69, paper.1), 1.0).is_empty());
        // Periods `n` at `setpoint` whose pressure climbs from it to 1.5 × it (a move on its
        // way, a valve's step).
        let off_band = |probe: &mut LiftProbe, t: &mut u32, setpoint: f32, n: u16| {
            for i in 0..n {
                *t += CONTROL_PERIOD_MS;
                let p = setpoint * (1.0 + 0.5 * f32::from(i) / f32::from(n));
                assert_eq!(probe.period(*t, setpoint, setpoint - p, p, 10.0), None);
            }
        };
        // A move to 3 mca that never settled, then one to 4: no pair with the 2 mca point.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        off_band(&mut probe, &mut t, 3.0, 300);
        assert!(settle_at(&mut probe, &mut t, 4.0, lift, 1.0).is_empty());
        // The valve's step at 2 mca (the readings off the point), a move before the point
        // after it is confirmed: no pair; confirmed again at the new valve, the pair is of
        // the new valve.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        off_band(&mut probe, &mut t, 2.0, 20);
        assert!(settle_at(&mut probe, &mut t, 4.0, (2.0 * lift.0, lift.1), 1.0).is_empty());
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        off_band(&mut probe, &mut t, 2.0, 20);
        settle_at(&mut probe, &mut t, 2.0, (2.0 * lift.0, lift.1), 1.0);
        let c = settle_at(&mut probe, &mut t, 4.0, (2.0 * lift.0, lift.1), 1.0);
        assert!(c.len() == 1 && (c[0] - lift.1).abs() < 1e-3, "{c:?}");
        // Taken only when two pairs in a row agree within 0.1 mca.
        let (mut probe, _) = fresh();
        assert!(!probe.agrees(-1.5), "a first pair");
        assert!(probe.agrees(-1.45), "a second within 0.1 mca");
        assert!(!probe.agrees(-1.2), "one that disagrees");
        assert!(
            !probe.agrees(-1.5),
            "nor the next: it disagrees with that one"
        );
        assert!(probe.agrees(-1.5));
        // The valve moved 50 periods before the move (the flow 5 % lower, the pressure held):
        // the point from before it pairs with nothing.
        let moved_before = |probe: &mut LiftProbe, t: &mut u32, n: u16| {
            let q = ((2.0 + lift.1) / lift.0).sqrt() * 0.95;
            for _ in 0..n {
                *t += CONTROL_PERIOD_MS;
                assert_eq!(probe.period(*t, 2.0, 0.0, 2.0, q), None);
            }
        };
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        moved_before(&mut probe, &mut t, 50);
        assert!(settle_at(&mut probe, &mut t, 4.0, lift, 1.0).is_empty());
        // A single reading off by 20 % every 150 periods is noise: the means hold.
        let (mut probe, mut t) = fresh();
        settle_at(&mut probe, &mut t, 2.0, lift, 1.0);
        let q = ((4.0 + lift.1) / lift.0).sqrt();
        let got = (0..3 * LIFT_SETTLED_PERIODS)
            .filter_map(|i| {
                t += CONTROL_PERIOD_MS;
                let p = if i % 150 == 149 { 4.8 } else { 4.0 };
                probe.period(t, 4.0, 4.0 - p, p, q)
            })
            .count();
        assert_eq!(got, 1);
    }

    /// Noisy readings (the pressure's noise 1.5 % of a 1 mca setpoint, 1 σ, the transmitters'
    /// noise model: single readings off a 2 % band one period in five, which never settled
    /// before the means; the flow's 0.5 %) settle, and their means give the static head.
    #[test]
    fn the_lift_probe_settles_through_noise() {
        let (k, c) = (0.0117, -0.5);
        let mut rng = model_core::excitation::SplitMix64::new(12345);
        let mut noise = || 0.5 * model_core::transmitter::noise(&mut rng);
        let (mut probe, mut t) = (LiftProbe::NEW, 0u32);
        let mut got = Vec::new();
        for setpoint in [1.0f32, 3.0, 1.0] {
            let q = ((setpoint + c) / k).sqrt();
            for _ in 0..3 * LIFT_SETTLED_PERIODS {
                t += CONTROL_PERIOD_MS;
                let p = setpoint * (1.0 + 0.03 * noise());
                got.extend(probe.period(t, setpoint, setpoint - p, p, q * (1.0 + 0.01 * noise())));
            }
        }
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(got.iter().all(|g| (g - c).abs() < 0.05), "{got:?}");
    }

    /// Regression (defect 5c of the protection issue): a white-box step that failed left the
    /// diverged state in place and the fault latched for good, "any alarm" with it.
    #[test]
    fn a_diverged_white_box_restarts_at_its_steady_state() {
        let wb = WhiteBox::<f32>::paper();
        let mut s = wb.steady_state(50.0).unwrap();
        let good = s;
        s.speed_rpm = f32::NAN;
        assert!(
            !step_or_restart(&wb, &mut s, 50.0),
            "the failure is reported"
        );
        assert_eq!(s.speed_rpm, good.speed_rpm, "restarted at the steady state");
        assert!(step_or_restart(&wb, &mut s, 50.0), "and steps again");
    }

    /// A static head outside ±[`STATIC_HEAD_MAX_MCA`] or not finite, from an API caller (SCADA
    /// refuses it before), leaves the models as they were; one inside moves them.
    #[test]
    fn a_static_head_out_of_range_is_refused() {
        use pump_models::{flow, pressure};
        let p = NarmaxModel::new(&pressure::F32, &pressure::Q15, 50).unwrap();
        let q = NarmaxModel::new(&flow::F32, &flow::Q15, 100).unwrap();
        let mut c = Controller::new(&Config::bench(), p, q).unwrap();
        let held = |c: &Controller<_, _, _, _>| {
            (
                c.whitebox.params().static_head_c_mca,
                c.observer().config().params.static_head_c_mca,
            )
        };
        let paper = held(&c);
        for bad in [10.001, -10.5, 1e6, f32::NAN, f32::INFINITY] {
            c.take_static_head(bad);
            assert_eq!(held(&c), paper, "{bad} mca");
        }
        for good in [-STATIC_HEAD_MAX_MCA, 1.5, STATIC_HEAD_MAX_MCA] {
            c.take_static_head(good);
            assert_eq!(held(&c), (good, good));
        }
    }

    /// Register 20 as SCADA writes it: a learnt static head stands while the register holds
    /// its default; any write of it (the default too, which the learnt one had left in the
    /// register) sets the models' static head to it and starts the probe afresh.
    #[test]
    fn a_write_of_register_20_sets_the_static_head_even_at_its_default() {
        use crate::scada::ScadaSlave;
        use pump_models::{flow, pressure};
        let p = NarmaxModel::new(&pressure::F32, &pressure::Q15, 50).unwrap();
        let q = NarmaxModel::new(&flow::F32, &flow::Q15, 100).unwrap();
        let mut c = Controller::new(&Config::bench(), p, q).unwrap();
        let mut slave = ScadaSlave::new(1).unwrap();
        let paper = c.whitebox.params().static_head_c_mca;
        let step = |c: &mut Controller<_, _, _, _>, slave: &ScadaSlave| {
            c.step(&Inputs {
                pressure_code: 0,
                flow_code: 0,
                commands: slave.commands(),
                vfd: VfdStatus::START,
            });
            (
                c.whitebox.params().static_head_c_mca,
                c.observer().config().params.static_head_c_mca,
            )
        };
        // As if learnt: it stands while nothing is written.
        c.take_static_head(-1.5);
        assert_eq!(step(&mut c, &slave), (-1.5, -1.5));
        let default = (STATIC_HEAD_DEFAULT_MCA * 1000.0).round() as i16;
        slave.write_words(20, &[default as u16]).unwrap();
        assert_eq!(
            step(&mut c, &slave),
            (paper, paper),
            "the default written again"
        );
        slave.write_words(20, &[1000]).unwrap();
        assert_eq!(step(&mut c, &slave), (-1.0, -1.0), "a lift written");
        assert!(
            c.lift.anchor.0.is_nan() && c.lift.setpoint.is_nan(),
            "the probe afresh"
        );
    }

    /// The observer's pressure lag uncertainty: the paper's until the measured lag exceeds
    /// the observer's lag by more, then that excess.
    #[test]
    fn the_observers_lag_uncertainty_is_the_measured_lag_beyond_its_own() {
        let paper = ObserverConfig::<f32>::paper();
        let (lag, sd) = (paper.pressure_lag_s, paper.pressure_lag_sd_s);
        assert_eq!(observer_pressure_lag_sd_s(0.0, lag), sd);
        assert_eq!(observer_pressure_lag_sd_s(0.05, lag), sd);
        assert_eq!(observer_pressure_lag_sd_s(0.17, lag), 0.17 - lag);
        assert_eq!(observer_pressure_lag_sd_s(1.0, lag), 1.0 - lag);
    }

    const S: Scaling<f32> = Scaling {
        mean: 2.0,
        std: 0.5,
    };
    const TS: f32 = 0.05;

    /// A network output that moves (the pulses of a free run), its plant 1.3 times it.
    fn network(k: u32) -> f32 {
        2.0 + 0.6 * (k as f32 * 0.3).sin()
            + if (k / 40).is_multiple_of(2) {
                0.4
            } else {
                -0.3
            }
    }

    /// The controller's `Follow` (output now, update on the next tick) gives the bits of the
    /// output map run as `pumpbench simulate --adapt` runs it (output, then update).
    #[test]
    fn following_is_the_output_map_one_tick_later() {
        let mut f = Follow::new(S, TS);
        let mut map = OutputMap::new(S, TS, ADAPT_TAU_S).unwrap();
        for k in 0..2000 {
            let y = network(k);
            let m = (k % 7 != 3).then_some(1.3 * y - 0.4);
            let out = f.sample(true, 0, y, m);
            assert_eq!(out.to_bits(), map.output(y).to_bits(), "sample {k}");
            if let Some(m) = m {
                map.update(y, m);
            }
            f.settle(true);
        }
        let (a, b) = map.gain_offset();
        assert!((a - 1.3).abs() < 0.05 && b.abs() < 0.5, "learnt ({a}, {b})");
    }

    /// A `Follow` whose map has learnt a plant 1.3 times the network over 400 samples.
    fn learnt() -> Follow {
        let mut f = Follow::new(S, TS);
        for k in 0..400 {
            f.sample(true, 0, network(k), Some(1.3 * network(k)));
            f.settle(true);
        }
        f
    }

    /// Turned off, the map is forgotten: turned on again, it starts at the identity.
    #[test]
    fn turning_it_off_forgets_the_map() {
        let mut f = learnt();
        assert_ne!(f.sample(true, 0, 2.5, None), 2.5, "a map learnt");
        assert_eq!(f.sample(false, 0, 2.5, Some(4.0)), 2.5);
        f.settle(false);
        assert!(f.map.is_none());
        assert_eq!(f.sample(true, 0, 2.5, None), 2.5, "the identity");
    }

    /// A reading waiting for the next tick when following is turned off is not taken.
    #[test]
    fn a_pending_reading_is_dropped_when_turned_off() {
        let mut f = learnt();
        let before = f.map.as_ref().unwrap().gain_offset();
        f.sample(true, 0, 2.5, Some(9.0));
        f.settle(false);
        assert_eq!(f.map.as_ref().unwrap().gain_offset(), before);
        assert_eq!(f.pending, None);
    }

    /// A map that does worse than none (learnt at one valve, the plant back at the model)
    /// returns to the identity, and the fallback shows as the model-residual alarm.
    #[test]
    fn a_map_worse_than_none_falls_back_and_raises_the_alarm() {
        let mut f = Follow::new(S, TS);
        let mut k = 0;
        for _ in 0..400 {
            f.sample(true, 0, network(k), Some(network(k) + 1.0));
            f.settle(true);
            k += 1;
        }
        assert_eq!(f.fallback_left, 0);
        let mut fell = None;
        for n in 0..200 {
            f.sample(true, 0, network(k), Some(network(k)));
            f.settle(true);
            k += 1;
            if f.fallback_left > 0 {
                fell = Some(n);
                break;
            }
        }
        let n = fell.expect("the map fell back");
        assert!(n < 20, "after {n} samples");
        assert_eq!(f.sample(true, 0, 3.0, None), 3.0, "back at the identity");
        assert_eq!(f.fallback_left, ADAPT_FALLBACK_SHOWN_SAMPLES - 1);
    }

    type Board = crate::virtual_bench::VirtualBoard<
        { pump_models::pressure::FRAMES },
        { pump_models::pressure::HIDDEN },
        { pump_models::flow::FRAMES },
        { pump_models::flow::HIDDEN },
    >;

    /// The virtual board in profile mode, the models following the load from start-up.
    fn following_board() -> Board {
        use pump_models::{flow, pressure};
        let cfg = Config {
            initial_mode: Mode::Profile,
            initial_narmax_adapt: true,
            virtual_bench: true,
            ..Config::bench()
        };
        let p = NarmaxModel::new(&pressure::F32, &pressure::Q15, 50).unwrap();
        let q = NarmaxModel::new(&flow::F32, &flow::Q15, 100).unwrap();
        let bench = crate::virtual_bench::VirtualBenchConfig::default_offsets(7);
        Board::new(&cfg, p, q, bench).unwrap()
    }

    /// Holding register 19 written `v` over SCADA.
    fn write_19(b: &mut Board, v: u8) {
        let body = [1, 6, 0, 19, 0, v];
        let [c0, c1] = crate::modbus::crc16(&body).to_le_bytes();
        let req = [1, 6, 0, 19, 0, v, c0, c1];
        assert!(b
            .scada
            .handle(&req, &mut crate::modbus::Frame::new())
            .is_some());
        assert_eq!(b.scada.commands().narmax_adapt, v == 1);
    }

    /// Each model's map as the controller holds it (the identity when there is none).
    fn maps(b: &Board) -> [(f32, f32); 2] {
        let g = |f: &Follow| f.map.as_ref().map_or((1.0, 0.0), |m| m.gain_offset());
        [
            g(&b.controller.pressure.follow),
            g(&b.controller.flow.follow),
        ]
    }

    /// In `Controller::step`, a map takes its sample's reading on the tick after the sample,
    /// never on the sample's own tick (the observer's).
    #[test]
    fn the_maps_learn_on_the_tick_after_each_sample() {
        let mut b = following_board();
        let mut last = maps(&b);
        let mut changes = [0; 2];
        for _ in 0..5000 {
            let t = b.tick().unwrap().t_ms;
            let now = maps(&b);
            for (k, period) in [(0, 50), (1, 100)] {
                if now[k] != last[k] {
                    assert_eq!(t % period, 1, "model {k}'s map changed at {t} ms");
                    changes[k] += 1;
                }
            }
            last = now;
        }
        assert!(changes[0] > 90 && changes[1] > 45, "{changes:?}");
    }

    /// Register 19 written 0 then 1 between two samples: the maps are forgotten all the same.
    #[test]
    fn a_zero_between_two_samples_forgets_the_maps() {
        let mut b = following_board();
        for _ in 0..5001 {
            b.tick().unwrap();
        }
        assert!(
            maps(&b).iter().all(|&m| m != (1.0, 0.0)),
            "learnt: {:?}",
            maps(&b)
        );
        write_19(&mut b, 0);
        write_19(&mut b, 1);
        // The next tick is 5 001 ms: no sample. Each map starts again at the identity at its
        // model's next sample: the pressure's at 5 050 ms, the flow's at 5 100 ms.
        for _ in 0..49 {
            b.tick().unwrap();
        }
        assert!(
            maps(&b).iter().all(|&m| m != (1.0, 0.0)),
            "not yet a sample"
        );
        b.tick().unwrap();
        assert_eq!(
            maps(&b)[0],
            (1.0, 0.0),
            "the pressure's forgotten at its sample"
        );
        assert_ne!(maps(&b)[1], (1.0, 0.0));
        for _ in 0..50 {
            b.tick().unwrap();
        }
        assert_eq!(maps(&b)[1], (1.0, 0.0), "the flow's at its own");
    }

    proptest::proptest! {
        /// Whatever the network and the readings (NaN, ±∞, huge), the output is finite
        /// whenever the network's is, the gain stays in its range and the update never
        /// leaves a non-finite map.
        #[test]
        fn following_never_makes_a_non_finite_output(
            seq in proptest::collection::vec(
                (proptest::num::f32::ANY, proptest::option::of(proptest::num::f32::ANY)),
                1..400,
            )
        ) {
            let mut f = Follow::new(S, TS);
            for (y, m) in seq {
                let out = f.sample(true, 0, y, m);
                proptest::prop_assert!(!y.is_finite() || out.is_finite(), "{} -> {}", y, out);
                f.settle(true);
                if let Some(map) = &f.map {
                    use model_core::narmax::adapt::{A_RANGE, B_MAX};
                    let (a, b) = map.gain_offset();
                    proptest::prop_assert!((A_RANGE.0 as f32..=A_RANGE.1 as f32).contains(&a));
                    proptest::prop_assert!(b.abs() <= B_MAX as f32);
                }
            }
        }
    }
}
