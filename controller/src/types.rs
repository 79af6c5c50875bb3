//! The real-time core's own types: how it is told to run ([`Mode`], [`Arithmetic`]) and what
//! it publishes ([`Published`], with its [`Status`] flags), in the core's units (%, mca, l/s,
//! rpm). The core ([`crate::control`]) knows nothing of Modbus: the SCADA register map
//! ([`crate::scada`]) converts these to and from its registers at the edge.

/// Operating mode: what the torque reference follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Torque reference 0.
    #[default]
    Stop,
    /// Torque reference = the setpoint ([`crate::control::Commands::setpoint_pct`]).
    Manual,
    /// The built-in excitation profile (the paper's pulses).
    Profile,
    /// Pressure control: the loop holds the outlet pressure at
    /// [`ControlSettings::pressure_setpoint_mca`] ([`crate::regulate`]).
    Pressure,
    /// Flow control: the loop holds the flow at [`ControlSettings::flow_setpoint_lps`].
    Flow,
}

impl Mode {
    /// The name used in logs: `stop`, `manual` or `profile`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Stop => "stop",
            Mode::Manual => "manual",
            Mode::Profile => "profile",
            Mode::Pressure => "pressure",
            Mode::Flow => "flow",
        }
    }

    /// The mode holds a pressure or a flow in closed loop.
    pub fn regulates(self) -> bool {
        matches!(self, Mode::Pressure | Mode::Flow)
    }
}

/// The law of the pressure and flow loops ([`crate::regulate`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlLaw {
    /// The default: the white-box model's steady-state inverse at the observer's load as
    /// feedforward, plus a PI whose gains are scheduled on the model's local gain and time
    /// constant.
    #[default]
    Model,
    /// A PI alone with one gain set for the whole range, as a drive ships it: the comparison.
    Pi,
}

impl ControlLaw {
    /// Its name: `model`, `pi`.
    pub fn name(self) -> &'static str {
        match self {
            ControlLaw::Model => "model",
            ControlLaw::Pi => "pi",
        }
    }

    /// The law of a name ([`ControlLaw::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "model" => Some(ControlLaw::Model),
            "pi" => Some(ControlLaw::Pi),
            _ => None,
        }
    }
}

/// The pressure and flow loops' settings (SCADA holding registers 8..=18), in the core's
/// units.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlSettings {
    /// Pressure setpoint of mode 3, mca (0..=65.535).
    pub pressure_setpoint_mca: f32,
    /// Flow setpoint of mode 4, l/s (0..=655.35).
    pub flow_setpoint_lps: f32,
    /// Lowest torque reference the loops give, % (0..=100, below `torque_max_pct`).
    pub torque_min_pct: f32,
    /// Highest torque reference the loops give, % (0..=100).
    pub torque_max_pct: f32,
    /// Torque rate limit of the loops, %/s (0.1..=6 553.5); a mode switch moves at this rate
    /// or [`crate::control::SWITCH_RATE_MIN_PCT_PER_S`], the faster.
    pub rate_pct_per_s: f32,
    /// Time constant of the setpoint's first-order reference model, s (0..=10; 0: the
    /// setpoint goes straight in).
    pub setpoint_filter_s: f32,
    /// The loops' law.
    pub law: ControlLaw,
    /// The pressure transmitter's time constant (its damping), s (0..=10): the loop compares
    /// the reading with its reference lagged as much.
    pub pressure_lag_s: f32,
    /// The flow transmitter's time constant, s (0..=10).
    pub flow_lag_s: f32,
    /// The closed-loop time constant asked of the pressure loop (IMC λ), s (0.01..=10): the
    /// model's PI gains are `τ / (K λ)`, the PI alone's scale as `1 / λ`. Longer is calmer:
    /// for plants whose lags the model lacks (a water column, a slow drive).
    pub pressure_closed_loop_s: f32,
    /// The same for the flow loop, s (0.01..=10).
    pub flow_closed_loop_s: f32,
}

impl ControlSettings {
    /// Defaults: setpoints 0, torque 0..=100 %, 200 %/s, a 0.2 s setpoint filter, the
    /// model-based law, lags of 80 ms (pressure) and 250 ms (flow), closed loops of 0.2 s
    /// (pressure) and 0.3 s (flow): on plants whose
    /// transmitters and drives lag 20..110 ms (pressure) and 40..170 ms (flow) the loops held
    /// their targets better erring long than short (docs/control.md).
    pub const DEFAULT: Self = Self {
        pressure_setpoint_mca: 0.0,
        flow_setpoint_lps: 0.0,
        torque_min_pct: 0.0,
        torque_max_pct: 100.0,
        rate_pct_per_s: 200.0,
        setpoint_filter_s: 0.2,
        law: ControlLaw::Model,
        pressure_lag_s: 0.08,
        flow_lag_s: 0.25,
        pressure_closed_loop_s: crate::regulate::PRESSURE_CLOSED_LOOP_S,
        flow_closed_loop_s: crate::regulate::FLOW_CLOSED_LOOP_S,
    };
}

