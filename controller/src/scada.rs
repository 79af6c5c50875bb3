//! The SCADA side: a Modbus RTU slave with the controller's register map.
//!
//! | input register (FC 04) | meaning | unit |
//! |---|---|---|
//! | 0 | status bits: 0 running (commanded to run and not held at 0 % by a trip), 1 any alarm, 2 model extrapolating, 3 VFD link ok (the torque reference is delivered), 4 pressure transmitter fault, 5 flow transmitter fault, 6 VFD readings invalid (reads fail: registers 14-16 read 0), 7 tripped (the torque is held at 0 %: [`crate::protect`]), 8 saturated (a value in this map is beyond its register's range and reads as the range's end) | |
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
//!
//! | holding register (FC 03, 06, 16) | meaning | range |
//! |---|---|---|
//! | 0 | torque setpoint, 0.01 % | 0..=10000 |
//! | 1 | mode: 0 stop, 1 manual setpoint, 2 built-in excitation profile; writing 0 also acknowledges the latched alarms whose cause has gone | 0..=2 |
//! | 2 | NARMAX arithmetic: 0 f32, 1 fixed point | 0..=1 |
//! | 3 | virtual bench only: its valve, k2 in 0.1 % of nominal (1000 = nominal) | 500..=2000 |
//! | 4 | virtual bench only: fault injection bits: 0 dry run, 1 pressure transmitter at 2 mA, 2 flow transmitter at 2 mA, 3 VFD link cut | 0..=15 |
//! | 5 | overspeed limit, rpm (default 1925: 110 % of the nominal 1 750) | 100..=4000 |
//! | 6 | what trips ([`crate::protect`]): bit 0 dry run, bit 1 overspeed, bit 2 no flow; 1 trips to 0 %, 0 warns (default 3) | 0..=7 |
//! | 7 | no-flow trip delay: how long the no-flow alarm stands before it trips, if bit 2 of 6 is set (default 30) | 1..=3600 s |
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

use crate::modbus::{serve, signed_register, unsigned_register, Exception, Frame, RegisterMap};
use crate::protect::{ProtectionConfig, NO_FLOW_TRIP_RANGE_S, OVERSPEED_RANGE_RPM, TRIP_ALL};

/// Input registers.
pub const INPUT_REGISTERS: usize = 26;
/// Holding registers (0..=7; 3 and 4 only with a virtual bench).
pub const HOLDING_REGISTERS: usize = 8;
/// The holding registers that exist only with a virtual bench.
pub const BENCH_HOLDING_REGISTERS: core::ops::Range<usize> = 3..5;
/// Virtual bench valve, 0.1 % of nominal k2: nominal.
pub const VALVE_NOMINAL_PERMILLE: u16 = 1000;
/// Virtual bench valve: the range, 0.1 % of nominal k2.
pub const VALVE_RANGE_PERMILLE: core::ops::RangeInclusive<u16> = 500..=2000;
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

/// Operating mode (holding register 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Torque reference 0.
    #[default]
    Stop = 0,
    /// Torque reference = the setpoint.
    Manual = 1,
    /// The built-in excitation profile (the paper's pulses).
    Profile = 2,
}

/// Arithmetic of the NARMAX pass (holding register 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Arithmetic {
    /// f32 forward pass.
    #[default]
    F32 = 0,
    /// Fixed point (the Q15 pass, `NarxQ15`).
    Fixed = 1,
}

impl Arithmetic {
    /// The name used in logs and options: `f32` or `q15`.
    pub fn name(self) -> &'static str {
        match self {
            Arithmetic::F32 => "f32",
            Arithmetic::Fixed => "q15",
        }
    }

    /// The arithmetic of a [`Self::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "f32" => Some(Arithmetic::F32),
            "q15" => Some(Arithmetic::Fixed),
            _ => None,
        }
    }
}

impl Mode {
    /// The name used in logs: `stop`, `manual` or `profile`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Stop => "stop",
            Mode::Manual => "manual",
            Mode::Profile => "profile",
        }
    }

    fn from_register(v: u16) -> Option<Self> {
        match v {
            0 => Some(Mode::Stop),
            1 => Some(Mode::Manual),
            2 => Some(Mode::Profile),
            _ => None,
        }
    }
}

/// Status bits of input register 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Bit 0: the drive is commanded to run.
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
    /// controller is blind to the drive, and input registers 14-16 read 0.
    pub vfd_readings_invalid: bool,
    /// Bit 7: tripped: a protection holds the torque at 0 % ([`crate::protect`]).
    pub tripped: bool,
}

