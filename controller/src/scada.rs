//! The SCADA side: a Modbus RTU slave with the controller's register map, and the
//! conversions between its registers and the core's types ([`crate::types`], the core's
//! [`Commands`]): the setpoint's 0.01 %, the mode and arithmetic codes, the published values'
//! scales. The core sees none of it.
//!
//! | input register (FC 04) | meaning | unit |
//! |---|---|---|
//! | 0 | status bits: 0 running (commanded to run and not held at 0 % by a trip, or a torque still applied), 1 any alarm, 2 model extrapolating, 3 VFD link ok (the torque reference is delivered), 4 pressure transmitter fault, 5 flow transmitter fault, 6 VFD readings invalid (reads fail: registers 14-16 read 0), 7 tripped (the torque is held at 0 % by a protection: tripped, or cleared and waiting for mode 0: [`crate::protect`]), 8 saturated (a value in this map is beyond its register's range and reads as the range's end), 9 in control (mode 3 or 4 acting), 10 limited (the loop's torque at a limit or its rate), 11 virtual measurement (the loop acts on the observer's flow or pressure: its transmitter in fault), 12 control held (pressure lost and the observer's not trustworthy: the last torque held, any-alarm set), 13 the loop holds a flow (registers 26, 27 in 0.01 l/s) | |
//! | 1 | applied torque reference | 0.01 % |
//! | 2 | measured pressure | 0.001 mca, signed |
//! | 3 | measured flow | 0.01 l/s |
//! | 4 | white-box predicted pressure | 0.001 mca, signed |
//! | 5 | white-box predicted flow | 0.01 l/s |
//! | 6 | white-box speed | 0.1 rpm |
//! | 7 | NARMAX predicted pressure | 0.001 mca, signed |
//! | 8 | NARMAX predicted flow | 0.01 l/s |
//! | 9 | sample counter (wraps) | |
//! | 10 | white-box pressure residual (measured − predicted) | 0.001 mca, signed |
//! | 11 | white-box flow residual | 0.01 l/s, signed |
//! | 12 | NARMAX pressure residual | 0.001 mca, signed |
//! | 13 | NARMAX flow residual | 0.01 l/s, signed |
//! | 14 | VFD actual speed (read over the VFD link; 0 while status bit 6 is set) | 0.1 rpm, signed |
//! | 15 | VFD actual torque (0 while bit 6 is set) | 0.01 %, signed |
//! | 16 | VFD status word, the vendor's bits (0 while bit 6 is set) | |
//! | 17 | uptime (wraps) | s |
//! | 18 | observer speed | 0.1 rpm |
//! | 19 | observer flow | 0.01 l/s |
//! | 20 | observer valve coefficient k2 (0.1082 → 10820; saturates at 0.65535, see 25) | 1e-5 |
//! | 21 | alarm bits ([`model_core::monitor`]): 0 pressure transmitter, 1 flow transmitter, 2 VFD link, 3 dry run, 4 no flow, 5 end of curve, 6 load changed, 7 model residual, 8 overspeed | |
//! | 22 | observer flow standard deviation | 0.01 l/s |
//! | 23 | trip causes: the alarm bits (as 21) that tripped the controller; 0 when not tripped | |
//! | 24 | VFD actual speed, as 14 in whole rpm (±32 767 rpm; 14 saturates at ±3 276.7) | rpm, signed |
//! | 25 | observer valve coefficient k2, as 20 in 1e-4 (the observer's whole 0.02..1) | 1e-4 |
//! | 26 | loop's active setpoint (the setpoint's reference model): 0.001 mca, or 0.01 l/s with status bit 13 (mode 4); 0 in other modes | signed |
//! | 27 | loop's control error (active setpoint − measured), as 26 | signed |
//! | 28 | loop's feedforward part (the steady torque and its lead while the reference moves: may exceed 100 %) | 0.01 %, signed |
//! | 29 | loop's integral part | 0.01 %, signed |
//!
//! | holding register (FC 03, 06, 16) | meaning | range |
//! |---|---|---|
//! | 0 | torque setpoint, 0.01 % | 0..=10000 |
//! | 1 | mode: 0 stop, 1 manual setpoint, 2 built-in excitation profile, 3 pressure control, 4 flow control ([`crate::regulate`]); writing 0 also acknowledges the latched alarms whose cause has gone; a switch moves the torque at the rate of 12 (no step) | 0..=4 |
//! | 2 | NARMAX arithmetic: 0 f32, 1 Q15 fixed point | 0..=1 |
//! | 3 | virtual bench only: its valve, k2 in 0.1 % of nominal (1000 = nominal) | 500..=2000 |
//! | 4 | virtual bench only: fault injection bits: 0 dry run, 1 pressure transmitter at 2 mA, 2 flow transmitter at 2 mA, 3 VFD link cut | 0..=15 |
//! | 5 | overspeed limit, rpm (default 1925: 110 % of the nominal 1 750) | 100..=4000 |
//! | 6 | what trips ([`crate::protect`]): bit 0 dry run, bit 1 overspeed, bit 2 no flow; 1 trips to 0 %, 0 warns (default 3) | 0..=7 |
//! | 7 | no-flow trip delay: how long the no-flow alarm stands before it trips, if bit 2 of 6 is set (default 30) | 1..=3600 s |
//! | 8 | pressure setpoint of mode 3, 0.001 mca | 0..=65535 |
//! | 9 | flow setpoint of mode 4, 0.01 l/s | 0..=65535 |
//! | 10 | torque low limit of modes 3 and 4, 0.01 % (default 0); above the torque, reached at the rate (12), not in a step | 0..=10000, below 11 |
//! | 11 | torque high limit of modes 3 and 4, 0.01 % (default 10000) | 0..=10000, above 10 |
//! | 12 | torque rate limit of modes 3 and 4, 0.1 %/s (default 2000); a mode switch and the VFD link's return move at this rate or 50 %/s, the faster | 1..=65535 |
//! | 13 | setpoint filter of modes 3 and 4 (the reference model's time constant), ms (default 200; 0: none) | 0..=10000 |
//! | 14 | law of modes 3 and 4: 0 model-based (feedforward and scheduled PI), 1 PI alone (one gain set) | 0..=1 |
//! | 15 | pressure transmitter's time constant (its damping) and the lags the loop does not model (the drive's), ms (default 80): the loop compares its reading with the reference lagged as much | 0..=10000 |
//! | 16 | flow transmitter's time constant and the lags the loop does not model, ms (default 250) | 0..=10000 |
//! | 17 | pressure loop's closed-loop time constant (IMC λ), ms (default 200): longer is calmer, for plants with a water column or a slow drive | 60..=10000 |
//! | 18 | flow loop's closed-loop time constant, ms (default 300) | 60..=10000 |
//! | 19 | NARMAX models following the load: 0 off (one-step-ahead on the measurements, default), 1 on (each model runs free and an affine map of its output is fitted to the measurements, [`model_core::narmax::adapt`]); writing 0 forgets the maps | 0..=1 |
//! | 20 | the system's static head as the models take it: the pressure the system curve asks at no flow, `Hs(0) = −c` of eq. (8), 0.001 mca, signed (default −252: the paper's bench, its transmitter 0.252 m above the tank's level); a lift (the outlet's level above the suction's) is positive | −10000..=10000 |
//!
//! Holding registers 3 and 4 exist only with a virtual bench ([`ScadaSlave::with_virtual_bench`]):
//! on a board without one they answer exception 02 like any address outside the map, and so
//! does a read or write whose range covers them.
//!
//! Exceptions as the Modbus spec says: 01 illegal function (anything but 03, 04, 06, 16, whatever
//! its fields),
//! 02 illegal data address (a range outside the map), 03 illegal data value (a quantity of 0 or
//! above the limit, a byte count that does not match, a setpoint above 10000, an unknown mode).
//! A write with any bad value changes nothing. Frames with a bad CRC, for another unit
//! (broadcasts included), too short or too long get no answer and leave no state behind.
//!
//! The register map is served by the crate's one Modbus slave engine ([`crate::modbus::serve`]),
//! which gives the silences and the exceptions above (and works around rmodbus's defects).