impl Default for ControlSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Arithmetic of the NARMAX pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Arithmetic {
    /// f32 forward pass (`NarxF32`).
    #[default]
    F32,
    /// Q15 fixed-point forward pass (`NarxQ15`).
    Q15,
}

impl Arithmetic {
    /// The name used in logs and options: `f32` or `q15`.
    pub fn name(self) -> &'static str {
        match self {
            Arithmetic::F32 => "f32",
            Arithmetic::Q15 => "q15",
        }
    }

    /// The arithmetic of a [`Self::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "f32" => Some(Arithmetic::F32),
            "q15" => Some(Arithmetic::Q15),
            _ => None,
        }
    }
}

/// The controller's status flags, and their word ([`Status::bits`], SCADA input register 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Bit 0: the drive is commanded to run (and not held at 0 % by a trip), or a torque is
    /// still applied (a stop's ramp).
    pub running: bool,
    /// Bit 1: any alarm.
    pub any_alarm: bool,
    /// Bit 2: a model runs outside its fitted/training range.
    pub extrapolating: bool,
    /// Bit 3: the VFD link delivers the torque reference (no link alarm).
    pub vfd_link_ok: bool,
    /// Bit 4: pressure transmitter fault (NAMUR NE 43).
    pub pressure_fault: bool,
    /// Bit 5: flow transmitter fault.
    pub flow_fault: bool,
    /// Bit 6: the drive's readings are invalid (its reads fail, or the link is down): the
    /// controller is blind to the drive, and its readings are published as 0.
    pub vfd_readings_invalid: bool,
    /// Bit 7: a protection holds the torque at 0 % ([`crate::protect`]): tripped (the causes in
    /// input register 23), or, once the trip has cleared, until mode 0 is written (a restart
    /// takes a mode written after the trip cleared; register 23 then reads 0).
    pub tripped: bool,
    /// Bit 9: a pressure or flow loop is in control (mode 3 or 4, running, the link up, a
    /// measurement to act on).
    pub in_control: bool,
    /// Bit 10: the loop's torque is held at a limit (range or rate).
    pub limited: bool,
    /// Bit 11: the loop acts on the observer's flow or pressure (its transmitter in fault).
    pub virtual_measurement: bool,
    /// Bit 12: the loop lost its measurement and holds the last torque (pressure transmitter
    /// in fault and the observer's pressure not trustworthy).
    pub control_held: bool,
    /// Bit 13: the loop holds a flow (mode 4): input registers 26 and 27 are in 0.01 l/s,
    /// else in 0.001 mca.
    pub holds_flow: bool,
}

/// Status bits the core owns ([`Status::bits`]); bit 8 is the register map's (saturated).
pub const STATUS_CORE_BITS: u16 = 0x3EFF;

impl Status {
    /// The word: flag k in bit k (0..=7 and 9..=13, [`STATUS_CORE_BITS`]); the others are 0.
    pub fn bits(&self) -> u16 {
        // Shifts written out: the fold over an array was a call of ≈ 68 instructions in
        // every 1 ms step on the M4.
        u16::from(self.running)
            | u16::from(self.any_alarm) << 1
            | u16::from(self.extrapolating) << 2
            | u16::from(self.vfd_link_ok) << 3
            | u16::from(self.pressure_fault) << 4
            | u16::from(self.flow_fault) << 5
            | u16::from(self.vfd_readings_invalid) << 6
            | u16::from(self.tripped) << 7
            | u16::from(self.in_control) << 9
            | u16::from(self.limited) << 10
            | u16::from(self.virtual_measurement) << 11
            | u16::from(self.control_held) << 12
            | u16::from(self.holds_flow) << 13
    }

    /// The bits back as flags (bits this struct has no flag for are ignored).
    pub fn from_bits(bits: u16) -> Self {
        let b = |i: u32| bits & (1 << i) != 0;
        Self {
            running: b(0),
            any_alarm: b(1),
            extrapolating: b(2),
            vfd_link_ok: b(3),
            pressure_fault: b(4),
            flow_fault: b(5),
            vfd_readings_invalid: b(6),
            tripped: b(7),
            in_control: b(9),
            limited: b(10),
            virtual_measurement: b(11),
            control_held: b(12),
            holds_flow: b(13),
        }
    }
}

/// The virtual bench's valve, as a factor of the nominal k2: its range.
pub const VALVE_FACTOR_RANGE: core::ops::RangeInclusive<f32> = 0.5..=2.0;

/// Faults injected into the virtual bench (a test facility: a real board ignores them), one
/// bit each (a word, not four flags: the control task copies its commands every step).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InjectedFaults(u16);

impl InjectedFaults {
    /// The pump runs dry (no water: friction only).
    pub const DRY_RUN: Self = Self(1 << 0);
    /// The pressure transmitter reads 2 mA (NE 43: a fault).
    pub const PRESSURE_2MA: Self = Self(1 << 1);
    /// The flow transmitter reads 2 mA.
    pub const FLOW_2MA: Self = Self(1 << 2);
    /// The VFD link is cut.
    pub const VFD_LINK: Self = Self(1 << 3);
    /// All four.
    pub const ALL: Self = Self(0b1111);