impl Status {
    /// The register value.
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
        }
    }
}

/// What the controller publishes, in engineering units (converted and clamped here).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Published {
    /// Status bits, [`Status::bits`] (input register 0 without bit 8, which the registers
    /// add). A word, not the flags: the struct stays free of padding, so the 1 ms step copies
    /// it by words (with a padding byte at its end LLVM copied it byte by byte, ≈ 370
    /// instructions per step on the M4).
    pub status: u16,
    /// Applied torque reference, %.
    pub torque_pct: f32,
    /// Measured pressure, mca.
    pub pressure_mca: f32,
    /// Measured flow, l/s.
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
    /// Sample counter.
    pub sample: u16,
    /// White-box pressure residual, mca.
    pub whitebox_pressure_residual_mca: f32,
    /// White-box flow residual, l/s.
    pub whitebox_flow_residual_lps: f32,
    /// NARMAX pressure residual, mca.
    pub narmax_pressure_residual_mca: f32,
    /// NARMAX flow residual, l/s.
    pub narmax_flow_residual_lps: f32,
    /// VFD actual speed, rpm.
    pub vfd_speed_rpm: f32,
    /// VFD actual torque, %.
    pub vfd_torque_pct: f32,
    /// VFD status word.
    pub vfd_status: u16,
    /// Uptime, s.
    pub uptime_s: u16,
    /// Observer speed, rpm.
    pub observer_speed_rpm: f32,
    /// Observer flow, l/s.
    pub observer_flow_lps: f32,
    /// Observer valve coefficient k2.
    pub observer_valve_k2: f32,
    /// Alarm bits (see the module table).
    pub alarms: u16,
    /// Observer flow standard deviation, l/s.
    pub observer_flow_sd_lps: f32,
    /// The alarm bits that tripped the controller (0: not tripped).
    pub trip_causes: u16,
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