use crate::control::Commands;
use crate::modbus::{serve, signed_register, unsigned_register, Exception, Frame, RegisterMap};
use crate::protect::{ProtectionConfig, NO_FLOW_TRIP_RANGE_S, OVERSPEED_RANGE_RPM, TRIP_ALL};
use crate::types::{
    Arithmetic, ControlLaw, ControlSettings, InjectedFaults, Mode, Published, STATUS_CORE_BITS,
    VALVE_FACTOR_RANGE,
};

/// Input registers.
pub const INPUT_REGISTERS: usize = 30;
/// Holding registers (0..=20; 3 and 4 only with a virtual bench).
pub const HOLDING_REGISTERS: usize = 21;
/// Holding register 20: the static heads accepted, 0.001 mca (the register read as an
/// `i16`).
pub const STATIC_HEAD_RANGE: core::ops::RangeInclusive<i16> = {
    let max = (crate::control::STATIC_HEAD_MAX_MCA * 1000.0) as i16;
    -max..=max
};
/// Holding register 20's default: the paper's bench, `−c` (−0.252 mca) in 0.001 mca, the
/// core's [`crate::control::STATIC_HEAD_DEFAULT_MCA`] rounded to the register's unit (the
/// controller learns the lift while the register reads it back as that value).
pub const STATIC_HEAD_DEFAULT: i16 = {
    let milli = crate::control::STATIC_HEAD_DEFAULT_MCA * 1000.0;
    (if milli < 0.0 {
        milli - 0.5
    } else {
        milli + 0.5
    }) as i16
};
/// Largest setpoint filter and transmitter time constant (holding registers 13, 15, 16), ms.
pub const SETPOINT_FILTER_MAX_MS: u16 = 10_000;
/// Holding registers 17 and 18: the closed-loop time constants accepted, ms. Below 60 ms
/// (12 control periods) the loops oscillated on the paper's bench (a review: 10 ms on the
/// pressure loop, 30 ms on the flow loop, never settled).
pub const CLOSED_LOOP_RANGE_MS: core::ops::RangeInclusive<u16> = 60..=10_000;
/// The holding registers that exist only with a virtual bench.
pub const BENCH_HOLDING_REGISTERS: core::ops::Range<usize> = 3..5;
/// Virtual bench valve, 0.1 % of nominal k2: nominal.
pub const VALVE_NOMINAL_PERMILLE: u16 = 1000;
/// Virtual bench valve: the range, 0.1 % of nominal k2 (the core's
/// [`crate::types::VALVE_FACTOR_RANGE`] in the register's unit).
pub const VALVE_RANGE_PERMILLE: core::ops::RangeInclusive<u16> =
    (*VALVE_FACTOR_RANGE.start() * 1000.0) as u16..=(*VALVE_FACTOR_RANGE.end() * 1000.0) as u16;
/// Fault injection bit: the virtual pump runs dry.
pub const FAULT_DRY_RUN: u16 = 1 << 0;
/// Fault injection bit: the pressure transmitter at 2 mA.
pub const FAULT_PRESSURE_2MA: u16 = 1 << 1;
/// Fault injection bit: the flow transmitter at 2 mA.
pub const FAULT_FLOW_2MA: u16 = 1 << 2;
/// Fault injection bit: the virtual VFD link cut.
pub const FAULT_VFD_LINK: u16 = 1 << 3;
/// Largest torque setpoint, 0.01 %.
pub const SETPOINT_MAX: u16 = 10_000;

/// Holding register 1 for a mode: 0 stop, 1 manual, 2 profile.
pub fn mode_register(mode: Mode) -> u16 {
    match mode {
        Mode::Stop => 0,
        Mode::Manual => 1,
        Mode::Profile => 2,
        Mode::Pressure => 3,
        Mode::Flow => 4,
    }
}

/// The mode of holding register 1; `None` for a value outside 0..=4.
pub fn mode_from_register(v: u16) -> Option<Mode> {
    match v {
        0 => Some(Mode::Stop),
        1 => Some(Mode::Manual),
        2 => Some(Mode::Profile),
        3 => Some(Mode::Pressure),
        4 => Some(Mode::Flow),
        _ => None,
    }
}

/// The loops' holding registers 8..=18, raw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlRegisters {
    /// 8: pressure setpoint, 0.001 mca.
    pub pressure_setpoint: u16,
    /// 9: flow setpoint, 0.01 l/s.
    pub flow_setpoint: u16,
    /// 10: torque low limit, 0.01 % (0..=10000).
    pub torque_min: u16,
    /// 11: torque high limit, 0.01 % (0..=10000, above 10).
    pub torque_max: u16,
    /// 12: torque rate limit, 0.1 %/s (≥ 1).
    pub rate: u16,
    /// 13: setpoint filter, ms (0..=10000).
    pub filter_ms: u16,
    /// 14: law, 0 model-based, 1 PI alone.
    pub law: u16,
    /// 15: pressure transmitter's time constant, ms (0..=10000).
    pub pressure_lag_ms: u16,
    /// 16: flow transmitter's time constant, ms (0..=10000).
    pub flow_lag_ms: u16,
    /// 17: pressure loop's closed-loop time constant, ms (60..=10000).
    pub pressure_closed_loop_ms: u16,
    /// 18: flow loop's closed-loop time constant, ms (60..=10000).
    pub flow_closed_loop_ms: u16,
}

impl ControlRegisters {
    /// The registers of [`ControlSettings::DEFAULT`].
    pub const DEFAULT: Self = Self {
        pressure_setpoint: 0,
        flow_setpoint: 0,
        torque_min: 0,
        torque_max: SETPOINT_MAX,
        rate: 2000,
        filter_ms: 200,
        law: 0,
        pressure_lag_ms: 80,
        flow_lag_ms: 250,
        pressure_closed_loop_ms: 200,
        flow_closed_loop_ms: 300,
    };

    /// The settings in the core's units.
    pub fn settings(&self) -> ControlSettings {
        ControlSettings {
            pressure_setpoint_mca: f32::from(self.pressure_setpoint) / 1000.0,
            flow_setpoint_lps: f32::from(self.flow_setpoint) / 100.0,
            torque_min_pct: setpoint_pct(self.torque_min),
            torque_max_pct: setpoint_pct(self.torque_max),
            rate_pct_per_s: f32::from(self.rate) / 10.0,
            setpoint_filter_s: f32::from(self.filter_ms) / 1000.0,
            law: if self.law == 1 {
                ControlLaw::Pi
            } else {
                ControlLaw::Model
            },
            pressure_lag_s: f32::from(self.pressure_lag_ms) / 1000.0,
            flow_lag_s: f32::from(self.flow_lag_ms) / 1000.0,
            pressure_closed_loop_s: f32::from(self.pressure_closed_loop_ms) / 1000.0,
            flow_closed_loop_s: f32::from(self.flow_closed_loop_ms) / 1000.0,
        }
    }