    /// The faults of a bit word (bits other than the four are dropped).
    pub const fn from_bits(bits: u16) -> Self {
        Self(bits & Self::ALL.0)
    }

    /// The bit word.
    pub const fn bits(self) -> u16 {
        self.0
    }

    /// Whether every fault of `other` is injected.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
}

/// What the controller publishes, in engineering units (the SCADA register map scales and
/// clamps them: [`crate::scada::input_registers`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Published {
    /// Status flags, [`Status::bits`]. A word, not the flags: the struct stays free of
    /// padding, so the 1 ms step copies it by words (with a padding byte at its end LLVM
    /// copied it byte by byte, ≈ 370 instructions per step on the M4).
    pub status: u16,
    /// Applied torque reference, % (0..=100).
    pub torque_pct: f32,
    /// Measured pressure, mca (the transmitter's span, or the last good value in fault).
    pub pressure_mca: f32,
    /// Measured flow, l/s (as the pressure).
    pub flow_lps: f32,
    /// White-box predicted pressure, mca.
    pub whitebox_pressure_mca: f32,
    /// White-box predicted flow, l/s.
    pub whitebox_flow_lps: f32,
    /// White-box speed, rpm.
    pub whitebox_speed_rpm: f32,
    /// NARMAX predicted pressure, mca.
    pub narmax_pressure_mca: f32,
    /// NARMAX predicted flow, l/s.
    pub narmax_flow_lps: f32,
    /// Pressure samples taken so far (wraps).
    pub sample: u16,
    /// White-box pressure residual (measured − predicted), mca; 0 in fault.
    pub whitebox_pressure_residual_mca: f32,
    /// White-box flow residual, l/s; 0 in fault.
    pub whitebox_flow_residual_lps: f32,
    /// NARMAX pressure residual, mca; 0 in fault.
    pub narmax_pressure_residual_mca: f32,
    /// NARMAX flow residual, l/s; 0 in fault.
    pub narmax_flow_residual_lps: f32,
    /// VFD actual speed, rpm (0 while its readings are invalid).
    pub vfd_speed_rpm: f32,
    /// VFD actual torque, % (0 while its readings are invalid).
    pub vfd_torque_pct: f32,
    /// VFD status word, the vendor's bits (0 while its readings are invalid).
    pub vfd_status: u16,
    /// Uptime, s (wraps).
    pub uptime_s: u16,
    /// Observer speed, rpm.
    pub observer_speed_rpm: f32,
    /// Observer flow, l/s.
    pub observer_flow_lps: f32,
    /// Observer valve coefficient k2, √mca/(l/s).
    pub observer_valve_k2: f32,
    /// Alarm bits ([`model_core::monitor`]).
    pub alarms: u16,
    /// Observer flow standard deviation, l/s.
    pub observer_flow_sd_lps: f32,
    /// The alarm bits that tripped the controller (0: not tripped).
    pub trip_causes: u16,
    /// The loop's active setpoint (the reference model's output), mca in mode 3, l/s in mode
    /// 4; 0 in the other modes.
    pub active_setpoint: f32,
    /// The loop's control error (active setpoint − measured), as `active_setpoint`.
    pub control_error: f32,
    /// The loop's feedforward part, %.
    pub feedforward_pct: f32,
    /// The loop's integral part, %.
    pub integral_pct: f32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_bits_round_trip_each_flag_in_its_bit() {
        for bits in 0..=u16::MAX {
            let s = Status::from_bits(bits);
            assert_eq!(s.bits(), bits & STATUS_CORE_BITS, "{bits:#x}");
            assert_eq!(Status::from_bits(s.bits()), s);
        }
        let one = Status {
            vfd_readings_invalid: true,
            ..Status::default()
        };
        assert_eq!(one.bits(), 1 << 6);
        assert_eq!(
            Status {
                running: true,
                ..Status::default()
            }
            .bits(),
            1
        );
    }

    #[test]
    fn arithmetic_names_round_trip() {
        for a in [Arithmetic::F32, Arithmetic::Q15] {
            assert_eq!(Arithmetic::from_name(a.name()), Some(a));
        }
        assert_eq!(Arithmetic::Q15.name(), "q15");
        assert_eq!(Arithmetic::from_name("fixed"), None);
    }

    /// The 1 ms step copies `Published` into its outputs: no padding (see its `status`). A
    /// field added must keep the u16 fields even in number (or measure the step). And it
    /// must stay at 100 bytes or under: one f32 more (104 B) made the copy a byte loop on the
    /// M4, +800 instructions a tick (`cargo xtask bench`, tick_mean 1 288 → 2 097).
    #[test]
    fn published_is_the_sum_of_its_fields() {
        use core::mem::size_of;
        assert_eq!(
            size_of::<Published>(),
            22 * size_of::<f32>() + 6 * size_of::<u16>()
        );
    }
}