impl Published {
    /// The input registers. A value beyond its register's range reads as the range's end,
    /// and sets status bit 8 (saturated).
    pub fn registers(&self) -> [u16; INPUT_REGISTERS] {
        let mut f = Fit::default();
        let u = u16::MAX;
        let mut r = [
            0,
            f.unsigned(self.torque_pct, 100.0, SETPOINT_MAX),
            f.signed(self.pressure_mca, 1000.0),
            f.unsigned(self.flow_lps, 100.0, u),
            f.signed(self.whitebox_pressure_mca, 1000.0),
            f.unsigned(self.whitebox_flow_lps, 100.0, u),
            f.unsigned(self.whitebox_speed_rpm, 10.0, u),
            f.signed(self.narmax_pressure_mca, 1000.0),
            f.unsigned(self.narmax_flow_lps, 100.0, u),
            self.sample,
            f.signed(self.whitebox_pressure_residual_mca, 1000.0),
            f.signed(self.whitebox_flow_residual_lps, 100.0),
            f.signed(self.narmax_pressure_residual_mca, 1000.0),
            f.signed(self.narmax_flow_residual_lps, 100.0),
            f.signed(self.vfd_speed_rpm, 10.0),
            f.signed(self.vfd_torque_pct, 100.0),
            self.vfd_status,
            self.uptime_s,
            f.unsigned(self.observer_speed_rpm, 10.0, u),
            f.unsigned(self.observer_flow_lps, 100.0, u),
            f.unsigned(self.observer_valve_k2, 1e5, u),
            self.alarms,
            f.unsigned(self.observer_flow_sd_lps, 100.0, u),
            self.trip_causes,
            0,
            0,
        ];
        // The wide twins of 14 and 20: a saturated twin still reads the wide value.
        r[24] = signed_register(self.vfd_speed_rpm, 1.0);
        r[25] = unsigned_register(self.observer_valve_k2, 1e4);
        r[0] = self.status | (u16::from(f.saturated) << 8);
        r
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
    /// Holding registers 3 and 4 exist (a virtual bench).
    virtual_bench: bool,
    /// Virtual bench valve, 0.1 % of nominal k2 (500..=2000).
    pub valve_permille: u16,
    /// Virtual bench fault injection bits (0..=15).
    pub faults: u16,
    /// Writes of mode 0 (stop) so far (wraps): each acknowledges the latched alarms.
    pub stop_writes: u16,
    /// The protections (holding registers 5..=7).
    pub protection: ProtectionConfig,
}

impl ScadaSlave {
    /// A slave at `unit` (1..=247), stopped, setpoint 0; `None` for another address.
    pub fn new(unit: u8) -> Option<Self> {
        (1..=247).contains(&unit).then_some(Self {
            unit,
            setpoint: 0,
            mode: Mode::Stop,
            arithmetic: Arithmetic::F32,
            virtual_bench: false,
            valve_permille: VALVE_NOMINAL_PERMILLE,
            faults: 0,
            stop_writes: 0,
            protection: ProtectionConfig::DEFAULT,
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
            self.mode as u16,
            self.arithmetic as u16,
            self.valve_permille,
            self.faults,
            self.protection.overspeed_rpm,
            self.protection.trip_on,
            self.protection.no_flow_trip_s,
        ]
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

    /// Applies a write of `values` from `address` on, all or nothing.
    fn write_words(&mut self, address: u16, values: &[u16]) -> Result<(), Exception> {
        let start = usize::from(address);
        if !self.holding_exist(start, values.len()) {
            return Err(Exception::IllegalDataAddress);
        }
        let mut next = *self;
        for (k, &v) in values.iter().enumerate() {
            match start + k {
                0 if v <= SETPOINT_MAX => next.setpoint = v,
                1 => {
                    next.mode = Mode::from_register(v).ok_or(Exception::IllegalDataValue)?;
                    if next.mode == Mode::Stop {
                        next.stop_writes = next.stop_writes.wrapping_add(1);
                    }
                }
                2 => {
                    next.arithmetic = match v {
                        0 => Arithmetic::F32,
                        1 => Arithmetic::Fixed,
                        _ => return Err(Exception::IllegalDataValue),
                    }
                }
                3 if VALVE_RANGE_PERMILLE.contains(&v) => next.valve_permille = v,
                4 if v <= 15 => next.faults = v,
                5 if OVERSPEED_RANGE_RPM.contains(&v) => next.protection.overspeed_rpm = v,
                6 if v & !TRIP_ALL == 0 => next.protection.trip_on = v,
                7 if NO_FLOW_TRIP_RANGE_S.contains(&v) => next.protection.no_flow_trip_s = v,
                _ => return Err(Exception::IllegalDataValue),
            }
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
    use crate::modbus::crc16;

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
        assert_eq!(s.arithmetic, Arithmetic::Fixed);
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
        assert_eq!(exception(&mut s, &[1, 3, 0, 7, 0, 2]), 2, "past the map");
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

    /// Regression (defect 4 of the protection issue): register 14 held a runaway drive at
    /// 3 276.7 rpm and register 20 a k2 above 0.65535 at 0.65535, with nothing to say so.
    #[test]
    fn saturation_is_flagged_and_the_wide_registers_hold_the_value() {
        let ok = Published {
            vfd_speed_rpm: 1750.0,
            observer_valve_k2: 0.1082,
            ..Published::default()
        };
        let r = ok.registers();
        assert_eq!(r[0] & 1 << 8, 0);
        assert_eq!((r[14], r[24], r[20], r[25]), (17500, 1750, 10820, 1082));
        let fast = Published {
            vfd_speed_rpm: 5123.4,
            ..ok
        };
        let r = fast.registers();
        assert_eq!(r[0] & 1 << 8, 1 << 8, "saturated");
        assert_eq!((r[14], r[24]), (32767, 5123));
        let closed = Published {
            observer_valve_k2: 0.9,
            ..ok
        };
        let r = closed.registers();
        assert_eq!(r[0] & 1 << 8, 1 << 8);
        assert_eq!((r[20], r[25]), (65535, 9000));
        let back = Published {
            vfd_speed_rpm: -3300.0,
            ..ok
        };
        assert_eq!(back.registers()[0] & 1 << 8, 1 << 8, "negative too");
        assert_eq!(back.registers()[24] as i16, -3300);
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
            exception(&mut s, &[1, 4, 0, 25, 0, 2]),
            2,
            "past the input map"
        );
        assert_eq!(
            exception(&mut s, &[1, 3, 0, 3, 0, 1]),
            2,
            "the bench's holding registers on a board"
        );
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 8, 0, 1]),
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
        assert_eq!(exception(&mut s, &[1, 6, 0, 1, 0, 3]), 3, "mode 3");
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
        let r = p.registers();
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