    /// The registers are consistent: limits in 0..=10000 with low < high, a rate ≥ 1, a
    /// filter and lags ≤ 10 s, a known law, closed loops in [`CLOSED_LOOP_RANGE_MS`].
    pub fn is_valid(&self) -> bool {
        self.torque_max <= SETPOINT_MAX
            && self.torque_min < self.torque_max
            && self.rate >= 1
            && self.filter_ms <= SETPOINT_FILTER_MAX_MS
            && self.law <= 1
            && self.pressure_lag_ms <= SETPOINT_FILTER_MAX_MS
            && self.flow_lag_ms <= SETPOINT_FILTER_MAX_MS
            && CLOSED_LOOP_RANGE_MS.contains(&self.pressure_closed_loop_ms)
            && CLOSED_LOOP_RANGE_MS.contains(&self.flow_closed_loop_ms)
    }
}

/// Holding register 2 for an arithmetic: 0 f32, 1 Q15.
pub fn arithmetic_register(arithmetic: Arithmetic) -> u16 {
    match arithmetic {
        Arithmetic::F32 => 0,
        Arithmetic::Q15 => 1,
    }
}

/// The arithmetic of holding register 2; `None` for a value outside 0..=1.
pub fn arithmetic_from_register(v: u16) -> Option<Arithmetic> {
    match v {
        0 => Some(Arithmetic::F32),
        1 => Some(Arithmetic::Q15),
        _ => None,
    }
}

/// The virtual bench's valve of holding register 3 (0.1 % of nominal k2, 500..=2000), as a
/// factor of the nominal k2 (0.5..=2).
pub fn valve_factor(register: u16) -> f32 {
    f32::from(register) * 1e-3
}

/// The faults of holding register 4 (its `FAULT_*` bits, the core's bits: checked by
/// `_FAULT_BITS_ARE_THE_CORES`).
pub fn injected_faults(register: u16) -> InjectedFaults {
    InjectedFaults::from_bits(register)
}

const _FAULT_BITS_ARE_THE_CORES: () = assert!(
    FAULT_DRY_RUN == InjectedFaults::DRY_RUN.bits()
        && FAULT_PRESSURE_2MA == InjectedFaults::PRESSURE_2MA.bits()
        && FAULT_FLOW_2MA == InjectedFaults::FLOW_2MA.bits()
        && FAULT_VFD_LINK == InjectedFaults::VFD_LINK.bits(),
    "holding register 4's bits must be the core's InjectedFaults bits"
);

/// The torque setpoint of holding register 0 (0.01 %), in % (register 0..=10000: 0..=100 %;
/// the register's check refuses more).
pub fn setpoint_pct(register: u16) -> f32 {
    // A division, as the core always had it: 5000 → 50.0 exactly, 3333 → 33.33 rounded once.
    f32::from(register) / 100.0
}

/// Holding register 0 (0.01 %) for a torque setpoint in %, rounded to the register's step;
/// `None` unless `pct` is within 0..=100 (NaN included).
pub fn setpoint_register(pct: f32) -> Option<u16> {
    // 100.0 · 100 is exact; the rounding is half away from 0 and never leaves 0..=10000.
    (0.0..=100.0)
        .contains(&pct)
        .then_some((pct * 100.0 + 0.5) as u16)
}

/// Scales values into registers and remembers whether one did not fit (status bit 8).
#[derive(Default)]
struct Fit {
    saturated: bool,
}

impl Fit {
    /// [`unsigned_register`], noting a finite value outside 0..=`max` counts.
    fn unsigned(&mut self, x: f32, scale: f32, max: u16) -> u16 {
        let v = x * scale;
        self.saturated |= v <= -0.5 || v >= f32::from(max) + 0.5;
        unsigned_register(x, scale).min(max)
    }

    /// [`signed_register`], noting a finite value outside −32 768..=32 767 counts.
    fn signed(&mut self, x: f32, scale: f32) -> u16 {
        let v = x * scale;
        self.saturated |= v <= -32768.5 || v >= 32767.5;
        signed_register(x, scale)
    }
}

/// The input registers of the published values (the table in the module docs). A value
/// beyond its register's range reads as the range's end, and sets status bit 8 (saturated).
pub fn input_registers(p: &Published) -> [u16; INPUT_REGISTERS] {
    // One table and one loop, not a call per register: the loop is ≈ 800 B less flash on
    // the M4 than the same calls inlined.
    const U: u16 = u16::MAX;
    let loop_scale = loop_scale(p.status);
    let scaled: [(u8, f32, f32, Option<u16>); 24] = [
        (1, p.torque_pct, 100.0, Some(SETPOINT_MAX)),
        (2, p.pressure_mca, 1000.0, None),
        (3, p.flow_lps, 100.0, Some(U)),
        (4, p.whitebox_pressure_mca, 1000.0, None),
        (5, p.whitebox_flow_lps, 100.0, Some(U)),
        (6, p.whitebox_speed_rpm, 10.0, Some(U)),
        (7, p.narmax_pressure_mca, 1000.0, None),
        (8, p.narmax_flow_lps, 100.0, Some(U)),
        (10, p.whitebox_pressure_residual_mca, 1000.0, None),
        (11, p.whitebox_flow_residual_lps, 100.0, None),
        (12, p.narmax_pressure_residual_mca, 1000.0, None),
        (13, p.narmax_flow_residual_lps, 100.0, None),
        (14, p.vfd_speed_rpm, 10.0, None),
        (15, p.vfd_torque_pct, 100.0, None),
        (18, p.observer_speed_rpm, 10.0, Some(U)),
        (19, p.observer_flow_lps, 100.0, Some(U)),
        (20, p.observer_valve_k2, 1e5, Some(U)),
        (22, p.observer_flow_sd_lps, 100.0, Some(U)),
        (26, p.active_setpoint, loop_scale, None),
        (27, p.control_error, loop_scale, None),
        (28, p.feedforward_pct, 100.0, None),
        (29, p.integral_pct, 100.0, None),
        // The wide twins of 14 and 20: they do not count as saturated (the narrow ones say
        // so), a saturated twin still reads the wide value.
        (24, p.vfd_speed_rpm, 1.0, None),
        (25, p.observer_valve_k2, 1e4, Some(U)),
    ];
    let mut f = Fit::default();
    let mut r = [0u16; INPUT_REGISTERS];
    for (k, &(i, x, scale, max)) in scaled.iter().enumerate() {
        let twin = k >= scaled.len() - 2;
        let saturated_before = f.saturated;
        let v = match max {
            Some(max) => f.unsigned(x, scale, max),
            None => f.signed(x, scale),
        };
        // (Every address in the table is in the block; `get_mut`: no bounds check's panic.)
        if let Some(w) = r.get_mut(usize::from(i)) {
            *w = v;
        }
        if twin {
            f.saturated = saturated_before;
        }
    }
    r[9] = p.sample;
    r[16] = p.vfd_status;
    r[17] = p.uptime_s;
    r[21] = p.alarms;
    r[23] = p.trip_causes;
    r[0] = p.status | (u16::from(f.saturated) << 8);
    r
}

/// Scale of input registers 26 and 27: 1000 (0.001 mca) unless the loop holds a flow
/// (status bit 13), 100 (0.01 l/s).
fn loop_scale(status: u16) -> f32 {
    if crate::types::Status::from_bits(status).holds_flow {
        100.0
    } else {
        1000.0
    }
}

/// The published values back from input registers 0..=23 and 26..=29, as a SCADA client reads them:
/// each within half its register's step of the value published, a saturated one at its
/// range's end (status bit 8, not kept here, says so; the wide twins 24 and 25 are not read).
pub fn published_from_registers(r: &[u16; INPUT_REGISTERS]) -> Published {
    let unsigned = |i: usize, scale: f32| f32::from(r[i]) / scale;
    let signed = |i: usize, scale: f32| f32::from(r[i] as i16) / scale;
    Published {
        status: r[0] & STATUS_CORE_BITS,
        torque_pct: unsigned(1, 100.0),
        pressure_mca: signed(2, 1000.0),
        flow_lps: unsigned(3, 100.0),
        whitebox_pressure_mca: signed(4, 1000.0),
        whitebox_flow_lps: unsigned(5, 100.0),
        whitebox_speed_rpm: unsigned(6, 10.0),
        narmax_pressure_mca: signed(7, 1000.0),
        narmax_flow_lps: unsigned(8, 100.0),
        sample: r[9],
        whitebox_pressure_residual_mca: signed(10, 1000.0),
        whitebox_flow_residual_lps: signed(11, 100.0),
        narmax_pressure_residual_mca: signed(12, 1000.0),
        narmax_flow_residual_lps: signed(13, 100.0),
        vfd_speed_rpm: signed(14, 10.0),
        vfd_torque_pct: signed(15, 100.0),
        vfd_status: r[16],
        uptime_s: r[17],
        observer_speed_rpm: unsigned(18, 10.0),
        observer_flow_lps: unsigned(19, 100.0),
        observer_valve_k2: unsigned(20, 1e5),
        alarms: r[21],
        observer_flow_sd_lps: unsigned(22, 100.0),
        trip_causes: r[23],
        active_setpoint: signed(26, loop_scale(r[0])),
        control_error: signed(27, loop_scale(r[0])),
        feedforward_pct: signed(28, 100.0),
        integral_pct: signed(29, 100.0),
    }
}

/// The slave: its unit address and holding registers; the input registers are handed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScadaSlave {
    unit: u8,
    /// Torque setpoint, 0.01 % (0..=10000).
    pub setpoint: u16,
    /// Mode.
    pub mode: Mode,
    /// NARMAX arithmetic.
    pub arithmetic: Arithmetic,
    /// The NARMAX models follow the load (holding register 19).
    pub narmax_adapt: bool,
    /// Writes of 0 to holding register 19 so far (wraps): each forgets the output maps.
    pub narmax_adapt_offs: u16,
    /// Holding registers 3 and 4 exist (a virtual bench).
    virtual_bench: bool,
    /// Virtual bench valve, 0.1 % of nominal k2 (500..=2000).
    pub valve_permille: u16,
    /// Virtual bench fault injection bits (0..=15).
    pub faults: u16,
    /// Writes of mode 0 (stop) so far (wraps): each acknowledges the latched alarms.
    pub stop_writes: u16,
    /// Writes of the manual setpoint (holding register 0) so far (wraps): each releases
    /// manual mode's hold of an automatic mode's torque, whatever its value.
    pub setpoint_writes: u8,
    /// The protections (holding registers 5..=7).
    pub protection: ProtectionConfig,
    /// The loops' settings (holding registers 8..=18).
    pub control: ControlRegisters,
    /// The system's static head, 0.001 mca as an `i16` in its two's complement (holding
    /// register 20, [`STATIC_HEAD_RANGE`]).
    pub static_head: u16,
    /// Writes of holding register 20 so far (wraps): each sets the models' static head, the
    /// default too (the controller's learnt one then starts afresh).
    pub static_head_writes: u8,
}

impl ScadaSlave {
    /// A slave at `unit` (1..=247), stopped, setpoint 0; `None` for another address.
    pub fn new(unit: u8) -> Option<Self> {
        (1..=247).contains(&unit).then_some(Self {
            unit,
            setpoint: 0,
            mode: Mode::Stop,
            arithmetic: Arithmetic::F32,
            narmax_adapt: false,
            narmax_adapt_offs: 0,
            virtual_bench: false,
            valve_permille: VALVE_NOMINAL_PERMILLE,
            faults: 0,
            stop_writes: 0,
            setpoint_writes: 0,
            protection: ProtectionConfig::DEFAULT,
            control: ControlRegisters::DEFAULT,
            static_head: STATIC_HEAD_DEFAULT as u16,
            static_head_writes: 0,
        })
    }

    /// The slave with holding registers 3 and 4 (the virtual bench's valve and faults).
    pub fn with_virtual_bench(mut self) -> Self {
        self.virtual_bench = true;
        self
    }

    /// The holding registers (3 and 4 exist only with a virtual bench).
    pub fn holding(&self) -> [u16; HOLDING_REGISTERS] {
        [
            self.setpoint,
            mode_register(self.mode),
            arithmetic_register(self.arithmetic),
            self.valve_permille,
            self.faults,
            self.protection.overspeed_rpm,
            self.protection.trip_on,
            self.protection.no_flow_trip_s,
            self.control.pressure_setpoint,
            self.control.flow_setpoint,
            self.control.torque_min,
            self.control.torque_max,
            self.control.rate,
            self.control.filter_ms,
            self.control.law,
            self.control.pressure_lag_ms,
            self.control.flow_lag_ms,
            self.control.pressure_closed_loop_ms,
            self.control.flow_closed_loop_ms,
            u16::from(self.narmax_adapt),
            self.static_head,
        ]
    }

    /// What the holding registers ask of the core, in its units (the setpoint in %).
    pub fn commands(&self) -> Commands {
        Commands {
            mode: self.mode,
            setpoint_pct: setpoint_pct(self.setpoint),
            arithmetic: self.arithmetic,
            narmax_adapt: self.narmax_adapt,
            narmax_adapt_offs: self.narmax_adapt_offs,
            valve_factor: valve_factor(self.valve_permille),
            faults: injected_faults(self.faults),
            stop_writes: self.stop_writes,
            setpoint_writes: self.setpoint_writes,
            protection: self.protection,
            control: self.control.settings(),
            static_head_mca: f32::from(self.static_head as i16) / 1000.0,
            static_head_writes: self.static_head_writes,
        }
    }

    /// The holding registers `start..start + n` all exist on this board.
    fn holding_exist(&self, start: usize, n: usize) -> bool {
        let end = start + n;
        end <= HOLDING_REGISTERS
            && (self.virtual_bench
                || end <= BENCH_HOLDING_REGISTERS.start
                || start >= BENCH_HOLDING_REGISTERS.end)
    }

    /// Handles one received RTU frame (the bytes between two silences), `inputs` being the
    /// input registers (FC 04). Returns the length of the response written to `response`, or
    /// `None` for silence (see the module docs).
    pub fn handle(
        &mut self,
        frame: &[u8],
        inputs: &[u16; INPUT_REGISTERS],
        response: &mut Frame,
    ) -> Option<usize> {
        let unit = self.unit;
        serve(
            unit,
            &mut ScadaMap {
                slave: self,
                inputs,
            },
            frame,
            response,
        )
    }

    /// Applies a write of `values` to the holding registers from `address` on, all or
    /// nothing, as a Modbus FC 16 would (the exception it would answer on refusal): the one
    /// decode of the holding registers, also used by the plant link's in-band writes.
    pub fn write_words(&mut self, address: u16, values: &[u16]) -> Result<(), Exception> {
        let start = usize::from(address);
        if !self.holding_exist(start, values.len()) {
            return Err(Exception::IllegalDataAddress);
        }
        let mut next = *self;
        for (k, &v) in values.iter().enumerate() {
            match start + k {
                0 if v <= SETPOINT_MAX => {
                    next.setpoint = v;
                    next.setpoint_writes = next.setpoint_writes.wrapping_add(1);
                }
                1 => {
                    next.mode = mode_from_register(v).ok_or(Exception::IllegalDataValue)?;
                    if next.mode == Mode::Stop {
                        next.stop_writes = next.stop_writes.wrapping_add(1);
                    }
                }
                2 => {
                    next.arithmetic =
                        arithmetic_from_register(v).ok_or(Exception::IllegalDataValue)?
                }
                3 if VALVE_RANGE_PERMILLE.contains(&v) => next.valve_permille = v,
                4 if v <= 15 => next.faults = v,
                5 if OVERSPEED_RANGE_RPM.contains(&v) => next.protection.overspeed_rpm = v,
                6 if v & !TRIP_ALL == 0 => next.protection.trip_on = v,
                7 if NO_FLOW_TRIP_RANGE_S.contains(&v) => next.protection.no_flow_trip_s = v,
                8 => next.control.pressure_setpoint = v,
                9 => next.control.flow_setpoint = v,
                10 if v <= SETPOINT_MAX => next.control.torque_min = v,
                11 if v <= SETPOINT_MAX => next.control.torque_max = v,
                12 if v >= 1 => next.control.rate = v,
                13 if v <= SETPOINT_FILTER_MAX_MS => next.control.filter_ms = v,
                14 if v <= 1 => next.control.law = v,
                15 if v <= SETPOINT_FILTER_MAX_MS => next.control.pressure_lag_ms = v,
                16 if v <= SETPOINT_FILTER_MAX_MS => next.control.flow_lag_ms = v,
                17 if CLOSED_LOOP_RANGE_MS.contains(&v) => next.control.pressure_closed_loop_ms = v,
                18 if CLOSED_LOOP_RANGE_MS.contains(&v) => next.control.flow_closed_loop_ms = v,
                19 if v <= 1 => {
                    next.narmax_adapt = v == 1;
                    if v == 0 {
                        next.narmax_adapt_offs = next.narmax_adapt_offs.wrapping_add(1);
                    }
                }
                20 if STATIC_HEAD_RANGE.contains(&(v as i16)) => {
                    next.static_head = v;
                    next.static_head_writes = next.static_head_writes.wrapping_add(1);
                }
                _ => return Err(Exception::IllegalDataValue),
            }
        }
        // The limits as a pair: a write that leaves low ≥ high is refused whole.
        if !next.control.is_valid() {
            return Err(Exception::IllegalDataValue);
        }
        *self = next;
        Ok(())
    }
}

/// The SCADA register map for one request: the slave's holding registers and the inputs.
struct ScadaMap<'a> {
    slave: &'a mut ScadaSlave,
    inputs: &'a [u16; INPUT_REGISTERS],
}

impl RegisterMap for ScadaMap<'_> {
    fn read_input_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception> {
        read_words(self.inputs, address, out)
    }

    fn read_holding_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception> {
        if !self.slave.holding_exist(usize::from(address), out.len()) {
            return Err(Exception::IllegalDataAddress);
        }
        read_words(&self.slave.holding(), address, out)
    }

    fn write_holding_registers(&mut self, address: u16, values: &[u16]) -> Result<(), Exception> {
        self.slave.write_words(address, values)
    }
}

/// `out` from `table` at `address`; 02 if the range leaves the table.
fn read_words(table: &[u16], address: u16, out: &mut [u16]) -> Result<(), Exception> {
    let start = usize::from(address);
    let words = table
        .get(start..start + out.len())
        .ok_or(Exception::IllegalDataAddress)?;
    out.copy_from_slice(words);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Holding registers 3 and 4 in the core's units: the valve as a factor, each fault bit
    /// its own flag; the register range is the core's factor range.
    #[test]
    fn bench_registers_in_core_units() {
        assert_eq!([500u16, 1000, 2000].map(valve_factor), [0.5f32, 1.0, 2.0]);
        assert_eq!(VALVE_RANGE_PERMILLE, 500..=2000);
        let bits = [
            FAULT_DRY_RUN,
            FAULT_PRESSURE_2MA,
            FAULT_FLOW_2MA,
            FAULT_VFD_LINK,
        ];
        for (k, &bit) in bits.iter().enumerate() {
            let f = injected_faults(bit);
            let flags = [
                InjectedFaults::DRY_RUN,
                InjectedFaults::PRESSURE_2MA,
                InjectedFaults::FLOW_2MA,
                InjectedFaults::VFD_LINK,
            ]
            .map(|x| f.contains(x));
            assert_eq!(flags.iter().filter(|&&x| x).count(), 1, "{bit}");
            assert!(flags[k], "{bit}");
        }
        assert_eq!(injected_faults(0), InjectedFaults::default());
    }
    use crate::modbus::crc16;
    use crate::types::Status;

    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    fn ask(s: &mut ScadaSlave, f: &[u8]) -> Option<Vec<u8>> {
        let inputs: [u16; INPUT_REGISTERS] = core::array::from_fn(|i| 100 + i as u16);
        let mut r = Frame::new();
        s.handle(f, &inputs, &mut r).map(|n| r[..n].to_vec())
    }

    fn exception(s: &mut ScadaSlave, body: &[u8]) -> u8 {
        let r = ask(s, &frame(body)).expect("an answer");
        assert_eq!(r.len(), 5, "{r:?}");
        assert_eq!(r[1], body[1] | 0x80);
        assert_eq!(crc16(&r[..3]).to_le_bytes(), [r[3], r[4]]);
        r[2]
    }

    #[test]
    fn reads_and_writes() {
        let mut s = ScadaSlave::new(1).unwrap();
        let r = ask(&mut s, &frame(&[1, 4, 0, 0, 0, 10])).unwrap();
        assert_eq!(&r[..3], &[1, 4, 20]);
        assert_eq!(u16::from_be_bytes([r[3], r[4]]), 100);
        assert_eq!(u16::from_be_bytes([r[21], r[22]]), 109);
        // FC 06 setpoint 5000, FC 16 setpoint + mode, read back with FC 03.
        let w = frame(&[1, 6, 0, 0, 0x13, 0x88]);
        assert_eq!(ask(&mut s, &w).unwrap(), w, "FC 06 echoes the request");
        assert_eq!(s.setpoint, 5000);
        let r = ask(&mut s, &frame(&[1, 16, 0, 0, 0, 2, 4, 0x0F, 0xA0, 0, 1])).unwrap();
        assert_eq!(&r[..6], &[1, 16, 0, 0, 0, 2]);
        assert_eq!((s.setpoint, s.mode), (4000, Mode::Manual));
        let r = ask(&mut s, &frame(&[1, 3, 0, 0, 0, 2])).unwrap();
        assert_eq!(&r[..7], &[1, 3, 4, 0x0F, 0xA0, 0, 1]);
        ask(&mut s, &frame(&[1, 6, 0, 2, 0, 1])).unwrap();
        assert_eq!(s.arithmetic, Arithmetic::Q15);
        let r = ask(&mut s, &frame(&[1, 4, 0, 17, 0, 1])).unwrap();
        assert_eq!(&r[..5], &[1, 4, 2, 0, 117]);
        let r = ask(&mut s, &frame(&[1, 4, 0, 22, 0, 1])).unwrap();
        assert_eq!(&r[..5], &[1, 4, 2, 0, 122], "observer registers up to 22");
    }

    #[test]
    fn virtual_bench_registers_exist_only_with_one() {
        let mut board = ScadaSlave::new(1).unwrap();
        assert_eq!(
            exception(&mut board, &[1, 3, 0, 3, 0, 1]),
            2,
            "no bench: 02"
        );
        assert_eq!(exception(&mut board, &[1, 6, 0, 3, 0x05, 0x14]), 2);
        assert_eq!(exception(&mut board, &[1, 6, 0, 4, 0, 1]), 2);
        let mut s = ScadaSlave::new(1).unwrap().with_virtual_bench();
        let r = ask(&mut s, &frame(&[1, 3, 0, 0, 0, 5])).unwrap();
        assert_eq!(&r[..13], &[1, 3, 10, 0, 0, 0, 0, 0, 0, 0x03, 0xE8, 0, 0]);
        let w = frame(&[1, 6, 0, 3, 0x05, 0x14]);
        assert_eq!(ask(&mut s, &w).unwrap(), w);
        assert_eq!(s.valve_permille, 1300);
        assert_eq!(exception(&mut s, &[1, 6, 0, 3, 0x01, 0xF3]), 3, "499");
        assert_eq!(exception(&mut s, &[1, 6, 0, 3, 0x07, 0xD1]), 3, "2001");
        assert_eq!(exception(&mut s, &[1, 6, 0, 4, 0, 16]), 3, "fault bit 4");
        ask(&mut s, &frame(&[1, 6, 0, 4, 0, 0b1010])).unwrap();
        assert_eq!(s.faults, 0b1010);
        assert_eq!(
            exception(&mut s, &[1, 3, 0, HOLDING_REGISTERS as u8 - 1, 0, 2]),
            2,
            "past the map"
        );
    }

    #[test]
    fn protection_registers_on_every_board_with_their_ranges() {
        use crate::protect::ProtectionConfig;
        for mut s in [
            ScadaSlave::new(1).unwrap(),
            ScadaSlave::new(1).unwrap().with_virtual_bench(),
        ] {
            let r = ask(&mut s, &frame(&[1, 3, 0, 5, 0, 3])).unwrap();
            assert_eq!(
                &r[..9],
                &[1, 3, 6, 0x07, 0x85, 0, 3, 0, 30],
                "1925 rpm, 3, 30 s"
            );
            let w = frame(&[1, 16, 0, 5, 0, 3, 6, 0x03, 0xE8, 0, 7, 0, 5]);
            assert_eq!(&ask(&mut s, &w).unwrap()[..6], &[1, 16, 0, 5, 0, 3]);
            assert_eq!(
                s.protection,
                ProtectionConfig {
                    overspeed_rpm: 1000,
                    trip_on: 7,
                    no_flow_trip_s: 5
                }
            );
            for (reg, bad) in [(5u8, 99u16), (5, 4001), (6, 8), (7, 0), (7, 3601)] {
                let [hi, lo] = bad.to_be_bytes();
                assert_eq!(exception(&mut s, &[1, 6, 0, reg, hi, lo]), 3, "{reg}={bad}");
            }
            assert_eq!(
                s.protection.overspeed_rpm, 1000,
                "a refused write changes nothing"
            );
        }
        // On a board, a range over the bench's registers (3, 4) is 02; on either side, fine.
        let mut board = ScadaSlave::new(1).unwrap();
        assert_eq!(exception(&mut board, &[1, 3, 0, 0, 0, 8]), 2);
        assert_eq!(exception(&mut board, &[1, 3, 0, 2, 0, 4]), 2);
        assert_eq!(
            exception(&mut board, &[1, 16, 0, 4, 0, 2, 4, 0, 0, 0x03, 0xE8]),
            2
        );
        assert_eq!(
            &ask(&mut board, &frame(&[1, 3, 0, 0, 0, 3])).unwrap()[..3],
            &[1, 3, 6]
        );
        let mut bench = ScadaSlave::new(1).unwrap().with_virtual_bench();
        assert_eq!(
            &ask(&mut bench, &frame(&[1, 3, 0, 0, 0, 8])).unwrap()[..3],
            &[1, 3, 16]
        );
    }

    /// The control registers' defaults are the core's ([`ControlSettings::DEFAULT`]: one
    /// set of defaults, two units), registers 17 and 18 take 60..=10000 ms and nothing else,
    /// and reach the loop in seconds.
    #[test]
    fn control_registers_defaults_ranges_and_units() {
        assert_eq!(
            ControlRegisters::DEFAULT.settings(),
            ControlSettings::DEFAULT
        );
        let mut s = ScadaSlave::new(1).unwrap();
        for reg in [17u8, 18] {
            for bad in [0u16, 9, 59, 10_001, u16::MAX] {
                let [hi, lo] = bad.to_be_bytes();
                assert_eq!(exception(&mut s, &[1, 6, 0, reg, hi, lo]), 3, "{reg}={bad}");
            }
            for good in [60u16, 500, 10_000] {
                let [hi, lo] = good.to_be_bytes();
                let w = frame(&[1, 6, 0, reg, hi, lo]);
                assert_eq!(ask(&mut s, &w).unwrap(), w, "{reg}={good}");
                let c = s.control.settings();
                let got = if reg == 17 {
                    c.pressure_closed_loop_s
                } else {
                    c.flow_closed_loop_s
                };
                assert_eq!(got, f32::from(good) / 1000.0);
            }
        }
    }

    /// Regression (defect 4 of the protection issue): register 14 held a runaway drive at
    /// 3 276.7 rpm and register 20 a k2 above 0.65535 at 0.65535, with nothing to say so.
    #[test]
    fn saturation_is_flagged_and_the_wide_registers_hold_the_value() {
        let ok = Published {
            vfd_speed_rpm: 1750.0,
            observer_valve_k2: 0.1082,
            ..Published::default()
        };
        let r = input_registers(&ok);
        assert_eq!(r[0] & 1 << 8, 0);
        assert_eq!((r[14], r[24], r[20], r[25]), (17500, 1750, 10820, 1082));
        let fast = Published {
            vfd_speed_rpm: 5123.4,
            ..ok
        };
        let r = input_registers(&fast);
        assert_eq!(r[0] & 1 << 8, 1 << 8, "saturated");
        assert_eq!((r[14], r[24]), (32767, 5123));
        let closed = Published {
            observer_valve_k2: 0.9,
            ..ok
        };
        let r = input_registers(&closed);
        assert_eq!(r[0] & 1 << 8, 1 << 8);
        assert_eq!((r[20], r[25]), (65535, 9000));
        let back = Published {
            vfd_speed_rpm: -3300.0,
            ..ok
        };
        assert_eq!(input_registers(&back)[0] & 1 << 8, 1 << 8, "negative too");
        assert_eq!(input_registers(&back)[24] as i16, -3300);
    }

    #[test]
    fn spec_exceptions() {
        let mut s = ScadaSlave::new(1).unwrap();
        assert_eq!(
            exception(&mut s, &[1, 1, 0, 0, 0, 1]),
            1,
            "coils: illegal function"
        );
        assert_eq!(
            exception(&mut s, &[1, 0x2B, 0x0E, 1, 0]),
            1,
            "unknown function"
        );
        assert_eq!(
            exception(&mut s, &[1, 4, 0, INPUT_REGISTERS as u8 - 1, 0, 2]),
            2,
            "past the input map"
        );
        assert_eq!(
            exception(&mut s, &[1, 3, 0, 3, 0, 1]),
            2,
            "the bench's holding registers on a board"
        );
        assert_eq!(
            exception(&mut s, &[1, 6, 0, HOLDING_REGISTERS as u8, 0, 1]),
            2,
            "write past the map"
        );
        assert_eq!(exception(&mut s, &[1, 4, 0, 0, 0, 0]), 3, "zero quantity");
        assert_eq!(
            exception(&mut s, &[1, 4, 0, 0, 0, 126]),
            3,
            "quantity above 125"
        );
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 0, 0x27, 0x11]),
            3,
            "setpoint 10001"
        );
        assert_eq!(exception(&mut s, &[1, 6, 0, 1, 0, 5]), 3, "mode 5");
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 10, 0x27, 0x10]),
            3,
            "low limit 100 %"
        );
        assert_eq!(exception(&mut s, &[1, 6, 0, 11, 0, 0]), 3, "high limit 0 %");
        assert_eq!(exception(&mut s, &[1, 6, 0, 12, 0, 0]), 3, "rate 0");
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 13, 0x27, 0x11]),
            3,
            "filter 10.001 s"
        );
        assert_eq!(exception(&mut s, &[1, 6, 0, 14, 0, 2]), 3, "law 2");
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 16, 0x27, 0x11]),
            3,
            "flow lag 10.001 s"
        );
        // The limits as a pair: low and high crossed in one write, refused whole.
        assert_eq!(
            exception(&mut s, &[1, 16, 0, 10, 0, 2, 4, 0x13, 0x88, 0x03, 0xE8]),
            3
        );
        assert_eq!(s.control, ControlRegisters::DEFAULT);
        assert_eq!(
            ControlRegisters::DEFAULT.settings(),
            ControlSettings::DEFAULT
        );
        assert_eq!(exception(&mut s, &[1, 6, 0, 2, 0, 2]), 3, "arithmetic 2");
        // Regression (hostile run): an unsupported function is 01 whatever its fields; an
        // oversized quantity in FC 01, 02 or 15 used to answer 03 (rmodbus's own check).
        for body in [
            &[1, 1, 0, 0, 0x07, 0xD1][..],
            &[1, 2, 0, 0, 0xFF, 0xFF],
            &[1, 0x0F, 0, 0, 0x07, 0xB1, 1, 0xFF],
            &[1, 5, 0, 0, 0x12, 0x34],
            &[1, 0x0F, 0, 0, 0, 0, 0],
        ] {
            assert_eq!(exception(&mut s, body), 1, "{body:02x?}");
        }
        assert_eq!(
            exception(&mut s, &[1, 16, 0, 0, 0, 2, 2, 0, 1]),
            3,
            "byte count"
        );
        // A write with one bad value changes nothing.
        assert_eq!(exception(&mut s, &[1, 16, 0, 0, 0, 2, 4, 0, 100, 0, 9]), 3);
        assert_eq!((s.setpoint, s.mode), (0, Mode::Stop));
    }

    /// Regression set of malformed frames: silence, no state change, and the next valid
    /// request is answered.
    #[test]
    fn malformed_frames_get_silence_and_do_not_disturb() {
        let mut s = ScadaSlave::new(1).unwrap();
        let good = frame(&[1, 6, 0, 0, 0, 7]);
        let mut bad_crc = good.clone();
        bad_crc[7] ^= 0xFF;
        let mut long = good.clone();
        long.push(0);
        let mut unknown_bad_crc = frame(&[1, 0x2B, 0x0E, 1, 0]);
        unknown_bad_crc[5] ^= 1;
        let cases: Vec<Vec<u8>> = vec![
            frame(&[1, 0x85, 0, 0, 0, 1]),
            vec![],
            vec![1],
            vec![1, 6, 0],
            good[..7].to_vec(),
            bad_crc,
            long,
            unknown_bad_crc,
            frame(&[2, 6, 0, 0, 0, 7]),
            frame(&[0, 6, 0, 0, 0, 7]),
            frame(&[1, 16, 0, 0, 0, 1, 2, 0]),
            vec![0xFF; 300],
        ];
        for f in &cases {
            assert_eq!(ask(&mut s, f), None, "{f:?}");
            assert_eq!((s.setpoint, s.mode), (0, Mode::Stop), "{f:?}");
        }
        assert_eq!(ask(&mut s, &good).unwrap(), good);
        assert_eq!(s.setpoint, 7);
    }

    /// Holding register 19: the NARMAX models following the load, off by default, 0..=1.
    #[test]
    fn register_19_switches_the_models_following_the_load() {
        let mut s = ScadaSlave::new(1).unwrap();
        assert!(!s.commands().narmax_adapt);
        assert_eq!(s.holding()[19], 0);
        ask(&mut s, &frame(&[1, 6, 0, 19, 0, 1])).unwrap();
        assert!(s.commands().narmax_adapt);
        let r = ask(&mut s, &frame(&[1, 3, 0, 19, 0, 1])).unwrap();
        assert_eq!(&r[..5], &[1, 3, 2, 0, 1]);
        assert_eq!(exception(&mut s, &[1, 6, 0, 19, 0, 2]), 3, "adaptation 2");
        assert!(s.commands().narmax_adapt, "a refused write changes nothing");
        ask(&mut s, &frame(&[1, 6, 0, 19, 0, 0])).unwrap();
        assert!(!s.commands().narmax_adapt);
        assert_eq!(
            exception(&mut s, &[1, 3, 0, 20, 0, 2]),
            2,
            "nothing after 20"
        );
    }

    /// Holding register 20: the static head, signed 0.001 mca, the paper's −0.252 mca by
    /// default (read back as the core's default to the bit: the value at which the
    /// controller learns the lift, itself the paper's c), −10..=10 mca and nothing else.
    #[test]
    fn register_20_is_the_static_head_signed() {
        let mut s = ScadaSlave::new(1).unwrap();
        assert_eq!(s.holding()[20], (-252i16) as u16);
        let mca = s.commands().static_head_mca;
        assert_eq!(mca, crate::control::STATIC_HEAD_DEFAULT_MCA);
        assert_eq!(
            -mca,
            model_core::BenchParams::<f32>::PAPER.static_head_c_mca
        );
        for (v, mca) in [
            (1500i16, 1.5f32),
            (-10_000, -10.0),
            (10_000, 10.0),
            (0, 0.0),
        ] {
            let [hi, lo] = v.to_be_bytes();
            ask(&mut s, &frame(&[1, 6, 0, 20, hi, lo])).unwrap();
            assert_eq!(s.commands().static_head_mca, mca);
            let r = ask(&mut s, &frame(&[1, 3, 0, 20, 0, 1])).unwrap();
            assert_eq!(&r[3..5], &[hi, lo]);
        }
        for v in [10_001i16, -10_001, i16::MIN, i16::MAX] {
            let [hi, lo] = v.to_be_bytes();
            assert_eq!(exception(&mut s, &[1, 6, 0, 20, hi, lo]), 3, "{v}");
            assert_eq!(
                s.commands().static_head_mca,
                0.0,
                "a refused write changes nothing"
            );
        }
    }

    /// The holding registers ↔ the core's types: every valid register value round trips, and
    /// the wire codes are the table's.
    #[test]
    fn holding_registers_round_trip_through_the_core_types() {
        for v in 0..=u16::MAX {
            if let Some(m) = mode_from_register(v) {
                assert_eq!(mode_register(m), v);
            }
            if let Some(a) = arithmetic_from_register(v) {
                assert_eq!(arithmetic_register(a), v);
            }
            if v <= SETPOINT_MAX {
                assert_eq!(setpoint_register(setpoint_pct(v)), Some(v), "{v}");
            }
        }
        let modes = [
            Mode::Stop,
            Mode::Manual,
            Mode::Profile,
            Mode::Pressure,
            Mode::Flow,
        ];
        assert_eq!(modes.map(mode_register), [0, 1, 2, 3, 4]);
        assert_eq!(
            modes.map(|m| mode_from_register(mode_register(m))),
            modes.map(Some)
        );
        assert_eq!(mode_from_register(5), None);
        assert_eq!(
            [Arithmetic::F32, Arithmetic::Q15].map(arithmetic_register),
            [0, 1]
        );
        assert_eq!(arithmetic_from_register(2), None);
        // The setpoint as the core always read it: register / 100, a division.
        assert_eq!(setpoint_pct(5000), 50.0);
        assert_eq!(setpoint_pct(3333).to_bits(), (3333.0f32 / 100.0).to_bits());
        assert_eq!(setpoint_register(33.334), Some(3333));
        assert_eq!(setpoint_register(100.0), Some(SETPOINT_MAX));
        for bad in [-0.01, 100.01, f32::NAN, f32::INFINITY] {
            assert_eq!(setpoint_register(bad), None, "{bad}");
        }
        // The slave hands the core the setpoint in %.
        let mut s = ScadaSlave::new(1).unwrap();
        ask(
            &mut s,
            &frame(&[1, 16, 0, 0, 0, 3, 6, 0x0D, 0x05, 0, 1, 0, 1]),
        )
        .unwrap();
        let c = s.commands();
        assert_eq!(
            (c.setpoint_pct, c.mode, c.arithmetic),
            (33.33, Mode::Manual, Arithmetic::Q15)
        );
    }

    /// The input registers read back within half their step of the values published.
    #[test]
    fn input_registers_round_trip_within_half_a_step() {
        let p = Published {
            status: Status {
                running: true,
                vfd_link_ok: true,
                tripped: true,
                ..Status::default()
            }
            .bits(),
            torque_pct: 47.123,
            pressure_mca: -0.25,
            flow_lps: 15.776,
            whitebox_pressure_mca: 2.6604,
            whitebox_flow_lps: 15.3,
            whitebox_speed_rpm: 1629.14,
            narmax_pressure_mca: 2.7,
            narmax_flow_lps: 15.2,
            sample: 65535,
            whitebox_pressure_residual_mca: -0.0125,
            whitebox_flow_residual_lps: 0.47,
            narmax_pressure_residual_mca: 0.004,
            narmax_flow_residual_lps: -0.58,
            vfd_speed_rpm: -12.34,
            vfd_torque_pct: 48.0,
            vfd_status: 0xBEEF,
            uptime_s: 7,
            observer_speed_rpm: 1630.0,
            observer_flow_lps: 15.5,
            observer_valve_k2: 0.1082,
            alarms: 0x1FF,
            observer_flow_sd_lps: 0.3,
            trip_causes: 0x18,
            active_setpoint: 3.1234,
            control_error: -0.0456,
            feedforward_pct: 41.237,
            integral_pct: -3.21,
        };
        let r = input_registers(&p);
        assert_eq!(r[0] & 1 << 8, 0, "nothing saturated");
        let q = published_from_registers(&r);
        let fields = |x: &Published| {
            [
                (x.torque_pct, 100.0),
                (x.pressure_mca, 1000.0),
                (x.flow_lps, 100.0),
                (x.whitebox_pressure_mca, 1000.0),
                (x.whitebox_flow_lps, 100.0),
                (x.whitebox_speed_rpm, 10.0),
                (x.narmax_pressure_mca, 1000.0),
                (x.narmax_flow_lps, 100.0),
                (x.whitebox_pressure_residual_mca, 1000.0),
                (x.whitebox_flow_residual_lps, 100.0),
                (x.narmax_pressure_residual_mca, 1000.0),
                (x.narmax_flow_residual_lps, 100.0),
                (x.vfd_speed_rpm, 10.0),
                (x.vfd_torque_pct, 100.0),
                (x.observer_speed_rpm, 10.0),
                (x.observer_flow_lps, 100.0),
                (x.observer_valve_k2, 1e5),
                (x.observer_flow_sd_lps, 100.0),
                (x.active_setpoint, 1000.0),
                (x.control_error, 1000.0),
                (x.feedforward_pct, 100.0),
                (x.integral_pct, 100.0),
            ]
        };
        for (k, ((a, scale), (b, _))) in fields(&p).into_iter().zip(fields(&q)).enumerate() {
            assert!((a - b).abs() * scale <= 0.5 + 1e-3, "field {k}: {a} → {b}");
        }
        let words = |x: &Published| {
            [
                x.status,
                x.sample,
                x.vfd_status,
                x.uptime_s,
                x.alarms,
                x.trip_causes,
            ]
        };
        assert_eq!(words(&q), words(&p), "the words exactly");
        assert_eq!(input_registers(&q), r, "and back to the same registers");
    }

    #[test]
    fn registers_are_scaled_clamped_and_finite() {
        let p = Published {
            status: Status {
                running: true,
                flow_fault: true,
                ..Status::default()
            }
            .bits(),
            torque_pct: 150.0,
            pressure_mca: -0.25,
            flow_lps: f32::NAN,
            whitebox_pressure_mca: 1e9,
            whitebox_flow_lps: -3.0,
            whitebox_speed_rpm: 1629.14,
            narmax_pressure_mca: 2.6604,
            narmax_flow_lps: 15.776,
            sample: 65535,
            whitebox_pressure_residual_mca: -0.0125,
            vfd_speed_rpm: -12.34,
            vfd_status: 0xBEEF,
            uptime_s: 7,
            ..Published::default()
        };
        let r = input_registers(&p);
        assert_eq!(r[0], 0b1_0010_0001, "saturated: 150 % and 1e9 mca");
        assert_eq!(r[1], 10_000);
        assert_eq!(r[2] as i16, -250);
        assert_eq!(r[3], 0);
        assert_eq!(r[4] as i16, i16::MAX);
        assert_eq!(r[5], 0);
        assert_eq!(r[6], 16291);
        assert_eq!(r[7], 2660);
        assert_eq!(r[8], 1578);
        assert_eq!(r[9], 65535);
        assert_eq!(r[10] as i16, -13);
        assert_eq!(r[11], 0);
        assert_eq!(r[14] as i16, -123);
        assert_eq!((r[16], r[17]), (0xBEEF, 7));
        assert!(ScadaSlave::new(0).is_none() && ScadaSlave::new(248).is_none());
    }
}
